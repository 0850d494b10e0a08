"""The IMU error model of a scenario's ``[sensors.imu]`` table, shared by the problems whose
synthetic IMU is a :class:`~workbench.models.imu.ImuErrorModel` (entry, meads): the keys carry
their datasheet units (m/s², deg/s) in their names; the model holds SI (rad, rad/s)."""

from __future__ import annotations

import math
from typing import Any

from workbench.models.imu import ImuErrorModel

__all__ = ["imu_error_model"]


def imu_error_model(table: dict, **given: Any) -> ImuErrorModel:
    """The :class:`ImuErrorModel` of one validated ``[sensors.imu]`` table: ``accel_noise_mps2``,
    ``accel_bias_mps2`` [m/s²] and ``accel_scale`` [1] as they are, ``gyro_noise_dps`` and
    ``gyro_bias_dps`` [deg/s] to rad/s, ``gyro_scale`` [1]; ``given``: the other fields of the model
    (misalignments, full scales), already in SI."""
    return ImuErrorModel(
        accel_noise=table["accel_noise_mps2"],
        accel_bias=table["accel_bias_mps2"],
        accel_scale=table["accel_scale"],
        gyro_noise=math.radians(table["gyro_noise_dps"]),
        gyro_bias=math.radians(table["gyro_bias_dps"]),
        gyro_scale=table["gyro_scale"],
        **given,
    )
