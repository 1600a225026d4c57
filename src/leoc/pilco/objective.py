"""PILCO's objective: the predicted saturating cost over the horizon from the swing-up start,
and its minimisation by L-BFGS."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch
from torch import nn

from leoc.pilco.config import PilcoConfig
from leoc.pilco.gp import GPPosterior
from leoc.pilco.policy import obs_layout
from leoc.pilco.propagate import Prediction, predict
from leoc.systems.base import DTYPE, System

# Variance of a uniform distribution on [-a, a] is a^2 / 3.
UNIFORM_VARIANCE_FACTOR = 1.0 / 3.0


class CostSpec(NamedTuple):
    """Saturating cost on the observation: target (O,) and factor (K, O), W = F^T F."""

    target: torch.Tensor
    factor: torch.Tensor


def cost_spec(system: System, width: float, weights: Sequence[float] | None = None) -> CostSpec:
    """The saturating cost of ``system`` on the observation, divided by ``width``: target o(a)
    and the factor ``System.cost_factor()`` (e.g. the pendulum's rod tip, the cart-pole's pole
    tip over the track centre, the mountain car's position), or, with ``weights`` (one per
    observation entry, >= 0), the diagonal factor ``diag(sqrt(weights))``, i.e.
    ``W = diag(weights)`` on the observation."""
    target = torch.as_tensor(system.operating_obs, dtype=DTYPE)
    if weights is not None:
        weight = torch.as_tensor(np.asarray(weights, dtype=float), dtype=DTYPE)
        if weight.shape != (system.obs_dim,):
            raise ValueError(
                f"cost_weights: expected {system.obs_dim} weights (one per observation entry of "
                f"{type(system).__name__}), found {len(weight)}"
            )
        return CostSpec(target, torch.diag(weight.sqrt()) / width)
    factor = torch.as_tensor(np.asarray(system.cost_factor(), dtype=float), dtype=DTYPE)
    if factor.ndim != 2 or factor.shape[1] != system.obs_dim:
        raise ValueError(
            f"cost_factor: expected shape (K, {system.obs_dim}) from {type(system).__name__}, "
            f"found {tuple(factor.shape)}"
        )
    return CostSpec(target, factor / width)


def start_distribution(
    system: System,
    mean: Sequence[float] | None = None,
    variance: Sequence[float] | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and covariance of the predicted rollout's Gaussian start, in state coordinates.

    Defaults: the centre of the uniform swing-up start and its variance a^2 / 3 per entry;
    ``mean`` (S,) and ``variance`` (S,) (a diagonal covariance) replace them.
    """
    start_mean = torch.as_tensor(system.swing_up_centre if mean is None else mean, dtype=DTYPE)
    if variance is None:
        spread = torch.as_tensor(system.start_spread, dtype=DTYPE)
        start_var = UNIFORM_VARIANCE_FACTOR * spread.square()
    else:
        start_var = torch.as_tensor(variance, dtype=DTYPE)
    for name, value in (("start_mean", start_mean), ("start_variance", start_var)):
        if value.shape != (system.state_dim,):
            raise ValueError(
                f"{name}: expected {system.state_dim} entries (the state of "
                f"{type(system).__name__}), found {tuple(value.shape)}"
            )
    return start_mean, torch.diag(start_var)


def predict_policy(
    policy: nn.Module, model: GPPosterior, system: System, config: PilcoConfig
) -> Prediction:
    """Predicted trajectory and costs of ``policy`` from the swing-up start."""
    mean, cov = start_distribution(system, config.start_mean, config.start_variance)
    spec = cost_spec(system, config.cost_width, config.cost_weights)
    return predict(
        policy,
        model,
        mean,
        cov,
        config.horizon,
        obs_layout(system),
        spec.target,
        spec.factor,
        config.hybrid_method,
        config.quadrature_order,
    )


class PolicyOptimisation(NamedTuple):
    """Outcome of :func:`optimise_policy`.

    Attributes
    ----------
    cost : float
        The lowest predicted horizon cost seen (the policy is left at its parameters).
    iterations : int
        L-BFGS iterations made, over all rounds (at most ``policy_iterations``).
    evaluations : int
        Evaluations of the cost and its gradient, line searches included.
    restarts : int
        Rounds started again from the best parameters with a fresh curvature history.
    """

    cost: float
    iterations: int
    evaluations: int
    restarts: int


# A restart that lowers the best cost by less than this fraction of it ends the optimisation.
RESTART_MIN_IMPROVEMENT = 1e-6


def optimise_policy(
    policy: nn.Module, model: GPPosterior, system: System, config: PilcoConfig
) -> PolicyOptimisation:
    """Minimise the predicted horizon cost by L-BFGS (strong Wolfe line search).

    The budget is ``config.policy_iterations`` L-BFGS iterations. torch's L-BFGS stops early on
    "lack of progress" (a line search that could not move, typically after an evaluation that
    failed or at a kink of the saturation), long before the budget; so, as the original PILCO's
    ``minimize`` spends its whole budget of line searches, a round that stops early is followed
    by another from the best parameters with a fresh curvature history, until the budget is
    spent or a round lowers the best cost by less than ``RESTART_MIN_IMPROVEMENT`` of it.

    A failed evaluation (non-finite cost or a Cholesky failure) counts as +inf, which the line
    search backs away from; the best parameters seen are restored at the end.
    """
    params = [p for p in policy.parameters() if p.requires_grad]
    best = {"loss": math.inf, "state": None}
    evaluations = 0

    def closure() -> torch.Tensor:
        nonlocal evaluations
        evaluations += 1
        optimiser.zero_grad()
        try:
            loss = predict_policy(policy, model, system, config).total_cost
        except RuntimeError:  # CholeskyError or a linalg failure at extreme parameters
            loss = torch.tensor(math.inf, dtype=DTYPE)
        if not torch.isfinite(loss):
            for p in params:
                p.grad = torch.zeros_like(p)
            return torch.tensor(math.inf, dtype=DTYPE)
        loss.backward()
        if loss.item() < best["loss"]:
            best["loss"] = loss.item()
            best["state"] = {k: v.detach().clone() for k, v in policy.state_dict().items()}
        return loss

    iterations, rounds = 0, 0
    while iterations < config.policy_iterations:
        before = best["loss"]
        optimiser = torch.optim.LBFGS(
            params, max_iter=config.policy_iterations - iterations, line_search_fn="strong_wolfe"
        )
        optimiser.step(closure)
        rounds += 1
        iterations += max(1, optimiser.state[params[0]].get("n_iter", 0))
        if best["state"] is not None:
            policy.load_state_dict(best["state"])
        if not before - best["loss"] > RESTART_MIN_IMPROVEMENT * abs(best["loss"]):
            break
    return PolicyOptimisation(best["loss"], iterations, evaluations, rounds - 1)
