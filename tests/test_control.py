"""Tests of leoc.control: linearisation, LQR, observation gain and margins."""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pytest
import scipy.linalg
import torch

from leoc.control import design_lqr, linearise, observation_gain
from leoc.evaluation.rollout import rollout
from leoc.policies import LinearController
from leoc.systems import SYSTEM_NAMES, make_system
from leoc.systems.base import ObsComponent, PhysicalParams, System

FD_STEP = 1e-6


def central_differences(system: System, state: np.ndarray, action: np.ndarray):
    def f(x, u):
        return system.step(x, u)[0].numpy()

    a_matrix = np.zeros((system.state_dim, system.state_dim))
    b_matrix = np.zeros((system.state_dim, system.action_dim))
    for j in range(system.state_dim):
        e = np.zeros(system.state_dim)
        e[j] = FD_STEP
        a_matrix[:, j] = (f(state + e, action) - f(state - e, action)) / (2 * FD_STEP)
    for j in range(system.action_dim):
        e = np.zeros(system.action_dim)
        e[j] = FD_STEP
        b_matrix[:, j] = (f(state, action + e) - f(state, action - e)) / (2 * FD_STEP)
    return a_matrix, b_matrix


@pytest.mark.parametrize("name", SYSTEM_NAMES)
@pytest.mark.parametrize("at_operating_point", [True, False])
def test_autodiff_linearisation_matches_central_differences(name, at_operating_point) -> None:
    system = make_system(name)
    rng = np.random.default_rng(0)
    state = system.operating_state if at_operating_point else system.sample_start(rng) * 0.3
    action = system.u_eq if at_operating_point else np.array([0.3])
    lin = linearise(system, state, action)
    a_fd, b_fd = central_differences(system, state, action)
    np.testing.assert_allclose(lin.A_d, a_fd, atol=1e-7)
    np.testing.assert_allclose(lin.B_d, b_fd, atol=1e-7)


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_dlqr_gain_matches_scipy_riccati_and_is_stable(name) -> None:
    design = design_lqr(make_system(name))
    a_d, b_d, q, r = design.A_d, design.B_d, design.Q, design.R
    p = scipy.linalg.solve_discrete_are(a_d, b_d, q, r)
    gain = np.linalg.solve(r + b_d.T @ p @ b_d, b_d.T @ p @ a_d)
    np.testing.assert_allclose(design.K, gain, rtol=1e-8)
    np.testing.assert_allclose(design.P, p, rtol=1e-8)
    assert design.spectral_radius < 1.0
    # the open loop is unstable: the operating point needs the controller
    assert np.max(np.abs(np.linalg.eigvals(a_d))) > 1.0


@pytest.mark.parametrize("name", SYSTEM_NAMES)
@pytest.mark.parametrize("method", ["discrete", "continuous"])
def test_linear_controller_returns_nonlinear_system_to_operating_point(name, method) -> None:
    system = make_system(name)
    design = design_lqr(system, method=method)
    controller = LinearController(design.W, design.b)
    offset = np.zeros(system.state_dim)
    offset[system.main_index] = 0.1  # 0.1 rad (5.7 degrees) or 0.1 m
    trajectory = rollout(system, controller, system.operating_state + offset, steps=400)
    assert not trajectory.terminated
    final = trajectory.states[-50:]
    assert np.max(np.abs(final - system.operating_state)) < 1e-4


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_observation_gain_has_value_u_eq_and_jacobian_minus_k(name) -> None:
    system = make_system(name)
    design = design_lqr(system)
    w_matrix = torch.as_tensor(design.W)
    bias = torch.as_tensor(design.b)

    def linear_in_state(state: torch.Tensor) -> torch.Tensor:
        return system.observe(state.unsqueeze(0))[0] @ w_matrix.T + bias

    operating = torch.as_tensor(system.operating_state)
    jacobian = torch.autograd.functional.jacobian(linear_in_state, operating).numpy()
    np.testing.assert_allclose(jacobian, -design.K, atol=1e-12)
    np.testing.assert_allclose(linear_in_state(operating).numpy(), system.u_eq, atol=1e-12)


