"""Interval rules for the learned parts (leoc.control.intervals, issue 42).

Every rule and every learned module leoc trains, evaluated on interval jets, is checked against
evidence the enclosures do not use:

- soundness on boxes of several widths: values and autograd Jacobians at 2000 uniform points
  of each box and at its corners, evaluated in floating point, lie in the value and derivative
  enclosures;
- soundness against exact arithmetic: points of a box given exactly (its ends and a grid), the
  functions evaluated by mpmath at 60 digits (exact rationals for linear layers and sums, with
  products that cancel), lie in the enclosures; this is what sees rounding, which samples
  evaluated in floating point cannot;
- not vacuous: on small boxes the enclosure is at most a fixed multiple of the sampled spread
  (its overestimation factor, measured for each case and stated beside it), and derivative
  enclosures shrink with the box away from kinks.

The learned modules are the objects leoc builds: MLP actors (a realistically sized 400 x 300
one among them), PILCO's RBF network and its policies from ``build_policy``, hybrids from
``build_hybrid`` with every relevance and saturation, and the float64 physical policies of SB3
DDPG/TD3/SAC actors built by ``build_model`` (what leoc evaluates and certifies).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable
from fractions import Fraction
from typing import NamedTuple

import mpmath
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from torch import nn

from leoc.control import design_lqr
from leoc.control.intervals import Jet, UnsupportedOperation, box_jet, smootherstep
from leoc.policies import (
    HeldPolicy,
    HybridDesign,
    HybridSpec,
    MLPActor,
    RBFNetwork,
    build_hybrid,
    relevance_floor,
    relevance_of_distance,
)
from leoc.policies.relevance import ROARelevance
from leoc.policies.saturation import apply_saturation
from leoc.systems import make_env, make_system

pytestmark = pytest.mark.usefixtures("single_thread")

DTYPE = torch.float64
SAMPLES = 2000  # uniform points per box, besides its corners
BOXES = 8
EXACT_DIGITS = 60
SMALL_WIDTHS = (1e-2, 1e-4, 1e-6)  # half-widths of the boxes the tightness tests shrink
ROUNDING_SLACK = 1e-12  # what rounding may add to an enclosure, relative to 1 + |value|
SLOPE_SHRINK = 1e3  # derivative radius allowed per unit of box half-width (times 1 + |slope|)
# Samples are floating-point evaluations, off the exact values by their own rounding (autograd's
# tanh' = 1 - tanh^2 keeps only an absolute 1e-16 where tanh is near 1): they may leave the
# enclosure by this much relative to 1 + |sample|. Rounding is checked against exact arithmetic.
SAMPLE_TOLERANCE = 1e-13


# ---- sampling and checking ---------------------------------------------------------------


def _points(centre: torch.Tensor, radius: torch.Tensor, count: int, seed: int) -> torch.Tensor:
    """``count`` uniform points of each box and its corners, (B, count + 2^S, S)."""
    generator = torch.Generator().manual_seed(seed)
    size = centre.shape[-1]
    unit = 2.0 * torch.rand(centre.shape[0], count, size, generator=generator, dtype=DTYPE) - 1
    signs = torch.cartesian_prod(*[torch.tensor([-1.0, 1.0], dtype=DTYPE)] * size)
    corners = signs.reshape(1, -1, size).expand(centre.shape[0], -1, -1)
    return centre[:, None] + torch.cat([unit, corners], 1) * radius[:, None]


def _values_and_jacobians(function: Callable, points: torch.Tensor):
    """Values (B, K, F) and autograd Jacobians (B, K, F, S) of ``function`` at ``points``."""
    flat = points.reshape(-1, points.shape[-1]).clone().requires_grad_(True)
    values = function(flat).reshape(flat.shape[0], -1)
    rows = [
        torch.autograd.grad(values[:, i].sum(), flat, retain_graph=True)[0]
        for i in range(values.shape[1])
    ]
    jacobians = torch.stack(rows, 1)
    leading = points.shape[:-1]
    return values.detach().reshape(*leading, -1), jacobians.reshape(*leading, *jacobians.shape[1:])


class Enclosure(NamedTuple):
    """A jet's enclosures with the value flattened to (B, F) and the derivative (B, F, S)."""

    mid: torch.Tensor
    rad: torch.Tensor
    dmid: torch.Tensor
    drad: torch.Tensor


def _enclose(function: Callable, centre: torch.Tensor, radius: torch.Tensor) -> Enclosure:
    with torch.no_grad():
        jet = function(box_jet(centre, radius))
    assert isinstance(jet, Jet)
    batch, size = centre.shape
    return Enclosure(
        jet.mid.reshape(batch, -1),
        jet.rad.reshape(batch, -1),
        jet.dmid.reshape(batch, -1, size),
        jet.drad.reshape(batch, -1, size),
    )


def _outside(samples: torch.Tensor, mid: torch.Tensor, rad: torch.Tensor) -> torch.Tensor:
    """Samples (B, K, ...) farther from the enclosures (B, ...) than their own rounding."""
    tolerance = SAMPLE_TOLERANCE * (1.0 + samples.abs())
    return (samples - mid[:, None]).abs() > rad[:, None] + tolerance


def _check_sound(function: Callable, centre, radius, seed: int = 0, count: int = SAMPLES):
    """Every sampled value and Jacobian inside the enclosures; returns them and the samples."""
    enclosure = _enclose(function, centre, radius)
    values, jacobians = _values_and_jacobians(function, _points(centre, radius, count, seed))
    outside = _outside(values, enclosure.mid, enclosure.rad)
    assert not outside.any(), f"{int(outside.sum())} sampled values outside the enclosure"
    slope_outside = _outside(jacobians, enclosure.dmid, enclosure.drad)
    assert not slope_outside.any(), f"{int(slope_outside.sum())} Jacobians outside"
    return enclosure, values, jacobians


