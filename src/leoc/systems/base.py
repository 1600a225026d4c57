"""The ``System`` protocol: what a plant must provide to work with every part of leoc.

Every system is described by

* a frozen parameter dataclass (physical constants with units, derived quantities as
  properties, :meth:`PhysicalParams.scaled` to build perturbed copies for robustness sweeps);
* a pure, batched, differentiable step function in torch (float64), the single source of truth
  used by the gymnasium environment, the linearisation, PILCO and the robustness sweeps;
* a :class:`System` subclass that bundles the step function with the observation map, reward,
  termination test, operating point and start distribution.

Writing a system (``docs/user_guide/custom_system.md`` has a worked example). A subclass must
provide:

============================  =================================================================
``name``                      registry name (lower-case identifier)
``params_type``               its :class:`PhysicalParams` dataclass; it must have a field ``dt``
                              (time step, s) or the subclass overrides :attr:`System.dt`
``state_names``               names of the S state entries
``obs_layout``                the observation (see :mod:`leoc.systems.observation`): every
                              state entry as itself (``state_entry(i)``) or, for an angle,
                              through cos and sin (``*angle_entries(i)``)
``action_limit``              property: the actuator limit ``|u| <= action_limit`` (> 0)
``step_fn(state, action)``    batched step ``(B, S), (B, A) -> (B, S)``, torch float64,
                              differentiable, clipping the action to the limit inside
``reward_fn(state, action)``  reward ``(B,)`` of the step (before it)
``swing_up_centre``,          the swing-up start: uniform in centre +/- spread (S each)
``start_spread``
``operating_region``          half-widths (S) of the box robustness episodes start from
``default_q``,                diagonals of the default LQR weights (S and A entries)
``default_r``
``main_label``,               the response's main coordinate (``main_index``, default 0) and
``main_in_degrees``           whether it is an angle reported in degrees
``settling_band``,            settling band of the metrics, hold band and minimum hold
``hold_band``,                duration (steps) of the "reached and held" test, in the units of
``hold_min_steps``            the main coordinate
============================  =================================================================

and may override, with these defaults:

==========================  =================================================================
``operating_state``         the origin (S zeros)
``u_eq``                    zeros (A); ``(operating_state, u_eq)`` must be an equilibrium of
                            ``step_fn``, which :meth:`System.validate` checks
``angle_indices``           the angles of the observation map
``out_of_bounds(state)``    never; the step that leaves the allowed region earns
                            ``out_of_bounds_reward`` (0) for itself and for every step the
                            episode would still have run (:meth:`System.termination_reward`)
``cost_factor()``           PILCO's cost on the main coordinate's observation entries
``continuous_model()``      none (only the optional continuous-time LQR design needs it)
``episode_steps``           200
``velocity_indices``        none: the state entries that are generalised velocities, one per
                            degree of freedom (friction and pushes act on them,
                            :mod:`leoc.systems.perturbations`)
``forced_step_fn(...)``     raises: ``step_fn(state, action)`` with generalised forces
                            ``force(state)`` ``(B, V)`` (one per entry of
                            ``velocity_indices``) added to the dynamics beside the clipped
                            actuator (friction needs it)
==========================  =================================================================

:meth:`System.validate` (run by :func:`~leoc.systems.registry.register_system`) checks shapes,
signs, the observation layout and the equilibrium, and raises a ``ValueError`` that names the
system, the attribute, what was expected and what was found.

Shapes: ``B`` batch, ``S`` state dimension, ``O`` observation dimension, ``A`` action dimension.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from functools import cached_property
from typing import Any, ClassVar, Literal

import numpy as np
import torch
from torch import Tensor

from leoc.systems.observation import ObsComponent, ObservationMap

#: The dtype of every state, action and parameter tensor.
DTYPE = torch.float64
#: Episode length (steps) of every built-in system.
DEFAULT_EPISODE_STEPS = 200
# validate(): largest |f(a, u_eq) - a| (state units, angles wrapped) accepted as an equilibrium.
# Float64 round-off of one step is ~1e-16 times the state's size; 1e-9 leaves room for it and
# rejects any physical error.
EQUILIBRIUM_TOL = 1e-9
# validate(): states probed by the shape and finiteness checks of step_fn and reward_fn.
VALIDATION_BATCH = 3
REQUIRED_ATTRIBUTES = (
    "name",
    "params_type",
    "state_names",
    "obs_layout",
    "swing_up_centre",
    "start_spread",
    "operating_region",
    "default_q",
    "default_r",
    "main_label",
    "main_in_degrees",
    "settling_band",
    "hold_band",
    "hold_min_steps",
)
#: Start distributions: the swing-up start and the operating point (responses, robustness).
START_KINDS = ("swing_up", "operating_point")
StartKind = Literal["swing_up", "operating_point"]


def wrap_angle(angle: Tensor) -> Tensor:
    """Wrap an angle to ``[-pi, pi)``, exactly as gymnasium's ``angle_normalize``."""
    return torch.remainder(angle + math.pi, 2.0 * math.pi) - math.pi


