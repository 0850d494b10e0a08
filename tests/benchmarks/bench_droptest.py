"""Drop-test benchmark: Monte Carlo accuracy/consistency and speed of the reconstruction.

Run on demand from the repository root (not collected by pytest)::

    nice -n 10 .venv/bin/python tests/benchmarks/bench_droptest.py --seeds 50 --json docs/results/bench_droptest.json
        [--scheduler local|tcp://...] [--workers 2] [--no-speed]

Parts:

1. Monte Carlo over drops 1..N: every seed is a *different drop* drawn within the REDLand test
   envelope (:func:`workbench.problems.droptest.synthetic.disperse_drop`: impact speeds, release
   attitude, bag pressure, timing, true bungee stiffness; release point and bungee count solved),
   simulated once by the truth simulator and reconstructed three ways from the same telemetry
   draw (:func:`workbench.problems.droptest.montecarlo.run_seed`): IMU-only kinematic, IMU-only
   dynamic, kinematic with range aiding → every number of
   :func:`~workbench.problems.droptest.montecarlo.summarize_mc` (max-stroke error distribution,
   3σ coverage, ANEES with χ² bands, restitution against its reported and its estimation-only σ,
   the spread of the drawn drop parameters) and the wall time.  The one-drop README numbers of
   before (one deterministic drop, sensors redrawn) are printed beside them.
2. Speed (IMU-only kinematic, seed 1): whole-process wall time of ``workbench run droptest``
   (subprocess), the stage times of one reconstruction (time between the yields of
   :func:`workbench.problems.droptest.pipeline.reconstruct`), filter steps per second of the production
   forward pass (``forward_pass``: the compiled recursion of ``droptest.kernel``; see also
   ``bench_ekf_speed.py``) against a plain hand-written baseline loop
   (same ``redland.propagate`` + ``F P Fᵀ + Q`` predict, one stacked update of all the step's
   measurements with ``np.linalg.solve`` and ``P = (I − K H) P``), and peak memory of one
   reconstruction (tracemalloc peak; max RSS of the CLI subprocess).

Prints markdown tables; ``--json PATH`` writes everything (including the per-seed arrays) in the
benchmark convention ``{"benchmark", "command", "utc", "machine", "results"}``.
"""

from __future__ import annotations

import argparse
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

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.core.rotation import quat_to_dcm  # noqa: E402
from workbench.estimation.montecarlo import run_monte_carlo  # noqa: E402
from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.droptest import model as rl  # noqa: E402
from workbench.problems.droptest import pipeline as dt  # noqa: E402
from workbench.problems.droptest.montecarlo import (  # noqa: E402
    McResult,
    SeedResult,
    run_seed,
    stack_results,
    summarize_mc,
)
from workbench.problems.droptest.problem import DropTestProblem  # noqa: E402
from workbench.problems.droptest.synthetic import DROP_PARAMETER_NAMES, synthesize_droptest  # noqa: E402
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


