"""The Schiaparelli-like entry run end to end through the CLI path, read back from the ``.rrd``.

One synthetic run (truth simulation, telemetry files, reconstruction with a 2 000-member dispersion
for CI speed, recording) is shared by the module.  The tests check that every stage the issue asks
for is in the recording with consistent row counts, that the scorecard's accuracy numbers against the
synthetic truth meet the issue's bounds, and that the same telemetry given as *user* data (a
scenario with a ``[telemetry]`` table) goes through the same code path.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from scipy.stats import chi2

from workbench.cli import main
from workbench.io.assets import assets_dir
from workbench.io.scenario import Scenario, ScenarioError, load_scenario
from workbench.problems.base import RunOptions
from workbench.problems.entry import pipeline as en
from workbench.problems.entry.problem import EntryProblem
from workbench.problems.entry.telemetry import STREAMS, read_nominal_state
from workbench.problems.runner import run_scenario
from workbench.recording import layout
from workbench.recording.reader import read_recording, verify

MEMBERS = 2000


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    out = tmp_path_factory.mktemp("entry")
    return out, run_scenario("schiaparelli", out, RunOptions(members=MEMBERS))


@pytest.fixture(scope="module")
def run(full):
    out, r = full
    return out, r.summary


@pytest.fixture(scope="module")
def rec(run):
    out, _ = run
    return read_recording(out / "schiaparelli.rrd")


def test_recording_verifies_and_no_partial_left(run):
    out, summary = run
    ok, msg = verify(out / "schiaparelli.rrd")
    assert ok, msg
    assert not list(out.rglob("*.partial"))
    assert summary["recording_bytes"] == (out / "schiaparelli.rrd").stat().st_size
    on_disk = json.loads((out / "schiaparelli.summary.json").read_text())
    assert on_disk["dispersion"]["members"] == MEMBERS


def test_every_stage_is_in_the_recording(rec):
    ents = set(rec.entities())
    required = [
        layout.SURFACE,
        layout.VEHICLE,
        layout.VEHICLE_BODY,
        layout.UNCERTAINTY,
        layout.ESTIMATE_FORWARD,
        layout.ESTIMATE_SMOOTHED,
        "/world/estimate/nominal",
        "/world/onboard/track",
        "/world/truth/track",
        "/world/dispersion/at_PDD_accepted",
        "/world/estimate/forward_vehicle/uncertainty",
        "/world/dispersion/at_PDD_rejected",
        *[layout.radar_beam_path(b) for b in range(4)],
        "/plots/imu/f_G",
        "/plots/strapdown/h_amr/value",
        "/plots/altitude_agl/smoothed/value",
        "/plots/altitude_agl/plane_fit",
        "/residuals/rda/slant_out/value",
        "/residuals/rda/slant_out/plus_3sigma",
        "/residuals/rda/velocity_out/x/value",
        "/residuals/rda/slant_range/B0/value",
        "/profiles/density/smoothed",
        "/profiles/density/truth",
        "/profiles/density/default",
        "/profiles/temperature/smoothed",
        "/profiles/pressure/plus_1sigma",
        "/profiles/density/iteration",
        "/profiles/wind/north",
        "/profiles/wind/east_truth",
        layout.EVENTS,
        layout.REPORT,
    ]
    missing = [e for e in required if e not in ents]
    assert not missing, missing


def test_row_counts_are_consistent(rec, run):
    _, summary = run
    n = summary["samples"]
    t_pose, tr, q = rec.transforms(layout.VEHICLE)
    t_body, _, q_body = rec.transforms(layout.VEHICLE_BODY)
    assert len(t_pose) == n and len(t_body) == n
    assert rec.row_count(layout.VEHICLE, layout.STEP) == n
    assert np.allclose(np.linalg.norm(q_body, axis=1), 1.0, atol=1e-6)
    t_e, c, h, _ = rec.ellipsoids(layout.UNCERTAINTY)
    assert len(t_e) == n and np.all(h > 0)
    # float32-safe site frame: the whole track stays within ±1000 km of the origin
    assert np.max(np.abs(tr)) < 1.0e6
    beams = [rec.row_count(layout.radar_beam_path(b)) for b in range(4)]
    assert beams[0] > 300 and len(set(beams)) == 1
    # the same rows on the `step` timeline as on `time` (scrubbing by filter step shows everything)
    assert rec.row_count(layout.UNCERTAINTY, layout.STEP) == n
    # the Descent view names the smoothed 3σ ellipsoid's semi-axes at every step (it leaves it out)
    _, labels = rec.points(layout.ENTRY_UNCERTAINTY_LABEL)
    assert len(labels) == n and layout.VEHICLE_MARKER in rec.entities()
    # the Entry view names the two 3σ ellipsoids above / below them, not at their common centre
    assert "Ellipsoids3D:labels" not in rec.components(layout.UNCERTAINTY)
    assert "Ellipsoids3D:labels" not in rec.components(layout.ENTRY_FORWARD_UNCERTAINTY)
    assert rec.static_component(layout.ENTRY_UNCERTAINTY_SIGMA_LABEL, "Points3D:labels") == ["3σ smoothed"]
    assert rec.static_component(layout.ENTRY_FORWARD_SIGMA_LABEL, "Points3D:labels") == ["3σ forward"]
    _, above = rec.points(layout.ENTRY_UNCERTAINTY_SIGMA_LABEL)
    _, below = rec.points(layout.ENTRY_FORWARD_SIGMA_LABEL)
    assert len(above) == n and above[-1][0, 2] - below[-1][0, 2] >= 16e3
    assert [rec.row_count(layout.radar_beam_path(b), layout.STEP) for b in range(4)] == beams
    # one row per member on the `sample` timeline, split into accepted + rejected
    acc = rec.row_count("/plots/dispersion/h_pdd/accepted", layout.SAMPLE)
    rej = rec.row_count("/plots/dispersion/h_pdd/rejected", layout.SAMPLE)
    assert acc + rej == MEMBERS
    assert acc == round(summary["dispersion"]["accepted_fraction"] * MEMBERS)
    assert rec.row_count("/profiles/density/iteration", layout.ITERATION) == summary["atmosphere"]["iterations"]


def test_forward_uncertainty_grows_through_the_blackout_and_shrinks_at_the_radar_fix(rec, run):
    _, summary = run
    t, _, h, _ = rec.ellipsoids("/world/estimate/forward_vehicle/uncertainty")
    h = h[:, 0, :]  # (n, 3) 3σ semi-axes [m]
    dt = np.diff(t)
    k = int(np.argmax(dt))  # the 57 s blackout
    assert dt[k] > 50.0
    # bridged with the on-board Δv/Δp/ΔC plus their uncertainty: the ellipsoid grows (major axis +20 %)
    assert h[k + 1].max() > 1.1 * h[k].max()
    # at the radar fix the vertical (smallest) axis collapses from kilometres to about a hundred metres
    t_fix = summary["events"].get("RDA_ON", 222.65)
    before = h[(t < t_fix) & (t > t_fix - 2.0)].min(axis=1).max()
    after = h[t > t_fix + 5.0].min(axis=1).max()
    assert before > 1000.0 and after < 0.1 * before
    # the altitude 3σ plot of the forward pass shows the same collapse
    ts, h3 = rec.scalars("/plots/sigma_position/altitude_3sigma_forward")
    h3 = np.asarray(h3).reshape(len(ts), -1)[:, 0]
    assert h3[np.asarray(ts) > t_fix + 5.0].max() < 0.1 * h3[(np.asarray(ts) < t_fix)].max()


def test_scorecard_and_event_table(rec, run):
    _, summary = run
    md = rec.text_document(layout.REPORT)
    assert "Table 5" in md and "PDD" in md and "FSR" in md
    names = [r["event"] for r in summary["event_table"]]
    assert names[0] == "First data" and names[-1] == "Last data"
    assert {"EIP", "PDD", "FSR", "BSR"} <= set(names)
    # both conventions: the paper's (meridian at the UTC date, MMED latitude) is ahead in longitude by
    # the 68.184 s TT − UTC of 2016 (0.277° of Mars rotation) less the pole/node drift since J2000
    for r in summary["event_table"]:
        assert 0.25 < r["lon_amelia_deg"] - r["lon_deg"] < 0.28
        assert abs(r["lat_amelia_deg"] - r["lat_deg"]) < 0.01
    assert "as AMELIA" in md
    log = " ".join(text for _, text, _ in rec.text_log())
    assert "gap" in log and "saturated" in log and "plane fit" in log


def test_accuracy_against_the_independent_truth(run):
    """Against a truth the estimator does not share (planted coefficients, its own atmosphere,
    IMU errors, terrain relief): what must hold whatever the bounds say."""
    _, s = run
    tr = s["truth"]
    fix = tr["after_radar_fix"]
    # the radar pins the altitude to within the terrain relief the filter does not model
    radar = tr["radar"]
    assert fix["max_h_agl_error_m"] < radar["slant_out_rms_error_vs_sphere_m"] + 3.0 * fix["median_3sigma_m"]
    assert radar["slant_out_rms_terrain_m"] > 30.0  # the relief is there and seen by the beams
    assert s["radar_residuals"]["slant_out"]["max_abs"] < 3.0 * radar["slant_out_max_abs_error_vs_sphere_m"]
    assert s["radar_residuals"]["velocity_out"]["max_abs"] < 20.0  # AMELIA Sect. 8 bound (no relief in Doppler)
    assert s["atmosphere"]["converged"] and s["atmosphere"]["iterations"] <= 6
    assert s["covariance"]["symmetric"] and s["covariance"]["positive_definite"]
    # the smoother's initial state holds the truth inside its covariance (99.9 % χ², 9 dof)
    assert tr["initial_smoother_start"]["nees_9dof"] < chi2.ppf(0.999, 9)
    # density, pressure and temperature errors come with their σ, and the σ covers them outside
    # the blackout: the error is inside 3σ nearly everywhere and the σ is not inflated tenfold
    atm = tr["atmosphere"]
    for seg in ("entry_measured", "under_parachute"):
        a = atm[seg]
        assert a["density_fraction_within_3sigma"] > 0.95, seg
        assert 0.3 < a["density_error_over_sigma_rms_ratio"] < 2.0, seg
        assert a["pressure_fraction_within_3sigma"] > 0.9 and a["temperature_fraction_within_3sigma"] > 0.9, seg
    # the planted drag-coefficient error is in the density error: it is not below what the
    # table's coefficient error alone would give at the bound-setting samples
    ent = atm["entry_measured"]
    assert ent["drag_coefficient_rel_error_max_abs"] > 0.03
    assert ent["density_max_abs_error_rel"] > 0.5 * ent["drag_coefficient_rel_error_max_abs"]
    # winds: errors next to their σ
    w = tr["winds_in_layers"]
    assert w["rms_error_mps"] < 5.0 and w["fraction_within_5mps"] > 0.9
    assert w["wind_N_fraction_within_3sigma"] > 0.9 and w["wind_E_fraction_within_3sigma"] > 0.9


def test_scorecard_reports_bounds_as_measured(run, rec):
    """Each AMELIA bound is PASS or FAIL as measured, in the summary, the scorecard and the headline."""
    from workbench.problems.entry.problem import EntryProblem

    _, s = run
    atm = s["truth"]["atmosphere"]
    for seg, bound in en.DENSITY_BOUNDS.items():
        a = atm[seg]
        assert a["density_bound_rel"] == bound
        assert a["density_bound_pass"] == (a["density_max_abs_error_rel"] <= bound)
        for k in ("density", "pressure", "temperature"):
            assert 0.0 <= a[f"{k}_fraction_within_2sigma"] <= a[f"{k}_fraction_within_3sigma"] <= 1.0
    w = s["truth"]["winds_in_layers"]
    assert w["bound_pass"] == (w["max_error_mps"] <= en.WIND_BOUND_MPS)
    md = en.scorecard_markdown(s)
    n_fail = sum(not atm[seg]["density_bound_pass"] for seg in en.DENSITY_BOUNDS) + (not w["bound_pass"])
    n_pass = md.count("| PASS |") + md.count("m/s: PASS)")  # the density table cells and the wind line
    assert md.count("**FAIL**") == n_fail and n_pass == 4 - n_fail
    head = EntryProblem().headline(s)
    assert head.count("FAIL") == n_fail and "density max error" in head


def test_strapdown_validated_against_onboard_solution(run):
    _, s = run
    v = s["nominal_integration"]["vs_onboard_before_pdd"]
    # the paper saw 7.5 m/s and 530 m against its on-board solution
    assert v["max_velocity_mps"] < 10.0 and v["max_position_m"] < 1000.0 and v["max_attitude_deg"] < 0.5
    assert s["gaps_s"] == pytest.approx([1.4, 1.8, 3.3, 57.2], abs=0.05)
    assert s["saturated_samples"] > 0


@pytest.mark.slow
def test_user_telemetry_takes_the_same_path(run, tmp_path):
    out, s = run
    tel = tmp_path / "flight"
    shutil.copytree(out / "schiaparelli" / "telemetry", tel)
    (tel / "truth.npz").unlink()  # a user has no truth
    base = load_scenario(assets_dir() / "scenarios" / "schiaparelli.toml")
    data = {k: v for k, v in base.data.items() if k not in ("synthetic", "truth")}
    data["scenario"] = dict(data["scenario"], name="my_entry")
    data["vehicle"] = {"file": str(base.path_of("vehicle.file"))}
    data["telemetry"] = {k: str(tel / f"{k}.{'toml' if k == 'initial_state' else 'csv'}") for k in STREAMS}
    user_sc = Scenario(tmp_path / "my_entry.toml", "my_entry", "entry", "user data", data)
    assert not user_sc.is_synthetic
    user = run_scenario(user_sc, tmp_path / "rec", RunOptions(members=MEMBERS)).summary
    assert "truth" not in user
    assert user["dispersion"]["accepted"] == s["dispersion"]["accepted"]
    assert user["end"]["h_agl_m"] == pytest.approx(s["end"]["h_agl_m"], abs=1e-6)
    assert (tmp_path / "rec" / "my_entry.rrd").exists()


def test_bad_nominal_state_is_a_located_input_error(tmp_path, run):
    out, _ = run
    bad = tmp_path / "initial_state.toml"
    text = (out / "schiaparelli" / "telemetry" / "initial_state.toml").read_text()
    import re

    bad.write_text(re.sub(r"quaternion_jpl = \[[^\]]*\]", "quaternion_jpl = [0.9, 0.1, 0.0, 0.1]", text))
    with pytest.raises(ScenarioError, match="quaternion_jpl"):
        read_nominal_state(bad)


def test_cli_exit_code_for_unknown_scenario():
    assert main(["run", "no_such_scenario", "--out", "/tmp/none"]) == 3


def test_filled_blackout_density_within_20_percent(run):
    """AMELIA's 20 % on the filled blackout, for the shipped seed (the fill's temperature: an offset and a
    linear trend from the two edges, ``fill_temperature_shape = "linear"``; across dispersed truths it is
    not always met: docs/RESULTS.md)."""
    _, s = run
    assert s["truth"]["atmosphere"]["entry_filled_blackout"]["density_max_abs_error_rel"] < 0.20


def test_filled_blackout_error_inside_its_reported_3sigma(run):
    """The blackout fill's σ (a stated temperature prior, not a fit to the truth) covers its error."""
    _, s = run
    a = s["truth"]["atmosphere"]["entry_filled_blackout"]
    assert a["density_fraction_within_3sigma"] > 0.9
    assert a["density_rms_sigma_rel"] > 0.05  # a fill is never claimed to be as good as a measurement


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("reconstruction.bridge_mode", "exact", "bridge_mode"),
        ("winds.method", "drag", "winds.method"),
        ("radar.azimuths_deg", [0.0, 120.0], "azimuths_deg"),
        ("dispersion.rules.mach_pd", [2.0, 0.2], "mach_pd"),
        ("dispersion.rules.h_pdd_m", 10000.0, "h_pdd_m"),
        ("dispersion.members", 0, "members"),
    ],
)
def test_bad_entry_configuration_is_a_located_error(key, value, match):
    base = load_scenario(assets_dir() / "scenarios" / "schiaparelli.toml")
    with pytest.raises(ScenarioError, match=match):
        EntryProblem().settings(base.with_overrides({key: value}))


