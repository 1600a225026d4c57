"""A robustness protocol as practitioners test controllers: noise, delay, actuators, friction,
parameter errors and pushes, each swept from none to a level at which the LQR fails.

Modelled on the RealAIGym leaderboard's robustness score (Wiebe et al., "RealAIGym: education
and research platform for studying athletic intelligence", 2022; its double-pendulum
leaderboard): per *category* a sweep of levels (21 by default), ``N`` episodes per level, and
the share of them that succeed; the categories' mean is one robustness score.

Protocol. For every category of :data:`CATEGORY_NAMES` and every level of its grid
(:func:`level_grid`, from none to the system's maximum of :data:`DEFAULT_MAX_LEVELS`), the
controller runs ``episodes`` full episodes from the system's operating region
(:meth:`~leoc.systems.base.System.sample_operating_region`, as the mass/gravity sweep of
:mod:`leoc.evaluation.robustness`) and ``episodes`` from its swing-up start
(:meth:`~leoc.systems.base.System.sample_start`), on the plant with that category's
perturbation at that level (:mod:`leoc.systems.perturbations`; every other category at its
nominal level). An episode *succeeds* when it passes leoc's one hold test
(:meth:`~leoc.systems.base.System.hold_step`: not terminated, and the main coordinate inside
the hold band for at least the system's minimum hold duration at the end). Then

.. math::

    s_c = \\frac{\\#\\,\\text{held}}{L_c \\, K \\, N}, \\qquad
    s = \\frac{1}{C} \\sum_c s_c

with ``L_c`` the levels of category ``c`` (times its constants for the parameter errors),
``K`` the start kinds, ``N`` the episodes per start kind and ``C`` the categories run.

Categories: each level's unit and what it perturbs are tabled once, in
:mod:`leoc.systems.perturbation_levels`, whose
:func:`~leoc.systems.perturbation_levels.category_perturbations` is the one mapping from a
level to the plant (training under perturbation uses it too). The protocol sweeps the parameter
errors one constant at a time: one sub-sweep per constant of the system's table entry.

Friction is two categories, as RealAIGym scores damping and Coulomb friction apart: they act
differently (damping slows, Coulomb friction makes a dead zone), and one category would need an
arbitrary ratio of the two. The parameter errors are one category whose level grid is run once
per constant: every constant is perturbed on its own, and the robustness score weighs model
error as one kind of perturbation, like noise, whatever the number of constants a system has
(the acrobot has eight).

Seeds. One ``seed`` decides everything: the starts (the same at every level and category) and
the seed of every random perturbation, derived from ``seed``, the category and the start kind
(numpy's ``SeedSequence``), the same at every level: episode ``i`` of a level draws row ``i`` of
that stream, so the levels of a category differ in size only (common random numbers), and two
controllers run with one seed meet the same noise and pushes.

References
----------
Wiebe, F., Vyas, S., Maywald, L. J., Kumar, S., Kirchner, F., "RealAIGym: Education and
Research Platform for Studying Athletic Intelligence", RSS workshop on mind the gap, 2022.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from leoc.io import write_json_atomic
from leoc.names import ROBUSTNESS_CATEGORIES, ROBUSTNESS_EPISODES, ROBUSTNESS_LEVELS
from leoc.systems.base import System
from leoc.systems.perturbation_levels import (
    TWO_SIDED_CATEGORIES,
    category_perturbations,
)
from leoc.systems.perturbations import Perturbation
from leoc.systems.rollout import (
    BatchTrajectory,
    Controller,
    control_period,
    hold_step,
    simulate,
    simulate_settings,
)

__all__ = [
    "CALIBRATION_BISECTIONS",
    "CALIBRATION_EPISODES",
    "CALIBRATION_SEARCH",
    "CATEGORY_NAMES",
    "DEFAULT_EPISODES",
    "DEFAULT_LEVELS",
    "DEFAULT_MAX_LEVELS",
    "PROTOCOL_START_KINDS",
    "MAX_LEVEL_DIGITS",
    "CategoryResult",
    "FailureLevel",
    "LevelResult",
    "MaxLevels",
    "ProtocolResult",
    "Setting",
    "category_settings",
    "failure_level",
    "level_grid",
    "max_levels_for",
    "measured_max_levels",
    "protocol_starts",
    "run_protocol",
]

#: The categories, in report order (``leoc.names.ROBUSTNESS_CATEGORIES``).
CATEGORY_NAMES: tuple[str, ...] = ROBUSTNESS_CATEGORIES
#: Levels per category (RealAIGym's 21): an odd count puts the nominal plant in the middle of
#: a two-sided grid.
DEFAULT_LEVELS: int = ROBUSTNESS_LEVELS
#: Episodes per level and start kind: 21 levels x 2 kinds x 5 episodes is 210 per category.
DEFAULT_EPISODES: int = ROBUSTNESS_EPISODES
#: Where the episodes start: the operating region, and the swing-up start.
PROTOCOL_START_KINDS: tuple[str, ...] = ("operating_region", "swing_up")
STARTS_STREAM = 0  # the SeedSequence key of the starts (categories count from 1)


@dataclasses.dataclass(frozen=True)
class MaxLevels:
    """The largest level of each category for one system: the end of its sweeps.

    Each is the level at which the system's LQR (leoc's discrete design at period 1) holds none
    of ten operating-region episodes, rounded (``docs/user_guide/evaluation.md`` has the
    measurement), so each sweep runs from the nominal plant across the LQR's breakdown.

    Attributes
    ----------
    observation_noise : float
        Std of the velocity observation noise, in the velocities' units.
    action_delay : int
        Delay in simulator steps.
    actuator_gain : float
        Largest ``|gain - 1|``, at most 1.
    torque_noise : float
        Std of the torque noise, N or N m.
    viscous_friction, coulomb_friction : float
        Friction coefficients (N s/m or N m s/rad; N or N m).
    parameter_error : float
        Largest ``|factor - 1|`` of a constant, below 1.
    push : float
        Velocity change of a push, in the main coordinate's velocity units.
    constants : tuple of str
        The physical constants perturbed one at a time (``ParameterError`` names).
    """

    observation_noise: float
    action_delay: int
    actuator_gain: float
    torque_noise: float
    viscous_friction: float
    coulomb_friction: float
    parameter_error: float
    push: float
    constants: tuple[str, ...] = ("mass", "gravity")

    def __post_init__(self) -> None:
        for name in CATEGORY_NAMES:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise ValueError(f"MaxLevels.{name}: expected a positive number, found {value!r}")
        if int(self.action_delay) != self.action_delay:
            raise ValueError(
                f"MaxLevels.action_delay: expected whole simulator steps, found "
                f"{self.action_delay!r}"
            )
        # A factor 1 - level must stay >= 0 for a gain (a dead motor) and > 0 for a constant.
        if self.actuator_gain > 1.0:
            raise ValueError(
                f"MaxLevels.actuator_gain: expected a deviation of at most 1 (a gain >= 0), "
                f"found {self.actuator_gain!r}"
            )
        if self.parameter_error >= 1.0:
            raise ValueError(
                f"MaxLevels.parameter_error: expected a deviation below 1 (a factor > 0), "
                f"found {self.parameter_error!r}"
            )
        if not self.constants:
            raise ValueError("MaxLevels.constants: expected at least one constant, found none")

    def level(self, category: str) -> float:
        """The maximum level of ``category``."""
        return float(getattr(self, _category(category)))


#: The measured maximum levels of the built-in systems (:class:`MaxLevels`; the measurement
#: and its command are in ``docs/user_guide/evaluation.md``).
DEFAULT_MAX_LEVELS: dict[str, MaxLevels] = {
    # Order: observation noise, delay (steps), gain, torque noise, viscous, Coulomb, parameter
    # error, push; then the constants.
    "pendulum": MaxLevels(0.66, 3, 0.48, 1.4, 13.0, 4.0, 0.62, 1.8, ("gravity", "mass", "length")),
    "cartpole": MaxLevels(
        0.7,
        3,
        0.77,
        1.6,
        0.0069,
        0.0014,
        0.66,
        5.0,
        ("gravity", "cart_mass", "pole_mass", "half_length"),
    ),
    "mountaincar": MaxLevels(
        1.4, 8, 0.62, 0.94, 9.5, 6.0, 0.92, 6.1, ("gravity", "mass", "hill_amplitude")
    ),
    "acrobot": MaxLevels(
        0.064,
        3,
        0.51,
        4.0,
        1.4,
        0.11,
        0.16,
        0.12,
        ("gravity", "link_mass_1", "link_mass_2", "link_length_1")
        + ("link_com_1", "link_com_2", "link_moi_1", "link_moi_2"),
    ),
}


def _category(name: str) -> str:
    """``name`` if it is a category, else raise naming the choices."""
    if name not in CATEGORY_NAMES:
        raise ValueError(f"category: expected one of {', '.join(CATEGORY_NAMES)}, found {name!r}")
    return name


def max_levels_for(system: System | str) -> MaxLevels:
    """The :data:`DEFAULT_MAX_LEVELS` entry of ``system`` (a system or its name).

    Raises
    ------
    ValueError
        For a system without an entry (give ``max_levels`` to :func:`run_protocol`).
    """
    name = system if isinstance(system, str) else system.name
    if name not in DEFAULT_MAX_LEVELS:
        raise ValueError(
            f"system: expected one of {', '.join(DEFAULT_MAX_LEVELS)} (the systems with measured "
            f"maximum levels), found {name!r}; pass max_levels=MaxLevels(...) for it"
        )
    return DEFAULT_MAX_LEVELS[name]


def level_grid(category: str, max_level: float, count: int = DEFAULT_LEVELS) -> tuple[float, ...]:
    """The levels of ``category`` up to ``max_level``: ``count`` evenly spaced from 0 (from
    ``-max_level`` for the two-sided ones), and for ``action_delay`` the distinct whole steps
    among them (all of ``0 .. max_level`` when there are more levels than steps)."""
    _category(category)
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 2:
        raise ValueError(f"levels: expected an integer >= 2, found {count!r}")
    low = -max_level if category in TWO_SIDED_CATEGORIES else 0.0
    grid = np.linspace(low, max_level, int(count))
    if category == "action_delay":
        grid = np.unique(np.round(grid))
    # The middle of a symmetric odd grid is 0 up to round-off: make it exactly the nominal plant.
    grid[np.isclose(grid, 0.0, rtol=0.0, atol=1e-12 * max_level)] = 0.0
    return tuple(float(level) for level in grid)


class Setting(NamedTuple):
    """One level of a category: the ``level``, the ``constant`` a parameter error scales (None
    elsewhere) and the plant's ``perturbations``."""

    level: float
    constant: str | None
    perturbations: tuple[Perturbation, ...]


