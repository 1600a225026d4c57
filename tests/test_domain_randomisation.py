"""Training under perturbation (issue 43, item 4): fixed levels and domain randomisation.

What is checked: each training episode's levels are the documented seeded uniform draw
(recomputed here with numpy alone) and uniform over many episodes; the environment builds each
episode's own plant; randomisation at level 0 trains exactly as the nominal plant does (DDPG
family and PILCO); the perturbation reaches the training data (a dead actuator: every recorded
transition is the unforced plant's); the saved config round-trips and tells the evaluations how
the run was trained, while they stay on the nominal plant; an interrupted run resumes to the
uninterrupted result, plants included; bad arguments are one-line errors naming the flag.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback

from leoc.cli import main
from leoc.experiments.controllers import trained_perturbations
from leoc.pilco.config import PilcoConfig
from leoc.pilco.train import train_pilco
from leoc.sb3.checkpoint import CHECKPOINT_FILE
from leoc.sb3.config import DDPGConfig
from leoc.sb3.train import train_ddpg
from leoc.systems import (
    RANDOMISATION_STREAM,
    EpisodePlants,
    TrainingPerturbations,
    category_perturbations,
    make_env,
    make_system,
)
from leoc.training import TRAINING_PLANTS_FILE

#: Slow suite: the module's fixtures train perturbed runs (about 80 s).
pytestmark = [pytest.mark.slow, pytest.mark.usefixtures("single_thread")]

# the bookkeeping, not learning: small networks, a few hundred steps (an episode is 200)
TINY = {
    "total_steps": 300,
    "learning_starts": 50,
    "eval_interval": 100,
    "eval_episodes": 1,
    "actor_hidden": (16, 16),
    "critic_hidden": (16, 16),
    "checkpoint_interval": 100,
    "progress": False,
}
STOP_AT = 250  # between the checkpoints at 200 and 300, in the second episode
# PILCO: two random rollouts (real rollouts 0 and 1) and one iteration (rollout 2)
PILCO_TINY = {
    "horizon": 10,
    "num_basis": 5,
    "policy_iterations": 3,
    "initial_rollouts": 2,
    "iterations": 1,
    "eval_episodes": 1,
    "progress": False,
}
#: Every category at a maximum of 0: the nominal plant in every episode.
ZERO = {
    "randomised": {
        "observation_noise": 0.0,
        "action_delay": 0,
        "actuator_gain": 0.0,
        "torque_noise": 0.0,
        "viscous_friction": 0.0,
        "coulomb_friction": 0.0,
        "parameter_error.gravity": 0.0,
        "push": 0.0,
    }
}
DEAD_ACTUATOR = {"fixed": {"actuator_gain": -1.0}}  # gain - 1 = -1: the motor gives nothing
RANDOMISED = {"fixed": {"torque_noise": 0.1}, "randomised": {"observation_noise": 0.3}}
# sample statistics within this many standard errors (a false alarm: about 1 in 1.7 million)
SIGMAS = 5.0
DRAWS = 4000
SAME = 1e-12  # a recomputed level agrees to rounding


def _independent_levels(seed: int, episode: int, spec: TrainingPerturbations) -> tuple[dict, int]:
    """Episode ``episode``'s levels and noise seed by the documented rule, numpy alone."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, RANDOMISATION_STREAM, episode]))
    uniforms = rng.random(len(spec.randomised))
    noise_seed = int(rng.integers(2**32))
    levels = dict(spec.fixed)
    for (key, maximum), u in zip(spec.randomised, uniforms, strict=True):
        category = key.split(".")[0]
        if category == "action_delay":
            levels[key] = float(min(int(u * (maximum + 1)), maximum))
        elif category in ("actuator_gain", "parameter_error"):
            levels[key] = -maximum + 2.0 * maximum * u
        else:
            levels[key] = maximum * u
    return levels, noise_seed


def test_each_episode_draws_the_documented_seeded_levels() -> None:
    system = make_system("pendulum")
    spec = TrainingPerturbations(
        fixed={"torque_noise": 0.2},
        randomised={
            "push": 1.0,  # out of category order on purpose: the spec sorts its entries
            "observation_noise": 0.5,
            "action_delay": 3,
            "actuator_gain": 0.4,
            "parameter_error.mass": 0.3,
        },
    )
    assert [key for key, _ in spec.randomised][0] == "observation_noise"
    for episode in range(30):
        drawn = spec.episode(system, 11, episode)
        levels, noise_seed = _independent_levels(11, episode, spec)
        assert drawn.levels == pytest.approx(levels, rel=SAME, abs=SAME)
        assert drawn.seed == noise_seed
        expected = []
        for key, level in drawn.levels.items():
            category, _, constant = key.partition(".")
            expected += category_perturbations(
                system, category, level, noise_seed, 1, constant or None
            )
        assert sorted(map(repr, drawn.perturbations)) == sorted(map(repr, expected))
    # another run seed, another stream
    assert spec.episode(system, 12, 0).levels != spec.episode(system, 11, 0).levels


