"""Tests of workbench.estimation.smoother: exactness on a linear time-varying system, PD check."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.estimation.ekf import ErrorStateLayout, ForwardPass, Measurement, run_filter
from workbench.estimation.smoother import rts_smooth


def _spd(rng, n, scale):
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T / n + 0.5 * np.eye(n))


def _ltv_problem(seed=0, n=25, d=3):
    """x_k = F_k x_{k-1} + u_k + w_k with F_k, Q_k, H_k all varying; some steps without data,
    some with two measurements (processed sequentially)."""
    rng = np.random.default_rng(seed)
    Fs = [np.eye(d)] + [np.eye(d) + 0.3 * rng.standard_normal((d, d)) for _ in range(1, n)]
    us = [np.zeros(d)] + [rng.standard_normal(d) for _ in range(1, n)]
    Qs = [np.zeros((d, d))] + [_spd(rng, d, 0.2) for _ in range(1, n)]
    meas = {}
    for k in range(n):
        if k % 4 == 3:
            continue  # no measurement at this step
        items = []
        for _ in range(2 if k % 5 == 0 else 1):
            m = int(rng.integers(1, 3))
            H = rng.standard_normal((m, d))
            R = _spd(rng, m, 0.5)
            z = rng.standard_normal(m) * 3
            items.append((H, R, z))
        meas[k] = items
    m0 = rng.standard_normal(d)
    P0 = _spd(rng, d, 2.0)
    return Fs, us, Qs, meas, m0, P0


def _batch_map(Fs, us, Qs, meas, m0, P0):
    """Information matrix Λ (n d, n d) and MAP solution of the whole-batch least-squares problem."""
    n, d = len(Fs), m0.size
    Lam = np.zeros((n * d, n * d))
    eta = np.zeros(n * d)

    def add(rows_A, W, b):
        # rows_A: list of (block index, matrix); residual = Σ A_i x_i − b, weight W
        for i, Ai in rows_A:
            eta[i * d : (i + 1) * d] += Ai.T @ W @ b
            for j, Aj in rows_A:
                Lam[i * d : (i + 1) * d, j * d : (j + 1) * d] += Ai.T @ W @ Aj

    add([(0, np.eye(d))], np.linalg.inv(P0), m0)
    for k in range(1, n):
        add([(k, np.eye(d)), (k - 1, -Fs[k])], np.linalg.inv(Qs[k]), us[k])
    for k, items in meas.items():
        for H, R, z in items:
            add([(k, H)], np.linalg.inv(R), z)
    X = np.linalg.solve(Lam, eta).reshape(n, d)
    C = np.linalg.inv(Lam)
    return X, np.array([C[k * d : (k + 1) * d, k * d : (k + 1) * d] for k in range(n)])


def _run(Fs, us, Qs, meas, m0, P0):
    d = m0.size
    lay = ErrorStateLayout(d)
    t = np.arange(len(Fs), dtype=float)

    def transition(x, t0, t1):
        k = int(round(t1))
        return Fs[k] @ x + us[k], Fs[k]

    def process_noise(x, t0, t1):
        return Qs[int(round(t1))]

    def measurements_at(k, tk, x):
        return [
            Measurement(f"m{i}_{z.size}", z, R, lambda s, H=H: H @ s, H) for i, (H, R, z) in enumerate(meas.get(k, []))
        ]

    fp = run_filter(m0, P0, t, transition, process_noise, measurements_at, lay)
    return fp, rts_smooth(fp, lay)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kf_rts_equals_batch_map_on_linear_time_varying_system(seed):
    Fs, us, Qs, meas, m0, P0 = _ltv_problem(seed)
    fp, sp = _run(Fs, us, Qs, meas, m0, P0)
    X, C = _batch_map(Fs, us, Qs, meas, m0, P0)
    np.testing.assert_allclose(sp.x, X, rtol=1e-9, atol=1e-9 * np.abs(X).max())
    np.testing.assert_allclose(sp.P, C, rtol=1e-9, atol=1e-9 * np.abs(C).max())
    # the filter's last posterior is the smoother's last estimate
    np.testing.assert_array_equal(sp.x[-1], fp.x_post[-1])
    assert np.all(sp.G[-1] == 0.0)
    # smoothing never increases the variance
    var_s = np.diagonal(sp.P, axis1=1, axis2=2)
    assert np.all(var_s <= np.diagonal(fp.P_post, axis1=1, axis2=2) * (1 + 1e-12))


def test_time_varying_F_index_matters():
    """Guard against filterpy #278: using F[k] instead of F[k+1] gives a different (wrong) answer."""
    Fs, us, Qs, meas, m0, P0 = _ltv_problem(0)
    fp, sp = _run(Fs, us, Qs, meas, m0, P0)
    shifted = ForwardPass(
        fp.t, fp.x_prior, fp.P_prior, fp.x_post, fp.P_post, np.concatenate([fp.F[1:], fp.F[-1:]]), fp.Q, fp.innovations
    )
    try:
        wrong = rts_smooth(shifted, ErrorStateLayout(3))
    except ValueError:  # here the mis-indexed gain even drives P_s indefinite
        return
    assert np.max(np.abs(wrong.x - sp.x)) > 1e-3


def test_non_pd_smoothed_covariance_raises_naming_step():
    n = 4
    lay = ErrorStateLayout(1)
    F = np.ones((n, 1, 1))
    F[2] = 10.0  # inconsistent with P_prior[2] below
    P_post = np.ones((n, 1, 1))
    P_post[2:] = 1e-3
    P_prior = np.ones((n, 1, 1))
    fp = ForwardPass(
        np.arange(n, dtype=float), np.zeros((n, 1)), P_prior, np.zeros((n, 1)), P_post, F, np.zeros((n, 1, 1)), {}
    )
    with pytest.raises(ValueError, match="step 1"):
        rts_smooth(fp, lay)
