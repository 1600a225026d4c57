"""The report of ``leoc reproduce``, built only from the saved numbers (``leoc plot`` reruns it).

Outputs in the reproduce folder: ``results.json`` (every aggregated number), ``responses.csv``,
``robustness.csv``, ``learning_curves.csv``, ``learning_curves.png`` (paper figure 6),
``responses.png`` (figure 7), ``robustness.png`` (figure 8), ``relevance.png`` (figure 4) and
``report.md``.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.metrics import ResponseMetrics, summarise_metrics
from leoc.evaluation.plots import (
    _pyplot,
    controller_colour,
    plot_responses,
    save_figure,
)
from leoc.evaluation.robustness import SCALED_PARAMETERS
from leoc.evaluation.rollout import RESPONSE_TESTS
from leoc.experiments.paper import PAPER_IMPULSE_METRICS
from leoc.experiments.profiles import CONTROLLERS
from leoc.experiments.reproduce import EVALUATION_FILE, META_FILE
from leoc.io import write_csv_atomic, write_json_atomic, write_text_atomic
from leoc.systems import SYSTEM_NAMES, make_system

CURVE_GRID_POINTS = 50
FMT = "{:.3g}"

Evaluations = dict[str, dict[str, list[dict[str, Any]]]]  # system -> controller -> seeds


def load_evaluations(out_dir: Path) -> Evaluations:
    """Every finished run under ``out_dir/runs``, grouped by system and controller."""
    grouped: Evaluations = defaultdict(lambda: defaultdict(list))
    for path in sorted((out_dir / "runs").glob(f"*/*/seed*/{EVALUATION_FILE}")):
        data = json.loads(path.read_text())
        grouped[data["spec"]["system"]][data["spec"]["controller"]].append(data)
    return {system: dict(grouped[system]) for system in SYSTEM_NAMES if system in grouped}


def _ordered(controllers: dict[str, Any]) -> list[str]:
    return [name for name in CONTROLLERS if name in controllers]


def _metrics(entry: dict[str, Any]) -> ResponseMetrics:
    return ResponseMetrics(**entry["metrics"])


def response_summary(evaluations: Evaluations) -> list[dict[str, Any]]:
    """Rows: system, test, controller, mean/std of the metrics over seeds, settled count."""
    rows = []
    for system, by_controller in evaluations.items():
        for test in RESPONSE_TESTS:
            for controller in _ordered(by_controller):
                runs = by_controller[controller]
                summary = summarise_metrics([_metrics(run["responses"][test]) for run in runs])
                rows.append(
                    {"system": system, "test": test, "controller": controller, **summary._asdict()}
                )
    return rows


def robustness_summary(evaluations: Evaluations) -> list[dict[str, Any]]:
    """Rows: system, controller, parameter, scale, return mean/std, fraction held."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in _ordered(by_controller):
            points: dict[tuple[str, float], list[dict[str, Any]]] = defaultdict(list)
            for run in by_controller[controller]:
                for point in run["robustness"]:
                    points[(point["parameter"], point["scale"])].append(point)
            for (parameter, scale), group in sorted(points.items()):
                returns = np.array([p["total_reward"] for p in group])
                rows.append(
                    {
                        "system": system,
                        "controller": controller,
                        "parameter": parameter,
                        "scale": scale,
                        "return_mean": float(returns.mean()),
                        "return_std": float(returns.std()),
                        "fraction_held": float(np.mean([p["held"] for p in group])),
                        "n_runs": len(group),
                    }
                )
    return rows


def curve_summary(runs: list[dict[str, Any]]) -> dict[str, list[float]] | None:
    """Mean and std over seeds of the return against interaction seconds, on a common grid
    (each seed's curve linearly interpolated; the grid spans the seconds all seeds reached)."""
    curves = [run["curve"] for run in runs if run.get("curve") and run["curve"]["seconds"]]
    if not curves:
        return None
    end = min(curve["seconds"][-1] for curve in curves)
    start = max(curve["seconds"][0] for curve in curves)
    grid = np.linspace(start, end, CURVE_GRID_POINTS) if end > start else np.array([end])
    values = np.array([np.interp(grid, c["seconds"], c["returns"]) for c in curves])
    return {
        "seconds": grid.tolist(),
        "mean": values.mean(0).tolist(),
        "std": values.std(0).tolist(),
        "n_seeds": len(curves),
    }


