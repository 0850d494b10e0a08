"""Tests of workbench.estimation.ekf: layout, Jacobians, update variants, gating, Joseph, driver."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from workbench.core.rotation import (
    attitude_error,
    quat_boxplus,
    quat_conjugate,
    quat_from_rotvec,
    quat_normalize,
    quat_rotate,
    quat_to_dcm,
    skew,
)
from workbench.estimation.consistency import is_symmetric_pd
from workbench.estimation.ekf import (
    ErrorStateLayout,
    Measurement,
    numeric_measurement_jacobian,
    numeric_transition_jacobian,
    predict,
    run_filter,
    update,
)


def _random_quats(rng, n):
    return quat_normalize(rng.standard_normal((n, 4)))


def _right_jacobian(phi):
    a = np.linalg.norm(phi)
    K = skew(phi)
    return np.eye(3) - (1 - np.cos(a)) / a**2 * K + (a - np.sin(a)) / a**3 * K @ K


# --------------------------------------------------------------------------- layout


def test_layout_indices_and_validation():
    lay = ErrorStateLayout(13, ((6, 6),))
    assert lay.n_e == 12
    with pytest.raises(ValueError):
        ErrorStateLayout(6, ((4, 0),))  # quaternion runs past the end
    with pytest.raises(ValueError):
        ErrorStateLayout(8, ((0, 0), (2, 3)))  # overlapping quaternions


def test_boxplus_boxminus_roundtrip_vectorised_and_single():
    rng = np.random.default_rng(1)
    lay = ErrorStateLayout(12, ((3, 3), (8, 7)))  # [a(3), q(4), b(1), q(4)] -> e [a, θ, b, θ] = 10
    assert lay.n_e == 10
    n = 50
    x = rng.standard_normal((n, 12))
    x[:, 3:7] = _random_quats(rng, n)
    x[:, 8:12] = _random_quats(rng, n)
    dx = 0.5 * rng.standard_normal((n, 10))
    xp = lay.boxplus(x, dx)
    # additive part
    np.testing.assert_allclose(xp[:, :3], x[:, :3] + dx[:, :3], rtol=0, atol=1e-15)
    np.testing.assert_allclose(xp[:, 7], x[:, 7] + dx[:, 6], rtol=0, atol=1e-15)
    # quaternion part is q ⊗ exp(δθ)
    np.testing.assert_allclose(xp[:, 3:7], quat_boxplus(x[:, 3:7], dx[:, 3:6]), atol=1e-15)
    np.testing.assert_allclose(xp[:, 8:12], quat_boxplus(x[:, 8:12], dx[:, 7:10]), atol=1e-15)
    # x_ref ⊞ (x ⊟ x_ref) == x, and the error is the inverse of ⊞
    back = lay.boxminus(xp, x)
    np.testing.assert_allclose(back, dx, atol=1e-12)
    np.testing.assert_allclose(back[:, 3:6], attitude_error(x[:, 3:7], xp[:, 3:7]), atol=1e-12)
    # single-state fast path == vectorised path
    for i in range(n):
        np.testing.assert_allclose(lay.boxplus(x[i], dx[i]), xp[i], atol=1e-15)
        np.testing.assert_allclose(lay.boxminus(xp[i], x[i]), back[i], atol=1e-14)
    # tiny angles (Taylor branches) agree as well
    tiny = 1e-9 * rng.standard_normal(10)
    np.testing.assert_allclose(lay.boxplus(x[0], tiny), lay.boxplus(x[:1], tiny[None])[0], atol=1e-16)
    np.testing.assert_allclose(lay.boxminus(lay.boxplus(x[0], tiny), x[0]), tiny, atol=1e-15)
    # normalise
    x2 = x.copy()
    x2[:, 3:7] *= 3.0
    np.testing.assert_allclose(np.linalg.norm(lay.normalize(x2)[:, 3:7], axis=1), 1.0)


# --------------------------------------------------------------------------- Jacobians


SENSOR = np.array([2.0, -1.0])


def _range_bearing(x):
    d = x[:2] - SENSOR
    return np.array([np.hypot(d[0], d[1]), np.arctan2(d[1], d[0])])


def _range_bearing_H(x):
    d = x[:2] - SENSOR
    r2 = d @ d
    r = np.sqrt(r2)
    return np.array([[d[0] / r, d[1] / r, 0, 0], [-d[1] / r2, d[0] / r2, 0, 0]])


def _wrap_residual(z, zp):
    y = z - zp
    y[1] = (y[1] + np.pi) % (2 * np.pi) - np.pi
    return y


def test_numeric_measurement_jacobian_range_bearing():
    lay = ErrorStateLayout(4)
    rng = np.random.default_rng(2)
    for _ in range(20):
        x = np.concatenate([SENSOR + rng.uniform(-50, 50, 2), rng.standard_normal(2)])
        H = numeric_measurement_jacobian(_range_bearing, x, lay)
        np.testing.assert_allclose(H, _range_bearing_H(x), rtol=1e-7, atol=1e-9)
    # across the ±π bearing cut only the wrapping residual gives the right derivative
    x = np.array([SENSOR[0] - 10.0, SENSOR[1] + 1e-7, 0, 0])
    H_wrap = numeric_measurement_jacobian(_range_bearing, x, lay, residual=_wrap_residual)
    np.testing.assert_allclose(H_wrap, _range_bearing_H(x), rtol=1e-6, atol=1e-9)
    H_plain = numeric_measurement_jacobian(_range_bearing, x, lay)
    assert abs(H_plain[1, 1]) > 1e3  # the plain difference jumps by 2π


def test_update_numeric_H_equals_analytic_H():
    lay = ErrorStateLayout(4)
    x = np.array([30.0, 40.0, 1.0, -1.0])
    P = np.diag([25.0, 16.0, 1.0, 1.0])
    R = np.diag([0.5**2, 0.01**2])
    z = _range_bearing(x) + np.array([1.0, -0.02])
    a = update(x, P, z, _range_bearing, R, lay, H=_range_bearing_H, residual=_wrap_residual)
    b = update(x, P, z, _range_bearing, R, lay, residual=_wrap_residual)
    np.testing.assert_allclose(b.H, a.H, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(b.x_post, a.x_post, rtol=1e-7)
    np.testing.assert_allclose(b.P_post, a.P_post, rtol=1e-6, atol=1e-9)


def _unicycle(x, dt=0.5, omega=0.3):
    px, py, v, psi = x
    return np.array([px + v * np.cos(psi) * dt, py + v * np.sin(psi) * dt, v, psi + omega * dt])


def _unicycle_F(x, dt=0.5):
    _, _, v, psi = x
    return np.array(
        [
            [1, 0, np.cos(psi) * dt, -v * np.sin(psi) * dt],
            [0, 1, np.sin(psi) * dt, v * np.cos(psi) * dt],
            [0, 0, 1, 0],
            [0, 0, 0, 1],
        ]
    )


def test_predict_numeric_F_equals_analytic_and_symmetric():
    lay = ErrorStateLayout(4)
    x = np.array([1.0, 2.0, 7.0, 0.8])
    P = np.diag([1.0, 2.0, 0.5, 0.1])
    Q = np.diag([0.01, 0.01, 0.1, 0.001])
    num = predict(x, P, _unicycle, Q, lay)
    ana = predict(x, P, _unicycle, Q, lay, F=_unicycle_F(x))
    cal = predict(x, P, _unicycle, Q, lay, F=_unicycle_F)
    np.testing.assert_allclose(num.F, ana.F, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(num.P_prior, ana.P_prior, rtol=1e-8)
    np.testing.assert_array_equal(cal.P_prior, ana.P_prior)
    np.testing.assert_array_equal(num.P_prior, num.P_prior.T)
    np.testing.assert_array_equal(num.x_prior, _unicycle(x))


def test_numeric_F_quaternion_body_error_matches_analytic():
    """x = [q, b]: q⁺ = q ⊗ exp((ω_m − b) dt); F_θθ = C(exp(φ))ᵀ, F_θb = −J_r(φ) dt (φ = ω̂ dt)."""
    lay = ErrorStateLayout(7, ((0, 0),))
    dt = 0.1
    omega_m = np.array([1.5, -2.0, 2.5])
    x = np.concatenate([quat_normalize(np.array([0.3, -0.2, 0.5, 0.8])), [0.1, 0.05, -0.2]])

    def f(x):
        return np.concatenate([quat_boxplus(x[:4], (omega_m - x[4:]) * dt), x[4:]])

    phi = (omega_m - x[4:]) * dt
    F = np.eye(6)
    F[:3, :3] = quat_to_dcm(quat_from_rotvec(phi)).T
    F[:3, 3:] = -_right_jacobian(phi) * dt
    np.testing.assert_allclose(numeric_transition_jacobian(f, x, lay), F, atol=1e-8)


# --------------------------------------------------------------------------- update variants


def _random_prior_case(seed: int):
    """(layout, x (4,), random SPD P (4, 4), R (2, 2), range-bearing z (2,)) of the update tests."""
    rng = np.random.default_rng(seed)
    x = np.array([30.0, 40.0, 1.0, -1.0])
    A = rng.standard_normal((4, 4))
    z = _range_bearing(x) + np.array([0.4, 0.01])
    return ErrorStateLayout(4), x, A @ A.T + np.eye(4), np.diag([0.3, 0.02]), z


def test_single_update_matches_textbook_formulas():
    lay, x, P, R, z = _random_prior_case(3)
    res = update(x, P, z, _range_bearing, R, lay, H=_range_bearing_H)
    H = _range_bearing_H(x)
    y = z - _range_bearing(x)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    np.testing.assert_allclose(res.y, y)
    np.testing.assert_allclose(res.S, S, rtol=1e-12)
    np.testing.assert_allclose(res.K, K, rtol=1e-10)
    np.testing.assert_allclose(res.x_post, x + K @ y, rtol=1e-12)
    np.testing.assert_allclose(res.P_post, (np.eye(4) - K @ H) @ P, rtol=1e-9, atol=1e-12)
    assert res.nis == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-12)
    assert res.accepted
    # iterations=1 is exactly the single update
    one = update(x, P, z, _range_bearing, R, lay, H=_range_bearing_H, iterations=1)
    np.testing.assert_array_equal(one.x_post, res.x_post)
    np.testing.assert_array_equal(one.P_post, res.P_post)


def test_iterated_update_with_linear_model_equals_single():
    rng = np.random.default_rng(4)
    lay = ErrorStateLayout(3)
    H = rng.standard_normal((2, 3))
    P = np.diag([4.0, 1.0, 9.0])
    x = rng.standard_normal(3)
    z = rng.standard_normal(2)
    a = update(x, P, z, lambda s: H @ s, np.eye(2), lay, H=H)
    b = update(x, P, z, lambda s: H @ s, np.eye(2), lay, H=lambda s: H, iterations=5)
    np.testing.assert_allclose(b.x_post, a.x_post, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(b.P_post, a.P_post, rtol=1e-12)


def test_projected_gain_update_is_joseph_of_projected_gain():
    """``gain_projector``: K = Π P Hᵀ S⁻¹, the state moves only inside range(Π), and P_post is the
    Joseph form of that (sub-optimal) gain — larger in trace than the optimal update's."""
    lay, x, P, R, z = _random_prior_case(6)
    Pi = np.diag([1.0, 1.0, 0.0, 0.0])
    res = update(x, P, z, _range_bearing, R, lay, H=_range_bearing_H, gain_projector=lambda s: Pi)
    H = _range_bearing_H(x)
    K = Pi @ P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    J = np.eye(4) - K @ H
    np.testing.assert_allclose(res.K, K, rtol=1e-10)
    np.testing.assert_array_equal(res.x_post[2:], x[2:])
    np.testing.assert_allclose(res.x_post, x + K @ (z - _range_bearing(x)), rtol=1e-12)
    np.testing.assert_allclose(res.P_post, J @ P @ J.T + K @ R @ K.T, rtol=1e-9, atol=1e-12)
    opt = update(x, P, z, _range_bearing, R, lay, H=_range_bearing_H)
    assert np.trace(res.P_post) > np.trace(opt.P_post)
    # gate by threshold: the same decision as by probability
    far = z + np.array([100.0, 0.0])
    assert not update(x, P, far, _range_bearing, R, lay, H=_range_bearing_H, gate_threshold=9.21).accepted
    assert update(x, P, z, _range_bearing, R, lay, H=_range_bearing_H, gate_threshold=9.21).accepted


