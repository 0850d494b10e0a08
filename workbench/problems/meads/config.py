"""Flush air data (MEADS) scenario settings: the schema of a ``kind = "meads"`` scenario (every key,
its unit, default, bounds and meaning, once: :data:`SCHEMA`) and :class:`MeadsSettings`, the frozen
settings of one run built once from a validated scenario by
:meth:`~workbench.problems.meads.problem.MeadsProblem.settings` — one small dataclass per stage
(truth, sensors, least squares and winds, EKF, trade study), the telemetry files as absolute paths
and the flush-air-data vehicle read once.  Nothing below ``problem.py`` sees the scenario; a study
that varies a setting uses :func:`dataclasses.replace` on these (picklable) objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from workbench.io.scenario import RunInfo, Scenario, ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, from_table, scenario_table
from workbench.models.flush_airdata import FadsVehicle, load_fads_vehicle
from workbench.models.imu import ImuErrorModel
from workbench.problems.imu_settings import imu_error_model
from workbench.problems.meads.sensors import FAILURE_MODES, NavigationErrorSpec, PressureSensorSpec
from workbench.problems.meads.truth import MeadsTruthSpec

__all__ = [
    "SCHEMA",
    "EstimatorSettings",
    "EkfSettings",
    "ImuSettings",
    "McSettings",
    "MeadsSettings",
    "TelemetryFiles",
]


@dataclass(frozen=True)
class EstimatorSettings:
    """How the pressures are reduced (scenario ``[estimator]`` and ``[winds]``; defaults and units
    in :data:`SCHEMA`).

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
    this factor before the run is refused; ``min_qbar_pa``: the objectives' threshold [Pa];
    ``wind_det_min``: |det| of the normalised wind Jacobian below which the wind solution is
    declared singular (near-zero flight-path angle) and not published; ``wind_sigma_max`` [m/s]: nor is a
    wind whose 1σ (Eq. 16) exceeds it.
    """

    model: str
    solution: str
    switch_mach: float
    fixed_r: float
    gamma: float
    model_error_frac: float
    iterations: int
    lag_inversion: bool
    failed_port_nsigma: float
    failed_port_samples: int
    plausibility_factor: float
    min_qbar_pa: float
    wind_det_min: float
    wind_sigma_max: float


@dataclass(frozen=True)
class EkfSettings:
    """The filter's tuning (scenario ``[ekf]``; defaults, units and bounds in :data:`SCHEMA`).

    ``enabled``; ``passes`` 1 or 2; ``iterations`` of the iterated update (Eq. 33);
    ``accel_psd`` [m²/s³] velocity random walk (accelerometer noise, bias and scale not in the
    strapdown); ``attitude_psd`` [rad²/s] attitude random walk (gyro); ``wind_sigma_mps`` /
    ``vertical_wind_sigma_mps`` prior 1σ of the horizontal / vertical wind; ``wind_var_per_km``
    [(m/s)² per km of altitude travelled]; ``atmosphere_sigma_ln`` prior 1σ of ln p∞ and ln ρ∞ about
    the engineering atmosphere; ``temperature_sigma_ln`` prior 1σ of ln T∞ = ln p∞ − ln ρ∞ − ln R
    about the engineering atmosphere's (the two priors correlated so that their difference has it;
    0: independent — early in entry, where q∞ is a fraction of a pascal, the pressures then leave the
    temperature free and a filter can lose ρ∞ for good); ``atmosphere_var_per_km`` [per km] random walk of ln p∞, ln ρ∞;
    ``scale_factor_sigma`` prior 1σ of each transducer scale factor (of reading);
    ``model_level_sigma`` prior 1σ of the common level error of the pressure model (of reading,
    a constant state; 0: not modelled).

    The pressure model's error as coloured states (:mod:`.ekf`): ``model_error_sigma`` the
    steady-state 1σ of each port's multiplicative model error (of reading; 0: not modelled, and R
    then carries the estimator's white ``model_error_frac``); ``model_error_order`` 1 (first-order
    Gauss–Markov) or 2 (critically damped second order); ``model_error_mach_length`` [Mach] and
    ``model_error_angle_deg`` [deg of |Δα| + |Δβ|] its correlation lengths in flight condition
    (:func:`.ekf.flight_distance`); ``model_mach_sigma`` 1σ of the model's relative Mach error;
    ``bias_sigma_pa`` [Pa] prior 1σ of each transducer's additive residual bias (Eq. 51; 0: not
    modelled); ``noise_counts`` the channel's white noise N in counts (Eq. 38): with the model
    error a state, R is only that and the quantisation, σ² = (N² + 1)/12 counts².
    ``model_angle_sigma_deg`` [deg] 1σ of the model's flow-angle errors at and below Mach
    ``model_angle_mach_low``, ``model_angle_hypersonic_fraction`` of it at and above
    ``model_angle_mach_high``, linear in Mach between (:func:`.ekf.angle_sigma`);
    ``attitude_velocity_coupling``: the attitude error tilts the specific force the strapdown
    integrated; ``vertical_wind_length_km`` [km] the vertical wind as a first-order Gauss–Markov over
    the altitude travelled (0: a random walk like the horizontal wind).  What each default changed
    is measured in ``docs/tuning/meads.md``.
    """

    enabled: bool
    passes: int
    iterations: int
    accel_psd: float
    attitude_psd: float
    wind_sigma_mps: float
    vertical_wind_sigma_mps: float
    vertical_wind_length_km: float
    wind_var_per_km: float
    atmosphere_sigma_ln: float
    temperature_sigma_ln: float
    atmosphere_var_per_km: float
    scale_factor_sigma: float
    model_level_sigma: float
    model_error_sigma: float
    model_error_mach_length: float
    model_error_angle_deg: float
    model_error_order: int
    noise_counts: float
    bias_sigma_pa: float
    model_mach_sigma: float
    model_angle_sigma_deg: float
    model_angle_hypersonic_fraction: float
    model_angle_mach_low: float
    model_angle_mach_high: float
    attitude_velocity_coupling: bool


@dataclass(frozen=True)
class McSettings:
    """The trade study (``[montecarlo]``): ``runs`` per error level, ``levels`` (fractions of
    reading), ``fixed_r`` the fixed pressure ratio, ``stride`` (every stride-th pressure sample)."""

    runs: int
    levels: tuple[float, ...]
    fixed_r: float
    stride: int


@dataclass(frozen=True)
class ImuSettings:
    """The synthetic IMU (``[sensors.imu]``): its error ``model`` (SI: m/s², rad/s) and sample
    ``rate_hz`` [Hz]."""

    model: ImuErrorModel
    rate_hz: float


@dataclass(frozen=True)
class TelemetryFiles:
    """The user's ``[telemetry]`` files, absolute paths (None: not given; a synthetic run writes its
    own): ``pressures`` CSV, ``imu`` CSV, ``initial_state`` TOML."""

    pressures: Path | None
    imu: Path | None
    initial_state: Path | None


@dataclass(frozen=True)
class MeadsSettings:
    """The frozen settings of one MEADS run: ``run`` (name, file, seed …), the ``vehicle`` read once
    from ``vehicle_file`` (absolute path), the ``telemetry`` files, the truth simulator's ``truth``
    spec, the sensors (``pressure``, ``imu``, ``navigation``), the least squares and winds
    (``estimator``), the filter (``ekf``) and the trade study (``mc``)."""

    run: RunInfo
    vehicle_file: Path
    vehicle: FadsVehicle
    telemetry: TelemetryFiles
    truth: MeadsTruthSpec
    pressure: PressureSensorSpec
    imu: ImuSettings
    navigation: NavigationErrorSpec
    estimator: EstimatorSettings
    ekf: EkfSettings
    mc: McSettings

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> MeadsSettings:
        """Validate ``scenario`` against :data:`SCHEMA`, check what the bounds cannot express
        (cross-field rules), read the vehicle file and build the settings."""
        if scenario.kind != "meads":
            raise ScenarioError(scenario.path, "scenario.kind", f"{scenario.kind!r} is not a meads scenario")
        v = SCHEMA.validate(scenario.data, scenario.path)
        run = RunInfo.from_scenario(scenario)
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
        truth = from_table(
            MeadsTruthSpec, tr, bank_profile_deg=tuple((float(a), float(b)) for a, b in tr["bank_profile_deg"])
        )
        pressure = from_table(PressureSensorSpec, sp, time_tag_max_s=sp["time_tag_max_us"] * 1e-6)
        imu = imu_error_model(si, gyro_full_scale=(math.radians(400.0),) * 3)
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
        if not ek["temperature_sigma_ln"] < 2.0 * ek["atmosphere_sigma_ln"]:
            raise ScenarioError(
                scenario.path,
                "ekf.temperature_sigma_ln",
                f"{ek['temperature_sigma_ln']}: must be below 2 × atmosphere_sigma_ln ({ek['atmosphere_sigma_ln']}): "
                "ln T = ln p − ln rho cannot vary more than its two terms allow",
            )
        if not ek["model_angle_mach_low"] < ek["model_angle_mach_high"]:
            raise ScenarioError(
                scenario.path,
                "ekf.model_angle_mach_high",
                f"{ek['model_angle_mach_high']}: must be above model_angle_mach_low ({ek['model_angle_mach_low']})",
            )
        te = v["telemetry"]
        files = TelemetryFiles(
            **{
                k: None if te[k] is None else run.resolve(te[k]).resolve()
                for k in ("pressures", "imu", "initial_state")
            }
        )
        vehicle_file = run.resolve(v["vehicle"]["file"]).resolve()
        if not vehicle_file.exists():
            raise ScenarioError(scenario.path, "vehicle.file", f"file not found: {vehicle_file}")
        return cls(
            run=run,
            vehicle_file=vehicle_file,
            vehicle=load_fads_vehicle(vehicle_file),
            telemetry=files,
            truth=truth,
            pressure=pressure,
            imu=ImuSettings(imu, si["rate_hz"]),
            navigation=nav,
            estimator=est,
            ekf=EkfSettings(**ek),
            mc=McSettings(mc["runs"], tuple(float(x) / 100.0 for x in mc["levels_pct"]), mc["fixed_r"], mc["stride"]),
        )


SCHEMA = Schema(
    "meads",
    "flush air data (MEADS): forebody pressures + IMU -> q, Mach, alpha, beta, density, winds",
    (
        scenario_table(
            "meads",
            epoch="UTC of t = 0 (the entry interface), metadata only",
            name="names the run and its output files",
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
                Key("entry_altitude_km", "float", 125.0, "km", "entry interface altitude"),
                Key("entry_speed_kmps", "float", 5.845, "km/s", "inertial speed at entry"),
                Key("entry_fpa_deg", "float", -15.5, "deg", "inertial flight-path angle at entry"),
                Key("entry_azimuth_deg", "float", 80.0, "deg", "heading from north"),
                Key("entry_latitude_deg", "float", -10.0, "deg", "latitude of the entry point"),
                Key("mass_kg", "float", 3300.0, "kg", "entry mass"),
                Key(
                    "bank_profile_deg",
                    "list",
                    [
                        [0.0, 0.0],
                        [50.0, 0.0],
                        [58.0, 65.0],
                        [85.0, 65.0],
                        [92.0, 0.0],
                        [140.0, 0.0],
                        [148.0, -60.0],
                        [200.0, -60.0],
                    ],
                    "s, deg",
                    "(t, bank) nodes",
                ),
                Key("alpha_hyper_deg", "float", 16.0, "deg", "trim alpha above Mach 25"),
                Key("alpha_low_deg", "float", 20.0, "deg", "trim alpha below Mach 5"),
                Key("alpha_osc_deg", "float", 1.0, "deg", "alpha oscillation amplitude"),
                Key("beta_osc_deg", "float", 0.8, "deg", "sideslip oscillation amplitude"),
                Key("chute_mach", "float", 1.75, "", "parachute deployment Mach"),
                Key("hss_delay_s", "float", 24.0, "s", "heat-shield separation after deployment"),
                Key("surface_pressure_pa", "float", 640.0, "Pa", "true pressure at 0 km"),
                Key("gamma", "float", 1.33, "", "true ratio of specific heats"),
                Key("wave_amplitude_K", "float", 4.0, "K", "gravity-wave amplitude at 0 km"),
                Key("background_wind_mps", "float", 12.0, "m/s", "background wind speed"),
                Key("stagnation_shift", "float", 0.03, "", "true stagnation-point shift (of alpha_T)"),
                Key("shoulder", "float", 0.10, "", "true shoulder expansion coefficient"),
            ),
        ),
        Table(
            "sensors.pressure",
            "the pressure error chain (paper Sect. IV.A); each source switchable",
            (
                Key("rate_hz", "float", 8.0, "Hz", "sample rate"),
                Key("bits", "int", 14, "", "effective bits n (Eq. 38-39)"),
                Key("noise_counts", "float", 2.0, "", "noise counts N (Eq. 38)", ge=0.0),
                Key("port_location_sigma_m", "float", 0.05 * 0.0254 / 3.0, "m", "1-sigma port position", ge=0.0),
                Key("time_tag_max_us", "float", 25.0, "us", "uniform time-tag error bound"),
                Key("transducer_temperature_K", "float", 300.0, "K", "transducer temperature"),
                Key("wall_temperature_peak_K", "float", 1500.0, "K", "peak surface temperature"),
                Key("scale_sigma", "float", 0.003, "", "transducer scale factor 1-sigma", ge=0.0),
                Key("nonlinearity_sigma", "float", 0.001, "", "a2 nonlinearity at full scale", ge=0.0),
                Key("residual_bias_sigma_pa", "float", 3.5, "Pa", "bias after in-flight zero", ge=0.0),
                Key("multiplicative_sigma", "float", 0.0, "", "per-sample error, of reading", ge=0.0),
                Key("location", "bool", True, meaning="port location errors on"),
                Key("time_tag", "bool", True, meaning="time-tag errors on"),
                Key("lag", "bool", True, meaning="pneumatic lag on"),
                Key(
                    "transpiration",
                    "str",
                    "knudsen",
                    meaning="thermal transpiration model",
                    choices=("knudsen", "potter", "off"),
                ),
                Key("calibration", "bool", True, meaning="residual bias + nonlinearity on"),
                Key("scale_factors", "bool", True, meaning="transducer scale factors on"),
                Key("noise", "bool", True, meaning="noise on"),
                Key("quantization", "bool", True, meaning="quantisation on"),
                Key("failure_port", "str", "", meaning="port that fails (empty: none)"),
                Key("failure_time_s", "float", 150.0, "s", "when it fails"),
                Key("failure_mode", "str", "stuck", meaning="how it fails", choices=FAILURE_MODES),
                Key("failure_size", "float", 0.1, "", "offset/drift size, of reading"),
            ),
        ),
        Table(
            "sensors.imu",
            "the synthetic IMU (body axes)",
            (
                Key("rate_hz", "float", 20.0, "Hz", "sample rate"),
                Key("accel_noise_mps2", "float", 3e-3, "m/s^2", "white noise per sample", ge=0.0),
                Key("gyro_noise_dps", "float", 0.005, "deg/s", "white noise per sample", ge=0.0),
                Key("accel_bias_mps2", "float", 1e-3, "m/s^2", "bias 1-sigma", ge=0.0),
                Key("gyro_bias_dps", "float", 1.0 / 3600.0, "deg/s", "bias 1-sigma", ge=0.0),
                Key("accel_scale", "float", 1e-4, "", "scale factor 1-sigma", ge=0.0),
                Key("gyro_scale", "float", 1e-4, "", "scale factor 1-sigma", ge=0.0),
            ),
        ),
        Table(
            "sensors.navigation",
            "error of the initial state written for the reconstruction",
            (
                Key("position_sigma_m", "float", 200.0, "m", "1-sigma per axis", ge=0.0),
                Key("velocity_sigma_mps", "float", 0.2, "m/s", "1-sigma per axis", ge=0.0),
                Key("attitude_sigma_deg", "float", 0.05, "deg", "1-sigma per axis", ge=0.0),
            ),
        ),
        Table(
            "estimator",
            "the least-squares reduction (paper Sect. III.A)",
            (
                Key("model", "str", "newtonian", meaning="pressure model", choices=("newtonian", "table")),
                Key(
                    "solution",
                    "str",
                    "auto",
                    meaning="solution set",
                    choices=("auto", "mach", "static", "fixed_r"),
                ),
                Key("switch_mach", "float", 3.0, "", "auto: fixed R above this inertial Mach"),
                Key("fixed_r", "float", 0.0, "", "fixed pressure ratio (0: scheduled from inertial Mach)"),
                Key("gamma", "float", 1.335, "", "estimator's ratio of specific heats"),
                Key("model_error_frac", "float", 0.01, "", "model-form 1-sigma, of reading", ge=0.0),
                Key("iterations", "int", 12, "", "Gauss-Newton iterations"),
                Key("lag_inversion", "bool", True, meaning="invert the pneumatic lag first"),
                Key("failed_port_nsigma", "float", 6.0, "", "residual threshold, sigmas", gt=0.0),
                Key("failed_port_samples", "int", 4, "", "consecutive samples to fail a port"),
                Key("plausibility_factor", "float", 3.0, "", "pressure vs drag q-bar"),
                Key("min_qbar_pa", "float", 850.0, "Pa", "objectives apply above this q-bar"),
            ),
        ),
        Table(
            "winds",
            "wind solution (paper Eq. 11-17)",
            (
                Key("singular_det_min", "float", 0.1, "", "normalised |det Gamma| below: singular"),
                Key("max_sigma_mps", "float", 50.0, "m/s", "winds with a larger 1-sigma: not published", gt=0.0),
            ),
        ),
        Table(
            "ekf",
            "the tightly-coupled EKF (paper Sect. III.B, Eq. 19-35), multi-pass, RTS smoothed",
            (
                Key("enabled", "bool", True, meaning="run the filter after the least squares"),
                Key("passes", "int", 2, "", "1: scale factors estimated; 2: then reprocessed corrected", ge=1, le=2),
                Key("iterations", "int", 4, "", "iterated measurement update (Eq. 33), at most", ge=1),
                Key("accel_psd", "float", 2e-4, "m^2/s^3", "velocity random walk beyond the strapdown", ge=0.0),
                Key("attitude_psd", "float", 4e-9, "rad^2/s", "attitude random walk beyond the strapdown", ge=0.0),
                Key("wind_sigma_mps", "float", 30.0, "m/s", "prior 1-sigma of the horizontal wind", gt=0.0),
                Key("vertical_wind_sigma_mps", "float", 3.0, "m/s", "prior 1-sigma, vertical", gt=0.0),
                Key(
                    "vertical_wind_length_km",
                    "float",
                    5.0,
                    "km",
                    "vertical wind: Gauss-Markov correlation length in altitude (0: a random walk like the horizontal)",
                    ge=0.0,
                ),
                Key("wind_var_per_km", "float", 90.0, "(m/s)^2/km", "wind random walk per km descended", ge=0.0),
                Key("atmosphere_sigma_ln", "float", 1.0, "", "prior 1-sigma of ln p and ln rho", gt=0.0),
                Key(
                    "temperature_sigma_ln",
                    "float",
                    0.3,
                    "",
                    "prior 1-sigma of ln T = ln p - ln rho about the engineering atmosphere (0: independent)",
                    ge=0.0,
                ),
                Key("atmosphere_var_per_km", "float", 1e-4, "1/km", "ln p, ln rho random walk", ge=0.0),
                Key("scale_factor_sigma", "float", 0.01, "", "prior 1-sigma of each scale factor", gt=0.0),
                Key("model_level_sigma", "float", 0.01, "", "prior 1-sigma, pressure model level", ge=0.0),
                Key(
                    "model_error_sigma",
                    "float",
                    0.01,
                    "",
                    "model error per port, steady 1-sigma, of reading (0: off, R carries model_error_frac)",
                    ge=0.0,
                ),
                Key("model_error_mach_length", "float", 3.0, "", "model error correlation length in Mach", gt=0.0),
                Key(
                    "model_error_angle_deg",
                    "float",
                    2.0,
                    "deg",
                    "model error correlation length in |d alpha| + |d beta|",
                    gt=0.0,
                ),
                Key("model_error_order", "int", 1, "", "model error Gauss-Markov order: 1, or 2 (smooth)", ge=1, le=2),
                Key(
                    "noise_counts",
                    "float",
                    2.0,
                    "",
                    "white noise counts N of the channel (R when the model error is a state)",
                    gt=0.0,
                ),
                Key(
                    "bias_sigma_pa",
                    "float",
                    3.5,
                    "Pa",
                    "prior 1-sigma of each transducer bias (0: not modelled)",
                    ge=0.0,
                ),
                Key(
                    "model_mach_sigma", "float", 0.1, "", "model Mach error 1-sigma, relative (0: not modelled)", ge=0.0
                ),
                Key(
                    "model_angle_sigma_deg",
                    "float",
                    1.0,
                    "deg",
                    "model flow-angle error 1-sigma, alpha and beta each, at low Mach (0: not modelled)",
                    ge=0.0,
                ),
                Key(
                    "model_angle_hypersonic_fraction",
                    "float",
                    0.1,
                    "",
                    "the flow-angle error 1-sigma at and above model_angle_mach_high, a fraction of the low-Mach one",
                    ge=0.0,
                ),
                Key(
                    "model_angle_mach_low",
                    "float",
                    5.0,
                    "",
                    "Mach at and below which the flow-angle error has its full 1-sigma",
                    ge=0.0,
                ),
                Key(
                    "model_angle_mach_high",
                    "float",
                    10.0,
                    "",
                    "Mach at and above which it has the hypersonic fraction (linear in Mach between)",
                    ge=0.0,
                ),
                Key(
                    "attitude_velocity_coupling",
                    "bool",
                    True,
                    meaning="attitude error tilts the integrated specific force (velocity error grows with it)",
                ),
            ),
        ),
        Table(
            "montecarlo",
            "the trade study (paper Sect. IV.B.1, Fig. 6)",
            (
                Key("runs", "int", 3000, "", "runs per error level"),
                Key("levels_pct", "list", [0.5, 1.0, 2.5, 5.0], "%", "error levels, of reading"),
                Key("fixed_r", "float", 0.001, "", "fixed pressure ratio"),
                Key("stride", "int", 8, "", "use every stride-th pressure sample"),
            ),
        ),
    ),
)
