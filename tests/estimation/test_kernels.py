"""The compiled Joseph-form update (``workbench.estimation.kernels``) against the reference path,
:func:`workbench.estimation.ekf.update`: same innovation, S, NIS, increment and covariance; the
shared loop helpers against the numpy expressions they replace in the kernels, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.estimation.ekf import ErrorStateLayout, update
from workbench.estimation.kernels import add_into, cho_solve, joseph_update, symmetrise


def _random_spd(rng, n):
    A = rng.standard_normal((n, n))
    return A @ A.T + n * np.eye(n)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_compiled_update_is_the_reference_update(seed):
    rng = np.random.default_rng(seed)
    n_e, nc = 12, 5
    P = _random_spd(rng, n_e)
    cols = np.sort(rng.choice(n_e, nc, replace=False)).astype(np.int64)
    Hc = rng.standard_normal((3, nc))
    H = np.zeros((3, n_e))
    H[:, cols] = Hc
    R = _random_spd(rng, 3) * 0.1
    x = rng.standard_normal(n_e)
    z = H @ x + rng.standard_normal(3)
    ref = update(x, P, z, lambda s: H @ s, R, ErrorStateLayout(n_e), H=H)

    Pk = P.copy()
    y, S = np.empty(3), np.empty((3, 3))
    W, M, L, v = np.empty((9, n_e)), np.empty((n_e, n_e)), np.zeros((3, 3)), np.empty((4, n_e))
    nis, status = joseph_update(Pk, z, H @ x, Hc, cols, nc, R, y, S, W, M, L, v)
    assert status == 0
    np.testing.assert_allclose(y, ref.y, rtol=0, atol=1e-12)
    np.testing.assert_allclose(S, ref.S, rtol=1e-12, atol=1e-12)
    assert nis == pytest.approx(ref.nis, rel=1e-12)
    np.testing.assert_allclose(x + v[3], ref.x_post, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Pk, ref.P_post, rtol=0, atol=1e-11 * np.abs(P).max())
    assert np.array_equal(Pk, Pk.T) and np.all(np.linalg.eigvalsh(Pk) > 0)


def test_a_non_positive_definite_S_leaves_P_untouched():
    n_e = 4
    P = np.zeros((n_e, n_e))
    Hc, cols, R = np.eye(3), np.arange(3, dtype=np.int64), np.zeros((3, 3))
    y, S = np.empty(3), np.empty((3, 3))
    W, M, L, v = np.empty((9, n_e)), np.empty((n_e, n_e)), np.zeros((3, 3)), np.empty((4, n_e))
    nis, status = joseph_update(P, np.ones(3), np.zeros(3), Hc, cols, 3, R, y, S, W, M, L, v)
    assert status == 1 and not P.any()


def test_the_loop_helpers_give_the_bits_of_the_numpy_expressions():
    rng = np.random.default_rng(3)
    A, B = rng.standard_normal((7, 7)), rng.standard_normal((7, 7))
    S = A.copy()
    symmetrise(S)
    assert np.array_equal(S, 0.5 * (A + A.T)) and np.array_equal(S, S.T)
    C = A.copy()
    add_into(C, B)
    assert np.array_equal(C, A + B)
    P = _random_spd(rng, 4)
    L = np.linalg.cholesky(P)
    b, out = rng.standard_normal(4), np.empty(4)
    cho_solve(L, b, out)
    np.testing.assert_allclose(P @ out, b, rtol=0, atol=1e-12)
