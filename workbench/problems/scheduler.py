"""Several scenarios on one command line (``workbench run A B ...``, ``run all``): each in its own
process, ``jobs`` at a time, longest first.

A process knows only its own scenario, so nothing is shared between them. On POSIX the processes
are forked from the calling process after it imported the modules every scenario needs
(:data:`PRELOAD`: each new interpreter would spend ~2 s of CPU importing numpy, scipy, numba,
trimesh and rerun again) and loaded numba's compiler registries
(:func:`workbench.core.jit.load_compiler`); ``WORKBENCH_FORK=0`` (:func:`workbench.core.forking.fork_enabled`) starts
new interpreters instead. No thread is started before a fork, and the children's pipes are read
between polls. The command line builds each child's argument list and hands in its own entry point
(``entry(argv)``), so this module knows nothing of argument parsing.
"""

from __future__ import annotations

import contextlib
import json
import os
import selectors
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

from workbench.core.forking import fork_call, fork_enabled, gc_paused
from workbench.core.jit import load_compiler
from workbench.io import progress as prog
from workbench.problems import registry

__all__ = ["PRELOAD", "Child", "cost_hint", "jobs_for", "launch_order", "run_in_processes"]

#: modules every scenario process imports; they are imported once here before the children are forked
PRELOAD = (
    "scipy.interpolate",
    "scipy.linalg",
    "scipy.optimize",
    "scipy.signal",
    "scipy.special",
    "scipy.stats",
    "numba",
    "trimesh",
    "rerun",
    "rerun.blueprint",
    "workbench.problems.runner",
    "workbench.recording.compare",
)


def jobs_for(requested: int | None, n_scenarios: int) -> int:
    """Scenario processes to run at once: ``requested`` (``--jobs``), else one per CPU core; never
    more than there are scenarios, never fewer than 1."""
    n = requested if requested is not None else (os.cpu_count() or 1)
    return max(1, min(int(n), n_scenarios))


