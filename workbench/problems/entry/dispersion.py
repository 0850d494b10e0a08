"""Dispersion analysis of the entry initial state (AMELIA Sect. 6), vectorised over members.

Members: initial states sampled about the nominal ``(v0, q0, p0)`` with the error-state offsets
``dx0 = [δv_M, δθ_G, δp_M]`` (``v = v0 + δv``, ``q = q0 ⊗ exp(δθ)``, ``p = p0 + δp``), 1σ per
block from :class:`DispersionSigmas` (AMELIA Table 3: attitude 5°, velocity 0.5 km/s, position
10 km).  Every member is integrated through the same preprocessed IMU data (with the same gap
bridges) by :func:`workbench.estimation.ensemble.integrate_ensemble` — the attitude integrated once
for all members (``q_i = q0_i ⊗ Δq``, :func:`~workbench.estimation.ensemble.attitude_track`) and
the translational RK4 per member, compiled with numba when available; the same RK4 as
:func:`workbench.estimation.strapdown.integrate_members` up to rounding — and only its event
quantities are kept:

* ``mach_pdd`` — Mach at parachute deployment: speed relative to the co-rotating air (no wind),
  ``|v − Ω×p|`` with ``Ω = [0, 0, MARS.rotation_rate]`` in M, over the speed of sound of the
  default atmosphere (:class:`~workbench.core.atmosphere.MarsEngineeringAtmosphere`) at h_amr;
* ``h_pdd``, ``h_fsr``, ``h_end`` — altitudes above the MOLA radius ``|p| − 3396000`` [m] at PDD,
  FSR and the end of the data (BSR);
* ``time_to_impact`` — from the end state, falling vertically under gravity alone
  (``g = GM/r²``, initial radial velocity ``v·p̂``) to the terrain sphere ``r = 3396000 − 1440`` [s].

A member is accepted when every quantity lies inside its :class:`AcceptanceRules` band (centre ±
half-width).  The refined initial state is the mean of the accepted members (attitude: the mean
error vector about the nominal, ``q0 ⊗ exp(mean δθ)``); ``refined_P0`` is the 9x9 covariance of
their spread.  The paper instead quotes "the standard deviation of the initial states of the
selected trajectories" as one isotropic 1σ per block (Table 3: 1°, 0.01 km/s, 2 km):
``refined_sigma_max`` keeps that reading — the maximum over the three axes of each block's
standard deviation about the mean.

Randomness and scheduling: members are drawn in fixed blocks of :data:`SAMPLE_BLOCK`; block b
uses ``np.random.SeedSequence(seed, spawn_key=(b,))``, so a member's offsets depend only on
``(seed, member index)`` — not on the chunk size, the scheduler or the number of workers.  The
integration is member-wise element arithmetic, so results are bit-identical in-process, in a
process pool, on a Dask cluster (chunks run by :func:`workbench.estimation.montecarlo.run_monte_carlo`),
with either backend, and in the per-member loop baseline (:func:`run_dispersion_loop`).
Memory: only dx0 (n, 9), the five event quantities and a thinned position cloud (≤ n_cloud
members at ~1 Hz) are kept; a chunk's working set is a few MB.
"""

from __future__ import annotations

import multiprocessing as mp
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from workbench.core.atmosphere import Atmosphere, MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.rotation import quat_from_rotvec, quat_multiply, quat_normalize
from workbench.estimation.ensemble import AttitudeTrack, attitude_track, default_backend, integrate_ensemble
from workbench.estimation.montecarlo import run_monte_carlo
from workbench.estimation.strapdown import ImuArrays, imu_arrays
from workbench.io import progress
from workbench.problems.entry.site import R_GROUND, R_MOLA
from workbench.problems.entry.state import DP, DTH, DV

__all__ = [
    "SAMPLE_BLOCK",
    "EVENT_NAMES",
    "AcceptanceRules",
    "DispersionSigmas",
    "DispersionResult",
    "sample_offsets",
    "sigma_vector",
    "event_quantities",
    "run_dispersion",
    "run_dispersion_loop",
    "run_configured_dispersion",
    "FusedInitialState",
    "fuse_with_prior",
]

#: Members per random-number block (block b has its own SeedSequence ``(seed, spawn_key=(b,))``).
SAMPLE_BLOCK = 250
#: Names of the event quantities, in the order of :class:`AcceptanceRules`' fields.
EVENT_NAMES = ("mach_pdd", "h_pdd", "h_fsr", "h_end", "time_to_impact")
_OMEGA_Z = MARS.rotation_rate


