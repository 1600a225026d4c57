"""PILCO's objective: the predicted saturating cost over the horizon from the swing-up start,
and its minimisation by L-BFGS."""

from __future__ import annotations

import math
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


def cost_spec(system: System, width: float) -> CostSpec:
    """The saturating cost of ``system`` on the observation, divided by ``width``: target o(a)
    and the factor ``System.cost_factor()`` (e.g. the pendulum's rod tip, the cart-pole's pole
    tip over the track centre, the mountain car's position)."""
    target = torch.as_tensor(system.operating_obs, dtype=DTYPE)
    factor = torch.as_tensor(np.asarray(system.cost_factor(), dtype=float), dtype=DTYPE)
    if factor.ndim != 2 or factor.shape[1] != system.obs_dim:
        raise ValueError(
            f"cost_factor: expected shape (K, {system.obs_dim}) from {type(system).__name__}, "
            f"found {tuple(factor.shape)}"
        )
    return CostSpec(target, factor / width)


def start_distribution(system: System) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and covariance of the uniform swing-up start (variance a^2 / 3 per entry)."""
    mean = torch.as_tensor(system.swing_up_centre, dtype=DTYPE)
    spread = torch.as_tensor(system.start_spread, dtype=DTYPE)
    return mean, torch.diag(UNIFORM_VARIANCE_FACTOR * spread.square())


def predict_policy(
    policy: nn.Module, model: GPPosterior, system: System, config: PilcoConfig
) -> Prediction:
    """Predicted trajectory and costs of ``policy`` from the swing-up start."""
    mean, cov = start_distribution(system)
    spec = cost_spec(system, config.cost_width)
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


def optimise_policy(
    policy: nn.Module, model: GPPosterior, system: System, config: PilcoConfig
) -> float:
    """Minimise the predicted horizon cost by L-BFGS (strong Wolfe line search).

    A failed evaluation (non-finite cost or a Cholesky failure) counts as +inf, which the line
    search backs away from; the best parameters seen are restored at the end.
    """
    params = [p for p in policy.parameters() if p.requires_grad]
    optimiser = torch.optim.LBFGS(
        params, max_iter=config.policy_iterations, line_search_fn="strong_wolfe"
    )
    best = {"loss": math.inf, "state": None}

    def closure() -> torch.Tensor:
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

    optimiser.step(closure)
    if best["state"] is not None:
        policy.load_state_dict(best["state"])
    return best["loss"]
