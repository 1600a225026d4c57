r"""Train the LEOC hybrid (or the learner alone) on a gymnasium environment itself.

:func:`train_gym` runs leoc's DDPG, TD3 or SAC on ``gymnasium.make(env_id)`` with no torch step
function: the LQR comes from the env's own step map (:mod:`leoc.gym_adapter`), the hybrid's
linear part is that LQR written on the env's observation, and the learning curve is measured on
held-out episodes of the env. ``leoc train gym:InvertedPendulum-v5 --algo sac --hybrid`` is
the same call.

**The plant** (:func:`gym_plant`). The operating point is a state ``x_eq`` of the env
(MuJoCo: ``concat(qpos, qvel)``; default the rest state ``qpos = qvel = 0``, the upright of
gymnasium's inverted pendulums) and an action ``u_eq`` (default 0). The LQR
``u = u_eq - K (x - x_eq)`` is designed on the central-difference linearisation of the env's
step (:func:`~leoc.gym_adapter.linearise_env`, :func:`~leoc.gym_adapter.design_env_lqr`;
weights ``Q = I``, ``R = I`` unless given).

**The gain on the observation.** The hybrid's :math:`G(o) = W o + b` acts on the observation
:math:`o = h(x)` the learner sees (``env.unwrapped._get_obs()`` after the state is set), which
need not be the state (``InvertedDoublePendulum-v5`` shows the cart position, the sines and
cosines of the hinge angles, the clipped speeds and a constraint force). With
:math:`J = \partial h / \partial x` at ``x_eq`` (central differences of the observation map,
steps :func:`~leoc.gym_adapter.default_steps`) and :math:`M = J^+` its pseudo-inverse,

.. math::

    W = -K M, \qquad b = u_{eq} - W a, \qquad a = h(x_{eq}),

so :math:`G(a) = u_{eq}` exactly and :math:`\partial G(h(x)) / \partial x = -K M J = -K` at
``x_eq`` whenever :math:`J` has full column rank (:math:`M J = I`): the hybrid's linear part is
the state-space LQR to first order. An observation that does not determine the state to first
order (rank of :math:`J` below ``S``) is refused. :class:`GymPlant` states two errors: the
Richardson estimate of :math:`J`'s truncation (``jacobian_error``) and ``observation_error``,
the largest :math:`|M (h(x) - a) - (x - x_{eq})|` over seeded default starts of the env, relative
to the largest :math:`|x - x_{eq}|` there (0 when the observation *is* the state, as in
``InvertedPendulum-v5``; for ``InvertedDoublePendulum-v5`` the sines' curvature, about
:math:`\theta^2 / 6`). Where :math:`J = I` (checked to 1e-9) the observation is the state.

**Relevances.** The paper's relevance works on any observation. Its default floor ``r_min``
(:class:`~leoc.policies.HybridSpec`), the ROA relevance and the Lyapunov relevance need a level
:math:`\rho` of the LQR's :math:`V(x) = (x - x_{eq})^\top P (x - x_{eq})` inside its region of
attraction. No interval model of a gymnasium env exists to *prove* one, so the level is
**sampled** (:func:`sample_region`): the largest :math:`\rho` (doubling, then bisection in
:math:`\log\rho`) such that ``samples`` seeded starts *on* the level set
:math:`\{V = \rho\}`, held by the clipped LQR on the env's own step for ``steps`` steps, all
stay alive (no termination) and end below ``CONVERGED_FRACTION * rho``. A sampled level is
evidence, not a certificate: a start between the samples may fail, and an inner level may fail
where the tested one passed. The run's ``relevance_data`` says ``"region": "sampled"``. These
designs read the state from the observation through leoc's layouts, so they need an env
whose observation is its state; others are refused with a one-line error (use
``relevance="paper"`` with ``r_min=None``).

**Run folder**: the contract of :mod:`leoc.sb3.train` (``config.json`` with a ``"gym"`` entry
for the env's settings and the plant's design, ``model.zip``, ``curve.json/csv/png``,
``checkpoint.pkl`` while it runs). Learning curve: every ``eval_interval`` steps (and at step 0,
before any learning) the deterministic policy runs ``eval_episodes`` episodes of the env from
``reset(seed=seed + 10000 + k)``; a row's ``held_fraction`` is the share that reached the time
limit without termination. The controller is the final policy (``model_selection="final"``).
Resume: the MuJoCo or classic-control state of the training env is checkpointed with it
(:class:`StatefulEnv`), so a resumed run equals the uninterrupted one.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.logger import Logger

from leoc.gym_adapter import (
    EnvLQR,
    default_steps,
    design_env_lqr,
    linearise_env,
    state_access,
)
from leoc.io import write_text_atomic
from leoc.names import GYM_PREFIX, ControllerName, gym_env_id, gym_folder_name
from leoc.policies.spec import HybridDesign, HybridSpec
from leoc.sb3.checkpoint import (
    CHECKPOINT_FILE,
    CHECKPOINT_INTERVAL_STEPS,
    CheckpointCallback,
)
from leoc.sb3.config import DDPGConfig
from leoc.sb3.physical import physical_policy
from leoc.sb3.train import (
    DEFAULT_RUN_ROOT,
    MODEL_FILES,
    RUN_OUTPUTS,
    build_model,
    earlier_run,
    library_versions,
    load_ddpg_model,
    save_model_atomic,
)
from leoc.training import (
    CONFIG_FILE,
    EVAL_SEED_OFFSET,
    TrainResult,
    curve_summary,
    run_folder,
    write_curve,
)

__all__ = [
    "CONVERGED_FRACTION",
    "DESIGN_FILE",
    "GYM_DEFAULTS",
    "IDENTITY_TOLERANCE",
    "OBSERVATION_STARTS",
    "ROA_BISECTIONS",
    "ROA_DOUBLINGS",
    "ROA_SAMPLES",
    "ROA_STEPS",
    "GymController",
    "GymEvaluationCallback",
    "GymPlant",
    "SampledRegion",
    "StatefulEnv",
    "gym_hybrid_design",
    "gym_plant",
    "load_gym_controller",
    "make_gym_env",
    "sample_region",
    "train_gym",
]

#: :class:`~leoc.sb3.DDPGConfig` defaults of a gymnasium run where they differ from a leoc
#: system's: 10k steps, an evaluation of 5 episodes every 1000 steps, the final policy.
GYM_DEFAULTS: dict[str, Any] = {
    "total_steps": 10_000,
    "eval_interval": 1_000,
    "eval_episodes": 5,
    "model_selection": "final",
}
#: Seeded starts of the env (``reset(seed=k)``) over which ``observation_error`` is measured.
OBSERVATION_STARTS = 20
#: Largest entry of ``|J - I|`` for which the observation is taken to be the state.
IDENTITY_TOLERANCE = 1e-9
#: Starts on the level set per tested level of :func:`sample_region`.
ROA_SAMPLES = 16
#: Steps each start of :func:`sample_region` is held by the clipped LQR.
ROA_STEPS = 250
#: A start of :func:`sample_region` converges when it ends below this fraction of its level.
CONVERGED_FRACTION = 1e-2
#: Bisections of :func:`sample_region` in log rho, after the doubling that brackets the level.
ROA_BISECTIONS = 10
#: Doublings (or halvings) of :func:`sample_region` from rho = 1 before it gives up.
ROA_DOUBLINGS = 40


def make_gym_env(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> gym.Env:
    """``gymnasium.make(env_id, **env_kwargs)``, its failures as one-line ``ValueError``\\ s
    (an unknown id; MuJoCo missing, naming leoc's extra)."""
    try:
        return gym.make(env_id, **dict(env_kwargs or {}))
    except gym.error.DependencyNotInstalled as error:
        raise ValueError(
            f"env {env_id!r}: needs a package that is not installed ({error}); for MuJoCo envs "
            'install leoc\'s extra: pip install -e ".[mujoco]"'
        ) from None
    except gym.error.Error as error:
        raise ValueError(
            f"env: expected a gymnasium id (gymnasium.envs.registry), found {env_id!r} "
            f"({type(error).__name__}: {error})"
        ) from None


class StatefulEnv(gym.Wrapper):
    """An env whose pickle keeps the simulator's state, so that a checkpoint resumes exactly.

    gymnasium's MuJoCo and classic-control envs pickle as their constructor arguments (a fresh
    env). This wrapper adds the unwrapped env's state: MuJoCo's full integration state
    (``mj_getState(..., mjSTATE_INTEGRATION)``: time, qpos, qvel, activations, warm start,
    controls and applied forces), or a classic-control env's ``state`` attribute; and the
    env's own generator (``np_random``).
    """

    def __getstate__(self) -> dict[str, Any]:
        data = dict(self.__dict__)
        base = self.env.unwrapped
        snapshot: dict[str, Any] = {"rng": base.np_random.bit_generator.state}
        if hasattr(base, "model") and hasattr(base, "data"):
            import mujoco

            kind = mujoco.mjtState.mjSTATE_INTEGRATION
            values = np.empty(mujoco.mj_stateSize(base.model, kind))
            mujoco.mj_getState(base.model, base.data, values, kind)
            snapshot["mujoco"] = values
        elif hasattr(base, "state"):
            snapshot["state"] = None if base.state is None else np.array(base.state)
        data["_leoc_snapshot"] = snapshot
        return data

    def __setstate__(self, data: dict[str, Any]) -> None:
        snapshot = data.pop("_leoc_snapshot")
        self.__dict__.update(data)
        base = self.env.unwrapped
        base.np_random.bit_generator.state = snapshot["rng"]
        if "mujoco" in snapshot:
            import mujoco

            kind = mujoco.mjtState.mjSTATE_INTEGRATION
            mujoco.mj_setState(base.model, base.data, snapshot["mujoco"], kind)
        elif "state" in snapshot:
            base.state = snapshot["state"]


class GymPlant(NamedTuple):
    """What a hybrid on a gymnasium env is designed from (:func:`gym_plant`).

    ``lqr`` is the state-space LQR (``K``, ``P``); ``gain`` and ``bias`` are its ``W``, ``b``
    on the observation (module docstring), ``operating_obs`` is ``a = h(x_eq)``;
    ``obs_jacobian`` is ``J`` (D, S), ``obs_to_state`` is ``M = J^+`` (S, D), with their errors
    ``jacobian_error`` (largest entry) and ``observation_error`` (relative, over seeded starts).
    """

    env_id: str
    state: np.ndarray  # (S,)
    action: np.ndarray  # (F,)
    lqr: EnvLQR
    gain: np.ndarray  # (F, D)
    bias: np.ndarray  # (F,)
    operating_obs: np.ndarray  # (D,)
    obs_jacobian: np.ndarray  # (D, S)
    obs_to_state: np.ndarray  # (S, D)
    jacobian_error: float
    observation_error: float
    observation_is_state: bool


def _default_point(env: gym.Env, env_id: str) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo envs: the rest state ``qpos = qvel = 0`` and action 0; others must say."""
    base = env.unwrapped
    if not (hasattr(base, "model") and hasattr(base, "set_state")):
        raise ValueError(
            f"operating_point: expected (state, action) for {env_id!r} (only MuJoCo envs have a "
            "default, the rest state qpos = qvel = 0 with action 0), found None"
        )
    size = base.model.nq + base.model.nv
    return np.zeros(size), np.zeros(env.action_space.shape)


def _observation_jacobian(env: gym.Env, state: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``a = h(x_eq)``, ``J`` by central differences of the observation map and the Richardson
    estimate of its truncation error (largest entry; :mod:`leoc.gym_adapter`)."""
    base = env.unwrapped
    access = state_access(env)
    if not hasattr(base, "_get_obs"):
        raise ValueError(
            f"env: expected an env with _get_obs() (the observation of a set state), found "
            f"{type(base).__name__} without it"
        )

    def observe(x: np.ndarray) -> np.ndarray:
        access.set(x)
        return np.array(base._get_obs(), dtype=float)

    steps = default_steps(state, float(np.finfo(float).eps))
    columns, errors = [], []
    for index, h in enumerate(steps):
        pair = []
        for width in (h, h / 2.0):
            offset = np.zeros_like(state)
            offset[index] = width
            pair.append((observe(state + offset) - observe(state - offset)) / (2.0 * width))
        columns.append(pair[0])
        errors.append(4.0 / 3.0 * np.abs(pair[0] - pair[1]))
    operating_obs = observe(state)
    return operating_obs, np.stack(columns, axis=1), float(np.max(errors))


def _observation_error(env: gym.Env, plant_map: tuple[np.ndarray, ...], seed: int) -> float:
    """Largest ``|M (h(x) - a) - (x - x_eq)|`` over seeded default starts, relative to the
    largest ``|x - x_eq|`` there."""
    state, operating_obs, to_state = plant_map
    access = state_access(env)
    worst, scale = 0.0, 0.0
    for k in range(OBSERVATION_STARTS):
        observation, _ = env.reset(seed=seed + k)
        deviation = np.array(access.get(), dtype=float) - state
        recovered = to_state @ (np.asarray(observation, dtype=float) - operating_obs)
        worst = max(worst, float(np.max(np.abs(recovered - deviation))))
        scale = max(scale, float(np.max(np.abs(deviation))))
    return worst / scale if scale > 0.0 else worst


def gym_plant(
    env: gym.Env,
    env_id: str,
    operating_point: tuple[Any, Any] | None = None,
    Q: Any = None,
    R: Any = None,
    seed: int = 0,
) -> GymPlant:
    """The LQR of ``env`` about its operating point, written on its observation.

    Parameters
    ----------
    env : gymnasium.Env
        Its state settable (:func:`~leoc.gym_adapter.state_access`), with ``_get_obs``.
    env_id : str
        For messages and the record.
    operating_point : (state, action), optional
        Default for MuJoCo envs: zeros (the rest state, upright for the inverted pendulums).
    Q, R : optional
        LQR weights (:func:`~leoc.gym_adapter.design_env_lqr`; default identities).
    seed : int
        Seeds the env's resets (linearisation, observation error).

    Raises
    ------
    ValueError
        No default point, an observation that does not determine the state to first order.
    """
    env.reset(seed=seed)
    state, action = operating_point or _default_point(env, env_id)
    lqr = design_env_lqr(linearise_env(env, state, action, seed=seed), Q, R)
    operating_obs, jacobian, jacobian_error = _observation_jacobian(env, lqr.state)
    size = lqr.state.size
    rank = int(np.linalg.matrix_rank(jacobian))
    if rank < size:
        raise ValueError(
            f"env {env_id!r}: expected an observation that determines the {size} state entries "
            f"to first order at the operating point, found d obs / d state of rank {rank}"
        )
    to_state = np.linalg.pinv(jacobian)
    gain = lqr.W @ to_state
    bias = lqr.action - gain @ operating_obs
    error = _observation_error(env, (lqr.state, operating_obs, to_state), seed)
    is_state = jacobian.shape == (size, size) and bool(
        np.max(np.abs(jacobian - np.eye(size))) <= IDENTITY_TOLERANCE
    )
    fields = (env_id, lqr.state, lqr.action, lqr, gain, bias, operating_obs, jacobian, to_state)
    return GymPlant(*fields, jacobian_error, error, is_state)


class SampledRegion(NamedTuple):
    """A level ``rho`` of ``V(x) = (x - x_eq)^T P (x - x_eq)`` that sampled starts on its level
    set all survived (:func:`sample_region`): evidence, not a proof. Duck-types the LQR
    certificate the relevance designs read (``P``, ``rho``, ``certified``, ``action_repeat``)."""

    P: np.ndarray
    rho: float
    certified: bool  # rho > 0: some level passed
    samples: int
    steps: int
    seed: int
    action_repeat: int = 1
    linear_decrease: str = "sampled on the env, not proved"


def _held_end(env: gym.Env, access: Any, lqr: EnvLQR, start: np.ndarray, steps: int) -> Any:
    """The state after ``steps`` steps of the clipped LQR on ``env.unwrapped`` from the state
    ``start``, or None if the env terminated (or the state left the finite numbers)."""
    base = env.unwrapped
    access.set(start)
    for _ in range(steps):
        x = np.array(access.get(), dtype=float)
        u = np.clip(lqr.W @ x + lqr.b, lqr.action_low, lqr.action_high)
        _, _, terminated, _, _ = base.step(u)
        if terminated:
            return None
    end = np.array(access.get(), dtype=float)
    return end if np.all(np.isfinite(end)) else None


def sample_region(
    env: gym.Env, lqr: EnvLQR, samples: int = ROA_SAMPLES, steps: int = ROA_STEPS, seed: int = 0
) -> SampledRegion:
    """The largest level of the LQR's ``V`` whose sampled starts all converge (module
    docstring): ``samples`` directions drawn once (``default_rng(seed)``), the starts
    ``x_eq + sqrt(rho) L^-T u`` (``P = L L^T``, ``|u| = 1``, so ``V = rho`` exactly); rho
    doubled (or halved) from 1 to a bracket, then bisected in log rho :data:`ROA_BISECTIONS`
    times. ``certified`` is False (``rho = 0``) when no level down to ``2^-40`` passed.

    "Converge" is measured against the loop's own end state from ``x_eq``: an operating point
    that is not exactly an equilibrium of the env (``InvertedPendulum-v5``'s pole is modelled
    1 mm off vertical, so the clipped LQR settles 2 cm and 0.1 degrees away from the rest
    state) leaves every start with that offset; a start converges when it stays alive and ends
    with ``V(x_T - x_T^ref) <= CONVERGED_FRACTION * rho``.
    """
    env.reset(seed=seed)
    access = state_access(env)
    reference = _held_end(env, access, lqr, lqr.state, steps)
    directions = np.random.default_rng(seed).standard_normal((samples, lqr.state.size))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    unit = np.linalg.solve(np.linalg.cholesky(lqr.P).T, directions.T).T  # V(unit) = 1

    def passes(rho: float) -> bool:
        for start in lqr.state + np.sqrt(rho) * unit:
            end = _held_end(env, access, lqr, start, steps)
            if end is None or (end - reference) @ lqr.P @ (end - reference) > (
                CONVERGED_FRACTION * rho
            ):
                return False
        return True

    low, high, rho = 0.0, None, 1.0
    for _ in range(ROA_DOUBLINGS if reference is not None else 0):
        if passes(rho):
            low = rho
            if high is not None:
                break
            rho *= 2.0
        else:
            high = rho
            if low > 0.0:
                break
            rho /= 2.0
    if low > 0.0 and high is not None:
        for _ in range(ROA_BISECTIONS):
            middle = float(np.sqrt(low * high))
            low, high = (middle, high) if passes(middle) else (low, middle)
    return SampledRegion(lqr.P, float(low), low > 0.0, samples, steps, seed)


class _PlantView(NamedTuple):
    """What the relevance designs read of a system (``name``, ``observation.to_list()``,
    ``operating_state``), for a gymnasium env."""

    name: str
    observation: Any
    operating_state: np.ndarray


class _StateLayout:
    """The observation layout of an env whose observation is its state (every entry a state
    entry); for any other env ``to_list`` refuses, naming the fix."""

    def __init__(self, plant: GymPlant) -> None:
        self.plant = plant

    def to_list(self) -> list[list[Any]]:
        if not self.plant.observation_is_state:
            raise ValueError(
                f"relevance: r_min, relevance='roa' and relevance='lyapunov' read the state from "
                f"the observation, which for {self.plant.env_id!r} is not the state "
                f"(d obs / d state is not I); pass relevance='paper' with r_min=None (leoc train: "
                "--r-min none)"
            )
        return [["state", index] for index in range(self.plant.state.size)]


class _StateLQR(NamedTuple):
    """The LQR's ``P`` at the env's own step (``action_repeat`` 1), as the designs read it."""

    P: np.ndarray
    action_repeat: int = 1


def gym_hybrid_design(
    spec: HybridSpec, plant: GymPlant, region: Callable[[], SampledRegion]
) -> HybridDesign:
    """The :class:`~leoc.policies.HybridDesign` of ``spec`` on a gymnasium env: ``W``, ``b``,
    ``a`` of ``plant`` and the relevance design's data, resolved by the design itself with the
    *sampled* region (``region()``, called only by designs that need a level) in place of a
    proved certificate; such data is marked ``"region": "sampled"``."""
    view = _PlantView(f"{GYM_PREFIX}{plant.env_id}", _StateLayout(plant), plant.state)
    called: list[SampledRegion] = []

    def certificate() -> SampledRegion:
        view.observation.to_list()  # every design that needs a level reads the state: refuse first
        called.append(region())
        return called[-1]

    data = spec.design.resolve(spec, view, _StateLQR(plant.lqr.P), certificate)
    if called:
        sampled = called[-1]
        data = {**data, "region": "sampled", "samples": sampled.samples, "steps": sampled.steps}
    return HybridDesign(plant.gain, plant.bias, plant.operating_obs, data)


def _episodes(envs: Sequence[gym.Env], model: Any, seeds: Sequence[int]) -> list[tuple]:
    """Return, held (the time limit reached without termination) and length of one
    deterministic episode per env from ``reset(seed=seed)``, stepped together: one batched
    ``predict`` per step for the episodes still running."""
    observations = [env.reset(seed=seed)[0] for env, seed in zip(envs, seeds, strict=True)]
    totals, lengths = [0.0] * len(envs), [0] * len(envs)
    held: list[bool | None] = [None] * len(envs)
    while any(done is None for done in held):
        running = [k for k, done in enumerate(held) if done is None]
        batch = np.stack([observations[k] for k in running])
        actions, _ = model.predict(batch, deterministic=True)
        for k, action in zip(running, actions, strict=True):
            observations[k], reward, terminated, truncated, _ = envs[k].step(action)
            totals[k] += float(reward)
            lengths[k] += 1
            if terminated or truncated:
                held[k] = bool(truncated and not terminated)
    return list(zip(totals, held, lengths, strict=True))


class GymEvaluationCallback(BaseCallback):
    """The learning curve of a gymnasium run: at step 0 and every ``interval`` steps (and at
    the end) the deterministic policy runs one episode from each of ``seeds``, on ``envs``
    (one per seed, not the training env); a row holds :data:`~leoc.training.CURVE_COLUMNS`,
    the per-episode ``returns``, ``held`` and ``episode_steps``. Its curve is checkpointed
    with the run."""

    def __init__(
        self,
        envs: Sequence[gym.Env],
        seeds: Sequence[int],
        interval: int,
        dt: float,
        progress: Callable[[dict[str, Any]], None] | None = None,
    ) -> None:
        super().__init__(verbose=0)
        if len(envs) != len(seeds):
            raise ValueError(f"envs: expected one per seed ({len(seeds)}), found {len(envs)}")
        self.envs = list(envs)
        self.seeds = [int(seed) for seed in seeds]
        self.interval = int(interval)
        self.dt = float(dt)
        self.progress = progress
        self.curve: list[dict[str, Any]] = []

    def evaluate(self) -> None:
        """Append the row of the current policy at the current step (once per step)."""
        steps = int(self.num_timesteps)
        if self.curve and self.curve[-1]["steps"] == steps:
            return
        episodes = _episodes(self.envs, self.model, self.seeds)
        returns = [episode[0] for episode in episodes]
        held = [episode[1] for episode in episodes]
        row = {
            "steps": steps,
            "interaction_seconds": steps * self.dt,
            "mean_return": float(np.mean(returns)),
            "std_return": float(np.std(returns)),
            "held_fraction": float(np.mean(held)),
            "returns": returns,
            "held": held,
            "episode_steps": [episode[2] for episode in episodes],
        }
        self.curve.append(row)
        if self.progress is not None:
            self.progress(row)

    def _on_training_start(self) -> None:
        if self.num_timesteps == 0:
            self.evaluate()

    def _on_step(self) -> bool:
        if self.num_timesteps % self.interval == 0:
            self.evaluate()
        return True

    def _on_training_end(self) -> None:
        self.evaluate()

    def checkpoint_state(self) -> Any:
        """The curve so far (:class:`~leoc.sb3.checkpoint.CheckpointedState`)."""
        return [dict(row) for row in self.curve]

    def restore_checkpoint_state(self, state: Any) -> None:
        """Take the curve of a checkpoint back."""
        self.curve = [dict(row) for row in state]


class _GymRun(NamedTuple):
    """One gymnasium run: its config, the saved config dict, the env's settings, the folder."""

    config: DDPGConfig
    config_dict: dict[str, Any]
    env_id: str
    env_kwargs: dict[str, Any]
    run_path: Path
    seed: int
    progress: bool | str


def _gym_settings(
    env_kwargs: Mapping[str, Any] | None,
    operating_point: tuple[Any, Any] | None,
    weights: tuple[Any, Any],
    roa: tuple[int, int],
) -> dict[str, Any]:
    """The ``"gym"`` entry of ``config.json``: what the run's env and design were made from."""

    def listed(value: Any) -> Any:
        return None if value is None else np.asarray(value, dtype=float).tolist()

    state, action = operating_point if operating_point is not None else (None, None)
    return {
        "env_kwargs": dict(env_kwargs or {}),
        "state": listed(state),
        "action": listed(action),
        "Q": listed(weights[0]),
        "R": listed(weights[1]),
        "roa_samples": int(roa[0]),
        "roa_steps": int(roa[1]),
    }


def _gym_config(env_id: str, algo: str, hybrid: Any, overrides: dict[str, Any]) -> DDPGConfig:
    """The run's :class:`~leoc.sb3.DDPGConfig` (system ``gym:ENV_ID``, :data:`GYM_DEFAULTS`
    under the overrides); a gymnasium run has no leoc step rules and keeps its final policy."""
    values = {**GYM_DEFAULTS, **overrides}
    config = DDPGConfig.for_system(f"{GYM_PREFIX}{env_id}", algo, hybrid=hybrid, **values)
    if config.step_rules:
        raise ValueError(
            f"step_rules: expected none for a gymnasium env (it steps by its own rules), found "
            f"{config.step_rules!r}"
        )
    if config.model_selection != "final":
        raise ValueError(
            f"model_selection: expected 'final' for a gymnasium run, found "
            f"{config.model_selection!r}"
        )
    return config


def _design_record(plant: GymPlant, design: HybridDesign | None) -> dict[str, Any]:
    """The plant's design as saved in the run's config (JSON-friendly)."""
    return {
        "K": plant.lqr.K.tolist(),
        "closed_loop_abs_eigenvalues": np.abs(plant.lqr.closed_loop_eigenvalues).tolist(),
        "jacobian_error": plant.jacobian_error,
        "observation_error": plant.observation_error,
        "observation_is_state": plant.observation_is_state,
        "relevance_data": None if design is None else dict(design.relevance_data),
    }


#: The file beside ``config.json`` with the plant's design (:func:`train_gym`).
DESIGN_FILE = "design.json"


def train_gym(
    env_id: str,
    algo: str = "sac",
    hybrid: bool | HybridSpec | None = None,
    seed: int = 0,
    run_dir: str | Path | None = None,
    total_steps: int | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    operating_point: tuple[Any, Any] | None = None,
    progress: bool | str = True,
    overwrite: bool = False,
    **overrides: Any,
) -> TrainResult:
    """Train SB3's DDPG, TD3 or SAC (baseline, or the LEOC hybrid) on the gymnasium env itself.

    Parameters
    ----------
    env_id : str
        A gymnasium id (``"InvertedPendulum-v5"``; MuJoCo's need the ``mujoco`` extra).
    algo : {"ddpg", "td3", "sac"}
    hybrid : HybridSpec, bool or None
        The hybrid (``True``: :class:`~leoc.policies.HybridSpec`'s default, whose floor
        ``r_min`` uses the *sampled* region) or None, the learner alone.
    seed : int
        The only seed: SB3 and the training env (``seed``), the plant's design and the sampled
        region (``seed``), the evaluation episodes (``seed + 10000 + k``).
    run_dir : optional
        Default ``runs/gym-ENV_ID/CONTROLLER/seedN``.
    total_steps : int, optional
        Environment steps (default :data:`GYM_DEFAULTS`: 10k).
    env_kwargs : mapping, optional
        Keywords of ``gymnasium.make`` (``reset_noise_scale``, ``max_episode_steps``).
    operating_point : (state, action), optional
        Default for MuJoCo envs: the rest state (:func:`gym_plant`).
    progress : bool or "lines"
        A line per evaluation, or nothing (False).
    overwrite : bool
        Replace a run folder of another configuration (else refused). The same run resumes
        from its checkpoint or, complete, is returned without training.
    **overrides
        :class:`~leoc.sb3.DDPGConfig` or :class:`~leoc.policies.HybridSpec` fields; and ``Q``,
        ``R`` (LQR weights, default identities), ``roa_samples``, ``roa_steps``
        (:func:`sample_region`), ``checkpoint_interval`` (steps, default 1000).

    Returns
    -------
    TrainResult
        Its ``policy`` maps float64 observations (B, D) to physical actions (B, F).
    """
    gym_options = (env_kwargs, operating_point)
    options = (seed, run_dir, total_steps, progress)
    run, interval = _gym_run(env_id, algo, hybrid, options, gym_options, overrides)
    resumed, done = earlier_run(run.run_path, run.config_dict, overwrite, False, progress)
    if done is not None:
        return done
    model = resumed["model"] if resumed is not None else _fresh_model(run)
    if resumed is not None and progress:
        print(f"[{algo}] resuming {run.run_path} at step {resumed['steps']}", flush=True)
    return _learn_gym(run, model, resumed, interval)


def _gym_run(
    env_id: str,
    algo: str,
    hybrid: Any,
    options: tuple[int, str | Path | None, int | None, bool | str],
    gym_options: tuple[Mapping[str, Any] | None, tuple[Any, Any] | None],
    overrides: dict[str, Any],
) -> tuple[_GymRun, int]:
    """The run :func:`train_gym` describes (``options``: seed, run folder, budget, progress;
    ``gym_options``: the env's keywords and the operating point) and its checkpoint interval;
    the gymnasium keywords popped from ``overrides``."""
    seed, run_dir, total_steps, progress = options
    env_kwargs, operating_point = gym_options
    weights = (overrides.pop("Q", None), overrides.pop("R", None))
    roa = (
        int(overrides.pop("roa_samples", ROA_SAMPLES)),
        int(overrides.pop("roa_steps", ROA_STEPS)),
    )
    interval = overrides.pop("checkpoint_interval", CHECKPOINT_INTERVAL_STEPS)
    if total_steps is not None:
        overrides["total_steps"] = total_steps
    config = _gym_config(env_id, algo, hybrid, overrides)
    settings = _gym_settings(env_kwargs, operating_point, weights, roa)
    config_dict = {**config.as_dict(), "seed": seed, "gym": settings}
    if run_dir is None:
        relevance = None if config.hybrid is None else config.hybrid.relevance
        controller = ControllerName(config.algo, relevance).name
        run_dir = run_folder(DEFAULT_RUN_ROOT, gym_folder_name(config.system), controller, seed)
    kwargs = dict(env_kwargs or {})
    return _GymRun(config, config_dict, env_id, kwargs, Path(run_dir), seed, progress), interval


def _fresh_model(run: _GymRun) -> Any:
    """Design the plant (and the hybrid), build the SB3 model on a fresh training env, and
    start the run folder (cleared, with ``config.json`` and ``design.json``)."""
    config, settings = run.config, run.config_dict["gym"]
    env = make_gym_env(run.env_id, run.env_kwargs)
    point = None if settings["state"] is None else (settings["state"], settings["action"])
    plant = gym_plant(env, run.env_id, point, settings["Q"], settings["R"], run.seed)
    design = None
    if config.hybrid is not None:
        samples, steps = settings["roa_samples"], settings["roa_steps"]
        design = gym_hybrid_design(
            config.hybrid, plant, lambda: sample_region(env, plant.lqr, samples, steps, run.seed)
        )
    env.close()
    keywords = None
    if design is not None and config.hybrid is not None:
        keywords = {"hybrid_spec": config.hybrid.to_dict(), "hybrid_design": design.to_dict()}
    train_env = StatefulEnv(make_gym_env(run.env_id, run.env_kwargs))
    model = build_model(config, run.seed, train_env, keywords)
    run.run_path.mkdir(parents=True, exist_ok=True)
    for stale in (CHECKPOINT_FILE, DESIGN_FILE, *MODEL_FILES.values(), *RUN_OUTPUTS):
        (run.run_path / stale).unlink(missing_ok=True)
    record = {**run.config_dict, "versions": library_versions()}
    write_text_atomic(run.run_path / CONFIG_FILE, json.dumps(record, indent=2))
    write_text_atomic(
        run.run_path / DESIGN_FILE, json.dumps(_design_record(plant, design), indent=2)
    )
    return model


def _progress_line(run: _GymRun) -> Callable[[dict[str, Any]], None] | None:
    """A printer of one line per evaluation row, or None without progress."""
    if not run.progress:
        return None
    total, label = run.config.total_steps, run.config.algo

    def show(row: dict[str, Any]) -> None:
        print(
            f"[{label}] {run.env_id} step {row['steps']}/{total}: mean return "
            f"{row['mean_return']:.1f}, held {row['held_fraction']:.0%}",
            flush=True,
        )

    return show


def _learn_gym(run: _GymRun, model: Any, resumed: Any, checkpoint_interval: int) -> TrainResult:
    """Train to ``total_steps`` with the evaluation and checkpoint callbacks; save the model,
    the curve and the summary (the run is complete)."""
    config, seed = run.config, run.seed
    seeds = [seed + EVAL_SEED_OFFSET + k for k in range(config.eval_episodes)]
    eval_envs = [make_gym_env(run.env_id, run.env_kwargs) for _ in seeds]
    dt = float(getattr(eval_envs[0].unwrapped, "dt", 1.0))
    model.set_logger(Logger(folder=None, output_formats=[]))
    callback = GymEvaluationCallback(
        eval_envs, seeds, config.eval_interval, dt, progress=_progress_line(run)
    )
    checkpoint_path = run.run_path / CHECKPOINT_FILE
    checkpoint = CheckpointCallback(checkpoint_path, checkpoint_interval, (callback,), resumed)
    checkpoint.restore_callbacks()
    model.learn(
        total_timesteps=config.total_steps - model.num_timesteps,
        callback=CallbackList([checkpoint, callback]),
        reset_num_timesteps=resumed is None,
    )
    save_model_atomic(model, run.run_path / MODEL_FILES["final"])
    summary = {**curve_summary(callback.curve, dt), "model_selection": "final"}
    kind = "hybrid" if config.hybrid else "baseline"
    title = f"{run.env_id} {config.algo.upper()} {kind} (seed {seed})"
    write_curve(run.run_path, callback.curve, summary, title)
    checkpoint_path.unlink(missing_ok=True)
    for env in eval_envs:
        env.close()
    policy = physical_policy(model.actor)
    return TrainResult(policy, run.run_path, callback.curve, run.config_dict, summary, model)


class GymController:
    """A trained gymnasium run's controller as a callable ``observation -> action``.

    ``policy`` is its float64 physical-units actor (:func:`~leoc.sb3.physical_policy`); a call
    takes one observation (D,) or a batch (B, D) and returns the action (F,) or (B, F) as a
    float64 array, in the env's units and inside its action space.
    """

    def __init__(self, policy: torch.nn.Module) -> None:
        self.policy = policy

    def __call__(self, observation: Any) -> np.ndarray:
        """The deterministic action of ``observation``."""
        values = torch.as_tensor(np.asarray(observation, dtype=np.float64))
        with torch.no_grad():
            action = self.policy(values.reshape(-1, values.shape[-1]))
        out = action.numpy()
        return out[0] if values.ndim == 1 else out


def load_gym_controller(run_dir: str | Path) -> GymController:
    """The controller of a gymnasium run folder (:func:`train_gym`): its final model.

    Raises
    ------
    ValueError
        A run folder of a leoc system rather than a gymnasium env.
    """
    config = json.loads((Path(run_dir) / CONFIG_FILE).read_text()) if Path(run_dir).is_dir() else {}
    if gym_env_id(str(config.get("system", ""))) is None:
        raise ValueError(
            f"run_dir: expected a gymnasium run folder (system gym:ENV_ID), found "
            f"{str(run_dir)!r} with system {config.get('system')!r}"
        )
    return GymController(physical_policy(load_ddpg_model(run_dir).actor))
