"""MEADS tightly-coupled EKF (Karlgaard et al. 2013, Sect. III.B) — fast unit tests of the filter code.

The arc is built from the estimator's own models (its pressure model, its transition), so what is
tested is the filter: a planted transducer scale factor is found, the innovations are consistent
with their covariance, the covariances stay symmetric positive definite, pass 2 reprocesses the
corrected pressures.  How the filter does against the richer truth is the slow run test's job.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import dcm_to_quat, quat_to_dcm
from workbench.estimation.consistency import is_symmetric_pd
from workbench.estimation.health import ERROR, OK
from workbench.io.assets import asset_path
from workbench.io.scenario import Scenario
from workbench.models.flush_airdata import load_fads_vehicle
from workbench.problems.meads import ekf
from workbench.problems.meads.airdata import ned_frames
from workbench.problems.meads.config import MeadsSettings
from workbench.problems.meads.health import ekf_checks
from workbench.problems.meads.pipeline import sensor_sigma

VEHICLE = load_fads_vehicle(asset_path("vehicles", "msl_meads.toml"))


def _schema_defaults():
    """Settings of a scenario that sets nothing but its vehicle: every default of the schema."""
    data = {"scenario": {"name": "defaults", "kind": "meads"}, "vehicle": {"file": "../vehicles/msl_meads.toml"}}
    sc = Scenario(asset_path("scenarios", "msl_meads.toml"), "defaults", "meads", "", data)
    return MeadsSettings.from_scenario(sc)


DEFAULTS = _schema_defaults()
LAMBDA = np.array([0.008, -0.006, 0.004, 0.0, -0.005, 0.007, -0.008])
WIND_N = np.array([12.0, -6.0, 0.0])
#: the pressure model's error not carried as states (the filter before issue #10's coloured model error)
NO_MODEL_ERROR = dict(model_error_sigma=0.0, bias_sigma_pa=0.0, model_mach_sigma=0.0, model_angle_sigma_deg=0.0)


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation matrix taking unit vector a to unit vector b (Rodrigues)."""
    v, c = np.cross(a, b), float(a @ b)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def _arc(n: int = 160, seed: int = 3):
    """A straight 20 s arc at 25 km, 3 km/s, flight-path angle −10°, the attitude oscillating so
    that α = 16 ± 4°, β = ±2° in a constant wind; truth states by the filter's own transition,
    pressures by its own model with the planted scale factors and white noise of the σ the filter
    is given."""
    t = np.arange(n) / 8.0
    r0 = MARS.reference_radius + 25e3
    p0 = np.array([r0, 0.0, 0.0])
    gam = math.radians(-10.0)
    v_g = 3000.0 * np.array([math.sin(gam), math.cos(gam), 0.0])  # radial (x = up here), east (y)
    v_M = v_g + np.cross([0.0, 0.0, MARS.rotation_rate], p0)
    p_M = p0 + t[:, None] * v_M
    C_N_M = ned_frames(p0[None])[0]
    v_air_M = v_g - C_N_M.T @ WIND_N
    a = np.radians(16.0 + 4.0 * np.sin(2 * np.pi * t / 10.0))
    b = np.radians(2.0 * np.sin(2 * np.pi * t / 7.0))
    u_dir = np.stack([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)], 1)
    C_A_M = _rotation_between(v_air_M / np.linalg.norm(v_air_M), np.array([1.0, 0, 0]))
    C_B_M = np.array([_rotation_between(np.array([1.0, 0, 0]), u) @ C_A_M for u in u_dir])
    q_M_B = dcm_to_quat(np.swapaxes(C_B_M, 1, 2))
    inp = ekf.EkfInputs(
        t, p_M, np.broadcast_to(v_M, (n, 3)).copy(), q_M_B, 5.0, 0.05, 1e-4,
        np.zeros((n, 7)), np.ones((n, 7)), np.ones((n, 7), bool), VEHICLE, "newtonian", None, 1.335,
    )  # fmt: skip
    atm = MarsEngineeringAtmosphere()
    x = np.zeros(ekf.N_X)
    x[ekf.IP], x[ekf.IV], x[ekf.IW] = p_M[0], v_M, WIND_N
    x[ekf.ILP] = math.log(atm.pressure(25e3)) + 0.15  # the truth is off the prior mean
    x[ekf.ILR] = math.log(atm.density(25e3)) + 0.25
    x[ekf.ILAM] = LAMBDA
    step = ekf.make_transition(inp, replace(DEFAULTS.ekf, **NO_MODEL_ERROR))
    X = [x]
    for k in range(1, n):
        X.append(step(X[-1], t[k - 1], t[k])[0])
    X = np.array(X)
    h = ekf.make_pressure_model(inp)
    allp = np.arange(7)
    p_clean = np.array([h(X[k], C_B_M[k], allp)[0] for k in range(n)])
    sig = sensor_sigma(p_clean, VEHICLE, 0.002)
    p = p_clean + np.random.default_rng(seed).normal(0.0, sig)
    return replace(inp, p=p, sigma_p=sig), X


