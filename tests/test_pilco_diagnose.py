"""leoc.pilco.diagnose: each class of failure from curves written by hand to its definition
(the module docstring), the order the classes are checked in, and the errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from leoc.pilco.diagnose import (
    BIAS_SHARE,
    DEGENERATE_LOG_WIDTH,
    EARLY_STOP_SHARE,
    FLAT_GRADIENT,
    NEAR_BUDGET,
    PROGRESS_RATIO,
    SATURATED_SHARE,
    HorizonCheck,
    describe,
    diagnose_curve,
    diagnose_run,
    up_and_held,
)

HORIZON = 40


def _row(iteration, predicted, realised, held=0.0, failed=0, widths=None, gradient=0.5):
    row = {
        "iteration": iteration,
        "held_fraction": held,
        "predicted_cost": predicted,
        "realised_cost": realised,
        "gradient_norm_start": gradient,
        "failed_evaluations": failed,
    }
    if widths is not None:
        row["relevance_lambda"] = widths
    return row


def _curve(predicted, realised, **last):
    """Iteration 0 (random rollouts, no optimisation) then one row per predicted cost; ``last``
    overrides the last row's fields."""
    rows = [{"iteration": 0, "held_fraction": 0.0}]
    rows += [_row(i + 1, p, r) for i, (p, r) in enumerate(zip(predicted, realised, strict=True))]
    rows[-1].update(last)
    return rows


def test_each_class_from_its_definition() -> None:
    down, agreeing = [30.0, 20.0, 12.0, 10.0], [31.0, 22.0, 13.0, 11.0]
    assert diagnose_curve(_curve(down, agreeing, held_fraction=1.0), HORIZON).kind == "held"
    assert diagnose_curve(_curve(down, agreeing), HORIZON).kind == "local optimum"
    assert diagnose_curve(_curve(down, agreeing, held_fraction=0.4), HORIZON).kind == "partial"
    # the last cost at PROGRESS_RATIO of the first: no progress; just below: progress
    flat = [30.0, 29.0, 28.0, PROGRESS_RATIO * 30.0]
    assert diagnose_curve(_curve(flat, flat), HORIZON).kind == "stalled"  # gradients of 0.5
    flat[-1] = PROGRESS_RATIO * 30.0 - 0.01
    assert diagnose_curve(_curve(flat, flat), HORIZON).kind == "local optimum"
    # no progress with every start's gradient below FLAT_GRADIENT: a flat cost; one start on
    # a slope (the first one here) makes it a stall
    flat[-1] = PROGRESS_RATIO * 30.0
    rows = _curve(flat, flat)
    for row in rows[1:]:
        row["gradient_norm_start"] = 0.99 * FLAT_GRADIENT
    assert diagnose_curve(rows, HORIZON).kind == "flat cost"
    rows[1]["gradient_norm_start"] = FLAT_GRADIENT
    assert diagnose_curve(rows, HORIZON).kind == "stalled"
    # realised above predicted by BIAS_SHARE of the horizon on average over the last three
    gap = BIAS_SHARE * HORIZON
    above = [p + gap + 0.01 for p in down]
    assert diagnose_curve(_curve(down, above), HORIZON).kind == "model bias"
    above[-1] -= 0.06  # the mean gap now just below the share
    assert diagnose_curve(_curve(down, above), HORIZON).kind == "local optimum"


