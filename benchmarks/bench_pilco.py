"""Speed and memory of PILCO's long-term prediction on cart-pole swing-up data.

Cases: GP models fitted to 200 and to 400 cart-pole transitions (random-action rollouts from the
swing-up start, 3-step held actions) as exact GPs, and 400 transitions with the training loop's
default model beyond ``max_full_points = 300`` data (FITC, 200 inducing inputs). Policy: RBF
with 10 basis functions and sin squash; horizon 40; float64 on 2 CPU threads. Each case runs in
a fresh subprocess (so peak memories do not mix) and measures:

- one value-and-gradient of the horizon cost: median and range over ``--repeats`` runs, after
  a warm-up run;
- one full PILCO iteration at the training defaults: GP fit, then policy optimisation (L-BFGS,
  ``policy_iterations`` of :class:`~leoc.pilco.config.PilcoConfig`), with the number of cost
  evaluations L-BFGS made and the time per evaluation;
- the peak resident memory of the whole process (GP fits included).

It prints a markdown table and the targets of issue 11 (3x faster than the TensorFlow reference,
nrontsis/PILCO on TF 2.15 + gpflow 2.1.5 with tf.function, measured on the same 2-core machine
class) with met/missed.

Run: ``python benchmarks/bench_pilco.py`` (``--quick`` for a smoke run: 3 repeats and 10
L-BFGS iterations).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time

import numpy as np
import torch

from leoc.pilco.config import PilcoConfig
from leoc.pilco.gp import GPSettings, fit_gp
from leoc.pilco.objective import optimise_policy, predict_policy
from leoc.pilco.policy import build_policy
from leoc.pilco.rollout import run_rollout
from leoc.systems import make_system
from leoc.systems.rollout import RandomController

THREADS = 2
NUM_BASIS = 10
HORIZON = 40
KIB_PER_MIB = 1024.0
MIB_PER_GB = 1e9 / 2**20  # 1.5 GB = 1.5e9 bytes = 1430.5 MiB
CASES = (("200", 200, False), ("400", 400, False), ("400-FITC", 400, True))
# TensorFlow reference, value and gradient of the same horizon cost (issue 11).
REFERENCE_VALUE_GRAD_S = {"200": 1.03, "400": 3.97}
SPEED_FACTOR = 3.0
TARGET_VALUE_GRAD_S = {"200": 0.34, "400": 1.3}
TARGET_PEAK_GB = 1.5
QUICK_REPEATS = 3
QUICK_POLICY_ITERATIONS = 10


def cartpole_data(points: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``points`` transitions of random-action cart-pole rollouts from the swing-up start."""
    system = make_system("cartpole")
    rng = np.random.default_rng(seed)
    inputs, targets = [], []
    while sum(len(x) for x in inputs) < points:
        rollout = run_rollout(
            system, RandomController(system, rng, 3), system.sample_start(rng, "swing_up"), 200, 3
        )
        inputs.append(rollout.inputs)
        targets.append(rollout.targets)
    return np.concatenate(inputs)[:points], np.concatenate(targets)[:points]


def cpu_model() -> str:
    """The CPU's model name (Linux), else what ``platform`` knows."""
    try:
        with open("/proc/cpuinfo") as info:
            for line in info:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / KIB_PER_MIB  # Linux: KiB


def case_config(points: int, sparse: bool, **overrides) -> PilcoConfig:
    """The benchmark's PILCO settings (cart-pole, :data:`NUM_BASIS`, :data:`HORIZON`, then
    ``overrides``); an exact GP on all ``points`` unless ``sparse``."""
    config = PilcoConfig.for_system(
        "cartpole", **{"num_basis": NUM_BASIS, "horizon": HORIZON, **overrides}
    )
    if not sparse:
        config.gp = GPSettings(max_full_points=max(points, config.gp.max_full_points))
    return config


def run_case(points: int, sparse: bool, repeats: int, policy_iterations: int | None) -> dict:
    """One case in this process; returns its figures."""
    system = make_system("cartpole")
    overrides = {} if policy_iterations is None else {"policy_iterations": policy_iterations}
    config = case_config(points, sparse, **overrides)
    inputs, targets = cartpole_data(points, seed=0)
    start = time.perf_counter()
    model = fit_gp(inputs, targets, config.gp, np.random.default_rng(0))
    fit_seconds = time.perf_counter() - start
    rss_after_fit = peak_rss_mib()
    policy = build_policy(system, config, torch.Generator().manual_seed(0), inputs[:, :5])
    times = []
    for _ in range(repeats + 1):  # the first run is a warm-up
        policy.zero_grad()
        start = time.perf_counter()
        predict_policy(policy, model, system, config).total_cost.backward()
        times.append(time.perf_counter() - start)
    times = times[1:]
    # One full PILCO iteration: GP fit, then the policy optimisation of the training loop.
    start = time.perf_counter()
    model = fit_gp(inputs, targets, config.gp, np.random.default_rng(0))
    iteration_fit = time.perf_counter() - start
    start = time.perf_counter()
    optimisation = optimise_policy(policy, model, system, config)
    optimise_seconds = time.perf_counter() - start
    return {
        "points": points,
        "model": "FITC" if model.sparse else "exact GP",
        "support": int(model.support.shape[0]),
        "gp_fit_s": fit_seconds,
        "value_grad_median_s": statistics.median(times),
        "value_grad_min_s": min(times),
        "value_grad_max_s": max(times),
        "repeats": repeats,
        "iteration_fit_s": iteration_fit,
        "optimise_s": optimise_seconds,
        "policy_iterations": optimisation.iterations,
        "evaluations": optimisation.evaluations,
        "restarts": optimisation.restarts,
        "optimised_cost": optimisation.cost,
        "rss_after_fit_mib": rss_after_fit,
        "peak_rss_mib": peak_rss_mib(),
    }


