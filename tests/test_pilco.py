"""Tests of leoc.pilco against independent references.

Every moment-matching function is compared with Monte Carlo (N = 200 000 samples) on random
means and covariances, with tolerances derived from the sample size: an estimate of a mean or a
covariance entry must lie within ``Z_TOL`` standard errors (estimated from the same samples) of
the closed form. Gradients are checked by finite differences (``torch.autograd.gradcheck``).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from leoc.pilco.cost import expected_saturating_cost, saturating_cost
from leoc.pilco.gp import (
    CholeskyError,
    GPSettings,
    cholesky_jitter,
    fit_gp,
    gp_predict,
)
from leoc.pilco.moments import (
    gp_moments,
    linear_moments,
    observation_moments,
    quadrature_moments,
    rbf_moments,
    sin_squash_moments,
)
from leoc.pilco.propagate import (
    SaturatedPolicy,
    action_moments,
    floor_eigenvalues,
    hybrid_quadrature_moments,
    observe_torch,
)
from leoc.policies import HybridPolicy, LinearController, RBFNetwork

DTYPE = torch.float64
NUM_SAMPLES = 200_000
Z_TOL = 5.0  # standard errors: a false alarm has probability ~6e-7 per entry
ABS_FLOOR = 1e-9  # round-off allowance for entries whose sampling error is ~0


def random_gaussian(dim: int, seed: int, scale: float = 0.5) -> tuple[torch.Tensor, torch.Tensor]:
    gen = torch.Generator().manual_seed(seed)
    mean = torch.randn(dim, generator=gen, dtype=DTYPE)
    factor = scale * torch.randn(dim, dim, generator=gen, dtype=DTYPE)
    return mean, factor @ factor.T + 0.01 * torch.eye(dim, dtype=DTYPE)


def sample(mean: torch.Tensor, cov: torch.Tensor, seed: int) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed + 1000)
    noise = torch.randn(NUM_SAMPLES, mean.shape[0], generator=gen, dtype=DTYPE)
    return mean + noise @ torch.linalg.cholesky(cov).T


def assert_mean_mc(exact: torch.Tensor, samples: torch.Tensor) -> None:
    """|exact - sample mean| <= Z_TOL * std / sqrt(N) entrywise."""
    err = (exact - samples.mean(0)).abs()
    tol = Z_TOL * samples.std(0) / math.sqrt(len(samples)) + ABS_FLOOR
    assert bool((err <= tol).all()), f"mean error {err.tolist()} > tolerance {tol.tolist()}"


def assert_cov_mc(exact: torch.Tensor, left: torch.Tensor, right: torch.Tensor) -> None:
    """Cov[left, right] within Z_TOL standard errors; the standard error of each entry is the
    sample std of the products of centred samples over sqrt(N)."""
    a = left - left.mean(0)
    b = right - right.mean(0)
    products = a[:, :, None] * b[:, None, :]
    estimate = products.mean(0)
    tol = Z_TOL * products.std(0) / math.sqrt(len(left)) + ABS_FLOOR
    err = (exact - estimate).abs()
    assert bool((err <= tol).all()), f"cov error {err.tolist()} > tolerance {tol.tolist()}"


def small_gp(seed: int, num: int = 40, settings: GPSettings | None = None):
    gen = torch.Generator().manual_seed(seed)
    x = torch.randn(num, 3, generator=gen, dtype=DTYPE)
    y = torch.stack([torch.sin(x[:, 0]) + 0.5 * x[:, 1], torch.cos(x[:, 2]) * x[:, 0]], dim=1)
    y = y + 0.01 * torch.randn(y.shape, generator=gen, dtype=DTYPE)
    return fit_gp(x, y, settings or GPSettings(train_iterations=30), np.random.default_rng(seed))


# --------------------------------------------------------------------------- Monte Carlo
@pytest.mark.parametrize("seed", [0, 1])
def test_observation_moments_match_monte_carlo(seed: int) -> None:
    layout = [("cos", 0), ("sin", 0), ("state", 1), ("sin", 2), ("cos", 2)]
    mean, cov = random_gaussian(3, seed, scale=0.7)
    out = observation_moments(mean, cov, layout)
    x = sample(mean, cov, seed)
    o = observe_torch(x, layout)
    assert_mean_mc(out.mean, o)
    assert_cov_mc(out.cov, o, o)
    assert_cov_mc(cov @ out.io, x, o)


@pytest.mark.parametrize("seed", [0, 1])
def test_sin_squash_moments_match_monte_carlo(seed: int) -> None:
    mean, cov = random_gaussian(2, seed, scale=1.5)
    limit = 1.7
    out = sin_squash_moments(mean, cov, limit)
    u = sample(mean, cov, seed)
    y = limit * torch.sin(u / limit)
    assert_mean_mc(out.mean, y)
    assert_cov_mc(out.cov, y, y)
    assert_cov_mc(cov @ out.io, u, y)


def test_linear_moments_match_monte_carlo() -> None:
    mean, cov = random_gaussian(3, 3)
    weight = torch.tensor([[1.0, -2.0, 0.5], [0.3, 0.0, 1.0]], dtype=DTYPE)
    bias = torch.tensor([0.1, -0.2], dtype=DTYPE)
    out = linear_moments(mean, cov, weight, bias)
    x = sample(mean, cov, 3)
    y = x @ weight.T + bias
    assert_mean_mc(out.mean, y)
    assert_cov_mc(out.cov, y, y)
    assert_cov_mc(cov @ out.io, x, y)


@pytest.mark.parametrize("seed", [0, 1])
def test_rbf_moments_match_monte_carlo(seed: int) -> None:
    gen = torch.Generator().manual_seed(seed)
    net = RBFNetwork(3, 2, 8, lengthscales=[0.7, 1.2, 0.9], generator=gen, weight_std=1.0)
    mean, cov = random_gaussian(3, seed)
    with torch.no_grad():
        out = rbf_moments(net, mean, cov)
        x = sample(mean, cov, seed)
        y = net(x)
    assert_mean_mc(out.mean, y)
    assert_cov_mc(out.cov, y, y)
    assert_cov_mc(cov @ out.io, x, y)


@pytest.mark.parametrize("sparse", [False, True])
def test_gp_moments_match_monte_carlo(sparse: bool) -> None:
    settings = GPSettings(
        train_iterations=30, max_full_points=30 if sparse else 300, num_inducing=25
    )
    post = small_gp(0, num=60, settings=settings)
    assert post.sparse == sparse
    mean, cov = random_gaussian(3, 4, scale=0.4)
    out = gp_moments(post, mean, cov)
    x = sample(mean, cov, 4)
    f_mean, f_var = gp_predict(post, x)
    gen = torch.Generator().manual_seed(7)
    # The latent prediction at a random input: mean + sqrt(var) * N(0, 1), independent outputs.
    y = f_mean + f_var.clamp(min=0.0).sqrt() * torch.randn(f_mean.shape, generator=gen, dtype=DTYPE)
    assert_mean_mc(out.mean, y)
    assert_cov_mc(out.cov, y, y)
    assert_cov_mc(cov @ out.io, x, y)


@pytest.mark.parametrize("seed", [0, 1])
def test_expected_cost_matches_monte_carlo(seed: int) -> None:
    mean, cov = random_gaussian(3, seed)
    target = torch.tensor([0.2, -0.1, 0.0], dtype=DTYPE)
    factor = torch.tensor([[1.0, 0.5, 0.0], [0.0, 0.0, 2.0]], dtype=DTYPE)
    exact = expected_saturating_cost(mean, cov, target, factor)
    costs = saturating_cost(sample(mean, cov, seed), target, factor)
    assert_mean_mc(exact.reshape(1), costs[:, None])


def test_saturating_cost_is_zero_at_target_and_one_far_away() -> None:
    target = torch.tensor([1.0, 0.0], dtype=DTYPE)
    factor = torch.eye(2, dtype=DTYPE)
    assert float(saturating_cost(target, target, factor)) == 0.0
    assert float(saturating_cost(target + 100.0, target, factor)) == pytest.approx(1.0)
    # A vanishing covariance gives back the deterministic cost.
    point = torch.tensor([0.3, -0.4], dtype=DTYPE)
    tiny = 1e-14 * torch.eye(2, dtype=DTYPE)
    assert float(expected_saturating_cost(point, tiny, target, factor)) == pytest.approx(
        float(saturating_cost(point, target, factor)), abs=1e-10
    )


# --------------------------------------------------------------------------- hybrid policy
def make_hybrid(seed: int, lambda_init: float = 1.0) -> HybridPolicy:
    gen = torch.Generator().manual_seed(seed)
    rbf = RBFNetwork(3, 1, 10, generator=gen, weight_std=2.0, lengthscales=1.0)
    linear = LinearController([[0.0, -9.0, -2.5]])
    return HybridPolicy(
        linear,
        rbf,
        operating_point=[1.0, 0.0, 0.0],
        lambda_init=lambda_init,
        action_limit=2.0,
        saturation="sin",
    )


HYBRID_LAYOUT = [("cos", 0), ("sin", 0), ("state", 1)]
# Gaussian states of the pendulum: near the operating point, on the way up, at the bottom.
HYBRID_CASES = [
    ([0.3, 0.5], [[0.05, 0.01], [0.01, 0.2]]),
    ([1.2, -1.0], [[0.1, -0.05], [-0.05, 0.3]]),
    ([3.0, 0.2], [[0.02, 0.0], [0.0, 0.05]]),
]


def hybrid_errors(case: int, method: str, order: int = 7) -> tuple[float, float]:
    """|mean error| and |std error| of the action, relative to MC, for one method."""
    policy = make_hybrid(case)
    mean = torch.tensor(HYBRID_CASES[case][0], dtype=DTYPE)
    cov = torch.tensor(HYBRID_CASES[case][1], dtype=DTYPE)
    with torch.no_grad():
        obs = observation_moments(mean, cov, HYBRID_LAYOUT)
        out = action_moments(policy, mean, cov, obs, HYBRID_LAYOUT, method, order)
        actions = policy(observe_torch(sample(mean, cov, case), HYBRID_LAYOUT))
    return (
        abs(float(out.mean[0] - actions.mean())),
        abs(float(out.cov[0, 0].sqrt() - actions.std())),
    )


@pytest.mark.parametrize("case", range(len(HYBRID_CASES)))
def test_hybrid_quadrature_beats_constant_relevance(case: int) -> None:
    quad_mean, quad_std = hybrid_errors(case, "quadrature")
    heur_mean, heur_std = hybrid_errors(case, "constant_relevance")
    assert quad_mean + quad_std < heur_mean + heur_std
    # And the quadrature is close to Monte Carlo in absolute terms (actions are in [-2, 2]).
    assert quad_mean < 0.02 and quad_std < 0.02


def test_hybrid_quadrature_cross_covariances_match_monte_carlo() -> None:
    policy = make_hybrid(0)
    mean = torch.tensor([0.4, 0.3], dtype=DTYPE)
    cov = torch.tensor([[0.03, 0.01], [0.01, 0.1]], dtype=DTYPE)
    with torch.no_grad():
        obs = observation_moments(mean, cov, HYBRID_LAYOUT)
        out = action_moments(policy, mean, cov, obs, HYBRID_LAYOUT, "quadrature", 9)
        x = sample(mean, cov, 0)
        o = observe_torch(x, HYBRID_LAYOUT)
        u = policy(o)
    assert_mean_mc(out.mean, u)
    assert_cov_mc(out.cov, u, u)
    assert_cov_mc(out.cross_state, x, u)
    assert_cov_mc(out.cross_obs, o, u)


def test_quadrature_is_exact_for_polynomials() -> None:
    mean, cov = random_gaussian(2, 5)
    out = quadrature_moments(lambda x: x**2, mean, cov, order=3)
    # E[x_i^2] = mu_i^2 + S_ii; Var[x_i^2] = 4 mu_i^2 S_ii + 2 S_ii^2 (Isserlis).
    var = cov.diagonal()
    torch.testing.assert_close(out.mean, mean**2 + var)
    torch.testing.assert_close(out.cov.diagonal(), 4 * mean**2 * var + 2 * var**2)


# --------------------------------------------------------------------------- gradients
def spd(raw: torch.Tensor) -> torch.Tensor:
    return raw @ raw.T + 0.1 * torch.eye(raw.shape[0], dtype=DTYPE)


def test_gradcheck_observation_and_squash() -> None:
    layout = [("cos", 0), ("sin", 0), ("state", 1)]
    mean, raw = torch.tensor([0.3, -0.2], dtype=DTYPE), 0.3 * torch.eye(2, dtype=DTYPE)
    raw = raw + 0.1

    def obs_fn(m, r):
        return observation_moments(m, spd(r), layout)

    def squash_fn(m, r):
        return sin_squash_moments(m, spd(r), 1.3)

    for fn in (obs_fn, squash_fn):
        assert torch.autograd.gradcheck(
            fn, (mean.clone().requires_grad_(), raw.clone().requires_grad_())
        )


def test_gradcheck_gp_rbf_and_cost() -> None:
    post = small_gp(1, num=12)
    mean = torch.tensor([0.1, 0.2, -0.3], dtype=DTYPE, requires_grad=True)
    raw = (0.3 * torch.eye(3, dtype=DTYPE) + 0.05).requires_grad_()
    assert torch.autograd.gradcheck(lambda m, r: gp_moments(post, m, spd(r)), (mean, raw))
    net = RBFNetwork(3, 2, 4, generator=torch.Generator().manual_seed(0), weight_std=1.0)
    params = [p.detach().clone().requires_grad_() for p in net.parameters()]
    assert torch.autograd.gradcheck(
        lambda m, r, c, w, ls: rbf_moments_params(m, spd(r), c, w, ls), (mean, raw, *params)
    )
    target = torch.zeros(3, dtype=DTYPE)
    factor = torch.tensor([[1.0, 0.0, 0.5]], dtype=DTYPE)
    assert torch.autograd.gradcheck(
        lambda m, r: expected_saturating_cost(m, spd(r), target, factor), (mean, raw)
    )


def rbf_moments_params(mean, cov, centres, weights, log_ls):
    from leoc.pilco.moments import se_sum_moments

    log_signal = torch.zeros(weights.shape[0], dtype=DTYPE)
    return se_sum_moments(centres, weights, log_ls, log_signal, mean, cov)


def test_gradcheck_hybrid_quadrature() -> None:
    policy = make_hybrid(2)
    mean = torch.tensor([0.5, 0.1], dtype=DTYPE, requires_grad=True)
    raw = (0.2 * torch.eye(2, dtype=DTYPE) + 0.02).requires_grad_()
    log_lambda = policy.log_lambda.detach().clone().requires_grad_()
    weights = policy.nonlinear.weights.detach().clone().requires_grad_()

    def fn(m, r, lam, w):
        def act(o):
            return torch.func.functional_call(
                policy, {"log_lambda": lam, "nonlinear.weights": w}, (o,)
            )

        out = hybrid_quadrature_moments(act, m, spd(r), HYBRID_LAYOUT, 4)
        return out.mean, out.cov, out.cross_state, out.cross_obs

    assert torch.autograd.gradcheck(fn, (mean, raw, log_lambda, weights))


# --------------------------------------------------------------------------- GP model
def test_gp_fit_predicts_held_out_points() -> None:
    post = small_gp(2, num=80)
    gen = torch.Generator().manual_seed(11)
    x = 0.5 * torch.randn(50, 3, generator=gen, dtype=DTYPE)
    truth = torch.stack([torch.sin(x[:, 0]) + 0.5 * x[:, 1], torch.cos(x[:, 2]) * x[:, 0]], 1)
    mean, var = gp_predict(post, x)
    assert float((mean - truth).abs().max()) < 0.1
    assert bool((var > 0).all())


def test_fitc_agrees_with_exact_gp() -> None:
    exact = small_gp(3, num=120)
    sparse = small_gp(
        3, num=120, settings=GPSettings(train_iterations=30, max_full_points=100, num_inducing=60)
    )
    x = 0.5 * torch.randn(30, 3, generator=torch.Generator().manual_seed(5), dtype=DTYPE)
    assert sparse.sparse and not exact.sparse
    assert float((gp_predict(exact, x)[0] - gp_predict(sparse, x)[0]).abs().max()) < 0.05


def test_cholesky_jitter_rescues_semidefinite_and_rejects_indefinite() -> None:
    vec = torch.tensor([[1.0], [2.0], [3.0]], dtype=DTYPE)
    factor = cholesky_jitter(vec @ vec.T, "rank one")  # PSD, singular: jitter makes it PD
    assert torch.allclose(factor @ factor.T, vec @ vec.T, atol=1e-3)
    with pytest.raises(CholeskyError, match="indefinite"):
        cholesky_jitter(torch.diag(torch.tensor([1.0, -1.0], dtype=DTYPE)), "indefinite")


def test_floor_eigenvalues_only_moves_indefinite_matrices() -> None:
    good = torch.tensor([[2.0, 0.5], [0.5, 1.0]], dtype=DTYPE)
    assert torch.equal(floor_eigenvalues(good), good)
    bad = torch.tensor([[1.0, 0.0], [0.0, -1e-6]], dtype=DTYPE)
    assert float(torch.linalg.eigvalsh(floor_eigenvalues(bad))[0]) > 0.0


# --------------------------------------------------------------------------- policies
def test_saturated_linear_policy_moments_match_monte_carlo() -> None:
    """sin squash of a linear controller on a Gaussian input: every step is exact."""
    policy = SaturatedPolicy(LinearController([[1.5, -2.0, 0.7]], [0.3]), 1.5)
    mean = torch.tensor([0.8, 0.4, -0.2], dtype=DTYPE)
    cov = torch.tensor([[0.1, 0.02, 0.0], [0.02, 0.2, 0.05], [0.0, 0.05, 0.3]], dtype=DTYPE)
    layout = [("state", 0), ("state", 1), ("state", 2)]
    with torch.no_grad():
        obs = observation_moments(mean, cov, layout)
        out = action_moments(policy, mean, cov, obs, layout)
        x = sample(mean, cov, 9)
        u = policy(x)
    assert_mean_mc(out.mean, u)
    assert_cov_mc(out.cov, u, u)
    assert_cov_mc(out.cross_state, x, u)


# --------------------------------------------------------------------------- training loop
@pytest.mark.slow
def test_train_save_load_and_resume(tmp_path, tiny_pilco_settings) -> None:
    from leoc.pilco.checkpoint import load_pilco_controller
    from leoc.pilco.train import train_pilco
    from leoc.policies import HeldPolicy
    from leoc.training import CURVE_COLUMNS

    run = tmp_path / "run"
    first = train_pilco(
        "pendulum",
        hybrid=True,
        seed=3,
        run_dir=run,
        iterations=1,
        progress=False,
        **tiny_pilco_settings,
    )
    for name in (
        "config.json",
        "curve.json",
        "curve.csv",
        "learning_curve.png",
        "controller.pt",
        "checkpoint.pt",
    ):
        assert (run / name).exists(), name
    assert [row["iteration"] for row in first.curve] == [0, 1]
    keys = set(CURVE_COLUMNS) | {
        "iteration",
        "returns",
        "hold_steps",
        "rollout_return",
        "predicted_cost",
        "data_size",
        "wall_seconds",
    }
    assert keys <= set(first.curve[-1])
    assert len(first.curve[-1]["returns"]) == tiny_pilco_settings["eval_episodes"]
    assert first.curve[1]["interaction_seconds"] == pytest.approx(3 * 24 * 0.05)
    assert first.summary["model_selection"] == "final"
    # the controller carries PILCO's control period
    assert isinstance(first.policy, HeldPolicy) and first.policy.action_repeat == 2
    resumed = train_pilco(
        "pendulum",
        hybrid=True,
        seed=3,
        run_dir=run,
        iterations=2,
        progress=False,
        **tiny_pilco_settings,
    )
    assert [row["iteration"] for row in resumed.curve] == [0, 1, 2]
    saved = json.loads((run / "curve.json").read_text())["curve"]
    assert saved[:2] == json.loads(json.dumps(first.curve))
    loaded = load_pilco_controller(run)
    assert isinstance(loaded, HeldPolicy) and loaded.action_repeat == 2
    obs = torch.tensor([[0.5, 0.8, -1.0]], dtype=DTYPE)
    torch.testing.assert_close(loaded(obs), resumed.policy(obs))
    # the second iteration moved the policy, so the loaded one is not the first one by chance
    assert (loaded(obs) - first.policy(obs)).abs().max() > 1e-6
    # The same seed without resuming gives the same run (determinism).
    again = train_pilco(
        "pendulum",
        hybrid=True,
        seed=3,
        run_dir=tmp_path / "again",
        iterations=1,
        progress=False,
        resume=False,
        **tiny_pilco_settings,
    )
    assert [r["rollout_return"] for r in again.curve] == [
        r["rollout_return"] for r in resumed.curve[:2]
    ]
    assert [r["mean_return"] for r in again.curve] == [r["mean_return"] for r in resumed.curve[:2]]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar"])
def test_pilco_hybrid_identities_hold_at_its_control_period(name) -> None:
    from leoc.control import design_lqr
    from leoc.pilco.config import PilcoConfig
    from leoc.pilco.policy import build_policy
    from leoc.systems import make_system

    system = make_system(name)
    config = PilcoConfig.for_system(name, hybrid=True, num_basis=4)
    gen = torch.Generator().manual_seed(1)
    observations = system.observe(torch.randn(20, system.state_dim, generator=gen, dtype=DTYPE))
    policy = build_policy(system, config, gen, observations.numpy())
    held = design_lqr(system, action_repeat=config.action_repeat)
    single = design_lqr(system)
    a = torch.as_tensor(system.operating_obs, dtype=DTYPE)
    torch.testing.assert_close(policy(a[None])[0], torch.as_tensor(held.b + held.W @ a.numpy()))
    jacobian = torch.autograd.functional.jacobian(lambda x: policy(x[None])[0], a)
    np.testing.assert_allclose(jacobian.numpy(), held.W, rtol=0, atol=1e-12)
    assert not np.allclose(held.W, single.W, rtol=1e-3)  # the period changes the design

    # the closed loop actually run, x -> step_held(x, pi(o(x)), 3), has the design's poles
    def closed_loop(x: torch.Tensor) -> torch.Tensor:
        state = x[None]
        return system.step_held(state, policy(system.observe(state)), config.action_repeat)[0]

    state = torch.as_tensor(system.operating_state, dtype=DTYPE)
    poles = np.linalg.eigvals(torch.autograd.functional.jacobian(closed_loop, state).numpy())
    np.testing.assert_allclose(
        np.sort_complex(poles), np.sort_complex(held.closed_loop_eigenvalues), atol=1e-9
    )
    assert np.max(np.abs(poles)) < 1.0


@pytest.mark.extended
@pytest.mark.xfail(
    strict=False,
    reason="PILCO's seed outcomes depend on the machine's floating point (issue 41): 3 of 3 on "
    "a 2-core AMD EPYC with AVX2 kernels, 1 of 3 with AVX-512, 0 of 3 on a 2-core Intel Xeon "
    "with AVX2 kernels forced (2026-11-27; the code of the AMD run gives the same first "
    "iterations bit for bit there); "
    "the rate is issue 41's to fix, this test reports it",
)
def test_pilco_hybrid_learns_the_pendulum_swing_up_on_most_seeds(tmp_path, monkeypatch) -> None:
    """The paper's budget (10 iterations) on three seeds: at least two learn to swing up and
    hold (two consecutive evaluations held in every episode).

    PILCO's outcome on a seed depends on floating-point details: on one AVX-512 machine
    (2026-11-24) torch's default AVX-512 kernels gave 1 of 3 (seed 2 stuck at a return of -861,
    seed 1 first held at its 10th iteration), the same code with its AVX2 kernels 3 of 3. The
    workers (new processes) therefore run the AVX2 kernels the rate was measured with, on every
    x86 machine that has them; the dependence itself is a finding, not something this test
    hides (PILCO guide, "Floating point and seeds")."""
    from leoc.pilco.seeds import train_seeds

    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "avx2")
    monkeypatch.setenv("MKL_ENABLE_INSTRUCTIONS", "AVX2")
    outcomes = train_seeds("pendulum", True, [0, 1, 2], tmp_path, jobs=2, iterations=10)
    assert sum(outcome.success for outcome in outcomes) >= 2, outcomes


def test_recomputing_bilinear_exp_has_the_plain_gradients() -> None:
    from leoc.linalg import WeightedExpBilinear

    gen = torch.Generator().manual_seed(0)
    left = (0.3 * torch.randn(3, 5, 4, generator=gen, dtype=DTYPE)).requires_grad_()
    right = (0.3 * torch.randn(3, 5, 4, generator=gen, dtype=DTYPE)).requires_grad_()
    weights = torch.randn(3, 5, 5, generator=gen, dtype=DTYPE).requires_grad_()
    assert torch.autograd.gradcheck(WeightedExpBilinear.apply, (left, right, weights))
    plain = (weights * torch.exp(left @ right.transpose(-1, -2))).sum((-1, -2))
    torch.testing.assert_close(WeightedExpBilinear.apply(left, right, weights), plain)


@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar"])
def test_cost_distance_is_the_physical_target_distance(name) -> None:
    from leoc.pilco.objective import cost_spec
    from leoc.systems import make_system

    system = make_system(name)
    spec = cost_spec(system, width=1.0)
    gen = torch.Generator().manual_seed(0)
    states = torch.randn(50, system.state_dim, generator=gen, dtype=DTYPE)
    obs = system.observe(states)
    distance = ((obs - spec.target) @ spec.factor.T).square().sum(-1)
    if name == "pendulum":  # the rod's tip against the upright tip
        length = system.params.length
        theta = states[:, 0]
        expected = (length * torch.sin(theta)) ** 2 + (length * torch.cos(theta) - length) ** 2
    elif name == "cartpole":  # the pole's tip against the upright tip over the track centre
        length = 2.0 * system.params.half_length
        x, theta = states[:, 0], states[:, 2]
        expected = (x + length * torch.sin(theta)) ** 2 + (length * torch.cos(theta) - length) ** 2
    else:  # the car's position against the hilltop
        expected = states[:, 0] ** 2
    torch.testing.assert_close(distance, expected)
