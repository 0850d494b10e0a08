"""Monte Carlo of the synthetic drop test: synthesize → reconstruct → score, one task per seed.

Each task (:func:`run_seed`) writes the telemetry of its seed into its own temporary subfolder
of ``work_dir``, runs :func:`workbench.problems.droptest.pipeline.run_droptest`, scores the result against
the truth with :func:`workbench.problems.droptest.pipeline.score` plus the consistency numbers below, and
deletes the subfolder.  Every seed is a *different drop*: the impact speeds, release attitude, bag
pressure, timing and true bungee stiffness are drawn by
:func:`workbench.problems.droptest.synthetic.disperse_drop` within the REDLand test envelope
(:class:`~workbench.problems.droptest.synthetic.DropEnvelope`), and the release point and bungee
count follow from them; the truth simulator (its own airbag contact physics) flies that drop.
Every random draw of a task (the drop, sensor noise, bias, scale, 3DM errors, survey error,
ranging noise, the posterior sampling of the stroke-σ check) comes from its seed alone, so the
results do not depend on the executor
(:func:`workbench.estimation.montecarlo.run_monte_carlo`, one BLAS thread everywhere):

* ``scheduler=None, workers=1`` — a plain loop in this process;
* ``scheduler=None, workers=2`` — :class:`concurrent.futures.ProcessPoolExecutor` (2 processes);
* ``scheduler="local"`` — a ``dask.distributed.LocalCluster(n_workers=max(workers, 2),
  threads_per_worker=1, processes=True)`` started and closed here;
* ``scheduler="tcp://host:port"`` — a ``dask.distributed.Client`` to a running scheduler (its
  workers must have the package installed and see ``work_dir``).

Consistency statistics (Bar-Shalom, Li & Kirubarajan 2001, Sect. 5.4), per run:

* ``nees_pose_mean`` — NEES of the smoothed pose [δp (SPF), δθ (body)] (6 dof) averaged over the
  run's steps (as :func:`~workbench.problems.droptest.pipeline.score`);
* ``nees_pose_at_max`` — the same NEES at the max-stroke step only (one value per run, χ²(6)
  if consistent, independent across runs);
* ``nees_stroke`` — 1-D NEES of the max stroke ``((d_est − d_true)/σ)²`` (χ²(1) if consistent);
* ``z_at_max`` — normalised errors δ/σ of p, v, θ, ω and the gyro scale factors at the max-stroke
  step (for finding which states are over- or under-confident).

Error convention (the filter's, docs/ARCHITECTURE.md): ``truth = estimate ⊞ δ``, ``δp = p_true − p_est``,
``δθ = attitude_error(q_est, q_true)`` (``q_true = q_est ⊗ exp(δθ)``).
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from workbench.estimation.montecarlo import resolve_scheduler, run_monte_carlo
from workbench.io import progress
from workbench.problems.droptest.config import DropSettings
from workbench.problems.droptest.synthetic import DROP_PARAMETER_NAMES

__all__ = [
    "FailedSeed",
    "McResult",
    "SeedResult",
    "run_seed",
    "monte_carlo",
    "stack_results",
    "summarize_mc",
    "Z_NAMES",
]

#: Names of the columns of ``z_at_max``: position [SPF], velocity [SPF], attitude δθ [body],
#: body rate ω [body], gyro scale factors.
Z_NAMES: tuple[str, ...] = tuple(f"{blk}.{a}" for blk in ("p", "v", "theta", "w", "scale") for a in "xyz")
#: Error-state indices (redland layout) of the ``z_at_max`` columns.
_Z_INDEX = np.r_[0:6, 9:15, 18, 22, 26]  # p, v, θ, ω and the gyro scale factors (diagonal of E)


@dataclass(frozen=True)
class SeedResult:
    """Outcome of one Monte Carlo task (one seed). Lengths in m, times in s.

    ``max_stroke`` estimated max stroke (smoothed) [m]; ``sigma`` its reported 1σ [m]; ``truth``
    the truth max stroke [m]; ``error = max_stroke − truth`` [m]; ``inside_3sigma``
    ``|error| ≤ 3 σ``; ``nees_pose_mean`` time-averaged 6-dof pose NEES; ``nees_pose_at_max`` 6-dof
    pose NEES at the max-stroke step; ``nees_stroke`` ``(error/σ)²``; ``restitution_error``
    estimate − truth [-]; ``z_at_max`` (15,) δ/σ per state of :data:`Z_NAMES`;
    ``nees_blocks_mean`` (4,) time-averaged 3-dof NEES of p, v, θ, ω over the run;
    ``restitution_sigma`` reported σ_e (estimation and definition in quadrature) and
    ``restitution_sigma_estimation`` its estimation part alone [-]; ``restitution_truth`` [-] (same
    definition); ``restitution_error_touch_leave`` estimate − the truth at the instants the bags touch
    and leave (another definition) [-]; ``restitution_error_before`` the error as scored before the
    definition was revised (estimate just outside the first interval above 1 g − truth at touch/leave) [-];
    ``drop`` (len(DROP_PARAMETER_NAMES),) the drawn and solved drop parameters
    (:func:`~workbench.problems.droptest.synthetic.drop_parameters`);
    ``wall_time_s`` whole task; ``reconstruct_s`` the reconstruction alone.
    """

    seed: int
    max_stroke: float
    sigma: float
    truth: float
    error: float
    inside_3sigma: bool
    nees_pose_mean: float
    nees_pose_at_max: float
    nees_stroke: float
    restitution_error: float
    z_at_max: np.ndarray
    nees_blocks_mean: np.ndarray
    wall_time_s: float
    reconstruct_s: float
    restitution_sigma: float = float("nan")
    restitution_sigma_estimation: float = float("nan")
    restitution_truth: float = float("nan")
    restitution_error_touch_leave: float = float("nan")
    restitution_error_before: float = float("nan")
    drop: np.ndarray = field(default_factory=lambda: np.full(len(DROP_PARAMETER_NAMES), np.nan))


@dataclass(frozen=True)
class FailedSeed:
    """A Monte Carlo task that raised: its ``seed`` and the error as ``"<Type>: <message>"``.  The
    Monte Carlo goes on without it and says so (``McResult.failed``, ``summary["failed_members"]``,
    the headline): one bad member must not throw away the others, nor disappear."""

    seed: int
    error: str


@dataclass(frozen=True)
class McResult:
    """Per-seed arrays of a Monte Carlo, all of length n (the number of seeds), in seed order.

    Fields as in :class:`SeedResult` but stacked: ``seed`` (n,) int, ``max_stroke``, ``sigma``,
    ``truth``, ``error`` (n,) [m], ``inside_3sigma`` (n,) bool, ``nees_pose_mean``,
    ``nees_pose_at_max``, ``nees_stroke``, ``restitution_error`` (n,), ``z_at_max`` (n, 15),
    ``nees_blocks_mean`` (n, 4), ``wall_time_s``, ``reconstruct_s`` (n,) [s], ``restitution_sigma``,
    ``restitution_sigma_estimation``, ``restitution_truth``, ``restitution_error_touch_leave``,
    ``restitution_error_before`` (n,),
    ``drop`` (n, k) (columns
    :data:`~workbench.problems.droptest.synthetic.DROP_PARAMETER_NAMES`).  ``scenario`` name,
    ``mode`` filter mode, ``executor`` description, ``total_wall_s`` wall time of the whole
    Monte Carlo [s]; ``failed`` the tasks that raised (:class:`FailedSeed`, not in the arrays).
    """

    scenario: str
    mode: str
    executor: str
    total_wall_s: float
    seed: np.ndarray
    max_stroke: np.ndarray
    sigma: np.ndarray
    truth: np.ndarray
    error: np.ndarray
    inside_3sigma: np.ndarray
    nees_pose_mean: np.ndarray
    nees_pose_at_max: np.ndarray
    nees_stroke: np.ndarray
    restitution_error: np.ndarray
    z_at_max: np.ndarray
    nees_blocks_mean: np.ndarray
    wall_time_s: np.ndarray
    reconstruct_s: np.ndarray
    restitution_sigma: np.ndarray | None = None
    restitution_sigma_estimation: np.ndarray | None = None
    restitution_truth: np.ndarray | None = None
    restitution_error_touch_leave: np.ndarray | None = None
    restitution_error_before: np.ndarray | None = None
    drop: np.ndarray | None = None
    failed: tuple[FailedSeed, ...] = ()

    @property
    def n_runs(self) -> int:
        """Number of runs (seeds)."""
        return int(self.seed.size)

    #: per-seed fields that depend only on the seed (not on timing): compare these across executors
    DETERMINISTIC = (
        "seed", "max_stroke", "sigma", "truth", "error", "inside_3sigma", "nees_pose_mean",
        "nees_pose_at_max", "nees_stroke", "restitution_error", "z_at_max", "nees_blocks_mean",
        "restitution_sigma", "restitution_sigma_estimation", "restitution_truth", "restitution_error_touch_leave",
        "restitution_error_before", "drop",
    )  # fmt: skip


def _first_1g_interval_restitution(res) -> float:
    """The restitution as scored before the definition was revised [-]: ``−v_n(i1+1)/v_n(i0−1)``
    around the first interval of the smoothed non-gravitational acceleration above 1 g (the
    reconstruction's ``res.stroke.contact``); NaN without a bounce across it."""
    from workbench.problems.droptest import model as rl

    i0, i1 = res.stroke.contact
    x, n = res.smoothed.x, res.stroke.surface.normal
    if i0 <= 0 or i1 + 1 >= x.shape[0]:
        return np.nan
    b, a = float(x[i0 - 1, rl.SV] @ n), float(x[i1 + 1, rl.SV] @ n)
    return -a / b if b < 0.0 < a else np.nan


def run_seed(settings: DropSettings, seed: int, work_dir: str | Path) -> SeedResult:
    """One Monte Carlo task of the run with ``settings``: synthesize drop ``seed`` (a different drop per seed,
    ``synthesize_droptest(..., disperse=True)``) into a fresh subfolder of ``work_dir``,
    reconstruct (posterior-sampling seed = ``seed``), score, delete the subfolder."""
    from workbench.core.rotation import attitude_error
    from workbench.estimation.consistency import nees
    from workbench.problems.droptest import model as rl
    from workbench.problems.droptest.pipeline import run_droptest, score, truth_on_grid
    from workbench.problems.droptest.synthetic import load_truth, synthesize_droptest

    t0 = time.perf_counter()
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    sub = Path(tempfile.mkdtemp(prefix=f"seed{int(seed):06d}_", dir=work))
    try:
        syn = synthesize_droptest(settings, sub, seed=int(seed), disperse=True, compress_truth=False)
        truth = load_truth(syn.truth_path)
        t1 = time.perf_counter()
        res = run_droptest(settings, syn.telemetry, seed=int(seed))
        t2 = time.perf_counter()
        sc = score(res, truth)
    finally:
        shutil.rmtree(sub, ignore_errors=True)

    smo = res.smoothed
    tg = truth_on_grid(truth, smo.t)
    # full error δ = truth ⊟ estimate on the states with a truth (p, v, θ, ω, gyro scale)
    d = np.zeros((smo.t.size, rl.N_E))
    d[:, rl.EP] = tg["p_I"] - smo.x[:, rl.SP]
    d[:, rl.EV] = tg["v_I"] - smo.x[:, rl.SV]
    d[:, rl.ETH] = attitude_error(smo.x[:, rl.SQ], tg["q_I_B"])
    d[:, rl.EW] = tg["w_B"] - smo.x[:, rl.SW]
    d[:, rl.ES] = np.asarray(truth["gyro_error_matrix"], float).ravel() - smo.x[:, rl.SS]
    k = int(res.stroke.max.index)
    e6 = np.concatenate([d[k, rl.EP], d[k, rl.ETH]])
    nees_max = float(nees(e6, rl.pose_covariance(smo.P[k])))
    sd = np.sqrt(np.diagonal(smo.P[k]))
    z = d[k, _Z_INDEX] / sd[_Z_INDEX]
    blocks = []
    for sl in (rl.EP, rl.EV, rl.ETH, rl.EW):
        blocks.append(float(np.mean(nees(d[:, sl], smo.P[:, sl, sl]))))
    ms = res.stroke.max
    err = float(ms.distance - sc["max_stroke_truth_m"])
    return SeedResult(
        seed=int(seed),
        max_stroke=float(ms.distance),
        sigma=float(ms.sigma),
        truth=float(sc["max_stroke_truth_m"]),
        error=err,
        inside_3sigma=bool(sc["max_stroke_inside_3sigma"]),
        nees_pose_mean=float(sc["nees_pose_mean"]),
        nees_pose_at_max=nees_max,
        nees_stroke=float((err / ms.sigma) ** 2),
        restitution_error=float(sc["restitution_error"]),
        z_at_max=z,
        nees_blocks_mean=np.array(blocks),
        wall_time_s=time.perf_counter() - t0,
        reconstruct_s=t2 - t1,
        restitution_sigma=float(res.stroke.restitution[1]),
        restitution_sigma_estimation=float(res.stroke.restitution_sigma_estimation),
        restitution_truth=float(sc["restitution_truth"]),
        restitution_error_touch_leave=float(sc["restitution_error_touch_leave"]),
        restitution_error_before=float(_first_1g_interval_restitution(res) - sc["restitution_truth_touch_leave"]),
        drop=np.asarray(truth["drop_parameters"], float),
    )


def _seed_task(shared: tuple[DropSettings, list[int], Path], k: int, _ss: None) -> SeedResult | FailedSeed:
    """Task k of :func:`~workbench.estimation.montecarlo.run_monte_carlo`: :func:`run_seed` of the k-th seed
    (the seed is the task's only randomness, so the executor's member seed is not used); a task that
    raises is a :class:`FailedSeed`."""
    settings, seeds, work = shared
    try:
        return run_seed(settings, seeds[k], work)
    except Exception as err:  # one member's failure is reported with the Monte Carlo, not fatal to it
        return FailedSeed(int(seeds[k]), f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}")


def monte_carlo(
    settings: DropSettings,
    seeds: Sequence[int],
    work_dir: str | Path,
    *,
    scheduler: str | None = None,
    workers: int = 1,
) -> McResult:
    """Run :func:`run_seed` of the run with ``settings`` (picklable: every worker receives them)
    for every seed and stack the results (see module docstring).

    ``seeds`` sequence of non-negative ints (one task each); ``work_dir`` folder for the tasks'
    temporary subfolders (created if needed and then removed again; the ``seed*_`` subfolders of
    members whose worker was killed are removed at the end).  ``scheduler`` None (in-process loop, or
    a process pool of ``workers`` processes if ``workers > 1``), ``"local"`` (a dask LocalCluster
    of ``workers`` (≥ 2) processes) or ``"tcp://…"`` (a dask Client to that scheduler).  The result is in the order
    of ``seeds`` and does not depend on the executor (only ``wall_time_s``, ``reconstruct_s``,
    ``total_wall_s`` and ``executor`` do).
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("monte_carlo: no seeds")
    if len(set(seeds)) != len(seeds):
        raise ValueError("monte_carlo: repeated seeds")
    work = Path(work_dir)
    resolve_scheduler(scheduler, workers)  # refuses a bad scheduler/workers pair before any work
    created = not work.exists()
    work.mkdir(parents=True, exist_ok=True)
    try:
        return _monte_carlo(settings, seeds, work, scheduler, workers)
    finally:
        # a member whose worker was killed (SIGKILL, out of memory) could not delete its folder; the
        # member was redone elsewhere, so what is left under work/ is an orphan: remove it, and the
        # work folder itself when this call created it
        for sub in work.glob("seed*_*"):
            shutil.rmtree(sub, ignore_errors=True)
        if created:
            with contextlib.suppress(OSError):
                work.rmdir()


def _monte_carlo(settings: DropSettings, seeds: list[int], work: Path, scheduler: str | None, workers: int) -> McResult:
    """The body of :func:`monte_carlo` with its work folder in place."""
    # one BLAS thread in every executor (run_monte_carlo): BLAS reductions are only bitwise reproducible
    # for a fixed thread count, and two busy-waiting pools on two cores made each reconstruction ~10x
    # slower (measured 2.5 s -> 20-45 s)
    t0 = time.perf_counter()
    with progress.current().counter("Monte Carlo members", total=len(seeds), unit="members") as bar:
        run = run_monte_carlo(
            _seed_task,
            len(seeds),
            shared=(settings, seeds, work),
            workers=workers,
            scheduler=scheduler,
            name="droptest-seed",
            progress=bar,
        )
    executor = "loop" if run.kind == "loop" else run.executor
    ok = [r for r in run.results if isinstance(r, SeedResult)]
    failed = tuple(r for r in run.results if isinstance(r, FailedSeed))
    if not ok:
        raise RuntimeError(
            f"droptest Monte Carlo: all {len(failed)} members failed; first: seed {failed[0].seed}: {failed[0].error}"
        )
    return replace(
        stack_results(settings.name, settings.filter.mode, ok, executor, time.perf_counter() - t0), failed=failed
    )


def stack_results(name: str, mode: str, results: Sequence[SeedResult], executor: str, total_wall_s: float) -> McResult:
    """Stack per-seed results (in the given order) into an :class:`McResult` of scenario ``name``
    (filter ``mode``); ``executor`` describes how they ran, ``total_wall_s`` [s] the wall time of
    the whole run."""
    cols = {f.name: np.array([getattr(r, f.name) for r in results]) for f in fields(SeedResult)}
    return McResult(
        scenario=name,
        mode=mode,
        executor=executor,
        total_wall_s=float(total_wall_s),
        **cols,
    )


def summarize_mc(res: McResult, probability: float = 0.95) -> dict:
    """Statistics of a Monte Carlo (JSON-ready). Lengths in m.

    * ``fraction_inside_3sigma`` — runs whose truth max stroke lies inside the reported ±3σ
      (0.9973 expected for a consistent Gaussian estimate);
    * ``median_3sigma_m``; ``error_mean_m`` (bias), ``error_median_m`` (signed),
      ``abs_error_median_m``, ``abs_error_p95_m`` of the max-stroke error;
    * ``fraction_mer_requirement`` — runs with ``|error| ≤ 0.10 m`` AND ``3σ ≤ 0.10 m``;
    * ``anees_pose_time_avg`` — mean over runs of the per-run time-averaged smoothed-pose NEES
      (6 dof) with ``anees_pose_band`` = ``anees_bounds(6, n_runs, probability)``.  The steps of a
      run are strongly correlated (a smoother's errors are slow), so the time average is nearly as
      spread as a single step's NEES and this band is **only indicative**;
    * ``anees_pose_at_max`` — mean over runs of the pose NEES at the max-stroke step (one value
      per run, independent across runs): the proper test against the same band;
    * ``anees_stroke`` — mean of the 1-D max-stroke NEES ``(error/σ)²`` vs
      ``anees_bounds(1, n_runs, probability)`` (``anees_stroke_band``);
    * ``z2_at_max_mean`` — per state of :data:`Z_NAMES`, the mean over runs of (δ/σ)² at max stroke
      (≈ 1 if consistent; ≫ 1 over-confident, ≪ 1 under-confident), its band
      ``anees_bounds(1, n_runs, probability)``, and ``nees_blocks_time_avg`` (p, v, θ, ω; 3 dof);
    * restitution error median/p95 of |·|; ``restitution_fraction_inside_3sigma`` (|error| ≤ 3σ with
      the reported σ, estimation and definition in quadrature) beside
      ``restitution_fraction_inside_3sigma_estimation_only`` (the σ of the estimation alone, as
      reported before the definition term), ``restitution_abs_z_median`` / ``_p95`` of |error|/σ
      and the same for the estimation-only σ, and (``_touch_leave``) the reported σ against the truth at
      the instants the bags touch and leave (another definition), and (``_before``) the error as scored
      before the revision (1 g contact ends vs truth touch/leave) against the estimation-only σ;
      ``restitution_sigma_median``;
    * ``drop_spread``: per drawn/solved drop parameter (``DROP_PARAMETER_NAMES``) min, median, max;
    * wall times [s].
    """
    from workbench.estimation.consistency import anees_bounds

    n = res.n_runs
    err = res.error
    ae = np.abs(err)
    s3 = 3.0 * res.sigma
    b6 = anees_bounds(6, n, probability)
    b3 = anees_bounds(3, n, probability)
    b1 = anees_bounds(1, n, probability)
    a_time = float(np.mean(res.nees_pose_mean))
    a_max = float(np.mean(res.nees_pose_at_max))
    a_str = float(np.mean(res.nees_stroke))
    z2 = np.mean(res.z_at_max**2, axis=0)
    rest = res.restitution_error[np.isfinite(res.restitution_error)]
    rest_stats = _restitution_stats(res)
    drop_spread = {}
    if res.drop is not None and np.size(res.drop):
        for j, name in enumerate(DROP_PARAMETER_NAMES):
            col = np.asarray(res.drop, float).reshape(n, -1)[:, j]
            col = col[np.isfinite(col)]
            if col.size:
                drop_spread[name] = {"min": float(col.min()), "median": float(np.median(col)), "max": float(col.max())}
    blocks = np.mean(res.nees_blocks_mean, axis=0)
    return {
        "scenario": res.scenario,
        "mode": res.mode,
        "executor": res.executor,
        "n_runs": n,
        "n_failed": len(res.failed),
        "failed_members": [{"seed": f.seed, "error": f.error} for f in res.failed],
        "band_probability": probability,
        "fraction_inside_3sigma": float(np.mean(res.inside_3sigma)),
        "median_3sigma_m": float(np.median(s3)),
        "error_mean_m": float(np.mean(err)),
        "error_median_m": float(np.median(err)),
        "abs_error_median_m": float(np.median(ae)),
        "abs_error_p95_m": float(np.percentile(ae, 95)),
        "abs_error_max_m": float(np.max(ae)),
        "fraction_mer_requirement": float(np.mean((ae <= 0.10) & (s3 <= 0.10))),
        "anees_pose_time_avg": a_time,
        "anees_pose_band": list(b6),
        "anees_pose_time_avg_note": "steps within a run are correlated: band only indicative",
        "anees_pose_at_max": a_max,
        "anees_pose_at_max_inside": bool(b6[0] <= a_max <= b6[1]),
        "anees_stroke": a_str,
        "anees_stroke_band": list(b1),
        "anees_stroke_inside": bool(b1[0] <= a_str <= b1[1]),
        "z2_at_max_mean": {name: float(v) for name, v in zip(Z_NAMES, z2, strict=True)},
        "z2_band": list(b1),
        "nees_blocks_time_avg": {name: float(v) for name, v in zip(("p", "v", "theta", "w"), blocks, strict=True)},
        "nees_block_band": list(b3),
        "restitution_abs_error_median": float(np.median(np.abs(rest))) if rest.size else float("nan"),
        "restitution_abs_error_p95": float(np.percentile(np.abs(rest), 95)) if rest.size else float("nan"),
        **rest_stats,
        "drop_spread": drop_spread,
        "task_wall_median_s": float(np.median(res.wall_time_s)),
        "reconstruct_median_s": float(np.median(res.reconstruct_s)),
        "total_wall_s": float(res.total_wall_s),
    }


def _restitution_stats(res: McResult) -> dict:
    """Restitution error against its reported σ and against the estimation-only σ (see summarize_mc)."""
    out: dict = {}
    if res.restitution_sigma is None:
        return out
    err = np.asarray(res.restitution_error, float)
    cases = [("", err, res.restitution_sigma), ("_estimation_only", err, res.restitution_sigma_estimation)]
    if res.restitution_error_touch_leave is not None:
        cases.append(("_touch_leave", np.asarray(res.restitution_error_touch_leave, float), res.restitution_sigma))
    if res.restitution_error_before is not None:  # the old definition and its estimation-only σ
        cases.append(("_before", np.asarray(res.restitution_error_before, float), res.restitution_sigma_estimation))
    for key, err, sig in cases:
        sig = np.asarray(sig, float)
        ok = np.isfinite(err) & np.isfinite(sig) & (sig > 0)
        if not ok.any():
            continue
        z = np.abs(err[ok] / sig[ok])
        out[f"restitution_fraction_inside_3sigma{key}"] = float(np.mean(z <= 3.0))
        out[f"restitution_abs_z_median{key}"] = float(np.median(z))
        out[f"restitution_abs_z_p95{key}"] = float(np.percentile(z, 95))
        out[f"restitution_sigma_median{key}"] = float(np.median(sig[ok]))
        out[f"restitution_abs_error_median{key}"] = float(np.median(np.abs(err[ok])))
        out[f"restitution_n{key}"] = int(ok.sum())
    return out
