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
   odometer / radar-gun ranges; process noise raised on rapid acceleration changes.
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

import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from workbench.core.bodies import G0
from workbench.core.interpolation import interp_rows
from workbench.core.rotation import quat_conjugate, quat_normalize, quat_rotate, triad, triad_covariance
from workbench.estimation.consistency import whiteness
from workbench.estimation.ekf import ErrorStateLayout, ForwardPass, Measurement, run_filter
from workbench.estimation.smoother import SmoothedPass, rts_smooth
from workbench.io.scenario import Scenario, ScenarioError
from workbench.io.telemetry import Telemetry, read_events, read_telemetry
from workbench.problems.droptest import model as rl
from workbench.problems.droptest.lander import LanderModel, load_lander
from workbench.problems.droptest.sensors import RangingSpec, acquisition_group_delay
from workbench.problems.droptest.stroke import (
    MaxStroke,
    StrokeHistory,
    max_stroke,
    restitution,
    sampled_stroke_sigma,
    stroke_history,
)
from workbench.problems.droptest.surface import Surface, ramp_surface

__all__ = [
    "DropTelemetry",
    "InitialState",
    "FilterStage",
    "StrokeStage",
    "DropResult",
    "telemetry_paths",
    "reconstruct",
    "run_droptest",
]

GRAVITY = np.array([0.0, 0.0, -G0])


def layout_for(n_triads: int) -> ErrorStateLayout:
    """Error-state layout of the REDLand filter with ``n_triads`` accelerometer bias blocks."""
    return ErrorStateLayout(rl.sizes(n_triads)[0], rl.QUAT_BLOCKS)


# ---------------------------------------------------------------------------------------------
# stage results
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DropTelemetry:
    """Validated telemetry on the filter's time grid.

    ``t`` (n,) [s from release], already shifted back by ``group_delay_s``; ``f_B`` (n, n_triads, 3)
    triad specific forces [m/s², body] in the order of ``triads``; ``f_valid`` (n, n_triads) bool;
    ``w_B`` (n, 3) gyro rates [rad/s, body]; ``w_valid`` (n,) bool; ``hanging`` (n,) bool (before
    the release event); ``events`` name -> time [s]; ``degradations`` human-readable list of
    what was dropped or bridged and why; ``raw`` the files as read (for ``/sensors``).
    ``jerk`` (n,) measured jerk indicator [m/s³] that raises the process noise; ``counts`` the IMU
    samples averaged into each step, per triad (n, n_triads) and for the gyro (n,); ``rate_hz`` the
    filter rate actually used (a whole number of IMU samples per step).
    """

    t: np.ndarray
    f_B: np.ndarray
    f_valid: np.ndarray
    w_B: np.ndarray
    w_valid: np.ndarray
    hanging: np.ndarray
    triads: tuple[str, ...]
    lever_arms_B: np.ndarray
    events: dict[str, float]
    setup: dict
    group_delay_s: float
    degradations: tuple[tuple[float, str, str], ...]
    imu: Telemetry
    attitude: Telemetry
    ranging: Telemetry | None
    jerk: np.ndarray
    counts: tuple[np.ndarray, np.ndarray]
    rate_hz: float


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
    error covariance; ``forward`` the full :class:`ForwardPass` (priors, innovations) on the
    forward stage; ``smoothed`` the :class:`SmoothedPass` on the smoothed stage; ``q_accel`` and
    ``q_angular`` (n,) the process-noise PSDs used at each step."""

    name: str
    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    forward: ForwardPass | None = None
    smoothed: SmoothedPass | None = None
    q_accel: np.ndarray | None = None
    q_angular: np.ndarray | None = None


@dataclass(frozen=True)
class StrokeStage:
    """Stroke of the smoothed (and forward) pose against the ramp.

    ``smoothed``/``forward`` :class:`StrokeHistory` (n steps); ``max`` the maximum-stroke event;
    ``sampled_sigma`` 1σ at max stroke from 4000 posterior samples (check of the linearisation);
    ``restitution`` (e, σ_e) from the ramp-normal CM velocity before/after the impact;
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