@pytest.fixture(scope="module")
def arc():
    inp, X = _arc()
    # the arc has no process noise: the filter is given (almost) none, so its NIS can be judged;
    # and no model error (the pressures are the filter's own model): the paper's filter, R white
    st = replace(
        DEFAULTS.ekf,
        iterations=3,
        accel_psd=1e-8,
        attitude_psd=1e-14,
        wind_var_per_km=1e-4,
        atmosphere_var_per_km=1e-9,
        **NO_MODEL_ERROR,
    )
    passes = list(ekf.run_passes(inp, st, keep_all=True))
    return inp, X, passes


def test_pass1_recovers_planted_scale_factors(arc):
    inp, X, (p1, _) = arc
    assert p1.scale_estimated
    P = p1.smoothed.P[0][ekf.ILAM, ekf.ILAM]
    err = p1.scale - LAMBDA
    assert np.all(np.abs(err) <= 3.0 * p1.sigma_scale), (err, p1.sigma_scale)
    # the common mode of the seven scale factors is the density's (q∞ = ρV²/2 scales every port):
    # only the prior holds it; the differences between ports are observed
    D = np.eye(7) - np.full((7, 7), 1.0 / 7.0)
    sd_diff = np.sqrt(np.diag(D @ P @ D.T))
    assert np.all(sd_diff < 0.1 * DEFAULTS.ekf.scale_factor_sigma), sd_diff
    assert np.all(np.abs(D @ err) <= 3.0 * sd_diff), (D @ err, sd_diff)
    assert np.max(np.abs(D @ err)) < 0.25 * np.max(np.abs(LAMBDA))


def test_innovations_are_consistent_and_outputs_track_the_truth(arc):
    inp, X, (p1, p2) = arc
    for ps in (p1, p2):
        inn = ps.forward.innovations["pressure"]
        assert inn.accepted.all()
        # after the first few samples (prior transient) the NIS per port averages to ~1
        nis = ps.nis_port[8:]
        assert 0.7 < float(np.mean(nis)) < 1.4, float(np.mean(nis))
        a, sa = ps.output("alpha")
        ta = ekf.air_data_of_state(X, np.swapaxes(quat_to_dcm(inp.q_M_B), 1, 2), inp.gamma)
        for j, name in enumerate(("alpha", "beta", "qbar", "mach")):
            v, s = ps.output(name)
            inside = np.mean(np.abs(v - ta[j]) <= 3.0 * s)
            assert inside > 0.95, (ps.index, name, inside)
        assert np.degrees(np.max(sa[20:])) < 0.1


def test_covariances_symmetric_positive_definite(arc):
    _, _, passes = arc
    for ps in passes:
        for P in (ps.forward.P_post, ps.smoothed.P):
            d = np.einsum("nii->ni", P)
            act = np.flatnonzero(np.all(d > 0, axis=0))
            Pa = P[:, act][:, :, act]
            s = 1.0 / np.sqrt(d[:, act])
            ok, _ = is_symmetric_pd(Pa * s[:, :, None] * s[:, None, :])
            assert np.all(ok)


