"""A trained controller's proved region of attraction beside its LQR's.

:func:`proved_region` runs :func:`leoc.control.certify_controller` on one controller and
compares what it proves with the LQR's certificate
(:func:`leoc.policies.hybrid.lqr_certificate`), on one box of states around the operating
point a:

- the LQR's reference (:func:`lqr_reference`): the LQR proved with the same candidate V as
  the controller, the larger of its Riccati certificate (``lqr``) and the proof of its own
  linearisation's V (``own``), so that a ratio credits the controller, never the V;
- ``box_share``: the share of the box ``a +/- box`` inside the proved set (Monte Carlo, seeded:
  :func:`leoc.evaluation.basins.box_fraction`), and the LQR's on the same box and samples;
- ``volume_ratio``: the proved ellipsoid's volume over the LQR's (exact: from ``rho`` and
  ``det P``; it may exceed the box);
- the equilibrium ``offset`` ``x* - a``: a baseline's steady-state error (0 for a hybrid);
- what limited the proof and its seconds;
- for an ROA-relevance hybrid, whether its proved set lies inside its flat top
  ``{V_flat <= rho_in}`` (``flat_top_cover`` <= 1, :func:`flat_top_cover`): there r == 1,
  the hybrid is its saturated LQR, and its proved region is the LQR's by construction.

A proved share is a guarantee; the empirical basins of :mod:`leoc.evaluation.basins` (where the
controller is *seen* to converge) stay beside it as the sampled, larger, figure.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from leoc.control.proof import MAX_BOXES, MAX_SECONDS
from leoc.control.roa import DEFAULT_SAMPLES, LyapunovCertificate
from leoc.control.trained import (
    EQUILIBRIUM_TOL,
    PRACTICAL,
    ControllerCertificate,
    best_candidate,
    certify_controller,
    log_volume,
)
from leoc.evaluation.basins import box_fraction
from leoc.names import LYAPUNOV_CHOICES
from leoc.systems.base import System

__all__ = [
    "LQRReference",
    "describe_proved_region",
    "flat_top_cover",
    "lqr_reference",
    "proved_region",
    "refresh_lqr_reference",
]

REFERENCE_KEY = "lqr_lyapunov"
"""The entry's field naming the V of the LQR's reference; an entry without it was written when
the reference was the Riccati certificate alone (:func:`refresh_lqr_reference` updates it)."""
OLD_REFERENCE = "Riccati only"
"""What such an entry's reference V is called in text and tables (``leoc plot
--refresh-lqr-reference`` remakes the entry)."""


def _ratio(value: float, reference: float) -> float | None:
    """``value / reference``; None when the reference is 0 (nothing to compare with)."""
    return value / reference if reference > 0.0 else None


class LQRReference(NamedTuple):
    """The LQR's proved region a controller is compared with (:func:`lqr_reference`).

    Attributes
    ----------
    certificate : LyapunovCertificate
        The kept V's certificate (centred on a: the LQR's equilibrium).
    lyapunov : str
        Which V: ``lqr`` (its Riccati P) or ``own`` (its linearisation's discrete Lyapunov P).
    candidates : dict
        Every V tried: name -> ``{"rho", "log_volume"}``.
    """

    certificate: LyapunovCertificate
    lyapunov: str
    candidates: dict[str, dict[str, float]]


def lqr_reference(
    system: System,
    design: Any,
    riccati: LyapunovCertificate,
    saturation: str = "clip",
    *,
    lyapunov: str = "best",
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    max_seconds: float = MAX_SECONDS,
    device: Any = "cpu",
    max_boxes: int = MAX_BOXES,
) -> LQRReference:
    """The LQR proved as a controller is proved: with the Riccati V (``riccati``, its
    certificate) and, unless ``lyapunov == "lqr"``, with its own linearisation's V
    (:func:`leoc.control.certify_controller` of the saturated LQR,
    :func:`leoc.policies.hybrid.saturated_lqr`, ``lyapunov="own"``); the larger proved volume
    is kept (the Riccati V on a tie), only the own V with ``lyapunov == "own"``.

    A hybrid's linearisation at a is its LQR's (d pi/dx (a) = W), so its ``own`` V is its
    LQR's: measured against the Riccati certificate alone, the mountain car's hybrids proved
    1.46x their LQR's volume by the choice of V (docs/results.md). The other options are
    :func:`~leoc.control.certify_controller`'s, as the controller's proof got them.
    """
    from leoc.policies.hybrid import saturated_lqr

    if lyapunov not in LYAPUNOV_CHOICES:
        raise ValueError(f"lyapunov: expected one of {LYAPUNOV_CHOICES}, found {lyapunov!r}")
    candidates = {} if lyapunov == "own" else {"lqr": riccati}
    if lyapunov != "lqr":
        own = certify_controller(
            system,
            saturated_lqr(system, design, saturation),
            None,
            action_repeat=int(design.action_repeat),
            lyapunov="own",
            samples=samples,
            seed=seed,
            max_seconds=max_seconds,
            device=device,
            max_boxes=max_boxes,
        )
        candidates[own.lyapunov] = own.certificate
    kept = best_candidate(candidates)
    summary = {
        name: {"rho": entry.rho, "log_volume": log_volume(entry)}
        for name, entry in candidates.items()
    }
    return LQRReference(candidates[kept], kept, summary)


def _operating(system: System) -> np.ndarray:
    """The operating point a (float64): the centre of the box the shares are measured on."""
    return np.asarray(system.operating_state, dtype=float)


def _comparison(
    system: System,
    share: float,
    own_log_volume: float,
    reference: LQRReference,
    box: np.ndarray,
    seed: int,
) -> dict[str, Any]:
    """The LQR's share of the box and the ratios of the controller's (``share``, its proved
    set's; ``own_log_volume``, :func:`~leoc.control.trained.log_volume`) to the LQR's."""
    lqr_share, _ = box_fraction(reference.certificate, box, seed=seed, centre=_operating(system))
    own, lqr_volume = own_log_volume, log_volume(reference.certificate)
    volume_ratio = (
        math.exp(own - lqr_volume) if math.isfinite(own) and math.isfinite(lqr_volume) else None
    )
    if not math.isfinite(own) and math.isfinite(lqr_volume):
        volume_ratio = 0.0
    return {
        "lqr_box_share": lqr_share,
        "box_share_ratio": _ratio(share, lqr_share),
        "volume_ratio": volume_ratio,
        "lqr_rho": reference.certificate.rho,
        REFERENCE_KEY: reference.lyapunov,
        "lqr_candidates": reference.candidates,
    }


def _flat_top(controller: Any) -> tuple[float, np.ndarray] | None:
    """``rho_in`` and the matrix of an ROA relevance inside ``controller`` (None without)."""
    import torch

    from leoc.policies.relevance import ROARelevance

    modules = controller.modules() if isinstance(controller, torch.nn.Module) else ()
    for module in modules:
        if isinstance(module, ROARelevance):
            matrix = module.lyapunov_matrix.detach().cpu().numpy().astype(float)
            return float(module.rho_in), matrix
    return None


def flat_top_cover(controller: Any, proved: ControllerCertificate, offset: Any) -> float | None:
    r"""An upper bound on :math:`\max V_{flat}(x - a) / \rho_{in}` over the proved set
    :math:`\{(x - x^*)^\top P (x - x^*) \le \rho\}` of an ROA-relevance hybrid, whose
    relevance is 1 on :math:`\{V_{flat} \le \rho_{in}\}`; None for another controller or
    when nothing is proved. At most 1: r == 1 on the whole proved set.

    With :math:`d = x^* - a` (``offset``) and :math:`\lambda` the largest generalised
    eigenvalue of :math:`(P_{flat}, P)`, the triangle inequality in the :math:`P_{flat}` norm
    gives :math:`\sqrt{V_{flat}} \le \sqrt{d^\top P_{flat} d} + \sqrt{\lambda \rho}`
    (angles compared unwrapped: the proved set lies in the allowed region, well inside
    :math:`\pm\pi`).
    """
    found = _flat_top(controller)
    if found is None or not proved.rho > 0.0:
        return None
    rho_in, flat = found
    # lambda_max of P^-1 P_flat through the Cholesky factor of P (symmetric, no inverse)
    lower = np.linalg.cholesky(np.asarray(proved.certificate.P, dtype=float))
    scaled = np.linalg.solve(lower, np.linalg.solve(lower, flat).T)
    largest = float(np.linalg.eigvalsh(0.5 * (scaled + scaled.T)).max())
    shift = np.asarray(offset, dtype=float)
    reach = math.sqrt(max(0.0, float(shift @ flat @ shift))) + math.sqrt(largest * proved.rho)
    return reach**2 / rho_in


def proved_region(
    system: System,
    controller: Any,
    design: Any,
    lqr: LyapunovCertificate,
    box: Any,
    *,
    saturation: str = "clip",
    lyapunov: str = "best",
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    max_seconds: float = MAX_SECONDS,
    device: Any = "cpu",
    max_boxes: int = MAX_BOXES,
) -> dict[str, Any]:
    """The proved region of ``controller`` beside its LQR's (module docstring), JSON-friendly.

    Parameters
    ----------
    system, controller : System, callable
        The plant the controller was trained on; the loaded controller (float64 observations
        -> actions, at its own control period).
    design, lqr : LQRDesign, LyapunovCertificate
        Its LQR (the ``lqr`` candidate V) and the LQR's Riccati certificate (with the LQR's own
        V, the reference: :func:`lqr_reference`).
    box : (S,) half-widths
        The box around a the shares are measured on.
    saturation : str
        The controller's output squash (PILCO's ``sin``, else ``clip``), the reference LQR's.
    lyapunov, samples, seed, max_seconds, device, max_boxes :
        :func:`leoc.control.certify_controller`'s options, the controller's and the
        reference's; ``seed`` also seeds the box shares.

    Returns
    -------
    dict
        :meth:`~leoc.control.ControllerCertificate.summary` with ``box_share``, the
        comparison (:func:`lqr_reference`'s ``lqr_rho``, ``lqr_lyapunov``, ``lqr_candidates``;
        ``lqr_box_share``, ``box_share_ratio``, ``volume_ratio``), the flat top
        (:func:`flat_top_cover`), ``seconds`` and the ``device`` of the box search.
    """
    options = {"lyapunov": lyapunov, "samples": samples, "seed": seed}
    options.update(max_seconds=max_seconds, device=device, max_boxes=max_boxes)
    proved = certify_controller(system, controller, design, **options)
    reference = lqr_reference(system, design, lqr, saturation, **options)
    half = np.asarray(box, dtype=float)
    summary = proved.summary(system)
    found = _flat_top(controller)
    share, error = box_fraction(proved.certificate, half, seed=seed, centre=_operating(system))
    return {
        **summary,
        "box_share": share,
        "box_share_stderr": error,
        **_comparison(system, share, summary["log_volume"], reference, half, seed),
        "flat_top_rho": None if found is None else found[0],
        "flat_top_cover": flat_top_cover(controller, proved, summary["offset"]),
        "seconds": proved.seconds,
        "device": str(device),
    }


def refresh_lqr_reference(
    system: System,
    entry: dict[str, Any],
    design: Any,
    lqr: LyapunovCertificate,
    box: Any,
    *,
    seed: int = 0,
    samples: int = DEFAULT_SAMPLES,
) -> dict[str, Any]:
    """``entry`` (a :func:`proved_region` result written before the reference kept the LQR's
    own V) with its comparison remade against :func:`lqr_reference`, at the entry's
    ``saturation``, ``budget_seconds`` and ``budget_boxes``: the controller's proof and share
    are kept as they are (they do not depend on the reference), only the LQR's side is
    proved. An entry that already names its reference's V is returned unchanged."""
    if REFERENCE_KEY in entry:
        return entry
    budget = {
        "max_seconds": entry.get("budget_seconds") or MAX_SECONDS,
        "max_boxes": entry.get("budget_boxes") or MAX_BOXES,
    }
    saturation = entry.get("saturation", "clip")
    reference = lqr_reference(system, design, lqr, saturation, samples=samples, seed=seed, **budget)
    half = np.asarray(box, dtype=float)
    comparison = _comparison(system, entry["box_share"], entry["log_volume"], reference, half, seed)
    return {**entry, **comparison}


