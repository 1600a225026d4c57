"""Training glue: ``train_ddpg`` runs SB3's DDPG, TD3 or SAC (baseline or LEOC hybrid) on one
system.

Run folder: the trainer contract of :mod:`leoc.training` (every file written atomically)::

    config.json         DDPGConfig + seed + library versions
    model.zip           SB3 save of the final model: the run's controller (model selection:
                        the final policy, as for PILCO, by default; with
                        ``model_selection="best_last_third"`` its actor is the one of the best
                        evaluation in the last third of the updates, the authors' rule; with
                        ``"best_held"`` the one of the evaluation that held in the most
                        episodes, best return among those)
    best_model.zip      SB3 save of the model with the best evaluation mean return (kept for
                        users who want it; ``load_ddpg_controller(run, which="best")``)
    curve.json          learning curve + summary (held/reached steps, final and best returns)
    curve.csv           learning curve: steps, interaction_seconds, mean_return, std_return,
                        held_fraction
    learning_curve.png  mean return (+/- std) against interaction time in simulated seconds

"Reached" and "held": see :mod:`leoc.training`.
"""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.logger import Logger

from leoc.io import read_json_object, write_bytes_atomic, write_text_atomic
from leoc.names import ControllerName
from leoc.policies.spec import HybridSpec, legacy_hybrid_config
from leoc.sb3.callbacks import LearningCurveCallback, selection_start
from leoc.sb3.checkpoint import (
    CHECKPOINT_FILE,
    CHECKPOINT_INTERVAL_STEPS,
    CheckpointCallback,
    load_checkpoint,
)
from leoc.sb3.common import policy_of
from leoc.sb3.config import DDPGConfig
from leoc.sb3.ddpg import HybridDDPGPolicy, LeocDDPG
from leoc.sb3.noise import exploration_noise
from leoc.sb3.physical import physical_policy
from leoc.sb3.sac import HybridSACPolicy, LeocSAC, LeocSACPolicy, build_sac_model
from leoc.sb3.td3 import HybridTD3Policy, LeocTD3, LeocTD3Policy
from leoc.systems.base import System
from leoc.training import (
    CONFIG_FILE,
    CURVE_CSV,
    CURVE_JSON,
    CURVE_PNG,
    TRAINING_PLANTS_FILE,
    TrainResult,
    curve_summary,
    evaluation_starts,
    held_and_reached,
    read_config,
    run_folder,
    same_run,
    write_curve,
    write_training_plants,
)

__all__ = [
    "DDPGResult",
    "build_model",
    "held_and_reached",
    "load_ddpg_controller",
    "load_ddpg_model",
    "train_ddpg",
]

DEFAULT_RUN_ROOT = Path("runs")
MODEL_FILES = {"final": "model.zip", "best": "best_model.zip"}
#: What a run writes beside its models (:func:`leoc.training.write_curve`).
RUN_OUTPUTS = (CURVE_JSON, CURVE_CSV, CURVE_PNG, TRAINING_PLANTS_FILE)
ALGO_CLASSES = {"ddpg": LeocDDPG, "td3": LeocTD3, "sac": LeocSAC}


class PolicyClasses(NamedTuple):
    """The SB3 policy classes an algorithm's runs are built with (:func:`build_model`)."""

    baseline: type
    hybrid: type


#: Each algorithm's policy classes, given to SB3 when a saved model is loaded
#: (:func:`load_ddpg_model`).
POLICY_CLASSES = {
    "ddpg": PolicyClasses(LeocTD3Policy, HybridDDPGPolicy),
    "td3": PolicyClasses(LeocTD3Policy, HybridTD3Policy),
    "sac": PolicyClasses(LeocSACPolicy, HybridSACPolicy),
}
DDPGResult = TrainResult  # the one trainer result (leoc.training)


def save_model_atomic(model: Any, path: Path) -> None:
    """Save an SB3 ``model`` to ``path`` atomically: a crash leaves the old file or the new."""
    buffer = io.BytesIO()
    model.save(buffer)
    write_bytes_atomic(path, buffer.getvalue())


