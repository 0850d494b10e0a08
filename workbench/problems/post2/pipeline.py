"""The post2 reconstruction: observation files -> EKF forward pass (thesis [R3] Ch. 3.1.1) -> RTS smoother.

Stages (typed results, drawn by ``recording.py``, consumed by tests and benchmarks as they are):

1. :class:`ObservationData` — every observation channel read from its CSV (SI), optionally
   median-smoothed, with its noise covariance per sample from the weights file (R = W⁻¹) or the
   constant σ;
2. :class:`ForwardStage` — the shared :func:`workbench.estimation.ekf.run_filter` over a grid that
   holds every observation time; the transition is :class:`~workbench.problems.post2.model.TrajectoryModel`
   integrated with RK4 and its error-state Jacobian by central differences (a per-state step,
   one batched model call: :func:`~workbench.estimation.ekf.numeric_jacobian_batched`), the
   system noise from each state's process model;
3. :class:`Post2Result` — the RTS-smoothed pass (:func:`workbench.estimation.smoother.rts_smooth`)
   and the summary.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from workbench.core.rotation import attitude_error, quat_from_rotvec, quat_x_along
from workbench.core.smoothing import window_median_at
from workbench.estimation.consistency import chi2_ppf
from workbench.estimation.ekf import ErrorStateLayout, ForwardPass, Measurement, numeric_jacobian_batched, run_filter
from workbench.estimation.health import WARNING, covariance_check, health_report, interval_check, nis_check, notes_check
from workbench.estimation.smoother import SmoothedPass, rts_smooth
from workbench.io.scenario import ScenarioError
from workbench.io.telemetry import TelemetryError, read_telemetry
from workbench.io.units import likely_unit
from workbench.problems.post2 import build, rocket_checks, rocket_results
from workbench.problems.post2 import schedules as sched
from workbench.problems.post2.config import ObservationSpec, Post2Settings
from workbench.problems.post2.model import (
    OBSERVATIONS,
    STATES,
    StateMap,
    TrajectoryModel,
    aero_angles,
    quat_from_aero_angles,
    scurve,
    scurve_inverse,
    scurve_slope,
)

__all__ = [
    "INFORMED_RATIO",
    "Channel",
    "detect_event_times",
    "ObservationData",
    "ForwardStage",
    "Post2Result",
    "Estimator",
    "read_observations",
    "reconstruct",
    "state_history",
    "propagation_only",
]


@dataclass(frozen=True)
class Channel:
    """One observation channel: ``t`` (n,) [s], ``z`` (n, m) SI (after pre-smoothing), ``z_raw``
    (n, m) as read, ``R`` (n, m, m) noise covariance SI, its :class:`ObservationSpec`."""

    spec: ObservationSpec
    t: np.ndarray
    z: np.ndarray
    z_raw: np.ndarray
    R: np.ndarray


#: a parameter whose final posterior 1σ is not below this fraction of its prior 1σ (in the estimated
#: coordinate) is "not informed by the data": what it reports is its prior, whatever its error
INFORMED_RATIO = 0.7


@dataclass(frozen=True)
class ObservationData:
    """Stage 1: the observation channels by name; ``notes``: the readers' warnings (anomalies of the
    files); ``facts``: what a reviewer reads once and is no anomaly (the model running past the data)."""

    channels: dict[str, Channel]
    notes: tuple[str, ...] = ()
    facts: tuple[str, ...] = ()


@dataclass(frozen=True)
class ForwardStage:
    """Stage 2: the EKF forward pass, the events fired [(t [s], name)], and each channel's quantity;
    ``weight_factors`` {channel: (t (n,) [s], factor (n,))} of the channels a ``[schedules]`` window
    touches (W × factor, R / factor, at each sample as applied)."""

    forward: ForwardPass
    events: tuple[tuple[float, str], ...]
    quantities: dict[str, str]
    weight_factors: dict = field(default_factory=dict)

    def residual_sigma(self, name: str) -> np.ndarray:
        """1σ (n, m) of the innovations of channel ``name``: √diag S (negative rounding clipped to 0), SI."""
        S = self.forward.innovations[name].S
        return np.sqrt(np.maximum(np.einsum("nii->ni", S), 0.0))


@dataclass(frozen=True)
class Post2Result:
    """Final stage: grid ``t`` (n,) [s]; ``x``/``P`` the smoothed (or, without the smoother, the
    forward) state (n, n_x) and error covariance (n, n_e, n_e); ``forward`` pass; ``names`` of the
    state blocks; ``channels``; ``summary``; ``smap`` the state map; ``history`` per named quantity
    (physical values and 1σ, see :func:`state_history`) under ``"smoothed"``, ``"forward"`` and, with
    ``[filter] compare_propagation``, ``"propagated"`` (:func:`propagation_only`, 1σ the prior's);
    ``rocket`` the smoothed track in the pad's frame of a flight with a ``[launch]`` pad
    (:class:`~workbench.problems.post2.rocket_results.LocalTrack`; None otherwise);
    ``heading_direction`` (n_e,) the turn about the pad's vertical at the last grid time of a flight
    whose pad heading is untrusted (:meth:`Estimator.pad_rotation`, carried by F; None otherwise)."""

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    forward: ForwardPass
    smoothed: SmoothedPass | None
    smap: StateMap
    channels: dict[str, Channel]
    events: tuple[tuple[float, str], ...]
    history: dict
    summary: dict
    rocket: rocket_results.LocalTrack | None = None
    heading_direction: np.ndarray | None = None

    def phase_index(self) -> np.ndarray:
        """(n,) float: how many events had fired at each grid time (0 before the first, +1 at each)."""
        te = np.array([a for a, _ in self.events], dtype=float)
        return np.searchsorted(te, self.t, side="right").astype(float)

    def body_attitude(self, rows: np.ndarray, planet_rate_rad_s: float = 0.0) -> np.ndarray:
        """q_I_B (k, 4) scalar-last at the grid ``rows`` (k,) of the smoothed state: the attitude block
        (6-DOF) or, 3-DOF, +X_B along the planet-relative velocity v − ω × r (ω = ``planet_rate_rad_s``
        [rad/s] about +Z; zero angle of attack against the co-rotating atmosphere, wind neglected). For
        drawing only: under a parachute the planet's rotation can dominate the inertial velocity."""
        if "attitude" in self.smap:
            return np.array(self.smap.raw(self.x[rows], "attitude"))
        x = self.x[rows]
        p, v = self.smap.raw(x, "position"), self.smap.raw(x, "velocity")
        w = float(planet_rate_rad_s)
        return quat_x_along(v - np.stack([-w * p[..., 1], w * p[..., 0], np.zeros_like(p[..., 0])], axis=-1))

    def tilt_rotation(self, rows: np.ndarray) -> np.ndarray | None:
        """q_B_tilted (k, 4) of an estimated tilt state (``tilt*``, rad: a scalar about Y_B or a
        rotation vector) at the grid ``rows`` (k,) of the smoothed history; None without one."""
        name = next((nm for nm in self.history["smoothed"] if nm == "tilt" or nm.startswith("tilt")), None)
        if name is None:
            return None
        a = np.asarray(self.history["smoothed"][name]["value"], float)[rows]
        rv = np.zeros((a.shape[0], 3))
        if a.shape[1] == 1:
            rv[:, 1] = a[:, 0]
        else:
            rv[:, : min(3, a.shape[1])] = a[:, :3]
        return quat_from_rotvec(rv)


def _weights_R(file: Path, spec: ObservationSpec, t: np.ndarray, wpath: Path, obs_file: str) -> np.ndarray:
    """R (n, m, m) = W⁻¹ from a weights CSV (columns as the observation's, unit ``1`` meaning
    1/SI², held from each row to the next); a weights file that ends before the observations is an error
    located in the problem ``file`` (``obs_file``: the observation file's name, for the message)."""
    d = OBSERVATIONS[spec.quantity]
    wt = read_telemetry(wpath)
    missing = [c for c in d.residual_names if c not in wt.channels]
    if missing:
        raise ScenarioError(file, f"observations.{spec.name}.weights", f"{wpath.name}: no column(s) {missing}")
    if wt.time[0] > t[0] + 1e-9 or wt.time[-1] < t[-1] - 1e-9:
        bad = np.flatnonzero((t < wt.time[0] - 1e-9) | (t > wt.time[-1] + 1e-9))
        raise ScenarioError(
            file,
            f"observations.{spec.name}.weights",
            f"{wpath.name} (column time, rows 1..{wt.time.size}) covers {wt.time[0]:g} .. {wt.time[-1]:g} s but the "
            f"observations run {t[0]:g} .. {t[-1]:g} s: {obs_file} row {bad[0] + 1} ({t[bad[0]]:g} s) has no weight "
            f"({bad.size} such rows): the weights file is shorter than its observations",
        )
    idx = np.clip(np.searchsorted(wt.time, t + 1e-9, side="right") - 1, 0, wt.time.size - 1)
    W = wt.stack(d.residual_names)[idx]
    if np.any(W <= 0):
        raise ScenarioError(file, f"observations.{spec.name}.weights", f"{wpath.name}: weights must be > 0")
    R = np.zeros((t.size, d.size, d.size))
    R[:, np.arange(d.size), np.arange(d.size)] = 1.0 / W
    return R


def _check_gravity_units(path: Path, tel, column: str, cfg: Post2Settings) -> None:
    """Unit plausibility of a gravity-magnitude observation: its median lies between a tenth of and
    1.2 times the surface gravity GM/R² of ``[environment]``; a factor explained by a unit mix-up
    (g ↔ m/s² ...) is a :class:`TelemetryError` naming the file, the column and the likely unit."""
    gm, radius = cfg.environment.gm_m3_s2, cfg.environment.reference_radius_m
    if not gm or not radius:
        return
    g_surf = float(gm) / float(radius) ** 2
    ratio = float(np.median(np.abs(tel.channel(column)))) / g_surf
    if 0.1 <= ratio <= 1.2:
        return
    unit = tel.units[column]
    likely = likely_unit(ratio, unit) or likely_unit(ratio / 0.9, unit)
    why = f"the values look like [{likely}], not [{unit}]" if likely else "wrong unit or body?"
    src = f"[environment] gm_m3_s2 = {float(gm):.6g} / reference_radius_m = {float(radius):.6g}² in {cfg.run.path}"
    if g_surf < 0.1 or g_surf > 300.0:  # no body's surface gravity: the scenario's constants are the suspects
        why = "that is no planet's or moon's surface gravity: GM in km³/s² or the radius in km?"
    raise TelemetryError.single(
        path,
        f"median gravity {ratio:.4g}× the surface gravity {g_surf:.4g} m/s² of {src}: {why}",
        column=f"{column} [{unit}]",
    )


def read_observations(cfg: Post2Settings, telemetry) -> ObservationData:
    """Read every declared observation from ``telemetry`` {name: csv, name + "_weights": csv}; check
    that its times lie inside the reconstruction span; build R; apply the sliding median."""
    out = {}
    notes: list[str] = []
    for spec in cfg.observations:
        d = OBSERVATIONS[spec.quantity]
        path = Path(telemetry[spec.name])
        tel = read_telemetry(path, required={c: _kind(d.file_unit or d.unit) for c in d.components})
        t = np.asarray(tel.time, float)
        # to 1 µs: a time written to a CSV with six decimals may round past the span's end
        outside = np.flatnonzero((t < cfg.t_start - 1e-6) | (t > cfg.t_end + 1e-6))
        if outside.size:
            raise ScenarioError(
                cfg.run.path,
                f"observations.{spec.name}",
                f"{path.name} row {outside[0] + 1} (column time): observation at {t[outside[0]]:g} s is outside "
                f"the data span [{cfg.t_start:g}, {cfg.t_end:g}] s of [model] ({outside.size} such rows)",
            )
        z_raw = tel.stack(d.components)
        z = z_raw
        if spec.quantity == "quaternion":
            norm = np.linalg.norm(z_raw, axis=1)
            bad = np.flatnonzero(np.abs(norm - 1.0) > 1e-3)
            if bad.size:
                raise ScenarioError(
                    cfg.run.path,
                    f"observations.{spec.name}",
                    f"{path.name}: quaternion at {t[bad[0]]:g} s has norm {norm[bad[0]]:.6g}",
                )
            z = z_raw / norm[:, None]
            if spec.median_window > 1:
                raise ScenarioError(cfg.run.path, f"observations.{spec.name}.median_window", "not for a quaternion")
        if spec.sigma is not None:
            R = np.broadcast_to(np.diag(spec.sigma**2), (t.size, d.size, d.size)).copy()
        else:
            R = _weights_R(cfg.run.path, spec, t, Path(telemetry[spec.name + "_weights"]), path.name)
        rows = np.arange(t.size)
        if spec.median_window > 1:  # only medians over a whole window (see _complete_windows)
            rows = rows[_complete_windows(cfg.run.path, spec, path, t.size)]
        if spec.decimate > 1:  # every n-th (pre-smoothed) sample
            rows = rows[:: spec.decimate]
        if spec.median_window > 1:  # the sliding median, at the samples kept
            z = window_median_at(z_raw, spec.median_window, rows)
        else:
            z = z[rows]
        t, z_raw, R = (a[rows] for a in (t, z_raw, R))
        out[spec.name] = Channel(spec, t, z, z_raw, R)
        notes += [*tel.notes, *(f"{path}: gap {g.start_s:g}–{g.end_s:g} s (row {g.row})" for g in tel.gaps)]
        if spec.quantity == "gravity_magnitude" and z.size:
            _check_gravity_units(path, tel, d.components[0], cfg)
    return ObservationData(out, (*notes, *_end_note(cfg, out, telemetry)))


def detect_event_times(cfg: Post2Settings, telemetry) -> tuple[Post2Settings, tuple[str, ...]]:
    """The settings with the time [s] of every event declared ``detect_in`` read from those
    observations' raw files (sensed acceleration; |a| the norm of the file's components, the files'
    samples merged in time): the first rise of |a| by more than ``detect_jump`` [m/s²] between
    consecutive samples after the peak of |a|, at the two samples' midpoint — a parachute's opening
    shock after the entry pulse, read as a user would read it.  Returns (settings, one fact per
    event).  No such rise, or a name that is not an acceleration observation: a located error."""
    events, facts = [], []
    specs = {o.name: o for o in cfg.observations}
    for e in cfg.events:
        if not e.detect_in:
            events.append(e)
            continue
        key = f"events.{e.name}.detect_in"
        ts, mags = [], []
        for name in e.detect_in:
            spec = specs.get(name)
            if spec is None or not spec.quantity.startswith("acceleration_"):
                raise ScenarioError(cfg.run.path, key, f"{name!r} is not a declared sensed-acceleration observation")
            d = OBSERVATIONS[spec.quantity]
            kinds = {c: _kind(d.file_unit or d.unit) for c in d.components}
            tel = read_telemetry(Path(telemetry[name]), required=kinds)
            ts.append(np.asarray(tel.time, float))
            mags.append(np.linalg.norm(np.atleast_2d(tel.stack(d.components)).reshape(len(tel.time), -1), axis=1))
        t, a = np.concatenate(ts), np.concatenate(mags)
        order = np.argsort(t, kind="stable")
        t, a = t[order], a[order]
        files = ", ".join(Path(telemetry[n]).name for n in e.detect_in)
        k0 = int(np.argmax(a)) if a.size else 0
        jump = np.flatnonzero(np.diff(a[k0:]) > e.detect_jump) if a.size else np.array([], int)
        if not jump.size:
            raise ScenarioError(
                cfg.run.path, key,
                f"{files}: no rise of |a| by more than {e.detect_jump:g} m/s² between samples after the peak "
                f"of |a| (at {t[k0] if a.size else float('nan'):g} s): the event's time cannot be read from the data",
            )  # fmt: skip
        k = k0 + int(jump[0])
        tk = 0.5 * (t[k] + t[k + 1])
        if not cfg.t_start < tk < cfg.t_end:
            raise ScenarioError(cfg.run.path, key, f"{files}: the time read, {tk:g} s, is outside [model]'s span")
        events.append(replace(e, value=float(tk)))
        facts.append(
            f"event {e.name} at {tk:.3f} s, read from {files}: |a| rises {a[k + 1] - a[k]:.3g} m/s² between "
            f"{t[k]:g} and {t[k + 1]:g} s"
        )
    if not facts:
        return cfg, ()
    return replace(cfg, events=tuple(events)), tuple(facts)


def _end_note(cfg: Post2Settings, channels: dict[str, Channel], telemetry) -> tuple[str, ...]:
    """A reader's note (a WARNING) when the model runs past ALL the data: the last observation of
    every channel more than three of its own sample steps [s] before ``[model] t_end_s`` (a file cut
    short, or a span longer than the data: the end state is then a prediction).  One channel ending
    early is the design of a phased problem file (each phase its own file) and says nothing."""
    last = [(float(ch.t[-1]), float(np.median(np.diff(ch.t))) if ch.t.size > 1 else 0.0, n)
            for n, ch in channels.items() if ch.t.size]  # fmt: skip
    if not last:
        return ()
    t_last, step, name = max(last)
    if cfg.t_end - t_last <= 3.0 * step:
        return ()
    return (
        f"the model runs {cfg.t_end - t_last:g} s past the data: the last observation ({Path(telemetry[name]).name}) "
        f"is at {t_last:g} s, [model] t_end_s = {cfg.t_end:g} s; the states after it are predicted",
    )


def _complete_windows(file: Path, spec: ObservationSpec, path: Path, n: int) -> slice:
    """The samples (of ``n``) whose sliding-median window of ``spec.median_window`` samples lies
    wholly inside the file: scipy's window at index i spans i − w//2 … i + w − 1 − w//2.  At the
    edges ``mode="nearest"`` pads with copies of the first/last sample; once more than half the
    window is padding the "median" IS that one raw sample, with the raw sensor noise, not the
    smoothed noise the observation's σ describes (post2_huygens: the first drogue sample at
    1171.2 s, raw noise 0.05 m/s², was assimilated at σ = 0.006 m/s² and pulled the drogue drag,
    bias, tilt and wind together, issue #9).  A file shorter than one window is an error located in
    the problem ``file``."""
    w = spec.median_window
    lo, hi = w // 2, n - (w - 1 - w // 2)
    if hi <= lo:
        raise ScenarioError(
            file, f"observations.{spec.name}.median_window",
            f"{path.name} has {n} samples, fewer than one median window of {w}",
        )  # fmt: skip
    return slice(lo, hi)


def _kind(unit: str) -> str:
    return {
        "m/s^2": "acceleration",
        "deg/s": "angular_rate",
        "m": "length",
        "Pa": "pressure",
        "kg/m^3": "density",
        "1": "dimensionless",
        "K": "temperature",
    }[unit]


#: a ``consider`` state's 1σ in the filter pass, relative to its declared σ: held (nearly) at its value
#: so the estimate is the one that takes it as known, its declared σ added afterwards by sensitivity
#: (:func:`consider_covariance`); not zero, so that the smoother's predicted covariance stays invertible
CONSIDER_PASS_SCALE = 1e-3


#: observed quantities that a turn of the flight about the pad's vertical does not change
HEADING_INVARIANT = ("pressure", "acceleration_magnitude")


class Estimator:
    """The EKF set-up of one run (from its :class:`Post2Settings`): state map, error-state layout, the
    model, x0, P0, eps, the process models.  ``transition(x, t0, t1) -> (x1, F, Q)`` advances the
    event phase it keeps."""

    def __init__(self, cfg: Post2Settings):
        self.cfg = cfg
        self.smap = build.state_map(cfg)
        self.layout = ErrorStateLayout(self.smap.n_x, self.smap.quat_blocks)
        self.model = TrajectoryModel(self.smap, cfg.dof, build.environment(cfg), build.vehicle(cfg), build.events(cfg))
        self.x0, self.P0, self.eps, self.mean = self._initial()
        self.consider = np.concatenate(
            [np.arange(self.smap.n_e)[b.se] for n, b in self.smap.blocks.items() if cfg.state(n).process == "consider"]
            or [np.zeros(0, int)]
        )
        self._projector = None
        if self.consider.size:  # Schmidt: no gain on a consider parameter (Simon 2006, Sect. 7.5)
            diag = np.ones(self.smap.n_e)
            diag[self.consider] = 0.0
            self._projector = np.diag(diag)
        self._q_cache: list[tuple] | None = None
        # an untrusted rocket heading ([launch] heading_trusted = false): the rotation about the pad's
        # vertical, added to P0 with the heading's 1σ, carried by F and kept out of the Jacobians of the
        # observations it cannot change (observability-constrained EKF: Huang, Mourikis and
        # Roumeliotis 2010, "Observability-based rules for designing consistent EKF SLAM estimators")
        self.heading_direction: np.ndarray | None = None
        la = cfg.launch
        if la is not None and not la.heading_trusted and {"position", "velocity"} <= set(self.smap.blocks):
            n = self.pad_rotation(self.x0, cfg.t_start)
            self.P0 = self.P0 + math.radians(la.heading_sigma_deg) ** 2 * np.outer(n, n)
            self.heading_direction = n
        # events due at the start apply from it, before its observations (as in the truth simulator;
        # checked only at the first transition they came after the t_start samples, issue #9)
        self.phase = self.model.check_events(self.x0, cfg.t_start, self.model.initial_phase())
        self.phase_log: list[tuple[float, str]] = [(cfg.t_start, nm) for nm in self.phase["fired"]]
        self.weight_log: dict[str, list[tuple[float, float]]] = {}  # schedules: (t, factor) per channel

    def pad_rotation(self, x: np.ndarray, t: float) -> np.ndarray:
        """The error-state direction (n_e,) of turning the flight by 1 rad about the ``[launch]`` pad's
        vertical at ``t`` [s after launch] from the state ``x``: position u × (p − p_pad), the
        planet-relative velocity turned alike, the wind [east, north] turned alike; zero elsewhere.
        Pressure, |specific force| and the dynamics are invariant under it (up to the Coriolis force)."""
        C, p_pad = rocket_results.pad_frame(self.cfg.launch, t, self.model.env.radius_ref, self.model.env.omega)
        u = C[2]
        w_e = np.array([0.0, 0.0, self.model.env.omega])
        b = self.smap.blocks
        p, v = np.asarray(x, float)[b["position"].sx], np.asarray(x, float)[b["velocity"].sx]
        n = np.zeros(self.smap.n_e)
        dp = np.cross(u, p - p_pad)
        n[b["position"].se] = dp
        n[b["velocity"].se] = np.cross(u, v - np.cross(w_e, p)) + np.cross(w_e, dp)
        if "wind" in b:
            w = np.asarray(x, float)[b["wind"].sx]
            n[b["wind"].se] = [-w[1], w[0]]
        return n

    def _initial(self):
        sm, cfg = self.smap, self.cfg
        x0 = np.zeros(sm.n_x)
        sig = np.zeros(sm.n_e)
        eps = np.zeros(sm.n_e)
        for name, b in sm.blocks.items():
            s = cfg.state(name)
            if name == "attitude":
                continue
            val = s.value
            sd = s.sigma
            if b.bounds is not None:
                val = scurve_inverse(val, *b.bounds)
                sd = sd / scurve_slope(val, *b.bounds)
            if s.process == "consider":  # held at its value in the pass; its σ enters by sensitivity
                sd = sd * CONSIDER_PASS_SCALE
            x0[b.sx] = val
            sig[b.se] = sd
            eps[b.se] = s.step
        if "attitude" in sm:
            s = cfg.state("attitude")
            b = sm.blocks["attitude"]
            x0[b.sx] = quat_from_aero_angles(sm.raw(x0, "position"), self.model.v_rel(x0), s.value)
            # body-frame small angles: bank about X_B, α about Y_B, β about Z_B
            sig[b.se] = s.sigma[[2, 0, 1]]
            eps[b.se] = s.step
        mean = x0.copy()
        P0 = np.diag(sig**2)
        if cfg.initial_correlation is not None:  # [initial_correlation]: diag(σ) C diag(σ) over its states
            names, corr = cfg.initial_correlation
            idx = np.concatenate([np.arange(sm.n_e)[sm.blocks[n].se] for n in names])
            P0[np.ix_(idx, idx)] = sig[idx, None] * corr * sig[None, idx]
        return x0, P0, eps, mean

    def q_matrix(self, dt: float, t: float | None = None, h: float | None = None) -> tuple[np.ndarray, dict]:
        """System noise Q (n_e, n_e) of a step dt [s] and the Markov decay factors {name: Φ}; with the
        step's start ``t`` [s] the open ``[schedules]`` windows add their PSD (events: ``self.phase``);
        ``h`` [m]: the vehicle's altitude at the step's start, where a Markov state's stationary 1σ
        follows its ``sigma_profile`` (Q = σ(h)² (1 − Φ²): the variance relaxes towards σ(h)² with
        τ/2, the time-varying Gauss-Markov process; without h the state's ``sigma``)."""
        qd = np.zeros(self.smap.n_e)  # Q is diagonal: its diagonal, block by block
        phis = {}
        for name, i, s, scheduled, var0 in self._q_plan():
            if scheduled and t is not None:  # ---- schedules: late system noise
                qd[i] += sched.extra_psd(self.cfg.schedules, name, i.stop - i.start, t, self.phase["fired"]) * dt
            if s.process == "random_walk":
                qd[i] += s.psd * dt
            elif s.process == "markov":
                phi = math.exp(-dt / s.tau)
                var = var0
                if s.sigma_profile is not None and h is not None:
                    var = np.full(i.stop - i.start, np.interp(h, *s.sigma_profile) ** 2)
                qd[i] = var * (1.0 - phi * phi)
                phis[name] = phi
        return np.diag(qd), phis

    def _q_plan(self) -> list[tuple]:
        """Per state block of :meth:`q_matrix` that can add noise (built once): (name, error slice,
        its StateSpec, whether a ``[schedules]`` window targets it, the Markov stationary variance
        without a profile); a constant state no window targets adds none and is left out."""
        if self._q_cache is None:
            targets = {sc.target_name for sc in self.cfg.schedules if sc.target == "state"}
            plan = []
            for name, b in self.smap.blocks.items():
                s = self.cfg.state(name)
                if s.process not in ("random_walk", "markov") and name not in targets:
                    continue
                var0 = np.where(s.psd > 0, 0.5 * s.psd * s.tau, s.sigma**2) if s.process == "markov" else None
                plan.append((name, slice(b.se.start, b.se.stop), s, name in targets, var0))
            self._q_cache = plan
        return self._q_cache

    def advance(self, x: np.ndarray, t0: float, t1: float, phase: dict, phis: dict) -> np.ndarray:
        """Propagate a batch x (b, n_x) from t0 to t1 [s] with the phase; Markov states decay."""
        y = self.model.propagate(x, t0, t1, phase, self.cfg.step)
        for name, phi in phis.items():
            sx = self.smap.blocks[name].sx
            y[..., sx] = self.mean[sx] + phi * (x[..., sx] - self.mean[sx])
        return y

    def transition(self, x: np.ndarray, t0: float, t1: float):
        """run_filter's transition: events checked at (x, t0), RK4 to t1, batched numeric F, Q."""
        new = self.model.check_events(x, t0, self.phase)
        for nm in new["fired"][len(self.phase["fired"]) :]:
            self.phase_log.append((t0, nm))
        self.phase = new
        Q, phis = self.q_matrix(t1 - t0, t0, float(self.model.altitude(np.asarray(x, float))))
        x1, F = numeric_jacobian_batched(
            lambda X: self.advance(X, t0, t1, self.phase, phis), x, self.layout, self.eps, out_layout=self.layout
        )
        if self.heading_direction is not None:
            self.heading_direction = F @ self.heading_direction
        return x1, F, Q

    def measurement(self, ch: Channel, i: int) -> Measurement:
        """The :class:`Measurement` of sample i of a channel (batched numeric H at the current phase)."""
        q = ch.spec.quantity
        phase = self.phase
        model = self.model
        R = ch.R[i]
        if self.cfg.schedules:  # ---- schedules: weights × factor (R / factor) in the open windows
            f = sched.weight_factor(self.cfg.schedules, ch.spec.name, float(ch.t[i]), phase["fired"])
            self.weight_log.setdefault(ch.spec.name, []).append((float(ch.t[i]), f))
            R = R / f
        if q == "position_pad_enu":  # linear in the position: h = C (p − p0) at the sample's time
            C, p0 = rocket_results.pad_frame(self.cfg.launch, float(ch.t[i]), model.env.radius_ref, model.env.omega)
            sp, se = self.smap.blocks["position"].sx, self.smap.blocks["position"].se
            Hp = np.zeros((3, self.smap.n_e))
            Hp[:, se] = C

            def hp(x, C=C, p0=p0, sp=sp):
                return (np.asarray(x, float)[..., sp] - p0) @ C.T

            return Measurement(
                ch.spec.name, ch.z[i], R, hp, H=Hp, gate_probability=ch.spec.gate_probability,
                iterations=ch.spec.iterations, gain_projector=self.gain_projector,
            )  # fmt: skip
        if q == "quaternion":  # z = 0, h = body small angle from the measured attitude to the state's
            q_meas = ch.z[i]
            sq = self.smap.blocks["attitude"].sx

            def hq(x, q_meas=q_meas):
                return attitude_error(q_meas, np.asarray(x, float)[..., sq])

            def Hq(x):
                return numeric_jacobian_batched(hq, x, self.layout, self.eps)[1]

            return Measurement(
                ch.spec.name, np.zeros(3), R, hq, H=Hq, gate_probability=ch.spec.gate_probability,
                iterations=ch.spec.iterations, gain_projector=self.gain_projector,
            )  # fmt: skip

        # the update asks h(x) and then H(x) at the same x: one batched model call gives both (its
        # first row is h(x), the model evaluating every row alike)
        memo: list = []

        def h(x, q=q, phase=phase):
            x = np.asarray(x, float)
            if x.ndim != 1:
                return model.observe(x, q, phase)
            y0, J = numeric_jacobian_batched(lambda X: model.observe(X, q, phase), x, self.layout, self.eps)
            memo[:] = [x, J]
            return y0

        def H(x, q=q, phase=phase):
            if memo and memo[0] is x:
                return memo[1]
            return numeric_jacobian_batched(lambda X: model.observe(X, q, phase), x, self.layout, self.eps)[1]

        if self.heading_direction is not None and q in HEADING_INVARIANT:
            n = self.heading_direction
            H = self._without(H, n)
        return Measurement(
            ch.spec.name,
            ch.z[i],
            R,
            h,
            H=H,
            gate_probability=ch.spec.gate_probability,
            iterations=ch.spec.iterations,
            gain_projector=self.gain_projector,
        )

    @staticmethod
    def _without(H, n: np.ndarray):
        """H(x) with the direction ``n`` (n_e,) projected out of its rows: J − (J n) nᵀ / (nᵀ n)."""
        nn = float(n @ n)

        def Hn(x):
            J = np.asarray(H(x), float)
            return J - np.outer(J @ n, n) / nn

        return Hn

    @property
    def gain_projector(self):
        """The update's gain projector ``x -> Π`` (n_e, n_e): zero rows for the ``consider`` states
        (Schmidt-Kalman: their σ enters the other states' covariance, no observation moves them); None
        without consider states."""
        proj = self._projector
        return None if proj is None else (lambda x: proj)


def consider_covariance(cfg: Post2Settings, est: Estimator, t, index, channels, x, P, x_fwd, P_fwd):
    """The smoothed and forward covariances (n, n_e, n_e) with each ``consider`` state's declared σ
    added by sensitivity: the run again with that state's value moved by +1σ (a fresh
    :class:`Estimator`, the same observations ``channels`` on the grid ``t`` (n,) [s] at ``index``
    {step: [(channel, sample)]}), d = x_moved ⊟ x (n, n_e) the move of every state it causes (its own
    entry is its σ), and P + d dᵀ (consider covariance analysis, Bierman 1977 Ch. VIII, to first order
    in the finite difference).  ``x``/``P`` the smoothed (or forward) pass, ``x_fwd``/``P_fwd`` the
    forward one; the estimate itself is the one that takes the consider states as known."""
    P, P_fwd = P.copy(), P_fwd.copy()
    for name in est.smap.blocks:
        spec = cfg.state(name)
        if spec.process != "consider":
            continue
        moved = Estimator(cfg.with_state(name, value=spec.value + spec.sigma))

        def measurements_at(k, tk, xk, moved=moved):
            return [moved.measurement(channels[nm], i) for nm, i in index.get(k, ())]

        fp_m = run_filter(moved.x0, moved.P0, t, moved.transition, None, measurements_at, moved.layout, eps=moved.eps)
        sm_m = rts_smooth(fp_m, moved.layout, consider=moved.consider) if cfg.filter.smoother else None
        xm = sm_m.x if sm_m is not None else fp_m.x_post
        for Pk, xs, xr in ((P, xm, x), (P_fwd, fp_m.x_post, x_fwd)):
            d = est.layout.boxminus(xs, xr)
            Pk += d[:, :, None] * d[:, None, :]
    return P, P_fwd


def _grid(cfg: Post2Settings, channels: dict[str, Channel]) -> np.ndarray:
    n = max(1, int(math.ceil((cfg.t_end - cfg.t_start) / cfg.grid - 1e-9)))
    base = np.linspace(cfg.t_start, cfg.t_end, n + 1)
    allt = np.concatenate([base] + [ch.t for ch in channels.values()])
    ev_t = [e.value for e in cfg.events if e.when == "time" and cfg.t_start < e.value < cfg.t_end]
    allt = np.concatenate([allt, ev_t])  # time events exactly on the grid
    g = np.unique(np.round(allt, 9))
    return g


def state_history(est: Estimator, t: np.ndarray, x: np.ndarray, P: np.ndarray) -> dict:
    """Physical values and 1σ of every state block over (t, x (n, n_x), P (n, n_e, n_e)): name ->
    ``{"value": (n, size), "sigma": (n, size)}`` in SI; attitude as aerodynamic angles [α, β, σ] [rad]
    with the body small-angle 1σ mapped [σ_y, σ_z, σ_x]; bounded parameters through the S-curve."""
    sm = est.smap
    sd = np.sqrt(np.einsum("nii->ni", P))
    out = {}
    for name, b in sm.blocks.items():
        if name == "attitude":
            ang = aero_angles(sm.raw(x, "position"), est.model.v_rel(x), sm.raw(x, "attitude"))
            out[name] = {"value": ang, "sigma": sd[:, b.se][:, [1, 2, 0]]}
            continue
        v = x[:, b.sx]
        s = sd[:, b.se]
        if b.bounds is not None:
            s = s * scurve_slope(v, *b.bounds)
            v = scurve(v, *b.bounds)
        out[name] = {"value": v, "sigma": s}
    return out


def propagation_only(cfg: Post2Settings, t: np.ndarray) -> np.ndarray:
    """The estimator's model run from its initial estimate over the grid t (n,) [s] with no
    observation (events checked on its own state, Markov states decaying): x (n, n_x), the
    "no reconstruction" reference of thesis [R3] Ch. 3.2.3 (Figs. 3-36/3-37)."""
    est = Estimator(cfg)
    X = np.empty((t.size, est.smap.n_x))
    X[0] = est.x0
    phase = est.model.initial_phase()
    for k in range(1, t.size):
        phase = est.model.check_events(X[k - 1], float(t[k - 1]), phase)
        _, phis = est.q_matrix(float(t[k] - t[k - 1]))
        X[k] = est.advance(X[k - 1][None, :], float(t[k - 1]), float(t[k]), phase, phis)[0]
    return X


def _unit_scale(name: str) -> float:
    unit = STATES[name].unit
    return {"deg": 180.0 / math.pi, "deg/s": 180.0 / math.pi}.get(unit, 1.0)


def post2_health(fp, P: np.ndarray, x: np.ndarray, notes=(), extra=(), facts=()) -> dict:
    """``summary["health"]`` (:mod:`workbench.estimation.health`): mean NIS of every observation
    against χ² bounds, the share of rejected samples (WARNING above 10 %), the final covariance
    history ``P`` (n, k, k) symmetric positive definite and the state history ``x`` (n, m) finite;
    the readers' ``notes`` a WARNING, ``extra`` further checks (an imported rocket flight's:
    ``rocket_checks``) and ``facts`` the report's notes (no anomaly)."""
    checks = []
    for name, ih in fp.innovations.items():
        if ih.t.size:
            checks.append(nis_check(name, ih.nis, int(ih.y.shape[1])))
            rej = float(np.mean(~ih.accepted))
            checks.append(
                interval_check(f"rejected.{name}", rej, 0.0, 0.1, f"share of {name} samples rejected", status=WARNING)
            )
    checks.append(covariance_check(P, "covariance"))
    bad = int(np.sum(~np.isfinite(x)))
    checks.append(interval_check("state.finite", bad, 0, 0, "non-finite state components"))
    checks.append(notes_check("observations", list(notes)))
    return health_report([*checks, *extra], notes=list(facts))


def reconstruct(cfg: Post2Settings, telemetry, options=None):
    """Generator of the stages (see the module docstring) for a post2 run's settings and its telemetry
    files {name: csv, name + "_weights": csv}."""
    cfg, detected = detect_event_times(cfg, telemetry)
    data = read_observations(cfg, telemetry)
    data = replace(data, facts=(*detected, *data.facts))
    yield data
    est = Estimator(cfg)
    t = _grid(cfg, data.channels)
    index = {}
    for name, ch in data.channels.items():
        k = np.searchsorted(t, np.round(ch.t, 9))
        for i, kk in enumerate(k):
            index.setdefault(int(kk), []).append((name, i))

    def measurements_at(k, tk, x):
        return [est.measurement(data.channels[nm], i) for nm, i in index.get(k, ())]

    fp = run_filter(est.x0, est.P0, t, est.transition, None, measurements_at, est.layout, eps=est.eps)
    wf = {n: (np.array([a for a, _ in v]), np.array([b for _, b in v])) for n, v in est.weight_log.items()}
    touched = {s.target_name for s in cfg.schedules if s.target == "observation"}
    wf = {n: v for n, v in wf.items() if n in touched}
    yield ForwardStage(fp, tuple(est.phase_log), {n: ch.spec.quantity for n, ch in data.channels.items()}, wf)
    consider = est.consider if est.consider.size else None
    sm = rts_smooth(fp, est.layout, consider=consider) if cfg.filter.smoother else None
    x, P = (sm.x, sm.P) if sm is not None else (fp.x_post, fp.P_post)
    P_fwd = fp.P_post
    if consider is not None:
        P, P_fwd = consider_covariance(cfg, est, t, index, data.channels, x, P, fp.x_post, P_fwd)
    hist = state_history(est, t, x, P)
    fwd = state_history(est, t, fp.x_post, P_fwd)
    histories = {"smoothed": hist, "forward": fwd}
    if cfg.filter.compare_propagation:  # the no-observation reference (its P: the prior's)
        xp = propagation_only(cfg, t)
        histories["propagated"] = state_history(est, t, xp, np.broadcast_to(est.P0, (t.size, *est.P0.shape)))
    prior = state_history(est, t[:1], est.x0[None, :], est.P0[None, :, :])
    summary = {"scenario": cfg.run.name, "kind": "post2", "dof": cfg.dof, "grid_steps": int(t.size)}
    summary["smoothed"] = sm is not None
    states = {}
    for name in est.smap.blocks:
        k = _unit_scale(name)
        unit = "deg" if name == "attitude" else STATES[name].unit
        states[name] = {
            "unit": unit,
            "initial": (prior[name]["value"][0] * k).tolist(),
            "final": (hist[name]["value"][-1] * k).tolist(),
            "final_sigma": (hist[name]["sigma"][-1] * k).tolist(),
        }
        if not STATES[name].dynamic and cfg.state(name).process != "consider":  # (bounded: before its S-curve)
            i = np.arange(est.smap.blocks[name].se.start, est.smap.blocks[name].se.stop)
            ratio = np.sqrt(np.diag(P[-1])[i] / np.diag(est.P0)[i])
            states[name]["posterior_over_prior_sigma"] = ratio.tolist()
            states[name]["informed_by_data"] = (ratio < INFORMED_RATIO).tolist()
        if cfg.state(name).process == "consider":
            states[name]["consider"] = True
    summary["states"] = states
    uninformed = [
        f"{n} (posterior/prior σ {max(s['posterior_over_prior_sigma']):.2f})"
        for n, s in states.items()
        if cfg.state(n).process == "constant" and not any(s.get("informed_by_data", [True]))
    ]
    obs = {}
    for name, ih in fp.innovations.items():
        ok = ih.accepted
        yn = np.linalg.solve(np.linalg.cholesky(ih.S), ih.y[..., None])[..., 0]  # L⁻¹ y, sample by sample
        obs[name] = {
            "samples": int(ih.t.size),
            "accepted": int(np.sum(ok)),
            "mean_nis": float(np.mean(ih.nis)),
            "normalized_residual_rms": float(np.sqrt(np.mean(yn**2))),
            "dimension": int(ih.y.shape[1]),
        }
        n_dof = ih.t.size * ih.y.shape[1]
        lo, hi = (chi2_ppf(np.array([0.005, 0.995]), n_dof) / ih.t.size).tolist()
        m = obs[name]["mean_nis"]
        obs[name]["mean_nis_band_99"] = [lo, hi]
        obs[name]["nis_verdict"] = "consistent" if lo <= m <= hi else ("conservative" if m < lo else "overconfident")
    summary["observations"] = obs
    summary["events"] = [{"t_s": float(a), "event": b} for a, b in est.phase_log]
    track = _rocket(cfg, est, t, x, P, summary)
    extra, rocket_facts = rocket_checks.run_checks(cfg, hist)  # bounds; an imported flight: its import checks
    facts = [*data.facts, *rocket_facts]
    considered = [f"{n} (1σ {s['final_sigma'][0]:.4g} {s['unit']})" for n, s in states.items() if s.get("consider")]
    if considered:
        facts.append("consider parameters, in every σ and never fitted: " + ", ".join(considered))
    if uninformed:
        facts.append(
            f"not informed by the data (final posterior σ not below {INFORMED_RATIO:g} × the prior's): "
            + ", ".join(uninformed)
        )
    summary["health"] = post2_health(fp, P, x, data.notes, extra, facts)
    yield Post2Result(
        t, x, P, fp, sm, est.smap, data.channels, tuple(est.phase_log), histories, summary, track, est.heading_direction
    )


def _rocket(cfg: Post2Settings, est: Estimator, t, x, P, summary: dict):
    """A flight with a ``[launch]`` pad: its :class:`~workbench.problems.post2.rocket_results.LocalTrack`
    from the smoothed (or forward) ``x``, ``P`` on the grid ``t``, and ``summary["rocket"]``; else None."""
    if cfg.launch is None:
        return None
    sp, sv = est.smap.blocks["position"].se, est.smap.blocks["velocity"].se
    p, v = est.smap.raw(x, "position"), est.smap.raw(x, "velocity")
    env = est.model.env
    track = rocket_results.local_track(cfg.launch, t, p, v, P[:, sp, sp], P[:, sv, sv], env.radius_ref, env.omega)
    chutes = {e.name: e.chute for e in cfg.events if e.chute}
    wind = est.smap.raw(x, "wind") if "wind" in est.smap.blocks else None
    given = None
    if est.heading_direction is not None:
        given = rocket_results.covariance_given_heading(P[-1], est.heading_direction)
    summary["rocket"] = rocket_results.summary_block(
        cfg.launch, track, P[-1][sp, sp], est.phase_log, chutes, env.omega, p[-1], wind,
        given_heading=None if given is None else (given[0][sp, sp], given[1]),
    )  # fmt: skip
    return track
