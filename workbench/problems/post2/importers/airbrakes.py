"""Importer of the AirbrakesV2 "FIRM" flight-computer logs (NCSU High-Powered Rocketry Club, MIT
licence) into the workbench's telemetry files and a post2 problem file.

The log (one CSV per flight, ~91 Hz, one row per packet) and its ``metadata.json`` are described
in ``workbench/io/FORMATS.md`` ("Rocket flight logs").  What the importer does:

1. :func:`read_log` — the generic column-mapped reader of ``workbench import csv``
   (:mod:`workbench.problems.post2.importers.mapped`) with the FIRM layout as its built-in mapping
   (:data:`FIRM_LAYOUT`): every problem located by file, column and data row (missing column, text or
   NaN in a number, backwards or repeated time, unknown phase letter), converted to SI (g → m/s² with
   g0 = 9.80665, deg/s → rad/s, °C → K, µT → T), the flight computer's own solution (altitude,
   vertical velocity, quaternion scalar-first → scalar-last) kept apart as a *reference*;
2. :func:`find_gaps` — lists every step longer than ``gap_factor`` × the median step (reported in
   the import summary and in ``events.csv``; nothing is interpolated: an averaging block never
   spans a gap, and a gap inside the boost is refused because the IMU cannot be integrated across it);
3. :func:`read_metadata` — the flight's entry of ``metadata.json`` (mass, Cd, area, site weather,
   launch/landed coordinates, apogee), validated against :data:`METADATA_SCHEMA` (an unknown,
   missing, mistyped or out-of-range field a located :class:`~workbench.io.scenario.ScenarioError`);
4. :func:`import_flight` — :func:`~workbench.problems.post2.importers.flightlog.import_log`, shared
   with ``import csv``: the boost integrated from the IMU (:mod:`workbench.problems.post2.rocket`),
   the coast/descent observation files (pressure, |specific force|, 10 Hz block means with their
   weights vs time), the reference files and ``<flight>.toml``, a post2 problem file that
   ``workbench run`` reconstructs.  What stays FIRM's own is its ``metadata.json`` (:func:`read_metadata`).
"""

from __future__ import annotations

import difflib
import os
from pathlib import Path

import numpy as np

from workbench.io.scenario import ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, read_json
from workbench.problems.post2.importers.flightlog import (
    PHASES,
    FlightLog,
    FlightMetadata,
    Gap,
    add_common_arguments,
    block_means,
    check_rates,
    check_units,
    find_gaps,
    import_log,
)
from workbench.problems.post2.importers.mapped import Mapping, from_data, read_mapped

__all__ = [
    "HELP",
    "add_arguments",
    "run",
    "PHASES",
    "FIRM_LAYOUT",
    "firm_layout",
    "FlightLog",
    "Gap",
    "FlightMetadata",
    "METADATA_SCHEMA",
    "file_schemas",
    "read_log",
    "find_gaps",
    "block_means",
    "read_metadata",
    "import_flight",
    "import_log",
    "check_units",
    "check_rates",
]

#: the FIRM log's layout as a column mapping of the generic reader
#: (:mod:`workbench.problems.post2.importers.mapped`, ``workbench import csv``): one file, its own
#: column names and units, its phase letters and its flight computer's solution
FIRM_LAYOUT: dict = {
    "files": {"firm": {"path": "", "time": "timestamp_seconds", "time_unit": "s"}},
    "accelerometer": {"file": "firm", "unit": "g", **{f"body_{c}": f"raw_acceleration_{c}_gs" for c in "xyz"}},
    "gyro": {"file": "firm", "unit": "deg/s", **{f"body_{c}": f"raw_angular_rate_{c}_deg_per_s" for c in "xyz"}},
    "magnetometer": {"file": "firm", "unit": "uT", **{f"body_{c}": f"magnetic_field_{c}_microteslas" for c in "xyz"}},
    "barometer": {"file": "firm", "column": "pressure_pascals", "unit": "Pa"},
    "temperature": {"file": "firm", "column": "temperature_celsius", "unit": "degC"},
    "phases": {"file": "firm", "column": "state_letter", **{v: k for k, v in PHASES.items()}},
    "flight_computer": {
        "file": "firm",
        "altitude": "est_position_z_meters",
        "vertical_speed": "est_velocity_z_meters_per_s",
        **{f"quaternion_{c}": f"est_quaternion_{c}" for c in "wxyz"},
    },
}


