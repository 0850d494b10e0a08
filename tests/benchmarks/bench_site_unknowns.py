"""What a rocket run does not know is in its σ (issue #27 item 3): each real FIRM flight imported
and run with its metadata as given, then again with one site unknown changed by a plausible error
of a user's metadata (the site temperature ±7 K, the reported pressure ±5 hPa, the surface wind
+5 m/s), and the move of the headline numbers (apogee above the pad, landing point) compared with
the σ the unperturbed run reports.  A move of a few σ means the σ leaves that unknown out.

Run on demand from the repository root, with the data outside the repository::

    EDL_FLIGHT_DATA=/path/to/folder-with-airbrakes_firm .venv/bin/python tests/benchmarks/bench_site_unknowns.py \\
        [--json docs/results/bench_site_unknowns.json] [--out DIR]
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "support"))

from flight_data import FLIGHTS, SITE_MAGNETIC, airbrakes_dir  # noqa: E402

from workbench.cli import main as cli  # noqa: E402
from workbench.problems.post2.rocket import local_en  # noqa: E402

#: (name, what it changes, metadata edit on a flight's ``launch_site`` table)
PERTURBATIONS = (
    ("temperature -7 K", lambda s: s.__setitem__("air_temperature_celsius", s["air_temperature_celsius"] - 7.0)),
    ("temperature +7 K", lambda s: s.__setitem__("air_temperature_celsius", s["air_temperature_celsius"] + 7.0)),
    ("pressure -5 hPa", lambda s: s.__setitem__("air_pressure_mb", s["air_pressure_mb"] - 5.0)),
    ("pressure +5 hPa", lambda s: s.__setitem__("air_pressure_mb", s["air_pressure_mb"] + 5.0)),
    ("wind +5 m/s", lambda s: s.__setitem__("wind_speed_kmh", s["wind_speed_kmh"] + 18.0)),
)


def _run(log: str, data: Path, meta_path: Path, out: Path) -> dict:
    """Import ``log`` with the metadata file ``meta_path`` and run it; its ``summary["rocket"]``."""
    dec, inc = SITE_MAGNETIC[log]
    imp = out / "flight"
    args = ["import", "airbrakes", str(data / log), "--metadata", str(meta_path), "--out", str(imp)]
    assert cli([*args, "--declination-deg", str(dec), "--inclination-deg", str(inc)]) == 0
    stem = Path(log).stem
    assert cli(["run", str(imp / f"{stem}.toml"), "--out", str(out / "rec"), "--quiet"]) == 0
    summary = json.loads((out / "rec" / f"{stem}.summary.json").read_text(encoding="utf-8"))
    return summary["rocket"]


def _moves(base: dict, other: dict) -> dict:
    """The apogee's and the landing's move [m] from ``base`` to ``other`` and in ``base``'s σ."""
    a0, a1 = base["apogee"], other["apogee"]
    l0, l1 = base["landing"], other["landing"]
    d = local_en(l1["lat_deg"], l1["lon_deg"], l0["lat_deg"], l0["lon_deg"])
    # the landing's move in its own 1σ ellipse (Mahalanobis distance along the move)
    e = l0["ellipse_1sigma"]
    th = math.radians(e["orientation_deg"])
    u = (d[0] * math.sin(th) + d[1] * math.cos(th), d[0] * math.cos(th) - d[1] * math.sin(th))
    return {
        "apogee_move_m": a1["altitude_m"] - a0["altitude_m"],
        "apogee_move_sigma": (a1["altitude_m"] - a0["altitude_m"]) / a0["sigma_m"],
        "landing_move_m": float(math.hypot(*d)),
        "landing_move_sigma": float(math.hypot(u[0] / e["semi_major_m"], u[1] / e["semi_minor_m"])),
    }


def main(argv=None) -> int:
    """Run every flight with its metadata and with each perturbation; print the table, write the JSON."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="keep the imports and recordings here (default: temporary)")
    ap.add_argument("--json", default=None, help="write the measurements here")
    a = ap.parse_args(argv)
    data, why = airbrakes_dir()
    if data is None:
        print(f"skipped: {why}", file=sys.stderr)
        return 2
    meta = json.loads((data / "metadata.json").read_text(encoding="utf-8"))
    t0 = time.perf_counter()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        base_dir = Path(a.out) if a.out else Path(tmp)
        for log in FLIGHTS:
            stem = Path(log).stem
            base = _run(log, data, data / "metadata.json", base_dir / stem / "given")
            row = {
                "apogee_m": base["apogee"]["altitude_m"],
                "apogee_sigma_m": base["apogee"]["sigma_m"],
                "landing_1sigma_m": [
                    base["landing"]["ellipse_1sigma"]["semi_major_m"],
                    base["landing"]["ellipse_1sigma"]["semi_minor_m"],
                ],
                "perturbed": {},
            }
            for k, (name, edit) in enumerate(PERTURBATIONS):
                m = copy.deepcopy(meta)
                edit(m[log]["launch_site"])
                path = base_dir / stem / f"meta_{k}.json"
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(m), encoding="utf-8")
                row["perturbed"][name] = _moves(base, _run(log, data, path, base_dir / stem / f"p{k}"))
            rows[stem] = row
    md = "| flight | apogee ± 1σ [m] | " + " | ".join(p[0] for p in PERTURBATIONS) + " |\n"
    md += "|---" * (2 + len(PERTURBATIONS)) + "|\n"
    for stem, r in rows.items():
        cells = [
            f"apogee {v['apogee_move_m']:+.1f} m ({v['apogee_move_sigma']:+.2f}σ), landing {v['landing_move_m']:.0f} m "
            f"({v['landing_move_sigma']:.2f}σ)"
            for v in r["perturbed"].values()
        ]
        md += f"| {stem} | {r['apogee_m']:.1f} ± {r['apogee_sigma_m']:.1f} | " + " | ".join(cells) + " |\n"
    print(md)
    wall = time.perf_counter() - t0
    print(f"wall {wall:.0f} s")
    if a.json:
        out = {
            "command": "python tests/benchmarks/bench_site_unknowns.py --json " + a.json,
            "generated": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "wall_s": wall,
            "flights": rows,
        }
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
