"""Perturbations as data (issue 43): each against a closed form or an independent simulation.

The references here do not go through :class:`PerturbedPlant`: a hand-written closed loop on
``System.step_fn`` (today's plant), the equations of motion written again in numpy from each
system's Lagrangian, the acrobot's energy balance, and sampling statistics with stated bounds.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest
import torch

from leoc.control.lqr import design_lqr
from leoc.policies.held import lqr_controller
from leoc.systems import make_system
from leoc.systems.acrobot import acrobot_energy, acrobot_step
from leoc.systems.base import DTYPE
from leoc.systems.envs import LeocEnv
from leoc.systems.perturbations import (
    ActionDelay,
    ActuatorGain,
    Friction,
    ObservationNoise,
    ParameterError,
    PerturbedPlant,
    Push,
    TorqueNoise,
    perturbation_from_dict,
)
from leoc.systems.rollout import simulate, simulate_settings

SYSTEMS = ("pendulum", "cartpole", "mountaincar", "acrobot")
STEPS = 60
# Sampling bounds: a mean within Z standard errors, a sample std within Z of its own standard
# error (sigma / sqrt(2 N) for a Gaussian); Z = 5 fails a correct implementation with
# probability below 1e-6 per check (and the draws are seeded, so a pass is reproducible).
Z = 5.0
SAMPLES = 40_000
# Round-off between two orderings of the same float64 formula.
RTOL = 1e-12

# One of every kind at its nominal level: the plant must be today's, bit for bit.
NOMINAL = (
    ObservationNoise(std=0.0, seed=3),
    TorqueNoise(std=0.0, seed=4),
    ActionDelay(periods=0.0),
    ActuatorGain(gain=1.0),
    Friction(viscous=0.0, coulomb=0.0),
    ParameterError("gravity", 1.0),
    Push(size=0.0, rate=2.0, seed=5),
)


@functools.cache
def _lqr(name: str, repeat: int = 1):
    system = make_system(name)
    return lqr_controller(design_lqr(system, action_repeat=repeat))


def _starts(system, count: int = 4, seed: int = 0) -> np.ndarray:
    return system.sample_operating_region(np.random.default_rng(seed), count)


def _reference_loop(system, controller, starts, steps, repeat=1, delay_steps=0):
    """Today's closed loop on ``system.step_fn``, written again: the controller decides every
    ``repeat`` steps at the observation, its clipped command is applied ``delay_steps`` steps
    later (the operating action before). Returns states (B, T+1, S), commands, rewards."""
    state = torch.as_tensor(starts, dtype=DTYPE)
    rest = torch.as_tensor(system.u_eq, dtype=DTYPE).expand(state.shape[0], -1)
    states, commands, rewards = [state], [], []
    with torch.no_grad():
        for t in range(steps):
            if t % repeat == 0:
                decided = system.clip_action(controller(system.observe(state)))
            commands.append(decided)
            applied = commands[t - delay_steps] if t >= delay_steps else rest
            following = system.step_fn(state, applied)
            leaving = system.out_of_bounds(following)
            rewards.append(system.step_reward(state, decided, following, leaving, steps - t - 1))
            state = following
            states.append(state)
    return torch.stack(states, 1), torch.stack(commands, 1), torch.stack(rewards, 1)


# ----------------------------------------------------------------------------- level zero
@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("repeat", [1, 3])
def test_nominal_levels_reproduce_todays_plant_bit_for_bit(name, repeat) -> None:
    system = make_system(name)
    controller = _lqr(name, repeat)
    starts = _starts(system)
    run = simulate(system, controller, starts, STEPS, perturbations=NOMINAL)
    states, commands, rewards = _reference_loop(system, controller, starts, STEPS, repeat)
    assert not run.terminated.any()
    assert torch.equal(torch.as_tensor(run.states), states)
    assert torch.equal(torch.as_tensor(run.actions), commands)
    assert torch.equal(torch.as_tensor(run.rewards), rewards)
    assert torch.equal(torch.as_tensor(run.observations), system.observation.observe(states))
    assert PerturbedPlant(system, NOMINAL).system is system


@pytest.mark.parametrize("name", SYSTEMS)
def test_a_nominal_env_is_todays_env_bit_for_bit(name) -> None:
    plain = LeocEnv(system=name)
    nominal = LeocEnv(system=name, perturbations=NOMINAL)
    assert np.array_equal(plain.observation_space.high, nominal.observation_space.high)
    first, second = plain.reset(seed=7), nominal.reset(seed=7)
    assert np.array_equal(first[0], second[0])
    for t in range(STEPS):
        action = np.array([4.0 * math.sin(0.3 * t)])
        one, two = plain.step(action), nominal.step(action)
        assert np.array_equal(one[0], two[0]) and one[1:4] == two[1:4]
        assert np.array_equal(one[4]["state"], two[4]["state"])


# ----------------------------------------------------------------------------- observation noise
@pytest.mark.parametrize("name", ["pendulum", "cartpole"])
def test_observation_noise_has_the_stated_mean_and_std_per_entry(name) -> None:
    system = make_system(name)
    std = tuple(0.01 * (i + 1) for i in range(system.obs_dim))
    plant = PerturbedPlant(system, [ObservationNoise(std=std, seed=11)])
    state = torch.as_tensor(_starts(system, 1), dtype=DTYPE).expand(SAMPLES, -1)
    noise = (plant.observe(state) - system.observe(state)).numpy()
    sigma = np.asarray(std)
    assert np.all(np.abs(noise.mean(axis=0)) < Z * sigma / math.sqrt(SAMPLES))
    assert np.all(np.abs(noise.std(axis=0) - sigma) < Z * sigma / math.sqrt(2 * SAMPLES))
    correlation = np.corrcoef(noise.T) - np.eye(system.obs_dim)
    assert np.all(np.abs(correlation) < Z / math.sqrt(SAMPLES))
    again = (plant.observe(state) - system.observe(state)).numpy()  # a fresh draw per call
    assert np.all(np.abs(np.corrcoef(noise[:, 0], again[:, 0])[0, 1]) < Z / math.sqrt(SAMPLES))


@pytest.mark.parametrize("name", SYSTEMS)
def test_observation_noise_acts_on_what_the_controller_sees_not_on_the_state(name) -> None:
    system = make_system(name)
    seen = []

    def controller(obs):
        seen.append(obs.clone())
        return torch.zeros(obs.shape[0], 1, dtype=DTYPE)  # blind: the states cannot change

    noise = ObservationNoise(std=0.05, seed=2)
    clean = simulate(system, controller, _starts(system), 20)
    seen.clear()
    run = simulate(system, controller, _starts(system), 20, perturbations=[noise])
    assert torch.equal(torch.as_tensor(run.states), torch.as_tensor(clean.states))
    recorded = torch.as_tensor(run.observations)
    assert torch.equal(torch.stack(seen, 1), recorded[:, :20])
    deviation = recorded - system.observation.observe(torch.as_tensor(run.states))
    assert float(deviation.abs().min()) > 0.0 and float(deviation.std()) == pytest.approx(
        0.05, rel=0.1
    )


# ----------------------------------------------------------------------------- delay
@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize(("periods", "repeat"), [(1, 1), (2, 1), (1, 3), (0.5, 2), (2 / 3, 3)])
def test_a_delay_of_k_periods_is_the_undelayed_loop_shifted_by_k(name, periods, repeat) -> None:
    system = make_system(name)
    controller = _lqr(name, repeat)
    starts = _starts(system)
    run = simulate(system, controller, starts, STEPS, perturbations=[ActionDelay(periods)])
    delay_steps = round(periods * repeat)
    states, commands, _ = _reference_loop(system, controller, starts, STEPS, repeat, delay_steps)
    assert torch.equal(torch.as_tensor(run.states), states)
    assert torch.equal(torch.as_tensor(run.actions), commands)


@pytest.mark.parametrize("name", SYSTEMS)
def test_a_delayed_open_loop_is_the_command_sequence_shifted(name) -> None:
    system = make_system(name)
    rng = np.random.default_rng(1)
    commands = torch.as_tensor(rng.uniform(-1, 1, (STEPS, 3, 1)) * system.action_limit)
    start = torch.as_tensor(_starts(system, 3), dtype=DTYPE)
    delayed = PerturbedPlant(system, [ActionDelay(2)], action_repeat=2)  # 4 steps
    delayed.reset(3)
    rest = torch.as_tensor(system.u_eq, dtype=DTYPE).expand(3, -1)
    shifted = [rest] * 4 + list(commands[:-4])
    state_a = state_b = start
    for t in range(STEPS):
        state_a = delayed.step(state_a, commands[t]).state
        state_b = system.step_fn(state_b, shifted[t])
        assert torch.equal(state_a, state_b)


def test_a_delay_must_be_a_whole_number_of_steps() -> None:
    system = make_system("pendulum")
    with pytest.raises(ValueError, match="whole number"):
        PerturbedPlant(system, [ActionDelay(0.5)], action_repeat=1)
    assert PerturbedPlant(system, [ActionDelay(0.5)], action_repeat=4).delay_steps == 2
    assert ActionDelay(1 / 3).steps(3) == 1


# ----------------------------------------------------------------------------- actuator
@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("gain", [0.0, 0.6, 1.7])
def test_actuator_gain_scales_the_clipped_command_within_the_limit(name, gain) -> None:
    system = make_system(name)
    rng = np.random.default_rng(2)
    state = torch.as_tensor(_starts(system, 64), dtype=DTYPE)
    limit = system.action_limit
    command = torch.as_tensor(rng.uniform(-2.0 * limit, 2.0 * limit, (64, 1)))
    step = PerturbedPlant(system, [ActuatorGain(gain)]).step(state, command)
    expected = np.clip(gain * np.clip(command.numpy(), -limit, limit), -limit, limit)
    assert np.array_equal(step.applied.numpy(), expected)
    assert torch.equal(step.state, system.step_fn(state, torch.as_tensor(expected)))
    assert float(step.applied.abs().max()) <= limit


def test_actuator_gain_scales_the_pendulum_acceleration() -> None:
    """Closed form: theta_ddot is affine in the torque, so the gain scales its torque part."""
    system = make_system("pendulum")
    state = torch.tensor([[0.3, -0.5]], dtype=DTYPE)
    command = torch.tensor([[1.2]], dtype=DTYPE)
    dt, inertia = system.params.dt, system.params.inertia
    free = system.step_fn(state, torch.zeros(1, 1, dtype=DTYPE))
    for gain in (0.25, 0.5, 1.5):
        stepped = PerturbedPlant(system, [ActuatorGain(gain)]).step(state, command).state
        speed_change = float(stepped[0, 1] - free[0, 1])
        assert speed_change == pytest.approx(dt * gain * 1.2 / inertia, rel=RTOL * 100)


def test_torque_noise_has_the_stated_statistics_and_keeps_the_limit() -> None:
    system = make_system("pendulum")
    limit, sigma = system.action_limit, 0.3
    plant = PerturbedPlant(system, [TorqueNoise(std=sigma, seed=9)])
    state = torch.zeros(SAMPLES, 2, dtype=DTYPE)
    step = plant.step(state, torch.zeros(SAMPLES, 1, dtype=DTYPE))
    noise = step.applied.numpy()[:, 0]
    assert abs(noise.mean()) < Z * sigma / math.sqrt(SAMPLES)
    assert abs(noise.std() - sigma) < Z * sigma / math.sqrt(2 * SAMPLES)
    assert torch.equal(step.state, system.step_fn(state, step.applied))
    at_limit = plant.step(state, torch.full((SAMPLES, 1), limit, dtype=DTYPE)).applied
    assert float(at_limit.max()) == limit and float(at_limit.min()) < limit - sigma


# ----------------------------------------------------------------------------- friction
def _pendulum_reference(state, torque, p, viscous, coulomb):
    """The rod about its end: (m l^2 / 3) theta_ddot = m g (l / 2) sin theta + u + Q,
    semi-implicit Euler with the speed clip (numpy, from the physics)."""
    theta, speed = state[:, 0], state[:, 1]
    friction = -viscous * speed - coulomb * np.sign(speed)
    moment = p.mass * p.length**2 / 3.0
    acceleration = (p.mass * p.gravity * p.length / 2.0 * np.sin(theta) + torque + friction) / (
        moment
    )
    speed = np.clip(speed + p.dt * acceleration, -p.max_speed, p.max_speed)
    return np.stack([theta + p.dt * speed, speed], axis=1)


def _cartpole_reference(state, force, p, cart, pole):
    """Lagrange's equations of the cart and the rod (kinetic energy 1/2 M x_dot^2 + m l cos
    x_dot theta_dot + 2/3 m l^2 theta_dot^2), solved as a 2x2 system; explicit Euler."""
    x, x_dot, theta, theta_dot = state.T
    total, m, half = p.cart_mass + p.pole_mass, p.pole_mass, p.half_length
    q_cart = -cart[0] * x_dot - cart[1] * np.sign(x_dot)
    q_pole = -pole[0] * theta_dot - pole[1] * np.sign(theta_dot)
    result = []
    for i in range(len(x)):
        mass = np.array(
            [
                [total, m * half * np.cos(theta[i])],
                [m * half * np.cos(theta[i]), 4 / 3 * m * half**2],
            ]
        )
        rhs = np.array(
            [
                force[i] + q_cart[i] + m * half * np.sin(theta[i]) * theta_dot[i] ** 2,
                m * p.gravity * half * np.sin(theta[i]) + q_pole[i],
            ]
        )
        x_ddot, theta_ddot = np.linalg.solve(mass, rhs)
        result.append(
            [
                x[i] + p.dt * x_dot[i],
                x_dot[i] + p.dt * x_ddot,
                theta[i] + p.dt * theta_dot[i],
                theta_dot[i] + p.dt * theta_ddot,
            ]
        )
    return np.array(result)


def _states_and_torques(system, count=32, seed=3):
    rng = np.random.default_rng(seed)
    state = rng.uniform(-1.0, 1.0, (count, system.state_dim))
    state[0, list(system.velocity_indices)] = 0.0  # sign(0) = 0: no Coulomb force at rest
    limit = system.action_limit
    command = rng.uniform(-1.5 * limit, 1.5 * limit, (count, 1))
    return state, command, np.clip(command[:, 0], -limit, limit)


@pytest.mark.parametrize(("viscous", "coulomb"), [(0.4, 0.0), (0.0, 0.3), (0.2, 0.5)])
def test_pendulum_friction_against_its_equations_of_motion(viscous, coulomb) -> None:
    system = make_system("pendulum")
    state, command, torque = _states_and_torques(system)
    plant = PerturbedPlant(system, [Friction(viscous=viscous, coulomb=coulomb)])
    stepped = plant.step(torch.as_tensor(state), torch.as_tensor(command)).state.numpy()
    expected = _pendulum_reference(state, torque, system.params, viscous, coulomb)
    np.testing.assert_allclose(stepped, expected, rtol=RTOL, atol=RTOL)


def test_mountaincar_friction_against_its_equations_of_motion() -> None:
    system = make_system("mountaincar")
    p = system.params
    state, command, force = _states_and_torques(system)
    plant = PerturbedPlant(system, [Friction(viscous=0.05, coulomb=0.2)])
    stepped = plant.step(torch.as_tensor(state), torch.as_tensor(command)).state.numpy()
    x, x_dot = state.T
    friction = -0.05 * x_dot - 0.2 * np.sign(x_dot)
    slope = -p.hill_amplitude * np.sin(x)  # h'(x)
    speed = x_dot + p.dt * ((force + friction) / p.mass - p.gravity * slope)
    np.testing.assert_allclose(stepped, np.stack([x + p.dt * speed, speed], 1), rtol=RTOL)


@pytest.mark.parametrize(
    ("frictions", "cart", "pole"),
    [
        ([Friction(viscous=0.1, coulomb=0.05)], (0.1, 0.05), (0.1, 0.05)),
        ([Friction(viscous=0.02, joints=("theta_dot",))], (0.0, 0.0), (0.02, 0.0)),
        (
            [Friction(coulomb=0.3, joints=("x_dot",)), Friction(viscous=0.01, joints="theta_dot")],
            (0.0, 0.3),
            (0.01, 0.0),
        ),
    ],
)
def test_cartpole_friction_against_lagranges_equations(frictions, cart, pole) -> None:
    system = make_system("cartpole")
    state, command, force = _states_and_torques(system)
    plant = PerturbedPlant(system, frictions)
    stepped = plant.step(torch.as_tensor(state), torch.as_tensor(command)).state.numpy()
    expected = _cartpole_reference(state, force, system.params, cart, pole)
    np.testing.assert_allclose(stepped, expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize(("viscous", "coulomb"), [(0.3, 0.0), (0.0, 0.4)])
def test_acrobot_friction_dissipates_its_power(viscous, coulomb) -> None:
    """Energy balance: with no torque, dE/dt = Q . q_dot = -b |q_dot|^2 - mu |q_dot|_1.
    Integrated in fine steps, the energy lost equals the friction's work (trapezoid rule)."""
    system = make_system("acrobot")
    fine = 400
    params = dataclasses.replace(system.params, dt=system.params.dt / fine)
    plant = PerturbedPlant(system, [Friction(viscous=viscous, coulomb=coulomb)])
    state = torch.tensor([[0.4, -0.3, 1.5, -2.0], [2.0, 1.0, 0.8, 1.2]], dtype=DTYPE)
    torque = torch.zeros(2, 1, dtype=DTYPE)
    energy, work = acrobot_energy(state, params), torch.zeros(2, dtype=DTYPE)

    def power(x):
        speeds = x[:, 2:]
        return -(viscous * speeds**2 + coulomb * speeds.abs()).sum(-1)

    for _ in range(fine):
        following = acrobot_step(state, torque, params, plant.friction_force)
        work = work + 0.5 * params.dt * (power(state) + power(following))
        state = following
    change = acrobot_energy(state, params) - energy
    assert bool((work < 0).all())
    torch.testing.assert_close(change, work, rtol=1e-4, atol=0.0)


