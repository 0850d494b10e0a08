"""Foreign CSV logs: named columns of a flight computer's CSV file, read with located errors.

The workbench's own telemetry format is :mod:`workbench.io.telemetry`; a third-party log is a CSV
file with a header row of column names (no units) and one sample per row, read by an importer
through :func:`read_columns`.  Every problem is located by file, column and 1-based data row (the
line is row + 1), up to :data:`~workbench.io.telemetry.MAX_PROBLEMS` of them in one
:class:`~workbench.io.telemetry.TelemetryError`: a column the caller needs and the header lacks, an
empty row, a wrong field count, an empty / non-numeric / non-finite cell, a time not strictly after
the previous row's.  A row repeating the previous row's time *and* every value read is a packet
logged twice: dropped and counted, never an error.  A byte-order mark before the header is ignored.
Values stay in the file's units: the importer converts (:mod:`workbench.io.units`).
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.io.telemetry import MAX_PROBLEMS, Problem, TelemetryError

__all__ = ["Columns", "read_columns"]


@dataclass(frozen=True, eq=False)
class Columns:
    """The columns read from ``path``: ``values`` {name: (n,) float, the file's unit} of the numeric
    columns (the time column among them), ``texts`` {name: (n,) str}; ``rows`` (n,) the 0-based data
    rows kept; ``repeated_rows`` how many rows repeated the previous one exactly (dropped)."""

    path: Path
    values: dict
    texts: dict
    rows: np.ndarray
    repeated_rows: int


def read_columns(
    path: str | os.PathLike,
    time: str,
    numeric: list[str] | tuple[str, ...],
    texts: list[str] | tuple[str, ...] = (),
    *,
    needed_by: str = "the mapping names it",
    check_text=None,
) -> Columns:
    """Read the columns ``time`` and ``numeric`` (numbers) and ``texts`` (strings) of the CSV ``path``
    (other columns are ignored).  ``needed_by`` ends the message of a missing column ("is missing
    (<needed_by>)"); ``check_text(column, value)`` returns a reason when a text cell is invalid (None
    when fine), reported with the other problems.  Raises a located TelemetryError (module docstring)."""
    path = Path(path)
    fname = str(path)
    try:
        fh = path.open(newline="", encoding="utf-8-sig")  # a byte-order mark is not part of the first name
    except OSError as e:
        raise TelemetryError.single(fname, f"cannot read: {e.strerror or e}") from None
    problems: list[Problem] = []
    total = 0

    def add(column, row, reason):
        nonlocal total
        total += 1
        if len(problems) < MAX_PROBLEMS:
            problems.append(Problem(fname, column, row, None if row is None else row + 1, reason))

    names = list(dict.fromkeys([time, *numeric]))
    with fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None:
            raise TelemetryError.single(fname, "empty file (expected a header row of column names)")
        header = [h.strip() for h in header]
        missing = [c for c in (*texts, *names) if c not in header]
        if missing:
            raise TelemetryError(
                [Problem(fname, c, None, 1, f"is missing ({needed_by})") for c in missing], len(missing)
            )
        idx = {c: header.index(c) for c in (*texts, *names)}
        width = len(header)
        vals: dict[str, list[float]] = {c: [] for c in names}
        txt: dict[str, list[str]] = {c: [] for c in texts}
        for r, cells in enumerate(reader, start=1):
            if not cells or all(not c.strip() for c in cells):
                add(None, r, "empty row")
                continue
            if len(cells) != width:
                add(None, r, f"has {len(cells)} fields, the header has {width}")
                continue
            for c in texts:
                s = cells[idx[c]].strip()
                why = check_text(c, s) if check_text is not None else None
                if why:
                    add(c, r, why)
                txt[c].append(s)
            for c in names:
                s = cells[idx[c]].strip()
                try:
                    v = float(s)
                except ValueError:
                    v = math.nan
                    add(c, r, f"{s!r} is not a number" if s else "empty cell")
                else:
                    if not math.isfinite(v):
                        add(c, r, f"{s!r} is not a finite number")
                vals[c].append(v)
    arr = {c: np.asarray(v, float) for c, v in vals.items()}
    t = arr[time]
    if t.size == 0 and not problems:
        raise TelemetryError.single(fname, "no data rows under the header")
    stack = np.column_stack([arr[c] for c in names])
    repeat = np.zeros(t.size, dtype=bool)
    repeat[1:] = np.all(stack[1:] == stack[:-1], axis=1)
    rows = np.flatnonzero(~repeat)
    dt = np.diff(t[rows])
    for i in np.flatnonzero(~(dt > 0)):
        if np.isfinite(dt[i]):
            r0, r1 = int(rows[i]), int(rows[i + 1])
            what = "repeats (with other values)" if dt[i] == 0 else "goes backwards from"
            add(time, r1 + 1, f"time {t[r1]:.6f} {what} the time {t[r0]:.6f} of row {r0 + 1}: not increasing")
    if problems:
        problems.sort(key=lambda p: p.row or 0)
        raise TelemetryError(problems, total)
    return Columns(
        path,
        {c: v[rows] for c, v in arr.items()},
        {c: np.asarray(v)[rows] for c, v in txt.items()},
        rows,
        int(np.sum(repeat)),
    )
