"""The proved region of any controller (:func:`leoc.control.certify_controller`) against
independent references: the equilibrium of an offset controller from the pendulum's equations
of motion (scipy's brentq), the LQR's own certificate, a closed loop written here in numpy, and
Monte Carlo violations of the decrease."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.optimize
import torch

from leoc.cli import main
from leoc.control import (
    certify_controller,
    certify_lqr,
    design_lqr,
    find_equilibrium,
    lqr_closed_loop,
)
from leoc.control.proof import prove_level
from leoc.control.roa import _decrease, _uniform_ellipsoid, certify_level
from leoc.policies import HybridDesign, HybridSpec, RBFNetwork, build_hybrid
from leoc.systems import make_system

pytestmark = pytest.mark.usefixtures("single_thread")

OFFSET = 0.3
"""A constant torque (N m) added to the pendulum's LQR: its equilibrium leaves a."""
MONTE_CARLO = 20_000


class OffsetLQR:
    """``u = W o + b + c``: the LQR with a constant error, an exact fixed point off a."""

    is_hybrid = False
    action_repeat = 1

    def __init__(self, design, offset: float) -> None:
        self.W = torch.as_tensor(design.W, dtype=torch.float64)
        self.b = torch.as_tensor(design.b, dtype=torch.float64) + offset

    def __call__(self, obs):
        return obs @ self.W.T + self.b


def _pendulum():
    system = make_system("pendulum")
    return system, design_lqr(system)


