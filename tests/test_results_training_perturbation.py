"""The published training-under-perturbation study's table (``results/robustness-training-
pendulum-sac/README.md``) against the records it was read from: each run's ``leoc robustness``
output and the nominal runs' ``evaluation.json`` of ``results/certified-pendulum-sac``; and the
one switch between its two randomised arms: the same training (identical nominal curves), the
kept actor chosen on the nominal plant or on the randomised plants."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "results"
FOLDER = RESULTS / "robustness-training-pendulum-sac"
SELECTED = FOLDER / "select-on-training"
NOMINAL = RESULTS / "certified-pendulum-sac" / "runs" / "pendulum"
KINDS = ("all", "operating_region", "swing_up")


def _cell(values: list[float]) -> str:
    """Median [least, largest] to three decimals, as the README writes them."""
    ordered = sorted(values)
    return f"{statistics.median(ordered):.3f} [{ordered[0]:.3f}, {ordered[-1]:.3f}]"


def _row(scores: list[dict]) -> list[str]:
    cells = [_cell([s[kind]["actuator_gain"] for s in scores]) for kind in KINDS]
    return [*cells, _cell([s["all"]["robustness"] for s in scores])]


@pytest.mark.skipif(not FOLDER.is_dir(), reason="the study is not in this checkout")
def test_the_readme_table_is_the_records_median_over_seeds() -> None:
    """The nominal hybrid's and both randomised arms' rows are the medians and ranges of their
    five seeds' scores; the first randomised arm below nominal on actuator gain on every seed,
    the second above the first on every seed; the per-seed changes the README writes."""
    randomised = [
        json.loads((FOLDER / f"seed{s}" / "robustness.json").read_text())["scores"]["train"]
        for s in range(5)
    ]
    nominal = [
        json.loads((NOMINAL / "sac_hybrid" / f"seed{s}" / "evaluation.json").read_text())[
            "robustness_protocol"
        ]["scores"]
        for s in range(5)
    ]
    selected = [
        json.loads((SELECTED / f"seed{s}" / "robustness.json").read_text())["scores"]["train"]
        for s in range(5)
    ]
    readme = (FOLDER / "README.md").read_text()
    for name, scores in (
        ("SAC hybrid, nominal plant", nominal),
        (
            "SAC hybrid, gain randomised in [0.52, 1.48], kept actor chosen on the nominal plant",
            randomised,
        ),
        (
            "SAC hybrid, gain randomised in [0.52, 1.48], kept actor chosen on randomised plants",
            selected,
        ),
    ):
        assert f"| {name} | {' | '.join(_row(scores))} |" in readme

    def changes(new: list[dict], old: list[dict]) -> list[float]:
        return [
            a["all"]["actuator_gain"] - b["all"]["actuator_gain"]
            for a, b in zip(new, old, strict=True)
        ]

    assert all(change < 0 for change in changes(randomised, nominal))
    assert all(change > 0 for change in changes(selected, randomised))
    for new, old in ((selected, randomised), (selected, nominal)):
        shown = [f"{c:+.3f}" for c in changes(new, old)]
        assert f"{', '.join(shown[:-1])} and {shown[-1]}" in readme.replace("\n  ", " ")


def _kept_step(rows: list[dict], record) -> int:
    """The step ``best_held`` keeps when it judges each row by ``record(row)`` (return, held
    share): the best key, the earliest on ties."""
    from leoc.sb3.callbacks import selection_key

    keys = [selection_key("best_held", *record(row)) for row in rows]
    return rows[max(range(len(rows)), key=lambda i: (keys[i], -i))]["steps"]


@pytest.mark.skipif(not SELECTED.is_dir(), reason="the study is not in this checkout")
def test_the_two_randomised_arms_differ_in_the_selection_alone() -> None:
    """Each seed of the selection arm trained exactly as the first arm (the nominal learning
    curves agree to the last digit written), its kept actor is the best of its randomised-plant
    records by the ``best_held`` rule, and the nominal rule, applied to the same curve, picks
    another step: the step the first arm kept. It scores above the first arm on actuator gain
    on every seed."""
    import csv

    kept = {"nominal": [], "randomised": []}
    for seed in range(5):
        run = SELECTED / f"seed{seed}"
        curve = json.loads((run / "curve.json").read_text())
        rows = curve["curve"]
        with (FOLDER / f"seed{seed}" / "curve.csv").open() as handle:
            first = list(csv.DictReader(handle))
        assert [int(r["steps"]) for r in first] == [row["steps"] for row in rows]
        for old, row in zip(first, rows, strict=True):
            assert float(old["mean_return"]) == pytest.approx(row["mean_return"], rel=1e-12)

        chosen = _kept_step(
            rows, lambda row: (row["selection"]["mean_return"], row["selection"]["held_fraction"])
        )
        assert curve["summary"]["selected_steps"] == chosen
        nominal = _kept_step(rows, lambda row: (row["mean_return"], row["held_fraction"]))
        assert nominal != chosen
        kept["nominal"].append(nominal)
        kept["randomised"].append(chosen)
        scores = [
            json.loads((folder / "robustness.json").read_text())["scores"]["train"]["all"]
            for folder in (FOLDER / f"seed{seed}", run)
        ]
        assert scores[1]["actuator_gain"] > scores[0]["actuator_gain"], seed
    readme = " ".join((FOLDER / "README.md").read_text().split())
    for steps in kept.values():
        assert f"{', '.join(map(str, steps[:-1]))} and {steps[-1]}" in readme
