"""Perturbations of a plant as data: noise, delay, actuator gain, friction, parameter errors
and pushes, each a frozen, documented, seeded object, applied by one :class:`PerturbedPlant`.

The same plant object runs inside :func:`leoc.systems.rollout.simulate` (every rollout: the
response tests, the robustness sweeps, PILCO's data, the DDPG/TD3/SAC evaluations, the basins)
and inside the gymnasium environment (:class:`leoc.systems.envs.LeocEnv`'s ``perturbations``),
so both see the same plant, and the same seeds give the same trajectories.

Where each acts in one simulator step from the state :math:`x_t` (the order of the loop):

==================  =====================================================================
observation         the controller sees ``observe(x_t) + n_t`` (:class:`ObservationNoise`)
command             ``u_t``: the held controller output (plus any offset), clipped to the
                    actuator limit, as without perturbations
delay               the actuator receives the command of ``D`` steps before
                    (:class:`ActionDelay`; ``u_eq`` before the first ``D`` steps)
gain                ``g`` times it (:class:`ActuatorGain`)
torque noise        plus ``w_t`` (:class:`TorqueNoise`)
actuator clip       the system's ``step_fn`` clips to the limit: the limit bounds what the
                    actuator delivers under every perturbation
push                ``x_t`` plus a velocity impulse at random steps (:class:`Push`)
dynamics            the plant's own constants (:class:`ParameterError`) and friction forces
                    beside the actuator (:class:`Friction`) give :math:`x_{t+1}`
==================  =====================================================================

The reward and the termination are the task's, unchanged: a step's reward is that of the
state before it and the controller's command (the plant's constants decide where the allowed
region ends). A perturbation at its nominal level (:attr:`Perturbation.is_null`: zero noise,
delay, friction or push size, unit gain or factor) is not applied at all, so such a plant is
today's plant bit for bit.

Randomness. Each random perturbation (observation noise, torque noise, each push) draws from
its own ``torch.Generator``, seeded from its ``seed``, its kind and its place among the
perturbations of its kind (so two noises with one seed do not draw the same numbers), and, for
a gymnasium episode reset with a seed, that seed too (:meth:`PerturbedPlant.reseed`). It draws
at every simulator step for every episode of the batch, whether or not a controller decides
then, so the stream does not depend on the controller.

Shapes: ``B`` batch, ``S`` state, ``O`` observation, ``A`` action, ``V`` the system's
degrees of freedom (``System.velocity_indices``, :class:`~leoc.systems.base.System`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.systems.base import DTYPE, System, check_repeat

__all__ = [
    "PERTURBATION_KINDS",
    "ActionDelay",
    "ActuatorGain",
    "Friction",
    "ObservationNoise",
    "ParameterError",
    "Perturbation",
    "PerturbedPlant",
    "PlantRows",
    "PlantStep",
    "Push",
    "TorqueNoise",
    "perturbation_from_dict",
]

# A delay of `periods` control periods must be a whole number of simulator steps to this
# relative tolerance (0.5 periods at a 2-step period is 1.0 step up to round-off).
WHOLE_STEPS_TOL = 1e-9
# Push direction: a uniform draw below this is a negative push.
NEGATIVE_PUSH_SHARE = 0.5


def _number(owner: str, name: str, value: Any, low: float = 0.0) -> float:
    """``value`` as a float if it is a finite number >= ``low``, else raise naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
        raise ValueError(f"{owner}.{name}: expected a number >= {low:g}, found {value!r}")
    if not math.isfinite(value) or value < low:
        raise ValueError(f"{owner}.{name}: expected a finite number >= {low:g}, found {value!r}")
    return float(value)


def _numbers(owner: str, name: str, value: Any) -> float | tuple[float, ...]:
    """A non-negative number, or a non-empty sequence of them as a tuple (raises naming it)."""
    if isinstance(value, (list, tuple, np.ndarray)):
        if len(value) == 0:
            raise ValueError(f"{owner}.{name}: expected a number or a non-empty sequence")
        return tuple(_number(owner, f"{name}[{i}]", entry) for i, entry in enumerate(value))
    return _number(owner, name, value)


