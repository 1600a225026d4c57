"""Why a PILCO run failed, from what its learning curve recorded.

Every PILCO iteration's curve row (``curve.json`` of the run folder) records, besides the
evaluation, the policy optimisation's predicted horizon cost at its start and at its end, the
gradient's norm there, its failed evaluations, the horizon cost the iteration's training
rollout realised (the same saturating cost on the real episode), the GP's hyperparameters and
the hybrid's relevance widths. :func:`diagnose_run` reads them and puts a run in one class:

``held``
    The last evaluation held the operating point in every episode: no failure.
``numerical``
    The last policy optimisation had failed evaluations (a non-finite cost or a Cholesky
    failure), or the relevance widths left the range where ``r`` can vary (``|ln lambda|``
    above :data:`DEGENERATE_LOG_WIDTH`: ``r`` is 1, or 0, wherever the run goes).
``flat cost``
    The last predicted cost is at least :data:`PROGRESS_RATIO` of the first iteration's, and
    either the gradient was below :data:`FLAT_GRADIENT` where every optimisation started, or
    every iteration's predicted cost was at least :data:`SATURATED_SHARE` of its most (one
    per step of the horizon): the saturating cost is flat around the policies tried (the
    predicted states are far from the target along the whole horizon), so no descent method
    can leave them.
``stalled``
    No progress either (the same test on the predicted cost), but a slope (some optimisation
    started on a gradient of :data:`FLAT_GRADIENT` or more, and the cost was not saturated),
    and L-BFGS stopped early (below :data:`NEAR_BUDGET` of its iteration budget) in at least
    :data:`EARLY_STOP_SHARE` of the optimisations after the first: the optimiser gave up
    before the slope ran out (a line search that found no decrease, failed evaluations on the
    way). Also the class when the curve or the config does not say how many iterations
    L-BFGS ran or was allowed.
``slow descent``
    No progress by the same test, a slope, and L-BFGS spent (nearly) its whole budget in more
    than the rest of those optimisations: the optimiser kept going and the cost fell less
    than the test asks (a budget too small for the landscape, or a shallow one).
``model bias``
    The rollouts realised more cost than the model predicted, by more than
    :data:`BIAS_SHARE` of the horizon on average over the last :data:`RECENT` iterations: the
    policy is good for the model and not for the plant.
``partial``
    Some evaluation episodes held, not all.
``local optimum``
    Everything else: the predicted cost went down and the rollouts realised about what was
    predicted, but the policy settled on a behaviour that does not hold.

The classes are checked in this order; the thresholds are choices (stated with each constant),
so :func:`describe` prints the evidence next to the class.

**Beyond the horizon.** PILCO optimises the cost of ``horizon`` decisions (the pendulum's 40 at
2 x 0.05 s: 4 s) while its evaluation episodes are longer (200 steps: 10 s) and ask the
pendulum to be held at their end. A policy can swing up and hold inside the horizon, so that
its predicted and realised costs are those of the runs that hold, and then let go: the curve
cannot tell it from ``local optimum`` or ``partial``. :func:`horizon_check` replays a run's final
controller from its evaluation starts and counts the episodes that were within the hold band
at the horizon's last simulator step and are not held at the episode's end.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "BIAS_SHARE",
    "DEGENERATE_LOG_WIDTH",
    "DIAGNOSES",
    "EARLY_STOP_SHARE",
    "FLAT_GRADIENT",
    "NEAR_BUDGET",
    "PROGRESS_RATIO",
    "RECENT",
    "SATURATED_SHARE",
    "Diagnosis",
    "HorizonCheck",
    "describe",
    "describe_horizon",
    "diagnose_curve",
    "diagnose_run",
    "horizon_check",
    "up_and_held",
]

#: The classes, in the order they are checked.
DIAGNOSES = (
    "held",
    "numerical",
    "flat cost",
    "stalled",
    "slow descent",
    "model bias",
    "partial",
    "local optimum",
)
#: ``flat cost`` and ``stalled``: the last predicted cost is at least this share of the first
#: iteration's (a tenth off the start is within what a redrawn start distribution moves it).
PROGRESS_RATIO = 0.9
#: ``flat cost``: the gradient's norm at every optimisation's start below this. The stalled
#: pendulum runs measured started every optimisation after the first on norms of 1.2 to 700
#: (medians 4.5 to 330); a pendulum hybrid whose predicted cost stayed at 39.97 of 40 (every
#: predicted state far from the target) started them on 2e-4 to 0.04 (2026-11-29; 1e-3
#: before, which that run crossed).
FLAT_GRADIENT = 0.1
#: ``flat cost``: every iteration's predicted cost at least this share of its most (the
#: horizon: a cost of at most 1 per step). A pendulum hybrid whose predicted cost stayed at
#: 39.97 of 40 through ten iterations started its later optimisations on gradients of about 1
#: once the FITC jitter smoothed its cost (``results/pilco-reliability/fitc-jitter-ab``, seed
#: 0), above :data:`FLAT_GRADIENT`: a slope of the last 0.1% of the cost, not a way out.
SATURATED_SHARE = 0.99
#: ``stalled`` against ``slow descent``: the share of the optimisations after the first (whose
#: random policy starts on a flat cost, where L-BFGS's restarts are the rule) that stopped
#: early (:data:`NEAR_BUDGET`). The stalled pendulum runs measured stopped early in 9 of 9.
EARLY_STOP_SHARE = 0.5
#: An optimisation that ran at least this share of its iteration budget spent it: it ended
#: because a restart gained less than ``leoc.pilco.objective.RESTART_MIN_IMPROVEMENT`` a
#: few iterations short. The pendulum hybrids that held with the FITC jitter ended theirs
#: at 72 to 75 of 75; the stalled baselines without it at 3 to 39.
NEAR_BUDGET = 0.9
#: ``model bias``: mean (realised - predicted) cost over the last iterations above this share
#: of the horizon (a fifth: eight of the pendulum's 40 decisions at the full cost).
BIAS_SHARE = 0.2
#: Iterations averaged for ``model bias``.
RECENT = 3
#: ``numerical``: a relevance width with ``|ln lambda|`` above this (e^20 = 4.9e8) makes
#: ``r`` constant on any state the run visits.
DEGENERATE_LOG_WIDTH = 20.0


class Diagnosis(NamedTuple):
    """The class of one run (module docstring) and the evidence it was read from.

    Attributes
    ----------
    kind : str
        One of :data:`DIAGNOSES`.
    held_fraction : float
        The last evaluation's share of held episodes.
    evidence : dict
        ``horizon``; ``predicted`` and ``realised`` (per iteration from 1); ``start_gradient``
        (the gradient's norm where each optimisation started); ``failed_evaluations`` (per
        iteration); ``max_abs_log_width`` (the relevance's widths, None for a baseline);
        ``lbfgs_iterations`` (per iteration, None where not recorded) and
        ``policy_iterations`` (L-BFGS's budget, None if unknown).
    """

    kind: str
    held_fraction: float
    evidence: dict[str, Any]


def _widths(row: Mapping[str, Any]) -> float | None:
    widths = row.get("relevance_lambda") or row.get("relevance_width")
    if not widths:
        return None
    return max(abs(math.log(w)) if w > 0 else math.inf for w in widths)


def diagnose_curve(
    rows: list[Mapping[str, Any]], horizon: int, policy_iterations: int | None = None
) -> Diagnosis:
    """The diagnosis of a run's curve rows (``curve.json``'s ``curve``, iteration 0 first) at
    prediction horizon ``horizon``, with L-BFGS's iteration budget ``policy_iterations`` (None:
    unknown; ``stalled`` and ``slow descent`` are then not told apart).

    Raises
    ------
    ValueError
        No iteration after the random rollouts, or rows without the diagnostics (a run trained
        before they were recorded).
    """
    iterations = [row for row in rows if row.get("iteration", 0) >= 1]
    if not iterations:
        raise ValueError("rows: expected at least one PILCO iteration, found none")
    if "realised_cost" not in iterations[-1]:
        raise ValueError(
            "rows: expected each iteration's diagnostics (realised_cost, gradient norms), "
            "found a curve recorded without them (an older leoc): train the run again"
        )
    last = iterations[-1]
    predicted = [row["predicted_cost"] for row in iterations]
    realised = [row["realised_cost"] for row in iterations]
    evidence = {
        "horizon": int(horizon),
        "predicted": predicted,
        "realised": realised,
        "start_gradient": [row["gradient_norm_start"] for row in iterations],
        "failed_evaluations": [row["failed_evaluations"] for row in iterations],
        "max_abs_log_width": _widths(last),
        "lbfgs_iterations": [row.get("lbfgs_iterations") for row in iterations],
        "policy_iterations": policy_iterations,
    }
    held = float(last["held_fraction"])
    return Diagnosis(_kind(held, evidence), held, evidence)


def _stall_kind(evidence: Mapping[str, Any]) -> str:
    """``stalled`` or ``slow descent`` (module docstring) from the L-BFGS iteration counts."""
    budget, counts = evidence["policy_iterations"], evidence["lbfgs_iterations"][1:]
    if budget is None or not counts or any(c is None for c in counts):
        return "stalled"
    early = sum(c < NEAR_BUDGET * budget for c in counts)
    return "stalled" if early >= EARLY_STOP_SHARE * len(counts) else "slow descent"


def _kind(held: float, evidence: Mapping[str, Any]) -> str:
    """The first class of :data:`DIAGNOSES` whose test the evidence passes."""
    predicted, realised = evidence["predicted"], evidence["realised"]
    width = evidence["max_abs_log_width"]
    if held >= 1.0:
        return "held"
    if predicted[-1] is None or evidence["failed_evaluations"][-1] > 0:
        return "numerical"
    if width is not None and width > DEGENERATE_LOG_WIDTH:
        return "numerical"
    if predicted[-1] >= PROGRESS_RATIO * predicted[0]:
        flat = all(g is not None and g < FLAT_GRADIENT for g in evidence["start_gradient"])
        most = SATURATED_SHARE * evidence["horizon"]
        saturated = all(p is not None and p >= most for p in predicted)
        return "flat cost" if flat or saturated else _stall_kind(evidence)
    recent = list(zip(realised, predicted, strict=True))[-RECENT:]
    gap = sum(r - p for r, p in recent) / len(recent)
    if gap > BIAS_SHARE * evidence["horizon"]:
        return "model bias"
    return "partial" if held > 0.0 else "local optimum"


def diagnose_run(train_dir: str | Path) -> Diagnosis:
    """The diagnosis of the PILCO run in ``train_dir`` (its ``curve.json`` and
    ``config.json``)."""
    folder = Path(train_dir)
    try:
        rows = json.loads((folder / "curve.json").read_text(encoding="utf-8"))["curve"]
        config = json.loads((folder / "config.json").read_text(encoding="utf-8"))
        horizon = config["horizon"]
    except (OSError, ValueError, KeyError) as error:
        raise ValueError(
            f"train_dir: expected a PILCO run folder with curve.json and config.json, found "
            f"{folder} ({type(error).__name__}: {error})"
        ) from None
    return diagnose_curve(rows, horizon, config.get("policy_iterations"))


def _cell(values: list[Any], digits: int = 1) -> str:
    shown = [f"{v:.{digits}f}" if isinstance(v, float) else str(v) for v in values]
    return " ".join(shown)


def describe(diagnoses: Mapping[str, Diagnosis]) -> str:
    """A markdown table of ``{run: diagnosis}`` (run, class, held, predicted and realised cost
    per iteration, gradient norm at the first and last optimisation's start, L-BFGS's
    iterations per optimisation (``-`` where not recorded), the widths' largest ``|ln
    lambda|``) and the count per class."""
    lines = [
        "| run | class | held | predicted cost | realised cost | start gradient "
        "| L-BFGS iterations | max |ln w| |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for run, found in diagnoses.items():
        ev = found.evidence
        gradients = [ev["start_gradient"][0], ev["start_gradient"][-1]]
        width = "-" if ev["max_abs_log_width"] is None else f"{ev['max_abs_log_width']:.2f}"
        lbfgs = _cell(["-" if n is None else n for n in ev.get("lbfgs_iterations", [])])
        lines.append(
            f"| {run} | {found.kind} | {found.held_fraction:.0%} | {_cell(ev['predicted'])} | "
            f"{_cell(ev['realised'])} | {_cell(gradients, 2)} | {lbfgs or '-'} | {width} |"
        )
    counts = Counter(found.kind for found in diagnoses.values())
    summary = ", ".join(f"{kind} {counts[kind]}" for kind in DIAGNOSES if counts[kind])
    return "\n".join([*lines, "", f"{len(diagnoses)} runs: {summary or 'none'}"])


class HorizonCheck(NamedTuple):
    """A final controller's evaluation episodes against PILCO's prediction horizon
    (:func:`horizon_check`): the horizon's length in simulator steps, and per episode whether
    the main coordinate was within the hold band at that step (``up``) and whether the episode
    is held at its end (``held``); and the run's GP model's predicted cost of the policy over
    the horizon (``predicted``, what the optimisation saw) and over the evaluation episode's
    decisions (``predicted_episode``: does the model see the let-go?), ``episode_decisions``
    of them (None, both, where they are not computed)."""

    horizon_steps: int
    up: list[bool]
    held: list[bool]
    predicted: float | None = None
    predicted_episode: float | None = None
    episode_decisions: int | None = None

    @property
    def let_go(self) -> int:
        """Episodes up at the horizon's end and not held at the episode's end."""
        return sum(up and not held for up, held in zip(self.up, self.held, strict=True))


def up_and_held(system: Any, states: Any, terminated: Any, step: int) -> tuple[list, list]:
    """Per episode of ``states`` (B, T + 1, S; the start first): within ``system``'s hold band
    after ``step`` simulator steps (a terminated episode that ended before then is not), and
    held at its end (:meth:`~leoc.systems.System.hold_step`)."""
    states = np.asarray(states)
    up, held = [], []
    for i in range(states.shape[0]):
        episode = states[i]
        ended = bool(terminated[i])
        inside = step < episode.shape[0] and abs(
            float(system.main_coordinate(episode[step : step + 1])[0])
        ) <= float(system.hold_band)
        up.append(bool(inside))
        held.append(system.hold_step(episode[1:], terminated=ended) is not None)
    return up, held


def horizon_check(train_dir: str | Path) -> HorizonCheck:
    """:class:`HorizonCheck` of the PILCO run in ``train_dir``: its saved controller replayed
    on its plant from its evaluation starts (those of the training's evaluations), the
    horizon ``horizon * action_repeat`` simulator steps.

    Raises
    ------
    FileNotFoundError
        If ``train_dir`` holds no saved controller.
    """
    import dataclasses

    import torch

    from leoc.pilco.checkpoint import load_pilco_run
    from leoc.pilco.objective import predict_policy
    from leoc.systems.rollout import simulate
    from leoc.training import evaluation_starts

    run = load_pilco_run(train_dir)
    config = run.config
    starts = evaluation_starts(run.system, config.seed, config.eval_episodes)
    batch = simulate(run.system, run.controller, starts)
    steps = int(config.horizon) * int(config.action_repeat)
    up, held = up_and_held(run.system, batch.states, batch.terminated, steps)
    decisions = int(batch.states.shape[1] - 1) // int(config.action_repeat)
    costs = []
    for horizon in (int(config.horizon), decisions):
        longer = dataclasses.replace(config, horizon=horizon)
        with torch.no_grad():
            prediction = predict_policy(run.policy, run.model, run.system, longer)
        costs.append(float(prediction.total_cost))
    return HorizonCheck(steps, up, held, costs[0], costs[1], decisions)


def describe_horizon(checks: Mapping[str, HorizonCheck]) -> str:
    """A markdown table of :func:`horizon_check` per run (``checks``: run name -> check): the
    horizon in simulator steps, the episodes up at its end, held at their end, and let go; the
    predicted cost over the horizon and over the episode's decisions."""
    lines = [
        "| run | horizon (simulator steps) | up at the horizon's end | held at the end | let go "
        "after the horizon | predicted cost, horizon | predicted cost, whole episode |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, check in checks.items():
        episodes = len(check.up)
        episode = (
            "-"
            if check.predicted_episode is None
            else f"{check.predicted_episode:.2f} ({check.episode_decisions} decisions)"
        )
        horizon = "-" if check.predicted is None else f"{check.predicted:.2f}"
        lines.append(
            f"| {name} | {check.horizon_steps} | {sum(check.up)}/{episodes} | "
            f"{sum(check.held)}/{episodes} | {check.let_go}/{episodes} | {horizon} | {episode} |"
        )
    return "\n".join(lines)
