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
from workbench.problems.entry.telemetry import STREAMS, read_nominal_state
from workbench.problems.runner import run_scenario
from workbench.recording import layout
from workbench.recording.reader import read_recording, verify

MEMBERS = 2000


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("entry")
    summary = run_scenario("schiaparelli", out, RunOptions(members=MEMBERS)).summary
    return out, summary


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


def test_accuracy_against_truth_meets_the_issue_bounds(run):
    _, s = run
    tr = s["truth"]
    fix = tr["after_radar_fix"]
    assert fix["max_h_agl_error_m"] < 50.0
    assert fix["inside_3sigma_fraction"] == 1.0
    assert s["radar_residuals"]["slant_out"]["max_abs"] < 150.0  # AMELIA Sect. 8 bound
    assert s["radar_residuals"]["velocity_out"]["max_abs"] < 20.0
    atm = tr["atmosphere"]
    assert atm["entry_measured"]["max_abs_rel_error"] < 0.10
    assert atm["under_parachute"]["max_abs_rel_error"] < 0.25
    assert s["atmosphere"]["converged"] and s["atmosphere"]["iterations"] <= 5
    assert tr["winds_in_layers"]["max_error_mps"] < 5.0
    assert s["covariance"]["symmetric"] and s["covariance"]["positive_definite"]
    # the smoother's initial state holds the truth inside its covariance (99.9 % χ², 9 dof)
    assert tr["initial_smoother_start"]["nees_9dof"] < chi2.ppf(0.999, 9)


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


@pytest.mark.xfail(
    strict=True,
    reason="measured 25.5 %: the truth's warm layer near 42 km lies inside the 57 s blackout, where no "
    "measurement sees it; the hydrostatic fill (default-model temperature shape) cannot know it",
)
def test_filled_blackout_density_within_20_percent(run):
    _, s = run
    assert s["truth"]["atmosphere"]["entry_filled_blackout"]["max_abs_rel_error"] < 0.20


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
        en.check_config(base.with_overrides({key: value}))


def test_initial_state_at_the_wrong_time_is_rejected(run, tmp_path):
    out, _ = run
    tel = tmp_path / "tel"
    shutil.copytree(out / "schiaparelli" / "telemetry", tel)
    f = tel / "initial_state.toml"
    f.write_text(f.read_text().replace("t0_s = -15.000000", "t0_s = 5.0"))
    paths = {k: tel / f"{k}.{'toml' if k == 'initial_state' else 'csv'}" for k in STREAMS}
    sc = load_scenario(assets_dir() / "scenarios" / "schiaparelli.toml")
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
    sc = load_scenario(assets_dir() / "scenarios" / "schiaparelli.toml")
    with pytest.raises(ScenarioError, match="PDD"):
        for _ in en.reconstruct(sc, paths, members=200):
            pass
