"""Entry and descent reconstruction (AMELIA method, Aboudan et al. 2018): telemetry -> trajectory, atmosphere, winds.

Stages, each yielded as a frozen dataclass so the recorder (or a test) can observe them:

1. :class:`~workbench.problems.entry.preprocess.EntryTelemetry` — the files as read and validated
   (GNC rate/quaternion/total acceleration at 10 Hz, on-board position/velocity at 1 Hz, RDA
   packets); defects reported by file, column and row.
2. :class:`~workbench.problems.entry.preprocess.PreprocessedIMU` — AMELIA Sect. 4: gravity removed
   at the on-board position, acceleration rotated to the body with the on-board quaternion, gaps
   turned into Δv/Δp/ΔC bridges, the saturated X rate rebuilt, 100 Hz resampling after PDD.
3. :class:`NominalIntegration` — Sect. 5: strapdown (RK4) with first-order covariance from the
   nominal initial state, validated against the on-board solution before PDD.
4. :class:`~workbench.problems.entry.dispersion.DispersionResult` — Sect. 6: ≥ 10 000 trajectories from a
   dispersed initial state, acceptance rules, refined state and its uncertainty (in-process or Dask).
5. :class:`~workbench.problems.entry.filter.EntryFilterResult` — Sects. 7–8: RDA plane fits, EKF with
   the radar models B.3–B.6 and constrained update directions, RTS backward pass.
6. :class:`~workbench.problems.entry.atmosphere.AtmosphereResult` — Sect. 9: density from drag with the
   drag coefficient iterated from the tables, blackout fill, hydrostatic pressure, temperature, 1σ.
7. :class:`~workbench.problems.entry.winds.WindResult` — Sect. 10: by default from the direction of the
   measured specific force (the air-relative velocity of the parachute–module system); the attitude
   method is computed as a cross-check (``[winds] method``).
8. :class:`EntryResult` — all of it plus the summary numbers.

The reconstruction reads only its :class:`~workbench.problems.entry.config.EntrySettings`, the
telemetry files and the nominal initial state (``initial_state.toml``, AMELIA Table 2 style); truth
never enters here.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.frames import julian_date_from_utc, planetocentric_amelia, planetocentric_of_date
from workbench.core.interpolation import interp_rows
from workbench.core.rotation import attitude_error, quat_normalize
from workbench.core.timescales import julian_date_utc
from workbench.estimation.consistency import chi2_interval, is_symmetric_pd, nees
from workbench.estimation.health import ERROR, OK, WARNING, Check, health_markdown
from workbench.estimation.strapdown import integrate, integrate_members
from workbench.io import scorecard as fmt
from workbench.io.scenario import ScenarioError
from workbench.io.telemetry import TelemetryError
from workbench.io.units import UnitError
from workbench.models.aerodynamics import EntryVehicle
from workbench.models.radar import velocity_out_model
from workbench.problems.entry.atmosphere import reconstruct_atmosphere
from workbench.problems.entry.config import EntrySettings
from workbench.problems.entry.dispersion import run_configured_dispersion
from workbench.problems.entry.filter import RadarData, run_entry_smoother
from workbench.problems.entry.health import (
    drag_axis_check,
    entry_health,
    radar_first_lock_check,
    radar_velocity_axes_check,
)
from workbench.problems.entry.initial import initial_for_smoother, reconstruction_P0
from workbench.problems.entry.preprocess import preprocess
from workbench.problems.entry.scoring import errors_sigmas
from workbench.problems.entry.site import R_MOLA
from workbench.problems.entry.state import DP, DTH, DV
from workbench.problems.entry.telemetry import (
    NominalState,
    check_event_span,
    read_entry_telemetry,
    read_nominal_state,
)
from workbench.problems.entry.winds import estimate_winds

__all__ = [
    "inertial_velocity_out",
    "phase_index",
    "NominalIntegration",
    "EntryResult",
    "imu_error_process_noise",
    "reconstruct",
    "score",
    "score_atmosphere",
    "score_winds",
    "DENSITY_BOUNDS",
    "WIND_BOUND_MPS",
    "scorecard_markdown",
    "event_table",
    "epoch_utc",
]


@dataclass(frozen=True)
class NominalIntegration:
    """Strapdown from the nominal state (Sect. 5) and its validation against the on-board solution.

    ``onboard_t`` (m,) the on-board 1 Hz times before PDD; ``diff_position_m``, ``diff_velocity_mps``
    (m,) |reconstruction − on-board|; ``diff_attitude_deg`` (m,) angle between the attitudes.
    """

    strapdown: object
    onboard_t: np.ndarray | None
    diff_position_m: np.ndarray | None
    diff_velocity_mps: np.ndarray | None
    diff_attitude_deg: np.ndarray | None
    summary: dict = field(default_factory=dict)


@dataclass(frozen=True)
class EntryResult:
    """Everything the reconstruction produced, plus ``summary`` (JSON-ready numbers)."""

    telemetry: object
    imu: object
    nominal: NominalIntegration
    dispersion: object
    filter: object
    atmosphere: object
    winds: object
    vehicle: EntryVehicle
    events: dict
    summary: dict
    start: object = None


# ----------------------------------------------------------------------------------------- inputs
def imu_error_process_noise(t: np.ndarray, f_G: np.ndarray, w_G: np.ndarray, levels: dict) -> np.ndarray:
    """State-noise PSD η (9,) [units²/s] of ``[δv_M, δθ_G, δp_M]`` that covers the IMU's per-run errors.

    The filter has no bias/scale/misalignment states; instead each constant per-run error is
    replaced by the random walk that reaches the same 1σ at the end of the arc of duration ``T``
    (``t[-1] − t[0]`` [s]): a bias ``b`` integrates to ``b T`` (η = b² T); a scale factor ``s`` and
    an accelerometer misalignment ``m`` to ``s ΔV`` and ``m ΔV`` with ``ΔV = ∫|f| dt`` over the arc
    (η = (s² + m²) ΔV² / T); a gyro scale factor to ``s Θ`` with ``Θ = ∫|ω| dt``; a gyro
    misalignment of a spinning body stays bounded at ≈ ``m`` (its error rotates with the spin), so
    η = m² / T.  Per axis, velocity and attitude; the position noise is zero (it follows the
    velocity).  The random walk spreads the error evenly in time where the true one follows the
    deceleration pulse: a conservative, documented approximation.  ``t`` (n,) [s], ``f_G`` (n,3)
    [m/s²], ``w_G`` (n,3) [rad/s]; ``levels`` the 1σ of ``accel_bias`` [m/s²], ``accel_scale``,
    ``accel_misalignment`` [rad], ``gyro_bias`` [rad/s], ``gyro_scale``, ``gyro_misalignment`` [rad].
    """
    t = np.asarray(t, dtype=float)
    T = float(t[-1] - t[0])
    if T <= 0:
        return np.zeros(9)
    dt = np.diff(t)
    fn = np.linalg.norm(np.nan_to_num(np.asarray(f_G, dtype=float)), axis=1)
    wn = np.linalg.norm(np.nan_to_num(np.asarray(w_G, dtype=float)), axis=1)
    dV = float(np.sum(0.5 * (fn[1:] + fn[:-1]) * dt))
    Th = float(np.sum(0.5 * (wn[1:] + wn[:-1]) * dt))
    g = {k: float(levels.get(k, 0.0)) for k in ("accel_bias", "accel_scale", "accel_misalignment")}
    g.update({k: float(levels.get(k, 0.0)) for k in ("gyro_bias", "gyro_scale", "gyro_misalignment")})
    eta_v = g["accel_bias"] ** 2 * T + (g["accel_scale"] ** 2 + g["accel_misalignment"] ** 2) * dV**2 / T
    eta_th = g["gyro_bias"] ** 2 * T + g["gyro_scale"] ** 2 * Th**2 / T + g["gyro_misalignment"] ** 2 / T
    return np.array([eta_v] * 3 + [eta_th] * 3 + [0.0] * 3)


# ----------------------------------------------------------------------------------------- stages
def _nominal_integration(imu, nom: NominalState, tm, P0: np.ndarray, bridge_mode: str) -> NominalIntegration:
    sp = integrate(imu, nom.v_M, nom.q_M_G, nom.p_M, P0, bridge_mode=bridge_mode, body=MARS, fast=True)
    # validation against the on-board solution before PDD (afterwards the on-board attitude is wrong)
    t_pdd = tm.events.get("PDD", np.inf)
    m = (tm.t_nav >= sp.t[0]) & (tm.t_nav <= min(t_pdd, sp.t[-1]))
    if not m.any():
        return NominalIntegration(sp, None, None, None, None, {})
    tn = tm.t_nav[m]
    pi = interp_rows(tn, sp.t, sp.p_M)
    vi = interp_rows(tn, sp.t, sp.v_M)
    dp = np.linalg.norm(pi - tm.p_M_nav[m], axis=1)
    dv = np.linalg.norm(vi - tm.v_M_nav[m], axis=1)
    k = np.searchsorted(sp.t, tn).clip(0, sp.t.size - 1)
    kq = np.searchsorted(tm.t_gnc, tn).clip(0, tm.t_gnc.size - 1)
    dth = np.degrees(np.linalg.norm(attitude_error(tm.q_M_G_nav[kq], sp.q_M_G[k]), axis=1))
    summ = {
        "vs_onboard_before_pdd": {
            "max_velocity_mps": float(dv.max()),
            "max_position_m": float(dp.max()),
            "max_attitude_deg": float(dth.max()),
            "paper": "7.5 m/s, 530 m, < 0.01 deg (AMELIA Sect. 5)",
        }
    }
    return NominalIntegration(sp, tn, dp, dv, dth, summ)


def phase_index(t: np.ndarray, events: dict) -> np.ndarray:
    """Flight phase (n,) int of the times ``t`` (n,) [s]: 0 before the parachute deployment (event
    ``PDD``), 1 under the parachute, 2 after the front-shield release (``FSR``); ``events`` {name: t [s]}."""
    ph = np.zeros(t.shape, dtype=int)
    ph[t >= events.get("PDD", np.inf)] = 1
    ph[t >= events.get("FSR", np.inf)] = 2
    return ph


def reconstruct(
    settings: EntrySettings,
    paths: dict[str, Path],
    *,
    scheduler: str | None = None,
    members: int | None = None,
    progress=None,
) -> Iterator[object]:
    """Run the entry reconstruction; yields the stages in order, the last an :class:`EntryResult`.

    ``settings``: the run's :class:`~workbench.problems.entry.config.EntrySettings`; ``paths``: the
    telemetry files (keys of :data:`~workbench.problems.entry.telemetry.STREAMS`);
    ``scheduler``: None (in-process), ``"local"`` (Dask LocalCluster) or ``"tcp://host:port"`` for the
    dispersion; ``members`` overrides ``[dispersion] members``.
    """
    cfg = settings
    vehicle = cfg.require_vehicle()
    r_ground = cfg.r_ground
    tm = read_entry_telemetry(paths, cfg.checks)
    check_event_span(tm, paths)
    nom = read_nominal_state(paths["initial_state"])
    yield tm
    stages = _stages(cfg, vehicle, r_ground, paths, tm, nom, scheduler=scheduler, members=members)
    last = "EntryTelemetry"
    while True:
        try:
            stage = next(stages)
        except StopIteration:
            return
        except (TelemetryError, ScenarioError, UnitError):
            raise
        except (ValueError, ArithmeticError, IndexError) as err:
            raise np.linalg.LinAlgError(
                f"the entry reconstruction failed in the stage after {last} ({type(err).__name__}: {err}); the inputs "
                "passed the unit and axis checks: look at the health of the telemetry (gaps, saturation) and the "
                "vehicle and scenario settings"
            ) from err
        last = type(stage).__name__
        yield stage


def _stages(cfg, vehicle, r_ground, paths, tm, nom, *, scheduler, members) -> Iterator[object]:
    """The stages of :func:`reconstruct` after the telemetry (preprocessing to the result)."""
    imu = preprocess(tm, cfg.preprocess)
    drag = drag_axis_check(imu.t, imu.f_G, str(paths["gnc"]), f"the vehicle ({vehicle.name})")
    if drag.status == ERROR:
        raise TelemetryError.single(paths["gnc"], drag.message, column="q1..q4, w_x..w_z")
    yield imu
    if abs(nom.t0 - float(imu.t[0])) > 0.05:
        raise ScenarioError(
            Path(paths["initial_state"]),
            "initial_state.t0_s",
            f"{nom.t0:.3f} s, but the IMU data of {Path(paths['gnc']).name} start at {float(imu.t[0]):.3f} s: the "
            "state must be given at the first sample with an acceleration (or that file's times are shifted)",
        )
    bridge_mode = cfg.reconstruction.bridge_mode
    P0 = reconstruction_P0(cfg.reconstruction)
    nomi = _nominal_integration(imu, nom, tm, P0, bridge_mode)
    yield nomi

    # ---- dispersion (Sect. 6)
    disp = run_configured_dispersion(
        cfg, imu, nom, tm.events, members=members, scheduler=scheduler, n_cloud=cfg.dispersion.cloud
    )
    yield disp

    # ---- radar-aided smoother (Sects. 7-8) from the refined state
    beams = cfg.radar.beams_G()
    radar = RadarData.of(tm, beams, r_ground)
    init = initial_for_smoother(cfg.reconstruction, disp, nom, P0)
    yield init
    v0, q0, p0, P0_ref = init.v0, init.q0, init.p0, init.P0
    t_out = np.asarray(tm.t_rda, float)[np.asarray(tm.rda_valid, bool)]
    dt_out = float(np.median(np.diff(t_out))) if t_out.size > 1 else None
    sigmas = dict(cfg.smoother_sigmas(slant_out_dt_s=dt_out))
    psd = imu_error_process_noise(imu.t, imu.f_G, imu.w_G, cfg.reconstruction.imu_errors)
    if np.any(psd > 0):
        sigmas["q_state_psd"] = tuple(float(x) for x in psd)
    filt = run_entry_smoother(
        imu,
        radar,
        v0,
        q0,
        p0,
        P0_ref,
        sigmas=sigmas,
        constrained=cfg.radar.constrained,
    )
    yield filt

    # ---- atmosphere (Sect. 9) and winds (Sect. 10) along the smoothed trajectory
    sm = filt.smoothed
    ph = phase_index(sm.t, tm.events)
    f_valid = np.ones(sm.t.size, dtype=bool)
    atm = reconstruct_atmosphere(
        sm.t,
        sm.p_M,
        sm.v_M,
        sm.q_M_G,
        sm.P,
        imu.f_G,
        f_valid,
        ph,
        vehicle,
        default_atmosphere=MarsEngineeringAtmosphere(),
        settings=cfg.atmosphere,
        events=tm.events,
    )
    yield atm
    wind_method = cfg.wind_method
    winds = estimate_winds(
        sm.t, sm.p_M, sm.v_M, sm.q_M_G, sm.P, imu.f_G, ph, vehicle, atm, events=tm.events, method=wind_method
    )
    other = "attitude" if wind_method == "specific_force" else "specific_force"
    winds_check = estimate_winds(
        sm.t, sm.p_M, sm.v_M, sm.q_M_G, sm.P, imu.f_G, ph, vehicle, atm, events=tm.events, method=other
    )
    yield winds

    summary = _summary(cfg, tm, imu, nomi, disp, filt, atm, winds, r_ground)
    summary["filter_sigmas"] = {
        "slant_range_m": float(sigmas["slant_range"]),
        "slant_out_m": float(sigmas["slant_out"]),
        "velocity_out_mps": float(sigmas["velocity_out"]),
        "imu_process_noise_velocity_m2ps3": float(psd[0]),
        "imu_process_noise_attitude_rad2ps": float(psd[3]),
    }
    ok = winds.valid & winds_check.valid
    summary["winds"] = {
        "method": winds.method,
        "valid_samples": int(np.sum(winds.valid)),
        "cross_check_method": winds_check.method,
        "max_difference_between_methods_mps": float(
            np.max(np.hypot(winds.wind_N[ok] - winds_check.wind_N[ok], winds.wind_E[ok] - winds_check.wind_E[ok]))
        )
        if ok.any()
        else float("nan"),
    }
    summary["smoother_start"] = {
        "mode": init.mode,
        "note": init.note,
        "sigma_velocity_mps": float(np.sqrt(np.max(np.diag(init.P0)[DV]))),
        "sigma_attitude_deg": float(np.degrees(np.sqrt(np.max(np.diag(init.P0)[DTH])))),
        "sigma_position_m": float(np.sqrt(np.max(np.diag(init.P0)[DP]))),
    }
    n_acc = int(np.sum(disp.accepted))
    acc = Check(
        "dispersion.accepted",
        OK if init.mode == cfg.reconstruction.initial else WARNING,
        n_acc,
        10,
        f"{n_acc} of {int(disp.n)} dispersion members satisfy the acceptance rules"
        + (
            f" — {init.note}: the nominal state, the events or the rules disagree with the data"
            if init.note and init.mode != cfg.reconstruction.initial
            else ""
        ),
    )
    lock = radar_first_lock_check(filt.innovations.get("slant_out"), str(paths["rda_out"]))
    vaxes = radar_velocity_axes_check(*inertial_velocity_out(tm, imu, init), str(paths["rda_out"]))
    summary["health"] = entry_health(tm, imu, filt, atm, r_ground, extra=[drag, lock, vaxes, acc])
    yield EntryResult(tm, imu, nomi, disp, filt, atm, winds, vehicle, dict(tm.events), summary, init)


def inertial_velocity_out(tm, imu, init) -> tuple[np.ndarray, np.ndarray]:
    """The radar's valid velocity-out samples inside the IMU data (k, 3) [m/s, G] and their
    prediction from the inertial trajectory alone (the smoother's start state ``init`` integrated
    through ``imu`` without radar updates, ``models.radar.velocity_out_model``), (k, 3)."""
    ok = np.asarray(tm.rda_valid, bool) & (tm.t_rda >= imu.t[0]) & (tm.t_rda <= imu.t[-1])
    if ok.sum() < 5:
        return np.empty((0, 3)), np.empty((0, 3))
    tr = np.asarray(tm.t_rda, float)[ok]
    r = integrate_members(imu, init.v0, init.q0, init.p0, at_t=tr, body=MARS)
    y, _ = velocity_out_model(r["v_at"].reshape(-1, 3), r["q_at"].reshape(-1, 4), r["p_at"].reshape(-1, 3))
    return np.asarray(tm.v_out_G, float)[ok], y


# ----------------------------------------------------------------------------------------- summary
def epoch_utc(settings: EntrySettings, tm=None) -> str:
    """UTC of t = 0 (EIP): ``[scenario] epoch_utc``, else the telemetry's ``# epoch_utc:`` line."""
    if settings.epoch_utc is not None:
        return settings.epoch_utc
    if tm is not None and getattr(tm, "epoch_utc", ""):
        return str(tm.epoch_utc)
    raise ScenarioError(
        settings.run.path, "scenario.epoch_utc", "missing, and the telemetry has no '# epoch_utc:' line"
    )


