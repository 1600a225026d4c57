"""Which choice makes each difference in appendix D's Linear row: one field switched at a time.

Prints, per system, the impulse response of the linear reference under the authors' variant
with one of its choices set back to leoc's, and under leoc's defaults with one authors' choice
switched on, each measured with both metric sets (leoc's: final-window mean, band 2 % of the
peak; the authors': last sample, band pi/180), beside the paper's printed row. Seconds to run::

    python benchmarks/bench_authors_linear.py
"""

from __future__ import annotations

from leoc.experiments.linear import linear_row_ablation
from leoc.experiments.paper import PAPER_IMPULSE_METRICS


def _settling(value: int | None) -> str:
    return "-" if value is None else str(value)


def main() -> None:
    rows = linear_row_ablation()
    header = (
        f"{'configuration':50s} | {'authors: SSE':>11s} {'overshoot':>9s} {'settle':>6s} | "
        f"{'leoc: SSE':>10s} {'peak':>9s} {'settle':>6s}"
    )
    system = None
    for row in rows:
        if row.system != system:
            system = row.system
            paper = PAPER_IMPULSE_METRICS[system]["linear"]
            print(
                f"\n{system} (paper: SSE {paper.steady_state_error[0]:.3g}, overshoot "
                f"{paper.overshoot[0]:.3g}, settling {paper.settling_time[0]:.0f})"
            )
            print(header)
        a, lm = row.authors, row.leoc
        print(
            f"{row.label:50s} | {a.steady_state_error:11.3g} {a.overshoot:9.3g} "
            f"{_settling(a.settling_time):>6s} | {lm.steady_state_error:10.3g} "
            f"{lm.peak_deviation:9.3g} {_settling(lm.settling_time):>6s}"
        )


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