def test_iterated_update_absolute_step_rule_and_undefined_iterate():
    """``step_tol``: a coarse absolute rule stops after fewer Gauss-Newton steps than the default
    relative rule (different result), a fine one reaches the same fixed point; an iterate where h
    is NaN ends the iterations at the previous iterate (here: the single update)."""
    lay = ErrorStateLayout(2)
    m = np.array([3.0, 0.5])
    P = np.diag([4.0, 0.01])
    station = np.array([0.0, 0.0])

    def h(s):
        return np.array([np.hypot(*(s - station))])

    def Hf(s):
        return ((s - station) / np.hypot(*(s - station)))[None]

    z = np.array([1.0])
    R = np.array([[1e-4]])
    ref = update(m, P, z, h, R, lay, H=Hf, iterations=50)
    fine = update(m, P, z, h, R, lay, H=Hf, iterations=50, step_tol=np.full(2, 1e-12))
    coarse = update(m, P, z, h, R, lay, H=Hf, iterations=50, step_tol=np.full(2, 1.0))
    np.testing.assert_allclose(fine.x_post, ref.x_post, atol=1e-10)
    assert np.max(np.abs(coarse.x_post - ref.x_post)) > 1e-6
    calls = []

    def h_nan(s):
        calls.append(s)
        return h(s) if len(calls) == 1 else np.array([np.nan])

    one = update(m, P, z, h, R, lay, H=Hf)
    stop = update(m, P, z, h_nan, R, lay, H=Hf, iterations=10)
    np.testing.assert_array_equal(stop.x_post, one.x_post)
    np.testing.assert_array_equal(stop.P_post, one.P_post)
    assert len(calls) == 2


