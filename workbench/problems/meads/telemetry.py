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
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.io.scenario import ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, load_file
from workbench.io.telemetry import read_telemetry
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
    "true_runs",
]

STREAMS = ("pressures", "imu", "initial_state")
IMU_COLUMNS = ("f_x", "f_y", "f_z", "w_x", "w_y", "w_z")

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
    ``initial``; ``degradations``: logged findings (one line each, file/column/rows)."""

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
    return InitialState(
        st["time_s"],
        arr("p_M_m", 3),
        arr("v_M_mps", 3),
        q / np.linalg.norm(q),
        st["sigma_position_m"],
        st["sigma_velocity_mps"],
        math.radians(st["sigma_attitude_deg"]),
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
    )
