"""The REDLand drop-test filter model (the paper's 19 states + augmentations): state, transition,
Jacobians, measurement models.

State (full / error): p [m, SPF] 0:3 / 0:3; v [m/s, SPF] 3:6 / 3:6; a_B non-gravitational
acceleration [m/s², body] 6:9 / 6:9; q_I_B (scalar last) / δθ [rad, body] 9:13 / 9:12; ω [rad/s]
13:16 / 12:15; α [rad/s²] 16:19 / 15:18 (REDLand "Algorithm", Eq. 9–19); then our augmentations:
the gyro error matrix E (scale and misalignment, row-major, 19:28 / 18:27), the gyro bias b_g
(28:31 / 27:30) and each triad's bias b_j (31+3j / 30+3j) — left out, the estimate was
over-confident (docs/tuning/droptest.md, "model.py"). Attitude error: ``q_true = q_est ⊗ exp(δθ)``.

On purpose unlike the paper, ``a`` is carried in the **body** frame: in SPF it couples δa and δθ
in every triad Jacobian and gives the filter spurious heading information; in the body frame the
triad model is linear in it and heading stays unobservable, as in a strapdown INS
(``a_I = C_I_B a_B`` for plots). Kinematic mode: ``ṗ = v``, ``v̇ = C_I_B a_B + g``, ``a_I`` a
random walk, ``q̇ = ½ q ⊗ ω``, ``ω̇ = α``, ``α̇ = w_α``; dynamic mode adds the test plan's bungee
until the cut. A triad at lever arm r senses ``f = a_B + α × r + ω × (ω × r)`` (Eq. 3–8); the gyro
senses ω; optional ranges to fixed points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.rotation import quat_from_rotvec, quat_multiply, quat_normalize, quat_to_dcm, skew

N_X = 31  # core state (without accelerometer biases)
N_E = 30
SP, SV, SA, SQ, SW, SAL = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 13), slice(13, 16), slice(16, 19)
EP, EV, EA, ETH, EW, EAL = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15), slice(15, 18)
SS, ES = slice(19, 28), slice(18, 27)  # gyro error matrix E, row-major (augmentation, see docstring)
GYRO_SCALE_X, GYRO_SCALE_E = np.array([19, 23, 27]), np.array([18, 22, 26])  # diagonal of E: scale factors
SBG, EBG = slice(28, 31), slice(27, 30)  # gyro bias [rad/s]


def bias_slices(j: int) -> tuple[slice, slice]:
    """(full-state, error-state) slices of the accelerometer bias of triad ``j`` (augmentation)."""
    return slice(N_X + 3 * j, N_X + 3 * j + 3), slice(N_E + 3 * j, N_E + 3 * j + 3)


def sizes(n_triads: int) -> tuple[int, int]:
    """(n_x, n_e) of the filter with ``n_triads`` accelerometer bias blocks."""
    return N_X + 3 * n_triads, N_E + 3 * n_triads


QUAT_BLOCKS = ((9, 9),)

#: error-state block -> the scenario setting that sets its prior σ or process noise
ERROR_STATE_KEYS = (
    (EP, "the setup file's [hanging] position_sigma_m"),
    (EV, "[filter] velocity_sigma_mps / hang_zupt_sigma_mps"),
    (EA, "[filter] accel_sigma_mps2 / q_accel"),
    (ETH, "[sensors.attitude_3dm] gravity_sigma_deg / magnetic_sigma_deg"),
    (EW, "[filter] rate_sigma_dps"),
    (EAL, "[filter] angular_accel_sigma / q_angular"),
    (ES, "[sensors.gyro] misalignment_deg"),
    (EBG, "[sensors.gyro] bias_dps"),
)


def error_state_key(c: int) -> str:
    """The scenario setting behind error-state component ``c`` (its prior σ or process noise): the
    gyro error matrix's diagonal is ``[sensors.gyro] scale``, its other entries ``misalignment_deg``;
    components from ``N_E`` on are the triads' ``[sensors.accelerometer] bias_g``."""
    if c >= N_E:
        return "[sensors.accelerometer] bias_g"
    if c in GYRO_SCALE_E:
        return "[sensors.gyro] scale"
    return next(key for sl, key in ERROR_STATE_KEYS if sl.start <= c < sl.stop)


