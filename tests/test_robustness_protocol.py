"""The robustness protocol (issue 43, item 2) against references that do not go through it:
the unperturbed closed loop and its hold test, scores counted by hand, and level grids written
out in full."""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
import torch

from leoc.cli import main
from leoc.control.lqr import design_lqr
from leoc.evaluation.plots.common import layout_problems
from leoc.evaluation.plots.robustness_protocol import draw_protocol_scores
from leoc.evaluation.robustness_protocol import (
    CALIBRATION_EPISODES,
    CATEGORY_NAMES,
    DEFAULT_MAX_LEVELS,
    CategoryResult,
    LevelResult,
    MaxLevels,
    ProtocolResult,
    failure_level,
    level_grid,
    max_levels_for,
    protocol_starts,
    run_protocol,
)
from leoc.policies.held import lqr_controller
from leoc.systems import make_system
from leoc.systems.base import DTYPE
from leoc.systems.rollout import simulate

# A perturbation this small changes no hold-test outcome of the LQR (its sweep is "the nominal
# plant, 3 times"), yet every category's code path runs.
TINY = 1e-9


@functools.cache
def _lqr(name: str):
    system = make_system(name)
    return system, lqr_controller(design_lqr(system), "clip", system.action_limit)


def _zero(obs: torch.Tensor) -> torch.Tensor:
    """A controller that never acts."""
    return torch.zeros(obs.shape[0], 1, dtype=DTYPE)


def _unperturbed_held(system, controller, starts) -> list[bool]:
    """The hold test on the unperturbed closed loop, written out (System.hold_step)."""
    batch = simulate(system, controller, np.asarray(starts))
    return [
        system.hold_step(batch.states[i, 1:], terminated=bool(batch.terminated[i])) is not None
        for i in range(len(starts))
    ]


def _tiny_levels(system_name: str) -> MaxLevels:
    table = DEFAULT_MAX_LEVELS[system_name]
    return MaxLevels(TINY, 1, TINY, TINY, TINY, TINY, TINY, TINY, table.constants)


# ---------------------------------------------------------------------------- level grids
@pytest.mark.parametrize(
    ("category", "max_level", "count", "expected"),
    [
        ("torque_noise", 1.0, 5, (0.0, 0.25, 0.5, 0.75, 1.0)),
        ("push", 2.0, 3, (0.0, 1.0, 2.0)),
        ("actuator_gain", 0.5, 5, (-0.5, -0.25, 0.0, 0.25, 0.5)),
        ("parameter_error", 0.3, 3, (-0.3, 0.0, 0.3)),
        ("action_delay", 3, 21, (0.0, 1.0, 2.0, 3.0)),
        ("action_delay", 40, 21, tuple(float(s) for s in range(0, 41, 2))),
        ("action_delay", 8, 3, (0.0, 4.0, 8.0)),
    ],
)
def test_level_grids_written_out(category, max_level, count, expected) -> None:
    assert level_grid(category, max_level, count) == pytest.approx(expected, abs=1e-15)


def test_every_one_sided_grid_starts_at_none_and_ends_at_the_maximum() -> None:
    for category in CATEGORY_NAMES:
        grid = level_grid(category, 0.7 if category != "action_delay" else 7, 21)
        assert len(grid) == (8 if category == "action_delay" else 21)
        assert 0.0 in grid and grid[-1] == pytest.approx(0.7 if category != "action_delay" else 7)


def test_a_two_sided_grid_holds_the_nominal_plant_exactly() -> None:
    # 0.1 * k for k = -10..10 is not exactly 0 at k = 0 after linspace's arithmetic in general;
    # the grid must give the nominal plant itself (a null perturbation, not applied).
    grid = level_grid("actuator_gain", 0.62, 21)
    assert grid[10] == 0.0


