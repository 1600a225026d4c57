r"""Multilayer-perceptron actor, the nonlinear part :math:`H` used with DDPG/TD3.

Letters: D observation dimension, F action dimension, :math:`h_k` hidden widths.

.. math::

    z = L_K \circ \sigma \circ L_{K-1} \circ \cdots \circ \sigma \circ L_0 (x), \qquad
    H(x) = \begin{cases} z & u_{max} \text{ not set} \\
                         u_{max} \tanh(z) & \text{otherwise} \end{cases}

with affine layers :math:`L_k` and activation :math:`\sigma` (ReLU by default). The default
widths (400, 300) are those of the DDPG paper (Lillicrap et al., 2016).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import torch
from torch import Tensor, nn

from ._checks import (
    check_last_dim,
    check_positive_int,
    positive_scalar_or_vector,
)

__all__ = ["MLPActor"]

DEFAULT_HIDDEN_SIZES: tuple[int, ...] = (400, 300)
"""Hidden widths of the DDPG actor (Lillicrap et al., 2016)."""


def _reset_linear(layer: nn.Linear, generator: torch.Generator | None) -> None:
    r"""Draw weights and bias from :math:`U(-1/\sqrt{h_{in}}, 1/\sqrt{h_{in}})`.

    This is the distribution of PyTorch's own ``nn.Linear`` initialisation
    (Kaiming-uniform with :math:`a = \sqrt 5`), redrawn here so that it can use ``generator``.
    """
    bound = 1.0 / math.sqrt(layer.in_features)
    with torch.no_grad():
        layer.weight.uniform_(-bound, bound, generator=generator)
        layer.bias.uniform_(-bound, bound, generator=generator)


class MLPActor(nn.Module):
    r"""Fully connected actor network.

    .. math::

        H(x) = u_{max} \tanh\big(\mathrm{MLP}(x)\big) \quad\text{or}\quad H(x) = \mathrm{MLP}(x)

    Shapes: input (..., D), output (..., F).

    Parameters
    ----------
    obs_dim : int
        Observation dimension D.
    act_dim : int
        Action dimension F.
    hidden_sizes : sequence of int
        Widths of the hidden layers; empty gives an affine map.
    activation : callable returning nn.Module
        Activation class (or factory) placed after every hidden layer, e.g. ``nn.ReLU``.
    action_limit : float or array-like, optional
        Positive bound :math:`u_{max}`, scalar or shape (F,). ``None`` leaves the output linear.
    dtype : torch.dtype
        Floating dtype of the parameters (float64 by default).
    generator : torch.Generator, optional
        Source of randomness for the initialisation; torch's global generator if omitted (so
        ``torch.manual_seed`` makes it reproducible too). Layers are drawn input to output,
        weight before bias.
    """

    action_limit: Tensor | None

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden_sizes: Sequence[int] = DEFAULT_HIDDEN_SIZES,
        activation: Callable[[], nn.Module] = nn.ReLU,
        action_limit: float | object | None = None,
        dtype: torch.dtype = torch.float64,
        generator: torch.Generator | None = None,
    ):
        super().__init__()
        obs_dim = check_positive_int(obs_dim, "obs_dim")
        act_dim = check_positive_int(act_dim, "act_dim")
        if isinstance(hidden_sizes, (str, bytes)) or not isinstance(hidden_sizes, Sequence):
            raise TypeError(
                f"hidden_sizes must be a sequence of positive ints, "
                f"found {type(hidden_sizes).__name__}"
            )
        widths = [check_positive_int(h, f"hidden_sizes[{k}]") for k, h in enumerate(hidden_sizes)]
        if not callable(activation):
            raise TypeError(
                f"activation must be a callable returning an nn.Module (e.g. nn.ReLU), "
                f"found {type(activation).__name__}"
            )
        if generator is not None and not isinstance(generator, torch.Generator):
            raise TypeError(
                f"generator must be a torch.Generator or None, found {type(generator).__name__}"
            )

        layers: list[nn.Module] = []
        sizes = [obs_dim, *widths]
        for width_in, width_out in zip(sizes[:-1], sizes[1:], strict=True):
            layers.append(nn.Linear(width_in, width_out, dtype=dtype))
            act = activation()
            if not isinstance(act, nn.Module):
                raise TypeError(
                    f"activation() must return an nn.Module, found {type(act).__name__}"
                )
            layers.append(act)
        layers.append(nn.Linear(sizes[-1], act_dim, dtype=dtype))
        self.net = nn.Sequential(*layers)
        for layer in self.net:
            if isinstance(layer, nn.Linear):
                _reset_linear(layer, generator)

        limit = None
        if action_limit is not None:
            limit = positive_scalar_or_vector(action_limit, "action_limit", act_dim, "F", dtype)
        self.register_buffer("action_limit", limit)
        self._obs_dim = obs_dim
        self._act_dim = act_dim

    @property
    def obs_dim(self) -> int:
        """Observation dimension D."""
        return self._obs_dim

    @property
    def act_dim(self) -> int:
        """Action dimension F."""
        return self._act_dim

    def forward(self, x: Tensor) -> Tensor:
        r"""Evaluate :math:`H(x)`.

        Shapes: ``x`` (..., D) -> (..., F).
        """
        check_last_dim(x, self.obs_dim, self.net[0].weight.dtype)
        z = self.net(x)
        if self.action_limit is None:
            return z
        return self.action_limit * torch.tanh(z)

    def extra_repr(self) -> str:
        return f"obs_dim={self.obs_dim}, act_dim={self.act_dim}"
