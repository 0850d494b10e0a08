"""Radar-aided extended RTS smoother of the entry and descent (AMELIA Sect. 8, Appendix B).

What: an error-state EKF over the preprocessed IMU grid (state ``[v_M, q_M_G, p_M]``, error
``[δv_M, δθ_G, δp_M]``, propagation identical to the strapdown pass) with the radar slant-range,
slant-out and velocity-out updates (B.3-B.6), AMELIA's constrained update directions (gain
projection, Joseph covariance), optional χ² gating, iterated updates and relinearised passes,
then the error-state RTS backward pass.  Why: the radar fixes the altitude and the
terrain-relative velocity at the end of the descent; the smoother carries that information back
along the whole trajectory.  This module supplies the models; the estimation steps are the shared
engine's (:mod:`workbench.estimation.ekf`, :mod:`workbench.estimation.smoother`,
:mod:`workbench.estimation.grid`).  The method notes and the tuning measurements are in
``docs/tuning/entry.md``.

References: Aboudan et al., "ExoMars 2016 Schiaparelli Module Trajectory and Atmospheric Profiles
Reconstruction", Space Sci. Rev. 214:97, 2018 (AMELIA; Sects. 7-8, App. A-B); Särkkä, *Bayesian
Filtering and Smoothing*, 2013; Simon, *Optimal State Estimation*, 2006, Sect. 7.5.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from scipy.linalg import lapack

from workbench.core.bodies import MARS
from workbench.core.gravity import j2_factor
from workbench.core.rotation import quat_boxplus, quat_to_dcm
from workbench.estimation.consistency import chi2_gate
from workbench.estimation.ekf import (
    ErrorStateLayout,
    ForwardPass,
    InnovationHistory,
    Measurement,
    run_filter,
    update,
)
from workbench.estimation.grid import MergedGrid, merge_time_tags
from workbench.estimation.smoother import iterated_rts
from workbench.estimation.strapdown import (
    GAP_SIGMA_DEFAULT,
    apply_gap,
    covariance_step,
    gap_transition,
    imu_columns,
    rk4_step,
)
from workbench.estimation.strapdown_kernel import transition_step
from workbench.io import progress
from workbench.models.radar import (
    PlaneFit,
    beam_directions_G,
    mars_rate_M,
    plane_fit,
    slant_range_model,
    velocity_out_model,
)
from workbench.problems.entry.site import R_GROUND
from workbench.problems.entry.state import DP, DTH, DV, N_ERR, N_X, XP, XQ, XV
from workbench.problems.entry.telemetry import RadarTracks

__all__ = [
    "CHANNELS",
    "RadarData",
    "EntryFilterSigmas",
    "EntryPass",
    "EntryFilterResult",
    "gain_projector",
    "radar_update",
    "RadarMeasurement",
    "radar_measurement",
    "UPDATE_STEP_TOL",
    "run_entry_smoother",
]

#: Radar channels, in the order they are applied at one node.
CHANNELS: tuple[str, ...] = ("slant_range", "slant_out", "velocity_out")
_I9 = np.eye(N_ERR)
_I3 = np.eye(3)
#: x = [v_M, q_M_G, p_M], e = [δv_M, δθ_G, δp_M] (:mod:`.state`)
_LAYOUT = ErrorStateLayout(N_X, ((XQ.start, DTH.start),))


@dataclass(frozen=True)
class RadarData(RadarTracks):
    """Radar altimeter telemetry, SI, times [s] from EIP.

    ``t_sr`` (k,), ``slant_ranges`` (k, 4) [m] beams B0..B3, ``sr_valid`` (k,) bool (False for the
    zero-filled packets); ``t_rda`` (j,), ``slant_out`` (j,) [m] along B0, ``v_out_G`` (j, 3) [m/s]
    terrain-relative (co-rotating) velocity in G, ``rda_valid`` (j,) bool; ``beams_G`` (4, 3) unit
    beam directions in G (:func:`~workbench.models.radar.beam_directions_G`); ``r_ground`` [m]
    terrain sphere radius.
    """

    beams_G: np.ndarray = field(default_factory=beam_directions_G)
    r_ground: float = R_GROUND

    @classmethod
    def of(cls, tracks: Any, beams_G: np.ndarray, r_ground: float) -> RadarData:
        """The radar data of ``tracks`` (:class:`~workbench.problems.entry.telemetry.RadarTracks`,
        e.g. the telemetry as read), with the beam directions ``beams_G`` (4, 3) in G and the
        terrain radius ``r_ground`` [m]."""
        names = [f.name for f in fields(RadarTracks)]
        return cls(**{name: getattr(tracks, name) for name in names}, beams_G=beams_G, r_ground=r_ground)


@dataclass(frozen=True)
class EntryFilterSigmas:
    """Tuning of the radar-aided smoother (defaults: AMELIA Table 3, reconstruction column).

    ``slant_range``, ``slant_out`` [m] and ``velocity_out`` [m/s] measurement 1σ (per beam / per
    axis); ``q_state_psd`` (9,) state-noise PSD η [units²/s] or None; ``gap_sigma`` per-second
    growth across data gaps (:data:`~workbench.estimation.strapdown.GAP_SIGMA_DEFAULT`);
    ``bridge_mode`` "relative" | "paper"; ``gate_probability`` χ² gate (None: no gating);
    ``snap_tolerance`` [s] below which a measurement is applied at the nearest IMU sample;
    ``gravity_gradient`` include G(p) in the error dynamics; ``omega_M`` (3,) Mars rotation in M
    [rad/s] (None: ``[0, 0, MARS.rotation_rate]``); ``iterations`` forward-backward passes, each
    after the first relinearised about the previous smoothed trajectory (1: the plain EKF + RTS);
    ``update_iterations`` Gauss-Newton steps of each radar update in the first (causal) pass
    (iterated EKF of :func:`workbench.estimation.ekf.update`; 1: the ordinary update).
    """

    slant_range: float = 100.0
    slant_out: float = 100.0
    velocity_out: float = 25.0
    q_state_psd: tuple[float, ...] | None = None
    gap_sigma: tuple[float, float, float] = GAP_SIGMA_DEFAULT
    bridge_mode: str = "relative"
    gate_probability: float | None = None
    snap_tolerance: float = 1e-3
    gravity_gradient: bool = True
    omega_M: tuple[float, float, float] | None = None
    iterations: int = 3
    update_iterations: int = 4

    @classmethod
    def from_any(cls, sigmas: EntryFilterSigmas | Mapping[str, Any] | None) -> EntryFilterSigmas:
        """Accept an instance, None (defaults) or a mapping (known keys used, others ignored —
        the same mapping may carry the atmosphere/wind σ of Table 3)."""
        if sigmas is None:
            return cls()
        if isinstance(sigmas, cls):
            return sigmas
        if isinstance(sigmas, Mapping):
            names = {f.name for f in fields(cls)}
            return cls(**{k: v for k, v in sigmas.items() if k in names})
        raise TypeError(f"sigmas must be EntryFilterSigmas, a mapping or None, not {type(sigmas).__name__}")


@dataclass(frozen=True)
class EntryPass:
    """A pass on the IMU grid: ``t`` (n,) [s]; ``v_M`` (n, 3) [m/s]; ``q_M_G`` (n, 4); ``p_M`` (n, 3)
    [m]; ``P`` (n, 9, 9) covariance of ``[δv_M, δθ_G, δp_M]`` (forward: post-update; smoothed: RTS)."""

    t: np.ndarray
    v_M: np.ndarray
    q_M_G: np.ndarray
    p_M: np.ndarray
    P: np.ndarray

    @property
    def sigma_radial(self) -> np.ndarray:
        """1σ (n,) [m] of the position along the local vertical (:func:`radial_sigma`)."""
        return radial_sigma(self.p_M, self.P)

    @property
    def sigma_velocity(self) -> np.ndarray:
        """Per-axis 1σ (n, 3) [m/s] of the MMED velocity."""
        return np.sqrt(np.einsum("nii->ni", self.P[:, DV, DV]))

    @property
    def sigma_attitude(self) -> np.ndarray:
        """Per-axis 1σ (n, 3) [rad] of the body-frame attitude error δθ_G."""
        return np.sqrt(np.einsum("nii->ni", self.P[:, DTH, DTH]))

    @property
    def sigma_position(self) -> np.ndarray:
        """Per-axis 1σ (n, 3) [m] of the MMED position."""
        return np.sqrt(np.einsum("nii->ni", self.P[:, DP, DP]))


def radial_sigma(p_M: np.ndarray, P: np.ndarray) -> np.ndarray:
    """1σ (n,) [m] of the position error along the local vertical û = p/|p|: ``sqrt(ûᵀ P_pp û)``,
    the altitude's 1σ (a sphere's radius).  ``p_M`` (n, 3) [m] MMED, ``P`` (n, 9, 9) error-state
    covariance ``[δv_M, δθ_G, δp_M]``."""
    u = p_M / np.linalg.norm(p_M, axis=1, keepdims=True)
    return np.sqrt(np.einsum("ni,nij,nj->n", u, P[:, DP, DP], u))


@dataclass(frozen=True)
class EntryFilterResult:
    """Output of :func:`run_entry_smoother`.

    ``forward``/``smoothed`` (:class:`EntryPass`, IMU grid); ``innovations`` and
    ``smoothed_residuals``: channel name (:data:`CHANNELS`) ->
    :class:`~workbench.estimation.ekf.InnovationHistory` (processed samples, invalid packets
    excluded; slant ranges d = 4 with NaN components for a skipped beam, slant-out d = 1 [m],
    velocity-out d = 3 [m/s]; ``step`` the IMU sample at or before the sample; forward: prior
    prediction, smoothed: ``h(x_s)`` with ``S = H P_s Hᵀ + R``);
    ``plane_fits``: (t [s], :class:`~workbench.models.radar.PlaneFit`) per valid slant-range packet;
    ``constrained``; ``info``: counts (nodes inserted, snapped, updates per channel, gated) and
    ``wall_s`` [s].
    """

    forward: EntryPass
    smoothed: EntryPass
    innovations: dict[str, InnovationHistory]
    smoothed_residuals: dict[str, InnovationHistory]
    plane_fits: list[tuple[float, PlaneFit]]
    constrained: bool = True
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def stage_label(self) -> str:
        """Its name in progress lines and ``summary["stage_times_s"]``, with the passes it ran."""
        n = self.info.get("iterations")
        return "radar-aided iterated smoother" + ("" if n is None else f" ({n} pass{'es' if n != 1 else ''})")


# ---------------------------------------------------------------------------------------------
# update


def gain_projector(kind: str, p_M: np.ndarray, q_M_G: np.ndarray) -> np.ndarray:
    """Projector Π (9, 9) of AMELIA Sect. 8's constrained update directions.

    ``kind`` "range" (slant range, slant-out): ``blockdiag(0, C_G_M (I − p̂p̂ᵀ) C_M_G, p̂p̂ᵀ)`` —
    no velocity update, attitude correction horizontal in M, position correction vertical;
    "velocity" (velocity-out): ``blockdiag(I, I, 0)``; "none": I.
    """
    if kind == "none":
        return _I9.copy()
    Pi = np.zeros((9, 9))
    if kind == "range":
        u = np.asarray(p_M, dtype=float)
        u = u / math.sqrt(u @ u)
        vert = np.outer(u, u)
        C = quat_to_dcm(q_M_G)
        Pi[DTH, DTH] = C.T @ (_I3 - vert) @ C
        Pi[DP, DP] = vert
    elif kind == "velocity":
        Pi[0:6, 0:6] = np.eye(6)
    else:
        raise ValueError(f"gain_projector: kind must be 'range', 'velocity' or 'none', got {kind!r}")
    return Pi


def radar_update(
    v: np.ndarray,
    q: np.ndarray,
    p: np.ndarray,
    P: np.ndarray,
    residual: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    kind: str,
    *,
    constrained: bool = True,
    gate: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """One (possibly constrained) EKF update of the state (v_M, q_M_G, p_M) and P (9, 9), by
    :func:`workbench.estimation.ekf.update` with the gain projector of :func:`gain_projector`.

    ``residual`` (d,) measured − predicted, ``H`` (d, 9), ``R`` (d, d); ``kind`` "range" or
    "velocity" (:func:`gain_projector`), ignored when ``constrained`` is False.  ``gate``: χ²
    threshold on the NIS (None: none).  Gain ``K = Π P Hᵀ S⁻¹``; Joseph-form covariance,
    symmetrised; state ``v + δv``, ``q ⊗ exp(δθ)``, ``p + δp`` (error reset, P kept — MEKF
    practice).  Returns ``(v, q, p, P, K (9, d), accepted)``; when gated out, the inputs are
    returned unchanged with K = 0.
    """
    x = np.r_[v, q, p]
    res = np.asarray(residual, dtype=float)
    Hc = np.asarray(H, dtype=float)
    ur = update(
        x,
        P,
        res,
        lambda xx: Hc @ _LAYOUT.boxminus(xx, x),  # linear model about x: y = residual at x
        R,
        _LAYOUT,
        H=Hc,
        gain_projector=(lambda xx: gain_projector(kind, xx[7:10], xx[3:7])) if constrained else None,
        gate_threshold=gate,
    )
    if not ur.accepted:
        return v, q, p, P, np.zeros((9, res.size)), False
    xn = ur.x_post
    return xn[XV], xn[XQ], xn[XP], ur.P_post, ur.K, True


# ---------------------------------------------------------------------------------------------
# measurement bookkeeping


@dataclass
class _Event:
    t: float
    channel: str  # one of CHANNELS
    index: int  # row in the channel's table
    node: int = -1  # augmented-grid node


def _build_events(radar: RadarData) -> tuple[list[_Event], list[tuple[float, PlaneFit]]]:
    events: list[_Event] = []
    fits: list[tuple[float, PlaneFit]] = []
    sr = np.asarray(radar.slant_ranges, dtype=float).reshape(-1, 4)
    for j, tj in enumerate(np.asarray(radar.t_sr, dtype=float)):
        if not bool(radar.sr_valid[j]):
            continue
        ok = np.isfinite(sr[j]) & (sr[j] > 0.0)
        if not ok.any():
            continue
        events.append(_Event(float(tj), "slant_range", j))
        if ok.sum() >= 3:
            try:
                fits.append((float(tj), plane_fit(sr[j], radar.beams_G)))
            except ValueError:
                pass
    so = np.asarray(radar.slant_out, dtype=float).reshape(-1)
    vo = np.asarray(radar.v_out_G, dtype=float).reshape(-1, 3)
    for j, tj in enumerate(np.asarray(radar.t_rda, dtype=float)):
        if not bool(radar.rda_valid[j]):
            continue
        if np.isfinite(so[j]) and so[j] > 0.0:
            events.append(_Event(float(tj), "slant_out", j))
        if np.all(np.isfinite(vo[j])):
            events.append(_Event(float(tj), "velocity_out", j))
    order = {c: i for i, c in enumerate(CHANNELS)}
    events.sort(key=lambda e: (e.t, order[e.channel]))
    return events, fits


def _augmented_grid(
    t: np.ndarray, gaps: set[int], events: list[_Event], tol: float
) -> tuple[MergedGrid, list[_Event], dict[str, int]]:
    """The IMU grid merged with the radar time tags (:func:`workbench.estimation.grid.merge_time_tags`,
    no node inserted in a bridged gap); sets ``node`` of the events inside the span and returns the
    merged grid, those events and the counts."""
    g = merge_time_tags(t, [e.t for e in events], tol, no_insert=gaps)
    kept: list[_Event] = []
    for e, a in zip(events, g.tag_node.tolist(), strict=True):
        if a >= 0:
            e.node = a
            kept.append(e)
    counts = {"n_outside": g.n_outside, "n_snapped": g.n_snapped, "n_snapped_in_gap": g.n_moved,
              "n_inserted": g.n_inserted}  # fmt: skip
    return g, kept, counts


def _predict_channel(
    channel: str, index: int, radar: RadarData, v: np.ndarray, q: np.ndarray, p: np.ndarray, sg: EntryFilterSigmas
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """(measured (d_full,), predicted (d_full,), mask (d_full,) bool, H (m, 9), R (m, m), kind) with
    m = mask.sum() the used components (NaN predictions for unused)."""
    if channel == "slant_range":
        z = np.asarray(radar.slant_ranges[index], dtype=float)
        B = np.asarray(radar.beams_G, dtype=float)
        y, H = slant_range_model(np.broadcast_to(p, (4, 3)), np.broadcast_to(q, (4, 4)), B, radar.r_ground)
        mask = np.isfinite(z) & (z > 0.0) & np.isfinite(y)
        pred = np.where(np.isfinite(y), y, np.nan)
        return z, pred, mask, H[mask, 0, :], sg.slant_range**2 * np.eye(int(mask.sum())), "range"
    if channel == "slant_out":
        z = np.array([float(radar.slant_out[index])])
        y, H = slant_range_model(p, q, np.asarray(radar.beams_G, dtype=float)[0], radar.r_ground)
        if not np.isfinite(y):
            return z, np.array([np.nan]), np.array([False]), np.zeros((0, 9)), np.zeros((0, 0)), "range"
        return z, np.array([float(y)]), np.array([True]), H, sg.slant_out**2 * np.eye(1), "range"
    z = np.asarray(radar.v_out_G[index], dtype=float)
    om = mars_rate_M() if sg.omega_M is None else np.asarray(sg.omega_M, dtype=float)
    y, H = velocity_out_model(v, q, p, om)
    return z, y, np.ones(3, dtype=bool), H, sg.velocity_out**2 * np.eye(3), "velocity"


#: Stop rule of the iterated radar update (error-state units): 1e-6 m/s, 1e-9 rad, 1e-6 m.
UPDATE_STEP_TOL = np.r_[np.full(3, 1e-6), np.full(3, 1e-9), np.full(3, 1e-6)]


class _ChannelModel:
    """``h(x)``, ``H(x)`` of the used components of one radar sample, memoised on x (10,).

    The iterated update evaluates h and H at the same iterate; a change of the set of usable
    components (a beam that misses or starts hitting the terrain sphere) makes h NaN, which ends
    the iterations of :func:`workbench.estimation.ekf.update` at the previous iterate.
    """

    def __init__(self, channel, index, radar, sg, mask, x, pred, H):
        self.channel, self.index, self.radar, self.sg, self.mask = channel, index, radar, sg, mask
        self.x, self.pred, self.Hm = x, pred[mask], H

    def _at(self, x: np.ndarray) -> None:
        if not np.array_equal(x, self.x):
            _, pred, mask, H, _, _ = _predict_channel(
                self.channel, self.index, self.radar, x[XV], x[XQ], x[XP], self.sg
            )
            m = int(self.mask.sum())
            if np.array_equal(mask, self.mask):
                self.pred, self.Hm = pred[mask], H
            else:
                self.pred, self.Hm = np.full(m, np.nan), np.full((m, 9), np.nan)
            self.x = np.array(x)

    def h(self, x: np.ndarray) -> np.ndarray:
        self._at(x)
        return self.pred

    def H(self, x: np.ndarray) -> np.ndarray:
        self._at(x)
        return self.Hm


@dataclass(frozen=True)
class RadarMeasurement:
    """One radar sample as a measurement of the shared EKF (:class:`~workbench.estimation.ekf.Measurement`).

    ``z_full`` (d,) measured and ``pred_full`` (d,) predicted at the linearisation state (NaN where
    the model is undefined), ``mask`` (d,) the used components (finite, positive measurement and
    finite prediction); ``measurement``: name = channel, ``z = z_full[mask]``, ``h``/``H`` of the
    used components (Jacobian w.r.t. ``[δv_M, δθ_G, δp_M]``), R, the gain projector of
    :func:`gain_projector` (None when unconstrained) and :data:`UPDATE_STEP_TOL`; None when no
    component is usable.  ``kind`` "range" | "velocity".
    """

    z_full: np.ndarray
    pred_full: np.ndarray
    mask: np.ndarray
    kind: str
    x_lin: np.ndarray
    constrained: bool
    measurement: Measurement | None

    def linearised(self, x: np.ndarray) -> RadarMeasurement:
        """The affine model about ``x_lin`` (x̄): ``h(x) = h(x̄) + H(x̄) (x ⊟ x̄)``, constant H and
        projector Π(x̄) — the measurement of a relinearised (Gauss-Newton) smoother pass."""
        mm = self.measurement
        if mm is None:
            return self
        xb = self.x_lin
        hb = self.pred_full[self.mask]
        Hb = np.asarray(mm.H(xb), dtype=float)
        Pi = None if mm.gain_projector is None else mm.gain_projector(xb)
        lin = Measurement(
            mm.name,
            mm.z,
            mm.R,
            lambda xx: hb + Hb @ _LAYOUT.boxminus(xx, xb),
            Hb,
            gain_projector=None if Pi is None else (lambda _xx: Pi),
        )
        return RadarMeasurement(self.z_full, self.pred_full, self.mask, self.kind, xb, self.constrained, lin)


def radar_measurement(
    channel: str, index: int, radar: RadarData, x: np.ndarray, sg: EntryFilterSigmas, *, constrained: bool = True
) -> RadarMeasurement:
    """Sample ``index`` of radar ``channel`` (:data:`CHANNELS`) linearised at x = [v_M, q_M_G, p_M] (10,).

    Models of :mod:`workbench.models.radar` (slant ranges B.3/B.4 of the four beams, slant-out
    along B0, velocity-out B.5/B.6 [m/s]); R from ``sg`` (1σ per component, SI).
    """
    x = np.asarray(x, dtype=float)
    z, pred, mask, H, R, kind = _predict_channel(channel, index, radar, x[XV], x[XQ], x[XP], sg)
    if not mask.any():
        return RadarMeasurement(z, pred, mask, kind, x, constrained, None)
    model = _ChannelModel(channel, index, radar, sg, mask, x, pred, H)
    proj = (lambda xx: gain_projector(kind, xx[7:10], xx[3:7])) if constrained else None
    mm = Measurement(channel, z[mask], R, model.h, model.H, gain_projector=proj, step_tol=UPDATE_STEP_TOL)
    return RadarMeasurement(z, pred, mask, kind, x, constrained, mm)


# ---------------------------------------------------------------------------------------------
# driver


def run_entry_smoother(
    imu: Any,
    radar: RadarData,
    v0: np.ndarray,
    q0: np.ndarray,
    p0: np.ndarray,
    P0: np.ndarray,
    *,
    sigmas: EntryFilterSigmas | Mapping[str, Any] | None = None,
    constrained: bool = True,
    fast: bool = True,
) -> EntryFilterResult:
    """Forward EKF with radar updates + error-state RTS backward pass (docs/tuning/entry.md).

    ``imu``: a PreprocessedIMU (uses ``t`` (n,), ``f_G``, ``w_G``, ``sigma_f``, ``sigma_w`` (n, 3),
    ``gaps``); ``radar``: :class:`RadarData`; initial state at ``imu.t[0]``: v0 (3,) [m/s], q0 (4,)
    ``q_M_G``, p0 (3,) [m], P0 (9, 9); ``sigmas``: :class:`EntryFilterSigmas` or a mapping;
    ``constrained``: AMELIA's projected update directions (False: plain EKF updates).
    ``fast``: the IMU steps by the compiled strapdown kernel
    (:func:`~workbench.estimation.strapdown_kernel.transition_step`); False: ``rk4_step`` and
    ``covariance_step``, the reference path (the two agree to rounding).
    Raises ``ValueError`` naming the step if a covariance stops being positive definite.
    """
    wall0 = time.perf_counter()
    sg = EntryFilterSigmas.from_any(sigmas)
    t, f, w, sf, sw = imu_columns(imu)
    n = t.size
    if n < 2 or np.any(np.diff(t) <= 0.0):
        raise ValueError("run_entry_smoother: need ≥ 2 strictly increasing IMU times")
    sample_dt = float(np.median(np.diff(t)))
    gaps = _gap_map(t, getattr(imu, "gaps", ()) or ())
    events, fits = _build_events(radar)
    grid, events, counts = _augmented_grid(t, set(gaps), events, sg.snap_tolerance)
    t_aug, interval, imu_node = grid.t, grid.interval, grid.base_node
    N = t_aug.size
    # inputs on the augmented grid (IMU samples exactly, inserted nodes interpolated linearly)
    fa = np.empty((N, 3))
    wa = np.empty((N, 3))
    for a in range(N):
        k = imu_node[a]
        if k >= 0:
            fa[a], wa[a] = f[k], w[k]
        else:
            i = interval[a]
            s = grid.fraction[a]
            fa[a] = f[i] + s * (f[i + 1] - f[i])
            wa[a] = w[i] + s * (w[i + 1] - w[i])
    by_node: dict[int, list[_Event]] = {}
    for e in events:
        by_node.setdefault(e.node, []).append(e)
    gate = {
        c: (None if sg.gate_probability is None else chi2_gate(sg.gate_probability, d))
        for c, d in (("slant_range", 4), ("slant_out", 1), ("velocity_out", 3))
    }
    qpsd = None if sg.q_state_psd is None else np.asarray(sg.q_state_psd, dtype=float)

    x0 = np.concatenate([np.asarray(v0, dtype=float), np.asarray(q0, dtype=float) / np.linalg.norm(q0), p0])
    n_iter = max(1, int(sg.iterations))
    rms0: dict[int, RadarMeasurement] = {}

    def run_pass(lin: np.ndarray | None) -> ForwardPass:
        fw, rms = _forward(x0, np.asarray(P0, dtype=float), lin, t_aug, interval, imu_node, fa, wa, sw, sf,
                           sample_dt, gaps, by_node, radar, sg, qpsd, gate, constrained, fast)  # fmt: skip
        if lin is None:
            rms0.update(rms)
        return fw

    with progress.current().counter(
        f"iterated smoother: forward + backward sweeps of {n_iter} pass{'es' if n_iter > 1 else ''}",
        total=2 * n_iter,
        unit="sweeps",
    ) as bar:
        its = iterated_rts(run_pass, _LAYOUT, n_iter, progress=bar)
    fw0 = its.first
    Xs, Ps = its.smoothed.x, its.smoothed.P
    Xpo, Ppo = fw0.x_post, fw0.P_post
    counts["iterations"] = its.passes
    counts["relinearisation_max_attitude_change_rad"] = [float(np.max(c[DTH])) for c in its.changes]

    # residuals
    innov: dict[str, InnovationHistory] = {}
    sres: dict[str, InnovationHistory] = {}
    for c, d in (("slant_range", 4), ("slant_out", 1), ("velocity_out", 3)):
        ev = [e for e in events if e.channel == c]
        k = len(ev)
        T = np.array([e.t for e in ev])
        Z = np.full((k, d), np.nan)
        Y = np.full((k, d), np.nan)
        S = np.full((k, d, d), np.nan)
        acc = np.zeros(k, dtype=bool)
        nis = np.full(k, np.nan)
        Ys = np.full((k, d), np.nan)
        Ss = np.full((k, d, d), np.nan)
        ih = fw0.innovations.get(c)
        j = 0  # the channel's rows in the forward pass are in event order; unusable events have none
        for r, e in enumerate(ev):
            rm = rms0[id(e)]
            Z[r], Y[r] = rm.z_full, rm.pred_full
            if rm.measurement is not None:
                u = rm.mask
                Y[r][u] = ih.z_pred[j][u]  # predicted at the state the update saw
                S[r], acc[r], nis[r] = ih.S[j], ih.accepted[j], ih.nis[j]
                j += 1
            xs = Xs[e.node]
            z2, pred_s, mask, H, R, _ = _predict_channel(c, e.index, radar, xs[XV], xs[XQ], xs[XP], sg)
            Ys[r] = pred_s
            if mask.any():
                Ss[r][np.ix_(mask, mask)] = H @ Ps[e.node] @ H.T + R
        steps = np.array([interval[e.node] for e in ev], dtype=int)
        innov[c] = InnovationHistory(T, steps, Z, Y, Z - Y, S, nis, acc)
        sres[c] = InnovationHistory(T, steps.copy(), Z.copy(), Ys, Z - Ys, Ss, _nis(Z - Ys, Ss), acc.copy())
        counts[f"n_{c}"] = int(k)
        counts[f"n_{c}_rejected"] = int(k - acc.sum())

    sel = np.flatnonzero(imu_node >= 0)
    fwd = EntryPass(t.copy(), Xpo[sel, XV], Xpo[sel, XQ], Xpo[sel, XP], Ppo[sel])
    smo = EntryPass(t.copy(), Xs[sel, XV], Xs[sel, XQ], Xs[sel, XP], Ps[sel])
    counts["n_nodes"] = int(N)
    counts["wall_s"] = time.perf_counter() - wall0
    return EntryFilterResult(fwd, smo, innov, sres, fits, bool(constrained), counts)


def _forward(
    x0,
    P0,
    lin,
    t_aug,
    interval,
    imu_node,
    fa,
    wa,
    sw,
    sf,
    sample_dt,
    gaps,
    by_node,
    radar,
    sg,
    qpsd,
    gate,
    constrained,
    fast=True,
) -> tuple[ForwardPass, dict]:
    """EKF forward pass on the augmented grid (N nodes) by :func:`workbench.estimation.ekf.run_filter`:
    a :class:`~workbench.estimation.ekf.ForwardPass` (``F[a]``, ``Q[a]`` the error transition and
    process noise into node a; ``innovations`` per channel, slant ranges NaN for unused beams) and
    ``id(event) -> RadarMeasurement`` (prior predictions of each event, first pass only).
    ``lin`` None: the ordinary EKF (dynamics and measurements linearised at the running estimate).
    ``lin`` (N, 10) a linearisation trajectory (the previous iteration's smoothed states): the step
    is the affine model ``x⁻ = f(x̄) ⊞ Φ(x̄) (x ⊟ x̄)`` and a measurement
    ``h(x) ≈ h(x̄) + H(x̄) (x ⊟ x̄)`` (iterated extended smoother, Gauss-Newton; Bell 1994).
    ``fast``: IMU steps by :func:`~workbench.estimation.strapdown_kernel.transition_step`."""
    n_upd = max(1, int(sg.update_iterations))
    node = {tt: a for a, tt in enumerate(t_aug.tolist())}
    rms: dict[int, RadarMeasurement] = {}
    # per-interval input noise 1σ (the mean variance of the two samples) and the kernel's constants
    sw_mid = np.sqrt(0.5 * (sw[:-1] ** 2 + sw[1:] ** 2))
    sf_mid = np.sqrt(0.5 * (sf[:-1] ** 2 + sf[1:] ** 2))
    qpsd_k = np.zeros(N_ERR) if qpsd is None else np.ascontiguousarray(qpsd, dtype=float)
    gm, j2k, grad = float(MARS.gm), float(j2_factor(MARS)), bool(sg.gravity_gradient)

    def transition(x, t0, t1):
        a = node[t1]
        xb = x if lin is None else lin[a - 1]
        vb, qb, pb = xb[XV], xb[XQ], xb[XP]
        i = interval[a - 1]
        if i in gaps and imu_node[a - 1] >= 0 and imu_node[a] == i + 1:
            g = gaps[i]
            Fk, Qk = gap_transition(qb, pb, g, sg.bridge_mode, sg.gap_sigma, body=MARS)
            v1, q1, p1 = apply_gap(vb, qb, pb, g, sg.bridge_mode)
        elif fast:
            dt = float(t_aug[a] - t_aug[a - 1])
            v1, q1, p1, Fk, Qk = transition_step(
                vb,
                qb,
                pb,
                fa[a - 1],
                wa[a - 1],
                fa[a],
                wa[a],
                dt,
                sw_mid[i],
                sf_mid[i],
                sample_dt,
                qpsd_k,
                grad,
                gm,
                j2k,
            )
        else:
            dt = t_aug[a] - t_aug[a - 1]
            v1, q1, p1 = rk4_step(vb, qb, pb, fa[a - 1], wa[a - 1], fa[a], wa[a], dt, MARS)
            qm = qb + q1 if (qb @ q1) >= 0.0 else qb - q1
            qm = qm / math.sqrt(qm @ qm)
            _, Fk, Qk = covariance_step(
                _I9,
                qm,
                0.5 * (fa[a - 1] + fa[a]),
                0.5 * (wa[a - 1] + wa[a]),
                dt,
                np.sqrt(0.5 * (sw[i] ** 2 + sw[i + 1] ** 2)),
                np.sqrt(0.5 * (sf[i] ** 2 + sf[i + 1] ** 2)),
                sample_dt,
                qpsd,
                0.5 * (pb + p1) if sg.gravity_gradient else None,
                body=MARS,
            )
        if lin is not None:  # affine model about x̄
            dx = Fk @ _LAYOUT.boxminus(x, xb)
            q1 = quat_boxplus(q1, dx[DTH])
            v1, p1 = v1 + dx[DV], p1 + dx[DP]
        return np.concatenate((v1, q1, p1)), Fk, Qk

    def measurements_at(a, ta, x):
        out = []
        for e in by_node.get(a, ()):
            rm = radar_measurement(e.channel, e.index, radar, x if lin is None else lin[a], sg, constrained=constrained)
            if lin is None:
                rms[id(e)] = rm
            else:
                rm = rm.linearised(x)
            if rm.measurement is not None:
                out.append(
                    replace(
                        rm.measurement,
                        iterations=n_upd if lin is None else 1,
                        gate_threshold=gate[e.channel],
                        slots=np.flatnonzero(rm.mask),
                        size=rm.mask.size,
                    )
                )
        return out

    fw = run_filter(x0, P0, t_aug, transition, None, measurements_at, _LAYOUT)
    for a in range(t_aug.size):
        _check_pd(fw.P_post[a], a, t_aug, "forward")
    return fw, rms


def _nis(y: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``yᵀ S⁻¹ y`` (k,) over the used (finite) components of each row of y (k, d), S (k, d, d); NaN
    for a row without any."""
    out = np.full(y.shape[0], np.nan)
    for r in range(y.shape[0]):
        u = np.isfinite(y[r]) & np.isfinite(np.diagonal(S[r]))
        if u.any():
            yu = y[r][u]
            out[r] = float(yu @ np.linalg.solve(S[r][np.ix_(u, u)], yu))
    return out


def _gap_map(t: np.ndarray, gaps: Any) -> dict[int, Any]:
    out: dict[int, Any] = {}
    for g in gaps:
        i = int(np.searchsorted(t, float(g.t_a) - 1e-6))
        if i >= t.size - 1 or abs(t[i] - float(g.t_a)) > 1e-6 or abs(t[i + 1] - float(g.t_b)) > 1e-6:
            raise ValueError(f"gap bridge t_a={g.t_a:.3f} s, t_b={g.t_b:.3f} s does not match two adjacent IMU samples")
        out[i] = g
    return out


def _check_pd(A: np.ndarray, k: int, t: np.ndarray, which: str) -> None:
    _, info = lapack.dpotrf(A, lower=1)
    if info != 0 or not np.all(np.isfinite(A)):
        raise ValueError(f"entry smoother: {which} covariance at node {k} (t={t[k]:.3f} s) is not positive definite")
