"""The authors' PILCO hybrid with one of their choices switched back to leoc's.

Trains the PILCO hybrid under the authors' variant (``leoc reproduce --variant authors``'s
settings at the paper's budget) with one switch, per seed, then prints the learnt Lambda, the
last evaluation and the impulse response under the authors' metric set on the plant it was
trained on. Switches:

* ``none``: the authors' settings as they are;
* ``quadrature``: leoc's Gauss-Hermite moments of the hybrid instead of the authors' mixture;
* ``fixed_lambda``: Lambda fixed at its initial value (1) instead of learnt;
* ``leoc_cost``: leoc's cost (the system's cost factor and width) instead of the authors'
  weights.

Each run is resumable (``train_pilco``'s checkpoint) and single-threaded (two torch processes
with default threads on 2 cores ran more than ten times slower than two with one thread each).

Prints one JSON line per run as it finishes, then a table: switch, seed, learnt log lambda,
last evaluation return and held fraction, impulse steady-state error, overshoot and settling
time. Run folders are kept under ``--out`` (rerunning resumes).

Usage::

    python benchmarks/bench_authors_pilco_switch.py quadrature fixed_lambda --seeds 0 1 --jobs 2

(about 8 minutes per run on one core; ``docs/results.md`` gives the figures of that command).
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from contextlib import redirect_stdout
from pathlib import Path

SWITCHES = ("none", "quadrature", "fixed_lambda", "leoc_cost")


def switch_overrides(switch: str, system: str) -> dict:
    """The PilcoConfig fields that undo one authors' choice (``{}`` for ``none``)."""
    from leoc.pilco.config import PilcoConfig

    if switch == "quadrature":
        return {"hybrid_method": "quadrature"}
    if switch == "fixed_lambda":
        return {"learn_lambda": False}
    if switch == "leoc_cost":
        return {"cost_weights": None, "cost_width": PilcoConfig.for_system(system).cost_width}
    if switch == "none":
        return {}
    raise ValueError(f"switch: expected one of {SWITCHES}, found {switch!r}")


def run_one(system: str, switch: str, seed: int, out: Path) -> dict:
    """Train one run (or resume it) and measure it."""
    import torch

    from leoc.cli import main
    from leoc.experiments.variants import AUTHORS
    from leoc.pilco.train import train_pilco

    torch.set_num_threads(1)
    settings = AUTHORS.training_settings("pilco", system, True)
    settings.update(switch_overrides(switch, system))
    folder = out / switch / f"seed{seed}"
    result = train_pilco(system, hybrid=True, seed=seed, run_dir=folder, progress=False, **settings)
    saved = torch.load(folder / "controller.pt", weights_only=False)
    impulse_file = folder / "impulse_authors.json"
    args = ["simulate", str(folder), "--metrics", "authors", "--json"]
    with impulse_file.open("w") as stream, redirect_stdout(stream):
        main(args)
    impulse = json.loads(impulse_file.read_text())["metrics"]
    last = result.curve[-1]
    return {
        "switch": switch,
        "seed": seed,
        "log_lambda": [round(v, 2) for v in saved["policy_state"]["log_lambda"].tolist()],
        "last_eval_return": round(float(last["mean_return"]), 1),
        "held": last.get("held_fraction"),
        "impulse": {k: impulse[k] for k in ("steady_state_error", "overshoot", "settling_time")},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("switches", nargs="+", choices=SWITCHES)
    parser.add_argument("--system", default="pendulum")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("runs/authors-pilco-switch"))
    args = parser.parse_args()
    jobs = [(args.system, s, seed, args.out) for s in args.switches for seed in args.seeds]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows = []
        for row in pool.map(run_one, *zip(*jobs, strict=True)):
            print(json.dumps(row), flush=True)
            rows.append(row)
    print_table(rows)


def print_table(rows: list[dict]) -> None:
    """One line per run: the switch, seed, learnt Lambda, last evaluation and impulse."""
    print(
        f"{'switch':<13} {'seed':>4} {'log lambda':<28} {'last return':>11} {'held':>5} "
        f"{'ss error':>9} {'overshoot':>9} {'settling':>8}"
    )
    for row in rows:
        impulse = row["impulse"]
        print(
            f"{row['switch']:<13} {row['seed']:>4} {str(row['log_lambda']):<28} "
            f"{row['last_eval_return']:>11} {row['held']!s:>5} "
            f"{impulse['steady_state_error']!s:>9.9} {impulse['overshoot']!s:>9.9} "
            f"{impulse['settling_time']!s:>8}"
        )


if __name__ == "__main__":
    main()
