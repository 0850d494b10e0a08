"""One Monte Carlo executor: run a task for every member in a loop, a process pool or on Dask.

:func:`run_monte_carlo` calls a picklable, module-level ``task`` once per member ``k = 0..n−1``
(or once per chunk of consecutive members) and returns the results ordered by member index, never
by completion order.  The executor does not change a number:

* every task sees the same ``shared`` object (shipped once per worker, not once per task);
* member ``k``'s randomness is ``np.random.SeedSequence(seed, spawn_key=(k,))``
  (:func:`member_seed`), whatever the chunk size, executor or number of workers; a caller that
  seeds differently passes ``seed=None`` and seeds inside the task from the member index;
* BLAS/OpenMP run one thread in every executor (threadpoolctl), in the calling process for the
  loop as in the workers: multi-threaded BLAS reductions are only bitwise reproducible for a fixed
  thread count, and several busy-waiting BLAS pools on a few cores made small linear algebra ~10x
  slower;
* a process-pool worker that dies (e.g. SIGKILL from the out-of-memory killer) breaks the pool
  (:class:`~concurrent.futures.process.BrokenProcessPool`): the pool is restarted and only the
  missing members are run again, up to ``max_pool_restarts`` times.

Executors (``scheduler``):

* ``None`` — ``"loop"`` when ``workers ≤ 1``, else ``"processes"``;
* ``"loop"`` — a plain loop in this process;
* ``"processes"`` — :class:`concurrent.futures.ProcessPoolExecutor` of ``workers`` processes
  (default start method of the platform);
* ``"local"`` or ``"dask"`` — a ``dask.distributed.LocalCluster`` (``workers`` processes, 2 if
  ``workers ≤ 1``, one thread each), started and closed here, its scratch folder removed after;
* ``"tcp://host:port"`` (also ``tls://``, ``inproc://``, ``ucx://``) — a ``dask.distributed``
  client of a running scheduler (its workers must have the package installed).

Dask is optional: it is imported only for a Dask scheduler, and a missing install raises
:class:`NotImplementedError` naming the extra to install.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import shutil
import tempfile
import time
import uuid
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "DASK_PREFIXES",
    "MonteCarloRun",
    "chunk_ranges",
    "member_seed",
    "resolve_scheduler",
    "run_monte_carlo",
]

#: Address prefixes of a running Dask scheduler.
DASK_PREFIXES = ("tcp://", "tls://", "inproc://", "ucx://")


@dataclass(frozen=True)
class MonteCarloRun:
    """Outcome of :func:`run_monte_carlo`.

    ``results`` one task result per entry of ``ranges``, in member order; ``ranges`` the
    ``(start, stop)`` member ranges of the tasks (``(k, k + 1)`` per member without chunks);
    ``kind`` the executor: "loop" | "processes" | "dask"; ``executor`` a description (e.g.
    ``"process pool (2 workers)"``); ``workers`` processes used (1 for the loop; for a remote Dask
    scheduler the workers it had when the run started); ``wall_s`` [s] wall time of the tasks
    (including starting and closing a pool or cluster); ``pool_restarts`` how often a broken
    process pool was restarted.
    """

    results: list
    ranges: tuple[tuple[int, int], ...]
    kind: str
    executor: str
    workers: int
    wall_s: float
    pool_restarts: int = 0

    @property
    def keys(self) -> tuple[int, ...]:
        """First member index of each task (the member index without chunks)."""
        return tuple(a for a, _ in self.ranges)


def member_seed(seed: int, k: int) -> np.random.SeedSequence:
    """The seed sequence of member ``k`` of a run with base ``seed``: ``SeedSequence(seed, spawn_key=(k,))``."""
    return np.random.SeedSequence(int(seed), spawn_key=(int(k),))


def chunk_ranges(n: int, chunk_size: int) -> list[tuple[int, int]]:
    """Consecutive ``(start, stop)`` member ranges of at most ``chunk_size`` members covering ``0..n−1``."""
    if n < 0 or chunk_size < 1:
        raise ValueError(f"chunk_ranges: need n ≥ 0 and chunk_size ≥ 1, got n={n}, chunk_size={chunk_size}")
    return [(a, min(a + chunk_size, n)) for a in range(0, n, chunk_size)]


def resolve_scheduler(scheduler: str | None, workers: int | None = 1) -> str:
    """The executor kind ``"loop"``, ``"processes"`` or ``"dask"`` a ``scheduler`` argument selects
    (see the module docstring); raises ``ValueError`` for an unknown one."""
    if scheduler is None:
        return "loop" if (workers or 1) <= 1 else "processes"
    if scheduler in ("loop", "processes"):
        return scheduler
    if scheduler in ("local", "dask") or str(scheduler).startswith(DASK_PREFIXES):
        return "dask"
    raise ValueError(
        "scheduler must be None, 'loop', 'processes', 'local' (or 'dask': a LocalCluster) "
        f"or a Dask scheduler address 'tcp://host:port', got {scheduler!r}"
    )


# ---------------------------------------------------------------------------------------------
# calling a task (the same code in every executor)


def _call(task: Callable, shared: Any, a: int, b: int, chunked: bool, seed: int | None):
    if chunked:
        seeds = None if seed is None else [member_seed(seed, k) for k in range(a, b)]
        return task(shared, a, b, seeds)
    return task(shared, a, None if seed is None else member_seed(seed, a))


def _one_blas_thread() -> None:
    """Limit BLAS/OpenMP to one thread in this process (pool initializer; run on Dask workers)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


