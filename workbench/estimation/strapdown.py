"""Strapdown integration of an entry vehicle's IMU with first-order covariance (AMELIA Appendix A).

State (AMELIA Eq. A.1, our conventions, docs/ARCHITECTURE.md): inertial velocity ``v_M`` [m/s],
attitude ``q_M_G`` (body G → inertial M, Hamilton scalar-last; ``C_G_M = quat_to_dcm(q_M_G).T`` is
the paper's ``C(q)``) and inertial position ``p_M`` [m], all in a planet-centred inertial frame M
whose +Z is the pole (Mars: MMED), so :func:`workbench.core.gravity.gravity_j2` applies directly.
The planet is a parameter: every function that needs gravity takes ``body`` (a
:class:`~workbench.core.bodies.Body`; GM, J2 and the equatorial radius are used).  It defaults to
Mars, the planet of the existing callers.

Equations of motion (Eq. A.2), inputs the body specific force ``f_G`` [m/s²] (non-gravitational
acceleration) and body rate ``w_G`` [rad/s]::

    dv/dt = g_M(p) + C_M_G f_G,     dq/dt = ½ q ⊗ [w_G, 0],     dp/dt = v

integrated with the classical RK4 (:func:`rk4_step`): the inputs are taken linear between the two
IMU samples (the mid-point stage uses their mean) and the quaternion is renormalised after each step.

Error state (9) ``δx = [δv_M (0:3), δθ_G (3:6), δp_M (6:9)]`` with ``v_true = v + δv``,
``p_true = p + δp`` and the body-frame right perturbation ``q_true = q ⊗ exp(δθ)`` (our version of
Eq. A.10-A.12, which perturbs on the other side).  Error dynamics (our Eq. A.14)::

    d(δv)/dt = −C_M_G S(f_G) δθ + G(p) δp + C_M_G ε_a
    d(δθ)/dt = −S(w_G) δθ + ε_ω
    d(δp)/dt = δv

with ``S`` the cross-product matrix and ``G(p) = GM/r³ (3 p̂ p̂ᵀ − I)`` the point-mass gravity
gradient (the paper neglects it; it is cheap and included when a position is given).  Input noise
``ε = [ε_ω, ε_a]`` (B columns in that order, as the paper) is white with spectral densities
``σ² · sample_dt`` from the per-sample σ of the rate and acceleration samples taken every
``sample_dt`` seconds.  Covariance (Eq. A.15) is propagated in discrete form (:func:`covariance_step`).

Data gaps (AMELIA Sect. 5, :func:`apply_gap`) are bridged with the on-board solution's velocity,
position and attitude changes across the gap (:class:`GapBridge`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import expm

from workbench.core.bodies import Body
from workbench.core.gravity import gravity_j2_xyz, gravity_point_mass_gradient, j2_factor
from workbench.core.rotation import dcm_to_quat, quat_multiply, quat_normalize, quat_to_dcm, skew
from workbench.estimation.strapdown_kernel import transition_step

__all__ = [
    "GAP_SIGMA_DEFAULT",
    "GapBridge",
    "ImuArrays",
    "imu_arrays",
    "imu_columns",
    "rotate",
    "StrapdownPass",
    "derivatives",
    "rk4_step",
    "error_dynamics",
    "covariance_step",
    "gap_transition",
    "apply_gap",
    "integrate",
    "integrate_members",
]

#: Default added noise across a data gap: per-second 1σ growth of (velocity [m/s per s],
#: attitude [rad per s], position [m per s]).  The added standard deviation grows *linearly* with
#: the gap length Δt (σ_added = gap_sigma · Δt), modelling the drift of the on-board solution that
#: bridges the gap.  Sized from AMELIA Sect. 5 (their integration differed from the on-board
#: solution by up to 7.5 m/s, 530 m and < 0.01° over the entry): 0.1 m/s/s, 2e-6 rad/s (≈ 0.0065°
#: over the 57 s gap) and 5 m/s give 5.7 m/s, 0.0065° and 290 m across the longest gap.
GAP_SIGMA_DEFAULT: tuple[float, float, float] = (0.1, 2.0e-6, 5.0)

_I3 = np.eye(3)
_I9 = np.eye(9)


# ---------------------------------------------------------------------------------------------
# small component-wise helpers (vectorised over leading axes, cheap for a single vector)


def _stack(parts: list | tuple) -> np.ndarray:
    """Stack components along a new last axis; ``np.array`` for scalars (5x cheaper than ``np.stack``)."""
    if np.ndim(parts[0]) == 0 and all(np.ndim(c) == 0 for c in parts):
        return np.array(parts, dtype=float)
    return np.stack(np.broadcast_arrays(*parts), -1)


def rotate(q: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``C(q) x`` [units of x] for q (..., 4) (scalar-last Hamilton) and x (..., 3), broadcasting;
    in component form, so also defined (scaled as the component formula scales) for a non-unit q."""
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    X, Y, Z = x[..., 0], x[..., 1], x[..., 2]
    tx = 2.0 * (qy * Z - qz * Y)
    ty = 2.0 * (qz * X - qx * Z)
    tz = 2.0 * (qx * Y - qy * X)
    return _stack(
        (X + qw * tx + (qy * tz - qz * ty), Y + qw * ty + (qz * tx - qx * tz), Z + qw * tz + (qx * ty - qy * tx))
    )


