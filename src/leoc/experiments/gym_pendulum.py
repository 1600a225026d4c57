r"""Gymnasium's ``Pendulum-v1`` through the adapter against leoc's own pendulum (same dynamics).

leoc's pendulum (:mod:`leoc.systems.pendulum`) is ``Pendulum-v1``'s dynamics and reward written
as a torch step; :func:`~leoc.sb3.train_gym` trains on gymnasium's own env through the adapter
(a finite-difference linearisation, the env's own step and reset). Trained with the same learner
and settings, the two paths should give the same results within seed noise; this part of the
gym study (:mod:`leoc.experiments.gym_study`) measures whether they do.

**Arms**, each over the study's seeds, for SAC alone (``sac_baseline``) and the SAC hybrid with
the paper's relevance and no floor (``sac_hybrid``; the floor needs the state, and
``Pendulum-v1`` shows ``[cos, sin, theta_dot]``):

- ``leoc``: :func:`~leoc.sb3.train_ddpg` on leoc's pendulum system, its swing-up starts
  (hanging, +/- 10 degrees and 0.1 rad/s);
- ``gymnasium``: :func:`~leoc.sb3.train_gym` on ``Pendulum-v1``, its own starts (anywhere on the
  circle, +/- 1 rad/s), the operating point the upright rest, the LQR with the pendulum's own
  weights (``Q = diag(2, 2)``, ``R = 1``).

Both with leoc's pendulum SAC settings (:func:`pendulum_settings`: 400-300 networks, 10k steps,
Adam 1e-3; ``DDPGConfig.for_system("pendulum", "sac")``) and the final policy (a gymnasium run
keeps its final policy, so the ``leoc`` arm does too, not its default best held-out model).
The two arms differ in the plant's implementation, the linearisation (autodiff against central
differences) and the *training* start distribution, which each env defines for itself.

**Evaluation** of every final controller on two tasks, the same episodes for every run of a
study seeded ``b``:

- ``return``: the mean return of ``Pendulum-v1``'s own episodes (200 steps) from
  ``reset(seed=b + 20000 + j)``, the task rl-baselines3-zoo's published figure is about
  (:data:`ZOO_PENDULUM_SAC`, shown beside it);
- ``held``: the share of leoc's swing-up starts ``sample_start(default_rng(b + 20000 + j))``
  that the controller swings up and holds (:meth:`~leoc.systems.System.hold_step`: within 5
  degrees for the last 50 steps), simulated on leoc's pendulum.

**Agreement** per controller and task: P(a ``gymnasium`` seed scores above a ``leoc`` seed) with
its 95% interval (:func:`~leoc.experiments.stats.improvement_verdict`): ``unresolved`` (the
interval holds 0.5) or ``equal`` is agreement within seed noise; ``above`` or ``below`` is not.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from leoc.evaluation.gym_response import held_episodes
from leoc.experiments.stats import improvement_verdict
from leoc.io import read_json_object, write_json_atomic
from leoc.policies.spec import HybridSpec
from leoc.sb3 import DDPGConfig, GymController, load_ddpg_controller, train_ddpg
from leoc.sb3.gym import load_gym_controller, train_gym
from leoc.systems import make_system
from leoc.training import evaluate_episodes

__all__ = [
    "PENDULUM_ARMS",
    "PENDULUM_CONTROLLERS",
    "PENDULUM_ENV",
    "PENDULUM_PROFILES",
    "PENDULUM_SYSTEM",
    "PENDULUM_TASKS",
    "ZOO_PENDULUM_SAC",
    "PendulumProfile",
    "pendulum_agreement",
    "pendulum_settings",
    "swing_up_starts",
]

#: The gymnasium env of this part.
PENDULUM_ENV = "Pendulum-v1"
#: leoc's system with the same dynamics and reward.
PENDULUM_SYSTEM = "pendulum"
#: The two training paths, in table order.
PENDULUM_ARMS = ("leoc", "gymnasium")
#: The controllers trained on each path.
PENDULUM_CONTROLLERS = ("sac_baseline", "sac_hybrid")
#: The evaluation tasks (module docstring): the key of each run's record and what it measures.
PENDULUM_TASKS = {
    "mean_return": "mean return on Pendulum-v1's own episodes",
    "held_share": "share of leoc's swing-up starts held",
}
#: The operating point of ``Pendulum-v1``: the upright rest, no torque.
OPERATING_POINT = ([0.0, 0.0], [0.0])
#: rl-baselines3-zoo's published SAC figure on ``Pendulum-v1`` (one trained agent, evaluated
#: over 750 episodes), cited beside the ``return`` task; the zoo's own settings and budget.
ZOO_PENDULUM_SAC = {
    "mean_reward": -156.995,
    "std_reward": 88.714,
    "n_timesteps": 20_000,
    "eval_episodes": 750,
    "source": "DLR-RM/rl-baselines3-zoo, benchmark.md at commit "
    "0088472b8cb622732bdbc4aa3d0d0abde86c67ed (row 'sac Pendulum-v1'; the MuJoCo inverted "
    "pendulums have no SAC row there, nor at 02a1a9014660a15ae2ecba900576ca2c51cf0ed7)",
}


class PendulumProfile(NamedTuple):
    """The part's budget: SAC's ``total_steps`` and the ``settings`` both arms train with."""

    total_steps: int
    settings: dict[str, Any]


def pendulum_settings() -> dict[str, Any]:
    """leoc's pendulum SAC settings (``DDPGConfig.for_system("pendulum", "sac")``) as training
    overrides, with the final policy kept (JSON form)."""
    config = DDPGConfig.for_system(PENDULUM_SYSTEM, "sac").as_dict()
    dropped = ("system", "algo", "hybrid", "total_steps", "step_rules")
    settings = {key: value for key, value in config.items() if key not in dropped}
    return json.loads(json.dumps({**settings, "model_selection": "final"}))


#: The part's profiles, named as the study's: ``smoke`` (tiny networks, 300 steps; nothing is
#: learned) and ``full`` (:func:`pendulum_settings` at the pendulum's budget).
PENDULUM_PROFILES = {
    "smoke": PendulumProfile(
        300,
        {
            **pendulum_settings(),
            "actor_hidden": [16, 16],
            "critic_hidden": [16, 16],
            "batch_size": 32,
            "learning_starts": 100,
            "eval_interval": 100,
            "eval_episodes": 2,
        },
    ),
    "full": PendulumProfile(
        int(DDPGConfig.for_system(PENDULUM_SYSTEM, "sac").total_steps), pendulum_settings()
    ),
}


def swing_up_starts(seeds: list[int]) -> np.ndarray:
    """The ``held`` task's starts: leoc's pendulum swing-up start drawn from
    ``default_rng(seed)`` for each of the study's evaluation ``seeds`` (``(len(seeds), 2)``)."""
    system = make_system(PENDULUM_SYSTEM)
    return np.stack([system.sample_start(np.random.default_rng(s), "swing_up") for s in seeds])


