"""The layout of a ``leoc reproduce`` folder, shared by the pipeline and the report.

::

    OUT/meta.json                                   what the last invocation ran (profile, seeds,
                                                    systems, controllers, versions, command)
    OUT/runs/SYSTEM/CONTROLLER/seedN/train/         the trainer's own run folder
    OUT/runs/SYSTEM/CONTROLLER/seedN/train.log      the worker's output (progress)
    OUT/runs/SYSTEM/CONTROLLER/seedN/evaluation.json   written last, atomically: the run is done
    OUT/results.json, *.csv, *.png, report.md      the aggregated report
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

EVALUATION_FILE = "evaluation.json"
LOG_FILE = "train.log"
META_FILE = "meta.json"
# Swing-up episodes of every evaluated controller (the trainers' evaluation starts).
SWING_UP_EPISODES = 5


def run_dir_of(out_dir: Path, spec: Any) -> Path:
    """The folder of one run (a :class:`~leoc.experiments.profiles.RunSpec`)."""
    return Path(out_dir) / "runs" / spec.system / spec.controller / f"seed{spec.seed}"
