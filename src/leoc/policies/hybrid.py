r"""The LEOC hybrid policy: a linear controller near the operating point, a learned one elsewhere.

Letters: D observation dimension, F action dimension; ``...`` any leading batch shape.

Following Zhang & Capel (L4DC 2021, eq. 4-5),

.. math::

    \pi(x) = \operatorname{sat}\big(r(x)\, G(x) + (1 - r(x))\, H(x)\big), \qquad
    G(x) = W x + b,

    r(x) = \frac{1}{(1 + d(x))^2}, \qquad
    d(x) = (x - a)^\top \Lambda^{-1} (x - a) = \sum_{i=1}^{D} \frac{(x_i - a_i)^2}{\lambda_i},
    \qquad \Lambda = \operatorname{diag}(\lambda),\; \lambda_i > 0,

with operating point :math:`a` (in observation coordinates), linear part :math:`G`
(:class:`~leoc.policies.LinearController`), any differentiable nonlinear part :math:`H` and an
actuator saturation :math:`\operatorname{sat}` (:func:`~leoc.policies.saturate`).

Local identities (the paper's stability argument, Sec. 4.1). Since
:math:`d(a) = 0` and :math:`\nabla d(a) = 2 \Lambda^{-1}(a - a) = 0`,

.. math::

    r(a) = 1, \qquad \nabla r(a) = -\frac{2\, \nabla d(a)}{(1 + d(a))^3} = 0,

so the blend :math:`\beta = r G + (1 - r) H` satisfies

.. math::

    \beta(a) = G(a), \qquad
    \frac{\partial \beta}{\partial x}(a)
        = r W + (G - H) \nabla r^\top + (1 - r) \frac{\partial H}{\partial x} \Big|_{a} = W.

The saturation keeps both identities when its value and slope at :math:`G(a)` are the identity's:
``"clip"`` needs :math:`|G(a)| < u_{max}` (strictly inside the limits), ``"sin"`` and ``"tanh"``
need :math:`G(a) = 0`. :class:`HybridPolicy` checks this at construction. Then
:math:`\pi(a) = G(a)` and :math:`\partial \pi / \partial x (a) = W`: the closed loop linearised
at :math:`a` is the linear design's, so the hybrid inherits its local stability.

Limits in :math:`\Lambda`. For :math:`x \ne a`, as :math:`\max_i \lambda_i \to 0`,
:math:`d(x) \ge \|x - a\|^2 / \max_i \lambda_i \to \infty`, hence :math:`r(x) \to 0` and
:math:`\pi(x) \to \operatorname{sat}(H(x))`, with
:math:`|\beta - H| = r\, |G - H| \le (\max_i \lambda_i / \|x - a\|^2)^2\, |G - H|`.
As :math:`\min_i \lambda_i \to \infty`, :math:`d \to 0` and :math:`\pi \to \operatorname{sat}(G)`.
The paper (Sec. 4.2) states the first limit as :math:`\lambda_i \to \infty`; with :math:`d` as
written in its eq. 5 (weights :math:`1/\lambda_i`) the direction is :math:`\lambda_i \to 0`, which
is what this module implements and documents. Either way :math:`\pi` can approximate any
function that :math:`H` can, away from :math:`a`.

References
----------
Y. Zhang and F. Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
Classical Control Theory", L4DC 2021, eq. 4-5.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor, nn

from leoc.control.intervals import Jet, exact_rows, with_rows

from ._checks import (
    as_float_tensor,
    check_finite,
    check_flag,
    check_last_dim,
    check_shape,
    positive_scalar_or_vector,
    register_learnable,
    shape_str,
)
from .linear import LinearController
from .relevance import FlatRegion, ROARelevance, paper_relevance
from .saturation import apply_saturation, check_saturation_mode

__all__ = [
    "ACTUATOR_CLIPS",
    "HybridOutput",
    "HybridPolicy",
    "SMOOTH_SATURATION_ATOL",
    "lqr_certificate",
    "output_saturation",
    "saturated_lqr",
]

DEFAULT_LAMBDA = 1.0  # the paper's initial Lambda: the identity
SMOOTH_SATURATION_ATOL = 1e-9
r"""Tolerance, relative to :math:`\max(1, u_{max})`, on :math:`|G(a)|` for ``"sin"``/``"tanh"``.

