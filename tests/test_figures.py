"""Every figure drawn from synthetic runs, falling-over runs included, passes the layout checks:
no data beyond its axes, no legend over a panel or a label, no panel reaching into another;
and the checks themselves catch a figure that breaks them."""

from __future__ import annotations

import numpy as np
import pytest

from leoc.evaluation.plots.basins import draw_basins
from leoc.evaluation.plots.common import layout_problems, pyplot
from leoc.evaluation.plots.learning import draw_learning_curves, learning_caption
from leoc.evaluation.plots.relevance import break_at_wraps, draw_relevance
from leoc.evaluation.plots.responses import (
    Response,
    draw_responses,
    exit_mark,
    exit_text,
    falls_or_diverges,
    panel_layout,
    visible_part,
)
from leoc.evaluation.plots.robustness import draw_robustness
from leoc.experiments.profiles import CONTROLLER_LABELS, CONTROLLERS
from leoc.systems import make_system

STEPS = 201
TIME = np.arange(STEPS)


def _wrap_degrees(values: np.ndarray) -> np.ndarray:
    return (values + 180.0) % 360.0 - 180.0


def _settling(peak: float, rate: float = 0.08, final: float = 0.0) -> np.ndarray:
    return (
        final
        + (peak - final) * np.exp(-rate * TIME) * np.cos(0.05 * TIME)
        - final * np.exp(-rate * TIME)
    )


def _falling(speed: float) -> np.ndarray:
    """A pendulum falling over and spinning: a wrapped angle that sweeps the whole circle."""
    return _wrap_degrees(-0.5 * speed * (TIME / 10.0) ** 2 - 1.0)


def _record(deviation, terminated=False, settled=True) -> dict:
    return {"deviation": deviation, "terminated": terminated, "settled": settled}


def _responses() -> dict:
    pendulum = {
        "linear": [_record(_settling(-1.0))],
        "ddpg_hybrid": [_record(_settling(-1.0 - 0.1 * s)) for s in range(3)],
        "ddpg_baseline": [_record(_falling(30.0 + 5 * s), settled=False) for s in range(3)],
        "pilco_hybrid": [
            _record(_settling(-1.3)),
            _record(_settling(-1.2)),
            _record(_falling(20.0), settled=False),
        ],
    }
    cartpole = {
        "linear": [_record(_settling(1.2))],
        # the cart leaves its track with the pole still near upright: a cross, in range
        "ddpg_hybrid": [_record(np.linspace(0, 0.8, 30), terminated=True, settled=False)] * 3,
        "pilco_baseline": [_record(np.linspace(0, 40, 30), terminated=True, settled=False)],
    }
    mountaincar = {
        "linear": [_record(_settling(-0.02, final=-0.114))],
        "pilco_baseline": [_record(_settling(-0.005, final=-0.007)) for _ in range(3)],
        "pilco_hybrid": [_record(_settling(-0.03, final=-0.13)) for _ in range(3)],
    }
    return {
        "pendulum": {"impulse": pendulum, "step": pendulum},
        "cartpole": {"impulse": cartpole, "step": cartpole},
        "mountaincar": {"impulse": mountaincar, "step": mountaincar},
    }


@pytest.mark.slow
def test_responses_figure_reads_cleanly():
    plt = pyplot()
    figure = draw_responses(_responses(), CONTROLLER_LABELS)
    assert layout_problems(figure) == []
    labels = [text.get_text() for text in figure.legends[0].get_texts()]
    assert len(labels) == len(set(labels))  # one entry per controller, no "(clipped)" twins
    assert set(labels) == {
        *(CONTROLLER_LABELS[c] for c in ("linear", "ddpg_hybrid", "ddpg_baseline")),
        CONTROLLER_LABELS["pilco_hybrid"],
        CONTROLLER_LABELS["pilco_baseline"],
        "falls or diverges (leaves the range)",
        "episode ended early",
    }
    pendulum = figure.axes[0]
    low, high = pendulum.get_ylim()
    assert low < -1.3 and high > 0 and high - low < 3  # the references set the range
    falling = [
        line
        for line in pendulum.lines
        if line.get_color() == "#1f77b4" and np.isfinite(line.get_ydata()).sum() > 1
    ]
    (trace,) = falling  # one line for three falling seeds
    drawn = np.flatnonzero(np.isfinite(trace.get_ydata()))
    assert drawn[-1] < 20  # a short trace, not lines across the panel
    assert trace.get_ydata()[drawn[-1]] == pytest.approx(low)  # it ends at the edge
    step_panel = figure.axes[5]  # mountaincar step: the LQR's -0.114 m is inside the range
    assert step_panel.get_ylim()[0] < -0.13
    plt.close(figure)


