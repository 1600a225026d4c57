"""Appendix D's verdicts: when a variant's mean over its seeds reproduces a row of the paper."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from leoc.evaluation.metrics import MetricsSummary
from leoc.experiments.appendix_d import (
    AGREES,
    DIFFERS,
    NOT_RUN,
    SPREAD,
    UNSETTLED,
    AppendixRow,
    appendix_d_verdict_lines,
    appendix_d_verdicts,
    authors_metrics_from_trace,
    metric_verdict,
    row_verdict,
)
from leoc.experiments.paper import PAPER_IMPULSE_METRICS, PaperMetrics

RESULTS = Path(__file__).resolve().parents[1] / "results"
# the paper's pendulum Linear row: -2.95e-13 ± 0, 0.45 ± 0, 26 ± 0
LINEAR = PAPER_IMPULSE_METRICS["pendulum"]["linear"]


def _summary(sse=(0.0, 0.0), overshoot=(0.45, 0.0), settling=(26.0, 0.0), n=5, settled=None):
    return MetricsSummary(
        sse[0], sse[1], overshoot[0], overshoot[1], settling[0], settling[1], n,
        n if settled is None else settled,
    )  # fmt: skip


def test_a_mean_within_two_standard_errors_agrees_and_beyond_them_differs() -> None:
    paper = PaperMetrics((0.0, 1.0), (5.0, 1.0), (50.0, 10.0))
    # settling: 2 sqrt((10^2 + 10^2) / 5) = 12.6, plus 2% of 50 = 1: the edge is at 13.6
    edge = 2 * math.sqrt(200 / 5) + 1.0
    inside = _summary(overshoot=(5.0, 1.0), settling=(50.0 + edge - 0.01, 10.0))
    outside = _summary(overshoot=(5.0, 1.0), settling=(50.0 + edge + 0.01, 10.0))
    assert metric_verdict(paper, "settling_time", inside) == AGREES
    assert metric_verdict(paper, "settling_time", outside) == DIFFERS
    # fewer seeds, wider tolerance: the same mean agrees over 3 seeds
    three = _summary(overshoot=(5.0, 1.0), settling=(50.0 + edge + 0.01, 10.0), n=3)
    assert metric_verdict(paper, "settling_time", three) == AGREES


def test_seeds_that_disagree_cannot_reproduce_but_a_far_mean_still_differs() -> None:
    paper = PaperMetrics((0.0, 0.0), (0.45, 0.0), (26.0, 0.0))
    # steady-state error judged against the paper's overshoot 0.45: std 1 over 5 seeds gives
    # 2 standard errors of 0.89 > 0.45
    assert metric_verdict(paper, "steady_state_error", _summary(sse=(0.1, 1.0))) == SPREAD
    assert metric_verdict(paper, "steady_state_error", _summary(sse=(5.0, 1.0))) == DIFFERS


def test_round_off_agrees_and_every_run_must_settle() -> None:
    # the paper's -2.95e-13 against leoc's -4e-10: round-off against a response of size 0.45
    assert metric_verdict(LINEAR, "steady_state_error", _summary(sse=(-4e-10, 0.0))) == AGREES
    assert metric_verdict(LINEAR, "settling_time", _summary(settled=4)) == UNSETTLED
    assert metric_verdict(LINEAR, "settling_time", None) == NOT_RUN
    # a metric the paper does not print (DDPG baseline's overshoot) agrees
    baseline = PAPER_IMPULSE_METRICS["pendulum"]["ddpg_baseline"]
    assert metric_verdict(baseline, "overshoot", _summary(overshoot=(100.0, 50.0))) == AGREES


def test_rows_and_their_count_per_variant() -> None:
    good = AppendixRow("pendulum", "linear", LINEAR, {"authors": _summary(), "leoc": None})
    bad = AppendixRow(
        "pendulum",
        "linear",
        LINEAR,
        {"authors": _summary(settling=(42.0, 0.0)), "leoc": None},
        {"authors": True, "leoc": True},
    )
    assert row_verdict(good, "authors") == {}
    assert row_verdict(bad, "authors") == {"settling_time": DIFFERS}
    assert row_verdict(good, "leoc") is None
    assert (good.missing("leoc"), bad.missing("leoc")) == ("not run", "not measured")
    lines = appendix_d_verdict_lines([good, bad])
    assert lines[2] == "| pendulum | linear | **reproduces** | not run |"
    assert lines[3] == "| pendulum | linear | no: settling time differs | not measured |"
    assert lines[-2:] == [
        "- leoc, authors' variant: 1 of 2 rows measured reproduce (pendulum linear).",
        "- leoc default: 0 of 0 rows measured reproduce; 1 not run; 1 not measured.",
    ]


@pytest.mark.parametrize("system", sorted(PAPER_IMPULSE_METRICS))
def test_the_papers_own_numbers_reproduce_every_row(system) -> None:
    """The paper's means and stds, read as a variant's over 3 seeds, reproduce each row."""
    for controller, paper in PAPER_IMPULSE_METRICS[system].items():
        overshoot = paper.overshoot or (0.0, 0.0)
        summary = _summary(paper.steady_state_error, overshoot, paper.settling_time, n=3)
        verdicts = row_verdict(AppendixRow(system, controller, paper, {"v": summary}), "v")
        # rows whose seeds disagree beyond the scale cannot reproduce even themselves
        assert set(verdicts.values()) <= {SPREAD}, (system, controller, verdicts)


def _authors_by_hand(e_degrees: list[float]) -> tuple[float, float, int]:
    """The authors' steady-state error, overshoot and settling time of a pendulum trace, by
    hand: arcsin(sin e) sample by sample, the last sample, the largest distance from it, one
    past the last sample at least pi/180 (in degrees, as the authors' band is) away from it."""
    mapped = [math.degrees(math.asin(math.sin(math.radians(value)))) for value in e_degrees]
    final = mapped[-1]
    overshoot = max(abs(value - final) for value in mapped)
    outside = [index for index, value in enumerate(mapped) if abs(value - final) >= math.pi / 180]
    return final, overshoot, outside[-1] + 1 if outside else len(mapped)


def test_the_authors_metrics_from_a_trace_match_a_recomputation_by_hand() -> None:
    # a response past 90 degrees (arcsin(sin e) folds it back), then settling to 0.001
    trace = [0.0, 30.0, 120.0, 170.0, 60.0, 5.0, 0.5] + [0.001] * 14
    impulse = {"deviation": trace, "metrics": {"terminated": False}}
    measured = authors_metrics_from_trace("pendulum", impulse)
    final, overshoot, settle = _authors_by_hand(trace)
    assert measured.steady_state_error == pytest.approx(final, abs=1e-12)
    assert measured.overshoot == pytest.approx(overshoot, abs=1e-12)
    assert measured.settling_time == settle == 7
    assert measured.overshoot == pytest.approx(60.0 - 0.001, abs=1e-9)  # 120 folds to 60


def test_traces_of_the_committed_runs_give_their_recorded_authors_metrics() -> None:
    import json

    runs = sorted((RESULTS / "paper" / "runs").glob("*/*/seed*/evaluation.json"))
    assert runs
    for path in runs:
        impulse = json.loads(path.read_text())["responses"]["impulse"]
        measured = authors_metrics_from_trace(path.parts[-4], impulse)
        recorded = impulse["metrics_authors"]
        assert measured.steady_state_error == pytest.approx(recorded["steady_state_error"]), path
        assert measured.overshoot == pytest.approx(recorded["overshoot"]), path
        assert measured.settling_time == recorded["settling_time"], path


def test_the_verdicts_of_the_committed_folders() -> None:
    lines = appendix_d_verdicts([RESULTS / "paper-authors", RESULTS / "paper"])
    assert "- leoc, authors' variant: 6 of 15 rows measured reproduce" in "\n".join(lines)
    assert any(line.startswith("- leoc default: 0 of 15 rows measured") for line in lines)
    assert not any("measured from the stored traces" in line for line in lines)
    with pytest.raises(ValueError, match="one folder per variant"):
        appendix_d_verdicts([RESULTS / "paper", RESULTS / "paper"])
