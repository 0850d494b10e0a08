"""The layer rules of docs/ARCHITECTURE.md, checked on the source tree (static, no imports run).

- imports point up only: core <- io <- models/estimation <- recording <- problems <- cli;
  a problem package never imports another problem package, and the shared modules of
  ``workbench/problems/`` (protocol, registry, runner) import none (the registry names the
  built-in problems by string);
- no import cycles between modules (imports inside functions count: they only hide a cycle);
- no private name (leading underscore) imported from, or reached into, another module,
  in the package or in the tests;
- ``rerun`` is imported only by the recording code;
- no file of the repository points at a path outside it;
- settings in one place (issue 25): no Scenario below a problem's entry point (``Problem.settings``
  builds the frozen settings once; no ``config_for``), TOML parsed only in the schema layer and JSON
  input files through it, no dynamic import outside the registry, no module-level switch or
  written-to module-level container (the documented exceptions listed with their reason).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "workbench"

#: layer -> the layers it may import from (besides itself)
ALLOWED = {
    "core": set(),
    "io": {"core"},
    "models": {"core", "io"},
    "estimation": {"core", "io", "models"},
    "recording": {"core", "io", "models", "estimation"},
    "problems": {"core", "io", "models", "estimation", "recording"},
    "cli": {"core", "io", "models", "estimation", "recording", "problems"},
    "assets": set(),
}


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def _resolve(mod: str, node: ast.ImportFrom, is_pkg: bool) -> str:
    if node.level == 0:
        return node.module or ""
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(mod: str, path: Path, known: dict[str, Path]):
    """Yield (imported workbench module, imported names or None, lineno) for every import."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("workbench"):
                    yield a.name, None, node.lineno
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(mod, node, is_pkg)
            if not target.startswith("workbench"):
                continue
            names = []
            for a in node.names:
                sub = f"{target}.{a.name}"
                if sub in known:  # "from workbench.core import rotation": a module import
                    yield sub, None, node.lineno
                else:
                    names.append(a.name)
            if names:
                yield target, names, node.lineno


def _layer(mod: str) -> str:
    parts = mod.split(".")
    return parts[1] if len(parts) > 1 else "cli"


def _problem(mod: str) -> str | None:
    """The problem package of ``mod`` (``workbench.problems.<p>...``), None outside one.  The
    modules directly in ``workbench/problems/`` (protocol, registry, runner) are shared by all."""
    parts = mod.split(".")
    if len(parts) > 2 and parts[1] == "problems" and (PKG / "problems" / parts[2]).is_dir():
        return parts[2]
    return None


def test_imports_point_up_and_problems_stay_apart():
    known = _modules()
    bad = []
    for mod, path in known.items():
        src = _layer(mod)
        for target, _names, line in _imports(mod, path, known):
            dst = _layer(target)
            if target == "workbench" or dst == src:
                if src == "problems" and _problem(mod) and _problem(target) and _problem(mod) != _problem(target):
                    bad.append(f"{path.relative_to(ROOT)}:{line} imports another problem: {target}")
                if src == "problems" and not _problem(mod) and _problem(target):
                    bad.append(f"{path.relative_to(ROOT)}:{line} shared problem code imports a problem: {target}")
                continue
            if dst not in ALLOWED.get(src, set()):
                bad.append(f"{path.relative_to(ROOT)}:{line} ({src}) imports {target} ({dst})")
    assert not bad, "upward or sideways imports:\n" + "\n".join(bad)