def test_a_falling_trace_stops_at_the_edge_and_a_settling_one_comes_back():
    values = np.concatenate([np.linspace(0, 5, 10), np.full(30, 0.5)])
    visible = visible_part(values, (-1.0, 2.0), tail=20)
    assert visible.exit == (4, 2.0)
    assert np.isnan(visible.values[5:10]).all() and visible.values[4] == 2.0
    np.testing.assert_array_equal(visible.values[10:], 0.5)  # back in range for good
    gone = visible_part(np.linspace(0, -50, 40), (-1.0, 2.0), tail=20)
    assert gone.exit == (1, -1.0) and np.isfinite(gone.values).sum() == 2


def test_wrapped_angles_are_broken_at_the_wrap():
    values = np.array([170.0, 178.0, -179.0, -170.0])
    broken = break_at_wraps(values, wrapped=True)
    assert np.isnan(broken[2]) and broken.size == 5
    np.testing.assert_array_equal(break_at_wraps(values, wrapped=False), values)


def _robustness_rows() -> list[dict]:
    rows = []
    for system in ("pendulum", "cartpole"):
        for controller in ("linear", "ddpg_hybrid", "pilco_baseline"):
            for parameter in ("mass", "gravity"):
                for scale in (0.5, 1.0, 2.0, 5.0):
                    fraction = 1.0 if scale < 2 or controller == "pilco_baseline" else 0.0
                    rows.append(
                        {
                            "system": system,
                            "controller": controller,
                            "parameter": parameter,
                            "scale": scale,
                            "fraction_stabilised": fraction,
                            "return_mean": -100.0 * scale,
                            "n_episodes": 30,
                        }
                    )
    return rows


def _roa_rows() -> list[dict]:
    return [
        {
            "system": system,
            "controller": controller,
            "basin_box_fraction": box,
            "certified_set_held": held,
            "certified_box_fraction": 0.6,
        }
        for system in ("pendulum", "mountaincar")
        for controller, box, held in (
            ("linear", 0.7, 1.0),
            ("ddpg_baseline", 0.0, 0.0),
            ("pilco_hybrid", 0.8, None),
        )
    ]


def _curves() -> dict:
    seconds = np.linspace(0, 100, 30).tolist()
    rising = (-1000 + 8 * np.array(seconds)).tolist()
    three = {"seconds": seconds, "mean": rising, "std": [50.0] * 30, "n_seeds": 3}
    three.update(iqm=rising, ci_low=[r - 80 for r in rising], ci_high=[r + 80 for r in rising])
    one = {"seconds": seconds, "mean": rising, "std": [0.0] * 30, "n_seeds": 1}
    return {
        "pendulum": {"ddpg_baseline": three, "ddpg_hybrid": three, "pilco_hybrid": one},
        "cartpole": {"ddpg_baseline": three, "pilco_baseline": one},
    }


def _relevance():
    time = np.arange(STEPS) * 0.05
    spin = _falling(8.0)
    traces = {
        ("pendulum", "ddpg_hybrid"): {
            "time": time,
            "main": spin,
            "relevance": np.clip(time / 10, 0, 1),
        },
        ("cartpole", "ddpg_hybrid"): {
            "time": time[:16] * 0.4,
            "main": np.linspace(170, 40, 16),
            "relevance": np.zeros(16),
        },
    }
    systems = {name: make_system(name) for name in ("pendulum", "cartpole")}
    seconds = {name: s.episode_steps * s.dt for name, s in systems.items()}
    return traces, systems, ["ddpg_hybrid", "pilco_hybrid"], seconds


