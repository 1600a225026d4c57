"""Learning over seeds (issue 20): leoc's DDPG and SAC defaults learn the cart-pole and
mountain-car swing-ups on most seeds.

Each case trains seeds 0-3 through the ablation harness (:mod:`leoc.experiments.ablation`, two
worker processes, its ``defaults`` setting: ``DDPGConfig.for_system`` with no override) and
counts the seeds whose delivered controller (``best_held``) holds the operating point in every
one of 5 held-out swing-up episodes: the success test of ``results/ddpg-ablation``. Four seeds,
not five: two full rounds of the two workers. These tests are ``extended`` (run by hand, not
by CI: together they exceed its 45 minutes). The thresholds sit one seed below the rates
measured over the same seeds (docs/getting_started.md), so one seed that a different CPU's
rounding sends elsewhere passes, and a regression to the defaults before issue 20 fails (under
those, the grid's ``leoc`` setting: cart-pole baseline 0 of 5 at 15k, mountain-car ROA hybrid 0
of 5 at 10k, 1 of 5 re-selected with ``best_held``).

SAC's cart-pole case is its baseline, the controller that SAC's change of loss (SB3's squared
TD error to the Huber loss, issue 20) was measured on: with the squared error it never held
the operating point at any evaluation up to 21k steps (seeds 0 and 1; the SAC ROA hybrid, by
contrast, held at 12k on one of two seeds with it, so it would not guard the change). SAC costs
more per step than DDPG (1.3 to 1.9 times in the 5-seed validation's wall times), so the case
runs 12k steps where
SAC's baseline holds on 3 of seeds 0-3 (4 of 4 from 15.3k), and asks for 2. SAC's mountain-car
case is its ROA hybrid at 4k steps, where it holds on 5 of 5 seeds (results/sac-defaults; its
baseline first holds at 2.8k-5.6k): cheap, and it fails if SAC's hybrid stops learning the
hilltop early.
"""

from __future__ import annotations

import pytest

from leoc.experiments.ablation import (
    AblationPlan,
    AblationSpec,
    read_records,
    run_ablation,
    run_outcome,
)

# (system, controller, budget, seeds, seeds that hold when measured, at least): the cart-pole
# DDPG baseline at leoc's budget (21k), the mountain-car ROA hybrid at the paper's 10k (leoc's
# is 20k; the hybrids learn it at 10k, the baseline does not). Measured on seeds 0-4 with the same
# settings (results/ddpg-defaults): 5 of 5 each, so 4 of 4 on seeds 0-3. About 7 and 3 min on 2
# cores. SAC's cart-pole baseline at 12k: results/sac-defaults (commit 75ea5b3, the 21k runs
# re-selected at 12k with best_held): seeds 1, 2 and 3 of 0-3 hold (and seed 4; seed 0 first
# at 15.3k), as in the earlier validation at da65235; with the squared TD error seeds 0 and 1
# never held up to 21k. SAC's mountain-car ROA hybrid at 4k: results/sac-defaults (20k runs
# re-selected at 4k): seeds 0-4 hold, first at 2.2k-3.2k steps. About 3 min.
CASES = [
    ("cartpole", "ddpg_baseline", 21_000, 4, 4, 3),
    ("mountaincar", "ddpg_hybrid_roa", 10_000, 4, 4, 3),
    ("cartpole", "sac_baseline", 12_000, 4, 3, 2),
    ("mountaincar", "sac_hybrid_roa", 4_000, 4, 4, 3),
]


@pytest.mark.extended
@pytest.mark.parametrize(("system", "controller", "budget", "seeds", "measured", "at_least"), CASES)
def test_model_free_defaults_learn_the_swing_up_on_most_seeds(
    tmp_path, system, controller, budget, seeds, measured, at_least
) -> None:
    plan = AblationPlan(budgets={system: budget})
    specs = [AblationSpec(system, controller, "defaults", seed) for seed in range(seeds)]
    result = run_ablation(tmp_path, specs, plan, jobs=2, echo=lambda _: None)
    assert not result.failed, result.failed
    records = read_records(tmp_path, echo=lambda _: None)
    assert len(records) == seeds
    assert all(record["model_selection"] == "best_held" for record in records)
    held = [run_outcome(record, budget).success for record in records]
    assert sum(held) >= at_least, (
        f"{sum(held)} of {seeds} hold (measured {measured} of {seeds}): {held}"
    )


# (learner's hybrid, seed): leoc's default pendulum hybrids (issue 40: r = (1 + d^2)^-2, Lambda
# floored so that r >= 0.5 on the LQR's proved set; the ablation's relevance_power_2_floor_0.5)
# at leoc's budget (10k steps) and the relevance ablation's evaluation interval (200 steps).
# Measured in results/relevance-ablation: DDPG 5 of 5 seeds learn the swing-up and keep their
# LQR's impulse response, at 0.00007-0.00044 % of the LQR's peak against the 2 % tolerance; seed
# 0: 0.00034 % (DDPG), 0.00012 % (SAC). The paper's unfloored relevance gives 18-384 % (DDPG) and
# 0.14-6.6 % (SAC); the p = 1 floor 0.55-0.72 % and 0.20-0.67 %.
KEEP_CASES = [("ddpg_hybrid", 0), ("sac_hybrid", 0)]


@pytest.mark.extended
def test_default_pendulum_hybrids_learn_and_keep_their_lqr(tmp_path) -> None:
    """Issue 40's promise (b), with a margin a regression breaks: leoc's default DDPG and SAC
    hybrids (p = 2, floored at r >= 0.5) learn the pendulum swing-up and their delivered
    controller's response to the paper's impulse stays within 2 % of the LQR's peak, with the
    LQR's settling time
    (leoc.evaluation.lqr_agreement, against the LQR designed at the hybrid's period), while
    the relevance is below 1 along it (so the comparison could fail), about 4 min on 2 cores."""
    from leoc.evaluation.lqr_agreement import KEEP_TOLERANCE_PCT

    plan = AblationPlan(budgets={"pendulum": 10_000}, eval_intervals={"pendulum": 200})
    specs = [
        AblationSpec("pendulum", controller, "defaults", seed) for controller, seed in KEEP_CASES
    ]
    result = run_ablation(tmp_path, specs, plan, jobs=2, echo=lambda _: None)
    assert not result.failed, result.failed
    records = read_records(tmp_path, echo=lambda _: None)
    assert sorted(record["controller"] for record in records) == ["ddpg_hybrid", "sac_hybrid"]
    for record in records:
        hybrid = record["config"]["hybrid"]
        assert (hybrid["r_min"], hybrid["relevance_power"]) == (0.5, 2.0), hybrid
        name = record["controller"]
        assert run_outcome(record, 10_000).success, f"{name} does not learn the swing-up"
        impulse = record["lqr_agreement"]["impulse"]
        assert not impulse["by_construction"] and impulse["min_relevance"] < 1.0, (name, impulse)
        assert impulse["distance_pct"] < KEEP_TOLERANCE_PCT, (name, impulse)
        assert impulse["keeps_lqr"], (name, impulse)
