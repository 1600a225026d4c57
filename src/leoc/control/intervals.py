r"""Interval arithmetic with first-order interval derivatives (interval jets), in batched torch.

A :class:`Jet` encloses, over a box of inputs :math:`\xi \in [c - h, c + h] \subset
\mathbb{R}^S`, both the range of a quantity :math:`q(\xi)` and the range of its gradient
:math:`\nabla_\xi q`, in midpoint-radius form:

.. math::

    q(\xi) \in [m - r,\ m + r], \qquad \frac{\partial q}{\partial \xi_s}(\xi)
    \in [m'_s - r'_s,\ m'_s + r'_s] \quad \text{for every } \xi \text{ in the box.}

The existing pure torch step functions, observation maps, linear controllers and the learned
parts leoc trains (MLP actors, PILCO's RBF network, the relevances and saturations of
:mod:`leoc.policies`) run on jets unchanged: arithmetic operators are overloaded and the torch
functions they call (``sin``, ``cos``, ``tanh``, ``exp``, ``atan2``, ``remainder``, ``pow``,
``relu``, ``clamp``, ``minimum``, ``maximum``, ``abs``, ``sum``, ``stack``, ``matmul``,
``nn.functional.linear``, ``nn.functional.relu``) are dispatched through
``__torch_function__``. Any other torch function raises :class:`UnsupportedOperation`, so a
proof never silently uses an unsound enclosure. (``torch.where`` is deliberately absent: its
condition would come from the "possibly" comparisons below, and selecting by a "possibly"
is not sound.)

Rules (Moore, Kearfott and Cloud 2009, ch. 2-5; Rump 1999 for the midpoint-radius form):
products :math:`m = m_a m_b`, :math:`r = |m_a| r_b + r_a |m_b| + r_a r_b`; ``sin`` and ``cos``
by the addition theorem, :math:`|\sin(m + t) - \sin m| \le |\sin m| \min(t^2/2, 2) + |\cos m|
\min(|t|, 1)`; monotone functions by their endpoints (``exp``, ``tanh``, reciprocal,
:math:`x^p` for real :math:`p \ge 1` on :math:`x \ge 0`, ``relu`` and ``clamp``), with the
slopes :math:`\exp' = \exp`, :math:`\tanh' = 1/\cosh^2` (at the point of the interval nearest
0 and at the farthest end), :math:`(x^p)' = p x^{p-1}`; ``atan2(y, x)`` over a box that misses
its branch cut :math:`\{x \le 0, y = 0\}` by the hull of its four corners (the angle of a
convex set that misses the origin is extreme at a vertex), with the gradient
:math:`(x y' - y x') / (x^2 + y^2)` in interval arithmetic; a box that meets the cut gets
:math:`[-\pi, \pi]` and an unbounded derivative; ``remainder`` by a positive constant
:math:`m` is the shift :math:`x - k m` where the box stays in one period and :math:`[0, m]`
with an unbounded derivative where it crosses a jump; :func:`smootherstep` (the ROA
relevance's quintic) by its monotonicity; derivatives by the chain rule on intervals.
``clamp``, ``relu``, ``minimum``, ``maximum`` and ``abs`` are not differentiable at their kinks:
where an interval straddles a kink the derivative enclosure is the hull of both one-sided
derivatives (ReLU's slope is :math:`[0, 1]` there; the hull contains Clarke's generalised
gradient, which is what the mean-value form of a piecewise smooth map needs). An unbounded
derivative (a jump) or an overflow gives an infinite radius, which every proof rejects
(:mod:`leoc.control.proof` fails a box whose enclosure is not finite).

Rounding: every result's radius is widened by ``ROUNDING`` (four units of roundoff) relative
to its midpoint and radius, plus the smallest subnormal number. That covers the at most half-ulp
error of IEEE 754 ``+ - * /`` (correctly rounded) and the at most one-ulp error of the
platform's ``sin`` and ``cos``, so the enclosures hold for the exact real-number functions, not
only for the floating-point evaluation (emulated outward rounding; the one assumption is libm's
documented accuracy). The rules for ``exp``, ``tanh``, ``atan2`` and ``pow`` allow each libm
call a further ``LIBM_ERROR`` (four ulps, above the measured maximum errors of glibc's double
functions, Zimmermann 2021) and evaluate it at the ends of the enclosure rounded outward
(``nextafter``), which matters for ``exp``, whose relative condition number is :math:`|x|`.
Off the CPU (CUDA: the NVIDIA CUDA C++ Programming Guide's table of double-precision
functions documents 2 ulps for ``sin``, ``cos``, ``atan2`` and ``pow``, 1 for ``exp`` and
``tanh``) ``sin`` and ``cos`` get the same further ``LIBM_ERROR``; the other rules' four ulps
already cover those bounds.
Matrix products and sums of :math:`n` terms add the standard bound :math:`\gamma_n |x|\,|M|`
(:math:`\gamma_n |x|` for sums) with :math:`\gamma_n = n u / (1 - n u)` (Higham 2002, sec.
3.1 and 3.5; any order of summation, blocked or pairwise), and divide the accumulated radius by
:math:`1 - \gamma_n`, as its own computation is a sum of :math:`n` non-negative terms.

Comparisons (``<``, ``>``, ``<=``, ``>=``) answer "possibly": ``jet > c`` is true where some
value in the enclosure exceeds ``c``. A region predicate such as ``System.out_of_bounds``
built from such comparisons joined by ``|`` and ``&`` (no negation) then answers "possibly out
of bounds", which is the conservative direction for a proof.

Letters: B batch (boxes), S input dimension (the box's), ``...`` any value shape.

References
----------
- Moore, R. E., Kearfott, R. B. and Cloud, M. J., *Introduction to Interval Analysis*, SIAM
  2009.
- Rump, S. M., "Fast and parallel interval arithmetic", BIT 39(3), 1999.
- Higham, N. J., *Accuracy and Stability of Numerical Algorithms*, 2nd ed., SIAM 2002.
- Zimmermann, P., "Accuracy of mathematical functions in single, double, double extended, and
  quadruple precision", HAL hal-03141101, 2021.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import torch
from torch import Tensor

__all__ = [
    "QUADRATIC_CORNER_DIM",
    "SMOOTHERSTEP",
    "Jet",
    "UnsupportedOperation",
    "box_corners",
    "box_jet",
    "corner_quadratic_high",
    "exact_rows",
    "pinned_rows",
    "point_jet",
    "quadratic_form",
    "smootherstep",
    "with_rows",
]

UNIT_ROUNDOFF = 2.0**-53
ROUNDING = 4.0 * UNIT_ROUNDOFF
"""Relative widening of every computed radius and midpoint (emulated outward rounding)."""
TINY = 2.0**-1074
"""Smallest subnormal double: the absolute error of a rounding that underflows."""
LIBM_ERROR = 8.0 * UNIT_ROUNDOFF
"""Relative error allowed to one call of the platform's ``exp``, ``tanh``, ``cosh``, ``atan2``
or ``pow`` (four units in the last place), on top of ``ROUNDING``."""
LIBM_TINY = 4.0 * TINY
"""Absolute error allowed to a libm result that underflows into the subnormal range."""


class UnsupportedOperation(TypeError):
    """A torch function or operand that the interval evaluator has no sound rule for."""


def _holds(shape: torch.Size, *others: torch.Size) -> bool:
    """Whether a tensor of ``shape`` holds the broadcast of itself with ``others`` (an
    in-place result fits); equal shapes are answered without torch's broadcasting."""
    if all(other == shape for other in others):
        return True
    return torch.broadcast_shapes(shape, *others) == shape


