r"""PILCO's radial-basis-function controller (Deisenroth & Rasmussen, 2011).

Letters: B batch (any leading shape ...), N basis functions, D observation dimension,
F action dimension.

.. math::

    u_f(x) = \sum_{i=1}^{N} w_{f i}
        \exp\Big(-\tfrac{1}{2} \sum_{d=1}^{D} \frac{(x_d - c_{i d})^2}{\ell_{f d}^2}\Big)

Each action dimension f has its own weights :math:`w_{f\cdot}` and length-scales
:math:`\ell_{f\cdot}`; the centres :math:`c` are shared. This is the posterior mean of a GP with a
squared-exponential kernel (unit signal variance), which is what lets PILCO propagate a Gaussian
state through it in closed form.
"""

from __future__ import annotations

import math
import numbers

import torch
from torch import Tensor, nn

from ._checks import (
    as_float_tensor,
    check_finite,
    check_last_dim,
    check_positive,
    check_positive_int,
    check_shape,
    scalar_or_vector,
    shape_str,
)

__all__ = ["RBFNetwork"]

_HALF = 0.5  # the 1/2 in the squared-exponential exponent


def _nonnegative_float(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a non-negative float, found {type(value).__name__}")
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be non-negative and finite, found {value}")
    return float(value)


class RBFNetwork(nn.Module):
    r"""Sum of Gaussian bumps with shared centres and per-output length-scales.

    .. math::

        u_f(x) = \sum_{i=1}^{N} w_{f i}
            \exp\Big(-\tfrac{1}{2} \sum_{d=1}^{D} (x_d - c_{i d})^2 / \ell_{f d}^2\Big)

    Shapes: input (..., D), output (..., F). Parameters: ``centres`` (N, D), ``weights`` (F, N),
    ``log_lengthscales`` (F, D) (length-scales are kept positive through the log).

    Parameters
    ----------
    obs_dim : int
        Observation dimension D.
    act_dim : int
        Action dimension F.
    num_basis : int
        Number of basis functions N.
    centres : array-like, optional
        Initial centres, shape (N, D). Drawn at random if omitted.
    weights : array-like, optional
        Initial weights, shape (F, N). Drawn at random if omitted.
    lengthscales : float or array-like
        Initial positive length-scales: a scalar, shape (D,) (shared by all outputs) or (F, D).
    generator : torch.Generator, optional
        Source of randomness for the initialisation; torch's global generator if omitted.
        Centres are drawn first, then weights.
    centre_mean : float or array-like, optional
        Mean of the random centres, scalar or shape (D,); zero if omitted.
    centre_std : float
        Standard deviation of the random centres: ``c = centre_mean + centre_std * N(0, 1)``.
    weight_std : float
        Standard deviation of the random weights: ``w = weight_std * N(0, 1)``.
    dtype : torch.dtype
        Floating dtype of the parameters (float64 by default).

    References
    ----------
    M. P. Deisenroth and C. E. Rasmussen, "PILCO: A Model-Based and Data-Efficient Approach to
    Policy Search", ICML 2011.
    """

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        num_basis: int,
        centres: object | None = None,
        weights: object | None = None,
        lengthscales: float | object = 1.0,
        generator: torch.Generator | None = None,
        centre_mean: float | object | None = None,
        centre_std: float = 1.0,
        weight_std: float = 0.1,
        dtype: torch.dtype = torch.float64,
    ):
        super().__init__()
        obs_dim = check_positive_int(obs_dim, "obs_dim")
        act_dim = check_positive_int(act_dim, "act_dim")
        num_basis = check_positive_int(num_basis, "num_basis")
        centre_std = _nonnegative_float(centre_std, "centre_std")
        weight_std = _nonnegative_float(weight_std, "weight_std")
        if generator is not None and not isinstance(generator, torch.Generator):
            raise TypeError(
                f"generator must be a torch.Generator or None, found {type(generator).__name__}"
            )

        if centres is None:
            mean = torch.zeros(obs_dim, dtype=dtype)
            if centre_mean is not None:
                mean = mean + self._vector_or_scalar(centre_mean, "centre_mean", obs_dim, dtype)
            noise = torch.randn(num_basis, obs_dim, generator=generator, dtype=dtype)
            centres_t = mean + centre_std * noise
        else:
            centres_t = as_float_tensor(centres, "centres", dtype)
            check_shape(centres_t, "centres", (num_basis, obs_dim), "(N, D)")
            check_finite(centres_t, "centres")

        if weights is None:
            noise = torch.randn(act_dim, num_basis, generator=generator, dtype=dtype)
            weights_t = weight_std * noise
        else:
            weights_t = as_float_tensor(weights, "weights", dtype)
            check_shape(weights_t, "weights", (act_dim, num_basis), "(F, N)")
            check_finite(weights_t, "weights")

        scales = as_float_tensor(lengthscales, "lengthscales", dtype)
        if scales.shape not in (torch.Size([]), (obs_dim,), (act_dim, obs_dim)):
            raise ValueError(
                f"lengthscales must have shape (), (D,) = ({obs_dim},) or (F, D) = "
                f"({act_dim}, {obs_dim}), found {shape_str(scales.shape)}"
            )
        check_positive(scales, "lengthscales")
        scales = scales.expand(act_dim, obs_dim).clone()

        self.centres = nn.Parameter(centres_t)
        self.weights = nn.Parameter(weights_t)
        self.log_lengthscales = nn.Parameter(torch.log(scales))

    @staticmethod
    def _vector_or_scalar(value: object, name: str, size: int, dtype: torch.dtype) -> Tensor:
        tensor = scalar_or_vector(value, name, size, "D", dtype)
        check_finite(tensor, name)
        return tensor

    @property
    def lengthscales(self) -> Tensor:
        r"""Length-scales :math:`\ell = \exp(\text{log\_lengthscales})`, shape (F, D)."""
        return torch.exp(self.log_lengthscales)

    @property
    def num_basis(self) -> int:
        """Number of basis functions N."""
        return int(self.centres.shape[0])

    @property
    def obs_dim(self) -> int:
        """Observation dimension D."""
        return int(self.centres.shape[1])

    @property
    def act_dim(self) -> int:
        """Action dimension F."""
        return int(self.weights.shape[0])

    def forward(self, x: Tensor) -> Tensor:
        r"""Evaluate :math:`u_f(x) = \sum_i w_{fi} \exp(-\tfrac12 \|(x - c_i) / \ell_f\|^2)`.

        Shapes: ``x`` (..., D) -> (..., F); intermediates (..., F, N, D).
        """
        check_last_dim(x, self.obs_dim, self.centres.dtype)
        diff = x[..., None, :] - self.centres  # (..., N, D)
        # Scale per output: (..., 1, N, D) / (F, 1, D) -> (..., F, N, D). Dividing the
        # difference (rather than expanding the square) avoids cancellation far from centres.
        scaled = diff[..., None, :, :] / self.lengthscales[:, None, :]
        kernel = torch.exp(-_HALF * scaled.square().sum(dim=-1))  # (..., F, N)
        return (kernel * self.weights).sum(dim=-1)

    def extra_repr(self) -> str:
        return f"obs_dim={self.obs_dim}, act_dim={self.act_dim}, num_basis={self.num_basis}"
