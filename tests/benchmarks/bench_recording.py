"""Micro-benchmark of workbench.recording: 5000 rows × 30 scalar series + 5000 poses + 5000 ellipsoids.

Run: ``.venv/bin/python tests/benchmarks/bench_recording.py`` (from the repository root). Prints
wall times per part and in total, including the footer write, fsync and atomic rename.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from workbench.recording import layout  # noqa: E402
from workbench.recording.reader import read_recording  # noqa: E402
from workbench.recording.writer import open_recording  # noqa: E402


def run(path: Path, n: int = 5000, n_series: int = 30) -> dict[str, float]:
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.01
    step = np.arange(n)
    values = rng.normal(size=(n_series, n))
    sigma = np.abs(rng.normal(size=(n_series, n)))
    pos = rng.normal(size=(n, 3))
    quat = Rotation.random(n, random_state=0).as_quat()
    a = rng.normal(size=(n, 3, 3))
    cov = a @ np.swapaxes(a, 1, 2) + 1e-3 * np.eye(3)
    times: dict[str, float] = {}
    t0 = time.perf_counter()
    with open_recording(path, "bench") as rec:
        t1 = time.perf_counter()
        for i in range(n_series):
            rec.scalars(layout.plot_path(f"q{i}"), t, values[i], step=step, names=f"q{i}")
        t2 = time.perf_counter()
        rec.poses(layout.VEHICLE, t, pos, quat, step=step)
        t3 = time.perf_counter()
        rec.ellipsoids(layout.UNCERTAINTY, t, pos, cov, step=step)
        t4 = time.perf_counter()
        for i in range(10):
            rec.series_with_bounds(layout.plot_path(f"b{i}"), t, values[i], sigma[i], truth=values[i], step=step)
        t5 = time.perf_counter()
    t6 = time.perf_counter()
    times.update(
        open=t1 - t0,
        scalars_30x5000=t2 - t1,
        poses_5000=t3 - t2,
        ellipsoids_5000=t4 - t3,
        bounds_10x4x5000=t5 - t4,
        close_footer_rename=t6 - t5,
        total_required=(t4 - t0) + (t6 - t5),
        total=t6 - t0,
    )
    t7 = time.perf_counter()
    read_recording(path).scalars(layout.plot_path("q0"))
    times["read_back"] = time.perf_counter() - t7
    times["file_MB"] = path.stat().st_size / 1e6
    return times


def baseline_log_loop(path: Path, n: int = 5000, n_series: int = 3) -> float:
    """Named baseline: the same scalar rows logged one ``rr.log`` call per row (2 timelines), the
    way a per-step recorder would; returns seconds per 5000-row series."""
    import rerun as rr

    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.01
    values = rng.normal(size=(n_series, n))
    with open_recording(path, "bench-baseline") as rec:
        st = rec.stream
        t0 = time.perf_counter()
        for i in range(n_series):
            for k in range(n):
                st.set_time("time", duration=float(t[k]))
                st.set_time("step", sequence=k)
                st.log(layout.plot_path(f"q{i}"), rr.Scalars(values[i, k]))
        el = time.perf_counter() - t0
    return el / n_series


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as d:
        for rep in range(3):
            r = run(Path(d) / f"bench{rep}.rrd")
            print(f"run {rep}: " + "  ".join(f"{k}={v:.3f}" for k, v in r.items()))
        per_series_cols = r["scalars_30x5000"] / 30
        per_series_loop = baseline_log_loop(Path(d) / "baseline.rrd")
        print(
            f"5000-row scalar series: Recorder.scalars (send_columns) {per_series_cols * 1e3:.2f} ms, "
            f"baseline rr.log loop {per_series_loop * 1e3:.0f} ms: ratio {per_series_loop / per_series_cols:.0f}x"
        )
