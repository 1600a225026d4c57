r"""A proof that a sublevel set of :math:`V = z^\top P z` is a region of attraction.

Letters: B batch (boxes), S state dimension.

**Claim.** For the sampled-data closed loop :math:`F` that is actually run (the nonlinear step
applied ``repeat`` times with the saturated action held, :mod:`leoc.control.roa`) and
:math:`V(z) = |L^\top z|^2` (:math:`P = L L^\top`, Cholesky; equal to :math:`z^\top P z` to
rounding), :func:`prove_level` returns a level :math:`\rho` with

.. math::

    V(F(z)) < V(z) \quad \text{for all } z \text{ with } \varepsilon^2 < V(z) \le \rho,

and every state of :math:`\{V \le \rho\}` and of its held steps inside the allowed region
(``System.out_of_bounds`` never true), :math:`\varepsilon` the stated excluded radius (0 when
the operating point is an exact fixed point of the floating-point model, as for every built-in
system). Then :math:`\{V \le \rho\}` is positively invariant and every trajectory from it
converges to the operating point (Khalil 2002, Thm 4.1 and sec. 8.2; with
:math:`\varepsilon > 0`, to the ball :math:`V \le \varepsilon^2`).

**Coordinates.** In :math:`w = L^\top z` the set is the ball :math:`|w|^2 \le \rho` and
:math:`\tilde F(w) = L^\top (F(a + L^{-\top} w) - a)` gives
:math:`\Delta(w) = |\tilde F(w)|^2 - |w|^2`. (:math:`L^{-\top}` is computed; its error
:math:`e \ge \|L^\top L^{-\top} - I\|_2` enters every bound, :math:`V \ge (1 - e)^2 |w|^2`.)

**Inner ball: the linearisation, made rigorous.** On the box :math:`B_0 = [-s, s]^S`, interval
arithmetic (:mod:`leoc.control.intervals`) encloses the Jacobian :math:`\tilde J(B_0)` in
:math:`J_c \pm R`. By the mean-value theorem in integral form
:math:`\tilde F(w) = \tilde F(0) + \bar J w` with :math:`\bar J` in that enclosure, so
:math:`|\tilde F(w)| \le |\tilde F(0)| + k |w|`, :math:`k = \|J_c\|_2 + \|R\|_2`. If
:math:`k < 1 - e` the decrease holds for :math:`|w| > \varepsilon = |\tilde F(0)| /
(1 - e - k)` on the ball of radius s; the largest such s is found by bisection.

**Annulus: adaptive verified boxes.** The ball is covered by boxes :math:`c \pm h` in w. On a
box, with :math:`\delta = w - c`, :math:`\tilde F(c) \in f \pm f_r` (point enclosure) and
:math:`\bar J = J_c + D`, :math:`|D| \le R` (enclosure over the box),

.. math::

    \Delta(w) = \Delta_0 + g^\top \delta + \delta^\top M \delta + E, \qquad
    \Delta_0 = |f|^2 - |c|^2,\ g = 2 (J_c^\top f - c),\ M = J_c^\top J_c - I,

with :math:`|E| \le 2 |f|^\top R h + 2 f_r^\top (|J_c| + R) h + 2 |f| |f_r| + |f_r|^2 +
h^\top (2 |J_c|^\top R + R^\top R) h`. The quadratic part is bounded over the box in two ways
and the smaller taken: :math:`\Delta_0 + |g|^\top h + \max(0, \lambda_{\max}(M)) |h|^2`, and,
when :math:`M \prec 0`, its maximum over :math:`\mathbb{R}^S` at
:math:`\delta^* = -M^{-1} g / 2` lowered by :math:`\lambda_{\max}(M)\,
\operatorname{dist}(\delta^*, \text{box})^2`. This keeps the cancellation between
:math:`V(F(z))` and :math:`V(z)` that plain interval evaluation loses (the dependency
problem), so boxes a few percent of the radius wide suffice in 4-D. A box passes when the
bound is negative and no state of it or of its held steps is possibly out of bounds; a failing
box is bisected along its widest side, smallest levels first, until its size relative to its
distance from a is below ``resolution`` (``RESOLUTION``); boxes
inside the inner ball or outside the target ball are skipped. The proved level is the
smallest :math:`\min_{\text{box}} |w|^2` of the boxes left unproved (or the target).

**Flat regions.** A controller with a ``flat_region()`` method returning a
:class:`~leoc.policies.relevance.FlatRegion` (or None) says where it equals a simpler
controller exactly: an ROA hybrid is its linear part on its relevance's flat top
:math:`\{V_r \le \rho_{in}\}` (r = 1 there). On a box whose every state lies there the
simpler controller is evaluated instead, which is the same map, so every claim above is
unchanged. The test is exact up to rounding: x is affine in w, so :math:`V_r` (a convex
quadratic) is largest over a box at one of its :math:`2^S` corners, each evaluated in
interval arithmetic; an angle deviation must also stay in :math:`(-\pi, \pi)` on the box,
where the relevance's wrap is the identity. The relevance's own interval enclosure of its
level cannot do this: it sees the box only through the state's intervals, the hull of the
box's image, which overestimates :math:`V_r` several times (docs, ``roa.md``).

**Practical stability** (:func:`prove_practical`, inner level :math:`\eta`): for a centre that is no
stable fixed point (a baseline whose loop oscillates about an unstable equilibrium, or has
none near a), no inner ball contracts. Instead a box that fails the decrease passes if it
reaches within :math:`\eta` of the centre (:math:`\min_{\text{box}} |w|^2 \le \eta`, up to
the frame error) and its image is proved below a ceiling (at most the target; a lower one
bisects these boxes finer): :math:`V(F(z)) = |\tilde F(w)|^2 \le U_{\text{box}}`, with
:math:`|\tilde F_i|` bounded by the smaller of the plain enclosure and the mean-value form
:math:`|f_i| + f_{r,i} + ((|J_c| + R) h)_i`. Let :math:`I` be the union of the boxes passed
so, :math:`U = \max U_{\text{box}}` and :math:`\rho` the level proved as above. The claim is
kept only if :math:`U \le \rho` (else ``limited_by = "inner image"``); then
:math:`\{V \le \rho\}` is positively invariant (a state of :math:`I` maps below :math:`U`,
any other decreases), every trajectory from it enters :math:`I` in finite time (on the
finitely many decrease boxes the bound is at most some :math:`-\delta < 0`, and
:math:`V \ge 0`), and from then on :math:`V \le \max(\sup_I V, U)`, reported as
``ultimate_level`` (``excluded_level`` is :math:`\sup_I V \le (1 + e)^2
\max_{\text{box}} |w|^2`). This is uniform ultimate boundedness (Khalil 2002, sec. 4.8),
proved on the exact sampled-data loop; the centre need not be a fixed point at all.

Floating point: the interval evaluator rounds outward (:mod:`leoc.control.intervals`); the
few dense operations on S x S matrices of the bound (products, ``eigvalsh``) get a relative
slack ``BOUND_SLACK`` of their magnitudes, many orders above their rounding errors.

**Device.** The search runs on the CPU by default, or on an accelerator (``device="cuda"``):
the proof's tensors are made there and a controller that is a ``torch.nn.Module`` is copied
there (the caller's stays where it is); the system's step must be plain torch on its inputs,
as every leoc system is. The proved level does not depend on the device beyond the libm
allowance of :mod:`leoc.control.intervals`, which widens ``sin`` and ``cos`` off the CPU (CUDA
documents 2 ulps for them, glibc 1); the order of the box search does not change.

References
----------
H. K. Khalil, *Nonlinear Systems*, 3rd ed., Prentice Hall, 2002.
R. E. Moore, R. B. Kearfott and M. J. Cloud, *Introduction to Interval Analysis*, SIAM 2009,
sec. 6.1 (mean-value form).
"""