def test_iterated_update_reduces_error_on_strongly_nonlinear_range():
    """Range to a near station with a prior elongated across the line of sight: the single
    linearisation misses the curvature of the range circle; Gauss-Newton iterations reach the
    MAP point (lower MAP cost) and a smaller position error on average."""
    lay = ErrorStateLayout(2)
    rng = np.random.default_rng(1)
    m = np.array([10.0, 15.0])
    P = np.diag([1.0, 100.0])
    sr = 0.1
    R = np.array([[sr**2]])

    def h(x):
        return np.array([np.hypot(x[0], x[1])])

    def Hf(x):
        return (x / np.hypot(x[0], x[1]))[None]

    err1, err_it, cost1, cost_it = [], [], [], []
    for _ in range(200):
        xt = rng.multivariate_normal(m, P)
        z = h(xt) + sr * rng.standard_normal(1)

        def cost(x, z=z):
            return (x - m) @ np.linalg.solve(P, x - m) + float(np.sum(((z - h(x)) / sr) ** 2))

        one = update(m, P, z, h, R, lay, H=Hf)
        it = update(m, P, z, h, R, lay, H=Hf, iterations=20)
        np.testing.assert_array_equal(it.y, one.y)  # innovation of the prior linearisation
        err1.append(np.linalg.norm(one.x_post - xt))
        err_it.append(np.linalg.norm(it.x_post - xt))
        cost1.append(cost(one.x_post))
        cost_it.append(cost(it.x_post))
    err1, err_it = np.array(err1), np.array(err_it)
    cost1, cost_it = np.array(cost1), np.array(cost_it)
    assert np.sqrt(np.mean(err_it**2)) < 0.95 * np.sqrt(np.mean(err1**2))
    assert np.mean(cost_it <= cost1 + 1e-9) > 0.95
    assert np.mean(cost_it) < 0.5 * np.mean(cost1)


