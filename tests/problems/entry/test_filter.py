"""Radar-aided entry smoother (AMELIA Sect. 8): constrained updates, split steps, RTS, consistency.

Synthetic kinematic descent: constant inertial velocity (80 m/s down + 10 m/s east relative to
the rotating ground) from 8 km above the terrain sphere, attitude = local vertical ⊗ slow spin
⊗ two pendulum swings; the IMU senses f_G = −C_G_M g(p) and the analytic body rate, plus white
noise; radar ranges by exact ray-sphere intersection (+ noise), velocity-out = C_G_M (v − Ω p).
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import (
    attitude_error,
    dcm_to_quat,
    quat_boxplus,
    quat_from_rotvec,
    quat_multiply,
    quat_rotate,
    quat_to_dcm,
)
from workbench.estimation.consistency import anees_bounds, is_symmetric_pd, nees
from workbench.estimation.strapdown import GapBridge, ImuArrays, integrate
from workbench.models.radar import (
    beam_directions_G,
    mars_rate_M,
    slant_range_model,
    slant_range_sphere,
    velocity_out_model,
)
from workbench.problems.entry.filter import (
    EntryFilterSigmas,
    RadarData,
    gain_projector,
    radar_measurement,
    radar_update,
    run_entry_smoother,
)
from workbench.problems.entry.site import R_GROUND

OM = mars_rate_M()
EX, EY, EZ = np.eye(3)


_IMU = ImuArrays  # the workbench's own type (was a duck-typed copy)


def _site():
    lat, lon = np.deg2rad(-2.05), np.deg2rad(-6.2)  # near the Schiaparelli site (in M, for geometry only)
    u = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    east = np.cross(EZ, u)
    east /= np.linalg.norm(east)
    return u, east


def _q_vertical(u, east):
    """q_M_G with +Z_G = up (u), +X_G = east."""
    C = np.stack([east, np.cross(u, east), u], axis=1)  # columns: G axes in M
    return dcm_to_quat(C)


SPIN = np.deg2rad(5.0)
A1, W1 = np.deg2rad(8.0), 2 * np.pi / 7.0
A2, W2 = np.deg2rad(5.0), 2 * np.pi / 11.0


def truth(t, h0=8000.0):
    """Kinematic truth at times t (n,): dict v, p, q, w_G, f_G."""
    u, east = _site()
    p0 = (R_GROUND + h0) * u
    v = -80.0 * u + 10.0 * east + np.cross(OM, p0)  # constant inertial velocity
    p = p0 + t[:, None] * v
    psi, phi, th = SPIN * t, A1 * np.sin(W1 * t), A2 * np.sin(W2 * t)
    dpsi, dphi, dth = SPIN + 0 * t, A1 * W1 * np.cos(W1 * t), A2 * W2 * np.cos(W2 * t)
    qv = _q_vertical(u, east)
    qz, qx, qy = (quat_from_rotvec(a[:, None] * e) for a, e in ((psi, EZ), (phi, EX), (th, EY)))
    q = quat_multiply(quat_multiply(quat_multiply(qv, qz), qx), qy)
    # body rate: w = Ry(θ)ᵀ (Rx(φ)ᵀ ψ̇ e_z + φ̇ e_x) + θ̇ e_y
    Cx, Cy = quat_to_dcm(qx), quat_to_dcm(qy)
    w1 = np.einsum("nji,j->ni", Cx, EZ) * dpsi[:, None] + dphi[:, None] * EX
    w = np.einsum("nji,nj->ni", Cy, w1) + dth[:, None] * EY
    f = -np.einsum("nji,nj->ni", quat_to_dcm(q), gravity_j2(p, MARS))  # a = 0  ->  f = −g, in G
    return dict(t=t, v=np.broadcast_to(v, p.shape).copy(), p=p, q=q, w_G=w, f_G=f)


SIG_F, SIG_W = 0.01, 1e-4
SIG = EntryFilterSigmas(slant_range=30.0, slant_out=30.0, velocity_out=3.0)
P0_SIG = np.r_[[3.0] * 3, [np.deg2rad(1.0)] * 3, [500.0] * 3]


def scenario(rng, t_end=60.0, dt=0.1, rda_offset=0.013, noise=True):
    t = np.round(np.arange(0.0, t_end + 1e-9, dt), 10)
    tr = truth(t)
    n = t.size
    f = tr["f_G"] + (SIG_F * rng.standard_normal((n, 3)) if noise else 0.0)
    w = tr["w_G"] + (SIG_W * rng.standard_normal((n, 3)) if noise else 0.0)
    imu = _IMU(t, f, w, np.full((n, 3), SIG_F), np.full((n, 3), SIG_W))
    B = beam_directions_G()
    t_sr = np.array([15.037, 25.037, 35.037, 45.037])
    ts = truth(t_sr)
    sr = np.stack([slant_range_sphere(ts["p"], ts["q"], B[j], R_GROUND) for j in range(4)], -1)
    sr = sr + (SIG.slant_range * rng.standard_normal(sr.shape) if noise else 0.0)
    sr[0] = 0.0  # the first packet zero-filled (AMELIA Sect. 7)
    t_rda = 20.0 + rda_offset + 0.1 * np.arange(int((t_end - 20.5) / 0.1))
    trr = truth(t_rda)
    so = slant_range_sphere(trr["p"], trr["q"], B[0], R_GROUND)
    vo = np.einsum("nji,nj->ni", quat_to_dcm(trr["q"]), trr["v"] - np.cross(OM, trr["p"]))
    if noise:
        so = so + SIG.slant_out * rng.standard_normal(so.shape)
        vo = vo + SIG.velocity_out * rng.standard_normal(vo.shape)
    radar = RadarData(
        t_sr, sr, np.array([False, True, True, True]), t_rda, so, vo, np.ones(t_rda.size, bool), B, R_GROUND
    )
    dx0 = P0_SIG * rng.standard_normal(9) if noise else np.zeros(9)
    v0 = tr["v"][0] + dx0[0:3]
    q0 = quat_boxplus(tr["q"][0], dx0[3:6])
    p0 = tr["p"][0] + dx0[6:9]
    return imu, radar, tr, (v0, q0, p0, np.diag(P0_SIG**2))


def errors(pass_, tr):
    """Error state estimate ⊟ truth: (n, 9) [δv, δθ, δp] (sign irrelevant for NEES)."""
    return np.concatenate([pass_.v_M - tr["v"], attitude_error(tr["q"], pass_.q_M_G), pass_.p_M - tr["p"]], axis=1)


def h_agl(p):
    return np.linalg.norm(p, axis=-1) - R_GROUND


# ---------------------------------------------------------------------------------------------


def test_truth_body_rate_matches_quaternion_derivative():
    t = np.linspace(0.0, 30.0, 301)
    h = 1e-5
    a, b = truth(t - h), truth(t + h)
    w_fd = attitude_error(a["q"], b["q"]) / (2 * h)
    assert np.allclose(w_fd, truth(t)["w_G"], atol=1e-8)


_Bridge = GapBridge  # the workbench's own type (was a duck-typed copy)


def _with_gap(imu, tr, ia, ib):
    """Drop IMU samples ia+1..ib−1 and bridge ia -> ib from the truth."""
    keep = np.ones(imu.t.size, bool)
    keep[ia + 1 : ib] = False
    Ca, Cb = quat_to_dcm(tr["q"][ia]).T, quat_to_dcm(tr["q"][ib]).T
    dt = imu.t[ib] - imu.t[ia]
    dp = tr["p"][ib] - tr["p"][ia]
    br = _Bridge(
        imu.t[ia], imu.t[ib], Ca @ (tr["v"][ib] - tr["v"][ia]), Ca @ dp, Ca @ (dp - tr["v"][ia] * dt), Cb @ Ca.T
    )
    sub = {k: v[keep] for k, v in tr.items()}
    return _IMU(imu.t[keep], imu.f_G[keep], imu.w_G[keep], imu.sigma_f[keep], imu.sigma_w[keep], [br]), sub


def test_no_radar_forward_equals_strapdown_integrate():
    rng = np.random.default_rng(0)
    imu, radar, tr, (v0, q0, p0, P0) = scenario(rng, t_end=20.0)
    imu, tr = _with_gap(imu, tr, 50, 80)
    empty = RadarData(
        np.zeros(0), np.zeros((0, 4)), np.zeros(0, bool), np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros(0, bool)
    )
    res = run_entry_smoother(imu, empty, v0, q0, p0, P0, sigmas=SIG)
    sp = integrate(imu, v0, q0, p0, P0, body=MARS)
    assert sp.bridged.sum() == 1
    assert np.allclose(res.forward.p_M, sp.p_M, atol=1e-9, rtol=0)
    assert np.allclose(res.forward.q_M_G, sp.q_M_G, atol=1e-12)
    assert np.allclose(res.forward.P, sp.P, rtol=1e-10, atol=1e-12)
    # without data the smoother is the forward pass
    assert np.allclose(res.smoothed.p_M, res.forward.p_M) and np.allclose(res.smoothed.P, res.forward.P, rtol=1e-8)
    # a measurement inside the gap is snapped to the nearer gap end
    one = RadarData(
        np.zeros(0),
        np.zeros((0, 4)),
        np.zeros(0, bool),
        np.array([5.6]),
        np.array([7000.0]),
        np.zeros((1, 3)),
        np.ones(1, bool),
    )
    r1 = run_entry_smoother(imu, one, v0, q0, p0, P0, sigmas=SIG)
    assert r1.info["n_snapped_in_gap"] == 2 and r1.info["n_inserted"] == 0


def test_noise_free_strapdown_tracks_truth():
    """The discrete model (RK4, inputs linear between samples) matches the analytic truth."""
    imu, _, tr, _ = scenario(np.random.default_rng(1), noise=False)
    sp = integrate(imu, tr["v"][0], tr["q"][0], tr["p"][0], np.eye(9), body=MARS)
    e = errors(sp, tr)
    assert np.abs(e[:, 0:3]).max() < 0.02 and np.abs(e[:, 3:6]).max() < 2e-4 and np.abs(e[:, 6:9]).max() < 0.5


def _random_state(rng):
    tr = truth(np.array([rng.uniform(0, 50)]))
    P = np.diag(P0_SIG**2)
    L = rng.normal(size=(9, 9)) * 0.2
    P = P + (L @ L.T) * np.outer(P0_SIG, P0_SIG)
    return tr["v"][0], tr["q"][0], tr["p"][0], P


def test_constrained_update_directions():
    """Slant range: δv = 0, δp ∥ vertical, attitude correction ⟂ vertical in M; velocity-out: δp = 0."""
    rng = np.random.default_rng(2)
    B = beam_directions_G()
    for _ in range(5):
        v, q, p, P = _random_state(rng)
        u = p / np.linalg.norm(p)
        y, H = slant_range_model(np.broadcast_to(p, (4, 3)), np.broadcast_to(q, (4, 4)), B, R_GROUND)
        res = rng.normal(scale=200.0, size=4)
        R = 30.0**2 * np.eye(4)
        v1, q1, p1, P1, K, ok = radar_update(v, q, p, P, res, H[:, 0, :], R, "range", constrained=True)
        assert ok
        assert np.allclose(v1, v)
        dp = p1 - p
        assert np.linalg.norm(dp) > 1.0 and np.linalg.norm(np.cross(dp, u)) < 1e-9 * np.linalg.norm(dp)
        dth_M = quat_rotate(q, attitude_error(q, q1))
        assert abs(dth_M @ u) < 1e-9 * np.linalg.norm(dth_M) and np.linalg.norm(dth_M) > 1e-6
        # covariance: horizontal position block unchanged, P stays symmetric PD
        Ph = np.eye(3) - np.outer(u, u)
        assert np.allclose(Ph @ P1[6:9, 6:9] @ Ph, Ph @ P[6:9, 6:9] @ Ph, rtol=1e-9, atol=1e-6)
        assert is_symmetric_pd(P1)[0]
        # the unconstrained update moves the horizontal position and the velocity
        v2, _, p2, P2, _, _ = radar_update(v, q, p, P, res, H[:, 0, :], R, "range", constrained=False)
        assert np.linalg.norm(np.cross(p2 - p, u)) > 1.0 and np.linalg.norm(v2 - v) > 1e-3
        assert np.trace(P2) <= np.trace(P1)  # optimal gain: smaller covariance
        # velocity-out: position untouched
        yv, Hv = velocity_out_model(v, q, p, OM)
        v3, q3, p3, P3, _, _ = radar_update(
            v, q, p, P, rng.normal(scale=5, size=3), Hv, 9.0 * np.eye(3), "velocity", constrained=True
        )
        assert np.allclose(p3, p) and np.linalg.norm(v3 - v) > 1e-3 and is_symmetric_pd(P3)[0]
    # Π is a projector
    Pi = gain_projector("range", p, q)
    assert np.allclose(Pi @ Pi, Pi) and np.allclose(Pi, Pi.T)


def test_gate_rejects_outlier():
    v, q, p, P = _random_state(np.random.default_rng(4))
    yv, Hv = velocity_out_model(v, q, p, OM)
    out = radar_update(v, q, p, P, np.array([1e4, 0, 0]), Hv, 9.0 * np.eye(3), "velocity", gate=16.27)
    assert not out[5] and out[0] is v and out[3] is P


@pytest.fixture(scope="module")
def one_run():
    rng = np.random.default_rng(11)
    imu, radar, tr, init = scenario(rng)
    res = run_entry_smoother(imu, radar, *init, sigmas=SIG, constrained=True)
    return imu, radar, tr, init, res


def test_radar_fix_altitude_and_bookkeeping(one_run):
    imu, radar, tr, init, res = one_run
    hs_err = h_agl(res.smoothed.p_M) - h_agl(tr["p"])
    e0 = h_agl(init[2]) - h_agl(tr["p"][0])
    # vertical σ of the smoothed position
    u = tr["p"] / np.linalg.norm(tr["p"], axis=1, keepdims=True)
    sig_h = np.sqrt(np.einsum("ni,nij,nj->n", u, res.smoothed.P[:, 6:9, 6:9], u))
    assert np.all(np.abs(hs_err) <= 3.0 * sig_h)
    assert np.abs(hs_err).max() < 0.1 * max(abs(e0), 100.0) and np.abs(hs_err).max() < 30.0
    assert sig_h.max() < 20.0 < np.sqrt(P0_SIG[6] ** 2 / 3)
    # bookkeeping: 3 valid slant-range packets, rda samples inserted between IMU samples
    assert res.innovations["slant_range"].t.size == 3 and len(res.plane_fits) == 3
    assert res.info["n_inserted"] == radar.t_rda.size + 3 and res.info["n_snapped"] == 0
    assert res.forward.t.size == imu.t.size == res.smoothed.P.shape[0]
    # smoothed residuals inside the (conservative) 3σ band
    for c in ("slant_range", "slant_out", "velocity_out"):
        sr = res.smoothed_residuals[c]
        z = sr.y / np.sqrt(np.einsum("kii->ki", sr.S))
        assert np.nanmax(np.abs(z)) < 3.5, c
    # covariances symmetric PD throughout
    assert is_symmetric_pd(res.forward.P)[0].all() and is_symmetric_pd(res.smoothed.P)[0].all()
    # plane fits agree with the truth AGL at the packet times
    for tk, fit in res.plane_fits:
        assert abs(fit.h_agl - h_agl(truth(np.array([tk]))["p"])[0]) < 3 * SIG.slant_range


def test_constrained_vs_unconstrained_horizontal_position(one_run):
    """Slant ranges alone never move the horizontal position in the constrained forward pass."""
    imu, radar, tr, init, res_c = one_run
    only_sr = RadarData(
        radar.t_sr, radar.slant_ranges, radar.sr_valid, np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros(0, bool)
    )
    sp = integrate(imu, *init, body=MARS)
    r_c = run_entry_smoother(imu, only_sr, *init, sigmas=SIG, constrained=True)
    r_u = run_entry_smoother(imu, only_sr, *init, sigmas=SIG, constrained=False)
    k = np.searchsorted(imu.t, radar.t_sr[1])  # first valid packet; strapdown identical before it
    u = sp.p_M[k] / np.linalg.norm(sp.p_M[k])
    d_c = r_c.forward.p_M[k] - sp.p_M[k]
    d_u = r_u.forward.p_M[k] - sp.p_M[k]
    assert np.linalg.norm(d_c - (d_c @ u) * u) < 0.05 * abs(d_c @ u)  # vertical (within one step's drift)
    assert np.allclose(r_c.forward.v_M[k], sp.v_M[k], atol=0.05)  # no velocity update
    assert np.linalg.norm(d_u - (d_u @ u) * u) > 1.0  # the plain EKF moves it horizontally
    # both fix the altitude
    for r in (r_c, r_u):
        assert abs(h_agl(r.smoothed.p_M[-1]) - h_agl(tr["p"][-1])) < 60.0


def test_split_step_vs_snap():
    """RDA tags 0.5 ms off the IMU grid are snapped to it; 1.5 ms off, the interval is split; same answer."""
    imu, radar, tr, init = scenario(np.random.default_rng(5), t_end=40.0, rda_offset=0.0005)
    r_snap = run_entry_smoother(imu, radar, *init, sigmas=SIG)
    n = radar.t_rda.size
    assert r_snap.info["n_snapped"] == 2 * n and r_snap.info["n_inserted"] == 2 and r_snap.info["n_outside"] == 1
    assert r_snap.info["n_slant_out"] == n and r_snap.info["n_velocity_out"] == n
    imu2, radar2, tr2, init2 = scenario(np.random.default_rng(5), t_end=40.0, rda_offset=0.0015)
    r_split = run_entry_smoother(imu2, radar2, *init2, sigmas=SIG)
    assert r_split.info["n_snapped"] == 0 and r_split.info["n_inserted"] == n + 2
    dh = h_agl(r_split.smoothed.p_M) - h_agl(r_snap.smoothed.p_M)
    assert np.abs(dh).max() < 0.5  # both within a fraction of a metre (80 m/s × 1 ms scale)
    e_split = np.abs(h_agl(r_split.smoothed.p_M) - h_agl(tr2["p"])).max()
    assert e_split < 30.0


@pytest.mark.slow
def test_smoothed_nees_over_seeded_runs():
    n_runs = 20
    vals = []
    for seed in range(n_runs):
        imu, radar, tr, init = scenario(np.random.default_rng(100 + seed))
        res = run_entry_smoother(imu, radar, *init, sigmas=SIG)
        vals.append(nees(errors(res.smoothed, tr), res.smoothed.P))
    vals = np.array(vals)
    anees = vals.mean()
    lo, hi = anees_bounds(9, n_runs)
    print(f"smoothed ANEES (9 dof, {n_runs} runs) = {anees:.3f}, 95% band [{lo:.2f}, {hi:.2f}]")
    assert lo <= anees <= hi


def test_relinearised_iterations(one_run):
    """Iterations relinearise about the previous smoothed trajectory (Gauss-Newton): the forward
    pass and its innovations stay the causal EKF's, the changes shrink, and in this nearly linear
    scenario the answer moves by far less than its σ."""
    imu, radar, tr, init, res3 = one_run
    res1 = run_entry_smoother(imu, radar, *init, sigmas=EntryFilterSigmas(**{**SIG.__dict__, "iterations": 1}))
    assert res1.info["iterations"] == 1 and res1.info["relinearisation_max_attitude_change_rad"] == []
    assert res3.info["iterations"] == 3
    steps = res3.info["relinearisation_max_attitude_change_rad"]
    assert len(steps) == 2 and steps[1] < steps[0]
    assert np.array_equal(res1.forward.p_M, res3.forward.p_M) and np.array_equal(res1.forward.P, res3.forward.P)
    for c in ("slant_range", "slant_out", "velocity_out"):
        assert np.array_equal(res1.innovations[c].y, res3.innovations[c].y, equal_nan=True)
    dh = np.abs(h_agl(res1.smoothed.p_M) - h_agl(res3.smoothed.p_M))
    assert dh.max() < 0.2 * np.sqrt(res3.smoothed.P[:, 6:9, 6:9].trace(axis1=1, axis2=2)).min()


def test_iterated_update_gauss_newton():
    """Iterated update (``update_iterations``): one step is the ordinary update; iterating re-linearises
    the slant ranges about the updated state and reaches the Gauss-Newton fixed point, with a
    smaller post-update residual than the single linearised step at a 7° attitude error."""
    from workbench.estimation.ekf import ErrorStateLayout, update

    lay = ErrorStateLayout(10, ((3, 3),))
    rng = np.random.default_rng(5)
    v, q_t, p, _ = _random_state(rng)
    q = quat_boxplus(q_t, np.deg2rad([5.0, -5.0, 0.0]))  # ~7° tilt error
    B = beam_directions_G()
    z = np.array([float(slant_range_model(p, q_t, B[b], R_GROUND)[0]) for b in range(4)])
    radar = RadarData(np.array([0.0]), z[None, :], np.ones(1, bool), np.zeros(0), np.zeros(0), np.zeros((0, 3)),
                      np.zeros(0, bool))  # fmt: skip
    sg = EntryFilterSigmas(slant_range=5.0)
    P = np.diag(np.r_[np.full(3, 10.0), np.full(3, np.deg2rad(7.0)), np.full(3, 200.0)] ** 2)
    x = np.r_[v, q, p]
    rm = radar_measurement("slant_range", 0, radar, x, sg)
    m = rm.measurement
    assert rm.mask.all() and m.z.shape == (4,)

    def upd(n):
        return update(x, P, m.z, m.h, m.R, lay, H=m.H, iterations=n, gain_projector=m.gain_projector,
                      step_tol=m.step_tol)  # fmt: skip

    res0 = z - rm.pred_full
    _, q1, p1, P1, K, _ = radar_update(v, q, p, P, res0, m.H(x), m.R, rm.kind)
    one = upd(1)
    assert np.allclose(one.x_post, np.r_[v + (K @ res0)[0:3], q1, p1]) and np.allclose(one.P_post, P1)
    it = upd(30)
    assert is_symmetric_pd(it.P_post)[0]

    def post_res(xx):
        return np.linalg.norm(z - m.h(xx))

    assert post_res(it.x_post) < 0.5 * post_res(one.x_post)
    # fixed point: one more Gauss-Newton step about the result does not move it
    xs = it.x_post
    d = lay.boxminus(xs, x)
    Hs = m.H(xs)
    Ks = m.gain_projector(xs) @ P @ Hs.T @ np.linalg.inv(Hs @ P @ Hs.T + m.R)
    d_next = Ks @ (m.z - m.h(xs) + Hs @ d)
    assert np.linalg.norm(d) > 1e-3 and np.allclose(d_next, d, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# pinned numbers: the forward and smoothed passes of a small deterministic case must not move when
# the filter is refactored onto the shared engine (workbench.estimation.ekf / .smoother).

PIN_FILE = __import__("pathlib").Path(__file__).with_name("data") / "entry_filter_pin.npz"


def _pin_case() -> dict[str, np.ndarray]:
    """Arrays of the pinned case: 27 s synthetic descent with a bridged IMU gap (10.0-11.2 s), RDA
    samples between IMU samples (inserted nodes), one valid slant-range packet, a χ² gate,
    relinearised RTS (3 passes) and iterated updates (4); constrained and unconstrained."""
    out: dict[str, np.ndarray] = {}
    for tag, constrained in (("c", True), ("u", False)):
        imu, radar, tr, init = scenario(np.random.default_rng(11), t_end=27.0)
        imu, tr = _with_gap(imu, tr, 100, 112)
        sg = EntryFilterSigmas(**{**SIG.__dict__, "gate_probability": 0.9999})
        res = run_entry_smoother(imu, radar, *init, sigmas=sg, constrained=constrained)
        for name, ps in (("fwd", res.forward), ("smo", res.smoothed)):
            for f in ("v_M", "q_M_G", "p_M"):
                out[f"{tag}_{name}_{f}"] = getattr(ps, f)
            out[f"{tag}_{name}_P"] = ps.P[::7]  # every 7th node keeps the file small
        for c in ("slant_range", "slant_out", "velocity_out"):
            for name, d in (("inn", res.innovations), ("sres", res.smoothed_residuals)):
                out[f"{tag}_{name}_{c}_y"] = d[c].y
                out[f"{tag}_{name}_{c}_S"] = d[c].S
                out[f"{tag}_{name}_{c}_accepted"] = d[c].accepted
    return out


def _assert_close_rel(name: str, got: np.ndarray, want: np.ndarray, rtol: float = 1e-9) -> None:
    """Elementwise |got − want| ≤ rtol·scale, with scale = max(|want|, rtol-scaled array norm) for
    states and sqrt(P_ii P_jj) for covariance-like (…, d, d) arrays; NaN patterns must agree."""
    assert got.shape == want.shape, name
    assert np.array_equal(np.isnan(got), np.isnan(want)), name
    if want.dtype == bool:
        assert np.array_equal(got, want), name
        return
    g, w = np.nan_to_num(got), np.nan_to_num(want)
    if name.endswith(("_P", "_S")):
        d = np.sqrt(np.abs(np.einsum("...ii->...i", w)))
        scale = d[..., :, None] * d[..., None, :]
    else:
        scale = np.abs(w)
    bad = np.abs(g - w) > rtol * scale + 1e-300
    assert not bad.any(), f"{name}: {bad.sum()} entries differ, max rel {np.max(np.abs(g - w) / (scale + 1e-300)):.2e}"


def test_pinned_forward_and_smoothed_numbers():
    """Forward/smoothed states, covariances, innovations and smoothed residuals equal (1e-9 rel) the
    numbers of the pre-refactor entry filter (data/entry_filter_pin.npz, see data/README.md)."""
    want = np.load(PIN_FILE)
    got = _pin_case()
    assert sorted(got) == sorted(want.files)
    for k in want.files:
        _assert_close_rel(k, got[k], want[k])


def test_compiled_steps_match_reference_path():
    """The compiled IMU steps (``fast=True``, estimation.strapdown_kernel) against ``rk4_step`` +
    ``covariance_step`` (``fast=False``): forward and smoothed states and covariances to rounding."""
    imu, radar, tr, init = scenario(np.random.default_rng(11), t_end=27.0)
    imu, tr = _with_gap(imu, tr, 100, 112)
    sg = EntryFilterSigmas(**{**SIG.__dict__, "gate_probability": 0.9999})
    fast = run_entry_smoother(imu, radar, *init, sigmas=sg, fast=True)
    ref = run_entry_smoother(imu, radar, *init, sigmas=sg, fast=False)
    for name in ("forward", "smoothed"):
        a, b = getattr(fast, name), getattr(ref, name)
        for f in ("v_M", "q_M_G", "p_M", "P"):
            _assert_close_rel(f"{name}_{f}" if f != "P" else f"{name}_P", getattr(a, f), getattr(b, f), rtol=1e-11)


if __name__ == "__main__":  # regenerate the pin (only when a number is meant to change)
    np.savez_compressed(PIN_FILE, **_pin_case())
