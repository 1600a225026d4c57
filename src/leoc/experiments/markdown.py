"""Markdown tables: the one helper every report of ``leoc.experiments`` builds its tables with."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

__all__ = ["ALIGN_MARKERS", "markdown_table", "stacked_tables"]

#: The separator cell of each column alignment ("": markdown's default, left in most renderers).
ALIGN_MARKERS = {"": "---", "left": ":---", "right": "---:", "center": ":---:"}


def _row(cells: Sequence[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def markdown_table(
    headers: Sequence[str], rows: Iterable[Sequence[str]], align: str | Sequence[str] = ""
) -> list[str]:
    """The lines of a markdown table: the header, the separator, one line per row.

    Parameters
    ----------
    headers
        The column titles.
    rows
        The cells of each row, already formatted; an empty cell is ``""``.
    align
        One key of :data:`ALIGN_MARKERS` for every column, or one per column.

    Returns
    -------
    list[str]
        ``| a | b |``, ``|---|---|``, then ``| 1 | 2 |`` per row (no trailing blank line).

    Raises
    ------
    ValueError
        A row whose cell count differs from the headers', or an unknown or miscounted ``align``.
    """
    aligns = [align] * len(headers) if isinstance(align, str) else list(align)
    if len(aligns) != len(headers) or any(a not in ALIGN_MARKERS for a in aligns):
        raise ValueError(
            f"align: expected one of {sorted(ALIGN_MARKERS)} for each of {len(headers)} "
            f"columns, found {align!r}"
        )
    lines = [_row(headers), "|" + "".join(f"{ALIGN_MARKERS[a]}|" for a in aligns)]
    for index, cells in enumerate(rows):
        if len(cells) != len(headers):
            raise ValueError(
                f"rows: expected {len(headers)} cells in row {index}, found {len(cells)}"
            )
        lines.append(_row(cells))
    return lines


def stacked_tables(table: Callable[[Any, str], list[str]], groups: Mapping[str, Any]) -> list[str]:
    """One markdown table of several groups' tables: ``table(rows, name)`` renders one group's
    rows with ``name`` in its first columns (its header and separator the same for every name);
    the header once, then every group's rows in the order of ``groups`` (name -> rows)."""
    lines = table([], "")[:2]
    for name, rows in groups.items():
        lines += table(rows, name)[2:]
    return lines
