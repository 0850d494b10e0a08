"""post2 case 4 benchmark: the Huygens-like descent at Titan (thesis [R3] Ch. 4-5).

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_post2_huygens.py [--seeds 50] [--mc-members 10000]
        [--loop-members 200] [--skip-nominal] [--stream validation|tuning] [--entropy N] [--workers 2]
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
* **nees** — ``workbench mc post2_huygens --truth-sim``'s study
  (:mod:`workbench.problems.post2.truth_mc`) over ``--seeds`` truths on ``--workers`` processes,
  each with its own sensor noise, its own initial state drawn from the Table 4-2 covariance and the
  parameters of ``--draw-parameters`` (default the scenario's ``[truth]
  monte_carlo_draw_from_prior``; ``all``) drawn from the estimator's prior (the other planted
  deviations kept): the NEES of the estimated parameter vector (final smoothed, the parameters' full
  covariance block) against the χ² band of its mean (95 %), per-parameter error/σ statistics and the
  fraction inside 3σ; the NEES of the end position (3) and end velocity (3) and the position NEES
  averaged over the grid, each with its band.  The NEES is χ²(d) only for truths distributed as the
  filter assumes: with one fixed planted value, a parameter the data hardly inform adds its fixed
  (planted − prior)²/σ² to every run whatever the filter does (ca_multiplier_fm: the posterior is the
  prior, planted 1.8σ off: z² = 3.2 — the CA multipliers' prior IS Table 4-1's dispersion);
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

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.io.assets import assets_dir  # noqa: E402
from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.base import RunOptions  # noqa: E402
from workbench.problems.post2 import huygens  # noqa: E402
from workbench.problems.post2.config import Post2Settings  # noqa: E402
from workbench.problems.post2.pipeline import read_observations  # noqa: E402
from workbench.problems.post2.problem import Post2Problem  # noqa: E402
from workbench.problems.post2.truth_mc import parameter_names, run_truth_monte_carlo  # noqa: E402
from workbench.problems.runner import run_scenario  # noqa: E402

TOML = assets_dir() / "scenarios" / "post2_huygens.toml"


def bench_nominal(out: Path) -> dict:
    """The shipped scenario, seed 1."""
    t0 = time.perf_counter()
    r = run_scenario(load_scenario(TOML), out / "nominal", RunOptions(seed=1))
    wall = time.perf_counter() - t0
    rows = r.summary["truth"]["planted_vs_recovered"]
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


def bench_nees(seeds: int, draw: tuple[str, ...] | None, stream: str, entropy: int, first: int, workers: int) -> dict:
    """NEES of the parameter vector, the end position and the end velocity over ``seeds`` dispersed
    truths (members ``first`` … of ``stream``): :func:`workbench.problems.post2.truth_mc.run_truth_monte_carlo`,
    the study ``workbench mc post2_huygens --truth-sim`` runs, on ``workers`` processes."""
    prob = Post2Problem()
    cfg = prob.settings(load_scenario(TOML))
    res = run_truth_monte_carlo(
        prob, cfg, n_runs=seeds, entropy=entropy, stream=stream, first=first, workers=workers, draw=draw
    )  # fmt: skip
    s = res.summary
    tp, tv = s["trajectory"]["position"], s["trajectory"]["velocity"]
    print(
        f"{stream} members {first}-{first + seeds - 1}: NEES params {s['mean_nees']:.2f} (band {s['band_95'][0]:.2f}.."
        f"{s['band_95'][1]:.2f}, {s['verdict']}); end position {tp['end_mean_nees']:.2f} ({tp['end_verdict']}), "
        f"velocity {tv['end_mean_nees']:.2f} ({tv['end_verdict']}); {s['wall_s']:.0f} s on {s['workers']} workers",
        flush=True,
    )
    return {**s, "wall_s_total": s["wall_s"], "wall_s_per_run_mean": float(np.mean([r["wall_s"] for r in s["runs"]]))}


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
    ap.add_argument(
        "--draw-parameters",
        default="",
        help="NAME,... or 'all' (default: the scenario's [truth] monte_carlo_draw_from_prior)",
    )
    ap.add_argument("--workers", type=int, default=2, help="processes of the NEES study")
    ap.add_argument(
        "--stream", choices=("tuning", "validation"), default="validation", help="seed stream of the NEES truths"
    )
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
            cfg = Post2Settings.from_scenario(load_scenario(TOML))
            params = parameter_names(cfg)
            draw = None  # the scenario's [truth] monte_carlo_draw_from_prior
            if args.draw_parameters:
                draw = params if args.draw_parameters == "all" else tuple(args.draw_parameters.split(","))
                if set(draw) - set(params):
                    ap.error(f"--draw-parameters: not among {params}: {sorted(set(draw) - set(params))}")
            results["nees"] = bench_nees(args.seeds, draw, args.stream, args.entropy, args.first_member, args.workers)
    write_benchmark_json(args.json, __file__, results, argv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
