"""The gym study's ``Pendulum-v1`` part (leoc.experiments.gym_pendulum): both evaluation tasks
against loops written here on gymnasium's own env, and a smoke study's records, agreement and
report (slow)."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import numpy as np
import pytest
import torch

from leoc.experiments import gym_pendulum
from leoc.experiments.gym_study import PENDULUM_KEY, run_gym_study
from leoc.experiments.gym_study_report import write_study_report
from leoc.experiments.publish import publish

SEEDS = list(range(20_000, 20_008))
#: leoc's pendulum swing-up start: hanging (theta = pi), +/- 10 degrees and +/- 0.1 rad/s.
SPREAD = np.array([math.radians(10.0), 0.1])


class EnergySwingUp(torch.nn.Module):
    """Pump the energy (torque along the speed), then catch near the top with a PD law; on
    ``Pendulum-v1``'s observation ``[cos, sin, theta_dot]`` (theta = 0 upright, I = 1/3, the
    weight's torque 5 sin theta, limit 2)."""

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        cos, sin, speed = obs[..., 0], obs[..., 1], obs[..., 2]
        energy = speed**2 / 6.0 + 5.0 * (cos - 1.0)  # zero at the upright rest
        pump = torch.clamp(-2.0 * energy * torch.sign(speed + 1e-9), -2.0, 2.0)
        catch = torch.clamp(-10.0 * torch.atan2(sin, cos) - 2.0 * speed, -2.0, 2.0)
        return torch.where(cos > 0.95, catch, pump)[..., None]


class NoTorque(torch.nn.Module):
    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.zeros(obs.shape[:-1] + (1,), dtype=obs.dtype)


