"""The calibrated health verdict of honest drops other than each scenario's own: the drop tests'
truth Monte Carlo draws (``disperse_drop``, the REDLand test envelope: impact speeds, attitude, bag
pressure, timing, bungee) on the validation stream, reconstructed and judged with the stored
calibration (:func:`workbench.problems.runner.judge_health`) — what a user's honest drop meets.

The health calibration (``workbench calibrate droptest``) draws its members' drops from the same
envelope on the calibration stream; this benchmark holds out the validation stream and measures how the
verdict fares there.  Per scenario: the verdict counts, the drops with an ERROR from a check that a
user's own run has (all but the ``truth.*`` scoring checks), and per check that is not OK the status
counts and the range of its value.

    python tests/benchmarks/bench_dispersed_health.py [--members 20] [--scenarios droptest,droptest_ranging]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402

from workbench.io.assets import assets_dir  # noqa: E402
from workbench.io.scenario import resolve_scenario  # noqa: E402
from workbench.problems.calibration import VALIDATION_STREAM, seeds_of  # noqa: E402
from workbench.problems.droptest.pipeline import run_droptest, score  # noqa: E402
from workbench.problems.droptest.problem import DropTestProblem  # noqa: E402
from workbench.problems.droptest.synthetic import load_truth, synthesize_droptest  # noqa: E402
from workbench.problems.runner import judge_health  # noqa: E402


def member(problem: DropTestProblem, settings, seed: int) -> dict:
    """One dispersed drop ``seed`` of the run with ``settings``: its calibrated health."""
    with tempfile.TemporaryDirectory(prefix="wb-dispersed-") as tmp:
        syn = synthesize_droptest(settings, Path(tmp), seed=seed, disperse=True, compress_truth=False)
        res = run_droptest(settings, syn.telemetry, seed=seed)
        summary = dict(res.summary, truth=score(res, load_truth(syn.truth_path)))
    judge_health(problem, summary)
    bad = {c["name"]: (c["status"], c["value"]) for c in summary["health"]["checks"] if c["status"] != "OK"}
    return {"seed": seed, "verdict": summary["health"]["verdict"], "not_ok": bad}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=20, help="dispersed drops per scenario")
    ap.add_argument("--scenarios", default="droptest,droptest_ranging")
    ap.add_argument("--out", default=str(HERE.parents[1] / "docs" / "results" / "bench_dispersed_health.json"))
    a = ap.parse_args(argv)
    problem = DropTestProblem()
    t0 = time.perf_counter()
    per: dict[str, dict] = {}
    for name in a.scenarios.split(","):
        settings = problem.settings(resolve_scenario(name, assets_dir()))
        rows = [member(problem, settings, s) for s in seeds_of(VALIDATION_STREAM, a.members)]
        checks: dict[str, list] = defaultdict(list)
        for r in rows:
            for c, (status, value) in r["not_ok"].items():
                checks[c].append((status, value))
        per[name] = {
            "verdicts": {v: sum(r["verdict"] == v for r in rows) for v in ("OK", "WARNING", "ERROR")},
            "error_checks_a_user_run_has": sum(
                any(st == "ERROR" and not c.startswith("truth.") for c, (st, _) in r["not_ok"].items()) for r in rows
            ),
            "not_ok": {
                c: {
                    "status": dict(Counter(s for s, _ in v)),
                    "range": [min(x for _, x in v if x is not None), max(x for _, x in v if x is not None)]
                    if any(x is not None for _, x in v)
                    else None,
                }
                for c, v in sorted(checks.items())
            },
            "rows": rows,
        }
        print(f"{name}: verdicts {per[name]['verdicts']}; not OK {per[name]['not_ok']}", flush=True)
    totals = {v: sum(p["verdicts"][v] for p in per.values()) for v in ("OK", "WARNING", "ERROR")}
    totals["drops"] = sum(totals.values())
    totals["error_checks_a_user_run_has"] = sum(p["error_checks_a_user_run_has"] for p in per.values())
    results = {"members": a.members, "wall_s": round(time.perf_counter() - t0, 1), "scenarios": per, "totals": totals}
    out = write_benchmark_json(a.out, __file__, results, argv)
    print(f"{results['wall_s']:.0f} s -> {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