def _train(arm: str, controller: str, seed: int, run_dir: Path, profile: PendulumProfile) -> Any:
    """Train (or resume, or return) one run; its final policy, a float64 torch module."""
    hybrid = HybridSpec("paper", r_min=None) if controller == "sac_hybrid" else None
    settings = {**profile.settings, "progress": False}
    args = (hybrid, seed, run_dir, profile.total_steps)
    if arm == "leoc":
        train_ddpg(PENDULUM_SYSTEM, "sac", *args, **settings)
        return load_ddpg_controller(run_dir)
    system = make_system(PENDULUM_SYSTEM)
    weights = {"Q": list(system.default_q), "R": list(system.default_r)}
    train_gym(PENDULUM_ENV, "sac", *args, operating_point=OPERATING_POINT, **weights, **settings)
    return load_gym_controller(run_dir).policy


def _evaluate(policy: Any, seeds: list[int]) -> dict[str, Any]:
    """Both tasks of one final policy (module docstring), on the study's evaluation ``seeds``
    (``b + 20000 + j``)."""
    returns = held_episodes(PENDULUM_ENV, {}, GymController(policy), seeds)["returns"]
    starts = swing_up_starts(seeds)
    swing_up = evaluate_episodes(make_system(PENDULUM_SYSTEM), policy, starts)
    return {
        "returns": returns,
        "mean_return": float(np.mean(returns)),
        "held": swing_up.held,
        "held_share": swing_up.held_fraction,
    }


def _record(arm: str, controller: str, seed: int, plan: dict[str, Any]) -> dict[str, Any]:
    """One run's record: its saved ``evaluation.json`` where the key matches, else trained
    and evaluated now (saved atomically)."""
    profile = plan["pendulum_profile"]
    folder = plan["out"] / "runs" / PENDULUM_ENV / arm / controller / f"seed{seed}"
    key = {
        "arm": arm,
        "controller": controller,
        "seed": seed,
        "total_steps": profile.total_steps,
        "settings": profile.settings,
        "evaluation_seeds": list(plan["evaluation_seeds"]),
    }
    path = folder / "evaluation.json"
    saved = read_json_object(path, print, "run record")
    if saved is not None and saved.get("key") == key:
        return saved
    started = time.perf_counter()
    policy = _train(arm, controller, seed, folder, profile)
    record = {"key": key, "seed": seed, **_evaluate(policy, list(plan["evaluation_seeds"]))}
    record["wall_seconds"] = time.perf_counter() - started
    write_json_atomic(path, record, indent=1)
    return record


def _agreement(runs: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """Per task, :func:`~leoc.experiments.stats.improvement_verdict` of the ``gymnasium``
    arm's per-seed scores against the ``leoc`` arm's."""
    return {
        task: improvement_verdict(
            [run[task] for run in runs["gymnasium"]], [run[task] for run in runs["leoc"]]
        )
        for task in PENDULUM_TASKS
    }


def pendulum_agreement(plan: dict[str, Any], echo: Callable[[str], None]) -> dict[str, Any]:
    """The study's ``Pendulum-v1`` entry: every arm's runs per controller and their agreement.

    ``plan``: the study's settings (``out``, training ``seeds``, ``evaluation_seeds``,
    ``pendulum_profile``, and the progress counters ``done`` and ``total``)."""
    profile = plan["pendulum_profile"]
    entry: dict[str, Any] = {
        "total_steps": profile.total_steps,
        "settings": profile.settings,
        "evaluation_seeds": list(plan["evaluation_seeds"]),
        "zoo": ZOO_PENDULUM_SAC,
        "controllers": {},
    }
    for controller in PENDULUM_CONTROLLERS:
        runs: dict[str, list[dict[str, Any]]] = {}
        for arm in PENDULUM_ARMS:
            runs[arm] = []
            for seed in plan["seeds"]:
                runs[arm].append(_record(arm, controller, seed, plan))
                plan["done"] += 1
                echo(
                    f"[gym-study {plan['done']}/{plan['total']}] {PENDULUM_ENV} {arm} "
                    f"{controller} seed {seed}: mean return {runs[arm][-1]['mean_return']:.1f}, "
                    f"swing-up held {runs[arm][-1]['held_share']:.0%}"
                )
        entry["controllers"][controller] = {"runs": runs, "agreement": _agreement(runs)}
    return entry