def test_the_drawn_levels_are_uniform_over_many_episodes() -> None:
    """Over DRAWS episodes: a one-sided level's mean m/2 and variance m^2/12, a two-sided one's
    0 and m^2/3, a delay's every whole step equally often, each within SIGMAS standard errors."""
    system = make_system("pendulum")
    high = {"observation_noise": 0.6, "actuator_gain": 0.5, "action_delay": 3}
    spec = TrainingPerturbations(randomised=high)
    drawn = [spec.episode(system, 3, k).levels for k in range(DRAWS)]
    for key, low, top in (("observation_noise", 0.0, 0.6), ("actuator_gain", -0.5, 0.5)):
        values = np.array([levels[key] for levels in drawn])
        width = top - low
        mean, variance = (low + top) / 2, width**2 / 12
        fourth = width**4 / 80  # central fourth moment of a uniform
        assert values.min() >= low and values.max() <= top
        assert abs(values.mean() - mean) < SIGMAS * math.sqrt(variance / DRAWS)
        spread = math.sqrt((fourth - variance**2) / DRAWS)
        assert abs(values.var() - variance) < SIGMAS * spread, key
    delays = np.array([levels["action_delay"] for levels in drawn])
    counts = np.bincount(delays.astype(int), minlength=4)
    share = 1 / 4
    assert len(counts) == 4
    assert np.all(np.abs(counts - DRAWS * share) < SIGMAS * math.sqrt(DRAWS * share * (1 - share)))


def test_the_environment_builds_each_episode_its_own_plant() -> None:
    system = make_system("pendulum")
    spec = TrainingPerturbations(fixed={"torque_noise": 0.2}, randomised=RANDOMISED["randomised"])
    env = make_env(system, plants=EpisodePlants(spec, system, seed=5))
    # unbounded where some episode is noisy (the velocity), bounded elsewhere
    assert np.isinf(env.observation_space.high[2]) and np.all(env.observation_space.high[:2] == 1)
    seeds = set()
    for episode in range(4):
        env.reset(seed=9 if episode == 0 else None)
        drawn = spec.episode(system, 5, episode)
        assert env.unwrapped.plant.perturbations == drawn.perturbations
        seeds.add(drawn.seed)
        env.step(np.zeros(1))
    assert len(seeds) == 4  # fresh noise in every episode, the fixed torque noise's too
    assert env.unwrapped.plants.episodes == 4


def _buffer(result) -> dict[str, np.ndarray]:
    """The transitions a DDPG-family run stored."""
    buffer = result.model.replay_buffer
    size = buffer.buffer_size if buffer.full else buffer.pos
    names = ("observations", "actions", "next_observations", "rewards", "dones")
    return {name: getattr(buffer, name)[:size, 0].copy() for name in names}


@pytest.fixture(scope="module")
def sb3_runs(tmp_path_factory) -> dict:
    """TD3 baseline runs of one seed: nominal, randomised at level 0, with a dead actuator (the
    hybrids' path is the workflow matrix's: a hybrid's first run proves its LQR's region)."""
    root = tmp_path_factory.mktemp("sb3")
    settings = {"nominal": {}, "zero": ZERO, "dead": DEAD_ACTUATOR}
    return {
        name: train_ddpg(
            "pendulum",
            algo="td3",
            seed=2,
            run_dir=root / name,
            training_perturbations=perturbations,
            **TINY,
        )
        for name, perturbations in settings.items()
    }


def test_level_zero_randomisation_trains_as_the_nominal_plant_bit_for_bit(sb3_runs) -> None:
    nominal, zero = _buffer(sb3_runs["nominal"]), _buffer(sb3_runs["zero"])
    for name, values in nominal.items():
        assert np.array_equal(values, zero[name]), name
    parameters = [
        torch.nn.utils.parameters_to_vector(sb3_runs[run].model.policy.parameters())
        for run in ("nominal", "zero")
    ]
    assert torch.equal(*parameters)
    assert sb3_runs["zero"].curve == sb3_runs["nominal"].curve


