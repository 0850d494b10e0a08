"""Drop-test settings: the schemas of the three input file kinds a drop test reads — the
``kind = "droptest"`` scenario (:data:`SCHEMA`), the lander asset (:data:`LANDER_SCHEMA`) and the
drop setup file (:data:`SETUP_SCHEMA`), every key once with type, unit, default and bounds — and
:class:`DropSettings`, the frozen settings of one run built once from a validated scenario by
``DropTestProblem.settings`` (one small dataclass per stage, the lander model read once).

Values keep the unit their key names (``noise_g``, ``bias_dps``); the code converts at its edge.
Not to be confused with :class:`workbench.problems.droptest.truth.DropTestConfig` (the truth
simulator's own settings of one drop, built from :class:`Synthetic`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.io.scenario import RunInfo, Scenario, ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, from_table, scenario_table
from workbench.problems.droptest.lander import LANDER_SCHEMA as _LANDER_SCHEMA
from workbench.problems.droptest.lander import LanderModel, load_lander, require_simulator_keys
from workbench.problems.droptest.surface import ramp_normal

__all__ = [
    "SCHEMA",
    "LANDER_SCHEMA",
    "SETUP_SCHEMA",
    "DropSettings",
    "Chamber",
    "Rocks",
    "Accelerometer",
    "Gyro",
    "Acquisition",
    "Attitude3dm",
    "Ranging",
    "FilterSettings",
    "Synthetic",
]

_F, _I, _S, _B, _V, _L = "float", "int", "str", "bool", "vec3", "list"

#: What an IMU noise key's σ is of (the simulator's ``sensors.apply_errors`` after
#: ``sensors.acquisition_filter``; the filter's R in ``pipeline``).
_AFTER_FILTER = (
    "white noise of each recorded sample, 1σ, *after* the acquisition filter (the simulator adds it to the "
    "filtered, sampled signal; the filter divides its variance by the samples averaged into each step)"
)

SCHEMA = Schema(
    "droptest",
    "REDLand airbag drop test",
    (
        scenario_table("droptest", epoch="UTC of t = 0 (metadata)"),
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
                Key(
                    "ramp_angle_deg",
                    _F,
                    60.0,
                    "deg",
                    "ramp inclination from the horizontal",
                    gt=0.0,
                    lt=90.0,
                    example=True,
                ),
                Key(
                    "nail_depth_m",
                    _F,
                    0.3,
                    "m",
                    "where the ramp plane lies from the nail (the SPF origin, where the bungee-cut hammer "
                    "strikes), along the ramp's free-side normal n = (0, −sin a, cos a): the plane passes "
                    "through `nail_depth_m` · n. Signed, any value: positive = the nail below the ramp surface "
                    "(REDLand: 0.3), negative = the nail in front of it, on the lander's side. The ramp is "
                    "placed by its own plane, so a nail anywhere needs no other position moved; not together "
                    "with `ramp_point_m`",
                    example=True,
                ),
                Key(
                    "ramp_point_m",
                    _V,
                    None,
                    "m",
                    "instead of `nail_depth_m`: any surveyed point on the ramp surface, in SPF; the ramp is "
                    "the plane through it inclined at `ramp_angle_deg` (equivalent to `nail_depth_m` = n · "
                    "point; the rock window's origin is the foot of the nail on that plane); absent: "
                    "`nail_depth_m` places the ramp",
                    example=True,
                ),
                Key(
                    "magnetic_field_spf",
                    _V,
                    REQUIRED,
                    "1",
                    "local magnetic field direction in SPF (3DM attitude); any non-zero length",
                    example=True,
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
                    "triads",
                    _L,
                    ["BP", "PYBP", "PXBP", "MXBP"],
                    meaning="triad names (lever arms in the lander asset)",
                    example=True,
                ),
                Key(
                    "noise_g",
                    _F,
                    0.2,
                    "g",
                    _AFTER_FILTER + "; 0: absent",
                    ge=0.0,
                ),
                Key("bias_g", _F, 0.005, "g", "residual bias after zeroing, 1σ per axis", ge=0.0),
                Key("scale", _F, 0.002, "1", "scale-factor error, 1σ (filter: measurement noise ∝ the force)", ge=0.0),
                Key(
                    "misalignment_deg",
                    _F,
                    0.05,
                    "deg",
                    "axis misalignment, 1σ (filter: measurement noise ∝ the force)",
                    ge=0.0,
                ),
                Key("full_scale_g", _F, 2000.0, "g", "saturation level", gt=0.0),
            ),
        ),
        Table(
            "sensors.gyro",
            "rate gyro",
            (
                Key(
                    "noise_dps",
                    _F,
                    0.4,
                    "deg/s",
                    _AFTER_FILTER,
                    gt=0.0,
                ),
                Key("bias_dps", _F, 0.05, "deg/s", "bias, 1σ", ge=0.0),
                Key("scale", _F, 0.01, "1", "scale-factor error, 1σ", ge=0.0),
                Key("misalignment_deg", _F, 0.05, "deg", "axis misalignment, 1σ", ge=0.0),
                Key("full_scale_dps", _F, 1000.0, "deg/s", "saturation level", gt=0.0),
            ),
        ),
        Table(
            "sensors.acquisition",
            "data acquisition",
            (
                Key("sample_rate_hz", _F, 2000.0, "Hz", "IMU sample rate (synthetic)", gt=0.0, example=True),
                Key(
                    "filter",
                    _S,
                    "butterworth",
                    meaning="the anti-alias filter the IMU channels went through: `butterworth` causal (its "
                    "low-frequency group delay is removed from the time tags), `zero_phase` (forward-backward, "
                    "no delay), `none`",
                    choices=("butterworth", "zero_phase", "none"),
                    example=True,
                ),
                Key(
                    "filter_cutoff_hz", _F, 500.0, "Hz", "Butterworth cutoff, below half the sample rate", example=True
                ),
                Key(
                    "filter_order",
                    _I,
                    4,
                    meaning='Butterworth order (0: no filter, as `filter = "none"`)',
                    ge=0,
                    le=10,
                    example=True,
                ),
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
                    "the simulator)",
                    gt=0.0,
                ),
                Key(
                    "magnetic_sigma_deg",
                    _F,
                    1.0,
                    "deg",
                    "direction error of the measured magnetic vector, per perpendicular axis as above",
                    gt=0.0,
                ),
                Key("rate_hz", _F, 100.0, "Hz", "sample rate (synthetic)", gt=0.0),
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
                    gt=0.0,
                ),
                Key("odometer", _B, False, meaning="bungee-sheave odometer until the cut"),
                Key(
                    "odometer_sigma_m",
                    _F,
                    0.01,
                    "m",
                    "odometer noise of each recorded sample as written in the file, 1σ (after any filter the "
                    "channel went through; white: each sample is one measurement)",
                    ge=0.0,
                ),
                Key(
                    "odometer_quantisation_m",
                    _F,
                    0.0,
                    "m",
                    "the odometer's count step: it reads a whole number of steps; the filter adds the rounding's "
                    "variance q²/12 to `odometer_sigma_m`² (0: not quantised); the synthetic writer rounds to it",
                    ge=0.0,
                ),
                Key(
                    "odometer_zero_m",
                    _F,
                    0.0,
                    "m",
                    "the odometer's zero: it reads the rope length (sheave to attachment) minus this",
                    example=True,
                ),
                Key(
                    "radar_range_sigma_m",
                    _F,
                    0.02,
                    "m",
                    "radar-gun range noise of each recorded sample, 1σ (every gun without its own)",
                    gt=0.0,
                ),
                Key("radar_rate_sigma_mps", _F, 0.05, "m/s", "radar-gun range-rate noise, 1σ (idem)", gt=0.0),
                Key(
                    "reflector_body_m",
                    _V,
                    [0.0, 0.0, 0.0],
                    "m",
                    "corner reflector in the lander frame (the asset's; its origin is the CM unless the asset "
                    "gives `cm_m`), for every gun without its own",
                    example=True,
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
            free_gt=0.0,
        ),
        Table(
            "sensors.ranging.rate_sigma_mps",
            "per gun: range-rate noise (default `radar_rate_sigma_mps`)",
            free="float",
            free_meaning="gun name = range-rate noise, 1σ [m/s]",
            free_gt=0.0,
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
                Key("rate_hz", _F, 1000.0, "Hz", "IMU samples are averaged down to this rate", gt=0.0),
                Key("q_accel", _F, 5.0, "m²/s⁵", "white-jerk PSD floor", ge=0.0),
                Key("q_angular", _F, 20.0, "rad²/s⁵", "white angular-jerk PSD floor", ge=0.0),
                Key("adaptive_gain", _F, 4.0, "1", "Q raised by gain × (measured jerk)² × dt", ge=0.0),
                Key("hang_zupt_sigma_mps", _F, 0.005, "m/s", "zero-velocity update while hanging, 1σ", gt=0.0),
                Key("velocity_sigma_mps", _F, 0.01, "m/s", "initial velocity, 1σ", gt=0.0),
                Key("accel_sigma_mps2", _F, 0.5, "m/s²", "initial acceleration, 1σ", gt=0.0),
                Key("rate_sigma_dps", _F, 0.5, "deg/s", "initial body rate, 1σ", gt=0.0),
                Key("angular_accel_sigma", _F, 2.0, "rad/s²", "initial angular acceleration, 1σ", gt=0.0),
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
                Key("survey_sigma_m", _F, 0.03, "m", "error of the surveyed hanging position, 1σ", gt=0.0),
                Key("bag_pressure_psi", _F, None, "psi", "airbag pressure; absent: the lander asset's"),
            ),
        ),
    ),
)


#: The lander asset's schema is declared beside its reader (:mod:`.lander` may not import this
#: module: :class:`DropSettings` reads the asset) and listed here with the others.
LANDER_SCHEMA = _LANDER_SCHEMA

#: The drop setup file (``[telemetry] setup``), read by
#: :func:`workbench.problems.droptest.telemetry.read_setup`: which ``[bungee]`` keys are needed
#: depends on the filter mode and the odometer (code there); absent optional tables stay absent.
SETUP_SCHEMA = Schema(
    "droptest_setup",
    "drop setup file",
    (
        Table(
            "hanging",
            "the surveyed hanging state (SPF)",
            (
                Key("position_m", _V, REQUIRED, "m", "the CM in SPF while hanging", example=True),
                Key("position_sigma_m", _F, REQUIRED, "m", "its 1σ per axis", gt=0.0, example=True),
            ),
        ),
        Table(
            "bungee",
            'the bungee test plan: needed whole by `[filter] mode = "dynamic"`, only `anchor_m` and '
            "`attach_body_m` by the odometer; the kinematic filter ignores it",
            (
                Key("anchor_m", _V, None, "m", "bungee anchor (the odometer's sheave) in SPF", example=True),
                Key("rest_length_m", _F, None, "m", "rest length", gt=0.0, example=True),
                Key(
                    "coefficients",
                    _L,
                    None,
                    "N/m^k",
                    "per-bungee force polynomial in the stretch, k = 1..",
                    example=True,
                ),
                Key("count", _F, None, "1", "number of bungees (continuous: the design's)", gt=0.0, example=True),
                Key("attach_body_m", _V, None, "m", "rope attachment in the lander frame L", example=True),
                Key("mass_kg", _F, None, "kg", "lander mass of the test plan", gt=0.0, example=True),
            ),
        ),
        Table(
            "rocks",
            "a surveyed rock field (rigid spheres)",
            (
                Key("centers_m", _L, REQUIRED, "m", "sphere centres, n × [x, y, z] in SPF", example=True),
                Key("radii_m", _L, REQUIRED, "m", "sphere radii (n)", gt=0.0, example=True),
            ),
        ),
    ),
    noun="drop setup file",
    intro="Keys of a drop setup file (`[telemetry] setup`)",
)


# ------------------------------------------------------------------ the settings of one run
@dataclass(frozen=True)
class Rocks:
    """``[chamber.rocks]``: placement ``seed``, mean ``spacing_m`` [m], ``extent_m`` ramp-plane
    window ``((u0, u1), (v0, v1))`` [m] (across, up-slope)."""

    seed: int
    spacing_m: float
    extent_m: tuple[tuple[float, float], tuple[float, float]]


@dataclass(frozen=True, eq=False)
class Chamber:
    """``[chamber]``: ``ramp_angle_deg`` [deg]; ``nail_depth_m`` [m] the signed offset of the ramp
    plane from the nail along its normal (the key's, or ``n · ramp_point_m`` when that is given);
    ``magnetic_field_spf`` (3,) read-only, not normalised; ``rocks`` the rock field, or None without
    ``[chamber.rocks]``."""

    ramp_angle_deg: float
    nail_depth_m: float
    magnetic_field_spf: np.ndarray
    rocks: Rocks | None


@dataclass(frozen=True)
class Accelerometer:
    """``[sensors.accelerometer]`` (units as the names say): ``triads`` names, 1σ ``noise_g``,
    ``bias_g``, ``scale``, ``misalignment_deg``, saturation ``full_scale_g``."""

    triads: tuple[str, ...]
    noise_g: float
    bias_g: float
    scale: float
    misalignment_deg: float
    full_scale_g: float


@dataclass(frozen=True)
class Gyro:
    """``[sensors.gyro]``: 1σ ``noise_dps``, ``bias_dps``, ``scale``, ``misalignment_deg``,
    saturation ``full_scale_dps``."""

    noise_dps: float
    bias_dps: float
    scale: float
    misalignment_deg: float
    full_scale_dps: float


@dataclass(frozen=True)
class Acquisition:
    """``[sensors.acquisition]``: ``sample_rate_hz`` [Hz]; ``filter`` the anti-alias filter actually
    applied (``"none"`` when ``filter_order = 0``), ``cutoff_hz`` [Hz], ``order``; ``latency_s`` [s]."""

    sample_rate_hz: float
    filter: str
    cutoff_hz: float
    order: int
    latency_s: float


@dataclass(frozen=True)
class Attitude3dm:
    """``[sensors.attitude_3dm]``: 1σ ``gravity_sigma_deg``, ``magnetic_sigma_deg`` [deg],
    ``rate_hz`` [Hz], ``latency_s`` [s]."""

    gravity_sigma_deg: float
    magnetic_sigma_deg: float
    rate_hz: float
    latency_s: float


@dataclass(frozen=True, eq=False)
class Ranging:
    """``[sensors.ranging]`` (units as the key names say).  ``enabled``: the table is present (the
    synthetic writer then writes ranging); ``rate_given``: ``rate_hz`` was written (user data is
    then checked against it); ``radar_guns`` name -> SPF position (3,); per gun (every gun listed,
    the common value where the scenario gives none): ``reflectors_body_m`` (3,) in the lander frame,
    ``range_sigma_m``, ``rate_sigma_mps``."""

    enabled: bool
    rate_hz: float
    rate_given: bool
    odometer: bool
    odometer_sigma_m: float
    odometer_zero_m: float
    odometer_quantisation_m: float
    radar_range_sigma_m: float
    radar_rate_sigma_mps: float
    reflector_body_m: np.ndarray
    latency_s: float
    acquisition_filter: bool
    radar_guns: dict[str, np.ndarray]
    reflectors_body_m: dict[str, np.ndarray]
    range_sigma_m: dict[str, float]
    rate_sigma_mps: dict[str, float]


@dataclass(frozen=True)
class FilterSettings:
    """``[filter]``: ``mode``, ``rate_hz`` [Hz], PSD floors ``q_accel`` [m²/s⁵], ``q_angular``
    [rad²/s⁵], ``adaptive_gain``, 1σ ``hang_zupt_sigma_mps``, ``velocity_sigma_mps`` [m/s],
    ``accel_sigma_mps2`` [m/s²], ``rate_sigma_dps`` [deg/s], ``angular_accel_sigma`` [rad/s²]."""

    mode: str
    rate_hz: float
    q_accel: float
    q_angular: float
    adaptive_gain: float
    hang_zupt_sigma_mps: float
    velocity_sigma_mps: float
    accel_sigma_mps2: float
    rate_sigma_dps: float
    angular_accel_sigma: float


@dataclass(frozen=True)
class Synthetic:
    """``[synthetic]``, the truth side: sensor ``seed``; target impact speeds ``impact_parallel_mps``,
    ``impact_normal_mps`` [m/s, Mars frame]; ``release_euler123_deg`` (3,) [deg];
    ``release_to_contact_s``, ``pre_release_s`` [s]; ``bungee_truth_scale`` [1]; ``survey_sigma_m``
    [m]; ``bag_pressure_psi`` [psi] or None (the lander asset's)."""

    seed: int
    impact_parallel_mps: float
    impact_normal_mps: float
    release_euler123_deg: tuple[float, float, float]
    release_to_contact_s: float
    pre_release_s: float
    bungee_truth_scale: float
    survey_sigma_m: float
    bag_pressure_psi: float | None


@dataclass(frozen=True, eq=False)
class DropSettings:
    """The frozen settings of one drop-test run, built once by :meth:`from_scenario` (defaults from
    :data:`SCHEMA`).  ``run`` what the run is; ``lander_file`` the asset (absolute path) and
    ``lander`` the model read from it once; ``telemetry`` stream -> absolute path of each
    ``[telemetry]`` file given (None when absent; existence is checked when the files are used);
    one small dataclass per stage.  Picklable (Monte Carlo workers receive it); vary it with
    :func:`dataclasses.replace`."""

    run: RunInfo
    lander_file: Path
    lander: LanderModel
    telemetry: dict[str, Path | None]
    chamber: Chamber
    accelerometer: Accelerometer
    gyro: Gyro
    acquisition: Acquisition
    attitude_3dm: Attitude3dm
    ranging: Ranging
    filter: FilterSettings
    synthetic: Synthetic

    @property
    def name(self) -> str:
        """The scenario name."""
        return self.run.name

    @property
    def path(self) -> Path:
        """The scenario file (errors name it)."""
        return self.run.path

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> DropSettings:
        """Validate ``scenario`` against :data:`SCHEMA` (unknown keys, types, bounds: a
        :class:`ScenarioError` naming file and key), check what the bounds cannot express, read the
        lander asset (:data:`LANDER_SCHEMA`) and build the settings."""
        if scenario.kind != "droptest":
            raise ScenarioError(scenario.path, "scenario.kind", f"{scenario.kind!r} is not a droptest scenario")
        v = SCHEMA.validate(scenario.data, scenario.path)
        _check_cross_fields(v, scenario.path)
        if scenario.has("chamber.ramp_point_m") and scenario.has("chamber.nail_depth_m"):
            raise ScenarioError(
                scenario.path,
                "chamber.ramp_point_m",
                "give either 'nail_depth_m' or 'ramp_point_m' (both place the ramp plane), not both",
            )
        run = RunInfo.from_scenario(scenario)
        lander_file = run.resolve(v["vehicle"]["lander"]).absolute()
        if not lander_file.exists():
            raise ScenarioError(scenario.path, "vehicle.lander", f"file not found: {lander_file}")
        lander = load_lander(lander_file)
        if run.synthetic:  # the truth simulator's keys: user data may leave them out
            require_simulator_keys(lander, lander_file, except_pressure=v["synthetic"]["bag_pressure_psi"] is not None)
        ch, rk = v["chamber"], v["chamber"]["rocks"]
        acc, gyr = v["sensors"]["accelerometer"], v["sensors"]["gyro"]
        aq, a3, rg = v["sensors"]["acquisition"], v["sensors"]["attitude_3dm"], v["sensors"]["ranging"]
        f, s = v["filter"], v["synthetic"]
        guns = {str(k): _frozen(p) for k, p in rg.get("radar_guns", {}).items()}
        reflector = _frozen(rg["reflector_body_m"])
        refl = {str(k): _frozen(p) for k, p in rg.get("reflectors", {}).items()}
        sig_r = {str(k): float(x) for k, x in rg.get("range_sigma_m", {}).items()}
        sig_rr = {str(k): float(x) for k, x in rg.get("rate_sigma_mps", {}).items()}
        ext = rk["extent_m"]
        return cls(
            run=run,
            lander_file=lander_file,
            lander=lander,
            telemetry={k: (None if p is None else run.resolve(p).absolute()) for k, p in v["telemetry"].items()},
            chamber=from_table(
                Chamber,
                ch,
                nail_depth_m=ch["nail_depth_m"]
                if ch["ramp_point_m"] is None
                else float(ramp_normal(ch["ramp_angle_deg"]) @ np.asarray(ch["ramp_point_m"], float)),
                magnetic_field_spf=_frozen(ch["magnetic_field_spf"]),
                rocks=from_table(
                    Rocks, rk, extent_m=((float(ext[0][0]), float(ext[0][1])), (float(ext[1][0]), float(ext[1][1])))
                )
                if scenario.has("chamber.rocks")
                else None,
            ),
            accelerometer=from_table(Accelerometer, acc, triads=tuple(acc["triads"])),
            gyro=Gyro(**gyr),
            acquisition=Acquisition(
                sample_rate_hz=aq["sample_rate_hz"],
                filter="none" if aq["filter_order"] == 0 else aq["filter"],
                cutoff_hz=aq["filter_cutoff_hz"],
                order=aq["filter_order"],
                latency_s=aq["latency_s"],
            ),
            attitude_3dm=Attitude3dm(**a3),
            ranging=from_table(
                Ranging,
                rg,
                enabled=scenario.has("sensors.ranging"),
                rate_given=scenario.has("sensors.ranging.rate_hz"),
                reflector_body_m=reflector,
                radar_guns=guns,
                reflectors_body_m={g: refl.get(g, reflector) for g in guns},
                range_sigma_m={g: sig_r.get(g, rg["radar_range_sigma_m"]) for g in guns},
                rate_sigma_mps={g: sig_rr.get(g, rg["radar_rate_sigma_mps"]) for g in guns},
            ),
            filter=FilterSettings(**f),
            synthetic=from_table(Synthetic, s, release_euler123_deg=tuple(float(a) for a in s["release_euler123_deg"])),
        )


def _frozen(a) -> np.ndarray:
    out = np.array(a, float)
    out.flags.writeable = False  # shared by every user of the settings
    return out


# ------------------------------------------------------------------ checks the bounds cannot express
def _check_cross_fields(v: dict, path: Path) -> None:
    """What the schema's types and bounds cannot refuse: a ScenarioError naming file and key."""

    def bad(key: str, msg: str) -> None:
        raise ScenarioError(path, key, msg)

    if not np.isfinite(v["chamber"]["nail_depth_m"]):
        bad("chamber.nail_depth_m", "must be a finite number of metres")
    if v["chamber"]["ramp_point_m"] is not None and not np.all(np.isfinite(v["chamber"]["ramp_point_m"])):
        bad("chamber.ramp_point_m", "must be three finite numbers [m]")
    if not np.linalg.norm(v["chamber"]["magnetic_field_spf"]) > 0.0:
        bad("chamber.magnetic_field_spf", "a zero vector has no direction")
    rg = v["sensors"]["ranging"]
    for table in ("range_sigma_m", "rate_sigma_mps"):
        for gun, x in rg.get(table, {}).items():
            if not np.isfinite(x):  # > 0 is the table's schema bound
                bad(f"sensors.ranging.{table}.{gun}", f"{x}: a measurement's 1σ must be finite")
    if rg.get("odometer") and not rg["odometer_sigma_m"] ** 2 + rg["odometer_quantisation_m"] ** 2 / 12.0 > 0.0:
        bad(
            "sensors.ranging.odometer_sigma_m",
            "0 with `odometer_quantisation_m` 0 declares a perfect odometer: the filter's measurement variance "
            "σ² + q²/12 must be > 0",
        )
    guns = set(rg.get("radar_guns", {}))
    for table in ("reflectors", "range_sigma_m", "rate_sigma_mps"):
        for gun in rg.get(table, {}):
            if gun not in guns:
                bad(
                    f"sensors.ranging.{table}.{gun}",
                    f"no radar gun '{gun}' in [sensors.ranging.radar_guns] (guns: {', '.join(sorted(guns)) or 'none'})",
                )
    aq = v["sensors"]["acquisition"]
    if aq["filter"] != "none" and aq["filter_order"] > 0 and not 0.0 < aq["filter_cutoff_hz"]:
        bad("sensors.acquisition.filter_cutoff_hz", "must be > 0")
