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
from leoc.systems.observation import as_observation_map
from leoc.systems.observation import sine_product_cov as _sine_product_cov

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


def observation_moments(
    mean: Tensor, cov: Tensor, layout: Sequence[tuple[str, int]]
) -> MomentMatch:
    """Exact moments of the observation map of ``layout`` (sin/cos augmentation of angles):
    :meth:`leoc.systems.observation.ObservationMap.moments`, which owns the formula (and the
    cached layout constants).

    Shapes: ``mean`` (S,), ``cov`` (S, S) (symmetric) -> mean (O,), cov (O, O), io (S, O).
    """
    obs_map = as_observation_map(layout, mean.shape[0], complete=False)
    return MomentMatch(*obs_map.moments(mean, cov))


def _pairs(values: Tensor, index: Tensor) -> Tensor:
    """``values[index]`` along the first axis; the identity for one output (E = P = 1, the
    usual single-action RBF policy), which saves an indexing op and its backward."""
    return values if values.shape[0] == 1 else values[index]


class SESumConstants(NamedTuple):
    r"""The parts of :func:`se_sum_moments` that depend only on the kernel hyperparameters,
    not on the input distribution (see :func:`se_sum_constants`).

    A GP's hyperparameters stay fixed while the policy is optimised, so
    :func:`~leoc.pilco.propagate.predict` computes them once for the whole horizon.
    """

    b_scale: Tensor  # (E + P, D, D) s s^T, s the diagonal of S_a (outputs) or P_ab^1/2 (pairs)
    form_source: Tensor  # (E + 3P,) which B^-1 each quadratic form scales
    form_scale: Tensor  # (E + 3P, D, D) forms = form_offset + form_scale * B^-1[form_source]
    form_offset: Tensor  # (E + 3P, D, D)
    log_scale: Tensor  # (E,) log alpha_a^2
    pair_log_scale: Tensor  # (P,) log alpha_a^2 + log alpha_b^2


@functools.cache
def _form_layout(num_outputs: int) -> tuple[Tensor, Tensor]:
    """Source B^-1 (index into the E + P factorisations) and sign of each quadratic form of
    :func:`se_sum_constants`, in the order G_ab (P), F_a (E), A_ab / 2 (P), A_ba / 2 (P).
    Cached per E (constant tensors, never written to)."""
    num_pairs = num_outputs * (num_outputs + 1) // 2
    pairs = torch.arange(num_outputs, num_outputs + num_pairs)
    source = torch.cat([pairs, torch.arange(num_outputs), pairs, pairs])
    sign = torch.cat(
        [
            torch.full((num_pairs,), -1.0),
            torch.ones(num_outputs),
            torch.full((2 * num_pairs,), -0.5),
        ]
    ).to(torch.float64)
    return source, sign


def se_sum_constants(log_ls: Tensor, log_signal: Tensor) -> SESumConstants:
    r"""Hyperparameter-only parts of :func:`se_sum_moments` (differentiable).

    Every matrix of a quadratic form there is a diagonal scaling of some
    :math:`B^{-1}` plus a diagonal: :math:`F_a = S_a B_a^{-1} S_a`, and with
    :math:`T = I - B_{ab}^{-1}`, :math:`G_{ab} = C_a T C_b = C_a C_b - C_a B_{ab}^{-1} C_b` and
    :math:`\tfrac12 A_{ab} = \tfrac12 (C_a^2 - \Lambda_a^{-1}) - \tfrac12 C_a B_{ab}^{-1} C_a`.
    So all of them come from one gather of :math:`B^{-1}`, one product with ``form_scale`` and
    one sum with ``form_offset``, whatever E.

    Shapes: ``log_ls`` (E, D), ``log_signal`` (E,).
    """
    num_outputs = log_ls.shape[0]
    first, second, _ = pair_indices(num_outputs)
    inv_ls = torch.exp(-log_ls)  # (E, D) diagonal of S_a = Lambda_a^-1/2
    prec = inv_ls.square()  # (E, D) diagonal of Lambda_a^-1
    prec_first, prec_second = _pairs(prec, first), _pairs(prec, second)
    sqrt_prec = (prec_first + prec_second).sqrt()  # (P, D) diagonal of P^1/2
    c_first = prec_first / sqrt_prec  # (P, D) diagonal of C_a
    c_second = prec_second / sqrt_prec  # (P, D) diagonal of C_b
    scales = torch.cat([inv_ls, sqrt_prec])  # (E + P, D)
    source, sign = _form_layout(num_outputs)
    left = torch.cat([c_first, inv_ls, c_first, c_second])  # (E + 3P, D)
    right = torch.cat([c_second, inv_ls, c_first, c_second])
    offset = torch.cat(
        [
            c_first * c_second,
            torch.zeros_like(inv_ls),
            0.5 * (c_first.square() - prec_first),
            0.5 * (c_second.square() - prec_second),
        ]
    )
    log_scale = 2.0 * log_signal
    return SESumConstants(
        scales[:, :, None] * scales[:, None, :],
        source,
        sign.to(log_ls.dtype)[:, None, None] * left[:, :, None] * right[:, None, :],
        torch.diag_embed(offset),
        log_scale,
        _pairs(log_scale, first) + _pairs(log_scale, second),
    )


