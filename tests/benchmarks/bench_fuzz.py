"""Fuzz table (issue 12): mutation class → runs → outcome counts (GOOD / DEGRADED / SILENT /
TRACEBACK) over seeded mutations of the drop-test, entry and post2 inputs, through the validation +
health API (``tests/support/fuzz.py``).

    python tests/benchmarks/bench_fuzz.py [--seeds 3] [--label after] [--out docs/results/bench_fuzz.json]

Run it against another checkout (e.g. the code before issue 12) with ``PYTHONPATH=<checkout>``
and ``--label before --merge``: the JSON then holds both tables.  Inputs: the drop test's
telemetry from its truth simulator (shipped ``droptest`` scenario, seed 1), the entry's from the
short fake truth of ``tests/problems/entry/test_telemetry.py``, post2's from the ``post2_j2`` truth.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "support"))
sys.path.insert(0, str(HERE))

import fuzz  # noqa: E402
from bench_json import write_benchmark_json  # noqa: E402


def _targets(work: Path) -> list:
    import importlib.util

    spec = importlib.util.spec_from_file_location("test_fuzz_mod", HERE.parent / "problems" / "test_fuzz.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import load_scenario
    from workbench.problems.droptest.problem import DropTestProblem

    drop_dir = work / "droptest_clean"
    problem = DropTestProblem()
    problem.synthesize(problem.settings(load_scenario(assets_dir() / "scenarios" / "droptest.toml")), drop_dir, 1)
    return [
        fuzz.droptest_target(drop_dir, work),
        fuzz.entry_target(mod.entry_fake_files(work / "entry_clean"), work),
        fuzz.post2_target(mod.post2_files(work / "post2_clean"), work),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--label", default="after")
    ap.add_argument("--merge", action="store_true", help="keep the other labels already in --out")
    ap.add_argument("--code", default=None, help="what code was measured (recorded; default: the label)")
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_fuzz.json"))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        targets = _targets(work)
        t0 = time.perf_counter()
        results = fuzz.run_all(targets, range(args.seeds), work / "cases")
        wall = time.perf_counter() - t0
    tab = fuzz.table(results)
    totals = {
        k: sum(r[k] for r in tab.values()) for k in ("runs", fuzz.GOOD, fuzz.DEGRADED, fuzz.SILENT, fuzz.TRACEBACK)
    }
    print(f"{'class':36s} {'runs':>5s} {'GOOD':>5s} {'DEGR':>5s} {'SILENT':>6s} {'TRACE':>5s}")
    for k, r in tab.items():
        print(f"{k:36s} {r['runs']:5d} {r['GOOD']:5d} {r['DEGRADED']:5d} {r['SILENT']:6d} {r['TRACEBACK']:5d}")
    print(
        f"{'total':36s} {totals['runs']:5d} {totals['GOOD']:5d} {totals['DEGRADED']:5d} {totals['SILENT']:6d} "
        f"{totals['TRACEBACK']:5d}   ({wall:.1f} s)"
    )
    bad = [
        f"{r.case.problem}/{r.case.cls}/{r.case.stream}/{r.case.seed}: {r.outcome} {r.detail}"
        for r in results
        if r.outcome in (fuzz.SILENT, fuzz.TRACEBACK)
    ]
    out = Path(args.out)
    data = json.loads(out.read_text())["results"] if args.merge and out.exists() else {}
    data[args.label] = {
        "code": args.label if args.code is None else args.code,
        "seeds": args.seeds,
        "wall_s": wall,
        "totals": totals,
        "table": tab,
        "silent_or_traceback": bad[:60],
    }
    write_benchmark_json(out, __file__, data, argv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
