"""Entry Monte Carlo against the 6-DOF truth simulator, through the full pipeline from telemetry files.

:mod:`workbench.problems.entry.montecarlo` checks the filter against its own assumptions (truths from
its own discrete model); this module is the other half: every member's truth comes from
:func:`workbench.problems.entry.truth.simulate_entry` (its own aerodynamics, atmosphere, winds,
parachute) and every reconstruction runs the whole pipeline from the files a user would supply
(:func:`workbench.problems.entry.pipeline.reconstruct` up to its smoother stage).

Member k (``SeedSequence(seed, spawn_key=(k,))``, :mod:`workbench.estimation.montecarlo`'s rule):
dispersed specs (:func:`member_settings`, ``dataclasses.replace`` of the run's settings), the truth,
the telemetry files (:func:`~workbench.problems.entry.synthetic.synthesize_from_truth`), the
reconstruction, and the scores against ``truth.npz`` (:func:`~workbench.problems.entry.montecarlo.score_run`:
NEES, errors and reported 1σ, AGL error, NIS per radar channel). Members' grids differ, so values
are taken at each member's own epochs and the ANEES(t) curves map every member onto the first
one's grid between epochs; aggregation and summary are the self-consistency check's, so the two
read side by side. The step-by-step description: docs/tuning/entry.md, "truth_mc.py".
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.interpolation import interp_rows
from workbench.core.rotation import quat_normalize
from workbench.estimation.consistency import is_symmetric_pd
from workbench.io.telemetry import TelemetryError
from workbench.problems.entry import pipeline as en
from workbench.problems.entry.config import EntrySettings
from workbench.problems.entry.dispersion import DispersionResult
from workbench.problems.entry.filter import EntryFilterResult, EntryFilterSigmas
from workbench.problems.entry.initial import SmootherStart
from workbench.problems.entry.montecarlo import (
    RunScores,
    ValidationResult,
    aggregate_runs,
    failed_run,
    index_at,
    score_run,
    summarize_validation,
    summary_times,
)
from workbench.problems.entry.preprocess import EntryTelemetry, PreprocessedIMU
from workbench.problems.entry.sensors import IMU_ERROR_NAMES, EntryTelemetrySpec, disperse_telemetry_spec
from workbench.problems.entry.synthetic import load_truth, synthesize_from_truth
from workbench.problems.entry.truth import (
    DispersionSigmas,
    EntryTruthSpec,
    disperse_truth_spec,
    simulate_entry,
)
from workbench.problems.members import run_members

__all__ = [
    "TruthMcMember",
    "TruthMcResult",
    "disperse_member",
    "run_truth_monte_carlo",
    "member_settings",
    "DEFAULT_MEMBERS",
    "DEFAULT_REFINE_ROUNDS",
]

#: Dispersion members and refinement rounds of each member's reconstruction unless given.
DEFAULT_MEMBERS = 2000
DEFAULT_REFINE_ROUNDS = 1


def disperse_member(
    truth_spec: EntryTruthSpec,
    telemetry_spec: EntryTelemetrySpec,
    rng_truth: np.random.Generator,
    rng_sensors: np.random.Generator,
) -> tuple[EntryTruthSpec, EntryTelemetrySpec]:
    """One member's truth and telemetry specs drawn about the scenario's: the truth simulator's own
    dispersion (:func:`~workbench.problems.entry.truth.disperse_truth_spec`: initial state, planted
    aerodynamic deviations, atmosphere, winds, terrain relief) and the sensors'
    (:func:`~workbench.problems.entry.sensors.disperse_telemetry_spec`: IMU bias, scale and
    misalignment, the on-board nominal-state error), from the independent streams ``rng_truth`` and
    ``rng_sensors``.  The white noises (IMU samples, radar) are drawn later from the telemetry stream."""
    return disperse_truth_spec(truth_spec, rng_truth), disperse_telemetry_spec(telemetry_spec, rng_sensors)


# ---------------------------------------------------------------------------------------------
# one member


@dataclass(frozen=True)
class _Job:
    settings: EntrySettings  # picklable: the process pool / Dask workers receive it
    members: int
    work_dir: str | None

    @property
    def truth_spec(self) -> EntryTruthSpec:
        return self.settings.synthetic.truth

    @property
    def telemetry_spec(self) -> EntryTelemetrySpec:
        return self.settings.synthetic.telemetry


@dataclass(frozen=True)
class TruthMcMember:
    """One member of :func:`run_truth_monte_carlo`: ``scores`` (:class:`~workbench.problems.entry.montecarlo.RunScores`)
    on the member's own IMU grid ``t`` (n,) [s]; ``times`` {epoch: t [s]} its summary epochs;
    ``info`` JSON-ready facts (dispersed spec values, telemetry files and rows read back, dispersion
    acceptance, smoother start, radar noise simulated, covariance checks, wall times)."""

    scores: RunScores
    t: np.ndarray
    times: dict[str, float]
    info: dict = field(default_factory=dict)


def _stages(settings: EntrySettings, paths: Mapping[str, Path], members: int) -> dict[str, Any]:
    """The pipeline's stages up to the smoother (``pipeline.reconstruct``, the ``workbench run`` path)."""
    out: dict[str, Any] = {}
    gen = en.reconstruct(settings, dict(paths), members=members)
    try:
        for st in gen:
            for name, typ in (
                ("telemetry", EntryTelemetry),
                ("imu", PreprocessedIMU),
                ("dispersion", DispersionResult),
                ("start", SmootherStart),
                ("filter", EntryFilterResult),
            ):
                if isinstance(st, typ):
                    out[name] = st
            if "filter" in out:
                break
    finally:
        gen.close()
    return out


