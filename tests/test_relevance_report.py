"""leoc.experiments.relevance_report: the relevance ablation's cells from hand-made records,
whose counts, medians and first-hold times are known by construction of the records."""

from __future__ import annotations

import json
import math

import pytest

from leoc.experiments.ablation_report import publish_ablation
from leoc.experiments.relevance_report import (
    CUSTOM_SETTING,
    PILCO_FOLDER,
    first_hold_seconds,
    pilco_relevance_records,
    relevance_cells,
    relevance_setting,
    write_relevance_report,
)
from leoc.policies.spec import HybridSpec
from leoc.systems import make_system

HELD = [10, 20, 30]  # hold steps of three held-out episodes that all held
MISSED = [10, None, 30]


def _record(seed, holds, distance, keeps, min_r, lam, setting="defaults"):
    evaluations = [
        {
            "steps": 200 * (k + 1),
            "selection_return": -100.0 * (3 - k),
            "selection_held_fraction": 1.0,
            "test_returns": [0.0, 0.0, 0.0],
            "test_hold_steps": hold,
        }
        for k, hold in enumerate(holds)
    ]
    impulse = {"distance_pct": distance, "keeps_lqr": keeps, "min_relevance": min_r}
    impulse["by_construction"] = min_r >= 1.0
    return {
        "system": "pendulum",
        "controller": "ddpg_hybrid",
        "setting": setting,
        "seed": seed,
        "key": f"pendulum/ddpg_hybrid/{setting}/seed{seed}",
        "budget": 200 * len(holds),
        "learning_starts": 100,
        "model_selection": "final",
        "evaluations": evaluations,
        "lqr_agreement": {
            "impulse": impulse,
            "step": {"distance_pct": 2.0 * distance},
            "relevance": {"kind": "paper", "lambda": lam},
        },
    }


def _records():
    return [
        _record(0, [MISSED, HELD, HELD], 1.0, True, 0.99, [1.0, 2.0, 4.0]),  # first hold 400
        _record(1, [MISSED, MISSED, HELD], 3.0, False, 0.9, [3.0, 4.0, 8.0]),  # first hold 600
        _record(2, [MISSED, MISSED, MISSED], 5.0, False, 0.8, [5.0, 6.0, 16.0]),  # never
        _record(0, [HELD, HELD, MISSED], 0.0, True, 1.0, [1.0, 1.0, 1.0], "relevance_frozen"),
    ]


def test_first_hold_seconds_is_the_first_all_held_evaluation_in_seconds():
    dt = make_system("pendulum").dt
    records = _records()
    assert first_hold_seconds(records[0]) == pytest.approx(400 * dt)
    assert first_hold_seconds(records[1]) == pytest.approx(600 * dt)
    assert first_hold_seconds(records[2]) is None


def test_cells_count_and_take_medians_by_hand():
    dt = make_system("pendulum").dt
    cells = {cell["setting"]: cell for cell in relevance_cells(_records())}
    assert list(cells) == ["defaults", "relevance_frozen"]  # the grid's order
    cell = cells["defaults"]
    assert cell["seeds"] == 3
    assert cell["success"] == 2  # final evaluation held for seeds 0 and 1
    assert cell["ever_held"] == 2
    assert cell["median_first_hold_s"] == pytest.approx(500 * dt)
    assert cell["keeps_lqr"] == 1 and cell["by_construction"] == 0
    assert cell["median_distance_pct"] == 3.0
    assert (cell["min_distance_pct"], cell["max_distance_pct"]) == (1.0, 5.0)
    assert cell["median_min_relevance"] == pytest.approx(0.9)
    assert cell["median_step_distance_pct"] == 6.0
    assert cell["median_lambda"] == [3.0, 4.0, 8.0]
    frozen = cells["relevance_frozen"]
    assert frozen["success"] == 0 and frozen["by_construction"] == 1


def test_report_is_written_and_skips_records_without_agreement(tmp_path):
    records = _records() + [{**_records()[0], "lqr_agreement": None, "controller": "x"}]
    path = write_relevance_report(tmp_path, records, "leoc ablation ...")
    text = path.read_text()
    assert "| DDPG hybrid | leoc's defaults since issue 20 | 2/3 |" in text
    assert (tmp_path / "relevance_tradeoff.png").stat().st_size > 10_000
    assert write_relevance_report(tmp_path / "none", records[-1:]) is None
    assert not math.isnan(relevance_cells(records)[0]["median_distance_pct"])


def test_relevance_setting_names_the_spec_a_pilco_run_trained():
    default = HybridSpec().to_dict()
    assert relevance_setting(default) == "relevance_power_2_floor_0.5"  # leoc's default
    paper = {**default, "r_min": None, "relevance_power": 1.0}
    assert relevance_setting(paper) == "relevance_paper"
    assert relevance_setting({**paper, "lambda_init": 10.0}) == "relevance_init_10"
    assert relevance_setting({**default, "lambda_init": 10.0}) == CUSTOM_SETTING


