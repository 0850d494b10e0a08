"""``workbench compare``, ``workbench replay --mp4/--png`` and ``workbench init``, through the
command line (``workbench.cli.main``).

Fast tier: the worked example problem (falling body, registered here only) run twice with the same
seed and once with another, compared; a recording of another kind refused; the shared drop-test
run of the session (``droptest_run``) compared with itself and replayed as a short MP4 read back
with OpenCV, and its summary PNG; ``init`` scenarios generated from every problem's schema
validate; ``init post2_j2`` runs end to end. Slow tier: ``init droptest`` runs end to end,
``init schiaparelli`` validates with its example telemetry, the full-length MP4s.
"""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest
from example_problem import registered_fallingbody  # tests/support, on sys.path via tests/conftest.py

from workbench.cli import main
from workbench.io.assets import assets_dir
from workbench.io.scenario import find_scenarios, load_scenario
from workbench.problems import registry
from workbench.problems.template import SYNTHETIC_TABLE, scenario_toml
from workbench.recording import layout
from workbench.recording.compare import compare_runs
from workbench.recording.reader import read_recording
from workbench.recording.replay import frame_times
from workbench.recording.summary_image import SIZE_PX
from workbench.recording.writer import open_recording

FALLING = Path(__file__).resolve().parent / "example_fallingbody"


@pytest.fixture(scope="module")
def falling(tmp_path_factory):
    """Three falling-body runs: ``a`` and ``a2`` with seed 3, ``b`` with seed 4 -> {label: rrd}."""
    with registered_fallingbody():
        out = {}
        for label, seed in (("a", 3), ("a2", 3), ("b", 4)):
            d = tmp_path_factory.mktemp(f"fall_{label}")
            assert main(["run", str(FALLING / "fallingbody.toml"), "--out", str(d), "--seed", str(seed)]) == 0
            out[label] = d / "fallingbody.rrd"
        yield out


def test_compare_two_identical_runs_differ_by_exactly_zero(falling, tmp_path, capsys):
    c = tmp_path / "c.rrd"
    assert main(["compare", str(falling["a"]), str(falling["a2"]), "--out", str(c)]) == 0
    text = capsys.readouterr().out
    assert "identical: every difference is exactly 0" in text
    cmp = compare_runs(falling["a"], falling["a2"])
    assert cmp.identical and cmp.series and not cmp.numbers
    assert [d.root for d in cmp.series] == ["altitude"]
    d = cmp.series[0]
    assert len(d.t) == 801 and np.all(d.diff == 0.0) and np.all(d.sigma > 0)
    rec = read_recording(c)
    ents = set(rec.entities())
    for e in (
        layout.compare_diff_path("altitude") + "/value",
        layout.compare_diff_path("altitude") + "/plus_3sigma",
        layout.compare_overlay_path("altitude", "a"),
        layout.compare_overlay_path("altitude", "b"),
        layout.COMPARE_CHANGES,
        layout.COMPARE_REPORT_A,
        layout.COMPARE_REPORT_B,
    ):
        assert e in ents, e
    _, diff = rec.scalars(layout.compare_diff_path("altitude") + "/value")
    assert np.all(diff == 0.0)
    _, plus = rec.scalars(layout.compare_diff_path("altitude") + "/plus_3sigma")
    assert np.allclose(plus[:, 0], 3.0 * d.sigma[:, 0])
    assert rec.properties()["compare"]["identical"] is True


def test_compare_two_seeds_differ(falling, capsys):
    assert main(["compare", str(falling["a"]), str(falling["b"])]) == 0
    text = capsys.readouterr().out
    cmp = compare_runs(falling["a"], falling["b"])
    assert not cmp.identical
    d = cmp.series[0]
    assert np.max(np.abs(d.diff)) > 0.0
    # the seed also draws the release altitude: A - B follows the truth difference, within a few
    # combined sigma (the truths come from the telemetry folders, never from the recordings)
    tr = {k: np.load(falling[k].parent / "fallingbody" / "telemetry" / "truth.npz") for k in ("a", "b")}
    truth_diff = np.interp(d.t, tr["a"]["t"], tr["a"]["h"]) - np.interp(d.t, tr["b"]["t"], tr["b"]["h"])
    assert np.max(np.abs(truth_diff)) > 1.0
    assert np.max(np.abs(d.diff[:, 0] - truth_diff) / d.sigma[:, 0]) < 5.0
    assert ("seed", 3, 4) in cmp.numbers
    # the seeds are named with the runs, and different seeds said to mean different truths
    assert "seed 3" in text and "seed 4" in text and "Different truths" in text and "Key numbers" in text
    assert "| `seed` |" not in text


