"""Quaternions, direction-cosine matrices and attitude determination, vectorised over leading axes.

Conventions:

* Quaternions are scalar-last ``[x, y, z, w]`` with the Hamilton product, exactly as
  ``scipy.spatial.transform.Rotation`` and Rerun.  ``q_a_b`` rotates vectors from frame *b* to
  frame *a*: ``v_a = quat_rotate(q_a_b, v_b) = quat_to_dcm(q_a_b) @ v_b``.
* Attitude error is a 3-vector small angle expressed in the **body** frame (right/local
  perturbation): ``q_true = q_est ⊗ exp(δθ)``.  ``attitude_error(q_est, q_true)`` returns δθ.
* JPL/Shuster quaternions (scalar-last, *left-handed* product; ``q̄`` of frame *b* relative to
  *a* has ``C(q̄) = C_b_a``, mapping *a*-vectors into *b*) are converted only at the I/O edge with
  :func:`quat_from_jpl`, which returns the Hamilton ``q_b_a`` (same DCM; the conjugate numbers).
* Euler angles "1-2-3" are the aerospace sequence used by REDLand (Fig. 11): successive body-fixed
  rotations about x, then the new y, then the new z: ``C_N_B = Rx(φ) Ry(θ) Rz(ψ)``.

All angles are radians.  Every function accepts arrays with arbitrary leading shape ``(..., 4)``
or ``(..., 3)`` and broadcasts.

References: [1] Markley & Crassidis, *Fundamentals of Spacecraft Attitude Determination and
Control*, 2014 (Hamilton convention, Ch. 2–3, TRIAD covariance Sect. 5.2.2);
[2] Shuster, "A survey of attitude representations", J. Astronaut. Sci. 41(4), 1993;
[3] Wertz, *Spacecraft Attitude Determination and Control*, 1978, Sect. 12.2 (algebraic method,
cited by the REDLand paper for the 3DM initial attitude).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "skew",
    "quat_normalize",
    "quat_identity",
    "quat_multiply",
    "quat_conjugate",
    "quat_rotate",
    "quat_to_dcm",
    "dcm_components",
    "dcm_to_quat",
    "quat_from_rotvec",
    "quat_to_rotvec",
    "quat_from_axis_angle",
    "attitude_error",
    "quat_boxplus",
    "quat_boxplus_one",
    "attitude_error_one",
    "quat_integrate_body_rate",
    "quat_history_from_body_rates",
    "euler123_from_quat",
    "quat_from_euler123",
    "quat_from_jpl",
    "quat_to_jpl",
    "triad",
    "triad_covariance",
    "quat_positive",
    "quat_x_along",
]


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v×]`` so that ``skew(a) @ b == cross(a, b)``; shape (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    if v.ndim == 1:  # single vector: the filter's hot path (np.stack costs ~10x more here)
        x, y, w = v
        return np.array([[0.0, -w, y], [w, 0.0, -x], [-y, x, 0.0]])
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)


def quat_identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternion(s) ``[0, 0, 0, 1]`` of leading shape ``shape``."""
    q = np.zeros((*shape, 4))
    q[..., 3] = 1.0
    return q


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion(s) in the direction of ``q`` (..., 4); raises on a zero quaternion."""
    q = np.asarray(q, dtype=float)
    n = np.sqrt(q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1] + q[..., 2] * q[..., 2] + q[..., 3] * q[..., 3])
    if np.any(n == 0.0):
        raise ValueError("cannot normalise a zero quaternion")
    return q / n[..., None]


def quat_positive(q: np.ndarray) -> np.ndarray:
    """Same rotation with a non-negative scalar part (picks one of ±q); shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p ⊗ q`` of scalar-last quaternions; ``q_a_c = q_a_b ⊗ q_b_c``."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    px, py, pz, pw = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    parts = (
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
        pw * qw - px * qx - py * qy - pz * qz,
    )
    if p.ndim == 1 and q.ndim == 1:  # one pair: np.array is ~5x cheaper than np.stack
        return np.array(parts, dtype=float)
    return np.stack(parts, axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate ``[-x, -y, -z, w]``; the inverse of a unit quaternion (``q_b_a`` from ``q_a_b``)."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([-q[..., :3], q[..., 3:]], axis=-1)


def quat_to_dcm(q: np.ndarray) -> np.ndarray:
    """DCM ``C_a_b`` (..., 3, 3) of a unit quaternion ``q_a_b`` (..., 4): ``v_a = C_a_b @ v_b``."""
    q = np.asarray(q, dtype=float)
    rows = dcm_components(q[..., 0], q[..., 1], q[..., 2], q[..., 3])
    if q.ndim == 1:  # one quaternion: the filter's hot path (np.stack costs ~10x more here)
        return np.array(rows, dtype=float)
    return np.stack([np.stack(r, -1) for r in rows], -2)


def dcm_components(x, y, z, w):
    """Rows of the DCM ``C_a_b`` of the unit quaternion ``q_a_b = [x, y, z, w]`` given by components.

    The components may be Python floats (hot scalar loops) or arrays of one shape; returns three
    row tuples ``((C00, C01, C02), (C10, C11, C12), (C20, C21, C22))`` of that type.
    :func:`quat_to_dcm` is this, stacked.
    """
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        (1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)),
        (2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)),
        (2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)),
    )


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors: ``v_a = R(q_a_b) v_b``; q (..., 4), v (..., 3), broadcasting."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    u = q[..., :3]
    w = q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def dcm_to_quat(C: np.ndarray) -> np.ndarray:
    """Unit quaternion ``q_a_b`` (..., 4) of a rotation matrix ``C_a_b`` (..., 3, 3).

    Uses Shepperd's method (largest-pivot branch) so it is accurate for every rotation; the
    result has a non-negative scalar part.
    """
    C = np.asarray(C, dtype=float)
    shape = C.shape[:-2]
    C = C.reshape(-1, 3, 3)
    tr = np.trace(C, axis1=-2, axis2=-1)
    d = np.stack([C[:, 0, 0], C[:, 1, 1], C[:, 2, 2], tr], -1)
    k = np.argmax(d, axis=-1)
    q = np.empty((C.shape[0], 4))
    # branch w largest
    m = k == 3
    s = np.sqrt(1.0 + tr[m]) * 2.0
    q[m] = np.stack(
        [
            (C[m, 2, 1] - C[m, 1, 2]) / s,
            (C[m, 0, 2] - C[m, 2, 0]) / s,
            (C[m, 1, 0] - C[m, 0, 1]) / s,
            0.25 * s,
        ],
        -1,
    )
    m = k == 0
    s = np.sqrt(1.0 + C[m, 0, 0] - C[m, 1, 1] - C[m, 2, 2]) * 2.0
    q[m] = np.stack(
        [
            0.25 * s,
            (C[m, 0, 1] + C[m, 1, 0]) / s,
            (C[m, 0, 2] + C[m, 2, 0]) / s,
            (C[m, 2, 1] - C[m, 1, 2]) / s,
        ],
        -1,
    )
    m = k == 1
    s = np.sqrt(1.0 + C[m, 1, 1] - C[m, 0, 0] - C[m, 2, 2]) * 2.0
    q[m] = np.stack(
        [
            (C[m, 0, 1] + C[m, 1, 0]) / s,
            0.25 * s,
            (C[m, 1, 2] + C[m, 2, 1]) / s,
            (C[m, 0, 2] - C[m, 2, 0]) / s,
        ],
        -1,
    )
    m = k == 2
    s = np.sqrt(1.0 + C[m, 2, 2] - C[m, 0, 0] - C[m, 1, 1]) * 2.0
    q[m] = np.stack(
        [
            (C[m, 0, 2] + C[m, 2, 0]) / s,
            (C[m, 1, 2] + C[m, 2, 1]) / s,
            0.25 * s,
            (C[m, 1, 0] - C[m, 0, 1]) / s,
        ],
        -1,
    )
    q = quat_positive(quat_normalize(q))
    return q.reshape(*shape, 4)