def epoch_jd_tdb(settings: EntrySettings, tm=None) -> float:
    """Julian date (TDB) of t = 0 (EIP), from :func:`epoch_utc` (``core.frames.julian_date_from_utc``)."""
    return julian_date_from_utc(epoch_utc(settings, tm))


def event_table(
    settings: EntrySettings, events: dict, t: np.ndarray, p_M: np.ndarray, r_ground: float, tm=None
) -> list[dict]:
    """AMELIA Table 5 analogue: event, t [s], UTC, east longitude / latitude [deg], altitude AMR [km].

    ``lon_deg``/``lat_deg`` use the pole and meridian of date at TDB (``core.frames.planetocentric_of_date``);
    ``lon_amelia_deg``/``lat_amelia_deg`` the convention that reproduces the paper's printed Table 5
    (``core.frames.planetocentric_amelia``: MMED latitude, meridian at the UTC date), for comparison with it.
    """
    import datetime as dt

    jd0 = epoch_jd_tdb(settings, tm)
    jd0_utc = julian_date_utc(epoch_utc(settings, tm))
    epoch = dt.datetime.fromisoformat(epoch_utc(settings, tm).replace("Z", "+00:00"))
    rows = []
    names = [("First data", float(t[0]))] + sorted(events.items(), key=lambda kv: kv[1]) + [("Last data", float(t[-1]))]
    for name, te in names:
        step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
        if not (t[0] - 1e-9 <= te <= t[-1] + step + 1e-9):  # an event up to one sample after the end (BSR)
            continue
        te_pos = min(te, float(t[-1]))
        p = interp_rows(te_pos, t, p_M)
        lat, lon, r = planetocentric_of_date(MARS, jd0 + te_pos / 86400.0, p)
        lat_a, lon_a, _ = planetocentric_amelia(MARS, jd0_utc + te_pos / 86400.0, p)
        rows.append(
            {
                "event": name,
                "t_s": float(te),
                "utc": (epoch + dt.timedelta(seconds=float(te))).strftime("%H:%M:%S.%f")[:-3],
                "lon_deg": float(np.degrees(lon)),
                "lat_deg": float(np.degrees(lat)),
                "lon_amelia_deg": float(np.degrees(lon_a)),
                "lat_amelia_deg": float(np.degrees(lat_a)),
                "alt_amr_km": float((r - R_MOLA) / 1e3),
                "alt_agl_km": float((r - r_ground) / 1e3),
            }
        )
    return rows


