"""Multi-seed PILCO measurement: when does each policy reach and hold the operating point?

For every (system, policy, seed) it trains with :func:`leoc.pilco.train.train_pilco` (one
torch thread) and reports the first iteration whose evaluation episodes all held the operating
point (``System.hold_step``: inside the hold band to the end, for at least the system's
``hold_min_steps`` steps; :mod:`leoc.training`), the interaction time used up to and including
that iteration, and whether every later iteration held too.

Example::

    nice python scripts/pilco_seeds.py --systems pendulum --seeds 0 1 2 --iterations 8 \\
        --out runs/pilco_seeds
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from leoc.pilco.train import train_pilco


def summarise(curve: list[dict]) -> dict:
    held = [row for row in curve if row["held_fraction"] >= 1.0]
    if not held:
        return {
            "first_held_iteration": None,
            "interaction_seconds": None,
            "stayed": False,
            "iterations_run": curve[-1]["iteration"],
        }
    first = held[0]
    later = [row for row in curve if row["iteration"] >= first["iteration"]]
    return {
        "first_held_iteration": first["iteration"],
        "interaction_seconds": first["interaction_seconds"],
        "hold_steps": first["hold_steps"],
        "stayed": all(row["held_fraction"] >= 1.0 for row in later),
        "iterations_run": curve[-1]["iteration"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", default=["pendulum", "cartpole", "mountaincar"])
    parser.add_argument("--policies", nargs="+", default=["rbf", "hybrid"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--iterations", type=int, default=None)
    parser.add_argument("--stop-after-held", type=int, default=2)
    parser.add_argument("--policy-iterations", type=int, default=None)
    parser.add_argument("--out", default="runs/pilco_seeds")
    args = parser.parse_args()
    torch.set_num_threads(1)
    results = []
    out = Path(args.out)
    for system in args.systems:
        for policy in args.policies:
            for seed in args.seeds:
                overrides = {"stop_after_held": args.stop_after_held}
                if args.policy_iterations is not None:
                    overrides["policy_iterations"] = args.policy_iterations
                result = train_pilco(
                    system,
                    hybrid=policy == "hybrid",
                    seed=seed,
                    run_dir=out / f"{system}_{policy}_seed{seed}",
                    iterations=args.iterations,
                    **overrides,
                )
                row = {"system": system, "policy": policy, "seed": seed, **summarise(result.curve)}
                results.append(row)
                print(json.dumps(row), flush=True)
    summary = out / f"summary_{'_'.join(args.systems)}_{'_'.join(args.policies)}.json"
    summary.write_text(json.dumps(results, indent=2))
    print(f"summary written to {summary}")


if __name__ == "__main__":
    main()
