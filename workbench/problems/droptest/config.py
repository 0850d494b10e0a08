"""Drop-test scenario configuration: the schema of a ``kind = "droptest"`` scenario (every key the
reconstruction, the synthetic-telemetry writer and the truth simulator read, with its default, once)
and :class:`DropConfig`, the typed values built once from a validated scenario.

Values keep the unit their key names (``noise_g``, ``bias_dps``); the code converts at its edge.
Not to be confused with :class:`workbench.problems.droptest.truth.DropTestConfig` (the truth
simulator's own settings, built from ``[synthetic]``).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from workbench.io.scenario import Scenario, ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table

__all__ = ["SCHEMA", "DropConfig", "config_for"]

_F, _I, _S, _B, _V, _L = "float", "int", "str", "bool", "vec3", "list"

SCHEMA = Schema(
    "droptest",
    "REDLand airbag drop test",
    (
        Table(
            "scenario",
            "what the run is",
            (
                Key("name", _S, REQUIRED, meaning="names the run, its recording and summary"),
                Key("kind", _S, REQUIRED, meaning='`"droptest"`'),
                Key("description", _S, "", meaning="one line for listings"),
                Key("epoch_utc", _S, None, meaning="UTC of t = 0 (metadata)"),
            ),
        ),
        Table(
            "vehicle",
            "the lander",
            (Key("lander", _S, REQUIRED, meaning="lander asset TOML, relative to the scenario file"),),
        ),
        Table(
            "telemetry",
            "user telemetry files, relative to the scenario file (ignored by a synthetic scenario)",
            (
                Key("imu", _S, None, meaning="IMU CSV: triads `<name>.x..z [g]`, `gyro.x..z [deg/s]`; required"),
                Key("attitude_3dm", _S, None, meaning="3DM CSV: `up.x..z`, `mag.x..z` [1]; required"),
                Key("events", _S, None, meaning="events CSV (`release`, optional `bungee_cut`); required"),
                Key(
                    "setup",
                    _S,
                    None,
                    meaning="setup TOML: `[hanging]` survey, optional `[bungee]`, `[rocks]`; required",
                ),
                Key("ranging", _S, None, meaning="ranging CSV (odometer, radar guns); optional"),
            ),
        ),
        Table(
            "chamber",
            "the test chamber, SPF frame",
            (
                Key("ramp_angle_deg", _F, 60.0, "deg", "ramp inclination"),
                Key("nail_depth_m", _F, 0.3, "m", "the nail (SPF origin) lies this far below the ramp surface"),
                Key("magnetic_field_spf", _V, REQUIRED, "1", "local magnetic field direction in SPF (3DM attitude)"),
            ),
        ),
        Table(
            "chamber.rocks",
            "a rock field on the ramp (synthetic; its presence adds rocks)",
            (
                Key("seed", _I, 0, meaning="random seed of the rock placement"),
                Key("spacing_m", _F, 1.0, "m", "mean rock spacing"),
                Key(
                    "extent_m",
                    _L,
                    [[-4.0, 4.0], [-7.0, 3.0]],
                    "m",
                    "ramp-plane window [[u0, u1], [v0, v1]]: across, up-slope",
                ),
            ),
        ),
        Table(
            "sensors.accelerometer",
            "accelerometer triads",
            (
                Key(
                    "triads", _L, ["BP", "PYBP", "PXBP", "MXBP"], meaning="triad names (lever arms in the lander asset)"
                ),
                Key("noise_g", _F, 0.2, "g", "per-sample noise, 1σ"),
                Key("bias_g", _F, 0.005, "g", "residual bias after zeroing, 1σ per axis"),
                Key("scale", _F, 0.002, "1", "scale-factor error, 1σ (filter: measurement noise ∝ the force)"),
                Key(
                    "misalignment_deg", _F, 0.05, "deg", "axis misalignment, 1σ (filter: measurement noise ∝ the force)"
                ),
                Key("full_scale_g", _F, 2000.0, "g", "saturation level"),
            ),
        ),
        Table(
            "sensors.gyro",
            "rate gyro",
            (
                Key("noise_dps", _F, 0.4, "deg/s", "per-sample noise, 1σ"),
                Key("bias_dps", _F, 0.05, "deg/s", "bias, 1σ"),
                Key("scale", _F, 0.01, "1", "scale-factor error, 1σ"),
                Key("misalignment_deg", _F, 0.05, "deg", "axis misalignment, 1σ"),
                Key("full_scale_dps", _F, 1000.0, "deg/s", "saturation level"),
            ),
        ),
        Table(
            "sensors.acquisition",
            "data acquisition",
            (
                Key("sample_rate_hz", _F, 2000.0, "Hz", "IMU sample rate (synthetic)"),
                Key("filter_cutoff_hz", _F, 500.0, "Hz", "Butterworth anti-alias cutoff (its group delay is removed)"),
                Key("filter_order", _I, 4, meaning="Butterworth order"),
            ),
        ),
        Table(
            "sensors.attitude_3dm",
            "3DM attitude sensor, read while hanging",
            (
                Key("gravity_sigma_deg", _F, 0.2, "deg", "gravity-vector direction error, 1σ"),
                Key("magnetic_sigma_deg", _F, 1.0, "deg", "magnetic-vector direction error, 1σ"),
                Key("rate_hz", _F, 100.0, "Hz", "sample rate (synthetic)"),
            ),
        ),
        Table(
            "sensors.ranging",
            "range aiding (its presence adds the ranging telemetry)",
            (
                Key("rate_hz", _F, 200.0, "Hz", "ranging sample rate"),
                Key("odometer", _B, False, meaning="bungee-sheave odometer until the cut"),
                Key("odometer_sigma_m", _F, 0.01, "m", "odometer noise, 1σ"),
                Key("radar_range_sigma_m", _F, 0.02, "m", "radar-gun range noise, 1σ"),
                Key("radar_rate_sigma_mps", _F, 0.05, "m/s", "radar-gun range-rate noise, 1σ"),
                Key("reflector_body_m", _V, [0.0, 0.0, 0.0], "m", "corner reflector, body frame, from the CM"),
            ),
        ),
        Table(
            "sensors.ranging.radar_guns",
            "radar guns by name",
            free="vec3",
            free_meaning="gun position in SPF [m]",
        ),
        Table(
            "filter",
            "REDLand EKF + RTS smoother",
            (
                Key(
                    "mode",
                    _S,
                    "kinematic",
                    meaning="`dynamic` models the bungee until the cut",
                    choices=("kinematic", "dynamic"),
                ),
                Key("rate_hz", _F, 1000.0, "Hz", "IMU samples are averaged down to this rate"),
                Key("q_accel", _F, 5.0, "m²/s⁵", "white-jerk PSD floor"),
                Key("q_angular", _F, 20.0, "rad²/s⁵", "white angular-jerk PSD floor"),
                Key("adaptive_gain", _F, 4.0, "1", "Q raised by gain × (measured jerk)² × dt"),
                Key("hang_zupt_sigma_mps", _F, 0.005, "m/s", "zero-velocity update while hanging, 1σ"),
                Key("velocity_sigma_mps", _F, 0.01, "m/s", "initial velocity, 1σ"),
                Key("accel_sigma_mps2", _F, 0.5, "m/s²", "initial acceleration, 1σ"),
                Key("rate_sigma_dps", _F, 0.5, "deg/s", "initial body rate, 1σ"),
                Key("angular_accel_sigma", _F, 2.0, "rad/s²", "initial angular acceleration, 1σ"),
            ),
        ),
        Table(
            "synthetic",
            "truth simulation (its presence makes the scenario synthetic)",
            (
                Key("seed", _I, 0, meaning="seed of every sensor-side draw"),
                Key("impact_parallel_mps", _F, 16.0, "m/s", "impact speed along the ramp (Mars frame)"),
                Key("impact_normal_mps", _F, 12.0, "m/s", "impact speed normal to the ramp"),
                Key("release_euler123_deg", _V, [0.0, 0.0, 0.0], "deg", "lander attitude while hanging (1-2-3 Euler)"),
                Key("release_to_contact_s", _F, 1.3, "s", "release to first contact"),
                Key("pre_release_s", _F, 0.5, "s", "hanging data before the release"),
                Key("bungee_truth_scale", _F, 1.03, "1", "true bungee stiffness / the test plan's"),
                Key("survey_sigma_m", _F, 0.03, "m", "error of the surveyed hanging position, 1σ"),
                Key("bag_pressure_psi", _F, None, "psi", "airbag pressure; absent: the lander asset's"),
            ),
        ),
    ),
)


@dataclass(frozen=True)
class DropConfig:
    """The settings of one drop-test scenario, validated against :data:`SCHEMA` (defaults filled).

    Units as the key names say.  ``rocks`` / ``ranging``: the ``[chamber.rocks]`` /
    ``[sensors.ranging]`` tables are present; ``radar_guns`` name → SPF position (3,) [m];
    ``magnetic_field_spf`` (3,) (not normalised); ``telemetry`` stream → path string as written
    (None when absent).
    """

    lander: str
    telemetry: dict
    ramp_angle_deg: float
    nail_depth_m: float
    magnetic_field_spf: np.ndarray
    rocks: bool
    rocks_seed: int
    rocks_spacing_m: float
    rocks_extent_m: list
    triads: tuple[str, ...]
    accel_noise_g: float
    accel_bias_g: float
    accel_scale: float
    accel_misalignment_deg: float
    accel_full_scale_g: float
    gyro_noise_dps: float
    gyro_bias_dps: float
    gyro_scale: float
    gyro_misalignment_deg: float
    gyro_full_scale_dps: float
    sample_rate_hz: float
    filter_cutoff_hz: float
    filter_order: int
    gravity_sigma_deg: float
    magnetic_sigma_deg: float
    attitude_3dm_rate_hz: float
    ranging: bool
    ranging_rate_hz: float
    odometer: bool
    odometer_sigma_m: float
    radar_range_sigma_m: float
    radar_rate_sigma_mps: float
    reflector_body_m: np.ndarray
    radar_guns: dict
    mode: str
    filter_rate_hz: float
    q_accel: float
    q_angular: float
    adaptive_gain: float
    hang_zupt_sigma_mps: float
    velocity_sigma_mps: float
    accel_sigma_mps2: float
    rate_sigma_dps: float
    angular_accel_sigma: float
    seed: int
    impact_parallel_mps: float
    impact_normal_mps: float
    release_euler123_deg: np.ndarray
    release_to_contact_s: float
    pre_release_s: float
    bungee_truth_scale: float
    survey_sigma_m: float
    bag_pressure_psi: float | None

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> DropConfig:
        """Validate ``scenario`` against :data:`SCHEMA` (unknown keys, types: a
        :class:`ScenarioError` naming file, table and key) and build the config."""
        if scenario.kind != "droptest":
            raise ScenarioError(scenario.path, "scenario.kind", f"{scenario.kind!r} is not a droptest scenario")
        v = SCHEMA.validate(scenario.data, scenario.path)
        for a in (v["chamber"]["magnetic_field_spf"], v["sensors"]["ranging"]["reflector_body_m"]):
            a.flags.writeable = False  # shared by every user of the config
        v["synthetic"]["release_euler123_deg"].flags.writeable = False
        ch, rk = v["chamber"], v["chamber"]["rocks"]
        acc, gyr = v["sensors"]["accelerometer"], v["sensors"]["gyro"]
        aq, a3, rg = v["sensors"]["acquisition"], v["sensors"]["attitude_3dm"], v["sensors"]["ranging"]
        f, s = v["filter"], v["synthetic"]
        return cls(
            lander=v["vehicle"]["lander"],
            telemetry=dict(v["telemetry"]),
            ramp_angle_deg=ch["ramp_angle_deg"],
            nail_depth_m=ch["nail_depth_m"],
            magnetic_field_spf=ch["magnetic_field_spf"],
            rocks=scenario.has("chamber.rocks"),
            rocks_seed=rk["seed"],
            rocks_spacing_m=rk["spacing_m"],
            rocks_extent_m=rk["extent_m"],
            triads=tuple(acc["triads"]),
            accel_noise_g=acc["noise_g"],
            accel_bias_g=acc["bias_g"],
            accel_scale=acc["scale"],
            accel_misalignment_deg=acc["misalignment_deg"],
            accel_full_scale_g=acc["full_scale_g"],
            gyro_noise_dps=gyr["noise_dps"],
            gyro_bias_dps=gyr["bias_dps"],
            gyro_scale=gyr["scale"],
            gyro_misalignment_deg=gyr["misalignment_deg"],
            gyro_full_scale_dps=gyr["full_scale_dps"],
            sample_rate_hz=aq["sample_rate_hz"],
            filter_cutoff_hz=aq["filter_cutoff_hz"],
            filter_order=aq["filter_order"],
            gravity_sigma_deg=a3["gravity_sigma_deg"],
            magnetic_sigma_deg=a3["magnetic_sigma_deg"],
            attitude_3dm_rate_hz=a3["rate_hz"],
            ranging=scenario.has("sensors.ranging"),
            ranging_rate_hz=rg["rate_hz"],
            odometer=rg["odometer"],
            odometer_sigma_m=rg["odometer_sigma_m"],
            radar_range_sigma_m=rg["radar_range_sigma_m"],
            radar_rate_sigma_mps=rg["radar_rate_sigma_mps"],
            reflector_body_m=rg["reflector_body_m"],
            radar_guns={str(k): np.asarray(p, float) for k, p in rg.get("radar_guns", {}).items()},
            mode=f["mode"],
            filter_rate_hz=f["rate_hz"],
            q_accel=f["q_accel"],
            q_angular=f["q_angular"],
            adaptive_gain=f["adaptive_gain"],
            hang_zupt_sigma_mps=f["hang_zupt_sigma_mps"],
            velocity_sigma_mps=f["velocity_sigma_mps"],
            accel_sigma_mps2=f["accel_sigma_mps2"],
            rate_sigma_dps=f["rate_sigma_dps"],
            angular_accel_sigma=f["angular_accel_sigma"],
            seed=s["seed"],
            impact_parallel_mps=s["impact_parallel_mps"],
            impact_normal_mps=s["impact_normal_mps"],
            release_euler123_deg=s["release_euler123_deg"],
            release_to_contact_s=s["release_to_contact_s"],
            pre_release_s=s["pre_release_s"],
            bungee_truth_scale=s["bungee_truth_scale"],
            survey_sigma_m=s["survey_sigma_m"],
            bag_pressure_psi=s["bag_pressure_psi"],
        )


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def config_for(scenario: Scenario) -> DropConfig:
    """:meth:`DropConfig.from_scenario`, built once per scenario object (scenarios are read-only)."""
    cfg = _CACHE.get(scenario)
    if cfg is None:
        cfg = _CACHE[scenario] = DropConfig.from_scenario(scenario)
    return cfg
