"""MEADS benchmark: the nominal and failed-port runs against the truth, and the paper's trade study.

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_meads.py [--runs 3000] [--scheduler local]
        [--full-runs 50] [--skip-runs] [--skip-trade] [--json docs/results/bench_meads.json]

Measured, in one run:

* ``workbench run msl_meads`` (the shipped scenario, P5 sticking at 150 s) and the same scenario
  with no failure: max/RMS error above 850 Pa of α, β [deg], q∞ [%], Mach, density [%], p∞ [%],
  winds [m/s] (published, and the unpublished non-singular solution), each against its median
  reported 3σ and the fraction inside 3σ; the other estimator model (Newtonian vs table: the
  model-form error); the EKF passes (mean per-port NIS, errors against their 3σ, pass 1's scale
  factors against the truth's); the wall time of each run;
* the trade study (paper Sect. IV.B.1, Fig. 6): ``--runs`` runs at 0.5/1/2.5/5 % of reading,
  Newtonian pressures, fixed R = 0.001: the 3σ table with the objectives met, on 2 local worker
  processes and (``--scheduler``) on Dask, with a check that both give identical numbers;
* with ``--full-runs N``, the Monte Carlo with the full error model against the truth simulator
  (paper Figs. 11–13, ``workbench mc msl_meads --truth-sim``): N members (each its own dispersed
  truth and sensor errors, least squares + EKF pass 1 + pass 2 from its telemetry files) on
  ``--full-workers`` local processes: per estimator and quantity the Monte Carlo 3σ, the mean
  reported 3σ, their ratio and the fraction inside, the disagreements, the wall time per member;
  with ``--scheduler`` the first ``--full-check-runs`` members again on Dask, checked identical.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.io.assets import assets_dir  # noqa: E402
from workbench.io.scenario import resolve_scenario  # noqa: E402
from workbench.problems.meads.montecarlo import prepare_trade_study, run_trade_study  # noqa: E402
from workbench.problems.meads.problem import MeadsProblem  # noqa: E402
from workbench.problems.meads.truth_mc import run_full_monte_carlo  # noqa: E402
from workbench.problems.runner import run_scenario  # noqa: E402


def _run(scenario, out: Path) -> dict:
    t0 = time.perf_counter()
    r = run_scenario(scenario, out)
    s = r.summary
    return {
        "wall_s": time.perf_counter() - t0,
        "failed_ports": s["failed_ports"],
        "truth": s["truth"],
        "wind_singular_intervals_s": s["wind_singular_intervals_s"],
        "wind_sigma_mps_nonsingular_above_min_qbar": s["wind_sigma_mps_nonsingular_above_min_qbar"],
        "model": s["model"],
        "ekf": s.get("ekf"),
    }


def _print_ekf(name: str, run: dict) -> None:
    """One line per EKF pass: mean per-port NIS and the errors against the reported 3σ."""
    tr = run["truth"]
    for i in (1, 2):
        if f"ekf_pass{i}" not in tr:
            continue
        nis = run["ekf"][f"pass{i}"]["mean_nis_per_port_above_min_qbar"]
        blocks = ", ".join(
            f"{k} {v['max_abs']:.3g}/{v['rms']:.3g}/{100 * v['fraction_within_3sigma']:.0f}%"
            for k, v in tr[f"ekf_pass{i}"].items()
            if v.get("n", 0)
        )
        print(f"{name} EKF pass {i}: NIS/port {[None if v is None else round(v, 3) for v in nis]}; {blocks}")
    sf = tr.get("ekf_scale_factors")
    if sf:
        print(f"{name} scale factors inside 3σ: {sf['fraction_within_3sigma'] * len(sf['estimate']):.0f} of 7")


def _full_mc(sc, args) -> dict:
    """The full-error-model Monte Carlo row (and its Dask check)."""
    res = run_full_monte_carlo(sc, n_runs=args.full_runs, seed=args.seed, workers=args.full_workers)
    s = res.summary
    out = {k: v for k, v in s.items() if k not in ("member_health",)}
    out["member_wall_s_all"] = [m.info["wall_s"] for m in res.members]
    print(
        f"full Monte Carlo: {s['n_ok']}/{s['n_runs']} members, {s['wall_s']:.0f} s, median member "
        f"{s['member_wall_s']['median']:.1f} s",
        flush=True,
    )
    for d in s["disagreements"]:
        print("  ", d, flush=True)
    if args.scheduler:
        n = min(args.full_check_runs, args.full_runs)
        dk = run_full_monte_carlo(sc, n_runs=n, seed=args.seed, workers=2, scheduler=args.scheduler)
        same = all(
            np.array_equal(a.err, b.err, equal_nan=True) and np.array_equal(a.sig, b.sig, equal_nan=True)
            for a, b in zip(res.members[:n], dk.members, strict=True)
        )
        out["dask_check"] = {
            "scheduler": args.scheduler,
            "executor": dk.summary["executor"],
            "members": n,
            "identical_to_processes": bool(same),
        }
        print("full Monte Carlo on dask:", out["dask_check"], flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; print a summary; write the JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3000, help="trade-study runs per error level")
    ap.add_argument("--scheduler", default=None, help="also run the trade study on Dask (local | tcp://...)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip-runs", action="store_true", help="skip the two single runs")
    ap.add_argument("--skip-trade", action="store_true", help="skip the trade study")
    ap.add_argument("--full-runs", type=int, default=0, help="members of the full-error-model Monte Carlo (0: skip)")
    ap.add_argument("--full-workers", type=int, default=2, help="local processes of the full Monte Carlo")
    ap.add_argument(
        "--full-check-runs", type=int, default=2, help="with --scheduler: members of the full Monte Carlo rerun on Dask"
    )
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    results: dict = {}
    sc = resolve_scenario("msl_meads", assets_dir())
    if not args.skip_runs:
        with tempfile.TemporaryDirectory(prefix="bench_meads_") as tmp:
            out = Path(tmp)
            results["run_failed_port"] = _run(sc, out / "failed")
            print("failed-port run:", json.dumps(results["run_failed_port"]["truth"]["final"])[:600], flush=True)
            nominal = sc.with_overrides({"sensors.pressure.failure_port": ""})
            results["run_nominal"] = _run(nominal, out / "nominal")
            print("nominal run:", json.dumps(results["run_nominal"]["truth"]["final"])[:600], flush=True)
            for key in ("run_failed_port", "run_nominal"):
                _print_ekf(key, results[key])
    if not args.skip_trade:
        sh = prepare_trade_study(MeadsProblem().settings(sc))
        ts = run_trade_study(sh, args.runs, args.seed, workers=2, scheduler=None)
        results["trade_study"] = {**ts.summary, "executor_run": "2 local processes"}
        print("trade study:", ts.summary["wall_s"], "s;", json.dumps(ts.summary["table"])[:800], flush=True)
        if args.scheduler:
            td = run_trade_study(sh, args.runs, args.seed, workers=2, scheduler=args.scheduler)
            same = all(
                np.array_equal(ts.three_sigma[lv], td.three_sigma[lv], equal_nan=True)
                and np.array_equal(ts.bias[lv], td.bias[lv], equal_nan=True)
                for lv in ts.levels
            )
            results["trade_study_dask"] = {
                "scheduler": args.scheduler,
                "executor": td.summary["executor"],
                "wall_s": td.wall_s,
                "identical_to_processes": bool(same),
            }
            print("dask:", results["trade_study_dask"], flush=True)
    if args.full_runs > 0:
        results["truth_mc"] = _full_mc(MeadsProblem().settings(sc), args)
    results["wall_time_s"] = time.perf_counter() - t0
    if args.json:
        print(f"wrote {write_benchmark_json(args.json, __file__, results, argv)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
