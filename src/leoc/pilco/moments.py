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
- :func:`gp_moments` for the GP predictive distribution and :func:`rbf_moments` for the RBF
  controller, both by :func:`se_sum_moments` (the same sum of squared-exponential bumps;
  Deisenroth 2010, sec. 2.3.2-2.3.3).

The hybrid policy's relevance :math:`r(x) = (1 + d(x))^{-2}` has no closed form under a Gaussian;
:func:`quadrature_moments` integrates any function by tensor Gauss-Hermite quadrature (exact for
polynomials of degree ``2 * order - 1`` in each coordinate), differentiable through the nodes.

References
----------
M. P. Deisenroth, "Efficient Reinforcement Learning using Gaussian Processes", PhD thesis,
KIT 2010, sec. 2.3 and appendix A.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.linalg import cholesky_jitter, log_det_cholesky, symmetrise, weighted_exp_bilinear
from leoc.pilco.gp import GPPosterior, pair_indices, pair_weights

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


def linear_moments(mean: Tensor, cov: Tensor, weight: Tensor, bias: Tensor) -> MomentMatch:
    """Moments of ``y = W x + b``: ``W mu + b``, ``W Sigma W^T``, io ``= W^T``.

    Shapes: ``mean`` (D,), ``cov`` (D, D), ``weight`` (E, D), ``bias`` (E,).
    """
    return MomentMatch(weight @ mean + bias, symmetrise(weight @ cov @ weight.T), weight.T)


def _sine_product_cov(e_sin: Tensor, e_cos: Tensor, cov: Tensor) -> Tensor:
    r"""Covariance of :math:`\sin a_i` and :math:`\sin a_j` for jointly Gaussian ``a``.

    With :math:`C = \operatorname{Cov}[a]`, :math:`E[\sin a_i] = e^{-C_{ii}/2} \sin \mu_i` and
    :math:`E[\cos a_i] = e^{-C_{ii}/2} \cos \mu_i` (``e_sin``, ``e_cos``), the product rule
    :math:`\sin a \sin b = \tfrac12 (\cos(a - b) - \cos(a + b))` gives

    .. math::

        \operatorname{Cov}[\sin a_i, \sin a_j] = E[\cos a_i] E[\cos a_j] \sinh C_{ij}
            + E[\sin a_i] E[\sin a_j] (\cosh C_{ij} - 1).

    :math:`\cosh C - 1` is evaluated as :math:`2 \sinh^2(C / 2)`: no cancellation when C is
    small (a collapsed covariance near the operating point), unlike the difference of the two
    cosine terms. Exactly symmetric for a symmetric ``cov``. Shapes: (K,), (K,), (K, K).
    """
    cosh_minus_one = 2.0 * torch.sinh(0.5 * cov).square()
    return (e_cos[:, None] * e_cos[None, :]) * torch.sinh(cov) + (
        e_sin[:, None] * e_sin[None, :]
    ) * cosh_minus_one


def sin_squash_moments(mean: Tensor, cov: Tensor, limit: Tensor | float) -> MomentMatch:
    r"""Moments of :math:`y = u_{max} \sin(u / u_{max})` for :math:`u \sim \mathcal N(m, S)`.

    With :math:`v = u / u_{max}` and :math:`\sigma_i^2 = S_{ii} / u_{max}^2`,
    :math:`E[\sin v_i] = e^{-\sigma_i^2/2} \sin m_i`, the covariance of two sines by
    :func:`_sine_product_cov`, and by Stein's lemma
    :math:`\operatorname{Cov}[u, y_i] = S_{:i} E[\cos v_i]`, so ``io = diag(E[cos v])``.

    Shapes: ``mean`` (E,), ``cov`` (E, E) (symmetric), ``limit`` scalar or (E,).
    """
    limit_t = torch.as_tensor(limit, dtype=mean.dtype).expand_as(mean)
    v_mean = mean / limit_t
    v_cov = cov / (limit_t[:, None] * limit_t[None, :])
    damp = torch.exp(-0.5 * v_cov.diagonal())
    e_sin, e_cos = damp * torch.sin(v_mean), damp * torch.cos(v_mean)
    cov_out = _sine_product_cov(e_sin, e_cos, v_cov) * (limit_t[:, None] * limit_t[None, :])
    return MomentMatch(limit_t * e_sin, cov_out, torch.diag(e_cos))


OBSERVATION_KINDS = ("state", "sin", "cos")


class _LayoutConstants(NamedTuple):
    """Constant tensors of an observation layout (O entries over S state entries)."""

    index: Tensor  # (O,) state entry of each observation entry
    trig: Tensor  # (O,) bool, sin or cos entry
    both_trig: Tensor  # (O, O) bool
    phase: Tensor  # (O,) pi/2 for cos (cos x = sin(x + pi/2)), else 0
    selector: Tensor  # (S, O) one-hot: selector[i, k] = 1 if entry k reads state i


