"""MEADS reconstruction stages: pressures + IMU -> q∞, Mach, α, β, p∞, density and winds.

Stages (each a typed result, drawn by :mod:`.recording`, consumed by tests without a recorder):

1. :class:`PressureData` — the pressure and IMU files read (SI), dropouts logged;
2. :class:`Navigation` — strapdown of the IMU from the initial state
   (:func:`workbench.estimation.strapdown.integrate`) with its first-order covariance; the
   inertial Mach (planet-relative speed over the speed of sound of the estimator's engineering
   atmosphere, :class:`~workbench.core.atmosphere.MarsEngineeringAtmosphere`) for the initial
   guess and the fixed-R schedule;
3. :class:`LagCorrection` — pneumatic-lag inversion ``p_port ≈ p_meas + τ ṗ_meas`` with the
   group delay ``τ = 2ζ/ω_n`` of Eq. 41–42 at the measured pressure (tube gas at the transducer
   temperature 300 K — the estimator does not know the wall temperature);
4. :class:`AirDataStage` — the least-squares fit (:func:`.airdata.fit_air_data`), the stuck-
   transducer and residual-based failed-port detection (a port failed from the first of
   ``failed_port_samples`` consecutive samples beyond ``failed_port_nsigma``; the fit is redone
   without it; each a logged degradation), the plausibility check of q∞ against the IMU drag
   (``m |f| / (C_D S)``; a unit error such as kPa labelled Pa is refused, not published);
5. :class:`WindStage` — winds (Eq. 11–17) and density (Eq. 18);
6. :class:`~workbench.problems.meads.ekf.EkfPass` — the tightly-coupled EKF (Sect. III.B) on the
   same lag-corrected pressures, ports and pressure model, RTS smoothed: pass 1 estimates the
   transducer scale factors, pass 2 reprocesses the pressures corrected by them (scenario
   ``[ekf]``; :mod:`.ekf`);
7. :class:`MeadsResult` — everything plus the summary.

The other estimator model (Newtonian vs table) is fitted too on the same corrected pressures, so
the model-form difference can be scored (:func:`score`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from threadpoolctl import threadpool_limits

from workbench.core.atmosphere import CO2_SUTHERLAND, MARS_CO2_GAS_CONSTANT, MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.rotation import dcm_to_quat, quat_normalize, quat_to_dcm
from workbench.estimation.health import health_markdown
from workbench.estimation.strapdown import imu_arrays, integrate
from workbench.io.telemetry import TelemetryError
from workbench.models.flush_airdata import (
    FadsVehicle,
    SurfacePressureTable,
    build_estimator_table,
    second_order_tube,
)
from workbench.problems.meads.airdata import (
    AirDataFit,
    WindSolution,
    attitude_C_B_N,
    density_from_qbar,
    fit_air_data,
    ned_frames,
    solve_winds,
)
from workbench.problems.meads.config import EstimatorSettings, MeadsSettings
from workbench.problems.meads.ekf import EkfInputs, EkfPass, run_passes
from workbench.problems.meads.health import meads_health
from workbench.problems.meads.telemetry import MeadsTelemetry, read_meads_telemetry, true_runs

__all__ = [
    "PressureData",
    "Navigation",
    "LagCorrection",
    "AirDataStage",
    "WindStage",
    "MeadsResult",
    "PortFailure",
    "reconstruct",
    "reduce_pressures",
    "score",
    "headline_at_peak_qbar",
    "scorecard_markdown",
]

#: local East-North-Up from North-East-Down
C_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])

TRANSDUCER_T_K = 300.0
"""Gas temperature [K] the estimator assumes in the tubes (lag inversion)."""


@dataclass(frozen=True)
class PressureData:
    """Stage 1: the read telemetry and the vehicle."""

    telemetry: MeadsTelemetry
    vehicle: FadsVehicle


@dataclass(frozen=True)
class Navigation:
    """Stage 2: strapdown at the IMU times ``t`` and interpolated to the pressure times ``t_p``:
    ``p_M``, ``v_M`` (n, 3), ``q_M_B`` (n, 4), ``Q`` (n, 6, 6) covariance of [δv_N, δθ_B],
    ``mach_inertial`` (n,), ``h`` (n,) [m] altitude, ``f_mag`` (n,) [m/s²] |specific force|."""

    t_imu: np.ndarray
    p_M_imu: np.ndarray
    t_p: np.ndarray
    p_M: np.ndarray
    v_M: np.ndarray
    q_M_B: np.ndarray
    Q: np.ndarray
    mach_inertial: np.ndarray
    h: np.ndarray
    f_mag: np.ndarray

    def q_ENU_B(self) -> np.ndarray:
        """The strapdown attitude (n, 4) at ``t_p`` as body → local East-North-Up at the vehicle
        (scalar-last), ``C_ENU_NED C_N_M C_M_B``: the frame the recording's scene is drawn in."""
        C_L_B = np.einsum("ij,njk,nkl->nil", C_ENU_NED, ned_frames(self.p_M), quat_to_dcm(self.q_M_B))
        return dcm_to_quat(C_L_B)


@dataclass(frozen=True)
class LagCorrection:
    """Stage 3: ``p_raw`` and ``p`` (lag-inverted, or the same if off) (n, m), ``delay`` (n, m) [s]."""

    t: np.ndarray
    p_raw: np.ndarray
    p: np.ndarray
    delay: np.ndarray
    applied: bool

    @property
    def correction(self) -> np.ndarray:
        """What the inversion added to the measured pressures (n, m) [Pa] (NaN where no sample)."""
        return self.p - self.p_raw


@dataclass(frozen=True)
class PortFailure:
    """A port declared failed at ``t`` [s] (sample ``k``) by ``how`` (``"stuck"`` or ``"residual"``)."""

    port: str
    k: int
    t: float
    how: str
    message: str


