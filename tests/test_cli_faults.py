"""Clean failure of the command line (issue 12, item 5): signals, unwritable or full output
locations, rejected runs, numerical failures, a closed pipe, a killed Monte Carlo worker.

Signals go to a real ``workbench`` process (a subprocess running the worked example problem of
``tests/problems/example_fallingbody``, slowed down inside its reconstruction so that the signal
arrives while the recording is being written). Exit codes are those of ``workbench/cli.py``.
"""

from __future__ import annotations

import errno
import io
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from example_problem import registered_fallingbody  # tests/support, on sys.path via tests/conftest.py

from workbench import cli
from workbench.recording.writer import remove_stale_partials

HERE = Path(__file__).resolve().parent
EXAMPLE = HERE / "problems" / "example_fallingbody"
SCENARIO = EXAMPLE / "fallingbody.toml"

# registers the example problem, makes its reconstruction pause after the first stage (long enough
# for a signal) unless WB_NO_PAUSE is set, and runs the command line
DRIVER = textwrap.dedent(
    f"""
    import importlib.util, os, sys, time
    spec = importlib.util.spec_from_file_location("example_fallingbody", {str(EXAMPLE / "fallingbody.py")!r})
    m = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = m
    spec.loader.exec_module(m)
    from workbench.problems import registry
    from workbench.cli import main
    original = m.FallingBodyProblem.reconstruct
    def slow(self, *a, **k):
        for i, stage in enumerate(original(self, *a, **k)):
            yield stage
            if i == 0 and not os.environ.get("WB_NO_PAUSE"):
                print("PAUSED", file=sys.stderr, flush=True)
                time.sleep(60)
    m.FallingBodyProblem.reconstruct = slow
    registry.register(m.FallingBodyProblem())
    sys.exit(main(sys.argv[1:]))
    """
)


def _start(out: Path, env_extra: dict | None = None, user: int | None = None) -> subprocess.Popen:
    env = dict(os.environ, OMP_NUM_THREADS="1", **(env_extra or {}))
    cmd = [sys.executable, "-c", DRIVER, "run", str(SCENARIO), "--out", str(out)]
    if user is not None:
        cmd = ["setpriv", f"--reuid={user}", f"--regid={user}", "--clear-groups", *cmd]
    return subprocess.Popen(
        cmd,
        env=env,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a background job ignores it
    )


def _wait_paused(p: subprocess.Popen, timeout: float = 120.0) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = p.stderr.readline()
        if "PAUSED" in line:
            return
        if not line and p.poll() is not None:
            break
    p.kill()
    raise AssertionError("the run never reached its pause")


@pytest.mark.parametrize(
    ("sig", "code"), [(signal.SIGTERM, 143), pytest.param(signal.SIGINT, 130, marks=pytest.mark.slow)]
)
def test_sigterm_and_sigint_remove_the_partial(tmp_path, sig, code):
    out = tmp_path / "out"
    p = _start(out)
    _wait_paused(p)
    assert list(out.glob("*.partial")), "the recording is being written during the pause"
    p.send_signal(sig)
    err = p.communicate(timeout=120)[1]
    assert p.returncode == code, err
    assert "Traceback" not in err
    assert not list(out.glob("*.partial")) and not (out / "fallingbody.rrd").exists()
    assert ("terminated" if sig == signal.SIGTERM else "interrupted") in err


def test_sigterm_stops_every_scenario_process_of_a_multi_job_run(tmp_path):
    """``run A B --jobs 2`` (each scenario in a process forked from the command's): SIGTERM to the
    command reaches both running scenarios, each removes its partial recording, none is left
    running, and the command exits 143."""
    second = tmp_path / "fallingbody_b.toml"
    text = SCENARIO.read_text(encoding="utf-8")
    assert 'name = "fallingbody"' in text
    second.write_text(text.replace('name = "fallingbody"', 'name = "fallingbody_b"'), encoding="utf-8")
    out = tmp_path / "out"
    cmd = [sys.executable, "-c", DRIVER, "run", str(SCENARIO), str(second), "--jobs", "2", "--out", str(out)]
    p = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    paused, t0 = 0, time.monotonic()
    while paused < 2 and time.monotonic() - t0 < 120:
        line = p.stderr.readline()
        paused += "PAUSED" in line
        if not line and p.poll() is not None:
            break
    assert paused == 2, "both scenario processes reach their pause"
    children = subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True, text=True).stdout.split()
    assert len(children) == 2
    assert len(list(out.glob("*.partial"))) == 2
    p.send_signal(signal.SIGTERM)
    err = p.communicate(timeout=120)[1]
    assert p.returncode == 143, err
    assert "Traceback" not in err
    assert err.count("terminated (SIGTERM)") == 3  # both scenarios and the command
    assert not list(out.glob("*.partial")) and not list(out.glob("*.rrd"))
    for pid in children:
        assert not Path(f"/proc/{pid}").exists()


