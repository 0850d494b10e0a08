"""Gravity models: point mass, point mass + J2 zonal term, and uniform lab gravity.

All functions are vectorised over leading axes ``(..., 3)`` and return accelerations [m/s²] in the
frame of their input position.  The J2 model must be evaluated in the body-fixed frame F (its
+Z axis is the pole); it is the gradient of

    U(r) = GM / r · [1 − J2 (Re / r)² P2(z / r)],   P2(x) = (3x² − 1) / 2,

(Vallado, *Fundamentals of Astrodynamics and Applications*, 4th ed., Sect. 8.6.1; Montenbruck &
Gill, *Satellite Orbits*, Sect. 3.2), with Re the body's equatorial radius.
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.bodies import G0, Body

__all__ = [
    "G0",
    "gravity_point_mass",
    "gravity_point_mass_gradient",
    "j2_factor",
    "gravity_j2",
    "gravity_j2_xyz",
    "gravity_uniform",
]

_I3 = np.eye(3)


def gravity_point_mass(r: np.ndarray, gm: float) -> np.ndarray:
    """Point-mass gravity ``−GM r / |r|³`` [m/s²] at position(s) r (..., 3) [m]; ``gm`` in m³/s²."""
    r = np.asarray(r, dtype=float)
    rn = np.linalg.norm(r, axis=-1, keepdims=True)
    return -gm * r / rn**3


def gravity_point_mass_gradient(r: np.ndarray, gm: float) -> np.ndarray:
    """Point-mass gravity gradient ``∂g/∂r = GM/r³ (3 r̂ r̂ᵀ − I)`` [1/s²]; r (..., 3) [m] -> (..., 3, 3).

    ``gm`` in m³/s².  The J2 term changes it by ~J2 (0.2 % for Mars), which error dynamics neglect.
    """
    p = np.asarray(r, dtype=float)
    r2 = p[..., 0] * p[..., 0] + p[..., 1] * p[..., 1] + p[..., 2] * p[..., 2]
    k = gm / (r2 * np.sqrt(r2))
    outer = p[..., :, None] * p[..., None, :]
    return (3.0 * k / r2)[..., None, None] * outer - k[..., None, None] * _I3


def j2_factor(body: Body) -> float:
    """The J2 acceleration factor ``(3/2) J2 GM Re²`` [m⁵/s²] of ``body`` (Re its equatorial radius)."""
    return 1.5 * body.j2 * body.gm * body.equatorial_radius**2


def gravity_j2(r_F: np.ndarray, body: Body) -> np.ndarray:
    """Point-mass + J2 gravity [m/s²] in the body-fixed frame at r_F (..., 3) [m] -> (..., 3).

    ``a = −GM r/r³ − (3/2) J2 GM Re²/r⁵ · [x (1 − 5z²/r²), y (1 − 5z²/r²), z (3 − 5z²/r²)]`` with
    ``Re = body.equatorial_radius`` and ``J2 = body.j2``.  No centrifugal term: in a rotating
    frame add ``−ω × (ω × r)`` yourself.  Also valid in any frame whose +Z is the pole (e.g. the
    inertial frame of date aligned with the body equator, or Mars' MMED frame).
    :func:`gravity_j2_xyz` is the same model by components (it differs by rounding only, ≲ 1e-15).
    """
    r_F = np.asarray(r_F, dtype=float)
    r2 = np.sum(r_F * r_F, axis=-1, keepdims=True)
    rn = np.sqrt(r2)
    z2_r2 = r_F[..., 2:3] ** 2 / r2
    k = 1.5 * body.j2 * body.gm * body.equatorial_radius**2 / rn**5
    factor = np.concatenate([1.0 - 5.0 * z2_r2, 1.0 - 5.0 * z2_r2, 3.0 - 5.0 * z2_r2], axis=-1)
    return -body.gm * r_F / (rn * r2) - k * r_F * factor


def gravity_j2_xyz(x, y, z, gm: float, j2k: float) -> tuple:
    """:func:`gravity_j2` by components, for hot loops: Python floats, or arrays of one shape.

    x, y, z [m] in a frame whose +Z is the pole; ``gm`` [m³/s²]; ``j2k`` = :func:`j2_factor` of
    the body [m⁵/s²].  Returns ``(g_x, g_y, g_z, r)``: the acceleration components [m/s²] and
    ``|r|`` [m] (callers need it for the altitude), each of the type of the inputs.  The same
    operations are done for floats and arrays, so a member of an array call equals the scalar call
    to the last bit (the strapdown relies on that).
    """
    r2 = x * x + y * y + z * z
    r = math.sqrt(r2) if isinstance(r2, float) else np.sqrt(r2)
    gm_r3 = gm / (r2 * r)
    z2 = 5.0 * (z * z) / r2
    k = j2k / (r2 * r2 * r)
    a = gm_r3 + k * (1.0 - z2)
    return -a * x, -a * y, -(gm_r3 + k * (3.0 - z2)) * z, r


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
