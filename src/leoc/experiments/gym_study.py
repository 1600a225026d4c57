r"""A study of LEOC on MuJoCo's inverted pendulums (gymnasium), at growing start noise, and on
gymnasium's ``Pendulum-v1`` against leoc's own pendulum.

``Pendulum-v1`` among the study's envs (the default) runs :mod:`leoc.experiments.gym_pendulum`
instead of the grid below: SAC and the SAC hybrid trained on gymnasium's env through the adapter
and on leoc's pendulum (the same dynamics), and whether they agree within seed noise.

For each env (default ``InvertedPendulum-v5`` and ``InvertedDoublePendulum-v5``), each start
noise (the env's own ``reset_noise_scale``, 0.5 and 0.8), each controller of
:data:`~leoc.names.GYM_STUDY_CONTROLLERS` and each seed, :func:`run_gym_study` trains with
:func:`~leoc.sb3.train_gym` into ``OUT/runs/ENV/NOISE/CONTROLLER/seedK`` and evaluates:

- ``lqr``: the clipped LQR alone, ``clip(W o + b)``
  (:func:`~leoc.evaluation.gym_response.lqr_controller`), designed on the env at that noise
  with the seed (nothing trained);
- ``sac_baseline``: SAC alone, with rl-baselines3-zoo's MuJoCo settings (:data:`ZOO_SAC`);
- ``sac_hybrid``: the SAC hybrid with the paper's relevance and no floor (``r_min=None``: the
  floor needs the state, which ``InvertedDoublePendulum-v5``'s observation is not);
- ``sac_hybrid_roa``: the SAC hybrid with the ROA relevance on the *sampled* region
  (:func:`~leoc.sb3.sample_region`), only where the observation is the state; elsewhere its
  row says "not available: the observation is not the state".

**Evaluation** of each final controller (and of the LQR) on the same seeded starts: the
episodes of every run of a study whose seed base is ``b`` start from
``reset(seed=b + EVAL_SEED_OFFSET + j)`` of the env at that noise, whatever the run's training
seed (:func:`evaluation_seeds`: common starts, so rows and seeds differ by their controllers, not
by their starts; the learning curve's starts, ``s + 10000 + k``, are others), for the first
``episodes`` values of ``j`` whose start is *recoverable* (:func:`recoverable_seeds`), and run to
the env's time limit or its termination. A start is unrecoverable when the env terminates at
its first step under each of the operating action and the action space's two extreme corners:
at wide start noise ``InvertedPendulum-v5`` resets the pole beyond its 0.2 rad termination
angle on about half the seeds (14 of 30 at ``reset_noise_scale`` 0.5), and such an episode ends
at step 1 whatever the controller does, so it tells the controllers apart on nothing. The study
records how many seeds it skipped per noise. Per run: the **held share** (the episodes that reached
the time limit without termination), the **final return** (their mean return), the **steps to
95 %**: the first step of the learning curve whose mean evaluation return reaches 95 % of the
env's maximum return (:func:`maximum_return`: every step's reward
at rest at the operating point, for the whole episode), "not reached" otherwise; and the
**impulse distance**: the largest difference of the impulse response's main coordinate from the
LQR's, in percent of the LQR's peak (:func:`~leoc.evaluation.gym_response.gym_comparison`;
``None`` where only one of them terminated).

**Files**: each run keeps its record in ``evaluation.json`` beside the run (reused by a rerun
with the same settings); ``study.json`` holds every number and the command, and
:func:`write_study_report` writes ``README.md`` and one learning-curve figure per env from
``study.json`` alone (the same bytes every time). An interrupted study, rerun, continues where
it stopped: finished runs are not retrained (:func:`~leoc.sb3.train_gym` resumes a run from its
checkpoint, or returns a finished one).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from leoc.evaluation.gym_response import (
    gym_comparison,
    held_episodes,
    load_gym_run,
    lqr_controller,
)
from leoc.experiments.gym_pendulum import (
    PENDULUM_ARMS,
    PENDULUM_CONTROLLERS,
    PENDULUM_ENV,
    PENDULUM_PROFILES,
    pendulum_agreement,
)
from leoc.gym_adapter import state_access
from leoc.io import read_json_object, write_json_atomic
from leoc.names import (
    GYM_STUDY_CONTROLLERS,
    GYM_STUDY_DEFAULT_NOISE,
    GYM_STUDY_ENVS,
    GYM_STUDY_NOISES,
)
from leoc.policies.spec import HybridSpec
from leoc.sb3.gym import GymPlant, gym_plant, make_gym_env, train_gym

__all__ = [
    "EVAL_SEED_OFFSET",
    "PENDULUM_KEY",
    "RECORD_FILE",
    "RETURN_FRACTION",
    "RUNS_FOLDER",
    "STUDY_FILE",
    "STUDY_PROFILES",
    "ZOO_SAC",
    "ZOO_SOURCE",
    "ZOO_STEPS",
    "StudyProfile",
    "evaluation_seeds",
    "held_episodes",
    "recoverable_seeds",
    "maximum_return",
    "noise_kwargs",
    "run_gym_study",
    "steps_to_return",
]

#: The study's numbers, in the study folder.
STUDY_FILE = "study.json"
#: ``study.json``'s entry of the ``Pendulum-v1`` part (:mod:`leoc.experiments.gym_pendulum`).
PENDULUM_KEY = "pendulum_v1"
#: The folder of the runs, in the study folder (``runs/ENV/NOISE/CONTROLLER/seedK``).
RUNS_FOLDER = "runs"
#: A run's evaluation record, in its run folder.
RECORD_FILE = "evaluation.json"
#: Evaluation episode ``j`` of a study seeded ``b`` starts from ``reset(seed=b + 20000 + j)``.
EVAL_SEED_OFFSET = 20_000
#: :func:`recoverable_seeds` gives up after this many candidate seeds per wanted start.
MAX_SEEDS_PER_START = 20
#: The share of the env's maximum return that counts as learned (steps to 95 %).
RETURN_FRACTION = 0.95
#: Environment steps of rl-baselines3-zoo's MuJoCo SAC runs (``n_timesteps``).
ZOO_STEPS = 1_000_000
#: Where :data:`ZOO_SAC` comes from (cited, no code copied).
ZOO_SOURCE = (
    "DLR-RM/rl-baselines3-zoo, hyperparams/sac.yml at commit "
    "c94924e5b31bce36920f29d3eb18b975231bdec4, the MuJoCo anchor &mujoco-defaults (no "
    "InvertedPendulum entry for SAC): n_timesteps 1e6, MlpPolicy, learning_starts 10000, "
    "everything else SB3's SAC defaults"
)
#: rl-baselines3-zoo's MuJoCo SAC settings as :class:`~leoc.sb3.DDPGConfig` fields: SB3's SAC
#: defaults (256-256 networks, learning rate 3e-4, batch 256, buffer 1e6, polyak 0.005, gamma
#: 0.99, entropy coefficient auto, MSE critic loss, uniform random actions before learning
#: starts) with ``learning_starts`` 10000.
ZOO_SAC: dict[str, Any] = {
    "actor_hidden": (256, 256),
    "critic_hidden": (256, 256),
    "actor_learning_rate": 3e-4,
    "critic_learning_rate": 3e-4,
    "batch_size": 256,
    "buffer_size": 1_000_000,
    "polyak": 0.005,
    "discount": 0.99,
    "target_update_interval": 1,
    "train_freq": 1,
    "gradient_steps": 1,
    "learning_starts": 10_000,
    "warmup": "uniform",
    "critic_loss": "mse",
    "sac_entropy_coef": "auto",
}


class StudyProfile(NamedTuple):
    """A study's budget and settings: SAC's ``total_steps``, the number of ``seeds``, the
    evaluation ``episodes`` per run, :func:`~leoc.sb3.train_gym`'s ``settings`` and extra
    ``env_kwargs`` of ``gymnasium.make`` (on top of the start noise)."""

    name: str
    total_steps: int
    seeds: int
    episodes: int
    settings: dict[str, Any]
    env_kwargs: dict[str, Any]


#: The profiles: ``smoke``, a pipeline check (tiny networks, 300 steps, 60-step episodes, one
#: seed, two evaluation episodes; nothing is learned), and ``full``, the zoo's settings
#: (:data:`ZOO_SAC`) at 30k steps per run, 5 seeds, 30 evaluation episodes.
STUDY_PROFILES = {
    "smoke": StudyProfile(
        "smoke",
        300,
        1,
        2,
        {
            "actor_hidden": (16, 16),
            "critic_hidden": (16, 16),
            "batch_size": 32,
            "learning_starts": 100,
            "eval_interval": 100,
            "eval_episodes": 2,
            "roa_samples": 4,
            "roa_steps": 150,
            "checkpoint_interval": 100,
        },
        {"max_episode_steps": 60},
    ),
    "full": StudyProfile(
        "full", 30_000, 5, 30, {**ZOO_SAC, "eval_interval": 2_000, "eval_episodes": 5}, {}
    ),
}


def noise_kwargs(noise: str) -> dict[str, float]:
    """The ``gymnasium.make`` keywords of a start noise: none for ``"default"``, else
    ``reset_noise_scale`` (a positive number).

    Raises
    ------
    ValueError
        Naming ``noises``, for anything else.
    """
    if noise == GYM_STUDY_DEFAULT_NOISE:
        return {}
    try:
        value = float(noise)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(
            f"noises: expected {GYM_STUDY_DEFAULT_NOISE!r} or a positive reset_noise_scale, "
            f"found {noise!r}"
        )
    return {"reset_noise_scale": value}


def evaluation_seeds(base: int, episodes: int) -> list[int]:
    """The reset seeds of every evaluation of a study seeded ``base`` (every training seed and
    controller): ``base + 20000 + j``."""
    return [int(base) + EVAL_SEED_OFFSET + j for j in range(int(episodes))]


def _ends_at_once(env: Any, seed: int, actions: Sequence[np.ndarray]) -> bool:
    """Whether the env, reset with ``seed``, terminates at its first step under every one of
    ``actions``."""
    for action in actions:
        env.reset(seed=int(seed))
        if not env.step(action)[2]:
            return False
    return True


def recoverable_seeds(
    env_id: str, env_kwargs: Mapping[str, Any], action: Any, base: int, episodes: int
) -> tuple[list[int], list[int]]:
    """The evaluation seeds of a study seeded ``base`` (module docstring): the first
    ``episodes`` of :func:`evaluation_seeds`' sequence ``base + 20000 + j`` whose start is
    recoverable, i.e. the env does not terminate at its first step under at least one of the
    operating ``action`` and the action space's ``low`` and ``high`` corners; and the seeds
    skipped on the way.

    Raises
    ------
    RuntimeError
        When :data:`MAX_SEEDS_PER_START` ``* episodes`` candidates give fewer recoverable
        starts (a start noise so wide that the env has almost no recoverable start).
    """
    env = make_gym_env(env_id, env_kwargs)
    space = env.action_space
    actions = [np.asarray(action, dtype=space.dtype), space.low, space.high]
    kept: list[int] = []
    skipped: list[int] = []
    for seed in evaluation_seeds(base, MAX_SEEDS_PER_START * int(episodes)):
        if len(kept) == int(episodes):
            break
        (skipped if _ends_at_once(env, seed, actions) else kept).append(seed)
    env.close()
    if len(kept) < int(episodes):
        raise RuntimeError(
            f"{env_id} at {dict(env_kwargs)}: only {len(kept)} recoverable starts in "
            f"{len(kept) + len(skipped)} seeds, expected {episodes}"
        )
    return kept, skipped


def maximum_return(plant: GymPlant, env_kwargs: Mapping[str, Any]) -> float:
    """The env's maximum return: the reward of one step at rest at the operating point (the
    largest there is for the inverted pendulums: alive bonus, no distance or speed penalty),
    times the episode's steps (its time limit)."""
    env = make_gym_env(plant.env_id, env_kwargs)
    env.reset(seed=0)
    state_access(env).set(plant.state)
    _, reward, _, _, _ = env.unwrapped.step(plant.action)
    steps = int(env.spec.max_episode_steps)
    env.close()
    return float(reward) * steps


