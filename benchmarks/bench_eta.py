"""How close the ``leoc reproduce`` ETA comes to the time actually left, replayed on a finished
reproduce folder.

The runs of the folder's profile are dealt to ``--jobs`` workers in the order ``leoc reproduce``
starts them, each taking the wall time it took (its ``evaluation.json``), so the replay knows
when everything really ended. At each report time (1, 2, 5, 10, 20 ... minutes) it computes the
ETA the sweep would print (:func:`leoc.experiments.eta.estimate_remaining`) from the expected
costs and what has happened by then: runs finished (their wall times), runs running (their
elapsed time and, as their logs would say, the fraction done, taken as elapsed / wall time:
training progresses about evenly), runs queued.

The expected costs: the profile's measured table (``--costs profile``), or, to avoid judging the
table on the very runs it was measured from, the median over the *other* seeds of each kind
(``--costs other-seeds``, the default; needs at least two seeds).

Usage::

    python benchmarks/bench_eta.py [results/paper] [--jobs 2] [--costs other-seeds|profile]
"""

from __future__ import annotations

import argparse
import heapq
import json
import statistics
from pathlib import Path

from leoc.experiments.eta import Finished, Running, estimate_remaining
from leoc.experiments.profiles import get_profile, run_specs
from leoc.experiments.sweep import format_seconds

REPORT_MINUTES = (1, 2, 5, 10, 20, 30, 45, 60, 75, 90)
TARGET = 0.25


def wall_times(folder: Path) -> dict[tuple[str, str, int], float]:
    """(system, controller, seed) -> wall seconds of every finished run of ``folder``."""
    found = {}
    for path in folder.glob("runs/*/*/seed*/evaluation.json"):
        data = json.loads(path.read_text())
        spec = data["spec"]
        found[(spec["system"], spec["controller"], spec["seed"])] = float(data["wall_seconds"])
    return found


def schedule(durations: list[float], jobs: int) -> list[tuple[float, float]]:
    """(start, end) of each run, dealt in order to the first free of ``jobs`` workers."""
    free = [0.0] * jobs
    times = []
    for duration in durations:
        start = heapq.heappop(free)
        times.append((start, start + duration))
        heapq.heappush(free, start + duration)
    return times


def expected_costs(walls: dict, keys: list, mode: str, profile) -> list[float]:
    if mode == "profile":
        # the measured studies ran before the proof and the protocol: their training costs
        return [profile.training_seconds(spec) for spec in keys]
    costs = []
    for spec in keys:
        others = [
            wall
            for (system, controller, seed), wall in walls.items()
            if (system, controller) == (spec.system, spec.controller) and seed != spec.seed
        ]
        costs.append(statistics.median(others) if others else walls[spec[:3]])
    return costs


def eta_at(now: float, times, actual, expected, jobs: int) -> float:
    finished = [
        Finished(c, a) for (s, e), a, c in zip(times, actual, expected, strict=True) if e <= now
    ]
    running = [
        Running(c, now - s, (now - s) / a)
        for (s, e), a, c in zip(times, actual, expected, strict=True)
        if s <= now < e
    ]
    queued = [c for (s, _), c in zip(times, expected, strict=True) if s > now]
    return estimate_remaining(finished, running, queued, jobs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", nargs="?", default="results/paper", type=Path)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--costs", choices=("other-seeds", "profile"), default="other-seeds")
    args = parser.parse_args()
    meta = json.loads((args.folder / "meta.json").read_text())
    profile = get_profile(meta["profile"])
    specs = run_specs(profile, tuple(meta["systems"]), tuple(meta["controllers"]))
    walls = wall_times(args.folder)
    actual = [walls[(s.system, s.controller, s.seed)] for s in specs]
    expected = expected_costs(walls, specs, args.costs, profile)
    times = schedule(actual, args.jobs)
    end = max(e for _, e in times)
    print(
        f"{args.folder} ({meta['profile']} profile, {len(specs)} runs, {args.jobs} workers, "
        f"costs: {args.costs}); replayed end {format_seconds(end)}"
    )
    print(f"{'at':>6} {'ETA':>8} {'actual left':>12} {'error':>7}  within {TARGET:.0%}")
    for minutes in REPORT_MINUTES:
        now = 60.0 * minutes
        if now >= end:
            break
        eta = eta_at(now, times, actual, expected, args.jobs)
        left = end - now
        error = (eta - left) / left
        verdict = "yes" if abs(error) <= TARGET else "NO"
        print(
            f"{minutes:>4}m {format_seconds(eta):>8} {format_seconds(left):>12} "
            f"{error:+7.1%}  {verdict}"
        )


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