def cost_hint(name: str, out: Path) -> float:
    """Expected wall time [s] of scenario ``name``: its last run's ``wall_time_s`` in ``out`` (0 when
    never run), so that the longest scenarios start first (longest-processing-time order)."""
    try:
        return float(json.loads((out / f"{Path(name).stem}.summary.json").read_text(encoding="utf-8"))["wall_time_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0.0


def launch_order(names: list[str], out: Path) -> list[str]:
    """The order in which the scenario processes start: longest first by their last wall time in
    ``out``; with no earlier run (a fresh checkout), round-robin over the problem kinds, so that two
    scenarios of one kind do not both compile the same kernels (numba, first run of a checkout) at
    the same time — the second one starts when the first has written the compiled cache."""
    hints = {n: cost_hint(n, out) for n in names}
    if any(hints.values()):
        return sorted(names, key=lambda n: -hints[n])
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import ScenarioError, resolve_scenario

    by_kind: dict[str, list[str]] = {}
    for n in names:
        try:
            kind = resolve_scenario(n, assets_dir()).kind
        except (ScenarioError, OSError):
            kind = ""  # reported by the scenario's own process
        by_kind.setdefault(kind, []).append(n)
    queues = list(by_kind.values())
    order = []
    while any(queues):
        for q in queues:
            if q:
                order.append(q.pop(0))
    return order


class Child:
    """One scenario's process: forked from this one (``entry(argv)`` runs in the child, its imports
    done), or the new interpreter ``argv`` when forking is off.  ``pipe``: its stderr goes to a pipe
    this process reads (:attr:`fd`, non-blocking), else to the inherited stderr.  The fork happens
    while this process runs no other thread, so the child inherits no held lock."""

    def __init__(self, argv: list[str], entry: Callable[[list[str]], int], pipe: bool, fork: bool):
        r = w = None
        if pipe:
            r, w = os.pipe()
        self.returncode: int | None = None
        self.proc = None
        if fork:
            self.pid = fork_call(lambda: entry(argv), stderr_fd=w, close_fds=(r,) if pipe else ())
        else:
            self.proc = subprocess.Popen(argv, stderr=w)
            self.pid = self.proc.pid
        self.fd = None
        if pipe:
            os.close(w)
            os.set_blocking(r, False)
            self.fd = r
        self._buf = b""
        self.eof = False

    def poll(self) -> int | None:
        """The exit code once the process ended (reaped here), else None."""
        if self.returncode is None:
            if self.proc is not None:
                self.returncode = self.proc.poll()
            else:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
                if pid:
                    self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def terminate(self) -> None:
        """SIGTERM (the child removes its partial recording and exits 143)."""
        if self.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGTERM)

    def wait(self) -> int:
        """Block until the process ended; its exit code."""
        while self.poll() is None:
            if self.proc is not None:
                self.proc.wait()
            else:
                _, status = os.waitpid(self.pid, 0)
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def lines(self, final: bool = False) -> list[str]:
        """The complete stderr lines the child wrote since the last call (pipe mode; :attr:`eof` once
        the child closed its end); ``final``: also an unterminated last line, and close the pipe
        (the caller unregisters it from its selector first)."""
        if self.fd is None:
            return []
        while not self.eof:
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            if not chunk:
                self.eof = True
                break
            self._buf += chunk
        *done, self._buf = self._buf.split(b"\n")
        if final:
            if self._buf:
                done.append(self._buf)
            self._buf = b""
            os.close(self.fd)
            self.fd = None
        return [d.decode("utf-8", errors="replace") for d in done]


def run_in_processes(
    names: list[str],
    argv_for: Callable[[str], list[str]],
    jobs: int,
    out: Path,
    rep: prog.Reporter,
    *,
    entry: Callable[[list[str]], int],
    progress: Callable[[str], None],
) -> int:
    """Run each scenario of ``names`` in its own process, ``jobs`` at a time, longest first
    (:func:`launch_order` over the summaries in ``out``).

    ``argv_for(name)``: the child's full command line (``[python, -m, workbench.cli, run, NAME, ...]``,
    run as a new interpreter when forking is off); ``entry(argv)``: what a forked child runs (the
    command line's ``main`` on that argv). Every scenario runs even when another fails; returns 0
    when all succeed, else the exit code of the first failed scenario in the order given (each
    failure is listed in the final ``progress`` line). Ctrl-C or SIGTERM stop the running processes
    with SIGTERM (each removes its partial recording) and start no new one. Each process inherits
    this one's environment, so also its one BLAS thread, and is this process's child (its memory
    shows in ``RUSAGE_CHILDREN``).

    Progress: on a terminal (``rep`` in bars mode) the children's stderr is piped through this
    process, which prints their lines above one bar of the scenarios finished (count, ETA);
    otherwise the children write to the inherited stderr directly.
    """
    order = launch_order(names, out)
    t0 = time.perf_counter()
    piped = rep.mode == "bars"
    fork = fork_enabled()
    if fork:
        with gc_paused():
            registry.import_modules(PRELOAD)
            load_compiler()
    pending, running, codes = list(order), {}, {}
    sel = selectors.DefaultSelector()

    def drain(child: Child, final: bool = False) -> None:
        if child.fd is not None and (final or child.eof) and child.fd in sel.get_map():
            sel.unregister(child.fd)  # before the pipe is closed (its number may be reused)
        for text in child.lines(final):
            rep.result(text.rstrip("\r"))
        if child.eof and child.fd is not None and child.fd in sel.get_map():
            sel.unregister(child.fd)  # at EOF a pipe is always readable: stop selecting it

    rep.line(f"running {len(names)} scenarios, {jobs} at a time (--jobs), in the order {', '.join(order)}")
    bar = rep.counter("scenarios finished", total=len(names), unit="scenarios")
    try:
        while pending or running:
            while pending and len(running) < jobs:
                name = pending.pop(0)
                child = Child(argv_for(name), entry, piped, fork)
                running[name] = child
                if child.fd is not None:
                    sel.register(child.fd, selectors.EVENT_READ, child)
            if sel.get_map():
                for key, _ in sel.select(timeout=0.05):
                    drain(key.data)
            else:
                time.sleep(0.05)
            for name, child in list(running.items()):
                if child.poll() is not None:
                    drain(child, final=True)
                    codes[name] = child.returncode
                    del running[name]
            bar.set(len(codes))
    except BaseException:
        for child in running.values():
            child.terminate()
        for child in running.values():
            child.wait()
            drain(child, final=True)
        raise
    finally:
        sel.close()
        bar.close(report=False)
    failed = [n for n in names if codes.get(n)]
    progress(
        f"{len(names) - len(failed)} of {len(names)} scenarios succeeded in {time.perf_counter() - t0:.1f} s"
        + "".join(f"\n  {n}: exit {codes[n]}" for n in failed)
    )
    return codes[failed[0]] if failed else 0
