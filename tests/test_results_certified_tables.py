"""The published certified studies' README tables (``results/certified-*/README.md``) against
the runs' records: each row's proved rho, share of the box, ratios, swing-up count and
robustness score are the medians [least, largest] of the five seeds' ``evaluation.json``."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "results"
STUDIES = {
    "certified-pendulum-td3": ("pendulum", "td3"),
    "certified-mountaincar-ddpg": ("mountaincar", "ddpg"),
    "certified-mountaincar-sac": ("mountaincar", "sac"),
}
"""Study folder -> its system and learner; each README has one row per learned controller."""
KINDS = {"baseline": "_baseline", "hybrid": "_hybrid", "ROA hybrid": "_hybrid_roa"}
"""Row label after the learner's name -> the controller name's suffix."""
OPERATING_HEADER = "from the operating region"
"""The header of the optional column before the last: the robustness score from the operating
region's starts (the last column is every start's)."""


def _runs(folder: Path, system: str, controller: str) -> list[dict]:
    return [
        json.loads(
            (folder / "runs" / system / controller / f"seed{n}" / "evaluation.json").read_text()
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
        *(
            _spread(
                [run["robustness_protocol"]["scores"][starts]["robustness"] for run in runs],
                lambda v: f"{v:.2f}",
            )
            for starts in ("operating_region", "all")
        ),
    ]


@pytest.mark.parametrize("study", sorted(STUDIES))
def test_the_readme_table_is_the_records_median_over_seeds(study: str) -> None:
    folder = RESULTS / study
    if not folder.is_dir():
        pytest.skip(f"{study} is not in this checkout")
    system, learner = STUDIES[study]
    lines = (folder / "README.md").read_text().splitlines()
    for kind, suffix in KINDS.items():
        label = f"{learner.upper()} {kind}"
        row = next(line for line in lines if line.startswith(f"| {label} |"))
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        swing, rho, share, ratio, volume, *_, operating, score = cells[1:]
        expected = _cells(_runs(folder, system, learner + suffix))
        found = [swing, rho.split(" (")[0], share, ratio, volume, operating, score]
        if not any(OPERATING_HEADER in line for line in lines if line.startswith("| ")):
            del found[-2], expected[-2]  # a table without the operating-region score
        assert found == expected, label
