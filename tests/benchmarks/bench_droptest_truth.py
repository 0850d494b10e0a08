"""Drop-test truth simulation: compiled (numba) fast path against the numpy reference path.

Run on demand from the repository root (not collected by pytest)::

    nice -n 10 .venv/bin/python tests/benchmarks/bench_droptest_truth.py \\
        [--scenarios droptest droptest_rocks] [--json recordings/benchmarks/droptest_truth.json] [--no-jit]

For each scenario, in one process: CPU time (``time.process_time``) of ``simulate_drop`` with
``fast=True`` (after one warm-up call, so no compile time) beside the named baseline, the pure-numpy
reference path ``fast=False`` (the code before the kernels), and the same for ``design_release``.
Then how far the two truths are apart (max over the history of |Δp_I|, |Δv_I|, |Δa_ng_I|, |Δω_B|)
next to the sensor noise of the scenario, and two yardsticks of the reference's own precision
(both with the fast path, which is cheap): the change from nudging the release point by 1e-12 m,
and the change from tightening DOP853's rtol = atol from 1e-9 to 1e-12 (its truncation error).

JIT cost (unless ``--no-jit``): two fresh subprocesses with one new, empty ``NUMBA_CACHE_DIR``:
the first compiles every kernel (cold), the second loads them from that cache (warm); each reports
the CPU time of its first ``simulate_drop`` of the first scenario and of a second, steady call.

Prints a markdown table; ``--json`` writes the benchmark convention
``{"benchmark", "command", "utc", "machine", "results"}``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.droptest import synthetic as syn  # noqa: E402
from workbench.problems.droptest import truth  # noqa: E402
from workbench.problems.droptest.problem import DropTestProblem  # noqa: E402

SCEN = ROOT / "assets" / "scenarios"

_JIT_CHILD = """
import json, sys, time
c0 = time.process_time()
from pathlib import Path
from workbench.io.scenario import load_scenario
from workbench.problems.droptest import synthetic as syn
from workbench.problems.droptest.problem import DropTestProblem
from workbench.problems.droptest.truth import simulate_drop
st = DropTestProblem().settings(load_scenario(Path(sys.argv[1])))
surf, cfg, lander = syn.surface_of(st.chamber), syn.drop_config(st.synthetic), st.lander
c1 = time.process_time()
simulate_drop(cfg, lander, surf)
c2 = time.process_time()
simulate_drop(cfg, lander, surf)
c3 = time.process_time()
print(json.dumps({"import_s": c1 - c0, "first_call_s": c2 - c1, "steady_call_s": c3 - c2}))
"""


def _inputs(name: str):
    st = DropTestProblem().settings(load_scenario(SCEN / f"{name}.toml"))
    return st, syn.drop_config(st.synthetic), st.lander, syn.surface_of(st.chamber)


def _cpu(fn, *args, **kw):
    c = time.process_time()
    out = fn(*args, **kw)
    return out, time.process_time() - c


def _diff(a: truth.DropTruth, b: truth.DropTruth) -> dict[str, float]:
    """Max over the common history of the differences of two truths (same grid required)."""
    if a.t.size != b.t.size:
        return {"grid_differs": float(abs(a.t.size - b.t.size))}

    def mx(x, y):
        return float(np.max(np.linalg.norm(x - y, axis=-1)))

    return {
        "p_I_m": mx(a.p_I, b.p_I),
        "v_I_mps": mx(a.v_I, b.v_I),
        "a_ng_I_mps2": mx(a.a_ng_I, b.a_ng_I),
        "w_B_radps": mx(a.w_B, b.w_B),
        "events_s": max(abs(a.events[k] - b.events.get(k, np.inf)) for k in a.events),
    }


def _nudged(cfg, lander, surf, eps: float) -> truth.DropTruth:
    """Fast truth with the designed release point moved by ``eps`` [m] along SPF Y."""
    orig = truth.design_release

    def moved(*a, **k):
        p, rig, t_c = orig(*a, **k)
        return p + np.array([0.0, eps, 0.0]), rig, t_c

    truth.design_release = moved
    try:
        return truth.simulate_drop(cfg, lander, surf, fast=True)
    finally:
        truth.design_release = orig


def _noise(st) -> dict[str, float]:
    """1σ per-sample sensor noise of the run with settings ``st`` (``DropSettings``), in the units of :func:`_diff`."""
    g = 9.80665
    out = {
        "accel_mps2": float(st.accelerometer.noise_g) * g,
        "gyro_radps": float(np.radians(st.gyro.noise_dps)),
        "survey_m": float(st.synthetic.survey_sigma_m),
    }
    if st.ranging.enabled:
        out["radar_range_m"] = float(st.ranging.radar_range_sigma_m)
        out["radar_rate_mps"] = float(st.ranging.radar_rate_sigma_mps)
    return out


def bench_scenario(name: str) -> dict:
    sc, cfg, lander, surf = _inputs(name)
    truth.simulate_drop(cfg, lander, surf, fast=True)  # warm-up: compile or load the kernels
    fast, t_fast = _cpu(truth.simulate_drop, cfg, lander, surf, fast=True)
    ref, t_ref = _cpu(truth.simulate_drop, cfg, lander, surf, fast=False)
    _, d_fast = _cpu(truth.design_release, cfg, lander, surf, fast=True)
    _, d_ref = _cpu(truth.design_release, cfg, lander, surf, fast=False)
    tight = truth.simulate_drop(cfg, lander, surf, fast=True, tol=1e-12)
    nudged = _nudged(cfg, lander, surf, 1e-12)
    return {
        "simulate_drop_cpu_s": {"fast": t_fast, "baseline_numpy_reference": t_ref, "speedup": t_ref / t_fast},
        "design_release_cpu_s": {"fast": d_fast, "baseline_numpy_reference": d_ref, "speedup": d_ref / d_fast},
        "samples": int(fast.t.size),
        "fast_vs_reference": _diff(ref, fast),
        "reference_yardsticks": {
            "release_nudged_1e-12_m": _diff(fast, nudged),
            "truncation_tol_1e-9_vs_1e-12": _diff(fast, tight),
        },
        "sensor_noise_1sigma": _noise(sc),
    }


def bench_jit(name: str) -> dict:
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = {}
        for label in ("cold_cache", "warm_cache"):
            r = subprocess.run(
                [sys.executable, "-c", _JIT_CHILD, str(SCEN / f"{name}.toml")],
                env=env,
                cwd=ROOT,
                capture_output=True,
                text=True,
                check=True,
            )
            out[label] = json.loads(r.stdout.strip().splitlines()[-1])
        return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", nargs="+", default=["droptest", "droptest_rocks"])
    ap.add_argument("--json", default=None, help="write results here (e.g. recordings/benchmarks/droptest_truth.json)")
    ap.add_argument("--no-jit", action="store_true", help="skip the cold/warm numba cache subprocesses")
    args = ap.parse_args(argv)

    results: dict = {}
    if not args.no_jit:
        results["jit"] = bench_jit(args.scenarios[0])
    for name in args.scenarios:
        results[name] = bench_scenario(name)
        print(f"[{name}] done", flush=True)

    print("\n| scenario | truth fast [CPU s] | numpy reference [CPU s] | speed-up | design_release fast / ref [s] |")
    print("|---|---|---|---|---|")
    for name in args.scenarios:
        r = results[name]
        s, d = r["simulate_drop_cpu_s"], r["design_release_cpu_s"]
        print(
            f"| {name} | {s['fast']:.2f} | {s['baseline_numpy_reference']:.2f} | {s['speedup']:.1f}x | "
            f"{d['fast']:.3f} / {d['baseline_numpy_reference']:.2f} |"
        )
    print("\n| scenario | compared | max Δp [m] | max Δv [m/s] | max Δa_ng [m/s²] | max Δω [rad/s] |")
    print("|---|---|---|---|---|---|")
    for name in args.scenarios:
        r = results[name]
        rows = [("fast vs reference", r["fast_vs_reference"])] + list(r["reference_yardsticks"].items())
        for label, d in rows:
            if "grid_differs" in d:
                print(f"| {name} | {label} | (output grids differ) | | | |")
                continue
            vals = " | ".join(f"{d[k]:.2e}" for k in ("p_I_m", "v_I_mps", "a_ng_I_mps2", "w_B_radps"))
            print(f"| {name} | {label} | {vals} |")
        print(f"| {name} | sensor noise 1σ | {r['sensor_noise_1sigma']} | | | |")
    if "jit" in results:
        cold, warm = results["jit"]["cold_cache"], results["jit"]["warm_cache"]
        print(
            f"\nJIT ({args.scenarios[0]}): first simulate_drop {cold['first_call_s']:.2f} CPU s with an empty numba "
            f"cache, {warm['first_call_s']:.2f} with a warm cache; steady {warm['steady_call_s']:.2f}"
        )
    if args.json:
        write_benchmark_json(args.json, __file__, results, argv)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
