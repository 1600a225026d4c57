"""The report of ``leoc gym-study`` (:mod:`leoc.experiments.gym_study`), written from
``study.json`` alone: ``README.md`` (the tables, the command, the budget against the zoo's)
and one learning-curve figure per env. The same ``study.json`` gives the same bytes."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leoc.experiments.markdown import markdown_table
from leoc.io import save_figure_atomic, write_text_atomic

__all__ = [
    "AGREEMENT_WORDS",
    "ARM_LABELS",
    "CONTROLLER_LABELS",
    "README_FILE",
    "figure_name",
    "study_markdown",
    "write_study_report",
]

#: The report, in the study folder.
README_FILE = "README.md"
#: How the report names each controller of the study.
CONTROLLER_LABELS = {
    "lqr": "clipped LQR alone",
    "sac_baseline": "SAC alone",
    "sac_hybrid": "SAC hybrid, paper relevance (r_min none)",
    "sac_hybrid_roa": "SAC hybrid, ROA relevance (sampled region)",
}


def figure_name(env_id: str) -> str:
    """The learning-curve figure of ``env_id``, in the study folder."""
    return f"learning_curve_{env_id}.png"


def _mean_std(values: Sequence[float]) -> str:
    """``mean ± std`` (std over seeds, ddof 1; none for one seed)."""
    if len(values) < 2:
        return f"{np.mean(values):.2f}"
    return f"{np.mean(values):.2f} ± {np.std(values, ddof=1):.2f}"


def _steps(runs: Sequence[Mapping[str, Any]]) -> str:
    """Steps to 95 % per seed ("not reached"; "-" for the LQR, which has no curve)."""
    if all(run["curve"] is None for run in runs):
        return "-"
    return ", ".join(
        "not reached" if run["steps_to_95"] is None else str(run["steps_to_95"]) for run in runs
    )


def _distance(runs: Sequence[Mapping[str, Any]], controller: str) -> str:
    if controller == "lqr":
        return "0 (the reference)"
    values = [run["distance_pct"] for run in runs]
    finite = [v for v in values if v is not None]
    text = f"{np.mean(finite):.3g}" if finite else "-"
    missing = len(values) - len(finite)
    return text + (f" ({missing} terminated unlike the LQR)" if missing else "")


def _starts(entry: Mapping[str, Any]) -> str:
    """How many evaluation starts were kept and skipped at one noise."""
    kept, skipped = entry.get("evaluation_seeds", []), entry.get("skipped_seeds", [])
    tried = len(kept) + len(skipped)
    return (
        f"Evaluation starts: {len(kept)} recoverable of the first {tried} seeds "
        f"({len(skipped)} skipped: they end at the first step whatever the action)."
    )


def _table(entry: Mapping[str, Any]) -> list[str]:
    """The table of one env at one noise: a row per controller."""
    rows = []
    for controller, data in entry["controllers"].items():
        label = CONTROLLER_LABELS.get(controller, controller)
        runs = data["runs"]
        if not data["available"]:
            rows.append([label, data["reason"], "", "", "", ""])
            continue
        shares = [run["held_share"] for run in runs]
        per_seed = ", ".join(f"{share:.2f}" for share in shares)
        returns = _mean_std([run["mean_return"] for run in runs])
        rows.append(
            [label, _mean_std(shares), per_seed, _steps(runs), returns, _distance(runs, controller)]
        )
    headers = (
        "controller",
        "held share (mean ± std)",
        "held share per seed",
        "steps to 95 % of max return",
        "final return (mean ± std)",
        "impulse distance from LQR (%)",
    )
    return markdown_table(headers, rows)


def _header(study: Mapping[str, Any]) -> list[str]:
    """The report's opening: what was run, by which command, on which budget."""
    steps, zoo = study["total_steps"], study["zoo_steps"]
    seeds = study["seeds"]
    return [
        "# LEOC on gymnasium's pendulums: MuJoCo's inverted pendulums and Pendulum-v1",
        "",
        "Made by:",
        "",
        "```",
        study["command"] or "(no command recorded)",
        "```",
        "",
        f"Profile `{study['profile']}`: {len(seeds)} seed(s) ({', '.join(map(str, seeds))}), "
        f"{study['episodes']} evaluation episode(s) per run. SAC settings: "
        f"`{json.dumps(study['settings'], sort_keys=True)}`, from {study['zoo_source']}.",
        "",
        f"**Budget**: {steps} environment steps per SAC run, {steps / zoo:.3g} of the zoo's "
        f"{zoo} (`n_timesteps`): far smaller than the budget those settings were tuned for, so "
        "the learned controllers here are not the zoo's. The zoo publishes no SAC figure for "
        "either MuJoCo inverted pendulum (its `benchmark.md` has no such row), so none stands "
        "beside these tables.",
        "",
        "Held share: the share of the seeded evaluation episodes (from "
        "`reset(seed=b + 20000 + j)`, b the study's seed base, for the first values of j whose "
        "start is recoverable: the same starts for every controller and seed) held to the time "
        "limit without termination. Steps to 95 %: the first step of the learning curve whose "
        "mean evaluation return reaches 95 % of the maximum return (every step's reward at rest "
        "at the operating point), per seed. Final return: the evaluation episodes' mean return. "
        "Impulse distance: the largest difference of the impulse response's main coordinate from "
        "the LQR's, in percent of the LQR's peak, mean over seeds. A start is unrecoverable, "
        "and skipped, when the env terminates at its first step under each of the operating "
        "action and the two extreme actions (the pole starts past the termination angle): "
        "such an episode ends at step 1 whatever the controller does.",
        "",
    ]


