"""Rauch-Tung-Striebel fixed-interval smoother for the error-state EKF of :mod:`.ekf`.

It consumes a recorded :class:`~workbench.estimation.ekf.ForwardPass` (the Orekit pattern: the
filter is observed, then smoothed backwards) and returns a :class:`SmoothedPass`.  In the error
state, with ``F[k+1]`` the transition *from* step k *to* step k+1 as recorded by the driver:

    G_k   = P_post[k] F[k+1]ᵀ P_prior[k+1]⁻¹                 (Cholesky solve, no inverse)
    δx_k  = G_k (x_s[k+1] ⊟ x_prior[k+1])
    x_s[k] = x_post[k] ⊞ δx_k
    P_s[k] = P_post[k] + G_k (P_s[k+1] − P_prior[k+1]) G_kᵀ   (symmetrised, checked PD)

filterpy's ``rts_smoother`` indexes a time-varying F with the wrong step (filterpy issue #278);
here ``F[k+1]`` is the Jacobian used to predict ``P_prior[k+1]`` from ``P_post[k]``, so the gain
is exact for linear time-varying systems (pinned against a batch least-squares test).

Attitude error: body-frame small angle, ``q_true = q ⊗ exp(δθ)`` (docs/ARCHITECTURE.md).  As in the filter,
the covariance is not transported between the tangent spaces of ``x_prior[k+1]`` and
``x_s[k+1]`` (first-order, standard for multiplicative smoothers).

References: Rauch, Tung & Striebel, AIAA J. 3(8), 1965; Särkkä, *Bayesian Filtering and
Smoothing*, 2013, Sect. 8.2 (EKF/RTS); Solà 2017 for the error-state form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from workbench.estimation.ekf import ErrorStateLayout, ForwardPass

__all__ = ["SmoothedPass", "rts_smooth"]


@dataclass(frozen=True)
class SmoothedPass:
    """Smoothed (fixed-interval) estimates: ``t`` (n,) [s]; ``x`` (n, n_x); ``P`` (n, n_e, n_e)
    smoothed-pass covariance (error state); ``G`` (n, n_e, n_e) smoother gains (``G[n-1] = 0``)."""

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    G: np.ndarray


def rts_smooth(fp: ForwardPass, layout: ErrorStateLayout) -> SmoothedPass:
    """Error-state RTS smoothing of a forward pass (formulas in the module docstring).

    ``fp``: output of :func:`~workbench.estimation.ekf.run_filter` (or any ForwardPass with
    ``F[k]`` the transition from k−1 to k).  Raises ``ValueError`` naming the step if a predicted
    covariance cannot be factorised or a smoothed covariance is not positive definite.
    """
    n = fp.t.shape[0]
    n_e = layout.n_e
    xs = np.empty_like(fp.x_post)
    Ps = np.empty_like(fp.P_post)
    G = np.zeros((n, n_e, n_e))
    if n == 0:
        return SmoothedPass(fp.t, xs, Ps, G)
    xs[-1] = fp.x_post[-1]
    Ps[-1] = fp.P_post[-1]
    _check_pd(Ps[-1], n - 1, fp.t)
    for k in range(n - 2, -1, -1):
        Pp = fp.P_prior[k + 1]
        c, info = lapack.dpotrf(Pp, lower=1)
        if info != 0:
            raise ValueError(
                f"RTS smoother: predicted covariance P_prior[{k + 1}] (t={fp.t[k + 1]} s) is not "
                f"positive definite (potrf info={info})"
            )
        # Gᵀ = P_prior[k+1]⁻¹ F[k+1] P_post[k]   (P_post symmetric)
        Gt, _ = lapack.dpotrs(c, fp.F[k + 1] @ fp.P_post[k], lower=1)
        Gk = Gt.T
        dx = Gk @ layout.boxminus(xs[k + 1], fp.x_prior[k + 1])
        xs[k] = layout.boxplus(fp.x_post[k], dx)
        A = fp.P_post[k] + Gk @ (Ps[k + 1] - Pp) @ Gt
        A = 0.5 * (A + A.T)
        _check_pd(A, k, fp.t)
        Ps[k] = A
        G[k] = Gk
    return SmoothedPass(fp.t, xs, Ps, G)


def _check_pd(A: np.ndarray, k: int, t: np.ndarray) -> None:
    if not np.all(np.isfinite(A)):
        raise ValueError(f"RTS smoother: smoothed covariance at step {k} (t={t[k]} s) is not finite")
    _, info = lapack.dpotrf(A, lower=1)
    if info != 0:
        w = np.linalg.eigvalsh(A)
        raise ValueError(
            f"RTS smoother: smoothed covariance at step {k} (t={t[k]} s) is not positive definite "
            f"(smallest eigenvalue {w[0]:.3e}); the forward pass is inconsistent (P_prior vs F P_post Fᵀ + Q)"
        )
