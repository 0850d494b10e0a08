"""Atmosphere models: density, pressure, temperature and derived gas properties versus altitude.

Every model implements :class:`Atmosphere`: ``density(h)`` [kg/m³], ``pressure(h)`` [Pa],
``temperature(h)`` [K] for altitude ``h`` [m] (any shape, result has the same shape), and gets
``speed_of_sound``, ``viscosity`` (Sutherland), ``mean_free_path`` and ``knudsen`` from its gas
constant, ratio of specific heats and Sutherland constants.

Models:

* :class:`ExponentialAtmosphere` — isothermal, ρ = ρ0 exp(−h/H).
* :class:`TabulatedAtmosphere` — a profile table (e.g. a reconstructed or MCD profile).
* :class:`MarsEngineeringAtmosphere` — NASA Glenn Mars model (fit to MGS data), made physical
  above ~50 km by an isothermal hydrostatic extension.
* :class:`TitanDefaultAtmosphere` — a documented layered engineering profile anchored on the
  Huygens surface values.
* :class:`EarthStandardAtmosphere` — the U.S. Standard Atmosphere 1976 layers to 86 km, with the
  sea-level pressure and temperature replaceable by a site's weather (QNH and the site's
  temperature reduced to sea level along the standard lapse rate).

References: NASA Glenn Research Center, "Mars Atmosphere Model" (engineering fit to MGS data);
MEADS paper (Karlgaard et al., MSL air data),
Eq. (45)–(46) and Table 1 (Knudsen number, Sutherland law and constants for CO2); AMELIA Sect. 9
(M = 43.41 g/mol); Fulchignoni et al., Nature 438, 2005 (Titan HASI profile); White, *Viscous
Fluid Flow*, 3rd ed., Table 1-2 (Sutherland constants of N2 and air); NOAA/NASA/USAF, *U.S.
Standard Atmosphere, 1976*, Tables 1 and 4 (layers, R = 287.053 J/(kg K), γ = 1.4).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from workbench.core.bodies import MARS, TITAN, Body

__all__ = [
    "R_UNIVERSAL",
    "Sutherland",
    "CO2_SUTHERLAND",
    "N2_SUTHERLAND",
    "MARS_CO2_GAS_CONSTANT",
    "MARS_GAMMA",
    "TITAN_N2_GAS_CONSTANT",
    "TITAN_GAMMA",
    "Atmosphere",
    "ExponentialAtmosphere",
    "TabulatedAtmosphere",
    "MarsEngineeringAtmosphere",
    "TitanDefaultAtmosphere",
    "US76_EARTH_RADIUS",
    "AIR_GAS_CONSTANT",
    "AIR_GAMMA",
    "AIR_SUTHERLAND",
    "EarthStandardAtmosphere",
    "hydrostatic_table",
    "smooth_box",
    "layered_wind_NE",
]

R_UNIVERSAL = 8.314462618
"""Molar gas constant [J/(mol K)] (CODATA 2018, exact)."""
MARS_CO2_GAS_CONSTANT = 191.8
"""Specific gas constant of the Martian CO2 atmosphere [J/(kg K)] (MEADS Table 1).  For reference,
R/M with M = 43.41 g/mol (AMELIA Sect. 9) is 191.5 J/(kg K)."""
MARS_GAMMA = 1.335
"""Ratio of specific heats of CO2 used by MEADS [-]."""
TITAN_N2_GAS_CONSTANT = 296.8
"""Specific gas constant of N2 [J/(kg K)] (R/M, M = 28.0134 g/mol) for Titan (methane neglected)."""
TITAN_GAMMA = 1.4
"""Ratio of specific heats of N2 [-]."""


@dataclass(frozen=True)
class Sutherland:
    """Sutherland viscosity law ``μ = μ0 (T/T0)^{3/2} (T0 + C)/(T + C)`` (MEADS Eq. 46).

    Attributes: ``mu0`` [Pa s] at ``T0`` [K]; ``C`` Sutherland constant [K].
    """

    mu0: float
    T0: float
    C: float

    def viscosity(self, T: np.ndarray) -> np.ndarray:
        """Dynamic viscosity [Pa s] at temperature(s) T [K], any shape."""
        T = np.asarray(T, dtype=float)
        return self.mu0 * (T / self.T0) ** 1.5 * (self.T0 + self.C) / (T + self.C)


CO2_SUTHERLAND = Sutherland(mu0=14.8e-6, T0=293.15, C=240.0)
"""CO2: μ0 = 14.8e-6 Pa s, T0 = 293.15 K, C = 240 K (MEADS Table 1)."""
N2_SUTHERLAND = Sutherland(mu0=1.663e-5, T0=273.0, C=107.0)
"""N2: μ0 = 1.663e-5 Pa s, T0 = 273 K, C = 107 K (White, Table 1-2).  Used for
Titan below its ~100 K validity range: an engineering extrapolation."""


class Atmosphere(ABC):
    """Interface of an atmosphere model; altitudes ``h`` [m] above the body's reference radius.

    Subclasses provide ``density``, ``pressure``, ``temperature`` and the attributes
    ``gas_constant`` [J/(kg K)], ``gamma`` [-] and ``sutherland`` (:class:`Sutherland`).
    All methods accept ``h`` of any shape and return an array of the same shape.
    """

    gas_constant: float
    gamma: float
    sutherland: Sutherland

    @abstractmethod
    def density(self, h: np.ndarray) -> np.ndarray:
        """Density [kg/m³] at altitude h [m]."""

    @abstractmethod
    def pressure(self, h: np.ndarray) -> np.ndarray:
        """Static pressure [Pa] at altitude h [m]."""

    @abstractmethod
    def temperature(self, h: np.ndarray) -> np.ndarray:
        """Static temperature [K] at altitude h [m]."""

    def speed_of_sound(self, h: np.ndarray) -> np.ndarray:
        """Speed of sound ``sqrt(γ R T)`` [m/s] at altitude h [m]."""
        return np.sqrt(self.gamma * self.gas_constant * self.temperature(h))

    def viscosity(self, h: np.ndarray) -> np.ndarray:
        """Dynamic viscosity [Pa s] at altitude h [m] from the Sutherland law."""
        return self.sutherland.viscosity(self.temperature(h))

    def mean_free_path(self, h: np.ndarray) -> np.ndarray:
        """Mean free path ``λ = (μ / p) sqrt(π R T / 2)`` [m] at altitude h [m] (MEADS Eq. 45)."""
        T = self.temperature(h)
        return self.sutherland.viscosity(T) / self.pressure(h) * np.sqrt(0.5 * np.pi * self.gas_constant * T)

    def knudsen(self, h: np.ndarray, length: float | np.ndarray) -> np.ndarray:
        """Knudsen number ``λ / L`` [-] at altitude h [m] for a reference length L [m]."""
        return self.mean_free_path(h) / np.asarray(length, dtype=float)


def _h(h) -> np.ndarray:
    return np.asarray(h, dtype=float)


@dataclass(frozen=True)
class ExponentialAtmosphere(Atmosphere):
    """Isothermal exponential atmosphere: ``ρ = ρ0 exp(−h/H)``, ``T = T0``, ``p = ρ R T0``.

    Attributes: ``rho0`` [kg/m³] at h = 0, scale height ``H`` [m], ``T0`` [K], ``gas_constant``
    [J/(kg K)], ``gamma`` [-], ``sutherland`` (default CO2).  Valid for any h (negative too).
    """

    rho0: float
    H: float
    T0: float
    gas_constant: float = MARS_CO2_GAS_CONSTANT
    gamma: float = MARS_GAMMA
    sutherland: Sutherland = CO2_SUTHERLAND

    def __post_init__(self) -> None:
        if self.rho0 <= 0 or self.H <= 0 or self.T0 <= 0:
            raise ValueError("ExponentialAtmosphere: rho0, H and T0 must be positive")

    def density(self, h):
        return self.rho0 * np.exp(-_h(h) / self.H)

    def pressure(self, h):
        return self.density(h) * self.gas_constant * self.T0

    def temperature(self, h):
        return np.full(np.shape(h), self.T0)


@dataclass(frozen=True, eq=False)
class TabulatedAtmosphere(Atmosphere):
    """Atmosphere interpolated from a profile table.

    Attributes: node altitudes ``h`` [m] (strictly increasing), ``rho`` [kg/m³], ``p`` [Pa],
    ``T`` [K] (all positive, same length ≥ 2), ``gas_constant``, ``gamma``, ``sutherland``,
    ``extrapolate``.

    ρ and p are interpolated linearly in log (exact at the nodes, monotone and exponential
    between nodes); T linearly.  Outside ``[h[0], h[-1]]``: ``extrapolate="raise"`` (default)
    raises ``ValueError``; ``"clamp"`` returns the end-node values.
    """

    h: np.ndarray
    rho: np.ndarray
    p: np.ndarray
    T: np.ndarray
    gas_constant: float = MARS_CO2_GAS_CONSTANT
    gamma: float = MARS_GAMMA
    sutherland: Sutherland = CO2_SUTHERLAND
    extrapolate: str = "raise"

    def __post_init__(self) -> None:
        arrays = {}
        for name in ("h", "rho", "p", "T"):
            a = np.array(getattr(self, name), dtype=float)
            if a.ndim != 1:
                raise ValueError(f"TabulatedAtmosphere: {name} must be 1-D")
            arrays[name] = a
        n = arrays["h"].size
        if n < 2 or any(a.size != n for a in arrays.values()):
            raise ValueError("TabulatedAtmosphere: h, rho, p, T must have the same length >= 2")
        if np.any(np.diff(arrays["h"]) <= 0):
            raise ValueError("TabulatedAtmosphere: h must be strictly increasing")
        for name in ("rho", "p", "T"):
            if np.any(arrays[name] <= 0) or not np.all(np.isfinite(arrays[name])):
                raise ValueError(f"TabulatedAtmosphere: {name} must be finite and positive")
        if self.extrapolate not in ("raise", "clamp"):
            raise ValueError("TabulatedAtmosphere: extrapolate must be 'raise' or 'clamp'")
        for name, a in arrays.items():
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        object.__setattr__(self, "_log_rho", np.log(arrays["rho"]))
        object.__setattr__(self, "_log_p", np.log(arrays["p"]))

    def _check(self, h) -> np.ndarray:
        h = _h(h)
        if self.extrapolate == "raise" and (np.any(h < self.h[0]) or np.any(h > self.h[-1])):
            raise ValueError(
                f"altitude outside the table [{self.h[0]:.6g}, {self.h[-1]:.6g}] m "
                f"(min {np.min(h):.6g}, max {np.max(h):.6g}); use extrapolate='clamp' to hold end values"
            )
        return h

    def density(self, h):
        return np.exp(np.interp(self._check(h), self.h, self._log_rho))

    def pressure(self, h):
        return np.exp(np.interp(self._check(h), self.h, self._log_p))

    def temperature(self, h):
        return np.interp(self._check(h), self.h, self.T)


@dataclass(frozen=True)
class MarsEngineeringAtmosphere(Atmosphere):
    """NASA Glenn Mars engineering model (fit to MGS data) with an isothermal extension aloft.

    Below ``h_blend`` (default 50 km), exactly the published NASA Glenn fit:

    * ``T[°C] = −31 − 0.000998 h`` for h < 7000 m, ``−23.4 − 0.00222 h`` above;
    * ``p[kPa] = 0.699 exp(−0.00009 h)``;
    * ``ρ = p[kPa] / (0.1921 T[K])`` (i.e. R = 192.1 J/(kg K) inside the fit).

    Fix above ``h_blend``: the linear temperature would reach 0 K near 113 km, so the model is
    continued as an isothermal, hydrostatic exponential: ``T = T(h_blend)`` and ρ, p decay with
    the scale height ``H = 192.1 · T(h_blend) / g(h_blend)``, ``g = GM/(R_ref + h_blend)²``.
    T, p and ρ are continuous at ``h_blend``; their slopes are not (the Glenn pressure law has a
    fixed 11.1 km scale height, the isothermal layer ~7.3 km).  T is therefore positive at every
    altitude (≈ 139 K above 50 km).

    ``gas_constant`` (191.8, MEADS) and ``gamma`` (1.335) are used for the speed of sound and the
    mean free path; the density fit keeps its own 0.1921 so that its values match the source.
    """

    h_blend: float = 50.0e3
    body: Body = MARS
    gas_constant: float = MARS_CO2_GAS_CONSTANT
    gamma: float = MARS_GAMMA
    sutherland: Sutherland = CO2_SUTHERLAND

    #: gas constant implied by the Glenn density formula [J/(kg K)]
    GLENN_R = 192.1

    def __post_init__(self) -> None:
        if not (7000.0 <= self.h_blend <= 100.0e3):
            raise ValueError("MarsEngineeringAtmosphere: h_blend must be within 7-100 km")

    @staticmethod
    def _glenn_T(h):
        return np.where(h < 7000.0, -31.0 - 0.000998 * h, -23.4 - 0.00222 * h) + 273.15

    @staticmethod
    def _glenn_p(h):
        return 0.699e3 * np.exp(-0.00009 * h)

    @property
    def scale_height_aloft(self) -> float:
        """Scale height [m] of the isothermal layer above ``h_blend``."""
        g = self.body.gm / (self.body.reference_radius + self.h_blend) ** 2
        return self.GLENN_R * float(self._glenn_T(self.h_blend)) / g

    def temperature(self, h):
        h = _h(h)
        return self._glenn_T(np.minimum(h, self.h_blend))

    def pressure(self, h):
        h = _h(h)
        above = np.maximum(h - self.h_blend, 0.0)
        return self._glenn_p(np.minimum(h, self.h_blend)) * np.exp(-above / self.scale_height_aloft)

    def density(self, h):
        return self.pressure(h) / (self.GLENN_R * self.temperature(h))


def _layered_pressure(h, h_nodes, T_nodes, p0, g0, R, radius):
    """Hydrostatic pressure for T piecewise linear in geopotential altitude (US Std Atm method).

    Geopotential altitude ``z = radius h / (radius + h)`` absorbs the 1/r² decay of gravity with
    ``g0`` the surface gravity; T is linear in z between nodes and constant above the last node.
    """
    z = radius * h / (radius + h)
    z_nodes = radius * h_nodes / (radius + h_nodes)
    # base pressure of each layer
    p_nodes = [p0]
    for i in range(len(z_nodes) - 1):
        dz = z_nodes[i + 1] - z_nodes[i]
        Ta, Tb = T_nodes[i], T_nodes[i + 1]
        if abs(Tb - Ta) < 1e-12:
            ratio = np.exp(-g0 * dz / (R * Ta))
        else:
            lapse = (Tb - Ta) / dz
            ratio = (Tb / Ta) ** (-g0 / (R * lapse))
        p_nodes.append(p_nodes[-1] * ratio)
    p_nodes = np.asarray(p_nodes)
    idx = np.clip(np.searchsorted(z_nodes, z, side="right") - 1, 0, len(z_nodes) - 1)
    zb, Tb, pb = z_nodes[idx], T_nodes[idx], p_nodes[idx]
    nxt = np.minimum(idx + 1, len(z_nodes) - 1)
    last = idx == len(z_nodes) - 1
    span = np.where(last, 1.0, z_nodes[nxt] - zb)
    lapse = np.where(last, 0.0, (T_nodes[nxt] - Tb) / span)
    T = Tb + lapse * (z - zb)
    iso = np.abs(lapse) < 1e-15
    safe_lapse = np.where(iso, 1.0, lapse)
    p = np.where(iso, pb * np.exp(-g0 * (z - zb) / (R * Tb)), pb * (T / Tb) ** (-g0 / (R * safe_lapse)))
    return p, T


class _LayeredAtmosphere(Atmosphere):
    """A hydrostatic atmosphere whose pressure [Pa] and temperature [K] come together from one
    layered profile, ``_profile(h) -> (p, T)``; density ``p / (R T)`` with its ``gas_constant``."""

    gas_constant: float

    @abstractmethod
    def _profile(self, h) -> tuple[np.ndarray, np.ndarray]:
        """(pressure [Pa], temperature [K]) at geometric altitude h [m], any shape."""

    def pressure(self, h):
        return self._profile(h)[0]

    def temperature(self, h):
        return self._profile(h)[1]

    def density(self, h):
        p, T = self._profile(h)
        return p / (self.gas_constant * T)


@dataclass(frozen=True)
class TitanDefaultAtmosphere(_LayeredAtmosphere):
    """Layered engineering atmosphere of Titan (N2), hydrostatic, anchored on Huygens surface data.

    Surface: T = 93.65 K, p = 1467 hPa (Fulchignoni et al., Nature 438, 2005).  Temperature is
    piecewise linear in geopotential altitude through engineering nodes chosen to follow the
    Huygens HASI profile (engineering values, documented choices):

    * 0 km: 93.65 K  ->  44 km: 70.4 K (tropopause)  ->  250 km: 186 K (stratopause),
    * isothermal 186 K above 250 km (the HASI thermosphere oscillates around 150–180 K).

    Pressure integrates the hydrostatic equation exactly per layer (geopotential altitude with
    Titan's surface gravity GM/R²); ρ = p / (R T), R = 296.8 J/(kg K) (pure N2; the few % of CH4
    near the surface are neglected, so the surface density 5.28 kg/m³ is ~3 % below HASI).
    Altitudes are above ``TITAN.reference_radius``; h must be > −R.
    """

    node_altitudes: tuple[float, ...] = (0.0, 44.0e3, 250.0e3)
    node_temperatures: tuple[float, ...] = (93.65, 70.4, 186.0)
    surface_pressure: float = 146700.0
    body: Body = TITAN
    gas_constant: float = TITAN_N2_GAS_CONSTANT
    gamma: float = TITAN_GAMMA
    sutherland: Sutherland = field(default=N2_SUTHERLAND)

    def __post_init__(self) -> None:
        hn = np.asarray(self.node_altitudes, dtype=float)
        Tn = np.asarray(self.node_temperatures, dtype=float)
        if hn.ndim != 1 or hn.size != Tn.size or hn.size < 1 or hn[0] != 0.0 or np.any(np.diff(hn) <= 0):
            raise ValueError("TitanDefaultAtmosphere: node altitudes must start at 0 and increase")
        if np.any(Tn <= 0):
            raise ValueError("TitanDefaultAtmosphere: node temperatures must be positive")

    def _profile(self, h):
        h = _h(h)
        g0 = self.body.gm / self.body.reference_radius**2
        return _layered_pressure(
            h,
            np.asarray(self.node_altitudes, dtype=float),
            np.asarray(self.node_temperatures, dtype=float),
            self.surface_pressure,
            g0,
            self.gas_constant,
            self.body.reference_radius,
        )


US76_EARTH_RADIUS = 6356766.0
"""Effective Earth radius r0 [m] of the U.S. Standard Atmosphere 1976's geopotential altitude."""
AIR_GAS_CONSTANT = 287.053
"""Specific gas constant of dry air [J/(kg K)] (U.S. Standard Atmosphere 1976: R*/M0)."""
AIR_GAMMA = 1.4
"""Ratio of specific heats of dry air [-]."""
AIR_SUTHERLAND = Sutherland(mu0=1.716e-5, T0=273.15, C=110.4)
"""Air: μ0 = 1.716e-5 Pa s, T0 = 273.15 K, C = 110.4 K (White, Table 1-2)."""


