"""Training on a gymnasium env itself (leoc.sb3.gym): the hybrid's gain on the observation, the
run folder contract (resume, rerun, refusal), the untrained hybrid against its LQR, the CLI."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
import torch

from leoc.cli import main
from leoc.gym_adapter import LQRPolicy, design_env_lqr, linearise_env
from leoc.policies.spec import HybridSpec
from leoc.sb3.gym import (
    GymEvaluationCallback,
    gym_hybrid_design,
    gym_plant,
    load_gym_controller,
    make_gym_env,
    sample_region,
    train_gym,
)

pytestmark = pytest.mark.usefixtures("single_thread")

#: Fixed observations the final models are compared on.
PROBES = np.random.default_rng(3).normal(scale=0.05, size=(16, 4))


def independent_lqr(env_id: str, size: int) -> np.ndarray:
    """K of the clipped LQR at the rest state, designed here with the adapter alone."""
    env = gym.make(env_id)
    return design_env_lqr(linearise_env(env, np.zeros(size), [0.0])).K


def test_pendulum_gain_acts_on_sine_without_mujoco():
    """Pendulum-v1 shows [cos, sin, theta_dot]: d obs / d state = [[0, 0], [1, 0], [0, 1]] at
    the upright, so W = -K M puts K's angle gain on the sine and none on the cosine."""
    env = gym.make("Pendulum-v1")
    with pytest.raises(ValueError, match="operating_point: expected"):
        gym_plant(env, "Pendulum-v1")
    plant = gym_plant(env, "Pendulum-v1", ([0.0, 0.0], [0.0]))
    K = design_env_lqr(linearise_env(gym.make("Pendulum-v1"), [0.0, 0.0], [0.0])).K
    np.testing.assert_allclose(plant.gain, [[0.0, -K[0, 0], -K[0, 1]]], atol=1e-8)
    np.testing.assert_allclose(plant.operating_obs, [1.0, 0.0, 0.0], atol=1e-12)
    assert plant.gain @ plant.operating_obs + plant.bias == pytest.approx([0.0], abs=1e-12)
    assert not plant.observation_is_state
    # Pendulum-v1 starts anywhere on the circle, where sin(theta) is far from theta: the map
    # back to the state is a local one, and its stated error says so (measured 0.90)
    assert 0.5 < plant.observation_error < 1.1
    with pytest.raises(ValueError, match="r_min=None"):  # the floor needs the state
        gym_hybrid_design(HybridSpec(), plant, lambda: None)
    free = gym_hybrid_design(HybridSpec(r_min=None), plant, lambda: None)
    assert free.relevance_data == {}


def test_double_pendulum_gain_is_the_lqr_to_first_order():
    """InvertedDoublePendulum-v5's observation, differentiated by hand at the upright: x, the
    two sines (slope 1), the cosines (slope 0), the three speeds, the constraint force (0 at
    rest); the gain on it composed with that Jacobian is -K."""
    pytest.importorskip("mujoco")
    env = make_gym_env("InvertedDoublePendulum-v5")
    plant = gym_plant(env, "InvertedDoublePendulum-v5")
    jacobian = np.zeros((9, 6))
    for row, column in ((0, 0), (1, 1), (2, 2), (5, 3), (6, 4), (7, 5)):
        jacobian[row, column] = 1.0
    K = independent_lqr("InvertedDoublePendulum-v5", 6)
    np.testing.assert_allclose(plant.gain @ jacobian, -K, atol=1e-8)
    np.testing.assert_allclose(plant.gain[0, [3, 4, 8]], 0.0, atol=1e-8)
    assert plant.jacobian_error < 1e-8
    assert not plant.observation_is_state
    with pytest.raises(ValueError, match="not the state"):
        gym_hybrid_design(HybridSpec("roa"), plant, lambda: None)


@pytest.fixture(scope="module")
def runs(tmp_path_factory, tiny_gym_settings):
    """A tiny SAC hybrid run on InvertedPendulum-v5, and the same run interrupted after its
    checkpoint at step 200 and resumed."""
    pytest.importorskip("mujoco")
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("gym")
    whole = train_gym(
        "InvertedPendulum-v5", "sac", True, 0, root / "whole", 400, **tiny_gym_settings
    )
    original = GymEvaluationCallback._on_step

    def interrupt(self):
        if self.num_timesteps == 300:
            raise KeyboardInterrupt
        return original(self)

    GymEvaluationCallback._on_step = interrupt
    try:
        with pytest.raises(KeyboardInterrupt):
            train_gym("InvertedPendulum-v5", "sac", True, 0, root / "cut", 400, **tiny_gym_settings)
    finally:
        GymEvaluationCallback._on_step = original
    assert (root / "cut" / "checkpoint.pkl").is_file()
    resumed = train_gym(
        "InvertedPendulum-v5", "sac", True, 0, root / "cut", 400, **tiny_gym_settings
    )
    return whole, resumed


@pytest.mark.slow
def test_hybrid_run_is_its_lqr_at_the_operating_point(runs):
    """The trained hybrid's float64 actor at a = 0 outputs u_eq = 0 and its Jacobian there is
    W = -K of an independent design (autograd), whatever SAC learned."""
    whole, _ = runs
    K = independent_lqr("InvertedPendulum-v5", 4)
    point = torch.zeros(1, 4, dtype=torch.float64)
    assert whole.policy(point).item() == pytest.approx(0.0, abs=1e-12)
    jacobian = torch.autograd.functional.jacobian(lambda x: whole.policy(x), point)
    np.testing.assert_allclose(jacobian.reshape(1, 4).numpy(), -K, rtol=1e-9, atol=1e-12)
    design = json.loads((whole.run_dir / "design.json").read_text())
    assert design["relevance_data"]["region"] == "sampled"
    assert design["relevance_data"]["rho"] > 0.0


