"""Model selection on plants of the training distribution (``selection_plants="training"``).

What is checked: the selection episodes' plants are the documented Latin hypercube (recomputed
here with numpy alone) and cover one stratum of each range per episode; evaluating on them
equals one ``simulate`` per plant; the callback judges selection on them, not on the nominal
curve (scripted evaluations); a short SAC run records them, selects the step whose record is
best, and saves the actor that scores that record again on the same plants (slow); bad settings
are one-line errors naming the flag or the field.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from leoc.cli import main
from leoc.cli.train import SELECTION_PLANTS as CLI_CHOICES
from leoc.control import design_lqr
from leoc.policies.held import lqr_controller
from leoc.sb3 import callbacks as callbacks_module
from leoc.sb3.callbacks import LearningCurveCallback, selection_key
from leoc.sb3.config import SELECTION_PLANTS, DDPGConfig
from leoc.systems import (
    SELECTION_STREAM,
    TrainingPerturbations,
    category_perturbations,
    make_system,
)
from leoc.systems.rollout import simulate
from leoc.training import Evaluation, evaluate_episodes, evaluate_on_plants, evaluation_starts

SAME = 1e-12  # a recomputed level agrees to rounding
SPEC = TrainingPerturbations(
    fixed={"torque_noise": 0.1},
    randomised={"actuator_gain": 0.48, "action_delay": 2, "observation_noise": 0.3},
)


def _independent_draws(seed: int, episodes: int, spec: TrainingPerturbations) -> list:
    """The selection episodes' levels and noise seeds by the documented rule, numpy alone."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, SELECTION_STREAM]))
    permutations = [rng.permutation(episodes) for _ in spec.randomised]
    offsets = rng.random((episodes, len(spec.randomised)))
    found = []
    for k in range(episodes):
        levels = dict(spec.fixed)
        for j, (key, maximum) in enumerate(spec.randomised):
            u = (permutations[j][k] + offsets[k, j]) / episodes
            if key == "action_delay":
                levels[key] = float(min(int(u * (maximum + 1)), maximum))
            elif key == "actuator_gain":
                levels[key] = -maximum + 2.0 * maximum * u
            else:
                levels[key] = maximum * u
        found.append((levels, int(rng.integers(2**32))))
    return found


def test_selection_plants_are_the_documented_latin_hypercube() -> None:
    system = make_system("pendulum")
    for seed, episodes in ((0, 3), (7, 5), (3, 1)):
        draws = SPEC.selection_draws(system, seed, episodes)
        expected = _independent_draws(seed, episodes, SPEC)
        assert len(draws) == episodes
        for draw, (levels, noise_seed) in zip(draws, expected, strict=True):
            assert draw.levels == pytest.approx(levels, rel=SAME, abs=SAME)
            assert draw.seed == noise_seed
            built = []
            for key, level in draw.levels.items():
                built += category_perturbations(system, key, level, noise_seed, 1, None)
            assert sorted(map(repr, draw.perturbations)) == sorted(map(repr, built))
        # one stratum of each continuous range per episode
        gains = np.array([draw.levels["actuator_gain"] for draw in draws])
        strata = np.floor((gains / 0.48 + 1.0) / 2.0 * episodes).astype(int)
        assert sorted(strata) == list(range(episodes))
        noise = np.array([draw.levels["observation_noise"] for draw in draws])
        assert sorted(np.floor(noise / 0.3 * episodes).astype(int)) == list(range(episodes))
    assert SPEC.selection_draws(system, 0, 3) != SPEC.selection_draws(system, 1, 3)
    # not the training episodes' stream
    assert SPEC.selection_draws(system, 0, 1)[0].levels != SPEC.episode(system, 0, 0).levels
    with pytest.raises(ValueError, match=r"^episodes: expected a positive int, found 0$"):
        SPEC.selection_draws(system, 0, 0)


def test_evaluating_on_plants_equals_one_simulate_per_plant() -> None:
    system = make_system("pendulum")
    controller = lqr_controller(design_lqr(system))
    starts = np.stack(
        [system.sample_start(np.random.default_rng(k), "operating_point") for k in range(3)]
    )
    spec = TrainingPerturbations(randomised={"actuator_gain": 0.9, "torque_noise": 0.5})
    plants = [draw.perturbations for draw in spec.selection_draws(system, 4, 3)]
    found = evaluate_on_plants(system, controller, starts, plants)
    for i, plant in enumerate(plants):
        alone = simulate(system, controller, starts[i : i + 1], perturbations=plant)
        assert found.returns[i] == pytest.approx(float(alone.total_rewards[0]), rel=1e-9)
        held = system.hold_step(alone.states[0, 1:], terminated=bool(alone.terminated[0]))
        assert found.hold_steps[i] == held
    nominal = evaluate_episodes(system, controller, starts)
    assert max(abs(a - b) for a, b in zip(found.returns, nominal.returns, strict=True)) > 1e-3
    with pytest.raises(ValueError, match=r"^plants: expected one per start \(3\), found 2$"):
        evaluate_on_plants(system, controller, starts, plants[:2])


