"""MEADS Monte Carlo with the full error model against the truth simulator (paper Sect. IV, Figs. 11–13).

Karlgaard et al., "Mars Entry Atmospheric Data System Trajectory Reconstruction Algorithms and
Flight Results", AIAA 2013: least squares, EKF pass 1 and pass 2 over many seeded entries with every
error source of the pressure chain on; the 3σ of the error of α, β, q∞, Mach, p∞, density and the
winds over the members, against what each estimator reports (:mod:`.montecarlo` is the Newtonian
trade study of Fig. 6).

Member k (``SeedSequence(seed, spawn_key=(k,))``, a truth and a sensor stream, :func:`member_draws`):
the dispersed ``[truth]`` spec simulated (:func:`~workbench.problems.meads.truth.simulate_entry`),
telemetry files written with the scenario's ``[sensors.*]`` error chain (the injected port failure
switched off: the study is of the error model), the reconstruction as ``workbench run`` (less the
other model's fit, not scored), and the errors with their reported 1σ (:func:`error_histories`).
Members fly different entries, so the statistics are per flight condition: :func:`aggregate_by_mach`
bins every member-sample at its own true Mach (where its q∞ ≥ 850 Pa) and reduces each bin (bias,
Monte Carlo 3σ, reported 3σ, their ratio, fraction inside; thin bins marked); :func:`summarize`
tabulates them. Results are gathered by member index, so they do not depend on the executor. The
full description: docs/tuning/meads.md, "truth_mc.py".
"""

from __future__ import annotations

import math
import tempfile
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.io.telemetry import TelemetryError
from workbench.problems.meads import pipeline as md
from workbench.problems.meads.config import MeadsSettings
from workbench.problems.meads.montecarlo import OBJECTIVES
from workbench.problems.meads.synthetic import load_truth, synthesize_from_truth
from workbench.problems.meads.truth import MeadsDispersionSigmas, disperse_truth_spec, simulate_entry
from workbench.problems.members import run_members

__all__ = [
    "QUANTITIES",
    "ESTIMATORS",
    "MIN_QBAR_PA",
    "RATIO_BAND",
    "MIN_INSIDE",
    "MACH_BIN_EDGES",
    "MIN_BIN_MEMBER_FRACTION",
    "McJob",
    "MemberErrors",
    "FullMcResult",
    "member_draws",
    "error_histories",
    "stack_members",
    "aggregate",
    "aggregate_by_mach",
    "solid_bins",
    "by_mach_json",
    "summarize",
    "run_full_monte_carlo",
]

#: Quantities scored: α, β [deg], q∞ [%], Mach [-], p∞ [%], density [%], wind north/east/down [m/s].
QUANTITIES = (
    "alpha_deg",
    "beta_deg",
    "qbar_pct",
    "mach",
    "p_inf_pct",
    "density_pct",
    "wind_north_mps",
    "wind_east_mps",
    "wind_down_mps",
)
#: Estimators scored: the least squares (with its winds and density), EKF pass 1, EKF pass 2 (smoothed).
ESTIMATORS = ("least_squares", "ekf_pass1", "ekf_pass2")
#: The objectives apply above this true dynamic pressure [Pa].
MIN_QBAR_PA = 850.0
#: Reported / Monte Carlo 3σ (median above 850 Pa) outside this band is listed as a disagreement.
RATIO_BAND = (1.0 / 1.5, 1.5)
#: A fraction of member-samples inside the reported 3σ below this is listed as a disagreement.
MIN_INSIDE = 0.9
#: The Mach grid of the statistics per flight condition (bin edges [-], low to high): 0.5 wide
#: below Mach 5 (where Mach becomes observable from the pressures and the flow changes fastest),
#: 1 wide from Mach 5 to 40.  A sample is in bin i when edge[i] ≤ its true Mach < edge[i + 1].
MACH_BIN_EDGES = tuple(float(x) for x in np.r_[np.arange(0.0, 5.0, 0.5), np.arange(5.0, 41.0, 1.0)])
#: A Mach bin is *solid* (drawn as a curve, counted in the table) when at least this fraction of
#: the reconstructed members, and at least 2, have a scored sample in it; thinner bins are marked.
MIN_BIN_MEMBER_FRACTION = 0.5


