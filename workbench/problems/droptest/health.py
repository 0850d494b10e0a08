"""Health verdict of a drop-test reconstruction (composes :mod:`workbench.estimation.health`).

Checks: mean NIS per sensor (every triad, gyro, ZUPT, ranging channels) against χ² bounds; the
smoothed covariance symmetric and positive definite; the max-stroke clearance within the airbag
geometry (−3σ − the structure's give under the estimated peak load … bag thickness = lobe diameter +
standoff) and its 1σ below the bag thickness; the
coefficient of restitution between 0 and its energy bound + 3σ (:func:`restitution_energy_bound`;
1 without the run's settings); no IMU gap across the contact (the window the estimate
detects and the one where the measured specific force exceeds 2 g after release or bungee cut);
and every warning the telemetry readers reported.  With the run's settings also the physics
cross-checks of :mod:`.physics` and a note on the declared body vertex the max stroke rests on.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from workbench.core.bodies import G0
from workbench.estimation.health import (
    ERROR,
    WARNING,
    Check,
    covariance_check,
    gap_check,
    health_report,
    interval_check,
    nis_check,
    notes_check,
)
from workbench.problems.droptest import model as rl
from workbench.problems.droptest.model import error_state_key
from workbench.problems.droptest.physics import (
    contact_geometry_check,
    full_stroke_check,
    hanging_checks,
    max_stroke_note,
    structural_give,
    timing_checks,
)
from workbench.problems.droptest.stroke import contact_end

__all__ = ["drop_health", "input_checks", "input_health", "restitution_energy_bound"]


def input_checks(tel, windows: dict[str, tuple[float, float]] | None = None, settings=None) -> list[Check]:
    """The checks that need only the telemetry ``tel`` (``DropTelemetry``): no IMU gap across the
    impact (where the mean triad specific force exceeds 2 g after the release or bungee cut, and
    the extra ``windows`` {what: (t0, t1) [s]}), an impact present in the data at all, gaps after
    release longer than 20 ms (WARNING), and the readers' warnings; with the run's ``settings``
    (``DropSettings``) also the sensor axes against gravity while hanging (:func:`.physics.hanging_checks`)."""
    windows = dict(windows or {})
    imu = tel.imu
    start = max(tel.events.get("release", -np.inf), tel.events.get("bungee_cut", -np.inf))
    f = np.stack([imu.stack([f"{n}.x", f"{n}.y", f"{n}.z"]) for n in tel.triads], axis=1)
    fmag = np.linalg.norm(np.mean(f, axis=1), axis=1)
    hard = np.flatnonzero((imu.time >= start) & (fmag > 2.0 * G0))
    gaps = [(g.start_s, g.end_s) for g in imu.gaps]
    late = [(a, b) for a, b in gaps if b > tel.events.get("release", -np.inf)]
    checks: list[Check] = [] if settings is None else hanging_checks(tel, settings)
    if hard.size:
        # padded by two samples: a gap just before the first or after the last > 2 g sample is across it
        pad = 2.0 * float(np.median(np.diff(imu.time)))
        windows["measured impact (|f| > 2 g)"] = (float(imu.time[hard[0]]) - pad, float(imu.time[hard[-1]]) + pad)
    else:
        if late:
            a, b = max(late, key=lambda g: g[1] - g[0])
            why = f"a {b - a:.3g} s gap ({a:.4f}–{b:.4f} s) may hide it"
        else:
            why = f"the data end at {imu.time[-1]:.4f} s (a truncated file?)"
        checks.append(
            Check(
                "gaps.impact",
                ERROR,
                None,
                2.0 * G0,
                f"no impact (mean triad specific force > 2 g) in the IMU data after release: {why}; "
                "the contact is not observed",
            )
        )
    checks.append(gap_check("gaps.contact", gaps, windows))
    long_gaps = [(b - a, a, b) for a, b in late if b - a > 0.02]
    if long_gaps:
        d, a, b = max(long_gaps)
        checks.append(
            Check(
                "gaps.after_release", WARNING, float(d), 0.02, f"a {d:.3g} s IMU gap after release ({a:.4f}–{b:.4f} s)"
            )
        )
    checks.append(notes_check("telemetry", [f"{lvl}: {txt}" for _, lvl, txt in tel.degradations]))
    return checks


def input_health(settings, paths) -> dict:
    """``health_report`` of :func:`input_checks` after reading and validating the drop-test
    telemetry ``paths`` of a run with ``settings`` (``DropSettings``; raises the readers' located
    errors) — what can be said before the filter runs (the fuzz suite's fast path)."""
    from workbench.problems.droptest.telemetry import load_drop_telemetry

    tel = load_drop_telemetry(settings, paths)
    return health_report(input_checks(tel, settings=settings))


def drop_health(tel, fwd, smo, st, cov_stats=None, *, settings=None, completeness=None, lag=None) -> dict:
    """The ``summary["health"]`` of a drop test from its telemetry ``tel`` (``DropTelemetry``), the
    forward and smoothed ``FilterStage`` and the ``StrokeStage`` ``st`` (lengths in m, times in s);
    ``cov_stats``: :func:`~workbench.estimation.health.covariance_stats` of ``smo.P`` if already known.
    With the run's ``settings`` (``DropSettings``) also the physics cross-checks of :mod:`.physics`
    (sensor axes against gravity while hanging, rig geometry against the first contact, the
    full-stroke verdict against the IMU's rigid impact, timing);
    ``completeness`` (:class:`~.physics.ContactCompleteness`): data that end inside the contact
    make its outputs undefined (``data.contact`` WARNING naming the file and the time); ``lag``: the
    IMU lag against the ranging (:func:`~.physics.estimate_lag`) for the timing check."""
    checks: list[Check] = []
    notes: list[str] = []
    if settings is not None:
        checks += hanging_checks(tel, settings)
        geo = contact_geometry_check(tel, smo, st, settings)
        if geo is not None:
            sensors = [c.name for c in checks if c.status == ERROR]
            sensors += [
                f"nis.{n}"
                for n, ih in fwd.forward.innovations.items()
                if ih.t.size and np.mean(ih.nis[np.isfinite(ih.nis)]) > 16.0
            ]
            if geo.status == ERROR and sensors:
                geo = replace(
                    geo,
                    message=f"{geo.message}; or first the sensor errors ({', '.join(sensors)}): a wrong "
                    "sensor axis or scale moves the estimated trajectory as much",
                )
            checks.append(geo)
        if completeness is None or completeness.max_stroke_defined:
            full = full_stroke_check(tel, st, settings, smo)
            if full is not None:
                checks.append(full)
            note = max_stroke_note(smo, st, settings)
            if note is not None:
                notes.append(note)
        tchecks, tnotes = timing_checks(tel, smo, st, settings, lag)
        checks += tchecks
        notes += tnotes
    complete = completeness is None or completeness.complete
    ms_defined = completeness is None or completeness.max_stroke_defined
    if not complete:
        what = "restitution and rebound" + ("" if ms_defined else ", max stroke")
        checks.append(
            Check(
                "data.contact",
                WARNING,
                float(f"{completeness.t_data_end:.6g}"),
                None,
                f"{completeness.reason}: the contact's {what} are undefined (not reported)",
            )
        )
    for name, ih in fwd.forward.innovations.items():
        if ih.t.size:
            checks.append(nis_check(name, ih.nis, int(ih.y.shape[1])))
    labels = [error_state_key(c) for c in range(smo.P.shape[1])]
    checks.append(covariance_check(smo.P, "covariance.smoothed", stats=cov_stats, labels=labels))

    lander = st.lander
    thickness = float(2.0 * lander.lobe_radius + lander.standoff)  # lander face to the outer bag surface
    d, s = float(st.max.distance), float(st.max.sigma)
    if ms_defined:
        # a full stroke's vertex reaches into the ramp as far as the structure gives under the peak load
        give = structural_give(smo, tel, lander)
        depth = 0.0 if give is None else give[0]
        clear = interval_check(
            "max_stroke.clearance", d, -3.0 * max(s, 0.0) - depth, thickness, "max-stroke clearance", "m"
        )
        if give is not None:
            clear = replace(
                clear,
                message=f"{clear.message}; the lower bound is −3σ − m·|a|max/k, the depth a vertex reaches into "
                f"the ramp under the estimated peak load {give[1]:.1f} g of the CM ({depth:.4f} m with [lander] "
                f"contact_stiffness_n_per_m = {lander.contact_stiffness:.3g} N/m in the lander asset)",
            )
        checks.append(clear)
        checks.append(interval_check("max_stroke.sigma", s, 0.0, 0.5 * thickness, "max-stroke 1σ", "m"))
    e, se = st.restitution
    if not complete:
        pass
    elif np.isfinite(e):
        e_max = restitution_energy_bound(smo, st, settings)
        hi = 1.0 if e_max is None else e_max + 3.0 * (float(se) if np.isfinite(se) else 0.0)
        rest = interval_check("restitution", float(e), 0.0, hi, "coefficient of restitution")
        if e_max is not None:
            rest = replace(
                rest,
                message=f"{rest.message}; the upper bound is the energy's: the whole kinetic energy (rotation "
                f"included) at the approach turned into speed away from the surface, less gravity's work, "
                f"e ≤ {e_max:.3f}, + 3σ",
            )
        checks.append(rest)
        checks.append(interval_check("restitution.sigma", float(se), 0.0, 0.5, "restitution 1σ"))
    else:
        checks.append(Check("restitution", WARNING, None, [0.0, 1.0], "coefficient of restitution not determined"))

    windows: dict[str, tuple[float, float]] = {}
    i0, i1 = st.contact
    t_end = contact_end(smo.t, st.contact, st.restitution_index[1])
    if i0 >= 0 and t_end is not None:
        windows["detected airbag contact"] = (float(smo.t[i0]) - 0.01, t_end + 0.01)
    checks += input_checks(tel, windows)
    return health_report(checks, notes)


def restitution_energy_bound(smo, st, settings) -> float | None:
    """Largest coefficient of restitution the energy allows (dimensionless): e = −v_n,out / v_n,in of the
    CM can exceed 1 when a spinning or sliding lander turns rotation or motion along the surface into
    speed away from it, but never beyond the whole kinetic energy at the approach, less gravity's work
    up to the leaving instant: v_n,out² ≤ |v_in|² + ω_inᵀ J ω_in / m − 2 g (z_out − z_in) (friction,
    damping and venting only take energy away; the gas holds little at the approach instant).

    ``smo``: the smoothed ``FilterStage`` (SPF, z up, body rates in B); ``st``: the ``StrokeStage`` (its
    ``restitution_index`` and surface normal); ``settings``: ``DropSettings`` (mass [kg], inertia about the CM
    [kg m², B]). None without settings or the two instants."""
    ib, ia = st.restitution_index
    if settings is None or ib < 0 or ia < 0:
        return None
    lander = settings.lander
    x0, x1 = smo.x[ib], smo.x[ia]
    v0, w0 = x0[rl.SV], x0[rl.SW]
    vn0 = float(v0 @ np.asarray(st.surface.normal, float))
    if not vn0 < 0.0:
        return None
    J = np.asarray(lander.inertia_B, float)
    v1_sq = float(v0 @ v0 + w0 @ J @ w0 / lander.mass - 2.0 * G0 * (x1[rl.SP][2] - x0[rl.SP][2]))
    return float(np.sqrt(max(v1_sq, 0.0)) / -vn0)
