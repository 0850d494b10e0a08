"""Key moments: the record and its checks (``io.moments``), their bookmarks and property in a
recording, the per-moment layout (``recording.moments``), and ``workbench open`` (``--list``,
``--at NAME --dry-run``, an unknown name) on a run of the worked example problem."""

from __future__ import annotations

import json
import math
import shlex
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
import rerun.blueprint as rrb
from example_problem import registered_fallingbody  # tests/support, on sys.path via tests/conftest.py

from workbench.cli import EXIT_OK, EXIT_USAGE, main
from workbench.io.moments import KeyMoment, MomentError, default_window, moments_from_dicts, ordered, slug
from workbench.recording import layout
from workbench.recording.moments import (
    KEY_MOMENTS_PROPERTY,
    UnknownMomentError,
    bookmark_text,
    find_moment,
    log_key_moments,
    read_key_moments,
    viewer_command,
    write_moment_blueprint,
)
from workbench.recording.reader import read_recording
from workbench.recording.writer import open_recording

EXAMPLE = Path(__file__).resolve().parents[1] / "problems" / "example_fallingbody"


# ------------------------------------------------------------------------------------ the record
def test_key_moment_checks_name_time_and_window():
    m = KeyMoment("max_stroke", np.float64(1.5), "  max stroke 0.3 m ", (1.2, 1.9))
    assert m.t_s == 1.5 and type(m.t_s) is float and m.description == "max stroke 0.3 m"
    assert KeyMoment.from_dict(json.loads(json.dumps(m.to_dict()))) == m
    for bad in ("Max", "1st", "a b", "", "pdd!"):
        with pytest.raises(MomentError, match="lower-case"):
            KeyMoment(bad, 0.0, "x")
    with pytest.raises(MomentError, match="finite"):
        KeyMoment("a", math.nan, "x")
    with pytest.raises(MomentError, match="contain t = 2"):
        KeyMoment("a", 2.0, "x", (0.0, 1.0))
    with pytest.raises(MomentError, match="one non-empty line"):
        KeyMoment("a", 0.0, "two\nlines")
    with pytest.raises(MomentError, match="malformed"):
        KeyMoment.from_dict({"name": "a"})


def test_moments_are_ordered_by_time_and_names_are_unique():
    a, b, c = KeyMoment("b", 2.0, "x"), KeyMoment("a", 1.0, "x"), KeyMoment("c", 1.0, "y")
    assert [m.name for m in ordered([a, b, c])] == ["a", "c", "b"]  # stable for equal times
    with pytest.raises(MomentError, match="'a' appears twice"):
        ordered([b, KeyMoment("a", 3.0, "z")])
    assert moments_from_dicts([a.to_dict(), b.to_dict()]) == [b, a]
    assert [slug(s) for s in ("Main chute", "RDA_ON", "PDD", "2nd", "--")] == [
        "main_chute",
        "rda_on",
        "pdd",
        "event_2nd",
        "event",
    ]


def test_default_window_is_a_twentieth_of_the_span_clipped():
    assert default_window(5.0, (0.0, 100.0)) == (0.0, 10.0)
    assert default_window(50.0, (0.0, 100.0)) == (45.0, 55.0)
    assert default_window(0.5, (0.0, 1.0)) == (0.4, 0.6)  # at least ± 0.1 s
    assert default_window(3.0) == (2.0, 4.0)


# --------------------------------------------------------------------------- in a recording
MOMENTS = [
    KeyMoment("release", 0.0, "release"),
    KeyMoment("max_stroke", 1.5, "max stroke 0.25 ± 0.05 m (1σ)", (1.2, 1.9)),
    KeyMoment("rebound", 1.8, "rebound"),
]


def _scene_recording(path: Path, moments, *, blueprint=True) -> Path:
    """A small recording: a vehicle pose over 0..3 s, a ``time`` series, and (``blueprint``) a
    layout with a fixed-camera 3D view and a free 3D view in one tab strip."""
    t = np.linspace(0.0, 3.0, 31)
    bp = None
    if blueprint:
        bp = rrb.Blueprint(
            rrb.Horizontal(
                rrb.Tabs(
                    rrb.Spatial3DView(
                        name="Impact", origin=layout.WORLD, eye_controls=rrb.EyeControls3D(position=[5, 5, 5])
                    ),
                    rrb.Spatial3DView(name="Chamber", origin=layout.WORLD),
                    active_tab=0,
                ),
                rrb.TimeSeriesView(name="stroke", origin=layout.plot_path("stroke")),
            ),
            rrb.TimePanel(state="collapsed"),
        )
    with open_recording(path, "moments", blueprint=bp) as rec:
        rec.view_coordinates()
        rec.poses(layout.VEHICLE, t, np.c_[t, 0 * t, 10 - t], np.tile([0.0, 0.0, 0.0, 1.0], (t.size, 1)))
        rec.scalars(layout.plot_path("stroke"), t, 1.0 - t / 3)
        log_key_moments(rec, moments)
    return path


