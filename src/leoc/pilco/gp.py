r"""Gaussian-process dynamics model of PILCO: one GP per predicted state dimension.

Letters: N data, M support points (N for the full GP, the inducing inputs for FITC), D GP input
dimension (observation + action, angles as cos/sin), E outputs (state dimensions).

Each output ``a`` is an independent zero-mean GP with a squared-exponential ARD kernel

.. math::

    k_a(x, x') = \alpha_a^2 \exp\big(-\tfrac12 (x - x')^\top \Lambda_a^{-1} (x - x')\big),
    \qquad \Lambda_a = \operatorname{diag}(\ell_{a1}^2, \dots, \ell_{aD}^2),

observed with Gaussian noise :math:`\sigma_a^2`. Hyperparameters maximise the log marginal
likelihood plus a smooth penalty (PILCO's "hypCurb") that keeps every length-scale within
``lengthscale_ratio`` of the input's spread and the signal-to-noise ratio below ``max_snr``.

Whatever the approximation, the fitted model is summarised by a :class:`GPPosterior`:

.. math::

    m_a(x) = \sum_{i=1}^{M} \beta_{ai}\, k_a(x, z_i), \qquad
    v_a(x) = \alpha_a^2 - k_a(x, Z)^\top \Xi_a\, k_a(x, Z),

with ``Xi = (K + sigma^2 I)^-1`` for the full GP and
``Xi = K_mm^-1 - (K_mm + K_mn Gamma^-1 K_nm)^-1`` for FITC (Snelson & Ghahramani 2006), which is
all that moment matching (:func:`leoc.pilco.moments.gp_moments`) needs.

References
----------
M. P. Deisenroth, "Efficient Reinforcement Learning using Gaussian Processes", PhD thesis,
KIT 2010, sections 2.3-2.4 and appendix.
E. Snelson and Z. Ghahramani, "Sparse Gaussian processes using pseudo-inputs", NIPS 2006.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, ClassVar, NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.linalg import CholeskyError as CholeskyError  # re-exported: raised by fit_gp
from leoc.linalg import cholesky_jitter, log_det_cholesky, symmetrise

DTYPE = torch.float64
LOG_2PI = math.log(2.0 * math.pi)
# The smallest spread used to scale initial length-scales (a constant input column).
MIN_INPUT_STD = 1e-3
#: FITC's jitter on the inducing inputs' Gram matrix, a fraction of the signal variance
#: (the default of :class:`GPSettings`' ``inducing_jitter``).
INDUCING_JITTER = 1e-6


@dataclasses.dataclass
class GPSettings:
    """How the dynamics GPs are fitted.

    Attributes
    ----------
    max_full_points : int
        Up to this many data, the exact GP; beyond it, FITC with ``num_inducing`` inducing inputs.
    num_inducing : int
        Number of FITC inducing inputs (chosen from the data by k-means++ seeding).
    train_iterations : int
        L-BFGS iterations of the hyperparameter fit.
    lengthscale_ratio : float
        Length-scales are kept within this factor of each input's standard deviation.
    max_snr : float
        Signal-to-noise ratios alpha / sigma are kept below this.
    penalty_power : int
        Power p of the smooth barrier ``((log l - log std) / log ratio)^p``.
    noise_floor : float
        Lower bound on the noise standard deviation, relative to the target's standard deviation.
    fixed_noise_var : float or None
        If set, every output's noise variance is this value (absolute, in squared target units)
        and is not fitted (``noise_floor`` is then unused); None: fitted above the floor.
    inducing_jitter : float
        FITC only: ``K_mm + inducing_jitter * alpha^2 I`` in the fit and the posterior, a fixed
        jitter that bounds the condition number of the inducing inputs' Gram matrix near
        ``1 / inducing_jitter`` (GPflow adds an absolute 1e-6 for the same reason). Without it
        (0, leoc before this setting; the Cholesky then adds jitter only when it fails), 200
        inducing inputs closer than a length-scale made ``Xi`` reach 4.6e12 on the pendulum,
        and PILCO's predicted horizon cost moved by 2.5 (of 30) for 1e-8 and 1e-6 steps of the
        policy's parameters: the cancellation in the GP's variance made the cost noise that
        L-BFGS stalls on. At 1e-6 that noise fell below 1e-5
        (``benchmarks/bench_pilco_cost_noise.py --jitters``).
    """

    max_full_points: int = 300
    num_inducing: int = 200
    train_iterations: int = 100
    lengthscale_ratio: float = 100.0
    max_snr: float = 500.0
    penalty_power: int = 30
    noise_floor: float = 1e-4
    fixed_noise_var: float | None = None
    inducing_jitter: float = INDUCING_JITTER

    #: Fields added after runs were saved, with the value those runs had: a config saved
    #: before a field existed reads back as it trained (:meth:`from_dict`).
    LEGACY_VALUES: ClassVar[dict[str, Any]] = {"inducing_jitter": 0.0}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GPSettings:
        """Settings saved by ``dataclasses.asdict``; a field the saved run predates takes the
        value of then (:attr:`GPSettings.LEGACY_VALUES`), so a resumed or reloaded run fits as
        before."""
        return cls(**{**cls.LEGACY_VALUES, **data})

    def __post_init__(self) -> None:
        jitter = self.inducing_jitter
        if isinstance(jitter, bool) or not isinstance(jitter, (int, float)) or not 0 <= jitter < 1:
            raise ValueError(
                f"inducing_jitter: expected a number in [0, 1) (a fraction of the signal "
                f"variance), found {jitter!r}"
            )
        value = self.fixed_noise_var
        if value is not None and (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not 0.0 < value < math.inf
        ):
            raise ValueError(
                f"fixed_noise_var: expected None or a positive finite number, found {value!r}"
            )


class GPHyper(NamedTuple):
    """Log hyperparameters of the E independent GPs (unconstrained)."""

    log_lengthscales: Tensor  # (E, D)
    log_signal: Tensor  # (E,)  log alpha
    log_noise: Tensor  # (E,)  log sigma (above the floor)


class GPPosterior(NamedTuple):
    """What prediction and moment matching need (all float64 tensors, no grad).

    ``m_a(x) = sum_i beta[a, i] k_a(x, support_i)``;
    ``v_a(x) = alpha_a^2 - k_a(x, Z)^T inv_k[a] k_a(x, Z)``.
    """

    support: Tensor  # (M, D)
    beta: Tensor  # (E, M)
    inv_k: Tensor  # (E, M, M)
    log_lengthscales: Tensor  # (E, D)
    log_signal: Tensor  # (E,)
    noise_var: Tensor  # (E,)  floor + exp(2 log_noise)
    log_noise: Tensor  # (E,)  for warm starts
    sparse: bool
    pair_weights: Tensor  # (P, M, M) beta_a beta_b^T - delta_ab inv_k[a], pairs a <= b

    @property
    def hyper(self) -> GPHyper:
        """The hyperparameters, e.g. to warm-start the next fit."""
        return GPHyper(self.log_lengthscales, self.log_signal, self.log_noise)


def se_kernel(x1: Tensor, x2: Tensor, log_lengthscales: Tensor, log_signal: Tensor) -> Tensor:
    """Squared-exponential ARD kernel for every output.

    Shapes: ``x1`` (N, D), ``x2`` (M, D), ``log_lengthscales`` (E, D), ``log_signal`` (E,)
    -> (E, N, M).
    """
    num_rows, num_cols, dim = x1.shape[0], x2.shape[0], x1.shape[1]
    # Squared distances by differences (not the |a|^2 + |b|^2 - 2ab expansion): exact to
    # round-off and never negative. The squared differences (N M, D) do not depend on the
    # output, so one matmul with the E inverse squared length-scales weighs them for every
    # output at once; autograd keeps only them (a constant), never an (E, N, M, D) tensor.
    diff_sq = (x1[:, None, :] - x2[None, :, :]).square().reshape(num_rows * num_cols, dim)
    sq = (torch.exp(-2.0 * log_lengthscales) @ diff_sq.T).reshape(-1, num_rows, num_cols)
    return torch.exp(2.0 * log_signal[:, None, None] - 0.5 * sq)


def _noise_var(hyper: GPHyper, floor_var: Tensor) -> Tensor:
    # Noise floor: sigma^2 = floor^2 + exp(2 log sigma) can never reach 0 (noise-free simulator
    # data would otherwise drive it there and make K + sigma^2 I singular).
    return floor_var + torch.exp(2.0 * hyper.log_noise)


def _penalty(hyper: GPHyper, log_input_std: Tensor, settings: GPSettings) -> Tensor:
    """PILCO's smooth hyperparameter barrier: ~0 inside the bounds, steep outside.

    .. math::

        \\sum_{a,d} \\Big(\\frac{\\log \\ell_{ad} - \\log s_d}{\\log \\rho}\\Big)^p
        + \\sum_a \\Big(\\frac{\\log \\alpha_a - \\log \\sigma_a}{\\log \\mathrm{SNR}_{max}}\\Big)^p
    """
    power = settings.penalty_power
    ls_term = (hyper.log_lengthscales - log_input_std) / math.log(settings.lengthscale_ratio)
    snr_term = (hyper.log_signal - hyper.log_noise) / math.log(settings.max_snr)
    return ls_term.pow(power).sum() + snr_term.pow(power).sum()


def exact_nll(hyper: GPHyper, inputs: Tensor, targets: Tensor, floor_var: Tensor) -> Tensor:
    """Negative log marginal likelihood of the exact GPs, summed over outputs.

    .. math::

        -\\log p(y_a) = \\tfrac12 y_a^\\top (K_a + \\sigma_a^2 I)^{-1} y_a
        + \\tfrac12 \\log|K_a + \\sigma_a^2 I| + \\tfrac N2 \\log 2\\pi

    Shapes: ``inputs`` (N, D), ``targets`` (N, E).
    """
    num = inputs.shape[0]
    gram = se_kernel(inputs, inputs, hyper.log_lengthscales, hyper.log_signal)
    eye = torch.eye(num, dtype=inputs.dtype)
    chol = cholesky_jitter(gram + _noise_var(hyper, floor_var)[:, None, None] * eye, "K + s2 I")
    alpha = torch.cholesky_solve(targets.T[:, :, None], chol)[..., 0]  # (E, N)
    log_det = log_det_cholesky(chol)
    return (0.5 * (targets.T * alpha).sum(-1) + 0.5 * log_det + 0.5 * num * LOG_2PI).sum()


class _FitcTerms(NamedTuple):
    chol_mm: Tensor  # (E, M, M) Cholesky of K_mm
    v: Tensor  # (E, M, N) L_mm^-1 K_mn
    gamma: Tensor  # (E, N) diag(K_nn - Q_nn) + sigma^2
    chol_a: Tensor  # (E, M, M) Cholesky of A = I + V Gamma^-1 V^T


def _fitc_terms(
    hyper: GPHyper, inputs: Tensor, inducing: Tensor, floor_var: Tensor, jitter: float
) -> _FitcTerms:
    k_mm = se_kernel(inducing, inducing, hyper.log_lengthscales, hyper.log_signal)
    eye = torch.eye(inducing.shape[0], dtype=inputs.dtype)
    k_mm = k_mm + (jitter * torch.exp(2.0 * hyper.log_signal))[:, None, None] * eye
    k_mn = se_kernel(inducing, inputs, hyper.log_lengthscales, hyper.log_signal)
    chol_mm = cholesky_jitter(k_mm, "K_mm")
    v = torch.linalg.solve_triangular(chol_mm, k_mn, upper=False)
    # FITC keeps the exact prior variance on the diagonal: Gamma = diag(K_nn - Q_nn) + sigma^2,
    # with diag(K_nn) = alpha^2 and Q_nn = V^T V. The clamp guards round-off (K_nn >= Q_nn).
    diag_gap = (torch.exp(2.0 * hyper.log_signal)[:, None] - v.square().sum(1)).clamp(min=0.0)
    gamma = diag_gap + _noise_var(hyper, floor_var)[:, None]
    chol_a = cholesky_jitter(eye + (v / gamma[:, None, :]) @ v.transpose(-1, -2), "FITC A")
    return _FitcTerms(chol_mm, v, gamma, chol_a)


def fitc_nll(
    hyper: GPHyper,
    inputs: Tensor,
    targets: Tensor,
    inducing: Tensor,
    floor_var: Tensor,
    jitter: float = INDUCING_JITTER,
) -> Tensor:
    """Negative log marginal likelihood of FITC, ``y ~ N(0, Q_nn + Gamma)``, summed over outputs.

    By the matrix determinant lemma and Woodbury, with ``A = I + V Gamma^-1 V^T``:
    ``log|Q + Gamma| = log|Gamma| + log|A|`` and
    ``y^T (Q + Gamma)^-1 y = y^T Gamma^-1 y - |L_A^-1 V Gamma^-1 y|^2`` (cost O(N M^2)).
    ``Q_nn = K_nm K_mm^-1 K_mn`` with ``K_mm`` carrying ``jitter * alpha^2`` on its diagonal
    (:class:`GPSettings`, ``inducing_jitter``).

    Shapes: ``inputs`` (N, D), ``targets`` (N, E), ``inducing`` (M, D).
    """
    terms = _fitc_terms(hyper, inputs, inducing, floor_var, jitter)
    y = targets.T  # (E, N)
    weighted = terms.v @ (y / terms.gamma)[..., None]  # (E, M, 1)
    proj = torch.linalg.solve_triangular(terms.chol_a, weighted, upper=False)[..., 0]
    quad = (y.square() / terms.gamma).sum(-1) - proj.square().sum(-1)
    log_det = torch.log(terms.gamma).sum(-1) + log_det_cholesky(terms.chol_a)
    return (0.5 * quad + 0.5 * log_det + 0.5 * inputs.shape[0] * LOG_2PI).sum()


def select_inducing(inputs: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """Choose ``count`` inducing inputs among the data by k-means++ seeding (D^2 sampling).

    Each next point is drawn with probability proportional to its squared distance (inputs
    scaled by their standard deviation) to the nearest point already chosen, which spreads the
    inducing inputs over the visited region.

    Shapes: ``inputs`` (N, D) -> (count, D).
    """
    scaled = inputs / np.maximum(inputs.std(axis=0), MIN_INPUT_STD)
    chosen = [int(rng.integers(len(inputs)))]
    nearest = np.sum((scaled - scaled[chosen[0]]) ** 2, axis=1)
    for _ in range(count - 1):
        total = nearest.sum()
        if total <= 0.0:
            break
        index = int(rng.choice(len(inputs), p=nearest / total))
        chosen.append(index)
        nearest = np.minimum(nearest, np.sum((scaled - scaled[index]) ** 2, axis=1))
    return inputs[np.asarray(chosen)]


def initial_hyper(inputs: Tensor, targets: Tensor) -> GPHyper:
    """Start from the data's spread: l = std(inputs), alpha = std(targets), sigma = alpha / 10."""
    input_std = inputs.std(0).clamp(min=MIN_INPUT_STD)
    target_std = targets.std(0).clamp(min=MIN_INPUT_STD)
    num_outputs = targets.shape[1]
    return GPHyper(
        torch.log(input_std).expand(num_outputs, -1).clone(),
        torch.log(target_std).clone(),
        torch.log(target_std / 10.0).clone(),
    )


