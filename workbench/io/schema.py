"""Declarative scenario schemas: which tables and keys a problem reads, once, with type, unit,
default and meaning.

A problem package declares its :class:`Schema` (``problems/<p>/config.py``); :meth:`Schema.validate`
checks a scenario's parsed TOML against it and returns the values with every default filled in:

* a key that the schema does not know (a misspelling, a key of another problem) is an error —
  a :class:`~workbench.io.scenario.ScenarioError` naming the file, the table and the key, with a
  "did you mean" suggestion (:mod:`difflib`);
* a value of the wrong type, or outside its ``choices``, is an error naming the key;
* a missing key takes its default; a key whose default is :data:`REQUIRED` must be given; a
  default of ``None`` means "absent" (the code decides what that means, the meaning says it).

:func:`render_markdown` turns a schema into the tables of ``io/FORMATS.md`` (between the markers
``<!-- schema:<name>:begin -->`` and ``<!-- schema:<name>:end -->``), so the user documentation is
generated from the same declaration the code reads (:func:`update_formats`; a test checks the file
is in sync).  Regenerate with ``python -m workbench.io.schema --write-formats``.
"""

from __future__ import annotations

import difflib
import importlib
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from workbench.io.scenario import ScenarioError, check_value

__all__ = [
    "REQUIRED",
    "KINDS",
    "Key",
    "Table",
    "Schema",
    "render_markdown",
    "update_formats",
    "write_formats",
    "PROBLEM_CONFIG_MODULES",
]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: Default of a key that must be given.
REQUIRED: Any = _Required()

#: Value kinds: those of :meth:`Scenario.get <workbench.io.scenario.Scenario.get>`, plus
#: ``"number_or_vec3"`` (one number for all three axes, or a list of 3).
KINDS = ("float", "int", "str", "bool", "vec3", "list", "table", "number_or_vec3")

#: Modules holding a problem's ``SCHEMA`` (used by ``--write-formats``).
PROBLEM_CONFIG_MODULES = (
    "workbench.problems.droptest.config",
    "workbench.problems.entry.config",
    "workbench.problems.post2.config",
    "workbench.problems.meads.config",
)


@dataclass(frozen=True)
class Key:
    """One key of a table: ``name``, value ``kind`` (:data:`KINDS`), ``unit`` (as written in the
    file; "" when dimensionless or not a quantity), ``default`` (:data:`REQUIRED`, ``None`` for
    "absent", or the value), what it means, and optional ``choices`` for string keys."""

    name: str
    kind: str
    default: Any
    unit: str = ""
    meaning: str = ""
    choices: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"key {self.name!r}: kind must be one of {KINDS}, got {self.kind!r}")


@dataclass(frozen=True)
class Table:
    """A TOML table (dotted ``name``, e.g. ``"sensors.imu"``) and its keys.  ``free``: the value
    kind of free-form keys (e.g. named radar guns), ``None`` for a closed table."""

    name: str
    meaning: str
    keys: tuple[Key, ...] = ()
    free: str | None = None
    free_meaning: str = ""

    def key(self, name: str) -> Key | None:
        """The :class:`Key` called ``name``, or None."""
        for k in self.keys:
            if k.name == name:
                return k
        return None


def _check(file: Path, dotted: str, v: Any, key: Key | None, kind: str) -> Any:
    if kind == "number_or_vec3":
        if isinstance(v, int | float) and not isinstance(v, bool):
            return float(v)
        return check_value(file, dotted, v, "vec3")
    out = check_value(file, dotted, v, kind)
    if key is not None and key.choices and out not in key.choices:
        raise ScenarioError(file, dotted, f"{out!r}: use one of {', '.join(key.choices)}")
    return out


