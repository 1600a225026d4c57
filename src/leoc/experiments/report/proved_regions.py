"""The report's proved regions of the trained controllers: each run's own closed loop proved
beside its LQR's (``evaluation.json``'s ``proved_region``,
:func:`leoc.experiments.evaluators.evaluate_proved_region`), and the check that every hybrid
keeps its LQR's proved share of the basin box."""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from leoc.evaluation.proved_regions import OLD_REFERENCE, REFERENCE_KEY
from leoc.experiments.claims_report import BY_CONSTRUCTION, EVIDENCE
from leoc.experiments.layout import Evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.report.base import (
    FMT,
    Check,
    Report,
    Rows,
    Section,
    Study,
    flag_block,
    label,
    ordered,
)
from leoc.experiments.report.responses import RELATIVE_TOLERANCE
from leoc.experiments.stats import percent
from leoc.experiments.summary import Failure
from leoc.names import parse_controller
from leoc.systems import make_system

KEY = "proved_region"
"""The runs' entry the section reads (``evaluation.json``)."""
COVER_ROUNDING = 1e-9
"""A flat-top cover (:func:`leoc.evaluation.proved_regions.flat_top_cover`) up to 1 plus this
counts as r == 1 on the whole proved set (round-off of the bound)."""
ZERO_OFFSET = 1e-12
"""An equilibrium offset entry at most this large (in its state's unit) prints as 0."""
NOT_MEASURED = (
    "Not measured for these runs: they were written before `leoc reproduce` proved the "
    "trained controllers' own regions (`leoc roa --controller RUN_DIR --prove` proves one run)."
)
"""The section's text for a study whose runs have no ``proved_region`` entry."""
HEADERS = (
    "system",
    "controller",
    "seeds",
    "V kept",
    "proved rho",
    "share of the box",
    "LQR's share",
    "LQR's V",
    "ratio to the LQR's share",
    "volume / the LQR's",
    "x* - a",
    "limited by",
    "by construction",
)


def _spread(values: list[float]) -> dict[str, float]:
    """Median, least and largest of ``values``."""
    return {
        "median": float(np.median(values)),
        "min": float(np.min(values)),
        "max": float(np.max(values)),
    }


def _by_construction(entry: dict[str, Any]) -> bool:
    """Whether the proved set lies inside the hybrid's flat top (r == 1 on all of it)."""
    cover = entry.get("flat_top_cover")
    return cover is not None and cover <= 1.0 + COVER_ROUNDING


def _kept(entry: dict[str, Any]) -> str:
    """The V kept, ``lqr (practical)`` where it proved practical stability only (an invariant
    set attracted to an inner one: :mod:`leoc.control.trained`)."""
    practical = entry.get("claim") == "practical" and entry["rho"] > 0.0
    return f"{entry['lyapunov']} (practical)" if practical else entry["lyapunov"]


def _row(system: str, controller: str, entries: list[dict[str, Any]]) -> dict[str, Any]:
    """One controller's proved regions over its seeds (``entries``, seed order)."""
    ratios = [e["box_share_ratio"] for e in entries if e["box_share_ratio"] is not None]
    volumes = [e["volume_ratio"] for e in entries if e.get("volume_ratio") is not None]
    found = [e for e in entries if e.get("equilibrium_found", True)]
    return {
        "system": system,
        "controller": controller,
        "n_runs": len(entries),
        "rho": _spread([e["rho"] for e in entries]),
        "box_share": _spread([e["box_share"] for e in entries]),
        "lqr_box_share": _spread([e["lqr_box_share"] for e in entries]),
        "box_share_ratio": _spread(ratios) if ratios else None,
        "box_share_ratios": [e["box_share_ratio"] for e in entries],
        "volume_ratio": _spread(volumes) if volumes else None,
        "offset_median": np.median([e["offset"] for e in found], axis=0).tolist()
        if found
        else None,
        "equilibria_found": len(found),
        "lyapunov": dict(Counter(_kept(e) for e in entries)),
        "lqr_lyapunov": dict(Counter(e.get(REFERENCE_KEY, OLD_REFERENCE) for e in entries)),
        "limited_by": dict(Counter(e["limited_by"] for e in entries)),
        "by_construction": [_by_construction(e) for e in entries],
        "seconds_median": float(np.median([e["seconds"] for e in entries])),
        "budget_seconds": sorted({e.get("budget_seconds") for e in entries}, key=str),
        "budget_boxes": sorted({e.get("budget_boxes") for e in entries}, key=str),
        "saturation": sorted({e.get("saturation", "clip") for e in entries}),
    }


