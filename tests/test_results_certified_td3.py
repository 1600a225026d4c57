"""The published TD3 study's README table (``results/certified-pendulum-td3/README.md``) against
the runs' records: each row's proved rho, share of the box, ratios, swing-up count and
robustness score are the medians [least, largest] of the five seeds' ``evaluation.json``."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import pytest

FOLDER = Path(__file__).resolve().parents[1] / "results" / "certified-pendulum-td3"
ROWS = {
    "TD3 baseline": "td3_baseline",
    "TD3 hybrid": "td3_hybrid",
    "TD3 ROA hybrid": "td3_hybrid_roa",
}


def _runs(controller: str) -> list[dict]:
    return [
        json.loads(
            (FOLDER / "runs" / "pendulum" / controller / f"seed{n}" / "evaluation.json").read_text()
        )
        for n in range(5)
    ]


def _spread(values: list[float], show) -> str:
    """``median [least, largest]``, the median alone when every seed agrees."""
    low, high, middle = min(values), max(values), statistics.median(values)
    if show(low) == show(high):
        return show(middle)
    return f"{show(middle)} [{show(low)}, {show(high)}]"


def _cells(runs: list[dict]) -> list[str]:
    proved = [run["proved_region"] for run in runs]
    held = sum(run["swing_up"]["held_fraction"] >= 1.0 for run in runs)
    return [
        f"{held}/{len(runs)}",
        _spread([p["rho"] for p in proved], lambda v: f"{v:.3g}"),
        _spread([p["box_share"] for p in proved], lambda v: f"{100 * v:.0f}%"),
        _spread(
            [p["box_share_ratio"] for p in proved], lambda v: f"{v:.2g}" if v < 0.99 else f"{v:.3g}"
        ),
        _spread(
            [p["volume_ratio"] for p in proved], lambda v: f"{v:.2g}" if v < 0.99 else f"{v:.3g}"
        ),
        _spread(
            [run["robustness_protocol"]["scores"]["all"]["robustness"] for run in runs],
            lambda v: f"{v:.2f}",
        ),
    ]


@pytest.mark.skipif(not FOLDER.is_dir(), reason="the study is not in this checkout")
def test_the_readme_table_is_the_records_median_over_seeds() -> None:
    lines = (FOLDER / "README.md").read_text().splitlines()
    for label, controller in ROWS.items():
        row = next(line for line in lines if line.startswith(f"| {label} |"))
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        swing, rho, share, ratio, volume, *_, score = cells[1:]
        expected = _cells(_runs(controller))
        found = [swing, rho.split(" (")[0], share, ratio, volume, score]
        assert found == expected, label
