"""Compiled (numba) recursion of the drop-test EKF in kinematic mode: the IMU part of a step.

The same filter as :func:`workbench.problems.droptest.pipeline.forward_pass` through the generic
:func:`workbench.estimation.ekf.run_filter` (the pure-numpy *reference* path, selectable there),
written as one loop over the steps with nothing allocated per step:

* predict: :func:`workbench.problems.droptest.model.propagate` (kinematic, no bungee) and
  ``P = F P Fᵀ + Q`` with Q of :func:`~workbench.problems.droptest.model.process_noise` (at the
  propagated attitude), using that F
  is the identity outside its first 18 × 18 block (the core states p, v, a, θ, ω, α);
* the step's measurements one after the other, in the order of the reference path — every valid
  triad (:func:`~workbench.problems.droptest.model.triad_model`, bias states included), the gyro
  (:func:`~workbench.problems.droptest.model.gyro_model`), the hanging zero-velocity update — each
  its own update re-linearised at the current state by the compiled Joseph-form update of the
  estimation core (:func:`workbench.estimation.kernels.joseph_update`, the association of
  :func:`workbench.estimation.ekf.update`), H used by its non-zero columns only, then
  :func:`boxplus_into` the drop-test state;
* every per-sensor predicted measurement, innovation, innovation covariance and NIS recorded.

Units and frames are those of :mod:`workbench.problems.droptest.model` (SI, body-frame attitude
error ``q_true = q ⊗ exp(δθ)``).  Numbers agree with the reference path to floating-point noise
(sums taken in another order); ``tests/problems/droptest/test_kernel.py`` pins that.
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.jit import njit
from workbench.estimation.kernels import copy_matrix, joseph_update

__all__ = [
    "NC",
    "imu_steps",
    "propagate_kinematic",
    "bungee_accel",
    "bungee_step",
    "process_noise_into",
    "predict_covariance",
    "boxplus_into",
    "triad_into",
    "gyro_into",
]

#: size of the block of F that is not the identity (p, v, a, θ, ω, α)
NC = 18


@njit
def _dcm(q, C):
    x, y, z, w = q[0], q[1], q[2], q[3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    C[0, 0] = 1 - 2 * (yy + zz)
    C[0, 1] = 2 * (xy - wz)
    C[0, 2] = 2 * (xz + wy)
    C[1, 0] = 2 * (xy + wz)
    C[1, 1] = 1 - 2 * (xx + zz)
    C[1, 2] = 2 * (yz - wx)
    C[2, 0] = 2 * (xz - wy)
    C[2, 1] = 2 * (yz + wx)
    C[2, 2] = 1 - 2 * (xx + yy)


@njit
def _skew(v, S):
    S[0, 0] = 0.0
    S[0, 1] = -v[2]
    S[0, 2] = v[1]
    S[1, 0] = v[2]
    S[1, 1] = 0.0
    S[1, 2] = -v[0]
    S[2, 0] = -v[1]
    S[2, 1] = v[0]
    S[2, 2] = 0.0


@njit
def _mm3(A, B, out):
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@njit
def _mv3(A, v, out):
    for i in range(3):
        out[i] = A[i, 0] * v[0] + A[i, 1] * v[1] + A[i, 2] * v[2]


@njit
def propagate_kinematic(x, dt, g, xn, F, w3):
    """Kinematic :func:`workbench.problems.droptest.model.propagate` (no bungee) of x (n_x,) over
    dt [s] with gravity g (3,) [m/s², SPF], written into xn (n_x,) and the error transition F
    (n_e, n_e) (body-frame attitude error); w3 (8, 3, 3) scratch (entries 0–5 and 7 used)."""
    C, CaX, Sa, Rt, Jr, SJ = w3[0], w3[1], w3[2], w3[3], w3[4], w3[5]
    v3 = w3[7]
    for i in range(x.shape[0]):
        xn[i] = x[i]
    q = x[9:13]
    _dcm(q, C)
    aB = x[6:9]
    acc = v3[0]
    for i in range(3):
        acc[i] = C[i, 0] * aB[0] + C[i, 1] * aB[1] + C[i, 2] * aB[2] + g[i]
    for i in range(3):
        xn[i] = x[i] + x[3 + i] * dt + 0.5 * acc[i] * dt * dt
        xn[3 + i] = x[3 + i] + acc[i] * dt
    phi = v3[1]
    for i in range(3):
        phi[i] = x[13 + i] * dt + 0.5 * x[16 + i] * dt * dt
    a = math.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
    half = 0.5 * a
    k = 0.5 - a * a / 48.0 if a < 1e-6 else math.sin(half) / a
    dq = v3[2]  # (x, y, z) of exp(φ); w below
    dq[0], dq[1], dq[2] = phi[0] * k, phi[1] * k, phi[2] * k
    dw = math.cos(half)
    # Rt = dcm(dq)ᵀ
    xq, yq, zq = dq[0], dq[1], dq[2]
    xx, yy, zz = xq * xq, yq * yq, zq * zq
    xy, xz, yz = xq * yq, xq * zq, yq * zq
    wx, wy, wz = dw * xq, dw * yq, dw * zq
    Rt[0, 0] = 1 - 2 * (yy + zz)
    Rt[1, 0] = 2 * (xy - wz)
    Rt[2, 0] = 2 * (xz + wy)
    Rt[0, 1] = 2 * (xy + wz)
    Rt[1, 1] = 1 - 2 * (xx + zz)
    Rt[2, 1] = 2 * (yz - wx)
    Rt[0, 2] = 2 * (xz - wy)
    Rt[1, 2] = 2 * (yz + wx)
    Rt[2, 2] = 1 - 2 * (xx + yy)
    px, py, pz, pw = q[0], q[1], q[2], q[3]
    rx = pw * dq[0] + px * dw + py * dq[2] - pz * dq[1]
    ry = pw * dq[1] - px * dq[2] + py * dw + pz * dq[0]
    rz = pw * dq[2] + px * dq[1] - py * dq[0] + pz * dw
    rw = pw * dw - px * dq[0] - py * dq[1] - pz * dq[2]
    nq = math.sqrt(rx * rx + ry * ry + rz * rz + rw * rw)
    xn[9], xn[10], xn[11], xn[12] = rx / nq, ry / nq, rz / nq, rw / nq
    aBn = v3[0]  # acc no longer needed
    _mv3(Rt, aB, aBn)
    for i in range(3):
        xn[13 + i] = x[13 + i] + x[16 + i] * dt
        xn[16 + i] = x[16 + i]
        xn[6 + i] = aBn[i]
    # F: identity, then the blocks of model.propagate
    n_e = F.shape[0]
    for i in range(n_e):
        for j in range(n_e):
            F[i, j] = 0.0
        F[i, i] = 1.0
    _skew(aB, Sa)
    _mm3(C, Sa, CaX)
    _skew(phi, Sa)
    for i in range(3):
        for j in range(3):
            Jr[i, j] = (1.0 if i == j else 0.0) - 0.5 * Sa[i, j]
    _skew(aBn, Sa)
    _mm3(Sa, Jr, SJ)
    h2 = 0.5 * dt * dt
    for i in range(3):
        F[i, 3 + i] = dt
        F[12 + i, 15 + i] = dt
        for j in range(3):
            F[i, 6 + j] = h2 * C[i, j]
            F[i, 9 + j] = -0.5 * dt * dt * CaX[i, j]
            F[3 + i, 6 + j] = dt * C[i, j]
            F[3 + i, 9 + j] = -dt * CaX[i, j]
            F[9 + i, 9 + j] = Rt[i, j]
            F[9 + i, 12 + j] = dt * Jr[i, j]
            F[9 + i, 15 + j] = h2 * Jr[i, j]
            F[6 + i, 6 + j] = Rt[i, j]
            F[6 + i, 12 + j] = SJ[i, j] * dt
            F[6 + i, 15 + j] = SJ[i, j] * h2


@njit
def bungee_accel(p, q, bungee, coeffs, a, J, w):
    """:meth:`workbench.problems.droptest.model.BungeeModel.accel`: bungee acceleration a (3,)
    [m/s², SPF] at CM position p (3,) [m, SPF] and attitude q (4,), and ∂a/∂p J (3, 3) [1/s²];
    ``bungee``, ``coeffs`` as in :func:`imu_steps`; w (3, 3) scratch."""
    C = w
    _dcm(q, C)
    d0 = bungee[1] - (p[0] + (C[0, 0] * bungee[4] + C[0, 1] * bungee[5] + C[0, 2] * bungee[6]))
    d1 = bungee[2] - (p[1] + (C[1, 0] * bungee[4] + C[1, 1] * bungee[5] + C[1, 2] * bungee[6]))
    d2 = bungee[3] - (p[2] + (C[2, 0] * bungee[4] + C[2, 1] * bungee[5] + C[2, 2] * bungee[6]))
    L = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    u0, u1, u2 = d0 / L, d1 / L, d2 / L
    s = L - bungee[7]
    if s <= 0.0:
        for i in range(3):
            a[i] = 0.0
            for j in range(3):
                J[i, j] = 0.0
        return
    f = 0.0
    fp = 0.0
    for k in range(coeffs.shape[0]):
        f += coeffs[k] * s ** (k + 1)
        fp += (k + 1) * coeffs[k] * s**k
    kk = bungee[8]
    u = (u0, u1, u2)
    for i in range(3):
        a[i] = kk * f * u[i]
        for j in range(3):
            uu = u[i] * u[j]
            J[i, j] = kk * (-fp * uu - f * ((1.0 if i == j else 0.0) - uu) / L)


@njit
def bungee_step(x, xn, F, dt, bungee, coeffs, bw):
    """The bungee part of ``model.propagate`` (dynamic mode, between release and cut): adds the
    change of bungee acceleration over the step, rotated to the new body frame, to xn[6:9] and its
    Jacobian to F[a, v] and F[a, a] (n_e, n_e); x (n_x,) the state at the step's start, xn (n_x,)
    after :func:`propagate_kinematic` (its a_B before the bungee); bw (8, 3, 3) scratch."""
    a0, a1, J0, J1, C, Cn, A = bw[0, 0], bw[0, 1], bw[1], bw[2], bw[3], bw[4], bw[5]
    da = bw[0, 2]
    bungee_accel(x[0:3], x[9:13], bungee, coeffs, a0, J0, bw[6])
    bungee_accel(xn[0:3], xn[9:13], bungee, coeffs, a1, J1, bw[6])
    _dcm(x[9:13], C)
    _dcm(xn[9:13], Cn)
    for i in range(3):
        da[i] = a1[i] - a0[i]
    for i in range(3):
        xn[6 + i] = xn[6 + i] + (Cn[0, i] * da[0] + Cn[1, i] * da[1] + Cn[2, i] * da[2])
    for i in range(3):  # A = Cnᵀ J1
        for j in range(3):
            A[i, j] = Cn[0, i] * J1[0, j] + Cn[1, i] * J1[1, j] + Cn[2, i] * J1[2, j]
    h2 = 0.5 * dt * dt
    for i in range(3):
        for j in range(3):
            F[6 + i, 3 + j] += A[i, j] * dt
            F[6 + i, 6 + j] += (A[i, 0] * C[0, j] + A[i, 1] * C[1, j] + A[i, 2] * C[2, j]) * h2


@njit
def _bungee_jump(xn, bungee, coeffs, g, sign, bw):
    """Release (sign +1: a_B += C_B_I (a_bungee + g)) or cut (sign −1: a_B −= C_B_I a_bungee) at xn."""
    a, J, Cn, v = bw[0, 0], bw[1], bw[4], bw[0, 1]
    bungee_accel(xn[0:3], xn[9:13], bungee, coeffs, a, J, bw[6])
    for i in range(3):
        v[i] = a[i] + g[i] if sign > 0.0 else a[i]
    # quat_rotate(conj(q), v): u = −q_vec, w = q_w; t = 2 u × v; v + w t + u × t
    ux, uy, uz, w = -xn[9], -xn[10], -xn[11], xn[12]
    tx = 2.0 * (uy * v[2] - uz * v[1])
    ty = 2.0 * (uz * v[0] - ux * v[2])
    tz = 2.0 * (ux * v[1] - uy * v[0])
    rx = v[0] + w * tx + (uy * tz - uz * ty)
    ry = v[1] + w * ty + (uz * tx - ux * tz)
    rz = v[2] + w * tz + (ux * ty - uy * tx)
    if sign > 0.0:
        xn[6], xn[7], xn[8] = xn[6] + rx, xn[7] + ry, xn[8] + rz
    else:
        xn[6], xn[7], xn[8] = xn[6] - rx, xn[7] - ry, xn[8] - rz
    Cn[0, 0] = 0.0


@njit
def process_noise_into(dt, qa, qw, C, Q, B3):
    """:func:`workbench.problems.droptest.model.process_noise` into Q (n_e, n_e): white jerk PSD
    qa [m²/s⁵] and angular jerk PSD qw [rad²/s⁵] over dt [s] (zero outside the (p, v, a) and
    (θ, ω, α) chains); C (3, 3) the attitude C_I_B at the end of the step (the SPF (p, v) –
    body (a) cross blocks carry it); B3 (3, 3) scratch."""
    n_e = Q.shape[0]
    for i in range(n_e):
        for j in range(n_e):
            Q[i, j] = 0.0
    b = B3
    b[0, 0], b[0, 1], b[0, 2] = dt**5 / 20, dt**4 / 8, dt**3 / 6
    b[1, 0], b[1, 1], b[1, 2] = dt**4 / 8, dt**3 / 3, dt**2 / 2
    b[2, 0], b[2, 1], b[2, 2] = dt**3 / 6, dt**2 / 2, dt
    for r in range(3):
        for c in range(3):
            for i in range(3):
                Q[9 + 3 * r + i, 9 + 3 * c + i] = qw * b[r, c]
                if (r == 2) == (c == 2):
                    Q[3 * r + i, 3 * c + i] = qa * b[r, c]
                else:
                    for j in range(3):
                        Q[3 * r + i, 3 * c + j] = qa * b[r, c] * (C[i, j] if c == 2 else C[j, i])


@njit
def predict_covariance(P, F, Q, T):
    """``P ← ½(A + Aᵀ)``, ``A = F P Fᵀ + Q`` in place: P, F, Q (n_e, n_e) error-state units, F the
    identity outside its first NC × NC block (as from :func:`propagate_kinematic`); T (NC, n_e) scratch."""
    n_e = P.shape[0]
    for i in range(NC):
        for j in range(n_e):
            T[i, j] = 0.0
        for c in range(NC):
            f = F[i, c]
            for j in range(n_e):
                T[i, j] += f * P[c, j]
    for i in range(NC):
        for j in range(NC):
            s = 0.0
            for c in range(NC):
                s += T[i, c] * F[j, c]
            P[i, j] = s + Q[i, j]
    for i in range(NC):
        for j in range(i + 1, NC):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v
        for j in range(NC, n_e):
            P[i, j] = T[i, j]
            P[j, i] = T[i, j]
    for i in range(NC, n_e):
        for j in range(NC, n_e):
            P[i, j] += Q[i, j]


@njit
def boxplus_into(x, dx):
    """x ⊞ dx in place for the drop-test layout (one quaternion at x[9:13], error dx[9:12])."""
    for i in range(9):
        x[i] += dx[i]
    for i in range(13, x.shape[0]):
        x[i] += dx[i - 1]
    qx, qy, qz, qw = x[9], x[10], x[11], x[12]
    ex, ey, ez = dx[9], dx[10], dx[11]
    a = math.sqrt(ex * ex + ey * ey + ez * ez)
    k = 0.5 - a * a / 48.0 if a < 1e-6 else math.sin(0.5 * a) / a
    px, py, pz, pw = ex * k, ey * k, ez * k, math.cos(0.5 * a)
    rx = qw * px + qx * pw + qy * pz - qz * py
    ry = qw * py - qx * pz + qy * pw + qz * px
    rz = qw * pz + qx * py - qy * px + qz * pw
    rw = qw * pw - qx * px - qy * py - qz * pz
    n = math.sqrt(rx * rx + ry * ry + rz * rz + rw * rw)
    x[9], x[10], x[11], x[12] = rx / n, ry / n, rz / n, rw / n


@njit
def triad_into(x, r, j, has_bias, zp, Hc, cols, w3):
    """:func:`workbench.problems.droptest.model.triad_model` of triad j at lever arm r (3,) [m, body]:
    predicted specific force zp (3,) [m/s², body] and the non-zero columns of H, Hc[:, :nc] over the
    error-state indices cols[:nc] (a, ω, α, and b_j when ``has_bias``); returns nc (12 or 9).
    w3 (8, 3, 3) scratch (entries 0–4)."""
    Sw, Sr, Swr, SS = w3[0], w3[1], w3[2], w3[3]
    v = w3[4]
    _skew(x[13:16], Sw)
    _skew(r, Sr)
    wr = v[0]
    _mv3(Sw, r, wr)
    ra = v[1]
    _mv3(Sr, x[16:19], ra)
    wwr = v[2]
    _mv3(Sw, wr, wwr)
    for i in range(3):
        zp[i] = x[6 + i] - ra[i] + wwr[i]
    _skew(wr, Swr)
    _mm3(Sw, Sr, SS)
    for a in range(3):
        for c in range(12):
            Hc[a, c] = 0.0
        Hc[a, a] = 1.0
        for c in range(3):
            Hc[a, 3 + c] = -Swr[a, c] - SS[a, c]
            Hc[a, 6 + c] = -Sr[a, c]
    for c in range(3):
        cols[c] = 6 + c
        cols[3 + c] = 12 + c
        cols[6 + c] = 15 + c
    if has_bias:
        for i in range(3):
            zp[i] = zp[i] + x[31 + 3 * j + i]
            Hc[i, 9 + i] = 1.0
        for c in range(3):
            cols[9 + c] = 30 + 3 * j + c
        return 12
    return 9


@njit
def gyro_into(x, zp, Hc, cols):
    """:func:`workbench.problems.droptest.model.gyro_model`: predicted rate zp (3,) [rad/s, gyro axes]
    and the non-zero columns of H, Hc (3, 15) over the error-state indices cols (15,) = ω (3),
    E (9), b_g (3); returns 15."""
    for i in range(3):
        s = 0.0
        for c in range(3):
            s += x[19 + 3 * i + c] * x[13 + c]
        zp[i] = x[13 + i] + s + x[28 + i]
    for a in range(3):
        for c in range(15):
            Hc[a, c] = 0.0
        for c in range(3):
            Hc[a, c] = (1.0 if a == c else 0.0) + x[19 + 3 * a + c]
            Hc[a, 3 + 3 * a + c] = x[13 + c]
        Hc[a, 12 + a] = 1.0
    for c in range(3):
        cols[c] = 12 + c
        cols[12 + c] = 27 + c
    for c in range(9):
        cols[3 + c] = 18 + c
    return 15


@njit
def imu_steps(
    k_a, k_b, x, P, t, g, q_accel, q_angular, lever, z_meas, valid, r_diag, r_zupt, bungee, coeffs,
    x_prior, x_post, P_prior, P_post, F_hist, Q_hist, inn_zp, inn_y, inn_S, inn_nis,
):  # fmt: skip
    """Run steps ``k_a..k_b`` (inclusive) of the kinematic drop-test EKF, IMU measurements only.

    State: x (n_x,), P (n_e, n_e) — the posterior of step ``k_a − 1`` (or the initial state when
    ``k_a = 0``) on entry, the posterior of ``k_b`` on return (in place).  Inputs per step k: t (n,)
    [s]; g (3,) gravity [m/s², SPF]; q_accel, q_angular (n,) jerk PSDs; lever (n_t, 3) [m, body].
    Channels c = 0..n_t+1: triad c < n_t, the gyro (c = n_t), the zero-velocity update (c = n_t + 1),
    processed in that order: z_meas (n, n_t + 2, 3) measured [m/s², rad/s, m/s], valid (n, n_t + 2)
    bool, r_diag (n, n_t + 2, 3) the diagonal of R (triads, gyro), r_zupt (3, 3) the zero-velocity R.
    Written per step: x_prior, x_post (n, n_x), P_prior, P_post, F_hist (n, n_e, n_e) and Q_hist
    (n, n_e, n_e) — or Q_hist (1, n_e, n_e), one scratch matrix, when the Q history is not kept; per
    step and channel the predicted measurement inn_zp and innovation inn_y (n, n_t + 2, 3), its
    covariance inn_S (n, n_t + 2, 3, 3) and NIS inn_nis (n, n_t + 2).
    Dynamic mode (``bungee[0] > 0``): ``bungee`` (13,) = [on, anchor (3) [m, SPF], attachment (3)
    [m, body], rest length [m], count / mass [1/kg], release time, cut time [s], unused (2)] and
    ``coeffs`` (n_c,) the per-bungee force polynomial [N/m^k] (:class:`~workbench.problems.droptest.model.BungeeModel`):
    the bungee increment between release and cut (:func:`bungee_step`) and the force steps at
    release and cut, as in ``pipeline.forward_pass``'s transition; ``bungee[0] = 0``: kinematic.
    Returns (status, step, channel): status 0 ok, 1 an S not positive definite, 2 a non-finite NIS.
    """
    n_e = P.shape[0]
    n_x = x.shape[0]
    n_t = lever.shape[0]
    has_bias = n_x >= 31 + 3 * n_t
    xn = np.empty_like(x)
    T = np.empty((NC, n_e))
    W = np.empty((9, n_e))
    M = np.empty((n_e, n_e))
    L = np.zeros((3, 3))
    v = np.empty((4, n_e))
    w3 = np.empty((8, 3, 3))
    bw = np.empty((8, 3, 3))
    zp = np.empty(3)
    z = np.empty(3)
    y = np.empty(3)
    S = np.empty((3, 3))
    R = np.zeros((3, 3))
    Hc = np.empty((3, 15))
    cols = np.empty(15, dtype=np.int64)
    for k in range(k_a, k_b + 1):
        Fk = F_hist[k]
        Qk = Q_hist[k] if Q_hist.shape[0] > 1 else Q_hist[0]
        if k > 0:
            dt = t[k] - t[k - 1]
            propagate_kinematic(x, dt, g, xn, Fk, w3)
            if bungee[0] > 0.0:
                t0, t1 = t[k - 1], t[k]
                if bungee[11] <= t0 and t1 <= bungee[12]:
                    bungee_step(x, xn, Fk, dt, bungee, coeffs, bw)
                if t0 < bungee[11] <= t1:  # the release rope lets go: a jumps from -g to the bungee pull
                    _bungee_jump(xn, bungee, coeffs, g, 1.0, bw)
                if t0 < bungee[12] <= t1:  # the hammer hits the nail: the bungee pull vanishes
                    _bungee_jump(xn, bungee, coeffs, g, -1.0, bw)
            _dcm(xn[9:13], w3[0])  # the attitude at the end of the step (w3[0] free again)
            process_noise_into(dt, q_accel[k], q_angular[k], w3[0], Qk, w3[6])
            predict_covariance(P, Fk, Qk, T)
            for i in range(n_x):
                x[i] = xn[i]
        else:
            for i in range(n_e):
                for j in range(n_e):
                    Fk[i, j] = 1.0 if i == j else 0.0
                    Qk[i, j] = 0.0
        copy_matrix(P, P_prior[k])
        for i in range(n_x):
            x_prior[k, i] = x[i]
        for c in range(n_t + 2):
            if not valid[k, c]:
                continue
            if c < n_t:
                nc = triad_into(x, lever[c], c, has_bias, zp, Hc, cols, w3)
            elif c == n_t:
                nc = gyro_into(x, zp, Hc, cols)
            else:  # zero velocity while hanging: h(x) = v
                nc = 3
                for a in range(3):
                    zp[a] = x[3 + a]
                    cols[a] = 3 + a
                    for b in range(3):
                        Hc[a, b] = 1.0 if a == b else 0.0
            for a in range(3):
                z[a] = z_meas[k, c, a]
                for b in range(3):
                    R[a, b] = r_zupt[a, b] if c > n_t else (r_diag[k, c, a] if a == b else 0.0)
            nis, st = joseph_update(P, z, zp, Hc, cols, nc, R, y, S, W, M, L, v)
            if st == 0:
                boxplus_into(x, v[3])
            for a in range(3):
                inn_zp[k, c, a] = zp[a]
                inn_y[k, c, a] = y[a]
                for b in range(3):
                    inn_S[k, c, a, b] = S[a, b]
            inn_nis[k, c] = nis
            if st:
                return st, k, c
        copy_matrix(P, P_post[k])
        for i in range(n_x):
            x_post[k, i] = x[i]
    return 0, -1, -1
