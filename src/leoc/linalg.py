r"""Low-level linear algebra shared by the GP model and moment matching (imports only torch).

Letters: B batch, K rank of a bilinear form, M rows/columns of the matrices it generates.

- :func:`cholesky_jitter`: Cholesky factor with escalating jitter, :class:`CholeskyError`;
- :func:`symmetrise`: remove the round-off asymmetry of products like :math:`W S W^\top`;
- :func:`log_det_cholesky`: :math:`\log|A|` from a Cholesky factor of A;
- :func:`weighted_exp_bilinear`: :math:`v_b = \sum_{ij} W_{bij} \exp((L_b R_b^\top)_{ij} + a_{bi}
  + c_{bj})`, the inner loop of exact moment matching of sums of squared-exponential bumps,
  evaluated in row blocks with its gradient formed in the same pass (:class:`WeightedExpBilinear`).
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


def _block_rows(batch: int, rows: int, columns: int) -> int:
    """Rows per block so that a (batch, rows, columns) block holds at most about BLOCK_ENTRIES,
    the blocks of equal size (no short last block costing a full round of small ops)."""
    most = max(1, BLOCK_ENTRIES // max(1, batch * columns))
    return -(-rows // -(-rows // most)) if rows > 0 else most


def _exp_block(left: Tensor, right_t: Tensor, weights: Tensor) -> Tensor:
    """``weights * exp(left @ right_t)`` for one row block, computed in place (one buffer)."""
    return torch.bmm(left, right_t).exp_().mul_(weights)


class _BlockwiseResult(NamedTuple):
    value: Tensor  # (B,)
    grad_left: Tensor | None  # (B, M, K + 1) [dv/dL, dv/da]
    grad_right: Tensor | None  # (B, N, K + 1) [dv/dc, dv/dR]


def _extend(
    left: Tensor, right: Tensor, row_offset: Tensor | None, col_offset: Tensor | None
) -> tuple[Tensor, Tensor]:
    r"""``[1, L, a]`` and ``[c, R, 1]`` (zero offsets if None): their bilinear form is
    :math:`L R^\top + a 1^\top + 1 c^\top`, and the gradients need only the suffix ``[R, 1]``
    and the prefix ``[1, L]``, contiguous column ranges (the product of the offsets' own ones
    columns would be unused work)."""
    batch, rows, _ = left.shape
    columns = right.shape[1]
    if row_offset is None:
        row_offset = left.new_zeros(batch, rows)
    if col_offset is None:
        col_offset = right.new_zeros(batch, columns)
    ones_rows = left.new_ones(batch, rows, 1)
    ones_columns = right.new_ones(batch, columns, 1)
    left_ext = torch.cat([ones_rows, left, row_offset[..., None]], dim=-1)
    right_ext = torch.cat([col_offset[..., None], right, ones_columns], dim=-1)
    return left_ext, right_ext


def _blockwise(
    left_ext: Tensor, right_ext: Tensor, weights: Tensor, gradients: bool
) -> _BlockwiseResult:
    """Value of :class:`WeightedExpBilinear` from the extended factors of :func:`_extend` and,
    if ``gradients``, ``G [R, 1]`` and ``G^T [1, L]``, one row block of G at a time."""
    batch, rows, rank = left_ext.shape
    step = _block_rows(batch, rows, right_ext.shape[1])
    right_t = right_ext.transpose(-1, -2)
    if not gradients:
        value = left_ext.new_zeros(batch)
        for start in range(0, rows, step):
            block = slice(start, start + step)
            value += _exp_block(left_ext[:, block], right_t, weights[:, block]).sum(dim=(-1, -2))
        return _BlockwiseResult(value, None, None)
    right_grad_t = right_t[:, 1:].contiguous()  # [R, 1]^T
    left_grad = left_ext[..., :-1]  # [1, L]
    # Both gradients are formed transposed, (B, K + 1, M) = [R, 1]^T G^T and (B, K + 1, N) +=
    # [1, L]_block^T G_block: MKL runs these wide products about 1.7 times faster than the
    # tall G [R, 1] (our measurements, M = N = 200, K + 1 = 9).
    grad_left_t = left_ext.new_empty(batch, rank - 1, rows)
    grad_right_t = left_ext.new_zeros(batch, rank - 1, right_ext.shape[1])
    for start in range(0, rows, step):
        block = slice(start, start + step)
        g_block = _exp_block(left_ext[:, block], right_t, weights[:, block])  # (B, rows, N)
        grad_left_t[:, :, block] = torch.bmm(right_grad_t, g_block.transpose(-1, -2))
        grad_right_t.baddbmm_(left_grad[:, block].transpose(-1, -2), g_block)
    # The row sums of G (its product with the ones column) add up to the value: no extra pass.
    value = grad_left_t[:, -1].sum(-1)
    return _BlockwiseResult(value, grad_left_t.transpose(-1, -2), grad_right_t.transpose(-1, -2))


class WeightedExpBilinear(torch.autograd.Function):
    r""":math:`v_b = \sum_{ij} W_{bij} \exp((L_b R_b^\top)_{ij} + a_{bi} + c_{bj})`, with the
    gradient formed in the forward pass.

    With :math:`G_b = W_b \odot \exp(L_b R_b^\top + a_b 1^\top + 1 c_b^\top)` the gradients are
    :math:`\partial v_b / \partial L_b = G_b R_b`, :math:`\partial v_b / \partial a_b = G_b 1`,
    :math:`\partial v_b / \partial R_b = G_b^\top L_b` and
    :math:`\partial v_b / \partial c_b = G_b^\top 1`. They are computed in the forward pass, one
    row block of G at a time, while the block is in cache: the (B, M, N) matrix G is never
    stored, only the two (B, M or N, K + 1) gradients (a horizon of 40 steps with B = 10,
    M = 400 would otherwise keep 0.5 GB of G for the backward pass, or evaluate the
    exponentials twice). The value is the sum of :math:`G_b 1`. The backward pass only scales
    the gradients by the incoming gradient. If ``weights`` needs a gradient (an RBF policy, whose
    M is small), the exponentials are recomputed in the backward pass instead of stored.
    First order only. The offsets a and c may be None (zero).

    Shapes: ``left`` (B, M, K), ``right`` (B, N, K), ``weights`` (B, M, N), ``row_offset``
    (B, M), ``col_offset`` (B, N) -> (B,).
    """

    @staticmethod
    def forward(
        ctx,
        left: Tensor,
        right: Tensor,
        weights: Tensor,
        row_offset: Tensor | None = None,
        col_offset: Tensor | None = None,
    ) -> Tensor:
        """The value ``(B,)``; saves the extended factors and their gradients for backward."""
        gradients = any(ctx.needs_input_grad[i] for i in (0, 1, 3, 4))
        left_ext, right_ext = _extend(left, right, row_offset, col_offset)
        result = _blockwise(left_ext, right_ext, weights, gradients)
        ctx.save_for_backward(left_ext, right_ext, result.grad_left, result.grad_right)
        return result.value

    @staticmethod
    def backward(ctx, grad: Tensor):
        """Gradients of the five inputs from the saved factors (None where none is needed)."""
        left_ext, right_ext, grad_ext_left, grad_ext_right = ctx.saved_tensors
        scale = grad[:, None, None]
        grads = [None] * 5  # left, right, weights, row_offset, col_offset
        if grad_ext_left is not None:
            scaled_left = grad_ext_left * scale  # [dv/dL, dv/da]
            scaled_right = grad_ext_right * scale  # [dv/dc, dv/dR]
            grads[0], grads[3] = scaled_left[..., :-1], scaled_left[..., -1]
            grads[4], grads[1] = scaled_right[..., 0], scaled_right[..., 1:]
        if ctx.needs_input_grad[2]:
            grads[2] = torch.exp(left_ext @ right_ext.transpose(-1, -2)) * scale
        # One entry per input given (the offsets may be left out), None where none is needed.
        needs = ctx.needs_input_grad
        return tuple(g if need else None for g, need in zip(grads, needs, strict=False))


def weighted_exp_bilinear(
    left: Tensor,
    right: Tensor,
    weights: Tensor,
    row_offset: Tensor | None = None,
    col_offset: Tensor | None = None,
) -> Tensor:
    r""":math:`v_b = \sum_{ij} W_{bij} \exp((L_b R_b^\top)_{ij} + a_{bi} + c_{bj})`,
    differentiable (offsets a = ``row_offset``, c = ``col_offset``; None means zero).

    Goes through :class:`WeightedExpBilinear` only when a gradient can be asked for and W is
    larger than one row block; a smaller problem (the RBF policy's) is left to autograd, whose
    graph of a few ops costs less than the Function's Python overhead and stores at most one
    block of exponentials. Without gradients (``torch.no_grad`` or constant inputs) the value
    alone is evaluated, in row blocks.

    Shapes: ``left`` (B, M, K), ``right`` (B, N, K), ``weights`` (B, M, N), ``row_offset``
    (B, M), ``col_offset`` (B, N) -> (B,).
    """
    inputs = (left, right, weights, row_offset, col_offset)
    if torch.is_grad_enabled() and any(t is not None and t.requires_grad for t in inputs):
        if weights.numel() > BLOCK_ENTRIES:
            return WeightedExpBilinear.apply(*inputs)
        exponent = left @ right.transpose(-1, -2)
        if row_offset is not None:
            exponent = exponent + row_offset[..., None]
        if col_offset is not None:
            exponent = exponent + col_offset[..., None, :]
        return (weights * exponent.exp()).sum((-1, -2))
    left_ext, right_ext = _extend(left, right, row_offset, col_offset)
    return _blockwise(left_ext, right_ext, weights, gradients=False).value
