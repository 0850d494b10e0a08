"""Fuzz suite (issue 12): seeded mutations of user-style telemetry and scenario files for every
problem (drop test, entry, post2) through the validation + health API; every case must end GOOD
(a located error, or the same numbers as the clean files) or DEGRADED (reported: health not OK);
none SILENT, none a traceback.  The harness is ``tests/support/fuzz.py``; the before/after table is
``tests/benchmarks/bench_fuzz.py`` → ``docs/results/bench_fuzz.json``.

Inputs: the drop test's telemetry from the session's shared CLI run (``droptest_run``, paid once for
the fast tier); the entry's from the short fake truth of ``problems/entry/test_telemetry.py``
(−15 … 72 s, 10 Hz); post2's from the ``post2_j2`` truth simulator (a hundred samples).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import fuzz
import pytest

HERE = Path(__file__).resolve().parents[1]


def entry_fake_files(out: Path) -> dict[str, Path]:
    """Entry telemetry files of the fake truth of ``problems/entry/test_telemetry.py`` in ``out``."""
    spec = importlib.util.spec_from_file_location("entry_tm_test", HERE / "problems" / "entry" / "test_telemetry.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    from workbench.problems.entry import synthetic as es
    from workbench.problems.entry.sensors import EntryTelemetrySpec

    return es.synthesize_from_truth(mod.fake_truth(), out, EntryTelemetrySpec(gaps=mod.GAPS), mod.SEED)


def post2_files(out: Path) -> Path:
    """The ``post2_j2`` observation CSV written by its truth simulator into ``out``."""
    from workbench.io.assets import assets_dir
    from workbench.io.scenario import load_scenario
    from workbench.problems.post2.problem import Post2Problem

    sc = load_scenario(assets_dir() / "scenarios" / "post2_j2.toml")
    Post2Problem().synthesize(Post2Problem().settings(sc), out, 1)
    return out


@pytest.fixture(scope="module")
def targets(tmp_path_factory, droptest_run) -> tuple[list, Path]:
    work = tmp_path_factory.mktemp("fuzz")
    t_drop = fuzz.droptest_target(droptest_run.telemetry_dir, work)
    t_entry = fuzz.entry_target(entry_fake_files(work / "entry_clean"), work)
    t_post2 = fuzz.post2_target(post2_files(work / "post2_clean"), work)
    return [t_drop, t_entry, t_post2], work


def test_fuzz_no_silent_no_traceback(targets):
    tgts, work = targets
    results = fuzz.run_all(tgts, range(1), work / "cases")  # bench_fuzz.py runs more seeds
    ran = [r for r in results if r.outcome != "N/A"]
    assert len(ran) >= 170
    bad = [r for r in ran if r.outcome in (fuzz.SILENT, fuzz.TRACEBACK)]
    assert not bad, "\n".join(f"{r.case}: {r.outcome} {r.detail}" for r in bad)
    by_problem = {p: [r for r in ran if r.case.problem == p] for p in ("droptest", "entry", "post2")}
    for p, rs in by_problem.items():  # every problem fuzzed, with real rejections among the outcomes
        assert rs and sum(r.outcome == fuzz.GOOD for r in rs) > len(rs) // 3, p


def test_shipped_droptest_health_is_honest(droptest_run):
    """The shipped drop test comes out OK or WARNING (its ZUPT is conservative: mean NIS ≪ 3)."""
    h = droptest_run.summary["health"]
    assert h["verdict"] in ("OK", "WARNING"), h
    names = {c["name"]: c for c in h["checks"]}
    assert names["max_stroke.clearance"]["status"] == "OK" and names["gaps.contact"]["status"] == "OK"


def test_a_gap_across_contact_is_an_error(droptest_run, tmp_path):
    """The issue's case: 0.5 s of IMU rows removed across the impact -> ERROR before any filter runs."""
    import numpy as np

    from workbench.problems.droptest.health import input_health

    src = droptest_run.telemetry_paths()
    paths = {}
    for k, p in src.items():
        paths[k] = tmp_path / p.name
        paths[k].write_bytes(p.read_bytes())
    lines = paths["imu"].read_text().split("\n")
    h = next(i for i, s in enumerate(lines) if s.startswith("time"))
    t = np.array([float(s.split(",")[0]) for s in lines[h + 1 :] if s.strip()])
    f = np.array([[float(x) for x in s.split(",")[1:13]] for s in lines[h + 1 :] if s.strip()])
    peak = t[int(np.argmax(np.linalg.norm(f[:, 0:3], axis=1)))]
    keep = [s for s, tt in zip(lines[h + 1 :], t, strict=False) if not (peak - 0.25 < tt < peak + 0.25)]
    paths["imu"].write_text("\n".join(lines[: h + 1] + keep) + "\n")
    rep = input_health(droptest_run.settings, paths)
    assert rep["verdict"] == "ERROR"
    bad = [c for c in rep["checks"] if c["status"] == "ERROR"]
    assert bad and bad[0]["name"].startswith("gaps.") and "not observed" in bad[0]["message"]
    assert input_health(droptest_run.settings, src)["verdict"] != "ERROR"
