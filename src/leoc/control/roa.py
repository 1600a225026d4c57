r"""Region of attraction: a Lyapunov-level certificate of the LQR.

Letters: B batch (samples), S state dimension, O observation dimension,
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

**Proof (the reported rho).** :func:`leoc.control.proof.prove_level` proves the decrease
rigorously: a ball around :math:`a` by the linearisation with an interval enclosure of the
Jacobian (its remainder bounded, not neglected), and the rest of the set by adaptively bisected
boxes on which interval arithmetic over the analytic step bounds :math:`V(F(x)) - V(x)` from
above; boxes possibly leaving the allowed region (track limits) fail, so the proved set lies
inside it. ``LyapunovCertificate.rho`` is that proved level.

**Sampled estimate (a second figure).** The proof aims at the level found by sampling, after
Najafi, Babuska and Lopes (2016): draw :math:`n` points uniformly in the ellipsoid
:math:`\Omega_\rho` (:math:`z = \sqrt\rho\, L^{-\top} u`, :math:`P = L L^\top`, :math:`u`
uniform in the unit ball), and if any violates the decrease, lower :math:`\rho` to just below
the smallest violating level and draw a *fresh* batch; stop at the first batch without a
violation. Because the final batch is drawn after :math:`\rho` is fixed, it is an independent
uniform sample of :math:`\Omega_\rho`: with confidence :math:`1 - \delta` the violating volume
fraction is below :math:`\ln(1/\delta) / n`. That is a statistical statement, not a proof (a
thin shell near the boundary can violate it unseen); it is kept as ``sampled_rho``. Before
sampling, the linearisation is checked (Lyapunov's indirect method, Khalil Thm 4.7): if
:math:`A_{cl}^\top P A_{cl} - P` (:math:`A_{cl}` the autodiff Jacobian of :math:`F` at
:math:`a`) is not negative definite, :math:`V` increases arbitrarily close to :math:`a` and no
:math:`\rho > 0` exists: the certificate is :math:`\rho = 0`.

**Empirical basins** of any controller (where it actually converges and holds), the
certified set's share of a box and the basin figures are evaluations of a controller:
:mod:`leoc.evaluation.basins` and ``leoc.evaluation.plots.basins``.

References
----------
A. Najafi, R. Babuska and G. A. D. Lopes, "A fast sampling method for estimating the domain of
attraction of nonlinear systems with hybrid controllers", Automatica, 2016.
H. K. Khalil, *Nonlinear Systems*, 3rd ed., Prentice Hall, 2002, sections 4.1, 4.3 and 8.2.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import importlib.util
import math
import os
import pickle
import sys
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.control.proof import (
    INNER_IMAGE,
    MAX_BOXES,
    MAX_SECONDS,
    LevelProof,
    prove_level,
    prove_practical,
)
from leoc.io import write_bytes_atomic
from leoc.systems.base import DTYPE, System, check_repeat, wrap_angle
from leoc.systems.rollout import control_period

__all__ = [
    "LevelProof",
    "LinearClosedLoop",
    "LyapunovCertificate",
    "certify_level",
    "certify_lqr",
    "describe_certificate",
    "lqr_closed_loop",
    "lyapunov_value",
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
SYMMETRY_RTOL = 1e-9
"""Allowed asymmetry of P, relative to its largest entry."""
LINEAR_DECREASE_TOL = 0.0
"""The linear check needs max eig(A_cl^T P A_cl - P) < this (strictly negative definite)."""
PRACTICAL_RATIO = 4.0
"""A practical-stability claim is aimed at only where its target level is at least this
multiple of the inner level and of the inner set's sampled image (less says little more than
an invariant set)."""
INNER_MARGIN = 2.0
"""The practical inner level: this multiple of the largest V of the sampled violations it
holds (each retry multiplies it by ``INNER_GROWTH``)."""
INNER_GROWTH = 4.0
PRACTICAL_ATTEMPTS = 3
"""Proofs tried with a growing inner level while the box search finds decrease fail outside
the sampled one (they share the wall-clock budget)."""
PRACTICAL_SPAN = 1e-8
"""The practical estimate's samples have V log-uniform from this fraction of the initial level
up to it: the inner set can be orders of magnitude below the target."""


class LyapunovCertificate(NamedTuple):
    """A certified sublevel set ``{x : V(x) <= rho}`` of ``V = z^T P z`` (module docstring).

    Attributes
    ----------
    rho : float
        Certified level: the *proved* level when ``proof`` is given (0: nothing proved), the
        sampled estimate when the proof was switched off (``basis`` says which).
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
    sampled_rho : float
        The sampled estimate (the statistical statement above; the proof's target).
    proof : LevelProof or None
        The proof (None when switched off).
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
    sampled_rho: float = 0.0
    proof: LevelProof | None = None

    @property
    def certified(self) -> bool:
        """Whether a non-empty set was certified (``rho > 0``)."""
        return self.rho > 0.0

    @property
    def basis(self) -> str:
        """``proved`` (rho is a proved level), ``not proved`` (the proof found nothing) or
        ``sampled`` (no proof was run: rho is the sampled estimate)."""
        return "sampled" if self.proof is None else self.proof.status

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
        proof = None
        if self.proof is not None:
            # Without its wall-clock seconds: a summary is reproducible (runs compare equal).
            proof = {**self.proof._asdict(), "status": self.proof.status}
            del proof["seconds"]
        return {
            "rho": self.rho,
            "basis": self.basis,
            "sampled_rho": self.sampled_rho,
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
            "proof": proof,
        }


def _deviation(states: Tensor, operating_state: np.ndarray, angles: Sequence[int]) -> Tensor:
    deviation = states - torch.as_tensor(operating_state, dtype=states.dtype)
    if angles:
        columns = list(deviation.unbind(-1))
        for index in angles:
            columns[index] = wrap_angle(columns[index])
        deviation = torch.stack(columns, dim=-1)
    return deviation


def state_deviation(system: System, states: Tensor, centre: Any = None) -> Tensor:
    """``z = x - a`` (B, S) of states (B, S), every angle entry wrapped to [-pi, pi); from
    ``centre`` (S,) instead of a where given (a controller's own equilibrium)."""
    origin = system.operating_state if centre is None else centre
    return _deviation(states, origin, system.angle_indices)


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


def _values(
    system: System,
    P: Tensor,
    controller: Controller,
    repeat: int,
    states: Tensor,
    centre: np.ndarray,
) -> tuple[Tensor, Tensor, Tensor]:
    """``(V(x), V(F(x)), left)`` (B,) each for states x (B, S), V centred on ``centre``, F the
    held closed loop; ``left``: F left the allowed region on a held step."""
    angles = system.angle_indices
    with torch.no_grad():
        following, left = _closed_loop(system, controller, repeat, states)
        value = lyapunov_value(P, _deviation(states, centre, angles))
        value_next = lyapunov_value(P, _deviation(following, centre, angles))
    return value, value_next, left


def _decrease(
    system: System,
    P: Tensor,
    controller: Controller,
    repeat: int,
    states: Tensor,
    centre: np.ndarray,
) -> tuple[Tensor, Tensor]:
    """``(V(x), violates)`` (B,) each, V centred on ``centre``: violation = no strict decrease,
    a non-finite value, or leaving the allowed region."""
    value, value_next, left = _values(system, P, controller, repeat, states, centre)
    # The condition is on 0 < V <= rho: the operating point itself (V = 0) is a fixed point.
    violates = (value > 0.0) & (left | ~torch.isfinite(value_next) | ~(value_next < value))
    return value, violates


def held_map(system: System, controller: Controller, repeat: int) -> Callable[[Tensor], Tensor]:
    """``x -> F(x)``, the held closed loop on one state (S,), float64 and differentiable (for
    its autodiff Jacobian: the linear check here, Newton's method in
    :func:`leoc.control.find_equilibrium`)."""

    def closed(x: Tensor) -> Tensor:
        return _closed_loop(system, controller, repeat, x.unsqueeze(0))[0][0]

    return closed


def _linear_check(
    system: System, P: np.ndarray, controller: Controller, repeat: int, centre: np.ndarray
) -> tuple[bool, float]:
    """Largest eigenvalue of ``A_cl^T P A_cl - P``, A_cl the autodiff Jacobian of the held
    closed loop at ``centre`` (a, or a controller's own equilibrium); negative definite ->
    True."""
    point = torch.as_tensor(centre, dtype=DTYPE)
    closed = held_map(system, controller, repeat)
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
        else check_box(search_box, system, "search_box")
    )
    level = float(np.min(box**2 / diagonal))
    for index in system.angle_indices:
        level = min(level, math.pi**2 / float(diagonal[index]))
    if rho_max is not None:
        if not 0.0 < rho_max < math.inf:
            raise ValueError(f"rho_max: expected a positive finite number, found {rho_max!r}")
        level = min(level, float(rho_max))
    return level


