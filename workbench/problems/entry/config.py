"""Entry scenario settings: the schema of a ``kind = "entry"`` scenario (every key the
reconstruction, the synthetic telemetry and the truth simulator read, with its default, once) and
:class:`EntrySettings`, the frozen settings of one run built once by
:meth:`EntrySettings.from_scenario` (``EntryProblem.settings``).

Only this module sees the :class:`~workbench.io.scenario.Scenario`; every stage below receives its
own small frozen dataclass (telemetry checks, preprocessing, reconstruction prior, dispersion,
radar/filter, atmosphere, winds, synthetic sensors and truth) and the vehicle asset loaded once.
Defaults a stage dataclass already carries (:class:`~workbench.problems.entry.preprocess.PreprocessConfig`,
:class:`~workbench.problems.entry.sensors.EntryTelemetrySpec`, :class:`~workbench.problems.entry.truth.EntryTruthSpec`,
:class:`~workbench.problems.entry.atmosphere.AtmosphereSettings` ...) are read from it into the schema so
they are declared once; every other default lives in the schema's :class:`Key`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.core.frames import julian_date_from_utc
from workbench.io.assets import asset_path
from workbench.io.scenario import RunInfo, Scenario, ScenarioError
from workbench.io.schema import Key, Schema, Table, from_table, scenario_table
from workbench.models.aerodynamics import EntryVehicle, load_vehicle
from workbench.models.radar import AZIMUTHS_DEG, SQUINT_DEG, beam_directions_G
from workbench.problems.entry.atmosphere import FILL_TEMPERATURE_SHAPES, AtmosphereSettings, EntryProfileSigmas
from workbench.problems.entry.dispersion import AcceptanceRules, DispersionSigmas
from workbench.problems.entry.filter import EntryFilterSigmas
from workbench.problems.entry.preprocess import PreprocessConfig
from workbench.problems.entry.sensors import DEFAULT_GAPS, EntryTelemetrySpec, NominalErrorModel
from workbench.problems.entry.site import R_MOLA, TERRAIN_ELEVATION_M
from workbench.problems.entry.state import DP, DTH, DV
from workbench.problems.entry.telemetry import TelemetryChecks
from workbench.problems.entry.truth import EntryTruthSpec
from workbench.problems.imu_settings import imu_error_model

__all__ = [
    "SCHEMA",
    "RULES",
    "EntrySettings",
    "ReconstructionSettings",
    "DispersionSettings",
    "RadarSettings",
    "SyntheticSettings",
]

_F, _I, _S, _B, _V, _L = "float", "int", "str", "bool", "vec3", "list"

#: Dispersion acceptance rules (``[dispersion.rules]``): name -> (unit, meaning); defaults those of
#: :class:`~workbench.problems.entry.dispersion.AcceptanceRules` (AMELIA Sect. 6).
RULES = {
    "mach_pdd": ("1", "Mach number at PDD"),
    "h_pdd_m": ("m", "altitude above the MOLA radius at PDD"),
    "h_fsr_m": ("m", "altitude above the MOLA radius at FSR"),
    "h_end_m": ("m", "altitude above the MOLA radius at the end of the data"),
    "time_to_impact_s": ("s", "from the end of the data to the ballistic impact"),
}

_PRE = PreprocessConfig()
_TM = EntryTelemetrySpec()
_CHECKS = TelemetryChecks()
_RULES = AcceptanceRules()
_ATM = AtmosphereSettings()
_FS = EntryFilterSigmas()
_DS = DispersionSigmas()

_TRUTH_MEANING = {
    "epoch_utc": ("", "UTC of EIP; absent: `[scenario] epoch_utc`"),
    "t0": ("s", "start, from EIP (AMELIA Table 2)"),
    "p0_km": ("km", "initial position, MMED"),
    "v0_kmps": ("km/s", "initial velocity, MMED"),
    "q0_jpl": ("1", 'JPL quaternion "MMED to GNC" (4 numbers, scalar last)'),
    "fpa_offset_deg": ("deg", "truth flight-path angle minus the nominal (< 0 steeper)"),
    "speed_offset_mps": ("m/s", "truth speed minus the nominal"),
    "aoa_offset_deg": ("deg", "extra tilt of the nominal attitude"),
    "aoa_offset_azimuth_deg": ("deg", "body azimuth of that tilt (from +X_G towards +Y_G)"),
    "w0_dps": ("deg/s", "initial body rate"),
    "roll_moment_coeff": ("1", "constant roll-moment coefficient (asymmetric ablation)"),
    "initial_position_offset_km": ("km", "truth initial position minus the nominal, MMED"),
    "aero_deviation_mach": ("1", "Mach nodes of the planted axial-coefficient deviation"),
    "ca_deviation": ("1", "truth CA / table CA − 1 at those nodes (smooth in log Mach)"),
    "cn_deviation": ("1", "truth CN / table CN − 1"),
    "cm_deviation": ("1", "truth Cm / table Cm − 1"),
    "parachute_deviation_mach": ("1", "Mach nodes of the planted parachute CD deviation"),
    "parachute_cd_deviation": ("1", "truth CD / table CD − 1 of the parachute at those nodes"),
    "surface_pressure_pa": ("Pa", "true pressure at 0 km AMR"),
    "temperature_profile_km_K": ("km, K", "climate temperature profile nodes [h_km, T_K] (AMR)"),
    "temperature_waves": ("K, km, deg", "gravity waves [amplitude_K, wavelength_km, phase_deg]"),
    "wave_growth_scale_km": ("km", "wave amplitude grows as exp(h / this)"),
    "wave_growth_cap": ("1", "... up to this factor"),
    "inversion_center_km": ("km", "temperature inversion centre (AMR)"),
    "inversion_width_km": ("km", "inversion width"),
    "inversion_amplitude_K": ("K", "inversion amplitude"),
    "molar_mass_g_per_mol": ("g/mol", "true mean molar mass"),
    "gamma": ("1", "true ratio of specific heats"),
    "terrain_modes": (
        "m, km, deg, deg, deg",
        "terrain relief [amplitude_m, wavelength_km, dir_lat_deg, dir_lon_deg, phase_deg]",
    ),
    "h_top_km": ("km", "top of the true atmosphere table"),
    "wind_layers": ("km, m/s, deg", "[bottom_km, top_km, speed_mps, towards_deg, edge_km] (AMR)"),
    "background_wind_mps": ("m/s", "background wind speed"),
    "background_azimuth_deg": ("deg", "direction the background wind blows towards"),
    "background_turn_deg_per_km": ("deg/km", "turn of the background wind with altitude"),
    "pdd_mach": ("1", "PDD when the true Mach number drops below this"),
    "pdd_time_s": ("s", "PDD at this time instead (from EIP)"),
    "fsr_delay_s": ("s", "FSR after PDD"),
    "bsr_delay_s": ("s", "BSR (end of data) after FSR"),
    "deploy_tilt_deg": ("deg", "canopy direction at line stretch: tilt from +Z_G"),
    "deploy_azimuth_deg": ("deg", "... towards this body azimuth"),
    "eject_speed_mps": ("m/s", "mortar ejection speed"),
    "inflation_time_s": ("s", "canopy inflation time"),
    "breathing_amplitude": ("1", "canopy area oscillation (fraction of the area)"),
    "breathing_period_s": ("s", "breathing period"),
    "breathing_decay_s": ("s", "breathing decay time"),
    "side_force_coeff": ("1", "side force / drag during the asymmetric inflation"),
    "side_force_start_s": ("s", "side force from (after PDD)"),
    "side_force_end_s": ("s", "side force until (after PDD)"),
    "side_force_azimuth_deg": ("deg", "body azimuth of the side force"),
    "breathing_phase_sigma_deg": ("deg", "random breathing phase, 1σ"),
    "breathing_amp_jitter": ("1", "random ± relative change of the breathing amplitude"),
    "dt_entry": ("s", "integration step before PDD"),
    "dt_chute": ("s", "integration step from PDD on"),
    "dt_out": ("s", "output step"),
    "aero_enabled": ("", "false: vacuum flight (a test; needs t_end)"),
    "t_end": ("s", "end time (vacuum test)"),
}


def _truth_keys() -> tuple[Key, ...]:
    keys = []
    d = EntryTruthSpec()
    for f in dataclasses.fields(EntryTruthSpec):
        v = getattr(d, f.name)
        if isinstance(v, bool):
            kind = _B
        elif isinstance(v, str):
            kind = _S
        elif isinstance(v, tuple):
            kind = _V if len(v) == 3 and not isinstance(v[0], tuple) else _L
            v = [list(x) if isinstance(x, tuple) else x for x in v]
        else:
            kind = _F
        unit, meaning = _TRUTH_MEANING[f.name]
        keys.append(Key(f.name, kind, v, unit, meaning, ge=0.0 if "sigma" in f.name else None))  # a 1σ is ≥ 0
    return tuple(keys)


def _deg(x: float) -> float:
    return float(round(math.degrees(x), 12))


SCHEMA = Schema(
    "entry",
    "AMELIA entry and descent reconstruction",
    (
        scenario_table("entry", epoch="UTC of EIP (t = 0); absent: the telemetry's `# epoch_utc:`"),
        Table(
            "vehicle",
            "the entry vehicle",
            (
                Key(
                    "file",
                    _S,
                    None,
                    meaning="vehicle asset TOML, relative to the scenario file; required for a reconstruction "
                    "(a synthetic scenario falls back to the shipped Schiaparelli)",
                ),
            ),
        ),
        Table(
            "telemetry",
            "user telemetry files, relative to the scenario file (ignored by a synthetic scenario); all required",
            (
                Key("gnc", _S, None, meaning="GNC CSV, 10 Hz: rate, JPL quaternion, total acceleration"),
                Key("gnc_nav", _S, None, meaning="on-board navigation CSV, 1 Hz: position, velocity"),
                Key("rda_slant_range", _S, None, meaning="radar slant ranges CSV (B0..B3)"),
                Key("rda_out", _S, None, meaning="radar slant-out / velocity-out CSV"),
                Key("events", _S, None, meaning="events CSV (PDD, FSR needed)"),
                Key("initial_state", _S, None, meaning="nominal initial state TOML (AMELIA Table 2)"),
            ),
        ),
        Table(
            "site",
            "the landing site",
            (
                Key(
                    "terrain_m", _F, TERRAIN_ELEVATION_M, "m", "terrain elevation above the MOLA radius (ground sphere)"
                ),
            ),
        ),
        Table(
            "preprocess",
            "telemetry checks and AMELIA Sect. 4 preprocessing",
            (
                Key("quat_error_tol", _F, _CHECKS.quat_error_tol, "1", "a GNC quaternion norm off by more is an error"),
                Key("quat_warn_tol", _F, _CHECKS.quat_warn_tol, "1", "... by more than this a WARN (normalised)"),
                Key("saturation_dps", _F, _deg(_PRE.saturation), "deg/s", "gyro saturation threshold"),
                Key("saturation_margin_dps", _F, _deg(_PRE.saturation_margin), "deg/s", "detection margin"),
                Key("gap_factor", _F, _PRE.gap_factor, "1", "a gap is a step longer than this × the nominal"),
                Key("resample_hz", _F, _PRE.resample_rate_hz, "Hz", "resampling rate after PDD"),
                Key("resample_window_s", _F, _PRE.resample_window_s, "s", "resampled window after PDD"),
                Key(
                    "nav_interpolation",
                    _S,
                    _PRE.nav_interpolation,
                    meaning="on-board p/v to the 10 Hz grid",
                    choices=("acceleration", "cubic"),
                ),
                Key(
                    "rebuild_neighbours",
                    _I,
                    _PRE.rebuild_neighbours,
                    meaning="unsaturated neighbours per side that a saturated run's rebuild starts from",
                    gt=0,
                ),
                Key(
                    "rebuild_from_accel",
                    _B,
                    _PRE.rebuild_from_accel,
                    meaning="saturated X/Y rate from the lateral acceleration",
                ),
                Key(
                    "sigma_rate_dps",
                    _F,
                    None,
                    "deg/s",
                    "per-sample rate 1σ; absent: `[reconstruction] rate_dps`",
                    ge=0.0,
                ),
                Key(
                    "sigma_accel_mps2",
                    _F,
                    None,
                    "m/s²",
                    "per-sample acceleration 1σ; absent: `[reconstruction] accel_mps2`",
                    ge=0.0,
                ),
                Key(
                    "sigma_rate_saturated_dps",
                    _F,
                    None,
                    "deg/s",
                    "rebuilt saturated rate 1σ; absent: `[reconstruction] rate_pdd_dps`",
                    gt=0.0,
                ),
                Key(
                    "sigma_rate_resampled_dps",
                    _F,
                    None,
                    "deg/s",
                    "resampled rate 1σ; absent: `[reconstruction] rate_pdd_dps`",
                    gt=0.0,
                ),
                Key(
                    "sigma_accel_resampled_mps2",
                    _F,
                    _PRE.sigma_f_resampled,
                    "m/s²",
                    "resampled acceleration 1σ",
                    ge=0.0,
                ),
            ),
        ),
        Table(
            "reconstruction",
            "AMELIA Table 3, reconstruction column (1σ)",
            (
                Key("attitude_deg", _F, 1.0, "deg", "initial attitude", gt=0.0),
                Key("velocity_mps", _F, 10.0, "m/s", "initial velocity", gt=0.0),
                Key("position_m", _F, 2000.0, "m", "initial position", gt=0.0),
                Key("rate_dps", _F, _deg(_PRE.sigma_w), "deg/s", "body rate, per sample", ge=0.0),
                Key(
                    "rate_pdd_dps",
                    _F,
                    _deg(_PRE.sigma_w_saturated),
                    "deg/s",
                    "body rate inside the saturation window and after PDD's resampling",
                    gt=0.0,
                ),
                Key("accel_mps2", _F, _PRE.sigma_f, "m/s²", "specific force, per sample", ge=0.0),
                Key(
                    "bridge_mode",
                    _S,
                    _FS.bridge_mode,
                    meaning="gap bridge position form",
                    choices=("relative", "paper"),
                ),
                Key("initial", _S, "fused", meaning="the smoother's start", choices=("fused", "dispersion", "nominal")),
                Key(
                    "imu_accel_bias_mps2",
                    _F,
                    0.0,
                    "m/s²",
                    "IMU datasheet: accelerometer bias, 1σ (process noise)",
                    ge=0.0,
                ),
                Key("imu_accel_scale", _F, 0.0, "1", "IMU datasheet: accelerometer scale factor, 1σ", ge=0.0),
                Key(
                    "imu_accel_misalignment_rad",
                    _F,
                    0.0,
                    "rad",
                    "IMU datasheet: accelerometer misalignment, 1σ",
                    ge=0.0,
                ),
                Key("imu_gyro_bias_dps", _F, 0.0, "deg/s", "IMU datasheet: gyro bias, 1σ", ge=0.0),
                Key("imu_gyro_scale", _F, 0.0, "1", "IMU datasheet: gyro scale factor, 1σ", ge=0.0),
                Key("imu_gyro_misalignment_rad", _F, 0.0, "rad", "IMU datasheet: gyro misalignment, 1σ", ge=0.0),
            ),
        ),
        Table(
            "dispersion",
            "AMELIA Sect. 6 dispersion analysis",
            (
                Key("members", _I, 10000, meaning="trajectories per round", gt=0),
                Key("chunk_size", _I, 1000, meaning="members per work unit", gt=0),
                Key("seed", _I, 2016, meaning="random seed"),
                Key("attitude_deg", _F, _deg(_DS.attitude_rad), "deg", "initial attitude dispersion, 1σ", gt=0.0),
                Key("velocity_mps", _F, _DS.velocity_m_s, "m/s", "initial velocity dispersion, 1σ", gt=0.0),
                Key("position_m", _F, _DS.position_m, "m", "initial position dispersion, 1σ", gt=0.0),
                Key("cloud", _I, 300, meaning="members kept for the recording", ge=0),
                Key("refine_rounds", _I, 0, meaning="extra rounds sampled about the previous elite", ge=0),
            ),
        ),
        Table(
            "dispersion.rules",
            "acceptance rules, each [centre, half-width > 0]: a member is accepted when every quantity is inside",
            tuple(Key(k, _L, list(getattr(_RULES, k)), u, m) for k, (u, m) in RULES.items()),
        ),
        Table(
            "radar",
            "radar altimeter model of the filter (AMELIA Appendix B)",
            (
                Key("squint_deg", _F, SQUINT_DEG, "deg", "squint of beams B1..B3 from -Z_G"),
                Key("azimuths_deg", _V, list(AZIMUTHS_DEG), "deg", "azimuths of B1..B3 from +X_G towards +Y_G"),
                Key("slant_range_sigma_m", _F, _FS.slant_range, "m", "slant-range measurement 1σ", gt=0.0),
                Key("slant_out_sigma_m", _F, _FS.slant_out, "m", "slant-out measurement 1σ", gt=0.0),
                Key(
                    "terrain_sigma_m",
                    _F,
                    0.0,
                    "m",
                    "terrain relief about the sphere, 1σ: added in quadrature to both range 1σ",
                    ge=0.0,
                ),
                Key(
                    "terrain_correlation_s",
                    _F,
                    0.0,
                    "s",
                    "time over which the terrain error of consecutive slant-out samples is correlated "
                    "(relief correlation length / ground speed); 0 = white. The terrain variance of each "
                    "slant-out sample is multiplied by this time × the sample rate (R inflation for "
                    "time-correlated errors)",
                ),
                Key("velocity_out_sigma_mps", _F, _FS.velocity_out, "m/s", "velocity-out measurement 1σ", gt=0.0),
                Key("constrained", _B, True, meaning="AMELIA Sect. 8 constrained update directions"),
            ),
        ),
        Table(
            "atmosphere",
            "AMELIA Sect. 9 atmosphere reconstruction",
            (
                Key(
                    "molar_mass_g_per_mol", _F, _ATM.molar_mass_g_per_mol, "g/mol", "molar mass of the Mars atmosphere"
                ),
                Key(
                    "fill_method",
                    _S,
                    _ATM.fill_method,
                    meaning="blackout fill",
                    choices=("hydrostatic", "exponential"),
                ),
                Key(
                    "fill_temperature_shape",
                    _S,
                    _ATM.fill_temperature_shape,
                    meaning="hydrostatic fill's temperature across a gap: the default model's shape + offset + trend, "
                    "or offset + trend alone",
                    choices=FILL_TEMPERATURE_SHAPES,
                ),
                Key("tolerance", _F, _ATM.tolerance, "1", "drag-coefficient iteration tolerance (relative)", gt=0.0),
                Key("max_iterations", _I, _ATM.max_iterations, meaning="drag-coefficient iterations", gt=0),
                Key("cd_sigma", _F, _ATM.sigmas.cd_rel, "1", "drag coefficients, relative 1σ", ge=0.0),
                Key("wind_sigma_mps", _F, _ATM.sigmas.wind, "m/s", "wind uncertainty below 30 km, 1σ", ge=0.0),
                Key(
                    "fill_temperature_sigma_K",
                    _F,
                    _ATM.sigmas.fill_temperature_K,
                    "K",
                    "blackout fill: true temperature minus the assumed one, 1σ (Gaussian process)",
                    ge=0.0,
                ),
                Key(
                    "fill_correlation_km",
                    _F,
                    _ATM.sigmas.fill_correlation_km,
                    "km",
                    "blackout fill: correlation length of that departure",
                ),
            ),
        ),
        Table(
            "winds",
            "AMELIA Sect. 10 winds",
            (Key("method", _S, "specific_force", meaning="wind estimator", choices=("specific_force", "attitude")),),
        ),
        Table(
            "sensors.imu",
            "synthetic IMU",
            (
                Key("accel_noise_mps2", _F, _TM.imu.accel_noise, "m/s²", "per on-board sample, 1σ", ge=0.0),
                Key("accel_bias_mps2", _F, _TM.imu.accel_bias, "m/s²", "bias, 1σ", ge=0.0),
                Key("accel_scale", _F, _TM.imu.accel_scale, "1", "scale-factor error, 1σ", ge=0.0),
                Key(
                    "accel_misalignment_rad",
                    _F,
                    _TM.imu.accel_misalignment,
                    "rad",
                    "triad misalignment, 1σ per axis",
                    ge=0.0,
                ),
                Key("gyro_noise_dps", _F, _deg(_TM.imu.gyro_noise), "deg/s", "per on-board sample, 1σ", ge=0.0),
                Key("gyro_bias_dps", _F, _deg(_TM.imu.gyro_bias), "deg/s", "bias, 1σ", ge=0.0),
                Key("gyro_scale", _F, _TM.imu.gyro_scale, "1", "scale-factor error, 1σ", ge=0.0),
                Key(
                    "gyro_misalignment_rad",
                    _F,
                    _TM.imu.gyro_misalignment,
                    "rad",
                    "triad misalignment, 1σ per axis",
                    ge=0.0,
                ),
                Key(
                    "gyro_full_scale_dps",
                    "number_or_vec3",
                    _deg(_TM.imu.gyro_full_scale[0]),
                    "deg/s",
                    "gyro saturation, all axes or per axis",
                ),
                Key("accel_full_scale_mps2", _F, _TM.imu.accel_full_scale, "m/s²", "accelerometer saturation"),
                Key("onboard_rate_hz", _F, _TM.onboard_rate_hz, "Hz", "on-board IMU rate"),
                Key("tm_rate_hz", _F, _TM.gnc_rate_hz, "Hz", "GNC telemetry rate"),
                Key("nav_rate_hz", _F, _TM.nav_rate_hz, "Hz", "on-board navigation telemetry rate"),
            ),
        ),
        Table(
            "sensors.radar",
            "synthetic radar altimeter (RDA); zero_filled_packets also sets the telemetry check",
            (
                Key(
                    "range_sigma_m",
                    _F,
                    _TM.range_sigma,
                    "m",
                    "1σ = hypot(range_sigma_m, range_sigma_frac × range)",
                    ge=0.0,
                ),
                Key("range_sigma_frac", _F, _TM.range_sigma_frac, "1", "range-proportional part", ge=0.0),
                Key("velocity_sigma_mps", _F, _TM.velocity_sigma, "m/s", "velocity-out noise, 1σ", ge=0.0),
                Key("rate_hz", _F, _TM.rda_rate_hz, "Hz", "RDA packet rate"),
                Key("on_after_fsr_s", _F, _TM.rda_on_after_fsr_s, "s", "RDA switched on after FSR"),
                Key("slant_range_period_s", _F, _TM.sr_period_s, "s", "slant-range packet period"),
                Key("first_packet_after_on_s", _F, _TM.sr_first_after_on_s, "s", "first slant-range packet after on"),
                Key(
                    "zero_filled_packets",
                    _I,
                    _TM.sr_zero_filled,
                    meaning="leading zero-filled slant-range packets (written, and expected by the telemetry check)",
                ),
            ),
        ),
        Table(
            "synthetic",
            "synthetic telemetry (its presence makes the scenario synthetic)",
            (
                Key("seed", _I, 0, meaning="seed of the sensor-side draws"),
                Key("truth_seed", _I, None, meaning="seed of the truth's random parts; absent: `seed`"),
                Key(
                    "blackout_gaps_s",
                    _L,
                    [list(g) for g in DEFAULT_GAPS],
                    "s",
                    "telemetry gaps [start_s, duration_s]",
                ),
            ),
        ),
        Table(
            "synthetic.nominal_error",
            "error of the on-board nominal initial state",
            (
                Key("velocity_sigma_mps", _F, _TM.nominal.velocity_sigma, "m/s", "velocity, 1σ", ge=0.0),
                Key("attitude_sigma_deg", _F, _deg(_TM.nominal.attitude_sigma), "deg", "attitude, 1σ", ge=0.0),
                Key("position_sigma_m", _F, _TM.nominal.position_sigma, "m", "position, 1σ", ge=0.0),
                Key("dx0", _L, None, "m/s, deg, m", "a fixed error (9 numbers) instead of a draw"),
            ),
        ),
        Table("truth", "truth simulator (synthetic only; never read by the reconstruction)", _truth_keys()),
    ),
)


# ------------------------------------------------------------------------------------ settings
@dataclass(frozen=True)
class ReconstructionSettings:
    """``[reconstruction]``: the navigation prior 1σ of AMELIA Table 3 (velocity [m/s], attitude
    [deg], position [m]), the gap-bridge mode, the smoother start (``initial``) and the IMU datasheet
    error levels ``imu_errors`` (1σ, SI: ``accel_bias`` [m/s²], ``gyro_bias`` [rad/s], scales [-],
    misalignments [rad]) the smoother turns into process noise."""

    sigma_velocity_mps: float
    sigma_attitude_deg: float
    sigma_position_m: float
    bridge_mode: str
    initial: str
    imu_errors: dict


@dataclass(frozen=True)
class DispersionSettings:
    """``[dispersion]`` (AMELIA Sect. 6): member count, work-unit size, seed, the initial-state
    dispersion 1σ (attitude [deg], velocity [m/s], position [m]), members kept for the recording
    (``cloud``), refinement rounds and the acceptance ``rules``."""

    members: int
    chunk_size: int
    seed: int
    attitude_deg: float
    velocity_mps: float
    position_m: float
    cloud: int
    refine_rounds: int
    rules: AcceptanceRules

    def sigmas(self) -> dict:
        """The dispersion 1σ as ``run_dispersion`` takes them: attitude [rad], velocity [m/s], position [m]."""
        return {"attitude": math.radians(self.attitude_deg), "velocity": self.velocity_mps, "position": self.position_m}


@dataclass(frozen=True)
class RadarSettings:
    """``[radar]``: the filter's radar altimeter model (AMELIA Appendix B): beam squint and azimuths
    [deg], the instrument's range 1σ [m], the terrain relief 1σ [m] and its correlation time [s],
    the velocity-out 1σ [m/s] and the constrained update directions (AMELIA Sect. 8)."""

    squint_deg: float
    azimuths_deg: tuple[float, float, float]
    slant_range_sigma_m: float
    slant_out_sigma_m: float
    terrain_sigma_m: float
    terrain_correlation_s: float
    velocity_out_sigma_mps: float
    constrained: bool

    def beams_G(self) -> np.ndarray:
        """The beam unit vectors (4, 3) in the GNC frame (``models.radar.beam_directions_G``)."""
        return beam_directions_G(self.squint_deg, self.azimuths_deg)


@dataclass(frozen=True)
class SyntheticSettings:
    """``[synthetic]``, ``[sensors.*]`` and ``[truth]``: the sensor-side seed, the truth seed
    (``truth_seed``, else ``seed``), the synthetic telemetry spec and the truth simulator spec."""

    seed: int
    truth_seed: int
    telemetry: EntryTelemetrySpec
    truth: EntryTruthSpec


@dataclass(frozen=True)
class EntrySettings:
    """The frozen settings of one entry run, validated against :data:`SCHEMA` and built once by
    :meth:`from_scenario` (picklable: Monte Carlo workers receive them).

    ``run`` the scenario file's :class:`~workbench.io.scenario.RunInfo`; ``vehicle_path`` the
    absolute (resolved) vehicle asset path and ``vehicle`` the asset loaded once (None for a user scenario
    without ``[vehicle] file``: :meth:`require_vehicle` raises then); ``telemetry`` the absolute
    (resolved) paths of the ``[telemetry]`` keys given; ``epoch_utc`` of EIP or None; ``terrain_m`` [m] above
    the MOLA radius; the per-stage settings ``checks``, ``preprocess``, ``reconstruction``,
    ``dispersion``, ``radar``, ``atmosphere``, ``wind_method`` and ``synthetic``.
    """

    run: RunInfo
    vehicle_path: Path | None
    vehicle: EntryVehicle | None
    telemetry: dict
    epoch_utc: str | None
    terrain_m: float
    checks: TelemetryChecks
    preprocess: PreprocessConfig
    reconstruction: ReconstructionSettings
    dispersion: DispersionSettings
    radar: RadarSettings
    atmosphere: AtmosphereSettings
    wind_method: str
    synthetic: SyntheticSettings

    @property
    def r_ground(self) -> float:
        """Radius of the ground sphere [m]: the MOLA radius plus ``terrain_m``."""
        return R_MOLA + self.terrain_m

    def require_vehicle(self) -> EntryVehicle:
        """The vehicle asset; a :class:`ScenarioError` on ``vehicle.file`` if the scenario names none."""
        if self.vehicle is None:
            raise ScenarioError(self.run.path, "vehicle.file", "missing: a reconstruction needs the vehicle asset")
        return self.vehicle

    def smoother_sigmas(self, slant_out_dt_s: float | None = None) -> dict:
        """The radar-aided smoother's measurement 1σ and gap-bridge mode, as
        ``run_entry_smoother(sigmas=...)`` takes them: slant range [m], slant-out [m],
        velocity-out [m/s], ``bridge_mode``.  The range 1σ are the instrument's
        (``slant_range_sigma_m``, ``slant_out_sigma_m``) and the terrain relief the filter does not
        model (``terrain_sigma_m``, its sphere's error) in quadrature.

        The terrain error is not white: consecutive slant-out samples ``slant_out_dt_s`` [s] apart
        see nearly the same relief for ``terrain_correlation_s``.  A white-noise filter fed N
        samples of one constant error would average it down by √N; multiplying the terrain
        variance by N = max(1, terrain_correlation_s / slant_out_dt_s) keeps the information the
        filter draws from one correlation time equal to one independent sample (the usual R
        inflation for time-correlated measurement errors; Bar-Shalom, Li & Kirubarajan 2001,
        "Estimation with Applications to Tracking and Navigation", Sect. 8.3).  Without
        ``slant_out_dt_s`` (or with ``terrain_correlation_s = 0``) the terrain error is white."""
        r = self.radar
        n = 1.0
        if slant_out_dt_s is not None and slant_out_dt_s > 0 and r.terrain_correlation_s > 0:
            n = max(1.0, r.terrain_correlation_s / slant_out_dt_s)
        return {
            "slant_range": math.hypot(r.slant_range_sigma_m, r.terrain_sigma_m),
            "slant_out": math.hypot(r.slant_out_sigma_m, r.terrain_sigma_m * math.sqrt(n)),
            "velocity_out": r.velocity_out_sigma_mps,
            "bridge_mode": self.reconstruction.bridge_mode,
        }

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> EntrySettings:
        """Validate ``scenario`` against :data:`SCHEMA` (unknown keys, types, choices, the bounds it
        declares: counts, every 1σ), check the rest (rules ``[centre, half-width > 0]``, a parsable epoch,
        the truth and sensor specs), load the vehicle asset once and build the settings; every
        error is a :class:`ScenarioError` naming file and key."""
        if scenario.kind != "entry":
            raise ScenarioError(scenario.path, "scenario.kind", f"{scenario.kind!r} is not an entry scenario")
        file = scenario.path
        v = SCHEMA.validate(scenario.data, file)
        run = RunInfo.from_scenario(scenario)
        epoch = v["scenario"]["epoch_utc"]
        if epoch is not None:
            try:
                julian_date_from_utc(epoch)
            except ValueError as e:
                raise ScenarioError(file, "scenario.epoch_utc", str(e)) from None
        vpath, vehicle = _vehicle(run, v["vehicle"]["file"])
        return cls(
            run=run,
            vehicle_path=vpath,
            vehicle=vehicle,
            telemetry={k: run.resolve(p).resolve() for k, p in v["telemetry"].items() if p is not None},
            epoch_utc=epoch,
            terrain_m=v["site"]["terrain_m"],
            checks=TelemetryChecks(
                quat_error_tol=v["preprocess"]["quat_error_tol"],
                quat_warn_tol=v["preprocess"]["quat_warn_tol"],
                zero_filled_packets=v["sensors"]["radar"]["zero_filled_packets"],
            ),
            preprocess=_preprocess(file, v["preprocess"], v["reconstruction"]),
            reconstruction=_reconstruction(v["reconstruction"]),
            dispersion=_dispersion(file, v["dispersion"]),
            radar=_radar(v["radar"]),
            atmosphere=_atmosphere(v["atmosphere"], v["reconstruction"]["accel_mps2"]),
            wind_method=v["winds"]["method"],
            synthetic=SyntheticSettings(
                seed=v["synthetic"]["seed"],
                truth_seed=v["synthetic"]["seed"]
                if v["synthetic"]["truth_seed"] is None
                else v["synthetic"]["truth_seed"],
                telemetry=_telemetry_spec(file, v),
                truth=_truth_spec(file, v["truth"], epoch, "epoch_utc" in scenario.data.get("truth", {})),
            ),
        )


def _vehicle(run: RunInfo, rel: str | None) -> tuple[Path | None, EntryVehicle | None]:
    """``[vehicle] file`` resolved and loaded; absent: the shipped Schiaparelli for a synthetic
    scenario, nothing for a user one."""
    if rel is None:
        if not run.synthetic:
            return None, None
        path = asset_path("vehicles", "schiaparelli.toml")
    else:
        path = run.resolve(rel).resolve()
        if not path.exists():
            raise ScenarioError(run.path, "vehicle.file", f"file not found: {path}")
    return path, load_vehicle(path)


def _preprocess(file: Path, pre: dict, rec: dict) -> PreprocessConfig:
    def pick(key: str, fallback: str) -> float:
        return pre[key] if pre[key] is not None else rec[fallback]

    try:
        return PreprocessConfig(
            sigma_w=math.radians(pick("sigma_rate_dps", "rate_dps")),
            sigma_f=pick("sigma_accel_mps2", "accel_mps2"),
            sigma_w_saturated=math.radians(pick("sigma_rate_saturated_dps", "rate_pdd_dps")),
            sigma_w_resampled=math.radians(pick("sigma_rate_resampled_dps", "rate_pdd_dps")),
            sigma_f_resampled=pre["sigma_accel_resampled_mps2"],
            saturation=math.radians(pre["saturation_dps"]),
            saturation_margin=math.radians(pre["saturation_margin_dps"]),
            gap_factor=pre["gap_factor"],
            resample_rate_hz=pre["resample_hz"],
            resample_window_s=pre["resample_window_s"],
            nav_interpolation=pre["nav_interpolation"],
            rebuild_neighbours=pre["rebuild_neighbours"],
            rebuild_from_accel=pre["rebuild_from_accel"],
        )
    except ValueError as e:
        raise ScenarioError(file, "preprocess", str(e)) from None


def _reconstruction(rec: dict) -> ReconstructionSettings:
    return ReconstructionSettings(
        sigma_velocity_mps=rec["velocity_mps"],
        sigma_attitude_deg=rec["attitude_deg"],
        sigma_position_m=rec["position_m"],
        bridge_mode=rec["bridge_mode"],
        initial=rec["initial"],
        imu_errors={
            "accel_bias": rec["imu_accel_bias_mps2"],
            "accel_scale": rec["imu_accel_scale"],
            "accel_misalignment": rec["imu_accel_misalignment_rad"],
            "gyro_bias": math.radians(rec["imu_gyro_bias_dps"]),
            "gyro_scale": rec["imu_gyro_scale"],
            "gyro_misalignment": rec["imu_gyro_misalignment_rad"],
        },
    )


def _dispersion(file: Path, dis: dict) -> DispersionSettings:
    rules = {}
    for k, r in dis["rules"].items():
        if not (len(r) == 2 and all(isinstance(x, int | float) and not isinstance(x, bool) for x in r) and r[1] > 0):
            raise ScenarioError(file, f"dispersion.rules.{k}", "need [centre, half-width] with half-width > 0")
        rules[k] = (float(r[0]), float(r[1]))
    return from_table(DispersionSettings, dis, rules=AcceptanceRules(**rules))


def _radar(rad: dict) -> RadarSettings:
    return from_table(RadarSettings, rad, azimuths_deg=tuple(float(a) for a in rad["azimuths_deg"]))


def _atmosphere(atm: dict, accel_mps2: float) -> AtmosphereSettings:
    return dataclasses.replace(
        _ATM,
        molar_mass_g_per_mol=atm["molar_mass_g_per_mol"],
        fill_method=atm["fill_method"],
        fill_temperature_shape=atm["fill_temperature_shape"],
        tolerance=atm["tolerance"],
        max_iterations=atm["max_iterations"],
        sigmas=EntryProfileSigmas(
            cd_rel=atm["cd_sigma"],
            accel=accel_mps2,
            wind=atm["wind_sigma_mps"],
            fill_temperature_K=atm["fill_temperature_sigma_K"],
            fill_correlation_km=atm["fill_correlation_km"],
        ),
    )


def _telemetry_spec(file: Path, v: dict) -> EntryTelemetrySpec:
    """The synthetic telemetry spec from the validated ``[sensors.*]``, ``[synthetic]``, ``[site]``
    and ``[radar]`` tables (the beam geometry and terrain the filter uses too)."""
    imu, rad, syn, ne = v["sensors"]["imu"], v["sensors"]["radar"], v["synthetic"], v["synthetic"]["nominal_error"]
    fs = imu["gyro_full_scale_dps"]
    fs = [float(fs)] * 3 if isinstance(fs, int | float) else [float(x) for x in fs]
    dx0 = ne["dx0"]
    if dx0 is not None:
        dx0 = [float(x) for x in dx0]
        if len(dx0) != 9:
            raise ScenarioError(file, "synthetic.nominal_error.dx0", "must hold 9 numbers (m/s, deg, m)")
        dx0 = tuple(dx0[DV] + [math.radians(x) for x in dx0[DTH]] + dx0[DP])
    return EntryTelemetrySpec(
        imu=imu_error_model(
            imu,
            accel_misalignment=imu["accel_misalignment_rad"],
            gyro_misalignment=imu["gyro_misalignment_rad"],
            gyro_full_scale=tuple(math.radians(x) for x in fs),  # type: ignore[arg-type]
            accel_full_scale=imu["accel_full_scale_mps2"],
        ),
        nominal=NominalErrorModel(
            velocity_sigma=ne["velocity_sigma_mps"],
            attitude_sigma=math.radians(ne["attitude_sigma_deg"]),
            position_sigma=ne["position_sigma_m"],
            dx0=dx0,
        ),
        onboard_rate_hz=imu["onboard_rate_hz"],
        gnc_rate_hz=imu["tm_rate_hz"],
        nav_rate_hz=imu["nav_rate_hz"],
        gaps=tuple((float(a), float(b)) for a, b in syn["blackout_gaps_s"]),
        rda_rate_hz=rad["rate_hz"],
        rda_on_after_fsr_s=rad["on_after_fsr_s"],
        sr_period_s=rad["slant_range_period_s"],
        sr_first_after_on_s=rad["first_packet_after_on_s"],
        sr_zero_filled=rad["zero_filled_packets"],
        range_sigma=rad["range_sigma_m"],
        range_sigma_frac=rad["range_sigma_frac"],
        velocity_sigma=rad["velocity_sigma_mps"],
        r_ground=R_MOLA + v["site"]["terrain_m"],
        squint_deg=v["radar"]["squint_deg"],
        azimuths_deg=tuple(float(x) for x in v["radar"]["azimuths_deg"]),  # type: ignore[arg-type]
    )


#: ``[truth]`` keys holding arrays: 1 = a list of numbers, 2 = a list of rows of numbers.
_TRUTH_DEPTH = {
    "p0_km": 1,
    "v0_kmps": 1,
    "q0_jpl": 1,
    "w0_dps": 1,
    "initial_position_offset_km": 1,
    "aero_deviation_mach": 1,
    "ca_deviation": 1,
    "parachute_deviation_mach": 1,
    "parachute_cd_deviation": 1,
    "temperature_profile_km_K": 2,
    "temperature_waves": 2,
    "terrain_modes": 2,
    "wind_layers": 2,
}


def _truth_spec(file: Path, table: dict, epoch: str | None, epoch_given: bool) -> EntryTruthSpec:
    """The truth simulator spec from the validated ``[truth]`` table; its ``epoch_utc`` is
    ``[scenario] epoch_utc`` unless ``[truth]`` gives one."""
    kw = {}
    for key, val in table.items():
        depth = _TRUTH_DEPTH.get(key)
        try:
            if depth == 1:
                val = tuple(float(x) for x in val)
            elif depth == 2:
                val = tuple(tuple(float(x) for x in row) for row in val)
        except (TypeError, ValueError):
            raise ScenarioError(file, f"truth.{key}", f"need numbers, got {val!r}"[:300]) from None
        kw[key] = val
    if not epoch_given and epoch is not None:
        kw["epoch_utc"] = epoch
    try:
        return EntryTruthSpec(**kw)
    except ValueError as e:
        raise ScenarioError(file, "truth", str(e)) from None