Those saturations preserve value and slope only at 0, so :math:`G(a)` must vanish up to
round-off for :math:`\pi(a) = G(a)` to hold.
"""

_SMOOTH_SATURATIONS = ("sin", "tanh")


class HybridOutput(NamedTuple):
    """Action and relevance returned by ``HybridPolicy.forward(x, return_relevance=True)``."""

    action: Tensor
    """Saturated action :math:`\\pi(x)`, shape (..., F)."""
    relevance: Tensor
    """Relevance :math:`r(x)`, shape (..., 1)."""


class HybridPolicy(nn.Module):
    r"""LEOC hybrid policy :math:`\pi(x) = \operatorname{sat}(r G + (1 - r) H)`.

    .. math::

        \pi(x) = \operatorname{sat}\big(r(x) G(x) + (1 - r(x)) H(x)\big), \quad
        r(x) = (1 + d(x))^{-2}, \quad d(x) = \sum_i (x_i - a_i)^2 / \lambda_i

    Shapes: input (..., D); action (..., F); relevance and distance (..., 1).
    See the module docstring for the identities :math:`\pi(a) = G(a)`,
    :math:`\partial\pi/\partial x(a) = W` and the limits in :math:`\Lambda`.

    Parameters
    ----------
    linear : LinearController
        The linear part :math:`G(x) = W x + b`, acting on the observation.
    nonlinear : nn.Module
        The nonlinear part :math:`H`, mapping (..., D) to (..., F) (e.g. :class:`MLPActor` or
        :class:`RBFNetwork`). Must accept a (1, D) tensor of ``linear``'s dtype.
    operating_point : array-like
        Operating point :math:`a`, shape (D,), in observation coordinates. Stored as the buffer
        ``operating_point``.
    lambda_init : float or array-like, optional
        Initial :math:`\lambda > 0` of the paper's relevance, scalar (broadcast to all D) or
        shape (D,); default 1 (the identity, as in the paper). Only with ``relevance=None``.
    learn_lambda : bool, optional
        If True (default), ``log_lambda`` (shape (D,)) is an ``nn.Parameter``; otherwise a
        buffer. The log keeps :math:`\lambda = \exp(\text{log\_lambda})` positive while
        training. Only with ``relevance=None``.
    action_limit : float or array-like, optional
        Positive actuator limit :math:`u_{max}`, scalar or shape (F,). ``None``: no saturation.
        Stored as the buffer ``action_limit``.
    saturation : {"clip", "sin", "tanh", "none"}
        How the limit is applied after blending (see :func:`~leoc.policies.saturate`).
    relevance : nn.Module, optional
        A relevance module mapping (..., D) to (..., 1) with :math:`r(a) = 1` exactly (checked),
        e.g. :class:`~leoc.policies.ROARelevance` (flat on the LQR's certified region of
        attraction; see :func:`~leoc.policies.roa_hybrid`). Registered as
        ``relevance_module``. ``None``
        (default): the paper's :math:`r = (1 + d)^{-2}` with ``log_lambda`` on the policy
        itself, so state dicts saved before relevance modules existed still load.

    Raises
    ------
    TypeError
        If ``linear`` is not a :class:`LinearController`, ``nonlinear`` is not an
        ``nn.Module``, or an argument is not numeric.
    ValueError
        If shapes disagree, :math:`\lambda` or the limit is not positive and finite, the
        saturation is unknown, ``nonlinear`` does not map (1, D) to (1, F), or the saturation
        would break :math:`\pi(a) = G(a)` or :math:`\partial\pi/\partial x(a) = W`.
    """

    operating_point: Tensor
    log_lambda: Tensor
    action_limit: Tensor | None

    def __init__(
        self,
        linear: LinearController,
        nonlinear: nn.Module,
        operating_point: object,
        lambda_init: float | object | None = None,
        learn_lambda: bool | None = None,
        action_limit: float | object | None = None,
        saturation: str = "clip",
        relevance: nn.Module | None = None,
    ):
        super().__init__()
        if not isinstance(linear, LinearController):
            raise TypeError(f"linear must be a LinearController, found {type(linear).__name__}")
        if not isinstance(nonlinear, nn.Module):
            raise TypeError(f"nonlinear must be an nn.Module, found {type(nonlinear).__name__}")
        if relevance is not None:
            if not isinstance(relevance, nn.Module):
                raise TypeError(f"relevance must be an nn.Module, found {type(relevance).__name__}")
            if lambda_init is not None or learn_lambda is not None:
                raise ValueError(
                    "lambda_init, learn_lambda: only for the paper's relevance (relevance=None), "
                    f"found lambda_init={lambda_init!r}, learn_lambda={learn_lambda!r} with "
                    f"relevance={type(relevance).__name__}"
                )
        lambda_init = DEFAULT_LAMBDA if lambda_init is None else lambda_init
        learn_lambda = True if learn_lambda is None else learn_lambda
        check_flag(learn_lambda, "learn_lambda")
        self.saturation = check_saturation_mode(saturation, "saturation")
        self.linear = linear
        self.nonlinear = nonlinear
        obs_dim, act_dim = linear.obs_dim, linear.act_dim
        dtype, device = linear.W.dtype, linear.W.device

        point = as_float_tensor(operating_point, "operating_point", dtype).to(device)
        check_shape(point, "operating_point", (obs_dim,), "(D,) with D = linear.obs_dim")
        check_finite(point, "operating_point")
        self.register_buffer("operating_point", point)

        # The paper's relevance keeps its parameter on the policy itself (state_dict key
        # "log_lambda", as before relevance modules existed); any other relevance is the
        # submodule "relevance_module".
        self.relevance_module = relevance
        if relevance is None:
            log_lambda = torch.log(self._lambda_vector(lambda_init, obs_dim, dtype).to(device))
            register_learnable(self, "log_lambda", log_lambda, learn_lambda)

        self.register_buffer("action_limit", self._limit_tensor(action_limit, act_dim, dtype))
        if self.action_limit is not None:
            self.action_limit = self.action_limit.to(device)

        self._check_nonlinear_output(act_dim)
        self._check_relevance_module()
        self._check_identities_survive_saturation()

    def _check_relevance_module(self) -> None:
        """A relevance module must map (1, D) to (1, 1) and give exactly r(a) = 1."""
        if self.relevance_module is None:
            return
        probe = self.operating_point[None, :]
        with torch.no_grad():
            value = self.relevance_module(probe)
        if not isinstance(value, Tensor) or tuple(value.shape) != (1, 1):
            found = tuple(value.shape) if isinstance(value, Tensor) else type(value).__name__
            raise ValueError(
                f"relevance must map (1, D) = {shape_str(probe.shape)} to (1, 1), found {found}"
            )
        if float(value) != 1.0:
            raise ValueError(
                "relevance must be exactly 1 at the operating point (r(a) = 1 keeps "
                f"pi(a) = G(a)), found r(a) = {float(value)!r}"
            )

    @staticmethod
    def _lambda_vector(lambda_init: object, obs_dim: int, dtype: torch.dtype) -> Tensor:
        lam = positive_scalar_or_vector(lambda_init, "lambda_init", obs_dim, "D", dtype)
        return lam.expand(obs_dim).clone()

    @staticmethod
    def _limit_tensor(action_limit: object, act_dim: int, dtype: torch.dtype) -> Tensor | None:
        if action_limit is None:
            return None
        return positive_scalar_or_vector(action_limit, "action_limit", act_dim, "F", dtype)

    def _check_nonlinear_output(self, act_dim: int) -> None:
        """Evaluate H once at the operating point and check it maps (1, D) -> (1, F)."""
        probe = self.operating_point[None, :]
        try:
            with torch.no_grad():
                out = self.nonlinear(probe)
        except Exception as exc:  # any failure of user code is reported with the shapes
            raise ValueError(
                f"nonlinear must map a (1, D) = {shape_str(probe.shape)} tensor of dtype "
                f"{probe.dtype} to (1, F) = (1, {act_dim}); calling it raised "
                f"{type(exc).__name__}: {exc}"
            ) from exc
        if not isinstance(out, Tensor):
            raise ValueError(
                f"nonlinear must return a Tensor of shape (1, F) = (1, {act_dim}), "
                f"found {type(out).__name__}"
            )
        if tuple(out.shape) != (1, act_dim):
            raise ValueError(
                f"nonlinear must map (1, D) = {shape_str(probe.shape)} to (1, F) = "
                f"(1, {act_dim}) (F = linear.act_dim), found output shape {shape_str(out.shape)}"
            )

    def _check_identities_survive_saturation(self) -> None:
        """Reject saturations whose value/slope at G(a) would break pi(a)=G(a), dpi/dx(a)=W."""
        if self.action_limit is None or self.saturation == "none":
            return
        with torch.no_grad():
            g_a = self.linear(self.operating_point).abs()
            limit = self.action_limit.expand_as(g_a)
        if self.saturation in _SMOOTH_SATURATIONS:
            tol = SMOOTH_SATURATION_ATOL * torch.clamp(limit, min=1.0)
            if bool((g_a >= tol).any()):
                raise ValueError(
                    f"saturation={self.saturation!r} preserves value and slope only at 0, so "
                    f"the identity pi(a) = G(a) needs G(a) = 0 (|G(a)| < "
                    f"{SMOOTH_SATURATION_ATOL:g} * max(1, action_limit)); found |G(a)| = "
                    f"{g_a.tolist()}. Use saturation='clip' or a bias b with G(a) = 0."
                )
        elif bool((g_a >= limit).any()):
            raise ValueError(
                f"saturation='clip' keeps the identity dpi/dx(a) = W only strictly inside the "
                f"limits: need |G(a)| < action_limit, found |G(a)| = {g_a.tolist()} and "
                f"action_limit = {limit.tolist()}"
            )

    @property
    def obs_dim(self) -> int:
        """Observation dimension D."""
        return self.linear.obs_dim

    @property
    def act_dim(self) -> int:
        """Action dimension F."""
        return self.linear.act_dim

    @property
    def relevance_kind(self) -> str:
        """``"paper"`` for the default relevance, else the relevance module's class name."""
        if self.relevance_module is None:
            return "paper"
        return type(self.relevance_module).__name__

    def _require_paper(self, what: str) -> None:
        if self.relevance_module is not None:
            raise AttributeError(
                f"{what} belongs to the paper's relevance; this policy's relevance is "
                f"{self.relevance_kind}"
            )

    @property
    def lambda_(self) -> Tensor:
        r"""Diagonal of :math:`\Lambda`: :math:`\lambda = \exp(\text{log\_lambda})`, shape (D,)."""
        self._require_paper("lambda_")
        return torch.exp(self.log_lambda)

    def distance(self, x: Tensor) -> Tensor:
        r"""Weighted squared distance :math:`d(x) = \sum_i (x_i - a_i)^2 / \lambda_i`.

        Shapes: ``x`` (..., D) -> (..., 1). Only for the paper's relevance.
        """
        self._require_paper("distance")
        check_last_dim(x, self.obs_dim, self.operating_point.dtype)
        return ((x - self.operating_point).square() / self.lambda_).sum(dim=-1, keepdim=True)

    def relevance(self, x: Tensor) -> Tensor:
        r"""Relevance :math:`r(x) \in [0, 1]`, shape (..., 1) for ``x`` (..., D).

        The paper's :math:`1 / (1 + d(x))^2` (equal to 1 only at :math:`a`;
        :func:`~leoc.policies.relevance.paper_relevance`) by default, else the relevance
        module's (e.g. :class:`~leoc.policies.ROARelevance`, 1 on a certified set).
        """
        if self.relevance_module is not None:
            return self.relevance_module(x)
        check_last_dim(x, self.obs_dim, self.operating_point.dtype)
        return paper_relevance(x, self.operating_point, self.log_lambda)

    def blend(self, x: Tensor) -> Tensor:
        r"""Unsaturated blend :math:`r(x) G(x) + (1 - r(x)) H(x)`.

        Shapes: ``x`` (..., D) -> (..., F).
        """
        return self._blend(x, self.relevance(x))

    def flat_region(self, saturated: bool = True) -> FlatRegion | None:
        """Where this hybrid is its linear part G exactly (saturated as its output is, unless
        ``saturated`` is off): the ROA relevance's flat top, where r = 1 and the blend is G
        whatever H is (:class:`~leoc.policies.relevance.FlatRegion`); None for any other
        relevance."""
        if not isinstance(self.relevance_module, ROARelevance):
            return None
        if not saturated or self.action_limit is None:
            return self.relevance_module.flat_region(self.linear)
        return self.relevance_module.flat_region(self._saturated_linear)

    def _saturated_linear(self, x: Tensor) -> Tensor:
        return apply_saturation(self.linear(x), self.action_limit, self.saturation)

    def _blend(self, x: Tensor, r: Tensor) -> Tensor:
        # Written as r G + (1 - r) H rather than H + r (G - H): at x = a, r = 1 exactly and the
        # first form returns G(a) bit for bit, while the second would round G - H + H.
        if isinstance(r, Jet) and r.ndim == 2:
            return _blend_boxes(x, r, self.linear, self.nonlinear)
        return r * self.linear(x) + (1.0 - r) * self.nonlinear(x)

    def forward(self, x: Tensor, return_relevance: bool = False) -> Tensor | HybridOutput:
        r"""Evaluate :math:`\pi(x) = \operatorname{sat}(r G + (1 - r) H)`.

        Shapes: ``x`` (..., D) -> action (..., F); with ``return_relevance`` a
        :class:`HybridOutput` ``(action, relevance)`` with relevance (..., 1).
        """
        r = self.relevance(x)
        blended = self._blend(x, r)
        # limit and mode were validated at construction: skip the per-call checks (hot path)
        action = (
            blended
            if self.action_limit is None
            else apply_saturation(blended, self.action_limit, self.saturation)
        )
        if return_relevance:
            return HybridOutput(action, r)
        return action

    def extra_repr(self) -> str:
        learned = (
            f"learn_lambda={isinstance(self.log_lambda, nn.Parameter)}"
            if self.relevance_module is None
            else f"relevance={self.relevance_kind}"
        )
        return (
            f"obs_dim={self.obs_dim}, act_dim={self.act_dim}, saturation={self.saturation!r}, "
            f"{learned}"
        )


