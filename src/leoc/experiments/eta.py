r"""The time a sweep has left, from the expected cost of each run, refined as runs progress.

Each run has an expected wall time :math:`c` (seconds on one worker: the profile's measured
costs, :attr:`leoc.experiments.profiles.Profile.run_seconds`). What the runs have shown so far
scales them all by one speed factor, shrunk towards 1 by a prior worth ``PRIOR_WEIGHT_S``
seconds of expected work:

.. math:: f = \frac{\sum_\mathrm{done} a_j + \sum_\mathrm{running} e_i + W}
                   {\sum_\mathrm{done} c_j + \sum_\mathrm{running} p_i c_i + W}

(:math:`a_j` the wall time of a finished run, :math:`e_i` the elapsed time of a running run
whose log says how far it is, :math:`p_i` that fraction). A running run has
:math:`f c_i (1 - p_i)` left (or :math:`\max(f c_i - e_i, 1\,\mathrm{s})` when its log does not
say), a queued one :math:`f c`; the queue is then dealt, in order, to whichever worker is free
first, and the ETA is when the last one finishes (so a few short runs at the end do not look
like a long tail, and one long run does).

Runs of one *kind* (the sweep's ``kind_of``; ``leoc reproduce`` gives the learner: PILCO, DDPG,
SAC or linear) share a factor of their own, :math:`f_k`: the same sums over that kind's runs,
with the prior :math:`W` worth the factor of all runs instead of 1 (a kind may be a path,
``pilco/cartpole``, each level shrunk towards its parent; kind ``""``, the default, is the
single factor :math:`f`).

What the ETA gets wrong, measured by :func:`replay` on the committed studies' run times
(``results/paper``: 141 runs, ``results/paper-authors``: 42, 2 workers, a report every 15 s):

- it starts 48% (leoc's variant) and 182% (the authors') above the time the runs took, because
  the cost table is stale: the runs took 0.42x their expected time for DDPG, 0.39x for PILCO,
  0.23x for the linear designs, but 1.13x for SAC (the table was measured at older commits),
  and the authors' variant, costed with leoc's table, 0.35x;
- it jumps when the first run finishes (leoc's study: from 48% over to 40% under, a jump of
  10,700 s, as a cart-pole PILCO run ends after 156 s of its expected 469 s and its 0.4x is
  applied to every learner, SAC's 1.13x runs too), and again as runs of learners with other
  errors finish;
- with the table re-measured (each kind's median time in the same study, so in sample) the
  error is within 2% (median over the reports; 90th percentile 5-6%) from the first report on,
  with one factor or one per learner; with the stale table, a factor per learner cuts the
  median error on leoc's study from 25% to 16% but raises the authors' from 5% to 22% (their
  table's 3x dominates either way).

A run that resumes work an earlier invocation (or a failed attempt) began is left out of the
factors, running or finished: its wall time covers only the rest of its work (a study resumed
from checkpoints whose first runs only had their evaluation left made a cart-pole PILCO study's
ETA 26 minutes where 90 were left).

So the costs are to be measured on the code that runs (per variant); the factors per learner
then keep the residual small. The profiles' tables now are (:func:`measured_run_seconds` on
both studies, ``benchmarks/bench_eta_costs.py``, the authors' variant costed by its own): the
replay's first report is -0.6% (leoc's) and +0.3% (the authors') off, the median error 0.7%
and 2.1% (in sample; with each run costed by its kind's other seeds, +0.2%/0.5% and
0.0%/0.8%).
"""

from __future__ import annotations

import heapq
import json
import re
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

PRIOR_WEIGHT_S = 60.0
"""Seconds of expected work the prior speed factor (1) is worth."""
MIN_REMAINING_S = 1.0
"""What a running run that has outlived its expectation is still given."""
_DDPG = re.compile(r"\[(?:ddpg|td3|sac)\] step (\d+)/(\d+)")
COST_DECIMALS = 1
"""Decimals of the measured run costs [s] (:func:`measured_run_seconds`): a linear design takes
about 1 s."""


class Finished(NamedTuple):
    """A finished run: its expected and actual wall time [s], and its kind."""

    expected: float
    actual: float
    kind: str = ""


class Running(NamedTuple):
    """A running run: expected wall time and elapsed time [s], the fraction of its work done as
    its log says (None when the log does not say), its kind, and whether it is timed (not when
    it resumed work an earlier attempt began: its elapsed time then covers only part of it)."""

    expected: float
    elapsed: float
    fraction: float | None = None
    kind: str = ""
    timed: bool = True


