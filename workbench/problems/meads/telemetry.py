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
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.io.scenario import Scenario, ScenarioError
from workbench.io.telemetry import read_telemetry
from workbench.models.flush_airdata import FadsVehicle

__all__ = [
    "STREAMS",
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


def telemetry_paths(scenario: Scenario) -> dict[str, Path]:
    """``[telemetry]`` files of a user scenario; a missing key or file is a ScenarioError naming it."""
    out = {}
    for k in STREAMS:
        if not scenario.has(f"telemetry.{k}"):
            raise ScenarioError(
                scenario.path, f"telemetry.{k}", "missing: a meads scenario needs pressures, imu, initial_state"
            )
        out[k] = scenario.path_of(f"telemetry.{k}")
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
    """Read ``initial_state.toml``; a missing/bad key is a ScenarioError naming the file and key."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(path, None, f"not valid TOML: {exc}") from None
    st = data.get("state")
    if not isinstance(st, dict):
        raise ScenarioError(path, "state", "missing table [state]")

    def arr(key, n):
        v = st.get(key)
        a = np.asarray(v, dtype=float) if isinstance(v, list) else None
        if a is None or a.shape != (n,) or not np.all(np.isfinite(a)):
            raise ScenarioError(path, f"state.{key}", f"needs {n} finite numbers, got {v!r}")
        return a

    def num(key):
        v = st.get(key)
        if isinstance(v, bool) or not isinstance(v, int | float) or not v >= 0:
            raise ScenarioError(path, f"state.{key}", f"needs a non-negative number, got {v!r}")
        return float(v)

    q = arr("q_M_B", 4)
    if abs(np.linalg.norm(q) - 1.0) > 1e-3:
        raise ScenarioError(path, "state.q_M_B", f"not a unit quaternion (norm {np.linalg.norm(q):.6f})")
    return InitialState(
        num("time_s"),
        arr("p_M_m", 3),
        arr("v_M_mps", 3),
        q / np.linalg.norm(q),
        num("sigma_position_m"),
        num("sigma_velocity_mps"),
        math.radians(num("sigma_attitude_deg")),
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