def _suggest(word: str, candidates: list[str]) -> str:
    close = difflib.get_close_matches(word, candidates, n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


@dataclass(frozen=True)
class Schema:
    """The scenario tables of one problem ``name`` (its ``[scenario] kind``)."""

    name: str
    title: str
    tables: tuple[Table, ...]
    _index: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        index = {t.name: t for t in self.tables}
        if len(index) != len(self.tables):
            raise ValueError(f"schema {self.name}: a table is declared twice")
        object.__setattr__(self, "_index", index)

    def table(self, name: str) -> Table | None:
        """The :class:`Table` called ``name`` (dotted), or None."""
        return self._index.get(name)

    def _children(self, prefix: str) -> list[str]:
        """Names (last part) of the tables directly below ``prefix`` ("" = top level)."""
        out = []
        for t in self.tables:
            parts = t.name.split(".")
            depth = 0 if not prefix else len(prefix.split("."))
            if len(parts) > depth and ".".join(parts[:depth]) == prefix and parts[depth] not in out:
                out.append(parts[depth])
        return out

    def validate(self, data: dict, file: str | Path) -> dict:
        """Check ``data`` (the parsed TOML of ``file``) and return a new nested dict holding every
        declared key — the file's values checked and converted (numbers to float where the kind is
        ``"float"``, ``"vec3"`` to a float array (3,)), the defaults for the others.

        Raises :class:`ScenarioError` naming the file and the dotted key for an unknown key (with
        the table and a "did you mean"), a wrong type, a value outside its choices, or a missing
        required key.
        """
        file = Path(file)
        out: dict = {}
        self._walk(data, "", file, out)
        for t in self.tables:
            node = out
            for part in t.name.split("."):
                node = node.setdefault(part, {})
            for k in t.keys:
                if k.name in node:
                    continue
                if k.default is REQUIRED:
                    raise ScenarioError(file, f"{t.name}.{k.name}", f"missing (required in [{t.name}])")
                node[k.name] = None if k.default is None else _check(file, f"{t.name}.{k.name}", k.default, k, k.kind)
        return out

    def _walk(self, node: dict, prefix: str, file: Path, out: dict) -> None:
        table = self._index.get(prefix)
        children = self._children(prefix)
        for name, v in node.items():
            dotted = f"{prefix}.{name}" if prefix else name
            key = table.key(name) if table is not None else None
            if key is not None:
                out[name] = _check(file, dotted, v, key, key.kind)
            elif name in children:
                if not isinstance(v, dict):
                    raise ScenarioError(file, dotted, f"expected a table [{dotted}], got {type(v).__name__}")
                self._walk(v, dotted, file, out.setdefault(name, {}))
            elif table is not None and table.free is not None:
                out[name] = _check(file, dotted, v, None, table.free)
            else:
                known = ([k.name for k in table.keys] if table is not None else []) + children
                where = f"table [{prefix}]" if prefix else "the top level"
                raise ScenarioError(
                    file,
                    dotted,
                    f"unknown key '{name}' in {where} of a {self.name} scenario{_suggest(name, known)} "
                    f"(keys here: {', '.join(known) or 'none'})",
                )


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
    lines = [f'Keys of a `kind = "{schema.name}"` scenario ({schema.title}). Unknown keys are errors.', ""]
    for t in schema.tables:
        lines += [f"`[{t.name}]` — {_cell(t.meaning)}", ""]
        lines += ["| key | type | unit | default | meaning |", "|---|---|---|---|---|"]
        for k in t.keys:
            meaning = k.meaning
            if k.choices:
                listed = ", ".join(f"`{c}`" for c in k.choices)
                meaning += ("" if meaning.endswith(".") else ".") + f" One of: {listed}."
            kind = "number or vec3" if k.kind == "number_or_vec3" else k.kind
            lines.append(f"| `{k.name}` | {kind} | {_cell(k.unit)} | {_fmt_default(k)} | {_cell(meaning)} |")
        if t.free is not None:
            lines.append(f"| *any name* | {t.free} |  | — | {_cell(t.free_meaning)} |")
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


def main(argv: list[str] | None = None) -> int:
    """``python -m workbench.io.schema --write-formats``: regenerate ``io/FORMATS.md`` from the
    problems' schemas (the modules of :data:`PROBLEM_CONFIG_MODULES`, loaded by name)."""
    argv = sys.argv[1:] if argv is None else argv
    if argv != ["--write-formats"]:
        print("usage: python -m workbench.io.schema --write-formats", file=sys.stderr)
        return 2
    schemas = [importlib.import_module(m).SCHEMA for m in PROBLEM_CONFIG_MODULES]
    path = Path(__file__).with_name("FORMATS.md")
    print(f"{path}: {'updated' if write_formats(path, schemas) else 'already up to date'}")
    return 0


if __name__ == "__main__":  # run the imported module's main: the schemas compare with its REQUIRED
    raise SystemExit(importlib.import_module("workbench.io.schema").main())
