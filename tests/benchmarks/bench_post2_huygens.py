"""post2 case 4 benchmark: the Huygens-like descent at Titan (thesis [R3] Ch. 4-5).

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_post2_huygens.py [--seeds 50] [--mc-members 10000]
        [--loop-members 200] [--skip-nominal] [--stream validation|tuning] [--entropy N]
        [--json docs/results/bench_post2_huygens.json]

Seeds: member i of a study draws its sensor noise, its initial state and (``--draw-parameters``) its
parameters from ``np.random.SeedSequence(entropy, spawn_key=(k, i))`` with k = 1 for the tuning
stream and k = 2 for the validation stream (disjoint by construction); tuning may use any member of
the tuning stream, a number that claims consistency comes from the validation stream.  Both are
recorded in the JSON.

Measured:

* **nominal** — the shipped scenario (seed 1): the planted-vs-recovered table (each planted
  parameter's final smoothed value, error, 3σ, tolerance, PASS/FAIL), the MC selection summary,
  wall time of the run;
* **nees** — over ``--seeds`` truths, each with its own sensor noise AND its own initial state drawn
  from the Table 4-2 covariance (the planted parameter deviations kept): the NEES of the estimated
  parameter vector (final smoothed, the parameters' full covariance block) against the χ² band of
  its mean (95 %), per-parameter error/σ statistics and the fraction inside 3σ; the NEES of the end
  position (3) and end velocity (3) and the position NEES averaged over the grid, each with its
  band; the main chute's deploy time is read by the reconstruction from each run's accelerometer
  files (``[events.main_chute] detect_in``; :func:`deploy_time_from_telemetry`, the same reading,
  is recorded beside it).  The JSON
  is rewritten after every run, so a cut-short study still reports the runs it completed.  With
  ``--draw-parameters NAME,...`` (or ``all``) those parameters of each truth are ALSO drawn from
  the estimator's prior (:func:`draw_parameters`): the NEES is χ²(d) only for truths distributed
  as the filter assumes; with one fixed planted value, a parameter the data hardly inform adds its
  fixed (planted − prior)²/σ² to every run whatever the filter does (ca_multiplier_fm: the
  posterior is the prior, planted 1.8σ off: z² = 3.2; ca_multiplier_hyp: posterior/prior σ ≈ 0.8,
  planted 2σ off: z² ≈ 2.9 over 50 seeds — the CA multipliers' prior IS Table 4-1's dispersion);
* **mc_selection** — the Monte Carlo initial-state selection's member propagation: ``--mc-members``
  members vectorised (one array) vs the same maths one member at a time over ``--loop-members``
  members (the loop's wall time scaled to the vectorised count), in the same process.
"""

from __future__ import annotations

import argparse
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
from workbench.io.telemetry import read_telemetry  # noqa: E402
from workbench.problems.base import RunOptions  # noqa: E402
from workbench.problems.post2 import huygens  # noqa: E402
from workbench.problems.post2.config import Post2Settings, unit_factor  # noqa: E402
from workbench.problems.post2.model import STATES, scurve, scurve_inverse, scurve_slope  # noqa: E402
from workbench.problems.post2.pipeline import read_observations  # noqa: E402
from workbench.problems.post2.problem import Post2Problem  # noqa: E402
from workbench.problems.post2.scoring import trajectory_nees, truth_on_grid  # noqa: E402
from workbench.problems.runner import run_scenario  # noqa: E402

TOML = assets_dir() / "scenarios" / "post2_huygens.toml"
PARAMS = (
    "ca_multiplier_fm", "ca_multiplier_hyp", "ca_multiplier_sup", "parachute_drag_multiplier",
    "drogue_drag_multiplier", "accel_bias", "tilt", "wind_vertical", "radar_scale_factor",
)  # fmt: skip


def deploy_time_from_telemetry(folder: Path) -> float:
    """Main-chute deploy time [s]: the first rise of |a| by > 1 m/s² between consecutive samples of
    the entry + deploy accelerometer files after the entry pulse's peak (midpoint of the two samples)."""
    t, a = [], []
    for name in ("accel_entry", "accel_deploy"):
        tel = read_telemetry(folder / f"{name}.csv")
        t.append(tel.time)
        a.append(np.abs(tel.stack(("ax",))[:, 0]))
    t, a = np.concatenate(t), np.concatenate(a)
    k0 = int(np.argmax(a))
    jump = np.flatnonzero(np.diff(a[k0:]) > 1.0)
    k = k0 + int(jump[0])
    return 0.5 * (t[k] + t[k + 1])