def _roa_slices():
    from leoc.control import certify_lqr, design_lqr
    from leoc.evaluation.basins import empirical_basin, slice_grid
    from leoc.evaluation.plots.basins import draw_basin_slices

    system = make_system("mountaincar")
    design = design_lqr(system)
    certificate = certify_lqr(system, design, samples=2000, seed=0)
    box = np.maximum(np.array([0.5, 0.5]), 1.25 * certificate.extent)
    grid = slice_grid(system, (0, 1), box, 7)
    from leoc.control import lqr_closed_loop

    basin = empirical_basin(system, lqr_closed_loop(design), grid, box=box)
    return draw_basin_slices(system, certificate, {"LQR": basin}, (0, 1), 7, box=box / 2)


FIGURES = {
    "robustness": lambda: draw_robustness(
        _robustness_rows(), CONTROLLERS, ("mass", "gravity"), CONTROLLER_LABELS
    ),
    "basins": lambda: draw_basins(_roa_rows(), CONTROLLER_LABELS),
    "learning_curves": lambda: draw_learning_curves(_curves(), CONTROLLER_LABELS),
    "relevance": lambda: draw_relevance(*_relevance(), CONTROLLER_LABELS),
    "roa_slices": _roa_slices,
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(FIGURES))
def test_every_figure_reads_cleanly(name):
    figure = FIGURES[name]()
    assert layout_problems(figure) == []
    categorical = name == "basins"  # one bar group per controller, named on the ticks
    seen = set()
    for axis in figure.axes:
        if axis.axison:
            twin = axis.get_position().bounds in seen  # a right-hand axis over a panel
            seen.add(axis.get_position().bounds)
            assert axis.get_ylabel(), (name, axis.get_title())
            assert categorical or twin or axis.get_xlabel(), (name, axis.get_title())
    pyplot().close(figure)


def test_zero_bars_are_labelled_and_no_value_says_so():
    figure = draw_basins(_roa_rows(), CONTROLLER_LABELS)
    texts = [t.get_text() for t in figure.axes[0].texts]
    assert texts == ["70", "0", "80", "100", "0", "n/a"]
    pyplot().close(figure)


def test_the_checks_catch_data_beyond_the_axes_and_a_legend_over_a_panel():
    plt = pyplot()
    figure, axis = plt.subplots()
    axis.plot([0, 1, 2], [0, 5, 1], label="runs away")
    axis.set_ylim(0, 2)
    axis.set_xlabel("time [s]")
    axis.legend(loc="center")
    problems = layout_problems(figure)
    assert any("leaves" in p for p in problems)
    plt.close(figure)
    figure, axes = plt.subplots(1, 2)
    axes[0].plot([0, 1], [0, 1], label="a")
    figure.legend(loc="center")  # over both panels
    assert any("legend over" in p for p in layout_problems(figure))
    plt.close(figure)


# ------------------------------------------------------------ decisions, against known answers
PENDULUM_HOLD = 5.0  # deg, the pendulum's hold band
MOUNTAINCAR_HOLD = 0.05  # m
READABLE_POINTS = 8.0
"""Smallest font a bar label may have: 13 px at the saved 120 dpi."""


def _step_to(final: float, steps: int = 120, rise: int = 10) -> np.ndarray:
    """0, a linear rise to ``final`` over ``rise`` steps, then ``final`` held: its extremes are
    exactly 0 and ``final``."""
    return np.concatenate([np.linspace(0.0, final, rise), np.full(steps - rise, final)])


