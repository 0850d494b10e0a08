"""Entry-vehicle instruments and on-board navigation of a Schiaparelli-like lander (AMELIA Sects. 3, 7).

What the real-time telemetry (TM) of the ExoMars Schiaparelli module held (AMELIA Table 1), and
how this module produces the same thing from a truth trajectory for synthetic scenarios:

* an IMU (accelerometer triad + rate gyros, assumed at the CoG) sampled by the GNC computer at
  ``onboard_rate_hz`` = 100 Hz: white noise, optional per-run bias and scale factor, and the
  gyro range of 187.5 °/s: a rate beyond it is **clipped** (:func:`apply_imu_errors`);
* the **on-board navigation**: a strapdown integration of the measured (noisy, clipped) IMU at
  100 Hz from the on-board initial state — the "nominal state" propagated from the TGO
  prediction, which differs from truth by a few km, ~15 m/s and ~1° (:func:`nominal_state`,
  :func:`strapdown_onboard`).  After the gyro saturates its attitude, hence its velocity and
  position, go wrong, like Schiaparelli's;
* the TM subset of the GNC outputs (:func:`generate_entry_tm`): at 10 Hz the measured body rate,
  the on-board attitude and the on-board **total inertial acceleration**
  ``a_M = gravity_j2(p_nav) + C_M_G(q_nav) f_meas`` (gravity included, MMED frame); at 1 Hz the
  on-board position and velocity; rows inside the blackout windows are absent;
* the Ka-band radar altimeter (RDA): 4-beam slant-range packets every 10 s (the first ones
  zero-filled), slant-out along the central beam B0 and the terrain-relative velocity in the
  GNC frame at 10 Hz, from ``RDA_ON`` to ``BSR``.  Truth ranges are exact ray intersections with
  the terrain sphere ``r = 3396000 − 1440 m`` plus the truth's smooth relief (the truth's
  ``terrain_modes``, :class:`~workbench.problems.entry.site.TerrainRelief`,
  :func:`~workbench.models.radar.slant_range_surface`), not the estimator's flat-terrain model
  (Eq. B.3) on the sphere.

Frames and conventions (docs/ARCHITECTURE.md, "Conventions"): ``M`` = MMED inertial (Mars-centred, +Z the
pole), ``G`` = GNC body frame (+Z towards the back shell, B0 along −Z_G); ``q_M_G`` is
body → inertial, Hamilton, scalar-last; the TM quaternion is JPL "MMED to GNC", numerically the
raw components of ``q_M_G`` (:func:`workbench.core.rotation.quat_from_jpl`).  Error state
``[δv_M, δθ_G, δp_M]`` with ``v_true = v + δv``, ``q_true = q ⊗ exp(δθ)``, ``p_true = p + δp``.
Time ``t`` [s] from the entry interface point (EIP).  SI inside.

References: [1] Aboudan et al., "ExoMars 2016 Schiaparelli Module Trajectory and Atmospheric
Profiles Reconstruction", Space Sci. Rev. 214:97, 2018 (AMELIA) — Table 1 (TM content), Sect. 3
(gyro saturation at 187.5 °/s, blackout gaps of 1.4, 1.8, 3.3 and 57.2 s), Sect. 7 (RDA),
Table 3 (measurement uncertainties), Appendix B (radar models); [2] Savage, "Strapdown inertial
navigation integration algorithm design", J. Guid. Control Dyn. 21(1), 1998 (coning term of the
attitude increment).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from workbench.core.bodies import MARS, Body
from workbench.core.gravity import gravity_j2
from workbench.core.interpolation import interp_rows
from workbench.core.rotation import (
    quat_conjugate,
    quat_from_rotvec,
    quat_multiply,
    quat_normalize,
    quat_rotate,
)
from workbench.models.imu import IMU_ERROR_NAMES, ImuErrorModel, apply_imu_errors, draw_imu_errors
from workbench.models.radar import beam_directions_G, slant_range_sphere, slant_range_surface
from workbench.problems.entry.site import R_MOLA, TERRAIN_ELEVATION_M, TerrainRelief
from workbench.problems.entry.state import DP, DTH, DV

__all__ = [
    "GYRO_SATURATION_DPS",
    "EntryImuModel",
    "NominalErrorModel",
    "EntryTelemetrySpec",
    "OnboardSolution",
    "EntryTM",
    "IMU_ERROR_NAMES",
    "draw_imu_errors",
    "apply_imu_errors",
    "disperse_telemetry_spec",
    "nominal_state",
    "quat_cumprod",
    "strapdown_onboard",
    "terrain_relative_velocity_G",
    "generate_entry_tm",
]

#: Design range of the Schiaparelli X gyro (AMELIA Sect. 3): rates beyond are clipped [deg/s].
GYRO_SATURATION_DPS = 187.5

#: The entry's IMU error budget: :class:`workbench.models.imu.ImuErrorModel` (the model moved there,
#: shared with the flush-air-data problem; this name is kept for the entry's callers).
EntryImuModel = ImuErrorModel

#: Blackout gaps (start [s from EIP], duration [s]): the four gaps of AMELIA Sect. 3 (1.4, 1.8,
#: 3.3 and 57.2 s), chronologically inside the paper's 23 s → 91 s blackout window.
DEFAULT_GAPS: tuple[tuple[float, float], ...] = ((22.9, 1.4), (24.8, 1.8), (27.1, 3.3), (33.7, 57.2))


# --------------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class NominalErrorModel:
    """Error of the on-board ("nominal") initial state w.r.t. truth, 1σ per axis (SI).

    The nominal state is the TGO-predicted position/velocity plus the on-board attitude (AMELIA
    Sect. 6); the paper's refined state differed from it by ~1°, ~15 m/s and ~3.5 km.
    ``dx0`` — if given — fixes the offset instead of drawing it: the 9-vector
    ``[δv_M (m/s), δθ_G (rad), δp_M (m)]`` = truth − nominal in the error-state convention.
    """

    velocity_sigma: float = 9.0
    attitude_sigma: float = math.radians(0.6)
    position_sigma: float = 2000.0
    dx0: tuple[float, ...] | None = None


@dataclass(frozen=True)
class EntryTelemetrySpec:
    """How the synthetic TM is produced (rates [Hz], gaps [s], radar noise, terrain).

    ``gaps``: blackout windows ``(start_s, duration_s)``; TM rows strictly inside
    ``(start, start + duration)`` are absent (the TM sample at ``start`` is the last before the
    gap).  Radar: slant-range packets every ``sr_period_s`` starting ``sr_first_after_on_s``
    after ``RDA_ON`` (= FSR + ``rda_on_after_fsr_s``), the first ``sr_zero_filled`` of them
    zero-filled as on Schiaparelli; range noise 1σ ``hypot(range_sigma, range_sigma_frac ×
    range)`` [m]; velocity noise 1σ ``velocity_sigma`` [m/s] per axis.  ``r_ground`` [m] radius of
    the terrain sphere.  ``squint_deg``/``azimuths_deg`` the beam geometry (None: the documented
    geometry of :func:`~workbench.models.radar.beam_directions_G`; a scenario's comes from ``[radar]``).
    Built from a scenario by :meth:`~workbench.problems.entry.config.EntrySettings.from_scenario`.
    """

    imu: EntryImuModel = field(default_factory=EntryImuModel)
    nominal: NominalErrorModel = field(default_factory=NominalErrorModel)
    onboard_rate_hz: float = 100.0
    gnc_rate_hz: float = 10.0
    nav_rate_hz: float = 1.0
    gaps: tuple[tuple[float, float], ...] = DEFAULT_GAPS
    rda_rate_hz: float = 10.0
    rda_on_after_fsr_s: float = 4.0
    sr_period_s: float = 10.0
    sr_first_after_on_s: float = 0.4
    sr_zero_filled: int = 2
    range_sigma: float = 5.0
    range_sigma_frac: float = 0.01
    velocity_sigma: float = 1.0
    r_ground: float = R_MOLA + TERRAIN_ELEVATION_M
    squint_deg: float | None = None
    azimuths_deg: tuple[float, float, float] | None = None


# --------------------------------------------------------------------------------------------
# IMU and initial state
# --------------------------------------------------------------------------------------------


def disperse_telemetry_spec(spec: EntryTelemetrySpec, rng: np.random.Generator) -> EntryTelemetrySpec:
    """The telemetry spec of one Monte Carlo member: every per-run sensor error drawn and fixed as data.

    Draws, in this order from ``rng``: the IMU errors of :data:`IMU_ERROR_NAMES` from the spec's
    1σ levels (defaults, :class:`EntryImuModel`: accelerometer bias 1e-3 m/s², scale 300 ppm,
    misalignment 0.2 mrad; gyro bias 1 °/h, scale 100 ppm, misalignment 0.2 mrad; per axis) into
    ``imu.errors``; the on-board nominal initial-state error ``nominal.dx0`` = N(0, σ) per axis of
    ``[δv (9 m/s), δθ (0.6°), δp (2 km)]`` (:class:`NominalErrorModel`).  The white noises (IMU
    samples, radar ranges 1σ ``hypot(range_sigma, range_sigma_frac × range)``, velocity-out 1σ
    ``velocity_sigma``) stay at the spec's levels and are drawn by :func:`generate_entry_tm`
    from its own ``rng``.  Returns a new :class:`EntryTelemetrySpec`.
    """
    imu = spec.imu
    drawn = draw_imu_errors(dataclasses.replace(imu, errors=None), rng)
    imu = dataclasses.replace(imu, errors=tuple(tuple(float(x) for x in drawn[k]) for k in IMU_ERROR_NAMES))
    nm = spec.nominal
    dx0 = np.concatenate(
        [
            rng.normal(0.0, nm.velocity_sigma, 3),
            rng.normal(0.0, nm.attitude_sigma, 3),
            rng.normal(0.0, nm.position_sigma, 3),
        ]
    )
    nominal = dataclasses.replace(nm, dx0=tuple(float(x) for x in dx0))
    return dataclasses.replace(spec, imu=imu, nominal=nominal)


def nominal_state(
    v0: np.ndarray, q0: np.ndarray, p0: np.ndarray, model: NominalErrorModel, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """On-board initial state from the true one: ``(v_nom (3,), q_nom (4,), p_nom (3,), dx0 (9,))``.

    ``dx0 = [δv, δθ, δp]`` is truth − nominal in the error-state convention (``v_true = v_nom +
    δv``, ``q_true = q_nom ⊗ exp(δθ)``, ``p_true = p_nom + δp``), drawn from ``model``'s sigmas
    unless ``model.dx0`` fixes it.  v [m/s] and p [m] in M, q = q_M_G.
    """
    if model.dx0 is not None:
        dx0 = np.asarray(model.dx0, float)
    else:
        dx0 = np.concatenate(
            [
                rng.normal(0.0, model.velocity_sigma, 3),
                rng.normal(0.0, model.attitude_sigma, 3),
                rng.normal(0.0, model.position_sigma, 3),
            ]
        )
    v_nom = np.asarray(v0, float) - dx0[DV]
    q_nom = quat_normalize(quat_multiply(np.asarray(q0, float), quat_from_rotvec(-dx0[DTH])))
    p_nom = np.asarray(p0, float) - dx0[DP]
    return v_nom, q_nom, p_nom, dx0


# --------------------------------------------------------------------------------------------
# on-board strapdown
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OnboardSolution:
    """On-board navigation at the GNC rate: ``t`` (n,) [s]; ``v_M``, ``p_M`` (n,3) [m/s, m];
    ``q_M_G`` (n,4); ``a_M_total`` (n,3) [m/s²] = gravity_j2(p) + C_M_G f_G (what the TM reports);
    ``f_G``, ``w_G`` (n,3) the measured IMU it integrated."""

    t: np.ndarray
    v_M: np.ndarray
    q_M_G: np.ndarray
    p_M: np.ndarray
    a_M_total: np.ndarray
    f_G: np.ndarray
    w_G: np.ndarray


def quat_cumprod(q: np.ndarray) -> np.ndarray:
    """Inclusive running Hamilton product ``S[k] = q[0] ⊗ q[1] ⊗ … ⊗ q[k]`` of (n,4) quaternions.

    A parallel-prefix (Hillis–Steele) scan: ⌈log2 n⌉ vectorised multiplications, renormalised
    after each, instead of an n-step Python loop.  Returns (n,4).
    """
    s = np.array(q, dtype=float, copy=True)
    n = s.shape[0]
    k = 1
    while k < n:
        s[k:] = quat_multiply(s[:-k], s[k:])
        s = quat_normalize(s)
        k *= 2
    return s


def _cumtrapz(y: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Cumulative trapezoid integral along axis 0 (starts at 0); y (n,3), dt (n−1,)."""
    out = np.zeros_like(y)
    np.cumsum(0.5 * (y[1:] + y[:-1]) * dt[:, None], axis=0, out=out[1:])
    return out


def strapdown_onboard(
    t: np.ndarray,
    f_G: np.ndarray,
    w_G: np.ndarray,
    v0: np.ndarray,
    q0: np.ndarray,
    p0: np.ndarray,
    *,
    body: Body = MARS,
    tol: float = 1e-5,
    max_iter: int = 60,
) -> OnboardSolution:
    """Strapdown navigation in M from measured f_G, w_G (n,3) at times t (n,) [s], vectorised.

    Attitude: ``q[k+1] = q[k] ⊗ exp(φ_k)`` with ``φ_k = (w_k + w_{k+1}) Δt/2 + (w_k × w_{k+1}) Δt²/12``
    (rate linear over the step, with the coning term), evaluated for all steps at once by a
    prefix product (:func:`quat_cumprod`).  Translation (AMELIA Eq. A.2): ``v̇ = C_M_G f + g(p)``,
    ``ṗ = v`` by trapezoid sums; the gravity coupling is resolved by Picard iteration on the whole
    arc (contraction ≈ |∂g/∂p| T²/2 ≈ 0.1 for 300 s) until the position changes by < ``tol`` [m].
    Gravity: point mass + J2 of ``body`` evaluated in M (its +Z is the pole).
    """
    t = np.asarray(t, float)
    f_G = np.asarray(f_G, float)
    w_G = np.asarray(w_G, float)
    dt = np.diff(t)
    phi = 0.5 * (w_G[1:] + w_G[:-1]) * dt[:, None] + np.cross(w_G[:-1], w_G[1:]) * (dt**2 / 12.0)[:, None]
    q = quat_cumprod(np.vstack([quat_normalize(np.asarray(q0, float))[None], quat_from_rotvec(phi)]))
    a_ng = quat_rotate(q, f_G)
    v0 = np.asarray(v0, float)
    p0 = np.asarray(p0, float)
    g = np.broadcast_to(gravity_j2(p0, body), a_ng.shape)
    p = None
    for _ in range(max_iter):
        v = v0 + _cumtrapz(a_ng + g, dt)
        p_new = p0 + _cumtrapz(v, dt)
        done = p is not None and float(np.max(np.abs(p_new - p))) < tol
        p = p_new
        g = gravity_j2(p, body)
        if done:
            break
    else:  # pragma: no cover - only for absurd arcs
        raise RuntimeError("strapdown_onboard: gravity iteration did not converge")
    v = v0 + _cumtrapz(a_ng + g, dt)
    return OnboardSolution(t=t, v_M=v, q_M_G=q, p_M=p, a_M_total=a_ng + g, f_G=f_G, w_G=w_G)


# --------------------------------------------------------------------------------------------
# radar velocity (truth side)
# --------------------------------------------------------------------------------------------


def terrain_relative_velocity_G(
    p_M: np.ndarray, v_M: np.ndarray, q_M_G: np.ndarray, omega: float = MARS.rotation_rate
) -> np.ndarray:
    """Velocity relative to the rotating ground in G (AMELIA Eq. B.5): ``C_G_M (v − Ω × p)`` (n,3) [m/s],
    Ω = [0, 0, ``omega``] [rad/s] in M."""
    v_rel = np.asarray(v_M, float) - np.cross(np.array([0.0, 0.0, omega]), np.asarray(p_M, float))
    return quat_rotate(quat_conjugate(np.asarray(q_M_G, float)), v_rel)


# --------------------------------------------------------------------------------------------
# TM generation
# --------------------------------------------------------------------------------------------


def _outside_gaps(t: np.ndarray, gaps, eps: float = 1e-6) -> np.ndarray:
    keep = np.ones(t.shape, bool)
    for start, dur in gaps:
        keep &= ~((t > start + eps) & (t < start + dur - eps))
    return keep


@dataclass(frozen=True)
class EntryTM:
    """Synthetic telemetry in SI, before it is written to files (times [s] from EIP).

    ``t_gnc`` (n,), ``w_G`` (n,3) measured rate, ``q_jpl`` (n,4) JPL MMED→GNC (= raw q_M_G of the
    on-board navigation), ``a_M_total`` (n,3) on-board inertial acceleration incl. gravity;
    ``t_nav`` (m,), ``p_M``, ``v_M`` (m,3) on-board position/velocity; ``t_sr`` (k,),
    ``slant_ranges`` (k,4) (zero-filled packets are 0); ``t_rda`` (j,), ``slant_out`` (j,),
    ``v_out_G`` (j,3); ``events`` (incl. RDA_ON); ``epoch_utc``; ``onboard`` the full on-board
    solution at 100 Hz; ``nominal`` = (t0, v0, q0, p0, dx0) the on-board initial state and its
    error; ``imu_errors`` the drawn per-run IMU errors; ``saturated_G`` (n,3) the clipped samples;
    ``slant_out_true`` (j,) the noise-free slant-out on the truth's terrain and
    ``slant_out_sphere`` (j,) the same on the terrain sphere the estimator assumes [m].
    """

    t_gnc: np.ndarray
    w_G: np.ndarray
    q_jpl: np.ndarray
    a_M_total: np.ndarray
    t_nav: np.ndarray
    p_M: np.ndarray
    v_M: np.ndarray
    t_sr: np.ndarray
    slant_ranges: np.ndarray
    t_rda: np.ndarray
    slant_out: np.ndarray
    v_out_G: np.ndarray
    events: dict[str, float]
    epoch_utc: str
    onboard: OnboardSolution
    nominal: tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    imu_errors: dict[str, np.ndarray]
    saturated_G: np.ndarray
    slant_out_true: np.ndarray | None = None
    slant_out_sphere: np.ndarray | None = None


def _round_t(t: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(t, float), 9) + 0.0  # + 0.0 turns -0.0 into 0.0


def generate_entry_tm(truth, spec: EntryTelemetrySpec, rng: np.random.Generator) -> EntryTM:
    """Telemetry of AMELIA Table 1 from a truth trajectory (an ``EntryTruth`` or anything with the
    fields ``t, p_M, v_M, q_M_G, w_G, f_G, events, epoch_utc``).

    Draws, in this order from ``rng``: the on-board initial-state error, the IMU errors (per-run,
    then 100 Hz noise), the slant-range noise, the slant-out and velocity-out noise.  The data
    run from the truth's first sample to ``BSR`` (end of data; the truth's end if absent).
    """
    t_tr = np.asarray(truth.t, float)
    events = {str(k): float(v) for k, v in dict(truth.events).items()}
    t_end = min(float(t_tr[-1]), events.get("BSR", math.inf))
    dt_ob = 1.0 / spec.onboard_rate_hz
    n_ob = int(math.floor((t_end - t_tr[0]) / dt_ob + 1e-6)) + 1
    t_ob = _round_t(t_tr[0] + dt_ob * np.arange(n_ob))

    f_true = interp_rows(t_ob, t_tr, truth.f_G)
    w_true = interp_rows(t_ob, t_tr, truth.w_G)
    v0, q0, p0 = (np.asarray(truth.v_M[0], float), quat_normalize(truth.q_M_G[0]), np.asarray(truth.p_M[0], float))
    v_nom, q_nom, p_nom, dx0 = nominal_state(v0, q0, p0, spec.nominal, rng)
    f_meas, w_meas, drawn = apply_imu_errors(f_true, w_true, spec.imu, rng)
    ob = strapdown_onboard(t_ob, f_meas, w_meas, v_nom, q_nom, p_nom)
    sat = np.abs(w_meas) >= np.asarray(spec.imu.gyro_full_scale) * (1.0 - 1e-12)

    # 10 Hz GNC TM and 1 Hz navigation TM (decimations of the 100 Hz on-board outputs)
    k_gnc = max(1, int(round(spec.onboard_rate_hz / spec.gnc_rate_hz)))
    k_nav = max(1, int(round(spec.onboard_rate_hz / spec.nav_rate_hz)))
    ig = np.arange(0, n_ob, k_gnc)
    ig = ig[_outside_gaps(t_ob[ig], spec.gaps)]
    inav = np.arange(0, n_ob, k_nav)
    inav = inav[_outside_gaps(t_ob[inav], spec.gaps)]

    # radar (truth geometry, sampled at the radar times)
    if "FSR" in events and "RDA_ON" not in events:
        events["RDA_ON"] = events["FSR"] + spec.rda_on_after_fsr_s
    beams = beam_directions_G() if spec.squint_deg is None else beam_directions_G(spec.squint_deg, spec.azimuths_deg)
    modes = getattr(truth, "terrain_modes", None)
    modes = () if modes is None else tuple(tuple(float(x) for x in row) for row in np.asarray(modes).reshape(-1, 5))
    relief = TerrainRelief(spec.r_ground, modes)
    rho0 = rho0_sphere = np.empty(0)
    t_sr = np.empty(0)
    sr = np.empty((0, 4))
    t_rda = np.empty(0)
    so = np.empty(0)
    vo = np.empty((0, 3))
    if "RDA_ON" in events:
        t_on = events["RDA_ON"]
        t_sr = _round_t(np.arange(t_on + spec.sr_first_after_on_s, t_end + 1e-9, spec.sr_period_s))
        q_sr = quat_normalize(interp_rows(t_sr, t_tr, truth.q_M_G))
        p_sr = interp_rows(t_sr, t_tr, truth.p_M)
        sr = _ranges(p_sr[:, None], q_sr[:, None], beams, t_sr[:, None], spec.r_ground, relief)
        sr = sr + rng.normal(0.0, 1.0, sr.shape) * np.hypot(spec.range_sigma, spec.range_sigma_frac * sr)
        sr[: spec.sr_zero_filled] = 0.0
        sr = np.where(np.isfinite(sr), sr, 0.0)  # a beam without a ground echo reports 0 (flagged on reading)
        dt_r = 1.0 / spec.rda_rate_hz
        t_rda = _round_t(dt_r * np.arange(math.ceil(t_on / dt_r - 1e-6), math.floor(t_end / dt_r + 1e-6) + 1))
        p_r = interp_rows(t_rda, t_tr, truth.p_M)
        q_r = quat_normalize(interp_rows(t_rda, t_tr, truth.q_M_G))
        rho0 = _ranges(p_r, q_r, beams[0], t_rda, spec.r_ground, relief)
        rho0_sphere = slant_range_sphere(p_r, q_r, beams[0], spec.r_ground)
        so = rho0 + rng.normal(0.0, 1.0, rho0.shape) * np.hypot(spec.range_sigma, spec.range_sigma_frac * rho0)
        so = np.where(np.isfinite(so), so, 0.0)
        vo = terrain_relative_velocity_G(p_r, interp_rows(t_rda, t_tr, truth.v_M), q_r)
        vo = vo + rng.normal(0.0, spec.velocity_sigma, vo.shape)

    return EntryTM(
        t_gnc=t_ob[ig],
        w_G=w_meas[ig],
        q_jpl=ob.q_M_G[ig],  # JPL "MMED to GNC" = raw components of q_M_G (quat_from_jpl docstring)
        a_M_total=ob.a_M_total[ig],
        t_nav=t_ob[inav],
        p_M=ob.p_M[inav],
        v_M=ob.v_M[inav],
        t_sr=t_sr,
        slant_ranges=sr,
        t_rda=t_rda,
        slant_out=so,
        v_out_G=vo,
        events=dict(sorted(events.items(), key=lambda kv: kv[1])),
        epoch_utc=str(getattr(truth, "epoch_utc", "")),
        onboard=ob,
        nominal=(float(t_ob[0]), v_nom, q_nom, p_nom, dx0),
        imu_errors=drawn,
        saturated_G=sat[ig],
        slant_out_true=rho0,
        slant_out_sphere=rho0_sphere,
    )


def _ranges(p, q, beams, t, r_ground, relief: TerrainRelief):
    """Noise-free ranges: on the sphere, or on the sphere plus the truth's relief at times t."""
    if not relief.modes:
        return slant_range_sphere(p, q, beams, r_ground)
    return slant_range_surface(p, q, beams, r_ground, lambda x: relief.radius(x, t))