def draw_parameters(cfg, seed: int, names=PARAMS) -> dict:
    """One draw of the parameters ``names`` (of PARAMS) from the estimator's prior:
    ``{"truth.states.<name>": value}`` in the file's unit (deg for tilt); N(value, σ²) in the
    estimated coordinate, through the S-curve for a bounded state (the distribution the filter's
    P0 describes); each parameter from its own stream ``[seed, i]`` (the same draw whatever else is drawn)."""
    out = {}
    for i, name in enumerate(PARAMS):
        rng = np.random.default_rng([seed, i])
        if name not in names:
            continue
        s = cfg.state(name)
        v, sd = np.asarray(s.value, float), np.asarray(s.sigma, float)
        if s.bounds is not None:
            raw = scurve_inverse(v, *s.bounds)
            v = scurve(raw + sd / scurve_slope(raw, *s.bounds) * rng.standard_normal(v.shape), *s.bounds)
        else:
            v = v + sd * rng.standard_normal(v.shape)
        v = v / unit_factor(STATES[name].unit)
        out[f"truth.states.{name}"] = v.tolist() if v.size > 1 else float(v[0])  # scalars as numbers
    return out


STREAMS = {"tuning": 1, "validation": 2}


def member_seeds(entropy: int, stream: str, i: int) -> dict:
    """The integer seeds of member ``i`` of ``stream`` (``STREAMS``): ``noise`` (sensor noise and the
    run's options), ``state`` (the truth's initial state), ``params`` (its drawn parameters), from
    ``np.random.SeedSequence(entropy, spawn_key=(STREAMS[stream], i))``."""
    a, b, c = np.random.SeedSequence(entropy, spawn_key=(STREAMS[stream], i)).generate_state(3)
    return {"noise": int(a), "state": int(b), "params": int(c)}


def _rows(summary: dict) -> list[dict]:
    return summary["truth"]["planted_vs_recovered"]


def bench_nominal(out: Path) -> dict:
    """The shipped scenario, seed 1."""
    t0 = time.perf_counter()
    r = run_scenario(load_scenario(TOML), out / "nominal", RunOptions(seed=1))
    wall = time.perf_counter() - t0
    rows = _rows(r.summary)
    return {
        "wall_s": wall,
        "planted_vs_recovered": rows,
        "all_pass": all(x["pass"] for x in rows),
        "passed": [x["parameter"] for x in rows if x["pass"]],
        "failed": [x["parameter"] for x in rows if not x["pass"]],
        "mc_initial_state": r.summary.get("mc_initial_state"),
        "observations": {
            k: {"mean_nis": v["mean_nis"], "verdict": v["nis_verdict"]} for k, v in r.summary["observations"].items()
        },  # fmt: skip
        "position_error_m": {k: v for k, v in r.summary["truth"]["position_error_m"].items()},
    }


def _one_seed(seeds: dict, out: Path, draw: tuple[str, ...] = ()) -> dict:
    """A dispersed truth (initial state from the covariance, seed ``seeds["state"]``; sensor noise
    ``seeds["noise"]``; the parameters ``draw`` from the estimator's prior, seed ``seeds["params"]``,
    :func:`draw_parameters`) and its reconstruction."""
    prob = Post2Problem()
    sc0 = load_scenario(TOML)
    cfg = Post2Settings.from_scenario(sc0)
    mean = np.concatenate([cfg.state("position").value, cfg.state("velocity").value])
    x_true = huygens.dispersed_members(mean, huygens.delivered_covariance(cfg), 2, seed=seeds["state"])[1]
    sc = sc0.with_overrides(
        {
            "truth.states.position": x_true[:3].tolist(),
            "truth.states.velocity": x_true[3:].tolist(),
            **draw_parameters(cfg, seeds["params"], draw),
        }
    )
    seed = seeds["noise"]
    tel_dir = out / f"seed{seed}"
    syn = prob.synthesize(prob.settings(sc), tel_dir, seed)
    t_dep = deploy_time_from_telemetry(tel_dir)  # the reconstruction reads it itself ([events] detect_in)
    truth = prob.load_truth(syn.truth)
    opts = RunOptions(seed=seed)
    res = None
    for stage in prob.reconstruct(prob.settings(sc), syn.telemetry, opts):
        res = stage
    sm = res.smap
    idx, err = [], []
    for name in PARAMS:
        b = sm.blocks[name]
        h = res.history["smoothed"][name]
        tv = np.atleast_1d(truth[f"param_{name}"]).astype(float)
        e0 = b.se.start  # scalar parameters; the bias: its axial (x) component
        idx.append(e0)
        # error in the estimated (unbounded) coordinate: the covariance lives there
        v_phys, s_phys = h["value"][-1][0], h["sigma"][-1][0]
        raw_sigma = np.sqrt(res.P[-1][e0, e0])
        err.append((v_phys - tv[0]) * raw_sigma / max(s_phys, 1e-300))
    P = res.P[-1][np.ix_(idx, idx)]
    err = np.asarray(err)
    nees = float(err @ np.linalg.solve(P, err))
    traj = {}
    tg = truth_on_grid(truth, res.t)
    for name in ("position", "velocity"):
        ii = np.arange(sm.blocks[name].se.start, sm.blocks[name].se.stop)
        e = sm.raw(res.x[-1], name) - tg[name][-1]
        Pe = res.P[-1][np.ix_(ii, ii)]
        traj[name] = {
            "end_nees": float(e @ np.linalg.solve(Pe, e)),
            "end_error": e.tolist(),
            "end_sigma": np.sqrt(np.diag(Pe)).tolist(),
            "grid_mean_nees_smoothed": float(np.mean(trajectory_nees(res, truth, (name,))["smoothed"])),
        }
    rows = huygens.planted_table(res, truth)
    return {
        "seeds": seeds,
        "start_error_m": float(np.linalg.norm(sm.raw(res.x[0], "position") - tg["position"][0])),
        "mc_initial_state": res.summary.get("mc_initial_state"),
        "trajectory": traj,
        "deploy_time_s": t_dep,
        "deploy_time_reconstruction_s": next(e["t_s"] for e in res.summary["events"] if e["event"] == "main_chute"),
        "truth_event_time_s": float(truth["event_times"][0]),
        "nees": nees,
        "z": (err / np.sqrt(np.diag(P))).tolist(),
        "pass": {r["parameter"]: r["pass"] for r in rows},
    }


