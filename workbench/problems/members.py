"""The Monte Carlo member loop of the problems' truth studies, with its progress counter.

The entry (:mod:`workbench.problems.entry.truth_mc`) and flush-air-data
(:mod:`workbench.problems.meads.truth_mc`) Monte Carlo studies against the truth simulator run one
heavy task per member (simulate a truth, write its telemetry, reconstruct it) and count the members
on the run's progress reporter.  :func:`run_members` is that loop, in one place: the executor is
:func:`workbench.estimation.montecarlo.run_monte_carlo` (which stays free of the progress
reporter: it takes a ``progress(done, total)`` callable), the counter is the current
:func:`workbench.io.progress.current` reporter's.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from workbench.estimation.montecarlo import MonteCarloRun, run_monte_carlo
from workbench.io import progress

__all__ = ["run_members"]


def run_members(
    task: Callable,
    n_runs: int,
    *,
    shared: Any,
    seed: int,
    workers: int = 1,
    scheduler: str | None = None,
    name: str,
) -> MonteCarloRun:
    """``task(shared, k, seed_k)`` for members ``k = 0..n_runs−1`` on
    :func:`~workbench.estimation.montecarlo.run_monte_carlo` (member k seeded
    ``SeedSequence(seed, spawn_key=(k,))``; ``workers``, ``scheduler`` and ``name`` — the Dask
    task-key prefix — as there), counted as "Monte Carlo members" on the current progress reporter;
    the results in member order."""
    n = int(n_runs)
    with progress.current().counter("Monte Carlo members", total=n, unit="members") as bar:
        return run_monte_carlo(
            task,
            n,
            shared=shared,
            seed=int(seed),
            workers=int(workers),
            scheduler=scheduler,
            name=name,
            progress=bar,
        )