def steps_to_return(curve: Sequence[Mapping[str, Any]], target: float) -> int | None:
    """The first step of ``curve`` whose ``mean_return`` reaches ``target``; None if none."""
    for row in curve:
        if row["mean_return"] >= target:
            return int(row["steps"])
    return None


def _hybrid(controller: str) -> HybridSpec | None:
    """The hybrid of a study controller (None: SAC alone)."""
    return {
        "sac_baseline": None,
        "sac_hybrid": HybridSpec("paper", r_min=None),
        "sac_hybrid_roa": HybridSpec("roa"),
    }[controller]


class _Cell(NamedTuple):
    """One run of the study: where, what, and with which settings."""

    env_id: str
    noise: str
    controller: str
    seed: int
    env_kwargs: dict[str, Any]
    run_dir: Path
    profile: StudyProfile
    total_steps: int
    eval_seeds: tuple[int, ...]


def _record_key(cell: _Cell) -> dict[str, Any]:
    """What a run's saved record must match to be reused (JSON form)."""
    key = {
        "env_id": cell.env_id,
        "env_kwargs": cell.env_kwargs,
        "controller": cell.controller,
        "seed": cell.seed,
        "episodes": cell.profile.episodes,
        "total_steps": cell.total_steps,
        "settings": cell.profile.settings,
        "evaluation_seeds": list(cell.eval_seeds),
    }
    return json.loads(json.dumps(key))


