"""The compiled ``J P Jᵀ`` of ``derived_with_sigma`` agrees with ``np.einsum``, its reference, to the bit.

Contiguous operands and the layouts ``derived_with_sigma`` passes (a transposed Jacobian, the
leading block of a larger covariance), and the whole function on both paths.
"""

from __future__ import annotations

import numpy as np

from workbench.estimation.ekf import ErrorStateLayout, derived_with_sigma
from workbench.estimation.propagation_kernel import sandwich


def _einsum(J, P):
    return np.einsum("nkj,nji,nli->nkl", J, P, J)


def test_sandwich_is_einsums_sum_to_the_bit():
    rng = np.random.default_rng(5)
    n, k, m = 300, 9, 15
    J = rng.standard_normal((n, k, m))
    A = rng.standard_normal((n, m, m))
    P = A @ np.swapaxes(A, 1, 2)
    Jt = np.swapaxes(rng.standard_normal((n, m, k)) / 3.0, 1, 2)  # a transposed view
    B = rng.standard_normal((n, 40, 40))
    Pb = (B @ np.swapaxes(B, 1, 2))[:, :m, :m]  # the leading block of a larger covariance
    for JJ, PP in ((J, P), (Jt, Pb), (J[:, :1], P)):
        out = np.empty((JJ.shape[0], JJ.shape[1], JJ.shape[1]))
        sandwich(JJ, PP, out)
        assert np.array_equal(out, _einsum(JJ, PP))


def test_derived_with_sigma_paths_agree():
    rng = np.random.default_rng(6)
    layout = ErrorStateLayout(6)
    x = rng.standard_normal((50, 6))
    A = rng.standard_normal((50, 6, 6))
    P = A @ np.swapaxes(A, 1, 2)

    def g(X):
        return np.stack([np.sin(X[..., 0]) * X[..., 1], X[..., 2] ** 2 + X[..., 3], np.exp(0.1 * X[..., 5])], axis=-1)

    a = derived_with_sigma(g, x, P, layout)
    b = derived_with_sigma(g, x, P, layout, compiled=False)
    for u, v in zip(a, b, strict=True):
        assert np.array_equal(u, v)
