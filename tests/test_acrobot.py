"""The acrobot, built only through the System protocol: dynamics, linearisation, LQR, env."""

from __future__ import annotations

import dataclasses
import itertools
import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

from leoc.control import design_lqr
from leoc.control.lqr import linearise
from leoc.systems import make_env, make_system
from leoc.systems.acrobot import Acrobot, AcrobotParams, acrobot_derivative, acrobot_energy

DTYPE = torch.float64
# Energy test: RK4 at dt = 1 ms has a local error O(dt^5); over 1 s from a state with ~20 J of
# kinetic and potential energy swings the drift is far below 1e-6 J.
ENERGY_DT = 1e-3
ENERGY_STEPS = 1000
ENERGY_ATOL = 1e-6
FD_STEP = 1e-6
FD_RTOL = 1e-6
FD_ATOL = 1e-7
SETTLED_ATOL = 1e-6


def test_registered_and_valid() -> None:
    system = make_system("acrobot")
    assert isinstance(system, Acrobot)
    system.validate()
    assert system.angle_indices == (0, 1)
    assert system.obs_dim == 6


def test_energy_is_conserved_without_torque() -> None:
    """An independent check of the equations of motion: they are the Lagrange equations of
    acrobot_energy, so with no torque (and no damping in the model) the energy is constant."""
    params = AcrobotParams(dt=ENERGY_DT)
    system = Acrobot(params)
    state = torch.tensor([[2.0, -1.0, 1.5, -2.0], [0.3, 2.5, 0.0, 3.0]], dtype=DTYPE)
    energy = acrobot_energy(state, params)
    action = torch.zeros(2, 1, dtype=DTYPE)
    for _ in range(ENERGY_STEPS):
        state = system.step_fn(state, action)
    torch.testing.assert_close(acrobot_energy(state, params), energy, atol=ENERGY_ATOL, rtol=0)
    # and a torque does work: the energy changes at the rate tau * theta2_dot
    start = torch.tensor([[0.5, 0.2, 0.0, 1.0]], dtype=DTYPE)
    torque = torch.tensor([2.0], dtype=DTYPE)
    rate = torch.func.jvp(
        lambda x: acrobot_energy(x, params), (start,), (acrobot_derivative(start, torque, params),)
    )[1]
    torch.testing.assert_close(rate, torque * start[:, 3])


def test_gravity_pulls_down_from_upright() -> None:
    """theta1 measured from upright: a small tilt grows, a hanging rest state stays."""
    system = make_system("acrobot")
    tilted = system.step([0.01, 0.0, 0.0, 0.0], [0.0])[0]
    assert tilted[2] > 0  # falls further in the direction of the tilt
    hanging = system.step([math.pi, 0.0, 0.0, 0.0], [0.0])[0]
    np.testing.assert_allclose(hanging.numpy(), [math.pi, 0, 0, 0], atol=1e-12)


def test_linearisation_matches_finite_differences() -> None:
    system = make_system("acrobot")
    linearisation = linearise(system)
    a_matrix, b_matrix = linearisation.A_d, linearisation.B_d
    operating = system.operating_state
    numeric_a = np.zeros((4, 4))
    for index in range(4):
        step = np.zeros(4)
        step[index] = FD_STEP
        plus = system.step(operating + step, system.u_eq)[0].numpy()
        minus = system.step(operating - step, system.u_eq)[0].numpy()
        numeric_a[:, index] = (plus - minus) / (2.0 * FD_STEP)
    plus = system.step(operating, system.u_eq + FD_STEP)[0].numpy()
    minus = system.step(operating, system.u_eq - FD_STEP)[0].numpy()
    numeric_b = ((plus - minus) / (2.0 * FD_STEP))[:, None]
    np.testing.assert_allclose(a_matrix, numeric_a, rtol=FD_RTOL, atol=FD_ATOL)
    np.testing.assert_allclose(b_matrix, numeric_b, rtol=FD_RTOL, atol=FD_ATOL)
    # the continuous model (autodiff of the vector field) is the dt -> 0 limit of A_d, B_d
    a_cont, b_cont = system.continuous_model()
    np.testing.assert_allclose((a_matrix - np.eye(4)) / system.dt, a_cont, rtol=0.2, atol=0.5)
    np.testing.assert_allclose(b_matrix / system.dt, b_cont, rtol=0.2, atol=0.5)


