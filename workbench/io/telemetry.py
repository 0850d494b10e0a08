"""Telemetry CSV files: read with full validation, write atomically, plus the events CSV.

The format (FORMATS.md has the user-facing description)::

    # sensor: BP accelerometer triad            <- optional "# key: value" metadata lines
    # rate_hz: 1000
    time [s],BP.x [g],BP.y [g],BP.z [g]         <- one header row, every column "name [unit]"
    0.000,0.01,-0.02,1.00                       <- one row per sample, time first, strictly increasing
    0.001,0.02,-0.01,1.01

Values are converted to SI on reading (:mod:`workbench.io.units`) and from SI on writing.
Nothing bad is silently dropped or turned into a number: NaN/inf literals, empty or unparsable
cells, wrong field counts, duplicate or backwards times, unknown or wrong-kind units, missing
columns and out-of-limit values are all errors.  Every problem is located by file, column, data
row (1-based, the first row under the header is row 1) and file line (1-based), and up to
:data:`MAX_PROBLEMS` of them are reported together in one :class:`TelemetryError`.

Two things are *not* errors, because the pipeline decides what to do with them and reports it:
saturated samples (flagged in :attr:`Telemetry.saturated`) and time gaps (listed in
:attr:`Telemetry.gaps`).  A channel sampled less often than the time column (e.g. a radar
altimeter in an IMU file) may be declared *sparse* (``# sparse: range.R1, range.R2`` or
``read_telemetry(..., sparse=...)``): only its empty cells are then allowed, and read as NaN.

Parsing is vectorised per column (``float`` mapped over the column's cells); the row-by-row scan
runs only when a column fails, to locate the failing cells.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import tempfile
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from workbench.io.units import KINDS, SI_UNITS, UNITS, UnitError, canonical_unit, from_si, known_units, to_si

__all__ = [
    "MAX_PROBLEMS",
    "Gap",
    "Problem",
    "Telemetry",
    "TelemetryError",
    "atomic_write_npz",
    "atomic_write_text",
    "read_events",
    "read_telemetry",
    "write_events",
    "write_telemetry",
]

#: How many problems one TelemetryError lists (the total count is always given).
MAX_PROBLEMS = 20

_HEADER_RE = re.compile(r"^(?P<name>.*?)\s*\[(?P<unit>[^\[\]]*)\]$")
_META_RE = re.compile(r"^(?P<key>[A-Za-z_][\w.\-]*)\s*:\s*(?P<value>.*)$")
_BAD_NAME_CHARS = set(',[]"\n\r')


# --------------------------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    """One located problem in a telemetry or events file.

    ``column`` is the header cell as written in the file (``'BP.x [g]'``) or None for
    file-level problems; ``row`` is the 1-based data row (None for header/metadata problems);
    ``line`` is the 1-based line in the file (None when the whole file is concerned).
    """

    file: str
    column: str | None
    row: int | None
    line: int | None
    reason: str

    def __str__(self) -> str:
        if self.row is not None:
            where = f"{self.file}, column {self.column!r}, " if self.column is not None else f"{self.file}, "
            where += f"row {self.row}" + (f" (line {self.line})" if self.line is not None else "")
            return f"{where}: {self.reason}"
        loc = f"{self.file}, line {self.line}" if self.line is not None else self.file
        if self.column is not None:
            return f"{loc} (header): column {self.column!r} {self.reason}"
        return f"{loc}: {self.reason}"


class TelemetryError(ValueError):
    """Bad telemetry input.  Lists up to :data:`MAX_PROBLEMS` problems, in file order.

    Attributes ``file``, ``column``, ``row``, ``line``, ``reason`` describe the first problem;
    ``problems`` holds all listed ones (:class:`Problem`) and ``total`` how many were found.
    """

    def __init__(self, problems: Sequence[Problem], total: int | None = None):
        if not problems:
            raise ValueError("TelemetryError needs at least one problem")
        self.problems = tuple(problems)
        self.total = max(total or 0, len(self.problems))
        first = self.problems[0]
        self.file, self.column, self.row, self.line, self.reason = (
            first.file,
            first.column,
            first.row,
            first.line,
            first.reason,
        )
        super().__init__(self._message())

    @classmethod
    def single(
        cls, file, reason: str, *, column: str | None = None, row: int | None = None, line: int | None = None
    ) -> TelemetryError:
        """Build an error holding one problem."""
        return cls([Problem(str(file), column, row, line, reason)])

    def _message(self) -> str:
        if self.total == 1:
            return str(self.problems[0])
        head = f"{self.total} problems in {self.file}"
        if self.total > len(self.problems):
            head += f" (first {len(self.problems)} listed)"
        return head + ":\n" + "\n".join(f"  - {p}" for p in self.problems)

    def __reduce__(self):
        return (type(self), (self.problems, self.total))


class _Collector:
    """Gathers problems cheaply: totals are counted, only the earliest few are materialised."""

    def __init__(self, file: str):
        self.file = file
        self.items: list[tuple[int, int, Problem]] = []
        self.total = 0

    def add(self, reason: str, *, column=None, row=None, line=None, order: int = -1) -> None:
        self.total += 1
        key = line if line is not None else 0
        self.items.append((key, order, Problem(self.file, column, row, line, reason)))

    def add_rows(self, rows0: np.ndarray, first_line: int, column: str, order: int, reason_of) -> None:
        """Problems at 0-based data rows ``rows0`` of one column; ``reason_of(k)`` for the k-th."""
        rows0 = np.asarray(rows0)
        self.total += rows0.size
        for k in range(min(rows0.size, MAX_PROBLEMS)):
            r = int(rows0[k])
            self.items.append((first_line + r, order, Problem(self.file, column, r + 1, first_line + r, reason_of(k))))

    def raise_if_any(self) -> None:
        if self.total:
            self.items.sort(key=lambda it: (it[0], it[1]))
            raise TelemetryError([p for _, _, p in self.items[:MAX_PROBLEMS]], self.total)


# --------------------------------------------------------------------------------------------
# data model
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Gap:
    """A time gap: consecutive samples further apart than ``gap_factor`` × the nominal step.

    ``start_s``/``end_s`` are the times of the samples before and after the gap (s),
    ``duration_s = end_s - start_s``, ``row`` is the 1-based data row of the sample after it.
    """

    start_s: float
    end_s: float
    duration_s: float
    row: int


@dataclass(frozen=True, eq=False)
class Telemetry:
    """A validated telemetry file, all values in SI.

    ``time`` is ``(n,)`` seconds; ``channels[name]`` is ``(n,)`` SI values (read-only arrays;
    sparse channels hold NaN where the file had an empty cell); ``units`` holds each channel's
    unit as written in the file and ``kinds`` its quantity kind; ``meta`` the ``# key: value``
    lines; ``saturated[name]`` a boolean ``(n,)`` mask (all False without a threshold); ``gaps``
    the time gaps; ``notes`` warnings about the file that are not errors (e.g. a last line without
    a line end: possibly truncated).  Channel names are the header names without the unit (``'BP.x'``).
    """

    path: Path
    time: np.ndarray
    channels: dict[str, np.ndarray]
    units: dict[str, str]
    kinds: dict[str, str]
    meta: dict[str, str]
    saturated: dict[str, np.ndarray]
    gaps: list[Gap]
    time_name: str = "time"
    time_unit: str = "s"
    sparse: frozenset[str] = field(default_factory=frozenset)
    notes: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def names(self) -> list[str]:
        """Channel names in file order (time excluded)."""
        return list(self.channels)

    def channel(self, name: str) -> np.ndarray:
        """SI values ``(n,)`` of channel ``name``; KeyError listing the channels if absent."""
        try:
            return self.channels[name]
        except KeyError:
            raise KeyError(f"{self.path.name}: no channel {name!r}; channels: {', '.join(self.channels)}") from None

    def stack(self, names: Iterable[str]) -> np.ndarray:
        """Channels side by side: ``(n, k)`` SI array, columns in the order of ``names``."""
        cols = [self.channel(n) for n in names]
        if not cols:
            return np.empty((len(self), 0))
        return np.column_stack(cols)

    def samples(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(time (m,) s, values (m,) SI)`` of the rows where channel ``name`` has a value.

        For a dense channel this is all rows; for a sparse one, the rows with a non-empty cell.
        """
        v = self.channel(name)
        ok = ~np.isnan(v)
        return self.time[ok], v[ok]


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------


