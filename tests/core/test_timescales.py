"""Tests of workbench.core.timescales: UTC -> TAI -> TT -> TDB through ERFA.

Expected values are written out from their definitions, not from the code: leap seconds from
IERS Bulletin C (TAI − UTC = 32 s in 2000, 36 s from 2015-07-01, 37 s from 2017-01-01), TT − TAI
= 32.184 s (IAU 1991), J2000.0 = 2000-01-01T12:00:00 TT = JD 2451545.0 (TT), JD of a calendar
date at 0h from the Gregorian calendar, |TDB − TT| < 1.7 ms (Fairhead & Bretagnon 1990).
"""

import warnings

import numpy as np
import pytest

from workbench.core import frames, timescales

DAY = 86400.0


def _sec(a: tuple[float, float], b: tuple[float, float]) -> float:
    """a − b [s] of two-part Julian dates, without losing precision."""
    return ((a[0] - b[0]) + (a[1] - b[1])) * DAY


# ----------------------------------------------------------------------------------- leap seconds
@pytest.mark.parametrize(
    ("iso", "leap"),
    [
        ("2000-01-01T12:00:00Z", 32.0),
        ("2015-06-29T23:59:59Z", 35.0),
        ("2015-07-01T00:00:00Z", 36.0),
        ("2016-10-19T14:42:07.125Z", 36.0),  # AMELIA's Schiaparelli epoch
        ("2016-12-30T23:59:59.999Z", 36.0),
        ("2017-01-01T00:00:00Z", 37.0),
        ("2024-06-01T00:00:00Z", 37.0),
    ],
)
def test_tai_minus_utc_from_the_leap_second_table(iso, leap):
    assert timescales.tai_minus_utc(iso) == leap
    assert _sec(timescales.jd_tai_from_utc(iso), timescales.jd_utc_from_iso(iso)) == pytest.approx(leap, abs=1e-6)


def test_tai_minus_utc_on_the_day_of_a_leap_second():
    # the whole of 2016-12-31 is still at 36 s, including the inserted second 23:59:60
    assert timescales.tai_minus_utc("2016-12-31T23:59:59.999Z") == 36.0
    assert timescales.tai_minus_utc("2016-12-31T23:59:60.5Z") == 36.0


def test_tt_minus_tai_and_tt_minus_utc_in_2016():
    iso = "2016-10-19T14:42:07.125Z"
    assert timescales.TT_MINUS_TAI == 32.184
    assert _sec(timescales.jd_tt_from_utc(iso), timescales.jd_tai_from_utc(iso)) == pytest.approx(32.184, abs=1e-6)
    # the old constant 69.184 s was valid only from 2017: in October 2016 TT − UTC is 68.184 s
    assert _sec(timescales.jd_tt_from_utc(iso), timescales.jd_utc_from_iso(iso)) == pytest.approx(68.184, abs=1e-6)


def test_j2000_epoch_in_utc_and_tt():
    # J2000.0 = 2000-01-01T12:00:00 TT = 11:58:55.816 UTC (TAI − UTC = 32 s)
    tt = timescales.jd_tt_from_utc("2000-01-01T11:58:55.816Z")
    assert (tt[0] - 2451545.0) * DAY + tt[1] * DAY == pytest.approx(0.0, abs=1e-6)
    jd_tdb = timescales.julian_date_from_utc("2000-01-01T11:58:55.816Z")
    assert abs(jd_tdb - 2451545.0) * DAY < 2e-3  # TDB − TT only


def test_known_julian_dates():
    # 2017-01-01T00:00:00 UTC is JD 2457754.5 (UTC); TT = UTC + 69.184 s there
    tt = timescales.jd_tt_from_utc("2017-01-01T00:00:00Z")
    assert _sec(tt, (2457754.5, 0.0)) == pytest.approx(69.184, abs=1e-6)
    assert timescales.julian_date_utc("2016-10-19T14:42:07.125Z") == pytest.approx(
        2457680.5 + (14 * 3600 + 42 * 60 + 7.125) / DAY, abs=1e-9
    )


