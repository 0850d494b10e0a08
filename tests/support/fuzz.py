"""Seeded fuzzing of user-style inputs through the validation + health API (issue 12, item 6).

Each *case* mutates one file of a clean set of telemetry/scenario files (a copy in a fresh folder)
and runs the problem's input path — the readers with their validation, the unit-plausibility
checks and the input-level health checks (no full filter, except post2 whose filter takes a few
milliseconds) — then classifies the outcome:

* ``GOOD``      — a located error (``TelemetryError``/``ScenarioError``/``UnitError``/
  ``FileNotFoundError`` whose message names the mutated file), or a harmless mutation (CRLF, BOM,
  an extra column, spaces in the path) read to the same numbers as the clean files;
* ``DEGRADED``  — accepted with a reported warning (health verdict WARNING/ERROR, a degradation);
* ``SILENT``    — accepted as if nothing were wrong (health OK, numbers differ from the clean run);
* ``TRACEBACK`` — any other exception (a crash).

Works on the code before issue 12 too (it falls back to the degradations/problems lists when the
``input_health`` functions do not exist), so ``tests/benchmarks/bench_fuzz.py`` can measure before
and after.  Load with ``import fuzz`` (``tests/support`` is on the path, see ``tests/conftest.py``).
"""

from __future__ import annotations

import functools
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

GOOD, DEGRADED, SILENT, TRACEBACK = "GOOD", "DEGRADED", "SILENT", "TRACEBACK"
HARMLESS = {"crlf", "bom", "extra_column", "spaces_in_path"}

#: Unit relabels by a unit-like factor (header unit -> wrong unit of the same kind).
RELABEL = {
    "g": "m/s^2",
    "m/s^2": "g",
    "deg/s": "rad/s",
    "rad/s": "deg/s",
    "m": "km",
    "km": "m",
    "m/s": "km/s",
    "km/s": "m/s",
    "s": "ms",
    "ms": "s",
}


@dataclass(frozen=True)
class Case:
    """One mutation: ``problem``, mutation class ``cls``, the stream (file key) it mutates, a seed."""

    problem: str
    cls: str
    stream: str
    seed: int


@dataclass(frozen=True)
class Outcome:
    case: Case
    outcome: str
    detail: str


# ----------------------------------------------------------------------------------- CSV edits
def _split(text: str) -> tuple[list[str], int]:
    lines = text.split("\n")
    h = next(i for i, s in enumerate(lines) if s.strip() and not s.lstrip().startswith("#"))
    return lines, h


def _data_rows(lines: list[str], h: int) -> list[int]:
    return [i for i in range(h + 1, len(lines)) if lines[i].strip()]


def _set_cell(lines: list[str], i: int, j: int, value: str) -> None:
    cells = lines[i].split(",")
    cells[j] = value
    lines[i] = ",".join(cells)