def _read_text(path: Path, fname: str) -> str:
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise TelemetryError.single(fname, "file not found") from None
    except OSError as exc:
        raise TelemetryError.single(fname, f"cannot read file: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise TelemetryError.single(
            fname, f"not valid UTF-8 (byte 0x{raw[exc.start]:02x}); save the file as UTF-8", line=line
        ) from None
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    return text


def _preamble(lines: list[str], col: _Collector) -> tuple[dict[str, str], dict[str, int], int]:
    """Parse leading comment lines.  Returns (meta, meta_line_numbers, header_index or -1)."""
    meta: dict[str, str] = {}
    meta_lines: dict[str, int] = {}
    notes: list[str] = []
    for i, raw in enumerate(lines):
        s = raw.strip()
        if not s:
            continue
        if not s.startswith("#"):
            if notes:
                meta.setdefault("notes", "\n".join(notes))
            return meta, meta_lines, i
        body = s[1:].strip()
        if not body:
            continue
        m = _META_RE.match(body)
        if m is None:
            notes.append(body)
            continue
        key, value = m["key"], m["value"].strip()
        if key in meta:
            col.add(f"duplicate metadata key {key!r} (first on line {meta_lines[key]})", line=i + 1)
            continue
        meta[key] = value
        meta_lines[key] = i + 1
    if notes:
        meta.setdefault("notes", "\n".join(notes))
    return meta, meta_lines, -1