def test_no_import_cycles():
    known = _modules()
    graph = {m: set() for m in known}
    for mod, path in known.items():
        for target, _names, _line in _imports(mod, path, known):
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != mod and not mod.startswith(target + "."):
                graph[mod].add(target)
    # Tarjan's strongly connected components
    index, low, on, stack, sccs, counter = {}, {}, set(), [], [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    assert not sccs, f"import cycles: {sccs}"


def _private_uses(path: Path, mod: str, known: dict[str, Path]) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    out = []
    aliases: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _resolve(mod, node, is_pkg)
            if not target.startswith("workbench"):
                continue
            for a in node.names:
                if f"{target}.{a.name}" in known:
                    aliases[a.asname or a.name] = f"{target}.{a.name}"
                elif a.name.startswith("_") and not a.name.startswith("__") and target != mod:
                    out.append(f"{path.relative_to(ROOT)}:{node.lineno} imports private {target}.{a.name}")
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("workbench") and a.asname:
                    aliases[a.asname] = a.name
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in aliases
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            out.append(f"{path.relative_to(ROOT)}:{node.lineno} reaches into {aliases[node.value.id]}.{node.attr}")
    return out


def test_no_private_names_across_modules():
    known = _modules()
    files = [(m, p) for m, p in known.items()]
    files += [(_module_name(p), p) for p in sorted((ROOT / "tests").rglob("*.py"))]
    bad = [line for m, p in files for line in _private_uses(p, m, known)]
    assert not bad, "private names used across modules:\n" + "\n".join(bad)


def _imported_names(node: ast.AST) -> list[str]:
    """The module names an ``import`` / ``from ... import`` node imports ([] for other nodes)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        return [node.module or ""]
    return []


def test_rerun_only_in_recording_code():
    bad = []
    for mod, path in _modules().items():
        parts = mod.split(".")
        allowed = (len(parts) > 1 and parts[1] == "recording") or (
            len(parts) > 3 and parts[1] == "problems" and parts[3].startswith("recording")
        )
        if allowed:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = _imported_names(node)
            if any(n == "rerun" or n.startswith("rerun.") for n in names):
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not bad, "rerun imported outside recording code: " + ", ".join(bad)


OUTSIDE = ("../shared", "/work/shared", "/work/main", "shared/references", "shared/data", "DESIGN.md")


@pytest.mark.parametrize("folder", ["workbench", "docs", "assets", "tests", "README.md", "pyproject.toml", ".ci"])
def test_no_paths_outside_the_repository(folder):
    root = ROOT / folder
    files = [root] if root.is_file() else [p for p in root.rglob("*") if p.is_file()] if root.exists() else []
    bad = []
    for p in files:
        if p.suffix not in {".py", ".md", ".toml", ".txt", ""} or p == Path(__file__).resolve():
            continue
        try:
            text = p.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for needle in OUTSIDE:
            if needle in text:
                bad.append(f"{p.relative_to(ROOT)}: {needle}")
    assert not bad, "files pointing outside the repository:\n" + "\n".join(bad)


# ------------------------------------------------------------------ settings in one place (issue 25)
#: modules that may see a Scenario: the schema layer, the problems' shared entry (protocol, registry,
#: runner, template, precompile, calibration — which runs shipped scenarios as the runner does), each
#: problem's config.py (``from_scenario``) and problem.py
#: (``settings``), and the command line
SCENARIO_ALLOWED = (
    "workbench.io.scenario",
    "workbench.io.schema",
    "workbench.problems.base",
    "workbench.problems.registry",
    "workbench.problems.runner",
    "workbench.problems.template",
    "workbench.problems.precompile",
    "workbench.problems.scheduler",
    "workbench.problems.calibration",
    "workbench.cli",
)
SCENARIO_METHODS = {"get", "has", "path_of", "with_overrides", "is_synthetic"}


def _scenario_allowed(mod: str) -> bool:
    return mod in SCENARIO_ALLOWED or (_problem(mod) is not None and mod.rsplit(".", 1)[-1] in ("config", "problem"))


def _scenario_uses(path: Path, mod: str) -> list[str]:
    """Where ``path`` imports ``Scenario``, takes a parameter named ``scenario`` or annotated
    ``Scenario``, or reads a scenario (``scenario.get``/``has``/``path_of``/... on a name ``scenario``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = []
    where = path.relative_to(ROOT)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").endswith("io.scenario"):
            if any(a.name in ("Scenario", "load_scenario", "resolve_scenario") for a in node.names):
                out.append(f"{where}:{node.lineno} imports {', '.join(a.name for a in node.names)}")
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
            for a in args:
                ann = ast.unparse(a.annotation) if a.annotation is not None else ""
                if a.arg == "scenario" or "Scenario" in ann.replace("ScenarioError", ""):
                    out.append(f"{where}:{node.lineno} {node.name}({a.arg}: {ann or '?'}) takes a scenario")
        elif (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in ("scenario", "sc")
            and node.attr in SCENARIO_METHODS
        ):
            out.append(f"{where}:{node.lineno} reads scenario.{node.attr}")
        elif isinstance(node, ast.Name) and node.id == "config_for":
            out.append(f"{where}:{node.lineno} uses config_for (settings are built once, by Problem.settings)")
    return out


def test_no_scenario_below_a_problems_entry_point():
    """A run's settings are built once (``Problem.settings``); below the problem object no function
    receives a Scenario, reads one, or re-derives settings (``config_for``)."""
    bad = []
    for mod, path in _modules().items():
        if not _scenario_allowed(mod):
            bad += _scenario_uses(path, mod)
        else:
            bad += [u for u in _scenario_uses(path, mod) if "config_for" in u]
    assert not bad, "a scenario below a problem's entry point:\n" + "\n".join(bad)


#: the schema layer: the only modules that parse an input file's TOML
SCHEMA_LAYER = ("workbench.io.scenario", "workbench.io.schema")


def test_input_files_are_parsed_only_in_the_schema_layer():
    """``tomllib`` is imported only by io/scenario.py and io/schema.py; no problem package or model
    parses JSON itself (``io.schema.read_json`` / ``load_file``): every input file has a schema."""
    bad = []
    for mod, path in _modules().items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = _imported_names(node)
            if "tomllib" in names and mod not in SCHEMA_LAYER:
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno} imports tomllib")
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id == "json"
                and node.attr in ("load", "loads")
                and (_problem(mod) is not None or _layer(mod) == "models")
            ):
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno} parses JSON itself (use io.schema.read_json)")
    assert not bad, "input files parsed outside the schema layer:\n" + "\n".join(bad)


