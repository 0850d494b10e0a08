"""Tests of workbench.estimation.strapdown (AMELIA Appendix A): RK4 against Kepler and a constant
spin, IMU inputs integrated back to their trajectory, the error-dynamics Jacobian against finite
differences of the RK4 step, the covariance against a Monte Carlo of the integrator, gap bridging."""

from __future__ import annotations

import importlib
from dataclasses import replace

import numpy as np
import pytest

from workbench.core.bodies import MARS, TITAN
from workbench.core.gravity import gravity_j2, gravity_point_mass_gradient
from workbench.core.rotation import attitude_error, quat_from_rotvec, quat_multiply, quat_normalize
from workbench.estimation import strapdown as sd

synth = importlib.import_module("entry_synth")  # tests/support, on sys.path via tests/conftest.py


def _boxplus(q, d):
    return quat_normalize(quat_multiply(q, quat_from_rotvec(d)))


def test_derivatives_use_gravity_j2_of_the_body_and_gradient():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(50, 3))
    p = p / np.linalg.norm(p, axis=1, keepdims=True) * rng.uniform(3.4e6, 4e6, (50, 1))
    z = np.zeros(3)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(sd.derivatives(z, q, p, z, z, body=MARS)[0], gravity_j2(p, MARS), rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(sd.derivatives(z, q, p[3], z, z, TITAN)[0], gravity_j2(p[3], TITAN), rtol=1e-14)
    # the single-state path equals a member of the vectorised one to the last bit
    np.testing.assert_array_equal(
        sd.derivatives(z, q, p[3], z, z, body=MARS)[0], sd.derivatives(z, q, p, z, z, body=MARS)[0][3]
    )
    # point-mass gradient vs central differences of the point-mass field
    x = p[0]
    G = gravity_point_mass_gradient(x, MARS.gm)
    h = 10.0
    fd = np.stack([(-MARS.gm * (x + e) / np.linalg.norm(x + e) ** 3 + MARS.gm * (x - e) / np.linalg.norm(x - e) ** 3)
                   / (2 * h) for e in h * np.eye(3)], -1)  # fmt: skip
    np.testing.assert_allclose(G, fd, rtol=1e-6, atol=1e-12)


def _kepler(p0, v0, t, gm):
    """Analytic two-body propagation (Kepler's equation, elliptic) of (p0, v0) to times t."""
    r0 = np.linalg.norm(p0)
    a = 1.0 / (2.0 / r0 - v0 @ v0 / gm)
    h = np.cross(p0, v0)
    e_vec = np.cross(v0, h) / gm - p0 / r0
    e = np.linalg.norm(e_vec)
    P = e_vec / e
    Q = np.cross(h / np.linalg.norm(h), P)
    cosE0 = (1 - r0 / a) / e
    sinE0 = (p0 @ v0) / (e * np.sqrt(gm * a))
    E0 = np.arctan2(sinE0, cosE0)
    n = np.sqrt(gm / a**3)
    M = E0 - e * np.sin(E0) + n * t
    E = M.copy()
    for _ in range(50):
        E = E - (E - e * np.sin(E) - M) / (1 - e * np.cos(E))
    b = a * np.sqrt(1 - e * e)
    pos = (a * (np.cos(E) - e))[:, None] * P + (b * np.sin(E))[:, None] * Q
    Ed = n / (1 - e * np.cos(E))
    vel = (-a * np.sin(E) * Ed)[:, None] * P + (b * np.cos(E) * Ed)[:, None] * Q
    return pos, vel


def test_rk4_vacuum_matches_kepler():
    body = replace(MARS, j2=0.0)  # point-mass gravity only: the planet is a parameter
    p0 = np.array([3.6e6, 0.4e6, 0.9e6])
    v0 = np.array([-300.0, 3300.0, 900.0])  # an inclined ellipse (e ~ 0.1)
    q0 = synth.Q0
    dt, n = 1.0, 600
    z = np.zeros(3)
    # a single state (scalar path) and two members (vectorised path) together
    v, q, p = v0, q0, p0
    V, Qm, Pm = np.tile(v0, (2, 1)), np.tile(q0, (2, 1)), np.tile(p0, (2, 1))
    for _ in range(n):
        v, q, p = sd.rk4_step(v, q, p, z, z, z, z, dt, body)
        V, Qm, Pm = sd.rk4_step(V, Qm, Pm, z, z, z, z, dt, body)
    pk, vk = _kepler(p0, v0, np.array([n * dt]), MARS.gm)
    assert np.linalg.norm(p - pk[0]) < 1e-3  # 600 s of orbit at 1 s steps: RK4 error ~ (dt/T)^4
    assert np.linalg.norm(v - vk[0]) < 1e-6
    np.testing.assert_array_equal(Pm[0], p)
    np.testing.assert_array_equal(V[1], v)
    np.testing.assert_allclose(q, q0, atol=1e-15)  # no rotation without rate


def test_rk4_j2_conserves_energy_and_polar_momentum():
    p, v = np.array([3.6e6, 0.4e6, 0.9e6]), np.array([-300.0, 3300.0, 900.0])
    q, z = synth.Q0, np.zeros(3)

    def energy(p, v):
        r = np.linalg.norm(p)
        s = p[2] / r
        U = MARS.gm / r * (1 - MARS.j2 * (MARS.equatorial_radius / r) ** 2 * 0.5 * (3 * s * s - 1))
        return 0.5 * v @ v - U

    E0, hz0 = energy(p, v), np.cross(p, v)[2]
    for _ in range(600):
        v, q, p = sd.rk4_step(v, q, p, z, z, z, z, 1.0, body=MARS)
    assert abs(energy(p, v) - E0) < 1e-6 * abs(E0)
    assert abs(np.cross(p, v)[2] - hz0) < 1e-9 * abs(hz0)


def test_rk4_constant_rate_spin_is_exact():
    w = np.array([0.3, -0.2, np.deg2rad(187.5)])  # up to the saturation rate
    q = synth.Q0
    v, p, z = np.zeros(3), np.array([3.5e6, 0, 0]), np.zeros(3)
    dt, n = 0.01, 500
    for _ in range(n):
        _, q, _ = sd.rk4_step(v, q, p, z, w, z, w, dt, body=MARS)
    q_exact = _boxplus(synth.Q0, w * dt * n)
    assert np.linalg.norm(attitude_error(q_exact, q)) < 5e-8  # RK4: ~(|w| dt)^5 per step, 57 rad in all
    assert abs(np.linalg.norm(q) - 1.0) < 1e-15


def test_imu_of_known_trajectory_integrates_back():
    errs = {}
    for dt in (0.1, 0.05):
        tr = synth.truth(dt=dt)
        imu = synth.make_imu(tr)
        out = sd.integrate_members(imu, tr["v"][0], tr["q"][0], tr["p"][0], body=MARS)
        k = tr["t"] < tr["events"]["PDD"]  # smooth inputs (the drag jumps at deployment: O(dt) there)
        dp = np.linalg.norm(out["p"] - tr["p"], axis=-1)
        dv = np.linalg.norm(out["v"] - tr["v"], axis=-1)
        dth = np.linalg.norm(attitude_error(tr["q"], out["q"]), axis=-1)
        errs[dt] = (dp[k].max(), dv[k].max(), dth[k].max(), dp.max(), dv.max())
    # 280 s of entry at 10 Hz (spinning at 16 °/s, up to 8 g): tens of metres, ~1 m/s, µrad
    dp, dv, dth, dp_all, dv_all = errs[0.1]
    assert dp < 150.0 and dv < 2.5 and dth < 2e-4 and dp_all < 150.0 and dv_all < 2.5
    # second order in the sampling interval (inputs linear between samples)
    assert errs[0.05][0] < errs[0.1][0] / 3.0
    assert errs[0.05][1] < errs[0.1][1] / 3.0
    assert errs[0.05][2] < errs[0.1][2] / 3.0


def _fd_transition(v, q, p, f0, w0, f1, w1, dt, eps):
    """Finite-difference error transition of one RK4 step: columns d(δx_out)/d(δx_in)."""
    v1, q1, p1 = sd.rk4_step(v, q, p, f0, w0, f1, w1, dt, body=MARS)
    F = np.zeros((9, 9))
    for j in range(9):
        cols = []
        for s in (+1.0, -1.0):
            d = np.zeros(9)
            d[j] = s * eps[j]
            vv, qq, pp = sd.rk4_step(v + d[0:3], _boxplus(q, d[3:6]), p + d[6:9], f0, w0, f1, w1, dt, body=MARS)
            cols.append(np.concatenate([vv - v1, attitude_error(q1, qq), pp - p1]))
        F[:, j] = (cols[0] - cols[1]) / (2 * eps[j])
    return F, (v1, q1, p1)


@pytest.mark.parametrize("dt", [0.1, 0.01])
def test_error_dynamics_matches_finite_differences_of_rk4(dt):
    v, q, p = synth.V0, _boxplus(synth.Q0, np.array([0.3, -0.1, 0.2])), synth.P0
    f0, f1 = np.array([3.0, -2.0, 60.0]), np.array([3.5, -1.0, 62.0])
    w0, w1 = np.array([0.05, -0.1, 0.28]), np.array([0.06, -0.12, 0.30])
    eps = np.r_[np.full(3, 1e-1), np.full(3, 1e-3), np.full(3, 10.0)]  # central differences
    F_fd, (v1, q1, p1) = _fd_transition(v, q, p, f0, w0, f1, w1, dt, eps)
    qm = quat_normalize(q + q1)
    _, Phi, Qd = sd.covariance_step(np.eye(9), qm, 0.5 * (f0 + f1), 0.5 * (w0 + w1), dt, 0.0, 0.0, dt, None,
                                    0.5 * (p + p1), body=MARS)  # fmt: skip
    # compare Φ − I block by block relative to the block's scale.  Mid-point A (first Magnus term):
    # O(dt²) relative on δv/δθ, O(|Δf|/|f|) on δp←δθ (the double integral weights the start of the
    # step); the gravity gradient is point-mass only (J2 changes it by ~0.3 %).
    rel = {(0, 1): 1e-3, (1, 1): 1e-3, (2, 1): 1e-2, (0, 2): 1e-2, (2, 0): 1e-6}
    D = F_fd - np.eye(9)
    for (r, c), tol in rel.items():
        a, b = (Phi - np.eye(9))[3 * r : 3 * r + 3, 3 * c : 3 * c + 3], D[3 * r : 3 * r + 3, 3 * c : 3 * c + 3]
        assert np.abs(a - b).max() < tol * np.abs(b).max(), (r, c, a, b)
    for r, c in ((0, 0), (1, 0), (1, 2), (2, 2)):  # (nearly) zero blocks of Φ − I
        assert np.abs(D[3 * r : 3 * r + 3, 3 * c : 3 * c + 3]).max() < 2e-8 * max(dt / 0.1, 1.0)
    np.testing.assert_array_equal(Qd, 0.0)
    # continuous A: the structure of Eq. A.14 (right perturbation)
    A, B = sd.error_dynamics(q, f0, w0, body=MARS)
    from workbench.core.rotation import quat_to_dcm, skew

    C = quat_to_dcm(q)
    np.testing.assert_allclose(A[0:3, 3:6], -C @ skew(f0))
    np.testing.assert_allclose(A[3:6, 3:6], -skew(w0))
    np.testing.assert_array_equal(A[6:9, 0:3], np.eye(3))
    np.testing.assert_allclose(B[0:3, 3:6], C)
    np.testing.assert_array_equal(B[3:6, 0:3], np.eye(3))
    # vectorised over leading axes
    A2, B2 = sd.error_dynamics(np.stack([q, q]), np.stack([f0, f1]), w0, body=MARS)
    np.testing.assert_allclose(A2[0], A)
    assert A2.shape == (2, 9, 9) and B2.shape == (2, 9, 6)


def test_covariance_matches_monte_carlo_of_the_integrator():
    """2000 members with a perturbed initial state and their own noisy IMU samples, 30 s of entry
    at 10 Hz (near peak deceleration): sample covariance vs the propagated P (within ~10 %)."""
    tr = synth.truth()
    k0, n_steps, m = 1100, 300, 2000
    sl = slice(k0, k0 + n_steps + 1)
    t, f, w = tr["t"][sl], tr["f_G"][sl], tr["w_G"][sl]
    sig_f, sig_w = 0.3, np.deg2rad(0.3)
    imu = synth.SynthIMU(t=t, f_G=f, w_G=w, sigma_f=np.full(f.shape, sig_f), sigma_w=np.full(w.shape, sig_w))
    v0, q0, p0 = tr["v"][k0], tr["q"][k0], tr["p"][k0]
    s0 = np.r_[np.full(3, 2.0), np.full(3, np.deg2rad(0.2)), np.full(3, 100.0)]
    P0 = np.diag(s0**2)
    res = sd.integrate(imu, v0, q0, p0, P0, body=MARS)
    rng = np.random.default_rng(7)
    d0 = rng.standard_normal((m, 9)) * s0
    V, Q, X = v0 + d0[:, 0:3], _boxplus(q0, d0[:, 3:6]), p0 + d0[:, 6:9]
    nf = rng.standard_normal((t.size, m, 3)) * sig_f
    nw = rng.standard_normal((t.size, m, 3)) * sig_w
    for k in range(n_steps):
        V, Q, X = sd.rk4_step(V, Q, X, f[k] + nf[k], w[k] + nw[k], f[k + 1] + nf[k + 1], w[k + 1] + nw[k + 1],
                              t[k + 1] - t[k], body=MARS)  # fmt: skip
    err = np.concatenate([V - res.v_M[-1], attitude_error(res.q_M_G[-1], Q), X - res.p_M[-1]], axis=1)
    err = err - err.mean(axis=0)
    C_mc = err.T @ err / (m - 1)
    P = res.P[-1]
    ratio = np.diagonal(C_mc) / np.diagonal(P)
    assert np.all(np.abs(ratio - 1.0) < 0.10), ratio
    # the input noise matters (not only the initial state) and correlations agree too
    assert np.trace(P[3:6, 3:6]) > 1.5 * np.trace(P0[3:6, 3:6])
    sd_ = np.sqrt(np.diagonal(P))
    corr_p, corr_mc = P / np.outer(sd_, sd_), C_mc / np.outer(sd_, sd_)
    assert np.abs(corr_p - corr_mc).max() < 0.1


def test_integrate_pass_structure_and_consistency():
    tr = synth.truth()
    imu = synth.make_imu(tr, gaps=[(20.0, 77.2), (100.0, 101.4)])
    P0 = np.diag(np.r_[np.full(3, 10.0**2), np.full(3, np.deg2rad(1.0) ** 2), np.full(3, 2000.0**2)])
    res = sd.integrate(imu, tr["v"][0], tr["q"][0], tr["p"][0], P0, body=MARS)
    n = imu.t.size
    assert res.P.shape == res.Phi.shape == res.Qd.shape == (n, 9, 9)
    np.testing.assert_array_equal(res.Phi[0], np.eye(9))
    assert res.bridged.sum() == 2
    for k in (1, 50, int(np.flatnonzero(res.bridged)[0]), n - 1):
        np.testing.assert_allclose(res.P[k], res.Phi[k] @ res.P[k - 1] @ res.Phi[k].T + res.Qd[k], rtol=1e-10,
                                   atol=1e-12 * np.abs(res.P[k]).max())  # fmt: skip
    np.testing.assert_array_equal(res.P, np.swapaxes(res.P, 1, 2))
    assert np.all(np.linalg.eigvalsh(res.P) > 0)
    # the same states as the covariance-free member integration
    out = sd.integrate_members(imu, tr["v"][0], tr["q"][0], tr["p"][0], body=MARS)
    np.testing.assert_array_equal(out["p"], res.p_M)
    # position and velocity σ grow through the long gap (Δt·δv plus the bridge's own noise)
    ka = int(np.flatnonzero(res.bridged)[0]) - 1
    dt_gap = imu.t[ka + 1] - imu.t[ka]
    Pa, Pb = res.P[ka], res.P[ka + 1]
    assert np.trace(Pb[6:9, 6:9]) > np.trace(Pa[6:9, 6:9]) + 0.5 * dt_gap**2 * np.trace(Pa[0:3, 0:3])
    assert np.trace(Pb[0:3, 0:3]) > np.trace(Pa[0:3, 0:3])
    # and the truth stays within 3σ of the integrated state all along (noise-free inputs)
    kk = np.searchsorted(tr["t"], imu.t)
    e = np.concatenate([tr["v"][kk] - res.v_M, attitude_error(res.q_M_G, tr["q"][kk]), tr["p"][kk] - res.p_M], 1)
    assert np.all(np.abs(e) <= 3.0 * np.sqrt(np.diagonal(res.P, axis1=1, axis2=2)))


@pytest.mark.parametrize("mode", ["relative", "paper"])
def test_gap_bridge_reproduces_the_trajectory(mode):
    tr = synth.truth()
    imu = synth.make_imu(tr, gaps=[(20.0, 77.2)])
    g = imu.gaps[0]
    ia, ib = (int(np.argmin(abs(tr["t"] - x))) for x in (g.t_a, g.t_b))
    v, q, p = sd.apply_gap(tr["v"][ia], tr["q"][ia], tr["p"][ia], g, mode)
    np.testing.assert_allclose(v, tr["v"][ib], atol=1e-9)
    np.testing.assert_allclose(p, tr["p"][ib], atol=1e-6)
    assert np.linalg.norm(attitude_error(tr["q"][ib], q)) < 1e-12
    # vectorised over members
    V, Q, X = sd.apply_gap(np.tile(tr["v"][ia], (3, 1)), np.tile(tr["q"][ia], (3, 1)), np.tile(tr["p"][ia], (3, 1)),
                           g, mode)  # fmt: skip
    np.testing.assert_allclose(X[2], p, rtol=0, atol=1e-9)
    # the integration across the gap ends as close to the truth as without the gap
    out = sd.integrate_members(imu, tr["v"][0], tr["q"][0], tr["p"][0], bridge_mode=mode, body=MARS)
    kk = np.searchsorted(tr["t"], imu.t)
    assert np.linalg.norm(out["p"] - tr["p"][kk], axis=-1).max() < 150.0


def test_gap_transition_matches_finite_differences():
    tr = synth.truth()
    g = synth.make_imu(tr, gaps=[(20.0, 77.2)]).gaps[0]
    ia = int(np.argmin(abs(tr["t"] - g.t_a)))
    v, q, p = tr["v"][ia], tr["q"][ia], tr["p"][ia]
    for mode in ("relative", "paper"):
        Phi, Qd = sd.gap_transition(q, p, g, mode, gap_sigma=(0.1, 1e-5, 5.0), body=MARS)
        v1, q1, p1 = sd.apply_gap(v, q, p, g, mode)
        eps = np.r_[np.full(3, 1e-2), np.full(3, 1e-7), np.full(3, 1.0)]
        F = np.zeros((9, 9))
        for j in range(9):
            d = np.zeros(9)
            d[j] = eps[j]
            vv, qq, pp = sd.apply_gap(v + d[0:3], _boxplus(q, d[3:6]), p + d[6:9], g, mode)
            F[:, j] = np.concatenate([vv - v1, attitude_error(q1, qq), pp - p1]) / eps[j]
        # the bridge itself ignores gravity over the gap (G terms are the *true* error's growth)
        Phi_nog = Phi.copy()
        Phi_nog[0:3, 6:9] = 0.0
        Phi_nog[6:9, 6:9] = np.eye(3)
        if mode == "paper":
            Phi_nog[6:9, 0:3] = 0.0  # the paper bridge does not use our velocity
        np.testing.assert_allclose(F, Phi_nog, atol=2e-5 * np.abs(Phi).max(), rtol=1e-4)
        dt = g.t_b - g.t_a
        np.testing.assert_allclose(np.diagonal(Qd), np.repeat(np.array([0.1, 1e-5, 5.0]) * dt, 3) ** 2)
