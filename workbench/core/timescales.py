"""Time scales: UTC -> TAI -> TT -> TDB with the IERS leap-second table, through ERFA (``pyerfa``).

Every conversion here is done by ERFA (the open-source twin of the IAU SOFA library), so the
leap-second table and the TDB − TT series are the maintained ones rather than constants copied
into this repository:

* **UTC -> TAI**: ``erfa.utctai``, TAI − UTC from ERFA's built-in leap-second table
  (``erfa.dat``; e.g. 36 s from 2015-07-01, 37 s from 2017-01-01).  A UTC calendar time is first
  turned into ERFA's two-part *quasi* Julian date with ``erfa.dtf2d("UTC", ...)``, which knows
  that a day ending in a leap second has 86401 s (so ``23:59:60.5`` is valid on such days only).
* **TAI -> TT**: ``erfa.taitt``, TT = TAI + 32.184 s exactly (:data:`TT_MINUS_TAI`).
* **TT -> TDB**: ``erfa.tttdb`` with TDB − TT from ``erfa.dtdb`` (Fairhead & Bretagnon 1990
  series, ~1.7 ms amplitude) evaluated at the geocentre (``u = v = 0``).  For an event at another
  planet tagged in UTC this is the usual convention (SPICE's ``str2et`` does the same): the UTC
  tag is read as an Earth time and TDB is the barycentric coordinate time of that instant.

Julian dates come in two forms:

* a **two-part** Julian date ``(jd1, jd2)`` (ERFA style, ``jd1 + jd2`` is the date; ``jd1`` holds
  the day, ``jd2`` the fraction) where sub-microsecond precision matters (a single float64 JD
  near 2.46e6 resolves only ~40 µs);
* a **single float** JD [days] for everything else (planet rotation models: 40 µs of Mars
  rotation is 2e-7°).

Before 1960-01-01 UTC is not defined (a :class:`ValueError`); dates more than a few years past the end of
the leap-second table ERFA knows draw an ``erfa.ErfaWarning`` ("dubious year") and use the last
known TAI − UTC.
"""

from __future__ import annotations

import re
import warnings

import erfa
import numpy as np

__all__ = [
    "TT_MINUS_TAI",
    "SECONDS_PER_DAY",
    "parse_utc_iso",
    "jd_utc_from_iso",
    "tai_minus_utc",
    "jd_tai_from_utc",
    "jd_tt_from_utc",
    "tdb_minus_tt",
    "jd_tdb_from_utc",
    "julian_date_from_utc",
    "julian_date_utc",
    "utc_iso_from_jd_tdb",
]

TT_MINUS_TAI = 32.184
"""TT − TAI [s], exact by definition (IAU 1991 Resolution A4)."""
SECONDS_PER_DAY = 86400.0

_ISO_RE = re.compile(
    r"^\s*(\d{4})-(\d{2})-(\d{2})[T ](\d{2}):(\d{2}):(\d{2}(?:\.\d*)?)\s*(Z|[+-]00:?00|UTC)?\s*$",
    re.IGNORECASE,
)


def parse_utc_iso(iso: str) -> tuple[int, int, int, int, int, float]:
    """Split a UTC ISO-8601 string ``YYYY-MM-DDTHH:MM:SS[.fff][Z]`` into its calendar fields.

    Returns ``(year, month, day, hour, minute, second)`` (second a float [s]).  A space may replace
    the ``T``; the suffix may be ``Z``, ``+00:00`` or ``UTC`` or absent; fractional seconds of any
    length are accepted.  Anything else (a date alone, another time zone) is a :class:`ValueError`
    naming the string.  Ranges are checked by :func:`jd_utc_from_iso`.
    """
    m = _ISO_RE.match(iso) if isinstance(iso, str) else None
    if m is None:
        raise ValueError(f"not a UTC ISO-8601 time 'YYYY-MM-DDTHH:MM:SS[.fff]Z': {iso!r}")
    year, month, day, hour, minute = (int(m.group(i)) for i in range(1, 6))
    return year, month, day, hour, minute, float(m.group(6))


