"""The MEADS least-squares air data reduction and the wind/density solutions (paper Sect. III.A).

Composes the estimator's pressure models (:mod:`workbench.models.flush_airdata`) with the shared
vectorised point-wise Gauss–Newton (:func:`workbench.estimation.pointwise_wls.iterated_wls`):

* :func:`fit_air_data` — Eq. 5–10 at every pressure sample at once, solution set ``"mach"``
  (q∞, α, β, M), ``"static"`` (q∞, α, β, p∞) or ``"fixed_r"`` (p_t, α, β with R given per sample:
  a constant such as 0.001, q∞ from the limit of R M², or R scheduled from the inertial Mach with
  q∞ = (γ/2) p_t R M²; with the table model only the scheduled form, the table then read at
  the inertial Mach);
* :func:`solve_winds` — Eq. 11–15 by Newton iteration for the horizontal wind (vertical wind
  neglected) with the normalised determinant of Γ as the singularity test (Γ is singular at zero
  flight-path angle: a horizontal wind along a horizontal velocity changes only the speed, not
  α or β), and the covariance of Eq. 16–17;
* :func:`density_from_qbar` — Eq. 18.

Shapes: n samples, m ports; angles in rad, pressures in Pa, SI throughout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.frames import ned_basis
from workbench.core.rotation import quat_to_dcm, skew
from workbench.estimation.pointwise_wls import WlsResult, iterated_wls
from workbench.models.flush_airdata import (
    FadsVehicle,
    SurfacePressureTable,
    incidence_cos,
    newtonian_pressure,
    pressure_ratio,
    rm2_limit,
    total_angles,
)

__all__ = [
    "STATE_NAMES",
    "AirDataFit",
    "pressure_model",
    "fit_air_data",
    "WindSolution",
    "ned_frames",
    "solve_winds",
    "density_from_qbar",
]

STATE_NAMES = {
    "mach": ("qbar", "alpha", "beta", "mach"),
    "static": ("qbar", "alpha", "beta", "p_inf"),
    "fixed_r": ("p_t", "alpha", "beta"),
}
_LOWER = {"mach": [1.0, -0.9, -0.6, 0.3], "static": [1.0, -0.9, -0.6, 1e-3], "fixed_r": [1.0, -0.9, -0.6]}
_UPPER = {"mach": [1e6, 0.9, 0.6, 60.0], "static": [1e6, 0.9, 0.6, 1e5], "fixed_r": [1e6, 0.9, 0.6]}


@dataclass(frozen=True)
class AirDataFit:
    """Air data at the pressure times (n,): ``qbar``, ``alpha``, ``beta``, ``mach``, ``p_inf``,
    ``p_t`` and their 1σ ``sigma_*`` (NaN where the set does not estimate them and no other
    source is given), the raw :class:`~workbench.estimation.pointwise_wls.WlsResult` ``wls``,
    ``solution`` (its set), ``model``, ``sigma_p`` (n, m) the 1σ used for each port, ``predicted``
    (n, m) the model pressures at the solution."""

    qbar: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    mach: np.ndarray
    p_inf: np.ndarray
    p_t: np.ndarray
    sigma_qbar: np.ndarray
    sigma_alpha: np.ndarray
    sigma_beta: np.ndarray
    sigma_mach: np.ndarray
    sigma_p_inf: np.ndarray
    wls: WlsResult
    solution: str
    model: str
    sigma_p: np.ndarray
    predicted: np.ndarray

    @property
    def normalized_residual(self) -> np.ndarray:
        """Residual / its sensor σ (n, m) [-] of every port (NaN where not fitted)."""
        return self.wls.residual / self.sigma_p

    @property
    def measured(self) -> np.ndarray:
        """The pressures the fit saw (n, m) [Pa]: model + residual (the model where no residual)."""
        return self.predicted + np.nan_to_num(self.wls.residual)

    @property
    def air_direction_B(self) -> np.ndarray:
        """Unit vector (n, 3) in body axes B of the wind-relative velocity from the fitted α, β
        (``(cos α cos β, sin β, sin α cos β)``; α = β = 0 where not fitted)."""
        a, b = np.nan_to_num(self.alpha), np.nan_to_num(self.beta)
        return np.stack([np.cos(a) * np.cos(b), np.sin(b), np.sin(a) * np.cos(b)], 1)


def _freestream(x: np.ndarray, solution: str, gamma: float, ratio: np.ndarray | None, mach_fixed: np.ndarray | None):
    """(q, α, β, M, p∞, p_t, R) columns (n, 1) from states x (n, k)."""
    col = [x[:, j : j + 1] for j in range(x.shape[1])]
    if solution == "mach":
        q, a, b, M = col
        R = pressure_ratio(M, gamma)
        pt = 2.0 * q / (gamma * R * M**2)
        return q, a, b, M, R * pt, pt, R
    if solution == "static":
        q, a, b, pinf = col
        M = np.sqrt(2.0 * q / (gamma * pinf))
        R = pressure_ratio(M, gamma)
        return q, a, b, M, pinf, pinf / R, R
    pt, a, b = col
    R = ratio[:, None]
    if mach_fixed is None:  # constant R: q from the limit of R M^2 (Sect. II.A)
        q = 0.5 * gamma * pt * rm2_limit(gamma)
        M = np.full_like(pt, np.nan)
    else:
        M = mach_fixed[:, None]
        q = 0.5 * gamma * pt * R * M**2
    return q, a, b, M, R * pt, pt, R


def pressure_model(
    vehicle: FadsVehicle,
    model: str,
    solution: str,
    gamma: float,
    table: SurfacePressureTable | None = None,
    ratio: np.ndarray | None = None,
    mach_fixed: np.ndarray | None = None,
):
    """The model ``h(x) -> p (n, m)`` [Pa] of Eq. 5 for the ports of ``vehicle``: ``"newtonian"``
    (Eq. 1 with Eq. 3) or ``"table"`` (``p∞ + q∞ Cp``, the table at the ports' relative clock and
    radial position); ``ratio``/``mach_fixed`` (n,) for the fixed-R set."""
    cone, clock = vehicle.cone(), vehicle.clock()
    s = vehicle.radius() / vehicle.base_radius
    if model == "table" and table is None:
        raise ValueError("the table model needs its SurfacePressureTable")
    if model == "table" and solution == "fixed_r" and mach_fixed is None:
        raise ValueError("the table model with a fixed R needs the Mach it is scheduled with (fixed_r = 0)")

    def h(x: np.ndarray) -> np.ndarray:
        q, a, b, M, pinf, pt, R = _freestream(x, solution, gamma, ratio, mach_fixed)
        if model == "newtonian":
            return newtonian_pressure(pt, R, incidence_cos(a, b, cone, clock))
        at, phw = total_angles(a, b)
        return pinf + q * table.cp(M, at, clock[None, :] - phw, s[None, :])

    return h


def _steps(solution: str):
    def steps(x):
        st = np.empty_like(x)
        st[:, 0] = 1e-5 * np.maximum(np.abs(x[:, 0]), 1.0)
        st[:, 1:3] = 1e-6
        if x.shape[1] > 3:
            st[:, 3] = 1e-5 * np.maximum(np.abs(x[:, 3]), 1e-3)
        return st

    return steps


def fit_air_data(
    p: np.ndarray,
    sigma_p: np.ndarray,
    vehicle: FadsVehicle,
    *,
    model: str,
    solution: str,
    gamma: float,
    mach_guess: np.ndarray,
    fixed_r: float,
    iterations: int,
    table: SurfacePressureTable | None = None,
    mask: np.ndarray | None = None,
) -> AirDataFit:
    """Fit every sample of ``p`` (n, m) [Pa] (1σ ``sigma_p`` (n, m)) with the solution set.

    ``mach_guess`` (n,): the initial Mach (inertial) — for ``"fixed_r"`` with ``fixed_r = 0`` it
    also schedules R (``fixed_r`` is not used by the other sets); ``iterations`` of Gauss–Newton
    (the scenario's ``[estimator]`` values in a run); ``mask`` (n, m) usable ports.  Initial
    α = 18°, β = 0, p_t = the largest reading.  Derived quantities and their 1σ by first-order propagation of P.
    """
    n = p.shape[0]
    pmax = np.nanmax(np.where(np.isfinite(p), p, np.nan), axis=1)
    pmax = np.where(np.isfinite(pmax) & (pmax > 0), pmax, 1.0)
    Mg = np.clip(np.asarray(mach_guess, float), 1.2, 50.0)
    a0 = np.full(n, np.radians(18.0))
    ratio = mach_fixed = None
    if solution == "fixed_r":
        if fixed_r > 0:
            ratio = np.full(n, fixed_r)
        else:
            ratio = pressure_ratio(Mg, gamma)
            mach_fixed = Mg
        x0 = np.stack([pmax, a0, np.zeros(n)], 1)
    else:
        R0 = pressure_ratio(Mg, gamma)
        q0 = 0.5 * gamma * pmax * R0 * Mg**2
        x0 = np.stack([q0, a0, np.zeros(n), Mg if solution == "mach" else 2.0 * q0 / (gamma * Mg**2)], 1)
    h = pressure_model(vehicle, model, solution, gamma, table, ratio, mach_fixed)
    res = iterated_wls(
        h,
        x0,
        p,
        sigma_p,
        mask,
        steps=_steps(solution),
        iterations=iterations,
        lower=np.array(_LOWER[solution]),
        upper=np.array(_UPPER[solution]),
        damping=1e-6 if solution == "mach" else 1e-9,
    )
    x, P = res.x, res.P
    xs = np.where(np.isfinite(x), x, x0)
    q, a, b, M, pinf, pt, R = (c[:, 0] for c in _freestream(xs, solution, gamma, ratio, mach_fixed))
    sd = np.sqrt(np.einsum("nii->ni", P))
    bad = ~np.isfinite(x[:, 0])
    nan = np.full(n, np.nan)
    if solution == "mach":
        sq, sm = sd[:, 0], sd[:, 3]
        spinf = _propagate(lambda y: _freestream(y, solution, gamma, None, None)[4][:, 0], xs, P)
    elif solution == "static":
        sq = sd[:, 0]
        sm = _propagate(lambda y: _freestream(y, solution, gamma, None, None)[3][:, 0], xs, P)
        spinf = sd[:, 3]
    else:
        sq = sd[:, 0] * q / np.maximum(pt, 1e-12)
        sm = nan
        spinf = sd[:, 0] * R
    out = {k: np.where(bad, np.nan, v) for k, v in dict(q=q, a=a, b=b, M=M, pinf=pinf, pt=pt).items()}
    return AirDataFit(
        qbar=out["q"],
        alpha=out["a"],
        beta=out["b"],
        mach=out["M"],
        p_inf=out["pinf"],
        p_t=out["pt"],
        sigma_qbar=sq,
        sigma_alpha=sd[:, 1],
        sigma_beta=sd[:, 2],
        sigma_mach=sm,
        sigma_p_inf=spinf,
        wls=res,
        solution=solution,
        model=model,
        sigma_p=np.broadcast_to(sigma_p, p.shape),
        predicted=h(xs),
    )


def _propagate(f, x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """1σ of the scalar function f(x) (n,) by a numerical gradient and P (n, k, k)."""
    k = x.shape[1]
    g = np.empty_like(x)
    for j in range(k):
        e = np.zeros_like(x)
        e[:, j] = 1e-6 * np.maximum(np.abs(x[:, j]), 1e-3)
        g[:, j] = (f(x + e) - f(x - e)) / (2 * e[:, j])
    return np.sqrt(np.maximum(np.einsum("ni,nij,nj->n", g, P, g), 0.0))


# ----------------------------------------------------------------------------------- winds


def ned_frames(p_M: np.ndarray) -> np.ndarray:
    """C_N_M (n, 3, 3): rows north, east, down at positions p_M (n, 3) (+Z of M the pole):
    :func:`workbench.core.frames.ned_basis`."""
    return ned_basis(p_M)


@dataclass(frozen=True)
class WindSolution:
    """Horizontal wind ``wind_NE`` (n, 2) [m/s] (NaN where not published; ``wind_raw_NE`` the
    Newton solution everywhere it could be computed, for diagnosis), its covariance ``P``
    (n, 2, 2) (Eq. 16), ``det`` (n,) the normalised |det Γ|, ``singular`` (n,) True where
    |det| < the threshold (near-zero flight-path angle), ``v_ground_N`` (n, 3) planet-relative
    velocity in NED, ``fpa`` (n,) [rad] flight-path angle, ``iterations``."""

    wind_NE: np.ndarray
    wind_raw_NE: np.ndarray
    P: np.ndarray
    det: np.ndarray
    singular: np.ndarray
    v_ground_N: np.ndarray
    fpa: np.ndarray
    iterations: int

    @property
    def sigma_NE(self) -> np.ndarray:
        """1σ (n, 2) [m/s] of the north and east wind, the diagonal of ``P`` (NaN where unsolved)."""
        return np.sqrt(np.stack([self.P[:, 0, 0], self.P[:, 1, 1]], axis=1))


def _angles(C_B_N: np.ndarray, v_N: np.ndarray, w_NE: np.ndarray) -> np.ndarray:
    rel = v_N - np.concatenate([w_NE, np.zeros((w_NE.shape[0], 1))], axis=1)
    u = np.einsum("nij,nj->ni", C_B_N, rel)
    V = np.linalg.norm(u, axis=1)
    return np.stack([np.arctan2(u[:, 2], u[:, 0]), np.arcsin(np.clip(u[:, 1] / V, -1, 1))], 1)


def solve_winds(
    alpha: np.ndarray,
    beta: np.ndarray,
    P_ab: np.ndarray,
    v_ground_N: np.ndarray,
    C_B_N: np.ndarray,
    Q_nav: np.ndarray,
    *,
    det_min: float,
    sigma_max: float = np.inf,
    iterations: int = 8,
) -> WindSolution:
    """Eq. 14 Newton iteration for (u_w, v_w) at every sample with α̂, β̂ (n,) [rad], their 2×2
    covariance ``P_ab`` (n, 2, 2), the planet-relative velocity in NED (n, 3) and the attitude
    C_B_N (n, 3, 3) from the IMU; ``Q_nav`` (n, 6, 6) covariance of [δv_N, δθ_B] (trajectory
    error, Eq. 16's Q̂).  Samples with the normalised determinant ``|det Γ| V²`` below ``det_min``
    are singular: their wind is NaN (not published); so is any wind whose 1σ (Eq. 16, the larger
    component) exceeds ``sigma_max`` [m/s]."""
    n = alpha.size
    target = np.stack([alpha, beta], 1)
    w = np.zeros((n, 2))
    ok = np.all(np.isfinite(target), axis=1)
    V = np.linalg.norm(v_ground_N, axis=1)
    d = 0.05
    G = np.zeros((n, 2, 2))
    for _ in range(iterations):
        f0 = _angles(C_B_N, v_ground_N, w)
        G = np.stack(
            [
                (_angles(C_B_N, v_ground_N, w + np.array([d, 0.0])) - f0) / d,
                (_angles(C_B_N, v_ground_N, w + np.array([0.0, d])) - f0) / d,
            ],
            axis=2,
        )
        det = np.linalg.det(G) * V**2
        good = ok & (np.abs(det) > 1e-9)
        dw = np.zeros((n, 2))
        dw[good] = np.linalg.solve(G[good], (target - f0)[good][..., None])[..., 0]
        w = w + np.clip(dw, -200.0, 200.0)
    det = np.linalg.det(G) * V**2
    singular = np.abs(det) < det_min
    Gi = np.full((n, 2, 2), np.nan)
    inv_ok = ok & (np.abs(det) > 1e-9)
    Gi[inv_ok] = np.linalg.inv(G[inv_ok])
    # Eq. 17: sensitivity of the solved wind to the trajectory, Λ = −Γ⁻¹ ∂(α, β)/∂(v_N, θ)
    f0 = _angles(C_B_N, v_ground_N, w)
    J = np.empty((n, 2, 6))
    for j in range(3):
        e = np.zeros(3)
        e[j] = 0.05
        J[:, :, j] = (_angles(C_B_N, v_ground_N + e, w) - f0) / 0.05
        th = np.zeros(3)
        th[j] = 1e-5
        J[:, :, 3 + j] = (_angles((np.eye(3) - skew(th)) @ C_B_N, v_ground_N, w) - f0) / 1e-5
    Lam = -np.einsum("nij,njk->nik", Gi, J)
    Pw = np.einsum("nij,njk,nlk->nil", Gi, P_ab, Gi) + np.einsum("nij,njk,nlk->nil", Lam, Q_nav, Lam)
    fpa = np.arcsin(np.clip(-v_ground_N[:, 2] / np.maximum(V, 1e-9), -1, 1))
    big = np.sqrt(np.max(np.einsum("nii->ni", np.nan_to_num(Pw, nan=np.inf)), axis=1)) > sigma_max
    out = np.where((singular | ~ok | big)[:, None], np.nan, w)
    raw = np.where(inv_ok[:, None], w, np.nan)
    return WindSolution(out, raw, Pw, det, singular & ok, v_ground_N, fpa, iterations)


def density_from_qbar(qbar: np.ndarray, v_air_N: np.ndarray) -> np.ndarray:
    """Eq. 18: ρ∞ = 2 q∞ / |V_air|² [kg/m³]; ``v_air_N`` (n, 3) the air-relative velocity [m/s]."""
    return 2.0 * qbar / np.sum(v_air_N**2, axis=1)


def attitude_C_B_N(q_M_B: np.ndarray, p_M: np.ndarray) -> np.ndarray:
    """C_B_N (n, 3, 3) from the attitude q_M_B (n, 4) and position p_M (n, 3)."""
    C_M_B = quat_to_dcm(q_M_B)
    return np.einsum("nji,nkj->nik", C_M_B, ned_frames(p_M))