def build_model(
    config: DDPGConfig, seed: int, env: Any, hybrid_kwargs: dict[str, Any] | None = None
) -> Any:
    """The SB3 model (:class:`LeocDDPG`, :class:`LeocTD3` or :class:`~leoc.sb3.LeocSAC`) of
    ``config`` on ``env`` (a :class:`~leoc.systems.envs.LeocEnv`, possibly wrapped: its system is
    the one designed for; or any env, with the hybrid's ``hybrid_kwargs`` designed by the
    caller, :func:`~leoc.sb3.common.policy_of`)."""
    if config.algo == "sac":
        return build_sac_model(config, seed, env, hybrid_kwargs)
    # LeocTD3Policy is SB3's TD3Policy when the network options are at their defaults
    policy, policy_kwargs = policy_of(config, env, LeocTD3Policy, HybridTD3Policy, hybrid_kwargs)
    common: dict[str, Any] = {
        "learning_rate": config.critic_learning_rate,
        "actor_learning_rate": config.actor_learning_rate,
        "buffer_size": config.buffer_size,
        "learning_starts": config.learning_starts,
        "batch_size": config.batch_size,
        "tau": config.polyak,
        "gamma": config.discount,
        "train_freq": config.train_freq,
        "gradient_steps": config.gradient_steps,
        "action_noise": exploration_noise(config, env.action_space, seed),
        "target_update_interval": config.target_update_interval,
        "warmup": config.warmup,
        "critic_loss": config.critic_loss,
        "target_action_clip": config.actor_output_clip,
        "policy_kwargs": policy_kwargs,
        "seed": seed,
        "device": "cpu",
        "verbose": 0,
    }
    if config.algo == "td3":
        return LeocTD3(
            policy,
            env,
            policy_delay=config.td3_policy_delay,
            target_policy_noise=config.td3_target_noise,
            target_noise_clip=config.td3_target_noise_clip,
            **common,
        )
    return LeocDDPG(policy, env, **common)


def library_versions() -> dict[str, str]:
    """The versions of the libraries a run's ``config.json`` records."""
    import gymnasium
    import stable_baselines3

    return {
        "torch": torch.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "gymnasium": gymnasium.__version__,
        "numpy": np.__version__,
    }


def train_ddpg(
    system: str | System,
    algo: str = "ddpg",
    hybrid: bool | HybridSpec | None = None,
    seed: int = 0,
    run_dir: str | Path | None = None,
    total_steps: int | None = None,
    progress: bool | str = True,
    callbacks: Sequence[BaseCallback] = (),
    overwrite: bool = False,
    checkpoint_interval: int = CHECKPOINT_INTERVAL_STEPS,
    **overrides: Any,
) -> DDPGResult:
    """Train DDPG, TD3 or SAC (baseline MLP actor or LEOC hybrid) on ``system``; save the run.

    Parameters
    ----------
    system : str or leoc.systems.System
        A name, or the system (built once by the caller; it steps under the config's rules).
    algo : {"ddpg", "td3", "sac"}
        SAC starts from :data:`~leoc.sb3.SAC_DEFAULTS` at DDPG's budgets.
    hybrid : HybridSpec, bool or None
        The hybrid actor this :class:`~leoc.policies.HybridSpec` describes (``True``: the
        default) instead of the plain MLP (for SAC: the hybrid squashed mean).
    seed : int
        The only seed: SB3 (torch, numpy, random), the envs, the exploration noise
        (``seed + 20000``) and the evaluation starts (``seed + 10000 + k``).
    run_dir, total_steps : optional
        Default ``runs/SYSTEM/CONTROLLER/seedN`` (:func:`leoc.training.run_folder`) and the
        system's budget (:data:`~leoc.sb3.TOTAL_STEPS_BY_SYSTEM`).
    progress : bool or "lines"
        A progress bar, a plain line now and then (for logs), or nothing (False).
    callbacks : sequence of stable_baselines3.common.callbacks.BaseCallback
        Run before the learning-curve callback (at the end they see the final actor, before
        model selection); those with a ``checkpoint_state`` resume with the run.
    overwrite : bool
        A run folder of another configuration is refused (naming the settings that differ)
        unless True. The same run resumes exactly from its checkpoint (every
        ``checkpoint_interval`` steps), or, complete, is returned without training.
    **overrides
        Any :class:`DDPGConfig` or :class:`~leoc.policies.HybridSpec` field.

    Raises
    ------
    ValueError
        On an unknown ``algo`` or system, or a setting ``algo`` does not use (naming it).
    """
    name = system if isinstance(system, str) else system.name
    if total_steps is not None:
        overrides["total_steps"] = total_steps
    config = DDPGConfig.for_system(name, algo, hybrid=hybrid, **overrides)
    config_dict = {**config.as_dict(), "seed": seed}
    run_path = _run_path(config, run_dir, seed)
    resumed, done = earlier_run(run_path, config_dict, overwrite, bool(callbacks), progress)
    if done is not None:
        return done
    run = _Run(config, config_dict, seed, _plant(system, config), run_path, resumed, progress)
    return _learn(run, _start_model(run), callbacks, checkpoint_interval)


class _Run(NamedTuple):
    """One training run: its config (and as saved, with the seed), seed, plant, folder, the
    checkpoint it resumes (None: a fresh run) and how it shows progress."""

    config: DDPGConfig
    config_dict: dict[str, Any]
    seed: int
    plant: System
    run_path: Path
    resumed: Any
    progress: bool | str


