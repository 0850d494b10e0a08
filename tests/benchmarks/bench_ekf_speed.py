"""Speed of the drop-test filter driver and of the RTS smoother, each beside its named baseline.

Run on demand from the repository root (not collected by pytest)::

    nice -n 10 .venv/bin/python tests/benchmarks/bench_ekf_speed.py [--reps 5] [--seed 1]
        [--compile-time] [--json recordings/benchmarks/ekf_speed.json]

One synthetic drop (``assets/scenarios/droptest.toml``, IMU-only kinematic, 42 error states) is
simulated, then in the same process (CPU time, ``time.process_time``, best of ``--reps``):

1. Filter steps per second of the production forward pass
   (:func:`workbench.problems.droptest.pipeline.forward_pass`, default engine: the compiled
   recursion, sequential per-sensor Joseph-form updates, innovations/NIS per sensor recorded)
   against **the minimal stacked-update loop** ``bench_droptest.baseline_filter`` (same
   ``model.propagate``, ``F P Fᵀ + Q``, one stacked update of all the step's measurements by
   ``np.linalg.solve``, ``P = (I − K H) P``, nothing recorded) and against the reference engine
   (``engine="reference"``: the generic :func:`workbench.estimation.ekf.run_filter`, the previous
   production path).  The largest differences production − reference are printed (floating-point
   noise expected).
2. The RTS smoother (:func:`workbench.estimation.smoother.rts_smooth`) against
   :func:`rts_smooth_previous`, the implementation before issue #14 kept here verbatim (per-step
   loop, BLAS threads as the process has them) on the same forward pass; largest differences.
3. ``--compile-time``: CPU and wall time of the first ``forward_pass`` in a fresh process with an
   empty numba cache (JIT compilation of the kernel) and with the cache filled.

``--json`` writes the numbers in the benchmark convention (``bench_json.write_benchmark_json``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.linalg import lapack

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_droptest import baseline_filter, baseline_noise  # noqa: E402 (beside this script)
from bench_json import write_benchmark_json  # noqa: E402

from workbench.estimation.ekf import ErrorStateLayout, ForwardPass  # noqa: E402
from workbench.estimation.smoother import SmoothedPass, rts_smooth  # noqa: E402
from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.droptest import model as rl  # noqa: E402
from workbench.problems.droptest import pipeline as dt  # noqa: E402
from workbench.problems.droptest.problem import DropTestProblem  # noqa: E402
from workbench.problems.droptest.synthetic import synthesize_droptest  # noqa: E402

SCEN = ROOT / "assets" / "scenarios" / "droptest.toml"


def _active(A: np.ndarray) -> np.ndarray | None:
    """Copy of the smoother's check (private there): indices with positive variance, None if all."""
    dg = np.diag(A)
    if np.all(dg > 0.0):
        return None
    zero = dg == 0.0
    if np.any(dg < 0.0) or np.any(A[zero] != 0.0) or not np.all(np.isfinite(A)):
        raise ValueError("covariance not positive semi-definite")
    return np.flatnonzero(~zero)


def _check_pd(A: np.ndarray) -> None:
    """Copy of the smoother's per-step positive-definiteness check (a Cholesky factorisation)."""
    if not np.all(np.isfinite(A)):
        raise ValueError("smoothed covariance not finite")
    act = _active(A)
    _, info = lapack.dpotrf(A if act is None else A[np.ix_(act, act)], lower=1)
    if info != 0:
        raise ValueError(f"smoothed covariance not positive definite (potrf info={info})")


