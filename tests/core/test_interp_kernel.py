"""core.interp_kernel: the compiled scalar np.interp against numpy's, to the bit."""

import numpy as np

from workbench.core.interp_kernel import interp_at, interp_index, interp_index_near


def test_interp_at_is_numpys_interp_to_the_bit():
    """Uneven increasing nodes; x below, at, between and above the nodes, at the last node, NaN."""
    rng = np.random.default_rng(4)
    xp = np.cumsum(rng.uniform(0.1, 3.0, 40))
    fp = rng.normal(0.0, 1e3, 40)
    x = np.concatenate([rng.uniform(xp[0] - 5, xp[-1] + 5, 500), xp, [xp[0] - 1, xp[-1] + 1, np.nan]])
    got = np.array([interp_at(interp_index(v, xp), v, xp, fp) for v in x])
    want = np.interp(x, xp, fp)
    assert np.array_equal(got, want, equal_nan=True)
    inv = (xp.size - 1) / (xp[-1] - xp[0])
    assert all(interp_index_near(v, xp, inv) == interp_index(v, xp) for v in x[:-1])


def test_interp_at_on_one_node_holds_its_value():
    xp, fp = np.array([2.0]), np.array([7.0])
    assert [interp_at(interp_index(v, xp), v, xp, fp) for v in (1.0, 2.0, 3.0)] == [7.0, 7.0, 7.0]
