"""Tests of the proved region of attraction (leoc.control.proof, leoc.control.intervals).

The proof is checked against evidence it does not use: the interval enclosures against dense
samples and autograd; the proved sets against a Monte Carlo of 10^6 states per system (and
states on the boundary) pushed through closed loops written here in numpy from the equations
of motion, not through leoc's step functions; deliberately wrong controllers and matrices
against the violations such a Monte Carlo finds; the mountain car's set against the track.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import torch

from leoc.control import certify_level, certify_lqr, design_lqr, lqr_closed_loop
from leoc.control.intervals import Jet, UnsupportedOperation, box_jet
from leoc.control.proof import prove_level
from leoc.control.roa import _closed_loop, describe_certificate
from leoc.systems import make_system
from leoc.systems.mountaincar import TRACK_HIGH, TRACK_LOW

SAMPLES = 20_000  # sampling rounds of the estimate the proof aims at
MONTE_CARLO = 1_000_000
BOUNDARY = 200_000


pytestmark = pytest.mark.usefixtures("single_thread")


@functools.cache
def _certified(name: str):
    system = make_system(name)
    design = design_lqr(system)
    return system, design, certify_lqr(system, design, samples=SAMPLES, seed=1)


# ---- closed loops in numpy, from the equations of motion (independent of leoc's step) ------


def _pendulum(x: np.ndarray, u: np.ndarray, p) -> tuple[np.ndarray, np.ndarray]:
    torque = np.clip(u, -p.max_torque, p.max_torque)
    acc = 3 * p.gravity / (2 * p.length) * np.sin(x[:, 0]) + 3 / (p.mass * p.length**2) * torque
    speed = np.clip(x[:, 1] + p.dt * acc, -p.max_speed, p.max_speed)
    return np.stack([x[:, 0] + p.dt * speed, speed], 1), np.zeros(len(x), bool)


def _mountaincar(x: np.ndarray, u: np.ndarray, p) -> tuple[np.ndarray, np.ndarray]:
    force = np.clip(u, -p.max_force, p.max_force)
    speed = x[:, 1] + p.dt * (force / p.mass + p.gravity * p.hill_amplitude * np.sin(x[:, 0]))
    following = np.stack([x[:, 0] + p.dt * speed, speed], 1)
    outside = (following[:, 0] < TRACK_LOW) | (following[:, 0] > TRACK_HIGH)
    return following, outside


def _cartpole(x: np.ndarray, u: np.ndarray, p) -> tuple[np.ndarray, np.ndarray]:
    force = np.clip(u, -p.max_force, p.max_force)
    total, pole = p.cart_mass + p.pole_mass, p.pole_mass * p.half_length
    cos, sin = np.cos(x[:, 2]), np.sin(x[:, 2])
    tmp = (force + pole * x[:, 3] ** 2 * sin) / total
    theta_acc = (p.gravity * sin - cos * tmp) / (
        p.half_length * (4 / 3 - p.pole_mass * cos**2 / total)
    )
    x_acc = tmp - pole * theta_acc * cos / total
    following = x + p.dt * np.stack([x[:, 1], x_acc, x[:, 3], theta_acc], 1)
    return following, np.abs(following[:, 0]) > p.x_limit


NUMPY_STEPS = {"pendulum": _pendulum, "mountaincar": _mountaincar, "cartpole": _cartpole}


def _numpy_decrease(name: str, P: np.ndarray, W: np.ndarray, b: np.ndarray, z: np.ndarray):
    """(V(z), V(F(z)), left the region) for deviations z (N, S) with u = W o(a + z) + b."""
    system = make_system(name)
    x = system.operating_state + z
    columns = []
    for kind, index in system.obs_layout:
        column = x[:, index]
        columns.append(
            np.cos(column) if kind == "cos" else np.sin(column) if kind == "sin" else column
        )
    u = np.stack(columns, 1) @ W.T[:, 0] + b[0]
    following, outside = NUMPY_STEPS[name](x, u, system.params)
    if name == "mountaincar":
        outside |= (x[:, 0] < TRACK_LOW) | (x[:, 0] > TRACK_HIGH)
    after = following - system.operating_state
    value = np.einsum("bi,ij,bj->b", z, P, z)
    return value, np.einsum("bi,ij,bj->b", after, P, after), outside


def _ellipsoid(P: np.ndarray, rho: float, count: int, rng, surface: bool) -> np.ndarray:
    direction = rng.standard_normal((count, P.shape[0]))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = 1.0 if surface else rng.uniform(size=(count, 1)) ** (1.0 / P.shape[0])
    return math.sqrt(rho) * np.linalg.solve(np.linalg.cholesky(P).T, (direction * radius).T).T


@pytest.mark.parametrize(
    "name", ["pendulum", "mountaincar", pytest.param("cartpole", marks=pytest.mark.slow)]
)
def test_monte_carlo_finds_no_violation_in_the_proved_set(name):
    system, design, certificate = _certified(name)
    assert certificate.basis == "proved" and certificate.proof.proved
    assert 0.9 * certificate.sampled_rho < certificate.rho <= certificate.sampled_rho
    rng = np.random.default_rng(11)
    inside = _ellipsoid(design.P, certificate.rho, MONTE_CARLO, rng, surface=False)
    boundary = _ellipsoid(design.P, certificate.rho, BOUNDARY, rng, surface=True)
    for z in (inside, boundary):
        value, following, outside = _numpy_decrease(name, design.P, design.W, design.b, z)
        moving = value > 0.0
        assert not outside.any()
        assert np.all(following[moving] < value[moving])


def test_the_sampled_estimate_is_no_proof_the_pendulum_shell():
    # Between the proved and the sampled level a thin shell violates the decrease (the shell
    # the sampling misses); the proof stops below it.
    system, design, certificate = _certified("pendulum")
    rng = np.random.default_rng(12)
    z = _ellipsoid(design.P, certificate.sampled_rho, BOUNDARY, rng, surface=True)
    value, following, _ = _numpy_decrease("pendulum", design.P, design.W, design.b, z)
    violating = following >= value
    assert violating.any()
    assert certificate.rho < value[violating].min()


def test_the_mountain_car_proved_set_lies_inside_the_track():
    system, _, certificate = _certified("mountaincar")
    low, high = (certificate.operating_state[0] + s * certificate.extent[0] for s in (-1, 1))
    assert TRACK_LOW < low and high <= TRACK_HIGH
    # The track end is what limits it: the sampled estimate reaches past it.
    sampled_extent = math.sqrt(certificate.sampled_rho * np.linalg.inv(certificate.P)[0, 0])
    assert sampled_extent > TRACK_HIGH
    assert certificate.proof.limited_by == "region"
    assert high == pytest.approx(TRACK_HIGH, abs=1e-4)


# All gains at 0.45: the decrease fails at a moderate level of the set; the damping gain
# (theta_dot, observation column 2) doubled: it fails next to a (P is no Lyapunov matrix of it).
@pytest.mark.parametrize(("columns", "gain_scale"), [(slice(None), 0.45), (slice(2, 3), 2.0)])
def test_a_perturbed_k_is_not_proved_where_it_fails(columns, gain_scale):
    system, design, certificate = _certified("pendulum")
    wrong = lqr_closed_loop(design)
    wrong.W = wrong.W.clone()
    wrong.W[:, columns] *= gain_scale
    rng = np.random.default_rng(13)
    z = _ellipsoid(design.P, certificate.rho, MONTE_CARLO, rng, surface=False)
    value, following, _ = _numpy_decrease("pendulum", design.P, wrong.W.numpy(), wrong.b.numpy(), z)
    violating = (following >= value) & (value > 0.0)
    assert violating.any()  # the perturbation really breaks the certificate
    proof = prove_level(system, design.P, wrong, 1, certificate.rho)
    assert proof.rho < value[violating].min()
    below = value <= proof.rho
    assert not violating[below].any()


def test_a_perturbed_p_is_not_proved_where_it_fails():
    system, design, certificate = _certified("cartpole")
    rotation = np.eye(4)
    rotation[2, 3] = rotation[3, 2] = 0.35  # couple theta and theta_dot differently
    wrong = rotation @ design.P @ rotation
    proof = prove_level(system, wrong, lqr_closed_loop(design), 1, certificate.rho)
    rng = np.random.default_rng(14)
    z = _ellipsoid(wrong, certificate.rho, MONTE_CARLO, rng, surface=False)
    value, following, outside = _numpy_decrease("cartpole", wrong, design.W, design.b, z)
    violating = ((following >= value) | outside) & (value > 0.0)
    assert violating.any()
    assert proof.rho < value[violating].min()
    assert not violating[value <= proof.rho].any()


# The inner ball reaches a target level t through cover = sqrt(t) / (1 - e) and back through
# (1 - e)^2 cover^2 (``prove_level``, e the frame error): about six roundings of at most one
# unit of roundoff u = eps / 2 each, so the level comes back within 4 eps of t relative. Which
# side of t it lands on depends on the BLAS kernel (e comes from a Cholesky factor and an
# inverse): 0.39439789566064754 against 0.3943978956606476 on one Intel Xeon kernel.
LEVEL_ROUNDING = 4 * np.finfo(float).eps


def test_a_small_target_is_proved_whole_by_the_linearisation():
    system, design, certificate = _certified("pendulum")
    target = 0.5 * certificate.proof.inner_level
    proof = prove_level(system, design.P, lqr_closed_loop(design), 1, target)
    assert proof.limited_by == "target"
    # The proof never claims past its target, and reaches it to rounding.
    assert proof.rho <= target
    assert proof.rho == pytest.approx(target, rel=LEVEL_ROUNDING, abs=0)
    # The whole of it comes from the inner ball (the linearisation argument).
    assert proof.inner_level == proof.rho and proof.unproved_boxes == 0


def test_an_operation_without_interval_rule_is_reported_not_proved():
    system, design, certificate = _certified("pendulum")
    controller = lqr_closed_loop(design)

    def exotic(obs):
        return torch.exp(obs[..., :1]) - 1.0

    proof = prove_level(system, design.P, exotic, 1, certificate.rho)
    assert not proof.proved and proof.limited_by == "unsupported" and "exp" in proof.reason
    assert controller is not None


def test_certificate_without_proof_says_sampled():
    system = make_system("pendulum")
    design = design_lqr(system)
    sampled = certify_level(
        system, design.P, lqr_closed_loop(design), samples=SAMPLES, seed=1, prove=False
    )
    assert sampled.basis == "sampled" and sampled.rho == sampled.sampled_rho
    assert "SAMPLED estimate, not proved" in describe_certificate(system, sampled)[0]
    _, _, proved = _certified("pendulum")
    assert proved.sampled_rho == sampled.sampled_rho
    assert describe_certificate(system, proved)[0].startswith(f"rho = {proved.rho:.6g} (PROVED")


# ---- the interval evaluator against samples ----------------------------------------------


@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar", "acrobot"])
def test_closed_loop_enclosures_contain_sampled_values_and_jacobians(name):
    system = make_system(name)
    design = design_lqr(system)
    controller = lqr_closed_loop(design)
    rng = np.random.default_rng(3)
    size = system.state_dim
    centre = torch.as_tensor(rng.normal(scale=0.3, size=(64, size)))
    radius = torch.as_tensor(rng.uniform(0.001, 0.05, size=(64, size)))
    operating = torch.as_tensor(system.operating_state)
    with torch.no_grad():
        jet = box_jet(centre, radius) + operating
        obs = system.observation.observe(jet)
        following = system.step_fn(jet, controller(obs))
    for _ in range(8):
        corner = rng.choice([-1.0, 1.0], size=(64, size)) * rng.uniform(0.5, 1.0, (64, 1))
        points = (centre + torch.as_tensor(corner) * radius).requires_grad_(True)
        states, _ = _closed_loop(system, controller, 1, points + operating)
        jacobian = torch.stack(
            [
                torch.autograd.grad(states[:, i].sum(), points, retain_graph=True)[0]
                for i in range(size)
            ],
            1,
        )
        assert torch.all((states.detach() - following.mid).abs() <= following.rad)
        assert torch.all((jacobian - following.dmid).abs() <= following.drad)


@pytest.mark.parametrize(
    "function",
    [
        torch.sin,
        torch.cos,
        torch.tanh,
        torch.abs,
        lambda x: torch.clamp(x, -0.3, 0.2),
        lambda x: 1.0 / (x + 3.0),
        lambda x: x**2,
        lambda x: x**3 - 2.0 * x,
    ],
)
def test_elementary_enclosures_contain_every_sampled_value(function):
    rng = np.random.default_rng(4)
    centre = torch.as_tensor(rng.uniform(-2.0, 2.0, size=(200, 1)))
    radius = torch.as_tensor(rng.uniform(0.0, 1.0, size=(200, 1)))
    enclosure = function(box_jet(centre, radius))
    offsets = torch.as_tensor(np.linspace(-1.0, 1.0, 401))
    points = (centre + offsets * radius).reshape(-1, 1).requires_grad_(True)
    values = function(points)
    (slopes,) = torch.autograd.grad(values.sum(), points)
    values, slopes = values.detach().reshape(200, -1), slopes.reshape(200, -1)
    assert torch.all((values - enclosure.mid).abs() <= enclosure.rad)
    assert torch.all((slopes - enclosure.dmid[..., 0]).abs() <= enclosure.drad[..., 0])
    # Not vacuous: the sampled range fills a good part of the enclosure where the function is
    # not flat (x^3 - 2 x pays the dependency of interval products, about a third).
    spread = values.max(1).values - values.min(1).values
    varying = enclosure.rad[:, 0] > 1e-12
    assert torch.median(spread[varying] / (2.0 * enclosure.rad[varying, 0])) > 0.3


def test_unsupported_operations_raise():
    jet = box_jet(torch.zeros(2, 1, dtype=torch.float64), torch.ones(2, 1, dtype=torch.float64))
    with pytest.raises(UnsupportedOperation, match="exp"):
        torch.exp(jet)
    with pytest.raises(UnsupportedOperation, match="exponents"):
        jet**0.5
    assert isinstance(jet * 2.0 + torch.ones(1, dtype=torch.float64), Jet)
