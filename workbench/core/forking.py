"""Run a function in a forked copy of this process (POSIX): the command line's scenario processes
and the precompiling child, which would otherwise each start a new interpreter and import numpy,
scipy, numba, trimesh and rerun again (~2 s of CPU each)."""

from __future__ import annotations

import contextlib
import gc
import os
import sys
from collections.abc import Callable, Iterable, Iterator

__all__ = ["CAN_FORK", "FORK_ENV", "fork_call", "fork_enabled", "gc_paused"]

CAN_FORK = hasattr(os, "fork")
"""Whether this platform forks (False on Windows: callers start a new interpreter instead)."""

FORK_ENV = "WORKBENCH_FORK"
"""The one switch: ``WORKBENCH_FORK=0`` makes the callers start a new interpreter instead of forking."""


def fork_enabled() -> bool:
    """True when child processes are forked from this one: the platform forks and the environment
    variable :data:`FORK_ENV` is not ``"0"`` (read at each call, so a test or a user sets it per run)."""
    return CAN_FORK and os.environ.get(FORK_ENV, "1").strip() != "0"


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """Turn Python's cyclic garbage collector off inside the block (on again after it, if it was
    on): for importing the modules a process forks its children with, whose objects all live as
    long as the process, so the collections during the import would find nothing to free and only
    cost CPU (each full collection walks every object allocated so far)."""
    was_on = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_on:
            gc.enable()


def fork_call(
    fn: Callable[[], int],
    *,
    stdout_fd: int | None = None,
    stderr_fd: int | None = None,
    close_fds: Iterable[int] = (),
) -> int:
    """Fork; in the child redirect file descriptor 1 to ``stdout_fd`` and 2 to ``stderr_fd`` (each
    when given; ``sys.stdout`` / ``sys.stderr`` are rebound to them too), close ``close_fds``, run
    ``fn()`` and exit with the code it returns (1, with the traceback on stderr, if it raises: the
    child never returns into the caller). Returns the child's pid in the parent (reap it with
    ``os.waitpid``). Call it while no other thread of this process runs: a fork copies the locks
    another thread holds, not the thread that would release them.

    The child first moves every object it inherited to the collector's permanent generation
    (``gc.freeze``): its full collections then walk only the objects it allocates itself, not the
    imported modules (numba, scipy, rerun) that make up most of the inherited heap, and do not write
    into (so copy) the memory pages it shares with the caller. The inherited objects are never
    collected in the child, which exits when ``fn`` returns; the caller's own collector is left as
    it was."""
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid:
        return pid
    gc.freeze()
    code = 1
    try:
        for fd in close_fds:
            os.close(fd)
        if stdout_fd is not None:
            os.dup2(stdout_fd, 1)
            sys.stdout = open(1, "w", buffering=1, closefd=False)  # noqa: SIM115 - lives as long as the child
        if stderr_fd is not None:
            os.dup2(stderr_fd, 2)
            sys.stderr = open(2, "w", buffering=1, closefd=False)  # noqa: SIM115 - lives as long as the child
        code = fn()
    except BaseException:  # noqa: BLE001 - the child must never return into the caller
        import traceback

        traceback.print_exc()
    finally:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code)
