"""The drop-test run end to end through the CLI path, read back from the ``.rrd``.

What the recording must hold (docs/RECORDING.md) and that the numbers in it are the
numbers of the reconstruction: the pose per filter step, the stroke series and its bounds, the
3σ ellipsoids, the events and the scorecard; the summary JSON's truth scoring for the three
synthetic scenarios; the ``inspect`` and ``run`` commands; and that user telemetry goes through
the same code path as a synthetic scenario.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.io.assets import assets_dir
from workbench.problems.droptest import model as rl
from workbench.problems.runner import run_scenario
from workbench.recording import layout
from workbench.recording.reader import read_recording, verify

TRIADS = ("BP", "PYBP", "PXBP", "MXBP")


@pytest.fixture(scope="module")
def rec(droptest_run):
    return read_recording(droptest_run.rrd)


def _summary_json(run) -> dict:
    return json.loads(run.summary_json.read_text(encoding="utf-8"))


# ------------------------------------------------------------------------------ file


def test_recording_verifies_and_no_partial_left(droptest_run):
    ok, out = verify(droptest_run.rrd)
    assert ok, out
    assert not list(droptest_run.out.rglob("*.partial"))
    assert droptest_run.summary["recording_bytes"] == droptest_run.rrd.stat().st_size


def test_recording_identity(rec):
    assert rec.application_id == layout.APPLICATION_ID
    assert rec.recording_name == "droptest"
    assert set(rec.timelines()) >= {layout.TIME, layout.STEP}


def test_required_entities_present(rec):
    required = [
        layout.SURFACE,
        layout.VEHICLE,
        layout.VEHICLE_BODY,
        layout.AIRBAGS,
        layout.UNCERTAINTY,
        layout.ESTIMATE_FORWARD,
        layout.ESTIMATE_SMOOTHED,
        f"{layout.TRUTH}/vehicle",
        layout.STROKE,
        "/world/roll_line",
        "/sensors/BP",
        layout.EVENTS,
        layout.REPORT,
    ]
    required += [f"/plots/stroke/{s}" for s in ("value", "plus_1sigma", "minus_1sigma")]
    required += [f"/plots/stroke/{s}" for s in ("plus_3sigma", "minus_3sigma", "truth")]
    for sensor in (*TRIADS, "gyro"):
        for axis in "xyz":
            required += [f"/residuals/{sensor}/{axis}/{s}" for s in ("value", "plus_3sigma", "minus_3sigma")]
    have = set(rec.entities())
    missing = [e for e in required if e not in have]
    assert not missing, f"missing entities: {missing}"
    assert "Transform3D:translation" in rec.components(layout.VEHICLE)
    assert "Transform3D:quaternion" in rec.components(layout.VEHICLE)


def test_max_stroke_drawn_in_front_of_the_airbags_in_cm(rec, droptest_run):
    """The max-stroke segment hid inside the lobes: its copy (the dimension line) is as long and as
    oriented as the segment, moved along the Impact camera's view beyond the lobes, with extension
    lines to the real ends and a label in cm; it is drawn in screen points (thick at any zoom)."""
    ms = droptest_run.summary["max_stroke"]
    (seg,) = rec.static_component(layout.DROPTEST_MAX_STROKE_SEGMENT, "LineStrips3D:strips")
    dim, ext_a, ext_b = (
        np.asarray(s, float) for s in rec.static_component(layout.DROPTEST_MAX_STROKE_DIMENSION, "LineStrips3D:strips")
    )
    seg = np.asarray(seg, float)
    np.testing.assert_allclose(dim[1] - dim[0], seg[1] - seg[0], atol=1e-5)
    assert np.linalg.norm(seg[1] - seg[0]) == pytest.approx(ms["distance_m"], abs=1e-5)
    np.testing.assert_allclose([ext_a[0], ext_b[0]], seg, atol=1e-6)
    np.testing.assert_allclose([ext_a[1], ext_b[1]], dim, atol=1e-6)
    assert np.linalg.norm(dim[0] - seg[0]) > 1.0  # outside lobes of 2 m
    radii = np.asarray(rec.static_component(layout.DROPTEST_MAX_STROKE_DIMENSION, "LineStrips3D:radii"))
    assert np.all(radii < 0.0) and radii[0] < radii[1]  # screen points, the bar thicker than its extensions
    (label,) = rec.static_component(layout.DROPTEST_MAX_STROKE_DIMENSION_LABEL, "Points3D:labels")
    assert label == f"max stroke {100 * ms['distance_m']:.1f} ± {100 * ms['sigma_m']:.1f} cm (1σ)"


# ------------------------------------------------------------------------------ numbers


def test_pose_one_row_per_filter_step(rec, droptest_run, droptest_result):
    n = droptest_run.summary["steps"]
    assert rec.row_count(layout.VEHICLE, layout.TIME) == n
    assert rec.row_count(layout.VEHICLE, layout.STEP) == n
    t, p, _ = rec.transforms(layout.VEHICLE, layout.TIME)
    steps, _, _ = rec.transforms(layout.VEHICLE, layout.STEP)
    np.testing.assert_array_equal(steps, np.arange(n))
    assert np.unique(t).size == n  # no step logged twice, none merged
    smo = droptest_result.smoothed
    np.testing.assert_allclose(t, smo.t, rtol=0, atol=1e-9)  # stored as integer ns
    np.testing.assert_allclose(p, smo.x[:, rl.SP], rtol=0, atol=1e-5)  # float32 of metre-scale positions


def test_stroke_minimum_is_the_max_stroke_of_the_summary(rec, droptest_run):
    ms = droptest_run.summary["max_stroke"]
    t, v = rec.scalars("/plots/stroke/value")
    after = t >= droptest_run.summary["events"]["release"]
    k = int(np.argmin(v[after, 0]))
    # Scalars are float64 in Rerun, so this is tighter than float32 precision
    assert v[after, 0][k] == pytest.approx(ms["distance_m"], rel=1e-12)
    assert abs(t[after][k] - ms["time_s"]) <= 1e-9  # ns time stamps


def test_stroke_bounds_consistent(rec):
    _, v = rec.scalars("/plots/stroke/value")
    _, p1 = rec.scalars("/plots/stroke/plus_1sigma")
    _, m1 = rec.scalars("/plots/stroke/minus_1sigma")
    _, p3 = rec.scalars("/plots/stroke/plus_3sigma")
    _, m3 = rec.scalars("/plots/stroke/minus_3sigma")
    assert np.all(p1 - v > 0.0)  # a zero σ would make the checks below vacuous
    np.testing.assert_allclose(v - m1, p1 - v, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(p3 - v, 3.0 * (p1 - v), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(v - m3, 3.0 * (p1 - v), rtol=1e-9, atol=1e-12)


def test_ellipsoids_are_3sigma_of_the_smoothed_position_covariance(rec, droptest_result):
    steps, centers, half, _ = rec.ellipsoids(layout.UNCERTAINTY, layout.STEP)
    P = droptest_result.smoothed.P[:, rl.EP, rl.EP]
    assert steps.size == P.shape[0]
    np.testing.assert_array_equal(centers, 0.0)  # body-frame ellipsoid centred on the vehicle
    expected = 3.0 * np.sqrt(np.linalg.eigvalsh(P))  # ascending, every step
    logged = np.sort(half[:, 0, :], axis=1)
    # the re-run is bit-identical; the only difference is the float32 storage (≤ ½ ulp)
    np.testing.assert_allclose(logged, expected, rtol=float(np.finfo(np.float32).eps))


def test_nis_series_have_one_colour_each(rec):
    """The NIS view names its series in a legend: each sensor its own colour (the viewer's choice by
    entity path gave gyro, PXBP and PYBP one magenta), the χ² bound grey."""
    nis = [e for e in rec.entities() if e.startswith(layout.DROPTEST_PLOT_NIS + "/") and "chi2" not in e]
    assert {layout.droptest_nis_path(n) for n in (*TRIADS, "gyro")} <= set(nis)
    colours = [tuple(rec.static_component(e, "SeriesLines:colors")) for e in nis]
    assert len(set(colours)) == len(nis)


def test_events_and_report(rec, droptest_run):
    ms = droptest_run.summary["max_stroke"]
    log = rec.text_log(layout.EVENTS)
    texts = [x for _, x, _ in log]
    assert any(x.startswith("release") for x in texts)
    hits = [(t, x) for t, x, _ in log if x.startswith("max stroke")]
    assert len(hits) == 1
    assert abs(hits[0][0] - ms["time_s"]) <= 1e-9
    assert f"{ms['distance_m']:.3f} m" in hits[0][1]
    contact = droptest_run.summary["contact"]
    # the contact's start and the rebound are key moments only (★ rows): no second, earlier "rebound"
    km = {m["name"]: m["t_s"] for m in droptest_run.summary["key_moments"]}
    assert abs(km["first_contact"] - contact["start_s"]) <= 1e-9
    assert not [x for x in texts if x.startswith("rebound") or "contact begins" in x]
    # the instant the restitution's leaving velocity is read: after the max stroke, one event
    rest = droptest_run.summary["restitution"]
    leaves = [(t, x) for t, x, _ in log if x.startswith("the lander leaves the ramp")]
    assert len(leaves) == 1 and abs(leaves[0][0] - rest["times_s"][1]) <= 1e-9
    assert rest["times_s"][0] < km["max_stroke"] < rest["times_s"][1]
    assert f"e = {rest['e']:.3f}" in leaves[0][1]
    report = rec.text_document(layout.REPORT)
    assert "max stroke" in report
    assert f"{ms['distance_m']:.3f} m ± {ms['sigma_m']:.3f} m" in report
    assert "Against truth" in report


def test_key_moments_in_summary_recording_and_open(rec, droptest_run, tmp_path, capsys):
    """The drop's key moments, from the reconstruction: in time order in the summary, each one a
    bookmark at its time and in the recording property; ``open --at max_stroke --dry-run`` writes
    the layout with the impact window selected and the Chamber view following the lander."""
    from workbench.recording.moments import bookmark_text, read_key_moments

    s = _summary_json(droptest_run)
    km = s["key_moments"]
    names = [m["name"] for m in km]
    assert names == ["release", "bungee_cut", "first_contact", "max_stroke", "rebound"]
    t = {m["name"]: m["t_s"] for m in km}
    assert list(t.values()) == sorted(t.values())
    assert t["release"] == s["events"]["release"] and t["bungee_cut"] == s["events"]["bungee_cut"]
    assert t["first_contact"] == s["contact"]["start_s"] and t["max_stroke"] == s["max_stroke"]["time_s"]
    stroke_t, stroke = rec.scalars(layout.join(layout.DROPTEST_PLOT_STROKE, layout.VALUE))
    k0, k_up = np.searchsorted(stroke_t, [t["first_contact"], t["rebound"]])
    assert stroke[k_up, 0] >= stroke[k0, 0] > stroke[k_up - 1, 0]  # back at its first-contact value
    ms = next(m for m in km if m["name"] == "max_stroke")
    assert f"{s['max_stroke']['distance_m']:.3f} ± {s['max_stroke']['sigma_m']:.3f} m" in ms["description"]
    lo, hi = ms["window_s"]
    assert lo < t["first_contact"] and hi > t["rebound"]
    moments = read_key_moments(rec)
    assert [m.to_dict() for m in moments] == km
    rows = rec.text_log(layout.KEY_MOMENTS)
    assert [(x, lvl) for _, x, lvl in rows] == [(bookmark_text(m), "INFO") for m in moments]
    assert np.allclose([r[0] for r in rows], [m.t_s for m in moments], rtol=0, atol=1e-9)  # on the ns grid
    rbl = tmp_path / "max_stroke.rbl"
    assert main(["open", str(droptest_run.rrd), "--at", "max_stroke", "--dry-run", "--rbl", str(rbl)]) == 0
    out = capsys.readouterr().out
    assert f"time selection {lo:.3f} .. {hi:.3f} s" in out
    assert re.search(r"3D views? [^;]*'Chamber'[^;]* follows? /world/vehicle", out), out
    assert rbl.is_file() and rbl.stat().st_size > 0


# ------------------------------------------------------------------------------ scoring vs truth


def test_droptest_truth_scoring(droptest_run):
    s = _summary_json(droptest_run)
    tr = s["truth"]
    ms = s["max_stroke"]
    # one seed: a smoke check; the statistical claim (coverage over seeds) is the benchmark's
    assert abs(tr["max_stroke_error_m"]) <= 3.0 * ms["sigma_m"]
    assert tr["max_stroke_inside_3sigma"] is True
    assert abs(s["restitution"]["e"] - tr["restitution_truth"]) < 0.05
    assert tr["full_stroke_truth"] is False and ms["full_stroke"] is False


def test_ranging_truth_scoring(cli_run):
    s = _summary_json(cli_run("droptest_ranging"))
    assert abs(s["truth"]["max_stroke_error_m"]) < 0.10
    assert "odometer" in s["innovations"]
    assert {"G1.range", "G2.range", "G3.range"} <= set(s["innovations"])


def test_fullstroke_truth_scoring(cli_run):
    s = _summary_json(cli_run("droptest_fullstroke"))
    ms = s["max_stroke"]
    assert ms["full_stroke"] or ms["possible_full_stroke"]
    assert s["truth"]["full_stroke_truth"] is True


# ------------------------------------------------------------------------------ commands


def test_inspect_prints_the_scorecard_before_a_short_entity_listing(droptest_run, rec, capsys):
    from workbench.cli import INSPECT_ENTITY_ROWS

    code = main(["inspect", str(droptest_run.rrd)])
    out = capsys.readouterr().out
    assert code == 0
    n_ent = len(rec.entities())
    assert n_ent > INSPECT_ENTITY_ROWS
    assert out.index("scorecard") < out.index(f"{n_ent} entities")
    listed = [ln for ln in out.splitlines() if ln.startswith("  /")]
    assert len(listed) == INSPECT_ENTITY_ROWS
    assert f"... {n_ent - INSPECT_ENTITY_ROWS} more (list them all with --entities)" in out


def test_inspect_entities_prints_entities_and_scorecard(droptest_run, rec, capsys):
    code = main(["inspect", str(droptest_run.rrd), "--entities"])
    out = capsys.readouterr().out
    assert code == 0
    n = droptest_run.summary["steps"]
    assert f"{len(rec.entities())} entities (rows per timeline: step, time):" in out
    for e in (layout.VEHICLE, layout.UNCERTAINTY, "/plots/stroke/value", layout.REPORT):
        assert e in out
    vehicle_line = next(ln for ln in out.splitlines() if ln.split()[:1] == [layout.VEHICLE])
    assert vehicle_line.split()[1:] == [str(n), str(n)]  # one pose row per step on both timelines
    assert "scorecard" in out and "max stroke" in out


def test_run_unknown_scenario_exit_code_and_names(tmp_path, capsys):
    code = main(["run", "no_such_scenario", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 3
    assert "no_such_scenario" in err
    for name in ("droptest", "droptest_ranging", "droptest_fullstroke"):
        assert name in err
    assert not list(tmp_path.iterdir())  # nothing written for a rejected scenario


# ------------------------------------------------------------------------------ same code path


def test_user_telemetry_same_code_path(droptest_run, tmp_path):
    """The synthetic run's files as user telemetry: the reconstruction never used the truth."""
    tel = tmp_path / "mydrop" / "telemetry"
    tel.mkdir(parents=True)
    for f in ("imu.csv", "3dm.csv", "events.csv", "setup.toml"):
        shutil.copy(droptest_run.telemetry_dir / f, tel / f)
    text = (assets_dir() / "scenarios" / "droptest.toml").read_text(encoding="utf-8")
    assert text.count("[synthetic]") == 1
    text = text.split("[synthetic]")[0]  # [synthetic] is the last table of droptest.toml
    lander = (assets_dir() / "landers" / "mer_drop_lander.toml").resolve()
    text = text.replace('lander = "../landers/mer_drop_lander.toml"', f'lander = "{lander.as_posix()}"')
    text = text.replace('name = "droptest"', 'name = "mydrop"')
    text += (
        "\n[telemetry]\n"
        'imu = "telemetry/imu.csv"\n'
        'attitude_3dm = "telemetry/3dm.csv"\n'
        'events = "telemetry/events.csv"\n'
        'setup = "telemetry/setup.toml"\n'
    )
    toml = tmp_path / "mydrop" / "mydrop.toml"
    toml.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    s = run_scenario(str(toml), out).summary
    assert s["scenario"] == "mydrop"
    assert "truth" not in s
    assert not (out / "mydrop").exists()  # no synthetic telemetry written for a user scenario
    assert Path(s["recording"]).is_file()
    ref = droptest_run.summary["max_stroke"]
    assert abs(s["max_stroke"]["distance_m"] - ref["distance_m"]) <= 1e-9
    assert s["max_stroke"]["time_s"] == ref["time_s"]
    assert s["max_stroke"]["sigma_m"] == pytest.approx(ref["sigma_m"], rel=1e-12)


