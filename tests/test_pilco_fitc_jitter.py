"""FITC's fixed jitter on the inducing inputs' Gram matrix (``GPSettings.inducing_jitter``).

References, written here from the textbook definitions (Snelson and Ghahramani 2006;
Quinonero-Candela and Rasmussen 2005, eq. 24 and 26) with dense matrices and explicit inverses:
the FITC marginal likelihood ``y ~ N(0, Q_nn + diag(K_nn - Q_nn) + sigma^2 I)`` with
``Q_nn = K_nm (K_mm + j alpha^2 I)^-1 K_mn``, its posterior weights
``beta = Sigma^-1 K_mn Gamma^-1 y`` and ``Xi = K_mm^-1 - Sigma^-1`` with
``Sigma = K_mm + K_mn Gamma^-1 K_nm`` (jittered ``K_mm`` throughout), and the bound
``0 <= Xi <= (j alpha^2)^-1`` that the jitter exists for.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.stats import multivariate_normal

import leoc.pilco.gp
from leoc.pilco.config import PilcoConfig
from leoc.pilco.gp import GPHyper, GPSettings, fit_gp, fitc_nll, gp_predict, posterior

DTYPE = torch.float64
FLOOR_VAR = torch.tensor([1e-6, 4e-6], dtype=DTYPE)


def toy_data(num: int = 40) -> tuple[torch.Tensor, torch.Tensor]:
    gen = torch.Generator().manual_seed(11)
    x = torch.randn(num, 3, generator=gen, dtype=DTYPE)
    y = torch.stack([torch.sin(x[:, 0]) + 0.5 * x[:, 1], torch.cos(x[:, 2]) * x[:, 0]], dim=1)
    return x, y + 0.05 * torch.randn(y.shape, generator=gen, dtype=DTYPE)


HYPER = GPHyper(
    torch.log(torch.tensor([[1.2, 0.9, 2.0], [0.7, 1.5, 1.1]], dtype=DTYPE)),
    torch.log(torch.tensor([0.8, 1.3], dtype=DTYPE)),
    torch.log(torch.tensor([0.05, 0.08], dtype=DTYPE)),
)


def gram(a: np.ndarray, b: np.ndarray, lengthscales: np.ndarray, signal2: float) -> np.ndarray:
    diff = (a[:, None, :] - b[None, :, :]) / lengthscales
    return signal2 * np.exp(-0.5 * (diff**2).sum(-1))


def reference(x, y, inducing, jitter):
    """Per output: the FITC negative log likelihood, beta (M,) and Xi (M, M), dense."""
    x, y, z = x.numpy(), y.numpy(), inducing.numpy()
    out = []
    for a in range(y.shape[1]):
        ls = np.exp(HYPER.log_lengthscales[a].numpy())
        signal2 = math.exp(2.0 * float(HYPER.log_signal[a]))
        noise = float(FLOOR_VAR[a]) + math.exp(2.0 * float(HYPER.log_noise[a]))
        k_mm = gram(z, z, ls, signal2) + jitter * signal2 * np.eye(len(z))
        k_nm = gram(x, z, ls, signal2)
        q_nn = k_nm @ np.linalg.inv(k_mm) @ k_nm.T
        gamma = signal2 - np.diag(q_nn) + noise
        cov = q_nn + np.diag(gamma)
        nll = -multivariate_normal(np.zeros(len(x)), cov).logpdf(y[:, a])
        sigma = k_mm + k_nm.T @ np.diag(1.0 / gamma) @ k_nm
        beta = np.linalg.solve(sigma, k_nm.T @ (y[:, a] / gamma))
        xi = np.linalg.inv(k_mm) - np.linalg.inv(sigma)
        out.append((nll, beta, xi))
    return out


@pytest.mark.parametrize("jitter", [0.0, 1e-6, 0.05])
def test_fitc_likelihood_and_posterior_match_the_dense_formulas(jitter: float) -> None:
    x, y = toy_data()
    inducing = x[::4]  # 10 inducing inputs, well spread: K_mm is well conditioned at jitter 0
    want = reference(x, y, inducing, jitter)
    nll = fitc_nll(HYPER, x, y, inducing, FLOOR_VAR, jitter)
    assert float(nll) == pytest.approx(sum(w[0] for w in want), rel=1e-9)
    post = posterior(HYPER, x, y, FLOOR_VAR, inducing, jitter)
    for a, (_, beta, xi) in enumerate(want):
        np.testing.assert_allclose(post.beta[a].numpy(), beta, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(post.inv_k[a].numpy(), xi, rtol=1e-7, atol=1e-8)


def test_jitter_bounds_xi_with_near_duplicate_inducing_inputs() -> None:
    """Inducing inputs 1e-9 apart make K_mm singular; with the jitter, Xi stays within
    (j alpha^2)^-1 and the GP predicts as with each inducing input once (the same span, so
    the same FITC model up to the jitter's O(j) change)."""
    x, y = toy_data()
    single = x[::4]
    doubled = torch.cat([single, single + 1e-9])
    jitter = 1e-6
    post = posterior(HYPER, x, y, FLOOR_VAR, doubled, jitter)
    largest = torch.linalg.eigvalsh(post.inv_k)[:, -1]
    bound = 1.0 / (jitter * torch.exp(2.0 * HYPER.log_signal))
    assert bool((largest <= bound * (1 + 1e-6)).all()), (largest, bound)
    once = posterior(HYPER, x, y, FLOOR_VAR, single, jitter)
    probe = torch.randn(25, 3, generator=torch.Generator().manual_seed(2), dtype=DTYPE)
    for got, want in zip(gp_predict(post, probe), gp_predict(once, probe), strict=True):
        torch.testing.assert_close(got, want, rtol=0.0, atol=1e-4)


def test_fit_gp_uses_the_settings_jitter(monkeypatch: pytest.MonkeyPatch) -> None:
    """In the likelihood it maximises (a spy on its calls) and in the posterior it returns."""
    x, y = toy_data(60)
    settings = GPSettings(
        train_iterations=15, max_full_points=30, num_inducing=30, inducing_jitter=0.05
    )
    seen: list[float] = []

    def spy(*args, **kwargs):
        seen.append(args[5] if len(args) > 5 else kwargs.get("jitter", math.nan))
        return fitc_nll(*args, **kwargs)

    monkeypatch.setattr(leoc.pilco.gp, "fitc_nll", spy)
    model = fit_gp(x, y, settings, np.random.default_rng(0))
    assert model.sparse
    assert seen and set(seen) == {0.05}
    largest = torch.linalg.eigvalsh(model.inv_k)[:, -1]
    bound = 1.0 / (0.05 * torch.exp(2.0 * model.log_signal))
    assert bool((largest <= bound * (1 + 1e-9)).all()), (largest, bound)
    assert bool((largest > 0.2 * bound).all())  # 30 inducing inputs in 3-D: K_mm near singular


def test_saved_configs_without_the_jitter_read_back_as_they_trained() -> None:
    config = PilcoConfig.for_system("pendulum")
    assert config.gp.inducing_jitter == pytest.approx(1e-6, rel=1e-12)
    data = config.to_dict()
    assert PilcoConfig.from_dict(data).gp.inducing_jitter == pytest.approx(1e-6, rel=1e-12)
    del data["gp"]["inducing_jitter"]  # a run saved before the setting existed
    assert PilcoConfig.from_dict(data).gp.inducing_jitter == 0.0
    override = PilcoConfig.for_system("pendulum", gp_inducing_jitter=1e-4)
    assert override.gp.inducing_jitter == pytest.approx(1e-4, rel=1e-12)


@pytest.mark.parametrize("bad", [-1e-6, 1.0, True, "1e-6", math.nan])
def test_a_bad_jitter_is_refused_by_name(bad) -> None:
    with pytest.raises(ValueError, match=r"^inducing_jitter: expected a number in \[0, 1\)"):
        GPSettings(inducing_jitter=bad)