def _summary(settings: EntrySettings, tm, imu, nomi, disp, filt, atm, winds, r_ground) -> dict:
    sm = filt.smoothed
    sym, pd = is_symmetric_pd(sm.P)
    out = {
        "scenario": settings.run.name,
        "kind": "entry",
        "r_ground_m": float(r_ground),
        "samples": int(sm.t.size),
        "events": dict(tm.events),
        "event_table": event_table(settings, tm.events, sm.t, sm.p_M, r_ground, tm),
        "telemetry_problems": list(tm.problems),
        "gaps_s": [float(g.t_b - g.t_a) for g in imu.gaps],
        "saturated_samples": int(np.sum(np.asarray(imu.saturated, bool) & ~np.asarray(imu.resampled, bool))),
        "saturation_window_samples": int(np.sum(imu.saturated)),
        "nominal_integration": nomi.summary,
        "dispersion": {
            "members": int(disp.n),
            "accepted": int(np.sum(disp.accepted)),
            "accepted_fraction": float(np.mean(disp.accepted)),
            "wall_s": float(disp.wall_s),
            "scheduler": str(disp.scheduler),
            "refined_sigma": {
                "velocity_mps": float(np.sqrt(np.max(np.diag(disp.refined_P0)[DV]))),
                "attitude_deg": float(np.degrees(np.sqrt(np.max(np.diag(disp.refined_P0)[DTH])))),
                "position_m": float(np.sqrt(np.max(np.diag(disp.refined_P0)[DP]))),
            },
        },
        "covariance": {"symmetric": bool(np.all(sym)), "positive_definite": bool(np.all(pd))},
        "atmosphere": {"iterations": int(atm.n_iterations), "converged": bool(atm.converged)},
    }
    # radar residual maxima (smoothed), the paper's goodness-of-fit bounds
    res = {}
    for ch, r in filt.smoothed_residuals.items():
        if len(r.t):
            res[ch] = {"max_abs": float(np.max(np.abs(r.y))), "n": int(len(r.t))}
    out["radar_residuals"] = res
    if filt.plane_fits:
        out["plane_fits"] = [
            {
                "t_s": float(tp),
                "h_agl_m": float(pf.h_agl),
                "off_vertical_deg": float(np.degrees(pf.off_vertical)),
                "rms_m": float(pf.rms),
            }
            for tp, pf in filt.plane_fits
        ]
    t_last = float(sm.t[-1])
    out["end"] = {
        "t_s": t_last,
        "h_agl_m": float(np.linalg.norm(sm.p_M[-1]) - r_ground),
        "sigma_h_m": float(np.sqrt(_radial_var(sm.p_M[-1], sm.P[-1]))),
    }
    return out