def _optimise_hyper(objective, hyper: GPHyper, iterations: int) -> GPHyper:
    params = [p.clone().requires_grad_(True) for p in hyper]
    optimiser = torch.optim.LBFGS(
        params, max_iter=iterations, line_search_fn="strong_wolfe", tolerance_grad=1e-9
    )

    def closure() -> Tensor:
        optimiser.zero_grad()
        loss = objective(GPHyper(*params))
        loss.backward()
        return loss

    optimiser.step(closure)
    return GPHyper(*(p.detach() for p in params))


class _TrainingData(NamedTuple):
    """The GP's data as float64 tensors: ``inputs`` (N, D), ``targets`` (N, E)."""

    inputs: Tensor
    targets: Tensor


def _training_data(inputs: Tensor | np.ndarray, targets: Tensor | np.ndarray) -> _TrainingData:
    """``inputs`` and ``targets`` as float64 tensors, checked to be (N, D) and (N, E)."""
    x = torch.as_tensor(inputs, dtype=DTYPE)
    y = torch.as_tensor(targets, dtype=DTYPE)
    if x.ndim != 2 or y.ndim != 2 or x.shape[0] != y.shape[0]:
        raise ValueError(
            f"inputs, targets: expected (N, D) and (N, E), found {tuple(x.shape)}, {tuple(y.shape)}"
        )
    return _TrainingData(x, y)