def _check_positive(label: str, attribute: str, value: Any) -> None:
    """Raise naming ``attribute`` of system ``label`` unless ``value`` is a positive number."""
    if not isinstance(value, (int, float, np.floating)) or not math.isfinite(value) or value <= 0:
        raise ValueError(
            f"{label}: {attribute}: expected a positive finite number, found {value!r}"
        )


def _returned_tensor(label: str, method: str, value: Any, expected: str) -> Tensor:
    """``value`` if ``method`` of system ``label`` returned a torch tensor, else raise naming the
    method, ``expected`` and what it returned (a body left as ``...`` or ``pass`` returns None)."""
    if not isinstance(value, Tensor):
        hint = " (a body left as '...' or 'pass' returns None)" if value is None else ""
        raise ValueError(f"{label}: {method}: expected {expected}, found {value!r}{hint}")
    return value


def check_repeat(repeat: Any) -> int:
    """A control period in simulator steps: a positive integer (raises naming ``action_repeat``)."""
    if isinstance(repeat, bool) or not isinstance(repeat, (int, np.integer)) or repeat < 1:
        raise ValueError(f"action_repeat: expected a positive integer, found {repeat!r}")
    return int(repeat)


def as_state_tensor(value: Any, dim: int, name: str) -> Tensor:
    """Convert ``value`` to a float64 tensor of shape ``(B, dim)`` (a 1-D input gets ``B = 1``).

    Raises
    ------
    ValueError
        If the trailing dimension is not ``dim`` or the input has more than two dimensions.
    """
    tensor = torch.as_tensor(value, dtype=DTYPE)
    if tensor.ndim == 1:
        tensor = tensor.unsqueeze(0)
    if tensor.ndim != 2 or tensor.shape[-1] != dim:
        raise ValueError(
            f"{name}: expected shape ({dim},) or (B, {dim}), found {tuple(tensor.shape)}"
        )
    return tensor


