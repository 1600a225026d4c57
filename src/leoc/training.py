"""One trainer contract for PILCO and DDPG/TD3: evaluation episodes, learning curve, result,
run folder.

Both trainers (:func:`leoc.pilco.train_pilco`, :func:`leoc.sb3.train_ddpg`) evaluate their
current controller the same way, return the same :class:`TrainResult` and write the same files.

Evaluation. After every iteration (PILCO) or every ``eval_interval`` environment steps
(DDPG/TD3), the deterministic controller runs ``eval_episodes`` full episodes from the swing-up
start distribution, at its own control period, from the fixed starts
``System.sample_start(default_rng(seed + 10000 + k))`` (the same starts at every evaluation, so
points are comparable; the same starts the gymnasium env gives for ``reset(seed=seed + 10000 +
k)``). Evaluation episodes are not interaction: they do not count in the interaction time.

Hold test: :meth:`leoc.systems.System.hold_step` (the system's band and minimum duration, the
episode must not terminate). ``reached_steps``: the first evaluation at which every episode
holds; ``held_steps``: the first evaluation from which every later evaluation holds too.

Model selection: each trainer records the rule that chose the run's controller in its curve
summary (``model_selection``): ``MODEL_SELECTION`` (``"final"``, the policy at the end of
the training budget) unless the trainer selects otherwise: DDPG/TD3/SAC by their config's
``model_selection`` (leoc's default ``"best_held"``, :mod:`leoc.sb3.callbacks`), PILCO by
``select_best_from``. A rule other than ``"final"`` selects on the evaluation episodes, and the
report says so from what the runs recorded.

Run folder (every file written atomically)::

    config.json          the trainer's configuration (+ seed, library versions)
    curve.json           {"curve": [rows], "summary": {...}}, rows with CURVE_COLUMNS plus the
                         per-episode "returns" and "hold_steps"
    curve.csv            the rows, CURVE_COLUMNS only
    learning_curve.png   mean return (+/- std) against interaction time
    controller file      PILCO ``controller.pt``, DDPG/TD3 ``model.zip`` (loaded with its
                         control period by ``experiments.controllers.load_trained_controller``)
    training_plants.json a run trained under perturbation only (its config's
                         ``training_perturbations``): the levels of every training episode
                         begun, in order (:func:`write_training_plants`)
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from leoc.io import save_figure_atomic, write_csv_atomic, write_json_atomic
from leoc.systems.base import System
from leoc.systems.rollout import Controller, simulate, simulate_settings

EVAL_SEED_OFFSET = 10_000
CONFIG_FILE = "config.json"
CURVE_JSON = "curve.json"
CURVE_CSV = "curve.csv"
CURVE_PNG = "learning_curve.png"
TRAINING_PLANTS_FILE = "training_plants.json"
#: Columns of every learning-curve row (``curve.csv``).
CURVE_COLUMNS = ("steps", "interaction_seconds", "mean_return", "std_return", "held_fraction")
MODEL_SELECTION = "final"


class Evaluation(NamedTuple):
    """Deterministic episodes of one controller (see the module docstring)."""

    mean_return: float
    std_return: float
    returns: list[float]
    hold_steps: list[int | None]  # per episode; None if it did not hold

    @property
    def held(self) -> list[bool]:
        return [step is not None for step in self.hold_steps]

    @property
    def held_fraction(self) -> float:
        return float(np.mean(self.held)) if self.hold_steps else 0.0


def evaluation_starts(system: System, seed: int, episodes: int) -> np.ndarray:
    """``(episodes, S)`` swing-up starts of the evaluation episodes of a run seeded ``seed``."""
    return np.stack(
        [
            system.sample_start(np.random.default_rng(seed + EVAL_SEED_OFFSET + k), "swing_up")
            for k in range(episodes)
        ]
    )


def evaluate_episodes(system: System, controller: Controller, starts: np.ndarray) -> Evaluation:
    """Run ``controller`` (at its own period) from every start at once; returns and holds."""
    batch = simulate(system, controller, starts)
    hold_steps = [
        system.hold_step(batch.states[i, 1:], terminated=bool(batch.terminated[i]))
        for i in range(len(starts))
    ]
    returns = batch.total_rewards
    return Evaluation(float(returns.mean()), float(returns.std()), returns.tolist(), hold_steps)


def evaluate_on_plants(
    system: System, controller: Controller, starts: np.ndarray, plants: Sequence[Sequence[Any]]
) -> Evaluation:
    """:func:`evaluate_episodes` with episode ``i`` on its own perturbed plant: ``plants[i]``,
    a sequence of :class:`~leoc.systems.perturbations.Perturbation` (every episode at once,
    :func:`~leoc.systems.rollout.simulate_settings`)."""
    if len(plants) != len(starts):
        raise ValueError(f"plants: expected one per start ({len(starts)}), found {len(plants)}")
    settings = [(starts[i : i + 1], tuple(plant)) for i, plant in enumerate(plants)]
    batches = simulate_settings(system, controller, settings)
    hold_steps = [
        system.hold_step(batch.states[0, 1:], terminated=bool(batch.terminated[0]))
        for batch in batches
    ]
    returns = np.array([float(batch.total_rewards[0]) for batch in batches])
    return Evaluation(float(returns.mean()), float(returns.std()), returns.tolist(), hold_steps)


def curve_row(steps: int, dt: float, evaluation: Evaluation) -> dict[str, Any]:
    """One learning-curve row after ``steps`` simulator steps of interaction."""
    return {
        "steps": int(steps),
        "interaction_seconds": steps * dt,
        "mean_return": evaluation.mean_return,
        "std_return": evaluation.std_return,
        "held_fraction": evaluation.held_fraction,
        "returns": evaluation.returns,
        "hold_steps": evaluation.hold_steps,
    }


def held_and_reached(curve: Sequence[dict[str, Any]]) -> tuple[int | None, int | None]:
    """``(held_steps, reached_steps)`` of a learning curve (see the module docstring)."""
    reached = next((row["steps"] for row in curve if row["held_fraction"] >= 1.0), None)
    held = None
    for row in reversed(curve):
        if row["held_fraction"] < 1.0:
            break
        held = row["steps"]
    return held, reached


def curve_summary(curve: Sequence[dict[str, Any]], dt: float) -> dict[str, Any]:
    """Held/reached steps and seconds, final and best evaluation returns, selection rule."""
    held, reached = held_and_reached(curve)
    return {
        "held_steps": held,
        "held_seconds": None if held is None else held * dt,
        "reached_steps": reached,
        "reached_seconds": None if reached is None else reached * dt,
        "final_return": float(curve[-1]["mean_return"]),
        "best_return": float(max(row["mean_return"] for row in curve)),
        "dt": dt,
        "model_selection": MODEL_SELECTION,
    }


class TrainResult(NamedTuple):
    """What both trainers return.

    Attributes
    ----------
    policy : torch.nn.Module
        The final controller in physical units (float64 observations -> actions), carrying its
        control period (``action_repeat``).
    run_dir : Path
    curve : list of dict
        Learning-curve rows (:data:`CURVE_COLUMNS`, ``returns``, ``hold_steps``).
    config : dict
        The run's configuration.
    summary : dict
        :func:`curve_summary` of the curve.
    model : object
        The framework's own model (SB3 algorithm; PILCO's GP posterior).
    """

    policy: torch.nn.Module
    run_dir: Path
    curve: list[dict[str, Any]]
    config: dict[str, Any]
    summary: dict[str, Any]
    model: Any

    @property
    def held_steps(self) -> int | None:
        """Interaction steps until the first evaluation that held in every episode (None: never)."""
        return self.summary["held_steps"]

    @property
    def reached_steps(self) -> int | None:
        """Interaction steps until the first evaluation that reached the operating point (None:
        never)."""
        return self.summary["reached_steps"]

    @property
    def final_return(self) -> float:
        """Mean return of the last evaluation."""
        return self.summary["final_return"]

    @property
    def best_return(self) -> float:
        """Best mean return over the evaluations."""
        return self.summary["best_return"]


def plot_curve(curve: Sequence[dict[str, Any]], title: str, path: Path) -> None:
    """Mean evaluation return (+/- std) against interaction time, holds starred (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seconds = np.array([row["interaction_seconds"] for row in curve])
    mean = np.array([row["mean_return"] for row in curve])
    std = np.array([row["std_return"] for row in curve])
    figure, axis = plt.subplots(figsize=(6.0, 4.0))
    axis.plot(seconds, mean, marker="o", label="mean evaluation return")
    axis.fill_between(seconds, mean - std, mean + std, alpha=0.25, label="+/- std")
    held = [row for row in curve if row["held_fraction"] >= 1.0]
    if held:
        axis.plot(
            [row["interaction_seconds"] for row in held],
            [row["mean_return"] for row in held],
            "g*",
            markersize=12,
            label="every episode held the operating point",
        )
    axis.set_xlabel("interaction time [simulated s]")
    axis.set_ylabel("evaluation return")
    axis.set_title(title)
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize="small", loc="best")
    save_figure_atomic(figure, path)


