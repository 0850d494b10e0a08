"""The flight-log import shared by the rocket importers (``workbench import airbrakes`` and
``workbench import csv``): a log already read into SI (:class:`FlightLog`, its metadata
:class:`FlightMetadata`) becomes the workbench's telemetry files and a post2 problem file.

:func:`import_log` — the pad alignment and the boost integrated from the IMU
(:mod:`workbench.problems.post2.rocket`), the physics cross-checks
(:mod:`workbench.problems.post2.rocket_checks`; an ERROR stops the import unless allowed), the
coast/descent observation files (pressure, |specific force|: block means at ``obs_rate_hz`` that never
span a gap — :func:`find_gaps`, :func:`block_means` — with their weights), the log in the workbench's
units, the flight computer's own solution as a reference (when the log has one), ``events.csv``,
``flight.json`` and ``<name>.toml`` (+ ``<name>_landing.toml`` with landed coordinates), written into a
temporary folder moved into place at the end: an error leaves nothing.  :func:`check_units` and
:func:`check_rates` refuse a log whose values are not in their declared units.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.core.bodies import EARTH, G0
from workbench.io.telemetry import TelemetryError, write_events, write_telemetry
from workbench.io.units import likely_unit

__all__ = [
    "PHASES",
    "GnssFixes",
    "TEMPERATURE_SIGMA_K",
    "Gap",
    "FlightLog",
    "FlightMetadata",
    "MAX_MEDIAN_STEP_S",
    "MIN_FIELD_T",
    "STANDBY_G_BAND",
    "MAX_RATE_RAD_S",
    "check_units",
    "check_rates",
    "find_gaps",
    "block_means",
    "import_log",
    "add_common_arguments",
]

#: flight-phase letters of the FIRM log: standby, motor, coast, free fall / parachute, landed
PHASES = {"S": "standby", "M": "motor", "C": "coast", "F": "descent", "L": "landed"}


@dataclass(frozen=True)
class Gap:
    """A gap in the log: samples at ``t_a`` and ``t_b`` [s, log clock] ``dt = t_b − t_a`` apart,
    ``row`` the 1-based data row after it, ``phase`` the phase letter of that row."""

    t_a: float
    t_b: float
    dt: float
    row: int
    phase: str


@dataclass(frozen=True, eq=False)
class FlightLog:
    """A FIRM log in SI: ``t`` (n,) [s, log clock]; ``letters`` (n,) phase letters; ``f_B`` (n, 3)
    specific force [m/s²] and ``w_B`` (n, 3) body rate [rad/s] in the IMU's frame B; ``mag_B``
    (n, 3) [T]; ``pressure`` (n,) [Pa]; ``temperature`` (n,) [K] (the board's, not the air's);
    reference solution of the flight computer: ``ref_h`` (n,) [m] its altitude — a standard-day
    pressure altitude (:func:`workbench.problems.post2.rocket.firm_altitude`) whose zero is its
    initial pressure, not the pad at launch (it reads +0.0, +2.0, +7.6 m on the pad at launch on
    flights 1, 3, 4) —, ``ref_vz`` (n,)
    [m/s] up, ``ref_q`` (n, 4) its quaternion scalar-last (as logged, frame not documented);
    ``gaps`` the gaps (:func:`find_gaps`); ``repeated_rows`` how many rows repeated the previous
    packet exactly (dropped); ``path`` the file.  A log of another flight computer
    (:mod:`workbench.problems.post2.importers.mapped`) may lack ``mag_B``, ``temperature`` and the
    reference (None); its ``letters`` are then the detected phases (``phase_column`` None), and
    ``time_column`` / ``accel_columns`` name its own columns in messages; ``pressure_valid`` (n,) False
    where the pressure was interpolated across a gap of the barometer's own file (None: all valid):
    those samples are not observed."""

    path: Path
    t: np.ndarray
    letters: np.ndarray
    f_B: np.ndarray
    w_B: np.ndarray
    mag_B: np.ndarray | None
    pressure: np.ndarray
    temperature: np.ndarray | None
    ref_h: np.ndarray | None
    ref_vz: np.ndarray | None
    ref_q: np.ndarray | None
    gaps: tuple[Gap, ...]
    repeated_rows: int = 0
    phase_column: str | None = "state_letter"
    time_column: str = "timestamp_seconds"
    accel_columns: str = "raw_acceleration_[xyz]_gs"
    pressure_valid: np.ndarray | None = None
    gnss: GnssFixes | None = None

    def phase_start(self, letter: str) -> float:
        """Log time [s] of the first row with phase ``letter``; a TelemetryError (a ValueError) naming
        the last row if the phase is absent."""
        k = np.flatnonzero(self.letters == letter)
        if k.size == 0:
            last = self.letters[-1] if self.letters.size else "-"
            raise TelemetryError.single(
                self.path,
                f"the log has no phase '{letter}' ({PHASES[letter]}); it ends in phase '{last}' "
                f"({PHASES.get(str(last), '?')}) at {self.t[-1] if self.t.size else float('nan'):.3f} s: "
                "a truncated log? the import needs the boost, the coast and the descent's start",
                column=self.phase_column or self.time_column,
                row=int(self.t.size),
            )
        return float(self.t[k[0]])


#: a flight log samples faster than this step [s] (median): a slower one is in other units (ms)
MAX_MEDIAN_STEP_S = 1.0
#: a magnetometer reading less than this on the pad [T] is dead or missing (the Earth's surface field
#: is 22–67 µT)
MIN_FIELD_T = 1e-6
#: the standby specific force is 1 g: its median outside this band [g] is a unit error
STANDBY_G_BAND = (0.8, 1.2)
#: no MEMS gyro of a flight computer measures beyond ±4000 deg/s (the widest full scale sold): a rate
#: above this [rad/s] is a unit or scale error, not a measurement
MAX_RATE_RAD_S = float(np.radians(5000.0))


def check_units(
    fname: str,
    t: np.ndarray,
    letters: np.ndarray,
    f: np.ndarray,
    rows: np.ndarray,
    *,
    time_column: str = "timestamp_seconds",
    accel_column: str = "raw_acceleration_x_gs",
    accel_unit: str = "g",
) -> None:
    """Refuse a log whose time or accelerations are in other units than declared (the column names
    of a FIRM log; ``accel_unit`` of ``accel_column`` otherwise): the median time step above
    MAX_MEDIAN_STEP_S (milliseconds), the standby rows' median |specific force| outside
    STANDBY_G_BAND × 1 g (m/s², mg).  ``t`` (n,) [s], ``f`` (n, 3) [m/s²] of the kept rows ``rows``
    (n,) (0-based data rows, for the message)."""
    if t.size >= 3:
        step = float(np.median(np.diff(t)))
        if step > MAX_MEDIAN_STEP_S:
            raise TelemetryError.single(
                fname,
                f"median time step {step:.4g} s ({1.0 / step:.3g} Hz): a flight log samples at 10 Hz or more — "
                f"the time looks like milliseconds ({step / 1000.0:.4g} s if so); convert it to seconds",
                column=time_column,
            )
    standby = np.flatnonzero(letters == "S")
    if standby.size >= 3:
        g = float(np.median(np.linalg.norm(f[standby], axis=1))) / G0
        lo, hi = STANDBY_G_BAND
        if not lo <= g <= hi:
            other = likely_unit(g, accel_unit)
            if accel_unit != "g" and other is not None:
                why = f"the acceleration columns look like {other}, not {accel_unit}"
            elif 0.8 * G0 <= g <= 1.2 * G0 or 800.0 <= g <= 1200.0:
                why = f"the acceleration columns look like {'m/s²' if g < 100.0 else 'mg'}, not g"
            else:
                axes = ", ".join(
                    f"{c} {v:+.3g}" for c, v in zip("xyz", np.median(f[standby], axis=0) / G0, strict=True)
                )
                why = f"per axis (median, g) {axes}: a dead, missing or mis-scaled axis?"
            raise TelemetryError.single(
                fname,
                f"the standby rows' specific force is {g:.4g} g (median of |a| over {standby.size} rows, expected 1 g "
                f"at rest): {why}",
                column=accel_column,
                row=int(rows[standby[0]]) + 1,
            )


def check_rates(fname: str, w: np.ndarray, rows: np.ndarray, columns: tuple[str, ...] | None = None) -> None:
    """Refuse a log whose angular rates ``w`` (n, 3) [rad/s, as read in their declared unit] exceed
    MAX_RATE_RAD_S anywhere: beyond any flight computer's gyro range, a column in other units
    (mdeg/s) or scaled.  The message names the column (``columns`` (3,), default the FIRM names),
    the first such row and the other columns' largest rate for comparison; ``rows`` (n,) the 0-based
    data rows of ``w``."""
    columns = columns or tuple(f"raw_angular_rate_{c}_deg_per_s" for c in "xyz")
    peak = np.max(np.abs(w), axis=0) if w.size else np.zeros(3)
    for i in np.flatnonzero(peak > MAX_RATE_RAD_S):
        col = columns[i]
        k = int(np.flatnonzero(np.abs(w[:, i]) > MAX_RATE_RAD_S)[0])
        others = ", ".join(f"{'xyz'[j]} {np.degrees(peak[j]):.4g}" for j in range(3) if j != i)
        raise TelemetryError.single(
            fname,
            f"angular rate {np.degrees(w[k, i]):.6g} deg/s: beyond any flight computer's gyro range "
            f"(±{np.degrees(MAX_RATE_RAD_S):.0f} deg/s); the largest of the other axes: {others} deg/s — the "
            "column looks scaled or in other units (mdeg/s?)",
            column=col,
            row=int(rows[k]) + 1,
        )


def find_gaps(t: np.ndarray, letters: np.ndarray, gap_factor: float = 3.0) -> tuple[Gap, ...]:
    """Steps of t (n,) [s] longer than ``gap_factor`` × the median step, as :class:`Gap` (row
    1-based of the sample after the gap; ``phase`` its letter)."""
    if t.size < 2:
        return ()
    dt = np.diff(t)
    lim = gap_factor * float(np.median(dt))
    return tuple(
        Gap(float(t[i]), float(t[i + 1]), float(dt[i]), int(i) + 2, str(letters[i + 1]))
        for i in np.flatnonzero(dt > lim)
    )


#: default 1σ [K] of the air column's mean temperature (pad to apogee) about the model's, the site's
#: air temperature with the standard −6.5 K/km lapse: the lapse rate of the lowest 2 km ranges from
#: dry-adiabatic (−9.8 K/km) to an inversion (±3 K on the column's mean at 1.5 km), humid air is up to
#: 3 K warmer virtually, and a surface reading is good to ~1 K.  It becomes the ``baro_scale`` consider
#: parameter's 1σ, σ_T / T (the hypsometric equation: a column 1 % warmer is 1 % taller).
TEMPERATURE_SIGMA_K = 4.0


@dataclass(frozen=True)
class GnssFixes:
    """GNSS fixes relative to the pad: ``t`` (k,) [s, the log's clock], ``enu`` (k, 3) [m east, north,
    up of the pad's own fix: the median of the fixes before liftoff], ``sigma_h`` / ``sigma_v`` (k,) [m]
    horizontal (per axis) and vertical 1σ; ``info`` JSON-ready (the file, the pad fix, counts)."""

    t: np.ndarray
    enu: np.ndarray
    sigma_h: np.ndarray
    sigma_v: np.ndarray
    info: dict


@dataclass(frozen=True)
class FlightMetadata:
    """The flight's ``metadata.json`` entry in SI: ``mass`` [kg], ``cd`` [-], ``area`` [m²];
    site ``temperature`` [K], ``qnh`` [Pa] (the reported air pressure, read as reduced to sea level),
    ``wind_speed`` [m/s], ``wind_from_deg`` (direction the wind blows from, deg clockwise from north);
    ``launch_lat_deg``/``launch_lon_deg``, ``landed_lat_deg``/``landed_lon_deg``, ``apogee`` [m],
    ``rod_angle_deg``, ``date`` (ISO string), ``description``, ``motor`` (designation or None),
    ``temperature_sigma`` [K] (1σ of the air column's mean temperature about the site's with the
    standard lapse: the ``baro_scale`` consider parameter; default
    :data:`TEMPERATURE_SIGMA_K`).  The
    scoring references (landed coordinates, apogee) and the rod angle may be None (unknown: a
    column-mapped import without them; their checks and the ``_landing`` variant are then skipped)."""

    name: str
    mass: float
    cd: float
    area: float
    temperature: float
    qnh: float
    wind_speed: float
    wind_from_deg: float
    launch_lat_deg: float
    launch_lon_deg: float
    landed_lat_deg: float | None
    landed_lon_deg: float | None
    apogee: float | None
    rod_angle_deg: float | None
    date: str
    description: str
    motor: str | None = None
    temperature_sigma: float = TEMPERATURE_SIGMA_K


def block_means(t: np.ndarray, v: np.ndarray, t0: float, t1: float, rate_hz: float, gaps: tuple[Gap, ...]):
    """Means of v (n, k) over consecutive blocks of 1/rate_hz seconds in [t0, t1]; a block never
    spans a gap (the block is cut at the gap).  Returns (t_mean (m,), v_mean (m, k), count (m,))."""
    sel = (t >= t0) & (t <= t1)
    ts, vs = t[sel], v[sel]
    edges = np.floor((ts - t0) * rate_hz).astype(int)
    for g in gaps:  # a new block after every gap
        edges = edges + 1000000 * (ts >= g.t_b)
    _, start, count = np.unique(edges, return_index=True, return_counts=True)
    tm = np.add.reduceat(ts, start) / count
    vm = np.add.reduceat(vs, start, axis=0) / count[:, None]
    return tm, vm, count


def import_log(
    log: FlightLog,
    meta: FlightMetadata,
    out_dir: str | os.PathLike,
    *,
    name: str,
    declination_deg: float = 0.0,
    inclination_deg: float | None = None,
    obs_rate_hz: float = 10.0,
    t_end_s: float | None = None,
    allow_unhealthy: bool = False,
    heading_prior_deg: tuple[float | None, float] | None = None,
    main_s: float | None = None,
    source: dict | None = None,
    input_names: dict | None = None,
    model_error: dict | None = None,
) -> Path:
    """The import of a flight log already read into SI (:func:`read_log`, or the column-mapped reader
    :func:`workbench.problems.post2.importers.mapped.read_mapped`): the boost, the checks and the files
    of :func:`import_flight` (whose arguments these are).  ``heading_prior_deg`` (bearing [deg] or None
    for unknown, 1σ [deg]) is the pad heading of a log without a magnetometer (``log.mag_B`` None);
    ``main_s`` [s, log clock] the main parachute's opening instead of the detected one; ``source`` a
    JSON-ready record of where the log came from (kept in ``flight.json``); ``input_names`` {FIRM name:
    this import's name} of the inputs the checks' messages name
    (:data:`workbench.problems.post2.rocket_checks.INPUT_NAMES`; None: the FIRM log's); ``model_error``
    {level name: value or None} the observations' model-error levels a user overrides (None: the FIRM
    flights' measured levels)."""
    # imported here: the command line builds its parser from this module and stays light
    from workbench.estimation.health import ERROR, UnhealthyError, health_report
    from workbench.problems.post2 import rocket, rocket_checks

    out = Path(out_dir)
    phase_col = log.phase_column or log.time_column
    if not obs_rate_hz > 0.0:
        raise TelemetryError.single(log.path, f"--obs-rate-hz {obs_rate_hz:g}: the observation rate must be positive")
    t_launch = log.phase_start("M")
    log.phase_start("C"), log.phase_start("F")  # the coast and the descent's start are needed
    t = log.t - t_launch  # seconds from launch (the first motor row)
    for g in log.gaps:
        if log.phase_start("M") <= g.t_a and (g.phase in ("M",) or g.t_b <= log.phase_start("C") + 0.5):
            raise TelemetryError.single(
                log.path,
                f"gap of {g.dt:.3f} s inside the boost: the IMU cannot be integrated across it",
                column=log.time_column,
                row=g.row,
            )
    pad_field = (
        float(np.median(np.linalg.norm(log.mag_B[log.letters == "S"], axis=1)))
        if log.mag_B is not None and np.any(log.letters == "S")
        else 0.0
    )
    if log.mag_B is not None and not pad_field > MIN_FIELD_T:
        raise TelemetryError.single(
            log.path,
            f"the magnetometer reads {pad_field * 1e6:.3g} µT on the pad (median |B| of the standby rows; the Earth's "
            "field is 22–67 µT): a dead or missing magnetometer — the pad heading cannot be found",
            column="magnetic_field_x_microteslas",
        )
    try:
        fl = rocket.reconstruct_boost(
            t,
            log.letters,
            log.f_B,
            log.w_B,
            log.mag_B,
            log.pressure,
            meta,
            declination_deg,
            inclination_deg,
            **({} if heading_prior_deg is None else {"heading_prior_deg": heading_prior_deg}),
        )
    except ValueError as e:  # the pad window: too little standby data before the motor letter
        raise TelemetryError.single(
            log.path, str(e), column=phase_col, row=int(np.argmax(log.letters == "M")) + 1
        ) from None
    # the drogue opens at the ejection shock (the descent letter can lag it: flight 4, 3.5 s)
    t_apogee = rocket.detect_ejection(t, log.f_B, log.phase_start("C") - t_launch, log.phase_start("F") - t_launch)
    try:
        t_land = log.phase_start("L") - t_launch
    except ValueError:
        t_land = float(t[-1])
    t_end = min(t_land, t_end_s) if t_end_s is not None else t_land
    if main_s is None:
        t_main = rocket.detect_main_deploy(t, log.pressure, log.f_B, fl.atmosphere, t_apogee, t_end)
    else:
        t_main = float(main_s) - t_launch
    t0 = fl.t_start
    if not (np.all(np.isfinite(fl.p_M)) and np.all(np.isfinite(fl.v_M))):
        raise TelemetryError.single(
            log.path, "the boost integrated from the IMU is not finite (a degenerate pad alignment?)", column=phase_col
        )
    if not t_end > t0 + 1.0:
        raise TelemetryError.single(
            log.path, f"the reconstruction span {t0:.2f} .. {t_end:.2f} s after launch is too short", column=phase_col
        )
    # the coast drag multiplier's prior from the first measured coast drag at the burnout state
    r_b = float(np.linalg.norm(fl.p_M))
    v_rel = float(np.linalg.norm(fl.v_M - np.cross([0.0, 0.0, EARTH.rotation_rate], fl.p_M)))
    rho = float(fl.atmosphere.density(max(r_b - EARTH.reference_radius, 0.0)))
    ca0 = rocket.initial_ca_multiplier(t, log.f_B, t0, v_rel, rho, meta)
    ca0_raw = rocket.initial_ca_multiplier(t, log.f_B, t0, v_rel, rho, meta, clip=False)
    health = rocket_checks.import_checks(
        log,
        meta,
        fl,
        t,
        t_ej=t_apogee,
        t_main=t_main,
        ca0_unclipped=ca0_raw,
        inclination_deg=inclination_deg,
        obs_rate_hz=obs_rate_hz,
        names=input_names,
    )
    if not allow_unhealthy and any(c["status"] == ERROR for c in health["checks"]):
        from workbench.estimation.health import Check

        raise UnhealthyError(f"import of {log.path}", health_report([Check(**c) for c in health["checks"]]))
    # written into a temporary folder beside ``out``, moved into place at the end: a failure leaves nothing
    final, out = out, _staging_dir(out)
    try:
        path = _write_import(
            out,
            log,
            meta,
            fl,
            t,
            t_launch,
            (t0, t_end, t_apogee, t_main),
            ca0,
            health,
            name,
            declination_deg,
            obs_rate_hz,
            source,
            input_names,
            model_error,
        )
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise
    _commit_dir(out, final)
    return final / path.name


def _staging_dir(out: Path) -> Path:
    """A new empty folder ``.<out name>.<pid>.partial`` beside ``out`` to write the import into (named
    so a reader sees it is partial); the folders an import killed outright (SIGKILL) left behind —
    their process gone — are removed first."""
    out.parent.mkdir(parents=True, exist_ok=True)
    for old in out.parent.glob(f".{out.name}.*.partial"):
        pid = old.name[len(out.name) + 2 : -len(".partial")]
        if pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(old, ignore_errors=True)
    tmp = out.parent / f".{out.name}.{os.getpid()}.partial"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    return tmp


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (signal 0 probes without sending anything)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _commit_dir(tmp: Path, out: Path) -> None:
    """Move the finished import ``tmp`` to ``out``: a rename when ``out`` does not exist (or is an empty
    folder), else each file replaced in place (the other files of an existing ``out`` are kept)."""
    if out.is_dir() and not any(out.iterdir()):
        out.rmdir()
    if not out.exists():
        os.replace(tmp, out)
        return
    for f in tmp.iterdir():
        os.replace(f, out / f.name)
    tmp.rmdir()


def _write_import(
    out, log, meta, fl, t, t_launch, times, ca0, health, name, declination_deg, obs_rate_hz, source=None, names=None,
    model_error=None,
) -> Path:  # fmt: skip
    """Write the import's files into the folder ``out`` (:func:`import_flight` computed every input:
    ``times`` = (t0, t_end, t_apogee, t_main) [s after launch]; ``model_error`` the levels overriding
    :func:`~workbench.problems.post2.rocket.pressure_sigma`'s and ``accel_sigma``'s); returns the problem file."""
    from workbench.problems.post2 import rocket

    t0, t_end, t_apogee, t_main = times
    # observations: block means after burnout, never across a gap
    gaps_rel = tuple(Gap(g.t_a - t_launch, g.t_b - t_launch, g.dt, g.row, g.phase) for g in log.gaps)
    pv = np.ones(t.size, dtype=bool) if log.pressure_valid is None else log.pressure_valid
    tp, pm, cnt = block_means(t[pv], log.pressure[pv][:, None], t0, t_end, obs_rate_hz, gaps_rel)
    ta, am, _ = block_means(t, np.linalg.norm(log.f_B, axis=1)[:, None], t0, t_end, obs_rate_hz, gaps_rel)
    write_telemetry(
        out / "pressure.csv", tp, {"p": (pm[:, 0], "Pa")}, meta={"source": log.path.name, "samples_per_block": "varies"}
    )
    sig_p = rocket.pressure_sigma(
        tp, log.phase_start("C") - t_launch, t_apogee, fl.pad_pressure_std, cnt, t_main, levels=model_error
    )
    write_telemetry(
        out / "pressure_weights.csv", tp, {"p": (1.0 / sig_p**2, "1")}, meta={"meaning": "W = 1/sigma^2 [1/Pa^2]"}
    )
    write_telemetry(out / "accel.csv", ta, {"a": (am[:, 0], "m/s^2")}, meta={"source": log.path.name})
    fn = np.linalg.norm(log.f_B, axis=1)
    _, _, cnt_a = block_means(t, fn[:, None], t0, t_end, obs_rate_hz, gaps_rel)
    sig_a = rocket.accel_sigma(ta, t_apogee, t_main, rocket.local_noise(ta, t, fn), cnt_a, levels=model_error)
    write_telemetry(
        out / "accel_weights.csv", ta, {"a": (1.0 / sig_a**2, "1")}, meta={"meaning": "W = 1/sigma^2 [s^4/m^2]"}
    )
    # the raw IMU and the flight computer's reference solution (for scoring and drawing, not observed)
    imu_cols = {
        **{f"f.{c}": (log.f_B[:, i], "g") for i, c in enumerate("xyz")},
        **{f"w.{c}": (log.w_B[:, i], "deg/s") for i, c in enumerate("xyz")},
    }
    if log.mag_B is not None:
        imu_cols |= {f"mag.{c}": (log.mag_B[:, i], "uT") for i, c in enumerate("xyz")}
    imu_cols["pressure"] = (log.pressure, "Pa")
    if log.temperature is not None:
        imu_cols["board_temperature"] = (log.temperature, "degC")
    write_telemetry(
        out / "imu.csv",
        t,
        imu_cols,
        meta={"source": log.path.name, "frame": "IMU axes as logged", "time_zero": "first motor row"},
    )
    if log.ref_h is not None and log.ref_vz is not None and log.ref_q is not None:
        write_telemetry(
            out / "reference.csv",
            t,
            {
                "h": (log.ref_h, "m"),
                "vz": (log.ref_vz, "m/s"),
                **{f"q{c}": (log.ref_q[:, i], "1") for i, c in enumerate("xyzw")},
            },
            meta={"source": log.path.name, "meaning": "the flight computer's own solution (reference, not observed)"},
        )
    gnss_used = _write_gnss(out, log.gnss, t_launch, t0, t_end)
    events = [(float(t[0]), "log start")]
    letters = log.letters
    how = "" if log.phase_column else ", detected"
    for k in np.flatnonzero(letters[1:] != letters[:-1]) + 1:
        events.append((float(t[k]), f"phase {letters[k]} ({PHASES[letters[k]]}{how})"))
    for g in gaps_rel:
        events.append((g.t_a, f"gap {g.dt:.3f} s before row {g.row}"))
    events.append((t_apogee, "drogue ejection (detected)"))
    if t_main is not None:
        events.append((t_main, "main parachute (detected)"))
    write_events(out / "events.csv", sorted(events))
    info = {
        "initial_ca_multiplier": ca0,
        "flight": meta.name,
        "log": log.path.name,
        "t_launch_log_s": t_launch,
        "t_start_s": t0,
        "t_apogee_letter_s": log.phase_start("F") - t_launch,
        "t_ejection_s": t_apogee,
        "t_main_s": t_main,
        "t_end_s": t_end,
        "rows": int(t.size),
        "repeated_rows_dropped": log.repeated_rows,
        "gaps": [{"t_a_s": g.t_a, "t_b_s": g.t_b, "dt_s": g.dt, "row": g.row, "phase": g.phase} for g in gaps_rel],
        "declination_deg": declination_deg,
        "pad": fl.pad_info,
        "burnout": fl.burnout_info,
        "metadata": meta.__dict__,
        "observation_rate_hz": obs_rate_hz,
        "model_error_overrides": {k: v for k, v in (model_error or {}).items() if v is not None},
        "health_checks": health,
    }
    if source is not None:
        info["source"] = source
    if log.gnss is not None:
        info["gnss"] = {**log.gnss.info, "observed_in_span": gnss_used}
    if names is not None:
        info["input_names"] = names
    (out / "flight.json").write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    path = out / f"{name}.toml"
    # the pad's events for the rocket results: burnout (first coast row) and touchdown when the span reaches it
    t_burnout = log.phase_start("C") - t_launch
    t_touchdown = t_end if "L" in set(log.letters) and t_end >= log.phase_start("L") - t_launch - 1e-9 else None
    marks = {"t_burnout": t_burnout, "t_touchdown": t_touchdown, "gnss": gnss_used > 0}
    path.write_text(
        rocket.problem_file(name, meta, fl, t0, t_end, t_apogee, t_main, ca0=ca0, **marks), encoding="utf-8"
    )
    if meta.landed_lat_deg is None or meta.landed_lon_deg is None:
        return path  # no landed coordinates: no variant that observes them
    # the variant that also observes the landed coordinates (winds under the parachutes)
    p_land = rocket.landing_point_inertial(meta, fl.h_pad, t_end)
    write_telemetry(
        out / "landing.csv",
        np.array([t_end - 1e-3]),  # 1 ms before the touchdown letter: inside the span
        {c: (np.array([p_land[i]]), "m") for i, c in enumerate("xyz")},
        meta={"meaning": "metadata landed coordinates at touchdown, inertial frame M, pad elevation"},
    )
    text = rocket.problem_file(f"{name}_landing", meta, fl, t0, t_end, t_apogee, t_main, landing=True, ca0=ca0, **marks)
    (out / f"{name}_landing.toml").write_text(text, encoding="utf-8")
    return path


def _write_gnss(out: Path, fixes: GnssFixes | None, t_launch: float, t0: float, t_end: float) -> int:
    """Write the GNSS fixes inside the reconstructed span [t0, t_end] [s after launch] as
    ``gnss.csv`` (east/north/up of the pad [m]) and ``gnss_weights.csv`` (1/σ²); returns how many."""
    if fixes is None:
        return 0
    tr = fixes.t - t_launch
    k = (tr >= t0) & (tr <= t_end)
    if not np.any(k):
        return 0
    e, n, u = fixes.enu[k].T
    write_telemetry(
        out / "gnss.csv",
        tr[k],
        {"e": (e, "m"), "n": (n, "m"), "u": (u, "m")},
        meta={"source": fixes.info.get("file", ""), "meaning": "GNSS fix: east/north/up of the pad's own fix"},
    )
    wh, wv = 1.0 / fixes.sigma_h[k] ** 2, 1.0 / fixes.sigma_v[k] ** 2
    write_telemetry(
        out / "gnss_weights.csv",
        tr[k],
        {"e": (wh, "1"), "n": (wh, "1"), "u": (wv, "1")},
        meta={"meaning": "W = 1/sigma^2 [1/m^2]"},
    )
    return int(np.sum(k))


def add_common_arguments(parser) -> None:
    """The options every flight-log import takes (an ``argparse`` parser): ``--obs-rate-hz`` [Hz] of
    the block-mean observations and ``--allow-unhealthy``."""
    parser.add_argument("--obs-rate-hz", type=float, default=10.0, help="rate of the block-mean observations")
    parser.add_argument(
        "--allow-unhealthy",
        action="store_true",
        help="write the import even when a physics cross-check is ERROR (the run's verdict then carries it)",
    )
