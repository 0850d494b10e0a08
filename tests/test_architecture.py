"""The layer rules of docs/ARCHITECTURE.md, checked on the source tree (static, no imports run).

- imports point up only: core <- io <- models/estimation <- recording <- problems <- cli;
  a problem package never imports another problem package, and the shared modules of
  ``workbench/problems/`` (protocol, registry, runner) import none (the registry names the
  built-in problems by string);
- no import cycles between modules (imports inside functions count: they only hide a cycle);
- no private name (leading underscore) imported from, or reached into, another module,
  in the package or in the tests;
- ``rerun`` is imported only by the recording code;
- no file of the repository points at a path outside it.
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
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
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
