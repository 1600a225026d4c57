r"""Low-level linear algebra shared by the GP model and moment matching (imports only torch).

Letters: B batch, K rank of a bilinear form, M rows/columns of the matrices it generates.

- :func:`cholesky_jitter`: Cholesky factor with escalating jitter, :class:`CholeskyError`;
- :func:`symmetrise`: remove the round-off asymmetry of products like :math:`W S W^\top`;
- :func:`log_det_cholesky`: :math:`\log|A|` from a Cholesky factor of A;
- :func:`weighted_exp_bilinear`: :math:`v_b = \sum_{ij} W_{bij} \exp((L_b R_b^\top)_{ij})`, the
  inner loop of exact moment matching of sums of squared-exponential bumps, evaluated in row
  blocks with its gradient formed in the same pass (:class:`WeightedExpBilinear`).
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

# Cholesky with escalating jitter: start at JITTER_START * mean(diag), multiply by JITTER_GROWTH
# until JITTER_MAX * mean(diag) (a larger jitter would change the model, so we stop and raise).
JITTER_START = 1e-10
JITTER_GROWTH = 10.0
JITTER_MAX = 1e-3
# Smallest diagonal scale for the jitter (an all-zero matrix would otherwise get no jitter).
MIN_JITTER_SCALE = 1e-300
# Row blocks of weighted_exp_bilinear hold at most this many entries (B x rows x M doubles):
# 2^17 doubles = 1 MiB, so a block and its weights stay in the core's cache between the
# matmul, the exp, the weighting and the two gradient matmuls that read it.
BLOCK_ENTRIES = 2**17


class CholeskyError(RuntimeError):
    """Raised when a covariance stays numerically indefinite even with the largest jitter."""


def symmetrise(matrix: Tensor) -> Tensor:
    """(A + A^T) / 2: removes the round-off asymmetry that products like W S W^T accumulate."""
    return 0.5 * (matrix + matrix.transpose(-1, -2))


def cholesky_jitter(matrix: Tensor, name: str = "matrix") -> Tensor:
    """Lower Cholesky factor of a (batch of) symmetric matrix, adding jitter only if needed.

    Tries ``matrix`` first, then ``matrix + eps I`` with ``eps = JITTER_START * mean(diag)``
    growing by ``JITTER_GROWTH`` up to ``JITTER_MAX * mean(diag)``; the jitter is a constant, so
    gradients flow through ``matrix`` unchanged. The same jitter is added to every matrix of a
    batch (only when at least one of them fails).

    Shapes: ``matrix`` (..., K, K) -> (..., K, K).

    Raises
    ------
    CholeskyError
        If the matrix is still not positive definite at the largest jitter (or not finite).
    """
    factor, info = torch.linalg.cholesky_ex(matrix)
    if not bool((info != 0).any()):
        return factor
    scale = (
        matrix.diagonal(dim1=-2, dim2=-1).mean(dim=-1).detach().abs().clamp(min=MIN_JITTER_SCALE)
    )
    eye = torch.eye(matrix.shape[-1], dtype=matrix.dtype, device=matrix.device)
    jitter = JITTER_START
    while jitter <= JITTER_MAX:
        shifted = matrix + (jitter * scale)[..., None, None] * eye
        factor, info = torch.linalg.cholesky_ex(shifted)
        if not bool((info != 0).any()):
            return factor
        jitter *= JITTER_GROWTH
    raise CholeskyError(
        f"{name}: Cholesky failed even with jitter {JITTER_MAX:g} * mean(diag); the matrix of "
        f"shape {tuple(matrix.shape)} is indefinite or not finite "
        f"(finite: {bool(torch.isfinite(matrix).all())}). Check the data for duplicates with "
        "conflicting targets or NaNs, or raise the noise floor."
    )


def log_det_cholesky(factor: Tensor) -> Tensor:
    """:math:`\\log|A| = 2 \\sum_i \\log L_{ii}` for ``A = L L^T``. Shapes: (..., K, K) -> (...)."""
    return 2.0 * torch.log(factor.diagonal(dim1=-2, dim2=-1)).sum(-1)


def _block_rows(batch: int, columns: int) -> int:
    """Rows per block so that a (batch, rows, columns) block holds about BLOCK_ENTRIES."""
    return max(1, BLOCK_ENTRIES // max(1, batch * columns))


def _exp_block(left: Tensor, right_t: Tensor, weights: Tensor) -> Tensor:
    """``weights * exp(left @ right_t)`` for one row block, computed in place (one buffer)."""
    return torch.bmm(left, right_t).exp_().mul_(weights)


class _BlockwiseResult(NamedTuple):
    value: Tensor  # (B,)
    grad_left: Tensor | None  # (B, M, K) dv/dL
    grad_right: Tensor | None  # (B, N, K) dv/dR


def _blockwise(left: Tensor, right: Tensor, weights: Tensor, gradients: bool) -> _BlockwiseResult:
    """Value of :class:`WeightedExpBilinear` and, if ``gradients``, dv/dL and dv/dR, one row
    block of G at a time."""
    batch, rows, rank = left.shape
    step = _block_rows(batch, right.shape[1])
    right_t = right.transpose(-1, -2)
    value = left.new_zeros(batch)
    grad_left, grad_right_t = None, None
    if gradients:
        grad_left = torch.empty_like(left)
        # dv/dR accumulated transposed, (B, K, N) += L_block^T G_block: both operands in their
        # natural layout, faster in our measurements than G_block^T L_block into (B, N, K).
        grad_right_t = left.new_zeros(batch, rank, right.shape[1])
    for start in range(0, rows, step):
        block = slice(start, start + step)
        g_block = _exp_block(left[:, block], right_t, weights[:, block])  # (B, rows, N)
        value += g_block.sum(dim=(-1, -2))
        if gradients:
            grad_left[:, block] = torch.bmm(g_block, right)
            grad_right_t.baddbmm_(left[:, block].transpose(-1, -2), g_block)
    grad_right = None if grad_right_t is None else grad_right_t.transpose(-1, -2)
    return _BlockwiseResult(value, grad_left, grad_right)


class WeightedExpBilinear(torch.autograd.Function):
    r""":math:`v_b = \sum_{ij} W_{bij} \exp((L_b R_b^\top)_{ij})`, with the gradient formed in
    the forward pass.

    With :math:`G_b = W_b \odot \exp(L_b R_b^\top)` the gradients are
    :math:`\partial v_b / \partial L_b = G_b R_b` and :math:`\partial v_b / \partial R_b =
    G_b^\top L_b`. Both are computed in the forward pass, one row block of G at a time, while the
    block is in cache: the (B, M, M) matrix G is never stored, only the two (B, M, K) gradients
    (a horizon of 40 steps with B = 10, M = 400 would otherwise keep 0.5 GB of G for the
    backward pass, or evaluate the exponentials twice). The backward pass only scales them by
    the incoming gradient. If ``weights`` needs a gradient (the RBF policy, whose M is small),
    :math:`\exp(L_b R_b^\top)` is recomputed in the backward pass instead of stored. First
    order only.

    Shapes: ``left`` (B, M, K), ``right`` (B, N, K), ``weights`` (B, M, N) -> (B,).
    """

    @staticmethod
    def forward(ctx, left: Tensor, right: Tensor, weights: Tensor) -> Tensor:
        gradients = ctx.needs_input_grad[0] or ctx.needs_input_grad[1]
        result = _blockwise(left, right, weights, gradients)
        ctx.save_for_backward(left, right, result.grad_left, result.grad_right)
        return result.value

    @staticmethod
    def backward(ctx, grad: Tensor):
        left, right, grad_left, grad_right = ctx.saved_tensors
        scale = grad[:, None, None]
        grad_left = None if grad_left is None else grad_left * scale
        grad_right = None if grad_right is None else grad_right * scale
        grad_weights = None
        if ctx.needs_input_grad[2]:
            grad_weights = torch.exp(left @ right.transpose(-1, -2)) * scale
        return grad_left, grad_right, grad_weights


def weighted_exp_bilinear(left: Tensor, right: Tensor, weights: Tensor) -> Tensor:
    r""":math:`v_b = \sum_{ij} W_{bij} \exp((L_b R_b^\top)_{ij})`, differentiable.

    Goes through :class:`WeightedExpBilinear` only when a gradient can be asked for; otherwise
    (``torch.no_grad`` or constant inputs) evaluates the value alone, in row blocks.

    Shapes: ``left`` (B, M, K), ``right`` (B, N, K), ``weights`` (B, M, N) -> (B,).
    """
    if torch.is_grad_enabled() and any(t.requires_grad for t in (left, right, weights)):
        return WeightedExpBilinear.apply(left, right, weights)
    return _blockwise(left, right, weights, gradients=False).value