class _Actor(torch.nn.Module):
    """A stand-in actor whose state records the step it was copied at."""

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("step", torch.zeros(()))


class _Model:
    def __init__(self) -> None:
        self.actor = _Actor()


def _scripted(nominal: dict[int, float], selection: dict[int, float], monkeypatch) -> dict:
    """Evaluations by step: the nominal curve's and the selection plants' held shares."""
    seen: dict[str, list[int]] = {"nominal": [], "selection": []}

    def evaluation(held: float) -> Evaluation:
        return Evaluation(held, 0.0, [held], [1 if held else None])

    def fake_nominal(system, policy, starts):
        step = int(policy.step)
        seen["nominal"].append(step)
        return evaluation(nominal[step])

    def fake_plants(system, policy, starts, plants):
        step = int(policy.step)
        seen["selection"].append(step)
        return evaluation(selection[step])

    monkeypatch.setattr(callbacks_module, "evaluate_episodes", fake_nominal)
    monkeypatch.setattr(callbacks_module, "evaluate_on_plants", fake_plants)
    monkeypatch.setattr(callbacks_module, "physical_policy", lambda actor: actor)
    return seen


@pytest.mark.parametrize("judged_on", ["nominal", "training"])
def test_the_callback_selects_on_the_selection_plants(judged_on, monkeypatch) -> None:
    nominal = {100: 0.0, 200: 1.0, 300: 0.0}  # the nominal curve prefers step 200
    selection = {100: 0.0, 200: 0.0, 300: 1.0}  # the randomised plants prefer step 300
    seen = _scripted(nominal, selection, monkeypatch)
    system = make_system("pendulum")
    plants = None if judged_on == "nominal" else [()]
    callback = LearningCurveCallback(
        system,
        np.zeros((1, 2)),
        100,
        progress=False,
        model_selection="best_held",
        selection_plants=plants,
    )
    callback.model = _Model()
    for step in (100, 200, 300):
        callback.model.actor.step.fill_(step)
        callback.num_timesteps = step
        callback._evaluate()
    assert callback.selected_steps == (200 if judged_on == "nominal" else 300)
    assert [row["held_fraction"] for row in callback.curve] == [0.0, 1.0, 0.0]  # the curve
    if judged_on == "training":
        assert [row["selection"]["held_fraction"] for row in callback.curve] == [0.0, 0.0, 1.0]
        assert seen["selection"] == [100, 200, 300]
    else:
        assert "selection" not in callback.curve[0] and not seen["selection"]
    callback.restore_selected()
    assert int(callback.model.actor.step) == callback.selected_steps
    with pytest.raises(ValueError, match=r"^selection_plants: expected one per evaluation start"):
        LearningCurveCallback(system, np.zeros((2, 2)), 100, selection_plants=[()])


def test_config_checks_and_records_the_selection_plants() -> None:
    randomised = {"randomised": {"actuator_gain": 0.48}}
    config = DDPGConfig.for_system(
        "pendulum", algo="sac", training_perturbations=randomised, selection_plants="training"
    )
    saved = json.loads(json.dumps(config.as_dict()))
    assert saved["selection_plants"] == "training"
    assert DDPGConfig.from_dict(saved) == config
    plain = DDPGConfig.for_system("pendulum", algo="sac", training_perturbations=randomised)
    assert "selection_plants" not in plain.as_dict()  # as every run before the field
    assert DDPGConfig.from_dict(plain.as_dict()).selection_plants == "nominal"
    assert CLI_CHOICES == SELECTION_PLANTS
    bad = [
        ({"selection_plants": "randomised"}, "selection_plants: expected one of"),
        ({}, "selection_plants: expected 'training' only with randomised training"),
        (
            {"training_perturbations": {"fixed": {"actuator_gain": 0.2}}},
            "selection_plants: expected 'training' only with randomised training",
        ),
        (
            {"training_perturbations": randomised, "model_selection": "final"},
            "selection_plants: expected 'nominal' with model_selection='final'",
        ),
    ]
    for fields, message in bad:
        with pytest.raises(ValueError, match=f"^{message}"):
            DDPGConfig.for_system("pendulum", **{"selection_plants": "training", **fields})


BAD_ARGUMENTS = [
    (
        ["--algo", "pilco", "--select-on", "nominal"],
        "--select-on: expected it only with --algo ddpg, td3, sac",
    ),
    (
        ["--algo", "sac", "--select-on", "training"],
        "--select-on: selection_plants: expected 'training' only with randomised training "
        "perturbations (leoc train --randomise",
    ),
    (
        ["--algo", "sac", "--select-on", "training", "--perturb", "actuator_gain=0.2"],
        "--select-on: selection_plants: expected 'training' only with randomised training "
        "perturbations (leoc train --randomise",
    ),
    (["--algo", "sac", "--select-on", "worst"], "argument --select-on: invalid choice: 'worst'"),
]