class _SEForms(NamedTuple):
    """The quadratic forms of :func:`se_sum_moments` at one input distribution."""

    nu: Tensor  # (M, D) nu_i = z_i - mu
    nu_forms: Tensor  # (P + E + 2P, M, D) nu_i^T X for X = G_ab (P), F_a (E), A_ab / 2, A_ba / 2
    quad_f: Tensor  # (E, M) nu_i^T F_a nu_i
    half_first: Tensor  # (P, M) nu_i^T A_ab nu_i / 2
    half_second: Tensor  # (P, M) nu_j^T A_ba nu_j / 2
    log_det_out: Tensor  # (E,) log|B_a|
    log_det_pair: Tensor  # (P,) log|B_ab|


def _se_forms(support: Tensor, mean: Tensor, cov: Tensor, const: SESumConstants) -> _SEForms:
    r"""Factorise every B of the step and take every quadratic form of :func:`se_sum_moments`.

    Every B (E outputs, P pairs) shares one batched Cholesky factorisation, every form matrix
    comes from one gather of the :math:`B^{-1}` (:func:`se_sum_constants`), and every product
    :math:`\nu_i^\top X` with them is one batched matmul.

    Shapes: ``support`` (M, D), ``mean`` (D,), ``cov`` (D, D).
    """
    num_outputs, dim = const.log_scale.shape[0], cov.shape[0]
    num_pairs = const.pair_log_scale.shape[0]
    nu = support - mean  # (M, D)
    b_mat = torch.addcmul(torch.eye(dim, dtype=cov.dtype), const.b_scale, cov)  # (E + P, D, D)
    chol = cholesky_jitter(b_mat, "I + s S s")
    log_det = log_det_cholesky(chol)  # (E + P,)
    b_inv = torch.cholesky_inverse(chol)  # (E + P, D, D), well conditioned (eigenvalues <= 1)
    forms = torch.addcmul(const.form_offset, const.form_scale, b_inv[const.form_source])
    # nu_i^T X for every form X of the step (G_ab, F_a, A_ab / 2, A_ba / 2) in one matmul.
    nu_forms = nu @ forms  # (P + E + 2P, M, D)
    quad = (nu_forms[num_pairs:] * nu).sum(-1)  # (E + 2P, M)
    quad_f, half_first, half_second = quad.split([num_outputs, num_pairs, num_pairs])
    log_det_out, log_det_pair = log_det.split([num_outputs, num_pairs])
    return _SEForms(nu, nu_forms, quad_f, half_first, half_second, log_det_out, log_det_pair)


class _SEFirstMoments(NamedTuple):
    """Mean (E,) and io (D, E) of :func:`se_sum_moments`."""

    mean: Tensor
    io: Tensor


def _se_first_moments(beta: Tensor, const: SESumConstants, forms: _SEForms) -> _SEFirstMoments:
    """``E[y_a] = beta_a^T q_a`` and ``io_a = F_a sum_i beta_ai q_ai nu_i`` (F_a is symmetric:
    F_a nu_i is row i of nu F_a). Shapes: ``beta`` (E, M)."""
    num_outputs, num_pairs = beta.shape[0], const.pair_log_scale.shape[0]
    log_norm = const.log_scale - 0.5 * forms.log_det_out  # (E,) log(alpha^2 |B_a|^-1/2)
    weighted = beta * torch.exp(log_norm[:, None] - 0.5 * forms.quad_f)  # (E, M)
    out_mean = weighted.sum(-1)  # (E,)
    f_rows = forms.nu_forms[num_pairs : num_pairs + num_outputs]  # (E, M, D)
    io = (weighted[:, None, :] @ f_rows)[:, 0, :].T  # (D, E)
    return _SEFirstMoments(out_mean, io)