from __future__ import annotations

import contextlib
import copy
import math
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.control.intervals import (
    Jet,
    UnsupportedOperation,
    box_corners,
    box_jet,
    corner_quadratic_high,
    point_jet,
    with_rows,
)
from leoc.systems.base import DTYPE, System

__all__ = ["LevelProof", "check_device", "prove_level", "prove_practical"]

Controller = Callable[[Tensor], Tensor]

INITIAL_BOXES_PER_AXIS = {2: 16, 3: 8, 4: 6}
"""Boxes per axis of the first cover of the target ball (default 4 beyond four dimensions)."""
DEFAULT_INITIAL_BOXES = 4
RESOLUTION = {2: 2e-6, 3: 1e-4, 4: 1e-3}
"""A failing box counts as unproved once its widest half-width is below this fraction of its
distance from a (or of the inner ball's radius, if larger): the resolution is relative, so
boxes near the inner ball get as fine as those at the boundary."""
DEFAULT_RESOLUTION = 1e-3
MAX_DEPTH = 120
"""Bisections of one box (each halves its widest side) at most, whatever the resolution."""
MAX_BOXES = 3_000_000
"""Box evaluations before the search stops (the boxes still pending then count as unproved)."""
MAX_SECONDS = 480.0
"""Wall-clock budget of the box search (a safety valve for hard systems such as the acrobot;
the paper systems finish far below it and are then reproducible box for box)."""
BATCH = 16_384
"""Boxes evaluated per batched call, smallest levels first."""
INNER_BISECTIONS = 40
TIGHTEN_FACTOR = 0.5
"""The excluded radius epsilon is shrunk on smaller balls while each step at least halves it."""
BOUND_SLACK = 1e-10
"""Relative slack on the dense S x S operations of the box bound (module docstring)."""
HUGE_ENTRY = 1e150
"""A box whose ``J^T J`` has an entry beyond this gets no bound (it fails): its square would
overflow in the bound's products."""
LEVEL_MARGIN = 1e-12
"""The reported level is this fraction below the smallest unproved level (strict inequality)."""
NO_BALL = (
    "the rigorous linearisation proves no ball: the Jacobian enclosure is no contraction in the "
    "V-norm"
)
CLAIMS = ("asymptotic", "practical")
"""What a proof shows: convergence to the centre (its inner ball by the rigorous
linearisation), or practical stability (an invariant level set attracted to a small inner set
whose image stays inside it: :func:`prove_practical`)."""
INNER_IMAGE = "inner image"
"""``limited_by`` of a practical proof whose inner set maps past the level proved outside it."""
NO_GAP = "no sampled gap"
"""``limited_by`` of a practical proof with no target: among the samples at every scale, no
split of the violations left a target ``PRACTICAL_RATIO`` times the inner level
(:func:`leoc.control.roa.certify_level`)."""
STATUS_PROVED = "proved"
STATUS_NOT_PROVED = "not proved"
DEVICE_TYPES = ("cpu", "cuda")
"""Devices a proof runs on: the CPU, or an NVIDIA GPU through torch's CUDA build."""


