"""The published training-under-perturbation study's table (``results/robustness-training-
pendulum-sac/README.md``) against the records it was read from: each run's ``leoc robustness``
output and the nominal runs' ``evaluation.json`` of ``results/certified-pendulum-sac``."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "results"
FOLDER = RESULTS / "robustness-training-pendulum-sac"
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
    """The randomised and the nominal hybrid's rows are the medians and ranges of their five
    seeds' scores; randomised below nominal on actuator gain on every seed, as the README says."""
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
    readme = (FOLDER / "README.md").read_text()
    for name, scores in (
        ("SAC hybrid, nominal plant", nominal),
        ("SAC hybrid, actuator gain randomised in [0.52, 1.48]", randomised),
    ):
        assert f"| {name} | {' | '.join(_row(scores))} |" in readme
    changes = [
        r["all"]["actuator_gain"] - n["all"]["actuator_gain"]
        for r, n in zip(randomised, nominal, strict=True)
    ]
    assert all(change < 0 for change in changes)
    assert ", ".join(f"{c:.3f}" for c in changes[:-1]) in readme  # "The change per seed is"
