"""Impulse and step responses on a gymnasium env itself (leoc.evaluation.gym_response) and
``leoc simulate`` / ``leoc roa`` on a gymnasium run, against hand-written loops."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from leoc.cli import main
from leoc.evaluation.gym_response import gym_response, lqr_controller
from leoc.evaluation.metrics import response_metrics
from leoc.gym_adapter import design_env_lqr, linearise_env
from leoc.sb3.gym import gym_plant, make_gym_env, train_gym

pytestmark = pytest.mark.usefixtures("single_thread")


def hand_impulse(steps: int, impulse: float) -> tuple[np.ndarray, bool]:
    """InvertedPendulum-v5 from the rest state: the first action forced to ``impulse``, then
    u = clip(-K x) of an independent design, on the env's own observation (its state)."""
    K = design_env_lqr(linearise_env(gym.make("InvertedPendulum-v5"), np.zeros(4), [0.0])).K
    env = gym.make("InvertedPendulum-v5", max_episode_steps=steps)
    env.reset(seed=0)
    env.unwrapped.set_state(np.zeros(2), np.zeros(2))
    states = [np.concatenate([env.unwrapped.data.qpos, env.unwrapped.data.qvel])]
    action = np.array([impulse])
    while True:
        observation, _, terminated, truncated, _ = env.step(action)
        states.append(np.concatenate([env.unwrapped.data.qpos, env.unwrapped.data.qvel]))
        action = np.clip(-K @ observation, -3.0, 3.0)
        if terminated or truncated:
            return np.stack(states), terminated


def test_lqr_impulse_equals_a_hand_written_loop():
    """The module's impulse response of the LQR alone is the hand loop's, state by state, and
    its metrics are leoc's functions of the hand loop's pole angle in degrees."""
    pytest.importorskip("mujoco")
    plant = gym_plant(make_gym_env("InvertedPendulum-v5"), "InvertedPendulum-v5")
    result = gym_response(plant, lqr_controller(plant), "impulse", steps=300)
    states, terminated = hand_impulse(300, 3.0)
    assert result.states.shape == states.shape == (301, 4)
    np.testing.assert_allclose(result.states, states, rtol=0.0, atol=1e-12)
    angle = np.degrees(states[:, 1])
    np.testing.assert_allclose(result.deviation, angle, rtol=0.0, atol=1e-12)
    expected = response_metrics(angle, dt=0.04, terminated=terminated)
    for name, value in expected._asdict().items():  # the wrap to (-180, 180] rounds
        assert getattr(result.metrics, name) == pytest.approx(value, rel=1e-12, abs=1e-12)
    assert result.unit == "deg" and result.main_index == 1 and not result.terminated
    assert 1.0 < result.metrics.peak_deviation < 20.0  # the impulse moved the pole


def pendulum_controller(observation: np.ndarray) -> np.ndarray:
    """Not a stabiliser: a constant push and some damping, so the pendulum swings."""
    return np.clip([0.5 - 0.1 * observation[2]], -2.0, 2.0)


def hand_run(steps: int, offset: float) -> np.ndarray:
    """Pendulum-v1 from the upright, ``pendulum_controller`` plus ``offset`` on every step."""
    env = gym.make("Pendulum-v1", max_episode_steps=steps)
    env.reset(seed=0)
    env.unwrapped.state = np.array([0.0, 0.0])
    observation = env.unwrapped._get_obs()
    states = [np.array(env.unwrapped.state)]
    for _ in range(steps):
        action = np.clip(pendulum_controller(observation) + offset, -2.0, 2.0)
        observation, *_ = env.step(action)
        states.append(np.array(env.unwrapped.state))
    return np.stack(states)


def test_zero_step_is_the_unperturbed_run_and_a_step_adds_its_offset():
    """Without MuJoCo: a step of 0 is exactly the unperturbed run (the action passed in the
    controller's float32, as Pendulum-v1 computes in it); a step of 0.3 is the hand loop with
    0.3 added to (and clipped with) every action; theta is recorded in degrees, wrapped."""
    plant = gym_plant(gym.make("Pendulum-v1"), "Pendulum-v1", ([0.0, 0.0], [0.0]))
    zero = gym_response(plant, pendulum_controller, "step", steps=80, magnitude=0.0)
    unperturbed = hand_run(80, 0.0)
    np.testing.assert_array_equal(zero.states, unperturbed)
    wrapped = np.degrees(np.arctan2(np.sin(unperturbed[:, 0]), np.cos(unperturbed[:, 0])))
    assert np.max(np.abs(unperturbed[:, 0])) > np.pi  # it swung over: the wrap matters
    np.testing.assert_allclose(zero.deviation, wrapped, rtol=0.0, atol=1e-9)
    pushed = gym_response(plant, pendulum_controller, "step", steps=80, magnitude=0.3)
    expected = hand_run(80, 0.3)
    # the controller's float32 action plus 0.3, rounded to float32 once or twice: 1e-7 apart
    np.testing.assert_allclose(pushed.states, expected, rtol=0.0, atol=1e-5)
    assert not np.array_equal(zero.states, pushed.states)
    default = gym_response(plant, pendulum_controller, "step", steps=5)
    assert default.magnitude.tolist() == [pytest.approx(0.2)]  # 10% of the limit 2


