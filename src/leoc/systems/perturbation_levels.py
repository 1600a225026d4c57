"""Perturbation categories and their levels, and the plants a training run is perturbed with.

Categories. A *category* names one kind of perturbation and a *level* its size, in the
category's own unit; :func:`category_perturbations` turns a level into the plant's
perturbations (:mod:`leoc.systems.perturbations`). It is the one mapping from levels to plants:
the robustness protocol's sweeps (:mod:`leoc.evaluation.robustness_protocol`) and training under
perturbation (below) both go through it.

=====================  ===============================================================
``observation_noise``  std of Gaussian noise on the observed velocities (their units);
                       positions and cos/sin pairs exact (encoders; RealAIGym's choice)
``action_delay``       delay in whole simulator steps (a controller at a longer period
                       gets fractions of its period)
``actuator_gain``      ``gain - 1``: the torque response factor, two-sided
``torque_noise``       std of Gaussian noise on the delivered force or torque (N, N m)
``viscous_friction``   ``b`` on every degree of freedom (N s/m, N m s/rad)
``coulomb_friction``   ``mu`` on every degree of freedom (N, N m)
``parameter_error``    ``factor - 1`` of one physical constant, two-sided
``push``               velocity change of the main coordinate per push, at random
                       times (:data:`PUSHES_PER_EPISODE` expected per episode)
=====================  ===============================================================

Training under perturbation. :class:`TrainingPerturbations` is what a run is trained under:

* ``fixed`` levels: every training episode runs on the plant with that level;
* ``randomised`` maxima (domain randomisation): each training episode draws its level
  uniformly between none and the maximum: in ``[0, max]``, in ``[-max, max]`` for the
  two-sided categories (:data:`TWO_SIDED_CATEGORIES`), and for the delay a whole number of
  steps, each of ``0, 1, ..., max`` equally likely.

An entry is keyed by its category, or ``parameter_error.CONSTANT`` for a parameter error
(``parameter_error.gravity``: one constant per entry, several entries for several constants).
Every entry of both kinds acts at once (each category at most once, fixed or randomised).

Seeding (what makes a run reproducible). Episode ``k`` of a run seeded ``s`` (``k`` counts the
training episodes from 0: the environment's resets for DDPG, TD3 and SAC; the real rollouts for
PILCO, its random rollouts first) draws from numpy's
``default_rng(SeedSequence([s, RANDOMISATION_STREAM, k]))``: first ``random(R)``, one uniform
``u`` in ``[0, 1)`` per randomised entry in key order (``TrainingPerturbations.randomised``),
mapped to ``max * u``, ``max * (2 u - 1)`` (two-sided) or ``min(floor((max + 1) u), max)``
(delay); then ``integers(2**32)``, the seed of the episode's random perturbations (noise and
pushes, which :class:`~leoc.systems.perturbations.PerturbedPlant` mixes with their kind, so
every episode meets fresh noise). An episode's plant depends on ``s`` and ``k`` only, whatever
ran before it: a resumed run meets the plants the uninterrupted run would have met.

Selection plants. A DDPG/TD3/SAC run trained under randomisation may select its controller on
plants of the training distribution (``selection_plants="training"`` of
:class:`leoc.sb3.DDPGConfig`) rather than on the nominal one:
:meth:`TrainingPerturbations.selection_draws` gives its ``n`` selection episodes their plants, the
same at every evaluation (so evaluations compare), stratified so that few episodes still span
each range: a Latin hypercube, episode ``k``'s uniform for entry ``j`` being
``(p_j[k] + v_kj) / n`` with ``p_j`` a random permutation of ``0 .. n-1`` and ``v_kj`` uniform in
``[0, 1)``, mapped to a level as above. Drawn from
``default_rng(SeedSequence([s, SELECTION_STREAM]))``: the permutations in key order, then the
``(n, R)`` offsets, then one noise seed per episode; fixed entries keep their level.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from leoc.names import ROBUSTNESS_CATEGORIES
from leoc.systems.base import System
from leoc.systems.perturbations import (
    ActionDelay,
    ActuatorGain,
    Friction,
    ObservationNoise,
    ParameterError,
    Perturbation,
    PerturbedPlant,
    Push,
    TorqueNoise,
)

__all__ = [
    "CATEGORY_NAMES",
    "PUSHES_PER_EPISODE",
    "RANDOMISATION_STREAM",
    "SELECTION_STREAM",
    "TWO_SIDED_CATEGORIES",
    "EpisodeDraw",
    "EpisodePlants",
    "TrainingPerturbations",
    "category_perturbations",
    "training_setting",
]

#: The categories, in report order (``leoc.names.ROBUSTNESS_CATEGORIES``).
CATEGORY_NAMES: tuple[str, ...] = ROBUSTNESS_CATEGORIES
#: Categories whose level is a signed deviation from a nominal factor of 1.
TWO_SIDED_CATEGORIES: tuple[str, ...] = ("actuator_gain", "parameter_error")
#: Expected pushes per episode (the push rate is this over the episode's duration).
PUSHES_PER_EPISODE = 2.0
#: The ``SeedSequence`` key of the training episodes' draws (module docstring).
RANDOMISATION_STREAM = 43
#: The ``SeedSequence`` key of the selection episodes' plants (module docstring).
SELECTION_STREAM = 44
SEED_SPAN = 2**32  # the episode's noise seed is drawn from [0, SEED_SPAN)
PARAMETER_ERROR = "parameter_error"
KINDS = ("fixed", "randomised")  # the two fields of TrainingPerturbations
PROBE_LEVEL = 0.5  # a level inside every range but the delay's: checks a level-0 entry's key


def _velocity_noise(system: System, level: float, seed: int) -> tuple[Perturbation, ...]:
    """Observation noise of std ``level`` on the observed velocities, none elsewhere."""
    columns = system.observation.state_columns()
    velocity = {columns[i] for i in system.velocity_indices if i in columns}
    if not velocity:
        raise ValueError(
            f"observation_noise: system {system.name!r} observes no velocity as itself "
            "(velocity_indices and its observation map)"
        )
    std = tuple(level if column in velocity else 0.0 for column in range(system.obs_dim))
    return (ObservationNoise(std, seed),)


def category_perturbations(
    system: System,
    category: str,
    level: float,
    seed: int = 0,
    action_repeat: int = 1,
    constant: str | None = None,
) -> tuple[Perturbation, ...]:
    """The plant's perturbations at ``level`` of ``category`` (module docstring's table):
    random ones seeded with ``seed``, a delay of ``level`` simulator steps converted to periods
    of ``action_repeat`` steps, a parameter error on ``constant``.

    Raises
    ------
    ValueError
        An unknown category, a parameter error without a constant, observation noise on a
        system that observes no velocity, or a level a perturbation refuses (naming it).
    """
    if category not in CATEGORY_NAMES:
        raise ValueError(
            f"category: expected one of {', '.join(CATEGORY_NAMES)}, found {category!r}"
        )
    if category == "observation_noise":
        return _velocity_noise(system, level, seed)
    if category == "action_delay":
        return (ActionDelay(level / action_repeat),)
    if category == "actuator_gain":
        return (ActuatorGain(1.0 + level),)
    if category == "torque_noise":
        return (TorqueNoise(level, seed),)
    if category == "viscous_friction":
        return (Friction(viscous=level),)
    if category == "coulomb_friction":
        return (Friction(coulomb=level),)
    if category == PARAMETER_ERROR:
        if constant is None:
            raise ValueError("constant: a parameter error scales a named constant, found None")
        return (ParameterError(str(constant), 1.0 + level),)
    rate = PUSHES_PER_EPISODE / (system.episode_steps * system.dt)
    return (Push(level, rate, seed=seed),)


def _split(key: str) -> tuple[str, str | None]:
    """``(category, constant)`` of an entry's key (``parameter_error.gravity``)."""
    category, _, constant = key.partition(".")
    return category, constant or None


