r"""Affine state-feedback controller :math:`G(x) = W x + b`.

Letters: D observation dimension, F action dimension.

The gain acts on the policy's input, the observation, so :math:`G` is linear in the
observation (for an angle the gain multiplies :math:`\sin\theta`) and :math:`b` is chosen so that
:math:`G(a) = u_{eq}` at the operating point :math:`a`. For an LQR design
:math:`u - u_{eq} = -K (x - a)` this means :math:`W = -K` and :math:`b = u_{eq} + K a`.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from ._checks import as_float_tensor, check_finite, check_last_dim, check_shape

__all__ = ["LinearController"]


class LinearController(nn.Module):
    r"""Affine controller :math:`G(x) = W x + b` with fixed gains.

    .. math::

        G(x) = W x + b, \qquad W \in \mathbb{R}^{F \times D},\; b \in \mathbb{R}^{F}

    Shapes: input (..., D), output (..., F).

    Parameters
    ----------
    W : array-like
        Gain matrix, shape (F, D). Stored as the (non-trainable) buffer ``W``.
    b : array-like, optional
        Bias, shape (F,). Defaults to zeros. Stored as the buffer ``b``.
    dtype : torch.dtype
        Floating dtype of the buffers (float64 by default).

    Raises
    ------
    TypeError
        If ``W`` or ``b`` is not array-like of numbers.
    ValueError
        If ``W`` is not 2-D, ``b`` is not of shape (F,), or either is not finite.

    References
    ----------
    Zhang & Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
    Classical Control Theory", L4DC 2021, eq. 1.
    """

    W: Tensor
    b: Tensor

    def __init__(self, W: object, b: object | None = None, dtype: torch.dtype = torch.float64):
        super().__init__()
        gain = as_float_tensor(W, "W", dtype)
        if gain.dim() != 2:
            raise ValueError(
                f"W must have shape (F, D) (2-D), found {tuple(gain.shape)} ({gain.dim()}-D)"
            )
        check_finite(gain, "W")
        act_dim = gain.shape[0]
        if b is None:
            bias = torch.zeros(act_dim, dtype=dtype, device=gain.device)
        else:
            bias = as_float_tensor(b, "b", dtype).to(gain.device)
            check_shape(bias, "b", (act_dim,), "(F,)")
            check_finite(bias, "b")
        self.register_buffer("W", gain)
        self.register_buffer("b", bias)

    @property
    def obs_dim(self) -> int:
        """Observation dimension D."""
        return int(self.W.shape[1])

    @property
    def act_dim(self) -> int:
        """Action dimension F."""
        return int(self.W.shape[0])

    def forward(self, x: Tensor) -> Tensor:
        r"""Evaluate :math:`G(x) = W x + b`.

        Shapes: ``x`` (..., D) -> (..., F).
        """
        check_last_dim(x, self.obs_dim, self.W.dtype)
        return x @ self.W.T + self.b

    def extra_repr(self) -> str:
        return f"obs_dim={self.obs_dim}, act_dim={self.act_dim}"