def _truth_on(truth: dict, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth velocity (n,3) [m/s], attitude q_M_G (n,4) and position (n,3) [m] at times t (n,) [s]."""
    V = interp_rows(t, truth["t"], truth["v_M"])
    Q = quat_normalize(interp_rows(t, truth["t"], truth["q_M_G"]))
    X = interp_rows(t, truth["t"], truth["p_M"])
    return V, Q, X


def _first_fix(tm: Any) -> float:
    """First valid radar time tag [s] (slant-range packets or slant-out/velocity-out samples)."""
    first = [
        float(np.min(np.asarray(t, float)[np.asarray(ok, bool)]))
        for t, ok in ((tm.t_sr, tm.sr_valid), (tm.t_rda, tm.rda_valid))
        if np.any(ok)
    ]
    return min(first) if first else math.inf


def _run_member(job: _Job, k: int, ss: np.random.SeedSequence) -> TruthMcMember:
    """Member k (module docstring); depends on (job, k) only.  A task of
    :func:`~workbench.estimation.montecarlo.run_monte_carlo`."""
    t0 = time.perf_counter()
    g_spec, g_sensors, g_sim, g_tm = (np.random.Generator(np.random.PCG64(s)) for s in ss.spawn(4))
    spec, tspec = disperse_member(job.truth_spec, job.telemetry_spec, g_spec, g_sensors)
    info: dict[str, Any] = {
        "truth_spec": {
            "fpa_offset_deg": spec.fpa_offset_deg,
            "speed_offset_mps": spec.speed_offset_mps,
            "aoa_offset_deg": spec.aoa_offset_deg,
            "initial_position_offset_km": list(spec.initial_position_offset_km),
            "ca_deviation": list(spec.ca_deviation),
            "parachute_cd_deviation": list(spec.parachute_cd_deviation),
            "surface_pressure_pa": spec.surface_pressure_pa,
            "wind_layer_speeds_mps": [w[2] for w in spec.wind_layers],
        },
        "imu_errors": {nm: list(v) for nm, v in zip(IMU_ERROR_NAMES, tspec.imu.errors or (), strict=False)},
        "nominal_dx0": list(tspec.nominal.dx0 or ()),
        "radar_noise_simulated": {
            "range_sigma_m": float(tspec.range_sigma),
            "range_sigma_frac": float(tspec.range_sigma_frac),
            "velocity_sigma_mps": float(tspec.velocity_sigma),
        },
    }
    truth = simulate_entry(job.settings.require_vehicle(), spec, g_sim)
    t1 = time.perf_counter()
    info["truth_s"] = t1 - t0
    info["truth_events"] = dict(truth.events)
    tm_seed = int(g_tm.integers(0, 2**62))
    with tempfile.TemporaryDirectory(prefix=f"entry_truth_mc_{k}_") as tmp:
        folder = Path(job.work_dir) / f"member_{k}" / "telemetry" if job.work_dir else Path(tmp) / "telemetry"
        paths = dict(
            synthesize_from_truth(
                truth,
                folder,
                tspec,
                tm_seed,
                source=f"entry truth Monte Carlo, member {k}",
                compress=job.work_dir is not None,  # a temporary truth.npz is read back once
            )
        )
        truth_file = paths.pop("truth")
        info["telemetry_files"] = {s: p.name for s, p in sorted(paths.items())}
        info["telemetry_dir"] = str(folder) if job.work_dir else None
        try:
            st = _stages(job.settings, paths, job.members)
        except (ValueError, TelemetryError, ArithmeticError, np.linalg.LinAlgError) as err:
            return TruthMcMember(failed_run(k, -1, f"member {k}: {err}", 1, t0), np.zeros(1), {}, info)
        truth_npz = load_truth(truth_file)  # scoring only
    tm, imu, disp, start, filt = st["telemetry"], st["imu"], st["dispersion"], st["start"], st["filter"]
    sm = filt.smoothed
    t_fix = _first_fix(tm)
    V, Q, X = _truth_on(truth_npz, sm.t)
    scores = score_run(filt, V, Q, X, sm.t, t_fix, r=k, member=-1, t_start=t0)
    times = summary_times(np.asarray(sm.t, float), imu.gaps, tm.events, t_fix)
    i_fix = index_at(sm.t, t_fix) if math.isfinite(t_fix) else None
    sym_s, pd_s = is_symmetric_pd(sm.P)
    sym_f, pd_f = is_symmetric_pd(filt.forward.P)
    info.update(
        {
            "rows_read": {"gnc": int(tm.t_gnc.size), "gnc_nav": int(tm.t_nav.size), "rda_slant_range":
                          int(tm.t_sr.size), "rda_out": int(tm.t_rda.size)},
            "events_read": dict(tm.events),
            "dispersion": {"members": int(disp.n), "accepted": int(np.sum(disp.accepted))},
            "smoother_start": start.mode,
            "smoother_start_note": start.note,
            "covariance_symmetric_pd": {
                "smoothed": bool(np.all(sym_s) and np.all(pd_s)),
                "forward": bool(np.all(sym_f) and np.all(pd_f)),
            },
            "t_fix_s": t_fix,
            "h_agl_error_at_fix_m": float(scores.err[i_fix, 2]) if i_fix is not None else math.nan,
            "h_agl_3sigma_at_fix_m": float(3.0 * scores.sig[i_fix, 2]) if i_fix is not None else math.nan,
            "nees_stage": {lab: float(scores.nees[index_at(sm.t, te)]) for lab, te in times.items()},
            "wall_s": time.perf_counter() - t0,
        }
    )  # fmt: skip
    return TruthMcMember(scores, np.asarray(sm.t, float), times, info)


# ---------------------------------------------------------------------------------------------
# event-aligned common grid


def _warp_index(t_ref: np.ndarray, times_ref: Mapping[str, float], t: np.ndarray, times: Mapping[str, float]):
    """For every sample of the reference grid ``t_ref`` (n_ref,) the index (n_ref,) of the sample
    of ``t`` (n,) at the same event-aligned time: piecewise-linear between the epochs both have, and
    at each epoch exactly the member's own epoch sample (:func:`index_at`)."""
    labels = [lab for lab in times_ref if lab in times]
    x = np.array([times_ref[lab] for lab in labels])
    y = np.array([times[lab] for lab in labels])
    keep = np.r_[True, (np.diff(x) > 0) & (np.diff(y) > 0)]  # strictly increasing knots
    mapped = np.interp(t_ref, x[keep], y[keep]) if keep.sum() > 1 else t_ref - x[0] + y[0]
    idx = np.clip(np.searchsorted(t, mapped - 1e-9), 0, t.size - 1)
    for lab in labels:
        idx[index_at(t_ref, times_ref[lab])] = index_at(t, times[lab])
    return idx


def _on_reference(m: TruthMcMember, t_ref: np.ndarray, times_ref: Mapping[str, float]) -> RunScores:
    s = m.scores
    if s.failed:
        return failed_run(s.r, s.member, s.message, t_ref.size, time.perf_counter() - s.wall_s)
    i = _warp_index(t_ref, times_ref, m.t, m.times)
    return dataclasses.replace(
        s,
        nees=s.nees[i],
        nees_curvilinear=s.nees_curvilinear[i],
        nees_forward=s.nees_forward[i],
        nees_forward_curvilinear=s.nees_forward_curvilinear[i],
        err=s.err[i],
        sig=s.sig[i],
    )


# ---------------------------------------------------------------------------------------------
# result and driver


@dataclass(frozen=True)
class TruthMcResult:
    """Outcome of :func:`run_truth_monte_carlo`.

    ``validation`` a :class:`~workbench.problems.entry.montecarlo.ValidationResult` on the
    event-aligned grid of the first successful member (module docstring) with its ``summary``
    (:func:`~workbench.problems.entry.montecarlo.summarize_validation` keys plus the radar noise
    simulated vs the filter's R, the altitude error at the first fix vs its 3σ, the spread of the
    members' epochs, the dispersion acceptance); ``members`` the per-member results on their own
    grids (:class:`TruthMcMember`); ``summary`` = ``validation.summary``.
    """

    validation: ValidationResult
    members: tuple[TruthMcMember, ...]

    @property
    def summary(self) -> dict:
        """JSON-ready summary (``validation.summary``)."""
        return self.validation.summary


def member_settings(settings: EntrySettings, refine_rounds: int | None) -> EntrySettings:
    """``settings`` with the members' dispersion: ``refine_rounds`` (default
    :data:`DEFAULT_REFINE_ROUNDS`) and no recording cloud."""
    rr = DEFAULT_REFINE_ROUNDS if refine_rounds is None else int(refine_rounds)
    return dataclasses.replace(settings, dispersion=dataclasses.replace(settings.dispersion, refine_rounds=rr, cloud=0))


def run_truth_monte_carlo(
    settings: EntrySettings,
    *,
    n_runs: int,
    seed: int,
    members: int | None = None,
    refine_rounds: int | None = None,
    scheduler: str | None = None,
    workers: int = 1,
    work_dir: str | Path | None = None,
) -> TruthMcResult:
    """The entry Monte Carlo against the truth simulator (module docstring) for the
    :class:`~workbench.problems.entry.config.EntrySettings` of a synthetic entry scenario (its
    ``synthetic`` truth and telemetry specs are what the members are dispersed about; every other
    stage is configured as for ``workbench run``).

    ``n_runs`` ≥ 1 members, member k seeded ``SeedSequence(seed, spawn_key=(k,))``; ``members``
    dispersion members of each reconstruction (default :data:`DEFAULT_MEMBERS`),
    ``refine_rounds`` its refinement rounds (default :data:`DEFAULT_REFINE_ROUNDS`); ``scheduler``
    None | "loop" | "processes" | "local" | "tcp://…" and ``workers`` as
    :func:`~workbench.estimation.montecarlo.run_monte_carlo`; ``work_dir``: keep each member's
    telemetry files in ``work_dir/member_<k>/telemetry`` (default: a temporary folder, removed).
    """
    wall0 = time.perf_counter()
    if int(n_runs) < 1:
        raise ValueError("run_truth_monte_carlo: n_runs must be ≥ 1")
    cfg = member_settings(settings, refine_rounds)
    job = _Job(
        settings=cfg,
        members=int(members if members is not None else DEFAULT_MEMBERS),
        work_dir=None if work_dir is None else str(work_dir),
    )
    run = run_members(
        _run_member, n_runs, shared=job, seed=seed, workers=workers, scheduler=scheduler, name=f"entry-truth-mc-{seed}"
    )
    outs: list[TruthMcMember] = list(run.results)
    ok = [m for m in outs if not m.scores.failed]
    ref = ok[0] if ok else outs[0]
    t_ref, times_ref = ref.t, dict(ref.times)
    scores = [_on_reference(m, t_ref, times_ref) for m in outs]
    res = aggregate_runs(
        scores,
        t_ref,
        n_runs=int(n_runs),
        seed=int(seed),
        t_fix=float(times_ref.get("first_radar", math.inf)),
        times=times_ref,
        executor=run.executor,
        wall_s=time.perf_counter() - wall0,
    )
    summary = summarize_validation(res)
    # the R the pipeline used: slant-out terrain term inflated for its correlation at the telemetry's rate
    sigmas = cfg.smoother_sigmas(slant_out_dt_s=1.0 / job.telemetry_spec.rda_rate_hz)
    summary.update(_extra_summary(outs, ok, sigmas, job))
    res.summary.update(summary)
    return TruthMcResult(res, tuple(outs))


def _extra_summary(outs, ok, sigmas, job: _Job) -> dict:
    sg = EntryFilterSigmas.from_any(sigmas)
    tspec = job.telemetry_spec
    out: dict[str, Any] = {
        "kind": "entry_truth_mc",
        "truths_note": "6-DOF truth simulator per member (dispersed initial state, aerodynamics, atmosphere, "
        "winds, terrain, IMU errors), telemetry files, full pipeline (preprocessing, dispersion, iterated smoother)",
        "members_per_dispersion": job.members,
        "refine_rounds": int(job.settings.dispersion.refine_rounds),
        "radar_noise_simulated": {
            "range_sigma_m": float(tspec.range_sigma),
            "range_sigma_frac": float(tspec.range_sigma_frac),
            "velocity_sigma_mps": float(tspec.velocity_sigma),
            "note": "slant-range 1σ = hypot(range_sigma_m, range_sigma_frac × range)",
        },
        "filter_R": {
            "slant_range_m": sg.slant_range,
            "slant_out_m": sg.slant_out,
            "velocity_out_mps": sg.velocity_out,
            "note": "slant-out includes the terrain term × sqrt(terrain_correlation_s × rate) ([radar] keys)",
        },
        "truth_dispersion_sigmas": dataclasses.asdict(DispersionSigmas()),
    }
    if ok:
        labels = list(ok[0].times)
        out["epoch_spread_s"] = {
            lab: [min(m.times.get(lab, math.nan) for m in ok), max(m.times.get(lab, math.nan) for m in ok)]
            for lab in labels
        }
        e = np.array([m.info["h_agl_error_at_fix_m"] for m in ok])
        s3 = np.array([m.info["h_agl_3sigma_at_fix_m"] for m in ok])
        fin = np.isfinite(e) & np.isfinite(s3)
        if fin.any():
            out["h_agl_at_fix"] = {
                "rms_error_m": float(np.sqrt(np.mean(e[fin] ** 2))),
                "max_abs_error_m": float(np.max(np.abs(e[fin]))),
                "median_3sigma_m": float(np.median(s3[fin])),
                "fraction_inside_3sigma": float(np.mean(np.abs(e[fin]) <= s3[fin])),
                "max_abs_error_over_3sigma": float(np.max(np.abs(e[fin]) / s3[fin])),
            }
        acc = np.array([m.info["dispersion"]["accepted"] for m in ok])
        out["dispersion_accepted"] = {"min": int(acc.min()), "median": float(np.median(acc)), "max": int(acc.max())}
        modes = [m.info["smoother_start"] for m in ok]
        out["smoother_start_modes"] = {md: modes.count(md) for md in sorted(set(modes))}
        out["covariance_symmetric_pd_all"] = bool(
            all(
                m.info["covariance_symmetric_pd"]["smoothed"] and m.info["covariance_symmetric_pd"]["forward"]
                for m in ok
            )
        )
        out["member_wall_median_s"] = float(np.median([m.info["wall_s"] for m in ok]))
        out["truth_sim_median_s"] = float(np.median([m.info["truth_s"] for m in ok]))
    return out