def _order(key: str) -> tuple[int, str]:
    """Sort key of an entry: its category's place in :data:`CATEGORY_NAMES`, then the key."""
    return CATEGORY_NAMES.index(_split(key)[0]), key


def _check_key(kind: str, key: Any) -> None:
    """A known category, with a constant for (and only for) a parameter error."""
    category, constant = _split(key) if isinstance(key, str) else (key, None)
    if category not in CATEGORY_NAMES:
        raise ValueError(
            f"{kind}: expected a category among {', '.join(CATEGORY_NAMES)} (parameter errors "
            f"as {PARAMETER_ERROR}.CONSTANT), found {key!r}"
        )
    if (category == PARAMETER_ERROR) != (constant is not None):
        raise ValueError(
            f"{kind}: {key}: expected {PARAMETER_ERROR}.CONSTANT for a parameter error (a "
            f"physical constant of the system, e.g. {PARAMETER_ERROR}.gravity) and a bare "
            "category otherwise"
        )


def _check_level(kind: str, key: str, level: Any) -> float:
    """The level (``fixed``) or maximum (``randomised``) of entry ``key`` as a float, in its
    category's range (raises naming the kind and the key): >= 0, a signed level of a two-sided
    category down to a gain of 0 or a factor above 0, whole steps of delay."""
    what = "a maximum" if kind == "randomised" else "a level"
    if isinstance(level, bool) or not isinstance(level, (int, float, np.floating)):
        raise ValueError(f"{kind}: {key}: expected {what} (a number), found {level!r}")
    value = float(level)
    category = _split(key)[0]
    low = -1.0 if category in TWO_SIDED_CATEGORIES and kind == "fixed" else 0.0
    if category == "actuator_gain":
        inside, shown = low <= value <= 1.0, f"in [{low:g}, 1] (a gain >= 0)"
    elif category == PARAMETER_ERROR:
        above = value > low if low else value >= 0.0
        inside, shown = above and value < 1.0, f"in {'(-1' if low else '[0'}, 1) (a factor > 0)"
    else:
        inside, shown = value >= 0.0, ">= 0"
    if not math.isfinite(value) or not inside:
        raise ValueError(f"{kind}: {key}: expected {what} {shown}, found {level!r}")
    if category == "action_delay" and value != int(value):
        raise ValueError(f"{kind}: {key}: expected whole simulator steps, found {level!r}")
    return value