def test_pass2_uses_the_corrected_pressures_with_scale_factors_held(arc):
    inp, X, (p1, p2) = arc
    assert not p2.scale_estimated and p2.index == 2 and p2.passes == 2
    np.testing.assert_array_equal(p2.scale, p1.scale)
    # scale factors are consider parameters: held at zero (the pressures are corrected) with pass
    # 1's covariance at every step, forward and smoothed - not re-estimated from the same data
    for x, P in ((p2.forward.x_post, p2.forward.P_post), (p2.smoothed.x, p2.smoothed.P)):
        assert np.all(x[:, ekf.ILAM] == 0.0)
        np.testing.assert_allclose(P[:, ekf.ILAM, ekf.ILAM], np.broadcast_to(p1.scale_cov, (P.shape[0], 7, 7)))
    # and the corrected pressures are what it fitted: its innovations have no scale-factor pattern
    inn = p2.forward.innovations["pressure"]
    rel = np.nanmean(inn.y[20:] / inn.z_pred[20:], axis=0)
    assert np.max(np.abs(rel - rel.mean())) < 0.2 * np.max(np.abs(LAMBDA))
    assert p2.stage_label.startswith("EKF pass 2/2")


def test_health_checks_of_the_passes(arc):
    inp, _, passes = arc
    ports = VEHICLE.port_names
    above = np.ones(inp.t.size, bool)
    checks = {c.name: c for c in ekf_checks(passes, inp.t, above, ports)}
    for i in (1, 2):
        assert checks[f"covariance.ekf_pass{i}_smoothed_correlation"].status == OK
        for p in ports:
            assert checks[f"nis.pressure_ekf_pass{i}_{p}"].status == OK, checks[f"nis.pressure_ekf_pass{i}_{p}"]
    # innovations 6x their σ (a wrong unit or noise level) are an ERROR
    bad = replace(passes[1], nis_port=36.0 * passes[1].nis_port)
    checks = {c.name: c for c in ekf_checks([bad], inp.t, above, ports)}
    assert checks["nis.pressure_ekf_pass2_P1"].status == ERROR


def test_attitude_error_tilts_the_integrated_specific_force():
    """A strapdown that decelerates at 10 g along a fixed body axis: a planted attitude error
    δθ (C_M_B,true = C_M_B (I + [δθ×])) makes the true velocity drift from the strapdown's by
    C_M_B (δθ × f) Δt a step; the transition carries it (state and F[v, θ]), and without the
    coupling the velocity error would stay at zero."""
    n, dt = 17, 0.125
    t = np.arange(n) * dt
    rng = np.random.default_rng(5)
    u = rng.normal(size=3)
    C_M_B = _rotation_between(np.array([1.0, 0, 0]), u / np.linalg.norm(u))
    f_B = np.array([-98.0, 3.0, 20.0])  # m/s², drag along −x_B with some lift
    p0 = np.array([MARS.reference_radius + 40e3, 0.0, 0.0])
    p_M, v_M = [p0], [np.array([-1000.0, 5000.0, 0.0])]
    for _ in range(n - 1):  # the strapdown: specific force and gravity (trapezoidal)
        p_M.append(p_M[-1] + v_M[-1] * dt)
        g = 0.5 * (gravity_j2(p_M[-2][None], MARS)[0] + gravity_j2(p_M[-1][None], MARS)[0])
        v_M.append(v_M[-1] + (C_M_B @ f_B + g) * dt)
    p_M, v_M = np.array(p_M), np.array(v_M)
    q = dcm_to_quat(np.broadcast_to(C_M_B, (n, 3, 3)).copy())
    inp = ekf.EkfInputs(
        t, p_M, v_M, q, 5.0, 0.05, 1e-4, np.zeros((n, 7)), np.ones((n, 7)), np.ones((n, 7), bool),
        VEHICLE, "newtonian", None, 1.335,
    )  # fmt: skip
    dth = np.array([1e-3, -2e-3, 0.5e-3])
    x = np.zeros(ekf.N_X)
    x[ekf.IP], x[ekf.IV], x[ekf.ITH] = p_M[0], v_M[0], dth
    x[ekf.ILP], x[ekf.ILR] = math.log(30.0), math.log(1e-3)
    for on in (True, False):
        step = ekf.make_transition(inp, replace(DEFAULTS.ekf, attitude_velocity_coupling=on))
        xk = x.copy()
        for k in range(1, n):
            xk, F, _ = step(xk, t[k - 1], t[k])
        dv = xk[ekf.IV] - v_M[-1]
        # the true drift: the tilted specific force, (n − 1) steps (gravity differences are 2nd order)
        want = (n - 1) * dt * C_M_B @ np.cross(dth, f_B)
        if on:
            np.testing.assert_allclose(dv, want, rtol=1e-6, atol=1e-6)
            assert np.linalg.norm(want) > 0.1  # m/s after 2 s: the effect is not small
            np.testing.assert_allclose(F[ekf.IV, ekf.ITH] @ dth, C_M_B @ np.cross(dth, f_B) * dt, rtol=1e-6)
        else:
            assert np.linalg.norm(dv) < 1e-6