def check_box(box: Any, system: System, name: str) -> np.ndarray:
    """``box`` as S positive finite half-widths (a float array), or a ValueError naming the
    argument ``name``."""
    values = np.asarray(box, dtype=float).reshape(-1)
    if values.shape != (system.state_dim,) or not np.all(np.isfinite(values) & (values > 0)):
        raise ValueError(
            f"{name}: expected {system.state_dim} positive half-widths "
            f"({', '.join(system.state_names)}), found {box!r}"
        )
    return values


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
    linear_check: bool = True,
    prove: bool = True,
    max_boxes: int = MAX_BOXES,
    equilibrium: Any = None,
    practical: bool = False,
    **proof_options: Any,
) -> LyapunovCertificate:
    r"""The certificate of the largest rho with V(F(x)) < V(x) on 0 < V <= rho (module docs).

    Parameters
    ----------
    system : System
    P : (S, S) array
        Symmetric positive definite matrix of :math:`V(x) = z^\top P z`.
    controller : callable
        Observation (B, O) float64 -> action (B, A) (e.g. :math:`G(o) = W o + b`, clipped).
    action_repeat : int, optional
        Control period (default the controller's ``action_repeat`` or 1).
    samples, seed : int
        Uniform samples per round (the last, clean, round's count sets the confidence), seed.
    confidence : float in (0, 1)
        :math:`1 - \delta` of the bound :math:`\ln(1/\delta)/n` on the violating volume.
    search_box, rho_max : (S,) half-widths, float, optional
        Start: the largest ellipsoid in ``search_box`` (default ``SEARCH_BOX_FACTOR *
        system.operating_region``) and in the angle chart, at most ``rho_max``.
    linear_check : bool
        Check the linearised decrease first (rho = 0 if it fails); off to test sampling.
    prove, max_boxes : bool, int
        Prove the level (:func:`leoc.control.proof.prove_level`, aiming at the sampled
        estimate, with this box budget); off: ``rho`` is the sampled estimate.
    equilibrium : (S,) array, optional
        Centre of V (default a): a controller's own (:func:`leoc.control.certify_controller`).
    practical : bool
        Certify practical stability instead (:func:`leoc.control.proof.prove_practical`;
        target and inner level sampled at every scale: :func:`_practical_levels`).
    **proof_options
        Further keywords of :func:`~leoc.control.proof.prove_level` (``max_seconds``, ``batch``).
    """
    repeat = _check_options(controller, action_repeat, samples, seed, confidence, max_boxes)
    matrix, centre = _check_matrix(P, system.state_dim), _check_centre(system, equilibrium)
    initial = _initial_level(system, matrix, search_box, rho_max)
    linear = _linear_check(system, matrix, controller, repeat, centre)
    search = (system, matrix, controller, repeat, initial, samples, seed, centre)
    kw = {**proof_options, "max_boxes": max_boxes, "equilibrium": centre}
    sample = linear[0] or not linear_check
    sampled, proof = _estimate_and_proof(search, sample, practical, prove, kw)
    return _certificate(
        system, matrix, repeat, samples, confidence, initial, linear, sampled, proof, centre
    )