# ---------------------------------------------------------------------------- the protocol
@pytest.mark.slow
def test_level_zero_of_every_category_is_the_unperturbed_hold_test() -> None:
    system, lqr = _lqr("pendulum")
    result = run_protocol(system, lqr, "lqr", levels=3, episodes=3, seed=4)
    assert [c.name for c in result.categories] == list(CATEGORY_NAMES)
    for kind, starts in result.starts.items():
        reference = _unperturbed_held(system, lqr, starts)
        for category in result.categories:
            nominal = [level for level in category.levels if level.level == 0.0]
            assert nominal, category.name
            for level in nominal:
                assert level.held[kind] == reference, (category.name, kind, level.constant)
    # The starts are the system's own distributions, from the one seed.
    again = protocol_starts(system, 3, seed=4)
    for kind in result.starts:
        np.testing.assert_array_equal(np.asarray(result.starts[kind]), again[kind])
    region = np.asarray(result.starts["operating_region"]) - system.operating_state
    assert np.all(np.abs(region) <= np.asarray(system.operating_region))


@pytest.mark.slow
def test_scores_counted_by_hand_with_a_controller_that_fails_and_one_that_holds() -> None:
    system, lqr = _lqr("pendulum")
    tiny = _tiny_levels("pendulum")
    held = run_protocol(system, lqr, "lqr", levels=3, episodes=4, max_levels=tiny, seed=1)
    # Independent reference: the unperturbed LQR holds every operating-region start and no
    # swing-up start (it cannot swing up with 2 N m), so each category scores exactly
    # (levels x 4 held) / (levels x 8 run) = 1/2, per start kind 1 and 0.
    assert all(_unperturbed_held(system, lqr, held.starts["operating_region"]))
    assert not any(_unperturbed_held(system, lqr, held.starts["swing_up"]))
    assert held.scores() == {name: 0.5 for name in CATEGORY_NAMES}
    assert held.scores("operating_region") == {name: 1.0 for name in CATEGORY_NAMES}
    assert held.score() == 0.5 and held.score("swing_up") == 0.0
    parameter = held.categories[CATEGORY_NAMES.index("parameter_error")]
    assert len(parameter.levels) == 3 * len(tiny.constants)
    failed = run_protocol(system, _zero, "zero", levels=3, episodes=2, max_levels=tiny)
    assert failed.score() == 0.0 and set(failed.scores().values()) == {0.0}


def test_the_score_is_the_mean_of_every_category() -> None:
    def category(name, pattern):
        levels = [
            LevelResult(float(i), None, {"swing_up": row}, {}) for i, row in enumerate(pattern)
        ]
        return CategoryResult(name, 1.0, levels)

    categories = [
        category("observation_noise", [[True, True], [True, True]]),  # 4 of 4
        category("action_delay", [[True, False], [False, False]]),  # 1 of 4
        category("push", [[False, False], [False, True], [True, True]]),  # 3 of 6
    ]
    result = ProtocolResult("pendulum", "hand", 0, 2, 2, 1, {}, {"swing_up": []}, categories)
    assert result.scores() == {"observation_noise": 1.0, "action_delay": 0.25, "push": 0.5}
    assert result.score() == pytest.approx((1.0 + 0.25 + 0.5) / 3, abs=1e-15)


@pytest.mark.slow
def test_one_seed_decides_everything() -> None:
    system, lqr = _lqr("pendulum")
    options = dict(levels=2, episodes=2, categories=("observation_noise", "push"))
    first = run_protocol(system, lqr, "lqr", seed=7, **options).as_dict()
    assert run_protocol(system, lqr, "lqr", seed=7, **options).as_dict() == first
    other = run_protocol(system, lqr, "lqr", seed=8, **options).as_dict()
    assert other["starts"] != first["starts"]
    seeds = {
        entry["seed"]
        for category in first["categories"]
        for level in category["levels"]
        for entries in level["perturbations"].values()
        for entry in entries
    }
    # One seed per category and start kind (the same at every level): 2 x 2.
    assert len(seeds) == 4


