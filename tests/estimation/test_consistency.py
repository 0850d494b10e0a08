"""Tests of workbench.estimation.consistency, and Monte Carlo consistency of the EKF + RTS smoother
(constant-velocity system and a quaternion attitude filter)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

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
from workbench.estimation.consistency import (
    anees_bounds,
    chi2_interval,
    fraction_inside,
    is_symmetric_pd,
    mixture_hdr_level,
    nees,
    nis,
    whiteness,
)
from workbench.estimation.ekf import ErrorStateLayout, Measurement, run_filter
from workbench.estimation.smoother import rts_smooth

# --------------------------------------------------------------------------- unit tests


def test_nees_nis_match_explicit_formula():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((10, 3, 3))
    P = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3)
    e = rng.standard_normal((10, 3))
    expect = np.array([e[i] @ np.linalg.inv(P[i]) @ e[i] for i in range(10)])
    np.testing.assert_allclose(nees(e, P), expect, rtol=1e-10)
    np.testing.assert_allclose(nis(e, P), expect, rtol=1e-10)
    assert nees(e[0], P[0]).shape == ()


def test_chi2_bounds():
    lo, hi = chi2_interval(3, 0.95)
    assert lo == pytest.approx(chi2.ppf(0.025, 3)) and hi == pytest.approx(chi2.ppf(0.975, 3))
    lo, hi = anees_bounds(2, 100, 0.95)
    assert lo == pytest.approx(chi2.ppf(0.025, 200) / 100)
    assert hi == pytest.approx(chi2.ppf(0.975, 200) / 100)
    assert lo < 2 < hi and hi - lo < 1.2


def test_fraction_inside_ignores_nan():
    v = np.array([0.5, 1.0, 2.0, np.nan, 5.0])
    assert fraction_inside(v, 0.8, 2.5) == pytest.approx(0.5)


def test_is_symmetric_pd_flags_asymmetric_indefinite_and_nan():
    P = np.stack([np.eye(2), [[1.0, 0.1], [0.0, 1.0]], [[1.0, 2.0], [2.0, 1.0]], np.full((2, 2), np.nan)])
    ok, min_eig = is_symmetric_pd(P)
    np.testing.assert_array_equal(ok, [True, False, False, False])
    assert min_eig[0] == pytest.approx(1.0) and min_eig[2] == pytest.approx(-1.0)
    assert np.isnan(min_eig[3])


def test_whiteness_separates_white_from_coloured():
    rng = np.random.default_rng(1)
    w = rng.standard_normal(2000)
    acf, band, frac = whiteness(w, 20)
    assert acf[0] == pytest.approx(1.0) and band == pytest.approx(1.96 / np.sqrt(2000))
    assert frac < 0.15
    ar = np.empty_like(w)
    ar[0] = w[0]
    for i in range(1, w.size):
        ar[i] = 0.8 * ar[i - 1] + w[i]
    acf, _, frac_ar = whiteness(np.column_stack([ar, w]), 20)
    assert acf.shape == (21, 2)
    assert acf[1, 0] == pytest.approx(0.8, abs=0.05)
    assert frac_ar > 0.4
    # NaN rows (absent samples) are dropped
    wn = w.copy()
    wn[::10] = np.nan
    assert whiteness(wn, 5)[1] == pytest.approx(1.96 / np.sqrt(1800))


# --------------------------------------------------------------------------- constant velocity MC

DT = 1.0
F_CV = np.array([[1.0, DT], [0.0, 1.0]])
Q_CV = 0.1 * np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]])
H_CV = np.array([[1.0, 0.0]])
R_CV = np.array([[1.0]])
M0 = np.array([0.0, 1.0])
P0_CV = np.diag([4.0, 1.0])


def _simulate_cv(rng, n):
    x = np.empty((n, 2))
    x[0] = rng.multivariate_normal(M0, P0_CV)
    for k in range(1, n):
        x[k] = F_CV @ x[k - 1] + rng.multivariate_normal(np.zeros(2), Q_CV)
    z = x[:, 0] + rng.standard_normal(n) * np.sqrt(R_CV[0, 0])
    return x, z


def _filter_cv(z, q_scale=1.0):
    lay = ErrorStateLayout(2)
    Qf = q_scale * Q_CV

    def meas(k, tk, x):
        if k % 4 == 1:  # some steps without measurements
            return []
        return [Measurement("pos", z[k : k + 1], R_CV, lambda s: H_CV @ s, H_CV)]

    fp = run_filter(M0, P0_CV, DT * np.arange(z.size), lambda x, a, b: (F_CV @ x, F_CV), lambda x, a, b: Qf, meas, lay)
    return fp, rts_smooth(fp, lay)


def _cv_monte_carlo(n_runs, n_steps, q_scale=1.0, seed=10):
    rng = np.random.default_rng(seed)
    nees_f = np.empty((n_runs, n_steps))
    nees_s = np.empty((n_runs, n_steps))
    nis_r = []
    for r in range(n_runs):
        x, z = _simulate_cv(rng, n_steps)
        fp, sp = _filter_cv(z, q_scale)
        nees_f[r] = nees(fp.x_post - x, fp.P_post)
        nees_s[r] = nees(sp.x - x, sp.P)
        nis_r.append(fp.innovations["pos"].nis)
    return nees_f, nees_s, np.array(nis_r)


@pytest.mark.slow
def test_cv_monte_carlo_nees_nis_inside_bounds():
    n_runs, n_steps = 100, 40
    nees_f, nees_s, nis_r = _cv_monte_carlo(n_runs, n_steps)
    lo, hi = anees_bounds(2, n_runs)
    for name, v in (("forward", nees_f), ("smoothed", nees_s)):
        anees = v.mean(axis=0)  # per step, over runs
        assert lo <= anees.mean() <= hi, (name, anees.mean(), lo, hi)
        assert fraction_inside(anees, lo, hi) >= 0.85, name
    lo1, hi1 = anees_bounds(1, n_runs)
    assert nis_r.shape[1] == n_steps - n_steps // 4  # one NIS per measured step
    anis = nis_r.mean(axis=0)
    assert lo1 <= anis.mean() <= hi1
    assert fraction_inside(anis, lo1, hi1) >= 0.85
    # smoothing helps: smaller mean squared position error than filtering (same NEES scale)
    assert np.isfinite(nees_s).all()


@pytest.mark.slow
def test_cv_monte_carlo_detects_mistuned_filter():
    """The same statistics flag a filter whose process noise is 30x too small (power of the test)."""
    nees_f, _, nis_r = _cv_monte_carlo(100, 40, q_scale=1.0 / 30.0)
    _, hi = anees_bounds(2, 100)
    assert nees_f.mean(axis=0).mean() > hi
    assert nis_r.mean() > anees_bounds(1, 100)[1]


def test_cv_innovations_white_when_tuned():
    rng = np.random.default_rng(3)
    _, z = _simulate_cv(rng, 600)
    fp, _ = _filter_cv(z)
    pos = fp.innovations["pos"]
    _, _, frac = whiteness(pos.y[:, 0] / np.sqrt(pos.S[:, 0, 0]), 15)
    assert frac <= 0.2


# --------------------------------------------------------------------------- attitude MC (MEKF)

DT_A = 0.1
SIG_G = 0.01  # gyro white noise per sample [rad/s]
SIG_B = 2e-4  # bias random walk per step [rad/s]
SIG_V = 0.02  # vector measurement noise per axis [-] (unit vectors)
REFS_N = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.5]])
REFS_N = REFS_N / np.linalg.norm(REFS_N, axis=1, keepdims=True)
P0_ATT = np.diag([0.05**2] * 3 + [0.005**2] * 3)
Q_ATT = np.diag([(SIG_G * DT_A) ** 2] * 3 + [SIG_B**2] * 3)
LAYOUT_ATT = ErrorStateLayout(7, ((0, 0),))


def _omega_true(t):
    return np.stack([0.3 * np.sin(0.5 * t), 0.2 * np.cos(0.3 * t), 0.1 + 0 * t], -1)


def _simulate_attitude(rng, n, q_hat0):
    """Truth q_N_B, bias, gyro samples and vector measurements for one run."""
    t = DT_A * np.arange(n)
    q = np.empty((n, 4))
    b = np.empty((n, 3))
    q[0] = quat_boxplus(q_hat0, rng.standard_normal(3) * 0.05)  # q_true = q̂ ⊗ exp(δθ)
    b[0] = rng.standard_normal(3) * 0.005
    w = _omega_true(t)
    for k in range(1, n):
        q[k] = quat_boxplus(q[k - 1], w[k - 1] * DT_A)
        b[k] = b[k - 1] + SIG_B * rng.standard_normal(3)
    gyro = w + b + SIG_G * rng.standard_normal((n, 3))
    # gyro[k] is the sample used over [t_k, t_{k+1}] (bias b[k])
    vec = quat_rotate(quat_conjugate(q)[:, None, :], REFS_N[None]) + SIG_V * rng.standard_normal((n, 2, 3))
    return q, b, gyro, vec


def _attitude_filter(q_hat0, gyro, vec, numeric=False):
    def transition(x, t0, t1):
        k = int(round(t0 / DT_A))
        phi = (gyro[k] - x[4:]) * DT_A
        x_next = np.concatenate([quat_boxplus(x[:4], phi), x[4:]])
        if numeric:
            return x_next, None
        F = np.eye(6)
        F[:3, :3] = quat_to_dcm(quat_from_rotvec(phi)).T
        F[:3, 3:] = -DT_A * np.eye(3)
        return x_next, F

    def make_h(r):
        def h(x):
            return quat_rotate(quat_conjugate(x[:4]), r)

        def H(x):
            out = np.zeros((3, 6))
            out[:, :3] = skew(h(x))
            return out

        return h, H

    hs = [make_h(r) for r in REFS_N]
    R = SIG_V**2 * np.eye(3)

    def meas(k, tk, x):
        if k % 5:
            return []
        return [Measurement(f"v{i}", vec[k, i], R, hs[i][0], hs[i][1]) for i in range(2)]

    x0 = np.concatenate([q_hat0, np.zeros(3)])
    n = gyro.shape[0]
    fp = run_filter(x0, P0_ATT, DT_A * np.arange(n), transition, lambda x, a, b: Q_ATT, meas, LAYOUT_ATT)
    return fp, rts_smooth(fp, LAYOUT_ATT)


@pytest.mark.slow
def test_attitude_filter_monte_carlo_anees_and_pd():
    n_runs, n_steps = 50, 100
    rng = np.random.default_rng(20)
    q_hat0 = quat_normalize(np.array([0.1, -0.3, 0.2, 0.9]))
    nees_f = np.empty((n_runs, n_steps))
    nees_s = np.empty((n_runs, n_steps))
    for r in range(n_runs):
        q, b, gyro, vec = _simulate_attitude(rng, n_steps, q_hat0)
        fp, sp = _attitude_filter(q_hat0, gyro, vec)
        for P in (fp.P_prior, fp.P_post, sp.P):
            ok, min_eig = is_symmetric_pd(P, tol=0.0)
            assert ok.all(), min_eig.min()
        np.testing.assert_allclose(np.linalg.norm(fp.x_post[:, :4], axis=1), 1.0, atol=1e-12)
        err_f = attitude_error(fp.x_post[:, :4], q)  # q_true = q̂ ⊗ exp(δθ)
        err_s = attitude_error(sp.x[:, :4], q)
        nees_f[r] = nees(err_f, fp.P_post[:, :3, :3])
        nees_s[r] = nees(err_s, sp.P[:, :3, :3])
    lo, hi = anees_bounds(3, n_runs)
    for name, v in (("forward", nees_f), ("smoothed", nees_s)):
        anees = v.mean(axis=0)
        assert lo <= anees.mean() <= hi, (name, anees.mean(), lo, hi)
        assert fraction_inside(anees, lo, hi) >= 0.8, (name, fraction_inside(anees, lo, hi))


def test_attitude_filter_numeric_F_matches_analytic_to_first_order():
    rng = np.random.default_rng(21)
    q_hat0 = quat_normalize(np.array([0.1, -0.3, 0.2, 0.9]))
    _, _, gyro, vec = _simulate_attitude(rng, 30, q_hat0)
    fa, _ = _attitude_filter(q_hat0, gyro, vec)
    fn, _ = _attitude_filter(q_hat0, gyro, vec, numeric=True)
    # analytic uses F_θb = −dt I; the exact (numeric) one is −dt J_r(φ) ≈ −dt (I − ½[φ×]), |φ| ≲ 0.05 rad
    np.testing.assert_allclose(fn.F, fa.F, atol=0.03 * DT_A)
    phi = (gyro[:-1] - fn.x_post[:-1, 4:]) * DT_A  # F_θθ = C(exp(φ))ᵀ at the numeric filter's own states
    F_tt = np.swapaxes(quat_to_dcm(quat_from_rotvec(phi)), 1, 2)
    np.testing.assert_allclose(fn.F[1:, :3, :3], F_tt, atol=1e-8)
    np.testing.assert_allclose(fn.x_post, fa.x_post, atol=1e-4)


def test_chi2_gate_against_closed_forms():
    """χ²(2) has cdf 1 − exp(−x/2), so its p-quantile is −2 ln(1 − p); χ²(1) at 95 % is 1.95996² (the
    two-sided normal 95 % point squared)."""
    from workbench.estimation.consistency import chi2_gate

    for p in (0.5, 0.9, 0.99, 0.9999):
        assert chi2_gate(p, 2) == pytest.approx(-2.0 * np.log(1.0 - p), rel=1e-12)
    assert chi2_gate(0.95, 1) == pytest.approx(1.959963984540054**2, rel=1e-12)
    assert chi2_gate(0.95, 4) > chi2_gate(0.95, 3) > chi2_gate(0.9, 3)
    # the upper end of the two-sided interval is the gate at (1 + p) / 2
    assert chi2_interval(3, 0.9)[1] == pytest.approx(chi2_gate(0.95, 3), rel=1e-14)


def test_mixture_hdr_level_of_one_gaussian_is_the_chi2_cdf_and_a_ring_contains_its_rim():
    rng = np.random.default_rng(7)
    P = np.array([[4.0, 1.0], [1.0, 2.0]])
    x = np.array([3.0, -2.0])
    d2 = float(x @ np.linalg.solve(P, x))
    level = mixture_hdr_level(x, np.zeros((1, 2)), P[None], np.ones(1), rng)
    assert level == pytest.approx(chi2.cdf(d2, 2), abs=0.01)
    # a ring of radius 100 (headings around a circle) with 5-unit blur: a point on the far side of the
    # rim is inside its 3 sigma region, while the moment-matched Gaussian centred on the middle puts
    # the centre (no mass there) inside and a point 2x the radius out far beyond
    ang = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    means = 100.0 * np.column_stack([np.cos(ang), np.sin(ang)])
    covs = np.tile(25.0 * np.eye(2), (72, 1, 1))
    assert mixture_hdr_level(np.array([-100.0, 3.0]), means, covs, np.ones(72), rng) < 0.9
    assert mixture_hdr_level(np.array([0.0, 0.0]), means, covs, np.ones(72), rng) > 0.9973
    assert mixture_hdr_level(np.array([200.0, 0.0]), means, covs, np.ones(72), rng) > 0.9973
