"""PILCO training loop for the RBF baseline and the LEOC hybrid (Deisenroth & Rasmussen 2011).

Loop: ``initial_rollouts`` random rollouts; then, each iteration, fit the GP dynamics model ->
optimise the policy by L-BFGS on the predicted horizon cost (autograd through the whole
horizon) -> run the policy on the real system for one episode -> add its data.

Timing choice (documented in :mod:`leoc.pilco.rollout`): the policy decides every
``action_repeat`` simulator steps and holds its action (zero-order hold), the GP models that
``action_repeat``-step map, and the horizon is ``horizon`` decisions. The controller keeps that
period wherever it runs: it is returned, saved and loaded as a
:class:`~leoc.policies.HeldPolicy`, and the LQR part of the hybrid is designed by discrete LQR
on the ``action_repeat``-step held map, so pi(a) = G(a) and dpi/dx(a) = W hold for the closed
loop actually run. ``deploy_action_repeat`` (the authors' choice: 1) evaluates, returns and saves
it at another period instead.

Training under perturbation (``training_perturbations``): each real rollout ``k`` (counted
from 0, the random rollouts first) runs on episode ``k``'s plant of
:class:`~leoc.systems.TrainingPerturbations` (the run's seed), so the data come from the
perturbed plant; the GP model, the policy optimisation and the evaluation episodes are not
perturbed. The plant depends on the seed and ``k`` only, so a resumed or extended run meets the
plants the uninterrupted run would have.

Model selection: the final policy (:mod:`leoc.training`), or with ``select_best_from = k`` the
best-evaluated policy of iterations >= k (the authors' rule), written as ``controller.pt`` and
returned at the end; the checkpoint keeps the latest policy, so a resumed run goes on from it.

Learning curve and run folder: the trainer contract of :mod:`leoc.training` (evaluation
episodes from fixed starts after every iteration, ``config.json``, ``curve.json``/``curve.csv``
with PILCO's own columns added, ``learning_curve.png``), plus ``controller.pt`` (policy state +
GP model + config) and ``checkpoint.pt`` (everything needed to resume, written atomically).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn

from leoc.io import write_text_atomic
from leoc.names import ControllerName
from leoc.pilco.checkpoint import (
    BestPolicy,
    RunState,
    load_pilco_controller,
    resume_checkpoint,
    save_checkpoint,
    save_controller,
)
from leoc.pilco.config import PilcoConfig
from leoc.pilco.cost import saturating_cost
from leoc.pilco.gp import GPPosterior, fit_gp
from leoc.pilco.objective import PolicyOptimisation, cost_spec, optimise_policy
from leoc.pilco.policy import build_policy, redraw_rbf
from leoc.pilco.rollout import Rollout, hold_start, run_rollout
from leoc.policies import HeldPolicy
from leoc.policies.spec import HybridSpec
from leoc.progress import ProgressLine, evaluation_text, iterations_line
from leoc.systems import EpisodePlants, TrainingPerturbations
from leoc.systems.base import System
from leoc.systems.perturbations import Perturbation
from leoc.systems.rollout import RandomController
from leoc.training import (
    CONFIG_FILE,
    TrainResult,
    curve_row,
    curve_summary,
    evaluate_episodes,
    evaluation_starts,
    run_folder,
    write_curve,
    write_training_plants,
)

__all__ = ["PilcoResult", "load_pilco_controller", "train_pilco"]

DEFAULT_RUN_ROOT = Path("runs")
PilcoResult = TrainResult  # the one trainer result (leoc.training)


def _log_row(
    iteration: int,
    steps: int,
    system: System,
    evaluation_of: Any,
    rollouts: list[Rollout],
    optimisation: PolicyOptimisation | None,
    data_size: int,
    wall: float,
    sparse: bool,
) -> dict[str, Any]:
    """The learning-curve row of an iteration (leoc.training) plus PILCO's own columns."""
    row = curve_row(steps, system.dt, evaluation_of)
    row.update(
        iteration=iteration,
        rollout_return=float(np.mean([r.total_return for r in rollouts])),
        rollout_hold_step=hold_start(system, rollouts[-1]),
        predicted_cost=None if optimisation is None else optimisation.cost,
        lbfgs_iterations=None if optimisation is None else optimisation.iterations,
        lbfgs_evaluations=None if optimisation is None else optimisation.evaluations,
        lbfgs_restarts=None if optimisation is None else optimisation.restarts,
        data_size=data_size,
        wall_seconds=wall,
        gp_sparse=sparse,
    )
    return row


