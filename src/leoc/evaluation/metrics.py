"""Transient-response metrics of a recorded deviation signal.

Every function here takes ``e``, a 1-D record :math:`e[t],\\ t = 0, \\dots, T - 1` (time in
steps), the deviation of a system's main coordinate from its operating point (an angle in degrees
for the pendulum and the cart-pole, a position for the mountain car). Results are in the units of
``e`` (steady-state error, overshoot, peak deviation) or in steps (settling time; with ``dt``
also in seconds).

Letters used throughout:

- :math:`T` -- record length (samples), :math:`T \\ge 2`;
- :math:`W` -- final window (samples), clipped to :math:`T`;
- :math:`e_f` -- final value, by default the mean of the last :math:`W` samples;
- :math:`b` -- settling band, in the units of ``e``.

Settling band. By default the band is *relative to the response*: :math:`b = 0.02\\,
\\max_t |e[t] - e_f|`, 2 % of the peak error, the convention of MATLAB's ``stepinfo``/
``lsiminfo`` (for a step from rest without overshoot the peak error is
:math:`|y_{init} - y_{final}|`, stepinfo's reference; for an impulse, whose final value is the
initial one, it is the peak excursion). An absolute band (for example 1 degree) is an option:
pass ``band``. A relative band makes the settling time scale-free: an impulse that never leaves
a fixed 1-degree band would otherwise "settle" in 0 steps.

The definitions follow the project design ("Metrics"). They differ from
:func:`control.step_info` in documented ways: the final value is estimated from the record
(python-control uses the DC gain of the model), the relative band is taken from the peak error
(python-control uses 2 % of the final value, which is 0 for an impulse), and a record whose last
window leaves the band is "not settled" (``None``), whereas python-control returns a time
whenever only the very last sample is inside its band.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from numbers import Integral, Real
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "AUTHORS_BAND",
    "AUTHORS_STEADY_TOLERANCE",
    "AUTHORS_STEADY_WINDOW",
    "DEFAULT_FINAL_WINDOW",
    "DEFAULT_RELATIVE_BAND",
    "MIN_SAMPLES",
    "OVERSHOOT_ABS_TOLERANCE",
    "OVERSHOOT_REL_TOLERANCE",
    "MetricsSummary",
    "ResponseMetrics",
    "authors_response_metrics",
    "overshoot",
    "relative_band",
    "response_metrics",
    "settling_time",
    "steady_state_error",
    "summarise_metrics",
]

DEFAULT_RELATIVE_BAND = 0.02
r"""Default settling band as a fraction of the peak error :math:`\max_t |e[t] - e_f|`."""

DEFAULT_FINAL_WINDOW = 20
"""Number of final samples averaged to estimate the final value (clipped to the record)."""

MIN_SAMPLES = 2
"""Shortest record accepted: one sample cannot show a deviation and a final value."""
# The authors' metric set (nrjc/LEOC plotting/plotter.py): an absolute band of pi/180 in the
# units of e (degrees or metres), and a steady state "reached" when the last 10 samples agree
# with the last one to 1e-3.
#: The authors' absolute settling band, pi/180 in the units of e (degrees or metres).
AUTHORS_BAND = math.pi / 180.0
#: The authors' steady state is reached when this many final samples agree with the last one.
AUTHORS_STEADY_WINDOW = 10
#: ... to this tolerance (in the units of e).
AUTHORS_STEADY_TOLERANCE = 1e-3

OVERSHOOT_REL_TOLERANCE = 0.01
"""Fraction of :math:`\\max_t |e[t] - e_f|` a sample must exceed to fix the initial direction."""

OVERSHOOT_ABS_TOLERANCE = 1e-12
"""Absolute floor added to the relative tolerance, so a flat record never picks a direction."""

_POPULATION_DDOF = 0


class ResponseMetrics(NamedTuple):
    """Transient-response metrics of one record (see :func:`response_metrics`).

    Attributes
    ----------
    steady_state_error : float
        Final value :math:`e_f`, the mean of the last ``final_window`` samples (units of ``e``).
    overshoot : float
        Largest excursion past :math:`e_f` opposite to the initial deviation (units of ``e``).
    settling_time : int or None
        First step after which :math:`|e - e_f| \\le b` for the rest of the record; ``None``
        when the record has not settled (never a number then).
    settled : bool
        ``settling_time is not None``.
    band : float
        Settling band :math:`b` used (units of ``e``).
    final_window : int
        Number of final samples actually used, ``min(final_window, len(e))``.
    peak_deviation : float
        :math:`\\max_t |e[t]|`, the largest deviation from the operating point (units of ``e``).
    settling_seconds : float or None
        ``settling_time * dt`` when ``dt`` was given and the record settled.
    band_fraction : float or None
        The fraction of the peak error that defined a relative band; None for an absolute band.
    terminated : bool
        The episode ended early (left the allowed region); its record is then cut short.
    """

    steady_state_error: float
    overshoot: float
    settling_time: int | None
    settled: bool
    band: float
    final_window: int
    peak_deviation: float = math.nan
    settling_seconds: float | None = None
    band_fraction: float | None = None
    terminated: bool = False


class MetricsSummary(NamedTuple):
    """Mean and population standard deviation of :class:`ResponseMetrics` over runs.

    Attributes
    ----------
    steady_state_error_mean, steady_state_error_std : float
        Over all runs (units of ``e``).
    overshoot_mean, overshoot_std : float
        Over all runs (units of ``e``).
    settling_time_mean, settling_time_std : float
        Over the runs that settled only (steps); NaN when none settled.
    n_runs : int
        Number of runs summarised.
    n_settled : int
        Number of runs that settled.
    peak_deviation_mean, peak_deviation_std : float
        Over all runs (units of ``e``).
    n_terminated : int
        Number of runs whose episode terminated.
    """

    steady_state_error_mean: float
    steady_state_error_std: float
    overshoot_mean: float
    overshoot_std: float
    settling_time_mean: float
    settling_time_std: float
    n_runs: int
    n_settled: int
    peak_deviation_mean: float = math.nan
    peak_deviation_std: float = math.nan
    n_terminated: int = 0


# ---------------------------------------------------------------------------------------------
# Input checks: every public function converts and checks its arguments once, here.
# ---------------------------------------------------------------------------------------------


def _as_signal(e: ArrayLike) -> NDArray[np.float64]:
    """Return ``e`` as a finite 1-D float64 array of at least :data:`MIN_SAMPLES` samples."""
    if np.iscomplexobj(e):
        raise ValueError("e must be real, found a complex array")
    try:
        signal = np.asarray(e, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"e must be a 1-D array of real numbers, found {type(e).__name__}") from (
            error
        )
    if signal.ndim != 1:
        raise ValueError(f"e must be 1-D, found shape {signal.shape}")
    if signal.size < MIN_SAMPLES:
        raise ValueError(f"e must have at least {MIN_SAMPLES} samples, found {signal.size}")
    if not np.all(np.isfinite(signal)):
        n_bad = int(np.count_nonzero(~np.isfinite(signal)))
        raise ValueError(f"e must be finite, found {n_bad} non-finite sample(s)")
    return signal


def _check_real(value: object, name: str) -> float:
    """Return ``value`` as a finite float, or raise naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Real | np.floating | np.integer):
        raise ValueError(f"{name} must be a finite real number, found {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, found {number}")
    return number


