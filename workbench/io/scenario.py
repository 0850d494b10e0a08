"""Scenario files (TOML): what to reconstruct, from which telemetry, with which settings.

A scenario is one TOML file with a ``[scenario]`` table (``name``, ``kind``, optional
``description`` and ``epoch_utc``) and the tables of that kind: ``[vehicle]``, ``[sensors.*]``,
``[telemetry]`` (logical stream name → file path relative to the scenario file), ``[synthetic]``
(truth-simulator settings and ``seed``; its presence makes the scenario synthetic), ``[filter]``,
...  Which tables and keys a kind has is declared once in its schema
(``problems/<kind>/config.py``, :mod:`workbench.io.schema`); the problem validates the scenario
against it before it runs (unknown keys are errors).  FORMATS.md describes it for users.

Keys are addressed by dotted paths (``"sensors.imu.rate_hz"``) and type-checked on access by
:meth:`Scenario.get`; every error names the file and the dotted key.  Values are whatever the
file says: unit conventions are the scenario author's, and key names carry their unit
(``height_m``, ``tilt_deg``) so the pipeline converts at the edge.
"""

from __future__ import annotations

import copy
import datetime as _dt
import os
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "RunInfo",
    "Scenario",
    "ScenarioError",
    "check_value",
    "find_scenarios",
    "load_scenario",
    "parse_file",
    "read_toml",
    "resolve_scenario",
]

_VALUE_KINDS = ("float", "int", "str", "bool", "vec3", "list", "table")


class _Missing:
    def __repr__(self) -> str:
        return "<missing>"


_MISSING: Any = _Missing()


class ScenarioError(ValueError):
    """A problem in a scenario file.  Attributes ``file`` (str) and ``key`` (dotted, or None)."""

    def __init__(self, file, key: str | None, reason: str):
        self.file = str(file)
        self.key = key
        self.reason = reason
        where = f"{self.file}, key '{key}'" if key else self.file
        super().__init__(f"{where}: {reason}")

    def __reduce__(self):
        return (type(self), (self.file, self.key, self.reason))


def _type_name(v: Any) -> str:
    if isinstance(v, bool):
        return "bool"
    if isinstance(v, dict):
        return "table"
    if isinstance(v, list):
        return f"list of {len(v)}"
    if isinstance(v, str):
        return "str"
    return type(v).__name__


@dataclass(frozen=True, eq=False)
class Scenario:
    """A loaded scenario.  ``data`` is the whole parsed TOML document (including ``[scenario]``).

    Treat ``data`` as read-only: use :meth:`with_overrides` to derive a changed scenario.
    """

    path: Path
    name: str
    kind: str
    description: str
    data: dict

    # -- access ------------------------------------------------------------------------------

    def _lookup(self, dotted_key: str) -> Any:
        node: Any = self.data
        for part in dotted_key.split("."):
            if not isinstance(node, dict) or part not in node:
                return _MISSING
            node = node[part]
        return node

    def has(self, dotted_key: str) -> bool:
        """True if ``dotted_key`` (e.g. ``"synthetic.seed"``) is present."""
        return self._lookup(dotted_key) is not _MISSING

    def get(self, dotted_key: str, default: Any = _MISSING, *, kind: str | None = None) -> Any:
        """Value at ``dotted_key``, type-checked when ``kind`` is given.

        ``kind``: ``"float"`` (int accepted, returned as float), ``"int"``, ``"str"``, ``"bool"``,
        ``"vec3"`` (list of 3 numbers → float array ``(3,)``), ``"list"``, ``"table"`` (dict).
        A missing key returns ``default`` if given, else raises :class:`ScenarioError`; a present
        key of the wrong type always raises.  Lists and tables are returned as copies.
        """
        if kind is not None and kind not in _VALUE_KINDS:
            raise ValueError(f"kind must be one of {', '.join(_VALUE_KINDS)}, got {kind!r}")
        v = self._lookup(dotted_key)
        if v is _MISSING:
            if default is not _MISSING:
                return default
            parent, _, _ = dotted_key.rpartition(".")
            known = self._lookup(parent) if parent else self.data
            hint = f"; keys here: {', '.join(known)}" if isinstance(known, dict) and known else ""
            raise ScenarioError(self.path, dotted_key, f"missing{' ' + kind if kind else ''} value{hint}")
        if kind is None:
            return copy.deepcopy(v) if isinstance(v, dict | list) else v
        return check_value(self.path, dotted_key, v, kind)

    def path_of(self, dotted_key: str, *, must_exist: bool = True) -> Path:
        """The path string at ``dotted_key`` resolved against the scenario's directory.

        Raises :class:`ScenarioError` naming the key if it is missing, not a string, or (with
        ``must_exist``) points at nothing.
        """
        p = self.resolve(self.get(dotted_key, kind="str"))
        if must_exist and not p.exists():
            raise ScenarioError(self.path, dotted_key, f"file not found: {p}")
        return p

    def resolve(self, rel_path: str | os.PathLike) -> Path:
        """``rel_path`` relative to the directory of the scenario file (absolute paths pass)."""
        p = Path(rel_path).expanduser()
        return p if p.is_absolute() else (self.path.parent / p)

    @property
    def is_synthetic(self) -> bool:
        """True if the scenario has a ``[synthetic]`` table (telemetry is simulated)."""
        return isinstance(self.data.get("synthetic"), dict)

    def with_overrides(self, dotted: dict[str, Any]) -> Scenario:
        """A new scenario with ``{dotted_key: value}`` set (tables created as needed).

        The result is validated like a loaded file; setting a key under a non-table value
        raises :class:`ScenarioError`.
        """
        data = copy.deepcopy(self.data)
        for key, value in dotted.items():
            parts = key.split(".")
            if not all(parts):
                raise ScenarioError(self.path, key, "override key has an empty part")
            node = data
            for i, part in enumerate(parts[:-1]):
                nxt = node.setdefault(part, {})
                if not isinstance(nxt, dict):
                    raise ScenarioError(
                        self.path,
                        ".".join(parts[: i + 1]),
                        f"is a {_type_name(nxt)}, cannot set '{key}' under it",
                    )
                node = nxt
            node[parts[-1]] = value
        return _from_data(self.path, data)


