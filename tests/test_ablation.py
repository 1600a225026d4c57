"""The DDPG ablation harness: its grid, its success test, its resume and its publishing."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from pathlib import Path

import pytest

from leoc.experiments.ablation import (
    ABLATION_CONTROLLERS,
    ALL_SETTINGS,
    RESULT_FILE,
    SETTINGS,
    AblationPlan,
    AblationSpec,
    delivered_steps,
    grid_specs,
    merge_plan,
    read_records,
    run_ablation,
    run_cell,
    run_outcome,
)
from leoc.experiments.ablation_report import (
    TABLE_FILES,
    publish_ablation,
    success_rates,
)
from leoc.experiments.stats import wilson_interval
from leoc.experiments.variants import AUTHORS
from leoc.policies.spec import HybridSpec, legacy_hybrid_config
from leoc.sb3.config import (
    AUTHORS_CARTPOLE_BASELINE_ACTOR_LR,
    AUTHORS_DDPG,
    DDPGConfig,
)
from leoc.systems import StepRules

# What each single-factor setting is meant to switch (issue 20), written out here rather than
# read from the module under test.
INTENDED = {
    "exploration": {"noise_units", "ou_theta", "ou_sigma", "noise_reset"},
    "initial_collect": {"warmup", "learning_starts"},
    "critic": {
        "critic_loss",
        "critic_action_layer",
        "critic_action_units",
        "hidden_init",
        "last_layer_init",
    },
    "model_selection": {"model_selection", "eval_episodes"},
}
# The authors' numbers as the issue states them (a second, independent source).
ISSUE_VALUES = {
    "ou_theta": 0.2,
    "ou_sigma": 1.0,
    "noise_units": "physical",
    "noise_reset": False,
    "learning_starts": 1000,
    "warmup": "policy",
    "critic_loss": "huber",
    "critic_action_layer": 1,
    "critic_action_units": "physical",
    "hidden_init": "tf_agents",
    "last_layer_init": 0.003,
    "model_selection": "best_last_third",
    "eval_episodes": 3,
}
TINY = {"actor_hidden": [16, 16], "critic_hidden": [16, 16], "batch_size": 16}
# leoc's defaults before issue 20 switched them, the grid's ``leoc`` setting, written out here
# (SB3's choices: tests/test_ddpg.py checks the new defaults).
PRE_ISSUE_20 = {
    "noise_units": "normalised",
    "ou_theta": 0.15,
    "ou_sigma": 0.2,
    "noise_reset": True,
    "warmup": "uniform",
    "learning_starts": 200,
    "critic_loss": "mse",
    "critic_action_layer": 0,
    "critic_action_units": "normalised",
    "hidden_init": "torch",
    "last_layer_init": None,
    "model_selection": "final",
    "eval_episodes": 5,
    "step_rules": {},
    # the paper's relevance, unfloored (leoc's defaults floor it and square d since issue 40)
    "r_min": None,
    "relevance_power": 1.0,
}
PAPER_BUDGETS = {"pendulum": 10_000, "cartpole": 15_000, "mountaincar": 10_000}


def _fields(config: DDPGConfig) -> dict[str, object]:
    """Every setting of ``config`` by name: its own fields and its hybrid spec's (a baseline's at
    HybridSpec's defaults), as the grid's settings name them."""
    own = {field.name: getattr(config, field.name) for field in dataclasses.fields(config)}
    spec = own.pop("hybrid") or HybridSpec()
    return {**own, **{name: getattr(spec, name) for name in HybridSpec.field_names()}}


def _differences(first: DDPGConfig, second: DDPGConfig) -> dict[str, tuple]:
    one, two = _fields(first), _fields(second)
    return {name: (one[name], two[name]) for name in one if one[name] != two[name]}


CELLS = [
    (setting, system, controller)
    for setting in SETTINGS
    for system in ("cartpole", "mountaincar", "pendulum")
    for controller in ABLATION_CONTROLLERS
    if not (setting == "exit_penalty" and system == "pendulum")
]


@pytest.mark.slow
@pytest.mark.parametrize(("setting", "system", "controller"), CELLS)
def test_each_setting_differs_from_leoc_in_exactly_its_fields_with_the_authors_values(
    setting, system, controller
) -> None:
    plan = AblationPlan()
    config = plan.config(AblationSpec(system, controller, setting, 0))
    leoc = plan.config(AblationSpec(system, controller, "leoc", 0))
    # leoc's cell is DDPGConfig's defaults before issue 20, at the paper's budget and the
    # authors' interval
    expected_leoc = DDPGConfig.for_system(
        system,
        hybrid=controller != "ddpg_baseline",
        relevance="roa" if controller.endswith("roa") else "paper",
        eval_interval={"cartpole": 300}.get(system, 200),
        total_steps=PAPER_BUDGETS[system],
        **PRE_ISSUE_20,
    )
    assert leoc == expected_leoc
    differences = _differences(config, leoc)
    if setting == "leoc":
        assert differences == {}
    elif setting in INTENDED:
        assert set(differences) == INTENDED[setting]
        for name in differences:
            assert _fields(config)[name] == AUTHORS_DDPG[name] == ISSUE_VALUES[name]
    elif setting == "exit_penalty":
        assert set(differences) == {"step_rules"}
        rules, authors = StepRules(**config.step_rules), AUTHORS.rules_for(system)
        assert rules.exit_penalty == authors.exit_penalty == -100.0
        assert rules.reward_on_next_state is authors.reward_on_next_state is True
        assert rules.legacy_integrator is False
    else:  # the authors' full setup: every field of AUTHORS_DDPG that is not leoc's, + rules
        defaults = _fields(leoc)
        expected = {
            name
            for name, value in AUTHORS_DDPG.items()
            if json.dumps(value) != json.dumps(defaults[name])
        } | {"step_rules"}
        if controller == "ddpg_baseline":  # a baseline has no hybrid: its spec's fields drop
            expected -= set(HybridSpec.field_names())
        if system == "cartpole" and controller == "ddpg_baseline":
            expected.add("actor_learning_rate")
            assert config.actor_learning_rate == AUTHORS_CARTPOLE_BASELINE_ACTOR_LR == 1e-4
        assert set(differences) == expected
        assert INTENDED["exploration"] | INTENDED["critic"] <= expected
        assert StepRules(**config.step_rules) == AUTHORS.rules_for(system)
        for name in expected - {"step_rules", "actor_learning_rate"}:
            assert _fields(config)[name] == AUTHORS_DDPG[name]


def test_the_grid_has_the_issues_seeds_and_no_exit_penalty_on_the_pendulum() -> None:
    specs = grid_specs()
    keys = {spec.key for spec in specs}
    assert len(keys) == len(specs)
    by_cell: dict[tuple, set] = {}
    for spec in specs:
        by_cell.setdefault((spec.system, spec.controller, spec.setting), set()).add(spec.seed)
    for (system, _, setting), seeds in by_cell.items():
        assert seeds == set(range(5 if setting in ("leoc", "authors") else 3))
        assert not (system == "pendulum" and setting == "exit_penalty")
    # 3 systems x 3 controllers x (5 + 5 + 5 x 3) seeds, less the pendulum's exit penalty
    assert len(specs) == 3 * 3 * 25 - 3 * 3
    assert {s.seed for s in grid_specs(["pendulum"], seeds=[7, 8])} == {7, 8}
    with pytest.raises(ValueError, match="settings"):
        grid_specs(settings=["huber"])


def test_the_plan_refuses_overrides_of_what_the_grid_switches_and_off_grid_budgets() -> None:
    with pytest.raises(ValueError, match="ou_sigma"):
        AblationPlan(overrides={"ou_sigma": 0.5})
    with pytest.raises(ValueError, match="total_steps"):
        AblationPlan(overrides={"total_steps": 500})
    with pytest.raises(ValueError, match="multiple of the evaluation interval"):
        AblationPlan(budgets={"cartpole": 1000})  # the cart-pole evaluates every 300 steps
    assert AblationPlan(budgets={"cartpole": 1200}).budget_for("cartpole") == 1200


def test_a_folder_refuses_a_second_budget_for_a_system_but_takes_a_new_system() -> None:
    stored = merge_plan({}, AblationPlan(budgets={"pendulum": 600}), ["pendulum"])
    assert stored["budgets"] == {"pendulum": 600}
    extended = merge_plan(stored, AblationPlan(), ["cartpole"])
    assert extended["budgets"] == {"pendulum": 600, "cartpole": 15000}
    with pytest.raises(ValueError, match="pendulum runs have budgets 600"):
        merge_plan(stored, AblationPlan(budgets={"pendulum": 800}), ["pendulum"])
    with pytest.raises(ValueError, match="overrides"):
        merge_plan(stored, AblationPlan(overrides=TINY), ["pendulum"])


def test_wilson_interval_against_its_closed_form() -> None:
    z = 1.959963984540054  # the standard normal's 97.5% quantile
    # 4/5 by hand: centre (0.8 + z^2/10) / (1 + z^2/5), half-width
    # z / (1 + z^2/5) * sqrt(0.8 * 0.2 / 5 + z^2 / 100)
    shrink = 1 + z**2 / 5
    centre = (0.8 + z**2 / 10) / shrink
    half = z / shrink * math.sqrt(0.8 * 0.2 / 5 + z**2 / 100)
    low, high = wilson_interval(4, 5)
    assert low == pytest.approx(centre - half, abs=1e-12)
    assert high == pytest.approx(centre + half, abs=1e-12)
    assert (round(low, 4), round(high, 4)) == (0.3755, 0.9638)  # the published value
    # 0/n and n/n: [0, z^2/(n + z^2)] and [n/(n + z^2), 1]
    assert wilson_interval(0, 5) == pytest.approx((0.0, z**2 / (5 + z**2)), abs=1e-12)
    assert wilson_interval(5, 5) == pytest.approx((5 / (5 + z**2), 1.0), abs=1e-12)
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(6, 5)
    with pytest.raises(ValueError, match="trials"):
        wilson_interval(0, 0)


# ---------------------------------------------------------------------- scripted records
def _record(
    system: str = "cartpole",
    controller: str = "ddpg_baseline",
    setting: str = "leoc",
    seed: int = 0,
    budget: int = 3000,
    interval: int = 300,
    held_at: tuple[int, ...] = (),
    returns: dict[int, float] | None = None,
    model_selection: str = "final",
    learning_starts: int = 200,
    episodes: int = 5,
    selection_held: dict[int, float] | None = None,
) -> dict:
    """A run's record: the held-out episodes all hold at the steps in ``held_at``; the
    selection returns are ``returns`` where given, else -1000; the selection episodes' held
    shares ``selection_held`` where given, else 0."""
    returns = returns or {}
    selection_held = selection_held or {}
    evaluations = [
        {
            "steps": step,
            "selection_return": returns.get(step, -1000.0),
            "selection_held_fraction": selection_held.get(step, 0.0),
            "test_returns": [-100.0] * episodes,
            "test_hold_steps": [50] * episodes if step in held_at else [50, None] + [50] * 3,
        }
        for step in range(0, budget + 1, interval)
    ]
    spec = AblationSpec(system, controller, setting, seed)
    return {
        **spec._asdict(),
        "key": spec.key,
        "budget": budget,
        "eval_interval": interval,
        "learning_starts": learning_starts,
        "model_selection": model_selection,
        "test_episodes": episodes,
        "config": {},
        "evaluations": evaluations,
        "selected_steps": None,
        "wall_seconds": 100.0 + seed,
        "versions": {},
    }


def test_the_delivered_controller_is_the_final_one_or_the_best_of_the_last_third() -> None:
    steps = list(range(0, 3001, 300))
    returns = {1500: -10.0, 2400: -300.0, 2700: -200.0, 3000: -200.0}
    values = [returns.get(step, -1000.0) for step in steps]
    assert delivered_steps(steps, values, 3000, "final", 1000) == 3000
    # window after 1000 + int(2000 * 2 / 3) = 2333: 2400, 2700, 3000; 1500 is the best but
    # outside; 2700 and 3000 tie, the earliest wins (the trainer's strict comparison)
    assert delivered_steps(steps, values, 3000, "best_last_third", 1000) == 2700
    # budget 1800: window after 1000 + int(800 * 2 / 3) = 1533, so only 1800
    assert delivered_steps(steps, values, 1800, "best_last_third", 1000) == 1800
    # budget 2100: window after 1733: 1800, 2100 (both -1000: the earliest)
    assert delivered_steps(steps, values, 2100, "best_last_third", 1000) == 1800
    with pytest.raises(ValueError, match="evaluated step"):
        delivered_steps(steps, values, 2000, "final", 1000)


def test_success_at_a_budget_is_the_delivered_controllers_held_out_test() -> None:
    # learnt at 1200, forgot after 1500, relearnt at 2700 only
    record = _record(held_at=(1200, 1500, 2700))
    assert run_outcome(record, 900) == (900, False, False)
    assert run_outcome(record, 1200) == (1200, True, True)
    assert run_outcome(record, 1800) == (1800, False, True)  # forgot: reached, not delivered
    assert run_outcome(record, 3000) == (3000, False, True)
    # the same run selecting the best of the last third delivers the step-2700 actor at 3000
    selecting = _record(
        held_at=(1200, 1500, 2700),
        returns={2700: -150.0},
        model_selection="best_last_third",
        learning_starts=1000,
    )
    assert run_outcome(selecting, 3000) == (2700, True, True)
    # one episode that does not hold is a failure
    assert run_outcome(_record(held_at=()), 3000).success is False


def _synthetic_folder(root: Path) -> list[dict]:
    """A finished ablation folder: cart-pole baseline leoc (2 of 3 hold from 1500 on),
    authors (1 of 3 from 2700 on), pendulum hybrid leoc (3 of 3 from 600)."""
    records = []
    for seed in range(3):
        records.append(_record(seed=seed, held_at=tuple(range(1500, 3001, 300)) * (seed < 2)))
        records.append(
            _record(setting="authors", seed=seed, held_at=(2700, 3000) if seed == 0 else ())
        )
        records.append(
            _record(
                "pendulum",
                "ddpg_hybrid",
                seed=seed,
                budget=1000,
                interval=200,
                held_at=(600, 800, 1000),
            )
        )
    for record in records:
        path = root / "runs" / record["key"] / RESULT_FILE
        path.parent.mkdir(parents=True)
        path.write_text(json.dumps(record))
    return records


def test_success_rates_and_the_published_tables_from_a_synthetic_folder(tmp_path) -> None:
    records = _synthetic_folder(tmp_path / "runs-folder")
    rates = {(c.system, c.controller, c.setting, c.budget): c for c in success_rates(records)}
    leoc = rates[("cartpole", "ddpg_baseline", "leoc", 1500)]
    assert (leoc.successes, leoc.seeds, leoc.reached) == (2, 3, 2)
    assert (leoc.low, leoc.high) == wilson_interval(2, 3)
    assert rates[("cartpole", "ddpg_baseline", "leoc", 1200)].successes == 0
    assert rates[("cartpole", "ddpg_baseline", "authors", 3000)].successes == 1
    assert rates[("pendulum", "ddpg_hybrid", "leoc", 400)].successes == 0
    assert ("pendulum", "ddpg_hybrid", "leoc", 0) not in rates  # budget 0 is no budget

    dest = tmp_path / "published"
    markdown = publish_ablation(tmp_path / "runs-folder", dest, every=1500).read_text()
    assert "Runs from leoc commit unknown (9 runs)." in markdown  # the records name none
    # the runs stopped at 3000 steps: the headline table is at 3000, and says so
    assert "### cartpole, at 3000 steps (runs shorter than the paper's 15000)" in markdown
    assert "| leoc's defaults | 2/3 [0.21, 0.94] | 2/3 |" in markdown
    assert "| authors' full setup | 1/3 [0.06, 0.79] | 1/3 |" in markdown
    assert "| controller | setting | 1500 | 3000 |" in markdown
    assert "| DDPG baseline | leoc's defaults | 2/3 | 2/3 |" in markdown
    assert "| DDPG baseline | authors' full setup | 0/3 | 1/3 |" in markdown
    # the pendulum's runs end at 1000 steps: no multiple of 1500, so the last budget only
    assert "### pendulum, at 1000 steps (runs shorter than the paper's 10000)" in markdown
    assert "| controller | setting | 1000 |" in markdown
    assert "| DDPG hybrid | leoc's defaults | 3/3 |" in markdown
    csv_lines = (dest / "success_vs_budget.csv").read_text().splitlines()
    assert csv_lines[0] == (
        "system,controller,setting,budget,successes,seeds,rate,wilson_low,wilson_high,reached"
    )
    assert "cartpole,ddpg_baseline,leoc,1500,2,3,0.6667,0.2077,0.9385,2" in csv_lines
    assert len(read_records(dest)) == len(records)  # the records travel, the models do not
    # deterministic: publishing the published folder again gives the same bytes
    before = {name: (dest / name).read_bytes() for name in TABLE_FILES}
    publish_ablation(dest, every=1500)
    assert {name: (dest / name).read_bytes() for name in TABLE_FILES} == before


def test_model_selection_rules_re_apply_to_the_recorded_runs(tmp_path) -> None:
    from leoc.experiments.ablation_report import reselection_rows

    # learnt at 1200 (selection and held-out episodes all hold), forgot after; the return
    # peaks at 2700 in the last third, where one held-out episode falls
    learnt_and_forgot = {
        "held_at": (1200,),
        "returns": {1200: -300.0, 2700: -150.0},
        "selection_held": {1200: 1.0, 2700: 2 / 3},
        "model_selection": "best_last_third",
        "learning_starts": 1000,
    }
    records = [_record(seed=seed, **learnt_and_forgot) for seed in range(2)]
    late = {
        "held_at": (3000,),
        "returns": {3000: -100.0},
        "selection_held": {3000: 1.0},
        "model_selection": "best_last_third",
    }
    records.append(_record(seed=2, **late))
    outcomes = {
        rule: [run_outcome(r, 3000, rule) for r in records]
        for rule in ("final", "best_last_third", "best_held", None)
    }
    assert [o.delivered_steps for o in outcomes["best_held"]] == [1200, 1200, 3000]
    assert [o.delivered_steps for o in outcomes["best_last_third"]] == [2700, 2700, 3000]
    assert outcomes[None] == outcomes["best_last_third"]  # the run's own rule
    assert [o.success for o in outcomes["final"]] == [False, False, True]
    # budget 1500: the runs of budget 1500 could not have selected 2700
    assert run_outcome(records[0], 1500, "best_held").delivered_steps == 1200
    (row,) = reselection_rows(records, {"cartpole": 3000})
    assert (row["final"], row["best_last_third"], row["best_held"], row["reached"]) == (1, 1, 3, 3)
    assert (row["own_rule"], row["seeds"], row["budget"]) == ("best_last_third", 3, 3000)
    folder = tmp_path / "runs-folder"
    for record in records:
        path = folder / "runs" / record["key"] / RESULT_FILE
        path.parent.mkdir(parents=True)
        path.write_text(json.dumps(record))
    markdown = publish_ablation(folder).read_text()
    assert (
        "| DDPG baseline | leoc's defaults | best return, last third | 1/3 | 1/3 | 3/3 | 3/3 |"
        in markdown
    )


@pytest.mark.slow
def test_the_figure_reads_cleanly_for_the_full_grid() -> None:
    from leoc.evaluation.plots import layout_problems
    from leoc.evaluation.plots.ablation import draw_success_vs_budget
    from leoc.experiments.ablation_report import figure_caption, figure_curves

    records = [
        _record(
            system, controller, setting, seed, 3000, 300, held_at=tuple(range(seed * 900, 3001))
        )
        for system in ("cartpole", "mountaincar", "pendulum")
        for controller in ABLATION_CONTROLLERS
        for setting in ALL_SETTINGS
        for seed in range(3)
    ]
    rates = success_rates(records)
    figure = draw_success_vs_budget(
        figure_curves(rates), {"cartpole": 15000}, caption=figure_caption(rates)
    )
    assert layout_problems(figure) == []
    assert len(figure.axes) == 9


# ----------------------------------------------------------------------------- real runs
PLAN = AblationPlan(budgets={"pendulum": 400}, eval_intervals={"pendulum": 100}, overrides=TINY)


@pytest.mark.slow
def test_a_partial_folder_continues_without_redoing_finished_runs(tmp_path) -> None:
    specs = [
        AblationSpec("pendulum", "ddpg_baseline", "leoc", 0),
        AblationSpec("pendulum", "ddpg_baseline", "exploration", 0),
    ]
    quiet: list[str] = []
    plan = dataclasses.replace(PLAN, budgets={"pendulum": 200})  # no update: resume only
    first = run_ablation(tmp_path, specs, plan, jobs=1, echo=quiet.append)
    assert set(first.results) == {spec.key for spec in specs} and not first.failed
    kept = tmp_path / "runs" / specs[0].key / RESULT_FILE
    killed = tmp_path / "runs" / specs[1].key / RESULT_FILE
    kept_bytes = kept.read_bytes()
    killed.unlink()  # as if the worker died before the result was written
    second = run_ablation(tmp_path, specs, plan, jobs=1, echo=quiet.append, command="go --on")
    assert second.skipped == (specs[0].key,)
    assert set(second.results) == {specs[1].key}
    assert kept.read_bytes() == kept_bytes
    assert len(read_records(tmp_path)) == 2
    markdown = publish_ablation(tmp_path).read_text()  # beside the runs: the plan stays
    commit = read_records(tmp_path)[0]["versions"].get("leoc_commit") or "unknown"
    assert f"Runs from leoc commit {commit} (2 runs). Recorded command: `go --on`." in markdown
    with pytest.raises(ValueError, match="budgets"):
        run_ablation(tmp_path, specs, AblationPlan(overrides=TINY), jobs=1, echo=quiet.append)
    # a published folder (records, logs and plan; no models) is a resumable one: copied to a
    # new machine, the same command runs only what is missing and keeps the records it found
    published = publish_ablation(tmp_path, tmp_path.with_name(f"{tmp_path.name}-published")).parent
    moved = tmp_path.with_name(f"{tmp_path.name}-new-machine")
    shutil.copytree(published, moved)
    (moved / "runs" / specs[1].key / RESULT_FILE).unlink()
    third = run_ablation(moved, specs, plan, jobs=1, echo=quiet.append, command="go --on")
    assert third.skipped == (specs[0].key,)
    assert set(third.results) == {specs[1].key}
    assert (moved / "runs" / specs[0].key / RESULT_FILE).read_bytes() == kept_bytes
    with pytest.raises(ValueError, match="budgets"):  # the published plan is pinned too
        run_ablation(moved, specs, AblationPlan(overrides=TINY), jobs=1, echo=quiet.append)


@pytest.mark.slow
def test_the_command_runs_the_records_run_ablation_makes_and_resumes(tmp_path, capsys) -> None:
    """``leoc ablation`` on one cell gives the record :func:`run_ablation` gives called
    directly (same plan), pins the command line, publishes, and a rerun trains nothing."""
    from leoc.cli import main

    spec = AblationSpec("pendulum", "ddpg_baseline", "leoc", 0)
    plan = dataclasses.replace(PLAN, budgets={"pendulum": 200})  # no update: quick
    run_ablation(tmp_path / "direct", [spec], plan, jobs=1, echo=lambda _: None)
    argv = [
        "ablation",
        *("--out", str(tmp_path / "cli"), "--systems", "pendulum", "--settings", "leoc"),
        *("--controllers", "ddpg_baseline", "--seeds", "0", "--jobs", "1"),
        *("--budget", "200", "--eval-interval", "pendulum=100", "--overrides", json.dumps(TINY)),
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "1 runs: 0 already done, 1 to run" in out and "## Success at the paper's budget" in out
    (direct,), (command,) = read_records(tmp_path / "direct"), read_records(tmp_path / "cli")
    for record in (direct, command):
        del record["wall_seconds"]
    assert command == direct
    plan_file = json.loads((tmp_path / "cli" / "plan.json").read_text())
    assert plan_file["plan"] == json.loads((tmp_path / "direct" / "plan.json").read_text())["plan"]
    assert (tmp_path / "cli" / TABLE_FILES[0]).exists()
    assert main(argv) == 0
    assert "1 runs: 1 already done, 0 to run" in capsys.readouterr().out


@pytest.mark.slow
def test_a_short_run_is_the_prefix_of_a_long_one_and_selection_matches_the_trainer(
    tmp_path,
) -> None:
    spec = AblationSpec("pendulum", "ddpg_hybrid", "model_selection", 1)
    long = run_cell(spec, PLAN, tmp_path / "long")
    short_plan = dataclasses.replace(PLAN, budgets={"pendulum": 300})
    short = run_cell(spec, short_plan, tmp_path / "short")
    # 100 gradient updates happen before step 300 (learning_starts 200): the short run's
    # evaluations are the long run's, so one long run gives every shorter budget
    assert short["evaluations"] == long["evaluations"][: len(short["evaluations"])]
    for record in (long, short):
        steps = [row["steps"] for row in record["evaluations"]]
        assert steps == list(range(0, record["budget"] + 1, 100))
        delivered = run_outcome(record, record["budget"]).delivered_steps
        assert delivered == (record["selected_steps"] or record["budget"])


def test_sac_controllers_take_only_the_settings_that_are_not_ddpg_choices() -> None:
    specs = grid_specs(controllers=["sac_hybrid_roa", "ddpg_hybrid"], seeds=[0])
    sac = [spec for spec in specs if spec.controller == "sac_hybrid_roa"]
    # leoc's defaults everywhere, the authors' exit rule where there is a track
    assert {(s.system, s.setting) for s in sac} == {
        ("cartpole", "leoc"),
        ("cartpole", "exit_penalty"),
        ("mountaincar", "leoc"),
        ("mountaincar", "exit_penalty"),
        ("pendulum", "leoc"),
    }
    assert len([s for s in specs if s.controller == "ddpg_hybrid"]) == 3 * 7 - 1
    plan = AblationPlan()
    for spec in sac:
        config = plan.config(spec)
        assert spec.algo == "sac" and config.algo == "sac" and config.hybrid.relevance == "roa"
        # SAC's defaults before issue 20: leoc's step rules, the final actor on 5 episodes,
        # SB3's critics (written out: an independent reference for SB3_SAC_CRITIC)
        expected = DDPGConfig.for_system(
            spec.system,
            "sac",
            hybrid=True,
            relevance="roa",
            eval_interval=config.eval_interval,
            total_steps=PAPER_BUDGETS[spec.system],
            step_rules={},
            model_selection="final",
            eval_episodes=5,
            critic_loss="mse",
            critic_action_layer=0,
            critic_action_units="normalised",
            hidden_init="torch",
            last_layer_init=None,
        )
        assert _differences(expected, config).keys() <= {"step_rules"}
        assert bool(_differences(expected, config)) == (spec.setting == "exit_penalty")


@pytest.mark.slow
def test_a_short_sac_run_is_the_prefix_of_a_long_one(tmp_path) -> None:
    spec = AblationSpec("pendulum", "sac_hybrid", "leoc", 2)
    long = run_cell(spec, PLAN, tmp_path / "long")
    short = run_cell(spec, dataclasses.replace(PLAN, budgets={"pendulum": 300}), tmp_path / "s")
    assert long["config"]["algo"] == "sac"
    assert short["evaluations"] == long["evaluations"][: len(short["evaluations"])]
    assert [row["steps"] for row in long["evaluations"]] == [0, 100, 200, 300, 400]


@pytest.mark.parametrize("system", ["cartpole", "mountaincar", "pendulum"])
@pytest.mark.parametrize("controller", ["ddpg_baseline", "ddpg_hybrid_roa"])
def test_all_factors_has_every_single_factor_and_each_all_but_leaves_out_exactly_one(
    system, controller
) -> None:
    plan = AblationPlan()
    leoc = plan.config(AblationSpec(system, controller, "leoc", 0))
    everything = plan.config(AblationSpec(system, controller, "all_factors", 0))
    fields = set().union(*INTENDED.values())
    has_track = system != "pendulum"
    # all five choices at once, with the authors' values, and nothing else
    assert set(_differences(everything, leoc)) == fields | ({"step_rules"} if has_track else set())
    for name in fields:
        assert getattr(everything, name) == ISSUE_VALUES[name]
    for factor in ("exploration", "initial_collect", "critic", "exit_penalty", "model_selection"):
        setting = f"all_but_{factor}"
        specs = grid_specs([system], [controller], [setting], seeds=[0])
        if factor == "exit_penalty" and not has_track:
            assert specs == []  # the same as all_factors there: left out
            continue
        left = plan.config(specs[0])
        missing = INTENDED.get(factor, {"step_rules"})
        assert set(_differences(left, everything)) == missing
        for name in missing:  # back at leoc's value
            assert getattr(left, name) == getattr(leoc, name)


@pytest.mark.parametrize("system", ["cartpole", "mountaincar", "pendulum"])
def test_all_safe_exit_keeps_the_next_state_reward_and_leoc_exit_that_never_pays(system) -> None:
    plan = AblationPlan()
    specs = grid_specs([system], ["ddpg_hybrid"], ["all_safe_exit"], seeds=[0])
    if system == "pendulum":  # the authors take the pendulum's reward before the step: left out
        assert specs == []
        return
    safe = plan.config(specs[0])
    without = plan.config(AblationSpec(system, "ddpg_hybrid", "all_but_exit_penalty", 0))
    assert _differences(safe, without) == {"step_rules": ({"reward_on_next_state": True}, {})}
    rules = StepRules(**safe.step_rules)
    assert rules.exit_penalty is None  # leoc's exit, which never pays
    assert rules.reward_on_next_state == AUTHORS.rules_for(system).reward_on_next_state is True


@pytest.mark.parametrize("system", ["cartpole", "mountaincar", "pendulum"])
def test_the_horizon_exit_settings_change_only_the_exit_shape(system) -> None:
    plan = AblationPlan()
    specs = grid_specs([system], ["ddpg_baseline"], ["horizon_exit", "all_horizon_exit"], [0])
    if system == "pendulum":  # no track to leave: both would equal leoc / all_factors
        assert specs == []
        return
    alone, combined = (plan.config(spec) for spec in specs)
    leoc = plan.config(AblationSpec(system, "ddpg_baseline", "leoc", 0))
    safe = plan.config(AblationSpec(system, "ddpg_baseline", "all_safe_exit", 0))
    assert _differences(alone, leoc) == {"step_rules": ({"horizon_exit": True}, {})}
    assert _differences(combined, safe) == {
        "step_rules": (
            {"reward_on_next_state": True, "horizon_exit": True},
            {"reward_on_next_state": True},
        )
    }
    for config in (alone, combined):
        rules = StepRules(**config.step_rules)
        assert rules.exit_penalty is None and rules.horizon_exit  # never pays (test_rollout)


GRID_CONFIGS = json.loads(
    (Path(__file__).parent / "data" / "ablation_grid_configs.json").read_text(encoding="utf-8")
)


@pytest.mark.slow
@pytest.mark.parametrize(
    "cell",
    [
        (setting, key)
        for setting, cells in (("leoc", GRID_CONFIGS["leoc"]), *GRID_CONFIGS["settings"].items())
        for key in cells
    ],
    ids="/".join,
)
def test_every_setting_builds_the_config_the_published_grid_ran(cell) -> None:
    """The grid's configs, as the runs of commit 8221beb wrote them (tests/data), are what
    this code builds for the same cells (the rules as StepRules): ``leoc`` is
    LEOC_ABLATION_BASE written out, so
    leoc's new defaults (issue 20) leave the published grid reproducible."""
    setting, key = cell
    system, controller = key.split("/")
    recorded = dict(GRID_CONFIGS["leoc"][key])
    if setting != "leoc":
        recorded.update(GRID_CONFIGS["settings"][setting][key])
    # written before HybridSpec: the hybrid's fields beside the config's, read into its spec
    recorded = legacy_hybrid_config(recorded)
    built = AblationPlan().config(AblationSpec(system, controller, setting, 0)).as_dict()
    # StepRules fields added since (horizon_exit) keep their defaults: compare the rules
    assert StepRules(**built.pop("step_rules")) == StepRules(**recorded.pop("step_rules"))
    # DDPGConfig fields added since (sac_action_noise) keep their defaults
    defaults = {field.name: field.default for field in dataclasses.fields(DDPGConfig)}
    for name in set(built) - set(recorded):
        assert built.pop(name) == defaults[name], name
    assert built == recorded


