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