def _fills(shape: torch.Size, first: torch.Size, second: torch.Size) -> bool:
    """Whether the broadcast of ``first`` and ``second`` is exactly ``shape``."""
    if first == shape:
        return _holds(shape, second)
    if second == shape:
        return _holds(shape, first)
    return torch.broadcast_shapes(first, second) == shape


def _widen(mid: Tensor, rad: Tensor, fresh: bool = False) -> Tensor:
    """``rad (1 + ROUNDING) + ROUNDING |mid| + TINY``: the radius widened for the rounding of
    a result with midpoint ``mid``. ``fresh``: ``rad`` is a temporary that nothing else holds,
    and is overwritten (same operations in the same order, so the same bits, without the
    temporaries of the large gradient enclosures that dominate a proof's time on the CPU)."""
    if not _holds(rad.shape, mid.shape):
        return rad * (1.0 + ROUNDING) + ROUNDING * mid.abs() + TINY
    rad = rad.mul_(1.0 + ROUNDING) if fresh else rad * (1.0 + ROUNDING)
    return rad.add_(mid.abs().mul_(ROUNDING)).add_(TINY)


def _mul_rad(am: Tensor, ar: Tensor, bm: Tensor, br: Tensor) -> Tensor:
    """Radius ``|am| br + ar |bm| + ar br`` of a product (before rounding)."""
    first = am.abs() * br
    if not _holds(first.shape, ar.shape, bm.shape):
        return first + ar * bm.abs() + ar * br
    second = bm.abs()
    if second.shape != first.shape:
        second = second.expand(first.shape).clone()
    first.add_(second.mul_(ar))
    if not _fills(second.shape, ar.shape, br.shape):
        return first.add_(ar * br)
    return first.add_(torch.mul(ar, br, out=second))


def _plus_scaled_abs(rad: Tensor, mid: Tensor, factor: float) -> Tensor:
    """``rad + factor |mid|`` as a fresh tensor (the midpoint's rounding added to a radius)."""
    scaled = mid.abs().mul_(factor)
    if not _holds(scaled.shape, rad.shape):
        return rad + scaled
    return scaled.add_(rad)


def _hull_with_zero(mid: Tensor, rad: Tensor) -> tuple[Tensor, Tensor]:
    low = torch.clamp(mid - rad, max=0.0)
    high = torch.clamp(mid + rad, min=0.0)
    return 0.5 * (low + high), 0.5 * (high - low)


def _last_dim(dim: int, ndim: int) -> int:
    """A value dimension as a dimension of the derivative (one trailing dimension more)."""
    return dim - 1 if dim < 0 else dim


def _gamma(count: int) -> float:
    r""":math:`\gamma_n = n u / (1 - n u)`, the relative error bound of a sum of n products."""
    return count * UNIT_ROUNDOFF / (1.0 - count * UNIT_ROUNDOFF)


def _accumulated(radius_sum: Tensor, magnitude_sum: Tensor, gamma: float) -> Tensor:
    r"""Radius of a computed sum: the summed radii plus :math:`\gamma_n` times the summed
    magnitudes (the midpoint's rounding), over :math:`1 - \gamma_n` (both sums are computed
    sums of non-negative terms, which can fall short by that factor)."""
    return (radius_sum + gamma * magnitude_sum) / (1.0 - gamma)


def _outer_ends(x: Jet) -> tuple[Tensor, Tensor]:
    """Ends of the enclosure rounded outward: below :math:`m - r` and above :math:`m + r` in
    exact arithmetic (one ``nextafter`` past a correctly rounded difference or sum)."""
    low, high = x.mid - x.rad, x.mid + x.rad
    return (
        torch.nextafter(low, torch.full_like(low, -math.inf)),
        torch.nextafter(high, torch.full_like(high, math.inf)),
    )


def _enclose_ends(low: Tensor, high: Tensor, relative: float) -> tuple[Tensor, Tensor]:
    """Midpoint and radius of ``[low, high]``, ends computed with at most ``relative`` error
    (plus ``LIBM_TINY`` where they underflow); an infinite or NaN end gives the whole line."""
    mid = 0.5 * (low + high)
    half = 0.5 * (high - low)
    rad = _widen(mid, half + relative * (mid.abs() + half) + LIBM_TINY)
    bad = ~(torch.isfinite(mid) & torch.isfinite(rad))
    return torch.where(bad, 0.0, mid), torch.where(bad, math.inf, rad)


