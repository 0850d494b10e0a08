"""``docs/TUTORIAL_DROPRIG.md`` ("your own drop rig", issue #27 item 6) runs as written.

Its worked example, rig 2's drop 7, is the example drop ``workbench init droptest`` writes,
re-expressed as another rig would have logged it: the IMU along rig 2's lander axes L
(``x_L = C x_B + CM_L``: x toward the apex, y toward base vertex 0, the origin at the base centre),
triads named ``A1``..``A4``, accelerations in m/s², rates in rad/s, time in ms, the IMU's tags 3 ms
late; the 3DM vectors in L.  The test writes those files (the raw files of the page), then follows
the page: ``init`` in a fresh folder, the lander asset and the setup file from its TOML blocks, the
scenario's marked lines replaced by its scenario block, its ``run`` and ``open`` commands; the run
is OK and its max stroke and 1σ are the example's (computed on the example files before they were
replaced) within 1 mm.  The headers, the time shifts and the headline quoted on the page are the
run's; each mistake of its last section gives the message it quotes.
"""

from __future__ import annotations

import contextlib
import json
import re
import shlex
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.io.assets import assets_dir
from workbench.io.scenario import load_scenario
from workbench.io.schema import EXAMPLE_MARK
from workbench.io.telemetry import read_telemetry, write_telemetry
from workbench.problems.droptest.lander import load_lander
from workbench.problems.droptest.pipeline import run_droptest
from workbench.problems.droptest.problem import DropTestProblem
from workbench.recording.reader import read_recording

TUTORIAL = Path(__file__).resolve().parents[3] / "docs" / "TUTORIAL_DROPRIG.md"
#: rig 2's lander axes in the example's body axes B: x_L = z_B (apex), y_L = −y_B, z_L = x_B
C = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
CM_L = np.array([0.4, 0.0, 0.0])  # L's origin at the base petal's centre, 0.4 m below the CM
TRIADS = {"BP": "A1", "PYBP": "A2", "PXBP": "A3", "MXBP": "A4"}
LATENCY_S = 0.003  # rig 2's IMU tags lag the motion by this


def _text() -> str:
    return TUTORIAL.read_text(encoding="utf-8")


def _squash(text: str) -> str:
    """``text`` with every run of white space one blank (the page wraps its lines)."""
    return " ".join(text.split())


def _blocks(lang: str) -> list[str]:
    """The page's fenced blocks of language ``lang`` ("" for plain blocks), in order."""
    return re.findall(r"^```" + lang + r"\n(.*?)^```", _text(), flags=re.M | re.S)


def _toml_block(first_line: str) -> str:
    (block,) = [b for b in _blocks("toml") if b.splitlines()[0] == first_line]
    return block


def _commands(prefix: str) -> list[list[str]]:
    """The page's ``workbench`` command lines starting with ``prefix``, as argv (comments dropped)."""
    out = []
    for block in _blocks("bash"):
        for line in block.splitlines():
            if line.startswith(prefix):
                out.append(shlex.split(line, comments=True)[1:])
    return out


def rig2_files(example: Path, dst: Path) -> None:
    """Rig 2's raw files from the example's (``init``'s ``telemetry/``): see the module docstring."""
    imu = read_telemetry(example / "imu.csv")
    ch = {}
    for old, new in [*TRIADS.items(), ("gyro", "gyro")]:
        v = imu.stack([f"{old}.{a}" for a in "xyz"]) @ C.T
        unit = "rad/s" if old == "gyro" else "m/s^2"
        ch.update({f"{new}.{a}": (v[:, i], unit) for i, a in enumerate("xyz")})
    write_telemetry(dst / "imu.csv", imu.time + LATENCY_S, ch, float_format="%.9g", time_unit="ms")
    att = read_telemetry(example / "3dm.csv")
    ch = {}
    for name in ("up", "mag"):
        v = att.stack([f"{name}.{a}" for a in "xyz"]) @ C.T
        ch.update({f"{name}.{a}": (v[:, i], "1") for i, a in enumerate("xyz")})
    write_telemetry(dst / "3dm.csv", att.time, ch, float_format="%.9g")
    shutil.copyfile(example / "events.csv", dst / "events.csv")


