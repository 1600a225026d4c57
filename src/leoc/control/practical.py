r"""Candidate V for a proof of practical stability, where no asymptotic claim can exist.

Letters: S state dimension, N samples.

A controller whose loop has no stable equilibrium near the operating point (a baseline that
chatters about its hold point on a limit cycle, or settles just outside the operating region)
can still be *practically* stable: a level set invariant and every trajectory ending in a small
inner set (:func:`leoc.control.proof.prove_practical`). Whether a quadratic V shows it depends
on V's shape far more than an asymptotic proof does: the LQR's Riccati V of a chattering
mountain-car baseline increases on a few percent of the states at every scale, yet another
ellipse about the same cycle decreases outside it. This module proposes V by sampling; the
proof is what makes the claim, so a poor proposal costs time, never soundness.

1. **The attractor** (:func:`attractor`): :data:`ATTRACTOR_STARTS` starts uniform in the
   operating region are run :data:`ATTRACTOR_SETTLE` held steps; the next
   :data:`ATTRACTOR_RECORD` steps give its centre :math:`c` (their mean, angles wrapped about
   a) and half-widths :math:`h` (the largest deviation from c per coordinate, at least
   :data:`MIN_HALF_WIDTH` of the region). None when fewer than half the starts stay finite and
   inside the allowed region, or when the attractor reaches beyond :data:`SPREAD_LIMIT` times
   the region.
2. **A decrease fit** (:func:`decrease_matrix`): V(F(x)) - V(x) is *linear* in P, so the P
   with the largest margin t of sampled decrease,

   .. math::

       \max_{P, t}\ t \quad \text{s.t.}\quad (F(x_i) - c)^\top P (F(x_i) - c)
       - (x_i - c)^\top P (x_i - c) \le -t\, |(x_i - c) / h|^2,
       \qquad \textstyle\sum_j P_{jj} h_j^2 = 1,

   over states :math:`x_i` between :math:`k` and :math:`K` times h in the box norm (log-uniform
   scale), is a linear programme (scipy's HiGHS). Positive definiteness is kept by cutting
   planes :math:`v^\top P v \ge 0` (random directions, then the eigenvector of a negative
   eigenvalue, up to :data:`PSD_ROUNDS` rounds). A fit with t <= 0 or an indefinite P is
   dropped. This is the sampled-constraint Lyapunov search of the learning-then-verifying
   literature (e.g. Chang, Roohi and Gao, NeurIPS 2019, with a network in place of P), here
   linear, followed by the interval proof.
3. :func:`practical_candidates`: the first V of :func:`leoc.control.certify_controller` about
   its centre, and the fits for every :data:`INNER_SCALES` x :data:`OUTER_SCALES` x
   :data:`OUTER_FLOORS` (the outer box ``max(scale * region, floor * h)``) about c. The
   caller keeps the one whose sampled practical target has the largest volume and proves that
   one alone.
"""

from __future__ import annotations

import itertools
import math
from typing import Any, NamedTuple

import numpy as np
import scipy.optimize
import torch

from leoc.control.roa import _closed_loop, state_deviation
from leoc.systems.base import DTYPE, System

__all__ = ["Attractor", "attractor", "decrease_matrix", "practical_candidates"]

ATTRACTOR_STARTS = 32
"""Starts of the attractor's simulation, uniform in the operating region."""
ATTRACTOR_SETTLE = 2000
"""Held steps before the attractor is recorded."""
ATTRACTOR_RECORD = 200
"""Held steps recorded (its centre and half-widths)."""
MIN_HALF_WIDTH = 1e-3
"""The attractor's half-width is at least this fraction of the operating region."""
SPREAD_LIMIT = 10.0
"""An attractor reaching beyond this multiple of the operating region is not near a."""
FIT_SAMPLES = 20_000
"""Sampled decrease constraints of one fit."""
INNER_SCALES = (2.0, 3.0, 4.0)
"""k: a fit asks for decrease from k times the attractor's half-widths outwards."""
OUTER_SCALES = (1.0, 3.0, 10.0)
"""The fit's outer box: ``max(scale * region, floor * h)``, floor in :data:`OUTER_FLOORS`."""
OUTER_FLOORS = (4.0, 8.0)
"""The fit's outer box reaches at least this multiple of the attractor's half-widths."""
CUT_DIRECTIONS = 200
"""Random directions v of the first cutting planes ``v^T P v >= 0`` (and the axes)."""
PSD_ROUNDS = 10
"""Rounds of the linear programme, each adding the eigenvector of a negative eigenvalue."""
FITTED = "fitted"
"""Name prefix of a decrease-fit candidate (``fitted k=3 outer=5``)."""


class Attractor(NamedTuple):
    """Where the held closed loop settles from the operating region (:func:`attractor`)."""

    centre: np.ndarray  # (S,) c
    half_widths: np.ndarray  # (S,) h


