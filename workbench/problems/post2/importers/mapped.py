"""Column-mapped importer: any flight computer's CSV files -> the workbench's rocket flight import.

``workbench import csv --mapping MAP.toml --out DIR``.  The mapping file (:data:`MAPPING_SCHEMA`,
documented in ``workbench/io/FORMATS.md``, "Column-mapped rocket flight logs") names, for any number
of CSV files at their own rates: each file's path, time column, time unit and offset; which file and
column holds each quantity (accelerometer and gyro triads, barometric pressure; optional
magnetometer triad and temperature), its unit (:mod:`workbench.io.units`) and the map from the
log's columns to the body axes (``body_x = "-accel_z"``); the site, the rocket, optional scoring
references; optionally the flight phases, GNSS fixes (observed relative to the pad's own fix:
:func:`read_gnss`), the model-error levels of the observations, and the flight computer's own
solution (a reference, never observed).  The FIRM log of ``workbench import airbrakes`` is one such
layout (``airbrakes.FIRM_LAYOUT``, read by :func:`from_data` without site and rocket).  What it does:

1. :func:`read_mapped` — every file read with located errors (file, column, data row): a missing
   column, a cell that is not a finite number, a time not strictly after the previous row's (a row
   repeating the previous row exactly is a packet logged twice: dropped and counted), an unknown or
   wrong-kind unit (the data file, the column, the header line, and the mapping's key).  Values go
   to SI; the accelerometer's file is the time base and every other quantity is interpolated
   linearly onto its samples (those outside the span every file covers are dropped).  Gaps of every
   file are listed (a block mean never spans one, a gap in the boost is refused);
2. :func:`detect_phases` — the flight phases, from a phase column when the mapping names one, else
   from the data by the rules of :data:`PHASE_RULES`; a time given in ``[phases]`` overrides either;
3. :func:`workbench.problems.post2.importers.flightlog.import_log` — the same pad alignment, boost,
   physics cross-checks and files as ``workbench import airbrakes`` (nothing is written on an error).

Without a magnetometer the pad heading is unknown: it is the prior ``[site] pad_heading_deg`` ±
``pad_heading_sigma_deg`` (default: unknown, 60° 1σ) and the problem file marks it untrusted
(``[launch] heading_trusted = false``), which the landing ellipse reports.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from workbench.core.bodies import G0
from workbench.io.columns import read_columns
from workbench.io.scenario import ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, read_toml
from workbench.io.telemetry import MAX_PROBLEMS, Problem, TelemetryError
from workbench.io.units import UnitError, canonical_unit, known_units, to_si, unit_kind
from workbench.problems.post2.importers.flightlog import (
    TEMPERATURE_SIGMA_K,
    FlightLog,
    FlightMetadata,
    Gap,
    GnssFixes,
    add_common_arguments,
    check_rates,
    check_units,
    find_gaps,
    import_log,
)

__all__ = [
    "HELP",
    "add_arguments",
    "run",
    "MAPPING_SCHEMA",
    "FILE_SCHEMA",
    "PHASE_RULES",
    "file_schemas",
    "Mapping",
    "PhaseTimes",
    "read_mapping",
    "from_data",
    "read_mapped",
    "detect_phases",
    "import_mapped",
    "input_names",
]

_F, _S, _I = "float", "str", "int"

#: the triads a mapping can name (table -> quantity kind of its unit)
TRIADS = {"accelerometer": "acceleration", "gyro": "angular_rate", "magnetometer": "magnetic"}
#: the single-column quantities (table -> quantity kind)
SCALARS = {"barometer": "pressure", "temperature": "temperature"}


def _triad(table: str, what: str, optional: bool) -> Table:
    req = None if optional else REQUIRED
    axis = 'the log column along the body {0} axis, with an optional sign: `"ax"`, `"-accel_z"`'
    return Table(
        table,
        what,
        (
            Key("file", _S, req, meaning="the `[files.<name>]` entry holding the columns"),
            Key(
                "unit",
                _S,
                req,
                meaning=f"unit of the columns ({TRIADS[table].replace('_', ' ')}, workbench/io/units.py)",
            ),
            Key("body_x", _S, req, meaning=axis.format("x")),
            Key("body_y", _S, req, meaning=axis.format("y")),
            Key("body_z", _S, req, meaning=axis.format("z")),
        ),
    )


def _scalar(table: str, what: str, optional: bool) -> Table:
    req = None if optional else REQUIRED
    return Table(
        table,
        what,
        (
            Key("file", _S, req, meaning="the `[files.<name>]` entry holding the column"),
            Key("column", _S, req, meaning="the column's name in the header"),
            Key("unit", _S, req, meaning=f"its unit ({SCALARS[table]}, workbench/io/units.py)"),
        ),
    )


#: one ``[files.<name>]`` entry of a mapping: a CSV file (a header row of names, one sample per row)
FILE_SCHEMA = Schema(
    "csv_mapping_file",
    "a CSV file of a column-mapped log",
    (
        Table(
            "",
            "one CSV file (a header row of column names, then one sample per row, comma separated)",
            (
                Key("path", _S, REQUIRED, meaning="the file, relative to the mapping file's folder"),
                Key("time", _S, REQUIRED, meaning="its time column (strictly increasing)"),
                Key("time_unit", _S, "s", meaning="unit of the time column (`s`, `ms`, `us`)"),
                Key("time_offset_s", _F, 0.0, "s", "added to its times (after the unit) to put it on the common clock"),
            ),
        ),
    ),
    noun="mapping file entry",
    intro="Keys of each `[files.<name>]` entry of a column mapping",
)

#: the mapping file of ``workbench import csv``
MAPPING_SCHEMA = Schema(
    "csv_mapping",
    "column mapping of a rocket flight log",
    (
        Table(
            "flight",
            "what the flight is",
            (
                Key("name", _S, None, meaning="problem name (default: the mapping file's stem)"),
                Key("date", _S, "", meaning="launch date and time, ISO 8601 (shown in the problem file)"),
                Key("description", _S, "", meaning="one line on the flight"),
            ),
        ),
        Table(
            "site",
            "the pad and its weather at launch",
            (
                Key("lat_deg", _F, REQUIRED, "deg", "pad latitude (WGS-84), north positive", ge=-90.0, le=90.0),
                Key("lon_deg", _F, REQUIRED, "deg", "pad longitude, east positive", ge=-180.0, lt=360.0),
                Key(
                    "qnh_hpa",
                    _F,
                    None,
                    "hPa",
                    "air pressure reduced to sea level (give it or pad_altitude_m)",
                    ge=800.0,
                    le=1100.0,
                ),
                Key(
                    "pad_altitude_m",
                    _F,
                    None,
                    "m",
                    "pad altitude above sea level (give it or qnh_hpa)",
                    ge=-500.0,
                    le=6000.0,
                ),
                Key("temperature_degC", _F, REQUIRED, "degC", "air temperature at the pad", ge=-60.0, le=60.0),
                Key(
                    "temperature_sigma_K",
                    _F,
                    TEMPERATURE_SIGMA_K,
                    "K",
                    "1σ of the air column's mean temperature (pad to apogee) about the pad's with the standard "
                    "lapse (-6.5 K/km): the barometer's altitude scale, carried in every σ as the `baro_scale` "
                    "consider parameter; the default allows for the lapse rate, humidity and the reading",
                    gt=0.0,
                    le=40.0,
                ),
                Key("wind_speed_m_s", _F, 0.0, "m/s", "surface wind speed (the wind state's prior)", ge=0.0, le=60.0),
                Key(
                    "wind_from_deg",
                    _F,
                    0.0,
                    "deg",
                    "where the surface wind blows from, clockwise from north",
                    ge=0.0,
                    lt=360.0,
                ),
                Key(
                    "launch_rod_angle_deg",
                    _F,
                    None,
                    "deg",
                    "rod angle from the vertical (checked against the IMU's pad tilt)",
                    ge=0.0,
                    lt=90.0,
                ),
                Key(
                    "declination_deg",
                    _F,
                    0.0,
                    "deg",
                    "magnetic declination, east positive (with a magnetometer)",
                    ge=-180.0,
                    le=180.0,
                ),
                Key(
                    "inclination_deg",
                    _F,
                    None,
                    "deg",
                    "magnetic dip, down positive: the magnetometer's heading is trusted only if the pad agrees",
                    ge=-90.0,
                    le=90.0,
                ),
                Key(
                    "pad_heading_deg",
                    _F,
                    None,
                    "deg",
                    "without a magnetometer: bearing of the body x axis on the pad (of y when x is within 30° of "
                    "the vertical), clockwise from true north; absent: unknown",
                    ge=-360.0,
                    le=360.0,
                ),
                Key(
                    "pad_heading_sigma_deg",
                    _F,
                    60.0,
                    "deg",
                    "1σ of that pad heading (the heading is marked untrusted)",
                    gt=0.0,
                    le=60.0,
                ),
            ),
        ),
        Table(
            "rocket",
            "the rocket after burnout",
            (
                Key("dry_mass_kg", _F, REQUIRED, "kg", "dry mass: the coast and descent mass", gt=0.0),
                Key("cd", _F, REQUIRED, "1", "drag coefficient on the reference area (coast)", gt=0.0),
                Key("ref_area_m2", _F, REQUIRED, "m^2", "aerodynamic reference area", gt=0.0),
                Key("motor", _S, None, meaning="motor designation (e.g. L1390G-P: checks the mass against the boost)"),
            ),
        ),
        Table(
            "reference",
            "what is known of the flight from elsewhere (scoring references and checks; optional)",
            (
                Key("apogee_m", _F, None, "m", "apogee above the pad", gt=0.0),
                Key(
                    "landed_lat_deg",
                    _F,
                    None,
                    "deg",
                    "landing point latitude (a `_landing` variant observes it)",
                    ge=-90.0,
                    le=90.0,
                ),
                Key("landed_lon_deg", _F, None, "deg", "landing point longitude", ge=-180.0, lt=360.0),
            ),
        ),
        Table(
            "files", "the CSV files, one `[files.<name>]` table each (keys below)", free="table", free_meaning="a file"
        ),
        _triad("accelerometer", "specific force triad; its file is the time base", optional=False),
        _triad("gyro", "body rate triad (the same body axes as the accelerometer's)", optional=False),
        _triad("magnetometer", "magnetic field triad (optional: without it the pad heading is a prior)", optional=True),
        _scalar("barometer", "static pressure", optional=False),
        _scalar("temperature", "the board's temperature (optional; checked against the site's)", optional=True),
        Table(
            "model_error",
            "the observations' model-error 1σ per phase (optional; absent: the levels measured on the FIRM flights, "
            "docs/tuning/post2.md): raise them when the run's NIS of `baro` / `accel` is far above 1, lower them "
            "when far below",
            tuple(
                Key(f"{q}_{ph}_{u}", _F, None, unit, f"{what} under {txt}", gt=0.0)
                for q, u, unit, what in (
                    ("pressure", "pa", "Pa", "block-mean pressure"),
                    ("accel", "m_s2", "m/s^2", "block-mean |specific force|"),
                )
                for ph, txt in (("coast", "the coast"), ("drogue", "the drogue"), ("main", "the main parachute"))
            ),
        ),
        Table(
            "gnss",
            "GNSS fixes (optional): latitude/longitude/altitude observed relative to the pad (the fixes before "
            "liftoff give the pad's own fix, so a constant GNSS offset cancels); fixes in the reconstructed span "
            "are observations",
            (
                Key("file", _S, None, meaning="the `[files.<name>]` entry holding the fixes (read at their own times)"),
                Key("latitude", _S, None, meaning="latitude column [deg]"),
                Key("longitude", _S, None, meaning="longitude column [deg]"),
                Key(
                    "altitude", _S, None, meaning="altitude column (any datum: only differences from the pad are used)"
                ),
                Key("altitude_unit", _S, "m", meaning="unit of the altitude (length)"),
                Key("sigma_h", _S, None, meaning="column of each fix's horizontal 1σ (absent: `sigma_h_m`)"),
                Key("sigma_v", _S, None, meaning="column of each fix's vertical 1σ (absent: `sigma_v_m`)"),
                Key("sigma_unit", _S, "m", meaning="unit of the σ columns (length)"),
                Key(
                    "sigma_h_m",
                    _F,
                    10.0,
                    "m",
                    "horizontal 1σ of a fix (per axis) without a σ column: the receiver's and the 3-DOF model's "
                    "error over a second of flight together, not the receiver's alone",
                    gt=0.0,
                ),
                Key("sigma_v_m", _F, 20.0, "m", "vertical 1σ of a fix without a σ column (as `sigma_h_m`)", gt=0.0),
                Key(
                    "min_pad_fixes",
                    _I,
                    3,
                    "",
                    "fixes needed on the pad before liftoff to reference the others to (fewer: an error)",
                    ge=1,
                ),
            ),
        ),
        Table(
            "flight_computer",
            "the flight computer's own solution (optional): a reference for scoring and checks, never observed",
            (
                Key("file", _S, None, meaning="the `[files.<name>]` entry holding its columns"),
                Key("altitude", _S, None, meaning="its altitude column"),
                Key("altitude_unit", _S, "m", meaning="unit of the altitude (length)"),
                Key("vertical_speed", _S, None, meaning="its vertical speed column (up positive)"),
                Key("vertical_speed_unit", _S, "m/s", meaning="unit of the vertical speed"),
                Key("quaternion_w", _S, None, meaning="its attitude quaternion, scalar part (norm 1 ± 0.01)"),
                Key("quaternion_x", _S, None, meaning="... x part"),
                Key("quaternion_y", _S, None, meaning="... y part"),
                Key("quaternion_z", _S, None, meaning="... z part"),
            ),
        ),
        Table(
            "phases",
            "flight phases: from a phase column, else detected (rules in FORMATS.md); a time here overrides",
            (
                Key("file", _S, None, meaning="the file of a phase column (absent: phases detected from the data)"),
                Key("column", _S, None, meaning="the phase column"),
                Key("standby", _S, "S", meaning="the column's value for standby on the pad"),
                Key("motor", _S, "M", meaning="... for the motor burning"),
                Key("coast", _S, "C", meaning="... for the coast"),
                Key("descent", _S, "F", meaning="... for the descent under the parachutes"),
                Key("landed", _S, "L", meaning="... for landed"),
                Key("liftoff_s", _F, None, "s", "liftoff (first motor sample) on the common clock"),
                Key("burnout_s", _F, None, "s", "burnout (first coast sample)"),
                Key("apogee_s", _F, None, "s", "the drogue's deployment (first descent sample)"),
                Key("main_s", _F, None, "s", "the main parachute's opening"),
                Key("landing_s", _F, None, "s", "touchdown (first landed sample)"),
            ),
        ),
    ),
    noun="column mapping file",
    intro="Keys of a column mapping file (`workbench import csv --mapping MAP.toml`)",
)

#: the schemas of the files this importer reads (listed in FORMATS.md by the registry)
file_schemas = (MAPPING_SCHEMA, FILE_SCHEMA)

#: the log begins on the pad: its first UNIT_CHECK_S [s] check the accelerometer's unit (1 g at rest)
UNIT_CHECK_S = 1.0
#: liftoff: the first sample whose |specific force| exceeds LIFTOFF_G [g] and whose median over the
#: next LIFTOFF_HOLD_S [s] does too
LIFTOFF_G = 2.0
LIFTOFF_HOLD_S = 0.2
#: burnout: the first sample from BURNOUT_MIN_S [s] after liftoff whose specific force along the
#: boost's axis (its mean direction over the first BOOST_AXIS_S [s]) falls below BURNOUT_AXIAL_G [g]
#: (the thrust's collapse; FIRM's coast letter on the excerpt of flight 1 to the sample)
BURNOUT_MIN_S = 0.2
BOOST_AXIS_S = 0.5
BURNOUT_AXIAL_G = 1.0
#: apogee: the barometric apogee is the lowest pressure (moving mean over BARO_SMOOTH_S [s]) after
#: burnout; the drogue's deployment is the ejection shock (rocket.detect_ejection) up to
#: EJECTION_AFTER_APOGEE_S [s] after it, else the barometric apogee itself
BARO_SMOOTH_S = 0.5
EJECTION_AFTER_APOGEE_S = 4.0
#: landing: the first sample from LANDING_MIN_AFTER_APOGEE_S [s] after apogee after which the pressure
#: stays within a band (max − min) of LANDED_BAND_PA [Pa] or 6 × the pad's pressure noise for LANDED_HOLD_S [s]
LANDING_MIN_AFTER_APOGEE_S = 5.0
LANDED_BAND_PA = 15.0
LANDED_HOLD_S = 5.0

PHASE_RULES = (
    f"liftoff: first sample with |f| > {LIFTOFF_G:g} g whose median over the next {LIFTOFF_HOLD_S:g} s is too",
    f"burnout: first sample ≥ {BURNOUT_MIN_S:g} s after liftoff whose specific force along the boost axis "
    f"(mean direction over the first {BOOST_AXIS_S:g} s) falls below {BURNOUT_AXIAL_G:g} g: the thrust collapses",
    f"apogee (drogue): the ejection shock (|f| > 3 g, from 3 s after burnout) up to "
    f"{EJECTION_AFTER_APOGEE_S:g} s after the barometric apogee (lowest {BARO_SMOOTH_S:g} s mean pressure), "
    "else the barometric apogee",
    "main: the barometric descent rate falls below half the drogue's for 2 s; the opening is the largest "
    "|f| in the 3 s before (rocket.detect_main_deploy)",
    f"landing: first sample ≥ {LANDING_MIN_AFTER_APOGEE_S:g} s after apogee after which the pressure stays "
    f"within max({LANDED_BAND_PA:g} Pa, 6 × the pad's noise) for {LANDED_HOLD_S:g} s; none: the log ends in flight",
)


@dataclass(frozen=True)
class Mapping:
    """A validated mapping file: ``path``; ``data`` the validated tables (:data:`MAPPING_SCHEMA`,
    defaults filled); ``files`` {name: validated ``[files.<name>]`` entry with ``path`` absolute}."""

    path: Path
    data: dict
    files: dict


@dataclass(frozen=True)
class PhaseTimes:
    """Flight phase times [s, the log's common clock]: ``liftoff``, ``burnout``, ``apogee`` (the
    drogue's deployment: first descent sample), ``main`` and ``landing`` (None: not found / not in the
    log); ``source`` {phase: "column" | "detected" | "mapping"}."""

    liftoff: float
    burnout: float
    apogee: float
    main: float | None
    landing: float | None
    source: dict


def read_mapping(path: str | os.PathLike) -> Mapping:
    """The mapping file at ``path`` validated (:data:`MAPPING_SCHEMA`, each ``[files.<name>]`` entry
    against :data:`FILE_SCHEMA`), with the cross-references checked: every quantity's ``file`` names
    a ``[files]`` entry, exactly one of ``qnh_hpa`` / ``pad_altitude_m``, a phase column's ``file``
    and ``column`` together, ``pad_heading_deg`` only without a magnetometer.  ScenarioError naming
    the file and the key otherwise."""
    path = Path(path)
    return from_data(read_toml(path), path)


#: the tables a mapping of a log's layout alone (no site, no rocket: :func:`from_data` ``layout_only``) may omit
LAYOUT_ONLY_OPTIONAL = ("site", "rocket", "magnetometer", "temperature")
#: the columns of ``[flight_computer]``, all given or none
FLIGHT_COMPUTER_COLUMNS = ("altitude", "vertical_speed", "quaternion_w", "quaternion_x", "quaternion_y", "quaternion_z")


def from_data(data: dict, path: Path, *, layout_only: bool = False) -> Mapping:
    """A :class:`Mapping` from the parsed document ``data`` of the mapping file ``path`` (validated and
    cross-checked as :func:`read_mapping` says); ``layout_only``: a mapping of the files alone, without
    ``[site]`` and ``[rocket]`` (a built-in layout, e.g. the FIRM log's: ``airbrakes.FIRM_LAYOUT``)."""
    path = Path(path)
    data = MAPPING_SCHEMA.validate(
        data, path, optional=LAYOUT_ONLY_OPTIONAL if layout_only else ("magnetometer", "temperature")
    )
    files = {}
    for name, entry in (data.get("files") or {}).items():
        f = FILE_SCHEMA.validate(entry, path, where=f"files.{name}")
        f["path"] = (path.parent / f["path"]).resolve()
        files[name] = f
    if not files:
        raise ScenarioError(path, "files", "no [files.<name>] table: name at least the file of the accelerometer")
    for table in (*TRIADS, *SCALARS, "phases", "flight_computer"):
        ref = (data.get(table) or {}).get("file")
        if ref is not None and ref not in files:
            raise ScenarioError(path, f"{table}.file", f"{ref!r} is not a [files.<name>] entry ({', '.join(files)})")
    fc = data["flight_computer"]
    given = [k for k in FLIGHT_COMPUTER_COLUMNS if fc[k] is not None]
    if (fc["file"] is None) != (not given) or (given and len(given) < len(FLIGHT_COMPUTER_COLUMNS)):
        missing = [k for k in ("file", *FLIGHT_COMPUTER_COLUMNS) if fc[k] is None]
        raise ScenarioError(
            path, f"flight_computer.{missing[0]}", "give its file and every column of the solution, or none of them"
        )
    site = data["site"]
    if not layout_only and (site["qnh_hpa"] is None) == (site["pad_altitude_m"] is None):
        raise ScenarioError(path, "site.qnh_hpa", "give exactly one of site.qnh_hpa and site.pad_altitude_m")
    ph = data["phases"]
    if (ph["file"] is None) != (ph["column"] is None):
        raise ScenarioError(path, "phases.column", "a phase column needs both phases.file and phases.column")
    if data["magnetometer"]["file"] is not None and site.get("pad_heading_deg") is not None:
        raise ScenarioError(
            path, "site.pad_heading_deg", "is the heading prior of a log without a magnetometer; this one has one"
        )
    return Mapping(path, data, files)


def _unit(mp: Mapping, table: str, data_file: Path, column: str, kind: str, key: str = "unit") -> str:
    """The canonical unit ``[table] key`` checked against its quantity ``kind``; a TelemetryError naming
    the data file, the column, the header line and the mapping's key if unknown or of another kind."""
    u = mp.data[table][key]
    try:
        cu = canonical_unit(u)
        ok = unit_kind(cu) == kind
    except UnitError:
        ok = False
    if not ok:
        raise TelemetryError.single(
            data_file,
            f"unit {u!r} ({mp.path.name}: {table}.{key}) is not a known {kind.replace('_', ' ')} unit "
            f"({', '.join(known_units(kind))})",
            column=column,
            line=1,
        )
    return cu


def _signed(spec: str) -> tuple[float, str]:
    """(sign, column) of an axis entry ``"-accel_z"`` / ``"+ax"`` / ``"ax"``."""
    s = spec.strip()
    if s[:1] in "+-" and len(s) > 1:
        return (-1.0 if s[0] == "-" else 1.0), s[1:].strip()
    return 1.0, s


def read_mapped(mp: Mapping, needed_by: str = "the mapping names it"):
    """Read the files of the mapping ``mp`` into SI on the accelerometer's time base.

    Returns ``(t, quantities, phase_values, info)``: ``t`` (n,) [s, common clock]; ``quantities``
    {"f_B", "w_B", "mag_B": (n, 3) [m/s², rad/s, T]; "pressure", "temperature", "ref_h", "ref_vz": (n,)
    [Pa, K, m, m/s]; "ref_q": (n, 4) scalar-last, normalised} (an absent optional quantity is None; the
    ``ref_*`` the flight computer's solution); ``phase_values`` (n,) the phase column's values at each
    sample (the last row at or before it) or None; ``info`` JSON-ready: per file its rows, repeated rows
    dropped and gaps [s], the time-base samples dropped outside the common span, the columns used.
    ``needed_by`` ends the message of a missing column.  ``quantities["pressure_valid"]`` (n,) is False
    where the pressure was interpolated across a gap of the barometer's file (never observed)."""
    d = mp.data
    need: dict[str, list[str]] = {n: [] for n in mp.files}
    plan = {}  # quantity -> (file, [(sign, column)], unit)
    for table, kind in TRIADS.items():
        if d[table]["file"] is None:
            continue
        fname = d[table]["file"]
        axes = [_signed(d[table][f"body_{c}"]) for c in "xyz"]
        unit = _unit(mp, table, mp.files[fname]["path"], axes[0][1], kind)
        plan[table] = (fname, axes, unit)
        need[fname] += [c for _, c in axes]
    for table, kind in SCALARS.items():
        if d[table]["file"] is None:
            continue
        fname = d[table]["file"]
        unit = _unit(mp, table, mp.files[fname]["path"], d[table]["column"], kind)
        plan[table] = (fname, [(1.0, d[table]["column"])], unit)
        need[fname].append(d[table]["column"])
    fc = d["flight_computer"]
    if fc["file"] is not None:
        fname, path_fc = fc["file"], mp.files[fc["file"]]["path"]
        for key, kind in (("altitude", "length"), ("vertical_speed", "velocity")):
            unit = _unit(mp, "flight_computer", path_fc, fc[key], kind, f"{key}_unit")
            plan[f"ref_{key}"] = (fname, [(1.0, fc[key])], unit)
        plan["ref_quaternion"] = (fname, [(1.0, fc[f"quaternion_{c}"]) for c in "xyzw"], "1")
        need[fname] += [fc[k] for k in FLIGHT_COMPUTER_COLUMNS]
    phase_file, phase_col = d["phases"]["file"], d["phases"]["column"]
    values = [d["phases"][k] for k in ("standby", "motor", "coast", "descent", "landed")]

    def phase_ok(_column, v):
        return None if v in values else f"{v!r} is not a phase value ({', '.join(values)}; [phases] in {mp.path.name})"

    files = {}
    for name, spec in mp.files.items():
        if not need[name] and name != phase_file:
            continue
        try:
            tu = canonical_unit(spec["time_unit"])
            if unit_kind(tu) != "time":
                raise UnitError(tu)
        except UnitError:
            raise TelemetryError.single(
                spec["path"],
                f"time unit {spec['time_unit']!r} ({mp.path.name}: files.{name}.time_unit) is not a time unit "
                f"({', '.join(known_units('time'))})",
                column=spec["time"],
                line=1,
            ) from None
        texts = (phase_col,) if name == phase_file else ()
        c = read_columns(spec["path"], spec["time"], need[name], texts, needed_by=needed_by, check_text=phase_ok)
        if fc["file"] == name:
            _check_quaternion(spec["path"], c, [fc[f"quaternion_{k}"] for k in "wxyz"])
        if c.rows.size < 2:
            raise TelemetryError.single(spec["path"], "fewer than two data rows", column=spec["time"])
        t = to_si(c.values[spec["time"]], tu)[0] + spec["time_offset_s"]
        files[name] = (t, c.values, c.texts, c.repeated_rows, c.rows)
    master = d["accelerometer"]["file"]
    t_m = files[master][0]
    lo = max(f[0][0] for f in files.values())
    hi = min(f[0][-1] for f in files.values())
    keep = (t_m >= lo) & (t_m <= hi)
    t = t_m[keep]
    if t.size < 10:
        raise TelemetryError.single(
            mp.files[master]["path"],
            f"the files share only {t.size} accelerometer samples ({lo:.3f} .. {hi:.3f} s on the common clock): "
            "check each file's time unit and time_offset_s",
            column=mp.files[master]["time"],
        )

    def on_base(name, column):
        tf, cols = files[name][0], files[name][1]
        return cols[column][keep] if name == master else np.interp(t, tf, cols[column])

    q: dict[str, np.ndarray | None] = {}
    for table in (*TRIADS, *SCALARS, "ref_altitude", "ref_vertical_speed", "ref_quaternion"):
        if table not in plan:
            q[table] = None
            continue
        fname, axes, unit = plan[table]
        v = np.column_stack([sgn * on_base(fname, col) for sgn, col in axes])
        v = to_si(v, unit)[0]
        q[table] = v if v.shape[1] > 1 else v[:, 0]
    if q["ref_quaternion"] is not None:
        q["ref_quaternion"] = q["ref_quaternion"] / np.linalg.norm(q["ref_quaternion"], axis=1)[:, None]
    phase_values = None
    if phase_file is not None:
        tf, txt = files[phase_file][0], files[phase_file][2][phase_col]
        k = np.clip(np.searchsorted(tf, t, side="right") - 1, 0, tf.size - 1)
        phase_values = txt[k]
    info = {
        "mapping": mp.path.name,
        "time_base": mp.files[master]["path"].name,
        "dropped_outside_common_span": int(np.sum(~keep)),
        "files": {
            n: {
                "path": mp.files[n]["path"].name,
                "rows": int(f[4].size + f[3]),
                "repeated_rows_dropped": f[3],
                "median_step_s": float(np.median(np.diff(f[0]))),
            }
            for n, f in files.items()
        },
        "columns": {
            tb: {"file": p[0], "columns": [("-" if s < 0 else "") + c for s, c in p[1]], "unit": p[2]}
            for tb, p in plan.items()
        },
    }
    quantities = {
        "f_B": q["accelerometer"],
        "w_B": q["gyro"],
        "mag_B": q["magnetometer"],
        "pressure": q["barometer"],
        "temperature": q["temperature"],
        "ref_h": q["ref_altitude"],
        "ref_vz": q["ref_vertical_speed"],
        "ref_q": q["ref_quaternion"],
    }
    # gaps of every file (the time base's and the others', located on the time base)
    gaps_s = []
    for n, f in files.items():
        dtf = np.diff(f[0])
        lim = 3.0 * float(np.median(dtf))
        for i in np.flatnonzero(dtf > lim):
            if f[0][i + 1] > t[0] and f[0][i] < t[-1]:
                gaps_s.append((float(f[0][i]), float(f[0][i + 1]), n, int(f[4][i + 1]) + 1))
    info["gaps"] = [{"t_a_s": a, "t_b_s": b, "file": n, "row": r} for a, b, n, r in gaps_s]
    # the pressure interpolated across a gap of the barometer's own file is not a measurement
    valid = np.ones(t.size, dtype=bool)
    for a, b, n, _ in gaps_s:
        if n == d["barometer"]["file"] and n != master:
            valid &= ~((t > a) & (t < b))
    quantities["pressure_valid"] = valid
    return t, quantities, phase_values, info


def read_gnss(mp: Mapping, liftoff: float) -> GnssFixes | None:
    """The mapping's ``[gnss]`` fixes (None without ``[gnss] file``) relative to the pad: the median of
    the fixes before ``liftoff`` [s, common clock] is the pad's own fix (at least ``min_pad_fixes`` of
    them, else a located error), and every fix becomes east/north/up of it [m] (local east/north on the
    mean sphere; up the altitude difference, so the GNSS datum and a constant offset cancel)."""
    from workbench.problems.post2.rocket import local_en  # the rocket module's kernels load lazily

    g = mp.data["gnss"]
    if g["file"] is None:
        return None
    missing = [k for k in ("latitude", "longitude", "altitude") if g[k] is None]
    if missing:
        raise ScenarioError(
            mp.path, f"gnss.{missing[0]}", "a [gnss] file needs its latitude, longitude and altitude columns"
        )
    spec = mp.files[g["file"]]
    cols = [g["latitude"], g["longitude"], g["altitude"]] + [g[k] for k in ("sigma_h", "sigma_v") if g[k] is not None]
    c = read_columns(spec["path"], spec["time"], cols, needed_by=f"[gnss] of {mp.path.name}")
    tu = canonical_unit(spec["time_unit"])
    t = to_si(c.values[spec["time"]], tu)[0] + spec["time_offset_s"]
    lat, lon = c.values[g["latitude"]], c.values[g["longitude"]]
    alt = to_si(c.values[g["altitude"]], _unit(mp, "gnss", spec["path"], g["altitude"], "length", "altitude_unit"))[0]
    for col, v, lim in ((g["latitude"], lat, 90.0), (g["longitude"], lon, 360.0)):
        bad = np.flatnonzero(np.abs(v) > lim)
        if bad.size:
            raise TelemetryError.single(
                spec["path"], f"{v[bad[0]]:g} is not an angle in degrees (|value| <= {lim:g})", column=col,
                line=int(c.rows[bad[0]]) + 1,
            )  # fmt: skip

    def sigma(key, default):
        if g[key] is None:
            return np.full(t.size, default)
        v = to_si(c.values[g[key]], _unit(mp, "gnss", spec["path"], g[key], "length", "sigma_unit"))[0]
        bad = np.flatnonzero(~(v > 0))
        if bad.size:
            raise TelemetryError.single(
                spec["path"], f"a 1σ must be > 0, got {v[bad[0]]:g}", column=g[key], line=int(c.rows[bad[0]]) + 1
            )
        return v

    pad = t < liftoff
    if int(np.sum(pad)) < g["min_pad_fixes"]:
        raise TelemetryError.single(
            spec["path"],
            f"{int(np.sum(pad))} fixes before liftoff ({liftoff:.3f} s on the common clock); [gnss] min_pad_fixes = "
            f"{g['min_pad_fixes']} are needed to reference the fixes to the pad",
            column=spec["time"],
        )
    lat0, lon0, alt0 = (float(np.median(v[pad])) for v in (lat, lon, alt))
    enu = np.column_stack([local_en(lat, lon, lat0, lon0), alt - alt0])
    site = mp.data["site"]
    info = {
        "file": spec["path"].name,
        "fixes": int(t.size),
        "on_pad": int(np.sum(pad)),
        "pad_fix_deg_m": [lat0, lon0, alt0],
        "pad_fix_from_site_m": float(np.hypot(*local_en(lat0, lon0, site["lat_deg"], site["lon_deg"]))),
    }
    return GnssFixes(t, enu, sigma("sigma_h", g["sigma_h_m"]), sigma("sigma_v", g["sigma_v_m"]), info)


def _check_quaternion(path: Path, c, columns: list[str]) -> None:
    """Refuse the flight computer's quaternion (``columns`` w, x, y, z of the file read as ``c``) where
    its norm is not 1 ± 0.01: a located TelemetryError (file, the w column, data row)."""
    qn = np.linalg.norm(np.column_stack([c.values[k] for k in columns]), axis=1)
    bad = np.flatnonzero(np.abs(qn - 1.0) > 0.01)
    if bad.size:
        probs = [
            Problem(
                str(path),
                columns[0],
                int(c.rows[i]) + 1,
                int(c.rows[i]) + 2,
                f"quaternion norm {qn[i]:.4g} (expected 1)",
            )
            for i in bad[:MAX_PROBLEMS]
        ]
        raise TelemetryError(probs, int(bad.size))


def _first(t: np.ndarray, mask: np.ndarray) -> float | None:
    k = np.flatnonzero(mask)
    return float(t[k[0]]) if k.size else None


def detect_phases(t, f_B, pressure, mp: Mapping, phase_values=None, path: Path | None = None) -> PhaseTimes:
    """The flight phases [s, common clock] of the samples ``t`` (n,) [s] with specific force ``f_B``
    (n, 3) [m/s²] and ``pressure`` (n,) [Pa]: from ``phase_values`` (n,) (the mapping's phase column,
    its values translated by ``[phases]``) when given, else by :data:`PHASE_RULES`; each time given in
    the mapping's ``[phases]`` overrides.  A located TelemetryError (``path``, the time or phase
    column) when liftoff, burnout or apogee cannot be found."""
    from workbench.problems.post2 import rocket

    ph = mp.data["phases"]
    where = str(path or mp.path)
    col = ph["column"] or mp.files[mp.data["accelerometer"]["file"]]["time"]
    fn = np.linalg.norm(f_B, axis=1)
    src: dict[str, str] = {}
    main = landing = None
    if phase_values is not None:
        letters = {ph[k]: k for k in ("standby", "motor", "coast", "descent", "landed")}
        bad = np.flatnonzero(~np.isin(phase_values, list(letters)))
        if bad.size:
            raise TelemetryError.single(
                where,
                f"{phase_values[bad[0]]!r} is not a phase value ({', '.join(letters)})",
                column=col,
                row=int(bad[0]) + 1,
            )
        kind = np.array([letters[v] for v in phase_values])
        lift, burn, apo = (_first(t, kind == k) for k in ("motor", "coast", "descent"))
        landing = _first(t, kind == "landed")
        src = dict.fromkeys(("liftoff", "burnout", "apogee", "landing"), "column")
    else:
        above = fn > LIFTOFF_G * G0
        c = np.concatenate([[0], np.cumsum(above)])
        k1 = np.searchsorted(t, t + LIFTOFF_HOLD_S, side="right")  # the window [t_k, t_k + hold]
        held = 2 * (c[k1] - c[np.arange(t.size)]) > (k1 - np.arange(t.size))  # its median is above
        lift = _first(t, above & held)
        burn = apo = None
        if lift is not None:
            boost = (t >= lift) & (t <= lift + BOOST_AXIS_S)
            n = f_B[boost].mean(axis=0)
            n /= np.linalg.norm(n)
            burn = _first(t, (t >= lift + BURNOUT_MIN_S) & (f_B @ n < BURNOUT_AXIAL_G * G0))
        if burn is not None:
            w = max(1, int(round(BARO_SMOOTH_S / float(np.median(np.diff(t))))))
            ps = np.convolve(pressure, np.ones(w) / w, mode="same")
            after = np.flatnonzero(t > burn)
            if after.size:
                valid = after[(after >= w // 2) & (after < t.size - w // 2)]
                k = valid[np.argmin(ps[valid])] if valid.size else after[np.argmin(pressure[after])]
                t_baro = float(t[k])
                t_lim = t_baro + EJECTION_AFTER_APOGEE_S - 1.0  # detect_ejection searches to its letter + 1 s
                t_ej = rocket.detect_ejection(t, f_B, burn, t_lim)
                apo = t_ej if t_ej != t_lim else t_baro
        if apo is not None:
            pad = (t >= (lift or t[0]) - 1.1) & (t < (lift or t[0]) - 0.1)
            noise = float(np.std(pressure[pad])) if np.sum(pad) >= 3 else 0.0
            band = max(LANDED_BAND_PA, 6.0 * noise)
            k0 = int(np.searchsorted(t, apo + LANDING_MIN_AFTER_APOGEE_S))
            w = int(round(LANDED_HOLD_S / float(np.median(np.diff(t))))) + 1  # samples in the hold window
            if t.size - k0 >= w:
                win = np.lib.stride_tricks.sliding_window_view(pressure[k0:], w)
                flat = np.flatnonzero(win.max(axis=1) - win.min(axis=1) <= band)
                landing = float(t[k0 + flat[0]]) if flat.size else None
        src = dict.fromkeys(("liftoff", "burnout", "apogee", "landing"), "detected")
    times = {"liftoff": lift, "burnout": burn, "apogee": apo, "main": main, "landing": landing}
    src["main"] = "detected"
    for k in times:
        if ph[f"{k}_s"] is not None:
            times[k] = float(ph[f"{k}_s"])
            src[k] = "mapping"
    for k, what in (("liftoff", "no liftoff (|f| > 2 g held 0.2 s)"), ("burnout", "no burnout after liftoff"),
                    ("apogee", "no apogee after burnout")):  # fmt: skip
        if times[k] is None:
            raise TelemetryError.single(
                where,
                f"{what}: the import needs the boost, the coast and the descent's start; give [phases] {k}_s "
                "in the mapping if the detection misses it",
                column=col,
            )
    order = [times[k] for k in ("liftoff", "burnout", "apogee")] + [times["landing"] or math.inf]
    if not all(a < b for a, b in zip(order[:-1], order[1:], strict=True)):
        raise TelemetryError.single(
            where, f"the phases are out of order: liftoff, burnout, apogee, landing at {order} s", column=col
        )
    return PhaseTimes(times["liftoff"], times["burnout"], times["apogee"], times["main"], times["landing"], src)


def _letters(t: np.ndarray, ph: PhaseTimes) -> np.ndarray:
    """The FIRM phase letters (S, M, C, F, L) of the samples ``t`` (n,) [s] from the phase times."""
    out = np.full(t.size, "S")
    out[t >= ph.liftoff] = "M"
    out[t >= ph.burnout] = "C"
    out[t >= ph.apogee] = "F"
    if ph.landing is not None:
        out[t >= ph.landing] = "L"
    return out


def _metadata(mp: Mapping, name: str, standby_pressure: float) -> FlightMetadata:
    """The flight's metadata in SI from the mapping (QNH from the pad altitude when given so:
    the standby pressure ``standby_pressure`` [Pa] reduced to sea level through the site temperature
    with the standard lapse rate, −6.5 K/km)."""
    d = mp.data
    s, r, ref = d["site"], d["rocket"], d["reference"]
    t_site = s["temperature_degC"] + 273.15
    if s["qnh_hpa"] is not None:
        qnh = s["qnh_hpa"] * 100.0
    else:
        h = s["pad_altitude_m"]
        qnh = standby_pressure * ((t_site + 0.0065 * h) / t_site) ** 5.255876
    return FlightMetadata(
        name,
        r["dry_mass_kg"],
        r["cd"],
        r["ref_area_m2"],
        t_site,
        qnh,
        s["wind_speed_m_s"],
        s["wind_from_deg"],
        s["lat_deg"],
        s["lon_deg"],
        ref["landed_lat_deg"],
        ref["landed_lon_deg"],
        ref["apogee_m"],
        s["launch_rod_angle_deg"],
        d["flight"]["date"],
        d["flight"]["description"],
        r["motor"],
        s["temperature_sigma_K"],
    )


def input_names(mp: Mapping) -> dict:
    """{FIRM name: this mapping's name} of the inputs the physics cross-checks name
    (:data:`workbench.problems.post2.rocket_checks.INPUT_NAMES`)."""
    d, f = mp.data, mp.path.name

    def triad(table):
        if d[table]["file"] is None:
            return f"[{table}] of {f}"
        cols = ", ".join(d[table][f"body_{a}"] for a in "xyz")
        return f"{cols} ([{table}] of {f}, unit {d[table]['unit']})"

    return {
        "raw_acceleration_[xyz]_gs": triad("accelerometer"),
        "raw_angular_rate_[xyz]_deg_per_s": triad("gyro"),
        "magnetic_field_[xyz]_microteslas": triad("magnetometer"),
        "launch_site.launch_coordinates": f"[site] lat_deg, lon_deg of {f}",
        "flight_data.landed_coordinates": f"[reference] landed_lat_deg, landed_lon_deg of {f}",
        "launch_site.air_temperature_celsius": f"[site] temperature_degC of {f}",
        "launch_site.wind_speed_kmh": f"[site] wind_speed_m_s of {f}",
        "launch_rod_angle": "[site] launch_rod_angle_deg",
        "rocket_dry_mass_kg": "[rocket] dry_mass_kg",
        "rocket_cross_sectional_area_m2": "[rocket] ref_area_m2",
        "rocket_Cd": "[rocket] cd",
        "--inclination-deg": "[site] inclination_deg",
    }


def import_mapped(
    mapping: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    name: str | None = None,
    obs_rate_hz: float = 10.0,
    t_end_s: float | None = None,
    allow_unhealthy: bool = False,
) -> Path:
    """Import the flight described by the mapping file ``mapping`` into ``out_dir`` (the files of
    ``workbench import airbrakes``: telemetry CSVs, ``flight.json``, ``<name>.toml`` and, with landed
    coordinates, ``<name>_landing.toml``); returns the problem file.  ``name`` default: ``[flight]
    name`` or the mapping's stem; ``obs_rate_hz``, ``t_end_s``, ``allow_unhealthy`` as
    :func:`workbench.problems.post2.importers.airbrakes.import_flight`.  Nothing is written on an error."""
    mp = read_mapping(mapping)
    t, q, phase_values, info = read_mapped(mp)
    master = mp.files[mp.data["accelerometer"]["file"]]
    acc = [c for _, c in (_signed(mp.data["accelerometer"][f"body_{a}"]) for a in "xyz")]
    gyr = tuple(c for _, c in (_signed(mp.data["gyro"][f"body_{a}"]) for a in "xyz"))
    rows = np.arange(t.size)
    fname = str(master["path"])
    units = {"time_column": master["time"], "accel_column": acc[0], "accel_unit": mp.data["accelerometer"]["unit"]}
    # the units first, on the log's first second (the rocket on the pad): the detection needs them
    check_units(fname, t, np.where(t < t[0] + UNIT_CHECK_S, "S", "-"), q["f_B"], rows, **units)
    check_rates(fname, q["w_B"], rows, gyr)
    phases = detect_phases(t, q["f_B"], q["pressure"], mp, phase_values, master["path"])
    letters = _letters(t, phases)
    check_units(fname, t, letters, q["f_B"], rows, **units)  # and on the whole standby
    gaps = list(find_gaps(t, letters))
    for g in info["gaps"]:
        if g["file"] != mp.data["accelerometer"]["file"]:
            k = min(int(np.searchsorted(t, g["t_b_s"])), t.size - 1)
            gaps.append(Gap(g["t_a_s"], g["t_b_s"], g["t_b_s"] - g["t_a_s"], k + 1, str(letters[k])))
    pad = (t >= phases.liftoff - 1.1) & (t < phases.liftoff - 0.1)
    p_standby = float(np.mean(q["pressure"][pad])) if np.any(pad) else float(q["pressure"][0])
    name = name or mp.data["flight"]["name"] or mp.path.stem
    meta = _metadata(mp, name, p_standby)
    log = FlightLog(
        master["path"],
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
        tuple(sorted(gaps, key=lambda g: g.t_a)),
        sum(f["repeated_rows_dropped"] for f in info["files"].values()),
        phase_column=mp.data["phases"]["column"],
        time_column=master["time"],
        accel_columns=", ".join(acc),
        pressure_valid=q["pressure_valid"],
    )
    gnss = read_gnss(mp, phases.liftoff)
    if gnss is not None:
        log = replace(log, gnss=gnss)
    info["phases_s"] = {k: getattr(phases, k) for k in ("liftoff", "burnout", "apogee", "main", "landing")}
    info["phases_source"] = phases.source
    info["phase_rules"] = list(PHASE_RULES)
    site = mp.data["site"]
    return import_log(
        log,
        meta,
        out_dir,
        name=name,
        declination_deg=site["declination_deg"],
        inclination_deg=site["inclination_deg"],
        obs_rate_hz=obs_rate_hz,
        t_end_s=t_end_s,
        allow_unhealthy=allow_unhealthy,
        heading_prior_deg=(site["pad_heading_deg"], site["pad_heading_sigma_deg"]),
        main_s=phases.main,
        source=info,
        input_names=input_names(mp),
        model_error=dict(mp.data["model_error"]),
    )


HELP = "rocket flight log in any CSV layout (a TOML column mapping) -> telemetry + post2 problem file"


def add_arguments(parser) -> None:
    """The ``workbench import csv`` options (an ``argparse`` parser)."""
    parser.add_argument("--mapping", required=True, help="the column mapping file (TOML; workbench/io/FORMATS.md)")
    parser.add_argument("--out", required=True, help="output folder (telemetry CSVs, flight.json, problem files)")
    add_common_arguments(parser)
    parser.add_argument("--name", default=None, help="problem name (default: [flight] name or the mapping's stem)")
    parser.add_argument("--t-end-s", type=float, default=None, help="end the reconstruction this long after launch")


def run(args) -> Path:
    """Run the import from parsed ``args`` (:func:`add_arguments`); returns the problem file."""
    return import_mapped(
        args.mapping,
        args.out,
        name=args.name,
        obs_rate_hz=args.obs_rate_hz,
        t_end_s=args.t_end_s,
        allow_unhealthy=args.allow_unhealthy,
    )
