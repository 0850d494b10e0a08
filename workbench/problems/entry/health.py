"""Health verdict of an entry reconstruction (composes :mod:`workbench.estimation.health`).

Checks: mean NIS of every radar channel of the smoother's forward pass against χ² bounds; the
smoothed covariance symmetric and positive definite; the smoothed altitude inside the envelope
(above the ground less 500 m and 3σ, below the starting altitude plus 10 km) and the speed below
the starting speed plus 10 % (nothing accelerates an entry vehicle beyond its entry speed but
gravity); the reconstructed density within a factor of the default (engineering) model at the same
altitude (WARNING beyond 2, ERROR beyond 5 — Mars density varies by tens of percent with season
and dust, not by factors; with the vehicle's ballistic coefficient this is the measured drag
against the drag expected); the measured specific force along the vehicle's declared drag axis
(:func:`drag_axis_check`); the radar's first slant-out against the inertial prediction
(:func:`radar_first_lock_check`); the dispersion's acceptance; no gap of any telemetry file across
a key event (:func:`gap_checks`: the gaps away from them are notes); and every warning the
telemetry readers reported.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.estimation.health import (
    ERROR,
    OK,
    WARNING,
    Check,
    covariance_check,
    gap_check,
    health_report,
    interval_check,
    nis_check,
    notes_check,
)
from workbench.problems.entry.state import DP

__all__ = [
    "entry_health",
    "input_health",
    "drag_axis_check",
    "radar_first_lock_check",
    "radar_velocity_axes_check",
    "RADAR_VELOCITY_MISMATCH",
    "gap_checks",
    "key_event_windows",
    "DRAG_AXIS_MIN_COS",
    "DRAG_MIN_SPECIFIC_FORCE",
    "FIRST_LOCK_MAX_FACTOR",
    "UNDEFINED_ONLY_EVENTS",
]

#: Smallest median cosine between the measured specific force and the vehicle's declared drag axis
#: (+Z_G, towards the back shell).  A 70° sphere-cone's aerodynamic force lies within a few degrees
#: of its axis at any trim angle (C_N/C_A ≤ 0.1 → ≤ 6°), and under the parachute the riser pulls
#: along the axis within the canopy's swing (≲ 15°); 30° (cos 0.866) leaves room for both.
DRAG_AXIS_MIN_COS = float(np.cos(np.radians(30.0)))
#: Specific force [m/s²] above which a sample enters :func:`drag_axis_check` (0.5 g: drag well
#: above the accelerometer's bias and noise, mm/s² levels).
DRAG_MIN_SPECIFIC_FORCE = 5.0
#: Largest factor between the radar's first slant-out and its inertial prediction (before any radar
#: update) either way.  The inertial prediction at radar start (~7 km above ground) carries the
#: dispersion-refined state's kilometre-level altitude uncertainty and the terrain's ±a few hundred
#: metres about the sphere (tens of % of the range); a factor 2 is beyond them, and a unit mix-up
#: (ft 3.28, km 1000) lies far beyond that.
FIRST_LOCK_MAX_FACTOR = 2.0


def input_health(checks, paths) -> dict:
    """``health_report`` of what the telemetry alone tells, after reading and validating the entry
    telemetry ``paths`` with the run's :class:`~workbench.problems.entry.telemetry.TelemetryChecks`
    (``EntrySettings.checks``; raises the readers' located errors, unit mix-ups included): the
    readers' warnings, and their NOTE lines (time gaps) as notes.  The fuzz suite's fast path (no
    dispersion, no smoother)."""
    from workbench.problems.entry.telemetry import check_event_span, read_entry_telemetry

    tm = read_entry_telemetry(paths, checks)
    check_event_span(tm, paths)
    warns = [p for p in tm.problems if not str(p).startswith(("INFO", "NOTE"))]
    notes = [str(p) for p in tm.problems if str(p).startswith("NOTE")]
    return health_report([notes_check("telemetry", warns)], notes=notes)


def drag_axis_check(t: np.ndarray, f_G: np.ndarray, file: str = "gnc.csv", vehicle: str = "the vehicle") -> Check:
    """The measured drag along the vehicle's declared axis +Z_G (body frame G: +Z towards the back
    shell, the axis the drag equation of ``entry.atmosphere`` reads).  ``t`` (n,) [s], ``f_G``
    (n, 3) [m/s²] the preprocessed specific force in G (the GNC file's acceleration, gravity
    removed, rotated with its attitude quaternions).  Statistic: the median of f_z / |f| over the
    samples with |f| ≥ :data:`DRAG_MIN_SPECIFIC_FORCE` (entry and parachute); ERROR below
    :data:`DRAG_AXIS_MIN_COS`, naming the axis the drag does lie along (a GNC frame rotated or
    flipped against the vehicle's, e.g. quaternions of another body frame)."""
    f = np.asarray(f_G, float)
    n = np.linalg.norm(f, axis=1)
    use = np.isfinite(n) & (n >= DRAG_MIN_SPECIFIC_FORCE)
    if use.sum() < 10:
        return Check(
            "geometry.drag_axis",
            WARNING,
            None,
            DRAG_AXIS_MIN_COS,
            f"fewer than 10 samples with a specific force ≥ {DRAG_MIN_SPECIFIC_FORCE:g} m/s²: "
            "the drag axis is not checked",
        )
    u = f[use] / n[use, None]
    med = np.median(u, axis=0)
    cz = float(med[2])
    k = int(np.argmax(np.abs(med)))
    along = f"{'+' if med[k] > 0 else '−'}{'XYZ'[k]}_G"
    if cz < DRAG_AXIS_MIN_COS:
        return Check(
            "geometry.drag_axis",
            ERROR,
            round(cz, 6),
            round(DRAG_AXIS_MIN_COS, 6),
            f"the measured drag lies along {along} (median unit components {med[0]:+.2f}, {med[1]:+.2f}, "
            f"{med[2]:+.2f} over {int(use.sum())} samples ≥ {DRAG_MIN_SPECIFIC_FORCE:g} m/s²), but {vehicle} "
            f"declares +Z_G (towards the back shell): the attitude quaternions q1..q4 and rates w_* of {file} "
            "are in another body frame (axes swapped or flipped) than the vehicle's",
        )
    return Check(
        "geometry.drag_axis",
        OK,
        round(cz, 6),
        round(DRAG_AXIS_MIN_COS, 6),
        f"the measured drag lies along +Z_G as declared (median cosine {cz:.4f} over {int(use.sum())} samples)",
    )


def radar_first_lock_check(innovations, file: str = "rda_out.csv") -> Check:
    """The radar's first usable slant-out against its prediction from the inertial trajectory
    before any radar update (the forward pass's prior at that sample; ``innovations`` the
    smoother's ``innovations["slant_out"]``).  Statistic: measured / predicted range; ERROR when it
    is off by more than :data:`FIRST_LOCK_MAX_FACTOR` either way, naming a unit when one explains it
    (ft ↔ m, km ↔ m).  Value also reported: the innovation in units of its predicted 1σ."""
    from workbench.io.units import likely_unit

    name = "units.radar_first_lock"
    if innovations is None or not len(innovations.t):
        return Check(name, WARNING, None, None, "no slant-out sample was processed: the radar lock is not checked")
    z = np.asarray(innovations.z, float)[:, 0]
    zp = np.asarray(innovations.z_pred, float)[:, 0]
    ok = np.flatnonzero(np.isfinite(z) & np.isfinite(zp) & (zp > 0) & (z > 0))
    if not ok.size:
        return Check(name, WARNING, None, None, "no finite slant-out prediction: the radar lock is not checked")
    i = int(ok[0])
    ratio = float(z[i] / zp[i])
    S = float(np.asarray(innovations.S, float)[i, 0, 0])
    zs = (z[i] - zp[i]) / np.sqrt(S) if np.isfinite(S) and S > 0 else float("nan")
    what = (
        f"first slant-out at {float(innovations.t[i]):.2f} s: {z[i]:.0f} m measured, {zp[i]:.0f} m predicted from "
        f"the inertial trajectory (ratio {ratio:.3g}, {zs:+.2g}σ)"
    )
    lo, hi = 1.0 / FIRST_LOCK_MAX_FACTOR, FIRST_LOCK_MAX_FACTOR
    if not lo <= ratio <= hi:
        likely = likely_unit(ratio, "m", rtol=0.3)  # the prediction itself is off by tens of %
        hint = (
            f": the ranges of {file} (slant_out) look like [{likely}], not [m]"
            if likely
            else f": a wrong radar unit or beam geometry ({file}), or the inertial altitude is off"
        )
        return Check(name, ERROR, round(ratio, 6), [round(lo, 6), round(hi, 6)], what + hint)
    return Check(name, OK, round(ratio, 6), [round(lo, 6), round(hi, 6)], what)


#: Median disagreement, relative to the median speed, between the radar's terrain-relative velocity
#: and its inertial-only prediction above which :func:`radar_velocity_axes_check` looks for a swap
#: or flip.  The prediction from the smoother's start state (no radar update) drifts by tens of
#: m/s by the radar phase (0.2-0.5 of the ~70 m/s descent speed); a flip of the descent axis is ~2.
RADAR_VELOCITY_MISMATCH = 1.0


def radar_velocity_axes_check(v_out_G: np.ndarray, v_pred_G: np.ndarray, file: str = "rda_out.csv") -> Check:
    """The radar's terrain-relative velocity ``v_out_G`` (k, 3) [m/s, GNC frame] against its
    prediction ``v_pred_G`` (k, 3) from the inertial trajectory alone (the smoother's start state
    integrated through the IMU, no radar update) at the same valid samples.  Statistic: the median
    |difference| over the median predicted speed.  ERROR when it exceeds
    :data:`RADAR_VELOCITY_MISMATCH` and a swap or sign flip of the columns (a signed permutation)
    fits better by a factor 1/0.6 or more: named in the message.  The descent axis (−Z_G, tens of
    m/s) is what it can tell; horizontal components of a few m/s are below the prediction's drift."""
    from workbench.problems.entry.telemetry import signed_permutations

    name = "geometry.radar_velocity_axes"
    z, y = np.asarray(v_out_G, float), np.asarray(v_pred_G, float)
    ok = np.all(np.isfinite(z), axis=1) & np.all(np.isfinite(y), axis=1)
    if ok.sum() < 5:
        return Check(name, WARNING, None, None, "fewer than 5 valid velocity-out samples: radar axes not checked")
    z, y = z[ok], y[ok]
    scale = float(np.median(np.linalg.norm(y, axis=1)))
    mis = float(np.median(np.linalg.norm(z - y, axis=1))) / scale
    best, perm = min(
        (float(np.median(np.linalg.norm(z @ M.T - y, axis=1))) / scale, nm) for M, nm in signed_permutations("v_out_")
    )
    what = (
        f"the radar velocity ({file}, v_out_*) against the inertial-only prediction: median difference {mis:.3g}× "
        f"the median speed {scale:.3g} m/s"
    )
    if mis > RADAR_VELOCITY_MISMATCH and best < 0.6 * mis:
        return Check(
            name,
            ERROR,
            round(mis, 6),
            RADAR_VELOCITY_MISMATCH,
            f"{what}; read as {perm} they agree ({best:.2g}): a radar velocity axis swapped or sign-flipped",
        )
    return Check(name, OK, round(mis, 6), RADAR_VELOCITY_MISMATCH, what)


def key_event_windows(tm, imu, filt) -> dict[str, tuple[float, float]]:
    """The key events of an entry and the windows [s] a data gap must not cross: the peak
    deceleration (the largest measured specific force before PDD, ± one sample), PDD and FSR
    (± 0.5 s), the radar lock (the first valid slant-out, ± 0.5 s).  ``tm`` the telemetry, ``imu``
    the preprocessed IMU, ``filt`` the smoother result (or None)."""
    out: dict[str, tuple[float, float]] = {}
    for ev in ("PDD", "FSR"):
        if ev in tm.events:
            out[ev] = (tm.events[ev] - 0.5, tm.events[ev] + 0.5)
    t = np.asarray(imu.t, float)
    pre = t < tm.events.get("PDD", np.inf)
    if pre.sum() > 2:
        f = np.linalg.norm(np.nan_to_num(np.asarray(imu.f_G, float)), axis=1)
        k = int(np.flatnonzero(pre)[np.argmax(f[pre])])
        out["peak deceleration"] = (float(t[max(k - 1, 0)]), float(t[min(k + 1, t.size - 1)]))
    tr = np.asarray(tm.t_rda, float)[np.asarray(tm.rda_valid, bool)]
    if tr.size:
        out["radar lock"] = (float(tr[0]) - 0.5, float(tr[0]) + 0.5)
    return out


#: Key events no published number depends on: a gap across one makes only that event undefined
#: (said in its key moment and in a note), the reconstruction bridges it.  The peak deceleration
#: of an entry commonly falls in the plasma blackout (Schiaparelli's did); the trajectory across
#: it comes from the on-board velocity increments, the density there from the blackout fill.
UNDEFINED_ONLY_EVENTS = ("peak deceleration",)


def gap_checks(gaps, windows: dict[str, tuple[float, float]]) -> tuple[list[Check], list[str]]:
    """The telemetry gaps (:class:`~workbench.problems.entry.telemetry.StreamGap`) judged against the
    key-event ``windows``: a gap of the GNC file (or the radar file, for the radar lock) that
    overlaps an event's window is a WARNING ``gaps.<event>`` (that event is not observed: its outputs
    are undefined), except for :data:`UNDEFINED_ONLY_EVENTS` (OK, the event said undefined in a
    note); every other gap is a note (a blackout away from the key events, bridged by the
    reconstruction).  Returns (checks, notes)."""
    checks: list[Check] = []
    notes: list[str] = []
    hit: set[int] = set()
    for ev, (a, b) in windows.items():
        streams = ("rda_out",) if ev == "radar lock" else ("gnc",)
        bad = [(i, g) for i, g in enumerate(gaps) if Path(g.file).stem in streams and g.start_s < b and g.end_s > a]
        key = "gaps." + ev.replace(" ", "_")
        if bad and ev in UNDEFINED_ONLY_EVENTS:
            hit.update(i for i, _ in bad)
            g = max((g for _, g in bad), key=lambda g: g.end_s - g.start_s)
            msg = f"the {ev} lies inside the data gap {g}: it is not observed and undefined (no output depends on it)"
            checks.append(Check(key, OK, round(g.end_s - g.start_s, 6), 0.0, msg))
            notes.append(msg)
        elif bad:
            hit.update(i for i, _ in bad)
            g = max((g for _, g in bad), key=lambda g: g.end_s - g.start_s)
            checks.append(
                Check(
                    key,
                    WARNING,
                    round(g.end_s - g.start_s, 6),
                    0.0,
                    f"{g}: the gap lies across the {ev} ({a:.2f}–{b:.2f} s): the {ev} is not observed, its "
                    "outputs are undefined",
                )
            )
        else:
            checks.append(Check(key, OK, 0.0, 0.0, f"no data gap across the {ev} ({a:.2f}–{b:.2f} s)"))
    notes += [f"telemetry gap away from the key events (bridged): {g}" for i, g in enumerate(gaps) if i not in hit]
    return checks, notes


def entry_health(tm, imu, filt, atm, r_ground: float, extra=(), notes=()) -> dict:
    """``summary["health"]`` of an entry reconstruction: ``tm`` the telemetry (``EntryTelemetry``),
    ``imu`` the preprocessed IMU (its ``gaps``), ``filt`` the smoother result, ``atm`` the
    ``AtmosphereResult``, ``r_ground`` the ground radius [m]; ``extra`` further checks of the
    pipeline (e.g. :func:`drag_axis_check`), ``notes`` further notes."""
    checks: list[Check] = list(extra)
    for name, ih in filt.innovations.items():
        nis = np.asarray(ih.nis, float)
        if nis.size and np.isfinite(nis).any():
            checks.append(nis_check(name, nis, int(ih.y.shape[1])))
    sm = filt.smoothed
    checks.append(covariance_check(sm.P, "covariance.smoothed"))

    r = np.linalg.norm(sm.p_M, axis=1)
    h = r - r_ground
    sig_h = np.sqrt(np.maximum(np.einsum("ni,nij,nj->n", sm.p_M / r[:, None], sm.P[:, DP, DP], sm.p_M / r[:, None]), 0))
    k = int(np.argmin(h + 3.0 * sig_h))
    checks.append(
        interval_check(
            "envelope.altitude_min",
            float(h[k] + 3.0 * sig_h[k]),
            -500.0,
            np.inf,
            "lowest altitude above ground + 3σ",
            "m",
        )
    )
    checks.append(
        interval_check("envelope.altitude_max", float(np.max(h)), -np.inf, float(h[0]) + 10e3, "highest altitude", "m")
    )
    speed = np.linalg.norm(sm.v_M, axis=1)
    checks.append(
        interval_check(
            "envelope.speed_max", float(np.max(speed)), 0.0, 1.1 * float(speed[0]) + 50.0, "highest speed", "m/s"
        )
    )

    fin = atm.final
    rho = np.asarray(atm.rho_smooth, float)
    ok = np.isfinite(rho) & (rho > 0)
    if ok.any():
        ref = MarsEngineeringAtmosphere().density(np.asarray(fin.h_amr, float)[ok])
        ratio = rho[ok] / ref
        worst = float(np.max(np.abs(np.log(ratio))))
        fac = float(np.exp(worst))
        c = interval_check("density.vs_default", fac, 1.0, 5.0, "worst density ratio to the default model (either way)")
        cause = (
            " — the drag measured against the drag expected with the vehicle's ballistic coefficient m/(C_A S): "
            "a wrong mass, reference area or drag table, or an acceleration or radar unit?"
        )
        if c.status == OK and fac > 2.0:
            c = Check(
                c.name,
                WARNING,
                c.value,
                [1.0, 2.0],
                f"density departs from the default model by a factor {fac:.3g}" + cause,
            )
        elif c.status == ERROR:
            c = Check(c.name, c.status, c.value, c.bound, c.message + cause)
        checks.append(c)
    else:
        checks.append(Check("density.vs_default", WARNING, None, None, "no valid reconstructed density"))
    conv = bool(getattr(atm, "converged", True))
    checks.append(
        Check(
            "atmosphere.converged",
            OK if conv else WARNING,
            int(getattr(atm, "n_iterations", 0)),
            None,
            "the drag-coefficient iteration converged"
            if conv
            else "the drag-coefficient iteration did not converge: the density, pressure and temperature profiles "
            "are those of the last pass (a Mach or angle of attack off the drag tables?)",
        )
    )

    windows = key_event_windows(tm, imu, filt)
    pdd_fsr = {ev: w for ev, w in windows.items() if ev in ("PDD", "FSR")}
    checks.append(gap_check("gaps.events", [(g.t_a, g.t_b) for g in imu.gaps], pdd_fsr, status=WARNING))
    gchecks, gnotes = gap_checks(getattr(tm, "gaps", []), windows)
    checks += gchecks
    warns = [p for p in tm.problems if not str(p).startswith(("INFO", "NOTE"))]
    checks.append(notes_check("telemetry", warns))
    return health_report(checks, notes=list(notes) + gnotes)
