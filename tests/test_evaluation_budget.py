"""A profile's evaluation budget (``Profile.evaluation``): the smoke profile's reduced grid is a
subset of the full evaluation, not another evaluation.

References: the full robustness sweep and impulse sweep of the same controller (the reduced
grid's points must be the full grid's points at the same scales and sizes, to 1e-12), and a
response simulated once per metric set by :func:`leoc.evaluation.rollout.response_test` (the
evaluation now simulates once and measures twice).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from leoc.control import certify_lqr, design_lqr
from leoc.evaluation.basins import default_basin_box
from leoc.evaluation.hybrid_claims import hybrid_claims
from leoc.evaluation.impulse_sweep import SWEEP_POINTS
from leoc.evaluation.robustness import SCALE_FACTORS
from leoc.evaluation.rollout import RESPONSE_STEPS, response_test
from leoc.experiments.evaluators import (
    EvaluationContext,
    evaluate_responses,
    evaluate_robustness,
)
from leoc.experiments.profiles import EvaluationBudget, get_profile
from leoc.experiments.variants import LEOC
from leoc.policies import LinearController, lqr_controller, roa_hybrid
from leoc.systems import make_system

pytestmark = pytest.mark.usefixtures("single_thread")

SMOKE = get_profile("smoke").evaluation


@functools.cache
def _pendulum():
    system = make_system("pendulum")
    design = design_lqr(system)
    return system, design, certify_lqr(system, design, samples=20_000, seed=0)


def _same(value, reference, where) -> None:
    """Equal to 1e-12 relative (numbers), or exactly (None, flags)."""
    if isinstance(value, float) and isinstance(reference, float):
        assert value == pytest.approx(reference, rel=1e-12, nan_ok=True), where
    else:
        assert value == reference, where


def _points(points: list[dict]) -> dict[tuple[str, float], dict]:
    return {(point["parameter"], point["scale"]): point for point in points}


@pytest.mark.slow
def test_the_smoke_robustness_points_are_the_full_sweep_s_at_its_scales() -> None:
    system, design, _ = _pendulum()
    full = EvaluationContext("pendulum", system, lqr_controller(design), 3, LEOC, "linear")
    smoke = dataclasses.replace(full, budget=SMOKE)
    everything = _points(evaluate_robustness(full))
    reduced = _points(evaluate_robustness(smoke))
    assert len(everything) == 2 * len(SCALE_FACTORS)
    assert set(reduced) == {(p, s) for p in ("mass", "gravity") for s in (0.5, 1.0, 5.0)}
    for key, point in reduced.items():
        reference = everything[key]
        np.testing.assert_allclose(point["returns"], reference["returns"], rtol=1e-12)
        assert point["stabilised"] == reference["stabilised"], key
        for name, value in point["impulse"].items():
            _same(value, reference["impulse"][name], (key, name))
    # the sweep fails somewhere on the full grid (5x g), so equal points are no empty check
    assert not all(all(p["stabilised"]) for p in reduced.values())


@pytest.mark.slow
def test_two_sweep_points_are_the_paper_size_and_the_lqr_s_failure_size() -> None:
    system, design, certificate = _pendulum()
    lqr = lqr_controller(design)
    # a hybrid whose learned part is a softer gain: it differs from its LQR outside the flat top
    hybrid = roa_hybrid(
        system, design, LinearController(0.5 * design.W, design.b), certificate=certificate
    )
    common = dict(box=default_basin_box(system), seed=1, starts=50, shell_starts=20)
    full = hybrid_claims(system, hybrid, lqr, certificate, **common)
    reduced = hybrid_claims(system, hybrid, lqr, certificate, sweep_points=2, **common)
    for label in ("hybrid", "lqr"):
        sweep, pair = full["impulse_sweep"][label], reduced["impulse_sweep"][label]
        assert len(sweep) == SWEEP_POINTS and len(pair) == 2
        assert pair[0]["size"] == 1.0
        assert pair[1]["size"] == pytest.approx(full["lqr_failure_size"], rel=1e-12)
        for mine, theirs in zip(pair, (sweep[0], sweep[-1]), strict=True):
            assert mine.keys() == theirs.keys()
            for name, value in mine.items():
                _same(value, theirs[name], name)
    assert reduced["shells"] == full["shells"] and reduced["basin"] == full["basin"]


def test_one_response_simulation_serves_both_metric_sets() -> None:
    system, design, _ = _pendulum()
    # a weak gain: the step response leans past 1 degree, where the authors' band and final
    # value differ from leoc's
    controller = LinearController(0.3 * design.W, design.b)
    responses = evaluate_responses(
        EvaluationContext("pendulum", system, controller, 0, LEOC, "linear")
    )
    for test, entry in responses.items():
        alone = response_test(system, controller, test, RESPONSE_STEPS, metric_set="authors")
        np.testing.assert_allclose(entry["deviation_authors"], alone.deviation, rtol=1e-12)
        for name, value in alone.metrics._asdict().items():
            _same(entry["metrics_authors"][name], value, name)
        assert entry["metrics_authors"] != entry["metrics"], test


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"robustness_scales": ()}, "robustness_scales: expected None or a non-empty tuple"),
        ({"robustness_scales": [1.0]}, "robustness_scales: expected None or a non-empty tuple"),
        ({"robustness_scales": (1.0, -2.0)}, "found \\(1.0, -2.0\\)"),
        ({"impulse_sweep_points": 1}, "impulse_sweep_points: expected None or an integer >= 2"),
        ({"impulse_sweep_points": True}, "found True"),
    ],
)
def test_a_bad_budget_is_a_one_line_error_naming_the_field(fields, message) -> None:
    with pytest.raises(ValueError, match=message):
        EvaluationBudget(**fields)


def test_the_budget_in_words() -> None:
    assert EvaluationBudget().describe() == ""
    assert SMOKE.describe() == (
        "robustness at 0.5x, 1x, 5x only; 2 impulse-sweep sizes; proofs of 2000 boxes per "
        "candidate V; robustness protocol at 3 levels x 1 episode"
    )
    assert SMOKE.describe() in get_profile("smoke").description
    assert get_profile("paper").evaluation == EvaluationBudget()
    quick = get_profile("quick").evaluation  # shorter proofs and protocol, the full grids
    assert quick.robustness_scales is None and quick.impulse_sweep_points is None


@pytest.mark.parametrize(
    ("scales", "expected"),
    [
        ((0.5, 1.0, 5.0), "0.5x, 1x, 5x"),  # the smoke grid: each scale
        ((1.0, 1.5, 2.0, 2.5), "1.0x ... 2.5x"),  # evenly spaced: the range
        ((), f"{min(SCALE_FACTORS):.1f}x ... {max(SCALE_FACTORS):.1f}x"),  # empty: the default
    ],
)
def test_the_robustness_section_names_the_scales_it_ran(scales, expected) -> None:
    from leoc.experiments.report.robustness import _scales_in_words

    rows = [{"scale": scale} for scale in scales for _ in range(2)]  # two rows per scale
    assert _scales_in_words(rows) == expected