def _seed(owner: str, value: Any) -> int:
    """A non-negative integer seed (raises naming it)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"{owner}.seed: expected a non-negative integer, found {value!r}")
    return int(value)


@dataclasses.dataclass(frozen=True)
class Perturbation:
    """Base class of the perturbations: frozen data, applied by :class:`PerturbedPlant`.

    A subclass names the field that sets its size (``level_field``) and that field's nominal
    value (``nominal_level``); :attr:`level` is the distance from it and :attr:`is_null` says
    the perturbation changes nothing (it is then not applied at all).
    """

    #: The field that sets the perturbation's size.
    level_field: ClassVar[str]
    #: That field's value in the unperturbed plant.
    nominal_level: ClassVar[float] = 0.0
    #: Whether a plant takes at most one perturbation of this kind.
    unique: ClassVar[bool] = True
    #: The kind's salt in the seed of its random stream (0: not random).
    stream: ClassVar[int] = 0

    @property
    def level(self) -> float:
        """Largest distance of the level field (each entry of a tuple) from its nominal value."""
        value = getattr(self, self.level_field)
        entries = value if isinstance(value, tuple) else (value,)
        return max(abs(float(entry) - self.nominal_level) for entry in entries)

    @property
    def is_null(self) -> bool:
        """Whether this perturbation leaves the plant as it is (level 0, or a push that never
        comes)."""
        return self.level == 0.0

    def as_dict(self) -> dict[str, Any]:
        """``{"kind": class name, field: value, ...}`` for run records
        (:func:`perturbation_from_dict` reads it back)."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {"kind": type(self).__name__, **{k: _plain(v) for k, v in fields.items()}}


def _plain(value: Any) -> Any:
    """A JSON-friendly copy of a field value (tuples as lists)."""
    return list(value) if isinstance(value, tuple) else value


@dataclasses.dataclass(frozen=True)
class ObservationNoise(Perturbation):
    """Additive Gaussian noise on what the controller sees, not on the state.

    Every observation the plant emits (the start's and the one after each simulator step) is
    ``observe(x) + std * n`` with ``n`` standard normal, independent per entry, per episode of
    the batch and per step (also between the decisions of a controller with a longer period).
    The state, the reward, the termination and the recorded states are untouched; a rollout
    records the noisy observations (what the controller saw). A cos and sin pair gets
    independent noise (it leaves the unit circle) and is not clipped back to [-1, 1]: the
    environment's observation space is unbounded on every noisy entry.

    Attributes
    ----------
    std : float or tuple of float
        Standard deviation per observation entry, in that entry's units (``O`` numbers, or one
        for every entry); >= 0. Nominal 0.
    seed : int
        Seed of its stream (module docstring).
    """

    level_field: ClassVar[str] = "std"
    stream: ClassVar[int] = 1
    std: float | tuple[float, ...] = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "std", _numbers("ObservationNoise", "std", self.std))
        object.__setattr__(self, "seed", _seed("ObservationNoise", self.seed))


@dataclasses.dataclass(frozen=True)
class TorqueNoise(Perturbation):
    """Additive Gaussian noise on the actuator's output, inside its limit.

    At every simulator step the actuator delivers ``clip(g * u_delayed + std * n)``, ``n``
    standard normal per action entry, per episode and per step: the noise is added after the
    (delayed, scaled) clipped command and before the actuator clip of ``step_fn``. The limit
    keeps bounding what the plant gets, so at the limit the noise is one-sided (a saturated
    drive cannot give more).

    Attributes
    ----------
    std : float or tuple of float
        Standard deviation in N or N m (``A`` numbers, or one for every entry); >= 0.
    seed : int
        Seed of its stream (module docstring).
    """

    level_field: ClassVar[str] = "std"
    stream: ClassVar[int] = 2
    std: float | tuple[float, ...] = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "std", _numbers("TorqueNoise", "std", self.std))
        object.__setattr__(self, "seed", _seed("TorqueNoise", self.seed))


@dataclasses.dataclass(frozen=True)
class ActionDelay(Perturbation):
    """The actuator acts on the command of ``periods`` control periods before.

    A first-in first-out queue of ``D = periods * R`` simulator steps (``R`` the controller's
    period in simulator steps, :class:`PerturbedPlant`'s ``action_repeat``): the command
    applied at simulator step ``t`` is the clipped command issued at step ``t - D``; the queue
    starts full of the operating action ``u_eq`` (the plant had rested at its operating point).
    A fraction of a period is a delay where ``periods * R`` is a whole number of steps (half
    a period at ``R = 2``); any other fraction raises. The queue holds clipped commands, so the
    actuator limit keeps its meaning.

    Attributes
    ----------
    periods : float
        The delay in control periods, >= 0. Nominal 0.
    """

    level_field: ClassVar[str] = "periods"
    periods: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "periods", _number("ActionDelay", "periods", self.periods))

    def steps(self, action_repeat: int) -> int:
        """The delay in simulator steps at a control period of ``action_repeat`` steps.

        Raises
        ------
        ValueError
            If ``periods * action_repeat`` is not a whole number of steps.
        """
        repeat = check_repeat(action_repeat)
        exact = self.periods * repeat
        steps = round(exact)
        if abs(exact - steps) > WHOLE_STEPS_TOL * max(1.0, exact):
            raise ValueError(
                f"ActionDelay.periods: {self.periods!r} periods of {repeat} simulator step(s) "
                f"is {exact!r} steps, expected a whole number (a fractional delay needs a "
                "control period it divides)"
            )
        return int(steps)


