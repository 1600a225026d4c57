"""Overhead of the Ray sweep backend against the local one, on the same runs.

Two workloads, each run on both backends with the same number of parallel runs (``--jobs``):

- ``synthetic``: ``--runs`` runs that each keep one CPU busy for ``--work`` seconds (pure Python
  arithmetic, no imports), so the difference from the ideal ``runs * work / jobs`` is the
  backends' own cost: starting workers, scheduling, shipping results, writing them.
- a ``leoc reproduce`` profile (``smoke``, ``quick`` or ``paper``): the profile's real runs
  (``--systems``/``--controllers`` narrow it), as ``leoc reproduce`` executes them, without the
  report.

Ray is timed twice: with its own private instance, started and stopped inside the sweep (what
``leoc reproduce --backend ray`` pays on one machine), and on an instance already running (as on
a standing cluster joined with ``--address auto``), whose start is timed apart. The backends run
one after the other (the order of the first two reversed in every other round), each in a fresh
output folder, so nothing is skipped as already done.

Usage::

    python benchmarks/bench_sweep.py [--workload synthetic|smoke|quick|paper] [--jobs 2]
                                     [--runs 8] [--work 2.0] [--repeats 1]
                                     [--systems pendulum ...] [--controllers linear ...]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from leoc.experiments.sweep import default_run_dir, sweep

BACKEND_NAMES = ("local", "ray")


def busy_runner(spec: str, out_dir: Path) -> dict[str, Any]:
    """Keep one CPU busy for the seconds named in the spec (``run-N@SECONDS``)."""
    seconds = float(spec.split("@")[1])
    run_dir = default_run_dir(out_dir, spec)
    run_dir.mkdir(parents=True, exist_ok=True)
    deadline = time.perf_counter() + seconds
    count = 0
    while time.perf_counter() < deadline:
        count += sum(range(1000)) % 7
    return {"spec": spec, "count": count}


def _workload(args: argparse.Namespace) -> tuple[list[Any], Any, Any]:
    """Specs, runner and run-folder function of the workload."""
    if args.workload == "synthetic":
        specs = [f"run-{index}@{args.work}" for index in range(args.runs)]
        return specs, busy_runner, default_run_dir
    from leoc.experiments.profiles import CONTROLLERS, get_profile, run_specs
    from leoc.experiments.reproduce import ProfileRunner, run_dir_of
    from leoc.systems import SYSTEM_NAMES

    profile = get_profile(args.workload)
    systems = tuple(args.systems or SYSTEM_NAMES)
    controllers = tuple(args.controllers or CONTROLLERS)
    return run_specs(profile, systems, controllers), ProfileRunner(profile), run_dir_of


def time_backend(backend: str, specs: Sequence[Any], runner: Any, run_dir: Any, jobs: int) -> float:
    """Wall seconds of one sweep (Ray: starting and stopping its private instance included)."""
    with tempfile.TemporaryDirectory(prefix=f"bench-sweep-{backend}-") as out:
        started = time.perf_counter()
        result = sweep(
            specs,
            runner,
            Path(out),
            backend=backend,
            jobs=jobs,
            run_dir=run_dir,
            echo=lambda _: None,
        )
        wall = time.perf_counter() - started
    if result.failed:
        raise RuntimeError(f"{backend}: runs failed: {result.failed}")
    return wall


def time_warm_ray(
    specs: Sequence[Any], runner: Any, run_dir: Any, jobs: int
) -> tuple[float, float]:
    """Seconds to start a Ray instance of ``jobs`` CPUs, and of the sweep on it once started
    (as on a standing cluster joined with ``address="auto"``)."""
    import ray

    started = time.perf_counter()
    ray.init(address="local", num_cpus=jobs, include_dashboard=False, log_to_driver=False)
    start = time.perf_counter() - started
    try:
        return start, time_backend("ray", specs, runner, run_dir, jobs)
    finally:
        ray.shutdown()


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--workload", choices=("synthetic", "smoke", "quick", "paper"), default="synthetic"
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--runs", type=int, default=8, help="synthetic: number of runs")
    parser.add_argument("--work", type=float, default=2.0, help="synthetic: CPU seconds per run")
    parser.add_argument("--repeats", type=int, default=1, help="alternating rounds of both")
    parser.add_argument("--systems", nargs="+", help="profile workloads: systems to run")
    parser.add_argument("--controllers", nargs="+", help="profile workloads: controllers to run")
    args = parser.parse_args(argv)
    specs, runner, run_dir = _workload(args)
    print(f"workload {args.workload}: {len(specs)} runs, {args.jobs} at a time")
    walls: dict[str, list[float]] = {name: [] for name in (*BACKEND_NAMES, "ray-warm", "start")}
    for round_index in range(args.repeats):
        order = BACKEND_NAMES if round_index % 2 == 0 else BACKEND_NAMES[::-1]
        for backend in order:
            wall = time_backend(backend, specs, runner, run_dir, args.jobs)
            walls[backend].append(wall)
            print(f"  round {round_index + 1}: {backend:8s} {wall:8.1f} s")
        start, warm = time_warm_ray(specs, runner, run_dir, args.jobs)
        walls["start"].append(start)
        walls["ray-warm"].append(warm)
        print(f"  round {round_index + 1}: ray-warm {warm:8.1f} s (after {start:.1f} s to start)")
    median = {name: statistics.median(values) for name, values in walls.items()}
    local = median["local"]
    print(f"local backend:            {local:7.1f} s (medians of {args.repeats} rounds)")
    print(f"ray, own instance:        {median['ray']:7.1f} s (ratio {median['ray'] / local:.2f})")
    print(
        f"ray, instance running:    {median['ray-warm']:7.1f} s "
        f"(ratio {median['ray-warm'] / local:.2f}); starting Ray took {median['start']:.1f} s"
    )
    if args.workload == "synthetic":
        ideal = -(-args.runs // args.jobs) * args.work
        per_run = {
            name: (median[name] - ideal) * args.jobs / args.runs for name in ("local", "ray-warm")
        }
        print(
            f"ideal (runs x work / jobs): {ideal:.1f} s; overhead per run: "
            + ", ".join(f"{name} {value:.2f} s" for name, value in per_run.items())
        )


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
