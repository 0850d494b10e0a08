"""MEADS sensors of the truth simulator: the pressure error chain (paper Sect. IV.A) and the IMU.

Every error source is a switch of :class:`PressureSensorSpec` (scenario ``[sensors.pressure]``),
applied in this order to the true surface pressure (:func:`measure_pressures`):

1. **port location** (IV.A.1): each orifice displaced by N(0, σ) along the surface meridian (at
   constant clock) and N(0, σ) tangentially (at constant cone), σ = 0.05 in / 3 — the truth
   pressure is evaluated at the displaced point, the estimator keeps the nominal one;
2. **time tag** (IV.A.3): each port's samples are of the truth shifted by U(±25 µs);
3. **pneumatic lag** (IV.A.4, Eq. 40–42): the 2nd-order tube of each port delays the pressure by
   its low-frequency group delay ``2ζ/ω_n`` evaluated at the flight condition (gas in the tube at
   the mean of the wall and transducer temperatures) — exact for the slowly varying entry
   pressures, whose content is far below ω_n ≈ 600 rad/s;
4. **thermal transpiration** (IV.A.5, Eq. 43–47): Knudsen (or Potter) thermomolecular pressure
   ratio between the hot port (wall temperature from a Sutton–Graves heating history) and the
   cold transducer;
5. **calibration** (IV.A.6, Eq. 48–51): after the in-flight zero, a residual bias N(0, σ_b) per
   transducer (Eq. 51's first term) and a nonlinearity a2 V² (σ of a2 at full scale); the
   **transducer scale factor** (sensitivity a1 error) N(0, σ_s) per transducer;
6. optional **multiplicative error** of ``multiplicative_sigma`` of reading per sample (the
   paper's trade-study error model, Sect. IV.B.1);
7. **noise, quantisation and saturation** (IV.A.2, Eq. 38–39): uniform noise of ±N/2^n of the
   range, quantisation to 2^n counts of the range, clipping to [0, full scale];
8. an optional **failure** of one port at a time: ``stuck`` (holds its last reading),
   ``offset`` (reads ``failure_size`` × reading more) or ``drift`` (the same, ramping over 30 s).

The IMU (scenario ``[sensors.imu]``) samples the truth's specific force and body rate at its own
rate with the shared :class:`workbench.models.imu.ImuErrorModel`.  Units SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from workbench.core.atmosphere import CO2_SUTHERLAND
from workbench.core.rotation import quat_boxplus
from workbench.models.flush_airdata import FadsVehicle, second_order_tube, transpiration_ratio
from workbench.models.imu import ImuErrorModel, apply_imu_errors
from workbench.problems.meads.truth import MeadsTruth, MeadsTruthSpec, cfd_like_pressure

__all__ = [
    "PressureSensorSpec",
    "PressureMeasurements",
    "measure_pressures",
    "true_port_pressures",
    "wall_temperature",
    "NavigationErrorSpec",
    "measure_imu",
    "initial_navigation",
]

FAILURE_MODES = ("stuck", "offset", "drift")


@dataclass(frozen=True)
class PressureSensorSpec:
    """The pressure measurement chain (see the module docstring); SI, switches are booleans; the
    values (and defaults) come from the scenario's ``[sensors.pressure]`` (:data:`.config.SCHEMA`)."""

    rate_hz: float
    bits: int
    noise_counts: float
    port_location_sigma_m: float
    time_tag_max_s: float
    transducer_temperature_K: float
    wall_temperature_peak_K: float
    scale_sigma: float
    nonlinearity_sigma: float
    residual_bias_sigma_pa: float
    multiplicative_sigma: float
    location: bool
    time_tag: bool
    lag: bool
    transpiration: str
    calibration: bool
    scale_factors: bool
    noise: bool
    quantization: bool
    failure_port: str
    failure_time_s: float
    failure_mode: str
    failure_size: float


@dataclass(frozen=True)
class PressureMeasurements:
    """Measured pressures ``p`` (n, m) [Pa] at ``t`` (n,) [s], and what the truth drew: ``p_surface``
    (n, m) the true surface pressure at the true port positions and times, ``radius``/``clock``
    (m,) the true positions, ``time_shift`` (m,) [s], ``lag_delay`` (n, m) [s], ``transpiration``
    (n, m) ratio, ``scale``, ``nonlinearity``, ``bias`` (m,), ``failed_port`` index or −1."""

    t: np.ndarray
    p: np.ndarray
    p_surface: np.ndarray
    radius: np.ndarray
    clock: np.ndarray
    time_shift: np.ndarray
    lag_delay: np.ndarray
    transpiration: np.ndarray
    scale: np.ndarray
    nonlinearity: np.ndarray
    bias: np.ndarray
    failed_port: int


