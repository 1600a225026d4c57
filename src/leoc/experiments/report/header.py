"""The report's opening: title, profile, seeds, wall time, versions, machine, code, model
selection and the runs aggregated."""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Sequence
from typing import Any

from leoc.experiments.layout import Evaluations
from leoc.experiments.profiles import LINEAR_CONTROLLERS
from leoc.experiments.report.base import Report, Section, missing_runs, relevances
from leoc.experiments.summary import wall_time_text
from leoc.names import controller_framework

SELECTION_RULES = {
    "final": "the final controller (at the end of its training budget)",
    "best_held": "the evaluation that held the operating point in the most episodes, the "
    "highest mean return among those",
    "best_last_third": "the evaluation of highest mean return in the last third of training",
}
"""What each recorded ``model_selection`` rule returns (:mod:`leoc.sb3.callbacks`); PILCO's
selecting rule records its own sentence."""
NOT_RECORDED = "not recorded"


def invocations_lines(invocations: Sequence[dict[str, Any]] | None) -> list[str]:
    """The report's line on a folder resumed over several invocations (``meta.json``'s
    ``invocations``), followed by a blank line; nothing for a folder of one invocation.

    An invocation that ended without a word (``ended`` ``"lost"``: killed, or its machine lost)
    counts its wall time up to its last finished run; the line says so."""
    if not invocations or len(invocations) < 2:
        return []
    parts = [
        f"{item.get('started_utc', '?')}: {item.get('wall_seconds', 0):.0f} s, "
        f"{item.get('runs_finished', '?')} runs finished"
        + _how_it_ended(item)
        + (f", commit {item['leoc_commit']}" if item.get("leoc_commit") else "")
        for item in invocations
    ]
    total = sum(item.get("wall_seconds", 0) for item in invocations)
    lost = any(item.get("ended") == "lost" for item in invocations)
    return [
        f"Resumed over {len(invocations)} invocations ({total:.0f} s of wall time in all"
        + ("; a lost invocation counts up to its last finished run" if lost else "")
        + "): "
        + "; ".join(parts)
        + ".",
        "",
    ]


def _how_it_ended(item: dict[str, Any]) -> str:
    ended = item.get("ended")
    if ended == "lost":
        return ", lost (ended without a word: killed, or its machine lost)"
    if ended == "running":
        return ", running"
    return ", interrupted" if item.get("interrupted") else ""


def machine_line(machine: dict[str, Any] | None) -> str:
    """The report's line on the machine of the last invocation (``meta.json``'s ``machine``)."""
    if not machine:
        return "Machine: not recorded (a run folder written before leoc recorded it)."
    memory = machine.get("memory_gib")
    return (
        f"Machine of the last invocation: {machine.get('cpu', 'unknown CPU')}, "
        f"{machine.get('logical_cpus', '?')} logical CPUs"
        + (f", {memory} GiB memory" if memory is not None else "")
        + f", {machine.get('platform', 'unknown platform')}"
        + (
            f", torch's {machine['torch_cpu_capability']} kernels"
            if machine.get("torch_cpu_capability")
            else ""
        )
        + "."
    )


def code_versions(evaluations: Evaluations) -> dict[str, list[str]]:
    """Run keys (``system/controller/seedN``) per leoc commit that produced them (``unknown``:
    a run written outside a git checkout or before runs recorded their versions)."""
    found: dict[str, list[str]] = defaultdict(list)
    for system, by_c in evaluations.items():
        for controller, runs in by_c.items():
            for run in runs:
                commit = (run.get("versions") or {}).get("leoc_commit", "unknown")
                found[commit].append(f"{system}/{controller}/seed{run['spec']['seed']}")
    return dict(sorted(found.items()))


def code_line(versions_found: dict[str, list[str]]) -> str:
    """One sentence on the code version(s) behind the runs; a mix is said plainly."""
    if not versions_found:
        return "Code: no runs."
    if len(versions_found) == 1:
        ((commit, runs),) = versions_found.items()
        return f"Code: all {len(runs)} runs from leoc commit `{commit}`."
    parts = "; ".join(f"`{c}`: {len(r)} runs" for c, r in versions_found.items())
    return (
        f"**Code: the runs come from {len(versions_found)} different leoc versions** ({parts}); "
        "their numbers are not from one version of the code."
    )


def recorded_selection(run: dict[str, Any]) -> str:
    """The model selection a run recorded (its curve's ``model_selection``; a PILCO selection's
    iteration dropped, so runs of one rule group together), or ``NOT_RECORDED``."""
    rule = str((run.get("curve") or {}).get("model_selection") or NOT_RECORDED)
    return rule.split(" (iteration ")[0]


def model_selection_text(evaluations: Evaluations) -> str:
    """The report's sentence on model selection, from what each learned run recorded: per
    learner and rule, the runs and what the rule returns; runs that select on their trainer's
    evaluation episodes are said to (their starts are the first of the swing-up table's)."""
    groups: dict[tuple[str, str], int] = defaultdict(int)
    for by_controller in evaluations.values():
        for controller, runs in by_controller.items():
            if controller in LINEAR_CONTROLLERS:
                continue
            for run in runs:
                groups[(controller_framework(controller).upper(), recorded_selection(run))] += 1
    if not groups:
        return "Model selection: none (linear controllers only: designed, not trained)."
    parts = [
        f"{learner} ({count} run{'s' if count > 1 else ''}): "
        + (f"`{rule}`, {SELECTION_RULES[rule]}" if rule in SELECTION_RULES else rule)
        for (learner, rule), count in sorted(groups.items())
    ]
    text = "Model selection, as each run recorded it: " + "; ".join(parts) + "."
    if any(rule not in ("final", NOT_RECORDED) for _, rule in groups):
        text += (
            " A rule other than `final` selects on the trainer's evaluation episodes, whose "
            "seeded starts are the first of the swing-up table's: that table is optimistic "
            "for those runs."
        )
    if any(rule == NOT_RECORDED for _, rule in groups):
        text += (
            " 'Not recorded': runs written before leoc kept each run's selection (in its "
            "curve's model_selection)."
        )
    return text