class Jet:
    """Enclosure of a quantity and of its gradient over a box (module docstring).

    Parameters
    ----------
    mid, rad : Tensor (...,)
        Midpoint and radius (>= 0) of the value.
    dmid, drad : Tensor (..., S) or None
        Midpoint and radius of the gradient with respect to the box's S inputs; None for a
        quantity that does not depend on them (a constant).
    """

    __slots__ = ("mid", "rad", "dmid", "drad")

    def __init__(self, mid: Tensor, rad: Tensor, dmid: Tensor | None, drad: Tensor | None):
        if dmid is not None and drad is not None and dmid.shape[:-1] != mid.shape:
            # a gradient broadcast along some value dimensions (a constant's) is held at the
            # value's full shape (a view), so that indexing and sums see one gradient per value
            shape = (*mid.shape, dmid.shape[-1])
            dmid, drad = dmid.expand(shape), drad.expand(shape)
        self.mid, self.rad, self.dmid, self.drad = mid, rad, dmid, drad

    # ---- shape-like attributes, so shape checks of step functions pass ----------------------
    @property
    def shape(self) -> torch.Size:
        return self.mid.shape

    @property
    def dtype(self) -> torch.dtype:
        return self.mid.dtype

    @property
    def ndim(self) -> int:
        return self.mid.ndim

    def dim(self) -> int:
        return self.mid.ndim

    @property
    def device(self) -> torch.device:
        """Device of the enclosure's tensors."""
        return self.mid.device

    @property
    def low(self) -> Tensor:
        """Lower end of the value enclosure."""
        return self.mid - self.rad

    @property
    def high(self) -> Tensor:
        """Upper end of the value enclosure."""
        return self.mid + self.rad

    def __repr__(self) -> str:
        return f"Jet(shape={tuple(self.shape)}, derivative={self.dmid is not None})"

    # ---- structure -------------------------------------------------------------------------
    def _map_structure(self, value: Callable[[Tensor], Tensor], grad: Callable[[Tensor], Tensor]):
        dmid = None if self.dmid is None else grad(self.dmid)
        drad = None if self.drad is None else grad(self.drad)
        return Jet(value(self.mid), value(self.rad), dmid, drad)

    def __getitem__(self, index: Any) -> Jet:
        key = index if isinstance(index, tuple) else (index,)
        grad_key = (*key, slice(None)) if Ellipsis in key else key
        return self._map_structure(lambda t: t[key], lambda t: t[grad_key])

    def unbind(self, dim: int = 0) -> tuple[Jet, ...]:
        count = self.shape[dim]
        return tuple(self.select(dim, index) for index in range(count))

    def select(self, dim: int, index: int) -> Jet:
        gdim = _last_dim(dim, self.ndim)
        return self._map_structure(lambda t: t.select(dim, index), lambda t: t.select(gdim, index))

    def reshape(self, *shape: Any) -> Jet:
        size = tuple(shape[0]) if len(shape) == 1 and isinstance(shape[0], Sequence) else shape
        mid = self.mid.reshape(*size)
        return self._map_structure(
            lambda t: t.reshape(mid.shape), lambda t: t.reshape(*mid.shape, t.shape[-1])
        )

    def unsqueeze(self, dim: int) -> Jet:
        gdim = _last_dim(dim, self.ndim)
        return self._map_structure(lambda t: t.unsqueeze(dim), lambda t: t.unsqueeze(gdim))

    # ---- arithmetic ------------------------------------------------------------------------
    def __neg__(self) -> Jet:
        # Negation flips the midpoints only; radii stay as they are.
        dmid = None if self.dmid is None else -self.dmid
        return Jet(-self.mid, self.rad, dmid, self.drad)

    def __add__(self, other: Any) -> Jet:
        other = as_jet(other, self)
        mid = self.mid + other.mid
        rad = _widen(mid, self.rad + other.rad)
        dmid, drad = _add_grads(self, other)
        return Jet(mid, rad, dmid, drad)

    __radd__ = __add__

    def __sub__(self, other: Any) -> Jet:
        return self + (-as_jet(other, self))

    def __rsub__(self, other: Any) -> Jet:
        return as_jet(other, self) + (-self)

    def __mul__(self, other: Any) -> Jet:
        other = as_jet(other, self)
        mid = self.mid * other.mid
        rad = _widen(mid, _mul_rad(self.mid, self.rad, other.mid, other.rad))
        terms = []
        if other.dmid is not None:
            terms.append(_scale_grad(self, other.dmid, other.drad))
        if self.dmid is not None:
            terms.append(_scale_grad(other, self.dmid, self.drad))
        return Jet(mid, rad, *_sum_grads(terms))

    __rmul__ = __mul__

    def __truediv__(self, other: Any) -> Jet:
        return self * as_jet(other, self).reciprocal()

    def __rtruediv__(self, other: Any) -> Jet:
        return as_jet(other, self) * self.reciprocal()

    def __pow__(self, exponent: Any) -> Jet:
        number = isinstance(exponent, (int, float)) and not isinstance(exponent, bool)
        if not number or not exponent >= 1 or not math.isfinite(exponent):
            raise UnsupportedOperation(
                f"Jet ** {exponent!r}: only real exponents >= 1 are supported"
            )
        if not float(exponent).is_integer():
            return _real_power(self, float(exponent))
        if exponent == 2:
            return self.square()
        result = self
        for _ in range(int(exponent) - 1):
            result = result * self
        return result

    def pow(self, exponent: Any) -> Jet:
        """``self ** exponent`` for a real exponent >= 1 (``Tensor.pow``)."""
        return self**exponent

    def sum(self, dim: Any = None, keepdim: bool = False) -> Jet:
        """Sum over ``dim`` (an int, a tuple of ints or None for all), as ``Tensor.sum``."""
        return _sum(self, dim, keepdim)

    def square(self) -> Jet:
        """x^2 with the exact range (no dependency between the two factors)."""
        magnitude = self.mid.abs()
        high = (magnitude + self.rad) ** 2
        low = torch.clamp(magnitude - self.rad, min=0.0) ** 2
        mid, rad = 0.5 * (low + high), 0.5 * (high - low)
        grad = None
        if self.dmid is not None:
            twice = Jet(2.0 * self.mid, 2.0 * self.rad, None, None)
            grad = _scale_grad(twice, self.dmid, self.drad)
        return Jet(mid, _widen(mid, rad), *(grad or (None, None)))

    def reciprocal(self) -> Jet:
        """1 / x; an enclosure containing 0 gives an infinite radius (fails any proof)."""
        low, high = self.mid - self.rad, self.mid + self.rad
        safe = (low > 0.0) | (high < 0.0)
        inv_low = torch.where(safe, 1.0 / high, torch.full_like(low, -math.inf))
        inv_high = torch.where(safe, 1.0 / low, torch.full_like(low, math.inf))
        mid = torch.where(safe, 0.5 * (inv_low + inv_high), torch.zeros_like(low))
        rad = torch.where(safe, 0.5 * (inv_high - inv_low), torch.full_like(low, math.inf))
        result = Jet(mid, _widen(mid, rad), None, None)
        if self.dmid is None:
            return result
        minus_square = -result.square()
        return Jet(result.mid, result.rad, *_scale_grad(minus_square, self.dmid, self.drad))

    # ---- comparisons: "possibly" -----------------------------------------------------------
    def __lt__(self, other: Any) -> Tensor:
        return self.low < _upper(other)

    def __le__(self, other: Any) -> Tensor:
        return self.low <= _upper(other)

    def __gt__(self, other: Any) -> Tensor:
        return self.high > _lower(other)

    def __ge__(self, other: Any) -> Tensor:
        return self.high >= _lower(other)

    # ---- linear algebra --------------------------------------------------------------------
    def __matmul__(self, matrix: Any) -> Jet:
        if isinstance(matrix, Jet):
            raise UnsupportedOperation("Jet @ Jet: only products with constant matrices")
        return _matmul_right(self, torch.as_tensor(matrix, dtype=self.dtype))

    def __rmatmul__(self, matrix: Any) -> Jet:
        raise UnsupportedOperation("constant @ Jet: write the product as Jet @ matrix.T")

    # ---- torch functions -------------------------------------------------------------------
    @classmethod
    def __torch_function__(cls, func, types, args=(), kwargs=None):  # noqa: ANN001
        kwargs = kwargs or {}
        rule = _RULES.get(func)
        if rule is None:
            name = getattr(func, "__name__", repr(func))
            raise UnsupportedOperation(f"torch.{name} has no interval rule")
        return rule(*args, **kwargs)