def _pendulum_states(observations: np.ndarray) -> torch.Tensor:
    """Pendulum states [theta, theta_dot] of observations [cos, sin, theta_dot]."""
    theta = np.arctan2(observations[:, 1], observations[:, 0])
    return torch.as_tensor(np.stack([theta, observations[:, 2]], axis=1), dtype=torch.float64)


def _unforced_next(observations: np.ndarray, steps: int = 1) -> np.ndarray:
    """The pendulum's observations after ``steps`` unforced steps from ``observations``."""
    system = make_system("pendulum")
    state = _pendulum_states(observations)
    for _ in range(steps):
        state = system.step_fn(state, torch.zeros(len(state), 1, dtype=torch.float64))
    return system.observe(state).numpy()


def test_a_dead_actuator_reaches_every_recorded_transition(sb3_runs) -> None:
    dead, nominal = _buffer(sb3_runs["dead"]), _buffer(sb3_runs["nominal"])
    assert np.abs(dead["actions"]).max() > 0.1  # the agent asked for torque ...
    unforced = _unforced_next(dead["observations"])
    np.testing.assert_allclose(
        dead["next_observations"], unforced, rtol=0, atol=1e-9
    )  # ... none came
    # the check can fail: the nominal run's transitions are forced
    assert (
        np.abs(nominal["next_observations"] - _unforced_next(nominal["observations"])).max() > 1e-3
    )


def test_the_config_records_the_perturbations_and_the_evaluation_stays_nominal(sb3_runs) -> None:
    dead = sb3_runs["dead"]
    saved = json.loads((dead.run_dir / "config.json").read_text())
    spec = TrainingPerturbations.from_dict(DEAD_ACTUATOR)
    assert saved["training_perturbations"] == spec.as_dict()
    assert trained_perturbations(dead.run_dir) == spec
    assert DDPGConfig.from_dict(saved).training_perturbations == spec.as_dict()
    nominal = json.loads((sb3_runs["nominal"].run_dir / "config.json").read_text())
    assert "training_perturbations" not in nominal  # a nominal run's config is as before
    assert trained_perturbations(sb3_runs["nominal"].run_dir).is_nominal
    record = json.loads((dead.run_dir / TRAINING_PLANTS_FILE).read_text())
    assert record["episodes"] == [{"actuator_gain": -1.0}] * 2  # 300 steps: two episodes begun
    assert not (sb3_runs["nominal"].run_dir / TRAINING_PLANTS_FILE).exists()


def test_simulate_says_how_a_run_was_trained_and_runs_it_on_the_nominal_plant(
    sb3_runs, capsys
) -> None:
    runs = {name: sb3_runs[name].run_dir for name in ("dead", "zero")}
    printed = {}
    for name, run in runs.items():
        assert main(["simulate", str(run), "--json"]) == 0
        printed[name] = json.loads(capsys.readouterr().out)
    assert printed["dead"]["training_perturbations"] == {
        "fixed": {"actuator_gain": -1.0},
        "randomised": {},
    }
    assert main(["simulate", str(runs["dead"])]) == 0
    assert (
        "trained under:      actuator_gain fixed at -1 (simulated on the nominal plant)"
        in capsys.readouterr().out
    )
    # on the nominal plant the dead-actuator run's controller does move the pendulum
    from leoc.evaluation.rollout import response_test
    from leoc.experiments.controllers import load_trained_controller, trained_plant

    plant = trained_plant(runs["dead"])
    expected = response_test(plant, load_trained_controller(runs["dead"])).deviation
    np.testing.assert_allclose(printed["dead"]["deviation"], expected, rtol=0, atol=1e-12)


class StopAt(BaseCallback):
    """Interrupts training (as Ctrl-C does) once ``steps`` environment steps are done."""

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps = steps

    def _on_step(self) -> bool:
        if self.num_timesteps == self.steps:
            raise KeyboardInterrupt
        return True


