r"""Empirical basins of any controller, and starts that can tell a hybrid from its LQR.

Letters: N starts, S state dimension.

**Empirical basin.** Any controller (the LQR, a trained run's controller, any torch module
mapping observations to actions) is simulated from a seeded sample or a grid of starts in a
stated box around :math:`a`, all starts in one batched :func:`leoc.systems.rollout.simulate`
at the controller's own control period; a start belongs to the basin when the episode
converges and holds (``System.hold_step``: not terminated, inside the hold band for at least
``hold_min_steps`` final steps). The certified set it is compared with is
:mod:`leoc.control.roa`'s.

**Shells.** With :math:`V(x) = z^\top P z` of the LQR design and its proved level
:math:`\rho`, starts are drawn uniformly in the ellipsoidal shells
:math:`\{\rho_k \le V < \rho_{k+1}\}` for the edges ``SHELL_EDGES`` (in units of
:math:`\rho`): from the ROA hybrids' flat top :math:`\rho_{in}` out to :math:`3\rho`, past
the proved set towards the LQR's empirical basin edge. In :math:`w = L^\top z` a shell is a
spherical one, sampled by a uniform direction and a radius with :math:`r^S` uniform between
its ends. Robustness starts in the operating-region box lie deep inside the flat top (V at most
a few percent of :math:`\rho` on the paper systems), where an ROA hybrid *is* its LQR; starts
in the outer shells make the learned part act.

**Basins relative to the LQR's.** On the same seeded starts:

* share of the LQR's proved set held: the hybrid's basin on starts uniform in
  :math:`\{V \le \rho\}` (1 when it contains the set);
* share of the LQR's empirical basin held: among the box starts the LQR brings to the
  operating point and holds, the share the hybrid holds too;
* basin volume outside the LQR's: the box volume times the share of box starts the hybrid
  holds and the LQR does not (where the learned part adds reach), in the product of the state
  units.

Any of them compares two simulations started at the same states: the hybrid differs from its
LQR only where its relevance drops below 1 somewhere along the way, which is recorded per start
(``left_flat_top``): a start whose hybrid trajectory never leaves :math:`r = 1` is a comparison
*by construction*.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from leoc.control.roa import LyapunovCertificate, check_box
from leoc.systems.base import System
from leoc.systems.rollout import BatchTrajectory, Controller, simulate

__all__ = [
    "Basin",
    "BasinComparison",
    "ShellResult",
    "SHELL_EDGES",
    "basin_comparison",
    "basin_starts",
    "box_fraction",
    "certified_set_check",
    "default_basin_box",
    "empirical_basin",
    "shell_levels",
    "shell_robustness",
    "shell_starts",
    "slice_grid",
]

BASIN_BOX_FACTOR = 3.0
"""Default basin box: ``BASIN_BOX_FACTOR * System.operating_region`` half-widths around a."""
DEFAULT_BASIN_STARTS = 2_000
DEFAULT_SLICE_POINTS = 41
"""Grid points per axis of a basin slice (plots)."""
BOX_FRACTION_SAMPLES = 200_000

SHELL_EDGES = (1.0, 2.0, 3.0)
"""Outer shell edges in units of the proved rho (the first shell starts at the flat top)."""
SHELL_STARTS = 200
"""Starts per shell."""
FLAT_TOP = 1.0


class Basin(NamedTuple):
    """Empirical basin of one controller.

    Attributes
    ----------
    starts : (N, S) array
    held : (N,) bool array
        The episode converged and held the operating point (``System.hold_step``).
    terminated : (N,) bool array
        The episode left the allowed region.
    box : (S,) array or None
        Half-widths of the box the starts were drawn in.
    steps : int
    action_repeat : int
    """

    starts: np.ndarray
    held: np.ndarray
    terminated: np.ndarray
    box: np.ndarray | None
    steps: int
    action_repeat: int

    @property
    def count(self) -> int:
        """Number of starts brought to the operating point and held."""
        return int(self.held.sum())

    @property
    def fraction(self) -> float:
        """Share of the starts held (NaN when there are none)."""
        return float(self.held.mean()) if self.held.size else float("nan")


def _held(system: System, batch: BatchTrajectory) -> np.ndarray:
    """Which episodes (N,) of a batched rollout converge and hold (``System.hold_step``)."""
    return np.array(
        [
            system.hold_step(batch.states[i, 1:], terminated=bool(batch.terminated[i])) is not None
            for i in range(batch.states.shape[0])
        ],
        dtype=bool,
    )


def default_basin_box(system: System) -> np.ndarray:
    """``BASIN_BOX_FACTOR * system.operating_region`` half-widths (S,)."""
    return BASIN_BOX_FACTOR * np.asarray(system.operating_region, dtype=float)


def basin_starts(
    system: System,
    box: Sequence[float] | None = None,
    count: int = DEFAULT_BASIN_STARTS,
    seed: int = 0,
) -> np.ndarray:
    """``count`` seeded starts (count, S) uniform in ``a +/- box`` (default
    :func:`default_basin_box`)."""
    half = default_basin_box(system) if box is None else check_box(box, system, "box")
    rng = np.random.default_rng(seed)
    return system.operating_state + rng.uniform(-half, half, size=(count, system.state_dim))


def slice_grid(
    system: System,
    dims: tuple[int, int],
    box: Sequence[float] | None = None,
    points: int = DEFAULT_SLICE_POINTS,
) -> np.ndarray:
    """Starts (points**2, S) on a grid of the 2-D slice ``dims`` of ``a +/- box``, the other
    entries at the operating point; row-major with ``dims[0]`` the slow axis."""
    half = default_basin_box(system) if box is None else check_box(box, system, "box")
    first, second = dims
    axes = [np.linspace(-half[d], half[d], points) for d in dims]
    mesh_a, mesh_b = np.meshgrid(*axes, indexing="ij")
    starts = np.tile(system.operating_state, (points * points, 1))
    starts[:, first] += mesh_a.reshape(-1)
    starts[:, second] += mesh_b.reshape(-1)
    return starts


def empirical_basin(
    system: System,
    controller: Controller,
    starts: Any,
    steps: int | None = None,
    box: Sequence[float] | None = None,
) -> Basin:
    """Which starts a controller brings to the operating point and holds there.

    One batched :func:`~leoc.systems.rollout.simulate` over all ``starts`` (N, S) at the
    controller's own control period, then ``System.hold_step`` per episode.

    Parameters
    ----------
    system : System
    controller : callable
        Observation (N, O) float64 -> action (N, A): a torch module, a trained run's controller
        or a plain function; its ``action_repeat`` (default 1) is honoured.
    starts : (N, S) array
        E.g. :func:`basin_starts`, :func:`slice_grid` or ``certificate.sample``.
    steps : int, optional
        Episode length (default ``system.episode_steps``).
    box : (S,) array, optional
        Recorded with the result (the box the starts came from).
    """
    batch = simulate(system, controller, starts, steps)
    return Basin(
        np.asarray(starts, dtype=float).reshape(-1, system.state_dim),
        _held(system, batch),
        batch.terminated.copy(),
        None if box is None else np.asarray(box, dtype=float),
        int(batch.actions.shape[1]),
        int(batch.action_repeat),
    )


def certified_set_check(
    system: System,
    controller: Controller,
    certificate: LyapunovCertificate,
    count: int = DEFAULT_BASIN_STARTS,
    seed: int = 0,
    steps: int | None = None,
) -> Basin:
    """Empirical basin of ``controller`` over ``count`` starts uniform in the certified set:
    its ``fraction`` is 1 when the controller's basin contains the set (on these starts)."""
    rng = np.random.default_rng(seed)
    return empirical_basin(system, controller, certificate.sample(rng, count), steps)


