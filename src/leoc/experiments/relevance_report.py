r"""The relevance ablation's tables and trade-off figure: does a learned hybrid keep its LQR?

For the hybrid runs of an ablation folder (:mod:`leoc.experiments.ablation`) whose records
carry ``lqr_agreement`` (:mod:`leoc.evaluation.lqr_agreement`), one row per system x controller
x setting:

* **learns**: seeds whose delivered controller held the operating point in every held-out
  swing-up episode at the run's budget (the ablation's success test), and the median
  interaction time to the *first* evaluation that held in every episode (seconds of simulated
  interaction: environment steps times the system's step; over the seeds that ever held);
* **keeps its LQR**: seeds whose delivered controller's response to the paper's impulse stays
  within :data:`~leoc.evaluation.lqr_agreement.KEEP_TOLERANCE_PCT` % of the LQR's peak with
  the same settling time (``keeps_lqr``); the median and range of that distance; the least
  relevance along the response; and how many seeds held ``r == 1`` all along (*by
  construction*: such a seed cannot fail the comparison);
* the learned :math:`\Lambda` (median over seeds, per observation entry; the Lyapunov
  relevance's single scale).

PILCO is not trained by the ablation harness (its budget is iterations of rollouts, not
environment steps with evaluations between): its hybrids are PILCO run folders under
``OUT/pilco`` (:data:`PILCO_FOLDER`; ``SYSTEM/CONTROLLER/seedN/train`` as
``benchmarks/bench_pilco_failures.py`` trains them, exactly as ``leoc reproduce`` does, or a
``leoc reproduce`` folder's ``runs/...``). :func:`pilco_relevance_records` reads each PILCO
hybrid run there into a record of the same columns: (a) is the run's final controller holding
every one of its evaluation episodes after the last iteration (the trainer's evaluation starts,
``seed + 10000 + k``, the starts of ``leoc reproduce``'s swing-up test; PILCO's model selection
is ``"final"``, so they choose nothing), the first hold is the first iteration whose evaluation
held in every episode (interaction seconds), the LQR comparison is the ablation's (the saved
controller against the LQR at its control period), and the setting is the
:data:`~leoc.experiments.ablation.RELEVANCE_SETTINGS` entry whose
:class:`~leoc.policies.HybridSpec` the run trained (``custom`` if none).

The figure puts one point per run: the impulse distance (log scale) against the time to first
hold (runs that never held on the top edge), so the trade-off between keeping the LQR and
learning the swing-up shows as a cloud per setting.
"""

from __future__ import annotations

import functools
import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from leoc.evaluation.lqr_agreement import KEEP_TOLERANCE_PCT
from leoc.experiments.ablation import (
    ALL_SETTINGS,
    GRID_CONTROLLERS,
    PAPER_RELEVANCE_BASE,
    RELEVANCE_SETTINGS,
    SETTING_LABELS,
    TRAIN_DIR,
    delivered_lqr_agreement,
    run_outcome,
)
from leoc.experiments.markdown import markdown_table
from leoc.experiments.profiles import CONTROLLER_LABELS
from leoc.io import read_json_object, write_csv_atomic, write_json_atomic, write_text_atomic

__all__ = [
    "RELEVANCE_FIGURE",
    "first_hold_seconds",
    "pilco_relevance_records",
    "relevance_cells",
    "relevance_markdown",
    "write_relevance_report",
]

RELEVANCE_TABLE = "relevance.md"
"""The report's markdown, in the ablation folder."""
RELEVANCE_CSV = "relevance.csv"
"""One row per cell (:data:`CSV_COLUMNS`)."""
RELEVANCE_FIGURE = "relevance_tradeoff.png"
"""The trade-off figure (``plot_relevance_tradeoff``)."""
PILCO_FOLDER = "pilco"
"""The ``leoc reproduce`` folder of an ablation folder that holds its PILCO hybrid runs."""
PILCO_RECORD = "relevance.json"
"""A PILCO run's record (:func:`pilco_relevance_records`), beside its ``evaluation.json``;
what a published folder keeps of the run."""
CUSTOM_SETTING = "custom"
"""The setting of a PILCO run whose hybrid matches no relevance setting."""
CSV_COLUMNS = (
    "system",
    "controller",
    "setting",
    "seeds",
    "success",
    "median_first_hold_s",
    "keeps_lqr",
    "by_construction",
    "median_distance_pct",
    "min_distance_pct",
    "max_distance_pct",
    "median_min_relevance",
    "median_step_distance_pct",
    "median_lambda",
)


