"""Peak memory of one scenario run by itself (issue #30's memory budget of 600 MB), this checkout
against a baseline commit, and how the drop test's peak grows with the length of its log.

``workbench run all``'s "max RSS" is the largest of its processes, and those are forked from the
run after its imports: a forked scenario does not count the library pages it inherited until it
touches them, so a scenario run by itself (``workbench run NAME``, what a user runs on their own
data) peaks higher than the same scenario inside ``run all``. Here every shipped scenario runs in
its own new interpreter, with numba's cache warm (one ``run all`` per checkout first), and its
peak resident set is ``ru_maxrss`` of ``RUSAGE_CHILDREN`` of a wrapper process.

The log-length series runs the shipped ``droptest`` scenario with the lander hanging longer before
its release (``[synthetic] pre_release_s``, each variant a copy of the scenario file in a temporary
folder): the drop-test filter runs at 1 kHz over the whole log, and its covariance histories are
n_e × n_e per step (n_e = 42 with four accelerometer triads), so its peak grows linearly with the
number of filter steps; the slope [KiB per step] is a least-squares line through the series. Memory
is in MiB (``ru_maxrss`` / 1024), printed "MB" as /usr/bin/time's users read it.

Both checkouts' summaries of the shipped scenarios are compared number by number, exactly
(``compare_summaries.py --rtol 0``, timings skipped). The baseline is a ``git worktree`` (``checkouts.py``).

    python tests/benchmarks/bench_memory.py --baseline COMMIT [--scenarios all]
        [--hang 0.5,5,10] [--out docs/results/bench_memory.json]

About 4 min (two warm-up runs of ``run all``, then 13 single runs per checkout).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_json import write_benchmark_json  # noqa: E402
from checkouts import ROOT, RUSAGE, baseline_worktree, checkout_env, git  # noqa: E402

#: the issue's budget of one run's memory [MB]
BUDGET_MB = 600.0


def run_one(root: Path, scenario: str, out: Path) -> dict:
    """``workbench run scenario`` of checkout ``root`` in a new interpreter: peak RSS [MB], CPU [s],
    and from its summary the filter steps (drop test) and wall time."""
    cmd = [sys.executable, "-I", "-c", RUSAGE, sys.executable, "-m", "workbench.cli", "run", scenario]
    cmd += ["--out", str(out)]
    p = subprocess.run([*cmd, "--quiet"], cwd=root, env=checkout_env(root), capture_output=True, text=True)
    lines = p.stdout.strip().splitlines()
    if not lines:
        raise SystemExit(f"the wrapper of workbench run {scenario} in {root} printed nothing:\n{p.stderr[-2000:]}")
    usage = json.loads(lines[-1])
    if usage["code"] != 0:
        raise SystemExit(f"workbench run {scenario} failed in {root} (exit {usage['code']}):\n{p.stderr[-2000:]}")
    summary = json.loads((out / f"{Path(scenario).stem}.summary.json").read_text(encoding="utf-8"))
    return {
        "max_rss_mb": usage["max_rss_mb"],
        "cpu_s": usage["cpu_s"],
        "wall_s": summary.get("wall_time_s"),
        "steps": summary.get("steps"),
    }


def hang_variant(hang_s: float, folder: Path) -> Path:
    """The shipped ``droptest`` scenario with ``pre_release_s = hang_s`` (the lander file by its
    absolute path), written into ``folder``; its path."""
    src = ROOT / "assets" / "scenarios" / "droptest.toml"
    text = src.read_text(encoding="utf-8")
    text, n = re.subn(r"(?m)^pre_release_s\s*=\s*[0-9.]+", f"pre_release_s = {hang_s!r}", text)
    lander = (src.parent / "../landers/mer_drop_lander.toml").resolve()
    text = text.replace('"../landers/mer_drop_lander.toml"', json.dumps(str(lander)))
    name = f"droptest_hang_{hang_s:g}s".replace(".", "p")
    text = re.sub(r'(?m)^name\s*=\s*"droptest"', f'name = "{name}"', text)
    if n != 1 or not lander.is_file():
        raise SystemExit(f"{src}: expected one pre_release_s line and the lander file {lander}")
    path = folder / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", required=True, help="the commit to compare with (e.g. the one before a change)")
    ap.add_argument("--scenarios", default="all", help="comma-separated shipped scenarios, or all")
    ap.add_argument("--hang", default="0.5,5,10", help="pre-release hang times [s] of the droptest log-length series")
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "bench_memory.json"))
    a = ap.parse_args(argv)
    base_commit = git("rev-parse", "--short", a.baseline)
    head = git("rev-parse", "--short", "HEAD")
    if a.scenarios == "all":
        names = sorted(p.stem for p in (ROOT / "assets" / "scenarios").glob("*.toml"))
    else:
        names = a.scenarios.split(",")
    hangs = [float(h) for h in a.hang.split(",") if h]
    rows: dict[str, dict] = {"baseline": {}, "current": {}}
    series: dict[str, list[dict]] = {"baseline": [], "current": []}
    with tempfile.TemporaryDirectory(prefix="bench_memory_") as tmp:
        tmp = Path(tmp)
        variants = [hang_variant(h, tmp) for h in hangs]
        with baseline_worktree(base_commit, tmp) as roots:
            for name, root in roots.items():
                warm = [sys.executable, "-m", "workbench.cli", "run", "all", "--out", str(tmp / f"warm_{name}")]
                subprocess.run([*warm, "--quiet"], cwd=root, env=checkout_env(root), check=True, capture_output=True)
                for sc in names:
                    rows[name][sc] = run_one(root, sc, tmp / f"out_{name}")
                    print(f"{name:8s} {sc:22s} peak {rows[name][sc]['max_rss_mb']:6.0f} MB", flush=True)
                for h, path in zip(hangs, variants, strict=True):
                    r = run_one(root, str(path), tmp / f"hang_{name}")
                    series[name].append({"pre_release_s": h, **r})
                    print(f"{name:8s} hang {h:5g} s, {r['steps']} steps: peak {r['max_rss_mb']:6.0f} MB", flush=True)
            cmp = subprocess.run(
                [sys.executable, str(HERE / "compare_summaries.py"), str(tmp / "out_baseline"),
                 str(tmp / "out_current"), "--rtol", "0"],
                capture_output=True, text=True,
            )  # fmt: skip
    fits = {}
    for name, pts in series.items():
        if len(pts) >= 2:
            steps = np.array([p["steps"] for p in pts], float)
            mb = np.array([p["max_rss_mb"] for p in pts], float)
            slope, icpt = np.polyfit(steps, mb, 1)  # MB per step, MB (ru_maxrss in KiB / 1024: MiB)
            at_budget = (BUDGET_MB - icpt) / slope if slope > 0 else None
            fits[name] = {"kib_per_step": slope * 1024, "intercept_mb": icpt, "steps_at_budget": at_budget}
    results = {
        "baseline_commit": base_commit,
        "current_commit": head,
        "budget_mb": BUDGET_MB,
        "scenarios": {
            sc: {
                "baseline": rows["baseline"][sc],
                "current": rows["current"][sc],
                "ratio_max_rss": rows["current"][sc]["max_rss_mb"] / rows["baseline"][sc]["max_rss_mb"],
            }
            for sc in names
        },
        "largest_current": max(names, key=lambda sc: rows["current"][sc]["max_rss_mb"]),
        "droptest_log_length": {"series": series, "fit": fits},
        "summaries_identical": cmp.returncode == 0,
        "summaries_compare": cmp.stdout.strip().splitlines(),
    }
    for sc in names:
        b, c = rows["baseline"][sc]["max_rss_mb"], rows["current"][sc]["max_rss_mb"]
        print(f"{sc:22s} baseline {b:6.0f} MB, current {c:6.0f} MB, ratio {c / b:.3f}")
    for name, f in fits.items():
        print(f"{name:8s} drop-test log: {f['kib_per_step']:.1f} KiB per filter step + {f['intercept_mb']:.0f} MiB")
    print(cmp.stdout.strip().splitlines()[-1] if cmp.stdout.strip() else cmp.stderr.strip())
    path = write_benchmark_json(a.out, __file__, results, argv)
    print(f"-> {path}")
    return 0 if cmp.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
