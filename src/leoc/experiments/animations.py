"""One animation per system for a ``leoc reproduce`` report: a representative hybrid run's
swing-up and impulse response, with r(x) shown (:func:`leoc.evaluation.video.write_video`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from leoc.evaluation.video import write_video

__all__ = ["ANIMATIONS_DIR", "representative_run", "write_report_animations"]

#: Folder of a reproduce folder holding the animations, ``animations/SYSTEM.gif``.
ANIMATIONS_DIR = "animations"


def representative_run(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The run of median swing-up mean return (the lower median of an even count; ties by
    seed), from the ``evaluation.json`` records of one controller's seeds."""
    ordered = sorted(runs, key=lambda run: (run["swing_up"]["mean_return"], run["spec"]["seed"]))
    return ordered[(len(ordered) - 1) // 2]


def write_report_animations(
    out_dir: str | Path, evaluations: Mapping[str, Mapping[str, list[dict[str, Any]]]] | None = None
) -> dict[str, Path]:
    """``OUT/animations/SYSTEM.gif`` for one hybrid run per system of the ``leoc reproduce``
    folder ``out_dir``: the first hybrid controller (in report order) whose runs kept their
    trained controllers, at its seed of median swing-up return, on the plant it was trained on.

    Parameters
    ----------
    out_dir : path
        The ``leoc reproduce`` folder.
    evaluations : mapping, optional
        Its finished runs by system and controller (the report's, filtered by its
        ``meta.json``); default every finished run
        (:func:`~leoc.experiments.layout.load_evaluations`).

    Returns
    -------
    dict
        The animation of each system that has one; a system without a kept hybrid controller
        gets none (a published folder keeps no trained controllers, so it gets none at all).
        An animation newer than every ``evaluation.json`` of its controller is kept, not redrawn.
    """
    from leoc.experiments.controllers import load_trained_controller, trained_plant
    from leoc.experiments.layout import EVALUATION_FILE, load_evaluations
    from leoc.names import CONTROLLERS

    out_dir = Path(out_dir)
    evaluations = load_evaluations(out_dir) if evaluations is None else evaluations
    written: dict[str, Path] = {}
    for system_name, by_controller in evaluations.items():
        for controller in (name for name in CONTROLLERS if "hybrid" in name):
            every_run = by_controller.get(controller, [])
            runs = [run for run in every_run if _has_controller(_run_dir(out_dir, run))]
            if not runs:
                continue
            path = out_dir / ANIMATIONS_DIR / f"{system_name}.gif"
            newest = max(
                (_run_dir(out_dir, run) / EVALUATION_FILE).stat().st_mtime for run in every_run
            )
            if path.is_file() and path.stat().st_mtime > newest:
                written[system_name] = path
                break
            run = representative_run(runs)
            system = trained_plant(_run_dir(out_dir, run))  # the plant it was trained on
            policy = load_trained_controller(_run_dir(out_dir, run), system=system_name)
            label = f"{system_name}/{controller}/seed{run['spec']['seed']}"
            written[system_name] = write_video(system, policy, path, label=label)
            break
    return written


def _run_dir(out_dir: Path, run: dict[str, Any]) -> Path:
    """The folder of the run whose ``evaluation.json`` is ``run``."""
    from types import SimpleNamespace

    from leoc.experiments.layout import run_dir_of

    return run_dir_of(out_dir, SimpleNamespace(**run["spec"]))


def _has_controller(run_dir: Path) -> bool:
    """Whether ``run_dir`` kept its trained controller."""
    from leoc.experiments.controllers import trainer_dir

    try:
        trainer_dir(run_dir)
    except FileNotFoundError:
        return False
    return True
