"""Appendix D row by row: the paper, leoc's authors' variant and leoc's defaults, with a verdict.

Reads two reproduce (or published) folders, one per implementation variant, and prints, for
every row of the paper's appendix D and each of its three metrics, the paper's mean ± std and
each variant's mean ± std under the authors' metric set, then whether the variant reproduces
the paper's number within the seed spread.

Runs evaluated before leoc recorded the authors' metrics (``metrics_authors``) are measured here
from their stored impulse traces (``responses.impulse.deviation``, leoc's wrapped deviation,
mapped to the authors' arcsin(sin e) in degrees), over the length of the stored record; the
table says so ("from traces", and the record length when it is not the authors' one).

Verdict per metric: :func:`leoc.experiments.appendix_d.metric_verdict` (the rule the report's
appendix-D section applies; *yes* when the metric agrees, else why not). A row reproduces when
its three metrics do.

Run: ``python scripts/appendix_d_verdicts.py results/paper-authors results/paper``
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from leoc.evaluation.metrics import (
    MetricsSummary,
    ResponseMetrics,
    authors_response_metrics,
    summarise_metrics,
)
from leoc.experiments.appendix_d import (
    AGREES,
    APPENDIX_CONTROLLERS,
    VARIANT_HEADERS,
    VARIANT_ORDER,
    metric_verdict,
)
from leoc.experiments.layout import META_FILE
from leoc.experiments.paper import PAPER_IMPULSE_METRICS
from leoc.experiments.report import load_evaluations
from leoc.systems import make_system

METRICS = ("steady_state_error", "overshoot", "settling_time")


def run_metrics(system: str, run: dict) -> tuple[ResponseMetrics, str]:
    """The authors' impulse metrics of one run, recorded or recomputed from its trace."""
    impulse = run["responses"]["impulse"]
    if impulse.get("metrics_authors") is not None:
        return ResponseMetrics(**impulse["metrics_authors"]), "recorded"
    spec = make_system(system)
    e = np.asarray(impulse["deviation"], dtype=float)
    if spec.main_in_degrees:
        e = np.degrees(np.arcsin(np.sin(np.radians(e))))
    terminated = bool(impulse["metrics"].get("terminated", False))
    return authors_response_metrics(e, terminated=terminated), f"from {e.size}-step traces"


def summaries(folder: Path) -> tuple[str, dict[tuple[str, str], tuple[MetricsSummary, str]]]:
    meta = json.loads((folder / META_FILE).read_text())
    found = {}
    for system, controllers in load_evaluations(folder, meta).items():
        for controller, runs in controllers.items():
            measured = [run_metrics(system, run) for run in runs]
            sources = sorted({source for _, source in measured})
            found[system, controller] = (
                summarise_metrics([m for m, _ in measured]),
                ", ".join(sources),
            )
    return meta.get("variant", "leoc"), found


def mean_std(summary: MetricsSummary, metric: str) -> tuple[float, float] | None:
    if metric == "settling_time":
        if summary.n_settled == 0:
            return None
        return summary.settling_time_mean, summary.settling_time_std
    return getattr(summary, f"{metric}_mean"), getattr(summary, f"{metric}_std")


def cell(value) -> str:
    if value is None:
        return "-"
    mean, std = value
    return f"{mean:.3g} ± {abs(std):.2g}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path, help="reproduce folders, one per variant")
    parser.add_argument(
        "--rows",
        action="store_true",
        help="one line per row of appendix D (the three metrics joined by ' / ') instead of one "
        "per metric",
    )
    args = parser.parse_args()
    by_variant = dict(summaries(folder) for folder in args.folders)
    variants = [v for v in VARIANT_ORDER if v in by_variant]
    header = ["system", "controller"] + ([] if args.rows else ["metric"]) + ["paper"]
    for v in variants:
        header += [VARIANT_HEADERS[v], "reproduces"]
    if args.rows:
        header[2:] = [
            h + " (SSE / overshoot / settling)" if i % 2 == 0 else h
            for i, h in enumerate(header[2:])
        ]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    rows_ok = {v: [] for v in variants}
    notes = set()
    for system, papers in PAPER_IMPULSE_METRICS.items():
        for controller in APPENDIX_CONTROLLERS:
            paper = papers[controller]
            ok = {v: True for v in variants}
            metric_cells = []
            for metric in METRICS:
                p = getattr(paper, metric)
                cells = [system, controller, metric, cell(p)]
                for v in variants:
                    entry = by_variant[v].get((system, controller))
                    if entry is None:
                        cells += ["not run", "-"]
                        ok[v] = None
                        continue
                    summary, source = entry
                    if source != "recorded":
                        notes.add(f"{VARIANT_HEADERS[v]}: {system} {source}")
                    m = mean_std(summary, metric)
                    word = metric_verdict(paper, metric, summary)
                    good = word == AGREES
                    word = "yes" if good else word
                    if ok[v] is not None:
                        ok[v] = ok[v] and good
                    shown = cell(m) if m else f"not settled (0/{summary.n_runs})"
                    if metric == "settling_time" and m and summary.n_settled < summary.n_runs:
                        shown += f" ({summary.n_settled}/{summary.n_runs})"
                    cells += [shown, word]
                metric_cells.append(cells[3:])
                if not args.rows:
                    print("| " + " | ".join(cells) + " |")
            if args.rows:
                joined = [" / ".join(column) for column in zip(*metric_cells, strict=True)]
                for i, v in enumerate(variants):
                    if ok[v] is not None:
                        joined[2 + 2 * i] = "**yes**" if ok[v] else "no (" + joined[2 + 2 * i] + ")"
                print("| " + " | ".join([system, controller, *joined]) + " |")
            for v in variants:
                rows_ok[v].append((system, controller, ok[v]))
    print()
    for v in variants:
        good = [f"{s} {c}" for s, c, k in rows_ok[v] if k]
        bad = [f"{s} {c}" for s, c, k in rows_ok[v] if k is False]
        print(f"{VARIANT_HEADERS[v]}: {len(good)} of {len(good) + len(bad)} rows reproduce")
        print(f"  reproduce: {', '.join(good) or 'none'}")
        print(f"  do not: {', '.join(bad) or 'none'}")
    for note in sorted(notes):
        print(f"note: {note}")


if __name__ == "__main__":
    main()