def test_a_stall_stops_early_and_a_slow_descent_spends_its_budget() -> None:
    """No progress on a slope: ``stalled`` when L-BFGS stopped before its budget in at least
    EARLY_STOP_SHARE of the optimisations after the first, ``slow descent`` otherwise; the
    first optimisation (random policy, flat cost) does not count."""
    flat = [30.0, 29.5, 29.0, 28.5, 28.0]  # 28 / 30 > PROGRESS_RATIO: no progress
    rows = _curve(flat, flat)
    early = int(EARLY_STOP_SHARE * 4)  # of the 4 optimisations after the first
    for row, count in zip(rows[1:], [3] + [5] * early + [75] * (4 - early), strict=True):
        row["lbfgs_iterations"] = count
    found = diagnose_curve(rows, HORIZON, policy_iterations=75)
    assert found.kind == "stalled" and found.evidence["lbfgs_iterations"][0] == 3
    rows[1 + early]["lbfgs_iterations"] = 75  # one early stop fewer: below the share
    assert diagnose_curve(rows, HORIZON, policy_iterations=75).kind == "slow descent"
    rows[1]["lbfgs_iterations"] = 75  # the first optimisation's count changes nothing
    assert diagnose_curve(rows, HORIZON, policy_iterations=75).kind == "slow descent"
    assert diagnose_curve(rows, HORIZON).kind == "stalled"  # budget unknown: the old class
    table = describe({"run": diagnose_curve(rows, HORIZON, policy_iterations=75)})
    assert "| 0.50 0.50 | 75 5 75 75 75 | - |" in table


def test_a_stop_near_the_budget_spent_it_and_a_saturated_cost_is_flat_on_any_slope() -> None:
    """An optimisation that ran NEAR_BUDGET of its budget spent it (the held pendulum hybrids
    ended theirs at 72-75 of 75): one just short of that share is early, one at it is not. A
    predicted cost at SATURATED_SHARE of the horizon at every iteration is a flat cost even on
    start gradients far above FLAT_GRADIENT; just below it on one iteration, a stall."""
    flat = [30.0, 29.5, 29.0, 28.5, 28.0]
    rows = _curve(flat, flat)
    at = math.ceil(NEAR_BUDGET * 75)  # the least count that spent it
    for row in rows[1:]:
        row["lbfgs_iterations"] = at
    assert diagnose_curve(rows, HORIZON, policy_iterations=75).kind == "slow descent"
    for row in rows[2:]:
        row["lbfgs_iterations"] = at - 1
    assert diagnose_curve(rows, HORIZON, policy_iterations=75).kind == "stalled"
    top = SATURATED_SHARE * HORIZON
    saturated = _curve([top + 0.3, top + 0.2, top, top + 0.1], [HORIZON] * 4)
    for row in saturated[1:]:
        row["gradient_norm_start"] = 40 * FLAT_GRADIENT
        row["lbfgs_iterations"] = 3
    assert diagnose_curve(saturated, HORIZON, policy_iterations=75).kind == "flat cost"
    saturated[3]["predicted_cost"] = top - 0.01
    assert diagnose_curve(saturated, HORIZON, policy_iterations=75).kind == "stalled"


def test_numerical_failures_come_first() -> None:
    down, agreeing = [30.0, 20.0, 12.0], [31.0, 22.0, 13.0]
    assert diagnose_curve(_curve(down, agreeing, failed_evaluations=2), HORIZON).kind == (
        "numerical"
    )
    assert diagnose_curve(_curve(down, agreeing, predicted_cost=None), HORIZON).kind == (
        "numerical"
    )
    wide = [1.0, 1.0, float(2.0 * 10**9)]  # ln(2e9) = 21.4 > DEGENERATE_LOG_WIDTH
    found = diagnose_curve(_curve(down, agreeing, relevance_lambda=wide), HORIZON)
    assert found.kind == "numerical" and found.evidence["max_abs_log_width"] > DEGENERATE_LOG_WIDTH
    # a held run is held whatever its optimisation met on the way
    held = _curve(down, agreeing, failed_evaluations=2, held_fraction=1.0)
    assert diagnose_curve(held, HORIZON).kind == "held"


def test_run_folders_and_the_table(tmp_path) -> None:
    (tmp_path / "curve.json").write_text(json.dumps({"curve": _curve([30.0, 29.5], [30.0, 30.0])}))
    (tmp_path / "config.json").write_text(json.dumps({"horizon": HORIZON}))
    found = diagnose_run(tmp_path)
    assert found.kind == "stalled" and found.evidence["predicted"] == [30.0, 29.5]
    table = describe({"pendulum/pilco_baseline/seed2": found})
    assert "| pendulum/pilco_baseline/seed2 | stalled | 0% | 30.0 29.5 |" in table
    assert table.endswith("1 runs: stalled 1")