def test_friction_is_not_bounded_by_the_actuator_limit() -> None:
    system = make_system("pendulum")
    state = torch.tensor([[0.0, 4.0]], dtype=DTYPE)
    limit = torch.tensor([[system.action_limit]], dtype=DTYPE)
    stepped = PerturbedPlant(system, [Friction(viscous=5.0)]).step(state, limit).state
    expected = _pendulum_reference(state.numpy(), system.action_limit, system.params, 5.0, 0.0)
    np.testing.assert_allclose(stepped.numpy(), expected, rtol=RTOL)  # net torque -18 N m


# ----------------------------------------------------------------------------- parameter errors
@pytest.mark.parametrize(
    ("name", "constant", "factor"),
    [
        ("pendulum", "gravity", 1.3),
        ("pendulum", "length", 0.8),
        ("cartpole", "pole_mass", 2.0),
        ("cartpole", "mass", 1.5),
        ("mountaincar", "hill_amplitude", 1.1),
        ("acrobot", "link_moi_2", 0.7),
    ],
)
def test_a_parameter_error_is_the_system_built_with_that_constant_scaled(
    name, constant, factor
) -> None:
    system = make_system(name)
    params = system.params
    fields = params.MASS_FIELDS if constant == "mass" else (constant,)
    built = type(system)(
        dataclasses.replace(params, **{f: getattr(params, f) * factor for f in fields})
    )
    controller = _lqr(name)
    starts = _starts(system)
    run = simulate(
        system, controller, starts, STEPS, perturbations=[ParameterError(constant, factor)]
    )
    reference = simulate(built, controller, starts, STEPS)
    assert torch.equal(torch.as_tensor(run.states), torch.as_tensor(reference.states))
    assert not np.array_equal(run.states, simulate(system, controller, starts, STEPS).states)