def _qdot(q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``½ q ⊗ [w, 0]`` (Hamilton, scalar-last): the quaternion rate of ``q_M_G`` under body rate w."""
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    a, b, c = w[..., 0], w[..., 1], w[..., 2]
    return 0.5 * _stack(
        (qw * a + qy * c - qz * b, qw * b - qx * c + qz * a, qw * c + qx * b - qy * a, -(qx * a + qy * b + qz * c))
    )


# ---------------------------------------------------------------------------------------------
# equations of motion


def derivatives(
    v: np.ndarray, q: np.ndarray, p: np.ndarray, f_G: np.ndarray, w_G: np.ndarray, body: Body
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-hand side of AMELIA Eq. A.2: ``(dv/dt, dq/dt, dp/dt)``.

    v_M (..., 3) [m/s], q_M_G (..., 4), p_M (..., 3) [m]; f_G (..., 3) [m/s²] and w_G (..., 3)
    [rad/s] broadcast against the state (e.g. one IMU sample (3,) for all members (m, 3)).
    Gravity: point mass + J2 of ``body`` (:func:`~workbench.core.gravity.gravity_j2_xyz`, the
    component form, so that the vectorised and the single-state RK4 agree to the last bit).
    Returns ``g_M(p) + C_M_G f_G`` (..., 3), ``½ q ⊗ [w_G, 0]`` (..., 4), ``v`` (..., 3).
    """
    p = np.asarray(p, dtype=float)
    g = gravity_j2_xyz(p[..., 0], p[..., 1], p[..., 2], body.gm, j2_factor(body))
    return _stack(g[:3]) + rotate(q, f_G), _qdot(q, w_G), v


def rk4_step(
    v: np.ndarray,
    q: np.ndarray,
    p: np.ndarray,
    f0: np.ndarray,
    w0: np.ndarray,
    f1: np.ndarray,
    w1: np.ndarray,
    dt: float,
    body: Body,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One classical RK4 step of Eq. A.2 over ``dt`` [s] from the state (v_M, q_M_G, p_M).

    The inputs are linear between the samples (f0, w0) at the start and (f1, w1) at the end
    (shapes as :func:`derivatives`); the two mid-point stages use their mean.  The quaternion is
    renormalised at the end.  Vectorised over leading axes (members).  ``body`` gives the gravity
    (:func:`derivatives`).  Returns (v, q, p).
    """
    if v.ndim == 1 and q.ndim == 1 and p.ndim == 1 and np.ndim(f0) == 1 and np.ndim(f1) == 1:
        return _rk4_scalar(v, q, p, f0, w0, f1, w1, float(dt), body.gm, j2_factor(body))
    fm = 0.5 * (f0 + f1)
    wm = 0.5 * (w0 + w1)
    h = 0.5 * dt
    k1v, k1q, k1p = derivatives(v, q, p, f0, w0, body)
    k2v, k2q, k2p = derivatives(v + h * k1v, q + h * k1q, p + h * k1p, fm, wm, body)
    k3v, k3q, k3p = derivatives(v + h * k2v, q + h * k2q, p + h * k2p, fm, wm, body)
    k4v, k4q, k4p = derivatives(v + dt * k3v, q + dt * k3q, p + dt * k3p, f1, w1, body)
    s = dt / 6.0
    v1 = v + s * (k1v + 2.0 * (k2v + k3v) + k4v)
    q1 = q + s * (k1q + 2.0 * (k2q + k3q) + k4q)
    p1 = p + s * (k1p + 2.0 * (k2p + k3p) + k4p)
    return v1, quat_normalize(q1), p1


def _deriv_scalar(v, q, p, f, w, gm, j2k):
    """:func:`derivatives` on Python floats (tuples) — same operations in the same order."""
    gx, gy, gz, _ = gravity_j2_xyz(p[0], p[1], p[2], gm, j2k)
    qx, qy, qz, qw = q
    X, Y, Z = f
    tx = 2.0 * (qy * Z - qz * Y)
    ty = 2.0 * (qz * X - qx * Z)
    tz = 2.0 * (qx * Y - qy * X)
    dv = (
        gx + (X + qw * tx + (qy * tz - qz * ty)),
        gy + (Y + qw * ty + (qz * tx - qx * tz)),
        gz + (Z + qw * tz + (qx * ty - qy * tx)),
    )
    wa, wb, wc = w
    dq = (
        0.5 * (qw * wa + qy * wc - qz * wb),
        0.5 * (qw * wb - qx * wc + qz * wa),
        0.5 * (qw * wc + qx * wb - qy * wa),
        0.5 * -(qx * wa + qy * wb + qz * wc),
    )
    return dv, dq, v


def _rk4_scalar(v, q, p, f0, w0, f1, w1, dt, gm, j2k):
    """:func:`rk4_step` for one state with Python floats (the filter's hot path, ~6x cheaper)."""
    v, q, p = v.tolist(), q.tolist(), p.tolist()
    f0, w0, f1, w1 = f0.tolist(), w0.tolist(), f1.tolist(), w1.tolist()
    fm = [0.5 * (a + b) for a, b in zip(f0, f1, strict=True)]
    wm = [0.5 * (a + b) for a, b in zip(w0, w1, strict=True)]
    h = 0.5 * dt

    def add(x, c, d):
        return [a + c * b for a, b in zip(x, d, strict=True)]

    k1v, k1q, k1p = _deriv_scalar(v, q, p, f0, w0, gm, j2k)
    k2v, k2q, k2p = _deriv_scalar(add(v, h, k1v), add(q, h, k1q), add(p, h, k1p), fm, wm, gm, j2k)
    k3v, k3q, k3p = _deriv_scalar(add(v, h, k2v), add(q, h, k2q), add(p, h, k2p), fm, wm, gm, j2k)
    k4v, k4q, k4p = _deriv_scalar(add(v, dt, k3v), add(q, dt, k3q), add(p, dt, k3p), f1, w1, gm, j2k)
    s = dt / 6.0

    def comb(x, a, b, c, d):
        return [x0 + s * (a0 + 2.0 * (b0 + c0) + d0) for x0, a0, b0, c0, d0 in zip(x, a, b, c, d, strict=True)]

    v1 = comb(v, k1v, k2v, k3v, k4v)
    q1 = comb(q, k1q, k2q, k3q, k4q)
    p1 = comb(p, k1p, k2p, k3p, k4p)
    nq = math.sqrt(q1[0] * q1[0] + q1[1] * q1[1] + q1[2] * q1[2] + q1[3] * q1[3])
    return np.array(v1), np.array([c / nq for c in q1]), np.array(p1)


# ---------------------------------------------------------------------------------------------
# error dynamics and covariance


def error_dynamics(
    q_M_G: np.ndarray, f_G: np.ndarray, w_G: np.ndarray, p_M: np.ndarray | None = None, *, body: Body
) -> tuple[np.ndarray, np.ndarray]:
    """Continuous error dynamics ``d(δx)/dt = A δx + B ε`` (our AMELIA Eq. A.14, module docstring).

    q_M_G (..., 4), f_G (..., 3) [m/s²], w_G (..., 3) [rad/s]; ``p_M`` (..., 3) [m] adds the
    point-mass gravity gradient ``G(p)`` of ``body`` in ``A[0:3, 6:9]`` (None: omitted, as the paper).
    Returns A (..., 9, 9) over ``[δv_M, δθ_G, δp_M]`` and B (..., 9, 6) over ``[ε_ω, ε_a]``
    (``B[3:6, 0:3] = I``, ``B[0:3, 3:6] = C_M_G``).
    """
    q = np.asarray(q_M_G, dtype=float)
    C = quat_to_dcm(q)
    A = _a_matrix(C, np.asarray(f_G, dtype=float), np.asarray(w_G, dtype=float), p_M, body.gm)
    B = np.zeros((*A.shape[:-2], 9, 6))
    B[..., 3:6, 0:3] = _I3
    B[..., 0:3, 3:6] = C
    return A, B


def _a_matrix(C: np.ndarray, f: np.ndarray, w: np.ndarray, p: np.ndarray | None, gm: float) -> np.ndarray:
    shape = np.broadcast_shapes(C.shape[:-2], f.shape[:-1], w.shape[:-1])
    A = np.zeros((*shape, 9, 9))
    A[..., 0:3, 3:6] = -C @ skew(f)
    A[..., 3:6, 3:6] = -skew(w)
    A[..., 6:9, 0:3] = _I3
    if p is not None:
        A[..., 0:3, 6:9] = gravity_point_mass_gradient(p, gm)
    return A


def covariance_step(
    P: np.ndarray,
    q: np.ndarray,
    f: np.ndarray,
    w: np.ndarray,
    dt: float,
    sigma_w: np.ndarray | float,
    sigma_f: np.ndarray | float,
    sample_dt: float,
    Q_state_psd: np.ndarray | None = None,
    p: np.ndarray | None = None,
    *,
    body: Body,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete first-order covariance step (AMELIA Eq. A.15) over ``dt`` [s]: ``P⁺ = Φ P Φᵀ + Qd``.

    ``q`` (4,), ``f``, ``w`` (3,) [m/s², rad/s] and optional ``p`` (3,) [m] (gravity gradient) are
    the attitude, inputs and position at the **middle** of the step (:func:`integrate` passes the
    normalised mean of the two attitudes and the means of the two samples), so that
    ``Φ = expm(A dt)`` is second-order accurate in dt (first Magnus term; scipy's expm of a 9x9
    costs ~8 µs, about the price of a truncated series).
    Input noise: per-sample 1σ ``sigma_w`` [rad/s], ``sigma_f`` [m/s²] (scalar or (3,)) of samples
    taken every ``sample_dt`` [s] give the spectral densities ``σ² sample_dt``; with
    ``Qc = B diag(psd_ω, psd_a) Bᵀ + diag(Q_state_psd)`` (state noise η, (9,) in units²/s)::

        Qd = Qc dt + (A Qc + Qc Aᵀ) dt²/2 + A Qc Aᵀ dt³/3

    (second-order Van Loan series).  P (9, 9) (leading axes allowed); the result is symmetrised.
    ``body`` gives GM for the gravity gradient.
    Returns (P⁺, Φ, Qd).
    """
    C = quat_to_dcm(np.asarray(q, dtype=float))
    A = _a_matrix(C, np.asarray(f, dtype=float), np.asarray(w, dtype=float), p, body.gm)
    Phi = expm(A * dt)
    psd_w = np.asarray(sigma_w, dtype=float) ** 2 * sample_dt * np.ones(3)
    psd_f = np.asarray(sigma_f, dtype=float) ** 2 * sample_dt * np.ones(3)
    Qc = np.zeros(A.shape)
    Qc[..., 0:3, 0:3] = (C * psd_f[..., None, :]) @ np.swapaxes(C, -1, -2)
    Qc[..., 3:6, 3:6] = psd_w[..., :, None] * _I3
    if Q_state_psd is not None:
        Qc += np.asarray(Q_state_psd, dtype=float)[..., :, None] * _I9
    AQ = A @ Qc
    AQt = np.swapaxes(AQ, -1, -2)
    Qd = Qc * dt + (AQ + AQt) * (0.5 * dt * dt) + (AQ @ np.swapaxes(A, -1, -2)) * (dt**3 / 3.0)
    Qd = 0.5 * (Qd + np.swapaxes(Qd, -1, -2))
    Pn = Phi @ P @ np.swapaxes(Phi, -1, -2) + Qd
    Pn = 0.5 * (Pn + np.swapaxes(Pn, -1, -2))
    return Pn, Phi, Qd


# ---------------------------------------------------------------------------------------------
# data gaps


def _bridge_dt(bridge: Any) -> float:
    return float(bridge.t_b) - float(bridge.t_a)


def apply_gap(
    v: np.ndarray, q: np.ndarray, p: np.ndarray, bridge: Any, mode: str = "relative"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Carry the state (v_M, q_M_G, p_M) across a data gap with the on-board changes (AMELIA Sect. 5).

    ``bridge`` is a :class:`GapBridge` (fields ``t_a``,
    ``t_b``, ``dv_G``, ``dp_G``, ``dp_rel_G``, ``dC``; ``C = C_G_M`` of the on-board attitude).
    With ``C_a = C_G_M`` of *our* state at a (``C_aᵀ = C_M_G``)::

        v_b = v_a + C_aᵀ dv_G,   C_b = dC C_a   (i.e. q_b = q_a ⊗ q(dCᵀ))
        "paper":    p_b = p_a + C_aᵀ dp_G
        "relative": p_b = p_a + v_a Δt + C_aᵀ dp_rel_G       (default; Δt = t_b − t_a)

    "relative" keeps our own velocity in the position change so the on-board velocity error
    (v_onboard − v_true) does not leak Δt·δv into Δp.  Vectorised over leading axes of the state.
    """
    if mode not in ("relative", "paper"):
        raise ValueError(f"apply_gap: mode must be 'relative' or 'paper', got {mode!r}")
    dq = dcm_to_quat(np.asarray(bridge.dC, dtype=float).T)  # q_Ga_Gb
    v_b = v + rotate(q, np.asarray(bridge.dv_G, dtype=float))
    if mode == "paper":
        p_b = p + rotate(q, np.asarray(bridge.dp_G, dtype=float))
    else:
        p_b = p + _bridge_dt(bridge) * v + rotate(q, np.asarray(bridge.dp_rel_G, dtype=float))
    q_b = quat_normalize(quat_multiply(q, dq))
    return v_b, q_b, p_b


def gap_transition(
    q_a: np.ndarray,
    p_a: np.ndarray,
    bridge: Any,
    mode: str = "relative",
    gap_sigma: tuple[float, float, float] = GAP_SIGMA_DEFAULT,
    *,
    body: Body,
) -> tuple[np.ndarray, np.ndarray]:
    """Error transition Φ (9, 9) and added noise Qd (9, 9) of :func:`apply_gap` (our state at a).

    Linearising the bridge with ``q_true = q ⊗ exp(δθ)`` (``C_M_G,true ≈ C_M_G (I + S(δθ))``)::

        δv_b = δv_a − C_M_G S(dv_G) δθ_a + G Δt δp_a
        δθ_b = dC δθ_a
        δp_b = δp_a + Δt δv_a − C_M_G S(dp_rel_G) δθ_a + ½ G Δt² δp_a

    (G the point-mass gravity gradient of ``body`` at p_a).  The same Φ is used for mode "paper" (with dp_G in
    place of dp_rel_G): there, the true error also gains Δt (v_est − v_onboard), a bias that Φ
    does not model.  ``gap_sigma`` = per-second 1σ (velocity [m/s/s], attitude [rad/s], position
    [m/s]) of the bridge's own error; the added standard deviation is ``gap_sigma · Δt``
    (``Qd = diag((gap_sigma Δt)²)`` on each block).
    """
    dt = _bridge_dt(bridge)
    C = quat_to_dcm(np.asarray(q_a, dtype=float))
    G = gravity_point_mass_gradient(p_a, body.gm)
    dp = np.asarray(bridge.dp_G if mode == "paper" else bridge.dp_rel_G, dtype=float)
    Phi = np.eye(9)
    Phi[0:3, 3:6] = -C @ skew(np.asarray(bridge.dv_G, dtype=float))
    Phi[0:3, 6:9] = G * dt
    Phi[3:6, 3:6] = np.asarray(bridge.dC, dtype=float)
    Phi[6:9, 0:3] = dt * _I3
    Phi[6:9, 3:6] = -C @ skew(dp)
    Phi[6:9, 6:9] = _I3 + 0.5 * dt * dt * G
    s = np.repeat(np.asarray(gap_sigma, dtype=float) * dt, 3)
    return Phi, np.diag(s * s)


# ---------------------------------------------------------------------------------------------
# whole passes


@dataclass(frozen=True)
class GapBridge:
    """A TM gap between samples a (``t_a``, last before) and b (``t_b``, first after), AMELIA Sect. 5.

    From the on-board solution at the edges, with ``C = C_G_M`` of the on-board attitude:
    ``dv_G = C_a (v_b − v_a)`` [m/s]; ``dp_G = C_a (p_b − p_a)`` [m];
    ``dp_rel_G = C_a (p_b − p_a − v_a (t_b − t_a))`` [m]; ``dC = C_b C_aᵀ`` (3,3).
    """

    t_a: float
    t_b: float
    dv_G: np.ndarray
    dp_G: np.ndarray
    dp_rel_G: np.ndarray
    dC: np.ndarray


@dataclass(frozen=True)
class ImuArrays:
    """What integration needs of a PreprocessedIMU, as plain picklable arrays (for worker processes).

    ``t`` (n,) [s]; ``f_G`` (n, 3) [m/s²]; ``w_G`` (n, 3) [rad/s]; ``sigma_f``, ``sigma_w`` (n, 3)
    per-sample 1σ; ``gaps`` the :class:`GapBridge` of each data gap.
    """

    t: np.ndarray
    f_G: np.ndarray
    w_G: np.ndarray
    sigma_f: np.ndarray
    sigma_w: np.ndarray
    gaps: tuple[GapBridge, ...] = ()


def imu_columns(imu: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(t, f_G, w_G, sigma_f, sigma_w)`` of an IMU record (:class:`ImuArrays` or a
    PreprocessedIMU) as float arrays: t (n,) [s], f_G (n, 3) [m/s²], w_G (n, 3) [rad/s] and the
    per-sample 1σ (n, 3) of each."""
    return (
        np.asarray(imu.t, dtype=float),
        np.asarray(imu.f_G, dtype=float),
        np.asarray(imu.w_G, dtype=float),
        np.asarray(imu.sigma_f, dtype=float),
        np.asarray(imu.sigma_w, dtype=float),
    )


def imu_arrays(imu: Any) -> ImuArrays:
    """:class:`ImuArrays` from any object with ``t``, ``f_G``, ``w_G`` (optional ``sigma_f``/``sigma_w``,
    scalar or (n, 3), default 0; optional ``gaps``)."""
    n = np.asarray(imu.t).size

    def sig(a):
        return np.broadcast_to(np.asarray(0.0 if a is None else a, float), (n, 3)).copy()

    gaps = tuple(
        GapBridge(
            float(g.t_a),
            float(g.t_b),
            np.asarray(g.dv_G, float),
            np.asarray(g.dp_G, float),
            np.asarray(g.dp_rel_G, float),
            np.asarray(g.dC, float),
        )
        for g in (getattr(imu, "gaps", None) or ())
    )
    return ImuArrays(
        np.asarray(imu.t, float),
        np.asarray(imu.f_G, float),
        np.asarray(imu.w_G, float),
        sig(getattr(imu, "sigma_f", None)),
        sig(getattr(imu, "sigma_w", None)),
        gaps,
    )


@dataclass(frozen=True)
class StrapdownPass:
    """One strapdown pass over the IMU grid (forward, from the initial state), SI, frame M.

    ``t`` (n,) [s from EIP]; ``v_M`` (n, 3) [m/s]; ``q_M_G`` (n, 4); ``p_M`` (n, 3) [m];
    ``P`` (n, 9, 9) first-order covariance of ``[δv_M, δθ_G, δp_M]`` (forward pass);
    ``Phi`` (n, 9, 9) with ``Phi[k]`` the error transition from sample k−1 to k (``Phi[0] = I``);
    ``Qd`` (n, 9, 9) the noise added over that step (``Qd[0] = 0``), so
    ``P[k] = Phi[k] P[k−1] Phi[k]ᵀ + Qd[k]``; ``bridged`` (n,) True where sample k was reached
    across a data gap (:func:`apply_gap`).
    """

    t: np.ndarray
    v_M: np.ndarray
    q_M_G: np.ndarray
    p_M: np.ndarray
    P: np.ndarray
    Phi: np.ndarray
    Qd: np.ndarray
    bridged: np.ndarray


def gap_index(t: np.ndarray, gaps: Any) -> dict[int, Any]:
    """Map sample index i (gap between i and i+1, ``t[i] = t_a``) -> GapBridge; checks t_b."""
    out: dict[int, Any] = {}
    for g in gaps or ():
        i = int(np.searchsorted(t, float(g.t_a) - 1e-6))
        if i >= t.size - 1 or abs(t[i] - float(g.t_a)) > 1e-6 or abs(t[i + 1] - float(g.t_b)) > 1e-6:
            raise ValueError(f"gap bridge t_a={g.t_a:.3f} s, t_b={g.t_b:.3f} s does not match two adjacent IMU samples")
        out[i] = g
    return out


def _rms(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sqrt(0.5 * (a * a + b * b))


def integrate(
    imu: Any,
    v0: np.ndarray,
    q0: np.ndarray,
    p0: np.ndarray,
    P0: np.ndarray,
    *,
    q_state_psd: np.ndarray | None = None,
    gap_sigma: tuple[float, float, float] = GAP_SIGMA_DEFAULT,
    bridge_mode: str = "relative",
    sample_dt: float | None = None,
    gravity_gradient: bool = True,
    body: Body,
    fast: bool = False,
) -> StrapdownPass:
    """Strapdown integration with first-order covariance over a PreprocessedIMU (AMELIA Sect. 5).

    ``imu`` needs ``t`` (n,) [s], ``f_G`` (n, 3) [m/s²], ``w_G`` (n, 3) [rad/s], ``sigma_f``,
    ``sigma_w`` (n, 3) per-sample 1σ and ``gaps`` (list of GapBridge, gap k between samples i and
    i+1 with ``t[i] = t_a``, ``t[i+1] = t_b``).  Initial state at ``t[0]``: v0 (3,) [m/s], q0
    (4,) ``q_M_G``, p0 (3,) [m], P0 (9, 9).  Each ordinary step is :func:`rk4_step` +
    :func:`covariance_step` (mid-step attitude/inputs/position, input σ the RMS of the two
    samples'); a gap step is :func:`apply_gap` (``bridge_mode``) + :func:`gap_transition`
    (``gap_sigma``).  ``q_state_psd`` (9,) optional state noise PSD η (Eq. A.15's R) [units²/s];
    ``sample_dt`` [s] the raw sampling interval that turns per-sample σ into spectral densities
    (default: the median sample interval); ``gravity_gradient`` include G(p) in A; ``body`` the
    planet (gravity).  ``fast``: each ordinary step by the compiled
    :func:`~workbench.estimation.strapdown_kernel.transition_step` (the same state, Φ and Qd to
    rounding) instead of :func:`rk4_step` + :func:`covariance_step` (the reference path, default).
    """
    t, f, w, sf, sw = imu_columns(imu)
    n = t.size
    if n < 2:
        raise ValueError("integrate: need at least two IMU samples")
    if np.any(np.diff(t) <= 0.0):
        raise ValueError("integrate: IMU times must be strictly increasing")
    if sample_dt is None:
        sample_dt = float(np.median(np.diff(t)))
    gaps = gap_index(t, getattr(imu, "gaps", ()))
    V = np.empty((n, 3))
    Q = np.empty((n, 4))
    X = np.empty((n, 3))
    P = np.empty((n, 9, 9))
    Phi = np.empty((n, 9, 9))
    Qd = np.empty((n, 9, 9))
    bridged = np.zeros(n, dtype=bool)
    v = np.asarray(v0, dtype=float).copy()
    q = quat_normalize(np.asarray(q0, dtype=float))
    p = np.asarray(p0, dtype=float).copy()
    Pk = np.asarray(P0, dtype=float).copy()
    V[0], Q[0], X[0], P[0], Phi[0], Qd[0] = v, q, p, Pk, _I9, 0.0
    if fast:
        qpsd = np.zeros(9) if q_state_psd is None else np.ascontiguousarray(q_state_psd, dtype=float)
        sw_mid, sf_mid = _rms(sw[:-1], sw[1:]), _rms(sf[:-1], sf[1:])
        gm, j2k = float(body.gm), float(j2_factor(body))
    for k in range(n - 1):
        g = gaps.get(k)
        if g is not None:
            F, Qk = gap_transition(q, p, g, bridge_mode, gap_sigma, body=body)
            v, q, p = apply_gap(v, q, p, g, bridge_mode)
            Pk = F @ Pk @ F.T + Qk
            Pk = 0.5 * (Pk + Pk.T)
            bridged[k + 1] = True
        elif fast:
            dt = float(t[k + 1] - t[k])
            v, q, p, F, Qk = transition_step(
                v, q, p, f[k], w[k], f[k + 1], w[k + 1], dt, sw_mid[k], sf_mid[k], sample_dt, qpsd,
                bool(gravity_gradient), gm, j2k,
            )  # fmt: skip
            Pk = F @ Pk @ F.T + Qk
            Pk = 0.5 * (Pk + Pk.T)
        else:
            dt = t[k + 1] - t[k]
            v1, q1, p1 = rk4_step(v, q, p, f[k], w[k], f[k + 1], w[k + 1], dt, body)
            qm = q + q1 if (q @ q1) >= 0.0 else q - q1
            qm = qm / np.sqrt(qm @ qm)
            Pk, F, Qk = covariance_step(
                Pk,
                qm,
                0.5 * (f[k] + f[k + 1]),
                0.5 * (w[k] + w[k + 1]),
                dt,
                _rms(sw[k], sw[k + 1]),
                _rms(sf[k], sf[k + 1]),
                sample_dt,
                q_state_psd,
                0.5 * (p + p1) if gravity_gradient else None,
                body=body,
            )
            v, q, p = v1, q1, p1
        V[k + 1], Q[k + 1], X[k + 1], P[k + 1], Phi[k + 1], Qd[k + 1] = v, q, p, Pk, F, Qk
    return StrapdownPass(t=t, v_M=V, q_M_G=Q, p_M=X, P=P, Phi=Phi, Qd=Qd, bridged=bridged)


def integrate_members(
    imu: Any,
    v0: np.ndarray,
    q0: np.ndarray,
    p0: np.ndarray,
    *,
    bridge_mode: str = "relative",
    at_t: np.ndarray | None = None,
    every: np.ndarray | None = None,
    body: Body,
) -> dict[str, np.ndarray]:
    """Strapdown of many members at once (no covariance), vectorised over the leading member axis.

    v0 (m, 3) [m/s], q0 (m, 4) ``q_M_G``, p0 (m, 3) [m] (a single (3,)/(4,) state also works);
    same IMU inputs and gap bridges (``bridge_mode``) and planet ``body`` for every member, as
    :func:`integrate`.
    Returns a dict:

    * always ``"t"`` (n,) and the final state ``"v_end"``, ``"q_end"``, ``"p_end"`` (m, ·);
    * ``at_t`` (k,) [s] given: ``"v_at"``, ``"p_at"`` (k, m, 3) linearly interpolated between
      the bracketing samples, ``"q_at"`` (k, m, 4) normalised linear interpolation (times must
      lie in ``[t[0], t[-1]]``; inside a data gap this interpolates across the bridge);
    * ``every`` (j,) int sample indices given: ``"p_every"`` (j, m, 3) positions at those samples;
    * neither given: the full histories ``"v"``, ``"q"``, ``"p"`` (n, m, ·) — mind the memory.

    Only member-wise element operations are used, so a member's result does not depend on which
    other members share the call (chunking and scheduling give bit-identical results).
    """
    t = np.asarray(imu.t, dtype=float)
    f = np.asarray(imu.f_G, dtype=float)
    w = np.asarray(imu.w_G, dtype=float)
    n = t.size
    gaps = gap_index(t, getattr(imu, "gaps", ()))
    v = np.array(v0, dtype=float)
    q = quat_normalize(np.array(q0, dtype=float))
    p = np.array(p0, dtype=float)
    out: dict[str, np.ndarray] = {"t": t}
    full = at_t is None and every is None
    if full:
        Vh = np.empty((n, *v.shape))
        Qh = np.empty((n, *q.shape))
        Ph = np.empty((n, *p.shape))
        Vh[0], Qh[0], Ph[0] = v, q, p
    if at_t is not None:
        at_t = np.atleast_1d(np.asarray(at_t, dtype=float))
        if np.any(at_t < t[0] - 1e-9) or np.any(at_t > t[-1] + 1e-9):
            raise ValueError(f"integrate_members: requested times must lie within [{t[0]:.3f}, {t[-1]:.3f}] s")
        # interval index j (t[j] <= t_e <= t[j+1]) and weight of the later sample
        jj = np.clip(np.searchsorted(t, at_t, side="right") - 1, 0, n - 2)
        ww = (at_t - t[jj]) / (t[jj + 1] - t[jj])
        v_at = np.empty((at_t.size, *v.shape))
        q_at = np.empty((at_t.size, *q.shape))
        p_at = np.empty((at_t.size, *p.shape))
    if every is not None:
        every = np.asarray(every, dtype=int)
        p_every = np.empty((every.size, *p.shape))
        for i in np.flatnonzero(every == 0):
            p_every[i] = p
    for k in range(n - 1):
        g = gaps.get(k)
        if g is not None:
            v1, q1, p1 = apply_gap(v, q, p, g, bridge_mode)
        else:
            v1, q1, p1 = rk4_step(v, q, p, f[k], w[k], f[k + 1], w[k + 1], t[k + 1] - t[k], body)
        if at_t is not None:
            for i in np.flatnonzero(jj == k):
                a = ww[i]
                v_at[i] = (1.0 - a) * v + a * v1
                p_at[i] = (1.0 - a) * p + a * p1
                s = np.sign(np.sum(q * q1, axis=-1, keepdims=True))
                q_at[i] = quat_normalize((1.0 - a) * q + (a * s) * q1)
        v, q, p = v1, q1, p1
        if full:
            Vh[k + 1], Qh[k + 1], Ph[k + 1] = v, q, p
        if every is not None:
            for i in np.flatnonzero(every == k + 1):
                p_every[i] = p
    out.update(v_end=v, q_end=q, p_end=p)
    if full:
        out.update(v=Vh, q=Qh, p=Ph)
    if at_t is not None:
        out.update(v_at=v_at, q_at=q_at, p_at=p_at)
    if every is not None:
        out["p_every"] = p_every
    return out
