"""MEADS Monte Carlo with the full error model against the truth simulator (``truth_mc.py``).

Fast: the aggregation and the summary on constructed errors, the error histories of a constructed
reconstruction (units, signs, which estimator fills what), every member's own draws independent of
the executor, the truth dispersion.  Slow: two real members on the loop and through
``workbench mc msl_meads --truth-sim`` on a process pool give identical numbers, and the recording.
"""

from __future__ import annotations

import dataclasses
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.estimation.montecarlo import run_monte_carlo
from workbench.io.assets import assets_dir
from workbench.io.scenario import resolve_scenario
from workbench.problems.meads import truth_mc as tmc
from workbench.problems.meads.problem import MeadsProblem
from workbench.problems.meads.truth import MeadsDispersionSigmas, disperse_truth_spec
from workbench.recording import layout

Q, E = len(tmc.QUANTITIES), len(tmc.ESTIMATORS)
IQ = {q: j for j, q in enumerate(tmc.QUANTITIES)}
IE = {e: j for j, e in enumerate(tmc.ESTIMATORS)}


@pytest.fixture(scope="module")
def settings():
    """The frozen settings of the shipped ``msl_meads`` (what every member receives)."""
    return MeadsProblem().settings(resolve_scenario("msl_meads", assets_dir()))


# ------------------------------------------------------------------------------- aggregation


