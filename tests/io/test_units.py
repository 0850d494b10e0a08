"""Unit table and SI conversion (workbench.io.units)."""

import numpy as np
import pytest

from workbench.io.units import KINDS, SI_UNITS, UNITS, UnitError, canonical_unit, from_si, to_si, unit_kind


@pytest.mark.parametrize(
    ("value", "unit", "si", "kind"),
    [
        (1.0, "g", 9.80665, "acceleration"),
        (180.0, "deg", np.pi, "angle"),
        (90.0, "deg/s", np.pi / 2, "angular_rate"),
        (1.0, "ft", 0.3048, "length"),
        (36.0, "km/h", 10.0, "velocity"),
        (1.0, "psi", 6894.757293168361, "pressure"),
        (760.0, "torr", 101325.0, "pressure"),
        (1013.25, "mbar", 101325.0, "pressure"),
        (0.0, "degC", 273.15, "temperature"),
        (5.0, "ms", 0.005, "time"),
        (1.0, "gauss", 1e-4, "magnetic"),
        (50.0, "uT", 50e-6, "magnetic"),
        (3.0, "-", 3.0, "dimensionless"),
    ],
)
def test_to_si_known_values(value, unit, si, kind):
    out, k = to_si(value, unit)
    assert k == kind
    assert out == pytest.approx(si, rel=1e-12)
    assert from_si(out, unit) == pytest.approx(value, rel=1e-12, abs=1e-12)


def test_round_trip_every_unit_on_arrays():
    x = np.linspace(-5.0, 5.0, 11).reshape(11, 1) * np.ones((1, 3))
    for unit in UNITS:
        si, kind = to_si(x, unit)
        assert si.shape == x.shape and kind in KINDS
        np.testing.assert_allclose(from_si(si, unit), x, rtol=1e-12, atol=1e-12)


def test_to_si_does_not_alias_input():
    x = np.array([1.0, 2.0])
    si, _ = to_si(x, "m")
    si[0] = 99.0
    assert x[0] == 1.0


def test_aliases_and_kind():
    assert canonical_unit("µs") == "us"
    assert canonical_unit(" m/s2 ") == "m/s^2"
    assert unit_kind("°C") == "temperature"
    assert unit_kind("deg/s^2") == "angular_acceleration"
    assert SI_UNITS["acceleration"] == "m/s^2"


def test_unknown_unit_lists_known_units():
    with pytest.raises(UnitError) as info:
        to_si(1.0, "gee")
    assert "'gee'" in str(info.value)
    assert "m/s^2" in str(info.value) and "deg/s" in str(info.value)
    assert "g" in info.value.known
    with pytest.raises(UnitError):
        unit_kind("MBAR")  # units are case-sensitive


def test_likely_unit_names_the_unit_of_a_unit_like_mismatch():
    from workbench.io.units import likely_unit

    assert likely_unit(1 / 9.80665, "m/s^2") == "g"  # values in g under an m/s² header
    assert likely_unit(9.7, "g") == "m/s^2"
    assert likely_unit(1e-3, "m") == "km"
    assert likely_unit(1e3, "km/s") == "m/s"
    assert likely_unit(57.3, "rad/s") == "deg/s"
    assert likely_unit(1 / 57.3, "deg/s") == "rad/s"
    assert likely_unit(1e-3, "ms") == "s"
    assert likely_unit(3.28, "m") == "ft"
    assert likely_unit(1.05, "g") is None and likely_unit(4.0, "m") is None and likely_unit(0.0, "m") is None