def rts_smooth_previous(fp: ForwardPass, layout: ErrorStateLayout) -> SmoothedPass:
    """The smoother before issue #14 (commit d8f095f): the named baseline, verbatim but for the
    error messages of its checks (same checks, copied above).

    Same formulas and outputs as :func:`workbench.estimation.smoother.rts_smooth` (x (n, n_x),
    P and G (n, n_e, n_e)); per step ``F P_post``, a Cholesky factor and ``dpotrs`` with the BLAS
    threads of the process (OpenBLAS threads its triangular solves even at 42 × 42).
    """
    n = fp.t.shape[0]
    n_e = layout.n_e
    xs = np.empty_like(fp.x_post)
    Ps = np.empty_like(fp.P_post)
    G = np.zeros((n, n_e, n_e))
    if n == 0:
        return SmoothedPass(fp.t, xs, Ps, G)
    xs[-1] = fp.x_post[-1]
    Ps[-1] = fp.P_post[-1]
    _check_pd(Ps[-1])
    for k in range(n - 2, -1, -1):
        Pp = fp.P_prior[k + 1]
        d = np.sqrt(np.diag(Pp))
        act = _active(Pp)
        rhs = fp.F[k + 1] @ fp.P_post[k]
        if act is None:
            c, info = lapack.dpotrf(Pp / np.outer(d, d), lower=1)
            if info != 0:
                raise ValueError(f"predicted covariance P_prior[{k + 1}] not positive definite")
            Gt, _ = lapack.dpotrs(c, rhs / d[:, None], lower=1)
            Gt = Gt / d[:, None]
        else:
            da = d[act]
            c, info = lapack.dpotrf(Pp[np.ix_(act, act)] / np.outer(da, da), lower=1)
            if info != 0:
                raise ValueError(f"predicted covariance P_prior[{k + 1}] not positive definite")
            Gt = np.zeros_like(rhs)
            sol, _ = lapack.dpotrs(c, rhs[act] / da[:, None], lower=1)
            Gt[act] = sol / da[:, None]
        Gk = Gt.T
        dx = Gk @ layout.boxminus(xs[k + 1], fp.x_prior[k + 1])
        xs[k] = layout.boxplus(fp.x_post[k], dx)
        A = fp.P_post[k] + Gk @ (Ps[k + 1] - Pp) @ Gt
        A = 0.5 * (A + A.T)
        _check_pd(A)
        Ps[k] = A
        G[k] = Gk
    return SmoothedPass(fp.t, xs, Ps, G)


def _cpu(fn, reps: int):
    """(best CPU time [s] over ``reps`` calls, last result)."""
    best, out = np.inf, None
    for _ in range(reps):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    """Largest |a − b| relative to the largest |b| (0 when equal)."""
    s = float(np.max(np.abs(b))) if b.size else 0.0
    d = float(np.max(np.abs(a - b))) if b.size else 0.0
    return d / s if s > 0 else d


def setup(seed: int, work: str):
    """Simulate one drop and return (settings, telemetry, initial state, lander, R's of the baseline)."""
    sc = DropTestProblem().settings(load_scenario(SCEN))
    syn = synthesize_droptest(sc, work, seed=seed)
    tel = init = None
    for stage in dt.reconstruct(sc, syn.telemetry, seed=seed):
        if isinstance(stage, dt.InitialState):
            init = stage
            break
        tel = stage
    return sc, tel, init, sc.lander, baseline_noise(sc, tel)


