"""PILCO's policies: the RBF baseline and the LEOC hybrid (paper or ROA relevance), built
from the initial data."""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from leoc.pilco.config import PilcoConfig
from leoc.pilco.propagate import SaturatedPolicy
from leoc.policies import HybridPolicy, LinearController, RBFNetwork, roa_hybrid
from leoc.systems.base import DTYPE, System

# Initial RBF weights: standard deviation as a fraction of the actuator limit.
WEIGHT_STD_FRACTION = 0.1
# Smallest initial RBF length-scale (a constant observation column would otherwise give 0).
MIN_POLICY_LENGTHSCALE = 0.1


def obs_layout(system: System) -> list[tuple[str, int]]:
    """The observation layout as plain ``(kind, state_index)`` pairs (PILCO's moment code)."""
    return system.observation.pairs()


def build_policy(
    system: System,
    config: PilcoConfig,
    generator: torch.Generator,
    observations: np.ndarray | None = None,
) -> nn.Module:
    """RBF baseline ``u_max sin(H(o) / u_max)`` or the hybrid with the same H and squash.

    Centres: the plain entries of ``num_basis`` observations drawn from the initial data, the
    cos/sin entries of every angle at a uniformly random angle (random data from the swing-up
    start only visit the bottom, and a policy without a basis function near the top has
    nothing to balance with); length-scales: the data's spread per observation entry;
    weights ``0.1 u_max N(0, 1)``.
    """
    limit = system.action_limit
    centres, scales = None, 1.0
    if observations is not None and len(observations) > 0:
        picks = torch.randint(len(observations), (config.num_basis,), generator=generator)
        centres = observations[picks.numpy()].copy()
        _spread_angle_centres(system, centres, generator)
        scales = np.maximum(observations.std(axis=0), MIN_POLICY_LENGTHSCALE)
    rbf = RBFNetwork(
        system.obs_dim,
        system.action_dim,
        config.num_basis,
        centres=centres,
        lengthscales=scales,
        generator=generator,
        weight_std=WEIGHT_STD_FRACTION * limit,
    )
    if not config.hybrid:
        return SaturatedPolicy(rbf, limit, "sin")
    from leoc.control.lqr import design_lqr

    design = design_lqr(system, action_repeat=config.action_repeat)
    if config.relevance == "roa":
        return roa_hybrid(system, design, rbf, learn_width=config.learn_lambda, saturation="sin")
    return HybridPolicy(
        LinearController(design.W, design.b),
        rbf,
        operating_point=system.operating_obs,
        lambda_init=config.lambda_init,
        learn_lambda=config.learn_lambda,
        action_limit=limit,
        saturation="sin",
    )


def _spread_angle_centres(system: System, centres: np.ndarray, generator: torch.Generator) -> None:
    """Overwrite, in place, the cos/sin columns of ``centres`` (N, O) with those of uniformly
    random angles, one angle per basis function and angle state."""
    for angle in system.observation.angle_columns():
        angles = 2.0 * math.pi * torch.rand(len(centres), generator=generator, dtype=DTYPE)
        centres[:, angle.cos_column] = torch.cos(angles).numpy()
        centres[:, angle.sin_column] = torch.sin(angles).numpy()