def _dip(depth: float, steps: int = 120) -> np.ndarray:
    """0, down to ``-depth`` and back to 0, then 0 held: extremes exactly ``-depth`` and 0."""
    return np.concatenate(
        [np.linspace(0.0, -depth, 6), np.linspace(-depth, 0.0, 6)[1:], np.zeros(steps - 11)]
    )


@pytest.mark.parametrize(
    ("record", "falls"),
    [
        (Response(_step_to(3.35)), False),  # settles off zero: not a fall
        (Response(_step_to(180.0)), False),  # settles, wherever (the record says so)
        (Response(_step_to(1.0), terminated=True), True),  # the episode ended early
        (Response(_step_to(4.9), settled=False), False),  # still moving, within the band
        (Response(_step_to(5.1), settled=False), True),  # still moving, beyond the band
        # a wrapped record that turns once and ends at +2 deg: unwrapped it ends at 362 deg
        (Response(_wrap_degrees(_step_to(362.0)), settled=False), True),
    ],
    ids=["settles_off_zero", "settles_far", "terminated", "moving_in", "moving_out", "turned"],
)
def test_a_run_falls_or_diverges_from_its_record_alone(record, falls):
    assert falls_or_diverges(record, PENDULUM_HOLD, unwrap=True) is falls


def test_a_run_that_settles_off_zero_is_inside_the_range_and_not_marked():
    """The issue's pendulum: a DDPG baseline settling at +3.35 deg among traces near 0."""
    by_key = {
        "linear": [Response(_dip(1.0))],
        "ddpg_hybrid": [Response(_dip(0.8)), Response(_dip(0.9))],
        "ddpg_baseline": [Response(_step_to(3.35))],
    }
    limits, traces = panel_layout(by_key, unwrap=True, hold_band=PENDULUM_HOLD)
    span = 3.35 + 1.0
    assert limits == pytest.approx((-1.0 - 0.15 * span, 3.35 + 0.15 * span))
    assert {key: exit_mark(trace, limits) for key, trace in traces.items()} == dict.fromkeys(by_key)
    figure = draw_responses({"pendulum": {"step": by_key}}, CONTROLLER_LABELS)
    labels = {text.get_text() for text in figure.legends[0].get_texts()}
    assert not any("falls" in label or "range" in label for label in labels)
    assert "triangle" not in figure.legends[0].get_title().get_text()
    assert layout_problems(figure) == []
    pyplot().close(figure)


@pytest.mark.parametrize(
    ("settled", "terminated", "falls"),
    [(True, False, False), (False, False, True), (False, True, True)],
    ids=["settles_there", "diverges", "terminated"],
)
def test_a_run_far_off_is_left_out_of_the_range_and_marked(settled, terminated, falls):
    """The issue's mountain car: one run ends at -4.15 m among runs within 0.1 m. The range is
    the others' (whether the far run settled there or not); the far run is marked at the
    edge with its extreme, and as a fall only when its record says it falls."""
    by_key = {
        "linear": [Response(_step_to(-0.1))],
        "pilco_baseline": [Response(_step_to(-0.06)) for _ in range(3)],
        "pilco_hybrid": [
            Response(_step_to(-0.08)),
            Response(_step_to(-4.15), terminated=terminated, settled=settled),
        ],
        "ddpg_hybrid": [Response(_step_to(-4.15), terminated=terminated, settled=settled)],
    }
    limits, traces = panel_layout(by_key, unwrap=False, hold_band=MOUNTAINCAR_HOLD)
    assert limits == pytest.approx((-0.1 - 0.15 * 0.1, 0.15 * 0.1))
    marks = {key: exit_mark(trace, limits) for key, trace in traces.items()}
    assert [key for key, mark in marks.items() if mark is not None] == ["ddpg_hybrid"]
    mark = marks["ddpg_hybrid"]
    assert (mark.edge, mark.extreme, mark.falls) == (limits[0], -4.15, falls)
    assert exit_text(mark, "m", angle=False) == "min -4.15 m"
    figure = draw_responses({"mountaincar": {"step": by_key}}, CONTROLLER_LABELS)
    texts = [text.get_text() for text in figure.axes[0].texts]
    assert texts == ["min -4.15 m"]
    assert layout_problems(figure) == []
    pyplot().close(figure)