@dataclass(frozen=True)
class DropResult:
    """Everything the reconstruction produced, and ``summary`` (JSON-ready numbers)."""

    telemetry: DropTelemetry
    initial: InitialState
    forward: FilterStage
    smoothed: FilterStage
    stroke: StrokeStage
    summary: dict


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------


def telemetry_paths(scenario: Scenario) -> dict[str, Path]:
    """Telemetry files named by the scenario's ``[telemetry]`` table (relative to the file)."""
    paths = {}
    for key in ("imu", "attitude_3dm", "events", "setup"):
        paths[key] = scenario.path_of(f"telemetry.{key}")
    if scenario.has("telemetry.ranging"):
        paths["ranging"] = scenario.path_of("telemetry.ranging")
    return paths


def _read_setup(path: Path) -> dict:
    try:
        with open(path, "rb") as f:
            d = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise ScenarioError(path, None, f"cannot read the setup file: {err}") from err
    required = ["hanging.position_m", "hanging.position_sigma_m"]
    if "bungee" in d:  # the test plan is optional, but complete when given (dynamic mode, odometer)
        required += [
            f"bungee.{k}" for k in ("anchor_m", "rest_length_m", "coefficients", "count", "attach_body_m", "mass_kg")
        ]
    for key in required:
        a, b = key.split(".")
        if not isinstance(d.get(a), dict) or b not in d[a]:
            raise ScenarioError(path, key, "missing")
    return d


def _degrade(log: list, t: float, level: str, text: str) -> None:
    log.append((float(t), level, text))


