"""The REDLand 19-state drop-test filter model: state, transition, Jacobians, measurement models.

State (19, full) and error state (18), after the REDLand paper ("Algorithm", Eq. 9–19):

=====  ==========  ======================================================  =========
full   error       quantity                                                 frame
=====  ==========  ======================================================  =========
0:3    0:3         p — position of the CM [m]                               SPF (I)
3:6    3:6         v — velocity of the CM [m/s]                             SPF
6:9    6:9         a — non-gravitational acceleration of the CM [m/s²]      SPF
9:13   9:12        q_I_B — attitude quaternion (scalar last) / δθ [rad]     body
13:16  12:15       ω — angular rate [rad/s]                                 body
16:19  15:18       α — angular acceleration [rad/s²]                        body
=====  ==========  ======================================================  =========

Attitude error convention: body-frame small angle, ``q_true = q_est ⊗ exp(δθ)``.

Kinematic mode (REDLand's): ``ṗ = v``, ``v̇ = a + g``, ``ȧ = w_a`` (random walk),
``q̇ = ½ q ⊗ ω``, ``ω̇ = α``, ``α̇ = w_α``. Dynamic mode: until the bungee cut, ``a`` is the test
plan's bungee acceleration plus a random-walk residual (the model's change of bungee force is
predicted, the residual is estimated); at release and at the cut the known force step is applied.

Measurements: a triad at lever arm r senses ``f = C_B_I a + α × r + ω × (ω × r)`` (Eq. 3–8);
the gyro senses ω; optional ranges to fixed points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.rotation import quat_from_rotvec, quat_multiply, quat_normalize, quat_to_dcm, skew

G0 = 9.80665
N_X = 19
N_E = 18
SP, SV, SA, SQ, SW, SAL = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 13), slice(13, 16), slice(16, 19)
EP, EV, EA, ETH, EW, EAL = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15), slice(15, 18)
QUAT_BLOCKS = ((9, 9),)

__all__ = [
    "N_X",
    "N_E",
    "QUAT_BLOCKS",
    "BungeeModel",
    "propagate",
    "process_noise",
    "triad_model",
    "gyro_model",
    "range_model",
    "range_rate_model",
    "pose_covariance",
]


@dataclass(frozen=True)
class BungeeModel:
    """Test-plan bungee for the dynamic mode: anchor [m, SPF], rest length [m], per-bungee
    polynomial coefficients [N/m^k], count, lander mass [kg], attachment [m, body]."""

    anchor_I: np.ndarray
    rest_length: float
    coeffs: tuple[float, ...]
    count: float
    mass: float
    attach_B: np.ndarray

    def accel(self, p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bungee acceleration [m/s², SPF] (3,) at CM position p, attitude q, and ∂a/∂p (3,3)."""
        x = p + quat_to_dcm(q) @ self.attach_B
        d = self.anchor_I - x
        L = float(np.linalg.norm(d))
        u = d / L
        s = L - self.rest_length
        if s <= 0.0:
            return np.zeros(3), np.zeros((3, 3))
        f = sum(c * s ** (k + 1) for k, c in enumerate(self.coeffs))
        fp = sum((k + 1) * c * s**k for k, c in enumerate(self.coeffs))
        k = self.count / self.mass
        # ∂s/∂p = −uᵀ, ∂u/∂p = −(I − u uᵀ)/L
        J = k * (-fp * np.outer(u, u) - f * (np.eye(3) - np.outer(u, u)) / L)
        return k * f * u, J