def test_an_interrupted_randomised_run_resumes_to_the_uninterrupted_result(tmp_path) -> None:
    """Interrupted in its second episode and rerun, the run meets the same plants and ends
    with the same weights, curve and record of plants as the run never interrupted."""
    common = {"algo": "sac", "seed": 4, "training_perturbations": RANDOMISED}
    whole = train_ddpg("pendulum", run_dir=tmp_path / "whole", **common, **TINY)
    cut = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        train_ddpg("pendulum", run_dir=cut, callbacks=[StopAt(STOP_AT)], **common, **TINY)
    assert (cut / CHECKPOINT_FILE).is_file()
    resumed = train_ddpg("pendulum", run_dir=cut, **common, **TINY)
    for name, values in _buffer(whole).items():
        assert np.array_equal(values, _buffer(resumed)[name]), name
    assert resumed.curve == whole.curve
    plants = [
        json.loads((folder / TRAINING_PLANTS_FILE).read_text())
        for folder in (cut, tmp_path / "whole")
    ]
    assert plants[0] == plants[1] and len(plants[0]["episodes"]) == 2
    spec = TrainingPerturbations.from_dict(RANDOMISED)
    system = make_system("pendulum")
    assert plants[0]["episodes"] == [spec.episode(system, 4, k).levels for k in range(2)]


def _pilco_data(run) -> dict[str, np.ndarray]:
    """The GP data of a PILCO run (its checkpoint's inputs and targets)."""
    saved = torch.load(run / "checkpoint.pt", weights_only=False)
    return {"inputs": np.asarray(saved["inputs"]), "targets": np.asarray(saved["targets"])}


@pytest.fixture(scope="module")
def pilco_runs(tmp_path_factory) -> dict:
    """PILCO baseline runs of one seed: nominal, randomised at level 0, a dead actuator."""
    root = tmp_path_factory.mktemp("pilco")
    settings = {"nominal": {}, "zero": ZERO, "dead": DEAD_ACTUATOR}
    return {
        name: train_pilco(
            "pendulum",
            seed=1,
            run_dir=root / name,
            training_perturbations=perturbations,
            resume=False,
            **PILCO_TINY,
        )
        for name, perturbations in settings.items()
    }


def test_pilco_level_zero_randomisation_gives_the_nominal_data(pilco_runs) -> None:
    nominal, zero = (_pilco_data(pilco_runs[name].run_dir) for name in ("nominal", "zero"))
    for name in nominal:
        assert np.array_equal(nominal[name], zero[name]), name
    assert pilco_runs["zero"].curve[-1]["returns"] == pilco_runs["nominal"].curve[-1]["returns"]