@pytest.mark.parametrize("constant", ["dt", "max_torque"])
def test_a_parameter_error_cannot_change_the_period_or_the_limit(constant) -> None:
    with pytest.raises(ValueError, match="time step or the actuator limit"):
        PerturbedPlant(make_system("pendulum"), [ParameterError(constant, 1.1)])


# ----------------------------------------------------------------------------- pushes
def _pushed_run(system, push, steps=200, batch=50):
    plant = PerturbedPlant(system, [push])
    plant.reset(batch)
    state = torch.as_tensor(_starts(system, batch), dtype=DTYPE)
    rest = torch.zeros(batch, 1, dtype=DTYPE)
    impulses = []
    for _ in range(steps):
        step = plant.step(state, rest)
        assert torch.equal(step.state, system.step_fn(state + step.impulse, rest))
        impulses.append(step.impulse)
        state = step.state
    return torch.stack(impulses, 1)


@pytest.mark.parametrize(
    ("name", "joint"), [("pendulum", None), ("cartpole", "x_dot"), ("acrobot", "theta2_dot")]
)
def test_pushes_come_at_the_stated_rate_with_the_stated_size(name, joint) -> None:
    system = make_system(name)
    size, rate = 0.7, 2.0
    impulses = _pushed_run(system, Push(size=size, rate=rate, joint=joint, seed=4))
    index = system.state_names.index(joint or f"{system.state_names[system.main_index]}_dot")
    others = [i for i in range(system.state_dim) if i != index]
    assert torch.equal(impulses[..., others], torch.zeros_like(impulses[..., others]))
    kicks = impulses[..., index]
    assert set(kicks.unique().tolist()) == {-size, 0.0, size}
    count, trials, chance = int((kicks != 0).sum()), kicks.numel(), rate * system.dt
    assert abs(count - trials * chance) < Z * math.sqrt(trials * chance * (1 - chance))
    negative = int((kicks < 0).sum())
    assert abs(negative - count / 2) < Z * math.sqrt(count / 4)


