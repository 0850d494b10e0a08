"""Entry Monte Carlo against the 6-DOF truth simulator, full pipeline from telemetry files.

Run on demand from the repository root (not collected by pytest)::

    nice -n 10 .venv/bin/python tests/benchmarks/bench_entry_truth_mc.py --runs 50 --members 2000
        [--refine-rounds 1] [--scheduler pool|local|loop|tcp://...] [--workers 2] [--seed 1] [--json PATH]

Every member (``workbench.problems.entry.truth_mc.run_truth_monte_carlo``): a dispersed truth spec,
the truth simulator, telemetry files written as a user supplies them, the reconstruction exactly
as ``workbench run`` does it (preprocessing, dispersion with ``--members`` members and
``--refine-rounds`` rounds, iterated smoother), scored against the member's truth.  Prints the
ANEES (9 dof) per epoch against the 95 % χ² band and the altitude error at the radar fix; with
``--json PATH`` writes the benchmark JSON convention (``benchmark``, ``command``, ``utc``,
``machine``, ``results``: ANEES per epoch with the band, fraction of steps in band, RMS error vs
RMS σ at the end, altitude error after the fix vs 3σ, NIS per channel, radar noise simulated vs
the filter's R, wall time).  ``--runs`` members take ~20-40 s each on one core.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.entry.montecarlo import headline_numbers  # noqa: E402
from workbench.problems.entry.problem import EntryProblem  # noqa: E402
from workbench.problems.entry.truth_mc import run_truth_monte_carlo  # noqa: E402

SCHEDULERS = {"pool": "processes", "loop": "loop", "local": "local"}


def _table(r: dict) -> str:
    lo, hi = r["anees_band_95"]
    L = [
        f"## Entry Monte Carlo vs the truth simulator — {r['n_ok']}/{r['n_runs']} members, "
        f"95 % band {lo:.2f}–{hi:.2f} (9 dof)",
        "",
        "| epoch | t [s] | smoothed | curvilinear | forward | forward curvilinear |",
        "|---|---|---|---|---|---|",
    ]
    for ep, v in r["anees_at"].items():
        L.append(
            f"| {ep} | {v['t_s']:.2f} | {v['smoothed']:.2f} | {v['smoothed_curvilinear']:.2f} | "
            f"{v['forward']:.2f} | {v['forward_curvilinear']:.2f} |"
        )
    ta = r["anees_time_avg"]
    L += [
        "",
        f"time-averaged: smoothed {ta['smoothed']:.2f}, curvilinear {ta['smoothed_curvilinear']:.2f}, forward "
        f"{ta['forward']:.2f}; steps in band {r['fraction_of_steps_in_band']}",
        "RMS at end (error, σ): "
        + ", ".join(f"{k} {v['rms_error']:.3g}/{v['rms_sigma']:.3g}" for k, v in r["rms_at_end"].items()),
        f"altitude at fix: {r.get('h_agl_at_fix')}",
        f"NIS: {r['nis_mean']}",
        f"radar noise simulated {r.get('radar_noise_simulated')}; filter R {r.get('filter_R')}",
    ]
    return "\n".join(L)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "assets" / "scenarios" / "schiaparelli.toml"))
    ap.add_argument("--runs", type=int, default=50, help="Monte Carlo members (default 50)")
    ap.add_argument("--members", type=int, default=2000, help="dispersion members per reconstruction")
    ap.add_argument("--refine-rounds", type=int, default=1, help="dispersion refinement rounds per reconstruction")
    ap.add_argument("--seed", type=int, default=1, help="base seed (member k: SeedSequence(seed, spawn_key=(k,)))")
    ap.add_argument("--scheduler", default="pool", help="pool | local | loop | tcp://host:port")
    ap.add_argument("--workers", type=int, default=2, help="processes of the pool / LocalCluster")
    ap.add_argument("--json", default=None, help="write the benchmark JSON here")
    a = ap.parse_args(argv)

    sc = EntryProblem().settings(load_scenario(a.scenario))
    t0 = time.perf_counter()
    res = run_truth_monte_carlo(
        sc,
        n_runs=a.runs,
        seed=a.seed,
        members=a.members,
        refine_rounds=a.refine_rounds,
        scheduler=SCHEDULERS.get(a.scheduler, a.scheduler),
        workers=a.workers,
    )
    wall = time.perf_counter() - t0
    s = res.summary
    r = headline_numbers(s)
    r.update(
        {
            "dispersion_members": s["members_per_dispersion"],
            "refine_rounds": s["refine_rounds"],
            "dispersion_accepted": s.get("dispersion_accepted"),
            "smoother_start_modes": s.get("smoother_start_modes"),
            "epoch_spread_s": s.get("epoch_spread_s"),
            "truth_dispersion_model": s["truth_dispersion_sigmas"],
            "covariance_symmetric_pd_all": s.get("covariance_symmetric_pd_all"),
            "failures": s["failures"],
            "executor": s["executor"],
            "member_wall_median_s": s.get("member_wall_median_s"),
            "wall_time_s": wall,
        }
    )
    ok = [m for m in res.members if not m.scores.failed]
    r["median_nees_at"] = {
        lab: float(np.median([m.info["nees_stage"][lab] for m in ok if lab in m.info["nees_stage"]]))
        for lab in r["anees_at"]
    }
    r["per_member"] = [
        {
            "smoother_start": m.info["smoother_start"],
            "dispersion_accepted": m.info["dispersion"]["accepted"],
            "nees_at": m.info["nees_stage"],
            "h_agl_error_at_fix_m": m.info["h_agl_error_at_fix_m"],
            "h_agl_3sigma_at_fix_m": m.info["h_agl_3sigma_at_fix_m"],
        }
        for m in ok
    ]
    print(_table(r))
    if a.json:
        path = write_benchmark_json(a.json, __file__, r, argv)
        print(f"\nwrote {path} (wall {wall:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
