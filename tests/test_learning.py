"""Learning over seeds (issue 20): leoc's DDPG defaults learn the cart-pole and mountain-car
swing-ups on most seeds.

Each case trains 5 seeds through the ablation harness (:mod:`leoc.experiments.ablation`, two
worker processes, its ``defaults`` setting: ``DDPGConfig.for_system`` with no override) and
counts the seeds whose delivered controller (``best_held``) holds the operating point in every
one of 5 held-out swing-up episodes: the success test of ``results/ddpg-ablation``. The
thresholds sit one seed below the rates measured over the same 5 seeds (README), so one seed
that a different CPU's rounding sends elsewhere passes, and a regression to the defaults before
issue 20 fails (under those, the grid's ``leoc`` setting: cart-pole baseline 0 of 5 at 15k,
mountain-car ROA hybrid 0 of 5 at 10k, 1 of 5 re-selected with ``best_held``).
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

# (system, controller, budget, seeds that hold when measured, at least): the cart-pole baseline
# at leoc's budget (21k), the mountain-car ROA hybrid at the paper's 10k (leoc's is 20k; the
# hybrids learn it at 10k, the baseline does not). Measured on seeds 0-4 with the same
# settings (results/ddpg-safe-exit-long: all_safe_exit re-selected with best_held, the
# defaults' choices): 5 of 5 each. About 7 and 4 min on 2 cores.
CASES = [
    ("cartpole", "ddpg_baseline", 21_000, 5, 4),
    ("mountaincar", "ddpg_hybrid_roa", 10_000, 5, 4),
]


@pytest.mark.slow
@pytest.mark.parametrize(("system", "controller", "budget", "measured", "at_least"), CASES)
def test_ddpg_defaults_learn_the_swing_up_on_most_seeds(
    tmp_path, system, controller, budget, measured, at_least
) -> None:
    plan = AblationPlan(budgets={system: budget})
    specs = [AblationSpec(system, controller, "defaults", seed) for seed in range(5)]
    result = run_ablation(tmp_path, specs, plan, jobs=2, echo=lambda _: None)
    assert not result.failed, result.failed
    records = read_records(tmp_path, echo=lambda _: None)
    assert len(records) == 5
    assert all(record["model_selection"] == "best_held" for record in records)
    held = [run_outcome(record, budget).success for record in records]
    assert sum(held) >= at_least, f"{sum(held)} of 5 hold (measured {measured} of 5): {held}"
