"""Truth simulator of a Schiaparelli-like entry and parachute descent (synthetic scenarios only).

The *truth*, not the estimator's model: a 6-DOF rigid capsule through a true atmosphere of its own
(climate temperature profile, gas constants, gravity waves), the vehicle's aerodynamic database
times planted Mach-dependent deviations (10 % 1σ, AMELIA Table 3) the estimator does not know, over
a terrain with relief; after parachute deployment a two-body system — the module on an elastic
riser to the canopy, a point mass with its own drag, inflation and breathing, and an asymmetric
inflation side force — so the pendulum, the snatch and the X-rate spike past 187.5 °/s (AMELIA
Sect. 4) follow from the forces, nothing scripted on the module's motion.

Frames: M = MMED inertial (Mars rotating about its +Z, the atmosphere co-rotating; winds north/east
in local NED, blowing *towards* the stated direction); gravity point mass + J2; altitude above the
MOLA radius; body G with +Z towards the back shell, ``q_M_G`` body -> inertial. Time from EIP,
starting at −15 s from AMELIA Table 2's state; events PDD (Mach or time), FSR, BSR (end). Fixed-step
RK4 (``dt_entry``, ``dt_chute`` under the stiff riser) of a scalar model (19 states: a numpy call
costs more than the arithmetic), compiled by numba in :mod:`.truth_fast`; the Python model here is
the reference path (``simulate_entry(..., fast=False)``), the same operations in the same order.
The parachute's engineering choices are documented in :class:`EntryTruthSpec`; the full model
description: docs/tuning/entry.md, "truth.py".
References: Aboudan et al., Space Sci. Rev. 2018, Sects. 3–4, 9, Table 2, Figs. 2–4.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import PchipInterpolator

from workbench.core.atmosphere import (
    CO2_SUTHERLAND,
    R_UNIVERSAL,
    TabulatedAtmosphere,
    hydrostatic_table,
    layered_wind_NE,
)
from workbench.core.bodies import MARS
from workbench.core.frames import julian_date_from_utc, north_east_xyz
from workbench.core.gravity import j2_factor
from workbench.core.rotation import dcm_components, quat_multiply, quat_normalize, quat_to_dcm
from workbench.io import progress
from workbench.models.aerodynamics import EntryVehicle
from workbench.problems.entry import truth_fast as tf
from workbench.problems.entry.site import R_GROUND, draw_terrain_modes

__all__ = [
    "EntryTruthSpec",
    "EntryTruth",
    "MARS_MOLAR_MASS",
    "AERO_DEVIATION_MACH",
    "PARACHUTE_DEVIATION_MACH",
    "AERO_SIGMA_COMMON",
    "AERO_SIGMA_SHAPE",
    "DispersionSigmas",
    "disperse_truth_spec",
    "coefficient_deviation",
    "draw_coefficient_deviation",
    "true_atmosphere",
    "wind_profile_truth",
    "simulate_entry",
]

MARS_MOLAR_MASS = 0.04341
"""Mean molar mass of the Martian atmosphere below 104 km [kg/mol] (AMELIA Sect. 9)."""


AERO_DEVIATION_MACH: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
"""Mach nodes of the planted axial-coefficient deviation (smooth in log Mach between them, held
constant outside)."""
PARACHUTE_DEVIATION_MACH: tuple[float, ...] = (0.3, 0.8, 1.4, 2.2)
"""Mach nodes of the planted parachute drag-coefficient deviation."""

AERO_SIGMA_COMMON = 0.08
"""1σ of the Mach-independent part of a drawn relative coefficient deviation [-]."""
AERO_SIGMA_SHAPE = 0.06
"""1σ of the Mach-dependent part (Gaussian process in ln Mach, correlation length 1) [-]; with
:data:`AERO_SIGMA_COMMON` the total 1σ is 10 %, the drag-coefficient uncertainty of AMELIA Table 3."""

# The shipped truth's planted values: one draw of :func:`draw_coefficient_deviation` (seed
# 20161019), rounded.  Drag 4 % low subsonic, 5-7 % high in the hypersonic deceleration peak.
_CA_DEVIATION_DEFAULT = (-0.043, -0.017, -0.020, -0.026, 0.006, 0.051, 0.072)
_CHUTE_DEVIATION_DEFAULT = (0.059, 0.002, -0.041, -0.037)

# Temperature of the true atmosphere [h_km AMR, T_K] (smooth monotone cubic between nodes): a
# dusty-season (Ls ≈ 245°) afternoon profile of the Meridiani region built from published Mars
# climate numbers, not from the estimator's default model: near-surface air ≈ 225 K (Viking /
# Pathfinder / MER surface meteorology, 200-250 K by day), a lapse rate ≈ 2 K/km in the lowest
# 10 km (below the 4.5 K/km dry adiabat: dust heating), ≈ 1 K/km through a dust-warmed 10-60 km,
# a mesosphere cooling slowly to ≈ 128 K near 100 km and a thermosphere warming above 110 km
# (pressure ≈ 7e-3 Pa at 100 km, AMELIA Sect. 9's 104 km reference value) (Mars Pathfinder
# ASI/MET entry profile, Magalhães et al., JGR 104, 1999; Mars Climate Database climatology,
# Millour et al. 2015).  The estimator's engineering model is 242 K at the surface, 2.2 K/km
# above 7 km and isothermal (139 K) above 50 km: the truth is ~20 K colder near the ground and up
# to ~27 K warmer at 40-60 km, so the scale height differs by up to ~20 %.
_TEMPERATURE_PROFILE_DEFAULT: tuple[tuple[float, float], ...] = (
    (-5.0, 234.0),
    (0.0, 224.0),
    (5.0, 214.0),
    (10.0, 205.0),
    (20.0, 195.0),
    (30.0, 186.0),
    (40.0, 176.0),
    (50.0, 166.0),
    (60.0, 156.0),
    (70.0, 147.0),
    (80.0, 139.0),
    (90.0, 132.0),
    (100.0, 128.0),
    (110.0, 132.0),
    (125.0, 150.0),
    (140.0, 170.0),
)

# Terrain relief of the shipped truth: :func:`workbench.problems.entry.site.draw_terrain_modes`
# with seed 2016, 12 modes, RMS 100 m, wavelengths 2-12 km (peak-to-peak a few hundred m).
_TERRAIN_MODES_DEFAULT: tuple[tuple[float, float, float, float, float], ...] = (
    (40.825, 11.3149, 16.4726, -106.2415, 18.302),
    (40.825, 3.6758, -27.055, 73.0491, 303.669),
    (40.825, 3.1621, 55.6913, -37.6515, 216.196),
    (40.825, 4.1206, -6.8222, -127.0592, 358.279),
    (40.825, 6.9982, -69.3257, -27.4544, 308.629),
    (40.825, 10.9359, -18.2354, -160.3603, 167.356),
    (40.825, 10.3157, -4.9217, -15.205, 63.267),
    (40.825, 4.956, -68.8924, 104.7415, 0.643),
    (40.825, 3.7852, -70.4766, 15.1472, 354.813),
    (40.825, 3.4299, -43.6281, -103.1642, 359.455),
    (40.825, 4.5793, -17.1632, -34.1432, 56.591),
    (40.825, 2.1877, -39.6446, 171.2001, 259.469),
)


def _wind_layers_default() -> tuple[tuple[float, float, float, float, float], ...]:
    # (bottom_km, top_km, speed_mps, towards_azimuth_deg (from north, clockwise), edge_km)
    return ((5.0, 6.0, 18.0, 250.0, 0.25), (3.2, 4.4, 20.0, 240.0, 0.3))


@dataclass(frozen=True)
class EntryTruthSpec:
    """Settings of the truth simulation (SI unless a name carries a unit); built from ``[truth]``.

    Initial state (AMELIA Table 2, nominal, at ``t0`` = −15 s from EIP): ``p0_km`` [km, M],
    ``v0_kmps`` [km/s, M], ``q0_jpl`` the JPL quaternion "MMED to GNC" (numerically ``q_M_G``;
    with our conventions −Z_G is 1.85° from the air-relative velocity, so it is used as is),
    rotated by the optional extra tilt ``aoa_offset_deg`` (about the body axis at azimuth
    ``aoa_offset_azimuth_deg`` from +X_G towards +Y_G); initial body rate ``w0_dps`` [°/s]
    (spin 16 °/s about +Z_G, AMELIA Fig. 3).  The truth departs from the nominal like the flown
    state did (AMELIA Sect. 3: separation over-performance, slightly steeper flight path): the
    Table 2 velocity is rotated in its vertical plane by ``fpa_offset_deg`` (< 0 steeper) and
    lengthened by ``speed_offset_mps``.  ``roll_moment_coeff``: constant roll-torque
    coefficient (``M_z = Cl q S L``) standing for asymmetric ablation; it slows the spin from
    16 to ~12 °/s over the entry as AMELIA observed (engineering value).

    ``initial_position_offset_km`` (3,) [km, M] moves the initial position off Table 2's.

    Planted aerodynamic deviations (the estimator keeps the nominal tables of the vehicle
    asset): the truth's axial coefficient is ``CA_table × (1 + δ_CA(M))`` with ``δ_CA`` given by
    ``ca_deviation`` at the Mach nodes ``aero_deviation_mach`` (:func:`coefficient_deviation`);
    ``CN × (1 + cn_deviation)``, ``Cm × (1 + cm_deviation)`` (both configurations); the parachute
    ``CD × (1 + δ_P(M))`` from ``parachute_cd_deviation`` at ``parachute_deviation_mach``.  The
    shipped values are one draw of :func:`draw_coefficient_deviation` (10 % 1σ, AMELIA Table 3).

    Atmosphere (see :func:`true_atmosphere`): pressure ``surface_pressure_pa`` at 0 km AMR,
    temperature from the climate profile ``temperature_profile_km_K`` ([h_km, T_K] nodes) +
    ``temperature_waves`` (each ``(amplitude_K, wavelength_km, phase_deg)``, growing with
    altitude with ``wave_growth_scale_km`` up to ``wave_growth_cap``×) + a Gaussian warm layer
    ``inversion_*``; the truth's own ``molar_mass_g_per_mol`` and ``gamma``.  ``h_top_km`` top of
    the table.

    Terrain (see :class:`~workbench.problems.entry.site.TerrainRelief`): ``terrain_modes`` rows
    ``(amplitude_m, wavelength_km, dir_lat_deg, dir_lon_deg, phase_deg)`` of the relief about the
    terrain sphere that the radar beams see (the estimator keeps the sphere).

    Winds (see :func:`wind_profile_truth`): ``wind_layers`` of ``(bottom_km, top_km, speed_mps,
    towards_azimuth_deg, edge_km)`` (AMR altitudes, azimuth clockwise from north) on top of a
    light background ``background_wind_mps`` towards ``background_azimuth_deg`` (turning slowly
    with altitude by ``background_turn_deg_per_km``).

    Events / parachute / integration: see the module docstring.  ``aero_enabled = False`` flies
    in vacuum (a test of the gravity integration) and needs ``t_end``.  ``rng`` draws only the
    breathing phase jitter (``breathing_phase_sigma_deg``) and a ±``breathing_amp_jitter``
    relative change of the breathing amplitude.
    """

    epoch_utc: str = "2016-10-19T14:42:22.132Z"
    t0: float = -15.0
    p0_km: tuple[float, float, float] = (-1317.4056, 3254.8625, -223.9034)
    v0_kmps: tuple[float, float, float] = (-4.9636, -3.3138, 0.8326)
    q0_jpl: tuple[float, float, float, float] = (0.7250, -0.2476, 0.3916, -0.5096)
    fpa_offset_deg: float = -0.2
    speed_offset_mps: float = 15.0
    aoa_offset_deg: float = 0.0
    aoa_offset_azimuth_deg: float = 0.0
    w0_dps: tuple[float, float, float] = (0.0, 0.0, 16.0)
    roll_moment_coeff: float = -3.0e-6
    initial_position_offset_km: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # planted aerodynamic deviations (the estimator keeps the nominal tables)
    aero_deviation_mach: tuple[float, ...] = AERO_DEVIATION_MACH
    ca_deviation: tuple[float, ...] = _CA_DEVIATION_DEFAULT
    cn_deviation: float = 0.07
    cm_deviation: float = -0.05
    parachute_deviation_mach: tuple[float, ...] = PARACHUTE_DEVIATION_MACH
    parachute_cd_deviation: tuple[float, ...] = _CHUTE_DEVIATION_DEFAULT
    # atmosphere (its own climate profile, gas constants and waves; see true_atmosphere)
    surface_pressure_pa: float = 660.0
    temperature_profile_km_K: tuple[tuple[float, float], ...] = _TEMPERATURE_PROFILE_DEFAULT
    temperature_waves: tuple[tuple[float, float, float], ...] = (
        (2.5, 7.0, 40.0),
        (2.0, 12.0, 150.0),
        (1.2, 5.0, 270.0),
    )
    wave_growth_scale_km: float = 25.0
    wave_growth_cap: float = 2.0
    inversion_center_km: float = 11.5
    inversion_width_km: float = 1.0
    inversion_amplitude_K: float = 6.0
    molar_mass_g_per_mol: float = 43.34
    gamma: float = 1.33
    h_top_km: float = 140.0
    # terrain relief under the radar beams (see workbench.problems.entry.site.TerrainRelief)
    terrain_modes: tuple[tuple[float, float, float, float, float], ...] = _TERRAIN_MODES_DEFAULT
    # winds
    wind_layers: tuple[tuple[float, float, float, float, float], ...] = field(default_factory=_wind_layers_default)
    background_wind_mps: float = 2.5
    background_azimuth_deg: float = 200.0
    background_turn_deg_per_km: float = 2.0
    # events
    pdd_mach: float = 2.0
    pdd_time_s: float | None = None
    fsr_delay_s: float = 41.0
    bsr_delay_s: float = 41.0
    # parachute deployment
    deploy_tilt_deg: float = 4.0
    deploy_azimuth_deg: float = 90.0
    eject_speed_mps: float = 3.0
    inflation_time_s: float = 0.6
    breathing_amplitude: float = 0.4
    breathing_period_s: float = 0.35
    breathing_decay_s: float = 1.2
    side_force_coeff: float = 0.35
    side_force_start_s: float = 0.7
    side_force_end_s: float = 1.5
    side_force_azimuth_deg: float = -90.0
    breathing_phase_sigma_deg: float = 5.0
    breathing_amp_jitter: float = 0.05
    # integration
    dt_entry: float = 0.01
    dt_chute: float = 0.002
    dt_out: float = 0.01
    aero_enabled: bool = True
    t_end: float | None = None

    def __post_init__(self) -> None:
        if not (self.dt_out > 0 and self.dt_entry > 0 and self.dt_chute > 0):
            raise ValueError("EntryTruthSpec: time steps must be positive")
        for nm in ("dt_entry", "dt_chute"):
            r = self.dt_out / getattr(self, nm)
            if abs(r - round(r)) > 1e-9 or round(r) < 1:
                raise ValueError(f"EntryTruthSpec: dt_out must be an integer multiple of {nm}")
        if not self.aero_enabled and self.t_end is None:
            raise ValueError("EntryTruthSpec: aero_enabled = False needs t_end")


@dataclass(frozen=True, eq=False)
class EntryTruth:
    """Truth history of a simulated entry on a uniform ``dt_out`` grid (frames as in the module docstring).

    Shapes (n samples): ``t`` (n,) [s from EIP]; ``p_M``, ``v_M`` (n,3) [m, m/s, MMED, CoG];
    ``q_M_G`` (n,4); ``w_G`` (n,3) [rad/s]; ``f_G`` (n,3) [m/s², non-gravitational specific force at
    the CoG, body]; ``phase`` (n,) int (0 entry, 1 PDD..FSR, 2 FSR..BSR); ``mach``, ``knudsen``
    (diameter-based), ``alpha_total`` [rad], ``dynamic_pressure`` [Pa], ``h_amr`` [m] (n,);
    ``v_rel_M`` (n,3) air-relative velocity in M [m/s]; ``wind_NE`` (n,2) true wind north/east
    [m/s, blowing towards]; ``events`` {EIP, PDD, FSR, BSR} [s]; ``atmosphere`` the true
    atmosphere; ``epoch_utc`` of EIP and ``jd_tdb0`` its Julian date (TDB);
    ``parachute_p_M`` (n,3) canopy position [m, M] (NaN before PDD).
    Extra (not in the interface spec, for plots/diagnostics): ``riser_tension`` (n,) [N],
    ``parachute_area`` (n,) [m²], ``ca_factor`` (n,) the planted axial-coefficient factor
    ``1 + δ_CA(M)`` along the flight [-], ``chute_cd_factor`` (n,) the parachute's ``1 + δ_P(M)``
    at the canopy's Mach (1 before PDD) [-], ``terrain_modes`` (k, 5) the terrain relief
    (:class:`~workbench.problems.entry.site.TerrainRelief` rows) and ``spec`` the
    :class:`EntryTruthSpec` used.
    """

    t: np.ndarray
    p_M: np.ndarray
    v_M: np.ndarray
    q_M_G: np.ndarray
    w_G: np.ndarray
    f_G: np.ndarray
    phase: np.ndarray
    mach: np.ndarray
    knudsen: np.ndarray
    alpha_total: np.ndarray
    dynamic_pressure: np.ndarray
    h_amr: np.ndarray
    v_rel_M: np.ndarray
    wind_NE: np.ndarray
    events: dict[str, float]
    atmosphere: TabulatedAtmosphere
    epoch_utc: str
    jd_tdb0: float
    parachute_p_M: np.ndarray | None
    riser_tension: np.ndarray | None = None
    parachute_area: np.ndarray | None = None
    ca_factor: np.ndarray | None = None
    chute_cd_factor: np.ndarray | None = None
    terrain_modes: np.ndarray | None = None
    spec: EntryTruthSpec | None = None


#: The truth simulator's state rows: module position p_M, velocity v_M, attitude q_M_G, body rate
#: w_G, then the canopy position (from PDD on); its auxiliary output starts with f_G.
_TP, _TV, _TQ, _TW, _TCHUTE = slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 13), slice(13, 16)
_AUX_F = slice(0, 3)


@dataclass(frozen=True)
class DispersionSigmas:
    """1σ (or ranges) of :func:`disperse_truth_spec`'s draws; SI unless a name carries a unit.

    Initial state (AMELIA Table 3, "Reconstruction": 1°, 0.01 km/s, 2 km per axis — the
    uncertainty delivered with the Table 2 state): ``fpa_deg`` flight-path angle (10 m/s across
    5.9 km/s ≈ 0.1°), ``speed_mps``, ``attitude_deg`` (tilt of the initial attitude, random
    azimuth), ``position_km`` per axis.  Aerodynamics (AMELIA Table 3, drag coefficients 10 %):
    ``aero_common`` + ``aero_shape`` (see :func:`draw_coefficient_deviation`) for CA and the
    parachute CD, ``cn_rel``, ``cm_rel`` for CN and Cm.  Atmosphere: ``surface_pressure_rel``;
    ``temperature_K`` a smooth perturbation of the climate profile (Gaussian process in altitude,
    correlation ``temperature_corr_km``); gravity waves redrawn (amplitudes uniform in
    ``wave_amplitude_K``, wavelengths log-uniform in ``wave_wavelength_km``, phases uniform);
    the inversion centre uniform in ``inversion_center_km``, amplitude in ``inversion_amplitude_K``.
    Winds: each layer's speed × (1 + N(0, ``wind_speed_rel``)), direction + N(0,
    ``wind_direction_deg``), altitude + N(0, ``wind_altitude_km``); background speed N(spec,
    ``background_wind_mps``) (absolute value).  Terrain: new modes with RMS ``terrain_rms_m``.
    """

    fpa_deg: float = 0.1
    speed_mps: float = 10.0
    attitude_deg: float = 1.0
    position_km: float = 2.0
    aero_common: float = AERO_SIGMA_COMMON
    aero_shape: float = AERO_SIGMA_SHAPE
    cn_rel: float = 0.10
    cm_rel: float = 0.10
    surface_pressure_rel: float = 0.05
    temperature_K: float = 6.0
    temperature_corr_km: float = 15.0
    wave_amplitude_K: tuple[float, float] = (1.0, 3.5)
    wave_wavelength_km: tuple[float, float] = (5.0, 15.0)
    inversion_center_km: tuple[float, float] = (9.0, 14.0)
    inversion_amplitude_K: tuple[float, float] = (0.0, 8.0)
    wind_speed_rel: float = 0.25
    wind_direction_deg: float = 30.0
    wind_altitude_km: float = 0.5
    background_wind_mps: float = 2.0
    terrain_rms_m: float = 100.0


def disperse_truth_spec(
    spec: EntryTruthSpec, rng: np.random.Generator, sigmas: DispersionSigmas | None = None
) -> EntryTruthSpec:
    """A new, different truth for one Monte Carlo member: ``spec`` with its planted deviations redrawn.

    Draws (1σ in :class:`DispersionSigmas`, defaults in brackets), in this order from ``rng``:

    * initial state about the Table 2 nominal (AMELIA Table 3 "Reconstruction"):
      ``fpa_offset_deg`` N(0, 0.1°), ``speed_offset_mps`` N(0, 10 m/s), ``aoa_offset_deg``
      |N(0, 1°)| at a uniform azimuth, ``initial_position_offset_km`` N(0, 2 km) per axis;
    * aerodynamics: ``ca_deviation`` and ``parachute_cd_deviation`` smooth in Mach
      (:func:`draw_coefficient_deviation`: 8 % common + 6 % Mach-dependent = 10 % 1σ, AMELIA
      Table 3), ``cn_deviation`` and ``cm_deviation`` N(0, 10 %);
    * atmosphere: ``surface_pressure_pa`` × (1 + N(0, 5 %)); the climate profile's node
      temperatures + a smooth Gaussian-process perturbation (6 K, correlation 15 km); three new
      gravity waves (1-3.5 K, 5-15 km, random phase); the inversion centre U(9, 14) km and
      amplitude U(0, 8) K;
    * winds: each layer's speed ×(1 + N(0, 25 %)), direction + N(0, 30°), altitude + N(0, 0.5 km);
      background speed |N(spec, 2 m/s)|, azimuth uniform;
    * terrain: 12 new relief modes, RMS 100 m, wavelengths 2-12 km
      (:func:`~workbench.problems.entry.site.draw_terrain_modes`).

    Everything else (events, parachute deployment, integration) is kept; the canopy breathing
    jitter is drawn by :func:`simulate_entry` from its own ``rng``.  Returns a new
    :class:`EntryTruthSpec` (``spec`` is not modified).
    """
    sg = DispersionSigmas() if sigmas is None else sigmas
    n = rng.standard_normal
    kw: dict = {}
    kw["fpa_offset_deg"] = float(sg.fpa_deg * n())
    kw["speed_offset_mps"] = float(sg.speed_mps * n())
    kw["aoa_offset_deg"] = float(abs(sg.attitude_deg * n()))
    kw["aoa_offset_azimuth_deg"] = float(rng.uniform(0.0, 360.0))
    kw["initial_position_offset_km"] = tuple(float(x) for x in sg.position_km * n(3))
    kw["ca_deviation"] = draw_coefficient_deviation(rng, spec.aero_deviation_mach, sg.aero_common, sg.aero_shape)
    kw["cn_deviation"] = float(sg.cn_rel * n())
    kw["cm_deviation"] = float(sg.cm_rel * n())
    kw["parachute_cd_deviation"] = draw_coefficient_deviation(
        rng, spec.parachute_deviation_mach, sg.aero_common, sg.aero_shape
    )
    kw["surface_pressure_pa"] = float(spec.surface_pressure_pa * (1.0 + sg.surface_pressure_rel * n()))
    prof = np.asarray(spec.temperature_profile_km_K, dtype=float)
    hk = prof[:, 0]
    K = np.exp(-0.5 * ((hk[:, None] - hk[None, :]) / sg.temperature_corr_km) ** 2) + 1e-9 * np.eye(hk.size)
    dT = sg.temperature_K * (np.linalg.cholesky(K) @ n(hk.size))
    kw["temperature_profile_km_K"] = tuple(
        (float(h), round(float(T), 3)) for h, T in zip(hk, prof[:, 1] + dT, strict=True)
    )
    lo, hi = sg.wave_wavelength_km
    kw["temperature_waves"] = tuple(
        (
            round(float(rng.uniform(*sg.wave_amplitude_K)), 3),
            round(float(np.exp(rng.uniform(np.log(lo), np.log(hi)))), 3),
            round(float(rng.uniform(0.0, 360.0)), 2),
        )
        for _ in range(3)
    )
    kw["inversion_center_km"] = float(rng.uniform(*sg.inversion_center_km))
    kw["inversion_amplitude_K"] = float(rng.uniform(*sg.inversion_amplitude_K))
    layers = []
    for bottom, top, speed, az, edge in spec.wind_layers:
        dz = sg.wind_altitude_km * n()
        layers.append(
            (
                float(bottom + dz),
                float(top + dz),
                float(max(0.0, speed * (1.0 + sg.wind_speed_rel * n()))),
                float(az + sg.wind_direction_deg * n()),
                float(edge),
            )
        )
    kw["wind_layers"] = tuple(layers)
    kw["background_wind_mps"] = float(abs(spec.background_wind_mps + sg.background_wind_mps * n()))
    kw["background_azimuth_deg"] = float(rng.uniform(0.0, 360.0))
    kw["terrain_modes"] = draw_terrain_modes(rng, rms_m=sg.terrain_rms_m)
    return dataclasses.replace(spec, **kw)


# ------------------------------------------------------------------------------- true atmosphere


def _true_temperature(h: np.ndarray, spec: EntryTruthSpec) -> np.ndarray:
    """Temperature [K] of the true atmosphere at h [m] AMR: the climate profile
    ``temperature_profile_km_K`` (monotone cubic, PCHIP, between its nodes; end values held
    outside), + gravity waves, + the inversion layer."""
    nodes = np.asarray(spec.temperature_profile_km_K, dtype=float)
    hk = np.asarray(h, dtype=float) / 1e3
    T = PchipInterpolator(nodes[:, 0], nodes[:, 1], extrapolate=False)(np.clip(hk, nodes[0, 0], nodes[-1, 0]))
    # gravity waves: amplitude ∝ exp(h / 2H) (energy conservation in a thinning atmosphere) until
    # they saturate at ``wave_growth_cap`` times the surface amplitude
    grow = np.minimum(np.exp(np.maximum(hk, 0.0) / spec.wave_growth_scale_km), spec.wave_growth_cap)
    for amp, lam, ph in spec.temperature_waves:
        T = T + grow * amp * np.sin(2.0 * np.pi * hk / lam + np.radians(ph))
    T = T + spec.inversion_amplitude_K * np.exp(-0.5 * ((hk - spec.inversion_center_km) / spec.inversion_width_km) ** 2)
    return T


def true_atmosphere(spec: EntryTruthSpec, dh: float = 10.0, h_bottom: float = -5000.0) -> TabulatedAtmosphere:
    """The true atmosphere as a :class:`TabulatedAtmosphere` on nodes every ``dh`` [m] AMR.

    Temperature (:func:`_true_temperature`): the climate profile ``temperature_profile_km_K``
    (not the estimator's engineering model), gravity waves ``temperature_waves`` (amplitude
    growing as ``exp(h / wave_growth_scale_km)`` up to ``wave_growth_cap``×) and a Gaussian warm
    layer near ``inversion_center_km`` (a real inversion: dT/dh > 0 there).  Pressure: hydrostatic
    integration ``dp/dh = −ρ g``, ``ρ = p / (R T)``, ``g = GM/(R_ref + h)²`` (radial, no
    centrifugal term), from ``surface_pressure_pa`` at h = 0, with the truth's own gas constant
    ``R = R_universal / molar_mass`` (``molar_mass_g_per_mol``, default 43.34 g/mol, the NASA Mars
    fact sheet's mean molecular weight; the estimator assumes AMELIA's 43.41) and ratio of specific
    heats ``gamma`` (default 1.33, CO2 near 200 K; the estimator's 1.335); density from the ideal
    gas.  Trapezoid rule on g/T (dh = 10 m: relative error ~1e-7).  Extrapolation: clamp.
    """
    top = spec.h_top_km * 1e3
    h = np.arange(h_bottom, top + 0.5 * dh, dh)
    R = R_UNIVERSAL / (spec.molar_mass_g_per_mol * 1e-3)
    T = _true_temperature(h, spec)
    return hydrostatic_table(h, T, spec.surface_pressure_pa, R, spec.gamma, MARS, CO2_SUTHERLAND)


# ------------------------------------------------------------------------- planted deviations


def coefficient_deviation(mach, nodes_mach, deviation) -> np.ndarray:
    """Relative coefficient deviation [-] at Mach ``mach`` (any shape): the node values
    ``deviation`` at Mach ``nodes_mach`` (increasing, ≥ 2), joined by a monotone cubic (PCHIP) in
    ln Mach, held constant outside the nodes.  The truth multiplies a table coefficient by
    ``1 + deviation``."""
    x = np.log(np.asarray(nodes_mach, dtype=float))
    m = np.log(np.clip(np.asarray(mach, dtype=float), np.exp(x[0]), np.exp(x[-1])))
    return PchipInterpolator(x, np.asarray(deviation, dtype=float))(m)


def draw_coefficient_deviation(
    rng: np.random.Generator,
    nodes_mach: tuple[float, ...],
    sigma_common: float = AERO_SIGMA_COMMON,
    sigma_shape: float = AERO_SIGMA_SHAPE,
    corr_ln_mach: float = 1.0,
) -> tuple[float, ...]:
    """A smooth random relative deviation at the Mach nodes: a common offset N(0, ``sigma_common``)
    plus a Gaussian process in ln Mach (squared-exponential, correlation length ``corr_ln_mach``,
    1σ ``sigma_shape``).  Defaults: 10 % total 1σ (AMELIA Table 3).  Returns one value per node."""
    x = np.log(np.asarray(nodes_mach, dtype=float))
    K = np.exp(-0.5 * ((x[:, None] - x[None, :]) / corr_ln_mach) ** 2) + 1e-9 * np.eye(x.size)
    d = sigma_common * rng.standard_normal() + sigma_shape * (np.linalg.cholesky(K) @ rng.standard_normal(x.size))
    return tuple(round(float(v), 4) for v in d)


def _deviation_lookup(nodes_mach, deviation, n: int = 512) -> tuple[float, float, list[float]]:
    """(ln M_lo, 1/Δ, factors) of ``1 + deviation`` on a uniform ln-Mach grid for the scalar loop."""
    x = np.log(np.asarray(nodes_mach, dtype=float))
    grid = np.linspace(x[0], x[-1], n)
    fac = 1.0 + coefficient_deviation(np.exp(grid), nodes_mach, deviation)
    return float(x[0]), float((n - 1) / (x[-1] - x[0])), fac.tolist()


def _lookup(tab: tuple[float, float, list[float]], mach: float) -> float:
    x0, inv, fac = tab
    u = (math.log(mach) - x0) * inv if mach > 0.0 else 0.0
    if u <= 0.0:
        return fac[0]
    if u >= len(fac) - 1:
        return fac[-1]
    i = int(u)
    return fac[i] + (u - i) * (fac[i + 1] - fac[i])


# ------------------------------------------------------------------------------------- winds


def wind_profile_truth(h_amr, spec: EntryTruthSpec) -> np.ndarray:
    """True horizontal wind (n, 2) = [north, east] [m/s] (blowing towards) at altitudes ``h_amr`` [m].

    Sum of a light background (``background_wind_mps`` towards ``background_azimuth_deg``,
    turning by ``background_turn_deg_per_km``) and the ``wind_layers`` (smooth boxes in altitude
    with tanh edges).  Defaults: two layers blowing towards the WSW, 5–6 km at 18 m/s and
    3.2–4.4 km at 20 m/s AMR (AMELIA Sect. 10 "direction west/south-west"; its Table 5 puts the
    parachute, back shell and DM impacts W/SW of the last data point and the track hooks back
    west, i.e. the air moved towards the WSW).  ``h_amr`` any shape (...,) -> (..., 2).
    """
    return layered_wind_NE(
        h_amr, spec.background_wind_mps, spec.background_azimuth_deg, spec.background_turn_deg_per_km, spec.wind_layers
    )


# ----------------------------------------------------------------------------------- the model


class _Model:
    """Scalar force/derivative model of the module (+ canopy) for the RK4 loop."""

    def __init__(self, vehicle: EntryVehicle, spec: EntryTruthSpec, atm: TabulatedAtmosphere, rng):
        self.spec = spec
        self.veh = vehicle
        self.gm = MARS.gm
        self.j2k = j2_factor(MARS)
        self.rref = MARS.reference_radius
        self.om = MARS.rotation_rate
        self.aero_on = bool(spec.aero_enabled)
        # uniform-grid lookup tables (plain lists) for the atmosphere and winds
        h = atm.h
        self.h_lo = float(h[0])
        self.inv_dh = 1.0 / float(h[1] - h[0])
        self.n_h = h.size
        self.LR = np.log(atm.rho).tolist()
        self.A = np.asarray(atm.speed_of_sound(h)).tolist()
        self.LL = np.log(atm.mean_free_path(h)).tolist()
        w = wind_profile_truth(h, spec)
        self.WN = w[:, 0].tolist()
        self.WE = w[:, 1].tolist()
        self.atm_table = np.array([self.LR, self.A, self.LL, self.WN, self.WE], dtype=float)
        self.D = vehicle.diameter
        self.set_phase(0)
        # parachute
        ch = vehicle.parachute
        self.m_p = ch.mass
        self.A0 = ch.ref_area
        self.L0 = vehicle.riser_length
        self.k_r = vehicle.riser_stiffness
        self.c_r = vehicle.riser_damping
        self.att = [float(x) for x in vehicle.attach_point_G]
        self.t_pdd = math.inf
        self.side_M = (0.0, 0.0, 0.0)  # inertial direction of the asymmetric-inflation side force
        # planted aerodynamic deviations (lookup of 1 + δ(M) on a ln-Mach grid)
        self.ca_fac = _deviation_lookup(spec.aero_deviation_mach, spec.ca_deviation)
        self.cn_fac = 1.0 + spec.cn_deviation
        self.cm_fac = 1.0 + spec.cm_deviation
        self.cp_fac = _deviation_lookup(spec.parachute_deviation_mach, spec.parachute_cd_deviation)
        self.phi_b = math.radians(spec.breathing_phase_sigma_deg) * float(rng.standard_normal())
        self.amp_b = spec.breathing_amplitude * (1.0 + spec.breathing_amp_jitter * float(rng.uniform(-1.0, 1.0)))

    def set_phase(self, phase: int) -> None:
        veh = self.veh
        self.phase = phase
        tab = veh.aero_at(phase)
        self.tab = tab
        self.S = tab.ref_area
        self.Lref = tab.ref_length
        self.cmq = tab.cmq
        self.m = float(veh.mass_at(phase))
        I = np.asarray(veh.inertia_G, float) * (self.m / float(veh.mass_at(1)) if phase >= 2 else 1.0)
        self.I = I.tolist()
        self.Iinv = np.linalg.inv(I).tolist()

    def packed(self) -> tuple[np.ndarray, tuple]:
        """The model's current parameters as :mod:`.truth_fast` takes them: the scalar vector ``sc``
        (``truth_fast.SC_*``) and the array tuple ``arrs`` (phase's aero table and inertia, the
        atmosphere and wind tables, the deviation factors, the parachute CD); repack after
        :meth:`set_phase` or a deployment (``t_pdd``, ``side_M``)."""
        sc = np.zeros(tf.N_SC)
        sp = self.spec
        sc[tf.SC_GM], sc[tf.SC_J2K], sc[tf.SC_RREF], sc[tf.SC_OM] = self.gm, self.j2k, self.rref, self.om
        sc[tf.SC_AERO_ON] = 1.0 if self.aero_on else 0.0
        sc[tf.SC_H_LO], sc[tf.SC_INV_DH], sc[tf.SC_D] = self.h_lo, self.inv_dh, self.D
        sc[tf.SC_S], sc[tf.SC_LREF], sc[tf.SC_CMQ], sc[tf.SC_M] = self.S, self.Lref, self.cmq, self.m
        sc[tf.SC_CN_FAC], sc[tf.SC_CM_FAC], sc[tf.SC_ROLL] = self.cn_fac, self.cm_fac, sp.roll_moment_coeff
        sc[tf.SC_M_P], sc[tf.SC_A0], sc[tf.SC_L0] = self.m_p, self.A0, self.L0
        sc[tf.SC_K_R], sc[tf.SC_C_R] = self.k_r, self.c_r
        sc[tf.SC_ATT : tf.SC_ATT + 3] = self.att
        sc[tf.SC_T_PDD] = self.t_pdd
        sc[tf.SC_SIDE : tf.SC_SIDE + 3] = self.side_M
        sc[tf.SC_PHI_B], sc[tf.SC_AMP_B], sc[tf.SC_INFL] = self.phi_b, self.amp_b, sp.inflation_time_s
        sc[tf.SC_B_DECAY], sc[tf.SC_B_PERIOD] = sp.breathing_decay_s, sp.breathing_period_s
        sc[tf.SC_SF_START], sc[tf.SC_SF_END], sc[tf.SC_SF_COEFF] = (
            sp.side_force_start_s,
            sp.side_force_end_s,
            sp.side_force_coeff,
        )
        sc[tf.SC_CA_X0], sc[tf.SC_CA_INV] = self.ca_fac[0], self.ca_fac[1]
        sc[tf.SC_CP_X0], sc[tf.SC_CP_INV] = self.cp_fac[0], self.cp_fac[1]
        sc[tf.SC_TWO] = 2.0
        tab, ch = self.tab, self.veh.parachute
        # writable C-contiguous copies: one kernel signature whether the asset's read-only arrays
        # or their unpickled (writable) copies in a worker process come in
        arrs = tuple(
            np.array(a, dtype=float, order="C")
            for a in (
                self.atm_table,
                tab.mach,
                tab.log10_kn,
                tab.alpha,
                np.stack([tab.ca, tab.cn, tab.cm], axis=-1),
                self.ca_fac[2],
                self.cp_fac[2],
                ch.mach,
                ch.cd,
                self.I,
                self.Iinv,
            )
        )
        return sc, arrs

    def atm(self, h):
        """(rho, sound speed, mean free path) at altitude h [m] (clamped) and the wind (N, E)."""
        x = (h - self.h_lo) * self.inv_dh
        i = int(x)
        if i < 0:
            i, f = 0, 0.0
        elif i >= self.n_h - 1:
            i, f = self.n_h - 2, 1.0
        else:
            f = x - i
        LR, A, LL, WN, WE = self.LR, self.A, self.LL, self.WN, self.WE
        return (
            math.exp(LR[i] + f * (LR[i + 1] - LR[i])),
            A[i] + f * (A[i + 1] - A[i]),
            math.exp(LL[i] + f * (LL[i + 1] - LL[i])),
            WN[i] + f * (WN[i + 1] - WN[i]),
            WE[i] + f * (WE[i + 1] - WE[i]),
        )

    def area(self, t):
        """Canopy drag area [m²] at time t [s] (0 before PDD)."""
        tau = t - self.t_pdd
        if tau <= 0.0:
            return 0.0
        sp = self.spec
        ti = sp.inflation_time_s
        s = tau / ti
        u = 1.0 if s >= 1.0 else s * s * (3.0 - 2.0 * s)
        env = 1.0 if tau <= ti else math.exp(-(tau - ti) / sp.breathing_decay_s)
        b = self.amp_b * env * math.cos(2.0 * math.pi * (tau - ti) / sp.breathing_period_s + self.phi_b)
        return self.A0 * u * (1.0 + b)

    def side_weight(self, t):
        """Side-force fraction of the canopy drag at time t: smooth window (0 -> coeff -> 0)."""
        sp = self.spec
        tau = t - self.t_pdd
        a, b, e = sp.side_force_start_s, sp.side_force_end_s, 0.15
        if tau <= a - e or tau >= b + e or sp.side_force_coeff == 0.0:
            return 0.0
        up = 1.0 if tau >= a + e else 0.5 - 0.5 * math.cos(math.pi * (tau - a + e) / (2 * e))
        dn = 1.0 if tau <= b - e else 0.5 + 0.5 * math.cos(math.pi * (tau - b + e) / (2 * e))
        return sp.side_force_coeff * up * dn

    def gravity(self, x, y, z):
        """Point mass + J2 of Mars at (x, y, z) [m] in M -> (g_x, g_y, g_z [m/s²], |r| [m]).

        The model of :func:`workbench.core.gravity.gravity_j2_xyz`, written here with its own
        operation order: the reference trajectory (and every number derived from the synthetic
        telemetry) depends on it to the last bit — the riser dynamics amplify a 1-ulp change of g
        to ~1e-9 of the summary numbers.  It differs from the shared model by rounding only.
        """
        r2 = x * x + y * y + z * z
        r = math.sqrt(r2)
        ir3 = 1.0 / (r2 * r)
        k = self.j2k / (r2 * r2 * r)
        zz = 5.0 * z * z / r2
        a = -self.gm * ir3
        return a * x - k * x * (1.0 - zz), a * y - k * y * (1.0 - zz), a * z - k * z * (3.0 - zz), r

    def deriv(self, t, s, aux=False):
        """Time derivative of the state list s (13 entries, or 19 with the canopy)."""
        px, py, pz, vx, vy, vz, qx, qy, qz, qw, wx, wy, wz = s[:13]
        gx, gy, gz, r = self.gravity(px, py, pz)
        h = r - self.rref
        # DCM C_M_G from q_M_G
        (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = dcm_components(qx, qy, qz, qw)
        om = self.om
        FGx = FGy = FGz = 0.0  # non-gravitational force on the module, body frame [N]
        Mx = My = Mz = 0.0  # torque about the CoG, body frame [N m]
        mach = kn = alpha = qd = 0.0
        ca_f = cp_f = 1.0
        vrx = vry = vrz = 0.0
        wn = we = 0.0
        if self.aero_on:
            rho, a_snd, lam, wn, we = self.atm(h)
            nx, ny, nz, ex, ey = north_east_xyz(px, py, pz, r)  # local north/east in M (+Z the pole)
            vrx = vx + om * py - wn * nx - we * ex
            vry = vy - om * px - wn * ny - we * ey
            vrz = vz - wn * nz
            V = math.sqrt(vrx * vrx + vry * vry + vrz * vrz)
            if V > 1e-6:
                # air-relative velocity in G: C_G_M = C_M_Gᵀ
                bx = c00 * vrx + c10 * vry + c20 * vrz
                by = c01 * vrx + c11 * vry + c21 * vrz
                bz = c02 * vrx + c12 * vry + c22 * vrz
                ca_ = -bz / V
                alpha = math.acos(1.0 if ca_ > 1.0 else -1.0 if ca_ < -1.0 else ca_)
                mach = V / a_snd
                kn = lam / self.D
                CA, CN, CM = self.tab.coefficients_scalar(mach, kn, alpha)
                ca_f = _lookup(self.ca_fac, mach)
                CA, CN, CM = CA * ca_f, CN * self.cn_fac, CM * self.cm_fac
                qd = 0.5 * rho * V * V
                qS = qd * self.S
                FGz = CA * qS
                nl = math.sqrt(bx * bx + by * by)
                if nl > 1e-9 * V:
                    FGx = -CN * qS * bx / nl
                    FGy = -CN * qS * by / nl
                    # k = unit(v̂ × (−Z)) = (−by, bx, 0)/nl increases alpha; Cm < 0 restores
                    mm = CM * qS * self.Lref / nl
                    Mx = -mm * by
                    My = mm * bx
                damp = self.cmq * qS * self.Lref * self.Lref / (2.0 * V)
                Mx += damp * wx
                My += damp * wy
                Mz += self.spec.roll_moment_coeff * qS * self.Lref
        T = 0.0
        ux = uy = uz = 0.0
        chute = len(s) > 13
        if chute:
            ppx, ppy, ppz, vpx, vpy, vpz = s[13:19]
            ax_, ay_, az_ = self.att
            # attachment point position / velocity in M
            cax = c00 * ax_ + c01 * ay_ + c02 * az_
            cay = c10 * ax_ + c11 * ay_ + c12 * az_
            caz = c20 * ax_ + c21 * ay_ + c22 * az_
            # w × att (body), rotated to M
            tx, ty, tz = wy * az_ - wz * ay_, wz * ax_ - wx * az_, wx * ay_ - wy * ax_
            vax = vx + c00 * tx + c01 * ty + c02 * tz
            vay = vy + c10 * tx + c11 * ty + c12 * tz
            vaz = vz + c20 * tx + c21 * ty + c22 * tz
            dx, dy, dz = ppx - px - cax, ppy - py - cay, ppz - pz - caz
            L = math.sqrt(dx * dx + dy * dy + dz * dz)
            ux, uy, uz = dx / L, dy / L, dz / L
            stretch = L - self.L0
            if stretch > 0.0:
                sd = ux * (vpx - vax) + uy * (vpy - vay) + uz * (vpz - vaz)
                T = self.k_r * stretch + self.c_r * sd
                if T < 0.0:
                    T = 0.0
            # canopy aerodynamics
            gpx, gpy, gpz, rp = self.gravity(ppx, ppy, ppz)
            Dx = Dy = Dz = 0.0
            Ap = self.area(t)
            if self.aero_on and Ap > 0.0:
                rho_p, a_p, _, wnp, wep = self.atm(rp - self.rref)
                nxp, nyp, nzp, exp_, eyp = north_east_xyz(ppx, ppy, ppz, rp)
                wx_p = vpx + om * ppy - wnp * nxp - wep * exp_
                wy_p = vpy - om * ppx - wnp * nyp - wep * eyp
                wz_p = vpz - wnp * nzp
                Vp = math.sqrt(wx_p * wx_p + wy_p * wy_p + wz_p * wz_p)
                if Vp > 1e-6:
                    mp = Vp / a_p
                    cp_f = _lookup(self.cp_fac, mp)
                    Dk = 0.5 * rho_p * Vp * self.veh.parachute.cd_scalar(mp) * cp_f * Ap
                    Dx, Dy, Dz = -Dk * wx_p, -Dk * wy_p, -Dk * wz_p
                    ks = self.side_weight(t)
                    if ks > 0.0:  # asymmetric inflation: side force ⊥ the canopy's air velocity
                        sx, sy, sz = self.side_M
                        sv = (sx * wx_p + sy * wy_p + sz * wz_p) / (Vp * Vp)
                        sx, sy, sz = sx - sv * wx_p, sy - sv * wy_p, sz - sv * wz_p
                        sn = ks * Dk * Vp / math.sqrt(sx * sx + sy * sy + sz * sz)
                        Dx, Dy, Dz = Dx + sn * sx, Dy + sn * sy, Dz + sn * sz
            imp = 1.0 / self.m_p
            dchute = [
                vpx,
                vpy,
                vpz,
                gpx + (Dx - T * ux) * imp,
                gpy + (Dy - T * uy) * imp,
                gpz + (Dz - T * uz) * imp,
            ]
            # riser force on the module in G and its torque about the CoG
            fbx = T * (c00 * ux + c10 * uy + c20 * uz)
            fby = T * (c01 * ux + c11 * uy + c21 * uz)
            fbz = T * (c02 * ux + c12 * uy + c22 * uz)
            FGx += fbx
            FGy += fby
            FGz += fbz
            Mx += ay_ * fbz - az_ * fby
            My += az_ * fbx - ax_ * fbz
            Mz += ax_ * fby - ay_ * fbx
        im = 1.0 / self.m
        fx, fy, fz = FGx * im, FGy * im, FGz * im
        # translational
        dvx = gx + (c00 * fx + c01 * fy + c02 * fz)
        dvy = gy + (c10 * fx + c11 * fy + c12 * fz)
        dvz = gz + (c20 * fx + c21 * fy + c22 * fz)
        # Euler's equations
        I, Ii = self.I, self.Iinv
        hx = I[0][0] * wx + I[0][1] * wy + I[0][2] * wz
        hy = I[1][0] * wx + I[1][1] * wy + I[1][2] * wz
        hz = I[2][0] * wx + I[2][1] * wy + I[2][2] * wz
        rx = Mx - (wy * hz - wz * hy)
        ry = My - (wz * hx - wx * hz)
        rz = Mz - (wx * hy - wy * hx)
        dwx = Ii[0][0] * rx + Ii[0][1] * ry + Ii[0][2] * rz
        dwy = Ii[1][0] * rx + Ii[1][1] * ry + Ii[1][2] * rz
        dwz = Ii[2][0] * rx + Ii[2][1] * ry + Ii[2][2] * rz
        # q̇ = ½ q ⊗ [ω, 0]
        dq = (
            0.5 * (qw * wx + qy * wz - qz * wy),
            0.5 * (qw * wy + qz * wx - qx * wz),
            0.5 * (qw * wz + qx * wy - qy * wx),
            -0.5 * (qx * wx + qy * wy + qz * wz),
        )
        d = [vx, vy, vz, dvx, dvy, dvz, *dq, dwx, dwy, dwz]
        if chute:
            d.extend(dchute)
        if aux:
            area = self.area(t) if chute else 0.0
            return d, (fx, fy, fz, mach, kn, alpha, qd, h, vrx, vry, vrz, wn, we, T, area, ca_f, cp_f)
        return d


def _pdd_event(model: _Model, spec: EntryTruthSpec, y: list, k: int, t: float, events: dict) -> tuple[int, int, list]:
    """Deploy the parachute at output sample k, time t [s]: the events PDD/FSR/BSR on the output grid
    (the PDD sample belongs to phase 1), the model in phase 1; returns (i_fsr, i_bsr, y with the canopy)."""
    dt_out = spec.dt_out
    events["PDD"] = round(t, 9)
    i_fsr = k + int(round(spec.fsr_delay_s / dt_out))
    i_bsr = i_fsr + int(round(spec.bsr_delay_s / dt_out))
    events["FSR"] = round(spec.t0 + i_fsr * dt_out, 9)
    events["BSR"] = round(spec.t0 + i_bsr * dt_out, 9)
    model.set_phase(1)
    model.t_pdd = t
    return i_fsr, i_bsr, y + _deploy(model, y, spec)


def _loop_reference(model: _Model, spec: EntryTruthSpec, y: list, states, auxs, phases, events: dict, tick) -> int:
    """The output-sample loop of :func:`simulate_entry` on the scalar Python model (the reference
    path): fills ``states`` (n_max, 19), ``auxs`` (n_max, 17), ``phases`` (n_max,) and ``events``
    in place, calls ``tick(seconds simulated)`` per sample; returns the last sample's index."""
    dt_out = spec.dt_out
    n_entry = int(round(dt_out / spec.dt_entry))
    n_chute = int(round(dt_out / spec.dt_chute))
    h_ent, h_ch = dt_out / n_entry, dt_out / n_chute
    n_max = states.shape[0]
    k = 0
    t = spec.t0
    i_fsr = i_bsr = None
    while True:
        tick(float(t - spec.t0))
        if i_fsr is not None and k == i_fsr:  # front shield leaves: mass, inertia and aero table switch
            model.set_phase(2)
        _, a = model.deriv(t, y, aux=True)
        if model.phase == 0 and spec.aero_enabled:
            trig = (t >= spec.pdd_time_s - 1e-9) if spec.pdd_time_s is not None else (a[3] < spec.pdd_mach and t > 0)
            if trig:
                i_fsr, i_bsr, y = _pdd_event(model, spec, y, k, t, events)
                _, a = model.deriv(t, y, aux=True)
        states[k, : len(y)] = y
        auxs[k] = a
        phases[k] = model.phase
        if (i_bsr is not None and k >= i_bsr) or k == n_max - 1:
            return k
        if math.sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]) < R_GROUND:
            raise RuntimeError(f"simulate_entry: the module hit the ground at t = {t:.2f} s")
        if model.phase == 0:
            for j in range(n_entry):
                y = _rk4(model, t + j * h_ent, y, h_ent)
        else:
            for j in range(n_chute):
                y = _rk4(model, t + j * h_ch, y, h_ch)
        k += 1
        t = spec.t0 + k * dt_out