def test_aggregate_on_constructed_errors():
    rng = np.random.default_rng(4)
    K, n = 400, 3
    err = np.full((K, n, Q, E), np.nan)
    sig = np.full_like(err, np.nan)
    # α, least squares: bias 0.1, spread 0.2 (1σ), reported 1σ 0.2 -> ratio 1
    z = rng.standard_normal((K, n))
    err[:, :, IQ["alpha_deg"], IE["least_squares"]] = 0.1 + 0.2 * z
    sig[:, :, IQ["alpha_deg"], IE["least_squares"]] = 0.2
    # q∞, EKF pass 2: reported 1σ 3x the spread
    err[:, :, IQ["qbar_pct"], IE["ekf_pass2"]] = 0.5 * z
    sig[:, :, IQ["qbar_pct"], IE["ekf_pass2"]] = 1.5
    # Mach, EKF pass 1: one member only at sample 0, none at sample 1, two at sample 2
    err[0, 0, IQ["mach"], IE["ekf_pass1"]] = 0.3
    sig[0, 0, IQ["mach"], IE["ekf_pass1"]] = 0.05
    err[:2, 2, IQ["mach"], IE["ekf_pass1"]] = [0.1, 0.3]
    sig[:2, 2, IQ["mach"], IE["ekf_pass1"]] = [0.1, np.nan]  # the second has no 1σ: not counted
    err[2, 2, IQ["mach"], IE["ekf_pass1"]] = -0.1
    sig[2, 2, IQ["mach"], IE["ekf_pass1"]] = 0.01

    agg = tmc.aggregate(err, sig)
    a = (slice(None), IQ["alpha_deg"], IE["least_squares"])
    e = err[a[0], :, IQ["alpha_deg"], IE["least_squares"]]
    assert np.array_equal(agg["count"][a], np.full(n, K))
    np.testing.assert_allclose(agg["bias"][a], e.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(agg["mc_3sigma"][a], 3 * e.std(axis=0, ddof=1), rtol=1e-12)
    np.testing.assert_allclose(agg["mc_3rms"][a], 3 * np.sqrt((e**2).mean(axis=0)), rtol=1e-12)
    np.testing.assert_allclose(agg["reported_3sigma"][a], 0.6, rtol=1e-12)
    np.testing.assert_allclose(agg["ratio"][a], 0.6 / (3 * e.std(axis=0, ddof=1)), rtol=1e-12)
    assert np.all(np.abs(agg["ratio"][a] - 1.0) < 0.15)  # 400 members: std known to ~4 %
    np.testing.assert_allclose(agg["inside"][a], np.mean(np.abs(e) <= 0.6, axis=0), rtol=1e-12)
    b = (slice(None), IQ["qbar_pct"], IE["ekf_pass2"])
    assert np.all(np.abs(agg["ratio"][b] - 3.0) < 0.45)
    assert np.all(agg["inside"][b] == 1.0)
    m = (slice(None), IQ["mach"], IE["ekf_pass1"])
    assert agg["count"][m].tolist() == [1, 0, 2]
    assert np.isnan(agg["mc_3sigma"][m][:2]).all() and np.isnan(agg["ratio"][m][:2]).all()
    assert agg["inside"][m][0] == 0.0 and np.isnan(agg["inside"][m][1])  # |0.3| > 3 x 0.05
    assert agg["bias"][m][2] == pytest.approx(0.0)  # members 0 and 2: +0.1, −0.1
    assert agg["mc_3sigma"][m][2] == pytest.approx(3 * math.sqrt(0.02))
    assert agg["reported_3sigma"][m][2] == pytest.approx(3 * 0.055)
    assert agg["inside"][m][2] == 0.5  # 0.1 <= 0.3; 0.1 > 0.03
    assert np.isnan(agg["mc_3sigma"][:, IQ["wind_down_mps"], IE["least_squares"]]).all()


def test_summarize_flags_disagreements_and_objectives():
    rng = np.random.default_rng(9)
    K, n = 300, 20
    err = np.full((K, n, Q, E), np.nan)
    sig = np.full_like(err, np.nan)
    z = rng.standard_normal((K, n))
    cell = (slice(None), slice(None))
    err[(*cell, IQ["alpha_deg"], IE["ekf_pass2"])] = 0.1 * z  # MC 3σ 0.3 ≤ 0.5: met, consistent
    sig[(*cell, IQ["alpha_deg"], IE["ekf_pass2"])] = 0.1
    err[(*cell, IQ["density_pct"], IE["ekf_pass2"])] = 2.0 * z  # reported 3σ 1.5 vs MC 6: optimistic
    sig[(*cell, IQ["density_pct"], IE["ekf_pass2"])] = 0.5
    err[(*cell, IQ["qbar_pct"], IE["least_squares"])] = 0.3 * z  # reported 3x: conservative, not met
    sig[(*cell, IQ["qbar_pct"], IE["least_squares"])] = 0.9
    err[(*cell, IQ["mach"], IE["least_squares"])] = 5.0 + 0.01 * z  # biased: inside 0 %, ratio huge
    sig[(*cell, IQ["mach"], IE["least_squares"])] = 0.01
    s = tmc.summarize(tmc.aggregate(err, sig))
    assert set(s["table"]) == {"least_squares", "ekf_pass2"}  # pass 1 has nothing
    a = s["table"]["ekf_pass2"]["alpha_deg"]
    assert a["samples"] == n and a["member_samples"] == K * n
    assert 0.27 < a["mc_3sigma_median"] < 0.33 and a["reported_3sigma_median"] == pytest.approx(0.3)
    assert 0.9 < a["ratio_median"] < 1.1 and a["fraction_inside_reported_3sigma"] > 0.99
    assert a["mc_meets_objective"] and a["objective_3sigma"] == 0.5
    d = s["table"]["ekf_pass2"]["density_pct"]
    assert 0.2 < d["ratio_median"] < 0.3 and "objective_3sigma" not in d
    q = s["table"]["least_squares"]["qbar_pct"]
    assert 2.7 < q["ratio_median"] < 3.3 and q["mc_meets_objective"] is True  # MC 3σ 0.9 % ≤ 2 %
    assert 2.7 < q["ratio_to_3rms_median"] < 3.3 and q["3rms_meets_objective"] is True  # no bias
    m = s["table"]["least_squares"]["mach"]
    assert m["mc_meets_objective"] is True  # the spread is small: the bias shows in "inside", |bias| and 3 RMS
    assert m["3rms_meets_objective"] is False and m["fraction_of_samples_3rms_meeting_objective"] == 0.0
    assert m["ratio_to_3rms_median"] == pytest.approx(0.03 / 15.0, rel=0.01)
    assert m["fraction_inside_reported_3sigma"] == 0.0 and m["max_abs_bias"] == pytest.approx(5.0, abs=0.01)
    flagged = {line.split(":")[0] for line in s["disagreements"]}
    assert flagged == {"ekf_pass2 density_pct", "least_squares qbar_pct", "least_squares mach"}
    line = next(x for x in s["disagreements"] if x.startswith("ekf_pass2 density_pct"))
    assert "optimistic" in line and f"{d['ratio_median']:.2f}×" in line
    assert "spread matched" in next(x for x in s["disagreements"] if x.startswith("least_squares mach"))


def test_aggregate_by_mach_pools_each_member_at_its_own_flight_condition():
    # 4 members fly the same Mach history shifted in time: per time they are at different Mach,
    # per Mach bin the same.  The error depends on the Mach only (plus noise), so a per-time
    # spread mixes flight conditions while the per-bin spread is the noise alone.
    rng = np.random.default_rng(3)
    K, n = 4, 400
    shift = np.array([0, 40, 80, 120])
    mach = np.full((K, n), np.nan)
    for k in range(K):
        mach[k, shift[k] :] = np.linspace(20.0, 2.0, n - shift[k])
    qbar = np.where(np.isfinite(mach), 2000.0, np.nan)
    qbar[0, -50:] = 500.0  # member 0 ends below 850 Pa: not scored
    err = np.full((K, n, Q, E), np.nan)
    sig = np.full_like(err, np.nan)
    a = (slice(None), slice(None), IQ["alpha_deg"], IE["ekf_pass2"])
    err[a] = 0.05 * mach + 0.01 * rng.standard_normal((K, n))
    sig[a] = np.where(np.isfinite(mach), 0.01, np.nan)
    m1 = (slice(1, 2), slice(None), IQ["mach"], IE["ekf_pass1"])  # one member only: thin everywhere
    err[m1], sig[m1] = 0.1, 0.2
    bm = tmc.aggregate_by_mach(err, sig, qbar, mach)
    assert np.all(np.diff(bm["mach_mid"]) < 0)  # high Mach first
    assert bm["mach_hi"][0] == 20.0 + 1.0 and bm["mach_lo"][-1] == 2.0  # Mach 20 falls in [20, 21)
    j = (slice(None), IQ["alpha_deg"], IE["ekf_pass2"])
    edges = np.asarray(tmc.MACH_BIN_EDGES)
    for i, (lo, hi) in enumerate(zip(bm["mach_lo"], bm["mach_hi"], strict=True)):
        assert hi == edges[np.searchsorted(edges, lo) + 1]
        sel = (mach >= lo) & (mach < hi) & (qbar >= 850.0)
        e = err[a][sel]
        assert bm["count"][j][i] == sel.sum() and bm["members"][j][i] == np.any(sel, axis=1).sum()
        np.testing.assert_allclose(bm["mc_3sigma"][j][i], 3 * e.std(ddof=1), rtol=1e-12)
        np.testing.assert_allclose(bm["mc_3rms"][j][i], 3 * np.sqrt(np.mean(e**2)), rtol=1e-12)
        assert bm["reported_3sigma_median"][j][i] == pytest.approx(0.03)
    # within a 1-Mach bin the error changes by 0.05 (the bin width): spread ~ 0.05/√12 ⊕ 0.01
    assert np.all(bm["mc_3sigma"][j][bm["mach_lo"] >= 5.0] < 3 * 0.025)
    per_time = tmc.aggregate(err, sig)["mc_3sigma"][:, IQ["alpha_deg"], IE["ekf_pass2"]]
    assert np.nanmedian(per_time) > 2 * np.median(bm["mc_3sigma"][j])  # time mixes flight conditions
    assert bm["solid"][j].all()  # 3-4 members everywhere ≥ max(2, ⌈0.5 · 4⌉)
    low = bm["mach_lo"] == 2.0
    assert bm["members"][j][low][0] == 3  # member 0 is below 850 Pa there
    m = (slice(None), IQ["mach"], IE["ekf_pass1"])
    assert (bm["members"][m] == 1).all() and not bm["solid"][m].any()
    assert np.nanmax(bm["mc_3sigma"][m]) < 1e-12 and (bm["inside"][m] == 1.0).all()  # one member's samples
    table = tmc.summarize(tmc.solid_bins(bm), over="Mach bins")["table"]
    assert "ekf_pass1" not in table  # thin bins are left out of the table
    assert table["ekf_pass2"]["alpha_deg"]["samples"] == bm["solid"][j].sum()
    js = tmc.by_mach_json(bm)
    col = js["estimators"]["ekf_pass2"]["alpha_deg"]
    assert js["mach_lo"] == bm["mach_lo"].tolist() and col["members"] == bm["members"][j].tolist()
    assert js["estimators"]["ekf_pass1"]["mach"]["solid"] == [False] * len(js["mach_lo"])


def test_error_histories_of_a_constructed_reconstruction():
    t = np.arange(6) / 8.0
    truth = {
        "t": np.array([0.0, 1.0]),
        "alpha": np.array([0.3, 0.3]),
        "beta": np.array([0.0, 0.01]),
        "qbar": np.array([1000.0, 2000.0]),
        "mach": np.array([10.0, 9.0]),
        "p_inf": np.array([10.0, 10.0]),
        "rho": np.array([1e-3, 1e-3]),
        "wind_NE": np.array([[5.0, -3.0], [5.0, -3.0]]),
    }
    qt = np.interp(t, truth["t"], truth["qbar"])
    n = t.size
    one = np.ones(n)
    fit = SimpleNamespace(
        alpha=0.3 * one + np.radians(0.2),
        sigma_alpha=np.radians(0.1) * one,
        beta=np.interp(t, truth["t"], truth["beta"]),
        sigma_beta=np.r_[np.nan, np.full(n - 1, 0.01)],  # no solution at the first sample
        qbar=1.02 * qt,
        sigma_qbar=0.01 * 1.02 * qt,
    )
    winds = SimpleNamespace(
        wind_NE=np.full((n, 2), np.nan),  # not published: the raw non-singular solution is scored
        wind_raw_NE=np.tile([6.0, np.nan], (n, 1)),
        singular=np.r_[True, np.zeros(n - 1, bool)],
        P=np.tile(np.diag([4.0, 4.0]), (n, 1, 1)),
    )
    wind = SimpleNamespace(
        mach=np.interp(t, truth["t"], truth["mach"]) + 0.05,
        sigma_mach=0.1 * one,
        p_inf=9.0 * one,
        sigma_p_inf=0.9 * one,
        density=1.1e-3 * one,
        sigma_density=1.1e-5 * one,
        winds=winds,
    )

    class Pass:
        index = 2

        def output(self, name):
            v = {"wind_down": 1.5 * one, "qbar": qt}.get(name, np.zeros(n))
            return v, 0.5 * one

    result = SimpleNamespace(air=SimpleNamespace(t=t, fit=fit), wind=wind, ekf=(Pass(),))
    tt, err, sig = tmc.error_histories(result, truth)
    assert np.array_equal(tt, t) and err.shape == sig.shape == (n, Q, E)
    ls, p1, p2 = (IE[e] for e in tmc.ESTIMATORS)
    np.testing.assert_allclose(err[:, IQ["alpha_deg"], ls], 0.2, atol=1e-12)
    np.testing.assert_allclose(sig[:, IQ["alpha_deg"], ls], 0.1, atol=1e-12)
    assert np.isnan(err[0, IQ["beta_deg"], ls]) and np.isnan(sig[0, IQ["beta_deg"], ls])
    np.testing.assert_allclose(err[1:, IQ["beta_deg"], ls], 0.0, atol=1e-12)
    np.testing.assert_allclose(err[:, IQ["qbar_pct"], ls], 2.0, rtol=1e-9)  # % of the truth
    np.testing.assert_allclose(sig[:, IQ["qbar_pct"], ls], 1.0, rtol=1e-9)  # % of the estimate
    np.testing.assert_allclose(err[:, IQ["mach"], ls], 0.05, atol=1e-12)
    np.testing.assert_allclose(err[:, IQ["p_inf_pct"], ls], -10.0, rtol=1e-9)
    np.testing.assert_allclose(err[:, IQ["density_pct"], ls], 10.0, rtol=1e-9)
    assert np.isnan(err[0, IQ["wind_north_mps"], ls])  # singular
    np.testing.assert_allclose(err[1:, IQ["wind_north_mps"], ls], 1.0)
    np.testing.assert_allclose(sig[1:, IQ["wind_north_mps"], ls], 2.0)
    assert np.isnan(err[:, IQ["wind_east_mps"], ls]).all()  # no solution
    assert np.isnan(err[:, IQ["wind_down_mps"], ls]).all()  # the least squares has none
    assert np.isnan(err[:, :, p1]).all()  # pass 1 did not run
    np.testing.assert_allclose(err[:, IQ["wind_down_mps"], p2], 1.5)  # the true vertical wind is 0
    np.testing.assert_allclose(err[:, IQ["qbar_pct"], p2], 0.0, atol=1e-12)
    np.testing.assert_allclose(sig[:, IQ["qbar_pct"], p2], 100.0 * 0.5 / qt, rtol=1e-9)
    np.testing.assert_allclose(err[:, IQ["alpha_deg"], p2], np.degrees(-0.3 * one), rtol=1e-12)


def test_members_on_one_grid_are_padded():
    def member(k, n):
        t = np.arange(n) / 8.0
        e = np.full((n, Q, E), float(k))
        return tmc.MemberErrors(k, t, np.full(n, 900.0), np.ones(n), e, e, {})

    t, err, sig, qbar, mach = tmc.stack_members([member(0, 4), member(1, 6)])
    assert t.size == 6 and err.shape == (2, 6, Q, E)
    assert np.isnan(err[0, 4:]).all() and np.isnan(qbar[0, 4:]).all() and (err[1] == 1.0).all()


# ------------------------------------------------------------------------ draws and dispersion


def test_each_member_draws_its_own_truth_and_sensors_whatever_the_executor(settings):
    job = tmc.McJob(settings)
    loop = run_monte_carlo(tmc.member_draws, 4, shared=job, seed=7, workers=1)
    pool = run_monte_carlo(tmc.member_draws, 4, shared=job, seed=7, workers=2, scheduler="processes")
    for (s1, q1, i1), (s2, q2, i2) in zip(loop.results, pool.results, strict=True):
        assert s1 == s2 and i1 == i2
        assert np.array_equal(q1.generate_state(4), q2.generate_state(4))
    specs = [r[0] for r in loop.results]
    assert len({s.surface_pressure_pa for s in specs}) == 4  # every member its own atmosphere
    assert len({s.wind_layers for s in specs}) == 4 and len({s.entry_fpa_deg for s in specs}) == 4
    assert len({tuple(r[2]["sensor_seed_state"]) for r in loop.results}) == 4  # and its own sensor errors
    fixed = run_monte_carlo(tmc.member_draws, 2, shared=tmc.McJob(settings, disperse_truth=False), seed=7)
    base = settings.truth
    assert all(r[0] == base for r in fixed.results)
    # the sensor stream does not depend on whether the truth is dispersed
    assert fixed.results[1][2]["sensor_seed_state"] == loop.results[1][2]["sensor_seed_state"]


def test_health_calibration_members_fly_dispersed_truths(settings):
    """The health bands are fitted over other flights, not one truth's sensor noise: each calibration
    member's truth is dispersed (seeded), its sensors and injected failure are the scenario's."""
    prob = MeadsProblem()
    a, b = prob.calibration_settings(settings, 3), prob.calibration_settings(settings, 4)
    assert a.truth != settings.truth and a.truth != b.truth
    assert prob.calibration_settings(settings, 3).truth == a.truth  # a function of the seed
    assert a.pressure == settings.pressure and a.vehicle == settings.vehicle  # failure port and sensors kept


def test_truth_dispersion_draws_about_the_spec(settings):
    base = settings.truth
    zero = MeadsDispersionSigmas(**{f.name: 0.0 for f in dataclasses.fields(MeadsDispersionSigmas)})
    same = disperse_truth_spec(base, np.random.default_rng(1), zero)
    assert same == dataclasses.replace(base, wave_length_km=max(base.wave_length_km, 5.0))
    a = disperse_truth_spec(base, np.random.default_rng(1))
    b = disperse_truth_spec(base, np.random.default_rng(1))
    c = disperse_truth_spec(base, np.random.default_rng(2))
    assert a == b and a != c
    assert a.bank_profile_deg == base.bank_profile_deg and a.chute_mach == base.chute_mach
    draws = [disperse_truth_spec(base, np.random.default_rng(s)) for s in range(200)]
    ps = np.array([d.surface_pressure_pa for d in draws]) / base.surface_pressure_pa - 1.0
    assert abs(ps.std() - 0.05) < 0.01 and abs(ps.mean()) < 0.015
    dT = np.array([[T for _, T in d.temperature_nodes_km_K] for d in draws]) - np.array(
        [T for _, T in base.temperature_nodes_km_K]
    )
    assert abs(dT.std() - 5.0) < 0.5
    assert min(d.shoulder for d in draws) >= 0.0 and min(d.wave_amplitude_K for d in draws) >= 0.0


# ------------------------------------------------------------------------------------ slow


@pytest.mark.slow
def test_full_monte_carlo_is_executor_independent_and_recorded(settings, tmp_path):
    from workbench.cli import main
    from workbench.recording.reader import read_recording

    loop = tmc.run_full_monte_carlo(settings, n_runs=2, seed=3, workers=1)
    assert main(["mc", "msl_meads", "--truth-sim", "--seeds", "2", "--first-seed", "3", "--workers", "2",
                 "--out", str(tmp_path), "--quiet"]) == 0  # fmt: skip
    summary = json.loads((tmp_path / "msl_meads_truth.mc.json").read_text())
    assert summary["executor"].startswith("process pool") and summary["n_ok"] == 2
    for est, rows in loop.summary["table"].items():
        for q, row in rows.items():
            for key, v in row.items():
                w = summary["table"][est][q][key]
                assert (v == w) or (isinstance(v, float) and math.isnan(v) and w is None), (est, q, key)
    assert summary["disagreements"] == loop.summary["disagreements"]
    s = loop.summary
    assert s["failure_port_switched_off"] == "P5" and s["truth_dispersed"]
    assert set(s["table"]) == set(tmc.ESTIMATORS)
    assert "wind_down_mps" in s["table"]["ekf_pass2"] and "wind_down_mps" not in s["table"]["least_squares"]
    for m in loop.members:
        assert not m.failed and m.info["failed_ports"] == []
        assert np.isfinite(m.err[:, IQ["qbar_pct"], IE["ekf_pass2"]]).sum() > 1000
    # two different truths: the members' flights differ
    assert loop.members[0].info["truth"] != loop.members[1].info["truth"]
    rec = read_recording(tmp_path / "msl_meads_truth_mc.rrd")
    x, y = rec.scalars(layout.meads_truth_mc_path("qbar_pct", "ekf_pass2_mc"), layout.MACH_DESCENDING)
    bm, j = loop.by_mach, (slice(None), IQ["qbar_pct"], IE["ekf_pass2"])
    ok = bm["solid"][j] & np.isfinite(bm["mc_3sigma"][j])
    np.testing.assert_allclose(y[:, 0], bm["mc_3sigma"][j][ok], rtol=1e-12)  # sorted by x: high Mach first
    assert summary["by_mach"]["mach_lo"] == bm["mach_lo"].tolist() and summary["table_by_time"]
    assert "/plots/truth_mc/wind_down_mps/ekf_pass1_mc" in set(rec.entities())


def _constructed_result(K=5, n=40):
    rng = np.random.default_rng(2)
    t = np.arange(n) / 8.0
    err = rng.standard_normal((K, n, Q, E))
    sig = np.full_like(err, 0.5)
    err[..., IQ["wind_down_mps"], IE["least_squares"]] = np.nan
    mach = np.tile(np.linspace(12.0, 2.0, n), (K, 1)) + 0.3 * np.arange(K)[:, None]
    qbar = np.full((K, n), 1e3)
    qbar[:, :5] = 500.0  # below 850 Pa
    err[1:, :, IQ["beta_deg"], IE["ekf_pass1"]] = np.nan  # one member only: thin bins
    bm = tmc.aggregate_by_mach(err, sig, qbar, mach)
    summary = {
        "n_runs": K,
        "n_ok": K,
        "truth_dispersed": True,
        "failure_port_switched_off": "P5",
        "mc_3sigma_relative_uncertainty": 1 / math.sqrt(2 * (K - 1)),
        "min_qbar_pa": 850.0,
        "min_bin_members": 3,
        "objectives_3sigma": {"alpha_deg": 0.5, "beta_deg": 0.5, "qbar_pct": 2.0, "mach": 0.1},
        "executor": "in-process loop",
        "wall_s": 1.0,
        "member_wall_s": {"median": 0.2, "max": 0.3},
        "failed_members": [],
        **tmc.summarize(tmc.solid_bins(bm), over="Mach bins"),
        "by_mach": tmc.by_mach_json(bm),
    }
    agg = tmc.aggregate(err, sig)
    return tmc.FullMcResult(t, agg, mach[0], qbar[0], (), summary, bm), summary


def test_recording_holds_the_curves_against_mach_and_the_table(tmp_path):
    from workbench.problems.meads.recording_mc import mach_axis, record_truth_mc, truth_mc_markdown
    from workbench.recording.reader import read_recording

    res, summary = _constructed_result()
    md = truth_mc_markdown(summary)
    assert "| alpha_deg | least squares |" in md and "|  | EKF pass 2 |" in md and "P5 switched off" in md
    assert md.count("| mach |") == 1
    assert "| wind_down_mps | EKF pass 1 |" in md  # no least-squares vertical wind
    assert all(d in md for d in summary["disagreements"]) and summary["disagreements"]  # 3σ 1.5 vs MC ~3
    bm = res.by_mach
    assert "Per Mach bin, EKF pass 2" in md and f"| {bm['mach_lo'][0]:g}–{bm['mach_hi'][0]:g} |" in md
    path = record_truth_mc(tmp_path / "mc.rrd", "mc", res, summary)
    rec = read_recording(path)
    ents = set(rec.entities())
    assert layout.meads_truth_mc_path("wind_down_mps", "least_squares_mc") not in ents  # no values: no series
    assert layout.meads_truth_mc_path("density_pct", "objective") not in ents  # no objective for density
    assert layout.meads_truth_mc_path("beta_deg", "ekf_pass1_mc") not in ents  # thin everywhere: markers only
    x_axis = layout.MACH_DESCENDING
    x, y = rec.scalars(layout.meads_truth_mc_path("beta_deg", "ekf_pass1_mc_thin"), x_axis)
    seen = bm["count"][:, IQ["beta_deg"], IE["ekf_pass1"]] > 0  # member 0's bins above 850 Pa
    np.testing.assert_array_equal(x, np.sort(mach_axis(bm["mach_mid"][seen])))
    j = (slice(None), IQ["alpha_deg"], IE["ekf_pass2"])
    x, y = rec.scalars(layout.meads_truth_mc_path("alpha_deg", "ekf_pass2_mc"), x_axis)
    solid = bm["solid"][j]
    assert np.all(np.diff(x) > 0) and 3 < solid.sum() < solid.size  # the highest bins: too few members
    np.testing.assert_allclose(-x / 100.0, bm["mach_mid"][solid], atol=0.005)  # x = −100 · Mach, high first
    np.testing.assert_allclose(y[:, 0], bm["mc_3sigma"][j][solid], rtol=1e-12)
    xt, _ = rec.scalars(layout.meads_truth_mc_path("alpha_deg", "ekf_pass2_mc_thin"), x_axis)
    np.testing.assert_array_equal(xt, np.sort(mach_axis(bm["mach_mid"][~solid])))
    _, r = rec.scalars(layout.meads_truth_mc_path("alpha_deg", "ekf_pass2_reported"), x_axis)
    np.testing.assert_allclose(r[:, 0], 1.5)  # the median reported 3σ
    _, o = rec.scalars(layout.meads_truth_mc_path("mach", "objective"), x_axis)
    assert np.all(o[:, 0] == 0.1) and o.shape[0] == solid.sum()  # over the solid bins
