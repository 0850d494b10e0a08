"""Fuzz table (issue 26, item 5): the mistakes users make — axis swaps, sign flips, plausible-unit
mistakes, geometry offsets, truncation at key events, timing mis-declarations, metadata mix-ups —
applied to the FILES of a user's data folder, run through the real pipeline, and scored against the
same data unmutated.

    python tests/benchmarks/bench_fuzz.py [--label after] [--quick] [--problems droptest,rocket]
                                          [--jobs 2] [--fresh] [--input-level | --seeds N]

Writes ``docs/results/bench_fuzz_users.json`` (the other labels already there are kept unless
``--fresh``: ``before`` is main before the issue-26 checks).

Bases: ``workbench init <scenario>`` folders (droptest, droptest_ranging, schiaparelli, msl_meads,
post2_j2, post2_huygens; seed 1) — a scenario TOML naming its telemetry folder, exactly what a user
edits — plus a drop with ranging whose IMU went through a zero-phase filter, and the rocket
importer (``workbench import airbrakes``) on the committed excerpt of flight 1 and, when
``$EDL_FLIGHT_DATA`` holds them (``tests/support/flight_data.py``), the three full FIRM logs.  The
mutations are ``tests/benchmarks/fuzz_mutations.py``.  Each mutated folder is run like the clean one
(the scenario: read, validated, reconstructed, summarised with its key moments, health judged, as
``workbench run`` does without writing the recording;
the rocket: the importer CLI, then the problem file it wrote), in worker processes with a time limit.

Outcome of a mutation:

* ``CLEAR_ERROR`` — an input error (exit 3) or numerical failure (exit 4) whose message names the
  mutated file, column/key or a stage; ``UNCLEAR_ERROR`` — the same exits naming none of them;
* ``TRACEBACK`` — any other exception (``TIMEOUT``: no answer within ``--timeout``);
* a run that completes is WRONG when a headline quantity moved by more than 3σ_c from the clean run
  (σ_c = sqrt(σ_clean² + σ_mut²)): ``SILENT`` (verdict OK), ``UNDERRATED`` (WARNING), ``FLAGGED``
  (ERROR); otherwise ``ACCURATE`` (``raised``: its verdict is worse than the clean run's, a false
  alarm that is counted), or ``UNDEFINED`` when a headline is reported undefined (None/NaN).
  ``wrong_nothing_new`` counts the SILENT/UNDERRATED runs whose non-OK checks are all among the
  clean run's (a WARNING that a good run also has tells the user nothing).

Headlines (one of the end state, ``*_end``, only when both runs end within ``END_TIME_TOLERANCE_S``:
a file cut short ends elsewhere): drop test max stroke and restitution; entry height above ground at
the end of the data; MEADS the last EKF pass's α, β, q∞ at the clean run's peak q; post2 every
estimated state at the end (position, velocity, parameters); rocket the apogee above the pad and every
state at the end, the coast drag multiplier as the coast drag coefficient it means (× the declared Cd, which
only normalises it: a Cd declared wrong is a different multiplier for the same drag).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import multiprocessing as mp
import os
import shutil
import sys
import tempfile
import time
import traceback
from collections import Counter
from multiprocessing.connection import wait
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "support"))
sys.path.insert(0, str(HERE))

import fuzz_mutations as fm  # noqa: E402
from bench_json import write_benchmark_json  # noqa: E402

OUTCOMES = (
    "CLEAR_ERROR",
    "UNCLEAR_ERROR",
    "TRACEBACK",
    "TIMEOUT",
    "SILENT",
    "UNDERRATED",
    "FLAGGED",
    "ACCURATE",
    "UNDEFINED",
)
RANK = {"OK": 0, "WARNING": 1, "ERROR": 2}
INIT = {
    "droptest": "droptest",
    "droptest_ranging": "droptest_ranging",
    "entry": "schiaparelli",
    "meads": "msl_meads",
    "post2_j2": "post2_j2",
    "post2_huygens": "post2_huygens",
}
EXCERPT = HERE.parent / "problems" / "post2" / "data" / "airbrakes_excerpt"
EXCERPT_LOG = "jackpot_launch_1_excerpt.csv"
EXCERPT_MAGNETIC = ("-10.5", "64")  # flight 1's site (tests/support/flight_data.py)


# ----------------------------------------------------------------------------------- bases
def make_base(name: str, where: Path, seed: int = 1) -> Path:
    """The clean user folder of base ``name`` in ``where / name`` (returned)."""
    from workbench.problems.template import init_scenario

    out = where / name
    if name in INIT:
        init_scenario(INIT[name], out, seed=seed)
    elif name == "droptest_ranging_zp":
        _zero_phase_base(out, seed)
    elif name == "rocket":
        out.mkdir(parents=True)
        shutil.copyfile(EXCERPT / EXCERPT_LOG, out / EXCERPT_LOG)
        shutil.copyfile(EXCERPT / "metadata.json", out / "metadata.json")
    elif name.startswith("rocket_"):
        from flight_data import airbrakes_dir

        d, why = airbrakes_dir()
        if d is None:
            raise RuntimeError(why)
        out.mkdir(parents=True)
        log = name.removeprefix("rocket_") + ".csv"
        shutil.copyfile(d / log, out / log)
        shutil.copyfile(d / "metadata.json", out / "metadata.json")
    else:
        raise ValueError(name)
    return out


def _zero_phase_base(out: Path, seed: int) -> None:
    """``workbench init droptest_ranging``, its IMU re-synthesized through a zero-phase acquisition
    filter, and the scenario declaring ``filter = "zero_phase"`` (the clean case of the issue's
    mis-declared filter)."""
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import load_scenario
    from workbench.problems.runner import resolve
    from workbench.problems.template import init_scenario

    init_scenario("droptest_ranging", out, seed=seed)
    sc = load_scenario(assets_dir() / "scenarios" / "droptest_ranging.toml")
    sc = sc.with_overrides({"sensors.acquisition.filter": "zero_phase"})
    sc, problem = resolve(sc)
    tmp = out / "_zp"
    syn = problem.synthesize(problem.settings(sc), tmp, seed)
    for p in syn.telemetry.values():
        shutil.copyfile(p, out / "telemetry" / Path(p).name)
    shutil.rmtree(tmp)
    fm.toml_set(out / "scenario.toml", "sensors.acquisition", "filter", "zero_phase")


# ----------------------------------------------------------------------------------- one run
def _headline(problem_name: str, folder: Path, summary: dict, result, ref: dict) -> tuple[dict, dict]:
    """({name: (values, sigmas)}, extra facts) of a completed run; values None/NaN = undefined."""
    import numpy as np

    h: dict = {}
    extra: dict = {}
    if problem_name.startswith("droptest"):
        ms, rs = summary.get("max_stroke") or {}, summary.get("restitution") or {}
        h["max_stroke_m"] = ([ms.get("distance_m")], [ms.get("sigma_m")])
        h["restitution"] = ([rs.get("e")], [rs.get("sigma")])
    elif problem_name == "entry":
        end = summary.get("end") or {}
        h["h_agl_end_m"] = ([end.get("h_agl_m")], [end.get("sigma_h_m")])
        extra["end_t_s"] = end.get("t_s")
    elif problem_name == "meads":
        passes = getattr(result, "ekf", ()) or ()
        if passes:
            ps = passes[-1]
            t, y, s = np.asarray(ps.t), np.asarray(ps.outputs), np.asarray(ps.sigma)
        else:
            f = result.air.fit
            t = np.asarray(result.air.t)
            y = np.column_stack([f.alpha, f.beta, f.qbar])
            s = np.column_stack([f.sigma_alpha, f.sigma_beta, f.sigma_qbar])
        t_pk = ref.get("t_peak_q")
        if t_pk is None:
            k = int(np.nanargmax(y[:, 2]))
            extra["t_peak_q"] = float(t[k])
        else:
            k = int(np.argmin(np.abs(t - t_pk)))
            if abs(t[k] - t_pk) > 0.25:
                k = -1
        for j, n, f in ((0, "alpha_deg", 180 / math.pi), (1, "beta_deg", 180 / math.pi), (2, "qbar_pa", 1.0)):
            h[n] = ([float(y[k, j]) * f], [float(s[k, j]) * f]) if k >= 0 else ([None], [None])
    if problem_name.startswith(("post2", "rocket")):
        extra["end_t_s"] = float(result.t[-1])
        for name, st in (summary.get("states") or {}).items():
            h[f"{name}_end"] = (list(st.get("final") or []), list(st.get("final_sigma") or []))
    if problem_name.startswith("rocket") and "ca_multiplier_end" in h:
        # the multiplier is |f| m / (Cd S q) with the declared Cd: the physical result is its product
        cd = json.loads((folder / "import" / "flight.json").read_text(encoding="utf-8"))["metadata"]["cd"]
        v, s = h.pop("ca_multiplier_end")
        h["coast_cd_end"] = ([None if x is None else x * cd for x in v], [None if x is None else x * cd for x in s])
    if problem_name.startswith("rocket"):
        h["apogee_m"] = _apogee(folder, result)
    return h, extra


def _apogee(folder: Path, result) -> tuple[list, list]:
    """Apogee above the pad [m] and its 1σ from the smoothed positions (as ``rocket.score_flight``)."""
    import numpy as np

    from workbench.core.bodies import EARTH

    flight = json.loads((folder / "import" / "flight.json").read_text(encoding="utf-8"))
    h_pad = flight["pad"]["pad_altitude_m"]
    p = np.asarray(result.history["smoothed"]["position"]["value"])
    r = np.linalg.norm(p, axis=1)
    h = r - EARTH.reference_radius - h_pad
    k = int(np.argmax(h))
    sp = result.smap.blocks["position"].se
    up = p[k] / r[k]
    return [float(h[k])], [float(np.sqrt(up @ result.P[k][sp, sp] @ up))]


def _evaluate(scenario: Path):
    """(summary, result) of a user scenario as ``workbench run`` makes it, without the recording:
    the stages (a numerical failure named with the scenario and the stage, as the runner does), the
    summary with its key moments, the health judged (``runner.judge_health``)."""
    import numpy as np

    from workbench.io.moments import ordered
    from workbench.problems.base import RunOptions
    from workbench.problems.runner import NumericalFailure, judge_health, prepare

    sc, problem, settings = prepare(scenario)
    result, last = None, "start"
    try:
        for stage in problem.reconstruct(settings, problem.telemetry_files(settings), RunOptions(seed=1)):
            result, last = stage, type(stage).__name__
    except NumericalFailure:
        raise
    except np.linalg.LinAlgError as err:
        raise NumericalFailure(
            f"{sc.path}: the {problem.title} reconstruction failed numerically in the stage after {last}: {err}"
        ) from err
    summary = problem.summary(result)
    summary["key_moments"] = [m.to_dict() for m in ordered(problem.key_moments(result) or [])]
    judge_health(problem, summary, calibrated=True)
    return summary, result


def _input_errors() -> tuple:
    from workbench.estimation.health import UnhealthyError
    from workbench.io.moments import MomentError
    from workbench.io.scenario import ScenarioError
    from workbench.io.telemetry import TelemetryError
    from workbench.io.units import UnitError

    return (TelemetryError, ScenarioError, UnitError, FileNotFoundError, FileExistsError, MomentError, UnhealthyError)


def run_task(task: dict) -> dict:
    """Run one folder (clean or mutated) through the pipeline; a JSON-able outcome record."""
    import numpy as np

    folder = Path(task["folder"])
    problem = task["problem"]
    t0 = time.perf_counter()
    rec: dict = {"ok": False}
    try:
        if problem.startswith("rocket"):
            from workbench.cli import main as cli

            log = task["log"]
            args = ["import", "airbrakes", str(folder / log), "--metadata", str(folder / "metadata.json")]
            args += ["--out", str(folder / "import"), "--declination-deg", task["magnetic"][0]]
            args += ["--inclination-deg", task["magnetic"][1], *task.get("import_args", ())]
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                rc = cli(args)
            if rc != 0:
                rec.update(rc=rc, error="cli", message=err.getvalue().strip())
                return rec
            scenario = folder / "import" / f"{Path(log).stem}.toml"
        else:
            scenario = folder / "scenario.toml"
        summary, result = _evaluate(scenario)
        head, extra = _headline(problem, folder, summary, result, task.get("ref", {}))
        health = summary.get("health") or {}
        rec.update(
            ok=True,
            verdict=health.get("verdict", "OK"),
            fired=[f"{c['name']}:{c['status']}" for c in health.get("checks", []) if c.get("status") != "OK"],
            headline={k: ([_num(x) for x in v], [_num(x) for x in s]) for k, (v, s) in head.items()},
            extra=extra,
        )
    except _input_errors() as e:
        rec.update(rc=3, error=type(e).__name__, message=str(e))
    except np.linalg.LinAlgError as e:
        rec.update(rc=4, error=type(e).__name__, message=str(e))
    except Exception as e:  # noqa: BLE001 — any other exception is what the suite looks for
        tb = traceback.extract_tb(e.__traceback__)
        where = f"{Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else ""
        rec.update(rc=1, error=type(e).__name__, message=f"{e} [{where}]")
    finally:
        rec["wall_s"] = time.perf_counter() - t0
    return rec


def _num(x):
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


# ----------------------------------------------------------------------------------- workers
def _worker(conn) -> None:
    while True:
        task = conn.recv()
        if task is None:
            return
        conn.send(run_task(task))


class Pool:
    """``jobs`` long-lived worker processes (spawned: the kernels load once per worker), each task
    with a time limit: a worker past it is killed and replaced (the task is a ``TIMEOUT``)."""

    def __init__(self, jobs: int, timeout: float):
        self.ctx = mp.get_context("spawn")
        self.timeout = timeout
        self.workers = [self._start() for _ in range(max(1, jobs))]

    def _start(self):
        a, b = self.ctx.Pipe()
        p = self.ctx.Process(target=_worker, args=(b,), daemon=True)
        p.start()
        return {"proc": p, "conn": a, "task": None, "t0": 0.0}

    def map(self, tasks: list[dict], done=None) -> list[dict]:
        """The outcome records of ``tasks`` (in order); ``done(i, record)`` after each."""
        out: list[dict | None] = [None] * len(tasks)
        todo = list(range(len(tasks)))[::-1]
        busy = 0
        while todo or busy:
            for w in self.workers:
                if w["task"] is None and todo:
                    i = todo.pop()
                    w["task"], w["t0"] = i, time.monotonic()
                    w["conn"].send(tasks[i])
                    busy += 1
            ready = wait([w["conn"] for w in self.workers if w["task"] is not None], timeout=1.0)
            for w in list(self.workers):
                if w["task"] is None:
                    continue
                i = w["task"]
                if w["conn"] in ready:
                    try:
                        rec = w["conn"].recv()
                    except EOFError:  # the worker died (e.g. a segfault)
                        rec = {"ok": False, "rc": -1, "error": "WorkerDied", "message": "worker process died"}
                        self._replace(w)
                elif time.monotonic() - w["t0"] > self.timeout:
                    rec = {"ok": False, "rc": -1, "error": "TIMEOUT", "message": f"no answer in {self.timeout:.0f} s"}
                    self._replace(w)
                else:
                    continue
                out[i] = rec
                w["task"] = None
                busy -= 1
                if done:
                    done(i, rec)
        return out  # type: ignore[return-value]

    def _replace(self, w) -> None:
        w["proc"].kill()
        w["proc"].join()
        w.update(self._start())
        w["task"] = None

    def close(self) -> None:
        for w in self.workers:
            with contextlib.suppress(Exception):
                w["conn"].send(None)
        for w in self.workers:
            w["proc"].join(timeout=5)
            if w["proc"].is_alive():
                w["proc"].kill()


#: end-state headlines (``*_end``) are compared only when the two runs end within this [s] of each other
END_TIME_TOLERANCE_S = 1.0


# ----------------------------------------------------------------------------------- scoring
def score(m: fm.Mutation, clean: dict, rec: dict) -> dict:
    """The outcome row of mutation ``m`` from its record ``rec`` and the clean run's ``clean``."""
    row = {
        "class": m.cls,
        "problem": m.problem,
        "what": m.what,
        "file": m.file,
        "wall_s": round(rec.get("wall_s", 0), 2),
    }
    if not rec.get("ok"):
        msg = (rec.get("message") or "").strip()
        row["error"] = rec.get("error")
        row["message"] = msg.splitlines()[0][:300] if msg else ""
        rc = rec.get("rc")
        if rec.get("error") == "TIMEOUT":
            row["outcome"] = "TIMEOUT"
        elif rc in (3, 4, 6):
            names = [Path(m.file).name, *m.names, "stage"]
            row["outcome"] = "CLEAR_ERROR" if any(n and n in msg for n in names) else "UNCLEAR_ERROR"
        else:
            row["outcome"] = "TRACEBACK"
        return row
    row["verdict"] = rec["verdict"]
    if rec.get("extra"):
        row["extra"] = rec["extra"]  # e.g. the entry's end time: a shorter file ends elsewhere
    clean_fired = set(clean.get("fired", []))
    row["new_checks"] = [c for c in rec["fired"] if c not in clean_fired]
    z_max, undefined, zs = 0.0, [], {}
    # a file that ends elsewhere has its end state at another time: not the clean run's quantity
    t0_end, t1_end = (clean.get("extra") or {}).get("end_t_s"), (rec.get("extra") or {}).get("end_t_s")
    elsewhere = t0_end is not None and t1_end is not None and abs(t1_end - t0_end) > END_TIME_TOLERANCE_S
    if elsewhere:
        row["not_compared"] = [n for n in clean["headline"] if "_end" in n]
    for name, (v0, s0) in clean["headline"].items():
        if elsewhere and "_end" in name:
            continue
        v1, s1 = rec["headline"].get(name, ([None], [None]))
        if len(v1) != len(v0) or any(x is None for x in v1):
            undefined.append(name)
            continue
        if any(x is None for x in v0):
            continue
        z = 0.0
        for a, sa, b, sb in zip(v0, s0, v1, s1, strict=True):
            sc = math.sqrt((sa or 0.0) ** 2 + (sb or 0.0) ** 2)
            d = abs(b - a)
            z = max(z, d / sc if sc > 0 else (0.0 if d == 0 else math.inf))
        zs[name] = round(z, 2) if math.isfinite(z) else "inf"
        z_max = max(z_max, z)
    row["z"] = zs
    row["z_max"] = round(z_max, 2) if math.isfinite(z_max) else "inf"
    if z_max > 3.0:
        row["outcome"] = {"OK": "SILENT", "WARNING": "UNDERRATED"}.get(rec["verdict"], "FLAGGED")
    elif undefined:
        row["outcome"] = "UNDEFINED"
        row["undefined"] = undefined
    else:
        row["outcome"] = "ACCURATE"
    row["raised"] = RANK.get(rec["verdict"], 2) > RANK.get(clean["verdict"], 2)
    return row


