"""The pure parts of the web-viewer driver (``workbench.recording.browser``): the empty-3D-view
judgement on synthetic screenshots, the protobuf reading of the viewer's state and logs, ports and
command lines, and the command line's refusal when Chromium is missing. The browser itself is
exercised by the slow tier (``tests/test_browser.py``)."""

from __future__ import annotations

import socket
from urllib.parse import parse_qs, urlsplit

import numpy as np
import pytest

from workbench.cli import EXIT_KIND, EXIT_USAGE, main
from workbench.recording import browser as br
from workbench.recording.browser import encode_field as f

W, H = 1400, 900


def _blank(colour=(255, 255, 255)) -> np.ndarray:
    img = np.empty((H, W, 3), np.uint8)
    img[:] = colour
    return img


def _region_px():
    left, top, right, bottom = br.SCENE_REGION
    return int(left * W), int(top * H), int(right * W), int(bottom * H)


def test_uniform_and_faint_grid_are_empty():
    img = _blank()
    assert br.judge_scene(img).empty and br.judge_scene(img).content_fraction == 0.0
    # the viewer's ground grid: thin lines a few grey levels off the background
    img[::40, :, :] = 232
    img[:, ::40, :] = 236
    j = br.judge_scene(img)
    assert j.empty and j.background == (255, 255, 255)
    # dark theme background with a faint grid: still empty
    dark = _blank((13, 16, 17))
    dark[::30, :, :] = 40
    assert br.judge_scene(dark).empty


def test_a_thin_line_or_a_mesh_is_content():
    x0, y0, x1, y1 = _region_px()
    img = _blank()
    img[(y0 + y1) // 2 : (y0 + y1) // 2 + 2, x0:x1] = (230, 120, 20)  # a 2-px trajectory across the view
    j = br.judge_scene(img)
    assert not j.empty and j.content_fraction > br.MIN_CONTENT_FRACTION
    img = _blank()
    img[y0 + 50 : y0 + 150, x0 + 50 : x0 + 200] = (200, 40, 40)  # a mesh
    assert not br.judge_scene(img).empty
    # content outside the judged region (another view) does not count
    img = _blank()
    img[:, x1 + 20 :] = (0, 0, 255)
    assert br.judge_scene(img).empty


def test_rgba_input_and_bad_regions():
    img = np.dstack([_blank(), np.full((H, W), 255, np.uint8)])
    assert br.judge_scene(img).empty
    with pytest.raises(ValueError, match="region"):
        br.judge_scene(img, region=(0.6, 0.1, 0.5, 0.7))
    with pytest.raises(ValueError, match="image"):
        br.judge_scene(np.zeros((10, 10)))


def test_protobuf_round_trip():
    buf = f(1, "abc") + f(2, 300) + f(3, -5) + f(4, True) + f(5, f(1, "nested")) + f(1, "again")
    msg = br.decode_message(buf)
    assert msg[1] == [b"abc", b"again"] and msg[2] == [300] and msg[4] == [1]
    assert msg[3] == [(1 << 64) - 5]  # int64 as two's complement varint
    assert br.decode_message(msg[5][0]) == {1: [b"nested"]}
    with pytest.raises(ValueError):
        br.decode_message(f(1, "abc")[:-1])


def _timeline(name: str, start: int, end: int) -> bytes:
    return f(1, f(1, name)) + f(2, 2) + f(3, f(1, start) + f(2, end))


def test_parse_viewer_state():
    store = "Recording:edl-workbench:1234"
    rec = f(1, store) + f(2, _timeline("step", 0, 2790)) + f(2, _timeline("time", -500_581_715, 2_290_500_000))
    rec += f(3, f(1, f(1, "time")) + f(2, 2) + f(3, f(1, 599_418_296)))
    view3d = f(1, "id-1") + f(2, "3D") + f(3, "Impact") + f(4, "/world") + f(5, True)
    report = f(1, "error") + f(2, "bad transform") + f(3, "entity /world/x")
    plot = f(1, "id-2") + f(2, "TimeSeries") + f(3, "stroke") + f(4, "/plots/stroke") + f(6, report)
    loading = f(1, "http://x/a.rrd") + f(2, "Loading a.rrd…")
    buf = f(1, "about:recording") + f(2, store) + f(3, rec) + f(5, view3d) + f(5, plot) + f(6, "0.41.0")
    st = br.parse_viewer_state(buf + f(7, loading))
    assert st.version == "0.41.0" and st.active == store and st.recordings == (store,)
    assert st.timelines == {"step": (0, 2790), "time": (-500_581_715, 2_290_500_000)}
    assert st.cursor_timeline == "time" and st.cursor == 599_418_296
    assert st.views == (("id-1", "3D", "Impact", "/world"), ("id-2", "TimeSeries", "stroke", "/plots/stroke"))
    assert st.reports == (("error", "view 'stroke': bad transform (entity /world/x)"),)
    assert st.loading == ("Loading a.rrd…",)
    assert br.parse_viewer_state(buf).loading == ()


def test_parse_viewer_logs():
    entry = f(1, 7) + f(2, "ERROR") + f(3, "re_viewer") + f(4, "boom")
    resp = f(2, f(1, entry) + f(1, f(1, 8) + f(2, "WARN") + f(3, "eframe") + f(4, "meh")))
    assert br.parse_viewer_logs(resp) == [(7, "ERROR", "re_viewer: boom"), (8, "WARN", "eframe: meh")]


def test_ports_commands_and_urls():
    port = br.free_port()
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))  # really free on the loopback interface
    cmd = br.server_command("/x/rerun", 9001, 9002)
    assert cmd[0] == "/x/rerun" and "--serve-web" in cmd
    assert cmd[cmd.index("--bind") + 1] == "127.0.0.1"
    assert cmd[cmd.index("--web-viewer-port") + 1] == "9001" and cmd[cmd.index("--port") + 1] == "9002"
    url = br.viewer_url("http://127.0.0.1:9001/", ["http://127.0.0.1:9001/d/a b.rrd", "http://127.0.0.1:9001/d/l.rbl"])
    q = parse_qs(urlsplit(url).query)
    assert q["url"] == ["http://127.0.0.1:9001/d/a b.rrd", "http://127.0.0.1:9001/d/l.rbl"]
    assert q["renderer"] == ["webgl"] and url.startswith("http://127.0.0.1:9001/?")


