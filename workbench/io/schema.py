"""Declarative schemas of every input file: which tables and keys a file kind has, once, with
type, unit, default, bounds and meaning.

A problem package declares the :class:`Schema` of its scenario (``problems/<p>/config.py``) and of
every other file it reads (lander and vehicle assets, the drop setup file, a flight log's metadata:
its ``file_schemas``); :meth:`Schema.validate` checks a parsed TOML or JSON document against it and
returns the values with every default filled in:

* a key that the schema does not know (a misspelling, a key of another problem) is an error —
  a :class:`~workbench.io.scenario.ScenarioError` naming the file, the table and the key, with a
  "did you mean" suggestion (:mod:`difflib`);
* a value of the wrong type, outside its ``choices`` or outside its numeric bounds (``ge``, ``gt``,
  ``le``, ``lt``; every element of a vector or list) is an error naming the key and the bound;
* a missing key takes its default; a key whose default is :data:`REQUIRED` must be given; a
  default of ``None`` means "absent" (the code decides what that means, the meaning says it).

:func:`render_markdown` turns a schema into the tables of ``io/FORMATS.md`` (between the markers
``<!-- schema:<name>:begin -->`` and ``<!-- schema:<name>:end -->``), so the user documentation is
generated from the same declaration the code reads (:func:`update_formats`; a test checks the file
is in sync).  The schemas are handed in by :func:`workbench.problems.registry.schemas`; regenerate
with ``python -m workbench.problems.registry --write-formats``.

This module and :mod:`workbench.io.scenario` are the schema layer: the only places that open a
TOML or JSON input file (:func:`read_toml`, :func:`read_json`, :func:`load_file`).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from workbench.io.scenario import ScenarioError, check_value, parse_file, read_toml

__all__ = [
    "REQUIRED",
    "EXAMPLE_MARK",
    "KINDS",
    "Key",
    "Table",
    "Schema",
    "from_table",
    "load_file",
    "read_json",
    "read_toml",
    "render_markdown",
    "scenario_table",
    "update_formats",
    "write_formats",
]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: Default of a key that must be given.
REQUIRED: Any = _Required()

#: The comment ``workbench init`` writes above a shipped example's value of an ``example`` key.
EXAMPLE_MARK = "# EXAMPLE — replace with your own value (this is the shipped example's)"

#: Value kinds: those of :meth:`Scenario.get <workbench.io.scenario.Scenario.get>`, plus
#: ``"number_or_vec3"`` (one number for all three axes, or a list of 3) and ``"number_or_list"``
#: (one number for every item, or a list: e.g. one value per face); a number is returned as float.
KINDS = ("float", "int", "str", "bool", "vec3", "list", "table", "number_or_vec3", "number_or_list")


@dataclass(frozen=True)
class Key:
    """One key of a table: ``name``, value ``kind`` (:data:`KINDS`), ``unit`` (as written in the
    file; "" when dimensionless or not a quantity), ``default`` (:data:`REQUIRED`, ``None`` for
    "absent", or the value), what it means, optional ``choices`` for string keys, and optional
    numeric bounds in the key's own unit: ``ge`` (≥), ``gt`` (>), ``le`` (≤), ``lt`` (<), applied
    to a number and to every number of a vector or (nested) list; NaN is outside every bound.
    ``example``: the value is a fact of one particular test or flight (its date, its site, its rig)
    that has no default for another one: ``workbench init`` marks a shipped example's value of it
    to be replaced (:data:`EXAMPLE_MARK`)."""

    name: str
    kind: str
    default: Any
    unit: str = ""
    meaning: str = ""
    choices: tuple[str, ...] = ()
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    example: bool = False

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"key {self.name!r}: kind must be one of {KINDS}, got {self.kind!r}")

    @property
    def bounds(self) -> str:
        """The bounds as text, e.g. ``"> 0, < 90"`` ("" when unbounded)."""
        parts = [f"{op} {_num(v)}" for op, v in (("≥", self.ge), (">", self.gt), ("≤", self.le), ("<", self.lt))
                 if v is not None]  # fmt: skip
        return ", ".join(parts)

    def check_bounds(self, file: Path, dotted: str, v: Any) -> None:
        """:class:`ScenarioError` naming ``file``, ``dotted`` and the bound if a number of ``v``
        is outside the bounds (or NaN) while the key has any."""
        if self.ge is None and self.gt is None and self.le is None and self.lt is None:
            return
        for x in _numbers(v):
            ok = (
                (self.ge is None or x >= self.ge)
                and (self.gt is None or x > self.gt)
                and (self.le is None or x <= self.le)
                and (self.lt is None or x < self.lt)
            )
            if not ok:
                unit = f" {self.unit}" if self.unit and self.unit != "1" else ""
                raise ScenarioError(file, dotted, f"{_num(x)}{unit} is out of range: must be {self.bounds}{unit}")


def _num(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _numbers(v: Any) -> list[float]:
    """Every number in ``v`` (a number, an array, or nested lists); other values are skipped."""
    if isinstance(v, bool) or v is None or isinstance(v, str):
        return []
    if isinstance(v, int | float):
        return [float(v)]
    if isinstance(v, np.ndarray):
        return [float(x) for x in v.ravel()] if v.dtype.kind in "fiu" else []
    if isinstance(v, list | tuple):
        return [x for item in v for x in _numbers(item)]
    return []


@dataclass(frozen=True)
class Table:
    """A TOML table (dotted ``name``, e.g. ``"sensors.imu"``) and its keys.  ``free``: the value
    kind of free-form keys (e.g. named radar guns), ``None`` for a closed table; ``free_ge`` /
    ``free_gt``: bounds (≥, >) of every number of a free-form key's value, as a :class:`Key`'s."""

    name: str
    meaning: str
    keys: tuple[Key, ...] = ()
    free: str | None = None
    free_meaning: str = ""
    free_ge: float | None = None
    free_gt: float | None = None

    @property
    def free_key(self) -> Key | None:
        """The :class:`Key` every free-form key is checked as (its kind and bounds), or None."""
        if self.free is None:
            return None
        return Key("*", self.free, None, ge=self.free_ge, gt=self.free_gt)

    def key(self, name: str) -> Key | None:
        """The :class:`Key` called ``name``, or None."""
        for k in self.keys:
            if k.name == name:
                return k
        return None


def scenario_table(
    kind: str, *, epoch: str | None = None, name: str = "names the run, its recording and summary"
) -> Table:
    """The ``[scenario]`` table every scenario opens with (the keys :func:`~workbench.io.scenario.load_scenario`
    reads before the problem is known): ``name`` (required; ``name`` says what it names), ``kind``
    (required, ``"<kind>"``), ``description`` and, when ``epoch`` gives its meaning, ``epoch_utc``
    (UTC of t = 0; absent = the problem has no epoch)."""
    keys = (
        Key("name", "str", REQUIRED, meaning=name),
        Key("kind", "str", REQUIRED, meaning=f'`"{kind}"`'),
        Key("description", "str", "", meaning="one line for listings"),
    )
    if epoch is not None:
        keys += (Key("epoch_utc", "str", None, meaning=epoch, example=True),)
    return Table("scenario", "what the run is", keys)


def _check(file: Path, dotted: str, v: Any, key: Key | None, kind: str) -> Any:
    if kind in ("number_or_vec3", "number_or_list"):
        one = isinstance(v, int | float) and not isinstance(v, bool)
        out = float(v) if one else check_value(file, dotted, v, kind.removeprefix("number_or_"))
        if key is not None:
            key.check_bounds(file, dotted, out)
        return out
    out = check_value(file, dotted, v, kind)
    if key is not None and key.choices and out not in key.choices:
        raise ScenarioError(
            file, dotted, f"{out!r}: use one of {', '.join(key.choices)}{_suggest(str(out), list(key.choices))}"
        )
    if key is not None:
        key.check_bounds(file, dotted, out)
    return out


def _suggest(word: str, candidates: list[str]) -> str:
    close = difflib.get_close_matches(word, candidates, n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


@dataclass(frozen=True)
class Schema:
    """The tables of one file kind: a problem's scenario (``name`` its ``[scenario] kind``) or
    another input file (``name`` e.g. ``"lander"``).  ``noun`` names the file kind in errors
    (default ``"<name> scenario"``); ``intro``: the sentence that opens its generated documentation
    (default: ``Keys of a `kind = "<name>"` scenario (<title>)``).  A table named ``""`` holds the
    top-level keys of a file without tables (JSON)."""

    name: str
    title: str
    tables: tuple[Table, ...]
    noun: str = ""
    intro: str = ""
    _index: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        index = {t.name: t for t in self.tables}
        if len(index) != len(self.tables):
            raise ValueError(f"schema {self.name}: a table is declared twice")
        object.__setattr__(self, "_index", index)
        if not self.noun:
            object.__setattr__(self, "noun", f"{self.name} scenario")

    def table(self, name: str) -> Table | None:
        """The :class:`Table` called ``name`` (dotted), or None."""
        return self._index.get(name)

    def _children(self, prefix: str) -> list[str]:
        """Names (last part) of the tables directly below ``prefix`` ("" = top level)."""
        out = []
        for t in self.tables:
            if not t.name:
                continue
            parts = t.name.split(".")
            depth = 0 if not prefix else len(prefix.split("."))
            if len(parts) > depth and ".".join(parts[:depth]) == prefix and parts[depth] not in out:
                out.append(parts[depth])
        return out

    def validate(self, data: dict, file: str | Path, *, where: str = "", optional: tuple[str, ...] = ()) -> dict:
        """Check ``data`` (the parsed TOML or JSON of ``file``) and return a new nested dict holding
        every declared key — the file's values checked and converted (numbers to float where the kind
        is ``"float"``, ``"vec3"`` to a float array (3,)), the defaults for the others.

        ``where``: the dotted path of ``data`` inside the file (an entry of a JSON document), put
        before every key an error names.  ``optional``: tables whose required keys are required only
        when the table is present (an absent one is filled with its defaults and ``None``).

        Raises :class:`ScenarioError` naming the file and the dotted key for an unknown key (with
        the table and a "did you mean"), a wrong type, a value outside its choices or bounds, or a
        missing required key.
        """
        file = Path(file)
        if not isinstance(data, dict):
            raise ScenarioError(file, where or None, f"expected a table of keys, got {type(data).__name__}")
        out: dict = {}
        self._walk(data, "", file, out, where)
        for t in self.tables:
            node, given = out, data
            for part in [p for p in t.name.split(".") if p]:
                node = node.setdefault(part, {})
                given = given.get(part) if isinstance(given, dict) else None
            absent_optional = given is None and t.name in optional
            for k in t.keys:
                if k.name in node:
                    continue
                dotted = _join(where, f"{t.name}.{k.name}" if t.name else k.name)
                if k.default is REQUIRED and not absent_optional:
                    raise ScenarioError(file, dotted, f"missing (required in {_where(t.name)} of a {self.noun})")
                node[k.name] = (
                    None if (k.default is None or k.default is REQUIRED) else _check(file, dotted, k.default, k, k.kind)
                )
        return out

    def _walk(self, node: dict, prefix: str, file: Path, out: dict, where: str = "") -> None:
        table = self._index.get(prefix)
        children = self._children(prefix)
        for name, v in node.items():
            name = str(name)
            dotted = _join(where, f"{prefix}.{name}" if prefix else name)
            key = table.key(name) if table is not None else None
            if key is not None:
                out[name] = _check(file, dotted, v, key, key.kind)
            elif name in children:
                if not isinstance(v, dict):
                    raise ScenarioError(file, dotted, f"expected a table [{dotted}], got {type(v).__name__}")
                self._walk(v, f"{prefix}.{name}" if prefix else name, file, out.setdefault(name, {}), where)
            elif table is not None and table.free is not None:
                out[name] = _check(file, dotted, v, table.free_key, table.free)
            else:
                known = ([k.name for k in table.keys] if table is not None else []) + children
                raise ScenarioError(
                    file,
                    dotted,
                    f"unknown key '{name}' in {_where(prefix)} of a {self.noun}{_suggest(name, known)} "
                    f"(keys here: {', '.join(known) or 'none'})",
                )


def _join(where: str, dotted: str) -> str:
    return f"{where}.{dotted}" if where else dotted


def _where(table: str) -> str:
    return f"table [{table}]" if table else "the top level"


_T = TypeVar("_T")


def from_table(cls: type[_T], table: dict, **given: Any) -> _T:
    """The frozen settings dataclass ``cls`` of one validated table (:meth:`Schema.validate`):
    each field takes the value ``given`` for it, else the table's key of the same name (already
    checked and defaulted), else the field's own default.  For a stage whose fields mirror its
    table's keys, so only the fields that are converted or derived are spelled out; keys of the
    table that are no field of ``cls`` are left to the caller.  TypeError for a ``given`` name that
    is no field (a typo), or a field without a value."""
    fields = [f for f in dataclasses.fields(cls) if f.init]  # type: ignore[arg-type]
    unknown = set(given) - {f.name for f in fields}
    if unknown:
        raise TypeError(f"{cls.__name__} has no field {', '.join(sorted(unknown))}")
    kw = {
        f.name: given[f.name] if f.name in given else table[f.name]
        for f in fields
        if f.name in given or f.name in table
    }
    return cls(**kw)


# ------------------------------------------------------------------------------ reading files
def read_json(path: str | Path) -> Any:
    """The parsed JSON document at ``path``; :class:`ScenarioError` naming the file (line and
    column of a syntax error) when it is missing, unreadable or not valid JSON."""
    return parse_file(
        path,
        lambda p: json.loads(p.read_text(encoding="utf-8")),
        json.JSONDecodeError,
        lambda exc: f"not valid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})",
    )


def load_file(path: str | Path, schema: Schema, *, optional: tuple[str, ...] = ()) -> dict:
    """Read the TOML (or, for a ``.json`` path, JSON) file ``path`` and validate it against
    ``schema`` (:meth:`Schema.validate`): the values with every default filled in."""
    path = Path(path)
    data = read_json(path) if path.suffix.lower() == ".json" else read_toml(path)
    return schema.validate(data, path, optional=optional)


# ------------------------------------------------------------------------------ documentation
def _fmt_default(k: Key) -> str:
    d = k.default
    if d is REQUIRED:
        return "required"
    if d is None:
        return "—"
    if isinstance(d, bool):
        return f"`{str(d).lower()}`"
    if isinstance(d, str):
        return f'`"{d}"`'
    if isinstance(d, float) and math.isinf(d):
        return "`inf`"
    if isinstance(d, list | tuple | np.ndarray):
        return "`" + repr([x if not isinstance(x, tuple) else list(x) for x in d]).replace("'", '"') + "`"
    return f"`{d!r}`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render_markdown(schema: Schema) -> str:
    """The schema as markdown: one table per TOML table (key, type, unit, default, meaning)."""
    intro = schema.intro or f'Keys of a `kind = "{schema.name}"` scenario ({schema.title})'
    lines = [f"{intro}. Unknown keys are errors; a value outside its range is an error naming the bound.", ""]
    bounded = any(k.bounds for t in schema.tables for k in (*t.keys, *([t.free_key] if t.free_key else [])))
    for t in schema.tables:
        lines += [f"`[{t.name}]` — {_cell(t.meaning)}" if t.name else f"top level — {_cell(t.meaning)}", ""]
        if bounded:
            lines += ["| key | type | unit | default | range | meaning |", "|---|---|---|---|---|---|"]
        else:
            lines += ["| key | type | unit | default | meaning |", "|---|---|---|---|---|"]
        for k in t.keys:
            meaning = k.meaning
            if k.choices:
                listed = ", ".join(f"`{c}`" for c in k.choices)
                meaning += ("" if meaning.endswith(".") else ".") + f" One of: {listed}."
            kind = k.kind.replace("_", " ") if k.kind.startswith("number_or_") else k.kind
            rng = f" {k.bounds} |" if bounded else ""
            lines.append(f"| `{k.name}` | {kind} | {_cell(k.unit)} | {_fmt_default(k)} |{rng} {_cell(meaning)} |")
        if t.free is not None:
            rng = f" {t.free_key.bounds} |" if bounded else ""
            lines.append(f"| *any name* | {t.free} |  | — |{rng} {_cell(t.free_meaning)} |")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def update_formats(text: str, schemas: list[Schema] | tuple[Schema, ...]) -> str:
    """``text`` (FORMATS.md) with the part between ``<!-- schema:<name>:begin -->`` and
    ``<!-- schema:<name>:end -->`` replaced by :func:`render_markdown` of each schema.
    Raises ValueError when a schema's markers are missing."""
    for s in schemas:
        begin, end = f"<!-- schema:{s.name}:begin -->", f"<!-- schema:{s.name}:end -->"
        i, j = text.find(begin), text.find(end)
        if i < 0 or j < i:
            raise ValueError(f"FORMATS.md has no '{begin}' ... '{end}' markers")
        text = text[: i + len(begin)] + "\n" + render_markdown(s) + text[j:]
    return text


def write_formats(path: str | Path, schemas: list[Schema] | tuple[Schema, ...]) -> bool:
    """Regenerate the schema tables in the markdown file ``path``; True if it changed."""
    path = Path(path)
    old = path.read_text(encoding="utf-8")
    new = update_formats(old, schemas)
    if new != old:
        path.write_text(new, encoding="utf-8")
    return new != old
