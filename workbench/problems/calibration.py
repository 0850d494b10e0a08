"""Calibrate a problem's health checks on its own truth Monte Carlo and store the table.

Each member is one shipped synthetic scenario of the problem run end to end
(:func:`workbench.problems.runner.evaluate`: truth simulator → telemetry files → reconstruction →
summary, no recording) with a seed of the **calibration stream**; the statistic of every check that
carries one (``Check.stat``) is collected over the members of all the problem's scenarios and its
honest band fitted (:func:`workbench.estimation.calibration.fit_band`, half-width
:func:`~workbench.estimation.calibration.family_z` for the table's number of checks).  The table is written to
``workbench/problems/<kind>/health_calibration.json`` and judged against by every later run
(:func:`workbench.problems.runner.judge_health`).

Seed streams (one rule, the same in every benchmark): ``np.random.SeedSequence(SEED_ENTROPY,
spawn_key=(k,))`` with k = 1 tuning, 2 validation, 3 health calibration; the shipped scenarios' own
seeds are never calibration members.

    workbench calibrate droptest --members 30 --write      (or python -m workbench.problems.calibration ...)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from workbench.estimation.calibration import FAMILY_ALPHA, band_key, family_z, fit_band
from workbench.io import assets
from workbench.io.scenario import resolve_scenario
from workbench.problems import registry
from workbench.problems.base import SEED_ENTROPY, SEED_STREAMS, stream_seeds
from workbench.problems.runner import calibration_path, evaluate

__all__ = [
    "CALIBRATION_STREAM",
    "SEED_ENTROPY",
    "TUNING_STREAM",
    "VALIDATION_STREAM",
    "calibrate",
    "main",
    "seeds_of",
    "shipped_scenarios",
]

#: spawn keys of the streams (:data:`workbench.problems.base.SEED_STREAMS`): tuning may use any seed of
#: stream 1; consistency claims come from stream 2; the health bands from stream 3
TUNING_STREAM, VALIDATION_STREAM, CALIBRATION_STREAM = (
    SEED_STREAMS[k] for k in ("tuning", "validation", "calibration")
)


def seeds_of(stream: int, n: int) -> list[int]:
    """The first ``n`` integer seeds (< 2**31) of the seed stream ``stream`` (see the module docstring)."""
    return stream_seeds(stream, n)


def shipped_scenarios(kind: str) -> list[Path]:
    """The shipped synthetic scenario files whose ``kind`` is ``kind`` (sorted by name)."""
    out = []
    for p in sorted((assets.assets_dir() / "scenarios").glob("*.toml")):
        sc = resolve_scenario(p, assets.assets_dir())
        if sc.kind == kind and sc.is_synthetic:
            out.append(p)
    return out


def _member(args: tuple[str, int]) -> dict:
    """One calibration member: the checks of scenario ``args[0]`` run with seed ``args[1]`` (uncalibrated)."""
    path, seed = args
    with tempfile.TemporaryDirectory(prefix="wb-calib-") as tmp:
        try:
            summary = evaluate(path, Path(tmp), seed, calibrated=False)
        except Exception as err:  # a failed member is reported, not hidden
            return {"scenario": Path(path).stem, "seed": seed, "error": f"{type(err).__name__}: {err}"}
    health = summary.get("health") or {}
    checks = [
        {"name": c["name"], "value": c["value"], "stat": c.get("stat"), "status": c["status"]}
        for c in health.get("checks", [])
    ]
    return {"scenario": Path(path).stem, "seed": seed, "checks": checks}


def calibrate(kind: str, members: int, *, jobs: int = 2, scenarios: Sequence[Path] | None = None) -> dict:
    """The calibration table of problem ``kind``: ``members`` seeds of the calibration stream for each
    of its shipped synthetic ``scenarios`` (default all), run on ``jobs`` processes.  Every check with
    a ``stat`` gets a band (:func:`~workbench.estimation.calibration.fit_band`) over all members where it
    has a finite value; members that failed are listed under ``"failed"``."""
    paths = list(scenarios) if scenarios is not None else shipped_scenarios(kind)
    if not paths:
        raise SystemExit(f"no shipped synthetic scenario of kind {kind!r}")
    shipped = {int(resolve_scenario(p, assets.assets_dir()).get("synthetic.seed", 0, kind="int")) for p in paths}
    seeds = [s for s in seeds_of(CALIBRATION_STREAM, members + len(shipped)) if s not in shipped][:members]
    work = [(str(p), s) for p in paths for s in seeds]
    t0 = time.perf_counter()
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs) as ex:
            rows = list(ex.map(_member, work))
    else:
        rows = [_member(w) for w in work]
    values: dict[str, list[float]] = defaultdict(list)
    stats: dict[str, dict] = {}
    per_member = [0]
    for r in rows:
        n_stat = 0
        for c in r.get("checks", []):
            if c["stat"] and c["value"] is not None:
                key = band_key(c["name"], c["stat"])
                values[key].append(float(c["value"]))
                stats[key] = c["stat"]
                n_stat += 1
        per_member.append(n_stat)
    names = [n for n in sorted(values) if sum(np.isfinite(values[n])) >= 2]
    # Bonferroni over the checks one run is judged on (a pooled band judges several of them)
    z = family_z(max(len(names), max(per_member)))
    checks = {n: {"stat": stats[n], **fit_band(values[n], stats[n].get("kind", ""), z)} for n in names}
    return {
        "kind": kind,
        "source": f"{kind} truth Monte Carlo, calibration stream",
        "command": f"workbench calibrate {kind} --members {members} --write",
        "seed_stream": {"entropy": SEED_ENTROPY, "spawn_key": [CALIBRATION_STREAM]},
        "family_alpha": FAMILY_ALPHA,
        "z": round(z, 4),
        "members": len([r for r in rows if "checks" in r]),
        "seeds": seeds,
        "scenarios": [Path(p).stem for p in paths],
        "wall_s": round(time.perf_counter() - t0, 1),
        "failed": [r for r in rows if "error" in r],
        "checks": checks,
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: calibrate one or more problems and (``--write``) store their tables."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("kinds", nargs="+", help="problem kinds (droptest, entry, meads, post2)")
    ap.add_argument("--members", type=int, default=30, help="seeds per scenario (default 30)")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--write", action="store_true", help="write the problem's health_calibration.json")
    args = ap.parse_args(argv)
    for kind in args.kinds:
        table = calibrate(kind, args.members, jobs=args.jobs)
        path = calibration_path(registry.get(kind))
        text = json.dumps(table, indent=1, sort_keys=False) + "\n"
        if args.write:
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path} ({table['members']} members, {len(table['checks'])} checks, {table['wall_s']} s)")
        else:
            sys.stdout.write(text)
        for f in table["failed"]:
            print(f"member failed: {f['scenario']} seed {f['seed']}: {f['error']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