def test_iterated_update_numeric_H_runs_and_agrees_with_analytic():
    lay = ErrorStateLayout(2)
    m = np.array([10.0, 15.0])
    P = np.diag([1.0, 100.0])

    def h(x):
        return np.array([np.hypot(x[0], x[1])])

    z = np.array([22.0])
    a = update(m, P, z, h, 0.01, lay, H=lambda x: (x / np.hypot(*x))[None], iterations=10)
    b = update(m, P, z, h, 0.01, lay, iterations=10)
    np.testing.assert_allclose(b.x_post, a.x_post, rtol=1e-7)


def test_iterated_update_on_quaternion_state_converges_to_measured_attitude():
    """Two precise vector observations of an attitude 0.5 rad away from the prior: the single
    update stops short (linearisation), the iterated one (⊞/⊟ in the body frame) converges."""
    lay = ErrorStateLayout(4, ((0, 0),))
    refs = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    q_hat = quat_normalize(np.array([0.1, 0.2, -0.1, 0.95]))
    q_true = quat_boxplus(q_hat, np.array([0.3, -0.35, 0.2]))

    def h(x):
        return quat_rotate(quat_conjugate(x[:4]), refs).ravel()

    def H(x):
        return np.vstack([skew(v) for v in h(x).reshape(2, 3)])

    z = h(q_true)
    P = 0.4**2 * np.eye(3)
    R = 1e-6 * np.eye(6)
    one = update(q_hat, P, z, h, R, lay, H=H)
    it = update(q_hat, P, z, h, R, lay, H=H, iterations=10)
    err_one = np.linalg.norm(attitude_error(one.x_post, q_true))
    err_it = np.linalg.norm(attitude_error(it.x_post, q_true))
    assert err_one > 0.02
    assert err_it < 1e-3
    np.testing.assert_allclose(np.linalg.norm(it.x_post), 1.0, atol=1e-14)
    # numeric H (body-frame perturbation of the quaternion) gives the same iterate
    num = update(q_hat, P, z, h, R, lay, iterations=10)
    np.testing.assert_allclose(num.x_post, it.x_post, atol=1e-7)