def test_observation_gain_at_a_nonzero_angle() -> None:
    """An angle operating point a != 0 still gets dG/dtheta = -K (W_sin cos a - W_cos sin a)."""

    class Tilted(type(make_system("pendulum"))):
        @property
        def operating_state(self) -> np.ndarray:
            return np.array([0.7, 0.0])

    system = Tilted()
    gain = np.array([[3.0, 1.0]])
    w_matrix, bias = observation_gain(system, gain)
    state = torch.tensor([0.7, 0.0], dtype=torch.float64)
    jac = torch.autograd.functional.jacobian(
        lambda s: system.observe(s.unsqueeze(0))[0] @ torch.as_tensor(w_matrix).T, state
    )
    np.testing.assert_allclose(jac.numpy(), -gain, atol=1e-12)
    value = system.observe(state.unsqueeze(0))[0].numpy() @ w_matrix.T + bias
    np.testing.assert_allclose(value, [0.0], atol=1e-12)


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_continuous_model_is_the_limit_of_the_discrete_linearisation(name) -> None:
    system = make_system(name)
    a_cont, b_cont = system.continuous_model()
    lin = linearise(system)
    dt = system.dt
    # Euler-type integrators: A_d = I + dt A + O(dt^2 |A|^2), B_d = dt B + O(dt^2 |A| |B|)
    bound_a = dt * np.linalg.norm(a_cont, 2) ** 2
    bound_b = dt * np.linalg.norm(a_cont, 2) * np.linalg.norm(b_cont, 2)
    assert np.max(np.abs((lin.A_d - np.eye(system.state_dim)) / dt - a_cont)) <= bound_a
    assert np.max(np.abs(lin.B_d / dt - b_cont)) <= bound_b


class Scalar(System):
    """x' = a x + b u, the hand-solvable case."""

    name = "scalar"
    params_type = PhysicalParams
    state_names = ("x",)
    obs_layout = (ObsComponent("state", 0),)
    angle_indices = ()
    main_index = 0
    main_label = "x"
    main_in_degrees = False
    settling_band = 0.01
    swing_up_centre = (1.0,)
    start_spread = (0.0,)
    default_q = (1.0,)
    default_r = (1.0,)
    coefficients: ClassVar[tuple[float, float]] = (1.2, 0.5)

    @property
    def dt(self) -> float:
        return 0.1

    @property
    def action_limit(self) -> float:
        return math.inf

    def step_fn(self, state, action):
        a, b = self.coefficients
        return a * state + b * action

    def continuous_model(self):
        a, b = self.coefficients
        return np.array([[math.log(a) / self.dt]]), np.array([[b / self.dt]])


@pytest.mark.parametrize("q, r", [(1.0, 1.0), (2.0, 0.3), (0.5, 4.0)])
def test_k_matches_the_hand_solved_scalar_riccati_equation(q, r) -> None:
    a, b = Scalar.coefficients
    # p = q + a^2 p r / (r + b^2 p)  <=>  b^2 p^2 + (r - q b^2 - a^2 r) p - q r = 0
    linear_term = r - q * b**2 - a**2 * r
    p = (-linear_term + math.sqrt(linear_term**2 + 4 * b**2 * q * r)) / (2 * b**2)
    gain = b * p * a / (r + b**2 * p)
    design = design_lqr(Scalar(), Q=[q], R=[r])
    assert design.P[0, 0] == pytest.approx(p, rel=1e-10)
    assert design.K[0, 0] == pytest.approx(gain, rel=1e-10)
    assert design.closed_loop_eigenvalues[0].real == pytest.approx(a - b * gain, rel=1e-10)
    # scalar loop: |a - k b K| < 1  <=>  k in ((a - 1) / (b K), (a + 1) / (b K))
    low, high = design.margins.gain_interval
    assert low == pytest.approx((a - 1) / (b * gain), rel=1e-9)
    assert high == pytest.approx((a + 1) / (b * gain), rel=1e-9)


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_gain_interval_brackets_stability(name) -> None:
    design = design_lqr(make_system(name))
    low, high = design.margins.gain_interval
    assert 0 < low < 1 < high
    radius = lambda k: np.max(np.abs(np.linalg.eigvals(design.A_d - k * design.B_d @ design.K)))  # noqa: E731
    assert radius(low * 1.001) < 1 < radius(low * 0.999)
    assert radius(high * 0.999) < 1 < radius(high * 1.001)
    assert design.margins.gain_margin == pytest.approx(low, rel=1e-6)
    assert 0 < design.margins.phase_margin < 180


