"""Inertial measurement unit error model shared by the problems that simulate an IMU.

An IMU measures the body specific force ``f`` [m/s²] and body rate ``w`` [rad/s] (triads in the
vehicle's body frame, whatever that problem calls it).  :class:`ImuErrorModel` is the 1σ error
budget, :func:`draw_imu_errors` draws one run's constant errors and :func:`apply_imu_errors`
turns a truth history into measurements: ``y = (1 + s) ⊙ (x + m × x) + b + noise``, clipped at
the full-scale range.  Moved here from the entry problem's sensor module (unchanged numbers: the
same draws in the same order) when the flush-air-data problem needed the same IMU.

Default error levels: Groves, *Principles of GNSS, Inertial, and Multisensor Integrated
Navigation Systems*, 2nd ed., 2013, Sect. 4.4; noise per AMELIA Table 3 (Aboudan et al. 2018).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["IMU_ERROR_NAMES", "SCHIAPARELLI_GYRO_RANGE_DPS", "ImuErrorModel", "apply_imu_errors", "draw_imu_errors"]

#: Design range of the Schiaparelli X gyro (AMELIA Sect. 3), the default gyro range [deg/s].
SCHIAPARELLI_GYRO_RANGE_DPS = 187.5


#: Names of the per-run IMU errors (each (3,), per axis), in the order of ``ImuErrorModel.errors``.
IMU_ERROR_NAMES: tuple[str, ...] = (
    "accel_bias",
    "accel_scale",
    "accel_misalignment",
    "gyro_bias",
    "gyro_scale",
    "gyro_misalignment",
)


@dataclass(frozen=True)
class ImuErrorModel:
    """IMU error budget (1σ, SI), per axis.

    ``accel_noise`` [m/s²] and ``gyro_noise`` [rad/s] white noise per on-board (100 Hz) sample
    (defaults: AMELIA Table 3, 0.001 m/s² and 0.01 °/s); ``*_bias`` constant per run and axis
    [m/s², rad/s]; ``*_scale`` scale-factor error (fraction) per run and axis;
    ``*_misalignment`` [rad] small-angle rotation of the sensor triad from the body axes per run
    and axis; ``gyro_full_scale`` (3,) [rad/s] range of each gyro axis (measured rates are
    clipped at ±range; default 187.5 °/s, AMELIA Sect. 3); ``accel_full_scale`` [m/s²] likewise
    (default: no limit).

    Default error levels: no Schiaparelli IMU specification is published (AMELIA Sect. 8
    assumed a "standard navigation grade IMU"); the defaults are the intermediate/tactical-grade
    levels of Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
    Systems*, 2nd ed., 2013, Sect. 4.4 (accelerometer bias 100-1000 μg, scale factor and
    cross-coupling 100-1000 ppm / 0.1-1 mrad; tactical gyro bias 1-100 °/h, scale factor
    100-1000 ppm): accelerometer bias 1e-3 m/s² (≈ 100 μg), scale 300 ppm, misalignment
    0.2 mrad; gyro bias 1 °/h, scale 100 ppm, misalignment 0.2 mrad.

    ``errors``: if given, the per-run errors themselves (six (3,) tuples in the order of
    :data:`IMU_ERROR_NAMES`) instead of a draw from the 1σ levels (set by
    :func:`disperse_telemetry_spec`).
    """

    accel_noise: float = 1e-3
    accel_bias: float = 1e-3
    accel_scale: float = 3e-4
    accel_misalignment: float = 2e-4
    gyro_noise: float = math.radians(0.01)
    gyro_bias: float = math.radians(1.0 / 3600.0)
    gyro_scale: float = 1e-4
    gyro_misalignment: float = 2e-4
    gyro_full_scale: tuple[float, float, float] = (math.radians(SCHIAPARELLI_GYRO_RANGE_DPS),) * 3
    accel_full_scale: float = math.inf
    errors: tuple[tuple[float, float, float], ...] | None = None


def draw_imu_errors(model: ImuErrorModel, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Per-run IMU errors ``{name: (3,)}`` of :data:`IMU_ERROR_NAMES`: ``model.errors`` when set,
    else drawn N(0, 1σ) per axis from ``rng`` in that order (bias [m/s², rad/s], scale [-],
    misalignment [rad])."""
    if model.errors is not None:
        if len(model.errors) != len(IMU_ERROR_NAMES):
            raise ValueError(f"ImuErrorModel.errors needs {len(IMU_ERROR_NAMES)} triads ({', '.join(IMU_ERROR_NAMES)})")
        return {k: np.asarray(v, dtype=float).reshape(3) for k, v in zip(IMU_ERROR_NAMES, model.errors, strict=True)}
    return {k: rng.normal(0.0, float(getattr(model, k)), 3) for k in IMU_ERROR_NAMES}


def apply_imu_errors(
    f_G: np.ndarray, w_G: np.ndarray, model: ImuErrorModel, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Measured specific force and body rate from truth (n,3) each [m/s², rad/s], G frame.

    ``y = (1 + s) ⊙ (x + m × x) + b + noise`` per triad (``m`` the small-angle misalignment
    [rad], ``s`` the scale-factor error, ``b`` the bias), then clipped at ± full scale (a
    saturated channel reads its limit, as Schiaparelli's X gyro did).  Returns ``(f_meas,
    w_meas, drawn)`` with ``drawn`` the per-run errors (:func:`draw_imu_errors`, (3,) each).
    """
    f_G = np.asarray(f_G, float)
    w_G = np.asarray(w_G, float)
    drawn = draw_imu_errors(model, rng)
    f = f_G + np.cross(drawn["accel_misalignment"], f_G)
    w = w_G + np.cross(drawn["gyro_misalignment"], w_G)
    f = f * (1.0 + drawn["accel_scale"]) + drawn["accel_bias"] + rng.normal(0.0, model.accel_noise, f_G.shape)
    w = w * (1.0 + drawn["gyro_scale"]) + drawn["gyro_bias"] + rng.normal(0.0, model.gyro_noise, w_G.shape)
    f = np.clip(f, -model.accel_full_scale, model.accel_full_scale)
    fs = np.asarray(model.gyro_full_scale, float)
    w = np.clip(w, -fs, fs)
    return f, w, drawn