@dataclass(frozen=True, eq=False)
class _OpenedCsv:
    """A telemetry-style CSV read up to its header: the text and its lines, the problem
    collector, the ``# key: value`` metadata (and the line of each key) and ``h``, the index of
    the header line in ``lines``."""

    path: Path
    fname: str
    text: str
    lines: list[str]
    col: _Collector
    meta: dict[str, str]
    meta_lines: dict[str, int]
    h: int


def _open_csv(path: str | os.PathLike, expected_header: str) -> _OpenedCsv:
    """Read ``path`` (UTF-8, any newline) and parse its comment preamble.  Raises
    :class:`TelemetryError` (no header row, naming ``expected_header``, an example header line)
    when the file holds comments only.  Shared by :func:`read_telemetry` and :func:`read_events`."""
    path = Path(path)
    fname = str(path)
    text = _read_text(path, fname)
    lines = text.split("\n")
    col = _Collector(fname)
    meta, meta_lines, h = _preamble(lines, col)
    if h < 0:
        col.add(f"no header row (expected {expected_header})")
        col.raise_if_any()
    return _OpenedCsv(path, fname, text, lines, col, meta, meta_lines, h)


def _split_header(line: str) -> list[str]:
    return [c.strip() for c in next(csv.reader([line]))]


def _parse_column(cells: list[str], allow_empty: bool) -> tuple[np.ndarray, np.ndarray | None, list]:
    """Parse one column's cells.  Returns (values, empty_mask or None, [(index, reason)...])."""
    n = len(cells)
    try:
        if allow_empty:
            vals = np.array([float(s) if s.strip() else math.nan for s in cells], dtype=np.float64)
            empty = np.array([not s.strip() for s in cells], dtype=bool) if np.isnan(vals).any() else None
            return vals, empty, []
        return np.fromiter(map(float, cells), dtype=np.float64, count=n), None, []
    except ValueError:
        pass
    # slow path: locate the failing cells
    vals = np.full(n, math.nan)
    empty = np.zeros(n, dtype=bool)
    bad: list[tuple[int, str]] = []
    for i, s in enumerate(cells):
        st = s.strip()
        if not st:
            empty[i] = True
            if not allow_empty:
                bad.append((i, "empty cell (a dropout must be a gap in time, not an empty value)"))
            continue
        try:
            vals[i] = float(st)
        except ValueError:
            bad.append((i, f"cannot parse {st[:40]!r} as a number"))
    return vals, empty, bad


def _foreign_delimiter(header: str) -> str | None:
    """A message when ``header`` is delimited by ';' or a tab instead of commas, else None."""
    if "," in header:
        return None
    for d, what in ((";", "semicolons (';')"), ("\t", "tabs")):
        if header.count(d) >= 1:
            return (
                f"the header is delimited by {what}, not commas: save the file as comma-separated "
                "(CSV with ',' between fields and '.' as the decimal point)"
            )
    return None


def _truncation_notes(fname: str, ends_with_newline: bool, data: list[str], n: int, k: int) -> tuple[str, ...]:
    """A note when the last data row has no line end and its last field is shorter than in the
    row before (a file cut in the middle of a number still parses)."""
    if ends_with_newline or n < 2:
        return ()
    last, prev = data[-1].rsplit(",", 1)[-1].strip(), data[-2].rsplit(",", 1)[-1].strip()
    why = "its last field is shorter than the row before's" if len(last) < len(prev) else "possibly cut short"
    return (
        f"{fname}, row {n}: the file does not end with a line end and {why}: the file looks "
        "truncated; the last row was read as is",
    )


def _fmt(v: float) -> str:
    return f"{v:.9g}"


@dataclass(frozen=True)
class _Header:
    """The parsed header row: raw ``cells``, channel ``names``, canonical ``units`` (None when unknown
    or missing), the units as written (``units_raw``), quantity ``kinds`` and name -> column ``index``."""

    cells: list[str]
    names: list[str]
    units: list[str | None]
    units_raw: list[str]
    kinds: list[str | None]
    index: dict[str, int]

    @property
    def k(self) -> int:
        """Number of columns."""
        return len(self.cells)


def _check_options(
    required: dict[str, str], limits: dict[str, tuple[float, float]], saturation: dict[str, float], gap_factor: float
) -> None:
    """``ValueError`` for a caller's (not the file's) mistake in the options of :func:`read_telemetry`."""
    for name, kind in required.items():
        if kind not in KINDS:
            raise ValueError(f"required[{name!r}] = {kind!r} is not a quantity kind; kinds: {', '.join(KINDS)}")
    for name, lh in limits.items():
        lo, hi = lh
        if not lo <= hi:
            raise ValueError(f"limits[{name!r}] = {lh!r}: lower limit above upper limit")
    for name, thr in saturation.items():
        if not thr > 0:
            raise ValueError(f"saturation[{name!r}] = {thr!r}: threshold must be a positive SI magnitude")
    if gap_factor <= 1.0:
        raise ValueError(f"gap_factor must be > 1, got {gap_factor}")


