"""Radar Doppler altimeter (RDA) of a Schiaparelli-like descent module: beam geometry, measurement
models with their error-state Jacobians, exact ray-sphere ranges and the 4-beam plane fit.

Beam geometry (an assumption, documented): the antenna description quotes "one antenna at nadir and three
squinted ~20° symmetrically along azimuth" (Cecchini et al., ESA Antenna Workshop, 2015).  We take

* B0 along −Z_G (the GNC +Z axis points aft, to the back shell, so −Z_G looks at the ground
  under the parachute);
* B1..B3 squinted 20° from −Z_G at azimuths 0°, 120°, 240° measured from +X_G towards +Y_G:
  ``s_n = [sin σ cos a_n, sin σ sin a_n, −cos σ]``.  The 120° spacing is our assumption.

Frames and conventions: ``M`` = MMED inertial, ``G`` = GNC body,
``q_M_G`` Hamilton scalar-last body → inertial, ``C_M_G = quat_to_dcm(q_M_G)`` and
``C_G_M = C_M_Gᵀ`` (the paper's ``C(q)``).  Error state (9,) ``[δv_M, δθ_G, δp_M]`` with
``v_true = v + δv``, ``q_true = q ⊗ exp(δθ)`` (body-frame right perturbation, so
``C_M_G,true ≈ C_M_G (I + [δθ×])``) and ``p_true = p + δp`` — the same linearisation as
AMELIA A.10–A.12 (their ``C(δq) ≈ I − S(δθ)`` left-multiplies ``C_G_M``).

Flat terrain: a sphere of radius ``r_ground`` about the planet centre (AMELIA B.1); the value is
the caller's (the entry problem's site, ``3396000 − 1440 m``).

References: Aboudan et al., "ExoMars 2016 Schiaparelli module trajectory and atmospheric
profiles reconstruction", Space Sci. Rev. 214:97, 2018 — Sect. 7 (plane fit, Table 4),
Appendix B (Eqs. B.1–B.6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.bodies import MARS
from workbench.core.rotation import quat_rotate, quat_to_dcm, skew

__all__ = [
    "AZIMUTHS_DEG",
    "SQUINT_DEG",
    "beam_directions_G",
    "mars_rate_M",
    "slant_range_model",
    "slant_range_sphere",
    "slant_range_surface",
    "velocity_out_model",
    "PlaneFit",
    "plane_fit",
]


#: the documented beam geometry: B1..B3 squinted 20° off −Z_G (Cecchini et al. 2015) at azimuths
#: 0/120/240° from +X_G towards +Y_G (our assumption); the entry schema's ``[radar]`` defaults
SQUINT_DEG = 20.0
AZIMUTHS_DEG = (0.0, 120.0, 240.0)


def beam_directions_G(
    squint_deg: float = SQUINT_DEG, azimuths_deg: tuple[float, float, float] = AZIMUTHS_DEG
) -> np.ndarray:
    """Unit sensing directions of beams B0..B3 in the GNC frame G, shape (4, 3).

    B0 = ``[0, 0, −1]``; B(k+1) = ``[sin σ cos a_k, sin σ sin a_k, −cos σ]`` with σ = ``squint_deg``
    (off −Z_G) and a_k = ``azimuths_deg[k]`` measured from +X_G towards +Y_G.  Degrees only at this
    I/O edge.  The 20° squint follows Cecchini et al. (2015); the 0/120/240° azimuths are our assumption.
    """
    sig = np.deg2rad(float(squint_deg))
    az = np.deg2rad(np.asarray(azimuths_deg, dtype=float))
    if az.shape != (3,):
        raise ValueError(f"beam_directions_G: need three azimuths, got {az.shape}")
    out = np.empty((4, 3))
    out[0] = (0.0, 0.0, -1.0)
    out[1:, 0] = np.sin(sig) * np.cos(az)
    out[1:, 1] = np.sin(sig) * np.sin(az)
    out[1:, 2] = -np.cos(sig)
    return out


def mars_rate_M(rate: float = MARS.rotation_rate) -> np.ndarray:
    """Mars' rotation vector in M, ``[0, 0, ω]`` [rad/s] (+Z_M is the pole; valid over ~300 s)."""
    return np.array([0.0, 0.0, float(rate)])


