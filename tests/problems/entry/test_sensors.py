"""Entry instruments and on-board navigation (workbench.problems.entry.sensors): the pieces the synthetic
Schiaparelli telemetry is built from."""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import attitude_error, quat_from_rotvec, quat_multiply, quat_normalize, quat_rotate
from workbench.problems.entry.sensors import (
    EntryImuModel,
    NominalErrorModel,
    apply_imu_errors,
    nominal_state,
    quat_cumprod,
    strapdown_onboard,
    terrain_relative_velocity_G,
)

R_GROUND = MARS.reference_radius - 1440.0


def test_quat_cumprod_matches_sequential_product():
    rng = np.random.default_rng(1)
    q = quat_normalize(rng.normal(size=(37, 4)))
    ref = [q[0]]
    for k in range(1, q.shape[0]):
        ref.append(quat_multiply(ref[-1], q[k]))
    out = quat_cumprod(q)
    dots = np.abs(np.sum(out * np.array(ref), axis=1))
    assert np.all(dots > 1 - 1e-12)


def test_strapdown_free_fall_matches_ode_solver():
    t = np.arange(0.0, 200.0 + 1e-9, 0.01)
    p0 = np.array([-1317.4e3, 3254.9e3, -223.9e3]) * 1.03
    v0 = np.array([-4963.6, -3313.8, 832.6])
    z = np.zeros((t.size, 3))
    sol = strapdown_onboard(t, z, z, v0, np.array([0.0, 0.0, 0.0, 1.0]), p0)
    ode = solve_ivp(lambda _, y: np.r_[y[3:], gravity_j2(y[:3], MARS)], (0, 200), np.r_[p0, v0], rtol=1e-12, atol=1e-6)
    assert np.linalg.norm(sol.p_M[-1] - ode.y[:3, -1]) < 0.05
    assert np.linalg.norm(sol.v_M[-1] - ode.y[3:, -1]) < 1e-3
    assert np.allclose(sol.a_M_total, gravity_j2(sol.p_M, MARS))


def test_strapdown_attitude_constant_rate_is_exact():
    t = np.arange(0.0, 30.0 + 1e-9, 0.01)
    w = np.tile(np.radians([3.0, -16.0, 40.0]), (t.size, 1))
    q0 = quat_normalize(np.array([0.1, -0.2, 0.3, 0.9]))
    sol = strapdown_onboard(t, np.zeros_like(w), w, np.zeros(3), q0, np.array([0.0, 0.0, 4e6]))
    ref = quat_multiply(q0, quat_from_rotvec(w * t[:, None]))
    assert np.max(np.linalg.norm(attitude_error(ref, sol.q_M_G), axis=1)) < 1e-9


def test_gyro_clipped_at_its_range():
    rng = np.random.default_rng(0)
    w = np.radians(np.array([[250.0, -10.0, 16.0], [-300.0, 190.0, 0.0]]))
    _, wm, _ = apply_imu_errors(np.zeros_like(w), w, EntryImuModel(), rng)
    assert np.allclose(np.degrees(wm[:, 0]), [187.5, -187.5])
    assert math.isclose(np.degrees(wm[1, 1]), 187.5)


def test_nominal_state_error_convention():
    v0, p0 = np.array([1.0, 2.0, 3.0]), np.array([3.4e6, 0.0, 0.0])
    q0 = quat_normalize(np.array([0.3, 0.1, -0.2, 0.9]))
    dx = (1.0, -2.0, 3.0, 0.01, -0.02, 0.005, 1000.0, -2000.0, 500.0)
    v, q, p, dx0 = nominal_state(v0, q0, p0, NominalErrorModel(dx0=dx), np.random.default_rng(0))
    assert np.allclose(v + dx0[:3], v0) and np.allclose(p + dx0[6:], p0)
    assert np.allclose(attitude_error(q, q0), dx0[3:6], atol=1e-12)


def test_terrain_relative_velocity_zero_for_a_point_fixed_to_mars():
    p = np.array([[3.39e6, 1.0e5, 2.0e5]])
    v = np.cross([0.0, 0.0, MARS.rotation_rate], p)
    q = quat_normalize(np.array([[0.2, 0.3, -0.1, 0.9]]))
    assert np.allclose(terrain_relative_velocity_G(p, v, q), 0.0, atol=1e-9)
    v2 = v + np.array([[0.0, 0.0, -80.0]])
    assert np.allclose(quat_rotate(q, terrain_relative_velocity_G(p, v2, q)), [[0, 0, -80.0]])


def test_imu_errors_bias_scale_misalignment_and_fixed_draw():
    """y = (1 + s)(x + m × x) + b: the per-run errors act as stated, and a fixed set is used as given."""
    f = np.tile([0.0, 0.0, 50.0], (4, 1))
    w = np.tile(np.radians([0.0, 0.0, 16.0]), (4, 1))
    errs = (
        (1e-3, -2e-3, 3e-3),
        (0.0, 0.0, 3e-4),
        (2e-4, 0.0, 0.0),
        (1e-6, 0.0, 0.0),
        (0.0, 0.0, 1e-4),
        (0.0, 2e-4, 0.0),
    )
    model = EntryImuModel(accel_noise=0.0, gyro_noise=0.0, errors=errs)
    fm, wm, drawn = apply_imu_errors(f, w, model, np.random.default_rng(0))
    assert np.allclose(drawn["accel_bias"], errs[0])
    # misalignment about X tips the 50 m/s² Z force onto −Y; scale 300 ppm on Z; bias on every axis
    np.testing.assert_allclose(fm[0], [1e-3, -2e-3 - 2e-4 * 50.0, 50.0 * (1 + 3e-4) + 3e-3], atol=1e-12)
    np.testing.assert_allclose(
        wm[0], np.radians([0.0, 0.0, 16.0]) * [0, 0, 1 + 1e-4] + [1e-6 + 2e-4 * np.radians(16.0), 0, 0], atol=1e-15
    )


def test_disperse_telemetry_spec_fixes_the_per_run_errors():
    from workbench.problems.entry.sensors import IMU_ERROR_NAMES, EntryTelemetrySpec, disperse_telemetry_spec

    spec = EntryTelemetrySpec()
    rng = np.random.default_rng(4)
    draws = [disperse_telemetry_spec(spec, rng) for _ in range(400)]
    assert draws[0].imu.errors != draws[1].imu.errors and draws[0].nominal.dx0 != draws[1].nominal.dx0
    e = np.array([d.imu.errors for d in draws])  # (400, 6, 3)
    for i, name in enumerate(IMU_ERROR_NAMES):
        assert (
            np.std(e[:, i]) == np.float64(np.std(e[:, i])) and abs(np.std(e[:, i]) / getattr(spec.imu, name) - 1) < 0.1
        )
    # the fixed errors are what the telemetry then carries
    f = np.zeros((3, 3))
    _, _, drawn = apply_imu_errors(f, f, draws[0].imu, np.random.default_rng(9))
    assert np.allclose(drawn["gyro_scale"], draws[0].imu.errors[4])
