"""Compare the ``<name>.summary.json`` files of two output folders, number by number.

Used to show that a refactor changes no result: run ``workbench run all --out A`` on the old
commit and ``--out B`` on the new one, then::

    .venv/bin/python tests/benchmarks/compare_summaries.py A B [name ...] [--rtol 1e-9]

Every number must agree within ``rtol`` relative (NaN equals NaN); strings, lists and keys must be
equal, except that each run's own output folder inside a string is ignored (the folder of the
summary's ``recording``, so a summary copied to another folder compares as well). Keys that are timings,
sizes or output paths (``wall``, ``seconds``, ``bytes``, ``recording``, ``path``...) are skipped.
Prints one line per scenario and the differences; exit code 1 if any scenario differs.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

SKIP = (
    "wall",
    "second",
    "bytes",
    "recording",
    "path",
    "_dir",
    "elapsed",
    "time_s",
    "times_s",
    "duration_s",
    "workers",
    "rss",
)


def differences(a, b, where: str, base: str, new: str, rtol: float, out: list[str]) -> None:
    """Append to ``out`` every difference between the JSON values ``a`` (old) and ``b`` (new)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if any(s in k.lower() for s in SKIP):
                continue
            if k not in a or k not in b:
                out.append(f"{where}/{k}: only in {'new' if k in b else 'old'}")
            else:
                differences(a[k], b[k], f"{where}/{k}", base, new, rtol, out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{where}: length {len(a)} -> {len(b)}")
            return
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            differences(x, y, f"{where}[{i}]", base, new, rtol, out)
    elif isinstance(a, int | float) and isinstance(b, int | float) and not isinstance(a, bool):
        if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
            return
        if a != b and abs(a - b) > rtol * max(abs(a), abs(b)):
            out.append(f"{where}: {a!r} -> {b!r}")
    elif isinstance(a, str) and isinstance(b, str):
        if a.replace(base, "<OUT>") != b.replace(new, "<OUT>"):
            out.append(f"{where}: {a!r} -> {b!r}")
    elif a != b:
        out.append(f"{where}: {a!r} -> {b!r}")


def relative_differences(a, b, where: str = "") -> list[tuple[float, str, float, float]]:
    """Every number two JSON values share, as ``(relative difference, key path, old, new)``, largest
    first: ``|a − b| / max(|a|, |b|)`` (0 for two zeros or two NaNs, inf for a NaN against a number).
    The keys :func:`differences` skips (timings, sizes, paths) are skipped here too; strings, and
    keys or lists present on one side only, are left to :func:`differences`."""
    out: list[tuple[float, str, float, float]] = []

    def walk(x, y, at: str) -> None:
        if isinstance(x, dict) and isinstance(y, dict):
            for k in sorted(set(x) & set(y)):
                if not any(s in k.lower() for s in SKIP):
                    walk(x[k], y[k], f"{at}/{k}")
        elif isinstance(x, list) and isinstance(y, list) and len(x) == len(y):
            for i, (u, v) in enumerate(zip(x, y, strict=True)):
                walk(u, v, f"{at}[{i}]")
        elif isinstance(x, int | float) and isinstance(y, int | float) and not isinstance(x, bool):
            if math.isnan(x) or math.isnan(y):
                rel = 0.0 if math.isnan(x) and math.isnan(y) else math.inf
            else:
                scale = max(abs(x), abs(y))
                rel = abs(x - y) / scale if scale else 0.0
            out.append((rel, at, x, y))

    walk(a, b, where)
    out.sort(key=lambda r: -r[0])
    return out


def _written_in(summary: dict, folder: Path) -> str:
    """The output folder a summary was written in (the folder of its ``recording``; a summary copied
    elsewhere keeps the paths of where it was made), else ``folder``."""
    rec = summary.get("recording")
    return str(Path(rec).parent) if isinstance(rec, str) and rec else str(folder)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("names", nargs="*")
    ap.add_argument("--rtol", type=float, default=1e-9)
    args = ap.parse_args(argv)
    names = args.names or sorted(p.name[: -len(".summary.json")] for p in args.old.glob("*.summary.json"))
    bad = 0
    for name in names:
        p_old, p_new = args.old / f"{name}.summary.json", args.new / f"{name}.summary.json"
        if not p_new.exists() or not p_old.exists():
            print(f"{name}: MISSING {p_old if not p_old.exists() else p_new}")
            bad += 1
            continue
        diffs: list[str] = []
        a, b = json.loads(p_old.read_text()), json.loads(p_new.read_text())
        differences(a, b, "", _written_in(a, args.old), _written_in(b, args.new), args.rtol, diffs)
        print(f"{name}: {'identical' if not diffs else f'{len(diffs)} differences'}")
        for d in diffs[:30]:
            print("   ", d)
        bad += bool(diffs)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
