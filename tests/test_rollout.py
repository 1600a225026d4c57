"""Tests of the closed-loop rollouts and the response tests."""

from __future__ import annotations

import control
import numpy as np
import pytest
import torch

from leoc.control import design_lqr
from leoc.evaluation.metrics import response_metrics
from leoc.evaluation.rollout import (
    IMPULSE_MAGNITUDE,
    STEP_MAGNITUDE,
    hold_step,
    holds,
    response_offsets,
    response_test,
    rollout,
)
from leoc.policies import HybridPolicy, LinearController, MLPActor, lqr_controller
from leoc.systems import SYSTEM_NAMES, make_system
from leoc.systems.rollout import control_period, simulate


@pytest.mark.parametrize("name", SYSTEM_NAMES)
@pytest.mark.parametrize("test", ["impulse", "step"])
def test_small_response_follows_the_linearised_closed_loop(name, test) -> None:
    """The nonlinear response to a small disturbance matches the discrete linear closed loop
    x' = (A_d - B_d K) x + B_d w simulated with python-control, to second order."""
    system = make_system(name)
    design = design_lqr(system)
    result = response_test(system, LinearController(design.W, design.b), test, steps=200)
    offsets = response_offsets(test, 200)[:, 0]
    closed = control.ss(
        design.A_d - design.B_d @ design.K, design.B_d, np.eye(system.state_dim), 0, system.dt
    )
    linear = control.forced_response(closed, U=offsets, X0=np.zeros(system.state_dim))
    main = linear.states[system.main_index]
    main = np.degrees(main) if system.main_in_degrees else main
    peak = np.max(np.abs(main))
    # the nonlinear terms are O(peak^2) relative: compare with a tolerance of that order
    np.testing.assert_allclose(result.deviation[:200], main, atol=0.05 * peak)


def test_impulse_and_step_offsets() -> None:
    impulse = response_offsets("impulse", 5)
    step = response_offsets("step", 5)
    np.testing.assert_array_equal(impulse[:, 0], [IMPULSE_MAGNITUDE, 0, 0, 0, 0])
    np.testing.assert_array_equal(step[:, 0], [STEP_MAGNITUDE] * 5)
    with pytest.raises(ValueError, match="test: expected one of"):
        response_offsets("ramp", 5)


def test_the_response_applies_the_disturbance_to_the_action() -> None:
    system = make_system("pendulum")
    zero = LinearController(np.zeros((1, 3)))
    result = response_test(system, zero, "step", steps=3)
    np.testing.assert_allclose(result.trajectory.actions[:, 0], [STEP_MAGNITUDE] * 3)
    result = response_test(system, zero, "impulse", steps=3)
    np.testing.assert_allclose(result.trajectory.actions[:, 0], [IMPULSE_MAGNITUDE, 0, 0])
    # deviation in degrees after the first step of -1 N m: theta_1 = dt^2 * 3 u / (m l^2)
    assert result.deviation[1] == pytest.approx(np.degrees(0.05**2 * 3 * IMPULSE_MAGNITUDE))


def test_rollout_records_relevance_of_a_hybrid_and_reward_matches_the_env() -> None:
    system = make_system("pendulum")
    design = design_lqr(system)
    torch.manual_seed(0)
    hybrid = HybridPolicy(
        LinearController(design.W, design.b),
        MLPActor(3, 1, (16,)),
        system.operating_obs,
        action_limit=system.action_limit,
    )
    start = np.array([0.5, 0.0])
    trajectory = rollout(system, hybrid, start, steps=20)
    assert trajectory.relevance is not None and trajectory.relevance.shape == (20,)
    obs = torch.as_tensor(trajectory.observations[:20])
    np.testing.assert_allclose(trajectory.relevance, hybrid.relevance(obs).detach().numpy()[:, 0])
    from leoc.systems import make_env

    env = make_env("pendulum")
    env.reset(options={"state": start})
    rewards = [env.step(a)[1] for a in trajectory.actions]
    np.testing.assert_allclose(trajectory.rewards, rewards, rtol=1e-12)


def test_hybrid_response_equals_linear_response_to_first_order() -> None:
    """The paper's claim: at the operating point the hybrid responds like the LQR."""
    system = make_system("pendulum")
    design = design_lqr(system)
    linear = LinearController(design.W, design.b)
    torch.manual_seed(1)
    hybrid = HybridPolicy(
        linear,
        MLPActor(3, 1, (32,)),
        system.operating_obs,
        lambda_init=1.0,
        action_limit=system.action_limit,
    )
    ours = response_test(system, hybrid, "impulse")
    reference = response_test(system, linear, "impulse")
    peak = np.max(np.abs(reference.deviation))
    assert np.max(np.abs(ours.deviation - reference.deviation)) < 0.1 * peak
    assert abs(ours.metrics.steady_state_error) < 1e-6


