"""A user-data scenario to start from: ``workbench init KIND DIR``.

:func:`init_scenario` writes, for any registered problem kind (or a shipped scenario name, e.g.
``schiaparelli`` for the entry problem):

* ``DIR/scenario.toml`` — **generated from the problem's schema** (:mod:`workbench.io.schema`),
  not copied: every table and key is listed with its unit, default and meaning as comments; the
  keys the base scenario (the shipped scenario of that kind) sets are active with its values, the
  others commented out at their default; the ``[synthetic]`` tables are left out, so it is a
  user-data scenario; files the base scenario points at (a lander, a vehicle) are copied beside it;
* ``DIR/telemetry/`` — example telemetry files of the right shape, written by the problem's own
  truth simulator (:meth:`~workbench.problems.base.Problem.synthesize`) exactly as a user would
  supply them (the truth file it also writes is removed: user data has no truth);
* ``DIR/README.md`` — what to replace: each telemetry file with its scenario key, meaning and the
  first lines of the example (the columns and units), and the keys to review.

The values that are facts of the example's own test or flight (schema keys declared ``example``:
its epoch, its chamber, its rig) are marked ``# EXAMPLE — replace ...`` where the scenario sets them,
and in the example TOML telemetry files a problem declares in ``telemetry_schemas`` (the drop
setup file's hanging position and bungee); the README lists them.

The scenario's telemetry keys are found by name: ``[telemetry] <stream>`` when the schema has
that table, else ``[observations.<stream>] file`` (and ``weights`` for ``<stream>_weights``). The
written scenario is checked before returning: it validates against the schema and the problem
resolves exactly the telemetry files written. ``workbench run DIR/scenario.toml`` runs it as is.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from workbench.io.assets import assets_dir
from workbench.io.scenario import Scenario, ScenarioError, find_scenarios, load_scenario
from workbench.io.schema import EXAMPLE_MARK, REQUIRED, Key, Schema
from workbench.problems import registry
from workbench.problems.base import Problem
from workbench.problems.runner import resolve

__all__ = ["InitResult", "base_scenario", "init_scenario", "mark_examples", "scenario_toml"]

SYNTHETIC_TABLE = "synthetic"


@dataclass(frozen=True)
class InitResult:
    """What :func:`init_scenario` wrote: the ``scenario`` file, the ``telemetry`` files
    {stream: path}, the ``readme``, the ``copied`` auxiliary files, and the ``base`` scenario."""

    scenario: Path
    telemetry: dict[str, Path]
    readme: Path
    copied: tuple[Path, ...]
    base: Scenario


def base_scenario(kind_or_name: str) -> tuple[Scenario, Problem]:
    """The shipped scenario to start from and its problem: a shipped scenario name as given, or
    for a problem kind the shipped scenario named like the kind (else the first of that kind).
    Raises :class:`~workbench.problems.registry.UnknownKindError` / ``ScenarioError``."""
    shipped = find_scenarios(assets_dir())
    if kind_or_name in shipped:
        sc, problem = resolve(load_scenario(shipped[kind_or_name]))
        return sc, problem
    problem = registry.get(kind_or_name)
    same = sorted(n for n, p in shipped.items() if load_scenario(p).kind == kind_or_name)
    if not same:
        raise ScenarioError(
            Path(kind_or_name), "scenario.kind", f"no shipped scenario of kind {kind_or_name!r} to start from"
        )
    name = kind_or_name if kind_or_name in same else same[0]
    sc, _ = resolve(load_scenario(shipped[name]))
    return sc, problem


# ------------------------------------------------------------------------------ TOML writing
def _toml_value(v: Any) -> str:
    """A TOML literal of ``v`` (bool, int, float, str, list, dict as an inline table)."""
    if isinstance(v, bool | np.bool_):
        return "true" if v else "false"
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        f = float(v)
        if math.isinf(f):
            return "inf" if f > 0 else "-inf"
        if math.isnan(f):
            return "nan"
        return repr(f)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, np.ndarray):
        return _toml_value(v.tolist())
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_bare(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _bare(key: str) -> str:
    return key if key.replace("_", "").replace("-", "").isalnum() else json.dumps(key)


def _comment(text: str, width: int = 100) -> list[str]:
    words, lines, cur = text.split(), [], "#"
    for w in words:
        if len(cur) + 1 + len(w) > width and cur != "#":
            lines.append(cur)
            cur = "#"
        cur += " " + w
    if cur != "#":
        lines.append(cur)
    return lines


def _key_doc(k: Key) -> str:
    unit = f" [{k.unit}]" if k.unit else ""
    if k.default is REQUIRED:
        default = "required"
    elif k.default is None:
        default = "default: absent"
    else:
        default = f"default: {_toml_value(k.default)}"
    choices = f"; one of {', '.join(k.choices)}" if k.choices else ""
    return f"{k.name}{unit} ({k.kind}, {default}{choices}): {k.meaning}"


def _get(data: dict, dotted: str) -> Any:
    node: Any = data
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


def scenario_toml(schema: Schema, values: dict, header: str) -> str:
    """The scenario file text: ``header`` (comment lines), then every table of ``schema`` in
    declaration order with its meaning, every key documented (unit, kind, default, meaning) and
    set to ``values`` (the nested scenario dict) where given, else commented out at its default; a
    given value of an ``example`` key (a fact of the example's test or flight) is marked
    :data:`~workbench.io.schema.EXAMPLE_MARK`.
    Free-form tables write the entries ``values`` holds (sub-tables as ``[table.name]`` sections).
    Tables named ``synthetic`` (and below) are left out."""
    out = [*header.rstrip().splitlines(), ""]
    for t in schema.tables:
        if t.name == SYNTHETIC_TABLE or t.name.startswith(SYNTHETIC_TABLE + "."):
            continue
        node = _get(values, t.name)
        if not isinstance(node, dict):  # absent: its presence may switch a feature on (rocks)
            out += [f"# [{t.name}]   (not used by this scenario; uncomment the table to use it)"]
            out += _comment(t.meaning)
            for k in t.keys:
                out += ["#", *_comment(_key_doc(k))]
                absent = k.default is None or k.default is REQUIRED
                out.append(f"# {k.name} = " + ("" if absent else _toml_value(k.default)))
            out.append("")
            continue
        out.append(f"[{t.name}]")
        out += _comment(t.meaning)
        for k in t.keys:
            out += ["#", *_comment(_key_doc(k))]
            if k.name in node and node[k.name] is not None:
                if k.example:  # a fact of the example's test or flight: to be replaced
                    out.append(EXAMPLE_MARK)
                out.append(f"{k.name} = {_toml_value(node[k.name])}")
            elif k.default is REQUIRED:
                out.append(f"{k.name} = ")  # left empty on purpose: TOML refuses it until filled in
            elif k.default is None:
                out.append(f"# {k.name} = ")
            else:
                out.append(f"# {k.name} = {_toml_value(k.default)}")
        if t.free is not None:
            declared = {k.name for k in t.keys} | {
                s.name.split(".")[len(t.name.split("."))] for s in schema.tables if s.name.startswith(t.name + ".")
            }
            extra = {n: v for n, v in node.items() if n not in declared}
            out += ["#", *_comment(f"any name ({t.free}): {t.free_meaning}")]
            subtables = {n: v for n, v in extra.items() if isinstance(v, dict) and t.free == "table"}
            for n, v in extra.items():
                if n not in subtables:
                    out.append(f"{_bare(n)} = {_toml_value(v)}")
            for n, v in subtables.items():
                out += ["", f"[{t.name}.{_bare(n)}]"]
                out += [f"{_bare(a)} = {_toml_value(b)}" for a, b in v.items()]
        out.append("")
    return "\n".join(out).rstrip() + "\n"


def mark_examples(path: Path, schema: Schema) -> list[str]:
    """Mark, in the TOML file ``path`` of ``schema`` (an example telemetry file such as the drop
    setup file), every ``key = value`` line of an ``example`` key with :data:`EXAMPLE_MARK` on the
    line above; rewrites the file, returns the dotted keys marked (in file order)."""
    lines, out, marked, table = path.read_text(encoding="utf-8").splitlines(), [], [], ""
    for ln in lines:
        s = ln.strip()
        if s.startswith("[") and not s.startswith("[["):
            table = s.strip("[]").strip()
        elif "=" in s and not s.startswith("#"):
            t = schema.table(table)
            k = t.key(s.split("=", 1)[0].strip()) if t is not None else None
            if k is not None and k.example:
                out.append(EXAMPLE_MARK)
                marked.append(f"{table}.{k.name}" if table else k.name)
        out.append(ln)
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return marked


def _example_keys(schema: Schema, data: dict) -> list[str]:
    """The dotted ``example`` keys of ``schema`` that ``data`` (the nested scenario) sets."""
    out = []
    for t in schema.tables:
        node = _get(data, t.name)
        if isinstance(node, dict):
            out += [f"{t.name}.{k.name}" for k in t.keys if k.example and node.get(k.name) is not None]
    return out


# ------------------------------------------------------------------------------ the command
def _telemetry_key(schema: Schema, stream: str, data: dict) -> str:
    t = schema.table("telemetry")
    if t is not None and t.key(stream) is not None:
        return f"telemetry.{stream}"
    obs = data.get("observations", {})
    if stream.endswith("_weights") and stream[: -len("_weights")] in obs:
        return f"observations.{stream[: -len('_weights')]}.weights"
    if stream in obs:
        return f"observations.{stream}.file"
    raise ScenarioError(Path("scenario.toml"), stream, "no scenario key found for this telemetry stream")


def _set(data: dict, dotted: str, value: Any) -> None:
    parts = dotted.split(".")
    node = data
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value


def _copy_referenced(data: Any, base_dir: Path, out_dir: Path, copied: list[Path], prefix: str = "") -> Any:
    """Copy the files that string values point at (relative to ``base_dir``) into ``out_dir`` and
    point the values at the copies; returns the new value."""
    if isinstance(data, dict):
        return {k: _copy_referenced(v, base_dir, out_dir, copied, f"{prefix}{k}.") for k, v in data.items()}
    if isinstance(data, str) and ("/" in data or data.endswith((".toml", ".csv", ".json", ".obj", ".stl"))):
        src = (base_dir / data).resolve()
        if src.is_file():
            dst = out_dir / src.name
            shutil.copyfile(src, dst)
            copied.append(dst)
            return src.name
    return data


def _head(path: Path, n: int = 4) -> list[str]:
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            lines = [ln.rstrip("\n") for _, ln in zip(range(n), f, strict=False)]
    except OSError:
        return []
    return [ln if len(ln) <= 160 else ln[:157] + "..." for ln in lines]


def init_scenario(
    kind_or_name: str, out_dir: str | os.PathLike[str], *, seed: int = 1, overwrite: bool = False
) -> InitResult:
    """Write a working user-data scenario for ``kind_or_name`` (a problem kind or a shipped
    scenario name) into ``out_dir`` (see the module docstring); ``seed`` drives the example
    telemetry's sensor errors. Refuses (``FileExistsError``) to write into a folder that already
    holds a ``scenario.toml`` unless ``overwrite``."""
    out = Path(out_dir)
    if (out / "scenario.toml").exists() and not overwrite:
        raise FileExistsError(f"{out / 'scenario.toml'} exists; choose another folder")
    base, problem = base_scenario(kind_or_name)
    if problem.schema is None:
        raise NotImplementedError(f"the {base.kind} problem declares no schema: cannot write a scenario from it")
    out.mkdir(parents=True, exist_ok=True)
    tel_dir = out / "telemetry"
    syn = problem.synthesize(problem.settings(base), tel_dir, seed)
    Path(syn.truth).unlink(missing_ok=True)
    copied: list[Path] = []
    data = {k: v for k, v in base.data.items() if k != SYNTHETIC_TABLE}
    data = _copy_referenced(data, base.path.parent, out, copied)
    name = out.resolve().name.replace(" ", "_") or f"my_{base.kind}"
    data.setdefault("scenario", {})
    data["scenario"]["name"] = name
    data["scenario"]["description"] = f"user data ({base.kind}); started from the shipped scenario '{base.name}'"
    telemetry = {s: Path(p) for s, p in syn.telemetry.items()}
    keys = {}
    for stream, path in telemetry.items():
        key = _telemetry_key(problem.schema, stream, data)
        _set(data, key, path.relative_to(out).as_posix())
        keys[stream] = key
    header = "\n".join(
        [
            f"# Your own data: {problem.schema.title} (kind {base.kind!r}).",
            f"# Written by `workbench init {kind_or_name}` from the shipped scenario {base.name!r}; every key of",
            "# the schema is listed with its unit, kind, default and meaning. Active keys hold the",
            "# shipped scenario's values; commented keys are at their default. The example files under",
            "# telemetry/ were written by the problem's truth simulator: replace them with yours",
            "# (README.md says how) and run:  workbench run scenario.toml",
        ]
    )
    text = scenario_toml(problem.schema, data, header)
    examples = {"scenario.toml": _example_keys(problem.schema, data)}
    for stream, schema in (getattr(problem, "telemetry_schemas", None) or {}).items():
        if stream in telemetry:  # an example TOML telemetry file (the drop setup file): its site's values
            examples[telemetry[stream].relative_to(out).as_posix()] = mark_examples(telemetry[stream], schema)
    path = out / "scenario.toml"
    path.write_text(text, encoding="utf-8")
    # the check: it loads, validates and names exactly the files written
    sc, _ = resolve(load_scenario(path))
    if sc.is_synthetic:
        raise AssertionError(f"{path}: the written scenario is still synthetic")
    found = {s: Path(p).resolve() for s, p in problem.telemetry_files(problem.settings(sc)).items()}
    want = {s: p.resolve() for s, p in telemetry.items()}
    if found != want:
        raise ScenarioError(path, "telemetry", f"resolves {found}, expected the files written: {want}")
    readme = out / "README.md"
    readme.write_text(_readme(problem, base, sc, telemetry, keys, copied, out, examples), encoding="utf-8")
    return InitResult(path, telemetry, readme, tuple(copied), base)


def _readme(
    problem: Problem,
    base: Scenario,
    sc: Scenario,
    telemetry: dict[str, Path],
    keys: dict[str, str],
    copied: list[Path],
    out: Path,
    examples: dict[str, list[str]],
) -> str:
    schema = problem.schema
    lines = [
        f"# `{sc.name}`: your own data, {schema.title}",
        "",
        f"Written by `workbench init` from the shipped scenario `{base.name}` (kind `{base.kind}`). It runs as",
        "it is on the example telemetry in `telemetry/`, which the problem's truth simulator wrote in",
        "exactly the format a user supplies:",
        "",
        "```",
        f"workbench run {out / 'scenario.toml'} --out recordings",
        "```",
        "",
        "## What to replace",
        "",
        "1. **The telemetry files** below with your own, same columns and units (the header line of",
        "   each CSV names the column and its unit; the reader converts to SI and names file, column",
        "   and row of anything it cannot read). Keep the file names or change the keys that name them.",
        "2. **The keys of `scenario.toml`** that describe your test or flight: every key is documented",
        "   there (unit, default, meaning); the full tables are in `workbench/io/FORMATS.md`.",
        "3. `[scenario] name` (names the recording) and `description`.",
        "",
        "| stream | scenario key | meaning | file |",
        "|---|---|---|---|",
    ]
    tt = schema.table("telemetry")
    for stream, path in telemetry.items():
        key = keys[stream]
        k = tt.key(stream) if tt is not None else None
        meaning = (k.meaning if k is not None else "see the problem's observations").replace("|", "\\|")
        lines.append(f"| `{stream}` | `{key}` | {meaning} | `{path.relative_to(out).as_posix()}` |")
    marked = [(f, k) for f, ks in examples.items() for k in ks]
    if marked:
        lines += [
            "",
            "## Values of the example's test to replace",
            "",
            f"These hold the shipped example's facts (its date, site, rig), marked `{EXAMPLE_MARK}` where",
            "they are set; no default fits another test:",
            "",
            *[f"- `{f}`: `{k}`" for f, k in marked],
        ]
    lines += ["", "## The example files, first lines", ""]
    for stream, path in telemetry.items():
        lines += [f"`{path.relative_to(out).as_posix()}` ({stream}):", "", "```", *_head(path), "```", ""]
    if copied:
        lines += [
            "## Files copied from the shipped assets",
            "",
            *[f"- `{p.name}`: the base scenario pointed at it; edit it to describe your vehicle." for p in copied],
            "",
        ]
    lines += [
        "## Without truth",
        "",
        "User data has no truth: the run reports the reconstruction, its uncertainty, residual",
        "whiteness and NIS consistency, but no errors against a truth. To see how the reconstruction",
        f"scores against a known truth, run the shipped synthetic scenario `workbench run {base.name}`.",
        "",
    ]
    return "\n".join(lines)
