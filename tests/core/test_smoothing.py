"""window_median_at against scipy's median_filter (its reference) at the rows it is asked for."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import median_filter

from workbench.core.smoothing import window_median_at


@pytest.mark.parametrize("w", [2, 3, 40, 41, 100, 200])
def test_window_median_is_scipys_median_filter_at_the_rows(w):
    """Odd and even windows, ties (quantised values), two columns, every row whose window is inside
    and a decimated subset: the same numbers, to the bit."""
    rng = np.random.default_rng(w)
    n = 3 * w + 17
    z = np.round(rng.normal(size=(n, 2)) * 4.0) / 4.0  # many equal values
    ref = median_filter(z, size=(w, 1), mode="nearest")
    inside = np.arange(w // 2, n - (w - 1 - w // 2))
    for rows in (inside, inside[::w], inside[:1]):
        np.testing.assert_array_equal(window_median_at(z, w, rows), ref[rows])


def test_window_median_falls_back_to_scipy_at_the_edges_and_on_nan():
    rng = np.random.default_rng(1)
    z = rng.normal(size=(50, 1))
    ref = median_filter(z, size=(9, 1), mode="nearest")
    rows = np.array([0, 3, 25, 49])  # windows reaching past both ends
    np.testing.assert_array_equal(window_median_at(z, 9, rows), ref[rows])
    z[20] = np.nan
    ref = median_filter(z, size=(9, 1), mode="nearest")
    np.testing.assert_array_equal(window_median_at(z, 9, np.arange(4, 46)), ref[4:46])