def test_initial_state_at_the_wrong_time_is_rejected(run, tmp_path):
    out, _ = run
    tel = tmp_path / "tel"
    shutil.copytree(out / "schiaparelli" / "telemetry", tel)
    f = tel / "initial_state.toml"
    f.write_text(f.read_text().replace("t0_s = -15.000000", "t0_s = 5.0"))
    paths = {k: tel / f"{k}.{'toml' if k == 'initial_state' else 'csv'}" for k in STREAMS}
    sc = EntryProblem().settings(load_scenario(assets_dir() / "scenarios" / "schiaparelli.toml"))
    with pytest.raises(ScenarioError, match="t0_s"):
        for _ in en.reconstruct(sc, paths, members=200):
            pass


def test_missing_pdd_event_is_a_located_error(run, tmp_path):
    out, _ = run
    tel = tmp_path / "tel"
    shutil.copytree(out / "schiaparelli" / "telemetry", tel)
    ev = tel / "events.csv"
    ev.write_text("\n".join(line for line in ev.read_text().splitlines() if not line.endswith(",PDD")) + "\n")
    paths = {k: tel / f"{k}.{'toml' if k == 'initial_state' else 'csv'}" for k in STREAMS}
    sc = EntryProblem().settings(load_scenario(assets_dir() / "scenarios" / "schiaparelli.toml"))
    with pytest.raises(ScenarioError, match="PDD"):
        for _ in en.reconstruct(sc, paths, members=200):
            pass