def firm_layout(path: str | os.PathLike) -> Mapping:
    """The :data:`FIRM_LAYOUT` mapping of the log ``path`` (validated like a mapping file)."""
    path = Path(path).resolve()
    data = {**FIRM_LAYOUT, "files": {"firm": {**FIRM_LAYOUT["files"]["firm"], "path": str(path)}}}
    return from_data(data, path, layout_only=True)


def read_log(path: str | os.PathLike, gap_factor: float = 3.0) -> FlightLog:
    """Read a FIRM log CSV into SI: the generic reader
    (:func:`workbench.problems.post2.importers.mapped.read_mapped`) with the built-in mapping
    :data:`FIRM_LAYOUT` (g → m/s² with g0 = 9.80665, deg/s → rad/s, °C → K, µT → T; the flight
    computer's quaternion scalar-first → scalar-last, kept as a reference); other columns ignored.

    Raises :class:`~workbench.io.telemetry.TelemetryError` locating every problem (file, column,
    1-based data row and file line; :func:`workbench.io.columns.read_columns`): a missing column, an
    empty/non-numeric/non-finite cell, a wrong field count, a time not strictly after the previous
    row's (a row repeating the previous row's time and every value is a packet logged twice: dropped
    and counted), a phase letter not in :data:`PHASES`, a quaternion whose norm is not 1 ± 0.01, values
    not in the columns' units (:func:`check_units`, :func:`check_rates`).
    """
    path = Path(path)
    t, q, letters, info = read_mapped(firm_layout(path), needed_by="a FIRM log needs it")
    fname = str(path)
    rows = np.arange(t.size)
    check_units(fname, t, letters, q["f_B"], rows)
    check_rates(fname, q["w_B"], rows)
    return FlightLog(
        path,
        t,
        letters,
        q["f_B"],
        q["w_B"],
        q["mag_B"],
        q["pressure"],
        q["temperature"],
        q["ref_h"],
        q["ref_vz"],
        q["ref_q"],
        find_gaps(t, letters, gap_factor),
        info["files"]["firm"]["repeated_rows_dropped"],
    )


_COMPASS = {d: 22.5 * i for i, d in enumerate("N NNE NE ENE E ESE SE SSE S SSW SW WSW W WNW NW NNW".split())}

_F, _S = "float", "str"


def _coordinates(table: str, what: str) -> Table:
    return Table(
        table,
        f"{what} (WGS-84 geodetic, decimal degrees)",
        (
            Key("latitude", _F, REQUIRED, "deg", "latitude, north positive", ge=-90.0, le=90.0),
            Key("longitude", _F, REQUIRED, "deg", "longitude, east positive (0 … 360 accepted)", ge=-180.0, lt=360.0),
        ),
    )


