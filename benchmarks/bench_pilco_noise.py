"""How noisy is PILCO's predicted horizon cost at a trained policy, and does FITC's jitter fix it?

Issue 41's stalled runs (``leoc.pilco.diagnose``: L-BFGS stops long before its budget with a
large gradient, and the restarts gain nothing) point at a cost the line search cannot descend.
This benchmark measures that directly at the end of PILCO runs: for each run folder it takes the
last GP's hyperparameters and inducing inputs, refits the posterior on the data that GP saw with
each ``--jitters`` value (:attr:`leoc.pilco.gp.GPSettings.inducing_jitter`), and at the run's
final policy prints

- ``max |Xi|``: the largest entry of the GP variance weights (``inv_k``);
- ``cost``, ``|g|``: the predicted horizon cost and its gradient norm;
- ``noise``: the largest ``|f(theta - t g/|g|) - f(theta)|`` over the steps t = 1e-8 and 1e-6
  of the parameters (a smooth cost moves by at most about ``t |g|`` there);
- ``slope error``: ``|central difference at t = 1e-4 - |g|| / |g|``, 0 for a cost whose
  gradient the line search can follow.

Measured on the pendulum PILCO baselines of ``results/pilco-reliability/gp-max-snr-ab``
(default arm, trained at d062c6f, before the jitter; the run folders are not in the
repository), final policy, last GP (1200 data points, FITC with 200 inducing inputs), 1 core
beside two PILCO trainings, 2026-11-29:

==================  ======  ========  =======  =====  =======  ===========
run                 jitter  max |Xi|  cost     |g|    noise    slope error
==================  ======  ========  =======  =====  =======  ===========
seed2 (stalled)     0       4.6e12    30.432   12.1   2.5      400
seed2               1e-8    6.1e7     30.985   1.48   1.4e-4   0.21
seed2               1e-6    2.6e6     31.001   3.39   2.2e-6   0.0014
seed6 (stalled)     0       3.8e11    31.838   0.307  8.1e-5   0.58
seed6               1e-6    3.5e6     31.878   8.95   9.9e-6   0.011
seed7 (stalled)     0       2.9e10    32.189   0.899  2.1e-3   1.7
seed7               1e-6    2.6e6     32.125   6.01   6.3e-6   0.0002
seed0 (held)        0       1.0e10    20.807   0.129  3.9e-6   0.19
seed0               1e-6    1.4e7     20.808   0.110  7.1e-8   0.00059
seed5 (held)        0       2.9e10    20.722   0.222  8.4e-6   0.25
seed5               1e-6    2.5e7     20.723   0.242  2.3e-7   0.00054
==================  ======  ========  =======  =====  =======  ===========

Without the jitter the three stalled runs' costs are noise at the scale of their steps
(seed2: 2.5 of 30 for a step of 1e-8) and the central difference does not follow the gradient
(slope errors 0.58 to 400); with 1e-6 the noise is below 1e-5 on every run, the slope error
at most 0.011, and the stalled runs show gradients of 3 to 9 that a line search can follow.
The costs themselves move by at most 0.6 (seed2's, within its own noise). Whether that turns
the stalls into learning is measured by retraining: ``results/pilco-reliability/``.

Run: ``python benchmarks/bench_pilco_noise.py RUN_DIR [RUN_DIR ...]`` where each RUN_DIR is a
PILCO run folder holding ``checkpoint.pt`` and ``controller.pt`` (``leoc train --algo pilco``,
or ``benchmarks/bench_pilco_failures.py``'s ``SYSTEM/CONTROLLER/seedN/train``); about 10 s per
run and jitter on 1 core.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import NamedTuple

import torch

from leoc.pilco.checkpoint import CHECKPOINT_NAME, load_pilco_run
from leoc.pilco.gp import GPPosterior, _noise_model, _training_data, posterior
from leoc.pilco.objective import predict_policy

#: Parameter steps whose cost change is pure noise (a smooth cost moves by about t |g|).
NOISE_STEPS = (1e-8, 1e-6)
#: The central difference's step for the slope check.
SLOPE_STEP = 1e-4


class NoiseRow(NamedTuple):
    """One run and jitter: the figures the table prints."""

    run: str
    jitter: float
    data: int
    max_xi: float
    cost: float
    gradient_norm: float
    noise: float
    slope_error: float


def refit(run_dir: Path, model: GPPosterior, jitter: float, settings) -> tuple[GPPosterior, int]:
    """The run's last GP at its hyperparameters, refitted with ``jitter`` on the data it saw
    (the checkpoint's data less the last rollout, which came after the fit)."""
    saved = torch.load(run_dir / CHECKPOINT_NAME, weights_only=False)
    log = saved["log"]
    count = int(log[-2]["data_size"]) if len(log) > 1 else len(saved["inputs"])
    x, y = _training_data(saved["inputs"][:count], saved["targets"][:count])
    floor_var = _noise_model(y, settings).floor_var
    inducing = model.support if model.sparse else None
    return posterior(model.hyper, x, y, floor_var, inducing, jitter), count


def _set(params: list[torch.Tensor], theta: list[torch.Tensor], direction, step: float) -> None:
    offset = 0
    with torch.no_grad():
        for param, start in zip(params, theta, strict=True):
            size = param.numel()
            param.copy_(start + step * direction[offset : offset + size].view_as(param))
            offset += size


def measure(run_dir: Path, jitter: float) -> NoiseRow:
    """Cost, gradient, noise and slope error at the run's final policy under the refitted GP."""
    run = load_pilco_run(run_dir)
    model, count = refit(run_dir, run.model, jitter, run.config.gp)
    params = list(run.policy.parameters())
    for param in params:
        param.requires_grad_(True)

    def cost() -> float:
        with torch.no_grad():
            return float(predict_policy(run.policy, model, run.system, run.config).total_cost)

    loss = predict_policy(run.policy, model, run.system, run.config).total_cost
    loss.backward()
    gradient = torch.cat([p.grad.flatten() for p in params])
    norm = float(gradient.norm())
    direction = -gradient / norm
    theta = [p.detach().clone() for p in params]
    noise = 0.0
    for step in NOISE_STEPS:
        _set(params, theta, direction, step)
        noise = max(noise, abs(cost() - float(loss)))
    _set(params, theta, direction, SLOPE_STEP)
    down = cost()
    _set(params, theta, direction, -SLOPE_STEP)
    up = cost()
    _set(params, theta, direction, 0.0)
    slope = (up - down) / (2 * SLOPE_STEP)
    return NoiseRow(
        f"{run_dir.parent.parent.name}/{run_dir.parent.name}",
        jitter,
        count,
        float(model.inv_k.abs().max()),
        float(loss),
        norm,
        noise,
        abs(slope - norm) / norm,
    )


def table(rows: list[NoiseRow]) -> str:
    lines = [
        "| run | jitter | data | max abs Xi | cost | gradient norm | noise | slope error |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row.run} | {row.jitter:g} | {row.data} | {row.max_xi:.2g} | {row.cost:.4f} | "
            f"{row.gradient_norm:.3g} | {row.noise:.2g} | {row.slope_error:.2g} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="PILCO run folders (checkpoint.pt)")
    parser.add_argument("--jitters", nargs="+", type=float, default=[0.0, 1e-8, 1e-6])
    args = parser.parse_args()
    torch.set_num_threads(1)
    for run_dir in args.runs:
        if not (run_dir / CHECKPOINT_NAME).exists():
            parser.error(
                f"runs: expected a PILCO run folder with {CHECKPOINT_NAME}, found {run_dir}"
            )
    rows = []
    for run_dir in args.runs:
        for jitter in args.jitters:
            rows.append(measure(run_dir, jitter))
            print(table(rows[-1:]).splitlines()[-1], flush=True)
    print()
    print(table(rows))


if __name__ == "__main__":
    main()