def test_imu_error_process_noise_reaches_each_error_at_the_end_of_the_arc():
    """A random walk with the returned PSD reaches, at the arc's end, the 1σ the constant error
    accumulates: b T for a bias, s ΔV for a scale factor; zero levels give zero noise."""
    t = np.arange(0.0, 200.0 + 1e-9, 0.1)
    f = np.zeros((t.size, 3))
    f[:, 2] = 20.0  # ΔV = 4000 m/s
    w = np.zeros((t.size, 3))
    w[:, 2] = np.radians(16.0)
    T = 200.0
    eta = en.imu_error_process_noise(t, f, w, {"accel_bias": 1e-3})
    assert np.sqrt(eta[0] * T) == pytest.approx(1e-3 * T) and np.all(eta[3:] == 0.0)
    eta = en.imu_error_process_noise(t, f, w, {"accel_scale": 3e-4, "gyro_scale": 1e-4})
    assert np.sqrt(eta[1] * T) == pytest.approx(3e-4 * 4000.0)
    assert np.sqrt(eta[4] * T) == pytest.approx(1e-4 * np.radians(16.0) * T)
    assert np.all(en.imu_error_process_noise(t, f, w, {}) == 0.0)


def test_key_moments_of_the_entry(run, rec):
    """EIP, peak deceleration, PDD, opening load, FSR, the radar, BSR and the end, from the
    reconstruction, in time order: the telemetry events at their times, the peak deceleration
    between EIP and PDD, the opening load in the 10 s after PDD, the first
    radar fix after the radar is switched on; logged as bookmarks and the recording property."""
    from workbench.recording.moments import read_key_moments

    _, summary = run
    km = summary["key_moments"]
    t = {m["name"]: m["t_s"] for m in km}
    ev = summary["events"]
    assert {"eip", "pdd", "fsr", "rda_on", "bsr", "peak_deceleration", "first_radar_fix", "end"} <= set(t)
    assert [m["t_s"] for m in km] == sorted(m["t_s"] for m in km)
    assert t["eip"] == ev["EIP"] and t["pdd"] == ev["PDD"] and t["fsr"] == ev["FSR"]
    assert ev["EIP"] < t["peak_deceleration"] < ev["PDD"] <= t["opening_load"] <= ev["PDD"] + 10
    assert ev["RDA_ON"] <= t["first_radar_fix"] <= summary["end"]["t_s"] == t["end"]
    if summary["saturation_window_samples"]:
        assert "saturation" in t
    peak = next(m for m in km if m["name"] == "peak_deceleration")
    # seed 7: the true peak (84 s) lies inside the 33.7-90.9 s blackout, so it is undefined, and said so
    assert "undefined" in peak["description"] and "33.70–90.90 s data gap" in peak["description"]
    assert " g₀" not in peak["description"] and "h AGL" in peak["description"]
    opening = next(m for m in km if m["name"] == "opening_load")
    assert " g₀ (" in opening["description"]
    assert [m.to_dict() for m in read_key_moments(rec)] == km