def test_compare_refuses_runs_of_different_kinds(falling, tmp_path, capsys):
    other = tmp_path / "other.rrd"
    with open_recording(other, "other", properties={"run": {"kind": "droptest", "seed": 1}}) as rec:
        rec.report("other")
    assert main(["compare", str(falling["a"]), str(other), "--out", str(tmp_path / "c.rrd")]) == 3
    err = capsys.readouterr().err
    assert "differ in kind" in err and "'fallingbody'" in err and "'droptest'" in err
    assert not (tmp_path / "c.rrd").exists()
    assert main(["compare", str(falling["a"]), str(tmp_path / "missing.rrd")]) == 3


def test_replay_png_of_any_kind_and_no_mp4_without_a_vehicle(falling, tmp_path, capsys):
    png = tmp_path / "s.png"
    assert main(["replay", str(falling["a"]), "--png", str(png)]) == 0
    img = cv2.imread(str(png))
    assert img is not None and (img.shape[1], img.shape[0]) == SIZE_PX
    assert main(["replay", str(falling["a"]), "--mp4", str(tmp_path / "v.mp4")]) == 5
    assert "/world/vehicle" in capsys.readouterr().err
    assert not (tmp_path / "v.mp4").exists()
    assert main(["replay", str(falling["a"])]) == 2


def test_frame_times_slow_down_around_events():
    t = frame_times(0.0, 10.0, [5.0], duration_s=4.0, fps=25.0, slow=0.2, window_s=0.3)
    assert len(t) == 100 and t[0] == 0.0 and t[-1] <= 10.0 and np.all(np.diff(t) > 0)
    dt = np.diff(t)
    near = dt[np.abs(t[1:] - 5.0) < 0.1]
    far = dt[np.abs(t[1:] - 5.0) > 2.0]
    assert near.max() < 0.3 * far.min()
    assert np.allclose(far, far[0], rtol=1e-3)


def test_droptest_compare_with_itself_and_replay(droptest_run, tmp_path, capsys):
    a = droptest_run.rrd
    b_dir = tmp_path / "copy"
    b_dir.mkdir()
    b = b_dir / a.name
    shutil.copyfile(a, b)
    shutil.copyfile(droptest_run.summary_json, b_dir / droptest_run.summary_json.name)
    c = tmp_path / "c.rrd"
    assert main(["compare", str(a), str(b), "--out", str(c)]) == 0
    cmp = compare_runs(a, b)
    assert cmp.identical and cmp.position is not None and np.all(cmp.position.diff == 0.0)
    assert np.all(cmp.position.sigma > 0)  # from the two runs' 3-sigma ellipsoids
    assert {"stroke", "position/x", "velocity/vz"} <= {d.root for d in cmp.series}
    ents = set(read_recording(c).entities())
    assert layout.compare_run_path("a", "vehicle") in ents and layout.compare_run_path("b", "track") in ents
    assert layout.compare_position_path("x") + "/value" in ents and layout.SURFACE in ents
    assert any(e.startswith(layout.compare_run_path("b", "vehicle") + "/") for e in ents)  # meshes copied
    # A's bodies are meshes, B's their wireframe: B drawn solid on top hid A at the same pose
    crec = read_recording(c)
    a_mesh = [e for e in ents if e.startswith(layout.compare_run_path("a", "vehicle") + "/") and crec.meshes(e)]
    b_veh = [e for e in ents if e.startswith(layout.compare_run_path("b", "vehicle") + "/")]
    assert a_mesh and not any(crec.meshes(e) for e in b_veh)
    assert any("LineStrips3D:strips" in crec.components(e) for e in b_veh)

    mp4, png = tmp_path / "d.mp4", tmp_path / "d.png"
    assert main(["replay", str(a), "--mp4", str(mp4), "--png", str(png), "--duration", "2", "--quiet"]) == 0
    assert "wrote" in capsys.readouterr().err
    cap = cv2.VideoCapture(str(mp4))
    assert cap.isOpened()
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    frames = []
    ok, img = cap.read()
    while ok:
        frames.append(img)
        ok, img = cap.read()
    cap.release()
    assert (n, w, h, len(frames)) == (50, 1280, 720, 50)
    # the scene is drawn: frames differ from each other and are not a flat background
    assert np.std(frames[25].astype(float)) > 10.0
    assert np.mean(np.abs(frames[0].astype(float) - frames[-1].astype(float))) > 1.0
    img = cv2.imread(str(png))
    assert (img.shape[1], img.shape[0]) == SIZE_PX