def test_moments_logged_as_bookmarks_and_a_property_read_back(tmp_path):
    data = read_recording(_scene_recording(tmp_path / "r.rrd", [m.to_dict() for m in reversed(MOMENTS)]))
    assert read_key_moments(data) == MOMENTS  # from the property, in time order
    rows = data.text_log(layout.KEY_MOMENTS)
    assert [(t, text, lvl) for t, text, lvl in rows] == [(m.t_s, bookmark_text(m), "INFO") for m in MOMENTS]
    prop = data.properties()[KEY_MOMENTS_PROPERTY]
    assert prop["names"] == ["release", "max_stroke", "rebound"] and math.isnan(prop["window_start_s"][0])
    assert layout.KEY_MOMENTS.startswith(layout.EVENTS + "/")  # listed by the events view


def test_a_single_moment_and_the_summary_fallback(tmp_path):
    one = [KeyMoment("pdd", 180.5, "parachute deployment", (170.0, 200.0))]
    assert read_key_moments(read_recording(_scene_recording(tmp_path / "one.rrd", one))) == one
    # a recording without the property: the sibling summary's key_moments
    path = _scene_recording(tmp_path / "old.rrd", [])
    data = read_recording(path)
    assert KEY_MOMENTS_PROPERTY not in data.properties() and read_key_moments(data) == []
    (tmp_path / "old.summary.json").write_text(json.dumps({"key_moments": [m.to_dict() for m in MOMENTS]}))
    assert read_key_moments(data) == MOMENTS
    with pytest.raises(UnknownMomentError, match="no key moment 'pdd'; key moments: release, max_stroke, rebound"):
        find_moment(MOMENTS, "pdd")


def _blueprint_cells(path: Path) -> dict[str, dict]:
    """{entity: {component: value}} of the one blueprint store of an .rbl (latest row of each)."""
    reader = rr.chunk.RrdReader(path)
    (store,) = reader.blueprints()
    out: dict[str, dict] = {}
    for chunk in reader.stream(store=store):
        rb = chunk.to_record_batch()
        order = np.argsort(
            rb.column(rb.schema.get_field_index("blueprint")).to_numpy(zero_copy_only=False), kind="stable"
        )
        for i, f in enumerate(rb.schema):
            if ":" in f.name:
                for j in order:
                    v = rb.column(i)[int(j)]
                    if v.is_valid:
                        out.setdefault(chunk.entity_path, {})[f.name] = v.as_py()
    return out


def test_moment_layout_copies_the_recording_layout_with_time_panel_and_follow(tmp_path):
    data = read_recording(_scene_recording(tmp_path / "r.rrd", MOMENTS))
    lay = write_moment_blueprint(data, MOMENTS[1], tmp_path / "at.rbl")
    assert lay.copied and lay.window_s == (1.2, 1.9)
    assert lay.following_views == ["Chamber"] and lay.unchanged_views == ["Impact"] and lay.follow == layout.VEHICLE
    cells = _blueprint_cells(lay.path)
    tp = cells["/time_panel"]
    assert tp["TimePanelBlueprint:time_selection"] == [{"min": 1_200_000_000, "max": 1_900_000_000}]
    assert tp["TimePanelBlueprint:timeline"] == ["time"] and tp["TimePanelBlueprint:state"] == [3]  # expanded
    assert tp["TimePanelBlueprint:loop_mode"] == [2] and tp["TimePanelBlueprint:play_state"] == [1]  # selection, paused
    views = {d["ViewBlueprint:display_name"][0]: e for e, d in cells.items() if "ViewBlueprint:display_name" in d}
    assert set(views) == {"Impact", "Chamber", "stroke"}  # the recording's own views, copied
    eye = cells[views["Chamber"] + "/EyeControls3D"]
    assert eye["EyeControls3D:tracking_entity"] == [layout.VEHICLE]
    # the camera looks at the vehicle at the moment (pose row at 1.5 s), from 2 sizes (2 m: no
    # meshes) back along the track it came in on (from higher up: it descends)
    target, pos = np.array(eye["EyeControls3D:look_target"][0]), np.array(eye["EyeControls3D:position"][0])
    assert np.allclose(target, [1.5, 0.0, 8.5], atol=1e-5)
    assert np.linalg.norm(pos - target) == pytest.approx(4.0, rel=1e-5) and pos[2] > target[2]
    assert "EyeControls3D:tracking_entity" not in cells[views["Impact"] + "/EyeControls3D"]  # its own camera kept
    tabs = [d for d in cells.values() if "ContainerBlueprint:active_tab" in d]
    assert [d["ContainerBlueprint:active_tab"] for d in tabs] == [[views["Chamber"].lstrip("/")]]
    # playing instead of paused; no following
    lay2 = write_moment_blueprint(data, MOMENTS[0], tmp_path / "at2.rbl", follow=None, play=True)
    tp2 = _blueprint_cells(lay2.path)["/time_panel"]
    assert tp2["TimePanelBlueprint:play_state"] == [2] and tp2["TimePanelBlueprint:playback_speed"] == [0.25]
    assert tp2["TimePanelBlueprint:time_selection"] == [{"min": 0, "max": 150_000_000}]  # default: ±5 % of 3 s
    assert lay2.following_views == [] and lay2.follow is None


