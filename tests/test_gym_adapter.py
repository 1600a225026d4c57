"""The gymnasium adapter (issue 46, item 1): finite differences and identification of an env's
own step map against closed forms and autodiff, the LQR on MuJoCo's inverted pendulums, and the
one-line errors."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

from leoc.gym_adapter import (
    LQRPolicy,
    design_env_lqr,
    identify_linear,
    linearise_env,
)
from leoc.systems import make_system

# gymnasium Pendulum-v1's constants (envs/classic_control/pendulum.py)
GRAVITY, MASS, LENGTH, DT = 10.0, 1.0, 1.0, 0.05
FLOAT64_EPS = float(np.finfo(np.float64).eps)
# ulps of the float64 reference itself (a few roundings of each closed-form entry)
REFERENCE_ULPS = 4.0
# Points of Pendulum-v1 (theta = 0 upright): the operating point and one off equilibrium.
PENDULUM_POINTS = [((0.0, 0.0), (0.0,)), ((0.3, -0.5), (0.7,))]
MUJOCO_EPISODES = 100


def pendulum_closed_form(theta: float) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of Pendulum-v1's semi-implicit Euler step (speed clip inactive):
    theta_ddot = c sin(theta) + b u, theta_dot' = theta_dot + dt theta_ddot,
    theta' = theta + dt theta_dot'."""
    slope = 3.0 * GRAVITY / (2.0 * LENGTH) * math.cos(theta)
    gain = 3.0 / (MASS * LENGTH**2)
    a_matrix = np.array([[1.0 + DT**2 * slope, DT], [DT * slope, 1.0]])
    b_matrix = np.array([[DT**2 * gain], [DT * gain]])
    return a_matrix, b_matrix


def within(estimate: np.ndarray, reference: np.ndarray, bound: np.ndarray) -> bool:
    """|estimate - reference| <= bound plus the reference's own rounding, entry by entry."""
    slack = REFERENCE_ULPS * FLOAT64_EPS * np.abs(reference)
    return bool(np.all(np.abs(estimate - reference) <= bound + slack))


@pytest.mark.parametrize(("state", "action"), PENDULUM_POINTS)
def test_pendulum_v1_matches_the_closed_form_within_the_stated_bound(state, action) -> None:
    lin = linearise_env(gym.make("Pendulum-v1"), state, action)
    a_ref, b_ref = pendulum_closed_form(state[0])
    assert lin.precision == pytest.approx(FLOAT64_EPS, rel=1e-12)  # float64 state and action
    assert within(lin.A_d, a_ref, lin.error_A)
    assert within(lin.B_d, b_ref, lin.error_B)
    # the bound is informative: about eps^(2/3) (rounding of outputs of size |f| / h)
    assert lin.error_A.max() < 1e-9
    assert lin.error_B.max() < 1e-9


def test_pendulum_v1_matches_leoc_s_pendulum_by_autograd() -> None:
    system = make_system("pendulum")
    state, action = torch.zeros(2, dtype=torch.float64), torch.zeros(1, dtype=torch.float64)
    a_auto, b_auto = torch.autograd.functional.jacobian(
        lambda x, u: system.step_fn(x.unsqueeze(0), u.unsqueeze(0))[0], (state, action)
    )
    lin = linearise_env(gym.make("Pendulum-v1"), [0.0, 0.0], [0.0])
    assert within(lin.A_d, a_auto.numpy(), lin.error_A)
    assert within(lin.B_d, b_auto.numpy(), lin.error_B)


def test_float32_state_is_differenced_at_its_own_precision() -> None:
    """MountainCarContinuous-v0 keeps a float32 state: the step grows to eps32^(1/3) and the
    closed form v' = v + power u - 0.0025 cos(3 p), p' = p + v' still lies within the bound."""
    position, velocity, force = -0.5, 0.01, 0.2
    lin = linearise_env(gym.make("MountainCarContinuous-v0"), [position, velocity], [force])
    slope = 0.0075 * math.sin(3.0 * position)
    power = 0.0015
    assert lin.precision == pytest.approx(float(np.finfo(np.float32).eps), rel=1e-6)
    assert within(lin.A_d, np.array([[1.0 + slope, 1.0], [slope, 1.0]]), lin.error_A)
    assert within(lin.B_d, np.array([[power], [power]]), lin.error_B)
    assert lin.error_A.max() < 1e-3