@functools.cache
def _dt(system: str) -> float:
    """The system's step [s] (built once per name)."""
    from leoc.systems import make_system

    return float(make_system(system).dt)


def first_hold_seconds(record: Mapping[str, Any]) -> float | None:
    """Interaction seconds to the first evaluation whose held-out episodes all held; None if
    none did (a PILCO record carries it as ``first_hold_s``)."""
    if "first_hold_s" in record:
        return record["first_hold_s"]
    for row in record["evaluations"]:
        hold = row["test_hold_steps"]
        if hold and all(step is not None for step in hold):
            return float(row["steps"]) * _dt(str(record["system"]))
    return None


def _success(record: Mapping[str, Any]) -> bool:
    """The run's (a): a PILCO record's own ``success``, else the ablation's success test."""
    if "success" in record:
        return bool(record["success"])
    return run_outcome(record, int(record["budget"])).success


def _median(values: Iterable[float | None]) -> float | None:
    found = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return statistics.median(found) if found else None


def _lambda_median(agreements: Sequence[Mapping[str, Any]]) -> list[float] | None:
    vectors = [a["relevance"].get("lambda") for a in agreements if a.get("relevance")]
    vectors = [v for v in vectors if v]
    if not vectors or len({len(v) for v in vectors}) != 1:
        return None
    return [statistics.median(column) for column in zip(*vectors, strict=True)]


