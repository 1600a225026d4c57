r"""Impulse and step responses of a controller on a gymnasium environment itself.

leoc's response tests (:mod:`leoc.evaluation.rollout`) disturb the action of a leoc system's
torch step. A gymnasium env (:mod:`leoc.gym_adapter`, :mod:`leoc.sb3.gym`) has no such step, so
the disturbance goes through a wrapper of the env's action (:class:`ActionPerturbation`), and
the protocol is:

1. the env is made (``gymnasium.make(env_id, **env_kwargs)``, its time limit set to ``steps``
   when given), reset with ``seed``, and its state set to the operating state ``x_eq`` of the
   plant (:func:`~leoc.gym_adapter.state_access`: MuJoCo's ``set_state``, classic control's
   ``state``); the first observation is the env's ``_get_obs()`` there;
2. **impulse**: the action of the first env step is *forced* to ``magnitude`` (default the
   action space's upper limit), whatever the controller asked; the controller acts alone for
   every later step. **step**: ``magnitude`` (default :data:`STEP_FRACTION` of the upper
   limit) is *added* to every action. Every perturbed action is clipped to the action space
   (the actuator's limit) and passed in the controller's own floating-point type, so that a
   step of 0 is exactly the unperturbed run (``Pendulum-v1`` computes in the action's type);
3. the run lasts until the env's own time limit (or ``steps``) truncates it, or until the env
   terminates it (recorded as ``terminated``; the record is then shorter).

The recorded signal is the deviation of one state coordinate, the *main coordinate*
``x[main_index] - x_eq[main_index]``: by default the pole's hinge angle for the envs of
:data:`MAIN_COORDINATES` (``InvertedPendulum-v5``: ``qpos[1]``; ``InvertedDoublePendulum-v5``:
``qpos[1]``, the lower hinge; ``Pendulum-v1``: ``theta``), in degrees and wrapped to
:math:`(-180, 180]`; for any other env state entry 0 in the state's own units, unless
``main_index`` says otherwise (an index of an angle listed there is in degrees too). Its
metrics are leoc's (:func:`~leoc.evaluation.metrics.response_metrics`: final-window mean,
overshoot, peak deviation, settling time in the band 2 % of the peak error, or an absolute
``band``), with ``dt`` the env's own step (``env.unwrapped.dt``).

:func:`gym_comparison` runs the same test for a trained controller and for the plant's LQR
(the hybrid's linear part :math:`G(o) = W o + b` clipped to the action space,
:func:`lqr_controller`) and reports the largest difference of the two deviations in percent
of the LQR's peak (:func:`~leoc.evaluation.lqr_agreement.response_distance`): does the hybrid
keep its LQR.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

from leoc.evaluation.lqr_agreement import response_distance
from leoc.evaluation.metrics import ResponseMetrics, response_metrics
from leoc.gym_adapter import state_access
from leoc.sb3.gym import DESIGN_FILE, GymPlant, gym_plant, load_gym_controller, make_gym_env
from leoc.training import CONFIG_FILE

__all__ = [
    "GYM_RESPONSE_TESTS",
    "K_RTOL",
    "MAIN_COORDINATES",
    "STEP_FRACTION",
    "ActionPerturbation",
    "GymResponse",
    "GymRun",
    "gym_comparison",
    "gym_response",
    "held_episodes",
    "load_gym_run",
    "lqr_controller",
    "main_coordinate",
]

#: The response tests on a gymnasium env: the action forced for one step, or offset for all.
GYM_RESPONSE_TESTS = ("impulse", "step")
#: The step test's default offset, as a fraction of the action space's upper limit (leoc's
#: pendulum step, -0.2 with a limit of 2, is the same fraction).
STEP_FRACTION = 0.1
#: Default main coordinate per env id: (state index, an angle reported in degrees).
MAIN_COORDINATES: dict[str, tuple[int, bool]] = {
    "InvertedPendulum-v5": (1, True),
    "InvertedDoublePendulum-v5": (1, True),
    "Pendulum-v1": (0, True),
}
#: Agreement of a run's recorded ``K`` (``design.json``) with the LQR redesigned from its config.
K_RTOL = 1e-9


class ActionPerturbation(gym.ActionWrapper):
    """The env with its actions disturbed: ``forced`` replaces the action of the env step of
    that index (counted from the last reset), ``offset`` is added to every other one; each
    result is clipped to the action space."""

    def __init__(self, env: gym.Env, forced: Mapping[int, Any] | None, offset: Any) -> None:
        super().__init__(env)
        self.forced = {int(k): np.asarray(v, dtype=float) for k, v in (forced or {}).items()}
        self.offset = np.asarray(offset, dtype=float)
        self.count = 0

    def reset(self, **kwargs: Any) -> Any:
        """Reset the env and the step count."""
        self.count = 0
        return self.env.reset(**kwargs)

    def action(self, action: Any) -> np.ndarray:
        """The disturbed action of the current step, clipped to the action space, in the
        controller's floating-point type (so an offset of 0 leaves the action as it was)."""
        asked = np.asarray(action)
        value = self.forced.get(self.count)
        if value is None:
            value = asked + self.offset
        self.count += 1
        space = self.action_space
        value = np.clip(value, np.asarray(space.low, float), np.asarray(space.high, float))
        return value.astype(asked.dtype if asked.dtype.kind == "f" else np.float64)