def _run_path(config: DDPGConfig, run_dir: str | Path | None, seed: int) -> Path:
    """``run_dir``, or the default ``runs/SYSTEM/CONTROLLER/seedN`` of ``config``."""
    if run_dir is not None:
        return Path(run_dir)
    relevance = None if config.hybrid is None else config.hybrid.relevance
    controller = ControllerName(config.algo, relevance).name
    return run_folder(DEFAULT_RUN_ROOT, config.system, controller, seed)


def _plant(system: str | System, config: DDPGConfig) -> System:
    """The edge: the system (built here from a name, else the caller's), stepping under the
    config's rules."""
    from leoc.systems import StepRules, make_system

    plant = make_system(system) if isinstance(system, str) else system
    return plant.with_rules(StepRules(**config.step_rules))


def _episode_plants(config: DDPGConfig, plant: System, seed: int) -> Any:
    """The training episodes' plants (:class:`~leoc.systems.EpisodePlants`, from the run's
    seed) of a run trained under perturbation; None for the nominal plant."""
    from leoc.systems import EpisodePlants, TrainingPerturbations

    spec = TrainingPerturbations.from_dict(config.training_perturbations)
    return None if spec.is_nominal else EpisodePlants(spec, plant, seed)


def _selection_plants(config: DDPGConfig, plant: System, seed: int) -> list[Any] | None:
    """The perturbations of each evaluation episode model selection judges on, for a run that
    selects on its training distribution (``selection_plants="training"``); None: the
    nominal evaluation episodes."""
    from leoc.systems import TrainingPerturbations

    if config.selection_plants == "nominal":
        return None
    spec = TrainingPerturbations.from_dict(config.training_perturbations)
    draws = spec.selection_draws(plant, seed, config.eval_episodes)
    return [draw.perturbations for draw in draws]


def earlier_run(
    run_path: Path,
    config_dict: dict[str, Any],
    overwrite: bool,
    watched: bool,
    progress: bool | str,
) -> tuple[Any, DDPGResult | None]:
    """What ``run_path`` holds of this run: its checkpoint (or None), and its result when it is
    complete (a finished run is returned as it is, unless callbacks must watch it train: then
    it trains again, to the same result, runs being deterministic)."""
    algo = config_dict["algo"]
    if not same_run(run_path, config_dict, overwrite, normalise=legacy_hybrid_config):
        return None, None
    resumed = load_checkpoint(run_path / CHECKPOINT_FILE, label=algo)
    done = (
        None if resumed is not None or watched else _completed_result(run_path, config_dict, algo)
    )
    if done is not None and progress:
        print(f"[{algo}] {run_path} holds this run, complete: nothing to train", flush=True)
    return resumed, done


def _start_model(run: _Run) -> Any:
    """The model to train: the checkpoint's (``resumed``), or a fresh one, written in a
    cleared run folder with its ``config.json``."""
    from leoc.systems import make_env

    config, config_dict, seed, plant, run_path, resumed, progress = run

    algo = config.algo
    if resumed is not None:
        if progress:
            print(
                f"[{algo}] resuming {run_path} from its checkpoint at step {resumed['steps']}",
                flush=True,
            )
        return resumed["model"]
    env = make_env(plant, plants=_episode_plants(config, plant, seed))
    model = build_model(config, seed, env)  # may refuse the config: nothing written
    run_path.mkdir(parents=True, exist_ok=True)
    # a fresh run (new, or replacing another with --overwrite) keeps nothing of an earlier
    # one: an old controller beside the new config would read as this run, complete
    for stale in (CHECKPOINT_FILE, *MODEL_FILES.values(), *RUN_OUTPUTS):
        (run_path / stale).unlink(missing_ok=True)
    write_text_atomic(
        run_path / CONFIG_FILE,
        json.dumps({**config_dict, "versions": library_versions()}, indent=2),
    )
    return model


