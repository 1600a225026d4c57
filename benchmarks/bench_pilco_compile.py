"""Does ``torch.compile`` speed up PILCO's horizon cost, and are its gradients right?

Issue 41 asks for the value and gradient of the horizon cost at N = 200 GP points in <= 0.1 s
on 2 cores; the profile of ``benchmarks/bench_pilco.py``'s case shows about 1000 small torch
operations per horizon step, so fusing them (``torch.compile``) is the obvious lever. This
benchmark measures it on that case (cart-pole, exact GP on ``--points`` random-action
transitions, RBF policy with 10 basis functions, sin squash, horizon 40, float64):

- ``eager``: leoc as it is;
- ``compiled``: :func:`leoc.pilco.propagate.propagate_step` under ``torch.compile`` (inductor,
  static shapes). Dynamo stops at the ``.item()`` of :func:`leoc.linalg.cholesky_jitter`'s
  "did it fail" test, so here the moments' Cholesky of ``B = I + s Sigma s`` (eigenvalues >= 1
  whenever Sigma is positive semi-definite, which the step's eigenvalue floor keeps) is the
  plain ``torch.linalg.cholesky``; with that the step compiles without a graph break;
- ``compiled, bilinear eager``: the same, with :func:`leoc.linalg.weighted_exp_bilinear` (the
  GP's second moments, a custom autograd Function) left out of the graph;
- ``compiled, bilinear plain``: the same, with that call replaced by its plain autograd formula
  (no custom Function, no branch on ``requires_grad``) inside the graph.

For each: the compile time (first call), the median value+grad time over ``--repeats`` runs
after it, and how far the cost and each parameter's gradient are from eager's (relative
2-norm of the difference).

Measured on 2 loaded cores (AMD EPYC, torch 2.13.0, load average 2.8-3.1 from two PILCO
trainings, 2026-11-29), N = 200, relative gradient difference from eager per parameter:

=========================  ============  =============  =========  ======================
variant                    first call s  median s       cost diff  gradient diff
=========================  ============  =============  =========  ======================
eager                      0.9           0.90           0          0
compiled                   36.4          0.68           1.3e-11    1.0 (every parameter)
compiled, bilinear eager   15.0          1.20           8.8e-11    4e-8 to 5e-8
=========================  ============  =============  =========  ======================

(``compiled, bilinear plain`` was measured in a separate script before it joined this
benchmark: 0.65 s, the same wrong gradient.)

The compiled step is 1.3x faster (1.7x in a second, separate measurement: 0.43 s against
0.74 s) but its gradient is wrong: a relative difference of 1.0 on every parameter, the RBF
weights' gradient norm 0.0016 against eager's 0.067, while the cost agrees to 1e-11. The same
wrong gradient came with the GP's second moments computed by plain autograd instead of the
custom Function (``weighted_exp_bilinear``'s branch on ``requires_grad`` removed), so neither
the Function nor that branch is the cause; with that one call left out of the graph (a graph
break) the gradient agrees, and the time is no better than eager. The cause was not found. So
the speed-up torch.compile offers here comes with a wrong gradient, and leoc does not use it.
Eager's gradient is the reference: the moment tests check it against finite differences
(``gradcheck``) and Monte Carlo.

Run: ``python benchmarks/bench_pilco_compile.py`` (about 3 minutes on 2 cores, mostly
compiling; ``--points 400`` for the larger case).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import torch

import leoc.pilco.moments
import leoc.pilco.propagate
from bench_pilco import HORIZON, THREADS, cartpole_data, case_config, cpu_model
from leoc.pilco.gp import fit_gp
from leoc.pilco.objective import predict_policy
from leoc.pilco.policy import build_policy
from leoc.systems import make_system

EAGER_STEP = leoc.pilco.propagate.propagate_step
EAGER_BILINEAR = leoc.pilco.moments.weighted_exp_bilinear
EAGER_CHOLESKY = leoc.pilco.moments.cholesky_jitter


def _plain_cholesky(matrix: torch.Tensor, name: str = "matrix") -> torch.Tensor:
    """The Cholesky factor without cholesky_jitter's data-dependent retry (no graph break)."""
    return torch.linalg.cholesky(matrix)


