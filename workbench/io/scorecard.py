"""Numbers for people: the one formatter every scorecard, event line and ``inspect`` output uses.

A scorecard is read, not parsed, so a number in it carries its unit and no more digits than the
reconstruction can justify: :func:`num` prints at most ``digits`` (default 4) significant digits,
switches to ``1.2e-05`` notation only outside ``[1e-3, 1e6)``, and prints an undefined value
(``None``, NaN, ±inf) as words (``"not defined"`` or the reason the caller gives, e.g.
``"not defined: no rebound"``), never ``nan``.  :func:`fields` turns a (nested) summary dict into
``name value unit`` items, reading the unit from the key's suffix (``_m``, ``_mps``, ``_deg`` ...),
so no raw ``{'key': 0.0704793…}`` reaches a reader.

Units here are display strings only; values are whatever the caller passes (SI in the workbench,
a caller converting to cm or % says so with ``unit``/``scale``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from numbers import Integral, Real
from typing import Any

__all__ = ["UNDEFINED", "SUFFIX_UNITS", "num", "signed", "pct", "fields", "is_defined"]

UNDEFINED = "not defined"
"""Text printed for a value that does not exist (NaN, None, inf)."""

#: key suffix -> (display unit, multiplier applied before printing); longest suffix wins.
SUFFIX_UNITS: dict[str, tuple[str, float]] = {
    "_m": ("m", 1.0),
    "_km": ("km", 1.0),
    "_cm": ("cm", 1.0),
    "_s": ("s", 1.0),
    "_ms": ("ms", 1.0),
    "_mps": ("m/s", 1.0),
    "_mps2": ("m/s²", 1.0),
    "_deg": ("deg", 1.0),
    "_rad": ("rad", 1.0),
    "_dps": ("deg/s", 1.0),
    "_K": ("K", 1.0),
    "_Pa": ("Pa", 1.0),
    "_pa": ("Pa", 1.0),
    "_kgm3": ("kg/m³", 1.0),
    "_hz": ("Hz", 1.0),
    "_Hz": ("Hz", 1.0),
    "_g": ("g", 1.0),
    "_pct": ("%", 1.0),
    "_rel": ("%", 100.0),
    "_fraction": ("%", 100.0),
}


def is_defined(x: Any) -> bool:
    """True for a finite real number (or a bool / int); False for None, NaN and ±inf."""
    if x is None:
        return False
    if isinstance(x, bool | Integral):
        return True
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def num(
    x: Any,
    unit: str = "",
    *,
    digits: int = 4,
    scale: float = 1.0,
    undefined: str = UNDEFINED,
    sign: bool = False,
) -> str:
    """``x * scale`` with at most ``digits`` significant digits and ``unit`` after a space.

    Integers print exactly (``2791``); floats with ``digits`` significant digits and no trailing
    zeros beyond them (``0.07048``, ``4.42``, ``1235``, ``123500``), in ``e`` notation only when
    ``|x| < 1e-3`` or ``|x| >= 1e6``; ``sign`` forces a leading ``+`` (errors).  An undefined value
    (None, NaN, ±inf) prints ``undefined`` — pass the reason, e.g. ``"not defined: no rebound"``.
    """
    if not is_defined(x):
        return undefined
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, Integral) and scale == 1.0:
        s = f"{int(x):+d}" if sign else f"{int(x):d}"
    else:
        v = float(x) * scale
        a = abs(v)
        p = "+" if sign else ""
        if a == 0.0:
            s = "0"
        elif a < 1e-3 or a >= 1e6:
            mant, exp = f"{v:{p}.{max(digits - 1, 0)}e}".split("e")
            s = (mant.rstrip("0").rstrip(".") if "." in mant else mant) + "e" + exp
        else:
            mag = math.floor(math.log10(a))
            if mag >= digits:  # 123456.7 -> 123500: the digits beyond `digits` are not meaningful
                s = f"{round(v, digits - 1 - mag):{p}.0f}"
            else:
                s = f"{v:{p}.{max(digits - 1 - mag, 0)}f}"
                if "." in s:
                    s = s.rstrip("0").rstrip(".")
    return f"{s} {unit}" if unit else s


def signed(x: Any, unit: str = "", **kw: Any) -> str:
    """:func:`num` with a leading sign (an error or a difference)."""
    return num(x, unit, sign=True, **kw)


def pct(fraction: Any, *, digits: int = 3, undefined: str = UNDEFINED, sign: bool = False) -> str:
    """A fraction (0.071) as a percentage (``"7.1 %"``) with ``digits`` significant digits."""
    return num(fraction, "%", digits=digits, scale=100.0, undefined=undefined, sign=sign)


def _split_unit(key: str) -> tuple[str, str, float]:
    """(readable name, unit, scale) of a summary key from its suffix (``max_error_mps`` ->
    ``("max error", "m/s", 1)``); no recognised suffix: (name, "", 1)."""
    best = ""
    for suf in SUFFIX_UNITS:
        if key.endswith(suf) and len(suf) > len(best) and len(key) > len(suf):
            best = suf
    unit, scale = SUFFIX_UNITS.get(best, ("", 1.0))
    name = key[: len(key) - len(best)] if best else key
    if not best and key.startswith("fraction_"):
        unit, scale = "%", 100.0
    return name.replace("_", " "), unit, scale


def _value(key: str, v: Any, digits: int) -> str:
    _, unit, scale = _split_unit(key)
    if v is None or isinstance(v, bool | Real):
        return num(v, unit, scale=scale, digits=digits)
    if isinstance(v, str):
        return v
    if isinstance(v, Mapping):
        return "(" + ", ".join(fields(v, digits=digits)) + ")"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(key, x, digits) for x in v) + "]"
    return str(v)


def fields(d: Mapping[str, Any], *, digits: int = 4, skip: tuple[str, ...] = ()) -> list[str]:
    """``"name value unit"`` items of a (nested) summary dict, for a scorecard line or table cell.

    The unit and scale come from the key's suffix (:data:`SUFFIX_UNITS`: ``_m`` metres, ``_rel``
    and ``_fraction`` printed as %, ...); booleans print yes/no, undefined numbers
    :data:`UNDEFINED`, nested dicts in parentheses, lists in brackets. Keys in ``skip`` are left out.
    A ``|`` inside an item is escaped, so an item can go into a markdown table cell.
    """
    out = []
    for k, v in d.items():
        if k in skip:
            continue
        name, _, _ = _split_unit(str(k))
        out.append(f"{name} {_value(str(k), v, digits)}".replace("|", "\\|"))
    return out
