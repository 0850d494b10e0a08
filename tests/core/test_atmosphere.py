"""Tests of workbench.core.atmosphere.

Mars values are hand-computed from the NASA Glenn Mars Atmosphere Model formulas; gas properties
from textbook relations (a = sqrt(γRT), MEADS Eq. 45–46); Titan surface values from Fulchignoni
et al. (2005); hydrostatic balance dp/dh = −ρ g checked by finite differences.
"""

import numpy as np
import pytest

from workbench.core import atmosphere as atm
from workbench.core.bodies import TITAN


def _glenn(h):
    """NASA Glenn: T[°C] = −31 − 0.000998 h (h < 7000 m) else −23.4 − 0.00222 h; p[kPa] = 0.699 e^(−0.00009 h);
    ρ = p / (0.1921 T[K])."""
    T_c = -31 - 0.000998 * h if h < 7000 else -23.4 - 0.00222 * h
    p_kpa = 0.699 * np.exp(-0.00009 * h)
    return T_c + 273.15, p_kpa * 1e3, p_kpa / (0.1921 * (T_c + 273.15))


@pytest.mark.parametrize("h", [0.0, 5000.0, 6999.0, 7000.0, 20000.0, 49000.0])
def test_mars_glenn_values(h):
    m = atm.MarsEngineeringAtmosphere()
    T, p, rho = _glenn(h)
    assert m.temperature(h) == pytest.approx(T, rel=1e-12)
    assert m.pressure(h) == pytest.approx(p, rel=1e-12)
    assert m.density(h) == pytest.approx(rho, rel=1e-12)


def test_mars_glenn_literal_surface_values():
    m = atm.MarsEngineeringAtmosphere()
    assert m.temperature(0.0) == pytest.approx(242.15)
    assert m.pressure(0.0) == pytest.approx(699.0)
    assert m.density(0.0) == pytest.approx(0.015027, rel=1e-4)


def test_mars_positive_temperature_and_monotone_density_to_130km():
    m = atm.MarsEngineeringAtmosphere()
    h = np.linspace(0.0, 130e3, 2601)
    T, rho, p = m.temperature(h), m.density(h), m.pressure(h)
    assert T.shape == h.shape
    assert np.all(T > 100.0)
    assert np.all(np.diff(rho) < 0) and np.all(np.diff(p) < 0)
    # isothermal above the blend at T(50 km) = 273.15 − 23.4 − 111 = 138.75 K
    np.testing.assert_allclose(m.temperature([50e3, 80e3, 130e3]), 138.75, rtol=1e-12)
    # continuity at the blend altitude
    for f in (m.temperature, m.pressure, m.density):
        assert f(50e3 + 1e-3) == pytest.approx(f(50e3 - 1e-3), rel=1e-6)


def test_mars_aloft_is_hydrostatic():
    m = atm.MarsEngineeringAtmosphere()
    g_b = 42828.37362069909e9 / (3396.0e3 + 50e3) ** 2
    for h in (60e3, 90e3, 125e3):
        dpdh = (m.pressure(h + 1.0) - m.pressure(h - 1.0)) / 2.0
        # ρ in the Glenn fit uses R = 192.1 J/kg/K, so hydrostatic balance holds with it
        assert dpdh == pytest.approx(-m.density(h) * g_b, rel=1e-6)


def test_speed_of_sound_viscosity_mean_free_path():
    m = atm.MarsEngineeringAtmosphere()
    T, p, _ = _glenn(0.0)
    assert m.speed_of_sound(0.0) == pytest.approx(np.sqrt(1.335 * 191.8 * T), rel=1e-12)
    mu = 14.8e-6 * (T / 293.15) ** 1.5 * (293.15 + 240.0) / (T + 240.0)  # MEADS Table 1
    assert m.viscosity(0.0) == pytest.approx(mu, rel=1e-12)
    lam = mu / p * np.sqrt(np.pi * 191.8 * T / 2.0)
    assert m.mean_free_path(0.0) == pytest.approx(lam, rel=1e-12)
    assert m.knudsen(0.0, 4.5) == pytest.approx(lam / 4.5, rel=1e-12)
    assert 1e-7 < lam < 1e-5  # a few µm at the Martian surface
    # at 293.15 K the Sutherland law returns μ0
    assert atm.CO2_SUTHERLAND.viscosity(293.15) == pytest.approx(14.8e-6)


