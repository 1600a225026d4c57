"""A hybrid against its LQR where the comparison can fail (issue 21, claim (3)).

For one trained hybrid, at its control period, with the LQR designed for that period and that
LQR's proved certificate: the impulse sweep up to the LQR's failure size
(:mod:`leoc.evaluation.impulse_sweep`), held shares from starts in shells of V out to 3 rho,
and the basin relative to the LQR's (:mod:`leoc.evaluation.basins`). Every comparison records
whether the hybrid left its flat top r = 1 (evidence) or not (by construction).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from leoc.evaluation.basins import (
    SHELL_STARTS,
    BasinComparison,
    basin_comparison,
    shell_levels,
    shell_robustness,
)
from leoc.evaluation.impulse_sweep import (
    SWEEP_POINTS,
    ImpulsePoint,
    impulse_sweep,
    lqr_failure_size,
    sweep_sizes,
)
from leoc.systems.base import System
from leoc.systems.rollout import Controller, relevance_function

__all__ = ["BASIN_STARTS", "flat_top_level", "hybrid_claims", "operating_region_corners"]

BASIN_STARTS = 1000
"""Starts in the proved set and in the basin box (each)."""
HYBRID_LABEL = "hybrid"
LQR_LABEL = "lqr"


def flat_top_level(controller: Any) -> float | None:
    """rho_in of an ROA-relevance hybrid (r == 1 on V <= rho_in), found as the
    :class:`~leoc.policies.ROARelevance` inside the controller however it is wrapped
    (``HeldPolicy``, the DDPG actor in physical units, ...); None for the paper's relevance
    (r < 1 everywhere but at a) or a non-hybrid."""
    from leoc.policies.relevance import ROARelevance

    if not isinstance(controller, torch.nn.Module):
        return None
    for module in controller.modules():
        if isinstance(module, ROARelevance):
            return float(module.rho_in)
    return None


def operating_region_corners(system: System) -> np.ndarray:
    """The 2^S corners (2^S, S) of the operating-region box (the robustness starts' box): V
    is convex, so its largest value on the box is at one of them."""
    half = np.asarray(system.operating_region, dtype=float)
    signs = np.array(np.meshgrid(*([[-1.0, 1.0]] * half.size), indexing="ij")).reshape(
        half.size, -1
    )
    return system.operating_state + (signs.T * half)


def hybrid_claims(
    system: System,
    controller: Controller,
    lqr: Controller,
    certificate: Any,
    box: Any,
    seed: int = 0,
    starts: int = BASIN_STARTS,
    shell_starts: int = SHELL_STARTS,
    sweep_points: int = SWEEP_POINTS,
) -> dict[str, Any] | None:
    """The three comparisons of ``controller`` (a hybrid) with ``lqr`` as a JSON-friendly dict;
    None if ``controller`` is no hybrid or the LQR has no proved set.

    Parameters
    ----------
    system : System
    controller, lqr : callable
        The hybrid and the LQR at the same control period.
    certificate : LyapunovCertificate
        The LQR's (proved) certificate at that period.
    box : (S,) array
        Half-widths of the basin box.
    seed, starts, shell_starts, sweep_points : int
        The seed; the starts in the proved set and in the box (each); the starts per shell of
        V; the sizes of the impulse sweep (:func:`~leoc.evaluation.impulse_sweep.sweep_sizes`).

    Returns
    -------
    dict or None
        ``operating_region_max_v`` (largest V of the robustness box: below ``flat_top`` the
        nominal robustness episodes start inside the flat top), ``rho`` and its basis,
        ``flat_top``, ``lqr_failure_size``, ``impulse_sweep`` (per label, one entry per size;
        the first size is the paper's impulse test), ``shells`` and ``basin``.
    """
    if relevance_function(controller) is None or not certificate.certified:
        return None
    rho = float(certificate.rho)
    flat_top = flat_top_level(controller)
    failure = lqr_failure_size(system, lqr)
    labelled = {HYBRID_LABEL: controller, LQR_LABEL: lqr}
    sweep = impulse_sweep(system, labelled, sweep_sizes(failure, sweep_points))
    levels = shell_levels(rho, flat_top)
    shells = shell_robustness(system, controller, lqr, certificate.P, levels, shell_starts, seed)
    basin = _basin(system, controller, lqr, certificate, box, starts, seed)
    corners = operating_region_corners(system)
    return {
        "operating_region_max_v": float(certificate.value(corners).max()),
        "rho": rho,
        "rho_basis": certificate.basis,
        "flat_top": flat_top,
        "lqr_failure_size": failure,
        "impulse_sweep": {
            label: [_sweep_point(point) for point in pts] for label, pts in sweep.items()
        },
        "shells": [shell._asdict() for shell in shells],
        "basin": basin._asdict(),
    }


def _basin(
    system: System,
    controller: Controller,
    lqr: Controller,
    certificate: Any,
    box: Any,
    starts: int,
    seed: int,
) -> BasinComparison:
    """:func:`~leoc.evaluation.basins.basin_comparison` on ``starts`` seeded starts in the box,
    then as many in the proved set (one generator, in this order)."""
    rng = np.random.default_rng(seed)
    half = np.asarray(box, dtype=float)
    starts_box = system.operating_state + rng.uniform(-half, half, (starts, half.size))
    return basin_comparison(
        system, controller, lqr, certificate.sample(rng, starts), starts_box, half
    )


def _sweep_point(point: ImpulsePoint) -> dict[str, Any]:
    return {**point._asdict(), "by_construction": point.by_construction}
