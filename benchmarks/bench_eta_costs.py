"""The ``leoc reproduce`` cost tables, measured on the published studies, and how close the ETA
comes with them.

Prints, as Python for :mod:`leoc.experiments.profiles`, each kind's median wall time
(:func:`leoc.experiments.eta.measured_run_seconds`) in ``results/paper`` (leoc's variant:
``PAPER_RUN_SECONDS``) and ``results/paper-authors`` (the authors': ``AUTHORS_RUN_SECONDS``),
and each learner's (:func:`~leoc.experiments.eta.measured_learner_seconds`) in
``results/paper``: ``FALLBACK_RUN_SECONDS``. ``tests/test_eta_costs.py`` checks the committed
tables still equal these.

Then replays each study (:func:`leoc.experiments.eta.replay`): its runs in the order ``leoc
reproduce`` starts them under the committed table of its variant, each taking the wall time it
took, dealt to the study's workers, an ETA every ``--interval`` seconds with a factor per
learner (as ``leoc reproduce``), DDPG's and SAC's logs telling their fraction done. It prints
the first report's error (ETA over the time actually left, minus 1), the median and 90th
percentile of the absolute error over the reports. The tables are measured on these very runs,
so the replay is in sample: it measures the table's staleness, not a new machine's.

Usage::

    python benchmarks/bench_eta_costs.py [--interval 15]
"""

from __future__ import annotations

import argparse
import json
import pprint
import statistics
from pathlib import Path
from typing import NamedTuple

from leoc.experiments.eta import (
    Finished,
    measured_learner_seconds,
    measured_run_seconds,
    replay,
    run_times,
)
from leoc.experiments.layout import META_FILE
from leoc.experiments.profiles import get_profile, run_specs

STUDIES = {"PAPER_RUN_SECONDS": Path("results/paper")}
VARIANT_STUDIES = {"AUTHORS_RUN_SECONDS": Path("results/paper-authors")}
FALLBACK_STUDY = Path("results/paper")
REPORTS_PROGRESS = ("ddpg", "td3", "sac")  # learners whose log says the fraction done


class ReplayError(NamedTuple):
    """The replayed ETA's relative error (ETA over the time actually left, minus 1): at the
    first report, and the median and 90th percentile of its absolute value over the reports."""

    first: float
    median: float
    p90: float


def replay_errors(folder: Path, interval: float) -> ReplayError:
    """The ETA's relative error on ``folder``'s runs, replayed with the committed table of its
    variant (see the module docstring)."""
    meta = json.loads((folder / META_FILE).read_text())
    profile = get_profile(meta["profile"], len(meta["seeds"])).for_variant(meta["variant"])
    specs = run_specs(profile, tuple(meta["systems"]), tuple(meta["controllers"]))
    walls = {(run.system, run.controller, run.seed): run.wall_seconds for run in run_times(folder)}
    # the studies ran before the proof and the protocol: their costs without them
    runs = [Finished(profile.training_seconds(spec), walls[spec], spec.framework) for spec in specs]
    points = replay(runs, int(meta["jobs"]), interval, REPORTS_PROGRESS)
    errors = [(point.eta - point.remaining) / point.remaining for point in points]
    absolute = [abs(error) for error in errors]
    return ReplayError(
        errors[0], statistics.median(absolute), statistics.quantiles(absolute, n=10)[-1]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--interval", type=float, default=15.0, help="seconds between reports")
    args = parser.parse_args()
    for name, folder in {**STUDIES, **VARIANT_STUDIES}.items():
        print(f"# {folder}: {len(run_times(folder))} runs")
        print(f"{name} = {pprint.pformat(measured_run_seconds(folder), sort_dicts=False)}")
    print(f"# {FALLBACK_STUDY}: each learner's runs")
    print(f"FALLBACK_RUN_SECONDS = {measured_learner_seconds(FALLBACK_STUDY)}")
    print()
    for folder in dict.fromkeys([*STUDIES.values(), *VARIANT_STUDIES.values()]):
        errors = replay_errors(folder, args.interval)
        print(
            f"{folder}: ETA error at the first report {errors.first:+.1%}, "
            f"median {errors.median:.1%}, 90th percentile {errors.p90:.1%} "
            f"(a report every {args.interval:g} s)"
        )


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
