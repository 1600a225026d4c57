r"""Interval arithmetic with first-order interval derivatives (interval jets), in batched torch.

A :class:`Jet` encloses, over a box of inputs :math:`\xi \in [c - h, c + h] \subset
\mathbb{R}^S`, both the range of a quantity :math:`q(\xi)` and the range of its gradient
:math:`\nabla_\xi q`, in midpoint-radius form:

.. math::

    q(\xi) \in [m - r,\ m + r], \qquad \frac{\partial q}{\partial \xi_s}(\xi)
    \in [m'_s - r'_s,\ m'_s + r'_s] \quad \text{for every } \xi \text{ in the box.}

The existing pure torch step functions, observation maps and linear controllers run on jets
unchanged: arithmetic operators are overloaded and the torch functions they call (``sin``,
``cos``, ``tanh``, ``clamp``, ``minimum``, ``maximum``, ``abs``, ``stack``, ``matmul``,
``nn.functional.linear``) are dispatched through ``__torch_function__``. Any other torch
function raises :class:`UnsupportedOperation`, so a proof never silently uses an unsound
enclosure.

Rules (Moore, Kearfott and Cloud 2009, ch. 2-5; Rump 1999 for the midpoint-radius form):
products :math:`m = m_a m_b`, :math:`r = |m_a| r_b + r_a |m_b| + r_a r_b`; ``sin`` and ``cos``
by the addition theorem, :math:`|\sin(m + t) - \sin m| \le |\sin m| \min(t^2/2, 2) + |\cos m|
\min(|t|, 1)`; monotone functions (``tanh``, reciprocal) and ``clamp`` by their endpoints;
derivatives by the chain rule on intervals. ``clamp``, ``minimum``, ``maximum`` and ``abs`` are
not differentiable at their kinks: where an interval straddles a kink the derivative enclosure
is the hull of both one-sided derivatives (it contains Clarke's generalised gradient, which is
what the mean-value form of a piecewise smooth map needs).

Rounding: every result's radius is widened by ``ROUNDING`` (four units of roundoff) relative
to its midpoint and radius, plus the smallest subnormal number. That covers the at most half-ulp
error of IEEE 754 ``+ - * /`` (correctly rounded) and the at most one-ulp error of the
platform's ``sin``, ``cos`` and ``tanh``, so the enclosures hold for the exact real-number
functions, not only for the floating-point evaluation (emulated outward rounding; the one
assumption is libm's documented accuracy). Matrix products add the standard bound
:math:`\gamma_n |x|\,|M|` with :math:`\gamma_n = n u / (1 - n u)` (Higham 2002, sec. 3.5).

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
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import torch
from torch import Tensor

__all__ = ["Jet", "UnsupportedOperation", "box_jet", "point_jet"]

UNIT_ROUNDOFF = 2.0**-53
ROUNDING = 4.0 * UNIT_ROUNDOFF
"""Relative widening of every computed radius and midpoint (emulated outward rounding)."""
TINY = 2.0**-1074
"""Smallest subnormal double: the absolute error of a rounding that underflows."""


class UnsupportedOperation(TypeError):
    """A torch function or operand that the interval evaluator has no sound rule for."""


def _widen(mid: Tensor, rad: Tensor) -> Tensor:
    return rad * (1.0 + ROUNDING) + ROUNDING * mid.abs() + TINY


def _mul_rad(am: Tensor, ar: Tensor, bm: Tensor, br: Tensor) -> Tensor:
    return am.abs() * br + ar * bm.abs() + ar * br


def _hull_with_zero(mid: Tensor, rad: Tensor) -> tuple[Tensor, Tensor]:
    low = torch.clamp(mid - rad, max=0.0)
    high = torch.clamp(mid + rad, min=0.0)
    return 0.5 * (low + high), 0.5 * (high - low)


def _last_dim(dim: int, ndim: int) -> int:
    """A value dimension as a dimension of the derivative (one trailing dimension more)."""
    return dim - 1 if dim < 0 else dim


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
        if isinstance(exponent, bool) or not isinstance(exponent, int) or exponent < 1:
            raise UnsupportedOperation(
                f"Jet ** {exponent!r}: only positive integer exponents are supported"
            )
        if exponent == 2:
            return self.square()
        result = self
        for _ in range(exponent - 1):
            result = result * self
        return result

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
    return mid, _widen(mid, _mul_rad(fm, fr, dmid, drad))


def _sum_grads(terms: list[tuple[Tensor, Tensor]]) -> tuple[Tensor | None, Tensor | None]:
    if not terms:
        return None, None
    mid, rad = terms[0]
    for other_mid, other_rad in terms[1:]:
        mid = mid + other_mid
        rad = _widen(mid, rad + other_rad)
    return mid, rad


def _add_grads(first: Jet, second: Jet) -> tuple[Tensor | None, Tensor | None]:
    terms = [(jet.dmid, jet.drad) for jet in (first, second) if jet.dmid is not None]  # type: ignore[misc]
    if len(terms) == 2:
        shape = torch.broadcast_shapes(terms[0][0].shape, terms[1][0].shape)
        terms = [(m.expand(shape), r.expand(shape)) for m, r in terms]
    return _sum_grads(terms)  # type: ignore[arg-type]


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
    """Radius of sin (or cos) over m +/- r by the addition theorem (module docstring)."""
    half_square = torch.clamp(0.5 * rad**2, max=2.0)
    spread = same.abs() * half_square + other.abs() * torch.clamp(rad, max=1.0)
    return _widen(same, spread)


def _sin_value(x: Jet) -> Jet:
    mid = torch.sin(x.mid)
    return Jet(mid, _sin_cos_rad(mid, torch.cos(x.mid), x.rad), None, None)


def _cos_value(x: Jet) -> Jet:
    mid = torch.cos(x.mid)
    return Jet(mid, _sin_cos_rad(mid, torch.sin(x.mid), x.rad), None, None)


def _tanh(x: Jet) -> Jet:
    low, high = torch.tanh(x.low), torch.tanh(x.high)
    mid, rad = _from_ends(low, high)
    # 1 - tanh^2 over the interval: largest at the point nearest 0, smallest at an end.
    straddles = (x.low <= 0.0) & (x.high >= 0.0)
    nearest = torch.where(straddles, torch.zeros_like(low), torch.minimum(low.abs(), high.abs()))
    farthest = torch.maximum(low.abs(), high.abs())
    slope_mid, slope_rad = _from_ends(1.0 - farthest**2, 1.0 - nearest**2)
    return _chain(mid, rad, Jet(slope_mid, slope_rad, None, None), x)


def _clamp(x: Any, min: Any = None, max: Any = None) -> Jet:  # noqa: A002
    jet = x if isinstance(x, Jet) else as_jet(x, min if isinstance(min, Jet) else max)
    if isinstance(min, Jet) or isinstance(max, Jet):
        raise UnsupportedOperation("clamp with interval bounds has no interval rule")
    low, high = jet.low, jet.high
    below = torch.zeros_like(low, dtype=torch.bool)
    above = torch.zeros_like(low, dtype=torch.bool)
    inside = torch.ones_like(low, dtype=torch.bool)
    if min is not None:
        bound = torch.as_tensor(min, dtype=jet.dtype)
        low, high = torch.maximum(low, bound), torch.maximum(high, bound)
        below = jet.high <= bound
        inside = inside & (jet.low > bound)
    if max is not None:
        bound = torch.as_tensor(max, dtype=jet.dtype)
        low, high = torch.minimum(low, bound), torch.minimum(high, bound)
        above = jet.low >= bound
        inside = inside & (jet.high < bound)
    mid, rad = _from_ends(low, high)
    if jet.dmid is None:
        return Jet(mid, rad, None, None)
    hull_mid, hull_rad = _hull_with_zero(jet.dmid, jet.drad)
    constant = (below | above).unsqueeze(-1)
    smooth = inside.unsqueeze(-1)
    dmid = torch.where(constant, 0.0, torch.where(smooth, jet.dmid, hull_mid))
    drad = torch.where(constant, 0.0, torch.where(smooth, jet.drad, hull_rad))
    return Jet(mid, rad, dmid, drad)


def _minimum(x: Any, y: Any) -> Jet:
    if isinstance(x, Jet) and isinstance(y, Jet):
        raise UnsupportedOperation("minimum of two intervals has no interval rule")
    jet, bound = (x, y) if isinstance(x, Jet) else (y, x)
    return _clamp(jet, max=bound)


def _maximum(x: Any, y: Any) -> Jet:
    if isinstance(x, Jet) and isinstance(y, Jet):
        raise UnsupportedOperation("maximum of two intervals has no interval rule")
    jet, bound = (x, y) if isinstance(x, Jet) else (y, x)
    return _clamp(jet, min=bound)


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
    size = matrix.shape[0]
    gamma = size * UNIT_ROUNDOFF / (1.0 - size * UNIT_ROUNDOFF)
    magnitude = matrix.abs()
    mid = x.mid @ matrix
    rad = _widen(mid, x.rad @ magnitude + gamma * (x.mid.abs() @ magnitude))
    if x.dmid is None:
        return Jet(mid, rad, None, None)
    dmid = torch.einsum("...ds,df->...fs", x.dmid, matrix)
    spread = torch.einsum("...ds,df->...fs", x.drad + gamma * x.dmid.abs(), magnitude)
    return Jet(mid, rad, dmid, _widen(dmid, spread))


def _matmul(x: Any, y: Any) -> Jet:
    if isinstance(x, Jet) and not isinstance(y, Jet):
        return _matmul_right(x, torch.as_tensor(y, dtype=x.dtype))
    raise UnsupportedOperation("matmul: only Jet @ constant matrix has an interval rule")


def _linear(x: Jet, weight: Tensor, bias: Tensor | None = None) -> Jet:
    result = _matmul_right(x, torch.as_tensor(weight, dtype=x.dtype).T)
    return result if bias is None else result + bias


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


def point_jet(value: Tensor) -> Jet:
    """A value enclosure of a point (zero radius, no derivative)."""
    return Jet(value, torch.zeros_like(value), None, None)
