r"""Actuator saturation applied to a policy's output.

Four modes map an unbounded action :math:`u` to one inside :math:`[-u_{max}, u_{max}]`
(elementwise, :math:`u_{max} > 0`):

.. math::

    \text{clip}: \; \min(\max(u, -u_{max}), u_{max}) \qquad
    \text{sin}: \; u_{max} \sin(u / u_{max}) \qquad
    \text{tanh}: \; u_{max} \tanh(u / u_{max}) \qquad
    \text{none}: \; u

How each keeps the hybrid policy's identities :math:`\pi(a) = G(a)` and
:math:`\partial \pi / \partial x (a) = W` (see :mod:`leoc.policies.hybrid`):

- ``"clip"`` is the identity, value and slope, everywhere strictly inside the limits, so both
  identities hold whenever :math:`|G(a)| < u_{max}`.
- ``"sin"`` and ``"tanh"`` preserve value and slope only at :math:`u = 0` (value 0, slope 1);
  elsewhere they shrink both. The identities therefore hold only when :math:`G(a) = 0`.
- ``"sin"`` is PILCO's squashing function (Deisenroth & Rasmussen, 2011): its mean and
  variance under a Gaussian input are known in closed form. It is bounded but not monotone:
  it turns back for :math:`|u| > \tfrac{\pi}{2} u_{max}`.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from ._checks import check_positive

__all__ = ["SATURATION_MODES", "Saturated", "saturate"]

SATURATION_MODES: tuple[str, ...] = ("clip", "sin", "tanh", "none")
"""Names accepted by :func:`saturate` and by ``HybridPolicy(saturation=...)``."""


def check_saturation_mode(mode: object, name: str = "mode") -> str:
    """Return ``mode`` if it is one of :data:`SATURATION_MODES`, else raise."""
    if not isinstance(mode, str):
        raise TypeError(f"{name} must be a str in {SATURATION_MODES}, found {type(mode).__name__}")
    if mode not in SATURATION_MODES:
        raise ValueError(f"{name} must be one of {SATURATION_MODES}, found {mode!r}")
    return mode


def saturate(u: Tensor, limit: Tensor | float | None, mode: str = "clip") -> Tensor:
    r"""Bound an action elementwise to :math:`[-u_{max}, u_{max}]`.

    .. math::

        \text{clip}(u) = \min(\max(u, -u_{max}), u_{max}), \quad
        \text{sin}(u) = u_{max} \sin(u / u_{max}), \quad
        \text{tanh}(u) = u_{max} \tanh(u / u_{max})

    Shapes: ``u`` is (..., F); ``limit`` is a scalar or broadcastable to (..., F), typically
    (F,); the result is (..., F).

    Parameters
    ----------
    u : Tensor
        Unbounded action, shape (..., F).
    limit : Tensor, float or None
        Positive actuator limit :math:`u_{max}`. ``None`` means no saturation.
    mode : {"clip", "sin", "tanh", "none"}
        Saturation function; ``"none"`` returns ``u`` unchanged.

    Returns
    -------
    Tensor
        Saturated action, shape (..., F).

    Notes
    -----
    ``"clip"`` is exact (value and unit slope) strictly inside the limits and has zero slope
    outside. ``"sin"`` and ``"tanh"`` are smooth and have value 0 and slope 1 at :math:`u = 0`
    only; they preserve neither value nor slope anywhere else.
    """
    mode = check_saturation_mode(mode)
    # tensor-like: a Tensor or an object dispatching torch functions (an interval enclosure)
    if not torch.overrides.is_tensor_like(u):
        raise TypeError(f"u must be a torch.Tensor, found {type(u).__name__}")
    if limit is None or mode == "none":
        return u
    limit_t = torch.as_tensor(limit, dtype=u.dtype, device=u.device)
    check_positive(limit_t, "limit")
    return apply_saturation(u, limit_t, mode)


def apply_saturation(u: Tensor, limit: Tensor, mode: str) -> Tensor:
    """:func:`saturate` without its input checks, for hot paths whose ``limit`` (a positive
    tensor of ``u``'s dtype) and ``mode`` were validated once at construction."""
    limit_t = limit
    if mode == "none":
        return u
    if mode == "clip":
        return torch.minimum(torch.maximum(u, -limit_t), limit_t)
    if mode == "sin":
        return limit_t * torch.sin(u / limit_t)
    return limit_t * torch.tanh(u / limit_t)


class Saturated(nn.Module):
    r"""``policy`` followed by the actuator saturation: :math:`\text{sat}(\text{policy}(o))`.

    The authors' linear controller is one: :math:`u_{max} \sin(W o / u_{max})` with the
    physical gain ``W`` of :func:`leoc.control.design_lqr` ``(method="authors")``.

    Parameters
    ----------
    policy : nn.Module
        Observation ``(..., O)`` -> unbounded action ``(..., A)``.
    limit : float
        Actuator limit :math:`u_{max} > 0`.
    mode : {"clip", "sin", "tanh", "none"}
        See :func:`saturate`.
    """

    limit: Tensor

    def __init__(self, policy: nn.Module, limit: float, mode: str):
        super().__init__()
        if not isinstance(policy, nn.Module):
            raise TypeError(f"policy: expected an nn.Module, found {type(policy).__name__}")
        self.policy = policy
        self.mode = check_saturation_mode(mode)
        limit_t = torch.as_tensor(float(limit), dtype=torch.float64)
        check_positive(limit_t, "limit")
        self.register_buffer("limit", limit_t)

    def forward(self, x: Tensor) -> Tensor:
        u = self.policy(x)
        return apply_saturation(u, self.limit.to(u.dtype), self.mode)

    def extra_repr(self) -> str:
        return f"mode={self.mode!r}, limit={float(self.limit)}"