def test_errors_name_what_is_missing(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"^train_dir: expected a PILCO run folder"):
        diagnose_run(tmp_path)
    with pytest.raises(ValueError, match=r"^rows: expected at least one PILCO iteration"):
        diagnose_curve([{"iteration": 0, "held_fraction": 0.0}], HORIZON)
    old = [{"iteration": 0}, {"iteration": 1, "held_fraction": 0.0, "predicted_cost": 3.0}]
    with pytest.raises(ValueError, match=r"^rows: expected each iteration's diagnostics"):
        diagnose_curve(old, HORIZON)


PILCO_STUDIES = Path(__file__).resolve().parents[1] / "results" / "pilco-reliability"
# (study, arm, seeds published): every arm of every A/B study published there
PUBLISHED_ARMS = [
    ("gp-max-snr-ab", "default", 10),
    ("gp-max-snr-ab", "gp_max_snr_100", 10),
    ("fitc-jitter-ab", "inducing_jitter_1e-6", 20),  # 10 baselines, 10 hybrids
    ("fitc-jitter-ab", "inducing_jitter_1e-6_15_iterations", 4),
]


def test_every_published_arm_is_checked() -> None:
    """A study arm added under results/pilco-reliability/ joins PUBLISHED_ARMS (and so the test
    below); the list is not a snapshot that can go stale."""
    found = {
        (arm.parent.name, arm.name)
        for arm in PILCO_STUDIES.glob("*/*")
        if arm.is_dir() and any(arm.glob("*/*/seed*/train"))
    }
    assert found == {(study, arm) for study, arm, _ in PUBLISHED_ARMS}


@pytest.mark.parametrize(("study", "arm", "seeds"), PUBLISHED_ARMS)
def test_the_published_studies_print_what_their_records_hold(study, arm, seeds) -> None:
    """results/pilco-reliability/STUDY/README.md shows, per arm, the table that diagnose_run
    and describe make of the run records published beside it (so a change of a class's
    definition, or a hand edit of the README, cannot leave the published table stale)."""
    folder = PILCO_STUDIES / study / arm
    runs = sorted(folder.glob("*/*/seed*/train"))  # seeds 0-9: text order is seed order
    assert len(runs) == seeds
    table = describe({str(r.parent.relative_to(folder)): diagnose_run(r) for r in runs})
    assert table in (PILCO_STUDIES / study / "README.md").read_text(encoding="utf-8")


def test_up_at_the_horizon_and_held_at_the_end() -> None:
    """Episodes written by hand on the pendulum (theta in degrees, hold band 5, held: within it
    for the last 50 steps): up at the horizon's step and staying (held), up there and let go,
    up only one step later (not up: the step is the horizon's last), a terminated one, and up
    from the horizon's step exactly."""
    import numpy as np

    from leoc.systems import make_system

    system, steps, horizon = make_system("pendulum"), 160, 80
    theta = np.full((5, steps + 1), np.radians(30.0))
    theta[0, 60:] = np.radians(1.0)  # up from step 60 to the end
    theta[1, 60:100] = np.radians(1.0)  # up from step 60, let go at step 100
    theta[2, horizon + 1 :] = np.radians(1.0)  # up from the step after the horizon's
    theta[3, 60:] = np.radians(1.0)  # as the first, but terminated
    theta[4, horizon:] = np.radians(1.0)  # up from the horizon's step itself
    states = np.stack([theta, np.zeros_like(theta)], axis=-1)
    up, held = up_and_held(system, states, [False, False, False, True, False], horizon)
    assert up == [True, True, False, True, True]
    assert held == [True, False, True, False, True]
    assert HorizonCheck(horizon, up, held).let_go == 2