@pytest.mark.parametrize("kind", sorted(set(registry.kinds()) - {"fallingbody"}))
def test_init_scenario_text_from_every_schema_validates(kind, tmp_path):
    """The generated scenario of each problem's shipped scenarios loads as TOML and validates, and
    lists every key of the schema (the telemetry part is exercised by the end-to-end tests)."""
    problem = registry.get(kind)
    shipped = [p for p in find_scenarios(assets_dir()).values() if load_scenario(p).kind == kind]
    assert shipped
    for path in shipped:
        base = load_scenario(path)
        data = {k: v for k, v in base.data.items() if k != SYNTHETIC_TABLE}
        text = scenario_toml(problem.schema, data, "# test")
        out = tmp_path / f"{base.name}.toml"
        out.write_text(text, encoding="utf-8")
        parsed = tomllib.loads(text)
        assert SYNTHETIC_TABLE not in parsed
        problem.schema.validate(parsed, out)
        for t in problem.schema.tables:
            if t.name.split(".")[0] == SYNTHETIC_TABLE:
                continue
            for k in t.keys:
                assert f"# {k.name}" in text, (base.name, t.name, k.name)


def test_init_post2_j2_runs_end_to_end(tmp_path, capsys):
    d = tmp_path / "my_orbit"
    assert main(["init", "post2_j2", str(d)]) == 0
    assert "run it with: workbench run" in capsys.readouterr().out
    sc = load_scenario(d / "scenario.toml")
    assert not sc.is_synthetic and sc.name == "my_orbit"
    assert (d / "telemetry" / "gravity.csv").is_file() and not (d / "telemetry" / "truth.npz").exists()
    readme = (d / "README.md").read_text(encoding="utf-8")
    assert "telemetry/gravity.csv" in readme and "observations.gravity.file" in readme
    assert main(["run", str(d / "scenario.toml"), "--out", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "my_orbit.rrd").is_file()
    assert main(["init", "post2_j2", str(d)]) == 3  # refuses to overwrite


def _marked(text: str) -> list[str]:
    """The keys on the lines right after an EXAMPLE mark (each mark is followed by a key line)."""
    from workbench.io.schema import EXAMPLE_MARK

    lines = text.splitlines()
    out = []
    for i, ln in enumerate(lines):
        if ln == EXAMPLE_MARK:
            assert " = " in lines[i + 1] and not lines[i + 1].startswith("#"), lines[i + 1]
            out.append(lines[i + 1].split(" = ")[0])
    return out


def test_init_droptest_marks_the_example_chambers_values(tmp_path):
    """Issue 27 item 5: ``init droptest`` marks the values that are the example chamber's (its epoch,
    ramp, nail, magnetic field, triads, acquisition filter; in the setup file the hanging position and
    the bungee) as to be replaced, and no other; the README lists them; the files still parse."""
    d = tmp_path / "rig"
    assert main(["init", "droptest", str(d)]) == 0
    text = (d / "scenario.toml").read_text(encoding="utf-8")
    tomllib.loads(text)
    assert _marked(text) == [
        "epoch_utc",
        "ramp_angle_deg",
        "nail_depth_m",
        "magnetic_field_spf",
        "triads",
        "sample_rate_hz",
        "filter_cutoff_hz",
        "filter_order",
    ]
    setup = (d / "telemetry" / "setup.toml").read_text(encoding="utf-8")
    tomllib.loads(setup)
    assert _marked(setup) == [
        "position_m",
        "position_sigma_m",
        "anchor_m",
        "rest_length_m",
        "coefficients",
        "count",
        "attach_body_m",
        "mass_kg",
    ]
    readme = (d / "README.md").read_text(encoding="utf-8")
    for key in ("`scenario.toml`: `chamber.magnetic_field_spf`", "`telemetry/setup.toml`: `hanging.position_m`"):
        assert key in readme


@pytest.mark.slow
def test_init_droptest_runs_end_to_end(tmp_path):
    d = tmp_path / "drop"
    assert main(["init", "droptest", str(d)]) == 0
    assert (d / "mer_drop_lander.toml").is_file()  # the lander the scenario points at is copied
    assert main(["run", str(d / "scenario.toml"), "--out", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "drop.rrd").is_file()


@pytest.mark.slow
def test_init_schiaparelli_validates_with_its_telemetry(tmp_path):
    d = tmp_path / "edm"
    assert main(["init", "schiaparelli", str(d)]) == 0  # init checks the files resolve
    sc = load_scenario(d / "scenario.toml")
    assert sc.kind == "entry" and not sc.is_synthetic
    assert (d / "schiaparelli.toml").is_file()
    assert all((d / "telemetry" / f).is_file() for f in ("gnc.csv", "rda_slant_range.csv", "events.csv"))


def test_replay_text_draws_sigma_plus_minus_and_degree_not_a_placeholder():
    """The HUD's σ, ± and ° are drawn with their own glyphs (cv2's Hershey fonts drew "?")."""
    from workbench.recording import replay as rp

    def ink(s: str) -> np.ndarray:
        img = np.zeros((60, 200, 3), np.uint8)
        rp.draw_text(img, s, (10, 45), 1.0)
        return img.max(axis=2) > 60

    q = ink("?")
    for glyph in ("σ", "±", "°"):
        g = ink(glyph)
        assert g.sum() > 20 and np.sum(g != q) > 20, glyph


def test_replay_title_names_the_scenario_and_captions_stay_left_of_the_inset(droptest_run, tmp_path):
    from workbench.recording import replay as rp

    data = read_recording(droptest_run.rrd)
    title, subtitle = rp.replay_titles(data, "droptest")
    assert title.startswith("droptest — MER airbag drop") and "seed" in subtitle and "UTC" in subtitle
    ov = rp.Overlay(
        title=title,
        subtitle=subtitle,
        events=[(0.0, "a very long event caption " * 8)],
        hud=[],
        t0=0.0,
        t1=1.0,
        track_2d=np.array([[1000.0, 540.0], [1100.0, 560.0]]),  # the inset's dot above the caption band
        track_t=np.array([0.0, 1.0]),
        caption_s=1.0,
    )
    img = np.zeros((rp.H, rp.W, 3), np.uint8)
    rp.draw_overlay(img, ov, 0.5)
    a, b, c, d = ov.inset
    caption = (img[rp.H - 112 : rp.H - 74, :, 2] > 200) & (img[rp.H - 112 : rp.H - 74, :, 0] < 120)  # yellow text
    assert caption.any() and not caption[:, a:].any()
    # a 1920×1080 frame gets the same picture, scaled: shrunk to 1280×720 it matches the 720p one
    big = np.zeros((1080, 1920, 3), np.uint8)
    rp.draw_overlay(big, ov, 0.5)
    small = cv2.resize(big, (rp.W, rp.H), interpolation=cv2.INTER_AREA)
    assert np.mean(np.abs(small.astype(float) - img.astype(float))) < 6.0
    caption_big = (big[1080 - 168 : 1080 - 111, :, 2] > 200) & (big[1080 - 168 : 1080 - 111, :, 0] < 120)
    assert caption_big.any() and not caption_big[:, int(1.5 * a) :].any()

    mp4 = tmp_path / "hd.mp4"
    st = rp.render_mp4(data, mp4, duration_s=0.4, fps=10, size=(1920, 1080))
    cap = cv2.VideoCapture(str(mp4))
    assert st.size == (1920, 1080) and int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)) == 1920
    assert int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)) == 1080
    cap.release()
    with pytest.raises(ValueError, match="16:9"):
        rp.render_mp4(data, tmp_path / "sq.mp4", duration_s=0.4, fps=10, size=(1000, 1000))