@dataclass(frozen=True)
class McJob:
    """What every member needs (picklable: shipped to process pools and Dask): the run's
    ``settings`` (the injected failure switched off), whether to ``disperse_truth`` and with which
    ``sigmas``."""

    settings: MeadsSettings
    disperse_truth: bool = True
    sigmas: MeadsDispersionSigmas = field(default_factory=MeadsDispersionSigmas)


@dataclass(frozen=True)
class MemberErrors:
    """One member: ``t`` (n,) [s] pressure times, the true ``qbar`` [Pa] and ``mach`` (n,), ``err``
    (n, Q, E) estimate − truth and ``sig`` (n, Q, E) the reported 1σ (units of :data:`QUANTITIES`;
    Q quantities, E estimators of :data:`ESTIMATORS`; NaN where an estimator has no value or 1σ),
    ``info`` JSON-ready facts (draws, health, failed ports, scale factors, wall times) and
    ``failed`` the message if the member could not be reconstructed (arrays then empty)."""

    k: int
    t: np.ndarray
    qbar: np.ndarray
    mach: np.ndarray
    err: np.ndarray
    sig: np.ndarray
    info: dict
    failed: str = ""


# ---------------------------------------------------------------------------------------------
# one member


def member_draws(job: McJob, k: int, ss: np.random.SeedSequence) -> tuple[Any, np.random.SeedSequence, dict]:
    """Member ``k``'s draws from its seed sequence ``ss``: ``(truth spec, sensor seed sequence,
    info)`` — ``ss.spawn(2)`` = (truth dispersion, sensors); the spec is the scenario's when
    ``job.disperse_truth`` is off; ``info`` the dispersed values (JSON-ready)."""
    s_truth, s_sensors = ss.spawn(2)
    base = job.settings.truth
    spec = disperse_truth_spec(base, np.random.default_rng(s_truth), job.sigmas) if job.disperse_truth else base
    info = {
        "member": int(k),
        "truth": {
            "entry_fpa_deg": spec.entry_fpa_deg,
            "entry_speed_kmps": spec.entry_speed_kmps,
            "alpha_hyper_deg": spec.alpha_hyper_deg,
            "alpha_low_deg": spec.alpha_low_deg,
            "surface_pressure_pa": spec.surface_pressure_pa,
            "temperature_nodes_K": [T for _, T in spec.temperature_nodes_km_K],
            "wave_amplitude_K": spec.wave_amplitude_K,
            "wave_length_km": spec.wave_length_km,
            "background_wind_mps": spec.background_wind_mps,
            "background_azimuth_deg": spec.background_azimuth_deg,
            "wind_layer_speeds_mps": [w[2] for w in spec.wind_layers],
            "stagnation_shift": spec.stagnation_shift,
            "shoulder": spec.shoulder,
        },
        "sensor_seed_state": [int(x) for x in s_sensors.generate_state(2)],
    }
    return spec, s_sensors, info


