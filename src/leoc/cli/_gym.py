"""``leoc simulate`` and ``leoc roa`` on a gymnasium env (``gym:ENV_ID`` or a run folder of
``leoc train gym:ENV_ID``); heavy imports inside the functions."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from leoc.names import GYM_PREFIX, gym_env_id

#: ``leoc simulate`` options that describe a leoc system's simulation and mean nothing for a
#: gymnasium env, with the value that leaves them unset.
LEOC_ONLY_OPTIONS = {
    "action_repeat": 1,
    "method": None,
    "variant": None,
    "metrics": "leoc",
    "video": None,
    "plot": None,
}


def gym_run_system(path: str | Path) -> str | None:
    """The ``gym:ENV_ID`` a run folder was trained on, None for any other folder (or none)."""
    config = Path(path) / "config.json"
    if not config.is_file():
        return None
    try:
        system = json.loads(config.read_text()).get("system")
    except (OSError, ValueError, AttributeError):
        return None
    return system if isinstance(system, str) and gym_env_id(system) is not None else None


def check_gym_options(args: argparse.Namespace, gym: bool) -> None:
    """Refuse leoc-system options on a gymnasium env, and gymnasium options on a leoc system."""
    if gym:
        for name, unset in LEOC_ONLY_OPTIONS.items():
            if getattr(args, name) != unset:
                flag = "--" + name.replace("_", "-")
                raise ValueError(
                    f"{flag}: expected it left out for a gymnasium env (it sets a leoc "
                    f"system's simulation), found {getattr(args, name)}"
                )
        return
    for name in ("magnitude", "main_index", "env_option"):
        if getattr(args, name, None) is not None:
            flag = "--" + name.replace("_", "-")
            raise ValueError(
                f"{flag}: expected only for a gymnasium env ({GYM_PREFIX}ENV_ID or its run "
                f"folder), found {getattr(args, name)} for a leoc system"
            )


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _record(response: Any) -> dict[str, Any]:
    """A response as JSON: its metrics, deviation, return and termination."""
    return {
        "metrics": response.metrics._asdict(),
        "deviation": response.deviation.tolist(),
        "total_reward": response.total_reward,
        "terminated": response.terminated,
    }


def run_gym_simulate(args: argparse.Namespace, system: str, controller: str) -> int:
    """``leoc simulate`` on the gymnasium env of ``system`` (``gym:ENV_ID``): its LQR alone
    (``controller`` 'linear'), or a run folder's controller beside the run's LQR."""
    from leoc.evaluation.gym_response import gym_comparison, gym_response, load_gym_run
    from leoc.sb3.gym import gym_plant, make_gym_env

    check_gym_options(args, True)
    options = {"steps": args.steps, "magnitude": args.magnitude, "main_index": args.main_index}
    options["band"] = args.band
    if controller == "linear":
        from leoc.cli._args import env_kwargs_of
        from leoc.cli.train import check_env_kwargs
        from leoc.evaluation.gym_response import lqr_controller

        env_id = str(gym_env_id(system))
        kwargs = env_kwargs_of(getattr(args, "env_option", None))
        check_env_kwargs(env_id, kwargs)
        env = make_gym_env(env_id, kwargs)
        plant = gym_plant(env, env_id)
        env.close()
        options["env_kwargs"] = kwargs
        responses = {"lqr": gym_response(plant, lqr_controller(plant), args.test, **options)}
        distance = None
    else:
        if getattr(args, "env_option", None):
            raise ValueError(
                f"--env-option: expected it left out for a run folder (the run's own env_kwargs "
                f"are used), found {[f'{k}={v}' for k, v in args.env_option]}"
            )
        if gym_run_system(controller) != system:
            raise ValueError(
                f"--controller: expected a run folder trained on {system}, found {controller!r} "
                f"(trained on {gym_run_system(controller) or 'no gymnasium env'})"
            )
        run = load_gym_run(controller)
        options.update(env_kwargs=run.env_kwargs, seed=run.seed)
        result = gym_comparison(run.plant, run.controller, args.test, **options)
        responses = {"trained": result["controller"], "lqr": result["lqr"]}
        distance = result["distance_pct"]
    first = next(iter(responses.values()))
    if args.json:
        report = {"system": system, "controller": controller, "test": args.test}
        report.update(
            magnitude=first.magnitude.tolist(), main_index=first.main_index, unit=first.unit
        )
        report.update({key: _record(value) for key, value in responses.items()})
        report["distance_pct"] = None if distance is None else _finite(distance)
        print(json.dumps(report))
        return 0
    _print_gym(args, system, controller, responses, distance)
    return 0


def _settling(metrics: Any) -> str:
    if metrics.settling_time is None:
        return "not settled"
    return f"{metrics.settling_time} steps ({metrics.settling_seconds:.3g} s)"


def _print_gym(
    args: argparse.Namespace, system: str, controller: str, responses: dict, distance: Any
) -> None:
    """The metrics of each response in a column (the trained controller's, then the LQR's)."""
    first = next(iter(responses.values()))
    what = "forced to" if args.test == "impulse" else "offset by"
    print(
        f"{args.test} response of {controller} on {system} ({len(first.deviation) - 1} steps; "
        f"action {what} {', '.join(f'{v:.4g}' for v in first.magnitude)} "
        f"{'for the first step' if args.test == 'impulse' else 'on every step'}; main "
        f"coordinate: state[{first.main_index}] in {first.unit}; leoc metrics)"
    )
    names = {"trained": "trained", "lqr": "LQR"}
    print(f"  {'':20}" + "".join(f"{names[key]:>22}" for key in responses))
    rows = (
        ("steady-state error", lambda r: f"{r.metrics.steady_state_error:.6g}"),
        ("overshoot", lambda r: f"{r.metrics.overshoot:.6g}"),
        ("peak deviation", lambda r: f"{r.metrics.peak_deviation:.6g}"),
        ("settling time", lambda r: _settling(r.metrics)),
        ("settling band", lambda r: f"{r.metrics.band:.3g}"),
        ("terminated", lambda r: "yes" if r.terminated else "no"),
        ("return", lambda r: f"{r.total_reward:.4f}"),
    )
    for label, show in rows:
        print(f"  {label + ':':20}" + "".join(f"{show(r):>22}" for r in responses.values()))
    if distance is not None:
        print(f"  largest difference from the LQR: {distance:.4g}% of the LQR's peak deviation")


def refuse_gym_roa(specs: list[str]) -> None:
    """``leoc roa --controller RUN_DIR`` on a gymnasium run: one line saying why nothing can be
    proved there, with the sampled level of its ``design.json`` when it has one."""
    for spec in specs:
        system = gym_run_system(spec)
        if system is None:
            continue
        design = Path(spec) / "design.json"
        data = (
            json.loads(design.read_text()).get("relevance_data") or {} if design.is_file() else {}
        )
        level = (
            f"the sampled level in {design} is rho = {data['rho']:.6g} (seeded starts held by "
            f"the LQR on the env: evidence, not a proof)"
            if isinstance(data.get("rho"), (int, float))
            else f"{design} records no sampled level for this run"
        )
        raise ValueError(
            f"--controller: {spec!r} was trained on the gymnasium env {system}, which has no "
            f"interval model, so no region of attraction can be proved for it; {level}"
        )
