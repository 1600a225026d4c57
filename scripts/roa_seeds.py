"""Measure the ROA-relevance DDPG hybrids against the paper-relevance hybrids (issue 10).

For each system and relevance ("paper", "roa") and seed, train a DDPG hybrid at a quick budget
(cart-pole 8000 steps, mountain car 6000 steps), then record

* the impulse response metrics of the best evaluated policy (``response_test``) beside the
  linear controller's (the LQR at the same period);
* the learning curve's interaction time to the first evaluation where every episode holds
  (``reached_steps * dt``) and the time from which every later evaluation holds;
* whether the hybrid's empirical basin contains the LQR's certified set (fraction of starts
  uniform in the certified set that converge and hold) and its basin in the default box.

Writes ``OUT/results.json`` and ``OUT/summary.md``; finished runs are reused (``--resume``).

Run (2 cores shared, be nice)::

    nice -n 10 env PYTHONPATH=src python scripts/roa_seeds.py --out runs/roa-seeds
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

BUDGETS = {"cartpole": 8000, "mountaincar": 6000}
RELEVANCES = ("paper", "roa")
SEEDS = (0, 1, 2)
CHECK_STARTS = 1000
BASIN_STARTS = 1000


def impulse(system: Any, controller: Any) -> dict[str, Any]:
    from leoc.evaluation.rollout import response_test

    result = response_test(system, controller, "impulse")
    metrics = result.metrics
    return {
        "steady_state_error": float(metrics.steady_state_error),
        "overshoot": float(metrics.overshoot),
        "peak": float(np.max(np.abs(result.deviation))),
        "settling_time": metrics.settling_time,
        "terminated": bool(result.trajectory.terminated),
    }


def basins(system: Any, controller: Any, certificate: Any) -> dict[str, float]:
    from leoc.control import basin_starts, certified_set_check, empirical_basin

    inside = certified_set_check(system, controller, certificate, CHECK_STARTS, seed=1)
    box = empirical_basin(system, controller, basin_starts(system, count=BASIN_STARTS, seed=2))
    return {"certified_set_held": inside.fraction, "box_held": box.fraction}


def run_one(system_name: str, relevance: str, seed: int, out: Path, certificate: Any) -> dict:
    from leoc.ddpg.train import train_ddpg
    from leoc.systems import make_system

    system = make_system(system_name)
    run_dir = out / f"{system_name}-{relevance}-seed{seed}"
    started = time.perf_counter()
    result = train_ddpg(
        system_name,
        algo="ddpg",
        hybrid=True,
        seed=seed,
        run_dir=run_dir,
        total_steps=BUDGETS[system_name],
        progress=False,
        relevance=relevance,
    )
    seconds = time.perf_counter() - started
    hybrid = result.policy.hybrid
    learned = (
        {"lambda": hybrid.lambda_.tolist()}
        if hybrid.relevance_module is None
        else {"width": float(hybrid.relevance_module.width)}
    )
    row = {
        "system": system_name,
        "relevance": relevance,
        "seed": seed,
        "train_seconds": seconds,
        "reached_seconds": None
        if result.reached_steps is None
        else result.reached_steps * system.dt,
        "held_seconds": None if result.held_steps is None else result.held_steps * system.dt,
        "best_return": result.best_return,
        "impulse": impulse(system, result.policy),
        **basins(system, result.policy, certificate),
        **learned,
    }
    (run_dir / "roa_measure.json").write_text(json.dumps(row, indent=1))
    return row


def fmt(value: Any, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}" if math.isfinite(value) else str(value)
    return str(value)


def summary(rows: list[dict], linear: dict[str, dict]) -> str:
    lines = [
        "| system | controller | seed | ss error | overshoot | peak | settling | terminated "
        "| reached s | held s | certified set held | box held | learned |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, entry in linear.items():
        imp = entry["impulse"]
        lines.append(
            f"| {name} | linear (LQR) | - | {fmt(imp['steady_state_error'])} | "
            f"{fmt(imp['overshoot'])} | {fmt(imp['peak'])} | {fmt(imp['settling_time'])} | "
            f"{imp['terminated']} | - | - | {fmt(entry['certified_set_held'])} | "
            f"{fmt(entry['box_held'])} | rho={fmt(entry['rho'], 5)} |"
        )
    for row in rows:
        imp = row["impulse"]
        learned = (
            f"w={row['width']:.3g}"
            if "width" in row
            else "lambda=" + ",".join(f"{v:.2g}" for v in row["lambda"])
        )
        lines.append(
            f"| {row['system']} | DDPG hybrid {row['relevance']} | {row['seed']} | "
            f"{fmt(imp['steady_state_error'])} | {fmt(imp['overshoot'])} | {fmt(imp['peak'])} | "
            f"{fmt(imp['settling_time'])} | {imp['terminated']} | {fmt(row['reached_seconds'])} | "
            f"{fmt(row['held_seconds'])} | {fmt(row['certified_set_held'])} | "
            f"{fmt(row['box_held'])} | {learned} |"
        )
    return "\n".join(lines) + "\n"


def plot_curves(out: Path, rows: list[dict]) -> Path | None:
    """Mean evaluation return against interaction time, one line per run, per system."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    systems = sorted({row["system"] for row in rows})
    if not systems:
        return None
    fig, axes = plt.subplots(1, len(systems), figsize=(6.0 * len(systems), 4.0), squeeze=False)
    colours = {"paper": "tab:blue", "roa": "tab:orange"}
    for axis, name in zip(axes[0], systems, strict=True):
        for row in rows:
            if row["system"] != name:
                continue
            folder = out / f"{name}-{row['relevance']}-seed{row['seed']}"
            curve = json.loads((folder / "curve.json").read_text())["curve"]
            seconds = [point["interaction_seconds"] for point in curve]
            returns = [point["mean_return"] for point in curve]
            axis.plot(
                seconds,
                returns,
                color=colours[row["relevance"]],
                alpha=0.8,
                label=f"{row['relevance']} seed {row['seed']}",
            )
        axis.set_title(f"{name}: DDPG hybrids, paper vs ROA relevance")
        axis.set_xlabel("interaction time [simulated s]")
        axis.set_ylabel("mean evaluation return")
        axis.legend(fontsize="small", loc="lower right")
        axis.grid(True, alpha=0.3)
    path = out / "learning_curves.png"
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("runs") / "roa-seeds")
    parser.add_argument("--systems", nargs="+", default=list(BUDGETS))
    parser.add_argument("--relevances", nargs="+", default=list(RELEVANCES))
    parser.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS))
    args = parser.parse_args()
    torch.set_num_threads(1)
    from leoc.control import certify_lqr, design_lqr, lqr_closed_loop
    from leoc.systems import make_system

    args.out.mkdir(parents=True, exist_ok=True)
    linear: dict[str, dict] = {}
    certificates = {}
    for name in args.systems:
        system = make_system(name)
        design = design_lqr(system)
        certificate = certify_lqr(system, design)
        certificates[name] = certificate
        controller = lqr_closed_loop(design)
        linear[name] = {
            "rho": certificate.rho,
            "impulse": impulse(system, controller),
            **basins(system, controller, certificate),
        }
        print(name, "linear", json.dumps(linear[name]), flush=True)
    rows = []
    for name in args.systems:
        for relevance in args.relevances:
            for seed in args.seeds:
                done = args.out / f"{name}-{relevance}-seed{seed}" / "roa_measure.json"
                if done.is_file():
                    row = json.loads(done.read_text())
                else:
                    row = run_one(name, relevance, seed, args.out, certificates[name])
                rows.append(row)
                print(json.dumps(row), flush=True)
                (args.out / "results.json").write_text(
                    json.dumps({"linear": linear, "runs": rows}, indent=1)
                )
                (args.out / "summary.md").write_text(summary(rows, linear))
    print(summary(rows, linear))
    print("learning curves:", plot_curves(args.out, rows))


if __name__ == "__main__":
    main()