#: How the report words a :func:`~leoc.experiments.stats.improvement_verdict` of the
#: ``gymnasium`` arm against the ``leoc`` arm.
AGREEMENT_WORDS = {
    "equal": "agree (equal scores)",
    "unresolved": "agree within seed noise",
    "above": "differ: gymnasium higher",
    "below": "differ: gymnasium lower",
}
#: How the report names the two paths of the ``Pendulum-v1`` part.
ARM_LABELS = {"leoc": "leoc's pendulum (train_ddpg)", "gymnasium": "Pendulum-v1 (train_gym)"}


def _agreement_cell(verdict: Mapping[str, Any]) -> str:
    """P(a gymnasium seed above a leoc seed) [95% interval]: the verdict in words."""
    word, _, small = verdict["verdict"].partition(" (")
    text = AGREEMENT_WORDS.get(word, word) + (f" ({small}" if small else "")
    if verdict["ci_low"] is None:
        return f"{verdict['probability']:.2f} (no interval): {text}"
    return (
        f"{verdict['probability']:.2f} [{verdict['ci_low']:.2f}, {verdict['ci_high']:.2f}]: {text}"
    )


def _pendulum_tables(entry: Mapping[str, Any]) -> list[str]:
    """The ``Pendulum-v1`` part's two tables: each path's scores, then their agreement."""
    rows, verdicts = [], []
    for controller, data in entry["controllers"].items():
        label = CONTROLLER_LABELS.get(controller, controller)
        for arm, runs in data["runs"].items():
            returns = [run["mean_return"] for run in runs]
            shares = [run["held_share"] for run in runs]
            rows.append(
                [
                    label,
                    ARM_LABELS.get(arm, arm),
                    _mean_std(returns),
                    ", ".join(f"{value:.1f}" for value in returns),
                    _mean_std(shares),
                    ", ".join(f"{value:.2f}" for value in shares),
                ]
            )
        agreement = data["agreement"]
        verdicts.append(
            [label, *(_agreement_cell(agreement[task]) for task in ("mean_return", "held_share"))]
        )
    headers = (
        "controller",
        "trained on",
        "return on Pendulum-v1 (mean ± std)",
        "per seed",
        "swing-up held share (mean ± std)",
        "per seed",
    )
    agreement_headers = (
        "controller",
        "return: P(gymnasium seed > leoc seed) [95% CI]",
        "swing-up held share: P(gymnasium seed > leoc seed) [95% CI]",
    )
    return [*markdown_table(headers, rows), "", *markdown_table(agreement_headers, verdicts)]