def _has(evaluations: Evaluations, learner: str) -> bool:
    """Whether the report has a controller of ``learner``."""
    return any(controller_framework(c) == learner for by_c in evaluations.values() for c in by_c)


def _period_comparisons(evaluations: Evaluations) -> str:
    """Which LQR each learner's hybrids are compared with, for the learners the report has
    (every learner's rule where it has none: an LQR-only report)."""
    dt = [name.upper() for name in ("ddpg", "td3", "sac") if _has(evaluations, name)]
    pilco = _has(evaluations, "pilco")
    if not dt and not pilco:
        dt, pilco = ["DDPG", "TD3", "SAC"], True
    clauses = []
    if dt:
        listed = dt[0] if len(dt) == 1 else f"{', '.join(dt[:-1])} and {dt[-1]}"
        clauses.append(f"{listed} hybrids with *linear (LQR at dt)*")
    if pilco:
        clauses.append("PILCO hybrids with *linear (LQR at PILCO's period)*")
    return ", ".join(clauses)


def _learner_notes(evaluations: Evaluations) -> str:
    """What a TD3 or SAC controller is, said only in a report that has one."""
    note = ""
    if _has(evaluations, "td3"):
        note += (
            " A TD3 controller is TD3's actor (twin critics, delayed actor updates, target "
            "smoothing), trained with DDPG's settings and budgets."
        )
    if _has(evaluations, "sac"):
        note += (
            " A SAC controller is SAC's deterministic action (its squashed mean), trained at the "
            "DDPG budgets."
        )
    return note


RELEVANCE_NOTES = {
    "roa": "the ROA relevance is exactly 1 on a flat top V <= rho_in inside its LQR's certified "
    "region",
    "lyapunov": "the Lyapunov relevance is r = (1 + V~/(lambda rho))^-2, V~ its LQR's Lyapunov "
    "function: like the paper's, r < 1 everywhere but at the operating point (no flat top)",
}
"""What each relevance design other than the paper's r = (1 + d)^-2 is, as the report says it."""


def relevance_note(evaluations: Evaluations) -> str:
    """What the relevance designs named in the study's hybrid labels are, said only in a report
    that has a Lyapunov-relevance hybrid (the reports of the paper's and the ROA hybrids, those
    published under results/ among them, read as before)."""
    found = relevances(evaluations)
    if "lyapunov" not in found:
        return ""
    notes = [RELEVANCE_NOTES[name] for name in RELEVANCE_NOTES if name in found]
    return (
        " A hybrid's label names its relevance where it is not the paper's r = (1 + d)^-2: "
        + "; ".join(notes)
        + "."
    )


def _runs_lines(meta: dict[str, Any], evaluations: Evaluations) -> list[str]:
    """The runs aggregated (seeds per system and controller) and those without results."""
    aggregated = "; ".join(
        f"{system}/{controller}: seeds {sorted(run['spec']['seed'] for run in runs)}"
        for system, by_controller in evaluations.items()
        for controller, runs in by_controller.items()
    )
    lines = [f"Runs aggregated in this report: {aggregated or 'none'}.", ""]
    missing = missing_runs(meta, evaluations)
    if missing:
        lines += [f"Runs without results (failed or not run yet): {', '.join(missing)}.", ""]
    return lines


def render(report: Report) -> list[str]:
    """The title and the study's provenance: profile, seeds, times, versions, code, runs."""
    meta, evaluations = report.study.meta, report.study.evaluations
    wall = wall_time_text(meta)
    return [
        "# LEOC: reproduction of Zhang & Capel (L4DC 2021)",
        "",
        f"**Profile: {meta.get('profile')}** ({meta.get('description', '')}).",
        "",
        f"Seeds: {meta.get('seeds')}. Settings: `{json.dumps(meta.get('settings'))}`.",
        "",
        f"Wall time: {wall}; summed wall time of all runs: {report.run_seconds:.0f} s (runs "
        f"execute in parallel on {meta.get('jobs')} workers)."
        if wall is not None
        else "Wall time: not finished.",
        "",
        *invocations_lines(meta.get("invocations")),
        "Versions: " + ", ".join(f"{k} {v}" for k, v in meta.get("versions", {}).items()),
        "",
        machine_line(meta.get("machine")),
        "",
        code_line(code_versions(evaluations)),
        "",
        f"{model_selection_text(evaluations)} Every controller is evaluated at the control "
        "period it was trained at (the 'period' column: simulator steps per decision; PILCO "
        "holds each action for that many steps), and each hybrid is compared with the LQR "
        f"designed for its own period: {_period_comparisons(evaluations)}."
        + _learner_notes(evaluations)
        + relevance_note(evaluations),
        "",
        *_runs_lines(meta, evaluations),
    ]


SECTION = Section(render)