@dataclass(frozen=True)
class EarthStandardAtmosphere(_LayeredAtmosphere):
    """U.S. Standard Atmosphere 1976 (dry air, hydrostatic, T linear in geopotential altitude).

    Layer nodes (geopotential km / K): 0 / T0, 11 / T0 − 71.5, 20 / T0 − 71.5, 32 / T0 − 59.5,
    47 / T0 − 15.5, 51 / T0 − 15.5, 71 / T0 − 43.5, 84.852 / T0 − 101.3 (the standard lapse
    rates −6.5, 0, +1, +2.8, 0, −2.8, −2 K/km with T0 = 288.15 K reproduce the 1976 table).
    ``sea_level_pressure`` [Pa] (default 101 325; a site's QNH) and ``sea_level_temperature`` [K]
    (default 288.15) anchor the profile, so a day's weather shifts the whole column.
    Geometric altitudes h (above the sea-level sphere) and geopotential altitudes z are related as
    in the standard, ``z = r0 h / (r0 + h)`` with its r0 = 6 356 766 m and g0 = 9.80665 m/s²;
    held isothermal above 84.852 km.
    """

    sea_level_pressure: float = 101325.0
    sea_level_temperature: float = 288.15
    gas_constant: float = AIR_GAS_CONSTANT
    gamma: float = AIR_GAMMA
    sutherland: Sutherland = field(default=AIR_SUTHERLAND)

    #: geopotential node altitudes [m] and temperature offsets from T0 [K] of the 1976 layers
    NODE_Z = (0.0, 11000.0, 20000.0, 32000.0, 47000.0, 51000.0, 71000.0, 84852.0)
    NODE_DT = (0.0, -71.5, -71.5, -59.5, -15.5, -15.5, -43.5, -101.3)

    def __post_init__(self) -> None:
        if not self.sea_level_pressure > 0 or not self.sea_level_temperature > 80.0:
            raise ValueError("EarthStandardAtmosphere: sea-level pressure must be > 0 and temperature > 80 K")

    def _profile(self, h):
        h = _h(h)
        r = US76_EARTH_RADIUS
        z = np.asarray(self.NODE_Z, dtype=float)
        h_nodes = r * z / (r - z)  # geometric altitude of the geopotential nodes
        T_nodes = self.sea_level_temperature + np.asarray(self.NODE_DT, dtype=float)
        return _layered_pressure(h, h_nodes, T_nodes, self.sea_level_pressure, 9.80665, self.gas_constant, r)

    def altitude_of_pressure(self, p) -> np.ndarray:
        """Inverse of :meth:`pressure` in the troposphere (h < 11 km) [m] for p [Pa], any shape."""
        p = np.asarray(p, dtype=float)
        T0, L = self.sea_level_temperature, 0.0065
        z = T0 / L * (1.0 - (p / self.sea_level_pressure) ** (self.gas_constant * L / 9.80665))
        r = US76_EARTH_RADIUS
        return r * z / (r - z)


