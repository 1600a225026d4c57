"""Speed and memory of PILCO's long-term prediction on cart-pole swing-up data.

Measures, for GP models fitted to 200 and to 400 cart-pole transitions (random-action rollouts
from the swing-up start, 3-step held actions), an RBF policy with 10 basis functions, horizon
40, float64 on 2 CPU threads:

- one value-and-gradient of the horizon cost (median of ``--repeats`` runs, after a warm-up);
- one full policy optimisation (L-BFGS, ``--policy-iterations`` iterations);
- peak resident memory of the process (each case runs in a fresh subprocess).

Run: ``python benchmarks/bench_pilco.py`` (add ``--sparse`` to also time the default FITC model
that the training loop uses beyond 300 points).
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time

import numpy as np
import torch

from leoc.pilco.gp import GPSettings, fit_gp
from leoc.pilco.rollout import random_action_fn, run_rollout
from leoc.pilco.train import PilcoConfig, build_policy, optimise_policy, predict_policy
from leoc.systems import make_system

THREADS = 2
NUM_BASIS = 10
HORIZON = 40
KIB_PER_MIB = 1024.0


def cartpole_data(points: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``points`` transitions of random-action cart-pole rollouts from the swing-up start."""
    system = make_system("cartpole")
    rng = np.random.default_rng(seed)
    inputs, targets = [], []
    while sum(len(x) for x in inputs) < points:
        rollout = run_rollout(
            system, random_action_fn(system, rng), system.sample_start(rng, "swing_up"), 200, 3
        )
        inputs.append(rollout.inputs)
        targets.append(rollout.targets)
    return np.concatenate(inputs)[:points], np.concatenate(targets)[:points]


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / KIB_PER_MIB  # Linux: KiB


def run_case(points: int, sparse: bool, repeats: int, policy_iterations: int, threads: int) -> dict:
    torch.set_num_threads(threads)
    system = make_system("cartpole")
    config = PilcoConfig.for_system(
        "cartpole", num_basis=NUM_BASIS, horizon=HORIZON, policy_iterations=policy_iterations
    )
    if not sparse:
        config.gp = GPSettings(max_full_points=max(points, config.gp.max_full_points))
    inputs, targets = cartpole_data(points, seed=0)
    start = time.perf_counter()
    model = fit_gp(inputs, targets, config.gp, np.random.default_rng(0))
    fit_seconds = time.perf_counter() - start
    policy = build_policy(system, config, torch.Generator().manual_seed(0), inputs[:, :5])
    rss_before = peak_rss_mib()
    times = []
    for _ in range(repeats + 1):  # the first run is a warm-up
        policy.zero_grad()
        start = time.perf_counter()
        predict_policy(policy, model, system, config).total_cost.backward()
        times.append(time.perf_counter() - start)
    rss_value_grad = peak_rss_mib()
    start = time.perf_counter()
    cost = optimise_policy(policy, model, system, config)
    optimise_seconds = time.perf_counter() - start
    return {
        "points": points,
        "model": "FITC" if model.sparse else "exact GP",
        "support": int(model.support.shape[0]),
        "gp_fit_s": fit_seconds,
        "value_and_grad_s": statistics.median(times[1:]),
        "policy_optimisation_s": optimise_seconds,
        "policy_iterations": policy_iterations,
        "optimised_cost": cost,
        "peak_rss_mib": peak_rss_mib(),
        "rss_before_mib": rss_before,
        "rss_after_value_grad_mib": rss_value_grad,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--policy-iterations", type=int, default=50)
    parser.add_argument("--sparse", action="store_true", help="also time the FITC default")
    parser.add_argument("--threads", type=int, default=THREADS)
    parser.add_argument("--case", help=argparse.SUPPRESS)  # internal: one case, JSON out
    args = parser.parse_args()
    if args.case:
        points, sparse = args.case.split(":")
        result = run_case(
            int(points), sparse == "1", args.repeats, args.policy_iterations, args.threads
        )
        print(json.dumps(result))
        return
    cases = ["200:0", "400:0"] + (["400:1"] if args.sparse else [])
    print(
        f"PILCO benchmark: cart-pole, horizon {HORIZON}, RBF {NUM_BASIS} basis, float64, "
        f"{args.threads} threads, torch {torch.__version__}"
    )
    header = (
        f"{'N':>4} {'model':>8} {'M':>4} {'GP fit s':>9} {'val+grad s':>11} "
        f"{'optimise s':>11} {'L-BFGS it':>9} {'peak RSS MiB':>13} {'RSS before':>11}"
    )
    print(header)
    for case in cases:
        out = subprocess.run(
            [
                sys.executable,
                __file__,
                "--case",
                case,
                "--repeats",
                str(args.repeats),
                "--policy-iterations",
                str(args.policy_iterations),
                "--threads",
                str(args.threads),
            ],
            check=True,
            capture_output=True,
            text=True,
        )
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(
            f"{r['points']:>4} {r['model']:>8} {r['support']:>4} {r['gp_fit_s']:>9.2f} "
            f"{r['value_and_grad_s']:>11.3f} {r['policy_optimisation_s']:>11.2f} "
            f"{r['policy_iterations']:>9d} {r['peak_rss_mib']:>13.0f} {r['rss_before_mib']:>11.0f}"
        )


if __name__ == "__main__":
    main()