def test_layout_pickles_for_distributed_runs():
    lay = ErrorStateLayout(13, ((6, 6),))
    lay2 = pickle.loads(pickle.dumps(lay))
    assert lay2 == lay and hash(lay2) == hash(lay)
    x = np.zeros(13)
    x[9] = 1.0
    np.testing.assert_array_equal(lay2.boxplus(x, np.ones(12) * 0.1), lay.boxplus(x, np.ones(12) * 0.1))


# --------------------------------------------------------------------------- gating, Joseph


def test_gate_rejects_gross_outlier_and_keeps_state():
    lay = ErrorStateLayout(4)
    x = np.array([30.0, 40.0, 1.0, -1.0])
    P = np.diag([4.0, 4.0, 1.0, 1.0])
    R = np.diag([0.5**2, 0.01**2])
    good = _range_bearing(x) + np.array([0.5, 0.005])
    bad = _range_bearing(x) + np.array([500.0, 0.0])
    ok = update(x, P, good, _range_bearing, R, lay, H=_range_bearing_H, gate_probability=0.999)
    assert ok.accepted and not np.array_equal(ok.x_post, x)
    rej = update(x, P, bad, _range_bearing, R, lay, H=_range_bearing_H, gate_probability=0.999)
    assert not rej.accepted
    np.testing.assert_array_equal(rej.x_post, x)
    np.testing.assert_array_equal(rej.P_post, P)
    assert rej.nis > 1e3
    np.testing.assert_allclose(rej.y, [500.0, 0.0], atol=1e-9)
    assert rej.S.shape == (2, 2)
    # without a gate the same outlier is applied
    assert update(x, P, bad, _range_bearing, R, lay, H=_range_bearing_H).accepted


def test_joseph_form_keeps_P_symmetric_pd_with_badly_scaled_R():
    """R mixes a near-perfect channel (1e-8) with a poor one (1e6) against P ~ 1e6 (ratio 1e14).
    With these draws the short form P − K H P loses definiteness in a few percent of cases."""
    lay = ErrorStateLayout(4)
    rng = np.random.default_rng(0)
    for _ in range(300):
        A = rng.standard_normal((4, 4))
        P = A @ A.T * 1e6 + 1e-2 * np.eye(4)
        H = rng.standard_normal((2, 4))
        R = np.diag([1e-8, 1e6])
        res = update(np.zeros(4), P, np.zeros(2), lambda x, H=H: H @ x, R, lay, H=H)
        ok, min_eig = is_symmetric_pd(res.P_post, tol=0.0)
        assert ok, min_eig
        # the near-perfect channel collapses from ~1e6 to the noise scale (roundoff floor ~1e-9)
        assert 0.0 < H[0] @ res.P_post @ H[0] < 1e-7