def test_exponential_atmosphere():
    e = atm.ExponentialAtmosphere(rho0=0.02, H=11.1e3, T0=210.0)
    assert e.density(11.1e3) == pytest.approx(0.02 / np.e)
    assert e.pressure(0.0) == pytest.approx(0.02 * 191.8 * 210.0)
    assert e.temperature(np.zeros((2, 3))).shape == (2, 3)
    assert e.speed_of_sound(5e3) == pytest.approx(np.sqrt(1.335 * 191.8 * 210.0))


def _table():
    h = np.array([0.0, 10e3, 30e3, 60e3])
    rho = np.array([2e-2, 8e-3, 1e-3, 5e-5])
    p = np.array([700.0, 300.0, 40.0, 2.0])
    T = np.array([240.0, 220.0, 180.0, 150.0])
    return h, rho, p, T


def test_tabulated_exact_at_nodes_and_log_linear_between():
    h, rho, p, T = _table()
    t = atm.TabulatedAtmosphere(h, rho, p, T)
    np.testing.assert_allclose(t.density(h), rho, rtol=1e-14)
    np.testing.assert_allclose(t.pressure(h), p, rtol=1e-14)
    np.testing.assert_allclose(t.temperature(h), T, rtol=1e-14)
    mid = 0.5 * (h[1:] + h[:-1])
    np.testing.assert_allclose(t.density(mid), np.sqrt(rho[1:] * rho[:-1]), rtol=1e-12)  # geometric mean
    np.testing.assert_allclose(t.pressure(mid), np.sqrt(p[1:] * p[:-1]), rtol=1e-12)
    np.testing.assert_allclose(t.temperature(mid), 0.5 * (T[1:] + T[:-1]), rtol=1e-12)
    hh = np.linspace(0, 60e3, 1001)
    assert np.all(np.diff(t.density(hh)) < 0)


def test_tabulated_out_of_range():
    h, rho, p, T = _table()
    t = atm.TabulatedAtmosphere(h, rho, p, T)
    with pytest.raises(ValueError):
        t.density(61e3)
    with pytest.raises(ValueError):
        t.temperature(np.array([-1.0, 5.0]))
    c = atm.TabulatedAtmosphere(h, rho, p, T, extrapolate="clamp")
    assert c.density(100e3) == pytest.approx(5e-5)
    assert c.temperature(-10.0) == pytest.approx(240.0)
    with pytest.raises(ValueError):
        atm.TabulatedAtmosphere(h[::-1], rho, p, T)


def test_titan_surface_values():
    t = atm.TitanDefaultAtmosphere()
    assert t.temperature(0.0) == pytest.approx(93.65)
    assert t.pressure(0.0) == pytest.approx(146700.0)
    assert t.density(0.0) == pytest.approx(146700.0 / (296.8 * 93.65), rel=1e-12)
    assert 5.0 < t.density(0.0) < 5.6  # HASI surface density ≈ 5.4 kg/m³
    assert t.speed_of_sound(0.0) == pytest.approx(np.sqrt(1.4 * 296.8 * 93.65))


def test_titan_profile_is_hydrostatic_and_positive():
    t = atm.TitanDefaultAtmosphere()
    h = np.linspace(0.0, 1300e3, 1301)
    assert np.all(t.temperature(h) > 60.0) and np.all(np.diff(t.density(h)) < 0)
    for hk in (10e3, 100e3, 400e3, 1200e3):
        dpdh = (t.pressure(hk + 1.0) - t.pressure(hk - 1.0)) / 2.0
        g = TITAN.gm / (TITAN.reference_radius + hk) ** 2
        assert dpdh == pytest.approx(-t.density(hk) * g, rel=1e-6)
    # Huygens tropopause 70.4 K at 44 km (documented engineering node)
    assert t.temperature(44e3) == pytest.approx(70.4, abs=1e-9)
