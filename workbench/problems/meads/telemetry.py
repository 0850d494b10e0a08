"""MEADS telemetry: the files a user supplies, read and checked.

Streams (:data:`STREAMS`, scenario ``[telemetry]``; the synthetic scenario writes the same names):

* ``pressures.csv`` — ``time [s]`` and one column per port of the vehicle file, named as the port
  (``P1 [Pa]`` …; any pressure unit, converted to Pa on reading).  A missing port column, a unit that
  is not a pressure, a NaN/inf or unparsable cell, a repeated or backward time are errors naming the
  file, column and row (:class:`~workbench.io.telemetry.TelemetryError`).  **Empty cells** are
  telemetry dropouts: the port is left out of those samples' fits and the dropout is logged as a
  degradation (file, column, rows).
* ``imu.csv`` — ``time [s]``, ``f_x, f_y, f_z`` specific force (acceleration unit) and
  ``w_x, w_y, w_z`` body rate (angular-rate unit), body axes B (+x out of the nose).
* ``initial_state.toml`` — ``[state]``: ``time_s``, ``p_M_m`` (3), ``v_M_mps`` (3) in the
  Mars-centred inertial frame M (+Z the pole), ``q_M_B`` (4, scalar-last Hamilton, body → M),
  ``sigma_position_m``, ``sigma_velocity_mps``, ``sigma_attitude_deg`` (1σ per axis).

Units that stay plausible to the parser are caught here too, each an error naming the file, column
or key and the likely unit: an initial position or velocity off the entry envelope
(:data:`RADIUS_ENVELOPE_M`, :data:`SPEED_ENVELOPE_MPS`; km written as m), a pressure or IMU time
column whose span differs from the other stream's (ms written as s), a port whose readings are a
unit factor away from the other ports' (:data:`PORT_RATIO_MAX`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.core.bodies import MARS
from workbench.io.scenario import ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, load_file
from workbench.io.telemetry import TelemetryError, read_telemetry
from workbench.models.flush_airdata import FadsVehicle

__all__ = [
    "STREAMS",
    "INITIAL_STATE_SCHEMA",
    "InitialState",
    "MeadsTelemetry",
    "telemetry_paths",
    "read_initial_state",
    "write_initial_state",
    "read_meads_telemetry",
    "check_port_scales",
    "check_time_spans",
    "true_runs",
]

STREAMS = ("pressures", "imu", "initial_state")
IMU_COLUMNS = ("f_x", "f_y", "f_z", "w_x", "w_y", "w_z")

#: the initial state's distance from the centre of Mars [m] that an entry can have: from 10 km below
#: the reference sphere (the Hellas floor is 7 km below it) to 1000 km above it (entry interfaces
#: are defined at 125–130 km)
RADIUS_ENVELOPE_M = (MARS.reference_radius - 10e3, MARS.reference_radius + 1000e3)
#: the initial state's inertial speed [m/s] a flush-air-data reduction can start from: the ports
#: need at least low-supersonic flow (Mach 1 is about 230 m/s on Mars; Mars rotates at up to
#: 241 m/s) and nothing enters Mars faster than a hyperbolic arrival (~ 12 km/s)
SPEED_ENVELOPE_MPS = (100.0, 15e3)
#: a forebody port's pressure relative to the median of all ports at high pressure lies within
#: [1/PORT_RATIO_MAX, PORT_RATIO_MAX]: on a blunt sphere-cone with |α| ≤ 30° the modified-Newtonian
#: pressure of the least-loaded port is ≥ 0.3 of the stagnation pressure; the unit factors a
#: mislabelled pressure column carries are 100 (hPa, mbar), 133 (torr), 1000 (kPa), 6895 (psi)
PORT_RATIO_MAX = 10.0
#: the pressure and IMU files' time spans may differ by at most this factor (either way)
SPAN_RATIO_MAX = 2.0
#: the known pressure-unit factors, to name the likely one in a message
_PRESSURE_FACTORS = {100.0: "hPa/mbar", 133.322: "torr/mmHg", 1e3: "kPa", 6894.76: "psi", 1e5: "bar", 1e6: "MPa"}

#: ``initial_state.toml``: the navigation state at the first IMU time (a file kind of its own).
INITIAL_STATE_SCHEMA = Schema(
    "meads_initial_state",
    "MEADS initial navigation state",
    (
        Table(
            "state",
            "the navigation state at the first IMU time (Mars-centred inertial frame M, +Z the pole)",
            (
                Key("time_s", "float", REQUIRED, "s", "time of the state", ge=0.0),
                Key("p_M_m", "list", REQUIRED, "m", "position in M, 3 numbers"),
                Key("v_M_mps", "list", REQUIRED, "m/s", "velocity in M, 3 numbers"),
                Key("q_M_B", "list", REQUIRED, "", "attitude body -> M, scalar-last Hamilton unit quaternion (4)"),
                Key("sigma_position_m", "float", REQUIRED, "m", "1-sigma per axis", ge=0.0),
                Key("sigma_velocity_mps", "float", REQUIRED, "m/s", "1-sigma per axis", ge=0.0),
                Key("sigma_attitude_deg", "float", REQUIRED, "deg", "1-sigma per axis", ge=0.0),
            ),
        ),
    ),
    noun="MEADS initial-state file",
    intro="Keys of the MEADS `initial_state.toml` (written by a synthetic run; a user supplies the same)",
)


@dataclass(frozen=True)
class InitialState:
    """Navigation state at ``t`` [s]: ``p_M`` [m], ``v_M`` [m/s], ``q_M_B`` (4,), 1σ ``sigma_p`` [m],
    ``sigma_v`` [m/s], ``sigma_att`` [rad] per axis."""

    t: float
    p_M: np.ndarray
    v_M: np.ndarray
    q_M_B: np.ndarray
    sigma_p: float
    sigma_v: float
    sigma_att: float


@dataclass(frozen=True)
class MeadsTelemetry:
    """The read telemetry in SI: pressures ``p`` (n, m) [Pa] at ``t_p`` (NaN = dropout), ``ports``
    (m,) names in vehicle order, ``pressure_file``; IMU ``t_imu``, ``f_B`` [m/s²], ``w_B`` [rad/s];
    ``initial``; ``degradations``: logged findings (one line each, file/column/rows); ``imu_file``
    and ``imu_units`` ({column: unit as read}) name the IMU file and its columns in messages."""

    t_p: np.ndarray
    p: np.ndarray
    ports: tuple[str, ...]
    pressure_file: str
    pressure_units: dict
    t_imu: np.ndarray
    f_B: np.ndarray
    w_B: np.ndarray
    initial: InitialState
    degradations: tuple[str, ...]
    imu_file: str = ""
    imu_units: dict | None = None


def telemetry_paths(files, scenario_file: Path) -> dict[str, Path]:
    """The ``[telemetry]`` files of a user scenario (``files``: the settings'
    :class:`~workbench.problems.meads.config.TelemetryFiles`, absolute paths); a missing key or
    file is a :class:`ScenarioError` naming ``scenario_file`` and the key."""
    out = {}
    for k in STREAMS:
        p = getattr(files, k)
        if p is None:
            raise ScenarioError(
                scenario_file, f"telemetry.{k}", "missing: a meads scenario needs pressures, imu, initial_state"
            )
        if not p.exists():
            raise ScenarioError(scenario_file, f"telemetry.{k}", f"file not found: {p}")
        out[k] = p
    return out


def write_initial_state(path: Path, st: InitialState, comment: str = "") -> Path:
    """Write ``initial_state.toml`` (the format of the module docstring)."""

    def vec(a):
        return "[" + ", ".join(f"{float(x):.12g}" for x in a) + "]"

    text = (f"# {comment}\n" if comment else "") + (
        "[state]\n"
        f"time_s = {st.t:.9g}\n"
        f"p_M_m = {vec(st.p_M)}\n"
        f"v_M_mps = {vec(st.v_M)}\n"
        f"q_M_B = {vec(st.q_M_B)}\n"
        f"sigma_position_m = {st.sigma_p:.9g}\n"
        f"sigma_velocity_mps = {st.sigma_v:.9g}\n"
        f"sigma_attitude_deg = {math.degrees(st.sigma_att):.9g}\n"
    )
    path = Path(path)
    path.write_text(text, encoding="utf-8")
    return path


def read_initial_state(path: Path) -> InitialState:
    """Read ``initial_state.toml`` (:data:`INITIAL_STATE_SCHEMA`); an unknown, missing or bad key is
    a :class:`ScenarioError` naming the file and key (the vector lengths and the quaternion's norm
    are checked here, after validation)."""
    path = Path(path)
    st = load_file(path, INITIAL_STATE_SCHEMA)["state"]

    def arr(key, n):
        v = st[key]
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            a = None
        if a is None or a.shape != (n,) or not np.all(np.isfinite(a)):
            raise ScenarioError(path, f"state.{key}", f"needs {n} finite numbers, got {v!r}")
        return a

    q = arr("q_M_B", 4)
    if abs(np.linalg.norm(q) - 1.0) > 1e-3:
        raise ScenarioError(path, "state.q_M_B", f"not a unit quaternion (norm {np.linalg.norm(q):.6f})")
    p_M, v_M = arr("p_M_m", 3), arr("v_M_mps", 3)
    _check_envelope(
        path, "state.p_M_m", float(np.linalg.norm(p_M)), RADIUS_ENVELOPE_M, "m", "distance from the centre of Mars"
    )
    _check_envelope(path, "state.v_M_mps", float(np.linalg.norm(v_M)), SPEED_ENVELOPE_MPS, "m/s", "inertial speed")
    return InitialState(
        st["time_s"],
        p_M,
        v_M,
        q / np.linalg.norm(q),
        st["sigma_position_m"],
        st["sigma_velocity_mps"],
        math.radians(st["sigma_attitude_deg"]),
    )


def _check_envelope(path: Path, key: str, value: float, envelope: tuple[float, float], unit: str, what: str) -> None:
    """A :class:`ScenarioError` naming ``path`` and ``key`` when the magnitude ``value`` [``unit``]
    lies outside ``envelope`` (lo, hi), naming the power of 1000 that would bring it inside."""
    lo, hi = envelope
    if lo <= value <= hi:
        return
    hint = ""
    if lo <= value * 1e3 <= hi:
        hint = f": written in k{unit}? (× 1000 would be {value * 1e3:.6g} {unit})"
    elif lo <= value * 1e-3 <= hi:
        hint = f": 1000× too large (a value in m{unit} or a scale error?; / 1000 would be {value * 1e-3:.6g} {unit})"
    raise ScenarioError(
        path, key, f"{what} {value:.6g} {unit} is outside an entry's envelope [{lo:.6g}, {hi:.6g}] {unit}{hint}"
    )


def _unit_factor_hint(ratio: float) -> str:
    """The pressure-unit factor closest to ``ratio`` (or its inverse) within 30 %, as words."""
    r = ratio if ratio >= 1.0 else 1.0 / ratio
    for f, name in _PRESSURE_FACTORS.items():
        if abs(r / f - 1.0) < 0.3:
            side = "larger" if ratio >= 1.0 else "smaller"
            return (
                f" — {f:g}× {side}, the factor between {name} and Pa: the column's unit label is likely wrong "
                f"(values in one of Pa and {name} labelled as the other)"
            )
    return " — a unit or scale error of this column?"


def check_port_scales(path: str, t: np.ndarray, p: np.ndarray, ports, units: dict) -> None:
    """Raise a :class:`TelemetryError` naming the file ``path`` and the port column when a port's
    median pressure ratio to the median of all ports ``p`` (n, m) [Pa] over the quarter of the rows
    with the highest median (high dynamic pressure) lies outside [1/:data:`PORT_RATIO_MAX`,
    :data:`PORT_RATIO_MAX`]: a unit error that the parser cannot see (module docstring)."""
    med = np.nanmedian(p, axis=1) if p.size else np.zeros(0)
    ok = np.isfinite(med) & (med > 0.0)
    if ok.sum() < 8:
        return
    sel = ok & (med >= np.percentile(med[ok], 75.0))
    for j, name in enumerate(ports):
        r = p[sel, j] / med[sel]
        r = r[np.isfinite(r)]
        if r.size < 4:
            continue
        ratio = float(np.median(r))
        if 1.0 / PORT_RATIO_MAX <= ratio <= PORT_RATIO_MAX:
            continue
        rows = np.flatnonzero(sel)
        raise TelemetryError.single(
            path,
            f"port {name} reads {ratio:.4g}× the median of all ports over the {int(sel.sum())} samples of highest "
            f"pressure (t {t[rows[0]]:.3f}-{t[rows[-1]]:.3f} s, rows {rows[0] + 1}-{rows[-1] + 1}); forebody ports "
            f"differ by less than {PORT_RATIO_MAX:g}×"
            + _unit_factor_hint(ratio)
            + f" (read as '{name} [{units[name]}]')",
            column=f"{name} [{units[name]}]",
            row=int(rows[0]) + 1,
        )


def check_time_spans(pressure_file: str, t_p: np.ndarray, imu_file: str, t_imu: np.ndarray) -> None:
    """Raise a :class:`TelemetryError` naming the time column of the file likely wrong when the
    pressure and IMU time spans [s] differ by more than :data:`SPAN_RATIO_MAX` either way (a time in
    ms written as s) or when fewer than half the pressure samples lie within the IMU's time span
    (the streams are on different time bases)."""
    if t_p.size < 2 or t_imu.size < 2:
        return
    sp, si = float(t_p[-1] - t_p[0]), float(t_imu[-1] - t_imu[0])
    ratio = sp / si if si > 0 else math.inf
    if not (1.0 / SPAN_RATIO_MAX <= ratio <= SPAN_RATIO_MAX):
        bad, span, other = (pressure_file, sp, si) if ratio > 1.0 else (imu_file, si, sp)
        f = span / other
        hint = " (a time in ms written as s?)" if 300.0 <= f <= 3000.0 else ""
        raise TelemetryError.single(
            bad,
            f"the time column spans {span:.6g} s against {other:.6g} s of the other stream "
            f"{Path(imu_file if bad == pressure_file else pressure_file).name} "
            f"({'pressures' if bad == pressure_file else 'IMU'} {f:.4g}× longer){hint}; both streams must cover the "
            "same flight on the same time base (is one file cut short?)",
            column="time [s]",
        )
    inside = (t_p >= t_imu[0] - 1.0) & (t_p <= t_imu[-1] + 1.0)
    if inside.mean() < 0.5:
        raise TelemetryError.single(
            pressure_file,
            f"only {100 * inside.mean():.0f} % of the pressure times ({t_p[0]:.6g}-{t_p[-1]:.6g} s) lie within the "
            f"IMU's ({t_imu[0]:.6g}-{t_imu[-1]:.6g} s in {imu_file}): the two files are on different time bases",
            column="time [s]",
        )


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index pairs of the runs of True in a boolean (n,) mask."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(int))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1, strict=True))


def read_meads_telemetry(paths: dict[str, Path], vehicle: FadsVehicle) -> MeadsTelemetry:
    """Read the three streams (module docstring) for ``vehicle``'s ports."""
    ports = vehicle.port_names
    pt = read_telemetry(paths["pressures"], required={n: "pressure" for n in ports}, sparse=ports)
    p = pt.stack(ports)
    deg: list[str] = []
    for j, name in enumerate(ports):
        for a, b in true_runs(np.isnan(p[:, j])):
            deg.append(
                f"{pt.path}, column '{name} [{pt.units[name]}]', rows {a + 1}-{b + 1} "
                f"(t {pt.time[a]:.3f}-{pt.time[b]:.3f} s): {b - a + 1} empty samples (dropout); "
                f"{name} is left out of those fits"
            )
    imu = read_telemetry(
        paths["imu"],
        required={**{c: "acceleration" for c in IMU_COLUMNS[:3]}, **{c: "angular_rate" for c in IMU_COLUMNS[3:]}},
    )
    init = read_initial_state(paths["initial_state"])
    check_time_spans(str(pt.path), pt.time, str(imu.path), imu.time)
    check_port_scales(str(pt.path), pt.time, p, ports, pt.units)
    return MeadsTelemetry(
        t_p=pt.time,
        p=p,
        ports=ports,
        pressure_file=str(pt.path),
        pressure_units={n: pt.units[n] for n in ports},
        t_imu=imu.time,
        f_B=imu.stack(IMU_COLUMNS[:3]),
        w_B=imu.stack(IMU_COLUMNS[3:]),
        initial=init,
        degradations=tuple(deg),
        imu_file=str(imu.path),
        imu_units={c: imu.units[c] for c in IMU_COLUMNS},
    )