def _pct(v: np.ndarray, s: np.ndarray, tr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Error [% of truth] and 1σ [% of the estimate]."""
    return 100.0 * (v - tr) / tr, 100.0 * s / v


def error_histories(result: md.MeadsResult, truth: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, err, sig)`` of one reconstruction against its truth (``truth.npz`` arrays): ``t`` (n,)
    [s] the pressure times, ``err`` (n, Q, E) estimate − truth, ``sig`` (n, Q, E) the reported 1σ in
    the units of :data:`QUANTITIES` (percentages: error of the truth, 1σ of the estimate), for the
    estimators of :data:`ESTIMATORS`.  Least squares: the final fit (failed ports removed) for α, β,
    q∞ where it solved, Mach / p∞ / density of the wind stage (air data below the switch Mach,
    inertial above), the horizontal winds where the solution is not singular (also where they are
    not published because their 1σ exceeds ``[winds] max_sigma_mps``: on ``msl_meads`` that is
    everywhere), no vertical wind.  The
    true vertical wind is 0 (the truth's winds are horizontal); NaN columns for passes not run."""
    t = np.asarray(result.air.t, float)
    n = t.size
    err = np.full((n, len(QUANTITIES), len(ESTIMATORS)), np.nan)
    sig = np.full_like(err, np.nan)

    def tr(key: str) -> np.ndarray:
        return np.interp(t, truth["t"], truth[key])

    truths = {
        "alpha_deg": tr("alpha"),
        "beta_deg": tr("beta"),
        "qbar_pct": tr("qbar"),
        "mach": tr("mach"),
        "p_inf_pct": tr("p_inf"),
        "density_pct": tr("rho"),
        "wind_north_mps": np.interp(t, truth["t"], truth["wind_NE"][:, 0]),
        "wind_east_mps": np.interp(t, truth["t"], truth["wind_NE"][:, 1]),
        "wind_down_mps": np.zeros(n),
    }

    def put(e: int, q: str, v, s) -> None:
        v, s = np.asarray(v, float), np.asarray(s, float)
        j = QUANTITIES.index(q)
        if q.endswith("_pct"):
            a, b = _pct(v, s, truths[q])
        elif q.endswith("_deg"):
            a, b = np.degrees(v - truths[q]), np.degrees(s)
        else:
            a, b = v - truths[q], s
        ok = np.isfinite(a) & np.isfinite(b)
        err[:, j, e] = np.where(ok, a, np.nan)
        sig[:, j, e] = np.where(ok, b, np.nan)

    f, w = result.air.fit, result.wind
    with np.errstate(invalid="ignore", divide="ignore"):
        put(0, "alpha_deg", f.alpha, f.sigma_alpha)
        put(0, "beta_deg", f.beta, f.sigma_beta)
        put(0, "qbar_pct", f.qbar, f.sigma_qbar)
        put(0, "mach", w.mach, w.sigma_mach)
        put(0, "p_inf_pct", w.p_inf, w.sigma_p_inf)
        put(0, "density_pct", w.density, w.sigma_density)
        raw = np.where(w.winds.singular[:, None], np.nan, w.winds.wind_raw_NE)
        for j, q in enumerate(("wind_north_mps", "wind_east_mps")):
            put(0, q, raw[:, j], np.sqrt(w.winds.P[:, j, j]))
        names = {
            "alpha_deg": "alpha",
            "beta_deg": "beta",
            "qbar_pct": "qbar",
            "mach": "mach",
            "p_inf_pct": "p_inf",
            "density_pct": "rho",
            "wind_north_mps": "wind_north",
            "wind_east_mps": "wind_east",
            "wind_down_mps": "wind_down",
        }
        for ps in result.ekf:
            e = ESTIMATORS.index(f"ekf_pass{ps.index}")
            for q, name in names.items():
                put(e, q, *ps.output(name))
    return t, err, sig


def _run_member(job: McJob, k: int, ss: np.random.SeedSequence) -> MemberErrors:
    """Member k (module docstring); depends on (job, k, ss) only.  A task of
    :func:`~workbench.estimation.montecarlo.run_monte_carlo`."""
    t0 = time.perf_counter()
    spec, s_sensors, info = member_draws(job, k, ss)
    sc = job.settings
    empty = np.zeros(0)

    def failed(msg: str) -> MemberErrors:
        info["wall_s"] = time.perf_counter() - t0
        return MemberErrors(k, empty, empty, empty, np.zeros((0, 0, 0)), np.zeros((0, 0, 0)), info, msg)

    try:
        truth = simulate_entry(sc.vehicle, spec)
    except RuntimeError as err:
        return failed(f"member {k}: truth simulation: {err}")
    info["truth_s"] = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix=f"meads_truth_mc_{k}_") as tmp:
        paths = synthesize_from_truth(
            sc,
            truth,
            spec,
            Path(tmp) / "telemetry",
            s_sensors,
            f"meads truth Monte Carlo, member {k}",
            compress=False,  # a temporary truth.npz is read back once
        )
        truth_file = paths.pop("truth")
        t1 = time.perf_counter()
        result = None
        try:
            with np.errstate(all="ignore"):
                for stage in md.reconstruct(sc, paths, other_model=False):  # scored: fit, winds, EKF
                    result = stage
        except (ValueError, TelemetryError, ArithmeticError, np.linalg.LinAlgError) as err:
            return failed(f"member {k}: reconstruction: {err}")
        info["reconstruction_s"] = time.perf_counter() - t1
        truth_npz = load_truth(truth_file)  # scoring only
    t, err, sig = error_histories(result, truth_npz)
    s = result.summary
    info.update(
        {
            "health": s["health"]["verdict"],
            "health_not_ok": [c["name"] for c in s["health"]["checks"] if c["status"] != "OK"],
            "failed_ports": [f["port"] for f in s["failed_ports"]],
            "t_hss_s": float(truth.t_hss),
            "max_qbar_pa": float(np.max(truth.qbar)),
        }
    )
    if result.ekf:
        ps = result.ekf[0]
        true_scale = np.asarray(truth_npz["sensor_scale"], float)
        info["scale_factor_error_pass1"] = [float(x) for x in ps.scale - true_scale]
        info["scale_factor_inside_3sigma_pass1"] = float(np.mean(np.abs(ps.scale - true_scale) <= 3 * ps.sigma_scale))
        info["ekf_wall_s"] = [float(p.wall_s) for p in result.ekf]
    info["wall_s"] = time.perf_counter() - t0
    qbar = np.interp(t, truth_npz["t"], truth_npz["qbar"])
    mach = np.interp(t, truth_npz["t"], truth_npz["mach"])
    return MemberErrors(k, t, qbar, mach, err, sig, info)


