r"""Region of attraction: a Lyapunov-level certificate of the LQR, empirical basins of any policy.

Letters: B batch (samples, grid nodes or starts), S state dimension, O observation dimension,
A action dimension, T simulator steps.

**Certificate.** For an LQR design (:func:`leoc.control.design_lqr`) at control period
:math:`k` the Riccati solution :math:`P` gives the quadratic Lyapunov candidate

.. math::

    V(x) = z^\top P z, \qquad z = x - a \text{ with every angle entry wrapped to } [-\pi, \pi),

and the closed loop actually run is the *nonlinear, saturated, held* map

.. math::

    F(x) = f^{(k)}\big(x, \operatorname{sat}(G(o(x)))\big),

:math:`f^{(k)}` the simulator's step applied :math:`k` times with the action held
(``System.step_held``), :math:`o` the observation map, :math:`G(o) = W o + b` the linear
controller and sat the actuator clip inside the step (or the hybrid's own saturation, given as
the ``controller``). The certificate is the largest level :math:`\rho` (below a search bound) with

.. math::

    V(F(x)) < V(x) \quad \text{for all } x \text{ with } 0 < V(x) \le \rho,

no state of the set (nor its held steps) leaving the allowed region. Then
:math:`\Omega_\rho = \{V \le \rho\}` is positively invariant and every trajectory starting in it
converges to :math:`a` (discrete-time Lyapunov theorem: :math:`V` continuous, positive definite
and strictly decreasing on the compact :math:`\Omega_\rho \setminus \{a\}`; Khalil 2002,
Thm 4.1 and section 8.2 for the region of attraction estimate).

It is computed by sampling, after Najafi, Babuska and Lopes (2016): draw :math:`n` points
uniformly in the ellipsoid :math:`\Omega_\rho` (:math:`z = \sqrt\rho\, L^{-\top} u`,
:math:`P = L L^\top`, :math:`u` uniform in the unit ball), and if any violates the decrease,
lower :math:`\rho` to just below the smallest violating level and draw a *fresh* batch; stop at
the first batch without a violation. Because the final batch is drawn after :math:`\rho` is
fixed, it is an independent uniform sample of :math:`\Omega_\rho`: if the violating set had a
volume fraction :math:`\epsilon` or more, :math:`n` clean samples would occur with probability
at most :math:`(1 - \epsilon)^n \le e^{-\epsilon n}`. So with confidence :math:`1 - \delta`
the violating volume fraction is below :math:`\ln(1/\delta) / n`. Before sampling, the
linearisation is checked (Lyapunov's indirect method, Khalil Thm 4.7): if
:math:`A_{cl}^\top P A_{cl} - P` (:math:`A_{cl}` the autodiff Jacobian of :math:`F` at
:math:`a`) is not negative definite, :math:`V` increases arbitrarily close to :math:`a` and no
:math:`\rho > 0` exists: the certificate is :math:`\rho = 0`.

**Dense grid and Lipschitz margin (2-D states).** For a 2-D state every node of a regular grid
inside :math:`\Omega_\rho` is checked too (deterministically). With
:math:`\Delta(x) = V(F(x)) - V(x)` and a Lipschitz constant :math:`L` of :math:`\Delta`, every
point within the half cell diagonal :math:`h` of a node :math:`c` with
:math:`\Delta(c) + L h < 0` has :math:`\Delta < 0`: that part of the set is *proved*. :math:`L` is
estimated as a safety factor times the largest :math:`\|\nabla\Delta\|` at the nodes (autograd),
so the proof holds under that estimate; near :math:`a`, where :math:`\Delta = O(\|z\|^2)` and
the margin :math:`L h` dominates, a small core around :math:`a` stays unproved by the grid
(reported as ``core_level``) and rests on the sampling certificate and the linear check.

**Empirical basin.** Any controller (the LQR, a trained run's controller, any torch module
mapping observations to actions) is simulated from a seeded sample or a grid of starts in a
stated box around :math:`a`, all starts in one batched :func:`leoc.systems.rollout.simulate`
at the controller's own control period; a start belongs to the basin when the episode
converges and holds (``System.hold_step``: not terminated, inside the hold band for at least
``hold_min_steps`` final steps).

References
----------
A. Najafi, R. Babuska and G. A. D. Lopes, "A fast sampling method for estimating the domain of
attraction of nonlinear systems with hybrid controllers", Automatica, 2016.
H. K. Khalil, *Nonlinear Systems*, 3rd ed., Prentice Hall, 2002, sections 4.1, 4.3 and 8.2.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.systems.base import DTYPE, System, check_repeat, wrap_angle

__all__ = [
    "Basin",
    "GridProof",
    "LinearClosedLoop",
    "LyapunovCertificate",
    "basin_starts",
    "box_fraction",
    "certified_set_check",
    "certify_level",
    "certify_lqr",
    "default_basin_box",
    "empirical_basin",
    "lqr_closed_loop",
    "lyapunov_value",
    "plot_basins",
    "slice_grid",
    "state_deviation",
]

Controller = Callable[[Tensor], Tensor]

DEFAULT_SAMPLES = 100_000
"""Uniform samples per verification round (the final, clean round gives the confidence)."""
DEFAULT_CONFIDENCE = 0.999
"""Confidence 1 - delta of the violating-volume bound ln(1/delta) / n."""
MAX_ROUNDS = 200
"""Verification rounds before giving up (the certificate is then rho = 0)."""
MIN_RELATIVE_LEVEL = 1e-12
"""A level below this fraction of the initial level counts as no certificate (rho = 0)."""
SEARCH_BOX_FACTOR = 100.0
"""Default search box: ``SEARCH_BOX_FACTOR * System.operating_region``; the initial level is the
largest whose ellipsoid fits in it (and inside the angle chart)."""
BASIN_BOX_FACTOR = 3.0
"""Default basin box: ``BASIN_BOX_FACTOR * System.operating_region`` half-widths around a."""
DEFAULT_BASIN_STARTS = 2_000
DEFAULT_SLICE_POINTS = 41
"""Grid points per axis of a basin slice (plots)."""
GRID_POINTS_2D = 601
"""Grid points per axis of the dense grid check for 2-D states (over the set's bounding box)."""
LIPSCHITZ_SAFETY = 2.0
"""Factor on the largest sampled gradient norm of Delta used as its Lipschitz constant."""
BOX_FRACTION_SAMPLES = 200_000
SYMMETRY_RTOL = 1e-9
"""Allowed asymmetry of P, relative to its largest entry."""
LINEAR_DECREASE_TOL = 0.0
"""The linear check needs max eig(A_cl^T P A_cl - P) < this (strictly negative definite)."""


class GridProof(NamedTuple):
    """Dense-grid check of a 2-D certificate (see the module docstring).

    Attributes
    ----------
    points_per_axis : int
    spacing : (2,) array
        Grid steps per state entry.
    nodes : int
        Nodes inside the covering set (the certified set grown by half a cell diagonal).
    lipschitz : float
        Largest local Lipschitz constant used for Delta (``LIPSCHITZ_SAFETY`` times the largest
        gradient norm over a node's 3x3 neighbourhood: an estimate, not a bound).
    unproved_nodes : int
        Covering nodes where ``Delta(c) + L_c h >= 0``.
    core_level, proved_level : float
        The grid proves the decrease on ``core_level < V < proved_level`` given the Lipschitz
        estimate (the largest such annulus; ``(0, rho)`` when every node passes). Near a the
        margin ``L_c h`` outweighs ``|Delta| = O(|z|^2)``; near the certified boundary Delta
        tends to 0 (that is where rho was cut), so the annulus is narrower than the set.
    """

    points_per_axis: int
    spacing: np.ndarray
    nodes: int
    lipschitz: float
    unproved_nodes: int
    core_level: float
    proved_level: float


class LyapunovCertificate(NamedTuple):
    """A certified sublevel set ``{x : V(x) <= rho}`` of ``V = z^T P z`` (module docstring).

    Attributes
    ----------
    rho : float
        Certified level (0: no certificate).
    P : (S, S) array
    operating_state : (S,) array
    angle_indices : tuple of int
        State entries wrapped in the deviation z.
    action_repeat : int
        Control period of the certified closed loop (simulator steps per decision).
    samples : int
        Uniform samples of the final (clean) round; the confidence statement rests on them.
    rounds : int
        Verification rounds drawn (each a fresh batch of ``samples``).
    confidence : float
        1 - delta.
    violation_bound : float
        With probability ``confidence`` the volume fraction of the set violating the decrease
        is below this (``ln(1/delta) / samples``); nan without a certificate.
    initial_rho : float
        Level the search started from (the search bound).
    capped : bool
        True if ``rho == initial_rho``: no violation was found and the set is limited by the
        search bound, not by the dynamics.
    linear_decrease : bool
        Whether ``A_cl^T P A_cl - P`` is negative definite at a.
    linear_decrease_eig : float
        Its largest eigenvalue.
    grid : GridProof or None
        The dense grid check (2-D states only).
    """

    rho: float
    P: np.ndarray
    operating_state: np.ndarray
    angle_indices: tuple[int, ...]
    action_repeat: int
    samples: int
    rounds: int
    confidence: float
    violation_bound: float
    initial_rho: float
    capped: bool
    linear_decrease: bool
    linear_decrease_eig: float
    grid: GridProof | None = None

    @property
    def certified(self) -> bool:
        """Whether a non-empty set was certified (``rho > 0``)."""
        return self.rho > 0.0

    @property
    def extent(self) -> np.ndarray:
        """Half-widths (S,) of the set along each state entry: ``sqrt(rho (P^-1)_ii)``."""
        return np.sqrt(self.rho * np.diag(np.linalg.inv(self.P)))

    def value(self, states: Any) -> np.ndarray:
        """V (B,) of states (B, S) (angles wrapped)."""
        states_t = torch.as_tensor(np.asarray(states, dtype=float), dtype=DTYPE).reshape(
            -1, self.P.shape[0]
        )
        deviation = _deviation(states_t, self.operating_state, self.angle_indices)
        return lyapunov_value(torch.as_tensor(self.P, dtype=DTYPE), deviation).numpy()

    def contains(self, states: Any) -> np.ndarray:
        """Boolean (B,): the states lie in the certified set ``V <= rho``."""
        return self.value(states) <= self.rho

    def sample(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` states (count, S) uniform in the certified set."""
        deviation = _uniform_ellipsoid(self.P, self.rho, count, rng)
        return self.operating_state + deviation

    def summary(self) -> dict[str, Any]:
        """JSON-friendly description."""
        grid = None
        if self.grid is not None:
            grid = {**self.grid._asdict(), "spacing": self.grid.spacing.tolist()}
        return {
            "rho": self.rho,
            "P": self.P.tolist(),
            "operating_state": self.operating_state.tolist(),
            "extent": self.extent.tolist(),
            "action_repeat": self.action_repeat,
            "samples": self.samples,
            "rounds": self.rounds,
            "confidence": self.confidence,
            "violation_bound": self.violation_bound,
            "initial_rho": self.initial_rho,
            "capped": self.capped,
            "linear_decrease": self.linear_decrease,
            "linear_decrease_eig": self.linear_decrease_eig,
            "grid": grid,
        }


def _deviation(states: Tensor, operating_state: np.ndarray, angles: Sequence[int]) -> Tensor:
    deviation = states - torch.as_tensor(operating_state, dtype=states.dtype)
    if angles:
        columns = list(deviation.unbind(-1))
        for index in angles:
            columns[index] = wrap_angle(columns[index])
        deviation = torch.stack(columns, dim=-1)
    return deviation


def state_deviation(system: System, states: Tensor) -> Tensor:
    """``z = x - a`` (B, S) of states (B, S), every angle entry wrapped to [-pi, pi)."""
    return _deviation(states, system.operating_state, system.angle_indices)


def lyapunov_value(P: Tensor, deviation: Tensor) -> Tensor:
    """``V = z^T P z`` (B,) of deviations z (B, S)."""
    return ((deviation @ P) * deviation).sum(dim=-1)


def _uniform_ellipsoid(
    P: np.ndarray, rho: float, count: int, rng: np.random.Generator
) -> np.ndarray:
    """``count`` points (count, S) uniform in ``{z : z^T P z <= rho}``: ``z = sqrt(rho) L^-T u``
    with ``P = L L^T`` and u uniform in the unit ball (Gaussian direction, radius U^(1/S))."""
    size = P.shape[0]
    direction = rng.standard_normal((count, size))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = rng.uniform(size=(count, 1)) ** (1.0 / size)
    unit_ball = direction * radius
    cholesky = np.linalg.cholesky(P)
    return math.sqrt(rho) * np.linalg.solve(cholesky.T, unit_ball.T).T


def _check_matrix(P: Any, size: int) -> np.ndarray:
    matrix = np.asarray(P, dtype=float)
    if matrix.shape != (size, size) or not np.all(np.isfinite(matrix)):
        raise ValueError(f"P: expected finite numbers of shape ({size}, {size}), found {matrix!r}")
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=SYMMETRY_RTOL * np.abs(matrix).max()):
        raise ValueError(f"P: expected a symmetric matrix, found {matrix.tolist()}")
    smallest = float(np.linalg.eigvalsh(matrix)[0])
    if smallest <= 0.0:
        raise ValueError(f"P: expected positive definite, found smallest eigenvalue {smallest:.3g}")
    return matrix


def _closed_loop(system: System, controller: Controller, repeat: int, states: Tensor):
    """Held closed-loop map: (next states (B, S), left the allowed region on any held step)."""
    action = torch.as_tensor(controller(system.observe(states)), dtype=DTYPE)
    action = action.reshape(states.shape[0], system.action_dim)
    left = system.out_of_bounds(states)
    for _ in range(repeat):
        states = system.step_fn(states, action)
        left = left | system.out_of_bounds(states)
    return states, left


def _decrease(
    system: System, P: Tensor, controller: Controller, repeat: int, states: Tensor
) -> tuple[Tensor, Tensor]:
    """``(V(x), violates)`` (B,) each: violation = no strict decrease, a non-finite value, or
    leaving the allowed region."""
    with torch.no_grad():
        following, left = _closed_loop(system, controller, repeat, states)
        value = lyapunov_value(P, state_deviation(system, states))
        value_next = lyapunov_value(P, state_deviation(system, following))
    # The condition is on 0 < V <= rho: the operating point itself (V = 0) is a fixed point.
    violates = (value > 0.0) & (left | ~torch.isfinite(value_next) | ~(value_next < value))
    return value, violates


def _linear_check(
    system: System, P: np.ndarray, controller: Controller, repeat: int
) -> tuple[bool, float]:
    """Largest eigenvalue of ``A_cl^T P A_cl - P``, A_cl the autodiff Jacobian of the held
    closed loop at a; negative definite -> True."""

    def closed(x: Tensor) -> Tensor:
        return _closed_loop(system, controller, repeat, x.unsqueeze(0))[0][0]

    point = torch.as_tensor(system.operating_state, dtype=DTYPE)
    jacobian = torch.autograd.functional.jacobian(closed, point).numpy()
    change = jacobian.T @ P @ jacobian - P
    largest = float(np.max(np.linalg.eigvalsh(0.5 * (change + change.T))))
    return largest < LINEAR_DECREASE_TOL, largest


def _initial_level(
    system: System, P: np.ndarray, search_box: Sequence[float] | None, rho_max: float | None
) -> float:
    """Largest level whose ellipsoid fits in the search box and in the angle chart
    (angular extent at most pi), capped at ``rho_max``."""
    diagonal = np.diag(np.linalg.inv(P))
    box = (
        SEARCH_BOX_FACTOR * np.asarray(system.operating_region, dtype=float)
        if search_box is None
        else _check_box(search_box, system, "search_box")
    )
    level = float(np.min(box**2 / diagonal))
    for index in system.angle_indices:
        level = min(level, math.pi**2 / float(diagonal[index]))
    if rho_max is not None:
        if not 0.0 < rho_max < math.inf:
            raise ValueError(f"rho_max: expected a positive finite number, found {rho_max!r}")
        level = min(level, float(rho_max))
    return level


def _check_box(box: Any, system: System, name: str) -> np.ndarray:
    values = np.asarray(box, dtype=float).reshape(-1)
    if values.shape != (system.state_dim,) or not np.all(np.isfinite(values) & (values > 0)):
        raise ValueError(
            f"{name}: expected {system.state_dim} positive half-widths "
            f"({', '.join(system.state_names)}), found {box!r}"
        )
    return values


def _grid_axes(P: np.ndarray, level: float, points: int) -> list[np.ndarray]:
    """Axes of a regular grid over the bounding box of ``{z^T P z <= level}``."""
    extent = np.sqrt(level * np.diag(np.linalg.inv(P)))
    return [np.linspace(-width, width, points) for width in extent]


def _grid_nodes(P: np.ndarray, level: float, points: int) -> np.ndarray:
    """Nodes (B, 2) of the grid of :func:`_grid_axes` that lie in ``{z^T P z <= level}``."""
    mesh = np.stack(np.meshgrid(*_grid_axes(P, level, points), indexing="ij"), axis=-1)
    mesh = mesh.reshape(-1, 2)
    return mesh[np.einsum("bi,ij,bj->b", mesh, P, mesh) <= level]


def _neighbourhood_max(values: np.ndarray) -> np.ndarray:
    """Largest value over each node's 3x3 neighbourhood (edges padded with themselves)."""
    padded = np.pad(values, 1, mode="edge")
    rows, cols = values.shape
    shifted = [padded[i : i + rows, j : j + cols] for i in range(3) for j in range(3)]
    return np.max(np.stack(shifted), axis=0)


def _largest_gap(lower: np.ndarray, upper: np.ndarray, top: float) -> tuple[float, float]:
    """Largest interval of [0, top] that meets none of the intervals [lower_i, upper_i]."""
    best = (0.0, 0.0)
    reached = 0.0
    for low, high in sorted(zip(lower.tolist(), upper.tolist(), strict=True)):
        if low > reached and min(low, top) - reached > best[1] - best[0]:
            best = (reached, min(low, top))
        reached = max(reached, high)
        if reached >= top:
            break
    if reached < top and top - reached > best[1] - best[0]:
        best = (reached, top)
    return best


def _grid_proof(
    system: System, P: np.ndarray, controller: Controller, repeat: int, rho: float, points: int
) -> GridProof:
    """Dense-grid Lipschitz margin of a 2-D certificate (see the module docstring).

    Every point of the set lies within the half cell diagonal h of a node; the set is grown by
    ``sqrt(lambda_max(P)) h`` in ``sqrt(V)`` (a norm with that Lipschitz constant) so those
    nodes are all checked. A node c passes when ``Delta(c) + L_c h < 0``, ``L_c`` the safety
    factor times the largest gradient norm of Delta over c's 3x3 neighbourhood. A failing node
    leaves unproved at most its cell, whose levels lie in
    ``[(sqrt V(c) - s h)^2, (sqrt V(c) + s h)^2]``, s = sqrt(lambda_max(P)); the proved annulus
    is the largest level interval that none of these meets.
    """
    P_t = torch.as_tensor(P, dtype=DTYPE)
    scale = math.sqrt(float(np.linalg.eigvalsh(P)[-1]))
    axes = _grid_axes(P, rho, points)
    spacing = np.array([axis[1] - axis[0] for axis in axes])
    half_diagonal = 0.5 * float(np.linalg.norm(spacing))
    grown = (math.sqrt(rho) + scale * half_diagonal) ** 2
    axes = _grid_axes(P, grown, points + 2 * int(math.ceil(points * (math.sqrt(grown / rho) - 1))))
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    spacing = np.array([axis[1] - axis[0] for axis in axes])
    half_diagonal = 0.5 * float(np.linalg.norm(spacing))
    deviation = torch.as_tensor(mesh.reshape(-1, 2), dtype=DTYPE).requires_grad_(True)
    states = deviation + torch.as_tensor(system.operating_state, dtype=DTYPE)
    following, _ = _closed_loop(system, controller, repeat, states)
    change = lyapunov_value(P_t, state_deviation(system, following)) - lyapunov_value(
        P_t, deviation
    )
    (gradient,) = torch.autograd.grad(change.sum(), deviation)
    norms = gradient.norm(dim=-1).numpy().reshape(mesh.shape[:2])
    lipschitz = LIPSCHITZ_SAFETY * _neighbourhood_max(norms).reshape(-1)
    values = np.einsum("bi,ij,bj->b", mesh.reshape(-1, 2), P, mesh.reshape(-1, 2))
    covering = values <= (math.sqrt(rho) + scale * half_diagonal) ** 2
    failing = covering & (change.detach().numpy() + lipschitz * half_diagonal >= 0.0)
    root = np.sqrt(values[failing])
    lower = np.maximum(root - scale * half_diagonal, 0.0) ** 2
    upper = (root + scale * half_diagonal) ** 2
    core, proved = _largest_gap(lower, upper, rho)
    return GridProof(
        int(mesh.shape[0]),
        spacing,
        int(covering.sum()),
        float(lipschitz[covering].max()),
        int(failing.sum()),
        core,
        proved,
    )


def certify_level(
    system: System,
    P: Any,
    controller: Controller,
    action_repeat: int | None = None,
    samples: int = DEFAULT_SAMPLES,
    confidence: float = DEFAULT_CONFIDENCE,
    seed: int = 0,
    search_box: Sequence[float] | None = None,
    rho_max: float | None = None,
    grid_points: int | None = GRID_POINTS_2D,
    linear_check: bool = True,
) -> LyapunovCertificate:
    r"""Largest level :math:`\rho` with :math:`V(F(x)) < V(x)` on :math:`0 < V \le \rho`.

    Parameters
    ----------
    system : System
    P : (S, S) array
        Symmetric positive definite matrix of :math:`V(x) = z^\top P z`.
    controller : callable
        Observation (B, O) float64 -> action (B, A): the closed loop certified (e.g.
        :math:`G(o) = W o + b`; the step clips it to the actuator limit).
    action_repeat : int, optional
        Control period of the closed loop; default the controller's ``action_repeat`` or 1.
    samples : int
        Uniform samples per round; the final clean round's count sets the confidence.
    confidence : float in (0, 1)
        :math:`1 - \delta` of the violating-volume bound :math:`\ln(1/\delta)/n`.
    seed : int
        Seed of every sample drawn.
    search_box : (S,) half-widths, optional
        The search starts at the largest level whose ellipsoid fits in this box (default
        ``SEARCH_BOX_FACTOR * system.operating_region``) and in the angle chart.
    rho_max : float, optional
        Further cap on the initial level.
    grid_points : int or None
        Points per axis of the dense grid check for 2-D states (None: no grid).
    linear_check : bool
        Check the linearised decrease first (rho = 0 if it fails). Off only to test the
        sampling on its own.

    Returns
    -------
    LyapunovCertificate
    """
    repeat = check_repeat(
        getattr(controller, "action_repeat", 1) if action_repeat is None else action_repeat
    )
    matrix = _check_matrix(P, system.state_dim)
    for name, value in (("samples", samples), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"{name}: expected a non-negative integer, found {value!r}")
    if samples < 1:
        raise ValueError(f"samples: expected a positive integer, found {samples!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence: expected a number in (0, 1), found {confidence!r}")
    use_grid = grid_points is not None and system.state_dim == 2
    if use_grid and (isinstance(grid_points, bool) or int(grid_points) < 2):
        raise ValueError(f"grid_points: expected an integer >= 2 or None, found {grid_points!r}")
    rng = np.random.default_rng(seed)
    P_t = torch.as_tensor(matrix, dtype=DTYPE)
    operating = torch.as_tensor(system.operating_state, dtype=DTYPE)
    initial = _initial_level(system, matrix, search_box, rho_max)
    linear_ok, linear_eig = _linear_check(system, matrix, controller, repeat)
    delta = 1.0 - confidence

    def result(rho: float, rounds: int, grid: GridProof | None = None) -> LyapunovCertificate:
        bound = math.log(1.0 / delta) / samples if rho > 0.0 else float("nan")
        return LyapunovCertificate(
            rho,
            matrix,
            system.operating_state.copy(),
            tuple(system.angle_indices),
            repeat,
            samples,
            rounds,
            confidence,
            bound,
            initial,
            rho == initial,
            linear_ok,
            linear_eig,
            grid,
        )

    if linear_check and not linear_ok:
        return result(0.0, 0)
    rho = initial
    for rounds in range(1, MAX_ROUNDS + 1):
        deviation = _uniform_ellipsoid(matrix, rho, samples, rng)
        if use_grid:
            nodes = _grid_nodes(matrix, rho, int(grid_points))  # type: ignore[arg-type]
            deviation = np.concatenate([deviation, nodes])
        states = torch.as_tensor(deviation, dtype=DTYPE) + operating
        value, violates = _decrease(system, P_t, controller, repeat, states)
        if not bool(violates.any()):
            grid = None
            if use_grid:
                grid = _grid_proof(system, matrix, controller, repeat, rho, int(grid_points))  # type: ignore[arg-type]
            return result(rho, rounds, grid)
        smallest = float(value[violates].min())
        rho = float(np.nextafter(smallest, 0.0))
        if rho <= MIN_RELATIVE_LEVEL * initial:
            return result(0.0, rounds)
    return result(0.0, MAX_ROUNDS)


class LinearClosedLoop:
    """``G(o) = W o + b`` of an :class:`~leoc.control.LQRDesign`, float64, with the design's
    ``action_repeat`` (the actuator clip is inside the step). Observation (B, O) -> (B, A)."""

    is_hybrid = False

    def __init__(self, design: Any) -> None:
        self.W = torch.as_tensor(design.W, dtype=DTYPE)
        self.b = torch.as_tensor(design.b, dtype=DTYPE)
        self.action_repeat = check_repeat(design.action_repeat)

    def __call__(self, obs: Tensor) -> Tensor:
        return obs @ self.W.T + self.b


def lqr_closed_loop(design: Any) -> LinearClosedLoop:
    """The LQR of ``design`` as a controller at the design's control period."""
    return LinearClosedLoop(design)


def certify_lqr(
    system: System, design: Any, controller: Controller | None = None, **options: Any
) -> LyapunovCertificate:
    """Certificate of an LQR design's region of attraction (:func:`certify_level` with the
    design's ``P`` and control period).

    Parameters
    ----------
    system : System
    design : LQRDesign
    controller : callable, optional
        The saturated linear closed loop to certify; default ``G(o) = W o + b`` clipped by the
        actuator (a hybrid with another saturation, e.g. PILCO's sine, passes ``sat(G)``).
    **options
        :func:`certify_level`'s keywords (``samples``, ``confidence``, ``seed``, ...).
    """
    controller = lqr_closed_loop(design) if controller is None else controller
    return certify_level(
        system, design.P, controller, action_repeat=design.action_repeat, **options
    )


def box_fraction(
    certificate: LyapunovCertificate,
    box: Sequence[float],
    samples: int = BOX_FRACTION_SAMPLES,
    seed: int = 0,
) -> tuple[float, float]:
    """Fraction of the box ``a +/- box`` inside the certified set, by Monte Carlo.

    Returns
    -------
    fraction, standard_error : float
    """
    half = np.asarray(box, dtype=float)
    rng = np.random.default_rng(seed)
    states = certificate.operating_state + rng.uniform(-half, half, size=(samples, half.size))
    inside = certificate.contains(states)
    fraction = float(inside.mean())
    return fraction, math.sqrt(fraction * (1.0 - fraction) / samples)


class Basin(NamedTuple):
    """Empirical basin of one controller.

    Attributes
    ----------
    starts : (B, S) array
    held : (B,) bool array
        The episode converged and held the operating point (``System.hold_step``).
    terminated : (B,) bool array
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
    half = default_basin_box(system) if box is None else _check_box(box, system, "box")
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
    half = default_basin_box(system) if box is None else _check_box(box, system, "box")
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

    One batched :func:`~leoc.systems.rollout.simulate` over all ``starts`` (B, S) at the
    controller's own control period, then ``System.hold_step`` per episode.

    Parameters
    ----------
    system : System
    controller : callable
        Observation (B, O) float64 -> action (B, A): a torch module, a trained run's controller
        or a plain function; its ``action_repeat`` (default 1) is honoured.
    starts : (B, S) array
        E.g. :func:`basin_starts`, :func:`slice_grid` or ``certificate.sample``.
    steps : int, optional
        Episode length (default ``system.episode_steps``).
    box : (S,) array, optional
        Recorded with the result (the box the starts came from).
    """
    from leoc.systems.rollout import simulate

    batch = simulate(system, controller, starts, steps)
    held = np.array(
        [
            system.hold_step(batch.states[index, 1:], terminated=bool(batch.terminated[index]))
            is not None
            for index in range(batch.states.shape[0])
        ],
        dtype=bool,
    )
    return Basin(
        np.asarray(starts, dtype=float).reshape(-1, system.state_dim),
        held,
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


def _ellipse_boundary(P: np.ndarray, rho: float, dims: tuple[int, int], points: int) -> np.ndarray:
    """Boundary (points, 2) of the slice ``{z : z^T P z <= rho, z_k = 0 for k not in dims}``."""
    sub = P[np.ix_(dims, dims)]
    angles = np.linspace(0.0, 2.0 * math.pi, points)
    circle = np.stack([np.cos(angles), np.sin(angles)])
    return (math.sqrt(rho) * np.linalg.solve(np.linalg.cholesky(sub).T, circle)).T


ELLIPSE_POINTS = 400


def plot_basins(
    system: System,
    certificate: LyapunovCertificate,
    basins: Mapping[str, Basin],
    dims: tuple[int, int],
    points: int,
    path: str | Path,
) -> Path:
    """One panel per controller: the basin on a slice grid (:func:`slice_grid` with the same
    ``dims`` and ``points``) and the certified ellipse's slice over it. Returns the PNG path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    from leoc.io import save_figure_atomic

    count = len(basins)
    fig, axes = plt.subplots(1, count, figsize=(4.2 * count, 4.0), squeeze=False)
    boundary = _ellipse_boundary(certificate.P, certificate.rho, dims, ELLIPSE_POINTS)
    first, second = dims
    colours = ListedColormap(["#d9d9d9", "#74c476"])
    for axis, (label, basin) in zip(axes[0], basins.items(), strict=True):
        if basin.starts.shape[0] != points * points:
            raise ValueError(
                f"basins[{label!r}]: expected {points}x{points} slice starts, found "
                f"{basin.starts.shape[0]}"
            )
        grid_a = basin.starts[:, first].reshape(points, points)
        grid_b = basin.starts[:, second].reshape(points, points)
        held = basin.held.reshape(points, points).astype(float)
        axis.pcolormesh(grid_a, grid_b, held, cmap=colours, vmin=0.0, vmax=1.0, shading="nearest")
        centre = certificate.operating_state
        axis.plot(centre[first] + boundary[:, 0], centre[second] + boundary[:, 1], "k-", lw=1.5)
        axis.set_title(f"{label}: {basin.fraction:.0%} held")
        axis.set_xlabel(system.state_names[first])
        axis.set_ylabel(system.state_names[second])
    fig.suptitle(
        f"{system.name}: basins (green: converged and held) and certified set "
        f"V <= {certificate.rho:.4g} (black)"
    )
    fig.tight_layout()
    return save_figure_atomic(fig, Path(path))
