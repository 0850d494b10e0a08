"""post2 recording: a short 6-DOF entry with a parachute event, a weight schedule and the propagation-only
reference — what the recording holds (per-component state views with truth, residuals with ±3σ, the
applied weight factor, the phase index, the vehicle pose, the canopy from the opening event, the
scorecard's planted-vs-recovered table)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import load_scenario
from workbench.problems.base import RunOptions
from workbench.problems.runner import run_scenario
from workbench.recording import layout
from workbench.recording.reader import read_recording


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    sc = load_scenario(assets_dir() / "scenarios" / "post2_entry6dof.toml").with_overrides(
        {
            "model.t_end_s": 3.0,
            "events.chute": {"when": "time", "value": 1.5, "parachute": True},
            "schedules.early": {"observation": "rates", "weight_factor": 4.0, "end_event": "chute"},
            "filter.compare_propagation": True,
        }
    )
    out = tmp_path_factory.mktemp("post2_rec")
    # the rates weighted x4 for 1.5 s (a schedule to draw) understate their R: mean NIS 1.33 against the
    # shipped scenario's calibrated band 0.85-0.96, a health ERROR this drawing test writes through
    r = run_scenario(sc, out, RunOptions(allow_unhealthy=True))
    return r, read_recording(r.recording)


def test_states_residuals_schedule_and_phases_are_drawn(short_run):
    r, rec = short_run
    n = r.summary["grid_steps"]
    for c in ("x", "y", "z"):
        assert rec.row_count(f"/plots/position_error/{c}/value") == n
        assert rec.row_count(f"/plots/position_error/{c}/propagation_only") == n
    for c in ("alpha", "beta", "bank"):
        root = layout.plot_path(f"attitude/{c}")
        assert rec.row_count(f"{root}/value") == n and rec.row_count(f"{root}/truth") == n
        assert rec.row_count(f"{root}/plus_3sigma") == n
    t, v = rec.scalars("/plots/cm_multiplier/value/truth")
    assert np.allclose(v, 1.05)  # the planted truth beside the estimate
    for c in ("p", "q", "r"):
        assert rec.row_count(layout.join(layout.residual_path("rates", c), "value")) == 31
    t, f = rec.scalars(layout.plot_path("schedule/rates_weight_factor"))
    assert np.all(f[t < 1.5] == 4.0) and np.all(f[t > 1.5] == 1.0)  # the window closes at the event
    t, ph = rec.scalars(layout.POST2_PHASE)
    assert ph[0] == 0.0 and ph[-1] == 1.0
    assert any("chute" in text for _, text, _ in rec.text_log())


def test_vehicle_pose_and_parachute(short_run):
    r, rec = short_run
    t, tr, q = rec.transforms(layout.VEHICLE)
    assert t.size == r.summary["grid_steps"] and np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    assert layout.POST2_FOREBODY in rec.entities() and layout.POST2_PARACHUTE in rec.entities()
    assert rec.row_count(layout.POST2_PARACHUTE) == 1  # logged once, at the opening


def test_scorecard_has_planted_vs_recovered_and_propagation_only(short_run):
    r, rec = short_run
    md = rec.text_document()
    assert "| parameter | planted | recovered | ±3σ | error / 3σ | inside 3σ |" in md
    assert "| cm_multiplier | 1.05 |" in md
    assert "propagation only" in md
    s = json.loads(r.summary_path.read_text(encoding="utf-8"))
    e = s["truth"]["filtered_vs_propagation"]["position"]["end_error_norm"]
    assert set(e) == {"propagation_only", "forward", "smoothed"}


def test_key_moments_start_event_and_end(short_run):
    """The key moments of a post2 run: grid start and end and the event that fired, in time order,
    logged as bookmarks and the recording property (no peak acceleration: this problem file
    observes the total inertial acceleration, not a sensed one)."""
    from workbench.recording.moments import read_key_moments

    r, rec = short_run
    km = r.summary["key_moments"]
    t = {m["name"]: m["t_s"] for m in km}
    assert set(t) == {"start", "chute", "end"}
    assert [m["t_s"] for m in km] == sorted(t.values())
    assert t["start"] == r.result.t[0] and t["end"] == r.result.t[-1] and t["chute"] == 1.5
    assert [m.to_dict() for m in read_key_moments(rec)] == km
    assert len(rec.text_log(layout.KEY_MOMENTS)) == 3


def test_key_moments_peak_of_the_measured_sensed_acceleration():
    """The peak is the largest |z| over the sensed-acceleration observations only; an event fired
    twice is listed at its first time."""
    from types import SimpleNamespace

    from workbench.problems.post2.problem import key_moments

    def channel(quantity, t, z):
        return SimpleNamespace(spec=SimpleNamespace(quantity=quantity), t=np.asarray(t), z=np.asarray(z))

    result = SimpleNamespace(
        t=np.linspace(0.0, 10.0, 11),
        events=((4.0, "Main chute"), (6.0, "Main chute")),
        channels={
            "axial": channel("acceleration_axial", [1.0, 2.0, 3.0], [[-5.0], [-30.0], [-8.0]]),
            "total": channel("acceleration_inertial", [1.0, 5.0], [[0.0, 0.0, 99.0], [0.0, 0.0, 1.0]]),
            "magnitude": channel("acceleration_magnitude", [7.0, 8.0], [[12.0], [29.0]]),
        },
    )
    km = key_moments(result)
    assert [(m.name, m.t_s) for m in km] == [
        ("start", 0.0),
        ("main_chute", 4.0),
        ("peak_acceleration", 2.0),
        ("end", 10.0),
    ]
    assert "3.06 g₀ (30.0 m/s², axial measured)" in km[2].description


def _scene_views(bp):
    tabs = bp.root_container.contents[0].contents[0]  # left column: the 3D tabs above the event log
    return [v.name for v in tabs.contents]


def test_vehicle_view_only_when_a_vehicle_is_drawn():
    """A 3-DOF case without a vehicle diameter (post2_j2) draws nothing under /world/vehicle, so its
    layout has no "Vehicle" view (the browser test found that view empty in the web viewer)."""
    from workbench.problems.post2.recording import post2_blueprint

    assert _scene_views(post2_blueprint(["position"], ["gravity"], True, vehicle=False)) == ["Trajectory"]
    assert _scene_views(post2_blueprint(["position"], ["gravity"], True)) == ["Trajectory", "Vehicle"]


def test_the_drawn_quantities_come_from_the_result(short_run):
    """The recorder only draws: the phase index, the body attitude and the residual 1σ are the
    result's (issue 25)."""
    r, _ = short_run
    res = r.result
    idx = res.phase_index()
    assert idx.shape == res.t.shape and idx[0] == 0.0 and idx[-1] == float(len(res.events))
    rows = np.arange(0, res.t.size, 7)
    q = res.body_attitude(rows)
    assert q.shape == (rows.size, 4) and np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-9)
    assert res.tilt_rotation(rows) is None  # no tilt state in the 6-DOF entry
    from workbench.problems.post2.pipeline import ForwardStage

    fs = ForwardStage(res.forward, res.events, {})
    for name, ih in res.forward.innovations.items():
        np.testing.assert_array_equal(fs.residual_sigma(name)[:, 0], np.sqrt(np.maximum(ih.S[:, 0, 0], 0.0)))


