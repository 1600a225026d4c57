"""The acrobot's closing-note figures: its LQR (K, margins) and TD3 hybrid vs baseline.

Usage::

    PYTHONPATH=src python scripts/acrobot_measure.py --steps 4000 --seed 0 --out runs/acrobot

Prints the LQR design (K, spectral radius, gain and phase margins), trains a TD3 baseline and a
TD3 hybrid for ``--steps`` environment steps each (same seed), and prints their learning curves
(mean return and held fraction of the deterministic evaluations) and their impulse-response
metrics next to the linear controller's (:func:`leoc.evaluation.rollout.response_test`).
Writes ``summary.json`` in ``--out``.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
import torch

SYSTEM = "acrobot"


def _metrics(result) -> dict:
    metrics = result.metrics
    return {
        "peak_deviation_deg": float(metrics.peak_deviation),
        "steady_state_error_deg": float(metrics.steady_state_error),
        "overshoot_deg": float(metrics.overshoot),
        "settling_steps": metrics.settling_time if metrics.settled else None,
        "terminated": bool(metrics.terminated),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/acrobot_measure")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    from leoc.control import design_lqr
    from leoc.ddpg.train import load_ddpg_controller, train_ddpg
    from leoc.evaluation.rollout import response_test
    from leoc.policies import LinearController
    from leoc.systems import make_system

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    system = make_system(SYSTEM)
    design = design_lqr(system)
    margins = design.margins
    lqr = {
        "K": np.round(design.K, 4).tolist(),
        "spectral_radius": float(design.spectral_radius),
        "gain_margin": float(margins.gain_margin),
        "gain_interval": [float(v) for v in margins.gain_interval],
        "phase_margin_deg": float(margins.phase_margin),
    }
    print("LQR:", json.dumps(lqr))
    controllers = {"linear": LinearController(design.W, design.b)}
    curves = {}
    for kind, hybrid in (("baseline", False), ("hybrid", True)):
        run_dir = out / f"td3_{kind}_seed{args.seed}"
        train_ddpg(
            SYSTEM,
            "td3",
            hybrid=hybrid,
            seed=args.seed,
            run_dir=run_dir,
            total_steps=args.steps,
            progress=False,
        )
        controllers[f"td3_{kind}"] = load_ddpg_controller(run_dir)
        with open(run_dir / "curve.csv") as handle:
            curves[kind] = [{k: float(v) for k, v in row.items()} for row in csv.DictReader(handle)]
        for row in curves[kind]:
            print(
                f"td3 {kind}: step {int(row['steps'])}, return {row['mean_return']:.1f}, "
                f"held {row['held_fraction']:.2f}"
            )
    responses = {
        name: _metrics(response_test(system, controller, "impulse"))
        for name, controller in controllers.items()
    }
    for name, metrics in responses.items():
        print(f"impulse {name}: {json.dumps(metrics)}")
    summary = {"lqr": lqr, "steps": args.steps, "seed": args.seed, "curves": curves}
    summary["impulse"] = responses
    (out / "summary.json").write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