def test_pushes_are_seeded() -> None:
    system = make_system("pendulum")
    first = _pushed_run(system, Push(size=0.5, rate=3.0, seed=1), steps=50, batch=5)
    again = _pushed_run(system, Push(size=0.5, rate=3.0, seed=1), steps=50, batch=5)
    other = _pushed_run(system, Push(size=0.5, rate=3.0, seed=2), steps=50, batch=5)
    assert torch.equal(first, again) and not torch.equal(first, other)


# ----------------------------------------------------------------------------- gymnasium
def _everything():
    return (
        ObservationNoise(std=0.01, seed=1),
        TorqueNoise(std=0.05, seed=2),
        ActionDelay(1),
        ActuatorGain(0.9),
        Friction(viscous=0.01, coulomb=0.005),
        ParameterError("gravity", 1.05),
        Push(size=0.05, rate=1.0, seed=3),
    )


def _env_run(env, controller, start, steps, repeat, seed=None):
    obs, _ = env.reset(seed=seed, options={"state": start})
    states, observations, rewards = [start], [obs], []
    for t in range(steps):
        if t % repeat == 0:
            with torch.no_grad():
                action = controller(torch.as_tensor(obs)[None])[0].numpy()
        obs, reward, terminated, _, info = env.step(action)
        states.append(info["state"])
        observations.append(obs)
        rewards.append(reward)
        if terminated:
            break
    return np.array(states), np.array(observations), np.array(rewards)