def test_moment_layout_of_a_recording_without_a_layout(tmp_path):
    data = read_recording(_scene_recording(tmp_path / "r.rrd", MOMENTS, blueprint=False))
    lay = write_moment_blueprint(data, MOMENTS[2], tmp_path / "at.rbl")
    assert not lay.copied and lay.following_views == []
    cells = _blueprint_cells(lay.path)
    assert cells["/time_panel"]["TimePanelBlueprint:time_selection"] == [{"min": 1_650_000_000, "max": 1_950_000_000}]
    assert not any(e.startswith("/view/") for e in cells)  # the Viewer's automatic views


def test_viewer_command_native_web_and_control_url():
    c = viewer_command("rerun", "a.rrd", "b.rbl", port=9000)
    assert c.argv == ["rerun", "a.rrd", "b.rbl", "--port", "9000"]
    assert c.control_url == "rerun+http://127.0.0.1:9000/proxy"
    assert viewer_command("rerun", "a.rrd", web=True).argv == ["rerun", "a.rrd", "--web-viewer"]
    assert viewer_command("rerun", "a.rrd").control_url is None


# ------------------------------------------------------------------------- workbench open
@pytest.fixture(scope="module")
def falling(tmp_path_factory):
    """One run of the worked example problem (registered for this module) -> its .rrd."""
    with registered_fallingbody("example_fallingbody_moments"):
        out = tmp_path_factory.mktemp("fall")
        assert main(["run", str(EXAMPLE / "fallingbody.toml"), "--out", str(out), "--seed", "3"]) == EXIT_OK
        yield out / "fallingbody.rrd"


def test_run_stores_key_moments_in_order_in_summary_and_recording(falling):
    summary = json.loads(falling.with_name("fallingbody.summary.json").read_text(encoding="utf-8"))
    km = summary["key_moments"]
    assert [m["name"] for m in km] == ["first_sample", "fastest", "end"]
    t = [m["t_s"] for m in km]
    assert t == sorted(t) and t[0] == 0.0 and t[-1] == summary["end"]["t_s"]
    assert read_key_moments(read_recording(falling)) == moments_from_dicts(km)


def test_open_list_prints_every_moment(falling, capsys):
    assert main(["open", str(falling), "--list"]) == EXIT_OK
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == ["first_sample", "fastest", "end"]
    assert "fastest descent" in lines[1] and "t =" in lines[1]


def test_open_at_dry_run_writes_the_layout_and_prints_the_command(falling, tmp_path, capsys):
    rbl = tmp_path / "fastest.rbl"
    assert main(["open", str(falling), "--at", "fastest", "--dry-run", "--rbl", str(rbl)]) == EXIT_OK
    out = capsys.readouterr().out.splitlines()
    m = find_moment(read_key_moments(read_recording(falling)), "fastest")
    assert out[0] == f"key moment fastest at t = {m.t_s:.3f} s: {m.description}"
    assert out[1].startswith(f"layout: {rbl} (") and f"time selection {m.t_s - 2:.3f} .. {m.t_s + 2:.3f} s" in out[1]
    cmd = shlex.split(out[2].removeprefix("command: "))
    assert Path(cmd[0]).name == "rerun" and cmd[1:] == [str(falling), str(rbl)]
    assert "'★ fastest' mark" in out[3] and f"t = {m.t_s:.3f} s" in out[3]
    tp = _blueprint_cells(rbl)["/time_panel"]
    assert tp["TimePanelBlueprint:time_selection"] == [
        {"min": round((m.t_s - 2) * 1e9), "max": round((m.t_s + 2) * 1e9)}
    ]
    # the default layout path: beside the recording
    assert main(["open", str(falling), "--at", "end", "--dry-run"]) == EXIT_OK
    assert falling.with_name("fallingbody.at_end.rbl").is_file()


def test_open_at_an_unknown_moment_lists_the_valid_names(falling, tmp_path, capsys):
    assert main(["open", str(falling), "--at", "max_stroke", "--dry-run", "--rbl", str(tmp_path / "x.rbl")]) == (
        EXIT_USAGE
    )
    err = capsys.readouterr().err
    assert err.strip() == (
        f"workbench: {falling} has no key moment 'max_stroke'; key moments: first_sample, fastest, end"
    )
    assert not (tmp_path / "x.rbl").exists()