def _band(n: int, d: int) -> list[float]:
    """Two-sided 95 % band of the mean of n χ²(d) values."""
    return (chi2.ppf([0.025, 0.975], n * d) / n).tolist()


def _verdict(mean: float, band: list[float]) -> str:
    lo, hi = band
    return "consistent" if lo <= mean <= hi else ("conservative" if mean < lo else "overconfident")


def bench_nees(
    out: Path, seeds: int, json_path: Path, results: dict, argv, draw: tuple[str, ...] = (),
    stream: str = "validation", entropy: int = 0, first: int = 0,
) -> dict:  # fmt: skip
    """NEES of the parameter vector, the end position and the end velocity over ``seeds`` dispersed
    truths (members ``first`` … of ``stream``; JSON rewritten after each)."""
    runs = []
    d = len(PARAMS)
    t_all = time.perf_counter()
    for i in range(first, first + seeds):
        t0 = time.perf_counter()
        r = _one_seed(member_seeds(entropy, stream, i), out, draw)
        r["member"] = i
        r["wall_s"] = time.perf_counter() - t0
        runs.append(r)
        n = len(runs)
        z = np.array([x["z"] for x in runs])
        band = _band(n, d)
        mean = float(np.mean([x["nees"] for x in runs]))
        traj = {}
        for name in ("position", "velocity"):
            m_end = float(np.mean([x["trajectory"][name]["end_nees"] for x in runs]))
            m_grid = float(np.mean([x["trajectory"][name]["grid_mean_nees_smoothed"] for x in runs]))
            tr = [x["trajectory"][name] for x in runs]
            ze = np.array([np.divide(q["end_error"], q["end_sigma"]) for q in tr])
            traj[name] = {
                "end_mean_nees": m_end,
                "end_band_95": _band(n, 3),
                "end_verdict": _verdict(m_end, _band(n, 3)),
                "end_per_axis_mean_z2": np.mean(ze**2, axis=0).tolist(),
                "end_per_axis_inside_3sigma": np.mean(np.abs(ze) <= 3.0, axis=0).tolist(),
                "grid_mean_nees_smoothed": m_grid,
            }
        results["nees"] = {
            "seed_stream": {
                "stream": stream,
                "spawn_key": [STREAMS[stream], "member"],
                "entropy": entropy,
                "members": [x["member"] for x in runs],
                "rule": "SeedSequence(entropy, spawn_key=(1, i)) tuning, (2, i) validation",
            },
            "runs_completed": n,
            "runs_requested": seeds,
            "dimension": d,
            "parameters": list(PARAMS),
            "parameters_drawn_from_prior": list(draw),
            "mean_nees": mean,
            "band_95": band,
            "verdict": _verdict(mean, band),
            "trajectory": traj,
            "start_error_m_mean": float(np.mean([x["start_error_m"] for x in runs])),
            "per_parameter_mean_z": dict(zip(PARAMS, np.mean(z, axis=0).tolist(), strict=True)),  # bias
            "per_parameter_mean_z2": dict(zip(PARAMS, np.mean(z**2, axis=0).tolist(), strict=True)),
            "per_parameter_inside_3sigma": dict(zip(PARAMS, np.mean(np.abs(z) <= 3.0, axis=0).tolist(), strict=True)),
            "wall_s_total": time.perf_counter() - t_all,
            "wall_s_per_run_mean": float(np.mean([x["wall_s"] for x in runs])),
            "runs": runs,
        }
        write_benchmark_json(json_path, __file__, results, argv)
        tp, tv = traj["position"], traj["velocity"]
        print(
            f"{stream} member {i}: NEES params {r['nees']:.2f} (mean {mean:.2f}, band {band[0]:.2f}..{band[1]:.2f});"
            f" end position {r['trajectory']['position']['end_nees']:.2f} (mean {tp['end_mean_nees']:.2f}),"
            f" velocity {r['trajectory']['velocity']['end_nees']:.2f} (mean {tv['end_mean_nees']:.2f}),"
            f" band(3) {tp['end_band_95'][0]:.2f}..{tp['end_band_95'][1]:.2f}; {r['wall_s']:.0f} s",
            flush=True,
        )
    return results["nees"]