# ------------------------------------------------------------------ health: physics cross-checks


def _checks(summary: dict) -> dict:
    return {c["name"]: c for c in summary["health"]["checks"]}


def test_shipped_run_health_has_no_non_statistic_warning(run):
    """Every non-OK check of the shipped run is a filter statistic the truth-MC calibration judges
    (radar NIS, stat kind nis with its dof); the blackouts away from the key events are notes, the
    peak deceleration inside the blackout is said undefined; the new cross-checks are OK."""
    _, s = run
    c = _checks(s)
    assert [n for n, x in c.items() if x["status"] != "OK" and not x.get("stat")] == []
    for name, dof in (("nis.slant_out", 1), ("nis.velocity_out", 3), ("nis.slant_range", 4)):
        assert c[name]["stat"] == {"kind": "nis", "dof": dof}
    for name in (
        "geometry.drag_axis",
        "units.radar_first_lock",
        "dispersion.accepted",
        "gaps.PDD",
        "gaps.FSR",
        "gaps.radar_lock",
        "gaps.peak_deceleration",
        "telemetry",
    ):
        assert c[name]["status"] == "OK", c[name]
    assert c["geometry.drag_axis"]["value"] > 0.99
    assert 0.75 < c["units.radar_first_lock"]["value"] < 1.25
    notes = s["health"]["notes"]
    assert sum("telemetry gap away from the key events" in n for n in notes) == 6
    assert any("peak deceleration lies inside the data gap" in n and "33.700–90.900" in n for n in notes)


