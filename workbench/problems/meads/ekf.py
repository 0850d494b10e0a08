"""The tightly-coupled MEADS/IMU extended Kalman filter, multi-pass, with RTS smoothing.

Karlgaard et al., "Mars Entry Atmospheric Data System Modeling and Algorithm Development",
AIAA 2009-3916, and "... Trajectory Reconstruction Algorithms and Flight Results", AIAA 2013,
Sect. III.B (Eq. 19–35) and IV.B.4 (multi-pass), on the shared engine
(:func:`workbench.estimation.ekf.run_filter`, iterated update, :func:`~workbench.estimation.smoother.rts_smooth`).

State (:mod:`.state`, all additive): the deviation of position and velocity in the inertial frame
M from the IMU strapdown (with the attitude-error tilt of the integrated specific force,
``attitude_velocity_coupling``), the body attitude error δθ_B, the NED wind (horizontal a random
walk per km descended, vertical a Gauss–Markov over altitude: gravity waves), ln p∞ and ln ρ∞
(hydrostatic), the transducer scale factors λ_i, and — additions to the paper, so the published
1σ covers the estimator's pressure-model error — a common model level c, per-port coloured model
errors b_i (Gauss–Markov over the flight condition travelled, :func:`flight_distance`), additive
transducer biases β_i (Eq. 51), and the model's Mach and flow-angle errors m, a_m, b_m.

Measurement (Eq. 33–35, iterated): ``p_i = (1 + λ_i)(1 + c)(1 + b_i) h_i(x; M (1 + m), α + a_m,
β + b_m) + β_i`` through the least squares' pressure model (:func:`.airdata.pressure_model`); R
only the channel's white noise and quantisation.  Pass 1 estimates the scale factors; pass 2
divides the pressures by ``1 + λ̂`` and carries λ as Schmidt consider parameters (the data are not
used twice).  The tuning and what each default changed, measured: ``docs/tuning/meads.md``.

A pass runs compiled (:mod:`.kernel`; ``compiled=False``: the shared engine and numpy models, the
reference), on the states it carries (:func:`carried_states`: not the model-error rates b' of the
first-order process, identically zero).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2, gravity_point_mass_gradient
from workbench.core.rotation import quat_to_dcm, skew
from workbench.estimation.ekf import (
    ErrorStateLayout,
    ForwardPass,
    InnovationHistory,
    Measurement,
    derived_with_sigma,
    numeric_jacobian_batched,
    run_filter,
)
from workbench.estimation.smoother import SmoothedPass, rts_smooth
from workbench.models.flush_airdata import FadsVehicle, SurfacePressureTable
from workbench.problems.meads.airdata import ned_frames, pressure_model
from workbench.problems.meads.config import EkfSettings
from workbench.problems.meads.kernel import (
    TRANSITION_PARAMS,
    flow_kernel,
    forward_kernel,
    measurement_kernel,
    rts_kernel,
    transition_kernel,
)
from workbench.problems.meads.state import (
    IB,
    IBD,
    IBIAS,
    IC,
    ILAM,
    ILP,
    ILR,
    IMA,
    IMM,
    IP,
    ITH,
    IV,
    IW,
    IW_DOWN,
    IW_EAST,
    IW_NORTH,
    N_PORTS,
    N_X,
    STATE_NAMES,
)

__all__ = [
    "STATE_NAMES",
    "OUTPUT_NAMES",
    "EkfSettings",
    "EkfInputs",
    "EkfPass",
    "run_pass",
    "run_passes",
    "air_outputs",
    "air_data_of_state",
    "make_transition",
    "make_pressure_model",
    "flight_distance",
    "divergence_note",
    "markov_step",
    "markov_steady_var",
]

LAYOUT = ErrorStateLayout(N_X)
#: state columns the air data (α, β, q∞, M, p∞, ρ∞, wind) read: the air velocity's and ln p∞, ln ρ∞
N_AIR_COLS = ILR + 1
_AIR_LAYOUT = ErrorStateLayout(N_AIR_COLS)
OUTPUT_NAMES = ("alpha", "beta", "qbar", "mach", "p_inf", "rho", "wind_north", "wind_east", "wind_down")
"""Columns of :func:`air_outputs` [rad, rad, Pa, 1, Pa, kg/m³, m/s, m/s, m/s]."""

#: perturbations of the numeric Jacobians, error-state units
EPS = np.r_[
    np.full(3, 1.0), np.full(3, 1e-2), np.full(3, 1e-6), np.full(3, 1e-2), 1e-5, 1e-5, np.full(7, 1e-6), 1e-6,
    np.full(2 * N_PORTS, 1e-6), np.full(N_PORTS, 1e-2), 1e-6, 1e-6, 1e-6,
]  # fmt: skip


@dataclass(frozen=True)
class EkfInputs:
    """What the filter reads, at the n pressure times ``t`` [s]: the strapdown ``p_M``, ``v_M``
    (n, 3) and ``q_M_B`` (n, 4) (:class:`.pipeline.Navigation`), the initial 1σ of position [m],
    velocity [m/s] and attitude [rad], the (lag-corrected) pressures ``p`` (n, m) [Pa], their 1σ
    ``sigma_p`` (n, m) [Pa], ``usable`` (n, m) bool (finite and not failed), the vehicle, the
    pressure ``model`` (``"newtonian"``/``"table"``), its ``table`` and ``gamma``."""

    t: np.ndarray
    p_M: np.ndarray
    v_M: np.ndarray
    q_M_B: np.ndarray
    sigma_pos: float
    sigma_vel: float
    sigma_att: float
    p: np.ndarray
    sigma_p: np.ndarray
    usable: np.ndarray
    vehicle: FadsVehicle
    model: str
    table: SurfacePressureTable | None
    gamma: float


@dataclass(frozen=True)
class EkfPass:
    """One filter pass (a pipeline stage): ``index`` 1 or 2 of ``passes``; ``t`` (n,) [s];
    ``forward`` the :class:`ForwardPass` (innovations under ``"pressure"``, NaN for unused ports;
    ``P_prior``, ``P_post``, ``F`` empty and ``Q`` None: dropped after smoothing, the forward 1σ
    is ``sigma_post``; all kept with ``run_pass(keep_all=True)``); ``smoothed`` the
    :class:`SmoothedPass` (``G`` empty, dropped); ``outputs`` (n, 9) and ``sigma`` (n, 9) of
    :data:`OUTPUT_NAMES` from the smoothed state; ``scale`` (7,) the scale factors used or found
    (smoothed) with 1σ ``sigma_scale`` and covariance ``scale_cov`` (7, 7); ``scale_estimated``
    whether this pass estimated them;
    ``nis_port`` (k, 7) per-port normalised innovations squared ``y_i²/S_ii`` of the forward pass at
    the processed samples (NaN where unused); ``wall_s`` [s]; ``sigma_post`` (n, N_X) the forward
    pass's 1σ of every state (error-state units).  The states (``x_prior``, ``x_post``, smoothed
    ``x``) and ``sigma_post`` are in the full layout (:data:`N_X`, zero where not carried); the
    covariances, F, Q and gains over the carried states only (:func:`carried_states`, n_c): the
    states not carried have none (zero variance, no coupling)."""

    index: int
    passes: int
    t: np.ndarray
    forward: ForwardPass
    smoothed: SmoothedPass
    outputs: np.ndarray
    sigma: np.ndarray
    scale: np.ndarray
    sigma_scale: np.ndarray
    scale_cov: np.ndarray
    scale_estimated: bool
    nis_port: np.ndarray
    wall_s: float
    sigma_post: np.ndarray

    @property
    def stage_label(self) -> str:
        """Its name in progress lines and ``summary["stage_times_s"]``."""
        what = "scale factors estimated" if self.scale_estimated else "scale-corrected pressures"
        return f"EKF pass {self.index}/{self.passes} ({what}, RTS smoothed)"

    def output(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(value, 1σ) (n,) of one of :data:`OUTPUT_NAMES`."""
        j = OUTPUT_NAMES.index(name)
        return self.outputs[:, j], self.sigma[:, j]

    def output_error_pct(self, name: str, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(error, 1σ) (n,) [% of ``truth`` (n,), the true value on :attr:`t`] of one of
        :data:`OUTPUT_NAMES`."""
        v, s = self.output(name)
        return 100 * (v / truth - 1), 100 * s / truth

    def scale_history(self) -> tuple[np.ndarray, np.ndarray]:
        """Scale factors and their 1σ (n, 7) [of reading] along the pass: the forward filter's
        estimate converging when this pass estimated them, else the constant correction applied."""
        if self.scale_estimated:
            return self.forward.x_post[:, ILAM], self.sigma_post[:, ILAM]
        n, m = self.t.size, self.scale.size
        return np.broadcast_to(self.scale, (n, m)), np.broadcast_to(self.sigma_scale, (n, m))

    def innovation_sigma(self) -> np.ndarray | None:
        """√S_ii (k, 7) [Pa] of the forward pass's pressure innovations (None: no update ran)."""
        inn = self.forward.innovations.get("pressure")
        return None if inn is None else np.sqrt(np.einsum("kii->ki", inn.S))


# ------------------------------------------------------------------------------------- model


def _air_velocity(X: np.ndarray, C_B_M: np.ndarray) -> np.ndarray:
    """Air-relative velocity in body axes (..., 3) [m/s] of states X (..., 21) with the strapdown
    attitude C_B_M (..., 3, 3): ``(I − [δθ×]) C_B_M (v_M − Ω × p_M − C_M_N w_N)``."""
    p_M, v_M = X[..., IP], X[..., IV]
    v_g = v_M + MARS.rotation_rate * np.stack([p_M[..., 1], -p_M[..., 0], np.zeros_like(p_M[..., 0])], axis=-1)
    C_N_M = ned_frames(p_M.reshape(-1, 3)).reshape(*p_M.shape[:-1], 3, 3)
    v_air_M = v_g - np.einsum("...ji,...j->...i", C_N_M, X[..., IW])
    u = np.einsum("...ij,...j->...i", C_B_M, v_air_M)
    th = X[..., ITH]
    return u - np.stack(
        [
            th[..., 1] * u[..., 2] - th[..., 2] * u[..., 1],
            th[..., 2] * u[..., 0] - th[..., 0] * u[..., 2],
            th[..., 0] * u[..., 1] - th[..., 1] * u[..., 0],
        ],
        axis=-1,
    )


def _freestream(u: np.ndarray, ln_p: np.ndarray, ln_rho: np.ndarray, gamma: float) -> tuple[np.ndarray, ...]:
    """(α, β, q∞, M, p∞, ρ∞) (...,) from the body-axis air velocity u (..., 3) and ln p∞, ln ρ∞."""
    V = np.linalg.norm(u, axis=-1)
    alpha = np.arctan2(u[..., 2], u[..., 0])
    beta = np.arcsin(np.clip(u[..., 1] / V, -1.0, 1.0))
    p_inf, rho = np.exp(ln_p), np.exp(ln_rho)
    return alpha, beta, 0.5 * rho * V**2, V / np.sqrt(gamma * p_inf / rho), p_inf, rho


def air_data_of_state(X: np.ndarray, C_B_M: np.ndarray, gamma: float) -> tuple[np.ndarray, ...]:
    """(α, β, q∞, M, p∞, ρ∞) (...,) from states X (..., 21) and the strapdown C_B_M (..., 3, 3)."""
    return _freestream(_air_velocity(X, C_B_M), X[..., ILP], X[..., ILR], gamma)


#: perturbations of the air-data Jacobian in (u_B [m/s], ln p∞, ln ρ∞)
_EPS_Z = np.array([1e-2, 1e-2, 1e-2, 1e-5, 1e-5])
_NO_GRID = np.zeros(2)
_NO_TABLE = np.zeros((2, 2, 2, 2))


def make_pressure_model(inp: EkfInputs, *, compiled: bool = True, keep: np.ndarray | None = None):
    """``h(x, C_B_M, use) -> (p (k,), H (k, n_c))``: the pressures of the ports ``use`` [Pa] and
    their Jacobian over the state x (n_c,) of the carried states ``keep`` (:func:`carried_states`;
    None: all :data:`N_X`).  The model depends on the state only through z = (u_B, ln p∞, ln ρ∞)
    and λ, so the surface-pressure model is differenced in z (11 evaluations) and chained with
    ∂z/∂x.  ``compiled``: run as the compiled :func:`.kernel.measurement_kernel`; False: the numpy
    reference path (same numbers to a few ulp, ``tests/problems/meads/test_kernel.py``)."""
    keep = np.arange(N_X) if keep is None else np.asarray(keep, dtype=int)
    h4 = pressure_model(inp.vehicle, inp.model, "mach", inp.gamma, inp.table)
    D = np.diag(_EPS_Z)
    dz = np.concatenate([np.zeros((1, 5)), D, -D])
    compiled = compiled and inp.model in ("newtonian", "table")
    if compiled:
        eps_c, eps_z, gamma, omega, table_model, *rest = _measurement_args(inp, keep)

    def h(x: np.ndarray, C_B_M: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if compiled:
            return measurement_kernel(x, C_B_M, eps_c, eps_z, use, gamma, omega, table_model, *rest)
        pz, H = h_full(x if keep.size == N_X else _expand(x, keep), C_B_M, use)
        return pz, (H if keep.size == N_X else H[:, keep])

    def h_full(x: np.ndarray, C_B_M: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u0, Ju = numeric_jacobian_batched(lambda X: _air_velocity(X, C_B_M), x, LAYOUT, EPS)
        Z = np.r_[u0, x[ILP], x[ILR]][None, :] + dz
        a, b, q, M, _, _ = _freestream(Z[:, :3], Z[:, 3], Z[:, 4], inp.gamma)
        pz = h4(np.stack([q, a, b, M], axis=1))[:, use]  # (11, k)
        p0 = pz[0]
        dp_dz = ((pz[1:6] - pz[6:11]) / (2.0 * _EPS_Z)[:, None]).T  # (k, 5)
        Jz = np.zeros((5, N_X))
        Jz[:3] = Ju
        Jz[3, ILP] = Jz[4, ILR] = 1.0
        # the model read at M (1 + m): p ≈ p0 + m g_m with g_m = M ∂p/∂M at constant q∞, p∞, from
        # the ln p∞, ln ρ∞ columns (M = V √(ρ∞/γp∞), p = p∞ + q∞ Cp); g_m's own derivatives
        # (m times the model's curvature) are left out of H
        g_m = dp_dz[:, 4] - dp_dz[:, 3] - p0 + 2.0 * math.exp(x[ILP])
        # and at (α + a_m, β + b_m): g_a, g_b = ∂p/∂α, ∂p/∂β at constant V, q∞, M (u rotated)
        V = math.sqrt(float(u0 @ u0))
        ca, sa = u0[0] / math.hypot(u0[0], u0[2]), u0[2] / math.hypot(u0[0], u0[2])
        sb = u0[1] / V
        cb = math.sqrt(max(1.0 - sb * sb, 0.0))
        du = V * np.array([[-sa * cb, 0.0, ca * cb], [-ca * sb, cb, -sa * sb]])  # ∂u/∂α, ∂u/∂β
        g_ab = dp_dz[:, :3] @ du.T  # (k, 2)
        pm = p0 + x[IMM] * g_m + g_ab @ x[IMA]
        lam = 1.0 + x[ILAM][use]
        lev = 1.0 + x[IC]
        mod = 1.0 + x[IB][use]
        rows = np.arange(use.size)
        H = (lam * lev * mod)[:, None] * (dp_dz @ Jz)
        H[rows, ILAM.start + use] = pm * lev * mod
        H[:, IC] = pm * lam * mod
        H[rows, IB.start + use] = pm * lam * lev
        H[rows, IBIAS.start + use] = 1.0
        H[:, IMM] = g_m * lam * lev * mod
        H[:, IMA] = g_ab * (lam * lev * mod)[:, None]
        return pm * lam * lev * mod + x[IBIAS][use], H

    return h


def _measurement_args(inp: EkfInputs, keep: np.ndarray) -> tuple:
    """The arguments of :func:`.kernel.measurement_kernel` after ``x, C, … use`` ("newtonian" and
    "table" models): ``eps_x, eps_z, gamma, omega, table_model``, the ports, the table's grids
    and the carried-state columns of the model-error blocks."""
    veh, tab = inp.vehicle, inp.table
    ports = (veh.cone(), veh.clock(), veh.radius() / veh.base_radius)
    grids = (_NO_GRID,) * 4 + (_NO_TABLE,)
    if tab is not None:
        grids = (tab.mach, tab.alpha_t, tab.clock, tab.s, np.ascontiguousarray(tab.values, dtype=float))
    cols = np.searchsorted(keep, [ILAM.start, IC, IB.start, IBIAS.start, IMM, IMA.start])
    return (EPS[keep], _EPS_Z, inp.gamma, MARS.rotation_rate, inp.model == "table", *ports, *grids, cols)


def air_outputs(x: np.ndarray, P: np.ndarray, q_M_B: np.ndarray, gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """:data:`OUTPUT_NAMES` (n, 9) and their 1σ (n, 9) from states x (n, N_X), covariances P
    (n, n_c, n_c) (all states or the carried ones: the first :data:`N_AIR_COLS` are the same) and
    the strapdown attitude q_M_B (n, 4) (first-order propagation).  The outputs
    read only the first :data:`N_AIR_COLS` states, so only those and their covariance block enter
    (the Jacobian's other columns are exactly zero: the same sums without their zero terms).
    Evaluated :data:`OUTPUT_CHUNK` samples at a time (each sample's outputs depend on that sample
    only)."""
    x = x[:, :N_AIR_COLS]
    P = P[:, :N_AIR_COLS, :N_AIR_COLS]
    C_all = np.swapaxes(quat_to_dcm(q_M_B), 1, 2)[:, None]
    ys, ss = [], []
    for i in range(0, len(x), OUTPUT_CHUNK):
        C_B_M = C_all[i : i + OUTPUT_CHUNK]

        def g(X, C_B_M=C_B_M):
            a, b, q, M, pi, rho = air_data_of_state(X, C_B_M, gamma)
            w = X[..., IW]
            return np.stack([a, b, q, M, pi, rho, w[..., 0], w[..., 1], w[..., 2]], axis=-1)

        y, s, _ = derived_with_sigma(g, x[i : i + OUTPUT_CHUNK], P[i : i + OUTPUT_CHUNK], _AIR_LAYOUT, EPS[:N_AIR_COLS])
        ys.append(y)
        ss.append(s)
    return np.concatenate(ys), np.concatenate(ss)


#: samples per block of :func:`air_outputs`
OUTPUT_CHUNK = 256


def _initial(inp: EkfInputs, st: EkfSettings, scale0: np.ndarray, scale_cov: np.ndarray, compiled: bool) -> tuple:
    atm = MarsEngineeringAtmosphere()
    h0 = float(np.linalg.norm(inp.p_M[0]) - MARS.reference_radius)
    x0 = np.zeros(N_X)
    x0[IP], x0[IV] = inp.p_M[0], inp.v_M[0]
    x0[ILP], x0[ILR] = math.log(float(atm.pressure(h0))), math.log(float(atm.density(h0)))
    x0[ILAM] = scale0
    sw = st.wind_sigma_mps
    d = np.r_[
        np.full(3, inp.sigma_pos**2),
        np.full(3, inp.sigma_vel**2),
        np.full(3, inp.sigma_att**2),
        [sw**2, sw**2, st.vertical_wind_sigma_mps**2],
        np.full(2, st.atmosphere_sigma_ln**2),
        np.zeros(scale0.size),
        [st.model_level_sigma**2],
        np.full(N_PORTS, markov_steady_var(st)[0]),
        np.full(N_PORTS, markov_steady_var(st)[1]),
        np.full(N_PORTS, st.bias_sigma_pa**2),
        [st.model_mach_sigma**2],
        np.full(2, angle_sigma(st, _flow(x0, quat_to_dcm(inp.q_M_B[0]).T, inp.gamma, compiled)[2]) ** 2),
    ]
    P0 = np.diag(d)
    if st.temperature_sigma_ln > 0.0:  # var(ln p − ln rho) = 2 s² − 2 cov = temperature_sigma_ln²
        P0[ILP, ILR] = P0[ILR, ILP] = st.atmosphere_sigma_ln**2 - 0.5 * st.temperature_sigma_ln**2
    P0[ILAM, ILAM] = scale_cov
    return x0, P0


def markov_steady_var(st: EkfSettings) -> tuple[float, float]:
    """Steady-state variances of one port's model-error Gauss–Markov: (b [1], b' [1 per correlation
    length]); b' is absent (0) for the first-order process."""
    s2 = st.model_error_sigma**2
    return (s2, s2) if st.model_error_order == 2 else (s2, 0.0)


def markov_step(st: EkfSettings, d: float) -> tuple[np.ndarray, np.ndarray]:
    """(Φ, Q) (2, 2) of one port's model-error state [b, b'] over the distance ``d`` >= 0 travelled
    in flight condition, in correlation lengths (:func:`flight_distance`): first order
    ``db/ds = −b + w`` or critically damped second order ``b'' = −2b' − b + w`` (smooth: its
    increments over a short step are O(d^{3/2}) instead of O(d^{1/2})); Q is the exact
    ``P∞ − Φ P∞ Φᵀ`` of the stationary process (``P∞`` of :func:`markov_steady_var`)."""
    e = math.exp(-d)
    if st.model_error_order == 2:
        Phi = e * np.array([[1.0 + d, d], [-d, 1.0 - d]])
    else:
        Phi = np.array([[e, 0.0], [0.0, 0.0]])
    Pinf = np.diag(markov_steady_var(st))
    return Phi, Pinf - Phi @ Pinf @ Phi.T


def angle_sigma(st: EkfSettings, mach: float) -> float:
    """1σ [rad] of the model's flow-angle error at ``mach``: ``model_angle_sigma_deg`` at and below
    ``model_angle_mach_low``, ``model_angle_hypersonic_fraction`` of it at and above
    ``model_angle_mach_high``, linear in Mach between.  Why it falls with Mach: the Mach-independence
    principle (Oswatitsch, "Similarity laws for hypersonic flow", 1950; Anderson, "Hypersonic and
    High-Temperature Gas Dynamics", 2006, Sect. 4.4): a blunt forebody's surface-pressure
    distribution freezes as the Mach number grows, so a table or Newtonian-type model places the
    stagnation point well in hypersonic flow, while at low supersonic Mach the shock stand-off and
    the sonic line move with Mach and the flow angle the model infers is least certain (the
    flight FADS calibrations' "upwash" corrections are largest there: Whitmore, Cobleigh & Haering,
    "Design and calibration of the X-33 flush airdata sensing (FADS) system", AIAA 98-0201)."""
    s0 = math.radians(st.model_angle_sigma_deg)
    lo, hi = st.model_angle_mach_low, st.model_angle_mach_high
    w = min(max((float(mach) - lo) / (hi - lo), 0.0), 1.0)
    return s0 * (1.0 + w * (st.model_angle_hypersonic_fraction - 1.0))


def _flow(x: np.ndarray, C_B_M: np.ndarray, gamma: float, compiled: bool = True) -> tuple[float, float, float]:
    """(α [rad], β [rad], Mach) of one state ``x`` (N_X,) with the strapdown C_B_M (3, 3); compiled
    (:func:`.kernel.flow_kernel`) or the numpy :func:`air_data_of_state`."""
    if compiled:
        # C-ordered as the forward pass's C_B_M rows (a transposed DCM would compile a second signature)
        return flow_kernel(x, np.ascontiguousarray(C_B_M), MARS.rotation_rate, gamma)
    a, b, _, m, _, _ = air_data_of_state(x, C_B_M, gamma)
    return float(a), float(b), float(m)


def flight_distance(
    x0: np.ndarray, x1: np.ndarray, C0: np.ndarray, C1: np.ndarray, gamma: float, st: EkfSettings
) -> float:
    """The distance [correlation lengths] travelled in flight condition from state x0 (attitude
    C_B_M C0 (3, 3)) to x1 (C1): ``|ΔM| / model_error_mach_length + (|Δα| + |Δβ|) /
    model_error_angle_deg`` — the estimator's pressure model errs as a smooth function of Mach
    and the flow angles, so its error decorrelates with them, not with time."""
    return _distance(_flow(x0, C0, gamma), _flow(x1, C1, gamma), st)


def _distance(f0: tuple[float, float, float], f1: tuple[float, float, float], st: EkfSettings) -> float:
    """:func:`flight_distance` from the two states' (α [rad], β [rad], Mach) of :func:`_flow`."""
    a0, b0, m0 = f0
    a1, b1, m1 = f1
    d_angle = (abs(a1 - a0) + abs(b1 - b0)) / math.radians(st.model_error_angle_deg)
    return float(abs(m1 - m0) / st.model_error_mach_length + d_angle)


def make_transition(inp: EkfInputs, st: EkfSettings, *, compiled: bool = True, keep: np.ndarray | None = None):
    """``transition(x, t0, t1) -> (x1, F, Q)`` on the pressure-time grid (module docstring) over
    the state x (n_c,) of the carried states ``keep`` (:func:`carried_states`; None: all
    :data:`N_X`).  ``compiled``: one call of the compiled :func:`.kernel.transition_kernel`; False:
    the numpy reference path (``tests/problems/meads/test_kernel.py``)."""
    t = inp.t
    idx = {float(v): i for i, v in enumerate(t.tolist())}
    I3 = np.eye(3)
    C_M_B, dv_sf, markov = _strapdown_increments(inp, st)
    C_B_M = np.swapaxes(C_M_B, 1, 2)
    keep = np.arange(N_X) if keep is None else np.asarray(keep, dtype=int)
    if compiled:
        args = _transition_args(inp, st, keep, C_M_B, dv_sf, markov)

        def transition_compiled(x, t0, t1):
            return transition_kernel(x, idx[t1], t1 - t0, *args)

        return transition_compiled

    def transition(x, t0, t1):
        k = idx[t1]
        dt = t1 - t0
        dp, dv = x[IP] - inp.p_M[k - 1], x[IV] - inp.v_M[k - 1]
        G = gravity_point_mass_gradient(inp.p_M[k - 1][None], MARS.gm)[0]
        # the attitude error tilts the specific force the strapdown integrated:
        # δv' = δv − [Δv_sf×] C_M_B δθ (module docstring)
        Fvt = -skew(dv_sf[k - 1]) @ C_M_B[k - 1] if st.attitude_velocity_coupling else np.zeros((3, 3))
        x1 = x.copy()
        x1[IP] = inp.p_M[k] + dp + dv * dt
        x1[IV] = inp.v_M[k] + dv + G @ dp * dt + Fvt @ x[ITH]
        Rb = C_M_B[k].T @ C_M_B[k - 1]  # body at k-1 -> body at k
        x1[ITH] = Rb @ x[ITH]
        r0, r1 = np.linalg.norm(x[IP]), np.linalg.norm(x1[IP])
        dh = r1 - r0
        c = MARS.gm / r0**2 * math.exp(x[ILR] - x[ILP])  # g ρ/p [1/m]
        x1[ILP] = x[ILP] - c * dh
        x1[ILR] = x[ILR] - c * dh
        F = np.eye(N_X)
        F[IP, IV] = dt * I3
        F[IV, IP] = G * dt
        F[IV, ITH] = Fvt
        F[ITH, ITH] = Rb
        u0, u1 = x[IP] / r0, x1[IP] / r1
        dh_dp = u1 - u0  # ∂Δh/∂p (through p1 = p + ...)
        dh_dv = u1 * dt
        for i in (ILP, ILR):
            F[i, IP] = -c * dh_dp
            F[i, IV] = -c * dh_dv
            F[i, ILP] = F[i, ILP] + c * dh
            F[i, ILR] = F[i, ILR] - c * dh
        Q = np.zeros((N_X, N_X))
        qa = st.accel_psd
        Q[IP, IP] = qa * dt**3 / 3.0 * I3
        Q[IP, IV] = Q[IV, IP] = qa * dt**2 / 2.0 * I3
        Q[IV, IV] = qa * dt * I3
        Q[ITH, ITH] = st.attitude_psd * dt * I3
        km = abs(dh) / 1e3
        Q[IW_NORTH, IW_NORTH] = Q[IW_EAST, IW_EAST] = st.wind_var_per_km * km
        if st.vertical_wind_length_km > 0.0:
            # the vertical wind as gravity waves: zero-mean, decorrelating over the altitude travelled
            phi_w = math.exp(-km / st.vertical_wind_length_km)
            x1[IW_DOWN] = phi_w * x[IW_DOWN]
            F[IW_DOWN, IW_DOWN] = phi_w
            Q[IW_DOWN, IW_DOWN] = st.vertical_wind_sigma_mps**2 * (1.0 - phi_w**2)
        else:
            Q[IW_DOWN, IW_DOWN] = st.wind_var_per_km * km * (st.vertical_wind_sigma_mps / st.wind_sigma_mps) ** 2
        Q[ILP, ILP] = Q[ILR, ILR] = st.atmosphere_var_per_km * km
        # the flight condition at both ends, once: the distance and the flow-angle σ(M) read it
        f0 = _flow(x, C_B_M[k - 1], inp.gamma, compiled) if markov else None
        f1 = _flow(x1, C_B_M[k], inp.gamma, compiled) if markov else None
        dist = _distance(f0, f1, st) if markov else 0.0
        if st.model_error_sigma > 0.0:
            Phi, Qb = markov_step(st, dist)
            x1[IB] = Phi[0, 0] * x[IB] + Phi[0, 1] * x[IBD]
            x1[IBD] = Phi[1, 0] * x[IB] + Phi[1, 1] * x[IBD]
            for a, ia in ((0, IB), (1, IBD)):
                for b, ib in ((0, IB), (1, IBD)):
                    F[ia, ib] = Phi[a, b] * np.eye(N_PORTS)
                    Q[ia, ib] = Qb[a, b] * np.eye(N_PORTS)
        if st.model_mach_sigma > 0.0:
            phi = math.exp(-dist)
            x1[IMM] = phi * x[IMM]
            F[IMM, IMM] = phi
            Q[IMM, IMM] = st.model_mach_sigma**2 * (1.0 - phi**2)
        if st.model_angle_sigma_deg > 0.0:
            # a_m = s(M) z, z a unit first-order Gauss–Markov over the distance: as s(M) changes
            # with Mach (angle_sigma) the state scales with it, its variance stays s(M)²
            s0, s1 = angle_sigma(st, f0[2]), angle_sigma(st, f1[2])
            phi = math.exp(-dist)
            f = phi * s1 / s0 if s0 > 0.0 else 0.0
            x1[IMA] = f * x[IMA]
            F[IMA, IMA] = f * np.eye(2)
            Q[IMA, IMA] = s1**2 * (1.0 - phi**2) * np.eye(2)
        return x1, F, Q

    if keep.size == N_X:
        return transition
    ix = np.ix_(keep, keep)

    def carried(xr, t0, t1):
        # the full state's transition, the states not carried zero
        x1, F, Q = transition(_expand(xr, keep), t0, t1)
        return x1[keep], F[ix], Q[ix]

    return carried


def _strapdown_increments(inp: EkfInputs, st: EkfSettings) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(C_M_B (n, 3, 3), dv_sf (n − 1, 3) [m/s], markov)``: the strapdown attitude, its
    specific-force velocity increments in M over each step (its velocity change less the gravity
    it integrated: point mass + J2, trapezoidal) and whether a model-error state decorrelates
    with the flight condition."""
    C_M_B = quat_to_dcm(inp.q_M_B)
    markov = st.model_error_sigma > 0.0 or st.model_mach_sigma > 0.0 or st.model_angle_sigma_deg > 0.0
    g = gravity_j2(inp.p_M, MARS)
    dv_sf = np.diff(inp.v_M, axis=0) - 0.5 * (g[1:] + g[:-1]) * np.diff(inp.t)[:, None]
    return C_M_B, dv_sf, markov


def _transition_args(inp, st, keep, C_M_B, dv_sf, markov) -> tuple:
    """The arguments of :func:`.kernel.transition_kernel` after ``x, k, dt``: the strapdown, the
    per-step matrices for all steps at once, the constants, the settings and the carried-state
    columns of the model-error blocks."""
    G = gravity_point_mass_gradient(inp.p_M[:-1], MARS.gm)
    if st.attitude_velocity_coupling:
        Fvt = -np.matmul(skew(dv_sf), C_M_B[:-1])
    else:
        Fvt = np.zeros((max(len(inp.t) - 1, 0), 3, 3))
    Rb = np.matmul(np.swapaxes(C_M_B[1:], 1, 2), C_M_B[:-1])
    C_B_M = np.ascontiguousarray(np.swapaxes(C_M_B, 1, 2))
    p_M, v_M = np.ascontiguousarray(inp.p_M, dtype=float), np.ascontiguousarray(inp.v_M, dtype=float)
    values = {
        **{name: float(getattr(st, name)) for name in TRANSITION_PARAMS if hasattr(st, name)},
        "model_angle_sigma_rad": math.radians(st.model_angle_sigma_deg),
        "model_error_angle_rad": math.radians(st.model_error_angle_deg),
        "markov": float(markov),
    }
    par = np.array([values[name] for name in TRANSITION_PARAMS])
    second = bool(np.isin(np.arange(N_X)[IBD], keep).all())
    cols = np.array(
        [np.searchsorted(keep, IB.start), np.searchsorted(keep, IBD.start) if second else -1]
        + [np.searchsorted(keep, IMM), np.searchsorted(keep, IMA.start)]
    )
    if st.model_error_order == 2 and not second:
        raise ValueError("the second-order model error needs its rate states carried")
    return (p_M, v_M, G, Fvt, Rb, C_B_M, MARS.gm, MARS.rotation_rate, inp.gamma, par, cols)


def run_pass(
    inp: EkfInputs,
    st: EkfSettings,
    *,
    index: int = 1,
    passes: int = 1,
    estimate_scale: bool = True,
    scale_fixed: np.ndarray | None = None,
    scale_cov_fixed: np.ndarray | None = None,
    keep_all: bool = False,
    compiled: bool = True,
) -> EkfPass:
    """One pass: forward iterated EKF over the pressure samples, then RTS smoothing.

    ``keep_all``: keep the forward pass's covariances and the smoother's gains in the result
    (tests); by default they are dropped after smoothing (:class:`EkfPass`).  ``compiled``: the
    compiled measurement and flight-condition kernels (False: the numpy reference path).

    ``estimate_scale``: the scale factors are states (prior 0 ± ``st.scale_factor_sigma``);
    otherwise the pressures are divided by ``1 + scale_fixed`` (7,) and the scale-factor states
    become *consider* parameters (Schmidt): mean zero, covariance ``scale_cov_fixed`` (7, 7) (the
    previous pass's), carried in P so that the innovations' S and the outputs' 1σ include them,
    but never updated (gain projected to zero on them, no smoother gain) — the data are not
    used twice.
    """
    t0 = time.perf_counter()
    m = inp.p.shape[1]
    p, sig = inp.p, inp.sigma_p
    scale0 = np.zeros(m)
    if estimate_scale:
        Pl0 = np.diag(np.full(m, st.scale_factor_sigma**2))
        projector = None
    else:
        lam = np.zeros(m) if scale_fixed is None else np.asarray(scale_fixed, float)
        Pl0 = np.zeros((m, m)) if scale_cov_fixed is None else np.asarray(scale_cov_fixed, float)
        p = p / (1.0 + lam)
        Pi = np.eye(N_X)
        Pi[ILAM, ILAM] = 0.0

    keep = carried_states(st)
    ix = np.ix_(keep, keep)
    if not estimate_scale:
        Pi = Pi[ix]

        def projector(_x):
            return Pi

    layout = ErrorStateLayout(keep.size)
    x0, P0 = _initial(inp, st, scale0, Pl0, compiled)
    x0, P0 = x0[keep], P0[ix]
    h = make_pressure_model(inp, compiled=compiled, keep=keep)
    C_B_M = np.swapaxes(quat_to_dcm(inp.q_M_B), 1, 2)
    transition = make_transition(inp, st, compiled=compiled, keep=keep)

    seen = {}

    def measurements_at(k, tk, x):
        seen["x"] = x  # the prior of the step (the diagnosis of a failed update)
        use = np.flatnonzero(inp.usable[k] & np.isfinite(p[k]))
        if use.size == 0:
            return []
        C = C_B_M[k]
        cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

        def both(xx):
            # h and H from one evaluation; the update asks for h(x_i), then H(x_i)
            key = xx.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = h(xx, C, use)
            return cache[key]

        return [
            Measurement(
                "pressure",
                p[k, use],
                np.diag(sig[k, use] ** 2),
                lambda xx: both(xx)[0],
                H=lambda xx: both(xx)[1],
                iterations=st.iterations,
                step_tol=EPS[keep],
                gain_projector=projector,
                slots=use,
                size=m,
            )
        ]

    with np.errstate(invalid="ignore"):
        if compiled and inp.model in ("newtonian", "table"):
            consider = np.zeros(keep.size, bool)
            if not estimate_scale:
                consider[ILAM] = True
            fp = _forward_compiled(inp, st, keep, x0, P0, p, sig, consider, keep_all)
        else:
            try:
                fp = run_filter(x0, P0, inp.t, transition, None, measurements_at, layout, keep_q=keep_all)
            except np.linalg.LinAlgError as err:
                raise np.linalg.LinAlgError(f"{err}; {divergence_note(_expand(seen['x'], keep), st)}") from err
        consider_idx = None if estimate_scale else np.arange(keep.size)[ILAM]
        sm = _smooth_compiled(fp, consider_idx) if compiled else None
        if sm is None:
            sm = rts_smooth(fp, layout, consider=consider_idx)
    sigma_post = np.sqrt(np.maximum(np.einsum("nii->ni", fp.P_post), 0.0))
    if keep.size < N_X:  # the states back to the full layout: those not carried are exactly zero
        sigma_post = _expand(sigma_post, keep)
        fp = replace(fp, x_prior=_expand(fp.x_prior, keep), x_post=_expand(fp.x_post, keep))
        sm = replace(sm, x=_expand(sm.x, keep))
    out, sd = air_outputs(sm.x, sm.P, inp.q_M_B, inp.gamma)
    inn = fp.innovations.get("pressure")
    if inn is None:
        nis_port = np.zeros((0, m))
    else:
        nis_port = inn.y**2 / np.einsum("kii->ki", inn.S)
    if estimate_scale:
        lam = sm.x[0, ILAM].copy()
    Pl = sm.P[0][ILAM, ILAM].copy()
    slam = np.sqrt(np.diag(Pl))
    # what the pass keeps: the smoother's inputs P_prior and F, its gains G and the forward
    # covariances are not read after it (recording, health and summary use x_post, its 1σ, the
    # innovations, the smoothed x and P); each is an (n, n_c, n_c) array (28 MB on msl_meads)
    if not keep_all:
        none = np.empty((0, keep.size, keep.size))
        fp = replace(fp, P_prior=none, P_post=none, F=none, Q=None)
        sm = replace(sm, G=none)
    return EkfPass(
        index,
        passes,
        inp.t,
        fp,
        sm,
        out,
        sd,
        lam,
        slam,
        Pl,
        estimate_scale,
        nis_port,
        time.perf_counter() - t0,
        sigma_post,
    )


def _forward_compiled(inp, st, keep, x0, P0, p, sig, consider, keep_all) -> ForwardPass:
    """The forward pass of :func:`run_pass` as one :func:`.kernel.forward_kernel` call (the
    pressures ``p`` (n, m) [Pa] as the pass uses them, their 1σ ``sig``); the same
    :class:`ForwardPass` as ``run_filter`` with :func:`make_transition` and
    :func:`make_pressure_model` (the reference path, ``run_pass(compiled=False)``)."""
    t = np.ascontiguousarray(inp.t, dtype=float)
    n, m = p.shape
    n_c = keep.size
    usable = inp.usable & np.isfinite(p)
    C_M_B, dv_sf, markov = _strapdown_increments(inp, st)
    targs = _transition_args(inp, st, keep, C_M_B, dv_sf, markov)
    margs = _measurement_args(inp, keep)
    margs = margs[:2] + margs[4:]  # the kernel has gamma and omega from the transition's arguments
    out = dict(
        x_prior=np.empty((n, n_c)),
        P_prior=np.empty((n, n_c, n_c)),
        x_post=np.empty((n, n_c)),
        P_post=np.empty((n, n_c, n_c)),
        F=np.empty((n, n_c, n_c)),
        Q=np.empty((n if keep_all else 1, n_c, n_c)),
    )
    zp, y, S = np.full((n, m), np.nan), np.full((n, m), np.nan), np.full((n, m, m), np.nan)
    nis = np.full(n, np.nan)
    status, k = forward_kernel(
        np.ascontiguousarray(x0), np.ascontiguousarray(P0), t, *targs, *margs,
        np.ascontiguousarray(np.where(usable, p, 0.0)), np.ascontiguousarray(np.where(usable, sig, 1.0) ** 2),
        usable, int(st.iterations), EPS[keep], consider,
        out["x_prior"], out["P_prior"], out["x_post"], out["P_post"], out["F"], out["Q"], bool(keep_all),
        zp, y, S, nis,
    )  # fmt: skip
    if status:
        what = {
            1: "innovation covariance S is not positive definite",
            2: "non-finite innovation (check z, h(x) and R): the state diverged, or this measurement's values are "
            "not in the unit its file declares",
            3: "iterated update: H P Hᵀ + R not positive definite",
        }[int(status)]
        note = divergence_note(_expand(out["x_prior"][k], keep), st)
        raise np.linalg.LinAlgError(f"step {k} (t={t[k]} s), measurement 'pressure': {what}; {note}")
    steps = np.flatnonzero(usable.any(axis=1))
    inn = InnovationHistory(
        t=t[steps],
        step=steps,
        z=np.where(usable, p, np.nan)[steps],
        z_pred=zp[steps],
        y=y[steps],
        S=S[steps],
        nis=nis[steps],
        accepted=np.ones(steps.size, bool),
    )
    return ForwardPass(t, innovations={"pressure": inn} if steps.size else {}, **{
        **out, "Q": out["Q"] if keep_all else None})  # fmt: skip


def divergence_note(x: np.ndarray, st: EkfSettings) -> str:
    """What the state x (N_X,) of a failed update says about it: the atmosphere it carries (ln p∞,
    ln ρ∞ and the temperature their ratio implies, p∞/ρ∞ = R T with the engineering atmosphere's
    gas constant R) and the residual biases in σ of their prior.  A pressure model fed an
    atmosphere far below the true density predicts ~0 Pa with a vanishing sensitivity to ln ρ∞, so
    the biases take up the pressure instead: the filter lost the atmosphere (its own divergence,
    not a unit error of the inputs, when both show it)."""
    ln_t = float(x[ILP] - x[ILR]) - math.log(MarsEngineeringAtmosphere().gas_constant)
    temp = f"{math.exp(ln_t):.3g} K" if ln_t < 700.0 else f"e^{ln_t:.0f} K"
    text = (
        f"the state's atmosphere: ln p∞ = {x[ILP]:.3g}, ln ρ∞ = {x[ILR]:.3g} (p∞/ρ∞ the R T of {temp}; "
        "Mars' atmosphere is ~100–300 K)"
    )
    if st.bias_sigma_pa > 0.0:
        b = np.abs(x[IBIAS]) / st.bias_sigma_pa
        text += f", the largest residual bias {b.max():.3g}σ of its prior"
    return text


def _smooth_compiled(fp: ForwardPass, consider: np.ndarray | None) -> SmoothedPass | None:
    """:func:`~workbench.estimation.smoother.rts_smooth` of the forward pass (additive states) by
    the compiled :func:`.kernel.rts_kernel`; None where the reference must run instead: a predicted
    variance not positive (its exactly-known components) or a covariance not positive definite
    (the reference raises with the diagnosis)."""
    n, n_c = fp.x_post.shape
    dg = np.diagonal(fp.P_prior, axis1=1, axis2=2)
    if n < 2 or not np.all(dg > 0.0):
        return None
    G = np.zeros((n, n_c, n_c))
    np.matmul(fp.F[1:], fp.P_post[:-1], out=G[:-1])
    mask = np.zeros(n_c, bool)
    if consider is not None:
        mask[consider] = True
    xs, Ps = np.empty_like(fp.x_post), np.empty_like(fp.P_post)
    with threadpool_limits(limits=1, user_api="blas"):
        status, _ = rts_kernel(fp.x_prior, fp.P_prior, fp.x_post, fp.P_post, G, np.sqrt(dg), mask, xs, Ps)
    if status:
        return None
    G[-1] = 0.0
    return SmoothedPass(fp.t, xs, Ps, G)


def carried_states(st: EkfSettings) -> np.ndarray:
    """Indices (n_c,) into the full state (:data:`.state.STATE_NAMES`) of the states the filter
    carries: all but the model-error rates :data:`.state.IBD` for the first-order process, where
    they are identically zero with zero variance and no coupling (Φ, Q, P₀ and H zero on them),
    so dropping them leaves every other number as it was."""
    if st.model_error_order == 2:
        return np.arange(N_X)
    return np.delete(np.arange(N_X), np.arange(N_X)[IBD])


def _expand(xr: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """States (..., n_c) of the carried states ``keep`` to the full (..., N_X), zero elsewhere."""
    out = np.zeros((*xr.shape[:-1], N_X))
    out[..., keep] = xr
    return out


def run_passes(inp: EkfInputs, st: EkfSettings, keep_all: bool = False, *, compiled: bool = True):
    """Yield pass 1 (scale factors estimated) and, with ``st.passes == 2``, pass 2 (pressures
    corrected by pass 1's scale factors); ``keep_all``, ``compiled`` as :func:`run_pass`."""
    n = int(st.passes)
    first = run_pass(inp, st, index=1, passes=n, estimate_scale=True, keep_all=keep_all, compiled=compiled)
    yield first
    if n >= 2:
        yield run_pass(
            inp,
            st,
            index=2,
            passes=n,
            estimate_scale=False,
            scale_fixed=first.scale,
            scale_cov_fixed=first.scale_cov,
            keep_all=keep_all,
            compiled=compiled,
        )