def test_hold_test_on_real_episodes() -> None:
    system = make_system("pendulum")
    corner = np.asarray(system.operating_region)  # theta and theta_dot both outward
    design = design_lqr(system)
    linear = LinearController(design.W, design.b)
    held = rollout(system, linear, corner)
    assert hold_step(system, held) is not None and holds(system, held)
    # without torque the pendulum falls from the same start: not held
    falls = rollout(system, lambda obs: torch.zeros(obs.shape[0], 1, dtype=obs.dtype), corner)
    assert hold_step(system, falls) is None
    # an episode cut short by termination never holds, even if it ends inside the band
    cartpole = make_system("cartpole")
    start = np.array([2.39, 5.0, 0.0, 0.0])  # leaves the track within a few steps
    gone = rollout(cartpole, lambda obs: torch.zeros(obs.shape[0], 1, dtype=obs.dtype), start)
    assert gone.terminated and hold_step(cartpole, gone) is None


def test_metrics_of_response_use_the_relative_band_or_the_given_band() -> None:
    system = make_system("cartpole")
    design = design_lqr(system)
    controller = LinearController(design.W, design.b)
    result = response_test(system, controller, "impulse")
    e = result.deviation
    assert result.metrics.band == pytest.approx(0.02 * np.max(np.abs(e - e[-20:].mean())))
    assert result.metrics == response_metrics(e, dt=system.dt)
    assert result.metrics.settling_time > 0
    assert result.metrics.settling_seconds == pytest.approx(result.metrics.settling_time * 0.02)
    absolute = response_test(system, controller, "impulse", band=system.settling_band)
    assert absolute.metrics == response_metrics(e, system.settling_band, dt=system.dt)


def test_a_controller_keeps_its_control_period_in_the_rollout() -> None:
    system = make_system("cartpole")
    held = lqr_controller(design_lqr(system, action_repeat=3))
    assert control_period(held) == 3
    trajectory = rollout(system, held, np.asarray(system.operating_region))
    actions = trajectory.actions[:, 0]
    # the action changes only at decisions (every third step) and is constant in between
    changes = np.flatnonzero(np.diff(actions) != 0.0) + 1
    assert changes.size > 0 and np.all(changes % 3 == 0)
    # the same controller asked every step would act differently
    every_step = rollout(system, held, np.asarray(system.operating_region), action_repeat=1)
    assert not np.allclose(every_step.actions, trajectory.actions)


def test_batched_simulation_equals_one_rollout_per_start() -> None:
    system = make_system("cartpole")
    controller = lqr_controller(design_lqr(system))
    starts = np.array([[0.1, 0.0, 0.1, 0.0], [2.3, 3.0, 0.0, 0.0], [-0.2, 0.1, -0.1, 0.2]])
    batch = simulate(system, controller, starts, steps=60)
    assert batch.terminated.tolist() == [False, True, False]
    for index, start in enumerate(starts):
        single = rollout(system, controller, start, steps=60)
        episode = batch.episode(index)
        np.testing.assert_allclose(episode.states, single.states, rtol=0, atol=1e-12)
        np.testing.assert_allclose(episode.rewards, single.rewards, rtol=0, atol=1e-12)
        assert episode.terminated == single.terminated
    # a terminated start is frozen: no reward after its end; at it, the out-of-bounds reward
    # for that step and each of the 60 - length steps it would still have run
    length = int(batch.lengths[1])
    assert batch.rewards[1, length - 1] == pytest.approx(
        system.out_of_bounds_reward * (61 - length)
    )
    assert np.all(batch.rewards[1, length:] == 0.0)


