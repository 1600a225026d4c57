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


def _pilco_run(folder, seed, held, swing_up_holds, distance, hybrid=None):
    """A ``leoc reproduce`` PILCO hybrid run folder: curve held fractions per iteration at
    30, 40, ... interaction seconds, the swing-up test's hold steps, the impulse distance."""
    run = folder / "runs" / "cartpole" / "pilco_hybrid" / f"seed{seed}"
    (run / "train").mkdir(parents=True)
    config = {"iterations": len(held) - 1, "hybrid": hybrid or HybridSpec().to_dict()}
    (run / "train" / "config.json").write_text(json.dumps(config))
    impulse = {"distance_pct": distance, "keeps_lqr": distance <= 2.0, "min_relevance": 0.99}
    evaluation = {
        "spec": {"system": "cartpole", "controller": "pilco_hybrid", "seed": seed},
        "curve": {
            "seconds": [30.0 + 10.0 * k for k in range(len(held))],
            "held_fraction": held,
        },
        "swing_up": {"hold_steps": swing_up_holds},
        "lqr_agreement": {
            "impulse": {**impulse, "by_construction": False},
            "step": {"distance_pct": distance},
            "relevance": {"kind": "FlooredRelevance", "lambda": [1.0, 2.0]},
        },
    }
    (run / "evaluation.json").write_text(json.dumps(evaluation))


def test_pilco_runs_of_a_reproduce_folder_become_relevance_cells(tmp_path):
    folder = tmp_path / "reproduce"
    _pilco_run(folder, 0, [0.0, 0.8, 1.0, 1.0], [5, 6, 7], 0.5)  # first hold at 50 s
    _pilco_run(folder, 1, [0.0, 1.0, 0.6, 0.8], [5, None, 7], 3.0)  # held at 40 s, then fails
    _pilco_run(folder, 2, [0.0, 0.0, 0.0, 0.4], [None, None, None], 1.0)  # never holds
    records = pilco_relevance_records(folder)
    assert [r["first_hold_s"] for r in records] == [50.0, 40.0, None]
    assert [r["success"] for r in records] == [True, False, False]
    (cell,) = relevance_cells(records)
    assert (cell["controller"], cell["setting"]) == ("pilco_hybrid", "relevance_power_2_floor_0.5")
    assert (cell["seeds"], cell["success"], cell["ever_held"], cell["keeps_lqr"]) == (3, 1, 2, 2)
    assert cell["median_first_hold_s"] == pytest.approx(45.0)
    assert cell["median_distance_pct"] == pytest.approx(1.0)


def test_publishing_keeps_the_pilco_records_and_their_rows(tmp_path):
    source = tmp_path / "ablation"
    record = _records()[0]
    run = source / "runs" / "pendulum" / "ddpg_hybrid" / "defaults" / "seed0"
    run.mkdir(parents=True)
    (run / "result.json").write_text(json.dumps({**record, "wall_seconds": 1.0}))
    _pilco_run(source / PILCO_FOLDER, 0, [0.0, 1.0], [5], 0.5)
    paper = {**HybridSpec().to_dict(), "r_min": None, "relevance_power": 1.0}
    _pilco_run(source / PILCO_FOLDER, 1, [0.0, 0.0], [None], 40.0, paper)
    dest = tmp_path / "published"
    publish_ablation(source, dest)
    kept = sorted((dest / PILCO_FOLDER).rglob("relevance.json"))
    assert len(kept) == 2 and not list((dest / PILCO_FOLDER).rglob("evaluation.json"))
    text = (dest / "relevance.md").read_text()
    assert "| PILCO hybrid | the paper's r = (1 + d)^-2" in text
    assert "| PILCO hybrid | r = (1 + d^2)^-2, Lambda floored" in text
    publish_ablation(dest)  # the published folder regenerates its table from its records
    assert (dest / "relevance.md").read_text() == text