#: ``shared`` of the tasks in a process-pool worker (set once by the initializer)
_WORKER_SHARED: Any = None


def _init_worker(shared: Any) -> None:
    global _WORKER_SHARED
    _WORKER_SHARED = shared
    _one_blas_thread()


def _worker_call(task: Callable, a: int, b: int, chunked: bool, seed: int | None):
    return _call(task, _WORKER_SHARED, a, b, chunked, seed)


# ---------------------------------------------------------------------------------------------
# executors: each fills ``results`` {start: result} and calls ``done()`` once per finished task


def _run_loop(task, shared, ranges, chunked, seed, results, done) -> None:
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        for a, b in ranges:
            results[a] = _call(task, shared, a, b, chunked, seed)
            done()


def _run_pool(task, shared, ranges, chunked, seed, results, done, workers: int, max_restarts: int) -> int:
    """Process pool; returns the number of restarts after a broken pool."""
    restarts = 0
    while True:
        todo = [(a, b) for a, b in ranges if a not in results]
        if not todo:
            return restarts
        pool = ProcessPoolExecutor(
            max_workers=int(workers), mp_context=mp.get_context(), initializer=_init_worker, initargs=(shared,)
        )
        try:
            futs = {pool.submit(_worker_call, task, a, b, chunked, seed): a for a, b in todo}
            pending = set(futs)
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in finished:
                    if f.exception() is None:
                        results[futs[f]] = f.result()
                        done()
                for f in finished:
                    if f.exception() is not None:
                        raise f.exception()
        except BrokenProcessPool:
            # a worker died: keep every result that arrived, restart the pool for the rest
            for f, a in futs.items():
                if a not in results and f.done() and not f.cancelled() and f.exception() is None:
                    results[a] = f.result()
                    done()
            if restarts >= max_restarts:
                raise
            restarts += 1
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(task, shared, ranges, chunked, seed, results, done, scheduler: str, workers: int, name: str):
    """Dask; returns (description, number of workers)."""
    try:
        import dask
        from distributed import Client, LocalCluster, as_completed
    except ImportError as err:
        raise NotImplementedError(
            "a dask scheduler needs the optional dask extra: pip install 'workbench[dask]' "
            "(from a checkout: .venv/bin/pip install -e '.[dask]')"
        ) from err

    def gather(client) -> None:
        client.run(_one_blas_thread)
        shared_f = client.scatter(shared, broadcast=True)
        token = uuid.uuid4().hex[:8]  # keys unique per run: a long-lived cluster must not reuse results
        futs = {
            client.submit(_call, task, shared_f, a, b, chunked, seed, pure=False, key=f"{name}-{token}-{a}"): a
            for a, b in ranges
        }
        for f, res in as_completed(list(futs), with_results=True):
            results[futs[f]] = res
            done()

    if scheduler in ("local", "dask"):
        n = int(workers) if workers and workers > 1 else 2
        scratch = tempfile.mkdtemp(prefix="workbench-dask-")
        try:
            with (
                dask.config.set({"temporary-directory": scratch}),  # the scheduler's scratch too
                LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    local_directory=scratch,
                ) as cluster,
                Client(cluster) as client,
            ):
                gather(client)
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
        return f"dask LocalCluster ({n} workers x 1 thread, processes)", n
    with Client(scheduler) as client:
        n = len(client.scheduler_info().get("workers", {}))
        gather(client)
    return f"dask scheduler {scheduler}", n


