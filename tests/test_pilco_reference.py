"""The fast moment-matching code against straightforward recomputations kept here.

The references follow the textbook formulas (Deisenroth 2010, sec. 2.3; the (M, M, D) tensors,
explicit solves and inverses) with none of the fast code's rewrites (batched Cholesky, log-space
bilinear form, blockwise kernel with gradients formed in the forward pass, symmetric pairs).
Values and gradients must agree to 1e-10.

The GP test data carry noise of standard deviation 0.1: the GP variance term
``alpha^2 - tr(Xi Q)`` sums terms of size ``|Xi| ~ 1 / sigma^2``, so with a nearly noise-free GP
(``sigma ~ 0.01``, ``|Xi| ~ 1e4``) any two float64 implementations, the reference included,
differ by ~1e-9 in the covariance (round-off ~1e-17 of the sum of absolute terms).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import leoc.linalg
from leoc.linalg import weighted_exp_bilinear
from leoc.pilco.gp import GPSettings, fit_gp, se_kernel
from leoc.pilco.moments import gp_moments, observation_moments, se_sum_moments, sin_squash_moments

DTYPE = torch.float64
TOL = 1e-10


def reference_se_sum_moments(support, beta, log_ls, log_signal, mean, cov, inv_k=None):
    """Mean (E,), covariance (E, E) and Sigma^-1 Cov[x, y] (D, E) of sum_i beta_ai k_a(x, z_i)
    (plus the GP variance when ``inv_k`` is given), term by term from the textbook formulas."""
    num_outputs, dim = log_ls.shape
    eye = torch.eye(dim, dtype=DTYPE)
    nu = support - mean  # (M, D)
    lambdas = torch.exp(2.0 * log_ls)  # (E, D) squared length-scales
    signal2 = torch.exp(2.0 * log_signal)
    means, ios, k_at_mean = [], [], []
    for a in range(num_outputs):
        lam = torch.diag(lambdas[a])
        inv_sum = torch.linalg.inv(cov + lam)
        det = torch.linalg.det(cov @ torch.linalg.inv(lam) + eye)
        quad = torch.einsum("md,de,me->m", nu, inv_sum, nu)
        q = signal2[a] / torch.sqrt(det) * torch.exp(-0.5 * quad)
        means.append(beta[a] @ q)
        ios.append(inv_sum @ (nu.T @ (beta[a] * q)))
        k_at_mean.append(signal2[a] * torch.exp(-0.5 * (nu**2 / lambdas[a]).sum(-1)))
    out_mean = torch.stack(means)
    second = torch.zeros(num_outputs, num_outputs, dtype=DTYPE)
    for a in range(num_outputs):
        for b in range(num_outputs):
            inv_a, inv_b = torch.diag(1.0 / lambdas[a]), torch.diag(1.0 / lambdas[b])
            r_mat = cov @ (inv_a + inv_b) + eye
            z = (nu @ inv_a)[:, None, :] + (nu @ inv_b)[None, :, :]  # (M, M, D)
            r_inv_s = torch.linalg.solve(r_mat, cov)
            expo = 0.5 * torch.einsum("ijd,de,ije->ij", z, r_inv_s, z)
            q_ab = (
                k_at_mean[a][:, None]
                * k_at_mean[b][None, :]
                / torch.sqrt(torch.linalg.det(r_mat))
                * torch.exp(expo)
            )
            second[a, b] = beta[a] @ q_ab @ beta[b]
            if inv_k is not None and a == b:
                second[a, b] = second[a, b] + signal2[a] - torch.trace(inv_k[a] @ q_ab)
    out_cov = second - torch.outer(out_mean, out_mean)
    return out_mean, out_cov, torch.stack(ios, dim=1)


def spd(factor: torch.Tensor) -> torch.Tensor:
    """A covariance as a function of an unconstrained factor: gradients then compare the
    symmetric dependence on the covariance (functions of a symmetric matrix may read one
    triangle only, so derivatives by single entries of it are not comparable)."""
    return factor @ factor.T + 0.01 * torch.eye(factor.shape[0], dtype=DTYPE)


def random_input(dim: int, seed: int, scale: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean (D,) and covariance factor (D, D)."""
    gen = torch.Generator().manual_seed(seed)
    mean = torch.randn(dim, generator=gen, dtype=DTYPE)
    return mean, scale * torch.randn(dim, dim, generator=gen, dtype=DTYPE)


def assert_all_close(fast, reference) -> None:
    for got, want in zip(fast, reference, strict=True):
        torch.testing.assert_close(got, want, rtol=TOL, atol=TOL)


def small_gp(num: int, sparse: bool, noise: float = 0.1):
    gen = torch.Generator().manual_seed(3)
    x = torch.randn(num, 3, generator=gen, dtype=DTYPE)
    y = torch.stack([torch.sin(x[:, 0]) + 0.5 * x[:, 1], torch.cos(x[:, 2]) * x[:, 0]], dim=1)
    y = y + noise * torch.randn(y.shape, generator=gen, dtype=DTYPE)
    settings = GPSettings(
        train_iterations=20, max_full_points=20 if sparse else 300, num_inducing=15
    )
    return fit_gp(x, y, settings, np.random.default_rng(0))


