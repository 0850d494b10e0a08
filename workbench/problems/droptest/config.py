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
                Key("ramp_angle_deg", _F, 60.0, "deg", "ramp inclination from the horizontal, in (0, 90)"),
                Key(
                    "nail_depth_m",
                    _F,
                    0.3,
                    "m",
                    "the nail (SPF origin, where the bungee-cut hammer strikes) lies this far below the ramp "
                    "surface, along its normal; in [0, 10] (a nail in front of the ramp is rejected)",
                ),
                Key(
                    "magnetic_field_spf",
                    _V,
                    REQUIRED,
                    "1",
                    "local magnetic field direction in SPF (3DM attitude); any non-zero length",
                ),
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
                Key(
                    "filter",
                    _S,
                    "butterworth",
                    meaning="the anti-alias filter the IMU channels went through: `butterworth` causal (its "
                    "low-frequency group delay is removed from the time tags), `zero_phase` (forward-backward, "
                    "no delay), `none`",
                    choices=("butterworth", "zero_phase", "none"),
                ),
                Key("filter_cutoff_hz", _F, 500.0, "Hz", "Butterworth cutoff, below half the sample rate"),
                Key("filter_order", _I, 4, meaning='Butterworth order, 1–10 (0: no filter, as `filter = "none"`)'),
                Key(
                    "latency_s",
                    _F,
                    0.0,
                    "s",
                    "further delay of the IMU time tags behind the motion (transport, buffering), removed from "
                    "them as the filter delay is; negative: tags early",
                ),
            ),
        ),
        Table(
            "sensors.attitude_3dm",
            "3DM attitude sensor, read while hanging",
            (
                Key(
                    "gravity_sigma_deg",
                    _F,
                    0.2,
                    "deg",
                    "direction error of the measured gravity ('up') vector: 1σ of the tilt about each of the two "
                    "axes perpendicular to it (a per-run calibration error; 10 % of it as per-sample noise in "
                    "the simulator); ≥ 0",
                ),
                Key(
                    "magnetic_sigma_deg",
                    _F,
                    1.0,
                    "deg",
                    "direction error of the measured magnetic vector, per perpendicular axis as above; ≥ 0",
                ),
                Key("rate_hz", _F, 100.0, "Hz", "sample rate (synthetic)"),
                Key("latency_s", _F, 0.0, "s", "delay of the 3DM time tags behind the motion, removed from them"),
            ),
        ),
        Table(
            "sensors.ranging",
            "range aiding (its presence adds the ranging telemetry)",
            (
                Key(
                    "rate_hz",
                    _F,
                    200.0,
                    "Hz",
                    "ranging sample rate: the synthetic writer's; with user data, when given, it must match the "
                    "file's (median interval, within 10 %)",
                ),
                Key("odometer", _B, False, meaning="bungee-sheave odometer until the cut"),
                Key("odometer_sigma_m", _F, 0.01, "m", "odometer noise, 1σ"),
                Key(
                    "odometer_zero_m",
                    _F,
                    0.0,
                    "m",
                    "the odometer's zero: it reads the rope length (sheave to attachment) minus this",
                ),
                Key("radar_range_sigma_m", _F, 0.02, "m", "radar-gun range noise, 1σ (every gun without its own)"),
                Key("radar_rate_sigma_mps", _F, 0.05, "m/s", "radar-gun range-rate noise, 1σ (idem)"),
                Key(
                    "reflector_body_m",
                    _V,
                    [0.0, 0.0, 0.0],
                    "m",
                    "corner reflector in the lander frame (the asset's; its origin is the CM unless the asset "
                    "gives `cm_m`), for every gun without its own",
                ),
                Key(
                    "latency_s",
                    _F,
                    0.0,
                    "s",
                    "delay of the ranging time tags behind the motion, removed from them",
                ),
                Key(
                    "acquisition_filter",
                    _B,
                    False,
                    meaning="the ranging channels went through the IMU's acquisition filter "
                    "([sensors.acquisition]): its delay is removed from their tags too",
                ),
            ),
        ),
        Table(
            "sensors.ranging.radar_guns",
            "radar guns by name",
            free="vec3",
            free_meaning="gun position in SPF [m]",
        ),
        Table(
            "sensors.ranging.reflectors",
            "per gun: the reflector it tracks (default `reflector_body_m`)",
            free="vec3",
            free_meaning="gun name = reflector position in the lander frame [m]",
        ),
        Table(
            "sensors.ranging.range_sigma_m",
            "per gun: range noise (default `radar_range_sigma_m`)",
            free="float",
            free_meaning="gun name = range noise, 1σ [m]",
        ),
        Table(
            "sensors.ranging.rate_sigma_mps",
            "per gun: range-rate noise (default `radar_rate_sigma_mps`)",
            free="float",
            free_meaning="gun name = range-rate noise, 1σ [m/s]",
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
    acquisition_filter: str
    imu_latency_s: float
    attitude_3dm_latency_s: float
    ranging_latency_s: float
    ranging_filtered: bool
    odometer_zero_m: float
    gun_reflectors_body_m: dict
    gun_range_sigma_m: dict
    gun_rate_sigma_mps: dict
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
        _check_ranges(v, scenario)
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
            acquisition_filter="none" if aq["filter_order"] == 0 else aq["filter"],
            imu_latency_s=aq["latency_s"],
            attitude_3dm_latency_s=a3["latency_s"],
            ranging_latency_s=rg["latency_s"],
            ranging_filtered=rg["acquisition_filter"],
            odometer_zero_m=rg["odometer_zero_m"],
            gun_reflectors_body_m={str(k): np.asarray(p, float) for k, p in rg.get("reflectors", {}).items()},
            gun_range_sigma_m={str(k): float(x) for k, x in rg.get("range_sigma_m", {}).items()},
            gun_rate_sigma_mps={str(k): float(x) for k, x in rg.get("rate_sigma_mps", {}).items()},
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


# ------------------------------------------------------------------ value ranges (issue 12, item 4)
def _check_ranges(v: dict, scenario: Scenario) -> None:
    """Values the schema's types cannot refuse: a ScenarioError naming file and key."""
    path = scenario.path

    def bad(key: str, msg: str) -> None:
        raise ScenarioError(path, key, msg)

    ch = v["chamber"]
    if not 0.0 < ch["ramp_angle_deg"] < 90.0:
        bad("chamber.ramp_angle_deg", f"{ch['ramp_angle_deg']} deg: the ramp inclination must be in (0, 90) deg")
    if not 0.0 <= ch["nail_depth_m"] <= 10.0:
        bad(
            "chamber.nail_depth_m",
            f"{ch['nail_depth_m']} m: the nail must lie 0-10 m below the ramp surface (negative = in front of "
            "the ramp, where the lander would hit it)",
        )
    if not np.linalg.norm(ch["magnetic_field_spf"]) > 0.0:
        bad("chamber.magnetic_field_spf", "a zero vector has no direction")
    sensors = v["sensors"]
    sigmas = {
        "accelerometer": ("noise_g", "bias_g", "scale", "misalignment_deg"),
        "gyro": ("noise_dps", "bias_dps", "scale", "misalignment_deg"),
        "attitude_3dm": ("gravity_sigma_deg", "magnetic_sigma_deg"),
        "ranging": ("odometer_sigma_m", "radar_range_sigma_m", "radar_rate_sigma_mps"),
    }
    for table, keys in sigmas.items():
        for k in keys:
            x = sensors[table][k]
            if not (x >= 0.0 and np.isfinite(x)):
                bad(f"sensors.{table}.{k}", f"{x}: a 1σ must be ≥ 0 (0 = this error is absent)")
    for table in ("range_sigma_m", "rate_sigma_mps"):
        for gun, x in sensors["ranging"].get(table, {}).items():
            if not (x >= 0.0 and np.isfinite(x)):
                bad(f"sensors.ranging.{table}.{gun}", f"{x}: a 1σ must be ≥ 0")
    guns = set(sensors["ranging"].get("radar_guns", {}))
    for table in ("reflectors", "range_sigma_m", "rate_sigma_mps"):
        for gun in sensors["ranging"].get(table, {}):
            if gun not in guns:
                bad(
                    f"sensors.ranging.{table}.{gun}",
                    f"no radar gun '{gun}' in [sensors.ranging.radar_guns] (guns: {', '.join(sorted(guns)) or 'none'})",
                )
    for table, k in (("accelerometer", "full_scale_g"), ("gyro", "full_scale_dps")):
        if not sensors[table][k] > 0.0:
            bad(f"sensors.{table}.{k}", f"{sensors[table][k]}: the saturation level must be > 0")
    aq = sensors["acquisition"]
    if not aq["sample_rate_hz"] > 0.0:
        bad("sensors.acquisition.sample_rate_hz", "must be > 0")
    if not 0 <= aq["filter_order"] <= 10:
        bad("sensors.acquisition.filter_order", f"{aq['filter_order']}: use 1-10 (0: no filter)")
    if aq["filter"] != "none" and aq["filter_order"] > 0 and not 0.0 < aq["filter_cutoff_hz"]:
        bad("sensors.acquisition.filter_cutoff_hz", "must be > 0")
    for key, x in (("sensors.attitude_3dm.rate_hz", sensors["attitude_3dm"]["rate_hz"]),
                   ("sensors.ranging.rate_hz", sensors["ranging"]["rate_hz"]),
                   ("filter.rate_hz", v["filter"]["rate_hz"])):  # fmt: skip
        if not x > 0.0:
            bad(key, f"{x}: a rate must be > 0")


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def config_for(scenario: Scenario) -> DropConfig:
    """:meth:`DropConfig.from_scenario`, built once per scenario object (scenarios are read-only)."""
    cfg = _CACHE.get(scenario)
    if cfg is None:
        cfg = _CACHE[scenario] = DropConfig.from_scenario(scenario)
    return cfg
