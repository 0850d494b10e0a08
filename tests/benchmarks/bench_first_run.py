"""The first run of a checkout (issue #30): ``workbench run all`` with numba's cache deleted, this
checkout against a baseline commit, interleaved round by round on the same machine.

For each round and each of the two checkouts (the order alternates from round to round, so that a
drift of the machine's speed falls on both) the compiled kernels cached beside the sources
(``workbench/**/__pycache__/*.nbi|nbc``) are deleted and ``python -m workbench.cli run all --quiet``
runs into a fresh folder, with ``PYTHONPATH`` the checkout (so its own ``workbench`` is imported).
Measured per run: wall time, the CPU time (user + system) of every process of the run, the largest
peak resident set of any one of its processes (``ru_maxrss`` of ``RUSAGE_CHILDREN``), and the CPU
time Python's cyclic garbage collector took in each process (a ``sitecustomize`` on ``PYTHONPATH``
times every collection with ``gc.callbacks`` and ``time.thread_time``, as a collection runs in the
thread that started it; the same instrument in both checkouts). Both checkouts are byte-compiled
(``compileall``) before the first round, so neither pays for it in a measured run. The last round's summaries of the two
checkouts are compared number by number (``compare_summaries.py``, timings skipped).

The baseline is checked out with ``git worktree`` into a temporary folder and removed at the end. The
shipped assets come from the installed package (an editable install maps ``workbench.assets`` to
this checkout's ``assets/``), so a baseline whose ``assets/`` differ from this checkout's is refused.

    python tests/benchmarks/bench_first_run.py --baseline COMMIT [--rounds 3]
        [--out docs/results/bench_first_run.json]

Run on an otherwise idle machine; about 1.5 min per round.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402
from checkouts import RUSAGE, baseline_worktree, checkout_env, git  # noqa: E402

#: the instrument: per process, the CPU time of every garbage collection (written after each one, as
#: forked processes leave with os._exit and run no exit hook); counters restart in a forked child
_SITECUSTOMIZE = r"""
import gc, os, time
_t = {"gc_s": 0.0, "start": 0.0, "full": 0}
def _cb(phase, info):
    if phase == "start":
        _t["start"] = time.thread_time()
        return
    _t["gc_s"] += time.thread_time() - _t["start"]
    _t["full"] += info["generation"] == 2
    with open(os.path.join(os.environ["BENCH_GC_DIR"], str(os.getpid())), "w") as f:
        f.write(f'{_t["gc_s"]} {_t["full"]}')
def _reset():
    _t["gc_s"] = 0.0
    _t["full"] = 0
if os.environ.get("BENCH_GC_DIR"):
    os.register_at_fork(after_in_child=_reset)
    gc.callbacks.append(_cb)
"""


def _clear_cache(root: Path) -> int:
    """Delete numba's cached kernels under ``root/workbench``; the number of files deleted."""
    n = 0
    for pattern in ("*.nbi", "*.nbc"):
        for f in (root / "workbench").rglob(pattern):
            f.unlink()
            n += 1
    return n


def first_run(root: Path, out: Path, gc_dir: Path, site_dir: Path) -> dict:
    """One first run of ``workbench run all`` of the checkout ``root`` into ``out``: wall [s], CPU of
    all its processes [s], the largest peak RSS of one process [MB], garbage-collector CPU summed
    over its processes [s] and per process (largest first), full collections, processes that
    collected."""
    _clear_cache(root)
    gc_dir.mkdir(parents=True)
    env = checkout_env(root, PYTHONPATH=str(site_dir), BENCH_GC_DIR=str(gc_dir))
    run_all = ["-m", "workbench.cli", "run", "all", "--out", str(out), "--quiet"]
    cmd = [sys.executable, "-I", "-c", RUSAGE, sys.executable, *run_all]  # -I: the wrapper is not instrumented
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    usage = json.loads(p.stdout.strip().splitlines()[-1])
    if usage["code"] != 0:
        raise SystemExit(f"workbench run all failed in {root} (exit {usage['code']}):\n{p.stderr[-2000:]}")
    per_process = sorted((f.read_text().split() for f in gc_dir.iterdir()), key=lambda g: -float(g[0]))
    return {
        "wall_s": wall,
        "cpu_s": usage["cpu_s"],
        "max_rss_mb": usage["max_rss_mb"],
        "gc_cpu_s": sum(float(g) for g, _ in per_process),
        "gc_cpu_s_per_process": [float(g) for g, _ in per_process],
        "full_collections": sum(int(n) for _, n in per_process),
        "processes": len(per_process),
    }


def _median(rows: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", required=True, help="the commit to compare with (e.g. the one before a change)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "bench_first_run.json"))
    a = ap.parse_args(argv)
    base_commit = git("rev-parse", "--short", a.baseline)
    head = git("rev-parse", "--short", "HEAD")
    with tempfile.TemporaryDirectory(prefix="bench_first_run_") as tmp:
        tmp = Path(tmp)
        site = tmp / "site"
        site.mkdir()
        (site / "sitecustomize.py").write_text(_SITECUSTOMIZE)
        with baseline_worktree(base_commit, tmp) as roots:
            rows: dict[str, list[dict]] = {"baseline": [], "current": []}
            for r in range(a.rounds):
                order = ("baseline", "current") if r % 2 == 0 else ("current", "baseline")
                for name in order:
                    row = first_run(roots[name], tmp / f"out_{name}_{r}", tmp / f"gc_{name}_{r}", site)
                    rows[name].append(row)
                    print(
                        f"round {r + 1} {name:8s}: wall {row['wall_s']:.1f} s, CPU {row['cpu_s']:.1f} s, "
                        f"GC {row['gc_cpu_s']:.2f} s ({row['full_collections']} full), "
                        f"max RSS {row['max_rss_mb']:.0f} MB",
                        flush=True,
                    )
            last = a.rounds - 1
            cmp = subprocess.run(
                [sys.executable, str(HERE / "compare_summaries.py"), str(tmp / f"out_baseline_{last}"),
                 str(tmp / f"out_current_{last}"), "--rtol", "1e-9"],
                capture_output=True, text=True,
            )  # fmt: skip
    keys = ("wall_s", "cpu_s", "gc_cpu_s", "max_rss_mb")
    med = {n: {k: _median(rows[n], k) for k in keys} for n in rows}
    ratio = {k: med["current"][k] / med["baseline"][k] for k in keys}
    for k in keys:
        b, c = med["baseline"][k], med["current"][k]
        print(f"{k:11s} median: baseline {b:.2f}, current {c:.2f}, ratio {ratio[k]:.3f}")
    print(cmp.stdout.strip().splitlines()[-1] if cmp.stdout.strip() else cmp.stderr.strip())
    results = {
        "baseline_commit": base_commit,
        "current_commit": head,
        "rounds": a.rounds,
        "runs": rows,
        "median": med,
        # per round, current minus baseline (the two runs of a round are minutes apart, so the
        # machine's drift between rounds falls out of the difference)
        "paired_difference": {
            k: [c[k] - b[k] for c, b in zip(rows["current"], rows["baseline"], strict=True)] for k in keys
        },
        "ratio_current_to_baseline": ratio,
        "summaries_identical": cmp.returncode == 0,
        "summaries_compare": cmp.stdout.strip().splitlines(),
    }
    path = write_benchmark_json(a.out, __file__, results, argv)
    print(f"-> {path}")
    return 0 if cmp.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