def _ratio_text(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3g}x"


def _reference_v(entry: dict[str, Any]) -> str:
    """The V the LQR's reference kept, for people (:data:`OLD_REFERENCE` for an old entry)."""
    return entry.get(REFERENCE_KEY, OLD_REFERENCE)


def _ultimate_set(system: System, entry: dict[str, Any]) -> str:
    """The practical claim's ultimate set in states, for people: its centre's offset from a
    and its half-widths ``sqrt(u (P^-1)_ii)``."""
    certificate = entry["certificate"]
    P = np.asarray(certificate["P"], dtype=float)
    half = np.sqrt(entry["ultimate_level"] * np.diag(np.linalg.inv(P)))
    centre = np.asarray(certificate["operating_state"], dtype=float)
    offset = centre - np.asarray(system.operating_state, dtype=float)
    names = system.state_names
    where = ", ".join(f"{name} {value:+.3g}" for name, value in zip(names, offset, strict=True))
    reach = ", ".join(f"{name} +/- {value:.3g}" for name, value in zip(names, half, strict=True))
    return f"about c - a = ({where}), within {reach}"


def _rejected(system: System, entry: dict[str, Any]) -> str:
    """Where the equilibrium search ended instead, for people (nothing for old entries)."""
    offset, residual = entry.get("rejected_offset"), entry.get("rejected_residual")
    if offset is None or residual is None:
        return ""
    pairs = ", ".join(
        f"{name} {value:+.3g}" for name, value in zip(system.state_names, offset, strict=True)
    )
    kind = (
        "a fixed point outside the operating region"
        if residual <= EQUILIBRIUM_TOL
        else (f"no fixed point: scaled residual {residual:.3g}")
    )
    return f"; the search ended at x - a = ({pairs}), {kind}"