def _erfa(func, iso: str, *args):
    """Call an ERFA function; its errors and its 'not a valid time' warnings become ValueError."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", erfa.ErfaWarning)
        try:
            out = func(*args)
        except erfa.ErfaError as exc:
            raise ValueError(f"invalid UTC time {iso!r}: {exc}") from None
    for w in caught:
        text = str(w.message)
        if "dubious year" in text:  # past the known leap-second table: keep ERFA's warning
            warnings.warn(f"{iso!r}: {text}", erfa.ErfaWarning, stacklevel=3)
        else:  # e.g. "time is after end of day": second 60 on a day without a leap second
            raise ValueError(f"invalid UTC time {iso!r}: {text}")
    return out


def jd_utc_from_iso(iso: str) -> tuple[float, float]:
    """Two-part quasi Julian date in UTC ``(jd1, jd2)`` [days] of a UTC ISO-8601 string.

    ERFA's convention (``erfa.dtf2d("UTC", ...)``): during a day that ends in a leap second the
    fraction ``jd2`` advances by 1/86401 per second, so ``23:59:60.5`` is accepted on such days
    only.  Bad strings, bad calendar dates, hours ≥ 24, minutes ≥ 60, seconds ≥ 60 on a day
    without a leap second and dates before 1960 raise :class:`ValueError`.
    """
    year, month, day, hour, minute, second = parse_utc_iso(iso)
    if not (0 <= hour < 24 and 0 <= minute < 60 and 0.0 <= second < 61.0):
        raise ValueError(f"time of day out of range in {iso!r}")
    if year < 1960:
        raise ValueError(f"UTC is not defined before 1960 (leap-second era): {iso!r}")
    jd1, jd2 = _erfa(erfa.dtf2d, iso, "UTC", year, month, day, hour, minute, second)
    return float(jd1), float(jd2)


def tai_minus_utc(iso: str) -> float:
    """TAI − UTC [s] at a UTC ISO-8601 time: the leap-second count from ERFA's table (``erfa.dat``).

    E.g. 36.0 in October 2016, 37.0 from 2017-01-01T00:00:00 (IERS Bulletin C 52).
    """
    year, month, day, hour, minute, second = parse_utc_iso(iso)
    jd_utc_from_iso(iso)  # validates the whole string
    fraction = (hour * 3600.0 + minute * 60.0 + min(second, 60.0)) / SECONDS_PER_DAY
    return float(_erfa(erfa.dat, iso, year, month, day, min(fraction, 1.0)))


def jd_tai_from_utc(iso: str) -> tuple[float, float]:
    """Two-part Julian date in TAI ``(jd1, jd2)`` [days] of a UTC ISO-8601 string (``erfa.utctai``)."""
    jd1, jd2 = _erfa(erfa.utctai, iso, *jd_utc_from_iso(iso))
    return float(jd1), float(jd2)


def jd_tt_from_utc(iso: str) -> tuple[float, float]:
    """Two-part Julian date in TT ``(jd1, jd2)`` [days] of a UTC ISO-8601 string (TT = TAI + 32.184 s)."""
    jd1, jd2 = _erfa(erfa.taitt, iso, *jd_tai_from_utc(iso))
    return float(jd1), float(jd2)


def tdb_minus_tt(jd1_tt: float | np.ndarray, jd2_tt: float | np.ndarray = 0.0) -> np.ndarray:
    """TDB − TT [s] at a (two-part) Julian date in TT, at the geocentre (``erfa.dtdb``, |value| < 1.7 ms).

    Vectorised over the shapes of ``jd1_tt``, ``jd2_tt`` (days).  TT stands in for TDB in the
    argument and UT1 is not needed at the geocentre (both change the result by < 1e-13 s).
    """
    return np.asarray(erfa.dtdb(jd1_tt, jd2_tt, 0.0, 0.0, 0.0, 0.0), dtype=float)


def jd_tdb_from_utc(iso: str) -> tuple[float, float]:
    """Two-part Julian date in TDB ``(jd1, jd2)`` [days] of a UTC ISO-8601 string: UTC -> TAI -> TT -> TDB.

    Use this form where precision below ~40 µs matters; :func:`julian_date_from_utc` returns the
    sum as one float.
    """
    tt1, tt2 = jd_tt_from_utc(iso)
    jd1, jd2 = _erfa(erfa.tttdb, iso, tt1, tt2, float(tdb_minus_tt(tt1, tt2)))
    return float(jd1), float(jd2)


def julian_date_from_utc(iso: str) -> float:
    """Julian date in TDB [days] (one float, ~40 µs resolution) of a UTC ISO-8601 string.

    ``YYYY-MM-DDTHH:MM:SS[.fff][Z]``: fractional seconds of any length, a leap second
    (``:60`` on a day that has one); anything else is a :class:`ValueError`.  Leap seconds come
    from ERFA's table, TT − TAI = 32.184 s, TDB − TT from ``erfa.dtdb`` (see the module docstring);
    :func:`jd_tdb_from_utc` gives the two-part date.
    """
    jd1, jd2 = jd_tdb_from_utc(iso)
    return jd1 + jd2


def julian_date_utc(iso: str) -> float:
    """The UTC calendar time of ``iso`` as a plain Julian date [days], *no* time-scale conversion.

    ``JD = 2440587.5 + (days since 1970-01-01) + seconds_of_day / 86400`` with a 86400-s day (a
    leap second ``:60.x`` reads as the first second of the next day).  This is not a time on any
    uniform scale; it exists for conventions that feed UTC where a TDB argument is due (see
    :func:`workbench.core.frames.planetocentric_amelia`).
    """
    jd_day, _ = jd_utc_from_iso(iso)  # validates; the first part is the JD of 0h of the day
    _, _, _, hour, minute, second = parse_utc_iso(iso)
    return jd_day + (hour * 3600.0 + minute * 60.0 + second) / SECONDS_PER_DAY


def utc_iso_from_jd_tdb(jd1_tdb: float, jd2_tdb: float = 0.0, decimals: int = 6) -> str:
    """UTC ISO-8601 string ``YYYY-MM-DDTHH:MM:SS.ffffffZ`` of a (two-part) Julian date in TDB [days].

    The inverse of :func:`jd_tdb_from_utc`: TDB -> TT (``erfa.tdbtt``, TDB − TT evaluated at the
    TT found by one fixed-point step, exact to < 1e-12 s) -> TAI -> UTC (``erfa.taiutc``), formatted
    by ``erfa.d2dtf`` with ``decimals`` digits of the second (a leap second prints as ``:60``).
    """
    iso = f"JD(TDB) {jd1_tdb} + {jd2_tdb}"
    dtr = float(tdb_minus_tt(jd1_tdb, jd2_tdb))
    tt1, tt2 = _erfa(erfa.tdbtt, iso, jd1_tdb, jd2_tdb, dtr)
    dtr = float(tdb_minus_tt(tt1, tt2))
    tt1, tt2 = _erfa(erfa.tdbtt, iso, jd1_tdb, jd2_tdb, dtr)
    tai1, tai2 = _erfa(erfa.tttai, iso, tt1, tt2)
    utc1, utc2 = _erfa(erfa.taiutc, iso, tai1, tai2)
    y, mo, d, hmsf = _erfa(erfa.d2dtf, iso, "UTC", int(decimals), utc1, utc2)
    h, mi, s, f = (int(hmsf[k]) for k in ("h", "m", "s", "f"))
    frac = f".{f:0{int(decimals)}d}" if decimals > 0 else ""
    return f"{int(y):04d}-{int(mo):02d}-{int(d):02d}T{h:02d}:{mi:02d}:{s:02d}{frac}Z"
