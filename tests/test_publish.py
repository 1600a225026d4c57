"""Published results: numbers without weights, and `leoc plot` regenerating them byte for byte."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from leoc.cli import main
from leoc.experiments.layout import EVALUATION_FILE, META_FILE
from leoc.experiments.publish import REPORT_TEXT_FILES, publish
from leoc.experiments.reproduce import reproduce

RESULTS = Path(__file__).resolve().parents[1] / "results"
PUBLISHED = sorted(path.parent for path in RESULTS.glob(f"*/{META_FILE}"))


def _numbers_only(source: Path, dest: Path) -> None:
    """Copy what the report is made from (meta.json, every evaluation.json), nothing it wrote."""
    dest.mkdir(parents=True)
    shutil.copyfile(source / META_FILE, dest / META_FILE)
    for path in source.glob(f"runs/*/*/seed*/{EVALUATION_FILE}"):
        copy = dest / path.relative_to(source)
        copy.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, copy)


def _regenerates_byte_for_byte(published: Path, scratch: Path) -> None:
    _numbers_only(published, scratch)
    assert main(["plot", str(scratch)]) == 0
    for name in REPORT_TEXT_FILES:
        assert (scratch / name).read_bytes() == (published / name).read_bytes(), name


@pytest.mark.slow
def test_publish_copies_numbers_not_weights_and_plot_regenerates_them(tmp_path) -> None:
    source = tmp_path / "run"
    reproduce(
        source,
        profile_name="smoke",
        systems=["pendulum"],
        controllers=["linear"],
        jobs=1,
        echo=lambda _: None,
    )
    published = tmp_path / "published"
    report = publish(source, published)
    assert report == published / "report.md"
    copied = {p.relative_to(published).as_posix() for p in published.rglob("*") if p.is_file()}
    runs = {p for p in copied if p.startswith("runs/")}
    assert runs and all(p.endswith((EVALUATION_FILE, "train.log")) for p in runs)
    assert not any("/train/" in p for p in copied)  # no trainer folders (weights, checkpoints)
    for name in REPORT_TEXT_FILES:
        # the same numbers give the same report in the source folder and in the copy
        assert (published / name).read_bytes() == (source / name).read_bytes(), name
    _regenerates_byte_for_byte(published, tmp_path / "scratch")


def test_publish_refuses_a_destination_inside_the_source(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="no meta.json"):
        publish(tmp_path, tmp_path.parent / "elsewhere")
    (tmp_path / META_FILE).write_text("{}")
    with pytest.raises(ValueError, match="dest: expected a folder outside"):
        publish(tmp_path, tmp_path / "inside")


@pytest.mark.slow
@pytest.mark.parametrize("published", PUBLISHED, ids=[p.name for p in PUBLISHED])
def test_committed_results_regenerate_byte_for_byte(published, tmp_path) -> None:
    """`leoc plot` on the committed numbers gives the committed report and CSVs exactly.

    Every published folder's numbers are copied beside it, so that a companion recorded in
    meta.json (``compare``, a relative path such as ``../paper-authors``) resolves as in
    ``results/``."""
    for other in PUBLISHED:
        if other != published:
            _numbers_only(other, tmp_path / other.name)
    _regenerates_byte_for_byte(published, tmp_path / published.name)
