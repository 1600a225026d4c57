"""PILCO training loop for the RBF baseline and the LEOC hybrid (Deisenroth & Rasmussen 2011).

Loop: ``initial_rollouts`` random rollouts; then, each iteration, fit the GP dynamics model ->
optimise the policy by L-BFGS on the predicted horizon cost (autograd through the whole
horizon) -> run the policy on the real system for one episode -> add its data.

Timing choice (documented in :mod:`leoc.pilco.rollout`): the policy decides every
``action_repeat`` simulator steps and holds its action (zero-order hold), the GP models that
``action_repeat``-step map, and the horizon is ``horizon`` decisions. Every real rollout, for
data and for evaluation, is a full ``episode_steps``-step episode run with the same hold, so
training and evaluation see the same closed loop. (The LQR part of the hybrid, designed at
``dt``, stays stable under the 3-step hold on all three systems.)

The run folder holds ``config.json``, ``log.json``, ``log.csv``, ``learning_curve.png``,
``controller.pt`` (policy state + GP model + config) and ``checkpoint.pt`` (everything needed to
resume, written atomically).
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

from leoc.io import (
    save_figure_atomic,
    save_torch_atomic,
    write_csv_atomic,
    write_json_atomic,
    write_text_atomic,
)
from leoc.pilco.gp import GPHyper, GPPosterior, GPSettings, fit_gp
from leoc.pilco.propagate import Prediction, SaturatedPolicy, predict
from leoc.pilco.rollout import (
    Rollout,
    hold_start,
    policy_action_fn,
    random_action_fn,
    run_rollout,
)
from leoc.policies import HybridPolicy, LinearController, RBFNetwork
from leoc.systems import make_system
from leoc.systems.base import DTYPE, System

DEFAULT_RUN_ROOT = Path("runs")
CHECKPOINT_NAME = "checkpoint.pt"
CONTROLLER_NAME = "controller.pt"
LOG_FIELDS = (
    "iteration",
    "interaction_seconds",
    "steps",
    "return",
    "predicted_cost",
    "data_size",
    "wall_seconds",
    "held_operating_point",
    "hold_step",
    "gp_sparse",
)
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
    hold_band : float
        Band of the "reached and held the operating point" test (degrees or position units).
    hold_min_steps : int
        Fewest final steps inside the band that count as holding.
    quadrature_order : int
        Gauss-Hermite nodes per state dimension for the hybrid's moment matching.
    hybrid_method : str
        ``quadrature`` or the ``constant_relevance`` heuristic (for comparison only).
    lambda_init : float
        Initial diagonal of the hybrid's Lambda (paper: identity).
    learn_lambda : bool
        Optimise Lambda with the RBF parameters.
    gp : GPSettings
        GP fitting settings (sparse beyond ``gp.max_full_points`` data).
    num_threads : int or None
        ``torch.set_num_threads`` for the run (None: leave as is).
    stop_after_held : int
        Stop early once this many consecutive iterations held the operating point (0: never;
        for multi-seed measurements).
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
    hold_band: float = 5.0
    hold_min_steps: int = 30
    quadrature_order: int = 5
    hybrid_method: str = "quadrature"
    lambda_init: float = 1.0
    learn_lambda: bool = True
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

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PilcoConfig:
        data = dict(data)
        data["gp"] = GPSettings(**data["gp"])
        return cls(**data)


SYSTEM_DEFAULTS: dict[str, dict[str, Any]] = {
    "pendulum": {"num_basis": 30, "cost_width": 0.5, "hold_band": 5.0},
    "cartpole": {"num_basis": 60, "cost_width": 0.5, "hold_band": 5.0, "quadrature_order": 4},
    "mountaincar": {"num_basis": 60, "cost_width": 1.0, "hold_band": 0.05},
}


class PilcoResult(NamedTuple):
    """Result of :func:`train_pilco`."""

    policy: nn.Module
    run_dir: Path
    log: list[dict[str, Any]]
    config: dict[str, Any]
    model: GPPosterior | None


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

    design = design_lqr(system)
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
    interaction_seconds: float
    log: list[dict[str, Any]]
    rng_state: dict[str, Any]
    hyper: GPHyper | None


def _write_logs(run_dir: Path, log: list[dict[str, Any]]) -> None:
    write_json_atomic(run_dir / "log.json", log, indent=2)
    write_csv_atomic(run_dir / "log.csv", log, LOG_FIELDS)


def plot_learning_curve(log: list[dict[str, Any]], path: Path, title: str) -> None:
    """Return of each iteration's rollout against cumulative interaction time (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seconds = [row["interaction_seconds"] for row in log]
    returns = [row["return"] for row in log]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(seconds, returns, "o-", label="return of the iteration's rollout")
    held = [row for row in log if row["held_operating_point"]]
    if held:
        ax.plot(
            [row["interaction_seconds"] for row in held],
            [row["return"] for row in held],
            "g*",
            markersize=12,
            label="held the operating point",
        )
    ax.set_xlabel("interaction time [simulated s]")
    ax.set_ylabel("return")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    save_figure_atomic(fig, path)


