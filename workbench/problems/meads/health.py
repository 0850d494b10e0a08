"""Health verdict of a flush-air-data reconstruction (``summary["health"]``).

The MEADS reduction has no filter innovations; its consistency statistic is the per-sample
weighted least-squares residual ``χ² = Σ_ports (r_i / σ_i)²`` of Karlgaard et al., "Mars Entry
Atmospheric Data System Trajectory Reconstruction Algorithms and Flight Results" (AIAA 2013-0028),
Sect. III.A, Eq. 5–10: with ``m`` ports used and ``k`` states solved it is χ²(m − k) distributed
when the port σ are right, so it is judged like a normalised innovation squared
(:func:`~workbench.estimation.health.nis_check`), one check per number of degrees of freedom
(ports drop out when they fail; the fixed-R rows solve one state fewer).  The other checks:

* the WLS covariance of every sample above the dynamic-pressure threshold symmetric and
  positive definite;
* physical plausibility: q∞ against the IMU drag (the reader's gross unit test, here as a
  number), α and β inside the validity of the forebody pressure models, the air-data Mach against
  the inertial Mach, the density within ×5 of the default Mars model;
* physics (:mod:`.physics`): the pressures' flow angles against the IMU strapdown's
  (``physics.imu_vs_pressure_alpha|beta``, naming the likely IMU column mistake) and the
  accelerometer's force direction against the capsule's axis and the flow's plane
  (``physics.accel_axis_deg``, ``physics.accel_flow_plane_deg``);
* data: pressure-sample gaps across the peak dynamic pressure (WARNING); a port failure detected and
  excluded and a port dropout left out of its fits are handled, so each is a note of the report (not
  an anomaly), with ``data.failed_ports`` a WARNING when fewer than :data:`MIN_PORTS_LEFT` ports
  remain;
* model form, when the estimator uses the Newtonian model (Eq. 1–4): the same pressures reduced
  with the estimator's own CFD table (``air.alt``, the reference model of the vehicle) give α and
  q∞ that differ by the Newtonian's model-form error (the noise is common to both fits and
  cancels); where that difference exceeds the published 3σ at more than
  :data:`MODEL_FORM_MAX_OUTSIDE` of the samples, the published uncertainty does not cover the
  model's own error and the run cannot vouch for itself: a WARNING naming the output, the fraction
  and the sizes, an ERROR above :data:`MODEL_FORM_ERROR_OUTSIDE` (measured:
  ``docs/tuning/meads.md``). With the table as the model the check is not made: the Newtonian is
  the cruder model, its difference is not an error of the table;
* the tightly-coupled EKF (Sect. III.B), when run: per pass and port, the normalised innovation
  squared ``y_i² / S_ii`` of the forward pass above the threshold (χ²(1) each), and the smoothed
  covariance symmetric and positive definite (judged on its correlation matrix, so that
  variances of (10 m)² next to (10⁻⁴ rad)² do not decide it; a component with zero variance,
  e.g. a scale factor given a zero prior σ, is left out).
"""

from __future__ import annotations

from dataclasses import replace

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
)
from workbench.problems.meads.physics import accel_direction_checks, imu_vs_pressure_checks

__all__ = ["meads_health", "ekf_checks", "failed_ports_check", "model_form_checks", "wls_chi2"]

#: |α| [deg] beyond which the Newtonian / tabulated forebody models are outside their validity:
#: the stagnation point leaves the 70° sphere-cone's nose cap region at about 20°, the models are
#: tabulated / fitted to 30°; beyond 90° the ports face away from the flow (not physical)
ALPHA_WARN_DEG, ALPHA_ERROR_DEG = 30.0, 90.0
#: |β| [deg] likewise (the vehicle is trimmed near β = 0)
BETA_WARN_DEG, BETA_ERROR_DEG = 15.0, 90.0
#: relative difference of the air-data Mach to the inertial Mach that is worth a WARNING
MACH_WARN_REL = 0.3
#: a gap in the pressure samples longer than this many nominal intervals counts as a gap
GAP_INTERVALS = 3.0
#: minimum samples per degrees-of-freedom group for its χ² check
MIN_SAMPLES = 20
#: model-form check: the largest fraction of samples whose Newtonian − table difference may exceed
#: the published 3σ (a 3σ band misses 0.3 % of a Gaussian error; 10 % is far beyond that): WARNING
#: above it, ERROR above :data:`MODEL_FORM_ERROR_OUTSIDE` (the published 3σ is wrong for most of
#: the flight: nothing is published unless the user allows an unhealthy run)
MODEL_FORM_MAX_OUTSIDE = 0.1
MODEL_FORM_ERROR_OUTSIDE = 0.5
#: fewer ports than this left after the failures is a WARNING (the Mach set solves 4 states: with 4
#: ports left it has no redundancy to detect the next failure)
MIN_PORTS_LEFT = 5