def check_device(device: Any) -> torch.device:
    """``device`` (``"cpu"``, ``"cuda"``, ``"cuda:1"``, a :class:`torch.device`) as a torch device
    a proof can run on here.

    Raises
    ------
    ValueError
        Not a device name, a kind other than :data:`DEVICE_TYPES`, or CUDA without a usable GPU.
    """
    try:
        resolved = torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(
            f"device: expected one of {DEVICE_TYPES} (optionally 'cuda:N'), found {device!r}"
        ) from None
    if resolved.type not in DEVICE_TYPES:
        raise ValueError(f"device: expected one of {DEVICE_TYPES}, found {device!r}")
    if resolved.type == "cuda":
        available = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if (resolved.index or 0) >= available:
            raise ValueError(
                f"device: expected an available GPU, found {device!r} ({available} CUDA "
                f"device(s) usable by this torch build)"
            )
    return resolved


def _default_device(device: torch.device) -> contextlib.AbstractContextManager:
    """A context in which new tensors are made on ``device``: nothing to enter when that is
    already the default (the CPU, unless a user set another). ``torch.device`` as a context
    routes every torch call of the block through a Python ``__torch_function__`` mode, which
    took about half of a small proof's time on the CPU."""
    if device == torch.get_default_device():
        return contextlib.nullcontext()
    return torch.device(device)


def _on_device(controller: Controller, device: torch.device) -> Controller:
    """``controller`` with its tensors on ``device``: a copy of a module moved there, else
    itself (a plain callable must follow its inputs' device)."""
    if device.type == "cpu" or not isinstance(controller, torch.nn.Module):
        return controller
    return copy.deepcopy(controller).to(device)


class LevelProof(NamedTuple):
    """Outcome of :func:`prove_level` (module docstring).

    Attributes
    ----------
    rho : float
        Proved level of ``V = |L^T z|^2`` (0: nothing proved).
    target : float
        The level the proof aimed at (the sampled estimate).
    inner_level : float
        Level of the inner ball proved by the rigorous linearisation.
    excluded_level : float
        ``epsilon^2``: the decrease is proved for ``V > excluded_level`` only (0 when the
        operating point is an exact fixed point).
    boxes : int
        Boxes evaluated.
    unproved_boxes : int
        Boxes left unproved at the resolution (or pending when the budget ran out).
    limited_by : str
        What set ``rho``: ``target`` (all of the target proved), ``decrease`` (a box whose
        bound stays non-negative), ``region`` (a box possibly out of the allowed region),
        ``budget`` (``max_boxes`` or ``max_seconds`` reached) or ``unsupported`` (the model
        has an operation without an interval rule; ``reason`` names it).
    resolution : float
        Relative box size at which a failing box counts as unproved.
    seconds : float
    reason : str
        One line for people.
    claim : str
        ``asymptotic`` (the inner ball by the rigorous linearisation) or ``practical`` (an
        inner set passed by its image: ``CLAIMS``, module docstring).
    ultimate_level : float
        Every trajectory from ``{V <= rho}`` enters ``{V <= ultimate_level}`` in finite time
        and stays there (``excluded_level`` for the asymptotic claim, where that ball maps
        into itself; 0 when nothing was proved).
    """

    rho: float
    target: float
    inner_level: float
    excluded_level: float
    boxes: int
    unproved_boxes: int
    limited_by: str
    resolution: float
    seconds: float
    reason: str
    claim: str = "asymptotic"
    ultimate_level: float = 0.0

    @property
    def proved(self) -> bool:
        """Whether a positive level was proved (``rho > 0``)."""
        return self.rho > 0.0

    @property
    def status(self) -> str:
        """``"proved"`` if a positive level was proved, else ``"not proved"``."""
        return STATUS_PROVED if self.proved else STATUS_NOT_PROVED


class _Frame(NamedTuple):
    """The w-coordinates: ``w = L^T z``, ``z = inverse @ w``, ``error`` >= ||L^T inverse - I||."""

    factor: Tensor  # L (S, S)
    inverse: Tensor  # L^-T (S, S)
    operating: Tensor  # a (S,)
    error: float


class _Enclosure(NamedTuple):
    """Closed loop over boxes: F~ value and Jacobian (in w), and 'possibly out of bounds'."""

    mid: Tensor  # (B, S)
    rad: Tensor  # (B, S)
    jac_mid: Tensor | None  # (B, S, S): [i, s] = d F~_i / d w_s
    jac_rad: Tensor | None
    outside: Tensor  # (B,) bool


def _frame(system: System, P: np.ndarray, centre: np.ndarray | None = None) -> _Frame:
    factor = np.linalg.cholesky(P)
    inverse = np.linalg.inv(factor.T)
    size = P.shape[0]
    residual = factor.T @ inverse - np.eye(size)
    rounding = 2.0 * size * np.finfo(float).eps * np.abs(factor.T) @ np.abs(inverse)
    error = float(np.linalg.norm(residual, "fro") + np.linalg.norm(rounding, "fro"))
    return _Frame(
        torch.as_tensor(factor, dtype=DTYPE),
        torch.as_tensor(inverse, dtype=DTYPE),
        torch.as_tensor(system.operating_state if centre is None else centre, dtype=DTYPE),
        error,
    )