def bench_mc(out: Path, members: int, loop_members: int) -> dict:
    """Vectorised member propagation vs a per-member loop of the same maths (same process)."""
    prob = Post2Problem()
    sc = load_scenario(TOML)
    cfg = Post2Settings.from_scenario(sc)
    short = sc.with_overrides({"model.t_end_s": 300.0})  # the entry phase is all the selection reads
    for k in [k for k in short.data["observations"] if k != "accel_entry"]:
        short.data["observations"].pop(k)
    for k in ("front_shield_release", "drogue"):
        short.data["events"].pop(k)
    for k, sched in list(short.data.get("schedules", {}).items()):  # schedules tied to a dropped event
        if sched.get("end_event") in ("front_shield_release", "drogue") or sched.get("start_event") in (
            "front_shield_release",
            "drogue",
        ):
            short.data["schedules"].pop(k)
    short_settings = prob.settings(short)
    syn = prob.synthesize(short_settings, out / "mc", 1)
    data = read_observations(short_settings, syn.telemetry)
    ch = data.channels[cfg.monte_carlo.observation]
    sel = huygens.select_initial_state(cfg, ch, members, seed=1)
    model = huygens.entry_model(cfg)
    mc = cfg.monte_carlo
    h = float(mc.step_s)
    n_steps = int(np.ceil((mc.end_s + 60.0 - cfg.t_start) / h))
    t0 = time.perf_counter()
    m, s = huygens.member_loop_metric(
        model, sel.members[:loop_members], cfg.t_start, h, n_steps, ch.t, ch.z_raw[:, 0],
        float(mc.align_level_m_s2), float(mc.end_s),
    )  # fmt: skip
    loop = time.perf_counter() - t0
    same = bool(np.allclose(m, sel.metric[:loop_members], rtol=1e-9) and np.allclose(s, sel.shift_s[:loop_members]))
    return {
        "members": members,
        "vectorised_wall_s": sel.wall_s,
        "loop_members": loop_members,
        "loop_wall_s": loop,
        "loop_wall_s_scaled_to_members": loop * members / loop_members,
        "speedup": loop * members / loop_members / sel.wall_s,
        "loop_equals_vectorised": same,
        "rk4_step_s": h,
        "steps": n_steps,
        "selection": sel.summary(),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--mc-members", type=int, default=10_000)
    ap.add_argument("--loop-members", type=int, default=200)
    ap.add_argument("--skip-nominal", action="store_true")
    ap.add_argument("--skip-mc", action="store_true")
    ap.add_argument("--draw-parameters", default="", help="NAME,... or 'all': NEES truths' parameters from the prior")
    ap.add_argument("--stream", choices=tuple(STREAMS), default="validation", help="seed stream of the NEES truths")
    ap.add_argument("--entropy", type=int, default=20261204, help="SeedSequence entropy of the NEES truths")
    ap.add_argument("--first-member", type=int, default=0)
    ap.add_argument("--json", type=Path, default=ROOT / "docs" / "results" / "bench_post2_huygens.json")
    args = ap.parse_args(argv)
    argv = sys.argv[1:] if argv is None else argv
    results: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        if not args.skip_mc:
            results["mc_selection"] = bench_mc(out, args.mc_members, args.loop_members)
            print("mc", {k: v for k, v in results["mc_selection"].items() if k != "selection"}, flush=True)
            write_benchmark_json(args.json, __file__, results, argv)
        if not args.skip_nominal:
            results["nominal"] = bench_nominal(out)
            for r in results["nominal"]["planted_vs_recovered"]:
                print(r, flush=True)
            write_benchmark_json(args.json, __file__, results, argv)
        if args.seeds > 0:
            draw = PARAMS if args.draw_parameters == "all" else tuple(filter(None, args.draw_parameters.split(",")))
            if set(draw) - set(PARAMS):
                ap.error(f"--draw-parameters: not among {PARAMS}: {sorted(set(draw) - set(PARAMS))}")
            bench_nees(out, args.seeds, args.json, results, argv, draw, args.stream, args.entropy, args.first_member)
    write_benchmark_json(args.json, __file__, results, argv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
