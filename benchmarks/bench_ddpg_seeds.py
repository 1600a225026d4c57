"""How often DDPG/TD3 learns a system, and after how many steps: success rate against budget.

For each seed, trains DDPG or TD3 (baseline or hybrid) for ``--steps`` environment steps with an
evaluation every ``--eval-interval`` steps, in parallel worker processes (one torch thread each).
A seed has *learnt by step T* when some evaluation up to T held the operating point in every
episode and the best mean evaluation return up to T is above ``--min-return`` (the slow DDPG
learning test's criterion). SB3's DDPG/TD3 with a constant learning rate do not depend on the
total budget, so the prefix of one long run is the run a shorter budget would have made: one run
per seed gives the success rate at every budget.

Prints each seed's evaluations (return, held fraction), the first step it has learnt by, and the
success rate at every evaluation step. Run folders are kept under ``--out``.

Usage::

    python benchmarks/bench_ddpg_seeds.py [--system pendulum] [--algo ddpg] [--hybrid]
                                          [--seeds 0 1 2] [--steps 10000] [--eval-interval 500]
                                          [--min-return -600] [--jobs 2] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any


def train_one(
    system: str, algo: str, hybrid: bool, seed: int, steps: int, interval: int, out: str
) -> dict[str, Any]:
    import torch

    from leoc.sb3.train import train_ddpg

    torch.set_num_threads(1)
    started = time.perf_counter()
    run_dir = Path(out) / f"{system}_{algo}_{'hybrid' if hybrid else 'baseline'}_seed{seed}"
    result = train_ddpg(
        system,
        algo,
        hybrid=hybrid,
        seed=seed,
        run_dir=run_dir,
        total_steps=steps,
        eval_interval=interval,
        progress=False,
    )
    return {
        "seed": seed,
        "steps": [int(row["steps"]) for row in result.curve],
        "returns": [float(row["mean_return"]) for row in result.curve],
        "held": [float(row["held_fraction"]) for row in result.curve],
        "wall_seconds": time.perf_counter() - started,
        "run_dir": str(run_dir),
    }


def learnt_by(run: dict[str, Any], min_return: float) -> int | None:
    """The first evaluation step by which the run has learnt (None: never)."""
    reached = False
    best = -float("inf")
    for steps, ret, held in zip(run["steps"], run["returns"], run["held"], strict=True):
        reached = reached or held >= 1.0
        best = max(best, ret)
        if reached and best > min_return:
            return steps
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--system", default="pendulum")
    parser.add_argument("--algo", choices=("ddpg", "td3"), default="ddpg")
    parser.add_argument("--hybrid", action="store_true")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--eval-interval", type=int, default=500)
    parser.add_argument("--min-return", type=float, default=-600.0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", default=None, help="run folders (default: a temporary folder)")
    args = parser.parse_args()
    if args.jobs < 1 or args.steps < 1 or args.eval_interval < 1:
        raise SystemExit("--jobs, --steps and --eval-interval: expected positive integers")
    out = args.out or tempfile.mkdtemp(prefix="ddpg-seeds-")
    kind = "hybrid" if args.hybrid else "baseline"
    print(
        f"{args.algo.upper()} {kind}, {args.system}, seeds {args.seeds}, {args.steps} steps "
        f"(evaluation every {args.eval_interval}), learnt: held in every episode of some "
        f"evaluation and best return > {args.min_return:g}; {args.jobs} at a time; runs in {out}",
        flush=True,
    )
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(min(args.jobs, len(args.seeds)), mp_context=context) as pool:
        futures = [
            pool.submit(
                train_one,
                args.system,
                args.algo,
                args.hybrid,
                seed,
                args.steps,
                args.eval_interval,
                out,
            )
            for seed in args.seeds
        ]
        runs = [future.result() for future in futures]
    print("\n| seed | learnt by step | evaluations: steps return held | wall s |")
    print("|---|---|---|---|")
    for run in runs:
        evaluations = ", ".join(
            f"{s} {r:.0f} {h:.0%}"
            for s, r, h in zip(run["steps"], run["returns"], run["held"], strict=True)
        )
        print(
            f"| {run['seed']} | {learnt_by(run, args.min_return)} | {evaluations} | "
            f"{run['wall_seconds']:.0f} |"
        )
    print("\n| budget (steps) | seeds learnt |")
    print("|---|---|")
    for steps in runs[0]["steps"]:
        count = sum(
            (first := learnt_by(run, args.min_return)) is not None and first <= steps
            for run in runs
        )
        print(f"| {steps} | {count}/{len(runs)} |")
    (Path(out) / "summary.json").write_text(json.dumps(runs, indent=1))


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