@dataclass(frozen=True)
class AcceptanceRules:
    """Acceptance bands ``(centre, half-width)`` of the event quantities (AMELIA Sect. 6 defaults).

    ``mach_pdd`` [-] Mach at PDD; ``h_pdd_m``, ``h_fsr_m``, ``h_end_m`` [m] altitude above the MOLA
    radius at PDD, FSR and the end of the data; ``time_to_impact_s`` [s] from the end of the data to
    the ballistic impact.  A value is inside when ``|x − centre| ≤ half-width``.
    """

    mach_pdd: tuple[float, float] = (2.0, 0.2)
    h_pdd_m: tuple[float, float] = (10e3, 2e3)
    h_fsr_m: tuple[float, float] = (6e3, 2e3)
    h_end_m: tuple[float, float] = (3e3, 2e3)
    time_to_impact_s: tuple[float, float] = (40.0, 15.0)

    def bands(self) -> dict[str, tuple[float, float]]:
        """``{event name: (centre, half-width)}`` keyed by :data:`EVENT_NAMES`."""
        vals = (self.mach_pdd, self.h_pdd_m, self.h_fsr_m, self.h_end_m, self.time_to_impact_s)
        return {k: (float(c), float(hw)) for k, (c, hw) in zip(EVENT_NAMES, vals, strict=True)}

    def checks(self, events: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Per-rule pass flags ``{name: (n,) bool}`` (NaN fails)."""
        return {k: np.abs(np.asarray(events[k], dtype=float) - c) <= hw for k, (c, hw) in self.bands().items()}

    def accept(self, events: Mapping[str, np.ndarray]) -> np.ndarray:
        """(n,) bool: all rules satisfied."""
        return np.logical_and.reduce(list(self.checks(events).values()))

    def score(self, events: Mapping[str, np.ndarray]) -> np.ndarray:
        """(n,) worst normalised violation ``max_k |x_k − c_k| / hw_k`` (≤ 1 ⇔ accepted; NaN → inf)."""
        s = np.stack([np.abs(np.asarray(events[k], dtype=float) - c) / hw for k, (c, hw) in self.bands().items()])
        return np.where(np.isnan(s), np.inf, s).max(axis=0)


@dataclass(frozen=True)
class DispersionSigmas:
    """1σ of the sampled initial-state offsets (AMELIA Table 3, dispersion column), SI.

    ``velocity_m_s`` [m/s] per axis of δv_M, ``attitude_rad`` [rad] per axis of δθ_G (body),
    ``position_m`` [m] per axis of δp_M.
    """

    velocity_m_s: float = 500.0
    attitude_rad: float = float(np.deg2rad(5.0))
    position_m: float = 10e3

    def vector(self) -> np.ndarray:
        """(9,) standard deviations in the error-state order [δv, δθ, δp]."""
        return np.repeat([self.velocity_m_s, self.attitude_rad, self.position_m], 3).astype(float)


@dataclass(frozen=True)
class DispersionResult:
    """Outcome of a dispersion analysis (SI; frame M; error-state order [δv, δθ, δp]).

    ``n`` members; ``seed``; ``chunk_size``; ``dx0`` (n, 9) sampled offsets from the nominal;
    ``events`` {name: (n,)} of :data:`EVENT_NAMES` (Mach [-], altitudes AMR [m], time to impact
    [s]); ``accepted`` (n,) bool; ``refined_v0`` (3,) [m/s], ``refined_q0`` (4,) ``q_M_G``,
    ``refined_p0`` (3,) [m] the mean accepted initial state; ``refined_P0`` (9, 9) covariance of the
    accepted offsets (NaN if fewer than two accepted); ``cloud_t`` (k,) [s] the thinned time grid;
    ``cloud_p_M`` (m, k, 3) [m] positions of the ``m ≤ n_cloud`` cloud members (accepted and
    rejected mixed), ``cloud_accepted`` (m,) bool, ``cloud_index`` (m,) member indices;
    ``wall_s`` [s] wall time of the member integration; ``scheduler`` description.
    Extras: ``refined_sigma_max`` (3,) the paper's isotropic 1σ per block [m/s, rad, m] (max over
    axes of the accepted spread); ``sigmas`` (9,) the sampling 1σ; ``rules`` the acceptance rules;
    ``events_t`` {"PDD", "FSR", "BSR"} event times [s]; ``checks`` {name: (n,) bool} per-rule flags;
    ``score`` (n,) worst normalised rule violation (:meth:`AcceptanceRules.score`, ≤ 1 accepted);
    ``weights`` (n,) importance weights of the members (all 1 without refinement rounds);
    ``rounds`` one dict per sampling round (``round``, ``n_accepted``, ``proposal_sigma`` (9,),
    ``ess`` effective sample size of the accepted weights, ``wall_s``).  With refinement rounds,
    ``dx0``/``events``/``accepted``/the cloud are those of the **last** round.
    """

    n: int
    seed: int
    chunk_size: int
    dx0: np.ndarray
    events: dict[str, np.ndarray]
    accepted: np.ndarray
    refined_v0: np.ndarray
    refined_q0: np.ndarray
    refined_p0: np.ndarray
    refined_P0: np.ndarray
    cloud_t: np.ndarray
    cloud_p_M: np.ndarray
    cloud_accepted: np.ndarray
    cloud_index: np.ndarray
    wall_s: float
    scheduler: str
    refined_sigma_max: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    sigmas: np.ndarray = field(default_factory=lambda: np.full(9, np.nan))
    rules: AcceptanceRules = field(default_factory=AcceptanceRules)
    events_t: dict[str, float] = field(default_factory=dict)
    checks: dict[str, np.ndarray] = field(default_factory=dict)
    score: np.ndarray = field(default_factory=lambda: np.zeros(0))
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rounds: list[dict] = field(default_factory=list)

    @property
    def n_accepted(self) -> int:
        """Number of accepted members."""
        return int(np.count_nonzero(self.accepted))

    @property
    def accepted_fraction(self) -> float:
        """Accepted fraction of the members."""
        return self.n_accepted / max(self.n, 1)


# ---------------------------------------------------------------------------------------------
# pure pieces


def sample_offsets(
    seed: int,
    start: int,
    stop: int,
    sigmas: np.ndarray,
    *,
    round_index: int = 0,
    mean: np.ndarray | None = None,
    L: np.ndarray | None = None,
) -> np.ndarray:
    """Offsets dx0 (stop − start, 9) of members ``start..stop−1``: N(0, diag(sigmas²)).

    Drawn block by block (:data:`SAMPLE_BLOCK` members per block, block b seeded by
    ``SeedSequence(seed, spawn_key=(b,))``; refinement round r > 0 by ``spawn_key=(b, r)``), so
    member i's offsets depend only on (seed, round, i).  With ``L`` (9, 9) (a Cholesky factor)
    and ``mean`` (9,) the offsets are ``mean + L z`` instead (``sigmas`` unused), evaluated
    column by column so that every member's value is independent of the chunk it is in.
    """
    out = np.empty((stop - start, 9))
    for b in range(start // SAMPLE_BLOCK, (stop - 1) // SAMPLE_BLOCK + 1 if stop > start else 0):
        key = (b,) if round_index == 0 else (b, int(round_index))
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=key)))
        z = rng.standard_normal((SAMPLE_BLOCK, 9))
        lo, hi = max(start, b * SAMPLE_BLOCK), min(stop, (b + 1) * SAMPLE_BLOCK)
        out[lo - start : hi - start] = z[lo - b * SAMPLE_BLOCK : hi - b * SAMPLE_BLOCK]
    if L is None:
        out = out * np.asarray(sigmas, dtype=float)
        return out if mean is None else out + mean
    L = np.asarray(L, dtype=float)
    dx = np.broadcast_to(np.zeros(9) if mean is None else np.asarray(mean, dtype=float), out.shape).copy()
    for j in range(9):
        dx += out[:, j : j + 1] * L[:, j]
    return dx


def member_states(v0, q0, p0, dx0):
    """Initial states (m, ·) of the members with offsets dx0 (m, 9)."""
    v = np.asarray(v0, dtype=float) + dx0[:, DV]
    q = quat_normalize(quat_multiply(np.asarray(q0, dtype=float), quat_from_rotvec(dx0[:, DTH])))
    p = np.asarray(p0, dtype=float) + dx0[:, DP]
    return v, q, p


def _norm(x: np.ndarray) -> np.ndarray:
    return np.sqrt(x[..., 0] * x[..., 0] + x[..., 1] * x[..., 1] + x[..., 2] * x[..., 2])


def event_quantities(
    p_at: np.ndarray, v_at: np.ndarray, atmosphere: Atmosphere, r_ground: float = R_GROUND
) -> dict[str, np.ndarray]:
    """Event quantities of members from their states at (PDD, FSR, end): p_at, v_at (3, m, 3) [m, m/s].

    Returns {name: (m,)} for :data:`EVENT_NAMES` (see module docstring).  Mach uses the speed
    relative to the co-rotating atmosphere (no wind); the time to impact is the vertical
    gravity-only fall from the end state to ``r_ground`` [m] (0 if already below it).
    """
    r_ref = R_MOLA
    p, v = p_at[0], v_at[0]
    vr = np.stack([v[..., 0] + _OMEGA_Z * p[..., 1], v[..., 1] - _OMEGA_Z * p[..., 0], v[..., 2]], -1)
    h_pdd = _norm(p) - r_ref
    mach = _norm(vr) / atmosphere.speed_of_sound(h_pdd)
    h_fsr = _norm(p_at[1]) - r_ref
    pe, ve = p_at[2], v_at[2]
    r = _norm(pe)
    h_agl = np.maximum(r - r_ground, 0.0)
    v_up = (pe[..., 0] * ve[..., 0] + pe[..., 1] * ve[..., 1] + pe[..., 2] * ve[..., 2]) / r
    g = MARS.gm / (r * r)
    tti = (v_up + np.sqrt(v_up * v_up + 2.0 * g * h_agl)) / g
    return {"mach_pdd": mach, "h_pdd": h_pdd, "h_fsr": h_fsr, "h_end": r - r_ref, "time_to_impact": tti}


@dataclass(frozen=True)
class _Job:
    """Everything a chunk task needs (shipped once to each worker)."""

    imu: ImuArrays
    v0: np.ndarray
    q0: np.ndarray
    p0: np.ndarray
    sigmas: np.ndarray
    seed: int
    event_times: np.ndarray  # (3,) PDD, FSR, end
    atmosphere: Atmosphere
    bridge_mode: str
    r_ground: float
    track: AttitudeTrack | None = None
    backend: str = "numba"
    round_index: int = 0
    mean: np.ndarray | None = None
    L: np.ndarray | None = None


def _threads() -> int | None:
    """Kernel threads: one inside a worker process (the executor already uses the cores), else all."""
    return 1 if mp.parent_process() is not None else None


def _event_states(job: _Job, v, q, p, backend: str) -> tuple[np.ndarray, np.ndarray]:
    """States (p_at, v_at) (3, m, 3) of members at the event times: linear between the bracketing
    samples (as ``strapdown.integrate_members``' ``at_t``)."""
    t = job.track.t
    jj = np.clip(np.searchsorted(t, job.event_times, side="right") - 1, 0, t.size - 2)
    ww = (job.event_times - t[jj]) / (t[jj + 1] - t[jj])
    rec = np.unique(np.concatenate([jj, jj + 1]))
    V, P = integrate_ensemble(job.track, v, q, p, rec, body=MARS, backend=backend, threads=_threads())
    i0, i1 = np.searchsorted(rec, jj), np.searchsorted(rec, jj + 1)
    v_at = np.empty((jj.size, *V.shape[1:]))
    p_at = np.empty((jj.size, *P.shape[1:]))
    for i, a in enumerate(ww):
        v_at[i] = (1.0 - a) * V[i0[i]] + a * V[i1[i]]
        p_at[i] = (1.0 - a) * P[i0[i]] + a * P[i1[i]]
    return p_at, v_at


def member_offsets(job: _Job, start: int, stop: int) -> np.ndarray:
    """Initial-state offsets (stop − start, 9) [rad, m/s, m] of members ``start..stop−1`` of the
    job's current round (deterministic in the job's seed and round)."""
    return sample_offsets(job.seed, start, stop, job.sigmas, round_index=job.round_index, mean=job.mean, L=job.L)


def _run_chunk(job: _Job, start: int, stop: int, seeds=None) -> tuple[int, np.ndarray, dict[str, np.ndarray]]:
    """Integrate members start..stop−1 together; returns (start, dx0, events).

    A chunk task of :func:`~workbench.estimation.montecarlo.run_monte_carlo`; ``seeds`` is unused (None):
    the members' offsets come from :func:`sample_offsets`' blocks."""
    dx0 = member_offsets(job, start, stop)
    v, q, p = member_states(job.v0, job.q0, job.p0, dx0)
    p_at, v_at = _event_states(job, v, q, p, job.backend)
    ev = event_quantities(p_at, v_at, job.atmosphere, job.r_ground)
    return start, dx0, ev


def _run_loop(job: _Job, start: int, stop: int) -> tuple[int, np.ndarray, dict[str, np.ndarray]]:
    """The per-trajectory baseline: the same maths, one member at a time on Python floats
    (``integrate_ensemble(backend="python")``, sharing the job's attitude track)."""
    dx0 = member_offsets(job, start, stop)
    v, q, p = member_states(job.v0, job.q0, job.p0, dx0)
    evs = {k: np.empty(stop - start) for k in EVENT_NAMES}
    for i in range(stop - start):
        p_at, v_at = _event_states(job, v[i : i + 1], q[i : i + 1], p[i : i + 1], "python")
        ev = event_quantities(p_at, v_at, job.atmosphere, job.r_ground)
        for k in EVENT_NAMES:
            evs[k][i] = ev[k][0]
    return start, dx0, evs


def _event_times(imu: ImuArrays, events_t: Mapping[str, float]) -> tuple[np.ndarray, dict[str, float]]:
    try:
        t_pdd, t_fsr = float(events_t["PDD"]), float(events_t["FSR"])
    except KeyError as err:
        raise ValueError(f"run_dispersion: events_t needs 'PDD' and 'FSR' (got {sorted(events_t)})") from err
    t_end = float(events_t.get("BSR", imu.t[-1]))
    t_end = min(t_end, float(imu.t[-1]))
    return np.array([t_pdd, t_fsr, t_end]), {"PDD": t_pdd, "FSR": t_fsr, "BSR": t_end}


def sigma_vector(sigmas: Any) -> np.ndarray:
    """The (9,) 1σ of the initial-state offsets ``[δv_M (m/s), δθ_G (rad), δp_M (m)]`` from
    ``None`` (the defaults of :class:`DispersionSigmas`), a :class:`DispersionSigmas`, a mapping
    ``{velocity|velocity_m_s, attitude|attitude_rad, position|position_m}``, a (3,) per block or a
    (9,) per state; ``ValueError`` for an unknown key or shape."""
    if sigmas is None:
        return DispersionSigmas().vector()
    if isinstance(sigmas, DispersionSigmas):
        return sigmas.vector()
    if isinstance(sigmas, Mapping):
        d = DispersionSigmas()
        keys = {"velocity": "velocity_m_s", "attitude": "attitude_rad", "position": "position_m"}
        unknown = set(sigmas) - set(keys) - set(keys.values())
        if unknown:
            raise ValueError(
                f"sigmas: unknown keys {sorted(unknown)}; use velocity [m/s], attitude [rad], position [m]"
            )
        kw = {keys.get(k, k): float(v) for k, v in sigmas.items()}
        return DispersionSigmas(**{**d.__dict__, **kw}).vector()
    s = np.asarray(sigmas, dtype=float)
    if s.shape == (3,):
        return np.repeat(s, 3)
    if s.shape != (9,):
        raise ValueError("sigmas: DispersionSigmas, a mapping, (3,) per block [m/s, rad, m] or (9,) per state")
    return s


def _pick_cloud(accepted: np.ndarray, n_cloud: int) -> np.ndarray:
    """≤ n_cloud member indices, half accepted and half rejected where possible, evenly spread."""
    acc, rej = np.flatnonzero(accepted), np.flatnonzero(~accepted)
    n_acc = min(acc.size, max(n_cloud // 2, n_cloud - rej.size))
    n_rej = min(rej.size, n_cloud - n_acc)

    def spread(ix, k):
        if k <= 0:
            return ix[:0]
        return ix[np.unique(np.linspace(0, ix.size - 1, k).round().astype(int))]

    return np.sort(np.concatenate([spread(acc, n_acc), spread(rej, n_rej)]))


def _combine(parts) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    parts = sorted(parts, key=lambda r: r[0])
    dx0 = np.concatenate([r[1] for r in parts])
    return dx0, {k: np.concatenate([r[2][k] for r in parts]) for k in EVENT_NAMES}


def _log_normal(dx: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """log N(dx; mean, cov) up to the common constant, (n,)."""
    L = np.linalg.cholesky(cov)
    y = np.linalg.solve(L, (dx - mean).T)
    return -0.5 * np.sum(y * y, axis=0) - np.sum(np.log(np.diagonal(L)))


def _finish(
    job: _Job,
    dx0: np.ndarray,
    events: dict[str, np.ndarray],
    *,
    n: int,
    chunk_size: int,
    rules: AcceptanceRules,
    n_cloud: int,
    cloud_dt: float,
    wall: float,
    executor: str,
    events_t: dict[str, float],
    weights: np.ndarray | None = None,
    rounds: list[dict] | None = None,
) -> DispersionResult:
    checks = rules.checks(events)
    accepted = np.logical_and.reduce(list(checks.values()))
    acc = dx0[accepted]
    if weights is None:  # the paper's plain mean and spread
        mean = acc.mean(axis=0) if acc.shape[0] else np.zeros(9)
        P0 = np.cov(acc, rowvar=False) if acc.shape[0] >= 2 else np.full((9, 9), np.nan)
    else:  # importance-weighted (refinement rounds): estimates of the same prior-restricted moments
        w = weights[accepted]
        mean = np.average(acc, axis=0, weights=w) if acc.shape[0] else np.zeros(9)
        P0 = np.cov(acc, rowvar=False, aweights=w) if acc.shape[0] >= 2 else np.full((9, 9), np.nan)
    sig_max = np.sqrt(np.diagonal(P0)).reshape(3, 3).max(axis=1)
    v_r, q_r, p_r = member_states(job.v0, job.q0, job.p0, mean[None])
    # thinned cloud: re-integrate the chosen members (bit-identical to their chunk) at ~1/cloud_dt Hz
    t = job.imu.t
    idx_t = np.unique(np.searchsorted(t, np.arange(t[0], t[-1], cloud_dt)).clip(0, t.size - 1))
    idx_t = np.unique(np.append(idx_t, t.size - 1))
    cloud_index = _pick_cloud(accepted, n_cloud)
    if cloud_index.size:
        v, q, p = member_states(job.v0, job.q0, job.p0, dx0[cloud_index])
        cloud_p = np.swapaxes(integrate_ensemble(job.track, v, q, p, idx_t, body=MARS, backend=job.backend)[1], 0, 1)
    else:
        cloud_p = np.empty((0, idx_t.size, 3))
    return DispersionResult(
        n=n,
        seed=job.seed,
        chunk_size=chunk_size,
        dx0=dx0,
        events=events,
        accepted=accepted,
        refined_v0=v_r[0],
        refined_q0=q_r[0],
        refined_p0=p_r[0],
        refined_P0=P0,
        cloud_t=t[idx_t],
        cloud_p_M=cloud_p,
        cloud_accepted=accepted[cloud_index],
        cloud_index=cloud_index,
        wall_s=wall,
        scheduler=executor,
        refined_sigma_max=sig_max,
        sigmas=job.sigmas,
        rules=rules,
        events_t=events_t,
        checks=checks,
        score=rules.score(events),
        weights=np.ones(n) if weights is None else weights,
        rounds=rounds or [],
    )


def make_job(imu, v0, q0, p0, sigmas, seed, events_t, atmosphere, bridge_mode, r_ground, backend=None):
    """The picklable job of :func:`run_dispersion` (IMU arrays, attitude track integrated once,
    nominal state v0 [m/s], q0, p0 [m] in the Mars-fixed frame, 1σ ``sigmas`` (9,), seed, event
    times [s], atmosphere, gap mode, ground radius [m], kernel backend) and the nominal event
    quantities."""
    pim = imu_arrays(imu)
    et, ev_d = _event_times(pim, events_t)
    if np.any(et < pim.t[0]) or np.any(et > pim.t[-1]):
        raise ValueError(f"run_dispersion: event times {et} outside the IMU data [{pim.t[0]:.2f}, {pim.t[-1]:.2f}] s")
    job = _Job(
        imu=pim,
        v0=np.asarray(v0, float),
        q0=quat_normalize(np.asarray(q0, float)),
        p0=np.asarray(p0, float),
        sigmas=sigma_vector(sigmas),
        seed=int(seed),
        event_times=et,
        atmosphere=atmosphere if atmosphere is not None else MarsEngineeringAtmosphere(),
        bridge_mode=bridge_mode,
        r_ground=float(r_ground),
        track=attitude_track(pim, bridge_mode),
        backend=backend or default_backend(),
    )
    return job, ev_d


def run_dispersion(
    imu: Any,
    v0: np.ndarray,
    q0: np.ndarray,
    p0: np.ndarray,
    sigmas: DispersionSigmas | np.ndarray | None,
    n: int,
    *,
    rules: AcceptanceRules | None = None,
    events_t: Mapping[str, float],
    atmosphere: Atmosphere | None = None,
    chunk_size: int = 2000,
    seed: int = 0,
    scheduler: str | None = None,
    workers: int = 1,
    n_cloud: int,
    cloud_dt: float = 1.0,
    bridge_mode: str,
    r_ground: float = R_GROUND,
    refine_rounds: int = 0,
    elite_fraction: float = 0.01,
    min_elite: int = 20,
    inflation: float = 2.0,
    backend: str | None = None,
) -> DispersionResult:
    """Dispersion analysis of the initial state (AMELIA Sect. 6; module docstring).

    ``imu`` a PreprocessedIMU (``t``, ``f_G``, ``w_G``, ``gaps`` used); nominal initial state at
    ``imu.t[0]``: v0 (3,) [m/s], q0 (4,) ``q_M_G``, p0 (3,) [m]; ``sigmas`` sampling 1σ
    (:class:`DispersionSigmas`, a mapping ``{"velocity": m/s, "attitude": rad, "position": m}``,
    (3,) per block [m/s, rad, m] or (9,); default Table 3);
    ``n`` members; ``rules`` (default :class:`AcceptanceRules`); ``events_t`` {"PDD", "FSR",
    optional "BSR" (default: end of the data)} [s]; ``atmosphere`` for the speed of sound (default
    :class:`~workbench.core.atmosphere.MarsEngineeringAtmosphere`); ``chunk_size`` members
    integrated together; ``seed``; ``scheduler`` None (in-process; a process pool if ``workers > 1``),
    ``"local"`` (dask LocalCluster, ``workers`` (≥ 2) processes x 1 thread) or ``"tcp://host:port"``
    (dask Client), as :func:`workbench.estimation.montecarlo.run_monte_carlo`;
    ``n_cloud`` members kept in the thinned cloud, sampled every ``cloud_dt`` [s];
    ``bridge_mode`` of the gap bridges; ``r_ground`` terrain radius [m].

    ``refine_rounds`` > 0 (our addition; 0 = the paper): with the Table 3 spread only ~1e-4 of the
    members pass all five rules, too few for a mean and a spread.  Each extra round samples ``n``
    new members from ``N(mean, inflation² · cov)`` of the previous round's elite (its accepted
    members, or if fewer than ``max(min_elite, elite_fraction·n)``, that many best-scoring ones)
    and weights them by ``N(dx; 0, Σ_prior) / N(dx; mean, cov)``; the refined state and
    ``refined_P0`` are then importance-weighted estimates of the same prior-restricted moments as
    the paper's plain mean and spread (consistent while the proposal covers the accepted region).

    ``backend`` of the member integration (:data:`~workbench.estimation.ensemble.BACKENDS`:
    "numba" compiled, the default when numba imports; "numpy" the pure-numpy reference; "python"
    per member): bit-identical results.

    Results do not depend on ``chunk_size``, ``scheduler``, ``workers`` or ``backend`` (only
    ``wall_s`` and ``scheduler`` do).
    """
    if n < 1 or chunk_size < 1 or refine_rounds < 0:
        raise ValueError("run_dispersion: n and chunk_size must be positive, refine_rounds >= 0")
    rules = rules or AcceptanceRules()
    job, ev_d = make_job(imu, v0, q0, p0, sigmas, seed, events_t, atmosphere, bridge_mode, r_ground, backend)
    prior_cov = np.diag(job.sigmas**2)
    mean, cov = np.zeros(9), prior_cov
    history: list[dict] = []
    wall = 0.0
    rounds = int(refine_rounds) + 1
    bar = progress.current().counter(
        f"dispersion members ({rounds} round{'s' if rounds > 1 else ''})", total=int(n) * rounds, unit="members"
    )
    try:
        for r in range(rounds):
            if r > 0:
                job = replace(job, round_index=r, mean=mean, L=np.linalg.cholesky(cov))
            t0 = time.perf_counter()
            run = run_monte_carlo(
                _run_chunk,
                int(n),
                shared=job,
                chunk_size=int(chunk_size),
                workers=workers,
                scheduler=scheduler,
                name=f"dispersion-{job.seed}-round{r}",
                progress=lambda done, _tasks, r=r: bar.set(r * int(n) + min(done * int(chunk_size), int(n))),
            )
            parts, executor = run.results, run.executor
            dt = time.perf_counter() - t0
            wall += dt
            dx0, events = _combine(parts)
            accepted = rules.accept(events)
            weights = None
            if r > 0:
                logw = _log_normal(dx0, np.zeros(9), prior_cov) - _log_normal(dx0, mean, cov)
                weights = np.exp(logw - (logw[accepted].max() if accepted.any() else logw.max()))
            wa = np.ones(int(accepted.sum())) if weights is None else weights[accepted]
            history.append(
                {
                    "round": r,
                    "n_accepted": int(accepted.sum()),
                    "proposal_sigma": np.sqrt(np.diagonal(cov)).copy(),
                    "ess": float(wa.sum() ** 2 / np.sum(wa * wa)) if wa.size else 0.0,
                    "wall_s": dt,
                }
            )
            if r < refine_rounds:  # next proposal: the elite members' spread, inflated
                n_elite = max(min_elite, int(np.ceil(elite_fraction * n)))
                if accepted.sum() >= n_elite:
                    elite = np.flatnonzero(accepted)
                else:
                    elite = np.argsort(rules.score(events), kind="stable")[:n_elite]
                # the elite's Gaussian (inflated) times the prior: never wider than the prior
                ce = inflation**2 * np.cov(dx0[elite], rowvar=False) + 1e-6 * prior_cov
                ci = np.linalg.inv(ce)
                cov = np.linalg.inv(ci + np.linalg.inv(prior_cov))
                cov = 0.5 * (cov + cov.T)
                mean = cov @ (ci @ dx0[elite].mean(axis=0))
    finally:
        bar.close()
    return _finish(
        job,
        dx0,
        events,
        n=int(n),
        chunk_size=int(chunk_size),
        rules=rules,
        n_cloud=n_cloud,
        cloud_dt=cloud_dt,
        wall=wall,
        executor=executor,
        events_t=ev_d,
        weights=weights,
        rounds=history,
    )


def run_configured_dispersion(
    settings: Any,
    imu: Any,
    nominal: Any,
    events_t: Mapping[str, float],
    *,
    members: int | None = None,
    scheduler: str | None = None,
    n_cloud: int,
) -> DispersionResult:
    """:func:`run_dispersion` as a run's settings configure it: the scenario's ``[dispersion]``
    (sigmas, rules, member count unless ``members``, chunk size, seed, refinement rounds), its
    terrain radius ``settings.r_ground`` [m] and ``[reconstruction] bridge_mode``, about the
    nominal initial state ``nominal`` (``v_M`` [m/s], ``q_M_G``, ``p_M`` [m] at ``imu.t[0]``),
    with the engineering atmosphere.  ``settings`` is an
    :class:`~workbench.problems.entry.config.EntrySettings`; the pipeline and the smoother
    validation call this so that both run the same dispersion."""
    ds = settings.dispersion
    return run_dispersion(
        imu,
        nominal.v_M,
        nominal.q_M_G,
        nominal.p_M,
        ds.sigmas(),
        int(members if members is not None else ds.members),
        rules=ds.rules,
        events_t=events_t,
        atmosphere=MarsEngineeringAtmosphere(),
        chunk_size=ds.chunk_size,
        seed=ds.seed,
        scheduler=scheduler,
        n_cloud=n_cloud,
        r_ground=settings.r_ground,
        bridge_mode=settings.reconstruction.bridge_mode,
        refine_rounds=ds.refine_rounds,
    )


def run_dispersion_loop(
    imu: Any,
    v0: np.ndarray,
    q0: np.ndarray,
    p0: np.ndarray,
    sigmas: DispersionSigmas | np.ndarray | None,
    n: int,
    *,
    rules: AcceptanceRules | None = None,
    events_t: Mapping[str, float],
    atmosphere: Atmosphere | None = None,
    seed: int = 0,
    n_cloud: int,
    cloud_dt: float = 1.0,
    bridge_mode: str,
    r_ground: float = R_GROUND,
) -> DispersionResult:
    """Per-trajectory loop baseline of :func:`run_dispersion`: the same members and maths, one
    member at a time on Python floats (:func:`~workbench.estimation.ensemble.integrate_ensemble`
    with ``backend="python"``; the attitude track is shared, as in the vectorised run), in this
    process.

    Same arguments and result (bit-identical event quantities); for benchmarking the vectorised
    version.  ``scheduler`` of the result is "per-trajectory loop"; the cloud is integrated with
    the default backend.
    """
    job, ev_d = make_job(imu, v0, q0, p0, sigmas, seed, events_t, atmosphere, bridge_mode, r_ground)
    t0 = time.perf_counter()
    dx0, events = _combine([_run_loop(job, 0, int(n))])
    wall = time.perf_counter() - t0
    return _finish(
        job,
        dx0,
        events,
        n=int(n),
        chunk_size=1,
        rules=rules or AcceptanceRules(),
        n_cloud=n_cloud,
        cloud_dt=cloud_dt,
        wall=wall,
        executor="per-trajectory loop",
        events_t=ev_d,
    )


@dataclass(frozen=True)
class FusedInitialState:
    """Dispersion constraint fused with the navigation prior (:func:`fuse_with_prior`).

    ``v0`` (3,) [m/s], ``q0`` (4,) ``q_M_G``, ``p0`` (3,) [m] at the first IMU time; ``P0`` (9, 9)
    error-state covariance [δv, δθ, δp]; ``dx`` (9,) the offset from the nominal; ``P_prior`` (9, 9)
    the navigation prior; ``constrained_dims`` number of normalised directions in which the rules
    carry information (eigenvalues of the likelihood information > ``tol``).
    """

    v0: np.ndarray
    q0: np.ndarray
    p0: np.ndarray
    P0: np.ndarray
    dx: np.ndarray
    P_prior: np.ndarray
    constrained_dims: int


def fuse_with_prior(
    disp: DispersionResult,
    v_nom: np.ndarray,
    q_nom: np.ndarray,
    p_nom: np.ndarray,
    P_prior: np.ndarray,
    tol: float = 1e-3,
) -> FusedInitialState:
    """Combine the acceptance rules' information with an independent navigation prior (our addition).

    The accepted set approximates ``prior_wide × L`` (the wide sampling prior of Table 3 times the
    rules' likelihood).  With both Gaussian, the likelihood information is
    ``Λ_L = P_acc⁻¹ − P_wide⁻¹`` (clamped to ≥ 0 in the normalised coordinates ``x / σ_wide``: in
    directions the rules do not constrain the accepted spread is as wide as the prior) and its
    information vector ``η = P_acc⁻¹ μ_acc`` (projected on the constrained directions).  The
    posterior with the navigation prior ``N(0, P_prior)`` about the nominal is
    ``P0 = (P_prior⁻¹ + Λ_L)⁻¹``, ``dx = P0 η``.  Why: the rules pin the altitude profile
    (flight-path angle, vertical velocity, entry timing) but not along-/cross-track position or
    cross-track velocity; there the accepted spread stays at Table 3's 10 km / 0.5 km/s, which
    propagates to ~60 km of horizontal uncertainty at the radar fix — far outside the linear range
    of the radar models on a curved terrain.  The pre-entry navigation knowledge (AMELIA Table 3,
    "Reconstruction" column) bounds those directions.  ``v_nom``, ``q_nom``, ``p_nom``: the nominal
    state about which ``disp.dx0`` was sampled; ``P_prior`` (9, 9).
    """
    acc = np.asarray(disp.accepted, bool)
    if acc.sum() < 10 or not np.all(np.isfinite(disp.refined_P0)):
        raise ValueError(f"fuse_with_prior: need ≥ 10 accepted members with a finite spread, have {acc.sum()}")
    w = np.asarray(disp.weights, float)
    w = np.ones(acc.size) if w.size != acc.size else w
    mu = np.average(np.asarray(disp.dx0, float)[acc], axis=0, weights=w[acc])
    D = np.asarray(disp.sigmas, float)
    Pn = disp.refined_P0 / np.outer(D, D)
    Lam_acc = np.linalg.inv(0.5 * (Pn + Pn.T))
    Lam_L = Lam_acc - np.eye(9)
    lam, V = np.linalg.eigh(0.5 * (Lam_L + Lam_L.T))
    keep = lam > tol
    Lam_L = (V[:, keep] * lam[keep]) @ V[:, keep].T
    eta = V[:, keep] @ (V[:, keep].T @ (Lam_acc @ (mu / D)))
    Lam_prior = np.linalg.inv(np.asarray(P_prior, float) / np.outer(D, D))
    Pf_n = np.linalg.inv(Lam_prior + Lam_L)
    Pf_n = 0.5 * (Pf_n + Pf_n.T)
    dx = D * (Pf_n @ eta)
    P0 = Pf_n * np.outer(D, D)
    v0 = np.asarray(v_nom, float) + dx[DV]
    q0 = quat_normalize(quat_multiply(np.asarray(q_nom, float), quat_from_rotvec(dx[DTH])))
    p0 = np.asarray(p_nom, float) + dx[DP]
    return FusedInitialState(v0, q0, p0, P0, dx, np.asarray(P_prior, float), int(keep.sum()))