def load_drop_telemetry(scenario: Scenario, paths: dict[str, Path], lander: LanderModel) -> DropTelemetry:
    """Read and validate the drop-test telemetry; resample to the filter rate (see DropTelemetry)."""
    g = scenario.get
    triads = tuple(g("sensors.accelerometer.triads", ["BP", "PYBP", "PXBP", "MXBP"], kind="list"))
    fs_acc = g("sensors.accelerometer.full_scale_g", 2000.0, kind="float") * G0
    fs_gyr = np.radians(g("sensors.gyro.full_scale_dps", 1000.0, kind="float"))
    required = {f"{n}.{a}": "acceleration" for n in triads for a in "xyz"}
    required.update({f"gyro.{a}": "angular_rate" for a in "xyz"})
    sat = {k: (0.999 * fs_acc if k.split(".")[0] != "gyro" else 0.999 * fs_gyr) for k in required}
    imu = read_telemetry(paths["imu"], required=required, saturation=sat)
    att = read_telemetry(
        paths["attitude_3dm"], required={f"{v}.{a}": "dimensionless" for v in ("up", "mag") for a in "xyz"}
    )
    ev_list = read_events(paths["events"])
    att_log: list[tuple[float, str, str]] = []
    for v in ("up", "mag"):
        norms = np.linalg.norm(att.stack([f"{v}.x", f"{v}.y", f"{v}.z"]), axis=1)
        if np.any(np.abs(norms - 1.0) > 0.05):
            k = int(np.argmax(np.abs(norms - 1.0)))
            att_log.append(
                (
                    float(att.time[k]),
                    "WARN",
                    f"{paths['attitude_3dm']}: '{v}' vectors are not unit (|v| = {norms.min():.3f}–"
                    f"{norms.max():.3f}, worst at row {k + 1}); only their directions are used",
                )
            )
    events: dict[str, float] = {}
    dup_log: list[tuple[float, str, str]] = []
    for t_e, name in ev_list:
        if name in events:
            dup_log.append(
                (
                    float(t_e),
                    "WARN",
                    f"{paths['events']}: event '{name}' repeated at {t_e:.4f} s; "
                    f"the first, at {events[name]:.4f} s, is used",
                )
            )
            continue
        events[name] = t_e
    if "release" not in events:
        raise ScenarioError(paths["events"], None, "no 'release' event: the reconstruction needs the release time")
    setup = _read_setup(paths["setup"])
    ranging = None
    if "ranging" in paths:
        spec = RangingSpec.from_scenario(scenario)
        req = {"odometer": "length"} if spec.odometer else {}
        for gun in spec.guns:
            req.update({f"{gun}.range": "length", f"{gun}.rate": "velocity"})
        ranging = read_telemetry(paths["ranging"], required=req, sparse=[k for k in req])
    missing = [n for n in triads if n not in lander.instruments]
    if missing:
        raise ScenarioError(
            scenario.path,
            "sensors.accelerometer.triads",
            f"triads {missing} have no lever arm in the lander asset's [instruments]",
        )

    log: list[tuple[float, str, str]] = list(att_log) + dup_log
    n_raw = len(imu)
    f_raw = np.stack([imu.stack([f"{n}.x", f"{n}.y", f"{n}.z"]) for n in triads], axis=1)  # (n,4,3)
    w_raw = imu.stack(["gyro.x", "gyro.y", "gyro.z"])
    f_ok = np.ones((n_raw, len(triads)), bool)
    for j, n in enumerate(triads):
        s = np.zeros(n_raw, bool)
        for a in "xyz":
            s |= imu.saturated[f"{n}.{a}"]
        if s.any():
            f_ok[s, j] = False
            _degrade(
                log,
                imu.time[np.argmax(s)],
                "WARN",
                f"triad {n}: {int(s.sum())} saturated samples (±{fs_acc / G0:g} g) dropped from the filter",
            )
    w_ok = np.ones(n_raw, bool)
    for a in "xyz":
        s = imu.saturated[f"gyro.{a}"]
        if s.any():
            w_ok &= ~s
            _degrade(
                log,
                imu.time[np.argmax(s)],
                "WARN",
                f"gyro.{a}: {int(s.sum())} saturated samples (±{np.degrees(fs_gyr):g} °/s); gyro dropped, "
                "rate carried by the triads' lever arms",
            )
    # dead channels: a channel that does not move while the others see the impact
    moving = imu.time >= events["release"]
    if moving.sum() > 10:
        spread = np.ptp(f_raw[moving], axis=0)  # (4,3)
        ref = np.median(spread)
        for j, n in enumerate(triads):
            dead_axes = [a for i, a in enumerate("xyz") if spread[j, i] < 1e-3 * max(ref, 1.0)]
            if dead_axes:
                f_ok[:, j] = False
                _degrade(
                    log,
                    events["release"],
                    "ERROR",
                    f"triad {n}: channel(s) {', '.join(dead_axes)} dead (no variation after release): "
                    "triad excluded from the reconstruction",
                )
        if not f_ok.any():
            raise ScenarioError(paths["imu"], None, "no usable accelerometer triad (all dead)")
    for gap in imu.gaps:
        _degrade(
            log,
            gap.start_s,
            "WARN",
            f"IMU gap {gap.start_s:.4f}–{gap.end_s:.4f} s ({gap.duration_s * 1e3:.1f} ms, row {gap.row}): "
            "bridged by propagation, covariance grows",
        )

    # average down to the filter rate (boxcar of k samples, grouped on the uniform sample grid)
    rate_req = g("filter.rate_hz", 1000.0, kind="float")
    dt_raw = float(np.median(np.diff(imu.time)))
    k = max(1, int(round(1.0 / (rate_req * dt_raw))))
    rate = 1.0 / (k * dt_raw)  # the grid actually used: a whole number k of IMU samples per step
    slot = np.floor((imu.time - imu.time[0]) / (k * dt_raw) + 1e-6).astype(int)
    starts = np.flatnonzero(np.r_[True, np.diff(slot) != 0])
    counts = np.diff(np.r_[starts, n_raw])

    def avg(x, ok):
        okf = ok.astype(float)
        num = np.add.reduceat(x * okf[..., None], starts, axis=0)
        den = np.add.reduceat(okf, starts, axis=0)
        return num / np.maximum(den, 1.0)[..., None], den

    t = np.add.reduceat(imu.time, starts) / counts
    f_B, f_cnt = avg(f_raw, f_ok)
    w_B, w_cnt = avg(w_raw, w_ok)
    cutoff = g("sensors.acquisition.filter_cutoff_hz", 500.0, kind="float")
    order = g("sensors.acquisition.filter_order", 4, kind="int")
    delay = acquisition_group_delay(cutoff, order)
    t = t - delay
    hanging = t < events["release"]

    # measured jerk indicator (centred difference of 10 ms means of the mean triad force)
    fbar = np.where(f_cnt[..., None] > 0, f_B, np.nan)
    with np.errstate(invalid="ignore"):
        fbar = np.nanmean(fbar, axis=1)
    ok_rows = np.flatnonzero(np.all(np.isfinite(fbar), axis=1))
    if ok_rows.size:  # slots with no valid triad: hold the last valid mean (no artificial jerk spike)
        fill = ok_rows[np.clip(np.searchsorted(ok_rows, np.arange(fbar.shape[0]), side="right") - 1, 0, None)]
        fbar = fbar[fill]
    L = max(1, int(round(0.010 * rate)))
    ker = np.ones(L) / L
    sm = np.stack([np.convolve(np.nan_to_num(fbar[:, i]), ker, mode="same") for i in range(3)], 1)
    jerk = np.zeros(t.size)
    if t.size > 2 * L:
        d = np.zeros_like(sm)
        d[L:-L] = (sm[2 * L :] - sm[: -2 * L]) / (2 * L / rate)
        jerk = np.linalg.norm(d, axis=1)
    return DropTelemetry(
        t=t,
        f_B=f_B,
        f_valid=f_cnt > 0,
        w_B=w_B,
        w_valid=w_cnt > 0,
        hanging=hanging,
        triads=triads,
        lever_arms_B=np.array([lander.instruments[n] for n in triads]),
        events=events,
        setup=setup,
        group_delay_s=delay,
        degradations=tuple(sorted(log)),
        imu=imu,
        attitude=att,
        ranging=ranging,
        jerk=jerk,
        counts=(f_cnt.astype(int), w_cnt.astype(int)),
        rate_hz=rate,
    )