class Queued(NamedTuple):
    """A queued run: its expected wall time [s] and its kind."""

    expected: float
    kind: str = ""


def trainer_progress(line: str) -> float | None:
    """The fraction of a run's work done, from its last log line, where the line measures it.

    ``[ddpg] step K/N`` (or ``[td3]``, ``[sac]``): K/N (steps cost alike, and the line comes
    every few seconds). A PILCO line (``[pilco] iter K/N``) gives None: it comes once per
    iteration (a fifth of a quick-profile run) after a start-up it does not count, and its
    iterations do not cost alike (quick profile, idle 2-core machine: one pendulum run's took
    26, 19, 7, 18 and 23 s, the same run's first 40 s in another invocation). Read as K/N, or as
    K(K+1)/(N(N+1)) before, the first minute looked like a slow run and the quick profile's ETA
    at one minute came out 66-86% above the actual remaining time; without it a PILCO run
    counts by its elapsed time against its expected cost (-9% at one minute on an invocation
    the cost table was not measured on). None for any other line too.
    """
    match = _DDPG.search(line)
    if match:
        done, total = int(match.group(1)), int(match.group(2))
        return min(done / total, 1.0) if total > 0 else None
    return None


def speed_factor(
    finished: Sequence[Finished], running: Sequence[Running], prior: float = 1.0
) -> float:
    """How much slower (> 1) or faster than expected the runs have gone so far (``prior``: the
    factor assumed before any run, worth ``PRIOR_WEIGHT_S`` seconds of expected work)."""
    measured = sum(run.actual for run in finished)
    expected = sum(run.expected for run in finished)
    for run in running:
        if run.fraction and run.timed:
            measured += run.elapsed
            expected += run.fraction * run.expected
    return (measured + prior * PRIOR_WEIGHT_S) / (expected + PRIOR_WEIGHT_S)


def kind_factors(
    finished: Sequence[Finished], running: Sequence[Running], kinds: Sequence[str]
) -> dict[str, float]:
    """The speed factor of each kind in ``kinds`` (see the module docstring): a kind is a
    path, ``pilco/cartpole`` inside ``pilco``; each level's factor is its runs' shrunk towards
    its parent's, the root's (kind ``""``) all runs' shrunk towards 1."""
    factors: dict[str, float] = {"": speed_factor(finished, running)}

    def factor(kind: str) -> float:
        if kind not in factors:
            parent = kind.rpartition("/")[0]
            factors[kind] = speed_factor(
                [run for run in finished if _within(run.kind, kind)],
                [run for run in running if _within(run.kind, kind)],
                factor(parent),
            )
        return factors[kind]

    return {kind: factor(kind) for kind in set(kinds)}


def _within(kind: str, level: str) -> bool:
    return kind == level or kind.startswith(level + "/")


def _left(run: Running, factor: float) -> float:
    if run.fraction is not None:
        return factor * run.expected * (1.0 - run.fraction)
    return max(factor * run.expected - run.elapsed, MIN_REMAINING_S)


def estimate_remaining(
    finished: Sequence[Finished],
    running: Sequence[Running],
    queued: Sequence[float | Queued],
    slots: int,
) -> float:
    """Seconds until every run has finished (see the module docstring).

    ``queued``: the queued runs (:class:`Queued`, or their expected wall times alone, of kind
    ``""``), in the order they will start; ``slots``: runs at a time.
    """
    waiting = [item if isinstance(item, Queued) else Queued(float(item)) for item in queued]
    factors = kind_factors(
        finished, running, [run.kind for run in running] + [item.kind for item in waiting]
    )
    free = [_left(run, factors[run.kind]) for run in running]
    free += [0.0] * max(0, slots - len(free))
    heapq.heapify(free)
    end = max(free, default=0.0)
    for item in waiting:
        start = heapq.heappop(free)
        finish = start + factors[item.kind] * item.expected
        end = max(end, finish)
        heapq.heappush(free, finish)
    return end


class ReplayPoint(NamedTuple):
    """One progress report of a replayed sweep: its time, the ETA then and the truth [s]."""

    seconds: float
    eta: float
    remaining: float


