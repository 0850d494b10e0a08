"""post2 end to end through the command line: the Large-J2 validation case (thesis [R3] Table 3-1/3-2)
and the problem-file errors (each located, nothing written)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.io.assets import assets_dir
from workbench.io.telemetry import write_telemetry
from workbench.recording.reader import read_recording

J2_TOML = assets_dir() / "scenarios" / "post2_j2.toml"
EXIT_INPUT = 3


@pytest.fixture(scope="module")
def j2_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("post2_j2")
    assert main(["run", "post2_j2", "--out", str(out), "--export"]) == 0
    return out, json.loads((out / "post2_j2.summary.json").read_text(encoding="utf-8"))


def test_j2_is_recovered_within_its_3_sigma(j2_run):
    _, s = j2_run
    p = s["truth"]["parameters"]["j2"]
    assert p["truth"] == [1.9595e-3] and p["initial_error"] == [-1.9595e-3]
    # near zero after four observations (thesis Fig. 3-1): below 0.1 % of J2, and inside 3σ
    assert abs(p["error_after_4_obs"][0]) < 1e-3 * 1.9595e-3
    assert abs(p["error_after_4_obs"][0]) < 3.0 * p["sigma_after_4_obs"][0]
    assert p["inside_3sigma_at_end"] and abs(p["final_error_over_3sigma_forward"][0]) < 1.0
    g = s["observations"]["gravity"]
    assert g["samples"] == 100 and g["accepted"] == 100
    assert g["nis_verdict"] == "consistent"  # mean of 100 χ²(1) values inside its 99 % band (≈ 0.7 .. 1.4)


def test_j2_files_recording_and_export(j2_run):
    out, s = j2_run
    tel = out / "post2_j2" / "telemetry"
    assert (tel / "gravity.csv").is_file() and (tel / "truth.npz").is_file()
    rec = read_recording(out / "post2_j2.rrd")
    assert rec.row_count("/plots/j2/value/value") == s["grid_steps"]
    assert "j2" in rec.text_document("/report")
    assert (out / "post2_j2.reconstruction.csv").is_file()


def _bad(tmp_path: Path, old: str, new: str) -> Path:
    p = tmp_path / "bad.toml"
    text = J2_TOML.read_text(encoding="utf-8")
    assert old in text
    p.write_text(text.replace(old, new, 1), encoding="utf-8")
    return p


@pytest.mark.parametrize(
    ("old", "new", "expect"),
    [
        ("[states.j2]", "[states.j2x]", ["states.j2x", "unknown state 'j2x'", "did you mean 'j2'"]),
        ('quantity = "gravity_magnitude"', 'quantity = "gravity_magnitud"', ["did you mean 'gravity_magnitude'"]),
        ('process = "constant"', 'proces = "constant"', ["states.j2.proces", "did you mean 'process'"]),
        (
            "sigma = 2.0e-3 ",
            "bounds = [1.0, 0.5]\nsigma = 2.0e-3 ",
            ["states.j2.bounds", "lo (1) must be below hi (0.5)"],
        ),
        (
            "sigma = 2.0e-3 ",
            "bounds = [0.5, 0.5]\nsigma = 2.0e-3 ",
            ["states.j2.bounds", "lo (0.5) must be below hi (0.5)"],
        ),
        (
            "[truth]",
            '[schedules.late]\nobservation = "gravty"\nweight_factor = 2.0\n\n[truth]',
            ["schedules.late.observation", "unknown observation 'gravty'", "did you mean 'gravity'"],
        ),
        (
            "[truth]",
            '[schedules.late]\nstate = "cm_multiplier"\npsd = 1.0\n\n[truth]',
            ["schedules.late.state", "unknown estimated state 'cm_multiplier'"],
        ),
        (
            "[truth]",
            '[initial_correlation]\nstates = ["velocty"]\nmatrix = [[1.0]]\n\n[truth]',
            ["initial_correlation.states", "unknown estimated state 'velocty'"],
        ),
        (
            "[truth]",
            '[initial_correlation]\nstates = ["position"]\n'
            "matrix = [[1.0, 0.9, -0.9], [0.9, 1.0, 0.9], [-0.9, 0.9, 1.0]]\n\n[truth]",
            ["initial_correlation.matrix", "not positive semi-definite"],
        ),
        (
            "[truth]",
            '[initial_correlation]\nstates = ["position"]\nmatrix = [[1.0, 0.5], [0.5, 1.0]]\n\n[truth]',
            ["initial_correlation.matrix", "expected a 3×3 matrix"],
        ),
    ],
)
def test_problem_file_errors_are_located_and_nothing_is_written(tmp_path, capsys, old, new, expect):
    bad = _bad(tmp_path, old, new)
    assert main(["run", str(bad), "--out", str(tmp_path / "out")]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert "bad.toml" in err
    for e in expect:
        assert e in err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def _user_scenario(tmp_path: Path, j2_run, weights_rows: int | None, shift_s: float = 0.0) -> Path:
    """The J2 problem as user telemetry: the synthetic gravity file (times shifted by shift_s) and a
    weights file of ``weights_rows`` rows."""
    out, _ = j2_run
    src = out / "post2_j2" / "telemetry" / "gravity.csv"
    data = tmp_path / "data"
    data.mkdir()
    text = src.read_text(encoding="utf-8").splitlines()
    rows = [ln for ln in text if ln and not ln.startswith("#") and not ln.startswith("time")]
    t = np.array([float(r.split(",")[0]) for r in rows]) + shift_s
    g = np.array([float(r.split(",")[1]) for r in rows])
    write_telemetry(data / "gravity.csv", t, {"g": (g, "m/s^2")})
    toml = J2_TOML.read_text(encoding="utf-8").split("[truth]")[0]
    toml = toml.replace("sigma = 1.0e-5\n", 'file = "data/gravity.csv"\nweights = "data/w.csv"\n')
    n = weights_rows if weights_rows is not None else t.size
    write_telemetry(data / "w.csv", t[:n], {"g": (np.full(n, 1e10), "1")})
    p = tmp_path / "user.toml"
    p.write_text(toml, encoding="utf-8")
    return p


def test_user_telemetry_with_weights_file_runs(tmp_path, j2_run):
    sc = _user_scenario(tmp_path, j2_run, None)
    assert main(["run", str(sc), "--out", str(tmp_path / "out")]) == 0
    s = json.loads((tmp_path / "out" / "post2_j2.summary.json").read_text(encoding="utf-8"))
    assert "truth" not in s  # user data: no truth
    assert abs(s["states"]["j2"]["final"][0] - 1.9595e-3) < 3.0 * s["states"]["j2"]["final_sigma"][0]


def test_weights_file_shorter_than_observations_is_refused(tmp_path, j2_run, capsys):
    sc = _user_scenario(tmp_path, j2_run, 50)
    assert main(["run", str(sc), "--out", str(tmp_path / "out")]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert "observations.gravity.weights" in err and "shorter than its observations" in err
    assert "w.csv (column time, rows 1..50)" in err and "gravity.csv row 51 (5100 s) has no weight" in err
    assert not list((tmp_path / "out").glob("*.rrd")) and not list((tmp_path / "out").glob("*.json"))


def test_observation_outside_the_data_span_is_refused(tmp_path, j2_run, capsys):
    sc = _user_scenario(tmp_path, j2_run, None, shift_s=50.0)  # last sample at 10 050 s > t_end
    assert main(["run", str(sc), "--out", str(tmp_path / "out")]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert "observations.gravity" in err and "outside the data span" in err and "10050" in err
    assert "gravity.csv row 100 (column time)" in err and "(1 such rows)" in err
    assert not list((tmp_path / "out").glob("*.rrd")) and not list((tmp_path / "out").glob("*.json"))
    shutil.rmtree(tmp_path / "data")


def test_sliding_median_removes_an_outlier_and_keeps_the_raw_samples(tmp_path, j2_run):
    from workbench.io.scenario import load_scenario
    from workbench.io.telemetry import read_telemetry
    from workbench.problems.post2.config import Post2Settings
    from workbench.problems.post2.pipeline import read_observations

    sc_path = _user_scenario(tmp_path, j2_run, None)
    sc_path.write_text(
        sc_path.read_text(encoding="utf-8").replace(
            'file = "data/gravity.csv"', 'file = "data/gravity.csv"\nmedian_window = 3'
        ),
        encoding="utf-8",
    )
    tel = read_telemetry(tmp_path / "data" / "gravity.csv")
    g = np.array(tel.channel("g"))
    g[40] += 1.0  # a 1 m/s² spike
    write_telemetry(tmp_path / "data" / "gravity.csv", tel.time, {"g": (g, "m/s^2")})
    sc = load_scenario(sc_path)
    ch = read_observations(
        Post2Settings.from_scenario(sc),
        {"gravity": tmp_path / "data" / "gravity.csv", "gravity_weights": tmp_path / "data" / "w.csv"},
    ).channels["gravity"]
    k = int(np.flatnonzero(ch.t == tel.time[40])[0])
    assert ch.z_raw[k, 0] == pytest.approx(g[40])
    assert ch.z[k, 0] == pytest.approx(np.median(g[39:42]))
    np.testing.assert_allclose(ch.R[:, 0, 0], 1e-10)  # R = 1 / W
    # only whole windows: the edge samples (a window padded with copies of one raw sample) are dropped
    np.testing.assert_array_equal(ch.t, tel.time[1:-1])
    np.testing.assert_allclose(ch.z[:, 0], [np.median(g[i - 1 : i + 2]) for i in range(1, g.size - 1)])