def _estimate_and_proof(
    search: tuple, sample: bool, practical: bool, prove: bool, options: dict[str, Any]
) -> tuple[_Sampled, LevelProof | None]:
    """:func:`certify_level`'s sampled estimate and proof (None when ``prove`` is off) for
    ``search`` = (system, P, controller, repeat, initial level, samples, seed, centre): the
    practical claim's, else the asymptotic one's (its estimate only if ``sample``)."""
    if practical:
        aims = _practical_levels(*search)
        return aims.sampled, _practical_proof(*search[:4], aims, options) if prove else None
    sampled = _sampled_level(*search) if sample else _Sampled(0.0, 0)
    return sampled, prove_level(*search[:4], sampled.rho, **options) if prove else None


def _check_centre(system: System, equilibrium: Any) -> np.ndarray:
    """The centre of V: the operating point a, or ``equilibrium`` as S finite numbers."""
    if equilibrium is None:
        return np.asarray(system.operating_state, dtype=float).copy()
    centre = np.asarray(equilibrium, dtype=float).reshape(-1)
    if centre.shape != (system.state_dim,) or not np.all(np.isfinite(centre)):
        raise ValueError(
            f"equilibrium: expected {system.state_dim} finite numbers "
            f"({', '.join(system.state_names)}), found {equilibrium!r}"
        )
    return centre


