"""Run any scenario through its problem: the same steps for every ``kind``.

:func:`run_scenario`: settings -> (synthesize) -> reconstruct -> record -> score -> summary (-> CSV
export); :func:`run_monte_carlo`: settings -> the problem's Monte Carlo analysis -> summary.  Both
resolve a shipped scenario name (``workbench.io.assets.assets_dir()``) or a ``.toml`` path, find the
problem through :mod:`workbench.problems.registry` by the scenario's ``kind`` and build the run's
frozen settings once (:meth:`Problem.settings <workbench.problems.base.Problem.settings>`) before
anything runs; every problem method after that receives the settings, not the scenario.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.estimation.calibration import finish_health, load_table
from workbench.estimation.health import ERROR, UnhealthyError
from workbench.io import assets
from workbench.io import progress as prog
from workbench.io.moments import ordered
from workbench.io.results import OutputError, export_csv, write_summary
from workbench.io.scenario import Scenario, resolve_scenario
from workbench.problems import registry
from workbench.problems.base import McOptions, McOutcome, Problem, Progress, RunOptions
from workbench.problems.precompile import precompile

__all__ = [
    "NumericalFailure",
    "RunResult",
    "calibration_path",
    "evaluate",
    "judge_health",
    "output_folder",
    "prepare",
    "resolve",
    "run_monte_carlo",
    "run_scenario",
    "stage_label",
]


class NumericalFailure(np.linalg.LinAlgError):
    """The reconstruction failed numerically; the message names the scenario file and the stage
    (the one after the last stage that completed).  ``workbench`` exits 4 with it."""


def _under(path: Path, folder: Path) -> bool:
    try:
        Path(os.path.abspath(path)).relative_to(os.path.abspath(folder))
    except ValueError:
        return False
    return True


@contextlib.contextmanager
def output_folder(out: Path) -> Iterator[Path]:
    """Create the output folder ``out`` for the ``with`` block; if the block fails, the folders it
    created (``out`` and any missing parents) are removed again when nothing was written into them,
    so a rejected run leaves no empty ``--out``.  An ``OSError`` on a path inside ``out`` (or on
    ``out`` itself: read-only, missing because a parent is a file, full disk) becomes an
    :class:`~workbench.io.results.OutputError` naming the path."""
    out = Path(out)
    created = []
    p = Path(os.path.abspath(out))
    while not p.exists() and p != p.parent:
        created.append(p)
        p = p.parent
    try:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError.wrap(err, out, "cannot create the output folder") from err
        yield out
    except OutputError:
        _remove_empty(created)
        raise
    except OSError as err:
        _remove_empty(created)
        where = getattr(err, "filename", None)
        if where is not None and _under(Path(where), out):
            raise OutputError.wrap(err) from err
        raise
    except BaseException:
        _remove_empty(created)
        raise


def _remove_empty(created: list[Path]) -> None:
    """Remove the folders of ``created`` (deepest first) that are empty, and empty folders below them."""
    for top in created:
        if not top.is_dir():
            continue
        for sub in sorted((d for d in top.rglob("*") if d.is_dir()), key=lambda d: len(d.parts), reverse=True):
            with contextlib.suppress(OSError):
                sub.rmdir()  # only empty ones go
        with contextlib.suppress(OSError):
            top.rmdir()


@dataclass(frozen=True)
class RunResult:
    """What :func:`run_scenario` produced: the ``summary`` (as written to ``summary_path``), the
    final stage ``result``, the ``recording`` file, the ``telemetry`` files the reconstruction read
    and, for a synthetic scenario, the loaded ``truth`` (else None)."""

    scenario: Scenario
    problem: Problem
    summary: dict
    settings: Any = field(repr=False)
    result: Any = field(repr=False)
    recording: Path
    summary_path: Path
    telemetry: dict[str, Path]
    truth: Any = field(default=None, repr=False)
    export_path: Path | None = None


def stage_label(stage: object, seen: dict[str, int]) -> str:
    """The name of a reconstruction stage in progress lines and ``summary["stage_times_s"]``.

    The stage's own ``stage_label`` attribute when it has one (e.g. the drop test's
    ``"filter pass 1/2 (forward EKF)"``), else its type name with its ``name`` attribute when that
    is a string (``"FilterStage (forward)"``); a type seen before (``seen``: type name -> count,
    updated here) gets ``" #k"`` unless the label already differs."""
    kind = type(stage).__name__
    seen[kind] = seen.get(kind, 0) + 1
    own = getattr(stage, "stage_label", None)
    if isinstance(own, str) and own:
        return own
    name = getattr(stage, "name", None)
    label = f"{kind} ({name})" if isinstance(name, str) and name else kind
    return label if seen[kind] == 1 or label != kind else f"{kind} #{seen[kind]}"


def resolve(scenario: str | os.PathLike | Scenario) -> tuple[Scenario, Problem]:
    """The scenario (a shipped name, a ``.toml`` path or a loaded :class:`Scenario`) and its problem.

    Raises ``ScenarioError`` for an unknown name or a bad file — including any key the problem's
    schema does not declare (file, table, key and a "did you mean"), checked here before anything
    runs — and :class:`~workbench.problems.registry.UnknownKindError` if no problem handles its kind.
    """
    sc = scenario if isinstance(scenario, Scenario) else resolve_scenario(scenario, assets.assets_dir())
    problem = registry.get(sc.kind, where=str(sc.path))
    if problem.schema is not None:
        problem.schema.validate(sc.data, sc.path)
    return sc, problem


def prepare(scenario: str | os.PathLike | Scenario) -> tuple[Scenario, Problem, Any]:
    """:func:`resolve`, then the run's frozen settings (``problem.settings(scenario)``: the scenario
    and every file it names read against their schemas), before any computation."""
    sc, problem = resolve(scenario)
    return sc, problem, problem.settings(sc)


def run_scenario(
    scenario: str | os.PathLike | Scenario,
    out_dir: str | os.PathLike,
    options: RunOptions | None = None,
    progress: Progress | None = None,
) -> RunResult:
    """Run one scenario end to end: (synthesize) -> reconstruct -> record -> score -> summary.

    The problem's key moments (:meth:`Problem.key_moments`) go into ``summary["key_moments"]`` in
    time order, before the recorder's ``finish`` (which logs them into the recording).

    A summary whose ``"health"`` verdict is ERROR raises :class:`UnhealthyError` before anything is
    published, unless ``options.allow_unhealthy`` (then ``health["written_anyway"]`` is True and the
    scorecard and headline say UNHEALTHY).

    Writes ``<out>/<name>.rrd`` (atomically: nothing is left on failure), ``<out>/<name>.summary.json``,
    for synthetic scenarios the telemetry and ``truth.npz`` it generated under
    ``<out>/<name>/telemetry/``, and with ``options.export`` ``<out>/<name>.reconstruction.csv``.
    ``progress``: a :class:`workbench.io.progress.Reporter` (bars or plain lines; made the active
    reporter, so the truth simulation and ensemble stages show counters), or a callable receiving
    one plain line per stage, or None (quiet).  Every stage is timed: one line per stage with its
    wall time (the truth simulation, each reconstruction stage, drawing, writing), and the times
    are in ``summary["stage_times_s"]`` {label: s}; the paths written are reported at the end.
    """
    opts = options or RunOptions()
    rep = prog.as_reporter(progress)
    t_start = time.perf_counter()
    sc, problem, settings = prepare(scenario)
    out = Path(out_dir)
    prefix, rep.prefix = rep.prefix, f"[{sc.name}] "
    try:
        with prog.active(rep), output_folder(out):
            result, summary, rrd, summary_path, export_path, telemetry, truth, seed = _run(
                sc, problem, settings, out, opts, rep, t_start
            )
        health = summary.get("health")
        verdict = (
            ""
            if health is None
            else f"health {health['verdict']}"
            + (" — UNHEALTHY, written with --allow-unhealthy" if health.get("written_anyway") else "")
        )
        rep.result(f"{verdict + '; ' if verdict else ''}{problem.headline(summary)}")
        rep.result(
            f"wrote {rrd} ({summary['recording_bytes'] / 1e6:.1f} MB) in "
            f"{prog.format_seconds(time.perf_counter() - t_start)}"
        )
        rep.result(f"wrote {summary_path}")
        if sc.is_synthetic:
            rep.result(f"wrote {out / sc.name / 'telemetry'}{os.sep} (synthetic telemetry and truth.npz)")
        if export_path is not None:
            rep.result(f"wrote {export_path} (--export)")
    finally:
        rep.prefix = prefix
    return RunResult(sc, problem, summary, settings, result, rrd, summary_path, telemetry, truth, export_path)


def _run(
    sc: Scenario, problem: Problem, settings: Any, out: Path, opts: RunOptions, rep: prog.Reporter, t_start: float
):
    """The body of :func:`run_scenario` inside its output folder."""
    seed = int(sc.get("synthetic.seed", 0, kind="int") if opts.seed is None else opts.seed)
    truth = None
    n_times = len(rep.times)
    tel_dir = out / sc.name / "telemetry"
    # first run of a checkout: compile in a child (its memory goes with it), which also synthesizes
    compiled = precompile(sc, problem, seed, rep, settings=settings, telemetry=tel_dir if sc.is_synthetic else None)
    if sc.is_synthetic:
        with rep.stage(f"{problem.title} truth simulation + telemetry"):
            syn = compiled.synthesized if compiled is not None else None
            if syn is None:
                syn = problem.synthesize(settings, tel_dir, seed)
            telemetry = dict(syn.telemetry)
            truth = problem.load_truth(syn.truth)
    else:
        telemetry = problem.telemetry_files(settings)
    rrd = out / f"{sc.name}.rrd"
    properties = {
        "run": {
            "scenario": str(sc.path),
            "kind": sc.kind,
            "seed": seed,
            "synthetic": bool(sc.is_synthetic),
            "description": sc.description,
        }
    }
    with problem.open_recording(rrd, settings, truth, properties) as drawer:
        result = None
        last = "start"
        seen: dict[str, int] = {}
        draw_s = 0.0
        try:
            stages = iter(problem.reconstruct(settings, telemetry, replace(opts, seed=seed)))
            while True:
                t0 = time.perf_counter()
                try:
                    stage = next(stages)
                except StopIteration:
                    break
                result = stage  # now, not after drawing: the stage before is released while this one is drawn
                rep.record(stage_label(stage, seen), time.perf_counter() - t0)
                t0 = time.perf_counter()
                drawer.handle(stage)
                draw_s += time.perf_counter() - t0
                last = type(stage).__name__
        except NumericalFailure:
            raise
        except np.linalg.LinAlgError as err:
            raise NumericalFailure(
                f"{sc.path}: the {problem.title} reconstruction failed numerically in the stage after {last}: {err}"
            ) from err
        if result is None:
            raise RuntimeError(f"{sc.path}: the {sc.kind} reconstruction yielded no result")
        t0 = time.perf_counter()
        summary = problem.summary(result)
        summary["key_moments"] = [m.to_dict() for m in ordered(problem.key_moments(result) or [])]
        if truth is not None:
            summary["truth"] = problem.score(result, truth)
        rep.record("summary" + (" + score against the truth" if truth is not None else ""), time.perf_counter() - t0)
        rep.record("drawing the stages into the recording", draw_s)
        summary["seed"] = seed
        summary["stage_times_s"] = rep.stage_times(since=n_times)  # this run's (a reporter may serve several)
        summary["wall_time_s"] = time.perf_counter() - t_start
        judge_health(problem, summary)
        summary["headline"] = problem.headline(summary)
        health = summary.get("health")
        if health is not None and health["verdict"] == ERROR:
            if not opts.allow_unhealthy:
                raise UnhealthyError(sc.path, health)  # inside the recording: nothing is published
            health["written_anyway"] = True
        t0 = time.perf_counter()
        drawer.finish(result, summary)
    rep.record("scorecard + writing the recording", time.perf_counter() - t0)
    summary["recording"] = str(rrd)
    summary["recording_bytes"] = rrd.stat().st_size
    summary_path = write_summary(out / f"{sc.name}.summary.json", summary)
    export_path = None
    if opts.export:
        with rep.stage("CSV export"):
            table = problem.export_columns(result)
            export_path = export_csv(
                out / f"{sc.name}.reconstruction.csv",
                table.time_s,
                table.columns,
                meta={"source": f"workbench run {sc.name}", "frame": table.frame},
                sparse=table.sparse,
            )
    return result, summary, rrd, Path(summary_path), export_path, telemetry, truth, seed


def calibration_path(problem: Problem) -> Path:
    """Where the problem's truth-Monte-Carlo health calibration lives:
    ``health_calibration.json`` in the package of the problem's class (may not exist)."""
    return Path(sys.modules[type(problem).__module__].__file__).parent / "health_calibration.json"