def test_non_pd_innovation_covariance_raises():
    lay = ErrorStateLayout(2)
    with pytest.raises(np.linalg.LinAlgError):
        update(
            np.zeros(2),
            np.zeros((2, 2)),
            np.zeros(1),
            lambda x: x[:1],
            np.array([[-1.0]]),
            lay,
            H=np.array([[1.0, 0.0]]),
        )


# --------------------------------------------------------------------------- driver


def _cv_problem(n=30, dt=0.5):
    F = np.array([[1.0, dt], [0.0, 1.0]])
    Q = 0.01 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    H = np.array([[1.0, 0.0]])
    t = dt * np.arange(n)
    rng = np.random.default_rng(5)
    z = rng.standard_normal(n) + 0.3 * t
    return F, Q, H, t, z


def test_run_filter_bookkeeping_gating_and_gains():
    F, Q, H, t, z = _cv_problem()
    n = t.size
    lay = ErrorStateLayout(2)
    z = z.copy()
    z[7] += 1e4  # gross outlier
    calls = []

    def adapt_q(k, x, P, Qk):
        calls.append(k)
        return 2.0 * Qk if k == 10 else Qk

    def meas(k, tk, x):
        if k % 3 == 2:
            return []
        out = [Measurement("pos", np.array([z[k]]), np.array([[1.0]]), lambda s: H @ s, H, gate_probability=0.999)]
        if k % 5 == 0:
            out.append(Measurement("vel", np.array([0.3]), np.array([[0.04]]), lambda s: s[1:], None))
        return out

    x0 = np.zeros(2)
    P0 = np.diag([10.0, 1.0])
    fp = run_filter(
        x0, P0, t, lambda x, a, b: (F @ x, F), lambda x, a, b: Q, meas, lay, adapt_q=adapt_q, keep_gains=True
    )
    assert calls == list(range(1, n))
    np.testing.assert_array_equal(fp.x_prior[0], x0)
    np.testing.assert_array_equal(fp.P_prior[0], P0)
    np.testing.assert_array_equal(fp.F[0], np.eye(2))
    np.testing.assert_array_equal(fp.Q[0], 0.0)
    np.testing.assert_array_equal(fp.Q[10], 2.0 * Q)
    np.testing.assert_array_equal(fp.Q[11], Q)
    pos = fp.innovations["pos"]
    present = np.arange(n) % 3 != 2
    np.testing.assert_array_equal(pos.step, np.flatnonzero(present))
    np.testing.assert_array_equal(pos.t, t[present])
    k = pos.step.size
    assert pos.y.shape == (k, 1) and pos.S.shape == (k, 1, 1) and pos.nis.shape == (k,)
    assert np.all(np.isfinite(pos.y)) and np.all(np.isfinite(pos.S)) and np.all(np.isfinite(pos.nis))
    np.testing.assert_array_equal(pos.z[:, 0], z[present])
    np.testing.assert_allclose(pos.y, pos.z - pos.z_pred)
    np.testing.assert_allclose(pos.z_pred[:, 0], fp.x_prior[present, 0])  # pos first at every step
    assert pos.K.shape == (k, 2, 1) and np.all(np.isfinite(pos.K))
    # outlier at step 7 rejected: posterior == prior there (no vel measurement at 7)
    assert not pos.accepted[pos.step == 7].any()
    assert pos.accepted[pos.step != 7].all()
    np.testing.assert_array_equal(fp.x_post[7], fp.x_prior[7])
    np.testing.assert_array_equal(fp.P_post[7], fp.P_prior[7])
    # steps without measurements
    np.testing.assert_array_equal(fp.x_post[2], fp.x_prior[2])
    vel = fp.innovations["vel"]
    np.testing.assert_array_equal(vel.step, np.flatnonzero((np.arange(n) % 5 == 0) & present))
    # sequential processing at step 0: pos then vel, posterior equals two explicit updates
    r1 = update(x0, P0, [z[0]], lambda s: H @ s, [[1.0]], lay, H=H)
    r2 = update(r1.x_post, r1.P_post, [0.3], lambda s: s[1:], [[0.04]], lay)
    np.testing.assert_allclose(fp.x_post[0], r2.x_post, rtol=1e-9)
    np.testing.assert_allclose(fp.P_post[0], r2.P_post, rtol=1e-9)
    # prediction step k uses the posterior of k-1
    np.testing.assert_allclose(fp.x_prior[1], F @ fp.x_post[0])
    np.testing.assert_allclose(fp.P_prior[1], F @ fp.P_post[0] @ F.T + Q, rtol=1e-12)
    # without keep_gains no K is stored
    fp2 = run_filter(x0, P0, t, lambda x, a, b: (F @ x, F), lambda x, a, b: Q, meas, lay)
    assert fp2.innovations["pos"].K is None


