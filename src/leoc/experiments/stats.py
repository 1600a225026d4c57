"""Seed statistics researchers trust: interquartile mean, stratified-bootstrap confidence
intervals, probability of improvement and bootstrap bands for learning curves.

Everything follows Agarwal et al. (2021) [1]_ and reproduces the numbers of their reference package
``rliable`` (tested against it on synthetic data), without depending on it. Shapes: a score array
is ``(N,)`` (N runs, i.e. seeds, of one task) or ``(N, M)`` (N runs of each of M tasks); a set of
learning curves is ``(N, T)`` (T evaluation points). Every bootstrap takes a seed (default
:data:`DEFAULT_SEED`), so a report computed twice from the same numbers is identical.

With fewer than :data:`MIN_RUNS_FOR_INTERVAL` runs no interval is drawn: the summaries say so in
their ``note`` field and leave the bounds ``None`` instead of inventing them.

References
----------
.. [1] R. Agarwal, M. Schwarzer, P. S. Castro, A. Courville, M. G. Bellemare, "Deep
   reinforcement learning at the edge of the statistical precipice", NeurIPS 2021.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

DEFAULT_SEED = 0
"""Seed of every bootstrap unless one is given: reports are reproducible."""
DEFAULT_REPS = 10_000
"""Bootstrap resamples of a scalar statistic (rliable defaults to 50 000; with a handful of seeds
10 000 puts the Monte Carlo error of a 95% bound well below the spread between seeds)."""
DEFAULT_CURVE_REPS = 2_000
"""Bootstrap resamples per learning-curve band (one per evaluation point)."""
CONFIDENCE = 0.95
"""Coverage of every interval unless another is asked for."""
MIN_RUNS_FOR_INTERVAL = 3
"""Fewest runs (seeds) for which an interval is reported."""
TRIM_FRACTION = 0.25
"""Fraction trimmed from each end by the interquartile mean."""
RESAMPLE_BLOCK_ELEMENTS = 4_000_000
"""Upper bound on resampled values held in memory at once (the bootstrap runs in blocks)."""

Seed = np.random.Generator | int | None


class SeedSummary(NamedTuple):
    """IQM of one quantity over seeds, with its stratified-bootstrap confidence interval.

    ``ci_low``/``ci_high`` are ``None`` (and ``note`` says why) with fewer than
    :data:`MIN_RUNS_FOR_INTERVAL` usable values; ``iqm`` is ``None`` with none.
    """

    iqm: float | None
    ci_low: float | None
    ci_high: float | None
    n: int
    n_missing: int
    confidence: float
    note: str | None


class ImprovementEstimate(NamedTuple):
    """Probability that a run of X scores higher than a run of Y, with its interval."""

    probability: float | None
    ci_low: float | None
    ci_high: float | None
    n_x: int
    n_y: int
    confidence: float
    note: str | None


class CurveBands(NamedTuple):
    """Point-wise IQM of learning curves with bootstrap bands (arrays of shape ``(T,)``)."""

    iqm: np.ndarray
    ci_low: np.ndarray | None
    ci_high: np.ndarray | None
    n: int
    confidence: float
    note: str | None


# ------------------------------------------------------------------------------ input checks
def _scores(values: Any, name: str) -> np.ndarray:
    """Scores as a float64 ``(N, M)`` array (a 1-D input is one task), finite, N >= 1."""
    array = np.asarray(values, dtype=np.float64)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(
            f"{name}: expected a non-empty array of shape (runs,) or (runs, tasks), "
            f"found shape {np.shape(values)}"
        )
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite values, found {array[~np.isfinite(array)][:3]}")
    return array


def _check_confidence(confidence: float) -> float:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence: expected a value in (0, 1), found {confidence}")
    return float(confidence)


def _check_reps(reps: int) -> int:
    if int(reps) != reps or reps < 1:
        raise ValueError(f"reps: expected a positive integer, found {reps}")
    return int(reps)


def _generator(seed: Seed) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def _no_interval_note(n: int) -> str:
    return f"n = {n} < {MIN_RUNS_FOR_INTERVAL}: no interval"


# --------------------------------------------------------------------------------- estimators
def iqm(scores: Any, axis: int | None = None) -> np.ndarray | float:
    r"""Interquartile mean: the mean of the middle half of the scores.

    Parameters
    ----------
    scores : array_like
        Any shape; with ``axis=None`` all values are pooled (runs and tasks alike, as in [1]_).
    axis : int, optional
        Trim along this axis only (e.g. ``axis=0`` on learning curves ``(N, T)``: one IQM per
        evaluation point).

    Returns
    -------
    float or numpy.ndarray

    Notes
    -----
    With the :math:`n` values sorted, :math:`x_{(1)} \le \dots \le x_{(n)}`, and
    :math:`g = \lfloor n/4 \rfloor` values cut from each end,

    .. math:: \mathrm{IQM} = \frac{1}{n - 2g} \sum_{i=g+1}^{n-g} x_{(i)} ,

    the 25% trimmed mean of ``scipy.stats.trim_mean`` that ``rliable`` uses. With fewer than
    four values nothing is cut and the IQM is the mean. It is robust to one outlying seed in
    four, yet far less variable than the median [1]_.

    References
    ----------
    .. [1] Agarwal et al., "Deep reinforcement learning at the edge of the statistical
       precipice", NeurIPS 2021, section 4.
    """
    array = np.asarray(scores, dtype=np.float64)
    if axis is None:
        array, axis = array.reshape(-1), 0
    if array.size == 0:
        raise ValueError("scores: expected at least one value, found none")
    n = array.shape[axis]
    cut = int(math.floor(TRIM_FRACTION * n))
    middle = np.take(np.sort(array, axis=axis), np.arange(cut, n - cut), axis=axis)
    result = middle.mean(axis=axis)
    return float(result) if np.ndim(result) == 0 else result


def _iqm_of_resamples(resamples: np.ndarray) -> np.ndarray:
    """IQM of each resample: ``(B, N, M)`` -> ``(B,)``, runs and tasks pooled."""
    return iqm(resamples.reshape(resamples.shape[0], -1), axis=1)


def _percentile_interval(statistics: np.ndarray, confidence: float) -> tuple[Any, Any]:
    """Percentile bootstrap interval along axis 0 (linear interpolation, as numpy and arch)."""
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(statistics, [alpha, 1.0 - alpha], axis=0)
    return low, high


def _block_sizes(reps: int, elements_per_rep: int) -> list[int]:
    per_block = max(1, RESAMPLE_BLOCK_ELEMENTS // max(1, elements_per_rep))
    return [min(per_block, reps - start) for start in range(0, reps, per_block)]


def _stratified_resample(scores: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` stratified resamples of ``(N, M)`` scores: ``(count, N, M)``.

    Each task's runs are drawn with replacement from that task's own runs (the strata).
    """
    runs, tasks = scores.shape
    rows = rng.integers(0, runs, size=(count, runs, tasks))
    return scores[rows, np.arange(tasks)]


