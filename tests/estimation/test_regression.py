"""partial_coefficient: the coefficient of one regressor with the nuisance projected out equals the
full least-squares fit's, its σ is honest over many noise draws, and a rank-deficient nuisance costs
precision, not a failure."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.estimation.regression import partial_coefficient


def _design(rng, n=200):
    t = np.linspace(-1.0, 1.0, n)
    N = np.column_stack([np.ones(n), t, np.sin(3 * t), t**2])
    d = np.exp(-((t - 0.1) ** 2) / 0.01)  # a pulse, like dh/dt over an impact
    return N, d


def test_equals_the_full_least_squares_fit():
    rng = np.random.default_rng(3)
    N, d = _design(rng)
    y = N @ np.array([0.3, -1.0, 0.2, 0.5]) + 0.7 * d + rng.normal(0.0, 1.0, d.size)
    fit = partial_coefficient(N, d, y)
    A = np.column_stack([N, d])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    assert fit.coef == pytest.approx(coef[-1], rel=1e-10)
    assert fit.sigma == pytest.approx(np.sqrt(max(fit.chi2_red, 1.0) * cov[-1, -1]), rel=1e-10)
    assert fit.dof == d.size - 5


def test_sigma_is_honest_over_noise_draws():
    rng = np.random.default_rng(4)
    N, d = _design(rng)
    z = []
    for _ in range(400):
        y = N @ rng.normal(0.0, 5.0, 4) + 0.7 * d + rng.normal(0.0, 1.0, d.size)
        f = partial_coefficient(N, d, y)
        z.append((f.coef - 0.7) / f.sigma)
    z = np.asarray(z)
    assert abs(z.mean()) < 0.2
    assert 0.85 < z.std() < 1.1  # σ scaled by √χ²ᵣ only above 1: slightly conservative


def test_rank_deficient_nuisance_and_degenerate_inputs():
    rng = np.random.default_rng(5)
    N, d = _design(rng)
    y = N @ np.array([0.3, -1.0, 0.2, 0.5]) + 0.7 * d + rng.normal(0.0, 1.0, d.size)
    Ndup = np.column_stack([N, N[:, 1] * 2.0])  # a collinear column: the same span
    a, b = partial_coefficient(N, d, y), partial_coefficient(Ndup, d, y)
    assert b.coef == pytest.approx(a.coef, rel=1e-9) and b.sigma == pytest.approx(a.sigma, rel=1e-9)
    assert partial_coefficient(np.column_stack([N, d]), d, y) is None  # d inside the nuisance's span
    assert partial_coefficient(N[:5], d[:5], y[:5]) is None  # no degree of freedom left
    assert partial_coefficient(np.zeros((d.size, 0)), d, y).dof == d.size - 1  # no nuisance
