"""Compile a scenario's numba kernels in a short child process before its run (first run only).

Compiling numba kernels leaves LLVM's memory resident in the compiling process: the drop test's
truth and filter kernels add about 115 MB to the first run of a fresh checkout (698 MB peak against
584 MB once the cache is written, measured with ``/usr/bin/time -f %M``). :func:`precompile` runs,
when a problem's kernels are not in numba's on-disk cache (:func:`workbench.core.jit.cold_kernels`),
the scenario's truth simulation and reconstruction once in a child process (forked from the run,
or ``python -m workbench.problems.precompile`` where there is no fork) that writes the cache and
exits, so the run itself loads the compiled kernels. The child writes nothing the run keeps (its
telemetry goes to a temporary folder) and its outcome never changes the run's: if it fails, the run
compiles in place, as before.

A problem opts in with a ``compiled_modules`` attribute (module names holding its cached kernels).
``WORKBENCH_PRECOMPILE=0`` turns the child off.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

from workbench.core.forking import fork_call, fork_enabled
from workbench.core.jit import cold_kernels, cold_modules, load_compiler
from workbench.io import progress as prog
from workbench.io.scenario import Scenario
from workbench.problems import registry
from workbench.problems.base import Problem, RunOptions

__all__ = ["ENV_SWITCH", "child_argv", "main", "precompile"]

ENV_SWITCH = "WORKBENCH_PRECOMPILE"
"""Environment variable: ``0`` turns the precompiling child off (the run compiles in place)."""


def child_argv(scenario: Scenario, seed: int) -> list[str]:
    """The child's command line: this module run on the scenario file with the run's seed."""
    return [sys.executable, "-m", "workbench.problems.precompile", str(scenario.path), "--seed", str(seed)]


def precompile(scenario: Scenario, problem: Problem, seed: int, rep: prog.Reporter) -> bool:
    """Compile ``problem``'s cached numba kernels in a child process if a module of them is cold
    (:func:`~workbench.core.jit.cold_modules`: none of its kernels cached).

    Returns True when a child ran and left no module cold, False when nothing was needed (no
    ``compiled_modules``, none cold, or ``WORKBENCH_PRECOMPILE=0``) or the child failed (one progress
    line says so, with its exit code and last line of output; the run then compiles in place).
    Interrupting the parent (Ctrl-C, SIGTERM) kills the child."""
    names = tuple(getattr(problem, "compiled_modules", ()) or ())
    if not names or os.environ.get(ENV_SWITCH, "1") == "0":
        return False
    modules = registry.import_modules(names)
    cold = cold_modules(modules)
    if not cold:
        return False
    n = len(cold_kernels([m for m in modules if m.__name__ in cold]))
    with rep.stage(f"compiling {n} kernels in a child process (first run of this checkout)"):
        code, output = _run_child(scenario, seed)
    if code != 0:
        last = output.strip().splitlines()[-1:] or [""]
        rep.line(f"precompiling child exited {code} ({last[0][:200]}); compiling in this process")
        return False
    return not cold_modules(modules)


def _run_child(scenario: Scenario, seed: int) -> tuple[int, str]:
    """Run :func:`main` on the scenario in a child process; (exit code, its stdout and stderr).

    Forked from the running process (its imports are done, ~2–3 s of CPU saved) unless
    ``WORKBENCH_FORK=0`` (:func:`~workbench.core.forking.fork_enabled`; then a new interpreter,
    ``python -m workbench.problems.precompile``), when the caller runs no other thread: the run
    calls this before it starts its recording. Any exception here (Ctrl-C, SIGTERM's
    ``Terminated``) kills the child first."""
    argv = [str(scenario.path), "--seed", str(seed)]
    if not fork_enabled():
        proc = subprocess.run(child_argv(scenario, seed), capture_output=True, text=True, errors="replace")
        return proc.returncode, proc.stderr or proc.stdout
    load_compiler()  # the run needs it too, to load what the child compiles
    with tempfile.TemporaryFile() as log:
        pid = fork_call(lambda: main(argv), stdout_fd=log.fileno(), stderr_fd=log.fileno())
        try:
            _, status = os.waitpid(pid, 0)
        except BaseException:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            raise
        log.seek(0)
        return os.waitstatus_to_exitcode(status), log.read().decode("utf-8", errors="replace")


def main(argv: list[str] | None = None) -> int:
    """Child entry: synthesize (into a temporary folder) and reconstruct the scenario, quietly, until
    no module of the problem's ``compiled_modules`` is cold (the reconstruction stops at the first
    stage after which all are cached: the drop test's forward filter), which compiles and caches the
    kernels the run calls. Exit 0 on success."""
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import resolve_scenario

    ap = argparse.ArgumentParser(prog="python -m workbench.problems.precompile", description=main.__doc__)
    ap.add_argument("scenario", help="scenario .toml path or shipped name")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    sc = resolve_scenario(args.scenario, assets_dir())  # validated by the parent run
    problem = registry.get(sc.kind, where=str(sc.path))
    settings = problem.settings(sc)
    with tempfile.TemporaryDirectory(prefix="workbench_precompile_") as tmp:
        if sc.is_synthetic:
            telemetry = dict(problem.synthesize(settings, Path(tmp) / "telemetry", args.seed).telemetry)
        else:
            telemetry = problem.telemetry_files(settings)
        modules = registry.import_modules(tuple(getattr(problem, "compiled_modules", ()) or ()))
        if not cold_modules(modules):
            return 0
        for _ in problem.reconstruct(settings, telemetry, RunOptions(seed=args.seed)):
            if not cold_modules(modules):
                break
    return 0


if __name__ == "__main__":
    sys.exit(main())
