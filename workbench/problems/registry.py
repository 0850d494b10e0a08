"""Which :class:`~workbench.problems.base.Problem` handles a scenario ``kind``.

The built-in problems (``droptest``, ``entry``) are imported the first time they are asked for,
so ``import workbench.problems`` stays light.  Other problems (a user's, a test's) are added with
:func:`register` and removed with :func:`unregister`.
"""

from __future__ import annotations

import importlib

from workbench.problems.base import Problem

__all__ = ["IMPORTERS", "UnknownKindError", "get", "importer", "kinds", "register", "unregister"]

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