# ---------------------------------------------------------------------------------------------
# initial state
# ---------------------------------------------------------------------------------------------


def initial_state(scenario: Scenario, tel: DropTelemetry) -> InitialState:
    """Initial state and covariance at the first filter time (lander hanging at rest).

    The 3DM unit vectors are averaged over the samples before the release event only.
    """
    g = scenario.get
    att = tel.attitude
    hang = att.time < tel.events["release"]  # the 3DM reading is only valid while the lander hangs still
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
    mag_I = g("chamber.magnetic_field_spf", kind="vec3")
    q0 = triad(up_B, mag_B, np.array([0.0, 0.0, 1.0]), mag_I)
    sg = np.radians(g("sensors.attitude_3dm.gravity_sigma_deg", 0.2, kind="float"))
    sm = np.radians(g("sensors.attitude_3dm.magnetic_sigma_deg", 1.0, kind="float"))
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
    P0[rl.EV, rl.EV] = g("filter.velocity_sigma_mps", 0.01, kind="float") ** 2 * np.eye(3)
    P0[rl.EA, rl.EA] = g("filter.accel_sigma_mps2", 0.5, kind="float") ** 2 * np.eye(3)
    P0[rl.ETH, rl.ETH] = P_theta
    P0[rl.EW, rl.EW] = np.radians(g("filter.rate_sigma_dps", 0.5, kind="float")) ** 2 * np.eye(3)
    P0[rl.EAL, rl.EAL] = g("filter.angular_accel_sigma", 2.0, kind="float") ** 2 * np.eye(3)
    # gyro error matrix: scale factors on the diagonal, misalignment [rad] off it (datasheet 1σ)
    s_sc = g("sensors.gyro.scale", 0.01, kind="float")
    s_mis = np.radians(g("sensors.gyro.misalignment_deg", 0.05, kind="float"))
    P0[rl.ES, rl.ES] = np.diag(np.where(np.eye(3).ravel() > 0, s_sc, s_mis) ** 2)
    P0[rl.EBG, rl.EBG] = np.radians(g("sensors.gyro.bias_dps", 0.05, kind="float")) ** 2 * np.eye(3)
    sb = g("sensors.accelerometer.bias_g", 0.005, kind="float") * G0  # residual after zeroing, 1σ
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


