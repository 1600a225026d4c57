"""Publishing a reproduce folder: its numbers without its weights, and the report rebuilt there.

A ``leoc gym-study`` folder (:mod:`leoc.experiments.gym_study`: ``study.json``, runs under
``runs/ENV/NOISE/CONTROLLER/seedK``) publishes the same way: every run's record
(``evaluation.json``, which holds everything the report reads) with its ``config.json`` and
``design.json``, and ``study.json`` with the report when the study has one. A study still
running has no ``study.json`` yet: its finished runs are carried, and the same ``leoc gym-study``
command on the copy reuses them (its records' keys match) and trains only the rest.

``leoc publish RUN_DIR DEST`` copies what the report is made from (``meta.json`` and every run's
``evaluation.json``, plus its ``train.log`` when it is small) into ``DEST`` with the folder
layout of :mod:`leoc.experiments.layout`, leaves the trained controllers, checkpoints and replay
buffers behind, and writes the report in ``DEST``. ``leoc plot DEST`` then regenerates the same
report, CSVs and ``results.json`` byte for byte from the copied numbers (a test checks it for
every folder under ``results/``).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from leoc.experiments.layout import EVALUATION_FILE, LOG_FILE, META_FILE
from leoc.io import write_text_atomic

# A run's log is copied when it is at most this large (progress lines; a traceback at most).
MAX_LOG_BYTES = 256 * 1024
# The files `leoc plot` writes from the numbers (compared byte for byte by the tests).
REPORT_TEXT_FILES = (
    "report.md",
    "results.json",
    "responses.csv",
    "robustness.csv",
    "swing_up.csv",
    "seed_statistics.csv",
    "learning_curves.csv",
)


def publish(run_dir: str | Path, dest: str | Path) -> Path:
    """Copy the numbers of the reproduce folder ``run_dir`` into ``dest`` and write the report
    there; returns the path of ``dest/report.md``.

    Raises
    ------
    FileNotFoundError
        When ``run_dir`` has no ``meta.json`` or no finished run.
    ValueError
        When ``dest`` is ``run_dir`` or lies inside it.
    """
    from leoc.experiments.report import write_report

    source, target = Path(run_dir).resolve(), Path(dest).resolve()
    if not (source / META_FILE).is_file() and not _is_gym_study(source):
        raise FileNotFoundError(
            f"run_dir: no {META_FILE} in {str(run_dir)!r}; is it a reproduce folder (or a "
            "gym-study folder)?"
        )
    if target == source or source in target.parents:
        raise ValueError(f"dest: expected a folder outside {str(run_dir)!r}, found {str(dest)!r}")
    if not (source / META_FILE).is_file():
        return _publish_gym_study(source, target, str(run_dir))
    evaluations = sorted(source.glob(f"runs/*/*/seed*/{EVALUATION_FILE}"))
    if not evaluations:
        raise FileNotFoundError(f"run_dir: no finished run ({EVALUATION_FILE}) in {str(run_dir)!r}")
    target.mkdir(parents=True, exist_ok=True)
    write_text_atomic(target / META_FILE, (source / META_FILE).read_text())
    for path in evaluations:
        run = path.parent
        copy = target / run.relative_to(source)
        copy.mkdir(parents=True, exist_ok=True)
        write_text_atomic(copy / EVALUATION_FILE, path.read_text())
        log = run / LOG_FILE
        if log.is_file() and log.stat().st_size <= MAX_LOG_BYTES:
            shutil.copyfile(log, copy / LOG_FILE)
    return write_report(target)


#: A gym-study run's files that are copied (its record, its settings and its LQR design).
GYM_RUN_FILES = (EVALUATION_FILE, "config.json", "design.json")


def _gym_records(source: Path) -> list[Path]:
    """The run records of a gym-study folder (``runs/ENV/NOISE-or-ARM/CONTROLLER/seedK``)."""
    return sorted(source.glob(f"runs/*/*/*/seed*/{EVALUATION_FILE}"))


def _is_gym_study(source: Path) -> bool:
    from leoc.experiments.gym_study import STUDY_FILE

    return (source / STUDY_FILE).is_file() or bool(_gym_records(source))


def _publish_gym_study(source: Path, target: Path, name: str) -> Path:
    """:func:`publish` of a gym-study folder (module docstring): the README's path, or
    ``target`` itself when the study has no ``study.json`` yet."""
    from leoc.experiments.gym_study import STUDY_FILE
    from leoc.experiments.gym_study_report import write_study_report

    records = _gym_records(source)
    if not records:
        raise FileNotFoundError(f"run_dir: no finished run ({EVALUATION_FILE}) in {name!r}")
    for path in records:
        run = path.parent
        copy = target / run.relative_to(source)
        copy.mkdir(parents=True, exist_ok=True)
        for file_name in GYM_RUN_FILES:
            if (run / file_name).is_file():
                write_text_atomic(copy / file_name, (run / file_name).read_text())
    if not (source / STUDY_FILE).is_file():
        return target
    write_text_atomic(target / STUDY_FILE, (source / STUDY_FILE).read_text())
    return write_study_report(target)