def _check_options(
    controller: Controller,
    action_repeat: Any,
    samples: Any,
    seed: Any,
    confidence: Any,
    max_boxes: Any,
) -> int:
    """The control period of :func:`certify_level` (its ``action_repeat``, default the
    controller's or 1) once its options are checked; a ValueError names a wrong one."""
    repeat = control_period(controller, action_repeat)
    for name, value in (("samples", samples), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"{name}: expected a non-negative integer, found {value!r}")
    if samples < 1:
        raise ValueError(f"samples: expected a positive integer, found {samples!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence: expected a number in (0, 1), found {confidence!r}")
    if isinstance(max_boxes, bool) or not isinstance(max_boxes, (int, np.integer)) or max_boxes < 1:
        raise ValueError(f"max_boxes: expected a positive integer, found {max_boxes!r}")
    return repeat


class _Sampled(NamedTuple):
    rho: float  # the sampled estimate (0: none)
    rounds: int  # verification rounds drawn


def _sampled_level(
    system: System,
    matrix: np.ndarray,
    controller: Controller,
    repeat: int,
    initial: float,
    samples: int,
    seed: int,
    centre: np.ndarray,
) -> _Sampled:
    """The sampled estimate (module docstring): from ``initial`` down, a fresh batch of
    ``samples`` per round, until a round without a violation."""
    rng = np.random.default_rng(seed)
    P_t = torch.as_tensor(matrix, dtype=DTYPE)
    operating = torch.as_tensor(centre, dtype=DTYPE)
    rho = initial
    for rounds in range(1, MAX_ROUNDS + 1):
        deviation = _uniform_ellipsoid(matrix, rho, samples, rng)
        states = torch.as_tensor(deviation, dtype=DTYPE) + operating
        value, violates = _decrease(system, P_t, controller, repeat, states, centre)
        if not bool(violates.any()):
            return _Sampled(rho, rounds)
        smallest = float(value[violates].min())
        rho = float(np.nextafter(smallest, 0.0))
        if rho <= MIN_RELATIVE_LEVEL * initial:
            return _Sampled(0.0, rounds)
    return _Sampled(0.0, MAX_ROUNDS)


class _Practical(NamedTuple):
    """The sampled aims of a practical-stability proof (:func:`_practical_levels`)."""

    sampled: _Sampled  # its rho: the target level
    inner: float  # the inner level
    reach: float  # the largest V of the inner samples' images