#: output samples per call of the compiled loop between progress updates
_CHUNK = 2000


def _loop_compiled(model: _Model, spec: EntryTruthSpec, y: list, states, auxs, phases, events: dict, tick) -> int:
    """:func:`_loop_reference` on the compiled model (:func:`.truth_fast.run_segment`), the same
    samples and events; Python handles only the events (PDD deployment, FSR phase switch)."""
    dt_out = spec.dt_out
    n_sub = {0: int(round(dt_out / spec.dt_entry)), 1: int(round(dt_out / spec.dt_chute))}
    n_max = states.shape[0]
    yy = np.zeros(19)
    yy[: len(y)] = y
    n = len(y)
    k, k_last = 0, n_max - 1
    i_fsr = None
    if not spec.aero_enabled:
        trig_mode, trig_value = 0, 0.0
    elif spec.pdd_time_s is not None:
        trig_mode, trig_value = 1, float(spec.pdd_time_s)
    else:
        trig_mode, trig_value = 2, float(spec.pdd_mach)
    sc, arrs = model.packed()
    while True:
        tick(float(k * dt_out))
        if i_fsr is not None and k == i_fsr:  # front shield leaves: mass, inertia and aero table switch
            model.set_phase(2)
            sc, arrs = model.packed()
        k_end = min(i_fsr, k_last + 1) if model.phase == 1 and i_fsr is not None else k_last + 1
        k0 = k
        status, k = tf.run_segment(
            k,
            min(k_end, k + _CHUNK),
            k_last,
            spec.t0,
            dt_out,
            yy,
            n,
            n_sub[min(model.phase, 1)],
            trig_mode if model.phase == 0 else 0,
            trig_value,
            R_GROUND,
            states,
            auxs,
            sc,
            arrs,
        )
        stored = k + 1 if status in (tf.STATUS_DONE, tf.STATUS_GROUND) else k  # samples k0 .. stored - 1
        phases[k0:stored] = model.phase
        if status == tf.STATUS_PDD:
            i_fsr, i_bsr, y = _pdd_event(model, spec, yy[:n].tolist(), k, spec.t0 + k * dt_out, events)
            if i_fsr <= k:  # as the reference: the phase switch is checked before the PDD sample only
                i_fsr = None
            n = len(y)
            yy[:n] = y
            k_last = min(i_bsr, n_max - 1)
            sc, arrs = model.packed()
        elif status == tf.STATUS_DONE:
            return k
        elif status == tf.STATUS_GROUND:
            raise RuntimeError(f"simulate_entry: the module hit the ground at t = {spec.t0 + k * dt_out:.2f} s")