def test_headline_is_judged_against_the_truth(run):
    """The headline's h AGL at the end: its error against the truth and its 1σ, inside 3σ (seed 7)."""
    _, s = run
    (h,) = s["truth"]["headline"]
    assert h["name"] == "h_agl_end" and h["unit"] == "m"
    assert h["sigma"] == pytest.approx(s["end"]["sigma_h_m"])
    assert abs(h["error"]) < 3 * h["sigma"]
    assert _checks(s)["truth.h_agl_end"]["status"] == "OK"


def _flip_body_x(path):
    """The GNC file's body frame turned 180° about X (rates w_y, w_z and the quaternions with it):
    self-consistent, but +Z now points at the front shield."""
    from workbench.core.rotation import quat_conjugate, quat_from_axis_angle, quat_from_jpl, quat_multiply, quat_to_jpl

    lines = path.read_text(encoding="utf-8").splitlines()
    h = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    hdr = [c.split(" [")[0] for c in lines[h].split(",")]
    iq = [hdr.index(f"q{i}") for i in range(1, 5)]
    iw = [hdr.index("w_y"), hdr.index("w_z")]
    rx = quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), np.pi)
    out = lines[: h + 1]
    for ln in lines[h + 1 :]:
        r = ln.split(",")
        for j in iw:
            r[j] = repr(-float(r[j]))
        q = quat_to_jpl(
            quat_conjugate(quat_multiply(quat_conjugate(quat_from_jpl(np.array([float(r[i]) for i in iq]))), rx))
        )
        for i, x in zip(iq, q, strict=True):
            r[i] = repr(float(x))
        out.append(",".join(r))
    path.write_text("\n".join(out) + "\n", encoding="utf-8")