@pytest.mark.parametrize("sparse", [False, True])
@pytest.mark.parametrize("scale", [0.05, 0.6])
def test_gp_moments_and_gradients_match_reference(sparse: bool, scale: float) -> None:
    post = small_gp(40, sparse)
    assert post.sparse == sparse
    mean, factor = random_input(3, 1, scale)

    def fast(m, f):
        return gp_moments(post, m, spd(f))

    def reference(m, f):
        return reference_se_sum_moments(
            post.support, post.beta, post.log_lengthscales, post.log_signal, m, spd(f), post.inv_k
        )

    assert_all_close(fast(mean, factor), reference(mean, factor))
    jac_fast = torch.autograd.functional.jacobian(fast, (mean, factor))
    jac_ref = torch.autograd.functional.jacobian(reference, (mean, factor))
    for got, want in zip(jac_fast, jac_ref, strict=True):
        assert_all_close(got, want)


def test_rbf_moments_and_parameter_gradients_match_reference() -> None:
    gen = torch.Generator().manual_seed(4)
    centres = torch.randn(7, 3, generator=gen, dtype=DTYPE)
    weights = torch.randn(2, 7, generator=gen, dtype=DTYPE)
    log_ls = 0.3 * torch.randn(2, 3, generator=gen, dtype=DTYPE)
    log_signal = torch.zeros(2, dtype=DTYPE)
    mean, factor = random_input(3, 2, 0.5)

    def fast(*args):
        return se_sum_moments(*args[:3], log_signal, args[3], spd(args[4]))

    def reference(*args):
        return reference_se_sum_moments(*args[:3], log_signal, args[3], spd(args[4]))

    inputs = (centres, weights, log_ls, mean, factor)
    assert_all_close(fast(*inputs), reference(*inputs))
    jac_fast = torch.autograd.functional.jacobian(fast, inputs)
    jac_ref = torch.autograd.functional.jacobian(reference, inputs)
    for got, want in zip(jac_fast, jac_ref, strict=True):
        assert_all_close(got, want)


def reference_sine_cov(mean: torch.Tensor, cov: torch.Tensor) -> torch.Tensor:
    """Cov[sin x_i, sin x_j] = (E cos(x_i - x_j) - E cos(x_i + x_j)) / 2 - E sin x_i E sin x_j."""
    var = cov.diagonal()
    e_sin = torch.exp(-0.5 * var) * torch.sin(mean)
    var_diff = var[:, None] + var[None, :] - 2.0 * cov
    var_sum = var[:, None] + var[None, :] + 2.0 * cov
    return 0.5 * (
        torch.exp(-0.5 * var_diff) * torch.cos(mean[:, None] - mean[None, :])
        - torch.exp(-0.5 * var_sum) * torch.cos(mean[:, None] + mean[None, :])
    ) - torch.outer(e_sin, e_sin)


def test_sin_squash_and_observation_moments_match_reference() -> None:
    mean, factor = random_input(3, 5, 0.8)
    cov = spd(factor)
    limit = 1.7
    out = sin_squash_moments(mean, cov, limit)
    torch.testing.assert_close(
        out.cov, limit**2 * reference_sine_cov(mean / limit, cov / limit**2), rtol=TOL, atol=TOL
    )
    layout = [("cos", 0), ("sin", 0), ("state", 1), ("sin", 2)]
    obs = observation_moments(mean, cov, layout)
    phases = torch.tensor([math.pi / 2, 0.0, 0.0], dtype=DTYPE)
    trig = [0, 1, 3]
    index = torch.tensor([0, 0, 2])
    expected = reference_sine_cov(mean[index] + phases, cov[index][:, index])
    torch.testing.assert_close(obs.cov[trig][:, trig], expected, rtol=TOL, atol=TOL)


@pytest.mark.parametrize("block_entries", [7, 2**17])
def test_blockwise_exp_bilinear_matches_plain_formula(monkeypatch, block_entries: int) -> None:
    """Several row blocks (and a last, shorter one) give the plain value and gradients."""
    monkeypatch.setattr(leoc.linalg, "BLOCK_ENTRIES", block_entries)
    gen = torch.Generator().manual_seed(6)
    left = (0.3 * torch.randn(3, 11, 4, generator=gen, dtype=DTYPE)).requires_grad_()
    right = (0.3 * torch.randn(3, 9, 4, generator=gen, dtype=DTYPE)).requires_grad_()
    weights = torch.randn(3, 11, 9, generator=gen, dtype=DTYPE).requires_grad_()
    upstream = torch.randn(3, generator=gen, dtype=DTYPE)
    fast = weighted_exp_bilinear(left, right, weights)
    fast_grads = torch.autograd.grad(fast @ upstream, (left, right, weights))
    plain = (weights * torch.exp(left @ right.transpose(-1, -2))).sum((-1, -2))
    plain_grads = torch.autograd.grad(plain @ upstream, (left, right, weights))
    torch.testing.assert_close(fast, plain, rtol=1e-13, atol=0.0)
    for got, want in zip(fast_grads, plain_grads, strict=True):
        torch.testing.assert_close(got, want, rtol=1e-12, atol=1e-14)
    with torch.no_grad():
        torch.testing.assert_close(weighted_exp_bilinear(left, right, weights), plain)


def test_se_kernel_matches_scaled_differences() -> None:
    gen = torch.Generator().manual_seed(8)
    x1 = torch.randn(6, 3, generator=gen, dtype=DTYPE)
    x2 = torch.randn(5, 3, generator=gen, dtype=DTYPE)
    log_ls = 0.4 * torch.randn(2, 3, generator=gen, dtype=DTYPE)
    log_signal = torch.tensor([0.1, -0.3], dtype=DTYPE)
    scaled = (x1[None, :, None, :] - x2[None, None, :, :]) / torch.exp(log_ls)[:, None, None, :]
    expected = torch.exp(2.0 * log_signal)[:, None, None] * torch.exp(
        -0.5 * scaled.square().sum(-1)
    )
    torch.testing.assert_close(se_kernel(x1, x2, log_ls, log_signal), expected, rtol=1e-14, atol=0)
