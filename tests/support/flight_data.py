"""Where the real flight data live (never in the repository) and the per-site inputs of their import.

``EDL_FLIGHT_DATA`` names a folder holding ``airbrakes_firm/`` (the three FIRM logs, their
``metadata.json`` and LICENSE); tests and benchmarks that need the full data skip (or stop) with a
clear reason when it is unset or incomplete.

The magnetic declination and inclination at the three sites are not in the metadata; the values
below are approximate World Magnetic Model 2025 values at the launch coordinates (NOAA NCEI
calculator, rounded to 0.5 deg): an input of the import, stated here so a reader can change them.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV = "EDL_FLIGHT_DATA"
FLIGHTS = ("jackpot_launch_1.csv", "jackpot_launch_3.csv", "jackpot_launch_4.csv")

#: log -> (declination east + [deg], inclination down + [deg]) at the launch site
SITE_MAGNETIC = {
    "jackpot_launch_1.csv": (-10.5, 64.0),  # Bayboro, NC
    "jackpot_launch_3.csv": (-9.0, 66.0),  # Monterey, VA
    "jackpot_launch_4.csv": (-4.0, 62.0),  # Huntsville, AL
}


def airbrakes_dir() -> tuple[Path | None, str]:
    """(the ``airbrakes_firm`` folder, "") if ``$EDL_FLIGHT_DATA`` holds it complete, else (None, reason)."""
    root = os.environ.get(ENV)
    if not root:
        return None, f"${ENV} is not set (a folder containing airbrakes_firm/ with the FIRM logs)"
    d = Path(root) / "airbrakes_firm"
    missing = [f for f in (*FLIGHTS, "metadata.json") if not (d / f).is_file()]
    if missing:
        return None, f"${ENV}={root}: {d} lacks {', '.join(missing)}"
    return d, ""
