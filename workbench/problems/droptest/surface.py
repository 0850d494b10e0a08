"""Impact surfaces: a plane with optional spherical rocks, and the SPF 60° ramp with its rock field.

Provides :class:`Surface` (signed distance, its gradient and the feature hit, vectorised),
:func:`ramp_surface` (the SPF ramp in the SPF chamber frame), :func:`rock_field` (rocks
0.2–0.5 m about 1 m apart), and display meshes :func:`ramp_mesh`, :func:`rock_meshes`.

SPF chamber frame (REDLand paper [1], "Test facility"): "The nail is the origin of the SPF
reference frame. The Z-axis is pointed up, the Y-axis is towards the face of the ramp, and the
X-axis [is the] cross product of Y and Z"; the nail is "approximately 0.3 meters below the
center of the ramp".  The ramp is a 60° inclined plane containing the X direction and rising
toward +Y, so its outward (free-side) unit normal is ``n = (0, -sin 60°, cos 60°)``; "a -60
degree rotation about the SPF X-axis" turns it into the "Mars" frame where the ramp is level.
Rocks: "Lava rocks from 0.2 meters to 0.5 meters ... spaced approximately one meter apart".

Distance model.  The surface is the union of the half-space behind the plane and the rock
spheres.  The signed distance returned is ``min(d_plane, min_i(|x - c_i| - r_i))``.  Outside the
solid (d > 0) this is the exact Euclidean distance to the union.  Inside (d < 0) it is the usual
"min of SDFs" union: minus the penetration depth when one feature is penetrated; inside several
features at once its magnitude is the largest single depth, a lower bound of the true depth.

[1] JPL, REDLand paper on the MER airbag drop tests, sections "Test facility" and "Results".
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import trimesh

ROCK_BLOCK_ELEMENTS = 200_000
"""Point-rock pairs :meth:`Surface.distance` evaluates at once (its (points, rocks, 3) work arrays
stay under ~15 MB; a longer batch of points is done in blocks)."""

__all__ = ["Surface", "ramp_surface", "rock_field", "ramp_mesh", "rock_meshes"]


def _empty3() -> np.ndarray:
    return np.zeros((0, 3))


def _empty() -> np.ndarray:
    return np.zeros(0)


@dataclass(frozen=True, eq=False)
class Surface:
    """A plane plus optional spherical rocks, in one frame (e.g. the SPF chamber frame), SI units.

    Attributes:
        point: a point on the plane (3,) [m].
        normal: unit normal of the plane (3,), pointing to the free side (normalised on init).
        rock_centers: rock sphere centres (r, 3) [m]; the spheres may be partly embedded.
        rock_radii: rock sphere radii (r,) [m].

    ``eq=False``: equality is identity (fields are numpy arrays).
    """

    point: np.ndarray
    normal: np.ndarray
    rock_centers: np.ndarray = field(default_factory=_empty3)
    rock_radii: np.ndarray = field(default_factory=_empty)

    def __post_init__(self) -> None:
        p = np.array(self.point, dtype=float).reshape(3)
        n = np.array(self.normal, dtype=float).reshape(3)
        nn = np.linalg.norm(n)
        if not nn > 0.0:
            raise ValueError("Surface: the plane normal must be non-zero")
        c = np.array(self.rock_centers, dtype=float).reshape(-1, 3)
        r = np.array(self.rock_radii, dtype=float).reshape(-1)
        if c.shape[0] != r.shape[0]:
            raise ValueError(f"Surface: {c.shape[0]} rock centres but {r.shape[0]} radii")
        if np.any(r <= 0.0):
            raise ValueError("Surface: rock radii must be > 0")
        for name, arr in (("point", p), ("normal", n / nn), ("rock_centers", c), ("rock_radii", r)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_rocks(self) -> int:
        """Number of rocks."""
        return int(self.rock_radii.shape[0])

    def tangent_basis(self) -> tuple[np.ndarray, np.ndarray]:
        """In-plane unit vectors ``(t1, t2)`` (3,) each, with ``t1 × t2 = normal``.

        ``t1`` is the frame's X axis projected on the plane (Y if X is nearly normal to it);
        for the SPF ramp ``t1 = +X`` (across the ramp) and ``t2`` points up the slope.
        """
        n = self.normal
        ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        t1 = ref - np.dot(ref, n) * n
        t1 /= np.linalg.norm(t1)
        return t1, np.cross(n, t1)

    def distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance from points to the surface, its gradient, and the closest feature.

        Args:
            points: (..., 3) [m] in the surface's frame.

        Returns:
            ``d`` (...) [m]: ``min(n·(x - p), min_i |x - c_i| - r_i)``, positive on the free side;
            ``grad`` (..., 3): ∂d/∂x, ``n`` for the plane, ``(x - c_i)/|x - c_i|`` for rock i (``n``
            at a rock centre, where it is undefined);
            ``feature`` (...) int: -1 for the plane, i for rock i.  Ties go to the plane.
        """
        x = np.asarray(points, dtype=float)
        block = max(1, ROCK_BLOCK_ELEMENTS // max(self.n_rocks, 1))
        if self.n_rocks and x.ndim > 1 and x.size // 3 > block:
            # point-by-rock arrays in blocks of points: the same numbers, bounded memory
            flat = x.reshape(-1, 3)
            parts = [self.distance(flat[i : i + block]) for i in range(0, flat.shape[0], block)]
            lead = x.shape[:-1]
            return (
                np.concatenate([pt[0] for pt in parts]).reshape(lead),
                np.concatenate([pt[1] for pt in parts]).reshape(x.shape),
                np.concatenate([pt[2] for pt in parts]).reshape(lead),
            )
        d = (x - self.point) @ self.normal
        grad = np.broadcast_to(self.normal, x.shape).copy()
        feature = np.full(d.shape, -1, dtype=int)
        if self.n_rocks == 0:
            return d, grad, feature
        diff = x[..., None, :] - self.rock_centers  # (..., r, 3)
        dist = np.linalg.norm(diff, axis=-1)
        d_rock = dist - self.rock_radii
        k = np.argmin(d_rock, axis=-1)
        d_k = np.take_along_axis(d_rock, k[..., None], -1)[..., 0]
        use = d_k < d
        if np.any(use):
            diff_k = np.take_along_axis(diff, k[..., None, None], -2)[..., 0, :]
            dist_k = np.take_along_axis(dist, k[..., None], -1)[..., 0]
            safe = dist_k > 0.0
            g_rock = np.where(safe[..., None], diff_k / np.where(safe, dist_k, 1.0)[..., None], self.normal)
            d = np.where(use, d_k, d)
            grad = np.where(use[..., None], g_rock, grad)
            feature = np.where(use, k, feature)
        return d, grad, feature


def ramp_normal(angle_deg: float) -> np.ndarray:
    """The ramp's free-side unit normal ``n = (0, −sin a, cos a)`` (3,) in SPF for an inclination of
    ``angle_deg`` [deg] (the plane contains X and rises toward +Y)."""
    a = np.deg2rad(float(angle_deg))
    return np.array([0.0, -np.sin(a), np.cos(a)])


def ramp_surface(
    angle_deg: float,
    nail_depth: float,
    rocks: tuple[np.ndarray, np.ndarray] | None = None,
) -> Surface:
    """The SPF ramp in the SPF chamber frame (origin at the trigger nail, Z up, Y toward the ramp).

    The plane contains the X direction and rises toward +Y at ``angle_deg`` [deg]; its free-side
    unit normal is ``n = (0, -sin a, cos a)`` (:func:`ramp_normal`).  The plane passes through
    ``nail_depth * n`` [m]: the nail (the origin) is ``nail_depth`` behind (below) the ramp surface
    along n when positive, in front of it when negative (any sign: the plane places the ramp).
    ``rocks`` is an optional ``(centers (r, 3) [m], radii (r,) [m])`` pair in the same frame.
    """
    n = ramp_normal(angle_deg)
    if rocks is None:
        return Surface(point=float(nail_depth) * n, normal=n)
    centers, radii = rocks
    return Surface(point=float(nail_depth) * n, normal=n, rock_centers=centers, rock_radii=radii)


def rock_field(
    surface: Surface,
    rng: np.random.Generator,
    extent: tuple[tuple[float, float], tuple[float, float]],
    spacing: float,
    size_range: tuple[float, float] = (0.2, 0.5),
    center_height: float = 0.5,
    jitter: float = 0.2,
) -> Surface:
    """Scatter rocks on the plane of ``surface``; returns a new :class:`Surface` (old rocks kept).

    Rocks sit on a square grid of pitch ``spacing`` [m] (REDLand: "spaced approximately one
    meter apart"), each node jittered uniformly by ± ``jitter * spacing`` in both in-plane
    directions.  ``extent = ((u_min, u_max), (v_min, v_max))`` [m] bounds the grid in the plane
    coordinates ``x = point + u t1 + v t2`` of :meth:`Surface.tangent_basis` (for the ramp: u
    across along X, v up the slope, measured from the foot of the nail on the ramp).

    A rock of size s ~ U(size_range) [m] ("lava rocks from 0.2 to 0.5 m") is a sphere of
    diameter s (radius r = s/2) whose centre is ``center_height * r`` above the plane: with the
    default 0.5 a quarter of its diameter is buried and it stands 0.75 s proud of the ramp
    (``center_height = 0`` buries exactly half the sphere).
    """
    (u0, u1), (v0, v1) = extent
    spacing = float(spacing)
    if not spacing > 0.0:
        raise ValueError("rock_field: spacing must be > 0")
    us = np.arange(u0, u1 + 1e-9, spacing)
    vs = np.arange(v0, v1 + 1e-9, spacing)
    U, V = np.meshgrid(us, vs, indexing="ij")
    m = U.size
    U = U.ravel() + rng.uniform(-jitter, jitter, m) * spacing
    V = V.ravel() + rng.uniform(-jitter, jitter, m) * spacing
    radii = 0.5 * rng.uniform(size_range[0], size_range[1], m)
    t1, t2 = surface.tangent_basis()
    centers = (
        surface.point + U[:, None] * t1 + V[:, None] * t2 + (float(center_height) * radii)[:, None] * surface.normal
    )
    return dataclasses.replace(
        surface,
        rock_centers=np.concatenate([surface.rock_centers, centers]),
        rock_radii=np.concatenate([surface.rock_radii, radii]),
    )


def ramp_mesh(
    surface: Surface, width: float, length_down: float, length_up: float, thickness: float = 0.05
) -> trimesh.Trimesh:
    """Thin slab for display [m]: top face on the plane, ``width`` across (centred on
    ``surface.point``), from ``length_down`` below to ``length_up`` above it along the slope
    (:meth:`Surface.tangent_basis` t2), ``thickness`` behind the plane.  Watertight box mesh."""
    t1, t2 = surface.tangent_basis()
    n = surface.normal
    transform = np.eye(4)
    transform[:3, 0], transform[:3, 1], transform[:3, 2] = t1, t2, n
    centre = surface.point + 0.5 * (float(length_up) - float(length_down)) * t2 - 0.5 * float(thickness) * n
    transform[:3, 3] = centre
    extents = [float(width), float(length_up) + float(length_down), float(thickness)]
    return trimesh.creation.box(extents=extents, transform=transform)


def rock_meshes(surface: Surface, subdivisions: int = 2) -> trimesh.Trimesh:
    """All rocks as one mesh of icospheres [m] for display (empty mesh if there are no rocks)."""
    spheres = []
    for c, r in zip(surface.rock_centers, surface.rock_radii, strict=True):
        s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=float(r))
        s.apply_translation(c)
        spheres.append(s)
    if not spheres:
        return trimesh.Trimesh()
    return trimesh.util.concatenate(spheres)
