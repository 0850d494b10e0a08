"""Tests of workbench.core.bodies: lookup and the published constants (NAIF pck00011/gm_de440, NSSDC, WGS 84)."""

import pytest

from workbench.core import bodies


def test_get_body_case_insensitive():
    assert bodies.get_body("mars") is bodies.MARS
    assert bodies.get_body(" TITAN ") is bodies.TITAN
    assert bodies.get_body("Earth") is bodies.EARTH


def test_get_body_unknown_lists_known():
    with pytest.raises(KeyError) as exc:
        bodies.get_body("Venus")
    msg = str(exc.value)
    assert "Venus" in msg and all(n in msg for n in ("Mars", "Titan", "Earth"))


def test_published_constants():
    assert bodies.MARS.gm == pytest.approx(42828.37362069909e9, rel=1e-15)
    assert bodies.MARS.reference_radius == 3396.0e3
    assert bodies.MARS.flattening == pytest.approx((3396.19 - 3376.20) / 3396.19)
    assert bodies.TITAN.reference_radius == pytest.approx(2574.80e3, abs=10.0)
    assert bodies.EARTH.surface_gravity == pytest.approx(9.82, abs=0.01)  # GM / R_mean², no spin


def test_bad_periodic_kind_rejected():
    with pytest.raises(ValueError):
        bodies.Body("X", 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0, 0, 90, 0, 0, 1, periodic_terms=(("ra", 1.0, 0.0, 0.0),))
