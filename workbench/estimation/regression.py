"""One regression coefficient with nuisance regressors projected out (Frisch–Waugh–Lovell).

For a whitened linear model ``y = N b + c d + ε`` (ε ~ N(0, I): each row divided by its σ), the
least-squares ``c`` and its variance equal those of the full fit, and follow from the part of
``d`` orthogonal to the nuisance columns: ``d⊥ = d − N N⁺ d``, ``c = d⊥·y / d⊥·d⊥``,
``var c = 1 / d⊥·d⊥`` (Frisch & Waugh, "Partial time regressions as compared with individual
trends", Econometrica 1933; Lovell, "Seasonal adjustment of economic time series", JASA 1963).
Projecting with the pseudo-inverse makes a rank-deficient nuisance (collinear columns) cost
precision, not a singular matrix.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PartialFit", "partial_coefficient"]


@dataclass(frozen=True)
class PartialFit:
    """``coef`` the coefficient of ``d``; ``sigma`` its 1σ, scaled by √χ²ᵣ when that exceeds 1 (the
    residuals scatter more than their declared σ); ``chi2_red`` the reduced χ² of the full fit;
    ``dof`` its degrees of freedom (rows − rank of the nuisance − 1)."""

    coef: float
    sigma: float
    chi2_red: float
    dof: int


def partial_coefficient(N: np.ndarray, d: np.ndarray, y: np.ndarray) -> PartialFit | None:
    """The least-squares coefficient of regressor ``d`` (n,) in ``y`` (n,) beside the nuisance
    regressors ``N`` (n, p), all rows already whitened (divided by the measurement σ, so the
    residuals are unit-variance when the model holds).  None when no degree of freedom is left or
    ``d`` lies in the nuisance's span."""
    N = np.asarray(N, float).reshape(len(d), -1)
    d = np.asarray(d, float)
    y = np.asarray(y, float)
    if N.size:
        coef, _, rank, _ = np.linalg.lstsq(N, np.column_stack([d, y]), rcond=None)  # one SVD, one rank
        d_perp, y_perp = (np.column_stack([d, y]) - N @ coef).T
    else:
        rank, d_perp, y_perp = 0, d, y
    info = float(d_perp @ d_perp)
    dof = d.size - rank - 1
    if dof < 1 or not info > 1e-12 * float(d @ d):
        return None
    coef = float(d_perp @ y_perp) / info
    chi2_red = float(np.sum((y_perp - coef * d_perp) ** 2)) / dof
    return PartialFit(coef, float(np.sqrt(max(chi2_red, 1.0) / info)), chi2_red, dof)