def _practical_note(entry: dict[str, Any]) -> str:
    """``; practical stability: ...`` where a practical-stability proof was tried and failed
    (nothing for old entries, which never tried one)."""
    tried = entry.get("candidates", {}).get(PRACTICAL)
    if tried is None:
        return ""
    return f"; practical stability tried: limited by {tried.get('limited_by', 'unknown')}"


def describe_proved_region(system: System, label: str, entry: dict[str, Any]) -> list[str]:
    """Lines for people: the proved level, the equilibrium, the share of the box and the ratios
    to the LQR's, what limited the proof."""
    pairs = zip(system.state_names, entry["offset"], strict=True)
    offset = ", ".join(f"{name} {value:+.3g}" for name, value in pairs)
    where = f"x* - a = ({offset})"
    if not entry["equilibrium_found"]:
        where = f"none found near a{_rejected(system, entry)} (V centred on a)"
    if entry["rho"] > 0.0 and entry.get("claim") == "practical":
        proved = (
            f"PROVED PRACTICALLY STABLE: {{V <= {entry['rho']:.6g}}} invariant (V from the "
            f"{entry.get('practical_v') or entry['lyapunov']} P), every trajectory from it "
            f"enters and stays in {{V <= {entry['ultimate_level']:.3g}}}: "
            f"{_ultimate_set(system, entry)}; limited by {entry['limited_by']}"
        )
    elif entry["rho"] > 0.0:
        proved = (
            f"PROVED rho = {entry['rho']:.6g} (V from the {entry['lyapunov']} P), decrease on "
            f"{entry['excluded_level']:.3g} < V <= rho; limited by {entry['limited_by']}"
        )
    else:
        proved = f"NOTHING PROVED (limited by {entry['limited_by']}{_practical_note(entry)})"
    share, lqr_share = entry["box_share"], entry["lqr_box_share"]
    ratios = _ratio_text(entry["box_share_ratio"]), _ratio_text(entry["volume_ratio"])
    return [
        f"  {label}: {proved}",
        f"    equilibrium {where}",
        f"    proved set: {share:.1%} of the box (LQR's {lqr_share:.1%}, ratio {ratios[0]}); "
        f"volume {ratios[1]} the LQR's (LQR's V: {_reference_v(entry)}); "
        f"{entry['seconds']:.0f} s",
    ]
