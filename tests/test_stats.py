"""Seed statistics against closed forms and against the reference package ``rliable``."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from leoc.experiments.stats import (
    MIN_RUNS_FOR_INTERVAL,
    curve_bands,
    iqm,
    probability_of_improvement,
    seed_summary,
    stratified_bootstrap_ci,
)

REPS = 50_000
"""Our resamples when comparing with rliable (both sides are Monte Carlo estimates)."""
REFERENCE_REPS = 10_000
"""rliable's resamples (it loops in Python: 10 000 take seconds)."""
CURVE_REFERENCE_REPS = 3_000
MONTE_CARLO_TOLERANCE = 0.05
"""Independent percentile bounds from 10 000 and 50 000 resamples differ by far less than 5% of
the interval's width: the Monte Carlo standard error of a 2.5% quantile of B resamples is about
0.04 bootstrap standard deviations at B = 10 000, i.e. ~1% of the width (4 sd)."""


@pytest.fixture
def rliable_global_seed() -> Iterator[None]:
    """rliable draws its resamples from numpy's legacy global generator: seed it, then restore."""
    state = np.random.get_state()  # noqa: NPY002 (rliable's own generator)
    np.random.seed(0)  # noqa: NPY002
    yield
    np.random.set_state(state)  # noqa: NPY002


# -------------------------------------------------------------------------------------- IQM
def test_iqm_closed_forms() -> None:
    assert iqm([1, 2, 3, 4, 5, 6, 7, 8]) == pytest.approx(4.5)  # mean of 3, 4, 5, 6
    # one outlying seed in four is cut away
    assert iqm([1.0, 2.0, 3.0, 1e9]) == pytest.approx(2.5)
    # fewer than four values: nothing is cut, the IQM is the mean
    assert iqm([1.0, 2.0, 10.0]) == pytest.approx(13.0 / 3.0)
    assert iqm([7.0]) == 7.0
    # n = 10: floor(2.5) = 2 cut from each end
    assert iqm(np.arange(10.0)) == pytest.approx(np.mean(np.arange(2.0, 8.0)))
    curves = np.array([[0.0, 10.0], [1.0, 20.0], [2.0, 30.0], [100.0, -100.0]])
    np.testing.assert_allclose(iqm(curves, axis=0), [1.5, 15.0])


