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
import shutil
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


# ------------------------------------------------------------------------ issue 26: users' mistakes
def _bench_fuzz():
    """``tests/benchmarks/bench_fuzz.py`` (and its ``fuzz_mutations``) as a module."""
    bench = HERE / "benchmarks"
    if str(bench) not in sys.path:
        sys.path.insert(0, str(bench))
    import bench_fuzz

    return bench_fuzz


#: a fast set of the issue-26 classes on the cheap bases (the rocket importer on the committed
#: excerpt, post2_j2): one file edit each, run through the importer CLI / the scenario as a user does
FAST = (
    "rocket/axis_swap/IMU x<->z (acceleration and rate)",
    "rocket/sign_flip/all accelerations negated",
    "rocket/unit/pressure in kPa",
    "rocket/geometry/launch latitude and longitude swapped",
    "rocket/truncation/a third of the coast rows removed",
    "rocket/timing/observation rate 30 Hz",
    "rocket/metadata/Cd = 0",
    "post2_j2/unit/time in ms",
    "post2_j2/truncation/observations end at 5000 s",
    "post2_j2/timing/observation time +5 s",
)


def _run_inline(bf, muts, work: Path) -> list[dict]:
    """The outcome rows of ``muts`` run in this process (no worker pool), scored against their
    bases' clean runs."""
    from flight_data import SITE_MAGNETIC

    clean, base_dir = {}, {}
    for b in sorted({m.base for m in muts}):
        base_dir[b] = bf.make_base(b, work / "bases")
        problem = next(m.problem for m in muts if m.base == b)
        clean[b] = bf.run_task(bf._task(problem, b, base_dir[b], SITE_MAGNETIC))
        assert clean[b]["ok"], (b, clean[b])
    rows = []
    for i, m in enumerate(muts):
        folder = work / "cases" / f"{i:03d}"
        shutil.copytree(base_dir[m.base], folder, ignore=shutil.ignore_patterns("import"))
        m.edit(folder)
        rec = bf.run_task(bf._task(m.problem, m.base, folder, SITE_MAGNETIC, m.import_args, clean[m.base].get("extra")))
        rows.append(bf.score(m, clean[m.base], rec))
    return rows


def test_users_mistakes_fast_set_has_no_traceback(tmp_path):
    """Issue 26 item 5, fast tier: a mutation of every class on the importer and post2 ends in a
    located error or a completed, scored run; never a traceback."""
    bf = _bench_fuzz()
    muts = [m for m in bf.fm.catalogue(0) if m.key in FAST]
    assert {m.key for m in muts} == set(FAST)
    assert {m.cls for m in muts} == set(bf.fm.CLASSES)
    rows = _run_inline(bf, muts, tmp_path)
    bad = [r for r in rows if r["outcome"] in ("TRACEBACK", "TIMEOUT")]
    assert not bad, bad
    assert all(r["outcome"] in bf.OUTCOMES for r in rows)


def test_mutation_catalogue_covers_every_class_and_problem():
    """≥ 300 distinct mutations; every class on every problem (the bench's acceptance set)."""
    fm = _bench_fuzz().fm
    muts = fm.catalogue(0)
    assert len(muts) >= 300 and len({m.key for m in muts}) == len(muts)
    problems = {"droptest", "droptest_ranging", "entry", "meads", "post2_j2", "post2_huygens", "rocket"}
    assert {m.problem for m in muts} == problems
    for p in problems - {"post2_j2"}:  # post2_j2: no sensor axes (a gravity magnitude)
        assert {m.cls for m in muts if m.problem == p} == set(fm.CLASSES), p
    assert len(fm.quick(muts)) < len(muts) // 2


def test_csv_edits_keep_the_format(tmp_path):
    """A column edit rewrites only that column's cells; comments, header and empty cells stay."""
    fm = _bench_fuzz().fm
    p = tmp_path / "x.csv"
    p.write_text("# rate_hz: 10\ntime [s],a [g],b [g]\n0,1,\n0.1,2,3\n", encoding="utf-8")
    fm.csv_edit("x.csv", fm.scale("a", k=-1.0), fm.swap("a", "b"), fm.comment("rate_hz", "100"))(tmp_path)
    assert p.read_text(encoding="utf-8") == "# rate_hz: 100\ntime [s],a [g],b [g]\n0,,-1\n0.1,3,-2\n"


@pytest.mark.slow
def test_users_mistakes_quick_set_has_no_traceback(tmp_path):
    """Issue 26 item 5: two mutations per problem and class (``bench_fuzz.py --quick``) through the
    worker pool: no traceback, no timeout."""
    bf = _bench_fuzz()
    muts = bf.fm.quick(bf.fm.catalogue(0))
    rows, clean, _ = bf.run(muts, tmp_path, jobs=2, verbose=False)
    assert all(c["ok"] for c in clean.values()), clean
    bad = [r for r in rows if r["outcome"] in ("TRACEBACK", "TIMEOUT")]
    assert not bad, "\n".join(f"{r['problem']}/{r['class']}/{r['what']}: {r.get('message')}" for r in bad)
