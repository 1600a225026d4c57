"""How noisy PILCO's predicted horizon cost is, at the end of trained runs (issue 41).

For each PILCO run folder given (``OUT/SYSTEM/CONTROLLER/seedN/train`` of
``bench_pilco_failures.py``, or any ``leoc train --algo pilco`` folder): the run's saved policy and
last GP model (:func:`leoc.pilco.load_pilco_run`), the predicted horizon cost there, and how much
it moves when the policy's parameters move by ``h`` = 1e-13 ... 1e-10 along one seeded random
direction (``noise``: the largest change; a smooth cost moves by about ``h`` times its slope, far
below 1e-6), the gradient's norm, and the largest entry of the GP's pair weights
``beta_a beta_b^T - delta_ab K_a^-1`` (:class:`leoc.pilco.gp.GPPosterior`), the terms whose sum
gives the predicted variance by cancellation. With ``--gp KEY=VALUE ...`` the last GP is also
refitted on the run's data (its checkpoint) with those :class:`leoc.pilco.gp.GPSettings` changed,
and measured the same way (a refit draws its own FITC inducing inputs, seed 0).

Usage::

    python benchmarks/bench_pilco_cost_noise.py RUN_DIR ... [--gp noise_floor=1e-2 ...]

Measured on this project's 2-core machine (2026-11-29, the runs of ``bench_pilco_failures.py`` at
the paper profile, commit be653e6): the noise grows with the pair weights, and it is large where the
line search stalls (whether it causes the stall is not established: see the end). Pendulum baseline
seed 2 (stalled: L-BFGS stopped after 3-10 of its 75 iterations at every iteration from the second,
start gradients 1.8-22): noise 1.3 on a cost of 31.9, pair weights 1.2e13; pendulum ROA hybrid seed
3 (stalled, 40% held; L-BFGS stopped after 2-5 iterations from its 6th): 0.14, 6.3e13; the pendulum
baselines that held (seeds 0, 1): 2.2e-5 and 2.8e-4, 1.7e11 and 6.5e12; the cart-pole baselines
(local optima; seed 3's L-BFGS stopped after 3-4 iterations from its 6th): 7.7e-4 and 2.2e-3, 2.0e11
and 3.2e10. The cart-pole hybrids (seed 3 stalled, seed 1 unfinished at 8 of 10 iterations): 7e-8
and 2e-8, 1.1e8 and 2.1e8: their cost is smooth, and they spent the whole L-BFGS budget at every
iteration, a different failure. Refitting seed 2's last GP on its data: default settings 6.2e-2,
``noise_floor=1e-3`` 3.0e-2, ``noise_floor=1e-2`` 2.4e-3, ``max_snr=100`` 1.0e-3 (one run, one refit
each: an indication, not a rate). Seed 2 trained again with ``gp_noise_floor`` 1e-2 ended on a noise
of 4.4e-3 (pair weights 9.0e10) and still stalled: its L-BFGS stopped after 2-10 iterations from the
third iteration on, held 0%. On commit c2bada4 (2026-11-29), seed 2 trained again (one thread):
noise 1.3 (pair weights 1.2e13), stalled; with ``gp_noise_floor`` 1e-2: 4.4e-3 (9.0e10), stalled;
with ``gp_max_snr`` 100: 8.4e-7 (2.1e10), L-BFGS spent its whole budget from the fifth iteration
and the predicted cost fell from 27.1 to 23.2 (held 1 of 5 after 10 iterations; one run each).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
import torch

from leoc.pilco import load_pilco_run
from leoc.pilco.gp import GPPosterior, GPSettings, fit_gp
from leoc.pilco.objective import predict_policy

STEPS = (1e-13, 1e-12, 1e-11, 1e-10)


def _probe(run, model: GPPosterior) -> tuple[float, float, float]:
    """(cost, noise, gradient norm) of the run's policy under ``model``."""
    params = [p for p in run.policy.parameters() if p.requires_grad]
    theta = [p.detach().clone() for p in params]
    generator = torch.Generator().manual_seed(0)
    direction = [torch.randn(t.shape, generator=generator, dtype=t.dtype) for t in theta]
    costs = []
    for h in (0.0, *STEPS):
        with torch.no_grad():
            for p, t, d in zip(params, theta, direction, strict=True):
                p.copy_(t + h * d)
            costs.append(predict_policy(run.policy, model, run.system, run.config).total_cost)
    with torch.no_grad():
        for p, t in zip(params, theta, strict=True):
            p.copy_(t)
    run.policy.zero_grad()
    predict_policy(run.policy, model, run.system, run.config).total_cost.backward()
    norm = float(torch.cat([p.grad.reshape(-1) for p in params]).norm())
    base = float(costs[0])
    return base, max(abs(float(c) - base) for c in costs[1:]), norm


def _row(label: str, run, model: GPPosterior, seconds: float | None = None) -> str:
    cost, noise, norm = _probe(run, model)
    weights = float(model.pair_weights.abs().max())
    fit = "" if seconds is None else f" (fit {seconds:.0f} s)"
    return f"| {label}{fit} | {cost:.4f} | {noise:.1e} | {norm:.3g} | {weights:.1e} |"


def _changes(pairs: list[str]) -> dict[str, float]:
    changes = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        if key not in {f.name for f in dataclasses.fields(GPSettings)} or not value:
            raise SystemExit(f"--gp: expected KEY=VALUE with a GPSettings field, found {pair!r}")
        changes[key] = float(value)
    return changes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="PILCO run folders")
    parser.add_argument("--gp", nargs="*", default=[], help="refit with GPSettings KEY=VALUE")
    args = parser.parse_args()
    changes = _changes(args.gp)
    torch.set_num_threads(1)
    print("| run (model) | predicted cost | noise | gradient norm | max pair weight |")
    print("|---|---|---|---|---|")
    for folder in args.runs:
        run = load_pilco_run(folder)
        print(_row(f"{folder} (saved)", run, run.model), flush=True)
        if not changes:
            continue
        saved = torch.load(folder / "checkpoint.pt", weights_only=False)
        for label, change in (("default refit", {}), (" ".join(args.gp), changes)):
            settings = dataclasses.replace(run.config.gp, **change)
            started = time.perf_counter()
            model = fit_gp(saved["inputs"], saved["targets"], settings, np.random.default_rng(0))
            seconds = time.perf_counter() - started
            print(_row(f"{folder} ({label})", run, model, seconds), flush=True)


if __name__ == "__main__":
    main()