def _bungee(setup: dict) -> rl.BungeeModel | None:
    b = setup.get("bungee")
    if not b:
        return None
    return rl.BungeeModel(
        anchor_I=np.asarray(b["anchor_m"], float),
        rest_length=float(b["rest_length_m"]),
        coeffs=tuple(float(c) for c in b["coefficients"]),
        count=float(b["count"]),
        mass=float(b["mass_kg"]),
        attach_B=np.asarray(b["attach_body_m"], float),
    )


def forward_pass(scenario: Scenario, tel: DropTelemetry, init: InitialState, lander: LanderModel) -> FilterStage:
    """Run the REDLand EKF over the telemetry (see module docstring)."""
    g = scenario.get
    mode = g("filter.mode", "kinematic", kind="str")
    if mode not in ("kinematic", "dynamic"):
        raise ScenarioError(scenario.path, "filter.mode", f"must be 'kinematic' or 'dynamic', got {mode!r}")
    bungee = _bungee(tel.setup) if mode == "dynamic" else None
    if mode == "dynamic" and bungee is None:
        raise ScenarioError(scenario.path, "filter.mode", "'dynamic' needs a [bungee] table in the setup file")
    t_rel = tel.events["release"]
    t_cut = tel.events.get("bungee_cut", np.inf)

    rate = tel.rate_hz
    # per-sample noise divided by the number of samples actually averaged into each step
    v_acc = (g("sensors.accelerometer.noise_g", 0.2, kind="float") * G0) ** 2
    v_gyr = np.radians(g("sensors.gyro.noise_dps", 0.4, kind="float")) ** 2
    n_f, n_w = tel.counts
    eye3 = np.eye(3)
    r_zupt = g("filter.hang_zupt_sigma_mps", 0.005, kind="float") ** 2 * np.eye(3)

    # process noise schedule: floor + gain * (measured jerk)^2 * dt (REDLand: raised on rapid
    # acceleration changes); angular jerk scaled by m r / J (forces at ~1 m lever arm)
    q_a0 = g("filter.q_accel", 5.0, kind="float")
    q_w0 = g("filter.q_angular", 20.0, kind="float")
    gain = g("filter.adaptive_gain", 4.0, kind="float")
    dt_nom = 1.0 / rate
    s = gain * tel.jerk**2 * dt_nom
    ratio = lander.mass * 1.0 / float(np.min(np.linalg.eigvalsh(lander.inertia_B)))
    q_accel = q_a0 + s
    q_angular = q_w0 + ratio**2 * s

    def transition(x, t0, t1):
        dt = t1 - t0
        active = bungee is not None and t_rel <= t0 and t1 <= t_cut
        xn, F = rl.propagate(x, dt, GRAVITY, bungee if active else None)
        if bungee is not None:
            to_body = quat_conjugate(xn[rl.SQ])
            if t0 < t_rel <= t1:  # the release rope lets go: a jumps from -g to the bungee pull
                xn[rl.SA] += quat_rotate(to_body, bungee.accel(xn[rl.SP], xn[rl.SQ])[0] + GRAVITY)
            if t0 < t_cut <= t1:  # the hammer hits the nail: the bungee pull vanishes
                xn[rl.SA] -= quat_rotate(to_body, bungee.accel(xn[rl.SP], xn[rl.SQ])[0])
        return xn, F

    def process_noise(x, t0, t1):
        return None  # set per step in adapt_q

    def adapt_q(k, x, P, Q):
        return rl.process_noise(tel.t[k] - tel.t[k - 1], q_accel[k], q_angular[k], n_e)

    triad_memos = [_Memo(lambda x, r=r, j=j: rl.triad_model(x, r, j)) for j, r in enumerate(tel.lever_arms_B)]
    gyro_memo = _Memo(rl.gyro_model)
    n_e = init.P0.shape[0]
    H_zupt = np.zeros((3, n_e))
    H_zupt[:, rl.EV] = np.eye(3)

    ranging = _ranging_measurements(scenario, tel) if tel.ranging is not None else {}

    def measurements_at(k, tk, x_prior):
        out = []
        for j, name in enumerate(tel.triads):
            if tel.f_valid[k, j]:
                m = triad_memos[j]
                out.append(Measurement(name, tel.f_B[k, j], v_acc / n_f[k, j] * eye3, m.h, m.H))
        if tel.w_valid[k]:
            out.append(Measurement("gyro", tel.w_B[k], v_gyr / n_w[k] * eye3, gyro_memo.h, gyro_memo.H))
        if tel.hanging[k]:
            out.append(Measurement("zupt", np.zeros(3), r_zupt, lambda x: x[rl.SV], H_zupt))
        for meas in ranging.get(k, ()):
            out.append(meas)
        return out

    fp = run_filter(
        init.x0,
        init.P0,
        tel.t,
        transition,
        process_noise,
        measurements_at,
        layout_for(len(tel.triads)),
        adapt_q=adapt_q,
    )
    return FilterStage("forward", fp.t, fp.x_post, fp.P_post, forward=fp, q_accel=q_accel, q_angular=q_angular)


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