def propagate(
    x: np.ndarray, dt: float, gravity: np.ndarray, bungee: BungeeModel | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Propagate the full state x (19,) by dt [s]; returns (x_next (19,), F (18,18) error transition).

    ``gravity`` (3,) [m/s², SPF]. With ``bungee`` (dynamic mode) the predicted change of the
    bungee acceleration is added to ``a``. The attitude uses the exact exponential for the
    rotation vector φ = ω dt + ½ α dt²; its error transition is ``exp(−φ)`` (body-frame error).
    """
    p, v, a, q, w, al = x[SP], x[SV], x[SA], x[SQ], x[SW], x[SAL]
    acc = a + gravity
    xn = np.empty(N_X)
    xn[SP] = p + v * dt + 0.5 * acc * dt * dt
    xn[SV] = v + acc * dt
    phi = w * dt + 0.5 * al * dt * dt
    dq = quat_from_rotvec(phi)
    xn[SQ] = quat_normalize(quat_multiply(q, dq))
    xn[SW] = w + al * dt
    xn[SAL] = al
    F = np.eye(N_E)
    i3 = np.eye(3)
    F[EP, EV] = dt * i3
    F[EP, EA] = 0.5 * dt * dt * i3
    F[EV, EA] = dt * i3
    F[ETH, ETH] = quat_to_dcm(dq).T
    F[ETH, EW] = dt * i3
    F[ETH, EAL] = 0.5 * dt * dt * i3
    F[EW, EAL] = dt * i3
    if bungee is not None:
        a0, _ = bungee.accel(p, q)
        a1, J1 = bungee.accel(xn[SP], xn[SQ])
        xn[SA] = a + (a1 - a0)
        # δa⁺ = δa + J(p⁺) δp⁺ − J(p) δp ≈ δa + J (dt δv + ½dt² δa) (attitude dependence neglected)
        F[EA, EV] = J1 * dt
        F[EA, EA] = i3 + 0.5 * dt * dt * J1
    else:
        xn[SA] = a
    return xn, F


def _jerk_block(q: float, dt: float) -> np.ndarray:
    """Discrete process noise of a (pos, vel, acc) chain driven by white jerk of PSD q (3x3)."""
    return q * np.array(
        [[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2], [dt**3 / 6, dt**2 / 2, dt]]
    )


def process_noise(dt: float, q_a: float, q_alpha: float) -> np.ndarray:
    """Q (18,18) for white jerk PSD ``q_a`` [m²/s⁵] per axis and white angular jerk ``q_alpha``
    [rad²/s⁵] per axis, on the (p, v, a) and (θ, ω, α) chains."""
    Q = np.zeros((N_E, N_E))
    Bt = _jerk_block(q_a, dt)
    Br = _jerk_block(q_alpha, dt)
    for i in range(3):
        idx = [0 + i, 3 + i, 6 + i]
        Q[np.ix_(idx, idx)] = Bt
        idx = [9 + i, 12 + i, 15 + i]
        Q[np.ix_(idx, idx)] = Br
    return Q


def triad_model(x: np.ndarray, r_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted specific force (3,) [m/s², body] of a triad at lever arm r_B, and H (3,18)."""
    a, q, w, al = x[SA], x[SQ], x[SW], x[SAL]
    C_B_I = quat_to_dcm(q).T
    aB = C_B_I @ a
    wr = np.cross(w, r_B)
    z = aB + np.cross(al, r_B) + np.cross(w, wr)
    H = np.zeros((3, N_E))
    H[:, EA] = C_B_I
    H[:, ETH] = skew(aB)
    H[:, EW] = -skew(wr) - skew(w) @ skew(r_B)
    H[:, EAL] = -skew(r_B)
    return z, H


def gyro_model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted gyro rate (3,) [rad/s, body] and H (3,18)."""
    H = np.zeros((3, N_E))
    H[:, EW] = np.eye(3)
    return x[SW].copy(), H


def range_model(x: np.ndarray, point_I: np.ndarray, r_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range [m] (1,) from a fixed SPF point to the lander point at lever arm r_B, and H (1,18)."""
    C = quat_to_dcm(x[SQ])
    d = x[SP] + C @ r_B - point_I
    rho = float(np.linalg.norm(d))
    u = d / rho
    H = np.zeros((1, N_E))
    H[0, EP] = u
    H[0, ETH] = -u @ C @ skew(r_B)
    return np.array([rho]), H


def range_rate_model(x: np.ndarray, point_I: np.ndarray, r_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range rate [m/s] (1,) of the lander point r_B seen from a fixed SPF point, and H (1,18)."""
    C = quat_to_dcm(x[SQ])
    d = x[SP] + C @ r_B - point_I
    rho = float(np.linalg.norm(d))
    u = d / rho
    wr_B = np.cross(x[SW], r_B)
    vr = x[SV] + C @ wr_B
    rr = float(u @ vr)
    Pu = (np.eye(3) - np.outer(u, u)) / rho  # ∂u/∂d
    H = np.zeros((1, N_E))
    H[0, EP] = vr @ Pu
    # d depends on δθ through −C[r×]δθ; vr through −C[(ω×r)×]δθ
    H[0, ETH] = (vr @ Pu) @ (-C @ skew(r_B)) + u @ (-C @ skew(wr_B))
    H[0, EV] = u
    H[0, EW] = u @ C @ (-skew(r_B))
    return np.array([rr]), H


def pose_covariance(P: np.ndarray) -> np.ndarray:
    """Pose covariance (..., 6, 6) of [δp (SPF), δθ (body)] from full error covariances (..., 18, 18)."""
    idx = np.r_[0:3, 9:12]
    return P[..., idx[:, None], idx[None, :]]
