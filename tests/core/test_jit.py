"""Compiled kernels (``workbench.core.jit``) and the precompiling child
(``workbench.problems.precompile``): every kernel compiles with one set of options, cold kernels are
named, a call makes them warm, a module with one kernel never called is not cold, the child runs
only when a module is cold, and numba's registries load once before a fork."""

from __future__ import annotations

import gc
import importlib
import io
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest

from workbench.core.jit import KERNEL_OPTIONS, cold_kernels, cold_modules, njit
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
    assert pc.precompile(sc, problem, 3, rep) is None and calls == []
    monkeypatch.delenv(pc.ENV_SWITCH)
    assert pc.precompile(sc, problem, 3, rep) == pc.Compiled(None)
    assert calls == [[sys.executable, "-m", "workbench.problems.precompile", str(sc.path), "--seed", "3"]]
    assert "compiling 2 kernels in a child process" in out.getvalue()
    assert pc.precompile(sc, problem, 3, rep) is None and len(calls) == 1  # warm now: no second child
    assert pc.precompile(sc, SimpleNamespace(), 3, rep) is None  # a problem without compiled kernels


def test_a_failing_child_is_reported_and_the_run_goes_on(kernels, monkeypatch, tmp_path):
    name, mod = kernels
    failed = subprocess.CompletedProcess([], 1, "", "Traceback\nValueError: boom\n")
    monkeypatch.setattr(pc.subprocess, "run", lambda argv, **kw: failed)
    monkeypatch.setenv("WORKBENCH_FORK", "0")
    rep, out = _rep()
    sc, problem = SimpleNamespace(path=Path("s.toml")), SimpleNamespace(compiled_modules=(name,))
    assert pc.precompile(sc, problem, 0, rep) is None
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

    def failing(scenario, problem_, settings, seed, telemetry, manifest):
        raise ValueError("boom")

    monkeypatch.setattr(pc, "compile_by_running", failing)
    rep, out = _rep()
    assert pc.precompile(sc, problem, 0, rep) is None
    assert "precompiling child exited 1 (ValueError: boom); compiling in this process" in out.getvalue()
    assert cold_modules([mod]) == [name]

    def child(scenario, problem_, settings, seed, telemetry, manifest):
        assert os.getpid() != parent and (scenario, problem_, settings, seed) == (sc, problem, "S", 3)
        assert telemetry is None and manifest is None  # no folder handed over
        mod.used(1.0)  # what the child's run does: compile and cache
        return 0

    monkeypatch.setattr(pc, "compile_by_running", child)
    assert pc.precompile(sc, problem, 3, rep, settings="S") == pc.Compiled(None)
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


def test_the_kernel_decorator_is_numbas_with_the_workbench_options():
    """Bare or called, :func:`njit` gives a cached numba dispatcher with :data:`KERNEL_OPTIONS`;
    options given add to them. A division by zero is IEEE's (``error_model="numpy"``)."""

    def div(a, b):
        return a / b

    bare, called = njit(div), njit(nogil=True)(div)
    expected = {k: v for k, v in KERNEL_OPTIONS.items() if k != "cache"}
    assert {k: bare.targetoptions[k] for k in expected} == expected
    assert called.targetoptions["nogil"] is True and called.targetoptions["error_model"] == "numpy"
    assert type(bare._cache).__name__ == "FunctionCache"  # cache=True
    uncached = njit(div, cache=False)  # compiled here without writing a cache beside this file
    assert type(uncached._cache).__name__ == "NullCache"
    assert uncached(1.0, 0.0) == math.inf and math.isnan(uncached(0.0, 0.0))