def _log_row(
    iteration: int,
    rollouts: list[Rollout],
    seconds: float,
    predicted: float | None,
    data_size: int,
    wall: float,
    hold: int | None,
    sparse: bool,
) -> dict[str, Any]:
    return {
        "iteration": iteration,
        "interaction_seconds": seconds,
        "steps": int(sum(r.steps for r in rollouts)),
        "return": float(np.mean([r.total_return for r in rollouts])),
        "predicted_cost": predicted,
        "data_size": data_size,
        "wall_seconds": wall,
        "held_operating_point": hold is not None,
        "hold_step": hold,
        "gp_sparse": sparse,
    }


def _initial_state(
    system: System, config: PilcoConfig, rng: np.random.Generator
) -> tuple[_RunState, list[Rollout], float]:
    """Random rollouts (iteration 0)."""
    start_time = time.perf_counter()
    rollouts = [
        run_rollout(
            system,
            random_action_fn(system, rng),
            system.sample_start(rng, "swing_up"),
            config.episode_steps,
            config.action_repeat,
        )
        for _ in range(config.initial_rollouts)
    ]
    inputs = np.concatenate([r.inputs for r in rollouts])
    targets = np.concatenate([r.targets for r in rollouts])
    seconds = sum(r.steps for r in rollouts) * system.dt
    row = _log_row(0, rollouts, seconds, None, len(inputs), 0.0, None, False)
    row["wall_seconds"] = time.perf_counter() - start_time
    state = _RunState(0, inputs, targets, seconds, [row], {}, None)
    return state, rollouts, seconds


def _default_run_dir(config: PilcoConfig) -> Path:
    kind = "hybrid" if config.hybrid else "rbf"
    return DEFAULT_RUN_ROOT / f"pilco_{config.system}_{kind}_seed{config.seed}"


def _progress_line(row: dict[str, Any], total: int) -> str:
    cost = row["predicted_cost"]
    cost_text = "      -" if cost is None else f"{cost:7.3f}"
    held = f" held from step {row['hold_step']}" if row["held_operating_point"] else ""
    return (
        f"[pilco] iter {row['iteration']:2d}/{total} predicted cost {cost_text} "
        f"return {row['return']:9.2f} data {row['data_size']:4d} "
        f"interaction {row['interaction_seconds']:6.2f} s wall {row['wall_seconds']:6.1f} s{held}"
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
            "interaction_seconds": state.interaction_seconds,
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
    saved = torch.load(path, weights_only=False)
    old = PilcoConfig.from_dict(saved["config"])
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
        saved["interaction_seconds"],
        saved["log"],
        saved["rng_state"],
        hyper,
    )
    return state, policy, model