def tables(rows: list[dict]) -> dict:
    """{problem: {class: {outcome: n}}} and the totals per problem and per class."""
    by: dict = {}
    for r in rows:
        c = by.setdefault(r["problem"], {}).setdefault(r["class"], dict.fromkeys(OUTCOMES, 0))
        c[r["outcome"]] += 1
        if r["outcome"] == "ACCURATE" and r.get("raised"):
            c["false_alarm"] = c.get("false_alarm", 0) + 1
        if r["outcome"] in ("SILENT", "UNDERRATED") and not r.get("new_checks"):
            c["wrong_nothing_new"] = c.get("wrong_nothing_new", 0) + 1
    return by


def totals_by(rows: list[dict], key: str) -> dict:
    """{problem or class: {outcome: n}} (``key`` "problem" or "class")."""
    out: dict = {}
    for r in rows:
        c = out.setdefault(r[key], dict.fromkeys(OUTCOMES, 0))
        c[r["outcome"]] += 1
    return out


def _print_table(rows: list[dict], wall: float) -> None:
    cols = (
        "CLEAR_ERROR",
        "UNCLEAR_ERROR",
        "TRACEBACK",
        "TIMEOUT",
        "SILENT",
        "UNDERRATED",
        "FLAGGED",
        "ACCURATE",
        "UNDEFINED",
    )
    short = ("clear", "unclr", "trace", "tmout", "SILENT", "UNDER", "flagd", "accur", "undef")
    print(f"{'problem/class':34s} {'n':>4s} " + " ".join(f"{s:>6s}" for s in short) + "  f.alarm")
    tot = Counter()
    for p, cls in tables(rows).items():
        for c, n in cls.items():
            k = sum(n[o] for o in cols)
            tot.update({o: n[o] for o in cols})
            tot["n"] += k
            tot["fa"] += n.get("false_alarm", 0)
            print(
                f"{p + '/' + c:34s} {k:4d} " + " ".join(f"{n[o]:6d}" for o in cols) + f"  {n.get('false_alarm', 0):6d}"
            )
    print(
        f"{'total':34s} {tot['n']:4d} " + " ".join(f"{tot[o]:6d}" for o in cols) + f"  {tot['fa']:6d}   ({wall:.0f} s)"
    )