def test_one_layout_with_the_trajectory_camera_on_the_track(short_run):
    """The recording carries exactly one layout, sent at the end, whose Trajectory view has a camera
    looking at the smoothed track's middle (the viewer's own fit left the track half off the pane)."""
    import rerun as rr

    from workbench.recording.moments import embedded_blueprint_chunks

    r, rec = short_run
    assert len(rr.chunk.RrdReader(r.recording).blueprints()) == 1
    cells = {}
    for c in embedded_blueprint_chunks(r.recording):
        cells.setdefault(c.entity_path, []).append(c.to_record_batch())
    eye = [b for e, bs in cells.items() if e.endswith("/EyeControls3D") for b in bs]
    assert len(eye) == 1
    target = np.asarray(eye[0].column("EyeControls3D:look_target").to_pylist()[0][0])
    _, p = rec.translations(layout.VEHICLE)
    mid = 0.5 * (p.min(axis=0) + p.max(axis=0))
    assert np.linalg.norm(target - mid) < 0.05 * np.linalg.norm(p.max(axis=0) - p.min(axis=0)) + 1.0


def test_trajectory_eye_frames_the_whole_track():
    """Every point of a planet-scale track lies within 20° of the camera's line of sight, the camera's
    up is the local vertical at the track, and degenerate tracks give no camera."""
    from workbench.problems.post2.recording import trajectory_eye

    s = np.linspace(0.0, 1.0, 200)
    r = 2.575e6 + 1.2e6 * (1.0 - s)  # descending 1200 km over 40° of longitude
    lon = np.radians(40.0) * s
    track = np.column_stack([r * np.cos(lon), r * np.sin(lon), 0.1 * r])
    eye = trajectory_eye(track)
    pos = np.asarray(eye.position.as_arrow_array().to_pylist()[0])
    tgt = np.asarray(eye.look_target.as_arrow_array().to_pylist()[0])
    up = np.asarray(eye.eye_up.as_arrow_array().to_pylist()[0])
    axis = (tgt - pos) / np.linalg.norm(tgt - pos)
    rays = (track - pos) / np.linalg.norm(track - pos, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip(rays @ axis, -1, 1))).max() < 20.0
    np.testing.assert_allclose(up, tgt / np.linalg.norm(tgt), atol=1e-6)
    assert trajectory_eye(track[:1]) is None and trajectory_eye(np.repeat(track[:1], 5, 0)) is None


