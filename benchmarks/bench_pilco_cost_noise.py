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
and measured the same way (a refit draws its own FITC inducing inputs, seed 0). With
``--jitters J ...`` the last GP's posterior is rebuilt at its own hyperparameters and inducing
inputs, on the data it saw, with FITC's ``inducing_jitter`` J
(``GPSettings.inducing_jitter``): that one choice switched alone. Every row
also gives the ``slope error``, ``|central difference - |g|| / |g|`` along the negative gradient
at a step of 1e-4: near 0 for a cost whose gradient a line search can follow.

Usage::

    python benchmarks/bench_pilco_cost_noise.py RUN_DIR ... [--gp noise_floor=1e-2 ...]
        [--jitters 0 1e-8 1e-6]

**FITC's jitter** (2026-11-29, leoc 1ed329f, ``--jitters 0 1e-8 1e-6`` on the pendulum PILCO
baselines of ``results/pilco-reliability/gp-max-snr-ab``, default arm, trained before the jitter
existed; last GP on 1200 data points with 200 inducing inputs). Without a jitter (the runs as
trained) the largest entry of ``Xi`` (the GP's variance weights) reached 2.9e10 to 4.6e12; the
inducing inputs' Gram matrix K_mm was near singular, and the variance's cancellation made the
cost noise: along the negative gradient, steps of 1e-8 and 1e-6 moved the stalled seed 2's cost
by 2.5 (of 30.4) and the central difference missed the gradient by a factor of 400. With 1e-6
the noise was below 1e-5 on all five runs and the slope error at most 0.011:

=================  ======  ========  =======  =====  ======================  ===========
run                jitter  max |Xi|  cost     |g|    noise along -g (1e-8,   slope error
                                                     1e-6)
=================  ======  ========  =======  =====  ======================  ===========
seed2 (stalled)    0       4.6e12    30.432   12.1   2.5                     400
seed2              1e-8    6.1e7     30.985   1.48   1.4e-4                  0.21
seed2              1e-6    2.6e6     31.001   3.39   2.2e-6                  0.0014
seed6 (stalled)    0       3.8e11    31.838   0.307  8.1e-5                  0.58
seed6              1e-6    3.5e6     31.878   8.95   9.9e-6                  0.011
seed7 (stalled)    0       2.9e10    32.189   0.899  2.1e-3                  1.7
seed7              1e-6    2.6e6     32.125   6.01   6.3e-6                  0.0002
seed0 (held)       0       1.0e10    20.807   0.129  3.9e-6                  0.19
seed0              1e-6    1.4e7     20.808   0.110  7.1e-8                  0.00059
seed5 (held)       0       2.9e10    20.722   0.222  8.4e-6                  0.25
seed5              1e-6    2.5e7     20.723   0.242  2.3e-7                  0.00054
=================  ======  ========  =======  =====  ======================  ===========

(That table came from a first version of this measurement, which stepped along the negative
gradient; this script's noise column steps along a random direction, as below.) The costs move
by at most 0.6 (seed2's, within its own noise), and the stalled runs show gradients of 3 to 9
that a line search can follow. Whether that turns stalls into learning is measured by training
again: ``results/pilco-reliability/``.

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
from leoc.pilco.checkpoint import CHECKPOINT_NAME
from leoc.pilco.gp import (
    GPPosterior,
    GPSettings,
    _noise_model,
    _training_data,
    fit_gp,
    posterior,
)
from leoc.pilco.objective import predict_policy

STEPS = (1e-13, 1e-12, 1e-11, 1e-10)
#: The central difference's step along the negative gradient, for the slope error.
SLOPE_STEP = 1e-4


def _set(params: list[torch.Tensor], theta: list[torch.Tensor], direction, step: float) -> None:
    with torch.no_grad():
        for p, t, d in zip(params, theta, direction, strict=True):
            p.copy_(t + step * d)


def _slope_error(run, model: GPPosterior, params, theta, gradient, norm: float) -> float:
    """|central difference along -g / |g| at SLOPE_STEP - |g|| / |g| (the policy restored)."""
    direction = [-g / norm for g in gradient]
    costs = []
    for step in (SLOPE_STEP, -SLOPE_STEP):
        _set(params, theta, direction, step)
        with torch.no_grad():
            costs.append(
                float(predict_policy(run.policy, model, run.system, run.config).total_cost)
            )
    _set(params, theta, direction, 0.0)
    return abs((costs[1] - costs[0]) / (2 * SLOPE_STEP) - norm) / norm


def _probe(run, model: GPPosterior) -> tuple[float, float, float, float]:
    """(cost, noise, gradient norm, slope error) of the run's policy under ``model``."""
    params = [p for p in run.policy.parameters() if p.requires_grad]
    theta = [p.detach().clone() for p in params]
    generator = torch.Generator().manual_seed(0)
    direction = [torch.randn(t.shape, generator=generator, dtype=t.dtype) for t in theta]
    costs = []
    for h in (0.0, *STEPS):
        _set(params, theta, direction, h)
        with torch.no_grad():
            costs.append(predict_policy(run.policy, model, run.system, run.config).total_cost)
    _set(params, theta, direction, 0.0)
    run.policy.zero_grad()
    predict_policy(run.policy, model, run.system, run.config).total_cost.backward()
    gradient = [p.grad.detach().clone() for p in params]
    norm = float(torch.cat([g.reshape(-1) for g in gradient]).norm())
    slope_error = _slope_error(run, model, params, theta, gradient, norm)
    base = float(costs[0])
    return base, max(abs(float(c) - base) for c in costs[1:]), norm, slope_error


def _row(label: str, run, model: GPPosterior, seconds: float | None = None) -> str:
    cost, noise, norm, slope_error = _probe(run, model)
    weights = float(model.pair_weights.abs().max())
    fit = "" if seconds is None else f" (fit {seconds:.0f} s)"
    return (
        f"| {label}{fit} | {cost:.4f} | {noise:.1e} | {norm:.3g} | {slope_error:.2g} | "
        f"{weights:.1e} |"
    )


def rebuilt(saved: dict, model: GPPosterior, settings: GPSettings, jitter: float) -> GPPosterior:
    """The run's last GP at its own hyperparameters and inducing inputs, rebuilt with FITC's
    ``jitter`` on the data it saw (``saved``: the run's checkpoint, whose data end with the
    rollout that followed the fit)."""
    log = saved["log"]
    count = int(log[-2]["data_size"]) if len(log) > 1 else len(saved["inputs"])
    x, y = _training_data(saved["inputs"][:count], saved["targets"][:count])
    inducing = model.support if model.sparse else None
    return posterior(model.hyper, x, y, _noise_model(y, settings).floor_var, inducing, jitter)


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
    parser.add_argument(
        "--jitters", nargs="*", type=float, default=[], help="rebuild with FITC jitter J"
    )
    args = parser.parse_args()
    changes = _changes(args.gp)
    torch.set_num_threads(1)
    for folder in args.runs if changes or args.jitters else []:
        if not (folder / CHECKPOINT_NAME).exists():
            parser.error(
                f"runs: expected a PILCO run folder with {CHECKPOINT_NAME}, found {folder}"
            )
    print(
        "| run (model) | predicted cost | noise | gradient norm | slope error | max pair weight |"
    )
    print("|---|---|---|---|---|---|")
    for folder in args.runs:
        run = load_pilco_run(folder)
        print(_row(f"{folder} (saved)", run, run.model), flush=True)
        if not changes and not args.jitters:
            continue
        saved = torch.load(folder / CHECKPOINT_NAME, weights_only=False)
        for jitter in args.jitters:
            model = rebuilt(saved, run.model, run.config.gp, jitter)
            print(_row(f"{folder} (jitter {jitter:g})", run, model), flush=True)
        if not changes:
            continue
        for label, change in (("default refit", {}), (" ".join(args.gp), changes)):
            settings = dataclasses.replace(run.config.gp, **change)
            started = time.perf_counter()
            model = fit_gp(saved["inputs"], saved["targets"], settings, np.random.default_rng(0))
            seconds = time.perf_counter() - started
            print(_row(f"{folder} ({label})", run, model, seconds), flush=True)


if __name__ == "__main__":
    main()