def category_settings(
    system: System,
    category: str,
    max_levels: MaxLevels,
    count: int = DEFAULT_LEVELS,
    seed: int = 0,
    action_repeat: int = 1,
) -> list[Setting]:
    """Every setting of ``category`` in sweep order: its :func:`level_grid` (per constant of
    ``max_levels.constants`` for ``parameter_error``), random perturbations seeded with
    ``seed``, a delay converted to periods of ``action_repeat`` steps."""
    grid = level_grid(category, max_levels.level(category), count)
    constants = max_levels.constants if category == "parameter_error" else (None,)
    return [
        Setting(
            level,
            constant,
            category_perturbations(system, category, level, seed, action_repeat, constant),
        )
        for constant in constants
        for level in grid
    ]


def _derived_seed(seed: int, *keys: int) -> int:
    """A non-negative 32-bit seed mixed from ``seed`` and ``keys`` (numpy's SeedSequence)."""
    return int(np.random.SeedSequence([seed, *keys]).generate_state(1)[0])


def protocol_starts(system: System, episodes: int, seed: int = 0) -> dict[str, np.ndarray]:
    """``(episodes, S)`` starts per kind of :data:`PROTOCOL_START_KINDS`, from ``seed``: uniform
    in the operating region, and the system's swing-up start distribution."""
    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or episodes < 1:
        raise ValueError(f"episodes: expected a positive integer, found {episodes!r}")
    rng = np.random.default_rng(_derived_seed(seed, STARTS_STREAM))
    region = system.sample_operating_region(rng, int(episodes))
    swing_up = np.stack([system.sample_start(rng, "swing_up") for _ in range(int(episodes))])
    return {"operating_region": region, "swing_up": swing_up}


