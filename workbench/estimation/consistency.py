"""Filter consistency statistics: NEES, NIS, χ² bounds, covariance health, innovation whiteness.

The tests follow Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
Navigation*, 2001, Sect. 5.4: for a consistent filter the normalised estimation error squared
(NEES) of a d-dimensional error is χ²(d) and the normalised innovation squared (NIS) of an
m-dimensional innovation is χ²(m); averaged over N independent Monte Carlo runs, N·ANEES is
χ²(N·d).  Whiteness of an innovation sequence uses the normalised sample autocorrelation with
its ±1.96/√n band (Mehra 1970; Bar-Shalom Sect. 5.4.2).

Attitude errors entering :func:`nees` must use the body-frame convention
(``q_true = q_est ⊗ exp(δθ)``, :func:`workbench.core.rotation.attitude_error`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.special import gammaincinv

__all__ = [
    "nees",
    "nis",
    "anees_bounds",
    "chi2_interval",
    "chi2_ppf",
    "chi2_gate",
    "fraction_inside",
    "is_symmetric_pd",
    "whiteness",
    "mixture_hdr_level",
]


def nees(err: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``eᵀ P⁻¹ e`` per step (linear solve, no inverse).

    err (..., d) estimation error (estimate ⊟ truth or truth ⊟ estimate — the sign does not
    matter), P (..., d, d) its covariance; returns (...,), e.g. (n,) for err (n, d).
    """
    err = np.asarray(err, dtype=float)
    P = np.asarray(P, dtype=float)
    w = np.linalg.solve(P, err[..., None])[..., 0]
    return np.sum(err * w, axis=-1)


