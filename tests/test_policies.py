"""Tests for leoc.policies: known answers, independent numpy recomputations and the hybrid's
identities pi(a) = G(a), dpi/dx(a) = W (Zhang & Capel, L4DC 2021, eq. 4-5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torch import nn

from leoc.policies import (
    SATURATION_MODES,
    HybridOutput,
    HybridPolicy,
    LinearController,
    MLPActor,
    RBFNetwork,
    saturate,
)

DTYPE = torch.float64
IDENTITY_ATOL = 1e-10  # the brief's tolerance on dpi/dx(a) = W
VALUE_ATOL = 1e-12  # round-off budget for float64 recomputations of O(10) quantities
FD_STEP = 1e-6  # finite-difference step, in units of sqrt(lambda_i) (the width of r)
FD_ROUNDOFF = 1e-6  # >> eps |pi| / h ~ 2e-16 * 50 / 1e-7; << the O(1) slope error of a kink
HIDDEN = (16, 16)  # small networks keep the suite fast
NUM_BASIS = 10
LOG10_LAMBDA_RANGE = (-2.0, 2.0)
FAST = settings(max_examples=30, deadline=None)

seeds = st.integers(min_value=0, max_value=2**31 - 1)
obs_dims = st.integers(min_value=1, max_value=5)
act_dims = st.integers(min_value=1, max_value=3)
kinds = st.sampled_from(["mlp", "rbf"])


# ----------------------------------------------------------------------------- helpers


def make_nonlinear(kind: str, obs_dim: int, act_dim: int, seed: int) -> nn.Module:
    """A random smooth H: tanh MLP or RBF network with random length-scales."""
    gen = torch.Generator().manual_seed(seed)
    if kind == "mlp":
        return MLPActor(obs_dim, act_dim, HIDDEN, activation=nn.Tanh, generator=gen)
    scales = torch.exp(torch.randn(act_dim, obs_dim, generator=gen, dtype=DTYPE))
    return RBFNetwork(
        obs_dim, act_dim, NUM_BASIS, lengthscales=scales, weight_std=1.0, generator=gen
    )


def random_setup(seed: int, obs_dim: int, act_dim: int):
    """Random W (F, D), b (F,), operating point a (D,) and lambda (D,), log-uniform."""
    rng = np.random.default_rng(seed)
    W = rng.standard_normal((act_dim, obs_dim))
    b = rng.standard_normal(act_dim)
    a = 2.0 * rng.standard_normal(obs_dim)
    lam = 10.0 ** rng.uniform(*LOG10_LAMBDA_RANGE, size=obs_dim)
    return rng, W, b, a, lam


def numpy_distance(x: np.ndarray, a: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """d(x) = sum_i (x_i - a_i)^2 / lambda_i by explicit loops, shape (B, 1) for x (B, D)."""
    out = np.zeros((x.shape[0], 1))
    for n in range(x.shape[0]):
        for i in range(x.shape[1]):
            out[n, 0] += (x[n, i] - a[i]) ** 2 / lam[i]
    return out


def t(array) -> torch.Tensor:
    return torch.as_tensor(np.asarray(array), dtype=DTYPE)


# ----------------------------------------------------------------------------- hybrid identities


@FAST
@given(
    seed=seeds,
    obs_dim=obs_dims,
    act_dim=act_dims,
    kind=kinds,
    saturation=st.sampled_from(["clip", "sin", "tanh", "none"]),
)
def test_hybrid_equals_linear_part_to_first_order_at_operating_point(
    seed, obs_dim, act_dim, kind, saturation
):
    rng, W, b, a, lam = random_setup(seed, obs_dim, act_dim)
    if saturation in ("sin", "tanh"):
        b = -W @ a  # smooth squashes keep value and slope only at 0, so G(a) = 0
    g_a = W @ a + b
    limit = np.abs(g_a).max() + rng.uniform(0.1, 2.0, size=act_dim)  # |G(a)| < limit
    nonlinear = make_nonlinear(kind, obs_dim, act_dim, seed)
    policy = HybridPolicy(
        LinearController(W, b),
        nonlinear,
        a,
        lambda_init=lam,
        action_limit=None if saturation == "none" else limit,
        saturation=saturation,
    )
    a_t = t(a)

    np.testing.assert_allclose(policy(a_t).detach().numpy(), g_a, rtol=0, atol=VALUE_ATOL)
    jac = torch.autograd.functional.jacobian(policy, a_t).numpy()
    assert jac.shape == (act_dim, obs_dim)
    np.testing.assert_allclose(jac, W, rtol=0, atol=IDENTITY_ATOL)

    # One-sided finite differences, independent of autograd (which returns a zero subgradient
    # at a kink, so it alone would miss e.g. d = sum |x_i - a_i| / lambda_i). With step h along
    # e_i, pi - G = (1 - r)(H - G) and 1 - r <= 2 d = 2 h^2 / lambda_i, so the slope error is
    # at most 2 h |H - G| / lambda_i (doubled for the change of H - G over the step).
    steps = FD_STEP * np.sqrt(lam)
    gap = np.abs(g_a - nonlinear(a_t).detach().numpy())
    for i in range(obs_dim):
        tol = 2.0 * (2.0 * steps[i] * gap / lam[i]) + FD_ROUNDOFF
        for sign in (1.0, -1.0):
            shift = np.zeros(obs_dim)
            shift[i] = sign * steps[i]
            slope = (policy(a_t + t(shift)) - policy(a_t)).detach().numpy() / shift[i]
            assert np.all(np.abs(slope - W[:, i]) <= tol), (i, sign, slope, W[:, i], tol)

    # The identity is not vacuous: H's own Jacobian at a, and pi's away from a, differ from W.
    jac_h = torch.autograd.functional.jacobian(nonlinear, a_t).numpy()
    assert np.abs(jac_h - W).max() > IDENTITY_ATOL
    x_off = a_t + t(np.sqrt(lam))  # d = D, r = 1 / (1 + D)^2
    blend_jac = torch.autograd.functional.jacobian(policy.blend, x_off).numpy()
    assert np.abs(blend_jac - W).max() > IDENTITY_ATOL


def test_hybrid_identities_hold_for_batched_input_at_operating_point():
    rng, W, b, a, lam = random_setup(0, 4, 2)
    policy = HybridPolicy(LinearController(W, b), make_nonlinear("mlp", 4, 2, 0), a, lam)
    u = policy(t(a)[None, None, :])
    assert u.shape == (1, 1, 2)
    np.testing.assert_allclose(u.detach().numpy()[0, 0], W @ a + b, rtol=0, atol=VALUE_ATOL)


# ----------------------------------------------------------------------------- relevance


@FAST
@given(seed=seeds, obs_dim=obs_dims, kind=kinds)
def test_relevance_in_unit_interval_and_one_only_at_operating_point(seed, obs_dim, kind):
    rng, W, b, a, lam = random_setup(seed, obs_dim, 1)
    policy = HybridPolicy(
        LinearController(W, b), make_nonlinear(kind, obs_dim, 1, seed), a, lambda_init=lam
    )
    x = t(a + rng.standard_normal((64, obs_dim)) * rng.uniform(0.1, 10.0))
    r = policy.relevance(x)
    assert r.shape == (64, 1)
    assert bool((r > 0).all()) and bool((r <= 1).all())
    d = policy.distance(x)
    assert bool((r[d > VALUE_ATOL] < 1).all())
    assert policy.relevance(t(a)).item() == 1.0
    assert policy.distance(t(a)).item() == 0.0


@pytest.mark.parametrize("lambda_shape", ["scalar", "vector"])
def test_distance_and_relevance_match_numpy_loops(lambda_shape):
    rng, W, b, a, lam = random_setup(3, 4, 2)
    if lambda_shape == "scalar":
        lam_init, lam = 0.7, np.full(4, 0.7)
    else:
        lam_init = lam
    policy = HybridPolicy(LinearController(W, b), make_nonlinear("rbf", 4, 2, 3), a, lam_init)
    x = a + rng.standard_normal((3, 5, 4))
    d_np = numpy_distance(x.reshape(-1, 4), a, lam).reshape(3, 5, 1)
    r_np = 1.0 / (1.0 + d_np) ** 2
    np.testing.assert_allclose(policy.lambda_.detach().numpy(), lam, rtol=1e-14)
    np.testing.assert_allclose(policy.distance(t(x)).detach().numpy(), d_np, rtol=1e-13)
    np.testing.assert_allclose(policy.relevance(t(x)).detach().numpy(), r_np, rtol=1e-13)


def test_blend_forward_and_return_relevance_are_consistent():
    rng, W, b, a, _ = random_setup(5, 3, 2)
    lam = np.array([10.0, 3.0, 30.0])
    nonlinear = make_nonlinear("mlp", 3, 2, 5)
    limit = np.array([0.5, 3.0])
    b = 0.4 * np.tanh(b) - W @ a  # |G(a)| < limit, required by "clip"
    policy = HybridPolicy(LinearController(W, b), nonlinear, a, lam, action_limit=limit)
    x = t(a + 2.0 * rng.standard_normal((20, 3)))
    r_np = 1.0 / (1.0 + numpy_distance(x.numpy(), a, lam)) ** 2
    g_np = x.numpy() @ W.T + b
    h_np = nonlinear(x).detach().numpy()
    blend_np = r_np * g_np + (1.0 - r_np) * h_np
    assert np.any(np.abs(blend_np) > limit) and np.any(np.abs(blend_np) < limit)  # clip matters
    np.testing.assert_allclose(policy.blend(x).detach().numpy(), blend_np, atol=VALUE_ATOL)
    out = policy(x, return_relevance=True)
    assert isinstance(out, HybridOutput)
    u, r = out
    np.testing.assert_allclose(u.detach().numpy(), np.clip(blend_np, -limit, limit), atol=1e-12)
    np.testing.assert_allclose(r.detach().numpy(), r_np, rtol=1e-13)
    torch.testing.assert_close(policy(x), u)


# ----------------------------------------------------------------------------- limits in lambda


def points_outside_ball(rng, a: np.ndarray, radius_min: float, radius_max: float, n: int):
    """Random points with radius_min <= ||x - a|| <= radius_max."""
    direction = rng.standard_normal((n, a.size))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return a + direction * rng.uniform(radius_min, radius_max, size=(n, 1))


@pytest.mark.parametrize("saturation", ["none", "clip"])
def test_small_lambda_recovers_nonlinear_part(saturation):
    """lambda -> 0: |pi - H| <= r |G - H| <= (lambda_max / ||x - a||^2)^2 |G - H| -> 0.

    d >= ||x - a||^2 / lambda_max gives the second bound. With "clip", H = MLP with a tanh
    output lies inside the limits, and clipping is 1-Lipschitz, so |clip(beta) - H| <= |beta - H|.
    (The paper states this limit as lambda -> infinity; with d = (x-a)^T Lambda^-1 (x-a), as in its
    eq. 5, it is lambda -> 0.)
    """
    obs_dim, act_dim, limit = 3, 2, 2.0
    rng, W, b, a, _ = random_setup(11, obs_dim, act_dim)
    if saturation == "clip":
        b = np.tanh(b) - W @ a  # |G(a)| < 1 < limit, as HybridPolicy requires
    nonlinear = MLPActor(
        obs_dim, act_dim, HIDDEN, action_limit=limit, generator=torch.Generator().manual_seed(1)
    )
    x = t(points_outside_ball(rng, a, 0.5, 3.0, 200))
    dist_sq = ((x - t(a)) ** 2).sum(-1, keepdim=True).numpy()
    h = nonlinear(x).detach().numpy()
    g = x.numpy() @ W.T + b
    errors = []
    for lam in (1e-2, 1e-4, 1e-8):
        policy = HybridPolicy(
            LinearController(W, b),
            nonlinear,
            a,
            lambda_init=lam,
            action_limit=None if saturation == "none" else limit,
            saturation=saturation,
        )
        err = np.abs(policy(x).detach().numpy() - h)
        bound = (lam / dist_sq) ** 2 * np.abs(g - h)
        assert np.all(err <= bound + VALUE_ATOL)
        errors.append(err.max())
    assert errors[0] > errors[1] > errors[2]
    assert errors[-1] < VALUE_ATOL


def test_large_lambda_recovers_linear_part():
    """lambda -> infinity: |pi - G| = (1 - r)|G - H| <= 2 d |G - H| <= 2 ||x-a||^2/lambda |G - H|.

    1 - (1 + d)^-2 <= 2 d for d >= 0, since (1 + d)^2 (1 - 2 d) <= 1 there.
    """
    obs_dim, act_dim = 4, 1
    rng, W, b, a, _ = random_setup(12, obs_dim, act_dim)
    nonlinear = make_nonlinear("rbf", obs_dim, act_dim, 12)
    x = t(points_outside_ball(rng, a, 0.5, 3.0, 200))
    dist_sq = ((x - t(a)) ** 2).sum(-1, keepdim=True).numpy()
    h = nonlinear(x).detach().numpy()
    g = x.numpy() @ W.T + b
    errors = []
    for lam in (1e2, 1e4, 1e8):
        policy = HybridPolicy(LinearController(W, b), nonlinear, a, lam, saturation="none")
        err = np.abs(policy(x).detach().numpy() - g)
        assert np.all(err <= 2.0 * dist_sq / lam * np.abs(g - h) + VALUE_ATOL)
        errors.append(err.max())
    assert errors[0] > errors[1] > errors[2]
    assert errors[-1] < 1e-6


# ----------------------------------------------------------------------------- gradients


@pytest.mark.parametrize("kind", ["mlp", "rbf"])
def test_gradients_reach_nonlinear_parameters_and_log_lambda(kind):
    rng, W, b, a, lam = random_setup(21, 3, 2)
    nonlinear = make_nonlinear(kind, 3, 2, 21)
    policy = HybridPolicy(LinearController(W, b), nonlinear, a, lam)
    names = {name for name, _ in policy.named_parameters()}
    assert "log_lambda" in names
    assert not any(name.startswith("linear.") for name in names)  # W, b are frozen buffers
    assert names - {"log_lambda"} == {"nonlinear." + n for n, _ in nonlinear.named_parameters()}
    x = t(a + rng.standard_normal((32, 3)))
    policy(x).sum().backward()
    for name, param in policy.named_parameters():
        assert param.grad is not None and float(param.grad.abs().sum()) > 0, name


def test_relevance_gradient_in_log_lambda_matches_closed_form():
    """dr/dlog(lambda_i) = 2 (x_i - a_i)^2 / (lambda_i (1 + d)^3)."""
    rng, W, b, a, lam = random_setup(22, 3, 1)
    policy = HybridPolicy(LinearController(W, b), make_nonlinear("rbf", 3, 1, 22), a, lam)
    x = a + rng.standard_normal(3)
    policy.relevance(t(x)).sum().backward()
    d = np.sum((x - a) ** 2 / lam)
    expected = 2.0 * (x - a) ** 2 / (lam * (1.0 + d) ** 3)
    np.testing.assert_allclose(policy.log_lambda.grad.numpy(), expected, rtol=1e-12)


def test_frozen_lambda_is_a_buffer_without_gradient():
    rng, W, b, a, lam = random_setup(23, 3, 1)
    policy = HybridPolicy(
        LinearController(W, b), make_nonlinear("mlp", 3, 1, 23), a, lam, learn_lambda=False
    )
    assert "log_lambda" in dict(policy.named_buffers())
    assert "log_lambda" not in dict(policy.named_parameters())
    policy(t(a + rng.standard_normal((8, 3)))).sum().backward()
    assert policy.log_lambda.grad is None
    np.testing.assert_allclose(policy.lambda_.numpy(), lam, rtol=1e-14)


def test_state_dict_round_trip_reproduces_outputs():
    rng, W, b, a, lam = random_setup(24, 3, 2)
    policy = HybridPolicy(
        LinearController(W, b - W @ a), make_nonlinear("mlp", 3, 2, 1), a, lam, action_limit=2.0
    )
    other = HybridPolicy(
        LinearController(np.zeros((2, 3))),
        make_nonlinear("mlp", 3, 2, 2),
        np.zeros(3),
        lambda_init=1.0,
        action_limit=5.0,
    )
    other.load_state_dict(policy.state_dict())
    x = t(rng.standard_normal((10, 3)))
    torch.testing.assert_close(other(x), policy(x), rtol=0, atol=0)


# ----------------------------------------------------------------------------- components


def test_linear_controller_matches_numpy():
    rng = np.random.default_rng(31)
    W, b = rng.standard_normal((2, 4)), rng.standard_normal(2)
    ctrl = LinearController(W, b)
    assert (ctrl.obs_dim, ctrl.act_dim) == (4, 2)
    assert set(dict(ctrl.named_buffers())) == {"W", "b"} and not list(ctrl.parameters())
    x = rng.standard_normal((3, 5, 4))
    expected = np.einsum("fd,nmd->nmf", W, x) + b
    np.testing.assert_allclose(ctrl(t(x)).numpy(), expected, atol=VALUE_ATOL)
    W[0, 0] += 1.0  # the controller holds a copy
    np.testing.assert_allclose(ctrl(t(x)).numpy(), expected, atol=VALUE_ATOL)
    np.testing.assert_array_equal(LinearController(W).b.numpy(), np.zeros(2))


def test_rbf_matches_numpy_loops():
    rng = np.random.default_rng(32)
    obs_dim, act_dim, n = 3, 2, 7
    centres = rng.standard_normal((n, obs_dim))
    weights = rng.standard_normal((act_dim, n))
    scales = np.exp(rng.standard_normal((act_dim, obs_dim)))
    net = RBFNetwork(obs_dim, act_dim, n, centres, weights, scales)
    x = rng.standard_normal((6, obs_dim)) * 2.0
    expected = np.zeros((6, act_dim))
    for k in range(6):
        for f in range(act_dim):
            for i in range(n):
                exponent = sum(
                    (x[k, d] - centres[i, d]) ** 2 / scales[f, d] ** 2 for d in range(obs_dim)
                )
                expected[k, f] += weights[f, i] * math.exp(-0.5 * exponent)
    np.testing.assert_allclose(net(t(x)).detach().numpy(), expected, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(net.lengthscales.detach().numpy(), scales, rtol=1e-14)
    assert (net.num_basis, net.obs_dim, net.act_dim) == (n, obs_dim, act_dim)
    assert net(t(x).reshape(2, 3, obs_dim)).shape == (2, 3, act_dim)


def test_rbf_random_init_follows_generator():
    obs_dim, act_dim, n, mean, std, wstd = 2, 3, 5, np.array([1.0, -2.0]), 0.5, 0.2
    net = RBFNetwork(
        obs_dim,
        act_dim,
        n,
        generator=torch.Generator().manual_seed(7),
        centre_mean=mean,
        centre_std=std,
        weight_std=wstd,
    )
    gen = torch.Generator().manual_seed(7)
    centres = t(mean) + std * torch.randn(n, obs_dim, generator=gen, dtype=DTYPE)
    weights = wstd * torch.randn(act_dim, n, generator=gen, dtype=DTYPE)
    torch.testing.assert_close(net.centres.detach(), centres, rtol=0, atol=1e-15)
    torch.testing.assert_close(net.weights.detach(), weights, rtol=0, atol=1e-15)
    torch.testing.assert_close(net.lengthscales.detach(), torch.ones(act_dim, obs_dim, dtype=DTYPE))
    assert net.centres.dtype == DTYPE
    shared = RBFNetwork(obs_dim, act_dim, n, lengthscales=[0.5, 2.0])
    np.testing.assert_allclose(shared.lengthscales.detach().numpy(), [[0.5, 2.0]] * act_dim)


def test_mlp_matches_numpy_and_respects_action_limit():
    actor = MLPActor(3, 2, (5,), generator=torch.Generator().manual_seed(0))
    bounded = MLPActor(3, 2, (5,), action_limit=[1.0, 0.5])
    bounded.load_state_dict(actor.state_dict() | {"action_limit": torch.tensor([1.0, 0.5])})
    (w0, b0), (w1, b1) = [
        (layer.weight.detach().numpy(), layer.bias.detach().numpy())
        for layer in actor.net
        if isinstance(layer, nn.Linear)
    ]
    x = np.random.default_rng(33).standard_normal((9, 3)) * 5.0
    z = np.maximum(x @ w0.T + b0, 0.0) @ w1.T + b1
    np.testing.assert_allclose(actor(t(x)).detach().numpy(), z, atol=VALUE_ATOL)
    np.testing.assert_allclose(
        bounded(t(x)).detach().numpy(), np.array([1.0, 0.5]) * np.tanh(z), atol=VALUE_ATOL
    )
    big = MLPActor(3, 1, (8,), action_limit=2.0)
    assert bool((big(t(x * 100)).abs() <= 2.0).all())
    assert actor.net[0].weight.dtype == DTYPE
    assert len([m for m in MLPActor(3, 1).net if isinstance(m, nn.Linear)]) == 3


def test_mlp_seeding_is_reproducible():
    def params(actor):
        return torch.cat([p.detach().flatten() for p in actor.parameters()])

    def make(seed):
        return MLPActor(4, 2, (8, 8), generator=torch.Generator().manual_seed(seed))

    torch.testing.assert_close(params(make(1)), params(make(1)), rtol=0, atol=0)
    assert not torch.equal(params(make(1)), params(make(2)))
    torch.manual_seed(5)
    first = params(MLPActor(4, 2, (8,)))
    torch.manual_seed(5)
    torch.testing.assert_close(params(MLPActor(4, 2, (8,))), first, rtol=0, atol=0)
    bound = 1.0 / math.sqrt(4)  # PyTorch's default Linear init U(-1/sqrt(fan_in), 1/sqrt(fan_in))
    assert float(make(3).net[0].weight.detach().abs().max()) <= bound


# ----------------------------------------------------------------------------- saturation


@pytest.mark.parametrize("mode", SATURATION_MODES)
def test_saturate_matches_numpy_and_has_unit_slope_at_zero(mode):
    limit = np.array([0.5, 2.0, 3.0])
    u = np.linspace(-10.0, 10.0, 41)[:, None] * np.ones(3)
    expected = {
        "clip": np.clip(u, -limit, limit),
        "sin": limit * np.sin(u / limit),
        "tanh": limit * np.tanh(u / limit),
        "none": u,
    }[mode]
    np.testing.assert_allclose(saturate(t(u), t(limit), mode).numpy(), expected, atol=1e-14)
    np.testing.assert_allclose(saturate(t(u), 2.0, mode).numpy()[:, 1], expected[:, 1], atol=1e-14)
    zero = torch.zeros(3, dtype=DTYPE, requires_grad=True)
    jac = torch.autograd.functional.jacobian(lambda v: saturate(v, t(limit), mode), zero)
    np.testing.assert_allclose(jac.numpy(), np.eye(3), atol=1e-15)
    if mode != "none":
        assert bool((saturate(t(u), t(limit), mode).abs() <= t(limit) + 1e-15).all())


def test_clip_is_exact_inside_limits_and_none_limit_is_identity():
    limit = 1.5
    u = torch.linspace(-1.4, 1.4, 15, dtype=DTYPE, requires_grad=True)
    out = saturate(u, limit, "clip")
    assert torch.equal(out, u)
    out.sum().backward()
    assert torch.equal(u.grad, torch.ones_like(u))
    for mode in SATURATION_MODES:
        assert saturate(u, None, mode) is u
    # The smooth squashes preserve neither value nor slope away from 0.
    assert abs(saturate(torch.tensor(1.0, dtype=DTYPE), limit, "sin").item() - 1.0) > 1e-2
    assert abs(saturate(torch.tensor(1.0, dtype=DTYPE), limit, "tanh").item() - 1.0) > 1e-2


# ----------------------------------------------------------------------------- bad inputs


def _hybrid(**overrides):
    W = np.array([[1.0, 2.0, 3.0]])
    kwargs = dict(
        linear=LinearController(W),
        nonlinear=MLPActor(3, 1, (4,), generator=torch.Generator().manual_seed(0)),
        operating_point=np.zeros(3),
    )
    kwargs.update(overrides)
    return HybridPolicy(**kwargs)


def _shifted_linear():
    return LinearController(np.array([[1.0, 2.0, 3.0]]), b=[0.5])  # G(a = 0) = 0.5


BAD_INPUTS = [
    ("W 1-D", lambda: LinearController(np.ones(3)), ValueError, r"W must have shape \(F, D\)"),
    ("W 3-D", lambda: LinearController(np.ones((1, 2, 3))), ValueError, r"W must have shape"),
    ("W text", lambda: LinearController("abc"), TypeError, "W must be array-like"),
    ("W nan", lambda: LinearController([[np.nan]]), ValueError, "W must be finite"),
    ("b shape", lambda: LinearController(np.ones((2, 3)), np.ones(3)), ValueError, r"b must"),
    ("linear type", lambda: _hybrid(linear=nn.Linear(3, 1)), TypeError, "linear must be"),
    ("H type", lambda: _hybrid(nonlinear=lambda x: x), TypeError, "nonlinear must be an nn"),
    ("a length", lambda: _hybrid(operating_point=np.zeros(2)), ValueError, "operating_point"),
    ("a nan", lambda: _hybrid(operating_point=[0, np.nan, 0]), ValueError, "operating_point"),
    ("lambda 0", lambda: _hybrid(lambda_init=0.0), ValueError, "lambda_init must be positive"),
    ("lambda <0", lambda: _hybrid(lambda_init=-1.0), ValueError, "lambda_init must be positive"),
    ("lambda nan", lambda: _hybrid(lambda_init=np.nan), ValueError, "lambda_init must be pos"),
    ("lambda inf", lambda: _hybrid(lambda_init=np.inf), ValueError, "lambda_init must be pos"),
    ("lambda vec", lambda: _hybrid(lambda_init=[1, -1, 1]), ValueError, "lambda_init must be pos"),
    ("lambda shape", lambda: _hybrid(lambda_init=[1.0, 1.0]), ValueError, r"lambda_init must be a"),
    ("sat name", lambda: _hybrid(saturation="cube"), ValueError, "saturation must be one of"),
    ("sat type", lambda: _hybrid(saturation=3), TypeError, "saturation must be a str"),
    ("limit <0", lambda: _hybrid(action_limit=-1.0), ValueError, "action_limit must be positive"),
    ("limit 0", lambda: _hybrid(action_limit=0.0), ValueError, "action_limit must be positive"),
    ("limit shape", lambda: _hybrid(action_limit=[1.0, 2.0]), ValueError, r"action_limit must be"),
    (
        "H out",
        lambda: _hybrid(nonlinear=MLPActor(3, 2)),
        ValueError,
        r"nonlinear must map .*\(1, 1\)",
    ),
    ("H in", lambda: _hybrid(nonlinear=MLPActor(4, 1)), ValueError, r"nonlinear must map"),
    (
        "H float32",
        lambda: _hybrid(nonlinear=MLPActor(3, 1, dtype=torch.float32)),
        ValueError,
        "nonlinear must map",
    ),
    (
        "sin G(a)",
        lambda: _hybrid(linear=_shifted_linear(), action_limit=2.0, saturation="sin"),
        ValueError,
        r"pi\(a\) = G\(a\)",
    ),
    (
        "clip G(a)",
        lambda: _hybrid(linear=_shifted_linear(), action_limit=0.5, saturation="clip"),
        ValueError,
        r"dpi/dx\(a\) = W",
    ),
    ("sat limit", lambda: saturate(torch.ones(2), -1.0), ValueError, "limit must be positive"),
    ("sat mode", lambda: saturate(torch.ones(2), 1.0, "cube"), ValueError, "mode must be one of"),
    ("rbf centres", lambda: RBFNetwork(2, 1, 3, centres=np.ones((3, 3))), ValueError, "centres"),
    ("rbf weights", lambda: RBFNetwork(2, 1, 3, weights=np.ones((3, 1))), ValueError, "weights"),
    ("rbf scales", lambda: RBFNetwork(2, 1, 3, lengthscales=-1.0), ValueError, "lengthscales"),
    ("rbf basis", lambda: RBFNetwork(2, 1, 0), ValueError, "num_basis must be a positive int"),
    ("rbf dim", lambda: RBFNetwork(True, 1, 3), TypeError, "obs_dim must be a positive int"),
    ("rbf std", lambda: RBFNetwork(2, 1, 3, centre_std=-1.0), ValueError, "centre_std"),
    ("mlp limit", lambda: MLPActor(2, 1, action_limit=0.0), ValueError, "action_limit"),
    ("mlp width", lambda: MLPActor(2, 1, (4, 0)), ValueError, r"hidden_sizes\[1\]"),
    ("mlp act", lambda: MLPActor(2, 1, activation="relu"), TypeError, "activation must be"),
    ("x dim", lambda: _hybrid()(torch.zeros(2, dtype=DTYPE)), ValueError, r"x must have shape"),
    ("x dtype", lambda: _hybrid()(torch.zeros(3)), TypeError, "x must have the module's dtype"),
    ("x type", lambda: LinearController([[1.0]])([1.0]), TypeError, "x must be a torch.Tensor"),
]


@pytest.mark.parametrize(
    ("build", "error", "match"),
    [case[1:] for case in BAD_INPUTS],
    ids=[case[0] for case in BAD_INPUTS],
)
def test_bad_inputs_raise_naming_the_argument(build, error, match):
    with pytest.raises(error, match=match):
        build()


def test_valid_edge_cases_construct():
    """Boundary-adjacent but valid inputs pass the checks that the bad inputs above fail."""
    _hybrid(linear=_shifted_linear(), action_limit=0.5 + 1e-9, saturation="clip")
    _hybrid(action_limit=2.0, saturation="sin")  # G(a) = 0
    _hybrid(lambda_init=[1e-8, 1.0, 1e8], learn_lambda=False, saturation="tanh")