def _pendulum_section(entry: Mapping[str, Any]) -> list[str]:
    """The report's ``Pendulum-v1`` part (:mod:`leoc.experiments.gym_pendulum`)."""
    zoo = entry["zoo"]
    return [
        "## Pendulum-v1 through the adapter against leoc's own pendulum",
        "",
        "The same dynamics and reward, trained by two paths with the same learner and settings "
        f"(leoc's pendulum SAC, {entry['total_steps']} steps, final policy: "
        f"`{json.dumps(entry['settings'], sort_keys=True)}`): leoc's pendulum system "
        "(`train_ddpg`, its swing-up starts) and gymnasium's `Pendulum-v1` through the adapter "
        "(`train_gym`, the env's own starts anywhere on the circle; the LQR on central "
        "differences of the env's step). The hybrid is the paper's relevance without the floor. "
        f"Every final controller is evaluated on the same {len(entry['evaluation_seeds'])} "
        "episodes of each task: the return of `Pendulum-v1`'s own episodes "
        "(`reset(seed=b + 20000 + j)`), and the share of leoc's swing-up starts (drawn from "
        "the same seeds) swung up and held within 5 degrees for the last 50 steps.",
        "",
        *_pendulum_tables(entry),
        "",
        "Agreement: P(a seed trained on `Pendulum-v1` scores above a seed trained on leoc's "
        "pendulum) with its 95% stratified-bootstrap interval; an interval holding 0.5 is "
        "agreement within seed noise. The training starts differ between the paths (each env "
        "defines its own), so a difference is not the dynamics alone.",
        "",
        f"rl-baselines3-zoo's published SAC on `Pendulum-v1`: {zoo['mean_reward']:.1f} ± "
        f"{zoo['std_reward']:.1f} (one agent trained {zoo['n_timesteps']} steps with the zoo's "
        f"settings, {zoo['eval_episodes']} episodes; {zoo['source']}).",
        "",
    ]


def study_markdown(study: Mapping[str, Any]) -> str:
    """The README of ``study`` (the contents of ``study.json``)."""
    lines = _header(study)
    for env_id, noises in study["envs"].items():
        lines += [f"## {env_id}", "", f"![learning curves]({figure_name(env_id)})", ""]
        for noise, entry in noises.items():
            scale = entry["reset_noise_scale"]
            lines += [
                f"### start noise {noise} (reset_noise_scale {scale:g}; maximum return "
                f"{entry['maximum_return']:.6g})",
                "",
                _starts(entry),
                "",
                *_table(entry),
                "",
            ]
    pendulum = study.get("pendulum_v1")
    if pendulum is not None:
        lines += _pendulum_section(pendulum)
    seconds = sum(
        run["wall_seconds"]
        for noises in study["envs"].values()
        for entry in noises.values()
        for data in entry["controllers"].values()
        for run in data["runs"]
    )
    if pendulum is not None:
        seconds += sum(
            run["wall_seconds"]
            for data in pendulum["controllers"].values()
            for runs in data["runs"].values()
            for run in runs
        )
    lines += [
        f"Wall time of the runs (training and evaluation, this machine): {seconds:.0f} s.",
        "",
    ]
    return "\n".join(lines)


def _figure(env_id: str, noises: Mapping[str, Any]) -> Any:
    """One panel per noise: each trained controller's mean held share on the learning curve
    (mean over seeds) against steps, and the LQR's held share as a dashed line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(noises), figsize=(4.5 * len(noises), 3.5), squeeze=False)
    for axis, (noise, entry) in zip(axes[0], noises.items(), strict=True):
        for controller, data in entry["controllers"].items():
            runs = data["runs"]
            if not runs:
                continue
            label = CONTROLLER_LABELS.get(controller, controller)
            if runs[0]["curve"] is None:
                share = float(np.mean([run["held_share"] for run in runs]))
                axis.axhline(share, linestyle="--", color="black", label=f"{label} (final starts)")
                continue
            steps = [row["steps"] for row in runs[0]["curve"]]
            held = np.mean([[row["held_fraction"] for row in run["curve"]] for run in runs], 0)
            axis.plot(steps, held, marker=".", label=label)
        axis.set_title(f"{env_id}, noise {noise}")
        axis.set_xlabel("environment steps")
        axis.set_ylabel("held share (learning-curve episodes)")
        axis.set_ylim(-0.05, 1.05)
    axes[0][0].legend(fontsize="small")
    figure.tight_layout()
    return figure


def write_study_report(out: str | Path) -> Path:
    """Write ``README.md`` and the figures of the study folder ``out`` from its ``study.json``
    alone; returns the README's path."""
    folder = Path(out)
    study = json.loads((folder / "study.json").read_text())
    for env_id, noises in study["envs"].items():
        save_figure_atomic(_figure(env_id, noises), folder / figure_name(env_id))
    return write_text_atomic(folder / README_FILE, study_markdown(study))
