"""Compile a scenario's numba kernels in a short child process before its run (first run only).

Compiling numba kernels leaves LLVM's memory resident in the compiling process: the drop test's
truth and filter kernels add about 115 MB to the first run of a fresh checkout (698 MB peak against
584 MB once the cache is written, measured with ``/usr/bin/time -f %M``). :func:`precompile` runs,
when a problem's kernels are not in numba's on-disk cache (:func:`workbench.core.jit.cold_kernels`),
the scenario's truth simulation and reconstruction once in a child process (forked from the run,
or ``python -m workbench.problems.precompile`` where there is no fork) that writes the cache and
exits, so the run itself loads the compiled kernels. Its outcome never changes the run's: if it
fails, the run compiles in place, as before. A synthetic run may hand the child its telemetry
folder: the child synthesizes what the run would (the run's scenario, settings and seed) into a
temporary folder, moved into the run's folder once the child succeeded, and the run reads those
files instead of simulating its truth a second time.

A problem opts in with a ``compiled_modules`` attribute (module names holding its cached kernels).
``WORKBENCH_PRECOMPILE=0`` turns the child off.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from workbench.core.forking import fork_call, fork_enabled
from workbench.core.jit import cold_kernels, cold_modules, load_compiler
from workbench.io import progress as prog
from workbench.io.scenario import Scenario, load_scenario
from workbench.problems import registry
from workbench.problems.base import Problem, RunOptions, Synthesized

__all__ = ["ENV_SWITCH", "Compiled", "child_argv", "compile_by_running", "main", "precompile"]

ENV_SWITCH = "WORKBENCH_PRECOMPILE"
"""Environment variable: ``0`` turns the precompiling child off (the run compiles in place)."""


@dataclass(frozen=True)
class Compiled:
    """A precompiling child that succeeded: ``synthesized``, the synthetic telemetry and truth it
    wrote, moved into the run's telemetry folder (None when the run handed it none)."""

    synthesized: Synthesized | None = None


def child_argv(scenario: Scenario, seed: int, telemetry: Path | None = None, manifest: Path | None = None) -> list[str]:
    """The child's command line where there is no fork: this module run on the scenario file with
    the run's seed, and the folder to synthesize into with the file to list what it wrote in
    (:func:`main`)."""
    extra = [] if telemetry is None else ["--telemetry", str(telemetry), "--manifest", str(manifest)]
    return [sys.executable, "-m", "workbench.problems.precompile", str(scenario.path), "--seed", str(seed), *extra]


def precompile(
    scenario: Scenario,
    problem: Problem,
    seed: int,
    rep: prog.Reporter,
    *,
    settings: object | None = None,
    telemetry: Path | None = None,
) -> Compiled | None:
    """Compile ``problem``'s cached numba kernels in a child process if a module of them is cold
    (:func:`~workbench.core.jit.cold_modules`: none of its kernels cached).

    ``settings``: the run's (None: ``problem.settings(scenario)``). ``telemetry``: the run's
    synthetic telemetry folder (a synthetic scenario only); the child then synthesizes what the run
    would (its scenario, settings and ``seed``) into a temporary folder, and what it wrote is moved
    into ``telemetry`` once it succeeded (:attr:`Compiled.synthesized`), so an interrupted or failed
    child leaves nothing there. Where there is no fork the child reads the scenario file, so it is
    handed the folder only when that file still reads as ``scenario`` (no overrides, not edited).

    Returns :class:`Compiled` when a child ran and left no module cold, None when nothing was
    needed (no ``compiled_modules``, none cold, or ``WORKBENCH_PRECOMPILE=0``) or the child failed
    (one progress line says so, with its exit code and last line of output; the run then compiles,
    and synthesizes, in place). Interrupting the parent (Ctrl-C, SIGTERM) kills the child."""
    names = tuple(getattr(problem, "compiled_modules", ()) or ())
    if not names or os.environ.get(ENV_SWITCH, "1") == "0":
        return None
    modules = registry.import_modules(names)
    cold = cold_modules(modules)
    if not cold:
        return None
    n = len(cold_kernels([m for m in modules if m.__name__ in cold]))
    fork = fork_enabled()
    hand = telemetry is not None and scenario.is_synthetic and (fork or _as_on_disk(scenario))
    with tempfile.TemporaryDirectory(prefix="workbench_precompile_") as tmp:
        staging, manifest = (Path(tmp) / "telemetry", Path(tmp) / "synthesized.json") if hand else (None, None)
        with rep.stage(f"compiling {n} kernels in a child process (first run of this checkout)"):
            if fork:
                code, output = _fork_child(scenario, problem, settings, seed, staging, manifest)
            else:
                proc = subprocess.run(
                    child_argv(scenario, seed, staging, manifest), capture_output=True, text=True, errors="replace"
                )
                code, output = proc.returncode, proc.stderr or proc.stdout
        if code != 0:
            last = output.strip().splitlines()[-1:] or [""]
            rep.line(f"precompiling child exited {code} ({last[0][:200]}); compiling in this process")
            return None
        if cold_modules(modules):
            return None
        syn = _read_manifest(manifest)
        return Compiled(None if syn is None else _move_into(syn, staging, telemetry))


