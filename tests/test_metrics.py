"""Tests of leoc.evaluation.metrics against closed forms, python-control and properties."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from leoc.evaluation.metrics import (
    DEFAULT_FINAL_WINDOW,
    MetricsSummary,
    ResponseMetrics,
    overshoot,
    response_metrics,
    settling_time,
    steady_state_error,
    summarise_metrics,
)

# Smallest distance (relative) of a closed-form crossing from a grid point that we accept as
# "not on the grid": closer than this, rounding could legitimately move the answer by one step.
GRID_GAP = 1e-6


# ---------------------------------------------------------------------------------------------
# Closed forms
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("amplitude", "time_constant", "band"),
    [(5.0, 12.5, 0.3), (1.0, 3.0, 0.02), (-2.0, 40.0, 0.5), (10.0, 1.7, 1.0)],
)
def test_decaying_exponential_closed_form(amplitude, time_constant, band):
    n_samples = 100 * math.ceil(time_constant) + 200
    steps = np.arange(n_samples)
    e = amplitude * np.exp(-steps / time_constant)
    crossing = time_constant * math.log(abs(amplitude) / band)
    assert abs(crossing - round(crossing)) > GRID_GAP  # the crossing is not on a grid point
    # first integer t with |A| exp(-t / T) <= band
    expected = math.ceil(crossing)
    # the final-window mean is at most the value at the window's start
    tail = abs(amplitude) * math.exp(-(n_samples - DEFAULT_FINAL_WINDOW) / time_constant)

    metrics = response_metrics(e, band)
    assert metrics.steady_state_error == pytest.approx(0.0, abs=tail)
    # the record never crosses zero: the only "overshoot" is the tail below its own mean
    assert metrics.overshoot == pytest.approx(0.0, abs=tail)
    assert metrics.settling_time == expected
    assert metrics.settled
    assert settling_time(e, band) == expected


def _damped_sine(amplitude, zeta, omega):
    """f(t) = A exp(-zeta w t) sin(w_d t): decay rate, damped frequency and f."""
    decay = zeta * omega
    omega_d = omega * math.sqrt(1.0 - zeta**2)

    def f(t):
        return amplitude * np.exp(-decay * t) * np.sin(omega_d * t)

    return decay, omega_d, f


@pytest.mark.parametrize(
    ("amplitude", "zeta", "omega", "dt", "band"),
    [(2.0, 0.2, 1.0, 0.01, 0.05), (1.0, 0.05, 3.0, 0.005, 0.1), (30.0, 0.5, 0.7, 0.02, 1.0)],
)
def test_damped_sinusoid_closed_form(amplitude, zeta, omega, dt, band):
    decay, omega_d, f = _damped_sine(amplitude, zeta, omega)
    # long enough for the tail to be far below every tolerance used here
    duration = math.log(amplitude * 1e13) / decay
    times = dt * np.arange(math.ceil(duration / dt))
    e = f(times)

    # Extrema of f solve tan(w_d t) = w_d / (zeta w); they are t_n = (phi + n pi) / w_d with
    # phi = atan2(w_d, zeta w), where |sin(w_d t_n)| = w_d / w, so |f(t_n)| = A e^{-a t_n} w_d / w.
    phi = math.atan2(omega_d, decay)

    def peak_time(n):
        return (phi + n * math.pi) / omega_d

    def peak_size(n):
        return amplitude * math.exp(-decay * peak_time(n)) * omega_d / omega

    # Overshoot: f starts positive, so it is the first negative extremum (n = 1). Sampling
    # misses the true peak by at most max|f''| (dt/2)^2 / 2, and |f''| <= A w^2.
    expected_overshoot = peak_size(1)
    sampling_error = amplitude * omega**2 * dt**2 / 8.0
    tail = amplitude * math.exp(-decay * times[-DEFAULT_FINAL_WINDOW])
    got = overshoot(e)
    assert expected_overshoot - sampling_error - tail <= got <= expected_overshoot + tail

    # Settling: the last extremum above the band is n_last; the last exit t* from the band is
    # the root of |f| = band between t_{n_last} and the next zero (n_last + 1) pi / w_d.
    n_last = math.floor(
        (math.log(amplitude * omega_d / (omega * band)) / decay - phi / omega_d) * omega_d / math.pi
    )
    assert peak_size(n_last) > band >= peak_size(n_last + 1)
    t_exit = brentq(lambda t: abs(f(t)) - band, peak_time(n_last), (n_last + 1) * math.pi / omega_d)
    assert t_exit - peak_time(n_last) > dt  # a sample lies in the last excursion
    assert abs(t_exit / dt - round(t_exit / dt)) > GRID_GAP
    # samples k with k dt < t* include the last one outside the band: t_s = ceil(t* / dt)
    expected_settling = math.ceil(t_exit / dt)
    assert settling_time(e, band, final_value=0.0) == expected_settling
    metrics = response_metrics(e, band)
    assert metrics.settling_time == expected_settling
    assert metrics.steady_state_error == pytest.approx(0.0, abs=tail)

    # independent brute force on a 100x finer grid: the root brackets the last fine sample
    # outside the band, and the settling step lies within one step of it
    fine_dt = dt / 100.0
    fine = fine_dt * np.arange(math.ceil(times[-1] / fine_dt))
    last_fine = fine[np.flatnonzero(np.abs(f(fine)) > band)[-1]]
    assert 0.0 <= t_exit - last_fine <= fine_dt
    assert 0.0 <= metrics.settling_time - last_fine / dt <= 1.0 + fine_dt / dt


def test_undamped_sinusoid_never_settles():
    steps = np.arange(500)
    e = 3.0 * np.sin(2.0 * math.pi * steps / 40.0)  # period 40 samples: hits -3 at t = 30
    metrics = response_metrics(e, band=0.3, final_window=40)  # one period: e_f ~ 0
    assert metrics.settling_time is None
    assert not metrics.settled
    # it starts upwards, so the overshoot is the full swing below the final-window mean
    assert metrics.overshoot == pytest.approx(3.0 + metrics.steady_state_error, abs=1e-12)


def test_ramp_never_settles():
    e = 0.01 * np.arange(300)
    assert settling_time(e, band=0.05) is None
    assert not response_metrics(e, band=0.05).settled


def test_not_settled_even_if_last_sample_is_in_band():
    # the final window contains an excursion although the very last sample is at zero
    e = np.zeros(100)
    e[-5] = 1.0
    assert settling_time(e, band=0.5, final_value=0.0) is None
    # the same excursion just before the window: settles one step after it
    assert settling_time(e, band=0.5, final_value=0.0, final_window=4) == 96


@pytest.mark.parametrize("band", [0.1, 1.0, 7.5])
def test_never_leaves_band_settles_at_zero(band):
    steps = np.arange(200)
    e = 0.4 * band * np.sin(0.3 * steps) * np.exp(-steps / 50.0) + 2.0
    assert settling_time(e, band) == 0
    metrics = response_metrics(e, band)
    assert metrics.settling_time == 0
    assert metrics.settled


def test_constant_signal():
    e = np.full(50, -4.25)
    metrics = response_metrics(e, band=0.1)
    assert metrics == ResponseMetrics(-4.25, 0.0, 0, True, 0.1, DEFAULT_FINAL_WINDOW, 4.25)


@pytest.mark.parametrize("offset", [0.75, -3.0, 12.0])
def test_step_with_constant_offset(offset):
    time_constant = 8.0
    n_samples = 600
    e = offset * (1.0 - np.exp(-np.arange(n_samples) / time_constant))
    tail = abs(offset) * math.exp(-(n_samples - DEFAULT_FINAL_WINDOW) / time_constant)
    assert steady_state_error(e) == pytest.approx(offset, abs=tail)
    # a first-order step never passes its final value
    assert overshoot(e) == pytest.approx(0.0, abs=tail)


def test_step_overshoot_is_peak_past_final_value():
    # a step to 2 that peaks at 2.5: from below, so the overshoot is above the final value
    e = np.concatenate([[0.0, 1.0, 2.5, 1.8], np.full(30, 2.0)])
    assert overshoot(e) == pytest.approx(0.5)
    # mirrored step (to -2): same overshoot, below the final value
    assert overshoot(-e) == pytest.approx(0.5)
    # impulse-like record starting below zero: the largest swing above zero counts
    impulse = np.concatenate([[0.0, -3.0, 1.2, -0.4, 0.1], np.zeros(30)])
    assert overshoot(impulse) == pytest.approx(1.2)


def test_overshoot_tolerance_fixes_initial_direction():
    # a dip below 1% of the peak deviation does not fix the direction (default tolerance) ...
    e = np.concatenate([[0.0, -0.001, 1.0, -0.3], np.zeros(30)])
    assert overshoot(e) == pytest.approx(0.3)
    # ... but it does when the given tolerance is below it
    assert overshoot(e, tolerance=1e-4) == pytest.approx(1.0)
    # a final value a hair away from the start (an impulse that leaves a tiny steady-state
    # error) must not make the start sample the "initial deviation"
    e_offset = np.concatenate([[0.0, 0.7, 1.2, -0.5, 0.1], np.full(30, 0.001)])
    assert overshoot(e_offset) == pytest.approx(0.501)
    assert overshoot(e, final_value=0.0, tolerance=2.0) == 0.0  # never deviates by 2


def test_final_window_is_clipped():
    e = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    assert steady_state_error(e, final_window=2) == pytest.approx(4.5)
    assert steady_state_error(e, final_window=100) == pytest.approx(3.0)
    # the mean, not the median or the last sample: (1 + 2 + 6) / 3
    assert steady_state_error(np.array([0.0, 0.0, 1.0, 2.0, 6.0]), final_window=3) == 3.0
    metrics = response_metrics(e, band=10.0, final_window=100)
    assert metrics.final_window == e.size
    assert metrics.settling_time == 0


# ---------------------------------------------------------------------------------------------
# Agreement with python-control's step_info
# ---------------------------------------------------------------------------------------------
# step_info (control/timeresp.py, 0.10) on a step response y with final value y_inf = dcgain:
#   Overshoot    = 100 (max(sign(y_inf) y) - |y_inf|) / |y_inf|  (percent of the final value),
#   SettlingTime = T[k + 1], k the last index with |y / y_inf - 1| >= 0.02  (seconds),
#                  NaN only if k is the last index.
# Our e is y itself (the deviation from the zero operating point), so for y_inf > 0:
#   Overshoot    = 100 overshoot(y, final_value=y_inf) / |y_inf|,
#   SettlingTime = dt settling_time(y, band=0.02 |y_inf|, final_value=y_inf).
# Residual definition differences: (1) step_info flags |.| >= band, we flag |.| > band; they
# differ only for a sample exactly on the band edge, which the tests exclude explicitly.
# (2) our default final value is the final-window mean, not the DC gain; the overshoot then
# differs by exactly 100 P |1 - e_f / y_inf| / |e_f| (P the peak) and the settling index is
# unchanged if no sample lies within |e_f - y_inf| (1 + 0.02) of the band edge. (3) step_info
# gives a time when only the last sample is in band; we require the whole final window
# (test_python_control_reports_unsettled_oscillator_as_settled).

SETTLING_FRACTION = 0.02  # python-control's default SettlingTimeThreshold


@pytest.mark.parametrize(
    ("omega", "zeta", "dt", "gain"),
    [(2.0, 0.3, 0.01, 1.0), (5.0, 0.1, 0.002, 3.0), (1.0, 0.7, 0.02, 0.5)],
)
def test_agrees_with_python_control_step_info(omega, zeta, dt, gain):
    system = control.tf([gain * omega**2], [1.0, 2.0 * zeta * omega, omega**2])
    decay = zeta * omega
    duration = math.log(1e14) / decay
    n_samples = math.ceil(duration / dt) + 1
    times = dt * np.arange(n_samples)
    y = np.squeeze(control.step_response(system, times).outputs)
    info = control.step_info(system, T=times)
    y_inf = float(control.dcgain(system))
    assert y_inf == pytest.approx(gain)
    band = SETTLING_FRACTION * abs(y_inf)
    edge_gap = float(np.min(np.abs(np.abs(y - y_inf) - band)))
    assert edge_gap > 0.0  # no sample exactly on the band edge: '>=' and '>' agree

    # (a) same final value: identical definitions
    overshoot_percent = 100.0 * overshoot(y, final_value=y_inf) / abs(y_inf)
    assert overshoot_percent == pytest.approx(info["Overshoot"], rel=1e-12)
    steps = settling_time(y, band, final_value=y_inf)
    assert steps is not None
    # any tolerance below dt / 2 pins the grid index exactly
    assert steps * dt == pytest.approx(info["SettlingTime"], abs=dt / 2.0)

    # (b) our own final-value estimate, with the bounds derived in the block comment above
    metrics = response_metrics(y, band=SETTLING_FRACTION * abs(steady_state_error(y)))
    e_final = metrics.steady_state_error
    peak = float(np.max(y))
    offset_bound = 100.0 * peak * abs(1.0 - e_final / y_inf) / abs(e_final)
    ours = 100.0 * metrics.overshoot / abs(e_final)
    assert abs(ours - info["Overshoot"]) <= offset_bound + 1e-12 * info["Overshoot"]
    assert edge_gap > abs(e_final - y_inf) * (1.0 + SETTLING_FRACTION)
    assert metrics.settling_time is not None
    assert metrics.settling_time * dt == pytest.approx(info["SettlingTime"], abs=dt / 2.0)

    # (c) both agree with the closed form 100 exp(-zeta pi / sqrt(1 - zeta^2)) within the
    # sampling error of a peak, max|y''| (dt/2)^2 / 2 with |y''| <= w^3 / w_d (relative to gain)
    omega_d = omega * math.sqrt(1.0 - zeta**2)
    analytic = 100.0 * math.exp(-zeta * math.pi / math.sqrt(1.0 - zeta**2))
    sampling_error = 100.0 * omega**3 / omega_d * dt**2 / 8.0
    assert analytic - sampling_error <= overshoot_percent <= analytic + 1e-9


def test_python_control_reports_unsettled_oscillator_as_settled():
    # Undamped oscillator y = 1 - cos(w t), ending at w t = pi/2 + 2 pi n where y = 1: only the
    # last sample is inside the band. step_info gives the final time; we say "not settled".
    omega = 2.0
    dt = 0.01
    n_cycles = 5
    duration = (0.5 * math.pi + 2.0 * math.pi * n_cycles) / omega
    times = np.linspace(0.0, duration, round(duration / dt) + 1)
    system = control.tf([omega**2], [1.0, 0.0, omega**2])
    y = np.squeeze(control.step_response(system, times).outputs)
    info = control.step_info(system, T=times)
    assert info["SettlingTime"] == pytest.approx(times[-1])
    assert settling_time(y, SETTLING_FRACTION, final_value=1.0) is None
    assert not response_metrics(y, SETTLING_FRACTION).settled


# ---------------------------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------------------------
# Dyadic samples (integers / 64) scaled by powers of two keep every comparison exact, so the
# properties can be asserted with ==, not approximately.

DYADIC = 64.0
dyadic_values = st.integers(-2000, 2000).map(lambda k: k / DYADIC)
dyadic_signals = st.lists(dyadic_values, min_size=2, max_size=60).map(np.array)
bands = st.integers(1, 2000).map(lambda k: k / DYADIC)
windows = st.integers(1, 25)
powers_of_two = st.tuples(st.sampled_from([-1.0, 1.0]), st.integers(-8, 8)).map(
    lambda sign_exponent: sign_exponent[0] * 2.0 ** sign_exponent[1]
)


@settings(max_examples=200, deadline=None)
@given(e=dyadic_signals, band=bands, window=windows, scale=powers_of_two)
def test_scaling(e, band, window, scale):
    base = response_metrics(e, band, window)
    scaled = response_metrics(scale * e, abs(scale) * band, window)
    assert scaled.steady_state_error == scale * base.steady_state_error
    assert scaled.overshoot == abs(scale) * base.overshoot
    assert scaled.settling_time == base.settling_time
    assert scaled.settled == base.settled


@settings(max_examples=200, deadline=None)
@given(head=dyadic_signals, level=dyadic_values, window=windows, band=bands, shift=dyadic_values)
def test_shift(head, level, window, band, shift):
    # a constant final window makes the final value exact, so the shift is exact too
    e = np.concatenate([head, np.full(window, level)])
    base = response_metrics(e, band, window)
    shifted = response_metrics(e + shift, band, window)
    assert base.steady_state_error == level
    assert shifted.steady_state_error == level + shift
    assert shifted.overshoot == base.overshoot
    assert shifted.settling_time == base.settling_time


finite_floats = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(
    e=st.lists(finite_floats, min_size=2, max_size=60).map(np.array),
    band=st.floats(1e-3, 1e3),
    window=windows,
)
def test_settling_definition(e, band, window):
    e_final = steady_state_error(e, window)
    result = settling_time(e, band, final_window=window)
    metrics = response_metrics(e, band, window)
    assert metrics.settling_time == result
    assert metrics.settled == (result is not None)
    used = min(window, e.size)
    outside = [abs(value - e_final) > band for value in e]
    # None exactly when the last window leaves the band
    assert (result is None) == any(outside[-used:])
    if result is not None:
        assert not any(outside[result:])
        assert result == 0 or outside[result - 1]
    assert 0.0 <= metrics.overshoot <= float(np.max(np.abs(e - e_final)))


# ---------------------------------------------------------------------------------------------
# Summary over runs
# ---------------------------------------------------------------------------------------------


def test_summarise_metrics_known_values():
    runs = [
        ResponseMetrics(1.0, 0.0, 10, True, 1.0, 20),
        ResponseMetrics(2.0, 1.0, None, False, 1.0, 20),
        ResponseMetrics(3.0, 2.0, 20, True, 1.0, 20),
    ]
    summary = summarise_metrics(runs)
    assert isinstance(summary, MetricsSummary)
    assert summary.steady_state_error_mean == pytest.approx(2.0)
    assert summary.steady_state_error_std == pytest.approx(math.sqrt(2.0 / 3.0))  # ddof = 0
    assert summary.overshoot_mean == pytest.approx(1.0)
    assert summary.overshoot_std == pytest.approx(math.sqrt(2.0 / 3.0))
    assert summary.settling_time_mean == pytest.approx(15.0)  # settled runs only
    assert summary.settling_time_std == pytest.approx(5.0)
    assert (summary.n_runs, summary.n_settled) == (3, 2)


def test_summarise_metrics_none_settled():
    runs = [ResponseMetrics(0.5, 0.1, None, False, 1.0, 20)] * 2
    summary = summarise_metrics(runs)
    assert math.isnan(summary.settling_time_mean)
    assert math.isnan(summary.settling_time_std)
    assert summary.steady_state_error_std == 0.0
    assert (summary.n_runs, summary.n_settled) == (2, 0)


def test_summarise_metrics_rejects_bad_input():
    with pytest.raises(ValueError, match="at least one ResponseMetrics, found 0"):
        summarise_metrics([])
    with pytest.raises(ValueError, match=r"metrics\[0\] must be a ResponseMetrics, found tuple"):
        summarise_metrics([(1.0, 0.0, 3, True, 1.0, 20)])


# ---------------------------------------------------------------------------------------------
# Input validation
# ---------------------------------------------------------------------------------------------

GOOD = np.linspace(1.0, 0.0, 30)


@pytest.mark.parametrize(
    ("e", "match"),
    [
        (np.zeros((3, 4)), r"e must be 1-D, found shape \(3, 4\)"),
        (np.array(1.0), r"e must be 1-D, found shape \(\)"),
        (np.array([1.0]), "e must have at least 2 samples, found 1"),
        (np.array([0.0, np.nan, 1.0]), r"e must be finite, found 1 non-finite sample\(s\)"),
        (np.array([0.0, np.inf, -np.inf]), r"e must be finite, found 2 non-finite sample\(s\)"),
        (np.array([1j, 2.0]), "e must be real, found a complex array"),
        (["a", "b"], "e must be a 1-D array of real numbers, found list"),
    ],
)
def test_rejects_bad_signal(e, match):
    for call in (
        lambda: steady_state_error(e),
        lambda: overshoot(e),
        lambda: settling_time(e, 1.0),
        lambda: response_metrics(e, 1.0),
    ):
        with pytest.raises(ValueError, match=match):
            call()


@pytest.mark.parametrize(
    ("band", "match"),
    [
        (0.0, "band must be > 0, found 0.0"),
        (-1.0, "band must be > 0, found -1.0"),
        (math.nan, "band must be finite, found nan"),
        (math.inf, "band must be finite, found inf"),
        ("1", "band must be a finite real number, found '1'"),
        (True, "band must be a finite real number, found True"),
    ],
)
def test_rejects_bad_band(band, match):
    with pytest.raises(ValueError, match=match):
        settling_time(GOOD, band)
    with pytest.raises(ValueError, match=match):
        response_metrics(GOOD, band)


@pytest.mark.parametrize(
    ("window", "match"),
    [
        (0, "final_window must be an integer >= 1, found 0"),
        (-3, "final_window must be an integer >= 1, found -3"),
        (2.5, "final_window must be an integer >= 1, found 2.5"),
        (True, "final_window must be an integer >= 1, found True"),
    ],
)
def test_rejects_bad_final_window(window, match):
    with pytest.raises(ValueError, match=match):
        steady_state_error(GOOD, window)
    with pytest.raises(ValueError, match=match):
        settling_time(GOOD, 1.0, final_window=window)
    with pytest.raises(ValueError, match=match):
        response_metrics(GOOD, 1.0, window)
    with pytest.raises(ValueError, match=match):
        overshoot(GOOD, final_window=window)


def test_accepts_numpy_scalars():
    assert steady_state_error(GOOD, np.int64(5)) == pytest.approx(float(np.mean(GOOD[-5:])))
    assert settling_time(GOOD, np.float32(2.0)) == 0


def test_rejects_bad_final_value_and_tolerance():
    with pytest.raises(ValueError, match="final_value must be finite, found nan"):
        overshoot(GOOD, final_value=math.nan)
    with pytest.raises(ValueError, match="final_value must be finite, found inf"):
        settling_time(GOOD, 1.0, final_value=math.inf)
    with pytest.raises(ValueError, match="tolerance must be >= 0, found -0.1"):
        overshoot(GOOD, tolerance=-0.1)
    with pytest.raises(ValueError, match="tolerance must be finite, found nan"):
        overshoot(GOOD, tolerance=math.nan)


# ---------------------------------------------------------------------------------------------
# The relative band (default): 2 % of the peak error, against closed forms
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("pole", [0.5, 0.8, 0.95])
def test_relative_band_first_order_decay_closed_form(pole):
    # e[t] = pole^t: e_f ~ 0, peak error 1, band 0.02, so the record settles at the first t
    # with pole^t <= 0.02: t_s = ceil(ln 0.02 / ln pole) (the window is far inside the band)
    e = pole ** np.arange(400.0)
    metrics = response_metrics(e, dt=0.05)
    expected = math.ceil(math.log(0.02) / math.log(pole))
    assert metrics.band_fraction == 0.02
    assert metrics.band == pytest.approx(0.02 * (1.0 - metrics.steady_state_error))
    assert metrics.settling_time == expected
    assert metrics.settling_seconds == pytest.approx(expected * 0.05)
    assert metrics.peak_deviation == 1.0


@pytest.mark.parametrize(("radius", "frequency"), [(0.9, 0.5), (0.97, 0.2)])
def test_relative_band_second_order_decay_between_envelope_bounds(radius, frequency):
    # e[t] = r^t cos(w t): the envelope r^t reaches 2 % of the peak (1 at t = 0) at
    # t_env = ln 0.02 / ln r; the oscillation can only settle earlier, and not before the last
    # envelope crossing of the band less one half period
    t = np.arange(600.0)
    e = radius**t * np.cos(frequency * t)
    metrics = response_metrics(e)
    envelope = math.log(0.02) / math.log(radius)
    assert metrics.settled
    assert envelope - math.pi / frequency - 1 <= metrics.settling_time <= math.ceil(envelope)
    assert metrics.overshoot > 0.0  # the second-order record swings past zero


def test_relative_band_is_scale_free_and_absolute_band_is_not():
    e = 0.9 ** np.arange(300.0)
    assert response_metrics(1e-3 * e).settling_time == response_metrics(e).settling_time
    # an absolute band wider than the whole response: "settled" at 0, what the relative band
    # is there to avoid
    assert response_metrics(1e-3 * e, band=1.0).settling_time == 0


def test_flat_record_settles_at_zero_with_a_relative_band():
    metrics = response_metrics(np.zeros(30))
    assert (metrics.settling_time, metrics.band, metrics.peak_deviation) == (0, 0.0, 0.0)


def test_summary_counts_terminated_runs_and_peaks():
    runs = [
        response_metrics(0.9 ** np.arange(100.0)),
        response_metrics(2.0 * 0.9 ** np.arange(100.0), terminated=True),
    ]
    summary = summarise_metrics(runs)
    assert summary.n_terminated == 1
    assert summary.peak_deviation_mean == pytest.approx(1.5)