def _parse_header(line: str, header_line: int, required: dict[str, str], col: _Collector) -> _Header:
    """The header row ``line`` (file line ``header_line``): every ``name [unit]`` cell, its unit
    and kind; a cell without a unit, an unknown unit or a duplicate name is reported to ``col``."""
    delim = _foreign_delimiter(line)
    if delim:
        col.add(delim, line=header_line)
        col.raise_if_any()
    cells = _split_header(line)
    names: list[str] = []
    units: list[str | None] = []
    units_raw: list[str] = []
    kinds: list[str | None] = []
    for j, cell in enumerate(cells):
        m = _HEADER_RE.match(cell)
        if m is None or not m["name"].strip():
            what = "has no '[unit]'" if m is None else "has no name"
            col.add(
                f"{what}; write headers as 'name [unit]' (use '[1]' for dimensionless)",
                column=cell,
                line=header_line,
                order=j,
            )
            names.append(cell)
            units.append(None)
            units_raw.append("")
            kinds.append(None)
            continue
        name, unit_raw = m["name"].strip(), m["unit"].strip()
        names.append(name)
        units_raw.append(unit_raw)
        try:
            cu = canonical_unit(unit_raw)
        except UnitError:
            want = required.get(name) or ("time" if j == 0 else None)
            hint = f"expected {want}: {', '.join(known_units(want))}" if want else f"known units: {', '.join(UNITS)}"
            col.add(f"has unknown unit {unit_raw!r} ({hint})", column=cell, line=header_line, order=j)
            units.append(None)
            kinds.append(None)
            continue
        units.append(cu)
        kinds.append(UNITS[cu].kind)
    index: dict[str, int] = {}
    for j, name in enumerate(names):
        if name in index:
            col.add(
                f"duplicate column name {name!r} (also column {index[name] + 1})",
                column=cells[j],
                line=header_line,
                order=j,
            )
        else:
            index[name] = j
    return _Header(cells, names, units, units_raw, kinds, index)


def _check_columns(
    hd: _Header,
    header_line: int,
    required: dict[str, str],
    options: dict[str, Collection[str]],
    sparse_given: Collection[str],
    meta_lines: dict[str, int],
    col: _Collector,
) -> None:
    """The first column is time; every ``required`` channel is present with its kind; every channel
    named in ``options`` (``{"limits": ..., "saturation": ..., "sparse": ...}``) is a channel of the
    file (``sparse_given``: the caller's sparse names, the others came from the file's metadata)."""
    k = hd.k
    if hd.kinds and hd.kinds[0] not in (None, "time"):
        col.add(
            f"is the first column and must be time (unit s, ms or us), but has unit of {hd.kinds[0]}",
            column=hd.cells[0],
            line=header_line,
            order=0,
        )
    time_name = hd.names[0] if hd.names else "time"
    present = ", ".join(hd.cells)
    for name, kind in required.items():
        if name == time_name:
            continue
        j = hd.index.get(name)
        if j is None:
            col.add(f"missing column {name!r} ({kind}); columns present: {present}", line=header_line, order=k)
        elif hd.kinds[j] is not None and hd.kinds[j] != kind:
            col.add(f"has unit of {hd.kinds[j]}, expected {kind}", column=hd.cells[j], line=header_line, order=j)
    for what, keys in options.items():
        for name in keys:
            if hd.index.get(name, 0) != 0:
                continue
            if name in required and name != time_name:
                continue  # already reported as a missing column: the option is the pipeline's, not the user's
            why = (
                "the time column cannot be declared sparse"
                if what == "sparse" and name == time_name
                else "which is not a channel of this file"
            )
            col.add(
                f"{what} given for {name!r}, {why}; columns present: {present}",
                line=meta_lines.get("sparse") if what == "sparse" and name not in sparse_given else header_line,
                order=k,
            )


def _metadata_dt(meta: dict[str, str], meta_lines: dict[str, int], col: _Collector) -> float | None:
    """The sample interval [s] the metadata's ``rate_hz`` declares (None when absent or invalid)."""
    if "rate_hz" not in meta:
        return None
    try:
        rate = float(meta["rate_hz"])
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError
        return 1.0 / rate
    except ValueError:
        col.add(f"metadata rate_hz {meta['rate_hz']!r} is not a positive number", line=meta_lines["rate_hz"])
        return None


def _split_rows(data: list[str], k: int, first_line: int, ends_with_newline: bool, col: _Collector):
    """The data rows with ``k`` fields: (indices of the good rows (m,), their cells flattened
    row-major); a row with another field count is reported with the likely cause."""
    n = len(data)
    counts = np.fromiter((s.count(",") for s in data), dtype=np.int64, count=n)
    wrong = np.flatnonzero(counts != k - 1)
    if not wrong.size:
        return np.arange(n), ",".join(data).split(",")

    def wrong_reason(i: int) -> str:
        s = data[wrong[i]]
        if not s.strip():
            return "blank row inside the data"
        if s.lstrip().startswith("#"):
            return "comment line inside the data (comments go above the header)"
        if wrong[i] == n - 1 and not ends_with_newline:
            return (
                f"expected {k} fields, found {counts[wrong[i]] + 1}: the last line has no line end — "
                "the file looks truncated"
            )
        return f"expected {k} fields, found {counts[wrong[i]] + 1}"

    col.add_rows(wrong, first_line, None, -1, wrong_reason)  # type: ignore[arg-type]
    good = np.flatnonzero(counts == k - 1)
    return good, (",".join([data[i] for i in good]).split(",") if good.size else [])