# ----------------------------------------------------------------------------------- main
def flights_available() -> tuple[str, ...]:
    """The full FIRM logs found through ``$EDL_FLIGHT_DATA`` (empty when absent)."""
    from flight_data import FLIGHTS, airbrakes_dir

    d, _ = airbrakes_dir()
    return FLIGHTS if d is not None else ()


def _task(m_problem: str, base: str, folder: Path, flights_magnetic: dict, import_args=(), ref=None) -> dict:
    t = {"problem": m_problem, "folder": str(folder), "import_args": list(import_args), "ref": ref or {}}
    if m_problem.startswith("rocket"):
        if base == "rocket":
            t["log"], t["magnetic"] = EXCERPT_LOG, list(EXCERPT_MAGNETIC)
        else:
            t["log"] = base.removeprefix("rocket_") + ".csv"
            t["magnetic"] = [str(x) for x in flights_magnetic[t["log"]]]
    return t


#: rough cost order of the problems (cheap first: a run stopped early has the most rows)
COST = {"post2_j2": 0, "rocket": 1, "droptest": 2, "droptest_ranging": 3, "post2_huygens": 4, "meads": 5, "entry": 6}


def run(
    muts: list[fm.Mutation],
    work: Path,
    jobs: int = 2,
    timeout: float = 600.0,
    verbose: bool = True,
    rows_log: Path | None = None,
) -> tuple[list[dict], dict, float]:
    """Make the bases, run them clean, run every mutation (cheap problems first; each row appended
    to ``rows_log`` as a JSON line when given); (rows, clean records, wall [s])."""
    from flight_data import SITE_MAGNETIC

    muts = sorted(muts, key=lambda m: COST.get(m.problem, 1))

    t0 = time.perf_counter()
    bases = sorted({m.base for m in muts})
    problem_of = {m.base: m.problem for m in muts}
    base_dir = {}
    for b in bases:
        base_dir[b] = make_base(b, work / "bases")
    pool = Pool(jobs, timeout)
    try:
        clean_tasks = [_task(problem_of[b], b, base_dir[b], SITE_MAGNETIC) for b in bases]
        # the clean runs write into the base folder (rocket: its import/); mutations copy it first
        clean_recs = pool.map(clean_tasks)
        clean = {}
        for b, rec in zip(bases, clean_recs, strict=True):
            clean[b] = rec
            if rows_log is not None:
                with open(rows_log, "a", encoding="utf-8") as f:
                    f.write(json.dumps({"clean_base": b, **_clean_record(rec)}) + "\n")
            if verbose:
                print(
                    f"clean {b}: {rec.get('verdict') or rec.get('message')} ({rec.get('wall_s', 0):.1f} s)", flush=True
                )
        tasks, keep = [], []
        for i, m in enumerate(muts):
            if not clean[m.base].get("ok"):
                continue
            folder = work / "cases" / f"{i:03d}_{m.base}"
            shutil.copytree(base_dir[m.base], folder, ignore=shutil.ignore_patterns("import"))
            m.edit(folder)
            tasks.append(_task(m.problem, m.base, folder, SITE_MAGNETIC, m.import_args, clean[m.base].get("extra")))
            keep.append(m)
        rows: list[dict] = [None] * len(keep)  # type: ignore[list-item]

        def done(i, rec):
            rows[i] = score(keep[i], clean[keep[i].base], rec)
            shutil.rmtree(tasks[i]["folder"], ignore_errors=True)
            if rows_log is not None:
                with open(rows_log, "a", encoding="utf-8") as f:
                    f.write(json.dumps(rows[i]) + "\n")
            if verbose:
                r = rows[i]
                print(
                    f"[{sum(x is not None for x in rows):3d}/{len(keep)}] {r['problem']}/{r['class']}: {r['what']}: "
                    f"{r['outcome']} {r.get('verdict', '')} z={r.get('z_max', '')} {r.get('message', '')[:120]}",
                    flush=True,
                )

        pool.map(tasks, done)
    finally:
        pool.close()
    wall = time.perf_counter() - t0
    return rows, {b: _clean_record(rec) for b, rec in clean.items()}, wall