def _iterate(
    system: System,
    config: PilcoConfig,
    state: _RunState,
    policy: nn.Module,
    rng: np.random.Generator,
) -> tuple[_RunState, GPPosterior]:
    """One PILCO iteration: fit GP, optimise policy, run it, add its data."""
    start_time = time.perf_counter()
    model = fit_gp(state.inputs, state.targets, config.gp, rng, init=state.hyper)
    predicted = optimise_policy(policy, model, system, config)
    rollout = run_rollout(
        system,
        policy_action_fn(policy),
        system.sample_start(rng, "swing_up"),
        config.episode_steps,
        config.action_repeat,
    )
    seconds = state.interaction_seconds + rollout.steps * system.dt
    inputs = np.concatenate([state.inputs, rollout.inputs])
    targets = np.concatenate([state.targets, rollout.targets])
    hold = hold_start(
        system, rollout, config.hold_band, config.hold_min_steps, config.episode_steps
    )
    row = _log_row(
        state.iteration + 1,
        [rollout],
        seconds,
        predicted,
        len(inputs),
        time.perf_counter() - start_time,
        hold,
        model.sparse,
    )
    new_state = _RunState(
        state.iteration + 1,
        inputs,
        targets,
        seconds,
        [*state.log, row],
        rng.bit_generator.state,
        model.hyper,
    )
    return new_state, model


def _held_long_enough(log: list[dict[str, Any]], config: PilcoConfig) -> bool:
    count = config.stop_after_held
    recent = log[-count:] if count > 0 else []
    return len(recent) == count > 0 and all(row["held_operating_point"] for row in recent)


def train_pilco(
    system: str,
    hybrid: bool = False,
    seed: int = 0,
    run_dir: str | Path | None = None,
    iterations: int | None = None,
    resume: bool = True,
    progress: bool = True,
    **overrides: Any,
) -> PilcoResult:
    """Train a PILCO controller (RBF baseline or LEOC hybrid) on ``system``.

    Parameters
    ----------
    system : str
        ``pendulum``, ``cartpole`` or ``mountaincar``.
    hybrid : bool
        The hybrid RBF + LQR policy instead of the RBF baseline.
    seed : int
        The one seed of the run (numpy and torch generators).
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
    PilcoResult
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
    resumed = _resume(run_path, config, plant, generator) if resume else None
    model = None
    if resumed is None:
        state, _, _ = _initial_state(plant, config, rng)
        policy = build_policy(plant, config, generator, state.inputs[:, : plant.obs_dim])
        state = state._replace(rng_state=rng.bit_generator.state)
        write_text_atomic(run_path / "config.json", json.dumps(config.to_dict(), indent=2))
        _save_checkpoint(run_path, config, state, policy, None, generator)
        if progress:
            print(_progress_line(state.log[0], config.iterations), flush=True)
    else:
        state, policy, model = resumed
        rng.bit_generator.state = state.rng_state
    while state.iteration < config.iterations and not _held_long_enough(state.log, config):
        state, model = _iterate(plant, config, state, policy, rng)
        _save_checkpoint(run_path, config, state, policy, model, generator)
        _write_logs(run_path, state.log)
        if progress:
            print(_progress_line(state.log[-1], config.iterations), flush=True)
    _write_logs(run_path, state.log)
    kind = "hybrid" if config.hybrid else "RBF"
    plot_learning_curve(state.log, run_path / "learning_curve.png", f"PILCO {kind}, {system}")
    policy.eval()
    return PilcoResult(policy, run_path, state.log, config.to_dict(), model)


def load_pilco_controller(run_dir: str | Path) -> nn.Module:
    """The trained policy of a run folder (acts on observations, returns physical actions)."""
    saved = torch.load(Path(run_dir) / CONTROLLER_NAME, weights_only=False)
    config = PilcoConfig.from_dict(saved["config"])
    policy = build_policy(make_system(config.system), config, torch.Generator().manual_seed(0))
    policy.load_state_dict(saved["policy_state"])
    return policy.eval()