def test_hooks_give_the_attribute_route_s_result() -> None:
    def write(env: Any, state: np.ndarray) -> None:
        env.state = np.array(state, dtype=float)

    by_hooks = linearise_env(
        gym.make("Pendulum-v1"), [0.1, 0.2], [0.3], set_state=write, get_state=lambda e: e.state
    )
    plain = linearise_env(gym.make("Pendulum-v1"), [0.1, 0.2], [0.3])
    np.testing.assert_allclose(by_hooks.A_d, plain.A_d, rtol=0.0, atol=1e-15)
    np.testing.assert_allclose(by_hooks.B_d, plain.B_d, rtol=0.0, atol=1e-15)


def test_identification_recovers_pendulum_v1_within_its_bound() -> None:
    ident = identify_linear(gym.make("Pendulum-v1"), [0.0, 0.0], [0.0], seed=3)
    a_ref, b_ref = pendulum_closed_form(0.0)
    assert within(ident.A_d, a_ref, ident.error_A)
    assert within(ident.B_d, b_ref, ident.error_B)
    assert ident.error_A.max() < 1e-5  # informative
    assert ident.residual.max() < 1e-9  # the cubic remainder at scale 5e-4
    assert ident.samples > 0


def test_identification_through_a_reset_hook_is_seeded() -> None:
    """A reset_to hook that starts the env at the target (as a simulator that can only be
    started at a state): same seed, same fit; another seed, another fit."""

    def reset_to(env: Any, target: np.ndarray) -> None:
        env.reset()
        env.state = np.array(target, dtype=float)

    env = gym.make("Pendulum-v1")
    first = identify_linear(env, [0.0, 0.0], [0.0], reset_to=reset_to, seed=5)
    again = identify_linear(env, [0.0, 0.0], [0.0], reset_to=reset_to, seed=5)
    other = identify_linear(env, [0.0, 0.0], [0.0], reset_to=reset_to, seed=6)
    np.testing.assert_allclose(first.A_d, again.A_d, rtol=0.0, atol=0.0)
    assert np.abs(first.A_d - other.A_d).max() > 0.0
    assert within(first.A_d, pendulum_closed_form(0.0)[0], first.error_A)


def test_lqr_on_pendulum_v1_matches_dlqr_and_clips() -> None:
    import control

    lin = linearise_env(gym.make("Pendulum-v1"), [0.0, 0.0], [0.0])
    design = design_env_lqr(lin, Q=[2.0, 2.0], R=[1.0])
    gain, _, _ = control.dlqr(lin.A_d, lin.B_d, np.diag([2.0, 2.0]), np.eye(1))
    np.testing.assert_allclose(design.K, gain, rtol=1e-9, atol=1e-12)
    assert np.abs(design.closed_loop_eigenvalues).max() < 1.0
    policy = LQRPolicy(design)
    assert np.abs(policy(np.zeros(2))).max() < 1e-15  # u_eq at the operating point
    np.testing.assert_allclose(policy(np.array([1e-3, 0.0])), -design.K @ [1e-3, 0.0])
    assert policy(np.array([-3.0, 0.0]))[0] == pytest.approx(2.0, abs=0.0)  # clipped


class _NoStateEnv(gym.Env):
    """A Box-action env with no state attribute and no set_state."""

    action_space = gym.spaces.Box(-1.0, 1.0, (1,))
    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        return np.zeros(2), {}

    def step(self, action):
        return np.zeros(2), 0.0, False, False, {}