def as_jet(value: Any, like: Jet) -> Jet:
    """A jet of ``value`` (a jet, a number or a constant tensor) for arithmetic with ``like``."""
    if isinstance(value, Jet):
        return value
    if isinstance(value, bool) or (isinstance(value, Tensor) and value.dtype == torch.bool):
        raise UnsupportedOperation("boolean operands have no interval rule")
    tensor = torch.as_tensor(value, dtype=like.dtype)
    return Jet(tensor, torch.zeros_like(tensor), None, None)


def _upper(value: Any) -> Any:
    return value.high if isinstance(value, Jet) else value


def _lower(value: Any) -> Any:
    return value.low if isinstance(value, Jet) else value


def _scale_grad(factor: Jet, dmid: Tensor, drad: Tensor) -> tuple[Tensor, Tensor]:
    """Interval product of a value enclosure (...,) with a gradient enclosure (..., S)."""
    fm, fr = factor.mid.unsqueeze(-1), factor.rad.unsqueeze(-1)
    mid = fm * dmid
    return mid, _widen(mid, _mul_rad(fm, fr, dmid, drad), fresh=True)


def _sum_grads(terms: list[tuple[Tensor, Tensor]]) -> tuple[Tensor | None, Tensor | None]:
    if not terms:
        return None, None
    mid, rad = terms[0]
    for other_mid, other_rad in terms[1:]:
        mid = mid + other_mid
        rad = _widen(mid, rad + other_rad, fresh=True)
    return mid, rad


def _add_grads(first: Jet, second: Jet) -> tuple[Tensor | None, Tensor | None]:
    terms = [(jet.dmid, jet.drad) for jet in (first, second) if jet.dmid is not None]  # type: ignore[misc]
    return _combine(terms)  # type: ignore[arg-type]


def _combine(terms: list[tuple[Tensor, Tensor]]) -> tuple[Tensor | None, Tensor | None]:
    """Sum of gradient enclosures, broadcast to one shape."""
    if len(terms) > 1:
        shape = torch.broadcast_shapes(*(mid.shape for mid, _ in terms))
        terms = [(m.expand(shape), r.expand(shape)) for m, r in terms]
    return _sum_grads(terms)


def _from_ends(low: Tensor, high: Tensor) -> tuple[Tensor, Tensor]:
    mid = 0.5 * (low + high)
    return mid, _widen(mid, 0.5 * (high - low))


def _chain(result_mid: Tensor, result_rad: Tensor, slope: Jet, inner: Jet) -> Jet:
    """The value enclosure with the derivative ``slope * inner'`` (chain rule)."""
    if inner.dmid is None:
        return Jet(result_mid, result_rad, None, None)
    return Jet(result_mid, result_rad, *_scale_grad(slope, inner.dmid, inner.drad))


def _sin(x: Jet) -> Jet:
    mid = torch.sin(x.mid)
    rad = _sin_cos_rad(mid, torch.cos(x.mid), x.rad)
    slope = _cos_value(x)
    return _chain(mid, rad, slope, x)


def _cos(x: Jet) -> Jet:
    mid = torch.cos(x.mid)
    rad = _sin_cos_rad(mid, torch.sin(x.mid), x.rad)
    slope = -_sin_value(x)
    return _chain(mid, rad, slope, x)


def _sin_cos_rad(same: Tensor, other: Tensor, rad: Tensor) -> Tensor:
    """Radius of sin (or cos) over m +/- r by the addition theorem (module docstring); off the
    CPU each of the two libm values gets a further ``LIBM_ERROR``."""
    half_square = torch.clamp(0.5 * rad**2, max=2.0)
    spread = same.abs() * half_square + other.abs() * torch.clamp(rad, max=1.0)
    if same.device.type != "cpu":
        spread = spread + LIBM_ERROR * (same.abs() + other.abs() * torch.clamp(rad, max=1.0))
    return _widen(same, spread)


def _sin_value(x: Jet) -> Jet:
    mid = torch.sin(x.mid)
    return Jet(mid, _sin_cos_rad(mid, torch.cos(x.mid), x.rad), None, None)


def _cos_value(x: Jet) -> Jet:
    mid = torch.cos(x.mid)
    return Jet(mid, _sin_cos_rad(mid, torch.sin(x.mid), x.rad), None, None)


def _tanh(x: Jet) -> Jet:
    low, high = _outer_ends(x)
    mid, rad = _enclose_ends(torch.tanh(low), torch.tanh(high), LIBM_ERROR)
    # tanh' = 1 / cosh^2 (not 1 - tanh^2, which cancels where tanh is near 1): largest at the
    # point of the interval nearest 0, smallest at the farthest end
    straddles = (low <= 0.0) & (high >= 0.0)
    nearest = torch.where(straddles, 0.0, torch.minimum(low.abs(), high.abs()))
    farthest = torch.maximum(low.abs(), high.abs())
    slope_low = torch.cosh(farthest).reciprocal().square()
    slope_high = torch.cosh(nearest).reciprocal().square()
    slope = _enclose_ends(slope_low, slope_high, SECH_SQUARE_ERROR)
    return _chain(mid, rad, Jet(*slope, None, None), x)


SECH_SQUARE_ERROR = 2.0 * LIBM_ERROR + 4.0 * UNIT_ROUNDOFF
r"""Relative error of :math:`(1 / \cosh t)^2` computed with one ``cosh`` call."""


def _exp(x: Jet) -> Jet:
    low, high = _outer_ends(x)
    mid, rad = _enclose_ends(torch.exp(low), torch.exp(high), LIBM_ERROR)
    # exp' = exp: the slope's enclosure is the value's
    return _chain(mid, rad, Jet(mid, rad, None, None), x)


def _relu(x: Jet, inplace: bool = False) -> Jet:
    if inplace:
        raise UnsupportedOperation("relu(inplace=True): a jet cannot be changed in place")
    return _clamp(x, min=0.0)


def _real_power(x: Jet, exponent: float) -> Jet:
    r""":math:`x^p` for a real :math:`p > 1` on its domain :math:`x \ge 0` (torch gives NaN
    below 0): increasing, as is its slope :math:`p x^{p-1}`."""
    low, high = _outer_ends(x)
    low = torch.clamp(low, min=0.0)
    mid, rad = _enclose_ends(torch.pow(low, exponent), torch.pow(high, exponent), LIBM_ERROR)
    slope = _enclose_ends(
        exponent * torch.pow(low, exponent - 1.0),
        exponent * torch.pow(high, exponent - 1.0),
        LIBM_ERROR + 2.0 * UNIT_ROUNDOFF,
    )
    return _chain(mid, rad, Jet(*slope, None, None), x)


