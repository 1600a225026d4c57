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
loop actually run.

Learning curve and run folder: the trainer contract of :mod:`leoc.training` (evaluation
episodes from fixed starts after every iteration, ``config.json``, ``curve.json``/``curve.csv``
with PILCO's own columns added, ``learning_curve.png``), plus ``controller.pt`` (policy state +
GP model + config) and ``checkpoint.pt`` (everything needed to resume, written atomically).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn

from leoc.io import save_torch_atomic, set_aside, write_text_atomic
from leoc.pilco.gp import GPHyper, GPPosterior, GPSettings, fit_gp
from leoc.pilco.propagate import Prediction, SaturatedPolicy, predict
from leoc.pilco.rollout import Rollout, hold_start, run_rollout
from leoc.policies import HeldPolicy, HybridPolicy, LinearController, RBFNetwork, roa_hybrid
from leoc.policies.relevance import RELEVANCE_KINDS
from leoc.systems import make_system
from leoc.systems.base import DTYPE, System
from leoc.systems.rollout import RandomController
from leoc.training import (
    CONFIG_FILE,
    TrainResult,
    curve_row,
    curve_summary,
    evaluate_episodes,
    evaluation_starts,
    write_curve,
)

DEFAULT_RUN_ROOT = Path("runs")
CHECKPOINT_NAME = "checkpoint.pt"
CONTROLLER_NAME = "controller.pt"
# Initial RBF weights: standard deviation as a fraction of the actuator limit.
WEIGHT_STD_FRACTION = 0.1
# Smallest initial RBF length-scale (a constant observation column would otherwise give 0).
MIN_POLICY_LENGTHSCALE = 0.1
# Variance of a uniform distribution on [-a, a] is a^2 / 3.
UNIFORM_VARIANCE_FACTOR = 1.0 / 3.0