def _practical_levels(
    system: System,
    matrix: np.ndarray,
    controller: Controller,
    repeat: int,
    initial: float,
    samples: int,
    seed: int,
    centre: np.ndarray,
) -> _Practical:
    """The practical claim's target and inner level from ``samples`` states whose V spreads
    log-uniformly over ``[PRACTICAL_SPAN, 1] * initial``: for each split of the sorted
    violations into an inner group (possibly empty) and the rest, the inner level is
    ``INNER_MARGIN`` times the group's largest V (the smallest sample's if empty) and the
    target lies just below the next violation (the initial level if none); a split counts if
    its target is ``PRACTICAL_RATIO`` times its inner level and the sampled image of the inner
    set; the largest target is kept (target 0: none)."""
    rng = np.random.default_rng(seed)
    unit = _uniform_ellipsoid(matrix, 1.0, samples, rng)
    unit /= np.sqrt(np.einsum("bi,ij,bj->b", unit, matrix, unit))[:, None]
    scale = initial * PRACTICAL_SPAN ** rng.uniform(size=samples)
    states = torch.as_tensor(np.sqrt(scale)[:, None] * unit + centre, dtype=DTYPE)
    P_t = torch.as_tensor(matrix, dtype=DTYPE)
    value, image, left = (
        t.numpy() for t in _values(system, P_t, controller, repeat, states, centre)
    )
    image = np.where(np.isfinite(image) & ~left, image, np.inf)
    order = np.argsort(value)
    value, image = value[order], image[order]
    failing = value[~(image < value)]
    if not failing.size:
        return _Practical(_Sampled(initial, 1), INNER_MARGIN * float(value[0]), float(image[0]))
    # Splits: nothing inner (the smallest sampled V), then each violation's V and below.
    inner = INNER_MARGIN * np.append(value[0], failing)
    target = np.append(np.nextafter(failing, 0.0), initial)
    reach = np.maximum.accumulate(image)[np.searchsorted(value, inner, side="right") - 1]
    usable = target >= PRACTICAL_RATIO * np.maximum(inner, reach)
    if not usable.any():
        return _Practical(_Sampled(0.0, 1), 0.0, 0.0)
    best = int(np.argmax(np.where(usable, target, -np.inf)))
    return _Practical(_Sampled(float(target[best]), 1), float(inner[best]), float(reach[best]))


def _practical_proof(
    system: System,
    matrix: np.ndarray,
    controller: Controller,
    repeat: int,
    aims: _Practical,
    options: dict[str, Any],
) -> LevelProof:
    """The practical claim's proof aimed at the sampled target, the inner boxes' images held
    below ``INNER_MARGIN`` times the sampled reach (a tight ultimate level); while the boxes
    find the decrease or an image fail, retried with the inner level and that ceiling grown by
    ``INNER_GROWTH`` (up to ``PRACTICAL_ATTEMPTS`` tries, the ceiling at most the target, the
    target ``PRACTICAL_RATIO`` times the inner level); the tries share ``max_seconds``."""
    deadline = time.perf_counter() + float(options.get("max_seconds", MAX_SECONDS))
    target, inner = aims.sampled.rho, aims.inner
    ceiling = min(target, INNER_MARGIN * max(aims.reach, inner))
    proof = None
    for attempt in range(PRACTICAL_ATTEMPTS):
        left = max(0.0, deadline - time.perf_counter()) / (PRACTICAL_ATTEMPTS - attempt)
        tries = {**options, "max_seconds": left}
        trial = prove_practical(system, matrix, controller, repeat, target, inner, ceiling, **tries)
        proof = trial if proof is None or trial.rho > proof.rho else proof
        if trial.proved or trial.limited_by not in ("decrease", INNER_IMAGE):
            break
        if ceiling >= target and PRACTICAL_RATIO * inner * INNER_GROWTH > target:
            break
        ceiling = min(target, ceiling * INNER_GROWTH)
        inner = min(inner * INNER_GROWTH, target / PRACTICAL_RATIO)
    return proof


def _certificate(
    system: System,
    matrix: np.ndarray,
    repeat: int,
    samples: int,
    confidence: float,
    initial: float,
    linear: tuple[bool, float],
    sampled: _Sampled,
    proof: LevelProof | None,
    centre: np.ndarray,
) -> LyapunovCertificate:
    """The certificate of a search: ``rho`` the proved level (the sampled one without proof)."""
    delta = 1.0 - confidence
    bound = math.log(1.0 / delta) / samples if sampled.rho > 0.0 else float("nan")
    return LyapunovCertificate(
        sampled.rho if proof is None else proof.rho,
        matrix,
        centre,
        tuple(system.angle_indices),
        repeat,
        samples,
        sampled.rounds,
        confidence,
        bound,
        initial,
        sampled.rho == initial,
        linear[0],
        linear[1],
        sampled.rho,
        proof,
    )