def act(policy: torch.nn.Module, obs: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return policy(torch.as_tensor(obs, dtype=torch.float64)).numpy()


def hand_returns(policy: torch.nn.Module) -> list[float]:
    """Pendulum-v1's own episodes from reset(seed), written out here."""
    env, returns = gym.make("Pendulum-v1"), []
    for seed in SEEDS:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(act(policy, obs))
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    return returns


def hand_swing_up_holds(policy: torch.nn.Module) -> list[bool]:
    """gymnasium's Pendulum-v1 started (through its ``state``) at leoc's swing-up start drawn
    from default_rng(seed): held when the angle stays within 5 degrees for the last 50 of 200
    steps."""
    env, held = gym.make("Pendulum-v1"), []
    for seed in SEEDS:
        start = np.array([math.pi, 0.0]) + np.random.default_rng(seed).uniform(-SPREAD, SPREAD)
        env.reset(seed=seed)
        env.unwrapped.state = start.copy()
        obs, angles = env.unwrapped._get_obs(), []
        for _ in range(200):
            obs, *_ = env.step(act(policy, obs))
            angles.append((env.unwrapped.state[0] + math.pi) % (2.0 * math.pi) - math.pi)
        held.append(bool(np.all(np.abs(np.degrees(angles[-50:])) <= 5.0)))
    return held


@pytest.mark.parametrize("policy", [EnergySwingUp(), NoTorque()], ids=["swing-up", "no torque"])
def test_both_tasks_match_loops_on_gymnasiums_env(policy) -> None:
    """The return task is Pendulum-v1's own episodes; the swing-up task, simulated on leoc's
    pendulum, holds exactly where gymnasium's env started at the same states holds (same
    dynamics). The swing-up law holds every start and no torque none, so a task that read the
    wrong starts, the wrong episodes or the other controller fails."""
    record = gym_pendulum._evaluate(policy, SEEDS)
    expected = hand_returns(policy)
    np.testing.assert_allclose(record["returns"], expected, rtol=1e-9)
    assert record["mean_return"] == pytest.approx(np.mean(expected), rel=1e-12)
    assert record["held"] == hand_swing_up_holds(policy)
    assert record["held_share"] == pytest.approx(np.mean(record["held"]))


def test_swing_up_starts_are_leocs_swing_up_distribution() -> None:
    starts = gym_pendulum.swing_up_starts(SEEDS)
    for seed, start in zip(SEEDS, starts, strict=True):
        expected = np.array([math.pi, 0.0]) + np.random.default_rng(seed).uniform(-SPREAD, SPREAD)
        np.testing.assert_allclose(start, expected, rtol=0, atol=1e-15)


def test_both_arms_train_with_leocs_pendulum_sac_settings() -> None:
    """The full profile is leoc's pendulum SAC (400-300 networks, 10k steps, Adam 1e-3,
    discount 0.995) with the final policy, whichever path trains it."""
    profile = gym_pendulum.PENDULUM_PROFILES["full"]
    assert profile.total_steps == 10_000
    settings = profile.settings
    assert settings["actor_hidden"] == [400, 300] and settings["critic_hidden"] == [400, 300]
    assert settings["actor_learning_rate"] == 1e-3 and settings["discount"] == 0.995
    assert settings["model_selection"] == "final"
    assert "system" not in settings and "step_rules" not in settings


@pytest.mark.slow
@pytest.mark.usefixtures("single_thread")
def test_smoke_part_records_agreement_and_report(tmp_path, monkeypatch) -> None:
    """A smoke study of the Pendulum-v1 part: every arm x controller has its record; the
    agreement is P(gymnasium seed > leoc seed) of those records, counted here; a rerun trains
    nothing (the records are reused) and the report regenerates byte for byte. ``leoc
    publish`` carries the records without the models, and the same study on the copy trains
    nothing and gives the same numbers (a checkpoint of a study carried to another machine)."""
    options = {"envs": ["Pendulum-v1"], "seeds": 2, "episodes": 2, "command": "leoc x"}
    study = run_gym_study(tmp_path, "smoke", **options)
    entry = study[PENDULUM_KEY]
    for controller in gym_pendulum.PENDULUM_CONTROLLERS:
        data = entry["controllers"][controller]
        for task in gym_pendulum.PENDULUM_TASKS:
            mine = [run[task] for run in data["runs"]["gymnasium"]]
            theirs = [run[task] for run in data["runs"]["leoc"]]
            pairs = [(a > b) + 0.5 * (a == b) for a in mine for b in theirs]
            assert data["agreement"][task]["probability"] == pytest.approx(np.mean(pairs))
        for arm in gym_pendulum.PENDULUM_ARMS:
            assert [run["seed"] for run in data["runs"][arm]] == [0, 1]
            assert all(run["key"]["arm"] == arm for run in data["runs"][arm])
    readme = (tmp_path / "README.md").read_bytes()
    again = run_gym_study(tmp_path, "smoke", **options)
    assert json.dumps(again, sort_keys=True) == json.dumps(study, sort_keys=True)
    (tmp_path / "README.md").unlink()
    write_study_report(tmp_path)
    assert (tmp_path / "README.md").read_bytes() == readme
    assert b"## Pendulum-v1 through the adapter" in readme
    copy = tmp_path.parent / f"{tmp_path.name}-published"
    assert publish(tmp_path, copy) == copy / "README.md"
    names = {path.name for path in copy.rglob("*") if path.is_file()}
    assert names == {"README.md", "study.json", "evaluation.json", "config.json", "design.json"}
    monkeypatch.setattr(gym_pendulum, "_train", lambda *args: pytest.fail("retrained a run"))
    carried = run_gym_study(copy, "smoke", **options)
    assert json.dumps(carried, sort_keys=True) == json.dumps(study, sort_keys=True)
    (copy / "study.json").unlink()  # a study still running: its finished runs only
    partial = tmp_path.parent / f"{tmp_path.name}-partial"
    assert publish(copy, partial) == partial
    assert not (partial / "study.json").exists() and len(list(partial.rglob("evaluation.json")))