@dataclasses.dataclass
class PilcoConfig:
    """Settings of one PILCO run (defaults: the paper's appendix C and the original PILCO).

    Attributes
    ----------
    system : str
        ``pendulum``, ``cartpole`` or ``mountaincar``.
    hybrid : bool
        Train the LEOC hybrid (RBF + LQR) instead of the RBF baseline.
    seed : int
        Seeds the numpy and torch generators (everything random derives from it).
    iterations : int
        Policy-learning iterations after the random rollouts.
    horizon : int
        Prediction horizon H in controller decisions.
    action_repeat : int
        Simulator steps each action is held (the GP models this multi-step map).
    episode_steps : int
        Simulator steps of each real rollout.
    initial_rollouts : int
        Rollouts with uniform random actions before learning.
    num_basis : int
        RBF basis functions.
    policy_iterations : int
        L-BFGS iterations of each policy optimisation.
    cost_width : float
        Width of the saturating cost (distance at which the cost is 1 - exp(-1/2)).
    eval_episodes : int
        Deterministic evaluation episodes after every iteration (:mod:`leoc.training`).
    quadrature_order : int
        Gauss-Hermite nodes per state dimension for the hybrid's moment matching.
    hybrid_method : str
        ``quadrature`` or the ``constant_relevance`` heuristic (for comparison only).
    lambda_init : float
        Initial diagonal of the hybrid's Lambda (paper: identity).
    learn_lambda : bool
        Optimise Lambda (paper relevance) or the transition width (ROA relevance) with the RBF
        parameters.
    relevance : {"paper", "roa"}
        The hybrid's relevance: the paper's r(x) = 1 / (1 + d)^2, or exactly 1 on the certified
        region of attraction of the LQR at ``action_repeat`` (:func:`leoc.policies.roa_hybrid`).
    gp : GPSettings
        GP fitting settings (sparse beyond ``gp.max_full_points`` data).
    num_threads : int or None
        ``torch.set_num_threads`` for the run (None: leave as is).
    stop_after_held : int
        Stop early once this many consecutive evaluations held the operating point in every
        episode (0: never; for multi-seed measurements).
    """

    system: str = "pendulum"
    hybrid: bool = False
    seed: int = 0
    iterations: int = 10
    horizon: int = 40
    action_repeat: int = 3
    episode_steps: int = 200
    initial_rollouts: int = 3
    num_basis: int = 30
    policy_iterations: int = 75
    cost_width: float = 0.5
    eval_episodes: int = 5
    quadrature_order: int = 5
    hybrid_method: str = "quadrature"
    lambda_init: float = 1.0
    learn_lambda: bool = True
    relevance: str = "paper"
    gp: GPSettings = dataclasses.field(default_factory=GPSettings)
    num_threads: int | None = None
    stop_after_held: int = 0

    @classmethod
    def for_system(cls, name: str, **overrides: Any) -> PilcoConfig:
        """Per-system defaults, then ``overrides`` (GP fields may be given as ``gp_<field>``)."""
        if name not in SYSTEM_DEFAULTS:
            raise ValueError(f"system: expected one of {tuple(SYSTEM_DEFAULTS)}, found {name!r}")
        gp_fields = {f.name for f in dataclasses.fields(GPSettings)}
        gp_over = {k[3:]: v for k, v in overrides.items() if k.startswith("gp_")}
        unknown = set(gp_over) - gp_fields
        own = {k: v for k, v in overrides.items() if not k.startswith("gp_")}
        unknown |= set(own) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f"overrides: unknown PILCO settings {sorted(unknown)}")
        gp = own.pop("gp", None)
        if isinstance(gp, dict):
            gp = GPSettings(**gp)
        gp = dataclasses.replace(gp or GPSettings(), **gp_over)
        return cls(system=name, gp=gp, **{**SYSTEM_DEFAULTS[name], **own})

    def __post_init__(self) -> None:
        for name in (
            "iterations",
            "horizon",
            "action_repeat",
            "episode_steps",
            "num_basis",
            "policy_iterations",
            "quadrature_order",
            "eval_episodes",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected a positive integer, found {value!r}")
        for name in ("initial_rollouts", "seed", "stop_after_held"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name}: expected a non-negative integer, found {value!r}")
        for name in ("cost_width", "lambda_init"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not 0 < value < math.inf:
                raise ValueError(f"{name}: expected a positive number, found {value!r}")
        if self.relevance not in RELEVANCE_KINDS:
            raise ValueError(
                f"relevance: expected one of {RELEVANCE_KINDS}, found {self.relevance!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PilcoConfig:
        data = dict(data)
        data["gp"] = GPSettings(**data["gp"])
        return cls(**data)


SYSTEM_DEFAULTS: dict[str, dict[str, Any]] = {
    "pendulum": {"num_basis": 30, "cost_width": 0.5},
    "cartpole": {"num_basis": 60, "cost_width": 0.5, "quadrature_order": 4},
    "mountaincar": {"num_basis": 60, "cost_width": 1.0},
}


PilcoResult = TrainResult  # the one trainer result (leoc.training)


class CostSpec(NamedTuple):
    """Saturating cost on the observation: target (O,) and factor (K, O), W = F^T F."""

    target: torch.Tensor
    factor: torch.Tensor


def cost_spec(system: System, width: float) -> CostSpec:
    """The cost of each system, on the observation, divided by ``width``.

    pendulum: squared distance of the rod's tip to the upright tip,
    ``l^2 ((cos - 1)^2 + sin^2)``; cart-pole: the same for the pole tip over the track
    centre, ``(x + L sin)^2 + L^2 (cos - 1)^2`` with L the pole length; mountain car: ``x^2``.
    """
    target = torch.as_tensor(system.operating_obs, dtype=DTYPE)
    names = [f"{c.kind}:{system.state_names[c.state_index]}" for c in system.obs_layout]
    factor = torch.zeros(2 if system.angle_indices else 1, system.obs_dim, dtype=DTYPE)
    if system.name == "pendulum":
        length = system.params.length
        factor[0, names.index("cos:theta")] = length
        factor[1, names.index("sin:theta")] = length
    elif system.name == "cartpole":
        length = 2.0 * system.params.half_length
        factor[0, names.index("state:x")] = 1.0
        factor[0, names.index("sin:theta")] = length
        factor[1, names.index("cos:theta")] = length
    else:
        factor[0, names.index("state:x")] = 1.0
    return CostSpec(target, factor / width)


def obs_layout(system: System) -> list[tuple[str, int]]:
    return [(c.kind, c.state_index) for c in system.obs_layout]


def build_policy(
    system: System,
    config: PilcoConfig,
    generator: torch.Generator,
    observations: np.ndarray | None = None,
) -> nn.Module:
    """RBF baseline ``u_max sin(H(o) / u_max)`` or the hybrid with the same H and squash.

    Centres: the plain entries of ``num_basis`` observations drawn from the initial data, the
    cos/sin entries of every angle at a uniformly random angle (random data from the swing-up
    start only visit the bottom, and a policy without a basis function near the top has
    nothing to balance with); length-scales: the data's spread per observation entry;
    weights ``0.1 u_max N(0, 1)``.
    """
    limit = system.action_limit
    centres, scales = None, 1.0
    if observations is not None and len(observations) > 0:
        picks = torch.randint(len(observations), (config.num_basis,), generator=generator)
        centres = observations[picks.numpy()].copy()
        _spread_angle_centres(system, centres, generator)
        scales = np.maximum(observations.std(axis=0), MIN_POLICY_LENGTHSCALE)
    rbf = RBFNetwork(
        system.obs_dim,
        system.action_dim,
        config.num_basis,
        centres=centres,
        lengthscales=scales,
        generator=generator,
        weight_std=WEIGHT_STD_FRACTION * limit,
    )
    if not config.hybrid:
        return SaturatedPolicy(rbf, limit, "sin")
    from leoc.control.lqr import design_lqr

    design = design_lqr(system, action_repeat=config.action_repeat)
    if config.relevance == "roa":
        return roa_hybrid(system, design, rbf, learn_width=config.learn_lambda, saturation="sin")
    return HybridPolicy(
        LinearController(design.W, design.b),
        rbf,
        operating_point=system.operating_obs,
        lambda_init=config.lambda_init,
        learn_lambda=config.learn_lambda,
        action_limit=limit,
        saturation="sin",
    )


def _spread_angle_centres(system: System, centres: np.ndarray, generator: torch.Generator) -> None:
    """Overwrite, in place, the cos/sin columns of ``centres`` (N, O) with those of uniformly
    random angles, one angle per basis function and angle state."""
    for angle_index in system.angle_indices:
        angles = 2.0 * math.pi * torch.rand(len(centres), generator=generator, dtype=DTYPE)
        for column, component in enumerate(system.obs_layout):
            if component.state_index == angle_index and component.kind == "cos":
                centres[:, column] = torch.cos(angles).numpy()
            elif component.state_index == angle_index and component.kind == "sin":
                centres[:, column] = torch.sin(angles).numpy()


def start_distribution(system: System) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and covariance of the uniform swing-up start (variance a^2 / 3 per entry)."""
    mean = torch.as_tensor(system.swing_up_centre, dtype=DTYPE)
    spread = torch.as_tensor(system.start_spread, dtype=DTYPE)
    return mean, torch.diag(UNIFORM_VARIANCE_FACTOR * spread.square())


def predict_policy(
    policy: nn.Module, model: GPPosterior, system: System, config: PilcoConfig
) -> Prediction:
    """Predicted trajectory and costs of ``policy`` from the swing-up start."""
    mean, cov = start_distribution(system)
    spec = cost_spec(system, config.cost_width)
    return predict(
        policy,
        model,
        mean,
        cov,
        config.horizon,
        obs_layout(system),
        spec.target,
        spec.factor,
        config.hybrid_method,
        config.quadrature_order,
    )


def optimise_policy(
    policy: nn.Module, model: GPPosterior, system: System, config: PilcoConfig
) -> float:
    """Minimise the predicted horizon cost by L-BFGS (strong Wolfe line search).

    A failed evaluation (non-finite cost or a Cholesky failure) counts as +inf, which the line
    search backs away from; the best parameters seen are restored at the end.
    """
    params = [p for p in policy.parameters() if p.requires_grad]
    optimiser = torch.optim.LBFGS(
        params, max_iter=config.policy_iterations, line_search_fn="strong_wolfe"
    )
    best = {"loss": math.inf, "state": None}

    def closure() -> torch.Tensor:
        optimiser.zero_grad()
        try:
            loss = predict_policy(policy, model, system, config).total_cost
        except RuntimeError:  # CholeskyError or a linalg failure at extreme parameters
            loss = torch.tensor(math.inf, dtype=DTYPE)
        if not torch.isfinite(loss):
            for p in params:
                p.grad = torch.zeros_like(p)
            return torch.tensor(math.inf, dtype=DTYPE)
        loss.backward()
        if loss.item() < best["loss"]:
            best["loss"] = loss.item()
            best["state"] = {k: v.detach().clone() for k, v in policy.state_dict().items()}
        return loss

    optimiser.step(closure)
    if best["state"] is not None:
        policy.load_state_dict(best["state"])
    return best["loss"]


class _RunState(NamedTuple):
    iteration: int
    inputs: np.ndarray
    targets: np.ndarray
    interaction_steps: int
    log: list[dict[str, Any]]
    rng_state: dict[str, Any]
    hyper: GPHyper | None


def _log_row(
    iteration: int,
    steps: int,
    system: System,
    evaluation_of: Any,
    rollouts: list[Rollout],
    predicted: float | None,
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
        predicted_cost=predicted,
        data_size=data_size,
        wall_seconds=wall,
        gp_sparse=sparse,
    )
    return row


def _random_rollouts(
    system: System, config: PilcoConfig, rng: np.random.Generator
) -> tuple[list[Rollout], float]:
    """The random rollouts of iteration 0 and their wall time."""
    start_time = time.perf_counter()
    controller = RandomController(system, rng, config.action_repeat)
    rollouts = [
        run_rollout(
            system,
            controller,
            system.sample_start(rng, "swing_up"),
            config.episode_steps,
            config.action_repeat,
        )
        for _ in range(config.initial_rollouts)
    ]
    return rollouts, time.perf_counter() - start_time


def _default_run_dir(config: PilcoConfig) -> Path:
    kind = "hybrid" if config.hybrid else "rbf"
    return DEFAULT_RUN_ROOT / f"pilco_{config.system}_{kind}_seed{config.seed}"


def _progress_line(row: dict[str, Any], total: int) -> str:
    cost = row["predicted_cost"]
    cost_text = "      -" if cost is None else f"{cost:7.3f}"
    return (
        f"[pilco] iter {row['iteration']:2d}/{total} predicted cost {cost_text} "
        f"rollout return {row['rollout_return']:9.2f} eval return {row['mean_return']:9.2f} "
        f"held {row['held_fraction']:4.0%} data {row['data_size']:4d} "
        f"interaction {row['interaction_seconds']:6.2f} s wall {row['wall_seconds']:6.1f} s"
    )


def _save_checkpoint(
    run_dir: Path,
    config: PilcoConfig,
    state: _RunState,
    policy: nn.Module,
    model: GPPosterior | None,
    generator: torch.Generator,
) -> None:
    save_torch_atomic(
        {
            "config": config.to_dict(),
            "iteration": state.iteration,
            "inputs": state.inputs,
            "targets": state.targets,
            "interaction_steps": state.interaction_steps,
            "log": state.log,
            "rng_state": state.rng_state,
            "torch_rng_state": generator.get_state(),
            "hyper": None if state.hyper is None else state.hyper._asdict(),
            "policy_state": policy.state_dict(),
            "model": None if model is None else model._asdict(),
        },
        run_dir / CHECKPOINT_NAME,
    )
    save_torch_atomic(
        {
            "config": config.to_dict(),
            "policy_state": policy.state_dict(),
            "model": None if model is None else model._asdict(),
        },
        run_dir / CONTROLLER_NAME,
    )


def _resume(
    run_dir: Path, config: PilcoConfig, system: System, generator: torch.Generator
) -> tuple[_RunState, nn.Module, GPPosterior | None] | None:
    path = run_dir / CHECKPOINT_NAME
    if not path.exists():
        return None
    try:
        saved = torch.load(path, weights_only=False)
        old = PilcoConfig.from_dict(saved["config"])
    except Exception as error:  # truncated or garbled: set it aside and start afresh
        aside = set_aside(path)
        print(
            f"[pilco] damaged checkpoint {path} ({type(error).__name__}: {error}); set aside as "
            f"{aside.name}, starting the run afresh",
            flush=True,
        )
        return None
    if dataclasses.replace(old, iterations=config.iterations) != config:
        raise ValueError(
            f"resume: the checkpoint in {run_dir} was written with another configuration "
            f"({saved['config']}); use a new run_dir or resume=False"
        )
    generator.set_state(saved["torch_rng_state"])
    policy = build_policy(system, config, generator)
    policy.load_state_dict(saved["policy_state"])
    hyper = None if saved["hyper"] is None else GPHyper(**saved["hyper"])
    model = None if saved["model"] is None else GPPosterior(**saved["model"])
    state = _RunState(
        saved["iteration"],
        saved["inputs"],
        saved["targets"],
        saved["interaction_steps"],
        saved["log"],
        saved["rng_state"],
        hyper,
    )
    return state, policy, model


def _evaluate(system: System, config: PilcoConfig, policy: nn.Module, starts: np.ndarray) -> Any:
    """The policy's evaluation episodes, at its control period (leoc.training)."""
    return evaluate_episodes(system, HeldPolicy(policy, config.action_repeat), starts)


def _first_state(
    system: System,
    config: PilcoConfig,
    rng: np.random.Generator,
    generator: torch.Generator,
    starts: np.ndarray,
) -> tuple[_RunState, nn.Module]:
    """Iteration 0: random rollouts, the initial policy built from their data, its evaluation."""
    rollouts, wall = _random_rollouts(system, config, rng)
    inputs = np.concatenate([r.inputs for r in rollouts])
    targets = np.concatenate([r.targets for r in rollouts])
    policy = build_policy(system, config, generator, inputs[:, : system.obs_dim])
    steps = sum(r.steps for r in rollouts)
    evaluation = _evaluate(system, config, policy, starts)
    row = _log_row(0, steps, system, evaluation, rollouts, None, len(inputs), wall, False)
    state = _RunState(0, inputs, targets, steps, [row], rng.bit_generator.state, None)
    return state, policy


def _iterate(
    system: System,
    config: PilcoConfig,
    state: _RunState,
    policy: nn.Module,
    rng: np.random.Generator,
    starts: np.ndarray,
) -> tuple[_RunState, GPPosterior]:
    """One PILCO iteration: fit GP, optimise policy, run it, add its data, evaluate it."""
    start_time = time.perf_counter()
    model = fit_gp(state.inputs, state.targets, config.gp, rng, init=state.hyper)
    predicted = optimise_policy(policy, model, system, config)
    rollout = run_rollout(
        system,
        HeldPolicy(policy, config.action_repeat),
        system.sample_start(rng, "swing_up"),
        config.episode_steps,
        config.action_repeat,
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
        predicted,
        len(inputs),
        time.perf_counter() - start_time,
        model.sparse,
    )
    new_state = _RunState(
        state.iteration + 1,
        inputs,
        targets,
        steps,
        [*state.log, row],
        rng.bit_generator.state,
        model.hyper,
    )
    return new_state, model


def _held_long_enough(log: list[dict[str, Any]], config: PilcoConfig) -> bool:
    count = config.stop_after_held
    recent = log[-count:] if count > 0 else []
    return len(recent) == count > 0 and all(row["held_fraction"] >= 1.0 for row in recent)


def _title(config: PilcoConfig) -> str:
    kind = "hybrid" if config.hybrid else "RBF"
    return f"PILCO {kind}, {config.system} (seed {config.seed})"


def train_pilco(
    system: str,
    hybrid: bool = False,
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
    system : str
        ``pendulum``, ``cartpole`` or ``mountaincar``.
    hybrid : bool
        The hybrid RBF + LQR policy instead of the RBF baseline.
    seed : int
        The one seed of the run (numpy and torch generators, evaluation starts).
    run_dir : path, optional
        Run folder; default ``runs/pilco_<system>_<rbf|hybrid>_seed<seed>``.
    iterations : int, optional
        Policy-learning iterations (default: the config's).
    resume : bool
        Continue from ``run_dir/checkpoint.pt`` if present (same configuration required).
    progress : bool
        Print one line per iteration.
    **overrides
        Any :class:`PilcoConfig` field (``horizon=...``, ``num_basis=...``, ``gp_<field>=...``).

    Returns
    -------
    TrainResult
        The final policy as a :class:`~leoc.policies.HeldPolicy` at ``action_repeat``, the
        learning curve (one row per iteration, iteration 0 = the random rollouts), the config,
        its summary and the last GP posterior.
    """
    if iterations is not None:
        overrides["iterations"] = iterations
    config = PilcoConfig.for_system(system, hybrid=hybrid, seed=seed, **overrides)
    if config.num_threads is not None:
        torch.set_num_threads(config.num_threads)
    run_path = Path(run_dir) if run_dir is not None else _default_run_dir(config)
    run_path.mkdir(parents=True, exist_ok=True)
    plant = make_system(system)
    plant.episode_steps = config.episode_steps
    rng = np.random.default_rng(seed)
    generator = torch.Generator().manual_seed(seed)
    starts = evaluation_starts(plant, seed, config.eval_episodes)
    resumed = _resume(run_path, config, plant, generator) if resume else None
    model = None
    if resumed is None:
        state, policy = _first_state(plant, config, rng, generator, starts)
        write_text_atomic(run_path / CONFIG_FILE, json.dumps(config.to_dict(), indent=2))
        _save_checkpoint(run_path, config, state, policy, None, generator)
        if progress:
            print(_progress_line(state.log[0], config.iterations), flush=True)
    else:
        state, policy, model = resumed
        rng.bit_generator.state = state.rng_state
    while state.iteration < config.iterations and not _held_long_enough(state.log, config):
        state, model = _iterate(plant, config, state, policy, rng, starts)
        _save_checkpoint(run_path, config, state, policy, model, generator)
        write_curve(run_path, state.log, curve_summary(state.log, plant.dt), _title(config))
        if progress:
            print(_progress_line(state.log[-1], config.iterations), flush=True)
    summary = curve_summary(state.log, plant.dt)
    write_curve(run_path, state.log, summary, _title(config))
    policy.eval()
    held = HeldPolicy(policy, config.action_repeat).eval()
    return TrainResult(held, run_path, state.log, config.to_dict(), summary, model)


def load_pilco_controller(run_dir: str | Path) -> nn.Module:
    """The trained policy of a run folder at its control period (a
    :class:`~leoc.policies.HeldPolicy`: observations -> physical actions)."""
    path = Path(run_dir) / CONTROLLER_NAME
    try:
        saved = torch.load(path, weights_only=False)
        config = PilcoConfig.from_dict(saved["config"])
    except FileNotFoundError:
        raise
    except Exception as error:  # a truncated or garbled file: name it
        raise ValueError(
            f"controller: {path} could not be read as a PILCO controller "
            f"({type(error).__name__}: {error})"
        ) from error
    policy = build_policy(make_system(config.system), config, torch.Generator().manual_seed(0))
    policy.load_state_dict(saved["policy_state"])
    return HeldPolicy(policy.eval(), config.action_repeat).eval()