def _radial_var(p: np.ndarray, P: np.ndarray) -> float:
    u = p / np.linalg.norm(p)
    return float(u @ P[DP, DP] @ u)


# ----------------------------------------------------------------------------------------- scoring
def _truth_rows(truth: dict, key: str, t: np.ndarray) -> np.ndarray:
    return interp_rows(t, truth["t"], truth[key])


def score(result: EntryResult, truth: dict) -> dict:
    """Accuracy and consistency of a reconstruction against the synthetic truth (scoring only).
    ``out["headline"]``: the headline's height above ground at the end of the data, its error
    against the truth and its reported 1σ [m] (judged against ±3σ by the runner)."""
    sm = result.filter.smoothed
    t = sm.t
    pT = _truth_rows(truth, "p_M", t)
    vT = _truth_rows(truth, "v_M", t)
    qT = quat_normalize(_truth_rows(truth, "q_M_G", t))
    err = np.concatenate([vT - sm.v_M, attitude_error(sm.q_M_G, qT), pT - sm.p_M], axis=1)
    ne = nees(err, sm.P)
    ev = result.events
    out: dict = {}
    rg = float(result.summary["r_ground_m"])
    h_est = np.linalg.norm(sm.p_M, axis=1) - rg
    h_true = np.linalg.norm(pT, axis=1) - rg
    sd_h = np.sqrt([_radial_var(sm.p_M[k], sm.P[k]) for k in range(t.size)])
    fix = result.filter.innovations.get("slant_out")
    t_fix = float(fix.t[0]) if fix is not None and len(fix.t) else np.inf
    m = t >= t_fix
    if m.any():
        e = np.abs(h_est[m] - h_true[m])
        out["after_radar_fix"] = {
            "max_h_agl_error_m": float(e.max()),
            "inside_3sigma_fraction": float(np.mean(e <= 3 * sd_h[m])),
            "median_3sigma_m": float(np.median(3 * sd_h[m])),
        }
    lo, hi = chi2_interval(9)
    _, e_c, _, _ = errors_sigmas(sm, vT, qT, pT)
    ne_c = nees(e_c, sm.P)
    out["nees_smoothed_curvilinear"] = {
        "mean": float(np.mean(ne_c)),
        "median": float(np.median(ne_c)),
        "note": "position error as horizontal + altitude about the estimate (no |δp_h|²/2r curvature term); "
        "one run: see `workbench mc` for the ANEES over many",
    }
    out["nees_smoothed"] = {
        "mean": float(np.mean(ne)),
        "median": float(np.median(ne)),
        "single_step_95pct_band_9dof": [lo, hi],
        "fraction_inside_band": float(np.mean((ne >= lo) & (ne <= hi))),
    }
    # initial states against the truth at t0: the paper's refined state and the smoother's start
    t0 = np.array([float(sm.t[0])])
    v_t0, p_t0 = _truth_rows(truth, "v_M", t0)[0], _truth_rows(truth, "p_M", t0)[0]
    q_t0 = quat_normalize(_truth_rows(truth, "q_M_G", t0)[0])
    d = result.dispersion
    for name, (v0, q0, p0, P0) in {
        "dispersion_refined": (d.refined_v0, d.refined_q0, d.refined_p0, d.refined_P0),
        "smoother_start": (result.start.v0, result.start.q0, result.start.p0, result.start.P0),
    }.items():
        e0 = np.concatenate([v_t0 - v0, attitude_error(q0, q_t0), p_t0 - p0])
        ok = np.all(np.isfinite(P0))
        out[f"initial_{name}"] = {
            "nees_9dof": float(e0 @ np.linalg.solve(P0, e0)) if ok else float("nan"),
            "nees_95pct_band": list(chi2_interval(9)),
            "error_velocity_mps": float(np.linalg.norm(e0[DV])),
            "error_attitude_deg": float(np.degrees(np.linalg.norm(e0[DTH]))),
            "error_position_m": float(np.linalg.norm(e0[DP])),
        }
    # atmosphere as a profile: reconstructed ρ(h) vs the true ρ at the same (reconstructed) altitude.
    # (Blackout fill samples carry interpolated times, so a comparison along time would be wrong
    # there; along the measured parts h_est is within tens of metres of the truth.)
    atm = result.atmosphere
    if truth.get("atmosphere") is not None:
        out["atmosphere"] = score_atmosphere(atm, truth, ev)
    # winds inside the layers (where the true wind exceeds 5 m/s), with the reported 1σ
    w = result.winds
    if "wind_NE" in truth:
        out["winds_in_layers"] = score_winds(w, truth)
    # radar: what the filter's sphere model misses (relief + noise) against its 1σ
    tm = result.telemetry
    if "radar_slant_out_sphere" in truth and len(getattr(tm, "t_rda", [])):
        sph = np.interp(tm.t_rda, truth["radar_t"], truth["radar_slant_out_sphere"])
        ter = np.interp(tm.t_rda, truth["radar_t"], truth["radar_slant_out_true"]) - sph
        ok = np.asarray(tm.rda_valid, bool) & np.isfinite(sph) & np.isfinite(tm.slant_out)
        if ok.any():
            e = tm.slant_out[ok] - sph[ok]
            sg = float(result.summary.get("filter_sigmas", {}).get("slant_out_m", float("nan")))
            out["radar"] = {
                "slant_out_rms_error_vs_sphere_m": float(np.sqrt(np.mean(e**2))),
                "slant_out_max_abs_error_vs_sphere_m": float(np.max(np.abs(e))),
                "slant_out_rms_terrain_m": float(np.sqrt(np.mean(ter[ok] ** 2))),
                "filter_slant_out_sigma_m": sg,
                "slant_out_error_over_sigma_rms_ratio": float(np.sqrt(np.mean(e**2)) / sg),
                "n": int(ok.sum()),
            }
    nom = result.nominal.strapdown
    pN = _truth_rows(truth, "p_M", nom.t)
    vN = _truth_rows(truth, "v_M", nom.t)
    qN = quat_normalize(_truth_rows(truth, "q_M_G", nom.t))
    pre = nom.t <= ev.get("PDD", np.inf)
    out["nominal_vs_truth_before_pdd"] = {
        "max_velocity_mps": float(np.max(np.linalg.norm(vN - nom.v_M, axis=1)[pre])),
        "max_position_m": float(np.max(np.linalg.norm(pN - nom.p_M, axis=1)[pre])),
        "max_attitude_deg": float(np.degrees(np.max(np.linalg.norm(attitude_error(nom.q_M_G, qN), axis=1)[pre]))),
    }
    # the headline's number with its 1σ (problem.headline: h AGL at the end of the data), judged
    # against the truth by the runner (calibration.finish_health: ERROR outside ±3σ)
    out["headline"] = [
        {
            "name": "h_agl_end",
            "what": f"height above ground at the end of the data ({float(t[-1]):.2f} s)",
            "error": float(h_est[-1] - h_true[-1]),
            "sigma": float(sd_h[-1]),
            "unit": "m",
        }
    ]
    return out


