"""Tests of workbench.core.interpolation.interp_rows against hand-computed values and a loop over
scalar linear interpolation written out here (not numpy.interp)."""

import numpy as np
import pytest

from workbench.core.interpolation import interp_rows


def _lerp(t, ts, y):
    """Reference: scalar piecewise-linear interpolation of one row, end rows held outside."""
    if t <= ts[0]:
        return y[0]
    if t >= ts[-1]:
        return y[-1]
    j = max(k for k in range(len(ts) - 1) if ts[k] <= t)
    a = (t - ts[j]) / (ts[j + 1] - ts[j])
    return (1.0 - a) * y[j] + a * y[j + 1]


def test_vectors_match_reference_and_hit_samples_exactly():
    rng = np.random.default_rng(3)
    ts = np.cumsum(rng.uniform(0.1, 1.0, 12))
    y = rng.normal(size=(12, 3))
    tq = np.concatenate([[ts[0] - 1.0], rng.uniform(ts[0], ts[-1], 30), ts, [ts[-1] + 2.0]])
    out = interp_rows(tq, ts, y)
    assert out.shape == (tq.size, 3)
    ref = np.array([_lerp(t, ts, y) for t in tq])
    np.testing.assert_allclose(out, ref, rtol=1e-13, atol=1e-13)
    np.testing.assert_array_equal(interp_rows(ts, ts, y), y)  # exact at the sample times
    np.testing.assert_array_equal(out[0], y[0])  # held before the first sample
    np.testing.assert_array_equal(out[-1], y[-1])  # and after the last


def test_hand_values_and_shapes():
    ts = np.array([0.0, 1.0, 3.0])
    y = np.array([[0.0, 10.0], [1.0, 20.0], [5.0, 0.0]])
    np.testing.assert_allclose(interp_rows(np.array([0.5, 2.0]), ts, y), [[0.5, 15.0], [3.0, 10.0]])
    # a scalar query gives one row; a 1-D history behaves as numpy.interp
    np.testing.assert_allclose(interp_rows(2.0, ts, y), [3.0, 10.0])
    assert interp_rows(2.0, ts, y).shape == (2,)
    assert interp_rows(0.25, ts, y[:, 1]) == pytest.approx(12.5)
    # rows of matrices keep their trailing shape
    m = np.arange(3 * 2 * 2, dtype=float).reshape(3, 2, 2)
    out = interp_rows(np.array([0.5, 2.0, 2.5]), ts, m)
    assert out.shape == (3, 2, 2)
    np.testing.assert_allclose(out[0], 0.5 * (m[0] + m[1]))
    np.testing.assert_allclose(out[1], 0.5 * (m[1] + m[2]))
    np.testing.assert_allclose(out[2], 0.25 * m[1] + 0.75 * m[2])


def test_mismatched_lengths_raise():
    with pytest.raises(ValueError):
        interp_rows(np.array([0.5]), np.array([0.0, 1.0]), np.zeros((3, 2)))
