"""The command line: ``list``, the errors for no scenarios / an unknown kind, and a ``run``.

The run uses the worked example problem (``tests/problems/example_fallingbody``, a few seconds),
registered for the test, so it also checks that the command line holds no problem knowledge.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from example_problem import registered_fallingbody  # tests/support, on sys.path via tests/conftest.py

from workbench.cli import EXIT_INPUT, EXIT_KIND, EXIT_OK, main
from workbench.problems import registry

EXAMPLE = Path(__file__).resolve().parent / "problems" / "example_fallingbody"


@pytest.fixture
def fallingbody():
    with registered_fallingbody("example_fallingbody_cli") as module:
        yield registry.get(module.FallingBodyProblem.kind)


def _assets(tmp_path, monkeypatch, scenarios: dict[str, str]) -> Path:
    """A stand-in shipped-assets folder holding ``scenarios`` {file name: TOML text}."""
    root = tmp_path / "assets"
    (root / "scenarios").mkdir(parents=True)
    for name, text in scenarios.items():
        (root / "scenarios" / name).write_text(text, encoding="utf-8")
    monkeypatch.setattr("workbench.io.assets.assets_dir", lambda: root)
    return root


def test_list_prints_every_shipped_scenario(capsys):
    assert main(["list"]) == EXIT_OK
    lines = capsys.readouterr().out.splitlines()
    rows = {ln.split()[0]: ln.split()[1:3] for ln in lines}
    assert rows["droptest"] == ["droptest", "(synthetic)"]
    assert rows["schiaparelli"] == ["entry", "(synthetic)"]
    assert len(lines) >= 5


def test_list_states_the_filter_size_the_code_builds(capsys):
    """``list`` prints each drop test's error-state count from the filter model, and no description
    types a state count of its own (it said "19-state" where the filter has 42 error states)."""
    import re

    from workbench.io.assets import assets_dir
    from workbench.io.scenario import find_scenarios, load_scenario
    from workbench.problems.droptest import model as rl
    from workbench.problems.droptest.config import DropSettings

    assert main(["list"]) == EXIT_OK
    lines = {ln.split()[0]: ln for ln in capsys.readouterr().out.splitlines()}
    checked = 0
    for name, path in find_scenarios(assets_dir()).items():
        sc = load_scenario(path)
        assert not re.search(r"\d+-state", sc.description), name
        if sc.kind != "droptest":
            continue
        n_x, n_e = rl.sizes(len(DropSettings.from_scenario(sc).accelerometer.triads))
        assert re.findall(r"(\d+) error states", lines[name]) == [str(n_e)], lines[name]
        assert f"({n_x} full)" in lines[name]
        checked += 1
    assert checked >= 4


def test_list_with_no_scenarios_is_an_error(tmp_path, monkeypatch, capsys):
    root = _assets(tmp_path, monkeypatch, {})
    assert main(["list"]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert "no scenarios found" in err and str(root / "scenarios") in err
    assert main(["run", "all", "--out", str(tmp_path / "out")]) == EXIT_INPUT
    assert not (tmp_path / "out").exists()


def test_list_marks_a_kind_without_problem(tmp_path, monkeypatch, capsys):
    _assets(tmp_path, monkeypatch, {"r.toml": '[scenario]\nname = "r"\nkind = "rocket"\ndescription = "d"\n'})
    assert main(["list"]) == EXIT_OK
    assert "rocket (no problem)" in capsys.readouterr().out


def test_unknown_kind_is_exit_code_5_and_names_the_known_kinds(tmp_path, capsys):
    toml = tmp_path / "rocket.toml"
    toml.write_text('[scenario]\nname = "r"\nkind = "rocket"\n', encoding="utf-8")
    out = tmp_path / "out"
    assert main(["run", str(toml), "--out", str(out)]) == EXIT_KIND
    err = capsys.readouterr().err
    assert str(toml) in err and "'rocket'" in err and "known kinds: droptest, entry" in err
    assert not out.exists()  # nothing written
    assert main(["mc", str(toml), "--out", str(out)]) == EXIT_KIND


def test_run_an_example_problem(fallingbody, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(EXAMPLE / "fallingbody.toml"), "--out", str(out), "--seed", "5"]) == EXIT_OK
    err = capsys.readouterr().err.splitlines()
    s = json.loads((out / "fallingbody.summary.json").read_text(encoding="utf-8"))
    assert s["seed"] == 5 and s["truth"]["h_inside_3sigma_fraction"] >= 0.99
    assert (out / "fallingbody.rrd").stat().st_size == s["recording_bytes"]
    assert not (out / "fallingbody.reconstruction.csv").exists()  # no --export
    # progress (stderr is not a terminal here: plain lines): the truth simulation and every stage
    # timed, one line each, then the problem's headline and the paths written
    stage = re.compile(r"^\[fallingbody\] (?P<label>\S.*?)\s+(?P<s>[0-9.]+) s$")
    timed = [stage.match(ln) for ln in err]
    labels = [m["label"] for m in timed if m]
    assert labels[:4] == ["fall truth simulation + telemetry", "BaroData", "ForwardStage", "FallResult"]
    assert "drawing the stages into the recording" in labels and "CSV export" not in labels
    # the summary keeps the same stage times (the run's own, as printed, rounded)
    for m in timed[:4]:  # printed with 2 decimals below 10 s, 1 from 10 s
        half_digit = 0.5 * 10.0 ** -len(m["s"].split(".")[1]) + 1e-4
        assert s["stage_times_s"][m["label"]] == pytest.approx(float(m["s"]), abs=half_digit)
    assert sum(s["stage_times_s"].values()) <= s["wall_time_s"]
    assert any(ln.startswith("[fallingbody] end altitude ") for ln in err)
    assert any(ln.startswith(f"[fallingbody] wrote {out / 'fallingbody.rrd'} (") for ln in err)
    assert f"[fallingbody] wrote {out / 'fallingbody.summary.json'}" in err


def test_run_export_prints_the_csv_path_and_quiet_prints_no_progress(fallingbody, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["run", str(EXAMPLE / "fallingbody.toml"), "--out", str(out), "--export"]
    assert main([*argv, "--quiet"]) == EXIT_OK
    err = capsys.readouterr().err.splitlines()
    csv = out / "fallingbody.reconstruction.csv"
    assert csv.is_file() and f"[fallingbody] wrote {csv} (--export)" in err
    # --quiet: only the result lines (headline, paths written), no stage lines, no counters
    assert all(ln.startswith(("[fallingbody] end altitude ", "[fallingbody] wrote ")) for ln in err), err
    assert len(err) == 5  # headline, .rrd, summary, telemetry folder, CSV
    assert main([*argv, "--progress", "plain"]) == EXIT_OK
    plain = capsys.readouterr().err.splitlines()
    assert any(re.match(r"^\[fallingbody\] CSV export\s+[0-9.]+ s$", ln) for ln in plain)

    def strip(ln: str) -> str:  # the wall time in the .rrd line differs between two runs
        return re.sub(r" in [0-9.]+ s$", "", ln)

    assert {strip(ln) for ln in err} <= {strip(ln) for ln in plain} and len(plain) >= len(err) + 6


def test_children_of_a_parallel_run_log_plain_lines():
    """``run A B --jobs 2``: the child processes share the terminal, so none draws bars."""
    from workbench.cli import build_parser, child_argv

    args = build_parser().parse_args(["run", "a", "b", "--jobs", "2"])
    assert child_argv("a", args)[-2:] == ["--progress", "plain"]
    args = build_parser().parse_args(["run", "a", "b", "--jobs", "2", "-q"])
    assert child_argv("a", args)[-1] == "--quiet" and "--progress" not in child_argv("a", args)


def test_unhealthy_run_exits_6_writes_nothing_unless_allowed(tmp_path, capsys):
    """post2_j2 (a fraction of a second) with a gravity noise 1σ declared 100× too small: the filter is
    inconsistent with its sensor, the health verdict is ERROR -> exit 6 and no output; with
    --allow-unhealthy the outputs are written and marked."""
    from workbench.cli import EXIT_UNHEALTHY
    from workbench.io.assets import assets_dir

    text = (assets_dir() / "scenarios" / "post2_j2.toml").read_text(encoding="utf-8")
    assert "sigma = 1.0e-5" in text
    sc = tmp_path / "j2 tight.toml"
    sc.write_text(text.replace("sigma = 1.0e-5", "sigma = 1.0e-7\nnoise_sigma = 1.0e-5"), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["run", str(sc), "--out", str(out)]) == EXIT_UNHEALTHY
    err = capsys.readouterr().err
    assert "health verdict ERROR" in err and "filter inconsistent with sensor gravity" in err
    assert not list(out.glob("*.rrd")) and not list(out.glob("*.summary.json"))
    assert main(["run", str(sc), "--out", str(out), "--allow-unhealthy"]) == EXIT_OK
    s = json.loads((out / "post2_j2.summary.json").read_text())
    assert s["health"]["verdict"] == "ERROR" and s["health"]["written_anyway"] is True
    assert (out / "post2_j2.rrd").exists() and "UNHEALTHY" in capsys.readouterr().err


@pytest.mark.parametrize("fork", [True, False], ids=["forked", "new-interpreter"])
def test_several_scenarios_run_in_processes_and_a_failure_stops_none(tmp_path, capfd, monkeypatch, fork):
    """``run A B --jobs 2``: each scenario in its own process; the unhealthy one (exit 6, nothing
    written) does not stop the healthy one, whose outputs equal a run in this process; the exit code
    is the failed scenario's and the failure is listed.  With bars (a terminal; forced here), the
    children's plain timed lines are piped through the parent, above its bar of finished scenarios."""
    from workbench.cli import EXIT_UNHEALTHY
    from workbench.io.assets import assets_dir

    monkeypatch.setenv("WORKBENCH_FORK", "1" if fork else "0")

    text = (assets_dir() / "scenarios" / "post2_j2.toml").read_text(encoding="utf-8")
    assert 'name = "post2_j2"' in text and "sigma = 1.0e-5" in text
    bad = tmp_path / "tight.toml"
    bad.write_text(
        text.replace('name = "post2_j2"', 'name = "j2_tight"').replace(
            "sigma = 1.0e-5", "sigma = 1.0e-7\nnoise_sigma = 1.0e-5"
        ),
        encoding="utf-8",
    )
    out, ref = tmp_path / "out", tmp_path / "ref"
    argv = ["run", str(bad), "post2_j2", "--out", str(out), "--jobs", "2", "--progress", "bars"]
    assert main(argv) == EXIT_UNHEALTHY
    err = capfd.readouterr().err
    assert "1 of 2 scenarios succeeded" in err and f"{bad}: exit {EXIT_UNHEALTHY}" in err
    lines = err.replace("\r", "\n").splitlines()
    assert f"[post2_j2] wrote {out / 'post2_j2.summary.json'}" in lines  # a child's line, through the parent
    assert any(re.match(r"^\[post2_j2\] \S.*\s[0-9.]+ s$", ln) for ln in lines)  # its timed stage lines
    assert any("scenarios finished" in ln for ln in lines)  # the parent's bar
    assert not (out / "j2_tight.rrd").exists() and not (out / "j2_tight.summary.json").exists()
    assert main(["run", "post2_j2", "--out", str(ref), "--jobs", "1"]) == EXIT_OK
    a = json.loads((out / "post2_j2.summary.json").read_text())
    b = json.loads((ref / "post2_j2.summary.json").read_text())
    assert a["health"] == b["health"] and a["truth"] == b["truth"]