def write_curve(
    run_dir: Path, curve: Sequence[dict[str, Any]], summary: dict[str, Any], title: str
) -> None:
    """``curve.json``, ``curve.csv`` and ``learning_curve.png`` of a run folder."""
    write_json_atomic(run_dir / CURVE_JSON, {"curve": list(curve), "summary": summary}, indent=2)
    write_csv_atomic(run_dir / CURVE_CSV, curve, CURVE_COLUMNS)
    plot_curve(curve, title, run_dir / CURVE_PNG)


def write_training_plants(run_dir: Path, plants: Any) -> None:
    """``training_plants.json`` of a run trained under perturbation: its
    ``training_perturbations``, seed and the levels of each training episode begun
    (``plants``: the run's :class:`~leoc.systems.EpisodePlants`)."""
    record = {
        "training_perturbations": plants.spec.as_dict(),
        "seed": plants.seed,
        "episodes": plants.levels(),
    }
    write_json_atomic(Path(run_dir) / TRAINING_PLANTS_FILE, record, indent=2)


def run_folder(root: str | Path, system: str, controller: str, seed: int) -> Path:
    """``ROOT/SYSTEM/CONTROLLER/seedN``: the one naming scheme of run folders (``leoc train``'s
    under ``runs/``, ``leoc reproduce``'s under ``OUT/runs/``), CONTROLLER a controller name
    (:func:`leoc.names.parse_controller`: ``ddpg_hybrid_roa``, ``pilco_baseline``)."""
    return Path(root) / system / controller / f"seed{seed}"