@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("repeat", [1, 2])
def test_the_env_and_simulate_run_the_same_perturbed_plant(name, repeat) -> None:
    system = make_system(name)
    system.episode_steps = STEPS  # the env's steps left, for an exit's reward
    perturbations = _everything()
    controller = _lqr(name, repeat)
    start = _starts(system, 1, seed=5)[0] * 0.3
    env = LeocEnv(system=system, perturbations=perturbations, action_repeat=repeat)
    states, observations, rewards = _env_run(env, controller, start, STEPS, repeat)
    run = simulate(system, controller, start[None], STEPS, perturbations=perturbations)
    episode = run.episode(0)
    assert np.array_equal(states, episode.states)
    assert np.array_equal(observations, episode.observations)
    assert np.array_equal(rewards, episode.rewards)
    clean = simulate(system, controller, start[None], STEPS)
    assert not np.array_equal(states, clean.states[0, : len(states)])


def _settings(starts: np.ndarray, plants: str) -> list[tuple[np.ndarray, tuple]]:
    """Settings of simulate_settings' test: batches of different sizes, noises, a delay, pushes,
    wide starts that end early; ``plants="own"`` adds friction and parameter errors (each plant
    steps its own rows; one with friction alone sits between frictionless ones on the nominal
    system: their observation is shared, not their step), ``"errors"`` adds parameter errors
    without friction (a plant on its own system first: the nominal ones must not take its
    step), ``"one system"`` has neither (the system's work is shared)."""
    settings = [
        (starts[2:3], ()),
        (starts[1:5] * 12.0, (ObservationNoise(std=0.05, seed=7), ActionDelay(2))),
        (starts[:3], (TorqueNoise(std=0.3, seed=8), Push(size=0.5, rate=5.0, seed=9))),
        (starts[3:5], (ObservationNoise(std=0.01, seed=1), ActuatorGain(0.8))),
    ]
    if plants == "own":
        settings[0] = (starts[:2], _everything())
        settings.insert(2, (starts[1:4] * 3.0, (Friction(viscous=0.05, coulomb=0.02),)))
        settings.append((starts[:3], (ParameterError("gravity", 0.5), Push(0.5, 5.0, seed=9))))
    if plants == "errors":
        settings.insert(0, (starts[:3], (ParameterError("gravity", 0.5),)))
        settings.append((starts[1:3], (ParameterError("gravity", 1.5), ActionDelay(1))))
    return settings