@pytest.mark.parametrize(("arguments", "message"), BAD_ARGUMENTS)
def test_bad_select_on_arguments_are_one_line_errors(arguments, message, train_refusal):
    err = train_refusal(arguments)
    assert message in err, err


def test_gym_runs_refuse_select_on(tmp_path, capsys) -> None:
    run = tmp_path / "run"
    code = main(
        ["train", "gym:Pendulum-v1", "--algo", "sac", "--select-on", "nominal", "--out", str(run)]
    )
    err = capsys.readouterr().err
    assert code == 2 and "--select-on: expected it only for a leoc system" in err, err
    assert not run.exists()


@pytest.mark.slow
@pytest.mark.usefixtures("single_thread")
def test_a_run_selecting_on_its_training_plants_saves_the_actor_it_judged(tmp_path, capsys) -> None:
    """A short SAC run under a random actuator gain trains exactly as the same run selecting on
    the nominal plant (the replay buffers and nominal curves agree); every row records its
    selection episodes;
    the selected step is the best of those records by the rule; the saved controller, run again
    on the same plants from the same starts, scores that record (the restored actor is the one
    judged)."""
    from leoc.experiments.controllers import load_trained_controller
    from leoc.sb3.train import train_ddpg

    spec = {"randomised": {"actuator_gain": 0.9}}
    runs = {
        judged_on: train_ddpg(
            "pendulum",
            algo="sac",
            seed=1,
            run_dir=tmp_path / judged_on,
            total_steps=600,
            learning_starts=100,
            eval_interval=100,
            eval_episodes=3,
            actor_hidden=(16, 16),
            critic_hidden=(16, 16),
            training_perturbations=spec,
            selection_plants=judged_on,
            progress=False,
        )
        for judged_on in ("nominal", "training")
    }
    result = runs["training"]
    # the selection episodes change nothing of the training: same transitions, same curve
    buffers = [run.model.replay_buffer for run in runs.values()]
    assert np.array_equal(buffers[0].observations, buffers[1].observations)
    assert np.array_equal(buffers[0].actions, buffers[1].actions)
    nominal_rows = [
        [(row["steps"], row["mean_return"]) for row in run.curve] for run in runs.values()
    ]
    assert nominal_rows[0] == nominal_rows[1]
    curve = json.loads((result.run_dir / "curve.json").read_text())
    rows = curve["curve"]
    assert all("selection" in row for row in rows)
    keys = [
        selection_key(
            "best_held", row["selection"]["mean_return"], row["selection"]["held_fraction"]
        )
        for row in rows
    ]
    best = max(range(len(rows)), key=lambda i: (keys[i], -i))  # the earliest on ties
    assert curve["summary"]["selected_steps"] == rows[best]["steps"]
    system = make_system("pendulum")
    plants = TrainingPerturbations.from_dict(spec).selection_draws(system, 1, 3)
    controller = load_trained_controller(result.run_dir, "pendulum")
    again = evaluate_on_plants(
        system, controller, evaluation_starts(system, 1, 3), [d.perturbations for d in plants]
    )
    np.testing.assert_allclose(again.returns, rows[best]["selection"]["returns"], rtol=1e-6)
    # the check can fail: the plants change the returns
    nominal = evaluate_episodes(system, controller, evaluation_starts(system, 1, 3))
    assert np.max(np.abs(np.subtract(nominal.returns, again.returns))) > 1e-3
    # leoc simulate says which plants chose the kept actor (JSON and text)
    for judged_on, run in runs.items():
        assert main(["simulate", str(run.run_dir), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["selection_plants"] == judged_on
        assert main(["simulate", str(run.run_dir)]) == 0
        said = "kept actor:         chosen on plants of the training distribution"
        assert (said in capsys.readouterr().out) == (judged_on == "training")


@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac"])
def test_a_profile_selects_on_training_plants_through_its_overrides(algo) -> None:
    """A study profile asks for the selection on training plants as ``leoc train --select-on
    training`` does: ``ddpg_overrides`` reach every model-free learner's config (TD3 takes
    DDPG's), next to the profile's randomised perturbations; PILCO's settings never get it."""
    from leoc.experiments.profiles import Profile
    from leoc.experiments.variants import get_variant
    from leoc.learners import ControllerSpec

    profile = Profile(
        "randomised",
        (0,),
        {},
        {},
        ddpg_overrides={"selection_plants": "training"},
        training_perturbations=SPEC.as_dict(),
    )
    leoc_variant = get_variant("leoc")
    settings = profile.training_settings(leoc_variant, ControllerSpec(algo), "pendulum")
    config = DDPGConfig.for_system("pendulum", **settings)
    assert config.selection_plants == "training"
    assert config.training_perturbations == SPEC.as_dict()
    pilco = profile.training_settings(leoc_variant, ControllerSpec("pilco"), "pendulum")
    assert "selection_plants" not in pilco
