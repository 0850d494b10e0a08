"""Health verdict of an entry reconstruction (composes :mod:`workbench.estimation.health`).

Checks: mean NIS of every radar channel of the smoother's forward pass against χ² bounds; the
smoothed covariance symmetric and positive definite; the smoothed altitude inside the envelope
(above the ground less 500 m and 3σ, below the starting altitude plus 10 km) and the speed below
the starting speed plus 10 % (nothing accelerates an entry vehicle beyond its entry speed but
gravity); the reconstructed density within a factor of the default (engineering) model at the same
altitude (WARNING beyond 2, ERROR beyond 5 — Mars density varies by tens of percent with season
and dust, not by factors); no IMU gap across the parachute deployment (PDD) or front-shield release
(FSR); and every warning the telemetry readers reported.
"""

from __future__ import annotations

import numpy as np

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.estimation.health import (
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

__all__ = ["entry_health", "input_health"]


def input_health(checks, paths) -> dict:
    """``health_report`` of what the telemetry alone tells, after reading and validating the entry
    telemetry ``paths`` with the run's :class:`~workbench.problems.entry.telemetry.TelemetryChecks`
    (``EntrySettings.checks``; raises the readers' located errors, unit mix-ups included): the
    readers' warnings.  The fuzz suite's fast path (no dispersion, no smoother)."""
    from workbench.problems.entry.telemetry import check_event_span, read_entry_telemetry

    tm = read_entry_telemetry(paths, checks)
    check_event_span(tm, paths)
    return health_report([notes_check("telemetry", [p for p in tm.problems if not str(p).startswith("INFO")])])


def entry_health(tm, imu, filt, atm, r_ground: float) -> dict:
    """``summary["health"]`` of an entry reconstruction: ``tm`` the telemetry (``EntryTelemetry``),
    ``imu`` the preprocessed IMU (its ``gaps``), ``filt`` the smoother result, ``atm`` the
    ``AtmosphereResult``, ``r_ground`` the ground radius [m]."""
    checks: list[Check] = []
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
        if c.status == OK and fac > 2.0:
            c = Check(
                c.name, WARNING, c.value, [1.0, 2.0], f"density departs from the default model by a factor {fac:.3g}"
            )
        checks.append(c)
    else:
        checks.append(Check("density.vs_default", WARNING, None, None, "no valid reconstructed density"))

    windows = {ev: (tm.events[ev] - 0.5, tm.events[ev] + 0.5) for ev in ("PDD", "FSR") if ev in tm.events}
    checks.append(gap_check("gaps.events", [(g.t_a, g.t_b) for g in imu.gaps], windows, status=WARNING))
    notes = [p for p in tm.problems if not str(p).startswith("INFO")]
    checks.append(notes_check("telemetry", notes))
    return health_report(checks)