def _diagnostics(
    optimisation: PolicyOptimisation,
    model: GPPosterior,
    policy: nn.Module,
    realised_cost: float,
) -> dict[str, Any]:
    """What an iteration's curve row records to tell why a run fails (docs/user_guide/pilco.md,
    "Why a run fails"): the policy optimisation's start and gradients, the cost the training
    rollout realised (:func:`_realised_cost`), the GP's hyperparameters and the relevance's
    widths."""
    hyper = model.hyper
    return {
        "realised_cost": realised_cost,
        "predicted_cost_start": _plain_number(optimisation.start_cost),
        "gradient_norm_start": _plain_number(optimisation.start_gradient_norm),
        "gradient_norm_best": _plain_number(optimisation.best_gradient_norm),
        "failed_evaluations": optimisation.failed_evaluations,
        "gp_log_lengthscales": hyper.log_lengthscales.tolist(),
        "gp_log_signal": hyper.log_signal.tolist(),
        "gp_log_noise": hyper.log_noise.tolist(),
        **_relevance_widths(policy),
    }


def _realised_cost(system: System, config: PilcoConfig, rollout: Rollout) -> float:
    """The horizon cost a real episode incurred, in the units of PILCO's predicted cost: the
    saturating cost (:func:`leoc.pilco.objective.cost_spec`) of the observations at decisions
    ``1..H`` (``H = config.horizon``, a decision every ``config.action_repeat`` steps), each
    decision the episode did not reach (it ended first) counted at the cost's maximum, 1."""
    spec = cost_spec(system, config.cost_width, config.cost_weights)
    observations = rollout.trajectory.observations[:: config.action_repeat][1:]
    reached = torch.as_tensor(observations[: config.horizon], dtype=spec.target.dtype)
    costs = saturating_cost(reached, spec.target, spec.factor)
    return float(costs.sum()) + float(config.horizon - len(reached))


def _plain_number(value: float) -> float | None:
    """``value``, or None where it is not finite (JSON has no inf or NaN)."""
    return float(value) if math.isfinite(value) else None


def _relevance_widths(policy: nn.Module) -> dict[str, list[float]]:
    """The hybrid's relevance widths: ``relevance_lambda`` (the paper's Lambda, per
    observation entry) or ``relevance_width`` (the ROA relevance's); none for a baseline."""
    for module in policy.modules():
        if hasattr(module, "lambda_"):
            return {"relevance_lambda": module.lambda_.detach().reshape(-1).tolist()}
        if hasattr(module, "width") and hasattr(module, "lyapunov"):
            return {"relevance_width": module.width.detach().reshape(-1).tolist()}
    return {}


def _rollout_plant(system: System, config: PilcoConfig, index: int) -> tuple[Perturbation, ...]:
    """The perturbations of real rollout ``index`` (module docstring); none for a run on the
    nominal plant."""
    spec = TrainingPerturbations.from_dict(config.training_perturbations)
    if spec.is_nominal:
        return ()
    return spec.episode(system, config.seed, index, config.action_repeat).perturbations


def _random_rollouts(
    system: System, config: PilcoConfig, rng: np.random.Generator
) -> tuple[list[Rollout], float]:
    """The random rollouts of iteration 0 (real rollouts 0, 1, ...) and their wall time."""
    start_time = time.perf_counter()
    controller = RandomController(system, rng, config.action_repeat)
    rollouts = [
        run_rollout(
            system,
            controller,
            system.sample_start(rng, "swing_up"),
            config.training_rollout_steps,
            config.action_repeat,
            _rollout_plant(system, config, index),
        )
        for index in range(config.initial_rollouts)
    ]
    return rollouts, time.perf_counter() - start_time