def proved_region_summary(evaluations: Evaluations) -> Rows:
    """Rows: system, controller, over the seeds with an entry: the proved level, the proved
    set's share of the basin box, the LQR's, their ratio, the proved volume over the LQR's
    (median, least, largest; None where no run recorded it), the equilibrium offset (median
    per state over the seeds whose search found one, None if none did), the V kept and what
    limited the proof (counts), and per seed whether the proved set lies in the hybrid's flat
    top (by construction)."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in ordered(by_controller):
            entries = [run[KEY] for run in by_controller[controller] if run.get(KEY)]
            if entries:
                rows.append(_row(system, controller, entries))
    return rows


def measured(evaluations: Evaluations) -> bool:
    """Whether any run of the study has the entry (None for an LQR counts: it was measured)."""
    return any(
        KEY in run for by_c in evaluations.values() for runs in by_c.values() for run in runs
    )


def _failures(rows: Rows) -> tuple[int, list[Failure]]:
    """The hybrids with a ratio, and those whose proved share of the box is below
    ``1 - RELATIVE_TOLERANCE`` of their LQR's on some seed (size: 1 - the least ratio)."""
    checked = [
        row
        for row in rows
        if parse_controller(row["controller"]).hybrid and row["box_share_ratio"] is not None
    ]
    failures = []
    for row in checked:
        least = row["box_share_ratio"]["min"]
        if least >= 1.0 - RELATIVE_TOLERANCE:
            continue
        subject = f"{row['system']} {label(row['controller'])}"
        limits = _counts(row["limited_by"], row["n_runs"])
        failures.append(
            Failure(
                subject,
                1.0 - least,
                f"proves {least:.3g}x its LQR's share",
                f"limited by {limits}",
                f"**{subject}** proves as little as {least:.3g}x its LQR's share of the basin "
                f"box ({percent(row['box_share']['min'])} against "
                f"{percent(row['lqr_box_share']['median'])}; limited by {limits}).",
            )
        )
    return len(checked), failures


#: The check: every hybrid's proved share of the basin box is its LQR's (within 1%) on every seed.
PROVED_REGION_CHECK = Check(
    "proved_regions",
    _failures,
    cases="hybrids",
    threshold=f"its proved share of the basin box at least {1 - RELATIVE_TOLERANCE:.0%} of its "
    "LQR's on every seed; size: 1 - the least ratio",
    worked="keep their LQR's proved region",
)


def _span(spread: dict[str, float] | None, show: Any = FMT.format) -> str:
    """``median [least, largest]`` (the median alone when they agree), ``–`` for None."""
    if spread is None:
        return "–"
    if spread["min"] == spread["max"]:
        return show(spread["median"])
    return f"{show(spread['median'])} [{show(spread['min'])}, {show(spread['max'])}]"


def _counts(counts: dict[str, int], total: int) -> str:
    """``lqr`` when every seed agrees, else ``lqr 3/5, own 2/5``."""
    if len(counts) == 1:
        return next(iter(counts))
    return ", ".join(f"{name} {count}/{total}" for name, count in counts.items())


def _offset(row: dict[str, Any]) -> str:
    """The nonzero entries of the median ``x* - a`` by state name (``0`` when there are none),
    and the seeds whose equilibrium search found none near a."""
    missing = row["n_runs"] - row["equilibria_found"]
    if row["offset_median"] is None:
        return "none found"
    names = make_system(row["system"]).state_names
    shown = [
        f"{name} {value:+.3g}"
        for name, value in zip(names, row["offset_median"], strict=True)
        if abs(value) > ZERO_OFFSET
    ]
    text = ", ".join(shown) if shown else "0"
    return f"{text} (none found in {missing}/{row['n_runs']} seeds)" if missing else text


def _basis(row: dict[str, Any]) -> str:
    """Whether a hybrid's proved region is its LQR's by construction (– for a baseline)."""
    if not parse_controller(row["controller"]).hybrid:
        return "–"
    flags = row["by_construction"]
    if all(flags):
        return BY_CONSTRUCTION
    if not any(flags):
        return EVIDENCE
    return f"{BY_CONSTRUCTION} in {sum(flags)}/{len(flags)} seeds"


