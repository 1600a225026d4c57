"""The report assembled from its sections: ``results.json``, the CSV files, the figures and
``report.md`` of a reproduce folder, in the order of :data:`SECTIONS`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from leoc.experiments.layout import META_FILE, load_evaluations
from leoc.experiments.report import (
    appendix,
    claims,
    definitions,
    figures,
    header,
    overview,
    proved_regions,
    responses,
    roa,
    robustness,
    robustness_protocol,
    seeds,
    swing_up,
)
from leoc.experiments.report.base import Report, Study
from leoc.io import write_csv_atomic, write_json_atomic, write_text_atomic

SECTIONS = (
    header.SECTION,
    overview.SECTION,
    definitions.SECTION,
    appendix.SECTION,
    responses.SECTION,
    robustness.SECTION,
    robustness_protocol.SECTION,
    swing_up.SECTION,
    roa.SECTION,
    proved_regions.SECTION,
    claims.SECTION,
    seeds.SECTION,
    figures.SECTION,
)
"""The sections of ``report.md``, in its order; a new section is a module with a ``SECTION``
(:class:`leoc.experiments.report.base.Section`) and an entry here."""
RESULTS_ENTRIES = (
    ("responses", "responses"),
    ("robustness", "robustness"),
    ("swing_up", "swing_up"),
    ("seed_statistics", "seeds"),
    ("region_of_attraction", "roa"),
    ("proved_regions", "proved_regions"),
    ("robustness_protocol", "robustness_protocol"),
    ("robustness_protocol_verdicts", "robustness_protocol_verdicts"),
    ("probability_of_improvement", "improvements"),
    ("learning_curves", "curves"),
)
"""``results.json``'s entries (after ``meta``), each the sections' table of that name."""
CSV_FILES = (
    ("responses.csv", "responses"),
    ("robustness.csv", "robustness"),
    ("swing_up.csv", "swing_up"),
    ("seed_statistics.csv", "seeds"),
)
"""The tables also written as CSV files (``learning_curves.csv`` besides, one row per point)."""


def render_markdown(report: Report) -> str:
    """The markdown of ``report.md``: every section of :data:`SECTIONS` in turn."""
    return "\n".join(line for section in SECTIONS for line in section.render(report))


def record_companion(out_dir: str | Path, other: str | Path) -> None:
    """Record in ``out_dir``'s ``meta.json`` the reproduce folder ``other`` (of the other
    implementation variant) whose runs the appendix-D table sets beside this folder's; stored
    relative to ``out_dir`` so that a published pair of folders keeps it.

    Raises
    ------
    FileNotFoundError
        Either folder has no ``meta.json``.
    ValueError
        Both folders hold the same variant.
    """
    import os

    out, companion = Path(out_dir), Path(other)
    metas = []
    for folder, name in ((out, "run_dir"), (companion, "compare")):
        if not (folder / META_FILE).is_file():
            raise FileNotFoundError(f"{name}: no {META_FILE} in {str(folder)!r}")
        metas.append(json.loads((folder / META_FILE).read_text()))
    variants = [meta.get("variant", "leoc") for meta in metas]
    if variants[0] == variants[1]:
        raise ValueError(
            f"compare: expected a folder of the other variant, found {variants[1]!r} in both"
        )
    metas[0]["compare"] = os.path.relpath(companion.resolve(), out.resolve())
    write_json_atomic(out / META_FILE, metas[0])


def load_study(out_dir: str | Path) -> Study:
    """The reproduce folder ``out_dir``: its ``meta.json`` and its finished runs.

    Raises
    ------
    FileNotFoundError
        The folder, or its ``meta.json``, does not exist.
    ValueError
        Its ``meta.json`` is damaged.
    """
    out = Path(out_dir)
    if not out.is_dir():
        raise FileNotFoundError(f"run_dir: the folder {str(out)!r} does not exist")
    meta_path = out / META_FILE
    if not meta_path.is_file():
        raise FileNotFoundError(
            f"run_dir: no {META_FILE} in {str(out)!r}; is it a reproduce folder?"
        )
    try:
        meta = json.loads(meta_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{meta_path}: damaged reproduce metadata ({error})") from error
    return Study(out, meta, load_evaluations(out, meta))


def _write_numbers(report: Report, code_versions: dict[str, list[str]]) -> None:
    """``results.json`` and the CSV files of the report's tables."""
    out, tables = report.study.out, report.tables
    results: dict[str, Any] = {"meta": report.study.meta}
    results.update({entry: tables[name] for entry, name in RESULTS_ENTRIES})
    results.update(
        flags=report.flags,
        checks=report.checks,
        summed_run_wall_seconds=report.run_seconds,
        code_versions=code_versions,
    )
    write_json_atomic(out / "results.json", results)
    for filename, name in CSV_FILES:
        write_csv_atomic(out / filename, tables[name])
    curve_rows = [
        {"system": s, "controller": c, "seconds": t, "mean": m, "std": d}
        for s, by_c in tables["curves"].items()
        for c, curve in by_c.items()
        for t, m, d in zip(curve["seconds"], curve["mean"], curve["std"], strict=True)
    ]
    write_csv_atomic(out / "learning_curves.csv", curve_rows)


def write_report(out_dir: str | Path) -> Path:
    """Aggregate the finished runs of ``out_dir`` into numbers, figures and ``report.md``.

    Every section of :data:`SECTIONS` computes its tables, each check makes its flags and its
    summary, the numbers and figures are written, then the sections render the markdown.
    """
    study = load_study(out_dir)
    tables: dict[str, Any] = {}
    for section in SECTIONS:
        if section.compute is not None:
            tables.update(section.compute(study))
    checks = [section.check for section in SECTIONS if section.check is not None]
    run_seconds = sum(
        run["wall_seconds"]
        for by_c in study.evaluations.values()
        for runs in by_c.values()
        for run in runs
    )
    report = Report(
        study,
        tables,
        flags={check.key: check.flags(tables[check.key]) for check in checks},
        checks={check.key: check.summary(tables[check.key]).to_json() for check in checks},
        figures=[],  # drawn once the numbers are written, as below
        run_seconds=run_seconds,
    )
    _write_numbers(report, header.code_versions(study.evaluations))
    report = report._replace(figures=figures.write_figures(study, tables))
    path = study.out / "report.md"
    write_text_atomic(path, render_markdown(report))
    return path