def filter_speed(sc, tel, init, lander, rs, reps: int) -> dict:
    """Production forward pass vs the minimal stacked-update loop vs the reference engine."""
    n = int(tel.t.size)
    t0 = time.process_time()
    prod = dt.forward_pass(sc, tel, init)  # first call: numba cache load (or compile)
    first = time.process_time() - t0
    tp, prod = _cpu(lambda: dt.forward_pass(sc, tel, init), reps)
    tb, (p_base, _) = _cpu(lambda: baseline_filter(tel, init, prod.q_accel, prod.q_angular, *rs), reps)
    tr, ref = _cpu(lambda: dt.forward_pass(sc, tel, init, engine="reference"), max(1, reps // 2))
    fa, fr = prod.forward, ref.forward
    diffs = {f: _rel(getattr(fa, f), getattr(fr, f)) for f in ("x_post", "P_post", "x_prior", "P_prior", "F", "Q")}
    for name, h in fr.innovations.items():
        a = fa.innovations[name]
        diffs[f"innovation {name} y"] = _rel(a.y, h.y)
        diffs[f"innovation {name} nis"] = _rel(a.nis, h.nis)
    return {
        "steps": n,
        "n_error_states": int(init.P0.shape[0]),
        "production_first_call_cpu_s": first,
        "production_cpu_s": tp,
        "baseline_cpu_s": tb,
        "reference_cpu_s": tr,
        "steps_per_s_production": n / tp,
        "steps_per_s_baseline": n / tb,
        "steps_per_s_reference": n / tr,
        "ratio_production_over_baseline": tb / tp,
        "ratio_production_over_reference": tr / tp,
        "baseline_vs_production_max_position_diff_m": float(np.max(np.abs(p_base - prod.x[:, rl.SP]))),
        "production_vs_reference_max_rel_diff": diffs,
        "innovation_channels": list(fa.innovations),
    }, prod


def smoother_speed(prod, n_triads: int, reps: int) -> dict:
    """rts_smooth vs rts_smooth_previous on the production forward pass."""
    layout = dt.layout_for(n_triads)
    fp = prod.forward
    ts, new = _cpu(lambda: rts_smooth(fp, layout), reps)
    to, old = _cpu(lambda: rts_smooth_previous(fp, layout), reps)
    return {
        "steps": int(fp.t.size),
        "production_cpu_s": ts,
        "previous_cpu_s": to,
        "ratio_previous_over_production": to / ts,
        "max_rel_diff": {f: _rel(getattr(new, f), getattr(old, f)) for f in ("x", "P", "G")},
    }


_FIRST_CALL = """
import sys, time, tempfile
sys.path.insert(0, {root!r}); sys.path.insert(0, {here!r})
import bench_ekf_speed as b
from workbench.problems.droptest import pipeline as dt
with tempfile.TemporaryDirectory() as d:
    sc, tel, init, lander, rs = b.setup({seed}, d)
    t0, w0 = time.process_time(), time.perf_counter()
    dt.forward_pass(sc, tel, init, lander)
    print(time.process_time() - t0, time.perf_counter() - w0)
"""


def compile_time(seed: int) -> dict:
    """First forward_pass in a fresh process: with an empty numba cache, then with it filled."""
    out = {}
    code = _FIRST_CALL.format(root=str(ROOT), here=str(Path(__file__).resolve().parent), seed=seed)
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold_cache", "warm_cache"):
            r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
            cpu, wall = (float(v) for v in r.stdout.split()[-2:])
            out[f"first_forward_pass_{label}_cpu_s"] = cpu
            out[f"first_forward_pass_{label}_wall_s"] = wall
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=5, help="repetitions, best CPU time kept (default 5)")
    ap.add_argument("--seed", type=int, default=1, help="drop seed (default 1)")
    ap.add_argument("--compile-time", action="store_true", help="also time the first call with a cold numba cache")
    ap.add_argument("--json", default=None, help="write the results here (e.g. recordings/benchmarks/ekf_speed.json)")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        sc, tel, init, lander, rs = setup(a.seed, d)
        f, prod = filter_speed(sc, tel, init, lander, rs, a.reps)
        s = smoother_speed(prod, len(tel.triads), a.reps)
    res = {"filter": f, "smoother": s}
    if a.compile_time:
        res["compile"] = compile_time(a.seed)
    print(f"drop-test filter, {f['steps']} steps, {f['n_error_states']} error states (CPU, best of {a.reps}):")
    print(f"  production  {f['steps_per_s_production']:9.0f} steps/s")
    print(f"  baseline    {f['steps_per_s_baseline']:9.0f} steps/s (minimal stacked-update loop)")
    print(f"  reference   {f['steps_per_s_reference']:9.0f} steps/s (run_filter path)")
    print(f"  production / baseline = {f['ratio_production_over_baseline']:.2f}, "
          f"production / reference = {f['ratio_production_over_reference']:.2f}")  # fmt: skip
    worst = max(f["production_vs_reference_max_rel_diff"].values())
    print(f"  largest production-reference relative difference {worst:.1e}")
    print(f"RTS smoother, {s['steps']} steps: production {s['production_cpu_s']:.3f} s, previous "
          f"{s['previous_cpu_s']:.3f} s = {s['ratio_previous_over_production']:.1f}x; "
          f"largest relative difference {max(s['max_rel_diff'].values()):.1e}")  # fmt: skip
    if "compile" in res:
        c = res["compile"]
        cold, warm = c["first_forward_pass_cold_cache_cpu_s"], c["first_forward_pass_warm_cache_cpu_s"]
        print(f"first forward_pass in a fresh process: cold numba cache {cold:.1f} s CPU, warm cache {warm:.2f} s CPU")
    if a.json:
        print(f"wrote {write_benchmark_json(a.json, __file__, res)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