def _learn(
    run: _Run, model: Any, callbacks: Sequence[BaseCallback], checkpoint_interval: int
) -> DDPGResult:
    """Train ``model`` to ``config.total_steps`` with the learning-curve and checkpoint
    callbacks, then save the controller and the curve (the run is complete)."""
    config, config_dict, seed, plant, run_path, resumed, progress = run
    algo = config.algo
    env = model.get_env() if resumed is not None else model.env
    # SB3 would otherwise create an SB3-<date> folder in the system temp folder for its logger
    model.set_logger(Logger(folder=None, output_formats=[]))
    callback = LearningCurveCallback(
        plant,
        evaluation_starts(plant, seed, config.eval_episodes),
        config.eval_interval,
        save_best=lambda m: save_model_atomic(m, run_path / MODEL_FILES["best"]),
        progress=progress,
        total_steps=config.total_steps,
        model_selection=config.model_selection,
        selection_start=selection_start(
            config.model_selection, config.total_steps, config.learning_starts
        ),
        label=algo,
        selection_plants=_selection_plants(config, plant, seed),
    )
    checkpoint_path = run_path / CHECKPOINT_FILE
    checkpoint = CheckpointCallback(
        checkpoint_path, checkpoint_interval, (*callbacks, callback), resumed
    )
    checkpoint.restore_callbacks()
    model.learn(
        total_timesteps=config.total_steps - model.num_timesteps,
        callback=CallbackList([checkpoint, *callbacks, callback]),
        reset_num_timesteps=resumed is None,
    )
    save_model_atomic(model, run_path / MODEL_FILES["final"])
    plants = getattr(env.envs[0].unwrapped, "plants", None)  # None: nominal, or an older env
    if plants is not None:
        write_training_plants(run_path, plants)
    env.close()
    summary = {
        **curve_summary(callback.curve, plant.dt),
        "model_selection": config.model_selection,
        "selected_steps": callback.selected_steps,
    }
    kind = "hybrid" if config.hybrid else "baseline"
    title = f"{config.system} {algo.upper()} {kind} (seed {seed})"
    write_curve(run_path, callback.curve, summary, title)
    checkpoint_path.unlink(missing_ok=True)  # the run is complete: model.zip and curve.json
    return TrainResult(
        physical_policy(model.actor), run_path, callback.curve, config_dict, summary, model
    )


def _completed_result(run_path: Path, config_dict: dict[str, Any], algo: str) -> DDPGResult | None:
    """The result of the finished run in ``run_path`` (a rerun of the same command), or None
    when it did not finish (no controller or no curve; a damaged curve is set aside)."""
    if not (run_path / MODEL_FILES["final"]).is_file():
        return None
    saved = read_json_object(
        run_path / CURVE_JSON, lambda line: print(f"[{algo}] {line}", flush=True), "curve"
    )
    if saved is None or "curve" not in saved or "summary" not in saved:
        return None
    model = load_ddpg_model(run_path)
    return TrainResult(
        physical_policy(model.actor), run_path, saved["curve"], config_dict, saved["summary"], model
    )


def load_ddpg_model(run_dir: str | Path, which: str = "final") -> Any:
    """Load the SB3 model of a run folder (``which``: ``"final"``, the run's controller, or
    ``"best"``), on the CPU."""
    if which not in MODEL_FILES:
        raise ValueError(f"which: expected one of {tuple(MODEL_FILES)}, found {which!r}")
    run_path = Path(run_dir)
    config = read_config(run_path)
    algo_class = ALGO_CLASSES.get(config.get("algo", "ddpg"), LeocDDPG)
    path = run_path / MODEL_FILES[which]
    if not path.is_file():
        raise FileNotFoundError(f"controller: {path} is missing")
    try:
        return _load_zip(algo_class, path, _policy_class(config))
    except Exception as error:  # a truncated or garbled zip: name it
        raise ValueError(
            f"controller: {path} could not be read as an SB3 model "
            f"({type(error).__name__}: {error})"
        ) from error


def _policy_class(config: dict[str, Any]) -> type:
    """The policy class of a run's models, read from its saved ``config`` (``algo``; ``hybrid``:
    a spec dict or None, or a bool in configs saved before :class:`~leoc.policies.HybridSpec`)."""
    classes = POLICY_CLASSES.get(config.get("algo", "ddpg"), POLICY_CLASSES["ddpg"])
    hybrid = legacy_hybrid_config(config).get("hybrid") is not None
    return classes.hybrid if hybrid else classes.baseline


def _load_zip(algo_class: Any, path: Path, policy_class: type) -> Any:
    """SB3's ``load`` of ``path``, its policy class given rather than unpickled.

    A zip names its policy class and its exploration noise by module path; those of a model
    saved before ``leoc.ddpg`` became :mod:`leoc.sb3` name a module that is gone. The policy
    class comes from the run's config; such a model's exploration noise, not needed to act, is
    left out (``action_noise`` None: set one before training it further).
    """
    objects: dict[str, Any] = {"policy_class": policy_class}
    try:
        return algo_class.load(path, device="cpu", custom_objects=objects)
    except ModuleNotFoundError:
        objects["action_noise"] = None
        return algo_class.load(path, device="cpu", custom_objects=objects)


def load_ddpg_controller(run_dir: str | Path, which: str = "final") -> torch.nn.Module:
    """float64 physical-units policy of a run folder (the final model by default: the run's
    controller, see :mod:`leoc.training`).

    Returns
    -------
    PhysicalPolicy
        Maps float64 observations (B, O) to physical actions (B, 1); for a hybrid run
        ``pi(a) = G(a)`` and ``d pi / dx (a) = W``.
    """
    return physical_policy(load_ddpg_model(run_dir, which).actor)