def nis(y: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Normalised innovation squared ``yᵀ S⁻¹ y``: y (..., m), S (..., m, m) -> (...,)."""
    return nees(y, S)


def chi2_ppf(q, dof):
    """Quantile of the χ²(dof) distribution at probability ``q`` (scalar or array, in [0, 1]):
    ``2 γ⁻¹(dof/2, q)``, the formula of ``scipy.stats.chi2.ppf`` (same numbers) without importing
    ``scipy.stats`` (~0.5 s per process)."""
    return 2.0 * gammaincinv(0.5 * np.asarray(dof, float), q)


def chi2_interval(dof: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided interval (lo, hi) that a χ²(dof) variable falls in with ``probability``."""
    a = 0.5 * (1.0 - probability)
    return float(chi2_ppf(a, dof)), float(chi2_ppf(1.0 - a, dof))


@lru_cache(maxsize=256)
def chi2_gate(probability: float, dof: int) -> float:
    """One-sided bound ``chi2.ppf(probability, dof)``: a χ²(dof) variable stays below it with ``probability``.

    The innovation gate of the filters (reject a measurement whose NIS exceeds it).  Cached: the
    filters ask for the same few (probability, dof) pairs thousands of times.
    """
    return float(chi2_ppf(probability, dof))


def anees_bounds(dof: int, n_runs: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided bounds on the NEES (or NIS) averaged over ``n_runs`` independent runs.

    ``(chi2.ppf((1−p)/2, N·dof)/N, chi2.ppf((1+p)/2, N·dof)/N)`` with N = n_runs, dof the error
    dimension.  An average over time of such per-step averages is at least as concentrated, so
    these bounds are conservative for it.
    """
    lo, hi = chi2_interval(int(dof) * int(n_runs), probability)
    return lo / n_runs, hi / n_runs


def fraction_inside(values: np.ndarray, lo: float | np.ndarray, hi: float | np.ndarray) -> float:
    """Fraction of the finite ``values`` with ``lo ≤ value ≤ hi`` (NaN = absent, ignored)."""
    v = np.asarray(values, dtype=float)
    finite = np.isfinite(v)
    if not finite.any():
        return float("nan")
    inside = (v >= lo) & (v <= hi) & finite
    return float(inside.sum() / finite.sum())


def is_symmetric_pd(P: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Check covariances P (..., n, n): returns (ok (...,) bool, smallest eigenvalue (...,)).

    ``ok`` means ``max|P − Pᵀ| ≤ tol · max|P|`` and the smallest eigenvalue of the symmetric part
    is > 0 (and everything finite).
    """
    P = np.asarray(P, dtype=float)
    finite = np.all(np.isfinite(P), axis=(-2, -1))
    Pf = np.where(finite[..., None, None], P, 0.0)
    scale = np.max(np.abs(Pf), axis=(-2, -1))
    asym = np.max(np.abs(Pf - np.swapaxes(Pf, -1, -2)), axis=(-2, -1))
    sym = 0.5 * (Pf + np.swapaxes(Pf, -1, -2))
    min_eig = np.linalg.eigvalsh(sym)[..., 0]
    min_eig = np.where(finite, min_eig, np.nan)
    ok = finite & (asym <= tol * scale) & (min_eig > 0.0)
    return ok, min_eig


def whiteness(y: np.ndarray, max_lag: int) -> tuple[np.ndarray, float, float]:
    """Normalised autocorrelation of an innovation sequence and its 95 % whiteness band.

    y (n,) or (n, m) per step (rows with NaN — absent measurements — are dropped first, so lags
    count present samples).  Each channel is de-meaned;
    ``acf[l] = Σ_t y_t y_{t+l} / Σ_t y_t²`` for l = 0..max_lag, shape (max_lag+1,) or
    (max_lag+1, m) (``acf[0] = 1``).  Returns ``(acf, band, fraction_outside)`` with
    ``band = 1.96/√n`` and ``fraction_outside`` the fraction of |acf[1:]| entries beyond the band
    (≈ 0.05 for a white sequence).
    """
    y = np.asarray(y, dtype=float)
    vector = y.ndim == 2
    Y = y if vector else y[:, None]
    Y = Y[np.all(np.isfinite(Y), axis=1)]
    n = Y.shape[0]
    if n <= max_lag:
        raise ValueError(f"whiteness: {n} samples are not enough for max_lag={max_lag}")
    Y = Y - Y.mean(axis=0)
    denom = np.sum(Y * Y, axis=0)
    acf = np.empty((max_lag + 1, Y.shape[1]))
    for lag in range(max_lag + 1):
        acf[lag] = np.sum(Y[: n - lag] * Y[lag:], axis=0) / denom
    band = 1.96 / np.sqrt(n)
    frac = float(np.mean(np.abs(acf[1:]) > band)) if max_lag > 0 else 0.0
    return (acf if vector else acf[:, 0]), float(band), frac


def mixture_hdr_level(
    x: np.ndarray,
    means: np.ndarray,
    covs: np.ndarray,
    weights: np.ndarray,
    rng: np.random.Generator,
    samples: int = 20000,
) -> float:
    """Probability level of the smallest highest-density region of a Gaussian mixture that contains
    ``x`` (d,): the mixture's probability mass where its density exceeds the density at x, by Monte
    Carlo over ``samples`` draws from ``rng``.  ``means`` (K, d), ``covs`` (K, d, d), ``weights`` (K,)
    (normalised here).  For one Gaussian it is the χ²(d) CDF of x's Mahalanobis distance squared, so
    "inside 3σ" in 2-D is a level ≤ 0.9973 for any mixture (a ring of headings, say)."""
    x = np.asarray(x, float)
    means = np.asarray(means, float)
    covs = np.asarray(covs, float)
    w = np.asarray(weights, float)
    w = w / w.sum()
    d = x.size
    L = np.linalg.cholesky(covs)
    inv = np.linalg.inv(covs)
    norm = w / np.sqrt((2.0 * np.pi) ** d * np.linalg.det(covs))

    def density(y):  # y (m, d) -> (m,), in chunks of ~4 M sample-component pairs
        step = max(1, 4_000_000 // w.size)
        out = np.empty(y.shape[0])
        for a in range(0, y.shape[0], step):
            r = y[a : a + step, None, :] - means[None, :, :]
            q = np.einsum("mki,kij,mkj->mk", r, inv, r)
            out[a : a + step] = np.exp(-0.5 * q) @ norm
        return out

    k = rng.choice(w.size, size=samples, p=w)
    y = means[k] + np.einsum("mij,mj->mi", L[k], rng.standard_normal((samples, d)))
    return float(np.mean(density(y) > density(x[None, :])[0]))