def test_sigkill_partial_removed_by_the_next_run(tmp_path, fallingbody):
    out = tmp_path / "out"
    p = _start(out)
    _wait_paused(p)
    p.kill()
    p.wait(timeout=60)
    stale = list(out.glob("*.partial"))
    assert len(stale) == 1  # a killed process cannot clean up
    # a partial of a live process (a run in progress) is left alone
    live = out / f"fallingbody.rrd.{os.getppid()}.partial"
    live.write_bytes(b"")
    assert cli.main(["run", str(SCENARIO), "--out", str(out)]) == 0
    assert not stale[0].exists() and live.exists()
    assert (out / "fallingbody.rrd").is_file()
    assert remove_stale_partials(out / "fallingbody.rrd") == []


def _world_readable(root: Path) -> bool:
    """True if every folder from / down to ``root`` lets other users in (o+x) and ``root`` is o+r."""
    for d in [*reversed(root.parents), root]:
        if not os.stat(d).st_mode & 0o001:
            return False
    return bool(os.stat(root).st_mode & 0o004)


def _readonly_dir() -> Path:
    base = Path(tempfile.mkdtemp(prefix="wb-ro-"))
    os.chmod(base, 0o755)
    ro = base / "ro"
    ro.mkdir()
    os.chmod(ro, 0o555)
    return ro


@pytest.mark.parametrize(
    "sub",
    [pytest.param(False, marks=pytest.mark.slow), True],
    ids=["read-only folder", "new folder in a read-only folder"],
)
def test_read_only_output_is_a_located_error(sub):
    ro = _readonly_dir()
    try:
        out = ro / "new" if sub else ro
        user = None
        if os.geteuid() == 0:  # root ignores permissions: run as an unprivileged user
            if shutil.which("setpriv") is None:
                pytest.skip("running as root without setpriv: cannot make a folder read-only")
            if not _world_readable(Path(__file__).resolve().parents[1]):
                pytest.skip(
                    "running as root in a checkout that an unprivileged user cannot read "
                    "(e.g. a clone under a 0700 mkdtemp folder): cannot run the CLI as that user"
                )
            user = 65534
        p = _start(out, {"WB_NO_PAUSE": "1"}, user=user)
        err = p.communicate(timeout=300)[1]
        assert p.returncode == cli.EXIT_OUTPUT, err
        assert "Traceback" not in err and str(out) in err and "ermission denied" in err
        assert list(ro.iterdir()) == []
    finally:
        os.chmod(ro, 0o755)
        shutil.rmtree(ro.parent, ignore_errors=True)


@pytest.fixture
def fallingbody():
    with registered_fallingbody(replace=False) as module:
        yield module