def test_run_filter_numeric_transition_matches_analytic():
    lay = ErrorStateLayout(4)
    t = 0.5 * np.arange(20)

    def meas(k, tk, x):
        return [
            Measurement(
                "rb",
                _range_bearing(np.array([1.0 + k, 2.0, 0, 0])),
                np.diag([0.25, 1e-4]),
                _range_bearing,
                _range_bearing_H,
                residual=_wrap_residual,
            )
        ]

    Q = np.diag([0.01, 0.01, 0.1, 0.001])
    x0 = np.array([1.0, 2.0, 2.0, 0.1])
    P0 = np.diag([1.0, 1.0, 0.5, 0.1])
    a = run_filter(x0, P0, t, lambda x, t0, t1: (_unicycle(x), _unicycle_F(x)), lambda *_: Q, meas, lay)
    b = run_filter(x0, P0, t, lambda x, t0, t1: (_unicycle(x), None), lambda *_: Q, meas, lay)
    np.testing.assert_allclose(b.F, a.F, atol=1e-8)
    np.testing.assert_allclose(b.x_post, a.x_post, rtol=1e-7, atol=1e-8)


def test_run_filter_repeated_name_at_one_step_and_size_change_reported():
    """A channel may be measured twice at one step (two rows, sequential updates); a size change
    of a channel and a failing update are reported with the step."""
    lay = ErrorStateLayout(1)

    def meas(k, tk, x):
        m = Measurement("a", np.array([1.0]), np.array([[1.0]]), lambda s: s, np.eye(1))
        return [m, m] if k == 2 else [m]

    fp = run_filter(
        np.zeros(1), np.eye(1), np.arange(4.0), lambda x, a, b: (x, np.eye(1)), lambda *_: np.eye(1), meas, lay
    )
    a = fp.innovations["a"]
    np.testing.assert_array_equal(a.step, [0, 1, 2, 2, 3])
    r1 = update(fp.x_prior[2], fp.P_prior[2], [1.0], lambda s: s, [[1.0]], lay, H=np.eye(1))
    r2 = update(r1.x_post, r1.P_post, [1.0], lambda s: s, [[1.0]], lay, H=np.eye(1))
    np.testing.assert_allclose(a.y[2:4, 0], [r1.y[0], r2.y[0]])
    np.testing.assert_allclose(fp.x_post[2], r2.x_post)

    def grow(k, tk, x):
        return [Measurement("a", np.zeros(1 + (k == 2)), np.eye(1 + (k == 2)), lambda s: np.repeat(s, 1 + (k == 2)))]

    with pytest.raises(ValueError, match="step 2.*changed size"):
        run_filter(
            np.zeros(1), np.eye(1), np.arange(4.0), lambda x, a, b: (x, np.eye(1)), lambda *_: np.eye(1), grow, lay
        )

    def bad(k, tk, x):
        if k != 1:
            return []
        return [Measurement("b", np.array([0.0]), np.array([[-5.0]]), lambda s: s, np.eye(1))]

    with pytest.raises(np.linalg.LinAlgError, match="step 1.*'b'"):
        run_filter(
            np.zeros(1), np.eye(1), np.arange(4.0), lambda x, a, b: (x, np.eye(1)), lambda *_: np.eye(1), bad, lay
        )


