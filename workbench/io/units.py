"""Units at the I/O edge: a table of unit strings by quantity kind, and conversion to/from SI.

Everything inside the workbench is SI (m, s, kg, rad, Pa, K, T).  Files may declare any unit in
:data:`UNITS`; readers call :func:`to_si` once, writers call :func:`from_si` once, and nothing in
between ever sees a degree or a g.

A unit maps to ``(kind, factor, offset)`` with ``si = value * factor + offset``.  Only
temperature has a non-zero offset (``degC``).  Standard gravity is 9.80665 m/s^2 exactly
(CGPM 1901); ``psi`` and ``torr`` use their exact SI definitions (NIST SP 811, App. B.8).

Unit strings are case-sensitive (``mbar`` is not ``Mbar``).  A few typographic spellings are
accepted as aliases of the canonical ASCII names (``µs`` → ``us``, ``°`` → ``deg``,
``m/s²`` → ``m/s^2``); files written by the workbench always use the canonical names.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from workbench.core.bodies import G0

__all__ = [
    "KINDS",
    "SI_UNITS",
    "UNITS",
    "Unit",
    "UnitError",
    "canonical_unit",
    "from_si",
    "known_units",
    "likely_unit",
    "to_si",
    "unit_kind",
]

_LBF_PER_IN2 = 4.4482216152605 / 0.0254**2  # Pa in one psi
_FT = 0.3048  # m, exact


class Unit(NamedTuple):
    """One entry of the unit table: ``si = value * factor + offset``."""

    kind: str
    factor: float
    offset: float = 0.0


UNITS: dict[str, Unit] = {
    # time
    "s": Unit("time", 1.0),
    "ms": Unit("time", 1e-3),
    "us": Unit("time", 1e-6),
    # length
    "m": Unit("length", 1.0),
    "km": Unit("length", 1e3),
    "cm": Unit("length", 1e-2),
    "mm": Unit("length", 1e-3),
    "ft": Unit("length", _FT),
    # velocity
    "m/s": Unit("velocity", 1.0),
    "km/s": Unit("velocity", 1e3),
    "km/h": Unit("velocity", 1e3 / 3600.0),
    "ft/s": Unit("velocity", _FT),
    # acceleration
    "m/s^2": Unit("acceleration", 1.0),
    "g": Unit("acceleration", G0),
    # angle
    "rad": Unit("angle", 1.0),
    "deg": Unit("angle", np.pi / 180.0),
    # angular rate
    "rad/s": Unit("angular_rate", 1.0),
    "deg/s": Unit("angular_rate", np.pi / 180.0),
    # angular acceleration
    "rad/s^2": Unit("angular_acceleration", 1.0),
    "deg/s^2": Unit("angular_acceleration", np.pi / 180.0),
    # pressure
    "Pa": Unit("pressure", 1.0),
    "kPa": Unit("pressure", 1e3),
    "hPa": Unit("pressure", 1e2),
    "bar": Unit("pressure", 1e5),
    "mbar": Unit("pressure", 1e2),
    "psi": Unit("pressure", _LBF_PER_IN2),
    "torr": Unit("pressure", 101325.0 / 760.0),
    # temperature
    "K": Unit("temperature", 1.0),
    "degC": Unit("temperature", 1.0, 273.15),
    # density, mass
    "kg/m^3": Unit("density", 1.0),
    "kg": Unit("mass", 1.0),
    "m^2": Unit("area", 1.0),
    "cm^2": Unit("area", 1e-4),
    "ft^2": Unit("area", _FT**2),
    # dimensionless
    "1": Unit("dimensionless", 1.0),
    "-": Unit("dimensionless", 1.0),
    # magnetic flux density
    "T": Unit("magnetic", 1.0),
    "uT": Unit("magnetic", 1e-6),
    "nT": Unit("magnetic", 1e-9),
    "gauss": Unit("magnetic", 1e-4),
    # counts (samples, flags, bit counts): stored as float, factor 1
    "count": Unit("count", 1.0),
}

#: Typographic spellings accepted on input, mapped to the canonical name.
ALIASES: dict[str, str] = {
    "µs": "us",  # micro sign U+00B5
    "μs": "us",  # greek mu U+03BC
    "µT": "uT",
    "μT": "uT",
    "m/s2": "m/s^2",
    "m/s²": "m/s^2",
    "rad/s2": "rad/s^2",
    "rad/s²": "rad/s^2",
    "deg/s2": "deg/s^2",
    "deg/s²": "deg/s^2",
    "°": "deg",
    "°/s": "deg/s",
    "°/s^2": "deg/s^2",
    "°C": "degC",
    "kg/m3": "kg/m^3",
    "kg/m³": "kg/m^3",
    "m2": "m^2",
    "m²": "m^2",
    "cm2": "cm^2",
    "cm²": "cm^2",
    "ft2": "ft^2",
    "ft²": "ft^2",
}

#: Quantity kinds, in table order.
KINDS: tuple[str, ...] = tuple(dict.fromkeys(u.kind for u in UNITS.values()))

#: The SI unit of each kind (the unit of values inside the workbench).
SI_UNITS: dict[str, str] = {k: next(n for n, u in UNITS.items() if u.kind == k) for k in KINDS}


class UnitError(ValueError):
    """An unknown unit string, or a unit of the wrong kind.

    Attributes: ``unit`` (the offending string) and ``known`` (list of canonical unit names).
    """

    def __init__(self, unit: str, message: str | None = None):
        self.unit = unit
        self.known = list(UNITS)
        if message is None:
            message = f"unknown unit {unit!r}; known units: {_known_text()}"
        super().__init__(message)

    def __reduce__(self):
        return (type(self), (self.unit, str(self)))


def _known_text() -> str:
    groups = {k: [n for n, u in UNITS.items() if u.kind == k] for k in KINDS}
    return "; ".join(f"{k}: {', '.join(names)}" for k, names in groups.items())


def known_units(kind: str | None = None) -> list[str]:
    """Canonical unit names, all of them or those of one quantity ``kind``."""
    if kind is not None and kind not in KINDS:
        raise ValueError(f"unknown quantity kind {kind!r}; known kinds: {', '.join(KINDS)}")
    return [n for n, u in UNITS.items() if kind is None or u.kind == kind]


def canonical_unit(unit: str) -> str:
    """The canonical spelling of ``unit`` (strips spaces, resolves aliases); UnitError if unknown."""
    if not isinstance(unit, str):
        raise UnitError(repr(unit), f"unit must be a string, got {type(unit).__name__}")
    u = unit.strip()
    u = ALIASES.get(u, u)
    if u not in UNITS:
        raise UnitError(unit)
    return u


def unit_kind(unit: str) -> str:
    """Quantity kind of ``unit`` (e.g. ``"g"`` → ``"acceleration"``); UnitError if unknown."""
    return UNITS[canonical_unit(unit)].kind


def to_si(values, unit: str):
    """Convert ``values`` (scalar or array, any shape) from ``unit`` to SI.

    Returns ``(values_si, kind)``: a float64 array of the same shape (a numpy float for scalar
    input) and the quantity kind of the unit.
    """
    u = UNITS[canonical_unit(unit)]
    v = np.asarray(values, dtype=np.float64)
    out = v * u.factor + u.offset if (u.factor != 1.0 or u.offset != 0.0) else v.copy()
    return (out[()] if out.ndim == 0 else out), u.kind


def from_si(values_si, unit: str):
    """Convert SI ``values_si`` (scalar or array) to ``unit``; inverse of :func:`to_si`."""
    u = UNITS[canonical_unit(unit)]
    v = np.asarray(values_si, dtype=np.float64)
    out = (v - u.offset) / u.factor if (u.factor != 1.0 or u.offset != 0.0) else v.copy()
    return out[()] if out.ndim == 0 else out


def likely_unit(ratio: float, declared: str, *, rtol: float = 0.15) -> str | None:
    """The unit the values were probably written in, when a physics check finds them ``ratio``
    (measured / expected, both SI) times off and ``ratio`` is within ``rtol`` (relative) of the
    factor between the ``declared`` unit and another unit of the same kind (g ↔ m/s² 9.81,
    km ↔ m 1000, deg ↔ rad 57.3, ft ↔ m 3.28, s ↔ ms 1000 ...).  None when no unit explains it.

    Example: a triad declared ``[m/s^2]`` whose hanging specific force reads 1/9.81 of g gives
    ``"g"``.
    """
    try:
        cu = canonical_unit(declared)
    except UnitError:
        return None
    ratio = float(ratio)
    if not (np.isfinite(ratio) and ratio > 0):
        return None
    u0 = UNITS[cu]
    best, err = None, np.log1p(rtol)
    for name, u in UNITS.items():
        if u.kind != u0.kind or name == cu or u.offset or u0.offset:
            continue
        # values meant in `name` but read as `cu`: SI values scale by u0.factor / u.factor
        e = abs(np.log(ratio / (u0.factor / u.factor)))
        if e < err and abs(np.log(u0.factor / u.factor)) > np.log(1.5):
            best, err = name, e
    return best