def _closed_loop_jet(
    system: System, controller: Controller, repeat: int, states: Jet
) -> tuple[Jet, Tensor]:
    """The held closed loop on interval states: (next states, possibly out of bounds)."""
    outside = system.out_of_bounds(states)
    action = controller(system.observation.observe(states))
    if not isinstance(action, Jet):
        raise UnsupportedOperation(
            f"controller: returned {type(action).__name__}, not an interval enclosure"
        )
    for _ in range(repeat):
        states = system.step_fn(states, action)
        outside = outside | system.out_of_bounds(states)
    return states, outside


def _enclose(
    system: System,
    controller: Controller,
    repeat: int,
    frame: _Frame,
    centre: Tensor,
    radius: Tensor | None,
) -> _Enclosure:
    """F~ over boxes ``centre +/- radius`` in w (with its Jacobian), or at points (radius None)."""
    if radius is None:
        z = point_jet(centre) @ frame.inverse.T
    else:
        z = box_jet(centre, radius, frame.inverse)
        controller = _with_flat_region(controller, frame, centre, radius, z + frame.operating)
    following, outside = _closed_loop_jet(system, controller, repeat, z + frame.operating)
    image = (following - frame.operating) @ frame.factor
    finite = torch.isfinite(image.mid).all(-1) & torch.isfinite(image.rad).all(-1)
    if image.dmid is not None:
        finite &= torch.isfinite(image.dmid).all((-1, -2)) & torch.isfinite(image.drad).all(
            (-1, -2)
        )
    return _Enclosure(image.mid, image.rad, image.dmid, image.drad, outside | ~finite)


def _with_flat_region(
    controller: Controller, frame: _Frame, centre: Tensor, radius: Tensor, states: Jet
) -> Controller:
    """``controller``, except on the boxes inside its flat region (module docstring, **Flat
    regions**), where its simpler controller runs instead (the same map there)."""
    method = getattr(controller, "flat_region", None)
    region = method() if callable(method) else None
    if region is None:
        return controller
    flat = _flat_rows(region, frame, centre, radius, states)
    if not bool(flat.any()):
        return controller
    live = ~flat

    def split(obs: Jet) -> Jet:
        inner = region.inner(obs)
        if not bool(live.any()):
            return inner
        return with_rows(inner, live, controller(obs[live]))

    return split


def _flat_rows(region: Any, frame: _Frame, centre: Tensor, radius: Tensor, states: Jet) -> Tensor:
    r"""Boxes (B,) ``centre +/- radius`` in w on which the region's :math:`V \le` level holds
    everywhere: V is a convex quadratic of w (x is affine in w), so its largest value over a
    box is at one of the :math:`2^S` corners (ends rounded outward, values in interval
    arithmetic); and every angle deviation of ``states`` stays in :math:`(-\pi, \pi)`."""
    low = torch.nextafter(centre - radius, torch.full_like(centre, -math.inf))
    high = torch.nextafter(centre + radius, torch.full_like(centre, math.inf))
    corners = point_jet(box_corners(low, high)) @ frame.inverse.T  # (B, 2^S, S)
    top = corner_quadratic_high(corners + frame.operating - region.operating_state, region.lyapunov)
    inside = top <= region.level
    for index in region.angle_indices:
        angle = states[:, index] - region.operating_state[index]
        inside &= (angle.low > -math.pi) & (angle.high < math.pi)
    return inside


def _spectral_upper(matrix: Tensor) -> Tensor:
    """Upper bound of the spectral norm (B,) of matrices (B, S, S)."""
    norm = torch.linalg.matrix_norm(matrix, ord=2)
    return norm * (1.0 + BOUND_SLACK) + BOUND_SLACK


def _inner_contraction(
    system: System, controller: Controller, repeat: int, frame: _Frame, half_width: float
) -> tuple[bool, float]:
    """Whether the inner-ball argument holds on [-s, s]^S; and epsilon (module docstring)."""
    size = frame.factor.shape[0]
    centre = torch.zeros(1, size, dtype=DTYPE)
    box = _enclose(
        system, controller, repeat, frame, centre, torch.full((1, size), half_width, dtype=DTYPE)
    )
    point = _enclose(system, controller, repeat, frame, centre, None)
    if bool(box.outside[0]) or bool(point.outside[0]):
        return False, math.inf
    contraction = float(_spectral_upper(box.jac_mid)[0] + _spectral_upper(box.jac_rad)[0])
    room = 1.0 - frame.error - contraction
    if room <= 0.0:
        return False, math.inf
    offset = float(torch.linalg.vector_norm(point.mid.abs() + point.rad))
    return True, offset / room


def _tightened(
    system: System, controller: Controller, repeat: int, frame: _Frame, half_width: float, epsilon
) -> float:
    """A smaller epsilon, where the loop is no exact fixed point: the argument on the ball of
    radius ``epsilon`` (its own contraction is smaller) proves the decrease on (epsilon', epsilon],
    which joins (epsilon, s]; repeated while epsilon at least halves."""
    radius = half_width
    for _ in range(INNER_BISECTIONS):
        if not 0.0 < epsilon < radius:
            break
        works, value = _inner_contraction(system, controller, repeat, frame, epsilon)
        if not works or not value < TIGHTEN_FACTOR * epsilon:
            break
        radius, epsilon = epsilon, value
    return epsilon