class LevelResult(NamedTuple):
    """One setting's episodes.

    Attributes
    ----------
    level : float
        The category's level (its unit: module docstring).
    constant : str or None
        The constant a parameter error scales; None for the other categories.
    held : dict of str to list of bool
        Per start kind, whether each episode passed the hold test.
    perturbations : dict of str to list of dict
        Per start kind, the plant's perturbations
        (:meth:`~leoc.systems.perturbations.Perturbation.as_dict`; the kinds differ in the
        seeds of the random ones only).
    """

    level: float
    constant: str | None
    held: dict[str, list[bool]]
    perturbations: dict[str, list[dict[str, Any]]]

    def held_count(self, start_kind: str | None = None) -> tuple[int, int]:
        """Episodes held and episodes run, from ``start_kind`` (None: every kind)."""
        kinds = list(self.held) if start_kind is None else [start_kind]
        runs = [episode for kind in kinds for episode in self.held.get(kind, [])]
        return int(sum(runs)), len(runs)


class CategoryResult(NamedTuple):
    """One category's sweep: its ``name``, ``max_level`` and the :class:`LevelResult` of every
    setting (per constant, then level, for ``parameter_error``)."""

    name: str
    max_level: float
    levels: list[LevelResult]

    def score(self, start_kind: str | None = None) -> float:
        """Share of the episodes (levels x episodes) held, from ``start_kind`` (None: every
        kind); NaN when none ran."""
        counts = [level.held_count(start_kind) for level in self.levels]
        held, total = (sum(column) for column in zip(*counts, strict=True))
        return held / total if total else float("nan")

    def curve(self, constant: str | None = None) -> tuple[list[float], list[float]]:
        """Levels and the share held at each (every start kind), of one constant's sub-sweep
        for ``parameter_error``."""
        chosen = [level for level in self.levels if level.constant == constant]
        shares = [held / total for held, total in (level.held_count() for level in chosen)]
        return [level.level for level in chosen], shares