def _ranging_measurements(scenario: Scenario, tel: DropTelemetry) -> dict[int, list[Measurement]]:
    """Range aiding attached to the nearest filter step and evaluated at its own time tag: the
    odometer (rope length from the sheave to the attachment point, until the cut) and radar-gun
    range / range rate to the reflector. Ranging has no IDDAS filter, so its tags are not shifted."""
    spec = RangingSpec.from_scenario(scenario)
    rt = tel.ranging
    out: dict[int, list[Measurement]] = {}
    t_meas = rt.time
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
        attach = np.asarray(b["attach_body_m"], float)
        s2 = np.array([[spec.odometer_sigma**2]])
        vals = rt.channel("odometer")
        for i in np.flatnonzero(near & np.isfinite(vals)):
            m = _Memo(_at_time(lambda x: rl.range_model(x, anchor, attach), float(off[i])))
            out.setdefault(int(idx[i]), []).append(
                Measurement("odometer", np.array([vals[i]]), s2, m.h, m.H, gate_probability=0.9999)
            )
    r_ref = spec.reflector_B
    for name, G in spec.guns.items():
        if f"{name}.range" not in rt.channels or f"{name}.rate" not in rt.channels:
            raise ScenarioError(
                rt.path, None, f"radar gun {name} configured but no columns '{name}.range', '{name}.rate'"
            )
        zr = rt.channel(f"{name}.range")
        zrr = rt.channel(f"{name}.rate")
        for i in np.flatnonzero(near & (np.isfinite(zr) | np.isfinite(zrr))):  # sparse columns: empty = NaN
            dt_i = float(off[i])
            mr = _Memo(_at_time(lambda x, G=G: rl.range_model(x, G, r_ref), dt_i))
            mrr = _Memo(_at_time(lambda x, G=G: rl.range_rate_model(x, G, r_ref), dt_i))
            lst = out.setdefault(int(idx[i]), [])
            if np.isfinite(zr[i]):
                R_r = np.array([[spec.range_sigma**2]])
                lst.append(Measurement(f"{name}.range", np.array([zr[i]]), R_r, mr.h, mr.H, gate_probability=0.9999))
            if np.isfinite(zrr[i]):
                R_rr = np.array([[spec.rate_sigma**2]])
                lst.append(Measurement(f"{name}.rate", np.array([zrr[i]]), R_rr, mrr.h, mrr.H, gate_probability=0.9999))
    return out


# ---------------------------------------------------------------------------------------------
# stroke
# ---------------------------------------------------------------------------------------------


