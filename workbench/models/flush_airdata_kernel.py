"""Compiled (numba) multilinear interpolation of the flush-air-data pressure table.

:meth:`workbench.models.flush_airdata.SurfacePressureTable.cp` interpolates its 4-D Cp grid
(Mach × α_T × relative clock × s) linearly; its reference path is scipy's
``RegularGridInterpolator(method="linear")`` (``cp(..., fast=False)``), whose per-call overhead
dominates the least squares' Jacobians (a few thousand points per call, hundreds of calls per
fit).  :func:`multilinear4` does scipy's arithmetic in scipy's order — the cell of each
coordinate by its rule (``grid[i] ≤ x < grid[i + 1]``, the last cell closed), the normalised
distance ``(x − grid[i]) / (grid[i + 1] − grid[i])``, the 16 corners in ``itertools.product``
order with the weight ``((w0 w1) w2) w3`` and the terms summed in that order — so the two paths
agree bit for bit (tests/models/test_flush_airdata_kernel.py).
"""

from __future__ import annotations

import numpy as np

from workbench.core.jit import njit

__all__ = ["out_of_grid", "multilinear4"]


@njit
def out_of_grid(g0, g1, g2, g3, pts):  # pragma: no cover - compiled
    """The first axis (0..3) along which a point of ``pts`` (n, 4) is off its grid (``g0`` … ``g3``,
    ascending) or NaN, −1 when every point is on the grid (scipy's ``bounds_error`` test)."""
    lo = np.array([g0[0], g1[0], g2[0], g3[0]])
    hi = np.array([g0[-1], g1[-1], g2[-1], g3[-1]])
    first = 4
    for j in range(pts.shape[0]):
        for d in range(first):
            v = pts[j, d]
            if not (lo[d] <= v and v <= hi[d]):
                first = d
                break
    return -1 if first == 4 else first


@njit
def _cell(grid, v):  # pragma: no cover - compiled
    """(i, t): the cell ``grid[i] ≤ v < grid[i + 1]`` (the last closed) and the fraction of v in it."""
    n = grid.shape[0]
    lo, hi = 0, n  # np.searchsorted(grid, v, side="right"), bisected: numba's compiles for seconds
    if v != v:
        lo = n
    while lo < hi:
        mid = (lo + hi) >> 1
        if grid[mid] <= v:
            lo = mid + 1
        else:
            hi = mid
    i = lo - 1
    if i < 0:
        i = 0
    if i > n - 2:
        i = n - 2
    return i, (v - grid[i]) / (grid[i + 1] - grid[i])


@njit
def multilinear4(g0, g1, g2, g3, values, pts, out):  # pragma: no cover - compiled
    """Linear interpolation of ``values`` (n0, n1, n2, n3) on the grid ``g0`` … ``g3`` (ascending)
    at the points ``pts`` (n, 4) (on the grid: :func:`out_of_grid`) into ``out`` (n,)."""
    for j in range(pts.shape[0]):
        i0, t0 = _cell(g0, pts[j, 0])
        i1, t1 = _cell(g1, pts[j, 1])
        i2, t2 = _cell(g2, pts[j, 2])
        i3, t3 = _cell(g3, pts[j, 3])
        acc = 0.0
        for b0 in range(2):
            w0 = t0 if b0 else 1.0 - t0
            for b1 in range(2):
                w1 = t1 if b1 else 1.0 - t1
                for b2 in range(2):
                    w2 = t2 if b2 else 1.0 - t2
                    for b3 in range(2):
                        w3 = t3 if b3 else 1.0 - t3
                        acc = acc + values[i0 + b0, i1 + b1, i2 + b2, i3 + b3] * (((w0 * w1) * w2) * w3)
        out[j] = acc
