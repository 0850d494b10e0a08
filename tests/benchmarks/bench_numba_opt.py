"""What numba's optimisation level costs at run time (issue #30: ``workbench/__init__.py`` sets
``NUMBA_OPT=2`` because level 2 compiles a fresh checkout's kernels in less CPU than numba's default 3).

For each level (baseline: 3, numba's default) a child interpreter with ``NUMBA_OPT`` set and its own
empty ``NUMBA_CACHE_DIR`` synthesises and reconstructs each scenario ``--reps`` + 1 times in process
(the first round compiles and is dropped) and reports the best CPU time (``time.process_time``) of
the synthesis (truth simulator) and of the reconstruction; the levels run interleaved, round by
round, so that a drift of the machine's load falls on all of them.  Ratios are against level 3 in
the same run.  The compile cost of each level is ``bench_compile.py`` with ``NUMBA_OPT`` set.

    python tests/benchmarks/bench_numba_opt.py [--levels 3,2,1] [--reps 3]
        [--scenarios droptest,droptest_ranging,schiaparelli,msl_meads,post2_huygens,post2_entry6dof]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

#: the child: one round (compile or timed) of every scenario, CPU seconds as a JSON line on stdout
_CHILD = r"""
import json, sys, tempfile, time
from pathlib import Path
from workbench.io.assets import assets_dir
from workbench.io.scenario import resolve_scenario
from workbench.problems import registry
from workbench.problems.base import RunOptions
out = {}
for name in sys.argv[1].split(","):
    sc = resolve_scenario(name, assets_dir())
    problem = registry.get(sc.kind, where=str(sc.path))
    settings = problem.settings(sc)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.process_time()
        tel = dict(problem.synthesize(settings, Path(tmp) / "telemetry", 0).telemetry)
        t1 = time.process_time()
        for _ in problem.reconstruct(settings, tel, RunOptions(seed=0)):
            pass
        t2 = time.process_time()
    out[name] = [t1 - t0, t2 - t1]
print(json.dumps(out))
"""


def one_round(level: int, cache: str, scenarios: str) -> dict:
    """Every scenario once in a child at ``level`` with the cache folder ``cache``: {name: [synth, recon]} [s]."""
    env = dict(os.environ, NUMBA_OPT=str(level), NUMBA_CACHE_DIR=cache, OPENBLAS_NUM_THREADS="1")
    argv = [sys.executable, "-c", _CHILD, scenarios]
    p = subprocess.run(argv, env=env, capture_output=True, text=True, check=True, cwd=HERE.parents[1])
    return json.loads(p.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="3,2,1")
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument(
        "--scenarios", default="droptest,droptest_ranging,schiaparelli,msl_meads,post2_huygens,post2_entry6dof"
    )
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_numba_opt.json"))
    args = ap.parse_args(argv)
    levels = [int(x) for x in args.levels.split(",")]
    names = args.scenarios.split(",")
    t_start = time.perf_counter()
    best: dict[int, dict[str, list[float]]] = {lv: {} for lv in levels}
    with tempfile.TemporaryDirectory(prefix="bench_numba_opt_") as tmp:
        caches = {lv: str(Path(tmp) / f"opt{lv}") for lv in levels}
        for lv in levels:  # compile round, dropped
            one_round(lv, caches[lv], args.scenarios)
        for r in range(args.reps):
            for lv in levels:
                got = one_round(lv, caches[lv], args.scenarios)
                for n, (s, c) in got.items():
                    b = best[lv].setdefault(n, [float("inf"), float("inf")])
                    best[lv][n] = [min(b[0], s), min(b[1], c)]
            print(f"round {r + 1}/{args.reps}: " + json.dumps({lv: best[lv] for lv in levels}), flush=True)
    base = levels[0]
    per_level = {}
    for lv in levels:
        tot = sum(s + c for s, c in best[lv].values())
        tot0 = sum(s + c for s, c in best[base].values())
        per_level[str(lv)] = {
            "cpu_s": {n: {"synthesis": round(s, 4), "reconstruction": round(c, 4)} for n, (s, c) in best[lv].items()},
            "total_cpu_s": round(tot, 3),
            "ratio_total": round(tot / tot0, 4),
            "ratio_reconstruction": {n: round(best[lv][n][1] / best[base][n][1], 4) for n in names},
            "ratio_synthesis": {n: round(best[lv][n][0] / best[base][n][0], 4) for n in names},
        }
    results = {
        "baseline_level": base,
        "reps": args.reps,
        "scenarios": names,
        "wall_s": round(time.perf_counter() - t_start, 1),
        "levels": per_level,
    }
    print(json.dumps(results, indent=1))
    write_benchmark_json(args.out, __file__, results, argv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
