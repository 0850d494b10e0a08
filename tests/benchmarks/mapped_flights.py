"""The three real FIRM flights through the column-mapped importer (issue #27 item 1) against
``workbench import airbrakes``: each log imported with ``workbench import airbrakes`` and with
``workbench import csv`` and a mapping equal to the FIRM layout (``tests/support/firm_mapping.py``)
— with the phase letters and the magnetometer, with the phases detected, without the magnetometer,
and with neither — each run through the command line, and ``summary["rocket"]`` apogee and landing
printed as a markdown table with the differences in units of the airbrakes run's 1σ.

Run on demand from the repository root, with the data outside the repository::

    EDL_FLIGHT_DATA=/path/to/folder-with-airbrakes_firm .venv/bin/python tests/benchmarks/mapped_flights.py [--out DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "support"))

from firm_mapping import VARIANTS, compare, run_variant, table  # noqa: E402
from flight_data import FLIGHTS, airbrakes_dir  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=None, help="keep the imports and recordings here")
    args = p.parse_args(argv)
    data, why = airbrakes_dir()
    if data is None:
        print(f"skipped: {why}")
        return 0
    root = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="mapped_flights_"))
    rows = {}
    for log in FLIGHTS:
        ref = None
        for variant in VARIANTS:
            s = run_variant(log, data, root / Path(log).stem / variant.replace(", ", "_").replace(" ", "_"), variant)
            ref = ref or s
            rows[(log, variant)] = compare(ref, s)
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
