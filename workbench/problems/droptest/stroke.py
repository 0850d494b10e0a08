"""Airbag stroke: distance from the surface to the rigid lander, its 1σ, the max-stroke event,
and the coefficient of restitution.

REDLand paper [1], "Results": stroke is "the distance from the surface to the closest point on the
lander at that instant and the 1σ uncertainty of that measurement", the point of closest approach
the maximum stroke event (requirement: known within 10 cm, 3σ); "full stroke" is the rigid lander
reaching the surface; restitution "the ratio of velocity after the impact to the velocity before
the impact in the surface normal direction". The distance is exact for the plane (a vertex
minimum) and for rock spheres with ``faces_B`` (closest point on every triangle); its linearised
1σ is ``sqrt(J P_pose Jᵀ)`` over the pose error ``[δp_I, δθ]`` (body-frame δθ,
``q_true = q_est ⊗ exp(δθ)``), checked by posterior sampling where two body points tie
(:func:`sampled_stroke_sigma`). Restitution's primary definition is ``−max v_n / min v_n`` over the
impact, from the first touch to the rebound's apex; the spread of the equivalent readings is its
definition σ (:func:`restitution_definitions`). The derivations: docs/tuning/droptest.md, "stroke.py".

Provides :class:`StrokeHistory`, :func:`stroke_history`, :func:`sampled_stroke_sigma`,
:class:`MaxStroke`, :func:`max_stroke`, :func:`restitution`, :func:`contact_interval`,
:func:`restitution_definitions`.

[1] JPL, REDLand paper on the MER airbag drop tests, "Results" and Fig. 13.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from workbench.core.bodies import G0
from workbench.core.rotation import quat_boxplus, quat_to_dcm
from workbench.problems.droptest.surface import Surface

#: (pose, rock) pairs × body faces examined at once by the exact rock check (bounds its temporaries)
_PAIR_FACE_CHUNK = 65536
#: poses examined at once by :func:`stroke_history`
_POSE_CHUNK = 4096

__all__ = [
    "StrokeHistory",
    "stroke_history",
    "sampled_stroke_sigma",
    "MaxStroke",
    "max_stroke",
    "restitution",
    "contact_interval",
    "contact_end",
    "restitution_definitions",
    "RestitutionDefinitions",
    "RESTITUTION_THRESHOLDS_G",
]

#: contact-detection thresholds [g] of the alternative ("ends") restitution definitions
RESTITUTION_THRESHOLDS_G: tuple[float, ...] = (0.25, 0.5, 1.0)


@dataclass(frozen=True, eq=False)
class StrokeHistory:
    """Stroke (surface-to-rigid-body distance) per step, with its linearised 1σ.

    Attributes:
        distance: (n,) [m] signed distance from the surface to the closest point of the rigid
            body mesh; negative = penetration (full stroke).
        sigma: (n,) [m] linearised 1σ of ``distance`` (module docstring).
        vertex: (n,) int, the body vertex where the minimum is attained; when a rock's closest
            point lies inside a face/edge, the vertex of that face nearest to it.
        closest_point_I: (n, 3) [m] closest body point, chamber frame.
        surface_point_I: (n, 3) [m] its foot on the surface, ``x − d ∇φ`` (chamber frame).
        feature: (n,) int, -1 = plane, i = rock i.
        jacobian: (n, 6) ∂d/∂[δp_I (m), δθ_B (rad)] [m/m, m/rad].
    """

    distance: np.ndarray
    sigma: np.ndarray
    vertex: np.ndarray
    closest_point_I: np.ndarray
    surface_point_I: np.ndarray
    feature: np.ndarray
    jacobian: np.ndarray


@dataclass(frozen=True, eq=False)
class MaxStroke:
    """The maximum-stroke event = the step of closest approach of the rigid body to the surface.

    Attributes:
        index: step index; time: its time [s].
        distance: [m] closest approach (negative = penetration); sigma: its 1σ [m].
        vertex: body vertex index; faces: indices (k,) of the body faces that touch that vertex.
        point_I: (3,) [m] closest body point, chamber frame.
        full_stroke: ``distance <= 0`` (the rigid lander reached the surface).
        possible_full_stroke: ``distance − 3σ <= 0`` (full stroke not excluded at 3σ).
    """

    index: int
    time: float
    distance: float
    sigma: float
    vertex: int
    faces: np.ndarray
    point_I: np.ndarray
    full_stroke: bool
    possible_full_stroke: bool


# --------------------------------------------------------------------------- core geometry


def _check_convex(vertices_B: np.ndarray, faces_B: np.ndarray) -> None:
    tri = vertices_B[faces_B]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    h = np.einsum("fj,vfj->vf", nrm, vertices_B[:, None, :] - tri[None, :, 0])
    scale = np.ptp(vertices_B, axis=0).max()
    if np.any(h > 1e-9 * scale):
        raise ValueError("stroke: the exact rock check needs a convex body with outward face winding")


def _closest_approach(
    vertices_B: np.ndarray,
    faces_B: np.ndarray | None,
    p_I: np.ndarray,
    C_I_B: np.ndarray,
    surface: Surface,
) -> tuple[np.ndarray, ...]:
    """Closest approach for m poses: returns d (m,), grad (m,3), r_B (m,3), x_I (m,3), vertex, feature."""
    V = vertices_B
    m = p_I.shape[0]
    rows = np.arange(m)
    X = p_I[:, None, :] + np.einsum("mij,vj->mvi", C_I_B, V)  # (m, v, 3)
    # plane: the minimum of a linear function over a polyhedron is at a vertex (exact)
    d_v = (X - surface.point) @ surface.normal  # (m, v)
    k = np.argmin(d_v, axis=1)
    d = d_v[rows, k]
    grad = np.tile(surface.normal, (m, 1))
    feature = np.full(m, -1, dtype=int)
    vertex = k.copy()
    r_B = V[k].copy()
    x_I = X[rows, k].copy()
    if surface.n_rocks == 0:
        return d, grad, r_B, x_I, vertex, feature

    # rocks: only (pose, rock) pairs whose bounding-sphere lower bound |c - p| - R_body - r can
    # beat the plane are examined (|c - p|² expanded so no (m, r, 3) array is formed)
    c = surface.rock_centers
    rr = surface.rock_radii
    R_body = np.linalg.norm(V, axis=1).max()
    dist2 = np.sum(c * c, axis=1)[None, :] - 2.0 * p_I @ c.T + np.sum(p_I * p_I, axis=1)[:, None]
    lower = np.sqrt(np.maximum(dist2, 0.0)) - R_body - rr
    mi, ri = np.nonzero(lower < d[:, None] + 1e-9)
    if mi.size == 0:
        return d, grad, r_B, x_I, vertex, feature
    K = np.arange(mi.size)
    if faces_B is None:
        # vertex-only rock check: an upper bound of dist(c, body) - r
        diff = X[mi] - c[ri][:, None, :]  # (K, v, 3)
        dist_v = np.linalg.norm(diff, axis=-1)
        kv = np.argmin(dist_v, axis=1)
        dist = dist_v[K, kv]
        d_pair = dist - rr[ri]
        ok = dist > 0.0
        g_pair = np.where(ok[:, None], diff[K, kv] / np.where(ok, dist, 1.0)[:, None], surface.normal)
        q_pair_B = V[kv]
        vert_pair = kv
    else:
        # exact: closest point of every triangle to the rock centre, in the body frame
        c_B = np.einsum("kji,kj->ki", C_I_B[mi], c[ri] - p_I[mi])  # (K, 3)
        tri = V[faces_B]  # (f, 3, 3)
        nf = tri.shape[0]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
        q_pair_B = np.empty((mi.size, 3))
        dist = np.empty(mi.size)
        jf = np.empty(mi.size, dtype=int)
        sign = np.empty(mi.size)
        # pairs in chunks of ~_PAIR_FACE_CHUNK (pair, face) rows: the (K·f, 3, 3) temporaries of the
        # closest-point search stay a few MB however many poses approach a rock (same numbers)
        step = max(1, _PAIR_FACE_CHUNK // nf)
        for a in range(0, mi.size, step):
            cb = c_B[a : a + step]
            kk = np.arange(cb.shape[0])
            q = trimesh.triangles.closest_point(np.tile(tri, (cb.shape[0], 1, 1)), np.repeat(cb, nf, axis=0))
            q = q.reshape(cb.shape[0], nf, 3)
            dist_f = np.linalg.norm(q - cb[:, None, :], axis=-1)  # (k, f)
            j = np.argmin(dist_f, axis=1)
            jf[a : a + step] = j
            q_pair_B[a : a + step] = q[kk, j]
            dist[a : a + step] = dist_f[kk, j]
            # inside test (convex body): the centre is behind every face plane
            h = np.einsum("fj,kfj->kf", nrm, cb[:, None, :] - tri[None, :, 0])
            sign[a : a + step] = np.where(np.all(h < 0.0, axis=1), -1.0, 1.0)
        d_pair = sign * dist - rr[ri]
        # gradient of the distance wrt the body point: sign * unit(q - c), in B then in I
        ok = dist > 0.0
        u_B = np.where(ok[:, None], (q_pair_B - c_B) / np.where(ok, dist, 1.0)[:, None], nrm[jf])
        g_pair = np.einsum("kij,kj->ki", C_I_B[mi], sign[:, None] * u_B)
        # report the vertex of the closest face nearest to the closest point
        fv = faces_B[jf]  # (K, 3)
        near = np.argmin(np.linalg.norm(V[fv] - q_pair_B[:, None, :], axis=-1), axis=1)
        vert_pair = fv[K, near]
    # best candidate pair per pose, kept where it beats the plane
    order = np.lexsort((d_pair, mi))
    first = np.ones(order.size, dtype=bool)
    first[1:] = mi[order][1:] != mi[order][:-1]
    best = order[first]
    best = best[d_pair[best] < d[mi[best]]]
    steps = mi[best]
    if steps.size:
        d[steps] = d_pair[best]
        grad[steps] = g_pair[best]
        r_B[steps] = q_pair_B[best]
        x_I[steps] = p_I[steps] + np.einsum("mij,mj->mi", C_I_B[steps], q_pair_B[best])
        feature[steps] = ri[best]
        vertex[steps] = vert_pair[best]
    return d, grad, r_B, x_I, vertex, feature


def _prepare(vertices_B, p_I, q_I_B, faces_B):
    V = np.asarray(vertices_B, dtype=float).reshape(-1, 3)
    p = np.asarray(p_I, dtype=float)
    q = np.asarray(q_I_B, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or q.shape != (p.shape[0], 4):
        raise ValueError(f"stroke: need p_I (n, 3) and q_I_B (n, 4), got {p.shape} and {q.shape}")
    F = None
    if faces_B is not None:
        F = np.asarray(faces_B, dtype=int).reshape(-1, 3)
        _check_convex(V, F)
    return V, p, q, F


def stroke_history(
    vertices_B: np.ndarray,
    p_I: np.ndarray,
    q_I_B: np.ndarray,
    P_pose: np.ndarray,
    surface: Surface,
    faces_B: np.ndarray | None = None,
) -> StrokeHistory:
    """Distance from the surface to the rigid body at every step, with its linearised 1σ.

    Args:
        vertices_B: (v, 3) [m] body mesh vertices in the body frame (origin at the CM).
        p_I: (n, 3) [m] CM position in the chamber frame I (the surface's frame).
        q_I_B: (n, 4) unit quaternions body -> I, scalar-last Hamilton.
        P_pose: (n, 6, 6) covariance of ``[δp_I [m], δθ [rad]]``, δθ a BODY-frame small angle with
            ``q_true = q_est ⊗ exp(δθ)``.
        surface: the impact :class:`Surface` in frame I.
        faces_B: optional (f, 3) int triangles of the (convex) body; when given, rocks are checked
            against faces and edges too (exact), otherwise at the vertices only.

    Returns:
        :class:`StrokeHistory`; ``jacobian = [∇φᵀ, −∇φᵀ C_I_B [r_B×]]`` and
        ``sigma = sqrt(J P Jᵀ)`` (derivation in the module docstring).
    """
    V, p, q, F = _prepare(vertices_B, p_I, q_I_B, faces_B)
    P = np.asarray(P_pose, dtype=float)
    if P.shape != (p.shape[0], 6, 6):
        raise ValueError(f"stroke_history: P_pose must be ({p.shape[0]}, 6, 6), got {P.shape}")
    C = quat_to_dcm(q)
    # poses in chunks: every quantity is per pose, so the (m, v, 3) and (m, rocks) temporaries stay
    # bounded for long histories without changing a number
    parts = [
        _closest_approach(V, F, p[a : a + _POSE_CHUNK], C[a : a + _POSE_CHUNK], surface)
        for a in range(0, max(p.shape[0], 1), _POSE_CHUNK)
    ]
    d, grad, r_B, x_I, vertex, feature = (np.concatenate(c) for c in zip(*parts, strict=True))
    a_B = np.einsum("nji,nj->ni", C, grad)  # C_I_Bᵀ ∇φ
    J = np.concatenate([grad, np.cross(r_B, a_B)], axis=1)
    var = np.einsum("ni,nij,nj->n", J, P, J)
    return StrokeHistory(
        distance=d,
        sigma=np.sqrt(np.maximum(var, 0.0)),
        vertex=vertex,
        closest_point_I=x_I,
        surface_point_I=x_I - d[:, None] * grad,
        feature=feature,
        jacobian=J,
    )


def _sqrt_psd(P: np.ndarray) -> np.ndarray:
    """Matrix square roots L (..., 6, 6) with L Lᵀ = P for symmetric PSD P (eigen-decomposition)."""
    w, U = np.linalg.eigh(0.5 * (P + np.swapaxes(P, -1, -2)))
    return U * np.sqrt(np.maximum(w, 0.0))[..., None, :]


def sampled_stroke_sigma(
    vertices_B: np.ndarray,
    p_I: np.ndarray,
    q_I_B: np.ndarray,
    P_pose: np.ndarray,
    surface: Surface,
    n_samples: int,
    rng: np.random.Generator,
    faces_B: np.ndarray | None = None,
    steps: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Monte Carlo mean and 1σ of the stroke distance: the check of :func:`stroke_history`'s σ.

    Draws ``n_samples`` pose errors ``[δp_I, δθ] ~ N(0, P_pose)`` per step (same convention as
    :func:`stroke_history`: ``p = p_I + δp_I``, ``q = q_I_B ⊗ exp(δθ)``), computes the exact
    minimum distance for each sample (same geometry as :func:`stroke_history`), and returns
    ``(mean (k,) [m], std (k,) [m], ddof=1)`` for the selected ``steps`` (index array, default
    all n steps).  Samples are drawn in chunks of bounded memory from ``rng``.
    """
    V, p, q, F = _prepare(vertices_B, p_I, q_I_B, faces_B)
    P = np.asarray(P_pose, dtype=float)
    idx = np.arange(p.shape[0]) if steps is None else np.asarray(steps, dtype=int).reshape(-1)
    p, q, P = p[idx], q[idx], P[idx]
    k = idx.size
    n_samples = int(n_samples)
    if n_samples < 2:
        raise ValueError("sampled_stroke_sigma: need n_samples >= 2")
    L = _sqrt_psd(P)  # (k, 6, 6)
    chunk = max(1, int(1_000_000 // max(1, k * (V.shape[0] + surface.n_rocks))))
    done = 0
    all_d = []
    while done < n_samples:
        s = min(chunk, n_samples - done)
        z = rng.standard_normal((s, k, 6))
        e = np.einsum("kij,skj->ski", L, z)
        ps = (p[None] + e[..., :3]).reshape(-1, 3)
        qs = quat_boxplus(np.broadcast_to(q[None], (s, k, 4)), e[..., 3:]).reshape(-1, 4)
        d = _closest_approach(V, F, ps, quat_to_dcm(qs), surface)[0].reshape(s, k)
        all_d.append(d)
        done += s
    d = np.concatenate(all_d, axis=0)
    return d.mean(axis=0), d.std(axis=0, ddof=1)


def max_stroke(t: np.ndarray, history: StrokeHistory, body_mesh: trimesh.Trimesh) -> MaxStroke:
    """The maximum-stroke (closest-approach) event of a :class:`StrokeHistory`.

    Args:
        t: (n,) [s] step times; history: from :func:`stroke_history` (NaN distances ignored);
        body_mesh: the body mesh whose vertex indices ``history.vertex`` refers to.
    """
    t = np.asarray(t, dtype=float)
    if t.shape != history.distance.shape:
        raise ValueError(f"max_stroke: t {t.shape} and history {history.distance.shape} differ in length")
    i = int(np.nanargmin(history.distance))
    v = int(history.vertex[i])
    faces = np.nonzero(np.any(np.asarray(body_mesh.faces) == v, axis=1))[0]
    d = float(history.distance[i])
    s = float(history.sigma[i])
    return MaxStroke(
        index=i,
        time=float(t[i]),
        distance=d,
        sigma=s,
        vertex=v,
        faces=faces,
        point_I=np.array(history.closest_point_I[i]),
        full_stroke=bool(d <= 0.0),
        possible_full_stroke=bool(d - 3.0 * s <= 0.0),
    )


def restitution(
    t: np.ndarray,
    v_I: np.ndarray,
    P_v: np.ndarray,
    normal: np.ndarray,
    contact_start_idx: int,
    contact_end_idx: int,
    P_cross: np.ndarray | None = None,
) -> tuple[float, float]:
    """Coefficient of restitution along the surface normal and its first-order 1σ.

    ``e = −v_n(after) / v_n(before)`` with ``v_n = n·v_I`` (n the unit surface normal toward the
    free side; ``v_n(before) < 0`` when approaching), before = ``contact_start_idx``, after =
    ``contact_end_idx``.  With ``a = v_n(after)``, ``b = v_n(before)``:
    ``∂e/∂v_after = −n/b``, ``∂e/∂v_before = (a/b²) n`` and

        σ_e² = nᵀP_after n / b² + a² nᵀP_before n / b⁴ − 2 (a/b³) nᵀ P_cross n.

    By default ``P_cross = 0``: the two epochs' velocity errors are treated as independent.  In
    a filter/smoother they are positively correlated (``δv_after = δv_before + ∫δa dt``), and
    since ``a > 0 > b`` at a bounce the omitted term ``−2(a/b³) nᵀP_cross n`` is positive: the
    independent σ_e is then optimistic (too small).  Pass ``P_cross = E[δv_before δv_afterᵀ]``
    (3, 3) [m²/s²] to include it.

    Args:
        t: (n,) [s] times (checked for length and order of the two epochs).
        v_I: (n, 3) [m/s] CM velocity in the surface's frame; P_v: (n, 3, 3) its covariance.
        normal: (3,) surface normal (normalised here).

    Returns ``(e, sigma_e)`` (dimensionless).  Raises ``ValueError`` if ``v_n(before) >= 0``.
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(v_I, dtype=float)
    P = np.asarray(P_v, dtype=float)
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    i0, i1 = int(contact_start_idx), int(contact_end_idx)
    if v.shape != (t.shape[0], 3) or P.shape != (t.shape[0], 3, 3):
        raise ValueError(f"restitution: need v_I (n,3), P_v (n,3,3) with n={t.shape[0]}")
    if not t[i0] < t[i1]:
        raise ValueError("restitution: the contact end must come after the contact start")
    b = float(n @ v[i0])
    a = float(n @ v[i1])
    if not b < 0.0:
        raise ValueError(f"restitution: normal velocity before contact is {b} m/s, not approaching")
    e = -a / b
    var = (n @ P[i1] @ n) / b**2 + a**2 * (n @ P[i0] @ n) / b**4
    if P_cross is not None:
        var += -2.0 * (a / b**3) * float(n @ np.asarray(P_cross, dtype=float) @ n)
    return e, float(np.sqrt(max(var, 0.0)))


def contact_interval(
    t: np.ndarray, a: np.ndarray, after: float, threshold: float, merge_s: float = 0.01
) -> tuple[int, int]:
    """First contact interval: first and last step index after ``after`` [s] where the norm of the
    non-gravitational acceleration ``a`` (n, 3) [m/s², any frame] exceeds ``threshold`` [m/s²],
    bridging dips shorter than ``merge_s`` [s] (noise).  A later separate touch-down (a second
    bounce) is a new contact and not part of it.  ``(-1, -1)`` if there is none."""
    t = np.asarray(t, dtype=float)
    busy = (np.linalg.norm(np.asarray(a, dtype=float), axis=1) > threshold) & (t > after)
    if not busy.any():
        return -1, -1
    idx = np.flatnonzero(busy)
    i0 = int(idx[0])
    i1 = i0
    for j in idx[1:]:
        if t[j] - t[i1] > merge_s:
            break
        i1 = int(j)
    return i0, i1


def contact_end(t: np.ndarray, contact: tuple[int, int], leaving: int) -> float | None:
    """The end [s] of the contact the restitution is defined over, on the step times ``t`` (n,):
    the later of the detected contact's last step ``contact[1]`` and the step ``leaving`` where the
    restitution's leaving velocity is read (a bag pushing again as the lander rolls off extends
    it); -1 for either: none.  None when neither exists."""
    k = max(int(contact[1]), int(leaving))
    return None if k < 0 else float(t[k])


@dataclass(frozen=True)
class RestitutionDefinitions:
    """The coefficient of restitution of one history by each equivalent definition.

    ``values``: name → e [-] (NaN when that definition finds no rebound): ``"extremes"`` (the
    primary one) and ``"ends_<thr>g"`` per contact threshold; ``i_before`` / ``i_after`` the step
    indices of the primary definition's two velocities (min and max of ``v_n``; -1 if none);
    ``spread`` the largest |value − primary| over the other finite values (NaN if none).
    """

    values: dict
    i_before: int
    i_after: int
    spread: float

    @property
    def primary(self) -> float:
        """e by the primary definition (extremes of the normal velocity) [-]."""
        return float(self.values["extremes"])


def restitution_definitions(
    t: np.ndarray,
    v_I: np.ndarray,
    a_I: np.ndarray,
    normal: np.ndarray,
    after: float,
    thresholds_g: tuple[float, ...] = RESTITUTION_THRESHOLDS_G,
    pad_s: float = 0.05,
    gravity: np.ndarray | None = None,
) -> RestitutionDefinitions:
    """The coefficient of restitution by each equivalent definition (module docstring), on one history.

    Args:
        t: (n,) [s]; v_I: (n, 3) [m/s] CM velocity; a_I: (n, 3) [m/s²] non-gravitational
            acceleration (any frame: only its norm is used); normal: (3,) ramp normal toward the
            free side (v_I's frame); after: [s] contact is searched after this time (the cut).
        thresholds_g: contact thresholds [g = 9.80665 m/s²]: ``"ends_<thr>g"`` is
            ``−v_n(j1+1)/v_n(j0−1)``, j0 and j1 the first and last samples of the impact above the
            threshold; a reading whose ends are not within ``pad_s`` of the extremes (a glancing first
            touch or a last push above or below the threshold) is not a reading of the same instants
            and gives NaN.
        pad_s: the impact starts this long [s] before the lowest threshold's onset.
        gravity: (3,) [m/s²] gravity in v_I's frame; when given, ``"touch_leave"`` extrapolates
            ``v_n`` from the lowest threshold's crossings to the instants the bags touch and leave:
            the bag force is taken to rise linearly from zero (rise time = the time between the
            crossings of the two lowest thresholds), so over that time ``v_n`` changes by
            ``(a_thr/2 − g_n) Δt`` with ``g_n`` = −gravity·n.

    The impact is the rebound, not an interval of the load: it starts ``pad_s`` before the load
    first exceeds the lowest threshold and lasts until ``v_n`` (positive once the lander leaves)
    is back to zero in free flight (load below the lowest threshold) at the rebound's apex, or the
    data end.  A dip of the load while the lander
    still approaches (a glancing first touch, then the main strike) and a bag that pushes again
    while it already leaves (the lander rolling onto the next face) are parts of it; a touch-down
    after the apex is a new contact.  Primary, ``"extremes"``: ``e = −max v_n / min v_n``, the
    minimum of ``v_n`` before it first turns positive and the maximum after that, up to the apex.
    These are instants where the bag's normal force equals the normal component of gravity; being
    stationary points of ``v_n``, they make ``e`` insensitive to the timing of contact detection.
    Every definition is NaN without a rebound (``v_n`` never positive after the onset) and where an
    extreme is not a stationary point: the minimum at the window's first sample (``v_n`` still
    falling there: the ``after`` time inside the impact) or the maximum at the last sample with no
    apex (``v_n`` still rising where the data end), or a non-finite ``v_n``.
    """
    t = np.asarray(t, dtype=float)
    a_I = np.asarray(a_I, dtype=float)
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    vn = np.asarray(v_I, dtype=float) @ n
    an = np.linalg.norm(a_I, axis=1)
    idx = np.arange(t.size)
    thr_sorted = sorted(thresholds_g)
    vals: dict[str, float] = {"extremes": np.nan}
    for thr in thresholds_g:
        vals[f"ends_{thr:g}g"] = np.nan
    nan = RestitutionDefinitions(values=vals, i_before=-1, i_after=-1, spread=np.nan)
    i0, _ = contact_interval(t, a_I, after, thr_sorted[0] * G0)
    if i0 <= 0:
        return nan
    rising = np.flatnonzero((idx > i0) & (vn > 0.0))
    if not rising.size:
        return nan
    r = int(rising[0])
    start = int(np.flatnonzero((t >= t[i0] - pad_s) & (t > after))[0])
    kmin = start + int(np.argmin(vn[start:r]))
    if not vn[kmin] < 0.0 or kmin == start:
        return nan  # not approaching at the onset, or still falling where the window starts: no minimum
    # the apex: v_n back at zero in free flight (a lander rocking onto the next face under load
    # can dip to zero and push off again)
    back = np.flatnonzero((idx > r) & (vn <= 0.0) & (an <= thr_sorted[0] * G0))
    end = int(back[0]) if back.size else t.size
    kmax = r + int(np.argmax(vn[r:end]))
    if not back.size and kmax == t.size - 1:
        return nan  # still rising where the data end: the leaving velocity is not in the data
    e = float(-vn[kmax] / vn[kmin])
    if not np.isfinite(e):
        return nan
    vals["extremes"] = e

    def ends(thr: float) -> tuple[int, int] | None:
        """First and last samples above ``thr`` [g] within the impact, when they bracket the extremes."""
        above = np.flatnonzero((idx >= start) & (idx < end) & (t > after) & (an > thr * G0))
        if not above.size or above[0] == 0 or above[-1] + 1 >= t.size:
            return None
        j0, j1 = int(above[0]), int(above[-1])
        if abs(t[j0] - t[kmin]) > pad_s or abs(t[j1 + 1] - t[kmax]) > pad_s:
            return None
        return j0, j1

    brackets = {thr: ends(thr) for thr in thresholds_g}
    for thr, jj in brackets.items():
        if jj is not None and vn[jj[0] - 1] < 0.0 < vn[jj[1] + 1]:
            vals[f"ends_{thr:g}g"] = float(-vn[jj[1] + 1] / vn[jj[0] - 1])
    lo2 = [brackets.get(thr) for thr in thr_sorted[:2]]
    if gravity is not None and len(lo2) == 2 and all(jj is not None for jj in lo2):
        g_n = -float(np.asarray(gravity, dtype=float) @ n)  # > 0: gravity pulls toward the ramp
        a_lo = thr_sorted[0] * G0
        (j0, j1), (k0, k1) = lo2
        frac = thr_sorted[0] / (thr_sorted[1] - thr_sorted[0])
        dt_in = max(0.0, float(t[k0] - t[j0])) * frac
        dt_out = max(0.0, float(t[j1] - t[k1])) * frac
        v_touch = vn[j0 - 1] - (0.5 * a_lo - g_n) * dt_in
        v_leave = vn[j1 + 1] + (0.5 * a_lo - g_n) * dt_out
        vals["touch_leave"] = float(-v_leave / v_touch) if v_touch < 0.0 < v_leave else np.nan
    alt = np.array([v for k, v in vals.items() if k != "extremes" and np.isfinite(v)])
    spread = float(np.max(np.abs(alt - vals["extremes"]))) if alt.size else np.nan
    return RestitutionDefinitions(values=vals, i_before=kmin, i_after=kmax, spread=spread)
