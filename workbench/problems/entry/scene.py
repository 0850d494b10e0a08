"""Geometry for drawing an entry and descent: the landing-site frame, terrain, capsule and parachute meshes.

The landing-site frame ``L`` (docs/RECORDING.md: "log geometry relative to a local origin") is East-North-Up
with its origin on the terrain sphere (radius ``r_ground``) below a chosen site; it is fixed to the
planet (body-fixed, co-rotating).  A point of the MMED inertial frame ``M`` at time ``t`` [s from
EIP] maps to ``p_L = C_L_F (C_F_M(t) p_M − o_F)``.  Within ±700 km of the site every coordinate is
< 1e6 m, so float32 (Rerun's storage) keeps ≤ 0.06 m — enough to draw an entry track at km scale
and the descent at metre scale in one scene.

Meshes are ``trimesh.Trimesh`` in the GNC body frame G (+Z towards the back shell, heat shield
forward along −Z).  The 70° sphere-cone is built from the vehicle's diameter and nose radius.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from workbench.core.bodies import Body
from workbench.core.frames import C_bodyfixed_mmed, C_enu_bodyfixed, planetocentric_from_cartesian
from workbench.core.rotation import dcm_to_quat, quat_multiply

__all__ = ["LandingSiteFrame", "site_frame_below", "terrain_patch", "capsule_meshes", "parachute_mesh"]


@dataclass(frozen=True)
class LandingSiteFrame:
    """East-North-Up frame on the terrain sphere at planetocentric (lat, lon) [rad]; see module doc.

    ``jd_tdb0`` is the Julian date (TDB) of t = 0 (EIP); ``r_ground`` [m] the terrain radius.
    """

    body: Body
    lat: float
    lon: float
    r_ground: float
    jd_tdb0: float

    @property
    def C_L_F(self) -> np.ndarray:
        """DCM (3, 3) from the body-fixed frame F to L (rows E, N, U in F)."""
        return C_enu_bodyfixed(self.lat, self.lon)

    @property
    def origin_F(self) -> np.ndarray:
        """Origin of L in F [m], (3,)."""
        return self.r_ground * self.C_L_F[2]

    def C_L_M(self, t: np.ndarray) -> np.ndarray:
        """DCM(s) (..., 3, 3) from MMED to L at times ``t`` [s from EIP]."""
        jd = self.jd_tdb0 + np.asarray(t, dtype=float) / 86400.0
        return self.C_L_F @ C_bodyfixed_mmed(self.body, jd)

    def points(self, t: np.ndarray, p_M: np.ndarray) -> np.ndarray:
        """Positions p_M (n, 3) [m, MMED] at times t (n,) -> (n, 3) [m] in L."""
        C = self.C_L_M(t)
        return np.einsum("nij,nj->ni", C, np.asarray(p_M, float)) - (self.C_L_F @ self.origin_F)

    def vectors(self, t: np.ndarray, v_M: np.ndarray) -> np.ndarray:
        """Free vectors (n, 3) from MMED axes to L axes (no origin shift, no ω×r)."""
        return np.einsum("nij,nj->ni", self.C_L_M(t), np.asarray(v_M, float))

    def covariances(self, t: np.ndarray, P_M: np.ndarray) -> np.ndarray:
        """3x3 covariances (n, 3, 3) from MMED axes to L axes."""
        C = self.C_L_M(t)
        return C @ np.asarray(P_M, float) @ np.swapaxes(C, -1, -2)

    def attitudes(self, t: np.ndarray, q_M_G: np.ndarray) -> np.ndarray:
        """``q_L_G`` (n, 4) from ``q_M_G`` (n, 4): the body attitude in the landing-site frame."""
        return quat_multiply(dcm_to_quat(self.C_L_M(t)), np.asarray(q_M_G, float))

    def ground_point_L(self, p_L: np.ndarray) -> np.ndarray:
        """Points (n, 3) on the terrain sphere radially below p_L (n, 3) [m, L]."""
        c = np.array([0.0, 0.0, -self.r_ground])  # planet centre in L
        d = np.asarray(p_L, float) - c
        return c + self.r_ground * d / np.linalg.norm(d, axis=-1, keepdims=True)

    def ray_to_ground(self, origin_L: np.ndarray, dir_L: np.ndarray, max_range: float = 2.0e5) -> np.ndarray:
        """First intersection (n, 3) of rays origin + s·dir (dir unit, (n, 3)) with the terrain sphere.

        Rays that miss (or hit beyond ``max_range`` m) end at ``max_range`` along ``dir``.
        """
        c = np.array([0.0, 0.0, -self.r_ground])
        o = np.asarray(origin_L, float) - c
        d = np.asarray(dir_L, float)
        b = np.einsum("ni,ni->n", o, d)
        cc = np.einsum("ni,ni->n", o, o) - self.r_ground**2
        disc = b * b - cc
        s = -b - np.sqrt(np.maximum(disc, 0.0))
        s = np.where((disc > 0) & (s > 0) & (s < max_range), s, max_range)
        return np.asarray(origin_L, float) + s[:, None] * d


def site_frame_below(body: Body, p_M: np.ndarray, t: float, r_ground: float, jd_tdb0: float) -> LandingSiteFrame:
    """The landing-site frame on the terrain sphere radially below the MMED position ``p_M`` (3,) at ``t``."""
    r_F = C_bodyfixed_mmed(body, jd_tdb0 + t / 86400.0) @ np.asarray(p_M, float)
    lat, lon, _ = planetocentric_from_cartesian(r_F)
    return LandingSiteFrame(body, float(lat), float(lon), float(r_ground), float(jd_tdb0))


def terrain_patch(site: LandingSiteFrame, x_range: tuple[float, float], y_range: tuple[float, float], n: int = 60):
    """The terrain sphere over an East/North rectangle [m] of L as a curved grid mesh (trimesh).

    Heights follow the sphere (at 600 km from the site the surface is ~53 km below the tangent plane).
    """
    x = np.linspace(*x_range, n)
    y = np.linspace(*y_range, n)
    X, Y = np.meshgrid(x, y)
    R = site.r_ground
    Z = np.sqrt(np.maximum(R**2 - X**2 - Y**2, 0.0)) - R
    V = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    faces = np.concatenate([np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])])
    return trimesh.Trimesh(vertices=V, faces=faces, process=False)


def _revolve(profile_rz: np.ndarray, sections: int = 48) -> trimesh.Trimesh:
    """Surface of revolution about +Z of a profile of (radius, z) points [m]."""
    return trimesh.creation.revolve(np.asarray(profile_rz, float), sections=sections)


def capsule_meshes(diameter: float, nose_radius: float, half_angle_deg: float = 70.0) -> dict[str, trimesh.Trimesh]:
    """Front shield (70° sphere-cone, facing −Z) and back shell meshes in the body frame G [m].

    The CoG (origin) is placed 0.25 D behind the nose.  Returns ``{"front_shield", "back_shell"}``.
    """
    rb = 0.5 * diameter
    th = np.radians(half_angle_deg)
    z_nose = -0.25 * diameter
    # sphere cap to the tangency point with the cone, then the cone to the base radius
    a = np.linspace(0.0, 0.5 * np.pi - th, 12)
    cap = np.column_stack([nose_radius * np.sin(a), z_nose + nose_radius * (1.0 - np.cos(a))])
    r_t, z_t = cap[-1]
    z_base = z_t + (rb - r_t) / np.tan(th)
    fs = np.vstack([cap, [[rb, z_base], [rb * 0.98, z_base + 0.03], [0.0, z_base + 0.03]]])
    fs[0, 0] = 0.0
    # back shell: a 47° cone to a flat top
    h_bs = 0.9 * rb
    bs = np.array([[0.0, z_base + 0.03], [rb * 0.97, z_base + 0.03], [0.42 * rb, z_base + h_bs], [0.0, z_base + h_bs]])
    return {"front_shield": _revolve(fs), "back_shell": _revolve(bs)}


def parachute_mesh(diameter: float, distance: float) -> trimesh.Trimesh:
    """Disk-gap-band canopy (an open dome of nominal ``diameter`` [m]) centred ``distance`` [m] along +Z."""
    r = 0.5 * diameter * 0.7  # inflated projected radius ≈ 0.7 of the nominal radius
    a = np.linspace(0.05, 0.5 * np.pi, 10)
    dome = np.column_stack([r * np.sin(a)[::-1], distance + 0.5 * r * np.cos(a)[::-1]])
    dome = np.vstack([[[0.0, distance + 0.5 * r]], dome])
    return _revolve(dome, sections=24)