def _check_band(band: object) -> float:
    return _check_band_like(band, "band")


def _check_tolerance(tolerance: object) -> float:
    number = _check_real(tolerance, "tolerance")
    if number < 0.0:
        raise ValueError(f"tolerance must be >= 0, found {number}")
    return number


def _check_final_window(final_window: object, n_samples: int) -> int:
    """Return the window clipped to ``n_samples``, after checking it is an integer >= 1."""
    if isinstance(final_window, bool) or not isinstance(final_window, Integral | np.integer):
        raise ValueError(f"final_window must be an integer >= 1, found {final_window!r}")
    window = int(final_window)
    if window < 1:
        raise ValueError(f"final_window must be an integer >= 1, found {window}")
    return min(window, n_samples)


def _final_value(signal: NDArray[np.float64], final_value: object, final_window: object) -> float:
    """Checked ``final_value``, or the mean of the last ``final_window`` samples when None."""
    window = _check_final_window(final_window, signal.size)
    if final_value is None:
        return float(np.mean(signal[-window:]))
    return _check_real(final_value, "final_value")


# ---------------------------------------------------------------------------------------------
# Metrics
# ---------------------------------------------------------------------------------------------


def steady_state_error(e: ArrayLike, final_window: int = DEFAULT_FINAL_WINDOW) -> float:
    """Final value of the deviation: the mean of the last ``final_window`` samples.

    Parameters
    ----------
    e : array_like, shape (T,)
        Deviation from the operating point, finite, :math:`T \\ge 2`.
    final_window : int, optional
        Window :math:`W \\ge 1` (samples); clipped to :math:`T`. Default 20.

    Returns
    -------
    float
        :math:`e_f = \\frac{1}{W} \\sum_{t = T - W}^{T - 1} e[t]`, in the units of ``e``.

    Notes
    -----
    This is the steady-state error only once the record has settled; check
    :func:`settling_time` (or :attr:`ResponseMetrics.settled`) before reading it as one.
    """
    signal = _as_signal(e)
    return _final_value(signal, None, final_window)


