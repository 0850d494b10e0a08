"""The README's and docs/RESULTS.md's numbers are the committed JSON outputs, and those still hold.

Fast: the committed README.md and docs/RESULTS.md equal a fresh render of ``docs/results/*.json``
by ``tests/benchmarks/make_results.py`` (a hand edit of a number, or a JSON updated without
re-rendering, fails here). Slow: a fresh ``workbench run droptest`` reproduces the committed
``docs/results/summaries/droptest.summary.json`` (every number to 1e-6 relative, timings and
paths aside), so the committed tables cannot drift from what HEAD produces.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "tests" / "benchmarks"


def _module(name: str):
    spec = importlib.util.spec_from_file_location(f"_bench_{name}", BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_committed_docs_equal_a_render_of_the_committed_results():
    mk = _module("make_results")
    stale = [str(p.relative_to(ROOT)) for p, text in mk.render_all(ROOT).items() if p.read_text() != text]
    assert not stale, f"{stale} differ from docs/results/*.json; run tests/benchmarks/make_results.py --write"


def test_placeholder_errors_name_file_and_key(tmp_path):
    mk = _module("make_results")
    (tmp_path / "b.json").write_text(json.dumps({"results": {"x": 0.1234, "n": None, "l": [1, 2]}}))
    assert mk.fill("{{b:results.x|*100:.1f}} %", tmp_path) == "12.3 %"
    assert mk.fill("{{b:results.n|.2f}}", tmp_path) == "n/a"
    assert mk.fill("{{b:results.l.1}}", tmp_path) == "2"
    assert mk.format_value(172.4, "mmss") == "2 min 52 s"
    with pytest.raises(mk.ResultsError, match=r"b\.json has no key 'results\.y'"):
        mk.fill("{{b:results.y}}", tmp_path)
    with pytest.raises(mk.ResultsError, match="nope"):
        mk.fill("{{nope:x}}", tmp_path)
    with pytest.raises(mk.ResultsError, match="lacks the generated block"):
        mk.render_readme("no blocks here", {"a": "x"}, tmp_path)
    # the benchmarks' one JSON writer produces what the renderer reads (NaN → null → "n/a")
    bj = _module("bench_json")
    results = {"v": float("nan"), "w": 2.5}
    bj.write_benchmark_json(tmp_path / "c.json", "tests/benchmarks/bench_c.py", results, ["-n", "3"])
    assert mk.fill("{{c:benchmark}} {{c:command}} {{c:results.v|.1f}} {{c:results.w|.1f}}", tmp_path) == (
        "bench_c python tests/benchmarks/bench_c.py -n 3 n/a 2.5"
    )
    assert not list(tmp_path.glob("*.partial"))


def test_readme_times_come_from_the_commands_file():
    cmds = json.loads((ROOT / "docs" / "results" / "commands.json").read_text())
    mk = _module("make_results")
    readme = (ROOT / "README.md").read_text()
    assert mk.format_value(cmds["run_all_s"], "mmss") in readme
    assert mk.format_value(cmds["fast_tier_s"], "mmss") in readme


@pytest.mark.slow
def test_fresh_droptest_run_reproduces_the_committed_summary(tmp_path):
    cmp = _module("compare_summaries")
    committed = ROOT / "docs" / "results" / "summaries" / "droptest.summary.json"
    out = tmp_path / "out"
    subprocess.run(
        [sys.executable, "-m", "workbench.cli", "run", "droptest", "--out", str(out)],
        check=True,
        capture_output=True,
        text=True,
    )
    a = json.loads(committed.read_text())
    b = json.loads((out / "droptest.summary.json").read_text())
    diffs: list[str] = []
    cmp.differences(a, b, "droptest", "recordings", str(out), 1e-6, diffs)
    assert not diffs, "\n".join(diffs[:20])