class ProtocolResult(NamedTuple):
    """The protocol's outcome for one controller on one system (JSON-friendly: lists, dicts
    and numbers only; :meth:`as_dict`, :meth:`from_dict`, :meth:`save`, :meth:`load`).

    Attributes
    ----------
    system : str
        The system's name.
    controller : str
        The controller's label.
    seed, episodes, level_count, action_repeat : int
        The protocol's seed, episodes per level and start kind, levels per category, and the
        controller's control period in simulator steps.
    max_levels : dict
        The :class:`MaxLevels` the sweeps ran to (its fields).
    starts : dict of str to list
        The starts of each kind (``episodes`` states each).
    categories : list of CategoryResult
        One per category run, in :data:`CATEGORY_NAMES` order.
    """

    system: str
    controller: str
    seed: int
    episodes: int
    level_count: int
    action_repeat: int
    max_levels: dict[str, Any]
    starts: dict[str, list[list[float]]]
    categories: list[CategoryResult]

    def scores(self, start_kind: str | None = None) -> dict[str, float]:
        """Each category's score (:meth:`CategoryResult.score`), by name."""
        return {category.name: category.score(start_kind) for category in self.categories}

    def score(self, start_kind: str | None = None) -> float:
        """The robustness score: the mean of the category scores."""
        return float(np.mean(list(self.scores(start_kind).values())))

    def as_dict(self) -> dict[str, Any]:
        """Plain dicts and lists (what :meth:`save` writes), with the scores for readers."""
        record = self._asdict()
        record["categories"] = [
            {**category._asdict(), "levels": [level._asdict() for level in category.levels]}
            for category in self.categories
        ]
        record["scores"] = {
            "all": {**self.scores(), "robustness": self.score()},
            **{kind: {**self.scores(kind), "robustness": self.score(kind)} for kind in self.starts},
        }
        return record

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> ProtocolResult:
        """The result :meth:`as_dict` wrote (its derived ``scores`` are recomputed)."""
        fields = {name: record[name] for name in cls._fields}
        fields["categories"] = [
            CategoryResult(
                entry["name"],
                float(entry["max_level"]),
                [LevelResult(**level) for level in entry["levels"]],
            )
            for entry in record["categories"]
        ]
        return cls(**fields)

    def save(self, path: str | Path) -> Path:
        """Write :meth:`as_dict` to ``path`` as JSON, atomically."""
        return write_json_atomic(path, self.as_dict())

    @classmethod
    def load(cls, path: str | Path) -> ProtocolResult:
        """The result :meth:`save` wrote to ``path``."""
        import json

        return cls.from_dict(json.loads(Path(path).read_text(encoding="utf-8")))


def _held(
    system: System, controller: Controller, starts: np.ndarray, setting: Setting
) -> list[bool]:
    """Whether each episode from ``starts`` passes the hold test on the perturbed plant."""
    return _held_episodes(
        system, simulate(system, controller, starts, perturbations=setting.perturbations)
    )


