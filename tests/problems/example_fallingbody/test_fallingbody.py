"""The worked example problem (``fallingbody.py``), registered by this test only, run end to end
through the command line: ``workbench run <path.toml>``.

It shows that a problem outside the package plugs into the registry and the generic runner: the
summary JSON, the recording and the CSV export are written, and the smoothed altitude is
consistent with the synthetic truth.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.io.telemetry import read_telemetry
from workbench.problems import registry
from workbench.recording.reader import read_recording

HERE = Path(__file__).resolve().parent
SCENARIO = HERE / "fallingbody.toml"


@pytest.fixture(scope="module")
def problem():
    spec = importlib.util.spec_from_file_location("example_fallingbody", HERE / "fallingbody.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    p = registry.register(module.FallingBodyProblem())
    yield p
    registry.unregister(p.kind)
    sys.modules.pop(spec.name, None)


@pytest.fixture(scope="module")
def run(problem, tmp_path_factory):
    out = tmp_path_factory.mktemp("fallingbody")
    code = main(["run", str(SCENARIO), "--out", str(out), "--export"])
    assert code == 0
    return out, json.loads((out / "fallingbody.summary.json").read_text(encoding="utf-8"))


def test_registered_kind_is_listed(problem):
    assert "fallingbody" in registry.kinds()
    assert registry.get("fallingbody") is problem
    with pytest.raises(ValueError, match="already"):
        registry.register(problem)


def test_summary_altitude_within_3_sigma_of_truth(run):
    _, s = run
    tr = s["truth"]
    assert s["kind"] == "fallingbody" and s["seed"] == 3 and s["samples"] == 801
    assert tr["h_inside_3sigma_fraction"] >= 0.99
    assert tr["max_normalized_h_error"] < 4.0
    assert tr["rms_h_error_m"] < s["end"]["sigma_h_m"] * 3.0
    assert abs(tr["bias_error_pa"]) < 3.0 * s["bias_pa"]["sigma"]
    # the body fell: about 1.5 km in 40 s near its terminal velocity (~ -43 m/s)
    assert 1000.0 < s["end"]["h_m"] < 2000.0 and -50.0 < s["end"]["v_mps"] < -35.0


def test_recording_and_files_written(run):
    out, s = run
    rrd = out / "fallingbody.rrd"
    assert Path(s["recording"]) == rrd and s["recording_bytes"] == rrd.stat().st_size
    assert not list(out.glob("*.partial"))  # published atomically
    rec = read_recording(rrd)
    assert rec.row_count("/plots/altitude/smoothed") == s["samples"]
    assert "inside 3σ" in rec.text_document("/report")
    assert (out / "fallingbody" / "telemetry" / "baro.csv").is_file()  # what a user would supply
    csv = read_telemetry(out / "fallingbody.reconstruction.csv")
    assert np.isclose(csv.channel("h")[-1], s["end"]["h_m"], rtol=1e-9)


def test_no_monte_carlo_is_exit_code_5(problem, tmp_path, capsys):
    assert main(["mc", str(SCENARIO), "--out", str(tmp_path)]) == 5
    assert "no Monte Carlo" in capsys.readouterr().err


def test_misspelt_key_is_refused_by_the_schema(problem, tmp_path, capsys):
    """The runner checks every scenario against its problem's schema before anything runs."""
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENARIO.read_text().replace("noise_pa =", "noise_pa_ =", 1))
    assert main(["run", str(bad), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert "bad.toml" in err and "barometer" in err and "noise_pa_" in err and "did you mean 'noise_pa'" in err
    assert not (tmp_path / "out" / "fallingbody.rrd").exists()


def test_runner_releases_each_stage_before_it_draws_the_next(problem, tmp_path, monkeypatch):
    """The generic runner holds no earlier stage while it draws the next (a long log's stages are
    hundreds of MB of covariance histories): once a stage is drawn, only the problem keeps it."""
    import gc
    import weakref

    drawer = sys.modules["example_fallingbody"]._Drawer
    seen: dict[str, object] = {}

    def watched(name: str, orig):
        def wrapped(self, stage):
            gc.collect()
            seen[f"alive when {name} draws"] = [k for k, ref in seen.items() if k.startswith("ref") and ref()]
            seen[f"ref {name}"] = weakref.ref(stage)
            orig(self, stage)

        return wrapped

    for name in ("_baro", "_forward", "_result"):
        monkeypatch.setattr(drawer, name, watched(name, getattr(drawer, name)))
    assert main(["run", str(SCENARIO), "--out", str(tmp_path), "--quiet"]) == 0
    assert seen["alive when _forward draws"] == [] and seen["alive when _result draws"] == []


def test_the_run_reads_the_telemetry_its_precompiling_child_synthesized(problem, run, tmp_path, monkeypatch):
    """On a checkout's first run the precompiling child synthesizes for the run: the runner hands it
    the run's settings, seed and telemetry folder and reads what it lists instead of synthesizing
    again, with the same summary as a run that synthesized itself."""
    from workbench.problems import runner
    from workbench.problems.precompile import Compiled

    handed = {}
    synthesize = type(problem).synthesize

    def child(sc, problem_, seed, rep, *, settings=None, telemetry=None):
        handed.update(seed=seed, settings=settings, telemetry=telemetry)
        return Compiled(synthesize(problem_, settings, telemetry, seed))

    def no_second_synthesis(self, settings, out_dir, seed):
        raise AssertionError("the run synthesized although its child had")

    monkeypatch.setattr(runner, "precompile", child)
    monkeypatch.setattr(type(problem), "synthesize", no_second_synthesis)
    out = tmp_path / "out"
    assert main(["run", str(SCENARIO), "--out", str(out), "--quiet"]) == 0
    assert handed["seed"] == 3 and handed["telemetry"] == out / "fallingbody" / "telemetry"
    assert handed["settings"] is not None
    mine = json.loads((out / "fallingbody.summary.json").read_text(encoding="utf-8"))
    _, theirs = run
    assert mine["truth"] == theirs["truth"]