def test_bad_options_are_one_line_errors():
    plant = gym_plant(gym.make("Pendulum-v1"), "Pendulum-v1", ([0.0, 0.0], [0.0]))
    with pytest.raises(ValueError, match=r"main_index: expected a state index in \[0, 1\]"):
        gym_response(plant, pendulum_controller, main_index=2)
    with pytest.raises(ValueError, match="magnitude: expected an impulse action inside"):
        gym_response(plant, pendulum_controller, "impulse", magnitude=5.0)
    with pytest.raises(ValueError, match="test: expected one of"):
        gym_response(plant, pendulum_controller, "ramp")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, tiny_gym_settings):
    """A tiny SAC hybrid run on InvertedPendulum-v5 (120-step episodes, one evaluation
    episode)."""
    pytest.importorskip("mujoco")
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("gymsim") / "run"
    tiny = {**tiny_gym_settings, "env_kwargs": {"max_episode_steps": 120}, "eval_episodes": 1}
    train_gym("InvertedPendulum-v5", "sac", True, 0, folder, 250, **tiny)
    torch.set_num_threads(threads)
    return folder


@pytest.mark.slow
def test_cli_simulates_a_gym_run_beside_its_lqr(run_dir, capsys):
    assert main(["simulate", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert "impulse response" in out and "120 steps" in out
    for label in ("steady-state error", "overshoot", "peak deviation", "settling time"):
        assert label in out
    assert "largest difference from the LQR" in out
    assert main(["simulate", "gym:InvertedPendulum-v5", "--controller", str(run_dir)]) == 0
    assert capsys.readouterr().out == out
    argv = ["simulate", str(run_dir), "--test", "step", "--steps", "60", "--json"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["controller"] == str(run_dir) and report["test"] == "step"
    assert len(report["trained"]["deviation"]) == len(report["lqr"]["deviation"]) == 61
    assert report["magnitude"] == [pytest.approx(0.3)] and report["unit"] == "deg"
    assert report["distance_pct"] >= 0.0
    assert main(["simulate", "gym:InvertedPendulum-v5", "--steps", "50"]) == 0
    assert "50 steps" in capsys.readouterr().out


def test_cli_roa_refuses_a_gym_run_in_one_line(run_dir, capsys):
    assert main(["roa", "--controller", str(run_dir)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "no interval model" in err and "rho = " in err and "design.json" in err
    with pytest.raises(SystemExit) as exit_status:
        main(["roa", "gym:InvertedPendulum-v5"])
    assert exit_status.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no interval model" in err


def test_cli_refuses_leoc_options_on_a_gym_env(capsys):
    assert main(["simulate", "gym:Pendulum-v1", "--variant", "leoc"]) == 2
    assert "--variant: expected it left out for a gymnasium env" in capsys.readouterr().err
    assert main(["simulate", "pendulum", "--main-index", "0"]) == 2
    assert "--main-index: expected only for a gymnasium env" in capsys.readouterr().err


def test_cli_lqr_of_a_gym_env_is_the_adapters_design(capsys):
    """``leoc lqr gym:InvertedPendulum-v5 --json``: K of an independent design, stable, with
    the linearisation's error bounds; Pendulum-v1 has no default operating point."""
    pytest.importorskip("mujoco")
    assert main(["lqr", "gym:InvertedPendulum-v5", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    lin = linearise_env(gym.make("InvertedPendulum-v5"), np.zeros(4), [0.0])
    np.testing.assert_allclose(summary["K"], design_env_lqr(lin).K, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(summary["W"], -design_env_lqr(lin).K, rtol=1e-9, atol=1e-12)
    assert summary["error_A"] == pytest.approx(float(np.max(lin.error_A)))
    assert 0.0 < summary["error_A"] < 1e-9 and summary["spectral_radius"] < 1.0
    assert main(["lqr", "gym:Pendulum-v1"]) == 2
    assert "operating_point: expected" in capsys.readouterr().err
