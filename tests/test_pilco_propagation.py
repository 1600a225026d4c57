"""Multi-step moment matching (:func:`leoc.pilco.propagate.predict`) against Monte Carlo.

PILCO minimises the expected cost of the *horizon* prediction, so the prediction itself is
tested here over ``HORIZON`` decisions, for a saturated RBF policy (PILCO's baseline) and for
the paper's hybrid policy (relevance blend, moments by quadrature, ``predict``'s default).

Reference. ``predict`` models the closed loop as the Markov chain
``x_{t+1} = x_t + Delta_t`` with ``Delta_t ~ N(m(o_t, u_t), diag v(o_t, u_t))``, where
``o_t`` is the observation (angles as cos/sin), ``u_t = pi(o_t)`` the action and ``m``, ``v``
the GP's posterior mean and *latent* variance (``gp_moments`` gives the moments of the latent
prediction, without the observation noise, so the reference draws no noise either), drawn
independently at every step (no correlation of the GP function across steps, which moment
matching ignores too). Monte Carlo simulates exactly this chain: ``NUM_ROLLOUTS`` rollouts
from ``N(start_mean, start_cov)``, each step evaluating the same GP posterior
(:func:`~leoc.pilco.gp.gp_predict`) and the same policy at every rollout's own state.

Tolerance. Errors are normalised by the Monte Carlo standard deviations: a mean error in
units of the state's standard deviation, a covariance error in units of
``sqrt(C_ii C_jj)`` (so a correlation error). Two parts:

- sampling error: the sample mean's standard error is ``1 / sqrt(N)`` of a standard
  deviation, a covariance entry's at most ``sqrt(2 / N)`` of ``sqrt(C_ii C_jj)`` (Gaussian
  fourth moments); ``Z_TOL`` of them;
- projection error: moment matching replaces the state distribution by a Gaussian at every
  step and takes the GP input (cos/sin, action) as jointly Gaussian; with a small start
  covariance, a GP smooth on its scale and a short horizon, this error is of second order in
  the spread. ``PROJECTION_TOL`` allows for it (the measured errors of the correct code are
  below half of it, see the constants).

Regime: a pendulum-like GP (smooth hyperparameters, data around the start), a start spread of
0.05 rad and 0.1 rad/s, ``HORIZON`` = 6 decisions of 0.1 s, the sin saturation active but far
from flat. Planted bugs in ``propagate_step``, dropping ``Cov[x, Delta]``
(``cross_x_delta + cross_x_delta.T`` in the next covariance) or only its ``Cov[x, u]``
(``act.cross_state``) or ``Cov[x, o]`` (``state_cov @ obs.io``) part, give largest covariance
errors of 0.95 / 1.00, 0.21 / 0.20 and 1.12 / 0.94 (RBF / hybrid policy): every one more than
twice ``COV_TOL`` (measured with this module's seeds).
"""

from __future__ import annotations

import math

import pytest
import torch

from leoc.pilco.gp import GPHyper, gp_predict, posterior
from leoc.pilco.propagate import SaturatedPolicy, observe_torch, predict
from leoc.policies import HybridPolicy, LinearController, RBFNetwork

DTYPE = torch.float64
LAYOUT = [("cos", 0), ("sin", 0), ("state", 1)]  # pendulum: theta (0 upright), omega
DT = 0.1  # seconds per decision of the synthetic pendulum
ACTION_GAIN = 2.0  # angular acceleration per unit action
ACTION_LIMIT = 5.0  # u_max of both policies' sin saturation
HORIZON = 6
START_MEAN = (0.6, 0.0)
START_COV = ((0.0025, 0.0), (0.0, 0.01))
NUM_DATA = 100  # GP training transitions
NUM_ROLLOUTS = 40_000
Z_TOL = 5.0  # standard errors of the Monte Carlo estimates
# Allowance for the Gaussian projection, in the normalised units of the module docstring. The
# correct code's largest errors (measured at NUM_ROLLOUTS, seeds fixed) are 0.014 (means) and
# 0.017 / 0.037 (covariances, RBF / hybrid); the planted bugs' smallest is 0.197 (module docstring).
PROJECTION_TOL = 0.05
MEAN_TOL = Z_TOL / math.sqrt(NUM_ROLLOUTS) + PROJECTION_TOL  # 0.075
COV_TOL = Z_TOL * math.sqrt(2.0 / NUM_ROLLOUTS) + PROJECTION_TOL  # 0.085