def _inner_level(
    system: System, controller: Controller, repeat: int, frame: _Frame, target_radius: float
) -> tuple[float, float]:
    """Largest half-width s (by bisection) of the inner-ball argument, and its epsilon (made
    as small as the argument on smaller balls allows: :func:`_tightened`)."""
    low, epsilon = _largest_inner(system, controller, repeat, frame, target_radius)
    return low, _tightened(system, controller, repeat, frame, low, epsilon)


def _largest_inner(
    system: System, controller: Controller, repeat: int, frame: _Frame, target_radius: float
) -> tuple[float, float]:
    """Largest half-width s (by bisection) of the inner-ball argument whose epsilon is at most
    ``TIGHTEN_FACTOR * s`` (near the largest contracting s, epsilon = offset / room blows up as
    the room vanishes), and that epsilon (0 at an exact fixed point)."""

    def useful(half_width: float) -> tuple[bool, float]:
        works, value = _inner_contraction(system, controller, repeat, frame, half_width)
        return works and value <= TIGHTEN_FACTOR * half_width, value

    low, high, epsilon = 0.0, target_radius, math.inf
    works, value = useful(high)
    if works:
        return high, value
    for _ in range(INNER_BISECTIONS):
        middle = 0.5 * (low + high)
        works, value = useful(middle)
        if works:
            low, epsilon = middle, value
        else:
            high = middle
    return low, epsilon


def _box_bound(enclosure: _Enclosure, point: _Enclosure, centre: Tensor, radius: Tensor, error):
    """Upper bound (B,) of Delta over boxes ``centre +/- radius`` (module docstring)."""
    jac, spread = enclosure.jac_mid, enclosure.jac_rad
    f, f_rad = point.mid, point.rad
    h = radius
    delta0 = (f * f).sum(-1) - (centre * centre).sum(-1)
    g = 2.0 * (torch.einsum("bis,bi->bs", jac, f) - centre)
    jac_abs = jac.abs()
    error_first = (
        2.0 * torch.einsum("bi,bis,bs->b", f.abs(), spread, h)
        + 2.0 * torch.einsum("bi,bis,bs->b", f_rad, jac_abs + spread, h)
        + 2.0 * (f.abs() * f_rad).sum(-1)
        + (f_rad * f_rad).sum(-1)
    )
    cross = 2.0 * torch.einsum("bis,bit->bst", jac_abs, spread) + torch.einsum(
        "bis,bit->bst", spread, spread
    )
    error_second = torch.einsum("bs,bst,bt->b", h, cross, h)
    eye = torch.eye(jac.shape[-1], dtype=DTYPE)
    quadratic = jac.transpose(-1, -2) @ jac - eye
    eigenvalues, vectors, usable = _spectrum(quadratic)
    largest = eigenvalues[:, -1]
    h_square = (h * h).sum(-1)
    linear_bound = delta0 + (g.abs() * h).sum(-1) + torch.clamp(largest, min=0.0) * h_square
    coefficients = torch.einsum("bsk,bs->bk", vectors, g)
    negative = largest < 0.0
    safe = torch.where(negative.unsqueeze(-1), eigenvalues, -torch.ones_like(eigenvalues))
    peak = -0.25 * (coefficients**2 / safe).sum(-1)
    stationary = -0.5 * torch.einsum("bsk,bk->bs", vectors, coefficients / safe)
    distance = torch.clamp(stationary.abs() - h, min=0.0)
    concave_bound = delta0 + peak + largest * (distance * distance).sum(-1)
    bound = torch.where(negative, torch.minimum(linear_bound, concave_bound), linear_bound)
    outer = ((centre.abs() + h) ** 2).sum(-1)
    magnitude = (
        (f * f).sum(-1)
        + outer
        + (g.abs() * h).sum(-1)
        + peak.abs() * negative
        + (jac_abs**2).sum((-1, -2)) * h_square
    )
    total = bound + error_first + error_second + 2.0 * error * outer + BOUND_SLACK * magnitude
    return torch.where(usable, total, math.inf)


