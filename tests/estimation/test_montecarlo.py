"""The Monte Carlo executor: identical, keyed results whatever the executor, chunking or a killed worker."""

from __future__ import annotations

import os
import signal
import tempfile
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np
import pytest

from workbench.estimation.montecarlo import chunk_ranges, member_seed, resolve_scheduler, run_monte_carlo


def member_task(shared, k, ss):
    """Per-member task: a small numpy computation of the member's own random draws."""
    rng = np.random.Generator(np.random.PCG64(ss))
    a = rng.standard_normal((shared["m"], shared["m"]))
    return k, np.linalg.solve(a @ a.T + np.eye(shared["m"]), rng.standard_normal(shared["m"]))


def last_slow_task(shared, k, ss):
    """Member task: members ≥ 2 take ``shared`` seconds, members 0 and 1 none."""
    if k >= 2:
        time.sleep(shared)
    return k


def chunk_task(shared, start, stop, seeds):
    """Chunk task: the members' draws, one row per member."""
    assert len(seeds) == stop - start
    return np.stack([member_task(shared, k, s)[1] for k, s in zip(range(start, stop), seeds, strict=True)])


def slow_first_task(shared, k, ss):
    """Early members finish last (completion order reversed in a pool)."""
    time.sleep(0.05 * (shared - k))
    return k


def killing_task(shared, k, ss):
    """Member 3 SIGKILLs its worker process the first time it runs (marker file), then succeeds."""
    m, marker = shared
    if k == 3 and marker is not None and not Path(marker).exists():
        Path(marker).write_text("killed once")
        os.kill(os.getpid(), signal.SIGKILL)
    return member_task({"m": m}, k, ss)[1]


def always_killing_task(shared, k, ss):
    if k == 1:
        os.kill(os.getpid(), signal.SIGKILL)
    return k


def failing_task(shared, k, ss):
    if k == 2:
        raise RuntimeError("member 2 failed")
    return k


SHARED = {"m": 6}


def _stack(run):
    return np.stack([r[1] for r in run.results])


def test_loop_and_processes_identical_and_keyed():
    loop = run_monte_carlo(member_task, 9, shared=SHARED, seed=11)
    pool = run_monte_carlo(member_task, 9, shared=SHARED, seed=11, workers=2)
    assert loop.kind == "loop" and loop.executor == "in-process loop"
    assert pool.kind == "processes" and pool.executor == "process pool (2 workers)" and pool.pool_restarts == 0
    assert [r[0] for r in loop.results] == list(range(9)) == [r[0] for r in pool.results]
    assert loop.keys == tuple(range(9))
    np.testing.assert_array_equal(_stack(loop), _stack(pool))
    # a different base seed gives different members
    assert not np.array_equal(_stack(loop), _stack(run_monte_carlo(member_task, 9, shared=SHARED, seed=12)))


def test_order_is_member_order_not_completion_order():
    seen = []
    run = run_monte_carlo(slow_first_task, 6, shared=6, workers=2, progress=lambda d, t: seen.append((d, t)))
    assert run.results == list(range(6))
    assert seen == [(i, 6) for i in range(1, 7)]


def test_member_seeds_independent_of_chunking():
    ref = _stack(run_monte_carlo(member_task, 10, shared=SHARED, seed=5))
    for chunk, workers in ((1, 1), (3, 1), (4, 2), (10, 1)):
        run = run_monte_carlo(chunk_task, 10, shared=SHARED, seed=5, chunk_size=chunk, workers=workers)
        assert run.ranges == tuple(chunk_ranges(10, chunk))
        np.testing.assert_array_equal(np.concatenate(run.results), ref)
    assert chunk_ranges(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert member_seed(5, 3).spawn_key == (3,) and member_seed(5, 3).entropy == 5


def test_killed_worker_is_replaced_and_results_identical(tmp_path):
    ref = run_monte_carlo(killing_task, 8, shared=(6, None), seed=2)
    marker = tmp_path / "killed"
    run = run_monte_carlo(killing_task, 8, shared=(6, str(marker)), seed=2, workers=2)
    assert marker.exists() and run.pool_restarts == 1
    np.testing.assert_array_equal(np.stack(run.results), np.stack(ref.results))


def test_broken_pool_raises_after_max_restarts():
    with pytest.raises(BrokenProcessPool):
        run_monte_carlo(always_killing_task, 3, workers=2, max_pool_restarts=1)


def test_task_error_propagates():
    for workers in (1, 2):
        with pytest.raises(RuntimeError, match="member 2 failed"):
            run_monte_carlo(failing_task, 5, workers=workers)


def test_scheduler_names():
    assert resolve_scheduler(None, 1) == "loop" and resolve_scheduler(None, 3) == "processes"
    assert resolve_scheduler("local") == "dask" == resolve_scheduler("tcp://127.0.0.1:8786")
    with pytest.raises(ValueError, match="scheduler"):
        resolve_scheduler("threads")
    with pytest.raises(ValueError):
        run_monte_carlo(member_task, 0)


def test_dask_identical_and_scratch_removed(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    ref = run_monte_carlo(chunk_task, 7, shared=SHARED, seed=9, chunk_size=2)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    run = run_monte_carlo(chunk_task, 7, shared=SHARED, seed=9, chunk_size=3, scheduler="local", name="t")
    assert run.kind == "dask" and "LocalCluster (2 workers" in run.executor
    np.testing.assert_array_equal(np.concatenate(run.results), np.concatenate(ref.results))
    assert list(tmp_path.iterdir()) == []  # the cluster's scratch folders (scheduler's and workers') are gone


def test_progress_counter_counts_pool_members_once_each_also_after_a_killed_worker(tmp_path):
    """The Monte Carlo counter of ``workbench mc`` (``io.progress``) driven by the pool's completed
    futures: every member counted exactly once, also when a worker is killed and the pool restarted."""
    import io

    from workbench.io.progress import Reporter

    for marker, restarts in ((None, 0), (str(tmp_path / "killed"), 1)):
        out = io.StringIO()
        rep = Reporter("plain", stream=out, bar_every_s=0.0)
        seen = []
        with rep.counter("Monte Carlo members", total=8, unit="members") as bar:

            def count(done, total, bar=bar, seen=seen):
                seen.append(done)
                bar(done, total)

            run = run_monte_carlo(killing_task, 8, shared=(6, marker), seed=2, workers=2, progress=count)
            assert bar.n == 8
        assert run.kind == "processes" and run.pool_restarts == restarts
        assert seen == list(range(1, 9))
        assert out.getvalue().startswith("Monte Carlo members: 8/8 members in ")


def test_pool_progress_arrives_as_members_finish_not_at_the_end():
    """A pool run reports each member when it finishes: the first two (instant) members are counted
    while the slow ones still run — not all at once when the last one is done (the pool used to
    wait for every future before counting any)."""
    stamps = []
    t0 = time.perf_counter()
    run = run_monte_carlo(
        last_slow_task, 4, shared=1.5, seed=0, workers=2, progress=lambda d, n: stamps.append(time.perf_counter() - t0)
    )
    wall = time.perf_counter() - t0
    assert run.kind == "processes" and run.results == [0, 1, 2, 3] and len(stamps) == 4
    assert stamps[0] < wall - 1.0, (stamps, wall)