def test_json_round_trip_and_atomic_save(tmp_path) -> None:
    system, lqr = _lqr("mountaincar")
    result = run_protocol(system, lqr, "lqr", levels=2, episodes=1, categories=("actuator_gain",))
    path = result.save(tmp_path / "protocol.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["protocol.json"]
    loaded = ProtocolResult.load(path)
    assert loaded.as_dict() == json.loads(path.read_text())
    assert loaded.scores() == result.scores() and loaded.score() == result.score()
    assert loaded.categories[0].levels[0].held == result.categories[0].levels[0].held


@pytest.mark.slow
@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar"])
def test_the_table_ends_each_sweep_where_the_lqr_fails(name) -> None:
    # The documented measurement, redone: at each category's maximum level the LQR holds none
    # of the calibration's operating-region starts (Coulomb friction stops at its cap instead
    # where the LQR keeps the starts that begin inside the band: docs/user_guide/evaluation.md).
    system, lqr = _lqr(name)
    table = max_levels_for(name)
    for category in CATEGORY_NAMES:
        found = failure_level(system, lqr, category, CALIBRATION_EPISODES)
        assert table.level(category) >= found.level - 1e-12, category
        assert table.level(category) <= 1.1 * found.level + 1e-12, category


def test_bad_input_names_the_argument() -> None:
    system, lqr = _lqr("pendulum")
    with pytest.raises(ValueError, match="levels: expected an integer >= 2, found 1"):
        run_protocol(system, lqr, levels=1)
    with pytest.raises(ValueError, match="category: expected one of .* found 'wind'"):
        run_protocol(system, lqr, categories=("wind",))
    with pytest.raises(ValueError, match="episodes: expected a positive integer, found 0"):
        run_protocol(system, lqr, episodes=0)
    with pytest.raises(ValueError, match="system: expected one of .* found 'segway'"):
        max_levels_for("segway")
    with pytest.raises(ValueError, match="MaxLevels.parameter_error: expected a deviation"):
        MaxLevels(1, 1, 0.5, 1, 1, 1, 1.0, 1)
    with pytest.raises(ValueError, match="MaxLevels.actuator_gain: expected a deviation of at"):
        MaxLevels(1, 1, 1.5, 1, 1, 1, 0.5, 1)
    with pytest.raises(ValueError, match="MaxLevels.action_delay: expected whole simulator"):
        MaxLevels(1, 1.5, 0.5, 1, 1, 1, 0.5, 1)


# ---------------------------------------------------------------------------- the command
def test_cli_json_scores_and_output_file(tmp_path, capsys) -> None:
    output = tmp_path / "scores.json"
    argv = ["robustness", "pendulum", "--levels", "2", "--episodes", "1", "--seed", "3"]
    argv += ["--categories", "push", "action_delay", "--json", "--output", str(output)]
    assert main(argv) == 0
    captured = capsys.readouterr()
    printed = json.loads(captured.out)
    assert "swing_up starts (2/2" in captured.err  # progress goes to stderr
    (label,) = printed["results"]
    result = ProtocolResult.from_dict(printed["results"][label])
    assert [c.name for c in result.categories] == ["action_delay", "push"]
    assert printed["scores"][label]["all"]["robustness"] == result.score()
    assert json.loads(output.read_text())["results"] == printed["results"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "system: expected a system name or a run folder"),
        (["pendulum", "--levels", "1"], "argument --levels: expected an integer >= 2, found 1"),
        (["pendulum", "--episodes", "0"], "argument --episodes: expected a positive integer"),
        (["pendulum", "--categories", "wind"], "argument --categories: invalid choice: 'wind'"),
        (["pendulum", "--controller", "linear", "linear"], "--controller: expected each"),
    ],
)
def test_cli_errors_are_one_line_naming_the_argument(capsys, argv, message) -> None:
    try:
        status = main(["robustness", *argv])
    except SystemExit as exit_:
        status = exit_.code
    assert status == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert message in line


