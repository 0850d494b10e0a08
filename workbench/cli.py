"""Command line: ``workbench list | run | mc | inspect | open | compare | replay | screenshot | init | import``.

Exit codes (scripts can rely on them):
  0  success
  2  usage error (unknown command or option)
  3  bad input: scenario, telemetry or asset file rejected (the message names file, column, row)
  4  the reconstruction failed numerically (e.g. a covariance lost positive definiteness)
  5  no problem is registered for the scenario's kind, or it cannot do what was asked
  6  unhealthy: the reconstruction ran but its health verdict is ERROR (filter inconsistent with a
     sensor, physically impossible output, a data gap across contact ...); nothing is written
     unless --allow-unhealthy (then the outputs are written, marked UNHEALTHY, and the exit code is 0)
  7  ``workbench screenshot``: the web viewer reported an error or showed an empty 3D view for a
     recording (the screenshots are written all the same)
  73 an output location cannot be written: read-only, missing (a parent is a file) or full disk
     (the message names the path; folders the run created are removed again when left empty)
  130 interrupted (Ctrl-C, SIGINT); no half-written recording is left behind
  141 standard output closed early (e.g. ``workbench list | head -1``): stops quietly
  143 terminated (SIGTERM); handled like Ctrl-C, no half-written recording is left behind
A run killed outright (SIGKILL) cannot clean up; its ``<name>.rrd.<pid>.partial`` is removed by the
next run writing the same recording.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
from pathlib import Path

# One BLAS thread unless the user chose otherwise: the workbench's matrices are small (covariances of
# at most a few dozen states), where a threaded OpenBLAS spends far more CPU on synchronisation than
# on arithmetic (measured: the drop-test smoother's 42x42 solves cost ~30x the CPU with 2 threads).
# Set before numpy is imported, so it applies to the whole command-line process.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402 (after the BLAS thread setting)

EXIT_OK, EXIT_USAGE, EXIT_INPUT, EXIT_NUMERIC, EXIT_KIND, EXIT_INTERRUPT = 0, 2, 3, 4, 5, 130
EXIT_UNHEALTHY = 6
EXIT_VIEWER = 7
EXIT_OUTPUT, EXIT_PIPE, EXIT_TERMINATED = 73, 141, 143


class Terminated(BaseException):
    """Raised in the main thread by SIGTERM, so that a run unwinds like on Ctrl-C (the writer deletes
    its partial recording); a ``BaseException`` so that no ``except Exception`` swallows it."""


@contextlib.contextmanager
def _sigterm_raises():
    """SIGTERM raises :class:`Terminated` in the main thread for the duration of the block.  A
    process forked meanwhile (a Monte Carlo pool worker) inherits the handler; there SIGTERM keeps
    its default meaning (the pool stops its workers with it)."""
    main_pid = os.getpid()

    def _on_sigterm(signum, frame):  # noqa: ARG001 - signal handler signature
        if os.getpid() != main_pid:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGTERM)
            return
        raise Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread (e.g. called from a worker thread): leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _reporter(args: argparse.Namespace):
    """The progress reporter of ``run`` / ``mc`` (``workbench.io.progress``): bars on stderr when it
    is a terminal, plain timed lines when not (or ``--progress plain``), none with ``--quiet``."""
    from workbench.io.progress import reporter_for

    return reporter_for(args.progress, quiet=args.quiet)


def _shipped() -> dict[str, Path]:
    """The shipped scenarios ``{name: path}``; ``FileNotFoundError`` if there are none."""
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import find_scenarios

    root = assets_dir()
    found = find_scenarios(root)
    if not found:
        raise FileNotFoundError(f"no scenarios found under {root / 'scenarios'} (a broken installation?)")
    return found


def cmd_list(args: argparse.Namespace) -> int:
    """Print the shipped scenarios (name, kind, description); an error if there are none."""
    from workbench.io.scenario import load_scenario
    from workbench.problems import registry

    known = set(registry.kinds())
    for name, path in sorted(_shipped().items()):
        sc = load_scenario(path)
        kind = sc.kind + (" (synthetic)" if sc.is_synthetic else "") + ("" if sc.kind in known else " (no problem)")
        # the filter size from the code (Problem.estimator, optional), never a number typed into a description
        problem = registry.get(sc.kind) if sc.kind in known else None
        size = getattr(problem, "estimator", None)
        print(
            f"{name:22s} {kind:22s} {sc.description}" + (f" [{size(problem.settings(sc))}]" if size is not None else "")
        )
    return EXIT_OK


def _options_from(cls, args: argparse.Namespace, **given):
    """An options dataclass ``cls`` (:class:`~workbench.problems.base.RunOptions`,
    :class:`~workbench.problems.base.McOptions`) from the parsed ``args``: every field from the
    argument of the same name (``--first-seed`` → ``first_seed``), but those ``given`` (an
    argument named otherwise, e.g. ``n_runs`` from ``--seeds``)."""
    from dataclasses import fields

    return cls(**{f.name: getattr(args, f.name) for f in fields(cls) if f.name not in given}, **given)


def cmd_run(args: argparse.Namespace) -> int:
    """Run scenarios by name or path (``all`` = every shipped scenario)."""
    from workbench.problems.base import RunOptions
    from workbench.problems.runner import run_scenario

    names = list(args.scenario)
    if names == ["all"]:
        names = sorted(_shipped())
    options = _options_from(RunOptions, args)
    from workbench.problems import scheduler

    jobs = scheduler.jobs_for(args.jobs, len(names))
    if jobs > 1:
        return scheduler.run_in_processes(
            names,
            lambda name: child_argv(name, args),
            jobs,
            Path(args.out),
            _reporter(args),
            entry=lambda argv: main(argv[3:]),
            progress=_progress,
        )
    rep = _reporter(args)
    for name in names:
        run_scenario(name, Path(args.out), options, progress=rep)
    return EXIT_OK


def child_argv(name: str, args: argparse.Namespace) -> list[str]:
    """The ``workbench run`` command line of one scenario in its own process (same options)."""
    argv = [sys.executable, "-m", "workbench.cli", "run", str(name), "--out", str(args.out), "--jobs", "1"]
    for flag, value in (("--seed", args.seed), ("--scheduler", args.scheduler), ("--members", args.members)):
        if value is not None:
            argv += [flag, str(value)]
    argv += ["--export"] * bool(args.export) + ["--allow-unhealthy"] * bool(args.allow_unhealthy)
    # several processes share the terminal: bars would overwrite each other's lines, so every child
    # logs plain timed lines (each names its scenario) - or nothing but its results under --quiet
    argv += ["--quiet"] if args.quiet else ["--progress", "plain"]
    return argv


def cmd_mc(args: argparse.Namespace) -> int:
    """The Monte Carlo analysis of the scenario's problem (``Problem.monte_carlo``); writes
    ``<name>.mc.json`` and ``<name>_mc.rrd``."""
    from workbench.problems.base import McOptions
    from workbench.problems.runner import run_monte_carlo

    options = _options_from(McOptions, args, n_runs=args.seeds)
    run_monte_carlo(args.scenario, Path(args.out), options, progress=_reporter(args))
    return EXIT_OK


INSPECT_ENTITY_ROWS = 25
"""Entity rows ``inspect`` prints before the count of the rest (``--entities`` prints them all)."""


def cmd_inspect(args: argparse.Namespace) -> int:
    """Print what a recording holds: name, timelines and time range, the scorecard, then the entities
    with row counts (the first :data:`INSPECT_ENTITY_ROWS` and a count of the rest, all with
    ``--entities``)."""
    from workbench.recording import layout
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
    try:
        print("\n" + data.text_document(layout.REPORT))
    except (KeyError, ValueError):
        print("\n(no /report scorecard in this recording)\n")
    tls = data.timelines()
    entities = data.entities()
    print(f"{len(entities)} entities (rows per timeline: {', '.join(tls) or 'static only'}):")
    shown = entities if args.entities else entities[:INSPECT_ENTITY_ROWS]
    for e in shown:
        rows = " ".join(f"{data.row_count(e, tl):7d}" for tl in tls)
        print(f"  {e:60s} {rows}")
    if len(shown) < len(entities):
        print(f"  ... {len(entities) - len(shown)} more (list them all with --entities)")
    return EXIT_OK


def cmd_open(args: argparse.Namespace) -> int:
    """List a recording's key moments, or open it in the Rerun Viewer, with ``--at NAME`` at that
    moment (a layout ``.rbl`` written beside it; the time cursor moved there once loaded)."""
    import shlex
    import subprocess

    from workbench.recording import moments as km
    from workbench.recording.browser import free_port
    from workbench.recording.reader import read_recording, rerun_executable

    data = read_recording(args.recording)
    moments = km.read_key_moments(data)
    if args.list:
        if not moments:
            print(f"{data.path}: no key moments (a recording of an older run, or of a Monte Carlo study)")
        for m in moments:
            lo, hi = m.window_or_default(_span(data))
            print(f"{m.name:20s} t = {m.t_s:10.3f} s  [{lo:.3f}, {hi:.3f}] s  {m.description}")
        return EXIT_OK
    rerun = rerun_executable() or "rerun"
    moment = km.find_moment(moments, args.at, where=str(data.path)) if args.at else None
    rbl = None
    if moment is not None:
        rbl = Path(args.rbl) if args.rbl else data.path.with_name(f"{data.path.stem}.at_{moment.name}.rbl")
        lay = km.write_moment_blueprint(
            data, moment, rbl, follow=None if args.no_follow else km.layout.VEHICLE, play=args.play
        )
        lo, hi = lay.window_s
        print(f"key moment {moment.name} at t = {moment.t_s:.3f} s: {moment.description}")
        what = "the recording's layout" if lay.copied else "the Viewer's automatic layout"
        follows = (
            (
                f"; 3D view{'s' if len(lay.following_views) > 1 else ''} "
                f"{', '.join(repr(v) for v in lay.following_views)} "
                f"follow{'' if len(lay.following_views) > 1 else 's'} {lay.follow}"
            )
            if lay.follow
            else ""
        )
        print(
            f"layout: {rbl} ({what}; time selection {lo:.3f} .. {hi:.3f} s, looped, "
            f"{'playing' if args.play else 'paused'}{follows})"
        )
    port = None if args.dry_run or args.web or moment is None else free_port()
    cmd = km.viewer_command(rerun, data.path, rbl, web=args.web, port=port)
    print("command: " + shlex.join(cmd.argv))
    if args.dry_run:
        if moment is not None:
            print(f"(dry run: the Viewer was not started; {_seek_hint(moment)})")
        return EXIT_OK
    if rerun_executable() is None:
        print("workbench: the rerun Viewer (the `rerun` command of rerun-sdk) is not installed", file=sys.stderr)
        return EXIT_KIND
    proc = subprocess.Popen(cmd.argv)
    if moment is not None and cmd.control_url is not None:
        if km.seek_viewer(cmd.control_url, moment.t_s, rbl=rbl, play=args.play):
            _progress(f"time cursor at {moment.t_s:.3f} s")
        else:
            _progress(f"could not reach the Viewer to move the time cursor; {_seek_hint(moment)}")
    elif moment is not None:
        _progress(f"the web Viewer opens at the start; {_seek_hint(moment)}")
    return EXIT_OK if proc.wait() == 0 else EXIT_KIND


def _seek_hint(moment) -> str:
    """How to put the time cursor on ``moment`` by hand (a layout cannot set it in Rerun 0.41)."""
    return (
        f"a layout cannot place the time cursor: click the '★ {moment.name}' mark on the time panel's "
        f"events row, or the row in the events view, for t = {moment.t_s:.3f} s"
    )


def _span(data) -> tuple[float, float] | None:
    """(first, last) time [s] of the recording's ``time`` timeline, or None without one."""
    try:
        return data.time_range("time")
    except KeyError:
        return None