@dataclass(frozen=True)
class AirDataStage:
    """Stage 4: the fit with every port (``first``), the final fit (``fit``), the mask of ports used
    (n, m), the failures, the alternative model's fit (``alt``) and the plausibility ratio."""

    t: np.ndarray
    first: AirDataFit
    fit: AirDataFit
    mask: np.ndarray
    failures: tuple[PortFailure, ...]
    alt: AirDataFit | None
    plausibility_ratio: float
    fixed_r_rows: np.ndarray

    @property
    def residual_used(self) -> np.ndarray:
        """The final fit's residuals (n, m) [Pa] of the ports used, NaN for the others."""
        return np.where(self.mask, self.fit.wls.residual, np.nan)


@dataclass(frozen=True)
class WindStage:
    """Stage 5: winds and density at the pressure times."""

    winds: WindSolution
    density: np.ndarray
    sigma_density: np.ndarray
    mach: np.ndarray
    sigma_mach: np.ndarray
    mach_source: np.ndarray
    p_inf: np.ndarray
    sigma_p_inf: np.ndarray

    def density_error_pct(self, rho_true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(error, 1σ) (n,) [% of the true density ``rho_true`` (n,), kg/m³, on these samples]."""
        return 100 * (self.density / rho_true - 1), 100 * self.sigma_density / rho_true


@dataclass(frozen=True)
class MeadsResult:
    """Final stage: all stages and the JSON-ready ``summary``; ``ekf`` the filter passes (empty when
    ``[ekf] enabled = false``)."""

    data: PressureData
    nav: Navigation
    lag: LagCorrection
    air: AirDataStage
    wind: WindStage
    summary: dict
    ekf: tuple[EkfPass, ...] = ()


# ------------------------------------------------------------------------------ navigation


def navigate(tel: MeadsTelemetry, vehicle: FadsVehicle) -> Navigation:
    """Strapdown of the IMU from the initial state; values at the pressure times."""
    init = tel.initial
    sel = tel.t_imu >= init.t - 1e-9
    imu = imu_arrays(SimpleNamespace(t=tel.t_imu[sel], f_G=tel.f_B[sel], w_G=tel.w_B[sel], sigma_f=3e-3, sigma_w=1e-4))
    P0 = np.diag(np.r_[np.full(3, init.sigma_v**2), np.full(3, init.sigma_att**2), np.full(3, init.sigma_p**2)])
    with threadpool_limits(limits=1):  # 9x9 expm per step: BLAS threads only cost here
        sd = integrate(imu, init.v_M, init.q_M_B, init.p_M, P0, body=MARS, fast=True)
    t_p = tel.t_p

    def at(a):
        return np.stack([np.interp(t_p, sd.t, a[:, j]) for j in range(a.shape[1])], 1)

    p_M, v_M = at(sd.p_M), at(sd.v_M)
    q = sd.q_M_G.copy()  # the strapdown calls the body frame G
    flip = np.einsum("ni,ni->n", q[1:], q[:-1]) < 0
    q[1:][np.cumsum(flip) % 2 == 1] *= -1
    q_M_B = quat_normalize(at(q))
    C_N_M = ned_frames(p_M)
    P = np.stack([np.interp(t_p, sd.t, sd.P[:, i, j]) for i in range(6) for j in range(6)], 1).reshape(-1, 6, 6)
    Q = P.copy()
    Q[:, :3, :3] = np.einsum("nij,njk,nlk->nil", C_N_M, P[:, :3, :3], C_N_M)
    Q[:, :3, 3:] = np.einsum("nij,njk->nik", C_N_M, P[:, :3, 3:])
    Q[:, 3:, :3] = np.swapaxes(Q[:, :3, 3:], 1, 2)
    h = np.linalg.norm(p_M, axis=1) - MARS.reference_radius
    v_g = v_M - np.cross(np.array([0.0, 0.0, MARS.rotation_rate]), p_M)
    atm = MarsEngineeringAtmosphere()
    mach_i = np.linalg.norm(v_g, axis=1) / atm.speed_of_sound(h)
    f_mag = np.interp(t_p, tel.t_imu, np.linalg.norm(tel.f_B, axis=1))
    return Navigation(sd.t, sd.p_M, t_p, p_M, v_M, q_M_B, Q, mach_i, h, f_mag)


# ----------------------------------------------------------------------------- pressures


def invert_lag(t: np.ndarray, p: np.ndarray, vehicle: FadsVehicle, gamma: float, apply: bool) -> LagCorrection:
    """``p + τ ṗ`` per port with the Eq. 41–42 group delay at the measured pressure (module docstring)."""
    T = TRANSDUCER_T_K
    pc = np.maximum(np.nan_to_num(p, nan=1.0), 1.0)
    wn, z = second_order_tube(
        pc,
        T,
        vehicle.tube_length,
        vehicle.tube_diameter,
        vehicle.transducer_volume,
        gamma,
        MARS_CO2_GAS_CONSTANT,
        CO2_SUTHERLAND.viscosity(T),
    )
    delay = 2.0 * z / wn
    if not apply:
        return LagCorrection(t, p, p, delay, False)
    dpdt = np.gradient(p, t, axis=0)
    corr = p + np.where(np.isfinite(dpdt), delay * dpdt, 0.0)
    return LagCorrection(t, p, corr, delay, True)


def sensor_sigma(
    p: np.ndarray, vehicle: FadsVehicle, frac: float, bits: int = 14, noise_counts: float | None = None
) -> np.ndarray:
    """1σ [Pa] (n, m) assumed for each reading: quantisation and noise of a ``bits``-bit channel
    over the transducer range plus ``frac`` of reading (model form, calibration, trade-study
    error).  ``noise_counts`` None: two counts each side, uniform (σ² = (2 counts)²/3, the least
    squares' allowance); a number N: only the white part, noise uniform over N counts (Eq. 38)
    plus the quantisation's one count, σ² = (N² + 1)/12 counts²."""
    count = vehicle.transducer_full_scale / 2.0**bits
    var_counts = 4.0 / 3.0 if noise_counts is None else (noise_counts**2 + 1.0) / 12.0
    return np.sqrt(var_counts * count**2 + (frac * np.abs(np.nan_to_num(p))) ** 2)


def detect_stuck(t: np.ndarray, p: np.ndarray, ports, vehicle: FadsVehicle, min_run: int = 8) -> list[PortFailure]:
    """Ports whose reading repeats exactly for ≥ ``min_run`` samples (above 20 counts) while the
    median of the other ports changes by more than 2 %: failed from the first repeated sample."""
    count = vehicle.transducer_full_scale / 2.0**14
    out = []
    for j, name in enumerate(ports):
        same = np.r_[False, np.diff(p[:, j]) == 0.0] & (p[:, j] > 20 * count)
        others = np.nanmedian(np.delete(p, j, axis=1), axis=1)
        for a, b in true_runs(same):
            if b - a + 1 < min_run:
                continue
            k0 = a - 1
            change = abs(others[b] - others[k0]) / max(abs(others[k0]), 1e-9)
            if change > 0.02:
                out.append(
                    PortFailure(
                        name,
                        int(k0),
                        float(t[k0]),
                        "stuck",
                        f"{name} stuck at {p[k0, j]:.1f} Pa from t = {t[k0]:.2f} s (row {k0 + 1}) while the other "
                        f"ports changed by {100 * change:.0f} %: dropped from there on",
                    )
                )
                break
    return out


def detect_residual_failure(
    fit: AirDataFit, t: np.ndarray, ports, mask: np.ndarray, nsig: float, nrun: int
) -> PortFailure | None:
    """The port with the most samples in runs of ≥ ``nrun`` normalised residuals beyond ``nsig``
    (its first such run marks the failure), or None."""
    z = np.abs(fit.wls.residual) / fit.sigma_p
    best = None
    for j in range(len(ports)):
        bad = (z[:, j] > nsig) & mask[:, j]
        runs = [(a, b) for a, b in true_runs(bad) if b - a + 1 >= nrun]
        total = sum(b - a + 1 for a, b in runs)
        if runs and (best is None or total > best[0]):
            best = (total, j, runs[0][0])
    if best is None:
        return None
    total, j, k0 = best
    return PortFailure(
        ports[j],
        int(k0),
        float(t[k0]),
        "residual",
        f"{ports[j]} residual beyond {nsig:g} sigma for {total} samples from t = {t[k0]:.2f} s (row {k0 + 1}): "
        "declared failed and removed from the fit from there on",
    )


def reduce_pressures(
    t: np.ndarray,
    p: np.ndarray,
    vehicle: FadsVehicle,
    mach_inertial: np.ndarray,
    est: EstimatorSettings,
    *,
    model: str | None = None,
    mask: np.ndarray | None = None,
    table: SurfacePressureTable | None = None,
) -> tuple[AirDataFit, np.ndarray]:
    """One least-squares reduction with the settings' solution set (``"auto"``: fixed R above
    ``switch_mach``, the Mach set below); returns the fit and the rows solved with fixed R.
    ``table``: the estimator's table (:func:`build_estimator_table` of ``vehicle``) for the table
    model, built here when not given."""
    model = model or est.model
    if model != "table":
        table = None
    elif table is None:
        table = build_estimator_table(vehicle)
    sig = sensor_sigma(p, vehicle, est.model_error_frac)
    kw = dict(gamma=est.gamma, table=table, iterations=est.iterations, mask=mask)
    sol = est.solution
    if sol == "auto":
        hi = mach_inertial > est.switch_mach
        if hi.all() or not hi.any():
            s1 = "fixed_r" if hi.all() else "mach"
            f = fit_air_data(
                p, sig, vehicle, model=model, solution=s1, mach_guess=mach_inertial, fixed_r=est.fixed_r, **kw
            )
            return f, hi
        parts = {}
        for name, rows in (("fixed_r", hi), ("mach", ~hi)):
            kw_r = {**kw, "mask": None if mask is None else mask[rows]}
            parts[name] = fit_air_data(
                p[rows],
                sig[rows],
                vehicle,
                model=model,
                solution=name,
                mach_guess=mach_inertial[rows],
                fixed_r=est.fixed_r,
                **kw_r,
            )
        return _merge_rows(parts["mach"], parts["fixed_r"], hi), hi
    f = fit_air_data(p, sig, vehicle, model=model, solution=sol, mach_guess=mach_inertial, fixed_r=est.fixed_r, **kw)
    return f, np.full(t.size, sol == "fixed_r")


def _merge_rows(lo: AirDataFit, hi: AirDataFit, use_hi: np.ndarray) -> AirDataFit:
    """One fit from the Mach-set fit of the rows ``~use_hi`` and the fixed-R fit of the rows
    ``use_hi`` (the WLS state and covariance are those of each row's own set, padded to 4 states)."""
    n = use_hi.size

    def put(a_lo, a_hi):
        a_lo, a_hi = np.asarray(a_lo), np.asarray(a_hi)
        out = np.full((n, *a_lo.shape[1:]), np.nan, dtype=float)
        out[~use_hi] = a_lo
        out[use_hi] = a_hi if a_hi.shape[1:] == a_lo.shape[1:] else _pad(a_hi, a_lo.shape[1:])
        return out

    keys = (
        "qbar",
        "alpha",
        "beta",
        "mach",
        "p_inf",
        "p_t",
        "sigma_qbar",
        "sigma_alpha",
        "sigma_beta",
        "sigma_mach",
        "sigma_p_inf",
        "sigma_p",
        "predicted",
    )
    pick = {k: put(getattr(lo, k), getattr(hi, k)) for k in keys}
    used = np.zeros((n, lo.wls.used.shape[1]), bool)
    used[~use_hi], used[use_hi] = lo.wls.used, hi.wls.used
    wls = type(lo.wls)(
        put(lo.wls.x, hi.wls.x),
        put(lo.wls.P, hi.wls.P),
        put(lo.wls.residual, hi.wls.residual),
        used,
        max(lo.wls.iterations, hi.wls.iterations),
        put(lo.wls.step, hi.wls.step),
    )
    return AirDataFit(**pick, wls=wls, solution="auto", model=lo.model)


def _pad(a: np.ndarray, shape: tuple) -> np.ndarray:
    """Pad the trailing axes of ``a`` with NaN up to ``shape``."""
    out = np.full((a.shape[0], *shape), np.nan)
    out[(slice(None), *[slice(0, s) for s in a.shape[1:]])] = a
    return out


def fit_with_failures(
    t: np.ndarray,
    p: np.ndarray,
    vehicle: FadsVehicle,
    nav: Navigation,
    est: EstimatorSettings,
    ports,
    file: str,
    table: SurfacePressureTable | None = None,
) -> tuple[AirDataFit, AirDataFit, np.ndarray, list[PortFailure], np.ndarray]:
    """Fit with every port (``first``), stuck detection, residual detection (at most two ports),
    refits; returns (first, final, mask of the ports used, failures, fixed-R rows).  ``table`` as
    in :func:`reduce_pressures`."""
    mask = np.isfinite(p)
    first, hi = reduce_pressures(t, p, vehicle, nav.mach_inertial, est, mask=mask.copy(), table=table)
    failures = detect_stuck(t, p, ports, vehicle)
    for f in failures:
        mask[f.k :, ports.index(f.port)] = False
    fit = first
    if failures:
        fit, hi = reduce_pressures(t, p, vehicle, nav.mach_inertial, est, mask=mask, table=table)
    for _ in range(2):
        live = mask & (np.nan_to_num(fit.qbar)[:, None] > 50.0)
        f = detect_residual_failure(fit, t, ports, live, est.failed_port_nsigma, est.failed_port_samples)
        if f is None:
            break
        failures.append(f)
        mask[f.k :, ports.index(f.port)] = False
        fit, hi = reduce_pressures(t, p, vehicle, nav.mach_inertial, est, mask=mask, table=table)
    return first, fit, mask, failures, hi


def plausibility(
    fit: AirDataFit,
    nav: Navigation,
    vehicle: FadsVehicle,
    est: EstimatorSettings,
    tel: MeadsTelemetry,
    vehicle_file: Path | None = None,
) -> float:
    """Median ratio of the pressures' q∞ to the IMU drag's ``m |f| / (C_D S)`` where the latter
    exceeds the objectives' threshold (or 100 Pa); raises a TelemetryError naming the pressure
    file and its columns/units, and the vehicle file's ``mass_kg``, ``ref_area_m2`` and
    ``drag_coefficient`` (the other side of the ratio), when outside ``[1/F, F]``."""
    q_drag = vehicle.mass * nav.f_mag / (vehicle.drag_coefficient * vehicle.ref_area)
    sel = q_drag > est.min_qbar_pa
    if sel.sum() < 5:
        sel = q_drag > 100.0
    if sel.sum() < 5:
        return float("nan")
    ratio = float(np.nanmedian(fit.qbar[sel] / q_drag[sel]))
    F = est.plausibility_factor
    if not (1.0 / F <= ratio <= F) or not math.isfinite(ratio):
        units = ", ".join(f"{n} [{u}]" for n, u in tel.pressure_units.items())
        raise TelemetryError.single(
            tel.pressure_file,
            f"implausible pressures: the dynamic pressure fitted to them is {ratio:.3g} x the one implied by the "
            f"IMU drag (m|f|/(C_D S), median over {int(sel.sum())} samples; allowed 1/{F:g}-{F:g}). A unit error? "
            f"(kPa written as Pa gives 1e-3; an accelerometer in g written as m/s² gives ~9.8, see {tel.imu_file}). "
            f"Columns as read: {units}. Or the drag side: mass_kg = {vehicle.mass:g}, ref_area_m2 = "
            f"{vehicle.ref_area:g}, drag_coefficient = {vehicle.drag_coefficient:g} in "
            f"{Path(vehicle_file).name if vehicle_file else 'the vehicle file'} (a mass in lb, an area in ft²?). "
            "Nothing is published.",
            column=", ".join(tel.ports),
        )
    return ratio


def winds_and_density(fit: AirDataFit, nav: Navigation, est: EstimatorSettings, fixed_rows: np.ndarray) -> WindStage:
    """Winds (Eq. 11–17) and density (Eq. 18); Mach and p∞ from the air data where estimated,
    else inertial (5 % 1σ)."""
    C_N_M = ned_frames(nav.p_M)
    v_g = nav.v_M - np.cross(np.array([0.0, 0.0, MARS.rotation_rate]), nav.p_M)
    v_N = np.einsum("nij,nj->ni", C_N_M, v_g)
    C_B_N = attitude_C_B_N(nav.q_M_B, nav.p_M)
    Pab = np.zeros((fit.alpha.size, 2, 2))
    Pab[:, 0, 0], Pab[:, 1, 1] = fit.sigma_alpha**2, fit.sigma_beta**2
    winds = solve_winds(
        fit.alpha, fit.beta, Pab, v_N, C_B_N, nav.Q, det_min=est.wind_det_min, sigma_max=est.wind_sigma_max
    )
    # density: the wind where published, else interpolated over the gap (1σ 20 m/s there)
    w = winds.wind_NE.copy()
    good = np.all(np.isfinite(w), axis=1)
    sw2 = np.einsum("nii->n", np.nan_to_num(winds.P, nan=400.0))
    if good.sum() >= 2:
        for j in range(2):
            w[:, j] = np.interp(nav.t_p, nav.t_p[good], w[good, j])
    else:
        w[:] = 0.0
    sw2 = np.where(good, sw2, 2 * 20.0**2)
    v_air = v_N - np.concatenate([w, np.zeros((w.shape[0], 1))], 1)
    rho = density_from_qbar(fit.qbar, v_air)
    V = np.linalg.norm(v_air, axis=1)
    sv2 = np.einsum("nii->n", nav.Q[:, :3, :3]) + sw2
    srho = rho * np.sqrt((fit.sigma_qbar / fit.qbar) ** 2 + 4.0 * sv2 / V**2)
    mach = np.where(fixed_rows | ~np.isfinite(fit.mach), nav.mach_inertial, fit.mach)
    smach = np.where(fixed_rows | ~np.isfinite(fit.sigma_mach), 0.05 * nav.mach_inertial, fit.sigma_mach)
    src = np.where(fixed_rows | ~np.isfinite(fit.mach), "inertial", "air_data")
    pinf = np.where(fixed_rows, 2.0 * fit.qbar / (est.gamma * mach**2), fit.p_inf)
    spinf = np.where(
        fixed_rows, pinf * np.sqrt((fit.sigma_qbar / fit.qbar) ** 2 + 4 * (smach / mach) ** 2), fit.sigma_p_inf
    )
    return WindStage(winds, rho, srho, mach, smach, src, pinf, spinf)


# ------------------------------------------------------------------------------- pipeline


def reconstruct(
    settings: MeadsSettings, telemetry: Mapping[str, Path], *, other_model: bool = True
) -> Iterator[object]:
    """Run the stages of the module docstring on the telemetry files (``{stream: path}``) with the
    run's ``settings`` (its vehicle, estimator and filter); yields each stage.  ``other_model``
    False: the other estimator model is fitted only when the health needs it (the table beside
    a Newtonian estimator, :func:`~.health.model_form_checks`), else ``air.alt`` is None (a Monte
    Carlo member, which scores neither)."""
    t_start = time.perf_counter()
    cfg = settings
    est = cfg.estimator
    vehicle = cfg.vehicle
    tel = read_meads_telemetry(dict(telemetry), vehicle)
    yield PressureData(tel, vehicle)
    nav = navigate(tel, vehicle)
    yield nav
    lag = invert_lag(tel.t_p, tel.p, vehicle, est.gamma, est.lag_inversion)
    yield lag
    ports = list(tel.ports)
    alt_needed = other_model or est.model == "newtonian"
    table = build_estimator_table(vehicle) if est.model == "table" or alt_needed else None  # built once
    first, fit, mask, failures, hi = fit_with_failures(
        tel.t_p, lag.p, vehicle, nav, est, ports, tel.pressure_file, table
    )
    ratio = plausibility(first, nav, vehicle, est, tel, cfg.vehicle_file)
    alt = None
    if alt_needed:
        alt_model = "table" if est.model == "newtonian" else "newtonian"
        alt_est = replace(est, model=alt_model, fixed_r=0.0)
        alt, _ = reduce_pressures(tel.t_p, lag.p, vehicle, nav.mach_inertial, alt_est, mask=mask, table=table)
    air = AirDataStage(tel.t_p, first, fit, mask, tuple(failures), alt, ratio, hi)
    yield air
    wind = winds_and_density(fit, nav, est, hi)
    yield wind
    passes: list[EkfPass] = []
    if cfg.ekf.enabled:
        it = run_passes(ekf_inputs(tel, vehicle, nav, lag, air, est, cfg.ekf, table=table), cfg.ekf)
        while True:
            try:
                ps = next(it)
            except StopIteration:
                break
            except (OverflowError, ZeroDivisionError, FloatingPointError, np.linalg.LinAlgError) as err:
                raise np.linalg.LinAlgError(_divergence_message(len(passes) + 1, err, tel)) from err
            passes.append(ps)
            yield ps
    summary = _summary(settings.run.name, tel, nav, lag, air, wind, est)
    if passes:
        summary["ekf"] = _ekf_summary(passes, air, est)
    summary["health"] = meads_health(tel, nav, air, wind, est, passes, wind_sigma_mps=cfg.ekf.wind_sigma_mps)
    summary["reconstruction_wall_s"] = time.perf_counter() - t_start
    yield MeadsResult(PressureData(tel, vehicle), nav, lag, air, wind, summary, tuple(passes))


def _divergence_message(index: int, err: Exception, tel: MeadsTelemetry) -> str:
    """The error of EKF pass ``index`` diverging with ``err``: pass 1 names the files (the
    pressures, the IMU and the initial state may disagree: a unit, axis or time-base error); a
    later pass ran on the same inputs after pass 1 converged on them, so they are not implicated."""
    head = f"EKF pass {index}: the filter diverged ({type(err).__name__}: {err}) — its state left the physical range"
    if index == 1:
        return (
            f"{head}; the pressures ({tel.pressure_file}), the IMU ({tel.imu_file}) and the initial state are "
            "inconsistent (a unit, axis or time-base error?)"
        )
    return (
        f"{head}; pass 1 converged on the same pressures, IMU and initial state, so they are not implicated: "
        "a divergence of the filter itself (its state at the failed step above)"
    )


def ekf_inputs(
    tel: MeadsTelemetry,
    vehicle: FadsVehicle,
    nav: Navigation,
    lag: LagCorrection,
    air: AirDataStage,
    est,
    ek=None,
    *,
    table: SurfacePressureTable | None = None,
) -> EkfInputs:
    """The filter's inputs: the strapdown at the pressure times, the lag-corrected pressures with
    the least squares' σ (:func:`sensor_sigma`) and port mask (failed ports out), the model (its
    ``table`` for the table model: :func:`build_estimator_table` of ``vehicle``, built here when
    not given)."""
    init = tel.initial
    return EkfInputs(
        t=nav.t_p,
        p_M=nav.p_M,
        v_M=nav.v_M,
        q_M_B=nav.q_M_B,
        sigma_pos=init.sigma_p,
        sigma_vel=init.sigma_v,
        sigma_att=init.sigma_att,
        p=lag.p,
        sigma_p=sensor_sigma(lag.p, vehicle, est.model_error_frac)
        if ek is None or ek.model_error_sigma == 0.0
        else sensor_sigma(lag.p, vehicle, 0.0, noise_counts=ek.noise_counts),
        usable=air.mask & np.isfinite(lag.p),
        vehicle=vehicle,
        model=est.model,
        table=(table if table is not None else build_estimator_table(vehicle)) if est.model == "table" else None,
        gamma=est.gamma,
    )


def _ekf_summary(passes: list[EkfPass], air: AirDataStage, est) -> dict:
    """Per pass: the scale factors (and 1σ), the mean per-port NIS above the q∞ threshold (of the
    least squares), the reported 3σ of the outputs, the wall time."""
    out = {}
    above = np.nan_to_num(air.fit.qbar) >= est.min_qbar_pa
    for ps in passes:
        inn = ps.forward.innovations.get("pressure")
        sel = above[inn.step] if inn is not None else np.zeros(0, bool)
        nis = ps.nis_port[sel]
        mean_nis = [float(np.nanmean(nis[:, j])) if np.isfinite(nis[:, j]).any() else None for j in range(nis.shape[1])]
        a = above
        out[f"pass{ps.index}"] = {
            "scale_factors_estimated": ps.scale_estimated,
            "scale_factors": [float(v) for v in ps.scale],
            "scale_factor_sigma": [float(v) for v in ps.sigma_scale],
            "mean_nis_per_port_above_min_qbar": mean_nis,
            "three_sigma_above_min_qbar": {
                "alpha_deg": _stats(3 * np.degrees(ps.output("alpha")[1][a])),
                "beta_deg": _stats(3 * np.degrees(ps.output("beta")[1][a])),
                "qbar_pct": _stats(300 * ps.output("qbar")[1][a] / ps.output("qbar")[0][a]),
                "mach": _stats(3 * ps.output("mach")[1][a]),
                "density_pct": _stats(300 * ps.output("rho")[1][a] / ps.output("rho")[0][a]),
                "wind_north_mps": _stats(3 * ps.output("wind_north")[1][a]),
                "wind_east_mps": _stats(3 * ps.output("wind_east")[1][a]),
            },
            "wall_s": ps.wall_s,
        }
    return out


def _stats(x: np.ndarray) -> dict:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"n": 0}
    return {"n": int(x.size), "min": float(x.min()), "max": float(x.max()), "median": float(np.median(x))}


def _summary(name: str, tel, nav, lag, air: AirDataStage, wind: WindStage, est) -> dict:
    fit = air.fit
    above = np.nan_to_num(fit.qbar) >= est.min_qbar_pa
    w = wind.winds
    sing = true_runs(w.singular & above)
    return {
        "scenario": name,
        "kind": "meads",
        "model": est.model,
        "solution": est.solution,
        "samples": int(tel.t_p.size),
        "samples_above_min_qbar": int(above.sum()),
        "ports": list(tel.ports),
        "max_qbar_pa": float(np.nanmax(fit.qbar)),
        "three_sigma_above_min_qbar": {
            "alpha_deg": _stats(3 * np.degrees(fit.sigma_alpha[above])),
            "beta_deg": _stats(3 * np.degrees(fit.sigma_beta[above])),
            "qbar_pct": _stats(300 * fit.sigma_qbar[above] / fit.qbar[above]),
            "mach_air_data": _stats(3 * wind.sigma_mach[above & (wind.mach_source == "air_data")]),
            "density_pct": _stats(300 * wind.sigma_density[above] / wind.density[above]),
        },
        "lag_delay_ms": _stats(1e3 * lag.delay[above]),
        "fixed_r_samples": int(air.fixed_r_rows.sum()),
        "plausibility_qbar_ratio": air.plausibility_ratio,
        "failed_ports": [{"port": f.port, "t_s": f.t, "how": f.how, "message": f.message} for f in air.failures],
        "degradations": list(tel.degradations) + [f.message for f in air.failures],
        "wind_singular_intervals_s": [[float(tel.t_p[a]), float(tel.t_p[b])] for a, b in sing],
        "wind_singular_samples": int((w.singular & above).sum()),
        "wind_published_samples": int((np.all(np.isfinite(w.wind_NE), axis=1) & above).sum()),
        "wind_sigma_mps_nonsingular_above_min_qbar": _stats(
            np.sqrt(np.max(np.einsum("nii->ni", w.P), axis=1))[above & ~w.singular]
        ),
    }


# --------------------------------------------------------------------------------- scoring


def _err_block(err: np.ndarray, sig: np.ndarray, scale: float = 1.0) -> dict:
    ok = np.isfinite(err) & np.isfinite(sig)
    if not ok.any():
        return {"n": 0}
    e, s = err[ok] * scale, sig[ok] * scale
    return {
        "n": int(ok.sum()),
        "max_abs": float(np.max(np.abs(e))),
        "rms": float(np.sqrt(np.mean(e**2))),
        "median_3sigma": float(np.median(3 * s)),
        "fraction_within_3sigma": float(np.mean(np.abs(e) <= 3 * s)),
    }


def _truth_at(truth: dict, t: np.ndarray, key: str) -> np.ndarray:
    return np.interp(t, truth["t"], truth[key])


def score_fit(t: np.ndarray, fit: AirDataFit, truth: dict, sel: np.ndarray, wind: WindStage | None = None) -> dict:
    """Errors of one fit against the truth on the samples ``sel`` (above 850 Pa): α, β [deg], q∞
    [%], Mach (air-data rows), and with ``wind`` density [%], p∞ [%] and winds [m/s]."""
    out = {
        "alpha_deg": _err_block((fit.alpha - _truth_at(truth, t, "alpha"))[sel], fit.sigma_alpha[sel], 180 / math.pi),
        "beta_deg": _err_block((fit.beta - _truth_at(truth, t, "beta"))[sel], fit.sigma_beta[sel], 180 / math.pi),
        "qbar_pct": _err_block(
            ((fit.qbar - _truth_at(truth, t, "qbar")) / _truth_at(truth, t, "qbar"))[sel],
            (fit.sigma_qbar / fit.qbar)[sel],
            100.0,
        ),
    }
    mt = _truth_at(truth, t, "mach")
    if wind is None:
        out["mach"] = _err_block((fit.mach - mt)[sel], fit.sigma_mach[sel])
        return out
    ad = sel & (wind.mach_source == "air_data")
    out["mach_air_data"] = _err_block((wind.mach - mt)[ad], wind.sigma_mach[ad])
    iner = sel & (wind.mach_source == "inertial")
    out["mach_inertial"] = _err_block((wind.mach - mt)[iner], wind.sigma_mach[iner])
    rho_t = _truth_at(truth, t, "rho")
    out["density_pct"] = _err_block(
        ((wind.density - rho_t) / rho_t)[sel], (wind.sigma_density / wind.density)[sel], 100.0
    )
    pt = _truth_at(truth, t, "p_inf")
    out["p_inf_pct"] = _err_block(((wind.p_inf - pt) / pt)[sel], (wind.sigma_p_inf / wind.p_inf)[sel], 100.0)
    wt = np.stack([np.interp(t, truth["t"], truth["wind_NE"][:, j]) for j in range(2)], 1)
    pub = sel & np.all(np.isfinite(wind.winds.wind_NE), axis=1)
    raw = wind.winds.wind_raw_NE
    nonsing = sel & ~wind.winds.singular & np.all(np.isfinite(raw), axis=1)
    for j, name in enumerate(("wind_north_mps", "wind_east_mps")):
        sd = np.sqrt(wind.winds.P[:, j, j])
        out[name] = _err_block((wind.winds.wind_NE[:, j] - wt[:, j])[pub], sd[pub])
        out[name + "_unpublished_nonsingular"] = _err_block((raw[:, j] - wt[:, j])[nonsing], sd[nonsing])
    return out


def score_ekf(t: np.ndarray, ps: EkfPass, truth: dict, sel: np.ndarray) -> dict:
    """Errors of one filter pass (smoothed) against the truth on the samples ``sel``: α, β [deg],
    q∞ [%], Mach, p∞ [%], density [%], horizontal winds [m/s], each vs its reported 3σ."""
    out = {}
    for key, name, tkey in (("alpha_deg", "alpha", "alpha"), ("beta_deg", "beta", "beta")):
        v, s = ps.output(name)
        out[key] = _err_block((v - _truth_at(truth, t, tkey))[sel], s[sel], 180 / math.pi)
    for key, name, tkey in (
        ("qbar_pct", "qbar", "qbar"),
        ("p_inf_pct", "p_inf", "p_inf"),
        ("density_pct", "rho", "rho"),
    ):
        v, s = ps.output(name)
        tr = _truth_at(truth, t, tkey)
        out[key] = _err_block(((v - tr) / tr)[sel], (s / v)[sel], 100.0)
    v, s = ps.output("mach")
    out["mach"] = _err_block((v - _truth_at(truth, t, "mach"))[sel], s[sel])
    for j, name in enumerate(("wind_north", "wind_east")):
        v, s = ps.output(name)
        wt = np.interp(t, truth["t"], truth["wind_NE"][:, j])
        out[name + "_mps"] = _err_block((v - wt)[sel], s[sel])
    return out


def score(result: MeadsResult, truth: dict) -> dict:
    """Errors of the final result against the truth above 850 Pa (true q∞), each vs its reported 3σ;
    the same for the fit with every port (before failure removal) and for the other model."""
    t = result.air.t
    est_min = 850.0
    sel = _truth_at(truth, t, "qbar") >= est_min
    out = {
        "min_qbar_pa": est_min,
        "samples": int(sel.sum()),
        "final": score_fit(t, result.air.fit, truth, sel, result.wind),
        "all_ports_no_failure_handling": score_fit(t, result.air.first, truth, sel),
    }
    if result.air.alt is not None:
        out[f"other_model_{result.air.alt.model}"] = score_fit(t, result.air.alt, truth, sel)
    for ps in result.ekf:
        out[f"ekf_pass{ps.index}"] = score_ekf(t, ps, truth, sel)
    if result.ekf and "sensor_scale" in truth:
        ps = result.ekf[0]
        true_scale = np.asarray(truth["sensor_scale"], float)
        err = ps.scale - true_scale
        out["ekf_scale_factors"] = {
            "ports": list(result.data.telemetry.ports),
            "estimate": [float(v) for v in ps.scale],
            "sigma": [float(v) for v in ps.sigma_scale],
            "truth": [float(v) for v in true_scale],
            "error": [float(v) for v in err],
            "max_abs_error": float(np.max(np.abs(err))),
            "fraction_within_3sigma": float(np.mean(np.abs(err) <= 3 * ps.sigma_scale)),
            "common_mode_error": float(np.mean(err)),
        }
    fp = int(truth.get("sensor_failed_port", -1))
    if fp >= 0:
        ports = result.data.telemetry.ports
        det = [f for f in result.air.failures if f.port == ports[fp]]
        out["injected_failure"] = {"port": ports[fp], "detected": bool(det), "detected_at_s": det[0].t if det else None}
    fpa = truth["fpa"]
    out["true_fpa_zero_crossings_s"] = [float(x) for x in truth["t"][1:][np.diff(np.sign(fpa)) != 0]]
    out["headline"] = headline_at_peak_qbar(result, truth)
    return out


def headline_at_peak_qbar(result: MeadsResult, truth: dict) -> list[dict]:
    """The run's headline against its truth: α, β [rad] and q∞ [Pa] of the final EKF pass (the
    least squares when the filter is off) at the peak reconstructed q∞ (the ``peak_qbar`` key
    moment), each ``{"name", "what", "error", "sigma", "unit"}`` (estimate − truth and the pass's
    own 1σ there; :func:`workbench.estimation.calibration.truth_check` judges them)."""
    air = result.air
    if not np.isfinite(air.fit.qbar).any():
        return []
    k = int(np.nanargmax(air.fit.qbar))
    t = float(air.t[k])
    if result.ekf:
        ps = result.ekf[-1]
        src = f"EKF pass {ps.index}"

        def get(name):
            v, s = ps.output(name)
            return float(v[k]), float(s[k])
    else:
        src = "least squares"
        fit = air.fit

        def get(name):
            return float(getattr(fit, name)[k]), float(getattr(fit, f"sigma_{name}")[k])

    out = []
    for name, unit, what in (("alpha", "rad", "α"), ("beta", "rad", "β"), ("qbar", "Pa", "q∞")):
        v, s = get(name)
        tv = float(_truth_at(truth, np.array([t]), name)[0])
        out.append(
            {
                "name": f"{name}_at_peak_qbar",
                "what": f"{src} {what} at peak q∞ (t = {t:.2f} s)",
                "error": v - tv,
                "sigma": s,
                "unit": unit,
            }
        )
    return out


def scorecard_markdown(summary: dict) -> str:
    """Markdown scorecard of a run (with its truth score when present)."""
    md = [f"# {summary['scenario']} — flush air data (MEADS)", ""]
    md.append(
        f"model **{summary['model']}**, solution **{summary['solution']}**; {summary['samples']} samples, "
        f"{summary['samples_above_min_qbar']} above 850 Pa; max q∞ {summary['max_qbar_pa']:.0f} Pa"
    )
    md.append("")
    for f in summary["failed_ports"]:
        md.append(f"- **failed port** {f['message']}")
    for s in summary["wind_singular_intervals_s"]:
        md.append(f"- wind solution singular (flight-path angle near zero) {s[0]:.1f}–{s[1]:.1f} s: not published")
    if "health" in summary:
        md += ["", health_markdown(summary["health"]).rstrip()]
    tr = summary.get("truth")
    if tr:
        md += [
            "",
            "| quantity (above 850 Pa) | max error | RMS | median 3σ | within 3σ | objective |",
            "|---|---|---|---|---|---|",
        ]
        obj = {"alpha_deg": 0.5, "beta_deg": 0.5, "qbar_pct": 2.0, "mach_air_data": 0.1}
        for k, v in tr["final"].items():
            if v.get("n", 0) == 0:
                continue
            o = obj.get(k)
            md.append(
                f"| {k} | {v['max_abs']:.3g} | {v['rms']:.3g} | {v['median_3sigma']:.3g} | "
                f"{100 * v['fraction_within_3sigma']:.0f} % | {'' if o is None else f'3σ ≤ {o:g}'} |"
            )
        md += _ekf_table(tr)
    return "\n".join(md) + "\n"


def _ekf_table(tr: dict) -> list[str]:
    """Least squares vs EKF pass 1 vs pass 2 (max error / RMS / fraction within the reported 3σ)."""
    cols = [("least squares", tr["final"])] + [
        (f"EKF pass {i}", tr[f"ekf_pass{i}"]) for i in (1, 2) if f"ekf_pass{i}" in tr
    ]
    if len(cols) == 1:
        return []
    alias = {"mach": ("mach", "mach_air_data", "mach_inertial")}
    keys = ("alpha_deg", "beta_deg", "qbar_pct", "mach", "p_inf_pct", "density_pct", "wind_north_mps", "wind_east_mps")
    md = [
        "",
        "| above 850 Pa: max / RMS / within 3σ | " + " | ".join(c for c, _ in cols) + " |",
        "|---" * (len(cols) + 1) + "|",
    ]
    for k in keys:
        cells = []
        for _, blk in cols:
            v = next((blk[a] for a in alias.get(k, (k,)) if blk.get(a, {}).get("n", 0)), None)
            cells.append(
                "—" if v is None else f"{v['max_abs']:.3g} / {v['rms']:.3g} / {100 * v['fraction_within_3sigma']:.0f} %"
            )
        md.append(f"| {k} | " + " | ".join(cells) + " |")
    sf = tr.get("ekf_scale_factors")
    if sf:
        md.append("")
        md.append(
            f"EKF pass 1 scale factors: max |error| {sf['max_abs_error']:.4f} "
            f"(common mode {sf['common_mode_error']:+.4f}), "
            f"{100 * sf['fraction_within_3sigma']:.0f} % within 3σ"
        )
    return md