@dataclasses.dataclass(frozen=True)
class StepRules:
    """How a step is rewarded, ended and integrated, where implementations of a task differ.

    leoc's defaults are the fields' defaults; the authors' variant (nrjc/LEOC, see
    :mod:`leoc.experiments.variants`) sets the others. A system built with
    :meth:`System.with_rules` applies them in its gymnasium environment and in every rollout
    alike (:meth:`System.step_reward`).

    Attributes
    ----------
    exit_penalty : float or None
        ``None`` (leoc): the step that leaves the allowed region earns
        :meth:`System.termination_reward`, the worst on-track reward for it and for every step
        left, so leaving never pays. A number ``p``: that step earns its own reward plus ``p``
        once (nrjc/LEOC ``dao/envs/cartpole_env.py`` and ``mountaincar_env.py``: -100), which
        can pay (an immediate exit from the cart-pole's start costs about -143, hanging for 200
        steps about -987).
    reward_on_next_state : bool
        ``False`` (leoc, gym's pendulum): the reward of ``(state, action)`` before the step.
        ``True``: of ``(next_state, action)`` (nrjc/LEOC's cart-pole and mountain car).
    legacy_integrator : bool
        The integrator of the gym release the authors used, where a system's simulator changed
        since (the system's ``step_fn`` documents it; today the pendulum: gym 0.17's
        ``sin(theta + pi)`` form and speed clip after the position update).
    horizon_exit : bool
        With ``exit_penalty=None`` only. ``False`` (leoc): the exit step is charged for the
        steps actually left, so the same exit costs about -1061 at the cart-pole's first step
        and about -5 at its last; the observation does not show the time, so for a learner
        the same transition has rewards two orders of magnitude apart. ``True``: it is charged
        for a whole episode (``episode_steps`` steps, or the steps left if a longer rollout has
        more) whenever it happens: one reward per transition, and still never paying.
    """

    exit_penalty: float | None = None
    reward_on_next_state: bool = False
    legacy_integrator: bool = False
    horizon_exit: bool = False

    def __post_init__(self) -> None:
        penalty = self.exit_penalty
        if penalty is not None and (
            isinstance(penalty, bool)
            or not isinstance(penalty, (int, float))
            or not math.isfinite(penalty)
        ):
            raise ValueError(f"exit_penalty: expected None or a finite number, found {penalty!r}")
        for name in ("reward_on_next_state", "legacy_integrator", "horizon_exit"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected a bool, found {getattr(self, name)!r}")
        if self.horizon_exit and penalty is not None:
            raise ValueError(
                "horizon_exit: expected False with a fixed exit_penalty (it charges leoc's "
                f"exit for a whole episode), found True with exit_penalty={penalty!r}"
            )

    def plant(self) -> StepRules:
        """These rules with every reward-only field at leoc's default: what decides the plant
        a controller runs on (its dynamics and where an episode ends), without what a learner
        was paid. Two runs whose rules have the same ``plant()`` ran on the same plant; a
        controller is evaluated and certified on its own plant whatever reward it was trained
        with."""
        return dataclasses.replace(
            self, **{name: getattr(DEFAULT_RULES, name) for name in REWARD_ONLY_RULES}
        )


DEFAULT_RULES = StepRules()
#: :class:`StepRules` fields that change only the reward a transition earns, not the plant's
#: dynamics nor where an episode ends (termination is the system's allowed region under every
#: rule): training choices, which never block evaluating a controller on its plant.
REWARD_ONLY_RULES = ("exit_penalty", "reward_on_next_state", "horizon_exit")


@dataclasses.dataclass(frozen=True)
class PhysicalParams:
    """Base class of the frozen parameter dataclasses.

    Subclasses declare their constants as fields and list in ``MASS_FIELDS`` the fields that a
    mass scaling multiplies. Derived quantities (total mass, pole mass-length, ...) are
    properties, so they are recomputed for every scaled copy.
    """

    MASS_FIELDS: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(
                    f"{type(self).__name__}.{field.name}: expected a positive finite number, "
                    f"found {value!r}"
                )

    def scaled(self, **factors: float) -> PhysicalParams:
        """Return a copy with fields multiplied by the given factors.

        ``mass=f`` multiplies every field listed in ``MASS_FIELDS``; any other keyword must name
        a field (``gravity=2.0`` doubles g). Derived quantities follow automatically.

        Raises
        ------
        ValueError
            On an unknown name or a non-positive factor.
        """
        names = {field.name for field in dataclasses.fields(self)}
        changes: dict[str, float] = {}
        for key, factor in factors.items():
            if not isinstance(factor, (int, float)) or not math.isfinite(factor) or factor <= 0:
                raise ValueError(f"{key}: expected a positive scale factor, found {factor!r}")
            targets = self.MASS_FIELDS if key == "mass" else (key,)
            for target in targets:
                if target not in names:
                    valid = ", ".join(sorted(names | {"mass"}))
                    raise ValueError(
                        f"scaled(): unknown parameter {key!r} for {type(self).__name__}; "
                        f"expected one of: {valid}"
                    )
                changes[target] = changes.get(target, getattr(self, target)) * factor
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict[str, float]:
        """Plain dict of the fields (for JSON reports)."""
        return dataclasses.asdict(self)


class System:
    """A control benchmark: dynamics, observation, reward, operating point and starts.

    Subclasses set the class attributes below and implement :meth:`step_fn`,
    :meth:`reward_fn` and :meth:`continuous_model`.

    Attributes
    ----------
    name : str
        Registry name (``pendulum``, ``cartpole``, ``mountaincar``).
    state_names, obs_layout : tuple
        Names of the state entries and how each observation entry is built from them.
    angle_indices : tuple of int
        State entries that are angles (observed through cos/sin, wrapped in the reward).
    main_index : int
        State entry whose deviation is the response "main coordinate".
    main_in_degrees : bool
        Whether the main coordinate is reported in degrees (angles) or as is (positions).
    settling_band : float
        Settling band of the response metrics, in the units the main coordinate is reported in.
    hold_band : float
        Band of the "reached and held the operating point" test (:meth:`hold_step`), same units.
    hold_min_steps : int
        Fewest final simulator steps inside ``hold_band`` that count as holding: the one minimum
        duration of the hold test, used by both trainers, the swing-up table and robustness.
    operating_region : tuple of float
        Half-widths (state units) of the box around the operating point from which robustness
        episodes start (:meth:`sample_operating_region`).
    start_spread : tuple of float
        Half-widths of the uniform swing-up start distribution around ``swing_up_centre``.
    default_q, default_r : tuple
        Diagonals of the default LQR weights (state and action).
    velocity_indices : tuple of int
        State entries that are generalised velocities, one per degree of freedom (``V`` of
        them), in the order of the forces of :meth:`forced_step_fn`; empty (the default) for a
        system that takes no friction or pushes (:mod:`leoc.systems.perturbations`).
    """

    name: ClassVar[str]
    state_names: ClassVar[tuple[str, ...]]
    obs_layout: ClassVar[tuple[ObsComponent, ...]]
    main_index: ClassVar[int] = 0
    main_label: ClassVar[str]
    main_in_degrees: ClassVar[bool]
    settling_band: ClassVar[float]
    hold_band: ClassVar[float]
    hold_min_steps: ClassVar[int]
    operating_region: ClassVar[tuple[float, ...]]
    swing_up_centre: ClassVar[tuple[float, ...]]
    start_spread: ClassVar[tuple[float, ...]]
    default_q: ClassVar[tuple[float, ...]]
    default_r: ClassVar[tuple[float, ...]]
    out_of_bounds_reward: ClassVar[float] = 0.0
    params_type: ClassVar[type[PhysicalParams]]
    velocity_indices: ClassVar[tuple[int, ...]] = ()

    def __init__(self, params: PhysicalParams | None = None, **overrides: float) -> None:
        if params is None:
            params = self.params_type(**overrides)
        elif overrides:
            params = dataclasses.replace(params, **overrides)
        if not isinstance(params, self.params_type):
            raise TypeError(
                f"params: expected {self.params_type.__name__}, found {type(params).__name__}"
            )
        self.params = params
        self.episode_steps = DEFAULT_EPISODE_STEPS
        self.rules = DEFAULT_RULES

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.params!r})"

    # ------------------------------------------------------------------ dimensions and constants
    @property
    def angle_indices(self) -> tuple[int, ...]:
        """State entries that are angles: those the observation map sees through cos/sin."""
        return self.observation.angle_indices

    @property
    def state_dim(self) -> int:
        """State dimension S."""
        return len(self.state_names)

    @property
    def obs_dim(self) -> int:
        """Observation dimension D."""
        return len(self.obs_layout)

    @property
    def action_dim(self) -> int:
        """Action dimension A (1 for the built-in systems)."""
        return 1

    @property
    def dt(self) -> float:
        """Time step in seconds."""
        return float(self.params.dt)  # type: ignore[attr-defined]

    @property
    def action_limit(self) -> float:
        """Actuator limit ``|u| <= action_limit`` (N or N m)."""
        raise NotImplementedError

    @property
    def operating_state(self) -> np.ndarray:
        """The operating point a in state coordinates (all our systems: the origin)."""
        return np.zeros(self.state_dim)

    @property
    def u_eq(self) -> np.ndarray:
        """The action that keeps the operating point an equilibrium."""
        return np.zeros(self.action_dim)

    @property
    def operating_obs(self) -> np.ndarray:
        """The operating point in observation coordinates."""
        return self.observe(torch.as_tensor(self.operating_state, dtype=DTYPE)).numpy()[0]

    # ------------------------------------------------------------------ dynamics
    def step_fn(self, state: Tensor, action: Tensor) -> Tensor:
        """Pure batched step ``(B, S), (B, A) -> (B, S)``; the action is clipped inside."""
        raise NotImplementedError

    def forced_step_fn(
        self, state: Tensor, action: Tensor, force: Callable[[Tensor], Tensor]
    ) -> Tensor:
        """:meth:`step_fn` with generalised forces added to the dynamics.

        Parameters
        ----------
        state : (B, S) tensor
        action : (B, A) tensor
            Clipped to the actuator limit inside, as by :meth:`step_fn`.
        force : callable
            ``force(x)`` ``(B, V)``: the generalised force (N or N m) on each degree of freedom
            of :attr:`velocity_indices` at a state ``x`` ``(B, S)``, evaluated wherever the
            integrator evaluates the accelerations (once per Euler step at its start state,
            at each stage of a Runge-Kutta step). It is added beside the clipped actuator
            force, so the actuator limit does not bound it (friction is not the motor's).

        Raises
        ------
        NotImplementedError
            For a system that does not implement it (friction then cannot be applied).
        """
        raise NotImplementedError(
            f"system {getattr(self, 'name', type(self).__name__)!r} does not implement "
            "forced_step_fn (generalised forces such as friction)"
        )

    def reward_fn(self, state: Tensor, action: Tensor) -> Tensor:
        """Reward ``(B,)`` of taking ``action`` in ``state`` (before the step)."""
        raise NotImplementedError

    def out_of_bounds(self, state: Tensor) -> Tensor:
        """Boolean ``(B,)``: the state has left the allowed region (ends the episode)."""
        return torch.zeros(state.shape[:-1], dtype=torch.bool)

    def step_reward(
        self, state: Tensor, action: Tensor, next_state: Tensor, leaving: Tensor, steps_left: Any
    ) -> Tensor:
        """Reward ``(B,)`` of one step under ``self.rules``, the one place the gymnasium
        environment and every rollout take it from.

        ``leaving`` (bool ``(B,)``) marks the steps that leave the allowed region, ``steps_left``
        the steps the episode would still have run after this one. leoc's rules: the reward of
        ``(state, action)``, and :meth:`termination_reward` on an exit. Other rules may take the
        reward after the step, charge the exit for a whole episode (``horizon_exit``) or charge
        a one-off ``exit_penalty`` (:class:`StepRules`).
        """
        rules = self.rules
        reward = self.reward_fn(next_state if rules.reward_on_next_state else state, action)
        if rules.exit_penalty is None:
            if rules.horizon_exit:
                left = torch.as_tensor(steps_left, dtype=reward.dtype)
                steps_left = torch.clamp(left, min=self.episode_steps - 1)
            exit_reward = torch.as_tensor(self.termination_reward(steps_left), dtype=reward.dtype)
        else:
            exit_reward = reward + rules.exit_penalty
        return torch.where(leaving, exit_reward, reward)

    def with_rules(self, rules: StepRules) -> System:
        """A copy of this system that steps, rewards and ends episodes under ``rules``."""
        if not isinstance(rules, StepRules):
            raise TypeError(f"rules: expected a StepRules, found {type(rules).__name__}")
        clone = copy.copy(self)
        clone.rules = rules
        return clone

    def termination_reward(self, steps_left: Any) -> Any:
        """Reward of the step that leaves the allowed region, ``steps_left`` (int or tensor) being
        the steps the episode would still have run after it: ``out_of_bounds_reward`` for that
        step and for each of them.

        With ``out_of_bounds_reward`` no greater than the worst reward inside the region, an
        episode that leaves early never earns more than one that stays in the worst state to
        the end. A fixed one-off penalty does not have that property: the cart-pole's former
        -100 beat hanging down for 200 steps (about -987) by far, so DDPG learnt to drive off
        the track.
        """
        return self.out_of_bounds_reward * (1 + steps_left)

    def continuous_model(self) -> tuple[np.ndarray, np.ndarray]:
        """Analytic continuous-time linearisation ``(A, B)`` about the operating point."""
        raise NotImplementedError

    def cost_factor(self) -> np.ndarray:
        """Factor ``F`` (K, O) of PILCO's saturating cost on the observation deviation:
        ``c = 1 - exp(-|F (o - o(a))|^2 / (2 width^2))``. Default: the observation entries of
        the main coordinate (its cos and sin for an angle); systems override it with their
        physical target distance (e.g. a pendulum's tip)."""
        rows = []
        for column, component in enumerate(self.obs_layout):
            if component.state_index == self.main_index:
                row = np.zeros(self.obs_dim)
                row[column] = 1.0
                rows.append(row)
        return np.asarray(rows)

    def clip_action(self, action: Tensor) -> Tensor:
        """``action`` clipped to ``[-action_limit, action_limit]`` (any shape)."""
        return torch.clamp(action, -self.action_limit, self.action_limit)

    def step_held(self, state: Tensor, action: Tensor, repeat: int) -> Tensor:
        """The ``repeat``-step map: ``step_fn`` applied ``repeat`` times with the action held
        (zero-order hold), ``(B, S), (B, A) -> (B, S)``. ``repeat = 1`` is :meth:`step_fn`."""
        for _ in range(check_repeat(repeat)):
            state = self.step_fn(state, action)
        return state

    def step(self, state: Any, action: Any) -> Tensor:
        """Batched step accepting array-likes; see :meth:`step_fn`."""
        state_t = as_state_tensor(state, self.state_dim, "state")
        action_t = as_state_tensor(action, self.action_dim, "action")
        return self.step_fn(state_t, action_t)

    @cached_property
    def observation(self) -> ObservationMap:
        """The map of ``obs_layout`` (observe, invert, bounds, moments, Jacobian)."""
        return ObservationMap(self.obs_layout, self.state_dim)

    def observe(self, state: Tensor) -> Tensor:
        """Observation ``(B, O)`` of a batch of states ``(B, S)`` (1-D input gets B = 1)."""
        return self.observation.observe(as_state_tensor(state, self.state_dim, "state"))

    def state_from_obs(self, obs: Tensor) -> Tensor:
        """Invert :meth:`observe` (angles by atan2 of their sin and cos)."""
        return self.observation.invert(as_state_tensor(obs, self.obs_dim, "obs"))

    def main_coordinate(self, states: Any) -> np.ndarray:
        """Deviation of the main coordinate from the operating point, in report units.

        Angles are wrapped to [-pi, pi) and converted to degrees; positions are returned as is.
        ``states`` has shape ``(T, S)``; the result has shape ``(T,)``.
        """
        states_t = torch.as_tensor(np.asarray(states), dtype=DTYPE)
        deviation = states_t[..., self.main_index] - float(self.operating_state[self.main_index])
        if self.main_index in self.angle_indices:
            deviation = wrap_angle(deviation)
        values = deviation.numpy()
        return np.degrees(values) if self.main_in_degrees else values

    def hold_step(
        self,
        states: Any,
        band: float | None = None,
        min_steps: int | None = None,
        terminated: bool = False,
    ) -> int | None:
        """The one "reached and held the operating point" test.

        Returns the first step from which the main coordinate stays within ``band`` of the
        operating point until the end of ``states`` ``(T, S)``, or None when the episode does
        not hold: it terminated (left the allowed region), its last state is outside the band,
        or it stayed inside for fewer than ``min_steps`` steps. Defaults: :attr:`hold_band` and
        :attr:`hold_min_steps`.
        """
        band = self.hold_band if band is None else band
        min_steps = self.hold_min_steps if min_steps is None else int(min_steps)
        if terminated:
            return None
        inside = np.abs(self.main_coordinate(states)) <= band
        if inside.size == 0 or not inside[-1]:
            return None
        outside = np.flatnonzero(~inside)
        first = 0 if outside.size == 0 else int(outside[-1] + 1)
        return first if inside.size - first >= min_steps else None

    # ------------------------------------------------------------------ starts
    def sample_start(
        self,
        rng: np.random.Generator,
        kind: StartKind = "swing_up",
        offset: Sequence[float] | np.ndarray | None = None,
    ) -> np.ndarray:
        """Draw an initial state.

        Parameters
        ----------
        rng : numpy.random.Generator
            The only source of randomness (seeded by the caller).
        kind : {"swing_up", "operating_point"}
            ``swing_up``: uniform in ``swing_up_centre +/- start_spread``;
            ``operating_point``: exactly the operating point plus ``offset``.
        offset : array-like of shape (S,), optional
            Added to the operating point (only with ``kind="operating_point"``).
        """
        if kind == "swing_up":
            if offset is not None:
                raise ValueError("offset: only valid with kind='operating_point', found swing_up")
            centre = np.asarray(self.swing_up_centre, dtype=float)
            spread = np.asarray(self.start_spread, dtype=float)
            return centre + rng.uniform(-spread, spread)
        if kind == "operating_point":
            state = self.operating_state.copy()
            if offset is not None:
                offset_arr = np.asarray(offset, dtype=float)
                if offset_arr.shape != (self.state_dim,) or not np.all(np.isfinite(offset_arr)):
                    raise ValueError(
                        f"offset: expected {self.state_dim} finite numbers "
                        f"({', '.join(self.state_names)}), found {offset!r}"
                    )
                state = state + offset_arr
            return state
        raise ValueError(f"kind: expected one of {START_KINDS}, found {kind!r}")

    def sample_operating_region(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` starts ``(count, S)`` uniform in the operating point +/- ``operating_region``
        (the region robustness episodes start from)."""
        spread = np.asarray(self.operating_region, dtype=float)
        return self.operating_state + rng.uniform(-spread, spread, size=(count, self.state_dim))

    def with_params(self, **factors: float) -> System:
        """A copy of this system with scaled parameters (see :meth:`PhysicalParams.scaled`)."""
        return type(self)(self.params.scaled(**factors)).with_rules(self.rules)

    # ------------------------------------------------------------------ validation
    def validate(self) -> None:
        """Check that this system honours the protocol (module docstring).

        Raises
        ------
        ValueError
            Naming the system and the attribute, with what was expected and what was found:
            a missing attribute, wrong shapes, a non-positive ``dt`` or action limit, an
            inconsistent observation layout, a ``step_fn``/``reward_fn``/``out_of_bounds`` that
            returns no tensor (a body left as ``...``), the wrong shape or non-finite values, or
            an operating point that is not an equilibrium:
            ``max |f(a, u_eq) - a| > EQUILIBRIUM_TOL`` (angles wrapped).
        """
        label = f"system {getattr(self, 'name', type(self).__name__)!r}"
        for attribute in REQUIRED_ATTRIBUTES:
            if not hasattr(self, attribute):
                raise ValueError(f"{label}: missing class attribute {attribute!r}")
        try:
            observation = self.observation
        except ValueError as error:
            raise ValueError(f"{label}: obs_layout: {error}") from error
        self._validate_scalars(label)
        self._validate_vectors(label)
        self._validate_functions(label, observation.obs_dim)

    def _validate_scalars(self, label: str) -> None:
        """``dt``, the action limit, the bands, ``hold_min_steps`` and ``main_index``."""
        _check_positive(label, "dt", self.dt)
        _check_positive(label, "action_limit", self.action_limit)
        _check_positive(label, "hold_band", self.hold_band)
        _check_positive(label, "settling_band", self.settling_band)
        if not 1 <= int(self.hold_min_steps) <= self.episode_steps:
            raise ValueError(
                f"{label}: hold_min_steps: expected 1 .. episode_steps = {self.episode_steps}, "
                f"found {self.hold_min_steps!r}"
            )
        if not 0 <= self.main_index < self.state_dim:
            raise ValueError(
                f"{label}: main_index: expected 0 .. {self.state_dim - 1}, found {self.main_index}"
            )

    def _validate_vectors(self, label: str) -> None:
        """Shapes, finiteness and signs of the per-state and per-action vectors; ``u_eq``
        within the action limit."""
        size, actions = self.state_dim, self.action_dim
        vectors = {
            "operating_state": (self.operating_state, size),
            "u_eq": (self.u_eq, actions),
            "swing_up_centre": (self.swing_up_centre, size),
            "start_spread": (self.start_spread, size),
            "operating_region": (self.operating_region, size),
            "default_q": (self.default_q, size),
            "default_r": (self.default_r, actions),
        }
        for attribute, (value, length) in vectors.items():
            array = np.asarray(value, dtype=float)
            if array.shape != (length,) or not np.all(np.isfinite(array)):
                raise ValueError(
                    f"{label}: {attribute}: expected {length} finite numbers, found {value!r}"
                )
        for attribute in ("start_spread", "operating_region", "default_q"):
            if np.any(np.asarray(getattr(self, attribute)) < 0):
                raise ValueError(f"{label}: {attribute}: expected entries >= 0")
        if np.any(np.asarray(self.default_r) <= 0):
            raise ValueError(f"{label}: default_r: expected entries > 0, found {self.default_r}")
        if np.any(np.abs(self.u_eq) > self.action_limit):
            raise ValueError(
                f"{label}: u_eq: expected |u_eq| <= action_limit = {self.action_limit}, "
                f"found {self.u_eq.tolist()}"
            )

    def _validate_functions(self, label: str, obs_dim: int) -> None:
        """Shapes, finiteness and the equilibrium of ``step_fn``, ``reward_fn``, the cost."""
        size = self.state_dim
        operating = torch.as_tensor(self.operating_state, dtype=DTYPE)
        states = operating.expand(VALIDATION_BATCH, size).clone()
        actions = torch.as_tensor(self.u_eq, dtype=DTYPE).expand(VALIDATION_BATCH, -1).clone()
        with torch.no_grad():
            following = _returned_tensor(
                label, "step_fn", self.step_fn(states, actions), f"a (B, {size}) tensor"
            )
            reward = _returned_tensor(
                label, "reward_fn", self.reward_fn(states, actions), "a (B,) tensor of rewards"
            )
            left = _returned_tensor(
                label, "out_of_bounds", self.out_of_bounds(states), "a (B,) bool tensor"
            )
        if tuple(following.shape) != (VALIDATION_BATCH, size) or following.dtype != DTYPE:
            raise ValueError(
                f"{label}: step_fn: expected a float64 tensor of shape (B, {size}) for B = "
                f"{VALIDATION_BATCH}, found {following.dtype} {tuple(following.shape)}"
            )
        if tuple(reward.shape) != (VALIDATION_BATCH,) or not bool(torch.isfinite(reward).all()):
            raise ValueError(
                f"{label}: reward_fn: expected {VALIDATION_BATCH} finite rewards (shape (B,)), "
                f"found shape {tuple(reward.shape)}"
            )
        if bool(left.any()):
            raise ValueError(f"{label}: out_of_bounds: the operating point is out of bounds")
        change = following[0] - operating
        for index in self.angle_indices:
            change[index] = wrap_angle(change[index])
        residual = float(change.abs().max())
        if not residual <= EQUILIBRIUM_TOL:
            raise ValueError(
                f"{label}: the operating point {self.operating_state.tolist()} is not an "
                f"equilibrium of step_fn under u_eq = {self.u_eq.tolist()}: "
                f"max |f(a, u_eq) - a| = {residual:.3g} > tolerance {EQUILIBRIUM_TOL:g}"
            )
        factor = np.asarray(self.cost_factor(), dtype=float)
        if factor.ndim != 2 or factor.shape[1] != obs_dim or factor.shape[0] < 1:
            raise ValueError(
                f"{label}: cost_factor: expected an array of shape (K, {obs_dim}), found "
                f"{factor.shape}"
            )
        self._validate_termination(label, float(reward.min()) + 0.0)  # + 0.0: no "-0"

    def can_leave(self) -> bool:
        """Whether the system has an allowed region to leave (it overrides
        :meth:`out_of_bounds`)."""
        return type(self).out_of_bounds is not System.out_of_bounds

    def _validate_termination(self, label: str, reward_at_operating_point: float) -> None:
        """A system that can leave its allowed region charges no more per step left than the
        reward at the operating point (so that leaving never pays)."""
        if not self.can_leave():
            return
        penalty = self.out_of_bounds_reward
        if isinstance(penalty, bool) or not isinstance(penalty, (int, float)):
            raise ValueError(
                f"{label}: out_of_bounds_reward: expected a number (the reward per step left of "
                f"an episode that leaves the allowed region), found {penalty!r}"
            )
        if not penalty <= reward_at_operating_point:
            raise ValueError(
                f"{label}: out_of_bounds_reward: expected at most the reward at the operating "
                f"point ({reward_at_operating_point:.6g}) so that leaving never pays, "
                f"found {penalty!r}"
            )

    def describe(self) -> Mapping[str, Any]:
        """A JSON-friendly description (for reports)."""
        return {
            "name": self.name,
            "params": self.params.as_dict(),
            "state_names": list(self.state_names),
            "operating_state": self.operating_state.tolist(),
            "u_eq": self.u_eq.tolist(),
        }
