"""Command line: ``workbench list | run | mc | inspect``.

Exit codes (scripts can rely on them):
  0  success
  2  usage error (unknown command or option)
  3  bad input: scenario, telemetry or asset file rejected (the message names file, column, row)
  4  the reconstruction failed numerically (e.g. a covariance lost positive definiteness)
  5  a requested scenario kind is not implemented
  130 interrupted (Ctrl-C); no half-written recording is left behind
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

EXIT_OK, EXIT_USAGE, EXIT_INPUT, EXIT_NUMERIC, EXIT_KIND, EXIT_INTERRUPT = 0, 2, 3, 4, 5, 130


def _assets_dir() -> Path:
    """The shipped assets folder (package data ``workbench.assets``)."""
    from workbench.io.assets import assets_dir

    return assets_dir()


def _progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def cmd_list(args: argparse.Namespace) -> int:
    """Print the shipped scenarios (name, kind, description)."""
    from workbench.io.scenario import find_scenarios, load_scenario

    found = find_scenarios(_assets_dir())
    for name, path in sorted(found.items()):
        sc = load_scenario(path)
        kind = sc.kind + (" (synthetic)" if sc.is_synthetic else "")
        print(f"{name:22s} {kind:22s} {sc.description}")
    return EXIT_OK


def run_scenario(
    name_or_path: str,
    out_dir: Path,
    seed: int | None = None,
    export: bool = False,
    quiet: bool = False,
    scheduler: str | None = None,
    members: int | None = None,
) -> dict:
    """Run one scenario end to end: (synthesize) -> reconstruct -> record -> summary.

    Writes ``<out>/<name>.rrd`` (atomically), ``<out>/<name>.summary.json`` and, for synthetic
    scenarios, the telemetry it generated under ``<out>/<name>/telemetry/``. Returns the summary.
    ``scheduler``/``members`` apply to entry scenarios (dispersion analysis on Dask, member count).
    """
    from workbench.io.scenario import resolve_scenario

    sc = resolve_scenario(name_or_path, _assets_dir())
    if sc.kind == "droptest":
        return _run_droptest(sc, out_dir, seed, export, quiet)
    if sc.kind == "entry":
        return _run_entry(sc, out_dir, seed, export, quiet, scheduler, members)
    raise NotImplementedError(
        f"scenario kind {sc.kind!r} ({sc.path}) is not implemented yet; implemented: droptest, entry"
    )


def _run_entry(sc, out_dir: Path, seed, export: bool, quiet: bool, scheduler, members) -> dict:
    """Entry and descent (AMELIA): synthesize (if synthetic) -> reconstruct -> record -> summary."""
    from workbench.io.results import export_csv, write_summary
    from workbench.problems.entry import pipeline as en
    from workbench.problems.entry.recording import EntryRecorder, entry_blueprint
    from workbench.recording.writer import open_recording

    say = (lambda m: None) if quiet else _progress
    t_start = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    seed_used = int(sc.get("synthetic.seed", 0, kind="int") if seed is None else seed)
    truth = None
    if sc.is_synthetic:
        from workbench.problems.entry.synthetic import load_entry_truth, synthesize_entry

        say(f"[{sc.name}] simulating the entry (truth) and writing telemetry ...")
        paths = synthesize_entry(sc, out_dir / sc.name / "telemetry", seed=seed_used)
        truth = load_entry_truth(paths["truth"])
    else:
        paths = en.telemetry_paths(sc)
    vehicle = en.vehicle_for(sc)
    r_ground = en.R_MOLA + sc.get("site.terrain_m", en.TERRAIN_ELEVATION_M, kind="float")
    rrd = out_dir / f"{sc.name}.rrd"
    with open_recording(
        rrd,
        sc.name,
        blueprint=entry_blueprint(),
        properties={"run": {"scenario": str(sc.path), "kind": sc.kind, "seed": seed_used}},
    ) as rec:
        from workbench.core.bodies import MARS

        drawer = EntryRecorder(
            rec,
            vehicle,
            truth,
            r_ground=r_ground,
            jd_tdb0=en._jd0(sc) if sc.has("scenario.epoch_utc") else None,
            body=MARS,
        )
        result = None
        t0 = time.perf_counter()
        for stage in en.reconstruct(sc, paths, scheduler=scheduler, members=members):
            say(f"[{sc.name}] {type(stage).__name__:20s} {time.perf_counter() - t0:6.2f} s")
            drawer.handle(stage)
            result = stage
        summary = dict(result.summary)
        if truth is not None:
            summary["truth"] = en.score(result, truth)
        summary["seed"] = seed_used
        summary["wall_time_s"] = time.perf_counter() - t_start
        rec.report(en.scorecard_markdown(summary))
    summary["recording"] = str(rrd)
    summary["recording_bytes"] = rrd.stat().st_size
    write_summary(out_dir / f"{sc.name}.summary.json", summary)
    if export:
        sm = result.filter.smoothed
        sd = np.sqrt(np.einsum("nii->ni", sm.P))
        cols = {}
        for i, a in enumerate("xyz"):
            cols[f"p_M.{a}"] = (sm.p_M[:, i], "m")
            cols[f"v_M.{a}"] = (sm.v_M[:, i], "m/s")
            cols[f"sigma_v.{a}"] = (sd[:, i], "m/s")
            cols[f"sigma_theta.{a}"] = (sd[:, 3 + i], "rad")
            cols[f"sigma_p.{a}"] = (sd[:, 6 + i], "m")
        for i, a in enumerate("xyzw"):
            cols[f"q_M_G.{a}"] = (sm.q_M_G[:, i], "1")
        export_csv(
            out_dir / f"{sc.name}.reconstruction.csv",
            sm.t,
            cols,
            meta={"source": f"workbench run {sc.name}", "frame": "MMED inertial; q_M_G body (GNC) to MMED"},
        )
    e = summary["end"]
    say(
        f"[{sc.name}] end of data: h AGL {e['h_agl_m']:.0f} ± {e['sigma_h_m']:.0f} m (1σ); "
        f"dispersion {summary['dispersion']['accepted']}/{summary['dispersion']['members']} accepted; "
        f"wrote {rrd} ({summary['recording_bytes'] / 1e6:.1f} MB) in {summary['wall_time_s']:.1f} s"
    )
    return summary


def _run_droptest(sc, out_dir: Path, seed, export: bool, quiet: bool) -> dict:
    """Drop test (REDLand): synthesize (if synthetic) -> reconstruct -> record -> summary."""
    from workbench.io.results import export_csv, write_summary

    say = (lambda m: None) if quiet else _progress
    t_start = time.perf_counter()
    from workbench.problems.droptest import pipeline as dt
    from workbench.problems.droptest.recording import DropTestRecorder, droptest_blueprint, impact_view
    from workbench.problems.droptest.synthetic import load_truth, synthesize_droptest
    from workbench.recording.writer import open_recording

    out_dir.mkdir(parents=True, exist_ok=True)
    truth = None
    seed_used = int(sc.get("synthetic.seed", 0, kind="int") if seed is None else seed)
    if sc.is_synthetic:
        say(f"[{sc.name}] simulating the drop (truth) and writing telemetry ...")
        syn = synthesize_droptest(sc, out_dir / sc.name / "telemetry", seed=seed_used)
        paths = syn.telemetry
        truth = load_truth(syn.truth_path)
    else:
        paths = dt.telemetry_paths(sc)
    residual_names = list(sc.get("sensors.accelerometer.triads", ["BP", "PYBP", "PXBP", "MXBP"], kind="list"))
    residual_names += ["gyro", "zupt"]
    if sc.has("sensors.ranging"):
        if sc.get("sensors.ranging.odometer", False, kind="bool"):
            residual_names.append("odometer")
        for gname in sc.get("sensors.ranging.radar_guns", {}, kind="table"):
            residual_names += [f"{gname}.range", f"{gname}.rate"]
    rrd = out_dir / f"{sc.name}.rrd"
    with open_recording(
        rrd,
        sc.name,
        blueprint=droptest_blueprint(residual_names),
        properties={"run": {"scenario": str(sc.path), "kind": sc.kind, "seed": seed_used}},
    ) as rec:
        drawer = DropTestRecorder(rec, truth)
        result = None
        t0 = time.perf_counter()
        for stage in dt.reconstruct(sc, paths, seed=seed_used):
            say(f"[{sc.name}] {type(stage).__name__:14s} {time.perf_counter() - t0:6.2f} s")
            drawer.handle(stage)
            result = stage
        summary = dict(result.summary)
        if truth is not None:
            summary["truth"] = dt.score(result, truth)
        summary["seed"] = seed_used
        summary["wall_time_s"] = time.perf_counter() - t_start
        rec.report(dt.scorecard_markdown(summary))
        # the layout that needs the result (camera at the impact, stroke zoom) becomes the default
        rec.stream.send_blueprint(
            droptest_blueprint(residual_names, impact_view(result)), make_active=True, make_default=True
        )
    summary["recording"] = str(rrd)
    summary["recording_bytes"] = rrd.stat().st_size
    write_summary(out_dir / f"{sc.name}.summary.json", summary)
    if export:
        res = result
        x = res.smoothed.x
        sd = np.sqrt(np.einsum("nii->ni", res.smoothed.P))
        cols = {}
        for i, a in enumerate("xyz"):
            cols[f"p.{a}"] = (x[:, i], "m")
            cols[f"sigma_p.{a}"] = (sd[:, i], "m")
            cols[f"v.{a}"] = (x[:, 3 + i], "m/s")
        for i, a in enumerate("xyzw"):
            cols[f"q_spf_body.{a}"] = (x[:, 9 + i], "1")
        cols["stroke"] = (res.stroke.smoothed.distance, "m")
        cols["sigma_stroke"] = (res.stroke.smoothed.sigma, "m")
        export_csv(
            out_dir / f"{sc.name}.reconstruction.csv",
            res.smoothed.t,
            cols,
            meta={"source": f"workbench run {sc.name}", "frame": "SPF chamber frame"},
        )
    ms = summary["max_stroke"]
    say(
        f"[{sc.name}] max stroke {ms['distance_m']:.3f} ± {ms['sigma_m']:.3f} m (1σ) at t = {ms['time_s']:.3f} s"
        + (f"; truth {summary['truth']['max_stroke_truth_m']:.3f} m" if truth is not None else "")
        + f"; wrote {rrd} ({summary['recording_bytes'] / 1e6:.1f} MB) in {summary['wall_time_s']:.1f} s"
    )
    return summary


def cmd_run(args: argparse.Namespace) -> int:
    """Run scenarios by name or path (``all`` = every shipped scenario)."""
    from workbench.io.scenario import find_scenarios

    names = list(args.scenario)
    if names == ["all"]:
        names = sorted(find_scenarios(_assets_dir()))
    out = Path(args.out)
    for name in names:
        run_scenario(name, out, seed=args.seed, export=args.export, scheduler=args.scheduler, members=args.members)
    return EXIT_OK


def cmd_mc(args: argparse.Namespace) -> int:
    """Monte Carlo of a synthetic drop-test scenario (consistency statistics + a recording), or the
    AMELIA Sect. 8 validation of the smoother for an entry scenario (:func:`_mc_entry`)."""
    from workbench.io.results import write_summary
    from workbench.io.scenario import resolve_scenario
    from workbench.problems.droptest.montecarlo import monte_carlo, summarize_mc
    from workbench.recording.montecarlo import record_monte_carlo

    sc = resolve_scenario(args.scenario, _assets_dir())
    if sc.kind == "entry":
        return _mc_entry(sc, args)
    if sc.kind != "droptest" or not sc.is_synthetic:
        raise NotImplementedError(f"{sc.path}: Monte Carlo needs a synthetic droptest scenario or an entry scenario")
    out = Path(args.out)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    _progress(f"[{sc.name}] Monte Carlo: {len(seeds)} runs ({args.scheduler or f'{args.workers} local worker(s)'}) ...")
    res = monte_carlo(sc, seeds, out / f"{sc.name}_mc_work", scheduler=args.scheduler, workers=args.workers)
    summary = summarize_mc(res)
    rrd = record_monte_carlo(out / f"{sc.name}_mc.rrd", f"{sc.name} Monte Carlo", res, summary)
    write_summary(out / f"{sc.name}.mc.json", summary)
    _progress(
        f"[{sc.name}] truth inside 3σ in {100 * summary['fraction_inside_3sigma']:.0f} % of runs, "
        f"median 3σ {100 * summary['median_3sigma_m']:.1f} cm, max-stroke ANEES "
        f"{summary['anees_stroke']:.2f}; wrote {rrd} in {res.total_wall_s:.0f} s"
    )
    return EXIT_OK


def _mc_entry(sc, args: argparse.Namespace) -> int:
    """Entry scenario: validate the radar-aided smoother on ``--seeds`` trajectories drawn from the
    accepted dispersion members (AMELIA Sect. 8; ``pipelines.entry_mc``).  Synthetic scenarios are
    synthesized first (into ``<out>/<name>_mc_work/telemetry``); user scenarios use their telemetry.
    The stages up to the dispersion run with the scenario's settings (``--members`` overrides the
    member count, ``--scheduler`` also runs the dispersion on Dask).  Writes ``<out>/<name>.mc.json``
    and ``<out>/<name>_mc.rrd``."""
    from workbench.io.results import write_summary
    from workbench.problems.entry.montecarlo import prepare_validation, validate_smoother
    from workbench.problems.entry.recording_mc import record_entry_validation

    t_start = time.perf_counter()
    out = Path(args.out)
    if sc.is_synthetic:
        from workbench.problems.entry.synthetic import synthesize_entry

        _progress(f"[{sc.name}] simulating the entry (truth) and writing telemetry ...")
        paths = synthesize_entry(
            sc, out / f"{sc.name}_mc_work" / "telemetry", seed=sc.get("synthetic.seed", 0, kind="int")
        )
    else:
        from workbench.problems.entry.pipeline import telemetry_paths

        paths = telemetry_paths(sc)
    _progress(f"[{sc.name}] preprocessing and dispersion analysis ...")
    inp = prepare_validation(sc, paths, members=args.members, scheduler=args.scheduler)
    d = inp.dispersion
    _progress(
        f"[{sc.name}] dispersion: {int(d.accepted.sum())}/{d.accepted.size} accepted; validating the smoother on "
        f"{args.seeds} runs from the {inp.start_mode!r} start "
        f"({args.scheduler or f'{args.workers} local worker(s)'}) ..."
    )
    if int(d.accepted.sum()) < 2 and inp.start_mode == "dispersion":
        print(
            f"workbench: {sc.path}: the dispersion accepted {int(d.accepted.sum())} of {d.accepted.size} members; the "
            "validation draws its truths from the accepted ones (need >= 2): raise --members, [dispersion] "
            "refine_rounds or widen [dispersion.rules]",
            file=sys.stderr,
        )
        return EXIT_INPUT
    res = validate_smoother(
        inp.imu,
        inp.nominal,
        d,
        inp.radar_times,
        n_runs=args.seeds,
        seed=args.first_seed,
        scheduler=args.scheduler,
        workers=args.workers,
        **inp.validation_kwargs(),
    )
    summary = {"scenario": sc.name, "kind": "entry_validation", **res.summary}
    summary["smoother_start_mode"] = inp.start_mode
    summary["smoother_start_note"] = inp.start_note
    summary["dispersion"] = {
        "members": int(d.accepted.size),
        "accepted": int(d.accepted.sum()),
        "wall_s": float(d.wall_s),
        "scheduler": str(d.scheduler),
    }
    summary["wall_time_s"] = time.perf_counter() - t_start
    rrd = record_entry_validation(out / f"{sc.name}_mc.rrd", f"{sc.name} smoother validation", res, summary)
    write_summary(out / f"{sc.name}.mc.json", summary)
    lo, hi = summary["anees_band"]
    h = summary.get("h_agl_after_fix", {})
    _progress(
        f"[{sc.name}] smoothed ANEES (9 dof) time-avg {summary['anees_time_avg']:.2f}, at end "
        f"{summary['anees_at']['end']:.2f} (95 % band {lo:.2f}-{hi:.2f}); max altitude error after the radar fix "
        f"{h.get('max_error_m', float('nan')):.1f} m; wrote {rrd} in {summary['wall_time_s']:.0f} s"
    )
    return EXIT_OK


def cmd_inspect(args: argparse.Namespace) -> int:
    """Print what a recording holds: entities, timelines, time range, row counts, scorecard."""
    from workbench.recording.reader import read_recording

    data = read_recording(args.recording)
    s = data.summary()
    if args.json:
        print(json.dumps(s, indent=2, default=str))
        return EXIT_OK
    print(
        f"recording {args.recording}: name {data.recording_name!r}, app {data.application_id!r}, "
        f"{data.file_size / 1e6:.2f} MB"
    )
    for tl in data.timelines():
        lo, hi = data.time_range(tl)
        print(f"timeline {tl}: {lo} .. {hi}")
    tls = data.timelines()
    print(f"{len(data.entities())} entities (rows per timeline: {', '.join(tls) or 'static only'}):")
    for e in data.entities():
        rows = " ".join(f"{data.row_count(e, tl):7d}" for tl in tls)
        print(f"  {e:60s} {rows}")
    try:
        print("\n" + data.text_document("/report"))
    except (KeyError, ValueError):
        print("(no /report scorecard in this recording)")
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (sub-commands list, run, inspect)."""
    p = argparse.ArgumentParser(prog="workbench", description="EDL reconstruction workbench")
    sub = p.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("list", help="list the shipped scenarios")
    sp.set_defaults(func=cmd_list)
    sp = sub.add_parser("run", help="run scenarios (names, paths to .toml, or 'all')")
    sp.add_argument("scenario", nargs="+")
    sp.add_argument("--out", default="recordings", help="output folder (default: recordings)")
    sp.add_argument("--seed", type=int, default=None, help="random seed of the synthetic sensors")
    sp.add_argument("--export", action="store_true", help="also write the reconstructed histories as CSV")
    sp.add_argument(
        "--scheduler", default=None, help="entry dispersion on dask: 'local' (LocalCluster) or 'tcp://host:8786'"
    )
    sp.add_argument("--members", type=int, default=None, help="entry dispersion members (default: scenario)")
    sp.set_defaults(func=cmd_run)
    sp = sub.add_parser(
        "mc", help="Monte Carlo consistency of a synthetic drop-test scenario / entry smoother validation"
    )
    sp.add_argument("scenario")
    sp.add_argument("--seeds", type=int, default=20, help="number of runs (default 20)")
    sp.add_argument("--first-seed", type=int, default=1)
    sp.add_argument("--workers", type=int, default=2, help="local worker processes without --scheduler")
    sp.add_argument("--scheduler", default=None, help="dask: 'local' (LocalCluster) or 'tcp://host:8786'")
    sp.add_argument("--members", type=int, default=None, help="entry: dispersion members (default: scenario)")
    sp.add_argument("--out", default="recordings")
    sp.set_defaults(func=cmd_mc)
    sp = sub.add_parser("inspect", help="summarise a .rrd recording and print its scorecard")
    sp.add_argument("recording")
    sp.add_argument("--json", action="store_true", help="machine-readable summary")
    sp.set_defaults(func=cmd_inspect)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``workbench`` console script; returns the exit code."""
    from workbench.io.scenario import ScenarioError
    from workbench.io.telemetry import TelemetryError
    from workbench.io.units import UnitError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:
        return EXIT_USAGE if e.code else EXIT_OK
    try:
        return args.func(args)
    except (TelemetryError, ScenarioError, UnitError, FileNotFoundError) as err:
        print(f"workbench: input error: {err}", file=sys.stderr)
        return EXIT_INPUT
    except NotImplementedError as err:
        print(f"workbench: {err}", file=sys.stderr)
        return EXIT_KIND
    except np.linalg.LinAlgError as err:
        print(f"workbench: numerical failure: {err}", file=sys.stderr)
        return EXIT_NUMERIC
    except KeyboardInterrupt:
        print("workbench: interrupted; no partial recording was kept", file=sys.stderr)
        return EXIT_INTERRUPT


if __name__ == "__main__":
    sys.exit(main())
