"""Why PILCO's L-BFGS stops early (issue 41): its line searches, measured at a trained run.

For each PILCO run folder given (``leoc train --algo pilco`` or ``leoc reproduce``'s
``RUN/train``), the run's saved policy and last GP model (:func:`leoc.pilco.load_pilco_run`),
and one policy optimisation from there exactly as the trainer runs it
(:func:`leoc.pilco.objective.optimise_policy`), with torch's strong Wolfe line search wrapped to
record every call: the step it starts from and the one it returns, its function evaluations, the
cost before and after, the directional derivative, and the largest parameter move ``max|t d|``.
Then which of torch's stopping tests ended each L-BFGS round: the iteration budget, the
*evaluation* budget (``max_eval``, 1.25 x the iterations by default, which line searches spend:
up to 25 evaluations each), a flat directional derivative, "lack of progress" (``max|t d| <=
1e-9`` or a cost change below 1e-9), or the gradient tolerance.

Usage::

    python benchmarks/bench_pilco_line_search.py RUN_DIR ... [--iterations N]

Measured on this project's 2-core machine (2026-11-29, commit c2bada4): the pendulum PILCO
baseline's seed 2 at the paper profile (``OMP_NUM_THREADS=1 leoc train pendulum --algo pilco
--profile paper --seed 2``) stalled again (held 0% after 10 iterations, predicted cost 30.4-31.0;
L-BFGS 3-10 iterations per PILCO iteration from the second). From its final policy, the
optimisation stops after 2 iterations and 14 evaluations without moving: each of its two line
searches starts at t = 1.4e-2 along a direction whose directional derivative is -145 (a
predicted decrease of 2 at that step), spends 6 evaluations and returns t = 0, so "no move" ends
the round and the restart rule ends the optimisation. Along the normalised negative gradient
(norm 12.1) the cost, 30.432 at the start, is 32.99 at a step of 1e-10, 32.16 at 1e-9, 30.51 at
1e-8, 31.45 at 1e-7, 32.88 at 1e-6 and 30.65 at 1e-4, against a linear prediction that moves by
less than 1e-4 below 1e-5: the cost is noise of about 2.5 at every scale, and the start is a low
draw of that noise (the optimiser keeps the lowest cost it has seen). The cost at the same
parameters is 30.43 with autograd on and 31.94 without. This is how the noise of
``bench_pilco_cost_noise.py`` stops the optimisation; it does not say that removing it suffices
(a run with ``gp_noise_floor`` 1e-2 ended on 300 times less noise and still stalled).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import torch
import torch.optim.lbfgs as lbfgs

from leoc.pilco import load_pilco_run
from leoc.pilco.objective import optimise_policy

#: torch's L-BFGS defaults that its stopping tests use.
TOLERANCE_CHANGE = 1e-9
EVALS_PER_ITERATION = 1.25


class _Recorder:
    """Wraps ``torch.optim.lbfgs._strong_wolfe`` and records each call."""

    def __init__(self) -> None:
        self.calls: list[dict] = []
        self.original = lbfgs._strong_wolfe

    def __call__(self, obj_func, x, t, d, f, g, gtd, **options):
        start = float(t)
        f_new, g_new, t_new, evals = self.original(obj_func, x, t, d, f, g, gtd, **options)
        self.calls.append(
            {
                "t0": start,
                "t": float(t_new),
                "evals": int(evals),
                "max_ls": options.get("max_ls"),
                "f": float(f),
                "f_new": float(f_new),
                "gtd": float(gtd),
                "move": float(d.mul(t_new).abs().max()),
            }
        )
        return f_new, g_new, t_new, evals

    def __enter__(self) -> _Recorder:
        lbfgs._strong_wolfe = self
        return self

    def __exit__(self, *exc) -> None:
        lbfgs._strong_wolfe = self.original


def _stop_reason(call: dict, budget_left: float) -> str:
    """Which of torch's tests the round's last line search met (see the module docstring)."""
    reasons = []
    if call["evals"] >= budget_left:
        reasons.append("evaluation budget")
    if call["move"] <= TOLERANCE_CHANGE:
        reasons.append("no move (max|t d| <= 1e-9)")
    if abs(call["f_new"] - call["f"]) < TOLERANCE_CHANGE:
        reasons.append("no cost change")
    return ", ".join(reasons) or "iteration budget or gradient tolerance"


def probe(run_dir: Path, iterations: int | None) -> None:
    run = load_pilco_run(run_dir)
    config = run.config
    if iterations is not None:
        from dataclasses import replace

        config = replace(config, policy_iterations=iterations)
    print(f"## {run_dir} (policy_iterations {config.policy_iterations})")
    started = time.perf_counter()
    with _Recorder() as recorder:
        outcome = optimise_policy(run.policy, run.model, run.system, config)
    seconds = time.perf_counter() - started
    print(
        f"cost {outcome.start_cost:.4f} -> {outcome.cost:.4f}, {outcome.iterations} iterations, "
        f"{outcome.evaluations} evaluations, {outcome.restarts} restarts, "
        f"{outcome.failed_evaluations} failed, {seconds:.0f} s"
    )
    print("| search | t0 | t | evals (max) | cost before | cost after | gtd | max abs(t d) |")
    print("|---|---|---|---|---|---|---|---|")
    for k, call in enumerate(recorder.calls):
        print(
            f"| {k} | {call['t0']:.2e} | {call['t']:.2e} | {call['evals']} ({call['max_ls']}) | "
            f"{call['f']:.6f} | {call['f_new']:.6f} | {call['gtd']:.2e} | {call['move']:.1e} |"
        )
    if recorder.calls:
        last = recorder.calls[-1]
        budget = last["max_ls"] if last["max_ls"] is not None else math.inf
        print(f"last search: {_stop_reason(last, budget)}")
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="PILCO run folders")
    parser.add_argument("--iterations", type=int, help="policy_iterations (default: the run's)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    for run_dir in args.runs:
        probe(run_dir, args.iterations)


if __name__ == "__main__":
    main()