class _NoiseModel(NamedTuple):
    """How the noise enters the fit: ``floor_var`` (E,), the variance below which sigma^2 never
    falls (squared target units), and ``fixed_log_noise`` (E,), the log sigma used in place of
    the fitted one (None: fitted)."""

    floor_var: Tensor
    fixed_log_noise: Tensor | None


def _noise_model(targets: Tensor, settings: GPSettings) -> _NoiseModel:
    """The noise floor of ``settings`` relative to each target's spread, or a fixed noise.

    Shapes: ``targets`` (N, E).
    """
    floor_var = (settings.noise_floor * targets.std(0).clamp(min=MIN_INPUT_STD)) ** 2
    if settings.fixed_noise_var is None:
        return _NoiseModel(floor_var, None)
    # A fixed noise: no floor, and log sigma a constant that the objective of fit_gp uses in
    # place of the optimised one (whose gradient is then zero, so L-BFGS never moves it).
    log_noise = 0.5 * math.log(settings.fixed_noise_var)
    fixed_log_noise = torch.full((targets.shape[1],), log_noise, dtype=DTYPE)
    return _NoiseModel(torch.zeros_like(floor_var), fixed_log_noise)


def _inducing_inputs(
    inputs: Tensor, settings: GPSettings, rng: np.random.Generator | None
) -> Tensor | None:
    """FITC's inducing inputs (M, D) beyond ``settings.max_full_points`` data (chosen by
    :func:`select_inducing` with ``rng``, default seed 0); None for the exact GP."""
    if inputs.shape[0] <= settings.max_full_points:
        return None
    rng = rng if rng is not None else np.random.default_rng(0)
    return torch.as_tensor(select_inducing(inputs.numpy(), settings.num_inducing, rng), dtype=DTYPE)