# ------------------------------------------------------------------------------------ figures
def plot_learning_curves(curves: dict[str, dict[str, Any]], path: Path) -> Path:
    """Figure 6: return vs interaction time, baseline vs hybrid, rows = framework."""
    plt = _pyplot()
    systems = list(curves)
    frameworks = ("ddpg", "pilco")
    figure, axes = plt.subplots(
        2, max(1, len(systems)), figsize=(4.2 * max(1, len(systems)), 6), squeeze=False
    )
    for column, system in enumerate(systems):
        for row, framework in enumerate(frameworks):
            axis = axes[row][column]
            for kind in ("baseline", "hybrid"):
                label = f"{framework}_{kind}"
                curve = curves[system].get(label)
                if curve is None:
                    continue
                seconds, mean, std = (np.array(curve[k]) for k in ("seconds", "mean", "std"))
                colour = controller_colour(label)
                axis.plot(
                    seconds,
                    mean,
                    color=colour,
                    marker="." if len(seconds) < 20 else None,
                    label=f"{label} (n={curve['n_seeds']})",
                )
                axis.fill_between(seconds, mean - std, mean + std, color=colour, alpha=0.2)
            axis.set_title(f"{system}: {framework.upper()}")
            axis.set_xlabel("interaction time [s]")
            axis.set_ylabel("episode return")
            axis.legend(fontsize="small")
    figure.tight_layout()
    return save_figure(figure, path)


def plot_robustness(rows: list[dict[str, Any]], path: Path) -> Path:
    """Figure 8: return (mean +/- std) against the parameter scale, rows = parameter."""
    plt = _pyplot()
    systems = list(dict.fromkeys(row["system"] for row in rows))
    figure, axes = plt.subplots(
        len(SCALED_PARAMETERS),
        max(1, len(systems)),
        figsize=(4.2 * max(1, len(systems)), 6),
        squeeze=False,
    )
    for column, system in enumerate(systems):
        for row_index, parameter in enumerate(SCALED_PARAMETERS):
            axis = axes[row_index][column]
            for controller in CONTROLLERS:
                selected = [
                    r
                    for r in rows
                    if r["system"] == system
                    and r["parameter"] == parameter
                    and r["controller"] == controller
                ]
                if not selected:
                    continue
                scale = np.array([r["scale"] for r in selected])
                mean = np.array([r["return_mean"] for r in selected])
                std = np.array([r["return_std"] for r in selected])
                colour = controller_colour(controller)
                axis.plot(scale, mean, color=colour, marker="o", markersize=3, label=controller)
                axis.fill_between(scale, mean - std, mean + std, color=colour, alpha=0.15)
            axis.set_title(f"{system}: {parameter} scaled")
            axis.set_xlabel(f"{parameter} / nominal")
            axis.set_ylabel("episode return")
            axis.legend(fontsize="x-small")
    figure.tight_layout()
    return save_figure(figure, path)


def plot_relevance(evaluations: Evaluations, path: Path) -> Path | None:
    """Figure 4: main coordinate and r(x) along a swing-up with each hybrid (first seed)."""
    panels = [
        (system, controller, runs[0]["relevance"])
        for system, by_controller in evaluations.items()
        for controller, runs in by_controller.items()
        if runs and runs[0].get("relevance")
    ]
    if not panels:
        return None
    plt = _pyplot()
    figure, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.2), squeeze=False)
    for axis, (system, controller, trace) in zip(axes[0], panels, strict=True):
        label = make_system(system).main_label
        axis.plot(trace["time"], trace["main"], color="#1f77b4", label=label)
        axis.set_xlabel("time [s]")
        axis.set_ylabel(label, color="#1f77b4")
        twin = axis.twinx()
        twin.plot(trace["time"], trace["relevance"], color="#ff7f0e", label="r(x)")
        twin.set_ylim(-0.05, 1.05)
        twin.set_ylabel("relevance r(x)", color="#ff7f0e")
        axis.set_title(f"{system}: {controller}")
    figure.tight_layout()
    return save_figure(figure, path)


# ------------------------------------------------------------------------------------ markdown
def _pm(mean: float, std: float) -> str:
    if math.isnan(mean):
        return "-"
    return f"{FMT.format(mean)} ± {FMT.format(std)}"


def _paper_cells(system: str, controller: str) -> str:
    paper = PAPER_IMPULSE_METRICS.get(system, {}).get(controller)
    if paper is None:
        return "| | |"
    overshoot = _pm(*paper.overshoot) if paper.overshoot else "-"
    return f"| {_pm(*paper.steady_state_error)} | {overshoot} | {_pm(*paper.settling_time)} |"