def read_config(run_dir: Path) -> dict[str, Any]:
    """``config.json`` of a run folder, with errors that name the file."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"run folder: {path} is missing (expected the run's config)")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"run folder: {path} is not valid JSON ({error})") from error
    if not isinstance(data, dict):
        raise ValueError(f"run folder: {path}: expected a JSON object, found {type(data).__name__}")
    return data


#: Keys of ``config.json`` that describe the machine a run was trained on, not the run: a rerun
#: on another machine is the same run.
MACHINE_KEYS = ("versions",)


def config_differences(saved: dict[str, Any], config: dict[str, Any]) -> list[str]:
    """``"key: A there, B here"`` for each setting where ``saved`` and ``config`` differ."""
    keys = sorted((set(saved) | set(config)) - set(MACHINE_KEYS))
    return [
        f"{key}: {saved.get(key)!r} there, {config.get(key)!r} here"
        for key in keys
        if saved.get(key) != config.get(key)
    ]


def same_run(
    run_dir: str | Path,
    config: dict[str, Any],
    overwrite: bool = False,
    normalise: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
) -> bool:
    """Whether ``run_dir`` already holds a run of ``config`` (so a trainer resumes or reuses
    it), the one rule of a rerun for every learner.

    A folder without ``config.json`` is new (False). One whose config equals ``config`` (both
    as JSON; library versions aside) holds the same run (True). One with another config is
    refused, unless ``overwrite``, in which case it is treated as new (False) and the trainer
    replaces its files. ``normalise`` maps a saved config to today's form before the
    comparison (a learner whose config layout changed reads its older runs as the same run).

    Raises
    ------
    ValueError
        ``run_dir`` holds a run of another configuration and ``overwrite`` is False (naming the
        folder and the first differing settings).
    """
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        return False
    saved = read_config(Path(run_dir))
    if normalise is not None:
        saved = normalise(saved)
    differences = config_differences(saved, json.loads(json.dumps(config)))
    if not differences:
        return True
    if overwrite:
        return False
    shown = "; ".join(differences[:3]) + (
        f"; and {len(differences) - 3} more" if len(differences) > 3 else ""
    )
    raise ValueError(
        f"run folder: {str(run_dir)!r} holds a run of another configuration ({shown}); pass "
        "--overwrite (overwrite=True) to replace it, or choose another folder (--out)"
    )
