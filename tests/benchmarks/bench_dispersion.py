"""Dispersion-analysis benchmark (AMELIA Sect. 6): 10 000 members vectorised vs a per-trajectory loop.

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_dispersion.py [--members 10000] [--chunk-size 2000]
        [--loop-members 50] [--scheduler local|tcp://...] [--source scenario|fixture] [--seed 2016]
        [--refine-rounds 0]

Input: ``--source scenario`` (default) synthesizes the ``schiaparelli`` scenario's telemetry
(truth simulator → files), reads and preprocesses it exactly as the pipeline does, and starts the
members about the scenario's (erroneous) nominal state; ``--source fixture`` uses the point-mass
entry of ``tests/support/entry_synth.py`` (no dependency on the entry pipeline).

Measured, in one run:

* wall time of ``run_dispersion`` over ``--members`` members in-process (vectorised over chunks);
* peak memory: tracemalloc peak of a second, traced in-process run (numpy reports its buffers to
  tracemalloc) and the process's max RSS;
* the per-trajectory loop baseline (``run_dispersion_loop``, same maths one member at a time) on
  the first ``--loop-members`` members, scaled to ``--members``; the ratio; and a check that the
  loop's event quantities are bit-identical to the vectorised ones;
* optionally (``--scheduler``) the same run on Dask, with the identity check;
* accepted fraction, refined initial state vs the truth (normalised by the accepted spread);
  with ``--refine-rounds R`` a further run with R importance-sampled refinement rounds (same
  numbers, plus the accepted count and effective sample size per round).

Prints a markdown table and writes JSON to ``recordings/benchmarks/dispersion.json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import resource
import sys
import tempfile
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from workbench.core.rotation import attitude_error  # noqa: E402
from workbench.problems.entry import dispersion as ds  # noqa: E402
from workbench.problems.entry.site import R_GROUND  # noqa: E402


def _scenario_input(seed: int):
    """(imu, nominal (v, q, p), events, truth (v, q, p) at t0, r_ground, description)."""
    from workbench.io.scenario import load_scenario
    from workbench.problems.entry.config import config_for
    from workbench.problems.entry.preprocess import preprocess
    from workbench.problems.entry.synthetic import load_truth, synthesize_entry
    from workbench.problems.entry.telemetry import read_entry_telemetry

    sc = load_scenario(ROOT / "assets" / "scenarios" / "schiaparelli.toml")
    with tempfile.TemporaryDirectory() as d:
        paths = synthesize_entry(sc, d, seed=seed)
        tm = read_entry_telemetry(paths, config_for(sc).checks)
        imu = preprocess(tm, config_for(sc).preprocess)
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--members", type=int, default=10_000)
    ap.add_argument("--chunk-size", type=int, default=2000)
    ap.add_argument("--loop-members", type=int, default=50)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--source", choices=("scenario", "fixture"), default="scenario")
    ap.add_argument("--seed", type=int, default=2016)
    ap.add_argument("--refine-rounds", type=int, default=0, help="importance-sampled refinement rounds")
    ap.add_argument("--out", default=str(ROOT / "recordings" / "benchmarks" / "dispersion.json"))
    a = ap.parse_args(argv)

    if a.source == "scenario":
        imu, nom, events, truth0, r_ground, desc = _scenario_input(1)
    else:
        imu, nom, events, truth0, r_ground, desc = _fixture_input()
    kw = dict(events_t=events, seed=a.seed, r_ground=r_ground)
    v0, q0, p0 = nom

    # 1. vectorised, in-process (timed without tracing)
    res = ds.run_dispersion(imu, v0, q0, p0, None, a.members, chunk_size=a.chunk_size, **kw)
    # 2. the same with tracemalloc for the peak of numpy buffers
    tracemalloc.start()
    res_t = ds.run_dispersion(imu, v0, q0, p0, None, a.members, chunk_size=a.chunk_size, **kw)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert np.array_equal(res.accepted, res_t.accepted)
    # 3. per-trajectory loop on a subset
    loop = ds.run_dispersion_loop(imu, v0, q0, p0, None, a.loop_members, n_cloud=0, **kw)
    loop_identical = all(np.array_equal(loop.events[k], res.events[k][: a.loop_members]) for k in ds.EVENT_NAMES)
    loop_scaled = loop.wall_s / a.loop_members * a.members
    # 4. optional Dask
    dask = None
    if a.scheduler:
        r2 = ds.run_dispersion(imu, v0, q0, p0, None, a.members, chunk_size=a.chunk_size, scheduler=a.scheduler, **kw)
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

    refined = refined_vs_truth(res)
    refine = None
    if a.refine_rounds > 0:
        rr = ds.run_dispersion(imu, v0, q0, p0, None, a.members, chunk_size=a.chunk_size,
                               refine_rounds=a.refine_rounds, **kw)  # fmt: skip
        refine = {
            "rounds": [{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in h.items()} for h in rr.rounds],
            "wall_s": rr.wall_s,
            "refined": refined_vs_truth(rr),
        }
    out = {
        "input": desc,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__},
        "members": a.members,
        "chunk_size": a.chunk_size,
        "imu_samples": int(np.asarray(imu.t).size),
        "gaps": len(imu.gaps),
        "vectorised_wall_s": res.wall_s,
        "vectorised_us_per_member_step": res.wall_s / a.members / (np.asarray(imu.t).size - 1) * 1e6,
        "tracemalloc_peak_mb": peak / 2**20,
        "max_rss_mb": rss_mb,
        "loop_members": a.loop_members,
        "loop_wall_s": loop.wall_s,
        "loop_scaled_wall_s": loop_scaled,
        "loop_over_vectorised": loop_scaled / res.wall_s,
        "loop_identical": bool(loop_identical),
        "dask": dask,
        "accepted": res.n_accepted,
        "accepted_fraction": res.accepted_fraction,
        "rule_pass_fraction": {k: float(np.mean(v)) for k, v in res.checks.items()},
        "truth_offset_from_nominal": d_true.tolist(),
        "refined": refined,
        "refinement": refine,
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=2))
    rows = [
        ("input", desc),
        ("members / chunk", f"{a.members} / {a.chunk_size}"),
        ("vectorised wall [s]", f"{res.wall_s:.2f}"),
        ("per member-step [µs]", f"{out['vectorised_us_per_member_step']:.3f}"),
        ("tracemalloc peak [MB]", f"{peak / 2**20:.1f}"),
        ("max RSS [MB]", f"{rss_mb:.0f}"),
        (f"loop {a.loop_members} members [s]", f"{loop.wall_s:.2f} (scaled {loop_scaled:.0f} s)"),
        ("loop / vectorised", f"{loop_scaled / res.wall_s:.0f}x (identical: {loop_identical})"),
        ("dask", "-" if dask is None else f"{dask['wall_s']:.2f} s, identical: {dask['identical_to_in_process']}"),
        ("accepted", f"{res.n_accepted} ({100 * res.accepted_fraction:.2f} %)"),
        ("truth inside 3σ of refined", "-" if refined is None else str(refined["truth_inside_3sigma"])),
    ]
    if refine is not None:
        last = refine["rounds"][-1]
        rf = refine["refined"]
        rows += [
            (f"refinement ({a.refine_rounds} rounds) wall [s]", f"{refine['wall_s']:.1f}"),
            ("accepted per round", ", ".join(str(h["n_accepted"]) for h in refine["rounds"])),
            ("last round ESS", f"{last['ess']:.0f}"),
            (
                "truth inside 3σ (refined)",
                "-" if rf is None else f"{rf['truth_inside_3sigma']} (NEES {rf['nees_truth_9dof']:.1f})",
            ),
        ]
    print("| quantity | value |\n|---|---|")
    for k, v in rows:
        print(f"| {k} | {v} |")
    print(f"\nwritten {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