def mutate_csv(text: str, cls: str, rng: np.random.Generator, *, column: int | None = None) -> str | None:
    """``text`` of a telemetry/events CSV with mutation ``cls`` applied (None: not applicable)."""
    lines, h = _split(text)
    rows = _data_rows(lines, h)
    header = lines[h].split(",")
    k = len(header)
    if not rows:
        return None
    r = int(rng.integers(len(rows) // 4, max(len(rows) // 4 + 1, 3 * len(rows) // 4)))
    i = rows[min(r, len(rows) - 1)]
    j = column if column is not None else int(rng.integers(1, k)) if k > 1 else 0
    if cls in ("nan", "inf", "text", "empty_cell"):
        _set_cell(lines, i, j, {"nan": "nan", "inf": "inf", "text": "n/a", "empty_cell": ""}[cls])
    elif cls == "duplicate_time":
        lines.insert(i + 1, lines[i])
    elif cls == "duplicate_row_time":
        prev = rows[rows.index(i) - 1]
        _set_cell(lines, i, 0, lines[prev].split(",")[0])
    elif cls == "backwards_time":
        a, b = i, rows[rows.index(i) + 1] if rows.index(i) + 1 < len(rows) else rows[rows.index(i) - 1]
        lines[a], lines[b] = lines[b], lines[a]
    elif cls == "gap":
        n = max(2, len(rows) // 10)
        s = rows.index(i)
        for q in sorted(rows[s : s + n], reverse=True):
            del lines[q]
    elif cls == "truncation":
        last = rows[-1]
        cut = max(1, len(lines[last]) - int(rng.integers(2, 6)))
        lines = lines[: last + 1]
        lines[last] = lines[last][:cut]
        return "\n".join(lines)  # no final newline
    elif cls == "truncation_mid_row":
        last = rows[len(rows) // 2]
        lines = lines[:last]
        lines.append(lines[-1][: len(lines[-1]) // 2])
        return "\n".join(lines)
    elif cls == "truncated_rows":  # cut cleanly at a row boundary: a shorter, valid-looking file
        return "\n".join(lines[: rows[int(0.6 * len(rows))]]) + "\n"
    elif cls == "empty_file":
        return ""
    elif cls == "header_only":
        return "\n".join(lines[: h + 1]) + "\n"
    elif cls == "missing_column":
        if k < 2:
            return None
        for q in [h, *rows]:
            cells = lines[q].split(",")
            del cells[j]
            lines[q] = ",".join(cells)
    elif cls == "extra_column":
        for q in [h, *rows]:
            lines[q] = lines[q] + (",extra.note [1]" if q == h else ",0")
    elif cls == "renamed_column":
        m = re.match(r"^(.*?)(\s*\[.*\])$", header[j])
        if not m:
            return None
        header[j] = m.group(1) + "_renamed" + m.group(2)
        lines[h] = ",".join(header)
    elif cls == "wrong_unit_label":
        cands = []
        for jj, c in enumerate(header):
            m = re.match(r"^(.*?)\s*\[(.*)\]$", c.strip())
            if m and m.group(2) in RELABEL and (jj > 0 or column == 0):
                cands.append(jj)
        if column is not None:
            cands = [c for c in cands if c == column]
        if not cands:
            return None
        jj = cands[int(rng.integers(len(cands)))]
        m = re.match(r"^(.*?)\s*\[(.*)\]$", header[jj].strip())
        name, unit = m.group(1), m.group(2)
        # the whole group of the column (BP.x, BP.y, BP.z or a_x, a_y, a_z) is relabelled together
        stem = re.split(r"[._]", name)[0]
        for q, c in enumerate(header):
            mm = re.match(r"^(.*?)\s*\[(.*)\]$", c.strip())
            if mm and re.split(r"[._]", mm.group(1))[0] == stem and mm.group(2) == unit:
                header[q] = f"{mm.group(1)} [{RELABEL[unit]}]"
        lines[h] = ",".join(header)
    elif cls == "saturation":
        s = rows.index(i)
        for q in rows[s : s + 20]:
            cells = lines[q].split(",")
            big = "2000" if "[g]" in header[j] else "1000" if "deg/s" in header[j] else f"{float(cells[j]) * 1e4:g}"
            cells[j] = big
            lines[q] = ",".join(cells)
    elif cls == "crlf":
        return "\r\n".join(lines)
    elif cls == "bom":
        return "\ufeff" + "\n".join(lines)
    elif cls == "semicolon":
        return "\n".join(s.replace(",", ";") if not s.startswith("#") else s for s in lines)
    elif cls == "huge":
        return "\n".join(lines) + "\n" + ",".join(["1e308"] * 200_000) + "\n"
    elif cls == "mangled_label":
        if header[-1].strip() != "event":
            return None
        last = rows[-1]
        cells = lines[last].split(",")
        cells[-1] = cells[-1][:-2] if len(cells[-1]) > 3 else cells[-1] + "x"
        lines[last] = ",".join(cells)
    elif cls == "duplicate_row":
        lines.insert(rows[-1] + 1, lines[rows[-1]])
    else:
        raise ValueError(cls)
    return "\n".join(lines)


CSV_CLASSES = (
    "nan",
    "inf",
    "text",
    "empty_cell",
    "duplicate_time",
    "backwards_time",
    "gap",
    "truncation",
    "truncation_mid_row",
    "truncated_rows",
    "empty_file",
    "header_only",
    "missing_column",
    "extra_column",
    "renamed_column",
    "wrong_unit_label",
    "saturation",
    "crlf",
    "bom",
    "semicolon",
    "huge",
)
EVENT_CLASSES = ("mangled_label", "duplicate_row", "truncation", "semicolon", "empty_file", "wrong_unit_label")
TOML_CLASSES = (
    "toml_syntax",
    "toml_missing_key",
    "toml_wrong_type",
    "toml_unknown_key",
    "missing_file",
    "spaces_in_path",
)


def mutate_toml(text: str, cls: str, rng: np.random.Generator, keys: dict[str, str]) -> str | None:
    """Scenario TOML ``text`` with ``cls``; ``keys``: {"required": line prefix of a required key,
    "typed": line prefix of a numeric key, "unknown": a key line to misspell}."""
    lines = text.split("\n")

    def find(prefix: str) -> int:
        return next(i for i, s in enumerate(lines) if s.strip().startswith(prefix))

    if cls == "toml_syntax":
        lines.insert(len(lines) // 2, "this is = not [ toml")
    elif cls == "toml_missing_key":
        del lines[find(keys["required"])]
    elif cls == "toml_wrong_type":
        i = find(keys["typed"])
        lines[i] = lines[i].split("=")[0] + '= "fast"'
    elif cls == "toml_unknown_key":
        i = find(keys["unknown"])
        name = lines[i].split("=")[0].strip()
        lines[i] = lines[i].replace(name, name[:-1] + name[-1] * 2, 1)
    else:
        raise ValueError(cls)
    return "\n".join(lines)


# ----------------------------------------------------------------------------------- problems
@dataclass
class Target:
    """A problem's clean inputs: ``scenario`` file, the telemetry ``files`` {stream: path}, the
    ``run(scenario_path, files) -> (verdict, fingerprint)`` input path, TOML key hints, and which
    column of which stream a class mutates (default random)."""

    problem: str
    scenario: Path
    files: dict[str, Path]
    run: Callable[[Path, dict[str, Path]], tuple[str, tuple]]
    toml_keys: dict[str, str]
    columns: dict[tuple[str, str], int]
    streams: tuple[str, ...]
    event_stream: str | None = None


def _verdict_from(health: dict | None, notes: list) -> frozenset:
    """The set of reported findings: the messages of the non-OK health checks (or, before
    issue 12, the readers' notes)."""
    if health is not None:
        return frozenset(_nopath(c["message"]) for c in health["checks"] if c["status"] != "OK")
    return frozenset(_nopath(str(n)) for n in notes)


def _nopath(msg: str) -> str:
    """``msg`` without folder names (the clean and the mutated files live in different folders)."""
    return re.sub(r"(/[^/\n]*)+/", "", msg)


def _fp(*arrays) -> tuple:
    return tuple(round(float(np.nansum(np.asarray(a, float))), 6) for a in arrays) + tuple(
        int(np.asarray(a).size) for a in arrays
    )


@functools.lru_cache(maxsize=64)
def _resolved(path: str):
    """The loaded, schema-validated scenario at ``path`` (cached: CSV mutations share the clean one)."""
    from workbench.io.scenario import load_scenario
    from workbench.problems.runner import resolve

    return resolve(load_scenario(Path(path)))[0]


@functools.lru_cache(maxsize=16)
def _droptest_settings(path: str):
    """The frozen drop-test settings of the scenario at ``path`` (cached: the lander read once)."""
    from workbench.problems.droptest.config import DropSettings

    return DropSettings.from_scenario(_resolved(path))


def droptest_runner(scenario_path: Path, files: dict[str, Path]) -> tuple[frozenset, tuple]:
    """Drop test: ``load_drop_telemetry`` (validation, unit plausibility) + input health."""
    from workbench.problems.droptest.telemetry import load_drop_telemetry

    tel = load_drop_telemetry(_droptest_settings(str(scenario_path)), files)
    try:
        from workbench.estimation.health import health_report
        from workbench.problems.droptest.health import input_checks

        health = health_report(input_checks(tel))
    except ImportError:
        health = None
    att = tel.attitude
    att_v = att.stack([f"{v}.{a}" for v in ("up", "mag") for a in "xyz"])
    fp = _fp(tel.t, tel.f_B, tel.w_B, list(tel.events.values()), att.time, att_v)
    return _verdict_from(health, list(tel.degradations)), fp


def entry_runner(scenario_path: Path, files: dict[str, Path]) -> tuple[frozenset, tuple]:
    """Entry: ``read_entry_telemetry`` (validation, unit plausibility) + the readers' warnings."""
    from workbench.problems.entry.config import EntrySettings
    from workbench.problems.entry.telemetry import read_entry_telemetry, read_nominal_state

    sc = _resolved(str(scenario_path))
    tm = read_entry_telemetry(files, EntrySettings.from_scenario(sc).checks)
    nom = read_nominal_state(files["initial_state"])
    try:
        from workbench.problems.entry.telemetry import check_event_span
    except ImportError:  # before issue 12: the pipeline's check, as it was

        def check_event_span(tm, paths):
            from workbench.io.scenario import ScenarioError

            for ev in ("PDD", "FSR"):
                if ev not in tm.events:
                    raise ScenarioError(paths["events"], ev, "event missing")
                if not (tm.t_gnc[0] <= tm.events[ev] <= tm.t_gnc[-1]):
                    raise ScenarioError(paths["events"], ev, "outside the GNC data")

    check_event_span(tm, files)
    notes = frozenset(_nopath(str(p)) for p in tm.problems if not str(p).startswith("INFO"))
    fp = _fp(tm.t_gnc, tm.w_G, tm.a_M_total[tm.a_valid], tm.p_M_nav, tm.v_M_nav, tm.slant_ranges, tm.slant_out)
    return notes, fp + _fp(nom.p_M, list(tm.events.values()))


def post2_runner(scenario_path: Path, files: dict[str, Path]) -> tuple[frozenset, tuple]:
    """post2: the full reconstruction (a hundred-step filter, milliseconds) and its health."""
    from workbench.problems.post2 import pipeline
    from workbench.problems.post2.config import Post2Settings

    settings = Post2Settings.from_scenario(_resolved(str(scenario_path)))
    res = None
    for stage in pipeline.reconstruct(settings, files):
        res = stage
    health = res.summary.get("health")
    fp = _fp(*[ch.z for ch in res.channels.values()], *[ch.t for ch in res.channels.values()])
    return _verdict_from(health, []), fp


def _copy_inputs(t: Target, where: Path) -> tuple[Path, dict[str, Path]]:
    where.mkdir(parents=True, exist_ok=True)
    files = {}
    for k, p in t.files.items():
        q = where / p.name
        shutil.copyfile(p, q)
        files[k] = q
    sc = where / t.scenario.name
    text = t.scenario.read_text(encoding="utf-8")
    sc.write_text(text, encoding="utf-8")
    return sc, files


def run_case(t: Target, case: Case, work: Path, control: tuple[frozenset, tuple]) -> Outcome:
    """Apply ``case`` to a copy of ``t``'s inputs under ``work`` and classify the outcome."""
    from workbench.io.scenario import ScenarioError
    from workbench.io.telemetry import TelemetryError
    from workbench.io.units import UnitError

    rng = np.random.default_rng([case.seed, hash(case.cls) % 2**31])
    folder = work / (
        f"{case.problem} {case.cls} {case.stream} {case.seed}"
        if case.cls == "spaces_in_path"
        else f"{case.problem}_{case.cls}_{case.stream}_{case.seed}"
    )
    sc, files = _copy_inputs(t, folder)
    mutated = files.get(case.stream, sc)
    if case.cls in TOML_CLASSES:
        if case.cls == "missing_file":
            files[case.stream].unlink()
            mutated = files[case.stream]
        elif case.cls != "spaces_in_path":
            new = mutate_toml(sc.read_text(encoding="utf-8"), case.cls, rng, t.toml_keys)
            sc.write_text(new, encoding="utf-8")
            mutated = sc
    else:
        col = t.columns.get((case.stream, case.cls))
        new = mutate_csv(files[case.stream].read_text(encoding="utf-8"), case.cls, rng, column=col)
        if new is None:
            return Outcome(case, "N/A", "not applicable")
        files[case.stream].write_bytes(new.encode("utf-8"))
    if case.cls not in TOML_CLASSES:
        sc = t.scenario  # unchanged: the clean copy (its parsed form is cached)
    try:
        verdict, fp = t.run(sc, files)
    except (TelemetryError, ScenarioError, UnitError, FileNotFoundError) as err:
        msg = str(err)
        ok = mutated.name in msg or str(mutated) in msg
        return Outcome(case, GOOD if ok else SILENT, ("" if ok else "error does not name the file: ") + msg[:300])
    except Exception as err:  # noqa: BLE001 — any other exception is what the suite looks for
        return Outcome(case, TRACEBACK, f"{type(err).__name__}: {str(err)[:300]}")
    new = verdict - control[0]  # findings the clean files do not have
    if new:
        return Outcome(case, DEGRADED, "reported: " + sorted(new)[0][:200])
    if fp == control[1]:  # the numbers the reconstruction reads are those of the clean files
        return Outcome(case, GOOD, "read to the same numbers as the clean files")
    return Outcome(case, SILENT, "accepted with nothing reported, different numbers")


def cases_for(t: Target, seeds: range) -> list[Case]:
    """Every applicable (class, stream, seed) case of a target."""
    out = []
    for seed in seeds:
        for s in t.streams:
            for cls in CSV_CLASSES:
                out.append(Case(t.problem, cls, s, seed))
        if t.event_stream:
            for cls in EVENT_CLASSES:
                out.append(Case(t.problem, cls, t.event_stream, seed))
        for cls in TOML_CLASSES:
            stream = t.streams[0]
            out.append(Case(t.problem, cls, stream, seed))
    return out


def run_all(targets: list[Target], seeds: range, work: Path) -> list[Outcome]:
    """Run every case of every target; the clean inputs must read with health OK or WARNING."""
    results = []
    for t in targets:
        sc, files = _copy_inputs(t, work / f"{t.problem}_control")
        control = t.run(sc, files)
        for case in cases_for(t, seeds):
            results.append(run_case(t, case, work, control))
    return results


def table(results: list[Outcome]) -> dict[str, dict[str, int]]:
    """{"<problem>/<class>": {"runs": n, "GOOD": .., "DEGRADED": .., "SILENT": .., "TRACEBACK": ..}}."""
    out: dict[str, dict[str, int]] = {}
    for r in results:
        if r.outcome == "N/A":
            continue
        row = out.setdefault(
            f"{r.case.problem}/{r.case.cls}", {"runs": 0, GOOD: 0, DEGRADED: 0, SILENT: 0, TRACEBACK: 0}
        )
        row["runs"] += 1
        row[r.outcome] += 1
    return out


# ----------------------------------------------------------------------------------- targets
def _scenario_copy(name: str, dest: Path) -> Path:
    """The shipped scenario ``name`` written to ``dest`` with its asset paths made absolute."""
    from workbench.io.assets import assets_dir

    src = assets_dir() / "scenarios" / f"{name}.toml"
    text = src.read_text(encoding="utf-8")
    for sub in ("landers", "vehicles"):
        text = text.replace(f'"../{sub}/', f'"{(assets_dir() / sub).as_posix()}/')
    dest.mkdir(parents=True, exist_ok=True)
    out = dest / f"{name}.toml"
    out.write_text(text, encoding="utf-8")
    return out


def droptest_target(telemetry_dir: Path, work: Path) -> Target:
    """The shipped ``droptest`` scenario on the telemetry a synthetic run wrote in ``telemetry_dir``."""
    d = Path(telemetry_dir)
    files = {"imu": d / "imu.csv", "attitude_3dm": d / "3dm.csv", "events": d / "events.csv", "setup": d / "setup.toml"}
    return Target(
        "droptest",
        _scenario_copy("droptest", work / "droptest_src"),
        files,
        droptest_runner,
        {"required": "lander =", "typed": "noise_g =", "unknown": "noise_g ="},
        {("imu", "wrong_unit_label"): 1, ("imu", "saturation"): 1, ("events", "wrong_unit_label"): 0},
        ("imu", "attitude_3dm"),
        "events",
    )


def entry_target(files: dict[str, Path], work: Path) -> Target:
    """The shipped ``schiaparelli`` scenario on entry telemetry ``files`` (e.g. from a short fake
    truth written by ``entry.synthetic.synthesize_from_truth``)."""
    return Target(
        "entry",
        _scenario_copy("schiaparelli", work / "entry_src"),
        {k: Path(v) for k, v in files.items() if k != "truth"},
        entry_runner,
        {"required": "file =", "typed": "members =", "unknown": "saturation_dps ="},
        {("events", "wrong_unit_label"): 0},
        ("gnc", "gnc_nav", "rda_slant_range", "rda_out"),
        "events",
    )


def post2_target(obs_dir: Path, work: Path) -> Target:
    """The shipped ``post2_j2`` scenario on its observation CSV in ``obs_dir``."""
    return Target(
        "post2",
        _scenario_copy("post2_j2", work / "post2_src"),
        {"gravity": Path(obs_dir) / "gravity.csv"},
        post2_runner,
        {"required": "quantity =", "typed": "sigma =", "unknown": "rate_hz ="},
        {},
        ("gravity",),
        None,
    )
