"""Render the README's measured numbers and ``docs/RESULTS.md`` from committed JSON outputs.

Every number the README or ``docs/RESULTS.md`` states about accuracy, consistency or speed comes
from a JSON file under ``docs/results/``, written by the code that measured it:

* ``docs/results/<benchmark>.json`` — a benchmark's ``--json`` output (``tests/benchmarks/``);
* ``docs/results/summaries/<scenario>.summary.json`` — the summaries of ``workbench run all``;
* ``docs/results/commands.json`` — wall times of the README's two commands from a fresh clone
  (``tests/benchmarks/time_readme_commands.py``).

The texts to fill are the templates in this file. A placeholder ``{{source:key.path|format}}``
reads ``key.path`` (dot-separated dict keys; integers index lists) from ``docs/results/<source>.json``
and formats it; ``format`` is a Python format spec, optionally preceded by a scale ``*100`` (so
``*100:.1f`` writes a fraction as a percentage), or ``mmss`` (seconds as ``2 min 52 s``).
A missing file or key is an error that names both: a table can never silently lose a number.

Usage (from the repository root)::

    .venv/bin/python tests/benchmarks/make_results.py --write   # rewrite README blocks + docs/RESULTS.md
    .venv/bin/python tests/benchmarks/make_results.py --check   # exit 1 if they differ from a fresh render

The README holds generated blocks between ``<!-- generated:NAME -->`` and
``<!-- /generated:NAME -->``; text outside them is hand-written. ``tests/test_results_docs.py``
fails when the committed README/RESULTS.md differ from a render of the committed JSON files, and
(slow tier) when a fresh ``workbench run droptest`` disagrees with the committed summary.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RESULTS_DIR = ROOT / "docs" / "results"

_PLACEHOLDER = re.compile(r"\{\{([A-Za-z0-9_./-]+):([^|}]+)(?:\|([^}]*))?\}\}")
_BLOCK = re.compile(r"(<!-- generated:([a-z0-9_-]+) -->\n)(.*?)(<!-- /generated:\2 -->)", re.DOTALL)


class ResultsError(LookupError):
    """A placeholder names a results file or key that does not exist (message names both)."""


def _load(results_dir: Path, source: str, cache: dict) -> object:
    if source not in cache:
        path = results_dir / f"{source}.json"
        if not path.is_file():
            raise ResultsError(f"results file {path} (placeholder source '{source}') does not exist")
        cache[source] = json.loads(path.read_text())
    return cache[source]


def lookup(doc: object, key: str, *, source: str = "?") -> object:
    """Return ``doc[k1][k2]...`` for ``key = "k1.k2..."``; integer parts index lists; a dict key that
    itself contains dots (e.g. ``"0.5%"``) is matched greedily."""
    cur = doc
    parts = key.split(".")
    while parts:
        part = parts.pop(0)
        if isinstance(cur, dict) and part not in cur:
            for n in range(1, len(parts) + 1):  # the shortest join that is a key
                joined = ".".join([part, *parts[:n]])
                if joined in cur:
                    part, parts = joined, parts[n:]
                    break
        if isinstance(cur, list) and re.fullmatch(r"-?\d+", part):
            idx = int(part)
            if not -len(cur) <= idx < len(cur):
                raise ResultsError(f"{source}.json: index {part} out of range in '{key}'")
            cur = cur[idx]
        elif isinstance(cur, dict) and part in cur:
            cur = cur[part]
        else:
            raise ResultsError(f"{source}.json has no key '{key}' (missing part '{part}')")
    return cur


def format_value(value: object, fmt: str | None) -> str:
    """Format one JSON value: ``None`` → "n/a"; ``*S:spec`` scales by S first; ``mmss`` for seconds;
    ``pass`` writes a boolean as PASS/FAIL; ``min:spec`` / ``max:spec`` the smallest / largest finite
    number of a list."""
    if value is None:
        return "n/a"
    if not fmt:
        return str(value)
    if fmt == "pass":
        return "PASS" if value else "FAIL"
    m = re.fullmatch(r"(min|max):(.*)", fmt)
    if m:  # the smallest / largest finite number of a list
        vals = [float(v) for v in value if v is not None and math.isfinite(float(v))]
        if not vals:
            return "n/a"
        return format(min(vals) if m.group(1) == "min" else max(vals), m.group(2))
    if fmt == "mmss":
        s = round(float(value))
        return f"{s // 60} min {s % 60} s" if s >= 60 else f"{s} s"
    scale = 1.0
    m = re.fullmatch(r"\*([0-9.eE+-]+):(.*)", fmt)
    if m:
        scale, fmt = float(m.group(1)), m.group(2)
    if isinstance(value, bool) or not isinstance(value, int | float) or (isinstance(value, int) and scale == 1.0):
        return format(value, fmt)
    return format(float(value) * scale, fmt)


def fill(template: str, results_dir: Path = RESULTS_DIR, cache: dict | None = None) -> str:
    """Replace every ``{{source:key|fmt}}`` in ``template`` by the formatted value.  A callable
    ``template`` is first called with ``results_dir`` (a table built by a benchmark script's own
    renderer from the same JSON files, e.g. ``bench_speed.markdown``)."""
    cache = {} if cache is None else cache
    if callable(template):
        template = template(results_dir)

    def sub(m: re.Match) -> str:
        source, key, fmt = m.group(1), m.group(2), m.group(3)
        return format_value(lookup(_load(results_dir, source, cache), key, source=source), fmt)

    return _PLACEHOLDER.sub(sub, template)


def render_readme(readme: str, blocks: dict[str, str], results_dir: Path = RESULTS_DIR) -> str:
    """Return ``readme`` with every generated block replaced by its filled template.

    A block in the README without a template, or a template without a block, is an error.
    """
    cache: dict = {}
    seen: set[str] = set()

    def sub(m: re.Match) -> str:
        name = m.group(2)
        if name not in blocks:
            raise ResultsError(f"README block '{name}' has no template in make_results.py")
        seen.add(name)
        return m.group(1) + fill(blocks[name], results_dir, cache).rstrip("\n") + "\n" + m.group(4)

    out = _BLOCK.sub(sub, readme)
    missing = set(blocks) - seen
    if missing:
        raise ResultsError(f"README lacks the generated block(s) {sorted(missing)}")
    return out


def render_all(root: Path = ROOT) -> dict[Path, str]:
    """Return {path: text} for README.md and docs/RESULTS.md rendered from ``root/docs/results``."""
    from results_templates import README_BLOCKS, RESULTS_MD, RESULTS_MD_SECTIONS  # noqa: PLC0415 (beside this file)

    results_dir = root / "docs" / "results"
    readme = (root / "README.md").read_text()
    cache: dict = {}
    results_md = fill(RESULTS_MD, results_dir, cache)
    for section in RESULTS_MD_SECTIONS:  # sections built by a benchmark's own renderer, appended
        results_md = results_md.rstrip("\n") + "\n\n" + fill(section, results_dir, cache)
    return {
        root / "README.md": render_readme(readme, README_BLOCKS, results_dir),
        root / "docs" / "RESULTS.md": results_md,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", action="store_true", help="rewrite README.md blocks and docs/RESULTS.md")
    g.add_argument("--check", action="store_true", help="exit 1 if the committed files differ from a render")
    args = ap.parse_args(argv)
    rendered = render_all()
    stale = [p for p, text in rendered.items() if not p.is_file() or p.read_text() != text]
    if args.write:
        for p in stale:
            p.write_text(rendered[p])
            print(f"wrote {p.relative_to(ROOT)}")
        return 0
    for p in stale:
        print(f"{p.relative_to(ROOT)} differs from a render of docs/results/*.json; run make_results.py --write")
    return 1 if stale else 0


sys.path.insert(0, str(Path(__file__).resolve().parent))

if __name__ == "__main__":
    raise SystemExit(main())