def _entries(kind: str, given: Any) -> tuple[tuple[str, float], ...]:
    """The entries of ``given`` (a mapping, or ``(key, level)`` pairs) checked and sorted."""
    pairs = list(given.items()) if isinstance(given, Mapping) else list(given or ())
    keys = [pair[0] for pair in pairs]
    for key in keys:
        _check_key(kind, key)
    repeated = sorted({key for key in keys if keys.count(key) > 1})
    if repeated:
        raise ValueError(f"{kind}: expected each category once, found {repeated} twice")
    checked = [(key, _check_level(kind, key, level)) for key, level in pairs]
    return tuple(sorted(checked, key=lambda pair: _order(pair[0])))


def _drawn_level(key: str, maximum: float, uniform: float) -> float:
    """The level of a randomised entry for the uniform draw ``uniform`` in [0, 1)."""
    category = _split(key)[0]
    if category == "action_delay":
        return float(min(math.floor((maximum + 1.0) * uniform), maximum))
    if category in TWO_SIDED_CATEGORIES:
        return maximum * (2.0 * uniform - 1.0)
    return maximum * uniform


class EpisodeDraw(NamedTuple):
    """One training episode's plant: its ``levels`` by key (fixed and drawn), the ``seed`` of
    its random perturbations and the ``perturbations`` themselves."""

    levels: dict[str, float]
    seed: int
    perturbations: tuple[Perturbation, ...]