def test_bad_weights_and_unknown_method_are_rejected() -> None:
    system = make_system("pendulum")
    with pytest.raises(ValueError, match=r"Q: expected shape \(2, 2\)"):
        design_lqr(system, Q=np.eye(3))
    with pytest.raises(ValueError, match="Q: expected positive semi-definite"):
        design_lqr(system, Q=[[1.0, 0.0], [0.0, -1.0]])
    with pytest.raises(ValueError, match="Q: expected a symmetric"):
        design_lqr(system, Q=[[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="R: expected positive definite"):
        design_lqr(system, R=[0.0])
    with pytest.raises(ValueError, match="method: expected one of"):
        design_lqr(system, method="hinf")


def test_non_stabilisable_pair_is_rejected() -> None:
    class Uncontrollable(Scalar):
        coefficients: ClassVar[tuple[float, float]] = (1.2, 0.0)

    with pytest.raises(ValueError, match="not stabilisable"):
        design_lqr(Uncontrollable())


# --- The design at a control period (action_repeat), against an independent discretisation ---

HELD_PERIODS = (1, 2, 3, 5)


class LinearPlant(Scalar):
    """x' = A x + B u with a 2-by-2 unstable A that does not commute with B B^T: the held map
    is A_N = A^N, B_N = sum_{k<N} A^k B, and a period off by one changes both."""

    name = "linear_plant"
    state_names = ("x", "x_dot")
    obs_layout = (ObsComponent("state", 0), ObsComponent("state", 1))
    swing_up_centre = (1.0, 0.0)
    start_spread = (0.0, 0.0)
    default_q = (1.0, 0.5)
    default_r = (2.0,)
    A: ClassVar[np.ndarray] = np.array([[1.05, 0.1], [0.3, 0.98]])
    B: ClassVar[np.ndarray] = np.array([[0.0], [0.1]])

    def step_fn(self, state, action):
        return state @ torch.as_tensor(self.A).T + action @ torch.as_tensor(self.B).T

    def continuous_model(self):
        return (self.A - np.eye(2)) / self.dt, self.B / self.dt


def dare_gain(a_matrix, b_matrix, q_matrix, r_matrix):
    """K = (R + B^T P B)^-1 B^T P A with P from scipy's discrete Riccati solver."""
    p = scipy.linalg.solve_discrete_are(a_matrix, b_matrix, q_matrix, r_matrix)
    return np.linalg.solve(r_matrix + b_matrix.T @ p @ b_matrix, b_matrix.T @ p @ a_matrix), p


@pytest.mark.parametrize("period", HELD_PERIODS)
def test_linear_plant_design_at_a_period_is_the_lqr_of_a_power_n_and_the_held_sum(period):
    a, b = LinearPlant.A, LinearPlant.B
    # Closed form of the zero-order hold over N steps, written out by hand (no library call).
    a_held = np.linalg.matrix_power(a, period)
    b_held = sum(np.linalg.matrix_power(a, k) @ b for k in range(period))
    q, r = np.diag(LinearPlant.default_q), np.diag(LinearPlant.default_r)
    gain, p = dare_gain(a_held, b_held, q, r)
    design = design_lqr(LinearPlant(), action_repeat=period)
    assert design.action_repeat == period
    np.testing.assert_allclose(design.A_d, a_held, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(design.B_d, b_held, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(design.K, gain, rtol=1e-8)
    np.testing.assert_allclose(design.P, p, rtol=1e-8)
    expected_poles = np.sort_complex(np.linalg.eigvals(a_held - b_held @ gain))
    np.testing.assert_allclose(np.sort_complex(design.closed_loop_eigenvalues), expected_poles)
    # Margins at the sample time N dt: |L(e^{j w T})| = 1 at the gain crossover w (rad/s) with
    # T = N dt, L(z) = K (zI - A_N)^-1 B_N, and the phase margin is 180 deg + arg L there.
    sample_time = period * LinearPlant().dt
    crossover = design.margins.gain_crossover_frequency
    z = np.exp(1j * crossover * sample_time)
    loop = (gain @ np.linalg.solve(z * np.eye(2) - a_held, b_held))[0, 0]
    assert abs(loop) == pytest.approx(1.0, rel=1e-9)
    phase = 180.0 + np.degrees(np.angle(loop))
    assert design.margins.phase_margin == pytest.approx(phase, rel=1e-9)
    # The stable gain interval's ends put a closed-loop pole of A_N - k B_N K on the unit circle.
    for factor in design.margins.gain_interval:
        radius = np.max(np.abs(np.linalg.eigvals(a_held - factor * b_held @ gain)))
        assert radius == pytest.approx(1.0, abs=1e-9)


def test_the_period_changes_the_gain_enough_for_the_tests_to_tell() -> None:
    """The checks above could not catch an ignored or off-by-one period if neighbouring
    periods gave nearly the same gain: they differ by far more than the 1e-8 tolerance."""
    gains = [design_lqr(LinearPlant(), action_repeat=n).K for n in range(1, 7)]
    for one, next_one in zip(gains[:-1], gains[1:], strict=True):
        assert np.max(np.abs(one - next_one)) > 1e-2 * np.max(np.abs(one))


def held_map_by_central_differences(system: System, period: int):
    """Jacobians of the N-step map with the action held, by iterating ``system.step`` (numpy
    in, numpy out) and central differences: independent of ``linearise`` and ``step_held``."""

    def held(x, u):
        state = np.asarray(x, dtype=float)
        for _ in range(period):
            state = system.step(state, u)[0].numpy()
        return state

    state, action = system.operating_state, system.u_eq
    a_matrix = np.zeros((system.state_dim, system.state_dim))
    b_matrix = np.zeros((system.state_dim, system.action_dim))
    for j in range(system.state_dim):
        e = np.zeros(system.state_dim)
        e[j] = FD_STEP
        a_matrix[:, j] = (held(state + e, action) - held(state - e, action)) / (2 * FD_STEP)
    for j in range(system.action_dim):
        e = np.zeros(system.action_dim)
        e[j] = FD_STEP
        b_matrix[:, j] = (held(state, action + e) - held(state, action - e)) / (2 * FD_STEP)
    return a_matrix, b_matrix


# Central differences at h = 1e-6 on these smooth maps are good to ~1e-9 absolute; the gain of
# the Riccati equation moves by about the same relative amount (the DARE is well conditioned
# here), so 1e-5 is a safe bound that still sits far below the gap between periods (> 1e-2).
HELD_GAIN_RTOL = 1e-5


@pytest.mark.parametrize("name", SYSTEM_NAMES)
@pytest.mark.parametrize("period", [2, 3])
def test_design_at_a_period_matches_scipy_on_the_finite_difference_held_map(name, period):
    system = make_system(name)
    a_held, b_held = held_map_by_central_differences(system, period)
    design = design_lqr(system, action_repeat=period)
    np.testing.assert_allclose(design.A_d, a_held, atol=1e-6)
    np.testing.assert_allclose(design.B_d, b_held, atol=1e-6)
    gain, _ = dare_gain(a_held, b_held, design.Q, design.R)
    scale = np.max(np.abs(gain))
    np.testing.assert_allclose(design.K, gain, rtol=0, atol=HELD_GAIN_RTOL * scale)
    assert design.action_repeat == period
    # Poles and margins are those of the held loop (sample time N dt), not the one-step loop.
    poles = np.sort_complex(np.linalg.eigvals(a_held - b_held @ gain))
    np.testing.assert_allclose(np.sort_complex(design.closed_loop_eigenvalues), poles, atol=1e-5)
    # The one-step gain is not a solution at this period (so ignoring the period would fail).
    one_step = design_lqr(system).K
    assert np.max(np.abs(one_step - gain)) > 100 * HELD_GAIN_RTOL * scale


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_authors_design_at_a_period_is_evaluated_on_the_held_map(name) -> None:
    """The authors' gain does not depend on the period; its poles and Lyapunov matrix do."""
    system = make_system(name)
    period = 3
    a_held, b_held = held_map_by_central_differences(system, period)
    design = design_lqr(system, method="authors", action_repeat=period)
    closed = a_held - b_held @ design.K
    poles = np.sort_complex(np.linalg.eigvals(closed))
    np.testing.assert_allclose(np.sort_complex(design.closed_loop_eigenvalues), poles, atol=1e-5)
    stage = design.Q + design.K.T @ design.R @ design.K
    # P solves closed^T P closed - P + stage = 0 (checked as a residual, not by the same solver)
    residual = closed.T @ design.P @ closed - design.P + stage
    assert np.max(np.abs(residual)) < 1e-4 * np.max(np.abs(design.P))
