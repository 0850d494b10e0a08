"""Entry smoother validation benchmark (AMELIA Sect. 8): ≥ 100 simulated trajectories from the accepted set.

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_entry_validation.py [--runs 100] [--members N]
        [--refine-rounds R] [--scheduler local|tcp://...] [--workers 2] [--seed 1] [--json PATH]

Steps: synthesize the shipped ``schiaparelli`` scenario's telemetry
(:func:`workbench.problems.entry.synthetic.synthesize_entry`, scenario seed), run the
reconstruction stages up to the dispersion with the scenario's settings
(:func:`workbench.problems.entry.montecarlo.prepare_validation`; ``--members`` / ``--refine-rounds``
override ``[dispersion] members`` / ``refine_rounds``), then
:func:`~workbench.problems.entry.montecarlo.validate_smoother` with ``--runs`` runs (default: the
scenario's ``[validation] runs``, else 100) from the smoother start the pipeline uses
(``[reconstruction] initial``; truths from that start's Gaussian unless it is the paper's
"dispersion" start) or, with ``--paper``, AMELIA's setting (refined state, truths from the
accepted set).  Prints the ANEES (9 dof; Cartesian and curvilinear,
smoothed and forward) at the summary epochs against the 95 % χ² band, the RMS errors (with the
RMS of the reported 1σ) and the altitude after the radar fix, and writes everything — summary,
per-run scalars, wall times — to ``recordings/benchmarks/entry_validation.json``; ``--json PATH``
also writes the benchmark JSON convention (``benchmark``, ``command``, ``utc``, ``machine``,
``results``: the headline numbers of
:func:`~workbench.problems.entry.montecarlo.headline_numbers` and the wall time).  This is the
self-consistency check (truths from the filter's own model, radar noise at the filter's R); the
Monte Carlo against the truth simulator is ``bench_entry_truth_mc.py``.
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

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.io.results import to_jsonable  # noqa: E402
from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.entry.montecarlo import (  # noqa: E402
    ValidationSettings,
    headline_numbers,
    prepare_validation,
    validate_smoother,
)
from workbench.problems.entry.problem import EntryProblem  # noqa: E402
from workbench.problems.entry.synthetic import synthesize_entry  # noqa: E402


def _table(s: dict) -> str:
    lo, hi = s["anees_band"]
    L = [
        f"## Entry smoother validation — {s['n_ok']}/{s['n_runs']} runs, 95 % band {lo:.2f}–{hi:.2f} (9 dof)",
        "",
        "| epoch | t [s] | smoothed | curvilinear | forward | forward curvilinear |",
        "|---|---|---|---|---|---|",
    ]
    for k, v in s["anees_at"].items():
        L.append(
            f"| {k} | {s['times_s'][k]:.2f} | {v:.2f} | {s['anees_curvilinear_at'][k]:.2f} | "
            f"{s['anees_forward_at'][k]:.2f} | {s['anees_forward_curvilinear_at'][k]:.2f} |"
        )
    L += [
        "",
        f"time-averaged ANEES: smoothed {s['anees_time_avg']:.2f}, curvilinear {s['anees_curvilinear_time_avg']:.2f}, "
        f"forward {s['anees_forward_time_avg']:.2f}, forward curvilinear {s['anees_forward_curvilinear_time_avg']:.2f}",
        "",
        "| epoch | " + " | ".join(next(iter(s["rms_at"].values()))) + " |",
        "|---|" + "---|" * len(next(iter(s["rms_at"].values()))),
    ]
    for k, row in s["rms_at"].items():
        sig = s["rms_sigma_at"][k]
        L.append(f"| {k} | " + " | ".join(f"{v:.3g} ({sig[n]:.3g})" for n, v in row.items()) + " |")
    h = s.get("h_agl_after_fix")
    if h:
        L += ["", "altitude AGL after the fix: " + ", ".join(f"{k} {v:.3g}" for k, v in h.items())]
    L += ["", "NIS: " + ", ".join(f"{k} {v['value']:.2f} (dof {v['dof']})" for k, v in s["nis_mean"].items())]
    return "\n".join(L)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "assets" / "scenarios" / "schiaparelli.toml"))
    ap.add_argument("--runs", type=int, default=None, help="validation runs (default: [validation] runs, else 100)")
    ap.add_argument("--members", type=int, default=None, help="dispersion members (default: scenario)")
    ap.add_argument("--refine-rounds", type=int, default=None, help="dispersion refinement rounds (default: scenario)")
    ap.add_argument("--seed", type=int, default=1, help="base seed of the validation runs")
    ap.add_argument("--scheduler", default=None, help="dask: 'local' or 'tcp://host:8786'")
    ap.add_argument("--workers", type=int, default=2, help="local worker processes without --scheduler")
    ap.add_argument(
        "--paper",
        action="store_true",
        help="AMELIA's setting: start from the dispersion's refined state, truths from the accepted set "
        "(default: the scenario's [reconstruction] initial start)",
    )
    ap.add_argument("--out", default=str(ROOT / "recordings" / "benchmarks" / "entry_validation.json"))
    ap.add_argument("--json", default=None, help="also write the benchmark JSON convention here")
    a = ap.parse_args(argv)

    sc = load_scenario(a.scenario)
    if a.refine_rounds is not None:
        sc = sc.with_overrides({"dispersion.refine_rounds": int(a.refine_rounds)})
    n_runs = int(a.runs if a.runs is not None else sc.get("validation.runs", 100, kind="int"))
    name, sc = sc.name, EntryProblem().settings(sc)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_entry_validation_") as tmp:
        paths = synthesize_entry(sc, Path(tmp) / "telemetry")
        t1 = time.perf_counter()
        inp = prepare_validation(sc, paths, members=a.members, scheduler=a.scheduler)
    t2 = time.perf_counter()
    d = inp.dispersion
    print(
        f"synthesis {t1 - t0:.1f} s; preprocessing + dispersion {t2 - t1:.1f} s: "
        f"{int(d.accepted.sum())}/{d.accepted.size} accepted",
        file=sys.stderr,
    )
    kw = inp.validation_kwargs()
    if a.paper:  # AMELIA: the refined state, truths from the accepted set
        kw = {k: v for k, v in kw.items() if k not in ("start", "truth_initial")}
    elif "start" in kw:
        print(f"smoother start {inp.start_mode!r} ({inp.start_note}): truths drawn from N(start, P0)", file=sys.stderr)
    if int(d.accepted.sum()) < 2 and "start" not in kw:
        print("too few accepted members: pass --refine-rounds 2 or more --members", file=sys.stderr)
        return 1
    res = validate_smoother(
        inp.imu,
        inp.nominal,
        d,
        inp.radar_times,
        ValidationSettings(n_runs=n_runs, seed=a.seed, scheduler=a.scheduler, workers=a.workers, **kw),
    )
    s = res.summary
    print(_table(s))
    out = {
        "scenario": name,
        "argv": sys.argv[1:],
        "synthesis_s": t1 - t0,
        "prepare_s": t2 - t1,
        "validation_s": res.wall_s,
        "smoother_start": "dispersion (paper)" if a.paper else inp.start_mode,
        "smoother_start_note": inp.start_note,
        "dispersion": {
            "members": int(d.accepted.size),
            "accepted": int(d.accepted.sum()),
            "wall_s": float(d.wall_s),
            "refined_sigma": np.sqrt(np.diag(d.refined_P0)).tolist(),
            "rounds": getattr(d, "rounds", []),
        },
        "summary": s,
        "per_run": {
            "member": res.member,
            "failed": res.failed,
            "nees_time_avg": res.nees_time_avg,
            "nees_curvilinear_time_avg": res.nees_curvilinear_time_avg,
            "nees_end": res.nees[:, -1],
            "nees_curvilinear_end": res.nees_curvilinear[:, -1],
            "inside_3sigma": res.inside_3sigma,
            "h_err_max_after_fix_m": res.h_err_max_after_fix,
            "h_3sigma_at_max_m": res.h_3sigma_at_max,
            "nis_mean": res.nis_mean,
            "run_wall_s": res.run_wall_s,
        },
    }
    path = Path(a.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(to_jsonable(out), indent=1))
    print(f"\nwrote {path} (total {time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    if a.json:
        r = headline_numbers(s)
        r.update(
            {
                "truths": "self-consistency: the filter's own discrete model on the clean preprocessed IMU, "
                "radar noise at the filter's R",
                "smoother_start": out["smoother_start"],
                "dispersion_members": int(d.accepted.size),
                "dispersion_accepted": int(d.accepted.sum()),
                "failures": s["failures"],
                "executor": s["executor"],
                "synthesis_s": t1 - t0,
                "prepare_s": t2 - t1,
                "validation_s": res.wall_s,
                "wall_time_s": time.perf_counter() - t0,
            }
        )
        jp = write_benchmark_json(a.json, __file__, r, argv)
        print(f"wrote {jp}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
