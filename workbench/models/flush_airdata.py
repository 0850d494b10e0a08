"""Flush air data system (FADS) models: forebody port geometry and the estimator's pressure models.

Reference: Karlgaard, C. D., et al., "Mars Entry Atmospheric Data System Modeling and Algorithm
Development", AIAA 2009-3916 [R4], Sect. II (Eq. 1–4, the CFD table model) and Sect. IV.A
(pneumatic lag Eq. 40–42, thermal transpiration Eq. 43–47).

Frames and angles (the paper's, Eq. 3 and 11–12): body axes ``B`` with +x along the symmetry axis
out through the heat-shield nose (into the flow), +y to the right, +z completing the right-handed
set ("down" in the pitch plane).  The wind-relative velocity of the vehicle in B is
``V (cos α cos β, sin β, sin α cos β)``; α > 0 puts the flow on the +z side, so the *windward*
side of the heat shield is clock angle φ = 0.  A port is described by its **cone angle** λ (angle
of the outward surface normal from +x) and **clock angle** φ (from +z towards +y), so its normal
is ``n = (cos λ, sin λ sin φ, sin λ cos φ)`` and the incidence of the flow is ``cos θ = n · v̂``
(Eq. 3).  The total angle of attack α_T and aerodynamic roll φ_w are the polar form of the same
direction: ``v̂ = (cos α_T, sin α_T sin φ_w, sin α_T cos φ_w)``.

Forebody of a sphere-cone (nose radius Rn, half-angle θc, base radius Rb): the spherical cap
ends at radius ``r_t = Rn cos θc`` from the axis; there the normal's cone angle is ``90° − θc``.
On the cap ``λ = asin(r / Rn)``; on the conical flank λ is constant, ``90° − θc``.
:func:`load_fads_vehicle` checks every port against this geometry (a port that is not on the
forebody, or whose stated cone angle is not the surface normal at its radius, is an error naming
the file and the port).

Pressure models of the estimator (each ``p (n, m)`` for n samples and m ports, SI):

* :func:`newtonian_pressure` — Eq. (1): ``p = p_t [(1 − R) cos² θ + R]``, ``R = p∞/p_t`` from
  Mach by Eq. (2) (:func:`pressure_ratio`), ``q∞ = (γ/2) p_t R M²`` (Eq. 4);
* :class:`SurfacePressureTable` — a pressure-coefficient database on a Mach × α_T × clock × cone
  grid (the paper's CFD table, re-gridded to one zone of clock and cone angle) interpolated
  linearly, ``p = p∞ + q∞ Cp``.  :func:`modified_newtonian_cp` fills such a table with an
  engineering shock-layer model (Lees' modified Newtonian, a Mach-dependent stagnation pressure
  coefficient at an equilibrium effective γ, a flattening at low Mach and a shoulder expansion);
  it stands in for the LAURA/CAMAC database that is not public.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from workbench.core.atmosphere import MARS_GAMMA
from workbench.io.scenario import ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, load_file
from workbench.models.flush_airdata_kernel import multilinear4, out_of_grid

__all__ = [
    "FlushPort",
    "FadsVehicle",
    "VehicleFileError",
    "FADS_VEHICLE_SCHEMA",
    "FADS_PORT_SCHEMA",
    "load_fads_vehicle",
    "pressure_ratio",
    "rm2_limit",
    "incidence_cos",
    "total_angles",
    "newtonian_pressure",
    "rayleigh_pitot_cp",
    "modified_newtonian_cp",
    "SurfacePressureTable",
    "build_estimator_table",
    "second_order_tube",
    "transpiration_ratio",
    "KNUDSEN_CONSTANTS",
    "POTTER_CONSTANTS",
]

#: Knudsen's thermomolecular constants a1, a2, a3 (Eq. 43; hydrogen in glass tubes).
KNUDSEN_CONSTANTS = (2.46, 3.15, 24.6)
#: Potter's constants b1, b2, b3 (Eq. 47).
POTTER_CONSTANTS = (0.275, 0.625, 24.0)


class VehicleFileError(ScenarioError):
    """A bad flush-air-data vehicle file (a :class:`~workbench.io.scenario.ScenarioError`: the CLI
    exits 3 with it); ``file`` and the dotted ``key`` (``ports[i].radius_m``, i from 1) name it."""


@dataclass(frozen=True)
class FlushPort:
    """One flush pressure port: ``name``; ``radius`` [m] distance of the orifice from the symmetry
    axis; ``cone`` [rad] cone angle λ of the surface normal; ``clock`` [rad] clock angle φ (from
    +z_B towards +y_B); ``why``: the reason for its place (documentation)."""

    name: str
    radius: float
    cone: float
    clock: float
    why: str = ""


@dataclass(frozen=True)
class FadsVehicle:
    """Sphere-cone entry vehicle with flush ports (SI).

    ``diameter`` [m], ``half_angle`` θc [rad], ``nose_radius`` Rn [m], ``mass`` [kg],
    ``ref_area`` [m²], ``drag_coefficient`` nominal hypersonic C_D (plausibility checks only),
    ``ports`` in file order, ``transducer_full_scale`` [Pa] range of the pressure transducers,
    ``tube_length`` [m] and ``tube_diameter`` [m] of the port-to-transducer lines, ``transducer_volume``
    [m³] entrapped volume, ``source`` the file it came from.
    """

    name: str
    diameter: float
    half_angle: float
    nose_radius: float
    mass: float
    ref_area: float
    drag_coefficient: float
    ports: tuple[FlushPort, ...]
    transducer_full_scale: float
    tube_length: float
    tube_diameter: float
    transducer_volume: float
    source: str = ""

    @property
    def base_radius(self) -> float:
        """Rb = D/2 [m]."""
        return 0.5 * self.diameter

    @property
    def tangency_radius(self) -> float:
        """Radius [m] where the spherical cap meets the cone, ``Rn cos θc``."""
        return self.nose_radius * math.cos(self.half_angle)

    @property
    def port_names(self) -> tuple[str, ...]:
        """The port names in file order."""
        return tuple(p.name for p in self.ports)

    def surface_cone_angle(self, radius: np.ndarray) -> np.ndarray:
        """Cone angle λ [rad] of the forebody normal at ``radius`` [m] from the axis (any shape):
        ``asin(r/Rn)`` on the cap, ``90° − θc`` on the flank."""
        r = np.asarray(radius, dtype=float)
        cap = np.arcsin(np.clip(r / self.nose_radius, 0.0, 1.0))
        return np.where(r <= self.tangency_radius, cap, 0.5 * math.pi - self.half_angle)

    def surface_axial(self, radius: np.ndarray) -> np.ndarray:
        """Axial depth [m] of the forebody surface behind the nose at ``radius`` [m] (any shape)."""
        r = np.asarray(radius, dtype=float)
        rt = self.tangency_radius
        cap = self.nose_radius - np.sqrt(np.maximum(self.nose_radius**2 - np.minimum(r, rt) ** 2, 0.0))
        return cap + np.maximum(r - rt, 0.0) * math.tan(self.half_angle) ** -1

    def cone(self) -> np.ndarray:
        """Cone angles λ (m,) [rad] of the ports."""
        return np.array([p.cone for p in self.ports])

    def clock(self) -> np.ndarray:
        """Clock angles φ (m,) [rad] of the ports."""
        return np.array([p.clock for p in self.ports])

    def radius(self) -> np.ndarray:
        """Radial positions (m,) [m] of the ports."""
        return np.array([p.radius for p in self.ports])


_NOUN = "flush-air-data vehicle asset"

#: The flush-air-data vehicle asset (``assets/vehicles/*.toml``): ``[vehicle]`` and the
#: ``[[ports]]`` array, each entry checked against :data:`FADS_PORT_SCHEMA`.  The forebody
#: geometry of each port (on the heat shield, cone angle = surface normal) is checked in code.
FADS_VEHICLE_SCHEMA = Schema(
    "fads_vehicle",
    "flush-air-data vehicle: sphere-cone heat shield and its pressure ports",
    (
        Table(
            "vehicle",
            "the sphere-cone heat shield and the pressure lines",
            (
                Key("name", "str", "", meaning="display name (empty: the file name)"),
                Key("diameter_m", "float", REQUIRED, "m", "heat-shield diameter D", gt=0.0),
                Key("half_angle_deg", "float", REQUIRED, "deg", "cone half-angle", gt=0.0, lt=90.0),
                Key("nose_radius_m", "float", REQUIRED, "m", "nose radius Rn of the spherical cap", gt=0.0),
                Key("mass_kg", "float", REQUIRED, "kg", "entry mass (plausibility checks only)", gt=0.0),
                Key("ref_area_m2", "float", REQUIRED, "m^2", "aerodynamic reference area", gt=0.0),
                Key("drag_coefficient", "float", REQUIRED, "", "nominal hypersonic C_D (plausibility only)", gt=0.0),
                Key("transducer_full_scale_pa", "float", REQUIRED, "Pa", "range of the transducers", gt=0.0),
                Key("tube_length_m", "float", REQUIRED, "m", "port-to-transducer line length", gt=0.0),
                Key("tube_diameter_m", "float", REQUIRED, "m", "line (port) diameter", gt=0.0),
                Key("transducer_volume_m3", "float", REQUIRED, "m^3", "entrapped transducer volume", gt=0.0),
            ),
        ),
        Table(
            "",
            "the pressure ports",
            (Key("ports", "list", REQUIRED, meaning="the `[[ports]]` array of tables (keys below), at least one"),),
        ),
    ),
    noun=_NOUN,
    intro="Keys of a flush-air-data vehicle asset (`[vehicle] file` of a meads scenario)",
)

#: One ``[[ports]]`` entry of a :data:`FADS_VEHICLE_SCHEMA` file.
FADS_PORT_SCHEMA = Schema(
    "fads_port",
    "one flush pressure port",
    (
        Table(
            "",
            "one `[[ports]]` entry (errors name it `ports[i]`, i from 1)",
            (
                Key("name", "str", REQUIRED, meaning="port name, unique (the pressure CSV column)"),
                Key("radius_m", "float", REQUIRED, "m", "distance of the orifice from the symmetry axis", ge=0.0),
                Key(
                    "cone_deg",
                    "float",
                    REQUIRED,
                    "deg",
                    "cone angle of the surface normal (from +x_B)",
                    ge=0.0,
                    lt=90.0,
                ),
                Key("clock_deg", "float", REQUIRED, "deg", "clock angle (from +z_B towards +y_B)", ge=-360.0, le=360.0),
                Key("why", "str", "", meaning="the reason for its place (documentation)"),
            ),
        ),
    ),
    noun=_NOUN,
    intro="Keys of each `[[ports]]` entry of a flush-air-data vehicle asset",
)


#: Tolerance [deg] between a port's stated cone angle and the forebody normal at its radius.
CONE_TOLERANCE_DEG = 0.5


def load_fads_vehicle(path: str | Path) -> FadsVehicle:
    """Read a flush-air-data vehicle asset (TOML, :data:`FADS_VEHICLE_SCHEMA`; see
    ``assets/vehicles/msl_meads.toml``) into a :class:`FadsVehicle` (SI, angles in rad).

    Raises a :class:`~workbench.io.scenario.ScenarioError` naming the file and the dotted key for
    an unknown key (with the nearest valid one), a missing or mistyped key or a value out of its
    bounds; a :class:`VehicleFileError` (also a ScenarioError) for what the schema cannot express:
    no ports, a duplicated name, a port beyond the heat-shield radius (not on the forebody), a cone
    angle that is not the surface normal at the stated radius (:data:`CONE_TOLERANCE_DEG`), a nose
    radius that leaves no cone.
    """
    path = Path(path)
    data = load_file(path, FADS_VEHICLE_SCHEMA)
    v = data["vehicle"]
    diameter, half, rn = v["diameter_m"], math.radians(v["half_angle_deg"]), v["nose_radius_m"]
    ports_raw = data["ports"]
    if not ports_raw:
        raise VehicleFileError(path, "ports", "needs at least one [[ports]] entry")
    shell = FadsVehicle(
        name=v["name"] or path.stem,
        diameter=diameter,
        half_angle=half,
        nose_radius=rn,
        mass=v["mass_kg"],
        ref_area=v["ref_area_m2"],
        drag_coefficient=v["drag_coefficient"],
        ports=(),
        transducer_full_scale=v["transducer_full_scale_pa"],
        tube_length=v["tube_length_m"],
        tube_diameter=v["tube_diameter_m"],
        transducer_volume=v["transducer_volume_m3"],
        source=str(path),
    )
    if not rn * math.cos(half) < 0.5 * diameter:
        raise VehicleFileError(
            path, "vehicle.nose_radius_m", f"the nose radius {rn} m leaves no cone inside the diameter"
        )
    ports: list[FlushPort] = []
    seen: set[str] = set()
    for i, raw in enumerate(ports_raw):
        where = f"ports[{i + 1}]"
        p = FADS_PORT_SCHEMA.validate(raw, path, where=where)
        name = p["name"]
        if name in seen:
            raise VehicleFileError(path, f"{where}.name", f"duplicated port name '{name}'")
        seen.add(name)
        r, cone_deg, clock_deg = p["radius_m"], p["cone_deg"], p["clock_deg"]
        if r > shell.base_radius:
            raise VehicleFileError(
                path,
                f"{where}.radius_m",
                f"port '{name}': radius_m = {r} m is not on the forebody (0 to {shell.base_radius} m from the axis)",
            )
        expect = math.degrees(float(shell.surface_cone_angle(r)))
        if abs(cone_deg - expect) > CONE_TOLERANCE_DEG:
            raise VehicleFileError(
                path,
                f"{where}.cone_deg",
                f"port '{name}': cone_deg = {cone_deg} is not the forebody normal at radius_m = {r} m "
                f"(the {'spherical cap' if r <= shell.tangency_radius else 'cone flank'} there has {expect:.2f} deg); "
                "the port is not on the forebody surface",
            )
        ports.append(FlushPort(name, r, math.radians(cone_deg), math.radians(clock_deg % 360.0), p["why"]))
    return FadsVehicle(**{**shell.__dict__, "ports": tuple(ports)})


# ------------------------------------------------------------------------------ flow relations


def pressure_ratio(mach: np.ndarray, gamma: float = MARS_GAMMA) -> np.ndarray:
    """R = p∞ / p_t (Eq. 2) at freestream Mach ``mach`` (any shape): Rayleigh pitot above Mach 1,
    isentropic below; ``p_t`` the total pressure behind a normal shock."""
    m = np.asarray(mach, dtype=float)
    g = gamma
    m2 = np.maximum(m * m, 1e-12)
    m2s = np.maximum(m2, 1.0)
    sup = (2.0 / ((g + 1.0) * m2s)) ** (g / (g - 1.0)) * ((2.0 * g * m2s - (g - 1.0)) / (g + 1.0)) ** (1.0 / (g - 1.0))
    sub = (1.0 + 0.5 * (g - 1.0) * m2) ** (-g / (g - 1.0))
    return np.where(m > 1.0, sup, sub)


def rm2_limit(gamma: float = MARS_GAMMA) -> float:
    """lim R M² as M → ∞ (Sect. II.A): ``(2/(γ+1))^(γ/(γ−1)) (2γ/(γ+1))^(1/(γ−1))``."""
    g = gamma
    return (2.0 / (g + 1.0)) ** (g / (g - 1.0)) * (2.0 * g / (g + 1.0)) ** (1.0 / (g - 1.0))


def incidence_cos(alpha: np.ndarray, beta: np.ndarray, cone: np.ndarray, clock: np.ndarray) -> np.ndarray:
    """cos θ (Eq. 3) for angles α, β [rad] of shape (n, 1) (or broadcastable) and ports (m,)."""
    a, b = np.asarray(alpha, float), np.asarray(beta, float)
    c, k = np.asarray(cone, float), np.asarray(clock, float)
    cb = np.cos(b)
    u, v, w = np.cos(a) * cb, np.sin(b), np.sin(a) * cb  # wind direction in B, per sample
    sc = np.sin(c)
    return u * np.cos(c) + v * (np.sin(k) * sc) + w * (np.cos(k) * sc)


def total_angles(alpha: np.ndarray, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(α_T, φ_w) [rad]: total angle of attack and aerodynamic roll (clock of the wind) from α, β."""
    a, b = np.asarray(alpha, float), np.asarray(beta, float)
    u, v, w = np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)
    return np.arccos(np.clip(u, -1.0, 1.0)), np.arctan2(v, w)