def test_body_frame_flipped_against_the_vehicle_is_a_located_error(run, tmp_path):
    """The drag must lie along the vehicle's declared +Z_G: a GNC body frame turned 180° about X
    (self-consistent rates and quaternions, so the unit and axis checks pass) stops at the drag-axis
    check, an input error naming the GNC file and the axis the drag lies along (exit 3)."""
    from workbench.io.telemetry import TelemetryError

    out, _ = run
    tel = tmp_path / "tel"
    shutil.copytree(out / "schiaparelli" / "telemetry", tel)
    _flip_body_x(tel / "gnc.csv")
    sc = load_scenario(assets_dir() / "scenarios" / "schiaparelli.toml")
    settings = EntryProblem().settings(sc)
    paths = {k: tel / f"{k}.{'toml' if k == 'initial_state' else 'csv'}" for k in STREAMS}
    stages = en.reconstruct(settings, paths, members=100)
    next(stages)  # the telemetry passes its own checks
    with pytest.raises(TelemetryError, match=r"drag lies along −Z_G.*declares \+Z_G") as e:
        next(stages)
    assert e.value.file == str(tel / "gnc.csv")


def test_radar_in_feet_or_km_fails_the_first_lock_check(full):
    """The first slant-out is predicted from the inertial trajectory before any radar update, so a
    radar unit mix-up scales only the measurement: feet (×3.28) and km (×0.001) are ERRORs naming the
    unit; the clean run's ratio is OK."""
    import dataclasses

    from workbench.problems.entry.health import radar_first_lock_check

    ih = full[1].result.filter.innovations["slant_out"]
    assert radar_first_lock_check(ih).status == "OK"
    for factor, unit in ((1 / 0.3048, "ft"), (1e-3, "km")):
        c = radar_first_lock_check(dataclasses.replace(ih, z=ih.z * factor), "rda_out.csv")
        assert c.status == "ERROR" and f"look like [{unit}], not [m]" in c.message, c.message