def _spectrum(quadratic: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``eigh`` of symmetric matrices (B, S, S), and which are usable (B,): a box whose
    Jacobian enclosure is not finite or beyond :data:`HUGE_ENTRY` (a learned part on intervals
    can be soundly unbounded, e.g. a relevance whose 1 + d contains 0) gets no bound (+inf:
    it fails, which is sound); so does one whose decomposition does not converge."""
    usable = torch.isfinite(quadratic).all((-1, -2)) & (quadratic.abs().amax((-1, -2)) < HUGE_ENTRY)
    safe = torch.where(usable[:, None, None], quadratic, torch.zeros_like(quadratic))
    try:
        eigenvalues, vectors = torch.linalg.eigh(safe)
    except torch.linalg.LinAlgError:  # one ill-conditioned box fails the whole batch
        eigenvalues, vectors = torch.zeros_like(safe[..., 0]), torch.zeros_like(safe)
        for row in range(safe.shape[0]):
            try:
                eigenvalues[row], vectors[row] = torch.linalg.eigh(safe[row])
            except torch.linalg.LinAlgError:
                usable[row] = False
    return eigenvalues, vectors, usable


def _levels(centre: Tensor, radius: Tensor) -> tuple[Tensor, Tensor]:
    """Smallest and largest |w|^2 over boxes."""
    nearest = torch.clamp(centre.abs() - radius, min=0.0)
    farthest = centre.abs() + radius
    return (nearest * nearest).sum(-1), (farthest * farthest).sum(-1)


def _initial_cover(size: int, radius: float) -> tuple[Tensor, Tensor]:
    count = INITIAL_BOXES_PER_AXIS.get(size, DEFAULT_INITIAL_BOXES)
    width = radius / count
    axis = torch.linspace(-radius + width, radius - width, count, dtype=DTYPE)
    mesh = torch.stack(torch.meshgrid(*([axis] * size), indexing="ij"), dim=-1).reshape(-1, size)
    return mesh, torch.full_like(mesh, width)


def _split(centre: Tensor, radius: Tensor) -> tuple[Tensor, Tensor]:
    """Bisect each box along its widest side: (2B, S) children."""
    widest = radius.argmax(-1, keepdim=True)
    half = radius.clone()
    half.scatter_(-1, widest, radius.gather(-1, widest) * 0.5)
    shift = torch.zeros_like(radius)
    shift.scatter_(-1, widest, half.gather(-1, widest))
    return torch.cat([centre - shift, centre + shift]), torch.cat([half, half])


class _Budget(NamedTuple):
    """Limits of the box search: evaluations, wall-clock deadline, boxes per batched call."""

    max_boxes: int
    deadline: float
    batch: int


class _Search(NamedTuple):
    level: float  # smallest unproved |w|^2 (inf: none)
    boxes: int
    unproved: int
    limited_by: str
    image_level: float = 0.0  # largest bound of V(F) over the boxes passed by their image
    inner_reach: float = 0.0  # largest |w|^2 over those boxes


class _Inner(NamedTuple):
    """The practical-stability inner set of a search: a failing box with ``|w| <= radius``
    somewhere passes if its image's V is at most ``ceiling`` (module docstring)."""

    radius: float
    ceiling: float


def _image_bound(box: _Enclosure, point: _Enclosure, h: Tensor) -> Tensor:
    """Upper bound (B,) of ``|F~(w)|^2`` (= V(F(z))) over boxes: per coordinate the smaller of
    the plain enclosure and the mean-value form ``f +/- (f_r + (|J_c| + R) h)``."""
    spread = torch.einsum("bis,bs->bi", box.jac_mid.abs() + box.jac_rad, h)
    mean_value = point.mid.abs() + point.rad + spread
    plain = box.mid.abs() + box.rad
    reach = torch.minimum(mean_value, plain)
    total = (reach * reach).sum(-1)
    return total * (1.0 + BOUND_SLACK) + BOUND_SLACK


def _annulus(
    system: System,
    controller: Controller,
    repeat: int,
    frame: _Frame,
    inner: float,
    cover: float,
    resolution: float,
    budget: _Budget,
    practical: _Inner | None = None,
) -> _Search:
    """Best-first adaptive verification of the boxes between the inner ball and the cover
    (with ``practical``, boxes near a may pass by their image instead: module docstring)."""
    centre, radius = _initial_cover(frame.factor.shape[0], cover)
    depth = torch.zeros(centre.shape[0], dtype=torch.long)
    floor = inner if practical is None else max(inner, practical.radius)
    search = _Search(math.inf, 0, 0, "target")
    while centre.shape[0]:
        nearest, farthest = _levels(centre, radius)
        keep = (nearest <= cover**2) & (farthest > inner**2) & (nearest < search.level)
        centre, radius, depth, nearest = centre[keep], radius[keep], depth[keep], nearest[keep]
        if not centre.shape[0]:
            break
        if search.boxes >= budget.max_boxes or time.perf_counter() > budget.deadline:
            level = min(search.level, float(nearest.min()))
            unproved = search.unproved + int(centre.shape[0])
            return search._replace(level=level, unproved=unproved, limited_by="budget")
        order = torch.argsort(nearest)
        take, rest = order[: budget.batch], order[budget.batch :]
        c, h, d, near = centre[take], radius[take], depth[take], nearest[take]
        failed, outside, search = _verdicts(
            system, controller, repeat, frame, c, h, practical, search
        )
        scale = torch.clamp(near.sqrt(), min=floor)
        final = failed & ((h.max(-1).values <= resolution * scale) | (d >= MAX_DEPTH))
        if bool(final.any()):
            search = _unproved(search, near, final, outside)
        again = failed & ~final
        children, halves = _split(c[again], h[again])
        centre = torch.cat([centre[rest], children])
        radius = torch.cat([radius[rest], halves])
        depth = torch.cat([depth[rest], (d[again] + 1).repeat(2)])
    return search


def _verdicts(
    system: System,
    controller: Controller,
    repeat: int,
    frame: _Frame,
    c: Tensor,
    h: Tensor,
    practical: _Inner | None,
    search: _Search,
) -> tuple[Tensor, Tensor, _Search]:
    """One batch of boxes ``c +/- h``: (failed, possibly outside) (B,) each, and the search's
    counts updated (boxes, and the inner set's image level and reach)."""
    box = _enclose(system, controller, repeat, frame, c, h)
    point = _enclose(system, controller, repeat, frame, c, None)
    outside = box.outside | point.outside
    passed = ~outside & (_box_bound(box, point, c, h, frame.error) < 0.0)
    search = search._replace(boxes=search.boxes + int(c.shape[0]))
    if practical is not None:
        nearest, farthest = _levels(c, h)
        image = _image_bound(box, point, h)
        by_image = ~outside & ~passed & (nearest <= practical.radius**2)
        by_image &= image <= practical.ceiling
        if bool(by_image.any()):
            search = search._replace(
                image_level=max(search.image_level, float(image[by_image].max())),
                inner_reach=max(search.inner_reach, float(farthest[by_image].max())),
            )
        passed = passed | by_image
    return ~passed, outside, search


def _unproved(search: _Search, near: Tensor, final: Tensor, outside: Tensor) -> _Search:
    """The search once the boxes ``final`` (failing at the resolution) count as unproved: its
    level the smallest of theirs, and what limited it there."""
    search = search._replace(unproved=search.unproved + int(final.sum()))
    level = float(near[final].min())
    if level >= search.level:
        return search
    first = int(torch.nonzero(final & (near == level))[0, 0])
    return search._replace(level=level, limited_by="region" if bool(outside[first]) else "decrease")


def prove_level(
    system: System,
    P: np.ndarray,
    controller: Controller,
    repeat: int,
    target: float,
    resolution: float | None = None,
    max_boxes: int = MAX_BOXES,
    max_seconds: float = MAX_SECONDS,
    equilibrium: np.ndarray | None = None,
    batch: int = BATCH,
    device: Any = "cpu",
) -> LevelProof:
    r"""Prove the decrease of :math:`V = |L^\top z|^2` on the largest level set it can, up to
    ``target`` (module docstring).

    Parameters
    ----------
    system : System
    P : (S, S) array
        Symmetric positive definite (checked by the caller).
    controller : callable
        Observation -> action; it must run on :class:`~leoc.control.intervals.Jet` inputs
        (linear controllers, clip, sin and tanh saturations do, and so do leoc's learned
        policies: MLP actors, RBF networks, hybrids with any relevance).
    repeat : int
        Control period (simulator steps per decision, action held).
    target : float
        Level to prove up to (e.g. the sampled estimate); 0 gives an empty proof.
    resolution : float, optional
        Relative size of the smallest boxes (default per state dimension, ``RESOLUTION``).
    max_boxes : int
        Evaluation budget.
    max_seconds : float
        Wall-clock budget of the box search; past it the pending boxes count as unproved
        (``limited_by="budget"``: the level reported is still proved, only smaller).
    equilibrium : (S,) array, optional
        Centre of V (default a): a controller's own (:func:`leoc.control.certify_controller`).
    batch : int
        Boxes per batched call; the deadline is checked between them (the level does not
        depend on it).
    device : str or torch.device
        Where the boxes are evaluated (module docstring, **Device**; :func:`check_device`).
    Returns
    -------
    LevelProof
    """
    options = (resolution, max_boxes, max_seconds, equilibrium, batch, device)
    return _run(system, P, controller, repeat, target, *options)


def prove_practical(
    system: System,
    P: np.ndarray,
    controller: Controller,
    repeat: int,
    target: float,
    inner_level: float,
    ceiling: float | None = None,
    **options: Any,
) -> LevelProof:
    """Prove practical stability of the loop about the centre (module docstring, **Practical
    stability**): ``{V <= rho}`` invariant, up to ``target``, every trajectory from it entering
    and staying in ``{V <= ultimate_level}``; for a centre that is no stable fixed point.

    Parameters
    ----------
    system, P, controller, repeat, target :
        As :func:`prove_level`.
    inner_level : float
        A box within this level of V (0: a box holding the centre) that fails the decrease
        may pass by its image.
    ceiling : float, optional
        The V its image must stay below (default and at most ``target``): a lower one bisects
        the inner boxes finer and tightens ``ultimate_level``.
    **options
        :func:`prove_level`'s ``resolution``, ``max_boxes``, ``max_seconds``, ``equilibrium``,
        ``batch``, ``device``.
    """
    practical = _practical_aims(target, inner_level, ceiling)
    return _run(system, P, controller, repeat, target, **options, practical=practical)


def _run(
    system: System,
    P: np.ndarray,
    controller: Controller,
    repeat: int,
    target: float,
    resolution: float | None = None,
    max_boxes: int = MAX_BOXES,
    max_seconds: float = MAX_SECONDS,
    equilibrium: np.ndarray | None = None,
    batch: int = BATCH,
    device: Any = "cpu",
    practical: tuple[float, float] | None = None,
) -> LevelProof:
    """:func:`prove_level` or, with ``practical`` = (inner level, ceiling),
    :func:`prove_practical`."""
    started = time.perf_counter()
    size = P.shape[0]
    fine = RESOLUTION.get(size, DEFAULT_RESOLUTION) if resolution is None else float(resolution)
    if not 0.0 < fine < 1.0:
        raise ValueError(f"resolution: expected a number in (0, 1), found {resolution!r}")
    budget = _Budget(max_boxes, started + max_seconds, int(batch))
    place = check_device(device)
    with _default_device(place):
        frame = _frame(system, P, equilibrium)
        moved = _on_device(controller, place)
        if practical is None:
            outcome = _prove(system, frame, moved, repeat, target, fine, budget)
        else:
            outcome = _prove_practical(
                system, frame, moved, repeat, target, *practical, fine, budget
            )
    return _level_proof(outcome, target, fine, time.perf_counter() - started)


def _practical_aims(
    target: float, level: float | None, ceiling: float | None
) -> tuple[float, float] | None:
    """``(inner_level, ceiling)`` of a practical proof, checked (None: an asymptotic one)."""
    if level is None:
        return None
    if not 0.0 <= level < math.inf:
        raise ValueError(f"inner_level: expected a non-negative finite level, found {level!r}")
    return level, target if ceiling is None else ceiling


def _level_proof(outcome: _Outcome, target: float, fine: float, seconds: float) -> LevelProof:
    search = outcome.search
    return LevelProof(
        outcome.rho,
        target,
        outcome.inner_level,
        outcome.excluded,
        search.boxes,
        search.unproved,
        search.limited_by,
        fine,
        seconds,
        outcome.reason,
        outcome.claim,
        outcome.ultimate if outcome.rho > 0.0 else 0.0,
    )


class _Outcome(NamedTuple):
    rho: float
    inner_level: float
    excluded: float
    search: _Search
    reason: str
    claim: str = "asymptotic"
    ultimate: float = 0.0


_NO_SEARCH = _Search(math.inf, 0, 0, "target")
"""No box searched (the proof stopped before the annulus)."""


def _prove(
    system: System,
    frame: _Frame,
    controller: Controller,
    repeat: int,
    target: float,
    fine: float,
    budget: _Budget,
) -> _Outcome:
    """:func:`prove_level` past its checks: the inner ball by the rigorous linearisation, then
    the annulus of boxes out to ``target``."""
    if not target > 0.0:
        return _Outcome(0.0, 0.0, 0.0, _NO_SEARCH, "no target level (the sampled estimate is 0)")
    shrink = (1.0 - frame.error) ** 2
    cover = math.sqrt(target) / (1.0 - frame.error)
    with torch.no_grad():
        try:
            half_width, epsilon = _inner_level(system, controller, repeat, frame, cover)
            inner_level, excluded = min(target, shrink * half_width**2), epsilon**2
            if half_width <= 0.0:
                failed = _NO_SEARCH._replace(limited_by="decrease")
                return _Outcome(0.0, 0.0, 0.0, failed, NO_BALL)
            search = _annulus(system, controller, repeat, frame, half_width, cover, fine, budget)
        except UnsupportedOperation as error:
            unsupported = _NO_SEARCH._replace(limited_by="unsupported")
            return _Outcome(0.0, 0.0, 0.0, unsupported, str(error))
    level = min(search.level, cover**2)
    # The inner ball is proved on its own; neither claim goes past the target.
    rho = min(target, max(shrink * level * (1.0 - LEVEL_MARGIN), inner_level))
    reason = (
        f"decrease proved on {excluded:.3g} < V <= {rho:.6g} ({search.boxes} boxes); "
        f"limited by {search.limited_by}"
    )
    return _Outcome(rho, inner_level, excluded, search, reason, "asymptotic", excluded)


def _prove_practical(
    system: System,
    frame: _Frame,
    controller: Controller,
    repeat: int,
    target: float,
    practical_level: float,
    ceiling: float,
    fine: float,
    budget: _Budget,
) -> _Outcome:
    """:func:`prove_level`'s practical-stability claim: every box out to ``target`` decreases
    V or, within ``practical_level`` of it, maps into ``{V <= min(ceiling, target)}``; the
    level proved is kept only if it holds the inner set's image (module docstring)."""
    if not target > 0.0:
        reason = "no target level (no sampled gap between an inner set and the violations)"
        return _Outcome(0.0, 0.0, 0.0, _NO_SEARCH._replace(limited_by=NO_GAP), reason, "practical")
    shrink, grow = (1.0 - frame.error) ** 2, (1.0 + frame.error) ** 2
    cover = math.sqrt(target) / (1.0 - frame.error)
    inner = _Inner(math.sqrt(practical_level) / (1.0 - frame.error), min(ceiling, target))
    with torch.no_grad():
        try:
            search = _annulus(system, controller, repeat, frame, 0.0, cover, fine, budget, inner)
        except UnsupportedOperation as error:
            unsupported = _NO_SEARCH._replace(limited_by="unsupported")
            return _Outcome(0.0, 0.0, 0.0, unsupported, str(error), "practical")
    rho = min(target, shrink * min(search.level, cover**2) * (1.0 - LEVEL_MARGIN))
    excluded = grow * search.inner_reach
    ultimate = max(excluded, search.image_level)
    if search.image_level > rho:
        failed = search._replace(limited_by=INNER_IMAGE)
        reason = (
            f"the inner set's image reaches V = {search.image_level:.6g}, past the level "
            f"{rho:.6g} proved outside it (limited there by {search.limited_by})"
        )
        return _Outcome(0.0, 0.0, excluded, failed, reason, "practical")
    reason = (
        f"{{V <= {rho:.6g}}} invariant, every trajectory from it enters and stays in "
        f"{{V <= {ultimate:.3g}}} ({search.boxes} boxes); limited by {search.limited_by}"
    )
    return _Outcome(rho, 0.0, excluded, search, reason, "practical", ultimate)
