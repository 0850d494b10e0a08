"""The same scenario run twice on one machine gives the same summary (issue #29 item 7).

Every number of ``<name>.summary.json`` must agree to 1e-9 relative between two runs in fresh
processes (``tests/benchmarks/compare_summaries.py``: timings, sizes and paths are skipped). Fast
tier: the quickest scenario (``post2_j2``). Slow tier: every shipped scenario, run again, and run
with two BLAS / OpenMP threads instead of the command line's one — measured bit-identical
(``tests/benchmarks/bench_repro.py``, ``docs/results/bench_repro.json``), so held to the same 1e-9.
What does move the numbers (another CPU's BLAS kernels or numpy SIMD loops) cannot be varied in a
test of one machine's outputs against another's; its measured bound is in docs/RESULTS.md.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-9
#: thread settings removed from the reference runs' environment (the command line then uses one BLAS thread)
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def _compare_module():
    path = ROOT / "tests" / "benchmarks" / "compare_summaries.py"
    spec = importlib.util.spec_from_file_location("_bench_compare_summaries", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _run(out: Path, scenarios: list[str], threads: int | None = None) -> None:
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARS}
    if threads is not None:
        env.update({k: str(threads) for k in THREAD_VARS[:3]})
    r = subprocess.run(
        [sys.executable, "-m", "workbench.cli", "run", *scenarios, "--out", str(out), "-q"],
        env=env,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr[-3000:]


def _assert_same(a: Path, b: Path, names: list[str]) -> None:
    cmp = _compare_module()
    diffs: list[str] = []
    for name in names:
        x = json.loads((a / f"{name}.summary.json").read_text())
        y = json.loads((b / f"{name}.summary.json").read_text())
        cmp.differences(x, y, name, str(a), str(b), RTOL, diffs)
    assert not diffs, f"{len(diffs)} numbers differ:\n" + "\n".join(diffs[:30])


def test_rerun_of_the_quickest_scenario_gives_the_same_summary(tmp_path):
    _run(tmp_path / "a", ["post2_j2"])
    _run(tmp_path / "b", ["post2_j2"])
    _assert_same(tmp_path / "a", tmp_path / "b", ["post2_j2"])


def test_relative_differences_lists_every_shared_number_largest_first():
    cmp = _compare_module()
    a = {"x": 1.0, "wall_time_s": 3.0, "l": [2.0, float("nan")], "n": {"y": 0.0, "z": 4.0}}
    b = {"x": 1.5, "wall_time_s": 9.0, "l": [2.0, float("nan")], "n": {"y": 0.0, "z": float("nan")}}
    rel = cmp.relative_differences(a, b)
    assert [(r, k) for r, k, _, _ in rel[:2]] == [(float("inf"), "/n/z"), (pytest.approx(1 / 3), "/x")]
    assert {k for _, k, _, _ in rel} == {"/x", "/l[0]", "/l[1]", "/n/y", "/n/z"}  # timings skipped


@pytest.fixture(scope="module")
def reference_all(tmp_path_factory) -> tuple[Path, list[str]]:
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import find_scenarios

    names = sorted(find_scenarios(assets_dir()))
    out = tmp_path_factory.mktemp("repro") / "reference"
    _run(out, ["all"])
    return out, names


@pytest.mark.slow
def test_rerun_of_every_shipped_scenario_gives_the_same_summaries(reference_all, tmp_path):
    ref, names = reference_all
    _run(tmp_path / "again", ["all"])
    _assert_same(ref, tmp_path / "again", names)


@pytest.mark.slow
def test_two_blas_threads_give_the_same_summaries_as_one(reference_all, tmp_path):
    ref, names = reference_all
    _run(tmp_path / "threads2", ["all"], threads=2)
    _assert_same(ref, tmp_path / "threads2", names)
