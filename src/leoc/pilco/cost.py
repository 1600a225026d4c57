r"""PILCO's saturating cost and its exact expectation under a Gaussian.

Letters: O dimension of the costed vector (the observation), K rows of the cost factor.

.. math::

    c(x) = 1 - \exp\big(-\tfrac12 (x - t)^\top W (x - t)\big), \qquad W = F^\top F \succeq 0,

with target t. The cost is written through a factor F (K, O) so that a singular W (weights
that ignore some entries) needs no special case. For :math:`x \sim \mathcal N(\mu, \Sigma)`
(Deisenroth 2010, eq. 3.45), with the SPD :math:`B = I_K + F \Sigma F^\top` and
:math:`e = F (\mu - t)`,

.. math::

    E[c(x)] = 1 - |B|^{-1/2} \exp\big(-\tfrac12 e^\top B^{-1} e\big),

which equals the usual :math:`1 - |I + \Sigma W|^{-1/2} \exp(-\tfrac12 (\mu - t)^\top W
(I + \Sigma W)^{-1} (\mu - t))` by Sylvester's determinant identity and Woodbury; B has
eigenvalues >= 1, so its Cholesky factor is always well conditioned.
"""

from __future__ import annotations

import torch
from torch import Tensor

from leoc.linalg import cholesky_jitter


def saturating_cost(x: Tensor, target: Tensor, factor: Tensor) -> Tensor:
    """Saturating cost of deterministic points. Shapes: ``x`` (..., O) -> (...)."""
    scaled = (x - target) @ factor.T  # (..., K)
    return 1.0 - torch.exp(-0.5 * scaled.square().sum(-1))


def expected_saturating_cost(mean: Tensor, cov: Tensor, target: Tensor, factor: Tensor) -> Tensor:
    """Exact expected saturating cost for ``x ~ N(mean, cov)`` (see the module docstring).

    Shapes: ``mean`` (O,), ``cov`` (O, O), ``target`` (O,), ``factor`` (K, O) -> scalar.
    """
    error = factor @ (mean - target)
    b_mat = torch.eye(factor.shape[0], dtype=mean.dtype) + factor @ cov @ factor.T
    chol = cholesky_jitter(0.5 * (b_mat + b_mat.T), "I + F S F^T")
    whitened = torch.linalg.solve_triangular(chol, error[:, None], upper=False)[:, 0]
    log_det_half = torch.log(chol.diagonal()).sum()
    return 1.0 - torch.exp(-0.5 * whitened.square().sum() - log_det_half)