def stratified_bootstrap_ci(
    scores: Any,
    statistic: Callable[[np.ndarray], np.ndarray] = _iqm_of_resamples,
    *,
    confidence: float = CONFIDENCE,
    reps: int = DEFAULT_REPS,
    seed: Seed = DEFAULT_SEED,
) -> tuple[float, float]:
    r"""Percentile confidence interval of an aggregate statistic by stratified bootstrap.

    Parameters
    ----------
    scores : array_like, shape (N,) or (N, M)
        N runs (seeds) of each of M tasks; finite.
    statistic : callable
        Maps resamples ``(B, N, M)`` to ``(B,)`` (default: the IQM of each resample, runs and
        tasks pooled).
    confidence : float
        Coverage of the interval, in (0, 1).
    reps : int
        Number of bootstrap resamples B in total.
    seed : numpy.random.Generator, int or None

    Returns
    -------
    (low, high) : tuple of float

    Notes
    -----
    Each resample draws, independently for every task :math:`m`, :math:`N` runs with
    replacement from that task's runs (stratified bootstrap [1]_). With :math:`\hat\theta_b`
    the statistic of resample :math:`b` and :math:`\alpha = (1 - \text{confidence})/2`, the
    interval is the percentile interval :math:`[\hat q_{\alpha}, \hat q_{1-\alpha}]` of the
    :math:`\hat\theta_b` (``rliable``'s default method). Percentile intervals of a few seeds
    are narrow: with N = 3 there are only 10 distinct resamples.

    References
    ----------
    .. [1] Agarwal et al., "Deep reinforcement learning at the edge of the statistical
       precipice", NeurIPS 2021, section 3 and appendix A.
    """
    array = _scores(scores, "scores")
    confidence, reps, rng = _check_confidence(confidence), _check_reps(reps), _generator(seed)
    blocks = [
        np.asarray(statistic(_stratified_resample(array, count, rng)), dtype=np.float64)
        for count in _block_sizes(reps, array.size)
    ]
    low, high = _percentile_interval(np.concatenate(blocks), confidence)
    return float(low), float(high)