#: One flight's entry of ``metadata.json`` (the entry named as the log, e.g. ``jackpot_launch_1.csv``).
#: Fields marked "not used" are documented so a misspelling of a used one is caught, not ignored.
METADATA_SCHEMA = Schema(
    "airbrakes_metadata",
    "AirbrakesV2 flight-log metadata",
    (
        Table(
            "",
            "the flight's entry (`metadata.json` maps each log's file name to one)",
            (
                Key("date", _S, "", meaning="launch date and time, ISO 8601 (shown in the problem file)"),
                Key("flight_description", _S, "", meaning="what happened on the flight (shown in the problem file)"),
            ),
        ),
        Table(
            "rocket",
            "the rocket after burnout",
            (
                Key("rocket_dry_mass_kg", _F, REQUIRED, "kg", "dry mass: the coast and descent mass", gt=0.0),
                Key("rocket_Cd", _F, REQUIRED, "1", "drag coefficient on the cross-sectional area (coast)", gt=0.0),
                Key("rocket_cross_sectional_area_m2", _F, REQUIRED, "m^2", "aerodynamic reference area", gt=0.0),
                Key("rocket_diameter_m", _F, None, "m", "body diameter (not used)", gt=0.0),
                Key("rocket_moment_of_inertia_kg_m2", _F, None, "kg m^2", "moment of inertia (not used)", gt=0.0),
                Key("rocket_stab_margin_cal", _F, None, "cal", "static stability margin (not used)"),
                Key("rocket_cl_a", _F, None, "1/rad", "lift-curve slope (not used)"),
                Key(
                    "motor",
                    _S,
                    None,
                    meaning="motor designation (e.g. L1390G-P: its impulse class and average thrust check the mass)",
                ),
            ),
        ),
        Table(
            "launch_site",
            "the site and its weather at launch",
            (
                Key("air_temperature_celsius", _F, REQUIRED, "degC", "air temperature at the site", ge=-60.0, le=60.0),
                Key(
                    "air_pressure_mb",
                    _F,
                    REQUIRED,
                    "mb",
                    "reported air pressure, read as QNH (reduced to sea level; 1 mb = 100 Pa)",
                    ge=800.0,
                    le=1100.0,
                ),
                Key("wind_speed_kmh", _F, REQUIRED, "km/h", "surface wind speed", ge=0.0, le=200.0),
                Key(
                    "wind_direction",
                    _S,
                    REQUIRED,
                    meaning="where the wind blows from: a 16-point compass point (N, NNE, … NNW; any case)",
                ),
                Key("launch_rod_angle", _F, REQUIRED, "deg", "launch rod angle from the vertical", ge=0.0, lt=90.0),
                Key("location", _S, None, meaning="site name (not used)"),
                Key("launch_rod_length_ft", _F, None, "ft", "launch rod length (not used)", gt=0.0),
            ),
        ),
        _coordinates("launch_site.launch_coordinates", "the pad"),
        Table(
            "ins_details",
            "the flight computer (not used)",
            (
                Key("ins_model", _S, None, meaning="flight computer model"),
                Key("data_packet_frequency", _F, None, "Hz", "nominal packet rate", gt=0.0),
            ),
        ),
        Table(
            "flight_data",
            "what the team measured of the flight",
            (
                Key("apogee_meters", _F, REQUIRED, "m", "apogee above the pad (scored against)", gt=0.0),
                Key("log_buffer_index", "int", None, meaning="flight computer buffer index (not used)"),
                Key("landed_coordinates_precision", _S, None, meaning="how the landing point was found (not used)"),
                Key("flight_length_seconds", _F, None, "s", "flight duration (not used)", gt=0.0),
                Key("target_apogee_meters", _F, None, "m", "the air brakes' target apogee (not used)", gt=0.0),
            ),
        ),
        _coordinates("flight_data.landed_coordinates", "the landing point (observed by the `_landing` variant)"),
    ),
    noun="flight-log metadata file",
    intro="Keys of one flight's entry in an AirbrakesV2 `metadata.json`",
)

#: the schemas of the files this importer reads (listed in FORMATS.md by the registry)
file_schemas = (METADATA_SCHEMA,)


def read_metadata(path: str | os.PathLike, flight: str) -> FlightMetadata:
    """The entry ``flight`` (the log's file name, e.g. ``jackpot_launch_1.csv``) of ``metadata.json``,
    validated against :data:`METADATA_SCHEMA`, in SI (K, Pa, m/s, deg).

    A missing entry, an unknown, missing or mistyped field or a value outside its bounds is a
    :class:`~workbench.io.scenario.ScenarioError` naming the file and the JSON path (with a "did you
    mean" for an unknown key, the bound for a value out of range)."""
    path = Path(path)
    data = read_json(path)
    if not isinstance(data, dict):
        raise ScenarioError(path, None, f"expected a JSON object of flights, got {type(data).__name__}")
    if flight not in data:
        known = [k for k in data if not k.startswith("$")]
        close = difflib.get_close_matches(flight, known, n=1, cutoff=0.5)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ScenarioError(path, flight, f"no entry for {flight!r}{hint} (entries: {', '.join(known)})")
    m = METADATA_SCHEMA.validate(data[flight], path, where=flight)
    site, rocket, fd = m["launch_site"], m["rocket"], m["flight_data"]
    wdir = site["wind_direction"].strip().upper()
    if wdir not in _COMPASS:
        raise ScenarioError(
            path, f"{flight}.launch_site.wind_direction", f"{wdir!r} is not a compass point ({', '.join(_COMPASS)})"
        )
    return FlightMetadata(
        flight,
        rocket["rocket_dry_mass_kg"],
        rocket["rocket_Cd"],
        rocket["rocket_cross_sectional_area_m2"],
        site["air_temperature_celsius"] + 273.15,
        site["air_pressure_mb"] * 100.0,
        site["wind_speed_kmh"] / 3.6,
        _COMPASS[wdir],
        site["launch_coordinates"]["latitude"],
        site["launch_coordinates"]["longitude"],
        fd["landed_coordinates"]["latitude"],
        fd["landed_coordinates"]["longitude"],
        fd["apogee_meters"],
        site["launch_rod_angle"],
        m["date"],
        m["flight_description"],
        rocket.get("motor"),
    )


