"""Dispersion-analysis benchmark (AMELIA Sect. 6): 4 x 10 000 members (with refinement) vs a per-trajectory loop.

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_dispersion.py [--members 10000] [--chunk-size 1000]
        [--refine-rounds 3] [--loop-members 100] [--legacy-members 10] [--numpy-members 1000]
        [--scheduler local|tcp://...] [--source scenario|fixture] [--seed 2016] [--no-trace]

Input: ``--source scenario`` (default) synthesizes the ``schiaparelli`` scenario's telemetry
(truth simulator → files), reads and preprocesses it exactly as the pipeline does, and starts the
members about the scenario's (erroneous) nominal state; ``--source fixture`` uses the point-mass
entry of ``tests/support/entry_synth.py`` (no dependency on the entry pipeline).

Measured, in one run (wall ``time.perf_counter`` and CPU ``time.process_time`` of this process,
which counts the kernel's threads):

* the first call of the compiled kernel (numba JIT compile, or loading it from numba's cache —
  reported which);
* **the target row**: ``run_dispersion`` with ``--refine-rounds`` R (R + 1 passes of ``--members``
  members, the scenario's setting: 4 x 10 000) in-process, the whole call;
* one pass (no refinement) of ``--members`` members; peak memory of a second, traced pass
  (tracemalloc; skipped with ``--no-trace``) and the process's max RSS;
* the per-trajectory loop of the same maths (``run_dispersion_loop``: one member at a time on
  Python floats, the attitude track shared) on the first ``--loop-members`` members, **scaled** to
  (R + 1) x ``--members``; its event quantities must be bit-identical to the vectorised ones;
* the legacy per-trajectory loop (``strapdown.integrate_members`` on one state: the full
  strapdown, attitude included, per member — the loop before the attitude was shared) on
  ``--legacy-members`` members, scaled the same way; its events agree to rounding (max relative
  difference reported);
* the pure-numpy reference backend on ``--numpy-members`` members (one pass, scaled), identity;
* optionally (``--scheduler``) the same pass on Dask, with the identity check;
* accepted fraction, refined initial state vs the truth (normalised by the accepted spread).

Prints a markdown table and writes JSON (tests/benchmarks/bench_json.py convention) to
``recordings/benchmarks/dispersion.json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import resource
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.core.bodies import MARS  # noqa: E402
from workbench.core.rotation import attitude_error  # noqa: E402
from workbench.estimation import ensemble as en  # noqa: E402
from workbench.estimation.strapdown import integrate_members  # noqa: E402
from workbench.problems.entry import dispersion as ds  # noqa: E402
from workbench.problems.entry.site import R_GROUND  # noqa: E402


def scenario_input(seed: int):
    """(imu, nominal (v, q, p), events, truth (v, q, p) at t0, r_ground, description)."""
    from workbench.io.scenario import load_scenario
    from workbench.problems.entry.config import EntrySettings
    from workbench.problems.entry.preprocess import preprocess
    from workbench.problems.entry.synthetic import load_truth, synthesize_entry
    from workbench.problems.entry.telemetry import read_entry_telemetry

    sc = EntrySettings.from_scenario(load_scenario(ROOT / "assets" / "scenarios" / "schiaparelli.toml"))
    with tempfile.TemporaryDirectory() as d:
        paths = synthesize_entry(sc, d, seed=seed)
        tm = read_entry_telemetry(paths, sc.checks)
        imu = preprocess(tm, sc.preprocess)
        tr = load_truth(paths["truth"])
    k0 = int(np.argmin(np.abs(tr["t"] - imu.t[0])))
    return (
        imu,
        (tr["nominal_v0"], tr["nominal_q0"], tr["nominal_p0"]),
        dict(tm.events),
        (tr["v_M"][k0], tr["q_M_G"][k0], tr["p_M"][k0]),
        float(tr["r_ground"]),
        f"schiaparelli scenario (synthetic telemetry seed {seed}, preprocessed)",
    )


def _fixture_input():
    spec = importlib.util.spec_from_file_location("_entry_synth", ROOT / "tests" / "support" / "entry_synth.py")
    m = importlib.util.module_from_spec(spec)
    sys.modules["_entry_synth"] = m
    spec.loader.exec_module(m)
    tr = m.truth()
    imu = m.make_imu(tr, gaps=[(7.0, 8.4), (10.0, 11.8), (20.0, 23.3), (40.0, 97.2)])
    nominal = (tr["v"][0] + [8.0, -5.0, 3.0], m.perturb(tr["q"][0], np.radians([0.5, -0.3, 0.4])), tr["p"][0] + 1500.0)
    return imu, nominal, tr["events"], (tr["v"][0], tr["q"][0], tr["p"][0]), R_GROUND, "point-mass fixture"


def _timed(fn):
    """(result, wall [s], CPU [s] of this process) of ``fn()``."""
    w, c = time.perf_counter(), time.process_time()
    r = fn()
    return r, time.perf_counter() - w, time.process_time() - c


def _legacy_loop(imu, v0, q0, p0, n, kw):
    """The per-trajectory loop before the attitude was shared: the full strapdown
    (``strapdown.integrate_members`` on one state: scalar RK4 of v, q, p) member by member."""
    job, _ = ds.make_job(imu, v0, q0, p0, None, kw["seed"], kw["events_t"], None, "relative", kw["r_ground"])
    dx0 = ds.member_offsets(job, 0, n)
    v, q, p = ds.member_states(job.v0, job.q0, job.p0, dx0)
    evs = {k: np.empty(n) for k in ds.EVENT_NAMES}
    for i in range(n):
        out = integrate_members(job.imu, v[i], q[i], p[i], at_t=job.event_times, body=MARS)
        ev = ds.event_quantities(out["p_at"][:, None], out["v_at"][:, None], job.atmosphere, job.r_ground)
        for k in ds.EVENT_NAMES:
            evs[k][i] = ev[k][0]
    return evs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--members", type=int, default=10_000)
    ap.add_argument("--chunk-size", type=int, default=1000)
    ap.add_argument("--refine-rounds", type=int, default=3, help="importance-sampled refinement rounds (target: 3)")
    ap.add_argument("--loop-members", type=int, default=100)
    ap.add_argument("--legacy-members", type=int, default=10)
    ap.add_argument("--numpy-members", type=int, default=1000)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--source", choices=("scenario", "fixture"), default="scenario")
    ap.add_argument("--seed", type=int, default=2016)
    ap.add_argument("--no-trace", action="store_true", help="skip the tracemalloc pass")
    ap.add_argument("--out", default=str(ROOT / "recordings" / "benchmarks" / "dispersion.json"))
    a = ap.parse_args(argv)

    if a.source == "scenario":
        imu, nom, events, truth0, r_ground, desc = scenario_input(1)
    else:
        imu, nom, events, truth0, r_ground, desc = _fixture_input()
    kw = dict(events_t=events, seed=a.seed, r_ground=r_ground, bridge_mode="relative")
    v0, q0, p0 = nom
    n, R = a.members, a.refine_rounds
    passes = R + 1
    n_steps = np.asarray(imu.t).size - 1

    # 0. first call of the compiled kernel: JIT compile, or load from numba's cache
    jit = None
    if en.HAVE_NUMBA:
        _, w_first, c_first = _timed(lambda: ds.run_dispersion(imu, v0, q0, p0, None, 4, n_cloud=0, **kw))
        st = en.run_numba.stats
        jit = {"first_call_wall_s": w_first, "first_call_cpu_s": c_first,
               "from_cache": bool(sum(st.cache_hits.values())) and not sum(st.cache_misses.values())}  # fmt: skip
    backend = en.default_backend()
    # 1. the target: R + 1 passes (refinement rounds) of n members, the whole call
    rr, w_tgt, c_tgt = _timed(
        lambda: ds.run_dispersion(imu, v0, q0, p0, None, n, chunk_size=a.chunk_size, refine_rounds=R, n_cloud=300, **kw)
    )
    # 2. one pass (round 0 only)
    res, w_one, c_one = _timed(
        lambda: ds.run_dispersion(imu, v0, q0, p0, None, n, chunk_size=a.chunk_size, n_cloud=300, **kw)
    )
    peak = None
    if not a.no_trace:
        tracemalloc.start()
        res_t = ds.run_dispersion(imu, v0, q0, p0, None, n, chunk_size=a.chunk_size, n_cloud=300, **kw)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert np.array_equal(res.accepted, res_t.accepted)
    # 3. per-trajectory loop of the same maths on a subset, scaled to (R + 1) x n
    loop, w_loop, c_loop = _timed(
        lambda: ds.run_dispersion_loop(imu, v0, q0, p0, None, a.loop_members, n_cloud=0, **kw)
    )
    loop_identical = all(np.array_equal(loop.events[k], res.events[k][: a.loop_members]) for k in ds.EVENT_NAMES)
    per_member_loop = loop.wall_s / a.loop_members
    loop_scaled = per_member_loop * n * passes
    loop_scaled_cpu = c_loop / a.loop_members * n * passes
    # 4. the legacy per-trajectory loop (full strapdown per member)
    legacy = None
    if a.legacy_members > 0:
        lev, w_leg, c_leg = _timed(lambda: _legacy_loop(imu, v0, q0, p0, a.legacy_members, kw))
        rel = 0.0
        for k in ds.EVENT_NAMES:
            ref = res.events[k][: a.legacy_members]
            d = np.abs(lev[k] - ref) / np.maximum(np.abs(ref), np.finfo(float).tiny)
            rel = max(rel, float(np.max(d)))
        legacy = {"members": a.legacy_members, "wall_s": w_leg, "cpu_s": c_leg,
                  "scaled_wall_s": w_leg / a.legacy_members * n * passes,
                  "scaled_cpu_s": c_leg / a.legacy_members * n * passes,
                  "events_max_rel_diff_vs_vectorised": rel}  # fmt: skip
    # 5. the pure-numpy reference backend on a subset (one pass)
    numpy_ref = None
    if a.numpy_members > 0:
        rn, w_np, c_np = _timed(
            lambda: ds.run_dispersion(
                imu, v0, q0, p0, None, a.numpy_members, chunk_size=a.chunk_size, n_cloud=0, backend="numpy", **kw
            )  # fmt: skip
        )
        same = all(np.array_equal(rn.events[k], res.events[k][: a.numpy_members]) for k in ds.EVENT_NAMES)
        numpy_ref = {"members": a.numpy_members, "wall_s": w_np, "cpu_s": c_np,
                     "scaled_wall_s": w_np / a.numpy_members * n * passes,
                     "scaled_cpu_s": c_np / a.numpy_members * n * passes, "identical": bool(same)}  # fmt: skip
    # 6. optional Dask
    dask = None
    if a.scheduler:
        r2 = ds.run_dispersion(
            imu, v0, q0, p0, None, n, chunk_size=a.chunk_size, scheduler=a.scheduler, n_cloud=300, **kw
        )
        same = np.array_equal(r2.dx0, res.dx0) and all(
            np.array_equal(r2.events[k], res.events[k]) for k in ds.EVENT_NAMES
        )
        dask = {"scheduler": r2.scheduler, "wall_s": r2.wall_s, "identical_to_in_process": bool(same)}
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    # refined state vs truth (normalised by the accepted spread)
    tv, tq, tp = truth0
    d_true = np.concatenate([tv - v0, attitude_error(q0, tq), tp - p0])

    def refined_vs_truth(r):
        if r.n_accepted < 2:
            return None
        acc = r.accepted
        m = np.average(r.dx0[acc], axis=0, weights=r.weights[acc])
        s = np.sqrt(np.diagonal(r.refined_P0))
        e = d_true - m
        return {
            "accepted": r.n_accepted,
            "offset_mean": m.tolist(),
            "sigma": s.tolist(),
            "sigma_max_blocks_mps_rad_m": r.refined_sigma_max.tolist(),
            "z_truth": (e / s).tolist(),
            "nees_truth_9dof": float(e @ np.linalg.solve(r.refined_P0, e)),
            "truth_inside_3sigma": bool(np.all(np.abs(e) <= 3 * s)),
        }

    results = {
        "input": desc,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__},
        "backend": backend,
        "members": n,
        "chunk_size": a.chunk_size,
        "refine_rounds": R,
        "imu_samples": n_steps + 1,
        "gaps": len(imu.gaps),
        "jit": jit,
        "target": {
            "passes": passes,
            "wall_s": w_tgt,
            "cpu_s": c_tgt,
            "member_integration_wall_s": rr.wall_s,
            "round_wall_s": [h["wall_s"] for h in rr.rounds],
            "accepted_per_round": [h["n_accepted"] for h in rr.rounds],
            "last_round_ess": rr.rounds[-1]["ess"],
            "loop_over_target_wall": loop_scaled / w_tgt,
            "loop_over_target_cpu": loop_scaled_cpu / c_tgt,
            "legacy_loop_over_target_wall": None if legacy is None else legacy["scaled_wall_s"] / w_tgt,
            "meets_8s": bool(w_tgt <= 8.0),
            "meets_300x": bool(loop_scaled / w_tgt >= 300.0),
            "refined": refined_vs_truth(rr),
        },
        "one_pass": {
            "wall_s": w_one,
            "cpu_s": c_one,
            "member_integration_wall_s": res.wall_s,
            "cpu_ns_per_member_step": c_one / n / n_steps * 1e9,
            "accepted": res.n_accepted,
            "accepted_fraction": res.accepted_fraction,
            "rule_pass_fraction": {k: float(np.mean(v)) for k, v in res.checks.items()},
            "refined": refined_vs_truth(res),
        },
        "tracemalloc_peak_mb": None if peak is None else peak / 2**20,
        "max_rss_mb": rss_mb,
        "loop": {
            "members": a.loop_members,
            "wall_s": loop.wall_s,
            "cpu_s": c_loop,
            "scaled_wall_s": loop_scaled,
            "scaled_cpu_s": loop_scaled_cpu,
            "identical": bool(loop_identical),
        },
        "legacy_loop": legacy,
        "numpy_backend": numpy_ref,
        "dask": dask,
        "truth_offset_from_nominal": d_true.tolist(),
    }
    out = write_benchmark_json(a.out, __file__, results, argv)
    tg = results["target"]
    rows = [
        ("input", desc),
        ("backend / members / chunk", f"{backend} / {n} / {a.chunk_size}"),
        (
            "kernel first call (JIT)",
            "-"
            if jit is None
            else f"{jit['first_call_wall_s']:.2f} s wall, {jit['first_call_cpu_s']:.2f} s CPU "
            f"({'loaded from cache' if jit['from_cache'] else 'compiled'})",
        ),
        (
            f"**target: {passes} x {n} with refinement**",
            f"**{w_tgt:.2f} s wall, {c_tgt:.2f} s CPU** (≤ 8 s: {tg['meets_8s']})",
        ),
        (
            f"per-trajectory loop, same maths (scaled from {a.loop_members})",
            f"{loop_scaled:.0f} s wall, {loop_scaled_cpu:.0f} s CPU (identical: {loop_identical})",
        ),
        (
            "**loop / target**",
            f"**{loop_scaled / w_tgt:.0f}x wall, {loop_scaled_cpu / c_tgt:.0f}x CPU** (≥ 300x: {tg['meets_300x']})",
        ),
    ]
    if legacy is not None:
        rows += [
            (
                f"legacy loop, full strapdown per member (scaled from {a.legacy_members})",
                f"{legacy['scaled_wall_s']:.0f} s wall, {legacy['scaled_cpu_s']:.0f} s CPU; "
                f"{legacy['scaled_wall_s'] / w_tgt:.0f}x the target; events max rel. diff "
                f"{legacy['events_max_rel_diff_vs_vectorised']:.1e}",
            )
        ]
    if numpy_ref is not None:
        rows += [
            (
                f"numpy reference backend (scaled from {a.numpy_members})",
                f"{numpy_ref['scaled_wall_s']:.0f} s wall, {numpy_ref['scaled_cpu_s']:.0f} s CPU "
                f"(identical: {numpy_ref['identical']})",
            )
        ]
    rows += [
        ("one pass wall / CPU [s]", f"{w_one:.2f} / {c_one:.2f}"),
        ("CPU per member-step [ns]", f"{results['one_pass']['cpu_ns_per_member_step']:.1f}"),
        ("tracemalloc peak [MB]", "-" if peak is None else f"{peak / 2**20:.1f}"),
        ("max RSS [MB]", f"{rss_mb:.0f}"),
        ("dask", "-" if dask is None else f"{dask['wall_s']:.2f} s, identical: {dask['identical_to_in_process']}"),
        ("accepted (one pass)", f"{res.n_accepted} ({100 * res.accepted_fraction:.2f} %)"),
        ("accepted per round", ", ".join(str(h["n_accepted"]) for h in rr.rounds)),
        (
            "truth inside 3σ (refined)",
            "-"
            if tg["refined"] is None
            else f"{tg['refined']['truth_inside_3sigma']} (NEES {tg['refined']['nees_truth_9dof']:.1f})",
        ),
    ]
    print("| quantity | value |\n|---|---|")
    for k, v in rows:
        print(f"| {k} | {v} |")
    print(f"\nwritten {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
