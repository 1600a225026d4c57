"""leoc.experiments.relevance_report: the relevance ablation's cells from hand-made records,
whose counts, medians and first-hold times are known by construction of the records."""

from __future__ import annotations

import math

import pytest

from leoc.experiments.relevance_report import (
    first_hold_seconds,
    relevance_cells,
    write_relevance_report,
)
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
