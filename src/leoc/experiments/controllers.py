"""Load a trained controller, at its control period, from a run folder.

Accepted folders: the run folder written by ``leoc train`` (or ``train_pilco``/``train_ddpg``),
and the per-run folder ``OUT/runs/SYSTEM/CONTROLLER/seedN`` that ``leoc reproduce`` prints
(its trainer output is in ``train/``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import torch

from leoc.experiments.layout import EVALUATION_FILE
from leoc.learners import Learner, get_learner, learner_names
from leoc.names import LINEAR
from leoc.training import read_config

if TYPE_CHECKING:
    from leoc.systems import TrainingPerturbations
    from leoc.systems.base import StepRules, System

REPRODUCE_TRAIN_DIR = "train"


def _learner_of(folder: Path) -> Learner | None:
    """The registered learner whose run folder ``folder`` is (its marker file), or None."""
    for name in learner_names():
        learner = get_learner(name)
        if (folder / learner.marker).is_file():
            return learner
    return None


def trainer_dir(run_dir: str | Path) -> Path:
    """The folder holding the trainer's files: ``run_dir`` itself or its ``train/``."""
    path = Path(run_dir)
    if not path.is_dir():
        raise FileNotFoundError(f"controller: run folder {str(path)!r} does not exist")
    for candidate in (path, path / REPRODUCE_TRAIN_DIR):
        if _learner_of(candidate) is not None:
            return candidate
    recorded = _reproduce_record(path)
    spec = recorded.get("spec") if isinstance(recorded.get("spec"), dict) else {}
    if spec.get("controller") == LINEAR or str(spec.get("controller")).startswith(f"{LINEAR}_"):
        command = f"leoc simulate {spec.get('system')} --variant {recorded.get('variant')}"
        if recorded.get("action_repeat", 1) != 1:
            command += f" --action-repeat {recorded.get('action_repeat')}"
        raise FileNotFoundError(
            f"controller: {str(path)!r} is a linear reference of 'leoc reproduce' (designed, not "
            f"trained: it holds no controller file); simulate it as '{command}'"
        )
    markers = " or ".join(f"{get_learner(name).marker} ({name})" for name in learner_names())
    raise FileNotFoundError(
        f"controller: expected 'linear' or a run folder holding {markers}, directly or in "
        f"{REPRODUCE_TRAIN_DIR}/, found none in {str(path)!r}"
    )


def _reproduce_record(path: Path) -> dict:
    """What a ``leoc reproduce`` run folder records (its ``evaluation.json``), or {}."""
    import json

    try:
        record = json.loads((path / EVALUATION_FILE).read_text())
    except (OSError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def trained_system(run_dir: str | Path) -> str:
    """The name of the system the controller in ``run_dir`` was trained for (its config)."""
    folder = trainer_dir(run_dir)
    name = read_config(folder).get("system")
    if not isinstance(name, str):
        raise ValueError(f"run folder: {folder / 'config.json'} names no system")
    return name


def trained_step_rules(run_dir: str | Path) -> StepRules:
    """The step rules the controller in ``run_dir`` was trained under, from its config
    (leoc's rules when the config records none).

    Raises
    ------
    ValueError
        The recorded rules are not StepRules fields (the message names the file).
    """
    from leoc.systems.base import StepRules

    folder = trainer_dir(run_dir)
    rules = read_config(folder).get("step_rules") or {}
    try:
        return StepRules(**rules)
    except TypeError as error:
        raise ValueError(
            f"run folder: {folder / 'config.json'} records step_rules {rules!r}, which are not "
            f"StepRules fields ({error})"
        ) from error


def trained_perturbations(run_dir: str | Path) -> TrainingPerturbations:
    """What the controller in ``run_dir`` was trained under: its config's
    ``training_perturbations`` (:class:`~leoc.systems.TrainingPerturbations`; nominal when the
    config records none, as every run trained on the nominal plant). Evaluations run on the
    nominal plant (:func:`trained_plant`) whatever it says; it tells them how the run was
    trained.

    Raises
    ------
    ValueError
        The record is not a valid spec (the message names the file).
    """
    from leoc.systems import TrainingPerturbations

    folder = trainer_dir(run_dir)
    record = read_config(folder).get("training_perturbations")
    try:
        return TrainingPerturbations.from_dict(record)
    except ValueError as error:
        raise ValueError(f"run folder: {folder / 'config.json'}: {error}") from error


def trained_selection_plants(run_dir: str | Path) -> str:
    """Which plants the run's model selection judged on: its config's ``selection_plants``
    (``"training"``: plants of its training distribution), ``"nominal"`` when the config
    records none (every run before the option, and every run selecting on the nominal plant)."""
    return str(read_config(trainer_dir(run_dir)).get("selection_plants", "nominal"))


def trained_under(specs: list[str]) -> dict[str, dict]:
    """Per run folder of ``specs`` (``linear`` skipped), what it was trained under
    (:func:`trained_perturbations` as a dict; empty entries for a nominal run): what
    ``leoc roa`` and ``leoc robustness`` record beside results that are all of the nominal
    plant."""
    return {str(spec): trained_perturbations(spec).as_dict() for spec in specs if spec != LINEAR}


def trained_plant(run_dir: str | Path) -> System:
    """The system the controller in ``run_dir`` was trained on, stepping under the rules it was
    trained under: the plant to evaluate it on (its reward too, so a return is the one it was
    trained for).

    Raises
    ------
    ValueError
        The config names no registered system or records unknown rules (naming the file).
    """
    from leoc.systems import make_system

    return make_system(trained_system(run_dir)).with_rules(trained_step_rules(run_dir))


def load_trained_controller(run_dir: str | Path, system: str | None = None) -> torch.nn.Module:
    """The physical-units policy (float64 observations -> actions) saved in ``run_dir``, at the
    control period it was trained at (PILCO: a :class:`~leoc.policies.HeldPolicy`).

    Parameters
    ----------
    run_dir : path
        A ``leoc train`` run folder or a ``leoc reproduce`` per-run folder.
    system : str, optional
        The system the caller will run it on; a controller trained for another system is
        refused with both names.

    Raises
    ------
    FileNotFoundError
        If ``run_dir`` holds no controller.
    ValueError
        If the controller was trained for another system, or a file cannot be read (the
        message names the file).
    """
    folder = trainer_dir(run_dir)
    trained_for = read_config(folder).get("system")
    if system is not None and trained_for != system:
        raise ValueError(
            f"controller: {str(Path(run_dir))!r} was trained for {trained_for!r}, "
            f"not for {system!r}"
        )
    learner = _learner_of(folder)
    assert learner is not None  # trainer_dir found its marker
    return learner.load(folder)