def test_vertical_wind_and_flow_angle_errors_keep_their_stationary_variance():
    """The vertical wind (a Gauss–Markov over the altitude travelled) and the model's flow-angle
    errors (a Gauss–Markov whose 1σ follows Mach, :func:`ekf.angle_sigma`) propagate so that a
    state at its stationary variance stays there: F P Fᵀ + Q = σ² after each step, with the wind
    decaying by exp(−Δh / L) and the flow-angle σ moving with the Mach number of the step."""
    st = DEFAULTS.ekf
    assert st.vertical_wind_length_km > 0 and st.attitude_velocity_coupling and st.model_angle_sigma_deg > 0
    deg = math.radians(1.0)
    assert ekf.angle_sigma(st, 3.0) == pytest.approx(deg)
    assert ekf.angle_sigma(st, 7.5) == pytest.approx(0.55 * deg)
    assert ekf.angle_sigma(st, 25.0) == pytest.approx(0.1 * deg)
    n, dt = 9, 0.125
    t = np.arange(n) * dt
    p0 = np.array([MARS.reference_radius + 40e3, 0.0, 0.0])
    v0 = np.array([-1500.0, 1000.0, 0.0])  # descending 1.5 km/s: 190 m a step
    p_M = p0 + v0 * t[:, None]
    v_M = np.broadcast_to(v0, (n, 3)).copy()
    q = dcm_to_quat(np.broadcast_to(np.eye(3), (n, 3, 3)).copy())
    inp = ekf.EkfInputs(
        t, p_M, v_M, q, 5.0, 0.05, 1e-4, np.zeros((n, 7)), np.ones((n, 7)), np.ones((n, 7), bool),
        VEHICLE, "newtonian", None, 1.335,
    )  # fmt: skip
    x = np.zeros(ekf.N_X)
    x[ekf.IP], x[ekf.IV] = p_M[0], v_M[0]
    x[ekf.ILP], x[ekf.ILR] = math.log(30.0), math.log(1e-3)
    x[11] = 2.0  # m/s down
    step = ekf.make_transition(inp, st)
    x1, F, Q = step(x, t[0], t[1])
    dh_km = (np.linalg.norm(x1[ekf.IP]) - np.linalg.norm(x[ekf.IP])) / 1e3
    assert dh_km == pytest.approx(-0.1875, rel=1e-3)
    phi = math.exp(dh_km / st.vertical_wind_length_km)
    assert x1[11] == pytest.approx(2.0 * phi) and F[11, 11] == pytest.approx(phi)
    assert phi**2 * st.vertical_wind_sigma_mps**2 + Q[11, 11] == pytest.approx(st.vertical_wind_sigma_mps**2)
    mach = [ekf.air_data_of_state(xx[None], np.eye(3)[None], 1.335)[3][0] for xx in (x, x1)]
    s0, s1 = (ekf.angle_sigma(st, m) for m in mach)
    a = ekf.IMA
    np.testing.assert_allclose(F[a, a] @ (s0**2 * np.eye(2)) @ F[a, a].T + Q[a, a], s1**2 * np.eye(2), rtol=1e-12)


# ------------------------------------------------------------- the pressure model's error as states


