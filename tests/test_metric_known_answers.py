"""Known answers of the response metrics on records worked out by hand, where the relative
settling band's reference (the peak of |e - e_f|, not of |e|) changes the result."""

from __future__ import annotations

import numpy as np
import pytest

from leoc.evaluation.metrics import response_metrics


def test_relative_band_is_two_percent_of_the_peak_error_not_of_the_peak_value() -> None:
    """A step to e_f = 1 overshooting to 1.2: the peak error |e - e_f| is 1 (at t = 0), so the
    band is 0.02 (MATLAB stepinfo's convention), not 0.024 (2 % of max |e| = 1.2). The sample
    at t = 3 (error 0.022) is outside 0.02 and inside 0.024: settling at 4, not 3."""
    e = np.concatenate([[0.0, 0.6, 1.2, 1.022], np.ones(40)])
    metrics = response_metrics(e)
    assert metrics.steady_state_error == 1.0
    assert metrics.band == pytest.approx(0.02, rel=1e-12)
    assert metrics.settling_time == 4
    assert metrics.peak_deviation == 1.2
    assert metrics.overshoot == pytest.approx(0.2, rel=1e-12)  # past e_f, opposite to e(0) - e_f
