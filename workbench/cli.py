"""Command line: ``workbench list | run | mc | inspect``.

Exit codes (scripts can rely on them):
  0  success
  2  usage error (unknown command or option)
  3  bad input: scenario, telemetry or asset file rejected (the message names file, column, row)
  4  the reconstruction failed numerically (e.g. a covariance lost positive definiteness)
  5  no problem is registered for the scenario's kind, or it cannot do what was asked
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

import numpy as np

EXIT_OK, EXIT_USAGE, EXIT_INPUT, EXIT_NUMERIC, EXIT_KIND, EXIT_INTERRUPT = 0, 2, 3, 4, 5, 130
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
        print(f"{name:22s} {kind:22s} {sc.description}")
    return EXIT_OK


def cmd_run(args: argparse.Namespace) -> int:
    """Run scenarios by name or path (``all`` = every shipped scenario)."""
    from workbench.problems.base import RunOptions
    from workbench.problems.runner import run_scenario

    names = list(args.scenario)
    if names == ["all"]:
        names = sorted(_shipped())
    options = RunOptions(seed=args.seed, export=args.export, scheduler=args.scheduler, members=args.members)
    for name in names:
        run_scenario(name, Path(args.out), options, progress=_progress)
    return EXIT_OK


def cmd_mc(args: argparse.Namespace) -> int:
    """The Monte Carlo analysis of the scenario's problem (``Problem.monte_carlo``); writes
    ``<name>.mc.json`` and ``<name>_mc.rrd``."""
    from workbench.problems.base import McOptions
    from workbench.problems.runner import run_monte_carlo

    options = McOptions(
        n_runs=args.seeds,
        first_seed=args.first_seed,
        workers=args.workers,
        scheduler=args.scheduler,
        members=args.members,
        truth_sim=args.truth_sim,
        refine_rounds=args.refine_rounds,
    )
    run_monte_carlo(args.scenario, Path(args.out), options, progress=_progress)
    return EXIT_OK


def cmd_inspect(args: argparse.Namespace) -> int:
    """Print what a recording holds: entities, timelines, time range, row counts, scorecard."""
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
    tls = data.timelines()
    print(f"{len(data.entities())} entities (rows per timeline: {', '.join(tls) or 'static only'}):")
    for e in data.entities():
        rows = " ".join(f"{data.row_count(e, tl):7d}" for tl in tls)
        print(f"  {e:60s} {rows}")
    try:
        print("\n" + data.text_document(layout.REPORT))
    except (KeyError, ValueError):
        print("(no /report scorecard in this recording)")
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (sub-commands list, run, inspect)."""
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
    sp.set_defaults(func=cmd_run)
    sp = sub.add_parser(
        "mc", help="Monte Carlo analysis of a scenario (drop test: consistency; entry: smoother validation)"
    )
    sp.add_argument("scenario")
    sp.add_argument("--seeds", type=int, default=20, help="number of runs (default 20)")
    sp.add_argument("--first-seed", type=int, default=1)
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
        "(entry); writes <name>_truth.mc.json and <name>_truth_mc.rrd",
    )
    sp.add_argument(
        "--refine-rounds", type=int, default=None, help="refinement rounds of the ensemble stage (entry --truth-sim: 1)"
    )
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
    from workbench.problems.registry import UnknownKindError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:
        return EXIT_USAGE if e.code else EXIT_OK
    try:
        with _sigterm_raises():
            return args.func(args)
    except (TelemetryError, ScenarioError, UnitError, FileNotFoundError) as err:
        print(f"workbench: input error: {err}", file=sys.stderr)
        return EXIT_INPUT
    except (NotImplementedError, UnknownKindError) as err:
        print(f"workbench: {err}", file=sys.stderr)
        return EXIT_KIND
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