def fit_gp(
    inputs: Tensor | np.ndarray,
    targets: Tensor | np.ndarray,
    settings: GPSettings | None = None,
    rng: np.random.Generator | None = None,
    init: GPHyper | None = None,
) -> GPPosterior:
    """Fit the E dynamics GPs by type-II maximum likelihood (L-BFGS, float64).

    Parameters
    ----------
    inputs : (N, D) array
        GP inputs (observation with angles as cos/sin, then action).
    targets : (N, E) array
        State differences to predict.
    settings : GPSettings, optional
    rng : numpy.random.Generator, optional
        Chooses the FITC inducing inputs (only used beyond ``max_full_points`` data).
    init : GPHyper, optional
        Warm start (e.g. the previous iteration's hyperparameters); default from the data.

    Returns
    -------
    GPPosterior
    """
    settings = settings or GPSettings()
    x, y = _training_data(inputs, targets)
    floor_var, fixed_log_noise = _noise_model(y, settings)
    log_input_std = torch.log(x.std(0).clamp(min=MIN_INPUT_STD))
    inducing = _inducing_inputs(x, settings, rng)

    def objective(hyper: GPHyper) -> Tensor:
        hyper = _with_noise(hyper, fixed_log_noise)
        if inducing is None:
            nll = exact_nll(hyper, x, y, floor_var)
        else:
            nll = fitc_nll(hyper, x, y, inducing, floor_var, settings.inducing_jitter)
        return nll + _penalty(hyper, log_input_std, settings)

    hyper = _optimise_hyper(objective, init or initial_hyper(x, y), settings.train_iterations)
    if not all(bool(torch.isfinite(p).all()) for p in hyper):
        hyper = initial_hyper(x, y)  # a diverged line search: fall back to the data's spread
    hyper = _with_noise(hyper, fixed_log_noise)
    return posterior(hyper, x, y, floor_var, inducing, settings.inducing_jitter)