#: AMELIA's density accuracy per profile segment (issue #11 "Done means"): relative bound.
DENSITY_BOUNDS = {"entry_measured": 0.10, "entry_filled_blackout": 0.20, "under_parachute": 0.25}
#: AMELIA's wind accuracy bound [m/s].
WIND_BOUND_MPS = 5.0


def _err_stats(prefix: str, err: np.ndarray, sig: np.ndarray, unit: str) -> dict:
    """Flat error-vs-σ numbers of one quantity: max/median/rms |error|, rms reported 1σ, the
    fractions with |error| ≤ 2σ and ≤ 3σ, and rms(error)/rms(σ) (1 for a consistent σ)."""
    err = np.asarray(err, dtype=float)
    sig = np.asarray(sig, dtype=float)
    ok = np.isfinite(err) & np.isfinite(sig)
    err, sig = err[ok], sig[ok]
    if err.size == 0:
        return {}
    rms_e = float(np.sqrt(np.mean(err**2)))
    rms_s = float(np.sqrt(np.mean(sig**2)))
    return {
        f"{prefix}_max_abs_error_{unit}": float(np.max(np.abs(err))),
        f"{prefix}_median_abs_error_{unit}": float(np.median(np.abs(err))),
        f"{prefix}_rms_error_{unit}": rms_e,
        f"{prefix}_rms_sigma_{unit}": rms_s,
        f"{prefix}_error_over_sigma_rms_ratio": rms_e / rms_s if rms_s > 0 else float("nan"),
        f"{prefix}_fraction_within_2sigma": float(np.mean(np.abs(err) <= 2.0 * sig)),
        f"{prefix}_fraction_within_3sigma": float(np.mean(np.abs(err) <= 3.0 * sig)),
    }


