"""The one reader of the numeric CSV tables a user gives a run (a trajectory, a range table):
:func:`read_csv_table`. Each caller names its columns (one or more layouts), the rows it
needs and whether a header line is allowed; the reader checks the file row by row and refuses
with one line naming the file (the option that gave it), the line and the column:

* ``#`` starts a comment (to the end of the line); blank lines are skipped;
* with ``header=True`` the first line left whose first cell is not a number is a header
  (one at most, before the first row);
* every cell a finite number, every row one of the layouts, all rows of the same layout;
* at least ``min_rows`` rows (per layout);
* the first column, time, strictly increasing.

What a table means beyond that (speeds, coverage, visibility) is the caller's to check, with
:attr:`CsvTable.lines` to name the line.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["CsvTable", "read_csv_table"]


@dataclass(frozen=True)
class CsvTable:
    """A table read by :func:`read_csv_table`: ``values`` ``(rows, columns)`` float64 (read
    only), ``lines`` the file line of each row (1-based), ``columns`` the layout's names."""

    values: np.ndarray
    lines: tuple[int, ...]
    columns: tuple[str, ...]


def _layouts_text(layouts) -> str:
    if len(layouts) == 1:
        return f"{', '.join(layouts[0])} ({len(layouts[0])} columns)"
    return " or ".join(f"{len(c)} ({', '.join(c)})" for c in layouts) + " columns"


def read_csv_table(path, what: str, layouts, *, min_rows, header: bool = False,
                   separators: str = ",", extra_columns: bool = False,
                   rows_need: str = "the table") -> CsvTable:
    """Read and check the table in the file ``path`` (module doc).

    Parameters
    ----------
    path : str or Path
    what : str
        How a message names the file, e.g. ``"--trajectory-csv 'f.csv'"``.
    layouts : sequence of sequences of str
        The columns of a row, one sequence per layout accepted (first column: time, s).
    min_rows : int or sequence of int
        The fewest rows, for every layout or per layout.
    header : bool
        Allow one header line.
    separators : str
        The characters that separate cells (each one does).
    extra_columns : bool
        Cells beyond the widest layout are ignored (one layout only) instead of refused.
    rows_need : str
        Who needs ``min_rows`` rows, for the message (``"the spline"``).
    """
    layouts = tuple(tuple(c) for c in layouts)
    widths = [len(c) for c in layouts]
    mins = (min_rows,) * len(layouts) if isinstance(min_rows, int) else tuple(min_rows)
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{what} is not a file")
    split = re.compile("[" + re.escape(separators) + "]")
    rows, lines, seen_header = [], [], False
    with open(p, encoding="utf-8", errors="replace") as fh:
        for ln, text in enumerate(fh, 1):
            text = text.split("#", 1)[0].strip()
            if not text:
                continue
            cells = [c.strip() for c in split.split(text)]
            if header and not rows and not seen_header and not _is_number(cells[0]):
                seen_header = True
                continue
            if extra_columns and len(cells) > widths[0]:
                cells = cells[:widths[0]]
            if len(cells) not in widths or (rows and len(cells) != len(rows[0])):
                a_row = _layouts_text(layouts) if not rows else \
                    _layouts_text([layouts[widths.index(len(rows[0]))]])
                first = "" if not rows else f" as the first row (line {lines[0]})"
                raise ValueError(f"{what} line {ln}: {len(cells)} columns; a row is "
                                 f"{a_row}{first}")
            row = []
            for col, c in enumerate(cells, 1):
                v = _number(c)
                if not math.isfinite(v):
                    raise ValueError(f"{what} line {ln}, column {col}: {c!r} is not a finite "
                                     f"number")
                row.append(v)
            rows.append(row)
            lines.append(ln)
    k = widths.index(len(rows[0])) if rows else 0
    if len(rows) < mins[k]:
        raise ValueError(f"{what} has {len(rows)} rows of ({', '.join(layouts[k])}); "
                         f"{rows_need} needs at least {mins[k]}")
    a = np.array(rows, np.float64)
    bad = np.nonzero(np.diff(a[:, 0]) <= 0)[0]
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{what} line {lines[i + 1]}, column 1: time must increase strictly; "
                         f"{a[i + 1, 0]:g} s does not follow {a[i, 0]:g} s (line {lines[i]})")
    a.setflags(write=False)
    return CsvTable(a, tuple(lines), layouts[k])


def _number(cell: str) -> float:
    try:
        return float(cell)
    except ValueError:
        return math.nan


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True
