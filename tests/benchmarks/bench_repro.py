"""Reproducibility of the shipped scenarios' summaries: a rerun, the thread and job counts, and the
kernels another CPU would run (issue #29 item 7).

Run on demand from the repository root (not collected by pytest)::

    .venv/bin/python tests/benchmarks/bench_repro.py [--configs rerun blas_threads_2 ...]
        [--scenarios all] [--keep DIR] [--json docs/results/bench_repro.json]

Runs ``workbench run <scenarios>`` once in the reference configuration (the command line's own
defaults: one BLAS thread, two scenarios at a time, ensembles in the process) and once per
configuration of :data:`CONFIGS`,
each in a fresh process with only that setting changed, and compares every number of every summary
with the reference (``compare_summaries.relative_differences``: timings, sizes and paths skipped).
The configurations that emulate another machine on this one: ``OPENBLAS_CORETYPE`` (the BLAS kernels
OpenBLAS picks for another CPU), ``NPY_DISABLE_CPU_FEATURES`` (numpy's SIMD loops of a CPU without
AVX-512) and ``NUMBA_CPU_NAME=generic`` (the compiled kernels without FMA or AVX).

Per configuration and scenario: the count of numbers and of those that moved, the largest relative
difference and the keys that moved most; the same for the summary numbers the README and
docs/RESULTS.md cite (``{{summaries/<name>.summary:key}}`` in ``results_templates.py``) and for
the synthetic telemetry's ``truth.npz`` (relative to each array's largest magnitude). Then (unless
``--skip-same-telemetry``) one set of user telemetry per scenario (``workbench init``, written once
in the reference configuration) is reconstructed with each other-machine setting: what the
reconstruction adds without the truth simulator.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_json import write_benchmark_json  # noqa: E402
from compare_summaries import relative_differences  # noqa: E402

#: What the reference runs with: the variables below are removed from its environment (the command
#: line then sets one BLAS thread itself).
CLEARED = (
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "NUMBA_NUM_THREADS",
    "OPENBLAS_CORETYPE",
    "NPY_DISABLE_CPU_FEATURES",
    "NUMBA_CPU_NAME",
    "WORKBENCH_POST2_KERNEL",
)

#: name -> (what varies, environment, extra ``workbench run`` arguments, emulates another machine)
CONFIGS: dict[str, tuple[str, dict[str, str], list[str], bool]] = {
    "rerun": ("nothing: the same command again", {}, [], False),
    "jobs_1": ("scenarios one after another in one process (`--jobs 1`)", {}, ["--jobs", "1"], False),
    "blas_threads_2": (
        "2 BLAS / OpenMP threads (`OPENBLAS_NUM_THREADS=OMP_NUM_THREADS=MKL_NUM_THREADS=2`)",
        {"OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2", "MKL_NUM_THREADS": "2"},
        [],
        False,
    ),
    "dask_local": (
        "ensemble stages on a Dask LocalCluster (`--scheduler local`) instead of in the process",
        {},
        ["--scheduler", "local"],
        False,
    ),
    "openblas_haswell": (
        "OpenBLAS kernels of an AVX2 CPU (`OPENBLAS_CORETYPE=Haswell`)",
        {"OPENBLAS_CORETYPE": "Haswell"},
        [],
        True,
    ),
    "numpy_no_avx512": (
        "numpy's SIMD loops without AVX-512 (`NPY_DISABLE_CPU_FEATURES`)",
        {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"},
        [],
        True,
    ),
    "numba_generic": (
        "numba kernels compiled for a generic x86-64 (`NUMBA_CPU_NAME=generic`: no FMA)",
        {"NUMBA_CPU_NAME": "generic"},
        [],
        True,
    ),
}

#: summary numbers followed by name in every configuration (issue #29 item 7 names the MEADS EKF's β
#: maximum; the README's MEADS EKF numbers come from the same run through bench_meads.py)
WATCH = {
    "msl_meads": (
        "/truth/ekf_pass2/beta_deg/max_abs",
        "/truth/ekf_pass2/alpha_deg/rms",
        "/truth/ekf_pass2/qbar_pct/rms",
    ),
    "post2_huygens": (
        "/truth/planted_vs_recovered[3]/recovered",
        "/truth/position_error_m/end_smoothed",
    ),
    "schiaparelli": ("/truth/after_radar_fix/max_h_agl_error_m",),
}

_CITED = re.compile(r"\{\{summaries/([A-Za-z0-9_]+)\.summary:([^|}]+)")


def cited_keys() -> dict[str, set[str]]:
    """{scenario: {key path as '/a/b[0]'}} of the summary numbers the README and RESULTS.md cite."""
    import results_templates as rt  # noqa: PLC0415 (beside this file)

    texts = [rt.RESULTS_MD, *(t for t in rt.README_BLOCKS.values() if isinstance(t, str))]
    out: dict[str, set[str]] = {}
    for text in texts:
        for name, key in _CITED.findall(text):
            path = "".join(f"[{p}]" if p.isdigit() else f"/{p}" for p in key.split("."))
            out.setdefault(name, set()).add(path)
    return out


def run_all(out: Path, scenarios: list[str], env: dict[str, str], args: list[str]) -> float:
    """``workbench run <scenarios> --out <out> -q`` in a fresh process with ``env`` on top of the
    cleared environment; returns the wall time [s]."""
    full = {k: v for k, v in os.environ.items() if k not in CLEARED}
    full["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), full.get("PYTHONPATH", "")) if p)
    full.update(env)
    cmd = [sys.executable, "-m", "workbench.cli", "run", *scenarios, "--out", str(out), "-q", *args]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, env=full, cwd=ROOT, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}")
    return time.perf_counter() - t0


def init_user_scenarios(folder: Path, scenarios: list[str]) -> list[str]:
    """``workbench init <name> <folder>/<name>`` for each scenario in the reference environment: a
    user-data scenario whose telemetry the truth simulator wrote once; returns the scenario files."""
    env = {k: v for k, v in os.environ.items() if k not in CLEARED}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    files = []
    for name in scenarios:
        cmd = [sys.executable, "-m", "workbench.cli", "init", name, str(folder / name), "--force"]
        r = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}")
        files.append(str(folder / name / "scenario.toml"))
    return files


def truth_difference(a: Path, b: Path) -> tuple[float, str]:
    """Largest difference between two ``truth.npz`` files over their float arrays, relative to each
    array's largest magnitude, and the array's name."""
    worst, name = 0.0, ""
    with np.load(a) as x, np.load(b) as y:
        for k in x.files:
            u, v = x[k], y[k]
            if u.dtype.kind != "f" or u.shape != v.shape or u.size == 0:
                if u.shape != v.shape:
                    return float("inf"), k
                continue
            scale = float(np.nanmax(np.abs(u))) or 1.0
            d = float(np.nanmax(np.abs(u - v))) / scale if np.isfinite(u).any() else 0.0
            if d > worst:
                worst, name = d, k
    return worst, name


def compare(ref: Path, new: Path, scenarios: list[str], cited: dict[str, set[str]], top: int = 3) -> dict:
    """Per scenario: numbers, moved, max relative difference and the ``top`` keys that moved most,
    the cited numbers' largest difference, and the truth telemetry's."""
    out: dict = {}
    for name in scenarios:
        a = json.loads((ref / f"{name}.summary.json").read_text())
        b = json.loads((new / f"{name}.summary.json").read_text())
        rel = relative_differences(a, b)
        moved = [r for r in rel if r[0] > 0]
        mine = [r for r in rel if r[1] in cited.get(name, set())]
        tr_a, tr_b = ref / name / "telemetry" / "truth.npz", new / name / "telemetry" / "truth.npz"
        truth = truth_difference(tr_a, tr_b) if tr_a.is_file() and tr_b.is_file() else (0.0, "")
        out[name] = {
            "numbers": len(rel),
            "moved": len(moved),
            "max_rel": moved[0][0] if moved else 0.0,
            "top": [{"key": k, "reference": x, "value": y, "rel": r} for r, k, x, y in moved[:top]],
            "cited_numbers": len(mine),
            "cited_max_rel": max((r[0] for r in mine), default=0.0),
            "cited_top_key": max(mine, key=lambda r: r[0])[1] if mine else None,
            "watch": {
                r[1]: {"reference": r[2], "value": r[3], "rel": r[0]} for r in rel if r[1] in WATCH.get(name, ())
            },
            "truth_max_rel": truth[0],
            "truth_top_array": truth[1] or None,
        }
    return out


def machine() -> dict:
    """CPU, BLAS and library versions of this run."""
    import numba  # noqa: PLC0415
    import scipy  # noqa: PLC0415
    from threadpoolctl import threadpool_info  # noqa: PLC0415

    cpu = ""
    try:
        cpu = next(
            ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines() if "model name" in ln
        )
    except (OSError, StopIteration):
        cpu = platform.processor()
    blas = [
        {k: i.get(k) for k in ("internal_api", "architecture", "version", "threading_layer")}
        for i in threadpool_info()
        if i.get("user_api") == "blas"
    ]
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "blas": blas,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
    }


def _g(x: float) -> str:
    """A relative difference for the tables: "0" (bit-identical), else two significant digits."""
    return "0" if x == 0 else f"{x:.1e}"


def markdown_of(results_dir: Path = ROOT / "docs" / "results") -> str:
    """The "Reproducibility" section of docs/RESULTS.md from ``bench_repro.json`` in ``results_dir``
    (for ``make_results.py``); the words say the cause, every number is read from the JSON."""
    doc = json.loads((results_dir / "bench_repro.json").read_text())
    r = doc["results"]
    m = r["machine"]
    blas = ", ".join(f"{b['internal_api']} {b['version']} ({b['architecture']})" for b in m["blas"]) or "unknown"
    lines = [
        "## Reproducibility (issue #29 item 7)",
        "",
        f"`{doc['command']}` ({doc['utc']}; {m['cpu']}, {m['cores']} cores, {blas}, numpy {m['numpy']}, "
        f"scipy {m['scipy']}, numba {m['numba']}): every shipped scenario run in the reference configuration "
        "(the command line's defaults: one BLAS thread, two scenarios at a time) and again with one setting "
        "changed, every number of every summary compared (timings, sizes and paths aside; relative difference "
        '|a − b| / max(|a|, |b|)). "cited": the summary numbers the README and this file quote; '
        '"truth.npz": the synthetic truth written beside the telemetry, relative to each array\'s largest value.',
        "",
        "| what varies | summaries that move | largest relative difference (scenario: key) | cited | truth.npz |",
        "|---|---|---|---|---|",
    ]
    for c in r["configs"].values():
        moved = ", ".join(f"`{s}`" for s in c["scenarios_moved"]) or "none (bit-identical)"
        worst = c["per_scenario"][c["max_rel_scenario"]]
        where = f" (`{c['max_rel_scenario']}`: `{worst['top'][0]['key']}`)" if worst["top"] else ""
        cited, truth = _g(c["cited_max_rel"]), _g(c["truth_max_rel"])
        lines.append(f"| {c['what']} | {moved} | {_g(c['max_rel'])}{where} | {cited} | {truth} |")
    if r.get("other_machine"):
        lines += [
            "",
            "Bound per scenario over the configurations that emulate another machine (largest of them):",
            "",
            "| scenario | every number | the cited numbers | truth.npz | the key that moves most "
            "| the same telemetry reconstructed (key) |",
            "|---|---|---|---|---|---|",
        ]
        same = r.get("same_telemetry", {})
        for s, o in r["other_machine"].items():
            key = f"`{o['top_key']}`" if o["top_key"] else "—"
            st = same.get(s)
            st_text = (
                "not measured" if st is None else _g(st["max_rel"]) + (f" (`{st['top_key']}`)" if st["top_key"] else "")
            )
            lines.append(
                f"| `{s}` | {_g(o['max_rel'])} | {_g(o['cited_max_rel'])} | {_g(o['truth_max_rel'])} | {key} "
                f"| {st_text} |"
            )
        lines += [
            "",
            "The last column: one set of user telemetry per scenario (`workbench init <scenario>`, written once "
            "in the reference configuration; no truth, so no errors in its summary) reconstructed with each "
            "other-machine setting — what the reconstruction adds on its own.",
        ]
        others = {n: c for n, c in r["configs"].items() if c["other_machine"]}
        lines += [
            "",
            "Named numbers, the reference and each other-machine setting (relative difference):",
            "",
            "| scenario: key | reference | " + " | ".join(f"`{n}`" for n in others) + " |",
            "|---|---|" + "---|" * len(others),
        ]
        for s in r["scenarios"]:
            ref_watch = next(iter(others.values()))["per_scenario"][s].get("watch", {}) if others else {}
            for key, w in ref_watch.items():
                vals = []
                for c in others.values():
                    x = c["per_scenario"][s]["watch"][key]
                    vals.append(f"{x['value']:.4g} ({_g(x['rel'])})")
                lines.append(f"| `{s}`: `{key}` | {w['reference']:.4g} | " + " | ".join(vals) + " |")
    return "\n".join(lines) + "\n"


def readme_of(results_dir: Path = ROOT / "docs" / "results") -> str:
    """The README's one paragraph on the tolerance its numbers are reproduced to (``make_results.py``)."""
    r = json.loads((results_dir / "bench_repro.json").read_text())["results"]
    same = [c for c in r["configs"].values() if not c["other_machine"]]
    other = r.get("other_machine", {})
    same_max = max((c["max_rel"] for c in same), default=0.0)
    cited = {s: o["cited_max_rel"] for s, o in other.items() if o["cited_max_rel"] > 0}
    worst = sorted(cited, key=lambda s: -cited[s])
    text = (
        f"Reproduced to: on one machine a rerun, `--jobs 1`, Dask or two BLAS threads change no summary number "
        f"(largest relative difference {_g(same_max)}; `tests/test_reproducible.py` holds 1e-9). Another CPU "
        "runs other BLAS kernels and numpy SIMD loops (emulated here, `tests/benchmarks/bench_repro.py`): the "
        "truth simulators' adaptive step control then writes slightly different synthetic telemetry, and the "
        "summary numbers quoted here move by up to "
    )
    text += ", ".join(f"{_g(cited[s])} (`{s}`)" for s in worst) or "0"
    meads = [
        (x["rel"], k)
        for c in r["configs"].values()
        if c["other_machine"]
        for k, x in c["per_scenario"].get("msl_meads", {}).get("watch", {}).items()
    ]
    if meads:
        rel, key = max(meads)
        text += (
            f", and the MEADS EKF numbers (measured on the `msl_meads` run by `bench_meads.py`) by up to "
            f"{_g(rel)} (`{key}`)"
        )
    text += "; every number, per scenario, and why: docs/RESULTS.md (Reproducibility).\n"
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", nargs="*", default=list(CONFIGS), choices=list(CONFIGS))
    ap.add_argument("--scenarios", nargs="*", default=["all"])
    ap.add_argument("--keep", type=Path, default=None, help="keep the runs' output folders here")
    ap.add_argument("--json", type=Path, default=None, help="write the results (docs/results/bench_repro.json)")
    ap.add_argument(
        "--skip-same-telemetry",
        action="store_true",
        help="skip reconstructing one set of user telemetry (workbench init) with each other-machine setting",
    )
    args = ap.parse_args(argv)
    from workbench.io.assets import assets_dir  # noqa: PLC0415
    from workbench.io.scenario import find_scenarios  # noqa: PLC0415

    scenarios = sorted(find_scenarios(assets_dir())) if args.scenarios == ["all"] else list(args.scenarios)
    cited = cited_keys()
    with tempfile.TemporaryDirectory(prefix="bench-repro-") as tmp:
        work = args.keep or Path(tmp)
        wall = {"reference": run_all(work / "reference", scenarios, {}, [])}
        results: dict = {"machine": machine(), "scenarios": scenarios, "configs": {}}
        for name in args.configs:
            what, env, extra, other_machine = CONFIGS[name]
            wall[name] = run_all(work / name, scenarios, env, extra)
            per = compare(work / "reference", work / name, scenarios, cited)
            worst = max(per, key=lambda s: per[s]["max_rel"])
            results["configs"][name] = {
                "what": what,
                "env": env,
                "args": extra,
                "other_machine": other_machine,
                "max_rel": per[worst]["max_rel"],
                "max_rel_scenario": worst,
                "cited_max_rel": max(p["cited_max_rel"] for p in per.values()),
                "truth_max_rel": max(p["truth_max_rel"] for p in per.values()),
                "scenarios_moved": sorted(s for s in per if per[s]["moved"]),
                "per_scenario": per,
            }
            moved = results["configs"][name]["scenarios_moved"]
            print(f"{name:18s} max rel {per[worst]['max_rel']:.2e} ({worst}); moved: {moved}", flush=True)
        other = [c for c in results["configs"].values() if c["other_machine"]]
        results["other_machine"] = (
            {
                s: {
                    "max_rel": max(c["per_scenario"][s]["max_rel"] for c in other),
                    "cited_max_rel": max(c["per_scenario"][s]["cited_max_rel"] for c in other),
                    "truth_max_rel": max(c["per_scenario"][s]["truth_max_rel"] for c in other),
                    "top_key": max(other, key=lambda c: c["per_scenario"][s]["max_rel"])["per_scenario"][s]["top"][0][
                        "key"
                    ]
                    if any(c["per_scenario"][s]["moved"] for c in other)
                    else None,
                }
                for s in scenarios
            }
            if other
            else {}
        )
        if other and not args.skip_same_telemetry:
            # the reconstruction alone: the same user telemetry (written once, reference environment)
            # reconstructed with each other-machine setting
            files = init_user_scenarios(work / "user", scenarios)
            wall["same_telemetry_reference"] = run_all(work / "user-reference", files, {}, [])
            same: dict = {}
            for name in (n for n in args.configs if CONFIGS[n][3]):
                wall[f"same_telemetry_{name}"] = run_all(
                    work / f"user-{name}", files, CONFIGS[name][1], CONFIGS[name][2]
                )
                per = compare(work / "user-reference", work / f"user-{name}", scenarios, {})
                same[name] = {s: {k: per[s][k] for k in ("numbers", "moved", "max_rel", "top")} for s in scenarios}
                worst = max(per, key=lambda s: per[s]["max_rel"])
                print(f"same telemetry, {name:18s} max rel {per[worst]['max_rel']:.2e} ({worst})", flush=True)
            results["same_telemetry"] = {
                s: {
                    "max_rel": max(same[c][s]["max_rel"] for c in same),
                    "top_key": max(same.values(), key=lambda c: c[s]["max_rel"])[s]["top"][0]["key"]
                    if any(same[c][s]["moved"] for c in same)
                    else None,
                }
                for s in scenarios
            }
            results["same_telemetry_per_config"] = same
        results["wall_s"] = wall
    if args.json:
        print(f"wrote {write_benchmark_json(args.json, __file__, results, argv)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
