"""Truth simulator of an MSL-like entry for the flush air data problem (synthetic scenarios only).

This is the *truth*, not the estimator's model:

* **Trajectory** — 3-DOF point mass in the Mars-centred inertial frame M (+Z the pole; J2 gravity,
  :func:`workbench.core.gravity.gravity_j2`), from the entry interface (~125 km, 5.845 km/s,
  Way et al. AAS 13-420; FACTS) to heat-shield separation.  The atmosphere co-rotates with Mars and
  blows with the true winds.  Aerodynamics of the truth's own: drag coefficient
  ``C_D(M) = 1.45 + 0.2 tanh((M − 3)/3)`` and lift ``L/D = 0.24 α_trim/18°`` (MSL's L/D 0.24 at
  the hypersonic trim; NASA), the lift vector rolled about the air-relative velocity by a bank
  profile (MSL's guided entry: lift up, banked, lift up through the loft, banked); with the
  default profile the planet-relative flight-path angle crosses zero twice (near 109 s and
  166 s), as MSL's did (paper Fig. 1c), maximum q∞ ≈ 14 kPa (the paper's Table 2: 14.0 kPa) and
  the parachute opens near 269 s at 7.5 km.  A disk-gap-band parachute (``C_D S`` =
  ``chute_cds_m2``, inflating over 1 s) opens at Mach ``chute_mach`` (MSL: 1.75) and the data end
  ``hss_delay_s`` later at heat-shield separation.
* **Attitude** — the body axes B (flush_airdata conventions: +x out of the nose) follow the
  air-relative velocity at the angle of attack ``α(t) = α_trim(M) + oscillation`` (16° hypersonic
  rising to 20° below Mach 5, FACTS "α near 16–20°") and a sideslip oscillation; the lift side is
  the windward (+z_B) side.  Body rates come from differencing the attitude.
* **Atmosphere** — its own temperature profile with a gravity wave, hydrostatic
  (:func:`workbench.core.atmosphere.hydrostatic_table`), its own gas constant and γ (1.33; the
  estimator assumes MEADS's 1.335); winds from :func:`workbench.core.atmosphere.layered_wind_NE`.
* **Surface pressures** (:func:`cfd_like_pressure`) — a richer model than either estimator
  model, standing in for the LAURA/CAMAC solutions: modified Newtonian with (a) a shock-layer
  effective γ that relaxes from frozen (1.335) at low density to an equilibrium value that falls
  with speed (vibrational excitation of CO2; CAMAC's relaxation, reduced to
  ``f = ρ/(ρ + ρ_relax)``), (b) a displaced stagnation point (the windward shift of a blunt cone:
  the incidence is taken at ``α_T (1 − stagnation_shift)``), (c) a Mach-dependent flattening, (d) a
  Mach- and α-dependent shoulder expansion and (e) a small base-level pressure in the shadow.
  It is evaluated at each port's *true* (displaced) location.

The right-hand side of the trajectory is compiled (:mod:`.truth_fast`); :class:`TruthDynamics` is
its Python reference (``simulate_entry(..., fast=False)``).  Units SI; times in seconds from the
entry interface.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.integrate import solve_ivp

from workbench.core.atmosphere import CO2_SUTHERLAND, R_UNIVERSAL, hydrostatic_table, layered_wind_NE
from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import dcm_to_quat, quat_conjugate, quat_multiply, quat_positive, quat_to_rotvec
from workbench.models.flush_airdata import FadsVehicle, rayleigh_pitot_cp
from workbench.problems.meads import truth_fast as tf

__all__ = [
    "MeadsTruthSpec",
    "MeadsTruth",
    "MeadsDispersionSigmas",
    "disperse_truth_spec",
    "true_atmosphere",
    "simulate_entry",
    "TruthDynamics",
    "entry_state",
    "cfd_like_pressure",
    "alpha_trim",
]

_TEMPERATURE_NODES_KM_K: tuple[tuple[float, float], ...] = (
    (-10.0, 238.0),
    (0.0, 226.0),
    (10.0, 208.0),
    (20.0, 194.0),
    (30.0, 182.0),
    (40.0, 171.0),
    (50.0, 160.0),
    (60.0, 150.0),
    (70.0, 141.0),
    (80.0, 134.0),
    (90.0, 128.0),
    (100.0, 125.0),
    (115.0, 135.0),
    (140.0, 165.0),
)


@dataclass(frozen=True, kw_only=True)
class MeadsTruthSpec:
    """Parameters of the truth (SI unless the name says otherwise).  The scenario's ``[truth]`` keys
    (defaults: an MSL-like entry, in :data:`.config.SCHEMA`) are required here; the others keep
    their defaults below.

    Entry state at t = 0: altitude ``entry_altitude_km`` above the MOLA reference sphere,
    inertial speed ``entry_speed_kmps``, inertial flight-path angle ``entry_fpa_deg``, heading
    ``entry_azimuth_deg`` (from north), latitude ``entry_latitude_deg`` (longitude 0 in M).
    Vehicle: ``mass_kg``, reference area from the vehicle file.  ``bank_profile_deg``: (t_s, bank)
    nodes, linear between.  ``alpha_hyper_deg``/``alpha_low_deg``: trim α above Mach 25 / below 5
    (linear in Mach between), ``alpha_chute_deg`` under the parachute; ``alpha_osc_deg``,
    ``alpha_osc_hz``, ``beta_osc_deg``, ``beta_osc_hz``: attitude oscillations.  Atmosphere:
    ``surface_pressure_pa`` at 0 km, ``gamma``, ``molar_mass_g_per_mol``, a gravity wave
    ``wave_amplitude_K``/``wave_length_km``; winds: background and ``wind_layers`` as in
    :func:`~workbench.core.atmosphere.layered_wind_NE`.  Pressure model: ``rho_relax`` [kg/m³],
    ``gamma_eq_hyper``, ``stagnation_shift`` [-], ``shoulder`` [-].
    """

    entry_altitude_km: float
    entry_speed_kmps: float
    entry_fpa_deg: float
    entry_azimuth_deg: float
    entry_latitude_deg: float
    mass_kg: float
    bank_profile_deg: tuple[tuple[float, float], ...]
    alpha_hyper_deg: float
    alpha_low_deg: float
    alpha_chute_deg: float = 4.0
    alpha_osc_deg: float
    alpha_osc_hz: float = 0.23
    beta_osc_deg: float
    beta_osc_hz: float = 0.29
    chute_mach: float
    chute_cds_m2: float = 210.0
    hss_delay_s: float
    max_time_s: float = 600.0
    dt: float = 0.025
    surface_pressure_pa: float
    gamma: float
    molar_mass_g_per_mol: float = 43.34
    wave_amplitude_K: float
    wave_length_km: float = 13.0
    temperature_nodes_km_K: tuple[tuple[float, float], ...] = _TEMPERATURE_NODES_KM_K
    background_wind_mps: float
    background_azimuth_deg: float = 60.0
    background_turn_deg_per_km: float = 1.5
    wind_layers: tuple[tuple[float, float, float, float, float], ...] = field(
        default_factory=lambda: (
            (8.0, 14.0, 25.0, 200.0, 1.0),
            (20.0, 32.0, 45.0, 100.0, 2.0),
            (40.0, 60.0, 35.0, 300.0, 3.0),
        )
    )
    rho_relax: float = 2.0e-5
    gamma_eq_hyper: float = 1.16
    stagnation_shift: float
    shoulder: float


@dataclass(frozen=True)
class MeadsTruth:
    """The true entry on the simulation grid (n samples, SI, frame M unless said).

    ``t`` (n,) [s]; ``p_M``, ``v_M`` (n, 3); ``q_M_B`` (n, 4) body → M; ``w_B`` (n, 3) [rad/s] body
    rate; ``f_B`` (n, 3) [m/s²] specific force; ``h`` [m] above the reference sphere; ``rho``
    [kg/m³], ``p_inf`` [Pa], ``T`` [K], ``a`` [m/s] speed of sound; ``wind_NE`` (n, 2) [m/s];
    ``v_air_B`` (n, 3) [m/s] air-relative velocity in B; ``alpha``, ``beta`` [rad]; ``mach``,
    ``qbar`` [Pa]; ``fpa`` [rad] planet-relative flight-path angle; ``v_ground_N`` (n, 3) [m/s]
    planet-relative velocity in local NED; ``t_chute``, ``t_hss`` [s]; ``gamma``, ``gas_constant``.
    """

    t: np.ndarray
    p_M: np.ndarray
    v_M: np.ndarray
    q_M_B: np.ndarray
    w_B: np.ndarray
    f_B: np.ndarray
    h: np.ndarray
    rho: np.ndarray
    p_inf: np.ndarray
    T: np.ndarray
    a: np.ndarray
    wind_NE: np.ndarray
    v_air_B: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    mach: np.ndarray
    qbar: np.ndarray
    fpa: np.ndarray
    v_ground_N: np.ndarray
    t_chute: float
    t_hss: float
    gamma: float
    gas_constant: float

    def arrays(self) -> dict[str, np.ndarray]:
        """Every field as an array (for ``truth.npz``)."""
        return {k: np.asarray(v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class MeadsDispersionSigmas:
    """1σ of :func:`disperse_truth_spec`'s draws (SI unless a name carries a unit).

    Entry state: ``entry_fpa_deg``, ``entry_speed_mps`` (a well-delivered entry state, MSL
    delivered 0.01–0.05°).  Attitude: ``trim_alpha_deg`` (the hypersonic and low-Mach trim α, each).
    Atmosphere: ``surface_pressure_rel`` (of the spec's), ``temperature_K`` added to every node of
    the temperature profile independently (nodes 10 km apart, linear between: a perturbation
    correlated over ~10 km), ``wave_amplitude_K`` (added, clipped at 0) and ``wave_length_km``
    (added, clipped at 5 km) of the gravity wave.  Winds: ``background_wind_mps`` (|spec + N|),
    ``background_azimuth_deg``, each layer's speed × (1 + N(0, ``wind_layer_rel``)) and direction
    + N(0, ``wind_layer_deg``).  Surface pressures (the CFD uncertainty): ``stagnation_shift`` and
    ``shoulder`` added (clipped at 0).
    """

    entry_fpa_deg: float = 0.05
    entry_speed_mps: float = 2.0
    trim_alpha_deg: float = 0.5
    surface_pressure_rel: float = 0.05
    temperature_K: float = 5.0
    wave_amplitude_K: float = 2.0
    wave_length_km: float = 2.0
    background_wind_mps: float = 5.0
    background_azimuth_deg: float = 45.0
    wind_layer_rel: float = 0.3
    wind_layer_deg: float = 30.0
    stagnation_shift: float = 0.01
    shoulder: float = 0.02


def disperse_truth_spec(
    spec: MeadsTruthSpec, rng: np.random.Generator, sigmas: MeadsDispersionSigmas | None = None
) -> MeadsTruthSpec:
    """A new truth for one Monte Carlo member: ``spec`` with its entry state, trim α, atmosphere,
    winds and surface-pressure model drawn about the spec's values with the 1σ of ``sigmas``
    (:class:`MeadsDispersionSigmas`), in a fixed order from ``rng`` (entry FPA, speed, the two
    trim α, surface pressure, the node temperatures, wave amplitude and length, background wind
    speed and azimuth, per layer speed and direction, stagnation shift, shoulder).  Everything else
    (bank profile, oscillations, parachute, integration) is kept; ``spec`` is not modified."""
    sg = MeadsDispersionSigmas() if sigmas is None else sigmas
    n = rng.standard_normal
    nodes = np.asarray(spec.temperature_nodes_km_K, float)
    kw: dict = {
        "entry_fpa_deg": spec.entry_fpa_deg + sg.entry_fpa_deg * n(),
        "entry_speed_kmps": spec.entry_speed_kmps + 1e-3 * sg.entry_speed_mps * n(),
        "alpha_hyper_deg": spec.alpha_hyper_deg + sg.trim_alpha_deg * n(),
        "alpha_low_deg": spec.alpha_low_deg + sg.trim_alpha_deg * n(),
        "surface_pressure_pa": spec.surface_pressure_pa * (1.0 + sg.surface_pressure_rel * n()),
    }
    dT = sg.temperature_K * n(nodes.shape[0])
    kw["temperature_nodes_km_K"] = tuple((float(h), float(T + d)) for (h, T), d in zip(nodes, dT, strict=True))
    kw["wave_amplitude_K"] = max(spec.wave_amplitude_K + sg.wave_amplitude_K * n(), 0.0)
    kw["wave_length_km"] = max(spec.wave_length_km + sg.wave_length_km * n(), 5.0)
    kw["background_wind_mps"] = abs(spec.background_wind_mps + sg.background_wind_mps * n())
    kw["background_azimuth_deg"] = spec.background_azimuth_deg + sg.background_azimuth_deg * n()
    layers = []
    for bottom, top, speed, az, edge in spec.wind_layers:
        layers.append((bottom, top, speed * (1.0 + sg.wind_layer_rel * n()), az + sg.wind_layer_deg * n(), edge))
    kw["wind_layers"] = tuple(layers)
    kw["stagnation_shift"] = max(spec.stagnation_shift + sg.stagnation_shift * n(), 0.0)
    kw["shoulder"] = max(spec.shoulder + sg.shoulder * n(), 0.0)
    return replace(spec, **{k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in kw.items()})


def true_atmosphere(spec: MeadsTruthSpec):
    """The true atmosphere (TabulatedAtmosphere, 20 m nodes from −10 to 140 km): the spec's
    temperature nodes (linear between) plus a gravity wave growing as exp(h / 30 km), hydrostatic."""
    h = np.arange(-10e3, 140e3 + 1.0, 20.0)
    nodes = np.asarray(spec.temperature_nodes_km_K, float)
    hk = h / 1e3
    T = np.interp(hk, nodes[:, 0], nodes[:, 1])
    T = T + spec.wave_amplitude_K * np.minimum(np.exp(np.maximum(hk, 0) / 30.0), 4.0) * np.sin(
        2 * np.pi * hk / spec.wave_length_km
    )
    R = R_UNIVERSAL / (spec.molar_mass_g_per_mol * 1e-3)
    return hydrostatic_table(h, T, spec.surface_pressure_pa, R, spec.gamma, MARS, CO2_SUTHERLAND)


def alpha_trim(mach: np.ndarray, spec: MeadsTruthSpec) -> np.ndarray:
    """Trim angle of attack [rad] of the truth at Mach ``mach`` (before the parachute)."""
    frac = np.clip((25.0 - np.asarray(mach, float)) / 20.0, 0.0, 1.0)
    return np.radians(spec.alpha_hyper_deg + (spec.alpha_low_deg - spec.alpha_hyper_deg) * frac)


def _ned(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(north, east, up) unit vectors (..., 3) at position(s) p in M (+Z the pole)."""
    up = p / np.linalg.norm(p, axis=-1, keepdims=True)
    east = np.cross(np.array([0.0, 0.0, 1.0]), up)
    east = east / np.linalg.norm(east, axis=-1, keepdims=True)
    north = np.cross(up, east)
    return north, east, up


def _cross(a, b) -> np.ndarray:
    """3-vector cross product of two (3,) arrays (scalar arithmetic; np.cross is slow on one pair)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _ned_one(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x, y, z = float(p[0]), float(p[1]), float(p[2])
    r = math.sqrt(x * x + y * y + z * z)
    rxy = math.sqrt(x * x + y * y)
    up = np.array([x / r, y / r, z / r])
    east = np.array([-y / rxy, x / rxy, 0.0])
    return _cross(up, east), east, up


def _cd(mach: np.ndarray) -> np.ndarray:
    return 1.45 + 0.2 * np.tanh((np.asarray(mach, float) - 3.0) / 3.0)


class TruthDynamics:
    """Translational dynamics of the truth (state y = [p_M (3) m, v_M (3) m/s] in M) for
    ``vehicle`` and ``spec``: the true atmosphere and winds tabulated in altitude, the bank
    profile; ``t_chute`` [s] the parachute's opening once known (None before).  :meth:`accel` is
    the Python reference of the compiled :func:`.truth_fast.rhs` (:meth:`packed` its arguments)."""

    def __init__(self, vehicle: FadsVehicle, spec: MeadsTruthSpec):
        self.spec = spec
        self.atm = true_atmosphere(spec)
        self.h_tab = np.asarray(self.atm.h)
        self.rho_tab = np.asarray(self.atm.rho)
        self.T_tab = np.asarray(self.atm.T)
        self.wh = np.arange(-10e3, 141e3, 100.0)
        self.wtab = true_wind(self.wh, spec)
        self.R = self.atm.gas_constant
        self.S = vehicle.ref_area
        self.omega = np.array([0.0, 0.0, MARS.rotation_rate])
        bp = np.asarray(spec.bank_profile_deg, float)
        self.bank_t, self.bank = bp[:, 0], np.radians(bp[:, 1])
        self.t_chute: float | None = None

    def air(self, t: float, p: np.ndarray, v: np.ndarray):
        """(h [m], density [kg/m³], T [K], air-relative velocity (3) [m/s] in M, up (3)) at time t
        [s], position p (3) [m] and inertial velocity v (3) [m/s] in M."""
        r = math.sqrt(p @ p)
        h = r - MARS.reference_radius
        rho = float(np.interp(h, self.h_tab, self.rho_tab))
        T = float(np.interp(h, self.h_tab, self.T_tab))
        wn = float(np.interp(h, self.wh, self.wtab[:, 0]))
        we = float(np.interp(h, self.wh, self.wtab[:, 1]))
        north, east, up = _ned_one(p)
        w = self.omega[2]
        v_air = v - np.array([-w * p[1], w * p[0], 0.0]) - wn * north - we * east
        return h, rho, T, v_air, up

    def lift_dir(self, t: float, e_v: np.ndarray, up: np.ndarray) -> np.ndarray:
        """Unit lift direction (3) in M at time t [s]: ``up`` (3) made normal to the air-relative
        direction ``e_v`` (3), rolled about it by the bank profile."""
        u = up - (up @ e_v) * e_v
        u = u / math.sqrt(u @ u)
        s = float(np.interp(t, self.bank_t, self.bank))
        return math.cos(s) * u + math.sin(s) * _cross(e_v, u)

    def accel(self, t: float, p: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(total acceleration, non-gravitational acceleration) [m/s²] in M."""
        h, rho, T, v_air, up = self.air(t, p, v)
        V = math.sqrt(v_air @ v_air)
        e_v = v_air / V
        mach = V / math.sqrt(self.spec.gamma * self.R * T)
        q = 0.5 * rho * V * V
        drag = q * self.S * float(_cd(mach)) / self.spec.mass_kg
        a_ng = -drag * e_v
        if self.t_chute is None or t <= self.t_chute:
            ld = 0.24 * math.degrees(float(alpha_trim(mach, self.spec))) / 18.0
            a_ng = a_ng + ld * drag * self.lift_dir(t, e_v, up)
        else:
            infl = min(max((t - self.t_chute) / 1.0, 0.0), 1.0)
            a_ng = a_ng - infl * q * self.spec.chute_cds_m2 / self.spec.mass_kg * e_v
        return gravity_j2(p, MARS) + a_ng, a_ng

    def packed(self) -> tuple:
        """``(sc, h_tab, rho_tab, T_tab, wh, wn, we, bank_t, bank)``: these dynamics as
        :func:`.truth_fast.rhs` takes them (the parachute's time and whether it is open in ``sc``)."""
        sc = np.zeros(tf.N_SC)
        sc[tf.SC_GM] = MARS.gm
        sc[tf.SC_J2K] = 1.5 * MARS.j2 * MARS.gm * MARS.equatorial_radius**2
        sc[tf.SC_RREF] = MARS.reference_radius
        sc[tf.SC_OMEGA] = self.omega[2]
        sc[tf.SC_GAMMA], sc[tf.SC_R] = self.spec.gamma, self.R
        sc[tf.SC_S], sc[tf.SC_MASS], sc[tf.SC_CDS] = self.S, self.spec.mass_kg, self.spec.chute_cds_m2
        sc[tf.SC_ALPHA_HYPER], sc[tf.SC_ALPHA_LOW] = self.spec.alpha_hyper_deg, self.spec.alpha_low_deg
        sc[tf.SC_T_CHUTE] = 0.0 if self.t_chute is None else self.t_chute
        sc[tf.SC_CHUTE_ON] = 0.0 if self.t_chute is None else 1.0
        tabs = (self.h_tab, self.rho_tab, self.T_tab, self.wh, self.wtab[:, 0], self.wtab[:, 1], self.bank_t, self.bank)
        # writable C-ordered copies: numba types a read-only table apart from a writable one, and
        # would compile the interpolation a second time for it
        return (sc, *(np.array(a, dtype=float, order="C") for a in tabs))


def true_wind(h: np.ndarray, spec: MeadsTruthSpec) -> np.ndarray:
    """True horizontal wind (..., 2) [north, east] [m/s] (blowing towards) at altitude ``h`` [m]."""
    return layered_wind_NE(
        h, spec.background_wind_mps, spec.background_azimuth_deg, spec.background_turn_deg_per_km, spec.wind_layers
    )


def entry_state(spec: MeadsTruthSpec) -> tuple[np.ndarray, np.ndarray]:
    """(p_M (3) [m], v_M (3) [m/s]) in M at the entry interface (t = 0) of ``spec``: its altitude
    and latitude at longitude 0, inertial speed, flight-path angle and heading."""
    lat = math.radians(spec.entry_latitude_deg)
    r = MARS.reference_radius + spec.entry_altitude_km * 1e3
    p = r * np.array([math.cos(lat), 0.0, math.sin(lat)])
    north, east, up = _ned(p)
    g, az = math.radians(spec.entry_fpa_deg), math.radians(spec.entry_azimuth_deg)
    d = math.cos(g) * (math.cos(az) * north + math.sin(az) * east) + math.sin(g) * up
    return p, spec.entry_speed_kmps * 1e3 * d


def simulate_entry(vehicle: FadsVehicle, spec: MeadsTruthSpec, *, fast: bool = True) -> MeadsTruth:
    """Integrate the truth from the entry interface to heat-shield separation and build the
    attitude, rates, specific force and air data on a grid every ``spec.dt``.  Integration:
    adaptive Runge-Kutta (DOP853, rtol 1e-8, steps ≤ 1 s) with dense output, in two phases
    (before the parachute, ended by the Mach event; under it).  Deterministic (the sensor errors
    are drawn elsewhere).  ``fast``: the right-hand side compiled (:mod:`.truth_fast`); False: the
    Python reference (``TruthDynamics.accel``), the same model."""
    dyn = TruthDynamics(vehicle, spec)
    p0, v0 = entry_state(spec)

    packed = [dyn.packed()]  # refreshed when the parachute opens
    if fast:

        def rhs(t, y):
            return tf.rhs(t, y, *packed[0])

        def mach_event(t, y):
            return tf.mach(t, y, *packed[0][:7]) - spec.chute_mach

    else:

        def rhs(t, y):
            return np.concatenate([y[3:], dyn.accel(t, y[:3], y[3:])[0]])

        def mach_event(t, y):
            h, rho, T, v_air, _ = dyn.air(t, y[:3], y[3:])
            return math.sqrt(v_air @ v_air) / math.sqrt(spec.gamma * dyn.R * T) - spec.chute_mach

    mach_event.terminal = True
    mach_event.direction = -1
    kw = {"method": "DOP853", "rtol": 1e-8, "atol": 1e-4, "max_step": 1.0, "dense_output": True}
    s1 = solve_ivp(rhs, (0.0, spec.max_time_s), np.concatenate([p0, v0]), events=mach_event, **kw)
    if s1.status != 1:
        raise RuntimeError(f"the truth never slowed to Mach {spec.chute_mach} within {spec.max_time_s} s")
    t_chute = float(s1.t_events[0][0])
    dyn.t_chute = t_chute
    packed[0] = dyn.packed()
    t_hss = t_chute + spec.hss_delay_s
    s2 = solve_ivp(rhs, (t_chute, t_hss), s1.y_events[0][0], **kw)
    t = np.round(np.arange(0.0, t_hss + 1e-9, spec.dt), 9)
    y = np.where((t <= t_chute)[:, None], s1.sol(np.minimum(t, t_chute)).T, s2.sol(np.maximum(t, t_chute)).T)
    if np.any(np.linalg.norm(y[:, :3], axis=1) < MARS.reference_radius - 5e3):
        raise RuntimeError("the truth trajectory reached the ground before heat-shield separation")
    return _finish(dyn, spec, t, y[:, :3], y[:, 3:], t_chute, float(t[-1]))


def _finish(dyn: TruthDynamics, spec: MeadsTruthSpec, t, P, V, t_chute, t_hss) -> MeadsTruth:
    n = t.size
    north, east, up = _ned(P)
    h = np.linalg.norm(P, axis=1) - MARS.reference_radius
    rho = dyn.atm.density(h)
    p_inf = dyn.atm.pressure(h)
    T = dyn.atm.temperature(h)
    a = np.sqrt(spec.gamma * dyn.R * T)
    wind = true_wind(h, spec)
    v_g = V - np.cross(dyn.omega, P)
    v_air = v_g - wind[:, :1] * north - wind[:, 1:] * east
    Vn = np.linalg.norm(v_air, axis=1)
    e_v = v_air / Vn[:, None]
    mach = Vn / a
    qbar = 0.5 * rho * Vn**2
    chute = t > t_chute
    u = up - np.sum(up * e_v, 1, keepdims=True) * e_v
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    bank = np.interp(t, dyn.bank_t, dyn.bank)[:, None]
    e_L = np.cos(bank) * u + np.sin(bank) * np.cross(e_v, u)
    al = np.where(chute, math.radians(spec.alpha_chute_deg), alpha_trim(mach, spec))
    al = al + math.radians(spec.alpha_osc_deg) * np.sin(2 * np.pi * spec.alpha_osc_hz * t)
    be = math.radians(spec.beta_osc_deg) * np.sin(2 * np.pi * spec.beta_osc_hz * t + 1.0)
    ca, sa, cb, sb = np.cos(al), np.sin(al), np.cos(be), np.sin(be)
    C_B_W = np.stack(
        [
            np.stack([ca * cb, -ca * sb, -sa], -1),
            np.stack([sb, cb, np.zeros(n)], -1),
            np.stack([sa * cb, -sa * sb, ca], -1),
        ],
        axis=1,
    )
    y_w = np.cross(e_L, e_v)
    C_W_M = np.stack([e_v, y_w, e_L], axis=1)
    C_B_M = C_B_W @ C_W_M
    q_M_B = quat_positive(dcm_to_quat(np.swapaxes(C_B_M, 1, 2)))
    for i in range(1, n):  # continuous sign
        if q_M_B[i] @ q_M_B[i - 1] < 0:
            q_M_B[i] = -q_M_B[i]
    dq = quat_multiply(quat_conjugate(q_M_B[:-1]), q_M_B[1:])
    w_mid = quat_to_rotvec(dq) / np.diff(t)[:, None]
    w_B = np.empty((n, 3))
    w_B[1:-1] = 0.5 * (w_mid[1:] + w_mid[:-1])
    w_B[0], w_B[-1] = w_mid[0], w_mid[-1]
    cd_q = qbar * dyn.S * _cd(mach) / spec.mass_kg
    ld = 0.24 * np.degrees(alpha_trim(mach, spec)) / 18.0
    infl = np.clip((t - t_chute) / 1.0, 0.0, 1.0)
    a_ng = -cd_q[:, None] * e_v + np.where(chute, 0.0, ld * cd_q)[:, None] * e_L
    a_ng = a_ng - (infl * qbar * spec.chute_cds_m2 / spec.mass_kg)[:, None] * e_v
    f_B = np.einsum("nij,nj->ni", C_B_M, a_ng)
    v_air_B = np.einsum("nij,nj->ni", C_B_M, v_air)
    vN = np.stack([np.sum(v_g * north, 1), np.sum(v_g * east, 1), -np.sum(v_g * up, 1)], 1)
    fpa = np.arcsin(-vN[:, 2] / np.linalg.norm(vN, axis=1))
    return MeadsTruth(
        t=t,
        p_M=P,
        v_M=V,
        q_M_B=q_M_B,
        w_B=w_B,
        f_B=f_B,
        h=h,
        rho=rho,
        p_inf=p_inf,
        T=T,
        a=a,
        wind_NE=wind,
        v_air_B=v_air_B,
        alpha=np.arctan2(v_air_B[:, 2], v_air_B[:, 0]),
        beta=np.arcsin(v_air_B[:, 1] / Vn),
        mach=mach,
        qbar=qbar,
        fpa=fpa,
        v_ground_N=vN,
        t_chute=t_chute,
        t_hss=t_hss,
        gamma=spec.gamma,
        gas_constant=dyn.R,
    )


def cfd_like_pressure(
    mach: np.ndarray,
    speed: np.ndarray,
    rho: np.ndarray,
    qbar: np.ndarray,
    p_inf: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    radius: np.ndarray,
    clock: np.ndarray,
    vehicle: FadsVehicle,
    spec: MeadsTruthSpec,
) -> np.ndarray:
    """True surface pressure [Pa] (n, m) at ports at ``radius`` [m] and ``clock`` [rad] (m,) (their
    true positions) for flight conditions (n,) (Mach, air speed [m/s], density, q∞ [Pa], p∞ [Pa],
    α, β [rad]).  The model is described in the module docstring."""
    col = [np.asarray(x, float)[:, None] for x in (mach, speed, rho, qbar, p_inf, alpha, beta)]
    M, Vs, rh, q, pinf, a, b = col
    u, v, w = np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)
    at = np.arccos(np.clip(u, -1, 1)) * (1.0 - spec.stagnation_shift)
    phw = np.arctan2(v, w)
    r = np.asarray(radius, float)[None, :]
    cone = vehicle.surface_cone_angle(r)
    s = r / vehicle.base_radius
    crel = np.asarray(clock, float)[None, :] - phw
    g_eq = 1.335 - (1.335 - spec.gamma_eq_hyper) * (1.0 - np.exp(-((Vs / 3500.0) ** 2)))
    frac = rh / (rh + spec.rho_relax)
    g_eff = 1.335 + frac * (g_eq - 1.335)
    m2 = np.maximum(M, 0.05) ** 2
    sub = 2.0 / (g_eff * m2) * ((1.0 + 0.5 * (g_eff - 1.0) * m2) ** (g_eff / (g_eff - 1.0)) - 1.0)
    cpmax = np.where(M > 1.0, rayleigh_pitot_cp(np.maximum(M, 1.0), g_eff), sub)
    ct = np.cos(at) * np.cos(cone) + np.sin(at) * np.sin(cone) * np.cos(crel)
    n = 1.0 - 0.3 * np.exp(-(M - 1.2) / 3.5)
    sh = 1.0 - (spec.shoulder + 0.12 * np.exp(-M / 5.0)) * s**4 * (1.0 + 0.4 * np.sin(at) * np.cos(crel))
    cp = cpmax * np.maximum(ct, 0.0) ** (2.0 * n) * sh + 0.02 * (ct <= 0.0)
    return pinf + q * cp
