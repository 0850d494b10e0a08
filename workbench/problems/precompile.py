"""Compile a scenario's numba kernels in a short child process before its run (first run only).

Compiling numba kernels leaves LLVM's memory resident in the compiling process: the drop test's
truth and filter kernels add about 115 MB to the first run of a fresh checkout (698 MB peak against
584 MB once the cache is written, measured with ``/usr/bin/time -f %M``). :func:`precompile` runs,
when a problem's kernels are not in numba's on-disk cache (:func:`workbench.core.jit.cold_kernels`),
the scenario's truth simulation and reconstruction once in a child process (forked from the run,
or ``python -m workbench.problems.precompile`` where there is no fork) that writes the cache and
exits, so the run itself loads the compiled kernels. Its outcome never changes the run's: if it
fails, the run compiles in place, as before. A synthetic run may hand the child its telemetry
folder: the child then synthesizes there (the same settings and seed, so the same files the run
would write) and the run reads them instead of simulating its truth a second time; otherwise the
child's telemetry goes to a temporary folder.

A problem opts in with a ``compiled_modules`` attribute (module names holding its cached kernels).
``WORKBENCH_PRECOMPILE=0`` turns the child off.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from workbench.core.forking import fork_call, fork_enabled
from workbench.core.jit import cold_kernels, cold_modules, load_compiler
from workbench.io import progress as prog
from workbench.io.scenario import Scenario, ScenarioError, load_scenario
from workbench.problems import registry
from workbench.problems.base import Problem, RunOptions, Synthesized

__all__ = ["ENV_SWITCH", "Compiled", "child_argv", "main", "precompile"]

ENV_SWITCH = "WORKBENCH_PRECOMPILE"
"""Environment variable: ``0`` turns the precompiling child off (the run compiles in place)."""


@dataclass(frozen=True)
class Compiled:
    """A precompiling child that succeeded: ``synthesized``, the synthetic telemetry and truth it
    wrote into the run's telemetry folder (None when the run handed it none)."""

    synthesized: Synthesized | None = None


def child_argv(scenario: Scenario, seed: int, telemetry: Path | None = None, manifest: Path | None = None) -> list[str]:
    """The child's command line: this module run on the scenario file with the run's seed, and the
    folder to synthesize into with the file to list what it wrote in (:func:`main`)."""
    extra = [] if telemetry is None else ["--telemetry", str(telemetry), "--manifest", str(manifest)]
    return [sys.executable, "-m", "workbench.problems.precompile", str(scenario.path), "--seed", str(seed), *extra]


def precompile(
    scenario: Scenario, problem: Problem, seed: int, rep: prog.Reporter, *, telemetry: Path | None = None
) -> Compiled | None:
    """Compile ``problem``'s cached numba kernels in a child process if a module of them is cold
    (:func:`~workbench.core.jit.cold_modules`: none of its kernels cached).

    ``telemetry``: the run's synthetic telemetry folder (a synthetic scenario only); the child then
    synthesizes into it, as the run would with ``seed``, and :attr:`Compiled.synthesized` says what
    it wrote. Returns :class:`Compiled` when a child ran and left no module cold, None when nothing
    was needed (no ``compiled_modules``, none cold, or ``WORKBENCH_PRECOMPILE=0``) or the child
    failed (one progress line says so, with its exit code and last line of output; the run then
    compiles, and synthesizes, in place). Interrupting the parent (Ctrl-C, SIGTERM) kills the child."""
    names = tuple(getattr(problem, "compiled_modules", ()) or ())
    if not names or os.environ.get(ENV_SWITCH, "1") == "0":
        return None
    modules = registry.import_modules(names)
    cold = cold_modules(modules)
    if not cold:
        return None
    n = len(cold_kernels([m for m in modules if m.__name__ in cold]))
    if telemetry is not None and not _as_on_disk(scenario):
        telemetry = None  # the child reads the file: it would synthesize another scenario's telemetry
    with tempfile.TemporaryDirectory(prefix="workbench_precompile_") as tmp:
        manifest = None if telemetry is None else Path(tmp) / "synthesized.json"
        with rep.stage(f"compiling {n} kernels in a child process (first run of this checkout)"):
            code, output = _run_child(scenario, seed, telemetry, manifest)
        if code != 0:
            last = output.strip().splitlines()[-1:] or [""]
            rep.line(f"precompiling child exited {code} ({last[0][:200]}); compiling in this process")
            return None
        if cold_modules(modules):
            return None
        return Compiled(_read_manifest(manifest))


