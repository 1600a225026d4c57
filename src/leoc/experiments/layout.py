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

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

from leoc.names import controller_framework

EVALUATION_FILE = "evaluation.json"
LOG_FILE = "train.log"
META_FILE = "meta.json"
# Swing-up episodes of every evaluated controller (the trainers' evaluation starts).
SWING_UP_EPISODES = 5


def run_dir_of(out_dir: Path, spec: Any) -> Path:
    """The folder of one run (a :class:`~leoc.experiments.profiles.RunSpec`):
    ``OUT/runs/SYSTEM/CONTROLLER/seedN`` (:func:`leoc.training.run_folder`)."""
    from leoc.training import run_folder  # torch: not needed to import this module

    return run_folder(Path(out_dir) / "runs", spec.system, spec.controller, spec.seed)


Evaluations = dict[str, dict[str, list[dict[str, Any]]]]  # system -> controller -> seeds


def load_evaluations(out_dir: Path, meta: dict[str, Any] | None = None) -> Evaluations:
    """Finished runs under ``out_dir/runs``, grouped by system and controller.

    With ``meta``, only the runs of its systems, controllers and seeds are aggregated (a folder
    resumed with other settings never mixes runs into the report silently).

    Raises
    ------
    ValueError
        Naming the file, when an ``evaluation.json`` does not parse.
    """
    grouped: Evaluations = defaultdict(lambda: defaultdict(list))
    for path in sorted((out_dir / "runs").glob(f"*/*/seed*/{EVALUATION_FILE}")):
        try:
            data = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise ValueError(
                f"{path}: damaged evaluation file ({error}); rerun the 'leoc reproduce' command "
                "of this folder: it sets the damaged file aside and redoes that run"
            ) from error
        spec = data["spec"]
        if meta is not None and not _selected(spec, meta):
            continue
        grouped[spec["system"]][spec["controller"]].append(data)
    from leoc.systems import system_names  # torch: not needed to import this module

    return {system: dict(grouped[system]) for system in system_names() if system in grouped}


def _selected(spec: dict[str, Any], meta: dict[str, Any]) -> bool:
    seeds = meta.get("seeds", [])
    seed_ok = controller_framework(spec["controller"]) == "linear" or spec["seed"] in seeds
    return (
        spec["system"] in meta.get("systems", [])
        and spec["controller"] in meta.get("controllers", [])
        and seed_ok
    )
