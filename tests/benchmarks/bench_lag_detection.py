"""Does the drop test's timing check see a mis-declared acquisition filter, and leave honest drops alone?
(issue 26: "the mis-declared-filter drop (zero-phase declared causal, with ranging) → ERROR naming the
timing").

Two sets of ``droptest_ranging`` runs, each judged by ``timing.imu_vs_ranging`` (the IMU-against-ranging
lag over the impact, :func:`workbench.problems.droptest.physics.estimate_lag`):

1. **the mistake**: the scenario's nominal drop with noise seeds 1..K, its IMU through a *zero-phase*
   filter; reconstructed once declared so (right) and once with the shipped declaration, the causal
   4th-order 500 Hz Butterworth (wrong: its 0.83 ms group delay is taken off tags that have none).
   Per seed: the lag, its 1σ, z and the check's status (its own logic: ERROR when significant and the
   shift exceeds 2σ of the max stroke), the margin |lag| / the bound's half-width, and the run's own
   (uncalibrated) verdict.
2. **honest drops**: M dispersed drops of the validation stream (the health calibration's members are
   another stream), each with its own truth: the lag's z = lag/σ (mean, rms, max |z|) and the check's
   calibrated status — how often an honest drop is flagged.

The numbers come from each run's summary (the check's value and message), so the same script measures
any commit.

    python tests/benchmarks/bench_lag_detection.py [--seeds 12] [--members 40] [--jobs 2] [--out FILE]
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

CHECK = "timing.imu_vs_ranging"
SCENARIO = "droptest_ranging"
_LAG = re.compile(r"lag ([+-][\d.]+) ± ([\d.]+) ms")


def _timing(summary: dict) -> dict:
    """The timing check of ``summary``: its status, lag and 1σ [ms] and the fit's reduced χ² (from its
    message; χ² only since the joint fit) and the run's verdict."""
    found = [c for c in summary["health"]["checks"] if c["name"] == CHECK]
    if not found:
        raise SystemExit(f"{CHECK} missing from the run's health (notes: {summary['health'].get('notes')})")
    c = found[0]
    m = _LAG.search(c["message"])
    if m is None:
        raise SystemExit(f"{CHECK}: no lag in its message {c['message']!r}")
    lag, sig = float(m.group(1)), float(m.group(2))
    chi2 = re.search(r"reduced χ² ([\d.]+)", c["message"])  # in the message since the joint fit
    # the ERROR needs |lag| beyond the bound's half-width (the larger of the significance and the
    # 2σ-of-max-stroke shift): |lag| / half is the margin of the decision
    half = 1e3 * float(max(abs(b) for b in c["bound"]))
    out = {"status": c["status"], "lag_ms": lag, "sigma_ms": sig, "z": lag / sig, "bound_half_ms": half}
    return out | {"verdict": summary["health"]["verdict"]} | ({"chi2_red": float(chi2.group(1))} if chi2 else {})


def _mistake(seed: int) -> dict:
    """Nominal drop, noise ``seed``, IMU through a zero-phase filter: declared right and wrong."""
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import load_scenario
    from workbench.problems.droptest import pipeline as dt
    from workbench.problems.droptest.config import DropSettings
    from workbench.problems.droptest.problem import DropTestProblem
    from workbench.problems.droptest.synthetic import synthesize_droptest

    shipped = DropSettings.from_scenario(load_scenario(assets_dir() / "scenarios" / f"{SCENARIO}.toml"))
    zp = replace(shipped, acquisition=replace(shipped.acquisition, filter="zero_phase"))
    with tempfile.TemporaryDirectory(prefix="wb-lag-") as tmp:
        synthesize_droptest(zp, tmp, seed=seed)
        paths = DropTestProblem().telemetry_files(shipped, tmp)
        right = _timing(dt.run_droptest(zp, paths).summary)
        wrong_summary = dt.run_droptest(shipped, paths).summary
    wrong = _timing(wrong_summary)
    wrong["declared_shift_ms"] = 1e3 * wrong_summary["time_shifts_s"]["imu"]
    return {"seed": seed, "right": right, "wrong": wrong}