def test_an_angle_past_half_a_turn_is_written_as_such():
    by_key = {"linear": [Response(_dip(1.0))], "pilco_baseline": [Response(_step_to(-900.0))]}
    limits, traces = panel_layout(by_key, unwrap=True, hold_band=PENDULUM_HOLD)
    mark = exit_mark(traces["pilco_baseline"], limits)
    assert exit_text(mark, "deg", angle=True) == "min < -180 deg"


def _curve(seeds: int) -> dict:
    seconds = np.linspace(0, 100, 30).tolist()
    rising = (-1000 + 8 * np.array(seconds)).tolist()
    curve = {"seconds": seconds, "mean": rising, "std": [0.0 if seeds == 1 else 50.0] * 30}
    curve["n_seeds"] = seeds
    if seeds >= 3:
        curve.update(iqm=rising, ci_low=[r - 80 for r in rising], ci_high=[r + 80 for r in rising])
    return curve


@pytest.mark.parametrize("seeds", [1, 2, 5])
def test_learning_curves_describe_the_bands_they_draw(seeds):
    curves = {"pendulum": {"ddpg_baseline": _curve(seeds), "ddpg_hybrid": _curve(seeds)}}
    figure = draw_learning_curves(curves, CONTROLLER_LABELS)
    caption = figure.legends[0].get_title().get_text().replace("\n", " ")
    bands = sum(len(axis.collections) for axis in figure.axes)
    assert bands == (0 if seeds == 1 else 2)
    assert ("shaded" in caption) is (seeds > 1)
    if seeds == 1:
        assert "one seed (no band)" in caption
    else:
        assert f"over the {seeds} seeds" in caption
    pyplot().close(figure)


def test_the_learning_caption_names_each_kind_with_its_seeds():
    assert "shaded" not in learning_caption({"single": {1}})
    mixed = learning_caption({"iqm": {5}, "single": {1}})
    assert "interquartile mean over the 5 seeds; shaded" in mixed
    assert "A controller with one seed: its run's evaluation return, no band." in mixed


def _many_roa_rows() -> list[dict]:
    """Eleven controllers, as the paper's figure: 3-digit labels side by side, and bars of 93%
    under a certified tick at 100% (the mountain car's, where a label on its bar is crossed)."""
    return [
        {
            "system": system,
            "controller": controller,
            "basin_box_fraction": 0.93,
            "certified_set_held": 1.0,
            "certified_box_fraction": 1.0,
        }
        for system in ("pendulum", "cartpole", "mountaincar")
        for controller in CONTROLLERS
    ]


def test_bar_labels_are_readable_and_apart():
    """Every bar label is at least READABLE_POINTS, inside its panel, clear of the other
    labels and of the certified ticks, at the saved size."""
    figure = draw_basins(_many_roa_rows(), CONTROLLER_LABELS)
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    for axis in figure.axes:
        labels = axis.texts
        assert len(labels) == 2 * len(CONTROLLERS)
        assert min(text.get_fontsize() for text in labels) >= READABLE_POINTS
        ticks = [t.get_fontsize() for t in axis.get_xticklabels()]
        assert min(ticks) >= READABLE_POINTS
        boxes = [text.get_window_extent(renderer) for text in labels]
        panel = axis.get_window_extent(renderer)
        assert all(panel.contains(b.x0, b.y0) and panel.contains(b.x1, b.y1) for b in boxes)
        for index, box in enumerate(boxes):
            assert not any(box.overlaps(other) for other in boxes[index + 1 :]), index
        (certified,) = axis.collections  # the ticks at the certified share, here 100%
        half_width = certified.get_linewidth()[0] * figure.dpi / 72 / 2
        tick_top = axis.transData.transform((0, 100.0))[1] + half_width
        assert all(box.y0 >= tick_top for box in boxes)
    pyplot().close(figure)