def score_atmosphere(atm, truth: dict, events: dict) -> dict:
    """Density, pressure and temperature of the reconstruction against the true atmosphere, per
    segment (entry outside the blackout, the filled blackout, under the parachute), each error with
    the reconstruction's reported 1σ (smoothed profile; the σ of :func:`reconstruct_atmosphere`).

    Flat keys per segment: ``density_*_rel`` (relative error and σ), ``pressure_*_rel``,
    ``temperature_*_K``; ``density_bound_rel`` and ``density_bound_pass`` (AMELIA's 10 / 20 / 25 %
    on the maximum |error|, measured, PASS or FAIL); ``drag_coefficient_rel_error_median`` and
    ``_max_abs``: the table coefficient the reconstruction used minus the truth's planted one,
    relative (``truth["ca_factor"]`` along the entry, ``truth["chute_cd_factor"]`` under the
    parachute, whose drag dominates there), the part of the density error that the coefficient
    uncertainty stands for; n.
    """
    fin = atm.final
    ta = truth["atmosphere"]
    h = np.asarray(fin.h_amr, float)
    rho_t, p_t, T_t = ta.density(h), ta.pressure(h), ta.temperature(h)
    e_rho = atm.rho_smooth / rho_t - 1.0
    s_rho = atm.sigma_rho / atm.rho_smooth
    e_p = atm.p_smooth / p_t - 1.0
    s_p = atm.sigma_p / atm.p_smooth
    e_T = atm.T_smooth - T_t
    s_T = atm.sigma_T
    e_rho_raw = fin.rho / rho_t - 1.0
    pdd = events.get("PDD", np.inf)
    filled = np.asarray(fin.filled, bool)
    segs = {
        "entry_measured": (fin.t < pdd) & ~filled,
        "entry_filled_blackout": (fin.t < pdd) & filled,
        "under_parachute": fin.t >= pdd,
    }
    # the coefficient error the reconstruction carries: table / truth − 1 at the true Mach
    coef = np.full(h.size, np.nan)
    if "ca_factor" in truth:
        fac = np.interp(fin.t, truth["t"], np.asarray(truth["ca_factor"], float))
        coef = np.where(fin.t < pdd, 1.0 / np.where(fac > 0, fac, np.nan) - 1.0, np.nan)
    if "chute_cd_factor" in truth:
        fac_p = np.interp(fin.t, truth["t"], np.asarray(truth["chute_cd_factor"], float))
        coef = np.where(fin.t >= pdd, 1.0 / np.where(fac_p > 0, fac_p, np.nan) - 1.0, coef)
    out: dict = {}
    for nm, mk in segs.items():
        mk = mk & np.isfinite(e_rho)
        if not mk.any():
            continue
        d = {"n": int(mk.sum())}
        d.update(_err_stats("density", e_rho[mk], s_rho[mk], "rel"))
        d["density_max_abs_error_raw_rel"] = float(np.nanmax(np.abs(e_rho_raw[mk])))
        d.update(_err_stats("pressure", e_p[mk], s_p[mk], "rel"))
        d.update(_err_stats("temperature", e_T[mk], s_T[mk], "K"))
        bound = DENSITY_BOUNDS[nm]
        d["density_bound_rel"] = bound
        d["density_bound_pass"] = bool(d["density_max_abs_error_rel"] <= bound)
        c = coef[mk]
        c = c[np.isfinite(c)]
        if c.size:
            d["drag_coefficient_rel_error_median"] = float(np.median(c))
            d["drag_coefficient_rel_error_max_abs"] = float(np.max(np.abs(c)))
        out[nm] = d
    out["bounds"] = "max |density error| <= 10 % entry, 20 % filled blackout, 25 % under the parachute (AMELIA)"
    return out