def _setup(points: int):
    system = make_system("cartpole")
    config = case_config(points, sparse=False)
    inputs, targets = cartpole_data(points, seed=0)
    model = fit_gp(inputs, targets, config.gp, np.random.default_rng(0))
    policy = build_policy(system, config, torch.Generator().manual_seed(0), inputs[:, :5])
    return system, config, model, policy


def _value_grad(policy, model, system, config) -> tuple[float, float, dict[str, torch.Tensor]]:
    """(seconds, cost, gradient per parameter) of one value-and-gradient."""
    policy.zero_grad()
    start = time.perf_counter()
    cost = predict_policy(policy, model, system, config).total_cost
    cost.backward()
    seconds = time.perf_counter() - start
    grads = {name: p.grad.detach().clone() for name, p in policy.named_parameters()}
    return seconds, float(cost), grads


def _plain_bilinear(left, right, weights, row_offset, col_offset):
    """:func:`leoc.linalg.weighted_exp_bilinear`'s formula in plain autograd (offsets given)."""
    exponent = left @ right.transpose(-1, -2) + row_offset[..., None] + col_offset[..., None, :]
    return (weights * exponent.exp()).sum((-1, -2))


def _variant(name: str, bilinear: str) -> None:
    """Install variant ``name`` in leoc's modules (eager restores leoc as it is)."""
    torch._dynamo.reset()
    moments, propagate = leoc.pilco.moments, leoc.pilco.propagate
    if name == "eager":  # leoc as it is
        propagate.propagate_step, moments.weighted_exp_bilinear = EAGER_STEP, EAGER_BILINEAR
        moments.cholesky_jitter = EAGER_CHOLESKY
        return
    moments.cholesky_jitter = _plain_cholesky
    moments.weighted_exp_bilinear = {
        "graph": EAGER_BILINEAR,
        "eager": torch.compiler.disable(EAGER_BILINEAR),
        "plain": _plain_bilinear,
    }[bilinear]
    propagate.propagate_step = torch.compile(EAGER_STEP, dynamic=False)


def _relative(found: torch.Tensor, reference: torch.Tensor) -> float:
    return float((found - reference).norm() / reference.norm().clamp(min=1e-300))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=200, help="GP data points (default 200)")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs after the first")
    parser.add_argument("--threads", type=int, default=THREADS)
    args = parser.parse_args()
    if args.points < 10 or args.repeats < 1:
        parser.error(f"--points >= 10 and --repeats >= 1, found {args.points}, {args.repeats}")
    torch.set_num_threads(args.threads)
    load = os.getloadavg()[0]
    print(
        f"torch.compile on PILCO's horizon cost: cart-pole, N = {args.points}, horizon {HORIZON}, "
        f"{args.threads} threads, torch {torch.__version__}, {cpu_model()}, load {load:.2f}\n"
    )
    system, config, model, policy = _setup(args.points)
    reference = None
    rows = ["| variant | first call s | value+grad median s | cost diff | gradient diff |"]
    rows.append("|---|---|---|---|---|")
    for name, bilinear in (
        ("eager", "graph"),
        ("compiled", "graph"),
        ("compiled, bilinear eager", "eager"),
        ("compiled, bilinear plain", "plain"),
    ):
        _variant(name, bilinear)
        first = _value_grad(policy, model, system, config)
        runs = [_value_grad(policy, model, system, config) for _ in range(args.repeats)]
        _, cost, grads = runs[-1]
        reference = reference or (cost, grads)
        diffs = ", ".join(f"{k} {_relative(g, reference[1][k]):.1e}" for k, g in grads.items())
        median = statistics.median(r[0] for r in runs)
        rows.append(
            f"| {name} | {first[0]:.1f} | {median:.3f} | {abs(cost - reference[0]):.1e} | {diffs} |"
        )
        print(rows[-1], flush=True)
    _variant("eager", "graph")
    print("\n" + "\n".join(rows))
    print(f"\n(load average at end {os.getloadavg()[0]:.2f})")


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
