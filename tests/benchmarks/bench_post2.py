"""post2 validation benchmark: the thesis' [R3] Ch. 3.2 cases 1 and 2 through the shipped scenarios.

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_post2.py [--seeds 50] [--json docs/results/bench_post2.json]
    .venv/bin/python tests/benchmarks/bench_post2.py --cases mer --json docs/results/bench_post2_mer.json

Measured:

* **Large J2** (``post2_j2``, Tables 3-1/3-2): J2 error after 1, 4 and 10 observations, final error
  and final error / 3σ (seed 1), and over ``--seeds`` seeds the NEES of the final J2 estimate
  (mean of (error/σ)², χ²(1) mean 1, with its 95 % interval for that many seeds);
* **6-DOF ballistic Mars entry** (``post2_entry6dof``, Tables 3-3..3-5) from each of the three
  perturbed starts of Table 3-5: position error at the start, after 15 s of observations and at
  the end (forward pass and smoothed), mean NIS of both observation channels; for two truths:
  ``model_error`` (the shipped scenario: DOP853 truth with a density wave and CN/Cm factors, the
  estimator with density/CN/Cm multiplier states) and ``model_matched`` (the truth's only
  difference is its integrator; no multiplier states) — the thesis' own setting;
* **MER-type entry with quaternion observations** (``post2_mer_quaternion``, Tables 3-6/3-7, ``--cases
  mer``) from each start of Table 3-7: the errors at the end of the filtered run (forward, smoothed) vs
  the propagation-only run, the NIS, the events and the wall time of a ``workbench run``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.io.assets import assets_dir  # noqa: E402
from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.base import RunOptions  # noqa: E402
from workbench.problems.runner import run_scenario  # noqa: E402

#: Table 3-5 of the thesis: the estimator's three starts (position m, velocity m/s, [α, β, σ] deg,
#: body rates deg/s)
STARTS = {
    "test_case_1": (
        [-2840685.2, -1799150.9, -1070834.3],
        [3530.88, -4172.58, 1337.35],
        [-0.4, 0.4, -0.35],
        [12.010, 0.008, -0.0065],
    ),
    "test_case_2": (
        [-2833267.4, -1796194.1, -1071217.6],
        [3532.75, -4171.23, 1338.67],
        [-0.45, 0.35, 0.2],
        [11.991, -0.008, -0.0045],
    ),
    "test_case_3": (
        [-2824923.5, -1793427.2, -1072989.5],
        [3534.57, -4169.80, 1340.29],
        [0.45, -0.35, -0.25],
        [12.005, -0.009, 0.008],
    ),
}


def _scenario(name: str, overrides: dict, drop: tuple[str, ...] = ()):
    sc = load_scenario(assets_dir() / "scenarios" / f"{name}.toml").with_overrides(overrides)
    for key in drop:
        sc.data["states"].pop(key)
    return sc


def bench_j2(out: Path, seeds: int) -> dict:
    """J2 errors (seed 1) and the NEES of the final estimate over ``seeds`` seeds."""
    r = run_scenario(_scenario("post2_j2", {}), out / "j2", RunOptions(seed=1))
    p = r.summary["truth"]["parameters"]["j2"]
    res = {
        "truth": p["truth"][0],
        "initial_error": p["initial_error"][0],
        "error_after_1_obs": p["error_after_1_obs"][0],
        "error_after_4_obs": p["error_after_4_obs"][0],
        "error_after_10_obs": p["error_after_10_obs"][0],
        "sigma_after_4_obs": p["sigma_after_4_obs"][0],
        "final_error": p["final_error_forward"][0],
        "final_3sigma": p["final_3sigma_forward"][0],
        "final_error_over_3sigma": p["final_error_over_3sigma_forward"][0],
        "wall_time_s": r.summary["wall_time_s"],
    }
    if seeds:
        z2 = []
        for s in range(1, seeds + 1):
            rs = run_scenario(_scenario("post2_j2", {}), out / f"j2_{s}", RunOptions(seed=s))
            q = rs.summary["truth"]["parameters"]["j2"]
            z2.append((3.0 * q["final_error_over_3sigma_forward"][0]) ** 2)
        lo, hi = chi2.ppf([0.025, 0.975], seeds) / seeds
        res["nees"] = {"seeds": seeds, "mean": float(np.mean(z2)), "chi2_95_interval": [float(lo), float(hi)]}
        res["nees"]["inside_interval"] = bool(lo <= res["nees"]["mean"] <= hi)
    return res


def bench_entry(out: Path, variant: str) -> dict:
    """Case 2 from the three starts of Table 3-5, truth ``variant`` (model_error | model_matched)."""
    res = {}
    for case, (p, v, a, w) in STARTS.items():
        ov = {
            "states.position.value": p,
            "states.velocity.value": v,
            "states.attitude.value": a,
            "states.body_rates.value": w,
        }
        drop: tuple[str, ...] = ()
        if variant == "model_matched":
            ov |= {"truth.cn_factor": 1.0, "truth.cm_factor": 1.0, "truth.density_wave_amplitude": 0.0}
            drop = ("density_multiplier", "cn_multiplier", "cm_multiplier")
        t0 = time.perf_counter()
        r = run_scenario(_scenario("post2_entry6dof", ov, drop), out / f"{variant}_{case}", RunOptions(seed=1))
        e = r.summary["truth"]["position_error_m"]
        res[case] = {
            "position_error_start_m": e["start"],
            "position_error_after_15s_m": e["after_15s_forward"],
            "position_error_end_forward_m": e["end_forward"],
            "position_error_end_smoothed_m": e["end_smoothed"],
            "position_error_max_smoothed_m": e["max_smoothed"],
            "position_inside_3sigma_fraction": r.summary["truth"]["position_inside_3sigma_fraction"],
            "mean_nis_acceleration_dim3": r.summary["observations"]["acceleration"]["mean_nis"],
            "mean_nis_rates_dim3": r.summary["observations"]["rates"]["mean_nis"],
            "attitude_error_end_deg": r.summary["truth"]["attitude_error"]["end_forward"],
            "wall_time_s": time.perf_counter() - t0,
        }
        print(
            f"  {variant} {case}: {e['start']:.0f} m -> {e['after_15s_forward']:.0f} m (15 s)"
            f" -> {e['end_forward']:.1f} m",
            flush=True,
        )
    return res


#: Table 3-7 of the thesis: the estimator's three starts of the MER-type case (position m, velocity m/s,
#: [α, β, σ] deg, body rates deg/s)
MER_STARTS = {
    "test_case_1": (
        [-3333672.1, -1343492.7, -201973.4],
        [3361.50, -4527.61, 386.52],
        [-0.25, -1.45, 89.4],
        [11.99, 0.012, 0.008],
    ),
    "test_case_2": (
        [-3333431.0, -1343517.1, -202231.5],
        [3361.64, -4527.64, 386.74],
        [-0.33, -2.00, 90.1],
        [12.005, 0.0075, 0.0038],
    ),
    "test_case_3": (
        [-3333479.0, -1343489.4, -202238.4],
        [3361.60, -4527.64, 386.74],
        [-0.33, -1.29, 90.3],
        [12.0085, -0.0075, -0.0058],
    ),
}


def bench_mer(out: Path) -> dict:
    """Case 3 (``post2_mer_quaternion``, Tables 3-6/3-7) from the three starts of Table 3-7: errors at
    the end, filtered (forward, smoothed) vs propagation-only; NIS; the run's wall time."""
    res = {}
    for case, (p, v, a, w) in MER_STARTS.items():
        ov = {
            "states.position.value": p,
            "states.velocity.value": v,
            "states.attitude.value": a,
            "states.body_rates.value": w,
        }
        t0 = time.perf_counter()
        r = run_scenario(_scenario("post2_mer_quaternion", ov), out / f"mer_{case}", RunOptions(seed=1))
        tr = r.summary["truth"]
        res[case] = {
            "end_error_norm": {
                k: c["end_error_norm"] | {"unit": c["unit"]} for k, c in tr["filtered_vs_propagation"].items()
            },
            "position_error_start_m": tr["position_error_m"]["start"],
            "position_inside_3sigma_fraction": tr["position_inside_3sigma_fraction"],
            "attitude_error_end_deg": tr["attitude_error"]["end_forward"],
            "body_rates_error_end_deg_s": tr["body_rates_error"]["end_forward"],
            "mean_nis": {k: o["mean_nis"] for k, o in r.summary["observations"].items()},
            "events": r.summary["events"],
            "wall_time_s": time.perf_counter() - t0,
        }
        e = res[case]["end_error_norm"]["position"]
        print(
            f"  mer {case}: position error at the end {e['propagation_only']:.0f} m (propagation only)"
            f" -> {e['forward']:.1f} m (filtered)",
            flush=True,
        )
    return res


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; print a summary; write the JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=50, help="seeds of the J2 NEES (0: none)")
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    ap.add_argument(
        "--cases",
        default="j2,entry",
        help="comma-separated: j2, entry, mer (case 3: docs/results/bench_post2_mer.json)",
    )
    args = ap.parse_args(argv)
    cases = args.cases.split(",")
    t0 = time.perf_counter()
    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="bench_post2_") as tmp:
        out = Path(tmp)
        if "j2" in cases:
            results["j2"] = bench_j2(out, args.seeds)
            print("J2:", json.dumps(results["j2"]), flush=True)
        if "entry" in cases:
            results["entry6dof"] = {v: bench_entry(out, v) for v in ("model_error", "model_matched")}
        if "mer" in cases:
            results["mer_quaternion"] = bench_mer(out)
    results["wall_time_s"] = time.perf_counter() - t0
    if args.json:
        print(f"wrote {write_benchmark_json(args.json, __file__, results, argv)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