def _contact_interval(
    t: np.ndarray, a: np.ndarray, after: float, threshold: float = 1.0 * G0, merge_s: float = 0.01
) -> tuple[int, int]:
    """First airbag contact: first interval after ``after`` where |a_ng| > ``threshold`` (the bags
    push), bridging dips shorter than ``merge_s`` (noise). A later separate touch-down (a second
    bounce) is a new contact and is not part of the first impact's restitution."""
    busy = (np.linalg.norm(a, axis=1) > threshold) & (t > after)
    if not busy.any():
        return -1, -1
    idx = np.flatnonzero(busy)
    i0 = int(idx[0])
    i1 = i0
    for j in idx[1:]:
        if t[j] - t[i1] > merge_s:
            break
        i1 = int(j)
    return i0, i1


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
    i0, i1 = _contact_interval(smo.t, smo.x[:, rl.SA], after)
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
    e = (np.nan, np.nan)
    if i0 > 0 and i1 > i0:
        a, b = i0 - 1, min(i1 + 1, smo.t.size - 1)
        P_cross = _smoothed_cross_cov(smo, a, b)
        P_v = smo.P[:, rl.EV, rl.EV]
        v_in, v_out = smo.x[a, rl.SV] @ surface.normal, smo.x[b, rl.SV] @ surface.normal
        if v_in < 0.0 < v_out:  # approaching before, leaving after: a rebound to measure
            e = restitution(smo.t, smo.x[:, rl.SV], P_v, surface.normal, a, b, P_cross=P_cross[rl.EV, rl.EV])
        # otherwise undefined (no rebound, or the detected interval is not an impact): NaN
    return StrokeStage(
        smoothed=hist,
        forward=hist_f,
        max=ms,
        sampled_sigma=float(std[0]),
        sampled_mean=float(mean[0]),
        restitution=(float(e[0]), float(e[1])),
        contact=(i0, i1),
        surface=surface,
        lander=lander,
    )


def _subset(h: StrokeHistory, m: np.ndarray) -> StrokeHistory:
    return StrokeHistory(**{f: getattr(h, f)[m] for f in h.__dataclass_fields__})


def _reindex(ms: MaxStroke, k: int) -> MaxStroke:
    d = {f: getattr(ms, f) for f in ms.__dataclass_fields__}
    d["index"] = k
    return MaxStroke(**d)


def _smoothed_cross_cov(smo: FilterStage, a: int, b: int) -> np.ndarray:
    """Smoothed cross-covariance E[δx_a δx_bᵀ] (N_E, N_E) for a < b: G_a G_{a+1} … G_{b-1} P_s[b]."""
    G = smo.smoothed.G
    M = smo.P[b]
    for k in range(b - 1, a - 1, -1):
        M = G[k] @ M
    return M


# ---------------------------------------------------------------------------------------------
# the pipeline
# ---------------------------------------------------------------------------------------------


def reconstruct(scenario: Scenario, paths: dict[str, Path], seed: int = 0) -> Iterator[object]:
    """Run the drop-test reconstruction; yields the stages in order, the last a :class:`DropResult`.

    ``paths`` maps imu, attitude_3dm, events, setup (and optionally ranging) to files.
    ``seed`` drives only the posterior sampling of the stroke-σ check.
    """
    lander = load_lander(scenario.path_of("vehicle.lander"))
    tel = load_drop_telemetry(scenario, paths, lander)
    rocks = tel.setup.get("rocks")
    surface = ramp_surface(
        angle_deg=scenario.get("chamber.ramp_angle_deg", 60.0, kind="float"),
        nail_depth=scenario.get("chamber.nail_depth_m", 0.3, kind="float"),
        rocks=None
        if not rocks
        else (np.asarray(rocks["centers_m"], float).reshape(-1, 3), np.asarray(rocks["radii_m"], float).reshape(-1)),
    )
    yield tel
    init = initial_state(scenario, tel)
    yield init
    fwd = forward_pass(scenario, tel, init, lander)
    yield fwd
    sp = rts_smooth(fwd.forward, layout_for(len(tel.triads)))
    smo = FilterStage("smoothed", sp.t, sp.x, sp.P, smoothed=sp)
    yield smo
    st = stroke_stage(fwd, smo, lander, surface, tel.events, np.random.default_rng(seed))
    yield st
    yield DropResult(tel, init, fwd, smo, st, summarize(scenario, tel, fwd, smo, st))


def run_droptest(scenario: Scenario, paths: dict[str, Path], seed: int = 0) -> DropResult:
    """Run :func:`reconstruct` to the end without observers and return the :class:`DropResult`."""
    result = None
    for stage in reconstruct(scenario, paths, seed):
        result = stage
    assert isinstance(result, DropResult)
    return result