class GymResponse(NamedTuple):
    """One response: the test, its ``magnitude`` (F,), the states (T + 1, S) and actions
    (T, F) the controller asked for, the main coordinate's ``deviation`` (T + 1,) in ``unit``,
    its metrics, the return and whether the env terminated the run."""

    test: str
    magnitude: np.ndarray
    states: np.ndarray
    actions: np.ndarray
    deviation: np.ndarray
    unit: str
    main_index: int
    metrics: ResponseMetrics
    total_reward: float
    terminated: bool


def main_coordinate(env_id: str, size: int, main_index: int | None = None) -> tuple[int, bool]:
    """The main coordinate's state index and whether it is an angle in degrees (module
    docstring); a one-line error for an index outside the state."""
    default, in_degrees = MAIN_COORDINATES.get(env_id, (0, False))
    if main_index is None:
        return default, in_degrees
    if not 0 <= int(main_index) < size:
        raise ValueError(
            f"main_index: expected a state index in [0, {size - 1}] of {env_id!r}, found "
            f"{main_index}"
        )
    return int(main_index), in_degrees and int(main_index) == default


def _magnitude(plant: GymPlant, test: str, magnitude: Any) -> np.ndarray:
    """The impulse's forced action or the step's offset, checked (shape, inside the space)."""
    high, low = plant.lqr.action_high, plant.lqr.action_low
    if test not in GYM_RESPONSE_TESTS:
        raise ValueError(f"test: expected one of {GYM_RESPONSE_TESTS}, found {test!r}")
    if magnitude is None:
        return high.copy() if test == "impulse" else STEP_FRACTION * high
    value = np.broadcast_to(np.asarray(magnitude, dtype=float), high.shape).copy()
    if test == "impulse" and (np.any(value < low) or np.any(value > high)):
        raise ValueError(
            f"magnitude: expected an impulse action inside the action space [{low.tolist()}, "
            f"{high.tolist()}], found {value.tolist()}"
        )
    return value


def gym_response(
    plant: GymPlant,
    controller: Callable[[np.ndarray], Any],
    test: str = "impulse",
    *,
    env_kwargs: Mapping[str, Any] | None = None,
    steps: int | None = None,
    magnitude: Any = None,
    main_index: int | None = None,
    band: float | None = None,
    seed: int = 0,
) -> GymResponse:
    """The impulse or step response of ``controller`` (observation -> action) on the env of
    ``plant`` from its operating state (module docstring).

    Parameters
    ----------
    plant : GymPlant
        The env id, operating state and action bounds (:func:`~leoc.sb3.gym_plant`).
    controller : callable
        Maps one observation (D,) to an action (F,).
    test : {"impulse", "step"}
    env_kwargs : mapping, optional
        Keywords of ``gymnasium.make`` (a run's own).
    steps : int, optional
        Episode length; default the env's own time limit.
    magnitude : float or array (F,), optional
        The impulse's forced action (default the upper limit) or the step's offset (default
        :data:`STEP_FRACTION` of it).
    main_index : int, optional
        The recorded state entry (:func:`main_coordinate`).
    band : float, optional
        Absolute settling band in the deviation's unit (default 2 % of the peak error).
    seed : int
        Seed of the env's reset (before the state is set).
    """
    value = _magnitude(plant, test, magnitude)
    index, in_degrees = main_coordinate(plant.env_id, plant.state.size, main_index)
    kwargs = dict(env_kwargs or {})
    if steps is not None:
        kwargs["max_episode_steps"] = int(steps)
    base_env = make_gym_env(plant.env_id, kwargs)
    impulse = test == "impulse"
    env = ActionPerturbation(base_env, {0: value} if impulse else None, 0.0 if impulse else value)
    record, actions, total, terminated = _episode(env, plant.state, controller, seed)
    dt = float(base_env.unwrapped.dt)
    base_env.close()
    deviation = record[:, index] - plant.state[index]
    if in_degrees:
        deviation = np.degrees(np.angle(np.exp(1j * deviation)))
    metrics = response_metrics(deviation, band, dt=dt, terminated=bool(terminated))
    unit = "deg" if in_degrees else "state units"
    fields = (record, actions, deviation, unit, index, metrics, total, terminated)
    return GymResponse(test, value, *fields)


