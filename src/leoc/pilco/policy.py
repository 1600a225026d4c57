"""PILCO's policies: the RBF baseline and the LEOC hybrid (paper or ROA relevance), built
from the initial data."""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from leoc.pilco.config import PilcoConfig
from leoc.pilco.propagate import SaturatedPolicy
from leoc.policies import RBFNetwork
from leoc.policies.spec import build_hybrid, hybrid_design
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
    rbf = _draw_rbf(system, config, generator, observations)
    if not config.hybrid:
        return SaturatedPolicy(rbf, limit, "sin")
    from leoc.control.lqr import design_lqr

    # the LQR of the loop the controller runs in: its deployed period (the authors' PILCO plans
    # at a longer period than it deploys at; their continuous design's gain is the same at both,
    # but its region of attraction is the deployed loop's: held 3 steps on the pendulum it is
    # not even stable)
    design = design_lqr(
        system, method=config.lqr_method, action_repeat=config.controller_action_repeat
    )
    spec = config.hybrid
    return build_hybrid(
        spec,
        hybrid_design(spec, system, design, saturation="sin", action_limit=limit),
        rbf,
        action_limit=limit,
        saturation="sin",
    )


def _draw_rbf(
    system: System,
    config: PilcoConfig,
    generator: torch.Generator,
    observations: np.ndarray | None,
) -> RBFNetwork:
    """A fresh RBF part (the draw :func:`build_policy` documents)."""
    centres, scales = None, 1.0
    if observations is not None and len(observations) > 0:
        picks = torch.randint(len(observations), (config.num_basis,), generator=generator)
        centres = observations[picks.numpy()].copy()
        _spread_angle_centres(system, centres, generator)
        scales = np.maximum(observations.std(axis=0), MIN_POLICY_LENGTHSCALE)
    return RBFNetwork(
        system.obs_dim,
        system.action_dim,
        config.num_basis,
        centres=centres,
        lengthscales=scales,
        generator=generator,
        weight_std=WEIGHT_STD_FRACTION * system.action_limit,
    )


def redraw_rbf(
    policy: nn.Module,
    system: System,
    config: PilcoConfig,
    generator: torch.Generator,
    observations: np.ndarray,
) -> None:
    """Replace, in place, the RBF part of a :func:`build_policy` policy by a fresh draw from
    ``observations`` (a policy-optimisation restart); a hybrid keeps its linear part and
    relevance."""
    rbf = policy.inner if isinstance(policy, SaturatedPolicy) else policy.nonlinear
    if not isinstance(rbf, RBFNetwork):
        raise TypeError(f"policy: expected an RBF part, found {type(rbf).__name__}")
    fresh = _draw_rbf(system, config, generator, observations)
    with torch.no_grad():
        for name, value in fresh.state_dict().items():
            rbf.state_dict()[name].copy_(value)


def _spread_angle_centres(system: System, centres: np.ndarray, generator: torch.Generator) -> None:
    """Overwrite, in place, the cos/sin columns of ``centres`` (N, O) with those of uniformly
    random angles, one angle per basis function and angle state."""
    for angle in system.observation.angle_columns():
        angles = 2.0 * math.pi * torch.rand(len(centres), generator=generator, dtype=DTYPE)
        centres[:, angle.cos_column] = torch.cos(angles).numpy()
        centres[:, angle.sin_column] = torch.sin(angles).numpy()
