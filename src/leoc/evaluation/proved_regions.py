"""A trained controller's proved region of attraction beside its LQR's.

:func:`proved_region` runs :func:`leoc.control.certify_controller` on one controller and
compares what it proves with the LQR's certificate
(:func:`leoc.policies.hybrid.lqr_certificate`), on one box of states around the operating
point a:

- ``box_share``: the share of the box ``a +/- box`` inside the proved set (Monte Carlo, seeded:
  :func:`leoc.evaluation.basins.box_fraction`), and the LQR's on the same box and samples;
- ``volume_ratio``: the proved ellipsoid's volume over the LQR's (exact: from ``rho`` and
  ``det P``; it may exceed the box);
- the equilibrium ``offset`` ``x* - a``: a baseline's steady-state error (0 for a hybrid);
- what limited the proof and its seconds.

A proved share is a guarantee; the empirical basins of :mod:`leoc.evaluation.basins` (where the
controller is *seen* to converge) stay beside it as the sampled, larger, figure.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from leoc.control.proof import MAX_SECONDS
from leoc.control.roa import DEFAULT_SAMPLES, LyapunovCertificate
from leoc.control.trained import ControllerCertificate, certify_controller, log_volume
from leoc.evaluation.basins import box_fraction
from leoc.systems.base import System

__all__ = ["describe_proved_region", "proved_region"]


def _ratio(value: float, reference: float) -> float | None:
    """``value / reference``; None when the reference is 0 (nothing to compare with)."""
    return value / reference if reference > 0.0 else None


def _comparison(
    system: System,
    proved: ControllerCertificate,
    lqr: LyapunovCertificate,
    box: np.ndarray,
    seed: int,
) -> dict[str, Any]:
    """Box shares of the controller's and the LQR's proved sets, and their ratios."""
    operating = np.asarray(system.operating_state, dtype=float)
    share, error = box_fraction(proved.certificate, box, seed=seed, centre=operating)
    lqr_share, _ = box_fraction(lqr, box, seed=seed, centre=operating)
    own, reference = log_volume(proved.certificate), log_volume(lqr)
    volume_ratio = (
        math.exp(own - reference) if math.isfinite(own) and math.isfinite(reference) else None
    )
    if not math.isfinite(own) and math.isfinite(reference):
        volume_ratio = 0.0
    return {
        "box_share": share,
        "box_share_stderr": error,
        "lqr_box_share": lqr_share,
        "box_share_ratio": _ratio(share, lqr_share),
        "volume_ratio": volume_ratio,
        "lqr_rho": lqr.rho,
    }


def proved_region(
    system: System,
    controller: Any,
    design: Any,
    lqr: LyapunovCertificate,
    box: Any,
    *,
    lyapunov: str = "best",
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    max_seconds: float = MAX_SECONDS,
    device: Any = "cpu",
) -> dict[str, Any]:
    """The proved region of ``controller`` beside its LQR's (module docstring), JSON-friendly.

    Parameters
    ----------
    system : System
        The plant the controller was trained on.
    controller : callable
        A loaded controller (float64 observations -> actions, at its own control period).
    design : LQRDesign
        Its LQR (the ``lqr`` candidate V).
    lqr : LyapunovCertificate
        The LQR's certificate (the reference of the ratios).
    box : (S,) half-widths
        The box around a the shares are measured on.
    lyapunov, samples, seed, max_seconds, device :
        :func:`leoc.control.certify_controller`'s options; ``seed`` also seeds the box shares.

    Returns
    -------
    dict
        :meth:`~leoc.control.ControllerCertificate.summary` with the comparison
        (``box_share``, ``lqr_box_share``, ``box_share_ratio``, ``volume_ratio``),
        ``seconds`` and the ``device`` of the box search.
    """
    proved = certify_controller(
        system,
        controller,
        design,
        lyapunov=lyapunov,
        samples=samples,
        seed=seed,
        max_seconds=max_seconds,
        device=device,
    )
    half = np.asarray(box, dtype=float)
    return {
        **proved.summary(system),
        **_comparison(system, proved, lqr, half, seed),
        "seconds": proved.seconds,
        "device": str(device),
    }


def _ratio_text(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3g}x"


def describe_proved_region(system: System, label: str, entry: dict[str, Any]) -> list[str]:
    """Lines for people: the proved level, the equilibrium, the share of the box and the ratios
    to the LQR's, what limited the proof."""
    pairs = zip(system.state_names, entry["offset"], strict=True)
    offset = ", ".join(f"{name} {value:+.3g}" for name, value in pairs)
    where = f"x* - a = ({offset})"
    if not entry["equilibrium_found"]:
        where = "none found near a (V centred on a: practical stability at best)"
    if entry["rho"] > 0.0:
        proved = (
            f"PROVED rho = {entry['rho']:.6g} (V from the {entry['lyapunov']} P), decrease on "
            f"{entry['excluded_level']:.3g} < V <= rho; limited by {entry['limited_by']}"
        )
    else:
        proved = f"NOTHING PROVED (limited by {entry['limited_by']})"
    share, lqr_share = entry["box_share"], entry["lqr_box_share"]
    ratios = _ratio_text(entry["box_share_ratio"]), _ratio_text(entry["volume_ratio"])
    return [
        f"  {label}: {proved}",
        f"    equilibrium {where}",
        f"    proved set: {share:.1%} of the box (LQR's {lqr_share:.1%}, ratio {ratios[0]}); "
        f"volume {ratios[1]} the LQR's; {entry['seconds']:.0f} s",
    ]
