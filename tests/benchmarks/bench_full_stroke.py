"""The drop test's full-stroke check against the truth: how the IMU's sharpest jerk separates a
rigid impact from the bags, over the truth Monte Carlo of every shipped drop-test scenario.

Each member is one shipped drop-test scenario run end to end with a seed of the **validation
stream** (2: the stream no threshold was chosen on; the calibration's stream 3 and the shipped
seeds are not used): truth simulator → telemetry files → reconstruction → summary
(:func:`workbench.problems.runner.evaluate`).  Per member: the ``geometry.full_stroke`` check's
status and value (the sharpest mean-triad jerk after the impact starts [g/s]), the estimated max
stroke and its 1σ, and whether the truth's rigid lander reached the surface.  Reported: the jerk
range of the members whose truth had no full stroke and of those whose truth had one, against
``RIGID_JERK_G_PER_S``; each status count; every member whose check is not OK.

    python tests/benchmarks/bench_full_stroke.py [--members 20] [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

from workbench.problems.calibration import VALIDATION_STREAM, seeds_of, shipped_scenarios  # noqa: E402
from workbench.problems.droptest.physics import RIGID_JERK_G_PER_S  # noqa: E402
from workbench.problems.runner import evaluate  # noqa: E402


def member(args: tuple[str, int]) -> dict:
    """One member: scenario path and seed → the full-stroke check, stroke and truth (or the error)."""
    path, seed = args
    with tempfile.TemporaryDirectory(prefix="wb-fullstroke-") as tmp:
        try:
            s = evaluate(path, Path(tmp), seed)
        except Exception as err:  # a failed member is reported, not hidden
            return {"scenario": Path(path).stem, "seed": seed, "error": f"{type(err).__name__}: {err}"}
    c = next((c for c in s["health"]["checks"] if c["name"] == "geometry.full_stroke"), None)
    ms = s["max_stroke"]
    return {
        "scenario": Path(path).stem,
        "seed": seed,
        "status": None if c is None else c["status"],
        "jerk_g_s": None if c is None else c["value"],
        "threshold_g_s": None if c is None else c["bound"],
        "stroke_m": ms.get("distance_m"),
        "sigma_m": ms.get("sigma_m"),
        "full_stroke_truth": bool(s.get("truth", {}).get("full_stroke_truth", False)),
        "verdict": s["health"]["verdict"],
        "message": None if c is None or c["status"] == "OK" else c["message"],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=20, help="seeds per scenario")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_full_stroke.json"))
    a = ap.parse_args(argv)
    paths = shipped_scenarios("droptest")
    seeds = seeds_of(VALIDATION_STREAM, a.members)
    work = [(str(p), s) for p in paths for s in seeds]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=a.jobs) as ex:
        rows = list(ex.map(member, work))
    wall = time.perf_counter() - t0
    ok = [r for r in rows if "error" not in r and r["jerk_g_s"] is not None]

    def span(rs: list[dict]) -> dict:
        j = np.array([r["jerk_g_s"] for r in rs], float)
        return {"n": int(j.size), "min": float(j.min()) if j.size else None, "max": float(j.max()) if j.size else None}

    results = {
        "members": len(rows),
        "seeds": seeds,
        "scenarios": [p.stem for p in paths],
        "threshold_g_s": RIGID_JERK_G_PER_S,
        "wall_s": round(wall, 1),
        "jerk_no_full_stroke": span([r for r in ok if not r["full_stroke_truth"]]),
        "jerk_full_stroke": span([r for r in ok if r["full_stroke_truth"]]),
        # frame strikes too gentle for the run's own rigid-jerk threshold: only the geometry can call them
        "jerk_full_stroke_below_threshold": span(
            [r for r in ok if r["full_stroke_truth"] and r["jerk_g_s"] <= (r["threshold_g_s"] or RIGID_JERK_G_PER_S)]
        ),
        "status": dict(Counter(r["status"] for r in ok)),
        "not_ok": [r for r in ok if r["status"] != "OK"],
        "failed": [r for r in rows if "error" in r],
        "rows": rows,
    }
    out = write_benchmark_json(a.out, __file__, results, argv)
    print(
        f"{len(rows)} members in {wall:.0f} s: statuses {results['status']}; jerk without a full stroke "
        f"{results['jerk_no_full_stroke']}, with one {results['jerk_full_stroke']} (threshold {RIGID_JERK_G_PER_S:g}); "
        f"failed {len(results['failed'])} -> {out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