def _clean_record(rec: dict) -> dict:
    """The part of a clean run's record kept in the JSON."""
    return {k: rec.get(k) for k in ("ok", "verdict", "fired", "headline", "extra", "message", "wall_s")}


def combine(logs: list[Path]) -> tuple[list[dict], dict]:
    """(rows, clean records) read back from ``--rows-log`` files (e.g. a run stopped early and the
    runs that completed its problems); a later row of the same mutation replaces an earlier one."""
    rows: dict[tuple, dict] = {}
    clean: dict = {}
    for p in logs:
        for line in Path(p).read_text(encoding="utf-8").splitlines():
            if not line.strip():
                continue
            r = json.loads(line)
            if "clean_base" in r:
                clean[r.pop("clean_base")] = r
            else:
                rows[(r["problem"], r["class"], r["what"])] = r
    return list(rows.values()), clean


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--label", default="after")
    ap.add_argument("--code", default=None, help="what code was measured (recorded; default: the label)")
    ap.add_argument("--quick", action="store_true", help="two mutations per problem and class")
    ap.add_argument(
        "--problems",
        default="",
        help="comma-separated problems: droptest, droptest_ranging, entry, meads, post2_j2, post2_huygens, "
        "rocket, rocket_<flight stem>",
    )
    ap.add_argument("--classes", default="", help="comma-separated mutation classes")
    ap.add_argument("--seed", type=int, default=0, help="draws which columns/axes each mutation family takes")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--reverse", action="store_true", help="each problem's mutations in reverse order")
    ap.add_argument("--timeout", type=float, default=600.0, help="per run [s]")
    ap.add_argument("--rows-log", default=None, help="append each outcome row to this JSON-lines file as it comes")
    ap.add_argument("--fresh", action="store_true", help="drop the other labels already in --out")
    ap.add_argument(
        "--input-level", action="store_true", help="also the issue-12 input-level table (tests/support/fuzz.py)"
    )
    ap.add_argument("--seeds", type=int, default=0, help="seeds of the input-level table (implies --input-level)")
    ap.add_argument(
        "--combine", default="", help="comma-separated --rows-log files: write the JSON from them, run nothing"
    )
    ap.add_argument("--wall", type=float, default=None, help="with --combine: the wall time to record [s]")
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_fuzz_users.json"))
    args = ap.parse_args(argv)
    muts = fm.catalogue(args.seed, flights=flights_available())
    if args.problems:
        want = set(args.problems.split(","))
        muts = [m for m in muts if m.problem in want]
    if args.classes:
        muts = [m for m in muts if m.cls in set(args.classes.split(","))]
    if args.quick:
        muts = fm.quick(muts, 2, args.seed)
    if args.reverse:
        muts = muts[::-1]
    print(f"{len(muts)} mutations", flush=True)
    if args.combine:
        rows, clean = combine([Path(p) for p in args.combine.split(",")])
        order = {m.key: i for i, m in enumerate(muts)}
        rows = sorted(
            (r for r in rows if f"{r['problem']}/{r['class']}/{r['what']}" in order),
            key=lambda r: order[f"{r['problem']}/{r['class']}/{r['what']}"],
        )
        wall, legacy = args.wall, None
    else:
        with tempfile.TemporaryDirectory(prefix="bench_fuzz_") as tmp:
            rows_log = Path(args.rows_log) if args.rows_log else None
            rows, clean, wall = run(muts, Path(tmp), args.jobs, args.timeout, rows_log=rows_log)
            seeds = args.seeds or (1 if args.input_level else 0)
            legacy = _input_level(Path(tmp), seeds) if seeds else None
    _print_table(rows, wall or 0.0)
    tot = Counter(r["outcome"] for r in rows)
    out = Path(args.out)
    data = {}
    if not args.fresh and out.exists():
        old = json.loads(out.read_text(encoding="utf-8")).get("results", {})
        data = {k: v for k, v in old.items() if isinstance(v, dict) and "rows" in v}
    data[args.label] = {
        "code": args.label if args.code is None else args.code,
        "mutations": len(rows),
        "catalogue": len(muts),
        "quick": args.quick,
        "seed": args.seed,
        "jobs": args.jobs,
        "wall_s": wall,
        "totals": {"runs": len(rows)}
        | {o: tot.get(o, 0) for o in OUTCOMES}
        | {
            "false_alarm": sum(r["outcome"] == "ACCURATE" and bool(r.get("raised")) for r in rows),
            "wrong_nothing_new": sum(
                r["outcome"] in ("SILENT", "UNDERRATED") and not r.get("new_checks") for r in rows
            ),
        },
        "table": tables(rows),
        "by_problem": totals_by(rows, "problem"),
        "by_class": totals_by(rows, "class"),
        "clean": clean,
        "rows": rows,
    }
    if legacy is not None:
        data[args.label]["input_level"] = legacy
    write_benchmark_json(out, __file__, data, argv)
    print(f"wrote {out}")
    return 0


