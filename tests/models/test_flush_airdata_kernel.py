"""The compiled table interpolation of ``SurfacePressureTable.cp`` agrees with scipy's, its reference.

Random points over and beyond the grid (clamped), every node of each axis (where scipy's cell rule
decides between two cells) and the grid's far corner: the compiled path does scipy's arithmetic
in scipy's order, so the two are identical to the last bit; a NaN coordinate raises as scipy does.
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.io.assets import asset_path
from workbench.models.flush_airdata import build_estimator_table, load_fads_vehicle

TABLE = build_estimator_table(load_fads_vehicle(asset_path("vehicles", "msl_meads.toml")))


def test_compiled_cp_is_scipys_to_the_last_bit():
    rng = np.random.default_rng(3)
    n = 5000
    t = TABLE
    nodes = max(t.mach.size, t.alpha_t.size, t.clock.size, t.s.size)
    m = np.r_[rng.uniform(0.0, 45.0, n), np.resize(t.mach, nodes), t.mach[-1]]
    a = np.r_[rng.uniform(-0.1, 0.6, n), np.resize(t.alpha_t, nodes), t.alpha_t[-1]]
    c = np.r_[rng.uniform(-7.0, 7.0, n), np.resize(t.clock, nodes), t.clock[-1]]
    s = np.r_[rng.uniform(-0.1, 1.1, n), np.resize(t.s, nodes), t.s[-1]]
    ref, fast = t.cp(m, a, c, s, fast=False), t.cp(m, a, c, s)
    assert np.array_equal(fast, ref)
    # the shapes of the least squares' calls: samples × ports
    M, A, C, S = m[:50, None], a[:50, None], c[:50, None] + np.arange(7.0), s[50:57][None, :]
    assert np.array_equal(t.cp(M, A, C, S), t.cp(M, A, C, S, fast=False))


def test_nan_coordinate_raises_like_scipy():
    args = (np.array([np.nan]), np.array([0.2]), np.array([0.5]), np.array([0.5]))
    with pytest.raises(ValueError, match="dimension 0"):
        TABLE.cp(*args, fast=False)
    with pytest.raises(ValueError, match="dimension 0"):
        TABLE.cp(*args)