def test_a_numerical_failure_in_a_stage_is_named_not_a_traceback(run, monkeypatch):
    """Any remaining failure inside the stages (past the input checks) ends as a LinAlgError naming
    the stage after the last one completed; the runner makes it a NumericalFailure (exit 4)."""
    out, _ = run

    def boom(*a, **k):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(en, "preprocess", boom)
    sc = load_scenario(assets_dir() / "scenarios" / "schiaparelli.toml")
    tel = out / "schiaparelli" / "telemetry"
    paths = {k: tel / f"{k}.{'toml' if k == 'initial_state' else 'csv'}" for k in STREAMS}
    stages = en.reconstruct(EntryProblem().settings(sc), paths, members=100)
    next(stages)
    with pytest.raises(np.linalg.LinAlgError, match=r"stage after EntryTelemetry \(ZeroDivisionError: float division"):
        next(stages)


def test_radar_velocity_axis_swap_or_flip_is_named(full):
    """The radar's terrain-relative velocity against the inertial-only prediction: the descent
    axis (−Z_G, ~70 m/s) flipped or swapped with X is an ERROR naming the columns; clean is OK.
    (Horizontal components of a few m/s are below what the inertial prediction can tell.)"""
    from workbench.problems.entry.health import radar_velocity_axes_check

    res = full[1].result
    z, y = en.inertial_velocity_out(res.telemetry, res.imu, res.start)
    assert radar_velocity_axes_check(z, y).status == "OK"
    assert _checks(full[1].summary)["geometry.radar_velocity_axes"]["status"] == "OK"
    for M in (np.diag([1.0, 1.0, -1.0]), np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])):
        c = radar_velocity_axes_check(z @ M.T, y, "rda_out.csv")
        assert c.status == "ERROR" and "swapped or sign-flipped" in c.message and "rda_out.csv" in c.message


def test_plots_break_at_the_imu_blackouts_and_state_their_unit(rec, run):
    """The estimate is bridged across an IMU blackout in one step: its plots break there (a NaN row,
    no straight line through 57 s of no estimate); the strapdown altitude is in km, as its view says
    (it drew metres); the least-squares winds break where not valid instead of joining the ends."""
    for root in (layout.ENTRY_PLOT_ALTITUDE_AMR, layout.ENTRY_PLOT_TILT, layout.ENTRY_PLOT_STRAPDOWN_H_AMR):
        t, v = rec.scalars(layout.join(root, layout.VALUE))
        inside = (t > 40.0) & (t < 85.0)  # the long blackout
        assert inside.any() and np.isnan(v[inside]).all(), root
        assert np.isfinite(v[~inside]).mean() > 0.99, root
    _, h = rec.scalars(layout.join(layout.ENTRY_PLOT_STRAPDOWN_H_AMR, layout.VALUE))
    assert 0.0 < np.nanmax(h) < 200.0  # km
    t, w = rec.scalars(layout.join(layout.entry_wind_plot_path("north"), layout.VALUE))
    assert np.all(np.diff(t) < 1.0)  # no row left out across a gap: NaN there