def wall_temperature(truth: MeadsTruth, spec: PressureSensorSpec, t: np.ndarray) -> np.ndarray:
    """Heat-shield surface temperature [K] at times ``t``: ``T_tr + (T_peak − T_tr)(q̇/q̇_max)^¼``
    with the Sutton–Graves stagnation heating ``q̇ ∝ sqrt(ρ) V³`` of the truth."""
    V = np.linalg.norm(truth.v_air_B, axis=1)
    qdot = np.sqrt(truth.rho) * V**3
    T0 = spec.transducer_temperature_K
    return T0 + (spec.wall_temperature_peak_K - T0) * np.interp(t, truth.t, (qdot / qdot.max()) ** 0.25)


def true_port_pressures(
    truth: MeadsTruth, t: np.ndarray, radius: np.ndarray, clock: np.ndarray, vehicle: FadsVehicle, tspec: MeadsTruthSpec
) -> np.ndarray:
    """True surface pressure (n, m) [Pa] at times ``t`` (n,) (linear in the truth grid) at ports
    at ``radius`` [m], ``clock`` [rad] (m,)."""
    f = {k: np.interp(t, truth.t, getattr(truth, k)) for k in ("mach", "rho", "qbar", "p_inf", "alpha", "beta")}
    V = np.interp(t, truth.t, np.linalg.norm(truth.v_air_B, axis=1))
    return cfd_like_pressure(
        f["mach"], V, f["rho"], f["qbar"], f["p_inf"], f["alpha"], f["beta"], radius, clock, vehicle, tspec
    )