@pytest.mark.parametrize("shape", [(1,), (3,), (4,), (5, 1), (10, 3), (13, 4), (100, 2)])
def test_iqm_equals_rliable(shape: tuple[int, ...]) -> None:
    metrics = pytest.importorskip("rliable.metrics")
    scores = np.random.default_rng(sum(shape)).standard_cauchy(shape)
    assert iqm(scores) == pytest.approx(metrics.aggregate_iqm(scores), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("size", [4, 5, 7, 8, 9, 10, 31])
def test_iqm_equals_scipy_trim_mean(size: int) -> None:
    """scipy.stats.trim_mean(x, 0.25) cuts floor(n / 4) values from each end (no rliable
    needed), per column with axis=0 too."""
    from scipy.stats import trim_mean

    scores = np.random.default_rng(size).standard_cauchy((size, 3))
    np.testing.assert_allclose(iqm(scores[:, 0]), trim_mean(scores[:, 0], 0.25), rtol=1e-12)
    np.testing.assert_allclose(iqm(scores, axis=0), trim_mean(scores, 0.25, axis=0), rtol=1e-12)


# ------------------------------------------------------------------------- bootstrap interval
@pytest.mark.slow
def test_stratified_interval_equals_rliable(rliable_global_seed: None) -> None:
    library = pytest.importorskip("rliable.library")
    metrics = pytest.importorskip("rliable.metrics")
    rng = np.random.default_rng(1)
    # three tasks on very different scales: pooling runs across tasks (an unstratified
    # bootstrap) would give a far wider interval than resampling within each task
    scores = rng.normal([0.0, 10.0, 100.0], [1.0, 2.0, 5.0], size=(10, 3))
    _, reference = library.get_interval_estimates(
        {"x": scores},
        lambda s: np.array([metrics.aggregate_iqm(s)]),
        reps=REFERENCE_REPS,
    )
    expected_low, expected_high = reference["x"][:, 0]
    low, high = stratified_bootstrap_ci(scores, reps=REPS, seed=2)
    width = expected_high - expected_low
    assert low == pytest.approx(expected_low, abs=MONTE_CARLO_TOLERANCE * width)
    assert high == pytest.approx(expected_high, abs=MONTE_CARLO_TOLERANCE * width)


def test_interval_coverage_in_a_seeded_monte_carlo() -> None:
    """95% intervals of the IQM of a symmetric population (IQM = its centre) cover it ~95%."""
    rng = np.random.default_rng(3)
    centre, trials, runs = 2.0, 400, 30
    covered = 0
    for _ in range(trials):
        sample = rng.normal(centre, 1.0, size=runs)
        low, high = stratified_bootstrap_ci(sample, reps=2_000, seed=rng)
        covered += low <= centre <= high
    # the percentile bootstrap of n = 30 under-covers slightly (~93%); a 90% or 99% interval,
    # or one of the mean of a wrong sample, falls outside these bounds (binomial sd ~ 1.2%)
    assert 0.90 <= covered / trials <= 0.98
    # and a 50% interval covers about half of the time: the confidence level is honoured
    half = sum(
        low <= centre <= high
        for low, high in (
            stratified_bootstrap_ci(rng.normal(centre, 1.0, runs), confidence=0.5, reps=2_000)
            for _ in range(trials)
        )
    )
    assert 0.40 <= half / trials <= 0.60


def test_seed_summary_intervals_only_from_three_seeds() -> None:
    one = seed_summary({0: 5.0})
    assert one.iqm == 5.0 and one.ci_low is None and one.ci_high is None
    assert one.n == 1 and one.note == f"n = 1 < {MIN_RUNS_FOR_INTERVAL}: no interval"
    two = seed_summary([1.0, None, 3.0, float("nan")])
    assert two.iqm == 2.0 and two.n == 2 and two.n_missing == 2 and two.ci_low is None
    none = seed_summary([None])
    assert none.iqm is None and none.n == 0 and none.n_missing == 1
    three = seed_summary([1.0, 2.0, 6.0])
    assert three.note is None and three.n == 3
    # three values: the resampled IQM (= mean) ranges over {1, ..., 6}
    assert 1.0 <= three.ci_low < three.iqm < three.ci_high <= 6.0
    assert seed_summary([1.0, 2.0, 6.0]) == three  # seeded: the same report twice
    assert seed_summary([4.0, 4.0, 4.0])[:3] == (4.0, 4.0, 4.0)


def test_input_errors_name_the_argument() -> None:
    with pytest.raises(ValueError, match="scores: expected finite values"):
        stratified_bootstrap_ci([1.0, np.inf, 2.0])
    with pytest.raises(ValueError, match=r"scores: expected a non-empty array .* found shape"):
        stratified_bootstrap_ci(np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="confidence: expected a value in"):
        seed_summary([1.0, 2.0, 3.0], confidence=95)
    with pytest.raises(ValueError, match="reps: expected a positive integer, found 0"):
        seed_summary([1.0, 2.0, 3.0], reps=0)
    with pytest.raises(ValueError, match="values_by_seed: expected finite numbers"):
        seed_summary([1.0, float("inf")])
    with pytest.raises(ValueError, match="y: expected scores on the same 2 task"):
        probability_of_improvement(np.zeros((3, 2)), np.zeros((3, 1)))
    with pytest.raises(ValueError, match="curves: expected a non-empty array"):
        curve_bands([1.0, 2.0])


# ---------------------------------------------------------------- probability of improvement
def test_probability_of_improvement_closed_forms() -> None:
    low = np.array([1.0, 2.0, 3.0, 4.0])
    high = low + 10.0
    separated = probability_of_improvement(high, low)
    assert (separated.probability, separated.ci_low, separated.ci_high) == (1.0, 1.0, 1.0)
    assert probability_of_improvement(low, high).probability == 0.0
    identical = probability_of_improvement(low, low)
    assert identical.probability == 0.5 and identical.ci_low < 0.5 < identical.ci_high
    # ties count one half: P = (2 wins + 1 tie / 2) / 4 pairs
    assert probability_of_improvement([1.0, 3.0], [1.0, 2.0]).probability == 0.625
    few = probability_of_improvement([1.0, 2.0], [0.0, 1.0, 2.0])
    assert few.ci_low is None and few.note == f"n = 2 < {MIN_RUNS_FOR_INTERVAL}: no interval"


@pytest.mark.slow
def test_probability_of_improvement_equals_rliable(rliable_global_seed: None) -> None:
    library = pytest.importorskip("rliable.library")
    metrics = pytest.importorskip("rliable.metrics")
    rng = np.random.default_rng(4)
    x = rng.integers(0, 6, size=(8, 3)).astype(float)  # integer scores: plenty of ties
    y = rng.integers(0, 5, size=(6, 3)).astype(float)
    estimate = probability_of_improvement(x, y, reps=REPS, seed=5)
    assert estimate.probability == pytest.approx(metrics.probability_of_improvement(x, y))
    _, reference = library.get_interval_estimates(
        {"xy": [x, y]},
        lambda a, b: np.array([metrics.probability_of_improvement(a, b)]),
        reps=2_000,  # rliable loops over tasks per resample: 2 000 take seconds
    )
    expected_low, expected_high = reference["xy"][:, 0]
    # 2 000 reference resamples: a bound's Monte Carlo error is ~3% of the width
    width = expected_high - expected_low
    assert estimate.ci_low == pytest.approx(expected_low, abs=0.1 * width)
    assert estimate.ci_high == pytest.approx(expected_high, abs=0.1 * width)


# ---------------------------------------------------------------------------- learning curves
@pytest.mark.slow
def test_curve_bands_equal_rliable_pointwise(rliable_global_seed: None) -> None:
    library = pytest.importorskip("rliable.library")
    metrics = pytest.importorskip("rliable.metrics")
    rng = np.random.default_rng(6)
    points = np.linspace(0.0, 1.0, 5)
    curves = np.sin(3.0 * points) + rng.normal(0.0, 0.3, size=(12, points.size))
    bands = curve_bands(curves, reps=REPS, seed=7)
    np.testing.assert_allclose(bands.iqm, [metrics.aggregate_iqm(c) for c in curves.T])
    _, reference = library.get_interval_estimates(
        {"c": curves[:, None, :]},  # (runs, tasks = 1, points)
        lambda s: np.array([metrics.aggregate_iqm(s[..., t]) for t in range(s.shape[-1])]),
        reps=CURVE_REFERENCE_REPS,
    )
    # 3 000 reference resamples: a bound's Monte Carlo error is ~2% of the width
    width = reference["c"][1] - reference["c"][0]
    assert np.all(np.abs(bands.ci_low - reference["c"][0]) <= MONTE_CARLO_TOLERANCE * width)
    assert np.all(np.abs(bands.ci_high - reference["c"][1]) <= MONTE_CARLO_TOLERANCE * width)
    assert np.all(bands.ci_low <= bands.iqm) and np.all(bands.iqm <= bands.ci_high)


def test_curve_bands_without_enough_seeds_say_so() -> None:
    bands = curve_bands([[0.0, 1.0, 2.0], [2.0, 3.0, 4.0]])
    np.testing.assert_allclose(bands.iqm, [1.0, 2.0, 3.0])
    assert bands.ci_low is None and bands.ci_high is None and bands.n == 2
    assert bands.note == f"n = 2 < {MIN_RUNS_FOR_INTERVAL}: no interval"


# ------------------------------------------------------------------------ success-rate interval
def test_success_interval_closed_forms_and_scipy() -> None:
    from scipy.stats import binomtest

    from leoc.experiments.stats import success_interval

    # all or none succeed: the interval is [(alpha / 2)^(1/n), 1] or [0, 1 - (alpha / 2)^(1/n)]
    assert success_interval(5, 5) == (pytest.approx(0.025 ** (1 / 5)), 1.0)
    assert success_interval(0, 5) == (0.0, pytest.approx(1 - 0.025 ** (1 / 5)))
    for k, n in [(1, 3), (3, 5), (7, 20)]:
        reference = binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
        assert success_interval(k, n) == (
            pytest.approx(reference.low, rel=1e-9),
            pytest.approx(reference.high, rel=1e-9),
        )
    with pytest.raises(ValueError, match="successes: expected an integer in \\[0, 3\\], found 4"):
        success_interval(4, 3)
    with pytest.raises(ValueError, match="trials: expected a positive integer, found 0"):
        success_interval(0, 0)


# ------------------------------------------------------------- the report's seed statistics
def _seed_run(final_return: float, first_hold: float | None, settling: int | None) -> dict:
    """A run result with only what the report's seed statistics read."""
    seconds = [0.0, 5.0] + ([first_hold] if first_hold is not None else [])
    held = [0.0, 0.0] + ([1.0] if first_hold is not None else [])
    returns = [-1500.0] * (len(seconds) - 1) + [final_return]
    metrics = {"steady_state_error": 0.0, "peak_deviation": 1.0, "settling_time": settling}
    return {
        "curve": {"seconds": seconds, "returns": returns, "held_fraction": held},
        "responses": {"impulse": {"metrics": metrics}},
    }


def test_report_seed_statistics_match_scipy_trim_mean_and_a_hand_iqm() -> None:
    """The report's IQM over seeds, not against leoc's own ``iqm`` but against
    scipy.stats.trim_mean(x, 0.25) (what rliable's IQM is) and the value worked out by hand."""
    from scipy.stats import trim_mean

    from leoc.experiments.report import seed_statistics

    finals = [-100.0, -150.0, -900.0, -210.0, -205.0, -5000.0, -190.0, -180.0]
    holds = [10.0, 20.0, 30.0, None, 40.0, 50.0, 60.0, 1000.0]
    settlings = [30, 31, None, 33, 34, 35, 36, 400]
    runs = [_seed_run(*values) for values in zip(finals, holds, settlings, strict=True)]
    rows = seed_statistics({"pendulum": {"ddpg_hybrid": runs}})
    by_quantity = {row["quantity"]: row for row in rows}
    # sorted finals: -5000, -900 | -210, -205, -190, -180 | -150, -100: IQM = -785 / 4
    final = by_quantity["final return"]
    assert final["iqm"] == pytest.approx(-196.25, rel=1e-12)
    assert final["iqm"] == pytest.approx(trim_mean(finals, 0.25), rel=1e-12)
    assert final["n"] == 8 and final["n_missing"] == 0
    assert final["ci_low"] <= final["iqm"] <= final["ci_high"]
    # 7 values held: 10 | 20, 30, 40, 50, 60 | 1000 (one cut from each end): IQM = 40
    hold = by_quantity["interaction time to first hold [s]"]
    present = [value for value in holds if value is not None]
    assert hold["iqm"] == pytest.approx(40.0, rel=1e-12)
    assert hold["iqm"] == pytest.approx(trim_mean(present, 0.25), rel=1e-12)
    assert (hold["n"], hold["n_missing"]) == (7, 1)
    settling = by_quantity["impulse settling time [steps]"]
    # 30 | 31, 33, 34, 35, 36 | 400: IQM = 169 / 5
    assert settling["iqm"] == pytest.approx(169.0 / 5.0, rel=1e-12)
    assert (settling["n"], settling["n_missing"]) == (7, 1)
