"""The entry blackout fill's temperature shape ("model" vs "linear") on dispersed truths.

Run on demand from the repository root (not collected by pytest)::

    nice -n 10 .venv/bin/python tests/benchmarks/bench_entry_fill_shape.py --stream validation --runs 8
        [--members 2000] [--json PATH]

The members are those of ``workbench mc schiaparelli --truth-sim --stream <stream> --seeds <runs>``
(``workbench.problems.entry.truth_mc.run_truth_monte_carlo``: a dispersed truth, the truth
simulator, telemetry files, kept in a temporary folder here).  Each member's telemetry is
reconstructed as ``workbench run`` does it up to the smoother (``--members`` dispersion members,
one refinement round), then the atmosphere is reconstructed twice from the same smoothed
trajectory, ``[atmosphere] fill_temperature_shape`` "model" and "linear" (everything else from the
scenario), and scored against the member's truth (``pipeline.score_atmosphere``).  Prints per
member the filled-blackout max |density error|, median, rms 1σ and the fraction inside 3σ, with the
entry-outside-the-blackout and parachute maxima; the mean / median / worst and the count inside
AMELIA's 20 % per shape.  ~20 s per member on one core.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)

from workbench.core.atmosphere import MarsEngineeringAtmosphere  # noqa: E402
from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.base import stream_seeds  # noqa: E402
from workbench.problems.entry import pipeline as en  # noqa: E402
from workbench.problems.entry.atmosphere import FILL_TEMPERATURE_SHAPES, reconstruct_atmosphere  # noqa: E402
from workbench.problems.entry.filter import EntryFilterResult  # noqa: E402
from workbench.problems.entry.preprocess import EntryTelemetry, PreprocessedIMU  # noqa: E402
from workbench.problems.entry.problem import EntryProblem  # noqa: E402
from workbench.problems.entry.synthetic import load_truth  # noqa: E402
from workbench.problems.entry.truth_mc import member_settings, run_truth_monte_carlo  # noqa: E402

SEGMENTS = ("entry_measured", "entry_filled_blackout", "under_parachute")


def _smoothed(cfg, folder: Path, members: int) -> tuple:
    """The member's telemetry through the pipeline up to the smoother: (telemetry, imu, filter)."""
    out = {}
    gen = en.reconstruct(cfg, dict(EntryProblem().telemetry_files(cfg, folder)), members=members)
    try:
        for st in gen:
            for typ in (EntryTelemetry, PreprocessedIMU, EntryFilterResult):
                if isinstance(st, typ):
                    out[typ] = st
            if EntryFilterResult in out:
                break
    finally:
        gen.close()
    return out[EntryTelemetry], out[PreprocessedIMU], out[EntryFilterResult]


def _scores(cfg, tm, imu, filt, truth: dict, shape: str) -> dict:
    """The atmosphere from the smoothed trajectory with ``fill_temperature_shape=shape``, scored."""
    sm = filt.smoothed
    ev = dict(tm.events)
    phase = en.phase_index(sm.t, ev)
    atm = reconstruct_atmosphere(
        sm.t,
        sm.p_M,
        sm.v_M,
        sm.q_M_G,
        sm.P,
        imu.f_G,
        np.ones(sm.t.size, dtype=bool),
        phase,
        cfg.require_vehicle(),
        default_atmosphere=MarsEngineeringAtmosphere(),
        settings=dataclasses.replace(cfg.atmosphere, fill_temperature_shape=shape),
        events=ev,
    )
    s = en.score_atmosphere(atm, truth, ev)
    keys = ("density_max_abs_error_rel", "density_median_abs_error_rel", "density_rms_sigma_rel")
    out = {seg: {k: s[seg][k] for k in keys + ("density_fraction_within_3sigma",)} for seg in SEGMENTS if seg in s}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "assets" / "scenarios" / "schiaparelli.toml"))
    ap.add_argument("--stream", default="validation", help="seed stream of the members (tuning, validation, ...)")
    ap.add_argument("--runs", type=int, default=8, help="Monte Carlo members (default 8)")
    ap.add_argument("--members", type=int, default=2000, help="dispersion members per reconstruction")
    ap.add_argument("--json", default=None, help="write the benchmark JSON here")
    a = ap.parse_args(argv)

    t0 = time.perf_counter()
    sc = EntryProblem().settings(load_scenario(a.scenario))
    cfg = member_settings(sc, None)
    per_member = []
    with tempfile.TemporaryDirectory(prefix="bench_fill_shape_") as tmp:
        run_truth_monte_carlo(sc, n_runs=a.runs, seed=stream_seeds(a.stream, 1)[0], members=a.members, work_dir=tmp)
        for k in range(a.runs):
            folder = Path(tmp) / f"member_{k}" / "telemetry"
            truth = load_truth(folder / "truth.npz")
            tm, imu, filt = _smoothed(cfg, folder, a.members)
            per_member.append({shape: _scores(cfg, tm, imu, filt, truth, shape) for shape in FILL_TEMPERATURE_SHAPES})
    r: dict = {"stream": a.stream, "runs": a.runs, "dispersion_members": a.members, "per_member": per_member}
    print(f"## blackout fill temperature shape, stream {a.stream!r}, {a.runs} members")
    cols = " | ".join(f"{s}: filled max / median / rms 1σ / in 3σ" for s in FILL_TEMPERATURE_SHAPES)
    print(f"| member | {cols} | linear: entry / parachute max |")
    for k, m in enumerate(per_member):
        cells = []
        for shape in FILL_TEMPERATURE_SHAPES:
            f = m[shape]["entry_filled_blackout"]
            cells.append(
                f"{f['density_max_abs_error_rel'] * 100:.1f} / {f['density_median_abs_error_rel'] * 100:.1f} / "
                f"{f['density_rms_sigma_rel'] * 100:.1f} % / {f['density_fraction_within_3sigma'] * 100:.0f} %"
            )
        e = m["linear"]
        print(
            f"| {k} | "
            + " | ".join(cells)
            + f" | entry {e['entry_measured']['density_max_abs_error_rel'] * 100:.1f} %, chute "
            f"{e['under_parachute']['density_max_abs_error_rel'] * 100:.1f} % |"
        )
    r["summary"] = {}
    for shape in FILL_TEMPERATURE_SHAPES:
        mx = np.array([m[shape]["entry_filled_blackout"]["density_max_abs_error_rel"] for m in per_member])
        in3 = min(m[shape]["entry_filled_blackout"]["density_fraction_within_3sigma"] for m in per_member)
        r["summary"][shape] = {
            "filled_max_mean": float(mx.mean()),
            "filled_max_median": float(np.median(mx)),
            "filled_max_worst": float(mx.max()),
            "inside_20_percent": int(np.sum(mx <= 0.20)),
            "min_fraction_within_3sigma": float(in3),
        }
        v = r["summary"][shape]
        print(
            f"{shape}: filled-blackout max error mean {v['filled_max_mean'] * 100:.1f} %, median "
            f"{v['filled_max_median'] * 100:.1f} %, worst {v['filled_max_worst'] * 100:.1f} %; inside 20 % "
            f"{v['inside_20_percent']}/{a.runs}; min fraction inside 3σ {in3:.2f}"
        )
    r["wall_time_s"] = time.perf_counter() - t0
    if a.json:
        path = write_benchmark_json(a.json, __file__, r, argv)
        print(f"\nwrote {path} (wall {r['wall_time_s']:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
