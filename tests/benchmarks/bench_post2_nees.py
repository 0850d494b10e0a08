"""post2 case 2 over seeds: NEES of the 6-DOF ballistic Mars entry (thesis [R3] Ch. 3.2.2, Tables 3-3..3-5).

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_post2_nees.py [--seeds 50] [--starts test_case_1,...]
        [--variant shipped|phase1] [--json docs/results/bench_post2_nees.json]

For each of the three perturbed starts of Table 3-5 (the estimator's initial estimate) and each seed
``s``: the truth's initial state is the Table 3-5 truth plus a draw from the stated covariance (the
scenario's ``[states.*] sigma``, Table 3-4; generator seeded ``10_000 + s``), the sensor noise is
seeded ``s``; the synthetic observation files go through the full reconstruction.  Measured per
start: the position error at the start, after 15 s of observations and at the end (forward pass;
mean and max over seeds), and the NEES of the 12 trajectory states (position, velocity, body
small-angle attitude, body rates; :func:`workbench.problems.post2.scoring.trajectory_nees`) averaged
over the seeds (ANEES) at 15 s, at the end and over every grid step after 15 s, with the two-sided
95 % χ² band of an ANEES over that many seeds (``N·ANEES ~ χ²(12 N)``); plus the mean NIS of both
observation channels and the final error / 3σ of the CN and Cm multipliers.

``--variant phase1`` runs the system-noise settings of the phase-1 scenario (large random-walk PSDs on
velocity, attitude and body rates, which covered the RK4 stage error of the quaternion-norm bug fixed
in the model) on the current model.  ``--members DIR`` keeps one JSON per member so that a long study
can be stopped and summarised (``--summarize-only``) with the members it has.
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
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)
from bench_post2 import STARTS  # noqa: E402

from workbench.estimation.consistency import anees_bounds  # noqa: E402
from workbench.io.assets import assets_dir  # noqa: E402
from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.post2 import pipeline  # noqa: E402
from workbench.problems.post2.problem import Post2Problem  # noqa: E402
from workbench.problems.post2.scoring import score, trajectory_nees  # noqa: E402

#: the phase-1 estimator settings of post2_entry6dof.toml (before the integration-error fix)
PHASE1 = {
    "model.step_s": 0.025,
    "states.velocity.psd": 1e-7,
    "states.attitude.psd": 1e-6,
    "states.body_rates.psd": 1e-5,
}


def member(start: str, seed: int, variant: str, out: Path, t_end: float | None = None, extra=None) -> dict:
    """One run: start ``start`` of Table 3-5, seed ``seed``; returns the numbers of one member."""
    p, v, a, w = STARTS[start]
    base = load_scenario(assets_dir() / "scenarios" / "post2_entry6dof.toml")
    tr = base.data["truth"]["states"]
    rng = np.random.default_rng(10_000 + seed)
    disp = {}
    for name in ("position", "velocity", "attitude", "body_rates"):
        sd = np.asarray(base.data["states"][name]["sigma"], dtype=float) * np.ones(3)
        disp[f"truth.states.{name}"] = (np.asarray(tr[name], dtype=float) + sd * rng.standard_normal(3)).tolist()
    ov = {
        "states.position.value": p,
        "states.velocity.value": v,
        "states.attitude.value": a,
        "states.body_rates.value": w,
        **disp,
    }
    if variant == "phase1":
        ov |= PHASE1
    if t_end is not None:
        ov["model.t_end_s"] = t_end
    ov |= dict(extra or {})
    sc = base.with_overrides(ov)
    prob = Post2Problem()
    settings = prob.settings(sc)
    syn = prob.synthesize(settings, out / f"{start}_{seed}", seed)
    truth = prob.load_truth(syn.truth)
    res = None
    for stage in pipeline.reconstruct(settings, dict(syn.telemetry)):
        res = stage
    sc_ = score(res, truth)
    nees = trajectory_nees(res, truth)
    e = sc_["position_error_m"]
    obs = res.summary["observations"]
    params = {k: q["final_error_over_3sigma_forward"][0] for k, q in sc_["parameters"].items()}
    return {
        "seed": seed,
        "position_error_m": [e["start"], e["after_15s_forward"], e["end_forward"]],
        "t": nees["t"],
        "nees_forward": nees["forward"],
        "nees_smoothed": nees["smoothed"],
        "dim": nees["dim"],
        "nis": {k: o["mean_nis"] for k, o in obs.items()},
        "param_error_over_3sigma": params,
    }


def summarize(members: list[dict]) -> dict:
    """ANEES at 15 s / the end / averaged after 15 s with the χ² band, position errors, NIS."""
    n = len(members)
    dim = members[0]["dim"]
    t = members[0]["t"]
    k15 = int(np.searchsorted(t, t[0] + 15.0 - 1e-9))
    lo, hi = anees_bounds(dim, n, 0.95)
    out: dict = {"seeds": n, "dim": dim, "anees_band_95": [lo, hi]}
    for label in ("forward", "smoothed"):
        N = np.array([m[f"nees_{label}"] for m in members])  # (n, steps)
        an = N.mean(axis=0)
        out[f"anees_{label}"] = {
            "at_15s": float(an[k15]),
            "at_end": float(an[-1]),
            "time_mean_after_15s": float(an[k15:].mean()),
            "fraction_of_steps_inside_band_after_15s": float(np.mean((an[k15:] >= lo) & (an[k15:] <= hi))),
            "fraction_of_steps_above_band_after_15s": float(np.mean(an[k15:] > hi)),
        }
    pe = np.array([m["position_error_m"] for m in members])
    out["position_error_m"] = {
        "start_mean": float(pe[:, 0].mean()),
        "after_15s_mean": float(pe[:, 1].mean()),
        "after_15s_max": float(pe[:, 1].max()),
        "end_mean": float(pe[:, 2].mean()),
        "end_max": float(pe[:, 2].max()),
    }
    out["mean_nis"] = {k: float(np.mean([m["nis"][k] for m in members])) for k in members[0]["nis"]}
    out["param_error_over_3sigma"] = {
        k: {
            "mean": float(np.mean([m["param_error_over_3sigma"][k] for m in members])),
            "fraction_inside": float(np.mean([abs(m["param_error_over_3sigma"][k]) <= 1.0 for m in members])),
        }
        for k in members[0]["param_error_over_3sigma"]
    }
    return out


def _save_member(d: Path, start: str, seed: int, m: dict, wall: float) -> None:
    d.mkdir(parents=True, exist_ok=True)
    rec = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in m.items()} | {"wall_time_s": wall}
    (d / f"{start}_seed{seed:03d}.json").write_text(json.dumps(rec), encoding="utf-8")


def _load_members(d: Path) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for f in sorted(d.glob("*_seed*.json")):
        start = f.name.rsplit("_seed", 1)[0]
        m = json.loads(f.read_text(encoding="utf-8"))
        for k in ("t", "nees_forward", "nees_smoothed"):
            m[k] = np.asarray(m[k])
        out.setdefault(start, []).append(m)
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the NEES study (each member saved to ``--members``); summarise what is there; write the JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=50, help="seeds per start")
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--starts", default=",".join(STARTS), help="comma-separated Table 3-5 starts")
    ap.add_argument("--variant", choices=("shipped", "phase1"), default="shipped")
    ap.add_argument("--t-end", type=float, default=None, help="shorten the run (s); default: the scenario's")
    ap.add_argument("--set", action="append", default=[], help="scenario override key=value (value as JSON)")
    ap.add_argument("--members", type=Path, default=None, help="directory of per-member results (kept)")
    ap.add_argument("--summarize-only", action="store_true", help="only summarise the members already there")
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    args = ap.parse_args(argv)
    extra = {k: json.loads(v) for k, v in (a.split("=", 1) for a in args.set)}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_post2_nees_") as tmp:
        mdir = args.members or Path(tmp) / "members"
        if not args.summarize_only:
            for start in args.starts.split(","):
                for s in range(args.first_seed, args.first_seed + args.seeds):
                    tm = time.perf_counter()
                    m = member(start, s, args.variant, Path(tmp), args.t_end, extra)
                    _save_member(mdir, start, s, m, time.perf_counter() - tm)
                    print(
                        f"  {start} seed {s}: pos err {m['position_error_m'][0]:.0f} -> {m['position_error_m'][1]:.1f}"
                        f" -> {m['position_error_m'][2]:.1f} m; NEES end {m['nees_forward'][-1]:.2f}"
                        f" ({time.perf_counter() - tm:.0f} s)",
                        flush=True,
                    )
        members = _load_members(mdir)
    results: dict = {"variant": args.variant, "overrides": extra, "t_end_s": args.t_end, "starts": {}}
    for start, ms in members.items():
        results["starts"][start] = summarize(ms) | {
            "seeds_run": sorted(int(m.get("seed", -1)) for m in ms),
            "member_wall_time_s_mean": float(np.mean([m["wall_time_s"] for m in ms])),
        }
        print(start, json.dumps(results["starts"][start]), flush=True)
    results["wall_time_s"] = time.perf_counter() - t0
    if args.json:
        print(f"wrote {write_benchmark_json(args.json, __file__, results, argv)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
