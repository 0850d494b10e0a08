"""Compiled (numba) strapdown step with its error transition and process noise: the fast path of
:func:`workbench.estimation.strapdown.rk4_step` followed by
:func:`~workbench.estimation.strapdown.covariance_step` (the reference path) for one state.

:func:`transition_step` integrates ``(v_M, q_M_G, p_M)`` over one IMU interval with the classical
RK4 of ``strapdown._rk4_scalar`` (the same operations in the same order: the same bits), then
evaluates the discrete error transition ``Φ = expm(A dt)`` and the process noise ``Qd`` (second-
order Van Loan series, symmetrised) of ``covariance_step`` at the normalised mean of the two
attitudes, the mean inputs and, optionally, the mean position (point-mass gravity gradient).
Conventions, error state ``[δv_M, δθ_G, δp_M]`` and the A, B, Qc matrices as in
:mod:`workbench.estimation.strapdown`.  ``Φ`` comes from scaling and squaring of a Taylor series
summed to convergence instead of scipy's Padé approximant, and the small matrix products are
plain loops instead of BLAS, so Φ and Qd agree with the reference to rounding (relative ~1e-15,
tests/estimation/test_strapdown_kernel.py), not bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.jit import njit
from workbench.estimation.kernels import copy_matrix, symmetrise

__all__ = ["expm_taylor", "transition_step"]


@njit
def _deriv(v, q, p, f, w, gm, j2k, dv, dq):
    """``strapdown._deriv_scalar``: dv (3,) [m/s²] and dq (4,) written; dp/dt is v."""
    x, y, z = p[0], p[1], p[2]
    r2 = x * x + y * y + z * z
    r = math.sqrt(r2)
    gm_r3 = gm / (r2 * r)
    z2 = 5.0 * (z * z) / r2
    k = j2k / (r2 * r2 * r)
    a = gm_r3 + k * (1.0 - z2)
    gx, gy, gz = -a * x, -a * y, -(gm_r3 + k * (3.0 - z2)) * z
    qx, qy, qz, qw = q[0], q[1], q[2], q[3]
    X, Y, Z = f[0], f[1], f[2]
    tx = 2.0 * (qy * Z - qz * Y)
    ty = 2.0 * (qz * X - qx * Z)
    tz = 2.0 * (qx * Y - qy * X)
    dv[0] = gx + (X + qw * tx + (qy * tz - qz * ty))
    dv[1] = gy + (Y + qw * ty + (qz * tx - qx * tz))
    dv[2] = gz + (Z + qw * tz + (qx * ty - qy * tx))
    wa, wb, wc = w[0], w[1], w[2]
    dq[0] = 0.5 * (qw * wa + qy * wc - qz * wb)
    dq[1] = 0.5 * (qw * wb - qx * wc + qz * wa)
    dq[2] = 0.5 * (qw * wc + qx * wb - qy * wa)
    dq[3] = 0.5 * -(qx * wa + qy * wb + qz * wc)


@njit
def _rk4(v, q, p, f0, w0, f1, w1, dt, gm, j2k):
    """``strapdown._rk4_scalar``: (v1 (3,), q1 (4,), p1 (3,)) after one step of dt [s]."""
    fm = np.empty(3)
    wm = np.empty(3)
    for i in range(3):
        fm[i] = 0.5 * (f0[i] + f1[i])
        wm[i] = 0.5 * (w0[i] + w1[i])
    h = 0.5 * dt
    kv = np.empty((4, 3))
    kq = np.empty((4, 4))
    kp = np.empty((4, 3))
    vs, qs, ps = v.copy(), q.copy(), p.copy()
    for st in range(4):
        if st == 0:
            ff, ww = f0, w0
        elif st == 3:
            ff, ww = f1, w1
        else:
            ff, ww = fm, wm
        if st > 0:
            c = dt if st == 3 else h
            for i in range(3):
                vs[i] = v[i] + c * kv[st - 1, i]
                ps[i] = p[i] + c * kp[st - 1, i]
            for i in range(4):
                qs[i] = q[i] + c * kq[st - 1, i]
        _deriv(vs, qs, ps, ff, ww, gm, j2k, kv[st], kq[st])
        for i in range(3):
            kp[st, i] = vs[i]
    s = dt / 6.0
    v1 = np.empty(3)
    p1 = np.empty(3)
    q1 = np.empty(4)
    for i in range(3):
        v1[i] = v[i] + s * (kv[0, i] + 2.0 * (kv[1, i] + kv[2, i]) + kv[3, i])
        p1[i] = p[i] + s * (kp[0, i] + 2.0 * (kp[1, i] + kp[2, i]) + kp[3, i])
    for i in range(4):
        q1[i] = q[i] + s * (kq[0, i] + 2.0 * (kq[1, i] + kq[2, i]) + kq[3, i])
    nq = math.sqrt(q1[0] * q1[0] + q1[1] * q1[1] + q1[2] * q1[2] + q1[3] * q1[3])
    for i in range(4):
        q1[i] = q1[i] / nq
    return v1, q1, p1


@njit
def expm_taylor(M):
    """Matrix exponential of a small square matrix M (n, n): scaling to a 1-norm ≤ 0.5, the Taylor
    series summed until its terms no longer change the sum, then squaring (Moler & Van Loan,
    "Nineteen dubious ways to compute the exponential of a matrix", SIAM Rev. 2003, method 3)."""
    n = M.shape[0]
    norm = 0.0
    for j in range(n):
        c = 0.0
        for i in range(n):
            c += abs(M[i, j])
        norm = max(norm, c)
    s = 0
    while norm > 0.5:
        norm *= 0.5
        s += 1
    c = 0.5**s
    X = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            X[i, j] = M[i, j] * c
    E = np.zeros((n, n))  # identities (numba's np.eye compiles its k and dtype handling too)
    T = np.zeros((n, n))
    for i in range(n):
        E[i, i] = 1.0
        T[i, i] = 1.0
    E_new = np.empty((n, n))
    for k in range(1, 40):
        T = T @ X
        same = True
        for i in range(n):
            for j in range(n):
                T[i, j] = T[i, j] / k
                E_new[i, j] = E[i, j] + T[i, j]
                same = same and E_new[i, j] == E[i, j]
        if same:
            break
        copy_matrix(E_new, E)
    for _ in range(s):
        E = E @ E
    return E


@njit
def transition_step(v, q, p, f0, w0, f1, w1, dt, sw, sf, sample_dt, q_state_psd, gradient, gm, j2k):
    """One strapdown step and its covariance terms (module docstring).

    v (3,) [m/s], q (4,) ``q_M_G``, p (3,) [m] in M; f0, w0, f1, w1 (3,) the two IMU samples [m/s²,
    rad/s] (body G); dt [s]; sw, sf (3,) the per-sample 1σ of rate [rad/s] and specific force [m/s²]
    over the step (``covariance_step``'s ``sigma_w``, ``sigma_f``); ``sample_dt`` [s] the sampling
    interval of that noise; ``q_state_psd`` (9,) state noise [units²/s] (zeros: none); ``gradient``
    include the gravity gradient at the mean position; ``gm`` [m³/s²], ``j2k`` [m⁵/s²] of the body.
    Returns (v1 (3,), q1 (4,), p1 (3,), Φ (9, 9), Qd (9, 9))."""
    v1, q1, p1 = _rk4(v, q, p, f0, w0, f1, w1, dt, gm, j2k)
    # normalised mean attitude, mean inputs
    dot = q[0] * q1[0] + q[1] * q1[1] + q[2] * q1[2] + q[3] * q1[3]
    qm = np.empty(4)
    for i in range(4):
        qm[i] = q[i] + q1[i] if dot >= 0.0 else q[i] - q1[i]
    nq = math.sqrt(qm[0] * qm[0] + qm[1] * qm[1] + qm[2] * qm[2] + qm[3] * qm[3])
    f = np.empty(3)
    w = np.empty(3)
    for i in range(3):
        f[i] = 0.5 * (f0[i] + f1[i])
        w[i] = 0.5 * (w0[i] + w1[i])
    x, y, z, ww = qm[0] / nq, qm[1] / nq, qm[2] / nq, qm[3] / nq
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = ww * x, ww * y, ww * z
    C = np.empty((3, 3))
    C[0, 0], C[0, 1], C[0, 2] = 1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)
    C[1, 0], C[1, 1], C[1, 2] = 2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)
    C[2, 0], C[2, 1], C[2, 2] = 2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)
    Sf = np.empty((3, 3))
    Sf[0, 0], Sf[0, 1], Sf[0, 2] = 0.0, -f[2], f[1]
    Sf[1, 0], Sf[1, 1], Sf[1, 2] = f[2], 0.0, -f[0]
    Sf[2, 0], Sf[2, 1], Sf[2, 2] = -f[1], f[0], 0.0
    A = np.zeros((9, 9))
    for i in range(3):
        for j in range(3):
            A[i, 3 + j] = -(C[i, 0] * Sf[0, j] + C[i, 1] * Sf[1, j] + C[i, 2] * Sf[2, j])
    A[3, 4], A[3, 5] = w[2], -w[1]
    A[4, 3], A[4, 5] = -w[2], w[0]
    A[5, 3], A[5, 4] = w[1], -w[0]
    for i in range(3):
        A[6 + i, i] = 1.0
    if gradient:
        pm = np.empty(3)
        for i in range(3):
            pm[i] = 0.5 * (p[i] + p1[i])
        r2 = pm[0] * pm[0] + pm[1] * pm[1] + pm[2] * pm[2]
        k = gm / (r2 * math.sqrt(r2))
        c3 = 3.0 * k / r2
        for i in range(3):
            for j in range(3):
                A[i, 6 + j] = c3 * (pm[i] * pm[j]) - (k if i == j else 0.0)
    Adt = np.empty((9, 9))
    for i in range(9):
        for j in range(9):
            Adt[i, j] = A[i, j] * dt
    Phi = expm_taylor(Adt)
    Qc = np.zeros((9, 9))
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for m in range(3):
                acc += (C[i, m] * (sf[m] * sf[m] * sample_dt)) * C[j, m]
            Qc[i, j] = acc
        Qc[3 + i, 3 + i] = sw[i] * sw[i] * sample_dt
    for i in range(9):
        Qc[i, i] += q_state_psd[i]
    AQ = A @ Qc
    AQA = AQ @ A.T
    h2 = 0.5 * dt * dt
    h3 = dt**3 / 3.0
    Qd = np.empty((9, 9))
    for i in range(9):
        for j in range(9):
            Qd[i, j] = Qc[i, j] * dt + (AQ[i, j] + AQ[j, i]) * h2 + AQA[i, j] * h3
    symmetrise(Qd)
    return v1, q1, p1, Phi, Qd