def judge_health(problem: Problem, summary: dict, *, calibrated: bool = True) -> None:
    """Replace ``summary["health"]`` (if any) by its final form: the statistic checks re-judged
    against the problem's calibration table (:func:`calibration_path`; ``calibrated=False``: none)
    and a synthetic run's headline quantities against its truth (``summary["truth"]["headline"]``),
    see :func:`workbench.estimation.calibration.finish_health`."""
    health = summary.get("health")
    if health is None:
        return
    table = load_table(calibration_path(problem)) if calibrated else None
    summary["health"] = finish_health(health, table, summary.get("truth"))


def evaluate(scenario: str | os.PathLike | Scenario, work_dir: Path, seed: int, *, calibrated: bool = True) -> dict:
    """The summary of one run of ``scenario`` with ``seed`` — synthesized into ``work_dir`` when
    synthetic, reconstructed, summarised, scored against its truth and its health judged
    (:func:`judge_health`) — without a recording: a Monte Carlo member of the health calibration
    (:mod:`workbench.problems.calibration`).  A problem offering ``calibration_settings(settings,
    seed)`` disperses its truth there as its truth Monte Carlo does (the bands then cover the
    flights the filter meets, not one truth's sensor noise)."""
    sc, problem, settings = prepare(scenario)
    truth = None
    if sc.is_synthetic and hasattr(problem, "calibration_settings"):
        settings = problem.calibration_settings(settings, int(seed))
    if sc.is_synthetic:
        syn = problem.synthesize(settings, Path(work_dir) / "telemetry", int(seed))
        telemetry, truth = dict(syn.telemetry), problem.load_truth(syn.truth)
    else:
        telemetry = problem.telemetry_files(settings)
    result = None
    for stage in problem.reconstruct(settings, telemetry, RunOptions(seed=int(seed))):
        result = stage
    summary = problem.summary(result)
    if truth is not None:
        summary["truth"] = problem.score(result, truth)
    summary["seed"] = int(seed)
    judge_health(problem, summary, calibrated=calibrated)
    return summary