def replay(
    runs: Sequence[Finished],
    slots: int,
    interval: float,
    reports_progress: Sequence[str] = (),
    use_kinds: bool = True,
) -> list[ReplayPoint]:
    """The ETA a sweep would have printed every ``interval`` seconds, had its runs (in queue
    order, with their expected and actual wall times and kinds) taken the times they took.

    The queue is dealt to ``slots`` workers; a running run of a kind in ``reports_progress``
    tells its fraction done as elapsed over actual time (a trainer whose log measures its
    steps), the others tell nothing. ``use_kinds=False``: one factor for every run (the ETA
    before per-kind factors), for comparison.
    """
    kind_of = (lambda run: run.kind) if use_kinds else (lambda run: "")
    free = [(0.0, slot) for slot in range(slots)]
    schedule = []  # (start, end, run)
    for run in runs:
        start, slot = heapq.heappop(free)
        schedule.append((start, start + run.actual, run))
        heapq.heappush(free, (start + run.actual, slot))
    end = max(stop for _, stop, _ in schedule)
    points, now = [], 0.0
    while now < end:
        finished = [
            Finished(run.expected, run.actual, kind_of(run))
            for _, stop, run in schedule
            if stop <= now
        ]
        running = [
            Running(
                run.expected,
                now - start,
                (now - start) / run.actual if run.kind in reports_progress else None,
                kind_of(run),
            )
            for start, stop, run in schedule
            if start <= now < stop
        ]
        queued = [Queued(run.expected, kind_of(run)) for start, _, run in schedule if start > now]
        points.append(
            ReplayPoint(now, estimate_remaining(finished, running, queued, slots), end - now)
        )
        now += interval
    return points


class RunTime(NamedTuple):
    """One finished run of a ``leoc reproduce`` folder: its system, controller, seed and wall
    time [s] (``evaluation.json``'s ``wall_seconds``: training and evaluation on one worker)."""

    system: str
    controller: str
    seed: int
    wall_seconds: float


def run_times(folder: str | Path) -> list[RunTime]:
    """Every finished run under ``folder/runs`` (``SYSTEM/CONTROLLER/seedN/evaluation.json``).

    Raises
    ------
    ValueError
        Naming the folder, when it holds no finished run.
    """
    from leoc.experiments.layout import EVALUATION_FILE

    found = []
    for path in sorted(Path(folder).glob(f"runs/*/*/seed*/{EVALUATION_FILE}")):
        data = json.loads(path.read_text())
        spec = data["spec"]
        found.append(
            RunTime(
                spec["system"], spec["controller"], int(spec["seed"]), float(data["wall_seconds"])
            )
        )
    if not found:
        raise ValueError(
            f"folder: expected finished runs under {Path(folder) / 'runs'}, found none"
        )
    return found


def measured_run_seconds(folder: str | Path) -> dict[str, float]:
    """The expected cost of each run kind, measured on a finished ``leoc reproduce`` folder.

    Parameters
    ----------
    folder : path
        The folder (``results/paper``): every run in it counts (:func:`run_times`).

    Returns
    -------
    dict ``"system/controller"`` -> float
        The median over seeds of each kind's wall time [s], rounded to ``COST_DECIMALS``, in
        the order of the folder's ``meta.json`` (its systems, then its controllers): the form
        of :attr:`leoc.experiments.profiles.Profile.run_seconds`. The median, not the mean: a
        PILCO run that stops early, or one that shared the machine, is one seed of several.
    """
    from leoc.experiments.layout import META_FILE

    walls: dict[str, list[float]] = {}
    for run in run_times(folder):
        walls.setdefault(f"{run.system}/{run.controller}", []).append(run.wall_seconds)
    meta = json.loads((Path(folder) / META_FILE).read_text())
    order = [f"{system}/{name}" for system in meta["systems"] for name in meta["controllers"]]
    ranked = sorted(walls, key=lambda kind: order.index(kind) if kind in order else len(order))
    return {kind: round(statistics.median(walls[kind]), COST_DECIMALS) for kind in ranked}


def measured_learner_seconds(folder: str | Path) -> dict[str, float]:
    """The median wall time [s] of each learner's runs (``linear``, ``ddpg``, ``sac``,
    ``pilco``: ``leoc.names.controller_framework``) over every system, controller and seed
    of a finished ``leoc reproduce`` folder, rounded to ``COST_DECIMALS``: the expected cost of
    a run of a kind no profile has measured (a user's system)."""
    from leoc.names import controller_framework

    walls: dict[str, list[float]] = {}
    for run in run_times(folder):
        walls.setdefault(controller_framework(run.controller), []).append(run.wall_seconds)
    return {
        learner: round(statistics.median(times), COST_DECIMALS) for learner, times in walls.items()
    }