def _half_spread(samples: torch.Tensor) -> torch.Tensor:
    """Half the sampled range over each box's points: (B, K, ...) -> (B, ...)."""
    return 0.5 * (samples.max(1).values - samples.min(1).values)


def _check_tight(function: Callable, centre, factor: float, count: int = 400) -> float:
    """Not vacuous: on boxes of half-width h in ``SMALL_WIDTHS`` the value enclosure's radius
    is at most ``factor`` times C h (plus rounding), C the largest sampled half-range over h of
    any of these boxes (the function's own first-order variation there), and the derivative
    enclosure shrinks with the box (at most ``factor`` times the sampled Jacobians' half-range
    plus ``SLOPE_SHRINK`` h). An enclosure that keeps a fixed width, is infinite or does not
    shrink fails. Returns the largest ratio of radius to C h found (the measured factor)."""
    runs = []
    for width in SMALL_WIDTHS:
        radius = torch.full_like(centre, width)
        runs.append((width, *_check_sound(function, centre, radius, 1, count)))
    variation = max(float((_half_spread(values) / width).max()) for width, _, values, _ in runs)
    worst = 0.0
    for width, enclosure, _, jacobians in runs:
        slack = ROUNDING_SLACK * (1.0 + enclosure.mid.abs())
        allowed = factor * variation * width + slack
        assert torch.all(enclosure.rad <= allowed), (width, enclosure.rad, allowed)
        worst = max(worst, float((enclosure.rad / (variation * width + slack)).max()))
        scale = 1.0 + enclosure.dmid.abs()
        spread = factor * _half_spread(jacobians)
        allowed = spread + (SLOPE_SHRINK * width + ROUNDING_SLACK) * scale
        assert torch.all(enclosure.drad <= allowed), (width, enclosure.drad, allowed)
    return worst


# ---- the rules ---------------------------------------------------------------------------


class Case(NamedTuple):
    """A function to evaluate on jets and tensors alike, where its boxes lie, and the
    overestimation ``factor`` its enclosures are held to on small boxes (measured, with
    margin)."""

    function: Callable
    centres: Callable[[np.random.Generator], np.ndarray]
    widths: tuple[float, ...]
    factor: float


def _uniform(low: float, high: float, size: int = 1):
    return lambda rng: rng.uniform(low, high, size=(BOXES, size))


def _annulus(rng: np.random.Generator) -> np.ndarray:
    """Centres of (x, y) boxes away from atan2's cut (angles in (-2.5, 2.5), radius 1 to 2)."""
    angle = rng.uniform(-2.5, 2.5, BOXES)
    length = rng.uniform(1.0, 2.0, BOXES)
    return np.stack([length * np.cos(angle), length * np.sin(angle)], 1)


def _linear_layer() -> nn.Linear:
    torch.manual_seed(5)
    return nn.Linear(4, 3, dtype=DTYPE)


LAYER = _linear_layer()
LIMIT = torch.tensor(2.0, dtype=DTYPE)
CENTRES = torch.tensor([[0.5, -0.5], [1.0, 2.0], [-1.5, 0.0]], dtype=DTYPE)
WIDE = (1.0, 0.1, 1e-3)

RULES = {
    "exp": Case(torch.exp, _uniform(-5.0, 5.0), WIDE, 1.05),
    "relu": Case(torch.relu, _uniform(-1.0, 1.0), WIDE, 1.05),
    "relu_module": Case(nn.ReLU(), _uniform(-1.0, 1.0), WIDE, 1.05),
    "functional_relu": Case(F.relu, _uniform(-1.0, 1.0), WIDE, 1.05),
    "tanh": Case(torch.tanh, _uniform(-4.0, 4.0), WIDE, 1.05),
    "linear": Case(LAYER, _uniform(-2.0, 2.0, 4), WIDE, 1.05),
    "sum": Case(lambda z: z.sum(-1, keepdim=True), _uniform(-2.0, 2.0, 4), WIDE, 1.05),
    "torch_sum": Case(lambda z: torch.sum(z.square(), dim=-1), _uniform(-2, 2, 3), WIDE, 1.05),
    "pow_2": Case(lambda z: z.pow(2.0), _uniform(-2.0, 2.0), WIDE, 1.05),
    "pow_1.5": Case(lambda z: z**1.5, _uniform(1.0, 3.0), (0.9, 0.1, 1e-3), 1.05),
    "torch_pow_3": Case(lambda z: torch.pow(z, 3.0), _uniform(-2.0, 2.0), WIDE, 1.1),
    "atan2": Case(
        lambda z: torch.atan2(z[..., 1], z[..., 0]).unsqueeze(-1), _annulus, (0.5, 0.1, 1e-3), 1.05
    ),
    "remainder": Case(
        lambda z: torch.remainder(z + math.pi, 2.0 * math.pi) - math.pi,
        _uniform(-10.0, 10.0),
        (3.0, 0.3, 1e-3),
        1.05,
    ),
    # a jet broadcast along a constant's dimension, then summed over it (RBF's x - c_i): one
    # gradient per value, so that the sum counts each (slope 3)
    "broadcast_sum": Case(
        lambda z: (z[..., None, :] - CENTRES).sum(-2), _uniform(-1, 1, 2), WIDE, 1.05
    ),
    "maximum": Case(
        lambda z: torch.maximum(z[..., :1], z[..., 1:]), _uniform(-1, 1, 2), WIDE, 1.05
    ),
    "minimum": Case(
        lambda z: torch.minimum(z[..., :1], z[..., 1:]), _uniform(-1, 1, 2), WIDE, 1.05
    ),
    "paper_relevance": Case(
        lambda z: relevance_of_distance(z.square().sum(-1, keepdim=True), 1.0),
        _uniform(-2.0, 2.0, 3),
        WIDE,
        1.1,
    ),
    "relevance_power_2": Case(
        lambda z: relevance_of_distance(z.square().sum(-1, keepdim=True), 2.0),
        _uniform(-2.0, 2.0, 3),
        WIDE,
        1.1,
    ),
    # the ROA relevance of one plain state with P = 1, rho_in = 1, w = 1: 1 - S(clip(x^2 - 1))
    "smootherstep": Case(
        ROARelevance([("state", 0)], [0.0], [[1.0]], 1.0, 1.0, False), _uniform(0, 1.6), WIDE, 1.05
    ),
    "clip": Case(lambda z: apply_saturation(z, LIMIT, "clip"), _uniform(-4, 4), WIDE, 1.05),
    "sin_squash": Case(lambda z: apply_saturation(z, LIMIT, "sin"), _uniform(-8, 8), WIDE, 1.2),
    "tanh_squash": Case(lambda z: apply_saturation(z, LIMIT, "tanh"), _uniform(-6, 6), WIDE, 1.05),
}