# ------------------------------------------------------------ building blocks of true atmospheres


def hydrostatic_table(
    h: np.ndarray,
    T: np.ndarray,
    surface_pressure: float,
    gas_constant: float,
    gamma: float,
    body: Body = MARS,
    sutherland: Sutherland = CO2_SUTHERLAND,
) -> TabulatedAtmosphere:
    """A hydrostatic :class:`TabulatedAtmosphere` from a temperature profile.

    ``h`` (n,) node altitudes [m] above ``body.reference_radius`` (strictly increasing, must
    bracket 0), ``T`` (n,) [K]; ``surface_pressure`` [Pa] at h = 0.  ``dp/dh = −ρ g`` with
    ``ρ = p / (R T)`` and radial ``g = GM/(R_ref + h)²`` (no centrifugal term), integrated by the
    trapezoid rule on g/T; density from the ideal gas.  Extrapolation: clamp.  Used by the truth
    simulators (entry, flush air data) to build their own true atmospheres.
    """
    h = np.asarray(h, dtype=float)
    T = np.asarray(T, dtype=float)
    R = float(gas_constant)
    g = body.gm / (body.reference_radius + h) ** 2
    f = g / (R * T)
    lnp = np.concatenate([[0.0], -np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(h))])
    lnp = lnp - np.interp(0.0, h, lnp) + math.log(surface_pressure)
    p = np.exp(lnp)
    rho = p / (R * T)
    return TabulatedAtmosphere(
        h=h, rho=rho, p=p, T=T, gas_constant=R, gamma=gamma, sutherland=sutherland, extrapolate="clamp"
    )


