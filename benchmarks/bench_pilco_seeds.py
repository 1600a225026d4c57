"""How often PILCO learns the swing-up: success rate over seeds at the paper's budget.

For each seed, trains PILCO (baseline or hybrid) on a system for ``--iterations`` iterations
(default: the paper's 10), stopping early once two consecutive evaluations held the operating
point in every episode (the slow test's criterion), in parallel worker processes. Prints, per
seed, the first iteration whose evaluation held in every episode, the evaluation returns, the
L-BFGS iterations / evaluations / restarts of each policy optimisation and the wall time, then
the success rate. Each run's folder (curve, controller) is kept under ``--out``.

Usage::

    python benchmarks/bench_pilco_seeds.py [--system pendulum] [--hybrid] [--seeds 0 1 2]
                                           [--iterations 10] [--jobs 2] [--out DIR]
                                           [--set policy_iterations=75 ...]
"""

from __future__ import annotations

import argparse
import ast
import json
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import torch

HELD_TO_STOP = 2


def train_one(system: str, hybrid: bool, seed: int, iterations: int, out: str, overrides: dict):
    """One seed's run in this (worker) process; returns its summary."""
    from leoc.pilco.train import train_pilco

    torch.set_num_threads(1)
    started = time.perf_counter()
    kind = "hybrid" if hybrid else "baseline"
    result = train_pilco(
        system,
        hybrid=hybrid,
        seed=seed,
        run_dir=Path(out) / f"{system}_{kind}_seed{seed}",
        iterations=iterations,
        progress=False,
        stop_after_held=HELD_TO_STOP,
        **overrides,
    )
    curve = result.curve
    first_held = next((row["iteration"] for row in curve if row["held_fraction"] >= 1.0), None)
    return {
        "seed": seed,
        "first_held_iteration": first_held,
        "success": all(row["held_fraction"] >= 1.0 for row in curve[-HELD_TO_STOP:])
        and len(curve) > HELD_TO_STOP,
        "returns": [round(row["mean_return"]) for row in curve],
        "lbfgs": [
            (row["lbfgs_iterations"], row["lbfgs_evaluations"], row["lbfgs_restarts"])
            for row in curve[1:]
        ],
        "wall_s": time.perf_counter() - started,
    }


def parse_overrides(items: list[str]) -> dict[str, Any]:
    overrides = {}
    for item in items:
        name, _, text = item.partition("=")
        if not name or not text:
            raise SystemExit(f"--set: expected NAME=VALUE, found {item!r}")
        try:
            overrides[name] = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            overrides[name] = text
    return overrides


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--system", default="pendulum")
    parser.add_argument("--hybrid", action="store_true")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--iterations", type=int, default=10)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", default=None, help="run folders (default: a temporary folder)")
    parser.add_argument("--set", nargs="*", default=[], help="PilcoConfig overrides NAME=VALUE")
    args = parser.parse_args()
    overrides = parse_overrides(args.set)
    out = args.out or tempfile.mkdtemp(prefix="pilco-seeds-")
    kind = "hybrid" if args.hybrid else "baseline"
    print(
        f"PILCO {kind}, {args.system}, seeds {args.seeds}, {args.iterations} iterations, "
        f"overrides {overrides or 'none'}, {args.jobs} at a time; runs in {out}",
        flush=True,
    )
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [
            pool.submit(train_one, args.system, args.hybrid, seed, args.iterations, out, overrides)
            for seed in args.seeds
        ]
        results = [future.result() for future in futures]
    print(
        "| seed | first held iteration | success | eval returns | L-BFGS it/evals/restarts "
        "| wall s |"
    )
    print("|---|---|---|---|---|---|")
    for r in results:
        lbfgs = " ".join(f"{i}/{e}/{k}" for i, e, k in r["lbfgs"])
        print(
            f"| {r['seed']} | {r['first_held_iteration']} | {r['success']} | "
            f"{' '.join(map(str, r['returns']))} | {lbfgs} | {r['wall_s']:.0f} |"
        )
    successes = sum(r["success"] for r in results)
    print(f"success rate: {successes}/{len(results)}")
    (Path(out) / "summary.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
