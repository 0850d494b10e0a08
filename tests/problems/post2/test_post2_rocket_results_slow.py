"""The rocket results of the three real FIRM flights (issue #27 item 2), imported and run through the
command line, when the data are present (``EDL_FLIGHT_DATA``; skipped with the reason otherwise).
The table is printed by ``tests/benchmarks/rocket_results_flights.py``; asserted here: the summary's
apogee is the scored one and within 5 % of the metadata's, burnout < apogee < landing as key moments
on a flight that touched down, both parachutes' descent rates (the drogue's faster than the main's),
and the landed coordinates inside the landing point's 3σ ellipse."""

from __future__ import annotations

import json

import numpy as np
import pytest
from flight_data import FLIGHTS, SITE_MAGNETIC, airbrakes_dir

from workbench.cli import main
from workbench.estimation.consistency import chi2_ppf
from workbench.problems.post2.rocket import local_en

DATA, WHY = airbrakes_dir()

pytestmark = [pytest.mark.slow, pytest.mark.skipif(DATA is None, reason=WHY)]


@pytest.mark.parametrize("log", FLIGHTS)
def test_rocket_results_of_a_real_flight(log, tmp_path):
    dec, inc = SITE_MAGNETIC[log]
    args = ["import", "airbrakes", str(DATA / log), "--metadata", str(DATA / "metadata.json")]
    assert (
        main([*args, "--out", str(tmp_path / "f"), "--declination-deg", str(dec), "--inclination-deg", str(inc)]) == 0
    )
    stem = log.removesuffix(".csv")
    assert main(["run", str(tmp_path / "f" / f"{stem}.toml"), "--out", str(tmp_path / "r"), "--quiet"]) == 0
    s = json.loads((tmp_path / "r" / f"{stem}.summary.json").read_text(encoding="utf-8"))
    meta = json.loads((tmp_path / "f" / "flight.json").read_text(encoding="utf-8"))["metadata"]
    b = s["rocket"]
    assert abs(b["apogee"]["altitude_m"] - meta["apogee"]) < 0.05 * meta["apogee"]
    t = {m["name"]: m["t_s"] for m in s["key_moments"]}
    assert b["landing"]["touchdown"] and t["burnout"] < t["apogee"] < t["landing"]
    d = b["descent"]
    assert 15.0 < d["drogue"]["rate_m_s"] < 40.0 and 2.0 < d["main"]["rate_m_s"] < 12.0
    assert d["drogue"]["sigma_m_s"] > 0.0 and d["main"]["sigma_m_s"] > 0.0
    # the landed coordinates inside the 3σ ellipse of the summary (same metric as score_flight's)
    la = b["landing"]
    lat0, lon0 = meta["launch_lat_deg"], meta["launch_lon_deg"]
    err = local_en(la["lat_deg"], la["lon_deg"], lat0, lon0) - local_en(
        meta["landed_lat_deg"], meta["landed_lon_deg"], lat0, lon0
    )
    e = la["ellipse_1sigma"]
    o = np.radians(e["orientation_deg"])
    u = np.array([np.sin(o), np.cos(o)])  # major axis (east, north)
    v = np.array([u[1], -u[0]])
    d2 = (err @ u / e["semi_major_m"]) ** 2 + (err @ v / e["semi_minor_m"]) ** 2
    assert d2 <= chi2_ppf(0.9973, 2)
    assert s["headline"].startswith("apogee ") and "landing " in s["headline"]
