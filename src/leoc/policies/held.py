"""A policy with its control period: it decides every ``action_repeat`` simulator steps.

A controller keeps the period it was trained at wherever it is evaluated (responses,
robustness, ``leoc simulate``): PILCO trains its policy on the ``action_repeat``-step map with
the action held in between (zero-order hold), so a PILCO controller is saved and loaded as a
:class:`HeldPolicy`. The rollout (:func:`leoc.systems.rollout.simulate`) reads the period from
the ``action_repeat`` attribute; the wrapper itself is stateless and maps observations to
actions exactly as the wrapped policy does.
"""

from __future__ import annotations

from typing import Any

from torch import Tensor, nn

from leoc.systems.base import check_repeat

__all__ = ["HeldPolicy", "lqr_controller", "with_control_period"]


class HeldPolicy(nn.Module):
    """``policy`` run at a control period of ``action_repeat`` simulator steps.

    Parameters
    ----------
    policy : nn.Module
        Observation ``(..., O)`` -> action ``(..., A)``.
    action_repeat : int
        Simulator steps each decision is held (>= 1).

    Notes
    -----
    ``relevance`` (and so the relevance traces of the rollouts) is forwarded when the wrapped
    policy is a hybrid; ``is_hybrid`` says whether it is.
    """

    def __init__(self, policy: nn.Module, action_repeat: int):
        super().__init__()
        if not isinstance(policy, nn.Module):
            raise TypeError(f"policy: expected an nn.Module, found {type(policy).__name__}")
        self.policy = policy
        self.action_repeat = check_repeat(action_repeat)

    @property
    def is_hybrid(self) -> bool:
        """Whether the wrapped policy is a hybrid (it has a relevance r(x))."""
        return callable(getattr(self.policy, "relevance", None)) and getattr(
            self.policy, "is_hybrid", True
        )

    def relevance(self, x: Tensor) -> Tensor:
        """r(x) of the wrapped hybrid."""
        return self.policy.relevance(x)

    def flat_region(self) -> Any:
        """The wrapped policy's :class:`~leoc.policies.relevance.FlatRegion` (None if it has
        none): holding the action changes nothing about where it is its linear part."""
        method = getattr(self.policy, "flat_region", None)
        return method() if callable(method) else None

    def forward(self, x: Tensor, *args: object, **kwargs: object) -> Tensor:
        return self.policy(x, *args, **kwargs)

    def extra_repr(self) -> str:
        return f"action_repeat={self.action_repeat}"


def with_control_period(policy: nn.Module, action_repeat: int) -> nn.Module:
    """``policy`` itself for a period of one step, else ``HeldPolicy(policy, action_repeat)``."""
    return policy if check_repeat(action_repeat) == 1 else HeldPolicy(policy, action_repeat)


def lqr_controller(
    design: object, saturation: str = "none", limit: float | None = None
) -> nn.Module:
    """The linear controller ``G(o) = W o + b`` of an :class:`~leoc.control.LQRDesign`, run at
    the control period the design is for (``design.action_repeat``).

    ``saturation`` (with the actuator ``limit``) wraps it in
    :class:`~leoc.policies.saturation.Saturated`: ``"sin"`` gives the authors' PILCO
    ``LinearController``, u_max sin(W o / u_max);
    ``"none"`` (default) leaves the clip to the system, exact inside the limits.
    """
    from leoc.policies.linear import LinearController
    from leoc.policies.saturation import Saturated, check_saturation_mode

    W, b, repeat = design.W, design.b, design.action_repeat  # type: ignore[attr-defined]
    policy: nn.Module = LinearController(W, b)
    if check_saturation_mode(saturation, "saturation") != "none":
        if limit is None:
            raise ValueError(f"limit: expected the actuator limit with saturation={saturation!r}")
        policy = Saturated(policy, limit, saturation)
    return with_control_period(policy, repeat)
