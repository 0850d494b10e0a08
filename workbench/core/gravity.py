"""Gravity models: point mass, point mass + J2 zonal term, and uniform lab gravity.

All functions are vectorised over leading axes ``(..., 3)`` and return accelerations [m/s²] in the
frame of their input position.  The J2 model must be evaluated in the body-fixed frame F (its
+Z axis is the pole); it is the gradient of

    U(r) = GM / r · [1 − J2 (Re / r)² P2(z / r)],   P2(x) = (3x² − 1) / 2,

(Vallado, *Fundamentals of Astrodynamics and Applications*, 4th ed., Sect. 8.6.1; Montenbruck &
Gill, *Satellite Orbits*, Sect. 3.2), with Re the body's equatorial radius.
"""

from __future__ import annotations

import numpy as np

from workbench.core.bodies import Body

__all__ = ["G0", "gravity_point_mass", "gravity_j2", "gravity_uniform"]

G0 = 9.80665
"""Standard gravity [m/s²] (CGPM 1901), used to convert g's at the I/O edge and for lab frames."""


def gravity_point_mass(r: np.ndarray, gm: float) -> np.ndarray:
    """Point-mass gravity ``−GM r / |r|³`` [m/s²] at position(s) r (..., 3) [m]; ``gm`` in m³/s²."""
    r = np.asarray(r, dtype=float)
    rn = np.linalg.norm(r, axis=-1, keepdims=True)
    return -gm * r / rn**3


def gravity_j2(r_F: np.ndarray, body: Body) -> np.ndarray:
    """Point-mass + J2 gravity [m/s²] in the body-fixed frame at r_F (..., 3) [m].

    ``a = −GM r/r³ − (3/2) J2 GM Re²/r⁵ · [x (1 − 5z²/r²), y (1 − 5z²/r²), z (3 − 5z²/r²)]`` with
    ``Re = body.equatorial_radius`` and ``J2 = body.j2``.  No centrifugal term: in a rotating
    frame add ``−ω × (ω × r)`` yourself.  Also valid in any frame whose +Z is the pole (e.g. the
    inertial frame of date aligned with the body equator).
    """
    r_F = np.asarray(r_F, dtype=float)
    r2 = np.sum(r_F * r_F, axis=-1, keepdims=True)
    rn = np.sqrt(r2)
    z2_r2 = r_F[..., 2:3] ** 2 / r2
    k = 1.5 * body.j2 * body.gm * body.equatorial_radius**2 / rn**5
    factor = np.concatenate([1.0 - 5.0 * z2_r2, 1.0 - 5.0 * z2_r2, 3.0 - 5.0 * z2_r2], axis=-1)
    return -body.gm * r_F / (rn * r2) - k * r_F * factor


def gravity_uniform(
    g: float = G0, up: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 1.0), r: np.ndarray | None = None
) -> np.ndarray:
    """Uniform gravity ``−g · up/|up|`` [m/s²] for a lab frame (default: 1 g along −Z).

    Returns shape (3,), or broadcast to the shape of ``r`` (..., 3) when positions are given so it
    can stand in for the other gravity functions.  For the SPF chamber, ``up`` is +Z (REDLand).
    """
    up = np.asarray(up, dtype=float)
    n = np.linalg.norm(up)
    if n == 0.0:
        raise ValueError("gravity_uniform: 'up' must be a non-zero vector")
    a = -g * up / n
    if r is None:
        return a
    return np.broadcast_to(a, np.asarray(r).shape).copy()