def test_dynamic_imports_only_in_the_registry():
    """``importlib.import_module`` / ``__import__`` only in problems/registry.py, where the built-in
    problems, importers and preloaded modules are named (an import by name is invisible to the
    layer and cycle checks above)."""
    bad = []
    for mod, path in _modules().items():
        if mod == "workbench.problems.registry":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                f = node.func
                name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
                if name in ("import_module", "__import__"):
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno} {name}(...)")
    assert not bad, "dynamic imports outside the registry:\n" + "\n".join(bad)


_MUTATORS = {
    "append",
    "extend",
    "insert",
    "update",
    "setdefault",
    "pop",
    "popitem",
    "clear",
    "add",
    "discard",
    "remove",
}
_CONTAINERS = {"dict", "list", "set", "defaultdict", "OrderedDict", "WeakKeyDictionary", "WeakValueDictionary", "deque"}

#: module-level state that is there by design, each with its reason
MUTABLE_GLOBALS_ALLOWED = {
    # the registry of problems a user or a test adds (register/unregister): the one registry
    ("workbench.problems.registry", "_registered"),
    # a process-pool worker's shared input, set once by the pool's initializer in that process
    ("workbench.estimation.montecarlo", "_WORKER_SHARED"),
    # a memo of the deterministic drop-test truth simulation (the same results with or without it;
    # bounded to 8 drops): the tests and Monte Carlo members of one process fly the same drops
    ("workbench.problems.droptest.synthetic", "_TRUTH_CACHE"),
    # the same for the entry truth (4 trajectories)
    ("workbench.problems.entry.synthetic", "_TRUTH_CACHE"),
}


def _module_state(path: Path, mod: str) -> list[str]:
    """Module-level switches (a name bound to True/False) and module-level containers that code
    mutates (subscript store, a mutating method, ``global``) in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    where = path.relative_to(ROOT)
    containers, out = {}, []
    for node in tree.body:
        if not isinstance(node, ast.Assign | ast.AnnAssign) or node.value is None:
            continue
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        for t in targets:
            if not isinstance(t, ast.Name) or t.id == "__all__" or (mod, t.id) in MUTABLE_GLOBALS_ALLOWED:
                continue
            v = node.value
            if isinstance(v, ast.Constant) and isinstance(v.value, bool):
                out.append(f"{where}:{node.lineno} module-level switch {t.id} = {v.value} (a setting or an env var)")
            is_container = isinstance(v, ast.Dict | ast.List | ast.Set | ast.DictComp | ast.ListComp | ast.SetComp)
            if isinstance(v, ast.Call):
                f = v.func
                is_container = (f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")) in _CONTAINERS
            if is_container:
                containers[t.id] = node.lineno
    for node in ast.walk(tree):
        if isinstance(node, ast.Global):
            out += [f"{where}:{node.lineno} global {n}" for n in node.names if (mod, n) not in MUTABLE_GLOBALS_ALLOWED]
        target = None
        if isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Store | ast.Del):
            target = node.value
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _MUTATORS:
            target = node.func.value
        if isinstance(target, ast.Name) and target.id in containers:
            out.append(f"{where}:{node.lineno} mutates the module-level {target.id} (line {containers[target.id]})")
    return out


def test_no_module_level_mutable_state():
    """No module-level switches or caches (docs/ARCHITECTURE.md: no globals, no singletons): a
    switch is a setting, a keyword argument or one documented environment variable; constant
    lookup tables are fine as long as nothing writes into them."""
    bad = [line for mod, path in _modules().items() for line in _module_state(path, mod)]
    assert not bad, "module-level mutable state:\n" + "\n".join(bad)
