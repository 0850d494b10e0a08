"""The rocket results of the three real FIRM flights as a run reports them (issue #27 item 2): each log
imported and run through the command line (``workbench import airbrakes`` + ``workbench run --export``),
and ``summary["rocket"]`` printed as a markdown table beside the metadata's references (apogee, landed
coordinates) — the references are not in the summary: it is the reconstruction's alone.

Run on demand from the repository root, with the data outside the repository::

    EDL_FLIGHT_DATA=/path/to/folder-with-airbrakes_firm .venv/bin/python tests/benchmarks/rocket_results_flights.py \\
        [--out DIR] [--variant predicted|with_landing]

``--out`` keeps the imports, recordings (``DIR/<flight>/rec/*.rrd``), summaries and exports.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "support"))

from flight_data import FLIGHTS, SITE_MAGNETIC, airbrakes_dir  # noqa: E402

from workbench.cli import main as cli  # noqa: E402
from workbench.problems.post2.rocket import local_en  # noqa: E402
from workbench.problems.post2.rocket_results import format_lat_lon  # noqa: E402


def _one(log: str, data: Path, out: Path, variant: str) -> dict:
    dec, inc = SITE_MAGNETIC[log]
    imp = out / "flight"
    args = ["import", "airbrakes", str(data / log), "--metadata", str(data / "metadata.json"), "--out", str(imp)]
    assert cli([*args, "--declination-deg", str(dec), "--inclination-deg", str(inc)]) == 0
    stem = Path(log).stem + ("_landing" if variant == "with_landing" else "")
    assert cli(["run", str(imp / f"{stem}.toml"), "--out", str(out / "rec"), "--export", "--progress", "plain"]) == 0
    summary = json.loads((out / "rec" / f"{stem}.summary.json").read_text(encoding="utf-8"))
    meta = json.loads((imp / "flight.json").read_text(encoding="utf-8"))["metadata"]
    return {"summary": summary, "meta": meta}


def _table(rows: dict) -> str:
    md = (
        "| flight | apogee above pad ± 1σ [m] (t [s]) | metadata apogee [m] | max speed [m/s] (t [s]) "
        "| landing (3σ ellipse, major axis from N) | landed (metadata) | distance [m] | descent drogue / main [m/s] |\n"
        "|---|---|---|---|---|---|---|---|\n"
    )
    for log, r in rows.items():
        b, m = r["summary"]["rocket"], r["meta"]
        a, s, la = b["apogee"], b["max_speed"], b["landing"]
        e = la["ellipse_3sigma"]
        lat0, lon0 = m["launch_lat_deg"], m["launch_lon_deg"]
        d = local_en(la["lat_deg"], la["lon_deg"], lat0, lon0) - local_en(
            m["landed_lat_deg"], m["landed_lon_deg"], lat0, lon0
        )
        desc = " / ".join(
            f"{b['descent'][c]['rate_m_s']:.1f} ± {b['descent'][c]['sigma_m_s']:.1f}" if c in b["descent"] else "—"
            for c in ("drogue", "main")
        )
        md += (
            f"| {Path(log).stem} | {a['altitude_m']:.1f} ± {a['sigma_m']:.1f} ({a['t_s']:.2f}) | {m['apogee']:.1f} "
            f"| {s['speed_m_s']:.1f} ± {s['sigma_m_s']:.1f} ({s['t_s']:.2f}) "
            f"| {format_lat_lon(la['lat_deg'], la['lon_deg'])} ({e['semi_major_m']:.0f} × {e['semi_minor_m']:.0f} m, "
            f"{la['ellipse_1sigma']['orientation_deg']:.0f}°) "
            f"| {format_lat_lon(m['landed_lat_deg'], m['landed_lon_deg'])} | {math.hypot(*d):.0f} | {desc} |\n"
        )
    return md


def main(argv=None) -> int:
    """Import and run the three flights; print the table (and the headlines)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="keep the outputs here (default: a temporary folder)")
    ap.add_argument("--variant", choices=("predicted", "with_landing"), default="predicted")
    a = ap.parse_args(argv)
    data, why = airbrakes_dir()
    if data is None:
        print(f"skipped: {why}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(a.out) if a.out else Path(tmp)
        rows = {log: _one(log, data, base / Path(log).stem, a.variant) for log in FLIGHTS}
        print(_table(rows))
        for log, r in rows.items():
            print(f"- {Path(log).stem}: {r['summary']['headline']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