def summarize(scenario: Scenario, tel: DropTelemetry, fwd: FilterStage, smo: FilterStage, st: StrokeStage) -> dict:
    """Key numbers of the reconstruction (SI units; no truth involved)."""
    ms = st.max
    fp = fwd.forward
    innov = {}
    for name, ih in fp.innovations.items():
        m = ih.present
        if not m.any():
            continue
        dof = ih.y.shape[1]
        nis = ih.nis[m]
        sig = np.sqrt(np.einsum("nii->ni", ih.S[m]))
        inside = np.mean(np.abs(ih.y[m]) <= 3.0 * sig)
        # whiteness of the normalised innovations y/√S (S varies by orders of magnitude at impact)
        yn = ih.y[m] / sig
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
            "count": int(m.sum()),
            "dof": dof,
            "mean_nis": float(np.mean(nis)),
            "fraction_inside_3sigma": float(inside),
            "rejected": int((~ih.accepted[m]).sum()),
        }
    P = smo.P
    eig_min = float(np.min(np.linalg.eigvalsh(P)))
    sym = float(np.max(np.abs(P - np.swapaxes(P, 1, 2))))
    return {
        "scenario": scenario.name,
        "mode": scenario.get("filter.mode", "kinematic", kind="str"),
        "steps": int(tel.t.size),
        "filter_rate_hz": float(1.0 / np.median(np.diff(tel.t))),
        "group_delay_s": tel.group_delay_s,
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
        "restitution": {"e": st.restitution[0], "sigma": st.restitution[1]},
        "contact": {
            "start_s": float(smo.t[st.contact[0]]) if st.contact[0] >= 0 else None,
            "end_s": float(smo.t[st.contact[1]]) if st.contact[1] >= 0 else None,
        },
        "innovations": innov,
        "covariance": {"min_eigenvalue": eig_min, "max_asymmetry": sym, "positive_definite": eig_min > 0},
        "degradations": [{"time_s": t, "level": lvl, "text": txt} for t, lvl, txt in tel.degradations],
    }


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
    # truth restitution from the same normal-velocity definition, at the truth contact interval
    n = st.surface.normal
    ev = truth["events"]
    e_true = np.nan
    if "first_contact" in ev and "rebound" in ev:
        vb = np.interp(ev["first_contact"], truth["t"], truth["v_I"] @ n)
        va = np.interp(ev["rebound"], truth["t"], truth["v_I"] @ n)
        e_true = float(-va / vb) if va > 0.0 else np.nan  # no rebound: undefined
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
        "restitution_truth": e_true,
        "restitution_error": float(st.restitution[0] - e_true),
        "full_stroke_truth": bool(np.max(truth["body_penetration"]) > 0.0),
    }


def scorecard_markdown(summary: dict) -> str:
    """The run's scorecard as markdown (for ``/report`` in the recording and for ``inspect``)."""
    ms = summary["max_stroke"]
    e = summary["restitution"]
    lines = [
        f"# Drop test `{summary['scenario']}` — scorecard",
        "",
        f"Filter: REDLand EKF ({summary['mode']} mode) + RTS smoother, {summary['steps']} steps at "
        f"{summary['filter_rate_hz']:.0f} Hz; acquisition-filter delay "
        f"{summary['group_delay_s'] * 1e3:.2f} ms removed.",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| max stroke | **{ms['distance_m']:.3f} m ± {ms['sigma_m']:.3f} m (1σ)** at t = {ms['time_s']:.3f} s |",
        f"| 1σ check by posterior sampling | {ms['sampled_sigma_m']:.3f} m |",
        f"| closest vertex / faces | {ms['vertex']} / {ms['faces']} |",
        f"| full stroke | {'**YES**' if ms['full_stroke'] else 'no'}"
        f"{' (within 3σ: possible)' if ms['possible_full_stroke'] and not ms['full_stroke'] else ''} |",
        "| coefficient of restitution | "
        + (
            f"{e['e']:.3f} ± {e['sigma']:.3f} (1σ) |"
            if np.isfinite(e["e"])
            else "undefined (no rebound off the ramp) |"
        ),
        f"| covariance | symmetric (max asym {summary['covariance']['max_asymmetry']:.1e}), "
        f"min eigenvalue {summary['covariance']['min_eigenvalue']:.2e} |",
    ]
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
            f"| restitution truth / error | {tr['restitution_truth']:.3f} / {tr['restitution_error']:+.3f} |",
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
    return "\n".join(lines) + "\n"
