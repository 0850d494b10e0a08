"""Sliding medians evaluated only where they are used.

A pre-smoothed, decimated observation keeps one sliding median in every ``decimate`` samples, and
only where the whole window lies inside the data (``post2`` ``median_window``): filtering every
sample and then dropping most of them sorts every window for nothing.  :func:`window_median_at`
gives the same numbers as :func:`scipy.ndimage.median_filter` (``size=(w, 1)``, any ``mode``) at the
rows asked for, by one partial sort per kept window.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

__all__ = ["window_median_at"]


def window_median_at(z: np.ndarray, w: int, rows: np.ndarray) -> np.ndarray:
    """``median_filter(z, size=(w, 1), mode="nearest")[rows]`` for z (n, d) whose windows at ``rows``
    (k,) lie wholly inside z: row i's window spans i − w//2 … i + w − 1 − w//2 (scipy's), its value
    the window's element of rank w//2 per column (scipy's rank, an even w included) → (k, d), in z's
    unit.  Data with NaN, or a window reaching past an end, go through scipy itself."""
    z = np.asarray(z, dtype=float)
    rows = np.asarray(rows, dtype=np.int64)
    lo = rows - w // 2
    if rows.size == 0 or np.any(lo < 0) or np.any(lo + w > z.shape[0]) or np.isnan(z).any():
        return median_filter(z, size=(w, 1), mode="nearest")[rows]
    win = z[lo[:, None] + np.arange(w)[None, :]]  # (k, w, d)
    return np.partition(win, w // 2, axis=1)[:, w // 2]