def test_pilco_data_come_from_the_perturbed_plant(pilco_runs) -> None:
    """Every rollout's GP targets, random rollouts and the iteration's alike, are the unforced
    plant's state changes over PILCO's period; the nominal run's are not."""
    repeat = PilcoConfig.for_system("pendulum").action_repeat
    for name, dead in (("dead", True), ("nominal", False)):
        data = _pilco_data(pilco_runs[name].run_dir)
        observations = data["inputs"][:, :3]
        assert len(observations) == 3 * (200 // repeat)  # three rollouts' complete decisions
        start = _pendulum_states(observations).numpy()
        after = _pendulum_states(_unforced_next(observations, repeat)).numpy()
        unforced = after - start
        unforced[:, 0] = (unforced[:, 0] + np.pi) % (2 * np.pi) - np.pi  # atan2 wrapped theta
        error = np.abs(data["targets"] - unforced).max()
        assert (error < 1e-9) if dead else (error > 1e-3), (name, error)
    saved = json.loads((pilco_runs["dead"].run_dir / "config.json").read_text())
    assert (
        PilcoConfig.from_dict(saved).training_perturbations
        == TrainingPerturbations.from_dict(DEAD_ACTUATOR).as_dict()
    )
    record = json.loads((pilco_runs["dead"].run_dir / TRAINING_PLANTS_FILE).read_text())
    assert len(record["episodes"]) == 3  # two random rollouts and the iteration's


def test_an_extended_pilco_run_meets_the_plants_of_a_run_made_at_once(tmp_path) -> None:
    """PILCO's rollout k meets episode k's plant whatever ran before: a run extended from one
    iteration to two has the data of a two-iteration run."""
    common = {**PILCO_TINY, "training_perturbations": RANDOMISED, "seed": 2}
    del common["iterations"]
    train_pilco("pendulum", run_dir=tmp_path / "cut", iterations=1, **common)
    train_pilco("pendulum", run_dir=tmp_path / "cut", iterations=2, **common)
    train_pilco("pendulum", run_dir=tmp_path / "whole", iterations=2, **common)
    cut, whole = (_pilco_data(tmp_path / name) for name in ("cut", "whole"))
    for name in cut:
        assert np.array_equal(cut[name], whole[name]), name
    plants = [
        json.loads((tmp_path / name / TRAINING_PLANTS_FILE).read_text())
        for name in ("cut", "whole")
    ]
    assert plants[0] == plants[1] and len(plants[0]["episodes"]) == 4


def test_configs_check_and_sort_what_they_record() -> None:
    given = {"randomised": {"push": 1.0, "actuator_gain": 0.5}, "fixed": {"observation_noise": 0.1}}
    config = DDPGConfig.for_system("pendulum", training_perturbations=given)
    assert list(config.as_dict()["training_perturbations"]["randomised"]) == [
        "actuator_gain",
        "push",
    ]
    assert DDPGConfig.from_dict(json.loads(json.dumps(config.as_dict()))) == config
    pilco = PilcoConfig.for_system("cartpole", training_perturbations=given)
    assert PilcoConfig.from_dict(json.loads(json.dumps(pilco.to_dict()))) == pilco
    assert "training_perturbations" not in PilcoConfig.for_system("cartpole").to_dict()
    with pytest.raises(
        ValueError, match=r"^training_perturbations: randomised: parameter_error\.weight: "
    ):
        PilcoConfig.for_system(
            "pendulum", training_perturbations={"randomised": {"parameter_error.weight": 0.1}}
        )
    with pytest.raises(ValueError, match=r"^training_perturbations: expected a mapping with keys"):
        DDPGConfig.for_system("pendulum", training_perturbations={"fixd": {}})


def test_a_profile_may_train_under_perturbation_and_the_flags_replace_it() -> None:
    from leoc.cli import build_parser
    from leoc.cli.train import run_settings
    from leoc.experiments.profiles import PROFILES, Profile
    from leoc.experiments.variants import get_variant
    from leoc.learners import ControllerSpec

    assert all(not profile.training_perturbations for profile in PROFILES.values())
    profile = Profile("noisy", (0,), {}, {}, training_perturbations=RANDOMISED)
    settings = profile.training_settings(get_variant("leoc"), ControllerSpec("td3"), "pendulum")
    assert settings["training_perturbations"] == RANDOMISED
    assert "training_perturbations" not in PROFILES["smoke"].training_settings(
        get_variant("leoc"), ControllerSpec("td3"), "pendulum"
    )
    command = ["train", "pendulum", "--algo", "td3", "--profile", "smoke"]
    args = build_parser().parse_args([*command, "--perturb", "actuator_gain=-0.5"])
    assert run_settings(args)["training_perturbations"] == {
        "fixed": {"actuator_gain": -0.5},
        "randomised": {},
    }


BAD_ARGUMENTS = [
    (["--perturb", "observation_noise"], "argument --perturb: expected CATEGORY=LEVEL"),
    (
        ["--randomise", "push=lots"],
        "argument --randomise/--randomize: expected CATEGORY=LEVEL with LEVEL a number",
    ),
    (["--perturb", "wind=1"], "--perturb: expected a category among observation_noise"),
    (
        ["--perturb", "torque_noise=-0.1"],
        "--perturb: torque_noise: expected a level >= 0, found -0.1",
    ),
    (
        ["--randomise", "actuator_gain=1.5"],
        "--randomise: actuator_gain: expected a maximum in [0, 1] (a gain >= 0)",
    ),
    (["--perturb", "actuator_gain=-1.2"], "--perturb: actuator_gain: expected a level in [-1, 1]"),
    (
        ["--randomise", "parameter_error.mass=1"],
        "expected a maximum in [0, 1) (a factor > 0), found 1.0",
    ),
    (
        ["--perturb", "parameter_error=0.2"],
        "--perturb: parameter_error: expected parameter_error.CONSTANT",
    ),
    (
        ["--perturb", "parameter_error.weight=0.2"],
        "--perturb: parameter_error.weight: scaled(): unknown parameter 'weight'",
    ),
    (["--perturb", "parameter_error.dt=0.2"], "changes the time step or the actuator limit"),
    (
        ["--perturb", "action_delay=1.5"],
        "--perturb: action_delay: expected whole simulator steps, found 1.5",
    ),
    (
        ["--randomise", "action_delay=900"],
        "--randomise: action_delay: expected at most an episode (200 steps)",
    ),
    (["--perturb", "push=inf"], "--perturb: push: expected a level >= 0, found inf"),
    (
        ["--randomise", "push=1", "--randomize", "push=2"],
        "--randomise: expected each category once, found ['push'] twice",
    ),
    (["--perturb", "push=1", "--randomise", "push=2"], "--randomise: push: also fixed"),
]


@pytest.mark.parametrize(("arguments", "message"), BAD_ARGUMENTS)
def test_bad_perturbation_arguments_are_one_line_errors(arguments, message, train_refusal):
    err = train_refusal(["--algo", "td3", *arguments])
    assert message in err, err
