"""The authors' PILCO choices (nrjc/LEOC) as PilcoConfig fields, each checked against a value
computed from the authors' formulas independently of leoc's code path, and the defaults left
as they were."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from leoc.pilco.config import (
    AUTHORS_SYSTEM_SETTINGS,
    PilcoConfig,
    authors_pilco_overrides,
)
from leoc.pilco.cost import expected_saturating_cost
from leoc.pilco.gp import GPSettings, fit_gp
from leoc.pilco.moments import observation_moments
from leoc.pilco.objective import cost_spec, start_distribution
from leoc.pilco.propagate import action_moments
from leoc.policies import HybridPolicy, LinearController, RBFNetwork
from leoc.systems import make_system

DTYPE = torch.float64
NUM_SAMPLES = 200_000
Z_TOL = 5.0  # standard errors of a Monte Carlo mean


def exponential_reward_closed_form(m, s, t, w) -> float:
    """The authors' ExponentialReward mean (pilco/rewards.py), written from its formula:
    exp(-(m - t) W (I + S W)^-1 (m - t)^T / 2) / sqrt(det(I + S W))."""
    eye = np.eye(len(m))
    gap = m - t
    return float(
        np.exp(-0.5 * gap @ w @ np.linalg.inv(eye + s @ w) @ gap)
        / np.sqrt(np.linalg.det(eye + s @ w))
    )


@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar"])
def test_weighted_cost_is_one_minus_the_authors_exponential_reward(name) -> None:
    system = make_system(name)
    weights = AUTHORS_SYSTEM_SETTINGS[name]["cost_weights"]
    spec = cost_spec(system, 1.0, weights)
    np.testing.assert_allclose((spec.factor.T @ spec.factor).numpy(), np.diag(weights))
    gen = torch.Generator().manual_seed(7)
    for _ in range(3):
        mean = torch.randn(system.obs_dim, generator=gen, dtype=DTYPE)
        root = 0.4 * torch.randn(system.obs_dim, system.obs_dim, generator=gen, dtype=DTYPE)
        cov = root @ root.T + 0.01 * torch.eye(system.obs_dim, dtype=DTYPE)
        reward = exponential_reward_closed_form(
            mean.numpy(), cov.numpy(), system.operating_obs, np.diag(weights)
        )
        cost = expected_saturating_cost(mean, cov, spec.target, spec.factor)
        assert float(cost) == pytest.approx(1.0 - reward, rel=0, abs=1e-12)
    # and the closed form against Monte Carlo, once
    samples = mean + torch.randn(NUM_SAMPLES, system.obs_dim, generator=gen, dtype=DTYPE) @ (
        torch.linalg.cholesky(cov).T
    )
    gap = samples - spec.target
    rewards = torch.exp(-0.5 * (gap.square() * torch.as_tensor(weights, dtype=DTYPE)).sum(-1))
    tol = Z_TOL * float(rewards.std()) / math.sqrt(NUM_SAMPLES)
    assert float(rewards.mean()) == pytest.approx(reward, abs=tol)


def test_cost_weights_are_checked() -> None:
    system = make_system("pendulum")
    with pytest.raises(ValueError, match="cost_weights: expected 3 weights"):
        cost_spec(system, 1.0, (1.0, 2.0))
    for bad in ((1.0, -1.0, 0.0), (), "abc", (1.0, math.nan, 1.0), (True, 1.0, 1.0)):
        with pytest.raises(ValueError, match="cost_weights"):
            PilcoConfig(cost_weights=bad)


def test_fixed_noise_stays_fixed_after_fitting() -> None:
    gen = np.random.default_rng(0)
    inputs = gen.normal(size=(40, 3))
    targets = np.stack([np.sin(inputs[:, 0]), inputs[:, 1] * inputs[:, 2]], axis=1)
    settings = GPSettings(train_iterations=30, fixed_noise_var=1e-3)
    post = fit_gp(inputs, targets, settings)
    np.testing.assert_allclose(post.noise_var.numpy(), [1e-3, 1e-3], rtol=1e-12)
    # the posterior is (K + 1e-3 I)^-1 y with the fitted kernel, recomputed here
    for output in range(2):
        inv_sq = np.exp(-2.0 * post.log_lengthscales[output].numpy())
        diff = inputs[:, None, :] - inputs[None, :, :]
        gram = np.exp(2.0 * float(post.log_signal[output])) * np.exp(
            -0.5 * (diff**2 * inv_sq).sum(-1)
        )
        beta = np.linalg.solve(gram + 1e-3 * np.eye(len(inputs)), targets[:, output])
        np.testing.assert_allclose(post.beta[output].numpy(), beta, rtol=1e-7, atol=1e-9)
    # the noise that the default fit learns differs
    free = fit_gp(inputs, targets, GPSettings(train_iterations=30))
    assert not np.allclose(free.noise_var.numpy(), 1e-3, rtol=1e-3)
    for bad in (0.0, -1.0, math.inf, True, "1e-3"):
        with pytest.raises(ValueError, match="fixed_noise_var"):
            GPSettings(fixed_noise_var=bad)


def test_start_distribution_overrides() -> None:
    system = make_system("cartpole")
    mean, cov = start_distribution(system)
    np.testing.assert_allclose(mean.numpy(), system.swing_up_centre)
    np.testing.assert_allclose(cov.numpy(), np.diag(np.square(system.start_spread) / 3.0))
    settings = AUTHORS_SYSTEM_SETTINGS["cartpole"]
    mean, cov = start_distribution(system, settings["start_mean"], settings["start_variance"])
    np.testing.assert_allclose(mean.numpy(), [0.0, 0.0, math.pi, 0.0])
    np.testing.assert_allclose(cov.numpy(), np.diag([0.01, 0.01, 0.05, 0.01]))
    # in observation coordinates: the authors' m_init and their sin/plain variances S_init
    obs = observation_moments(mean, cov, system.observation.pairs())
    np.testing.assert_allclose(
        obs.mean.numpy(), [0.0, 0.0, -math.exp(-0.025), 0.0, 0.0], rtol=1e-12, atol=1e-15
    )
    sin_var = (1.0 - math.exp(-2 * 0.05)) / 2.0  # Var[sin th], th ~ N(pi, 0.05)
    np.testing.assert_allclose(
        obs.cov.diagonal().numpy()[[0, 1, 3, 4]], [0.01, 0.01, sin_var, 0.01]
    )
    assert sin_var == pytest.approx(0.05, rel=0.05)
    with pytest.raises(ValueError, match="start_variance: expected 4 entries"):
        start_distribution(system, None, (0.1, 0.1))
    with pytest.raises(ValueError, match="start_variance"):
        PilcoConfig(start_variance=(0.1, 0.0))


def test_mixture_moments_follow_the_authors_formula() -> None:
    """With H == 0 the mixture "G with probability r, else 0" has the closed form
    mean r m_G, variance r S_G + r (1 - r) m_G^2 (HybridController.compute_action), then the
    sin squash E[u sin(z / u)] = u exp(-S / 2u^2) sin(M / u)."""
    gen = torch.Generator().manual_seed(3)
    obs_dim = 3
    weight = torch.randn(1, obs_dim, generator=gen, dtype=DTYPE)
    point = torch.randn(obs_dim, generator=gen, dtype=DTYPE)
    lambdas = torch.tensor([0.5, 2.0, 1.5], dtype=DTYPE)
    mean = torch.randn(obs_dim, generator=gen, dtype=DTYPE)
    root = 0.3 * torch.randn(obs_dim, obs_dim, generator=gen, dtype=DTYPE)
    cov = root @ root.T + 0.01 * torch.eye(obs_dim, dtype=DTYPE)
    layout = [("state", i) for i in range(obs_dim)]
    obs = observation_moments(mean, cov, layout)
    rel = 1.0 / (1.0 + float(((mean - point) ** 2 / lambdas).sum())) ** 2
    m_g = float(weight[0] @ (mean - point))
    s_g = float(weight[0] @ cov @ weight[0])
    blend_mean, blend_var = rel * m_g, rel * s_g + rel * (1.0 - rel) * m_g**2
    limit = 2.0
    for action_limit, expected in (
        (None, blend_mean),
        (limit, limit * math.exp(-blend_var / (2 * limit**2)) * math.sin(blend_mean / limit)),
    ):
        policy = HybridPolicy(
            LinearController(weight, -weight @ point),
            RBFNetwork(obs_dim, 1, 4, weights=torch.zeros(1, 4, dtype=DTYPE), generator=gen),
            point,
            lambda_init=lambdas,
            action_limit=action_limit,
            saturation="sin" if action_limit else "clip",
        )
        moments = action_moments(policy, mean, cov, obs, layout, "mixture")
        assert float(moments.mean[0].detach()) == pytest.approx(expected, rel=1e-12)
        if action_limit is None:
            assert float(moments.cov[0, 0].detach()) == pytest.approx(blend_var, rel=1e-12)


def test_rollout_steps_sets_the_training_rollouts_only(tmp_path) -> None:
    from leoc.pilco.train import _random_rollouts

    config = PilcoConfig.for_system("pendulum", rollout_steps=24, episode_steps=48)
    assert config.training_rollout_steps == 24
    assert PilcoConfig.for_system("pendulum").training_rollout_steps == 200
    system = make_system("pendulum")
    rollouts, _ = _random_rollouts(system, config, np.random.default_rng(0))
    assert [r.steps for r in rollouts] == [24] * config.initial_rollouts
    assert [len(r.inputs) for r in rollouts] == [24 // config.action_repeat] * 3
    with pytest.raises(ValueError, match="rollout_steps"):
        PilcoConfig(rollout_steps=0)


TINY = dict(
    horizon=6,
    num_basis=5,
    policy_iterations=3,
    gp_train_iterations=3,
    eval_episodes=1,
    episode_steps=48,
    num_threads=1,
)


def test_policy_restart_keeps_the_lower_predicted_cost(tmp_path) -> None:
    from leoc.pilco.train import train_pilco

    runs = {
        restarts: train_pilco(
            "pendulum",
            seed=1,
            run_dir=tmp_path / str(len(restarts)),
            iterations=1,
            progress=False,
            policy_restarts=restarts,
            **TINY,
        ).curve[-1]
        for restarts in ((), (2,))
    }
    assert runs[(2,)]["lbfgs_restarts"] >= runs[()]["lbfgs_restarts"] + 2
    assert runs[(2,)]["lbfgs_iterations"] > runs[()]["lbfgs_iterations"]
    assert runs[(2,)]["predicted_cost"] <= runs[()]["predicted_cost"]
    with pytest.raises(ValueError, match="policy_restarts"):
        PilcoConfig(policy_restarts=(1, -1))


@pytest.mark.slow
def test_lqr_method_reaches_the_hybrid_linear_part() -> None:
    from leoc.control.lqr import design_lqr
    from leoc.pilco.policy import build_policy

    system = make_system("pendulum")
    gen = torch.Generator().manual_seed(0)
    config = PilcoConfig.for_system("pendulum", hybrid=True, num_basis=3, lqr_method="continuous")
    policy = build_policy(system, config, gen)
    expected = design_lqr(system, method="continuous", action_repeat=config.action_repeat)
    np.testing.assert_array_equal(policy.linear.W.detach().numpy(), expected.W)
    default = build_policy(system, PilcoConfig.for_system("pendulum", hybrid=True), gen)
    held = design_lqr(system, action_repeat=2)
    np.testing.assert_array_equal(default.linear.W.detach().numpy(), held.W)
    with pytest.raises(ValueError, match="lqr_method: expected one of"):
        PilcoConfig(lqr_method="dare")


@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar"])
def test_authors_overrides_give_their_numbers(name) -> None:
    overrides = authors_pilco_overrides(name, hybrid=False)
    config = PilcoConfig.for_system(name, **overrides)
    assert (config.action_repeat, config.horizon, config.rollout_steps) == (3, 39, 120)
    assert config.training_rollout_steps == 40 * 3 and config.episode_steps == 200
    assert (config.initial_rollouts, config.policy_iterations) == (3, 50)
    assert config.policy_restarts == (1, 1, 1, 1) and config.eval_episodes == 3
    assert config.gp.fixed_noise_var == 1e-3 and config.cost_width == 1.0
    # Evaluator saves from loop index int(num_rollouts / 2) + 1 on, leoc's iteration = index + 1
    assert config.select_best_from == {"pendulum": 6, "cartpole": 7, "mountaincar": 6}[name]
    assert config.deploy_action_repeat == 1 and config.controller_action_repeat == 1
    assert config.iterations == {"pendulum": 8, "cartpole": 10, "mountaincar": 8}[name]
    assert config.num_basis == {"pendulum": 30, "cartpole": 60, "mountaincar": 60}[name]
    assert (
        config.cost_weights
        == {
            "pendulum": (2.0, 2.0, 0.3),
            "cartpole": (2.0, 0.3, 2.0, 2.0, 0.3),
            "mountaincar": (2.0, 0.5),
        }[name]
    )
    hybrid = authors_pilco_overrides(name, hybrid=True)
    assert hybrid["lqr_method"] == "authors" and hybrid["hybrid_method"] == "mixture"
    # the relevance design is the controller's (its HybridSpec), not a setting of the variant
    assert hybrid["lambda_init"] == 1.0 and "relevance" not in hybrid
    assert {k: v for k, v in hybrid.items() if k in overrides} == overrides
    with pytest.raises(ValueError, match="system: the authors' PILCO settings exist for"):
        authors_pilco_overrides("acrobot", hybrid=False)


def test_defaults_keep_leocs_own_settings() -> None:
    config = PilcoConfig.for_system("pendulum")
    assert config.lqr_method == "discrete" and config.cost_weights is None
    assert config.start_mean is None and config.start_variance is None
    assert config.rollout_steps is None and config.policy_restarts == ()
    assert config.gp.fixed_noise_var is None and config.hybrid_method == "quadrature"
    assert config.select_best_from == 0 and config.deploy_action_repeat is None
    assert config.controller_action_repeat == config.action_repeat == 2
    # a config survives its dict round trip (checkpoints) with the new fields set
    authors = PilcoConfig.for_system("cartpole", **authors_pilco_overrides("cartpole", False))
    assert PilcoConfig.from_dict(authors.to_dict()) == authors


def test_select_best_keeps_the_best_evaluated_policy(tmp_path) -> None:
    from leoc.pilco.checkpoint import load_pilco_controller
    from leoc.pilco.train import train_pilco
    from leoc.training import evaluate_episodes, evaluation_starts

    result = train_pilco(
        "pendulum",
        seed=2,
        run_dir=tmp_path / "run",
        iterations=3,
        progress=False,
        select_best_from=2,
        **{**TINY, "eval_episodes": 2},
    )
    eligible = result.curve[2:]
    best = max(eligible, key=lambda row: row["mean_return"])  # the first of equal maxima
    assert result.summary["model_selection"].endswith(f"(iteration {best['iteration']})")
    system = make_system("pendulum")
    system.episode_steps = TINY["episode_steps"]
    starts = evaluation_starts(system, 2, 2)
    again = evaluate_episodes(system, result.policy, starts)
    assert again.mean_return == pytest.approx(best["mean_return"], rel=1e-12)
    loaded = load_pilco_controller(tmp_path / "run")
    assert evaluate_episodes(system, loaded, starts).mean_return == again.mean_return
    # an unreachable first iteration keeps the final policy
    late = train_pilco(
        "pendulum",
        seed=2,
        run_dir=tmp_path / "late",
        iterations=1,
        progress=False,
        select_best_from=5,
        **{**TINY, "eval_episodes": 2},
    )
    assert late.summary["model_selection"] == "final"


def test_deploy_action_repeat_sets_the_controller_period_only(tmp_path) -> None:
    from leoc.pilco.checkpoint import load_pilco_controller
    from leoc.pilco.train import train_pilco
    from leoc.policies import HeldPolicy
    from leoc.training import evaluate_episodes, evaluation_starts

    result = train_pilco(
        "pendulum",
        seed=4,
        run_dir=tmp_path / "run",
        iterations=1,
        progress=False,
        deploy_action_repeat=1,
        **TINY,
    )
    assert result.config["action_repeat"] == 2  # trained holding each action 2 steps
    assert result.curve[1]["data_size"] == 3 * 48 // 2 + 48 // 2
    assert result.policy.action_repeat == 1
    assert load_pilco_controller(tmp_path / "run").action_repeat == 1
    system = make_system("pendulum")
    system.episode_steps = TINY["episode_steps"]
    starts = evaluation_starts(system, 4, TINY["eval_episodes"])
    every_step = evaluate_episodes(system, HeldPolicy(result.policy.policy, 1), starts)
    assert every_step.mean_return == pytest.approx(result.curve[-1]["mean_return"], rel=1e-12)
    with pytest.raises(ValueError, match="deploy_action_repeat"):
        PilcoConfig(deploy_action_repeat=0)


@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar"])
def test_authors_hybrid_is_their_hybrid_controller(name) -> None:
    """u = u_max sin(r K o + (1 - r) H(o)) with K their u_max-free gain, r = 1 / (1 + d)^2 and
    d = (o - a)^T diag(S) (o - a), S = 1 at the start (HybridController, pilco/controllers.py);
    H is zeroed here so that the value is written out from their formula."""
    from leoc.control.lqr import design_lqr
    from leoc.pilco.policy import build_policy

    system = make_system(name)
    config = PilcoConfig.for_system(name, hybrid=True, **authors_pilco_overrides(name, True))
    policy = build_policy(system, config, torch.Generator().manual_seed(0))
    design = design_lqr(system, method="authors", action_repeat=config.action_repeat)
    np.testing.assert_array_equal(policy.linear.W.detach().numpy(), design.W)
    with torch.no_grad():
        policy.nonlinear.weights.zero_()
    limit = system.action_limit
    gain = design.W / limit  # their LinearController's W (u = u_max sin(W o))
    gen = np.random.default_rng(1)
    target = system.operating_obs
    for _ in range(5):
        obs = target + 0.3 * gen.normal(size=system.obs_dim)
        distance = float(np.sum((obs - target) ** 2))  # diag(S) = I
        relevance = 1.0 / (1.0 + distance) ** 2
        expected = limit * np.sin(relevance * (gain @ obs))
        with torch.no_grad():
            action = policy(torch.as_tensor(obs)[None]).numpy()[0]
        np.testing.assert_allclose(action, expected, rtol=1e-12, atol=1e-12)