@dataclasses.dataclass(frozen=True)
class TrainingPerturbations:
    """What a run is trained under: fixed levels and randomised maxima (module docstring).

    Attributes
    ----------
    fixed : tuple of (str, float)
        ``(key, level)``: the plant of every training episode has that level (a mapping is
        accepted and sorted); signed for the two-sided categories (``actuator_gain=-0.5``: a
        gain of 0.5).
    randomised : tuple of (str, float)
        ``(key, maximum)``: each episode draws its level between none and the maximum
        (``[-max, max]`` for the two-sided categories); a maximum >= 0.

    Raises
    ------
    ValueError
        Naming the field and the key: an unknown category, a parameter error without its
        constant, a key given twice or in both fields, a level that is not a finite number, a
        negative level or maximum (one-sided categories), a gain below 0 or a factor not
        above 0, a delay that is not whole.
    """

    fixed: tuple[tuple[str, float], ...] = ()
    randomised: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        for kind in KINDS:
            object.__setattr__(self, kind, _entries(kind, getattr(self, kind)))
        both = sorted(set(dict(self.fixed)) & set(dict(self.randomised)))
        if both:
            raise ValueError(
                f"randomised: {', '.join(both)}: also fixed (each category fixed or randomised, "
                "once)"
            )

    @property
    def is_nominal(self) -> bool:
        """Whether it names no perturbation (training on the nominal plant)."""
        return not self.fixed and not self.randomised

    def as_dict(self) -> dict[str, dict[str, float]]:
        """``{"fixed": {key: level}, "randomised": {key: maximum}}`` (a run's config records
        it; :meth:`from_dict` reads it back)."""
        return {kind: dict(getattr(self, kind)) for kind in KINDS}

    @classmethod
    def from_dict(cls, record: Mapping[str, Any] | None) -> TrainingPerturbations:
        """The spec :meth:`as_dict` wrote (None or ``{}``: nominal).

        Raises
        ------
        ValueError
            A record that is not a mapping of ``fixed`` and ``randomised`` mappings.
        """
        record = {} if record is None else record
        if not isinstance(record, Mapping) or set(record) - set(KINDS):
            raise ValueError(
                f"training_perturbations: expected a mapping with keys among {KINDS}, found "
                f"{record!r}"
            )
        for kind in KINDS:
            if not isinstance(record.get(kind, {}), Mapping):
                raise ValueError(
                    f"{kind}: expected a mapping of key -> level, found {record[kind]!r}"
                )
        return cls(**{kind: tuple(dict(record.get(kind, {})).items()) for kind in KINDS})

    def describe(self) -> str:
        """The entries in words (``observation_noise randomised up to 0.1; actuator_gain fixed
        at -0.2``), ``nominal`` without any."""
        fixed = [f"{key} fixed at {level:g}" for key, level in self.fixed]
        drawn = [f"{key} randomised up to {level:g}" for key, level in self.randomised]
        return "; ".join(fixed + drawn) or "nominal"

    def perturbations_at(
        self, system: System, levels: Mapping[str, float], seed: int = 0, action_repeat: int = 1
    ) -> tuple[Perturbation, ...]:
        """The plant's perturbations at ``levels`` (by key), random ones seeded ``seed``."""
        found: list[Perturbation] = []
        for key, level in levels.items():
            category, constant = _split(key)
            found += category_perturbations(system, category, level, seed, action_repeat, constant)
        return tuple(found)

    def episode(
        self, system: System, seed: int, episode: int, action_repeat: int = 1
    ) -> EpisodeDraw:
        """Episode ``episode``'s plant in a run seeded ``seed`` (module docstring's draw)."""
        rng = np.random.default_rng(np.random.SeedSequence([seed, RANDOMISATION_STREAM, episode]))
        uniforms = rng.random(len(self.randomised))
        noise_seed = int(rng.integers(SEED_SPAN))
        levels = dict(self.fixed)
        for (key, maximum), uniform in zip(self.randomised, uniforms, strict=True):
            levels[key] = _drawn_level(key, maximum, float(uniform))
        perturbations = self.perturbations_at(system, levels, noise_seed, action_repeat)
        return EpisodeDraw(levels, noise_seed, perturbations)

    def selection_draws(
        self, system: System, seed: int, episodes: int, action_repeat: int = 1
    ) -> list[EpisodeDraw]:
        """The plants of the ``episodes`` selection episodes of a run seeded ``seed`` (module
        docstring: one stratum of each randomised range per episode)."""
        if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes <= 0:
            raise ValueError(f"episodes: expected a positive int, found {episodes!r}")
        rng = np.random.default_rng(np.random.SeedSequence([seed, SELECTION_STREAM]))
        strata = [rng.permutation(episodes) for _ in self.randomised]
        offsets = rng.random((episodes, len(self.randomised)))
        draws = []
        for k in range(episodes):
            levels = dict(self.fixed)
            for j, (key, maximum) in enumerate(self.randomised):
                uniform = (float(strata[j][k]) + float(offsets[k, j])) / episodes
                levels[key] = _drawn_level(key, maximum, uniform)
            noise_seed = int(rng.integers(SEED_SPAN))
            found = self.perturbations_at(system, levels, noise_seed, action_repeat)
            draws.append(EpisodeDraw(levels, noise_seed, found))
        return draws

    def widest(self, system: System, action_repeat: int = 1) -> tuple[Perturbation, ...]:
        """The perturbations with every randomised entry at its maximum (the environment's
        observation bounds come from them: unbounded where any episode is noisy)."""
        return self.perturbations_at(
            system, {**dict(self.fixed), **dict(self.randomised)}, 0, action_repeat
        )

    def check(self, system: System, action_repeat: int = 1) -> None:
        """Raise, naming the field and the key, where an entry does not fit ``system``: a
        constant it does not have (or its time step or actuator limit), observation noise on a
        system that observes no velocity, a delay longer than an episode (an entry at level 0
        too, though its plant is the nominal one)."""
        for kind in KINDS:
            for key, level in getattr(self, kind):
                category, constant = _split(key)
                if category == "action_delay" and level > system.episode_steps:
                    raise ValueError(
                        f"{kind}: {key}: expected at most an episode ({system.episode_steps} "
                        f"steps), found {level:g}"
                    )
                signed = kind == "randomised" and category in TWO_SIDED_CATEGORIES
                # a level-0 perturbation is not applied: probe the entry at a level that is
                probe = level if level or category == "action_delay" else PROBE_LEVEL
                try:
                    for tried in {probe, -probe} if signed else {probe}:
                        found = category_perturbations(
                            system, category, tried, 0, action_repeat, constant
                        )
                        PerturbedPlant(system, found, action_repeat)
                except ValueError as error:
                    raise ValueError(f"{kind}: {key}: {error}") from None