def _held_episodes(system: System, batch: BatchTrajectory) -> list[bool]:
    """Whether each episode of ``batch`` passes the hold test."""
    return [hold_step(system, batch.episode(i)) is not None for i in range(len(batch.lengths))]


def _category_sweeps(
    system: System,
    controller: Controller,
    category: str,
    max_levels: MaxLevels,
    starts: Mapping[str, np.ndarray],
    options: _Options,
) -> dict[str, list[Setting]]:
    """The settings of one category's sweep per start kind (the kinds differ in the random
    perturbations' seeds only)."""
    key = CATEGORY_NAMES.index(category) + 1
    return {
        kind: category_settings(
            system,
            category,
            max_levels,
            options.levels,
            _derived_seed(options.seed, key, PROTOCOL_START_KINDS.index(kind)),
            control_period(controller),
        )
        for kind in starts
    }


def _category_result(
    category: str,
    max_levels: MaxLevels,
    sweeps: Mapping[str, list[Setting]],
    held: Mapping[str, list[list[bool]]],
) -> CategoryResult:
    """One category's result from its settings and, per start kind, each setting's episodes."""
    kinds = list(sweeps)
    results = []
    for index, setting in enumerate(sweeps[kinds[0]]):
        records = {kind: [p.as_dict() for p in sweeps[kind][index].perturbations] for kind in kinds}
        level_held = {kind: held[kind][index] for kind in kinds}
        results.append(LevelResult(setting.level, setting.constant, level_held, records))
    return CategoryResult(category, max_levels.level(category), results)


def _held_everywhere(
    system: System,
    controller: Controller,
    starts: Mapping[str, np.ndarray],
    settings: Mapping[str, list[Setting]],
    progress: Callable[[str, int, int], None] | None = None,
) -> dict[str, list[list[bool]]]:
    """:func:`_held` of every start kind at each of its settings, ``{kind: [held, ...]}``: one
    batch per start kind (:func:`~leoc.systems.rollout.simulate_settings`: one controller
    call per decision for every category's sweep). Not one batch for both: a batch steps until
    its last episode ends, and the swing-up starts often end early (the cart-pole's LQR leaves
    the track within 18 steps), which made the cart-pole's protocol 31.5 s in one batch against
    15.2 + 1.7 s in two. ``progress`` is called after each kind's batch with (kind, kinds
    done, kinds)."""
    held = {}
    for index, (kind, rows) in enumerate(starts.items()):
        pairs = [(rows, setting.perturbations) for setting in settings[kind]]
        batches = simulate_settings(system, controller, pairs)
        held[kind] = [_held_episodes(system, batch) for batch in batches]
        if progress is not None:
            progress(kind, index + 1, len(starts))
    return held


def _run_sweeps(
    system: System,
    controller: Controller,
    starts: Mapping[str, np.ndarray],
    sweeps: Mapping[str, Mapping[str, list[Setting]]],
    max_levels: MaxLevels,
    progress: Callable[[str, int, int], None] | None,
) -> list[CategoryResult]:
    """Every category's result, ``sweeps`` (``{category: {kind: settings}}``) run as one
    batch per start kind."""
    every_setting = {kind: [s for sweep in sweeps.values() for s in sweep[kind]] for kind in starts}
    held = _held_everywhere(system, controller, starts, every_setting, progress)
    results, done = [], 0
    for category, sweep in sweeps.items():
        count = len(sweep[next(iter(starts))])
        part = {kind: held[kind][done : done + count] for kind in starts}
        results.append(_category_result(category, max_levels, sweep, part))
        done += count
    return results


class _Options(NamedTuple):
    """What every category of one :func:`run_protocol` shares."""

    levels: int
    seed: int


def _chosen(categories: Sequence[str], start_kinds: Sequence[str]) -> list[str]:
    """The categories to run, in :data:`CATEGORY_NAMES` order (raises naming a bad argument:
    an unknown or no category, an unknown or no start kind)."""
    chosen = [name for name in CATEGORY_NAMES if name in {_category(c) for c in categories}]
    if not chosen:
        raise ValueError("categories: expected at least one category, found none")
    unknown = [kind for kind in start_kinds if kind not in PROTOCOL_START_KINDS]
    if unknown or not start_kinds:
        raise ValueError(
            f"start_kinds: expected some of {PROTOCOL_START_KINDS}, found {list(start_kinds)}"
        )
    return chosen