__all__ = [
    "N_X",
    "N_E",
    "QUAT_BLOCKS",
    "ERROR_STATE_KEYS",
    "error_state_key",
    "bias_slices",
    "sizes",
    "BungeeModel",
    "propagate",
    "process_noise",
    "triad_model",
    "triad_specific_force",
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
    """Propagate the full state x (N_X,) by dt [s]; returns (x_next (N_X,), F (N_E, N_E) error transition).

    ``gravity`` (3,) [m/s², SPF]. The attitude uses the exact exponential of the rotation
    vector φ = ω dt + ½ α dt²; the body-frame acceleration turns with the body,
    ``a_B⁺ = exp(φ)ᵀ a_B`` (inertially constant between steps). With ``bungee`` (dynamic mode)
    the test plan's change of bungee acceleration over the step is added (body frame).
    Error convention: ``q_true = q ⊗ exp(δθ)`` ⇒ ``δa_I = C δa_B − C [a_B×] δθ``.
    """
    p, v, aB, q, w, al = x[SP], x[SV], x[SA], x[SQ], x[SW], x[SAL]
    C = quat_to_dcm(q)
    aI = C @ aB
    acc = aI + gravity
    xn = np.array(x, dtype=float)  # gyro scales and accelerometer biases: random constants
    xn[SP] = p + v * dt + 0.5 * acc * dt * dt
    xn[SV] = v + acc * dt
    phi = w * dt + 0.5 * al * dt * dt
    dq = quat_from_rotvec(phi)
    Rt = quat_to_dcm(dq).T
    qn = quat_normalize(quat_multiply(q, dq))
    xn[SQ] = qn
    aBn = Rt @ aB
    xn[SW] = w + al * dt
    xn[SAL] = al
    F = np.eye(x.size - 1)
    i3 = np.eye(3)
    CaX = C @ skew(aB)
    F[EP, EV] = dt * i3
    F[EP, EA] = 0.5 * dt * dt * C
    F[EP, ETH] = -0.5 * dt * dt * CaX
    F[EV, EA] = dt * C
    F[EV, ETH] = -dt * CaX
    Jr = i3 - 0.5 * skew(phi)  # right Jacobian of exp, to second order in |φ|
    F[ETH, ETH] = Rt
    F[ETH, EW] = dt * Jr
    F[ETH, EAL] = 0.5 * dt * dt * Jr
    F[EA, EA] = Rt
    F[EA, EW] = skew(aBn) @ Jr * dt
    F[EA, EAL] = skew(aBn) @ Jr * (0.5 * dt * dt)
    F[EW, EAL] = dt * i3
    if bungee is not None:
        a0, _ = bungee.accel(p, q)
        a1, J1 = bungee.accel(xn[SP], qn)
        Cn_T = quat_to_dcm(qn).T
        aBn = aBn + Cn_T @ (a1 - a0)
        # δ(a1 − a0) ≈ J (dt δv + ½dt² δa_I): attitude dependence of the increment neglected
        F[EA, EV] += Cn_T @ J1 * dt
        F[EA, EA] += Cn_T @ J1 @ C * (0.5 * dt * dt)
    xn[SA] = aBn
    return xn, F


def accel_inertial(x: np.ndarray) -> np.ndarray:
    """Non-gravitational CM acceleration in SPF [m/s²] (..., 3) from full states (..., n_x)."""
    C = quat_to_dcm(x[..., SQ])
    return np.einsum("...ij,...j->...i", C, x[..., SA])


def _jerk_block(q: float, dt: float) -> np.ndarray:
    """Discrete process noise of a (pos, vel, acc) chain driven by white jerk of PSD q (3x3)."""
    return q * np.array(
        [[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2], [dt**3 / 6, dt**2 / 2, dt]]
    )


def process_noise(dt: float, q_a: float, q_alpha: float, C_I_B: np.ndarray, n_e: int = N_E) -> np.ndarray:
    """Q (n_e, n_e) for white jerk PSD ``q_a`` [m²/s⁵] per axis and white angular jerk ``q_alpha``
    [rad²/s⁵] per axis, on the (p, v, a) and (θ, ω, α) chains; ``C_I_B`` (3, 3) the attitude
    (body → SPF) at the end of the step.

    The translational chain mixes frames: δp, δv are SPF, δa is body.  The jerk is white and
    isotropic in SPF (``a_I`` is the random walk, ``a_B = C_I_Bᵀ a_I`` turns with the body), so over
    a step the noise is ``(∭j, ∬j, C_I_Bᵀ ∫j)`` and its cross-covariances with δa_B carry the
    attitude: ``Q_pa = q_a dt³/6 C_I_B``, ``Q_va = q_a dt²/2 C_I_B``, ``Q_aa = q_a dt I``.  (A
    per-axis-index coupling, SPF axis i with body axis i, would make the filter depend on how the
    lander frame is oriented on the body: 22 mm of max stroke, 0.45σ, for the shipped rig rotated;
    and, over 100 dispersed drops, a velocity at max stroke over-confident per axis, mean (δ/σ)²
    1.5 / 3.0 / 4.8, now 1.0 / 0.9 / 1.1.)  The rotational chain is all body frame.
    """
    Q = np.zeros((n_e, n_e))
    Bt = _jerk_block(q_a, dt)
    Br = _jerk_block(q_alpha, dt)
    C = np.asarray(C_I_B, float)
    i3 = np.eye(3)
    trans, rot = (EP, EV, EA), (ETH, EW, EAL)
    for r in range(3):
        for c in range(3):
            # SPF–SPF and body–body blocks are isotropic; SPF (p, v) rows against body (a) columns
            # carry C_I_B, body rows against SPF columns its transpose
            frame = i3 if (r == 2) == (c == 2) else (C if c == 2 else C.T)
            Q[trans[r], trans[c]] = Bt[r, c] * frame
            Q[rot[r], rot[c]] = Br[r, c] * i3
    return Q


def triad_model(x: np.ndarray, r_B: np.ndarray, j: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Predicted specific force (3,) [m/s², body] of triad ``j`` at lever arm r_B, and H (3, n_e).

    ``f = a_B + α × r + ω × (ω × r) + b_j``: linear in a_B and independent of attitude (H_θ = 0);
    ``b_j`` is the triad's bias state when ``j`` is given and the state carries bias blocks.
    """
    w = x[SW]
    Sw, Sr = skew(w), skew(r_B)
    wr = Sw @ r_B
    z = triad_specific_force(x, r_B, j)
    H = np.zeros((3, x.size - 1))
    if j is not None and x.size >= N_X + 3 * (j + 1):
        H[:, bias_slices(j)[1]] = np.eye(3)
    H[:, EA] = np.eye(3)
    H[:, EW] = -skew(wr) - Sw @ Sr
    H[:, EAL] = -Sr
    return z, H


def triad_specific_force(x: np.ndarray, r_B: np.ndarray, j: int | None = None) -> np.ndarray:
    """Predicted specific force (..., 3) [m/s², body] of triad ``j`` at lever arm ``r_B`` (3,) [m,
    body] for states ``x`` (..., n_x), over a whole history at once (the recording's measured-vs-
    predicted plot); :func:`triad_model` adds its Jacobian."""
    x = np.asarray(x, dtype=float)
    r = np.asarray(r_B, dtype=float)
    w = x[..., SW]
    z = x[..., SA] + np.cross(x[..., SAL], r) + np.cross(w, np.cross(w, r))
    if j is not None and x.shape[-1] >= N_X + 3 * (j + 1):
        z = z + x[..., bias_slices(j)[0]]
    return z


def gyro_model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted gyro rate ``(I + E) ω + b_g`` (3,) [rad/s, gyro axes = body] and H (3, n_e)."""
    H = np.zeros((3, x.size - 1))
    w = x[SW]
    E = x[SS].reshape(3, 3)
    H[:, EW] = np.eye(3) + E
    for i in range(3):
        H[i, ES.start + 3 * i : ES.start + 3 * i + 3] = w
    H[:, EBG] = np.eye(3)
    return w + E @ w + x[SBG], H


def range_model(x: np.ndarray, point_I: np.ndarray, r_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range [m] (1,) from a fixed SPF point to the lander point at lever arm r_B, and H (1, n_e)."""
    C = quat_to_dcm(x[SQ])
    d = x[SP] + C @ r_B - point_I
    rho = float(np.linalg.norm(d))
    u = d / rho
    H = np.zeros((1, x.size - 1))
    H[0, EP] = u
    H[0, ETH] = -u @ C @ skew(r_B)
    return np.array([rho]), H


def range_rate_model(x: np.ndarray, point_I: np.ndarray, r_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range rate [m/s] (1,) of the lander point r_B seen from a fixed SPF point, and H (1, n_e)."""
    C = quat_to_dcm(x[SQ])
    d = x[SP] + C @ r_B - point_I
    rho = float(np.linalg.norm(d))
    u = d / rho
    wr_B = np.cross(x[SW], r_B)
    vr = x[SV] + C @ wr_B
    rr = float(u @ vr)
    Pu = (np.eye(3) - np.outer(u, u)) / rho  # ∂u/∂d
    H = np.zeros((1, x.size - 1))
    H[0, EP] = vr @ Pu
    # d depends on δθ through −C[r×]δθ; vr through −C[(ω×r)×]δθ
    H[0, ETH] = (vr @ Pu) @ (-C @ skew(r_B)) + u @ (-C @ skew(wr_B))
    H[0, EV] = u
    H[0, EW] = u @ C @ (-skew(r_B))
    return np.array([rr]), H


def pose_covariance(P: np.ndarray) -> np.ndarray:
    """Pose covariance (..., 6, 6) of [δp (SPF), δθ (body)] from full error covariances (..., N_E, N_E)."""
    idx = np.r_[0:3, 9:12]
    return P[..., idx[:, None], idx[None, :]]