def attractor(system: System, controller: Any, repeat: int, seed: int = 0) -> Attractor | None:
    """The loop's attractor near a (module docstring, 1), or None."""
    rng = np.random.default_rng(seed)
    region = np.asarray(system.operating_region, dtype=float)
    operating = np.asarray(system.operating_state, dtype=float)
    starts = operating + rng.uniform(-1.0, 1.0, (ATTRACTOR_STARTS, operating.size)) * region
    states = torch.as_tensor(starts, dtype=DTYPE)
    gone = torch.zeros(ATTRACTOR_STARTS, dtype=torch.bool)
    recorded = []
    with torch.no_grad():
        for step in range(ATTRACTOR_SETTLE + ATTRACTOR_RECORD):
            states, left = _closed_loop(system, controller, repeat, states)
            gone |= left | ~torch.isfinite(states).all(-1)
            if step >= ATTRACTOR_SETTLE:
                recorded.append(state_deviation(system, states).numpy())
    kept = ~gone.numpy()
    if 2 * kept.sum() < ATTRACTOR_STARTS:
        return None
    deviation = np.stack(recorded)[:, kept].reshape(-1, operating.size)
    if not np.all(np.abs(deviation) <= SPREAD_LIMIT * region):
        return None
    mean = deviation.mean(0)
    half = np.maximum(np.abs(deviation - mean).max(0), MIN_HALF_WIDTH * region)
    return Attractor(operating + mean, half)


def _features(deviation: np.ndarray) -> np.ndarray:
    """``z^T P z`` as features (N, S(S+1)/2) times P's upper-triangular entries."""
    rows, columns = np.triu_indices(deviation.shape[1])
    twice = np.where(rows == columns, 1.0, 2.0)
    return deviation[:, rows] * deviation[:, columns] * twice


def _matrix(entries: np.ndarray, size: int) -> np.ndarray:
    matrix = np.zeros((size, size))
    matrix[np.triu_indices(size)] = entries
    return matrix + matrix.T - np.diag(np.diag(matrix))


def _fit_samples(
    system: System, controller: Any, repeat: int, centre, inner, outer, rng
) -> tuple[np.ndarray, np.ndarray] | None:
    """Deviations from c of the sampled states and of their images (each (N, S)), states that
    leave the allowed region dropped; None when the outer box is no larger than the inner."""
    size = centre.size
    largest = float(np.min(outer / inner))
    low = min(INNER_SCALES)
    if not largest > low:
        return None
    direction = rng.uniform(-1.0, 1.0, (FIT_SAMPLES, size))
    axis = rng.integers(0, size, FIT_SAMPLES)
    direction[np.arange(FIT_SAMPLES), axis] = np.sign(direction[np.arange(FIT_SAMPLES), axis])
    scale = np.exp(rng.uniform(math.log(low), math.log(largest), FIT_SAMPLES))
    states = torch.as_tensor(centre + scale[:, None] * direction * inner, dtype=DTYPE)
    with torch.no_grad():
        following, left = _closed_loop(system, controller, repeat, states)
    kept = ~left & torch.isfinite(following).all(-1)
    before = state_deviation(system, states[kept], centre).numpy()
    after = state_deviation(system, following[kept], centre).numpy()
    return before, after


def decrease_matrix(
    system: System,
    controller: Any,
    repeat: int,
    centre: np.ndarray,
    inner: np.ndarray,
    outer: np.ndarray,
    scale: float,
    seed: int = 0,
) -> np.ndarray | None:
    """The P of the largest sampled decrease margin from ``scale * inner`` out to ``outer``
    about ``centre`` (module docstring, 2), or None (no positive margin, or indefinite)."""
    samples = _fit_samples(
        system, controller, repeat, centre, inner, outer, np.random.default_rng(seed)
    )
    if samples is None:
        return None
    before, after = samples
    far = np.abs(before / inner).max(1) >= scale
    before, after = before[far], after[far]
    size = centre.size
    change = _features(after) - _features(before)
    weight = ((before / inner) ** 2).sum(1)
    count = change.shape[1]
    norm = np.zeros(count + 1)
    rows, columns = np.triu_indices(size)
    norm[:count][rows == columns] = inner[rows[rows == columns]] ** 2
    rng = np.random.default_rng(seed)
    cuts = list(np.eye(size)) + list(rng.standard_normal((CUT_DIRECTIONS, size)))
    for _ in range(PSD_ROUNDS):
        psd = np.hstack([-_features(np.asarray(cuts)), np.zeros((len(cuts), 1))])
        bound = np.vstack([np.hstack([change, weight[:, None]]), psd])
        fit = scipy.optimize.linprog(
            -np.eye(count + 1)[-1],
            A_ub=bound,
            b_ub=np.zeros(len(bound)),
            A_eq=norm[None],
            b_eq=[1.0],
            bounds=[(None, None)] * count + [(None, 1.0)],
            method="highs",
        )
        if not fit.success or not fit.x[-1] > 0.0:
            return None
        matrix = _matrix(fit.x[:-1], size)
        values, vectors = np.linalg.eigh(matrix)
        if values[0] > 0.0:
            return matrix
        cuts.append(vectors[:, 0])
    return None


def practical_candidates(
    system: System,
    controller: Any,
    repeat: int,
    first: tuple[str, np.ndarray, np.ndarray],
    seed: int = 0,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Name -> (P, centre) of the candidate V (module docstring, 3); ``first`` is
    :func:`~leoc.control.certify_controller`'s first V as (name, P, centre)."""
    name, matrix, centre = first
    candidates = {name: (matrix, centre)}
    found = attractor(system, controller, repeat, seed)
    if found is None:
        return candidates
    region = np.asarray(system.operating_region, dtype=float)
    for floor, outer_scale, scale in itertools.product(OUTER_FLOORS, OUTER_SCALES, INNER_SCALES):
        outer = np.maximum(outer_scale * region, floor * found.half_widths)
        fitted = decrease_matrix(
            system, controller, repeat, found.centre, found.half_widths, outer, scale, seed
        )
        if fitted is not None:
            label = f"{FITTED} k={scale:g} outer=max({outer_scale:g} region, {floor:g} h)"
            candidates[label] = (fitted, found.centre)
    return candidates