def _evaluate_cell(cell: _Cell, plant: GymPlant, target: float) -> dict[str, Any]:
    """Train (``train_gym``: resumes, or returns a finished run) and evaluate one run; the LQR
    is designed, not trained."""
    seeds = list(cell.eval_seeds)
    started = time.perf_counter()
    if cell.controller == "lqr":
        controller, curve, distance = lqr_controller(plant), None, 0.0
    else:
        settings = {**cell.profile.settings, "progress": False}
        hybrid = _hybrid(cell.controller)
        args = (cell.env_id, "sac", hybrid, cell.seed, cell.run_dir, cell.total_steps)
        result = train_gym(*args, env_kwargs=cell.env_kwargs, **settings)
        run = load_gym_run(cell.run_dir)
        controller = run.controller
        curve = [
            {k: row[k] for k in ("steps", "mean_return", "held_fraction")} for row in result.curve
        ]
        options = {"env_kwargs": run.env_kwargs, "seed": run.seed}
        distance = float(
            gym_comparison(run.plant, controller, "impulse", **options)["distance_pct"]
        )
    episodes = held_episodes(cell.env_id, cell.env_kwargs, controller, seeds)
    return {
        "key": _record_key(cell),
        "seed": cell.seed,
        "evaluation_seeds": seeds,
        **episodes,
        "held_share": float(np.mean(episodes["held"])),
        "mean_return": float(np.mean(episodes["returns"])),
        "steps_to_95": None if curve is None else steps_to_return(curve, RETURN_FRACTION * target),
        "distance_pct": distance if np.isfinite(distance) else None,
        "curve": curve,
        "wall_seconds": time.perf_counter() - started,
    }