def pendulum_delta(state: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    """State change over one decision of a damped pendulum (upright at 0), 4 Euler substeps."""
    theta, omega = state[:, 0], state[:, 1]
    h = DT / 4
    for _ in range(4):
        acc = 9.81 * torch.sin(theta) - 0.5 * omega + ACTION_GAIN * action[:, 0]
        theta, omega = theta + h * omega, omega + h * acc
    return torch.stack([theta, omega], dim=1) - state


def dynamics_gp():
    """Exact GP posterior of NUM_DATA transitions around the start, hand-set smooth hyperparameters
    (length-scales about the data's spread, tiny noise)."""
    gen = torch.Generator().manual_seed(0)
    states = torch.stack(
        [
            0.5 + 0.6 * torch.randn(NUM_DATA, generator=gen, dtype=DTYPE),
            1.2 * torch.randn(NUM_DATA, generator=gen, dtype=DTYPE),
        ],
        dim=1,
    )
    actions = 1.5 * torch.randn(NUM_DATA, 1, generator=gen, dtype=DTYPE)
    inputs = torch.cat([observe_torch(states, LAYOUT), actions], dim=1)
    targets = pendulum_delta(states, actions)
    lengthscales = torch.tensor([[0.6, 0.8, 2.0, 2.5], [0.6, 0.8, 2.0, 2.5]], dtype=DTYPE)
    hyper = GPHyper(
        torch.log(lengthscales),
        torch.log(targets.std(0)),
        torch.log(1e-3 * targets.std(0)),
    )
    return posterior(hyper, inputs, targets, torch.zeros(2, dtype=DTYPE), None)


def rbf_policy() -> SaturatedPolicy:
    """PILCO's baseline: an RBF network squashed by ``u_max sin(u / u_max)``."""
    gen = torch.Generator().manual_seed(1)
    net = RBFNetwork(3, 1, 10, generator=gen, weight_std=1.5, lengthscales=[0.7, 0.7, 1.5])
    return SaturatedPolicy(net, ACTION_LIMIT)


def hybrid_policy() -> HybridPolicy:
    """The paper's hybrid: relevance ``(1 + d)^-2`` blending a stabilising linear controller
    and an RBF network, sin-saturated."""
    gen = torch.Generator().manual_seed(2)
    rbf = RBFNetwork(3, 1, 10, generator=gen, weight_std=0.5, lengthscales=1.0)
    linear = LinearController([[0.0, -8.0, -0.5]])
    return HybridPolicy(
        linear,
        rbf,
        operating_point=[1.0, 0.0, 0.0],
        lambda_init=[1.0, 1.0, 10.0],
        action_limit=ACTION_LIMIT,
        saturation="sin",
    )


def monte_carlo(policy, model, start_mean, start_cov, horizon):
    """Rollouts of the chain of the module docstring: states (H+1, N, S)."""
    gen = torch.Generator().manual_seed(3)
    noise = torch.randn(NUM_ROLLOUTS, 2, generator=gen, dtype=DTYPE)
    x = start_mean + noise @ torch.linalg.cholesky(start_cov).T
    states = [x]
    for _ in range(horizon):
        obs = observe_torch(x, LAYOUT)
        mean, var = gp_predict(model, torch.cat([obs, policy(obs)], dim=1))
        x = (
            x
            + mean
            + var.clamp(min=0.0).sqrt() * torch.randn(mean.shape, generator=gen, dtype=DTYPE)
        )
        states.append(x)
    return torch.stack(states)


def normalised_errors(pred, states):
    """Largest mean error (in MC standard deviations) and covariance error (in
    ``sqrt(C_ii C_jj)``) over the horizon."""
    mc_mean = states.mean(1)
    centred = states - mc_mean[:, None, :]
    mc_cov = centred.transpose(1, 2) @ centred / (states.shape[1] - 1)
    std = mc_cov.diagonal(dim1=1, dim2=2).sqrt()
    mean_err = ((pred.means - mc_mean) / std).abs().max()
    cov_err = ((pred.covs - mc_cov) / (std[:, :, None] * std[:, None, :])).abs().max()
    return float(mean_err), float(cov_err)


def run_case(policy) -> tuple[float, float]:
    """Normalised errors (:func:`normalised_errors`) of ``predict`` (its default hybrid method,
    quadrature) against :func:`monte_carlo` for ``policy``."""
    model = dynamics_gp()
    mean = torch.tensor(START_MEAN, dtype=DTYPE)
    cov = torch.tensor(START_COV, dtype=DTYPE)
    target = torch.tensor([1.0, 0.0, 0.0], dtype=DTYPE)
    factor = torch.eye(3, dtype=DTYPE)
    with torch.no_grad():
        pred = predict(policy, model, mean, cov, HORIZON, LAYOUT, target, factor)
        states = monte_carlo(policy, model, mean, cov, HORIZON)
    return normalised_errors(pred, states)


@pytest.mark.slow
@pytest.mark.parametrize("make_policy", [rbf_policy, hybrid_policy])
def test_horizon_prediction_matches_monte_carlo(make_policy) -> None:
    """Predicted means and covariances of every step within the tolerance of Monte Carlo."""
    mean_err, cov_err = run_case(make_policy())
    assert mean_err <= MEAN_TOL, f"mean error {mean_err:.4f} > {MEAN_TOL:.4f}"
    assert cov_err <= COV_TOL, f"covariance error {cov_err:.4f} > {COV_TOL:.4f}"


def test_hybrid_relevance_blends_over_the_start_distribution() -> None:
    """The hybrid case tests the blend, not the linear part alone: at the start the relevance
    is neither 0 nor 1 and varies across the start distribution."""
    policy = hybrid_policy()
    gen = torch.Generator().manual_seed(4)
    start = (
        torch.tensor(START_MEAN, dtype=DTYPE)
        + torch.randn(1000, 2, generator=gen, dtype=DTYPE)
        @ torch.linalg.cholesky(torch.tensor(START_COV, dtype=DTYPE)).T
    )
    with torch.no_grad():
        relevance = policy.relevance(observe_torch(start, LAYOUT))
    assert 0.3 < float(relevance.mean()) < 0.9
    assert float(relevance.std()) > 0.02