def _rk4(model: _Model, t: float, y: list, dt: float) -> list:
    f = model.deriv
    k1 = f(t, y)
    h2 = 0.5 * dt
    k2 = f(t + h2, [a + h2 * b for a, b in zip(y, k1, strict=True)])
    k3 = f(t + h2, [a + h2 * b for a, b in zip(y, k2, strict=True)])
    k4 = f(t + dt, [a + dt * b for a, b in zip(y, k3, strict=True)])
    d6 = dt / 6.0
    out = [a + d6 * (b + 2.0 * (c + d) + e) for a, b, c, d, e in zip(y, k1, k2, k3, k4, strict=True)]
    qn = 1.0 / math.sqrt(out[6] ** 2 + out[7] ** 2 + out[8] ** 2 + out[9] ** 2)
    out[6] *= qn
    out[7] *= qn
    out[8] *= qn
    out[9] *= qn
    return out


def _initial_velocity(p0: np.ndarray, v0: np.ndarray, spec: EntryTruthSpec) -> np.ndarray:
    """Table 2 velocity [m/s, M] rotated in its vertical plane by ``fpa_offset_deg`` (< 0 steeper)
    and lengthened by ``speed_offset_mps`` (the truth's departure from the nominal state)."""
    if spec.fpa_offset_deg == 0.0 and spec.speed_offset_mps == 0.0:
        return v0
    speed = float(np.linalg.norm(v0))
    axis = np.cross(v0, p0)  # rotating v about v × p by a positive angle raises the flight path
    axis = axis / np.linalg.norm(axis)
    a = math.radians(spec.fpa_offset_deg)
    u = v0 / speed
    u = u * math.cos(a) + np.cross(axis, u) * math.sin(a) + axis * float(axis @ u) * (1.0 - math.cos(a))
    return u * (speed + spec.speed_offset_mps)