@dataclass(frozen=True)
class RunInfo:
    """What every run's settings carry about its scenario file, read once by the problem's
    ``settings(scenario)``: ``path`` of the file, ``name``, ``kind``, ``description``, ``synthetic``
    (a ``[synthetic]`` table is present), ``seed`` (``[synthetic] seed``, 0 when absent) and
    ``epoch_utc`` (ISO string or None).  Code below a problem's entry point resolves the file's
    relative paths with :meth:`resolve` and never sees the :class:`Scenario`."""

    path: Path
    name: str
    kind: str
    description: str = ""
    synthetic: bool = False
    seed: int = 0
    epoch_utc: str | None = None

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> RunInfo:
        """The run information of a loaded (already validated) ``scenario``."""
        return cls(
            path=scenario.path,
            name=scenario.name,
            kind=scenario.kind,
            description=scenario.description,
            synthetic=scenario.is_synthetic,
            seed=int(scenario.data.get("synthetic", {}).get("seed", 0)),
            epoch_utc=scenario.data["scenario"].get("epoch_utc"),
        )

    def resolve(self, rel_path: str | os.PathLike) -> Path:
        """``rel_path`` relative to the directory of the scenario file (absolute paths pass), made
        absolute and normalised (``a/scenarios/../landers/x.toml`` -> ``a/landers/x.toml``; links
        are not followed), so a message names the file as the user finds it."""
        p = Path(rel_path).expanduser()
        return Path(os.path.normpath(os.path.abspath(p if p.is_absolute() else (self.path.parent / p))))


def check_value(path: Path, key: str, v: Any, kind: str) -> Any:
    """``v`` checked against ``kind`` (see :meth:`Scenario.get`); :class:`ScenarioError` naming
    ``path`` and the dotted ``key`` otherwise.  Numbers come back as float for ``"float"``, a
    ``"vec3"`` as a float array ``(3,)``, lists and tables as copies."""

    def fail(expected: str) -> ScenarioError:
        return ScenarioError(path, key, f"expected {expected}, got {_type_name(v)} {v!r}"[:300])

    number = isinstance(v, int | float) and not isinstance(v, bool)
    if kind == "float":
        if not number:
            raise fail("a number")
        return float(v)
    if kind == "int":
        if not isinstance(v, int) or isinstance(v, bool):
            raise fail("an integer")
        return v
    if kind == "str":
        if not isinstance(v, str):
            raise fail("a string")
        return v
    if kind == "bool":
        if not isinstance(v, bool):
            raise fail("true or false")
        return v
    if kind == "vec3":
        if not (
            isinstance(v, list)
            and len(v) == 3
            and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        ):
            raise fail("a list of 3 numbers")
        return np.array(v, dtype=np.float64)
    if kind == "list":
        if not isinstance(v, list):
            raise fail("a list")
        return copy.deepcopy(v)
    if not isinstance(v, dict):
        raise fail("a table")
    return copy.deepcopy(v)