def slant_range_model(
    p_M: np.ndarray, q_M_G: np.ndarray, s_G: np.ndarray, r_ground: float, *, exact: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Predicted slant range along beam ``s_G`` and its error-state Jacobian (AMELIA B.3/B.4).

    ``p_M`` (..., 3) [m] position in M, ``q_M_G`` (..., 4), ``s_G`` (3,) or (..., 3) unit beam in G,
    ``r_ground`` [m] terrain radius.  With ``b = C_M_G s``, ``p̂ = p/|p|``, ``h = |p| − r_ground``
    and ``z = −p̂·b`` (cosine of the beam to the local vertical "down", B.2):

        y = h / z                                                         (B.3, flat terrain)
        ∂y/∂δv = 0
        ∂y/∂δθ = −(h/z²) p̂ᵀ C_M_G [s×]        (our right body perturbation; equals B.4's
                                                  (h/z²) e_Z N_C_M Cᵀ(q) S(s) since e_Z N_C_M = −p̂ᵀ)
        ∂y/∂δp = p̂ᵀ/z + (h/(z²|p|)) bᵀ (I − p̂p̂ᵀ)

    The last term (the local vertical turning with p, O(h/|p|) ~ 1e-3 of the first) is dropped in
    B.4 ("N_C_M considered constant"); ``exact=False`` reproduces B.4 literally.  Returns
    ``y`` (...,) [m] and ``H`` (..., 1, 9).  ``z ≤ 0`` (beam above the horizon) gives ``y = +inf``
    and a NaN Jacobian row — callers must skip such predictions.
    """
    p = np.asarray(p_M, dtype=float)
    C = quat_to_dcm(q_M_G)
    s = np.asarray(s_G, dtype=float)
    b = np.einsum("...ij,...j->...i", C, s)
    r = np.linalg.norm(p, axis=-1)
    ph = p / r[..., None]
    h = r - float(r_ground)
    z = -np.sum(ph * b, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        y = np.where(z > 0.0, h / z, np.inf)
        zz = np.where(z > 0.0, z, np.nan)
        H = np.zeros((*y.shape, 1, 9))
        # p̂ᵀ C [s×] = (Cᵀ p̂)ᵀ [s×] = −(s × Cᵀp̂)ᵀ ... computed as a row-vector product
        ph_G = np.einsum("...ji,...j->...i", C, ph)  # C_G_M p̂
        row_theta = np.cross(ph_G, s)  # (p̂_G)ᵀ [s×] = (p̂_G × s)ᵀ
        H[..., 0, 3:6] = -(h / zz**2)[..., None] * row_theta
        row_p = ph / zz[..., None]
        if exact:
            b_perp = b - np.sum(b * ph, axis=-1)[..., None] * ph
            row_p = row_p + (h / (zz**2 * r))[..., None] * b_perp
        H[..., 0, 6:9] = row_p
    return y, H


def slant_range_sphere(p_M: np.ndarray, q_M_G: np.ndarray, s_G: np.ndarray, r_ground: float) -> np.ndarray:
    """Exact range [m] from ``p_M`` along beam ``s_G`` (G) to the sphere of radius ``r_ground`` [m].

    Nearest root of ``|p + ρ d|² = r_ground²`` with ``d = C_M_G s``:
    ``ρ = −p·d − √((p·d)² − |p|² + r_ground²)``; **NaN** where the ray misses the sphere or
    points away from it (no ground echo).  ``p_M`` (..., 3) [m] in M, ``q_M_G`` (..., 4), ``s_G``
    (..., 3) unit beam(s), broadcasting: one beam for many states, or e.g. p (n, 1, 3),
    q (n, 1, 4) and four beams (4, 3) for (n, 4) ranges.  Returns the broadcast shape without the
    last axis.  Used to synthesise measurements (truth side) — the flat-plane model B.3
    (:func:`slant_range_model`) is shorter by ≈ (ρ sin α)²/(2 R cos α) for a beam at α off the
    local vertical (0.7 m at ρ = 6.4 km, α = 20°; 5 m at 7.8 km, 40°).
    """
    p = np.asarray(p_M, dtype=float)
    d = quat_rotate(np.asarray(q_M_G, dtype=float), np.asarray(s_G, dtype=float))
    b = np.sum(p * d, axis=-1)
    c = np.sum(p * p, axis=-1) - float(r_ground) ** 2
    disc = b * b - c
    with np.errstate(invalid="ignore"):
        rho = -b - np.sqrt(disc)
    return np.where((disc >= 0.0) & (rho > 0.0), rho, np.nan)


def slant_range_surface(
    p_M: np.ndarray,
    q_M_G: np.ndarray,
    s_G: np.ndarray,
    r_ground: float,
    radius_at,
    iterations: int = 6,
) -> np.ndarray:
    """Range [m] from ``p_M`` along beam ``s_G`` to a star-shaped surface ``|x| = radius_at(x)``.

    ``radius_at(x)`` maps points x (..., 3) [m, M] to the surface radius [m] below them (e.g. the
    sphere ``r_ground`` plus a smooth relief).  Starts from the sphere's range
    (:func:`slant_range_sphere`, same broadcasting) and solves ``g(ρ) = |x| − radius_at(x) = 0``,
    ``x = p + ρ d``, by Newton steps with a 1 m finite-difference derivative (the relief's slope
    included), ``iterations`` times.  NaN where the ray misses the sphere.  For a beam far off the
    local vertical over steep relief the root nearest the sphere's range is returned, which need
    not be the first along the ray (no occlusion test).
    """
    p = np.asarray(p_M, dtype=float)
    d = quat_rotate(np.asarray(q_M_G, dtype=float), np.asarray(s_G, dtype=float))
    rho = slant_range_sphere(p_M, q_M_G, s_G, r_ground)

    def gap(r):
        x = p + r[..., None] * d
        return np.linalg.norm(x, axis=-1) - radius_at(x)

    step = 1.0  # [m] finite-difference step of the derivative
    for _ in range(int(iterations)):
        g0 = gap(rho)
        dg = (gap(rho + step) - g0) / step
        rho = rho - g0 / np.where(np.abs(dg) > 1e-6, dg, -1e-6)
    return np.where(rho > 0.0, rho, np.nan)


def velocity_out_model(
    v_M: np.ndarray, q_M_G: np.ndarray, p_M: np.ndarray, omega_M: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Terrain-relative (co-rotating) velocity in G and its error-state Jacobian (AMELIA B.5/B.6).

    ``y = C_G_M (v − Ω p)`` with ``Ω = [ω_M×]``, ``omega_M`` (3,) [rad/s] Mars' rotation vector in M
    (default :func:`mars_rate_M`).  With ``u_G = y``:

        ∂y/∂δv = C_G_M,   ∂y/∂δθ = [u_G×] = C_G_M [(v − Ωp)×] C_M_G,   ∂y/∂δp = −C_G_M Ω   (B.6)

    (``C_G_M,true ≈ (I − [δθ×]) C_G_M`` for ``q_true = q ⊗ exp(δθ)``).  ``v_M``, ``p_M`` (..., 3)
    [m/s, m], ``q_M_G`` (..., 4); returns ``y`` (..., 3) [m/s] and ``H`` (..., 3, 9).
    """
    w = mars_rate_M() if omega_M is None else np.asarray(omega_M, dtype=float)
    Om = skew(w)
    v = np.asarray(v_M, dtype=float)
    p = np.asarray(p_M, dtype=float)
    CGM = np.swapaxes(quat_to_dcm(q_M_G), -1, -2)
    u_M = v - np.einsum("ij,...j->...i", Om, p)
    y = np.einsum("...ij,...j->...i", CGM, u_M)
    H = np.zeros((*y.shape[:-1], 3, 9))
    H[..., 0:3] = CGM
    H[..., 3:6] = skew(y)
    H[..., 6:9] = -CGM @ Om
    return y, H


@dataclass(frozen=True)
class PlaneFit:
    """Least-squares ground plane from one slant-range packet (AMELIA Sect. 7, Table 4).

    ``h_agl`` [m] distance from the GNC origin to the plane; ``off_vertical`` [rad] angle between
    the plane normal and the GNC Z axis (0 when Z_G is vertical, the module hanging straight);
    ``normal_G`` (3,) unit plane normal in G pointing from the module to the ground;
    ``rms`` [m] RMS orthogonal distance of the beam end points from the plane (0 for 3 points).
    """

    h_agl: float
    off_vertical: float
    normal_G: np.ndarray
    rms: float


def plane_fit(ranges: np.ndarray, beams_G: np.ndarray) -> PlaneFit:
    """Fit a plane to the beam end points ``x_n = r_n s_n`` (G) by orthogonal least squares.

    ``ranges`` (k,) [m] slant ranges, ``beams_G`` (k, 3) unit beam directions (k ≥ 3; invalid
    ranges — non-finite or ≤ 0 — are dropped first).  The plane ``n·x = d`` minimising
    ``Σ (n·x_n − d)²`` with ``|n| = 1`` passes through the centroid with ``n`` the right singular
    vector of the centred points of smallest singular value (total least squares, the fit of the
    orthogonal distances).  ``h_agl = |d|``; ``n`` is oriented so that ``d > 0`` (towards the
    ground); ``off_vertical = arccos(−n_z)``.  Raises ``ValueError`` if fewer than 3 valid beams or
    the points are collinear.
    """
    r = np.asarray(ranges, dtype=float).reshape(-1)
    s = np.asarray(beams_G, dtype=float).reshape(-1, 3)
    if r.shape[0] != s.shape[0]:
        raise ValueError(f"plane_fit: {r.shape[0]} ranges for {s.shape[0]} beams")
    ok = np.isfinite(r) & (r > 0.0)
    if ok.sum() < 3:
        raise ValueError(f"plane_fit: need ≥ 3 valid ranges, got {int(ok.sum())} of {r.shape[0]}")
    x = r[ok, None] * s[ok]
    c = x.mean(axis=0)
    _, sv, vt = np.linalg.svd(x - c)
    if sv[1] <= 1e-9 * max(sv[0], 1.0):
        raise ValueError("plane_fit: the beam end points are collinear")
    n = vt[-1]
    d = float(n @ c)
    if d < 0.0:
        n, d = -n, -d
    resid = (x - c) @ n
    return PlaneFit(
        h_agl=d,
        off_vertical=float(np.arccos(np.clip(-n[2], -1.0, 1.0))),
        normal_G=n,
        rms=float(np.sqrt(np.mean(resid**2))),
    )