def _displace(vehicle: FadsVehicle, rng: np.random.Generator, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """True (radius, clock) of the ports after a meridian and a tangential displacement N(0, σ)."""
    r0, c0 = vehicle.radius(), vehicle.clock()
    d_long = rng.normal(0.0, sigma, r0.size)
    d_tan = rng.normal(0.0, sigma, r0.size)
    slope = np.where(
        r0 <= vehicle.tangency_radius, np.cos(vehicle.surface_cone_angle(r0)), math.sin(vehicle.half_angle)
    )
    # in the plane of the heat shield around the nominal point: radial and tangential offsets
    x = r0 * np.cos(c0) + d_long * slope * np.cos(c0) - d_tan * np.sin(c0)
    y = r0 * np.sin(c0) + d_long * slope * np.sin(c0) + d_tan * np.cos(c0)
    return np.hypot(x, y), np.mod(np.arctan2(y, x), 2 * np.pi)


def measure_pressures(
    truth: MeadsTruth, vehicle: FadsVehicle, tspec: MeadsTruthSpec, spec: PressureSensorSpec, rng: np.random.Generator
) -> PressureMeasurements:
    """Run the error chain of the module docstring: measured pressures at ``spec.rate_hz`` from
    t = 0 to heat-shield separation.  Draw order from ``rng`` (fixed, whatever is switched off):
    location, time tags, scale, nonlinearity, bias, multiplicative, noise."""
    m = len(vehicle.ports)
    fs = vehicle.transducer_full_scale
    t = np.arange(0.0, truth.t[-1] + 1e-9, 1.0 / spec.rate_hz)
    n = t.size
    r_true, c_true = _displace(vehicle, rng, spec.port_location_sigma_m)
    if not spec.location:
        r_true, c_true = vehicle.radius(), vehicle.clock()
    shift = rng.uniform(-spec.time_tag_max_s, spec.time_tag_max_s, m) * (1.0 if spec.time_tag else 0.0)
    scale = rng.normal(0.0, spec.scale_sigma, m) * (1.0 if spec.scale_factors else 0.0)
    nonlin = rng.normal(0.0, spec.nonlinearity_sigma, m) * (1.0 if spec.calibration else 0.0)
    bias = rng.normal(0.0, spec.residual_bias_sigma_pa, m) * (1.0 if spec.calibration else 0.0)
    mult = rng.standard_normal((n, m)) * spec.multiplicative_sigma
    noise = rng.uniform(-0.5, 0.5, (n, m)) * spec.noise_counts / 2.0**spec.bits * (1.0 if spec.noise else 0.0)

    p_surface = true_port_pressures(truth, t, r_true, c_true, vehicle, tspec)
    T_wall = wall_temperature(truth, spec, t)[:, None]
    T_tr = spec.transducer_temperature_K
    delay = np.zeros((n, m))
    if spec.lag:
        T_gas = 0.5 * (T_wall + T_tr)
        wn, zeta = second_order_tube(
            p_surface,
            T_gas,
            vehicle.tube_length,
            vehicle.tube_diameter,
            vehicle.transducer_volume,
            truth.gamma,
            truth.gas_constant,
            CO2_SUTHERLAND.viscosity(T_gas),
        )
        delay = 2.0 * zeta / wn
    t_eff = t[:, None] + shift[None, :] - delay
    p = np.empty((n, m))
    for i in range(m):  # per port: its own times (m = 7)
        p[:, i] = true_port_pressures(truth, t_eff[:, i], r_true[i : i + 1], c_true[i : i + 1], vehicle, tspec)[:, 0]
    ratio = np.ones((n, m))
    if spec.transpiration != "off":
        ratio = transpiration_ratio(
            p,
            T_wall,
            T_tr,
            vehicle.tube_diameter,
            truth.gas_constant,
            CO2_SUTHERLAND.viscosity,
            model=spec.transpiration,
        )
    p = p * ratio
    p = p * (1.0 + scale) + nonlin * p**2 / fs + bias
    p = p * (1.0 + mult)
    p = p + fs * noise
    if spec.quantization:
        step = fs / 2.0**spec.bits
        p = step * np.floor(p / step)
    p = np.clip(p, 0.0, fs)
    failed = -1
    if spec.failure_port:
        names = list(vehicle.port_names)
        if spec.failure_port not in names:
            raise ValueError(f"failure port {spec.failure_port!r} is not one of {names}")
        failed = names.index(spec.failure_port)
        after = t >= spec.failure_time_s
        if np.any(after):
            k0 = int(np.argmax(after))
            if spec.failure_mode == "stuck":
                p[after, failed] = p[max(k0 - 1, 0), failed]
            elif spec.failure_mode == "offset":
                p[after, failed] *= 1.0 + spec.failure_size
            elif spec.failure_mode == "drift":
                ramp = np.clip((t[after] - spec.failure_time_s) / 30.0, 0.0, 1.0)
                p[after, failed] *= 1.0 + spec.failure_size * ramp
            else:
                raise ValueError(f"failure mode {spec.failure_mode!r}: use one of {FAILURE_MODES}")
    return PressureMeasurements(t, p, p_surface, r_true, c_true, shift, delay, ratio, scale, nonlin, bias, failed)


@dataclass(frozen=True)
class NavigationErrorSpec:
    """1σ error of the initial navigation state handed to the reconstruction (per axis): position
    [m], velocity [m/s], attitude [rad] (scenario ``[sensors.navigation]``, defaults in :data:`.config.SCHEMA`)."""

    position_sigma: float
    velocity_sigma: float
    attitude_sigma: float


def measure_imu(
    truth: MeadsTruth, model: ImuErrorModel, rate_hz: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """IMU samples ``(t, f_B, w_B, drawn)`` at ``rate_hz`` from 0 to the end of the truth:
    specific force [m/s²] and rate [rad/s] in B with the errors of ``model`` (``drawn``)."""
    t = np.arange(0.0, truth.t[-1] + 1e-9, 1.0 / rate_hz)
    f = np.stack([np.interp(t, truth.t, truth.f_B[:, k]) for k in range(3)], 1)
    w = np.stack([np.interp(t, truth.t, truth.w_B[:, k]) for k in range(3)], 1)
    fm, wm, drawn = apply_imu_errors(f, w, model, rng)
    return t, fm, wm, drawn


def initial_navigation(
    truth: MeadsTruth, spec: NavigationErrorSpec, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The initial state handed to the reconstruction: ``(p_M, v_M, q_M_B, sigmas)`` = truth at
    t = 0 plus N(0, σ) errors; ``sigmas`` = [σ_p, σ_v, σ_att]."""
    dp = rng.normal(0.0, spec.position_sigma, 3)
    dv = rng.normal(0.0, spec.velocity_sigma, 3)
    dth = rng.normal(0.0, spec.attitude_sigma, 3)
    q = quat_boxplus(truth.q_M_B[0], dth)
    return (
        truth.p_M[0] + dp,
        truth.v_M[0] + dv,
        q,
        np.array([spec.position_sigma, spec.velocity_sigma, spec.attitude_sigma]),
    )
