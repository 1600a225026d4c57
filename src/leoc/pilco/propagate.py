r"""Long-term prediction: propagate a Gaussian state through policy and GP over the horizon.

Letters: S state dimension, O observation dimension, F action dimension, H horizon.

One step, from :math:`x_t \sim \mathcal N(\mu_t, \Sigma_t)` (PILCO, Deisenroth & Rasmussen 2011):

1. observation :math:`o_t` (angles as cos/sin): exact moments, :func:`observation_moments`;
2. action :math:`u_t = \pi(o_t)`: mean, covariance, :math:`\operatorname{Cov}[o, u]` and
   :math:`\operatorname{Cov}[x, u]` by :func:`action_moments`;
3. the GP input :math:`(o_t, u_t)` is taken jointly Gaussian and the GP gives the exact moments
   of the state change :math:`\Delta_t` and :math:`\Sigma_{in}^{-1}\operatorname{Cov}[in, \Delta]`;
4. :math:`\mu_{t+1} = \mu_t + E[\Delta]`,
   :math:`\Sigma_{t+1} = \Sigma_t + \operatorname{Cov}[\Delta] + C + C^\top` with
   :math:`C = \operatorname{Cov}[x_t, \Delta]`.

Cross-covariances through a chain of maps are composed with PILCO's coefficient rule
:math:`\operatorname{Cov}[x, z] \approx \operatorname{Cov}[x, y]\, \Sigma_y^{-1}
\operatorname{Cov}[y, z]` (exact when y is an affine function of x, an approximation for the
cos/sin entries). The hybrid policy by quadrature gets :math:`\operatorname{Cov}[x, u]` and
:math:`\operatorname{Cov}[o, u]` directly from the nodes, with no such composition.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import torch
from torch import Tensor, nn

from leoc.linalg import symmetrise
from leoc.pilco.cost import expected_saturating_cost
from leoc.pilco.gp import GPPosterior
from leoc.pilco.moments import (
    MomentMatch,
    RBFConstants,
    SESumConstants,
    gp_constants,
    gp_moments,
    linear_moments,
    observation_moments,
    quadrature_moments,
    rbf_constants,
    rbf_moments,
    sin_squash_moments,
)
from leoc.policies import HybridPolicy, LinearController, RBFNetwork, saturate
from leoc.systems.observation import as_observation_map

HYBRID_METHODS = ("quadrature", "constant_relevance", "mixture")
DEFAULT_QUADRATURE_ORDER = 5
# Eigenvalue floor of the predicted state covariance: relative to its trace, plus an absolute
# floor for a collapsed covariance.
PSD_FLOOR_RELATIVE = 1e-9
PSD_FLOOR_ABSOLUTE = 1e-12


def floor_eigenvalues(cov: Tensor) -> Tensor:
    """Shift ``cov`` by ``max(0, floor - lambda_min) I`` so that it is positive definite.

    Why: near a stabilised operating point the predicted state covariance collapses (the
    closed loop contracts it by orders of magnitude), and the composed cross-covariance
    ``Cov[x, Delta]`` (coefficient rule, approximate for cos/sin entries) then leaves
    ``Sigma + Cov[Delta] + C + C^T`` slightly indefinite. The shift is zero (and so is its
    gradient) whenever the covariance is already above the floor; otherwise it moves only the
    smallest eigenvalue's share of mass, and the gradient of an eigenvalue is well defined.
    """
    smallest = torch.linalg.eigvalsh(cov)[0]
    floor = PSD_FLOOR_RELATIVE * cov.diagonal().sum().detach() + PSD_FLOOR_ABSOLUTE
    shift = torch.relu(floor - smallest)
    return cov + shift * torch.eye(cov.shape[0], dtype=cov.dtype)


class SaturatedPolicy(nn.Module):
    """``u_max sin(inner(o) / u_max)``: PILCO's squashed RBF (or linear) controller.

    Shapes: (..., O) -> (..., F).
    """

    def __init__(self, inner: nn.Module, action_limit: float, saturation: str = "sin"):
        super().__init__()
        self.inner = inner
        self.saturation = saturation
        self.register_buffer("action_limit", torch.tensor(float(action_limit), dtype=torch.float64))

    def forward(self, x: Tensor) -> Tensor:
        return saturate(self.inner(x), self.action_limit, self.saturation)


class ActionMoments(NamedTuple):
    """Moments of the action: mean (F,), cov (F, F), Cov[o, u] (O, F), Cov[x, u] (S, F)."""

    mean: Tensor
    cov: Tensor
    cross_obs: Tensor
    cross_state: Tensor


class Prediction(NamedTuple):
    """Predicted trajectory: means (H+1, S), covariances (H+1, S, S), expected costs (H,)."""

    means: Tensor
    covs: Tensor
    costs: Tensor

    @property
    def total_cost(self) -> Tensor:
        return self.costs.sum()


def observe_torch(state: Tensor, layout: Sequence[tuple[str, int]]) -> Tensor:
    """Observation (..., O) of states (..., S) (differentiable; angles through cos/sin):
    :meth:`leoc.systems.observation.ObservationMap.observe`."""
    return as_observation_map(layout, state.shape[-1], complete=False).observe(state)


def inner_moments(
    module: nn.Module, mean: Tensor, cov: Tensor, constants: RBFConstants | None = None
) -> MomentMatch:
    """Exact moments of an unsaturated RBF network or linear controller (``constants``: an RBF
    network's :func:`~leoc.pilco.moments.rbf_constants`, computed here if not given)."""
    if isinstance(module, RBFNetwork):
        return rbf_moments(module, mean, cov, constants)
    if isinstance(module, LinearController):
        return linear_moments(mean, cov, module.W, module.b)
    raise TypeError(
        f"policy: exact moment matching needs an RBFNetwork or LinearController, found "
        f"{type(module).__name__}"
    )


def _squash(moments: MomentMatch, limit: Tensor | None, mode: str) -> MomentMatch:
    if limit is None or mode == "none":
        eye = torch.eye(moments.mean.shape[0], dtype=moments.mean.dtype)
        return MomentMatch(moments.mean, moments.cov, eye)
    if mode != "sin":
        raise ValueError(f"saturation: exact moment matching needs 'sin' or 'none', found {mode!r}")
    return sin_squash_moments(moments.mean, moments.cov, limit)


def _chain(obs: MomentMatch, cross_xo: Tensor, pre: MomentMatch, squashed: MomentMatch):
    # Coefficient rule: Cov[o, u] = S_o C_o,pre C_pre,u; Cov[x, u] = Cov[x, o] C_o,pre C_pre,u.
    coefficient = pre.io @ squashed.io  # (O, F)
    return ActionMoments(squashed.mean, squashed.cov, obs.cov @ coefficient, cross_xo @ coefficient)


def constant_relevance_moments(
    policy: HybridPolicy, obs: MomentMatch, cross_xo: Tensor
) -> ActionMoments:
    r"""The weak heuristic: treat :math:`r` as the constant :math:`\bar r = r(E[o])`.

    Then the blend :math:`\bar r G + (1 - \bar r) H` is a fixed combination of an affine map and
    an RBF network, whose moments are exact given :math:`\operatorname{Cov}[G, H] = W S_o C_{oH}`.
    Offered only to measure how much :func:`action_moments`' quadrature improves on it.
    """
    rel = policy.relevance(obs.mean)[0]
    lin = linear_moments(obs.mean, obs.cov, policy.linear.W, policy.linear.b)
    non = inner_moments(policy.nonlinear, obs.mean, obs.cov)
    cross_gh = policy.linear.W @ obs.cov @ non.io  # (F, F) Cov[G, H]
    mean = rel * lin.mean + (1.0 - rel) * non.mean
    cov = (
        rel**2 * lin.cov + (1.0 - rel) ** 2 * non.cov + rel * (1.0 - rel) * (cross_gh + cross_gh.T)
    )
    blend = MomentMatch(mean, symmetrise(cov), rel * lin.io + (1.0 - rel) * non.io)
    return _chain(obs, cross_xo, blend, _squash(blend, policy.action_limit, policy.saturation))


def mixture_relevance_moments(
    policy: HybridPolicy, obs: MomentMatch, cross_xo: Tensor
) -> ActionMoments:
    r"""Another heuristic with :math:`\bar r = r(E[o])` frozen: the pre-saturation action as
    the two-component mixture "G with probability :math:`\bar r`, else H".

    .. math::

        m = \bar r m_G + (1 - \bar r) m_H, \qquad
        S = \bar r \big(S_G + (m_G - m)(m_G - m)^\top\big)
          + (1 - \bar r) \big(S_H + (m_H - m)(m_H - m)^\top\big),

    input-output coefficients blended as :math:`\bar r C_G + (1 - \bar r) C_H`, then the sin
    squash. Unlike :func:`constant_relevance_moments` it ignores :math:`\operatorname{Cov}[G,
    H]` and weighs each variance by :math:`\bar r` instead of :math:`\bar r^2`. It is the
    hybrid's moment approximation of nrjc/LEOC (``pilco/controllers.py``,
    ``HybridController.compute_action``), offered to reproduce it, not as a better method.
    """
    rel = policy.relevance(obs.mean)[0]
    lin = linear_moments(obs.mean, obs.cov, policy.linear.W, policy.linear.b)
    non = inner_moments(policy.nonlinear, obs.mean, obs.cov)
    mean = rel * lin.mean + (1.0 - rel) * non.mean
    lin_gap, non_gap = lin.mean - mean, non.mean - mean
    cov = rel * (lin.cov + torch.outer(lin_gap, lin_gap)) + (1.0 - rel) * (
        non.cov + torch.outer(non_gap, non_gap)
    )
    blend = MomentMatch(mean, symmetrise(cov), rel * lin.io + (1.0 - rel) * non.io)
    return _chain(obs, cross_xo, blend, _squash(blend, policy.action_limit, policy.saturation))


def hybrid_quadrature_moments(
    policy: nn.Module,
    state_mean: Tensor,
    state_cov: Tensor,
    layout: Sequence[tuple[str, int]],
    order: int,
) -> ActionMoments:
    """Moments of the whole policy (relevance, blend, saturation) by Gauss-Hermite quadrature
    over the *state*, with the observation map applied exactly at every node."""
    num_obs = len(layout)

    def obs_and_action(states: Tensor) -> Tensor:
        obs = observe_torch(states, layout)
        return torch.cat([obs, policy(obs)], dim=-1)

    quad = quadrature_moments(obs_and_action, state_mean, state_cov, order)
    return ActionMoments(
        quad.mean[num_obs:],
        quad.cov[num_obs:, num_obs:],
        quad.cov[:num_obs, num_obs:],
        quad.cross[:, num_obs:],
    )


def policy_moment_constants(policy: nn.Module) -> RBFConstants | None:
    """:func:`~leoc.pilco.moments.rbf_constants` of the RBF network whose exact moments
    :func:`action_moments` takes (a :class:`SaturatedPolicy` of one, or one alone); None for
    other policies (whose moments need none, or compute their own)."""
    inner = policy.inner if isinstance(policy, SaturatedPolicy) else policy
    return rbf_constants(inner) if isinstance(inner, RBFNetwork) else None


def action_moments(
    policy: nn.Module,
    state_mean: Tensor,
    state_cov: Tensor,
    obs: MomentMatch,
    layout: Sequence[tuple[str, int]],
    hybrid_method: str = "quadrature",
    order: int = DEFAULT_QUADRATURE_ORDER,
    policy_constants: RBFConstants | None = None,
) -> ActionMoments:
    """Moments of the action for :class:`SaturatedPolicy` (exact) or :class:`HybridPolicy`
    (``hybrid_method``: ``"quadrature"``, or the ``"constant_relevance"`` or ``"mixture"``
    heuristic).
    ``policy_constants``: :func:`policy_moment_constants` of ``policy`` (computed here if not
    given)."""
    cross_xo = state_cov @ obs.io  # Cov[x, o] (S, O)
    if isinstance(policy, HybridPolicy):
        if hybrid_method == "quadrature":
            return hybrid_quadrature_moments(policy, state_mean, state_cov, layout, order)
        if hybrid_method == "constant_relevance":
            return constant_relevance_moments(policy, obs, cross_xo)
        if hybrid_method == "mixture":
            return mixture_relevance_moments(policy, obs, cross_xo)
        raise ValueError(
            f"hybrid_method: expected one of {HYBRID_METHODS}, found {hybrid_method!r}"
        )
    if isinstance(policy, SaturatedPolicy):
        pre = inner_moments(policy.inner, obs.mean, obs.cov, policy_constants)
        return _chain(obs, cross_xo, pre, _squash(pre, policy.action_limit, policy.saturation))
    pre = inner_moments(policy, obs.mean, obs.cov, policy_constants)
    eye = torch.eye(pre.mean.shape[0], dtype=pre.mean.dtype)
    return _chain(obs, cross_xo, pre, MomentMatch(pre.mean, pre.cov, eye))


def propagate_step(
    state_mean: Tensor,
    state_cov: Tensor,
    obs: MomentMatch,
    policy: nn.Module,
    model: GPPosterior,
    layout: Sequence[tuple[str, int]],
    hybrid_method: str = "quadrature",
    order: int = DEFAULT_QUADRATURE_ORDER,
    model_constants: SESumConstants | None = None,
    policy_constants: RBFConstants | None = None,
) -> tuple[Tensor, Tensor]:
    """One step of the module docstring; ``obs`` are the observation moments of the state.
    ``model_constants``: :func:`~leoc.pilco.moments.gp_constants` of ``model``;
    ``policy_constants``: :func:`policy_moment_constants` of ``policy`` (both computed here if
    not given; :func:`predict` computes them once for the horizon).

    Shapes: ``state_mean`` (S,), ``state_cov`` (S, S) -> next mean (S,), next cov (S, S).
    """
    act = action_moments(
        policy, state_mean, state_cov, obs, layout, hybrid_method, order, policy_constants
    )
    in_mean = torch.cat([obs.mean, act.mean])
    in_cov = torch.cat(
        [
            torch.cat([obs.cov, act.cross_obs], dim=1),
            torch.cat([act.cross_obs.T, act.cov], dim=1),
        ],
        dim=0,
    )
    delta = gp_moments(model, in_mean, symmetrise(in_cov), model_constants)
    cross_x_in = torch.cat([state_cov @ obs.io, act.cross_state], dim=1)  # Cov[x, (o, u)]
    cross_x_delta = cross_x_in @ delta.io  # Cov[x, Delta] (S, S)
    next_cov = state_cov + delta.cov + cross_x_delta + cross_x_delta.T
    return state_mean + delta.mean, floor_eigenvalues(symmetrise(next_cov))


def predict(
    policy: nn.Module,
    model: GPPosterior,
    start_mean: Tensor,
    start_cov: Tensor,
    horizon: int,
    layout: Sequence[tuple[str, int]],
    cost_target: Tensor,
    cost_factor: Tensor,
    hybrid_method: str = "quadrature",
    order: int = DEFAULT_QUADRATURE_ORDER,
) -> Prediction:
    """Propagate the state over ``horizon`` decisions; expected saturating cost of each
    predicted observation :math:`o_1, \\dots, o_H` (the start's cost does not depend on the
    policy). Differentiable in the policy's parameters."""
    means, covs, costs = [start_mean], [start_cov], []
    mean, cov = start_mean, start_cov
    obs = observation_moments(mean, cov, layout)
    # Parts of the moments that stay fixed over the horizon, computed once.
    model_constants, rbf = gp_constants(model), policy_moment_constants(policy)
    for _ in range(horizon):
        mean, cov = propagate_step(
            mean, cov, obs, policy, model, layout, hybrid_method, order, model_constants, rbf
        )
        obs = observation_moments(mean, cov, layout)
        costs.append(expected_saturating_cost(obs.mean, obs.cov, cost_target, cost_factor))
        means.append(mean)
        covs.append(cov)
    return Prediction(torch.stack(means), torch.stack(covs), torch.stack(costs))