def _initial_quaternion(spec: EntryTruthSpec) -> np.ndarray:
    """q_M_G at t0: the Table 2 JPL quaternion (numerically q_M_G) with the optional extra tilt."""
    q = quat_normalize(np.asarray(spec.q0_jpl, dtype=float))
    if spec.aoa_offset_deg != 0.0:
        az = math.radians(spec.aoa_offset_azimuth_deg)
        half = 0.5 * math.radians(spec.aoa_offset_deg)
        # body-frame rotation about the axis (cos az, sin az, 0)
        dq = np.array([math.cos(az) * math.sin(half), math.sin(az) * math.sin(half), 0.0, math.cos(half)])
        q = quat_multiply(q, dq)
    return quat_normalize(q)


def simulate_entry(
    vehicle: EntryVehicle, spec: EntryTruthSpec, rng: np.random.Generator, *, fast: bool = True
) -> EntryTruth:
    """Simulate the entry and parachute descent from ``spec.t0`` to BSR (or ``spec.t_end``).

    Args:
        vehicle: the :class:`EntryVehicle` (``load_vehicle("assets/vehicles/schiaparelli.toml")``).
        spec: :class:`EntryTruthSpec` (a scenario's: ``EntrySettings.synthetic.truth``).
        rng: ``np.random.Generator``; only the canopy breathing phase/amplitude jitter uses it.
        fast: integrate with the compiled model (:mod:`.truth_fast`); False: the scalar Python
            reference model (the same operations, ~100x slower).

    Returns:
        :class:`EntryTruth` on a uniform ``spec.dt_out`` grid from ``t0`` to the end event,
        with events {EIP: 0, PDD, FSR, BSR} (NaN for events not reached before ``t_end``).
    """
    atm = true_atmosphere(spec)
    model = _Model(vehicle, spec, atm, rng)
    p0 = np.asarray(spec.p0_km, float) * 1e3
    v0 = _initial_velocity(p0, np.asarray(spec.v0_kmps, float) * 1e3, spec)
    p0 = p0 + np.asarray(spec.initial_position_offset_km, float) * 1e3
    q0 = _initial_quaternion(spec)
    w0 = np.radians(np.asarray(spec.w0_dps, float))
    y = [*p0.tolist(), *v0.tolist(), *q0.tolist(), *w0.tolist()]

    dt_out = spec.dt_out
    t_stop_cap = spec.t_end if spec.t_end is not None else 2000.0
    n_max = int(math.floor((t_stop_cap - spec.t0) / dt_out + 1e-9)) + 1

    states = np.full((n_max, 19), np.nan)
    auxs = np.zeros((n_max, 17))
    phases = np.zeros(n_max, dtype=int)
    events = {"EIP": 0.0, "PDD": math.nan, "FSR": math.nan, "BSR": math.nan}
    with progress.current().counter(
        "entry truth simulation", total=None if spec.t_end is None else float(spec.t_end - spec.t0), unit="s simulated"
    ) as bar:
        loop = _loop_compiled if fast else _loop_reference
        k = loop(model, spec, y, states, auxs, phases, events, bar.set)
    n = k + 1
    states, auxs, phases = states[:n], auxs[:n], phases[:n]
    tgrid = np.round(spec.t0 + dt_out * np.arange(n), 9)
    q = states[:, _TQ]
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    chute_p = states[:, _TCHUTE] if np.isfinite(events["PDD"]) else None
    return EntryTruth(
        t=tgrid,
        p_M=states[:, _TP].copy(),
        v_M=states[:, _TV].copy(),
        q_M_G=q,
        w_G=states[:, _TW].copy(),
        f_G=auxs[:, _AUX_F].copy(),
        phase=phases,
        mach=auxs[:, 3].copy(),
        knudsen=auxs[:, 4].copy(),
        alpha_total=auxs[:, 5].copy(),
        dynamic_pressure=auxs[:, 6].copy(),
        h_amr=auxs[:, 7].copy(),
        v_rel_M=auxs[:, 8:11].copy(),
        wind_NE=auxs[:, 11:13].copy(),
        events=events,
        atmosphere=atm,
        epoch_utc=spec.epoch_utc,
        jd_tdb0=julian_date_from_utc(spec.epoch_utc),
        parachute_p_M=None if chute_p is None else chute_p.copy(),
        riser_tension=auxs[:, 13].copy(),
        parachute_area=auxs[:, 14].copy(),
        ca_factor=auxs[:, 15].copy(),
        chute_cd_factor=auxs[:, 16].copy(),
        terrain_modes=np.asarray(spec.terrain_modes, dtype=float).reshape(-1, 5),
        spec=spec,
    )


def _deploy(model: _Model, y: list, spec: EntryTruthSpec) -> list:
    """Canopy state [p (3), v (3)] at line stretch, ``riser_length`` behind the attachment point."""
    px, py, pz, vx, vy, vz, qx, qy, qz, qw, wx, wy, wz = y[:13]
    q = np.array([qx, qy, qz, qw])
    C = quat_to_dcm(q)
    tilt, az = math.radians(spec.deploy_tilt_deg), math.radians(spec.deploy_azimuth_deg)
    u_G = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), math.cos(tilt)])
    att = np.asarray(model.att)
    w = np.array([wx, wy, wz])
    pa = np.array([px, py, pz]) + C @ att
    va = np.array([vx, vy, vz]) + C @ np.cross(w, att)
    u = C @ u_G
    az_s = math.radians(spec.side_force_azimuth_deg)
    model.side_M = tuple((C @ np.array([math.cos(az_s), math.sin(az_s), 0.0])).tolist())
    pp = pa + model.L0 * u
    vp = va + spec.eject_speed_mps * u
    return [*pp.tolist(), *vp.tolist()]
