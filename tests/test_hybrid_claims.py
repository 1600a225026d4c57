"""Tests of the hybrid-against-LQR comparisons that can fail: the impulse sweep, the shells of
V, the basins relative to the LQR's, and their report section.

References are independent: offsets against the paper's impulse and their integral; the
failure size against direct rollouts just below and at it; shell samples against their V and
the uniform law of V^(S/2); a hybrid whose learned part is its own LQR (pi = G everywhere, so
every share must match the LQR's while most outer starts leave the flat top) and one whose
learned part pushes away (it must lose starts the LQR holds).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch

from leoc.control import certify_lqr, design_lqr
from leoc.evaluation.basins import basin_comparison, default_basin_box, shell_levels, shell_starts
from leoc.evaluation.hybrid_claims import flat_top_level, hybrid_claims, operating_region_corners
from leoc.evaluation.impulse_sweep import (
    ImpulsePoint,
    impulse_offsets,
    lqr_failure_size,
    pulse_amplitude,
    sweep_sizes,
)
from leoc.evaluation.rollout import response_offsets
from leoc.experiments.claims_report import hybrid_claims_section
from leoc.policies import HeldPolicy, LinearController, lqr_controller, roa_hybrid
from leoc.systems import make_system
from leoc.systems.rollout import hold_step, rollout

SAMPLES = 20_000


pytestmark = pytest.mark.usefixtures("single_thread")


@functools.cache
def _pendulum():
    system = make_system("pendulum")
    design = design_lqr(system)
    return system, design, certify_lqr(system, design, samples=SAMPLES, seed=0)


class _Push(torch.nn.Module):
    """A learned part that pushes the pendulum over: full torque along theta."""

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return 2.0 * torch.sign(obs[..., 1:2])


def test_paper_size_offsets_are_the_paper_impulse_and_integrate_to_the_size():
    np.testing.assert_array_equal(impulse_offsets(1.0, 200, 4.0), response_offsets("impulse", 200))
    offsets = impulse_offsets(10.5, 200, 4.0)
    assert offsets.sum() == pytest.approx(-10.5)
    np.testing.assert_array_equal(offsets[:3, 0], [-4.0, -4.0, -2.5])
    assert not offsets[3:].any()
    with pytest.raises(ValueError, match="size: expected at most 800"):
        impulse_offsets(801.0, 200, 4.0)
    with pytest.raises(ValueError, match="size: expected a positive finite"):
        impulse_offsets(-1.0, 200, 4.0)


def test_lqr_failure_size_separates_held_from_fallen_rollouts():
    system, design, _ = _pendulum()
    lqr = lqr_controller(design)
    failure = lqr_failure_size(system, lqr)
    assert np.isfinite(failure) and failure > 1.0
    amplitude = pulse_amplitude(system)

    def held(size: float) -> bool:
        offsets = impulse_offsets(size, 200, amplitude)
        return (
            hold_step(system, rollout(system, lqr, system.operating_state, 200, offsets))
            is not None
        )

    assert not held(failure)
    assert held(failure / 1.06)  # within the bisection's 5 % below the failure size
    sizes = sweep_sizes(failure)
    assert sizes[0] == 1.0 and sizes[-1] == pytest.approx(failure)


def test_shell_starts_lie_in_their_shell_with_uniform_volume():
    _, design, certificate = _pendulum()
    rng = np.random.default_rng(0)
    low, high = certificate.rho, 3.0 * certificate.rho
    starts = shell_starts(design.P, np.zeros(2), low, high, 20_000, rng)
    value = certificate.value(starts)
    assert np.all((value >= low * (1 - 1e-12)) & (value < high))
    # Uniform in the 2-D shell: V (= r^2) is uniform on [low, high).
    assert np.mean(value) == pytest.approx(0.5 * (low + high), rel=0.01)
    assert shell_levels(10.0, None) == [0.0, 10.0, 20.0, 30.0]
    assert shell_levels(10.0, 4.0) == [4.0, 10.0, 20.0, 30.0]
    assert shell_levels(10.0, 10.0) == [10.0, 20.0, 30.0]


@pytest.mark.slow
def test_a_hybrid_that_is_its_lqr_matches_every_share_but_leaves_the_flat_top():
    system, design, certificate = _pendulum()
    lqr = lqr_controller(design)
    twin = roa_hybrid(
        system,
        design,
        LinearController(design.W, design.b),
        certificate=certificate,
        rho_in_fraction=0.5,
    )
    assert flat_top_level(twin) == pytest.approx(0.5 * certificate.rho)
    assert flat_top_level(HeldPolicy(twin, 2)) == flat_top_level(twin)
    assert flat_top_level(lqr) is None
    claims = hybrid_claims(
        system,
        twin,
        lqr,
        certificate,
        default_basin_box(system),
        seed=3,
        starts=300,
        shell_starts=100,
    )
    for hybrid, reference in zip(
        claims["impulse_sweep"]["hybrid"], claims["impulse_sweep"]["lqr"], strict=True
    ):
        assert hybrid["held"] == reference["held"]
    for shell in claims["shells"]:
        assert shell["held"] == pytest.approx(shell["lqr_held"], abs=0.02)
        assert shell["left_flat_top"] == 1.0  # every shell start is outside the flat top
    basin = claims["basin"]
    assert basin["proved_set_held"] == 1.0 and basin["outside_share"] <= 0.01
    assert basin["lqr_basin_held"] >= 0.99
    assert 0.0 < basin["proved_set_left_flat_top"] < 1.0
    # The paper-size impulse stays inside the flat top: by construction; the failure size not.
    sweep = claims["impulse_sweep"]["hybrid"]
    assert sweep[0]["by_construction"] and not sweep[-1]["by_construction"]
    corners_v = certificate.value(operating_region_corners(system))
    assert claims["operating_region_max_v"] == pytest.approx(corners_v.max())


def test_a_pushing_hybrid_loses_what_its_lqr_holds():
    system, design, certificate = _pendulum()
    lqr = lqr_controller(design)
    pushing = roa_hybrid(system, design, _Push(), certificate=certificate, rho_in_fraction=0.05)
    rng = np.random.default_rng(5)
    box = default_basin_box(system)
    starts = system.operating_state + rng.uniform(-box, box, (300, 2))
    comparison = basin_comparison(system, pushing, lqr, certificate.sample(rng, 300), starts, box)
    assert comparison.proved_set_held < 0.9 and comparison.lqr_basin_held < 0.9
    assert comparison.proved_set_left_flat_top > 0.9


def test_the_report_section_marks_by_construction_comparisons():
    point = ImpulsePoint(1.0, True, 40, 1.0, 1.0)._asdict()
    claims = {
        "operating_region_max_v": 0.5,
        "rho": 40.0,
        "rho_basis": "proved",
        "flat_top": 20.0,
        "lqr_failure_size": 16.0,
        "impulse_sweep": {
            "hybrid": [{**point, "by_construction": True}],
            "lqr": [{**point, "min_relevance": None, "by_construction": False}],
        },
        "shells": [{"low": 20.0, "high": 40.0, "held": 0.7, "lqr_held": 1.0, "left_flat_top": 1.0}],
        "basin": {
            "proved_set_held": 0.9,
            "proved_set_left_flat_top": 0.5,
            "lqr_basin_held": 0.8,
            "lqr_basin_left_flat_top": 0.4,
            "outside_share": 0.1,
            "outside_volume": 0.2,
            "box": [0.6, 0.9],
            "starts": 100,
        },
    }
    evaluations = {"pendulum": {"ddpg_hybrid_roa": [{"hybrid_claims": claims}], "linear": [{}]}}
    text = "\n".join(hybrid_claims_section(evaluations))
    assert (
        "| pendulum | ddpg_hybrid_roa | 0.5 rho | by construction | by construction (0.025) |"
        in text
    )
    assert "| [0.5, 1) | 70% | 100% | 100% |" in text
    assert "| 90% (50%) | 80% (40%) | 10% | 0.2 |" in text
    assert hybrid_claims_section({"pendulum": {"linear": [{}]}}) == []
