"""Tests of leoc.policies.relevance: the paper's relevance as a module, the observation ->
state deviation map, and the ROA relevance (flat on the LQR's certified set) inside
HybridPolicy, including PILCO's moment propagation through it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from leoc.control import certify_lqr, design_lqr
from leoc.policies import (
    HybridPolicy,
    LinearController,
    MLPActor,
    ObservationDeviation,
    PaperRelevance,
    PrecisionRelevance,
    RBFNetwork,
    ROARelevance,
    roa_hybrid,
    saturate,
)
from leoc.systems import SYSTEM_NAMES, make_system

DTYPE = torch.float64
SAMPLES = 20_000
POINTS = 2_000
GRADIENT_STEP = 1e-7  # relative offset of the level on either side of a band edge
GRADIENT_ATOL = 1e-5  # |grad r| on both sides of an edge, where C^1 makes it tend to 0
HIDDEN = (16, 16)


@pytest.fixture(scope="module")
def setups():
    """System, design and certificate of each system (computed once)."""
    torch.set_num_threads(1)
    out = {}
    for name in SYSTEM_NAMES:
        system = make_system(name)
        design = design_lqr(system)
        out[name] = (system, design, certify_lqr(system, design, samples=SAMPLES, seed=0))
    return out


def _mlp(system, seed: int = 0) -> nn.Module:
    gen = torch.Generator().manual_seed(seed)
    return MLPActor(system.obs_dim, 1, HIDDEN, activation=nn.Tanh, generator=gen)


def _hybrid(setup, seed: int = 0, **kwargs) -> HybridPolicy:
    system, design, certificate = setup
    policy = roa_hybrid(system, design, _mlp(system, seed), certificate=certificate, **kwargs)
    with torch.no_grad():  # a large, random H, far from G everywhere
        for param in policy.nonlinear.parameters():
            param.mul_(5.0)
    return policy


def _observe(system, states: np.ndarray) -> torch.Tensor:
    return system.observe(torch.as_tensor(states, dtype=DTYPE))


def test_paper_relevance_module_gives_the_hybrid_default_bit_for_bit():
    rng = np.random.default_rng(0)
    a, lam = rng.standard_normal(3), np.exp(rng.standard_normal(3))
    policy = HybridPolicy(
        LinearController(rng.standard_normal((1, 3))), _mlp(make_system("pendulum")), a, lam
    )
    module = PaperRelevance(a, lam)
    x = torch.as_tensor(rng.standard_normal((50, 3)))
    torch.testing.assert_close(module(x), policy.relevance(x), rtol=0, atol=0)
    with_module = HybridPolicy(
        LinearController(policy.linear.W), policy.nonlinear, a, relevance=module
    )
    torch.testing.assert_close(with_module(x), policy(x), rtol=0, atol=0)


def test_old_state_dict_keys_still_load():
    rng = np.random.default_rng(1)
    system = make_system("pendulum")
    policy = HybridPolicy(LinearController(rng.standard_normal((1, 3))), _mlp(system), np.zeros(3))
    keys = set(policy.state_dict())
    assert "log_lambda" in keys and not any(k.startswith("relevance_module") for k in keys)


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_observation_deviation_inverts_the_observation(name):
    system = make_system(name)
    deviation = ObservationDeviation(system.obs_layout, system.operating_state)
    states = system.sample_operating_region(np.random.default_rng(2), 100)
    for index in system.angle_indices:
        states[:, index] += 2.0 * math.pi  # the wrap must undo whole turns
    expected = states - system.operating_state
    for index in system.angle_indices:
        expected[:, index] -= 2.0 * math.pi
    got = deviation(_observe(system, states)).numpy()
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_roa_hybrid_is_the_saturated_lqr_bit_for_bit_inside_the_flat_top(setups, name):
    system, design, certificate = setups[name]
    policy = _hybrid(setups[name], rho_in_fraction=0.8)
    rho_in = float(policy.relevance_module.rho_in)
    states = certificate.sample(np.random.default_rng(3), POINTS)
    inside = certificate.value(states) <= rho_in
    assert inside.sum() > POINTS // 2
    obs = _observe(system, states[inside])
    with torch.no_grad():
        action = policy(obs)
        relevance = policy.relevance(obs)
        linear = saturate(policy.linear(obs), system.action_limit, "clip")
        nonlinear = policy.nonlinear(obs)
    assert torch.equal(relevance, torch.ones_like(relevance))
    assert torch.equal(action, linear)  # bit for bit
    assert float((nonlinear - linear).abs().max()) > 0.1  # H differs: the test can fail
    # Outside the band the learned part governs alone.
    far = _observe(
        system,
        system.operating_state + 0.99 * math.pi * np.eye(system.state_dim)[system.main_index],
    )
    with torch.no_grad():
        assert float(policy.relevance(far)) == 0.0
        assert torch.equal(policy(far), saturate(policy.nonlinear(far), system.action_limit))


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_identities_at_the_operating_point(setups, name):
    system, design, _ = setups[name]
    policy = _hybrid(setups[name])
    a = torch.as_tensor(system.operating_obs, dtype=DTYPE)
    np.testing.assert_allclose(
        policy(a[None]).detach().numpy()[0], design.W @ a.numpy() + design.b, rtol=0, atol=1e-12
    )
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None])[0], a).numpy()
    np.testing.assert_allclose(jacobian, design.W, rtol=0, atol=1e-10)


def _level_ray(policy: HybridPolicy, system, direction: np.ndarray, level: float):
    """Observation at the state deviation along ``direction`` where V / rho_in = level."""
    module = policy.relevance_module
    P = module.lyapunov_matrix.numpy()
    scale = math.sqrt(level * float(module.rho_in) / float(direction @ P @ direction))
    return _observe(system, system.operating_state + scale * direction)


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_transition_is_continuously_differentiable_across_both_edges(setups, name):
    system, _, _ = setups[name]
    policy = _hybrid(setups[name], width_init=0.5)
    width = float(policy.relevance_module.width.detach())
    direction = np.random.default_rng(4).standard_normal(system.state_dim)
    for edge in (1.0, 1.0 + width):
        gradients = []
        for level in (edge * (1 - GRADIENT_STEP), edge * (1 + GRADIENT_STEP)):
            obs = _level_ray(policy, system, direction, level).requires_grad_(True)
            (grad,) = torch.autograd.grad(policy.relevance(obs).sum(), obs)
            gradients.append(grad)
        # C^1: the gradient is continuous across the edge, where it vanishes (flat top, zero).
        for grad in gradients:
            assert float(grad.abs().max()) < GRADIENT_ATOL
    # Inside the band the gradient is not zero (r falls): a check that can fail.
    obs = _level_ray(policy, system, direction, 1.0 + 0.5 * width).requires_grad_(True)
    (grad,) = torch.autograd.grad(policy.relevance(obs).sum(), obs)
    assert float(grad.abs().max()) > 1e-3
    with torch.no_grad():
        value = float(policy.relevance(obs))
    assert value == pytest.approx(0.5, abs=1e-9)  # smootherstep(1/2) = 1/2


def test_width_is_learnable_and_never_moves_the_flat_top(setups):
    system, _, _ = setups["pendulum"]
    policy = _hybrid(setups["pendulum"])
    module = policy.relevance_module
    names = {name for name, _ in policy.named_parameters()}
    assert "relevance_module.width_param" in names
    assert "relevance_module.rho_in" in dict(policy.named_buffers())
    direction = np.array([1.0, 0.3])
    obs = _level_ray(policy, system, direction, 1.0 + 0.3 * float(module.width.detach()))
    policy.blend(obs).sum().backward()  # before the clip, which may be saturated here
    assert module.width_param.grad is not None and float(module.width_param.grad.abs()) > 0
    assert all(p.grad is not None for p in policy.nonlinear.parameters())
    # The band ends before the angle chart's cut (the wrap at +/- pi): r is C^2 everywhere.
    assert 0.0 < float(module.width.detach()) < module.max_width < math.inf


def test_save_and_load_round_trip(setups):
    policy = _hybrid(setups["cartpole"], seed=1, width_init=2.0)
    other = _hybrid(setups["cartpole"], seed=2, width_init=0.5)
    other.load_state_dict(policy.state_dict())
    x = torch.as_tensor(np.random.default_rng(5).standard_normal((20, 5)))
    torch.testing.assert_close(other(x), policy(x), rtol=0, atol=0)
    assert float(other.relevance_module.width.detach()) == pytest.approx(2.0, rel=1e-12)


def test_pilco_moments_through_the_roa_hybrid_match_monte_carlo(setups):
    from leoc.pilco.moments import observation_moments
    from leoc.pilco.propagate import action_moments

    system, design, _ = setups["pendulum"]
    gen = torch.Generator().manual_seed(6)
    rbf = RBFNetwork(system.obs_dim, 1, 20, weight_std=1.0, generator=gen)
    policy = roa_hybrid(system, design, rbf, saturation="sin", samples=SAMPLES, prove=False)
    layout = [(c.kind, c.state_index) for c in system.obs_layout]
    mean = torch.tensor([0.25, -0.4], dtype=DTYPE)  # straddles the band
    cov = torch.diag(torch.tensor([0.04, 0.3], dtype=DTYPE))
    obs = observation_moments(mean, cov, layout)
    quad = action_moments(policy, mean, cov, obs, layout, "quadrature", order=9)
    rough = action_moments(policy, mean, cov, obs, layout, "constant_relevance")
    states = torch.distributions.MultivariateNormal(mean, cov).sample((200_000,))
    with torch.no_grad():
        actions = policy(system.observe(states))
    mc_mean, mc_var = float(actions.mean()), float(actions.var())
    assert float(quad.mean) == pytest.approx(mc_mean, abs=0.02)
    assert float(quad.cov) == pytest.approx(mc_var, rel=0.05)
    assert torch.isfinite(rough.mean).all() and torch.isfinite(rough.cov).all()
    # Gradients of the quadrature mean reach the band width and H.
    quad.mean.sum().backward()
    assert float(policy.relevance_module.width_param.grad.abs()) > 0


def test_bad_arguments_raise_naming_them(setups):
    system, design, certificate = setups["pendulum"]
    layout, a, P = system.obs_layout, system.operating_state, design.P
    with pytest.raises(ValueError, match="width_init must be below the chart's limit"):
        ROARelevance(layout, a, P, certificate.rho, width_init=1e6)
    with pytest.raises(ValueError, match="rho_in must be a positive"):
        ROARelevance(layout, a, P, -1.0)
    with pytest.raises(ValueError, match="P must be positive definite"):
        ROARelevance(layout, a, -P, 1.0)
    with pytest.raises(ValueError, match="rho_in: expected a level in"):
        roa_hybrid(
            system, design, _mlp(system), certificate=certificate, rho_in=2 * certificate.rho
        )
    with pytest.raises(ValueError, match="lambda_init, learn_lambda: only for the paper"):
        HybridPolicy(
            LinearController(design.W, design.b),
            _mlp(system),
            system.operating_obs,
            lambda_init=2.0,
            relevance=ROARelevance(layout, a, P, 1.0),
        )
    with pytest.raises(ValueError, match="exactly 1 at the operating point"):
        HybridPolicy(
            LinearController(design.W, design.b),
            _mlp(system),
            system.operating_obs,
            relevance=PaperRelevance(system.operating_obs + 0.1),
        )


# ---- known answers, written out by hand (independent of paper_relevance and the modules) ----

# a, lambda and four observations whose d(x) = sum_i (x_i - a_i)^2 / lambda_i is worked out
# by hand: d = 0.5^2/0.25 + 2^2/4 + 0.5^2/1 = 2.25, 0, 1 and 4; r = 1/(1 + d)^2.
KNOWN_A = [0.5, -1.0, 2.0]
KNOWN_LAMBDA = [0.25, 4.0, 1.0]
KNOWN_X = [[1.0, 1.0, 2.5], [0.5, -1.0, 2.0], [0.5, -1.0, 3.0], [0.5, 3.0, 2.0]]
KNOWN_D = [2.25, 0.0, 1.0, 4.0]
KNOWN_R = [16.0 / 169.0, 1.0, 0.25, 1.0 / 25.0]


def test_paper_relevance_matches_its_closed_form_with_numbers():
    """r(x) = 1/(1 + sum (x - a)^2 / lambda)^2 (paper eq. 5) for the module, the hybrid's
    default and the precision parametrisation with S = 1/lambda; a lambda that multiplies
    instead of dividing gives d = 16.3125 at the first point, r = 0.0033, not 16/169."""
    x = torch.tensor(KNOWN_X, dtype=DTYPE)
    expected_r = torch.tensor(KNOWN_R, dtype=DTYPE).unsqueeze(-1)
    module = PaperRelevance(KNOWN_A, KNOWN_LAMBDA)
    torch.testing.assert_close(module(x), expected_r, rtol=1e-14, atol=0)
    precision = PrecisionRelevance(KNOWN_A, [1.0 / value for value in KNOWN_LAMBDA])
    torch.testing.assert_close(precision(x), expected_r, rtol=1e-14, atol=0)
    policy = HybridPolicy(
        LinearController(np.ones((1, 3))), _mlp(make_system("pendulum")), KNOWN_A, KNOWN_LAMBDA
    )
    torch.testing.assert_close(policy.relevance(x), expected_r, rtol=1e-14, atol=0)
    expected_d = torch.tensor(KNOWN_D, dtype=DTYPE).unsqueeze(-1)
    torch.testing.assert_close(policy.distance(x), expected_d, rtol=1e-14, atol=0)


def test_paper_relevance_gradients_match_their_closed_forms():
    """dr/dx_i = -4 (x_i - a_i) / (lambda_i (1 + d)^3) and, with lambda = exp(l),
    dr/dl_i = 2 (x_i - a_i)^2 / (lambda_i (1 + d)^3), at x = (1, 1, 2.5): 1 + d = 3.25."""
    module = PaperRelevance(KNOWN_A, KNOWN_LAMBDA, learn_lambda=True)
    x = torch.tensor(KNOWN_X[0], dtype=DTYPE, requires_grad=True)
    module(x).sum().backward()
    cube = 3.25**3
    # (x - a) / lambda = (0.5 / 0.25, 2 / 4, 0.5 / 1); (x - a)^2 / lambda = (1, 1, 0.25)
    expected_x = [-4.0 * 2.0 / cube, -4.0 * 0.5 / cube, -4.0 * 0.5 / cube]
    expected_log_lambda = [2.0 * 1.0 / cube, 2.0 * 1.0 / cube, 2.0 * 0.25 / cube]
    np.testing.assert_allclose(x.grad.numpy(), expected_x, rtol=1e-13)
    np.testing.assert_allclose(module.log_lambda.grad.numpy(), expected_log_lambda, rtol=1e-13)


class _Constant(nn.Module):
    """H(x) = value everywhere."""

    def __init__(self, value: float) -> None:
        super().__init__()
        self.value = value

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.full((*x.shape[:-1], 1), self.value, dtype=x.dtype)


def test_paper_hybrid_blends_with_the_closed_form_weights():
    """pi = r G + (1 - r) H: G(x) = x_0 - 0.5, H = 2, at the known points (limit 10, inactive);
    at (1, 1, 2.5): 16/169 * 0.5 + 153/169 * 2 = 314/169."""
    policy = HybridPolicy(
        LinearController(np.array([[1.0, 0.0, 0.0]]), np.array([-0.5])),
        _Constant(2.0),
        KNOWN_A,
        KNOWN_LAMBDA,
        action_limit=10.0,
    )
    x = torch.tensor(KNOWN_X, dtype=DTYPE)
    linear = np.array(KNOWN_X)[:, 0] - 0.5
    r = np.array(KNOWN_R)
    expected = r * linear + (1.0 - r) * 2.0
    with torch.no_grad():
        np.testing.assert_allclose(policy(x).numpy()[:, 0], expected, rtol=1e-14)
    assert expected[0] == pytest.approx(314.0 / 169.0, rel=1e-15)


def test_roa_relevance_matches_its_closed_form_with_numbers():
    """r = 1 - (10 t^3 - 15 t^4 + 6 t^5), t = clamp((z^T P z / rho_in - 1) / w, 0, 1), worked
    out by hand for a plain 2-state layout and for an angle seen through (cos, sin)."""
    plain = make_system("mountaincar").obs_layout
    module = ROARelevance(
        plain, [0.0, 0.0], [[2.0, 0.5], [0.5, 1.0]], 1.0, width_init=0.5, learn_width=False
    )
    # w = 0.5. z = (0.5, 0): V = 0.5, flat top. z = (1, 0): V = 2, t = 2 -> 1, r = 0.
    # z = (0.6, 0.6): V = 2 (0.36) + 2 (0.5)(0.36) + 0.36 = 1.44, t = 0.88,
    # 10 (0.681472) - 15 (0.59969536) + 6 (0.5277319168) = 0.9856811008.
    # z = (0.8, 0): V = 1.28, t = 0.56, 10 (0.175616) - 15 (0.09834496) + 6 (0.0550731776)
    # = 0.6114246656.
    obs = torch.tensor([[0.5, 0.0], [1.0, 0.0], [0.6, 0.6], [0.8, 0.0]], dtype=DTYPE)
    expected = [1.0, 0.0, 1.0 - 0.9856811008, 1.0 - 0.6114246656]
    np.testing.assert_allclose(module(obs).detach().numpy()[:, 0], expected, rtol=1e-12)
    angle = make_system("pendulum").obs_layout
    module = ROARelevance(angle, [0.0, 0.0], [[2.0, 0.0], [0.0, 1.0]], 0.4, width_init=1.0)
    # theta = 0.5 + 2 pi (wrapped to 0.5), theta_dot = 0.2: V = 2 (0.25) + 0.04 = 0.54,
    # V / rho_in = 1.35, t = 0.35: 10 (0.042875) - 15 (0.01500625) + 6 (0.0052521875)
    # = 0.235169375.
    theta = 0.5 + 2.0 * math.pi
    obs = torch.tensor([[math.cos(theta), math.sin(theta), 0.2]], dtype=DTYPE)
    assert float(module.width.detach()) == pytest.approx(1.0, rel=1e-12)
    np.testing.assert_allclose(float(module(obs).detach()), 1.0 - 0.235169375, rtol=1e-12)
