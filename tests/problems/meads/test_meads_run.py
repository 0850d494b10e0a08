"""MEADS end to end: the shipped scenario through the runner, and a unit error caught (slow tier)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.estimation.health import UnhealthyError
from workbench.io.telemetry import TelemetryError, read_telemetry, write_telemetry
from workbench.problems.runner import run_scenario

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return run_scenario("msl_meads", tmp_path_factory.mktemp("meads"))


def test_msl_meads_end_to_end(run):
    s = run.summary
    assert run.recording.stat().st_size > 1e6
    # the stuck P5 (150 s) is found within a second and dropped
    assert [f["port"] for f in s["failed_ports"]] == ["P5"]
    assert abs(s["failed_ports"][0]["t_s"] - 150.0) < 1.0
    fin = s["truth"]["final"]
    assert fin["beta_deg"]["max_abs"] < 0.5
    assert fin["qbar_pct"]["fraction_within_3sigma"] > 0.95
    assert fin["alpha_deg"]["fraction_within_3sigma"] > 0.95
    # the wind singularity is reported around both true zero crossings of the flight-path angle
    for tc in s["truth"]["true_fpa_zero_crossings_s"]:
        assert any(a - 2.0 <= tc <= b + 2.0 for a, b in s["wind_singular_intervals_s"]), tc
    # model form: the Newtonian model misses alpha by more than the table does
    assert s["truth"]["other_model_newtonian"]["alpha_deg"]["rms"] > fin["alpha_deg"]["rms"]


def test_kpa_labelled_pa_is_refused(run, tmp_path):
    tel = dict(run.telemetry)
    pr = read_telemetry(tel["pressures"], sparse=run.result.data.telemetry.ports)
    ports = run.result.data.telemetry.ports
    bad = tmp_path / "pressures.csv"
    write_telemetry(bad, pr.time, {n: (pr.channel(n) / 1e3, "Pa") for n in ports}, sparse=ports)  # kPa numbers, "Pa"
    toml = tmp_path / "user.toml"
    veh = run.settings.vehicle_file
    toml.write_text(
        f'[scenario]\nname = "kpa"\nkind = "meads"\n[vehicle]\nfile = "{veh}"\n[telemetry]\n'
        f'pressures = "{bad}"\nimu = "{tel["imu"]}"\ninitial_state = "{tel["initial_state"]}"\n'
    )
    with pytest.raises(TelemetryError, match=r"pressures.csv.*implausible pressures.*1e-3") as info:
        run_scenario(toml, tmp_path / "out")
    assert not (tmp_path / "out" / "kpa.summary.json").exists()
    assert np.isfinite(run.summary["plausibility_qbar_ratio"])
    assert "P1 [Pa]" in str(info.value)


def test_health_verdict_of_the_shipped_run(run):
    """The shipped run carries a verdict; its WLS residual χ² is judged, nothing is an ERROR."""
    h = run.summary["health"]
    names = {c["name"]: c for c in h["checks"]}
    assert h["verdict"] in ("OK", "WARNING")
    assert any(n.startswith("nis.pressure_wls_dof") for n in names)
    for n in ("covariance.wls_qbar_alpha_beta", "plausibility.qbar_vs_imu_drag", "density.vs_default"):
        assert names[n]["status"] == "OK", names[n]
    # the planted stuck P5, detected and excluded, is a note, not a WARNING
    assert "telemetry" not in names and names["data.failed_ports"]["status"] == "OK"
    assert any(n.startswith("port P5 failed at") for n in h["notes"])
    # no check whose bound is physics fails on the shipped run (the NIS bands are the calibration's)
    assert not [c for c in h["checks"] if c["status"] != "OK" and not c.get("stat")]
    for n in ("physics.imu_vs_pressure_alpha", "physics.imu_vs_pressure_beta", "physics.accel_axis_deg"):
        assert names[n]["status"] == "OK", names[n]
    # the headline (EKF pass 2 at peak q∞) inside its own 3σ
    for n in ("truth.alpha_at_peak_qbar", "truth.beta_at_peak_qbar", "truth.qbar_at_peak_qbar"):
        assert names[n]["status"] == "OK", names[n]


def test_no_model_form_allowance_is_unhealthy(run, tmp_path):
    """The same telemetry reduced with port σ that leave out the model-form allowance: the WLS
    residuals are far outside their χ² bounds, so the run is refused (exit 6), nothing published."""
    tel = dict(run.telemetry)
    veh = run.settings.vehicle_file
    toml = tmp_path / "tight.toml"
    toml.write_text(
        f'[scenario]\nname = "tight"\nkind = "meads"\n[vehicle]\nfile = "{veh}"\n[telemetry]\n'
        f'pressures = "{tel["pressures"]}"\nimu = "{tel["imu"]}"\ninitial_state = "{tel["initial_state"]}"\n'
        "[estimator]\nmodel_error_frac = 0.0\n"
    )
    with pytest.raises(UnhealthyError, match="nis.pressure_wls_dof"):
        run_scenario(toml, tmp_path / "out")
    assert not (tmp_path / "out" / "tight.summary.json").exists()


def test_key_moments_of_the_flush_air_data(run):
    """Peak q∞ at the largest reconstructed q∞, the stuck port at its detection, in time order."""
    km = run.summary["key_moments"]
    t = {m["name"]: m["t_s"] for m in km}
    assert {"peak_qbar", "max_alpha", "max_beta", "port_failure"} <= set(t)
    assert [m["t_s"] for m in km] == sorted(t.values())
    air = run.result.air
    assert t["peak_qbar"] == air.t[np.nanargmax(air.fit.qbar)]
    assert t["port_failure"] == run.summary["failed_ports"][0]["t_s"]


def test_ekf_passes_of_the_shipped_run(run):
    """The tightly-coupled EKF (Sect. III.B), both passes, against the CFD-like truth above 850 Pa."""
    s, tr = run.summary, run.summary["truth"]
    labels = [k for k in s["stage_times_s"] if k.startswith("EKF pass")]
    assert len(labels) == 2 and labels[0].startswith("EKF pass 1/2") and labels[1].startswith("EKF pass 2/2")
    ls, p1, p2 = tr["final"], tr["ekf_pass1"], tr["ekf_pass2"]
    # pass 2 errors inside the reported 3σ for (nearly) every sample (every sample measured, seeds
    # 11/1/2; before the model error was a state α 91 %); q∞ thanks to the model-level state c
    keys = ("alpha_deg", "beta_deg", "qbar_pct", "mach", "p_inf_pct", "density_pct", "wind_north_mps", "wind_east_mps")
    for k in keys:
        assert p2[k]["n"] > 900 and p2[k]["fraction_within_3sigma"] > 0.97, (k, p2[k])
    # the IMU coupling pins the angles: α, β far better than the point-wise least squares
    for k in ("alpha_deg", "beta_deg"):
        assert p1[k]["rms"] < 0.5 * ls[k]["rms"] and p2[k]["rms"] < 0.5 * ls[k]["rms"], k
    # winds where the least squares publish none (singular or too uncertain), inside their 3σ above
    # (every sample on this seed).  The accuracy bound follows the tuning (history: docs/tuning/meads.md):
    # 10 m/s, then 15 m/s with the Gauss–Markov vertical wind, then 20 m/s since the wind random walk
    # was retuned on the tuning stream for an honest 3σ (its error grew with it)
    assert ls["wind_north_mps"]["n"] == 0 and p2["wind_north_mps"]["max_abs"] < 20.0
    names = {c["name"]: c for c in s["health"]["checks"]}
    for i in (1, 2):
        assert names[f"covariance.ekf_pass{i}_smoothed_correlation"]["status"] == "OK"
        nis = [c for n, c in names.items() if n.startswith(f"nis.pressure_ekf_pass{i}_")]
        assert len(nis) == 7 and all(c["status"] in ("OK", "WARNING") for c in nis)
    sf = tr["ekf_scale_factors"]
    assert len(sf["estimate"]) == 7 and all(0 < v < 0.01 for v in sf["sigma"])


def test_ekf_scale_factors_inside_their_3_sigma(run):
    """Pass 1's transducer scale factors against the truth's: with the table's model-form error a
    coloured state (not λ) every port inside its 3σ (4 of 7 when R carried it as white noise)."""
    sf = run.summary["truth"]["ekf_scale_factors"]
    assert sf["fraction_within_3sigma"] == 1.0, sf
    assert abs(sf["common_mode_error"]) < 0.005, sf


def test_ekf_innovations_inside_their_band(run):
    """Mean per-port NIS of both passes above 850 Pa (χ²(1) each): not optimistic (below 2) and no
    longer an order of magnitude conservative (above 0.1; 0.02–0.08 when R carried the 1 % model
    allowance as white noise; measured 0.14–0.20: the first-order Markov and the random walks add
    more per-step variance than the smooth truth shows, see problems/meads/ekf.py)."""
    for i in (1, 2):
        nis = [v for v in run.summary["ekf"][f"pass{i}"]["mean_nis_per_port_above_min_qbar"] if v is not None]
        assert len(nis) == 7 and all(0.1 < v < 2.0 for v in nis), (i, nis)


def test_ekf_in_the_recording(run):
    """The EKF's outputs sit next to the least squares', its scale factors converge to the summary's
    values, its innovations are there per port (the default blueprint's views)."""
    from workbench.recording import layout
    from workbench.recording.reader import read_recording

    rec = read_recording(run.recording)
    ents = set(rec.entities())
    for q in ("alpha_deg", "beta_deg", "qbar_kPa", "mach", "wind_north_mps", "wind_east_mps"):
        assert layout.join(layout.meads_ekf_plot_path(q, 2), layout.VALUE) in ents, q
        assert layout.join(layout.meads_ekf_plot_path(q, 1), layout.VALUE) in ents, q
    _, lam = rec.scalars(layout.join(layout.meads_scale_factor_path("pass1"), layout.VALUE))
    np.testing.assert_allclose(lam[-1] / 100.0, run.summary["ekf"]["pass1"]["scale_factors"], atol=2e-4)
    failed = {f["port"]: f["t_s"] for f in run.summary["failed_ports"]}
    for p in run.result.data.telemetry.ports:
        t, y = rec.scalars(layout.join(layout.meads_ekf_innovation_path(2, p), layout.VALUE))
        assert np.isfinite(y[0]) and np.isfinite(y[-1])  # NaN (a gap) only inside
        if p in failed:  # no innovation after the failure: the line ends there, not a flat zero
            assert t[-1] < failed[p] and np.isfinite(y).sum() > 1000
        else:
            assert np.isfinite(y).sum() > 2000


def test_port_labels_in_the_recording(run):
    """The port names move with the ports (timed rows, seven per row, one leader line each), on the
    circle around the nose that keeps them apart on screen."""
    from workbench.problems.meads.recording import LABEL_RING_M
    from workbench.recording import layout
    from workbench.recording.reader import read_recording

    rec = read_recording(run.recording)
    t, rows = rec.points(layout.MEADS_PORT_LABELS)
    _, leaders = rec.line_strips(layout.MEADS_PORT_LEADERS)
    assert t.size > 100 and len(leaders) == t.size
    assert all(r.shape == (7, 3) for r in rows) and all(len(s) == 7 for s in leaders)
    np.testing.assert_allclose(np.linalg.norm(np.concatenate(rows), axis=1), LABEL_RING_M, rtol=1e-5)
    labels = rec.static_component(layout.MEADS_PORT_LABELS, "Points3D:labels")
    assert list(labels) == list(run.result.data.telemetry.ports)


def test_recording_draws_gaps_not_zeros(run):
    """Where a port was not used or the least squares publish no wind, the recording holds NaN (a
    gap in the viewer's line) or no row at all: never a value of exactly 0 with a zero-width band,
    which reads as a perfect fit or a perfectly known calm."""
    from workbench.recording import layout
    from workbench.recording.reader import read_recording

    rec = read_recording(run.recording)
    plus, minus = layout.bound_names(3.0)
    failed = {f["port"]: f["t_s"] for f in run.summary["failed_ports"]}
    roots = [layout.plot_path(q) for q in ("wind_north_mps", "wind_east_mps")]
    roots += [layout.residual_path("pressure", p) for p in run.result.data.telemetry.ports]
    roots += [layout.meads_ekf_innovation_path(2, p) for p in run.result.data.telemetry.ports]
    for root in roots:
        t, v = rec.scalars(layout.join(root, layout.VALUE))
        _, hi = rec.scalars(layout.join(root, plus))
        _, lo = rec.scalars(layout.join(root, minus))
        flat = (v == 0.0) & (hi - lo == 0.0)
        assert not flat.any(), (root, t[flat.ravel()][:5])
        port = root.rstrip("/").rsplit("/", 1)[-1]
        if port in failed:
            assert t[-1] < failed[port], root
    # the shipped run publishes no least-squares wind: all of it a gap
    _, w = rec.scalars(layout.join(layout.plot_path("wind_north_mps"), layout.VALUE))
    assert np.isnan(w).sum() >= int(0.5 * w.size)


def test_export_marks_unsolved_samples_empty_and_reads_back(run, tmp_path):
    """``--export``: where the least squares has no solution (no 1σ: low q∞ early in the entry) the
    value is an empty cell too, the columns are declared sparse, and the file reads back."""
    from workbench.io.results import export_csv
    from workbench.io.telemetry import read_telemetry

    table = run.problem.export_columns(run.result)
    assert "sigma_qbar" in table.sparse and "qbar" in table.sparse
    path = export_csv(tmp_path / "x.csv", table.time_s, table.columns, sparse=table.sparse)
    tel = read_telemetry(path)
    q, sq = tel.channels["qbar"], tel.channels["sigma_qbar"]
    assert np.array_equal(np.isnan(q), np.isnan(sq)) and np.isnan(q).any() and np.isfinite(q).sum() > 1000
    assert np.all(np.isfinite(tel.channels["ekf_qbar"]))  # the filter runs through every sample


def test_swapped_accelerometer_axes_are_refused(run, tmp_path):
    """The shipped telemetry with the accelerometer's y and z columns swapped (the EKF's α then off
    by a median 2.6°, density by 20 %): the pressures' flow angles and the IMU's disagree, the run is
    refused (exit 6) naming the columns."""
    tel = dict(run.telemetry)
    imu = read_telemetry(tel["imu"])
    cols = {n: (imu.channel(n), imu.units[n]) for n in imu.names}
    cols["f_y"], cols["f_z"] = cols["f_z"], cols["f_y"]
    bad = tmp_path / "imu.csv"
    write_telemetry(bad, imu.time, {n: cols[n] for n in imu.names})
    veh = run.settings.vehicle_file
    toml = tmp_path / "swap.toml"
    toml.write_text(
        f'[scenario]\nname = "swap"\nkind = "meads"\n[vehicle]\nfile = "{veh}"\n[telemetry]\n'
        f'pressures = "{tel["pressures"]}"\nimu = "{bad}"\ninitial_state = "{tel["initial_state"]}"\n'
        '[estimator]\nmodel = "table"\n'
    )
    with pytest.raises(UnhealthyError, match=r"physics\.imu_vs_pressure_beta.*accelerometer axes y and z swapped"):
        run_scenario(toml, tmp_path / "out")
    assert not (tmp_path / "out" / "swap.summary.json").exists()