def test_mesh_edges_are_the_unique_edges_of_the_triangles():
    from workbench.recording.compare import mesh_edges

    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])  # a tetrahedron: 6 edges
    e = mesh_edges(v, f)
    assert e.shape == (6, 2, 3)
    assert len({tuple(sorted(map(tuple, s))) for s in e}) == 6


def test_compare_ranks_changes_by_sigma_and_drops_meaningless_percentages():
    """A summary number with a σ beside it is ranked by |B − A| / combined σ, ahead of the numbers
    without one; a vector component takes no sibling's σ; a sign change or a change larger than A
    has no percentage."""
    from workbench.recording.compare import Comparison, change_text, ranked_changes, sigma_of

    flat = {"ms.distance_m": 0.2, "ms.sigma_m": 0.05, "ms.point_m[0]": 1.0}
    assert sigma_of("ms.distance_m", flat) == 0.05 and sigma_of("ms.point_m[0]", flat) is None
    cmp = Comparison(a=None, b=None, kind="x", names=("a", "b"))
    cmp.summaries = (
        {"ms": {"distance_m": 0.2, "sigma_m": 0.05, "point_m": [1.0]}, "big": 1.0},
        {"ms": {"distance_m": 0.3, "sigma_m": 0.05, "point_m": [9.0]}, "big": 50.0},
    )
    cmp.numbers = [("big", 1.0, 50.0), ("ms.distance_m", 0.2, 0.3), ("ms.point_m[0]", 1.0, 9.0)]
    ranked = ranked_changes(cmp)
    assert ranked[0][0] == "ms.distance_m" and abs(ranked[0][3] - 0.1 / np.hypot(0.05, 0.05)) < 1e-12
    assert [r[3] for r in ranked[1:]] == [None, None]
    assert (
        "%" not in change_text(0.001, 0.00398)
        and "%" not in change_text(-1.0, 1.0)
        and "(+50.0 %)" in change_text(2.0, 3.0)
    )