def run_monte_carlo(
    scenario: str | os.PathLike | Scenario,
    out_dir: str | os.PathLike,
    options: McOptions | None = None,
    progress: Progress | None = None,
) -> McOutcome:
    """The Monte Carlo analysis of the scenario's problem; writes its recording
    (``<out>/<name>_mc.rrd``) and ``<out>/<name>.mc.json`` (``<name>_truth.mc.json`` with
    ``options.truth_sim``).  ``NotImplementedError`` if the problem
    has none for this scenario.  ``progress`` as in :func:`run_scenario`: the problem's study shows
    its members (and truth simulations, dispersions) as counters with an ETA on the active reporter;
    the paths written are reported at the end.  The problem's kernels are compiled first if the
    checkout has none cached (:func:`~workbench.problems.precompile.precompile`), so the workers
    load them instead of each compiling its own."""
    rep = prog.as_reporter(progress)
    sc, problem, settings = prepare(scenario)
    out = Path(out_dir)
    options = options or McOptions()
    prefix, rep.prefix = rep.prefix, f"[{sc.name}] "
    try:
        with prog.active(rep), output_folder(out):
            # first study of a checkout: compile once in a child, not once in every worker
            precompile(sc, problem, options.first_seed, rep)
            outcome = problem.monte_carlo(settings, out, options, rep)
            outcome.summary.setdefault("seeds", options.seed_record())
            summary_path = write_summary(
                out / f"{sc.name}{'_truth' if options.truth_sim else ''}.mc.json", outcome.summary
            )
        rep.result(outcome.headline)  # names the recording it wrote
        rep.result(f"wrote {summary_path}")
    finally:
        rep.prefix = prefix
    return outcome