def test_resumed_run_equals_uninterrupted_and_rerun_is_a_no_op(runs, tiny_gym_settings):
    whole, resumed = runs
    controller = load_gym_controller(whole.run_dir)
    again = load_gym_controller(resumed.run_dir)
    np.testing.assert_allclose(controller(PROBES), again(PROBES), atol=1e-6, rtol=0.0)
    assert [row["returns"] for row in whole.curve] == [row["returns"] for row in resumed.curve]
    assert not (resumed.run_dir / "checkpoint.pkl").exists()
    for name in ("config.json", "model.zip", "curve.json", "curve.csv", "learning_curve.png"):
        assert (whole.run_dir / name).is_file()
    stamp = (whole.run_dir / "model.zip").stat().st_mtime_ns
    rerun = train_gym(
        "InvertedPendulum-v5", "sac", True, 0, whole.run_dir, 400, **tiny_gym_settings
    )
    assert (whole.run_dir / "model.zip").stat().st_mtime_ns == stamp
    assert rerun.curve == json.loads((whole.run_dir / "curve.json").read_text())["curve"]
    with pytest.raises(ValueError, match="another configuration"):
        train_gym("InvertedPendulum-v5", "sac", True, 0, whole.run_dir, 500, **tiny_gym_settings)


def lqr_held(env_id: str, seeds: list[int], steps: int) -> float:
    """Share of the seeded default starts the clipped LQR alone holds for ``steps`` steps."""
    env = gym.make(env_id, max_episode_steps=steps)
    policy = LQRPolicy(design_env_lqr(linearise_env(env, np.zeros(4), [0.0])))
    held = []
    for seed in seeds:
        observation, _ = env.reset(seed=seed)
        while True:
            observation, _, terminated, truncated, _ = env.step(policy(observation))
            if terminated or truncated:
                held.append(not terminated)
                break
    return float(np.mean(held))


def test_untrained_hybrid_holds_like_its_lqr(runs, tiny_gym_settings):
    """Step 0 of the curve (before any update): the hybrid holds every seeded default start,
    as the LQR alone does; there r is within 1e-6 of 1 (measured over 100 default starts:
    1 - r <= 6.8e-8 with the default floored relevance, 6.3e-4 with the paper's), so the
    learned part barely acts: a hold there is the LQR's, not evidence of learning."""
    whole, _ = runs
    first = whole.curve[0]
    assert first["steps"] == 0
    seeds = [10_000 + k for k in range(tiny_gym_settings["eval_episodes"])]
    assert first["held_fraction"] == lqr_held("InvertedPendulum-v5", seeds, 60) == 1.0
    env = gym.make("InvertedPendulum-v5")
    starts = torch.as_tensor(np.array([env.reset(seed=s)[0] for s in seeds]))
    actor = whole.model.actor
    relevance = actor.hybrid.relevance(starts.to(torch.float32))
    assert torch.all(relevance > 1.0 - 1e-6)


def test_sampled_region_is_not_vacuous():
    """The sampled level is positive and seeded (the same again), and starts at 100 times it
    (ten times the deviation) are not all held by the LQR: the level means something."""
    pytest.importorskip("mujoco")
    env = make_gym_env("InvertedPendulum-v5")
    plant = gym_plant(env, "InvertedPendulum-v5")
    region = sample_region(env, plant.lqr, samples=4, steps=150)
    assert region.certified and region.rho > 0.0
    assert sample_region(env, plant.lqr, samples=4, steps=150).rho == region.rho
    policy = LQRPolicy(plant.lqr)
    directions = np.random.default_rng(5).standard_normal((16, 4))
    fallen = 0
    for direction in directions:
        start = direction * np.sqrt(100.0 * region.rho / (direction @ plant.lqr.P @ direction))
        env.reset(seed=0)
        env.unwrapped.set_state(start[:2], start[2:])
        observation = env.unwrapped._get_obs()
        for _ in range(150):
            observation, _, terminated, _, _ = env.step(policy(observation))
            if terminated:
                fallen += 1
                break
    assert fallen > 0


def test_cli_refuses_unknown_env_and_pilco(capsys):
    assert main(["train", "gym:NoSuchEnv-v0", "--algo", "sac", "--quiet", "--steps", "10"]) == 2
    err = capsys.readouterr().err
    assert "expected a gymnasium id" in err and len(err.strip().splitlines()) == 1
    assert main(["train", "gym:Pendulum-v1", "--algo", "pilco"]) == 2
    assert "PILCO needs a leoc system" in capsys.readouterr().err
    assert main(["train", "gym:Pendulum-v1", "--algo", "sac", "--steps", "10"]) == 2
    assert "operating_point: expected" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_trains_a_gym_hybrid(tmp_path, capsys):
    pytest.importorskip("mujoco")
    out = tmp_path / "run"
    argv = ["train", "gym:InvertedPendulum-v5", "--algo", "sac", "--hybrid", "--r-min", "none"]
    assert main([*argv, "--steps", "250", "--out", str(out), "--quiet"]) == 0
    assert f"run folder: {out}" in capsys.readouterr().out
    config = json.loads((out / "config.json").read_text())
    assert config["system"] == "gym:InvertedPendulum-v5" and config["hybrid"]["r_min"] is None
    curve = json.loads((out / "curve.json").read_text())["curve"]
    assert [row["steps"] for row in curve] == [0, 250]
    assert load_gym_controller(out)(np.zeros(4)) == pytest.approx([0.0], abs=1e-12)