def _with_noise(hyper: GPHyper, log_noise: Tensor | None) -> GPHyper:
    """``hyper`` with its log noise replaced by ``log_noise`` (None: unchanged)."""
    return hyper if log_noise is None else hyper._replace(log_noise=log_noise)


@functools.cache
def pair_indices(num_outputs: int) -> tuple[Tensor, Tensor, Tensor]:
    """Output pairs ``a <= b`` (P = E (E + 1) / 2 of them): Q_ba = Q_ab^T, so half suffices.

    Returns ``first`` (P,), ``second`` (P,) and ``pair_of`` (E, E), the index of the pair
    ``(min(a, b), max(a, b))``, which spreads P pair values over a symmetric (E, E) matrix in
    one gather. Cached per E (constant tensors, never written to).
    """
    first, second = torch.triu_indices(num_outputs, num_outputs)
    pair_of = torch.empty(num_outputs, num_outputs, dtype=torch.long)
    pair_of[first, second] = torch.arange(first.shape[0])
    pair_of[second, first] = torch.arange(first.shape[0])
    return first, second, pair_of


def pair_weights(beta: Tensor, inv_k: Tensor | None = None) -> Tensor:
    r"""Weights :math:`\beta_a \beta_b^\top - \delta_{ab} \Xi_a` (P, M, M) of the pairs ``a <= b``.

    With them one elementwise contraction per pair gives both :math:`\beta_a^\top Q_{ab} \beta_b`
    and, for ``a = b``, the :math:`-\operatorname{tr}(\Xi_a Q_{aa})` of the GP variance
    (:math:`\Xi_a` is symmetric, so the trace is the elementwise sum). They do not depend on
    the input distribution, so a GP computes them once per model.

    Shapes: ``beta`` (E, M), ``inv_k`` (E, M, M) -> (P, M, M).
    """
    first, second, _ = pair_indices(beta.shape[0])
    weights = beta[first][:, :, None] * beta[second][:, None, :]
    if inv_k is not None:
        same = (first == second).to(beta.dtype)[:, None, None]
        weights = weights - same * inv_k[first]
    return weights