def import_flight(
    log_path: str | os.PathLike,
    metadata_path: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    declination_deg: float = 0.0,
    inclination_deg: float | None = None,
    obs_rate_hz: float = 10.0,
    name: str | None = None,
    t_end_s: float | None = None,
    flight: str | None = None,
    allow_unhealthy: bool = False,
) -> Path:
    """Import one flight: writes telemetry CSVs, ``flight.json``, ``<name>.toml`` and the variant
    ``<name>_landing.toml`` that also observes the landed coordinates into ``out_dir``.

    ``declination_deg`` magnetic declination at the site (east positive; used for the pad heading);
    ``inclination_deg`` the site's magnetic dip (the magnetometer's heading is trusted only if its
    dip on the pad agrees within 10°; None: unchecked); ``obs_rate_hz`` rate of the block-mean
    observations; ``t_end_s`` [s after launch] ends the
    reconstruction early (default: touchdown, the first ``L`` row).  Returns the problem file.

    The physics cross-checks of :mod:`workbench.problems.post2.rocket_checks` run before anything is
    written; an ERROR among them raises :class:`~workbench.estimation.health.UnhealthyError` unless
    ``allow_unhealthy`` (then they are kept in ``flight.json`` and join the run's health verdict).
    The files are written into a temporary folder moved into place at the end.
    """
    log = read_log(log_path)
    meta = read_metadata(metadata_path, flight or Path(log_path).name)
    return import_log(
        log,
        meta,
        out_dir,
        name=name or Path(log_path).stem,
        declination_deg=declination_deg,
        inclination_deg=inclination_deg,
        obs_rate_hz=obs_rate_hz,
        t_end_s=t_end_s,
        allow_unhealthy=allow_unhealthy,
    )


HELP = "AirbrakesV2 FIRM flight log (CSV + metadata.json) -> telemetry + post2 problem file"


def add_arguments(parser) -> None:
    """The ``workbench import airbrakes`` options (an ``argparse`` parser)."""
    parser.add_argument("log", help="the flight's CSV log (e.g. jackpot_launch_1.csv)")
    parser.add_argument("--metadata", required=True, help="metadata.json holding the flight's entry")
    parser.add_argument("--out", required=True, help="output folder (telemetry CSVs, flight.json, problem files)")
    parser.add_argument("--declination-deg", type=float, default=0.0, help="magnetic declination at the site, east +")
    parser.add_argument(
        "--inclination-deg",
        type=float,
        default=None,
        help="magnetic dip at the site (down +): the magnetometer heading is trusted only if the pad agrees",
    )
    add_common_arguments(parser)
    parser.add_argument("--name", default=None, help="problem name (default: the log's file stem)")
    parser.add_argument("--flight", default=None, help="the metadata entry (default: the log's file name)")


def run(args) -> Path:
    """Run the import from parsed ``args`` (:func:`add_arguments`); returns the problem file."""
    return import_flight(
        args.log,
        args.metadata,
        args.out,
        declination_deg=args.declination_deg,
        inclination_deg=args.inclination_deg,
        obs_rate_hz=args.obs_rate_hz,
        name=args.name,
        flight=args.flight,
        allow_unhealthy=args.allow_unhealthy,
    )
