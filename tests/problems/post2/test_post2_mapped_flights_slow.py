"""The three real FIRM flights through ``workbench import csv`` with a mapping equal to the FIRM layout
(issue #27 item 1), when the data are present (``EDL_FLIGHT_DATA``; skipped with the reason otherwise):
the same apogee and landing as ``workbench import airbrakes`` within the airbrakes run's 1σ — with the
phase letters (identical: the same code path), with the phases detected from the data, and without
the magnetometer (apogee only: the pad heading is then an untrusted prior and the landing turns about
the pad with it).  The table is printed by ``tests/benchmarks/mapped_flights.py``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from firm_mapping import compare, run_variant, table
from flight_data import FLIGHTS, airbrakes_dir

from workbench.problems.post2.rocket import local_en

DATA, WHY = airbrakes_dir()

pytestmark = [pytest.mark.slow, pytest.mark.skipif(DATA is None, reason=WHY)]


@pytest.mark.parametrize("log", FLIGHTS)
def test_mapped_import_of_a_real_flight_agrees_with_the_airbrakes_import(log, tmp_path):
    ref = run_variant(log, DATA, tmp_path / "a", "airbrakes")
    rows, summaries = {}, {}
    for i, variant in enumerate(("csv", "csv, phases detected", "csv, no magnetometer")):
        summaries[variant] = run_variant(log, DATA, tmp_path / str(i), variant)
        rows[variant] = compare(ref, summaries[variant])
    print(table({(log, v): c for v, c in rows.items()}))
    for variant, c in rows.items():
        assert abs(c["d_apogee_sigma"]) <= 1.0, (variant, c)
        assert c["touchdown"], (variant, c)
    for variant in ("csv", "csv, phases detected"):
        assert rows[variant]["heading_trusted"]
        assert all(abs(z) <= 1.0 for z in rows[variant]["d_landing_sigma"]), (variant, rows[variant])
    assert rows["csv"]["d_apogee_sigma"] == 0.0 and rows["csv"]["d_landing_m"] == (0.0, 0.0)
    assert not rows["csv, no magnetometer"]["heading_trusted"]
    # without the magnetometer the landing is the heading ring's: the landed coordinates (metadata,
    # "within 1-2 m") lie within 3σ of the ring's radius about the wind drift (the linearised ellipse
    # put flight 1's at 4.3σ)
    meta = json.loads((DATA / "metadata.json").read_text(encoding="utf-8"))[log]
    pad, landed = meta["launch_site"]["launch_coordinates"], meta["flight_data"]["landed_coordinates"]
    la = summaries["csv, no magnetometer"]["rocket"]["landing"]
    ring = la["heading_ring"]
    en = local_en(landed["latitude"], landed["longitude"], pad["latitude"], pad["longitude"])
    r = float(np.hypot(*(np.asarray(en) - ring["centre_en_m"])))
    sig = max(la["ellipse_1sigma"]["semi_major_m"], 1.0)
    assert ring["whole_ring"] and abs(r - ring["radius_m"]) <= 3.0 * sig, (log, r, ring, sig)
    assert math.hypot(en[0] - la["east_m"], en[1] - la["north_m"]) <= ring["max_miss_3sigma_m"]