def _cell(key: tuple[str, str, str], records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    agreements = [r["lqr_agreement"] for r in records]
    impulse = [a["impulse"] for a in agreements]
    distances = [p["distance_pct"] for p in impulse]
    success = sum(_success(r) for r in records)
    return {
        "system": key[0],
        "controller": key[1],
        "setting": key[2],
        "seeds": len(records),
        "success": success,
        "median_first_hold_s": _median(first_hold_seconds(r) for r in records),
        "ever_held": sum(first_hold_seconds(r) is not None for r in records),
        "keeps_lqr": sum(bool(p["keeps_lqr"]) for p in impulse),
        "by_construction": sum(bool(p["by_construction"]) for p in impulse),
        "median_distance_pct": _median(distances),
        "min_distance_pct": min(distances),
        "max_distance_pct": max(distances),
        "median_min_relevance": _median(p["min_relevance"] for p in impulse),
        "median_step_distance_pct": _median(a["step"]["distance_pct"] for a in agreements),
        "median_lambda": _lambda_median(agreements),
    }


def relevance_setting(hybrid: Mapping[str, Any]) -> str:
    """The :data:`~leoc.experiments.ablation.RELEVANCE_SETTINGS` entry that trains the hybrid
    ``hybrid`` (a :meth:`~leoc.policies.HybridSpec.to_dict`): leoc's default spec with the
    setting's fields; :data:`CUSTOM_SETTING` if none does."""
    from leoc.policies.spec import HybridSpec

    default = HybridSpec().to_dict()
    for name, (_, fields) in RELEVANCE_SETTINGS.items():
        if {**default, **PAPER_RELEVANCE_BASE, **fields} == dict(hybrid):
            return name
    return CUSTOM_SETTING


def _pilco_record(run: Path, echo: Any) -> dict[str, Any] | None:
    """The record of the PILCO hybrid run ``run`` (``.../CONTROLLER/seedN``, its run folder in
    ``run/train``); None when it is unfinished (fewer curve rows than its iterations + 1)."""
    from leoc.systems import make_system

    train = run / TRAIN_DIR
    config = read_json_object(train / "config.json", echo, "PILCO config")
    curve = read_json_object(train / "curve.json", echo, "PILCO curve")
    if not config or not curve or not config.get("hybrid"):
        return None
    rows = curve["curve"]
    if len(rows) < int(config["iterations"]) + 1 or not (train / "controller.pt").is_file():
        return None
    held = [row for row in rows if row["held_fraction"] >= 1.0]
    return {
        "system": config["system"],
        "controller": run.parent.name,
        "setting": relevance_setting(config["hybrid"]),
        "seed": int(config["seed"]),
        "key": f"{config['system']}/{run.parent.name}/seed{config['seed']}",
        "iterations": int(config["iterations"]),
        "success": rows[-1]["held_fraction"] >= 1.0,
        "first_hold_s": float(held[0]["interaction_seconds"]) if held else None,
        "hybrid": config["hybrid"],
        "lqr_agreement": delivered_lqr_agreement(run, make_system(str(config["system"])), True),
    }


def pilco_relevance_records(
    folder: str | Path, echo: Any = print, write_to: str | Path | None = None
) -> list[dict[str, Any]]:
    """The PILCO hybrid runs under ``folder`` (``.../pilco_hybrid*/seedN/train``, as ``leoc
    reproduce`` or ``benchmarks/bench_pilco_failures.py`` lay them out), as relevance records
    (module docstring): each run's :data:`PILCO_RECORD` where it has one (a published folder),
    else read from its run folder. ``write_to``: a folder where each record is written at the
    run's relative path (publishing)."""
    root = Path(folder)
    runs = {path.parent for path in root.glob(f"**/seed*/{PILCO_RECORD}")}
    runs |= {path.parent for path in root.glob("**/seed*/train")}
    records = []
    for run in sorted(r for r in runs if r.parent.name.startswith("pilco_hybrid")):
        record = read_json_object(run / PILCO_RECORD, echo, "PILCO relevance record")
        record = record or _pilco_record(run, echo)
        if record is None:
            continue
        records.append(record)
        if write_to is not None:
            target = Path(write_to) / run.relative_to(root)
            target.mkdir(parents=True, exist_ok=True)
            write_json_atomic(target / PILCO_RECORD, record, indent=1)
    return records


def relevance_cells(records: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per system x controller x setting of the hybrid records with an
    ``lqr_agreement`` (module docstring), in the grid's order."""
    groups: dict[tuple[str, str, str], list[Mapping[str, Any]]] = {}
    for record in records:
        if record.get("lqr_agreement"):
            key = (str(record["system"]), str(record["controller"]), str(record["setting"]))
            groups.setdefault(key, []).append(record)

    def order(key: tuple[str, str, str]) -> tuple:
        controller = GRID_CONTROLLERS.index(key[1]) if key[1] in GRID_CONTROLLERS else 99
        setting = ALL_SETTINGS.index(key[2]) if key[2] in ALL_SETTINGS else 99
        return (key[0], controller, setting)

    return [_cell(key, groups[key]) for key in sorted(groups, key=order)]


def _number(value: float | None, digits: int = 2) -> str:
    if value is None:
        return "-"
    if not math.isfinite(value):
        return "inf"
    return f"{value:.{digits}g}" if abs(value) < 0.01 else f"{value:.{digits}f}"


def _lambda_text(values: list[float] | None) -> str:
    return "-" if values is None else ", ".join(f"{v:.3g}" for v in values)


def _row(cell: Mapping[str, Any]) -> list[str]:
    n = cell["seeds"]
    first = _number(cell["median_first_hold_s"], 0)
    return [
        CONTROLLER_LABELS.get(str(cell["controller"]), str(cell["controller"])),
        SETTING_LABELS.get(cell["setting"], cell["setting"]),
        f"{cell['success']}/{n}",
        f"{first} ({cell['ever_held']}/{n})",
        f"**{cell['keeps_lqr']}/{n}**",
        f"{_number(cell['median_distance_pct'])} "
        f"[{_number(cell['min_distance_pct'])}, {_number(cell['max_distance_pct'])}]",
        _number(cell["median_min_relevance"], 4),
        f"{cell['by_construction']}/{n}",
        _lambda_text(cell["median_lambda"]),
    ]


HEADER = (
    "controller",
    "setting",
    "learns (a)",
    "first hold s (seeds)",
    "keeps LQR (b)",
    "impulse distance % median [range]",
    "min r (impulse)",
    "r == 1 all along",
    "learned Lambda (median)",
)
DEFINITIONS = (
    "(a) learns: seeds whose delivered controller held the operating point in every held-out "
    "swing-up episode at the budget; first hold: median interaction seconds to the first "
    "evaluation that held in every episode, over the seeds that ever held (how many in "
    f"brackets). (b) keeps its LQR: seeds whose response to the paper's impulse stays within "
    f"{KEEP_TOLERANCE_PCT:g} % of the LQR's peak deviation with the same settling time (one "
    "control period of slack); the distance is the largest difference of the two responses' "
    "main coordinate, in % of the LQR's peak. A seed with r == 1 all along the response equals "
    "its LQR by construction (it cannot fail (b)); with the paper's relevance r < 1 everywhere "
    "but at the operating point, so (b) can fail. Lambda: the diagonal of the learned Lambda "
    "per observation entry (the Lyapunov relevance: its one scale)."
)


PILCO_DEFINITIONS = (
    "PILCO hybrids (folder `pilco/`, trained as `leoc reproduce --profile paper` trains them): "
    "(a) is the final controller holding every one of its evaluation episodes after the last "
    "iteration (the starts of `leoc reproduce`'s swing-up test; none used for training or "
    "selection), and the first hold is the first iteration whose evaluation held in every "
    "episode, in interaction seconds."
)


def relevance_markdown(cells: Sequence[Mapping[str, Any]], command: str | None = None) -> str:
    """The ``relevance.md`` text of :func:`relevance_cells`."""
    lines = ["# Does the learned hybrid keep its LQR?", "", DEFINITIONS, ""]
    if any(str(cell["controller"]).startswith("pilco") for cell in cells):
        lines += [PILCO_DEFINITIONS, ""]
    if command:
        lines += [f"Command: `{command}`", ""]
    for system in dict.fromkeys(cell["system"] for cell in cells):
        rows = [_row(cell) for cell in cells if cell["system"] == system]
        lines += [f"## {system}", "", *markdown_table(HEADER, rows), ""]
    lines += [f"![impulse distance against time to first hold]({RELEVANCE_FIGURE})", ""]
    return "\n".join(lines)


def _csv_row(cell: Mapping[str, Any]) -> dict[str, Any]:
    row = {name: cell[name] for name in CSV_COLUMNS}
    row["median_lambda"] = _lambda_text(cell["median_lambda"])
    return row


def write_relevance_report(
    dest: str | Path, records: Sequence[Mapping[str, Any]], command: str | None = None
) -> Path | None:
    """Write ``relevance.md``, ``relevance.csv`` and the trade-off figure into ``dest`` when
    some record carries ``lqr_agreement``; returns the markdown's path (None: nothing to
    report)."""
    from leoc.evaluation.plots.relevance_tradeoff import plot_relevance_tradeoff

    cells = relevance_cells(records)
    if not cells:
        return None
    out = Path(dest)
    out.mkdir(parents=True, exist_ok=True)
    write_csv_atomic(out / RELEVANCE_CSV, [_csv_row(cell) for cell in cells], CSV_COLUMNS)
    points = [
        {
            "system": r["system"],
            "setting": r["setting"],
            "controller": r["controller"],
            "distance_pct": r["lqr_agreement"]["impulse"]["distance_pct"],
            "first_hold_s": first_hold_seconds(r),
        }
        for r in records
        if r.get("lqr_agreement") and not r["lqr_agreement"]["impulse"]["by_construction"]
    ]
    plot_relevance_tradeoff(points, out / RELEVANCE_FIGURE, SETTING_LABELS, KEEP_TOLERANCE_PCT)
    markdown = out / RELEVANCE_TABLE
    write_text_atomic(markdown, relevance_markdown(cells, command))
    return markdown