def box_fraction(
    certificate: LyapunovCertificate,
    box: Sequence[float],
    samples: int = BOX_FRACTION_SAMPLES,
    seed: int = 0,
    centre: Any = None,
) -> tuple[float, float]:
    """Fraction of the box ``centre +/- box`` inside the certified set, by Monte Carlo.

    ``centre`` defaults to the certificate's own centre (its ``operating_state``); a
    controller's certificate centred on its offset equilibrium passes the operating point a,
    so every controller is measured on one box.

    Returns
    -------
    fraction, standard_error : float
    """
    half = np.asarray(box, dtype=float)
    rng = np.random.default_rng(seed)
    middle = certificate.operating_state if centre is None else np.asarray(centre, dtype=float)
    states = middle + rng.uniform(-half, half, size=(samples, half.size))
    inside = certificate.contains(states)
    fraction = float(inside.mean())
    return fraction, math.sqrt(fraction * (1.0 - fraction) / samples)


def shell_starts(
    P: np.ndarray,
    operating_state: np.ndarray,
    low: float,
    high: float,
    count: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """``count`` states (count, S) uniform in ``{low <= (x - a)^T P (x - a) < high}``."""
    if not 0.0 <= low < high < math.inf:
        raise ValueError(f"low, high: expected 0 <= low < high < inf, found {low!r}, {high!r}")
    size = P.shape[0]
    direction = rng.standard_normal((count, size))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    inner, outer = math.sqrt(low) ** size, math.sqrt(high) ** size
    radius = (inner + rng.uniform(size=(count, 1)) * (outer - inner)) ** (1.0 / size)
    factor = np.linalg.cholesky(P)
    return operating_state + np.linalg.solve(factor.T, (direction * radius).T).T


class _Outcome(NamedTuple):
    held: np.ndarray  # (N,) bool
    left_flat_top: np.ndarray | None  # (N,) bool, hybrids only


def _outcome(system: System, controller: Controller, starts: np.ndarray) -> _Outcome:
    batch = simulate(system, controller, starts)
    held = _held(system, batch)
    left = None if batch.relevance is None else (batch.relevance < FLAT_TOP).any(axis=1)
    return _Outcome(held, left)


class ShellResult(NamedTuple):
    """One shell of V, one controller.

    Attributes
    ----------
    low, high : float
        Levels of V bounding the shell.
    held : float
        Share of its starts held.
    lqr_held : float
        Share the LQR holds from the same starts.
    left_flat_top : float or None
        Share of starts whose trajectory leaves r = 1 (the comparison is evidence there, by
        construction elsewhere); None for non-hybrids.
    """

    low: float
    high: float
    held: float
    lqr_held: float
    left_flat_top: float | None


def shell_levels(rho: float, flat_top: float | None) -> list[float]:
    """Edges of the shells: the flat top ``rho_in`` (0 for a relevance without one), then
    ``SHELL_EDGES`` times ``rho``; a flat top reaching rho merges the first shell away."""
    if not 0.0 < rho < math.inf:
        raise ValueError(f"rho: expected a positive finite level, found {rho!r}")
    inner = 0.0 if flat_top is None else float(flat_top)
    if not 0.0 <= inner:
        raise ValueError(f"flat_top: expected a non-negative level, found {flat_top!r}")
    outer = [edge * rho for edge in SHELL_EDGES]
    return outer if inner >= outer[0] else [inner, *outer]


def shell_robustness(
    system: System,
    controller: Controller,
    lqr: Controller,
    P: np.ndarray,
    levels: Sequence[float],
    count: int = SHELL_STARTS,
    seed: int = 0,
) -> list[ShellResult]:
    """Held shares of ``controller`` and of its ``lqr`` from the same seeded starts in each
    shell ``levels[k] <= V < levels[k + 1]`` (e.g. :func:`shell_levels`)."""
    rng = np.random.default_rng(seed)
    results = []
    for low, high in zip(levels[:-1], levels[1:], strict=True):
        starts = shell_starts(P, system.operating_state, low, high, count, rng)
        ours, reference = _outcome(system, controller, starts), _outcome(system, lqr, starts)
        left = None if ours.left_flat_top is None else float(ours.left_flat_top.mean())
        results.append(
            ShellResult(low, high, float(ours.held.mean()), float(reference.held.mean()), left)
        )
    return results


class BasinComparison(NamedTuple):
    """A hybrid's basin against its LQR's (module docstring).

    Attributes
    ----------
    proved_set_held : float
        Share of starts uniform in the LQR's proved set that the hybrid holds.
    proved_set_left_flat_top : float or None
        Share of those starts whose hybrid trajectory leaves r = 1.
    lqr_basin_held : float
        Share of the LQR's empirical basin (box starts it holds) that the hybrid holds.
    lqr_basin_left_flat_top : float or None
        Share of those starts whose hybrid trajectory leaves r = 1.
    outside_share : float
        Share of the box starts held by the hybrid and not by the LQR.
    outside_volume : float
        ``outside_share`` times the box volume (product of the state units).
    box : list of float
        Half-widths of the box.
    starts : int
        Starts per sample (box and proved set each).
    """

    proved_set_held: float
    proved_set_left_flat_top: float | None
    lqr_basin_held: float
    lqr_basin_left_flat_top: float | None
    outside_share: float
    outside_volume: float
    box: list[float]
    starts: int


def _share(mask: np.ndarray, among: np.ndarray) -> float:
    return float(mask[among].mean()) if among.any() else float("nan")


def basin_comparison(
    system: System,
    controller: Controller,
    lqr: Controller,
    proved_starts: np.ndarray,
    box_starts: np.ndarray,
    box: Any,
) -> BasinComparison:
    """The hybrid ``controller`` against its ``lqr`` on starts uniform in the LQR's proved set
    and on starts uniform in the box ``a +/- box`` (module docstring)."""
    half = np.asarray(box, dtype=float)
    inside = _outcome(system, controller, proved_starts)
    ours, reference = _outcome(system, controller, box_starts), _outcome(system, lqr, box_starts)
    everywhere = np.ones(proved_starts.shape[0], dtype=bool)
    left_inside = None if inside.left_flat_top is None else _share(inside.left_flat_top, everywhere)
    left_basin = None if ours.left_flat_top is None else _share(ours.left_flat_top, reference.held)
    outside = float((ours.held & ~reference.held).mean())
    return BasinComparison(
        float(inside.held.mean()),
        left_inside,
        _share(ours.held, reference.held),
        left_basin,
        outside,
        outside * float(np.prod(2.0 * half)),
        half.tolist(),
        int(box_starts.shape[0]),
    )
