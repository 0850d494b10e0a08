"""Every declared 1σ a user can get wrong: each noise or 1σ key that a shipped scenario sets to a
number other than 0 (a key named with "sigma" or "noise", or one whose schema meaning or table says
1σ, e.g. the entry ``[reconstruction]`` table) set to 0 and to minus its value, one edit at a time,
each run by ``workbench run`` in its own process, as a user would.

A 1σ of 0 declares a perfect measurement or model; a negative one is a typo. The outcome of every
edit is one of: ``input error`` (exit 3, the message names the file and key), ``numerical failure``
(exit 4), ``unhealthy`` (exit 6: the verdict refused to write), ``ran`` (exit 0, with its health
verdict) or ``traceback`` (an exception nobody caught). ``--root`` runs another checkout's
``workbench`` (its folder first on ``PYTHONPATH``) on the same edits: the before of a change.

    python tests/benchmarks/bench_declared_sigmas.py [--jobs 2] [--scenarios droptest,schiaparelli]
        [--keys rate_dps,...] [--root OTHER_CHECKOUT] [--out docs/results/bench_declared_sigmas.json]
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

#: a scenario line setting a key to a number: (indent, key, " = ", number, rest of the line)
_LINE = re.compile(r"^(\s*)([A-Za-z_0-9]+)(\s*=\s*)([-+0-9.eE]+)(.*)$")
#: a key named as a noise or 1σ
_NAMED = re.compile(r"sigma|noise")
#: a TOML table header ``[name]`` or ``[dotted.name]`` (not a line of a multi-line array)
_HEADER = re.compile(r"^\s*\[\s*([A-Za-z_][A-Za-z0-9_.\-]*)\s*\]\s*(?:#.*)?$")
#: a meaning that says 1σ, in either spelling
_SAYS = re.compile(r"1σ|1-sigma")
#: the scenario kind line
_KIND = re.compile(r'^\s*kind\s*=\s*"([^"]+)"')


def declared_1sigma() -> dict[str, set[tuple[str, str]]]:
    """{scenario kind: {(table, key)}}: the keys of each scenario schema (this checkout's) whose
    meaning or table says they are a 1σ, whatever their name."""
    from workbench.problems import registry

    out: dict[str, set[tuple[str, str]]] = {}
    for sch in registry.schemas():
        for t in sch.tables:
            for k in t.keys:
                if _SAYS.search(k.meaning) or _SAYS.search(t.meaning):
                    out.setdefault(sch.name, set()).add((t.name, k.name))
    return out


#: every outcome :func:`classify` gives (others are ``exit N``), each counted even when 0
OUTCOMES = ("input error", "numerical failure", "unhealthy", "ran", "traceback")


def edits(scenarios: Path, names: list[str] | None) -> list[dict]:
    """Every (scenario, line, key, value) edit of the scenario TOMLs in ``scenarios``: 0 and the
    negated value of each noise/1σ line (:data:`_NAMED`, :func:`declared_1sigma`) whose number is not 0."""
    out = []
    declared = declared_1sigma()
    for path in sorted(scenarios.glob("*.toml")):
        if names and path.stem not in names:
            continue
        table, kind = "", ""
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines()):
            if h := _HEADER.match(line):
                table = h.group(1).strip()
                continue
            if table == "scenario" and (k := _KIND.match(line)):
                kind = k.group(1)
            m = _LINE.match(line)
            if not m or not (_NAMED.search(m.group(2)) or (table, m.group(2)) in declared.get(kind, set())):
                continue
            try:
                x = float(m.group(4))
            except ValueError:
                continue
            if x == 0.0:
                continue
            for tag, value in (("zero", "0.0"), ("negative", "-" + m.group(4).lstrip("+-"))):
                out.append(
                    {
                        "scenario": path.stem,
                        "line": i + 1,
                        "table": table,
                        "key": m.group(2),
                        "tag": tag,
                        "value": value,
                    }
                )
    return out


def _dotted(e: dict) -> str:
    """The edited key as an error names it: ``table.key`` (``key`` at the top level)."""
    return f"{e['table']}.{e['key']}" if e["table"] else e["key"]


def classify(rc: int, stderr: str) -> str:
    """The outcome of one run from its exit code and standard error."""
    if "Traceback (most recent call last)" in stderr or rc == 1:
        return "traceback"
    return {0: "ran", 3: "input error", 4: "numerical failure", 6: "unhealthy"}.get(rc, f"exit {rc}")


def run_one(e: dict, assets: Path, out: Path, env: dict, root: Path) -> dict:
    """Write the edited scenario beside the shipped ones (its relative paths resolve as theirs) and run it."""
    src = assets / "scenarios" / f"{e['scenario']}.toml"
    lines = src.read_text(encoding="utf-8").splitlines()
    m = _LINE.match(lines[e["line"] - 1])
    lines[e["line"] - 1] = m.group(1) + m.group(2) + m.group(3) + e["value"] + m.group(5)
    stem = f"zz_{e['scenario']}_{e['line']}_{e['tag']}"
    path = assets / "scenarios" / f"{stem}.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    argv = [sys.executable, "-m", "workbench.cli", "run", str(path), "--out", str(out / stem), "--quiet"]
    # run in the checkout: ``-m`` puts the working folder first on sys.path, before PYTHONPATH
    p = subprocess.run(argv, capture_output=True, text=True, env=env, errors="replace", timeout=900, cwd=root)
    outcome = classify(p.returncode, p.stderr)
    verdict = ""
    for line in (p.stdout + p.stderr).splitlines():
        if "] health " in line:
            verdict = line.split("] health ", 1)[1].split(";")[0].split(" ")[0]
    last = (p.stderr.strip().splitlines() or [""])[-1]
    return {**e, "exit": p.returncode, "outcome": outcome, "verdict": verdict, "names_key": _dotted(e) in last,
            "message": last.replace(str(assets), "ASSETS").replace(str(out), "OUT")[:400]}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--scenarios", default="", help="comma-separated shipped scenario names (default: all)")
    ap.add_argument("--keys", default="", help="comma-separated key names or table.key (default: every noise/1σ key)")
    ap.add_argument("--root", default=str(REPO), help="the checkout whose workbench runs the edits")
    ap.add_argument("--out", default=str(REPO / "docs" / "results" / "bench_declared_sigmas.json"))
    a = ap.parse_args(argv)
    root = Path(a.root).resolve()
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(root))
    with tempfile.TemporaryDirectory(prefix="wb-sigmas-") as tmp:
        assets = Path(tmp) / "assets"
        shutil.copytree(root / "assets", assets)
        todo = edits(assets / "scenarios", [s for s in a.scenarios.split(",") if s] or None)
        if a.keys:
            keys = a.keys.split(",")
            todo = [e for e in todo if e["key"] in keys or f"{e['table']}.{e['key']}" in keys]
        print(f"{len(todo)} edits, {a.jobs} at a time, workbench of {root}", flush=True)
        with ThreadPoolExecutor(a.jobs) as ex:
            rows = list(ex.map(lambda e: run_one(e, assets, Path(tmp) / "out", env, root), todo))
    counts = _outcomes(rows)
    by = collections.defaultdict(collections.Counter)
    for r in rows:
        by[f"{r['scenario']} {r['tag']}"][r["outcome"]] += 1
    for r in rows:
        if r["outcome"] != "input error":
            print(f"  {r['scenario']:22s} {r['key']:28s} {r['tag']:8s} {r['outcome']:18s} {r['verdict']}")
    probe = subprocess.run([sys.executable, "-c", "import workbench; print(workbench.__file__)"], cwd=root, env=env,
                           capture_output=True, text=True)  # fmt: skip
    results = {
        "root_commit": _commit(root),
        "workbench_imported_from_root": Path(probe.stdout.strip()).resolve().parent.parent == root,
        "edits": len(rows),
        "outcomes": dict(counts),
        "input_errors_naming_the_key": sum(r["outcome"] == "input error" and r["names_key"] for r in rows),
        "by_scenario": {k: dict(v) for k, v in sorted(by.items())},
        # "named": keys named as a noise or 1σ; "declared": keys only their schema calls a 1σ
        "by_selection": {
            sel: {
                "edits": len(sub),
                "outcomes": dict(_outcomes(sub)),
                "input_errors_naming_the_key": sum(r["outcome"] == "input error" and r["names_key"] for r in sub),
            }
            for sel in ("named", "declared")
            for sub in [[r for r in rows if bool(_NAMED.search(r["key"])) == (sel == "named")]]
        },  # fmt: skip
        "rows": rows,
    }
    path = write_benchmark_json(a.out, __file__, results, argv)
    print(f"{dict(counts)} -> {path}")
    return 0


def _outcomes(rows: list[dict]) -> collections.Counter:
    """Edits per outcome, every one of :data:`OUTCOMES` counted even when 0."""
    counts = collections.Counter({k: 0 for k in OUTCOMES})
    counts.update(r["outcome"] for r in rows)
    return counts


def _commit(root: Path) -> str:
    p = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    return p.stdout.strip()


if __name__ == "__main__":
    raise SystemExit(main())