@pytest.mark.parametrize("name", ["cartpole", "mountaincar"])
def test_no_reward_inside_the_track_is_worse_than_the_out_of_bounds_reward(name) -> None:
    """The per-step out-of-bounds reward is at most every reward on the track (a dense grid of
    positions and angles, speeds 0 for the mountain car whose reward grows with speed, every
    force), and equals the worst one, so leaving never pays and the penalty is no harsher."""
    system = make_system(name)
    forces = torch.linspace(-system.action_limit, system.action_limit, 11, dtype=torch.float64)
    if name == "cartpole":
        limit = system.params.x_limit
        grid = torch.cartesian_prod(
            torch.linspace(-limit, limit, 41, dtype=torch.float64),
            torch.linspace(-3.0, 3.0, 5, dtype=torch.float64),
            torch.linspace(-np.pi, np.pi, 73, dtype=torch.float64),
            torch.linspace(-3.0, 3.0, 5, dtype=torch.float64),
        )
    else:
        from leoc.systems.mountaincar import TRACK_HIGH, TRACK_LOW

        positions = torch.linspace(TRACK_LOW, TRACK_HIGH, 201, dtype=torch.float64)
        grid = torch.stack([positions, torch.zeros_like(positions)], dim=-1)
    assert not bool(system.out_of_bounds(grid).any())
    rewards = torch.stack([system.reward_fn(grid, f.expand(len(grid), 1)) for f in forces])
    assert float(rewards.min()) >= system.out_of_bounds_reward
    assert float(rewards.min()) == pytest.approx(system.out_of_bounds_reward, rel=1e-12)


@pytest.mark.parametrize("name", ["cartpole", "mountaincar"])
def test_leaving_the_track_early_never_beats_doing_nothing(name) -> None:
    """From the swing-up start, a full push that leaves the track returns less than no force
    for the whole episode (hanging down / standing in the valley), in simulate and in the
    gymnasium environment alike; the one-off -100 of before returned more."""
    from leoc.systems import make_env

    system = make_system(name)
    start = np.asarray(system.swing_up_centre)
    push = 1.0 if name == "cartpole" else -1.0  # the mountain car's short way out is leftwards

    def pushing(obs):
        return np.full((len(obs), 1), push * system.action_limit)

    def idle(obs):
        return np.zeros((len(obs), 1))

    steps = system.episode_steps
    leaving = rollout(system, pushing, start, steps=steps)
    staying = rollout(system, idle, start, steps=steps)
    assert leaving.terminated and not staying.terminated
    assert leaving.steps < steps // 2
    assert leaving.total_reward < staying.total_reward
    assert -100.0 + leaving.rewards[:-1].sum() > staying.total_reward  # the old penalty paid
    env = make_env(name)
    env.reset(seed=0, options={"state": start})
    returns, done = 0.0, False
    while not done:
        _, reward, terminated, truncated, _ = env.step(np.array([push * system.action_limit]))
        returns += reward
        done = terminated or truncated
    assert terminated
    assert returns == pytest.approx(leaving.total_reward, rel=1e-9)


@pytest.mark.parametrize("name", ["cartpole", "mountaincar"])
def test_a_horizon_exit_costs_a_whole_episode_at_any_time_and_never_pays(name) -> None:
    """``StepRules(horizon_exit=True)``: leaving the track at any step earns the out-of-bounds
    reward for ``episode_steps`` steps, the same in simulate and the gymnasium environment;
    leoc's own rule charges the steps left; a rollout longer than an episode charges its own
    steps left, so that leaving still never pays."""
    from leoc.systems import StepRules, make_env

    system = make_system(name).with_rules(StepRules(horizon_exit=True))
    push = 1.0 if name == "cartpole" else -1.0

    def pushing(obs):
        return np.full((len(obs), 1), push * system.action_limit)

    whole = system.out_of_bounds_reward * system.episode_steps
    start = np.asarray(system.swing_up_centre)
    for steps in (system.episode_steps, 60):  # leaving at the same step, with 200 or 60 steps
        exit_ = rollout(system, pushing, start, steps=steps)
        assert exit_.terminated
        assert exit_.rewards[-1] == pytest.approx(whole, rel=1e-12)
        leoc = rollout(make_system(name), pushing, start, steps=steps)
        left = steps - leoc.steps
        assert leoc.rewards[-1] == pytest.approx(system.out_of_bounds_reward * (1 + left))
    staying = rollout(system, lambda obs: np.zeros((len(obs), 1)), start)
    assert rollout(system, pushing, start).total_reward < staying.total_reward
    longer = 3 * system.episode_steps
    late = rollout(system, pushing, start, steps=longer)
    assert late.rewards[-1] == pytest.approx(
        system.out_of_bounds_reward * (longer - late.steps + 1), rel=1e-12
    )
    env = make_env(system)
    env.reset(seed=0, options={"state": start})
    rewards, terminated = [], False
    while not terminated:
        _, reward, terminated, _, _ = env.step(np.array([push * system.action_limit]))
        rewards.append(reward)
    np.testing.assert_allclose(rewards, rollout(system, pushing, start).rewards, rtol=1e-12)
    with pytest.raises(ValueError, match="horizon_exit"):
        StepRules(exit_penalty=-100.0, horizon_exit=True)
    with pytest.raises(ValueError, match="horizon_exit"):
        StepRules(horizon_exit=1)