def _pow(base: Any, exponent: Any) -> Jet:
    if not isinstance(base, Jet) or isinstance(exponent, (Jet, Tensor)):
        raise UnsupportedOperation("pow: only Jet ** number has an interval rule")
    return base**exponent


def _sum(x: Jet, dim: Any = None, keepdim: bool = False, *, dtype: Any = None) -> Jet:
    if dtype is not None and dtype != x.dtype:
        raise UnsupportedOperation(f"sum(dtype={dtype}): only the jet's own dtype {x.dtype}")
    if x.ndim == 0:
        return x
    dims = range(x.ndim) if dim is None else (dim,) if isinstance(dim, int) else dim
    dims = tuple(sorted({int(d) % x.ndim for d in dims}))
    gamma = _gamma(math.prod(x.shape[d] for d in dims))
    mid = x.mid.sum(dims, keepdim=keepdim)
    spread = _accumulated(
        x.rad.sum(dims, keepdim=keepdim), x.mid.abs().sum(dims, keepdim=keepdim), gamma
    )
    if x.dmid is None:
        return Jet(mid, _widen(mid, spread), None, None)
    # the value dimensions keep their (non-negative) indices in the gradient
    dmid = x.dmid.sum(dims, keepdim=keepdim)
    dspread = _accumulated(
        x.drad.sum(dims, keepdim=keepdim), x.dmid.abs().sum(dims, keepdim=keepdim), gamma
    )
    return Jet(mid, _widen(mid, spread), dmid, _widen(dmid, dspread))


def _clamp(x: Any, min: Any = None, max: Any = None) -> Jet:  # noqa: A002
    jet = x if isinstance(x, Jet) else as_jet(x, min if isinstance(min, Jet) else max)
    if isinstance(min, Jet) or isinstance(max, Jet):
        raise UnsupportedOperation("clamp with interval bounds has no interval rule")
    low, high = jet.low, jet.high
    # which side of a kink the box lies on is decided on the ends rounded outward
    outer_low, outer_high = _outer_ends(jet)
    below = torch.zeros_like(low, dtype=torch.bool)
    above = torch.zeros_like(low, dtype=torch.bool)
    inside = torch.ones_like(low, dtype=torch.bool)
    if min is not None:
        bound = torch.as_tensor(min, dtype=jet.dtype)
        low, high = torch.maximum(low, bound), torch.maximum(high, bound)
        below = outer_high <= bound
        inside = inside & (outer_low > bound)
    if max is not None:
        bound = torch.as_tensor(max, dtype=jet.dtype)
        low, high = torch.minimum(low, bound), torch.minimum(high, bound)
        above = outer_low >= bound
        inside = inside & (outer_high < bound)
    mid, rad = _from_ends(low, high)
    if jet.dmid is None:
        return Jet(mid, rad, None, None)
    return Jet(mid, rad, *_kinked_grad(jet, below | above, inside))


def _kinked_grad(jet: Jet, constant: Tensor, smooth: Tensor) -> tuple[Tensor, Tensor]:
    """The gradient enclosure of a clamp (value shape masks): zero where ``constant``, the
    jet's where ``smooth``, else (the box straddles a kink) its hull with zero, computed on
    those entries only (few in small boxes)."""
    shape = (*constant.shape, jet.dmid.shape[-1])  # type: ignore[union-attr]
    # a mask of the gradient's full shape: selection by a mask broadcast along the last
    # (short) dimension is several times slower
    constant_full = constant.unsqueeze(-1).expand(shape).contiguous()
    zero = torch.zeros((), dtype=jet.dtype, device=jet.device)
    dmid = torch.where(constant_full, zero, jet.dmid)  # type: ignore[arg-type]
    drad = torch.where(constant_full, zero, jet.drad)  # type: ignore[arg-type]
    kinked = ~(constant | smooth)
    if bool(kinked.any()):
        hull_mid, hull_rad = _hull_with_zero(dmid[kinked], drad[kinked])
        dmid[kinked], drad[kinked] = hull_mid, hull_rad
    return dmid, drad


def _minimum(x: Any, y: Any) -> Jet:
    if isinstance(x, Jet) and isinstance(y, Jet):
        return _extreme(x, y, larger=False)
    jet, bound = (x, y) if isinstance(x, Jet) else (y, x)
    return _clamp(jet, max=bound)


def _maximum(x: Any, y: Any) -> Jet:
    if isinstance(x, Jet) and isinstance(y, Jet):
        return _extreme(x, y, larger=True)
    jet, bound = (x, y) if isinstance(x, Jet) else (y, x)
    return _clamp(jet, min=bound)


def _extreme(x: Jet, y: Jet, larger: bool) -> Jet:
    """max(x, y) (``larger``) or min(x, y) of two jets: the ends' max (min); the derivative
    of the operand that wins on the whole box, else the hull of both (Clarke's gradient)."""
    pick = torch.maximum if larger else torch.minimum
    mid, rad = _from_ends(pick(x.low, y.low), pick(x.high, y.high))
    if x.dmid is None and y.dmid is None:
        return Jet(mid, rad, None, None)
    (x_low, x_high), (y_low, y_high) = _outer_ends(x), _outer_ends(y)
    x_wins = (x_low > y_high) if larger else (x_high < y_low)
    y_wins = (y_low > x_high) if larger else (y_high < x_low)
    size = (x.dmid if x.dmid is not None else y.dmid).shape[-1]  # type: ignore[union-attr]
    shape = (*mid.shape, size)
    grads = [_full_grad(jet, shape) for jet in (x, y)]
    (xm, xr), (ym, yr) = grads
    hull_mid, hull_rad = _from_ends(
        torch.minimum(xm - xr, ym - yr), torch.maximum(xm + xr, ym + yr)
    )
    x_wins, y_wins = x_wins.unsqueeze(-1), y_wins.unsqueeze(-1)
    dmid = torch.where(x_wins, xm, torch.where(y_wins, ym, hull_mid))
    drad = torch.where(x_wins, xr, torch.where(y_wins, yr, hull_rad))
    return Jet(mid, rad, dmid, drad)


def _full_grad(jet: Jet, shape: tuple[int, ...]) -> tuple[Tensor, Tensor]:
    """The jet's gradient enclosure expanded to ``shape`` (zero for a constant)."""
    if jet.dmid is None or jet.drad is None:
        zero = torch.zeros(shape, dtype=jet.dtype, device=jet.device)
        return zero, zero
    return jet.dmid.expand(shape), jet.drad.expand(shape)