def overshoot(
    e: ArrayLike,
    final_value: float | None = None,
    tolerance: float | None = None,
    *,
    final_window: int = DEFAULT_FINAL_WINDOW,
) -> float:
    """Largest excursion past the final value on the side opposite to the initial deviation.

    Parameters
    ----------
    e : array_like, shape (T,)
        Deviation from the operating point, finite, :math:`T \\ge 2`.
    final_value : float, optional
        :math:`e_f`; default the mean of the last ``final_window`` samples.
    tolerance : float, optional
        :math:`\\varepsilon \\ge 0` a sample must exceed to fix the initial direction; default
        ``OVERSHOOT_REL_TOLERANCE * max_t |e[t] - e_f| + OVERSHOOT_ABS_TOLERANCE``.
    final_window : int, optional
        Window used when ``final_value`` is None. Default 20.

    Returns
    -------
    float
        Overshoot :math:`\\ge 0`, in the units of ``e``; 0 if the record never deviates by more
        than :math:`\\varepsilon` from :math:`e_f`.

    Notes
    -----
    Let :math:`t_0` be the first step with :math:`|e[t_0] - e_f| > \\varepsilon` and
    :math:`s = \\operatorname{sign}(e[t_0] - e_f)` the side of the initial deviation. Then

    .. math::

        \\mathrm{OS} = \\max\\Bigl(0,\\ \\max_{0 \\le t < T} -s\\,(e[t] - e_f)\\Bigr).

    For a step from 0 towards :math:`e_f` this is the classical absolute overshoot (peak past the
    final value; divide by :math:`|e_f|` for the fraction python-control reports in percent). For
    an impulse (:math:`e_f \\approx 0`) it is the largest swing to the other side.
    """
    signal = _as_signal(e)
    e_final = _final_value(signal, final_value, final_window)
    deviation = signal - e_final
    magnitude = np.abs(deviation)
    if tolerance is None:
        threshold = OVERSHOOT_REL_TOLERANCE * float(magnitude.max()) + OVERSHOOT_ABS_TOLERANCE
    else:
        threshold = _check_tolerance(tolerance)
    beyond = np.flatnonzero(magnitude > threshold)
    if beyond.size == 0:
        return 0.0
    side = np.sign(deviation[beyond[0]])
    return max(0.0, float(np.max(-side * deviation)))


def settling_time(
    e: ArrayLike,
    band: float,
    final_value: float | None = None,
    final_window: int = DEFAULT_FINAL_WINDOW,
) -> int | None:
    """First step after which the deviation stays within ``band`` of its final value.

    Parameters
    ----------
    e : array_like, shape (T,)
        Deviation from the operating point, finite, :math:`T \\ge 2`.
    band : float
        Band :math:`b > 0`, in the units of ``e`` (absolute, not relative to :math:`e_f`).
    final_value : float, optional
        :math:`e_f`; default the mean of the last ``final_window`` samples.
    final_window : int, optional
        Window :math:`W \\ge 1` (samples, clipped to :math:`T`) that must lie inside the band for
        the record to count as settled; also used for :math:`e_f` when it is not given.

    Returns
    -------
    int or None
        Settling time in steps, or ``None`` when the record has not settled.

    Notes
    -----
    With the set of samples outside the band
    :math:`O = \\{t : |e[t] - e_f| > b\\}`:

    .. math::

        t_s = \\begin{cases}
            \\text{None} & \\text{if } O \\cap [T - W, T - 1] \\neq \\emptyset,\\\\
            0 & \\text{if } O = \\emptyset,\\\\
            \\max O + 1 & \\text{otherwise.}
        \\end{cases}

    So a record still moving in its last window is never given a number, and
    :math:`|e[t] - e_f| \\le b` for every :math:`t \\ge t_s`.
    """
    signal = _as_signal(e)
    band_value = _check_band(band)
    window = _check_final_window(final_window, signal.size)
    e_final = _final_value(signal, final_value, window)
    outside = np.flatnonzero(np.abs(signal - e_final) > band_value)
    if outside.size == 0:
        return 0
    last_outside = int(outside[-1])
    if last_outside >= signal.size - window:
        return None
    return last_outside + 1


