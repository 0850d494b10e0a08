"""Drop-test benchmark: Monte Carlo accuracy/consistency and speed of the reconstruction.

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_droptest.py [--seeds N] [--seeds-dynamic M]
                                                        [--scheduler local|tcp://...] [--workers 2]

Parts:

1. Monte Carlo (:func:`workbench.problems.droptest.montecarlo.monte_carlo`) over seeds 1..N for the
   IMU-only kinematic, IMU-only dynamic and ranging kinematic configurations → every number of
   :func:`~workbench.problems.droptest.montecarlo.summarize_mc` and the wall time.
2. Speed (IMU-only kinematic, seed 1): whole-process wall time of ``workbench run droptest``
   (subprocess), the stage times of one reconstruction (time between the yields of
   :func:`workbench.problems.droptest.pipeline.reconstruct`), filter steps per second of the production
   forward pass (``forward_pass`` → ``run_filter``) against a plain hand-written baseline loop
   (same ``redland.propagate`` + ``F P Fᵀ + Q`` predict, one stacked update of all the step's
   measurements with ``np.linalg.solve`` and ``P = (I − K H) P``), and peak memory of one
   reconstruction (tracemalloc peak; max RSS of the CLI subprocess).

Prints a markdown table and writes everything (including the per-seed arrays) as JSON to
``recordings/benchmarks/droptest_mc.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import tracemalloc
from dataclasses import fields
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.droptest import model as rl  # noqa: E402
from workbench.problems.droptest import pipeline as dt  # noqa: E402
from workbench.problems.droptest.lander import load_lander  # noqa: E402
from workbench.problems.droptest.montecarlo import McResult, monte_carlo, summarize_mc  # noqa: E402
from workbench.problems.droptest.synthetic import synthesize_droptest  # noqa: E402
from workbench.problems.droptest.telemetry import DropTelemetry  # noqa: E402

SCEN = ROOT / "assets" / "scenarios"
CONFIGS = (
    ("IMU-only kinematic", "droptest.toml", {}),
    ("IMU-only dynamic", "droptest.toml", {"filter.mode": "dynamic"}),
    ("ranging kinematic", "droptest_ranging.toml", {}),
)


# ---------------------------------------------------------------------------------------------
# speed
# ---------------------------------------------------------------------------------------------


def baseline_filter(
    tel: DropTelemetry,
    init: dt.InitialState,
    q_accel: np.ndarray,
    q_angular: np.ndarray,
    r_acc: np.ndarray,
    r_gyr: np.ndarray,
    r_zupt: np.ndarray,
) -> tuple[np.ndarray, float]:
    """Minimal kinematic-mode EKF loop (IMU only): returns (positions (n, 3) [m], wall time [s]).

    Predict: ``redland.propagate`` and ``P = F P Fᵀ + Q`` (``redland.process_noise``). Update: the
    step's valid triads, gyro and (hanging) zero-velocity stacked into one vector (up to 18 rows),
    ``K = (S⁻¹ H P)ᵀ`` by ``np.linalg.solve``, ``x ⊞ K y`` and ``P = (I − K H) P``.
    """
    n = tel.t.size
    x = init.x0.copy()
    P = init.P0.copy()
    n_e = init.P0.shape[0]  # core states + accelerometer bias blocks
    layout = dt.layout_for(len(tel.triads))
    eye = np.eye(n_e)
    H_z = np.zeros((3, n_e))
    H_z[:, rl.EV] = np.eye(3)
    out = np.empty((n, 3))
    g = dt.GRAVITY
    t0 = time.perf_counter()
    for k in range(n):
        if k:
            dtk = tel.t[k] - tel.t[k - 1]
            x, F = rl.propagate(x, dtk, g)
            P = F @ P @ F.T + rl.process_noise(dtk, q_accel[k], q_angular[k], n_e)
        zs, hs, Hs, Rs = [], [], [], []
        for j, r in enumerate(tel.lever_arms_B):
            if tel.f_valid[k, j]:
                h, H = rl.triad_model(x, r, j)
                zs.append(tel.f_B[k, j])
                hs.append(h)
                Hs.append(H)
                Rs.append(r_acc)
        if tel.w_valid[k]:
            h, H = rl.gyro_model(x)
            zs.append(tel.w_B[k])
            hs.append(h)
            Hs.append(H)
            Rs.append(r_gyr)
        if tel.hanging[k]:
            zs.append(np.zeros(3))
            hs.append(x[rl.SV])
            Hs.append(H_z)
            Rs.append(r_zupt)
        if zs:
            y = np.concatenate(zs) - np.concatenate(hs)
            H = np.vstack(Hs)
            R = np.zeros((y.size, y.size))
            for i, Ri in enumerate(Rs):
                R[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = Ri
            HP = H @ P
            S = HP @ H.T + R
            K = np.linalg.solve(S, HP).T
            x = layout.boxplus(x, K @ y)
            P = (eye - K @ H) @ P
        out[k] = x[rl.SP]
    return out, time.perf_counter() - t0


def speed(seed: int = 1) -> dict:
    """Speed and memory numbers on the IMU-only kinematic scenario (see module docstring)."""
    sc = load_scenario(SCEN / "droptest.toml")
    res: dict = {}
    # whole process: the CLI end to end (truth simulation, telemetry, reconstruction, recording)
    with tempfile.TemporaryDirectory() as d:
        cmd = [sys.executable, "-m", "workbench.cli", "run", "droptest", "--out", d, "--seed", str(seed)]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
        res["cli_run_wall_s"] = time.perf_counter() - t0
        res["cli_run_maxrss_MB"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        syn = synthesize_droptest(sc, d, seed=seed)
        res["synthesize_first_s"] = time.perf_counter() - t0  # includes the truth simulation
        dt.run_droptest(sc, syn.telemetry, seed=seed)  # warm-up (imports, caches)
        stages = {}
        t_prev = t0 = time.perf_counter()
        result = None
        for stage in dt.reconstruct(sc, syn.telemetry, seed=seed):
            now = time.perf_counter()
            name = getattr(stage, "name", None) if isinstance(stage, dt.FilterStage) else type(stage).__name__
            stages[name] = now - t_prev
            t_prev = now
            result = stage
        res["stage_s"] = stages
        res["reconstruct_total_s"] = time.perf_counter() - t0
        res["filter_smoother_stroke_s"] = stages["forward"] + stages["smoothed"] + stages["StrokeStage"]
        n = int(result.telemetry.t.size)
        res["steps"] = n

        # production forward pass vs the baseline loop (same telemetry, same initial state)
        lander = load_lander(sc.path_of("vehicle.lander"))
        tel, init = result.telemetry, result.initial
        reps = 3
        tp = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fwd = dt.forward_pass(sc, tel, init, lander)
            tp.append(time.perf_counter() - t0)
        g = sc.get
        rate = g("filter.rate_hz", 1000.0, kind="float")
        n_avg = max(1, int(round(1.0 / (rate * float(np.median(np.diff(tel.imu.time)))))))
        r_acc = (g("sensors.accelerometer.noise_g", kind="float") * dt.G0) ** 2 / n_avg * np.eye(3)
        r_gyr = np.radians(g("sensors.gyro.noise_dps", kind="float")) ** 2 / n_avg * np.eye(3)
        r_z = g("filter.hang_zupt_sigma_mps", kind="float") ** 2 * np.eye(3)
        tb = []
        for _ in range(reps):
            p_base, tb_i = baseline_filter(tel, init, fwd.q_accel, fwd.q_angular, r_acc, r_gyr, r_z)
            tb.append(tb_i)
        sps_p = n / min(tp)
        sps_b = n / min(tb)
        res["filter_steps_per_s_production"] = sps_p
        res["filter_steps_per_s_baseline"] = sps_b
        res["filter_speed_ratio_production_over_baseline"] = sps_p / sps_b
        res["baseline_vs_production_max_position_diff_m"] = float(np.max(np.abs(p_base - fwd.x[:, rl.SP])))

        # peak memory of a single reconstruction (Python + numpy allocations)
        tracemalloc.start()
        dt.run_droptest(sc, syn.telemetry, seed=seed)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        res["reconstruct_peak_tracemalloc_MB"] = peak / 2**20
    res["bench_process_maxrss_MB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return res


# ---------------------------------------------------------------------------------------------
# Monte Carlo
# ---------------------------------------------------------------------------------------------


def run_mc(n_seeds: int, n_dyn: int, scheduler: str | None, workers: int, work: Path) -> dict:
    """Monte Carlo of the three configurations; returns {label: {"summary", "per_seed"}}."""
    out = {}
    for label, file, ov in CONFIGS:
        sc = load_scenario(SCEN / file)
        if ov:
            sc = sc.with_overrides(ov)
        n = n_dyn if "dynamic" in label else n_seeds
        print(f"[bench] {label}: {n} seeds ({scheduler or f'{workers} workers'}) ...", file=sys.stderr, flush=True)
        res: McResult = monte_carlo(sc, range(1, n + 1), work, scheduler=scheduler, workers=workers)
        s = summarize_mc(res)
        print(f"[bench] {label}: {s['total_wall_s']:.0f} s", file=sys.stderr, flush=True)
        per = {
            f.name: np.asarray(getattr(res, f.name)).tolist()
            for f in fields(res)
            if isinstance(getattr(res, f.name), np.ndarray)
        }
        out[label] = {"summary": s, "per_seed": per}
    return out


def _fmt_band(b) -> str:
    return f"[{b[0]:.2f}, {b[1]:.2f}]"


def markdown(mc: dict, sp: dict) -> str:
    """The benchmark as markdown tables."""
    labels = list(mc)
    S = [mc[k]["summary"] for k in labels]
    rows = [
        ("runs", lambda s: f"{s['n_runs']}"),
        ("truth inside reported 3σ", lambda s: f"{100 * s['fraction_inside_3sigma']:.1f} %"),
        ("median reported 3σ [m]", lambda s: f"{s['median_3sigma_m']:.4f}"),
        ("error mean / median [m]", lambda s: f"{s['error_mean_m']:+.4f} / {s['error_median_m']:+.4f}"),
        (
            "|error| median / p95 / max [m]",
            lambda s: f"{s['abs_error_median_m']:.4f} / {s['abs_error_p95_m']:.4f} / {s['abs_error_max_m']:.4f}",
        ),
        ("MER: |err| ≤ 0.10 m and 3σ ≤ 0.10 m", lambda s: f"{100 * s['fraction_mer_requirement']:.1f} %"),
        (
            "pose ANEES, time avg (6 dof; indicative)",
            lambda s: f"{s['anees_pose_time_avg']:.2f} {_fmt_band(s['anees_pose_band'])}",
        ),
        (
            "pose ANEES at max stroke (6 dof)",
            lambda s: (
                f"{s['anees_pose_at_max']:.2f} {_fmt_band(s['anees_pose_band'])}"
                + ("" if s["anees_pose_at_max_inside"] else " **out**")
            ),
        ),
        (
            "max-stroke ANEES (1 dof)",
            lambda s: (
                f"{s['anees_stroke']:.2f} {_fmt_band(s['anees_stroke_band'])}"
                + ("" if s["anees_stroke_inside"] else " **out**")
            ),
        ),
        (
            "restitution |err| median / p95",
            lambda s: f"{s['restitution_abs_error_median']:.4f} / {s['restitution_abs_error_p95']:.4f}",
        ),
        (
            "time-avg NEES p / v / θ / ω (3 dof)",
            lambda s: " / ".join(f"{v:.1f}" for v in s["nees_blocks_time_avg"].values()),
        ),
        (
            "task wall median / reconstruct median [s]",
            lambda s: f"{s['task_wall_median_s']:.2f} / {s['reconstruct_median_s']:.2f}",
        ),
        ("MC wall time [s]", lambda s: f"{s['total_wall_s']:.0f}"),
    ]
    lines = ["| quantity | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for name, f in rows:
        lines.append(f"| {name} | " + " | ".join(f(s) for s in S) + " |")
    lines += [
        "",
        "Mean (δ/σ)² at the max-stroke step per state (1 if consistent; band "
        f"{_fmt_band(S[0]['z2_band'])} for {S[0]['n_runs']} runs):",
        "",
    ]
    names = list(S[0]["z2_at_max_mean"])
    lines.append("| state | " + " | ".join(labels) + " |")
    lines.append("|---|" + "---|" * len(labels))
    for nm in names:
        lines.append(f"| {nm} | " + " | ".join(f"{s['z2_at_max_mean'][nm]:.2f}" for s in S) + " |")
    st = sp["stage_s"]
    lines += [
        "",
        "| speed (IMU-only kinematic, one run) | value |",
        "|---|---|",
        f"| `workbench run droptest` whole process | {sp['cli_run_wall_s']:.1f} s "
        f"(max RSS {sp['cli_run_maxrss_MB']:.0f} MB) |",
        f"| synthesize (first, incl. truth simulation) | {sp['synthesize_first_s']:.1f} s |",
        "| reconstruct stages | " + ", ".join(f"{k} {v:.2f} s" for k, v in st.items()) + " |",
        f"| forward + smoother + stroke | {sp['filter_smoother_stroke_s']:.2f} s ({sp['steps']} steps) |",
        f"| filter steps/s: production / baseline | {sp['filter_steps_per_s_production']:.0f} / "
        f"{sp['filter_steps_per_s_baseline']:.0f} = **{sp['filter_speed_ratio_production_over_baseline']:.2f}** "
        f"(max Δp {sp['baseline_vs_production_max_position_diff_m']:.1e} m) |",
        f"| peak memory of one reconstruction (tracemalloc) | {sp['reconstruct_peak_tracemalloc_MB']:.0f} MB |",
    ]
    return "\n".join(lines)


def _git_state() -> dict:
    """HEAD commit and the modified tracked files (the numbers belong to that working tree)."""

    def git(*a: str) -> str:
        r = subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True)
        return r.stdout.strip() if r.returncode == 0 else ""

    return {"head": git("rev-parse", "HEAD"), "modified": git("diff", "--name-only", "HEAD").splitlines()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=100, help="Monte Carlo runs per configuration (default 100)")
    ap.add_argument("--seeds-dynamic", type=int, default=None, help="runs for the dynamic mode (default --seeds)")
    ap.add_argument("--scheduler", default=None, help="'local' (dask LocalCluster) or 'tcp://host:port'")
    ap.add_argument("--workers", type=int, default=2, help="process-pool workers without --scheduler (default 2)")
    ap.add_argument("--out", default=str(ROOT / "recordings" / "benchmarks" / "droptest_mc.json"))
    ap.add_argument("--no-speed", action="store_true", help="skip the speed part")
    a = ap.parse_args(argv)
    n_dyn = a.seeds if a.seeds_dynamic is None else a.seeds_dynamic
    t0 = time.perf_counter()
    sp = {} if a.no_speed else speed()
    with tempfile.TemporaryDirectory(prefix="droptest_mc_") as d:
        mc = run_mc(a.seeds, n_dyn, a.scheduler, a.workers, Path(d))
    doc = {
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "cpu_count": os.cpu_count(),
        "git": _git_state(),
        "args": vars(a),
        "speed": sp,
        "monte_carlo": mc,
        "bench_wall_s": time.perf_counter() - t0,
    }
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1, default=float))
    if sp:
        print(markdown(mc, sp))
    else:
        print(
            markdown(
                mc,
                {
                    "stage_s": {},
                    **{
                        k: float("nan")
                        for k in (
                            "cli_run_wall_s",
                            "cli_run_maxrss_MB",
                            "synthesize_first_s",
                            "filter_smoother_stroke_s",
                            "steps",
                            "filter_steps_per_s_production",
                            "filter_steps_per_s_baseline",
                            "filter_speed_ratio_production_over_baseline",
                            "baseline_vs_production_max_position_diff_m",
                            "reconstruct_peak_tracemalloc_MB",
                        )
                    },
                },
            )
        )
    print(f"\nwrote {out} (benchmark {doc['bench_wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