@dataclasses.dataclass(frozen=True)
class ActuatorGain(Perturbation):
    """The actuator delivers ``gain`` times the torque it is asked, within its limit.

    The plant gets ``clip(gain * u)`` where ``u`` is the (delayed) command, itself clipped: the
    gain is the motor's torque response factor, applied to what the drive was asked, and the
    drive's limit still bounds the result (a weak motor, ``gain < 1``, never reaches the limit;
    a strong one saturates at it).

    Attributes
    ----------
    gain : float
        Torque response factor, >= 0. Nominal 1.
    """

    level_field: ClassVar[str] = "gain"
    nominal_level: ClassVar[float] = 1.0
    gain: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "gain", _number("ActuatorGain", "gain", self.gain))


@dataclasses.dataclass(frozen=True)
class Friction(Perturbation):
    """Viscous and Coulomb friction on the system's joints, as forces in its dynamics.

    Each listed degree of freedom with velocity ``v`` gets the generalised force
    ``Q = -viscous * v - coulomb * sign(v)`` (N or N m), added beside the clipped actuator
    force by :meth:`~leoc.systems.base.System.forced_step_fn` (each system's module writes its
    equations with Q) and evaluated where the integrator evaluates the accelerations (at the
    start of an Euler step; at each stage of the acrobot's Runge-Kutta step). It is not the
    motor's, so the actuator limit does not bound it. ``sign(0) = 0``: no stiction; an
    explicit step lets a velocity dominated by Coulomb friction chatter about zero (about
    ``coulomb * dt / inertia`` per step) rather than stick. Several ``Friction`` objects add up.

    Attributes
    ----------
    viscous : float
        b, in N s/m or N m s/rad of each joint, >= 0.
    coulomb : float
        mu, in N or N m, >= 0.
    joints : tuple of str, optional
        Names of the velocity state entries it acts on (``("theta_dot",)``); None: every
        degree of freedom (``System.velocity_indices``, :class:`~leoc.systems.base.System`).
    """

    level_field: ClassVar[str] = "viscous"
    unique: ClassVar[bool] = False
    viscous: float = 0.0
    coulomb: float = 0.0
    joints: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "viscous", _number("Friction", "viscous", self.viscous))
        object.__setattr__(self, "coulomb", _number("Friction", "coulomb", self.coulomb))
        if self.joints is not None:
            joints = (self.joints,) if isinstance(self.joints, str) else tuple(self.joints)
            if not joints or not all(isinstance(name, str) for name in joints):
                raise ValueError(f"Friction.joints: expected state names, found {self.joints!r}")
            object.__setattr__(self, "joints", joints)

    @property
    def level(self) -> float:
        """The larger of the two coefficients."""
        return max(self.viscous, self.coulomb)


@dataclasses.dataclass(frozen=True)
class ParameterError(Perturbation):
    """The plant's value of one physical constant is ``factor`` times the nominal one.

    The plant is the system built with that constant scaled
    (:meth:`~leoc.systems.base.System.with_params`; ``mass`` scales every mass field, derived
    quantities follow), while the controller and its model keep the nominal value. The time
    step and the actuator limit are not physical constants of the plant (they are the control
    period and the clip) and raise. Several errors on different constants combine.

    Attributes
    ----------
    name : str
        A field of the system's parameters (``gravity``, ``length``, ...) or ``mass``.
    factor : float
        Plant value over nominal value, > 0. Nominal 1.
    """

    level_field: ClassVar[str] = "factor"
    nominal_level: ClassVar[float] = 1.0
    unique: ClassVar[bool] = False
    name: str
    factor: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"ParameterError.name: expected a parameter name, found {self.name!r}")
        factor = _number("ParameterError", "factor", self.factor)
        if factor == 0.0:
            raise ValueError("ParameterError.factor: expected a positive number, found 0")
        object.__setattr__(self, "factor", factor)