def relative_band(
    e: ArrayLike,
    fraction: float = DEFAULT_RELATIVE_BAND,
    final_value: float | None = None,
    final_window: int = DEFAULT_FINAL_WINDOW,
) -> float:
    """Settling band relative to the response: ``fraction`` of the peak error.

    .. math::

        b = \text{fraction} \\cdot \\max_t |e[t] - e_f|

    Returns 0.0 for a record that never leaves its final value (it settles at step 0).
    """
    signal = _as_signal(e)
    number = _check_real(fraction, "band_fraction")
    if not 0.0 < number < 1.0:
        raise ValueError(f"band_fraction must be in (0, 1), found {number}")
    e_final = _final_value(signal, final_value, final_window)
    return number * float(np.max(np.abs(signal - e_final)))


def response_metrics(
    e: ArrayLike,
    band: float | None = None,
    final_window: int = DEFAULT_FINAL_WINDOW,
    *,
    band_fraction: float = DEFAULT_RELATIVE_BAND,
    dt: float | None = None,
    terminated: bool = False,
) -> ResponseMetrics:
    """All transient-response metrics of one record, from one estimate of the final value.

    Parameters
    ----------
    e : array_like, shape (T,)
        Deviation from the operating point, finite, :math:`T \\ge 2`.
    band : float, optional
        Absolute settling band :math:`b > 0`, in the units of ``e``. Default: relative,
        ``band_fraction`` of the peak error (:func:`relative_band`).
    final_window : int, optional
        Window :math:`W \\ge 1` (samples, clipped to :math:`T`; default 20).
    band_fraction : float, optional
        The default relative band's fraction of the peak error (default 0.02, 2 %).
    dt : float, optional
        Time step in seconds; fills ``settling_seconds``.
    terminated : bool, optional
        Whether the episode ended early (recorded).

    Returns
    -------
    ResponseMetrics
        :math:`e_f` (:func:`steady_state_error`), :func:`overshoot` and :func:`settling_time`
        with that same :math:`e_f`, and the peak deviation.
    """
    signal = _as_signal(e)
    window = _check_final_window(final_window, signal.size)
    e_final = _final_value(signal, None, window)
    if band is None:
        band_value = relative_band(signal, band_fraction, e_final, window)
        fraction: float | None = float(band_fraction)
    else:
        band_value, fraction = _check_band(band), None
    settle = 0  # a flat record (band 0): no sample ever leaves its final value
    if band_value > 0.0:
        settle = settling_time(signal, band_value, final_value=e_final, final_window=window)
    timed = dt is not None and settle is not None
    seconds = settle * _check_band_like(dt, "dt") if timed else None
    return ResponseMetrics(
        steady_state_error=e_final,
        overshoot=overshoot(signal, final_value=e_final),
        settling_time=settle,
        settled=settle is not None,
        band=band_value,
        final_window=window,
        peak_deviation=float(np.max(np.abs(signal))),
        settling_seconds=seconds,
        band_fraction=fraction,
        terminated=bool(terminated),
    )