def _abs(x: Jet) -> Jet:
    low, high = x.low, x.high
    positive, negative = low >= 0.0, high <= 0.0
    magnitude = torch.maximum(low.abs(), high.abs())
    end_low = torch.where(positive, low, torch.where(negative, -high, torch.zeros_like(low)))
    mid, rad = _from_ends(end_low, magnitude)
    if x.dmid is None:
        return Jet(mid, rad, None, None)
    sign = torch.where(positive, 1.0, -1.0).unsqueeze(-1)
    straddles = (~positive & ~negative).unsqueeze(-1)
    spread = x.dmid.abs() + x.drad
    dmid = torch.where(straddles, 0.0, sign * x.dmid)
    drad = torch.where(straddles, spread, x.drad)
    return Jet(mid, rad, dmid, drad)


def _stack(tensors: Sequence[Any], dim: int = 0) -> Jet:
    like = next(item for item in tensors if isinstance(item, Jet))
    jets = [as_jet(item, like) for item in tensors]
    mids = [jet.mid for jet in jets]
    shape = torch.broadcast_shapes(*(m.shape for m in mids))
    width = next((jet.dmid.shape[-1] for jet in jets if jet.dmid is not None), None)
    mid = torch.stack([m.expand(shape) for m in mids], dim=dim)
    rad = torch.stack([jet.rad.expand(shape) for jet in jets], dim=dim)
    if width is None:
        return Jet(mid, rad, None, None)
    gshape = (*shape, width)
    gdim = _last_dim(dim, len(shape))

    def grad(jet: Jet, part: str) -> Tensor:
        value = getattr(jet, part)
        return torch.zeros(gshape, dtype=mid.dtype) if value is None else value.expand(gshape)

    dmid = torch.stack([grad(jet, "dmid") for jet in jets], dim=gdim)
    drad = torch.stack([grad(jet, "drad") for jet in jets], dim=gdim)
    return Jet(mid, rad, dmid, drad)


def _matmul_right(x: Jet, matrix: Tensor) -> Jet:
    """``x @ matrix`` for x (..., D) and a constant matrix (D, F), with the rounding bound."""
    if matrix.ndim == 1:  # x @ v: the product with the column v, that column dropped
        return _matmul_right(x, matrix[:, None]).select(-1, 0)
    gamma = _gamma(matrix.shape[0])
    magnitude = matrix.abs()
    mid = x.mid @ matrix
    # (r + gamma |m|) |M|, over 1 - gamma: radius and midpoint rounding (module docstring)
    spread = (_plus_scaled_abs(x.rad, x.mid, gamma) @ magnitude).div_(1.0 - gamma)
    rad = _widen(mid, spread, fresh=True)
    if x.dmid is None:
        return Jet(mid, rad, None, None)
    dmid = torch.einsum("...ds,df->...fs", x.dmid, matrix)
    dspread = torch.einsum("...ds,df->...fs", _plus_scaled_abs(x.drad, x.dmid, gamma), magnitude)
    return Jet(mid, rad, dmid, _widen(dmid, dspread.div_(1.0 - gamma), fresh=True))


def _matmul(x: Any, y: Any) -> Jet:
    if isinstance(x, Jet) and not isinstance(y, Jet):
        return _matmul_right(x, torch.as_tensor(y, dtype=x.dtype))
    raise UnsupportedOperation("matmul: only Jet @ constant matrix has an interval rule")


def _linear(x: Jet, weight: Tensor, bias: Tensor | None = None) -> Jet:
    result = _matmul_right(x, torch.as_tensor(weight, dtype=x.dtype).T)
    return result if bias is None else result + bias


def _atan2(y: Any, x: Any) -> Jet:
    """Angle of (x, y), torch's ``atan2(y, x)`` in [-pi, pi] (module docstring)."""
    y, x = _operands(y, x)
    (y_low, y_high), (x_low, x_high) = _outer_ends(y), _outer_ends(x)
    cut = (x_low <= 0.0) & (y_low <= 0.0) & (y_high >= 0.0)
    corners = torch.stack([torch.atan2(a, b) for a in (y_low, y_high) for b in (x_low, x_high)])
    mid, rad = _enclose_ends(corners.min(0).values, corners.max(0).values, LIBM_ERROR)
    # where the box meets the cut the angle jumps by 2 pi: the whole range (pi rounded up)
    mid = torch.where(cut, 0.0, mid)
    rad = torch.where(cut, _widen(torch.zeros_like(rad), torch.full_like(rad, math.pi)), rad)
    # d atan2 = (x dy - y dx) / (x^2 + y^2), on value enclosures
    x_value, y_value = Jet(x.mid, x.rad, None, None), Jet(y.mid, y.rad, None, None)
    inverse = (x_value.square() + y_value.square()).reciprocal()
    terms = []
    if y.dmid is not None:
        terms.append(_scale_grad(x_value * inverse, y.dmid, y.drad))  # type: ignore[arg-type]
    if x.dmid is not None:
        terms.append(_scale_grad(-(y_value * inverse), x.dmid, x.drad))  # type: ignore[arg-type]
    dmid, drad = _combine(terms)
    if dmid is None or drad is None:
        return Jet(mid, rad, None, None)
    return Jet(mid, rad, *_unbounded_slope(dmid, drad, cut))


def _unbounded_slope(dmid: Tensor, drad: Tensor, jumps: Tensor) -> tuple[Tensor, Tensor]:
    """The gradient enclosure, unbounded (an infinite radius) where the value ``jumps``."""
    jumps = jumps.unsqueeze(-1)
    return torch.where(jumps, 0.0, dmid), torch.where(jumps, math.inf, drad)


def _remainder(x: Any, modulus: Any) -> Jet:
    """``remainder(x, m)`` for a positive constant m: x - k m, in [0, m) (module docstring)."""
    if not isinstance(x, Jet) or isinstance(modulus, Jet):
        raise UnsupportedOperation("remainder: only remainder(Jet, constant) has an interval rule")
    period = torch.as_tensor(modulus, dtype=x.dtype)
    if period.ndim != 0 or not bool(period > 0.0):
        raise UnsupportedOperation(f"remainder: only a positive scalar modulus, found {modulus!r}")
    shift = torch.floor(x.mid / period) * period  # k m, rounded: error at most u |k m|
    shifted = x - Jet(shift, ROUNDING * shift.abs(), None, None)
    low, high = _outer_ends(shifted)
    jumps = (low < 0.0) | (high >= period)
    half = 0.5 * period
    mid = torch.where(jumps, half, shifted.mid)
    rad = torch.where(jumps, _widen(half, half), shifted.rad)
    if shifted.dmid is None or shifted.drad is None:
        return Jet(mid, rad, None, None)
    return Jet(mid, rad, *_unbounded_slope(shifted.dmid, shifted.drad, jumps))


def _operands(first: Any, second: Any) -> tuple[Jet, Jet]:
    like = first if isinstance(first, Jet) else second
    return as_jet(first, like), as_jet(second, like)