def run_protocol(
    system: System,
    controller: Controller,
    label: str = "controller",
    levels: int = DEFAULT_LEVELS,
    episodes: int = DEFAULT_EPISODES,
    categories: Sequence[str] = CATEGORY_NAMES,
    seed: int = 0,
    max_levels: MaxLevels | None = None,
    start_kinds: Sequence[str] = PROTOCOL_START_KINDS,
    progress: Callable[[str, int, int], None] | None = None,
) -> ProtocolResult:
    """Run the robustness protocol (module docstring) on ``controller``.

    Parameters
    ----------
    system : System
        The nominal plant (the one the controller was designed or trained for).
    controller : callable
        Runs at its own control period.
    label : str
        The controller's name in the result.
    levels, episodes : int
        Levels per category (>= 2) and episodes per level and start kind (>= 1).
    categories : sequence of str
        Some of :data:`CATEGORY_NAMES` (run in that order).
    seed : int
        The one seed (module docstring).
    max_levels : MaxLevels, optional
        The end of each sweep; default :func:`max_levels_for` the system.
    start_kinds : sequence of str
        Some of :data:`PROTOCOL_START_KINDS`.
    progress : callable, optional
        Called with (start kind, kinds done, kinds) after each start kind's episodes (every
        category's settings run as one batch per start kind).

    Returns
    -------
    ProtocolResult
    """
    chosen = _chosen(categories, start_kinds)
    limits = max_levels_for(system) if max_levels is None else max_levels
    every = protocol_starts(system, episodes, seed)
    starts = {kind: every[kind] for kind in PROTOCOL_START_KINDS if kind in start_kinds}
    options = _Options(levels, seed)
    level_grid(chosen[0], 1.0, levels)  # checks ``levels`` before anything runs
    sweeps = {c: _category_sweeps(system, controller, c, limits, starts, options) for c in chosen}
    results = _run_sweeps(system, controller, starts, sweeps, limits, progress)
    return ProtocolResult(
        system.name,
        label,
        int(seed),
        int(episodes),
        int(levels),
        control_period(controller),
        dataclasses.asdict(limits),
        {kind: value.tolist() for kind, value in starts.items()},
        results,
    )


#: Calibration (:func:`failure_level`): first level tried and largest level searched per
#: category, as multiples of the actuator limit for the torques and in the level's own units
#: elsewhere (the two-sided ones: deviations from a factor of 1). Coulomb friction stops at
#: twice the actuator limit: the explicit step does not stick a joint (no stiction), its
#: velocity chatters about zero by about ``mu dt / inertia`` per step while the friction
#: averages out, so far beyond the limit only that chatter leaving the hold band ends an
#: episode, which measures the integrator, not the controller.
CALIBRATION_SEARCH: dict[str, tuple[float, float]] = {
    "observation_noise": (0.01, 100.0),
    "action_delay": (1.0, 100.0),
    "actuator_gain": (0.05, 1.0),
    "torque_noise": (0.01, 100.0),
    "viscous_friction": (0.001, 1000.0),
    "coulomb_friction": (0.001, 2.0),
    "parameter_error": (0.05, 0.95),
    "push": (0.01, 1000.0),
}
#: Bisection steps after the bracket is found: the level to 1/64 of the bracket.
CALIBRATION_BISECTIONS = 6
#: Operating-region episodes of the calibration.
CALIBRATION_EPISODES = 10
TORQUE_CATEGORIES = ("torque_noise", "coulomb_friction")  # searched in actuator limits


class FailureLevel(NamedTuple):
    """Where a controller stops holding: the smallest ``level`` found at which it holds none
    of the calibration's operating-region episodes (``found``), else the search's end."""

    level: float
    found: bool


def _fails(system, controller, starts, category, level, constant, seed) -> bool:
    """Whether ``controller`` holds none of ``starts`` at ``level`` of ``category``; for
    ``push``, whether it fails from the operating point pushed by ``+level`` or ``-level``
    (a push at a random time is seldom the first thing an episode meets, so holding none of
    the pushed episodes is a matter of chance: the deterministic question is the push it
    cannot recover from)."""
    if category == "push":
        index = system.state_names.index(_pushed(system))
        pushed = np.tile(system.operating_state, (2, 1))
        pushed[:, index] += (level, -level)
        return not all(_held(system, controller, pushed, Setting(level, None, ())))
    repeat = control_period(controller)
    perturbations = category_perturbations(system, category, level, seed, repeat, constant)
    return not any(_held(system, controller, starts, Setting(level, constant, perturbations)))


