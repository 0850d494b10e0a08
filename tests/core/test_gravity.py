"""Tests of workbench.core.gravity against GM/r², a finite-difference gradient of the J2 potential
and published surface gravities (Mars 3.71 m/s², NSSDC/Horizons; Titan 1.354 m/s² from GM/R², gm_de440 and pck00011)."""

import numpy as np
import pytest

from workbench.core import gravity
from workbench.core.bodies import MARS, TITAN


def test_point_mass_magnitude_and_direction():
    rng = np.random.default_rng(0)
    r = rng.normal(scale=4e6, size=(4, 5, 3))
    a = gravity.gravity_point_mass(r, MARS.gm)
    rn = np.linalg.norm(r, axis=-1)
    np.testing.assert_allclose(np.linalg.norm(a, axis=-1), 42828.37362069909e9 / rn**2, rtol=1e-13)
    np.testing.assert_allclose(np.einsum("...i,...i->...", a, r), -np.linalg.norm(a, axis=-1) * rn, rtol=1e-13)


def _j2_potential(r, gm, j2, re):
    """U = GM/r [1 − J2 (Re/r)² P2(z/r)], written independently of the module."""
    rn = np.linalg.norm(r, axis=-1)
    s = r[..., 2] / rn
    return gm / rn * (1.0 - j2 * (re / rn) ** 2 * 0.5 * (3.0 * s * s - 1.0))


def test_j2_is_gradient_of_potential():
    rng = np.random.default_rng(1)
    r = rng.normal(size=(20, 3))
    r = r / np.linalg.norm(r, axis=-1, keepdims=True) * rng.uniform(3.4e6, 2e7, (20, 1))
    a = gravity.gravity_j2(r, MARS)
    h = 1.0  # m; fourth-order central differences
    grad = np.zeros_like(r)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        U = lambda x: _j2_potential(x, MARS.gm, MARS.j2, MARS.equatorial_radius)  # noqa: E731
        grad[:, k] = (-U(r + 2 * e) + 8 * U(r + e) - 8 * U(r - e) + U(r - 2 * e)) / (12 * h)
    np.testing.assert_allclose(a, grad, rtol=0, atol=1e-8 * np.abs(a).max())
    # and the J2 part is really there (not just the point mass)
    assert np.abs(a - gravity.gravity_point_mass(r, MARS.gm)).max() > 1e-4


def test_j2_equator_and_pole_closed_form():
    R = MARS.equatorial_radius
    g_eq = gravity.gravity_j2(np.array([R, 0, 0]), MARS)
    g_pole = gravity.gravity_j2(np.array([0, 0, R]), MARS)
    g0 = MARS.gm / R**2
    np.testing.assert_allclose(g_eq, [-g0 * (1 + 1.5 * 1960.45e-6), 0, 0], rtol=1e-13)
    np.testing.assert_allclose(g_pole, [0, 0, -g0 * (1 - 3 * 1960.45e-6)], rtol=1e-13)


def test_mars_and_titan_surface_gravity():
    assert MARS.surface_gravity == pytest.approx(3.71, abs=0.01)
    g_eq = np.linalg.norm(gravity.gravity_j2(np.array([0, MARS.equatorial_radius, 0]), MARS))
    assert g_eq == pytest.approx(3.71, abs=0.02)
    assert TITAN.surface_gravity == pytest.approx(1.354, abs=0.002)


def test_uniform_gravity():
    np.testing.assert_allclose(gravity.gravity_uniform(), [0, 0, -9.80665])
    assert gravity.G0 == 9.80665
    a = gravity.gravity_uniform(3.71, up=[0, 0, 2.0], r=np.zeros((7, 3)))
    assert a.shape == (7, 3)
    np.testing.assert_allclose(a, np.tile([0, 0, -3.71], (7, 1)))
    with pytest.raises(ValueError):
        gravity.gravity_uniform(up=[0, 0, 0])


def test_component_form_matches_array_form_and_is_member_exact():
    rng = np.random.default_rng(5)
    r = rng.normal(size=(40, 3))
    r = r / np.linalg.norm(r, axis=-1, keepdims=True) * rng.uniform(3.4e6, 4e6, (40, 1))
    j2k = gravity.j2_factor(MARS)
    assert j2k == pytest.approx(1.5 * 1960.45e-6 * 42828.37362069909e9 * 3396.19e3**2, rel=1e-15)
    a = gravity.gravity_j2(r, MARS)
    gx, gy, gz, rn = gravity.gravity_j2_xyz(r[:, 0], r[:, 1], r[:, 2], MARS.gm, j2k)  # arrays
    np.testing.assert_allclose(np.stack([gx, gy, gz], -1), a, rtol=1e-14, atol=0)
    np.testing.assert_allclose(rn, np.linalg.norm(r, axis=-1), rtol=1e-15)
    for k in range(r.shape[0]):  # Python floats: the same operations, equal to the array call's member
        s = gravity.gravity_j2_xyz(*r[k].tolist(), MARS.gm, j2k)
        assert all(isinstance(c, float) for c in s)
        assert s == (gx[k], gy[k], gz[k], rn[k])


def test_point_mass_gradient_against_finite_differences():
    rng = np.random.default_rng(6)
    r = rng.normal(size=(5, 3)) * 2e6 + np.array([3e6, 0, 0])
    G = gravity.gravity_point_mass_gradient(r, MARS.gm)
    assert G.shape == (5, 3, 3)
    h = 1.0
    for k in range(5):
        fd = np.stack(
            [(gravity.gravity_point_mass(r[k] + e, MARS.gm) - gravity.gravity_point_mass(r[k] - e, MARS.gm)) / (2 * h)
             for e in h * np.eye(3)], -1)  # fmt: skip
        np.testing.assert_allclose(G[k], fd, rtol=1e-6, atol=1e-14)
        np.testing.assert_allclose(G[k], G[k].T, rtol=1e-15)
        assert np.trace(G[k]) == pytest.approx(0.0, abs=1e-20)  # Laplace: the field is divergence-free