ACTUATOR_CLIPS = ("clip", "none")
"""Saturations of G that are the actuator's own clip (the step clips every action to
``system.action_limit``), so that the saturated LQR is the design's plain ``G``."""


def output_saturation(controller: Any) -> str:
    """The squash of a loaded controller's output: that of its outermost module with a
    ``saturation`` (the hybrid's or PILCO's ``sin``); ``clip`` when it has none or it is the
    actuator's (:data:`ACTUATOR_CLIPS`). The LQR a run was trained with is saturated so
    (:func:`saturated_lqr`, :func:`lqr_certificate`)."""
    modules = controller.modules() if hasattr(controller, "modules") else ()
    for module in modules:
        saturation = getattr(module, "saturation", None)
        if isinstance(saturation, str):
            return "clip" if saturation in ACTUATOR_CLIPS else saturation
    return "clip"


def saturated_lqr(
    system: Any, design: Any, saturation: str = "clip", action_limit: float | None = None
) -> Any:
    r"""The closed loop :math:`\operatorname{sat}(G)`, :math:`G(o) = W o + b` of ``design``, at
    the design's control period: the linear part of a hybrid with this ``saturation``.

    Parameters
    ----------
    system : leoc.systems.System
    design : LQRDesign
    saturation : {"clip", "none", "sin", "tanh"}
        ``clip`` or ``none`` at the system's limit: the design's
        :func:`~leoc.control.lqr_closed_loop` (the step clips every action); otherwise
        :math:`G` written out and saturated, so that the interval proof of a certificate can
        evaluate it.
    action_limit : float, optional
        :math:`u_{max}` of the saturation; default ``system.action_limit``.
    """
    from leoc.control.roa import lqr_closed_loop

    from .held import with_control_period

    check_saturation_mode(saturation, "saturation")
    limit = float(system.action_limit if action_limit is None else action_limit)
    if saturation in ACTUATOR_CLIPS and limit == float(system.action_limit):
        return lqr_closed_loop(design)
    gain = torch.as_tensor(np.asarray(design.W), dtype=torch.float64)
    bias = torch.as_tensor(np.asarray(design.b), dtype=torch.float64)
    limit_t = torch.tensor(limit, dtype=torch.float64)

    def saturated_linear(obs: Tensor) -> Tensor:
        # G written out (not a LinearController) so that the certificate's interval proof can
        # evaluate it on interval enclosures (leoc.control.intervals).
        # on the device of its input (a proof may run on a GPU: leoc.control.proof)
        linear = obs @ gain.to(obs.device).T + bias.to(obs.device)
        return apply_saturation(linear, limit_t, saturation)

    return with_control_period(_Callable(saturated_linear), design.action_repeat)


