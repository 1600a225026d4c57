"""Gymnasium environments built on the pure step functions of :mod:`leoc.systems`.

Every system's environment is a :class:`LeocEnv` (the paper's three have documented subclasses;
a registered system gets the generic class, ``LeocEnv(system=name)``): ``episode_steps``-step
episodes (a ``TimeLimit`` added by ``gymnasium.make``), float64 observations bounded by the
observation map, a continuous action clipped to the actuator limit, and ``reset(options=...)``
with

* ``{"start": "swing_up"}`` (the default): the swing-up start distribution;
* ``{"start": "operating_point", "offset": [...]}``: the operating point plus an optional state
  offset (for response and robustness tests);
* ``{"state": [...]}``: an explicit initial state.

Perturbations (:mod:`leoc.systems.perturbations`): ``perturbations=[...]`` makes the env step
a :class:`~leoc.systems.perturbations.PerturbedPlant`, the same object every rollout steps, so
the env and :func:`~leoc.systems.rollout.simulate` see the same plant (and, from a fresh env or
a reset without a seed, the same random draws as a ``simulate`` call with batch 1). A
``reset(seed=s)`` restarts the perturbations' streams from their seeds and ``s``. The info's
``state`` is the plant's true state; the observation is what the controller sees.

Training under perturbation: ``plants=EpisodePlants(...)``
(:class:`~leoc.systems.perturbation_levels.EpisodePlants`) gives each episode its own plant,
built at every ``reset`` (episode ``k``'s fixed and drawn levels, from the run's seed), in place
of one fixed list; the observation space is that of the widest plant (unbounded on the entries
any episode makes noisy).

Rendering, as gymnasium's classic control: ``render_mode`` ``None``, ``"rgb_array"``
(``render()`` returns the ``(H, W, 3)`` uint8 frame of the current state) or ``"human"`` (a
matplotlib window, redrawn by ``reset`` and ``step`` at ``metadata["render_fps"]`` = 1 / dt).
The drawing lives apart from the physics, in :mod:`leoc.systems.rendering` (the hook for a
user's system is there too).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
import torch

from leoc.systems.base import DTYPE, START_KINDS, PhysicalParams, System
from leoc.systems.cartpole import CartPole
from leoc.systems.mountaincar import MountainCar
from leoc.systems.pendulum import Pendulum
from leoc.systems.perturbation_levels import EpisodePlants
from leoc.systems.perturbations import Perturbation, PerturbedPlant
from leoc.systems.registry import env_id, make_system
from leoc.systems.rendering import RENDER_MODES, Renderer

RESET_OPTION_KEYS = ("start", "offset", "state")


class LeocEnv(gym.Env[np.ndarray, np.ndarray]):
    """A gymnasium view of a :class:`~leoc.systems.base.System`.

    Parameters
    ----------
    params : PhysicalParams, optional
        Physical constants (defaults of the system when omitted).
    start : {"swing_up", "operating_point"}
        Default start used when ``reset`` gets no ``start`` option.
    system : System or str, optional
        The system (a registered name is resolved through the registry; this is how
        ``gymnasium.make`` builds the env of a user's system). Default: ``system_type(params)``
        of the subclass.
    render_mode : {None, "rgb_array", "human"}
        gymnasium's render mode (see the module docstring). A system that cannot be drawn
        accepts every mode and raises a one-line ``ValueError`` on the first frame.
    perturbations : sequence of Perturbation, optional
        The plant's perturbations (module docstring); none by default.
    action_repeat : int
        Simulator steps per decision of the agent that drives the env (each ``step`` is one
        simulator step); it only converts an action delay's periods into steps.
    plants : EpisodePlants, optional
        A plant per episode (module docstring), instead of ``perturbations``.
    """

    # render_fps is set per instance from the system's dt (gymnasium reads the class's
    # render_modes before building the env, and the instance's render_fps after).
    metadata: ClassVar[dict[str, Any]] = {"render_modes": list(RENDER_MODES)}
    system_type: ClassVar[type[System]]

    def __init__(
        self,
        params: PhysicalParams | None = None,
        start: str = "swing_up",
        system: System | str | None = None,
        render_mode: str | None = None,
        perturbations: Sequence[Perturbation] = (),
        action_repeat: int = 1,
        plants: EpisodePlants | None = None,
    ) -> None:
        if start not in START_KINDS:
            raise ValueError(f"start: expected one of {START_KINDS}, found {start!r}")
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode: expected None or one of {RENDER_MODES}, found {render_mode!r}"
            )
        if isinstance(system, str):
            system = make_system(system, params)
        elif system is None:
            if not hasattr(self, "system_type"):
                raise ValueError("system: expected a System or a registered name, found None")
            system = self.system_type(params)
        elif params is not None:
            raise ValueError("params: only with a system name, found a System object as well")
        self.system = system
        self.plants = plants
        if plants is None:
            self.plant = PerturbedPlant(system, perturbations, action_repeat)
        elif tuple(perturbations):
            raise ValueError("perturbations: expected none with plants (a plant per episode)")
        else:
            self.plant = plants.widest()  # the reset builds each episode's own
        self.default_start = start
        limit = np.float32(self.system.action_limit)
        shape = (self.system.action_dim,)
        self.action_space = gym.spaces.Box(-limit, limit, shape=shape, dtype=np.float32)
        high = self.plant.observation_bounds()
        self.observation_space = gym.spaces.Box(-high, high, dtype=np.float64)
        self.state: np.ndarray | None = None
        self._steps = 0  # steps taken in this episode
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.system.dt}
        self._renderer: Renderer | None = None  # built on the first frame

    def _obs(self) -> np.ndarray:
        assert self.state is not None
        state = torch.as_tensor(self.state, dtype=DTYPE).unsqueeze(0)
        with torch.no_grad():
            obs = self.plant.observe(state)[0].numpy()
        return np.clip(obs, self.observation_space.low, self.observation_space.high)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; ``options={"start": "operating_point", "offset": [...]}`` starts at
        the operating point (plus an offset), the default is the swing-up start.

        Returns the observation and ``{"state": state}``.
        """
        super().reset(seed=seed)
        self._steps = 0
        plants = getattr(self, "plants", None)  # an env pickled before it had plants: None
        if plants is not None:
            self.plant = plants.next()
        self.plant.reset(1, seed)
        options = dict(options or {})
        unknown = set(options) - set(RESET_OPTION_KEYS)
        if unknown:
            raise ValueError(
                f"options: unknown keys {sorted(unknown)}; expected some of {RESET_OPTION_KEYS}"
            )
        if "state" in options:
            state = np.asarray(options["state"], dtype=float)
            if state.shape != (self.system.state_dim,) or not np.all(np.isfinite(state)):
                raise ValueError(
                    f"options['state']: expected {self.system.state_dim} finite numbers "
                    f"({', '.join(self.system.state_names)}), found {options['state']!r}"
                )
            self.state = state.copy()
        else:
            kind = options.get("start", self.default_start)
            self.state = self.system.sample_start(self.np_random, kind, options.get("offset"))
        if self.render_mode == "human":
            self.render()
        return self._obs(), {"state": self.state.copy()}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One simulator step: ``(obs, reward, terminated, truncated, {"state": state})``."""
        if self.state is None:
            raise RuntimeError("step() called before reset()")
        action_arr = np.asarray(action, dtype=float).reshape(-1)
        if action_arr.shape != self.action_space.shape or not np.all(np.isfinite(action_arr)):
            raise ValueError(
                f"action: expected {self.system.action_dim} finite numbers, found {action!r}"
            )
        self._steps += 1
        state_t = torch.as_tensor(self.state, dtype=DTYPE).unsqueeze(0)
        action_t = torch.as_tensor(action_arr, dtype=DTYPE).unsqueeze(0)
        plant = self.plant.system
        with torch.no_grad():
            next_state = self.plant.step(state_t, action_t).state
            leaving = plant.out_of_bounds(next_state)
            left_after = max(0, plant.episode_steps - self._steps)
            reward = float(plant.step_reward(state_t, action_t, next_state, leaving, left_after)[0])
            terminated = bool(leaving[0])
        self.state = next_state[0].numpy()
        if self.render_mode == "human":
            self.render()
        return self._obs(), reward, terminated, False, {"state": self.state.copy()}

    def render(self) -> np.ndarray | None:
        """The frame of the current state: ``(H, W, 3)`` uint8 in ``rgb_array`` mode; drawn in
        the window (returning None) in ``human`` mode; None without a render mode (gymnasium
        warns then).

        Raises
        ------
        RuntimeError
            Before ``reset()``.
        ValueError
            If the system cannot be drawn (:func:`~leoc.systems.rendering.drawer_for`).
        """
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or "
                "'human' when making the env"
            )
            return None
        if self.state is None:
            raise RuntimeError("render() called before reset()")
        if self._renderer is None:
            self._renderer = Renderer(self.system, self.render_mode)
        return self._renderer.frame(self.state)

    def close(self) -> None:
        """Close the render window (if any)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class PendulumSwingUpEnv(LeocEnv):
    """Pendulum swing-up (``leoc/PendulumSwingUp-v0``), the dynamics of gymnasium's Pendulum-v1.

    ==============  ===========================================================
    State           theta (rad, 0 upright, unwrapped), theta_dot (rad/s)
    Observation     [cos theta, sin theta, theta_dot], float64
    Action          torque u in N m, ``|u|`` <= 2 (clipped)
    Dynamics        theta_ddot = 3 g / (2 l) sin theta + 3 / (m l^2) u,
                    semi-implicit Euler, dt = 0.05 s, ``|theta_dot|`` <= 8 rad/s
    Reward          -(theta^2 + 0.1 theta_dot^2 + 0.001 u^2), theta wrapped to [-pi, pi)
    Start           swing_up: theta = pi +/- 10 deg, theta_dot = 0 +/- 0.1 (uniform);
                    operating_point: [0, 0] (+ offset)
    Termination     none; truncation after 200 steps
    Parameters      g = 10 m/s^2, m = 1 kg, l = 1 m (:class:`PendulumParams`)
    ==============  ===========================================================
    """

    system_type = Pendulum


class CartPoleSwingUpEnv(LeocEnv):
    """Cart-pole swing-up with a continuous force (``leoc/CartPoleSwingUp-v0``).

    ==============  ===========================================================
    State           x (m), x_dot (m/s), theta (rad, 0 upright), theta_dot (rad/s)
    Observation     [x, x_dot, cos theta, sin theta, theta_dot], float64
    Action          force F in N on the cart, ``|F|`` <= 2.5 (clipped)
    Dynamics        tmp = (F + m_p l theta_dot^2 sin theta) / (m_c + m_p),
                    theta_ddot = (g sin theta - cos theta tmp)
                    / (l (4/3 - m_p cos^2 theta / (m_c + m_p))),
                    x_ddot = tmp - m_p l theta_ddot cos theta / (m_c + m_p),
                    explicit Euler, dt = 0.02 s
    Reward          -0.1 (5 theta^2 + x^2 + 0.005 F^2), theta wrapped;
                    leaving ``|x|`` <= 2.4 earns the worst on-track reward for that step
                    and every step left (:meth:`System.termination_reward`)
    Start           swing_up: [0, 0, pi, 0] +/- [0.1, 0.1, 10 deg, 0.1] (uniform);
                    operating_point: [0, 0, 0, 0] (+ offset)
    Termination     ``|x|`` > 2.4; truncation after 200 steps
    Parameters      m_c = 0.05 kg, m_p = 0.005 kg, l = 0.5 m (half-length), g = 9.8 m/s^2
    ==============  ===========================================================
    """

    system_type = CartPole


class MountainCarHilltopEnv(LeocEnv):
    """Mountain car that must reach and stay on the hilltop (``leoc/MountainCarHilltop-v0``).

    ==============  ===========================================================
    State           x (m, hilltop at 0, valley at -pi), x_dot (m/s)
    Observation     [x, x_dot], float64
    Action          force F in N, ``|F|`` <= 3 (clipped)
    Dynamics        x_ddot = F / m - g h'(x), h(x) = 1.35 cos x + 1.65,
                    semi-implicit Euler, dt = 0.02 s
    Reward          -0.1 (5 x^2 + x_dot^2 + 0.005 F^2); leaving [-3.6 - pi/2, 2.2 - pi/2]
                    earns the worst on-track reward for that step and every step left
    Start           swing_up: x = -pi +/- 10 deg, x_dot = 0 +/- 0.1 (uniform);
                    operating_point: [0, 0] (+ offset)
    Termination     leaving the track; truncation after 200 steps
    Parameters      m = 0.1 kg, g = 9.8 m/s^2
    ==============  ===========================================================
    """

    system_type = MountainCar


# The built-in systems' gymnasium ids and env classes (registered by leoc.systems).
BUILTIN_ENVS: dict[str, tuple[str, type[LeocEnv]]] = {
    "pendulum": ("leoc/PendulumSwingUp-v0", PendulumSwingUpEnv),
    "cartpole": ("leoc/CartPoleSwingUp-v0", CartPoleSwingUpEnv),
    "mountaincar": ("leoc/MountainCarHilltop-v0", MountainCarHilltopEnv),
}


def make_env(system: str | System, params: PhysicalParams | None = None, **kwargs: Any) -> Any:
    """A gymnasium environment (with the episode's ``TimeLimit``) of a system or system name.

    A name goes through ``gymnasium.make`` of its registered id; a ``System`` object is
    wrapped directly (so a scaled or unregistered system needs no registration).
    """
    if isinstance(system, System):
        from gymnasium.wrappers import TimeLimit

        if params is not None:
            raise ValueError("params: only with a system name, found a System object as well")
        env = LeocEnv(system=system, **kwargs)
        return TimeLimit(env, max_episode_steps=system.episode_steps)
    return gym.make(env_id(system), params=params, **kwargs)