def test_the_defaults_setting_is_leocs_defaults_and_differs_from_the_grids_leoc() -> None:
    """``defaults`` runs DDPGConfig.for_system as it is (with the plan's budget and interval);
    after issue 20 those are the ``all_safe_exit`` choices with ``best_held``, not the grid's
    ``leoc`` (a switch that silently fell back to the old defaults fails here)."""
    plan = AblationPlan(budgets={"cartpole": 21_000})
    for controller, hybrid, relevance in (
        ("ddpg_hybrid_roa", True, "roa"),
        ("sac_baseline", False, "paper"),
    ):
        algo = "sac" if controller.startswith("sac") else "ddpg"
        built = plan.config(AblationSpec("cartpole", controller, "defaults", 0))
        assert built == DDPGConfig.for_system("cartpole", algo, hybrid=hybrid, relevance=relevance)
    safe = plan.config(AblationSpec("cartpole", "ddpg_hybrid", "all_safe_exit", 0))
    defaults = plan.config(AblationSpec("cartpole", "ddpg_hybrid", "defaults", 0))
    # issue 40's defaults floor the paper relevance and square d; the grid keeps the paper's
    relevance = {"r_min": (0.5, None), "relevance_power": (2.0, 1.0)}
    assert _differences(defaults, safe) == {
        "model_selection": ("best_held", "best_last_third"),
        **relevance,
    }
    old = plan.config(AblationSpec("cartpole", "ddpg_hybrid", "leoc", 0))
    assert set(_differences(defaults, old)) == (
        INTENDED["exploration"]
        | INTENDED["initial_collect"]
        | INTENDED["critic"]
        | INTENDED["model_selection"]
        | {"step_rules", *relevance}
    )
    # relevance_paper: today's defaults with the paper's relevance as it was before issue 40;
    # each relevance setting differs from it in its own fields only
    paper = plan.config(AblationSpec("cartpole", "ddpg_hybrid", "relevance_paper", 0))
    assert _differences(defaults, paper) == relevance
    frozen = plan.config(AblationSpec("cartpole", "ddpg_hybrid", "relevance_frozen", 0))
    assert _differences(frozen, paper) == {"learn_lambda": (False, True)}
    chosen = plan.config(AblationSpec("cartpole", "ddpg_hybrid", "relevance_power_2_floor_0.5", 0))
    assert chosen == defaults


COMMITTED = sorted(
    path.parent for path in (Path(__file__).resolve().parents[1] / "results").glob("*/ablation.md")
)


@pytest.mark.slow
@pytest.mark.parametrize("published", COMMITTED, ids=[path.name for path in COMMITTED])
def test_committed_ablation_folders_regenerate_byte_for_byte(published, tmp_path) -> None:
    """Publishing a committed ablation folder's records again (``--publish-only``) gives its
    tables byte for byte: the README's numbers are what the records say."""
    dest = tmp_path / published.name
    publish_ablation(published, dest)
    for name in TABLE_FILES:
        assert (dest / name).read_bytes() == (published / name).read_bytes(), name
    # the report names the settings its runs ran, and no others
    line = next(
        text
        for text in (published / "ablation.md").read_text().splitlines()
        if text.startswith("Settings")
    )
    ran = {str(record["setting"]) for record in read_records(published, echo=lambda _: None)}
    assert {name for name in ALL_SETTINGS if f"`{name}`" in line} == ran