def _pilco_run(folder, seed, held, distance, hybrid=None, iterations=None):
    """A PILCO hybrid run folder ``cartpole/pilco_hybrid/seedN/train``: curve held fractions per
    iteration at 3, 7, 11, ... interaction seconds; its impulse distance, for the stand-in
    LQR comparison ``delivered_lqr_agreement`` (monkeypatched: the saved controller is an
    empty file)."""
    train = folder / "cartpole" / "pilco_hybrid" / f"seed{seed}" / "train"
    train.mkdir(parents=True)
    iterations = len(held) - 1 if iterations is None else iterations
    config = {"system": "cartpole", "seed": seed, "iterations": iterations}
    config["hybrid"] = hybrid or HybridSpec().to_dict()
    (train / "config.json").write_text(json.dumps(config))
    rows = [
        {"iteration": k, "interaction_seconds": 3.0 + 4.0 * k, "held_fraction": fraction}
        for k, fraction in enumerate(held)
    ]
    (train / "curve.json").write_text(json.dumps({"curve": rows, "summary": {}}))
    (train / "controller.pt").write_bytes(b"")
    impulse = {"distance_pct": distance, "keeps_lqr": distance <= 2.0, "min_relevance": 0.99}
    DISTANCES[str(train)] = {
        "impulse": {**impulse, "by_construction": False},
        "step": {"distance_pct": distance},
        "relevance": {"kind": "FlooredRelevance", "lambda": [1.0, 2.0]},
    }


DISTANCES: dict = {}


@pytest.fixture
def stand_in_agreement(monkeypatch):
    from leoc.experiments import relevance_report

    def stand_in(run, system, hybrid):
        assert hybrid and system.name == "cartpole"
        return DISTANCES[str(run / "train")]

    monkeypatch.setattr(relevance_report, "delivered_lqr_agreement", stand_in)


def test_pilco_run_folders_become_relevance_cells(tmp_path, stand_in_agreement):
    folder = tmp_path / "pilco"
    _pilco_run(folder, 0, [0.0, 0.8, 1.0, 1.0], 0.5)  # first hold at iteration 2: 11 s
    _pilco_run(folder, 1, [0.0, 1.0, 0.6, 0.8], 3.0)  # held at 7 s, then fails
    _pilco_run(folder, 2, [0.0, 0.0, 0.0, 0.4], 1.0)  # never holds
    _pilco_run(folder, 3, [0.0, 1.0, 1.0], 1.0, iterations=3)  # unfinished: left out
    records = pilco_relevance_records(folder)
    assert [r["first_hold_s"] for r in records] == [11.0, 7.0, None]
    assert [r["success"] for r in records] == [True, False, False]
    (cell,) = relevance_cells(records)
    assert (cell["controller"], cell["setting"]) == ("pilco_hybrid", "relevance_power_2_floor_0.5")
    assert (cell["seeds"], cell["success"], cell["ever_held"], cell["keeps_lqr"]) == (3, 1, 2, 2)
    assert cell["median_first_hold_s"] == pytest.approx(9.0)
    assert cell["median_distance_pct"] == pytest.approx(1.0)


def test_publishing_keeps_the_pilco_records_and_their_rows(tmp_path, stand_in_agreement):
    source = tmp_path / "ablation"
    record = _records()[0]
    run = source / "runs" / "pendulum" / "ddpg_hybrid" / "defaults" / "seed0"
    run.mkdir(parents=True)
    (run / "result.json").write_text(json.dumps({**record, "wall_seconds": 1.0}))
    _pilco_run(source / PILCO_FOLDER, 0, [0.0, 1.0], 0.5)
    paper = {**HybridSpec().to_dict(), "r_min": None, "relevance_power": 1.0}
    _pilco_run(source / PILCO_FOLDER, 1, [0.0, 0.0], 40.0, paper)
    dest = tmp_path / "published"
    publish_ablation(source, dest)
    kept = sorted((dest / PILCO_FOLDER).rglob("relevance.json"))
    assert len(kept) == 2 and not list((dest / PILCO_FOLDER).rglob("controller.pt"))
    text = (dest / "relevance.md").read_text()
    assert "| PILCO hybrid | the paper's r = (1 + d)^-2" in text
    assert "| PILCO hybrid | r = (1 + d^2)^-2, Lambda floored" in text
    publish_ablation(dest)  # the published folder regenerates its table from its records
    assert (dest / "relevance.md").read_text() == text


def test_a_trained_pilco_hybrid_is_compared_with_its_lqr(tmp_path, tiny_pilco_settings):
    """A real (tiny) PILCO hybrid run: its record's comparison is its saved controller's against
    the LQR, and (a) and the first hold follow its curve."""
    from leoc.pilco import train_pilco

    train = tmp_path / "pilco" / "pendulum" / "pilco_hybrid" / "seed0" / "train"
    options = {"run_dir": train, "iterations": 1, "progress": False}
    train_pilco("pendulum", HybridSpec(), 0, **options, **tiny_pilco_settings)
    (record,) = pilco_relevance_records(tmp_path / "pilco")
    curve = json.loads((train / "curve.json").read_text())["curve"]
    assert record["success"] == (curve[-1]["held_fraction"] >= 1.0)
    impulse = record["lqr_agreement"]["impulse"]
    assert 0.0 < impulse["min_relevance"] < 1.0 and not impulse["by_construction"]
    assert record["setting"] == "relevance_power_2_floor_0.5"
