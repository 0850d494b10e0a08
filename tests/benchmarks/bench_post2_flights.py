"""Real rocket flights (issue #9, case 5): import, reconstruction and scores of the three FIRM flights.

Run on demand from the repository root, with the data outside the repository::

    EDL_FLIGHT_DATA=/path/to/folder-with-airbrakes_firm .venv/bin/python tests/benchmarks/bench_post2_flights.py \\
        [--json docs/results/bench_post2_flights.json] [--keep DIR]

Per flight, two reconstructions of the same import (``workbench import airbrakes``):

* ``predicted`` — the problem file as imported: the boost integrated from the IMU, then the post2
  3-DOF EKF + RTS over coast and descent with the barometer and |specific force|; the landing point
  is a prediction (nothing horizontal is observed after the boost) scored against the landed
  coordinates with its own 3σ;
* ``with_landing`` — the ``_landing`` variant that also observes the landed coordinates: the winds
  under the parachutes it needs to get there.

Scores: apogee vs ``metadata.json`` (m, %; also the standard-day pressure altitude of the same
apogee, as an altimeter that assumes 15 °C reads it), landing error vs its 3σ, altitude vs the flight
computer's solution (``altitude_vs_flight_computer``: raw, its altitude as logged; ``like_for_like``, its
standard-day altitude made geometric above the pad in the site atmosphere, with the altimeter
convention measured from its log in ``flight_computer_altimeter``; ``barometer_scale``, ours as its
altimeter would read it — nearly the barometer against itself), the gyro attitude vs the flight
computer's quaternion (frame-free: tilt and rotation since the pad), and the estimated coast drag
multiplier, barometer offset, drogue and main drag areas and winds.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "support"))

from bench_json import write_benchmark_json  # noqa: E402 (beside this script)
from flight_data import FLIGHTS, SITE_MAGNETIC, airbrakes_dir  # noqa: E402

from workbench.io.scenario import load_scenario  # noqa: E402
from workbench.problems.post2 import rocket  # noqa: E402
from workbench.problems.post2.importers.airbrakes import import_flight  # noqa: E402
from workbench.problems.post2.problem import Post2Problem  # noqa: E402


def _one(log: str, data: Path, out: Path) -> dict:
    dec, inc = SITE_MAGNETIC[log]
    t0 = time.perf_counter()
    toml = import_flight(data / log, data / "metadata.json", out, declination_deg=dec, inclination_deg=inc)
    t_imp = time.perf_counter() - t0
    rec = {"declination_deg": dec, "inclination_deg": inc, "import_s": t_imp}
    for variant, path in (("predicted", toml), ("with_landing", toml.with_name(toml.stem + "_landing.toml"))):
        t0 = time.perf_counter()
        _, s = rocket.run_flight(Post2Problem().settings(load_scenario(path)))
        s["wall_s"] = time.perf_counter() - t0
        rec[variant] = s
    fl = json.loads((out / "flight.json").read_text(encoding="utf-8"))
    keys = (
        "t_start_s",
        "t_apogee_letter_s",
        "t_ejection_s",
        "t_main_s",
        "t_end_s",
        "rows",
        "gaps",
        "initial_ca_multiplier",
    )
    rec["import"] = {k: fl[k] for k in keys}
    rec["import"]["repeated_rows_dropped"] = fl["repeated_rows_dropped"]
    rec["pad"] = fl["pad"]
    rec["burnout"] = fl["burnout"]
    return rec


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", default=str(ROOT / "docs" / "results" / "bench_post2_flights.json"))
    ap.add_argument("--keep", default=None, help="keep the imported folders here")
    args = ap.parse_args(argv)
    data, why = airbrakes_dir()
    if data is None:
        print(f"bench_post2_flights: {why}", file=sys.stderr)
        return 2
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(args.keep) if args.keep else Path(tmp)
        for log in FLIGHTS:
            r = _one(log, data, base / Path(log).stem)
            results[Path(log).stem] = r
            p, w = r["predicted"], r["with_landing"]
            print(
                f"{log}: apogee {p['apogee']['reconstructed_m']:.1f} m vs {p['apogee']['metadata_m']:.1f} "
                f"({p['apogee']['error_percent']:+.2f} %); landing error {p['landing']['error_m']:.0f} m, "
                f"inside 3σ {p['landing']['inside_3sigma']}; altitude vs the flight computer RMS "
                f"{p['altitude_vs_flight_computer']['rms_after_burnout_transient_m']:.1f} m raw, "
                f"{p['altitude_vs_flight_computer']['like_for_like']['rms_after_burnout_transient_m']:.1f} m like for "
                f"like; wind with landing {w['parameters']['wind']['value']}",
                flush=True,
            )
    write_benchmark_json(args.json, __file__, {"flights": results}, argv)
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