def describe_certificate(system: System, certificate: LyapunovCertificate) -> list[str]:
    """Lines for people: the proved level (or why there is none) and, apart, the sampled
    estimate with its statistical statement."""
    names = system.state_names
    lines = []
    proof = certificate.proof
    if proof is None:
        lines.append(
            f"rho = {certificate.rho:.6g} (SAMPLED estimate, not proved: the proof was switched "
            "off)"
        )
    elif proof.proved and proof.claim == "practical":
        lines.append(
            f"rho = {certificate.rho:.6g} (PROVED PRACTICALLY STABLE: {{V <= rho}} is invariant "
            f"and every trajectory from it enters and stays in {{V <= "
            f"{proof.ultimate_level:.3g}}}: V decreases outside an inner set within V <= "
            f"{proof.excluded_level:.3g}, whose image stays in the set; {proof.boxes} verified "
            f"boxes; limited by {proof.limited_by}; {proof.seconds:.1f} s)"
        )
    elif proof.proved:
        lines.append(
            f"rho = {certificate.rho:.6g} (PROVED: V(F(x)) < V(x) for every x with "
            f"{proof.excluded_level:.3g} < V(x) <= rho, the set and its held steps inside the "
            f"allowed region; {proof.boxes} verified boxes, inner ball V <= "
            f"{proof.inner_level:.4g} by the rigorous linearisation; limited by "
            f"{proof.limited_by}; {proof.seconds:.1f} s)"
        )
    else:
        lines.append(f"rho: NOT PROVED ({proof.reason}); the sampled estimate below is no proof")
    if certificate.certified:
        extent = ", ".join(
            f"{name} +/- {width:.4g}" for name, width in zip(names, certificate.extent, strict=True)
        )
        lines.append(f"extent of the {certificate.basis} set: {extent}")
    if certificate.sampled_rho > 0.0:
        capped = " (capped by the search box)" if certificate.capped else ""
        lines.append(
            f"sampled estimate: rho_sampled = {certificate.sampled_rho:.6g}{capped}: "
            f"{certificate.samples} uniform samples in the final clean round "
            f"({certificate.rounds} rounds); with confidence {certificate.confidence:g} the "
            f"violating volume fraction is < {certificate.violation_bound:.3g} (a statistical "
            "statement, not a proof)"
        )
    else:
        lines.append(
            f"sampled estimate: 0 (linear decrease {certificate.linear_decrease}, largest "
            f"eigenvalue of A_cl^T P A_cl - P = {certificate.linear_decrease_eig:.4g})"
        )
    return lines


class LinearClosedLoop:
    """``G(o) = W o + b`` of an :class:`~leoc.control.LQRDesign`, float64, with the design's
    ``action_repeat`` (the actuator clip is inside the step). Observation (B, O) -> (B, A)."""

    is_hybrid = False

    def __init__(self, design: Any) -> None:
        self.W = torch.as_tensor(design.W, dtype=DTYPE)
        self.b = torch.as_tensor(design.b, dtype=DTYPE)
        self.action_repeat = check_repeat(design.action_repeat)

    def __call__(self, obs: Tensor) -> Tensor:
        # On the device of its input (a proof may run on a GPU: leoc.control.proof).
        return obs @ self.W.to(obs.device).T + self.b.to(obs.device)


def lqr_closed_loop(design: Any) -> LinearClosedLoop:
    """The LQR of ``design`` as a controller at the design's control period."""
    return LinearClosedLoop(design)


