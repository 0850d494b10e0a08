"""The shared [sensors.imu] reader (workbench/problems/imu_settings.py): datasheet units to SI."""

from __future__ import annotations

import math

from workbench.models.imu import ImuErrorModel
from workbench.problems.imu_settings import imu_error_model


def test_imu_error_model_converts_the_datasheet_units_and_keeps_the_given_fields():
    table = {
        "accel_noise_mps2": 1e-3,
        "accel_bias_mps2": 2e-3,
        "accel_scale": 1e-4,
        "gyro_noise_dps": 0.1,
        "gyro_bias_dps": 0.02,
        "gyro_scale": 3e-4,
        "rate_hz": 200.0,  # not an error-model key: the caller's
    }
    m = imu_error_model(table, gyro_full_scale=(1.0, 2.0, 3.0))
    assert isinstance(m, ImuErrorModel)
    assert (m.accel_noise, m.accel_bias, m.accel_scale, m.gyro_scale) == (1e-3, 2e-3, 1e-4, 3e-4)
    assert m.gyro_noise == math.radians(0.1) and m.gyro_bias == math.radians(0.02)
    assert tuple(m.gyro_full_scale) == (1.0, 2.0, 3.0)
