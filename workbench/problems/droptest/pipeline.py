"""Airbag drop-test reconstruction (REDLand): telemetry files -> pose, stroke and its 1σ.

Stages, each yielded as a frozen dataclass so that the recorder (or a test) can observe them:

1. :class:`DropTelemetry` — the files read and validated; IMU samples averaged to the filter rate,
   time tags corrected for the acquisition filter's group delay; saturated samples, dead
   channels and gaps found and turned into *visible* degradations (never silently integrated).
2. :class:`InitialState` — algebraic (TRIAD) attitude from the 3DM gravity/magnetic pair with its
   covariance mapped from the vector uncertainties; position from the surveyed hanging point.
3. :class:`FilterStage` ``forward`` — the REDLand EKF (19 states of the paper + gyro error matrix and
   bias + per-triad accelerometer biases; kinematic or dynamic mode), the
   four triads through their lever arms, the gyro, zero-velocity updates while hanging, optional
   odometer / radar-gun ranges; process noise raised on rapid acceleration changes.  The IMU part
   of every step runs in the compiled recursion :mod:`.kernel` (numba; the generic
   :func:`~workbench.estimation.ekf.run_filter` path is kept as ``engine="reference"``).
4. :class:`FilterStage` ``smoothed`` — RTS smoother over the forward pass.
5. :class:`StrokeStage` — at every step the distance from the ramp to the closest point of the
   lander mesh with its linearised 1σ (checked by sampling the posterior at max stroke), the
   maximum-stroke event, full-stroke flags, and the coefficient of restitution with its 1σ.
6. :class:`DropResult` — all of it plus the summary numbers.

The reconstruction reads only the scenario and telemetry files; truth never enters here.

References: REDLand paper (``redland-mer-airbag-droptest.txt``), Eq. 3–19 and "Results";
Wertz (1978) Sect. 12.2 for the algebraic attitude.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from workbench.core.bodies import G0
from workbench.core.interpolation import interp_rows
from workbench.core.rotation import (
    quat_conjugate,
    quat_normalize,
    quat_rotate,
    quat_to_dcm,
    triad,
    triad_covariance,
)
from workbench.estimation.consistency import whiteness
from workbench.estimation.ekf import (
    ErrorStateLayout,
    ForwardPass,
    InnovationHistory,
    Measurement,
    apply_measurements,
    run_filter,
)
from workbench.estimation.health import covariance_stats, finite_steps, health_markdown
from workbench.estimation.smoother import SmoothedPass, cross_covariance, rts_smooth
from workbench.io import scorecard as sc
from workbench.io.scenario import ScenarioError
from workbench.problems.droptest import model as rl
from workbench.problems.droptest.config import DropSettings
from workbench.problems.droptest.health import drop_health
from workbench.problems.droptest.lander import LanderModel
from workbench.problems.droptest.physics import LagEstimate, contact_completeness, estimate_lag
from workbench.problems.droptest.sensors import RangingSpec
from workbench.problems.droptest.stroke import (
    MaxStroke,
    StrokeHistory,
    contact_end,
    contact_interval,
    max_stroke,
    restitution,
    restitution_definitions,
    sampled_stroke_sigma,
    stroke_history,
)
from workbench.problems.droptest.surface import Surface, ramp_surface
from workbench.problems.droptest.telemetry import DropTelemetry, load_drop_telemetry

__all__ = [
    "finite_or_fail",
    "InitialState",
    "FilterStage",
    "StrokeStage",
    "DropResult",
    "reconstruct",
    "run_droptest",
]

GRAVITY = np.array([0.0, 0.0, -G0])

#: what the scorecard says where the restitution has no value (the lander never left the ramp)
NO_REBOUND = "not defined: no rebound"

#: the restitution definition, as the summary and scorecard state it
RESTITUTION_DEFINITION = (
    "e = -max(v_n)/min(v_n), v_n the smoothed CM velocity along the ramp normal, its minimum before it first turns "
    "positive (approaching) and its maximum after that up to the rebound's apex (v_n back at zero in free flight; "
    "leaving), over the whole impact: a glancing first touch and a bag pushing again as the lander rolls off are "
    "parts of it, a touch-down after the apex is not; both are where the bag normal force equals the normal "
    "component of gravity; sigma = sqrt(sigma_estimation^2 + sigma_definition^2), sigma_definition = the largest "
    "difference from e of the readings of v_n just outside the impact's samples above 0.25, 0.5 or 1 g and of v_n "
    "extrapolated to the instants the bags touch and leave, a reading whose ends are not within 0.05 s of the "
    "extremes left out"
)


def layout_for(n_triads: int) -> ErrorStateLayout:
    """Error-state layout of the REDLand filter with ``n_triads`` accelerometer bias blocks."""
    return ErrorStateLayout(rl.sizes(n_triads)[0], rl.QUAT_BLOCKS)


# ---------------------------------------------------------------------------------------------
# stage results
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class InitialState:
    """Filter start: x0 (N_X,), P0 (N_E, N_E); the 3DM mean unit vectors ``up_B``, ``mag_B`` (body);
    the TRIAD attitude ``q0`` (q_SPF_B) and its small-angle covariance ``P_theta`` (3,3) [rad²]."""

    x0: np.ndarray
    P0: np.ndarray
    q0: np.ndarray
    P_theta: np.ndarray
    up_B: np.ndarray
    mag_B: np.ndarray


@dataclass(frozen=True)
class FilterStage:
    """One pass: ``name`` "forward" or "smoothed"; ``t`` (n,); ``x`` (n, N_X); ``P`` (n, N_E, N_E)
    error covariance; ``forward`` the :class:`ForwardPass` (priors, innovations) on the forward
    stage, whose transitions ``F`` and priors ``P_prior`` the smoother consumes
    (:func:`reconstruct`); ``smoothed`` the :class:`SmoothedPass` on the smoothed stage;
    ``q_accel`` and ``q_angular`` (n,) the process-noise PSDs used at each step."""

    name: str
    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    forward: ForwardPass | None = None
    smoothed: SmoothedPass | None = None
    q_accel: np.ndarray | None = None
    q_angular: np.ndarray | None = None

    @property
    def stage_label(self) -> str:
        """Its name in progress lines and ``summary["stage_times_s"]``: which of the two filter passes."""
        what = {"forward": "1/2 (forward EKF)", "smoothed": "2/2 (RTS smoother)"}.get(self.name, f"({self.name})")
        return f"filter pass {what}"


@dataclass(frozen=True)
class StrokeStage:
    """Stroke of the smoothed (and forward) pose against the ramp.

    ``smoothed``/``forward`` :class:`StrokeHistory` (n steps); ``max`` the maximum-stroke event;
    ``sampled_sigma`` 1σ at max stroke from 4000 posterior samples (check of the linearisation);
    ``restitution`` (e, σ_e) from the ramp-normal CM velocity before/after the impact (definition in
    :mod:`.stroke`), σ_e = √(σ_est² + σ_def²); ``restitution_sigma_estimation`` σ_est (smoothed
    covariance, with the cross-covariance of the two epochs); ``restitution_sigma_definition``
    σ_def = the largest |difference| of the equivalent definitions of
    :func:`~.stroke.restitution_definitions` (``restitution_definitions``: name → e) from e;
    ``restitution_index`` the step indices of its two velocities (approaching, leaving; -1: none);
    ``contact`` (i_start, i_end) filter indices of the airbag contact detected from the estimated
    non-gravitational acceleration; ``surface`` the ramp; ``lander`` the model.
    """

    smoothed: StrokeHistory
    forward: StrokeHistory
    max: MaxStroke
    sampled_sigma: float
    sampled_mean: float
    restitution: tuple[float, float]
    contact: tuple[int, int]
    surface: Surface = field(repr=False)
    lander: LanderModel = field(repr=False)
    restitution_sigma_estimation: float = float("nan")
    restitution_sigma_definition: float = float("nan")
    restitution_definitions: dict = field(default_factory=dict)
    restitution_index: tuple[int, int] = (-1, -1)


@dataclass(frozen=True)
class DropResult:
    """Everything the reconstruction produced, and ``summary`` (JSON-ready numbers). Three
    histories are not kept (a long log's memory): the forward pass's transitions
    ``forward.forward.F`` and priors ``forward.forward.P_prior`` and the smoother's gains
    ``smoothed.smoothed.G`` are empty (0, n_e, n_e) arrays; the gains served the restitution's
    cross-covariance (:func:`stroke_stage`), the priors the IMU lag estimate
    (:func:`~.physics.estimate_lag`)."""

    telemetry: DropTelemetry
    initial: InitialState
    forward: FilterStage
    smoothed: FilterStage
    stroke: StrokeStage
    summary: dict


# ---------------------------------------------------------------------------------------------
# initial state
# ---------------------------------------------------------------------------------------------


def initial_state(settings: DropSettings, tel: DropTelemetry) -> InitialState:
    """Initial state and covariance at the first filter time (lander hanging at rest), from the
    run's ``settings`` (3DM and gyro errors, filter priors) and the telemetry ``tel``.

    The 3DM unit vectors are averaged over the samples before the release event only.
    """
    cfg = settings
    att = tel.attitude
    # the 3DM reading is only valid while the lander hangs still (its tags corrected by its latency)
    hang = att.time - tel.time_shifts_s.get("attitude_3dm", 0.0) < tel.events["release"]
    if not hang.any():
        raise ScenarioError(
            att.path,
            None,
            "no 3DM sample before the release event: the initial attitude needs the lander hanging still",
        )
    up_B = att.stack(["up.x", "up.y", "up.z"])[hang].mean(0)
    mag_B = att.stack(["mag.x", "mag.y", "mag.z"])[hang].mean(0)
    up_B /= np.linalg.norm(up_B)
    mag_B /= np.linalg.norm(mag_B)
    mag_I = cfg.chamber.magnetic_field_spf
    q0 = triad(up_B, mag_B, np.array([0.0, 0.0, 1.0]), mag_I)
    sg = np.radians(cfg.attitude_3dm.gravity_sigma_deg)
    sm = np.radians(cfg.attitude_3dm.magnetic_sigma_deg)
    P_theta = triad_covariance(up_B, mag_B, sg, sm)
    hang = tel.setup["hanging"]
    p0 = np.asarray(hang["position_m"], float)
    sp = float(hang["position_sigma_m"])
    n_x, n_e = rl.sizes(len(tel.triads))
    x0 = np.zeros(n_x)
    x0[rl.SP] = p0
    x0[rl.SQ] = quat_normalize(q0)
    x0[rl.SA] = quat_rotate(quat_conjugate(x0[rl.SQ]), -GRAVITY)  # hanging: a_ng = -g, in body axes
    P0 = np.zeros((n_e, n_e))
    P0[rl.EP, rl.EP] = sp**2 * np.eye(3)
    P0[rl.EV, rl.EV] = cfg.filter.velocity_sigma_mps**2 * np.eye(3)
    P0[rl.EA, rl.EA] = cfg.filter.accel_sigma_mps2**2 * np.eye(3)
    P0[rl.ETH, rl.ETH] = P_theta
    P0[rl.EW, rl.EW] = np.radians(cfg.filter.rate_sigma_dps) ** 2 * np.eye(3)
    P0[rl.EAL, rl.EAL] = cfg.filter.angular_accel_sigma**2 * np.eye(3)
    # gyro error matrix: scale factors on the diagonal, misalignment [rad] off it (datasheet 1σ)
    s_sc = cfg.gyro.scale
    s_mis = np.radians(cfg.gyro.misalignment_deg)
    P0[rl.ES, rl.ES] = np.diag(np.where(np.eye(3).ravel() > 0, s_sc, s_mis) ** 2)
    P0[rl.EBG, rl.EBG] = np.radians(cfg.gyro.bias_dps) ** 2 * np.eye(3)
    sb = cfg.accelerometer.bias_g * G0  # residual after zeroing, 1σ
    for j in range(len(tel.triads)):
        P0[rl.bias_slices(j)[1], rl.bias_slices(j)[1]] = sb**2 * np.eye(3)
    return InitialState(x0=x0, P0=P0, q0=x0[rl.SQ].copy(), P_theta=P_theta, up_B=up_B, mag_B=mag_B)


# ---------------------------------------------------------------------------------------------
# filter
# ---------------------------------------------------------------------------------------------


class _Memo:
    """Evaluate a model returning (z, H) once per state object (h and H share the work)."""

    def __init__(self, fn: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]):
        self.fn = fn
        self.key = None
        self.val = None

    def _get(self, x):
        if self.key is not x:
            self.key, self.val = x, self.fn(x)
        return self.val

    def h(self, x):
        return self._get(x)[0]

    def H(self, x):
        return self._get(x)[1]


def _bungee(setup: dict, lander: LanderModel) -> rl.BungeeModel | None:
    b = setup.get("bungee")
    if not b:
        return None
    return rl.BungeeModel(
        anchor_I=np.asarray(b["anchor_m"], float),
        rest_length=float(b["rest_length_m"]),
        coeffs=tuple(float(c) for c in b["coefficients"]),
        count=float(b["count"]),
        mass=float(b["mass_kg"]),
        attach_B=lander.to_body(b["attach_body_m"]),
    )


def forward_pass(
    settings: DropSettings, tel: DropTelemetry, init: InitialState, *, engine: str = "numba"
) -> FilterStage:
    """Run the REDLand EKF over the telemetry ``tel`` from ``init`` with the run's ``settings``
    (filter tuning, sensor noise, the lander's mass and inertia; see module docstring).

    ``engine``: ``"numba"`` (the default; every run uses it) runs the kinematic filter's IMU part
    through the compiled recursion :func:`workbench.problems.droptest.kernel.imu_steps` (ranging
    measurements still through :func:`~workbench.estimation.ekf.apply_measurements`); ``"reference"``
    the generic :func:`~workbench.estimation.ekf.run_filter` with the Python models.  The two agree
    to floating-point noise, in both modes.
    """
    cfg = settings
    lander = settings.lander
    mode = cfg.filter.mode
    if mode not in ("kinematic", "dynamic"):
        raise ScenarioError(settings.path, "filter.mode", f"must be 'kinematic' or 'dynamic', got {mode!r}")
    bungee = _bungee(tel.setup, lander) if mode == "dynamic" else None
    if mode == "dynamic" and bungee is None:
        raise ScenarioError(settings.path, "filter.mode", "'dynamic' needs a [bungee] table in the setup file")
    t_rel = tel.events["release"]
    t_cut = tel.events.get("bungee_cut", np.inf)

    rate = tel.rate_hz
    # per-sample noise divided by the number of samples actually averaged into each step
    v_acc = (cfg.accelerometer.noise_g * G0) ** 2
    v_gyr = np.radians(cfg.gyro.noise_dps) ** 2
    n_f, n_w = tel.counts
    eye3 = np.eye(3)
    r_zupt = cfg.filter.hang_zupt_sigma_mps**2 * np.eye(3)

    # process noise schedule: floor + gain * (measured jerk)^2 * dt (REDLand: raised on rapid
    # acceleration changes); angular jerk scaled by m r / J (forces at ~1 m lever arm)
    q_a0 = cfg.filter.q_accel
    q_w0 = cfg.filter.q_angular
    gain = cfg.filter.adaptive_gain
    dt_nom = 1.0 / rate
    s = gain * tel.jerk**2 * dt_nom
    ratio = lander.mass * 1.0 / float(np.min(np.linalg.eigvalsh(lander.inertia_B)))
    q_accel = q_a0 + s
    q_angular = q_w0 + ratio**2 * s

    def transition(x, t0, t1):
        """(x_next, F, Q): Q at the propagated attitude (the SPF–body cross blocks of the jerk chain)."""
        dt = t1 - t0
        active = bungee is not None and t_rel <= t0 and t1 <= t_cut
        xn, F = rl.propagate(x, dt, GRAVITY, bungee if active else None)
        if bungee is not None:
            to_body = quat_conjugate(xn[rl.SQ])
            if t0 < t_rel <= t1:  # the release rope lets go: a jumps from -g to the bungee pull
                xn[rl.SA] += quat_rotate(to_body, bungee.accel(xn[rl.SP], xn[rl.SQ])[0] + GRAVITY)
            if t0 < t_cut <= t1:  # the hammer hits the nail: the bungee pull vanishes
                xn[rl.SA] -= quat_rotate(to_body, bungee.accel(xn[rl.SP], xn[rl.SQ])[0])
        k = int(np.searchsorted(tel.t, t1))  # the step's process-noise PSDs (raised on rapid jerk)
        return xn, F, rl.process_noise(dt, q_accel[k], q_angular[k], quat_to_dcm(xn[rl.SQ]), n_e)

    triad_memos = [_Memo(lambda x, r=r, j=j: rl.triad_model(x, r, j)) for j, r in enumerate(tel.lever_arms_B)]
    gyro_memo = _Memo(rl.gyro_model)
    n_e = init.P0.shape[0]
    H_zupt = np.zeros((3, n_e))
    H_zupt[:, rl.EV] = np.eye(3)

    ranging = (
        _ranging_measurements(RangingSpec.from_settings(cfg.ranging), tel, lander) if tel.ranging is not None else {}
    )

    # the triads' declared scale-factor and misalignment errors (sensors.accelerometer.scale,
    # misalignment_deg; no states for them) as measurement noise proportional to the measured force:
    # per axis σ² = s² f_i² + m² (|f|² − f_i²) — not averaged down, the error is common to the samples
    s2, m2 = cfg.accelerometer.scale**2, np.radians(cfg.accelerometer.misalignment_deg) ** 2
    f2 = tel.f_B**2
    r_sm = s2 * f2 + m2 * (np.sum(f2, axis=-1, keepdims=True) - f2)  # (n, n_triads, 3)

    def measurements_at(k, tk, x_prior):
        out = []
        for j, name in enumerate(tel.triads):
            if tel.f_valid[k, j]:
                m = triad_memos[j]
                out.append(Measurement(name, tel.f_B[k, j], v_acc / n_f[k, j] * eye3 + np.diag(r_sm[k, j]), m.h, m.H))
        if tel.w_valid[k]:
            out.append(Measurement("gyro", tel.w_B[k], v_gyr / n_w[k] * eye3, gyro_memo.h, gyro_memo.H))
        if tel.hanging[k]:
            out.append(Measurement("zupt", np.zeros(3), r_zupt, lambda x: x[rl.SV], H_zupt))
        for meas in ranging.get(k, ()):
            out.append(meas)
        return out

    if engine not in ("numba", "reference"):
        raise ValueError(f"forward_pass: engine must be 'numba' or 'reference', got {engine!r}")
    if engine == "numba":  # the compiled recursion
        bp = np.zeros(13)
        coeffs = np.zeros(1)
        if bungee is not None:
            bp[0] = 1.0
            bp[1:4], bp[4:7] = bungee.anchor_I, bungee.attach_B
            bp[7], bp[8], bp[11], bp[12] = bungee.rest_length, bungee.count / bungee.mass, t_rel, t_cut
            coeffs = np.array(bungee.coeffs, dtype=float)
        fp = _forward_compiled(tel, init, q_accel, q_angular, v_acc, v_gyr, r_sm, r_zupt, ranging, bp, coeffs)
    else:
        fp = run_filter(
            init.x0,
            init.P0,
            tel.t,
            transition,
            None,
            measurements_at,
            layout_for(len(tel.triads)),
        )
    return FilterStage("forward", fp.t, fp.x_post, fp.P_post, forward=fp, q_accel=q_accel, q_angular=q_angular)


def _forward_compiled(
    tel: DropTelemetry,
    init: InitialState,
    q_accel: np.ndarray,
    q_angular: np.ndarray,
    v_acc: float,
    v_gyr: float,
    r_sm: np.ndarray,
    r_zupt: np.ndarray,
    ranging: dict[int, list[Measurement]],
    bungee: np.ndarray,
    coeffs: np.ndarray,
) -> ForwardPass:
    """The forward pass by :func:`workbench.problems.droptest.kernel.imu_steps`, the steps
    with ranging measurements split so that those are applied after the step's IMU updates (the
    order of the reference path); the same :class:`ForwardPass` as :func:`run_filter` would record."""
    from workbench.problems.droptest.kernel import imu_steps

    layout = layout_for(len(tel.triads))
    t = np.ascontiguousarray(tel.t, dtype=float)
    n, n_t = t.size, len(tel.triads)
    n_x, n_e = layout.n_x, layout.n_e
    x = np.array(init.x0, dtype=float)
    P = np.array(init.P0, dtype=float)
    if x.shape != (n_x,) or P.shape != (n_e, n_e):
        raise ValueError(f"x0 must be ({n_x},) and P0 ({n_e}, {n_e}); got {x.shape}, {P.shape}")
    n_f, n_w = tel.counts
    f_valid = np.ascontiguousarray(tel.f_valid, dtype=bool)
    w_valid = np.ascontiguousarray(tel.w_valid, dtype=bool)
    hanging = np.ascontiguousarray(tel.hanging, dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):  # no sample averaged: not used
        r_tri = np.where(f_valid[..., None], v_acc / n_f[..., None] + r_sm, 0.0)
        r_gyr = np.where(w_valid, v_gyr / n_w, 0.0)
    x_prior = np.empty((n, n_x))
    x_post = np.empty((n, n_x))
    P_prior = np.empty((n, n_e, n_e))
    P_post = np.empty((n, n_e, n_e))
    F_hist = np.empty((n, n_e, n_e))
    Q_hist = np.empty((1, n_e, n_e))  # scratch: no consumer reads a Q history (saves n·n_e² floats)
    n_c = n_t + 2  # channels: the triads, the gyro, the zero-velocity update
    valid = np.concatenate([f_valid, w_valid[:, None], hanging[:, None]], axis=1)
    z_meas = np.concatenate([tel.f_B, tel.w_B[:, None, :], np.zeros((n, 1, 3))], axis=1)
    r_diag = np.concatenate([r_tri, np.repeat(r_gyr[:, None, None], 3, axis=2), np.zeros((n, 1, 3))], axis=1)
    inn = (np.full((n, n_c, 3), np.nan), np.full((n, n_c, 3), np.nan), np.full((n, n_c, 3, 3), np.nan))
    inn = (*inn, np.full((n, n_c), np.nan))
    args = (
        t, np.asarray(GRAVITY, dtype=float), np.ascontiguousarray(q_accel, dtype=float),
        np.ascontiguousarray(q_angular, dtype=float), np.ascontiguousarray(tel.lever_arms_B, dtype=float),
        np.ascontiguousarray(z_meas, dtype=float), valid, np.ascontiguousarray(r_diag, dtype=float),
        np.ascontiguousarray(r_zupt, dtype=float), bungee, coeffs, x_prior, x_post, P_prior, P_post, F_hist, Q_hist,
        *inn,
    )  # fmt: skip
    names = [*tel.triads, "gyro", "zupt"]
    rows: dict[str, list[tuple]] = {}
    sizes: dict[str, int] = {}
    first: dict[str, tuple[int, int]] = {}  # name -> (first step, position in the step): record order
    k_a = 0
    for k_b in [*sorted(k for k in ranging if 0 <= k < n), n - 1]:
        if k_b < k_a:
            continue
        status, k_err, ch = imu_steps(k_a, k_b, x, P, *args)
        if status:
            what = (
                "innovation covariance S is not positive definite (Cholesky)"
                if status == 1
                else "non-finite innovation (check z, h(x) and R)"
            )
            raise np.linalg.LinAlgError(f"step {k_err} (t={t[k_err]} s), measurement {names[ch]!r}: {what}")
        if k_b in ranging:
            meas = ranging[k_b]
            for i, m in enumerate(meas):
                first.setdefault(m.name, (k_b, n_t + 2 + i))
            xr, Pr = apply_measurements(k_b, float(t[k_b]), x, P, meas, layout, rows, sizes)
            x[:] = xr
            P[:] = Pr
            x_post[k_b] = x
            P_post[k_b] = P
        k_a = k_b + 1
    innov: dict[str, InnovationHistory] = {}
    for c, name in enumerate(names):
        ks = np.flatnonzero(valid[:, c])
        if ks.size:
            first[name] = (int(ks[0]), c)
            zp, y, S, nis = (a[ks, c] for a in inn)
            innov[name] = InnovationHistory(
                t=t[ks], step=ks.astype(int), z=z_meas[ks, c], z_pred=zp, y=y, S=S, nis=nis,
                accepted=np.ones(ks.size, dtype=bool),
            )  # fmt: skip
    for name, r in rows.items():
        innov[name] = InnovationHistory.from_rows(r, sizes[name])
    order = sorted(innov, key=lambda nm: first[nm])
    return ForwardPass(
        t=t,
        x_prior=x_prior,
        P_prior=P_prior,
        x_post=x_post,
        P_post=P_post,
        F=F_hist,
        Q=None,
        innovations={name: innov[name] for name in order},
    )


def _at_time(model: Callable, dt: float) -> Callable:
    """Wrap a (z, H) model so that it is evaluated at ``dt`` [s] after the filter step: the state is
    propagated by the kinematic model (exact to second order over a sub-millisecond offset) and
    the Jacobian chained through that propagation, ``H = H_model(x(t+dt)) F(dt)``."""
    if dt == 0.0:
        return model

    def fn(x):
        xp, F = rl.propagate(x, dt, GRAVITY)
        z, H = model(xp)
        return z, H @ F

    return fn


def _ranging_measurements(spec: RangingSpec, tel: DropTelemetry, lander: LanderModel) -> dict[int, list[Measurement]]:
    """Range aiding of the instruments ``spec`` attached to the nearest filter step and evaluated
    at its own time tag: the odometer (rope length from the sheave to the attachment point, until the cut, plus the
    odometer's zero) and radar-gun range / range rate to each gun's reflector, with each gun's noise.
    The ranging tags are corrected by the ranging stream's own lag (``tel.time_shifts_s["ranging"]``:
    its declared latency, plus the acquisition filter's delay only if it went through that filter),
    just as the IMU tags are by theirs — the two streams meet on one time line."""
    rt = tel.ranging
    out: dict[int, list[Measurement]] = {}
    t_meas = rt.time - tel.time_shifts_s.get("ranging", 0.0)
    idx = np.clip(np.searchsorted(tel.t, t_meas), 1, tel.t.size - 1)
    left = np.abs(tel.t[idx - 1] - t_meas) < np.abs(tel.t[idx] - t_meas)
    idx = np.where(left, idx - 1, idx)
    dt_f = float(np.median(np.diff(tel.t)))
    off = t_meas - tel.t[idx]
    near = np.abs(off) <= dt_f  # outside the IMU record (or in a long gap): not used
    b = tel.setup.get("bungee", {})
    if "odometer" in rt.channels:
        if not b:
            raise ScenarioError(rt.path, None, "an odometer channel needs a [bungee] table in the setup file")
        anchor = np.asarray(b["anchor_m"], float)
        attach = lander.to_body(b["attach_body_m"])
        s2 = np.array([[spec.odometer_variance]])  # noise + the rounding to its count step
        vals = rt.channel("odometer") + spec.odometer_zero  # the rope length
        for i in np.flatnonzero(near & np.isfinite(vals)):
            m = _Memo(_at_time(lambda x: rl.range_model(x, anchor, attach), float(off[i])))
            out.setdefault(int(idx[i]), []).append(
                Measurement("odometer", np.array([vals[i]]), s2, m.h, m.H, gate_probability=0.9999)
            )
    for name, G in spec.guns.items():
        r_ref = lander.to_body(spec.reflectors_L[name])
        if f"{name}.range" not in rt.channels or f"{name}.rate" not in rt.channels:
            raise ScenarioError(
                rt.path, None, f"radar gun {name} configured but no columns '{name}.range', '{name}.rate'"
            )
        zr = rt.channel(f"{name}.range")
        zrr = rt.channel(f"{name}.rate")
        for i in np.flatnonzero(near & (np.isfinite(zr) | np.isfinite(zrr))):  # sparse columns: empty = NaN
            dt_i = float(off[i])
            mr = _Memo(_at_time(lambda x, G=G, r=r_ref: rl.range_model(x, G, r), dt_i))
            mrr = _Memo(_at_time(lambda x, G=G, r=r_ref: rl.range_rate_model(x, G, r), dt_i))
            lst = out.setdefault(int(idx[i]), [])
            if np.isfinite(zr[i]):
                R_r = np.array([[spec.range_sigmas[name] ** 2]])
                lst.append(Measurement(f"{name}.range", np.array([zr[i]]), R_r, mr.h, mr.H, gate_probability=0.9999))
            if np.isfinite(zrr[i]):
                R_rr = np.array([[spec.rate_sigmas[name] ** 2]])
                lst.append(Measurement(f"{name}.rate", np.array([zrr[i]]), R_rr, mrr.h, mrr.H, gate_probability=0.9999))
    return out


# ---------------------------------------------------------------------------------------------
# stroke
# ---------------------------------------------------------------------------------------------


def stroke_stage(
    fwd: FilterStage,
    smo: FilterStage,
    lander: LanderModel,
    surface: Surface,
    events: dict[str, float],
    rng: np.random.Generator,
) -> StrokeStage:
    """Stroke histories, max-stroke event (with a sampled-σ check) and restitution."""
    verts = np.asarray(lander.body.vertices, float)
    faces = np.asarray(lander.body.faces)
    hist = stroke_history(verts, smo.x[:, rl.SP], smo.x[:, rl.SQ], rl.pose_covariance(smo.P), surface, faces_B=faces)
    hist_f = stroke_history(verts, fwd.x[:, rl.SP], fwd.x[:, rl.SQ], rl.pose_covariance(fwd.P), surface, faces_B=faces)
    after = events.get("bungee_cut", events["release"])
    i0, i1 = contact_interval(smo.t, smo.x[:, rl.SA], after, 1.0 * G0)
    mask = smo.t >= events["release"]  # the closest approach after release is the max stroke
    sub = _subset(hist, mask)
    ms = max_stroke(smo.t[mask], sub, lander.body)
    k = int(np.flatnonzero(mask)[ms.index])
    ms = _reindex(ms, k)
    mean, std = sampled_stroke_sigma(
        verts,
        smo.x[k : k + 1, rl.SP],
        smo.x[k : k + 1, rl.SQ],
        rl.pose_covariance(smo.P[k : k + 1]),
        surface,
        4000,
        rng,
        faces_B=faces,
    )
    # restitution, primary definition (extremes of the ramp-normal velocity, module stroke), with its
    # estimation σ from the smoothed covariance of the two epochs and their cross-covariance, and
    # the spread of the equivalent definitions as its definition σ
    rd = restitution_definitions(smo.t, smo.x[:, rl.SV], smo.x[:, rl.SA], surface.normal, after, gravity=GRAVITY)
    e = (np.nan, np.nan)
    if rd.i_before >= 0:
        a, b = rd.i_before, rd.i_after
        P_cross = cross_covariance(smo.smoothed, a, b)
        e = restitution(smo.t, smo.x[:, rl.SV], smo.P[:, rl.EV, rl.EV], surface.normal, a, b, P_cross[rl.EV, rl.EV])
    s_est = float(e[1])
    s_def = rd.spread if np.isfinite(rd.spread) else 0.0
    return StrokeStage(
        smoothed=hist,
        forward=hist_f,
        max=ms,
        sampled_sigma=float(std[0]),
        sampled_mean=float(mean[0]),
        restitution=(float(e[0]), float(np.hypot(s_est, s_def))),
        contact=(i0, i1),
        surface=surface,
        lander=lander,
        restitution_sigma_estimation=s_est,
        restitution_sigma_definition=s_def,
        restitution_definitions=dict(rd.values),
        restitution_index=(int(rd.i_before), int(rd.i_after)),
    )


def _subset(h: StrokeHistory, m: np.ndarray) -> StrokeHistory:
    return StrokeHistory(**{f: getattr(h, f)[m] for f in h.__dataclass_fields__})


def _reindex(ms: MaxStroke, k: int) -> MaxStroke:
    d = {f: getattr(ms, f) for f in ms.__dataclass_fields__}
    d["index"] = k
    return MaxStroke(**d)


# ---------------------------------------------------------------------------------------------
# the pipeline
# ---------------------------------------------------------------------------------------------


def reconstruct(settings: DropSettings, paths: dict[str, Path], seed: int = 0) -> Iterator[object]:
    """Run the drop-test reconstruction of a run with ``settings``; yields the stages in order, the
    last a :class:`DropResult`.

    ``paths`` maps imu, attitude_3dm, events, setup (and optionally ranging) to files.
    ``seed`` drives only the posterior sampling of the stroke-σ check. Memory: the smoother writes
    its gains and smoothed covariances into the forward pass's transitions and priors, so the
    forward stage's ``forward.F`` and ``forward.P_prior`` are consumed once the smoothed stage
    follows (an observer reads a stage when it is yielded).
    """
    lander = settings.lander
    tel = load_drop_telemetry(settings, paths)
    rocks = tel.setup.get("rocks")
    surface = ramp_surface(
        angle_deg=settings.chamber.ramp_angle_deg,
        nail_depth=settings.chamber.nail_depth_m,
        rocks=None
        if not rocks
        else (np.asarray(rocks["centers_m"], float).reshape(-1, 3), np.asarray(rocks["radii_m"], float).reshape(-1)),
    )
    yield tel
    init = initial_state(settings, tel)
    yield init
    try:
        fwd = forward_pass(settings, tel, init)
    except np.linalg.LinAlgError as err:
        raise np.linalg.LinAlgError(f"forward EKF pass: {err}{likely_keys(settings, err)}") from err
    finite_or_fail(fwd, "forward EKF pass", settings)
    try:  # from the forward priors, before the smoother takes their memory
        lag = estimate_lag(settings, tel, fwd, forward_pass)
    except np.linalg.LinAlgError as err:
        raise np.linalg.LinAlgError(f"IMU lag estimate (forward pass re-run over the impact): {err}") from err
    yield fwd
    try:  # the gains and smoothed covariances take the memory of the transitions and the priors
        sp = rts_smooth(fwd.forward, layout_for(len(tel.triads)), overwrite_F=True, overwrite_prior=True)
    except np.linalg.LinAlgError as err:
        raise np.linalg.LinAlgError(f"RTS smoother: {err}{likely_keys(settings, err)}") from err
    gone = np.empty((0, *sp.G.shape[1:]))  # F is G and P_prior is P_s now: unreadable
    fwd = replace(fwd, forward=replace(fwd.forward, F=gone, P_prior=gone))
    smo = FilterStage("smoothed", sp.t, sp.x, sp.P, smoothed=sp)
    del sp
    finite_or_fail(smo, "RTS smoother", settings, fwd)
    yield smo
    st = stroke_stage(fwd, smo, lander, surface, tel.events, np.random.default_rng(seed))
    # the gains served the restitution's cross-covariance: the result keeps no G (memory, as F above)
    smo = replace(smo, smoothed=replace(smo.smoothed, G=gone))
    yield st
    yield DropResult(tel, init, fwd, smo, st, summarize(settings, tel, fwd, smo, st, lag))


def finite_or_fail(stage: FilterStage, what: str, settings: DropSettings, fwd: FilterStage | None = None) -> None:
    """Raise :class:`numpy.linalg.LinAlgError` (the runner's numerical failure, exit 4) when the
    ``stage``'s state or covariance is not finite, naming the stage, the first bad step and time [s]
    and the sensor whose innovations blew up first (the likely culprit: its file's columns)."""
    bad = ~(finite_steps(stage.x) & finite_steps(stage.P))
    if not bad.any():
        return
    k = int(np.flatnonzero(bad)[0])
    fp = (fwd or stage).forward
    worst = ""
    if fp is not None:
        first = []
        for name, ih in fp.innovations.items():
            big = np.flatnonzero(~np.isfinite(ih.nis) | (ih.nis > 1e3))
            if big.size:
                first.append((float(ih.t[big[0]]), name))
        if first:
            t0, name = min(first)
            worst = f"; the first sensor far off the filter (NIS > 1000) is {name!r} at t = {t0:.4f} s"
    raise np.linalg.LinAlgError(
        f"{what}: state or covariance not finite from step {k} (t = {stage.t[k]:.4f} s){worst}; "
        f"check the sensor axes, units and the settings in {settings.path}{likely_keys(settings, Exception())}"
    )


def likely_keys(settings: DropSettings, err: Exception) -> str:
    """The scenario settings behind a numerical failure: those of the error-state components the
    error names (``CovarianceError.components``), and any σ set to 0 (an error declared absent)."""
    cfg = settings
    keys = []
    for c in getattr(err, "components", ()):
        key = rl.error_state_key(int(c))
        if key not in keys:
            keys.append(key)
    zero = [
        name
        for name, v in (
            ("[sensors.gyro] bias_dps", cfg.gyro.bias_dps),
            ("[sensors.gyro] scale", cfg.gyro.scale),
            ("[sensors.gyro] misalignment_deg", cfg.gyro.misalignment_deg),
            ("[sensors.accelerometer] bias_g", cfg.accelerometer.bias_g),
            ("[filter] q_accel", cfg.filter.q_accel),
            ("[filter] q_angular", cfg.filter.q_angular),
        )
        if v == 0.0
    ]
    out = ""
    if keys:
        out += f"; likely scenario setting: {', '.join(keys)}"
    if zero:
        out += f"; set to 0 in {settings.path}: {', '.join(zero)}"
    return out


def run_droptest(settings: DropSettings, paths: dict[str, Path], seed: int = 0) -> DropResult:
    """Run :func:`reconstruct` to the end without observers and return the :class:`DropResult`."""
    result = None
    for stage in reconstruct(settings, paths, seed):
        result = stage
    assert isinstance(result, DropResult)
    return result


def summarize(
    settings: DropSettings,
    tel: DropTelemetry,
    fwd: FilterStage,
    smo: FilterStage,
    st: StrokeStage,
    lag: LagEstimate | None,
) -> dict:
    """Key numbers of the reconstruction of a run with ``settings`` (SI units; no truth involved);
    ``lag`` the IMU lag against the ranging (:func:`~.physics.estimate_lag` of the forward pass,
    taken before the smoother consumed its priors; None without ranging guns)."""
    ms = st.max
    fp = fwd.forward
    innov = {}
    for name, ih in fp.innovations.items():
        if not ih.t.size:
            continue
        dof = ih.y.shape[1]
        nis = ih.nis
        sig = np.sqrt(np.einsum("nii->ni", ih.S))
        inside = np.mean(np.abs(ih.y) <= 3.0 * sig)
        # whiteness of the normalised innovations y/√S (S varies by orders of magnitude at impact)
        yn = ih.y / sig
        white = {}
        if yn.shape[0] > 40:
            acf, band, frac = whiteness(yn, 20)
            white = {
                "whiteness_fraction_outside_95": frac,
                "acf_lag1_max": float(np.max(np.abs(acf[1]))),
                "whiteness_band": band,
            }
        innov[name] = {
            **white,
            "count": int(ih.t.size),
            "dof": dof,
            "mean_nis": float(np.mean(nis)),
            "fraction_inside_3sigma": float(inside),
            "rejected": int((~ih.accepted).sum()),
        }
    cov_stats = covariance_stats(smo.P)  # once: the summary's numbers and the health check
    eig_min = float(np.min(cov_stats[2]))
    sym = float(np.max(cov_stats[0]))
    # data ending inside the contact: its outputs are undefined, never a number
    cc = contact_completeness(
        tel,
        smo.t,
        smo.x[:, rl.SV],
        st.surface.normal,
        float(ms.time),
        contact_end(smo.t, st.contact, st.restitution_index[1]),
        float((st.smoothed.distance[-1] - ms.distance) / max(ms.sigma, 1e-9)),
    )
    undefined = {} if cc.complete else {"undefined": cc.reason, "data_end_s": cc.t_data_end}
    out = {
        "scenario": settings.name,
        "mode": settings.filter.mode,
        "steps": int(tel.t.size),
        "filter_rate_hz": float(1.0 / np.median(np.diff(tel.t))),
        "group_delay_s": tel.group_delay_s,
        "time_shifts_s": {k: float(v) for k, v in tel.time_shifts_s.items()},
        # every stream's shift with what it is made of (the events file's tags are used as written)
        "time_shifts": {
            stream: {"total_s": float(sum(causes.values())), "causes": {c: float(v) for c, v in causes.items()}}
            for stream, causes in tel.time_shift_causes.items()
        },
        "events": tel.events,
        "max_stroke": {
            "time_s": float(ms.time),
            "distance_m": float(ms.distance),
            "sigma_m": float(ms.sigma),
            "sampled_sigma_m": st.sampled_sigma,
            "sampled_mean_m": st.sampled_mean,
            "vertex": int(ms.vertex),
            "faces": [int(f) for f in ms.faces],
            "point_spf_m": ms.point_I,
            "full_stroke": bool(ms.full_stroke),
            "possible_full_stroke": bool(ms.possible_full_stroke),
        },
        "restitution": {
            "e": st.restitution[0],
            "sigma": st.restitution[1],
            "sigma_estimation": st.restitution_sigma_estimation,
            "sigma_definition": st.restitution_sigma_definition,
            "definitions": dict(st.restitution_definitions),
            "definition": RESTITUTION_DEFINITION,
            "times_s": [float(smo.t[k]) for k in st.restitution_index] if min(st.restitution_index) >= 0 else None,
        },
        "contact": {
            "start_s": float(smo.t[st.contact[0]]) if st.contact[0] >= 0 else None,
            "end_s": float(smo.t[st.contact[1]]) if st.contact[1] >= 0 else None,
        },
        "innovations": innov,
        "covariance": {"min_eigenvalue": eig_min, "max_asymmetry": sym, "positive_definite": eig_min > 0},
        "degradations": [{"time_s": t, "level": lvl, "text": txt} for t, lvl, txt in tel.degradations],
        "health": drop_health(
            tel,
            fwd,
            smo,
            st,
            cov_stats,
            settings=settings,
            completeness=cc,
            lag=lag,
        ),
    }
    if not cc.complete:
        out["restitution"].update(
            {"e": None, "sigma": None, "sigma_estimation": None, "sigma_definition": None, "times_s": None, **undefined}
        )
        out["contact"]["end_s"] = None
        if not cc.max_stroke_defined:
            out["max_stroke"].update(
                {
                    k: None
                    for k in ("time_s", "distance_m", "sigma_m", "sampled_sigma_m", "sampled_mean_m", "point_spf_m")
                }
            )
            out["max_stroke"].update(undefined)
    return out


# ---------------------------------------------------------------------------------------------
# scoring against truth (synthetic scenarios only; the reconstruction above never sees it)
# ---------------------------------------------------------------------------------------------


def truth_on_grid(truth: dict, t: np.ndarray) -> dict[str, np.ndarray]:
    """Truth interpolated to times ``t`` (n,) [s]: p_I, v_I (n,3), q_I_B (n,4, normalised lerp),
    w_B (n,3), a_ng_I (n,3). ``truth`` is the dict of :func:`droptest_synthetic.load_truth`."""
    tt = truth["t"]

    def lin(a):
        return interp_rows(t, tt, a)

    q = truth["q_I_B"].copy()
    q[1:] *= np.sign(np.sum(q[1:] * q[:-1], axis=1))[:, None].cumprod(axis=0)  # continuous sign
    return {
        "p_I": lin(truth["p_I"]),
        "v_I": lin(truth["v_I"]),
        "q_I_B": quat_normalize(lin(q)),
        "w_B": lin(truth["w_B"]),
        "a_ng_I": lin(truth["a_ng_I"]),
    }


def truth_stroke(truth: dict, lander: LanderModel, surface: Surface) -> tuple[np.ndarray, float, float]:
    """Truth stroke history (n_truth,) [m], its minimum after release [m] and the time [s]."""
    zeros = np.zeros((truth["t"].size, 6, 6))
    h = stroke_history(
        np.asarray(lander.body.vertices, float),
        truth["p_I"],
        truth["q_I_B"],
        zeros,
        surface,
        faces_B=np.asarray(lander.body.faces),
    )
    m = truth["t"] >= 0.0
    k = int(np.flatnonzero(m)[np.argmin(h.distance[m])])
    return h.distance, float(h.distance[k]), float(truth["t"][k])


def score(result: DropResult, truth: dict) -> dict:
    """Accuracy and consistency of a reconstruction against the synthetic truth.

    Returns max-stroke error and whether the truth lies inside the reported 3σ, pose errors,
    NEES of the smoothed pose (6 dof) averaged over the run with its χ² band for one run,
    restitution error. Truth values come from ``truth.npz``; nothing here feeds back.
    """
    from workbench.core.rotation import attitude_error
    from workbench.estimation.consistency import anees_bounds, nees

    st = result.stroke
    smo = result.smoothed
    tg = truth_on_grid(truth, smo.t)
    _, d_true, t_true = truth_stroke(truth, st.lander, st.surface)
    ms = st.max
    # error-state convention of the filter: truth = estimate ⊞ δ (δp = p_true − p_est, and
    # q_true = q_est ⊗ exp(δθ)); the signs matter for the position–attitude cross-covariance
    err_p = tg["p_I"] - smo.x[:, rl.SP]
    err_th = attitude_error(smo.x[:, rl.SQ], tg["q_I_B"])
    e6 = np.concatenate([err_p, err_th], axis=1)
    nees6 = nees(e6, rl.pose_covariance(smo.P))
    lo, hi = anees_bounds(6, smo.t.size)  # band of a time average if steps were independent
    # truth restitution by the primary definition (extremes of v_n) on the truth history, and at the
    # instants the bags physically touch and leave (total bag force > 1 N: the truth simulator's
    # events), a definition the IMU cannot see; the reported σ carries a definition term for that
    n = st.surface.normal
    ev = truth["events"]
    e_true = np.nan
    if "first_contact" in ev and "rebound" in ev:
        vb = np.interp(ev["first_contact"], truth["t"], truth["v_I"] @ n)
        va = np.interp(ev["rebound"], truth["t"], truth["v_I"] @ n)
        e_true = float(-va / vb) if va > 0.0 else np.nan  # no rebound: undefined
    after = ev.get("bungee_cut", 0.0)
    rd_true = restitution_definitions(truth["t"], truth["v_I"], truth["a_ng_I"], n, after, gravity=GRAVITY)
    e_est, s_e = st.restitution
    e_prim = rd_true.primary
    # a restitution the summary calls undefined (the data end or break inside the contact) is not judged
    reported = (result.summary or {}).get("restitution", {}).get("e", e_est) is not None
    sig_p = np.sqrt(np.einsum("nii->ni", smo.P[:, rl.EP, rl.EP]))
    return {
        "max_stroke_truth_m": d_true,
        "max_stroke_truth_time_s": t_true,
        "max_stroke_error_m": float(ms.distance - d_true),  # estimate − truth
        "max_stroke_inside_3sigma": bool(abs(ms.distance - d_true) <= 3.0 * ms.sigma),
        "max_stroke_error_over_sigma": float((ms.distance - d_true) / ms.sigma),
        "position_error_max_m": float(np.max(np.linalg.norm(err_p, axis=1))),
        "position_error_at_max_stroke_m": (-err_p[ms.index]).tolist(),  # estimate − truth
        "position_error_over_sigma_max": float(np.max(np.abs(err_p / sig_p))),
        "attitude_error_max_deg": float(np.degrees(np.max(np.linalg.norm(err_th, axis=1)))),
        "nees_pose_mean": float(np.mean(nees6)),
        "nees_pose_band_one_run": [lo, hi],
        "restitution_truth": e_prim,
        "restitution_error": float(e_est - e_prim),
        "restitution_error_over_sigma": float((e_est - e_prim) / s_e),
        "restitution_inside_3sigma": bool(abs(e_est - e_prim) <= 3.0 * s_e),
        "restitution_truth_touch_leave": e_true,
        "restitution_error_touch_leave": float(e_est - e_true),
        "restitution_truth_definitions": dict(rd_true.values),
        "full_stroke_truth": bool(np.max(truth["body_penetration"]) > 0.0),
        # the headline numbers against the truth (estimate − truth, the run's own 1σ), judged by the
        # runner (``calibration.finish_health``: outside ±3σ is an ERROR)
        "headline": [
            {
                "name": "max_stroke",
                "what": "max stroke",
                "error": float(ms.distance - d_true),
                "sigma": float(ms.sigma),
                "unit": "m",
            },
            *(
                [
                    {
                        "name": "restitution",
                        "what": "coefficient of restitution",
                        "error": float(e_est - e_prim),
                        "sigma": float(s_e),
                        "unit": "",
                    }
                ]
                if np.isfinite(e_est) and np.isfinite(e_prim) and np.isfinite(s_e) and s_e > 0.0 and reported
                else []
            ),
        ],
    }


def time_shift_lines(summary: dict) -> list[str]:
    """The scorecard's table of the time shifts taken off each stream's tags, with their causes
    (``summary["time_shifts"]``; a summary without it: the totals of ``time_shifts_s``)."""
    shifts = summary.get("time_shifts") or {
        k: {"total_s": v, "causes": {}} for k, v in summary.get("time_shifts_s", {}).items()
    }
    if not shifts:
        return []
    lines = ["| stream | time shift taken off its tags | made of |", "|---|---|---|"]
    for stream, sh in shifts.items():
        parts = "; ".join(f"{c}: {v * 1e3:.3f} ms" for c, v in sh["causes"].items()) or "—"
        lines.append(f"| {stream} | {sh['total_s'] * 1e3:.3f} ms | {parts} |")
    lines += ["| events | 0 (tags used as written) | — |", ""]
    return lines


def scorecard_markdown(summary: dict) -> str:
    """The run's scorecard as markdown (for ``/report`` in the recording and for ``inspect``)."""
    ms = summary["max_stroke"]
    e = summary["restitution"]
    lines = [
        f"# Drop test `{summary['scenario']}` — scorecard",
        "",
        f"Filter: REDLand EKF ({summary['mode']} mode) + RTS smoother, {summary['steps']} steps at "
        f"{summary['filter_rate_hz']:.0f} Hz.",
        "",
        *time_shift_lines(summary),
        "| quantity | value |",
        "|---|---|",
        (
            f"| max stroke | **{ms['distance_m']:.3f} m ± {ms['sigma_m']:.3f} m (1σ)** at t = {ms['time_s']:.3f} s |"
            if sc.is_defined(ms["distance_m"])
            else f"| max stroke | **undefined**: {ms.get('undefined', 'not determined')} |"
        ),
        "| 1σ check by posterior sampling | "
        + (f"{ms['sampled_sigma_m']:.3f} m |" if sc.is_defined(ms["sampled_sigma_m"]) else "undefined |"),
        f"| closest vertex / faces | {ms['vertex']} / {ms['faces']} |",
        f"| full stroke | {'**YES**' if ms['full_stroke'] else 'no'}"
        f"{' (within 3σ: possible)' if ms['possible_full_stroke'] and not ms['full_stroke'] else ''} |",
        "| coefficient of restitution | "
        + (
            f"{e['e']:.3f} ± {e['sigma']:.3f} (1σ: estimation {sc.num(e.get('sigma_estimation'), digits=2)}, "
            f"definition {sc.num(e.get('sigma_definition'), digits=2)}, in quadrature)"
            + (
                f"; v_n read at t = {e['times_s'][0]:.3f} s (approaching) and {e['times_s'][1]:.3f} s (leaving) |"
                if e.get("times_s")
                else " |"
            )
            if sc.is_defined(e["e"])
            else f"**undefined**: {e['undefined']} |"
            if e.get("undefined")
            else f"{NO_REBOUND} |"
        ),
        f"| covariance | symmetric (max asym {summary['covariance']['max_asymmetry']:.1e}), "
        f"min eigenvalue {summary['covariance']['min_eigenvalue']:.2e} |",
    ]
    if "definition" in e:
        lines += ["", f"Restitution definition: {e['definition']}."]
    if "truth" in summary:
        tr = summary["truth"]
        lines += [
            "",
            "## Against truth (synthetic scenario)",
            "",
            "| quantity | value |",
            "|---|---|",
            f"| truth max stroke | {tr['max_stroke_truth_m']:.3f} m at t = {tr['max_stroke_truth_time_s']:.3f} s |",
            f"| max-stroke error | {tr['max_stroke_error_m'] * 100:+.1f} cm = "
            f"{tr['max_stroke_error_over_sigma']:+.2f} σ "
            f"({'inside' if tr['max_stroke_inside_3sigma'] else '**outside**'} 3σ) |",
            f"| max position error | {tr['position_error_max_m']:.3f} m "
            f"(max {tr['position_error_over_sigma_max']:.1f} σ per axis) |",
            f"| max attitude error | {tr['attitude_error_max_deg']:.2f} deg |",
            f"| smoothed pose NEES (6 dof, mean over run) | {tr['nees_pose_mean']:.2f} |",
            "| restitution truth (same definition) / error | "
            + (
                f"{tr['restitution_truth']:.3f} / {tr['restitution_error']:+.4f}"
                + (
                    f" = {tr['restitution_error_over_sigma']:+.2f} σ "
                    f"({'inside' if tr['restitution_inside_3sigma'] else '**outside**'} 3σ) |"
                    if sc.is_defined(tr.get("restitution_error_over_sigma"))
                    else " |"
                )
                if sc.is_defined(tr["restitution_truth"]) and sc.is_defined(tr["restitution_error"])
                else f"{NO_REBOUND} |"
            ),
            *(
                [
                    "| restitution truth at bags touch / leave (another definition) / error | "
                    + (
                        f"{tr['restitution_truth_touch_leave']:.3f} / {tr['restitution_error_touch_leave']:+.4f} |"
                        if sc.is_defined(tr["restitution_truth_touch_leave"])
                        and sc.is_defined(tr["restitution_error_touch_leave"])
                        else f"{NO_REBOUND} |"
                    )
                ]
                if "restitution_truth_touch_leave" in tr
                else []
            ),
            f"| truth full stroke | {'yes' if tr['full_stroke_truth'] else 'no'} |",
        ]
    lines += [
        "",
        "## Innovations (forward pass)",
        "",
        "| sensor | samples | mean NIS (dof) | inside ±3σ | gated | whiteness: ACF lags 1–20 outside 95 % band"
        " (white ≈ 5 %) | max lag-1 ACF |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, d in summary["innovations"].items():
        wf = d.get("whiteness_fraction_outside_95")
        lines.append(
            f"| {name} | {d['count']} | {d['mean_nis']:.2f} ({d['dof']}) | "
            f"{100 * d['fraction_inside_3sigma']:.1f} % | {d['rejected']} | "
            + (f"{100 * wf:.0f} % | {d['acf_lag1_max']:.2f} |" if wf is not None else "– | – |")
        )
    if summary["degradations"]:
        lines += ["", "## Degradations", ""]
        lines += [f"- t = {d['time_s']:.3f} s [{d['level']}] {d['text']}" for d in summary["degradations"]]
    else:
        lines += ["", "No telemetry degradations (no saturation, gaps or dead channels)."]
    if "health" in summary:
        lines += ["", health_markdown(summary["health"]).rstrip()]
    return "\n".join(lines) + "\n"