@dataclasses.dataclass(frozen=True)
class Push(Perturbation):
    """Random velocity impulses of a given size at random steps.

    At every simulator step, independently per episode, a push comes with probability
    ``rate * dt``; it adds ``+size`` or ``-size`` (equally likely) to the ``joint`` velocity of
    the state after the controller observed it and before the step integrates, so the step
    (and its speed clip) runs from the pushed state and the push shows in the next state. An
    impulse ``J`` on an inertia ``I`` is ``size = J / I``. Several pushes (on different joints)
    add up.

    Attributes
    ----------
    size : float
        The velocity change, in the joint velocity's units, >= 0. Nominal 0.
    rate : float
        Expected pushes per second, >= 0 with ``rate * dt <= 1``.
    joint : str, optional
        The velocity state entry pushed; None: the main coordinate's velocity (the state entry
        named ``<main state name>_dot``).
    seed : int
        Seed of its stream (module docstring).
    """

    level_field: ClassVar[str] = "size"
    unique: ClassVar[bool] = False
    stream: ClassVar[int] = 3
    size: float = 0.0
    rate: float = 1.0
    joint: str | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", _number("Push", "size", self.size))
        object.__setattr__(self, "rate", _number("Push", "rate", self.rate))
        object.__setattr__(self, "seed", _seed("Push", self.seed))
        if self.joint is not None and not isinstance(self.joint, str):
            raise ValueError(f"Push.joint: expected a state name or None, found {self.joint!r}")

    @property
    def is_null(self) -> bool:
        """Whether no push changes anything (size 0 or rate 0)."""
        return self.size == 0.0 or self.rate == 0.0


#: The perturbation classes by name (what :meth:`Perturbation.as_dict` records as ``kind``).
PERTURBATION_KINDS: dict[str, type[Perturbation]] = {
    kind.__name__: kind
    for kind in (ObservationNoise, TorqueNoise, ActionDelay, ActuatorGain, Friction)
    + (ParameterError, Push)
}


def perturbation_from_dict(record: Mapping[str, Any]) -> Perturbation:
    """The perturbation that :meth:`Perturbation.as_dict` wrote.

    Raises
    ------
    ValueError
        On an unknown ``kind`` or fields the kind does not have.
    """
    fields = dict(record)
    kind = fields.pop("kind", None)
    if kind not in PERTURBATION_KINDS:
        raise ValueError(f"kind: expected one of {sorted(PERTURBATION_KINDS)}, found {kind!r}")
    cls = PERTURBATION_KINDS[kind]
    known = {field.name for field in dataclasses.fields(cls)}
    if set(fields) - known:
        raise ValueError(f"{kind}: unknown fields {sorted(set(fields) - known)}")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()})


class PlantStep(NamedTuple):
    """One step of a :class:`PerturbedPlant`.

    Attributes
    ----------
    state : (B, S) tensor
        The state after the step.
    applied : (B, A) tensor
        What the actuator delivered: the delayed, scaled, noisy command, clipped to the limit.
    impulse : (B, S) tensor
        The velocity change pushed into the state before the step (zeros without a push).
    """

    state: Tensor
    applied: Tensor
    impulse: Tensor


class _Noise(NamedTuple):
    """A Gaussian noise of the plant: its standard deviations and the key of its generator."""

    std: Tensor
    key: int


class _PushSpec(NamedTuple):
    """A push of the plant: the state entry pushed, the size, the chance per step, the key of
    its generator."""

    index: int
    size: float
    probability: float
    key: int


class _FrictionSpec(NamedTuple):
    """A friction of the plant: the degrees of freedom it acts on (columns of the generalised
    force) and its coefficients."""

    columns: tuple[int, ...]
    viscous: float
    coulomb: float


def _checked(perturbations: Sequence[Perturbation]) -> tuple[Perturbation, ...]:
    """The perturbations as a tuple, each a :class:`Perturbation`, at most one of each unique
    kind (raises naming the offender)."""
    if isinstance(perturbations, Perturbation):
        perturbations = (perturbations,)
    items = tuple(perturbations)
    for index, item in enumerate(items):
        if not isinstance(item, Perturbation):
            raise TypeError(
                f"perturbations[{index}]: expected a Perturbation, found {type(item).__name__}"
            )
        if item.unique and any(type(other) is type(item) for other in items[:index]):
            raise ValueError(
                f"perturbations[{index}]: expected at most one {type(item).__name__}, found two"
            )
    return items