def _numpy_loop(system, W: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The pendulum's held step (semi-implicit Euler, gymnasium's Pendulum-v1) under
    ``u = W o + b``, written here from its equations of motion."""
    p = system.params
    obs = np.stack([np.cos(x[:, 0]), np.sin(x[:, 0]), x[:, 1]], 1)
    torque = np.clip(obs @ W.T[:, 0] + b[0], -p.max_torque, p.max_torque)
    acc = 3 * p.gravity / (2 * p.length) * np.sin(x[:, 0]) + 3 / (p.mass * p.length**2) * torque
    speed = np.clip(x[:, 1] + p.dt * acc, -p.max_speed, p.max_speed)
    return np.stack([x[:, 0] + p.dt * speed, speed], 1)


def _offset_angle(system, design) -> float:
    """theta* of ``u = W o + b + c`` at rest: gravity's torque balances the controller's."""
    p, W, b = system.params, np.asarray(design.W)[0], float(np.asarray(design.b)[0]) + OFFSET

    def balance(theta: float) -> float:
        torque = W[0] * math.cos(theta) + W[1] * math.sin(theta) + b
        return 3 * p.gravity / (2 * p.length) * math.sin(theta) + 3 * torque / (
            p.mass * p.length**2
        )

    return scipy.optimize.brentq(balance, -0.5, 0.5, xtol=1e-15)


def test_the_equilibrium_of_an_offset_controller_is_the_closed_form_one():
    system, design = _pendulum()
    expected = _offset_angle(system, design)
    assert abs(expected) > 1e-3  # the offset moves it
    equilibrium = find_equilibrium(system, OffsetLQR(design, OFFSET))
    assert equilibrium.found and equilibrium.iterations >= 1
    np.testing.assert_allclose(equilibrium.state, [expected, 0.0], atol=1e-12)
    assert equilibrium.residual < 1e-12
    np.testing.assert_allclose(equilibrium.offset(system), [expected, 0.0], atol=1e-12)
    # The LQR's own fixed point is a itself, with no Newton step.
    exact = find_equilibrium(system, lqr_closed_loop(design))
    assert exact.found and exact.iterations == 0 and exact.residual == 0.0
    np.testing.assert_array_equal(exact.state, system.operating_state)


def test_the_lqr_as_a_controller_proves_its_own_certificate():
    system, design = _pendulum()
    reference = certify_lqr(system, design)
    proved = certify_controller(system, lqr_closed_loop(design), design, lyapunov="lqr")
    assert proved.lyapunov == "lqr" and proved.equilibrium.found
    assert math.isclose(proved.rho, reference.rho, rel_tol=1e-9)
    assert proved.certificate.proof.excluded_level == 0.0


def test_an_offset_controller_is_proved_around_its_own_equilibrium():
    # Both V are tried; the proved set is centred on x*, and a closed loop written here in
    # numpy finds no increase of V in it, nor on its boundary.
    system, design = _pendulum()
    controller = OffsetLQR(design, OFFSET)
    proved = certify_controller(system, controller, design)
    assert set(proved.candidates) == {"lqr", "own"}
    levels = {name: entry.rho for name, entry in proved.candidates.items()}
    assert all(rho > 0.0 for rho in levels.values()), levels
    # The larger ellipsoid is kept: volume ~ rho^(S/2) / sqrt(det P).
    volumes = {
        name: entry.rho / math.sqrt(np.linalg.det(entry.P))
        for name, entry in proved.candidates.items()
    }
    assert proved.lyapunov == max(volumes, key=volumes.get) and len(set(volumes.values())) == 2
    certificate = proved.certificate
    np.testing.assert_allclose(
        certificate.operating_state, [_offset_angle(system, design), 0.0], atol=1e-12
    )
    assert proved.summary(system)["limited_by"] in ("decrease", "target")
    rng = np.random.default_rng(5)
    inside = certificate.sample(rng, MONTE_CARLO)
    following = _numpy_loop(system, design.W, np.asarray(design.b) + OFFSET, inside)
    centre = certificate.operating_state
    value = np.einsum("bi,ij,bj->b", inside - centre, certificate.P, inside - centre)
    after = np.einsum("bi,ij,bj->b", following - centre, certificate.P, following - centre)
    moving = value > certificate.proof.excluded_level
    assert np.all(after[moving] < value[moving])


def test_practical_stability_off_the_fixed_point_excludes_a_ball_that_contains_it():
    # Centred on a, which the offset controller does not hold: the proof excludes a ball whose
    # level is at least V(F(a)) (epsilon >= |F~(0)|), proves the decrease outside it, and the
    # numpy loop agrees on the annulus.
    system, design = _pendulum()
    controller = OffsetLQR(design, 0.01)
    a = np.asarray(system.operating_state, dtype=float)[None]
    step = _numpy_loop(system, design.W, np.asarray(design.b) + 0.01, a)[0]
    moved = float((step - a[0]) @ design.P @ (step - a[0]))
    proof = prove_level(system, design.P, controller, 1, 20.0)
    assert proof.proved and moved <= proof.excluded_level < proof.rho
    rng = np.random.default_rng(7)
    states = a + _uniform_ellipsoid(design.P, proof.rho, MONTE_CARLO, rng)
    value = np.einsum("bi,ij,bj->b", states - a, design.P, states - a)
    following = _numpy_loop(system, design.W, np.asarray(design.b) + 0.01, states)
    after = np.einsum("bi,ij,bj->b", following - a, design.P, following - a)
    annulus = value > proof.excluded_level
    assert annulus.sum() > 0.99 * MONTE_CARLO and np.all(after[annulus] < value[annulus])


def _destabilised_hybrid(system, design, lambda_init: float):
    """The paper's hybrid whose learned part is a random RBF network of large weights: the LQR
    near a, a destabilising policy where the relevance has fallen."""
    generator = torch.Generator().manual_seed(8)
    learned = RBFNetwork(3, 1, 10, weight_std=4.0, generator=generator)
    spec = HybridSpec(r_min=None, relevance_power=1.0, lambda_init=lambda_init)
    resolved = HybridDesign(design.W, design.b, system.operating_obs, {})
    hybrid = build_hybrid(spec, resolved, learned, action_limit=2.0, saturation="clip")
    return hybrid.double().eval()


@pytest.mark.parametrize("lambda_init", [0.3, 1.0])
def test_a_destabilised_hybrid_is_proved_up_to_never_past_the_first_violation(lambda_init):
    system, design = _pendulum()
    hybrid = _destabilised_hybrid(system, design, lambda_init)
    proved = certify_controller(system, hybrid, design, lyapunov="lqr")
    # pi(a) = G(a): the equilibrium is a, up to the rounding of W o(a) + b
    assert proved.equilibrium.found and max(abs(proved.equilibrium.offset(system))) < 1e-12
    assert proved.rho < 0.1 * certify_lqr(system, design).rho  # the learned part costs it
    # Dense samples around the proved level find the first violation within a few percent.
    rng = np.random.default_rng(0)
    z = _uniform_ellipsoid(design.P, 2.0 * proved.rho, 200_000, rng)
    states = torch.as_tensor(z) + torch.as_tensor(system.operating_state)
    with torch.no_grad():
        value, violates = _decrease(
            system, torch.as_tensor(design.P), hybrid, 1, states, system.operating_state
        )
    first = float(value[violates].min())
    assert 0.9 * first < proved.rho < first


def test_an_unstable_loop_proves_nothing_and_says_why():
    system, design = _pendulum()

    def zero(obs):
        return obs[..., :1] * 0.0

    proved = certify_controller(system, zero, design)
    assert proved.equilibrium.spectral_radius > 1.0  # upright, unactuated
    # No Lyapunov matrix of its own; practical stability is tried and fails too (the pendulum
    # falls from every state near the top: no set about it is invariant).
    assert set(proved.candidates) == {"lqr", "practical"}
    assert proved.rho == 0.0 and proved.limited_by == "unstable linearisation"
    assert proved.candidates["practical"].rho == 0.0 and proved.claim == "asymptotic"
    alone = certify_controller(system, zero)  # without a design: the region's V states why
    assert set(alone.candidates) == {"region", "practical"} and alone.rho == 0.0


def test_bad_options_are_refused_in_one_line():
    system, design = _pendulum()
    controller = lqr_closed_loop(design)
    with pytest.raises(ValueError, match="lyapunov: expected one of"):
        certify_controller(system, controller, design, lyapunov="quadratic")
    with pytest.raises(ValueError, match="design: expected an LQRDesign"):
        certify_controller(system, controller, lyapunov="lqr")
    with pytest.raises(ValueError, match=r"equilibrium: expected 2 finite numbers"):
        certify_level(system, design.P, controller, equilibrium=[0.0, math.nan])


def test_roa_prove_needs_a_controller(capsys):
    assert main(["roa", "pendulum", "--prove"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--prove:" in line and "--controller" in line


@pytest.mark.slow
def test_roa_prove_reports_a_trained_runs_region(tmp_path, capsys):
    """``leoc roa --controller RUN --prove`` on a smoke-trained DDPG hybrid: its equilibrium is
    a, and its proved set, centred there, shares the box with the LQR's."""
    run = tmp_path / "ddpg_hybrid"
    args = ["train", "pendulum", "--algo", "ddpg", "--hybrid", "--profile", "smoke", "--quiet"]
    assert main([*args, "--out", str(run)]) == 0
    capsys.readouterr()
    cheap = ["--samples", "2000", "--starts", "20", "--proof-seconds", "60", "--json"]
    assert main(["roa", "--controller", str(run), "--prove", *cheap]) == 0
    report = json.loads(capsys.readouterr().out)
    (entry,) = report["proofs"].values()
    assert entry["equilibrium_found"] and max(map(abs, entry["offset"])) < 1e-12
    assert entry["rho"] > 0.0 and entry["lyapunov"] in ("lqr", "own")
    assert 0.0 < entry["box_share"] <= 1.0 and entry["lqr_box_share"] == report["box_fraction"]
    assert math.isclose(entry["box_share_ratio"], entry["box_share"] / entry["lqr_box_share"])


def test_a_box_with_an_unbounded_jacobian_fails_instead_of_raising():
    # A learned part on intervals can be soundly unbounded (a relevance whose 1 + d contains 0):
    # such a box gets no bound (+inf, it fails) and the others of its batch keep theirs.
    from leoc.control.proof import _box_bound, _Enclosure

    size = 2
    centre = torch.tensor([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0]], dtype=torch.float64)
    radius = torch.full((3, size), 0.1, dtype=torch.float64)
    jacobian = torch.zeros(3, size, size, dtype=torch.float64)
    jacobian[1, 0, 0], jacobian[2, 0, 0] = math.inf, 1e200
    zeros = torch.zeros(3, size, dtype=torch.float64)
    box = _Enclosure(zeros, zeros, jacobian, torch.zeros_like(jacobian), torch.zeros(3, dtype=bool))
    point = _Enclosure(zeros, zeros, None, None, torch.zeros(3, dtype=bool))
    bound = _box_bound(box, point, centre, radius, 0.0)
    # The map w -> 0: Delta = -|w|^2 <= -(0.9^2) on the first box.
    assert bound[0] <= -0.81 + 1e-9 and bound[0] > -1.0
    assert bound[1] == math.inf and bound[2] == math.inf
