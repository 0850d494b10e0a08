"""Flush air data (MEADS) scenario configuration: the schema of a ``kind = "meads"`` scenario (every
key, its unit, default and meaning, once) and :class:`MeadsConfig`, the typed settings built once
from a validated scenario.  Truth and sensor defaults come from the dataclasses of
:mod:`.truth` and :mod:`.sensors`, so they are declared once.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, replace

from workbench.io.scenario import Scenario, ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table
from workbench.models.imu import ImuErrorModel
from workbench.problems.meads.sensors import FAILURE_MODES, NavigationErrorSpec, PressureSensorSpec
from workbench.problems.meads.truth import MeadsTruthSpec

__all__ = ["SCHEMA", "EstimatorSettings", "EkfSettings", "McSettings", "MeadsConfig", "config_for"]

_T = MeadsTruthSpec()
_P = PressureSensorSpec()
_N = NavigationErrorSpec()
_IMU_DEFAULT = {
    "rate_hz": 20.0,
    "accel_noise_mps2": 3e-3,
    "gyro_noise_dps": 0.005,
    "accel_bias_mps2": 1e-3,
    "gyro_bias_dps": 1.0 / 3600.0,
    "accel_scale": 1e-4,
    "gyro_scale": 1e-4,
}


@dataclass(frozen=True)
class EstimatorSettings:
    """How the pressures are reduced (scenario ``[estimator]`` and ``[winds]``).

    ``model``: ``"newtonian"`` (Eq. 1–4) or ``"table"`` (the estimator's own Cp database);
    ``solution``: ``"mach"`` (q∞, α, β, M), ``"static"`` (q∞, α, β, p∞), ``"fixed_r"`` (p_t, α, β
    with R fixed, q∞ from the limit of R M²; Newtonian only) or ``"auto"`` (fixed R where the
    inertial Mach exceeds ``switch_mach``, the Mach set below); ``fixed_r``: the fixed pressure ratio
    (0: scheduled from the inertial Mach, the paper's suggestion); ``gamma`` the estimator's ratio of
    specific heats; ``model_error_frac``: 1σ model-form allowance as a fraction of reading added
    to the sensor σ in R; ``iterations``: Gauss–Newton iterations; ``lag_inversion``: undo the
    pneumatic lag before the fit; ``failed_port_nsigma``/``failed_port_samples``: a port whose
    normalised residual exceeds the first for the second consecutive samples is declared failed
    from there on; ``plausibility_factor``: the pressures' q∞ and the IMU drag's q∞ may differ by
    this factor before the run is refused; ``min_qbar_pa``: the objectives' threshold (850 Pa);
    ``wind_det_min``: |det| of the normalised wind Jacobian below which the wind solution is
    declared singular (near-zero flight-path angle) and not published; ``wind_sigma_max`` [m/s]: nor is a
    wind whose 1σ (Eq. 16) exceeds it.
    """

    model: str = "newtonian"
    solution: str = "auto"
    switch_mach: float = 3.0
    fixed_r: float = 0.0
    gamma: float = 1.335
    model_error_frac: float = 0.01
    iterations: int = 12
    lag_inversion: bool = True
    failed_port_nsigma: float = 6.0
    failed_port_samples: int = 4
    plausibility_factor: float = 3.0
    min_qbar_pa: float = 850.0
    wind_det_min: float = 0.1
    wind_sigma_max: float = 50.0


@dataclass(frozen=True)
class EkfSettings:
    """The filter's tuning (scenario ``[ekf]``).

    ``enabled``; ``passes`` 1 or 2; ``iterations`` of the iterated update (Eq. 33);
    ``accel_psd`` [m²/s³] velocity random walk (accelerometer noise, bias and scale not in the
    strapdown); ``attitude_psd`` [rad²/s] attitude random walk (gyro); ``wind_sigma_mps`` /
    ``vertical_wind_sigma_mps`` prior 1σ of the horizontal / vertical wind; ``wind_var_per_km``
    [(m/s)² per km of altitude travelled]; ``atmosphere_sigma_ln`` prior 1σ of ln p∞ and ln ρ∞ about
    the engineering atmosphere; ``atmosphere_var_per_km`` [per km] random walk of ln p∞, ln ρ∞;
    ``scale_factor_sigma`` prior 1σ of each transducer scale factor (of reading);
    ``model_level_sigma`` prior 1σ of the common level error of the pressure model (of reading,
    a constant state; 0: not modelled).

    The pressure model's error as coloured states (:mod:`.ekf`): ``model_error_sigma`` the
    steady-state 1σ of each port's multiplicative model error (of reading; the least squares'
    1 % allowance, made a state; 0: not modelled, and R then carries the estimator's white
    ``model_error_frac`` as before); ``model_error_order`` 1 (first-order Gauss–Markov) or 2
    (critically damped second order: smooth, like the table's error; measured on ``msl_meads``
    NIS 0.3 instead of 0.15 but scale factors 4–7 of 7 inside 3σ instead of 7, :mod:`.ekf`); ``model_error_mach_length``
    [Mach] and ``model_error_angle_deg`` [deg of |Δα| + |Δβ|] its correlation lengths in flight
    condition (:func:`.ekf.flight_distance`); ``model_mach_sigma`` 1σ of the model's relative
    Mach error (pressures read at M(1 + m), a first-order Gauss–Markov over the same distance;
    0: not modelled); ``bias_sigma_pa`` [Pa] prior 1σ of each transducer's additive residual
    bias after the in-flight zero (Eq. 51; constant; 0: not modelled); ``noise_counts`` the
    channel's white noise N in counts (Eq. 38, uniform over N counts): with the model error a
    state, R is only that and the quantisation, σ² = (N² + 1)/12 counts².
    ``model_angle_sigma_deg`` [deg] 1σ of the model's flow-angle errors (pressures read at
    α + a_m, β + b_m; first-order Gauss–Markov over the same distance; 0: not modelled) at and
    below Mach ``model_angle_mach_low``, ``model_angle_hypersonic_fraction`` of it at and above
    ``model_angle_mach_high``, linear in Mach between (:func:`.ekf.angle_sigma`);
    ``attitude_velocity_coupling``: the attitude error tilts the specific force the strapdown
    integrated (``δv' = δv − [Δv_f×] C_M_B δθ``); ``vertical_wind_length_km`` [km] the vertical
    wind as a first-order Gauss–Markov over the altitude travelled, 1σ
    ``vertical_wind_sigma_mps`` (gravity waves: zero mean, short vertical correlation; 0: a random
    walk like the horizontal wind).  The defaults (1°, 0.1, coupling on, 5 km) and what each
    changed are measured in :mod:`.ekf`.
    """

    enabled: bool = True
    passes: int = 2
    iterations: int = 4
    accel_psd: float = 2e-4
    attitude_psd: float = 4e-9
    wind_sigma_mps: float = 30.0
    vertical_wind_sigma_mps: float = 3.0
    vertical_wind_length_km: float = 5.0
    wind_var_per_km: float = 30.0
    atmosphere_sigma_ln: float = 1.0
    atmosphere_var_per_km: float = 1e-4
    scale_factor_sigma: float = 0.01
    model_level_sigma: float = 0.01
    model_error_sigma: float = 0.01
    model_error_mach_length: float = 3.0
    model_error_angle_deg: float = 2.0
    model_error_order: int = 1
    noise_counts: float = 2.0
    bias_sigma_pa: float = 3.5
    model_mach_sigma: float = 0.1
    model_angle_sigma_deg: float = 1.0
    model_angle_hypersonic_fraction: float = 0.1
    model_angle_mach_low: float = 5.0
    model_angle_mach_high: float = 10.0
    attitude_velocity_coupling: bool = True


@dataclass(frozen=True)
class McSettings:
    """The trade study (``[montecarlo]``): ``runs`` per error level, ``levels`` (fractions of
    reading), ``fixed_r``, ``stride`` (every stride-th pressure sample)."""

    runs: int = 3000
    levels: tuple[float, ...] = (0.005, 0.01, 0.025, 0.05)
    fixed_r: float = 0.001
    stride: int = 8


@dataclass(frozen=True)
class MeadsConfig:
    """Everything a MEADS run reads from its scenario."""

    vehicle_file: str
    telemetry: dict
    truth: MeadsTruthSpec
    pressure: PressureSensorSpec
    imu: ImuErrorModel
    imu_rate_hz: float
    navigation: NavigationErrorSpec
    estimator: EstimatorSettings
    ekf: EkfSettings
    mc: McSettings
    seed: int

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> MeadsConfig:
        """Validate ``scenario`` against :data:`SCHEMA` and build the config."""
        if scenario.kind != "meads":
            raise ScenarioError(scenario.path, "scenario.kind", f"{scenario.kind!r} is not a meads scenario")
        v = SCHEMA.validate(scenario.data, scenario.path)
        tr, sp, si, sn, es, wi, mc, ek = (
            v["truth"],
            v["sensors"]["pressure"],
            v["sensors"]["imu"],
            v["sensors"]["navigation"],
            v["estimator"],
            v["winds"],
            v["montecarlo"],
            v["ekf"],
        )
        truth = replace(
            _T,
            **{k: tr[k] for k in tr if k not in ("bank_profile_deg",)},
            bank_profile_deg=tuple((float(a), float(b)) for a, b in tr["bank_profile_deg"]),
        )
        pressure = replace(
            _P,
            **{k: sp[k] for k in sp if k not in ("time_tag_max_us",)},
            time_tag_max_s=sp["time_tag_max_us"] * 1e-6,
        )
        if pressure.failure_mode not in FAILURE_MODES:
            raise ScenarioError(
                scenario.path, "sensors.pressure.failure_mode", f"use one of {', '.join(FAILURE_MODES)}"
            )
        imu = ImuErrorModel(
            accel_noise=si["accel_noise_mps2"],
            accel_bias=si["accel_bias_mps2"],
            accel_scale=si["accel_scale"],
            gyro_noise=math.radians(si["gyro_noise_dps"]),
            gyro_bias=math.radians(si["gyro_bias_dps"]),
            gyro_scale=si["gyro_scale"],
            gyro_full_scale=(math.radians(400.0),) * 3,
        )
        nav = NavigationErrorSpec(
            sn["position_sigma_m"], sn["velocity_sigma_mps"], math.radians(sn["attitude_sigma_deg"])
        )
        est = EstimatorSettings(**es, wind_det_min=wi["singular_det_min"], wind_sigma_max=wi["max_sigma_mps"])
        if est.model == "table" and est.solution == "fixed_r":
            raise ScenarioError(
                scenario.path,
                "estimator.solution",
                "the fixed-R solution is a Newtonian variant: use model = 'newtonian'",
            )
        if ek["passes"] not in (1, 2):
            raise ScenarioError(scenario.path, "ekf.passes", f"{ek['passes']}: use 1 or 2")
        if ek["iterations"] < 1:
            raise ScenarioError(scenario.path, "ekf.iterations", f"{ek['iterations']}: at least 1")
        for k in ("wind_sigma_mps", "vertical_wind_sigma_mps", "atmosphere_sigma_ln", "scale_factor_sigma"):
            if not ek[k] > 0.0:
                raise ScenarioError(scenario.path, f"ekf.{k}", f"{ek[k]}: a prior 1-sigma must be > 0")
        if ek["model_error_order"] not in (1, 2):
            raise ScenarioError(scenario.path, "ekf.model_error_order", f"{ek['model_error_order']}: use 1 or 2")
        for k in ("model_error_mach_length", "model_error_angle_deg", "noise_counts"):
            if not ek[k] > 0.0:
                raise ScenarioError(scenario.path, f"ekf.{k}", f"{ek[k]}: must be > 0")
        for k in (
            "accel_psd",
            "attitude_psd",
            "wind_var_per_km",
            "atmosphere_var_per_km",
            "model_level_sigma",
            "model_error_sigma",
            "model_mach_sigma",
            "model_angle_sigma_deg",
            "model_angle_hypersonic_fraction",
            "vertical_wind_length_km",
            "bias_sigma_pa",
        ):
            if not ek[k] >= 0.0:
                raise ScenarioError(scenario.path, f"ekf.{k}", f"{ek[k]}: a 1-sigma or process noise must be >= 0")
        if not ek["model_angle_mach_low"] < ek["model_angle_mach_high"]:
            raise ScenarioError(
                scenario.path,
                "ekf.model_angle_mach_high",
                f"{ek['model_angle_mach_high']}: must be above model_angle_mach_low ({ek['model_angle_mach_low']})",
            )
        levels = tuple(float(x) / 100.0 for x in mc["levels_pct"])
        return cls(
            vehicle_file=v["vehicle"]["file"],
            telemetry=dict(v["telemetry"]),
            truth=truth,
            pressure=pressure,
            imu=imu,
            imu_rate_hz=si["rate_hz"],
            navigation=nav,
            estimator=est,
            ekf=EkfSettings(**ek),
            mc=McSettings(mc["runs"], levels, mc["fixed_r"], mc["stride"]),
            seed=v["synthetic"]["seed"],
        )


_E = EstimatorSettings()
_K = EkfSettings()
_M = McSettings()

SCHEMA = Schema(
    "meads",
    "flush air data (MEADS): forebody pressures + IMU -> q, Mach, alpha, beta, density, winds",
    (
        Table(
            "scenario",
            "what the run is",
            (
                Key("name", "str", REQUIRED, meaning="names the run and its output files"),
                Key("kind", "str", REQUIRED, meaning='`"meads"`'),
                Key("description", "str", "", meaning="one line for listings"),
                Key("epoch_utc", "str", None, meaning="UTC of t = 0 (the entry interface), metadata only"),
            ),
        ),
        Table(
            "vehicle",
            "the heat shield and its ports",
            (Key("file", "str", REQUIRED, meaning="vehicle TOML with the port geometry (relative to the scenario)"),),
        ),
        Table(
            "telemetry",
            "the user's files (a synthetic scenario writes its own)",
            (
                Key("pressures", "str", None, meaning="pressure CSV: `time [s]` and one column per port `P1 [Pa]`..."),
                Key("imu", "str", None, meaning="IMU CSV: `f_x..f_z [m/s^2]`, `w_x..w_z [deg/s]` (body axes)"),
                Key("initial_state", "str", None, meaning="TOML: the navigation state at the first IMU time"),
            ),
        ),
        Table("synthetic", "simulate instead of reading telemetry", (Key("seed", "int", 0, meaning="sensor errors"),)),
        Table(
            "truth",
            "the truth simulator (synthetic only)",
            (
                Key("entry_altitude_km", "float", _T.entry_altitude_km, "km", "entry interface altitude"),
                Key("entry_speed_kmps", "float", _T.entry_speed_kmps, "km/s", "inertial speed at entry"),
                Key("entry_fpa_deg", "float", _T.entry_fpa_deg, "deg", "inertial flight-path angle at entry"),
                Key("entry_azimuth_deg", "float", _T.entry_azimuth_deg, "deg", "heading from north"),
                Key("entry_latitude_deg", "float", _T.entry_latitude_deg, "deg", "latitude of the entry point"),
                Key("mass_kg", "float", _T.mass_kg, "kg", "entry mass"),
                Key("bank_profile_deg", "list", [list(x) for x in _T.bank_profile_deg], "s, deg", "(t, bank) nodes"),
                Key("alpha_hyper_deg", "float", _T.alpha_hyper_deg, "deg", "trim alpha above Mach 25"),
                Key("alpha_low_deg", "float", _T.alpha_low_deg, "deg", "trim alpha below Mach 5"),
                Key("alpha_osc_deg", "float", _T.alpha_osc_deg, "deg", "alpha oscillation amplitude"),
                Key("beta_osc_deg", "float", _T.beta_osc_deg, "deg", "sideslip oscillation amplitude"),
                Key("chute_mach", "float", _T.chute_mach, "", "parachute deployment Mach"),
                Key("hss_delay_s", "float", _T.hss_delay_s, "s", "heat-shield separation after deployment"),
                Key("surface_pressure_pa", "float", _T.surface_pressure_pa, "Pa", "true pressure at 0 km"),
                Key("gamma", "float", _T.gamma, "", "true ratio of specific heats"),
                Key("wave_amplitude_K", "float", _T.wave_amplitude_K, "K", "gravity-wave amplitude at 0 km"),
                Key("background_wind_mps", "float", _T.background_wind_mps, "m/s", "background wind speed"),
                Key("stagnation_shift", "float", _T.stagnation_shift, "", "true stagnation-point shift (of alpha_T)"),
                Key("shoulder", "float", _T.shoulder, "", "true shoulder expansion coefficient"),
            ),
        ),
        Table(
            "sensors.pressure",
            "the pressure error chain (paper Sect. IV.A); each source switchable",
            (
                Key("rate_hz", "float", _P.rate_hz, "Hz", "sample rate"),
                Key("bits", "int", _P.bits, "", "effective bits n (Eq. 38-39)"),
                Key("noise_counts", "float", _P.noise_counts, "", "noise counts N (Eq. 38)"),
                Key("port_location_sigma_m", "float", _P.port_location_sigma_m, "m", "1-sigma port position"),
                Key("time_tag_max_us", "float", _P.time_tag_max_s * 1e6, "us", "uniform time-tag error bound"),
                Key("transducer_temperature_K", "float", _P.transducer_temperature_K, "K", "transducer temperature"),
                Key("wall_temperature_peak_K", "float", _P.wall_temperature_peak_K, "K", "peak surface temperature"),
                Key("scale_sigma", "float", _P.scale_sigma, "", "transducer scale factor 1-sigma"),
                Key("nonlinearity_sigma", "float", _P.nonlinearity_sigma, "", "a2 nonlinearity at full scale"),
                Key("residual_bias_sigma_pa", "float", _P.residual_bias_sigma_pa, "Pa", "bias after in-flight zero"),
                Key("multiplicative_sigma", "float", _P.multiplicative_sigma, "", "per-sample error, of reading"),
                Key("location", "bool", _P.location, meaning="port location errors on"),
                Key("time_tag", "bool", _P.time_tag, meaning="time-tag errors on"),
                Key("lag", "bool", _P.lag, meaning="pneumatic lag on"),
                Key(
                    "transpiration",
                    "str",
                    _P.transpiration,
                    meaning="thermal transpiration model",
                    choices=("knudsen", "potter", "off"),
                ),
                Key("calibration", "bool", _P.calibration, meaning="residual bias + nonlinearity on"),
                Key("scale_factors", "bool", _P.scale_factors, meaning="transducer scale factors on"),
                Key("noise", "bool", _P.noise, meaning="noise on"),
                Key("quantization", "bool", _P.quantization, meaning="quantisation on"),
                Key("failure_port", "str", _P.failure_port, meaning="port that fails (empty: none)"),
                Key("failure_time_s", "float", _P.failure_time_s, "s", "when it fails"),
                Key("failure_mode", "str", _P.failure_mode, meaning="how it fails", choices=FAILURE_MODES),
                Key("failure_size", "float", _P.failure_size, "", "offset/drift size, of reading"),
            ),
        ),
        Table(
            "sensors.imu",
            "the synthetic IMU (body axes)",
            (
                Key("rate_hz", "float", _IMU_DEFAULT["rate_hz"], "Hz", "sample rate"),
                Key("accel_noise_mps2", "float", _IMU_DEFAULT["accel_noise_mps2"], "m/s^2", "white noise per sample"),
                Key("gyro_noise_dps", "float", _IMU_DEFAULT["gyro_noise_dps"], "deg/s", "white noise per sample"),
                Key("accel_bias_mps2", "float", _IMU_DEFAULT["accel_bias_mps2"], "m/s^2", "bias 1-sigma"),
                Key("gyro_bias_dps", "float", _IMU_DEFAULT["gyro_bias_dps"], "deg/s", "bias 1-sigma"),
                Key("accel_scale", "float", _IMU_DEFAULT["accel_scale"], "", "scale factor 1-sigma"),
                Key("gyro_scale", "float", _IMU_DEFAULT["gyro_scale"], "", "scale factor 1-sigma"),
            ),
        ),
        Table(
            "sensors.navigation",
            "error of the initial state written for the reconstruction",
            (
                Key("position_sigma_m", "float", _N.position_sigma, "m", "1-sigma per axis"),
                Key("velocity_sigma_mps", "float", _N.velocity_sigma, "m/s", "1-sigma per axis"),
                Key("attitude_sigma_deg", "float", math.degrees(_N.attitude_sigma), "deg", "1-sigma per axis"),
            ),
        ),
        Table(
            "estimator",
            "the least-squares reduction (paper Sect. III.A)",
            (
                Key("model", "str", _E.model, meaning="pressure model", choices=("newtonian", "table")),
                Key(
                    "solution",
                    "str",
                    _E.solution,
                    meaning="solution set",
                    choices=("auto", "mach", "static", "fixed_r"),
                ),
                Key("switch_mach", "float", _E.switch_mach, "", "auto: fixed R above this inertial Mach"),
                Key("fixed_r", "float", _E.fixed_r, "", "fixed pressure ratio (0: scheduled from inertial Mach)"),
                Key("gamma", "float", _E.gamma, "", "estimator's ratio of specific heats"),
                Key("model_error_frac", "float", _E.model_error_frac, "", "model-form 1-sigma, of reading"),
                Key("iterations", "int", _E.iterations, "", "Gauss-Newton iterations"),
                Key("lag_inversion", "bool", _E.lag_inversion, meaning="invert the pneumatic lag first"),
                Key("failed_port_nsigma", "float", _E.failed_port_nsigma, "", "residual threshold, sigmas"),
                Key("failed_port_samples", "int", _E.failed_port_samples, "", "consecutive samples to fail a port"),
                Key("plausibility_factor", "float", _E.plausibility_factor, "", "pressure vs drag q-bar"),
                Key("min_qbar_pa", "float", _E.min_qbar_pa, "Pa", "objectives apply above this q-bar"),
            ),
        ),
        Table(
            "winds",
            "wind solution (paper Eq. 11-17)",
            (
                Key("singular_det_min", "float", _E.wind_det_min, "", "normalised |det Gamma| below: singular"),
                Key("max_sigma_mps", "float", _E.wind_sigma_max, "m/s", "winds with a larger 1-sigma: not published"),
            ),
        ),
        Table(
            "ekf",
            "the tightly-coupled EKF (paper Sect. III.B, Eq. 19-35), multi-pass, RTS smoothed",
            (
                Key("enabled", "bool", _K.enabled, meaning="run the filter after the least squares"),
                Key("passes", "int", _K.passes, "", "1: scale factors estimated; 2: then reprocessed corrected"),
                Key("iterations", "int", _K.iterations, "", "iterated measurement update (Eq. 33), at most"),
                Key("accel_psd", "float", _K.accel_psd, "m^2/s^3", "velocity random walk beyond the strapdown"),
                Key("attitude_psd", "float", _K.attitude_psd, "rad^2/s", "attitude random walk beyond the strapdown"),
                Key("wind_sigma_mps", "float", _K.wind_sigma_mps, "m/s", "prior 1-sigma of the horizontal wind"),
                Key("vertical_wind_sigma_mps", "float", _K.vertical_wind_sigma_mps, "m/s", "prior 1-sigma, vertical"),
                Key(
                    "vertical_wind_length_km",
                    "float",
                    _K.vertical_wind_length_km,
                    "km",
                    "vertical wind: Gauss-Markov correlation length in altitude (0: a random walk like the horizontal)",
                ),
                Key("wind_var_per_km", "float", _K.wind_var_per_km, "(m/s)^2/km", "wind random walk per km descended"),
                Key("atmosphere_sigma_ln", "float", _K.atmosphere_sigma_ln, "", "prior 1-sigma of ln p and ln rho"),
                Key("atmosphere_var_per_km", "float", _K.atmosphere_var_per_km, "1/km", "ln p, ln rho random walk"),
                Key("scale_factor_sigma", "float", _K.scale_factor_sigma, "", "prior 1-sigma of each scale factor"),
                Key("model_level_sigma", "float", _K.model_level_sigma, "", "prior 1-sigma, pressure model level"),
                Key(
                    "model_error_sigma",
                    "float",
                    _K.model_error_sigma,
                    "",
                    "model error per port, steady 1-sigma, of reading (0: off, R carries model_error_frac)",
                ),
                Key(
                    "model_error_mach_length",
                    "float",
                    _K.model_error_mach_length,
                    "",
                    "model error correlation length in Mach",
                ),
                Key(
                    "model_error_angle_deg",
                    "float",
                    _K.model_error_angle_deg,
                    "deg",
                    "model error correlation length in |d alpha| + |d beta|",
                ),
                Key(
                    "model_error_order",
                    "int",
                    _K.model_error_order,
                    "",
                    "model error Gauss-Markov order: 1, or 2 (smooth)",
                ),
                Key(
                    "noise_counts",
                    "float",
                    _K.noise_counts,
                    "",
                    "white noise counts N of the channel (R when the model error is a state)",
                ),
                Key(
                    "bias_sigma_pa",
                    "float",
                    _K.bias_sigma_pa,
                    "Pa",
                    "prior 1-sigma of each transducer bias (0: not modelled)",
                ),
                Key(
                    "model_mach_sigma",
                    "float",
                    _K.model_mach_sigma,
                    "",
                    "model Mach error 1-sigma, relative (0: not modelled)",
                ),
                Key(
                    "model_angle_sigma_deg",
                    "float",
                    _K.model_angle_sigma_deg,
                    "deg",
                    "model flow-angle error 1-sigma, alpha and beta each, at low Mach (0: not modelled)",
                ),
                Key(
                    "model_angle_hypersonic_fraction",
                    "float",
                    _K.model_angle_hypersonic_fraction,
                    "",
                    "the flow-angle error 1-sigma at and above model_angle_mach_high, a fraction of the low-Mach one",
                ),
                Key(
                    "model_angle_mach_low",
                    "float",
                    _K.model_angle_mach_low,
                    "",
                    "Mach at and below which the flow-angle error has its full 1-sigma",
                ),
                Key(
                    "model_angle_mach_high",
                    "float",
                    _K.model_angle_mach_high,
                    "",
                    "Mach at and above which it has the hypersonic fraction (linear in Mach between)",
                ),
                Key(
                    "attitude_velocity_coupling",
                    "bool",
                    _K.attitude_velocity_coupling,
                    meaning="attitude error tilts the integrated specific force (velocity error grows with it)",
                ),
            ),
        ),
        Table(
            "montecarlo",
            "the trade study (paper Sect. IV.B.1, Fig. 6)",
            (
                Key("runs", "int", _M.runs, "", "runs per error level"),
                Key("levels_pct", "list", [100 * x for x in _M.levels], "%", "error levels, of reading"),
                Key("fixed_r", "float", _M.fixed_r, "", "fixed pressure ratio"),
                Key("stride", "int", _M.stride, "", "use every stride-th pressure sample"),
            ),
        ),
    ),
)

_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def config_for(scenario: Scenario) -> MeadsConfig:
    """:meth:`MeadsConfig.from_scenario`, built once per scenario object."""
    cfg = _CACHE.get(scenario)
    if cfg is None:
        cfg = _CACHE[scenario] = MeadsConfig.from_scenario(scenario)
    return cfg