@pytest.mark.parametrize("order", [1, 2])
def test_model_error_markov_is_stationary_and_smooth(order):
    """Φ, Q of the model-error Gauss–Markov keep its steady-state covariance (Q = P∞ − Φ P∞ Φᵀ,
    symmetric PSD), tend to I / 0 for short / long distances; the second order is smooth: its
    increments over a short step are far smaller than the first order's at the same σ."""
    st = replace(DEFAULTS.ekf, model_error_sigma=0.01, model_error_order=order)
    Pinf = np.diag(ekf.markov_steady_var(st))
    for d in (1e-4, 0.1, 1.0, 10.0):
        Phi, Q = ekf.markov_step(st, d)
        np.testing.assert_allclose(Phi @ Pinf @ Phi.T + Q, Pinf, atol=1e-15)
        np.testing.assert_allclose(Q, Q.T, atol=0)
        assert np.all(np.linalg.eigvalsh(Q) >= -1e-18)
    Phi, Q = ekf.markov_step(st, 1e-4)
    assert abs(Phi[0, 0] - 1.0) < 2e-4 and Q[0, 0] < 1e-3 * st.model_error_sigma**2
    Phi, _ = ekf.markov_step(st, 50.0)
    assert np.max(np.abs(Phi)) < 1e-15
    if order == 2:
        q1 = ekf.markov_step(replace(st, model_error_order=1), 0.01)[1][0, 0]
        assert ekf.markov_step(st, 0.01)[1][0, 0] < 1e-3 * q1


def test_pressure_model_jacobian_of_the_model_error_states():
    """The columns of H that the model-error states add (scale factor, level, per-port model error,
    bias, model Mach error) are the derivatives of h: central differences of h agree; the
    atmosphere's columns too where the model Mach error is zero (elsewhere H leaves out m times
    the model's curvature)."""
    inp, X = _arc(n=16)
    h = ekf.make_pressure_model(inp)
    C = np.swapaxes(quat_to_dcm(inp.q_M_B), 1, 2)
    x = X[5].copy()
    rng = np.random.default_rng(1)
    x[ekf.IB] = rng.normal(0.0, 0.01, 7)
    x[ekf.IBIAS] = rng.normal(0.0, 3.0, 7)
    x[ekf.IC], x[ekf.IMM] = 0.004, 0.05
    use = np.array([0, 2, 3, 6])
    cols = [*range(ekf.ILAM.start, ekf.ILAM.stop), ekf.IC, *range(ekf.IB.start, ekf.IB.stop)]
    cols += [*range(ekf.IBIAS.start, ekf.IBIAS.stop), ekf.IMM, *range(ekf.IMA.start, ekf.IMA.stop)]

    def check(x, cols):
        p, H = h(x, C[5], use)
        for j in cols:
            e = 1e-3 if j in range(ekf.IBIAS.start, ekf.IBIAS.stop) else 1e-6
            dx = np.zeros(ekf.N_X)
            dx[j] = e
            num = (h(x + dx, C[5], use)[0] - h(x - dx, C[5], use)[0]) / (2 * e)
            atol = 1e-6 * np.max(np.abs(p))
            np.testing.assert_allclose(H[:, j], num, rtol=2e-4, atol=atol, err_msg=ekf.STATE_NAMES[j])
        return H

    H = check(x, cols)
    assert np.all(np.abs(H[:, ekf.IMM]) > 0)  # the Mach dependence of the table is felt
    # the model's flow-angle errors are felt by every port
    assert np.all(np.abs(H[:, ekf.IMA.start]) > 0) and np.all(np.abs(H[:, ekf.IMA.start + 1]) > 0)
    x[ekf.IMM] = 0.0
    check(x, [ekf.ILP, ekf.ILR, ekf.IMM])


@pytest.fixture(scope="module")
def arc_model_error():
    """The arc's pressures with a smooth port-dependent model error (0.6 % of reading, varying
    over the arc), transducer biases and white noise of the σ the filter is given (its R: white
    only); the filter carries the model error as coloured states (the defaults)."""
    inp, X = _arc()
    n = inp.t.size
    h = ekf.make_pressure_model(inp)
    C = np.swapaxes(quat_to_dcm(inp.q_M_B), 1, 2)
    allp = np.arange(7)
    p_clean = np.array([h(X[k], C[k], allp)[0] for k in range(n)])
    rng = np.random.default_rng(7)
    phase = rng.uniform(0.0, 2 * np.pi, 7)
    err = 0.006 * np.sin(2 * np.pi * inp.t[:, None] / 15.0 + phase[None, :])
    bias = rng.normal(0.0, 2.0, 7)
    st = replace(
        DEFAULTS.ekf, iterations=3, accel_psd=1e-8, attitude_psd=1e-14, wind_var_per_km=1e-4, atmosphere_var_per_km=1e-9
    )
    assert st.model_error_sigma > 0.0 and st.bias_sigma_pa > 0.0
    sig = sensor_sigma(p_clean, VEHICLE, 0.0, noise_counts=st.noise_counts)
    p = p_clean * (1.0 + err) + bias + rng.normal(0.0, sig)
    inp = replace(inp, p=p, sigma_p=sig)
    return inp, X, list(ekf.run_passes(inp, st, keep_all=True))