def _plant_system(system: System, errors: Sequence[ParameterError]) -> System:
    """``system`` with the parameter errors' constants scaled (itself without any)."""
    if not errors:
        return system
    factors: dict[str, float] = {}
    for error in errors:
        factors[error.name] = factors.get(error.name, 1.0) * error.factor
    plant = system.with_params(**factors)
    if plant.dt != system.dt or plant.action_limit != system.action_limit:
        raise ValueError(
            f"ParameterError.name: {sorted(factors)} changes the time step or the actuator "
            "limit (the control period and the clip, not physical constants of the plant)"
        )
    plant.episode_steps = system.episode_steps
    return plant


def _joint_columns(system: System, joints: Sequence[str] | None, owner: str) -> tuple[int, ...]:
    """Columns in ``system.velocity_indices`` of the named velocity entries (all for None;
    raises naming ``owner`` for a system without degrees of freedom or an unknown name)."""
    names = [system.state_names[index] for index in system.velocity_indices]
    if not names:
        raise ValueError(
            f"{owner}: system {system.name!r} declares no velocity_indices (its degrees of "
            "freedom), so it takes no friction or pushes"
        )
    if joints is None:
        return tuple(range(len(names)))
    unknown = [joint for joint in joints if joint not in names]
    if unknown:
        raise ValueError(f"{owner}.joints: expected some of {names}, found {unknown}")
    return tuple(names.index(joint) for joint in joints)


def _std(owner: str, std: float | tuple[float, ...], size: int, what: str) -> Tensor:
    """The standard deviations as a ``(size,)`` tensor (one number broadcast)."""
    values = std if isinstance(std, tuple) else (std,) * size
    if len(values) != size:
        raise ValueError(f"{owner}.std: expected 1 or {size} numbers ({what}), found {len(values)}")
    return torch.as_tensor(values, dtype=DTYPE)


def _generator(source: Perturbation, occurrence: int, episode_seed: int | None) -> torch.Generator:
    """The generator of a random perturbation: seeded from its seed, its kind's stream, its
    place among its kind and the episode seed (numpy's ``SeedSequence`` mixes them)."""
    entropy = [source.seed, source.stream, occurrence]  # type: ignore[attr-defined]
    if episode_seed is not None:
        entropy.append(_seed("reset", episode_seed))
    seed = int(np.random.SeedSequence(entropy).generate_state(1, dtype=np.uint64)[0])
    return torch.Generator().manual_seed(seed)