def _run_cell(cell: _Cell, plant: GymPlant, target: float) -> dict[str, Any]:
    """The record of one run: its saved ``evaluation.json`` when its key matches, else a new
    one (trained and evaluated, then saved atomically)."""
    path = cell.run_dir / RECORD_FILE
    saved = read_json_object(path, print, "run record")
    if saved is not None and saved.get("key") == _record_key(cell):
        return saved
    record = _evaluate_cell(cell, plant, target)
    cell.run_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, record, indent=1)
    return record


def _noise_entry(
    env_id: str, noise: str, plan: dict[str, Any], echo: Callable[[str], None]
) -> dict[str, Any]:
    """Every controller's runs of one env at one noise (``plan``: the study's settings)."""
    profile, out = plan["profile"], plan["out"]
    env_kwargs = {**profile.env_kwargs, **noise_kwargs(noise)}
    env = make_gym_env(env_id, env_kwargs)
    scale = float(getattr(env.unwrapped, "_reset_noise_scale", float("nan")))
    plants = {seed: gym_plant(env, env_id, seed=seed) for seed in plan["seeds"]}
    env.close()
    first = plants[plan["seeds"][0]]
    target = maximum_return(first, env_kwargs)
    args = (env_id, env_kwargs, first.action, plan["seeds"][0], profile.episodes)
    seeds, skipped = recoverable_seeds(*args)
    entry: dict[str, Any] = {"reset_noise_scale": scale, "env_kwargs": env_kwargs}
    entry.update(maximum_return=target, evaluation_seeds=seeds, skipped_seeds=skipped)
    entry["controllers"] = {}
    for controller in GYM_STUDY_CONTROLLERS:
        if controller == "sac_hybrid_roa" and not plants[plan["seeds"][0]].observation_is_state:
            reason = "not available: the observation is not the state"
            entry["controllers"][controller] = {"available": False, "reason": reason, "runs": []}
            plan["done"] += len(plan["seeds"])
            echo(
                f"[gym-study {plan['done']}/{plan['total']}] {env_id} noise {noise} {controller}: "
                f"{reason}"
            )
            continue
        runs = []
        for seed in plan["seeds"]:
            folder = out / RUNS_FOLDER / env_id / noise / controller / f"seed{seed}"
            cell = _Cell(
                env_id,
                noise,
                controller,
                seed,
                env_kwargs,
                folder,
                profile,
                plan["steps"],
                tuple(seeds),
            )
            runs.append(_run_cell(cell, plants[seed], target))
            plan["done"] += 1
            echo(
                f"[gym-study {plan['done']}/{plan['total']}] {env_id} noise {noise} {controller} "
                f"seed {seed}: held {runs[-1]['held_share']:.0%}, mean return "
                f"{runs[-1]['mean_return']:.1f}"
            )
        entry["controllers"][controller] = {"available": True, "reason": None, "runs": runs}
    return entry