class EpisodePlants:
    """The plants of a run's training episodes, in order: :meth:`next` builds episode ``k``'s
    :class:`~leoc.systems.perturbations.PerturbedPlant` (:meth:`TrainingPerturbations.episode`)
    and counts it. It is plain picklable state (the count), so an environment checkpointed with
    it goes on with the next episode's plant.

    Parameters
    ----------
    spec : TrainingPerturbations
        What the run is trained under (checked against ``system`` here).
    system : System
        The nominal system.
    seed : int
        The run's seed.
    action_repeat : int
        The agent's period in simulator steps (converts a delay's steps to periods).
    """

    def __init__(
        self, spec: TrainingPerturbations, system: System, seed: int, action_repeat: int = 1
    ) -> None:
        spec.check(system, action_repeat)
        self.spec = spec
        self.system = system
        self.seed = int(seed)
        self.action_repeat = int(action_repeat)
        self.episodes = 0

    def next(self) -> PerturbedPlant:
        """The plant of the next training episode (counted)."""
        drawn = self.spec.episode(self.system, self.seed, self.episodes, self.action_repeat)
        self.episodes += 1
        return PerturbedPlant(self.system, drawn.perturbations, self.action_repeat)

    def widest(self) -> PerturbedPlant:
        """The plant with every randomised entry at its maximum
        (:meth:`TrainingPerturbations.widest`)."""
        perturbations = self.spec.widest(self.system, self.action_repeat)
        return PerturbedPlant(self.system, perturbations, self.action_repeat)

    def levels(self) -> list[dict[str, float]]:
        """The levels of every episode begun so far, in order."""
        return [
            self.spec.episode(self.system, self.seed, k, self.action_repeat).levels
            for k in range(self.episodes)
        ]


#: The config field of a run's :class:`TrainingPerturbations` (DDPG/TD3/SAC's and PILCO's).
SETTING = "training_perturbations"


def training_setting(record: Any, system: str | System, action_repeat: int = 1) -> dict[str, Any]:
    """A run config's ``training_perturbations`` as it is recorded: the canonical
    :meth:`TrainingPerturbations.as_dict`, or ``{}`` for training on the nominal plant (a
    config that records nothing, as every run before training under perturbation).

    Raises
    ------
    ValueError
        ``training_perturbations: <field>: <key>: ...``, naming what is wrong
        (:class:`TrainingPerturbations`, :meth:`TrainingPerturbations.check` on ``system``).
    """
    from leoc.systems.registry import make_system

    try:
        spec = TrainingPerturbations.from_dict(record)
        if not spec.is_nominal:
            plant = make_system(system) if isinstance(system, str) else system
            spec.check(plant, action_repeat)
    except ValueError as error:
        message = str(error)
        prefix = "" if message.startswith(f"{SETTING}:") else f"{SETTING}: "
        raise ValueError(prefix + message) from None
    return {} if spec.is_nominal else spec.as_dict()