def test_lqr_stabilises_the_nonlinear_closed_loop_from_the_operating_region() -> None:
    system = make_system("acrobot")
    design = design_lqr(system)
    assert design.spectral_radius < 1.0
    gain = torch.as_tensor(design.K)
    corners = torch.tensor(list(itertools.product([-1.0, 1.0], repeat=4)), dtype=DTYPE)
    state = corners * torch.as_tensor(system.operating_region, dtype=DTYPE)
    for _ in range(system.episode_steps):
        state = system.step_fn(state, -(state @ gain.T))
    torch.testing.assert_close(state, torch.zeros_like(state), atol=SETTLED_ATOL, rtol=0)
    # through the observation gain G(o) = W o + b as the hybrid uses it
    obs = system.observe(torch.tensor([0.01, -0.01, 0.0, 0.02], dtype=DTYPE))
    state_gain = -(torch.tensor([0.01, -0.01, 0.0, 0.02], dtype=DTYPE) @ gain.T)
    obs_gain = obs @ torch.as_tensor(design.W).T + torch.as_tensor(design.b)
    torch.testing.assert_close(obs_gain[0], state_gain, atol=1e-3, rtol=0)


def test_env_passes_the_checker_and_scaled_params() -> None:
    env = gym.make("leoc/Acrobot-v0")
    check_env(env.unwrapped)
    obs, info = env.reset(seed=0)
    assert obs.shape == (6,) and abs(info["state"][0] - math.pi) <= math.radians(10.0)
    heavy = make_system("acrobot", mass=2.0)
    assert heavy.params.link_mass_1 == heavy.params.link_mass_2 == 2.0
    direct = make_env(heavy)
    assert direct.unwrapped.system is heavy
    assert dataclasses.asdict(make_env("acrobot").unwrapped.system.params)["max_torque"] == 5.0


@pytest.mark.parametrize("kind", ["operating_point", "swing_up"])
def test_hold_test_and_starts(kind: str) -> None:
    system = make_system("acrobot")
    start = system.sample_start(np.random.default_rng(0), kind)
    assert start.shape == (4,)
    states = np.zeros((60, 4))
    assert system.hold_step(states) == 0


PILCO_TINY = dict(
    horizon=4,
    policy_iterations=2,
    num_basis=4,
    episode_steps=24,
    initial_rollouts=1,
    gp_train_iterations=3,
    eval_episodes=1,
)


def test_pilco_hybrid_trains_on_the_acrobot(tmp_path) -> None:
    from leoc.pilco.train import train_pilco

    # no floor on Lambda: the floor needs the LQR's proved region at PILCO's period, whose proof
    # takes 2-8 minutes on the acrobot (the slow workflow matrix trains the floored default)
    result = train_pilco(
        "acrobot",
        hybrid=True,
        r_min=None,
        run_dir=tmp_path,
        iterations=1,
        progress=False,
        **PILCO_TINY,
    )
    assert [row["iteration"] for row in result.curve] == [0, 1]
    # the hybrid equals the LQR at the operating point: it holds an upright start
    states = np.zeros((1, 4))
    with torch.no_grad():
        action = result.policy(make_system("acrobot").observe(torch.as_tensor(states)))
    assert abs(float(action[0, 0])) < 1e-9


def test_cli_trains_a_td3_hybrid_on_the_acrobot(tmp_path) -> None:
    from leoc.cli import main

    out = tmp_path / "td3"
    assert (
        main(
            [
                "train",
                "acrobot",
                "--algo",
                "td3",
                "--hybrid",
                "--r-min",
                "none",  # no proof of the acrobot's region (minutes; see above)
                "--steps",
                "200",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    assert (out / "curve.csv").is_file() and (out / "model.zip").is_file()