def _search(fails: Callable[[float], bool], first: float, last: float, whole: bool) -> FailureLevel:
    """The smallest failing level in ``(0, last]``: doubling from ``first``, then bisection
    (whole numbers: a scan)."""
    if whole:
        step = next((s for s in range(int(first), int(last) + 1) if fails(float(s))), None)
        return FailureLevel(float(last if step is None else step), step is not None)
    level, below = first, 0.0
    while not fails(level):
        if level >= last:
            return FailureLevel(last, False)
        level, below = min(2.0 * level, last), level
    for _ in range(CALIBRATION_BISECTIONS):
        middle = 0.5 * (below + level)
        below, level = (below, middle) if fails(middle) else (middle, level)
    return FailureLevel(level, True)


def _pushed(system: System) -> str:
    """The state entry a :class:`~leoc.systems.perturbations.Push` without a joint pushes."""
    return f"{system.state_names[system.main_index]}_dot"


def failure_level(
    system: System,
    controller: Controller,
    category: str,
    episodes: int = CALIBRATION_EPISODES,
    seed: int = 0,
) -> FailureLevel:
    """The level of ``category`` at which ``controller`` holds none of ``episodes``
    operating-region starts (seeded with ``seed``), searched by doubling and bisection up to
    :data:`CALIBRATION_SEARCH`'s end; for the two-sided categories the smaller deviation of
    the two sides, for ``parameter_error`` over the constants of :func:`max_levels_for` the
    system (mass and gravity for a system without an entry)."""
    first, last = CALIBRATION_SEARCH[_category(category)]
    if category in TORQUE_CATEGORIES:
        first, last = first * system.action_limit, last * system.action_limit
    starts = protocol_starts(system, episodes, seed)["operating_region"]
    noise_seed = _derived_seed(seed, CATEGORY_NAMES.index(category) + 1)
    constants: tuple[str | None, ...] = (None,)
    if category == "parameter_error":
        table = DEFAULT_MAX_LEVELS.get(system.name)
        constants = table.constants if table else MaxLevels.constants
    signs = (-1.0, 1.0) if category in TWO_SIDED_CATEGORIES else (1.0,)
    found = [
        _search(
            lambda level, s=sign, c=constant: _fails(
                system, controller, starts, category, s * level, c, noise_seed
            ),
            first,
            last,
            category == "action_delay",
        )
        for constant in constants
        for sign in signs
    ]
    failing = [entry.level for entry in found if entry.found]
    return FailureLevel(min(failing), True) if failing else FailureLevel(last, False)


#: Significant digits of a measured maximum level (rounded up, so it still fails).
MAX_LEVEL_DIGITS = 2


def _round_up(value: float, digits: int = MAX_LEVEL_DIGITS) -> float:
    """``value`` rounded up to ``digits`` significant digits."""
    scale = 10.0 ** (digits - 1 - int(np.floor(np.log10(value))))
    return float(np.ceil(value * scale - 1e-9) / scale)


def measured_max_levels(
    system: System,
    controller: Controller,
    episodes: int = CALIBRATION_EPISODES,
    seed: int = 0,
    progress: Callable[[str, FailureLevel], None] | None = None,
) -> tuple[MaxLevels, dict[str, FailureLevel]]:
    """The :class:`MaxLevels` of ``system`` from ``controller``'s :func:`failure_level` in
    every category, rounded up to :data:`MAX_LEVEL_DIGITS` significant digits (the two-sided
    ones capped at their limits), and the failure levels themselves; how the built-in table
    was made (with the LQR), and the maximum levels of a system without an entry."""
    found = {}
    for category in CATEGORY_NAMES:
        found[category] = failure_level(system, controller, category, episodes, seed)
        if progress is not None:
            progress(category, found[category])
    levels = {name: _round_up(entry.level) for name, entry in found.items()}
    levels["action_delay"] = int(found["action_delay"].level)
    levels["actuator_gain"] = min(levels["actuator_gain"], 1.0)
    levels["parameter_error"] = min(
        levels["parameter_error"], CALIBRATION_SEARCH["parameter_error"][1]
    )
    table = DEFAULT_MAX_LEVELS.get(system.name)
    constants = table.constants if table else MaxLevels.constants
    return MaxLevels(**levels, constants=constants), found