def _honest(seed: int) -> dict:
    """One dispersed honest drop (validation-stream ``seed``): the raw check and its calibrated status."""
    from workbench.estimation.calibration import calibrate_checks, load_table
    from workbench.io.assets import assets_dir
    from workbench.problems import registry
    from workbench.problems.runner import calibration_path, evaluate

    path = assets_dir() / "scenarios" / f"{SCENARIO}.toml"
    with tempfile.TemporaryDirectory(prefix="wb-lag-") as tmp:
        s = evaluate(path, Path(tmp), seed, calibrated=False)
    out = _timing(s)
    c = next(c for c in s["health"]["checks"] if c["name"] == CHECK)
    judged, _ = calibrate_checks([c], load_table(calibration_path(registry.get("droptest"))))
    out["calibrated_status"] = judged[0]["status"]
    out["seed"] = seed
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=12, help="noise seeds of the mis-declared nominal drop")
    ap.add_argument("--members", type=int, default=40, help="honest dispersed drops, validation stream")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_lag_detection.json"))
    args = ap.parse_args(argv)
    from workbench.problems.calibration import VALIDATION_STREAM, seeds_of

    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as ex:
        mistakes = list(ex.map(_mistake, range(1, args.seeds + 1)))
        honest = list(ex.map(_honest, seeds_of(VALIDATION_STREAM, args.members)))
    wall = time.perf_counter() - t0
    for m in mistakes:
        r, w = m["right"], m["wrong"]
        print(
            f"seed {m['seed']:3d}: right {r['lag_ms']:+.3f} ± {r['sigma_ms']:.3f} ms {r['status']:7s} | "
            f"wrong {w['lag_ms']:+.3f} ± {w['sigma_ms']:.3f} ms (z {w['z']:+.1f}) {w['status']:7s} "
            f"verdict {w['verdict']}"
        )
    z_h = np.array([h["z"] for h in honest])
    z_right = np.array([m["right"]["z"] for m in mistakes])
    z_wrong = np.array([m["wrong"]["z"] for m in mistakes])
    n_err = sum(m["wrong"]["status"] == "ERROR" for m in mistakes)
    summary = {
        "mistake_seeds": args.seeds,
        "wrong_error": n_err,
        "wrong_verdict_error": sum(m["wrong"]["verdict"] == "ERROR" for m in mistakes),
        "right_ok": sum(m["right"]["status"] == "OK" for m in mistakes),
        "wrong_z_min_abs": float(np.min(np.abs(z_wrong))),
        "wrong_z_median": float(np.median(z_wrong)),
        "wrong_lag_ms_median": float(np.median([m["wrong"]["lag_ms"] for m in mistakes])),
        "right_lag_ms_median": float(np.median([m["right"]["lag_ms"] for m in mistakes])),
        "sigma_ms_median": float(np.median([m["wrong"]["sigma_ms"] for m in mistakes])),
        "declared_shift_ms": mistakes[0]["wrong"]["declared_shift_ms"],
        "right_z_rms": float(np.sqrt(np.mean(z_right**2))),
        "honest_members": len(honest),
        "honest_z_mean": float(z_h.mean()),
        "honest_z_rms": float(np.sqrt(np.mean(z_h**2))),
        "honest_z_max_abs": float(np.max(np.abs(z_h))),
        "honest_sigma_ms_median": float(np.median([h["sigma_ms"] for h in honest])),
        "honest_lag_ms_std": float(np.std([h["lag_ms"] for h in honest])),
        "honest_chi2_red_range": [float(f([h.get("chi2_red", np.nan) for h in honest])) for f in (np.nanmin, np.nanmax)]
        if any("chi2_red" in h for h in honest)
        else None,
        "honest_calibrated": {s: sum(h["calibrated_status"] == s for h in honest) for s in ("OK", "WARNING", "ERROR")},
        "honest_own": {s: sum(h["status"] == s for h in honest) for s in ("OK", "WARNING", "ERROR")},
        "wrong_margin_min": float(min(abs(m["wrong"]["lag_ms"]) / m["wrong"]["bound_half_ms"] for m in mistakes)),
        "wall_s": round(wall, 1),
    }
    print(
        f"mistake: ERROR on {n_err}/{args.seeds} (z {summary['wrong_z_median']:+.1f} median, |z| ≥ "
        f"{summary['wrong_z_min_abs']:.1f}); honest: z rms {summary['honest_z_rms']:.2f}, max |z| "
        f"{summary['honest_z_max_abs']:.1f}, calibrated {summary['honest_calibrated']}; {wall:.0f} s"
    )
    write_benchmark_json(args.out, __file__, {"summary": summary, "mistakes": mistakes, "honest": honest}, argv)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