def _progress_line(log: list[dict[str, Any]], total: int) -> str:
    """``[pilco] iter K/N, S s/iter so far, ETA T, last evaluation: ...``: the ETA is the mean
    wall time of the iterations so far (iteration 0, the random rollouts, apart) times the
    iterations left; PILCO's iterations do not cost alike (7-40 s in one quick-profile run), so
    it is rough early on. The predicted cost, rollout return and data size of each iteration
    are in the run's ``curve.json``."""
    row = log[-1]
    walls = [entry["wall_seconds"] for entry in log if entry["iteration"] > 0]
    per_iteration = sum(walls) / len(walls) if walls else None
    evaluation = evaluation_text(row["mean_return"], row["held_fraction"])
    return iterations_line("pilco", row["iteration"], total, per_iteration, evaluation)


def _show_progress(log: list[dict[str, Any]], total: int) -> ProgressLine:
    """The run's progress (``leoc.progress``), showing where it starts (or resumes)."""
    shown = ProgressLine(total, "iter", "pilco", initial=log[-1]["iteration"])
    _update_progress(shown, log, total)
    return shown


def _update_progress(shown: ProgressLine, log: list[dict[str, Any]], total: int) -> None:
    row = log[-1]
    evaluation = evaluation_text(row["mean_return"], row["held_fraction"])
    shown.update(row["iteration"], _progress_line(log, total), evaluation, force=True)


def _evaluate(system: System, config: PilcoConfig, policy: nn.Module, starts: np.ndarray) -> Any:
    """The policy's evaluation episodes, at its control period (leoc.training)."""
    return evaluate_episodes(system, HeldPolicy(policy, config.controller_action_repeat), starts)


def _first_state(
    system: System,
    config: PilcoConfig,
    rng: np.random.Generator,
    generator: torch.Generator,
    starts: np.ndarray,
) -> tuple[RunState, nn.Module]:
    """Iteration 0: random rollouts, the initial policy built from their data, its evaluation."""
    rollouts, wall = _random_rollouts(system, config, rng)
    inputs = np.concatenate([r.inputs for r in rollouts])
    targets = np.concatenate([r.targets for r in rollouts])
    policy = build_policy(system, config, generator, inputs[:, : system.obs_dim])
    steps = sum(r.steps for r in rollouts)
    evaluation = _evaluate(system, config, policy, starts)
    row = _log_row(0, steps, system, evaluation, rollouts, None, len(inputs), wall, False)
    state = RunState(0, inputs, targets, steps, [row], rng.bit_generator.state, None)
    return state, policy


def _restart_policy(
    best: PolicyOptimisation,
    policy: nn.Module,
    model: GPPosterior,
    system: System,
    config: PilcoConfig,
    generator: torch.Generator,
    observations: np.ndarray,
) -> PolicyOptimisation:
    """One policy-optimisation restart from a freshly drawn RBF part: keep whichever of it and
    ``best`` (the policy's current parameters) predicts the lower cost. The figures returned
    add up both optimisations."""
    kept = {k: v.detach().clone() for k, v in policy.state_dict().items()}
    redraw_rbf(policy, system, config, generator, observations)
    fresh = optimise_policy(policy, model, system, config)
    kept_one = fresh if fresh.cost < best.cost else best  # a NaN cost never wins
    if kept_one is best:
        policy.load_state_dict(kept)
    return PolicyOptimisation(
        kept_one.cost,
        best.iterations + fresh.iterations,
        best.evaluations + fresh.evaluations,
        best.restarts + fresh.restarts + 1,
        best.start_cost,
        best.start_gradient_norm,
        kept_one.best_gradient_norm,
        best.failed_evaluations + fresh.failed_evaluations,
    )


