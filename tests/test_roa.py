"""Tests of leoc.control.roa (the Lyapunov-level certificate of the LQR's region of attraction)
and of the empirical basins beside it (leoc.evaluation.basins).

The certificate is checked against independent evidence: every certified sample simulated
forward with the batched rollout converges; the sampled set has the ellipsoid's closed-form
volume; a smaller actuator limit gives a smaller set; a wrong P is rejected.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import torch

from leoc.control import certify_level, certify_lqr, design_lqr, lqr_closed_loop, state_deviation
from leoc.evaluation.basins import (
    basin_starts,
    box_fraction,
    certified_set_check,
    empirical_basin,
    slice_grid,
)
from leoc.evaluation.plots.basins import plot_basins
from leoc.systems import SYSTEM_NAMES, make_system
from leoc.systems.rollout import simulate

SAMPLES = 20_000  # per round: fast, still a violating-volume bound of 3.5e-4
CHECK_STARTS = 1000
CONVERGED_V_FRACTION = 1e-6  # V at the end of an episode, relative to rho: converged


pytestmark = pytest.mark.usefixtures("single_thread")


@functools.cache
def _cached(name: str, overrides: tuple[tuple[str, float], ...]):
    system = make_system(name, **dict(overrides)) if overrides else make_system(name)
    design = design_lqr(system)
    return system, design, certify_lqr(system, design, samples=SAMPLES, seed=1)


def _certificate(name: str, **system_overrides: float):
    return _cached(name, tuple(sorted(system_overrides.items())))


@pytest.mark.slow
@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_every_certified_sample_converges_when_simulated(name):
    system, design, certificate = _certificate(name)
    assert certificate.certified and certificate.linear_decrease
    assert certificate.violation_bound == pytest.approx(math.log(1000.0) / SAMPLES)
    starts = certificate.sample(np.random.default_rng(7), CHECK_STARTS)
    assert np.all(certificate.contains(starts))
    batch = simulate(system, lqr_closed_loop(design), starts)
    assert not batch.terminated.any()
    final = certificate.value(batch.states[:, -1])
    assert np.all(final < CONVERGED_V_FRACTION * certificate.rho)
    # V decreases along every simulated trajectory at every step (the certified property).
    values = np.stack([certificate.value(batch.states[:, t]) for t in range(3)], axis=1)
    moving = values[:, 0] > 0
    assert np.all(np.diff(values[moving], axis=1) < 0)


def test_certificate_reports_the_proof_beside_the_sampled_estimate():
    _, _, certificate = _certificate("mountaincar")
    proof = certificate.proof
    assert certificate.basis == "proved" and proof.proved
    assert certificate.rho == proof.rho <= certificate.sampled_rho == proof.target
    assert 0.0 < proof.inner_level <= certificate.rho and proof.excluded_level == 0.0
    summary = certificate.summary()
    assert summary["basis"] == "proved" and summary["proof"]["status"] == "proved"
    assert summary["sampled_rho"] == certificate.sampled_rho


# The car's set is cut by the track's end (x = 0.63 m past the hilltop) until the force is
# small enough that holding x takes more than the limit: 0.1 * 3 N holds only |x| < 0.23 m.
@pytest.mark.parametrize(
    ("name", "field", "scale"), [("pendulum", "max_torque", 0.5), ("mountaincar", "max_force", 0.1)]
)
def test_rho_shrinks_when_the_actuator_limit_shrinks(name, field, scale):
    _, design, wide = _certificate(name)
    system, narrow_design, narrow = _certificate(name, **{field: scale})  # a scale factor
    assert system.action_limit == pytest.approx(scale * make_system(name).action_limit)
    np.testing.assert_array_equal(narrow_design.P, design.P)  # same V, only the limit moved
    assert narrow.certified
    assert narrow.rho < wide.rho


def test_wrong_p_is_rejected():
    system = make_system("pendulum")
    design = design_lqr(system)
    # P of the *open-loop* weights swapped: a positive definite matrix that is no Lyapunov
    # matrix of the closed loop (its linear decrease fails along some direction).
    wrong = np.array([[1.0, -0.9], [-0.9, 1.0]])
    controller = lqr_closed_loop(design)
    checked = certify_level(system, wrong, controller, samples=SAMPLES, seed=2)
    assert not checked.linear_decrease and checked.rho == 0.0 and not checked.certified
    # The sampling alone (no linear pre-check) drives rho to 0 as well.
    sampled = certify_level(
        system, wrong, controller, samples=SAMPLES, seed=2, linear_check=False, prove=False
    )
    assert sampled.rho == 0.0


def test_bad_p_raises_naming_the_argument():
    system = make_system("pendulum")
    controller = lqr_closed_loop(design_lqr(system))
    with pytest.raises(ValueError, match="P: expected positive definite"):
        certify_level(system, np.diag([1.0, -1.0]), controller)
    with pytest.raises(ValueError, match=r"P: expected finite numbers of shape \(2, 2\)"):
        certify_level(system, np.eye(3), controller)
    with pytest.raises(ValueError, match="confidence"):
        certify_level(system, np.eye(2), controller, confidence=1.0)


def test_held_certificate_uses_the_design_period():
    system = make_system("pendulum")
    design = design_lqr(system, action_repeat=3)
    certificate = certify_lqr(system, design, samples=SAMPLES, seed=3)
    assert certificate.action_repeat == 3 and certificate.certified
    starts = certificate.sample(np.random.default_rng(4), CHECK_STARTS)
    controller = lqr_closed_loop(design)
    assert controller.action_repeat == 3
    basin = empirical_basin(system, controller, starts)
    assert basin.action_repeat == 3 and basin.fraction == 1.0


def test_box_fraction_matches_the_ellipsoid_volume():
    _, _, certificate = _certificate("cartpole")
    box = 3.0 * certificate.extent  # the ellipsoid lies inside: closed-form volume ratio
    fraction, error = box_fraction(certificate, box, samples=400_000, seed=5)
    dim = certificate.P.shape[0]
    ball = math.pi ** (dim / 2) / math.gamma(dim / 2 + 1)
    volume = ball * certificate.rho ** (dim / 2) / math.sqrt(np.linalg.det(certificate.P))
    expected = volume / np.prod(2.0 * box)
    assert abs(fraction - expected) < 4.0 * error


def test_angles_are_wrapped_in_the_deviation():
    system = make_system("pendulum")
    states = torch.tensor([[2.0 * math.pi + 0.1, 0.3], [-2.0 * math.pi - 0.1, 0.0]])
    deviation = state_deviation(system, states.double())
    torch.testing.assert_close(
        deviation, torch.tensor([[0.1, 0.3], [-0.1, 0.0]], dtype=torch.float64)
    )
    _, _, certificate = _certificate("pendulum")
    shifted = certificate.sample(np.random.default_rng(0), 10)
    shifted[:, 0] += 2.0 * math.pi
    assert np.all(certificate.contains(shifted))


def test_empirical_basin_is_batched_and_seeded():
    system = make_system("pendulum")
    design = design_lqr(system)
    starts = basin_starts(system, count=64, seed=9)
    np.testing.assert_array_equal(starts, basin_starts(system, count=64, seed=9))
    basin = empirical_basin(system, lqr_closed_loop(design), starts)
    assert basin.held.shape == (64,) and basin.terminated.shape == (64,)
    # A zero controller cannot hold the inverted pendulum from any start but the exact top.
    zero = empirical_basin(system, lambda obs: torch.zeros(obs.shape[0], 1), starts)
    assert zero.count == 0 and basin.count > 0
    # Per-start agreement with one-at-a-time simulations (independent of the batching).
    for index in range(0, 64, 16):
        single = simulate(system, lqr_closed_loop(design), starts[index])
        held = system.hold_step(single.states[0, 1:], terminated=bool(single.terminated[0]))
        assert (held is not None) == bool(basin.held[index])


def test_certified_set_check_and_plot(tmp_path):
    system, design, certificate = _certificate("pendulum")
    check = certified_set_check(system, lqr_closed_loop(design), certificate, count=200)
    assert check.fraction == 1.0
    grid = slice_grid(system, (0, 1), certificate.extent, points=9)
    assert grid.shape == (81, 2)
    basin = empirical_basin(system, lqr_closed_loop(design), grid)
    path = plot_basins(system, certificate, {"LQR": basin}, (0, 1), 9, tmp_path / "roa.png")
    assert path.is_file() and path.stat().st_size > 0
    with pytest.raises(ValueError, match="expected 10x10 slice starts"):
        plot_basins(system, certificate, {"LQR": basin}, (0, 1), 10, tmp_path / "x.png")


def test_lqr_certificates_are_cached_per_system_design_and_options():
    from leoc.control import roa

    system = make_system("pendulum")
    design = design_lqr(system)
    options = {"samples": 2000, "seed": 3, "prove": False}
    roa._CERTIFICATES.clear()
    first = certify_lqr(system, design, **options)
    # The same certificate, computed without the cache (an explicit controller bypasses it).
    direct = certify_level(
        system, design.P, lqr_closed_loop(design), action_repeat=design.action_repeat, **options
    )
    assert first.rho == direct.rho and first.rounds == direct.rounds
    # A rebuilt system and design hit the cache; callers get copies they may change.
    first.P[0, 0] = -1.0
    again = certify_lqr(make_system("pendulum"), design_lqr(make_system("pendulum")), **options)
    assert len(roa._CERTIFICATES) == 1
    np.testing.assert_array_equal(again.P, design.P)
    assert again.rho == direct.rho
    # Anything the certificate depends on changes the key: a system parameter, an option.
    heavier = make_system("pendulum", mass=2.0)
    assert certify_lqr(heavier, design, **options).rho != direct.rho
    assert certify_lqr(system, design, **{**options, "seed": 4}).rho != direct.rho
    assert len(roa._CERTIFICATES) == 3