def _input_level(work: Path, seeds: int = 1) -> dict:
    """The issue-12 input-level table (readers, validation and input health) over ``seeds``."""
    import importlib.util

    import fuzz

    from workbench.io.assets import assets_dir
    from workbench.io.scenario import load_scenario
    from workbench.problems.droptest.problem import DropTestProblem

    test_file = HERE.parent / "problems" / "test_fuzz.py"
    spec = importlib.util.spec_from_file_location("test_fuzz_mod", test_file)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    drop_dir = work / "legacy" / "droptest_clean"
    problem = DropTestProblem()
    problem.synthesize(problem.settings(load_scenario(assets_dir() / "scenarios" / "droptest.toml")), drop_dir, 1)
    targets = [
        fuzz.droptest_target(drop_dir, work / "legacy"),
        fuzz.entry_target(mod.entry_fake_files(work / "legacy" / "entry_clean"), work / "legacy"),
        fuzz.post2_target(mod.post2_files(work / "legacy" / "post2_clean"), work / "legacy"),
    ]
    t0 = time.perf_counter()
    results = fuzz.run_all(targets, range(seeds), work / "legacy" / "cases")
    return {"seeds": seeds, "wall_s": time.perf_counter() - t0, "table": fuzz.table(results)}


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    raise SystemExit(main())
