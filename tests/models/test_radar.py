"""Radar altimeter geometry: beams, B.3-B.6 models and Jacobians (finite differences), plane fit."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.bodies import MARS
from workbench.core.rotation import quat_boxplus, quat_from_rotvec, quat_multiply, quat_rotate
from workbench.models.radar import (
    beam_directions_G,
    mars_rate_M,
    plane_fit,
    slant_range_model,
    slant_range_sphere,
    velocity_out_model,
)

R_GROUND = MARS.reference_radius - 1440.0  # a terrain sphere for the tests [m]


def _state(rng: np.random.Generator, h_agl: float = 5000.0, tilt_deg: float = 15.0):
    """A descent state: position over the sphere, attitude with −Z_G tilted from the local down."""
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    p = (R_GROUND + h_agl) * u
    # q_M_G that maps −Z_G onto the local down −u, then a tilt about a random body axis and a spin
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, u)
    ang = np.arccos(np.clip(z @ u, -1, 1))
    q = quat_from_rotvec(axis / np.linalg.norm(axis) * ang)
    q = quat_multiply(q, quat_from_rotvec(np.array([0, 0, rng.uniform(0, 2 * np.pi)])))
    a = rng.uniform(0, 2 * np.pi)
    tilt_axis = np.array([np.cos(a), np.sin(a), 0.0])
    q = quat_multiply(q, quat_from_rotvec(np.deg2rad(tilt_deg) * tilt_axis))
    v = -80.0 * u + rng.normal(scale=20.0, size=3)
    assert np.isclose(quat_rotate(q, z) @ u, np.cos(np.deg2rad(tilt_deg)))
    return v, q, p


def _perturb(v, q, p, dx):
    return v + dx[0:3], quat_boxplus(q, dx[3:6]), p + dx[6:9]


def _fd_jacobian(fun, v, q, p, steps):
    y0 = np.atleast_1d(fun(v, q, p))
    J = np.zeros((y0.size, 9))
    for j in range(9):
        e = np.zeros(9)
        e[j] = steps[j]
        yp = np.atleast_1d(fun(*_perturb(v, q, p, e)))
        ym = np.atleast_1d(fun(*_perturb(v, q, p, -e)))
        J[:, j] = (yp - ym) / (2 * steps[j])
    return J


STEPS = np.array([1e-3] * 3 + [1e-6] * 3 + [1e-2] * 3)


def test_beam_geometry():
    B = beam_directions_G()
    assert B.shape == (4, 3)
    assert np.allclose(np.linalg.norm(B, axis=1), 1.0)
    assert np.allclose(B[0], [0, 0, -1])
    ang = np.rad2deg(np.arccos(-B[1:, 2]))
    assert np.allclose(ang, 20.0)
    az = np.rad2deg(np.arctan2(B[1:, 1], B[1:, 0])) % 360.0
    assert np.allclose(az, [0.0, 120.0, 240.0])
    assert np.allclose(
        beam_directions_G(10.0, (90.0, 210.0, 330.0))[1], [0, np.sin(np.deg2rad(10)), -np.cos(np.deg2rad(10))]
    )


@pytest.mark.parametrize("beam", [0, 1, 2, 3])
def test_slant_range_jacobian_matches_finite_differences(beam):
    rng = np.random.default_rng(10 + beam)
    s = beam_directions_G()[beam]
    for _ in range(5):
        v, q, p = _state(rng, h_agl=rng.uniform(1e3, 8e3), tilt_deg=rng.uniform(0, 25))
        y, H = slant_range_model(p, q, s, R_GROUND)
        assert H.shape == (1, 9) and np.ndim(y) == 0
        J = _fd_jacobian(lambda v_, q_, p_: slant_range_model(p_, q_, s, R_GROUND)[0], v, q, p, STEPS)
        for blk in (slice(0, 3), slice(3, 6), slice(6, 9)):  # relative error per error-state block
            scale = np.abs(J[:, blk]).max() + 1e-12
            assert np.all(np.abs(H[:, blk] - J[:, blk]) <= 1e-7 * scale + 1e-12), (H, J)
        # the literal B.4 (vertical frozen) differs only by O(h/|p|) in the position block
        _, Hb = slant_range_model(p, q, s, R_GROUND, exact=False)
        assert np.allclose(Hb[0, :6], H[0, :6])
        assert np.allclose(Hb[0, 6:], H[0, 6:], atol=5e-3 * np.abs(H[0, 6:]).max())


def test_slant_range_model_vs_exact_sphere_and_vectorised():
    rng = np.random.default_rng(3)
    B = beam_directions_G()
    v, q, p = _state(rng, h_agl=6000.0, tilt_deg=20.0)
    y, _ = slant_range_model(np.broadcast_to(p, (4, 3)), np.broadcast_to(q, (4, 4)), B, R_GROUND)
    ys = slant_range_sphere(p, q, B, R_GROUND)
    assert y.shape == (4,) and ys.shape == (4,)
    # flat plane vs sphere: the ground drops by x²/(2R) at horizontal distance x = ρ sin α
    cos_a = 6000.0 / y
    drop = (y * np.sqrt(1 - cos_a**2)) ** 2 / (2 * R_GROUND) / cos_a
    assert np.all(ys > y) and np.allclose(ys - y, drop, rtol=0.05)
    # vertical beam from straight above: both equal the AGL altitude
    u = p / np.linalg.norm(p)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, u)
    qv = quat_from_rotvec(axis / np.linalg.norm(axis) * np.arccos(z @ u))
    assert np.isclose(slant_range_model(p, qv, B[0], R_GROUND)[0], 6000.0)
    assert np.isclose(slant_range_sphere(p, qv, B[0], R_GROUND), 6000.0)
    # a beam looking up never hits
    assert np.isnan(slant_range_sphere(p, qv, -B[0], R_GROUND))  # no echo: NaN
    assert np.isinf(slant_range_model(p, qv, -B[0], R_GROUND)[0])


def test_slant_range_sphere_geometry_and_broadcasting():
    """Hand geometry: from straight above, B0 hits at the AGL height and the 20° beams by the law of
    cosines; p (n, 1, 3), q (n, 1, 4) with four beams (4, 3) give (n, 4); a miss is NaN."""
    import math

    h = 5000.0
    p = np.array([[0.0, 0.0, R_GROUND + h]])
    q = np.array([[0.0, 0.0, 0.0, 1.0]])  # Z_G up: B0 = −Z_G looks at the centre
    beams = beam_directions_G()
    rho = slant_range_sphere(p[:, None], q[:, None], beams, R_GROUND)
    assert rho.shape == (1, 4)
    assert math.isclose(rho[0, 0], h, rel_tol=1e-12)
    r0 = R_GROUND + h
    c = math.cos(math.radians(20.0))
    expect = r0 * c - math.sqrt(R_GROUND**2 - r0**2 * (1 - c * c))
    np.testing.assert_allclose(rho[0, 1:], expect, rtol=1e-12)
    up = np.array([1.0, 0.0, 0.0, 0.0])  # 180° about X: B0 looks up -> no echo
    assert np.isnan(slant_range_sphere(p[0], up, beams[0], R_GROUND))
    # a beam that passes beside the sphere misses too (NaN, not +inf)
    far = np.array([0.0, 0.0, 3.0 * R_GROUND])
    side = quat_from_rotvec(np.array([np.deg2rad(60.0), 0.0, 0.0]))  # −Z_G tilted 60° off the centre
    assert np.isnan(slant_range_sphere(far, side, beams[0], R_GROUND))


def test_velocity_out_model_and_jacobian():
    rng = np.random.default_rng(5)
    w = mars_rate_M()
    assert np.allclose(w, [0, 0, MARS.rotation_rate])
    for _ in range(5):
        v, q, p = _state(rng)
        y, H = velocity_out_model(v, q, p, w)
        assert y.shape == (3,) and H.shape == (3, 9)
        # co-rotating velocity rotated into G
        u_M = v - np.cross(w, p)
        assert np.allclose(quat_rotate(q, y), u_M)
        J = _fd_jacobian(lambda v_, q_, p_: velocity_out_model(v_, q_, p_, w)[0], v, q, p, STEPS)
        assert np.allclose(H, J, rtol=1e-6, atol=1e-7)


def test_plane_fit_exact_recovery_synthetic():
    rng = np.random.default_rng(7)
    B = beam_directions_G()
    for _ in range(20):
        tilt = np.deg2rad(rng.uniform(0, 30))
        az = rng.uniform(0, 2 * np.pi)
        n = np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), -np.cos(tilt)])
        d = rng.uniform(500, 8000)
        r = d / (B @ n)
        f = plane_fit(r, B)
        assert np.isclose(f.h_agl, d, rtol=1e-10)
        assert np.isclose(f.off_vertical, tilt, atol=1e-9)
        assert np.allclose(f.normal_G, n, atol=1e-9)
        assert f.rms < 1e-8 * d
        # invalid beam dropped: three points still define the plane exactly
        r2 = r.copy()
        r2[2] = 0.0
        f2 = plane_fit(r2, B)
        assert np.isclose(f2.h_agl, d, rtol=1e-10) and f2.rms < 1e-8 * d
    with pytest.raises(ValueError, match="valid"):
        plane_fit(np.array([0.0, 0.0, 100.0, 200.0]), B)


def test_plane_fit_reproduces_amelia_table4():
    """Table 4: the 20° / 120° beam geometry reproduces the paper's AGL and off-vertical angle.

    (Both are invariant to a rotation of the beam pattern about Z_G, so this pins the squint and
    the 120° spacing, not the azimuth origin.)
    """
    B = beam_directions_G()
    rda3 = plane_fit(np.array([5932.10, 6515.18, 6969.29, 5563.50]), B)
    rda4 = plane_fit(np.array([4764.35, 4966.60, 5051.11, 5237.19]), B)
    assert abs(rda3.h_agl - 5544.02) < 0.1 and abs(np.rad2deg(rda3.off_vertical) - 20.48) < 0.01
    assert abs(rda4.h_agl - 4755.66) < 0.1 and abs(np.rad2deg(rda4.off_vertical) - 4.89) < 0.01
    assert rda3.rms < 10.0 and rda4.rms < 10.0
