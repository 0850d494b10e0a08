"""A column mapping file (``workbench import csv``) equal to the AirbrakesV2 FIRM layout that
``workbench import airbrakes`` reads (its built-in mapping ``airbrakes.FIRM_LAYOUT`` written out): the
log's own columns and units, its phase letters (or none: the phases detected), its flight computer's
solution, with or without its magnetometer, and the site, rocket and references copied from the
flight's ``metadata.json`` entry.  Shared by the slow test and the table script of the
column-mapped importer on the real flights (:func:`run_variant`, :func:`compare`, :func:`table`)."""

from __future__ import annotations

import json
from pathlib import Path

from flight_data import SITE_MAGNETIC

from workbench.cli import main as cli
from workbench.problems.post2.importers.airbrakes import FIRM_LAYOUT

#: the 16 compass points of the metadata's wind direction -> deg clockwise from north
COMPASS = {d: 22.5 * i for i, d in enumerate("N NNE NE ENE E ESE SE SSE S SSW SW WSW W WNW NW NNW".split())}


def firm_mapping(
    log: Path,
    metadata: Path,
    dst: Path,
    *,
    declination_deg: float,
    inclination_deg: float | None,
    magnetometer: bool = True,
    phase_column: bool = True,
) -> Path:
    """Write ``dst/<log stem>.toml``: the mapping of the FIRM log ``log`` (absolute path) with the site
    and rocket of its ``metadata`` entry; returns it."""
    m = json.loads(Path(metadata).read_text(encoding="utf-8"))[Path(log).name]
    site, rocket, fd = m["launch_site"], m["rocket"], m["flight_data"]
    lines = [
        "[flight]",
        f'name = "{Path(log).stem}"',
        f'date = "{m.get("date", "")}"',
        "",
        "[site]",
        f"lat_deg = {site['launch_coordinates']['latitude']}",
        f"lon_deg = {site['launch_coordinates']['longitude']}",
        f"qnh_hpa = {site['air_pressure_mb']}",
        f"temperature_degC = {site['air_temperature_celsius']}",
        f"wind_speed_m_s = {site['wind_speed_kmh'] / 3.6}",
        f"wind_from_deg = {COMPASS[site['wind_direction'].strip().upper()]}",
        f"launch_rod_angle_deg = {site['launch_rod_angle']}",
    ]
    if magnetometer:
        lines.append(f"declination_deg = {declination_deg}")
        if inclination_deg is not None:
            lines.append(f"inclination_deg = {inclination_deg}")
    lines += [
        "",
        "[rocket]",
        f"dry_mass_kg = {rocket['rocket_dry_mass_kg']}",
        f"cd = {rocket['rocket_Cd']}",
        f"ref_area_m2 = {rocket['rocket_cross_sectional_area_m2']}",
        *([f'motor = "{rocket["motor"]}"'] if rocket.get("motor") else []),
        "",
        "[reference]",
        f"apogee_m = {fd['apogee_meters']}",
        f"landed_lat_deg = {fd['landed_coordinates']['latitude']}",
        f"landed_lon_deg = {fd['landed_coordinates']['longitude']}",
        "",
    ]
    layout = {k: v for k, v in FIRM_LAYOUT.items() if k != "files"}
    if not magnetometer:
        del layout["magnetometer"]
    if not phase_column:
        del layout["phases"]
    lines += ["", "[files.firm]", f"path = {json.dumps(str(Path(log).resolve()))}"]
    lines += [f"{k} = {json.dumps(v)}" for k, v in FIRM_LAYOUT["files"]["firm"].items() if k != "path"]
    for table, keys in layout.items():
        lines += ["", f"[{table}]", *(f"{k} = {json.dumps(v)}" for k, v in keys.items())]
    dst = Path(dst)
    dst.mkdir(parents=True, exist_ok=True)
    path = dst / f"{Path(log).stem}.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


#: the imports compared: name -> (magnetometer, phase column); None: ``workbench import airbrakes``
VARIANTS = {
    "airbrakes": None,
    "csv": (True, True),
    "csv, phases detected": (True, False),
    "csv, no magnetometer": (False, True),
    "csv, no magnetometer, phases detected": (False, False),
}


def run_variant(log: str, data: Path, out: Path, variant: str) -> dict:
    """Import ``log`` as ``variant`` (:data:`VARIANTS`) into ``out`` and run it; the summary."""
    dec, inc = SITE_MAGNETIC[log]
    imp, stem = out / "flight", Path(log).stem
    how = VARIANTS[variant]
    if how is None:
        args = ["import", "airbrakes", str(data / log), "--metadata", str(data / "metadata.json"), "--out", str(imp)]
        assert cli([*args, "--declination-deg", str(dec), "--inclination-deg", str(inc)]) == 0
    else:
        mp = firm_mapping(
            data / log,
            data / "metadata.json",
            out / "mapping",
            declination_deg=dec,
            inclination_deg=inc,
            magnetometer=how[0],
            phase_column=how[1],
        )
        assert cli(["import", "csv", "--mapping", str(mp), "--out", str(imp)]) == 0
    assert cli(["run", str(imp / f"{stem}.toml"), "--out", str(out / "rec"), "--quiet"]) == 0
    return json.loads((out / "rec" / f"{stem}.summary.json").read_text(encoding="utf-8"))


def compare(ref: dict, s: dict) -> dict:
    """Apogee and landing of the summary ``s`` against the airbrakes summary ``ref``: the values, the
    differences [m] and those in units of ``ref``'s 1σ (landing: east and north separately)."""
    a, a0 = s["rocket"]["apogee"], ref["rocket"]["apogee"]
    la, la0 = s["rocket"]["landing"], ref["rocket"]["landing"]
    de, dn = la["east_m"] - la0["east_m"], la["north_m"] - la0["north_m"]
    return {
        "apogee_m": a["altitude_m"],
        "apogee_sigma_m": a["sigma_m"],
        "d_apogee_sigma": (a["altitude_m"] - a0["altitude_m"]) / a0["sigma_m"],
        "landing_en_m": (la["east_m"], la["north_m"]),
        "landing_sigma_en_m": (la["sigma_east_m"], la["sigma_north_m"]),
        "d_landing_m": (de, dn),
        "d_landing_sigma": (de / la0["sigma_east_m"], dn / la0["sigma_north_m"]),
        "touchdown": la["touchdown"],
        "t_landing_s": la.get("t_s"),
        "heading_trusted": la["heading_trusted"],
    }


def table(rows: dict) -> str:
    """Markdown table of {(flight, variant): :func:`compare`}."""
    md = (
        "| flight | import | apogee ± 1σ [m] | Δ apogee [σ] | landing E, N ± 1σ [m] | Δ landing E, N [m] | "
        "Δ landing [σ] | t landing [s] | heading trusted |\n|---|---|---|---|---|---|---|---|---|\n"
    )
    for (log, variant), c in rows.items():
        (e, n), (se, sn) = c["landing_en_m"], c["landing_sigma_en_m"]
        (de, dn), (ze, zn) = c["d_landing_m"], c["d_landing_sigma"]
        md += (
            f"| {Path(log).stem} | {variant} | {c['apogee_m']:.1f} ± {c['apogee_sigma_m']:.1f} | "
            f"{c['d_apogee_sigma']:+.2f} | {e:.0f} ± {se:.0f}, {n:.0f} ± {sn:.0f} | {de:+.0f}, {dn:+.0f} | "
            f"{ze:+.2f}, {zn:+.2f} | {c['t_landing_s']:.1f} | {'yes' if c['heading_trusted'] else 'no'} |\n"
        )
    return md
