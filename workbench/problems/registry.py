"""Which :class:`~workbench.problems.base.Problem` handles a scenario ``kind``, and the schema of
every input file kind.

The built-in problems (``droptest``, ``entry``, ``post2``, ``meads``) are imported the first time
they are asked for, so ``import workbench.problems`` stays light.  Other problems (a user's, a
test's) are added with :func:`register` and removed with :func:`unregister`.  This module is the
only place that imports a module by name (the built-ins and the importers, :data:`BUILTIN`,
:data:`IMPORTERS`); it hands the schemas to :mod:`workbench.io.schema` (:func:`schemas`,
``python -m workbench.problems.registry --write-formats`` regenerates ``io/FORMATS.md``).
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType

from workbench.io.schema import Schema, write_formats
from workbench.problems.base import Problem

__all__ = [
    "IMPORTERS",
    "UnknownKindError",
    "get",
    "import_modules",
    "importer",
    "kinds",
    "register",
    "schemas",
    "unregister",
]

#: built-in kinds -> "module:attribute" of a zero-argument factory (imported on first use)
BUILTIN: dict[str, str] = {
    "droptest": "workbench.problems.droptest.problem:DropTestProblem",
    "entry": "workbench.problems.entry.problem:EntryProblem",
    "post2": "workbench.problems.post2.problem:Post2Problem",
    "meads": "workbench.problems.meads.problem:MeadsProblem",
}

#: importers of third-party logs (``workbench import <name> ...``) -> module; each module has
#: ``HELP`` (one line), ``add_arguments(parser)`` and ``run(args) -> Path`` (the problem file written)
IMPORTERS: dict[str, str] = {
    "airbrakes": "workbench.problems.post2.importers.airbrakes",
    "csv": "workbench.problems.post2.importers.mapped",
}

_registered: dict[str, Problem] = {}


class UnknownKindError(LookupError):
    """No problem is registered for a scenario kind; the message lists the known kinds."""

    def __init__(self, kind: str, where: str | None = None):
        self.kind = kind
        self.where = where
        prefix = f"{where}: " if where else ""
        super().__init__(
            f"{prefix}no problem is registered for scenario kind {kind!r}; known kinds: {', '.join(kinds())}"
        )


def register(problem: Problem, *, replace: bool = False) -> Problem:
    """Make ``problem`` handle scenarios of kind ``problem.kind``; returns it.

    Raises ``ValueError`` if the kind is already taken (a registered or a built-in problem) unless
    ``replace`` is True, and ``TypeError`` if ``problem`` lacks a method of the protocol.
    """
    kind = getattr(problem, "kind", None)
    if not isinstance(kind, str) or not kind:
        raise TypeError(f"a problem needs a non-empty string attribute 'kind', got {kind!r}")
    if not isinstance(problem, Problem):
        missing = [m for m in _protocol_members() if not hasattr(problem, m)]
        raise TypeError(f"{type(problem).__name__} does not implement the Problem protocol; missing: {missing}")
    if not replace and (kind in _registered or kind in BUILTIN):
        raise ValueError(f"scenario kind {kind!r} already has a problem; pass replace=True to replace it")
    _registered[kind] = problem
    return problem


def unregister(kind: str) -> Problem | None:
    """Remove the problem registered for ``kind``; returns it (None if there was none).

    A built-in kind stays available: the next :func:`get` imports it again.
    """
    return _registered.pop(kind, None)


def get(kind: str, *, where: str | None = None) -> Problem:
    """The problem for scenario kind ``kind``; :class:`UnknownKindError` (naming ``where``, e.g. the
    scenario file, and the known kinds) if there is none."""
    problem = _registered.get(kind)
    if problem is not None:
        return problem
    target = BUILTIN.get(kind)
    if target is None:
        raise UnknownKindError(kind, where)
    module, _, attr = target.partition(":")
    problem = getattr(importlib.import_module(module), attr)()
    _registered[kind] = problem
    return problem


def kinds() -> list[str]:
    """Every scenario kind with a problem (registered or built-in), sorted."""
    return sorted(set(_registered) | set(BUILTIN))


def _protocol_members() -> list[str]:
    return [*Problem.__annotations__, *(n for n in vars(Problem) if not n.startswith("_"))]


def importer(name: str):
    """The importer module called ``name`` (:data:`IMPORTERS`); KeyError listing the known ones."""
    if name not in IMPORTERS:
        raise KeyError(f"unknown importer {name!r}; importers: {', '.join(sorted(IMPORTERS))}")
    return importlib.import_module(IMPORTERS[name])


def import_modules(names: tuple[str, ...] | list[str]) -> list[ModuleType]:
    """The modules called ``names``, imported (a problem's ``compiled_modules``, the scheduler's
    preloaded modules): the one place besides :func:`get` and :func:`importer` that imports by name."""
    return [importlib.import_module(n) for n in names]


def schemas() -> list[Schema]:
    """The schema of every input file kind of the built-in problems and importers, in
    :data:`BUILTIN` order: each problem's scenario ``schema`` then its ``file_schemas`` (assets,
    setup files), then each importer's ``file_schemas`` (log metadata).  A schema shared by two
    problems (a vehicle asset) is listed once."""
    out: list[Schema] = []
    sources = [get(kind) for kind in BUILTIN] + [importer(name) for name in IMPORTERS]
    for src in sources:
        own = getattr(src, "schema", None)
        for s in ([own] if isinstance(own, Schema) else []) + list(getattr(src, "file_schemas", ()) or ()):
            if all(s is not o for o in out):
                out.append(s)
    return out


def main(argv: list[str] | None = None) -> int:
    """``python -m workbench.problems.registry --write-formats``: regenerate the generated tables of
    ``workbench/io/FORMATS.md`` from :func:`schemas`."""
    argv = sys.argv[1:] if argv is None else argv
    if argv != ["--write-formats"]:
        print("usage: python -m workbench.problems.registry --write-formats", file=sys.stderr)
        return 2
    import workbench.io.schema as schema_module

    path = Path(schema_module.__file__).with_name("FORMATS.md")
    print(f"{path}: {'updated' if write_formats(path, schemas()) else 'already up to date'}")
    return 0


if __name__ == "__main__":  # the imported module's main: its registry is the one the problems fill
    raise SystemExit(importlib.import_module("workbench.problems.registry").main())
