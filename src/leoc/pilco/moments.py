r"""Moment matching: mean, covariance and input-output covariance of f(x) for Gaussian x.

Letters: D input dimension, E output dimension, M support points (GP data, inducing inputs or RBF
centres), K quadrature nodes.

For :math:`x \sim \mathcal N(\mu, \Sigma)` every function here returns the exact first two moments
of :math:`y = f(x)` (no linearisation) and the input-output covariance in PILCO's coefficient form
``io`` :math:`= \Sigma^{-1} \operatorname{Cov}[x, y]` (D, E), computed without inverting
:math:`\Sigma` (so a singular input covariance is fine). Exact cases:

- :func:`linear_moments` for :math:`W x + b`;
- :func:`observation_moments` for the observation map (state entries and cos/sin of angles);
- :func:`sin_squash_moments` for :math:`u_{max} \sin(u / u_{max})`;
- :func:`gp_moments` for the GP predictive distribution and, with ``variance=False``, for the RBF
  controller (the same sum of squared-exponential bumps; Deisenroth 2010, sec. 2.3.2-2.3.3).

The hybrid policy's relevance :math:`r(x) = (1 + d(x))^{-2}` has no closed form under a Gaussian;
:func:`quadrature_moments` integrates any function by tensor Gauss-Hermite quadrature (exact for
polynomials of degree ``2 * order - 1`` in each coordinate), differentiable through the nodes.

References
----------
M. P. Deisenroth, "Efficient Reinforcement Learning using Gaussian Processes", PhD thesis,
KIT 2010, sec. 2.3 and appendix A.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.pilco.gp import GPPosterior, cholesky_jitter

HALF_PI = 0.5 * math.pi


class MomentMatch(NamedTuple):
    """Moments of y = f(x): ``mean`` (E,), ``cov`` (E, E), ``io`` = Sigma_x^-1 Cov[x, y] (D, E)."""

    mean: Tensor
    cov: Tensor
    io: Tensor


class QuadratureMoments(NamedTuple):
    """Moments of y = f(x) by quadrature: ``mean`` (E,), ``cov`` (E, E), ``cross`` = Cov[x, y]
    (D, E) (explicit covariance: no coefficient form, which would need Sigma_x^-1)."""

    mean: Tensor
    cov: Tensor
    cross: Tensor


def symmetrise(matrix: Tensor) -> Tensor:
    """(A + A^T) / 2: removes the round-off asymmetry that products like W S W^T accumulate."""
    return 0.5 * (matrix + matrix.transpose(-1, -2))


def linear_moments(mean: Tensor, cov: Tensor, weight: Tensor, bias: Tensor) -> MomentMatch:
    """Moments of ``y = W x + b``: ``W mu + b``, ``W Sigma W^T``, io ``= W^T``.

    Shapes: ``mean`` (D,), ``cov`` (D, D), ``weight`` (E, D), ``bias`` (E,).
    """
    return MomentMatch(weight @ mean + bias, symmetrise(weight @ cov @ weight.T), weight.T)


def sin_squash_moments(mean: Tensor, cov: Tensor, limit: Tensor | float) -> MomentMatch:
    r"""Moments of :math:`y = u_{max} \sin(u / u_{max})` for :math:`u \sim \mathcal N(m, S)`.

    With :math:`v = u / u_{max}` and :math:`\sigma_i^2 = S_{ii} / u_{max}^2`,

    .. math::

        E[\sin v_i] = e^{-\sigma_i^2/2} \sin m_i, \qquad
        E[\sin v_i \sin v_j] = \tfrac12\big(e^{-\operatorname{var}(v_i - v_j)/2}\cos(m_i - m_j)
            - e^{-\operatorname{var}(v_i + v_j)/2} \cos(m_i + m_j)\big),

    and by Stein's lemma :math:`\operatorname{Cov}[u, y_i] = S_{:i} E[\cos v_i]`, so
    ``io = diag(E[cos v])``.

    Shapes: ``mean`` (E,), ``cov`` (E, E), ``limit`` scalar or (E,).
    """
    limit_t = torch.as_tensor(limit, dtype=mean.dtype).expand_as(mean)
    v_mean = mean / limit_t
    v_cov = cov / (limit_t[:, None] * limit_t[None, :])
    var = v_cov.diagonal()
    damp = torch.exp(-0.5 * var)
    e_sin, e_cos = damp * torch.sin(v_mean), damp * torch.cos(v_mean)
    var_diff = var[:, None] + var[None, :] - 2.0 * v_cov
    var_sum = var[:, None] + var[None, :] + 2.0 * v_cov
    e_sin_sin = 0.5 * (
        torch.exp(-0.5 * var_diff) * torch.cos(v_mean[:, None] - v_mean[None, :])
        - torch.exp(-0.5 * var_sum) * torch.cos(v_mean[:, None] + v_mean[None, :])
    )
    cov_out = (e_sin_sin - e_sin[:, None] * e_sin[None, :]) * limit_t[:, None] * limit_t[None, :]
    return MomentMatch(limit_t * e_sin, symmetrise(cov_out), torch.diag(e_cos))


def observation_moments(
    mean: Tensor, cov: Tensor, layout: Sequence[tuple[str, int]]
) -> MomentMatch:
    r"""Moments of the observation map: entries ``("state", i)`` copy :math:`x_i`, ``("sin", i)``
    and ``("cos", i)`` are :math:`\sin x_i` and :math:`\cos x_i` (sin/cos augmentation of angles).

    Every trigonometric entry is written :math:`\sin(x_i + \varphi)` (``cos`` has
    :math:`\varphi = \pi/2`). Then, exactly,

    .. math::

        E[\sin(x_i + \varphi)] = e^{-\Sigma_{ii}/2} \sin(\mu_i + \varphi), \qquad
        \operatorname{Cov}[x, \sin(x_i + \varphi)] = \Sigma_{:i}\, e^{-\Sigma_{ii}/2}
            \cos(\mu_i + \varphi),

    the second by Stein's lemma, and products of two sines by
    :math:`\sin a \sin b = \tfrac12 (\cos(a - b) - \cos(a + b))`.

    Shapes: ``mean`` (S,), ``cov`` (S, S) -> mean (O,), cov (O, O), io (S, O).
    """
    index = torch.tensor([i for _, i in layout])
    trig = torch.tensor([kind != "state" for kind, _ in layout])
    phase = torch.tensor(
        [HALF_PI if kind == "cos" else 0.0 for kind, _ in layout], dtype=mean.dtype
    )
    mu = mean[index] + phase
    sub_cov = cov[index][:, index]  # (O, O) covariance of the underlying state entries
    var = sub_cov.diagonal()
    damp = torch.exp(-0.5 * var)
    out_mean = torch.where(trig, damp * torch.sin(mu), mean[index])
    slope = torch.where(trig, damp * torch.cos(mu), torch.ones_like(mu))  # E[d o_k / d x_i]
    var_diff = var[:, None] + var[None, :] - 2.0 * sub_cov
    var_sum = var[:, None] + var[None, :] + 2.0 * sub_cov
    trig_cov = (
        0.5
        * (
            torch.exp(-0.5 * var_diff) * torch.cos(mu[:, None] - mu[None, :])
            - torch.exp(-0.5 * var_sum) * torch.cos(mu[:, None] + mu[None, :])
        )
        - out_mean[:, None] * out_mean[None, :]
    )
    # Any pair with at least one plain state entry: Stein's lemma gives Sigma_ij E[o_i'] E[o_j'].
    stein_cov = sub_cov * slope[:, None] * slope[None, :]
    both_trig = trig[:, None] & trig[None, :]
    out_cov = torch.where(both_trig, trig_cov, stein_cov)
    selector = torch.nn.functional.one_hot(index, mean.shape[0]).to(mean.dtype).T  # (S, O)
    return MomentMatch(out_mean, symmetrise(out_cov), selector * slope[None, :])


def _se_first_moments(
    support: Tensor, beta: Tensor, log_ls: Tensor, log_signal: Tensor, mean: Tensor, cov: Tensor
) -> tuple[Tensor, Tensor, Tensor]:
    r"""Mean and io of :math:`y_a = \sum_i \beta_{ai} k_a(x, z_i)`, and :math:`\nu_i = z_i - \mu`.

    With :math:`\tilde\nu = \Lambda_a^{-1/2}\nu` and the SPD matrix
    :math:`B_a = I + \Lambda_a^{-1/2} \Sigma \Lambda_a^{-1/2}` (eigenvalues >= 1, so its Cholesky
    factor is always well conditioned, unlike :math:`\Sigma + \Lambda_a` itself):

    .. math::

        q_{ai} = \alpha_a^2 |B_a|^{-1/2} \exp(-\tfrac12 \tilde\nu_i^\top B_a^{-1} \tilde\nu_i),
        \quad E[y_a] = \beta_a^\top q_a, \quad
        \Sigma^{-1}\operatorname{Cov}[x, y_a] = (\Sigma + \Lambda_a)^{-1} \sum_i \beta_{ai}
            q_{ai} \nu_i = \Lambda_a^{-1/2} B_a^{-1} \sum_i \beta_{ai} q_{ai} \tilde\nu_i.

    Shapes: ``support`` (M, D), ``beta`` (E, M), ``log_ls`` (E, D), ``log_signal`` (E,);
    returns mean (E,), io (D, E), nu (M, D).
    """
    dim = mean.shape[0]
    inv_ls = torch.exp(-log_ls)  # (E, D)
    nu = support - mean  # (M, D)
    nu_scaled = nu[None] * inv_ls[:, None, :]  # (E, M, D)
    b_mat = torch.eye(dim, dtype=mean.dtype) + inv_ls[:, :, None] * cov * inv_ls[:, None, :]
    chol = cholesky_jitter(b_mat, "I + L^-1/2 S L^-1/2")
    solved = torch.cholesky_solve(nu_scaled.transpose(-1, -2), chol)  # (E, D, M)
    quad = (nu_scaled.transpose(-1, -2) * solved).sum(-2)  # (E, M)
    log_det = 2.0 * torch.log(chol.diagonal(dim1=-2, dim2=-1)).sum(-1)  # (E,)
    q = torch.exp(2.0 * log_signal[:, None] - 0.5 * log_det[:, None] - 0.5 * quad)
    weighted = beta * q  # (E, M)
    out_mean = weighted.sum(-1)
    io = (inv_ls * (solved @ weighted[..., None])[..., 0]).T  # (D, E)
    return out_mean, io, nu


# From this many support points on, Q is recomputed in the backward pass instead of stored:
# storing it costs P M^2 doubles per horizon step (0.5 GB over 40 steps at M = 400, E = 4),
# recomputing costs one more batched matmul and exp per step.
RECOMPUTE_MIN_SUPPORT = 300


class WeightedExpBilinear(torch.autograd.Function):
    r""":math:`v_p = \sum_{ij} W_{pij} \exp((L_p R_p^\top)_{ij})` with the exponential
    recomputed in the backward pass, so only L, R (P, M, K) and W are kept.

    Gradients: with :math:`G_p = v'_p\, W_p \odot \exp(L_p R_p^\top)`,
    :math:`\partial L_p = G_p R_p`, :math:`\partial R_p = G_p^\top L_p` and
    :math:`\partial W_p = v'_p \exp(L_p R_p^\top)`. First order only.
    """

    @staticmethod
    def forward(ctx, left: Tensor, right: Tensor, weights: Tensor) -> Tensor:
        ctx.save_for_backward(left, right, weights)
        q = torch.exp(left @ right.transpose(-1, -2))
        return (weights * q).sum(dim=(-1, -2))

    @staticmethod
    def backward(ctx, grad: Tensor):
        left, right, weights = ctx.saved_tensors
        q = torch.exp(left @ right.transpose(-1, -2)) * grad[:, None, None]
        grad_weights = q if ctx.needs_input_grad[2] else None
        g = q * weights
        return g @ right, g.transpose(-1, -2) @ left, grad_weights


def pair_indices(num_outputs: int) -> tuple[Tensor, Tensor]:
    """Output pairs ``a <= b`` (P = E (E + 1) / 2 of them): Q_ba = Q_ab^T, so half suffices."""
    pairs = torch.triu_indices(num_outputs, num_outputs)
    return pairs[0], pairs[1]


def pair_weights(beta: Tensor, inv_k: Tensor | None = None) -> Tensor:
    r"""Weights :math:`\beta_a \beta_b^\top - \delta_{ab} \Xi_a` (P, M, M) of the pairs ``a <= b``.

    With them one elementwise contraction per pair gives both :math:`\beta_a^\top Q_{ab} \beta_b`
    and, for ``a = b``, the :math:`-\operatorname{tr}(\Xi_a Q_{aa})` of the GP variance. They do
    not depend on the input distribution, so a GP computes them once per model.
    """
    first, second = pair_indices(beta.shape[0])
    weights = beta[first][:, :, None] * beta[second][:, None, :]
    if inv_k is not None:
        same = (first == second).to(beta.dtype)[:, None, None]
        weights = weights - same * inv_k[first]
    return weights


def _se_second_moments(
    nu: Tensor, log_ls: Tensor, log_signal: Tensor, cov: Tensor, weights: Tensor
) -> Tensor:
    r"""The (E, E) matrix :math:`\sum_{ij} [\beta_a\beta_b^\top - \delta_{ab}\Xi_a]_{ij} Q_{ab,ij}`.

    Deisenroth (2010, eq. 2.53):
    :math:`Q_{ab,ij} = k_a(z_i, \mu) k_b(z_j, \mu) |R|^{-1/2}
    \exp(\tfrac12 w_{ij}^\top R^{-1} \Sigma w_{ij})` with
    :math:`R = \Sigma (\Lambda_a^{-1} + \Lambda_b^{-1}) + I` and
    :math:`w_{ij} = \Lambda_a^{-1} \nu_i + \Lambda_b^{-1} \nu_j`.

    Numerics:

    - with :math:`P = \Lambda_a^{-1} + \Lambda_b^{-1}` (diagonal) and the SPD
      :math:`B = I + P^{1/2} \Sigma P^{1/2}` (eigenvalues >= 1), :math:`|R| = |B|` and
      :math:`R^{-1}\Sigma = P^{-1/2} (I - B^{-1}) P^{-1/2}`: no non-symmetric solve;
    - writing :math:`P^{-1/2} w_{ij} = p_i + s_j` and :math:`T = I - B^{-1}`, the exponent is
      :math:`\rho_i + \gamma_j + p_i^\top T s_j`, a rank-(D + 2) bilinear form: one batched
      matmul of (M, D + 2) by (D + 2, M) gives :math:`\log Q` without the (M, M, D) tensor of
      the naive formula or any (M, M) broadcast, then one ``exp`` (everything summed in log
      space first, so nothing overflows: :math:`Q_{ab,ij} \le \alpha_a^2 \alpha_b^2`) and one
      batched dot with the weights. Only Q, (P, M, M), is kept for the backward pass;
    - only the pairs ``a <= b`` are computed (:math:`Q_{ba} = Q_{ab}^\top`).

    Shapes: ``nu`` (M, D), ``log_ls`` (E, D), ``log_signal`` (E,), ``cov`` (D, D),
    ``weights`` (P, M, M) from :func:`pair_weights` -> (E, E).
    """
    dim, num_outputs, num_support = cov.shape[0], log_ls.shape[0], nu.shape[0]
    first, second = pair_indices(num_outputs)
    inv_ls2 = torch.exp(-2.0 * log_ls)  # (E, D) diagonal of Lambda^-1
    prec = inv_ls2[first] + inv_ls2[second]  # (P, D)
    sqrt_prec = prec.sqrt()
    eye = torch.eye(dim, dtype=cov.dtype)
    b_mat = eye + sqrt_prec[:, :, None] * cov * sqrt_prec[:, None, :]  # (P, D, D)
    chol = cholesky_jitter(b_mat, "I + P^1/2 S P^1/2")
    log_det = 2.0 * torch.log(chol.diagonal(dim1=-2, dim2=-1)).sum(-1)  # (P,)
    t_mat = eye - torch.cholesky_inverse(chol)  # (P, D, D), symmetric
    row = nu * (inv_ls2[first] / sqrt_prec)[:, None, :]  # (P, M, D): p_i
    col = nu * (inv_ls2[second] / sqrt_prec)[:, None, :]  # (P, M, D): s_j
    row_t = row @ t_mat
    sq_dist = (nu * torch.exp(-log_ls)[:, None, :]).square().sum(-1)  # (E, M)
    log_k = 2.0 * log_signal[:, None] - 0.5 * sq_dist  # (E, M) log k_a(z_i, mu)
    row_log = log_k[first] + 0.5 * (row_t * row).sum(-1) - 0.5 * log_det[:, None]  # (P, M)
    col_log = log_k[second] + 0.5 * ((col @ t_mat) * col).sum(-1)  # (P, M)
    ones = torch.ones(first.shape[0], num_support, 1, dtype=cov.dtype)
    left = torch.cat([row_t, row_log[..., None], ones], dim=-1)  # (P, M, D + 2)
    right = torch.cat([col, ones, col_log[..., None]], dim=-1)  # (P, M, D + 2)
    if num_support >= RECOMPUTE_MIN_SUPPORT:
        values = WeightedExpBilinear.apply(left, right, weights)
    else:
        q = torch.exp(left @ right.transpose(-1, -2))  # (P, M, M)
        values = (weights * q).sum(dim=(-1, -2))  # (P,)
    upper = torch.zeros(num_outputs, num_outputs, dtype=cov.dtype).index_put(
        (first, second), values
    )
    return upper + upper.T - torch.diag(upper.diagonal())


def se_sum_moments(
    support: Tensor,
    beta: Tensor,
    log_ls: Tensor,
    log_signal: Tensor,
    mean: Tensor,
    cov: Tensor,
    weights: Tensor | None = None,
    gp_variance: bool = False,
) -> MomentMatch:
    r"""Exact moments of :math:`y_a(x) = \sum_i \beta_{ai} k_a(x, z_i)` (+ GP variance).

    ``gp_variance``: y is a GP prediction and each output's variance gains the expected
    posterior variance :math:`\alpha_a^2 - \operatorname{tr}(\Xi_a Q_{aa})` (Deisenroth 2010,
    eq. 2.55; the trace comes in through ``weights``); otherwise y is a deterministic RBF
    network. ``weights`` defaults to :func:`pair_weights` of ``beta`` (no GP term).

    Shapes: ``support`` (M, D), ``beta`` (E, M), ``log_ls`` (E, D), ``log_signal`` (E,),
    ``mean`` (D,), ``cov`` (D, D), ``weights`` (P, M, M).
    """
    out_mean, io, nu = _se_first_moments(support, beta, log_ls, log_signal, mean, cov)
    weights = pair_weights(beta) if weights is None else weights
    second = _se_second_moments(nu, log_ls, log_signal, cov, weights)
    out_cov = second - out_mean[:, None] * out_mean[None, :]
    if gp_variance:
        out_cov = out_cov + torch.diag(torch.exp(2.0 * log_signal))
    return MomentMatch(out_mean, symmetrise(out_cov), io)


def gp_moments(post: GPPosterior, mean: Tensor, cov: Tensor) -> MomentMatch:
    """Exact moments of the GP prediction at a Gaussian input (latent f, without noise).

    Shapes: ``mean`` (D,), ``cov`` (D, D) -> mean (E,), cov (E, E), io (D, E).
    """
    return se_sum_moments(
        post.support,
        post.beta,
        post.log_lengthscales,
        post.log_signal,
        mean,
        cov,
        post.pair_weights,
        gp_variance=True,
    )


def rbf_moments(network: torch.nn.Module, mean: Tensor, cov: Tensor) -> MomentMatch:
    """Exact moments of an :class:`~leoc.policies.RBFNetwork` (unit signal variance).

    Shapes: ``mean`` (D,), ``cov`` (D, D) -> mean (F,), cov (F, F), io (D, F).
    """
    log_signal = torch.zeros(network.weights.shape[0], dtype=mean.dtype)
    return se_sum_moments(
        network.centres, network.weights, network.log_lengthscales, log_signal, mean, cov
    )


def gauss_hermite_rule(dim: int, order: int) -> tuple[Tensor, Tensor]:
    """Tensor-product Gauss-Hermite rule for the standard normal in ``dim`` dimensions.

    Returns nodes (K, dim) and weights (K,) summing to one, K = order^dim; exact for every
    polynomial of degree <= 2 order - 1 in each coordinate.
    """
    nodes_1d, weights_1d = np.polynomial.hermite_e.hermegauss(order)  # weight exp(-x^2 / 2)
    weights_1d = weights_1d / weights_1d.sum()
    grid = np.array(list(itertools.product(range(order), repeat=dim)))
    nodes = nodes_1d[grid]
    weights = np.prod(weights_1d[grid], axis=1)
    return torch.as_tensor(nodes, dtype=torch.float64), torch.as_tensor(weights)


def quadrature_moments(
    fn: Callable[[Tensor], Tensor], mean: Tensor, cov: Tensor, order: int
) -> QuadratureMoments:
    r"""Moments of ``y = fn(x)`` for :math:`x \sim \mathcal N(\mu, \Sigma)` by Gauss-Hermite
    quadrature on :math:`x = \mu + L \xi`, :math:`L L^\top = \Sigma`.

    Differentiable in ``mean``, ``cov`` and ``fn``'s parameters. ``fn`` maps (K, D) -> (K, E).
    """
    nodes, weights = gauss_hermite_rule(mean.shape[0], order)
    chol = cholesky_jitter(cov, "quadrature covariance")
    offsets = nodes.to(mean.dtype) @ chol.T  # (K, D)
    values = fn(mean + offsets)  # (K, E)
    weights = weights.to(mean.dtype)
    out_mean = weights @ values
    centred = values - out_mean
    out_cov = centred.T @ (weights[:, None] * centred)
    cross = offsets.T @ (weights[:, None] * centred)
    return QuadratureMoments(out_mean, symmetrise(out_cov), cross)
