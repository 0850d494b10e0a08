"""Time the README's two commands from a fresh clone and keep what the main job wrote.

Clones the repository's committed ``HEAD`` into a temporary folder (so nothing uncommitted and
no existing ``.venv`` helps), then runs, each timed with a wall clock:

1. the main job: ``python3 -m venv .venv && .venv/bin/pip install -q -e . && .venv/bin/workbench run all``
   (the install and the run are timed separately);
   (the run's wall time, the largest resident set of any of its processes and each scenario's own
   wall time are kept), then the main job once more (compiled kernels from the cache);
2. the test command: ``.venv/bin/pip install -q -e ".[test]"`` then
   ``.venv/bin/python -m pytest -q -m "not slow"`` (fast tier), and ``-m slow`` (statistical tier).

Writes ``docs/results/commands.json`` (seconds, test counts, the commit, the date) and copies
every ``<scenario>.summary.json`` that the main job wrote to ``docs/results/summaries/``; the
README's times and scenario tables are rendered from those by ``make_results.py``.

Usage: ``.venv/bin/python tests/benchmarks/time_readme_commands.py [--skip-slow] [--keep DIR]``
(about 9 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _run(cmd: str, cwd: Path) -> tuple[float, str]:
    """Run ``cmd`` in a shell in ``cwd``; return (wall seconds, combined output). Raises on failure."""
    t0 = time.perf_counter()
    p = subprocess.run(cmd, shell=True, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    out = p.stdout + p.stderr
    if p.returncode != 0:
        sys.stderr.write(out[-4000:])
        raise SystemExit(f"command failed ({p.returncode}): {cmd}")
    return wall, out


def pytest_counts(output: str) -> dict[str, int]:
    """Parse pytest's final line ("475 passed, 1 xfailed in 130.2s") into {"passed": 475, ...}."""
    tail = [ln for ln in output.strip().splitlines() if re.search(r"\d+ (passed|failed)", ln)]
    if not tail:
        raise ValueError("no pytest summary line in the output")
    return {k: int(n) for n, k in re.findall(r"(\d+) (passed|failed|xfailed|xpassed|skipped|errors?)", tail[-1])}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--skip-slow", action="store_true", help="do not run the slow tier")
    ap.add_argument("--keep", type=Path, help="clone into this folder instead of a temporary one")
    args = ap.parse_args(argv)

    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True)
    work = args.keep or Path(tempfile.mkdtemp(prefix="wb_clone_"))
    clone = work / "repo"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
    res: dict = {
        "benchmark": "time_readme_commands",
        "commit": commit.stdout.strip(),
        "utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "machine": "2 cores",
        "command": "python tests/benchmarks/time_readme_commands.py",
    }

    res["install_s"], _ = _run("python3 -m venv .venv && .venv/bin/pip install -q -e .", clone)
    # the main job under a small Python parent that reports the largest resident set of its
    # descendants (every scenario process of ``run all`` is waited for, so it counts)
    rss = (
        ".venv/bin/python -c 'import resource, subprocess, sys; "
        'r = subprocess.run([".venv/bin/workbench", "run", "all"]).returncode; '
        'print("MAXRSS_KB", resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(r)\''
    )
    res["run_all_s"], out = _run(rss, clone)
    res["run_all_max_rss_mb"] = int(re.search(r"MAXRSS_KB (\d+)", out).group(1)) / 1024.0
    res["run_all_scenario_wall_s"] = {
        f.name.removesuffix(".summary.json"): json.loads(f.read_text())["wall_time_s"]
        for f in sorted((clone / "recordings").glob("*.summary.json"))
    }
    # the same command again: the compiled kernels now come from numba's cache beside the sources
    # (the first run of a fresh checkout compiles them)
    res["run_all_warm_s"], out = _run(rss, clone)
    res["run_all_warm_max_rss_mb"] = int(re.search(r"MAXRSS_KB (\d+)", out).group(1)) / 1024.0
    res["install_test_extra_s"], _ = _run('.venv/bin/pip install -q -e ".[test]"', clone)
    res["fast_tier_s"], out = _run('.venv/bin/python -m pytest -q -p no:cacheprovider -m "not slow"', clone)
    res["fast_tier"] = pytest_counts(out)
    if not args.skip_slow:
        res["slow_tier_s"], out = _run(".venv/bin/python -m pytest -q -p no:cacheprovider -m slow", clone)
        res["slow_tier"] = pytest_counts(out)

    dest = ROOT / "docs" / "results"
    (dest / "summaries").mkdir(parents=True, exist_ok=True)
    for f in sorted((clone / "recordings").glob("*.summary.json")):
        # paths inside the summary name the clone's folder; keep them relative to the repository
        text = f.read_text().replace(str(clone / "recordings"), "recordings")
        (dest / "summaries" / f.name).write_text(text)
    (dest / "commands.json").write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps(res, indent=2))
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