def _binary(operation: Callable[[Jet, Jet], Jet], reflected: bool = False) -> Callable:
    """A tensor operator method (``Tensor.__add__`` ...) met by a jet operand."""

    def apply(first: Any, second: Any) -> Jet:
        left, right = _operands(first, second)
        return operation(right, left) if reflected else operation(left, right)

    return apply


_RULES: dict[Any, Callable[..., Any]] = {
    torch.sin: _sin,
    torch.cos: _cos,
    torch.tanh: _tanh,
    torch.exp: _exp,
    torch.relu: _relu,
    torch.nn.functional.relu: _relu,
    torch.pow: _pow,
    torch.sum: _sum,
    torch.atan2: _atan2,
    torch.arctan2: _atan2,
    torch.remainder: _remainder,
    torch.clamp: _clamp,
    torch.clip: _clamp,
    torch.minimum: _minimum,
    torch.maximum: _maximum,
    torch.abs: _abs,
    torch.stack: _stack,
    torch.matmul: _matmul,
    torch.Tensor.__matmul__: _matmul,
    torch.nn.functional.linear: _linear,
    torch.Tensor.__add__: _binary(Jet.__add__),
    torch.Tensor.__radd__: _binary(Jet.__add__, reflected=True),
    torch.Tensor.__sub__: _binary(Jet.__sub__),
    torch.Tensor.__rsub__: _binary(Jet.__sub__, reflected=True),
    torch.Tensor.__mul__: _binary(Jet.__mul__),
    torch.Tensor.__rmul__: _binary(Jet.__mul__, reflected=True),
    torch.Tensor.__truediv__: _binary(Jet.__truediv__),
    torch.Tensor.__rtruediv__: _binary(Jet.__truediv__, reflected=True),
}


def box_jet(centre: Tensor, radius: Tensor, basis: Tensor | None = None) -> Jet:
    """Jet of the identity over the box ``centre +/- radius`` (B, S): derivative the identity.

    With ``basis`` (S, S), the jet of ``z = basis @ xi`` over the box of xi, whose gradient
    with respect to xi is ``basis`` (a linear change of coordinates, e.g. z = L^-T w).
    """
    if basis is None:
        eye = torch.eye(centre.shape[-1], dtype=centre.dtype).expand(*centre.shape, -1)
        return Jet(centre, radius, eye, torch.zeros_like(eye))
    xi = Jet(centre, radius, None, None)
    size = centre.shape[-1]
    image = _matmul_right(xi, basis.T)
    gradient = basis.expand(*centre.shape[:-1], size, size)
    # The real map xi -> basis @ xi has exactly this gradient; only its values are rounded.
    return Jet(image.mid, image.rad, gradient, torch.zeros_like(gradient))


def exact_rows(jet: Jet, value: float) -> Tensor:
    """Rows (the first dimension, B) of a (B, ...) enclosure that are exactly ``value`` with a
    zero derivative in every entry: the function is that constant on the whole box (B,)."""
    rows = jet.shape[0]
    exact = (jet.mid.reshape(rows, -1) == value).all(-1) & (jet.rad.reshape(rows, -1) == 0).all(-1)
    if jet.dmid is not None:
        exact &= (jet.dmid.reshape(rows, -1) == 0).all(-1) & (jet.drad.reshape(rows, -1) == 0).all(
            -1
        )
    return exact


def pinned_rows(jet: Jet, rows: Tensor, value: float) -> Jet:
    """``jet`` with its rows ``rows`` (B,) bool set to exactly ``value``, derivative 0: for
    boxes on which the function is known to be that constant (e.g. the ROA relevance's flat
    top, where t is exactly 0 on the box and r = 1 - S(0) = 1 in every rounding)."""
    keep = ~rows.reshape(-1, *([1] * (jet.ndim - 1)))
    mid = torch.where(keep, jet.mid, torch.full_like(jet.mid, value))
    rad = torch.where(keep, jet.rad, torch.zeros_like(jet.rad))
    if jet.dmid is None:
        return Jet(mid, rad, None, None)
    grad_keep = keep.unsqueeze(-1)
    zero = torch.zeros_like(jet.dmid)
    return Jet(
        mid, rad, torch.where(grad_keep, jet.dmid, zero), torch.where(grad_keep, jet.drad, zero)
    )


def with_rows(whole: Jet, rows: Tensor, part: Jet) -> Jet:
    """``whole`` (B, ...) with the rows ``rows`` (B,) bool replaced by ``part`` (rows.sum(),
    ...), derivatives included (``whole`` must carry one if ``part`` does)."""
    mid, rad = whole.mid.clone(), whole.rad.clone()
    mid[rows], rad[rows] = part.mid, part.rad
    if whole.dmid is None:
        return Jet(mid, rad, None, None)
    dmid, drad = whole.dmid.clone(), whole.drad.clone()
    dmid[rows], drad[rows] = part.dmid, part.drad
    return Jet(mid, rad, dmid, drad)


def point_jet(value: Tensor) -> Jet:
    """A value enclosure of a point (zero radius, no derivative)."""
    return Jet(value, torch.zeros_like(value), None, None)


SMOOTHERSTEP = (10.0, -15.0, 6.0)
r"""Coefficients of :math:`t^3, t^4, t^5` in Perlin's smootherstep :math:`S(t) = 10 t^3 - 15 t^4
+ 6 t^5`: :math:`S(0) = 0`, :math:`S(1) = 1`, :math:`S' = S'' = 0` at both ends."""
SMOOTHERSTEP_ABS_SUM = sum(abs(c) for c in SMOOTHERSTEP)
SMOOTHERSTEP_SLOPE_ERROR = 8.0 * UNIT_ROUNDOFF
r"""Relative error of :math:`S'(t) = 30 (t (1 - t))^2` computed in floating point (one
subtraction, two products, a square and a scaling: at most 6 roundings)."""


def smootherstep(t: Any) -> Any:
    r"""Perlin's quintic smootherstep :math:`S(t) = 10 t^3 - 15 t^4 + 6 t^5` (Horner form).

    On a tensor, ``t * t * t * (10 + t * (-15 + t * 6))``, elementwise. On a :class:`Jet`, the
    interval rule: :math:`S' = 30 t^2 (1 - t)^2 \ge 0`, so :math:`S` is increasing and its range
    is :math:`[S(t_{low}), S(t_{high})]` (ends rounded outward, plus the Horner bound
    :math:`\gamma_{10} \sum_i |c_i| |t|^i`, Higham 2002, sec. 5.1); :math:`S'` is the hull of its
    values at the ends and at its critical points 0, 1/2, 1 inside the interval. Naive interval
    arithmetic on the Horner form would lose the flatness of :math:`S` at 0 and 1 (an
    enclosure wider than the box where the true range is of third order).

    Parameters
    ----------
    t : Tensor or Jet
        Any shape ``...``; the ROA relevance feeds :math:`t \in [0, 1]`.

    Returns
    -------
    Tensor or Jet
        :math:`S(t)`, same shape.
    """
    if isinstance(t, Jet):
        return _smootherstep(t)
    c3, c4, c5 = SMOOTHERSTEP
    return t * t * t * (c3 + t * (c4 + t * c5))