def _as_on_disk(scenario: Scenario) -> bool:
    """True when the scenario's file still reads as ``scenario`` (no overrides, not edited since),
    so the child, which reads the file, synthesizes what the run would."""
    try:
        return load_scenario(scenario.path).data == scenario.data
    except (ScenarioError, OSError):
        return False


def _read_manifest(path: Path | None) -> Synthesized | None:
    """The :class:`Synthesized` a child listed in ``path`` (None: no file, or not one it finished)."""
    if path is None or not path.is_file():
        return None
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
        return Synthesized(telemetry={k: Path(v) for k, v in d["telemetry"].items()}, truth=Path(d["truth"]))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def _run_child(
    scenario: Scenario, seed: int, telemetry: Path | None = None, manifest: Path | None = None
) -> tuple[int, str]:
    """Run :func:`main` on the scenario in a child process; (exit code, its stdout and stderr).

    Forked from the running process (its imports are done, ~2–3 s of CPU saved) unless
    ``WORKBENCH_FORK=0`` (:func:`~workbench.core.forking.fork_enabled`; then a new interpreter,
    ``python -m workbench.problems.precompile``), when the caller runs no other thread: the run
    calls this before it starts its recording. Any exception here (Ctrl-C, SIGTERM's
    ``Terminated``) kills the child first."""
    argv = child_argv(scenario, seed, telemetry, manifest)
    if not fork_enabled():
        proc = subprocess.run(argv, capture_output=True, text=True, errors="replace")
        return proc.returncode, proc.stderr or proc.stdout
    load_compiler()  # the run needs it too, to load what the child compiles
    with tempfile.TemporaryFile() as log:
        pid = fork_call(lambda: main(argv[3:]), stdout_fd=log.fileno(), stderr_fd=log.fileno())
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
    """Child entry: synthesize (into ``--telemetry``, else a temporary folder) and reconstruct the
    scenario, quietly, until no module of the problem's ``compiled_modules`` is cold (the
    reconstruction stops at the first stage after which all are cached: the drop test's forward
    filter), which compiles and caches the kernels the run calls. With ``--telemetry``, the files
    synthesized are listed in ``--manifest`` (JSON: ``telemetry`` {stream: path}, ``truth`` path),
    written last. Exit 0 on success."""
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import resolve_scenario

    ap = argparse.ArgumentParser(prog="python -m workbench.problems.precompile", description=main.__doc__)
    ap.add_argument("scenario", help="scenario .toml path or shipped name")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--telemetry", type=Path, default=None, help="synthesize the telemetry into this folder")
    ap.add_argument("--manifest", type=Path, default=None, help="with --telemetry: list what was written here")
    args = ap.parse_args(argv)
    sc = resolve_scenario(args.scenario, assets_dir())  # validated by the parent run
    problem = registry.get(sc.kind, where=str(sc.path))
    settings = problem.settings(sc)
    syn = None
    with tempfile.TemporaryDirectory(prefix="workbench_precompile_") as tmp:
        if sc.is_synthetic:
            syn = problem.synthesize(settings, args.telemetry or Path(tmp) / "telemetry", args.seed)
            telemetry = dict(syn.telemetry)
        else:
            telemetry = problem.telemetry_files(settings)
        modules = registry.import_modules(tuple(getattr(problem, "compiled_modules", ()) or ()))
        if cold_modules(modules):
            for _ in problem.reconstruct(settings, telemetry, RunOptions(seed=args.seed)):
                if not cold_modules(modules):
                    break
    if syn is not None and args.telemetry is not None and args.manifest is not None:
        listing = {"telemetry": {k: str(v) for k, v in syn.telemetry.items()}, "truth": str(syn.truth)}
        args.manifest.write_text(json.dumps(listing), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
