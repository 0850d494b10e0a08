"""Tests of workbench.core.frames: time, IAU rotation, geodesy, NED and the SPF lab frame.

Expected values are written out from the published elements (IAU 2015, NAIF pck00011), JPL Horizons
(Mars sidereal period 24.622962 h), the REDLand paper and the AMELIA paper (Aboudan et al. 2018,
Tables 2 and 5), not taken from the code.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from workbench.core import frames, timescales
from workbench.core.bodies import MARS, TITAN

J2000 = 2451545.0


# ------------------------------------------------------------------------------------------ time
# UTC -> TDB itself is tested in test_timescales.py.
def test_days_and_centuries():
    assert frames.days_since_j2000(J2000 + 36525.0) == pytest.approx(36525.0)
    np.testing.assert_allclose(frames.centuries_since_j2000(np.array([J2000, J2000 + 73050.0])), [0.0, 2.0])


# ------------------------------------------------------------------------------------------- IAU
def test_mars_sidereal_period_from_W_rate():
    w = frames.meridian_rate(MARS, J2000)
    assert 2 * np.pi / w / 3600.0 == pytest.approx(24.622962, abs=2e-6)  # JPL Horizons
    assert w == pytest.approx(7.08822e-5, rel=2e-6)


def _pole_radec_and_W(C):
    """Pole RA/Dec and prime-meridian angle [deg] read back from C_F_I geometrically."""
    pole = C[2]  # body +Z in inertial coordinates
    ra = np.degrees(np.arctan2(pole[1], pole[0])) % 360.0
    dec = np.degrees(np.arcsin(pole[2]))
    node = np.array([np.cos(np.radians(ra + 90)), np.sin(np.radians(ra + 90)), 0.0])
    x = C[0]
    W = np.degrees(np.arctan2(np.cross(node, x) @ pole, node @ x)) % 360.0
    return ra, dec, W


def test_mars_pole_and_meridian_at_j2000():
    C = frames.C_bodyfixed_inertial(MARS, J2000)
    ra, dec, W = _pole_radec_and_W(C)
    # pck00011 at T = d = 0, largest periodic terms evaluated by hand:
    assert ra == pytest.approx(317.269202 + 0.419057 * np.sin(np.radians(79.398797)), abs=1e-9)
    assert dec == pytest.approx(54.432516 + 1.591274 * np.cos(np.radians(166.325722)), abs=1e-9)
    assert W == pytest.approx(176.049863 + 0.584542 * np.sin(np.radians(95.391654)), abs=1e-9)
    a, d, w = frames.iau_pole_and_meridian(MARS, J2000)
    assert np.degrees([a, d, w]) == pytest.approx([ra, dec, W], abs=1e-9)


def test_titan_pole_and_meridian_one_century_later():
    jd = J2000 + 36525.0
    ra, dec, W = _pole_radec_and_W(frames.C_bodyfixed_inertial(TITAN, jd))
    assert ra == pytest.approx(39.4827, abs=1e-9)
    assert dec == pytest.approx(83.4279, abs=1e-9)
    assert W == pytest.approx((186.5855 + 22.5769768 * 36525.0) % 360.0, abs=1e-6)


def test_C_is_orthonormal_and_vectorised():
    jd = J2000 + np.array([[0.0, 100.25, -3000.7], [6000.0, 12.5, 8888.1]])
    C = frames.C_bodyfixed_inertial(MARS, jd)
    assert C.shape == (2, 3, 3, 3)
    np.testing.assert_allclose(C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(C), 1.0, atol=1e-14)
    np.testing.assert_allclose(C[0, 1], frames.C_bodyfixed_inertial(MARS, jd[0, 1]), atol=1e-15)


def test_inertial_bodyfixed_round_trip():
    rng = np.random.default_rng(7)
    jd = J2000 + rng.uniform(5000, 6000, 20)
    r_I = rng.normal(scale=4e6, size=(20, 3))
    v_I = rng.normal(scale=5e3, size=(20, 3))
    r_F, v_F = frames.inertial_to_bodyfixed(MARS, jd, r_I, v_I)
    r_back, v_back = frames.bodyfixed_to_inertial(MARS, jd, r_F, v_F)
    np.testing.assert_allclose(r_back, r_I, rtol=0, atol=1e-7)
    np.testing.assert_allclose(v_back, v_I, rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.linalg.norm(r_F, axis=-1), np.linalg.norm(r_I, axis=-1), rtol=1e-14)


def test_surface_point_inertial_velocity_is_transport_rate():
    """A point at rest in F moves in I with ω × r: compare with a finite difference of C(t)ᵀ r_F."""
    jd0 = J2000 + 6130.1
    r_F = np.array([3.0e6, 1.0e6, 1.5e6])
    _, v_I = frames.bodyfixed_to_inertial(MARS, jd0, r_F, np.zeros(3))
    # JD float resolution is ~40 µs and the central-difference error (ω dt)²/6: dt = 20 s balances both
    dt = 20.0  # s
    r_p = frames.bodyfixed_to_inertial(MARS, jd0 + dt / 86400.0, r_F)
    r_m = frames.bodyfixed_to_inertial(MARS, jd0 - dt / 86400.0, r_F)
    np.testing.assert_allclose(v_I, (r_p - r_m) / (2 * dt), rtol=0, atol=1e-6 * np.linalg.norm(v_I))
    # speed = ω × distance from the spin axis, with ω = 7.08822e-5 rad/s (Horizons)
    assert np.linalg.norm(v_I) == pytest.approx(7.08822e-5 * np.hypot(3.0e6, 1.0e6), rel=1e-5)
    # and the inverse: the same inertial state is at rest in F
    _, v_F = frames.inertial_to_bodyfixed(MARS, jd0, frames.bodyfixed_to_inertial(MARS, jd0, r_F), v_I)
    np.testing.assert_allclose(v_F, 0.0, atol=1e-9)


# --------------------------------------------------------------------------------------- geodesy
def test_planetocentric_known_points_and_round_trip():
    lat, lon, rad = frames.planetocentric_from_cartesian(np.array([[0, 3.0, 0], [1.0, 0, 1.0], [0, 0, -2.0]]))
    np.testing.assert_allclose(lat, [0, np.pi / 4, -np.pi / 2], atol=1e-15)
    np.testing.assert_allclose(lon[:2], [np.pi / 2, 0.0], atol=1e-15)
    np.testing.assert_allclose(rad, [3.0, np.sqrt(2), 2.0])
    rng = np.random.default_rng(3)
    r = rng.normal(scale=3.4e6, size=(50, 3))
    np.testing.assert_allclose(
        frames.cartesian_from_planetocentric(*frames.planetocentric_from_cartesian(r)), r, atol=1e-8
    )


def test_altitude_above_sphere():
    r = np.array([[3396.0e3 + 125e3, 0, 0], [0, 0, 3396.0e3 - 1440.0]])
    np.testing.assert_allclose(frames.altitude_above_sphere(r, MARS.reference_radius), [125e3, -1440.0], atol=1e-8)


def test_ned_at_equator_prime_meridian():
    C = frames.C_ned_bodyfixed(0.0, 0.0)
    np.testing.assert_allclose(C, [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-15)  # N=+Z, E=+Y, D=-X=-r̂


def test_ned_general_properties():
    rng = np.random.default_rng(11)
    lat, lon = rng.uniform(-1.5, 1.5, 30), rng.uniform(-np.pi, np.pi, 30)
    C = frames.C_ned_bodyfixed(lat, lon)
    r_hat = frames.cartesian_from_planetocentric(lat, lon, 1.0)
    np.testing.assert_allclose(C[:, 2], -r_hat, atol=1e-15)  # Down = -r̂
    np.testing.assert_allclose(np.cross(C[:, 0], C[:, 1]), C[:, 2], atol=1e-15)  # right-handed
    assert np.all(C[:, 0, 2] > 0)  # North has a positive polar component
    np.testing.assert_allclose(C[:, 1] @ np.array([0, 0, 1.0]), 0.0, atol=1e-15)  # East is horizontal
    v = rng.normal(size=(30, 3))
    np.testing.assert_allclose(
        frames.bodyfixed_from_ned(frames.ned_from_bodyfixed(v, lat, lon), lat, lon), v, atol=1e-14
    )


def test_local_ned_position():
    origin = frames.cartesian_from_planetocentric(0.3, -1.2, 3396e3 - 1440.0)
    up = origin / np.linalg.norm(origin)
    east = np.array([np.sin(1.2), np.cos(1.2), 0.0])  # -sin(lon), cos(lon) with lon = -1.2
    p = origin + 100.0 * up + 20.0 * east
    np.testing.assert_allclose(frames.local_ned_position(p, origin), [0.0, 20.0, -100.0], atol=1e-8)


# ------------------------------------------------------------------------------------ lab frames
def test_spf_ramp_normal_maps_to_mars_up():
    s60, c60 = np.sin(np.radians(60)), np.cos(np.radians(60))
    n_spf = np.array([0.0, -s60, c60])
    np.testing.assert_allclose(frames.C_mars_spf() @ n_spf, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(frames.SPF_LAB.to_planet(n_spf), [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(frames.C_mars_spf(), Rotation.from_euler("x", -60, degrees=True).as_matrix(), atol=1e-15)
    # X axis is the rotation axis
    np.testing.assert_allclose(frames.SPF_LAB.to_planet([1.0, 0, 0]), [1, 0, 0], atol=1e-15)


def test_lab_frame_round_trips_and_points():
    rng = np.random.default_rng(2)
    lab = frames.LabFrame("test", frames.C_mars_spf(), origin=np.array([1.0, 2.0, 3.0]))
    v = rng.normal(size=(5, 4, 3))
    np.testing.assert_allclose(lab.from_planet(lab.to_planet(v)), v, atol=1e-14)
    np.testing.assert_allclose(lab.point_to_planet(np.zeros(3)), [1.0, 2.0, 3.0])
    np.testing.assert_allclose(lab.point_from_planet(lab.point_to_planet(v)), v, atol=1e-14)
    np.testing.assert_allclose(Rotation.from_quat(lab.q_planet_lab).as_matrix(), frames.C_mars_spf(), atol=1e-14)
    with pytest.raises(ValueError):
        frames.LabFrame("bad", np.diag([1.0, 1.0, -1.0]))


# ------------------------------------------------------------------------ local bases from position
def test_ned_basis_from_position_matches_latitude_longitude_form():
    rng = np.random.default_rng(7)
    lat = rng.uniform(-1.4, 1.4, 50)
    lon = rng.uniform(-np.pi, np.pi, 50)
    r = frames.cartesian_from_planetocentric(lat, lon, rng.uniform(3.3e6, 3.6e6, 50))
    C = frames.ned_basis(r)
    np.testing.assert_allclose(C, frames.C_ned_bodyfixed(lat, lon), atol=1e-14)
    # Down is −r̂, written out by hand for one point on the equator at 90° E
    np.testing.assert_allclose(frames.ned_basis(np.array([0.0, 5.0, 0.0])), [[0, 0, 1], [-1, 0, 0], [0, -1, 0]],
                               atol=1e-15)  # fmt: skip


def test_enu_basis_and_ned_from_enu():
    lat, lon = 0.3, -2.0
    C_enu = frames.C_enu_bodyfixed(lat, lon)
    # up is the radial direction, east is horizontal and points to increasing longitude
    up = [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)]
    np.testing.assert_allclose(C_enu[2], up, atol=1e-15)
    np.testing.assert_allclose(C_enu[0], [-np.sin(lon), np.cos(lon), 0.0], atol=1e-15)
    np.testing.assert_allclose(C_enu @ C_enu.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(C_enu) == pytest.approx(1.0)
    v_enu = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    np.testing.assert_array_equal(frames.ned_from_enu(v_enu), [[2.0, 1.0, -3.0], [5.0, 4.0, -6.0]])
    # consistent with the two DCMs
    np.testing.assert_allclose(frames.ned_from_enu(C_enu @ [0.1, 0.2, 0.3]),
                               frames.C_ned_bodyfixed(lat, lon) @ [0.1, 0.2, 0.3], atol=1e-15)  # fmt: skip


def test_north_east_xyz_are_the_first_rows_of_ned_basis():
    rng = np.random.default_rng(8)
    r = rng.normal(size=(20, 3)) * 3.4e6
    C = frames.ned_basis(r)
    for k in range(20):
        x, y, z = r[k].tolist()
        nx, ny, nz, ex, ey = frames.north_east_xyz(x, y, z, float(np.linalg.norm(r[k])))
        np.testing.assert_allclose([nx, ny, nz], C[k, 0], atol=1e-15)
        np.testing.assert_allclose([ex, ey, 0.0], C[k, 1], atol=1e-15)
    # hand value: on the equator at 0° E, north is +Z and east is +Y
    np.testing.assert_allclose(frames.north_east_xyz(7.0, 0.0, 0.0, 7.0), [0.0, 0.0, 1.0, 0.0, 1.0], atol=0)


# ------------------------------------------------------------------ AMELIA Table 2 -> Table 5
# Aboudan et al. 2018, Space Sci. Rev. 214:97. Table 2, "Optimal" column: the MMED position of the
# initial state at 14:42:07.125 UTC on 2016-10-19; Table 5, first row ("First data", same time):
# lon E -17.3091 deg, lat N -3.5723 deg, altitude AMR 122.6329 km (above the 3396 km MOLA sphere).
AMELIA_EPOCH_UTC = "2016-10-19T14:42:07.125Z"
AMELIA_P_M_KM = np.array([-1317.8932, 3255.1296, -219.2404])
AMELIA_TABLE5_FIRST = {"lon_deg": -17.3091, "lat_deg": -3.5723, "alt_km": 122.6329}


def test_amelia_table5_first_row_from_table2_state():
    p_M = AMELIA_P_M_KM * 1e3
    lat, lon, r = frames.planetocentric_amelia(MARS, timescales.julian_date_utc(AMELIA_EPOCH_UTC), p_M)
    # latitude and altitude to the paper's printed digits (4 decimals)
    assert round(float(np.degrees(lat)), 4) == AMELIA_TABLE5_FIRST["lat_deg"]
    assert round((float(r) - MARS.reference_radius) / 1e3, 4) == AMELIA_TABLE5_FIRST["alt_km"]
    # longitude: the best convention found is +0.0102 deg from the printed value (frames module
    # docstring lists the hypotheses measured); the issue asks for 0.3 deg, this pins the residual
    assert float(np.degrees(lon)) - AMELIA_TABLE5_FIRST["lon_deg"] == pytest.approx(0.0102, abs=5e-4)


def test_exact_conversion_against_an_independent_construction_and_the_paper():
    """Pole and meridian of date at TDB: built here from the pole vector and node instead of the
    Euler chain; it differs from Table 5 by the pole drift since J2000 in latitude and by ~68 s of
    Mars rotation (plus the pole) in longitude."""
    p_M = AMELIA_P_M_KM * 1e3
    jd_tdb = frames.julian_date_from_utc(AMELIA_EPOCH_UTC)
    lat, lon, r = frames.planetocentric_of_date(MARS, jd_tdb, p_M)
    assert float(r) == pytest.approx(np.linalg.norm(p_M), rel=1e-14)
    alpha, delta, W = frames.iau_pole_and_meridian(MARS, jd_tdb)
    n = np.array([np.cos(delta) * np.cos(alpha), np.cos(delta) * np.sin(alpha), np.sin(delta)])
    node = np.cross([0.0, 0.0, 1.0], n)
    node /= np.linalg.norm(node)
    p_I = frames.C_mmed_icrf(MARS).T @ p_M
    lat_ref = np.arcsin(p_I @ n / np.linalg.norm(p_I))
    lon_ref = np.arctan2(p_I @ np.cross(n, node), p_I @ node) - W
    assert float(lat) == pytest.approx(float(lat_ref), abs=1e-12)
    assert np.degrees(float(lon)) == pytest.approx((np.degrees(float(lon_ref)) + 180.0) % 360.0 - 180.0, abs=1e-9)
    assert np.degrees(float(lat)) - AMELIA_TABLE5_FIRST["lat_deg"] == pytest.approx(-0.0055, abs=2e-4)
    assert np.degrees(float(lon)) - AMELIA_TABLE5_FIRST["lon_deg"] == pytest.approx(-0.2513, abs=5e-4)


def test_amelia_convention_vectorised_and_rotating():
    p_M = np.tile(AMELIA_P_M_KM * 1e3, (3, 1))
    dt = np.array([0.0, 100.0, 200.0])  # [s]; a one-float JD resolves ~40 µs
    jd = timescales.julian_date_utc(AMELIA_EPOCH_UTC) + dt / 86400.0
    lat, lon, r = frames.planetocentric_amelia(MARS, jd, p_M)
    assert lat.shape == lon.shape == r.shape == (3,)
    np.testing.assert_allclose(np.diff(lon), -frames.meridian_rate(MARS, jd[0]) * 100.0, rtol=1e-6)