def quat_x_along(v: np.ndarray) -> np.ndarray:
    """Unit quaternion ``q_a_b`` (n, 4) of a frame b whose +X points along ``v`` (n, 3) (any length
    but zero), +Y along ẑ × X (horizontal), or x̂ × X where X is within 26° of ±ẑ, +Z completing it:
    e.g. a 3-DOF trajectory drawn at zero angle of attack."""
    v = np.asarray(v, dtype=float)
    x = v / np.maximum(np.linalg.norm(v, axis=-1), 1e-12)[:, None]
    a = np.where((np.abs(x[:, 2]) < 0.9)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    y = np.cross(a, x)
    y /= np.linalg.norm(y, axis=-1)[:, None]
    return dcm_to_quat(np.stack([x, y, np.cross(x, y)], axis=-1))


def quat_from_rotvec(phi: np.ndarray) -> np.ndarray:
    """Quaternion ``exp(φ)`` of a rotation vector φ (..., 3) [rad] (axis × angle), exact for any angle."""
    phi = np.asarray(phi, dtype=float)
    a = np.linalg.norm(phi, axis=-1, keepdims=True)
    half = 0.5 * a
    # sin(a/2)/a with a Taylor series near zero
    small = a < 1e-6
    k = np.where(small, 0.5 - a * a / 48.0, np.sin(half) / np.where(small, 1.0, a))
    return np.concatenate([phi * k, np.cos(half)], axis=-1)


def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vector (..., 3) [rad], angle in [0, π], of a unit quaternion (..., 4)."""
    q = quat_positive(np.asarray(q, dtype=float))
    v = q[..., :3]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    w = q[..., 3:4]
    angle = 2.0 * np.arctan2(s, w)
    small = s < 1e-8
    # angle / s -> 2 / w as s -> 0 (w -> 1 for a unit quaternion)
    k = np.where(small, 2.0 / np.maximum(w, 1e-300), angle / np.where(small, 1.0, s))
    return v * k


def quat_from_axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Quaternion of a rotation by ``angle`` [rad] about unit-normalised ``axis`` (..., 3)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    return quat_from_rotvec(axis * np.asarray(angle, dtype=float)[..., None])


def attitude_error(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Body-frame small-angle error δθ (..., 3) [rad] with ``q_true = q_est ⊗ exp(δθ)``."""
    return quat_to_rotvec(quat_multiply(quat_conjugate(q_est), q_true))


def quat_boxplus(q: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """Apply a body-frame attitude correction ``q ⊗ exp(δθ)``, renormalised; q (..., 4), δθ (..., 3) [rad]."""
    return quat_normalize(quat_multiply(q, quat_from_rotvec(dtheta)))


def quat_integrate_body_rate(q: np.ndarray, omega_B: np.ndarray, dt: float | np.ndarray) -> np.ndarray:
    """Propagate ``q_I_B`` under a constant body rate ω_B [rad/s] for ``dt`` [s]: ``q ⊗ exp(ω dt)``.

    This is the exact solution of ``q̇ = ½ q ⊗ [ω, 0]`` for constant ω (REDLand Eq. 14).
    """
    dt = np.asarray(dt, dtype=float)
    return quat_boxplus(q, np.asarray(omega_B, dtype=float) * dt[..., None] if dt.ndim else omega_B * dt)


def quat_history_from_body_rates(t: np.ndarray, omega_B: np.ndarray) -> np.ndarray:
    """Attitudes ``q_0_B(t_k)`` (n, 4) of the body at the samples t (n,) [s] relative to its attitude
    at ``t[0]`` (the identity), from the body rates ``omega_B`` (n, 3) [rad/s] sampled at t: body-frame
    right products ``q_k = q_(k-1) ⊗ exp(½ (ω_k + ω_(k-1)) Δt)`` (trapezoidal rate), renormalised
    each step.  A rotation of ``v_B`` into the frame at ``t[0]`` is ``quat_to_dcm(q) @ v_B``."""
    t = np.asarray(t, float)
    w = np.asarray(omega_B, float)
    rv = 0.5 * (w[1:] + w[:-1]) * np.diff(t)[:, None]
    steps = quat_from_rotvec(rv)
    q = np.zeros((t.size, 4))
    q[0] = [0.0, 0.0, 0.0, 1.0]
    for i in range(1, t.size):  # a recursion: one cheap product per sample
        q[i] = quat_multiply(q[i - 1], steps[i - 1])
        q[i] /= np.linalg.norm(q[i])
    return q


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def quat_from_euler123(angles: np.ndarray) -> np.ndarray:
    """``q_N_B`` from aerospace 1-2-3 angles (φ, θ, ψ) (..., 3) [rad]: ``C_N_B = Rx(φ) Ry(θ) Rz(ψ)``.

    Equivalent to scipy's intrinsic ``Rotation.from_euler("XYZ", angles)``.
    """
    a = np.asarray(angles, dtype=float)
    C = _rx(a[..., 0]) @ _ry(a[..., 1]) @ _rz(a[..., 2])
    return dcm_to_quat(C)


def euler123_from_quat(q: np.ndarray) -> np.ndarray:
    """Aerospace 1-2-3 angles (φ, θ, ψ) (..., 3) [rad] of ``q_N_B`` (inverse of :func:`quat_from_euler123`).

    θ is in [-π/2, π/2]; at θ = ±π/2 (gimbal lock) ψ is set to 0 and φ absorbs the rotation.
    """
    C = quat_to_dcm(q)
    # C = Rx Ry Rz: C[0,2] = sin θ, C[0,0] = cθ cψ, C[0,1] = -cθ sψ, C[1,2] = -sφ cθ, C[2,2] = cφ cθ
    s_theta = np.clip(C[..., 0, 2], -1.0, 1.0)
    theta = np.arcsin(s_theta)
    lock = np.abs(s_theta) > 1.0 - 1e-12
    phi = np.where(lock, np.arctan2(C[..., 2, 1], C[..., 1, 1]), np.arctan2(-C[..., 1, 2], C[..., 2, 2]))
    psi = np.where(lock, 0.0, np.arctan2(-C[..., 0, 1], C[..., 0, 0]))
    return np.stack([phi, theta, psi], -1)


def quat_from_jpl(q_jpl: np.ndarray) -> np.ndarray:
    """Convert a JPL/Shuster quaternion to the Hamilton quaternion with the same DCM.

    A JPL quaternion ``q̄ = [e sin(θ/2), cos(θ/2)]`` (scalar-last, product ``⊗_JPL``) of frame *b*
    with respect to *a* has ``C(q̄) = (2q4² − 1) I − 2 q4 [q×] + 2 q qᵀ = C_b_a`` (it maps
    *a*-vectors into *b*, a passive rotation by θ; Trawny & Roumeliotis 2005, Eq. 62).  The
    Hamilton quaternion with that DCM is the conjugate ``[-e sin(θ/2), cos(θ/2)]``, i.e. our
    ``q_b_a`` (Sola 2017, "Quaternion kinematics for the error-state Kalman filter", Sect. 3.5).
    Composition is preserved: ``quat_from_jpl(p̄ ⊗_JPL q̄) = quat_from_jpl(p̄) ⊗ quat_from_jpl(q̄)``.

    Example (AMELIA): the JPL quaternion "from MMED to GNC" gives ``q_G_M``; the body-to-inertial
    ``q_M_G`` is its conjugate (numerically the raw JPL components).  Shape (..., 4) -> (..., 4).
    """
    return quat_conjugate(np.asarray(q_jpl, dtype=float))


def quat_to_jpl(q: np.ndarray) -> np.ndarray:
    """Inverse of :func:`quat_from_jpl`: Hamilton ``q_b_a`` -> JPL quaternion of *b* w.r.t. *a* (same DCM)."""
    return quat_conjugate(np.asarray(q, dtype=float))


def triad(u_B: np.ndarray, v_B: np.ndarray, u_N: np.ndarray, v_N: np.ndarray) -> np.ndarray:
    """Algebraic (TRIAD) attitude ``q_N_B`` from two non-parallel vector pairs.

    ``u`` is the more accurate vector (e.g. gravity), ``v`` the secondary one (magnetic field);
    ``*_B`` are measured in the body frame, ``*_N`` known in the reference frame (any length,
    shape (..., 3)).  Wertz Sect. 12.2.2; Markley & Crassidis Eq. (5.45).
    """

    def frame(a, b):
        t1 = a / np.linalg.norm(a, axis=-1, keepdims=True)
        t2 = np.cross(a, b)
        n2 = np.linalg.norm(t2, axis=-1, keepdims=True)
        scale = np.linalg.norm(a, axis=-1, keepdims=True) * np.linalg.norm(b, axis=-1, keepdims=True)
        if np.any(n2 < 1e-9 * scale):
            raise ValueError("TRIAD: the two reference vectors are (nearly) parallel")
        t2 = t2 / n2
        t3 = np.cross(t1, t2)
        return np.stack([t1, t2, t3], -1)  # columns

    M_B = frame(np.asarray(u_B, float), np.asarray(v_B, float))
    M_N = frame(np.asarray(u_N, float), np.asarray(v_N, float))
    C_N_B = M_N @ np.swapaxes(M_B, -1, -2)
    return dcm_to_quat(C_N_B)


def triad_covariance(u_B: np.ndarray, v_B: np.ndarray, sigma_u: float, sigma_v: float) -> np.ndarray:
    """Covariance (3, 3) [rad²] of the TRIAD attitude error δθ (body frame, convention above).

    Measured unit-vector errors are modelled as isotropic small tilts of 1σ ``sigma_u`` and
    ``sigma_v`` [rad] perpendicular to each vector (QUEST measurement model); the reference
    vectors are taken as exact.  Closed form of Shuster & Oh (1981), Markley & Crassidis
    Eq. (5.49), with unit vectors ``b1 = û_B``, ``b2 = v̂_B``:

    ``P = σu² I + |b1×b2|⁻² [ (σv² − σu²) b1 b1ᵀ + σu² (b1·b2)(b1 b2ᵀ + b2 b1ᵀ) ]``

    This is the "a priori covariance of the quaternion mapped from the vectors" of the REDLand
    paper (Error Sources), in small-angle form.
    """
    b1 = np.asarray(u_B, float)
    b2 = np.asarray(v_B, float)
    b1 = b1 / np.linalg.norm(b1)
    b2 = b2 / np.linalg.norm(b2)
    c = np.cross(b1, b2)
    s2 = float(c @ c)
    d = float(b1 @ b2)
    P = (
        sigma_u**2 * np.eye(3)
        + ((sigma_v**2 - sigma_u**2) * np.outer(b1, b1) + sigma_u**2 * d * (np.outer(b1, b2) + np.outer(b2, b1))) / s2
    )
    return 0.5 * (P + P.T)


# ---------------------------------------------------------------------------------------------
# single-quaternion fast paths (a filter recursion calls ⊞ once per measurement; the vectorised
# quat_boxplus / attitude_error cost ~20 µs for one quaternion, these ~2 µs).  Tested equal to them.
# ---------------------------------------------------------------------------------------------


def quat_boxplus_one(q: np.ndarray, d: np.ndarray) -> list[float]:
    """``q ⊗ exp(d)`` renormalised, for one quaternion (4,) and one body small angle (3,) [rad]."""
    qx, qy, qz, qw = q.tolist()
    dx, dy, dz = d.tolist()
    a = math.sqrt(dx * dx + dy * dy + dz * dz)
    k = 0.5 - a * a / 48.0 if a < 1e-6 else math.sin(0.5 * a) / a
    px, py, pz, pw = dx * k, dy * k, dz * k, math.cos(0.5 * a)
    rx = qw * px + qx * pw + qy * pz - qz * py
    ry = qw * py - qx * pz + qy * pw + qz * px
    rz = qw * pz + qx * py - qy * px + qz * pw
    rw = qw * pw - qx * px - qy * py - qz * pz
    n = math.sqrt(rx * rx + ry * ry + rz * rz + rw * rw)
    return [rx / n, ry / n, rz / n, rw / n]


def attitude_error_one(q_ref: np.ndarray, q: np.ndarray) -> list[float]:
    """Body small angle δθ (3,) [rad] with ``q = q_ref ⊗ exp(δθ)``, for single quaternions."""
    ax, ay, az, aw = q_ref.tolist()
    bx, by, bz, bw = q.tolist()
    # conj(a) ⊗ b
    rx = aw * bx - ax * bw - ay * bz + az * by
    ry = aw * by + ax * bz - ay * bw - az * bx
    rz = aw * bz - ax * by + ay * bx - az * bw
    rw = aw * bw + ax * bx + ay * by + az * bz
    if rw < 0.0:
        rx, ry, rz, rw = -rx, -ry, -rz, -rw
    s = math.sqrt(rx * rx + ry * ry + rz * rz)
    k = 2.0 / max(rw, 1e-300) if s < 1e-8 else 2.0 * math.atan2(s, rw) / s
    return [rx * k, ry * k, rz * k]