def test_tdb_minus_tt_is_below_two_milliseconds():
    jd = 2451545.0 + np.linspace(0.0, 40 * 365.25, 2001)  # two Mars synodic periods and more
    d = timescales.tdb_minus_tt(jd)
    assert d.shape == jd.shape
    assert np.max(np.abs(d)) < 2e-3
    assert np.max(np.abs(d)) > 1.5e-3  # the annual term (1.657 ms) is there
    iso = "2016-10-19T14:42:07.125Z"
    assert abs(_sec(timescales.jd_tdb_from_utc(iso), timescales.jd_tt_from_utc(iso))) < 2e-3


def test_leap_second_is_one_second_long():
    tdb = timescales.jd_tdb_from_utc
    assert _sec(tdb("2016-12-31T23:59:60.5"), tdb("2016-12-31T23:59:59.5")) == pytest.approx(1.0, abs=1e-6)
    assert _sec(tdb("2017-01-01T00:00:00Z"), tdb("2016-12-31T23:59:59Z")) == pytest.approx(2.0, abs=1e-6)
    assert _sec(tdb("2016-10-20T00:00:00Z"), tdb("2016-10-19T23:59:59Z")) == pytest.approx(1.0, abs=1e-6)


def test_two_part_date_resolves_microseconds_and_one_float_agrees():
    a = timescales.jd_tdb_from_utc("2016-10-19T14:42:22.132001Z")
    b = timescales.jd_tdb_from_utc("2016-10-19T14:42:22.132000Z")
    assert _sec(a, b) == pytest.approx(1e-6, abs=1e-9)
    one = timescales.julian_date_from_utc("2016-10-19T14:42:22.132Z")
    assert (one - sum(b)) * DAY == pytest.approx(0.0, abs=5e-5)  # one float: ~40 µs resolution
    # fractional seconds of any length
    c = timescales.julian_date_from_utc("2016-10-19T14:42:22.123456789Z")
    d = timescales.julian_date_from_utc("2016-10-19T14:42:22Z")
    assert (c - d) * DAY == pytest.approx(0.123456789, abs=1e-4)


@pytest.mark.parametrize(
    "iso", ["2016-10-19T14:42:07.125000Z", "2016-12-31T23:59:60.250000Z", "2017-01-01T00:00:00.000000Z"]
)
def test_round_trip_utc_tdb_utc(iso):
    assert timescales.utc_iso_from_jd_tdb(*timescales.jd_tdb_from_utc(iso)) == iso


def test_frames_reexports_the_same_conversion():
    assert frames.julian_date_from_utc is timescales.julian_date_from_utc


# ------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("bad", "says"),
    [
        ("2016-10-19", "not a UTC ISO-8601 time"),
        ("19/10/2016 14:42:22", "not a UTC ISO-8601 time"),
        ("2016-10-19T00:00:00+02:00", "not a UTC ISO-8601 time"),
        ("2016-13-01T00:00:00Z", "bad month"),
        ("2016-02-30T00:00:00Z", "bad day"),
        ("2016-10-19T25:00:00Z", "out of range"),
        ("2016-10-19T23:59:60.5Z", "after end of day"),  # no leap second that day
        ("1959-12-31T00:00:00Z", "not defined before 1960"),
    ],
)
def test_bad_strings_are_a_clear_value_error(bad, says):
    with pytest.raises(ValueError, match=says) as info:
        timescales.julian_date_from_utc(bad)
    assert repr(bad) in str(info.value)


def test_far_future_dates_warn_dubious_year():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        jd = timescales.julian_date_from_utc("2100-01-01T00:00:00Z")
    assert any("dubious year" in str(w.message) for w in caught)
    assert jd == pytest.approx(2488069.5 + (37 + 32.184) / DAY, abs=1e-6)
