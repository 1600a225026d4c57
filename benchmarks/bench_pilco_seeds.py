"""How often PILCO learns the swing-up: success rate over seeds at the paper's budget.

For each seed, trains PILCO (baseline or hybrid) on a system for ``--iterations`` iterations
(default: the paper's 10), stopping early once two consecutive evaluations held the operating
point in every episode (:func:`leoc.pilco.seeds.train_seeds`, the slow tests' criterion), in
parallel worker processes. Prints, per seed, the first iteration whose evaluation held in every
episode, the evaluation returns, the L-BFGS iterations / evaluations / restarts of each policy
optimisation and the wall time, then the success rate. Run folders are kept under ``--out``.

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
from pathlib import Path
from typing import Any

from leoc.pilco.seeds import train_seeds


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
    outcomes = train_seeds(
        args.system,
        args.hybrid,
        args.seeds,
        out,
        jobs=args.jobs,
        iterations=args.iterations,
        **overrides,
    )
    print(
        "| seed | success | first held iteration (interaction s) | eval returns "
        "| L-BFGS it/evals/restarts | wall s |"
    )
    print("|---|---|---|---|---|---|")
    for o in outcomes:
        lbfgs = " ".join(f"{i}/{e}/{k}" for i, e, k in o.lbfgs)
        returns = " ".join(f"{r:.0f}" for r in o.returns)
        print(
            f"| {o.seed} | {o.success} | {o.first_held_iteration} "
            f"({o.first_held_interaction_seconds}) | {returns} | {lbfgs} | "
            f"{o.wall_seconds:.0f} |"
        )
    print(f"success rate: {sum(o.success for o in outcomes)}/{len(outcomes)}")
    (Path(out) / "summary.json").write_text(json.dumps([o._asdict() for o in outcomes], indent=1))


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