@functools.cache
def _layout_constants(
    layout: tuple[tuple[str, int], ...], state_dim: int, dtype: torch.dtype
) -> _LayoutConstants:
    """Built once per layout (cached; the tensors are never written to)."""
    kinds = [kind for kind, _ in layout]
    unknown = sorted(set(kinds) - set(OBSERVATION_KINDS))
    if unknown:
        raise ValueError(f"layout: kinds must be among {OBSERVATION_KINDS}, found {unknown}")
    index = torch.tensor([i for _, i in layout])
    trig = torch.tensor([kind != "state" for kind in kinds])
    phase = torch.tensor([HALF_PI if kind == "cos" else 0.0 for kind in kinds], dtype=dtype)
    selector = torch.nn.functional.one_hot(index, state_dim).to(dtype).T
    return _LayoutConstants(index, trig, trig[:, None] & trig[None, :], phase, selector)


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

    the second by Stein's lemma (which also gives the covariance of a trigonometric and a plain
    entry), and the covariance of two trigonometric entries by :func:`_sine_product_cov`.

    Shapes: ``mean`` (S,), ``cov`` (S, S) (symmetric) -> mean (O,), cov (O, O), io (S, O).
    """
    const = _layout_constants(tuple(map(tuple, layout)), mean.shape[0], mean.dtype)
    mu = mean[const.index] + const.phase
    sub_cov = cov[const.index[:, None], const.index[None, :]]  # (O, O) of the state entries
    damp = torch.exp(-0.5 * sub_cov.diagonal())
    e_sin, e_cos = damp * torch.sin(mu), damp * torch.cos(mu)
    out_mean = torch.where(const.trig, e_sin, mu)  # plain entries have phase 0
    slope = torch.where(const.trig, e_cos, 1.0)  # E[d o_k / d x_i]
    # Any pair with at least one plain state entry: Stein's lemma gives Sigma_ij E[o_i'] E[o_j'].
    stein_cov = sub_cov * (slope[:, None] * slope[None, :])
    trig_cov = _sine_product_cov(e_sin, e_cos, sub_cov)
    out_cov = torch.where(const.both_trig, trig_cov, stein_cov)
    return MomentMatch(out_mean, out_cov, const.selector * slope[None, :])


class _ScaledInverses(NamedTuple):
    """Log-determinants (E + P,) and inverses (E + P, D, D) of the SPD matrices
    ``I + s Sigma s`` for the scales ``s`` of the E outputs, then of the P output pairs."""

    log_det: Tensor
    inverse: Tensor


def _scaled_inverses(scales: Tensor, cov: Tensor) -> _ScaledInverses:
    r"""One batched Cholesky for every :math:`B = I + \operatorname{diag}(s) \Sigma
    \operatorname{diag}(s)` of a step (eigenvalues >= 1: well conditioned whatever
    :math:`\Sigma`, so its explicit inverse is accurate). Shapes: ``scales`` (K, D) -> (K, D, D).
    """
    eye = torch.eye(cov.shape[0], dtype=cov.dtype)
    b_mat = eye + scales[:, :, None] * cov * scales[:, None, :]
    chol = cholesky_jitter(b_mat, "I + s S s")
    return _ScaledInverses(log_det_cholesky(chol), torch.cholesky_inverse(chol))


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
    network. ``weights`` defaults to :func:`~leoc.pilco.gp.pair_weights` of ``beta`` (no GP
    term).

    **Mean and io.** With :math:`\nu_i = z_i - \mu`, :math:`\tilde\nu = \Lambda_a^{-1/2}\nu` and
    the SPD :math:`B_a = I + \Lambda_a^{-1/2} \Sigma \Lambda_a^{-1/2}` (eigenvalues >= 1, unlike
    :math:`\Sigma + \Lambda_a` itself):

    .. math::

        q_{ai} = \alpha_a^2 |B_a|^{-1/2} \exp(-\tfrac12 \tilde\nu_i^\top B_a^{-1} \tilde\nu_i),
        \quad E[y_a] = \beta_a^\top q_a, \quad
        \Sigma^{-1}\operatorname{Cov}[x, y_a] = \Lambda_a^{-1/2} B_a^{-1} \sum_i \beta_{ai}
            q_{ai} \tilde\nu_i.

    **Second moments** (Deisenroth 2010, eq. 2.53):
    :math:`E[y_a y_b] = \sum_{ij} [\beta_a\beta_b^\top - \delta_{ab}\Xi_a]_{ij} Q_{ab,ij}` with
    :math:`Q_{ab,ij} = k_a(z_i, \mu) k_b(z_j, \mu) |R|^{-1/2}
    \exp(\tfrac12 w_{ij}^\top R^{-1} \Sigma w_{ij})`, :math:`R = \Sigma (\Lambda_a^{-1} +
    \Lambda_b^{-1}) + I` and :math:`w_{ij} = \Lambda_a^{-1} \nu_i + \Lambda_b^{-1} \nu_j`.
    Numerics:

    - with :math:`P = \Lambda_a^{-1} + \Lambda_b^{-1}` (diagonal) and the SPD
      :math:`B_{ab} = I + P^{1/2} \Sigma P^{1/2}`, :math:`|R| = |B_{ab}|` and
      :math:`R^{-1}\Sigma = P^{-1/2} (I - B_{ab}^{-1}) P^{-1/2}`: no non-symmetric solve, and
      all E + P matrices B of the step share one batched Cholesky factorisation;
    - writing :math:`P^{-1/2} w_{ij} = p_i + s_j` and :math:`T = I - B_{ab}^{-1}`, the exponent is
      :math:`\rho_i + \gamma_j + p_i^\top T s_j`, a bilinear form of rank D + 2 in the rows
      :math:`[T p_i, \rho_i, 1]` and :math:`[s_j, 1, \gamma_j]`: no (M, M, D) tensor, everything
      summed in log space before the one ``exp`` (no overflow: :math:`Q_{ab,ij} \le \alpha_a^2
      \alpha_b^2`), and :func:`~leoc.linalg.weighted_exp_bilinear` contracts it with the
      weights in cache-sized row blocks, never storing Q;
    - only the pairs ``a <= b`` are computed (:math:`Q_{ba} = Q_{ab}^\top`), and one gather
      spreads them over the symmetric (E, E) result.

    Shapes: ``support`` (M, D), ``beta`` (E, M), ``log_ls`` (E, D), ``log_signal`` (E,),
    ``mean`` (D,), ``cov`` (D, D), ``weights`` (P, M, M) -> mean (E,), cov (E, E), io (D, E).
    """
    num_outputs = beta.shape[0]
    first, second, pair_of = pair_indices(num_outputs)
    nu = support - mean  # (M, D)
    inv_ls = torch.exp(-log_ls)  # (E, D) diagonal of Lambda^-1/2
    inv_ls2 = inv_ls.square()  # (E, D) diagonal of Lambda^-1
    sqrt_prec = (inv_ls2[first] + inv_ls2[second]).sqrt()  # (P, D) diagonal of P^1/2
    inverses = _scaled_inverses(torch.cat([inv_ls, sqrt_prec]), cov)
    log_det_out, log_det_pair = inverses.log_det[:num_outputs], inverses.log_det[num_outputs:]
    # Mean and io.
    nu_scaled = nu * inv_ls[:, None, :]  # (E, M, D)
    solved = nu_scaled @ inverses.inverse[:num_outputs]  # (E, M, D) rows B_a^-1 nu~_i
    sq_scaled = nu_scaled.square().sum(-1)  # (E, M)
    log_q = -0.5 * ((solved * nu_scaled).sum(-1) + log_det_out[:, None])
    weighted = beta * torch.exp(2.0 * log_signal[:, None] + log_q)  # (E, M) beta_ai q_ai
    out_mean = weighted.sum(-1)
    io = (inv_ls * (weighted[:, None, :] @ solved)[:, 0]).T  # (D, E)
    # Second moments.
    t_mat = torch.eye(cov.shape[0], dtype=cov.dtype) - inverses.inverse[num_outputs:]
    row = nu * (inv_ls2[first] / sqrt_prec)[:, None, :]  # (P, M, D): p_i
    col = nu * (inv_ls2[second] / sqrt_prec)[:, None, :]  # (P, M, D): s_j
    row_t = row @ t_mat
    log_k = 2.0 * log_signal[:, None] - 0.5 * sq_scaled  # (E, M) log k_a(z_i, mu)
    row_log = log_k[first] + 0.5 * ((row_t * row).sum(-1) - log_det_pair[:, None])  # (P, M)
    col_log = log_k[second] + 0.5 * ((col @ t_mat) * col).sum(-1)  # (P, M)
    ones = torch.ones(first.shape[0], nu.shape[0], 1, dtype=cov.dtype)
    left = torch.cat([row_t, row_log[..., None], ones], dim=-1)  # (P, M, D + 2)
    right = torch.cat([col, ones, col_log[..., None]], dim=-1)  # (P, M, D + 2)
    weights = pair_weights(beta) if weights is None else weights
    second_moment = weighted_exp_bilinear(left, right, weights)[pair_of]  # (E, E)
    # Exactly symmetric already (a gather of pair values minus an outer product).
    out_cov = second_moment - out_mean[:, None] * out_mean[None, :]
    if gp_variance:
        out_cov = out_cov + torch.diag(torch.exp(2.0 * log_signal))
    return MomentMatch(out_mean, out_cov, io)


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