def test_output_below_a_file_is_a_located_error(tmp_path, fallingbody, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    assert cli.main(["run", str(SCENARIO), "--out", str(f / "out")]) == cli.EXIT_OUTPUT
    err = capsys.readouterr().err
    assert "Not a directory" in err and str(f / "out") in err


@pytest.mark.parametrize("where", ["recording", "summary"])
def test_full_disk_is_a_located_error_and_leaves_nothing(tmp_path, fallingbody, monkeypatch, capsys, where):
    def enospc(*_a, **_k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    out = tmp_path / "new" / "out"
    if where == "recording":
        import workbench.recording.writer as writer

        monkeypatch.setattr(writer.os, "fsync", enospc)  # the recording's final flush to disk
    else:
        from workbench.problems import runner

        def summary_enospc(path, *_a, **_k):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

        monkeypatch.setattr(runner, "write_summary", summary_enospc)
    assert cli.main(["run", str(SCENARIO), "--out", str(out)]) == cli.EXIT_OUTPUT
    err = capsys.readouterr().err
    assert "No space left on device" in err and str(out) in err and "Traceback" not in err
    assert not list(out.glob("*.partial"))
    assert (out / "fallingbody.rrd").exists() == (where == "summary")  # published only if it was complete


def test_rerun_writer_failure_is_a_located_error(tmp_path, fallingbody, monkeypatch, capsys):
    import rerun as rr

    def dead(self, *a, **k):
        raise RuntimeError("File-writer thread shut down prematurely")

    monkeypatch.setattr(rr.RecordingStream, "flush", dead)
    out = tmp_path / "out"
    assert cli.main(["run", str(SCENARIO), "--out", str(out)]) == cli.EXIT_OUTPUT
    err = capsys.readouterr().err
    assert "cannot write the recording" in err and "MB free" in err
    assert not list(out.glob("*.partial")) and not (out / "fallingbody.rrd").exists()


def test_rejected_user_run_creates_no_output_folder(tmp_path, capsys):
    data = tmp_path / "data"
    data.mkdir()
    shutil.copy(
        Path(cli.__file__).resolve().parents[1] / "assets" / "landers" / "mer_drop_lander.toml", data / "lander.toml"
    )
    (data / "imu.csv").write_text("time [s],BP.x [g]\n")  # header only
    for name in ("3dm.csv", "events.csv"):
        (data / name).write_text("time [s],x\n0,1\n")
    (data / "setup.toml").write_text("[hanging]\nposition_m = [0, 0, 5]\nposition_sigma_m = 0.03\n")
    sc = data / "drop.toml"
    sc.write_text(
        textwrap.dedent(
            """
            [scenario]
            name = "drop"
            kind = "droptest"
            [vehicle]
            lander = "lander.toml"
            [chamber]
            magnetic_field_spf = [0.12, 0.33, -0.936]
            [telemetry]
            imu = "imu.csv"
            attitude_3dm = "3dm.csv"
            events = "events.csv"
            setup = "setup.toml"
            """
        )
    )
    out = tmp_path / "out"
    assert cli.main(["run", str(sc), "--out", str(out)]) == cli.EXIT_INPUT
    assert "imu.csv" in capsys.readouterr().err
    assert not out.exists()


def test_numerical_failure_names_the_stage(tmp_path, fallingbody, monkeypatch, capsys):
    original = fallingbody.FallingBodyProblem.reconstruct

    def broken(self, *a, **k):
        it = original(self, *a, **k)
        yield next(it)
        raise np.linalg.LinAlgError("innovation covariance S is not positive definite")

    monkeypatch.setattr(fallingbody.FallingBodyProblem, "reconstruct", broken)
    out = tmp_path / "out"
    assert cli.main(["run", str(SCENARIO), "--out", str(out)]) == cli.EXIT_NUMERIC
    err = capsys.readouterr().err
    assert "stage after BaroData" in err and str(SCENARIO) in err
    assert not list(out.glob("*.partial")) and not (out / "fallingbody.rrd").exists()


def test_closed_pipe_exits_quietly(monkeypatch, capsys):
    class Closed(io.StringIO):
        def write(self, s):
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")

    monkeypatch.setattr(sys, "stdout", Closed())
    assert cli.main(["list"]) == cli.EXIT_PIPE
    assert capsys.readouterr().err == ""


def test_killed_monte_carlo_worker_leaves_no_orphan_folder(tmp_path, monkeypatch):
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import resolve_scenario
    from workbench.problems.droptest import montecarlo

    def killed_member(settings, seeds, work, scheduler, workers):
        # what a SIGKILLed worker leaves: its member folder, never deleted (the member is redone)
        (work / "seed000003_abcd").mkdir()
        (work / "seed000003_abcd" / "imu.csv").write_text("x")
        return "done"

    monkeypatch.setattr(montecarlo, "_monte_carlo", killed_member)
    from workbench.problems.droptest.problem import DropTestProblem

    sc = DropTestProblem().settings(resolve_scenario("droptest", assets_dir()))
    work = tmp_path / "droptest_mc_work"
    assert montecarlo.monte_carlo(sc, [3], work) == "done"
    assert list(tmp_path.iterdir()) == []
    work.mkdir()  # a folder the caller made is kept, emptied of orphans
    (work / "keep.txt").write_text("x")
    montecarlo.monte_carlo(sc, [3], work)
    assert [p.name for p in work.iterdir()] == ["keep.txt"]