def _se_covariance(
    beta: Tensor,
    weights: Tensor | None,
    const: SESumConstants,
    forms: _SEForms,
    out_mean: Tensor,
    gp_variance: bool,
) -> Tensor:
    r"""Covariance (E, E) of :func:`se_sum_moments`: :math:`E[y_a y_b]` (the sum over i, j of
    ``weights`` times :math:`Q_{ab}`) minus the outer product of ``out_mean`` (E,), plus
    :math:`\alpha_a^2` on the diagonal with ``gp_variance``.

    Only the pairs ``a <= b`` are computed (:math:`Q_{ba} = Q_{ab}^\top`), and one gather
    spreads them over the symmetric (E, E) result. :math:`\log Q` is the bilinear form
    :math:`(G_{ab}^\top \nu_i)^\top \nu_j` plus the row offsets :math:`c_{ab} + \tfrac12
    \nu_i^\top A_{ab} \nu_i` and the column offsets :math:`\tfrac12 \nu_j^\top A_{ba} \nu_j`:
    no (M, M, D) tensor, everything summed in log space before the one ``exp`` (no overflow:
    :math:`Q_{ab,ij} \le \alpha_a^2 \alpha_b^2`), and :func:`~leoc.linalg.weighted_exp_bilinear`
    contracts it with the weights in cache-sized row blocks, never storing Q.

    Shapes: ``beta`` (E, M), ``weights`` (P, M, M) (default ``pair_weights(beta)``).
    """
    num_outputs, num_pairs = beta.shape[0], const.pair_log_scale.shape[0]
    constant = const.pair_log_scale - 0.5 * forms.log_det_pair  # (P,) c_ab
    weights = pair_weights(beta) if weights is None else weights
    values = weighted_exp_bilinear(
        forms.nu_forms[:num_pairs],
        forms.nu.expand(num_pairs, -1, -1),
        weights,
        constant[:, None] + forms.half_first,
        forms.half_second,
    )  # (P,)
    _, _, pair_of = pair_indices(num_outputs)
    second_moment = values.reshape(1, 1) if num_outputs == 1 else values[pair_of]  # (E, E)
    # Exactly symmetric already (a gather of pair values minus an outer product).
    out_cov = second_moment - out_mean[:, None] * out_mean[None, :]
    if gp_variance:
        out_cov = out_cov + torch.diag(torch.exp(const.log_scale))
    return out_cov