def test_model_error_states_keep_the_filter_honest(arc_model_error):
    """With R white only and a smooth model error the filter does not know: the outputs and the
    planted scale factors inside their 3σ, the innovations not optimistic (mean per-port NIS
    below 2; the first-order Markov's increments make them conservative on this fast-turning
    arc), covariances symmetric positive definite."""
    inp, X, passes = arc_model_error
    ta = ekf.air_data_of_state(X, np.swapaxes(quat_to_dcm(inp.q_M_B), 1, 2), inp.gamma)
    for ps in passes:
        assert np.all(np.nanmean(ps.nis_port[8:], axis=0) < 2.0)
        for j, name in enumerate(("alpha", "beta", "qbar", "mach")):
            v, s = ps.output(name)
            assert np.mean(np.abs(v - ta[j]) <= 3.0 * s) > 0.95, (ps.index, name)
        for P in (ps.forward.P_post, ps.smoothed.P):
            d = np.einsum("nii->ni", P)
            act = np.flatnonzero(np.all(d > 0, axis=0))
            s = 1.0 / np.sqrt(d[:, act])
            ok, _ = is_symmetric_pd(P[:, act][:, :, act] * s[:, :, None] * s[:, None, :])
            assert np.all(ok)
    p1 = passes[0]
    assert np.all(np.abs(p1.scale - LAMBDA) <= 3.0 * p1.sigma_scale), (p1.scale - LAMBDA, p1.sigma_scale)


def test_flow_angle_mach_range_must_be_ordered():
    """``model_angle_mach_high`` at or below ``model_angle_mach_low`` is a located error."""
    from workbench.io.scenario import ScenarioError, load_scenario
    from workbench.problems.meads.problem import MeadsProblem

    sc = load_scenario(asset_path("scenarios", "msl_meads.toml"))
    with pytest.raises(ScenarioError, match="ekf.model_angle_mach_high"):
        MeadsProblem().settings(sc.with_overrides({"ekf.model_angle_mach_low": 10.0, "ekf.model_angle_mach_high": 5.0}))


def test_temperature_prior_correlates_the_atmosphere_states(arc):
    """The prior on ln T = ln p − ln ρ: the first prior covariance has var(ln p − ln ρ) =
    temperature_sigma_ln² with ln p and ln ρ each keeping atmosphere_sigma_ln² (and 0: independent);
    a temperature σ the two priors cannot give is a located error."""
    from workbench.io.scenario import ScenarioError, load_scenario
    from workbench.problems.meads.problem import MeadsProblem
    from workbench.problems.meads.state import ILP, ILR

    inp, _, passes = arc
    st = DEFAULTS.ekf
    assert st.temperature_sigma_ln > 0.0
    P = passes[0].forward.P_prior[0]
    s2 = st.atmosphere_sigma_ln**2
    assert P[ILP, ILP] == pytest.approx(s2) and P[ILR, ILR] == pytest.approx(s2)
    assert P[ILP, ILP] + P[ILR, ILR] - 2.0 * P[ILP, ILR] == pytest.approx(st.temperature_sigma_ln**2)
    off = list(ekf.run_passes(inp, replace(st, temperature_sigma_ln=0.0, passes=1), keep_all=True))[0]
    assert off.forward.P_prior[0][ILP, ILR] == 0.0
    sc = load_scenario(asset_path("scenarios", "msl_meads.toml"))
    with pytest.raises(ScenarioError, match="ekf.temperature_sigma_ln"):
        MeadsProblem().settings(sc.with_overrides({"ekf.temperature_sigma_ln": 2.0}))