def score_winds(w, truth: dict) -> dict:
    """Wind error against the truth inside the layers (true speed > 5 m/s), with the reported 1σ:
    flat keys ``wind_N_*_mps``, ``wind_E_*_mps`` (error vs σ, :func:`_err_stats`),
    ``max_error_mps`` (horizontal vector), ``bound_mps`` and ``bound_pass`` (AMELIA's 5 m/s, on the
    largest vector error, measured), ``n``, ``method``."""
    twN = np.interp(w.t, truth["t"], np.asarray(truth["wind_NE"])[:, 0])
    twE = np.interp(w.t, truth["t"], np.asarray(truth["wind_NE"])[:, 1])
    layer = w.valid & (np.hypot(twN, twE) > 5.0)
    if not layer.any():
        return {}
    eN, eE = w.wind_N[layer] - twN[layer], w.wind_E[layer] - twE[layer]
    err = np.hypot(eN, eE)
    out = {
        "max_error_mps": float(err.max()),
        "rms_error_mps": float(np.sqrt(np.mean(err**2))),
        "fraction_within_5mps": float(np.mean(err <= WIND_BOUND_MPS)),
        "bound_mps": WIND_BOUND_MPS,
        "bound_pass": bool(err.max() <= WIND_BOUND_MPS),
        "n": int(layer.sum()),
        "method": w.method,
    }
    out.update(_err_stats("wind_N", eN, w.sigma_N[layer], "mps"))
    out.update(_err_stats("wind_E", eE, w.sigma_E[layer], "mps"))
    return out


def _pf(ok) -> str:
    return "PASS" if ok else "**FAIL**"


