"""Multi-seed measurement: DDPG/TD3, baseline vs LEOC hybrid, on the three systems.

For every (system, algo, policy, seed) this trains with the paper's defaults
(:func:`leoc.ddpg.train_ddpg`) into ``OUT/{system}-{algo}-{policy}-seed{seed}`` (skipped when
that run folder already holds a ``curve.json``, so an interrupted sweep resumes), then prints
and writes (``OUT/summary.json``, ``OUT/summary.csv``) per (system, algo, policy):

* reached: training steps (and simulated seconds) until the first evaluation in which every
  episode reaches and holds the operating point (:mod:`leoc.training`);
* held: steps (seconds) from which every later evaluation holds it;
* final / best: mean evaluation return of the final and of the best model;
* hold start: in the final evaluation, the mean episode step from which the episodes hold;
* final offset: the final model's mean absolute main coordinate (degrees, or metres for the
  car) over the last ``System.hold_min_steps`` steps of the evaluation episodes.

Means and standard deviations are over the seeds that got there; ``n`` says how many did.

Usage::

    nice python scripts/ddpg_seeds.py --systems pendulum cartpole mountaincar \
        --algos ddpg --seeds 0 1 2 --out runs/ddpg_seeds
    python scripts/ddpg_seeds.py --out runs/ddpg_seeds --report-only
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import statistics
import time
from pathlib import Path
from typing import Any

import torch

POLICIES = {"baseline": False, "hybrid": True}


def _run_name(system: str, algo: str, policy: str, seed: int) -> str:
    return f"{system}-{algo}-{policy}-seed{seed}"


def _final_offset(run_dir: Path, config: dict[str, Any]) -> float:
    """Mean |main coordinate| over the last ``hold_min_steps`` steps, final model, eval starts."""
    from leoc.ddpg import load_ddpg_controller
    from leoc.systems import make_system
    from leoc.systems.rollout import simulate
    from leoc.training import evaluation_starts

    system = make_system(config["system"])
    policy = load_ddpg_controller(run_dir, "final")
    batch = simulate(
        system, policy, evaluation_starts(system, config["seed"], config["eval_episodes"])
    )
    offsets = [
        float(abs(system.main_coordinate(states)[-system.hold_min_steps :]).mean())
        for states in batch.states
    ]
    return statistics.mean(offsets)


def _summarise_run(run_dir: Path) -> dict[str, Any]:
    data = json.loads((run_dir / "curve.json").read_text())
    config = json.loads((run_dir / "config.json").read_text())
    summary = data["summary"]
    final_starts = [s for s in data["curve"][-1].get("hold_steps", []) if s is not None]
    return {
        "system": config["system"],
        "algo": config["algo"],
        "policy": "hybrid" if config["hybrid"] else "baseline",
        "seed": config["seed"],
        "reached_steps": summary["reached_steps"],
        "reached_seconds": summary["reached_seconds"],
        "held_steps": summary["held_steps"],
        "held_seconds": summary["held_seconds"],
        "final_return": summary["final_return"],
        "best_return": summary["best_return"],
        "final_hold_start_step": statistics.mean(final_starts) if final_starts else None,
        "final_offset": _final_offset(run_dir, config),
        "total_steps": config["total_steps"],
    }


def _stat(values: list[Any]) -> str:
    present = [float(v) for v in values if v is not None]
    if not present:
        return f"-- (0/{len(values)})"
    mean = statistics.mean(present)
    std = statistics.pstdev(present) if len(present) > 1 else 0.0
    return f"{mean:.6g} +/- {std:.3g} ({len(present)}/{len(values)})"


def aggregate(rows: list[dict[str, Any]]) -> list[dict[str, str]]:
    """One line per (system, algo, policy): mean +/- std (count) of each measure."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["system"], row["algo"], row["policy"]), []).append(row)
    table = []
    for (system, algo, policy), members in sorted(groups.items()):
        line = {"system": system, "algo": algo, "policy": policy}
        line["seeds"] = ",".join(str(m["seed"]) for m in sorted(members, key=lambda m: m["seed"]))
        for key in (
            "reached_steps",
            "reached_seconds",
            "held_steps",
            "held_seconds",
            "final_return",
            "best_return",
            "final_hold_start_step",
            "final_offset",
        ):
            line[key] = _stat([m[key] for m in members])
        table.append(line)
    return table


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def report(out: Path) -> list[dict[str, str]]:
    rows = [_summarise_run(run) for run in sorted(out.iterdir()) if (run / "curve.json").is_file()]
    table = aggregate(rows)
    _write_atomic(out / "summary.json", json.dumps({"runs": rows, "table": table}, indent=2))
    if table:
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=list(table[0]))
        writer.writeheader()
        writer.writerows(table)
        _write_atomic(out / "summary.csv", buffer.getvalue())
    for line in table:
        print(" | ".join(f"{key}={value}" for key, value in line.items()))
    return table


def main(argv: list[str] | None = None) -> None:
    from leoc.ddpg import train_ddpg

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--systems", nargs="+", default=["pendulum", "cartpole", "mountaincar"])
    parser.add_argument("--algos", nargs="+", default=["ddpg"], choices=["ddpg", "td3"])
    parser.add_argument("--policies", nargs="+", default=list(POLICIES), choices=list(POLICIES))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--out", type=Path, default=Path("runs") / "ddpg_seeds")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--report-only", action="store_true")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.report_only:
        for seed in args.seeds:
            for system in args.systems:
                for algo in args.algos:
                    for policy in args.policies:
                        run_dir = args.out / _run_name(system, algo, policy, seed)
                        if (run_dir / "curve.json").is_file():
                            continue
                        start = time.perf_counter()
                        result = train_ddpg(
                            system,
                            algo,
                            hybrid=POLICIES[policy],
                            seed=seed,
                            run_dir=run_dir,
                            progress=False,
                        )
                        print(
                            f"{run_dir.name}: reached {result.reached_steps}, held "
                            f"{result.held_steps}, final {result.final_return:.1f}, best "
                            f"{result.best_return:.1f} ({time.perf_counter() - start:.0f} s)",
                            flush=True,
                        )
    report(args.out)


if __name__ == "__main__":
    main()