def test_monte_carlo_command_writes_a_recording(tmp_path, capsys):
    """`workbench mc` runs the members, writes the summary JSON and one row per member on `sample`."""
    from workbench.recording.reader import read_recording, verify

    code = main(["mc", "droptest", "--seeds", "2", "--out", str(tmp_path)])
    assert code == 0
    data = read_recording(tmp_path / "droptest_mc.rrd")
    assert verify(tmp_path / "droptest_mc.rrd")[0]
    assert data.timelines() == ["sample"]
    assert data.row_count("/plots/mc/stroke/error", "sample") == 2
    t, err = data.scalars("/plots/mc/stroke/error", timeline="sample")
    _, plus = data.scalars("/plots/mc/stroke/plus_3sigma", timeline="sample")
    summary = json.loads((tmp_path / "droptest.mc.json").read_text())
    assert summary["n_runs"] == 2
    # the logged ±3σ band is the reported 3σ of each member (median matches the summary)
    assert np.isclose(np.median(plus), summary["median_3sigma_m"])
    assert np.all(np.isfinite(err)) and list(t) == [1, 2]
    assert "Monte Carlo" in data.text_document("/report")
    # progress (plain: stderr is not a terminal): the members counted as the pool's futures complete
    # (default: 2 local workers), and the paths written
    err = capsys.readouterr().err.splitlines()
    assert any(ln.startswith("[droptest] Monte Carlo members: 2/2 members in ") for ln in err), err
    assert f"[droptest] wrote {tmp_path / 'droptest.mc.json'}" in err
    assert any(str(tmp_path / "droptest_mc.rrd") in ln for ln in err)