# ---------------------------------------------------------------------------------------------


def run_monte_carlo(
    task: Callable,
    n: int,
    *,
    shared: Any = None,
    seed: int | None = None,
    chunk_size: int | None = None,
    workers: int | None = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    name: str = "mc",
    max_pool_restarts: int = 1,
) -> MonteCarloRun:
    """Run ``task`` for members ``0..n−1`` and return the results in member order (module docstring).

    Without chunks (``chunk_size=None``) ``task(shared, k, seed_k)`` is called once per member k,
    ``seed_k`` = :func:`member_seed` ``(seed, k)`` (None if ``seed`` is None).  With
    ``chunk_size`` ≥ 1, ``task(shared, start, stop, seeds)`` is called once per range of
    :func:`chunk_ranges` ``(n, chunk_size)`` with ``seeds`` the list of the members' seed sequences
    (None if ``seed`` is None); each result stays one entry of ``MonteCarloRun.results``.
    ``task`` must be a module-level function and ``shared`` and the results picklable for the
    process pool and Dask.  ``workers`` processes of the pool or the LocalCluster (``None``: the
    CPU count); ``scheduler`` None | "loop" | "processes" | "local" | "dask" | a Dask address;
    ``progress(done, total)`` is called in this process after each finished task (units: tasks);
    ``name`` prefixes the Dask task keys; ``max_pool_restarts`` restarts of a broken process pool
    before its :class:`~concurrent.futures.process.BrokenProcessPool` is raised.  An exception of a
    task propagates (the pool's queued tasks are cancelled).
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"run_monte_carlo: n must be ≥ 1, got {n}")
    if workers is None:
        workers = os.cpu_count() or 1
    workers = int(workers)
    kind = resolve_scheduler(scheduler, workers)
    chunked = chunk_size is not None
    ranges = chunk_ranges(n, int(chunk_size)) if chunked else [(k, k + 1) for k in range(n)]
    seed = None if seed is None else int(seed)
    results: dict[int, Any] = {}
    count = [0]

    def done() -> None:
        count[0] += 1
        if progress is not None:
            progress(count[0], len(ranges))

    t0 = time.perf_counter()
    restarts = 0
    if kind == "loop":
        _run_loop(task, shared, ranges, chunked, seed, results, done)
        executor, used = ("in-process loop over chunks" if chunked else "in-process loop"), 1
    elif kind == "processes":
        workers = max(workers, 1)
        restarts = _run_pool(task, shared, ranges, chunked, seed, results, done, workers, int(max_pool_restarts))
        executor, used = f"process pool ({workers} workers)", workers
    else:
        executor, used = _run_dask(task, shared, ranges, chunked, seed, results, done, scheduler, workers, name)
    wall = time.perf_counter() - t0
    return MonteCarloRun(
        results=[results[a] for a, _ in ranges],
        ranges=tuple(ranges),
        kind=kind,
        executor=executor,
        workers=used,
        wall_s=wall,
        pool_restarts=restarts,
    )