def _truth_tables(tr: dict) -> list[str]:
    """Markdown tables of the atmosphere, wind and radar scores (error next to the reported 1σ)."""
    L: list[str] = []
    atm = tr.get("atmosphere", {})
    rows = [(k, v) for k, v in atm.items() if isinstance(v, dict)]
    if rows:
        L += [
            "### Atmosphere: error vs the reconstruction's 1σ (smoothed profile, at the reconstructed altitude)",
            "",
            "| segment | n | ρ max abs err | ρ rms err | ρ rms 1σ | ρ ≤2σ | ρ ≤3σ | bound | ρ bound | "
            "p rms err | p rms 1σ | p ≤3σ | T rms err [K] | T rms 1σ [K] | T ≤3σ | C_D table−truth |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for nm, d in rows:
            cd = d.get("drag_coefficient_rel_error_median", float("nan"))
            L.append(
                f"| {nm} | {d['n']} | {100 * d['density_max_abs_error_rel']:.1f} % | "
                f"{100 * d['density_rms_error_rel']:.1f} % | {100 * d['density_rms_sigma_rel']:.1f} % | "
                f"{100 * d['density_fraction_within_2sigma']:.0f} % | "
                f"{100 * d['density_fraction_within_3sigma']:.0f} % | "
                f"{100 * d['density_bound_rel']:.0f} % | {_pf(d['density_bound_pass'])} | "
                f"{100 * d['pressure_rms_error_rel']:.1f} % | {100 * d['pressure_rms_sigma_rel']:.1f} % | "
                f"{100 * d['pressure_fraction_within_3sigma']:.0f} % | {d['temperature_rms_error_K']:.1f} | "
                f"{d['temperature_rms_sigma_K']:.1f} | {100 * d['temperature_fraction_within_3sigma']:.0f} % | "
                f"{fmt.pct(cd, sign=True, digits=2)} |"
            )
        L += [
            "",
            "Errors are measured at the reconstructed altitude, so the trajectory's altitude error is part of "
            "them (and σ_h/H part of the 1σ); C_D table−truth is the relative error of the coefficient the "
            "reconstruction used (table) against the truth's planted one, carried by the density error and "
            "covered by the 10 % coefficient term of its 1σ.  A bound is PASS or FAIL as measured.",
        ]
        L.append("")
    w = tr.get("winds_in_layers")
    if w:
        L += [
            f"Winds in the layers ({w['method']}, n = {w['n']}): max error {w['max_error_mps']:.2f} m/s "
            f"(bound {w['bound_mps']:.0f} m/s: {_pf(w['bound_pass'])}), rms {w['rms_error_mps']:.2f} m/s; "
            f"north rms error {fmt.num(w.get('wind_N_rms_error_mps'), digits=3)} vs rms 1σ "
            f"{fmt.num(w.get('wind_N_rms_sigma_mps'), 'm/s', digits=3)}, east "
            f"{fmt.num(w.get('wind_E_rms_error_mps'), digits=3)} "
            f"vs {fmt.num(w.get('wind_E_rms_sigma_mps'), 'm/s', digits=3)}; inside 3σ: north "
            f"{fmt.pct(w.get('wind_N_fraction_within_3sigma'))}, east "
            f"{fmt.pct(w.get('wind_E_fraction_within_3sigma'))}.",
            "",
        ]
    r = tr.get("radar")
    if r:
        L += [
            f"Radar slant-out against the filter's sphere: rms error {r['slant_out_rms_error_vs_sphere_m']:.1f} m "
            f"(terrain relief alone {r['slant_out_rms_terrain_m']:.1f} m) vs the filter's 1σ "
            f"{r['filter_slant_out_sigma_m']:.1f} m "
            f"(ratio {fmt.num(r['slant_out_error_over_sigma_rms_ratio'], digits=2)}).",
            "",
        ]
    return L


def scorecard_markdown(summary: dict) -> str:
    """The run's scorecard as markdown (``/report`` in the recording and ``workbench inspect``)."""
    d = summary["dispersion"]
    L = [
        f"# Entry `{summary['scenario']}` — scorecard",
        "",
        f"AMELIA pipeline: preprocessing, strapdown + covariance, dispersion ({d['members']} members, "
        f"{d['accepted']} accepted = {100 * d['accepted_fraction']:.1f} %, {d['wall_s']:.1f} s, "
        f"{d['scheduler']}), radar-aided EKF + RTS, atmosphere "
        f"({summary['atmosphere']['iterations']} iterations), winds.",
        "",
        "## Events (AMELIA Table 5 analogue, reconstructed)",
        "",
        "lon/lat: pole and meridian of date at TDB; *as AMELIA*: the paper's Table 5 convention (MMED",
        "latitude, meridian at the UTC date; `core.frames.planetocentric_amelia`), to compare with its printed rows.",
        "",
        "| event | t [s] | UTC | lon E [°] | lat N [°] | lon E as AMELIA [°] | lat N as AMELIA [°] "
        "| alt AMR [km] | alt AGL [km] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in summary["event_table"]:
        L.append(
            f"| {r['event']} | {r['t_s']:.2f} | {r['utc']} | {r['lon_deg']:.4f} | {r['lat_deg']:.4f} | "
            f"{r['lon_amelia_deg']:.4f} | {r['lat_amelia_deg']:.4f} | {r['alt_amr_km']:.3f} | {r['alt_agl_km']:.3f} |"
        )
    v = summary["nominal_integration"].get("vs_onboard_before_pdd")
    if v:
        L += [
            "",
            f"Strapdown vs on-board before PDD: max {v['max_velocity_mps']:.2f} m/s, {v['max_position_m']:.0f} m, "
            f"{v['max_attitude_deg']:.4f}° (paper: {v['paper']}).",
        ]
    if "plane_fits" in summary:
        L += [
            "",
            "## RDA plane fits (Table 4 method)",
            "",
            "| t [s] | AGL [m] | off-vertical [°] | rms [m] |",
            "|---|---|---|---|",
        ]
        L += [
            f"| {p['t_s']:.2f} | {p['h_agl_m']:.1f} | {p['off_vertical_deg']:.2f} | {p['rms_m']:.1f} |"
            for p in summary["plane_fits"]
        ]
    rr_ = summary.get("radar_residuals", {})
    if rr_:
        L += [
            "",
            "Radar residuals (smoothed, max |r|): "
            + ", ".join(f"{k} {v['max_abs']:.1f} (n={v['n']})" for k, v in rr_.items())
            + " — paper bounds 150 m / 20 m/s.",
        ]
    if "truth" in summary:
        tr = summary["truth"]
        L += ["", "## Against the synthetic truth", ""]
        L += _truth_tables(tr)
        rest = [
            (k, v) for k, v in tr.items() if isinstance(v, dict) and k not in ("atmosphere", "winds_in_layers", "radar")
        ]
        if rest:
            L += ["| check | values |", "|---|---|"]
            L += [f"| {k.replace('_', ' ')} | {'; '.join(fmt.fields(v))} |" for k, v in rest]
    if "health" in summary:
        L += ["", health_markdown(summary["health"]).rstrip()]
    return "\n".join(L) + "\n"