def run_in_subprocess(name: str, args: argparse.Namespace) -> dict:
    command = [sys.executable, __file__, "--case", name, "--repeats", str(args.repeats)]
    command += ["--threads", str(args.threads)]
    if args.policy_iterations is not None:
        command += ["--policy-iterations", str(args.policy_iterations)]
    out = subprocess.run(command, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def table(results: dict[str, dict]) -> list[str]:
    lines = [
        "| case | model (M) | value+grad median s (range) | TF ref s | speed-up | GP fit s "
        "| full iteration s (fit + optimise) | L-BFGS it / evals (restarts) | s per eval "
        "| peak RSS MiB |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in results.items():
        ref = REFERENCE_VALUE_GRAD_S.get(name)
        median = r["value_grad_median_s"]
        full = r["iteration_fit_s"] + r["optimise_s"]
        per_eval = r["optimise_s"] / max(1, r["evaluations"])
        lines.append(
            f"| N={name} | {r['model']} ({r['support']}) | {median:.3f} "
            f"({r['value_grad_min_s']:.3f}-{r['value_grad_max_s']:.3f}, {r['repeats']} runs) | "
            f"{'-' if ref is None else f'{ref:.2f}'} | "
            f"{'-' if ref is None else f'{ref / median:.1f}x'} | {r['gp_fit_s']:.2f} | "
            f"{full:.1f} ({r['iteration_fit_s']:.1f} + {r['optimise_s']:.1f}) | "
            f"{r['policy_iterations']} / {r['evaluations']} ({r['restarts']}) | {per_eval:.3f} | "
            f"{r['peak_rss_mib']:.0f} |"
        )
    return lines


def targets(results: dict[str, dict]) -> list[str]:
    lines = []
    for name, limit in TARGET_VALUE_GRAD_S.items():
        if name in results:
            got = results[name]["value_grad_median_s"]
            verdict = "met" if got <= limit else "MISSED"
            lines.append(
                f"- value+grad at N={name} <= {limit} s ({SPEED_FACTOR:.0f}x faster than the "
                f"reference's {REFERENCE_VALUE_GRAD_S[name]} s): {got:.3f} s, {verdict}"
            )
    limit_mib = TARGET_PEAK_GB * MIB_PER_GB
    for name in ("400", "400-FITC"):
        if name in results:
            got = results[name]["peak_rss_mib"]
            verdict = "met" if got <= limit_mib else "MISSED"
            lines.append(
                f"- peak RSS at N={name} <= {TARGET_PEAK_GB} GB ({limit_mib:.0f} MiB): "
                f"{got:.0f} MiB, {verdict}"
            )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--policy-iterations", type=int, default=None, help="default: the training default"
    )
    parser.add_argument("--quick", action="store_true", help="3 repeats, 10 L-BFGS iterations")
    parser.add_argument("--cases", nargs="+", default=[c[0] for c in CASES])
    parser.add_argument("--threads", type=int, default=THREADS)
    parser.add_argument("--case", help=argparse.SUPPRESS)  # internal: one case, JSON out
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if args.quick:
        args.repeats, args.policy_iterations = QUICK_REPEATS, QUICK_POLICY_ITERATIONS
    if args.case:
        _, points, sparse = next(c for c in CASES if c[0] == args.case)
        print(json.dumps(run_case(points, sparse, args.repeats, args.policy_iterations)))
        return
    load = os.getloadavg()
    print(
        f"PILCO benchmark: cart-pole, horizon {HORIZON}, RBF {NUM_BASIS} basis, float64, "
        f"{args.threads} threads, torch {torch.__version__}, {cpu_model()} x {os.cpu_count()} "
        f"cores, load average at start {load[0]:.2f} {load[1]:.2f} "
        f"{load[2]:.2f}\n"
    )
    results = {}
    for name in args.cases:
        results[name] = run_in_subprocess(name, args)
        # Each case's row as soon as it is measured (a long run keeps what it has).
        print(table({name: results[name]})[-1], f"(load {os.getloadavg()[0]:.2f})", flush=True)
    print()
    print("\n".join(table(results)))
    print(f"\nTargets (load average at end {os.getloadavg()[0]:.2f}):")
    print("\n".join(targets(results)))


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
