"""Errors of an entry reconstruction against a truth, and their reported 1σ, in the local frame
(used by the scorecard of a synthetic run and by the smoother validation of
:mod:`workbench.problems.entry.montecarlo`).
"""

from __future__ import annotations

import numpy as np

from workbench.core.frames import ned_basis
from workbench.core.rotation import attitude_error
from workbench.problems.entry.state import DP, DTH, DV

__all__ = ["ERROR_NAMES", "ERROR_UNITS", "local_frame", "errors_sigmas"]

#: Columns of the error / σ curves (estimate − truth), in the local frame at the estimate (north
#: towards the MMED pole): horizontal position N, E [m] and altitude above ground ``|p| − r_ground``
#: [m] (σ along the estimated local vertical); velocity N, E, D [m/s]; attitude error δθ about
#: X_G, Y_G, Z_G [rad] (Z_G the spin axis).
ERROR_NAMES: tuple[str, ...] = ("pos_N", "pos_E", "h_agl", "vel_N", "vel_E", "vel_D", "att_x", "att_y", "att_z")
#: Column blocks of :data:`ERROR_NAMES` after the local position (N, E, h): local velocity (N, E, D), attitude.
_VEL, _ATT = slice(3, 6), slice(6, 9)
ERROR_UNITS: tuple[str, ...] = ("m",) * 3 + ("m/s",) * 3 + ("rad",) * 3


def local_frame(p: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rows north, east, down at positions p (n, 3) in M (north towards the +Z_M pole):
    :func:`workbench.core.frames.ned_basis`."""
    return ned_basis(p)


def errors_sigmas(est, V, Q, X) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Errors of a pass ``est`` (attributes ``v_M`` (n,3) [m/s], ``q_M_G`` (n,4), ``p_M`` (n,3) [m], ``P``
    (n,9,9), MMED) against the truth ``V`` (n,3), ``Q`` (n,4), ``X`` (n,3) on the same samples.

    Returns ``e`` (n, 9) truth ⊟ estimate (Cartesian, the filter's error state), ``e_c`` (n, 9) the
    same with the position error written in curvilinear form about the estimate (horizontal part
    ``(I − ûûᵀ) δp`` plus ``û (|p_t| − |p|)``, û = p/|p|: identical to first order, but free of the
    ``|δp_h|²/2|p|`` curvature term that a tens-of-km horizontal error puts on the Cartesian
    vertical), ``err`` (n, k) estimate − truth of :data:`ERROR_NAMES` and ``sig`` (n, k) the
    reported 1σ (local frame at the estimate; altitude along û).
    """
    e = np.concatenate([V - est.v_M, attitude_error(est.q_M_G, Q), X - est.p_M], axis=1)
    P = est.P
    L = local_frame(est.p_M)
    up = -L[:, 2]
    dh = np.linalg.norm(X, axis=1) - np.linalg.norm(est.p_M, axis=1)  # truth − estimate
    dp = e[:, DP]
    e_c = e.copy()
    e_c[:, DP] = dp - up * np.sum(up * dp, axis=1, keepdims=True) + up * dh[:, None]
    err = np.empty((V.shape[0], len(ERROR_NAMES)))
    sig = np.empty_like(err)
    Ppp = np.einsum("nij,njk,nlk->nil", L, P[:, DP, DP], L)
    err[:, 0:2] = -np.einsum("nij,nj->ni", L[:, 0:2], dp)
    sig[:, 0:2] = np.sqrt(np.einsum("nii->ni", Ppp)[:, 0:2])
    err[:, 2] = -dh
    sig[:, 2] = np.sqrt(Ppp[:, 2, 2])
    Pvv = np.einsum("nij,njk,nlk->nil", L, P[:, DV, DV], L)
    err[:, _VEL] = -np.einsum("nij,nj->ni", L, e[:, DV])
    sig[:, _VEL] = np.sqrt(np.einsum("nii->ni", Pvv))
    err[:, _ATT] = -e[:, DTH]
    sig[:, _ATT] = np.sqrt(np.einsum("nii->ni", P[:, DTH, DTH]))
    return e, e_c, err, sig
