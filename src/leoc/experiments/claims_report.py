"""Report section: hybrids against their LQR where the comparison can fail.

Reads the ``hybrid_claims`` entry of each run's ``evaluation.json``
(:func:`leoc.evaluation.hybrid_claims.hybrid_claims`) and writes one markdown section: which
comparisons hold by construction, the impulse sweep up to the LQR's failure size, held shares
from shells of V out to 3 rho, and each hybrid's basin against its LQR's. Shares are means over
the seeds that have the entry.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from leoc.experiments.markdown import markdown_table
from leoc.experiments.stats import percent

__all__ = ["claims_rows", "hybrid_claims_section", "roa_estimate_lines", "roa_method_text"]

Evaluations = Mapping[str, Mapping[str, Sequence[Mapping[str, Any]]]]
BY_CONSTRUCTION = "by construction"
EVIDENCE = "evidence"


def _proved(evaluations: Evaluations) -> bool:
    """Whether the runs' ROA certificates are proofs (runs written before issue 21 hold only
    the sampled estimate and no ``basis``)."""
    return any(
        (run.get("roa") or {}).get("certificate", {}).get("basis") == "proved"
        for by_controller in evaluations.values()
        for runs in by_controller.values()
        for run in runs
    )


def roa_method_text(evaluations: Evaluations) -> str:
    """The opening of the region-of-attraction paragraph: proved or sampled certificates."""
    if _proved(evaluations):
        return (
            "For each controller: the proved region of attraction of the LQR designed for the "
            "controller's period (V = (x - a)^T P (x - a) decreases along the nonlinear, "
            "saturated, held closed loop on {V <= rho}, proved by interval arithmetic on "
            "verified boxes, the set inside the allowed region; `leoc roa`), and the "
        )
    return (
        "For each controller: the sampling certificate of the region of attraction of the LQR "
        "designed for the controller's period (V = (x - a)^T P (x - a) decreases along the "
        "nonlinear, saturated, held closed loop on {V <= rho}; `leoc roa`), and the "
    )


def roa_estimate_lines(evaluations: Evaluations, first: Mapping[str, Any]) -> list[str]:
    """The sentence on the sampled estimate (the proof's target, or the certificate itself)."""
    if _proved(evaluations):
        return [
            f"The proof aims at a sampled estimate ({first['samples']} samples per round; with "
            f"confidence {first['confidence']:g} its violating share is below "
            f"{first['violation_bound']:.2g}); rho in the table is the proved level.",
            "",
        ]
    return [
        f"Certificates: {first['samples']} samples per round; with confidence "
        f"{first['confidence']:g} the violating share of the set is below "
        f"{first['violation_bound']:.2g}.",
        "",
    ]


def claims_rows(evaluations: Evaluations) -> list[dict[str, Any]]:
    """One row per (system, hybrid) with the runs' ``hybrid_claims`` entries."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller, runs in by_controller.items():
            claims = [run["hybrid_claims"] for run in runs if run.get("hybrid_claims")]
            if claims:
                rows.append({"system": system, "controller": controller, "claims": claims})
    return rows


def _mean(values: Sequence[float | None]) -> float | None:
    kept = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.mean(kept)) if kept else None


def _share(value: float | None) -> str:
    return "–" if value is None else percent(value)


def _basis(by_construction: Sequence[bool]) -> str:
    if all(by_construction):
        return BY_CONSTRUCTION
    if not any(by_construction):
        return EVIDENCE
    return f"{BY_CONSTRUCTION} in {sum(by_construction)}/{len(by_construction)} seeds"


CONSTRUCTION_HEADERS = (
    "system",
    "hybrid",
    "flat top (V <= rho_in)",
    "paper impulse (size 1)",
    "nominal robustness starts (max V / rho_in)",
)
IMPULSE_HEADERS = (
    "system",
    "hybrid",
    "LQR failure size",
    "sizes",
    "hybrid held",
    "LQR held",
    "by construction",
)
SHELL_HEADERS = (
    "system",
    "hybrid",
    "shell (V / rho)",
    "hybrid held",
    "LQR held",
    "left the flat top",
)
BASIN_HEADERS = (
    "system",
    "hybrid",
    "LQR's proved set held (left flat top)",
    "LQR's empirical basin held (left flat top)",
    "box held by the hybrid only",
    "volume outside the LQR's basin",
)


def _construction_cells(row: dict[str, Any]) -> list[str]:
    claims = row["claims"]
    first = claims[0]
    paper = [c["impulse_sweep"]["hybrid"][0]["by_construction"] for c in claims]
    if first["flat_top"] is None:
        flat, robust = "none (r < 1 off a)", EVIDENCE
    else:
        flat = f"{first['flat_top'] / first['rho']:.2g} rho"
        ratio = first["operating_region_max_v"] / first["flat_top"]
        robust = f"{BY_CONSTRUCTION} ({ratio:.2g})" if ratio <= 1.0 else f"{EVIDENCE} ({ratio:.2g})"
    return [row["system"], row["controller"], flat, _basis(paper), robust]


def _construction_lines(rows: list[dict[str, Any]]) -> list[str]:
    return markdown_table(CONSTRUCTION_HEADERS, [_construction_cells(row) for row in rows])


def _sweep_share(claims: Sequence[Mapping[str, Any]], label: str, index: int, key: str) -> float:
    """Share of seeds where the ``index``-th sweep point of ``label`` has ``key`` true."""
    return float(np.mean([c["impulse_sweep"][label][index][key] for c in claims]))


def _impulse_cells(row: dict[str, Any]) -> list[str]:
    claims = row["claims"]
    sizes = [p["size"] for p in claims[0]["impulse_sweep"]["hybrid"]]

    def shares(label: str, key: str) -> str:
        return ", ".join(_share(_sweep_share(claims, label, i, key)) for i in range(len(sizes)))

    failure = _mean([c["lqr_failure_size"] for c in claims])
    return [
        row["system"],
        row["controller"],
        "never" if failure is None else f"{failure:.3g}",
        ", ".join(f"{s:.3g}" for s in sizes),
        shares("hybrid", "held"),
        shares("lqr", "held"),
        shares("hybrid", "by_construction"),
    ]


def _impulse_lines(rows: list[dict[str, Any]]) -> list[str]:
    return markdown_table(IMPULSE_HEADERS, [_impulse_cells(row) for row in rows])


def _shell_lines(rows: list[dict[str, Any]]) -> list[str]:
    table = []
    for row in rows:
        claims = row["claims"]
        rho = claims[0]["rho"]
        for index, shell in enumerate(claims[0]["shells"]):
            entries = [c["shells"][index] for c in claims if index < len(c["shells"])]
            table.append(
                [
                    row["system"],
                    row["controller"],
                    f"[{shell['low'] / rho:.2g}, {shell['high'] / rho:.2g})",
                    _share(_mean([e["held"] for e in entries])),
                    _share(_mean([e["lqr_held"] for e in entries])),
                    _share(_mean([e["left_flat_top"] for e in entries])),
                ]
            )
    return markdown_table(SHELL_HEADERS, table)


def _basin_cells(row: dict[str, Any]) -> list[str]:
    basins = [c["basin"] for c in row["claims"]]
    mean = {key: _mean([b[key] for b in basins]) for key in basins[0] if key != "box"}
    volume = mean["outside_volume"]
    return [
        row["system"],
        row["controller"],
        f"{_share(mean['proved_set_held'])} ({_share(mean['proved_set_left_flat_top'])})",
        f"{_share(mean['lqr_basin_held'])} ({_share(mean['lqr_basin_left_flat_top'])})",
        _share(mean["outside_share"]),
        "–" if volume is None else f"{volume:.3g}",
    ]


def _basin_lines(rows: list[dict[str, Any]]) -> list[str]:
    return markdown_table(BASIN_HEADERS, [_basin_cells(row) for row in rows])


def hybrid_claims_section(evaluations: Evaluations) -> list[str]:
    """Markdown lines of the section (empty when no run has ``hybrid_claims``)."""
    rows = claims_rows(evaluations)
    if not rows:
        return []
    lines = [
        "",
        "## Hybrids against their LQR where the comparison can fail",
        "",
        "A hybrid pi = r G + (1 - r) H whose relevance stays r = 1 along a test applies its "
        "LQR G exactly: the comparison holds *by construction* and is no evidence. The ROA "
        "hybrids have r = 1 on the flat top V <= rho_in; the paper's relevance has r < 1 "
        "everywhere but at a. Which comparisons of the sections above are by construction "
        "(the paper impulse: r = 1 along the whole response in every seed; the nominal "
        "robustness starts: the operating-region box lies inside the flat top, largest V of "
        "its corners over rho_in <= 1):",
        "",
    ]
    lines += _construction_lines(rows)
    lines += [
        "",
        "**Impulse sweep.** Disturbances of growing size m (the integral of the action "
        "offset: one step of -m up to twice the actuator limit, then longer pulses; m = 1 is "
        "the paper's impulse) from the paper's size to the LQR's own failure size (the "
        "smallest m after which the LQR no longer holds the operating point). Per size: share "
        "of seeds held by the hybrid and by its LQR, and share of seeds where the hybrid's "
        "comparison is by construction (r = 1 all along).",
        "",
    ]
    lines += _impulse_lines(rows)
    lines += [
        "",
        "**Robustness starts in shells of V.** Starts uniform in shells of V of the LQR (at "
        "the hybrid's period) from the flat top rho_in (0 without one) to 3 rho, rho the "
        "LQR's proved level: outside the proved set towards the LQR's empirical basin edge. "
        "Hybrid and LQR from the same seeded starts; 'left the flat top': share of starts "
        "whose hybrid trajectory has r < 1 somewhere (where the comparison is evidence).",
        "",
    ]
    lines += _shell_lines(rows)
    lines += [
        "",
        "**Basins against the LQR's.** Share of starts uniform in the LQR's proved set that "
        "the hybrid holds; share of the LQR's empirical basin (box starts the LQR holds) that "
        "the hybrid holds; share of the basin box held by the hybrid and not by the LQR, and "
        "that share times the box volume (where the learned part adds reach). In brackets: "
        "share of those starts whose hybrid trajectory leaves r = 1.",
        "",
    ]
    lines += _basin_lines(rows)
    return lines