def cmd_compare(args: argparse.Namespace) -> int:
    """Compare two runs of the same kind of scenario: print the markdown table of what changed and,
    with ``--out``, write the comparison recording."""
    from workbench.recording.compare import changes_markdown, compare_runs, write_comparison

    cmp = compare_runs(args.a, args.b)
    print(changes_markdown(cmp, max_rows=args.rows))
    if args.out:
        path = write_comparison(cmp, args.out)
        _progress(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    return EXIT_OK


def _headline(rrd: Path, properties: dict) -> str | None:
    """The run's one-line result (``Problem.headline`` of its sibling summary), or None."""
    from workbench.problems import registry

    summary = rrd.with_name(rrd.stem + ".summary.json")
    kind = properties.get("run", {}).get("kind")
    if not summary.is_file() or not kind:
        return None
    try:
        return registry.get(str(kind)).headline(json.loads(summary.read_text(encoding="utf-8")))
    except (LookupError, ValueError, TypeError, KeyError):
        return None


def cmd_replay(args: argparse.Namespace) -> int:
    """Presentation outputs of a run recording: ``--mp4`` video and/or ``--png`` summary image."""
    if not args.mp4 and not args.png:
        print("workbench replay: give --mp4 OUT.mp4 and/or --png OUT.png", file=sys.stderr)
        return EXIT_USAGE
    from workbench.recording.reader import read_recording

    data = read_recording(args.recording)
    if args.png:
        from workbench.recording.summary_image import render_png

        path = render_png(data, args.png, headline=_headline(data.path, data.properties()))
        _progress(f"wrote {path}")
    if args.mp4:
        from workbench.recording.replay import ReplayError, render_mp4

        try:
            size = _replay_size(args.size)
        except ValueError as err:
            print(f"workbench replay: {err}", file=sys.stderr)
            return EXIT_USAGE
        try:
            st = render_mp4(
                data,
                args.mp4,
                fps=args.fps,
                duration_s=args.duration,
                progress=None if args.quiet else _progress,
                size=size,
            )
        except ReplayError as err:
            print(f"workbench: {err}", file=sys.stderr)
            return EXIT_KIND
        _progress(
            f"wrote {st.path}: {st.frames} frames {st.size[0]}x{st.size[1]} at {st.fps:g} fps "
            f"(t = {st.t0:.2f} .. {st.t1:.2f} s) in {st.render_s:.1f} s ({st.cpu_s:.1f} s CPU)"
        )
    return EXIT_OK


def _replay_size(text: str) -> tuple[int, int]:
    """``"1920x1080"`` -> (1920, 1080) [px]; ``ValueError`` unless WIDTHxHEIGHT of a 16:9 frame at
    least 320 wide (the replay's overlay is laid out for 16:9)."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ValueError(f"--size {text!r}: give WIDTHxHEIGHT, e.g. 1920x1080") from None
    if w < 320 or abs(w * 9 - h * 16) > 16:
        raise ValueError(f"--size {text!r}: give a 16:9 frame at least 320 wide, e.g. 1920x1080")
    return w, h


def cmd_screenshot(args: argparse.Namespace) -> int:
    """Open recordings in Rerun's web viewer (headless Chromium), save a PNG of each and check it:
    exit 7 when the viewer reported an error or showed an empty 3D view for any of them."""
    from workbench.recording.browser import ViewerUnavailable, check_recordings

    at: str | float = args.at
    if at not in ("end", "start", "keep"):
        try:
            at = float(at)
        except ValueError:
            print(f"workbench screenshot: --at must be end, start, keep or seconds, not {at!r}", file=sys.stderr)
            return EXIT_USAGE
    try:
        w, h = (int(x) for x in args.size.lower().split("x"))
    except ValueError:
        print(f"workbench screenshot: --size must look like 1400x900, not {args.size!r}", file=sys.stderr)
        return EXIT_USAGE
    for path in [*args.recording, *([args.blueprint] if args.blueprint else [])]:
        if not Path(path).is_file():
            raise FileNotFoundError(f"no such file: {path}")
    failed = 0
    try:
        for check in check_recordings(
            args.recording,
            args.out,
            blueprint=args.blueprint,
            at=at,
            progress=None if args.quiet else _progress,
            size=(w, h),
            load_timeout_s=args.timeout,
        ):
            failed += not check.ok
            print(check.png if check.png else f"(no screenshot of {check.recording})")
            for line in check.errors:
                print(f"  error: {line}", file=sys.stderr)
    except ViewerUnavailable as err:
        print(f"workbench screenshot: cannot drive the web viewer: {err}", file=sys.stderr)
        return EXIT_KIND
    return EXIT_VIEWER if failed else EXIT_OK


def cmd_init(args: argparse.Namespace) -> int:
    """Write a user-data scenario (scenario.toml, example telemetry, README) for a problem kind."""
    from workbench.problems.template import init_scenario

    res = init_scenario(args.kind, Path(args.dir), seed=args.seed, overwrite=args.force)
    print(f"wrote {res.scenario} (from the shipped scenario {res.base.name!r}, kind {res.base.kind!r})")
    for stream, path in res.telemetry.items():
        print(f"  telemetry {stream:16s} {path}")
    for path in res.copied:
        print(f"  copied    {path}")
    print(f"  {res.readme}: what to replace")
    print(f"run it with: workbench run {res.scenario}")
    return EXIT_OK


def cmd_import(args: argparse.Namespace) -> int:
    """Convert a third-party log with the importer named on the command line (registry.IMPORTERS)."""
    from workbench.problems import registry

    path = registry.importer(args.importer).run(args)
    print(f"wrote {path} (run it with: workbench run {path})")
    return EXIT_OK


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Calibrate the health thresholds of problems on their truth Monte Carlo
    (:mod:`workbench.problems.calibration`); ``--write`` stores each problem's table."""
    from workbench.problems.calibration import main as calibrate_main

    argv = [*args.kinds, "--members", str(args.members), "--jobs", str(args.jobs)]
    return calibrate_main(argv + (["--write"] if args.write else []))


def _progress_options(sp: argparse.ArgumentParser) -> None:
    """``--quiet/-q`` and ``--progress`` of the long-running commands (``run``, ``mc``)."""
    sp.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="no progress output (no bars, no stage lines); the result lines and the paths written still print",
    )
    sp.add_argument(
        "--progress",
        choices=("auto", "bars", "plain"),
        default="auto",
        help="progress on stderr: 'bars' (counts and ETA), 'plain' (one timed line per stage, for logs), "
        "'auto' (default: bars when stderr is a terminal, else plain)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (sub-commands list, run, mc, inspect, open, compare, replay, calibrate, init, import)."""
    p = argparse.ArgumentParser(prog="workbench", description="EDL reconstruction workbench")
    sub = p.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("list", help="list the shipped scenarios (an error if none are found)")
    sp.set_defaults(func=cmd_list)
    sp = sub.add_parser("run", help="run scenarios (names, paths to .toml, or 'all')")
    sp.add_argument("scenario", nargs="+")
    sp.add_argument("--out", default="recordings", help="output folder (default: recordings)")
    sp.add_argument("--seed", type=int, default=None, help="random seed of the synthetic sensors")
    sp.add_argument("--export", action="store_true", help="also write the reconstructed histories as CSV")
    sp.add_argument(
        "--scheduler", default=None, help="ensemble stages on dask: 'local' (LocalCluster) or 'tcp://host:8786'"
    )
    sp.add_argument("--members", type=int, default=None, help="ensemble members (entry: dispersion; default: scenario)")
    sp.add_argument(
        "--allow-unhealthy",
        action="store_true",
        help="write the outputs even when the health verdict is ERROR (marked UNHEALTHY; else exit 6, nothing written)",
    )
    sp.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="scenarios run at once, each in its own process (default: one per CPU core; 1 = one after another "
        "in this process). With several, every scenario runs even if one fails",
    )
    _progress_options(sp)
    sp.set_defaults(func=cmd_run)
    sp = sub.add_parser(
        "mc",
        help="Monte Carlo analysis of a scenario (drop test: consistency; entry: smoother validation; "
        "meads: trade study)",
    )
    sp.add_argument("scenario")
    sp.add_argument("--seeds", type=int, default=20, help="number of runs (default 20)")
    sp.add_argument("--first-seed", type=int, default=1)
    sp.add_argument(
        "--stream",
        choices=("tuning", "validation", "calibration", "tests"),
        default=None,
        help="seed the members from this seed stream of the project (SeedSequence(20261204, spawn_key=(k,))) "
        "instead of --first-seed: 'validation' for consistency numbers on truths no setting was tuned on",
    )
    sp.add_argument("--workers", type=int, default=2, help="local worker processes without --scheduler")
    sp.add_argument("--scheduler", default=None, help="dask: 'local' (LocalCluster) or 'tcp://host:8786'")
    sp.add_argument(
        "--members",
        type=int,
        default=None,
        help="ensemble members (entry: dispersion; default: scenario, with --truth-sim 2000)",
    )
    sp.add_argument(
        "--truth-sim",
        action="store_true",
        help="truths from the truth simulator, reconstructions by the full pipeline from telemetry files "
        "(entry; meads: full error model, least squares vs EKF passes); writes <name>_truth.mc.json and "
        "<name>_truth_mc.rrd",
    )
    sp.add_argument(
        "--refine-rounds", type=int, default=None, help="refinement rounds of the ensemble stage (entry --truth-sim: 1)"
    )
    sp.add_argument("--out", default="recordings")
    _progress_options(sp)
    sp.set_defaults(func=cmd_mc)
    sp = sub.add_parser("inspect", help="summarise a .rrd recording and print its scorecard")
    sp.add_argument("recording")
    sp.add_argument("--json", action="store_true", help="machine-readable summary")
    sp.add_argument("--entities", action="store_true", help="list every entity (default: the first 25 and a count)")
    sp.set_defaults(func=cmd_inspect)
    sp = sub.add_parser(
        "open",
        help="open a recording in the Rerun Viewer, --at a key moment (max_stroke, pdd ...); --list them",
    )
    sp.add_argument("recording", help="a run recording (.rrd)")
    sp.add_argument("--at", default=None, metavar="NAME", help="start at this key moment (see --list)")
    sp.add_argument("--list", action="store_true", help="list the key moments (name, time, window, what) and exit")
    sp.add_argument(
        "--dry-run", action="store_true", help="write the layout and print the command line; do not start the Viewer"
    )
    sp.add_argument("--rbl", default=None, help="write the moment's layout here (default: <recording>.at_<NAME>.rbl)")
    sp.add_argument("--play", action="store_true", help="loop the moment's time range at 0.25x instead of pausing")
    sp.add_argument("--web", action="store_true", help="serve the web Viewer instead of the native one")
    sp.add_argument("--no-follow", action="store_true", help="leave the 3D cameras as the recording's layout has them")
    sp.set_defaults(func=cmd_open)
    sp = sub.add_parser(
        "compare", help="compare two runs of the same kind (seeds, tunings, code versions): table + recording"
    )
    sp.add_argument("a", help="recording A (.rrd; its <name>.summary.json beside it is read too)")
    sp.add_argument("b", help="recording B (.rrd)")
    sp.add_argument("--out", default=None, help="write the comparison recording here (.rrd)")
    sp.add_argument(
        "--rows",
        type=int,
        default=12,
        help="the largest this many changed numbers in the table (by |B − A| / σ where known)",
    )
    sp.set_defaults(func=cmd_compare)
    sp = sub.add_parser("replay", help="presentation outputs of a run: --mp4 video (OpenCV) and/or --png summary")
    sp.add_argument("recording", help="a run recording (.rrd)")
    sp.add_argument("--mp4", default=None, help="write the presentation video here (1280x720 unless --size)")
    sp.add_argument("--size", default="1280x720", help="video frame WIDTHxHEIGHT, 16:9 (1920x1080 for full HD)")
    sp.add_argument("--png", default=None, help="write the one-page summary image of the key plots here")
    sp.add_argument("--fps", type=float, default=25.0, help="video frame rate (default 25)")
    sp.add_argument("--duration", type=float, default=None, help="video length [s] (default: the problem's)")
    sp.add_argument("--quiet", action="store_true", help="no progress lines")
    sp.set_defaults(func=cmd_replay)
    sp = sub.add_parser(
        "screenshot",
        help="open recordings in Rerun's web viewer (headless Chromium), save PNGs, fail on viewer errors "
        "or an empty 3D view",
    )
    sp.add_argument("recording", nargs="+", help="run recordings (.rrd)")
    sp.add_argument("--out", default="screenshots", help="folder for <name>.png (default: screenshots)")
    sp.add_argument("--blueprint", default=None, help="open with this layout (.rbl) instead of the recording's own")
    sp.add_argument(
        "--at",
        default="end",
        help="time cursor on the 'time' timeline, paused: end (default), start, keep (as the layout sets it) "
        "or seconds",
    )
    sp.add_argument("--size", default="1400x900", help="browser window in CSS pixels (default 1400x900)")
    sp.add_argument("--timeout", type=float, default=240.0, help="seconds to wait for one recording to load")
    sp.add_argument("--quiet", action="store_true", help="no progress lines")
    sp.set_defaults(func=cmd_screenshot)
    sp = sub.add_parser(
        "calibrate",
        help="health thresholds from a problem's truth Monte Carlo (each shipped synthetic scenario over N seeds)",
    )
    sp.add_argument("kinds", nargs="+", help="problem kinds (droptest, entry, meads, post2)")
    sp.add_argument("--members", type=int, default=30, help="seeds per scenario (default 30)")
    sp.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="processes (default 2)")
    sp.add_argument("--write", action="store_true", help="write workbench/problems/<kind>/health_calibration.json")
    sp.set_defaults(func=cmd_calibrate)
    sp = sub.add_parser("init", help="write a user-data scenario to start from (scenario.toml, telemetry, README)")
    sp.add_argument("kind", help="a problem kind (droptest, entry, post2) or a shipped scenario name")
    sp.add_argument("dir", help="folder to write into (created)")
    sp.add_argument("--seed", type=int, default=1, help="seed of the example telemetry's sensor errors")
    sp.add_argument("--force", action="store_true", help="overwrite an existing scenario.toml in the folder")
    sp.set_defaults(func=cmd_init)
    from workbench.problems import registry

    sp = sub.add_parser("import", help="convert a third-party flight log into telemetry files and a problem file")
    isub = sp.add_subparsers(dest="importer", required=True)
    for name in sorted(registry.IMPORTERS):
        mod = registry.importer(name)
        ip = isub.add_parser(name, help=mod.HELP)
        mod.add_arguments(ip)
        ip.set_defaults(func=cmd_import)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``workbench`` console script; returns the exit code."""
    from workbench.estimation.health import UnhealthyError
    from workbench.io.moments import MomentError
    from workbench.io.scenario import ScenarioError
    from workbench.io.telemetry import TelemetryError
    from workbench.io.units import UnitError
    from workbench.problems.registry import UnknownKindError
    from workbench.recording.compare import ComparisonError
    from workbench.recording.moments import UnknownMomentError
    from workbench.recording.reader import RecordingError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:
        return EXIT_USAGE if e.code else EXIT_OK
    try:
        with _sigterm_raises():
            return args.func(args)
    except UnknownMomentError as err:
        print(f"workbench: {err}", file=sys.stderr)
        return EXIT_USAGE
    except (
        TelemetryError,
        ScenarioError,
        UnitError,
        FileNotFoundError,
        FileExistsError,
        RecordingError,
        ComparisonError,
        MomentError,
    ) as err:
        print(f"workbench: input error: {err}", file=sys.stderr)
        return EXIT_INPUT
    except (NotImplementedError, UnknownKindError) as err:
        print(f"workbench: {err}", file=sys.stderr)
        return EXIT_KIND
    except UnhealthyError as err:
        print(f"workbench: unhealthy: {err}", file=sys.stderr)
        return EXIT_UNHEALTHY
    except np.linalg.LinAlgError as err:
        print(f"workbench: numerical failure: {err}", file=sys.stderr)
        return EXIT_NUMERIC
    except KeyboardInterrupt:
        print("workbench: interrupted; no partial recording was kept", file=sys.stderr)
        return EXIT_INTERRUPT
    except Terminated:
        print("workbench: terminated (SIGTERM); no partial recording was kept", file=sys.stderr)
        return EXIT_TERMINATED
    except BrokenPipeError:
        # the reader went away (``| head``): say nothing more, and keep Python's exit-time flush of
        # stdout from raising again
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_PIPE
    except OSError as err:  # OutputError first: an output location that cannot be written
        from workbench.io.results import OutputError

        if isinstance(err, OutputError):
            print(f"workbench: output error: {err}", file=sys.stderr)
            return EXIT_OUTPUT
        if err.filename is not None:  # any other file the run could not read (e.g. no permission)
            print(f"workbench: input error: cannot read {err.filename}: {err.strerror or err}", file=sys.stderr)
            return EXIT_INPUT
        raise


if __name__ == "__main__":
    sys.exit(main())