def _iterate(
    system: System,
    config: PilcoConfig,
    state: RunState,
    policy: nn.Module,
    rng: np.random.Generator,
    generator: torch.Generator,
    starts: np.ndarray,
) -> tuple[RunState, GPPosterior]:
    """One PILCO iteration: fit GP, optimise policy, run it, add its data, evaluate it."""
    start_time = time.perf_counter()
    model = fit_gp(state.inputs, state.targets, config.gp, rng, init=state.hyper)
    optimisation = optimise_policy(policy, model, system, config)
    restarts = config.policy_restarts
    if state.iteration < len(restarts) and restarts[state.iteration] > 0:
        observations = state.inputs[:, : system.obs_dim]
        for _ in range(restarts[state.iteration]):
            optimisation = _restart_policy(
                optimisation, policy, model, system, config, generator, observations
            )
    rollout = run_rollout(
        system,
        HeldPolicy(policy, config.action_repeat),
        system.sample_start(rng, "swing_up"),
        config.training_rollout_steps,
        config.action_repeat,
        _rollout_plant(system, config, config.initial_rollouts + state.iteration),
    )
    steps = state.interaction_steps + rollout.steps
    inputs = np.concatenate([state.inputs, rollout.inputs])
    targets = np.concatenate([state.targets, rollout.targets])
    evaluation = _evaluate(system, config, policy, starts)
    row = _log_row(
        state.iteration + 1,
        steps,
        system,
        evaluation,
        [rollout],
        optimisation,
        len(inputs),
        time.perf_counter() - start_time,
        model.sparse,
    )
    realised = _realised_cost(system, config, rollout)
    row.update(_diagnostics(optimisation, model, policy, realised))
    new_state = RunState(
        state.iteration + 1,
        inputs,
        targets,
        steps,
        [*state.log, row],
        rng.bit_generator.state,
        model.hyper,
    )
    return new_state, model


def _best_policy(
    config: PilcoConfig, state: RunState, policy: nn.Module, kept: BestPolicy | None
) -> BestPolicy | None:
    """The policy kept so far (``kept``), replaced by the iteration just run (``state``) if it
    is eligible (``PilcoConfig.select_best_from``) and its mean evaluation return is higher."""
    if config.select_best_from < 1 or state.iteration < config.select_best_from:
        return kept
    mean_return = float(state.log[-1]["mean_return"])
    if kept is not None and not mean_return > kept.mean_return:
        return kept
    parameters = {k: v.detach().clone() for k, v in policy.state_dict().items()}
    return BestPolicy(state.iteration, mean_return, parameters)


def held_long_enough(log: list[dict[str, Any]], count: int) -> bool:
    """Whether the last ``count`` (> 0) iterations' evaluations held the operating point in
    every episode: the early stop of ``stop_after_held`` and a learnt run's test."""
    recent = log[-count:] if count > 0 else []
    return len(recent) == count > 0 and all(row["held_fraction"] >= 1.0 for row in recent)


def _title(config: PilcoConfig) -> str:
    kind = "hybrid" if config.hybrid else "RBF"
    return f"PILCO {kind}, {config.system} (seed {config.seed})"


def train_pilco(
    system: str | System,
    hybrid: bool | HybridSpec | None = None,
    seed: int = 0,
    run_dir: str | Path | None = None,
    iterations: int | None = None,
    resume: bool = True,
    progress: bool = True,
    **overrides: Any,
) -> TrainResult:
    """Train a PILCO controller (RBF baseline or LEOC hybrid) on ``system``.

    Parameters
    ----------
    system : str or leoc.systems.System
        A registered system name (``leoc.systems.system_names()``), or the system itself
        (built once by the caller; it steps under the config's ``step_rules``).
    hybrid : HybridSpec, bool or None
        The hybrid RBF + LQR policy this :class:`~leoc.policies.HybridSpec` describes
        (``True``: the default spec) instead of the RBF baseline (None).
    seed : int
        The one seed of the run (numpy and torch generators, evaluation starts).
    run_dir : path, optional
        Run folder; default ``runs/SYSTEM/CONTROLLER/seedN`` (:func:`leoc.training.run_folder`,
        CONTROLLER e.g. ``pilco_hybrid``).
    iterations : int, optional
        Policy-learning iterations (default: the config's).
    resume : bool
        Continue from ``run_dir/checkpoint.pt`` if present (same configuration required).
    progress : bool
        Show the progress (``leoc.progress``): a live bar on a terminal, one line per
        iteration elsewhere, each with an ETA from the mean time per iteration so far.
    **overrides
        Any :class:`PilcoConfig` field (``horizon=...``, ``gp_<field>=...``) or
        :class:`~leoc.policies.HybridSpec` field (changing ``hybrid``).

    Returns
    -------
    TrainResult
        The run's controller (the final policy, or the ``select_best_from`` one) as a
        :class:`~leoc.policies.HeldPolicy` at ``controller_action_repeat``, the learning curve
        (one row per iteration, iteration 0 = the random rollouts), the config, its summary and
        the last GP posterior.
    """
    name = system if isinstance(system, str) else system.name
    if iterations is not None:
        overrides["iterations"] = iterations
    config = PilcoConfig.for_system(name, hybrid=hybrid, seed=seed, **overrides)
    if config.num_threads is not None:
        torch.set_num_threads(config.num_threads)
    relevance = None if config.hybrid is None else config.hybrid.relevance
    controller = ControllerName("pilco", relevance).name
    run_path = Path(run_dir or run_folder(DEFAULT_RUN_ROOT, name, controller, seed))
    plant = config.plant(None if isinstance(system, str) else system)
    run = _start_run(plant, config, run_path, resume)
    state, model = _learn(plant, config, run_path, run, progress)
    return _finish(plant, config, run_path, run.policy, state, model)