def _parse_cells(
    hd: _Header, good: np.ndarray, flat: list[str], sparse_set: set[str], first_line: int, col: _Collector
) -> tuple[np.ndarray, np.ndarray]:
    """Every cell as a number in the file's units: (values (m, k), cell parsed and finite (m, k));
    an unparsable, empty (outside sparse columns) or non-finite cell is reported with its row."""
    k, ng = hd.k, good.size
    raw = np.empty((ng, k))
    cell_ok = np.ones((ng, k), dtype=bool)
    for j in range(k):
        vals, empty, bad = _parse_column(flat[j::k], allow_empty=hd.names[j] in sparse_set and j > 0)
        raw[:, j] = vals
        if bad:
            bi = np.array([b[0] for b in bad])
            cell_ok[bi, j] = False
            col.add_rows(good[bi], first_line, hd.cells[j], j, lambda q, bad=bad: bad[q][1])
        nonfin = ~np.isfinite(vals)
        if empty is not None:
            nonfin &= ~empty
        if bad:
            nonfin[bi] = False
        nf = np.flatnonzero(nonfin)
        if nf.size:
            cell_ok[nf, j] = False
            col.add_rows(
                good[nf],
                first_line,
                hd.cells[j],
                j,
                lambda q, nf=nf, v=vals: "value is NaN" if np.isnan(v[nf[q]]) else f"value is {v[nf[q]]:g}",
            )
    return raw, cell_ok


def _check_time(
    hd: _Header, raw: np.ndarray, cell_ok: np.ndarray, good: np.ndarray, first_line: int, col: _Collector
) -> None:
    """Time strictly increasing over the rows whose time cell parsed; a repeat or a step back is
    reported with the row it repeats or follows."""
    tok = np.flatnonzero(cell_ok[:, 0]) if hd.k else np.empty(0, int)
    if tok.size <= 1:
        return
    tv = raw[tok, 0]
    back = np.flatnonzero(~(np.diff(tv) > 0))
    if not back.size:
        return
    tu = hd.units_raw[0] or "?"

    def time_reason(q: int) -> str:
        b = back[q]
        prev_row = int(good[tok[b]]) + 1
        t_prev, t_here = tv[b], tv[b + 1]
        if t_here == t_prev:
            return f"duplicate time {_fmt(t_here)} {tu}: same as row {prev_row}"
        return f"time goes backwards: {_fmt(t_here)} {tu} after {_fmt(t_prev)} {tu} at row {prev_row}"

    col.add_rows(good[tok[back + 1]], first_line, hd.cells[0], 0, time_reason)


def _check_limits(
    hd: _Header,
    raw: np.ndarray,
    cell_ok: np.ndarray,
    good: np.ndarray,
    limits: dict[str, tuple[float, float]],
    first_line: int,
    col: _Collector,
) -> None:
    """Values outside the caller's ``limits`` (SI) are reported in the file's unit and in SI."""
    for name, (lo, hi) in limits.items():
        j = hd.index.get(name)
        if j is None or j == 0 or hd.units[j] is None:
            continue
        vsi, _ = to_si(raw[:, j], hd.units[j])
        with np.errstate(invalid="ignore"):
            out = np.flatnonzero(cell_ok[:, j] & ((vsi < lo) | (vsi > hi)))
        if out.size:
            si = SI_UNITS[hd.kinds[j]]  # type: ignore[index]

            def lim_reason(q, j=j, out=out, vsi=vsi, lo=lo, hi=hi, si=si):
                r = out[q]
                return (
                    f"value {_fmt(raw[r, j])} {hd.units_raw[j]} (= {_fmt(vsi[r])} {si}) is outside the "
                    f"limits [{_fmt(lo)}, {_fmt(hi)}] {si}"
                )

            col.add_rows(good[out], first_line, hd.cells[j], j, lim_reason)


def _find_gaps(time_s: np.ndarray, nominal: float | None, gap_factor: float) -> list[Gap]:
    """Steps longer than ``gap_factor`` × the nominal interval [s] (the median step when None)."""
    if time_s.size < 2:
        return []
    dt = np.diff(time_s)
    nominal = float(np.median(dt)) if nominal is None else nominal
    return [
        Gap(float(time_s[i]), float(time_s[i + 1]), float(dt[i]), int(i) + 2)
        for i in np.flatnonzero(dt > gap_factor * nominal)
    ]