class PerturbedPlant:
    """A system with perturbations, stepped in a closed loop (module docstring).

    It holds what a perturbed plant remembers between steps (the delay's queue, the random
    streams), so one object serves one batch of episodes at a time: :meth:`reset` before each.

    Parameters
    ----------
    system : System
        The nominal system (the one the controller was designed for).
    perturbations : sequence of Perturbation
        Any of the kinds of this module; those at their nominal level are dropped.
    action_repeat : int
        The controller's period in simulator steps (converts :class:`ActionDelay`'s periods).

    Attributes
    ----------
    nominal : System
        The given system.
    system : System
        The plant's system: ``nominal`` with the :class:`ParameterError` constants (the same
        object without any); its ``step_fn`` does the actuator clip, its ``out_of_bounds`` and
        ``step_reward`` end and reward the plant's steps.
    perturbations : tuple of Perturbation
        All of those given (nominal ones included, for the record).
    delay_steps : int
        The action delay in simulator steps.

    Raises
    ------
    ValueError
        Naming the perturbation and field: a second delay, gain or noise of one kind, a joint
        the system does not have (or a system without ``velocity_indices``), a noise with the
        wrong number of entries, ``rate * dt > 1``, a delay that is not a whole number of
        steps, a parameter error on an unknown constant, the time step or the actuator limit.
    """

    def __init__(
        self, system: System, perturbations: Sequence[Perturbation] = (), action_repeat: int = 1
    ) -> None:
        if not isinstance(system, System):
            raise TypeError(f"system: expected a System, found {type(system).__name__}")
        self.nominal = system
        self.perturbations = _checked(perturbations)
        self.action_repeat = check_repeat(action_repeat)
        active = {key: p for key, p in enumerate(self.perturbations) if not p.is_null}
        errors = [p for p in active.values() if isinstance(p, ParameterError)]
        self.system = _plant_system(system, errors)
        self.delay_steps = 0
        self._gain: float | None = None
        self._observation_noise: _Noise | None = None
        self._torque_noise: _Noise | None = None
        self._friction: list[_FrictionSpec] = []
        self._pushes: list[_PushSpec] = []
        for key, perturbation in active.items():
            self._add(key, perturbation)
        self._queue: list[Tensor] = []
        self._generators: dict[int, torch.Generator] = {}
        self.reseed()

    def _add(self, key: int, perturbation: Perturbation) -> None:
        """Set up the active perturbation ``perturbation`` (at ``key`` in the list)."""
        system = self.system
        if isinstance(perturbation, ObservationNoise):
            std = _std("ObservationNoise", perturbation.std, system.obs_dim, "observation")
            self._observation_noise = _Noise(std, key)
        elif isinstance(perturbation, TorqueNoise):
            std = _std("TorqueNoise", perturbation.std, system.action_dim, "action")
            self._torque_noise = _Noise(std, key)
        elif isinstance(perturbation, ActionDelay):
            self.delay_steps = perturbation.steps(self.action_repeat)
        elif isinstance(perturbation, ActuatorGain):
            self._gain = perturbation.gain
        elif isinstance(perturbation, Friction):
            columns = _joint_columns(system, perturbation.joints, "Friction")
            spec = _FrictionSpec(columns, perturbation.viscous, perturbation.coulomb)
            self._friction.append(spec)
        elif isinstance(perturbation, Push):
            self._pushes.append(self._push_spec(key, perturbation))

    def _push_spec(self, key: int, push: Push) -> _PushSpec:
        """The state entry, size and chance per step of ``push``."""
        system = self.system
        joint = push.joint
        if joint is None:
            joint = f"{system.state_names[system.main_index]}_dot"
        (column,) = _joint_columns(system, (joint,), "Push")
        probability = push.rate * system.dt
        if probability > 1.0:
            raise ValueError(
                f"Push.rate: expected rate * dt <= 1 (dt = {system.dt:g} s), found "
                f"{push.rate!r} per second"
            )
        return _PushSpec(system.velocity_indices[column], push.size, probability, key)

    def reseed(self, episode_seed: int | None = None) -> None:
        """Restart every random stream from its seed (and ``episode_seed``, a non-negative
        integer, when given: what a gymnasium ``reset(seed=...)`` passes)."""
        keys = [noise.key for noise in (self._observation_noise, self._torque_noise) if noise]
        keys += [push.key for push in self._pushes]
        self._generators = {}
        for key in keys:
            source = self.perturbations[key]
            occurrence = sum(type(p) is type(source) for p in self.perturbations[:key])
            self._generators[key] = _generator(source, occurrence, episode_seed)

    def reset(self, batch: int, episode_seed: int | None = None) -> None:
        """Start ``batch`` episodes: the delay's queue full of ``u_eq``; the random streams
        restarted only with an ``episode_seed`` (:meth:`reseed`), else they go on."""
        if episode_seed is not None:
            self.reseed(episode_seed)
        rest = torch.as_tensor(self.system.u_eq, dtype=DTYPE).expand(batch, -1).clone()
        self._queue = [rest] * self.delay_steps

    @property
    def has_observation_noise(self) -> bool:
        """Whether the observations are noisy."""
        return self._observation_noise is not None

    def observation_bounds(self) -> np.ndarray:
        """Upper bounds ``(O,)`` of what the controller sees: the observation map's, infinite
        on the noisy entries."""
        high = self.system.observation.bounds()
        noise = self._observation_noise
        return high if noise is None else np.where(noise.std.numpy() > 0, np.inf, high)

    def _gaussian(self, noise: _Noise, like: Tensor) -> Tensor:
        """``noise.std * n`` with ``n`` standard normal, shaped like ``like``."""
        draw = torch.randn(like.shape, generator=self._generators[noise.key], dtype=DTYPE)
        return noise.std * draw

    def observe(self, state: Tensor) -> Tensor:
        """What the controller sees ``(B, O)`` of the states ``(B, S)``: their observation plus
        the observation noise (a fresh draw at every call)."""
        return self.noisy(self.system.observe(state))

    def noisy(self, obs: Tensor) -> Tensor:
        """The observations ``(B, O)`` plus the observation noise (a fresh draw), if any."""
        if self._observation_noise is None:
            return obs
        return obs + self._gaussian(self._observation_noise, obs)

    def _actuate(self, command: Tensor) -> Tensor:
        """The actuator's input before its clip: the delayed command, scaled, plus noise."""
        if self.delay_steps:
            if len(self._queue) != self.delay_steps or self._queue[0].shape != command.shape:
                self.reset(command.shape[0])
            self._queue.append(command)
            command = self._queue.pop(0)
        if self._gain is not None:
            command = self._gain * command
        if self._torque_noise is not None:
            command = command + self._gaussian(self._torque_noise, command)
        return command

    def _impulse(self, state: Tensor) -> Tensor:
        """The velocity change ``(B, S)`` of this step's pushes (drawn for every episode)."""
        impulse = torch.zeros_like(state)
        batch = state.shape[0]
        for push in self._pushes:
            generator = self._generators[push.key]
            comes = torch.rand(batch, generator=generator, dtype=DTYPE) < push.probability
            negative = torch.rand(batch, generator=generator, dtype=DTYPE) < NEGATIVE_PUSH_SHARE
            size = torch.full((batch,), push.size, dtype=DTYPE)
            kick = torch.where(negative, -size, size)
            impulse[:, push.index] += torch.where(comes, kick, torch.zeros_like(kick))
        return impulse

    def friction_force(self, state: Tensor) -> Tensor:
        """The friction's generalised forces ``(B, V)`` at the states ``(B, S)``:
        ``-b v - mu sign(v)`` per degree of freedom, summed over the frictions."""
        velocities = state[..., list(self.system.velocity_indices)]
        total = torch.zeros_like(velocities)
        for friction in self._friction:
            mask = torch.zeros(velocities.shape[-1], dtype=DTYPE)
            mask[list(friction.columns)] = 1.0
            force = -friction.viscous * velocities - friction.coulomb * torch.sign(velocities)
            total = total + mask * force
        return total

    def out_of_bounds(self, state: Tensor) -> Tensor:
        """Boolean ``(B,)``: the plant's states ``(B, S)`` have left its allowed region."""
        return self.system.out_of_bounds(state)

    def step_reward(
        self, state: Tensor, action: Tensor, next_state: Tensor, leaving: Tensor, steps_left: Any
    ) -> Tensor:
        """Reward ``(B,)`` of one step of the plant (its system's
        :meth:`~leoc.systems.base.System.step_reward`)."""
        return self.system.step_reward(state, action, next_state, leaving, steps_left)

    def step(self, state: Tensor, command: Tensor) -> PlantStep:
        """One simulator step ``(B, S), (B, A)`` of the plant under the controller's command
        (clipped here to the actuator limit first; module docstring for the order). A delay's
        queue not yet filled for this batch size is filled with ``u_eq`` first (:meth:`reset`)."""
        pushed, actuated, impulse = self.inputs(state, command)
        following = self.dynamics(pushed, actuated)
        return PlantStep(following, self.system.clip_action(actuated), impulse)

    def inputs(self, state: Tensor, command: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """What :meth:`step` gives the dynamics: the state after this step's pushes, the
        actuator's input (delayed, scaled, noisy, before its clip) and the pushes' impulse."""
        actuated = self._actuate(self.system.clip_action(command))
        impulse = self._impulse(state)
        return (state + impulse if self._pushes else state), actuated, impulse

    @property
    def has_friction(self) -> bool:
        """Whether the dynamics have friction (:meth:`dynamics` then takes the forced step)."""
        return bool(self._friction)

    def dynamics(self, state: Tensor, actuated: Tensor) -> Tensor:
        """The system's step from ``state`` under the actuator input ``actuated`` (clipped by
        ``step_fn``), with the friction's forces if any."""
        if self._friction:
            return self.system.forced_step_fn(state, actuated, self.friction_force)
        return self.system.step_fn(state, actuated)


class PlantRows:
    """Several :class:`PerturbedPlant` run as one batch of episodes: plant ``i`` owns the next
    ``sizes[i]`` rows. Each steps, observes, ends and rewards its own rows exactly as it would
    alone (its random streams draw for its rows only), so one controller call serves every
    plant: what :func:`leoc.systems.rollout.simulate_settings` runs.

    Parameters
    ----------
    plants : sequence of PerturbedPlant
        At least one, all of one nominal system.
    sizes : sequence of int
        Rows per plant (positive).
    """

    def __init__(self, plants: Sequence[PerturbedPlant], sizes: Sequence[int]) -> None:
        if not plants or len(plants) != len(sizes):
            raise ValueError(
                f"sizes: expected one positive row count per plant ({len(plants)}), found "
                f"{list(sizes)}"
            )
        if any(int(size) < 1 for size in sizes):
            raise ValueError(f"sizes: expected positive row counts, found {list(sizes)}")
        self.plants = tuple(plants)
        self.sizes = tuple(int(size) for size in sizes)
        self.system = self.plants[0].nominal
        self._runs = _plant_runs(self.plants, self.sizes)

    def _check_rows(self, tensor: Tensor) -> None:
        if tensor.shape[0] != sum(self.sizes):
            raise ValueError(
                f"batch: expected {sum(self.sizes)} rows (the plants' sizes {list(self.sizes)}),"
                f" found {tensor.shape[0]}"
            )

    def _parts(self, tensor: Tensor) -> tuple[Tensor, ...]:
        """``tensor``'s rows split by plant."""
        self._check_rows(tensor)
        return torch.split(tensor, self.sizes)

    def _run_parts(self, tensor: Tensor) -> tuple[Tensor, ...]:
        """``tensor``'s rows split by run (see :func:`_plant_runs`)."""
        self._check_rows(tensor)
        return torch.split(tensor, [run.rows for run in self._runs])

    def reset(self, batch: int, episode_seed: int | None = None) -> None:
        """:meth:`PerturbedPlant.reset` of each plant for its rows (``batch`` their sum)."""
        if batch != sum(self.sizes):
            raise ValueError(f"batch: expected {sum(self.sizes)} rows, found {batch}")
        for plant, size in zip(self.plants, self.sizes, strict=True):
            plant.reset(size, episode_seed)

    def observe(self, state: Tensor) -> Tensor:
        """Each plant's :meth:`PerturbedPlant.observe` of its rows, stacked (one observation
        per run, each plant's noise on its rows)."""
        observed = []
        for run, rows in zip(self._runs, self._run_parts(state), strict=True):
            parts = torch.split(run.system.observe(rows), run.sizes)
            observed.extend(p.noisy(obs) for p, obs in zip(run.plants, parts, strict=True))
        return torch.cat(observed)

    def out_of_bounds(self, state: Tensor) -> Tensor:
        """Each plant's :meth:`PerturbedPlant.out_of_bounds` of its rows, stacked."""
        parts = zip(self._runs, self._run_parts(state), strict=True)
        return torch.cat([run.system.out_of_bounds(rows) for run, rows in parts])

    def step_reward(
        self, state: Tensor, action: Tensor, next_state: Tensor, leaving: Tensor, steps_left: Any
    ) -> Tensor:
        """Each plant's :meth:`PerturbedPlant.step_reward` of its rows, stacked."""
        split = (self._run_parts(t) for t in (state, action, next_state, leaving))
        rows = zip(self._runs, *split, strict=True)
        return torch.cat([run.system.step_reward(*row, steps_left) for run, *row in rows])

    def step(self, state: Tensor, command: Tensor) -> PlantStep:
        """Each plant's :meth:`PerturbedPlant.step` of its rows, stacked field by field (one
        step per run without friction)."""
        rows = zip(self._parts(state), self._parts(command), strict=True)
        inputs = [p.inputs(x, u) for p, (x, u) in zip(self.plants, rows, strict=True)]
        pushed, actuated, impulse = (torch.cat(field) for field in zip(*inputs, strict=True))
        following = []
        split = zip(self._runs, self._run_parts(pushed), self._run_parts(actuated), strict=True)
        for run, x, u in split:
            if run.frictionless:
                following.append(run.system.step_fn(x, u))
            else:
                split_x, split_u = torch.split(x, run.sizes), torch.split(u, run.sizes)
                parts = zip(run.plants, split_x, split_u, strict=True)
                following.extend(p.dynamics(*part) for p, *part in parts)
        return PlantStep(torch.cat(following), self.system.clip_action(actuated), impulse)


class _PlantRun(NamedTuple):
    """Consecutive plants of a :class:`PlantRows` that share one system object."""

    plants: tuple[PerturbedPlant, ...]
    sizes: tuple[int, ...]
    system: System
    frictionless: bool

    @property
    def rows(self) -> int:
        return sum(self.sizes)


def _plant_runs(plants: Sequence[PerturbedPlant], sizes: Sequence[int]) -> tuple[_PlantRun, ...]:
    """The plants cut into runs of consecutive plants sharing one system: a run's observation,
    end test, reward and (without friction) step are one call on its rows. Plants without
    parameter errors share the nominal system: placed side by side, as a sweep of several
    categories places them, they cost one call per step, not one per plant."""
    runs: list[_PlantRun] = []
    for plant, size in zip(plants, sizes, strict=True):
        if runs and runs[-1].system is plant.system:
            last = runs.pop()
            frictionless = last.frictionless and not plant.has_friction
            plant_rows = (last.plants + (plant,), last.sizes + (size,))
            runs.append(_PlantRun(*plant_rows, last.system, frictionless))
        else:
            runs.append(_PlantRun((plant,), (size,), plant.system, not plant.has_friction))
    return tuple(runs)