def _finish(
    plant: System,
    config: PilcoConfig,
    run_path: Path,
    policy: nn.Module,
    state: RunState,
    model: GPPosterior | None,
) -> TrainResult:
    """The run's controller (the selected iteration's policy when ``select_best_from`` chose
    one, saved as the controller) and its curve, written."""
    summary = curve_summary(state.log, plant.dt)
    if state.best is not None:
        policy.load_state_dict(state.best.policy_state)
        save_controller(run_path, config, state.best.policy_state, model)
        summary["model_selection"] = (
            f"best evaluation of iterations >= {config.select_best_from} "
            f"(iteration {state.best.iteration})"
        )
    write_curve(run_path, state.log, summary, _title(config))
    spec = TrainingPerturbations.from_dict(config.training_perturbations)
    if not spec.is_nominal:
        plants = EpisodePlants(spec, plant, config.seed, config.action_repeat)
        plants.episodes = config.initial_rollouts + state.iteration  # the real rollouts run
        write_training_plants(run_path, plants)
    policy.eval()
    held = HeldPolicy(policy, config.controller_action_repeat).eval()
    return TrainResult(held, run_path, state.log, config.to_dict(), summary, model)


class _Run(NamedTuple):
    """A PILCO run under way: its state and policy, the last GP model (None before the first
    iteration of this process), its random generators and evaluation starts."""

    state: RunState
    policy: nn.Module
    model: GPPosterior | None
    rng: np.random.Generator
    generator: torch.Generator
    starts: np.ndarray


def _start_run(plant: System, config: PilcoConfig, run_path: Path, resume: bool) -> _Run:
    """The run's checkpoint (``resume``), or a new run: iteration 0 done, its config and first
    checkpoint written (a rerun's config records its budget: a larger one extends the run)."""
    seed = config.seed
    rng = np.random.default_rng(seed)
    generator = torch.Generator().manual_seed(seed)
    starts = evaluation_starts(plant, seed, config.eval_episodes)
    resumed = resume_checkpoint(run_path, config, plant, generator) if resume else None
    model = None
    if resumed is None:
        state, policy = _first_state(plant, config, rng, generator, starts)
        run_path.mkdir(parents=True, exist_ok=True)  # the config was accepted: a run begins
        write_text_atomic(run_path / CONFIG_FILE, json.dumps(config.to_dict(), indent=2))
        save_checkpoint(run_path, config, state, policy, None, generator)
    else:
        state, policy, model = resumed
        rng.bit_generator.state = state.rng_state
        write_text_atomic(run_path / CONFIG_FILE, json.dumps(config.to_dict(), indent=2))
    return _Run(state, policy, model, rng, generator, starts)


def _learn(
    plant: System, config: PilcoConfig, run_path: Path, run: _Run, progress: bool
) -> tuple[RunState, GPPosterior | None]:
    """Iterate to ``config.iterations`` (or until held long enough), checkpointing and writing
    the curve after each iteration; returns the last state and GP model."""
    state, model = run.state, run.model
    shown = _show_progress(state.log, config.iterations) if progress else None
    while state.iteration < config.iterations and not held_long_enough(
        state.log, config.stop_after_held
    ):
        kept = state.best
        state, model = _iterate(
            plant, config, state, run.policy, run.rng, run.generator, run.starts
        )
        state = state._replace(best=_best_policy(config, state, run.policy, kept))
        save_checkpoint(run_path, config, state, run.policy, model, run.generator)
        write_curve(run_path, state.log, curve_summary(state.log, plant.dt), _title(config))
        if shown is not None:
            _update_progress(shown, state.log, config.iterations)
    if shown is not None:
        shown.close()
    return state, model
