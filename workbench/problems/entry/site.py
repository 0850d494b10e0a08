"""The landing site of the entry problem (Schiaparelli, Meridiani Planum): the one place for its
reference sphere and terrain height.

AMELIA (Aboudan et al., Space Sci. Rev. 214:97, 2018) measures altitude above the MOLA reference
sphere of radius 3396 km (Eq. B.1) and models the terrain near the landing site as flat at
1440 m below it (Sect. 7), i.e. as the sphere of radius :data:`R_GROUND` about the Mars centre.
A scenario may override the terrain height (``[site] terrain_m``); these are the defaults.
"""

from __future__ import annotations

from workbench.core.bodies import MARS

__all__ = ["R_MOLA", "TERRAIN_ELEVATION_M", "R_GROUND"]

R_MOLA: float = MARS.reference_radius
"""MOLA reference radius [m] (3396 km, AMELIA Eq. B.1): altitudes "AMR" are measured from it."""

TERRAIN_ELEVATION_M: float = -1440.0
"""Terrain height of the landing site above the MOLA sphere [m] (AMELIA Sect. 7)."""

R_GROUND: float = R_MOLA + TERRAIN_ELEVATION_M
"""Terrain radius [m]: the flat terrain as a sphere, 3396 km − 1440 m."""