def test_missing_chromium_is_named_and_the_cli_refuses(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("WORKBENCH_CHROMIUM", str(tmp_path / "no-such-chrome"))
    assert br.find_chromium() is None
    assert "Chromium" in br.unavailable_reason()
    rec = tmp_path / "a.rrd"
    rec.write_bytes(b"")
    assert main(["screenshot", str(rec), "--out", str(tmp_path / "shots"), "--quiet"]) == EXIT_KIND
    assert "Chromium" in capsys.readouterr().err
    assert main(["screenshot", str(rec), "--at", "later"]) == EXIT_USAGE
    assert main(["screenshot", str(rec), "--size", "big"]) == EXIT_USAGE


def test_check_outside_a_session_is_an_error():
    with pytest.raises(RuntimeError, match="with-block"):
        br.WebViewer().check("a.rrd", "a.png")


def test_the_negative_control_recording_is_written(tmp_path):
    """The browser test's empty-scene control is a valid recording (its layout passes the same
    checks as a problem's: this broke once without a browser to notice): a plot, a report, no /world."""
    from workbench.recording.reader import read_recording

    path = br.write_empty_scene_recording(tmp_path / "empty_scene.rrd")
    assert path.is_file() and path.stat().st_size > 0
    rec = read_recording(path)
    assert not [e for e in rec.entities() if e.startswith("/world")]


def test_a_plots_only_recording_needs_no_3d_view(tmp_path):
    """A Monte Carlo summary (plots and a table) has no 3D content: its blueprint's lack of a 3D view
    is not an error, so ``workbench screenshot`` no longer exits 7 on it; a recording with any 3D
    archetype still needs a drawn 3D view, and an empty one still fails."""
    from pathlib import Path

    import rerun as rr

    from workbench.recording.writer import open_recording

    plots = br.write_empty_scene_recording(tmp_path / "plots.rrd")
    assert not br.has_3d_content(plots)
    with open_recording(tmp_path / "scene.rrd", "scene") as rec:
        rec.stream.log("world/line", rr.LineStrips3D([[[0, 0, 0], [1, 1, 1]]]), static=True)
    assert br.has_3d_content(tmp_path / "scene.rrd")
    assert br.has_3d_content(tmp_path / "missing.rrd")  # unreadable: the viewer judges it, as before
    plots_only = br.ViewerCheck(recording=Path(plots), needs_3d=False)
    assert plots_only.ok and "plots only" in plots_only.summary()
    assert not br.ViewerCheck(recording=Path(plots)).ok  # a 3D recording without a judged 3D view
    empty = br.SceneJudgement(content_fraction=0.0, background=(255, 255, 255), region_px=(0, 0, 1, 1), empty=True)
    assert not br.ViewerCheck(recording=Path(plots), needs_3d=False, scenes={"3D": empty}).ok
