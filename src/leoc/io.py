"""Atomic file output shared by every part of leoc.

Every result file goes to a temporary file in the same folder and is then renamed over the
target (``os.replace`` is atomic on POSIX and Windows), so an interrupted run never leaves a
half-written file behind, and concurrent writers never interleave.
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

FILE_MODE = 0o666  # an ordinary new file, before the umask


def _umask() -> int:
    """The process umask (read by setting it and restoring it at once)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a unique temporary file and a rename.

    The file gets the permissions of an ordinary new file (``0o666`` less the umask), not the
    private ``0o600`` of the temporary file, which would otherwise survive the rename.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        if hasattr(os, "fchmod"):  # POSIX
            os.fchmod(handle, FILE_MODE & ~_umask())
        with os.fdopen(handle, "wb") as file:
            file.write(data)
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise
    return path


def write_text_atomic(path: str | Path, text: str) -> Path:
    """UTF-8 text, atomically."""
    return write_bytes_atomic(path, text.encode("utf-8"))


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_json_atomic(path: str | Path, data: Any, indent: int = 1) -> Path:
    """JSON (numpy scalars and arrays and paths converted), atomically."""
    return write_text_atomic(path, json.dumps(data, indent=indent, default=_json_default))


def write_csv_atomic(
    path: str | Path, rows: Iterable[Mapping[str, Any]], fieldnames: Sequence[str] | None = None
) -> Path:
    """CSV with a header (default: the keys of the first row; extra keys ignored), atomically."""
    rows = list(rows)
    if fieldnames is None:
        fieldnames = list(rows[0]) if rows else []
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(fieldnames), extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    return write_text_atomic(path, buffer.getvalue())


def save_torch_atomic(obj: Any, path: str | Path) -> Path:
    """``torch.save`` atomically."""
    import torch

    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return write_bytes_atomic(path, buffer.getvalue())


def save_figure_atomic(figure: Any, path: str | Path, dpi: int = 120) -> Path:
    """Save a matplotlib figure as PNG atomically, then close it."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(figure)
    return write_bytes_atomic(path, buffer.getvalue())


def set_aside(path: str | Path) -> Path:
    """Rename a damaged file to ``NAME.damaged-YYYYmmdd-HHMMSS[-k]`` beside it and return the
    new path. Never deleted: the user may want to look at it; never in the way of a rerun."""
    import time

    path = Path(path)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    target = path.with_name(f"{path.name}.damaged-{stamp}")
    count = 1
    while target.exists():
        count += 1
        target = path.with_name(f"{path.name}.damaged-{stamp}-{count}")
    os.replace(path, target)
    return target


def read_json_object(path: str | Path, echo: Any, what: str) -> dict[str, Any] | None:
    """The JSON object in ``path``; None when the file is absent or damaged. A file that does
    not parse as a JSON object (truncated, garbled) is set aside (:func:`set_aside`) and
    ``echo`` gets one line naming it, so a damaged file never blocks a rerun."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
        if not isinstance(data, dict):
            raise ValueError(f"expected a JSON object, found {type(data).__name__}")
    except (ValueError, UnicodeDecodeError) as error:
        aside = set_aside(path)
        reason = f"{type(error).__name__}: {error}".splitlines()[0]
        echo(f"damaged {what} {path} ({reason}): set aside as {aside.name}")
        return None
    return data
