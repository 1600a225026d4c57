"""Tests of leoc.systems against gymnasium's own environments and the equations of motion."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

from leoc.systems import (
    SYSTEM_NAMES,
    CartPole,
    CartPoleParams,
    MountainCar,
    Pendulum,
    PendulumParams,
    make_env,
    make_system,
)

ROLLOUT_STEPS = 300
EXACT = 1e-12


def test_pendulum_matches_gymnasium_pendulum_v1_step_for_step() -> None:
    reference = gym.make("Pendulum-v1").unwrapped
    system = Pendulum()
    rng = np.random.default_rng(0)
    for _ in range(5):
        state = np.array([rng.uniform(-math.pi, math.pi), rng.uniform(-8, 8)])
        for _ in range(ROLLOUT_STEPS // 5):
            action = rng.uniform(-3.0, 3.0, size=1)  # beyond the limit too: both clip
            reference.state = state.copy()
            ref_obs, ref_reward, *_ = reference.step(action.astype(np.float32))
            ours = system.step(state, action)[0].numpy()
            reward = float(system.reward_fn(torch.tensor([state]), torch.tensor([action]))[0])
            np.testing.assert_allclose(ours, reference.state, rtol=0, atol=1e-6)
            np.testing.assert_allclose(system.observe(ours)[0].numpy(), ref_obs, atol=1e-6)
            assert reward == pytest.approx(ref_reward, abs=1e-5)
            state = reference.state.copy()


def test_pendulum_matches_gymnasium_in_float64_with_float64_actions() -> None:
    reference = gym.make("Pendulum-v1", g=10.0).unwrapped
    system = Pendulum()
    rng = np.random.default_rng(1)
    state = np.array([2.0, -1.0])
    for _ in range(ROLLOUT_STEPS):
        action = rng.uniform(-2.0, 2.0, size=1)
        reference.state = state.copy()
        reference.step(action)
        ours = system.step(state, action)[0].numpy()
        np.testing.assert_allclose(ours, reference.state, rtol=0, atol=EXACT)
        state = ours


def _gym_cartpole(params: CartPoleParams) -> gym.Env:
    env = gym.make("CartPole-v1").unwrapped
    env.gravity = params.gravity
    env.masscart = params.cart_mass
    env.masspole = params.pole_mass
    env.total_mass = params.cart_mass + params.pole_mass
    env.length = params.half_length
    env.polemass_length = params.pole_mass * params.half_length
    env.tau = params.dt
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("scale", [1.0, 3.0])
def test_cartpole_matches_gymnasium_cartpole_equations_with_continuous_force(scale) -> None:
    system = CartPole().with_params(mass=scale)
    reference = _gym_cartpole(system.params)
    rng = np.random.default_rng(2)
    state = np.array([0.1, -0.2, math.pi - 0.3, 0.5])
    for _ in range(ROLLOUT_STEPS):
        force = rng.uniform(-2.5, 2.5)
        # gymnasium applies +force_mag for action 1 and -force_mag for action 0
        reference.force_mag = abs(force)
        reference.state = state.copy()
        reference.step(1 if force > 0 else 0)
        ours = system.step(state, [force])[0].numpy()
        np.testing.assert_allclose(ours, reference.state, rtol=0, atol=EXACT)
        state = ours


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_operating_point_is_an_equilibrium(name) -> None:
    system = make_system(name)
    state = system.operating_state
    for _ in range(50):
        state = system.step(state, system.u_eq)[0].numpy()
    np.testing.assert_array_equal(state, system.operating_state)


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_env_passes_gymnasium_env_checker(name) -> None:
    check_env(make_env(name).unwrapped, skip_render_check=True)


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_seeded_rollouts_repeat_exactly(name) -> None:
    def run(seed: int) -> np.ndarray:
        env = make_env(name)
        env.action_space.seed(seed)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for _ in range(60):
            obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
            out.append(obs)
            if terminated or truncated:
                break
        return np.array(out)

    np.testing.assert_array_equal(run(7), run(7))
    assert not np.array_equal(run(7)[0], run(8)[0])


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_swing_up_start_lies_in_the_documented_box(name) -> None:
    system = make_system(name)
    rng = np.random.default_rng(3)
    starts = np.array([system.sample_start(rng) for _ in range(2000)])
    centre = np.array(system.swing_up_centre)
    spread = np.array(system.start_spread)
    assert np.all(np.abs(starts - centre) <= spread)
    # uniform: the sample covers most of the box in every coordinate
    assert np.all(np.abs(starts - centre).max(axis=0) > 0.95 * spread)


def test_reset_at_operating_point_with_offset_and_explicit_state() -> None:
    env = make_env("cartpole")
    obs, info = env.reset(seed=0, options={"start": "operating_point"})
    np.testing.assert_array_equal(info["state"], np.zeros(4))
    np.testing.assert_array_equal(obs, [0, 0, 1, 0, 0])
    _, info = env.reset(options={"start": "operating_point", "offset": [0.1, 0, 0.2, 0]})
    np.testing.assert_array_equal(info["state"], [0.1, 0, 0.2, 0])
    _, info = env.reset(options={"state": [1.0, 2.0, 3.0, 4.0]})
    np.testing.assert_array_equal(info["state"], [1.0, 2.0, 3.0, 4.0])


def test_bad_reset_options_are_rejected() -> None:
    env = make_env("pendulum")
    with pytest.raises(ValueError, match="offset"):
        env.reset(options={"start": "operating_point", "offset": [1.0]})
    with pytest.raises(ValueError, match="unknown keys"):
        env.reset(options={"begin": "swing_up"})
    with pytest.raises(ValueError, match="kind"):
        env.reset(options={"start": "upside_down"})


def test_cartpole_leaving_the_track_is_charged_the_worst_reward_for_every_step_left() -> None:
    env = make_env("cartpole")
    env.reset(options={"state": [2.39, 1.0, 0.0, 0.0]})
    _, reward, terminated, _, _ = env.step(np.array([2.5], dtype=np.float32))
    # the pole hanging down at the track's end with full force: -0.1 (5 pi^2 + 2.4^2 + 0.005 2.5^2)
    worst = -0.1 * (5.0 * math.pi**2 + 2.4**2 + 0.005 * 2.5**2)
    assert terminated and reward == pytest.approx(200 * worst, rel=1e-12)


def test_mountaincar_leaving_the_track_is_charged_the_worst_reward_for_every_step_left() -> None:
    env = make_env("mountaincar")
    env.reset(options={"state": [0.0, 0.0]})
    for _ in range(9):  # nine steps at the hilltop, then a jump off the track's right end
        env.step(np.array([0.0], dtype=np.float32))
    env.unwrapped.state = np.array([2.2 - math.pi / 2 - 1e-3, 1.0])
    _, reward, terminated, _, _ = env.step(np.array([3.0], dtype=np.float32))
    # standing at the far (left) end, x = -3.6 - pi / 2, with full force, for 191 steps
    worst = -0.1 * (5.0 * (3.6 + math.pi / 2) ** 2 + 0.005 * 3.0**2)
    assert terminated and reward == pytest.approx(191 * worst, rel=1e-12)


def test_pendulum_mass_scaling_follows_the_equations() -> None:
    # theta_ddot = 3 g / (2 l) sin(theta) + 3 u / (m l^2): the torque term scales as 1 / m
    base, heavy = Pendulum(), Pendulum().with_params(mass=2.0)
    state, torque = np.array([0.3, 0.0]), np.array([1.0])
    dt = base.dt

    def torque_effect(system) -> float:
        pushed = system.step(state, torque)[0, 1] - system.step(state, [0.0])[0, 1]
        return float(pushed) / dt

    assert torque_effect(base) == pytest.approx(3.0 / (1.0 * 1.0**2) * 1.0, rel=EXACT)
    assert torque_effect(heavy) == pytest.approx(3.0 / (2.0 * 1.0**2) * 1.0, rel=EXACT)
    assert heavy.params.inertia == pytest.approx(2.0 * base.params.inertia)


def test_cartpole_scaling_recomputes_derived_quantities_and_dynamics() -> None:
    params = CartPoleParams().scaled(mass=2.0, gravity=1.5)
    assert params.total_mass == pytest.approx(2 * 0.055)
    assert params.pole_mass_length == pytest.approx(2 * 0.005 * 0.5)
    assert params.gravity == pytest.approx(9.8 * 1.5)
    system = CartPole(params)
    # upright at rest with force F: theta_ddot = -F / (l (4/3 - m_p / M_t) M_t)
    force, state = 1.0, np.zeros(4)
    next_state = system.step(state, [force])[0].numpy()
    total = params.total_mass
    theta_ddot = -force / total / (0.5 * (4 / 3 - params.pole_mass / total))
    x_ddot = force / total - params.pole_mass_length * theta_ddot / total
    np.testing.assert_allclose(next_state[[1, 3]] / system.dt, [x_ddot, theta_ddot], rtol=1e-12)


def test_mountaincar_scaling_changes_force_and_gravity_terms() -> None:
    x, force = 0.4, 1.5
    for mass_scale, gravity_scale in [(1.0, 1.0), (2.0, 1.0), (1.0, 0.5)]:
        system = MountainCar().with_params(mass=mass_scale, gravity=gravity_scale)
        speed = system.step([x, 0.0], [force])[0, 1].item()
        expected = force / (0.1 * mass_scale) + 9.8 * gravity_scale * 1.35 * math.sin(x)
        assert speed / system.dt == pytest.approx(expected, rel=1e-12)


def test_params_validation_and_unknown_scale_names() -> None:
    with pytest.raises(ValueError, match="PendulumParams.mass"):
        PendulumParams(mass=-1.0)
    with pytest.raises(ValueError, match="unknown parameter 'length_of_pole'"):
        PendulumParams().scaled(length_of_pole=2.0)
    with pytest.raises(ValueError, match="mass: expected a positive scale factor"):
        CartPoleParams().scaled(mass=0.0)
    with pytest.raises(ValueError, match="expected one of pendulum, cartpole, mountaincar"):
        make_system("segway")  # acrobot was unknown before it was built


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_step_is_batched_and_differentiable(name) -> None:
    system = make_system(name)
    rng = np.random.default_rng(4)
    states = torch.tensor(
        np.array([system.sample_start(rng) for _ in range(8)]), requires_grad=True
    )
    actions = torch.zeros(8, 1, dtype=torch.float64)
    batched = system.step_fn(states, actions)
    singles = torch.cat([system.step_fn(states[i : i + 1], actions[i : i + 1]) for i in range(8)])
    torch.testing.assert_close(batched, singles, rtol=0, atol=0)
    batched.sum().backward()
    assert states.grad is not None and torch.all(torch.isfinite(states.grad))


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_state_from_obs_inverts_observe(name) -> None:
    system = make_system(name)
    rng = np.random.default_rng(5)
    states = torch.tensor(np.array([system.sample_start(rng) for _ in range(16)]))
    recovered = system.state_from_obs(system.observe(states))
    for index in system.angle_indices:  # angles come back wrapped
        recovered[:, index] = torch.remainder(recovered[:, index], 2 * math.pi)
        states[:, index] = torch.remainder(states[:, index], 2 * math.pi)
    torch.testing.assert_close(recovered, states, rtol=0, atol=1e-12)


def test_hold_step_known_answers() -> None:
    system = MountainCar()  # main coordinate: x in metres, hold band 0.05
    states = np.zeros((6, 2))
    states[:, 0] = [1.0, 0.01, 0.9, 0.01, -0.02, 0.005]
    assert system.hold_step(states, min_steps=0) == 3
    assert system.hold_step(states, band=0.001, min_steps=0) is None  # outside at the end
    assert system.hold_step(states, min_steps=3) == 3
    assert system.hold_step(states, min_steps=4) is None  # inside for only 3 steps
    assert system.hold_step(states) is None  # the default minimum duration is the system's
    assert system.hold_step(np.zeros((4, 2)), min_steps=0) == 0
    assert system.hold_step(np.zeros((4, 2)), min_steps=0, terminated=True) is None
    long = np.zeros((system.hold_min_steps + 3, 2))
    long[:3, 0] = 1.0
    assert system.hold_step(long) == 3  # exactly hold_min_steps samples inside
    long[3, 0] = 1.0
    assert system.hold_step(long) is None  # one sample short
    pendulum = Pendulum()  # angles are wrapped and in degrees: 2 pi + 1 degree is 1 degree
    angles = np.array([[math.pi, 0.0], [2 * math.pi + math.radians(1.0), 0.0]])
    assert pendulum.hold_step(angles, min_steps=0) == 1