def posterior(
    hyper: GPHyper,
    inputs: Tensor,
    targets: Tensor,
    floor_var: Tensor,
    inducing: Tensor | None,
    jitter: float = INDUCING_JITTER,
) -> GPPosterior:
    """Build the :class:`GPPosterior` (beta, Xi) of given hyperparameters (no gradients);
    ``jitter`` is FITC's ``inducing_jitter`` (:class:`GPSettings`)."""
    with torch.no_grad():
        noise_var = _noise_var(hyper, floor_var)
        if inducing is None:
            gram = se_kernel(inputs, inputs, hyper.log_lengthscales, hyper.log_signal)
            eye = torch.eye(inputs.shape[0], dtype=DTYPE)
            chol = cholesky_jitter(gram + noise_var[:, None, None] * eye, "K + s2 I")
            beta = torch.cholesky_solve(targets.T[:, :, None], chol)[..., 0]
            inv_k = torch.cholesky_inverse(chol)
            return GPPosterior(
                inputs,
                beta,
                inv_k,
                hyper.log_lengthscales,
                hyper.log_signal,
                noise_var,
                hyper.log_noise,
                False,
                pair_weights(beta, inv_k),
            )
        terms = _fitc_terms(hyper, inputs, inducing, floor_var, jitter)
        # With K_mm = L L^T: K_mm + K_mn Gamma^-1 K_nm = L A L^T, hence
        # beta = L^-T A^-1 V Gamma^-1 y and Xi = L^-T (I - A^-1) L^-1.
        weighted = terms.v @ (targets.T / terms.gamma)[..., None]
        a_inv_w = torch.cholesky_solve(weighted, terms.chol_a)
        beta = torch.linalg.solve_triangular(terms.chol_mm.transpose(-1, -2), a_inv_w, upper=True)[
            ..., 0
        ]
        eye = torch.eye(inducing.shape[0], dtype=DTYPE)
        middle = eye - torch.cholesky_inverse(terms.chol_a)
        l_inv = torch.linalg.solve_triangular(terms.chol_mm, eye.expand_as(middle), upper=False)
        inv_k = l_inv.transpose(-1, -2) @ middle @ l_inv
        inv_k = symmetrise(inv_k)  # remove the round-off asymmetry of the triple product
        return GPPosterior(
            inducing,
            beta,
            inv_k,
            hyper.log_lengthscales,
            hyper.log_signal,
            noise_var,
            hyper.log_noise,
            True,
            pair_weights(beta, inv_k),
        )


PREDICT_CHUNK = 1024  # inputs per kernel block in gp_predict (bounds the (B M, D) memory)


def gp_predict(post: GPPosterior, x: Tensor) -> tuple[Tensor, Tensor]:
    """Predictive mean and latent variance at deterministic inputs.

    Shapes: ``x`` (B, D) -> mean (B, E), variance (B, E). Evaluated in blocks of
    ``PREDICT_CHUNK`` inputs.
    """
    means, variances = [], []
    for block in torch.split(x, PREDICT_CHUNK):
        k = se_kernel(block, post.support, post.log_lengthscales, post.log_signal)  # (E, B, M)
        means.append((k * post.beta[:, None, :]).sum(-1).T)
        var = torch.exp(2.0 * post.log_signal)[:, None] - ((k @ post.inv_k) * k).sum(-1)
        variances.append(var.T)
    return torch.cat(means), torch.cat(variances)