def se_sum_moments(
    support: Tensor,
    beta: Tensor,
    log_ls: Tensor,
    log_signal: Tensor,
    mean: Tensor,
    cov: Tensor,
    weights: Tensor | None = None,
    gp_variance: bool = False,
    constants: SESumConstants | None = None,
) -> MomentMatch:
    r"""Exact moments of :math:`y_a(x) = \sum_i \beta_{ai} k_a(x, z_i)` (+ GP variance).

    ``gp_variance``: y is a GP prediction and each output's variance gains the expected
    posterior variance :math:`\alpha_a^2 - \operatorname{tr}(\Xi_a Q_{aa})` (Deisenroth 2010,
    eq. 2.55; the trace comes in through ``weights``); otherwise y is a deterministic RBF
    network. ``weights`` defaults to :func:`~leoc.pilco.gp.pair_weights` of ``beta`` (no GP
    term). ``constants``: :func:`se_sum_constants` of ``log_ls`` and ``log_signal``, computed
    here if not given (pass them to reuse them over many inputs).

    **Mean and io.** With :math:`\nu_i = z_i - \mu`, :math:`S_a = \Lambda_a^{-1/2}` and the SPD
    :math:`B_a = I + S_a \Sigma S_a` (eigenvalues >= 1, unlike :math:`\Sigma + \Lambda_a`), and
    :math:`F_a = S_a B_a^{-1} S_a = (\Sigma + \Lambda_a)^{-1}`:

    .. math::

        q_{ai} = \alpha_a^2 |B_a|^{-1/2} \exp(-\tfrac12 \nu_i^\top F_a \nu_i),
        \quad E[y_a] = \beta_a^\top q_a, \quad
        \Sigma^{-1}\operatorname{Cov}[x, y_a] = F_a \sum_i \beta_{ai} q_{ai} \nu_i.

    **Second moments** (Deisenroth 2010, eq. 2.53):
    :math:`E[y_a y_b] = \sum_{ij} [\beta_a\beta_b^\top - \delta_{ab}\Xi_a]_{ij} Q_{ab,ij}` with
    :math:`Q_{ab,ij} = k_a(z_i, \mu) k_b(z_j, \mu) |R|^{-1/2}
    \exp(\tfrac12 w_{ij}^\top R^{-1} \Sigma w_{ij})`, :math:`R = \Sigma (\Lambda_a^{-1} +
    \Lambda_b^{-1}) + I` and :math:`w_{ij} = \Lambda_a^{-1} \nu_i + \Lambda_b^{-1} \nu_j`.
    With the diagonal :math:`P = \Lambda_a^{-1} + \Lambda_b^{-1}` and the SPD
    :math:`B_{ab} = I + P^{1/2} \Sigma P^{1/2}`, :math:`|R| = |B_{ab}|` and
    :math:`R^{-1}\Sigma = P^{-1/2} T P^{-1/2}` with :math:`T = I - B_{ab}^{-1}`, so that

    .. math::

        \log Q_{ab,ij} = c_{ab} + \tfrac12 \nu_i^\top A_{ab} \nu_i + \tfrac12 \nu_j^\top
            A_{ba} \nu_j + \nu_i^\top G_{ab} \nu_j, \qquad
        c_{ab} = 2 \log\alpha_a + 2 \log\alpha_b - \tfrac12 \log|B_{ab}|,

    with :math:`C_a = \Lambda_a^{-1} P^{-1/2}`, :math:`G_{ab} = C_a T C_b` and
    :math:`A_{ab} = C_a T C_a - \Lambda_a^{-1}` (all diagonal scalings of T). The helpers
    :func:`_se_forms` (the quadratic forms), :func:`_se_first_moments` (mean and io) and
    :func:`_se_covariance` say how each part is computed.

    Shapes: ``support`` (M, D), ``beta`` (E, M), ``log_ls`` (E, D), ``log_signal`` (E,),
    ``mean`` (D,), ``cov`` (D, D), ``weights`` (P, M, M) -> mean (E,), cov (E, E), io (D, E).
    """
    const = se_sum_constants(log_ls, log_signal) if constants is None else constants
    forms = _se_forms(support, mean, cov, const)
    first = _se_first_moments(beta, const, forms)
    out_cov = _se_covariance(beta, weights, const, forms, first.mean, gp_variance)
    return MomentMatch(first.mean, out_cov, first.io)


def gp_moments(
    post: GPPosterior, mean: Tensor, cov: Tensor, constants: SESumConstants | None = None
) -> MomentMatch:
    """Exact moments of the GP prediction at a Gaussian input (latent f, without noise).

    ``constants``: :func:`gp_constants` of ``post``, to reuse over many inputs (computed here
    if not given).

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
        constants=constants,
    )


def gp_constants(post: GPPosterior) -> SESumConstants:
    """:func:`se_sum_constants` of a GP's hyperparameters, for :func:`gp_moments`."""
    return se_sum_constants(post.log_lengthscales, post.log_signal)


class RBFConstants(NamedTuple):
    """What :func:`rbf_moments` needs of a network whatever the input distribution: the
    :func:`se_sum_constants` of its length-scales and its pair weights ``w_a w_b^T``
    (differentiable; computed once per prediction, they are shared by all its steps)."""

    kernel: SESumConstants
    weights: Tensor  # (P, N, N)


def rbf_constants(network: torch.nn.Module) -> RBFConstants:
    """:class:`RBFConstants` of an :class:`~leoc.policies.RBFNetwork` (unit signal variance)."""
    log_signal = torch.zeros(network.weights.shape[0], dtype=network.weights.dtype)
    return RBFConstants(
        se_sum_constants(network.log_lengthscales, log_signal), pair_weights(network.weights)
    )


def rbf_moments(
    network: torch.nn.Module, mean: Tensor, cov: Tensor, constants: RBFConstants | None = None
) -> MomentMatch:
    """Exact moments of an :class:`~leoc.policies.RBFNetwork` (unit signal variance).

    ``constants``: :func:`rbf_constants` of ``network``, to reuse over many inputs (computed
    here if not given).

    Shapes: ``mean`` (D,), ``cov`` (D, D) -> mean (F,), cov (F, F), io (D, F).
    """
    constants = rbf_constants(network) if constants is None else constants
    return se_sum_moments(
        network.centres,
        network.weights,
        network.log_lengthscales,
        torch.zeros(network.weights.shape[0], dtype=mean.dtype),
        mean,
        cov,
        constants.weights,
        constants=constants.kernel,
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