def _episode(
    env: ActionPerturbation, state: np.ndarray, controller: Callable[[np.ndarray], Any], seed: int
) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """One episode of ``controller`` on the perturbed ``env`` from ``state`` (set after the
    seeded reset) to truncation or termination: the states (T + 1, S), the actions the
    controller asked for (T, F), the return and whether the env terminated it."""
    env.reset(seed=seed)
    access = state_access(env.env)
    access.set(state)
    observation = env.unwrapped._get_obs()  # as the env shows it (its dtype)
    states, actions, total = [np.array(access.get(), dtype=float)], [], 0.0
    shape = env.action_space.shape
    while True:
        action = np.asarray(controller(observation)).reshape(shape)
        observation, reward, terminated, truncated, _ = env.step(action)
        states.append(np.array(access.get(), dtype=float))
        actions.append(action.astype(float))
        total += float(reward)
        if terminated or truncated:
            return np.stack(states), np.stack(actions), total, bool(terminated)


def lqr_controller(plant: GymPlant) -> Callable[[np.ndarray], np.ndarray]:
    """The plant's LQR on the observation, ``clip(W o + b)`` (the hybrid's linear part ``G``
    clipped to the action space)."""
    low, high = plant.lqr.action_low, plant.lqr.action_high

    def act(observation: np.ndarray) -> np.ndarray:
        return np.clip(plant.gain @ np.asarray(observation, dtype=float) + plant.bias, low, high)

    return act


def gym_comparison(
    plant: GymPlant, controller: Callable[[np.ndarray], Any], test: str = "impulse", **options
) -> dict[str, Any]:
    """The same test of ``controller`` and of the plant's LQR (:func:`lqr_controller`), and
    ``distance_pct``, the largest difference of their deviations in percent of the LQR's peak
    (infinite when only one of them terminated). ``options``: those of :func:`gym_response`."""
    ours = gym_response(plant, controller, test, **options)
    lqr = gym_response(plant, lqr_controller(plant), test, **options)
    return {
        "controller": ours,
        "lqr": lqr,
        "distance_pct": response_distance(ours.deviation, lqr.deviation),
    }


class GymRun(NamedTuple):
    """A gymnasium run folder loaded for evaluation: its plant (redesigned from its config and
    checked against ``design.json``), its controller, the env's keywords and its seed."""

    plant: GymPlant
    controller: Callable[[np.ndarray], np.ndarray]
    env_kwargs: dict[str, Any]
    seed: int
    sampled_rho: float | None


def load_gym_run(run_dir: str | Path) -> GymRun:
    """The plant and controller of a run folder of :func:`~leoc.sb3.train_gym`.

    Raises
    ------
    ValueError
        Not a gymnasium run, or an LQR redesigned from its config that is not the one in its
        ``design.json`` (another version of the env or of leoc).
    """
    controller = load_gym_controller(run_dir)  # refuses a run of a leoc system
    folder = Path(run_dir)
    config = json.loads((folder / CONFIG_FILE).read_text())
    settings, seed = config["gym"], int(config.get("seed", 0))
    env_id = str(config["system"]).split(":", 1)[1]
    env = make_gym_env(env_id, settings["env_kwargs"])
    point = None if settings["state"] is None else (settings["state"], settings["action"])
    plant = gym_plant(env, env_id, point, settings["Q"], settings["R"], seed)
    env.close()
    design = json.loads((folder / DESIGN_FILE).read_text())
    if not np.allclose(plant.lqr.K, design["K"], rtol=K_RTOL, atol=0.0):
        raise ValueError(
            f"run_dir: expected the LQR redesigned from {folder / CONFIG_FILE} to equal the "
            f"recorded one, found K {plant.lqr.K.tolist()} against {design['K']} in "
            f"{folder / DESIGN_FILE}"
        )
    rho = (design.get("relevance_data") or {}).get("rho")
    sampled = None if rho is None else float(rho)
    return GymRun(plant, controller, dict(settings["env_kwargs"]), seed, sampled)


def held_episodes(
    env_id: str,
    env_kwargs: Mapping[str, Any],
    controller: Callable[[np.ndarray], Any],
    seeds: Sequence[int],
) -> dict[str, list]:
    """One deterministic episode of ``controller`` (observation -> action) per seed, from
    ``reset(seed=seed)`` of ``gymnasium.make(env_id, **env_kwargs)`` to its time limit or
    termination: the ``returns``, ``held`` (truncated, not terminated) and ``steps`` of each."""
    env = make_gym_env(env_id, env_kwargs)
    record: dict[str, list] = {"returns": [], "held": [], "steps": []}
    for seed in seeds:
        observation, _ = env.reset(seed=int(seed))
        total, steps = 0.0, 0
        while True:
            action = np.asarray(controller(observation), dtype=float)
            observation, reward, terminated, truncated, _ = env.step(action)
            total, steps = total + float(reward), steps + 1
            if terminated or truncated:
                break
        record["returns"].append(total)
        record["held"].append(bool(truncated and not terminated))
        record["steps"].append(steps)
    env.close()
    return record
