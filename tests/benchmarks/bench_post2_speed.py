"""post2 speed benchmark (issue #14): CPU time of each POST2 scenario's reconstruction and of one
model derivative call, the compiled kernel beside the numpy reference, in the same process.

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_post2_speed.py [--scenarios post2_entry6dof ...]
        [--no-baseline] [--json recordings/benchmarks/post2_speed.json]

Per scenario (its truth synthesised once into a temporary folder, then the reconstruction run on it):

* ``reconstruct_cpu_s``: CPU time (``time.process_time``) of all stages of ``Post2Problem.reconstruct``
  with the kernel and, unless ``--no-baseline``, with the numpy reference (``WORKBENCH_POST2_KERNEL=0``:
  the code before the kernel); ``speedup`` their ratio;
  ``identical``: the two summaries equal number by number (``compare_summaries.differences``, rtol 0);
* ``derivative_us``: CPU µs per ``derivative`` call on the estimator's batch (the 1 + 2 n_e rows the
  batched numeric Jacobian propagates): ``kernel_batched``, ``reference_batched`` (numpy, the whole
  batch in one call) and ``reference_one_at_a_time`` (numpy, one call per row, summed over the batch);
* ``jit_first_call_s``: wall time of the first kernel call in this process (numba's cache load, or
  the compilation when the cache is cold).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)
from compare_summaries import differences  # noqa: E402

from workbench.io.assets import assets_dir  # noqa: E402
from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.base import RunOptions  # noqa: E402
from workbench.problems.post2 import model as post2_model  # noqa: E402
from workbench.problems.post2.config import Post2Settings  # noqa: E402
from workbench.problems.post2.pipeline import Estimator  # noqa: E402
from workbench.problems.post2.problem import Post2Problem  # noqa: E402

SCENARIOS = ("post2_entry6dof", "post2_mer_quaternion", "post2_huygens", "post2_j2")


def _reconstruct(prob, sc, telemetry, seed: int, use_kernel: bool) -> tuple[float, dict]:
    os.environ[post2_model.KERNEL_ENV] = "1" if use_kernel else "0"  # the models are built in reconstruct
    try:
        t0 = time.process_time()
        result = None
        for stage in prob.reconstruct(prob.settings(sc), telemetry, RunOptions(seed=seed)):
            result = stage
        return time.process_time() - t0, prob.summary(result)
    finally:
        os.environ.pop(post2_model.KERNEL_ENV, None)


def _per_call(fn, n: int) -> float:
    t0 = time.process_time()
    for _ in range(n):
        fn()
    return (time.process_time() - t0) / n * 1e6


def _derivative_timings(sc, n_calls: int) -> dict:
    est = Estimator(Post2Settings.from_scenario(sc))
    m, phase = est.model, est.model.initial_phase()
    n_e = est.layout.n_e
    D = np.diag(est.eps)
    X = np.concatenate([est.x0[None, :], est.layout.boxplus(est.x0, D), est.layout.boxplus(est.x0, -D)], axis=0)
    w0 = time.perf_counter()
    m.derivative(X, phase)
    jit = time.perf_counter() - w0
    kern = _per_call(lambda: m.derivative(X, phase), n_calls)
    ref = _per_call(lambda: m.derivative_reference(X, phase), max(1, n_calls // 10))
    one = _per_call(lambda: [m.derivative_reference(x, phase) for x in X], max(1, n_calls // 100))
    return {
        "batch_rows": int(X.shape[0]),
        "n_e": int(n_e),
        "jit_first_call_s": jit,
        "derivative_us": {"kernel_batched": kern, "reference_batched": ref, "reference_one_at_a_time": one},
        "derivative_speedup_vs_reference_batched": ref / kern,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    ap.add_argument("--no-baseline", action="store_true", help="skip the reconstruction with the numpy reference")
    ap.add_argument("--calls", type=int, default=2000, help="kernel derivative calls timed (reference: 1/10)")
    ap.add_argument("--json", default=str(ROOT / "recordings" / "benchmarks" / "post2_speed.json"))
    args = ap.parse_args(argv)
    prob = Post2Problem()
    results = {}
    for name in args.scenarios:
        sc = load_scenario(assets_dir() / "scenarios" / f"{name}.toml")
        seed = int(sc.get("synthetic.seed", 0, kind="int"))
        row = _derivative_timings(sc, args.calls)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.process_time()
            syn = prob.synthesize(prob.settings(sc), Path(tmp) / "telemetry", seed)
            row["synthesize_cpu_s"] = time.process_time() - t0
            kern_s, kern_sum = _reconstruct(prob, sc, dict(syn.telemetry), seed, True)
            row["reconstruct_cpu_s"] = {"kernel": kern_s}
            if not args.no_baseline:
                ref_s, ref_sum = _reconstruct(prob, sc, dict(syn.telemetry), seed, False)
                diffs: list[str] = []
                differences(ref_sum, kern_sum, "", tmp, tmp, 0.0, diffs)
                row["reconstruct_cpu_s"]["reference"] = ref_s
                row["reconstruct_speedup"] = ref_s / kern_s
                row["identical"] = not diffs
                row["differences"] = diffs[:10]
        results[name] = row
        rc = row["reconstruct_cpu_s"]
        print(
            f"{name}: reconstruct CPU {rc['kernel']:.2f} s (reference {rc.get('reference', float('nan')):.2f} s); "
            f"derivative {row['derivative_us']['kernel_batched']:.0f} us/call on {row['batch_rows']} rows "
            f"(reference {row['derivative_us']['reference_batched']:.0f} us, one at a time "
            f"{row['derivative_us']['reference_one_at_a_time']:.0f} us); identical {row.get('identical')}",
            flush=True,
        )
    path = write_benchmark_json(args.json, __file__, results, argv)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
