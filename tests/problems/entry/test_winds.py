"""Tests of workbench.problems.entry.winds on a synthetic parachute descent with a known wind layer.

Synthetic descent: the system falls through the air at ~65 m/s with a small air-relative glide;
the ground velocity is air velocity + wind (a Gaussian layer of 20 m/s towards ENE at 7 km plus a
light background); the module's −Z_G axis is along the air-relative velocity, optionally with a
pendulum swing (4°, 1.3 s).  Positions are integrated in MMED including Mars' rotation so that
``v_M − ω×p`` is the ground velocity.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from workbench.core.bodies import MARS
from workbench.core.frames import ned_basis
from workbench.core.rotation import dcm_to_quat, quat_boxplus
from workbench.problems.entry.atmosphere import EntryProfileSigmas
from workbench.problems.entry.winds import estimate_winds, pendulum_period

OMEGA = np.array([0.0, 0.0, MARS.rotation_rate])
T_PDD, T_FSR = 175.0, 216.0
AZ = np.deg2rad(67.5)


def true_wind(h):
    layer = 20.0 * np.exp(-0.5 * ((h - 7000.0) / 400.0) ** 2)
    n = layer * np.cos(AZ) + 2.0
    e = layer * np.sin(AZ) - 1.0
    return np.stack([n, e], -1)


@lru_cache(maxsize=8)
def descent(pendulum_deg: float = 0.0, period: float = 1.3, dt: float = 0.05):
    t = np.arange(170.0, 262.0, dt)
    n = t.size
    lat, lon = np.deg2rad(6.0), np.deg2rad(350.0)
    p = (MARS.reference_radius + 10.5e3) * np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    p_M = np.zeros((n, 3))
    v_M = np.zeros((n, 3))
    d_N = np.zeros((n, 3))
    wind = np.zeros((n, 2))
    for k in range(n):
        C_N_M = ned_basis(p[None])[0]
        h = np.linalg.norm(p) - MARS.reference_radius
        v_air = np.array([2.0 * np.sin(0.1 * t[k]), 1.5 * np.cos(0.07 * t[k]), 65.0])
        wind[k] = true_wind(h)
        v_g = v_air + np.array([wind[k, 0], wind[k, 1], 0.0])
        swing = np.deg2rad(pendulum_deg) * np.sin(2 * np.pi * t[k] / period)
        d_N[k] = v_air / np.linalg.norm(v_air) + swing * np.array([0.6, 0.8, 0.0])
        p_M[k] = p
        v_M[k] = C_N_M.T @ v_g + np.cross(OMEGA, p)
        p = p + dt * v_M[k]
    C_M_N = np.transpose(ned_basis(p_M), (0, 2, 1))
    d_M = np.einsum("nij,nj->ni", C_M_N, d_N)
    z = -d_M / np.linalg.norm(d_M, axis=-1, keepdims=True)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    q = dcm_to_quat(np.stack([x, y, z], -1))
    # specific force against the air-relative velocity (drag ≈ weight), expressed in G
    v_air_M = v_M - np.cross(OMEGA, p_M) - np.einsum("nij,nj->ni", C_M_N, np.column_stack([wind, np.zeros(n)]))
    f_M = -3.7 * v_air_M / np.linalg.norm(v_air_M, axis=-1, keepdims=True)
    C_G_M = np.stack([x, y, z], -2)  # rows of C_G_M are the body axes in M
    f_G = np.einsum("nij,nj->ni", C_G_M, f_M)
    phase = np.where(t < T_PDD, 0, np.where(t < T_FSR, 1, 2))
    h = np.linalg.norm(p_M, axis=-1) - MARS.reference_radius
    return dict(t=t, p_M=p_M, v_M=v_M, q_M_G=q, f_G=f_G, phase=phase, wind=wind, h=h)


def _P(n, sv=1.0, sth_deg=0.2, sp=50.0):
    return np.broadcast_to(np.diag([sv**2] * 3 + [np.deg2rad(sth_deg) ** 2] * 3 + [sp**2] * 3), (n, 9, 9)).copy()


def _est(d, P=None, **kw):
    n = d["t"].size
    return estimate_winds(
        d["t"], d["p_M"], d["v_M"], d["q_M_G"], _P(n) if P is None else P, d["f_G"], d["phase"], None, None, **kw
    )


def test_wind_layer_recovered_noise_free():
    d = descent()
    w = _est(d, window_s=1.3)
    assert w.method == "attitude"
    err = np.hypot(w.wind_N - d["wind"][:, 0], w.wind_E - d["wind"][:, 1])[w.valid]
    assert w.valid.sum() > 1000
    assert np.max(err) < 0.2  # 1.3 s window over a 400 m (6 s) layer
    layer = w.valid & (np.abs(d["h"] - 7000.0) < 400.0)
    assert layer.sum() > 50 and np.min(np.hypot(w.wind_N, w.wind_E)[layer]) > 12.0


def test_pendulum_is_averaged_out_with_estimated_period():
    d = descent(pendulum_deg=4.0, period=1.3)
    w = _est(d)  # window = estimated pendulum period
    err = np.hypot(w.wind_N - d["wind"][:, 0], w.wind_E - d["wind"][:, 1])[w.valid]
    assert np.max(err) < 0.3
    # without averaging the swing leaves ~v_D·4° ≈ 4.5 m/s
    raw = _est(d, window_s=1e-6)
    raw_err = np.hypot(raw.wind_N - d["wind"][:, 0], raw.wind_E - d["wind"][:, 1])[raw.valid]
    assert np.max(raw_err) > 3.5


def test_pendulum_period_estimate():
    t = np.arange(0.0, 60.0, 0.1)
    x = np.column_stack([np.sin(2 * np.pi * t / 1.3), 0.5 * np.cos(2 * np.pi * t / 1.3)]) + 0.01 * t[:, None]
    assert pendulum_period(t, x) == pytest.approx(1.3, rel=0.02)
    assert pendulum_period(t[:20], x[:20]) is None


def test_specific_force_cross_check_agrees():
    d = descent()
    wa = _est(d, window_s=1.0)
    wf = _est(d, window_s=1.0, method="specific_force")
    assert wf.method == "specific_force"
    ok = wa.valid & wf.valid
    assert ok.sum() > 1000
    assert np.max(np.abs(wf.wind_N[ok] - d["wind"][ok, 0])) < 0.2
    assert np.max(np.abs(wf.wind_E[ok] - wa.wind_E[ok])) < 0.2


def test_validity_window():
    d = descent()
    w = _est(d, settle_s=10.0, fsr_exclusion_s=(-0.5, 3.0), window_s=1.3)
    t = d["t"]
    assert not w.valid[t < T_PDD + 10.0].any()
    assert not w.valid[(t >= T_FSR - 0.49) & (t <= T_FSR + 2.99)].any()
    assert w.valid[(t > T_PDD + 11.0) & (t < T_FSR - 1.5)].all()  # half a window trimmed at the ends
    assert np.isnan(w.wind_N[~w.valid]).all() and np.isfinite(w.sigma_E[w.valid]).all()
    # explicit event times override the phase transitions
    w2 = _est(d, events={"PDD": T_PDD + 5.0, "FSR": T_FSR})
    assert not w2.valid[t < T_PDD + 15.0].any()


def test_sigma_first_order_matches_monte_carlo_and_grows_with_velocity_sigma():
    d = descent()
    sel = slice(600, 760)  # a short stretch under the parachute (phase 1)
    dd = {k: (v[sel] if isinstance(v, np.ndarray) else v) for k, v in d.items()}
    n = dd["t"].size
    P = _P(n, sv=2.0, sth_deg=0.5, sp=100.0)
    no_model = EntryProfileSigmas(wind_model=0.0)
    kw = dict(window_s=1e-6, sigmas=no_model, events={"PDD": 100.0, "FSR": 1e9})
    w0 = estimate_winds(dd["t"], dd["p_M"], dd["v_M"], dd["q_M_G"], P, dd["f_G"], dd["phase"], **kw)
    assert w0.valid.all()
    rng = np.random.default_rng(3)
    L = np.linalg.cholesky(P[0])
    samples = []
    for _ in range(300):
        dx = rng.standard_normal((n, 9)) @ L.T
        w = estimate_winds(
            dd["t"],
            dd["p_M"] + dx[:, 6:9],
            dd["v_M"] + dx[:, 0:3],
            quat_boxplus(dd["q_M_G"], dx[:, 3:6]),
            P,
            dd["f_G"],
            dd["phase"],
            **kw,
        )
        samples.append(np.stack([w.wind_N, w.wind_E], -1))
    sd = np.std(np.array(samples), axis=0)
    ratio = sd / np.stack([w0.sigma_N, w0.sigma_E], -1)
    assert 0.85 < np.median(ratio) < 1.15
    # first-order values: ~sqrt(σ_v² + (v_D σ_θ)²) ≈ sqrt(4 + 0.57²·…) m/s
    assert np.all((w0.sigma_N > 2.0) & (w0.sigma_N < 3.0))
    w_big = estimate_winds(dd["t"], dd["p_M"], dd["v_M"], dd["q_M_G"], _P(n, sv=8.0), dd["f_G"], dd["phase"], **kw)
    assert np.all(w_big.sigma_N > 3.0 * _est(dd, window_s=1e-6, sigmas=no_model, events=kw["events"]).sigma_N)
    # the model term adds in quadrature
    w_model = estimate_winds(
        dd["t"], dd["p_M"], dd["v_M"], dd["q_M_G"], P, dd["f_G"], dd["phase"], window_s=1e-6, events=kw["events"]
    )
    assert np.allclose(w_model.sigma_N**2, w0.sigma_N**2 + 2.0**2)


def test_bad_method_raises():
    d = descent()
    with pytest.raises(ValueError, match="method"):
        _est(d, method="magic")