def edit_scenario(text: str, block: str) -> str:
    """``text`` (the scenario ``init`` wrote) with the page's scenario ``block`` applied as a user
    would: a key the block sets replaces its line in that table (an active line, else the commented
    ``# key =`` line is uncommented), a ``# key = ...`` line of the block comments that key out, and
    the example mark above a changed line goes."""
    edits: dict[tuple[str, str], str | None] = {}
    table = ""
    for ln in block.splitlines():
        if ln.startswith("["):
            table = ln.strip("[]")
        elif " = " in ln and table:
            key, value = ln.lstrip("# ").split(" = ", 1)
            edits[(table, key)] = None if ln.startswith("#") else value
    lines, table, done = text.splitlines(), "", set()
    for i, ln in enumerate(lines):
        if ln.startswith("[") or ln.startswith("# ["):
            table = ln.lstrip("# ").split("]")[0].strip("[")
            continue
        m = re.match(r"^(# )?(\w+) = ", ln)
        if m is None or (table, m.group(2)) not in edits:
            continue
        value = edits[(table, m.group(2))]
        if value is None:
            lines[i] = f"# {m.group(2)} = " + ln[m.end() :]
        else:
            lines[i] = f"{m.group(2)} = {value}"
        if i and lines[i - 1] == EXAMPLE_MARK:
            lines[i - 1] = None
        done.add((table, m.group(2)))
    assert done == set(edits), f"keys of the page's scenario block not found: {set(edits) - done}"
    return "\n".join(ln for ln in lines if ln is not None) + "\n"


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """The page followed up to the run: ``(folder, the example's max_stroke summary)``."""
    root = tmp_path_factory.mktemp("tutorial")
    (init,) = _commands("workbench init droptest")
    with contextlib.chdir(root):
        assert main(init) == 0
    d = root / init[-1]
    st = DropTestProblem().settings(load_scenario(d / "scenario.toml"))
    ref = run_droptest(st, DropTestProblem().telemetry_files(st)).summary
    example = root / "example"
    shutil.copytree(d / "telemetry", example)
    rig2_files(example, d / "telemetry")
    for first in ("# myrig/rig2_lander.toml", "# myrig/telemetry/setup.toml"):
        (root / first[2:]).write_text(_toml_block(first), encoding="utf-8")
    sc = d / "scenario.toml"
    sc.write_text(edit_scenario(sc.read_text(encoding="utf-8"), _toml_block("# myrig/scenario.toml")), "utf-8")
    return root, ref


def test_the_tutorial_lander_is_the_example_lander_in_rig_2s_axes(rig):
    """The page's lander asset is the example's body in L: vertices, CM, inertia, lever arms."""
    root, _ = rig
    a = load_lander(assets_dir() / "landers" / "mer_drop_lander.toml")
    b = load_lander(root / "myrig" / "rig2_lander.toml")
    np.testing.assert_allclose(b.cm_L, CM_L)
    np.testing.assert_allclose(np.asarray(b.body.vertices), np.asarray(a.body.vertices) @ C.T, atol=1e-6)
    np.testing.assert_allclose(b.inertia_B, C @ a.inertia_B @ C.T)
    np.testing.assert_allclose(b.lobe_centers_B, a.lobe_centers_B @ C.T, atol=1e-5)
    for old, new in [*TRIADS.items(), ("gyro", "gyro")]:
        np.testing.assert_allclose(b.instruments[new], C @ a.instruments[old], atol=1e-12)
    assert b.pressure_pa is None  # the simulator-only keys are left out


def test_the_tutorial_runs_as_written(rig, capsys):
    root, ref = rig
    d = root / "myrig"
    text = _text()
    for f in ("imu.csv", "3dm.csv", "events.csv"):  # the layouts the page shows are the files'
        lines = (d / "telemetry" / f).read_text(encoding="utf-8").splitlines()
        header = next(ln for ln in lines if not ln.startswith("#"))
        assert f"```\n{header}\n" in text, f
    assert "time [s],event\n0,release\n1.2245,bungee_cut\n" in (d / "telemetry" / "events.csv").read_text()
    for f in ("scenario.toml", "telemetry/setup.toml"):  # every marked value was replaced
        assert "EXAMPLE" not in (d / f).read_text(encoding="utf-8"), f
    ms = ref["max_stroke"]
    assert f"max stroke {ms['distance_m']:.3f} ± {ms['sigma_m']:.3f} m (1σ) at t = {ms['time_s']:.3f} s" in text

    (run,) = _commands("workbench run myrig")
    with contextlib.chdir(root):
        capsys.readouterr()
        assert main(run) == 0
        out = capsys.readouterr()
        summary = json.loads(Path("runs/drop7.summary.json").read_text(encoding="utf-8"))
        listed, at = _commands("workbench open")
        assert main(listed) == 0
        assert "max_stroke " in capsys.readouterr().out
        assert main([*at, "--dry-run"]) == 0  # the Viewer is not started
        assert Path("runs/drop7.at_max_stroke.rbl").is_file()
        export = Path("runs/drop7.reconstruction.csv").read_text(encoding="utf-8").splitlines()
        report = read_recording("runs/drop7.rrd").text_document("/report")

    assert summary["health"]["verdict"] == "OK", [c for c in summary["health"]["checks"] if c["status"] != "OK"]
    got = summary["max_stroke"]
    print(
        f"max stroke: example {ms['distance_m']:.5f} ± {ms['sigma_m']:.5f} m at {ms['time_s']:.4f} s; "
        f"rig 2 {got['distance_m']:.5f} ± {got['sigma_m']:.5f} m at {got['time_s']:.4f} s"
    )
    assert abs(got["distance_m"] - ms["distance_m"]) < 1e-3  # the same drop: 0.02σ
    assert abs(got["sigma_m"] - ms["sigma_m"]) < 1e-3
    assert abs(got["time_s"] - ms["time_s"]) < 0.002
    shifts = summary["time_shifts"]["imu"]["causes"]
    assert shifts["latency ([sensors.acquisition] latency_s)"] == LATENCY_S
    (quoted,) = [b for b in _blocks("json") if '"imu"' in b]
    assert json.loads("{" + quoted + "}")["imu"] == summary["time_shifts"]["imu"]
    headline = f"[drop7] health OK; {summary['headline']}"
    assert headline in out.err + out.out and f"\n{headline}\n" in text
    assert report.startswith("**Health: OK**") and f"**{summary['headline']}**" in report  # the scorecard
    header = next(ln for ln in export if not ln.startswith("#"))
    assert header.startswith("time [s],p.x [m],sigma_p.x [m],v.x [m/s]")
    assert "q_spf_body.w [1]" in header and header.endswith("stroke [m],sigma_stroke [m]")