def lqr_certificate(
    system: Any,
    design: Any,
    saturation: str = "clip",
    action_limit: float | None = None,
    **certify_options: Any,
) -> Any:
    r"""Certificate (:func:`leoc.control.certify_lqr`) of :func:`saturated_lqr` at the design's
    period: the region of attraction an ROA hybrid is flat on (:func:`~leoc.policies.roa_hybrid`;
    a DDPG/TD3/SAC hybrid's is the ``clip`` case, :func:`leoc.policies.hybrid_design`), and the one
    ``leoc roa --controller`` certifies for a trained run.

    Every saturation is cached as :func:`~leoc.control.certify_lqr` caches (in the process and
    on disk): ``clip``/``none`` at the system's limit is the design's own certificate, any other
    is keyed by its saturation, limit and :data:`SATURATED_LQR_MODULES`.
    ``certify_options`` are :func:`~leoc.control.certify_level`'s keywords.
    """
    from leoc.control.roa import LinearClosedLoop, certify_lqr

    closed_loop = saturated_lqr(system, design, saturation, action_limit)
    if isinstance(closed_loop, LinearClosedLoop):
        return certify_lqr(system, design, **certify_options)
    limit = float(system.action_limit if action_limit is None else action_limit)
    return certify_lqr(
        system,
        design,
        closed_loop,
        controller_key=f"saturated_lqr(saturation={saturation!r}, action_limit={limit!r})",
        controller_modules=SATURATED_LQR_MODULES,
        **certify_options,
    )


SATURATED_LQR_MODULES = ("leoc.policies.hybrid", "leoc.policies.saturation", "leoc.policies.held")
"""Modules whose source writes :func:`saturated_lqr` (its certificate's cache key holds them)."""


class _Callable(nn.Module):
    """A plain function as a module (so it can carry a control period)."""

    def __init__(self, function: Any) -> None:
        super().__init__()
        self.function = function

    def forward(self, x: Tensor) -> Tensor:
        return self.function(x)


def _blend_boxes(x: Jet, r: Jet, linear: nn.Module, nonlinear: nn.Module) -> Jet:
    """``r G + (1 - r) H`` on interval enclosures of boxes (B, D), H evaluated only on the
    boxes where r is not exactly 1: on the others (the ROA relevance's flat top) the blend is
    G, exactly, whatever H is (a proof inside the flat top then costs what the LQR's does)."""
    g = linear(x)
    flat = exact_rows(r, 1.0)
    if not bool(flat.any()):
        return r * g + (1.0 - r) * nonlinear(x)
    live = ~flat
    if not bool(live.any()):
        return g
    part = r[live] * g[live] + (1.0 - r[live]) * nonlinear(x[live])
    return with_rows(g, live, part)
