"""Compiled (numba) ``np.interp`` for one scalar at a time, to the bit: the node search and the
arithmetic of numpy's (and numba's) ``arr_interp``, written out so a kernel calling it compiles a
few small functions instead of numba's generic ``np.interp`` (seconds on a fresh checkout).

:func:`interp_index` finds the node (shared when several columns of one table are read at the same
x), :func:`interp_index_near` finds the same node from a guess on a nearly even table, and
:func:`interp_at` interpolates. ``tests/core/test_interp_kernel.py`` pins them against ``np.interp``.
"""

from __future__ import annotations

import math

from workbench.core.jit import njit

__all__ = ["interp_at", "interp_index", "interp_index_near"]


@njit
def interp_index(x, xp):
    """The node index of ``np.interp(x, xp, ·)`` for a scalar x and increasing nodes xp (n,): −1 below
    xp[0], n above xp[n − 1], else the largest j with xp[j] ≤ x (n − 1 at the last node)."""
    n = xp.size
    if x < xp[0]:
        return -1
    if x > xp[n - 1]:
        return n
    lo, hi = 0, n  # first index with xp[i] > x, minus one
    while lo < hi:
        mid = (lo + hi) // 2
        if xp[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return lo - 1


@njit
def interp_index_near(x, xp, inv_step):
    """:func:`interp_index` (the same index) found from the guess ``(x − xp[0]) · inv_step`` and a
    few steps to the neighbouring nodes (a table of nearly even nodes), else by bisection."""
    n = xp.size
    if x < xp[0]:
        return -1
    if x > xp[n - 1]:
        return n
    g = (x - xp[0]) * inv_step
    if not (g >= 0.0 and g < n):  # NaN, no spacing given, or off the table
        return interp_index(x, xp)
    j = int(g)
    for _ in range(4):  # the answer: xp[j] <= x < xp[j + 1] (j = n − 1 at the last node)
        if j + 1 < n and xp[j + 1] <= x:
            j += 1
        elif xp[j] > x:
            j -= 1
        else:
            return j
    return interp_index(x, xp)


@njit
def interp_at(j, x, xp, fp):
    """``np.interp(x, xp, fp)`` for a scalar x with its node index j (:func:`interp_index`): the
    branches and the arithmetic of numpy's (and numba's) ``arr_interp``, to the bit (NaN x: NaN)."""
    n = xp.size
    if math.isnan(x):
        return x
    if j == -1:
        return fp[0]
    if j >= n - 1:
        return fp[n - 1]
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    res = slope * (x - xp[j]) + fp[j]
    if math.isnan(res):
        res = slope * (x - xp[j + 1]) + fp[j + 1]
        if math.isnan(res) and fp[j] == fp[j + 1]:
            res = fp[j]
    return res