def is_missing(value: Any) -> bool:
    """Whether a recorded value is missing: ``None`` or NaN (how the studies' JSON marks a value
    that was not measured)."""
    return value is None or (isinstance(value, float) and math.isnan(value))


def _usable_values(values_by_seed: Mapping[Any, Any] | Sequence[Any]) -> tuple[list[float], int]:
    """Finite values and the count of missing ones (:func:`is_missing`)."""
    is_mapping = isinstance(values_by_seed, Mapping)
    kept, missing = [], 0
    for value in values_by_seed.values() if is_mapping else values_by_seed:
        if is_missing(value):
            missing += 1
            continue
        number = float(value)
        if not math.isfinite(number):
            raise ValueError(
                f"values_by_seed: expected finite numbers (None or NaN for missing), "
                f"found {value!r}"
            )
        kept.append(number)
    return kept, missing


def seed_summary(
    values_by_seed: Mapping[Any, Any] | Sequence[Any],
    *,
    confidence: float = CONFIDENCE,
    reps: int = DEFAULT_REPS,
    seed: Seed = DEFAULT_SEED,
) -> SeedSummary:
    r"""IQM over seeds of one quantity and its 95% stratified-bootstrap interval.

    Parameters
    ----------
    values_by_seed : mapping seed -> number, or sequence of numbers
        One value per seed (e.g. final return of each seed of one controller on one system).
        ``None`` or NaN marks a missing value (e.g. a settling time of a run that never
        settled): it is left out and counted in ``n_missing``. Leaving such runs out biases
        the IQM toward the runs that did settle; report ``n_missing`` beside it.
    confidence, reps, seed
        See :func:`stratified_bootstrap_ci`.

    Returns
    -------
    SeedSummary
        ``iqm``, ``ci_low``, ``ci_high``, ``n`` (values used), ``n_missing``, ``confidence``
        and ``note``. With ``n < MIN_RUNS_FOR_INTERVAL`` the bounds are ``None`` and ``note``
        reads ``"n = 1 < 3: no interval"``; with ``n = 0`` the IQM is ``None`` too.

    Notes
    -----
    One task, so the stratified bootstrap is the ordinary bootstrap over seeds; the IQM is
    defined in :func:`iqm` and the interval in :func:`stratified_bootstrap_ci` ([1]_).

    References
    ----------
    .. [1] Agarwal et al., "Deep reinforcement learning at the edge of the statistical
       precipice", NeurIPS 2021.
    """
    values, missing = _usable_values(values_by_seed)
    confidence = _check_confidence(confidence)
    n = len(values)
    if n == 0:
        return SeedSummary(None, None, None, 0, missing, confidence, "no values")
    center = float(iqm(values))
    if n < MIN_RUNS_FOR_INTERVAL:
        return SeedSummary(center, None, None, n, missing, confidence, _no_interval_note(n))
    low, high = stratified_bootstrap_ci(values, confidence=confidence, reps=reps, seed=seed)
    return SeedSummary(center, low, high, n, missing, confidence, None)


