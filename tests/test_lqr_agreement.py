"""leoc.evaluation.lqr_agreement: a hybrid's responses against its LQR's, checked against
hybrids whose answer is known without the code under test (H = G, H = 0), a hand-computed
relevance along the trajectory, and the closed-form distance."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from leoc.control import design_lqr
from leoc.evaluation.lqr_agreement import (
    KEEP_TOLERANCE_PCT,
    lqr_agreement,
    relevance_parameters,
    response_distance,
)
from leoc.evaluation.rollout import response_test
from leoc.policies import HybridPolicy, LinearController, lqr_controller
from leoc.systems import make_system


class Zero(torch.nn.Module):
    """H(o) = 0: the learned part that pulls hardest away from G near the operating point."""

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.zeros(*obs.shape[:-1], 1, dtype=obs.dtype)


def _hybrid(system, learned, lambda_init):
    design = design_lqr(system)
    linear = LinearController(design.W, design.b)
    return HybridPolicy(
        linear, learned, system.operating_obs, lambda_init=lambda_init, learn_lambda=False
    ), lqr_controller(design)


def test_response_distance_closed_form():
    assert response_distance([0.0, 1.0, 2.0], [0.0, 2.0, -4.0]) == pytest.approx(100 * 6 / 4)
    assert response_distance([0.0, 1.0], [0.0, 1.0]) == 0.0
    assert math.isinf(response_distance([0.0, 1.0], [0.0, 1.0, 0.5]))  # one terminated early
    assert math.isinf(response_distance([0.0, 1.0], [0.0, 0.0]))  # no LQR peak to scale by


@pytest.mark.slow
@pytest.mark.parametrize("name", ["pendulum", "cartpole", "mountaincar"])
def test_hybrid_whose_learned_part_is_its_lqr_keeps_it_not_by_construction(name):
    system = make_system(name)
    design = design_lqr(system)
    same = LinearController(design.W, design.b)  # H = G: pi = r G + (1 - r) G = G
    hybrid, _ = _hybrid(system, same, 1.0)
    found = lqr_agreement(system, hybrid)  # the default LQR: designed at the hybrid's period
    for test in ("impulse", "step"):
        assert found[test]["distance_pct"] < 1e-9
        assert found[test]["keeps_lqr"]
        assert found[test]["min_relevance"] < 1.0  # the paper's relevance leaves 1 off a
        assert not found[test]["by_construction"]
        assert found[test]["settling_time"] == found[test]["lqr_settling_time"]
    ones = [1.0] * len(system.operating_obs)
    assert found["relevance"] == {"kind": "paper", "lambda": pytest.approx(ones, rel=1e-12)}


def test_hybrid_with_zero_learned_part_leaves_its_lqr_and_min_r_matches_by_hand():
    system = make_system("pendulum")
    lam = np.array([0.01, 0.01, 0.05])  # narrow: r falls along the impulse response
    hybrid, lqr = _hybrid(system, Zero(), lam)
    found = lqr_agreement(system, hybrid, lqr)["impulse"]
    assert found["distance_pct"] > KEEP_TOLERANCE_PCT and not found["keeps_lqr"]
    # min r by hand along the hybrid's own response (numpy, from its observations)
    states = response_test(system, hybrid, "impulse").trajectory.states
    obs = np.asarray(system.observe(torch.as_tensor(states)).detach(), dtype=float)
    d = (((obs - np.asarray(system.operating_obs)) ** 2) / lam).sum(axis=1)
    expected = (1.0 / (1.0 + d) ** 2)[:-1]  # r of the states the controller acted on
    assert found["min_relevance"] == pytest.approx(expected.min(), rel=1e-9)
    # and the LQR's peak is the LQR's own response's
    lqr_response = response_test(system, lqr, "impulse").deviation
    assert found["lqr_peak"] == pytest.approx(np.abs(lqr_response).max(), rel=1e-12)


def test_relevance_parameters_of_a_non_hybrid_is_none():
    system = make_system("pendulum")
    assert relevance_parameters(lqr_controller(design_lqr(system))) is None
