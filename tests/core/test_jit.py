"""Compiled-kernel cache state (``workbench.core.jit``) and the precompiling child
(``workbench.problems.precompile``): cold kernels are named, a call makes them warm, a module with
one kernel never called is not cold, and the child runs only when a module is cold."""

from __future__ import annotations

import importlib
import io
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest

from workbench.core.jit import cold_kernels, cold_modules
from workbench.io.progress import Reporter
from workbench.problems import precompile as pc

SOURCE = """
from numba import njit

@njit(cache=True)
def used(x):
    return 2.0 * x

@njit(cache=True)
def never_called(x):
    return x + 1.0

def plain(x):
    return x
"""


@pytest.fixture
def kernels(tmp_path, monkeypatch):
    """A throwaway module of two cached kernels in its own folder (numba's cache beside it)."""
    name = f"wb_jit_probe_{tmp_path.name.replace('-', '_')}"
    (tmp_path / f"{name}.py").write_text(textwrap.dedent(SOURCE), encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    yield name, importlib.import_module(name)
    sys.modules.pop(name, None)


def test_a_fresh_module_is_cold_and_a_call_warms_the_kernel_it_compiles(kernels):
    name, mod = kernels
    assert cold_kernels([mod]) == [f"{name}.never_called", f"{name}.used"]  # plain functions not listed
    assert cold_modules([mod]) == [name]
    assert mod.used(1.5) == 3.0
    assert cold_kernels([mod]) == [f"{name}.never_called"]
    # one kernel cached: the module is not cold (a kernel the scenario never calls must not make
    # every run precompile)
    assert cold_modules([mod]) == []


def test_a_module_without_cached_kernels_is_never_cold():
    import workbench.core.rotation as rotation

    assert cold_kernels([rotation]) == []
    assert cold_modules([rotation]) == []


def _rep():
    out = io.StringIO()
    return Reporter("plain", stream=out, prefix="[x] "), out


def test_the_child_runs_only_for_a_cold_module_and_not_when_switched_off(kernels, monkeypatch, tmp_path):
    name, mod = kernels
    calls = []

    def fake_run(argv, **kw):
        calls.append(argv)
        mod.used(1.0)  # what the child's run does: compile and cache
        return subprocess.CompletedProcess(argv, 0, "", "")

    monkeypatch.setattr(pc.subprocess, "run", fake_run)
    monkeypatch.setenv("WORKBENCH_FORK", "0")
    problem = SimpleNamespace(compiled_modules=(name,))
    sc = SimpleNamespace(path=tmp_path / "x.toml")
    monkeypatch.setenv(pc.ENV_SWITCH, "0")
    rep, out = _rep()
    assert pc.precompile(sc, problem, 3, rep) is False and calls == []
    monkeypatch.delenv(pc.ENV_SWITCH)
    assert pc.precompile(sc, problem, 3, rep) is True
    assert calls == [[sys.executable, "-m", "workbench.problems.precompile", str(sc.path), "--seed", "3"]]
    assert "compiling 2 kernels in a child process" in out.getvalue()
    assert pc.precompile(sc, problem, 3, rep) is False and len(calls) == 1  # warm now: no second child
    assert pc.precompile(sc, SimpleNamespace(), 3, rep) is False  # a problem without compiled kernels


def test_a_failing_child_is_reported_and_the_run_goes_on(kernels, monkeypatch, tmp_path):
    name, mod = kernels
    failed = subprocess.CompletedProcess([], 1, "", "Traceback\nValueError: boom\n")
    monkeypatch.setattr(pc.subprocess, "run", lambda argv, **kw: failed)
    monkeypatch.setenv("WORKBENCH_FORK", "0")
    rep, out = _rep()
    sc, problem = SimpleNamespace(path=Path("s.toml")), SimpleNamespace(compiled_modules=(name,))
    assert pc.precompile(sc, problem, 0, rep) is False
    assert "precompiling child exited 1 (ValueError: boom); compiling in this process" in out.getvalue()
    assert cold_modules([mod]) == [name]


def test_a_forked_child_compiles_for_the_run_and_its_failure_is_reported(kernels, monkeypatch, tmp_path):
    """POSIX: the child is forked from the run (its imports done); a child that fails is one progress
    line with its last line of output and the module stays cold; what a child compiles is cached
    for the run."""
    name, mod = kernels
    if not pc.fork_enabled():
        pytest.skip("no fork on this platform")
    parent = os.getpid()
    problem = SimpleNamespace(compiled_modules=(name,))
    sc = SimpleNamespace(path=tmp_path / "x.toml")

    def failing(argv):
        raise ValueError("boom")

    monkeypatch.setattr(pc, "main", failing)
    rep, out = _rep()
    assert pc.precompile(sc, problem, 0, rep) is False
    assert "precompiling child exited 1 (ValueError: boom); compiling in this process" in out.getvalue()
    assert cold_modules([mod]) == [name]

    def child_main(argv):
        assert os.getpid() != parent and argv == [str(sc.path), "--seed", "3"]
        mod.used(1.0)  # what the child's run does: compile and cache
        return 0

    monkeypatch.setattr(pc, "main", child_main)
    assert pc.precompile(sc, problem, 3, rep) is True
    assert cold_modules([mod]) == []


def test_a_monte_carlo_precompiles_before_its_workers_start(monkeypatch, tmp_path):
    """``workbench mc`` compiles a cold checkout's kernels once in a child before the study (its
    workers then load them) — the same call as ``workbench run``."""
    from workbench.problems import runner
    from workbench.problems.base import McOptions

    order = []
    monkeypatch.setattr(runner, "precompile", lambda sc, problem, seed, rep: order.append(("precompile", seed)))

    class Stop(Exception):
        pass

    def study(self, settings, out, options, rep):
        order.append(("study", options.first_seed))
        raise Stop

    sc, problem, _ = runner.prepare("droptest")
    monkeypatch.setattr(type(problem), "monte_carlo", study)
    with pytest.raises(Stop):
        runner.run_monte_carlo("droptest", tmp_path, McOptions(n_runs=1, first_seed=7), progress="none")
    assert order == [("precompile", 7), ("study", 7)]


@pytest.mark.parametrize(("env", "level"), [(None, 2), ("3", 3)])
def test_importing_the_workbench_sets_numbas_level_unless_the_user_did(env, level):
    """``import workbench`` sets ``NUMBA_OPT=2`` before any kernel compiles, and numba's config
    reads it; a user's own ``NUMBA_OPT`` wins."""
    code = "import workbench, numba.core.config as c; c.reload_config(); print(int(c.OPT))"
    e = {k: v for k, v in os.environ.items() if k != "NUMBA_OPT"}
    if env is not None:
        e["NUMBA_OPT"] = env
    e["PYTHONPATH"] = str(Path(__file__).resolve().parents[2])
    out = subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == str(level)