def _improvement_of_resamples(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """P(X > Y) of paired resample batches ``(B, N_x, M)``, ``(B, N_y, M)`` -> ``(B,)``."""
    difference = x[:, :, None, :] - y[:, None, :, :]  # (B, N_x, N_y, M)
    wins = (difference > 0).astype(np.float64) + 0.5 * (difference == 0)
    return wins.mean(axis=(1, 2)).mean(axis=1)


def probability_of_improvement(
    x: Any,
    y: Any,
    *,
    confidence: float = CONFIDENCE,
    reps: int = DEFAULT_REPS,
    seed: Seed = DEFAULT_SEED,
) -> ImprovementEstimate:
    r"""Probability that a run of X scores higher than a run of Y, with its bootstrap interval.

    Parameters
    ----------
    x, y : array_like, shape (N_x,) or (N_x, M), and (N_y,) or (N_y, M)
        Scores of the two algorithms (e.g. hybrid and baseline) on the same M tasks; higher
        is better (negate a cost such as a settling time first).
    confidence, reps, seed
        See :func:`stratified_bootstrap_ci`.

    Returns
    -------
    ImprovementEstimate
        ``probability`` in [0, 1], ``ci_low``, ``ci_high`` (``None`` with fewer than
        ``MIN_RUNS_FOR_INTERVAL`` runs on either side, ``note`` saying so), ``n_x``, ``n_y``.

    Notes
    -----
    Per task, the Mann-Whitney U statistic normalised by the number of pairs,

    .. math::
        P(X_m > Y_m) = \frac{1}{N_x N_y} \sum_{i=1}^{N_x} \sum_{j=1}^{N_y}
        \left( [x_{im} > y_{jm}] + \tfrac12 [x_{im} = y_{jm}] \right),

    averaged over the M tasks [1]_. It is 1 when every run of X beats every run of Y, 0.5 for
    identical samples. The interval comes from resampling X and Y independently, each
    stratified by task (``rliable``'s ``StratifiedIndependentBootstrap``), percentile method.

    References
    ----------
    .. [1] Agarwal et al., "Deep reinforcement learning at the edge of the statistical
       precipice", NeurIPS 2021, section 4.
    """
    x_scores, y_scores = _scores(x, "x"), _scores(y, "y")
    if x_scores.shape[1] != y_scores.shape[1]:
        raise ValueError(
            f"y: expected scores on the same {x_scores.shape[1]} task(s) as x, "
            f"found {y_scores.shape[1]}"
        )
    confidence, reps, rng = _check_confidence(confidence), _check_reps(reps), _generator(seed)
    n_x, n_y = x_scores.shape[0], y_scores.shape[0]
    point = float(_improvement_of_resamples(x_scores[None], y_scores[None])[0])
    if min(n_x, n_y) < MIN_RUNS_FOR_INTERVAL:
        note = _no_interval_note(min(n_x, n_y))
        return ImprovementEstimate(point, None, None, n_x, n_y, confidence, note)
    low, high = _percentile_interval(
        _resampled_improvements(x_scores, y_scores, reps, rng), confidence
    )
    return ImprovementEstimate(point, float(low), float(high), n_x, n_y, confidence, None)


def _resampled_improvements(
    x_scores: np.ndarray, y_scores: np.ndarray, reps: int, rng: np.random.Generator
) -> np.ndarray:
    """P(X > Y) of ``reps`` stratified resamples of X and Y (in blocks that bound the memory)."""
    blocks = []
    for count in _block_sizes(reps, x_scores.shape[0] * y_scores.shape[0] * x_scores.shape[1]):
        x_resamples = _stratified_resample(x_scores, count, rng)
        y_resamples = _stratified_resample(y_scores, count, rng)
        blocks.append(_improvement_of_resamples(x_resamples, y_resamples))
    return np.concatenate(blocks)


#: Score differences at most this large are nil (:func:`interval_verdict`): the scores compared
#: there are shares of held episodes or mean returns, so anything smaller is a sum's rounding,
#: not a difference.
NIL_DIFFERENCE = 1e-9


def interval_verdict(differences: Any, low: float | None, high: float | None, tie: float) -> str:
    """``equal`` where every score difference is nil (within :data:`NIL_DIFFERENCE`), else
    ``above`` or ``below`` where the interval ``[low, high]`` excludes ``tie``, ``unresolved``
    where it holds it; without an interval (fewer than :data:`MIN_RUNS_FOR_INTERVAL` seeds), the
    sign of the mean difference, marked ``(n < 3)``."""
    differences = np.asarray(differences, dtype=float)
    if np.all(np.abs(differences) <= NIL_DIFFERENCE):
        return "equal"
    if low is None or high is None:
        mean = float(differences.mean())
        if abs(mean) <= NIL_DIFFERENCE:
            return f"unresolved (n < {MIN_RUNS_FOR_INTERVAL})"
        return f"{'above' if mean > 0 else 'below'} (n < {MIN_RUNS_FOR_INTERVAL})"
    if low > tie:
        return "above"
    return "below" if high < tie else "unresolved"


def improvement_verdict(x: Any, y: Any) -> dict[str, Any]:
    """P(a run of X scores above a run of Y) with its 95% interval
    (:func:`probability_of_improvement`; X and Y unpaired, one task) and the verdict of
    :func:`interval_verdict` against 0.5: ``above`` or ``below`` where the interval excludes
    0.5, ``unresolved`` where the seeds cannot tell them apart, ``equal`` for identical scores."""
    estimate = probability_of_improvement(x, y)
    differences = np.subtract.outer(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    return {
        "probability": estimate.probability,
        "ci_low": estimate.ci_low,
        "ci_high": estimate.ci_high,
        "verdict": interval_verdict(differences.ravel(), estimate.ci_low, estimate.ci_high, 0.5),
    }


def curve_bands(
    curves: Any,
    *,
    confidence: float = CONFIDENCE,
    reps: int = DEFAULT_CURVE_REPS,
    seed: Seed = DEFAULT_SEED,
) -> CurveBands:
    r"""Point-wise IQM of learning curves over seeds, with percentile bootstrap bands.

    Parameters
    ----------
    curves : array_like, shape (N, T)
        One row per seed, all evaluated at the same T points (interpolate onto a common grid of
        interaction time or steps first).
    confidence, reps, seed
        See :func:`stratified_bootstrap_ci`.

    Returns
    -------
    CurveBands
        ``iqm`` of shape (T,); ``ci_low``/``ci_high`` of shape (T,), or ``None`` with fewer than
        ``MIN_RUNS_FOR_INTERVAL`` curves (``note`` says so); ``n``.

    Notes
    -----
    Whole curves are resampled (N rows drawn with replacement), and at every point :math:`t`
    the band is the percentile interval of the resampled :math:`\mathrm{IQM}_t` (defined in
    :func:`iqm`). ``rliable`` resamples each point independently; the two give the same
    point-wise bands in distribution, since a point-wise band only sees the marginal
    resampling of that point. Drawing whole curves also keeps a band's neighbouring points
    consistent, so the band is smooth where the curves are. As in [1]_, figure 3.

    References
    ----------
    .. [1] Agarwal et al., "Deep reinforcement learning at the edge of the statistical
       precipice", NeurIPS 2021.
    """
    array = np.asarray(curves, dtype=np.float64)
    if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(
            f"curves: expected a non-empty array of shape (seeds, points), found shape "
            f"{np.shape(curves)}"
        )
    if not np.all(np.isfinite(array)):
        raise ValueError("curves: expected finite values, found NaN or infinity")
    confidence, reps, rng = _check_confidence(confidence), _check_reps(reps), _generator(seed)
    n = array.shape[0]
    center = np.asarray(iqm(array, axis=0))
    if n < MIN_RUNS_FOR_INTERVAL:
        return CurveBands(center, None, None, n, confidence, _no_interval_note(n))
    blocks = []
    for count in _block_sizes(reps, array.size):
        rows = rng.integers(0, n, size=(count, n))
        blocks.append(iqm(array[rows], axis=1))  # (count, n, T) -> (count, T)
    low, high = _percentile_interval(np.concatenate(blocks), confidence)
    return CurveBands(center, low, high, n, confidence, None)


# ------------------------------------------------------------------------------- proportions
class Interval(NamedTuple):
    """A confidence interval ``[low, high]``."""

    low: float
    high: float


def wilson_interval(successes: int, trials: int, confidence: float = CONFIDENCE) -> Interval:
    r"""Wilson score interval of a success rate ``successes / trials`` [1]_.

    With :math:`\hat p = k / n` and :math:`z` the standard normal quantile of
    :math:`(1 + c) / 2` (1.96 for :math:`c` = 0.95):

    .. math::
        \frac{\hat p + \frac{z^2}{2n}}{1 + \frac{z^2}{n}} \pm
        \frac{z}{1 + \frac{z^2}{n}} \sqrt{\frac{\hat p (1 - \hat p)}{n} + \frac{z^2}{4 n^2}}

    Unlike the normal-approximation (Wald) interval it stays inside [0, 1] and does not
    collapse to a point at 0/n or n/n, which matters with a handful of seeds (0/5 gives
    [0, 0.43]).

    Parameters
    ----------
    successes : int
        :math:`k`, with :math:`0 \le k \le n`.
    trials : int
        :math:`n \ge 1`.
    confidence : float
        Coverage :math:`c` in (0, 1).

    Returns
    -------
    Interval
        ``low`` and ``high``, clipped to [0, 1] against round-off.

    References
    ----------
    .. [1] E. B. Wilson, "Probable inference, the law of succession, and statistical
       inference", Journal of the American Statistical Association 22 (1927) 209-212.
    """
    from statistics import NormalDist

    confidence = _check_confidence(confidence)
    if isinstance(trials, bool) or int(trials) != trials or trials < 1:
        raise ValueError(f"trials: expected a positive integer, found {trials!r}")
    if isinstance(successes, bool) or int(successes) != successes or not 0 <= successes <= trials:
        raise ValueError(f"successes: expected an integer in [0, {trials}], found {successes!r}")
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    n = float(trials)
    rate = successes / n
    shrink = 1.0 + z * z / n
    centre = (rate + z * z / (2.0 * n)) / shrink
    half = z / shrink * math.sqrt(rate * (1.0 - rate) / n + z * z / (4.0 * n * n))
    return Interval(max(0.0, centre - half), min(1.0, centre + half))


def percent(fraction: float) -> str:
    """``fraction`` as a whole percentage, with as many decimals as it takes (up to 3) not to
    print a fraction below 1 as 100% or one above 0 as 0% (a flag saying "only 100%" would
    hide the one start in 2000 that failed); beyond that, "> 99.999%" or "< 0.001%"."""
    for decimals in range(4):
        text = f"{fraction:.{decimals}%}"
        value = float(text[:-1])
        if not (0.0 < fraction and value == 0.0) and not (fraction < 1.0 and value == 100.0):
            return text
    return "> 99.999%" if fraction > 0.5 else "< 0.001%"


def success_interval(
    successes: int, trials: int, confidence: float = CONFIDENCE
) -> tuple[float, float]:
    r"""Clopper-Pearson ("exact") interval of a success rate: ``successes`` of ``trials``.

    The ends are quantiles of beta distributions,
    :math:`B(\alpha/2; k, n - k + 1)` and :math:`B(1 - \alpha/2; k + 1, n - k)`, with
    :math:`\alpha = 1 - \text{confidence}` (0 at k = 0 and 1 at k = n). Conservative: it covers
    the rate at least ``confidence`` of the time for every rate. With 5 of 5 successes the 95%
    interval is [0.478, 1]: five seeds cannot tell 100% from 50%.
    """
    from scipy.stats import beta

    if int(trials) != trials or trials < 1:
        raise ValueError(f"trials: expected a positive integer, found {trials!r}")
    if int(successes) != successes or not 0 <= successes <= trials:
        raise ValueError(f"successes: expected an integer in [0, {trials}], found {successes!r}")
    alpha = 1.0 - _check_confidence(confidence)
    low = 0.0 if successes == 0 else float(beta.ppf(alpha / 2, successes, trials - successes + 1))
    high = (
        1.0
        if successes == trials
        else float(beta.ppf(1 - alpha / 2, successes + 1, trials - successes))
    )
    return low, high
