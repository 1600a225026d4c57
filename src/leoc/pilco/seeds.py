"""PILCO over several seeds: how often it learns, not whether one seed was lucky.

:func:`train_seeds` trains one PILCO run per seed in parallel worker processes (one torch thread
each), each stopping early once ``held_to_stop`` consecutive evaluations held the operating
point in every episode, and returns one :class:`SeedOutcome` per seed. The slow learning tests
assert a success rate with it and ``benchmarks/bench_pilco_seeds.py`` prints it.
"""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, NamedTuple

import torch

# Consecutive evaluations that held in every episode: the run has learnt the task.
HELD_TO_STOP = 2


class SeedOutcome(NamedTuple):
    """One seed's run.

    Attributes
    ----------
    seed : int
    success : bool
        The last ``held_to_stop`` evaluations held the operating point in every episode.
    first_held_iteration : int or None
        The first iteration whose evaluation held in every episode.
    first_held_interaction_seconds : float or None
        Interaction time on the real system up to and including that iteration.
    returns : list of float
        Mean evaluation return after each iteration (iteration 0: the random rollouts).
    lbfgs : list of (iterations, evaluations, restarts)
        Each policy optimisation's L-BFGS figures.
    wall_seconds : float
    run_dir : str
    """

    seed: int
    success: bool
    first_held_iteration: int | None
    first_held_interaction_seconds: float | None
    returns: list[float]
    lbfgs: list[tuple[int, int, int]]
    wall_seconds: float
    run_dir: str


def _train_one(
    system: str, hybrid: bool, seed: int, out: str, held_to_stop: int, overrides: dict[str, Any]
) -> SeedOutcome:
    from leoc.names import ControllerName
    from leoc.pilco.train import held_long_enough, train_pilco
    from leoc.training import run_folder

    torch.set_num_threads(1)
    started = time.perf_counter()
    controller = ControllerName("pilco", "paper" if hybrid else None).name
    run_dir = run_folder(out, system, controller, seed)
    result = train_pilco(
        system,
        hybrid=hybrid,
        seed=seed,
        run_dir=run_dir,
        progress=False,
        stop_after_held=held_to_stop,
        **overrides,
    )
    curve = result.curve
    first = next((row for row in curve if row["held_fraction"] >= 1.0), None)
    return SeedOutcome(
        seed=seed,
        success=held_long_enough(curve[1:], held_to_stop),
        first_held_iteration=None if first is None else first["iteration"],
        first_held_interaction_seconds=None if first is None else first["interaction_seconds"],
        returns=[float(row["mean_return"]) for row in curve],
        lbfgs=[
            (row["lbfgs_iterations"], row["lbfgs_evaluations"], row["lbfgs_restarts"])
            for row in curve[1:]
        ],
        wall_seconds=time.perf_counter() - started,
        run_dir=str(run_dir),
    )


def train_seeds(
    system: str,
    hybrid: bool,
    seeds: Sequence[int],
    out_dir: str | Path,
    jobs: int = 2,
    held_to_stop: int = HELD_TO_STOP,
    **overrides: Any,
) -> list[SeedOutcome]:
    """Train PILCO on ``system`` once per seed, ``jobs`` at a time; outcomes in seed order.

    ``overrides`` are :class:`~leoc.pilco.config.PilcoConfig` fields (``iterations=10`` ...).
    Run folders ``out_dir/SYSTEM/CONTROLLER/seedN`` (:func:`leoc.training.run_folder`) resume
    when they exist.
    """
    if jobs < 1:
        raise ValueError(f"jobs: expected a positive integer, found {jobs}")
    if held_to_stop < 1:
        raise ValueError(f"held_to_stop: expected a positive integer, found {held_to_stop}")
    # spawned, not forked: a fork of a process whose OpenMP threads already ran can hang
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(min(jobs, len(seeds)), mp_context=context) as pool:
        futures = [
            pool.submit(_train_one, system, hybrid, seed, str(out_dir), held_to_stop, overrides)
            for seed in seeds
        ]
        return [future.result() for future in futures]
