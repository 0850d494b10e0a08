"""In-flight magnetometer alignment (estimation/magnetometer.py) on a synthetic coning body."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.rotation import quat_from_rotvec, quat_history_from_body_rates, quat_to_dcm
from workbench.estimation.magnetometer import align_magnetometer


def _coning(n=1500, dt=0.011):
    """Body rates of a rolling (4 rad/s) and coning rocket whose long axis lies in the IMU x-y plane."""
    t = np.arange(n) * dt
    axis = np.array([-1.0, 1.0, 0.0]) / np.sqrt(2.0)
    w = 4.0 * axis[None, :] + np.column_stack([0.6 * np.sin(1.3 * t), 0.4 * np.cos(0.7 * t), 0.8 * np.sin(0.9 * t)])
    return t, w


def test_attitude_history_matches_a_constant_rate_rotation():
    t = np.linspace(0.0, 2.0, 201)
    w = np.array([0.3, -0.2, 1.1])
    q = quat_history_from_body_rates(t, np.tile(w, (t.size, 1)))
    np.testing.assert_allclose(quat_to_dcm(q[-1]), quat_to_dcm(quat_from_rotvec(w * 2.0)), atol=1e-12)
    np.testing.assert_allclose(q[0], [0.0, 0.0, 0.0, 1.0])


@pytest.mark.parametrize("turn_deg", [-134.0, -45.0, 100.0])
def test_recovers_the_magnetometer_axes_offset_and_field(turn_deg):
    rng = np.random.default_rng(3)
    t, w = _coning()
    C_0_B = quat_to_dcm(quat_history_from_body_rates(t, w))
    field_0 = np.array([-20.0, 12.0, 44.0])  # µT in the IMU frame at t0 (dip ~ 62 deg if z is down)
    C = quat_to_dcm(quat_from_rotvec(np.radians([5.0, -3.0, turn_deg])))  # IMU -> magnetometer axes
    offset = np.array([1.5, -13.0, 2.0])
    m = (np.swapaxes(C_0_B, -1, -2) @ field_0) @ C.T + offset + rng.normal(0.0, 0.5, (t.size, 3))
    fit = align_magnetometer(C_0_B, m)
    np.testing.assert_allclose(fit.C_mag_imu, C, atol=2e-3)
    np.testing.assert_allclose(fit.offset, offset, atol=0.1)
    np.testing.assert_allclose(fit.field_0, field_0, atol=0.1)
    assert fit.rms == pytest.approx(0.5, rel=0.05)
    np.testing.assert_allclose(fit.to_imu(m[0]), field_0, atol=2.0)  # one noisy sample at t0


def test_a_mirrored_magnetometer_comes_back_as_a_rotation_with_the_field_reversed():
    # a reflection M is the proper rotation -M with the field's sign flipped: the rotating body cannot
    # tell them apart, so the fit (det = +1) returns the reversed field - whose dip (up, not down)
    # is what the caller's check against the site's inclination catches
    t, w = _coning()
    C_0_B = quat_to_dcm(quat_history_from_body_rates(t, w))
    field_0 = np.array([-20.0, 12.0, 44.0])
    mirror = np.diag([1.0, 1.0, -1.0])
    fit = align_magnetometer(C_0_B, (np.swapaxes(C_0_B, -1, -2) @ field_0) @ mirror.T)
    assert np.linalg.det(fit.C_mag_imu) == pytest.approx(1.0)
    np.testing.assert_allclose(fit.C_mag_imu, -mirror, atol=1e-9)
    np.testing.assert_allclose(fit.field_0, -field_0, atol=1e-9)


def test_too_few_samples():
    with pytest.raises(ValueError, match="at least 10"):
        align_magnetometer(np.tile(np.eye(3), (5, 1, 1)), np.zeros((5, 3)))
