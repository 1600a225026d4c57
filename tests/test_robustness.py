"""Tests of the robustness sweep: it exercises the closed loop and can fail."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from leoc.control import design_lqr
from leoc.evaluation.robustness import robustness_starts, robustness_sweep
from leoc.policies import LinearController, lqr_controller
from leoc.systems import SYSTEM_NAMES, make_system
from leoc.systems.rollout import simulate


@pytest.mark.parametrize("name", SYSTEM_NAMES)
@pytest.mark.parametrize("action_repeat", [1, 2, 3])
def test_the_nominal_lqr_recovers_from_every_corner_of_the_operating_region(name, action_repeat):
    system = make_system(name)
    controller = lqr_controller(design_lqr(system, action_repeat=action_repeat))
    corners = np.array(list(itertools.product(*[(-w, w) for w in system.operating_region])))
    batch = simulate(system, controller, corners)
    for index in range(len(corners)):
        assert (
            system.hold_step(batch.states[index, 1:], terminated=bool(batch.terminated[index]))
            is not None
        ), corners[index]


def test_the_linear_controller_fails_where_its_actuator_limit_makes_failure_physical():
    system = make_system("pendulum")
    controller = lqr_controller(design_lqr(system))
    points = robustness_sweep(system, controller, seed=0, episodes=6, scales=(1.0, 5.0))
    by_key = {(p.parameter, p.scale): p for p in points}
    for parameter in ("mass", "gravity"):
        assert by_key[(parameter, 1.0)].fraction_stabilised == 1.0
        # holding 0.2 rad at 5x needs 5 N m of a 2 N m limit: no start is held
        assert by_key[(parameter, 5.0)].fraction_stabilised == 0.0
        assert by_key[(parameter, 5.0)].return_mean < by_key[(parameter, 1.0)].return_mean
    assert by_key[("mass", 1.0)].impulse["settled"]
    assert len({p.fraction_stabilised for p in points}) > 1  # the cells are not all identical


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_a_destabilising_controller_fails_at_every_scale(name):
    system = make_system(name)
    design = design_lqr(system)
    # positive feedback: the LQR's gain with the wrong sign pushes every start away
    wrong = LinearController(-design.W, design.b)
    points = robustness_sweep(system, wrong, seed=1, episodes=4, scales=(0.5, 1.0, 2.0))
    assert all(point.fraction_stabilised == 0.0 for point in points)
    for point in points:  # nor does its impulse response return to the operating point
        impulse = point.impulse
        returned = impulse["settled"] and abs(impulse["steady_state_error"]) <= system.hold_band
        assert impulse["terminated"] or not returned, (point.parameter, point.scale)


def test_the_starts_are_seeded_and_inside_the_operating_region():
    system = make_system("cartpole")
    starts = robustness_starts(system, seed=3, episodes=50)
    np.testing.assert_array_equal(starts, robustness_starts(system, seed=3, episodes=50))
    assert not np.array_equal(starts, robustness_starts(system, seed=4, episodes=50))
    assert np.all(np.abs(starts) <= np.asarray(system.operating_region))
    with pytest.raises(ValueError, match="episodes: expected a positive integer, found 0"):
        robustness_starts(system, seed=0, episodes=0)


@pytest.mark.parametrize("name", SYSTEM_NAMES)
def test_each_scale_s_episodes_are_the_scaled_system_simulated_alone(name):
    """The sweep runs every scale in one batch (a parameter error per scale); reference: each
    scaled system built with ``with_params`` and simulated alone, its returns and held starts.
    A controller at period 2 on wide starts, so that some scales fail and some hold."""
    system = make_system(name)
    controller = lqr_controller(design_lqr(system, action_repeat=2))
    scales = (0.5, 1.0, 3.0)
    points = robustness_sweep(system, controller, seed=4, episodes=5, scales=scales)
    starts = robustness_starts(system, 4, 5)
    expected = []
    for parameter, scale in itertools.product(("mass", "gravity"), scales):
        scaled = system.with_params(**{parameter: scale})
        batch = simulate(scaled, controller, starts)
        held = [
            scaled.hold_step(batch.states[i, 1:], terminated=bool(batch.terminated[i])) is not None
            for i in range(len(starts))
        ]
        expected.append((parameter, scale, batch.total_rewards, held))
    assert [(p.parameter, p.scale) for p in points] == [e[:2] for e in expected]
    for point, (_, _, returns, held) in zip(points, expected, strict=True):
        np.testing.assert_allclose(point.returns, returns, rtol=1e-9, atol=1e-9)
        assert point.stabilised == held
    assert len({p.fraction_stabilised for p in points}) > 1
