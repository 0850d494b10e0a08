"""The Entry view's names of its two 3σ ellipsoids stay apart when the ellipsoids coincide (fast)."""

from __future__ import annotations

import numpy as np

from workbench.problems.entry.recording import SIGMA_NAME_GAP_M, sigma_name_positions


def test_the_two_ellipsoid_names_stand_apart_when_the_ellipsoids_coincide():
    """At the end of the run the smoothed and forward 3σ ellipsoids are one (the radar fixes both):
    their names, written at the centres, stood on each other ("3σ forward" hidden). The smoothed
    one's is above its top, the forward one's below its bottom."""
    P = np.tile(np.diag([40.0**2, 60.0**2, 42.0**2]), (3, 1, 1))
    P[1] = np.diag([30e3, 20e3, 9e3]) ** 2  # the blackout: kilometres wide
    up, down = sigma_name_positions(P, above=True), sigma_name_positions(P, above=False)
    np.testing.assert_allclose(up[:, :2], 0.0)
    np.testing.assert_allclose(up[:, 2], 3.0 * np.sqrt(P[:, 2, 2]) + SIGMA_NAME_GAP_M)
    np.testing.assert_allclose(down, -up)
    assert np.all(up[:, 2] - down[:, 2] >= 2 * SIGMA_NAME_GAP_M)  # about 40 px at the Entry view's scale