def _study_plan(out: Path, profile: str, seed: int, counts: dict[str, int | None]) -> dict:
    """The study's settings, checked (one-line errors naming the argument); ``counts``: the
    numbers of ``seeds``, ``steps`` and ``episodes`` that override the profile's."""
    if profile not in STUDY_PROFILES:
        raise ValueError(f"profile: expected one of {tuple(STUDY_PROFILES)}, found {profile!r}")
    chosen = STUDY_PROFILES[profile]
    count = chosen.seeds if counts.get("seeds") is None else int(counts["seeds"])
    budget = chosen.total_steps if counts.get("steps") is None else int(counts["steps"])
    episodes = chosen.episodes if counts.get("episodes") is None else int(counts["episodes"])
    checks = (("seeds", count, 1), ("steps", budget, 1), ("episodes", episodes, 1))
    for name, value, low in (*checks, ("seed", seed, 0)):
        if value < low:
            raise ValueError(f"{name}: expected an integer >= {low}, found {value}")
    return {
        "out": Path(out),
        "profile": chosen._replace(episodes=episodes),
        "seeds": [int(seed) + k for k in range(count)],
        "evaluation_seeds": evaluation_seeds(seed, episodes),
        "pendulum_profile": PENDULUM_PROFILES[profile],
        "steps": budget,
        "done": 0,
    }


def _check_noises(noises: Sequence[str]) -> None:
    """Refuse a bad start noise before any run (:func:`noise_kwargs`)."""
    for noise in noises:
        noise_kwargs(noise)


def _study_total(plan: dict[str, Any], envs: Sequence[str], noises: Sequence[str]) -> int:
    """The number of runs of the study (the progress lines' denominator)."""
    grid = [env_id for env_id in envs if env_id != PENDULUM_ENV]
    total = len(grid) * len(noises) * len(GYM_STUDY_CONTROLLERS) * len(plan["seeds"])
    if PENDULUM_ENV in envs:
        total += len(PENDULUM_ARMS) * len(PENDULUM_CONTROLLERS) * len(plan["seeds"])
    return total


def _study_head(plan: dict[str, Any], command: str) -> dict[str, Any]:
    """``study.json``'s settings, before any env's entry."""
    chosen = plan["profile"]
    return {
        "command": command,
        "profile": chosen.name,
        "total_steps": plan["steps"],
        "seeds": plan["seeds"],
        "episodes": chosen.episodes,
        "settings": json.loads(json.dumps(chosen.settings)),
        "zoo_steps": ZOO_STEPS,
        "zoo_source": ZOO_SOURCE,
        "envs": {},
    }


def run_gym_study(
    out: str | Path,
    profile: str = "full",
    seeds: int | None = None,
    seed: int = 0,
    steps: int | None = None,
    episodes: int | None = None,
    envs: Sequence[str] = GYM_STUDY_ENVS,
    noises: Sequence[str] = GYM_STUDY_NOISES,
    command: str = "",
    echo: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Run (or resume) the study into ``out`` and write ``study.json``, ``README.md`` and the
    figures (module docstring).

    Parameters
    ----------
    out : path
        The study folder.
    profile : {"smoke", "full"}
        :data:`STUDY_PROFILES`; ``seeds``, ``steps`` and ``episodes`` override its number of
        seeds, its SAC budget (environment steps per run) and its evaluation episodes per run.
        ``Pendulum-v1`` trains at the pendulum's own budget
        (:data:`~leoc.experiments.gym_pendulum.PENDULUM_PROFILES`), not ``steps``.
    seed : int
        The seed base: training seeds ``seed, seed + 1, ...``; every other seed follows.
    envs, noises : sequences of str
        Gymnasium ids; start noises (``"default"`` or a ``reset_noise_scale``). ``Pendulum-v1``
        among the ids runs :mod:`leoc.experiments.gym_pendulum` (no start noises) instead.
    command : str
        The command line that made the study, written in the report.
    echo : callable
        Receives one progress line per finished run.

    Returns
    -------
    dict
        What ``study.json`` holds.
    """
    _check_noises(noises)
    counts = {"seeds": seeds, "steps": steps, "episodes": episodes}
    plan = _study_plan(Path(out), profile, seed, counts)
    plan["total"] = _study_total(plan, envs, noises)
    study = _study_head(plan, command)
    for env_id in envs:
        if env_id == PENDULUM_ENV:
            study[PENDULUM_KEY] = pendulum_agreement(plan, echo)
            continue
        study["envs"][env_id] = {noise: _noise_entry(env_id, noise, plan, echo) for noise in noises}
    write_json_atomic(plan["out"] / STUDY_FILE, study, indent=1)
    from leoc.experiments.gym_study_report import write_study_report

    write_study_report(plan["out"])
    return study