def test_the_figure_reads_cleanly() -> None:
    system, lqr = _lqr("pendulum")
    options = dict(levels=2, episodes=1, categories=("actuator_gain", "push"))
    results = {
        "LQR": run_protocol(system, lqr, "LQR", **options),
        "zero": run_protocol(system, _zero, "zero", **options),
    }
    figure = draw_protocol_scores(results, {"LQR": "linear"})
    assert layout_problems(figure) == []
    assert len(figure.axes) == 3


# ---------------------------------------------------------------------------- run folders
@pytest.fixture(scope="module")
def two_pilco_runs_named_train(tmp_path_factory, tiny_pilco_settings) -> list[str]:
    """Two tiny PILCO pendulum runs (control period 2), each in a folder named ``train``, as
    ``benchmarks/bench_pilco_failures.py`` lays them out (``.../seedN/train``)."""
    from leoc.pilco.train import train_pilco

    root = tmp_path_factory.mktemp("runs")
    runs = []
    for seed, hybrid in ((0, False), (1, True)):
        run = root / f"seed{seed}" / "train"
        train_pilco(
            "pendulum",
            hybrid=hybrid,
            seed=seed,
            run_dir=run,
            iterations=1,
            progress=False,
            **tiny_pilco_settings,
        )
        runs.append(str(run))
    return runs


def test_cli_scores_runs_of_one_name_apart_and_the_lqr_at_their_period(
    two_pilco_runs_named_train, capsys
) -> None:
    """Two runs in folders of one name are both scored (one used to replace the other), and
    the LQR beside them runs at their control period (2), not the simulator's step: its
    scores equal the protocol run on a period-2 LQR and differ from a period-1 LQR's."""
    from leoc.experiments.controllers import load_trained_controller
    from leoc.experiments.variants import get_variant

    argv = ["robustness", "--controller", "linear", *two_pilco_runs_named_train]
    argv += ["--levels", "2", "--episodes", "2", "--categories", "viscous_friction", "push"]
    assert main([*argv, "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert list(printed["results"]) == ["LQR (period 2 steps)", "seed0/train", "seed1/train"]
    system = make_system("pendulum")
    # At these levels the period-1 LQR holds fewer viscous-friction episodes (0.25 against 0.5).
    options = dict(levels=2, episodes=2, categories=("viscous_friction", "push"))
    for period in (2, 1):
        lqr = get_variant("leoc").linear_controller(system, period)
        expected = run_protocol(system, lqr, "LQR", **options).score()
        got = printed["scores"]["LQR (period 2 steps)"]["all"]["robustness"]
        assert (abs(got - expected) < 1e-12) == (period == 2)
    for spec in two_pilco_runs_named_train:
        controller = load_trained_controller(spec, system="pendulum")
        expected = run_protocol(system, controller, "run", **options).score()
        label = "/".join(spec.split("/")[-2:])
        assert abs(printed["scores"][label]["all"]["robustness"] - expected) < 1e-12


def test_cli_asks_for_the_lqr_period_beside_runs_of_two_periods(
    two_pilco_runs_named_train, tmp_path, tiny_pilco_settings, capsys
) -> None:
    """A period-1 run beside a period-2 run: which period the LQR shares is the user's call,
    asked in one line; naming it scores all three."""
    from leoc.pilco.train import train_pilco

    one = tmp_path / "period1"
    settings = {**tiny_pilco_settings, "action_repeat": 1}
    train_pilco("pendulum", seed=2, run_dir=one, iterations=1, progress=False, **settings)
    argv = ["robustness", "--controller", "linear", two_pilco_runs_named_train[0], str(one)]
    argv += ["--levels", "2", "--episodes", "1", "--categories", "push"]
    assert main(argv) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--action-repeat: expected it for the LQR beside runs of different" in line
    assert main([*argv, "--action-repeat", "1", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert list(printed["results"]) == ["LQR (period 1 step)", "train", "period1"]
    # without the LQR, runs of two periods are scored side by side as they are
    assert main([*argv[:2], *argv[3:], "--json"]) == 0
    assert list(json.loads(capsys.readouterr().out)["results"]) == ["train", "period1"]