def _check_band_like(value: object, name: str) -> float:
    number = _check_real(value, name)
    if number <= 0.0:
        raise ValueError(f"{name} must be > 0, found {number}")
    return number


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and population std (ddof 0); NaN for both when ``values`` is empty."""
    if len(values) == 0:
        return math.nan, math.nan
    array = np.asarray(values, dtype=np.float64)
    return float(np.mean(array)), float(np.std(array, ddof=_POPULATION_DDOF))


def summarise_metrics(metrics: Sequence[ResponseMetrics]) -> MetricsSummary:
    """Mean and std of the metrics of several runs (for example one per seed).

    Parameters
    ----------
    metrics : sequence of ResponseMetrics
        At least one run.

    Returns
    -------
    MetricsSummary
        Means and population standard deviations
        (:math:`\\sigma = \\sqrt{\\frac{1}{n}\\sum_i (x_i - \\bar x)^2}`, ``ddof=0``) of the
        steady-state error and the overshoot over all runs, and of the settling time over the
        runs that settled only (NaN when none did), with ``n_runs`` and ``n_settled``.
    """
    runs = list(metrics)
    if len(runs) == 0:
        raise ValueError("metrics must hold at least one ResponseMetrics, found 0")
    for index, run in enumerate(runs):
        if not isinstance(run, ResponseMetrics):
            raise ValueError(
                f"metrics[{index}] must be a ResponseMetrics, found {type(run).__name__}"
            )
    error_mean, error_std = _mean_std([run.steady_state_error for run in runs])
    overshoot_mean, overshoot_std = _mean_std([run.overshoot for run in runs])
    settled_times = [float(run.settling_time) for run in runs if run.settling_time is not None]
    settle_mean, settle_std = _mean_std(settled_times)
    peak_mean, peak_std = _mean_std([run.peak_deviation for run in runs])
    return MetricsSummary(
        steady_state_error_mean=error_mean,
        steady_state_error_std=error_std,
        overshoot_mean=overshoot_mean,
        overshoot_std=overshoot_std,
        settling_time_mean=settle_mean,
        settling_time_std=settle_std,
        n_runs=len(runs),
        n_settled=len(settled_times),
        peak_deviation_mean=peak_mean,
        peak_deviation_std=peak_std,
        n_terminated=sum(bool(run.terminated) for run in runs),
    )


def authors_response_metrics(
    e: ArrayLike, *, dt: float | None = None, terminated: bool = False
) -> ResponseMetrics:
    r"""The authors' transient metrics (nrjc/LEOC ``plotting/plotter.py``), leoc's second set.

    With :math:`T` samples :math:`e[0..T-1]` (``e`` as the authors compute it: the angle as
    :math:`\arcsin(\sin\theta)` in degrees, the mountain car's position as is; see
    :mod:`leoc.evaluation.metric_sets`):

    * steady state :math:`e_f = e[T-1]`, the last sample; it counts as reached when the last
      :data:`AUTHORS_STEADY_WINDOW` samples agree with it to :data:`AUTHORS_STEADY_TOLERANCE`;
    * "overshoot" :math:`\max_t |e[t] - e_f|`, the peak deviation from that value (for an
      impulse from the operating point: the peak excursion, not an overshoot past it);
    * settling time: one plus the last index with :math:`|e[t] - e_f| \ge \pi/180` (an
      absolute band in the units of ``e``), or :math:`T` when no sample leaves the band (the
      paper's mountain-car 201 is this case: the response never leaves 0.0175 m);
      ``None`` when the steady state was not reached.

    Differences from leoc's :func:`response_metrics`: the last sample, not a window mean; an
    absolute band, not 2 % of the peak; a record that never leaves the band settles at
    :math:`T` rather than 0.

    Returns
    -------
    ResponseMetrics
        ``band = pi/180``, ``final_window = 10``, ``band_fraction = None``.
    """
    signal = _as_signal(e)
    final = float(signal[-1])
    window = min(AUTHORS_STEADY_WINDOW, signal.size)
    reached = bool(np.all(np.abs(signal[-window:] - final) <= AUTHORS_STEADY_TOLERANCE))
    outside = np.flatnonzero(np.abs(signal - final) >= AUTHORS_BAND)
    settle = (int(outside[-1]) + 1 if outside.size else int(signal.size)) if reached else None
    seconds = settle * _check_band_like(dt, "dt") if dt is not None and settle is not None else None
    return ResponseMetrics(
        steady_state_error=final,
        overshoot=float(np.max(np.abs(signal - final))),
        settling_time=settle,
        settled=settle is not None,
        band=AUTHORS_BAND,
        final_window=window,
        peak_deviation=float(np.max(np.abs(signal))),
        settling_seconds=seconds,
        band_fraction=None,
        terminated=bool(terminated),
    )