def certify_lqr(
    system: System,
    design: Any,
    controller: Controller | None = None,
    *,
    controller_key: str | None = None,
    controller_modules: Sequence[str] = (),
    **options: Any,
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
    controller_key : str, optional
        What fixes ``controller`` given system and design (its saturation and limit, say):
        the certificate is then cached as the design's own; without it, proved at every call.
    controller_modules : sequence of str
        Modules that define ``controller``: their source enters the key.
    **options
        :func:`certify_level`'s keywords (``samples``, ``confidence``, ``seed``, ...).

    Notes
    -----
    A certificate (of ``G``, or of a keyed ``controller``) is computed once per key and copied
    out: the proof is deterministic (seeded) and costs seconds to minutes. It is kept twice:

    - in the process (the last :data:`~leoc.control.roa.CERTIFICATE_CACHE_SIZE`), and
    - on disk, for the next process (xdist workers, each ``leoc train``, each ablation run):
      a pickle ``<key>.pkl`` in :func:`~leoc.control.roa.certificate_cache_dir`, that is
      ``$LEOC_CACHE_DIR/certificates``, else ``$XDG_CACHE_HOME/leoc/certificates``, else
      ``~/.cache/leoc/certificates``. ``LEOC_CACHE_DIR=off`` turns the disk cache off. Files
      are written atomically (temporary file, then rename), so concurrent processes never
      read half a file; a file that does not load is recomputed and rewritten, and a folder
      that cannot be written is skipped, never an error.

    The key is a SHA-256 of the system's class and attributes, the design's ``W, b, P`` and
    control period, the options, leoc's version and the source of the modules that compute
    the certificate (:data:`~leoc.control.roa.PROOF_MODULES` and the system's own module), so
    editing the proof or the dynamics makes a new key (a system whose source cannot be read
    is not cached on disk). A proof cut by its wall-clock budget (the acrobot's) is stored as
    found; delete the folder to prove again. Point ``LEOC_CACHE_DIR`` only at a folder no one
    else can write: the files are unpickled.
    """
    closed_loop = lqr_closed_loop(design) if controller is None else controller
    prove = functools.partial(
        certify_level, system, design.P, closed_loop, action_repeat=design.action_repeat, **options
    )
    if controller is not None and controller_key is None:
        return prove()
    if controller is None:
        controller_key, controller_modules = None, ()
    key = _certificate_key(system, design, options, controller_key, controller_modules)
    return _held_stored_or_computed(key, prove, (type(system).__module__, *controller_modules))


def _held_stored_or_computed(
    key: str, prove: Callable[[], LyapunovCertificate], modules: Sequence[str]
) -> LyapunovCertificate:
    """A copy of the certificate of ``key``: held in the process (the last
    :data:`CERTIFICATE_CACHE_SIZE`), else :func:`_stored_or_computed`."""
    cached = _CERTIFICATES.get(key)
    if cached is None:
        cached = _stored_or_computed(key, prove, modules)
        _CERTIFICATES[key] = cached
        while len(_CERTIFICATES) > CERTIFICATE_CACHE_SIZE:
            _CERTIFICATES.popitem(last=False)
    else:
        _CERTIFICATES.move_to_end(key)
    return copy.deepcopy(cached)


def _stored_or_computed(
    key: str, prove: Callable[[], LyapunovCertificate], modules: Sequence[str]
) -> LyapunovCertificate:
    """The certificate of ``key`` from the disk cache, or ``prove()`` (and stored there; not
    if the source of one of ``modules`` cannot be read, since the key would not change with
    it)."""
    folder = certificate_cache_dir()
    if any(_module_digest(name) is None for name in modules):
        folder = None  # dynamics or a controller without readable source: not in the key
    path = None if folder is None else folder / f"{key}.pkl"
    stored = None if path is None else _load_certificate(path)
    if stored is not None:
        return stored
    certificate = prove()
    if path is not None:
        _store_certificate(path, certificate)
    return certificate


CERTIFICATE_CACHE_SIZE = 16
"""How many LQR certificates :func:`certify_lqr` keeps per process (least recently used go)."""

_CERTIFICATES: OrderedDict[str, LyapunovCertificate] = OrderedDict()

CACHE_DIR_VARIABLE = "LEOC_CACHE_DIR"
"""Environment variable naming leoc's cache folder; certificates go to its ``certificates``
subfolder. Unset or empty: ``$XDG_CACHE_HOME/leoc`` (``~/.cache/leoc`` without it). Set to
:data:`CACHE_OFF`: no disk cache (:func:`certificate_cache_dir`)."""

CACHE_OFF = "off"
"""The value of :data:`CACHE_DIR_VARIABLE` that turns the disk cache off (exactly this)."""

CERTIFICATE_FOLDER = "certificates"
"""Subfolder of the cache folder holding the LQR certificates, one ``<key>.pkl`` each."""

PROOF_MODULES = (
    "leoc.control.roa",
    "leoc.control.proof",
    "leoc.control.intervals",
    "leoc.systems.base",
    "leoc.systems.observation",
)
"""Modules whose source enters the certificate key (with the system's own module): the
search, the proof, the interval engine and the shared step and observation code."""


def certificate_cache_dir() -> Path | None:
    """The folder of the on-disk certificate cache, or None when it is off.

    ``$LEOC_CACHE_DIR/certificates`` if :data:`CACHE_DIR_VARIABLE` is set and not empty (None
    if it is :data:`CACHE_OFF`), else ``$XDG_CACHE_HOME/leoc/certificates``, else
    ``~/.cache/leoc/certificates`` (None if there is no home folder). Read at every call; the
    folder is created only when a certificate is written.
    """
    value = os.environ.get(CACHE_DIR_VARIABLE, "")
    if value == CACHE_OFF:
        return None
    if value:
        return Path(value).expanduser() / CERTIFICATE_FOLDER
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    try:
        base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    except RuntimeError:  # no home folder to expand
        return None
    return base / "leoc" / CERTIFICATE_FOLDER


@functools.cache
def _module_digest(name: str) -> str | None:
    """SHA-256 of a module's source file, read once per process; None if it cannot be read
    (a class defined in ``__main__``, a notebook, a zip without source)."""
    try:
        spec = importlib.util.find_spec(name)
        origin = None if spec is None else spec.origin
        if origin is None or not origin.endswith(".py"):
            return None
        return hashlib.sha256(Path(origin).read_bytes()).hexdigest()
    except (ImportError, ValueError, OSError):
        return None


@functools.cache
def _source_digest() -> str:
    """SHA-256 of leoc's version and of the source of :data:`PROOF_MODULES`, once per
    process: a change of the proof code changes every certificate key."""
    digest = hashlib.sha256()
    digest.update(str(getattr(sys.modules.get("leoc"), "__version__", "")).encode())
    for name in PROOF_MODULES:
        digest.update(name.encode())
        digest.update(str(_module_digest(name)).encode())
    return digest.hexdigest()


def _load_certificate(path: Path) -> LyapunovCertificate | None:
    """The certificate pickled at ``path``; None if there is none or it does not load."""
    try:
        with path.open("rb") as file:
            loaded = pickle.load(file)
    except Exception:  # missing, truncated, corrupt or stale: any failure is a cache miss
        return None
    return loaded if isinstance(loaded, LyapunovCertificate) else None


def _store_certificate(path: Path, certificate: LyapunovCertificate) -> None:
    """Pickle ``certificate`` to ``path`` atomically (:func:`leoc.io.write_bytes_atomic`: a
    reader sees the old file or the whole new one). A folder that cannot be written is skipped
    silently (the cache is an optimisation)."""
    try:
        write_bytes_atomic(path, pickle.dumps(certificate, protocol=pickle.HIGHEST_PROTOCOL))
    except Exception:  # unwritable, full disk, unpicklable: keep the certificate, skip the file
        pass


def _certificate_key(
    system: System,
    design: Any,
    options: Mapping[str, Any],
    controller_key: str | None = None,
    controller_modules: Sequence[str] = (),
) -> str:
    """What an LQR certificate depends on, hashed: the system's class and attributes
    (parameters, step rules; not the cached derived ones), the design's ``W, b, P`` and
    control period, the options, the closed loop (``controller_key`` and the source of
    ``controller_modules``, for a controller other than the design's own), and the code
    (:func:`_source_digest`, the source of the system's module). The search is deterministic
    (seeded), so equal keys give equal certificates."""
    digest = hashlib.sha256()
    digest.update(f"{type(system).__module__}.{type(system).__qualname__}".encode())
    for name, value in sorted(vars(system).items()):
        if isinstance(getattr(type(system), name, None), functools.cached_property):
            continue  # derived from the rest, and present only once it was first used
        digest.update(name.encode())
        digest.update(pickle.dumps(value))
    for name in ("W", "b", "P"):
        array = np.ascontiguousarray(np.asarray(getattr(design, name), dtype=np.float64))
        digest.update(name.encode())
        digest.update(repr(array.shape).encode())
        digest.update(array.tobytes())
    digest.update(repr(int(design.action_repeat)).encode())
    digest.update(repr(sorted(options.items())).encode())
    digest.update(_source_digest().encode())
    digest.update(str(_module_digest(type(system).__module__)).encode())
    if controller_key is not None:
        digest.update(f"controller={controller_key}".encode())
        for name in controller_modules:
            digest.update(f"{name}={_module_digest(name)}".encode())
    return digest.hexdigest()