def _from_data(path: Path, data: dict) -> Scenario:
    sc = data.get("scenario", _MISSING)
    if sc is _MISSING:
        raise ScenarioError(path, "scenario", "missing [scenario] table (with name and kind)")
    if not isinstance(sc, dict):
        raise ScenarioError(path, "scenario", f"expected a table, got {_type_name(sc)}")
    name = sc.get("name")
    if not isinstance(name, str) or not name.strip():
        raise ScenarioError(path, "scenario.name", f"expected a non-empty string, got {name!r}")
    kind = sc.get("kind")  # which problem handles it is the registry's business (workbench.problems)
    if not isinstance(kind, str) or not kind.strip():
        raise ScenarioError(path, "scenario.kind", f"expected a non-empty string (the problem kind), got {kind!r}")
    desc = sc.get("description", "")
    if not isinstance(desc, str):
        raise ScenarioError(path, "scenario.description", f"expected a string, got {_type_name(desc)}")
    epoch = sc.get("epoch_utc")
    if isinstance(epoch, _dt.datetime | _dt.date):
        sc["epoch_utc"] = epoch.isoformat()
    elif epoch is not None and not isinstance(epoch, str):
        raise ScenarioError(path, "scenario.epoch_utc", f"expected a UTC date-time, got {_type_name(epoch)}")
    for table in ("telemetry", "synthetic"):
        if table in data and not isinstance(data[table], dict):
            raise ScenarioError(path, table, f"expected a table, got {_type_name(data[table])}")
    for stream, rel in data.get("telemetry", {}).items():
        if not isinstance(rel, str):
            raise ScenarioError(path, f"telemetry.{stream}", f"expected a CSV path string, got {_type_name(rel)}")
    seed = data.get("synthetic", {}).get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise ScenarioError(path, "synthetic.seed", f"expected a non-negative integer, got {seed!r}")
    return Scenario(path=path, name=name.strip(), kind=kind.strip(), description=desc.strip(), data=data)


def read_toml(path: str | os.PathLike) -> dict:
    """The parsed TOML document at ``path``; :class:`ScenarioError` naming the file (and the line,
    as :mod:`tomllib` reports it) when it is missing, unreadable, not UTF-8 or not valid TOML.
    With :func:`workbench.io.schema.read_json`, the one place an input file's text is parsed."""
    return parse_file(path, _load_toml, tomllib.TOMLDecodeError, lambda exc: f"not valid TOML: {exc}")


def _load_toml(path: Path) -> dict:
    with path.open("rb") as f:
        return tomllib.load(f)


def parse_file(
    path: str | os.PathLike, load: Callable[[Path], Any], syntax_error: type[Exception], describe: Callable[[Any], str]
) -> Any:
    """``load(path)`` (the parsed document of one input file), every failure a :class:`ScenarioError`
    naming the file: "file not found", ``describe(exc)`` for the format's ``syntax_error`` (e.g. line
    and column), not UTF-8, or any other read error.  Shared by :func:`read_toml` and
    :func:`workbench.io.schema.read_json` so both report a bad file the same way."""
    path = Path(path)
    try:
        return load(path)
    except FileNotFoundError:
        raise ScenarioError(path, None, "file not found") from None
    except syntax_error as exc:
        raise ScenarioError(path, None, describe(exc)) from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(path, None, f"not valid UTF-8: {exc}") from None
    except OSError as exc:
        raise ScenarioError(path, None, f"cannot read file: {exc.strerror or exc}") from None


def load_scenario(path: str | os.PathLike) -> Scenario:
    """Load and validate a scenario TOML file; :class:`ScenarioError` names file and key/line."""
    path = Path(path)
    return _from_data(path, read_toml(path))


def find_scenarios(assets_dir: str | os.PathLike) -> dict[str, Path]:
    """Shipped scenarios: ``{name: path}`` for every ``*.toml`` under ``assets_dir/scenarios/``
    (recursively) that has a ``[scenario]`` table; sorted by name.

    TOML files without a ``[scenario]`` table are skipped; an invalid TOML file or two files
    with the same scenario name raise :class:`ScenarioError`.
    """
    root = Path(assets_dir) / "scenarios"
    found: dict[str, Path] = {}
    if not root.is_dir():
        return found
    for p in sorted(root.rglob("*.toml")):
        data = read_toml(p)
        if "scenario" not in data:
            continue
        sc = _from_data(p, data)
        if sc.name in found:
            raise ScenarioError(p, "scenario.name", f"name {sc.name!r} is also used by {found[sc.name]}")
        found[sc.name] = p
    return dict(sorted(found.items()))


def resolve_scenario(name_or_path: str | os.PathLike, assets_dir: str | os.PathLike) -> Scenario:
    """Load a scenario given a path to a ``.toml`` file or the name of a shipped scenario.

    A shipped scenario matches by its ``[scenario] name`` or its file stem.  An unknown name
    raises :class:`ScenarioError` listing the shipped names.
    """
    s = str(name_or_path)
    p = Path(s)
    if s.endswith(".toml") or p.is_file():
        return load_scenario(p)
    shipped = find_scenarios(assets_dir)
    if s in shipped:
        return load_scenario(shipped[s])
    by_stem = {q.stem: q for q in shipped.values()}
    if s in by_stem:
        return load_scenario(by_stem[s])
    names = ", ".join(shipped) or "(none found)"
    raise ScenarioError(Path(assets_dir) / "scenarios", None, f"no scenario named {s!r}; shipped scenarios: {names}")