def baseline_noise(st, tel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measurement covariances of :func:`baseline_filter` from the run's settings ``st``: accelerometer
    triad [(m/s²)²] and gyro [(rad/s)²] (3, 3) per-sample noise over the samples averaged into one
    filter step, and the hanging zero-velocity update [(m/s)²] (3, 3)."""
    rate = st.filter.rate_hz
    n_avg = max(1, int(round(1.0 / (rate * float(np.median(np.diff(tel.imu.time)))))))
    r_acc = (st.accelerometer.noise_g * dt.G0) ** 2 / n_avg * np.eye(3)
    r_gyr = np.radians(st.gyro.noise_dps) ** 2 / n_avg * np.eye(3)
    r_z = st.filter.hang_zupt_sigma_mps**2 * np.eye(3)
    return r_acc, r_gyr, r_z


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
            P = F @ P @ F.T + rl.process_noise(dtk, q_accel[k], q_angular[k], quat_to_dcm(x[rl.SQ]), n_e)
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
    sc = DropTestProblem().settings(load_scenario(SCEN / "droptest.toml"))
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
        tel, init = result.telemetry, result.initial
        reps = 3
        tp = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fwd = dt.forward_pass(sc, tel, init)
            tp.append(time.perf_counter() - t0)
        r_acc, r_gyr, r_z = baseline_noise(sc, tel)
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

#: the README table before every seed was a different drop (one deterministic drop, sensors
#: redrawn, 100 seeds; README of commit a67a7fd): IMU-only kinematic / dynamic / ranging
BEFORE_ONE_DROP = {
    "fraction_inside_3sigma": (0.99, 1.00, 1.00),
    "median_3sigma_m": (0.147, 0.147, 0.0047),
    "abs_error_median_m": (0.034, 0.033, 0.0010),
    "anees_stroke": (1.02, 0.99, 0.95),
    "anees_pose_at_max": (7.49, 7.56, 6.41),
    "restitution_abs_error_median": (0.003, 0.003, 0.002),
}


def _seed_task(shared: tuple[list, list[int], str], k: int, _ss) -> dict:
    """Task k: drop ``seeds[k]`` (one truth, cached in this process) reconstructed by every
    configuration; a configuration that raises is recorded as its error message."""
    configs, seeds, work = shared
    out = {}
    for label, sc in configs:
        try:
            out[label] = run_seed(sc, seeds[k], work)
        except Exception as exc:  # noqa: BLE001 - one failed drop must not lose the other 49
            out[label] = f"{type(exc).__name__}: {exc}"
    return out


def run_mc(n_seeds: int, scheduler: str | None, workers: int, work: Path, batch: int = 10, on_batch=None) -> dict:
    """Monte Carlo over drops 1..n_seeds (every seed a different drop, ``disperse_drop``), each
    reconstructed by the three configurations; returns {label: {"summary", "per_seed", "failed"}}.
    Runs in batches of ``batch`` drops and calls ``on_batch(partial_result)`` after each (so a long
    run leaves its numbers so far on disk)."""
    configs = []
    for label, file, ov in CONFIGS:
        sc = load_scenario(SCEN / file)
        configs.append((label, DropTestProblem().settings(sc.with_overrides(ov) if ov else sc)))
    seeds = list(range(1, n_seeds + 1))
    print(f"[bench] {n_seeds} drops x {len(configs)} reconstructions ({scheduler or f'{workers} workers'}) ...",
          file=sys.stderr, flush=True)  # fmt: skip
    t0 = time.perf_counter()
    results: list[dict] = []
    executor = "loop"
    for start in range(0, len(seeds), batch):
        part = seeds[start : start + batch]
        run = run_monte_carlo(
            _seed_task,
            len(part),
            shared=(configs, part, str(work)),
            workers=workers,
            scheduler=scheduler,
            name="bench-droptest",
        )
        results += run.results
        executor = run.executor if run.kind != "loop" else "loop"
        print(
            f"[bench] {len(results)}/{len(seeds)} drops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True
        )
        out = _collect(configs, seeds[: len(results)], results, executor, time.perf_counter() - t0)
        if on_batch is not None:
            on_batch(out)
    return out


def _collect(configs, seeds, results, executor, total) -> dict:
    out = {}
    for label, sc in configs:
        ok = [r[label] for r in results if isinstance(r[label], SeedResult)]
        failed = {
            int(sd): r[label] for sd, r in zip(seeds, results, strict=True) if not isinstance(r[label], SeedResult)
        }
        res: McResult = stack_results(sc.name, sc.filter.mode, ok, executor, total)
        s = summarize_mc(res)
        per = {
            f.name: np.asarray(getattr(res, f.name)).tolist()
            for f in fields(res)
            if isinstance(getattr(res, f.name), np.ndarray)
        }
        out[label] = {"summary": s, "per_seed": per, "failed": failed}
    out["_wall_s"] = total
    return out


def _fmt_band(b) -> str:
    return f"[{b[0]:.2f}, {b[1]:.2f}]"


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def markdown(mc: dict, sp: dict) -> str:
    """The benchmark as markdown tables (after, with the one-drop README numbers before in brackets)."""
    labels = [k for k in mc if not k.startswith("_")]
    S = [mc[k]["summary"] for k in labels]

    def before(key: str, fmt) -> list[str]:
        return [f" (before {fmt(v)})" for v in BEFORE_ONE_DROP[key]]

    def row(name, f, key=None, fmt=None):
        b = before(key, fmt) if key else [""] * len(S)
        return f"| {name} | " + " | ".join(f(s) + bb for s, bb in zip(S, b, strict=True)) + " |"

    lines = ["| quantity | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    lines += [
        row("drops (failed)", lambda s: f"{s['n_runs']} ({len(mc[labels[S.index(s)]]['failed'])})"),
        row("truth inside reported 3σ", lambda s: _pct(s["fraction_inside_3sigma"]), "fraction_inside_3sigma", _pct),
        row("median reported 3σ [m]", lambda s: f"{s['median_3sigma_m']:.4f}", "median_3sigma_m", lambda v: f"{v:.4f}"),
        row("error mean / median [m]", lambda s: f"{s['error_mean_m']:+.4f} / {s['error_median_m']:+.4f}"),
        row(
            "|error| median / p95 / max [m]",
            lambda s: f"{s['abs_error_median_m']:.4f} / {s['abs_error_p95_m']:.4f} / {s['abs_error_max_m']:.4f}",
            "abs_error_median_m",
            lambda v: f"{v:.4f}",
        ),
        row("MER: |err| ≤ 0.10 m and 3σ ≤ 0.10 m", lambda s: _pct(s["fraction_mer_requirement"])),
        row(
            "max-stroke ANEES (1 dof)",
            lambda s: (
                f"{s['anees_stroke']:.2f} {_fmt_band(s['anees_stroke_band'])}"
                + ("" if s["anees_stroke_inside"] else " **out**")
            ),
            "anees_stroke",
            lambda v: f"{v:.2f}",
        ),
        row(
            "pose NEES at max stroke (6 dof)",
            lambda s: (
                f"{s['anees_pose_at_max']:.2f} {_fmt_band(s['anees_pose_band'])}"
                + ("" if s["anees_pose_at_max_inside"] else " **out**")
            ),
            "anees_pose_at_max",
            lambda v: f"{v:.2f}",
        ),
        row("pose ANEES, time avg (6 dof; indicative)", lambda s: f"{s['anees_pose_time_avg']:.2f}"),
        row(
            "restitution |err| median / p95",
            lambda s: f"{s['restitution_abs_error_median']:.4f} / {s['restitution_abs_error_p95']:.4f}",
            "restitution_abs_error_median",
            lambda v: f"{v:.3f}",
        ),
        row(
            "restitution inside 3σ: reported σ / estimation-only σ",
            lambda s: (
                f"{_pct(s.get('restitution_fraction_inside_3sigma', np.nan))} / "
                f"{_pct(s.get('restitution_fraction_inside_3sigma_estimation_only', np.nan))}"
            ),
        ),
        row(
            "restitution |err|/σ median: reported / estimation-only",
            lambda s: (
                f"{s.get('restitution_abs_z_median', np.nan):.2f} / "
                f"{s.get('restitution_abs_z_median_estimation_only', np.nan):.2f}"
            ),
        ),
        row("restitution median σ (reported)", lambda s: f"{s.get('restitution_sigma_median', np.nan):.4f}"),
        row(
            "restitution as before (1 g ends vs touch/leave, estimation σ): |err| median, |err|/σ median, inside 3σ",
            lambda s: (
                f"{s.get('restitution_abs_error_median_before', np.nan):.4f}, "
                f"{s.get('restitution_abs_z_median_before', np.nan):.2f}, "
                f"{_pct(s.get('restitution_fraction_inside_3sigma_before', np.nan))}"
            ),
        ),
        row(
            "restitution vs touch/leave truth: |err| median, inside 3σ",
            lambda s: (
                f"{s.get('restitution_abs_error_median_touch_leave', np.nan):.4f}, "
                f"{_pct(s.get('restitution_fraction_inside_3sigma_touch_leave', np.nan))}"
            ),
        ),
        row(
            "time-avg NEES p / v / θ / ω (3 dof)",
            lambda s: " / ".join(f"{v:.1f}" for v in s["nees_blocks_time_avg"].values()),
        ),
        row(
            "task wall median / reconstruct median [s]",
            lambda s: f"{s['task_wall_median_s']:.2f} / {s['reconstruct_median_s']:.2f}",
        ),
    ]
    lines += [f"\nMonte Carlo wall time {mc['_wall_s']:.0f} s (all three configurations).", ""]
    spread = S[0]["drop_spread"]
    lines += ["| drawn / solved drop parameter | min | median | max |", "|---|---|---|---|"]
    for name in DROP_PARAMETER_NAMES:
        if name in spread:
            d = spread[name]
            lines.append(f"| {name} | {d['min']:.3f} | {d['median']:.3f} | {d['max']:.3f} |")
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
    if sp:
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
    ap.add_argument("--seeds", type=int, default=50, help="different drops, each reconstructed 3 ways (default 50)")
    ap.add_argument("--scheduler", default=None, help="'local' (dask LocalCluster) or 'tcp://host:port'")
    ap.add_argument("--workers", type=int, default=2, help="process-pool workers without --scheduler (default 2)")
    ap.add_argument("--json", default=None, help="write the results as JSON here (benchmark convention)")
    ap.add_argument("--no-speed", action="store_true", help="skip the speed part")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    sp = {} if a.no_speed else speed()

    def write(mc: dict) -> None:
        if not a.json:
            return
        results = {
            "n_drops": len(next(v for k, v in mc.items() if not k.startswith("_"))["per_seed"]["seed"]),
            "n_drops_requested": a.seeds,
            "bench_wall_s": time.perf_counter() - t0,
            "monte_carlo_wall_s": mc["_wall_s"],
            "configurations": {k: v for k, v in mc.items() if not k.startswith("_")},
            "before_one_drop_readme": {
                k: dict(zip([c[0] for c in CONFIGS], v, strict=True)) for k, v in BEFORE_ONE_DROP.items()
            },
            "speed": sp,
            "git": _git_state(),
        }
        out = write_benchmark_json(a.json, __file__, results)
        print(f"wrote {out}", file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory(prefix="droptest_mc_") as d:
        mc = run_mc(a.seeds, a.scheduler, a.workers, Path(d), on_batch=write)
    wall = time.perf_counter() - t0
    print(markdown(mc, sp))  # after the JSON: a formatting slip cannot lose the run
    print(f"benchmark wall time {wall:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