# ---------------------------------------------------------------------------------------------
# aggregation (pure functions of arrays)


def stack_members(members: list[MemberErrors]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The successful members on one grid: ``t`` (n,), ``err``/``sig`` (K, n, Q, E), true ``qbar``
    and ``mach`` (K, n), NaN-padded to the longest member."""
    n = max(m.t.size for m in members)
    longest = max(members, key=lambda m: m.t.size)
    K = len(members)
    shape = (K, n, len(QUANTITIES), len(ESTIMATORS))
    err, sig = np.full(shape, np.nan), np.full(shape, np.nan)
    qbar, mach = np.full((K, n), np.nan), np.full((K, n), np.nan)
    for i, m in enumerate(members):
        j = m.t.size
        if not np.allclose(m.t, longest.t[:j], rtol=0.0, atol=1e-9):
            raise ValueError(f"member {m.k}: pressure times are not on the common grid of the longest member")
        err[i, :j], sig[i, :j], qbar[i, :j], mach[i, :j] = m.err, m.sig, m.qbar, m.mach
    return longest.t, err, sig, qbar, mach


def aggregate(err: np.ndarray, sig: np.ndarray) -> dict[str, np.ndarray]:
    """Per sample, quantity and estimator over the members (axis 0) of ``err`` and ``sig`` (K, n, ...)
    — the error and reported 1σ, NaN where a member has none (axis 0 may also be the member-samples
    pooled in one flight condition, :func:`aggregate_by_mach`): ``count`` members with both,
    ``bias`` the mean error, ``mc_3sigma`` 3 × the sample standard deviation (ddof 1), ``mc_3rms``
    3 × the root mean square (bias included), ``reported_3sigma`` the mean of 3σ, ``ratio`` =
    reported_3sigma / mc_3sigma, ``inside`` the fraction of members with |error| ≤ their 3σ.  Arrays
    (n, ...); NaN where fewer than 2 members have values (``count`` and ``inside`` with 1)."""
    ok = np.isfinite(err) & np.isfinite(sig)
    e = np.where(ok, err, 0.0)
    s = np.where(ok, sig, 0.0)
    cnt = ok.sum(axis=0)
    c = np.maximum(cnt, 1)
    mean = e.sum(axis=0) / c
    var = np.where(ok, (err - mean) ** 2, 0.0).sum(axis=0) / np.maximum(cnt - 1, 1)
    two = cnt >= 2
    nan = np.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        out = {
            "count": cnt,
            "bias": np.where(two, mean, nan),
            "mc_3sigma": np.where(two, 3.0 * np.sqrt(var), nan),
            "mc_3rms": np.where(two, 3.0 * np.sqrt((e * e).sum(axis=0) / c), nan),
            "reported_3sigma": np.where(two, 3.0 * s.sum(axis=0) / c, nan),
            "inside": np.where(cnt >= 1, (ok & (np.abs(e) <= 3.0 * s)).sum(axis=0) / c, nan),
        }
        out["ratio"] = out["reported_3sigma"] / out["mc_3sigma"]
    return out


def aggregate_by_mach(
    err: np.ndarray,
    sig: np.ndarray,
    qbar: np.ndarray,
    mach: np.ndarray,
    edges: tuple[float, ...] = MACH_BIN_EDGES,
    min_member_fraction: float = MIN_BIN_MEMBER_FRACTION,
) -> dict[str, np.ndarray]:
    """The statistics of :func:`aggregate` per flight condition: the member-samples of ``err`` and
    ``sig`` (K, n, Q, E) whose own true ``mach`` (K, n) [-] falls in a bin of ``edges`` (low to high)
    and whose own true ``qbar`` (K, n) [Pa] is ≥ :data:`MIN_QBAR_PA`, pooled per bin (members fly
    different entries: the same time is a different flight condition per member, the same Mach is
    not).  Bins with a sample, **high Mach first** (B of them); arrays (B, Q, E) unless noted:

    ``mach_lo``, ``mach_hi``, ``mach_mid`` (B,) the bin's edges and centre; from :func:`aggregate`
    over the pooled samples ``count`` (member-samples), ``bias``, ``mc_3sigma`` (3 × their standard
    deviation, ddof 1), ``mc_3rms`` (3 × their RMS), ``reported_3sigma`` (mean reported 3σ),
    ``ratio`` (that / ``mc_3sigma``), ``inside``; ``reported_3sigma_median`` the median reported 3σ;
    ``members`` how many members have a sample there; ``solid`` True when ``members`` ≥
    max(2, ⌈``min_member_fraction`` · K⌉) — else the bin is *thin* (too few members to stand for the
    study)."""
    K = err.shape[0]
    e = np.asarray(edges, float)
    with np.errstate(invalid="ignore"):
        scored = (qbar >= MIN_QBAR_PA) & np.isfinite(mach)
    b = np.digitize(np.where(scored, mach, -np.inf), e) - 1  # bin of each member-sample
    scored &= (b >= 0) & (b < e.size - 1)
    bins = np.unique(b[scored])[::-1]  # high Mach first
    keys = ("count", "bias", "mc_3sigma", "mc_3rms", "reported_3sigma", "inside", "ratio")
    shape = (bins.size, *err.shape[2:])
    out: dict[str, np.ndarray] = {k: np.full(shape, np.nan) for k in (*keys, "reported_3sigma_median")}
    out["count"] = np.zeros(shape, int)
    out["members"] = np.zeros(shape, int)
    for i, bi in enumerate(bins):
        sel = scored & (b == bi)
        ei, si = err[sel], sig[sel]  # (N, Q, E) pooled member-samples
        a = aggregate(ei[:, None], si[:, None])
        for k in keys:
            out[k][i] = a[k][0]
        ok = np.isfinite(ei) & np.isfinite(si)
        has = np.zeros((K, *err.shape[2:]), bool)
        np.logical_or.at(has, np.nonzero(sel)[0], ok)
        out["members"][i] = has.sum(axis=0)
        with warnings.catch_warnings():  # an estimator or quantity without values: NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            out["reported_3sigma_median"][i] = np.nanmedian(np.where(ok, 3.0 * si, np.nan), axis=0)
    out["solid"] = out["members"] >= max(2, math.ceil(min_member_fraction * K))
    out["mach_lo"], out["mach_hi"] = e[bins], e[bins + 1]
    out["mach_mid"] = 0.5 * (out["mach_lo"] + out["mach_hi"])
    return out


def solid_bins(by_mach: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The :func:`aggregate` arrays of :func:`aggregate_by_mach` with the thin bins blanked
    (``count`` 0, the rest NaN), for :func:`summarize`: the table counts the solid bins only."""
    keys = ("count", "bias", "mc_3sigma", "mc_3rms", "reported_3sigma", "inside", "ratio")
    return {k: np.where(by_mach["solid"], by_mach[k], 0 if k == "count" else np.nan) for k in keys}


def by_mach_json(by_mach: dict[str, np.ndarray]) -> dict:
    """:func:`aggregate_by_mach` as JSON-ready columns: ``mach_lo``, ``mach_hi`` (B,) and, per
    estimator and quantity with a value, lists (B,) of ``mc_3sigma``, ``mc_3rms``,
    ``reported_3sigma_median``, ``ratio``, ``inside``, ``bias`` (NaN → None when written),
    ``members``, ``member_samples`` and ``solid``; high Mach first."""

    def col(x: np.ndarray) -> list:
        return [float(v) for v in x]

    out: dict = {"mach_lo": col(by_mach["mach_lo"]), "mach_hi": col(by_mach["mach_hi"]), "estimators": {}}
    for e, est in enumerate(ESTIMATORS):
        rows = {}
        for j, q in enumerate(QUANTITIES):
            if not np.any(by_mach["count"][:, j, e] > 0):
                continue
            rows[q] = {
                **{
                    k: col(by_mach[k][:, j, e])
                    for k in ("mc_3sigma", "mc_3rms", "reported_3sigma_median", "ratio", "inside", "bias")
                },
                "members": [int(v) for v in by_mach["members"][:, j, e]],
                "member_samples": [int(v) for v in by_mach["count"][:, j, e]],
                "solid": [bool(v) for v in by_mach["solid"][:, j, e]],
            }
        if rows:
            out["estimators"][est] = rows
    return out


def _median(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else math.nan


def _max(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.max(x)) if x.size else math.nan


def summarize(agg: dict[str, np.ndarray], over: str = "samples") -> dict:
    """The study's table (JSON-ready) from :func:`aggregate` arrays (n, Q, E) of errors already
    restricted to the samples that count (each member's true q∞ ≥ :data:`MIN_QBAR_PA`) — rows per
    time sample, or per Mach bin (:func:`solid_bins`), named ``over`` in the disagreement lines
    (``samples`` counts the rows): per
    estimator and quantity, over the rows with at least 2 member-samples — the median and max of the
    Monte Carlo 3σ, the median of 3 × RMS, the median and max of the mean reported 3σ, the median
    and 10/90 % quantiles of the ratio reported / Monte Carlo, the largest |bias|, the fraction of
    member-samples inside their reported 3σ, the objective (α, β, q∞, Mach) and whether the Monte
    Carlo 3σ (the spread) and 3 × RMS (the total error, bias included: what the objective is about)
    meet it at every sample and at which fraction of the samples; and ``disagreements``: one line
    per estimator and quantity whose median ratio is outside :data:`RATIO_BAND` or whose fraction
    inside is below :data:`MIN_INSIDE`."""
    table: dict = {}
    notes: list[str] = []
    for e, est in enumerate(ESTIMATORS):
        rows = {}
        for j, q in enumerate(QUANTITIES):
            cnt = agg["count"][:, j, e]
            sel = cnt >= 2
            if not sel.any():
                continue
            inside = float(np.sum(agg["inside"][sel, j, e] * cnt[sel]) / np.sum(cnt[sel]))
            ratio = agg["ratio"][sel, j, e]
            fin = ratio[np.isfinite(ratio)]
            mc = agg["mc_3sigma"][sel, j, e]
            row = {
                "samples": int(sel.sum()),
                "member_samples": int(cnt[sel].sum()),
                "mc_3sigma_median": _median(mc),
                "mc_3sigma_max": _max(mc),
                "mc_3rms_median": _median(agg["mc_3rms"][sel, j, e]),
                "reported_3sigma_median": _median(agg["reported_3sigma"][sel, j, e]),
                "reported_3sigma_max": _max(agg["reported_3sigma"][sel, j, e]),
                "ratio_median": _median(ratio),
                "ratio_to_3rms_median": _median(agg["reported_3sigma"][sel, j, e] / agg["mc_3rms"][sel, j, e]),
                "ratio_p10": float(np.quantile(fin, 0.1)) if fin.size else math.nan,
                "ratio_p90": float(np.quantile(fin, 0.9)) if fin.size else math.nan,
                "max_abs_bias": _max(np.abs(agg["bias"][sel, j, e])),
                "fraction_inside_reported_3sigma": inside,
            }
            if q in OBJECTIVES:
                rms = agg["mc_3rms"][sel, j, e]
                row["objective_3sigma"] = OBJECTIVES[q]
                row["mc_meets_objective"] = bool(np.nanmax(mc) <= OBJECTIVES[q])
                row["fraction_of_samples_meeting_objective"] = float(np.mean(mc <= OBJECTIVES[q]))
                row["3rms_meets_objective"] = bool(np.nanmax(rms) <= OBJECTIVES[q])
                row["fraction_of_samples_3rms_meeting_objective"] = float(np.mean(rms <= OBJECTIVES[q]))
            rows[q] = row
            r = row["ratio_median"]
            off_band = math.isfinite(r) and not RATIO_BAND[0] <= r <= RATIO_BAND[1]
            if off_band or inside < MIN_INSIDE:
                what = ("conservative" if r > 1 else "optimistic") if off_band else "spread matched"
                notes.append(
                    f"{est} {q}: reported 3σ {row['reported_3sigma_median']:.3g} is {r:.2f}× the Monte Carlo 3σ "
                    f"{row['mc_3sigma_median']:.3g} (median over the {over} above {MIN_QBAR_PA:g} Pa; {what}; 3 × RMS "
                    f"{row['mc_3rms_median']:.3g}, ratio {row['ratio_to_3rms_median']:.2f}); "
                    f"{100 * inside:.1f} % of member-samples inside the reported 3σ, largest |bias| "
                    f"{row['max_abs_bias']:.3g}"
                )
        if rows:
            table[est] = rows
    return {"table": table, "disagreements": notes}


# ---------------------------------------------------------------------------------------------
# driver


@dataclass(frozen=True)
class FullMcResult:
    """Outcome of :func:`run_full_monte_carlo`: ``by_mach`` the :func:`aggregate_by_mach` arrays
    (B, Q, E) per Mach bin, high Mach first (the summary's table and the recording's curves);
    ``t`` (n,) [s] the common grid and ``curves`` the :func:`aggregate` arrays (n, Q, E) per time
    sample of each member's samples above :data:`MIN_QBAR_PA` (the summary's ``table_by_time``,
    for comparison: the same time is a different flight condition per member), ``mach`` (n,) the
    members' median true Mach, ``qbar`` (n,) their median true q∞ [Pa]; ``members`` every
    :class:`MemberErrors` in member order (failed ones included); ``summary`` JSON-ready."""

    t: np.ndarray
    curves: dict
    mach: np.ndarray
    qbar: np.ndarray
    members: tuple[MemberErrors, ...]
    summary: dict
    by_mach: dict = field(default_factory=dict)


def run_full_monte_carlo(
    settings: MeadsSettings,
    *,
    n_runs: int,
    seed: int,
    workers: int = 1,
    scheduler: str | None = None,
    disperse_truth: bool = True,
    sigmas: MeadsDispersionSigmas | None = None,
) -> FullMcResult:
    """The study of the module docstring for the ``settings`` of a synthetic MEADS scenario: ``n_runs`` ≥ 1
    members seeded ``SeedSequence(seed, spawn_key=(k,))`` on
    :func:`~workbench.estimation.montecarlo.run_monte_carlo` (``workers``, ``scheduler`` as
    there); ``disperse_truth``: each member its own truth (``sigmas``, default
    :class:`~workbench.problems.meads.truth.MeadsDispersionSigmas`), else the scenario's truth
    with new sensor errors only.  Raises ``RuntimeError`` when no member could be reconstructed."""
    wall0 = time.perf_counter()
    if int(n_runs) < 1:
        raise ValueError("run_full_monte_carlo: n_runs must be ≥ 1")
    removed = settings.pressure.failure_port
    sc = replace(settings, pressure=replace(settings.pressure, failure_port="")) if removed else settings
    job = McJob(sc, bool(disperse_truth), sigmas or MeadsDispersionSigmas())
    run = run_members(
        _run_member, n_runs, shared=job, seed=seed, workers=workers, scheduler=scheduler, name=f"meads-truth-mc-{seed}"
    )
    members: list[MemberErrors] = list(run.results)
    ok = [m for m in members if not m.failed]
    if not ok:
        raise RuntimeError("no Monte Carlo member could be reconstructed: " + "; ".join(m.failed for m in members))
    t, err, sig, qbar, mach = stack_members(ok)
    by_mach = aggregate_by_mach(err, sig, qbar, mach)  # each member's own Mach and q∞ ≥ 850 Pa
    table = summarize(solid_bins(by_mach), over="Mach bins")
    above = (qbar >= MIN_QBAR_PA)[..., None, None]  # each member's own samples above 850 Pa
    curves = aggregate(np.where(above, err, np.nan), np.where(above, sig, np.nan))
    by_time = summarize(curves, over="time samples")
    walls = np.array([m.info["wall_s"] for m in members])
    K = len(ok)
    summary = {
        "kind": "meads_truth_mc",
        "scenario": settings.run.name,
        "n_runs": int(n_runs),
        "n_ok": K,
        "seed": int(seed),
        "failed_members": [m.failed for m in members if m.failed],
        "estimators": list(ESTIMATORS),
        "quantities": list(QUANTITIES),
        "min_qbar_pa": MIN_QBAR_PA,
        "truth_dispersed": bool(disperse_truth),
        "truth_dispersion_sigmas": dict(job.sigmas.__dict__) if disperse_truth else None,
        "failure_port_switched_off": removed or None,
        "error_model": {
            k: getattr(sc.pressure, k)
            for k in ("location", "time_tag", "lag", "transpiration", "calibration", "scale_factors", "noise")
        },
        "aggregation": (
            "per Mach bin (mach_bin_edges, each member-sample at its own true Mach, q∞ ≥ min_qbar_pa), "
            "the member-samples of a bin pooled; table: over the solid bins (≥ min_bin_members members)"
        ),
        "mach_bin_edges": list(MACH_BIN_EDGES),
        "min_bin_members": max(2, math.ceil(MIN_BIN_MEMBER_FRACTION * K)),
        "mc_3sigma_definition": "3 × the standard deviation (ddof 1) of the errors pooled in a Mach bin; "
        "mc_3rms: 3 × their root mean square (bias included)",
        "ratio_definition": "mean reported 3σ / Monte Carlo 3σ (3 × std of the pooled errors, ddof 1)",
        "mc_3sigma_relative_uncertainty": 1.0 / math.sqrt(2.0 * (K - 1)) if K > 1 else None,
        "objectives_3sigma": OBJECTIVES,
        **table,
        "by_mach": by_mach_json(by_mach),
        "table_by_time": by_time["table"],
        "disagreements_by_time": by_time["disagreements"],
        "member_health": {m.k: m.info.get("health") for m in ok},
        "member_health_not_ok": {m.k: m.info.get("health_not_ok") for m in ok if m.info.get("health_not_ok")},
        "member_failed_ports": {m.k: m.info.get("failed_ports") for m in ok if m.info.get("failed_ports")},
        "scale_factor_inside_3sigma_pass1": [m.info.get("scale_factor_inside_3sigma_pass1") for m in ok],
        "member_wall_s": {"median": float(np.median(walls)), "max": float(np.max(walls))},
        "executor": run.executor,
        "workers": run.workers,
        "executor_wall_s": run.wall_s,
        "wall_s": time.perf_counter() - wall0,
    }
    with np.errstate(all="ignore"):
        qm, mm = np.nanmedian(qbar, axis=0), np.nanmedian(mach, axis=0)
    return FullMcResult(t, curves, mm, qm, tuple(members), summary, by_mach)
