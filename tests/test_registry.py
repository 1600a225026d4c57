"""The system registry and the System protocol's validation."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from leoc.systems import (
    Pendulum,
    PendulumParams,
    make_env,
    make_system,
    register_system,
    system_names,
    unregister_system,
)


class TiltedPendulum(Pendulum):
    """A user's mistake: an operating point 0.3 rad off upright, where gravity pulls."""

    name = "tilted"

    @property
    def operating_state(self) -> np.ndarray:
        return np.array([0.3, 0.0])


class NegativeStepPendulum(Pendulum):
    name = "negative_dt"

    @property
    def dt(self) -> float:
        return -0.05


class WrongShapePendulum(Pendulum):
    name = "wrong_shape"
    default_q = (1.0,)


class RunawayPendulum(Pendulum):
    """A user's mistake: an allowed region whose exit pays (a bonus for leaving it)."""

    name = "runaway"
    out_of_bounds_reward = 10.0

    def out_of_bounds(self, state):
        return state[..., 1].abs() > 7.0


class HeavyPendulum(Pendulum):
    """A valid user system: the pendulum with a 2 kg rod and its own gymnasium id."""

    name = "heavy_pendulum"

    def __init__(self, params: PendulumParams | None = None, **overrides: float) -> None:
        super().__init__(params if params is not None else PendulumParams(mass=2.0), **overrides)


def test_built_in_systems_are_registered() -> None:
    assert system_names()[:4] == ("pendulum", "cartpole", "mountaincar", "acrobot")
    with pytest.raises(ValueError, match="unknown name 'segway'.*register_system"):
        make_system("segway")


def test_a_wrong_operating_point_is_rejected_with_the_residual() -> None:
    message = (
        r"system 'tilted': the operating point \[0.3, 0.0\] is not an equilibrium of step_fn "
        r"under u_eq = \[0.0\]: max \|f\(a, u_eq\) - a\| = .* > tolerance 1e-09"
    )
    with pytest.raises(ValueError, match=message):
        register_system("tilted", TiltedPendulum)
    assert "tilted" not in system_names()


@pytest.mark.parametrize(
    "factory, message",
    [
        (NegativeStepPendulum, "system 'negative_dt': dt: expected a positive finite number"),
        (WrongShapePendulum, r"system 'wrong_shape': default_q: expected 2 finite numbers"),
        (
            RunawayPendulum,
            r"system 'runaway': out_of_bounds_reward: expected at most the reward at the "
            r"operating point \(0\) so that leaving never pays, found 10.0",
        ),
    ],
)
def test_inconsistent_systems_are_rejected(factory: type, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        register_system(factory.name, factory)


def test_names_are_checked() -> None:
    with pytest.raises(ValueError, match="already registered"):
        register_system("pendulum", Pendulum)
    with pytest.raises(ValueError, match="expected a system named 'pendulum_two'"):
        register_system("pendulum_two", Pendulum)
    with pytest.raises(ValueError, match="lower-case identifier"):
        register_system("Bad Name", Pendulum)


def test_a_user_system_works_through_the_registry_and_gymnasium() -> None:
    register_system("heavy_pendulum", HeavyPendulum)
    try:
        system = make_system("heavy_pendulum")
        assert system.params.mass == 2.0
        assert make_system("heavy_pendulum", mass=0.5).params.mass == 1.0
        env = gym.make("leoc/HeavyPendulum-v0")
        obs, info = env.reset(seed=1)
        assert obs.shape == (3,) and abs(info["state"][0] - math.pi) < 0.2
        assert env.unwrapped.system.params.mass == 2.0
        assert make_env("heavy_pendulum").spec.max_episode_steps == system.episode_steps
    finally:
        unregister_system("heavy_pendulum")
    assert "heavy_pendulum" not in system_names()
    assert "leoc/HeavyPendulum-v0" not in gym.registry