@pytest.mark.parametrize("name", SYSTEMS)
@pytest.mark.parametrize("repeat", [1, 2])
@pytest.mark.parametrize("plants", ["own", "errors", "one system"])
def test_settings_run_together_are_each_run_alone(name, repeat, plants) -> None:
    """simulate_settings runs each setting's episodes on its own plant exactly as simulate runs
    them alone: batches of different sizes, their own noise and push streams, delay queues and
    constants, episodes that end early beside ones that run on. Reference: simulate, one call
    per setting; the only difference allowed is the controller's batched round-off."""
    system = make_system(name)
    system.episode_steps = STEPS
    controller = _lqr(name, repeat)
    settings = _settings(_starts(system, 5, seed=2), plants)
    together = simulate_settings(system, controller, settings, STEPS)
    assert len(together) == len(settings)
    for (rows, perturbations), batch in zip(settings, together, strict=True):
        alone = simulate(system, controller, rows, STEPS, perturbations=perturbations)
        np.testing.assert_array_equal(batch.lengths, alone.lengths)
        np.testing.assert_array_equal(batch.terminated, alone.terminated)
        for field in ("states", "observations", "actions", "rewards"):
            np.testing.assert_allclose(
                getattr(batch, field), getattr(alone, field), rtol=RTOL, atol=RTOL, err_msg=field
            )
    if name in ("cartpole", "mountaincar"):  # they end episodes: some end, others run on
        ended = np.concatenate([batch.terminated for batch in together])
        assert ended.any() and not ended.all()