def _smootherstep(t: Jet) -> Jet:
    low, high = _outer_ends(t)
    # t^3 (c3 + t (c4 + t c5)) rounds at most 7 times: within gamma_7 sum_i |c_i| |t|^i
    # (Higham 2002, sec. 5.1), taken with room as gamma_10
    gamma = _gamma(10)

    def bound(value: Tensor) -> Tensor:
        magnitude = value.abs()
        return gamma * SMOOTHERSTEP_ABS_SUM * torch.maximum(magnitude**3, magnitude**5)

    value_low, value_high = smootherstep(low), smootherstep(high)
    mid, rad = _enclose_ends(value_low - bound(low), value_high + bound(high), 0.0)
    if t.dmid is None:
        return Jet(mid, rad, None, None)
    candidates = [_smootherstep_slope(low), _smootherstep_slope(high)]
    for critical in (0.0, 0.5, 1.0):
        inside = (low <= critical) & (critical <= high)
        peak = _smootherstep_slope(torch.full_like(low, critical))
        # a critical point outside the interval stands in as one of its ends' values
        candidates.append(torch.where(inside, peak, candidates[0]))
    stacked = torch.stack(candidates)
    slope = _enclose_ends(stacked.min(0).values, stacked.max(0).values, SMOOTHERSTEP_SLOPE_ERROR)
    return _chain(mid, rad, Jet(*slope, None, None), t)


def _smootherstep_slope(t: Tensor) -> Tensor:
    """:math:`S'(t) = 30 (t (1 - t))^2`."""
    return 30.0 * (t * (1.0 - t)).square()


QUADRATIC_CORNER_DIM = 6
"""Largest dimension S for which :func:`quadratic_form` bounds a box's largest level by the
:math:`2^S` corners of the box of ``z`` (64 corners at S = 6)."""


def quadratic_form(z: Any, matrix: Tensor) -> Any:
    r""":math:`z^\top P z` over the last dimension, kept: (..., S) -> (..., 1), ``matrix`` P
    (S, S) symmetric positive definite.

    On a tensor, ``((z @ P) * z).sum(-1, keepdim=True)``. On a :class:`Jet` the value
    enclosure is that formula's interval evaluation intersected with the sum of exact squares
    :math:`|L^\top z|^2` (P = L L^T, Cholesky), which keeps the dependency between the factors
    that the plain product loses (several times tighter on the boxes of a proof), plus the
    factorisation's error :math:`|z^\top (P - L L^\top) z| \le e\,|z|^2`
    (:func:`_factor_error`). Up to :data:`QUADRATIC_CORNER_DIM` dimensions its upper end is
    also at most the largest value at the corners of the enclosure of ``z`` (outward rounded,
    each evaluated in interval arithmetic): a convex function's maximum over a box is at a
    corner, so that end is the exact maximum over the box of ``z`` up to rounding. The
    derivative is the plain formula's.
    """
    plain = ((z @ matrix) * z).sum(-1, keepdim=True)
    if not isinstance(z, Jet):
        return plain
    factor = torch.linalg.cholesky(matrix)
    squares = (z @ factor).square().sum(-1, keepdim=True)
    largest = (z.mid.abs() + z.rad).square().sum(-1, keepdim=True)
    slack = _factor_error(matrix, factor) * largest * (1.0 + 4.0 * matrix.shape[0] * ROUNDING)
    slack = slack + TINY
    (plain_low, plain_high), (low, high) = _outer_ends(plain), _outer_ends(squares)
    low = torch.nextafter(low - slack, torch.full_like(low, -math.inf))
    high = torch.nextafter(high + slack, torch.full_like(high, math.inf))
    high = torch.minimum(plain_high, high)
    if matrix.shape[0] <= QUADRATIC_CORNER_DIM:
        high = torch.minimum(high, _corner_high(z, matrix))
    mid, rad = _from_ends(torch.maximum(plain_low, low), high)
    return Jet(mid, rad, plain.dmid, plain.drad)


def _corner_high(z: Jet, matrix: Tensor) -> Tensor:
    r"""An upper bound (..., 1) of :math:`z^\top P z` over the box of ``z``'s value enclosure
    (P positive semidefinite): :func:`corner_quadratic_high` at the corners of that box, its
    ends rounded outward."""
    return corner_quadratic_high(point_jet(box_corners(*_outer_ends(z))), matrix).unsqueeze(-1)


def box_corners(low: Tensor, high: Tensor) -> Tensor:
    """The :math:`2^S` corners (..., 2^S, S) of the boxes ``[low, high]`` (..., S): corner k
    takes ``high`` on the coordinates i where bit i of k is set, ``low`` elsewhere."""
    size = low.shape[-1]
    bits = torch.arange(size, device=low.device)
    pick = ((torch.arange(2**size, device=low.device)[:, None] >> bits) & 1).bool()
    return torch.where(pick, high.unsqueeze(-2), low.unsqueeze(-2))


def corner_quadratic_high(corners: Jet, matrix: Tensor) -> Tensor:
    r"""An upper bound (...,) of :math:`c^\top P c` over the corners (..., K, S), P (S, S)
    positive semidefinite: the largest upper end of the interval evaluations, rounded outward.
    When the corners are those of a box (:func:`box_corners`) and c is affine in the box, the
    convex quadratic's maximum over the box is at a corner, so this bounds it over the whole
    box. A NaN (an infinite end times a zero) counts as unbounded."""
    values = ((corners @ matrix) * corners).sum(-1)  # (..., K)
    top = _outer_ends(values)[1].amax(-1)
    return torch.nan_to_num(top, nan=math.inf)


def _factor_error(matrix: Tensor, factor: Tensor) -> float:
    r"""An upper bound :math:`e \ge \|P - L L^\top\|_2` in exact arithmetic: the computed
    residual plus the rounding of the product (:math:`\gamma_S |L| |L|^\top`, Higham 2002,
    sec. 3.5) and of the difference, through the Frobenius norm, with a relative slack."""
    size = matrix.shape[0]
    residual = (matrix - factor @ factor.T).abs() * (1.0 + UNIT_ROUNDOFF)
    product = (factor.abs() @ factor.abs().T) * (_gamma(size) * (1.0 + _gamma(size)))
    return float(torch.linalg.matrix_norm(residual + product)) * (1.0 + 1e-10)