def test_run_filter_transition_with_own_q_and_slotted_records():
    """``transition`` may return (x, F, Q) with ``process_noise=None``; a measurement carrying
    ``slots`` of a channel of ``size`` components is recorded NaN-padded to that size."""
    lay = ErrorStateLayout(3)
    Q = np.diag([0.1, 0.2, 0.3])

    def meas(k, tk, x):
        slots = np.array([0, 2]) if k % 2 else np.array([1])
        return [Measurement("c", np.ones(slots.size), np.eye(slots.size), lambda s, i=slots: s[i], slots=slots, size=3)]

    fp = run_filter(np.zeros(3), np.eye(3), np.arange(4.0), lambda x, a, b: (x, np.eye(3), Q), None, meas, lay)
    np.testing.assert_allclose(fp.P_prior[1], fp.P_post[0] + Q)
    c = fp.innovations["c"]
    assert c.y.shape == (4, 3) and c.S.shape == (4, 3, 3)
    np.testing.assert_array_equal(np.isnan(c.y[1]), [False, True, False])
    np.testing.assert_array_equal(np.isnan(c.y[0]), [True, False, True])
    np.testing.assert_array_equal(np.isnan(c.S[1]), ~np.outer([1, 0, 1], [1, 0, 1]).astype(bool))
    np.testing.assert_array_equal(c.z[1], [1.0, np.nan, 1.0])
    np.testing.assert_allclose(c.y[1][[0, 2]], 1.0 - fp.x_prior[1][[0, 2]])


def test_numeric_jacobian_batched_equals_the_per_column_functions():
    """One vectorised call gives the numbers of numeric_transition_jacobian / numeric_measurement_jacobian
    (quaternion block included)."""
    from workbench.core.rotation import quat_integrate_body_rate
    from workbench.estimation.ekf import (
        ErrorStateLayout,
        numeric_jacobian_batched,
        numeric_measurement_jacobian,
        numeric_transition_jacobian,
    )

    layout = ErrorStateLayout(7, ((0, 0),))  # x = [q (4), w (3)], e = [dθ (3), w (3)]

    def f(x):
        x = np.atleast_2d(x)
        out = x.copy()
        out[:, :4] = quat_integrate_body_rate(x[:, :4], x[:, 4:7], 0.1)
        out[:, 4:7] = x[:, 4:7] * 0.99
        return out

    def h(x):
        x = np.atleast_2d(x)
        return np.column_stack([x[:, 4] * x[:, 5], np.sin(x[:, 6]), x[:, 3]])

    x = np.array([0.1, -0.2, 0.3, 0.9, 0.2, -0.1, 0.05])
    x[:4] /= np.linalg.norm(x[:4])
    eps = np.full(6, 1e-6)
    fx, F = numeric_jacobian_batched(f, x, layout, eps, out_layout=layout)
    np.testing.assert_allclose(fx, f(x)[0])
    np.testing.assert_allclose(F, numeric_transition_jacobian(lambda z: f(z)[0], x, layout, eps), rtol=1e-9, atol=1e-12)
    hx, H = numeric_jacobian_batched(h, x, layout, eps)
    np.testing.assert_allclose(
        H, numeric_measurement_jacobian(lambda z: h(z)[0], x, layout, eps=eps), rtol=1e-9, atol=1e-12
    )


def test_numeric_jacobian_batched_rows_are_the_boxplus_of_each_column():
    """The batch handed to f is [x, x ⊞ ε e_0, …, x ⊞ −ε e_0, …] to the bit (one ⊞ call over the 2 n_e
    perturbations gives each row's own numbers), with and without quaternion blocks."""
    from workbench.estimation.ekf import ErrorStateLayout, numeric_jacobian_batched

    rng = np.random.default_rng(2)
    for layout in (ErrorStateLayout(9, ()), ErrorStateLayout(12, ((2, 2),))):
        x = rng.normal(size=layout.n_x)
        for ix, _ in layout.quat_blocks:
            x[ix : ix + 4] /= np.linalg.norm(x[ix : ix + 4])
        eps = 10.0 ** rng.uniform(-7, -2, layout.n_e)
        seen = []

        def f(X, seen=seen):
            seen.append(X.copy())
            return X[:, :2]

        numeric_jacobian_batched(f, x, layout, eps)
        D = np.diag(eps)
        expect = np.vstack([x[None, :]] + [layout.boxplus(x, s * D[j]) for s in (1.0, -1.0) for j in range(layout.n_e)])
        np.testing.assert_array_equal(seen[0], expect)
