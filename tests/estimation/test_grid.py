"""Tests of workbench.estimation.grid: measurement nodes inserted at their own time tags."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.estimation.grid import merge_time_tags


def test_merge_snaps_inserts_shares_moves_and_drops():
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    tags = [0.0005, 1.5004, 1.5, 2.25, 3.7, 3.2, -0.5, 4.0008, 5.0, 0.9995]
    g = merge_time_tags(t, tags, 1e-3, no_insert={3})
    np.testing.assert_array_equal(g.t, [0.0, 1.0, 1.5004, 2.0, 2.25, 3.0, 4.0])
    np.testing.assert_array_equal(g.interval, [0, 1, 1, 2, 2, 3, 4])
    np.testing.assert_array_equal(g.base_node, [0, 1, -1, 2, -1, 3, 4])
    np.testing.assert_allclose(g.fraction, [0.0, 0.0, 0.5004, 0.0, 0.25, 0.0, 0.0], rtol=1e-15)
    # 1.5 shares the node inserted for the earlier tag 1.5004 (within tol, same interval);
    # 3.7 and 3.2 lie in the no-insert interval 3 and go to its nearer end
    np.testing.assert_array_equal(g.tag_node, [0, 2, 2, 4, 6, 5, -1, 6, -1, 1])
    np.testing.assert_array_equal(g.tag_snapped, [1, 0, 0, 0, 0, 0, 0, 1, 0, 1])
    np.testing.assert_array_equal(g.tag_moved, [0, 0, 0, 0, 1, 1, 0, 0, 0, 0])
    assert (g.n_outside, g.n_snapped, g.n_moved, g.n_inserted) == (2, 3, 2, 2)


def test_merge_random_tags_invariants():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.03, 400))
    tags = rng.uniform(t[0] - 0.05, t[-1] + 0.05, 300)
    tol = 1e-3
    g = merge_time_tags(t, tags, tol)
    assert np.all(np.diff(g.t) > 0.0)
    np.testing.assert_array_equal(g.t[g.base_node >= 0], t)
    np.testing.assert_array_equal(g.base_node[g.base_node >= 0], np.arange(t.size))
    ins = g.base_node < 0
    assert ins.sum() == g.n_inserted == g.t.size - t.size
    i = g.interval[ins]
    assert np.all((t[i] < g.t[ins]) & (g.t[ins] < t[i + 1]))
    np.testing.assert_allclose(t[i] + g.fraction[ins] * (t[i + 1] - t[i]), g.t[ins], rtol=0, atol=1e-12)
    inside = (tags >= t[0] - tol) & (tags <= t[-1] + tol)
    np.testing.assert_array_equal(g.tag_node >= 0, inside)
    assert g.n_outside == (~inside).sum()
    # every tag in the span is applied within tol of its own time; snapped ones at a base step
    assert np.all(np.abs(g.t[g.tag_node[inside]] - tags[inside]) <= tol)
    assert np.all(g.base_node[g.tag_node[g.tag_snapped]] >= 0)
    assert g.n_moved == 0
    # with tol = 0 every tag in the open span gets a node at exactly its time
    g0 = merge_time_tags(t, tags, 0.0)
    sel = (tags > t[0]) & (tags < t[-1])
    np.testing.assert_array_equal(g0.t[g0.tag_node[sel]], tags[sel])


def test_merge_rejects_bad_base_grid():
    with pytest.raises(ValueError, match="strictly increasing"):
        merge_time_tags(np.array([0.0, 1.0, 1.0]), [0.5], 1e-3)
    with pytest.raises(ValueError, match="strictly increasing"):
        merge_time_tags(np.array([0.0]), [0.5], 1e-3)