def test_first_order_filter_carries_no_rate_states(arc_model_error, monkeypatch):
    """The first-order model error has no rate b': the filter carries 39 states, not 46, and its
    numbers are those of the filter carrying the 7 identically-zero rates (the same sums without
    their zero terms, summed by BLAS in another order: the iterated update's stop rule turns those
    last-place differences into ~1e-8)."""
    inp, _, passes = arc_model_error
    st = replace(
        DEFAULTS.ekf, iterations=3, accel_psd=1e-8, attitude_psd=1e-14, wind_var_per_km=1e-4, atmosphere_var_per_km=1e-9
    )
    assert st.model_error_order == 1 and ekf.carried_states(st).size == ekf.N_X - ekf.N_PORTS
    assert ekf.carried_states(replace(st, model_error_order=2)).size == ekf.N_X
    keep = ekf.carried_states(st)
    ix = np.ix_(keep, keep)
    monkeypatch.setattr(ekf, "carried_states", lambda _st: np.arange(ekf.N_X))
    full = list(ekf.run_passes(inp, st, keep_all=True))
    for ps, pf in zip(passes, full, strict=True):
        assert ps.smoothed.x.shape == pf.smoothed.x.shape and np.all(ps.smoothed.x[:, ekf.IBD] == 0.0)
        # the covariances are over the carried states; the full filter's are zero on the others
        assert ps.smoothed.P.shape[1:] == ps.forward.F.shape[1:] == (keep.size, keep.size)
        assert np.all(pf.smoothed.P[:, ekf.IBD] == 0.0)
        np.testing.assert_allclose(ps.outputs, pf.outputs, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(ps.sigma, pf.sigma, rtol=1e-6)
        np.testing.assert_allclose(ps.smoothed.x, pf.smoothed.x, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(ps.sigma_post, pf.sigma_post, rtol=1e-6, atol=1e-15)
        # covariances on the correlation scale: cross terms near zero are differences of large ones
        Pf = pf.smoothed.P[:, ix[0], ix[1]]
        d = np.sqrt(np.einsum("nii->ni", Pf))
        dP = np.abs(ps.smoothed.P - Pf) / (d[:, :, None] * d[:, None, :])
        assert dP.max() < 1e-6


@pytest.mark.parametrize("order", [1, 2])
def test_compiled_transition_matches_the_numpy_reference(order):
    """The compiled transition (:func:`.kernel.transition_kernel`) against the numpy path: the
    same x1, F, Q to a few ulp over the full and the carried states, with every state perturbed
    (model errors, vertical wind, flow-angle errors active)."""
    inp, X = _arc(n=40)
    st = replace(DEFAULTS.ekf, model_error_order=order, model_error_sigma=0.01, vertical_wind_length_km=2.0)
    assert st.model_mach_sigma > 0.0 and st.model_angle_sigma_deg > 0.0 and st.attitude_velocity_coupling
    rng = np.random.default_rng(11)
    for keep in (None, ekf.carried_states(st)):
        fast = ekf.make_transition(inp, st, keep=keep)
        ref = ekf.make_transition(inp, st, compiled=False, keep=keep)
        for k in range(1, inp.t.size, 7):
            x = X[k - 1].copy()
            x[ekf.IP] += rng.normal(0.0, 50.0, 3)
            x[ekf.IV] += rng.normal(0.0, 1.0, 3)
            x[ekf.ITH] = rng.normal(0.0, 1e-3, 3)
            x[ekf.IW] += rng.normal(0.0, 5.0, 3)
            x[ekf.IB] = rng.normal(0.0, 0.01, 7)
            x[ekf.IBD] = rng.normal(0.0, 0.01, 7) if order == 2 else 0.0
            x[ekf.IBIAS] = rng.normal(0.0, 2.0, 7)
            x[ekf.IMM] = rng.normal(0.0, 0.01)
            x[ekf.IMA] = rng.normal(0.0, 0.01, 2)
            if keep is not None:
                x = x[keep]
            x1, F1, Q1 = fast(x, inp.t[k - 1], inp.t[k])
            x0, F0, Q0 = ref(x, inp.t[k - 1], inp.t[k])
            np.testing.assert_allclose(x1, x0, rtol=1e-14, atol=1e-15)
            np.testing.assert_allclose(F1, F0, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(Q1, Q0, rtol=1e-12, atol=1e-30)


def test_compiled_forward_pass_matches_the_reference(arc_model_error):
    """The compiled forward pass (:func:`.kernel.forward_kernel`, both passes: scale factors
    estimated, then held as consider parameters) and smoother against the reference path
    (``run_filter`` with the numpy transition and pressure model, ``rts_smooth``): the same
    states, covariances and innovations, to the last-place differences the iterated update's stop
    rule amplifies."""
    inp, _, passes = arc_model_error
    st = replace(
        DEFAULTS.ekf, iterations=3, accel_psd=1e-8, attitude_psd=1e-14, wind_var_per_km=1e-4, atmosphere_var_per_km=1e-9
    )
    ref = list(ekf.run_passes(inp, st, keep_all=True, compiled=False))
    for ps, pr in zip(passes, ref, strict=True):
        fa, fr = ps.forward, pr.forward
        for name in ("x_prior", "x_post", "F"):
            np.testing.assert_allclose(getattr(fa, name), getattr(fr, name), rtol=1e-6, atol=1e-8, err_msg=name)
        for name in ("P_prior", "P_post", "Q"):
            A, B = getattr(fa, name), getattr(fr, name)
            d = np.sqrt(np.abs(np.einsum("nii->ni", B)))
            d[d == 0.0] = 1.0
            assert np.max(np.abs(A - B) / (d[:, :, None] * d[:, None, :])) < 1e-6, name
        ia, ir = fa.innovations["pressure"], fr.innovations["pressure"]
        np.testing.assert_array_equal(ia.step, ir.step)
        np.testing.assert_array_equal(ia.accepted, ir.accepted)
        np.testing.assert_array_equal(np.isnan(ia.S), np.isnan(ir.S))
        for name in ("z", "z_pred", "y", "nis"):
            np.testing.assert_allclose(getattr(ia, name), getattr(ir, name), rtol=1e-6, atol=1e-6, err_msg=name)
        d = np.sqrt(np.einsum("kii->ki", ir.S))  # S on the correlation scale: its cross terms cancel
        assert np.nanmax(np.abs(ia.S - ir.S) / (d[:, :, None] * d[:, None, :])) < 1e-6
        # and the compiled smoother (:func:`.kernel.rts_kernel`) against rts_smooth
        np.testing.assert_allclose(ps.smoothed.x, pr.smoothed.x, rtol=1e-6, atol=1e-8)
        d = np.sqrt(np.abs(np.einsum("nii->ni", pr.smoothed.P)))
        d[d == 0.0] = 1.0
        assert np.max(np.abs(ps.smoothed.P - pr.smoothed.P) / (d[:, :, None] * d[:, None, :])) < 1e-6
        # the gains in σ units: G_ij σ_j / σ_i
        assert np.max(np.abs(ps.smoothed.G - pr.smoothed.G) * d[:, None, :] / d[:, :, None]) < 1e-6
        np.testing.assert_allclose(ps.outputs, pr.outputs, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(ps.sigma, pr.sigma, rtol=1e-6)


def test_compiled_pass_with_the_second_order_model_error():
    """The compiled pass carries the rates b' of the second-order model error (all 46 states) and
    agrees with the reference path there too."""
    inp, _ = _arc()
    st = replace(
        DEFAULTS.ekf, iterations=3, accel_psd=1e-8, attitude_psd=1e-14, wind_var_per_km=1e-4,
        atmosphere_var_per_km=1e-9, model_error_order=2, model_error_sigma=0.01,
    )  # fmt: skip
    fast = list(ekf.run_passes(inp, st))
    ref = list(ekf.run_passes(inp, st, compiled=False))
    for pa, pr in zip(fast, ref, strict=True):
        assert pa.smoothed.P.shape[1:] == (ekf.N_X, ekf.N_X)
        np.testing.assert_allclose(pa.outputs, pr.outputs, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(pa.sigma, pr.sigma, rtol=1e-6)
        np.testing.assert_allclose(pa.smoothed.x[:, ekf.IBD], pr.smoothed.x[:, ekf.IBD], atol=1e-9)