def test_simulate_settings_refuses_no_settings() -> None:
    with pytest.raises(ValueError, match=r"^settings: expected at least one"):
        simulate_settings(make_system("pendulum"), _lqr("pendulum"), [])


def test_the_plants_constants_decide_where_an_episode_ends() -> None:
    """A shorter track (a parameter error on x_limit) ends the episode in the env and in
    simulate alike, with the plant's exit reward."""
    system = make_system("cartpole")
    error, start = ParameterError("x_limit", 0.05), np.array([0.119, 0.2, 0.0, 0.0])  # 0.12 m
    env = LeocEnv(system=system, perturbations=[error])
    env.reset(options={"state": start})
    _, reward, terminated, _, _ = env.step(np.zeros(1))
    run = simulate(
        system, lambda obs: torch.zeros(1, 1, dtype=DTYPE), start, 5, perturbations=[error]
    )
    short = system.with_params(x_limit=0.05)
    assert terminated and run.terminated[0] and run.lengths[0] == 1
    assert reward == short.termination_reward(system.episode_steps - 1)
    assert not simulate(system, lambda obs: torch.zeros(1, 1, dtype=DTYPE), start, 5).terminated[0]


def test_an_env_reset_with_a_seed_replays_its_perturbations() -> None:
    env = LeocEnv(system="pendulum", perturbations=_everything())
    controller, start = _lqr("pendulum"), np.array([0.05, 0.0])
    first = _env_run(env, controller, start, 30, 1, seed=8)
    second = _env_run(env, controller, start, 30, 1, seed=8)
    unseeded = _env_run(env, controller, start, 30, 1)
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    assert not np.array_equal(first[1], unseeded[1])
    assert np.isinf(env.observation_space.high).all()


