"""Run outputs: the JSON summary (scorecard) and CSV exports of reconstructed histories.

``recordings/<name>.summary.json`` holds the key numbers of a run (docs/ARCHITECTURE.md, "Outputs").
:func:`to_jsonable` turns numpy values, dataclasses and paths into plain JSON types; JSON has
no NaN or infinity, so NaN becomes ``null`` and ±inf the strings ``"inf"``/``"-inf"``.
CSV exports use the telemetry format (:func:`workbench.io.telemetry.write_telemetry`), so an
export reads back with :func:`~workbench.io.telemetry.read_telemetry`.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import enum
import json
import math
import os
from collections.abc import Collection, Mapping
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from workbench.io.telemetry import atomic_write_text, write_telemetry

__all__ = ["OutputError", "export_csv", "read_summary", "to_jsonable", "write_summary"]


class OutputError(OSError):
    """An output location cannot be written: read-only, missing (a path component is a file) or
    full.  The message names the path and the operating system's reason; ``workbench`` exits 73
    (``EX_CANTCREAT`` of sysexits.h) with it, no traceback."""

    @classmethod
    def wrap(cls, err: OSError, path: str | os.PathLike | None = None, what: str = "cannot write") -> OutputError:
        """An :class:`OutputError` for the ``OSError`` ``err`` at ``path`` (default: the error's own
        file name), keeping its ``errno``."""
        where = path if path is not None else (err.filename or "the output folder")
        reason = err.strerror or str(err)
        out = cls(f"{what} {where}: {reason}")
        out.errno = err.errno
        return out


def _float(x: float) -> float | str | None:
    if math.isnan(x):
        return None
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return x


def to_jsonable(obj: Any, _where: str = "summary") -> Any:
    """Convert ``obj`` to JSON-ready Python types, recursively.

    numpy scalars → int/float/bool; arrays → nested lists; dataclasses → dicts of their fields;
    ``Path`` → str; tuples/sets → lists; mapping keys → str; datetimes → ISO strings; enums →
    their value; NaN → None, ±inf → "inf"/"-inf".  Anything else raises TypeError naming where
    in the structure it sits (e.g. ``summary['stroke']['sigma']``).
    """
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return _float(float(obj))
    if isinstance(obj, np.generic):
        if isinstance(obj, np.bool_):
            return bool(obj)
        if isinstance(obj, np.integer):
            return int(obj)
        if isinstance(obj, np.floating):
            return _float(float(obj))
        if isinstance(obj, np.str_):
            return str(obj)
        raise TypeError(f"{_where}: cannot convert numpy {obj.dtype} value {obj!r} to JSON")
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in "biuf":
            if obj.dtype.kind == "f" and not np.isfinite(obj).all():
                return to_jsonable(obj.tolist(), _where)
            return obj.tolist()
        if obj.dtype.kind == "U":
            return obj.tolist()
        raise TypeError(f"{_where}: cannot convert array of dtype {obj.dtype} to JSON")
    if isinstance(obj, PurePath):
        return str(obj)
    if isinstance(obj, enum.Enum):
        return to_jsonable(obj.value, _where)
    if isinstance(obj, _dt.datetime | _dt.date | _dt.time):
        return obj.isoformat()
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name), f"{_where}.{f.name}") for f in dataclasses.fields(obj)}
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v, f"{_where}[{k!r}]") for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v, f"{_where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, set | frozenset):
        items = [to_jsonable(v, f"{_where}[{i}]") for i, v in enumerate(obj)]
        try:
            return sorted(items)
        except TypeError:
            return items
    raise TypeError(f"{_where}: cannot convert {type(obj).__name__} {obj!r:.80} to JSON")


def write_summary(path: str | os.PathLike, summary: Mapping[str, Any]) -> Path:
    """Write ``summary`` as JSON (indent 2, keys in insertion order) atomically; returns the path."""
    text = json.dumps(to_jsonable(summary), indent=2, sort_keys=False, allow_nan=False, ensure_ascii=False)
    return atomic_write_text(path, text + "\n")


def read_summary(path: str | os.PathLike) -> dict[str, Any]:
    """Read a summary JSON written by :func:`write_summary` (NaN reads back as None).

    Raises ValueError naming the file (and line/column for invalid JSON) or FileNotFoundError.
    """
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}, line {exc.lineno} column {exc.colno}: invalid JSON: {exc.msg}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a summary must be a JSON object, got {type(data).__name__}")
    return data


def export_csv(
    path: str | os.PathLike,
    time_s,
    columns: Mapping[str, tuple[np.ndarray, str]],
    meta: Mapping[str, object] | None = None,
    *,
    sparse: Collection[str] = (),
    float_format: str = "%.12g",
) -> Path:
    """Export histories as a telemetry-format CSV (readable by ``read_telemetry``).

    ``time_s`` is ``(n,)`` seconds; ``columns`` maps name → ``(values_si (n,), unit)``, e.g.
    ``{"alt": (alt_m, "km"), "sigma_alt": (s_m, "m")}``.  NaN is refused unless the column is
    listed in ``sparse``.  Twelve significant digits by default.  Written atomically.
    """
    return write_telemetry(path, time_s, columns, meta=meta, float_format=float_format, sparse=sparse)