def newtonian_pressure(pt: np.ndarray, ratio: np.ndarray, cos_theta: np.ndarray) -> np.ndarray:
    """Eq. (1): ``p = p_t [(1 − R) cos² θ + R]`` [Pa]; ``pt``, ``ratio`` (n, 1), ``cos_theta`` (n, m)."""
    return pt * ((1.0 - ratio) * cos_theta**2 + ratio)


def rayleigh_pitot_cp(mach: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """Stagnation pressure coefficient ``(p_t − p∞)/q∞`` behind a normal shock, Rayleigh pitot
    formula at ratio of specific heats ``gamma`` (any broadcastable shapes), Mach > 1."""
    m2 = np.maximum(np.asarray(mach, float) ** 2, 1.0 + 1e-9)
    g = np.asarray(gamma, float)
    p0_pinf = ((g + 1.0) ** 2 * m2 / (4.0 * g * m2 - 2.0 * (g - 1.0))) ** (g / (g - 1.0)) * (
        (1.0 - g + 2.0 * g * m2) / (g + 1.0)
    )
    return 2.0 / (g * m2) * (p0_pinf - 1.0)


def modified_newtonian_cp(
    mach: np.ndarray,
    alpha_t: np.ndarray,
    clock_rel: np.ndarray,
    cone: np.ndarray,
    radius_frac: np.ndarray,
    *,
    gamma_eq_hyper: float = 1.20,
    gamma_mach_scale: float = 8.0,
    flatten: float = 0.25,
    shoulder: float = 0.12,
) -> np.ndarray:
    """Engineering pressure coefficient on a sphere-cone (broadcasting arrays; SI, angles in rad).

    ``Cp = Cp_max(M, γ_eff) · cos θ^(2 n(M)) · (1 − shoulder · s⁴)`` with ``cos θ = cos α_T cos λ +
    sin α_T sin λ cos(φ − φ_w)`` (``clock_rel`` = φ − φ_w), ``Cp_max`` the Rayleigh pitot value at
    an equilibrium shock-layer ``γ_eff = 1.335 − (1.335 − gamma_eq_hyper)(1 − exp(−M/gamma_mach_scale))``
    (vibrational excitation of CO2 lowers the effective γ behind a strong shock), the exponent
    ``n = 1 − flatten · exp(−(M − 1.5)/4)`` flattening the distribution at low supersonic Mach
    (subsonic shock layer) and ``s = r / Rb`` the radial position (expansion towards the
    shoulder).  Negative incidence (shadow) gives 0.
    """
    g = MARS_GAMMA - (MARS_GAMMA - gamma_eq_hyper) * (1.0 - np.exp(-np.asarray(mach, float) / gamma_mach_scale))
    cpmax = rayleigh_pitot_cp(mach, g)
    ct = np.cos(alpha_t) * np.cos(cone) + np.sin(alpha_t) * np.sin(cone) * np.cos(clock_rel)
    n = 1.0 - flatten * np.exp(-(np.asarray(mach, float) - 1.5) / 4.0)
    return cpmax * np.maximum(ct, 0.0) ** (2.0 * n) * (1.0 - shoulder * np.asarray(radius_frac, float) ** 4)


@dataclass(frozen=True)
class SurfacePressureTable:
    """Pressure-coefficient database ``cp[i_mach, i_alpha_t, i_clock, i_s]`` on a Mach × α_T [rad] ×
    relative clock φ − φ_w [rad, 0..π, symmetric] × radial position s = r/Rb grid; the cone angle at
    each s is the forebody normal there.  Interpolated linearly (:meth:`cp`), clamped at the grid
    edges (the paper: linear interpolation for Monte Carlo, cubic for single cases)."""

    mach: np.ndarray
    alpha_t: np.ndarray
    clock: np.ndarray
    s: np.ndarray
    values: np.ndarray

    def cp(
        self, mach: np.ndarray, alpha_t: np.ndarray, clock_rel: np.ndarray, s: np.ndarray, *, fast: bool = True
    ) -> np.ndarray:
        """Cp [-] at the broadcast points (any common shape): Mach [-], α_T [rad], clock relative to
        the wind plane [rad, wrapped to 0..π], s = r/Rb [-], clamped to the grid.  ``fast``: the
        compiled interpolation (:func:`.flush_airdata_kernel.multilinear4`, scipy's arithmetic);
        False: scipy's ``RegularGridInterpolator``, the reference (bit-identical results)."""
        m, a, c, s = np.broadcast_arrays(
            np.asarray(mach, float), np.asarray(alpha_t, float), np.asarray(clock_rel, float), np.asarray(s, float)
        )
        c = np.abs(np.angle(np.exp(1j * c)))
        pts = np.stack(
            [
                np.clip(m, self.mach[0], self.mach[-1]),
                np.clip(a, self.alpha_t[0], self.alpha_t[-1]),
                c,
                np.clip(s, self.s[0], self.s[-1]),
            ],
            axis=-1,
        )
        flat = pts.reshape(-1, 4)
        if not fast:
            return self._interpolator(flat).reshape(m.shape)
        grid = (self.mach, self.alpha_t, self.clock, self.s)
        bad = out_of_grid(*grid, flat)
        if bad >= 0:  # a NaN coordinate: as scipy's bounds check
            raise ValueError(f"One of the requested xi is out of bounds in dimension {bad}")
        out = np.empty(flat.shape[0])
        multilinear4(*grid, self._values_c, flat, out)
        return out.reshape(m.shape)

    @cached_property
    def _values_c(self) -> np.ndarray:
        """``values`` as a C-contiguous float array (what the compiled interpolation indexes)."""
        return np.ascontiguousarray(self.values, dtype=float)

    @cached_property
    def _interpolator(self) -> RegularGridInterpolator:
        """The linear interpolator over the grid, built once per table (a filter calls :meth:`cp`
        thousands of times with a few points each)."""
        return RegularGridInterpolator((self.mach, self.alpha_t, self.clock, self.s), self.values, method="linear")


def build_estimator_table(vehicle: FadsVehicle) -> SurfacePressureTable:
    """The estimator's own database: :func:`modified_newtonian_cp` (default parameters) on Mach
    {1.5 … 40} (14 nodes) × α_T 0–30° (every 2.5°) × clock 0–180° (every 5°, 37 like the paper's) ×
    61 radial nodes (finer towards the shoulder)."""
    mach = np.array([1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 14.0, 18.0, 24.0, 30.0, 40.0])
    alpha = np.radians(np.arange(0.0, 30.01, 2.5))
    clock = np.radians(np.arange(0.0, 180.01, 5.0))
    s = np.sin(np.linspace(0.0, 0.5 * math.pi, 61))
    cone = vehicle.surface_cone_angle(s * vehicle.base_radius)
    M, A, C, S = np.meshgrid(mach, alpha, clock, s, indexing="ij")
    L = np.broadcast_to(cone, S.shape)
    return SurfacePressureTable(mach, alpha, clock, s, modified_newtonian_cp(M, A, C, L, S))


# ------------------------------------------------------------------------- pneumatics and gas


def second_order_tube(
    p_port: np.ndarray,
    T_gas: np.ndarray,
    length: float,
    diameter: float,
    volume: float,
    gamma: float,
    gas_constant: float,
    viscosity: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequency ω_n [rad/s] and damping ζ [-] of a port-tube-transducer line (Eq. 41–42).

    ``p_port`` [Pa] and ``T_gas`` [K] (any shape) the gas state in the tube, ``length``,
    ``diameter`` [m], ``volume`` [m³] the transducer's entrapped volume, ``viscosity`` [Pa s].
    Acoustic impedance of laminar (Poiseuille) flow ``R_d = 32 μ / D²``.  The low-frequency group
    delay of the resulting 2nd-order system is ``2 ζ / ω_n``.
    """
    p = np.asarray(p_port, float)
    T = np.asarray(T_gas, float)
    rho0 = p / (gas_constant * T)
    c = np.sqrt(gamma * gas_constant * T)
    Ac = 0.25 * math.pi * diameter**2
    L, V = length, volume
    Rd = 32.0 * np.asarray(viscosity, float) / diameter**2
    x2 = (gamma * L * Rd) ** 2 / (c * rho0) ** 2
    wn2 = (Ac * c**2 / (L * V)) / ((L * Ac / (2.0 * V)) * (1.0 + x2 / 12.0) + 1.0 + x2 / 6.0)
    wn = np.sqrt(wn2)
    zeta = 0.5 * wn * (gamma * Rd / rho0) * (V * L / (Ac * c**2) + 0.5 * (L / c) ** 2)
    return wn, zeta


def transpiration_ratio(
    p_port: np.ndarray,
    T_port: np.ndarray,
    T_transducer: np.ndarray,
    diameter: float,
    gas_constant: float,
    viscosity_of,
    model: str,
    steps: int = 16,
) -> np.ndarray:
    """Thermal transpiration: transducer/port pressure ratio (any broadcast shape) (Eq. 43–47).

    Integrates ``dP/dT = P/(2T) · G(κ)`` along a tube whose temperature runs linearly from
    ``T_port`` to ``T_transducer`` [K] (``steps`` RK2 steps in T), ``κ = μ/(D P) sqrt(π R T / 2)``
    (Eq. 45), μ from ``viscosity_of(T)`` [Pa s] (Sutherland, Eq. 46).  ``model``: ``"knudsen"``
    ``G = [(κ² + a1 κ)/(κ² + (a1 + a2) κ + a2 a3)]²`` (Eq. 44) or ``"potter"``
    ``G = [1 + b1/κ + b2/(κ + b3/κ)]^-2`` (Eq. 47).  Both → 0 as κ → 0 (continuum: no effect)
    and P ∝ sqrt(T) as κ → ∞ (free molecular).
    """
    P = np.asarray(p_port, float).copy()
    T0 = np.asarray(T_port, float)
    T1 = np.asarray(T_transducer, float)
    P, T0, T1 = np.broadcast_arrays(P, T0, T1)
    P = P.copy()

    def g_of(P, T):
        kap = viscosity_of(T) / (diameter * np.maximum(P, 1e-12)) * np.sqrt(math.pi * gas_constant * T / 2.0)
        if model == "knudsen":
            a1, a2, a3 = KNUDSEN_CONSTANTS
            return ((kap**2 + a1 * kap) / (kap**2 + (a1 + a2) * kap + a2 * a3)) ** 2
        if model == "potter":
            b1, b2, b3 = POTTER_CONSTANTS
            return (1.0 + b1 / kap + b2 / (kap + b3 / kap)) ** -2
        raise ValueError(f"transpiration model {model!r}: use 'knudsen' or 'potter'")

    dT = (T1 - T0) / steps
    T = T0.copy()
    for _ in range(steps):
        k1 = P / (2.0 * T) * g_of(P, T)
        Pm, Tm = P + 0.5 * dT * k1, T + 0.5 * dT
        k2 = Pm / (2.0 * Tm) * g_of(Pm, Tm)
        P = P + dT * k2
        T = T + dT
    return P / np.asarray(p_port, float)