def _cells(row: dict[str, Any]) -> list[str]:
    return [
        row["system"],
        label(row["controller"]),
        str(row["n_runs"]),
        _counts(row["lyapunov"], row["n_runs"]),
        _span(row["rho"]),
        _span(row["box_share"], percent),
        _span(row["lqr_box_share"], percent),
        _counts(row.get("lqr_lyapunov", {OLD_REFERENCE: row["n_runs"]}), row["n_runs"]),
        _span(row["box_share_ratio"], lambda value: f"{FMT.format(value)}x"),
        _span(row["volume_ratio"], lambda value: f"{FMT.format(value)}x"),
        _offset(row),
        _counts(row["limited_by"], row["n_runs"]),
        _basis(row),
    ]


def proved_region_table(rows: Rows, study: str | None = None) -> list[str]:
    """Markdown rows of the proved-region table (:data:`HEADERS`); with ``study``, a first
    column names it on every row (several studies' in one table:
    :func:`leoc.experiments.markdown.stacked_tables`)."""
    if study is None:
        return markdown_table(HEADERS, [_cells(row) for row in rows])
    return markdown_table(("study", *HEADERS), [[study, *_cells(row)] for row in rows])


def _budget_text(rows: Rows) -> str:
    """The proof budget and the proofs' times, from the rows."""
    budgets = sorted({b for row in rows for b in row["budget_seconds"] if b is not None})
    times = [row["seconds_median"] for row in rows]
    budget = " / ".join(f"{FMT.format(b)} s" for b in budgets) or "an unrecorded budget"
    boxes = sorted({b for row in rows for b in row.get("budget_boxes", []) if b is not None})
    if boxes:
        budget = f"{' / '.join(f'{b:,}' for b in boxes)} boxes per candidate V within {budget}"
    took = FMT.format(min(times))
    if max(times) > min(times):
        took += f"-{FMT.format(max(times))}"
    return (
        f"Budget: {budget} of box search per run (past it the level proved so far is kept: "
        f"'limited by budget'); the proofs took {took} s (median per controller)."
    )


def compute(study: Study) -> dict[str, Any]:
    """The ``proved_regions`` table (:func:`proved_region_summary`)."""
    return {"proved_regions": proved_region_summary(study.evaluations)}


METHOD = (
    "For each trained controller, its own closed loop (at its control period, through its "
    "network on intervals) proved as `leoc roa --controller RUN_DIR --prove` proves it "
    "(`leoc.control.certify_controller`): its equilibrium x* near a, then "
    "V = (x - x*)^T P (x - x*) with P the LQR's Riccati matrix (`lqr`) or the discrete "
    "Lyapunov matrix of its own linearisation (`own`), whichever proves the larger ellipsoid "
    "('V kept'); rho is the proved level, in the units of that V. Beside it, the proved region "
    "of its LQR (at the controller's period, saturated as the controller's output is: PILCO's "
    "sin, else the clip), proved with the same two candidate V, the larger kept ('LQR's V'; a "
    "hybrid's linearisation at a is its LQR's, so a V the LQR could use earns the hybrid "
    "nothing), on the same seeded samples of the basin box of the region-of-"
    "attraction section: the share of the box inside each proved set, and their ratio; and the "
    "proved ellipsoid's volume over the LQR's (exact, from rho and det P; it tells apart "
    "controllers whose proved sets both cover the whole box, and counts states outside it). "
    "x* - a is the equilibrium's offset (a baseline's steady-state error; 0 for a hybrid, "
    "whose pi(a) = G(a)). Cells: median [least, largest] over seeds. A hybrid whose proved set "
    "lies inside its relevance's flat top (r == 1 on all of it: the ROA relevance) is its "
    "saturated LQR there, so its proved region is its LQR's *by construction* and no evidence; "
    "the paper's and the Lyapunov relevance have r < 1 everywhere but at a (evidence)."
)
"""The section's opening paragraph."""


def render(report: Report) -> list[str]:
    """``## Proved regions of the trained controllers``: the method, the budget, what failed,
    the table; or that the runs did not measure it."""
    rows = report.tables["proved_regions"]
    lines = ["", "## Proved regions of the trained controllers", ""]
    if not measured(report.study.evaluations):
        return [*lines, NOT_MEASURED]
    if not rows:
        return [*lines, "No trained controller in these runs (the LQRs' regions are above)."]
    lines += [METHOD, "", _budget_text(rows), ""]
    lines += flag_block(
        report.flags["proved_regions"], "every hybrid keeps its LQR's proved region."
    )
    return lines + proved_region_table(rows)


SECTION = Section(render, compute, PROVED_REGION_CHECK)
