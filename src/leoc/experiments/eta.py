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
"""

from __future__ import annotations

import heapq
import re
from collections.abc import Sequence
from typing import NamedTuple

PRIOR_WEIGHT_S = 60.0
"""Seconds of expected work the prior speed factor (1) is worth."""
MIN_REMAINING_S = 1.0
"""What a running run that has outlived its expectation is still given."""
_DDPG = re.compile(r"\[(?:ddpg|td3|sac)\] step (\d+)/(\d+)")


class Finished(NamedTuple):
    """A finished run: its expected and actual wall time [s]."""

    expected: float
    actual: float


class Running(NamedTuple):
    """A running run: expected wall time and elapsed time [s], and the fraction of its work
    done as its log says (None when the log does not say)."""

    expected: float
    elapsed: float
    fraction: float | None = None


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


def speed_factor(finished: Sequence[Finished], running: Sequence[Running]) -> float:
    """How much slower (> 1) or faster than expected the runs have gone so far."""
    measured = sum(run.actual for run in finished)
    expected = sum(run.expected for run in finished)
    for run in running:
        if run.fraction:
            measured += run.elapsed
            expected += run.fraction * run.expected
    return (measured + PRIOR_WEIGHT_S) / (expected + PRIOR_WEIGHT_S)


def _left(run: Running, factor: float) -> float:
    if run.fraction is not None:
        return factor * run.expected * (1.0 - run.fraction)
    return max(factor * run.expected - run.elapsed, MIN_REMAINING_S)


def estimate_remaining(
    finished: Sequence[Finished],
    running: Sequence[Running],
    queued: Sequence[float],
    slots: int,
) -> float:
    """Seconds until every run has finished (see the module docstring).

    ``queued``: the expected wall times of the queued runs, in the order they will start;
    ``slots``: runs at a time.
    """
    factor = speed_factor(finished, running)
    free = [_left(run, factor) for run in running]
    free += [0.0] * max(0, slots - len(free))
    heapq.heapify(free)
    end = max(free, default=0.0)
    for cost in queued:
        start = heapq.heappop(free)
        finish = start + factor * cost
        end = max(end, finish)
        heapq.heappush(free, finish)
    return end