class _NoisyEnv(_NoStateEnv):
    """A settable env whose step adds noise: no step map to linearise."""

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self.state = np.zeros(2)
        return super().reset(seed=seed)

    def step(self, action):
        self.state = self.state + self.np_random.normal(size=2)
        return self.state.copy(), 0.0, False, False, {}


@pytest.mark.parametrize(
    ("make", "kwargs", "message"),
    [
        (lambda: gym.make("Pendulum-v1"), {"state": [0.0, 0.0, 0.0]}, "state: expected 2"),
        (lambda: gym.make("Pendulum-v1"), {"action": [2.5]}, "action: expected inside"),
        (lambda: gym.make("Pendulum-v1"), {"action": [0.0, 0.0]}, r"action: expected shape"),
        (lambda: gym.make("Pendulum-v1"), {"step_sizes": [1e-6]}, "step_sizes: expected 3"),
        (lambda: gym.make("Pendulum-v1"), {"get_state": lambda e: e.state}, "set_state, get"),
        (lambda: gym.make("CartPole-v1"), {"state": [0.0] * 4}, "env: expected a 1-D Box"),
        (_NoStateEnv, {}, "env: expected a MuJoCo env"),
        (_NoisyEnv, {}, "env: expected a deterministic step"),
    ],
)
def test_bad_input_raises_a_one_line_error(make, kwargs, message) -> None:
    arguments = {"state": [0.0, 0.0], "action": [0.0], **kwargs}
    with pytest.raises(ValueError, match=message) as error:
        linearise_env(make(), **arguments)
    assert "\n" not in str(error.value)


def test_identification_without_a_way_to_start_raises() -> None:
    with pytest.raises(ValueError, match="reset_to, get_state: expected hooks") as error:
        identify_linear(_NoStateEnv(), [0.0, 0.0], [0.0])
    assert "\n" not in str(error.value)


def double_pendulum_state(observation: np.ndarray) -> np.ndarray:
    """InvertedDoublePendulum-v5's state from its observation ``[x, sin q1, sin q2, cos q1,
    cos q2, qvel (3, clipped at +/-10), constraint force]``: ``concat(qpos, qvel)``."""
    angles = np.arctan2(observation[1:3], observation[3:5])
    return np.concatenate([observation[:1], angles, observation[5:8]])


@pytest.mark.slow
@pytest.mark.parametrize(
    ("env_id", "state_of"),
    [("InvertedPendulum-v5", None), ("InvertedDoublePendulum-v5", double_pendulum_state)],
)
def test_mujoco_lqr_holds_every_default_start(env_id, state_of) -> None:
    """Linearised at the upright rest state (init_qpos = 0, init_qvel = 0), the LQR with
    Q = I, R = 1 (action clipped) holds all MUJOCO_EPISODES seeded episodes to the time limit;
    the identification agrees with the differences within the two bounds."""
    pytest.importorskip("mujoco")
    env = gym.make(env_id)
    base = env.unwrapped
    assert np.abs(base.init_qpos).max() < 1e-15 and np.abs(base.init_qvel).max() < 1e-15
    rest = np.zeros(base.model.nq + base.model.nv)
    lin = linearise_env(env, rest, np.zeros(env.action_space.shape))
    ident = identify_linear(env, rest, np.zeros(env.action_space.shape))
    assert np.all(np.abs(ident.A_d - lin.A_d) <= ident.error_A + lin.error_A)
    assert np.all(np.abs(ident.B_d - lin.B_d) <= ident.error_B + lin.error_B)
    policy = LQRPolicy(design_env_lqr(lin), state_of)
    failed = []
    for seed in range(MUJOCO_EPISODES):
        observation, _ = env.reset(seed=seed)
        steps, terminated, truncated = 0, False, False
        while not (terminated or truncated):
            observation, _, terminated, truncated, _ = env.step(policy(observation))
            steps += 1
        if terminated or steps < env.spec.max_episode_steps:
            failed.append(seed)
    assert failed == []