def wls_chi2(residual: np.ndarray, sigma: np.ndarray, used: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample WLS residual χ² and its degrees of freedom.

    Args:
        residual: (n, m) [Pa] z − h(x̂) per port (NaN where not used).
        sigma: (n, m) [Pa] the 1σ each port was weighted with.
        used: (n, m) bool, the ports that counted.
        x: (n, k) the solved state (NaN in the columns a row did not solve).

    Returns:
        chi2 (n,) and dof (n,) int = ports used − states solved.
    """
    r = np.where(used, residual / np.where(used, sigma, 1.0), 0.0)
    chi2 = np.sum(r * r, axis=1)
    dof = used.sum(axis=1) - np.isfinite(x).sum(axis=1)
    return chi2, dof.astype(int)


def ekf_checks(passes, t: np.ndarray, above: np.ndarray, ports) -> list[Check]:
    """Checks of the filter passes (``EkfPass``): per-port NIS above the threshold (``above`` (n,)
    at the pressure times ``t``; calibrated in one band per pass over all ports, the stat's
    ``pool``) and the smoothed covariance (module docstring)."""
    checks: list[Check] = []
    for ps in passes:
        inn = ps.forward.innovations.get("pressure")
        if inn is None:
            checks.append(Check(f"nis.pressure_ekf_pass{ps.index}", WARNING, None, None, "no pressure was processed"))
            continue
        sel = above[inn.step]
        for j, port in enumerate(ports):
            v = ps.nis_port[sel, j]
            v = v[np.isfinite(v)]
            if v.size >= MIN_SAMPLES:
                c = nis_check(f"pressure_ekf_pass{ps.index}_{port}", v, 1)
                # the ports' honest NIS are exchangeable: one band per pass over every port's members
                checks.append(replace(c, stat={**(c.stat or {}), "pool": f"nis.pressure_ekf_pass{ps.index}_port"}))
        P = ps.smoothed.P
        d = np.einsum("nii->ni", P)
        act = np.flatnonzero(np.all(d > 0.0, axis=0))
        Pa = P[:, act][:, :, act]
        s = 1.0 / np.sqrt(d[:, act])
        checks.append(
            covariance_check(Pa * s[:, :, None] * s[:, None, :], f"covariance.ekf_pass{ps.index}_smoothed_correlation")
        )
    return checks


def model_form_checks(air, above: np.ndarray, est, passes=()) -> list[Check]:
    """When ``est.model`` is ``"newtonian"`` and the table fit ``air.alt`` exists: per output (α [deg],
    q∞ [%]) the fraction of the samples above the threshold (``above`` (n,)) where the Newtonian −
    table difference of the least squares exceeds the published 3σ (the last EKF pass's, else the
    least squares'); WARNING above :data:`MODEL_FORM_MAX_OUTSIDE` (module docstring)."""
    alt = air.alt
    if est.model != "newtonian" or alt is None or alt.model != "table":
        return []
    fit = air.fit
    checks = []
    for name in ("alpha", "qbar"):
        if passes:
            _, sig = passes[-1].output(name)
        else:
            sig = fit.sigma_alpha if name == "alpha" else fit.sigma_qbar
        a, b = getattr(fit, name), getattr(alt, name)
        ok = above & np.isfinite(a) & np.isfinite(b) & np.isfinite(sig)
        if ok.sum() < MIN_SAMPLES:
            continue
        d, s3 = np.abs(a[ok] - b[ok]), 3.0 * sig[ok]
        if name == "alpha":
            d, s3, unit = np.degrees(d), np.degrees(s3), "deg"
        else:
            d, s3, unit = 100.0 * d / np.abs(b[ok]), 100.0 * s3 / np.abs(b[ok]), "%"
        frac = float(np.mean(d > s3))
        msg = (
            f"Newtonian − table {name}: median |difference| {np.median(d):.3g} {unit} against a published 3σ of "
            f"{np.median(s3):.3g} {unit}; beyond it at {100 * frac:.0f} % of the samples above the threshold"
        )
        if frac > MODEL_FORM_MAX_OUTSIDE:
            msg += (
                ": the published uncertainty does not cover the Newtonian model's own error "
                "(the run cannot vouch for its " + name + '; reduce with model = "table")'
            )
            status = ERROR if frac > MODEL_FORM_ERROR_OUTSIDE else WARNING
            checks.append(Check(f"model_form.{name}_newtonian_vs_table", status, frac, MODEL_FORM_MAX_OUTSIDE, msg))
        else:
            checks.append(Check(f"model_form.{name}_newtonian_vs_table", OK, frac, MODEL_FORM_MAX_OUTSIDE, msg))
    return checks


def meads_health(tel, nav, air, wind, est, passes=(), *, wind_sigma_mps: float = 30.0, diagnose: bool = True) -> dict:
    """``summary["health"]`` of a MEADS reconstruction: ``tel`` the telemetry (``MeadsTelemetry``),
    ``nav`` the ``Navigation``, ``air`` the ``AirDataStage``, ``wind`` the ``WindStage``, ``est``
    the ``EstimatorSettings`` (its ``min_qbar_pa`` [Pa] selects the samples judged, its
    ``plausibility_factor`` the allowed q∞ ratio), ``passes`` the EKF passes (``EkfPass``), if any;
    ``wind_sigma_mps`` [m/s] the wind's prior 1σ in the IMU-vs-pressure comparison; ``diagnose``:
    name the IMU column mistake when that comparison fails (re-runs the strapdown per candidate)."""
    fit = air.fit
    w = fit.wls
    above = np.nan_to_num(fit.qbar) >= est.min_qbar_pa
    checks: list[Check] = []
    if not above.any():
        checks.append(
            Check("qbar.threshold", WARNING, None, est.min_qbar_pa, "no sample above the q∞ threshold: nothing judged")
        )
    chi2, dof = wls_chi2(w.residual, fit.sigma_p, w.used, w.x)
    for d in np.unique(dof[above]):
        sel = above & (dof == d)
        if d < 1:
            continue
        if sel.sum() < MIN_SAMPLES:
            continue
        checks.append(nis_check(f"pressure_wls_dof{d}", chi2[sel], int(d)))

    P = w.P[above]
    fin = np.all(np.isfinite(P[:, :3, :3]), axis=(1, 2))
    if fin.all():
        checks.append(covariance_check(P[:, :3, :3], "covariance.wls_qbar_alpha_beta"))
    else:
        first = float(tel.t_p[above][~fin][0])
        checks.append(
            Check(
                "covariance.wls_qbar_alpha_beta",
                WARNING,
                int((~fin).sum()),
                0,
                f"{int((~fin).sum())} samples above the threshold have no finite WLS covariance "
                f"(first at {first:.3f} s)",
            )
        )

    ratio = air.plausibility_ratio
    if np.isfinite(ratio):
        F = est.plausibility_factor
        checks.append(
            interval_check(
                "plausibility.qbar_vs_imu_drag", ratio, 1.0 / F, F, "median q∞ / (m|f| / (C_D S)) from the IMU drag"
            )
        )
    else:
        checks.append(
            Check("plausibility.qbar_vs_imu_drag", WARNING, None, None, "too little drag to compare q∞ with the IMU")
        )

    for name, val, warn, err in (
        ("alpha", fit.alpha, ALPHA_WARN_DEG, ALPHA_ERROR_DEG),
        ("beta", fit.beta, BETA_WARN_DEG, BETA_ERROR_DEG),
    ):
        a = np.abs(np.degrees(val[above]))
        a = a[np.isfinite(a)]
        worst = float(a.max()) if a.size else 0.0
        c = interval_check(f"envelope.{name}_deg", worst, 0.0, err, f"largest |{name}| [deg]", "deg")
        if c.status == OK and worst > warn:
            c = Check(
                c.name,
                WARNING,
                c.value,
                [0.0, warn],
                f"largest |{name}| {worst:.3g} deg is outside the pressure models' validity (|{name}| ≤ {warn:g} deg)",
            )
        checks.append(c)

    air_rows = above & (wind.mach_source == "air_data") & np.isfinite(fit.mach)
    if air_rows.any():
        rel = np.abs(fit.mach[air_rows] / nav.mach_inertial[air_rows] - 1.0)
        worst = float(np.median(rel))
        c = interval_check("plausibility.mach_vs_inertial", worst, 0.0, 1.0, "median |Mach_air / Mach_inertial − 1|")
        if c.status == OK and worst > MACH_WARN_REL:
            msg = f"air-data Mach departs from inertial by {worst:.0%}"
            c = Check(c.name, WARNING, c.value, [0.0, MACH_WARN_REL], msg)
        checks.append(c)

    rho = np.asarray(wind.density, float)
    ok = above & np.isfinite(rho) & (rho > 0)
    if ok.any():
        ref = MarsEngineeringAtmosphere().density(nav.h[ok])
        fac = float(np.exp(np.max(np.abs(np.log(rho[ok] / ref)))))
        checks.append(
            interval_check("density.vs_default", fac, 1.0, 5.0, "worst density ratio to the default model (either way)")
        )
    else:
        checks.append(Check("density.vs_default", WARNING, None, None, "no valid air-data density"))

    t = np.asarray(tel.t_p, float)
    if t.size > 2:
        dt = np.diff(t)
        nominal = float(np.median(dt))
        k = np.flatnonzero(dt > GAP_INTERVALS * nominal)
        gaps = [(float(t[i]), float(t[i + 1])) for i in k]
        if np.isfinite(fit.qbar).any():
            tq = float(t[int(np.nanargmax(fit.qbar))])
            checks.append(gap_check("gaps.peak_qbar", gaps, {"peak q∞": (tq - 2.0, tq + 2.0)}, status=WARNING))
    checks += model_form_checks(air, above, est, passes)
    if getattr(tel, "f_B", None) is not None and getattr(nav, "q_M_B", None) is not None:
        checks += imu_vs_pressure_checks(tel, nav, fit, above, wind_sigma_mps, diagnose=diagnose)
        checks += accel_direction_checks(tel, fit, above)
    if passes:
        checks += ekf_checks(passes, tel.t_p, above, tel.ports)
    checks.append(failed_ports_check(air.failures, len(tel.ports) if hasattr(tel, "ports") else None))
    notes = [
        f"port {f.port} failed at {f.t:.1f} s ({f.how}), detected and excluded from there on: {f.message}"
        for f in air.failures
    ] + [f"telemetry dropout, handled: {d}" for d in tel.degradations]
    return health_report(checks, notes=notes)


def failed_ports_check(failures, n_ports: int | None) -> Check:
    """``data.failed_ports``: the number of ports declared failed (each detected and excluded, a note
    of the report); WARNING when fewer than :data:`MIN_PORTS_LEFT` of ``n_ports`` remain."""
    k = len(failures)
    names = ", ".join(f"{f.port} at {f.t:.1f} s ({f.how})" for f in failures) or "none"
    if n_ports is not None and k and n_ports - k < MIN_PORTS_LEFT:
        return Check(
            "data.failed_ports",
            WARNING,
            k,
            n_ports - MIN_PORTS_LEFT,
            f"{k} of {n_ports} ports failed ({names}): {n_ports - k} left, fewer than {MIN_PORTS_LEFT} — the fit has "
            "no redundancy left to detect the next failure",
        )
    return Check(
        "data.failed_ports",
        OK,
        k,
        None if n_ports is None else n_ports - MIN_PORTS_LEFT,
        f"failed ports detected and excluded: {names}",
    )
