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
    start_cost : float
        The predicted cost of the policy the optimisation started from (inf if it failed).
    start_gradient_norm : float
        The Euclidean norm of that cost's gradient over the trained parameters: near 0, a cost
        saturated along the whole predicted trajectory gives the optimiser nothing to follow.
    best_gradient_norm : float
        The gradient's norm at the parameters kept (those of ``cost``).
    failed_evaluations : int
        Evaluations that failed (a non-finite cost or a Cholesky failure).
    """

    cost: float
    iterations: int
    evaluations: int
    restarts: int
    start_cost: float = math.nan
    start_gradient_norm: float = math.nan
    best_gradient_norm: float = math.nan
    failed_evaluations: int = 0


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
    track = _Evaluations(policy, params)

    def closure() -> torch.Tensor:
        optimiser.zero_grad()
        try:
            loss = predict_policy(policy, model, system, config).total_cost
        except RuntimeError:  # CholeskyError or a linalg failure at extreme parameters
            loss = torch.tensor(math.inf, dtype=DTYPE)
        return track.record(loss)

    iterations, rounds = 0, 0
    while iterations < config.policy_iterations:
        before = track.best_loss
        optimiser = torch.optim.LBFGS(
            params, max_iter=config.policy_iterations - iterations, line_search_fn="strong_wolfe"
        )
        optimiser.step(closure)
        rounds += 1
        iterations += max(1, optimiser.state[params[0]].get("n_iter", 0))
        if track.best_state is not None:
            policy.load_state_dict(track.best_state)
        if not before - track.best_loss > RESTART_MIN_IMPROVEMENT * abs(track.best_loss):
            break
    return track.outcome(iterations, rounds - 1)


class _Evaluations:
    """The evaluations of one :func:`optimise_policy`: each cost and gradient norm, and the best
    parameters seen."""

    def __init__(self, policy: nn.Module, params: list[torch.Tensor]) -> None:
        self.policy, self.params = policy, params
        self.seen: list[tuple[float, float]] = []  # (cost, gradient norm) of each evaluation
        self.best_loss, self.best_gradient = math.inf, math.nan
        self.best_state: dict[str, torch.Tensor] | None = None

    def record(self, loss: torch.Tensor) -> torch.Tensor:
        """The loss the line search sees: ``loss`` with its gradient, or +inf (zero gradient)
        for a failed evaluation."""
        if not torch.isfinite(loss):
            for p in self.params:
                p.grad = torch.zeros_like(p)
            self.seen.append((math.inf, math.nan))
            return torch.tensor(math.inf, dtype=DTYPE)
        loss.backward()
        grads = [p.grad for p in self.params if p.grad is not None]
        norm = math.sqrt(sum(float(g.square().sum()) for g in grads))
        self.seen.append((loss.item(), norm))
        if loss.item() < self.best_loss:
            self.best_loss, self.best_gradient = loss.item(), norm
            self.best_state = {k: v.detach().clone() for k, v in self.policy.state_dict().items()}
        return loss

    def outcome(self, iterations: int, restarts: int) -> PolicyOptimisation:
        start_cost, start_gradient = self.seen[0] if self.seen else (math.inf, math.nan)
        return PolicyOptimisation(
            self.best_loss,
            iterations,
            len(self.seen),
            restarts,
            start_cost,
            start_gradient,
            self.best_gradient,
            sum(cost == math.inf for cost, _ in self.seen),
        )