def smooth_box(h, bottom, top, edge):
    """≈1 inside [bottom, top], 0 outside, tanh edges of width ``edge`` (all in the same unit)."""
    return 0.25 * (1.0 + np.tanh((h - bottom) / edge)) * (1.0 + np.tanh((top - h) / edge))


def layered_wind_NE(
    h,
    background_mps: float,
    background_azimuth_deg: float,
    turn_deg_per_km: float,
    layers,
) -> np.ndarray:
    """Horizontal wind (..., 2) = [north, east] [m/s] (blowing towards) at altitudes ``h`` [m] (any shape).

    A background ``background_mps`` towards ``background_azimuth_deg`` (from north, clockwise)
    turning by ``turn_deg_per_km`` with altitude, plus ``layers``: tuples ``(bottom_km, top_km,
    speed_mps, towards_azimuth_deg, edge_km)``, each a :func:`smooth_box` in altitude.
    """
    hk = np.asarray(h, dtype=float) / 1e3
    az = np.radians(background_azimuth_deg + turn_deg_per_km * hk)
    n = background_mps * np.cos(az)
    e = background_mps * np.sin(az)
    for bottom, top, speed, azd, edge in layers:
        s = speed * smooth_box(hk, bottom, top, edge)
        n = n + s * math.cos(math.radians(azd))
        e = e + s * math.sin(math.radians(azd))
    return np.stack([n, e], axis=-1)
