"""Tuning and validation of the radar-aided entry smoother on simulated trajectories (AMELIA Sect. 8).

What: :func:`validate_smoother` draws truths from the accepted dispersion members (or from the
smoother's own initial distribution), integrates them with the clean IMU, simulates the IMU and
radar noise the filter assumes at the real telemetry time tags, runs the smoother on each and
scores it (RMS errors, Cartesian and curvilinear NEES, NIS per radar channel, altitude error after
the radar fix).  Why: AMELIA validated its smoother this way (100 dispersion trajectories); the
NEES adds the consistency test of the reported covariance (Bar-Shalom, Li & Kirubarajan 2001,
Sect. 5.4).  Runs are independent per seed and executor (loop, process pool, Dask).  The per-run
recipe and the measurements behind its choices are in ``docs/tuning/entry.md``.

Reference: Aboudan et al., Space Sci. Rev. 214:97, 2018 (AMELIA), Sect. 8.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.bodies import MARS
from workbench.core.rotation import quat_boxplus
from workbench.estimation.consistency import anees_bounds, fraction_inside, nees
from workbench.estimation.montecarlo import run_monte_carlo
from workbench.estimation.strapdown import GapBridge, ImuArrays, apply_gap, gap_transition, imu_arrays, rk4_step
from workbench.io import progress
from workbench.models.radar import beam_directions_G, mars_rate_M, slant_range_sphere, velocity_out_model
from workbench.problems.entry.dispersion import run_configured_dispersion
from workbench.problems.entry.filter import CHANNELS, EntryFilterSigmas, RadarData, run_entry_smoother
from workbench.problems.entry.initial import initial_for_smoother, reconstruction_P0
from workbench.problems.entry.preprocess import preprocess
from workbench.problems.entry.scoring import ERROR_NAMES, ERROR_UNITS, errors_sigmas
from workbench.problems.entry.site import R_GROUND
from workbench.problems.entry.state import DP, DTH, DV
from workbench.problems.entry.telemetry import read_entry_telemetry, read_nominal_state

if TYPE_CHECKING:
    from workbench.problems.entry.config import EntrySettings

__all__ = [
    "RunScores",
    "score_run",
    "failed_run",
    "aggregate_runs",
    "index_at",
    "summary_times",
    "ValidationResult",
    "ValidationInputs",
    "validate_smoother",
    "ValidationSettings",
    "noise_scale",
    "summarize_validation",
    "headline_numbers",
    "prepare_validation",
]

#: Degrees of freedom of the radar channels' NIS (slant ranges: up to 4 beams, counted per packet).
_NIS_DOF = {"slant_range": 4, "slant_out": 1, "velocity_out": 3}


# ---------------------------------------------------------------------------------------------
# job and per-run output (plain, picklable)


@dataclass(frozen=True)
class _Job:
    imu: ImuArrays
    v0: np.ndarray
    q0: np.ndarray
    p0: np.ndarray
    truth_mode: str  # "accepted" | "gaussian"
    L_start: np.ndarray  # (9, 9) Cholesky factor of P_ref ("gaussian")
    dx0_accepted: np.ndarray  # (m, 9)
    index_accepted: np.ndarray  # (m,) member indices
    prob_accepted: np.ndarray  # (m,) draw probabilities (∝ importance weights; uniform without)
    v_ref: np.ndarray
    q_ref: np.ndarray
    p_ref: np.ndarray
    P_ref: np.ndarray
    t_sr: np.ndarray
    t_rda: np.ndarray
    beams_G: np.ndarray
    r_ground: float
    sigmas: EntryFilterSigmas
    noise: tuple[float, float, float]  # slant range [m], slant-out [m], velocity-out [m/s]
    constrained: bool
    gap_noise: bool
    seed: int
    t_fix: float


@dataclass(frozen=True)
class RunScores:
    """Scores of one reconstruction against its truth (one Monte Carlo run), on the run's IMU grid
    (n,): ``r`` run index, ``member`` (dispersion member taken as the truth, or −1), ``failed`` and
    ``message``; NEES (9 dof) of the smoothed and forward passes, Cartesian and curvilinear
    (float32, NaN if failed); ``err``/``sig`` (n, k) estimate − truth and reported 1σ of
    :data:`~workbench.problems.entry.scoring.ERROR_NAMES`; fractions of (step, state) pairs inside
    3σ; ``h_err_max_after_fix`` [m] max |altitude-AGL error| from the first radar time tag on,
    ``h_3sigma_at_max`` [m] its 3σ, ``h_inside_after_fix`` fraction of those steps inside 3σ;
    ``nis_mean`` (3,) mean NIS per radar channel (``filter.CHANNELS``); ``wall_s`` [s]."""

    r: int
    member: int
    failed: bool
    message: str
    nees: np.ndarray  # (n,) float32 smoothed, Cartesian error; NaN if failed
    nees_curvilinear: np.ndarray  # (n,) float32 smoothed, curvilinear position error
    nees_forward: np.ndarray  # (n,) float32
    nees_forward_curvilinear: np.ndarray  # (n,) float32
    err: np.ndarray  # (n, k) float32 estimate − truth
    sig: np.ndarray  # (n, k) float32 reported 1σ
    inside_3sigma: float
    inside_3sigma_curvilinear: float
    h_err_max_after_fix: float
    h_3sigma_at_max: float
    h_inside_after_fix: float
    nis_mean: np.ndarray  # (3,)
    wall_s: float


def _gap_index(t: np.ndarray, gaps: Sequence[GapBridge]) -> dict[int, GapBridge]:
    out = {}
    for g in gaps:
        i = int(np.searchsorted(t, g.t_a - 1e-6))
        if i >= t.size - 1 or abs(t[i] - g.t_a) > 1e-6 or abs(t[i + 1] - g.t_b) > 1e-6:
            raise ValueError(f"gap bridge t_a={g.t_a:.3f} s, t_b={g.t_b:.3f} s does not match two adjacent IMU samples")
        out[i] = g
    return out


def noise_scale(t: np.ndarray, gap_at: Mapping[int, Any]) -> tuple[np.ndarray, float]:
    """Per-sample factor √(sample_dt / dt_k) (docs/tuning/entry.md, montecarlo, step 2), shape (n,), and the
    median sample interval sample_dt [s], for IMU times ``t`` (n,) [s]; ``gap_at`` maps the index
    of a sample followed by a data gap to its bridge (that interval is not a sampling interval)."""
    d = np.diff(t)
    sample_dt = float(np.median(d))
    d = d.copy()
    d[list(gap_at)] = np.nan  # a gap is not a sampling interval
    left = np.r_[np.nan, d]
    right = np.r_[d, np.nan]
    local = np.nanmean(np.stack([left, right]), axis=0) if t.size > 1 else np.array([sample_dt])
    local = np.where(np.isfinite(local), local, sample_dt)
    return np.sqrt(sample_dt / local), sample_dt


# ---------------------------------------------------------------------------------------------
# one run


def _truth(job: _Job, dx0: np.ndarray, rng: np.random.Generator, gap_at: dict[int, GapBridge]):
    """Truth on the IMU grid (v (n,3), q (n,4), p (n,3)) from nominal ⊞ dx0, clean inputs."""
    imu = job.imu
    t, f, w = imu.t, imu.f_G, imu.w_G
    n = t.size
    V = np.empty((n, 3))
    Q = np.empty((n, 4))
    X = np.empty((n, 3))
    v = job.v0 + dx0[DV]
    q = quat_boxplus(job.q0, dx0[DTH])
    p = job.p0 + dx0[DP]
    qpsd = None if job.sigmas.q_state_psd is None else np.asarray(job.sigmas.q_state_psd, float)
    V[0], Q[0], X[0] = v, q, p
    for k in range(n - 1):
        g = gap_at.get(k)
        if g is not None:
            _, Qd = gap_transition(q, p, g, job.sigmas.bridge_mode, job.sigmas.gap_sigma, body=MARS)
            v, q, p = apply_gap(v, q, p, g, job.sigmas.bridge_mode)
            if job.gap_noise:
                e = np.sqrt(np.diagonal(Qd)) * rng.standard_normal(9)
                v, q, p = v + e[DV], quat_boxplus(q, e[DTH]), p + e[DP]
        else:
            dt = t[k + 1] - t[k]
            v, q, p = rk4_step(v, q, p, f[k], w[k], f[k + 1], w[k + 1], dt, MARS)
            if qpsd is not None:
                e = np.sqrt(qpsd * dt) * rng.standard_normal(9)
                v, q, p = v + e[DV], quat_boxplus(q, e[DTH]), p + e[DP]
        V[k + 1], Q[k + 1], X[k + 1] = v, q, p
    return V, Q, X


def _truth_at(job: _Job, V, Q, X, gap_at, tm: np.ndarray):
    """Truth at measurement times tm (m,): grid sample within snap tolerance, else the RK4 step
    from the previous sample with linearly interpolated inputs (gap: the nearer gap end)."""
    imu = job.imu
    t, f, w = imu.t, imu.f_G, imu.w_G
    n = t.size
    tol = float(job.sigmas.snap_tolerance)
    out_v = np.empty((tm.size, 3))
    out_q = np.empty((tm.size, 4))
    out_p = np.empty((tm.size, 3))
    for j, tj in enumerate(tm):
        k = int(np.clip(np.searchsorted(t, tj), 1, n - 1))
        k = k if abs(t[k] - tj) <= abs(t[k - 1] - tj) else k - 1
        i = int(np.clip(np.searchsorted(t, tj) - 1, 0, n - 2))
        if abs(t[k] - tj) <= tol or i in gap_at:
            out_v[j], out_q[j], out_p[j] = V[k], Q[k], X[k]
            continue
        s = (tj - t[i]) / (t[i + 1] - t[i])
        fm = f[i] + s * (f[i + 1] - f[i])
        wm = w[i] + s * (w[i + 1] - w[i])
        out_v[j], out_q[j], out_p[j] = rk4_step(V[i], Q[i], X[i], f[i], w[i], fm, wm, tj - t[i], MARS)
    return out_v, out_q, out_p


def _nis_mean(res) -> np.ndarray:
    out = np.full(len(CHANNELS), np.nan)
    for c, ch in enumerate(CHANNELS):
        inn = res.innovations.get(ch)
        if inn is None or len(inn.t) == 0:
            continue
        vals = []
        for y, S in zip(inn.y, inn.S, strict=True):
            m = np.isfinite(y)
            if not m.any():
                continue
            Sm = S[np.ix_(m, m)]
            if not np.all(np.isfinite(Sm)):
                continue
            vals.append(float(y[m] @ np.linalg.solve(Sm, y[m])) * (_NIS_DOF[ch] / m.sum()))
        if vals:
            out[c] = float(np.mean(vals))
    return out


def _run_one(job: _Job, r: int, ss: np.random.SeedSequence) -> RunScores:
    """One validation run (docs/tuning/entry.md); depends on (job, r) only.

    A task of :func:`~workbench.estimation.montecarlo.run_monte_carlo`: ``ss`` is run r's
    ``SeedSequence(job.seed, spawn_key=(r,))``."""
    t0 = time.perf_counter()
    g_member, g_truth, g_imu, g_radar = (np.random.Generator(np.random.PCG64(s)) for s in ss.spawn(4))
    imu = job.imu
    n = imu.t.size
    if job.truth_mode == "accepted":
        j = int(g_member.choice(job.prob_accepted.size, p=job.prob_accepted))
        member, dx0 = int(job.index_accepted[j]), job.dx0_accepted[j]
    else:  # "gaussian": start ⊞ N(0, P0)
        member, dx0 = -1, job.L_start @ g_member.standard_normal(9)
    gap_at = _gap_index(imu.t, imu.gaps)
    V, Q, X = _truth(job, dx0, g_truth, gap_at)

    # filter input: IMU + white noise with the filter's PSD
    scale, _ = noise_scale(imu.t, gap_at)
    f_noisy = imu.f_G + imu.sigma_f * scale[:, None] * g_imu.standard_normal((n, 3))
    w_noisy = imu.w_G + imu.sigma_w * scale[:, None] * g_imu.standard_normal((n, 3))
    noisy = ImuArrays(imu.t, f_noisy, w_noisy, imu.sigma_f, imu.sigma_w, imu.gaps)

    # radar from the truth at the telemetry time tags
    s_sr, s_so, s_vo = job.noise
    B = job.beams_G
    if job.t_sr.size:
        v_, q_, p_ = _truth_at(job, V, Q, X, gap_at, job.t_sr)
        sr = np.stack([slant_range_sphere(p_, q_, B[b], job.r_ground) for b in range(4)], -1)
        sr = sr + s_sr * g_radar.standard_normal(sr.shape)
        sr[~np.isfinite(sr)] = np.nan
    else:
        sr = np.zeros((0, 4))
    if job.t_rda.size:
        v_, q_, p_ = _truth_at(job, V, Q, X, gap_at, job.t_rda)
        so = slant_range_sphere(p_, q_, B[0], job.r_ground) + s_so * g_radar.standard_normal(job.t_rda.size)
        so[~np.isfinite(so)] = np.nan
        om = mars_rate_M() if job.sigmas.omega_M is None else np.asarray(job.sigmas.omega_M, float)
        vo = velocity_out_model(v_, q_, p_, om)[0] + s_vo * g_radar.standard_normal((job.t_rda.size, 3))
    else:
        so, vo = np.zeros(0), np.zeros((0, 3))
    radar = RadarData(
        job.t_sr,
        sr,
        np.ones(job.t_sr.size, bool),
        job.t_rda,
        so,
        vo,
        np.ones(job.t_rda.size, bool),
        B,
        job.r_ground,
    )
    try:
        res = run_entry_smoother(
            noisy,
            radar,
            job.v_ref,
            job.q_ref,
            job.p_ref,
            job.P_ref,
            sigmas=job.sigmas,
            constrained=job.constrained,
        )
    except (ValueError, np.linalg.LinAlgError) as err:
        return failed_run(r, member, str(err), n, t0)
    return score_run(res, V, Q, X, imu.t, job.t_fix, r=r, member=member, t_start=t0)


def failed_run(r: int, member: int, message: str, n: int, t_start: float) -> RunScores:
    """The :class:`RunScores` of a run that failed with ``message`` on a grid of ``n`` steps
    (NaN everywhere); ``t_start`` its ``time.perf_counter()`` start [s]."""
    k = len(ERROR_NAMES)
    nan = np.full(n, np.nan, np.float32)
    nank = np.full((n, k), np.nan, np.float32)
    return RunScores(
        r, member, True, message, nan, nan, nan, nan, nank, nank, math.nan, math.nan, math.nan, math.nan,
        math.nan, np.full(len(CHANNELS), np.nan), time.perf_counter() - t_start,
    )  # fmt: skip


def score_run(
    res: Any, V: np.ndarray, Q: np.ndarray, X: np.ndarray, t: np.ndarray, t_fix: float, *, r: int, member: int,
    t_start: float,
) -> RunScores:  # fmt: skip
    """Score an :class:`~workbench.problems.entry.filter.EntryFilterResult` ``res`` (forward and
    smoothed passes on the IMU grid ``t`` (n,) [s]) against the truth on the same samples: ``V``
    (n, 3) [m/s], ``Q`` (n, 4) ``q_M_G``, ``X`` (n, 3) [m], MMED.  ``t_fix`` [s] the first radar
    time tag (altitude statistics from there on); ``r`` run index, ``member`` truth member (or −1),
    ``t_start`` the run's ``time.perf_counter()`` start [s].  NEES and errors as in the module
    docstring (Cartesian and curvilinear, 9 dof)."""
    sm = res.smoothed
    e, e_c, err, sig = errors_sigmas(sm, V, Q, X)
    e_f, e_fc, _, _ = errors_sigmas(res.forward, V, Q, X)
    sd3 = 3.0 * np.sqrt(np.einsum("nii->ni", sm.P))
    after = t >= t_fix
    if after.any():
        dh = np.abs(err[after, 2])
        i_max = int(np.argmax(dh))
        h_max = float(dh[i_max])
        h3 = float(3.0 * sig[after, 2][i_max])
        h_in = float(np.mean(dh <= 3.0 * sig[after, 2]))
    else:
        h_max = h3 = h_in = math.nan
    return RunScores(
        r=r,
        member=member,
        failed=False,
        message="",
        nees=nees(e, sm.P).astype(np.float32),
        nees_curvilinear=nees(e_c, sm.P).astype(np.float32),
        nees_forward=nees(e_f, res.forward.P).astype(np.float32),
        nees_forward_curvilinear=nees(e_fc, res.forward.P).astype(np.float32),
        err=err.astype(np.float32),
        sig=sig.astype(np.float32),
        inside_3sigma=float(np.mean(np.abs(e) <= sd3)),
        inside_3sigma_curvilinear=float(np.mean(np.abs(e_c) <= sd3)),
        h_err_max_after_fix=h_max,
        h_3sigma_at_max=h3,
        h_inside_after_fix=h_in,
        nis_mean=_nis_mean(res),
        wall_s=time.perf_counter() - t_start,
    )


# ---------------------------------------------------------------------------------------------
# result


@dataclass(frozen=True)
class ValidationResult:
    """Outcome of :func:`validate_smoother` (SI; errors estimate − truth; method in docs/tuning/entry.md).

    ``t`` (n,) [s] IMU grid; ``n_runs``; ``seed``; ``member`` (n_runs,) the accepted dispersion
    member each run took as its truth; ``failed`` (n_runs,) bool and ``messages`` (why);
    ``nees`` (n_runs, n) float32 smoothed NEES (9 dof, NaN for failed runs) of the Cartesian error
    state and ``nees_curvilinear`` the same with the curvilinear position error (horizontal +
    altitude about the estimate, :func:`~workbench.problems.entry.scoring.errors_sigmas`); ``anees``,
    ``anees_curvilinear`` (n,)
    their means over the successful runs, ``anees_forward``, ``anees_forward_curvilinear`` (n,)
    the forward pass's; ``anees_band`` the 95 % band ``anees_bounds(9, n_ok)``;
    ``error_names``/``error_units`` (:data:`ERROR_NAMES`),
    ``rms_error``, ``mean_error``, ``rms_sigma`` (n, k) — RMS and mean over runs of the errors and
    the RMS of the reported 1σ (what the RMS error should be if the covariance is right);
    per run: ``nees_time_avg``, ``nees_curvilinear_time_avg``, ``inside_3sigma`` and
    ``inside_3sigma_curvilinear`` (fraction of (step, state) pairs with |e| ≤ 3σ),
    ``h_err_max_after_fix`` [m] max |altitude-AGL error| from ``t_fix`` (first radar time tag)
    on and ``h_3sigma_at_max`` [m] the 3σ at that step, ``h_inside_after_fix`` fraction of those
    steps inside 3σ, ``nis_mean`` (n_runs, 3) mean NIS per radar channel (CHANNELS;
    slant ranges scaled to 4 dof), ``run_wall_s``; ``times`` {label: t [s]} of the summary
    epochs; ``summary`` JSON-ready numbers (:func:`summarize_validation`); ``executor``, ``wall_s``.
    """

    t: np.ndarray
    n_runs: int
    seed: int
    member: np.ndarray
    failed: np.ndarray
    messages: tuple[str, ...]
    nees: np.ndarray
    nees_curvilinear: np.ndarray
    anees: np.ndarray
    anees_curvilinear: np.ndarray
    anees_forward: np.ndarray
    anees_forward_curvilinear: np.ndarray
    anees_band: tuple[float, float]
    rms_error: np.ndarray
    mean_error: np.ndarray
    rms_sigma: np.ndarray
    nees_time_avg: np.ndarray
    nees_curvilinear_time_avg: np.ndarray
    inside_3sigma: np.ndarray
    inside_3sigma_curvilinear: np.ndarray
    h_err_max_after_fix: np.ndarray
    h_3sigma_at_max: np.ndarray
    h_inside_after_fix: np.ndarray
    nis_mean: np.ndarray
    run_wall_s: np.ndarray
    t_fix: float
    times: dict[str, float]
    executor: str
    wall_s: float
    error_names: tuple[str, ...] = ERROR_NAMES
    error_units: tuple[str, ...] = ERROR_UNITS
    summary: dict = field(default_factory=dict)

    #: fields that depend only on the inputs and the seed (compare these across executors)
    DETERMINISTIC = (
        "t", "member", "failed", "nees", "nees_curvilinear", "anees", "anees_curvilinear", "anees_forward",
        "anees_forward_curvilinear", "rms_error", "mean_error", "rms_sigma", "nees_time_avg",
        "nees_curvilinear_time_avg", "inside_3sigma", "inside_3sigma_curvilinear", "h_err_max_after_fix",
        "h_3sigma_at_max", "h_inside_after_fix", "nis_mean",
    )  # fmt: skip


def summary_times(
    t: np.ndarray, gaps: Sequence[GapBridge], events: Mapping[str, float], t_fix: float
) -> dict[str, float]:
    """The summary epochs {label: t [s]} of a run on the IMU grid ``t`` (n,) [s]: "start", "blackout_end"
    (end of the longest data gap of ``gaps``), "PDD" (from ``events``, if inside the data), "first_radar"
    (``t_fix``, if finite and inside) and "end"."""
    out = {"start": float(t[0])}
    if gaps:
        g = max(gaps, key=lambda g: g.t_b - g.t_a)
        out["blackout_end"] = float(g.t_b)
    if "PDD" in events and t[0] <= float(events["PDD"]) <= t[-1]:
        out["PDD"] = float(events["PDD"])
    if np.isfinite(t_fix) and t_fix <= t[-1]:
        out["first_radar"] = float(t_fix)
    out["end"] = float(t[-1])
    return out


def index_at(t: np.ndarray, te: float) -> int:
    """Index of the IMU sample of ``t`` (n,) [s] at or right after ``te`` [s] (the first smoothed state
    that has seen that time), clipped to the grid."""
    return int(np.clip(np.searchsorted(t, te - 1e-9), 0, t.size - 1))


@dataclass(frozen=True)
class ValidationSettings:
    """Settings of :func:`validate_smoother` (picklable).

    ``n_runs`` ≥ 1; ``seed`` base seed (run r: ``SeedSequence(seed, spawn_key=(r,))``);
    ``sigmas``: the filter tuning (:class:`EntryFilterSigmas` or mapping); ``radar_noise``: 1σ of
    the simulated radar noise, mapping with keys ``slant_range`` [m], ``slant_out`` [m],
    ``velocity_out`` [m/s] or a 3-tuple in that order (default: the filter's R — the test is then
    of the filter's own assumptions); ``beams_G`` (4, 3) (default documented geometry);
    ``r_ground`` [m]; ``constrained`` AMELIA's update directions; ``events`` {name: t [s]} for the
    summary epochs (default ``dispersion.events_t``); ``gap_noise`` draw the filter's gap noise
    into the truth; ``start`` ``(v0, q0, p0, P0)`` the smoother's initial state and covariance
    (default: the dispersion's refined state and ``refined_P0``, AMELIA; e.g. the pipeline's
    "fused" start); ``truth_initial`` "accepted" (AMELIA: truths from the accepted members about
    ``nominal``) or "gaussian" (truth initial state ``start ⊞ N(0, P0)``, the smoother's own
    initial assumption — the textbook NEES test for a start that is not the accepted set's
    spread; ``dispersion`` is then only used for ``events_t``); ``scheduler`` None | "local" |
    "tcp://…" and ``workers`` (process pool when > 1 without a scheduler).
    """

    n_runs: int
    seed: int
    sigmas: EntryFilterSigmas | Mapping[str, Any] | None = None
    radar_noise: Mapping[str, float] | tuple[float, float, float] | None = None
    beams_G: np.ndarray | None = None
    r_ground: float = R_GROUND
    constrained: bool = True
    events: Mapping[str, float] | None = None
    gap_noise: bool = True
    start: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    truth_initial: str = "accepted"
    scheduler: str | None = None
    workers: int = 1


def validate_smoother(
    imu: Any,
    nominal: tuple[np.ndarray, np.ndarray, np.ndarray],
    dispersion: Any,
    radar_times: tuple[np.ndarray, np.ndarray],
    settings: ValidationSettings,
) -> ValidationResult:
    """Validate the radar-aided smoother on ``settings.n_runs`` simulated trajectories (docs/tuning/entry.md).

    ``imu``: a PreprocessedIMU (``t``, ``f_G``, ``w_G``, ``sigma_f``, ``sigma_w``, ``gaps``) — the
    clean inputs of the truth; ``nominal``: ``(v0 [m/s], q0 q_M_G, p0 [m])`` at ``imu.t[0]`` about
    which the dispersion offsets were drawn; ``dispersion``: a DispersionResult (``dx0`` (N, 9),
    ``accepted`` (N,), ``refined_v0/q0/p0``, ``refined_P0`` (9, 9), optional ``weights`` (N,),
    ``events_t``); ``radar_times``:
    ``(t_sr (k,), t_rda (j,))`` [s] the (valid) telemetry time tags of the slant-range packets
    and of the slant-out/velocity-out samples; ``settings`` the :class:`ValidationSettings`.
    Raises ``ValueError`` if the dispersion has fewer than 2 accepted members and no ``start`` is given.
    """
    vs = settings
    n_runs, seed, sigmas, radar_noise, beams_G = vs.n_runs, vs.seed, vs.sigmas, vs.radar_noise, vs.beams_G
    r_ground, constrained, events, gap_noise = vs.r_ground, vs.constrained, vs.events, vs.gap_noise
    start, truth_initial, scheduler, workers = vs.start, vs.truth_initial, vs.scheduler, vs.workers
    wall0 = time.perf_counter()
    if int(n_runs) < 1:
        raise ValueError("validate_smoother: n_runs must be ≥ 1")
    sg = EntryFilterSigmas.from_any(sigmas)
    if truth_initial not in ("accepted", "gaussian"):
        raise ValueError(f"validate_smoother: truth_initial must be 'accepted' or 'gaussian', got {truth_initial!r}")
    v0, q0, p0 = (np.asarray(a, float) for a in nominal)
    q0 = q0 / np.linalg.norm(q0)
    if start is None:
        accepted = np.asarray(dispersion.accepted, bool)
        v_ref, q_ref, p_ref = (
            np.asarray(a, float) for a in (dispersion.refined_v0, dispersion.refined_q0, dispersion.refined_p0)
        )
        P_ref = np.asarray(dispersion.refined_P0, float)
        if accepted.sum() < 2 or not np.all(np.isfinite(P_ref)):
            raise ValueError(
                f"validate_smoother: the dispersion has {int(accepted.sum())} accepted members of {accepted.size}; "
                "need ≥ 2 (a refined initial state and covariance) — widen the acceptance rules or add members"
            )
    else:
        v_ref, q_ref, p_ref, P_ref = (np.asarray(a, float) for a in start)
    P_ref = 0.5 * (P_ref + P_ref.T)
    idx = np.zeros(0, int)
    prob = np.zeros(0)
    ess = math.nan
    dx0_acc = np.zeros((0, 9))
    L_start = np.zeros((9, 9))
    if truth_initial == "accepted":
        accepted = np.asarray(dispersion.accepted, bool)
        idx = np.flatnonzero(accepted)
        if idx.size < 1:
            raise ValueError("validate_smoother: no accepted dispersion member to draw the truths from")
        w_all = getattr(dispersion, "weights", None)
        w_all = np.asarray(w_all if w_all is not None else [], float).reshape(-1)
        w = w_all[idx] if w_all.size == accepted.size else np.ones(idx.size)
        if not (np.all(np.isfinite(w)) and np.all(w >= 0.0) and w.sum() > 0.0):
            raise ValueError("validate_smoother: the importance weights of the accepted members are invalid")
        prob = w / w.sum()
        ess = float(w.sum() ** 2 / np.sum(w * w))
        dx0_acc = np.asarray(dispersion.dx0, float)[idx]
    else:
        try:
            L_start = np.linalg.cholesky(P_ref)
        except np.linalg.LinAlgError as err:
            raise ValueError("validate_smoother: the start covariance is not positive definite") from err
        v0, q0, p0 = v_ref, q_ref / np.linalg.norm(q_ref), p_ref
    if radar_noise is None:
        noise = (sg.slant_range, sg.slant_out, sg.velocity_out)
    elif isinstance(radar_noise, Mapping):
        noise = (
            float(radar_noise.get("slant_range", sg.slant_range)),
            float(radar_noise.get("slant_out", sg.slant_out)),
            float(radar_noise.get("velocity_out", sg.velocity_out)),
        )
    else:
        noise = tuple(float(x) for x in radar_noise)
        if len(noise) != 3:
            raise ValueError("radar_noise: mapping or (slant_range, slant_out, velocity_out)")
    plain = imu_arrays(imu)
    t_sr = np.sort(np.asarray(radar_times[0], float).reshape(-1))
    t_rda = np.sort(np.asarray(radar_times[1], float).reshape(-1))
    first = [x[0] for x in (t_sr, t_rda) if x.size]
    t_fix = float(min(first)) if first else math.inf
    job = _Job(
        imu=plain,
        v0=v0,
        q0=q0,
        p0=p0,
        truth_mode=truth_initial,
        L_start=L_start,
        dx0_accepted=dx0_acc,
        index_accepted=idx,
        prob_accepted=prob,
        v_ref=v_ref,
        q_ref=q_ref,
        p_ref=p_ref,
        P_ref=P_ref,
        t_sr=t_sr,
        t_rda=t_rda,
        beams_G=beam_directions_G() if beams_G is None else np.asarray(beams_G, float),
        r_ground=float(r_ground),
        sigmas=sg,
        noise=noise,
        constrained=bool(constrained),
        gap_noise=bool(gap_noise),
        seed=int(seed),
        t_fix=t_fix,
    )
    # one BLAS thread in every executor: results must not depend on it, and multi-threaded BLAS on
    # 9x9 matrices made one smoother run ~10x slower (measured 0.65 s -> 7 s)
    with progress.current().counter("smoother validation runs", total=int(n_runs), unit="runs") as bar:
        run = run_monte_carlo(
            _run_one,
            int(n_runs),
            shared=job,
            seed=job.seed,
            workers=int(workers),
            scheduler=scheduler,
            name=f"entry-validation-{job.seed}",
            progress=bar,
        )
    outs, executor = run.results, run.executor
    ev = dict(getattr(dispersion, "events_t", {}) or {}) if events is None else dict(events)
    res = aggregate_runs(
        outs,
        plain.t,
        n_runs=int(n_runs),
        seed=int(seed),
        t_fix=t_fix,
        times=summary_times(plain.t, plain.gaps, ev, t_fix),
        executor=executor,
        wall_s=time.perf_counter() - wall0,
    )
    summary = summarize_validation(res)
    summary["radar_noise"] = {"slant_range_m": noise[0], "slant_out_m": noise[1], "velocity_out_mps": noise[2]}
    summary["filter_R"] = {
        "slant_range_m": sg.slant_range,
        "slant_out_m": sg.slant_out,
        "velocity_out_mps": sg.velocity_out,
    }
    summary["truth_initial"] = truth_initial
    summary["smoother_start"] = "dispersion refined state" if start is None else "given"
    summary["accepted_members"] = int(idx.size)
    summary["accepted_effective_sample_size"] = ess
    summary["distinct_members_used"] = int(np.unique(res.member).size)
    summary["gap_noise_in_truth"] = bool(gap_noise)
    summary["constrained"] = bool(constrained)
    res.summary.update(summary)
    return res


def aggregate_runs(
    outs: Sequence[RunScores],
    t: np.ndarray,
    *,
    n_runs: int,
    seed: int,
    t_fix: float,
    times: Mapping[str, float],
    executor: str,
    wall_s: float,
) -> ValidationResult:
    """A :class:`ValidationResult` (without its summary) from the per-run scores ``outs`` on the
    common grid ``t`` (n,) [s]: ANEES(t) and RMS curves over the successful runs, the 95 % band,
    per-run scalars.  ``t_fix`` [s] first radar time tag, ``times`` {label: t [s]} the summary
    epochs, ``executor`` and ``wall_s`` [s] as reported."""
    failed = np.array([o.failed for o in outs])
    ok = [o for o in outs if not o.failed]
    n_ok = len(ok)
    k = len(ERROR_NAMES)
    curves = ("nees", "nees_curvilinear", "nees_forward", "nees_forward_curvilinear")
    if n_ok:
        s2 = np.zeros((t.size, k))
        s1 = np.zeros((t.size, k))
        q2 = np.zeros((t.size, k))
        acc = {c: np.zeros(t.size) for c in curves}
        for o in ok:  # fixed order: deterministic sums
            e = o.err.astype(np.float64)
            s2 += e * e
            s1 += e
            sd = o.sig.astype(np.float64)
            q2 += sd * sd
            for c in curves:
                acc[c] += getattr(o, c)
        rms_error, mean_error, rms_sigma = np.sqrt(s2 / n_ok), s1 / n_ok, np.sqrt(q2 / n_ok)
        an = {c: a / n_ok for c, a in acc.items()}
        band = anees_bounds(9, n_ok)
    else:
        rms_error = mean_error = rms_sigma = np.full((t.size, k), np.nan)
        an = {c: np.full(t.size, np.nan) for c in curves}
        band = (math.nan, math.nan)
    res = ValidationResult(
        t=t,
        n_runs=int(n_runs),
        seed=int(seed),
        member=np.array([o.member for o in outs]),
        failed=failed,
        messages=tuple(o.message for o in outs),
        nees=np.stack([o.nees for o in outs]),
        nees_curvilinear=np.stack([o.nees_curvilinear for o in outs]),
        anees=an["nees"],
        anees_curvilinear=an["nees_curvilinear"],
        anees_forward=an["nees_forward"],
        anees_forward_curvilinear=an["nees_forward_curvilinear"],
        anees_band=(float(band[0]), float(band[1])),
        rms_error=rms_error,
        mean_error=mean_error,
        rms_sigma=rms_sigma,
        nees_time_avg=np.array([float(np.mean(o.nees, dtype=np.float64)) for o in outs]),
        nees_curvilinear_time_avg=np.array([float(np.mean(o.nees_curvilinear, dtype=np.float64)) for o in outs]),
        inside_3sigma=np.array([o.inside_3sigma for o in outs]),
        inside_3sigma_curvilinear=np.array([o.inside_3sigma_curvilinear for o in outs]),
        h_err_max_after_fix=np.array([o.h_err_max_after_fix for o in outs]),
        h_3sigma_at_max=np.array([o.h_3sigma_at_max for o in outs]),
        h_inside_after_fix=np.array([o.h_inside_after_fix for o in outs]),
        nis_mean=np.stack([o.nis_mean for o in outs]),
        run_wall_s=np.array([o.wall_s for o in outs]),
        t_fix=t_fix,
        times=dict(times),
        executor=executor,
        wall_s=float(wall_s),
    )
    return res


def summarize_validation(res: ValidationResult, probability: float = 0.95) -> dict:
    """JSON-ready statistics of a :class:`ValidationResult`.

    * ``anees_at`` {epoch: ANEES} of the smoothed state (Cartesian error state) at the summary
      epochs (start, blackout end, PDD, first radar, end; the IMU sample at or after the epoch),
      each an average of n_ok independent χ²(9) values if consistent, against ``anees_band`` =
      ``anees_bounds(9, n_ok, probability)``, ``anees_at_inside`` per epoch; the same for the
      curvilinear position error (``anees_curvilinear_at``, ``..._inside``) and for the forward
      pass (``anees_forward_at``, ``anees_forward_curvilinear_at``);
    * ``anees_time_avg`` (and ``_curvilinear``, ``_forward``, ``_forward_curvilinear``): mean over
      runs and steps (steps are strongly correlated: the band is only indicative for it);
      ``anees_fraction_of_steps_in_band`` (and ``_curvilinear``) of the ANEES(t) curve;
    * ``rms_at`` {epoch: {quantity: RMS error}} and ``rms_sigma_at`` (RMS of the reported 1σ) with
      the units of :data:`ERROR_UNITS` except attitude in degrees; ``rms_horizontal_m`` at the
      epochs; ``rms_max_after_fix`` the max over the steps after the fix;
    * ``h_agl_after_fix``: max over runs of the max |altitude-AGL error| [m], the median 3σ at
      those maxima, the fraction of runs whose max lies inside its 3σ, the mean fraction of steps
      inside 3σ, runs within 50 m;
    * ``inside_3sigma_mean`` (and ``_curvilinear``) fraction of (step, state) pairs with
      |e| ≤ 3σ (0.9973 expected);
    * ``nis_mean`` per radar channel with its dof; wall times [s]; failed runs.
    """
    ok = ~res.failed
    n_ok = int(ok.sum())
    lo, hi = anees_bounds(9, max(n_ok, 1), probability)
    conv = np.array([180.0 / math.pi if u == "rad" else 1.0 for u in res.error_units])
    unit = [u if u != "rad" else "deg" for u in res.error_units]
    names = [f"{n} [{u}]" for n, u in zip(res.error_names, unit, strict=True)]
    curves = {
        "": res.anees,
        "_curvilinear": res.anees_curvilinear,
        "_forward": res.anees_forward,
        "_forward_curvilinear": res.anees_forward_curvilinear,
    }
    at = {c: {} for c in curves}
    rms_at, rsig_at, rms_h = {}, {}, {}
    for label, te in res.times.items():
        i = index_at(res.t, te)
        for c, a in curves.items():
            at[c][label] = float(a[i])
        rms_at[label] = {nm: float(v) for nm, v in zip(names, res.rms_error[i] * conv, strict=True)}
        rsig_at[label] = {nm: float(v) for nm, v in zip(names, res.rms_sigma[i] * conv, strict=True)}
        rms_h[label] = float(np.hypot(res.rms_error[i, 0], res.rms_error[i, 1]))
    after = res.t >= res.t_fix
    hm = res.h_err_max_after_fix[ok]
    h3 = res.h_3sigma_at_max[ok]
    out = {
        "n_runs": int(res.n_runs),
        "n_ok": n_ok,
        "n_failed": int(res.failed.sum()),
        "failures": sorted({m for m in res.messages if m})[:5],
        "seed": int(res.seed),
        "dof": 9,
        "band_probability": probability,
        "anees_band": [float(lo), float(hi)],
        "times_s": dict(res.times),
        **{f"anees{c}_at": at[c] for c in curves},
        "anees_at_inside": {k: bool(lo <= v <= hi) for k, v in at[""].items()},
        "anees_curvilinear_at_inside": {k: bool(lo <= v <= hi) for k, v in at["_curvilinear"].items()},
        **{f"anees{c}_time_avg": float(np.nanmean(a)) for c, a in curves.items()},
        "anees_time_avg_note": "steps within a run are correlated: the band is only indicative for the time average",
        "anees_fraction_of_steps_in_band": fraction_inside(res.anees, lo, hi),
        "anees_curvilinear_fraction_of_steps_in_band": fraction_inside(res.anees_curvilinear, lo, hi),
        "rms_at": rms_at,
        "rms_sigma_at": rsig_at,
        "rms_horizontal_m": rms_h,
        "inside_3sigma_mean": float(np.nanmean(res.inside_3sigma)) if n_ok else math.nan,
        "inside_3sigma_curvilinear_mean": float(np.nanmean(res.inside_3sigma_curvilinear)) if n_ok else math.nan,
        "nis_mean": {
            ch: {"value": float(np.nanmean(res.nis_mean[ok, c])) if n_ok else math.nan, "dof": _NIS_DOF[ch]}
            for c, ch in enumerate(CHANNELS)
        },
        "total_wall_s": float(res.wall_s),
        "run_wall_median_s": float(np.median(res.run_wall_s)),
        "executor": res.executor,
    }
    if after.any() and n_ok:
        out["rms_max_after_fix"] = {
            nm: float(v) for nm, v in zip(names, np.nanmax(res.rms_error[after], axis=0) * conv, strict=True)
        }
        out["h_agl_after_fix"] = {
            "t_fix_s": float(res.t_fix),
            "max_error_m": float(np.nanmax(hm)),
            "median_max_error_m": float(np.nanmedian(hm)),
            "median_3sigma_at_max_m": float(np.nanmedian(h3)),
            "fraction_runs_max_inside_3sigma": float(np.mean(hm <= h3)),
            "fraction_runs_within_50m": float(np.mean(hm <= 50.0)),
            "mean_fraction_steps_inside_3sigma": float(np.nanmean(res.h_inside_after_fix[ok])),
        }
    return out


# ---------------------------------------------------------------------------------------------
# inputs from a scenario (CLI, benchmark)


@dataclass(frozen=True)
class ValidationInputs:
    """What :func:`validate_smoother` needs, prepared from a scenario's telemetry by
    :func:`prepare_validation`: the telemetry and preprocessed IMU, the nominal state, the
    dispersion, the valid radar time tags, beams, terrain radius, filter sigmas, constrained flag,
    event times, and the smoother start the pipeline would use (``start_mode`` "dispersion" |
    "fused" | "nominal", ``start`` (v0, q0, p0, P0), ``start_note``)."""

    telemetry: Any
    imu: Any
    nominal: tuple[np.ndarray, np.ndarray, np.ndarray]
    dispersion: Any
    radar_times: tuple[np.ndarray, np.ndarray]
    beams_G: np.ndarray
    r_ground: float
    sigmas: dict
    constrained: bool
    events: dict
    start_mode: str = "dispersion"
    start: tuple | None = None
    start_note: str = ""

    def validation_kwargs(self) -> dict:
        """Keyword arguments of :func:`validate_smoother` for these inputs: the pipeline's smoother
        start; truths from the accepted set for the paper's "dispersion" start, else drawn from the
        start's own Gaussian (docs/tuning/entry.md)."""
        kw = dict(
            sigmas=self.sigmas,
            beams_G=self.beams_G,
            r_ground=self.r_ground,
            constrained=self.constrained,
            events=self.events,
        )
        if self.start_mode != "dispersion" and self.start is not None:
            kw.update(start=self.start, truth_initial="gaussian")
        return kw


def prepare_validation(
    settings: EntrySettings, paths: Mapping[str, Path], *, members: int | None = None, scheduler: str | None = None
) -> ValidationInputs:
    """The reconstruction stages up to the dispersion (AMELIA Sects. 4-6), configured as
    :func:`workbench.problems.entry.pipeline.reconstruct` configures them — from the same
    :class:`~workbench.problems.entry.config.EntrySettings`: read the telemetry ``paths``
    (with the run's telemetry checks), preprocess, the nominal initial state
    (``paths["initial_state"]``, required), and the dispersion with the scenario's ``[dispersion]``
    settings (``members`` overrides the member count; ``scheduler`` runs it on Dask); the smoother
    start of ``[reconstruction] initial``.  Radar time tags are the valid packets'."""
    cfg = settings
    if "initial_state" not in paths or not Path(paths["initial_state"]).exists():
        # the estimator never reads truth.npz, not even for the nominal state
        raise FileNotFoundError("prepare_validation: no initial_state file among the telemetry paths")
    tm = read_entry_telemetry(paths, cfg.checks)
    imu = preprocess(tm, cfg.preprocess)
    nom = read_nominal_state(paths["initial_state"])
    v0, q0, p0 = nom.v_M, nom.q_M_G, nom.p_M
    r_ground = cfg.r_ground
    disp = run_configured_dispersion(cfg, imu, nom, tm.events, members=members, scheduler=scheduler, n_cloud=0)
    rec = cfg.reconstruction
    st = initial_for_smoother(rec, disp, nom, reconstruction_P0(rec))  # the pipeline's smoother start
    beams = cfg.radar.beams_G()
    sr_ok = np.asarray(tm.sr_valid, bool)
    rda_ok = np.asarray(tm.rda_valid, bool)
    return ValidationInputs(
        telemetry=tm,
        imu=imu,
        nominal=(np.asarray(v0, float), np.asarray(q0, float), np.asarray(p0, float)),
        dispersion=disp,
        radar_times=(np.asarray(tm.t_sr, float)[sr_ok], np.asarray(tm.t_rda, float)[rda_ok]),
        beams_G=beams,
        r_ground=float(r_ground),
        sigmas=cfg.smoother_sigmas(),
        constrained=cfg.radar.constrained,
        events=dict(tm.events),
        start_mode=st.mode,
        start=(st.v0, st.q0, st.p0, st.P0),
        start_note=st.note,
    )


def _unit_key(name: str) -> str:
    """'pos_N [m]' -> 'pos_N_m', 'vel_N [m/s]' -> 'vel_N_mps', 'att_x [deg]' -> 'att_x_deg'."""
    base, _, unit = name.partition(" [")
    unit = unit.rstrip("]").replace("m/s", "mps")
    return f"{base}_{unit}" if unit else base


def headline_numbers(summary: Mapping[str, Any]) -> dict:
    """The headline numbers of a :func:`summarize_validation` summary with SI-unit key names (the
    benchmark JSON convention): ANEES (9 dof) per epoch — smoothed and forward, Cartesian and
    curvilinear — with the 95 % χ² band and whether it is inside, the time averages, the fraction
    of steps of the ANEES(t) curve inside the band, the RMS error vs the RMS reported 1σ at the end,
    the altitude-AGL error after the first radar fix (``h_agl_after_fix``, and ``h_agl_at_fix``
    when the summary has it) and the mean NIS per radar channel."""
    s = summary
    lo, hi = s["anees_band"]
    at = {}
    for ep in s["anees_at"]:
        at[ep] = {
            "t_s": s["times_s"][ep],
            "smoothed": s["anees_at"][ep],
            "smoothed_curvilinear": s["anees_curvilinear_at"][ep],
            "forward": s["anees_forward_at"][ep],
            "forward_curvilinear": s["anees_forward_curvilinear_at"][ep],
            "smoothed_inside_band": bool(lo <= s["anees_at"][ep] <= hi),
            "smoothed_curvilinear_inside_band": bool(lo <= s["anees_curvilinear_at"][ep] <= hi),
            "forward_inside_band": bool(lo <= s["anees_forward_at"][ep] <= hi),
            "forward_curvilinear_inside_band": bool(lo <= s["anees_forward_curvilinear_at"][ep] <= hi),
        }
    end = s["rms_at"].get("end", {})
    end_sig = s["rms_sigma_at"].get("end", {})
    out = {
        "n_runs": s["n_runs"],
        "n_ok": s["n_ok"],
        "n_failed": s["n_failed"],
        "dof": s["dof"],
        "anees_band_95": [lo, hi],
        "anees_at": at,
        "anees_time_avg": {
            "smoothed": s["anees_time_avg"],
            "smoothed_curvilinear": s["anees_curvilinear_time_avg"],
            "forward": s["anees_forward_time_avg"],
            "forward_curvilinear": s["anees_forward_curvilinear_time_avg"],
            "note": s["anees_time_avg_note"],
        },
        "fraction_of_steps_in_band": {
            "smoothed": s["anees_fraction_of_steps_in_band"],
            "smoothed_curvilinear": s["anees_curvilinear_fraction_of_steps_in_band"],
        },
        "rms_at_end": {_unit_key(k): {"rms_error": v, "rms_sigma": end_sig.get(k, math.nan)} for k, v in end.items()},
        "inside_3sigma_fraction": {
            "cartesian": s["inside_3sigma_mean"],
            "curvilinear": s["inside_3sigma_curvilinear_mean"],
        },
        "nis_mean": {ch: {"value": v["value"], "dof": v["dof"]} for ch, v in s["nis_mean"].items()},
    }
    if "h_agl_after_fix" in s:
        out["h_agl_after_fix"] = dict(s["h_agl_after_fix"])
    if "h_agl_at_fix" in s:
        out["h_agl_at_fix"] = dict(s["h_agl_at_fix"])
    for key in ("radar_noise", "radar_noise_simulated", "filter_R"):
        if key in s:
            out[key] = dict(s[key])
    return out
