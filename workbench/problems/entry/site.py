"""The landing site of the entry problem (Schiaparelli, Meridiani Planum): the one place for its
reference sphere and terrain height.

AMELIA (Aboudan et al., Space Sci. Rev. 214:97, 2018) measures altitude above the MOLA reference
sphere of radius 3396 km (Eq. B.1) and models the terrain near the landing site as flat at
1440 m below it (Sect. 7), i.e. as the sphere of radius :data:`R_GROUND` about the Mars centre.
A scenario may override the terrain height (``[site] terrain_m``); these are the defaults.  The
*truth* of a synthetic scenario adds a smooth random relief (:class:`TerrainRelief`) that the
reconstruction does not know: it keeps the sphere and a terrain-noise term in its radar 1σ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from workbench.core.bodies import MARS

__all__ = ["R_MOLA", "TERRAIN_ELEVATION_M", "R_GROUND", "TerrainRelief", "draw_terrain_modes"]

R_MOLA: float = MARS.reference_radius
"""MOLA reference radius [m] (3396 km, AMELIA Eq. B.1): altitudes "AMR" are measured from it."""

TERRAIN_ELEVATION_M: float = -1440.0
"""Terrain height of the landing site above the MOLA sphere [m] (AMELIA Sect. 7)."""

R_GROUND: float = R_MOLA + TERRAIN_ELEVATION_M
"""Terrain radius [m]: the flat terrain as a sphere, 3396 km − 1440 m."""


@dataclass(frozen=True)
class TerrainRelief:
    """A smooth random terrain about the sphere of radius ``r_ground`` [m] (truth side only).

    The height above the sphere is a sum of plane waves on the unit sphere,
    ``h(u) = Σ A_k cos(r_ground · (k̂_k · u) · 2π/λ_k + φ_k)``, with ``u`` the unit position vector
    in the *rotating* (body-fixed) frame ``F = Rz(−ω t) M`` (t [s] from EIP, ω the Mars rotation
    rate, so the terrain turns with the planet), ``k̂`` the unit wave direction given by its
    latitude/longitude in F.  Near any point the field is a sum of surface waves of wavelength
    ``λ / sin(angle(k̂, up))`` ≥ λ: an isotropic, stationary, smooth random surface whose variance
    is ``Σ A_k² / 2``.  ``modes`` rows ``(amplitude_m, wavelength_km, dir_lat_deg, dir_lon_deg,
    phase_deg)``; no modes = the sphere.  ``omega`` [rad/s] the rotation rate.
    """

    r_ground: float
    modes: tuple[tuple[float, float, float, float, float], ...] = ()
    omega: float = MARS.rotation_rate

    def rms_m(self) -> float:
        """RMS height of the relief [m] (``sqrt(Σ A²/2)``)."""
        return float(math.sqrt(sum(0.5 * m[0] ** 2 for m in self.modes)))

    def height(self, p_M: np.ndarray, t: np.ndarray | float) -> np.ndarray:
        """Terrain height above the sphere [m] below positions ``p_M`` (..., 3) [m, M] at times ``t``
        [s from EIP] (broadcast against ``p_M[..., 0]``).  Returns shape (...)."""
        p = np.asarray(p_M, dtype=float)
        out = np.zeros(p.shape[:-1])
        if not self.modes:
            return out
        a = self.omega * np.asarray(t, dtype=float)
        c, s = np.cos(a), np.sin(a)
        x = c * p[..., 0] + s * p[..., 1]  # Rz(−a) p
        y = -s * p[..., 0] + c * p[..., 1]
        z = p[..., 2]
        r = np.sqrt(x * x + y * y + z * z)
        for amp, lam_km, lat, lon, ph in self.modes:
            la, lo = math.radians(lat), math.radians(lon)
            k = (math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la))
            kk = 2.0 * math.pi * self.r_ground / (lam_km * 1e3)
            out = out + amp * np.cos(kk * (k[0] * x + k[1] * y + k[2] * z) / r + math.radians(ph))
        return out

    def radius(self, p_M: np.ndarray, t: np.ndarray | float) -> np.ndarray:
        """Terrain radius [m] below ``p_M`` (..., 3) at ``t``: ``r_ground + height``."""
        return self.r_ground + self.height(p_M, t)


def draw_terrain_modes(
    rng: np.random.Generator,
    rms_m: float = 100.0,
    n_modes: int = 12,
    wavelength_km: tuple[float, float] = (2.0, 12.0),
) -> tuple[tuple[float, float, float, float, float], ...]:
    """Random modes of a :class:`TerrainRelief`: ``n_modes`` waves with directions uniform on the
    sphere, wavelengths log-uniform in ``wavelength_km`` [km], phases uniform, amplitudes equal
    so that the RMS height is ``rms_m`` [m].  Rows ``(amplitude_m, wavelength_km, dir_lat_deg,
    dir_lon_deg, phase_deg)``."""
    amp = rms_m * math.sqrt(2.0 / n_modes)
    lam = np.exp(rng.uniform(math.log(wavelength_km[0]), math.log(wavelength_km[1]), n_modes))
    lat = np.degrees(np.arcsin(rng.uniform(-1.0, 1.0, n_modes)))
    lon = rng.uniform(-180.0, 180.0, n_modes)
    ph = rng.uniform(0.0, 360.0, n_modes)
    return tuple(
        (round(amp, 3), round(float(a), 4), round(float(b), 4), round(float(c), 4), round(float(d), 3))
        for a, b, c, d in zip(lam, lat, lon, ph, strict=True)
    )