def response_table(rows: list[dict[str, Any]], test: str) -> list[str]:
    lines = [
        "| system | controller | steady-state error | overshoot | settling time [steps] "
        "| settled | paper: steady-state error | paper: overshoot | paper: settling time |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        if row["test"] != test:
            continue
        paper = _paper_cells(row["system"], row["controller"]) if test == "impulse" else "| | |"
        lines.append(
            f"| {row['system']} | {row['controller']} "
            f"| {_pm(row['steady_state_error_mean'], row['steady_state_error_std'])} "
            f"| {_pm(row['overshoot_mean'], row['overshoot_std'])} "
            f"| {_pm(row['settling_time_mean'], row['settling_time_std'])} "
            f"| {row['n_settled']}/{row['n_runs']} {paper}"
        )
    return lines


def robustness_table(rows: list[dict[str, Any]]) -> list[str]:
    """Fraction of runs that stay at the operating point, over all scales, per parameter."""
    lines = [
        "| system | controller | "
        + " | ".join(f"{p}: held / mean return" for p in SCALED_PARAMETERS)
        + " |",
        "|---|---|" + "---|" * len(SCALED_PARAMETERS),
    ]
    keys = list(dict.fromkeys((r["system"], r["controller"]) for r in rows))
    for system, controller in keys:
        cells = []
        for parameter in SCALED_PARAMETERS:
            selected = [
                r
                for r in rows
                if (r["system"], r["controller"], r["parameter"]) == (system, controller, parameter)
            ]
            held = np.mean([r["fraction_held"] for r in selected])
            mean_return = np.mean([r["return_mean"] for r in selected])
            cells.append(f"{held:.0%} / {mean_return:.3g}")
        lines.append(f"| {system} | {controller} | " + " | ".join(cells) + " |")
    return lines


def swing_up_table(evaluations: Evaluations) -> list[str]:
    lines = [
        "| system | controller | swing-up return | runs holding the operating point "
        "| mean hold step |",
        "|---|---|---|---|---|",
    ]
    for system, by_controller in evaluations.items():
        for controller in _ordered(by_controller):
            runs = by_controller[controller]
            returns = np.array([run["swing_up"]["total_reward"] for run in runs])
            holds = [run["swing_up"]["hold_step"] for run in runs]
            held = [h for h in holds if h is not None]
            lines.append(
                f"| {system} | {controller} | {_pm(returns.mean(), returns.std())} "
                f"| {len(held)}/{len(runs)} | {FMT.format(np.mean(held)) if held else '-'} |"
            )
    return lines


def write_report(out_dir: str | Path) -> Path:
    """Aggregate the finished runs of ``out_dir`` into numbers, figures and ``report.md``."""
    out = Path(out_dir)
    meta_path = out / META_FILE
    if not meta_path.is_file():
        raise FileNotFoundError(
            f"run_dir: no {META_FILE} in {str(out)!r}; is it a reproduce folder?"
        )
    meta = json.loads(meta_path.read_text())
    evaluations = load_evaluations(out)
    responses = response_summary(evaluations)
    robustness = robustness_summary(evaluations)
    curves = {
        system: {c: curve_summary(runs) for c, runs in by_c.items() if curve_summary(runs)}
        for system, by_c in evaluations.items()
    }
    train_seconds = sum(
        run["wall_seconds"]
        for by_c in evaluations.values()
        for runs in by_c.values()
        for run in runs
    )
    write_json_atomic(
        out / "results.json",
        {
            "meta": meta,
            "responses": responses,
            "robustness": robustness,
            "learning_curves": curves,
            "summed_run_wall_seconds": train_seconds,
        },
    )
    write_csv_atomic(out / "responses.csv", responses)
    write_csv_atomic(out / "robustness.csv", robustness)
    curve_rows = [
        {"system": s, "controller": c, "seconds": t, "mean": m, "std": d}
        for s, by_c in curves.items()
        for c, curve in by_c.items()
        for t, m, d in zip(curve["seconds"], curve["mean"], curve["std"], strict=True)
    ]
    write_csv_atomic(out / "learning_curves.csv", curve_rows)
    figures = []
    if evaluations:
        plot_responses(
            {
                system: {
                    test: {
                        c: [run["responses"][test]["deviation"] for run in runs]
                        for c, runs in by_c.items()
                    }
                    for test in RESPONSE_TESTS
                }
                for system, by_c in evaluations.items()
            },
            out / "responses.png",
        )
        figures.append(("Impulse and step responses (paper figure 7)", "responses.png"))
    if any(curves.values()):
        plot_learning_curves(curves, out / "learning_curves.png")
        figures.append(("Learning curves (paper figure 6)", "learning_curves.png"))
    if robustness:
        plot_robustness(robustness, out / "robustness.png")
        figures.append(("Robustness (paper figure 8)", "robustness.png"))
    if plot_relevance(evaluations, out / "relevance.png"):
        figures.append(("Relevance along a swing-up (paper figure 4)", "relevance.png"))
    path = out / "report.md"
    write_text_atomic(
        path, render_markdown(meta, evaluations, responses, robustness, figures, train_seconds)
    )
    return path


def render_markdown(
    meta: dict[str, Any],
    evaluations: Evaluations,
    responses: list[dict[str, Any]],
    robustness: list[dict[str, Any]],
    figures: list[tuple[str, str]],
    train_seconds: float,
) -> str:
    wall = meta.get("wall_seconds_last_invocation")
    lines = [
        "# LEOC: reproduction of Zhang & Capel (L4DC 2021)",
        "",
        f"**Profile: {meta.get('profile')}** ({meta.get('description', '')}).",
        "",
        f"Seeds: {meta.get('seeds')}. Settings: `{json.dumps(meta.get('settings'))}`.",
        "",
        f"Wall time of the last invocation: {wall:.0f} s; summed wall time of all runs: "
        f"{train_seconds:.0f} s (runs execute in parallel on {meta.get('jobs')} workers)."
        if wall is not None
        else "Wall time: not finished.",
        "",
        "Versions: " + ", ".join(f"{k} {v}" for k, v in meta.get("versions", {}).items()),
        "",
    ]
    missing = [
        f"{s}/{c}"
        for s in meta.get("systems", [])
        for c in meta.get("controllers", [])
        if c not in evaluations.get(s, {})
    ]
    if missing:
        lines += [f"Runs without results (failed or not run yet): {', '.join(missing)}.", ""]
    lines += [
        "## Metric definitions",
        "",
        "Every test starts exactly at the operating point; *impulse* adds -1.0 to the first "
        "action, *step* adds -0.2 to every action, for 200 steps. e(t) is the deviation of the "
        "main coordinate (degrees for pendulum and cart-pole, metres for mountain car).",
        "- steady-state error: mean of e over the last 20 samples;",
        "- overshoot: largest excursion past that final value on the side opposite to the "
        "initial deviation (the side of the first sample deviating by more than 1% of the "
        "peak deviation);",
        "- settling time: first step after which |e - e_final| stays within the band (1 degree; "
        "0.001 m for mountain car) to the end; 0 if it never leaves the band; runs that do not "
        "settle (a sample of the last 20 outside the band) count in 'settled' and get no number.",
        "Mean ± std (population) over seeds; settling time over the settled runs only.",
        "",
        "The paper's numbers (appendix D, typed in) do not state their band or their "
        "overshoot reference; its 'Linear' overshoots (0.45 deg pendulum, 0.67 deg cart-pole) "
        "equal the deviation one step after the impulse in our simulators, so its overshoot "
        "appears to measure the first swing, not the swing past the final value, and its "
        "mountain-car settling times (~201 steps) exceed the 200-step episode.",
        "",
        "## Impulse response",
        "",
    ]
    lines += response_table(responses, "impulse")
    lines += ["", "## Step response", ""] + response_table(responses, "step")
    bands = ", ".join(f"{s} {make_system(s).hold_band}" for s in SYSTEM_NAMES)
    lines += [
        "",
        "## Robustness",
        "",
        "Each controller, trained on the nominal system, starts exactly at the operating point "
        "on systems whose mass (all masses) or g is scaled by 0.5x ... 5.0x; one 200-step "
        "episode per scale and seed. "
        f"'held': the main coordinate ends within the hold band ({bands}; degrees or m) and "
        "the episode did not terminate. Cells: fraction held over all scales / mean return.",
        "",
    ]
    lines += robustness_table(robustness)
    lines += [
        "",
        "## Swing-up",
        "",
        "One 200-step episode from the seeded swing-up start per controller and seed.",
        "",
    ]
    lines += swing_up_table(evaluations)
    for title, filename in figures:
        lines += ["", f"## {title}", "", f"![{title}]({filename})"]
    lines += [
        "",
        "All numbers: results.json, responses.csv, robustness.csv, "
        "learning_curves.csv. Regenerate figures and this report: `leoc plot <folder>`.",
        "",
    ]
    return "\n".join(lines)
