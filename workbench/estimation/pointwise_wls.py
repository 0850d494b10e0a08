"""Iterated weighted least squares solved independently at every sample, vectorised over samples.

The point-wise fit of a flush air data system (Karlgaard et al. 2009 [R4], Sect. III.A, Eq. 5–10)
and any other problem that fits a small state to one epoch's measurements: at each sample k

    z_k = h(x_k) + ε_k,   ε_k ~ N(0, diag σ_k²)

Gauss–Newton from the reference ``x̄`` (Eq. 6–9): ``x̂ = x̄ + (Hᵀ W H)⁻¹ Hᵀ W (z − h(x̄))`` with
``W = diag(1/σ²)`` and ``H = ∂h/∂x`` at x̄ (Eq. 7; central differences here, so any model —
analytic or tabulated — can be used), iterated by replacing x̄ with x̂; the covariance is
``P = (Hᵀ W H)⁻¹`` (Eq. 10) at the converged state.  All samples are solved together as arrays
``(n, k)``: one model call evaluates every sample.  Measurements with zero weight (``mask``
False or NaN) do not count; a sample with fewer usable measurements than states is returned as
NaN.  A small Levenberg damping (``damping`` × the diagonal) keeps ill-conditioned samples
(e.g. Mach at hypersonic speed) from diverging; the reported P is undamped.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["WlsResult", "iterated_wls", "numeric_jacobian"]


@dataclass(frozen=True)
class WlsResult:
    """``x`` (n, k) estimates, ``P`` (n, k, k) covariance (Eq. 10), ``residual`` (n, m) = z − h(x)
    (NaN where not used), ``used`` (n, m) the measurements that counted, ``iterations`` done,
    ``step`` (n,) the size of the last normalised step (convergence check)."""

    x: np.ndarray
    P: np.ndarray
    residual: np.ndarray
    used: np.ndarray
    iterations: int
    step: np.ndarray


def numeric_jacobian(model: Callable[[np.ndarray], np.ndarray], x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian (n, m, k) of ``model`` (x (n, k) -> (n, m)) with per-sample,
    per-state steps ``steps`` (n, k) (or broadcastable)."""
    n, k = x.shape
    h = np.broadcast_to(np.asarray(steps, float), (n, k))
    cols = []
    for j in range(k):
        e = np.zeros((n, k))
        e[:, j] = h[:, j]
        cols.append((model(x + e) - model(x - e)) / (2.0 * h[:, j : j + 1]))
    return np.stack(cols, axis=-1)


def iterated_wls(
    model: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    z: np.ndarray,
    sigma: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    steps: Callable[[np.ndarray], np.ndarray],
    iterations: int = 10,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
    damping: float = 1e-9,
    tol: float = 1e-3,
) -> WlsResult:
    """Solve every sample's weighted least-squares problem (module docstring).

    ``model(x (n, k)) -> (n, m)``; ``x0`` (n, k) reference states; ``z`` (n, m) measurements,
    ``sigma`` (n, m) or (m,) their 1σ; ``mask`` (n, m) True where usable (NaN in z is unusable
    too); ``steps(x) -> (n, k)`` finite-difference steps; ``lower``/``upper`` (k,) bounds the
    iterate is clipped to.  Stops early when every sample's normalised step (|Δx| relative to
    ``sqrt(diag P)``) is below ``tol``.
    """
    x = np.array(x0, dtype=float)
    z = np.asarray(z, float)
    n, k = x.shape
    sig = np.broadcast_to(np.asarray(sigma, float), z.shape)
    used = np.isfinite(z) & np.isfinite(sig) & (sig > 0)
    if mask is not None:
        used &= np.asarray(mask, bool)
    w = np.where(used, 1.0 / np.where(used, sig, 1.0) ** 2, 0.0)
    zz = np.where(used, z, 0.0)
    enough = used.sum(axis=1) >= k
    lo = -np.inf if lower is None else np.asarray(lower, float)
    hi = np.inf if upper is None else np.asarray(upper, float)
    eye = np.eye(k)
    step_norm = np.full(n, np.inf)
    done = 0
    for it in range(1, iterations + 1):
        done = it
        H = numeric_jacobian(model, x, steps(x))
        r = np.where(used, zz - model(x), 0.0)
        HW = H * w[:, :, None]
        A = np.einsum("nmi,nmj->nij", HW, H)
        b = np.einsum("nmi,nm->ni", HW, r)
        diag = np.einsum("nii->ni", A)
        Ad = A + damping * diag[:, :, None] * eye + 1e-300 * eye
        dx = np.linalg.solve(Ad[enough], b[enough][..., None])[..., 0]
        full = np.zeros((n, k))
        full[enough] = dx
        x = np.clip(x + full, lo, hi)
        sd = np.sqrt(np.maximum(1.0 / np.maximum(diag, 1e-300), 0.0))
        step_norm = np.max(np.abs(full) / np.maximum(sd, 1e-300), axis=1)
        if np.all(step_norm[enough] < tol):
            break
    H = numeric_jacobian(model, x, steps(x))
    HW = H * w[:, :, None]
    A = np.einsum("nmi,nmj->nij", HW, H)
    P = np.full((n, k, k), np.nan)
    d = np.sqrt(np.maximum(np.einsum("nii->ni", A), 1e-300))
    An = A / (d[:, :, None] * d[:, None, :])  # unit diagonal: the determinant measures conditioning
    ok = enough & (np.abs(np.linalg.det(np.where(enough[:, None, None], An, eye))) > 1e-14)
    P[ok] = np.linalg.inv(An[ok]) / (d[ok][:, :, None] * d[ok][:, None, :])
    x[~enough] = np.nan
    res = np.where(used, z - model(np.where(np.isfinite(x), x, np.nan_to_num(x0))), np.nan)
    res[~enough] = np.nan
    return WlsResult(x=x, P=P, residual=res, used=used, iterations=done, step=step_norm)