def _rule_boxes(case: Case, width: float, seed: int):
    rng = np.random.default_rng(seed)
    centre = torch.as_tensor(case.centres(rng), dtype=DTYPE)
    radius = torch.as_tensor(width * rng.uniform(0.5, 1.0, size=centre.shape), dtype=DTYPE)
    return centre, radius


@pytest.mark.parametrize("width_index", range(3))
@pytest.mark.parametrize("name", RULES)
def test_rule_encloses_dense_samples_and_autograd(name, width_index):
    case = RULES[name]
    centre, radius = _rule_boxes(case, case.widths[width_index], seed=width_index)
    _check_sound(case.function, centre, radius, seed=width_index)


@pytest.mark.parametrize("name", RULES)
def test_rule_enclosure_shrinks_with_the_box(name):
    case = RULES[name]
    centre, _ = _rule_boxes(case, 1.0, seed=7)
    _check_tight(case.function, centre, case.factor)


def test_relu_slope_is_zero_to_one_on_a_box_straddling_zero():
    """Known answers: ReLU's derivative enclosure is [0, 1] across the kink, 1 above it and 0
    below it; its value is [0, max(high, 0)]."""
    centre = torch.tensor([[0.1], [2.0], [-2.0]], dtype=DTYPE)
    radius = torch.tensor([[0.5], [0.5], [0.5]], dtype=DTYPE)
    jet = torch.relu(box_jet(centre, radius))
    low, high = jet.dmid[:, 0, 0] - jet.drad[:, 0, 0], jet.dmid[:, 0, 0] + jet.drad[:, 0, 0]
    np.testing.assert_allclose(low.numpy(), [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(high.numpy(), [1.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(jet.low[:, 0].numpy(), [0.0, 1.5, 0.0], atol=1e-15)
    np.testing.assert_allclose(jet.high[:, 0].numpy(), [0.6, 2.5, 0.0], atol=1e-15)


def test_atan2_across_its_cut_is_the_whole_circle_with_an_unbounded_slope():
    """A box of (x, y) that meets x <= 0, y = 0 (or holds the origin) gets [-pi, pi] and an
    infinite derivative radius (a jump), which a proof rejects; the samples stay inside."""
    centre = torch.tensor([[-1.0, 0.05], [-1.0, -0.05], [0.0, 0.0], [0.1, 0.0]], dtype=DTYPE)
    radius = torch.full_like(centre, 0.2)
    function = RULES["atan2"].function
    enclosure, _, _ = _check_sound(function, centre, radius)
    assert torch.all(enclosure.mid - enclosure.rad <= -math.pi)
    assert torch.all(enclosure.mid + enclosure.rad >= math.pi)
    assert torch.all(torch.isinf(enclosure.drad))


def test_remainder_across_a_jump_is_one_period_with_an_unbounded_slope():
    centre = torch.tensor([[0.0], [2.0 * math.pi], [1.0]], dtype=DTYPE)
    radius = torch.tensor([[0.1], [0.1], [0.1]], dtype=DTYPE)
    enclosure, _, _ = _check_sound(lambda z: torch.remainder(z, 2.0 * math.pi), centre, radius)
    jumps = torch.isinf(enclosure.drad[:, 0, 0])
    assert jumps.tolist() == [True, True, False]
    assert float(enclosure.rad[2, 0]) < 0.11  # one period: the shift, as narrow as the box


def test_operations_without_a_sound_rule_are_refused():
    jet = box_jet(torch.zeros(2, 1, dtype=DTYPE), torch.ones(2, 1, dtype=DTYPE))
    with pytest.raises(UnsupportedOperation, match="inplace"):
        F.relu(jet, inplace=True)
    with pytest.raises(UnsupportedOperation, match="where"):
        torch.where(jet > 0.0, jet, 0.0)  # a "possibly" condition cannot select soundly
    with pytest.raises(UnsupportedOperation, match="exponents"):
        jet**0.5
    with pytest.raises(UnsupportedOperation, match="modulus"):
        torch.remainder(jet, -1.0)


# ---- against exact arithmetic --------------------------------------------------------------


class Exact(NamedTuple):
    """A unary rule, its exact value and slope in mpmath, and where its boxes' centres lie."""

    function: Callable
    value: Callable
    slope: Callable
    low: float
    high: float


def _exact_remainder(t):
    period = mpmath.mpf(2.0 * math.pi)  # the float modulus, exactly
    return t - period * mpmath.floor(t / period)


EXACT = {
    "exp": Exact(torch.exp, mpmath.exp, mpmath.exp, -740.0, 700.0),
    "tanh": Exact(torch.tanh, mpmath.tanh, lambda t: mpmath.sech(t) ** 2, -40.0, 40.0),
    "relu": Exact(torch.relu, lambda t: max(t, 0), lambda t: 1 if t > 0 else 0, -1.0, 1.0),
    "pow_1.5": Exact(lambda z: z**1.5, lambda t: t**1.5, lambda t: 1.5 * mpmath.sqrt(t), 0, 50),
    "pow_2": Exact(lambda z: z.pow(2.0), lambda t: t**2, lambda t: 2 * t, -1e3, 1e3),
    "sin": Exact(torch.sin, mpmath.sin, mpmath.cos, -100.0, 100.0),
    "cos": Exact(torch.cos, mpmath.cos, lambda t: -mpmath.sin(t), -100.0, 100.0),
    # far from 0, so that the shift k m rounds
    "remainder": Exact(
        lambda z: torch.remainder(z, 2.0 * math.pi), _exact_remainder, lambda t: 1, -1e4, 1e4
    ),
    # a large exponent, so that the rounding of the box's ends shows (condition number p)
    "pow_20.5": Exact(lambda z: z**20.5, lambda t: t**20.5, lambda t: 20.5 * t**19.5, 0, 3),
    "smootherstep": Exact(
        smootherstep,
        lambda t: 10 * t**3 - 15 * t**4 + 6 * t**5,
        lambda t: 30 * t**2 * (1 - t) ** 2,
        -0.5,
        1.5,
    ),
}
GRID = [Fraction(k, 8) for k in range(-8, 9)]  # points mid + t rad of a box, t in [-1, 1]


def _exact_boxes(low: float, high: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres in [low, high]; radii relative to the centre (1e-17 to 1e-1) and absolute."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform(low, high, 120)
    relative = np.abs(centre) * 10.0 ** rng.uniform(-17, -1, 120)
    absolute = 10.0 ** rng.uniform(-17, 0, 120)
    return np.concatenate([centre, centre]), np.concatenate([relative, absolute])


def _inside(value, mid: float, rad: float) -> bool:
    return mpmath.mpf(mid) - mpmath.mpf(rad) <= value <= mpmath.mpf(mid) + mpmath.mpf(rad)


@pytest.mark.slow
@pytest.mark.parametrize("name", EXACT)
def test_rule_encloses_exact_values_and_slopes(name):
    """At points of each box given exactly (its ends and a grid of 17), the exact value and
    slope (mpmath, 60 digits) lie in the enclosures: this sees the rounding (of the ends, of
    libm, of the midpoint and radius) that float samples cannot."""
    rule = EXACT[name]
    centre, radius = _exact_boxes(rule.low, rule.high, seed=len(name))
    with torch.no_grad():
        jet = rule.function(
            box_jet(torch.as_tensor(centre)[:, None], torch.as_tensor(radius)[:, None])
        )
    mid, rad = jet.mid[:, 0].tolist(), jet.rad[:, 0].tolist()
    dmid, drad = jet.dmid[:, 0, 0].tolist(), jet.drad[:, 0, 0].tolist()
    failures = []
    with mpmath.workdps(EXACT_DIGITS):
        for index, (c, h) in enumerate(zip(centre.tolist(), radius.tolist(), strict=True)):
            for t in GRID:
                point = mpmath.mpf(c) + mpmath.mpf(t.numerator) / t.denominator * mpmath.mpf(h)
                if name.startswith("pow_") and point < 0:
                    continue  # outside the function's domain
                if not _inside(rule.value(point), mid[index], rad[index]):
                    failures.append(("value", c, h, float(t)))
                slope_known = name != "relu" or point != 0
                if slope_known and not _inside(rule.slope(point), dmid[index], drad[index]):
                    failures.append(("slope", c, h, float(t)))
    assert not failures, failures[:5]


def test_atan2_encloses_exact_values_and_slopes():
    rng = np.random.default_rng(3)
    centre = _annulus(rng)
    radius = 10.0 ** rng.uniform(-16, -0.5, size=centre.shape)
    with torch.no_grad():
        jet = RULES["atan2"].function(box_jet(torch.as_tensor(centre), torch.as_tensor(radius)))
    failures = []
    with mpmath.workdps(EXACT_DIGITS):
        for index in range(len(centre)):
            for s, t in ((s, t) for s in GRID[::4] for t in GRID[::4]):
                x = mpmath.mpf(centre[index, 0]) + mpmath.mpf(float(s)) * mpmath.mpf(
                    radius[index, 0]
                )
                y = mpmath.mpf(centre[index, 1]) + mpmath.mpf(float(t)) * mpmath.mpf(
                    radius[index, 1]
                )
                norm = x**2 + y**2
                expected = [mpmath.atan2(y, x), -y / norm, x / norm]
                found = [
                    (float(jet.mid[index, 0]), float(jet.rad[index, 0])),
                    *zip(jet.dmid[index, 0].tolist(), jet.drad[index, 0].tolist(), strict=True),
                ]
                failures += [
                    (index, float(s), float(t), k)
                    for k, (value, (m, r)) in enumerate(zip(expected, found, strict=True))
                    if not _inside(value, m, r)
                ]
    assert not failures, failures[:5]


def _cancelling(rng: np.random.Generator, rows: int, size: int) -> np.ndarray:
    """Rows of ``size`` numbers over 24 orders of magnitude, each holding the three terms
    K, K and -2K (K = 1e12) at random places: their sum is far below the largest term, so the
    rounding of any order of summation shows."""
    values = rng.normal(size=(rows, size)) * 10.0 ** rng.uniform(-12, 6, size=(rows, size))
    for row in values:
        places = rng.choice(size, 3, replace=False)
        row[places] = [1e12, 1e12, -2e12]
    return values


def test_linear_layer_encloses_the_exact_range_of_cancelling_products():
    """nn.Linear on boxes whose products cancel: the exact range (rationals: the centre's image
    plus or minus |W| r) and the exact Jacobian W lie in the enclosures."""
    rng = np.random.default_rng(11)
    size_in, size_out = 24, 6
    layer = nn.Linear(size_in, size_out, dtype=DTYPE)
    weight = _cancelling(rng, size_out, size_in)
    bias = rng.normal(size=size_out) * 1e3
    with torch.no_grad():
        layer.weight.copy_(torch.as_tensor(weight))
        layer.bias.copy_(torch.as_tensor(bias))
    centre = 1.0 + rng.integers(0, 3, size=(BOXES, size_in)).astype(float)
    radius = np.where(rng.uniform(size=centre.shape) < 0.5, 0.0, 10.0 ** rng.uniform(-14, -2))
    with torch.no_grad():
        jet = layer(box_jet(torch.as_tensor(centre), torch.as_tensor(radius)))
    W = [[Fraction(w) for w in row] for row in weight.tolist()]
    for b in range(BOXES):
        c, r = [Fraction(v) for v in centre[b]], [Fraction(v) for v in radius[b]]
        for i in range(size_out):
            image = sum((w * x for w, x in zip(W[i], c, strict=True)), Fraction(bias[i]))
            spread = sum((abs(w) * h for w, h in zip(W[i], r, strict=True)), Fraction(0))
            mid, rad = Fraction(float(jet.mid[b, i])), Fraction(float(jet.rad[b, i]))
            assert mid - rad <= image - spread and image + spread <= mid + rad, (b, i)
            dmid, drad = jet.dmid[b, i].tolist(), jet.drad[b, i].tolist()
            for s in range(size_in):
                assert abs(W[i][s] - Fraction(dmid[s])) <= Fraction(drad[s]), (b, i, s)


@pytest.mark.parametrize("via", ["linear", "matmul"])
@pytest.mark.parametrize("size", [1024, 4096])
def test_linear_layer_radius_covers_the_rounding_of_its_own_sum(size, via):
    """Boxes centred at 0 (an exact 0 midpoint): the radius |W| r is a computed sum of
    ``size`` positive products, which can fall short of the exact one by more than the
    relative widening of a single rounding (4 units of roundoff): measured up to about 12 at
    4096 terms for ``jet @ M`` with M contiguous (BLAS's order of summation; through
    ``nn.Linear``'s transposed weight about 1.5)."""
    rng = np.random.default_rng(size)
    weight = rng.normal(size=(8, size)) * 10.0 ** rng.uniform(-3, 3, size=(8, size))
    layer = nn.Linear(size, 8, bias=False, dtype=DTYPE)
    with torch.no_grad():
        layer.weight.copy_(torch.as_tensor(weight))
    matrix = torch.as_tensor(weight.T.copy())  # (size, 8), contiguous
    function = layer if via == "linear" else (lambda z: z @ matrix)
    radius = rng.uniform(1.0, 2.0, size=(1, size))
    with torch.no_grad():
        jet = function(box_jet(torch.zeros(1, size, dtype=DTYPE), torch.as_tensor(radius)))
    r = [Fraction(v) for v in radius[0].tolist()]
    for i in range(8):
        exact = sum((abs(Fraction(w)) * h for w, h in zip(weight[i].tolist(), r, strict=True)), 0)
        assert Fraction(float(jet.mid[0, i])) == 0
        assert exact <= Fraction(float(jet.rad[0, i])), i


@pytest.mark.parametrize("via", ["method", "torch"])
def test_sum_encloses_the_exact_sum_of_cancelling_terms(via):
    rng = np.random.default_rng(12)
    centre = _cancelling(rng, BOXES, 16)
    radius = np.where(rng.uniform(size=centre.shape) < 0.5, 0.0, 10.0 ** rng.uniform(-14, 0))
    with torch.no_grad():
        jet = box_jet(torch.as_tensor(centre), torch.as_tensor(radius))
        total = jet.sum(-1) if via == "method" else torch.sum(jet, dim=-1)
    for b in range(BOXES):
        exact = sum((Fraction(v) for v in centre[b]), Fraction(0))
        spread = sum((Fraction(v) for v in radius[b]), Fraction(0))
        mid, rad = Fraction(float(total.mid[b])), Fraction(float(total.rad[b]))
        assert mid - rad <= exact - spread and exact + spread <= mid + rad, b
        assert torch.all(total.dmid[b] - total.drad[b] <= 1.0)
        assert torch.all(total.dmid[b] + total.drad[b] >= 1.0)


# ---- the learned modules leoc trains -------------------------------------------------------

MODULE_WIDTHS = (0.3, 0.03, 1e-3)  # half-widths of observation boxes (cos, sin, theta_dot)


def _pendulum_centres(rng: np.random.Generator, count: int = BOXES) -> np.ndarray:
    """Pendulum observations (cos, sin, theta_dot) for theta in [-2.2, 2.2]: a box of half-width
    up to 0.3 then never meets atan2's cut (cos < 0 with sin = 0), where the ROA relevance's
    angle jumps."""
    theta = rng.uniform(-2.2, 2.2, count)
    rate = rng.uniform(-3.0, 3.0, count)
    return np.stack([np.cos(theta), np.sin(theta), rate], 1)


def _observation_boxes(width: float, seed: int, count: int = BOXES):
    rng = np.random.default_rng(seed)
    centre = torch.as_tensor(_pendulum_centres(rng, count), dtype=DTYPE)
    radius = torch.as_tensor(width * rng.uniform(0.5, 1.0, size=centre.shape), dtype=DTYPE)
    return centre, radius


def _check_module(module: Callable, width: float, seed: int, count: int = SAMPLES) -> None:
    """Sound on pendulum observation boxes, and finite: no box of these is rejected."""
    centre, radius = _observation_boxes(width, seed)
    enclosure, _, _ = _check_sound(module, centre, radius, seed, count)
    for part in enclosure:
        assert torch.isfinite(part).all()


@functools.cache
def _pendulum():
    system = make_system("pendulum")
    return system, design_lqr(system)


@functools.cache
def _pilco_policy(hybrid: bool) -> nn.Module:
    """PILCO's policy as ``load_pilco_controller`` gives it: ``build_policy`` (the sine-squashed
    RBF network, or the hybrid of leoc's default spec with that RBF part) at its control period,
    its RBF weights drawn from initial data."""
    from leoc.pilco.config import PilcoConfig
    from leoc.pilco.policy import build_policy

    system, _ = _pendulum()
    config = PilcoConfig.for_system("pendulum", hybrid=hybrid, num_basis=10)
    generator = torch.Generator().manual_seed(4)
    observations = _pendulum_centres(np.random.default_rng(4), 40)
    policy = build_policy(system, config, generator, observations)
    return HeldPolicy(policy.eval(), config.controller_action_repeat)


def _seeded(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


class Module(NamedTuple):
    """A learned module's builder and the overestimation factor its value enclosures are held
    to on small boxes (:func:`_check_tight`; measured, and doubled with room)."""

    build: Callable[[], nn.Module]
    factor: float


MODULES = {
    # measured 8.8: interval products through two ReLU layers
    "mlp_actor": Module(
        lambda: MLPActor(3, 1, (16, 16), action_limit=2.0, generator=_seeded(1)), 20
    ),
    "mlp_actor_tanh_hidden": Module(
        lambda: MLPActor(
            3, 2, (16,), activation=nn.Tanh, action_limit=[1.0, 3.0], generator=_seeded(2)
        ),
        5,  # measured 2.2
    ),
    "rbf_network": Module(
        lambda: RBFNetwork(
            3, 2, 10, lengthscales=[0.5, 1.0, 2.0], weight_std=1.0, generator=_seeded(3)
        ),
        3,  # measured 1.3
    ),
    "pilco_rbf_policy": Module(lambda: _pilco_policy(False), 5),  # measured 2.0
    "pilco_hybrid_policy": Module(lambda: _pilco_policy(True), 7),  # measured 3.0
}
HYBRID_FACTOR = 10.0  # measured at most 4.9 (the paper relevance with the clip)
SB3_FACTOR = 8.0  # measured at most 3.4 (the SAC hybrid)


@pytest.mark.parametrize("width", MODULE_WIDTHS)
@pytest.mark.parametrize("name", MODULES)
def test_learned_module_encloses_dense_samples_and_autograd(name, width):
    _check_module(MODULES[name].build(), width, seed=int(1e3 * width))


@pytest.mark.parametrize("name", MODULES)
def test_learned_module_enclosure_shrinks_with_the_box(name):
    centre, _ = _observation_boxes(1.0, seed=9)
    _check_tight(MODULES[name].build(), centre, MODULES[name].factor)


@functools.cache
def _large_actor() -> MLPActor:
    """The DDPG paper's actor size, 400 x 300 (leoc's MLPActor default), ReLU and tanh."""
    actor = MLPActor(3, 1, action_limit=2.0, generator=_seeded(6))
    assert [layer.out_features for layer in actor.net if isinstance(layer, nn.Linear)] == [
        400,
        300,
        1,
    ]
    return actor


# Measured 144: naive interval products through 400 and 300 units of random signs lose their
# cancellations (the wrapping effect); the derivative enclosure, which the proof's mean-value
# form uses, stays exact to rounding on boxes without a kink.
LARGE_FACTOR = 300.0


@pytest.mark.parametrize("width", MODULE_WIDTHS)
def test_a_400_by_300_actor_encloses_dense_samples_and_autograd(width):
    _check_module(_large_actor(), width, seed=int(1e3 * width))


def test_a_400_by_300_actor_enclosure_shrinks_with_the_box():
    centre, _ = _observation_boxes(1.0, seed=9)
    _check_tight(_large_actor(), centre, LARGE_FACTOR)


# ---- hybrids: every relevance design and saturation, through build_hybrid -----------------

RELEVANCES = ("paper", "paper_power_2", "floored", "precision", "lyapunov", "roa")
SATURATIONS = ("clip", "sin", "tanh", "none")
RHO = 2.0  # a level for the designs that scale by one (a proof's, in a run)


def _relevance_design(relevance: str) -> tuple[HybridSpec, dict]:
    """The spec of each relevance design and its plant data, as ``hybrid_design`` resolves
    them (the level given here instead of proved: these tests need no certificate)."""
    system, design = _pendulum()
    layout = system.observation.to_list()
    P = np.asarray(design.P).tolist()
    if relevance == "paper":
        return HybridSpec(r_min=None, relevance_power=1.0), {}
    if relevance == "paper_power_2":
        return HybridSpec(r_min=None), {}
    if relevance == "floored":  # leoc's default: p = 2 and Lambda floored (r >= 0.5 on V <= rho)
        floor = relevance_floor(layout, P, RHO, 0.5, 2.0)
        return HybridSpec(), {"lambda_floor": floor.tolist(), "rho": RHO, "r_min": 0.5}
    if relevance == "precision":
        return HybridSpec(relevance_parametrisation="precision", lambda_init=0.7), {}
    if relevance == "lyapunov":
        return HybridSpec("lyapunov"), {"obs_layout": layout, "lyapunov_matrix": P, "rho": RHO}
    state = np.asarray(system.operating_state).tolist()
    data = {"obs_layout": layout, "operating_state": state, "lyapunov_matrix": P, "rho_in": 0.5}
    return HybridSpec("roa", width_init=1.5), data


def _hybrid(relevance: str, saturation: str, learned: nn.Module) -> nn.Module:
    system, design = _pendulum()
    spec, data = _relevance_design(relevance)
    resolved = HybridDesign(design.W, design.b, system.operating_obs, data)
    return build_hybrid(spec, resolved, learned, action_limit=2.0, saturation=saturation)


def _learned_part() -> RBFNetwork:
    return RBFNetwork(3, 1, 10, weight_std=2.0, generator=_seeded(8))


KINDS = {
    "paper": "paper",
    "paper_power_2": "PaperRelevance",
    "floored": "FlooredRelevance",
    "precision": "PrecisionRelevance",
    "lyapunov": "LyapunovRelevance",
    "roa": "ROARelevance",
}


@pytest.mark.parametrize("saturation", SATURATIONS)
@pytest.mark.parametrize("relevance", RELEVANCES)
def test_hybrid_policy_with_each_relevance_and_saturation_on_jets(relevance, saturation):
    hybrid = _hybrid(relevance, saturation, _learned_part())
    assert hybrid.relevance_kind == KINDS[relevance]
    # The Lyapunov relevance's (y P) . y loses its sign to the dependency of interval products
    # on wide boxes: there 1 + d may contain 0 and r is (soundly) unbounded, which a proof
    # rejects; its boxes are narrower.
    widest = 0.03 if relevance == "lyapunov" else 0.3
    for width in (widest, 1e-3):
        _check_module(hybrid, width, seed=int(1e4 * width), count=1000)
    centre, _ = _observation_boxes(1.0, seed=9)
    _check_tight(hybrid, centre, HYBRID_FACTOR)


def test_the_roa_relevance_is_exactly_one_with_zero_slope_on_its_flat_top():
    """A box inside V <= rho_in: the enclosure of r is [1, 1] up to rounding and its slope 0
    (the clamp proves t = 0 on the whole box), so the proof sees the LQR there."""
    hybrid = _hybrid("roa", "clip", _learned_part())
    point = torch.as_tensor(_pendulum()[0].operating_obs, dtype=DTYPE)[None]
    with torch.no_grad():
        relevance = hybrid.relevance(box_jet(point, torch.full_like(point, 1e-3)))
    assert abs(float(relevance.mid[0, 0]) - 1.0) + float(relevance.rad[0, 0]) < 1e-12
    assert float(relevance.dmid.abs().max()) == 0.0 and float(relevance.drad.max()) < 1e-300


class _Counting(nn.Module):
    """A learned part that counts the boxes it is evaluated on."""

    def __init__(self, inner: nn.Module) -> None:
        super().__init__()
        self.inner, self.boxes = inner, 0

    def forward(self, x):
        self.boxes += x.shape[0]
        return self.inner(x)


def test_the_roa_hybrid_skips_its_learned_part_on_flat_top_boxes():
    """Boxes inside the flat top get G's enclosure exactly and never reach H (a proof there
    costs what the LQR's does); in a mixed batch H sees only the other boxes, whose enclosures
    are those of the plain blend r G + (1 - r) H."""
    counting = _Counting(_learned_part())
    hybrid = _hybrid("roa", "clip", counting)
    point = torch.as_tensor(_pendulum()[0].operating_obs, dtype=DTYPE)[None]
    inside = point.repeat(4, 1) + torch.as_tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.01]] * 2)
    outside = point.repeat(3, 1) + torch.as_tensor([[0.0, 0.0, 2.0]] * 3)
    radius = torch.full((7, 3), 1e-3, dtype=DTYPE)
    boxes = box_jet(torch.cat([inside, outside]), radius)
    counting.boxes = 0  # building the hybrid probed its learned part
    with torch.no_grad():
        blended = hybrid.blend(boxes)
        linear = hybrid.linear(boxes)
        r = hybrid.relevance(boxes)
        plain = r * linear + (1.0 - r) * counting.inner(boxes)
    assert counting.boxes == 3
    assert torch.equal(blended.mid[:4], linear.mid[:4]) and torch.equal(
        blended.rad[:4], linear.rad[:4]
    )
    assert torch.equal(blended.dmid[:4], linear.dmid[:4])
    assert torch.equal(blended.mid[4:], plain.mid[4:]) and torch.equal(
        blended.rad[4:], plain.rad[4:]
    )
    assert torch.equal(blended.drad[4:], plain.drad[4:])
    # The skipped boxes are really in the flat top: r == 1 at dense samples of each.
    offsets = torch.as_tensor(np.random.default_rng(3).uniform(-1, 1, (500, 3)))
    for row in range(4):
        samples = inside[row] + offsets * 1e-3
        assert torch.all(hybrid.relevance(samples) == 1.0)


# ---- the quadratic form of the Lyapunov-based relevances ---------------------------------


def _cartpole_level_boxes(half: float, count: int = 200, seed: int = 0):
    """Boxes of half-width ``half`` in the coordinates w = L^T (x - a) of the cart-pole LQR's
    V (as a proof makes them), centres at |w| <= 3; returns the ROA relevance's V of the
    observation of a box's state (a function of w), the centres, and that V's plain interval
    product ``((z P) z).sum()`` on the boxes (the enclosure the relevance had before)."""
    system = make_system("cartpole")
    P = torch.as_tensor(design_lqr(system).P, dtype=DTYPE)
    inverse = torch.linalg.inv(torch.linalg.cholesky(P)).T  # z = L^-T w
    operating = torch.as_tensor(system.operating_state, dtype=DTYPE)
    relevance = ROARelevance(system.obs_layout, system.operating_state, P, 18.0, 1.0, False)
    generator = torch.Generator().manual_seed(seed)
    direction = torch.randn(count, 4, generator=generator, dtype=DTYPE)
    length = 3.0 * torch.rand(count, 1, generator=generator, dtype=DTYPE)
    centre = direction / direction.norm(dim=1, keepdim=True) * length

    def observation(w):
        if isinstance(w, Jet):
            return system.observation.observe(box_jet(w.mid, w.rad, inverse) + operating)
        return system.observation.observe(w @ inverse.T + operating)

    with torch.no_grad():
        z = relevance.deviation(observation(Jet(centre, torch.full_like(centre, half), None, None)))
        plain = ((z @ P) * z).sum(-1)
    return (lambda w: relevance.lyapunov(observation(w))), centre, plain


@pytest.mark.parametrize("half", [0.35, 0.1, 0.02])
def test_the_level_enclosure_holds_and_beats_the_plain_product_on_proof_boxes(half):
    """Sound: the ROA relevance's V at dense samples of each box (and its Jacobian) lies in the
    enclosure. Tight: the median over boxes of the enclosure's excess over the sampled maximum
    is at most 0.75 times that of the plain interval product ((z P) z).sum() (measured 0.56,
    0.33 and 0.17 at half-widths 0.35, 0.1 and 0.02 with the corner bound; 0.63, 0.42 and 0.28
    with the sum of exact squares of L^T z alone, which keeps the dependency the product
    loses); the plain rule itself gives 1."""
    level, centre, plain = _cartpole_level_boxes(half)
    enclosure, values, _ = _check_sound(level, centre, torch.full_like(centre, half), count=500)
    sampled_max = values.amax(dim=(1, 2))
    excess = (enclosure.mid + enclosure.rad)[:, 0] - sampled_max
    plain_excess = plain.high - sampled_max
    assert torch.all(excess >= 0.0)
    assert float((excess / plain_excess).median()) <= 0.75


@pytest.mark.parametrize("size", [2, 4, 6])
def test_the_level_top_is_the_exact_largest_value_over_the_box_of_z(size):
    """Up to ``QUADRATIC_CORNER_DIM`` the enclosure's upper end is at least the exact maximum
    of z^T P z over the box of z (the largest corner value, computed in rationals at the
    box's ends; a convex quadratic is largest at a corner) and within 1e-12 of it (relative),
    on random SPD P (condition numbers up to 1e4) and boxes, some straddling 0; an unbounded
    box gives an enclosure that is not finite (which a proof rejects)."""
    from leoc.control.intervals import QUADRATIC_CORNER_DIM, quadratic_form

    assert size <= QUADRATIC_CORNER_DIM
    rng = np.random.default_rng(size)
    basis, _ = np.linalg.qr(rng.standard_normal((size, size)))
    P = torch.as_tensor((basis * np.logspace(0, 4, size)) @ basis.T)
    P = 0.5 * (P + P.T)
    centre = torch.as_tensor(rng.uniform(-2.0, 2.0, (40, size)))
    radius = torch.as_tensor(rng.uniform(0.0, 1.0, (40, size)))
    top = quadratic_form(box_jet(centre, radius), P)
    top = (top.mid + top.rad)[:, 0]
    exact_P = [[Fraction(float(P[i, j])) for j in range(size)] for i in range(size)]
    for row in range(40):
        ends = [
            (Fraction(float(c)) - Fraction(float(r)), Fraction(float(c)) + Fraction(float(r)))
            for c, r in zip(centre[row], radius[row], strict=True)
        ]
        largest = max(
            sum(z[i] * exact_P[i][j] * z[j] for i in range(size) for j in range(size))
            for z in itertools.product(*ends)
        )
        assert Fraction(float(top[row])) >= largest
        assert float(top[row]) <= float(largest) * (1.0 + 1e-12) + 1e-300
    unbounded = quadratic_form(
        Jet(centre[:1], torch.full_like(radius[:1], math.inf), None, None), P
    )
    assert not math.isfinite((unbounded.mid + unbounded.rad).item())  # a proof rejects it


def test_the_factor_error_bounds_the_exact_cholesky_residual():
    """``_factor_error`` >= ||P - L L^T||_2 for L the computed Cholesky factor, the residual
    computed exactly in rationals (an upper bound of the 2-norm: its Frobenius norm is not
    needed, the exact 2-norm is at most the exact Frobenius norm, checked squared), on SPD
    matrices with condition numbers up to 1e10; and not vacuous: below 1e3 S u ||P||_F."""
    from leoc.control.intervals import _factor_error

    rng = np.random.default_rng(5)
    for size, condition in ((4, 10.0), (4, 1e6), (8, 1e10), (3, 1.0)):
        basis, _ = np.linalg.qr(rng.standard_normal((size, size)))
        spectrum = np.logspace(0, math.log10(condition), size) * rng.uniform(0.5, 50.0)
        P = torch.as_tensor((basis * spectrum) @ basis.T)
        P = 0.5 * (P + P.T)
        L = torch.linalg.cholesky(P)
        bound = _factor_error(P, L)
        exact = [
            [
                Fraction(float(P[i, j]))
                - sum(Fraction(float(L[i, k])) * Fraction(float(L[j, k])) for k in range(size))
                for j in range(size)
            ]
            for i in range(size)
        ]
        frobenius_squared = sum(entry * entry for row in exact for entry in row)
        assert Fraction(bound) ** 2 >= frobenius_squared
        assert bound <= 1e3 * size * 2.0**-53 * float(torch.linalg.matrix_norm(P))


# ---- SB3 actors built by leoc: their float64 physical policies -----------------------------

SB3_CASES = {
    "ddpg_baseline": ("ddpg", None),
    "td3_hybrid_default": ("td3", HybridSpec()),
    "ddpg_hybrid_roa": ("ddpg", HybridSpec("roa")),
    "sac_baseline": ("sac", None),
    "sac_hybrid_default": ("sac", HybridSpec()),
}


@functools.cache
def _sb3_policy(name: str) -> nn.Module:
    """``physical_policy`` (what leoc evaluates and certifies) of an actor from
    ``build_model``, every actor parameter moved off its initialisation (the output layer's
    U(+/-0.003) would leave the learned part nearly constant)."""
    from leoc.sb3 import DDPGConfig, build_model, physical_policy

    algo, spec = SB3_CASES[name]
    config = DDPGConfig.for_system(
        "pendulum", algo, hybrid=spec, actor_hidden=(16, 16), critic_hidden=(16, 16)
    )
    model = build_model(config, seed=0, env=make_env("pendulum"))
    generator = _seeded(13)
    with torch.no_grad():
        for param in model.actor.parameters():
            param.add_(0.5 * torch.randn(param.shape, generator=generator))
    return physical_policy(model.actor)


@pytest.mark.parametrize("name", SB3_CASES)
def test_sb3_actor_physical_policy_on_jets(name):
    policy = _sb3_policy(name)
    assert policy.is_hybrid is (SB3_CASES[name][1] is not None)
    for width in MODULE_WIDTHS:
        _check_module(policy, width, seed=int(1e4 * width), count=1000)
    centre, _ = _observation_boxes(1.0, seed=9)
    _check_tight(policy, centre, SB3_FACTOR)
