"""Round trips through workbench.recording: Recorder -> .rrd -> RecordingData, plus layout/blueprint."""

from __future__ import annotations

import numpy as np
import pytest
import rerun as rr
import trimesh
from scipy.spatial.transform import Rotation

from workbench.recording import layout
from workbench.recording.blueprint import save_blueprint, standard_blueprint
from workbench.recording.reader import RecordingError, read_recording, verify
from workbench.recording.writer import covariance_ellipsoids, open_recording, to_ns

F32 = dict(rtol=1e-6, atol=1e-6)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Write one recording exercising every Recorder method; return (path, inputs)."""
    rng = np.random.default_rng(7)
    n = 200
    t = np.arange(n) * 0.01
    step = np.arange(n)
    inp = {
        "t": t,
        "xyz": rng.normal(size=(n, 3)),
        "alt": 100.0 - 3.0 * t,
        "sig": 0.1 + 0.01 * t,
        "truth": 100.0 - 3.0 * t + rng.normal(0, 0.05, n),
        "meas": rng.normal(size=n),
        "pos": rng.normal(size=(n, 3)),
        "quat": Rotation.random(n, random_state=1).as_quat(),
        "centers": rng.normal(size=(n, 3)),
        "beams": rng.normal(size=(n, 4, 2, 3)),
        "beam_colors": rng.integers(0, 255, size=(n, 4, 4)),
        "ragged": [[rng.normal(size=(int(m), 3)) for m in rng.integers(2, 5, size=k)] for k in step % 3],
        "cloud": rng.normal(size=(n, 6, 3)),
        "ragged_pts": [rng.normal(size=(k % 4, 3)) for k in range(n)],
        "track": rng.normal(size=(30, 3)),
        "events": [(1.5, "max stroke", "WARN"), (0.0, "release", "INFO"), (0.73, "contact", "DEBUG")],
        "report": "# Scorecard\n\n| quantity | value |\n|---|---|\n| stroke | 0.31 m |\n",
    }
    a = rng.normal(size=(n, 3, 3))
    inp["cov"] = a @ np.swapaxes(a, 1, 2) * 0.01 + np.eye(3) * 1e-4
    bp = standard_blueprint(
        plots=[("altitude [m]", layout.plot_path("altitude"))],
        residuals=[("radar B0 [m]", layout.residual_path("radar", "B0"))],
        scene_exclude=[layout.TRUTH],
        time_window_s=5.0,
    )
    path = tmp_path_factory.mktemp("rec") / "recordings" / "run.rrd"
    with open_recording(
        path, "drop-test-42", blueprint=bp, properties={"solver": {"name": "EKF", "dt_s": 0.01}}
    ) as rec:
        rec.view_coordinates()
        rec.scalars("/plots/xyz", t, inp["xyz"], step=step, names=["x", "y", "z"], colors=(255, 0, 0), widths=1.0)
        rec.scalars(layout.sensor_path("imu", "ax_raw"), t, inp["meas"])
        rec.scatter(layout.sensor_path("imu", "ax"), t, inp["meas"], names="ax", colors=(214, 39, 40), marker="cross")
        rec.series_with_bounds(layout.plot_path("altitude"), t, inp["alt"], inp["sig"], truth=inp["truth"], step=step)
        rec.poses(layout.VEHICLE, t, inp["pos"], inp["quat"], step=step)
        rec.static_transform(layout.SURFACE, translation=[0, 0, -1], quaternion_xyzw=[0, 0, 0.7071068, 0.7071068])
        rec.axes(layout.VEHICLE, 0.5)
        inp["hs"], inp["q"] = rec.ellipsoids(layout.UNCERTAINTY, t, inp["centers"], inp["cov"], step=step)
        rec.line_strip(layout.ESTIMATE_SMOOTHED, inp["track"], color=(0, 128, 255), radius=0.01)
        rec.line_strip(layout.STROKE, inp["track"][:2], color=(255, 0, 0), radius=0.02, static=False, t=0.73)
        rec.line_strips_series(layout.RADAR, t, inp["beams"], colors=inp["beam_colors"], radii=0.005, step=step)
        rec.line_strips_series("/world/ragged", t, inp["ragged"], colors=(255, 128, 0))
        rec.points_series(layout.DISPERSION, t, inp["cloud"], colors=(0, 200, 0, 255), radii=0.02)
        rec.points_series("/world/ragged_pts", t, inp["ragged_pts"])
        rec.points("/world/landmarks", inp["track"][:5], colors=(1, 2, 3), radii=0.1)
        rec.mesh(layout.VEHICLE_BODY, trimesh.creation.box(extents=[0.4, 0.2, 0.1]), color=(80, 160, 255, 255))
        rec.text_labels_series("/world/labels", t, inp["pos"], ["vehicle"])
        rec.text_labels_series("/world/labels_blue", t, inp["pos"], ["3σ"], color=(31, 119, 180, 255))
        rec.ellipsoids("/world/wire", t, inp["centers"], inp["cov"], color=(31, 119, 180, 255), label="3σ", fill=False)
        rec.arrows_series("/world/arrow", t, inp["xyz"], color=(20, 90, 200, 255), radius=-2.0, label="velocity")
        rec.events(inp["events"])
        rec.report(inp["report"])
    return path, inp


def test_file_is_published_and_verifies(recorded):
    path, _ = recorded
    assert path.is_file()
    assert not list(path.parent.glob("*.partial"))
    ok, msg = verify(path)
    assert ok, msg


def test_metadata_and_structure(recorded):
    path, _ = recorded
    d = read_recording(path)
    assert d.application_id == layout.APPLICATION_ID
    assert d.recording_name == "drop-test-42"
    assert d.properties()["solver"] == {"name": "EKF", "dt_s": 0.01}
    assert d.timelines() == [layout.STEP, layout.TIME]
    assert {layout.VEHICLE, layout.UNCERTAINTY, layout.EVENTS, layout.REPORT, layout.WORLD} <= set(d.entities())
    assert d.row_count(layout.VEHICLE) == 200 and d.row_count(layout.VEHICLE, "step") == 200
    assert d.row_count(layout.VEHICLE_BODY) == 0
    assert "Mesh3D:vertex_positions" in d.components(layout.VEHICLE_BODY)
    assert d.time_range() == (0.0, 1.99)
    assert d.time_range("step") == (0, 199)
    s = d.summary()
    assert s["recording_name"] == "drop-test-42" and s["file_size_bytes"] == path.stat().st_size
    assert s["entities"]["/plots/xyz"]["rows"] == {"step": 200, "time": 200}
    assert s["timelines"]["time"] == {"type": "duration", "range": [0.0, 1.99]}


def test_scalars_round_trip(recorded):
    path, inp = recorded
    d = read_recording(path)
    t, v = d.scalars("/plots/xyz")
    np.testing.assert_allclose(t, inp["t"], rtol=0, atol=1e-12)  # stored as integer ns
    np.testing.assert_array_equal(v, inp["xyz"])  # Scalars are float64: exact
    _, v = d.scalars(layout.sensor_path("imu", "ax_raw"))
    np.testing.assert_array_equal(v[:, 0], inp["meas"])
    assert d.static_component("/plots/xyz", "SeriesLines:names") == ["x", "y", "z"]
    step, _ = d.scalars("/plots/xyz", timeline="step")
    np.testing.assert_array_equal(step, np.arange(200))
    assert d.static_component(layout.sensor_path("imu", "ax"), "SeriesPoints:markers") is not None


def test_series_with_bounds(recorded):
    path, inp = recorded
    d = read_recording(path)
    root = layout.plot_path("altitude")
    plus, minus = layout.bound_names(3.0)
    assert (plus, minus) == ("plus_3sigma", "minus_3sigma")
    _, v = d.scalars(f"{root}/value")
    _, hi = d.scalars(f"{root}/{plus}")
    _, lo = d.scalars(f"{root}/{minus}")
    _, tr = d.scalars(f"{root}/truth")
    np.testing.assert_allclose(v[:, 0], inp["alt"])
    np.testing.assert_allclose(hi[:, 0], inp["alt"] + 3 * inp["sig"])
    np.testing.assert_allclose(lo[:, 0], inp["alt"] - 3 * inp["sig"])
    np.testing.assert_allclose(tr[:, 0], inp["truth"])
    assert d.static_component(f"{root}/value", "SeriesLines:names") == ["altitude"]


def test_poses_round_trip(recorded):
    path, inp = recorded
    d = read_recording(path)
    t, p, q = d.transforms(layout.VEHICLE)
    np.testing.assert_allclose(t, inp["t"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(p, inp["pos"], **F32)
    np.testing.assert_allclose(q, inp["quat"], **F32)
    assert d.static_component(layout.SURFACE, "Transform3D:translation") == [[0.0, 0.0, -1.0]]


def test_ellipsoids_match_covariance(recorded):
    path, inp = recorded
    d = read_recording(path)
    t, c, hs, q = d.ellipsoids(layout.UNCERTAINTY)
    assert c.shape == hs.shape == (200, 1, 3) and q.shape == (200, 1, 4)
    np.testing.assert_allclose(c[:, 0], inp["centers"], **F32)
    np.testing.assert_allclose(hs[:, 0], inp["hs"], rtol=1e-6)
    w = np.linalg.eigvalsh(inp["cov"])
    np.testing.assert_allclose(inp["hs"], 3.0 * np.sqrt(w), rtol=1e-12)
    R = Rotation.from_quat(q[:, 0]).as_matrix()
    assert np.all(np.linalg.det(R) > 0)
    rebuilt = R @ (((hs[:, 0] / 3.0) ** 2)[:, :, None] * np.swapaxes(R, 1, 2))
    scale = np.abs(inp["cov"]).max(axis=(1, 2))[:, None, None]
    assert np.max(np.abs(rebuilt - inp["cov"]) / scale) < 1e-5  # float32 storage


def test_covariance_ellipsoids_vectorised_any_leading_shape():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(4, 5, 3, 3))
    cov = a @ np.swapaxes(a, -1, -2)
    cov[0, 0] = np.diag([4.0, 1.0, 9.0])  # eigh returns a det -1 basis for some inputs
    hs, q = covariance_ellipsoids(cov, nsigma=2.0)
    assert hs.shape == (4, 5, 3) and q.shape == (4, 5, 4)
    R = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(4, 5, 3, 3)
    rebuilt = R @ (((hs / 2.0) ** 2)[..., :, None] * np.swapaxes(R, -1, -2))
    np.testing.assert_allclose(rebuilt, cov, atol=1e-10)


def test_line_strips_round_trip(recorded):
    path, inp = recorded
    d = read_recording(path)
    t, rows = d.line_strips(layout.RADAR)
    assert len(rows) == 200 and all(len(r) == 4 for r in rows)
    np.testing.assert_allclose(np.array(rows), inp["beams"], **F32)
    colors = d._gather(layout.RADAR, "LineStrips3D:colors", "time")[1]
    assert len(colors) == 200  # per-step colours stored with the strips, not static
    _, rows = d.line_strips("/world/ragged")
    assert [len(r) for r in rows] == [len(r) for r in inp["ragged"]]
    for got, want in zip(rows, inp["ragged"], strict=True):
        for g, w in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w, **F32)
    t, rows = d.line_strips(layout.STROKE)
    assert t.tolist() == [0.73] and len(rows[0]) == 1
    np.testing.assert_allclose(rows[0][0], inp["track"][:2], **F32)
    static = d.static_component(layout.ESTIMATE_SMOOTHED, "LineStrips3D:strips")
    np.testing.assert_allclose(np.array(static[0]), inp["track"], **F32)


def test_points_round_trip(recorded):
    path, inp = recorded
    d = read_recording(path)
    _, rows = d.points(layout.DISPERSION)
    np.testing.assert_allclose(np.array(rows), inp["cloud"], **F32)
    _, rows = d.points("/world/ragged_pts")
    assert [len(r) for r in rows] == [len(r) for r in inp["ragged_pts"]]
    for g, w in zip(rows, inp["ragged_pts"], strict=True):
        np.testing.assert_allclose(g, w, **F32)
    assert len(d.static_component("/world/landmarks", "Points3D:positions")) == 5
    assert d.static_component("/world/labels", "Points3D:labels") == ["vehicle"]


def test_mesh_events_report(recorded):
    path, inp = recorded
    d = read_recording(path)
    box = trimesh.creation.box(extents=[0.4, 0.2, 0.1])
    verts = np.array(d.static_component(layout.VEHICLE_BODY, "Mesh3D:vertex_positions"))
    np.testing.assert_allclose(verts, box.vertices, **F32)
    assert len(d.static_component(layout.VEHICLE_BODY, "Mesh3D:vertex_normals")) == len(box.vertices)
    assert d.text_log() == sorted(inp["events"])
    assert d.text_document() == inp["report"]
    assert d.static_component(layout.WORLD, "ViewCoordinates:xyz") is not None


def test_time_rounding_on_ns_grid(tmp_path):
    k = np.arange(5000)
    t = k * 0.01
    raw_truncated = rr.TimeColumn("time", duration=t).as_arrow_array().cast("int64").to_numpy()
    assert np.any(raw_truncated != k * 10_000_000)  # the truncation exists in this SDK
    assert np.array_equal(to_ns(t).astype(np.int64), k * 10_000_000)
    path = tmp_path / "grid.rrd"
    with open_recording(path, "grid") as rec:
        rec.scalars("/plots/s", t, np.sin(t))
    d = read_recording(path)
    raw = d.times("/plots/s", "Scalars:scalars", raw=True)
    np.testing.assert_array_equal(raw, k * 10_000_000)
    np.testing.assert_array_equal(d.scalars("/plots/s")[0], (k * 10_000_000) / 1e9)


def test_unsorted_times_are_sorted_on_read(tmp_path):
    path = tmp_path / "unsorted.rrd"
    t = np.array([0.3, 0.1, 0.2])
    with open_recording(path, "u") as rec:
        rec.scalars("/plots/s", t, [3.0, 1.0, 2.0])
    t_read, v = read_recording(path).scalars("/plots/s")
    np.testing.assert_array_equal(t_read, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(v[:, 0], [1.0, 2.0, 3.0])


def test_strict_mode_length_mismatch_raises_and_is_restored(tmp_path):
    before = rr.strict_mode()
    path = tmp_path / "strict.rrd"
    with pytest.raises(ValueError, match="same length"):
        with open_recording(path, "strict") as rec:
            assert rr.strict_mode()
            rec.stream.send_columns(
                "/plots/bad",
                indexes=[rr.TimeColumn("time", duration=to_ns([0.0, 1.0, 2.0]))],
                columns=rr.Scalars.columns(scalars=[1.0, 2.0]),
            )
    assert rr.strict_mode() == before
    assert not path.exists()
    assert not list(tmp_path.glob("*.partial"))


def test_recorder_validates_shapes(tmp_path):
    with pytest.raises(ValueError):
        with open_recording(tmp_path / "v.rrd", "v") as rec:
            rec.poses(layout.VEHICLE, [0.0, 1.0], np.zeros((3, 3)), np.zeros((3, 4)))
    with pytest.raises(ValueError):
        with open_recording(tmp_path / "v.rrd", "v") as rec:
            rec.scalars("/plots/a", [0.0, 1.0], [1.0, 2.0], step=[0.5, 1.5])
    with pytest.raises(ValueError):
        with open_recording(tmp_path / "v.rrd", "v") as rec:
            rec.events([(0.0, "x", "LOUD")])
    assert not list(tmp_path.iterdir())


def test_reader_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_recording(tmp_path / "missing.rrd")
    partial = tmp_path / "x.rrd.123.partial"
    partial.write_bytes(b"whatever")
    with pytest.raises(RecordingError, match="partial"):
        read_recording(partial)
    garbage = tmp_path / "garbage.rrd"
    garbage.write_bytes(b"hello")
    with pytest.raises(RecordingError):
        read_recording(garbage)
    nofooter = tmp_path / "nofooter.rrd"
    rec = rr.RecordingStream(layout.APPLICATION_ID, recording_id="00000000-0000-0000-0000-000000000001")
    rec.save(str(nofooter), write_footer=False)  # what a writer that never finished leaves behind
    rec.disconnect()
    with pytest.raises(RecordingError, match="footer"):
        read_recording(nofooter)
    ok, _ = verify(garbage)
    assert not ok


def test_layout_paths():
    assert layout.plot_path("velocity/north") == "/plots/velocity/north"
    assert layout.residual_path("radar", "B0") == "/residuals/radar/B0"
    assert layout.sensor_path("imu", "ax") == "/sensors/imu/ax"
    assert layout.radar_beam_path(2) == "/world/vehicle/radar/B2"
    assert layout.bound_names(2.5) == ("plus_2.5sigma", "minus_2.5sigma")
    with pytest.raises(ValueError):
        layout.plot_path("bad name")


def test_blueprint_saves_and_verifies(tmp_path):
    bp = standard_blueprint(
        plots=[("alt [m]", layout.plot_path("alt")), ("vel [m/s]", layout.plot_path("vel"))],
        extra_views=[rr.blueprint.TimeSeriesView(name="dispersion", origin="/plots/dispersion")],
    )
    p = save_blueprint(bp, tmp_path / "layouts" / "std.rbl")
    ok, msg = verify(p)
    assert ok, msg
    with pytest.raises(ValueError):
        standard_blueprint(time_window_s=0.0)


def test_series_with_bounds_breaks_at_gaps_and_draws_the_truth_through(tmp_path):
    """``gap_s``: a NaN row (a break in the viewer's line) at the middle of every longer time step in
    the estimate and its bounds, the truth drawn through; ``truth_style`` colours and widths the truth."""
    path = tmp_path / "gaps.rrd"
    t = np.array([0.0, 0.1, 0.2, 5.0, 5.1])
    v = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    truth = 10.0 * v
    with open_recording(path, "gaps") as rec:
        rec.series_with_bounds(
            "/plots/g", t, v, np.full(5, 0.5), truth=truth, gap_s=1.0, truth_style=((0, 200, 0, 100), 4.0)
        )
    d = read_recording(path)
    tv, vv = d.scalars("/plots/g/value")
    _, hi = d.scalars("/plots/g/plus_3sigma")
    _, tr = d.scalars("/plots/g/truth")
    np.testing.assert_allclose(tv, [0.0, 0.1, 0.2, 2.6, 5.0, 5.1])
    assert np.isnan(vv[3, 0]) and np.isnan(hi[3, 0]) and np.isfinite(np.delete(vv[:, 0], 3)).all()
    np.testing.assert_allclose(tr[:, 0], [10.0, 20.0, 30.0, 35.0, 40.0, 50.0])
    assert d.static_component("/plots/g/truth", "SeriesLines:widths") == [4.0]


def test_arrows_series_one_arrow_per_step_with_static_style(recorded, tmp_path):
    path, inp = recorded
    d = read_recording(path)
    assert np.allclose(d.times("/world/arrow", "Arrows3D:vectors"), inp["t"])
    assert d.static_component("/world/arrow", "Arrows3D:labels") == ["velocity"]
    assert d.static_component("/world/arrow", "Arrows3D:radii") == [-2.0]
    with open_recording(tmp_path / "bad.rrd", "bad") as rec, pytest.raises(ValueError, match="vectors"):
        rec.arrows_series("/world/arrow", [0.0, 1.0], np.zeros((3, 3)))


def test_ellipsoid_label_wireframe_and_label_colour(recorded):
    """An ellipsoid can carry its σ level as a label and be drawn as a wireframe only; a text label
    can have its own colour (else the viewer's)."""
    path, _ = recorded
    d = read_recording(path)
    assert d.static_component("/world/wire", "Ellipsoids3D:labels") == ["3σ"]
    assert d.static_component("/world/wire", "Ellipsoids3D:show_labels") == [True]
    wire, filled = (d.static_component(e, "Ellipsoids3D:fill_mode") for e in ("/world/wire", layout.UNCERTAINTY))
    assert wire != filled
    with pytest.raises(KeyError):
        d.static_component(layout.UNCERTAINTY, "Ellipsoids3D:labels")
    assert d.static_component("/world/labels_blue", "Points3D:colors") is not None
    with pytest.raises(KeyError):
        d.static_component("/world/labels", "Points3D:colors")


def test_value_range_of_a_plot_origin(tmp_path):
    """The recorder keeps what it drew against time per entity (per time bin): a layout sent after
    the run sets a plot's y range from it, over a time window when given."""
    t = np.arange(1000) * 0.5
    noisy = np.where(t < 100.0, 60.0 * np.sin(t), 20.0 + np.sin(t))
    with open_recording(tmp_path / "r.rrd", "ranges") as rec:
        rec.series_with_bounds(layout.plot_path("alt"), t[:4], [1.0, 2.0, np.nan, 3.0], [0.1, 0.1, 0.1, 0.1])
        rec.scatter(layout.plot_path("alt/meas"), t[:4], [0.5, 9.0, 1.0, 2.0], names="z", colors=(0, 0, 0))
        rec.scalars(layout.plot_path("alt_b"), t[:4], [-50.0, 0.0, 0.0, 0.0])
        rec.scalars(layout.plot_path("seq"), None, [7.0, 8.0], sequences={layout.SAMPLE: np.arange(2)})
        rec.scalars(layout.plot_path("alpha"), t, noisy)
        assert rec.value_range(layout.plot_path("alt")) == (0.5, 9.0)
        assert rec.value_range(layout.plot_path("alt") + "/") == (0.5, 9.0)
        assert rec.value_range(layout.plot_path("alt/value")) == (1.0, 3.0)
        assert rec.value_range(layout.plot_path("alt_b")) == (-50.0, 0.0)
        assert rec.value_range(layout.plot_path("seq")) is None
        assert rec.value_range("/plots/nothing") is None
        lo, hi = rec.value_range(layout.plot_path("alpha"))
        assert lo < -59.0 and hi > 59.0
        # the window leaves the noise out, to a bin (2 s here) of the edge
        lo, hi = rec.value_range(layout.plot_path("alpha"), 102.0, 499.5)
        assert 19.0 <= lo < 19.1 and 20.9 < hi <= 21.0
        assert rec.value_range(layout.plot_path("alpha"), 600.0, 700.0) is None
