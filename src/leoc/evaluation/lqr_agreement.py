r"""Does a trained hybrid keep its LQR? Its responses against the LQR's, and what it learned.

LEOC's promise is that near the operating point the hybrid *is* the engineer's LQR: same
equilibrium, same transient. The paper's relevance makes that exact only at :math:`a`
(:math:`r(a) = 1`); training moves :math:`\Lambda`, and wherever :math:`r < 1` along a
response the learned part leaks in. :func:`lqr_agreement` measures the leak on the paper's
response tests (:func:`~leoc.evaluation.rollout.response_test`: the impulse of -1 on the first
action, and the step of -0.2 on every action), run by the hybrid and by the LQR designed for the
hybrid's control period, from the operating point:

* ``distance_pct``: :math:`100 \max_t |e_H(t) - e_L(t)| / \max_t |e_L(t)|`, the largest
  difference of the main coordinate's deviations (report units), in percent of the LQR's peak;
  infinite when only one of the two responses ended early (terminated);
* ``min_relevance``: :math:`\min_t r(x_t)` along the hybrid's response: exactly 1 means the
  hybrid applied :math:`G` throughout, so the two responses agree *by construction*
  (``by_construction``) and the comparison measures nothing;
* ``settling_time`` of both (2 % band of the peak error; seconds), and ``keeps_lqr``: the
  distance is at most :data:`KEEP_TOLERANCE_PCT` and the settling times differ by at most one
  control period (or neither settles).

:func:`relevance_parameters` reads what training left in the relevance (its :math:`\Lambda`,
the precision, the floor, the Lyapunov scale or the ROA band), whatever wraps the hybrid.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from leoc.evaluation.impulse_sweep import FLAT_TOP
from leoc.evaluation.rollout import RESPONSE_TESTS, control_period, response_test
from leoc.systems.base import System
from leoc.systems.rollout import Controller

__all__ = ["KEEP_TOLERANCE_PCT", "lqr_agreement", "relevance_parameters", "response_distance"]

KEEP_TOLERANCE_PCT = 2.0
"""Largest response distance [% of the LQR's peak] of a hybrid that keeps its LQR."""


def response_distance(hybrid: np.ndarray, lqr: np.ndarray) -> float:
    """``100 max|hybrid - lqr| / max|lqr|`` over the common samples; ``inf`` when the lengths
    differ (one response terminated early) or the LQR's response is identically 0."""
    hybrid, lqr = np.asarray(hybrid, dtype=float), np.asarray(lqr, dtype=float)
    peak = float(np.max(np.abs(lqr))) if lqr.size else 0.0
    if hybrid.shape != lqr.shape or peak == 0.0:
        return math.inf
    return 100.0 * float(np.max(np.abs(hybrid - lqr))) / peak


def _seconds(steps: int | None, dt: float) -> float | None:
    return None if steps is None else float(steps) * dt


def _test_agreement(system: System, controller: Controller, lqr: Controller, test: str) -> dict:
    """One response test of the hybrid and of the LQR (see the module docstring)."""
    ours = response_test(system, controller, test)
    theirs = response_test(system, lqr, test)
    relevance = ours.trajectory.relevance
    lowest = None if relevance is None else float(np.min(relevance))
    settle = [_seconds(result.metrics.settling_time, system.dt) for result in (ours, theirs)]
    distance = response_distance(ours.deviation, theirs.deviation)
    period = control_period(controller) * system.dt
    same_settling = (settle[0] is None and settle[1] is None) or (
        None not in settle and abs(settle[0] - settle[1]) <= period + 1e-12  # type: ignore[operator]
    )
    return {
        "distance_pct": distance,
        "min_relevance": lowest,
        "by_construction": lowest is not None and lowest >= FLAT_TOP,
        "settling_time": settle[0],
        "lqr_settling_time": settle[1],
        "lqr_peak": float(np.max(np.abs(theirs.deviation))),
        "keeps_lqr": bool(distance <= KEEP_TOLERANCE_PCT and same_settling),
    }


def lqr_agreement(
    system: System, controller: Controller, lqr: Controller | None = None
) -> dict[str, Any]:
    """The hybrid ``controller`` against ``lqr`` (the LQR at the same control period) on the
    paper's impulse and step tests, and its relevance's parameters.

    Parameters
    ----------
    system : System
        The plant the controller was trained on (its rules).
    controller : callable
        A trained hybrid at its own control period.
    lqr : callable, optional
        The LQR designed for that period (:func:`leoc.policies.lqr_controller`); default the
        discrete LQR of ``system`` designed for the controller's period.

    Returns
    -------
    dict
        ``impulse`` and ``step`` (each: ``distance_pct``, ``min_relevance``,
        ``by_construction``, ``settling_time``, ``lqr_settling_time``, ``lqr_peak``,
        ``keeps_lqr``) and ``relevance`` (:func:`relevance_parameters`).
    """
    if lqr is None:
        from leoc.control import design_lqr
        from leoc.policies import lqr_controller

        lqr = lqr_controller(design_lqr(system, action_repeat=control_period(controller)))
    result: dict[str, Any] = {
        test: _test_agreement(system, controller, lqr, test) for test in RESPONSE_TESTS
    }
    result["relevance"] = relevance_parameters(controller)
    return result


def _hybrid_inside(controller: Any) -> Any:
    from leoc.policies import HybridPolicy

    if isinstance(controller, torch.nn.Module):
        for module in controller.modules():
            if isinstance(module, HybridPolicy):
                return module
    return None


def _numbers(value: Any) -> list[float]:
    return [float(x) for x in torch.as_tensor(value).detach().double().reshape(-1).tolist()]


def relevance_parameters(controller: Any) -> dict[str, Any] | None:
    """What the hybrid's relevance holds: ``kind`` (``"paper"`` or the relevance module's class
    name) and, where the relevance has them, ``lambda`` (the diagonal of :math:`\\Lambda`, or
    the Lyapunov relevance's scale), ``precision`` (:math:`\\Lambda^{-1}` of the authors'
    unconstrained parametrisation), ``lambda_floor``, ``width`` and ``rho_in`` (ROA); None
    for a controller with no :class:`~leoc.policies.HybridPolicy` inside."""
    hybrid = _hybrid_inside(controller)
    if hybrid is None:
        return None
    out: dict[str, Any] = {"kind": hybrid.relevance_kind}
    module = hybrid.relevance_module
    if module is None:
        out["lambda"] = _numbers(torch.exp(hybrid.log_lambda))
        return out
    for name, key in (("lambda_", "lambda"), ("precision", "precision"), ("floor", "lambda_floor")):
        value = getattr(module, name, None)
        if isinstance(value, torch.Tensor):
            out[key] = _numbers(value)
    if "precision" in out and "lambda" not in out:
        out["lambda"] = [1.0 / value if value != 0 else math.inf for value in out["precision"]]
    for name in ("width", "rho_in"):
        value = getattr(module, name, None)
        if isinstance(value, (torch.Tensor, float, int)) and not isinstance(value, bool):
            out[name] = _numbers(value)[0]
    return out
