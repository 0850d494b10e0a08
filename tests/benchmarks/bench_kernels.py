"""Kernel benchmark: the per-call cost of hot building blocks, as ratios against a named baseline
measured in the same run (so the numbers mean something on any machine).

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_kernels.py

1. ``io.telemetry.read_telemetry`` of a 10 000-row, 20-column CSV (with header parsing, unit
   conversion and the per-cell checks) against ``numpy.loadtxt`` of the same file (no checks).
2. ``estimation.strapdown.rk4_step`` and ``covariance_step`` (the entry filter calls each ~3000
   times per run) against one bare 9×9 ``F @ P @ F.T + Q`` in numpy.

Prints a markdown table and writes ``recordings/benchmarks/kernels.json``.  These replaced the
timed assertions that used to sit in the unit tests (timings belong here, not in pass/fail tests).
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np

from workbench.core.bodies import MARS
from workbench.estimation import strapdown as sd
from workbench.io.telemetry import read_telemetry, write_telemetry

ROOT = Path(__file__).resolve().parents[2]


def best_of(fn, repeat: int = 5, number: int = 1) -> float:
    """Best wall time [s] per call of ``fn()`` over ``repeat`` batches of ``number`` calls."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def main() -> int:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        n = 10_000
        rng = np.random.default_rng(0)
        chans = {f"c{j}": (rng.normal(size=n), "g") for j in range(19)}
        p = write_telemetry(Path(tmp) / "big.csv", np.arange(n) * 1e-3, chans)
        t_read = best_of(lambda: read_telemetry(p))
        t_loadtxt = best_of(lambda: np.loadtxt(p, delimiter=",", comments="#", skiprows=1))
        rows.append(("read_telemetry 10k x 20", t_read, "numpy.loadtxt", t_loadtxt))

    v, q, pos = np.array([5000.0, 100.0, -200.0]), np.array([0.0, 0.0, 0.0, 1.0]), np.array([3.5e6, 0.0, 0.0])
    f, w, P = np.array([1.0, 2.0, 30.0]), np.array([0.1, 0.05, 0.28]), np.eye(9)
    F, Q = np.eye(9) + 1e-3, 1e-4 * np.eye(9)
    sd.covariance_step(P, q, f, w, 0.1, 1e-4, 1e-3, 0.1, None, pos, body=MARS)  # warm-up (lazy scipy imports)
    t_base = best_of(lambda: F @ P @ F.T + Q, number=300)
    t_rk4 = best_of(lambda: sd.rk4_step(v, q, pos, f, w, f, w, 0.1, body=MARS), number=300)
    t_cov = best_of(lambda: sd.covariance_step(P, q, f, w, 0.1, 1e-4, 1e-3, 0.1, None, pos, body=MARS), number=300)
    rows.append(("strapdown.rk4_step", t_rk4, "9x9 F P F^T + Q", t_base))
    rows.append(("strapdown.covariance_step", t_cov, "9x9 F P F^T + Q", t_base))

    print("| kernel | time per call | baseline | baseline time | ratio |\n|---|---|---|---|---|")
    for name, t, bname, tb in rows:
        print(f"| {name} | {t * 1e6:.1f} µs | {bname} | {tb * 1e6:.1f} µs | {t / tb:.1f}× |")
    out = ROOT / "recordings" / "benchmarks"
    out.mkdir(parents=True, exist_ok=True)
    (out / "kernels.json").write_text(
        json.dumps(
            [{"kernel": a, "s": t, "baseline": b, "baseline_s": tb, "ratio": t / tb} for a, t, b, tb in rows], indent=1
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