def test_every_workbench_kernel_is_declared_with_the_workbench_decorator():
    """numba compiles its own implementations once per set of options of the kernels typing them:
    a kernel declared with ``numba.njit`` and other options would compile them again. Only the
    ensemble's member kernel (its own options: it releases the GIL for threads, and the module
    runs without numba) is declared with numba's decorator."""
    root = Path(__file__).resolve().parents[2] / "workbench"
    direct = []
    for path in sorted(root.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if "from numba import njit" in text or "numba.njit(" in text or "@jit" in text:
            direct.append(path.relative_to(root).as_posix())
    assert direct == ["core/jit.py", "estimation/ensemble.py"]


def test_the_kernels_of_every_problem_have_the_workbench_options():
    """The dispatchers of every built-in problem's compiled modules carry :data:`KERNEL_OPTIONS`."""
    from workbench.problems import registry

    expected = {k: v for k, v in KERNEL_OPTIONS.items() if k != "cache"}
    names = sorted({m for kind in registry.kinds() for m in getattr(registry.get(kind), "compiled_modules", ())})
    assert len(names) >= 5
    seen = 0
    for mod in registry.import_modules(tuple(names)):
        for obj in vars(mod).values():
            if hasattr(obj, "targetoptions") and getattr(obj.py_func, "__module__", None) == mod.__name__:
                assert {k: obj.targetoptions.get(k) for k in expected} == expected, f"{mod.__name__}.{obj.__name__}"
                assert "nogil" not in obj.targetoptions, f"{mod.__name__}.{obj.__name__}"
                seen += 1
    assert seen >= 40


def test_numbas_registries_load_before_a_fork():
    """:func:`load_compiler` loads what numba otherwise loads at each process's first compile or
    cache load (its lowering registries, its runtime), so forked children inherit them; the
    scheduler of ``run all`` and the precompiling child's parent call it before they fork."""
    code = (
        "import sys, workbench.core.jit as j\n"
        "from numba.core.runtime.nrt import rtsys\n"
        "before = ('numba.np.linalg' in sys.modules, rtsys._init)\n"
        "j.load_compiler(); j.load_compiler()\n"
        "print(before, ('numba.np.linalg' in sys.modules, rtsys._init))"
    )
    e = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    out = subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(False, False) (True, True)"


def test_run_all_loads_numbas_registries_once_before_its_first_fork(monkeypatch, tmp_path):
    """The scheduler of several scenarios imports :data:`PRELOAD` and calls :func:`load_compiler`
    before it forks its first scenario process (not at all when it starts new interpreters)."""
    from workbench.problems import scheduler

    events = []

    class FakeChild:
        def __init__(self, argv, entry, pipe, fork):
            events.append(("child", argv[0], fork))
            self.fd, self.eof, self.returncode = None, True, 0

        def poll(self):
            return 0

        def lines(self, final=False):
            return []

    monkeypatch.setattr(scheduler, "Child", FakeChild)
    monkeypatch.setattr(scheduler, "load_compiler", lambda: events.append(("load_compiler",)))
    monkeypatch.setattr(
        scheduler.registry,
        "import_modules",
        lambda names: events.append(("import", len(names), "gc off" if not gc.isenabled() else "gc on")),
    )
    rep, _ = _rep()
    for fork in (True, False):
        events.clear()
        monkeypatch.setenv("WORKBENCH_FORK", "1" if fork else "0")
        code = scheduler.run_in_processes(
            ["a", "b"], lambda n: [n], 2, tmp_path, rep, entry=lambda argv: 0, progress=lambda text: None
        )
        assert code == 0
        forked = fork and pc.fork_enabled()
        head = [("import", len(scheduler.PRELOAD), "gc off"), ("load_compiler",)] if forked else []
        assert events == [*head, ("child", "a", forked), ("child", "b", forked)]


def _probe_problem(module, tmp_path):
    """A synthetic scenario file of a probe problem whose reconstruction calls the module's kernel,
    and the problem (it synthesizes one CSV holding the seed, and a truth file)."""
    from workbench.io.scenario import load_scenario
    from workbench.problems.base import Synthesized

    toml = tmp_path / "probe.toml"
    toml.write_text('[scenario]\nname = "probe"\nkind = "probe"\n\n[synthetic]\nseed = 0\n', encoding="utf-8")

    class Probe:
        compiled_modules = (module.__name__,)

        def settings(self, scenario):
            return scenario

        def synthesize(self, settings, out_dir, seed):
            out_dir.mkdir(parents=True, exist_ok=True)
            (out_dir / "imu.csv").write_text(f"seed {seed} {settings.description}\n", encoding="utf-8")
            (out_dir / "truth.npz").write_bytes(b"truth")
            return Synthesized(telemetry={"imu": out_dir / "imu.csv"}, truth=out_dir / "truth.npz")

        def reconstruct(self, settings, telemetry, options):
            module.used(1.0)  # compiles and caches the module's kernel
            yield "stage"

    return load_scenario(toml), Probe()


def test_the_forked_child_synthesizes_the_runs_own_scenario_for_the_run_to_read(kernels, tmp_path):
    """A synthetic run hands the forked child its telemetry folder: the child synthesizes the run's
    own scenario (overrides included: it is the run's object, not the file) with the run's seed into
    a temporary folder, and what it wrote is moved into the run's folder and listed for the run."""
    from workbench.problems.base import Synthesized

    name, mod = kernels
    if not pc.fork_enabled():
        pytest.skip("no fork on this platform")
    sc, probe = _probe_problem(mod, tmp_path)
    sc = sc.with_overrides({"scenario.description": "edited in memory"})
    tel = tmp_path / "out" / "probe" / "telemetry"
    rep, _ = _rep()
    got = pc.precompile(sc, probe, 7, rep, telemetry=tel)
    assert got == pc.Compiled(Synthesized(telemetry={"imu": tel / "imu.csv"}, truth=tel / "truth.npz"))
    assert (tel / "imu.csv").read_text(encoding="utf-8") == "seed 7 edited in memory\n"
    assert sorted(p.name for p in tel.iterdir()) == ["imu.csv", "truth.npz"]
    assert cold_modules([mod]) == []


def test_a_child_that_fails_after_synthesizing_leaves_the_runs_folder_untouched(kernels, tmp_path):
    """The child writes into a temporary folder: a child that fails (or is killed) after its
    synthesis moves nothing into the run's telemetry folder, and the run synthesizes itself."""
    name, mod = kernels
    if not pc.fork_enabled():
        pytest.skip("no fork on this platform")
    sc, probe = _probe_problem(mod, tmp_path)

    def broken(settings, telemetry, options):
        raise RuntimeError("reconstruction failed")
        yield

    probe.reconstruct = broken
    tel = tmp_path / "out" / "probe" / "telemetry"
    rep, out = _rep()
    assert pc.precompile(sc, probe, 7, rep, telemetry=tel) is None
    assert "RuntimeError: reconstruction failed" in out.getvalue() and not (tmp_path / "out").exists()
    assert cold_modules([mod]) == [name]


@pytest.mark.parametrize("overridden", [False, True])
def test_without_fork_the_child_is_handed_the_folder_only_for_the_scenario_as_on_disk(
    kernels, monkeypatch, tmp_path, overridden
):
    """Where there is no fork the child is a new interpreter that reads the scenario file: it gets
    ``--telemetry``/``--manifest`` only when the file still reads as the run's scenario; what it
    listed is moved into the run's folder."""
    from workbench.problems.base import Synthesized

    name, mod = kernels
    sc, probe = _probe_problem(mod, tmp_path)
    if overridden:
        sc = sc.with_overrides({"scenario.description": "edited in memory"})
    calls = []

    def fake_run(argv, **kw):  # what ``python -m workbench.problems.precompile ARGV`` does
        calls.append(argv)
        args = argv[3:]
        tel = Path(args[args.index("--telemetry") + 1]) if "--telemetry" in args else None
        man = Path(args[args.index("--manifest") + 1]) if "--manifest" in args else None
        pc.compile_by_running(sc, probe, None, int(args[2]), tel, man)
        return subprocess.CompletedProcess(argv, 0, "", "")

    monkeypatch.setattr(pc.subprocess, "run", fake_run)
    monkeypatch.setenv("WORKBENCH_FORK", "0")
    tel = tmp_path / "out" / "probe" / "telemetry"
    rep, _ = _rep()
    got = pc.precompile(sc, probe, 7, rep, telemetry=tel)
    assert len(calls) == 1 and ("--telemetry" in calls[0]) == (not overridden)
    if overridden:
        assert got == pc.Compiled(None) and not tel.exists()
    else:
        assert got == pc.Compiled(Synthesized(telemetry={"imu": tel / "imu.csv"}, truth=tel / "truth.npz"))
        assert (tel / "imu.csv").read_text(encoding="utf-8") == "seed 7 \n"
