"""Compiled (numba) estimation kernels: the sequential Joseph-form measurement update that a
problem's compiled filter recursion calls at every step (the drop test's ``droptest/kernel.py``),
and the small loops every compiled filter shares (:func:`copy_vector`, :func:`copy_matrix`,
:func:`add_into`, :func:`symmetrise`, :func:`cho_solve`): an array expression in a kernel
(``A + A.T``, ``x + dx``, ``B.T.copy()``) compiles a loop nest of its own, with numba's broadcasting
and shape checks, in every kernel that writes it; a helper is compiled once per process and gives
the same bits.

:func:`joseph_update` is the same update as :func:`workbench.estimation.ekf.update` (one iteration,
no gate) written for a small measurement with H non-zero in a few columns, allocating nothing:
innovation ``y = z − ẑ``, ``S = H P Hᵀ + R`` (Cholesky), gain ``K = P Hᵀ S⁻¹`` and the covariance
in Joseph form associated as ``M = P − K (P Hᵀ)ᵀ``, ``P⁺ = M − (M Hᵀ − K R) Kᵀ``, symmetrised
(Gelb, *Applied Optimal Estimation*, 1974, Sect. 4.2). The state increment is returned for the
caller's own ⊞ (its quaternion layout). ``tests/estimation/test_kernels.py`` pins it against
:func:`~workbench.estimation.ekf.update`, the reference path.

numba caches each module's kernels beside its source; a kernel calling into this module is
recompiled only when its own source changes, so an edit here needs the callers' caches cleared
(``find workbench -name '*.nbi' -delete``), as for any cross-module numba call.
"""

from __future__ import annotations

import math

from workbench.core.jit import njit

__all__ = ["add_into", "cho_solve", "copy_matrix", "copy_vector", "joseph_update", "symmetrise"]


@njit
def copy_vector(src, dst):
    """Copy src (n,) into dst (n,) element by element (any unit; dst written).

    A kernel's ``dst[k] = src`` with an array on the right compiles numba's shape-mismatch message
    (string formatting) into every caller; this loop compiles to a copy and nothing else."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@njit
def copy_matrix(src, dst):
    """Copy src (n, m) into dst (n, m) element by element (any unit; dst written); see
    :func:`copy_vector` for why a loop and not a slice assignment."""
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


@njit
def add_into(A, B):
    """``A += B`` element by element for A, B (n, m) of one unit (A written): the loop a kernel's
    ``A += B`` or ``A + B`` would compile as an array expression of its own."""
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            A[i, j] += B[i, j]


@njit
def symmetrise(A):
    """``A ← ½(A + Aᵀ)`` in place for a square A (n, n) (any unit): each pair's mean, the diagonal
    untouched; the same bits as numpy's ``0.5 * (A + A.T)``, without the array expression's loop
    nest and temporary that every kernel writing it would compile on its own."""
    n = A.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            u = 0.5 * (A[i, j] + A[j, i])
            A[i, j] = u
            A[j, i] = u


@njit
def cho_solve(L, b, out):
    """Solve ``L Lᵀ out = b`` for a lower Cholesky factor L (m, m); b, out (m,) (out written)."""
    m = L.shape[0]
    for i in range(m):
        s = b[i]
        for c in range(i):
            s -= L[i, c] * out[c]
        out[i] = s / L[i, i]
    for i in range(m - 1, -1, -1):
        s = out[i]
        for c in range(i + 1, m):
            s -= L[c, i] * out[c]
        out[i] = s / L[i, i]


@njit
def joseph_update(P, z, zp, Hc, cols, nc, R, y, S, W, M, L, v):
    """Joseph-form update of the error covariance P (n_e, n_e), in place, by a measurement of size
    3 whose H is non-zero only in the error-state columns ``cols[:nc]`` (values ``Hc[:, :nc]``).

    ``z`` measured and ``zp`` predicted (3,), ``R`` (3, 3), in the measurement's units; writes the
    innovation ``y`` (3,), its covariance ``S`` (3, 3) and the state increment ``dx = K y`` into
    ``v[3]`` (n_e,), for the caller's ⊞. Returns ``(nis, status)``: status 0 ok, 1 S not positive
    definite (P untouched), 2 non-finite NIS (P untouched). Scratch: W (9, n_e) holding (P Hᵀ)ᵀ, Kᵀ,
    (M Hᵀ − K R)ᵀ; M (n_e, n_e); L (3, 3); v (4, n_e)."""
    n_e = P.shape[0]
    m = 3
    PHt = W[0:3]  # (P Hᵀ)ᵀ, rows contiguous: the n_e-long loops below vectorise
    K = W[3:6]  # Kᵀ
    D = W[6:9]  # (M Hᵀ − K R)ᵀ
    for a in range(m):
        y[a] = z[a] - zp[a]
    for i in range(n_e):
        for a in range(m):
            s = 0.0
            for c in range(nc):
                s += P[i, cols[c]] * Hc[a, c]
            PHt[a, i] = s
    for a in range(m):
        for b in range(m):
            s = 0.0
            for c in range(nc):
                s += Hc[a, c] * PHt[b, cols[c]]
            S[a, b] = s + R[a, b]
    # Cholesky S = L Lᵀ (lower)
    for j in range(m):
        s = S[j, j]
        for c in range(j):
            s -= L[j, c] * L[j, c]
        if not s > 0.0:
            return 0.0, 1
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, m):
            s = S[i, j]
            for c in range(j):
                s -= L[i, c] * L[j, c]
            L[i, j] = s / L[j, j]
    # w = S⁻¹ y, nis = yᵀ w
    w, r, kr, dx = v[0, :m], v[1, :m], v[2, :m], v[3]
    cho_solve(L, y, w)
    nis = 0.0
    for a in range(m):
        nis += y[a] * w[a]
    if not math.isfinite(nis):
        return nis, 2
    # K = P Hᵀ S⁻¹ row by row
    for i in range(n_e):
        for a in range(m):
            r[a] = PHt[a, i]
        cho_solve(L, r, kr)
        for a in range(m):
            K[a, i] = kr[a]
    for i in range(n_e):
        dx[i] = K[0, i] * y[0] + K[1, i] * y[1] + K[2, i] * y[2]
    # Joseph form: M = P − K (P Hᵀ)ᵀ, P⁺ = M − (M Hᵀ − K R) Kᵀ, symmetrised
    P0, P1, P2 = PHt[0], PHt[1], PHt[2]
    for i in range(n_e):
        k0, k1, k2 = K[0, i], K[1, i], K[2, i]
        for j in range(n_e):
            M[i, j] = P[i, j] - (k0 * P0[j] + k1 * P1[j] + k2 * P2[j])
    for i in range(n_e):
        for a in range(m):
            s = 0.0
            for c in range(nc):
                s += M[i, cols[c]] * Hc[a, c]
            t = 0.0
            for b in range(m):
                t += K[b, i] * R[b, a]
            D[a, i] = s - t
    K0, K1, K2 = K[0], K[1], K[2]
    for i in range(n_e):
        d0, d1, d2 = D[0, i], D[1, i], D[2, i]
        for j in range(n_e):
            P[i, j] = M[i, j] - (d0 * K0[j] + d1 * K1[j] + d2 * K2[j])
    symmetrise(P)
    return nis, 0
