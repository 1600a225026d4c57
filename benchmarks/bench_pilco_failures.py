"""Why PILCO runs fail: train PILCO runs as ``leoc reproduce`` trains them, and classify each.

For each system x PILCO controller x seed: trains the run exactly as ``leoc reproduce`` does
under the profile (default ``paper``: its budget, leoc's defaults; the ROA hybrid on its
certified LQR) into ``OUT/SYSTEM/CONTROLLER/seedN/train`` (resumed where a run stopped), then
prints, per run, the diagnosis of :func:`leoc.pilco.diagnose.diagnose_run` (held, or the class
of the failure with its evidence) and the count per class; then, for the runs whose final
controller is kept, :func:`leoc.pilco.diagnose.horizon_check`: the episodes that were up at the
prediction horizon's end and are not held at the episode's end. Only the training: no evaluation,
proof or protocol. ``--report-only`` prints the table of what ``OUT`` holds.

Usage::

    python benchmarks/bench_pilco_failures.py --out DIR [--systems pendulum cartpole]
        [--controllers pilco_baseline pilco_hybrid pilco_hybrid_roa] [--seeds 0 1 2 3 4]
        [--profile paper] [--jobs 2] [--report-only] [--runs SYSTEM/CONTROLLER/seedN ...]
        [--pilco-overrides '{"gp_max_snr": 100.0}']

``--pilco-overrides``: PILCO settings (:class:`~leoc.pilco.config.PilcoConfig` fields, JSON) laid
over the profile's own ``pilco_overrides``, for A/B studies of one learner choice: train each arm
into its own ``--out``.

Each run takes one torch thread; the paper profile's runs take about 1-3 minutes each on this
project's machine (the pendulum's about 1, the cart-pole's about 3).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import multiprocessing
import signal
from pathlib import Path

from leoc.pilco.diagnose import describe, describe_horizon, diagnose_run, horizon_check

PILCO_CONTROLLERS = ("pilco_baseline", "pilco_hybrid", "pilco_hybrid_roa")


def _train(key: str, profile_name: str, out: str, overrides: dict | None = None) -> str:
    """Train the run ``key`` (SYSTEM/CONTROLLER/seedN) of the profile, with ``overrides`` laid
    over its PILCO overrides; its train folder."""
    import contextlib

    import torch

    from leoc.experiments.profiles import get_profile, run_specs
    from leoc.experiments.reproduce import train_controller

    torch.set_num_threads(1)
    system, controller, seed = key.split("/")
    profile = get_profile(profile_name, seeds=int(seed.removeprefix("seed")) + 1)
    if overrides:
        merged = {**profile.pilco_overrides, **overrides}
        profile = dataclasses.replace(profile, pilco_overrides=merged)
    (spec,) = [s for s in run_specs(profile, (system,), (controller,)) if s.key == key]
    train_dir = Path(out) / key / "train"
    train_dir.mkdir(parents=True, exist_ok=True)
    with open(train_dir.parent / "train.log", "a", buffering=1) as log:
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            train_controller(spec, profile, train_dir)
    return str(train_dir)


def _overrides(parser: argparse.ArgumentParser, text: str | None) -> dict | None:
    """``--pilco-overrides`` as a dict of PilcoConfig fields (a clear error otherwise)."""
    if text is None:
        return None
    from leoc.pilco.config import PilcoConfig

    try:
        overrides = json.loads(text)
    except ValueError as error:
        parser.error(f"--pilco-overrides: expected a JSON object, found {text!r} ({error})")
    if not isinstance(overrides, dict):
        parser.error(f"--pilco-overrides: expected a JSON object, found {text!r}")
    try:
        PilcoConfig.for_system("pendulum", **overrides)
    except (TypeError, ValueError) as error:
        parser.error(f"--pilco-overrides: expected PILCO settings, found {text!r} ({error})")
    return overrides


def _stop(signum: int, frame: object) -> None:
    raise SystemExit(128 + signum)


def _train_all(keys: list[str], args: argparse.Namespace, overrides: dict | None) -> None:
    """Train the runs ``keys`` on ``args.jobs`` worker processes, in order. SIGTERM (or Ctrl-C)
    stops the workers too (a run resumes from its last finished iteration when the same command
    runs again); a process pool's workers would otherwise finish their runs orphaned."""
    signal.signal(signal.SIGTERM, _stop)
    pool = multiprocessing.get_context("spawn").Pool(args.jobs)
    try:
        pending = {
            key: pool.apply_async(_train, (key, args.profile, args.out, overrides)) for key in keys
        }
        for key, result in pending.items():
            result.get()
            print(f"trained {key}", flush=True)
    except BaseException:
        pool.terminate()
        raise
    finally:
        pool.close()
        pool.join()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="folder of the runs (resumed)")
    parser.add_argument("--systems", nargs="+", default=["pendulum", "cartpole"])
    parser.add_argument("--controllers", nargs="+", default=list(PILCO_CONTROLLERS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--profile", default="paper")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--report-only", action="store_true")
    parser.add_argument(
        "--runs", nargs="+", default=None, help="SYSTEM/CONTROLLER/seedN keys, in this order"
    )
    parser.add_argument(
        "--pilco-overrides", default=None, help="JSON object of PILCO settings (module doc)"
    )
    args = parser.parse_args()
    overrides = _overrides(parser, args.pilco_overrides)
    keys = args.runs or [
        f"{system}/{controller}/seed{seed}"
        for system in args.systems
        for controller in args.controllers
        for seed in args.seeds
    ]
    unknown = sorted(
        {key.split("/")[1] for key in keys if key.count("/") == 2} - set(PILCO_CONTROLLERS)
    )
    malformed = [
        key for key in keys if key.count("/") != 2 or not key.split("/")[2].startswith("seed")
    ]
    if unknown or malformed:
        parser.error(
            f"--controllers/--runs: expected SYSTEM/CONTROLLER/seedN with CONTROLLER one of "
            f"{PILCO_CONTROLLERS}, found {unknown + malformed}"
        )
    if not args.report_only:
        _train_all(keys, args, overrides)
    diagnoses = {}
    for key in keys:
        train_dir = Path(args.out) / key / "train"
        if (train_dir / "curve.json").is_file():
            diagnoses[key] = diagnose_run(train_dir)
    print(describe(diagnoses))
    # The final controllers that the runs kept, replayed against the horizon (runs published
    # without their controllers are left out).
    checks = {
        key: horizon_check(Path(args.out) / key / "train")
        for key in diagnoses
        if (Path(args.out) / key / "train" / "controller.pt").is_file()
    }
    if checks:
        print()
        print(describe_horizon(checks))


if __name__ == "__main__":
    main()
