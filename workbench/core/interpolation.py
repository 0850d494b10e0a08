"""Piecewise-linear interpolation of sampled rows (time histories of vectors, quaternions, matrices).

One convention everywhere: the arguments are in :func:`numpy.interp` order — query times first,
then the sample times, then the samples — and outside the sampled interval the end rows are held
(no extrapolation).  Each component is interpolated with :func:`numpy.interp`, so the result is
exactly a sample where a query time equals a sample time.
"""

from __future__ import annotations

import numpy as np

__all__ = ["interp_rows"]


def interp_rows(t: np.ndarray | float, t_src: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Rows ``y`` (n, ...) sampled at increasing times ``t_src`` (n,), linearly interpolated to ``t``.

    ``t`` is a scalar or an array of query times (any shape S; same unit as ``t_src``, usually s).
    Returns shape ``S + y.shape[1:]``: for ``y`` (n,) the same as ``np.interp(t, t_src, y)``; for
    ``y`` (n, 3) an (m, 3) array; for ``y`` (n, 3, 3) an (m, 3, 3) array.  Query times before
    ``t_src[0]`` or after ``t_src[-1]`` get the first or last row.  Quaternion rows come back
    un-normalised (normalise them, and make neighbouring samples' signs agree first).
    """
    y = np.asarray(y, dtype=float)
    t_src = np.asarray(t_src, dtype=float)
    if y.shape[:1] != t_src.shape:
        raise ValueError(f"interp_rows: {t_src.shape} sample times for rows of shape {y.shape}")
    if y.ndim == 1:
        return np.interp(t, t_src, y)
    flat = y.reshape(y.shape[0], -1)
    out = np.stack([np.interp(t, t_src, flat[:, j]) for j in range(flat.shape[1])], -1)
    return out.reshape(np.shape(t) + y.shape[1:])