# ----------------------------------------------------------------------------- the data
def test_perturbations_are_frozen_data_that_round_trip() -> None:
    for perturbation in _everything() + (Friction(viscous=0.1, joints=["theta_dot"]),):
        record = perturbation.as_dict()
        assert perturbation_from_dict(record) == perturbation
        with pytest.raises(dataclasses.FrozenInstanceError):
            perturbation.seed = 1  # type: ignore[misc]
    assert ActuatorGain(0.8).level == pytest.approx(0.2) and ActuatorGain().is_null
    assert Push(size=1.0, rate=0.0).is_null and not Push(size=1.0).is_null


@pytest.mark.parametrize(
    ("perturbations", "message"),
    [
        ([ActionDelay(1), ActionDelay(2)], "at most one ActionDelay"),
        ([ObservationNoise(std=(0.1, 0.2))], "expected 1 or 3 numbers"),
        ([Friction(viscous=1.0, joints=("x_dot",))], "expected some of"),
        ([Push(size=1.0, rate=100.0)], "rate \\* dt <= 1"),
        ([ParameterError("stiffness", 1.1)], "unknown parameter"),
    ],
)
def test_a_wrong_perturbation_is_named(perturbations, message) -> None:
    with pytest.raises(ValueError, match=message):
        PerturbedPlant(make_system("pendulum"), perturbations)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: ObservationNoise(std=-0.1), "ObservationNoise.std"),
        (lambda: ActuatorGain(gain=float("nan")), "ActuatorGain.gain"),
        (lambda: Push(size=1.0, seed=-1), "Push.seed"),
        (lambda: ParameterError("gravity", 0.0), "ParameterError.factor"),
    ],
)
def test_a_wrong_field_is_named(build, message) -> None:
    with pytest.raises(ValueError, match=message):
        build()
