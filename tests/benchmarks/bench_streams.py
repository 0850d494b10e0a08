"""Consistency on the seeds a problem was tuned on against the validation seed stream (issue #29 item 2).

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_streams.py [--seeds 50] [--problems droptest,msl_meads,schiaparelli]
        [--json docs/results/bench_streams.json]
    .venv/bin/python tests/benchmarks/bench_streams.py --table      # print the table of the JSON

Per problem, ``workbench mc <scenario> --truth-sim --seeds N --workers 2`` three times: with
``--first-seed 1`` (the members the drop test's, the entry smoother's and the first MEADS EKF defaults
were chosen on — the MEADS EKF on members 0–7 of it), with ``--stream tuning`` (``SeedSequence(20261204,
spawn_key=(1,))``: where a setting is chosen now) and with ``--stream validation`` (spawn key 2, never
used to choose a setting). The consistency numbers of each study are read from
its ``<name>_truth.mc.json``. The Huygens case (post2) has its own streams in
``bench_post2_huygens.py`` (``--stream tuning`` / ``validation``); its two committed JSONs are read
here, not re-run.
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

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

RESULTS = ROOT / "docs" / "results"
PROBLEMS = ("droptest", "msl_meads", "schiaparelli")
STREAMS = {
    "first seed 1 (earlier defaults chosen on)": ["--first-seed", "1"],
    "tuning stream": ["--stream", "tuning"],
    "validation stream": ["--stream", "validation"],
}


def run_mc(scenario: str, seeds: int, extra: list[str], out: Path) -> dict:
    """The scenario's truth Monte Carlo (2 workers) with ``extra`` seed arguments; its JSON and wall [s]."""
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "workbench.cli", "mc", scenario, "--truth-sim", "--seeds", str(seeds),
           "--workers", "2", "--out", str(out), "--quiet", *extra]  # fmt: skip
    subprocess.run(cmd, cwd=ROOT, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    doc = json.loads((out / f"{scenario}_truth.mc.json").read_text())
    return {"summary": doc, "wall_s": time.perf_counter() - t0}


def metrics(scenario: str, s: dict) -> dict:
    """The consistency numbers of a study's JSON ``s`` (one flat dict: name -> value; bands as lists)."""
    if scenario.startswith("droptest"):
        return {
            "truth max stroke inside 3σ": s["fraction_inside_3sigma"],
            "max-stroke ANEES (1 dof)": s["anees_stroke"],
            "max-stroke ANEES band": s["anees_stroke_band"],
            "pose ANEES, time average": s["anees_pose_time_avg"],
            "pose ANEES band": s["anees_pose_band"],
            "restitution inside 3σ": s["restitution_fraction_inside_3sigma"],
        }
    if scenario == "schiaparelli":
        return {
            "smoothed ANEES, time average (9 dof)": s["anees_time_avg"],
            "ANEES band": s["anees_band"],
            "share of steps with ANEES in band": s["anees_fraction_of_steps_in_band"],
            "forward-filter ANEES, time average": s["anees_forward_time_avg"],
            "truth inside 3σ (mean over steps)": s["inside_3sigma_mean"],
            "altitude after the radar fix inside 3σ": s["h_agl_after_fix"]["mean_fraction_steps_inside_3sigma"],
        }
    if scenario == "msl_meads":
        out = {}
        for est in ("least_squares", "ekf_pass2"):
            for q in ("alpha_deg", "beta_deg", "qbar_pct", "mach"):
                row = s["table"][est][q]
                out[f"{est} {q}: inside reported 3σ"] = row["fraction_inside_reported_3sigma"]
                out[f"{est} {q}: reported 3σ / 3 RMS"] = row["ratio_to_3rms_median"]
        return out
    raise ValueError(f"no consistency metrics for {scenario}")


def post2_rows() -> dict:
    """The Huygens NEES of the committed tuning and validation JSONs (bench_post2_huygens.py)."""
    out = {}
    for name, stream in (("tuning stream", "tuning"), ("validation stream", "validation")):
        path = RESULTS / f"bench_post2_huygens_{stream}.json"
        if not path.is_file():
            continue
        n = json.loads(path.read_text())["results"]["nees"]
        tp = n["trajectory"]["position"]
        out[name] = {
            "members": n["runs_completed"],
            "metrics": {
                "parameter NEES (9 dof)": n["mean_nees"],
                "parameter NEES band": n["band_95"],
                "end position NEES (3 dof)": tp["end_mean_nees"],
                "end position NEES band": tp["end_band_95"],
            },
            "source": path.name,
        }
    return out


def _fmt(v) -> str:
    if isinstance(v, list):
        return f"{v[0]:.2f}–{v[1]:.2f}"
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def markdown(res: dict) -> str:
    """One table per problem: each consistency number on the tuned-on seeds and on the validation stream."""
    lines = []
    for sc, by_stream in res["problems"].items():
        names = list(by_stream)
        keys = list(next(iter(by_stream.values()))["metrics"])
        members = " / ".join(str(by_stream[n]["members"]) for n in names)
        lines += [f"**{sc}** ({members} members)", "", f"| | {' | '.join(names)} |", "|---" * (len(names) + 1) + "|"]
        for k in keys:
            lines.append(f"| {k} | {' | '.join(_fmt(by_stream[n]['metrics'].get(k)) for n in names)} |")
        lines.append("")
    return "\n".join(lines)


def markdown_of(results_dir: Path = RESULTS) -> str:
    """The "tuning vs validation" section of docs/RESULTS.md from ``bench_streams.json``."""
    doc = json.loads((results_dir / "bench_streams.json").read_text())
    return (
        "## Consistency on the seeds tuned on vs the validation stream (issue #29 item 2)\n\n"
        "Each study on the members its earlier defaults were chosen on (first seed 1), on the tuning stream "
        "(where a setting is chosen now) and on the validation seed stream, which no setting was chosen on; "
        "a cell's member count is the members reconstructed (a failed member is listed in the JSON). "
        f"`{doc['command']}` ({doc['utc'][:10]}).\n\n" + markdown(doc["results"])
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--problems", default=",".join(PROBLEMS))
    ap.add_argument("--json", default=str(RESULTS / "bench_streams.json"))
    ap.add_argument("--table", action="store_true")
    a = ap.parse_args(argv)
    if a.table:
        print(markdown(json.loads(Path(a.json).read_text())["results"]))
        return 0
    problems: dict = {}
    with tempfile.TemporaryDirectory(prefix="bench_streams_") as tmp:
        for sc in a.problems.split(","):
            problems[sc] = {}
            for name, extra in STREAMS.items():
                r = run_mc(sc, a.seeds, extra, Path(tmp) / f"{sc}_{extra[-1]}")
                s = r["summary"]
                problems[sc][name] = {
                    "members": s.get("n_ok", s.get("n_runs", a.seeds)),
                    "failed_members": s.get("failed_members", []),
                    "wall_s": r["wall_s"],
                    "seeds": s.get("seeds"),
                    "metrics": metrics(sc, s),
                }
                print(f"[{sc}] {name}: {r['wall_s']:.0f} s", flush=True)
    p2 = post2_rows()
    if p2:
        problems["post2_huygens"] = p2
    results = {"seeds": a.seeds, "problems": problems}
    write_benchmark_json(a.json, __file__, results, argv)
    print(markdown(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
