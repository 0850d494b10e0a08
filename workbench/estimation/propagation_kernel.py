"""Compiled (numba) first-order covariance propagation ``J P Jᵀ`` of a history of samples.

:func:`workbench.estimation.ekf.derived_with_sigma` propagates each sample's state covariance
through the Jacobian of the derived quantities; its reference path is
``np.einsum("nkj,nji,nli->nkl", J, P, J)`` (``compiled=False``), whose unoptimised three-operand
loop is the cost of a filter's output stage.  :func:`sandwich` does that loop's arithmetic in its
order — per output entry one accumulator over j, then i, of ``(J[k, j] P[j, i]) J[l, i]`` — so
the two paths agree bit for bit (tests/estimation/test_propagation_kernel.py).
"""

from __future__ import annotations

import numpy as np

from workbench.core.jit import njit

__all__ = ["sandwich"]


@njit
def sandwich(J, P, out):  # pragma: no cover - compiled
    """``out[n] = J[n] P[n] J[n]ᵀ`` for J (n, k, m), P (n, m, m), out (n, k, k) (written), summed
    as ``np.einsum("nkj,nji,nli->nkl", J, P, J)`` sums."""
    n, k, m = J.shape
    T = np.empty((m, m))
    for s in range(n):
        for a in range(k):
            for j in range(m):
                for i in range(m):
                    T[j, i] = J[s, a, j] * P[s, j, i]
            for b in range(k):
                acc = 0.0
                for j in range(m):
                    for i in range(m):
                        acc += T[j, i] * J[s, b, i]
                out[s, a, b] = acc
