"""Every figure drawn from synthetic runs, falling-over runs included, passes the layout checks:
no data beyond its axes, no legend over a panel or a label, no panel reaching into another;
and the checks themselves catch a figure that breaks them."""

from __future__ import annotations

import numpy as np
import pytest

from leoc.evaluation.plots.basins import draw_basins
from leoc.evaluation.plots.common import layout_problems, pyplot
from leoc.evaluation.plots.learning import draw_learning_curves
from leoc.evaluation.plots.relevance import break_at_wraps, draw_relevance
from leoc.evaluation.plots.responses import draw_responses, visible_part
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
        "left the plotted range",
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
    from leoc.control import certify_lqr, design_lqr, empirical_basin, slice_grid
    from leoc.control.roa import draw_basin_slices

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