def _as_on_disk(scenario: Scenario) -> bool:
    """True when the scenario's file still reads as ``scenario`` (no overrides, not edited since),
    so a child that reads the file synthesizes what the run would. Compared by ``repr`` (values of
    overrides may be arrays, and 1, 1.0 and True differ); any failure counts as changed."""
    try:
        return repr(load_scenario(scenario.path).data) == repr(scenario.data)
    except Exception:
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


def _move_into(syn: Synthesized, staging: Path, folder: Path) -> Synthesized | None:
    """Move every file under ``staging`` to the same place under ``folder`` (replacing what is
    there) and return ``syn`` with its paths moved alike; None (nothing moved) when ``syn`` names
    a file outside ``staging``."""
    paths = [*syn.telemetry.values(), syn.truth]
    if not all(p.is_relative_to(staging) for p in paths):
        return None
    for f in sorted(p for p in staging.rglob("*") if p.is_file()):
        dest = folder / f.relative_to(staging)
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(f, dest)

    def moved(p: Path) -> Path:
        return folder / p.relative_to(staging)

    return Synthesized(telemetry={k: moved(p) for k, p in syn.telemetry.items()}, truth=moved(syn.truth))


def _fork_child(
    scenario: Scenario,
    problem: Problem,
    settings: object | None,
    seed: int,
    telemetry: Path | None,
    manifest: Path | None,
) -> tuple[int, str]:
    """Run :func:`compile_by_running` in a child forked from the running process (its imports and
    the run's own scenario and settings in memory, ~2–3 s of CPU saved); (exit code, its stdout
    and stderr). The caller runs no other thread: the run calls this before it starts its
    recording. Any exception here (Ctrl-C, SIGTERM's ``Terminated``) kills the child first."""
    load_compiler()  # the run needs it too, to load what the child compiles

    def child() -> int:
        return compile_by_running(scenario, problem, settings, seed, telemetry, manifest)

    with tempfile.TemporaryFile() as log:
        pid = fork_call(child, stdout_fd=log.fileno(), stderr_fd=log.fileno())
        try:
            _, status = os.waitpid(pid, 0)
        except BaseException:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            raise
        log.seek(0)
        return os.waitstatus_to_exitcode(status), log.read().decode("utf-8", errors="replace")


def compile_by_running(
    scenario: Scenario,
    problem: Problem,
    settings: object | None,
    seed: int,
    telemetry: Path | None = None,
    manifest: Path | None = None,
) -> int:
    """The child's work: synthesize the scenario (into ``telemetry``, else a temporary folder) with
    ``settings`` (None: ``problem.settings(scenario)``) and ``seed``, and reconstruct it, quietly,
    until no module of the problem's ``compiled_modules`` is cold (the reconstruction stops at the
    first stage after which all are cached: the drop test's forward filter), which compiles and
    caches the kernels the run calls. With ``telemetry`` and ``manifest``, the files synthesized are
    listed in ``manifest`` (JSON: ``telemetry`` {stream: path}, ``truth`` path), written last.
    Returns 0."""
    settings = problem.settings(scenario) if settings is None else settings
    syn = None
    with tempfile.TemporaryDirectory(prefix="workbench_precompile_") as tmp:
        if scenario.is_synthetic:
            syn = problem.synthesize(settings, telemetry or Path(tmp) / "telemetry", seed)
            files = dict(syn.telemetry)
        else:
            files = problem.telemetry_files(settings)
        modules = registry.import_modules(tuple(getattr(problem, "compiled_modules", ()) or ()))
        if cold_modules(modules):
            for _ in problem.reconstruct(settings, files, RunOptions(seed=seed)):
                if not cold_modules(modules):
                    break
    if syn is not None and telemetry is not None and manifest is not None:
        listing = {"telemetry": {k: str(v) for k, v in syn.telemetry.items()}, "truth": str(syn.truth)}
        manifest.write_text(json.dumps(listing), encoding="utf-8")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Child entry where there is no fork (``python -m workbench.problems.precompile``): the
    scenario read from its file, then :func:`compile_by_running`. Exit 0 on success."""
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
    return compile_by_running(sc, problem, None, args.seed, args.telemetry, args.manifest)


if __name__ == "__main__":
    sys.exit(main())