def test_vehicle_view_has_the_local_horizon_and_the_velocity_arrow(short_run):
    """The horizon entity's rotation, composed with the vehicle's, puts its up axis along the local
    vertical r̂ and its east axis horizontal; one velocity arrow per vehicle pose; the Vehicle view's own
    grid (in the body frame) is off."""
    from workbench.core.rotation import quat_to_dcm
    from workbench.problems.post2.recording import post2_blueprint

    r, rec = short_run
    t, p, q_I_B = rec.transforms(layout.VEHICLE)
    th, tr, q_B_L = rec.transforms(layout.POST2_HORIZON)
    assert np.array_equal(t, th) and np.allclose(tr, 0.0)
    C_I_L = quat_to_dcm(q_I_B) @ quat_to_dcm(q_B_L)
    up = p / np.linalg.norm(p, axis=1, keepdims=True)
    assert np.allclose(C_I_L[:, :, 2], up, atol=1e-5)
    assert np.allclose(np.einsum("ni,ni->n", C_I_L[:, :, 0], up), 0.0, atol=1e-5)
    assert np.allclose(C_I_L[:, 2, 0], 0.0, atol=1e-5)  # east has no polar component
    assert rec.times(layout.POST2_VELOCITY_ARROW, "Arrows3D:vectors").size == t.size
    grid = rec.static_component(layout.join(layout.POST2_HORIZON, layout.GRID), "LineStrips3D:strips")
    assert len(grid) == 18 and len({round(pt[2], 9) for s in grid for pt in s}) == 1  # one plane below
    vehicle = post2_blueprint(["position"], ["gravity"], True).root_container.contents[0].contents[0].contents[1]
    assert vehicle.name == "Vehicle" and vehicle.properties["LineGrid3D"].visible.as_arrow_array().to_pylist() == [
        False
    ]


def test_local_level_in_body_is_the_east_north_up_frame():
    """q_B_L for random attitudes: C_I_B C_B_L has columns east (Ẑ × r̂), north, up (r̂)."""
    from scipy.spatial.transform import Rotation

    from workbench.core.rotation import quat_to_dcm
    from workbench.problems.post2.recording import horizon_grid, local_level_in_body

    rng = np.random.default_rng(3)
    p = rng.normal(size=(20, 3)) * 2.5e6
    q = Rotation.random(20, random_state=4).as_quat()
    C = quat_to_dcm(q) @ quat_to_dcm(local_level_in_body(p, q))
    up = p / np.linalg.norm(p, axis=1, keepdims=True)
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east, axis=1, keepdims=True)
    assert np.allclose(C[:, :, 2], up) and np.allclose(C[:, :, 0], east)
    assert np.allclose(C[:, :, 1], np.cross(up, east))
    lines = horizon_grid(10.0, 4.0, n=4)
    assert len(lines) == 10 and all(np.allclose(ln[:, 2], -4.0) for ln in lines)