#: the page's mistakes: (what is changed, the file's text -> the mistaken text, exit code, quoted text)
MISTAKES = {
    "unit": (
        "telemetry/imu.csv",
        lambda t: re.sub(r"^(time.*)$", lambda m: m.group(1).replace("[m/s^2]", "[g]"), t, count=1, flags=re.M),
        3,
        "column 'A1.x [g]' the hanging lander reads 10.12 g on triad A1 (expected 1 g at rest): "
        "the values look like [m/s^2], not [g]",
    ),
    "gyro unit": (
        "telemetry/imu.csv",
        lambda t: re.sub(r"^(time.*)$", lambda m: m.group(1).replace("[rad/s]", "[deg/s]"), t, count=1, flags=re.M),
        3,
        "the hanging gyro scatters 0.0174× its declared noise (sensors.gyro.noise_dps = 0.4): the values look like "
        "[rad/s], not [deg/s]",
    ),
    "swapped axis": (
        "telemetry/imu.csv",
        lambda t: t.replace("A2.y [m/s^2],A2.z [m/s^2]", "A2.z [m/s^2],A2.y [m/s^2]", 1),
        6,
        "units.hanging.A2: triad A2 while hanging: specific force (+8.47, +0.01, -4.83) m/s², 0.994 g, 41.31° from "
        "the other 3 triads (+8.46, -4.96, -0.05) = 69.8σ: y and z swapped",
    ),
    "nail": (
        "scenario.toml",
        lambda t: t.replace("# nail_depth_m = 0.3", "nail_depth_m = -0.3").replace(
            "ramp_point_m = [", "# ramp_point_m = [", 1
        ),
        6,
        "geometry.first_contact: airbag lobes +0.414 ± 0.073 m (1σ) from the ramp at the measured first touch "
        "(t = 1.3627 s, the last mean triad |f| ≤ 0.25 g before the 2 g onset at 1.3672 s); the bag pressures not "
        "declared, up to a lobe radius (1.000 m) pressed in, ± 0.006 m in one IMU sample; the estimated lobes touch "
        "the ramp at 1.3994 s: the declared geometry puts the bags clear of the ramp when the IMU feels the impact",
    ),
}


@pytest.mark.parametrize("mistake", list(MISTAKES))
def test_each_mistake_gives_the_message_the_tutorial_quotes(rig, mistake, tmp_path, capsys):
    root, _ = rig
    file, edit, code, quoted = MISTAKES[mistake]
    d = tmp_path / "myrig"
    shutil.copytree(root / "myrig", d)
    p = d / file
    text = p.read_text(encoding="utf-8")
    p.write_text(edit(text), encoding="utf-8")
    assert p.read_text(encoding="utf-8") != text
    capsys.readouterr()
    assert main(["run", str(d / "scenario.toml"), "--out", str(tmp_path / "runs"), "-q"]) == code
    err = capsys.readouterr().err
    assert quoted in _squash(err), err
    assert quoted in _squash(_text())  # the page quotes what the run says
    assert not list(tmp_path.glob("runs/*.rrd"))  # nothing written
    if mistake == "nail":  # the keys it names: rig 2's lander is given by its vertices
        assert "(height_m, cm_height_m or vertices_m, cm_m; lobe_diameter_m, standoff_m or lobe_centers_m)" in err
        assert "nail_depth_m (or ramp_point_m)" in err


def test_the_tutorial_is_linked_and_its_keys_exist():
    """The scenario block's keys are the droptest schema's, the page is in the README's list."""
    from workbench.problems import registry

    schema = registry.get("droptest").schema
    data = tomllib.loads(_toml_block("# myrig/scenario.toml"))
    for table, keys in (("chamber", data["chamber"]), ("sensors.acquisition", data["sensors"]["acquisition"])):
        for k in keys:
            assert schema.table(table).key(k) is not None, (table, k)
    assert schema.table("chamber").key("nail_depth_m") is not None  # the key the block comments out
    readme = (TUTORIAL.parents[1] / "README.md").read_text(encoding="utf-8")
    assert "TUTORIAL_DROPRIG.md (your own drop rig)" in readme
