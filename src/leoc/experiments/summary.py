"""The few lines ``leoc reproduce`` prints at the end: what failed and where the report is.

The whole report is in ``report.md``; the terminal gets its headline: the runs aggregated and
those without results, the count of failed checks per report section with the controllers
named, and the paths to open.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from leoc.experiments.layout import META_FILE

RESULTS_FILE = "results.json"
REPORT_FILE = "report.md"
FLAG_SECTIONS = {
    "responses": "impulse/step responses",
    "robustness": "robustness",
    "swing_up": "swing-up",
    "roa": "region of attraction",
}
"""Report section of each group of checks (``results.json``'s ``flags``)."""
_FLAG_SUBJECT = re.compile(r"^\*\*(.+?)\*\*")


def flagged_subjects(flags: list[str]) -> list[str]:
    """The bold subjects (``system controller``) of the flags, each once, in order."""
    found = (_FLAG_SUBJECT.match(flag) for flag in flags)
    return list(dict.fromkeys(match.group(1) for match in found if match))


def summary_lines(out_dir: str | Path) -> list[str]:
    """The end-of-run summary of a reproduce folder whose report has been written."""
    out = Path(out_dir)
    results = json.loads((out / RESULTS_FILE).read_text())
    meta = json.loads((out / META_FILE).read_text())
    responses = results.get("responses", [])
    aggregated = {(row["system"], row["controller"]) for row in responses}
    missing = [
        f"{system}/{controller}"
        for system in meta.get("systems", [])
        for controller in meta.get("controllers", [])
        if (system, controller) not in aggregated
    ]
    wall = meta.get("wall_seconds_last_invocation")
    lines = [
        f"Finished: {len(aggregated)} system/controller pairs in the report"
        + (f", {wall:.0f} s wall time" if wall is not None else "")
        + "."
    ]
    if missing:
        lines.append(f"Without results (failed; see their train.log): {', '.join(missing)}.")
    flags = results.get("flags", {})
    failed = {key: flags.get(key, []) for key in FLAG_SECTIONS if flags.get(key)}
    if not failed:
        lines.append("Checks: all passed.")
    for key, section_flags in failed.items():
        subjects = flagged_subjects(section_flags)
        lines.append(
            f"Failed checks, {FLAG_SECTIONS[key]}: {len(section_flags)} ({', '.join(subjects)})."
        )
    lines += [
        f"Report: {out / REPORT_FILE} (figures and CSV files beside it).",
        f"Redraw after a change: leoc plot {out}",
    ]
    return lines