def read_telemetry(
    path: str | os.PathLike,
    *,
    required: Mapping[str, str] | None = None,
    limits: Mapping[str, tuple[float, float]] | None = None,
    saturation: Mapping[str, float] | None = None,
    sparse: Collection[str] = (),
    nominal_dt: float | None = None,
    gap_factor: float = 3.0,
) -> Telemetry:
    """Read and validate a telemetry CSV; return it in SI.

    ``required`` maps channel name → quantity kind (``{"BP.x": "acceleration"}``): a missing
    channel or a unit of another kind is an error.  ``limits`` maps channel name → ``(lo, hi)``
    in SI: values outside are errors.  ``saturation`` maps channel name → SI magnitude: samples
    with ``|v| >= threshold`` are flagged in ``Telemetry.saturated`` (not an error).  ``sparse``
    names channels whose empty cells are allowed (read as NaN), in addition to those listed in a
    ``# sparse:`` metadata line.  A gap is a step ``dt > gap_factor * nominal``, where nominal
    is ``nominal_dt`` (s), else ``1 / rate_hz`` from the metadata, else the median step.

    Steps: the metadata preamble, the header (:func:`_parse_header`, :func:`_check_columns`), the
    rows (:func:`_split_rows`, :func:`_parse_cells`), time and limits (:func:`_check_time`,
    :func:`_check_limits`), then the SI result with saturation flags and gaps.  Raises
    :class:`TelemetryError` listing every problem found (up to :data:`MAX_PROBLEMS`).  Channel names
    given in ``required``/``limits``/``saturation``/``sparse`` must exist.
    """
    required, limits, saturation = dict(required or {}), dict(limits or {}), dict(saturation or {})
    _check_options(required, limits, saturation, gap_factor)
    src = _open_csv(path, "a line like 'time [s],BP.x [g],...'")
    path, fname, text, lines, col = src.path, src.fname, src.text, src.lines, src.col
    meta, meta_lines, h = src.meta, src.meta_lines, src.h
    header_line = h + 1
    hd = _parse_header(lines[h], header_line, required, col)
    sparse_set = set(sparse)
    if "sparse" in meta:
        sparse_set |= {s.strip() for s in meta["sparse"].split(",") if s.strip()}
    options = {"limits": limits, "saturation": saturation, "sparse": sparse_set}
    _check_columns(hd, header_line, required, options, sparse, meta_lines, col)
    rate_dt = _metadata_dt(meta, meta_lines, col)

    data = lines[h + 1 :]
    ends_with_newline = text.endswith("\n")
    while data and not data[-1].strip():
        data.pop()
    n, k = len(data), hd.k
    first_line = h + 2  # file line of data row 1
    if n == 0:
        col.add("no data rows below the header", line=header_line)
        col.raise_if_any()
    good, flat = _split_rows(data, k, first_line, ends_with_newline, col)
    raw, cell_ok = _parse_cells(hd, good, flat, sparse_set, first_line, col)
    _check_time(hd, raw, cell_ok, good, first_line, col)
    _check_limits(hd, raw, cell_ok, good, limits, first_line, col)
    col.raise_if_any()

    # no problems: every row is good
    time_s, _ = to_si(raw[:, 0], hd.units[0])  # type: ignore[arg-type]
    channels: dict[str, np.ndarray] = {}
    for j in range(1, k):
        v, _ = to_si(raw[:, j], hd.units[j])  # type: ignore[arg-type]
        v.flags.writeable = False
        channels[hd.names[j]] = v
    time_s.flags.writeable = False
    saturated: dict[str, np.ndarray] = {}
    for name, v in channels.items():
        thr = saturation.get(name)
        mask = np.zeros(n, dtype=bool) if thr is None else (np.abs(np.nan_to_num(v)) >= thr)
        mask.flags.writeable = False
        saturated[name] = mask
    return Telemetry(
        path=path,
        time=time_s,
        channels=channels,
        units={hd.names[j]: hd.units_raw[j] for j in range(1, k)},
        kinds={hd.names[j]: hd.kinds[j] for j in range(1, k)},  # type: ignore[misc]
        meta=meta,
        saturated=saturated,
        gaps=_find_gaps(time_s, nominal_dt if nominal_dt is not None else rate_dt, gap_factor),
        time_name=hd.names[0] if hd.names else "time",
        time_unit=hd.units_raw[0],
        sparse=frozenset(sparse_set),
        notes=_truncation_notes(fname, ends_with_newline, data, n, k),
    )


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically: temp file in the same directory, then
    ``os.replace``.  An interrupted write never leaves a partial file under ``path``, and the
    temp file is removed on failure.  Creates missing parent directories.  Returns the path."""

    def write(f) -> None:
        f.write(text.encode("utf-8"))

    return _atomic_write(Path(path), write)


def atomic_write_npz(path: str | os.PathLike, arrays: Mapping[str, object], *, compress: bool = True) -> Path:
    """Write ``arrays`` {name: array-like} as a ``.npz`` archive (what ``np.load`` reads), atomically
    as :func:`atomic_write_text`. ``compress``: deflate at level 1 (``np.savez_compressed`` uses 6:
    within 1 % of its size on the workbench's float histories at about 0.65 of its CPU); False:
    stored, as ``np.savez``. Object arrays are refused (no pickles). Returns the path."""
    import zipfile

    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED

    def write(f) -> None:
        with zipfile.ZipFile(f, "w", compression=method, compresslevel=1 if compress else None, allowZip64=True) as z:
            for name, value in arrays.items():
                with z.open(f"{name}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)

    return _atomic_write(Path(path), write)


def _atomic_write(path: Path, write) -> Path:
    """``write(f)`` into a temp file (binary) beside ``path``, fsync, then ``os.replace`` onto it; the
    temp file removed on any failure, an ``OSError`` without a file name given ``path``'s."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as err:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(err, OSError) and err.filename is None:  # e.g. ENOSPC from write/fsync: say where
            raise OSError(err.errno, err.strerror or str(err), str(path)) from err
        raise
    return path


def _meta_lines(path: Path, meta: Mapping[str, object] | None) -> list[str]:
    out = []
    for key, value in (meta or {}).items():
        if not _META_RE.match(f"{key}: x") or key == "notes":
            if key == "notes":
                out.extend(f"# {ln}" if ln.strip() else "#" for ln in str(value).split("\n"))
                continue
            raise ValueError(f"cannot write {path}: metadata key {key!r} must be a plain identifier")
        sval = str(value)
        if "\n" in sval or "\r" in sval:
            raise ValueError(f"cannot write {path}: metadata {key!r} contains a line break")
        out.append(f"# {key}: {sval}")
    return out


def _check_name(path: Path, name: str) -> None:
    if not isinstance(name, str) or not name.strip() or name != name.strip() or _BAD_NAME_CHARS & set(name):
        raise ValueError(
            f"cannot write {path}: channel name {name!r} must be non-empty, without surrounding "
            'spaces, and contain none of , [ ] " or line breaks'
        )


def write_telemetry(
    path: str | os.PathLike,
    time_s,
    channels: Mapping[str, tuple[np.ndarray, str]],
    meta: Mapping[str, object] | None = None,
    float_format: str = "%.9g",
    *,
    sparse: Collection[str] = (),
    time_name: str = "time",
    time_unit: str = "s",
) -> Path:
    """Write a telemetry CSV that :func:`read_telemetry` reads back.

    ``time_s`` is ``(n,)`` seconds, strictly increasing; ``channels`` maps name →
    ``(values_si (n,), unit)``: values are given in SI and written in ``unit``.  ``meta`` becomes
    ``# key: value`` lines.  NaN/inf values are refused (ValueError naming the channel and index)
    except in channels listed in ``sparse``, where NaN is written as an empty cell and the
    channel is declared in a ``# sparse:`` line.  Written atomically; returns the path.
    """
    path = Path(path)
    t = np.asarray(time_s, dtype=np.float64)
    if t.ndim != 1 or t.size == 0:
        raise ValueError(f"cannot write {path}: time must be a non-empty 1-D array, got shape {t.shape}")
    n = t.size
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ValueError(f"cannot write {path}: time has {t[bad[0]]} at index {bad[0]}")
    back = np.flatnonzero(~(np.diff(t) > 0))
    if back.size:
        i = back[0] + 1
        raise ValueError(
            f"cannot write {path}: time must be strictly increasing; index {i} ({_fmt(t[i])} s) "
            f"follows {_fmt(t[i - 1])} s"
        )
    _check_name(path, time_name)
    tu = canonical_unit(time_unit)
    if UNITS[tu].kind != "time":
        raise ValueError(f"cannot write {path}: time_unit {time_unit!r} is not a unit of time")
    sparse = set(sparse)
    unknown = sparse - set(channels)
    if unknown:
        raise ValueError(f"cannot write {path}: sparse channels {sorted(unknown)} are not in channels")
    try:
        float_format % 1.0
    except (TypeError, ValueError):
        raise ValueError(f"float_format {float_format!r} is not a %-format for one float") from None

    headers = [f"{time_name} [{tu}]"]
    cols = [from_si(t, tu)]
    for name, spec in channels.items():
        _check_name(path, name)
        if name == time_name:
            raise ValueError(f"cannot write {path}: channel {name!r} has the name of the time column")
        values, unit = spec
        v = np.asarray(values, dtype=np.float64)
        if v.shape != (n,):
            raise ValueError(f"cannot write {path}: channel {name!r} has shape {v.shape}, time has ({n},)")
        cu = canonical_unit(unit)
        nonfin = ~np.isfinite(v)
        if name in sparse:
            nonfin &= ~np.isnan(v)
        bad = np.flatnonzero(nonfin)
        if bad.size:
            i = int(bad[0])
            more = f" (and {bad.size - 1} more)" if bad.size > 1 else ""
            raise ValueError(
                f"cannot write {path}: channel {name!r} has {v[i]} at index {i} (time {_fmt(t[i])} s){more}; "
                "a dropout must be a gap in time, or declare the channel sparse"
            )
        headers.append(f"{name} [{cu}]")
        cols.append(from_si(v, cu))

    meta = dict(meta or {})
    if sparse:
        declared = {s.strip() for s in str(meta.get("sparse", "")).split(",") if s.strip()}
        meta["sparse"] = ", ".join([c for c in channels if c in sparse | declared])
    out = _meta_lines(path, meta)
    out.append(",".join(headers))
    arr = np.column_stack(cols)
    if not sparse:
        row_fmt = ",".join([float_format] * arr.shape[1])
        out.extend(row_fmt % tuple(r) for r in arr.tolist())
    else:
        scols = [["" if math.isnan(x) else float_format % x for x in c.tolist()] for c in arr.T]
        out.extend(",".join(r) for r in zip(*scols, strict=True))
    return atomic_write_text(path, "\n".join(out) + "\n")


# --------------------------------------------------------------------------------------------
# events
# --------------------------------------------------------------------------------------------


def read_events(path: str | os.PathLike) -> list[tuple[float, str]]:
    """Read an events CSV (header ``time [s],event``) → list of ``(time_s, label)``.

    Times may use any time unit and are returned in seconds; they must be finite and
    non-decreasing (several events may share a time).  Labels must be non-empty; a label with a
    comma is written in double quotes.  ``# key: value`` lines above the header are allowed.
    Raises :class:`TelemetryError` with every problem located.
    """
    src = _open_csv(path, "'time [s],event'")
    lines, col, h = src.lines, src.col, src.h
    cells = _split_header(lines[h])
    unit = None
    delim = _foreign_delimiter(lines[h])
    if delim:
        col.add(delim, line=h + 1)
        col.raise_if_any()
    if len(cells) != 2 or cells[1] != "event":
        col.add(f"header must be 'time [s],event', found {lines[h].strip()!r}", line=h + 1)
    else:
        m = _HEADER_RE.match(cells[0])
        try:
            if m is None:
                raise UnitError("")
            unit = canonical_unit(m["unit"])
            if UNITS[unit].kind != "time":
                raise UnitError(unit)
        except UnitError:
            unit = None
            col.add(
                f"must be time with a unit of time ({', '.join(known_units('time'))})",
                column=cells[0],
                line=h + 1,
                order=0,
            )
    tcol = cells[0] if cells else "time"
    data = lines[h + 1 :]
    while data and not data[-1].strip():
        data.pop()
    events: list[tuple[float, str]] = []
    prev: tuple[float, int] | None = None
    for i, row in enumerate(csv.reader(data)):
        line, rown = h + 2 + i, i + 1
        if not row or not "".join(row).strip():
            col.add("blank row inside the data", row=rown, line=line)
            continue
        if row[0].lstrip().startswith("#"):
            col.add("comment line inside the data (comments go above the header)", row=rown, line=line)
            continue
        if len(row) != 2:
            col.add(f"expected 2 fields, found {len(row)}", row=rown, line=line)
            continue
        ts, label = row[0].strip(), row[1].strip()
        t = None
        try:
            t = float(ts)
            if not math.isfinite(t):
                col.add(f"value is {ts}", column=tcol, row=rown, line=line, order=0)
                t = None
        except ValueError:
            col.add(
                "empty cell" if not ts else f"cannot parse {ts[:40]!r} as a number",
                column=tcol,
                row=rown,
                line=line,
                order=0,
            )
        if not label:
            col.add("empty event label", column="event", row=rown, line=line, order=1)
        if t is not None:
            if prev is not None and t < prev[0]:
                col.add(
                    f"time goes backwards: {_fmt(t)} after {_fmt(prev[0])} at row {prev[1]}",
                    column=tcol,
                    row=rown,
                    line=line,
                    order=0,
                )
            prev = (t, rown)
            if label and unit is not None:
                events.append((float(to_si(t, unit)[0]), label))
    col.raise_if_any()
    return events


def write_events(
    path: str | os.PathLike, events: Iterable[tuple[float, str]], meta: Mapping[str, object] | None = None
) -> Path:
    """Write an events CSV (``time [s],event``) atomically; times in seconds, non-decreasing.

    Refuses non-finite times, decreasing times, and empty or multi-line labels (ValueError).
    """
    path = Path(path)
    buf = io.StringIO()
    for line in _meta_lines(path, meta):
        buf.write(line + "\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["time [s]", "event"])
    prev = -math.inf
    for i, (t, label) in enumerate(events):
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f"cannot write {path}: event {i} ({label!r}) has time {t}")
        if t < prev:
            raise ValueError(f"cannot write {path}: event {i} ({label!r}) at {t!r} s is before {prev!r} s")
        if not isinstance(label, str) or not label.strip() or "\n" in label or "\r" in label:
            raise ValueError(f"cannot write {path}: event {i} label {label!r} must be a non-empty single line")
        short = f"{t:.9g}"
        w.writerow([short if float(short) == t else repr(t), label.strip()])
        prev = t
    return atomic_write_text(path, buf.getvalue())
