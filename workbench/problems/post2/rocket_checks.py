"""Physics cross-checks of an imported rocket flight (issue 26): the log's units and sensor axes,
the metadata's site, weather and vehicle against what the log itself measures, data gaps at the
key moments, and (after the run) estimated parameters pinned at their bounds.

Each check is a :class:`~workbench.estimation.health.Check` named ``units.*``, ``geometry.*``,
``physics.*``, ``timing.*`` or ``data.*`` with its statistic, a bound taken from physics or the sensor (the
source is said beside each constant) and a message naming the file, column or metadata key and the
likely cause.  The import (:mod:`workbench.problems.post2.importers.airbrakes`) computes the checks
on the log and the metadata (:func:`import_checks`), refuses on an ERROR unless asked not to, and
stores them in ``flight.json``; a run of the imported problem file adds them to its health verdict
together with the checks of its own estimate (:func:`run_checks`).

The Earth's field for the site checks is a centred tilted dipole: the degree-1 Gauss coefficients of
IGRF-13 (Alken et al. 2021, "International Geomagnetic Reference Field: the thirteenth
generation", Earth Planets Space 73:49), epoch 2020.  It gives the inclination's sign and the field
magnitude within ~30 % (the South Atlantic anomaly, ~25 % below it, is the worst) — enough to tell a
hemisphere, not a declination.  No check here has a truth-Monte-Carlo band (``stat`` is None): the
truth simulator makes no raw flight-computer log, so every bound is the physics' or the sensor's.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np

from workbench.core.bodies import EARTH
from workbench.core.rotation import dcm_to_quat, quat_history_from_body_rates, quat_to_dcm, quat_to_rotvec
from workbench.estimation.health import ERROR, OK, WARNING, Check
from workbench.estimation.strapdown import ImuArrays, integrate_members
from workbench.io.schema import read_json

__all__ = [
    "INPUT_NAMES",
    "rename",
    "dipole_field",
    "BOUND_PRIOR_Z",
    "bound_checks",
    "gyro_magnetometer_check",
    "motor_check",
    "import_checks",
    "run_checks",
    "undefined_outputs",
    "coast_drag_coefficient",
    "KEY_WINDOWS",
    "key_windows",
    "rate_check",
    "site_checks",
    "weather_checks",
    "fl_gaps",
    "pad_tilt_check",
    "accel_sign_check",
    "pitch_over_check",
    "coast_strapdown",
    "strapdown_apogee_check",
]

#: IGRF-13 degree-1 Gauss coefficients at epoch 2020 [nT] (Alken et al. 2021, Table 2)
IGRF_G10, IGRF_G11, IGRF_H11 = -29404.8, -1450.9, 4652.5

#: the aligned magnetometer's dip agrees with the dipole's inclination within this [deg] (the
#: non-dipole field moves the inclination by up to ~15° outside the South Atlantic anomaly; the
#: three FIRM sites: measured 62–65° vs dipole 59–63°)
DIP_TOLERANCE_DEG = 25.0
#: the measured field magnitude within this factor of the dipole's (±30 %: the dipole's accuracy)
FIELD_RATIO_BAND = (0.7, 1.3)
#: the rocket's long axis from the boost's mean specific force (accelerometer frame) and the
#: principal axis of the body rates over boost and coast (gyro frame, a rolling rocket) agree within
#: this [deg] if the two sensors share their axes (measured 0.8–3.0° on the three flights)
AXES_TOLERANCE_DEG = 15.0
#: the pad tilt the IMU sees agrees with the metadata's launch rod angle within this [deg] (measured
#: −0.4, +0.2, +0.7 deg on the three flights); the rod angle is not used by the reconstruction: WARNING
PAD_TILT_TOLERANCE_DEG = 5.0
#: geometry.accel_sign needs this much mean roll [deg/s] in both solutions (measured −115 .. −228)
ROLL_MIN_DEG_S = 20.0
#: geometry.pitch_over: the nose (the boost's axis turned by the integrated gyro) and the velocity
#: (the integrated specific force) differ in elevation by at most the angle between them, which for a
#: stable rocket above PITCH_OVER_MIN_SPEED_M_S is its angle of attack plus the wind's tilt of the air
#: velocity: the wind at the launch limit (WIND_MAX_M_S / 2 = 8.9 m/s) tilts it ≤ 8.5° at 60 m/s, a
#: stable rocket's coast angle of attack stays within ~10° (the flights: docs/tuning/post2.md)
PITCH_OVER_BOUND_DEG = 20.0
PITCH_OVER_MIN_SPEED_M_S = 60.0
#: ... compared up to this long before the drogue's ejection [s] (the ejection tumbles the body)
PITCH_OVER_BEFORE_EJECTION_S = 0.5
#: gyro full scale of the FIRM logs [rad/s] (rocket.GYRO_SATURATION): a saturated sample leaves it unchecked
PITCH_OVER_GYRO_SATURATION = math.radians(1790.0)
#: physics.strapdown_apogee: the strapdown's apogee above the pad agrees with the barometer's within
#: this fraction; its 1σ sources: 1 % accelerometer scale (rocket.ACCEL_SCALE_SIGMA), 1° pad tilt
#: (rocket.TILT_SIGMA: ≤ 4 % at a 55° burnout elevation), 4 K site temperature (1.4 % of the pressure
#: altitude), 6.4 % summed (the flights: docs/tuning/post2.md)
STRAPDOWN_APOGEE_BOUND = 0.10
#: ... compared only when the barometric apogee is at least this high above the pad [m]
STRAPDOWN_APOGEE_MIN_M = 100.0
#: the magnetic field's turning over a short window cannot exceed the body's rotation (a vector
#: turns at most by the rotation angle): Σθ_mag / Σθ_gyro above this means the gyro reads too small
#: (hard iron, noise: ≤ 0.6 measured on the three flights and the excerpt); windows of this length [s]
MAG_GYRO_RATIO_MAX = 1.5
MAG_GYRO_WINDOW_S = 0.25
#: the implied coast drag coefficient (measured deceleration × mass / (q S)) of any rocket [-]: above
#: a flat plate's (1.2–2.0, Hoerner, Fluid-Dynamic Drag, 1965) on a frontal area at most ~1.3× the
#: body's with air brakes out, or below a slender clean body's (~0.3, Barrowman; minus margin)
ROCKET_CD_RANGE = (0.15, 2.5)
#: NAR high-power safety code: no launch in surface winds above 20 mph (8.9 m/s); twice that is not
#: a launch day
WIND_MAX_M_S = 2.0 * 8.94
#: the flight computer's board is warmer than the air on the pad (+19, +24, +33 K on the three
#: flights: electronics and sun): a site temperature above the board's by more than this [K] is wrong
BOARD_COOLER_MARGIN_K = 10.0
#: the landing point lies within this of the pad [m] (a drift of a few km at most for a hobby rocket;
#: the three flights: 0.6–1.1 km), or 5 × the apogee if more
LANDING_DISTANCE_MAX_M = 10000.0
#: the rate [Hz] at which the per-block model-error levels of the pressure and |f| observations were
#: measured (rocket.PRESSURE_SIGMA_*, ACCEL_SIGMA_*: RMS of 10 Hz innovations)
OBSERVATION_RATE_MEASURED_HZ = 10.0
#: a gap longer than this [s] inside a key window makes that window's outputs undefined (ERROR);
#: shorter gaps there are a WARNING (the 10 Hz observation blocks lose at most a few)
KEY_GAP_ERROR_S = 0.5
#: key windows [s] around the key moments: the parachute openings (−0.5 .. +2 s)
OPENING_WINDOW_S = (-0.5, 2.0)
#: the key windows by name, for messages and :func:`undefined_outputs`
KEY_WINDOWS = {
    "coast": "the coast and the apogee (apogee height and time)",
    "drogue_opening": "the drogue's opening (drogue drag area, the apogee's end of the coast)",
    "main_opening": "the main's opening (main drag area, its time)",
}
#: likely inputs behind an estimated parameter pinned at its bound
BOUND_HINTS = {
    "ca_multiplier": "the coast drag is a multiple of the metadata's Cd·S/m: check rocket_dry_mass_kg "
    "(in lb? ×0.4536), rocket_Cd and rocket_cross_sectional_area_m2",
    "drogue_drag_area": "the descent rate fixes mass / drag area: check rocket_dry_mass_kg (in lb? ×0.4536)",
    "main_drag_area": "the descent rate fixes mass / drag area: check rocket_dry_mass_kg (in lb? ×0.4536)",
    "drogue_drag_multiplier": "the drogue's drag is this multiple of its declared C_D·S: check the drogue's area "
    "(a diameter given for a radius: ×4), its C_D and the masses in the vehicle file",
    "parachute_drag_multiplier": "the main chute's drag is this multiple of its declared C_D·S: check its area "
    "(a diameter given for a radius: ×4), its C_D and the masses in the vehicle file",
}


def dipole_field(lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """(|B| [T], inclination [deg, down positive]) of the centred tilted dipole (IGRF-13 degree 1,
    2020) at the Earth's surface at latitude/longitude [deg] (spherical; geodetic is close enough).

    B = 3 (g·r̂) r̂ − g with g = (g11, h11, g10) in Earth-fixed axes (x to longitude 0, z north)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    r = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    g = np.array([IGRF_G11, IGRF_H11, IGRF_G10]) * 1e-9
    B = 3.0 * float(g @ r) * r - g
    down = -float(B @ r)
    horiz = math.sqrt(max(float(B @ B) - down**2, 0.0))
    return float(np.linalg.norm(B)), math.degrees(math.atan2(down, horiz))


def _great_circle_m(lat1, lon1, lat2, lon2) -> float:
    """Distance [m] on the mean sphere between two points [deg]."""
    p1, p2, dl = math.radians(lat1), math.radians(lat2), math.radians(lon2 - lon1)
    c = math.sin(p1) * math.sin(p2) + math.cos(p1) * math.cos(p2) * math.cos(dl)
    return EARTH.reference_radius * math.acos(max(-1.0, min(1.0, c)))


def _check(name, status, value, bound, message, stat=None) -> Check:
    v = None if value is None else float(f"{float(value):.6g}")
    return Check(name, status, v, bound, message, stat)


def coast_drag_coefficient(ca0_unclipped: float, cd: float) -> float:
    """The coast drag coefficient on the reference area implied by the first measured coast drag:
    the unclipped drag multiplier (:func:`workbench.problems.post2.rocket.initial_ca_multiplier`
    before its clip) × the metadata's Cd [-]."""
    return float(ca0_unclipped * cd)


def _axes_check(t, f_B, w_B, bias, t_coast: float, t_ej: float, log_name: str) -> Check:
    """geometry.imu_axes: the boost's mean specific-force direction (accelerometer frame) against the
    principal axis of the body rates over boost and coast (gyro frame)."""
    boost = (t >= 0.0) & (t < t_coast)
    fc = (t >= 0.0) & (t < t_ej - 0.5)
    if np.sum(boost) < 3 or np.sum(fc) < 10:
        return _check("geometry.imu_axes", OK, None, AXES_TOLERANCE_DEG, "too few boost/coast samples: unchecked")
    a = f_B[boost].mean(axis=0)
    a /= np.linalg.norm(a)
    w = w_B[fc] - bias
    ev, V = np.linalg.eigh(w.T @ w)
    g = V[:, -1]
    if not ev[-1] > 4.0 * ev[-2]:  # no dominant roll: the gyro does not tell the long axis
        return _check("geometry.imu_axes", OK, None, AXES_TOLERANCE_DEG, "no dominant roll axis: unchecked")
    ang = math.degrees(math.acos(min(1.0, abs(float(a @ g)))))
    if ang <= AXES_TOLERANCE_DEG:
        msg = f"rocket axis from the boost's specific force and the gyro's roll axis {ang:.1f} deg apart"
        return _check("geometry.imu_axes", OK, ang, AXES_TOLERANCE_DEG, msg)
    comp = ", ".join(f"{c} {a[i]:+.2f}/{g[i]:+.2f}" for i, c in enumerate("xyz"))
    msg = (
        f"the accelerometer's and the gyro's axes disagree: the boost's specific force (rocket axis) and "
        f"the gyro's roll axis are {ang:.0f} deg apart (accel/gyro components {comp}; expected parallel "
        f"within {AXES_TOLERANCE_DEG:g} deg); an accelerometer or gyro axis of {log_name} looks swapped or "
        "sign-flipped (columns raw_acceleration_[xyz]_gs / raw_angular_rate_[xyz]_deg_per_s)"
    )
    return _check("geometry.imu_axes", ERROR, ang, AXES_TOLERANCE_DEG, msg)


def accel_sign_check(t, f_B, w_B, ref_q, t_coast: float, t_end: float, log_name: str) -> Check:
    """geometry.accel_sign: the roll rate about the rocket's nose as the accelerometer defines it
    (mean of ω·n over boost and coast, n the boost's mean specific-force direction) against the roll
    rate the flight computer's own attitude (``ref_q`` (n, 4) scalar-last, body → navigation, z up)
    shows about its body axis that pointed up on the pad.  The same gyro turns both, so the two agree
    in sign unless the accelerometer's "up" is the flight computer's "down": all the accelerometer's
    signs flipped, which no rotation of the IMU frame and no other check without an aligned
    magnetometer can see (−I commutes with every rotation).  ``t`` (n,) [s after launch], ``f_B``,
    ``w_B`` (n, 3) [m/s², rad/s]; ``t_coast``/``t_end`` [s] the coast letter and the window's end."""
    name = "geometry.accel_sign"
    boost = (t >= 0.0) & (t < t_coast)
    sel = np.flatnonzero((t >= 0.0) & (t < t_end))
    if np.sum(boost) < 3 or sel.size < 10:
        return _check(name, OK, None, 0.0, "too few boost/coast samples: unchecked")
    n = f_B[boost].mean(axis=0)
    n /= np.linalg.norm(n)
    ours = float(np.mean(w_B[sel] @ n))
    R = quat_to_dcm(ref_q[sel])
    inc = np.einsum("nji,njk->nik", R[:-1], R[1:])  # R_(k-1)^T R_k: the increments in its body axes
    rv = quat_to_rotvec(dcm_to_quat(inc))
    k = int(np.argmax(np.abs(R[0][2])))
    fc = float(np.mean(np.sign(R[0][2, k]) * rv[:, k] / np.diff(t[sel])))
    if min(abs(ours), abs(fc)) < math.radians(ROLL_MIN_DEG_S):
        msg = f"roll {math.degrees(ours):.0f} deg/s (ours) / {math.degrees(fc):.0f} deg/s (flight computer)"
        msg += ": too slow to tell"
        return _check(name, OK, None, 0.0, msg)
    ratio = ours / fc
    msg = (
        f"roll rate about the nose {math.degrees(ours):.0f} deg/s (gyro about the accelerometer's boost axis) vs "
        f"{math.degrees(fc):.0f} deg/s about the flight computer's own up axis (est_quaternion), ratio {ratio:.2f}"
    )
    if ratio > 0.0:
        return _check(name, OK, ratio, 0.0, msg)
    msg += (
        f": opposite senses — the accelerometer's 'up' is the flight computer's 'down': the signs of "
        f"raw_acceleration_[xyz]_gs of {log_name} look flipped"
    )
    return _check(name, ERROR, ratio, 0.0, msg)


def coast_strapdown(t, f_B, w_B, fl, t_end: float) -> dict | None:
    """The whole IMU integrated (strapdown, no covariance) from the pad to ``t_end`` [s after launch]:
    ``fl`` the :class:`~workbench.problems.post2.rocket.BoostSolution` gives the pad attitude and
    position, the gyro bias, the ignition time and the boost's axis in the IMU frame.  ``t`` (n,) [s
    after launch], ``f_B``, ``w_B`` (n, 3) [m/s², rad/s] as logged.  Returns {"t", "k" (indices into
    ``t``), "el_nose", "el_v" [deg] (elevations of the nose — the boost axis turned by the integrated
    gyro — and of the Earth-relative velocity), "speed" [m/s], "h" [m above the pad]} (m,) each, or None
    with fewer than 10 samples or a saturated gyro sample (the attitude would be wrong from there on)."""
    k0 = max(int(np.searchsorted(t, float(fl.pad_info["ignition_t_s"]))) - 1, 0)
    sel = np.arange(k0, int(np.searchsorted(t, t_end)))
    if sel.size < 10 or np.any(np.abs(w_B[sel]) >= PITCH_OVER_GYRO_SATURATION):
        return None
    ones = np.ones((sel.size, 3))
    imu = ImuArrays(t[sel], f_B[sel], w_B[sel] - fl.gyro_bias, ones, ones)
    earth_rate = np.array([0.0, 0.0, EARTH.rotation_rate])
    v0 = np.cross(earth_rate, fl.p_pad)
    out = integrate_members(imu, v0[None], np.asarray(fl.q_M_B_pad)[None], np.asarray(fl.p_pad)[None], body=EARTH)
    q, v, p = out["q"][:, 0], out["v"][:, 0], out["p"][:, 0]
    v_rel = v - np.cross(earth_rate, p)
    speed = np.linalg.norm(v_rel, axis=1)
    r = np.linalg.norm(p, axis=1)
    up = p / r[:, None]
    nose = np.einsum("nij,j->ni", quat_to_dcm(q), fl.axis_B)
    el_nose = np.degrees(np.arcsin(np.clip(np.einsum("ni,ni->n", nose, up), -1.0, 1.0)))
    el_v = np.degrees(np.arcsin(np.clip(np.einsum("ni,ni->n", v_rel, up) / np.maximum(speed, 1e-9), -1.0, 1.0)))
    h = r - EARTH.reference_radius - fl.h_pad
    return {"t": t[sel], "k": sel, "el_nose": el_nose, "el_v": el_v, "speed": speed, "h": h}


def pitch_over_check(sd: dict | None, t_coast: float, log_name: str) -> Check:
    """geometry.pitch_over: a rocket flies nose first, so over the coast (from ``t_coast`` [s after
    launch], above :data:`PITCH_OVER_MIN_SPEED_M_S`) the elevation of its nose follows the elevation of
    its velocity as gravity turns it over (``sd`` the :func:`coast_strapdown`; None: unchecked).  An
    accelerometer whose axes are a mirror image of the gyro's (a swapped or one sign-flipped column of
    either) turns the nose the wrong way: the two elevations part by more than
    :data:`PITCH_OVER_BOUND_DEG` → ERROR.  Elevations need no heading: the magnetometer plays no part."""
    name = "geometry.pitch_over"
    if sd is None:
        return _check(name, OK, None, PITCH_OVER_BOUND_DEG, "too few coast samples or a saturated gyro: unchecked")
    tt, el_nose, el_v = sd["t"], sd["el_nose"], sd["el_v"]
    coast = np.flatnonzero((tt >= t_coast) & (sd["speed"] > PITCH_OVER_MIN_SPEED_M_S))
    if coast.size < 5:
        return _check(name, OK, None, PITCH_OVER_BOUND_DEG, "too few coast samples above the speed limit: unchecked")
    d = el_nose[coast] - el_v[coast]
    k = int(np.argmax(np.abs(d)))
    i0, i1, kk = coast[0], coast[-1], coast[k]
    msg = (
        f"over the coast the nose's elevation went {el_nose[i0]:.0f}° → {el_nose[i1]:.0f}° and the velocity's "
        f"{el_v[i0]:.0f}° → {el_v[i1]:.0f}° (strapdown of the IMU from the pad); they part by at most "
        f"{abs(d[k]):.1f}° (at {tt[kk]:.1f} s; a stable rocket: within {PITCH_OVER_BOUND_DEG:g}°)"
    )
    if abs(d[k]) <= PITCH_OVER_BOUND_DEG:
        return _check(name, OK, abs(d[k]), PITCH_OVER_BOUND_DEG, msg)
    msg += (
        ": the integrated gyro does not turn the accelerometer's nose the way the flight turned — the axes of "
        f"raw_acceleration_[xyz]_gs and raw_angular_rate_[xyz]_deg_per_s of {log_name} look like mirror images "
        "(two columns of one sensor swapped, or one column's sign flipped)"
    )
    return _check(name, ERROR, abs(d[k]), PITCH_OVER_BOUND_DEG, msg)


def strapdown_apogee_check(sd: dict | None, pressure, atmosphere, h_pad: float, log_name: str) -> Check:
    """physics.strapdown_apogee: the highest point of the strapdown (``sd``, :func:`coast_strapdown`;
    None: unchecked) against the barometer's over the same samples (``pressure`` (n,) [Pa] as logged,
    read as altitude in the site's ``atmosphere``, ``h_pad`` [m] its pad altitude): relative difference
    above :data:`STRAPDOWN_APOGEE_BOUND` → ERROR (the IMU's axes, signs or units integrate another
    flight than the one the air pressure saw)."""
    name = "physics.strapdown_apogee"
    if sd is None:
        return _check(name, OK, None, STRAPDOWN_APOGEE_BOUND, "too few samples or a saturated gyro: unchecked")
    hg = h_pad + np.arange(0.0, 30000.0, 1.0)
    pg = np.asarray(atmosphere.pressure(hg), float)
    h_baro = np.interp(-np.asarray(pressure, float)[sd["k"]], -pg, hg) - h_pad
    kb, ks = int(np.argmax(h_baro)), int(np.argmax(sd["h"]))
    hb, hs = float(h_baro[kb]), float(sd["h"][ks])
    if hb < STRAPDOWN_APOGEE_MIN_M:
        return _check(name, OK, None, STRAPDOWN_APOGEE_BOUND, f"barometric apogee {hb:.0f} m: too low to compare")
    rel = (hs - hb) / hb
    msg = (
        f"the IMU's strapdown from the pad peaks {hs:.0f} m above it at {sd['t'][ks]:.1f} s, the barometer "
        f"{hb:.0f} m at {sd['t'][kb]:.1f} s ({100 * rel:+.1f} %; at most ±{100 * STRAPDOWN_APOGEE_BOUND:g} %)"
    )
    if abs(rel) <= STRAPDOWN_APOGEE_BOUND:
        return _check(name, OK, rel, STRAPDOWN_APOGEE_BOUND, msg)
    msg += (
        f": the accelerometer and gyro of {log_name} integrate another flight than the one the air pressure saw — "
        "an axis of raw_acceleration_[xyz]_gs or raw_angular_rate_[xyz]_deg_per_s swapped or sign-flipped, or "
        "a scale (units) wrong"
    )
    return _check(name, ERROR, rel, STRAPDOWN_APOGEE_BOUND, msg)


def pad_tilt_check(tilt_deg: float, rod_deg: float) -> Check:
    """geometry.pad_tilt: the angle [deg] between the pad's specific force (up) and the boost's (the
    rocket's axis) — the rod's tilt the IMU sees — against the metadata's ``launch_rod_angle`` [deg]."""
    d = tilt_deg - rod_deg
    msg = f"the IMU's pad tilt {tilt_deg:.1f} deg (pad specific force vs the boost's axis)"
    msg += f" vs launch_rod_angle {rod_deg:g} deg"
    if abs(d) <= PAD_TILT_TOLERANCE_DEG:
        return _check("geometry.pad_tilt", OK, d, PAD_TILT_TOLERANCE_DEG, msg)
    msg += (
        ": the rod angle in the metadata is wrong (radians? the angle from the horizontal?) or an accelerometer "
        "axis has another scale than the others"
    )
    return _check("geometry.pad_tilt", WARNING, d, PAD_TILT_TOLERANCE_DEG, msg)


def _mag_gyro_check(t, w_B, mag_B, bias, k0: int, t_end: float, log_name: str) -> Check:
    """units.gyro: Σ over short windows of the field's turning angle against the gyro's rotation angle
    (a vector turns by at most the body's rotation, so the ratio is ≤ 1 up to noise and hard iron)."""
    k1 = int(np.searchsorted(t, t_end))
    tt, ww, mm = t[k0:k1], w_B[k0:k1] - bias, mag_B[k0:k1]
    if tt.size < 10:
        return _check("units.gyro", OK, None, MAG_GYRO_RATIO_MAX, "too few samples to compare gyro and magnetometer")
    edges = np.unique(np.searchsorted(tt, np.arange(tt[0], tt[-1], MAG_GYRO_WINDOW_S)))
    th_m = th_g = 0.0
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        if b - a < 1:
            continue
        m0, m1 = mm[a], mm[b]
        nn = float(np.linalg.norm(m0) * np.linalg.norm(m1))
        if not nn > 0.0:
            continue
        th_m += math.acos(max(-1.0, min(1.0, float(m0 @ m1) / nn)))
        q = quat_history_from_body_rates(tt[a : b + 1], ww[a : b + 1])[-1]
        th_g += float(np.linalg.norm(quat_to_rotvec(q)))
    if th_g < math.radians(90.0) and th_m < math.radians(90.0):
        return _check("units.gyro", OK, None, MAG_GYRO_RATIO_MAX, "the body barely turned: gyro scale unchecked")
    ratio = th_m / max(th_g, 1e-12)
    msg = (
        f"the magnetic field turned {math.degrees(th_m):.0f} deg over boost and coast while the gyro "
        f"integrates {math.degrees(th_g):.0f} deg (ratio {ratio:.2f}, at most ~1)"
    )
    if ratio <= MAG_GYRO_RATIO_MAX:
        return _check("units.gyro", OK, ratio, MAG_GYRO_RATIO_MAX, msg)
    msg += (
        f": the gyro reads {ratio:.0f}× too small — are raw_angular_rate_[xyz]_deg_per_s of {log_name} in rad/s "
        "(×57.3)? a field cannot turn more than the body"
    )
    return _check("units.gyro", ERROR, ratio, MAG_GYRO_RATIO_MAX, msg)


#: a magnetometer fit (``pad_info["magnetometer_alignment"]``) is good when its residual RMS is at most
#: this fraction of the field (the importer's MAG_FIT_RMS_FRACTION: 0.9–2.9 µT of ~50 µT on the FIRM flights)
MAG_FIT_GOOD_FRACTION = 0.1


def gyro_magnetometer_check(pad_info: dict, log_name: str) -> Check | None:
    """geometry.gyro_magnetometer: the Earth's field, constant in an inertial frame, must turn in the
    magnetometer's axes as the gyro's rates say (the importer's in-flight alignment: one rotation,
    an offset, the field).  A fit that fails while the same fit with one gyro axis mirrored succeeds
    is a gyro whose axes are a mirror image of the magnetometer's — a swapped or sign-flipped column
    of the rates (a magnetometer column swap keeps the fit, the field's sign absorbing the mirror,
    and shows as a wrong dip instead): ERROR.  A fit that fails either way: WARNING (soft iron, a
    saturated gyro, a wrong field unit; the heading is then not trusted).  None when the log allowed
    no fit (decimated, or shorter than 2 s of boost and coast)."""
    al = pad_info.get("magnetometer_alignment")
    if not al:
        return None
    rms, field = float(al["fit_rms_uT"]), float(al.get("field_uT") or pad_info.get("magnetic_field_uT") or 0.0)
    lim = MAG_FIT_GOOD_FRACTION * field
    base = f"the magnetometer's field follows the gyro's rates to {rms:.2g} µT rms ({field:.0f} µT field)"
    if al.get("fit_accepted"):
        return _check("geometry.gyro_magnetometer", OK, rms, lim, base)
    mir = al.get("mirrored_gyro_fit_rms_uT")
    if mir is not None and mir <= lim:
        msg = (
            f"{base}, beyond the {lim:.2g} µT a consistent pair reaches; with one gyro axis mirrored it follows to "
            f"{mir:.2g} µT: the gyro's axes are a mirror image of the magnetometer's — a swapped or sign-flipped "
            f"column of raw_angular_rate_[xyz]_deg_per_s of {log_name}"
        )
        return _check("geometry.gyro_magnetometer", ERROR, rms, lim, msg)
    msg = (
        f"{base}, beyond the {lim:.2g} µT a consistent pair reaches (mirrored: "
        f"{'not tried' if mir is None else f'{mir:.2g} µT'}): soft iron, a saturated gyro or a field unit; "
        "the magnetometer's heading is not trusted"
    )
    return _check("geometry.gyro_magnetometer", WARNING, rms, lim, msg)


#: a motor designation: impulse class letter (A–O), average thrust [N], the rest (delay, propellant)
_MOTOR = re.compile(r"^\s*([A-Oa-o])\s*(\d+(?:\.\d+)?)")
#: the boost's m_dry·|f| (dry mass: propellant and drag left out) against the designation: its total
#: impulse inside the class's range widened to these factors of its ends, its mean over the motor
#: phase within these factors of the designation's average thrust (measured on the three FIRM flights:
#: 0.82–0.85 of the L1390's 3 950 N·s, 0.87–0.92 of its 1 390 N)
MOTOR_IMPULSE_SLACK = (0.6, 1.25)
MOTOR_THRUST_RATIO = (0.5, 1.5)


def motor_check(t, f_B, letters, meta, log_name: str) -> Check | None:
    """physics.motor: the declared motor against the measured boost. ``t`` (n,) [s], ``f_B`` (n, 3)
    [m/s²], ``letters`` (n,) the log's phase letters (``M`` the motor phase), ``meta`` the
    :class:`FlightMetadata` (``mass`` [kg], ``motor`` e.g. "L1390G-P": class L = 2 560–5 120 N·s,
    1 390 N average).  m·|f| integrated over the motor phase is the impulse the declared dry mass
    implies: a mass in lb doubles it, a ×10 mass moves it three classes, a wrong motor names a
    class it does not reach.  None without a parseable designation or motor rows."""
    m = _MOTOR.match(meta.motor or "")
    k = np.flatnonzero(np.asarray(letters) == "M")
    if m is None or k.size < 3:
        return None
    letter, f_avg = m.group(1).upper(), float(m.group(2))
    hi = 2.5 * 2.0 ** (ord(letter) - ord("A"))
    lo = hi / 2.0 if letter != "A" else 0.0
    sl = slice(int(k[0]), int(k[-1]) + 1)
    force = meta.mass * np.linalg.norm(f_B[sl], axis=1)
    impulse = float(np.trapezoid(force, t[sl]))
    dur = float(t[sl][-1] - t[sl][0])
    mean = impulse / dur if dur > 0.0 else float("nan")
    ratio = mean / f_avg if f_avg > 0.0 else float("nan")
    a, b = MOTOR_IMPULSE_SLACK
    r0, r1 = MOTOR_THRUST_RATIO
    base = (
        f"the declared motor {meta.motor} (class {letter}: {lo:.0f}–{hi:.0f} N·s, {f_avg:g} N average) against "
        f"rocket_dry_mass_kg × |f| over the motor phase: {impulse:.0f} N·s, {mean:.0f} N average (ratio {ratio:.2f})"
    )
    if a * lo <= impulse <= b * hi and r0 <= ratio <= r1:
        return _check("physics.motor", OK, ratio, [r0, r1], base)
    k_mass = ratio if np.isfinite(ratio) else 1.0
    why = (
        f"rocket_dry_mass_kg = {meta.mass:g} looks {k_mass:.2g}× too large (in lb? ×0.4536; ×10?)"
        if ratio > r1
        else f"rocket_dry_mass_kg = {meta.mass:g} looks too small"
    )
    msg = f"{base}: {why}, or the motor is not {meta.motor} (the metadata of {log_name})"
    return _check("physics.motor", ERROR, ratio, [r0, r1], msg)


def _coordinate_mixup(meta, d_max: float, inclination_deg: float | None = None) -> str:
    """What likely went wrong when the landed coordinates lie more than ``d_max`` [m] from the launch
    coordinates: the first of the usual mix-ups (latitude and longitude swapped, a sign dropped, on
    either pair of ``metadata.json``) that brings them within ``d_max``; else both pairs named.  The
    distance alone cannot tell which pair is wrong (the mix-up on either pair looks the same); the
    declared inclination [deg] can when the dipole's inclination at the launch coordinates and at the
    corrected ones differ by more than :data:`DIP_TOLERANCE_DEG`: the pair whose reading agrees
    with it is the right one.  Else both pairs are named."""
    la, lo, La, Lo = meta.launch_lat_deg, meta.launch_lon_deg, meta.landed_lat_deg, meta.landed_lon_deg
    both = "launch_site.launch_coordinates or flight_data.landed_coordinates"
    fixes = (
        ("latitude and longitude swapped", (lo, la, La, Lo)),
        ("the longitude's sign", (la, -lo, La, Lo)),
        ("the latitude's sign", (-la, lo, La, Lo)),
    )
    for what, (a, b, c, e) in fixes:
        if abs(a) <= 90.0 and abs(c) <= 90.0 and _great_circle_m(a, b, c, e) <= d_max:
            pair = both
            if inclination_deg is not None:
                as_declared = abs(inclination_deg - dipole_field(la, lo)[1]) <= DIP_TOLERANCE_DEG
                as_fixed = abs(inclination_deg - dipole_field(a, b)[1]) <= DIP_TOLERANCE_DEG
                if as_declared and not as_fixed:
                    pair = "flight_data.landed_coordinates (the launch site agrees with the declared inclination)"
                elif as_fixed and not as_declared:
                    pair = "launch_site.launch_coordinates (the declared inclination agrees with the corrected site)"
            km = d_max / 1000.0
            return f"in the metadata, {what} of {pair} looks wrong (corrected, the landing is within {km:.0f} km)"
    return f"{both} of the metadata are wrong"


def site_checks(meta, pad_info: dict, inclination_deg, log_name: str) -> list[Check]:
    """The launch coordinates against the landed ones, the dipole field against the measured field and
    the declared inclination (geometry.site, units.magnetometer, physics.magnetic_dip)."""
    out = []
    lat, lon = meta.launch_lat_deg, meta.launch_lon_deg
    landed = meta.landed_lat_deg is not None and meta.landed_lon_deg is not None
    d = _great_circle_m(lat, lon, meta.landed_lat_deg, meta.landed_lon_deg) if landed else 0.0
    d_max = max(LANDING_DISTANCE_MAX_M, 5.0 * (meta.apogee or 0.0))
    if not landed:
        pass  # no landed coordinates (a column-mapped import without them): unchecked
    elif d <= d_max:
        out.append(_check("geometry.landing_distance", OK, d, d_max, f"landed {d:.0f} m from the pad"))
    else:
        why = _coordinate_mixup(meta, d_max, inclination_deg)
        msg = (
            f"the landing point is {d / 1000:.0f} km from the launch coordinates (at most {d_max / 1000:.0f} km): {why}"
        )
        out.append(_check("geometry.landing_distance", ERROR, d, d_max, msg))
    b_exp, inc_exp = dipole_field(lat, lon)
    b_sw, inc_sw = dipole_field(lon, lat) if abs(lon) <= 90.0 else (b_exp, inc_exp)
    where = f"at the launch coordinates ({lat:.4f}, {lon:.4f})"
    b = pad_info.get("magnetic_field_uT")
    if b is not None and np.isfinite(b):
        ratio = b * 1e-6 / b_exp
        lo, hi = FIELD_RATIO_BAND
        msg = f"field magnitude {b:.1f} uT vs the dipole's {b_exp * 1e6:.1f} uT {where} (ratio {ratio:.2f})"
        if lo <= ratio <= hi:
            out.append(_check("units.magnetometer", OK, ratio, [lo, hi], msg))
        else:
            msg += ": magnetic_field_[xyz]_microteslas not in µT (gauss: ×100; nT: ×0.001)? or the site is wrong"
            out.append(_check("units.magnetometer", WARNING, ratio, [lo, hi], msg))
    swapped_hint = abs(inc_sw - inc_exp) > DIP_TOLERANCE_DEG
    dip = pad_info.get("magnetometer_dip_deg")
    aligned = (pad_info.get("magnetometer_alignment") or {}).get("fit_accepted", False)
    if dip is not None and aligned:
        diff = dip - inc_exp
        msg = f"the aligned magnetometer's dip on the pad {dip:.1f} deg vs the dipole's inclination {inc_exp:.1f} deg"
        msg += f" {where}"
        if abs(diff) <= DIP_TOLERANCE_DEG:
            out.append(_check("physics.magnetic_dip", OK, diff, DIP_TOLERANCE_DEG, msg))
        else:
            flipped = abs(dip + inc_exp) <= DIP_TOLERANCE_DEG
            swapped = swapped_hint and abs(dip - inc_sw) <= DIP_TOLERANCE_DEG
            # a declared inclination that agrees with the site (or a landing near the pad) vouches for it
            site_vouched = inclination_deg is not None and abs(inclination_deg - inc_exp) <= DIP_TOLERANCE_DEG
            site_vouched = site_vouched or d <= d_max
            acc = (
                "the dip has the wrong sign: the accelerometer's axes look sign-flipped (the pad's 'up' is the "
                f"sensor's down: raw_acceleration_[xyz]_gs of {log_name})"
            )
            swp = f"site latitude and longitude may be swapped (swapped, the dipole's inclination is {inc_sw:.0f} deg)"
            if flipped and (site_vouched or not swapped):
                why = acc
            elif swapped and not flipped:
                why = swp
            elif flipped and swapped:
                why = f"{acc}; or {swp}"
            else:
                why = "the site coordinates or the magnetometer's axes are wrong"
            out.append(_check("physics.magnetic_dip", ERROR, diff, DIP_TOLERANCE_DEG, f"{msg}: {why}"))
    if inclination_deg is not None:
        diff = inclination_deg - inc_exp
        msg = f"declared --inclination-deg {inclination_deg:g} vs the dipole's {inc_exp:.1f} deg {where}"
        if abs(diff) <= DIP_TOLERANCE_DEG:
            out.append(_check("geometry.site_inclination", OK, diff, DIP_TOLERANCE_DEG, msg))
        else:
            why = "the inclination or the launch coordinates are wrong"
            if swapped_hint and abs(inclination_deg - inc_sw) <= DIP_TOLERANCE_DEG:
                why = "site latitude and longitude may be swapped"
            out.append(_check("geometry.site_inclination", ERROR, diff, DIP_TOLERANCE_DEG, f"{msg}: {why}"))
    return out


def weather_checks(meta, board_pad_K: float | None) -> list[Check]:
    """The metadata's site temperature against the board's own pad temperature (the board runs warmer
    than the air; None: no board temperature, unchecked) and the wind against the launch limit
    (physics.site_temperature, physics.wind)."""
    out = []
    t_c = meta.temperature - 273.15
    b_c = board_pad_K - 273.15 if board_pad_K is not None else math.nan
    excess = meta.temperature - board_pad_K if board_pad_K is not None else math.nan
    msg = f"site air temperature {t_c:.1f} °C vs the flight computer's board on the pad {b_c:.1f} °C"
    if board_pad_K is None:
        pass  # no board temperature in the log: unchecked
    elif excess <= BOARD_COOLER_MARGIN_K:
        out.append(_check("physics.site_temperature", OK, excess, BOARD_COOLER_MARGIN_K, msg))
    else:
        msg += (
            f": the air {excess:.0f} K warmer than a board that runs warmer than the air — is "
            f"launch_site.air_temperature_celsius in °F ({t_c:.1f} °F = {(t_c - 32.0) / 1.8:.1f} °C)?"
        )
        out.append(_check("physics.site_temperature", ERROR, excess, BOARD_COOLER_MARGIN_K, msg))
    w = meta.wind_speed
    msg = f"surface wind {w:.1f} m/s ({w * 3.6:.1f} km/h)"
    if w <= WIND_MAX_M_S:
        out.append(_check("physics.wind", OK, w, WIND_MAX_M_S, msg))
    else:
        msg += " is twice the safety code's launch limit (20 mph): is launch_site.wind_speed_kmh in km/h?"
        out.append(_check("physics.wind", WARNING, w, WIND_MAX_M_S, msg))
    return out


def rate_check(obs_rate_hz: float, packet_hz: float, log_name: str) -> Check:
    """timing.observation_rate: the block-mean observations' effective rate (at most one block per
    packet) against the rate the per-block model-error levels were measured at."""
    eff = min(obs_rate_hz, packet_hz)
    ref = OBSERVATION_RATE_MEASURED_HZ
    msg = (
        f"observation rate {obs_rate_hz:g} Hz (--obs-rate-hz) on a log of {packet_hz:.1f} packets/s: "
        f"{eff:.1f} observations/s"
    )
    if eff <= 1.05 * ref:
        return _check("timing.observation_rate", OK, eff, ref, msg)
    status = ERROR if eff > 2.0 * ref or obs_rate_hz > 1.05 * packet_hz else WARNING
    msg += (
        f": the model-error levels of the pressure and |f| blocks were measured at {ref:g} Hz; at {eff:.0f} Hz "
        f"their errors are correlated and count {eff / ref:.1f}× over (σ too small by {math.sqrt(eff / ref):.1f}×)"
    )
    if obs_rate_hz > 1.05 * packet_hz:
        msg += f"; above {log_name}'s packet rate a block holds one sample or none"
    return _check("timing.observation_rate", status, eff, ref, msg)


def key_windows(t_coast: float, t_ej: float, t_main) -> dict[str, tuple[float, float]]:
    """The key windows [s after launch] by name (:data:`KEY_WINDOWS`): the coast from the coast letter
    to the drogue's ejection, each parachute opening over :data:`OPENING_WINDOW_S`."""
    a, b = OPENING_WINDOW_S
    w = {"coast": (t_coast, t_ej), "drogue_opening": (t_ej + a, t_ej + b)}
    if t_main is not None:
        w["main_opening"] = (t_main + a, t_main + b)
    return w


def _gap_checks(gaps_rel, windows: dict, log_name: str) -> tuple[list[Check], list[str], list[str]]:
    """(checks, undefined window names, notes) of the log's gaps against the key windows: a gap
    overlapping a key window longer than KEY_GAP_ERROR_S → ERROR and the window undefined, shorter →
    WARNING; gaps elsewhere are notes."""
    checks, undefined, notes = [], [], []
    for name, (a, b) in windows.items():
        hits = [g for g in gaps_rel if g.t_b > a and g.t_a < b]
        if not hits:
            checks.append(_check(f"data.gap.{name}", OK, 0.0, KEY_GAP_ERROR_S, f"no gap in {KEY_WINDOWS[name]}"))
            continue
        g = max(hits, key=lambda x: x.dt)
        what = f"{log_name}: a gap of {g.dt:.3f} s before row {g.row} ({g.t_a:.2f} .. {g.t_b:.2f} s)"
        what += f" in {KEY_WINDOWS[name]}"
        if g.dt > KEY_GAP_ERROR_S:
            undefined.append(name)
            checks.append(
                _check(f"data.gap.{name}", ERROR, g.dt, KEY_GAP_ERROR_S, what + ": its outputs are undefined")
            )
        else:
            checks.append(_check(f"data.gap.{name}", WARNING, g.dt, KEY_GAP_ERROR_S, what))
    for g in gaps_rel:
        if not any(g.t_b > a and g.t_a < b for a, b in windows.values()) and g.t_a >= 0.0:
            notes.append(
                f"gap of {g.dt:.3f} s before row {g.row} at {g.t_a:.2f} s (phase {g.phase}), away from the key moments"
            )
    return checks, undefined, notes


def import_checks(
    log,
    meta,
    fl,
    t,
    *,
    t_ej: float,
    t_main,
    ca0_unclipped: float,
    inclination_deg=None,
    obs_rate_hz: float = 10.0,
    names: dict | None = None,
) -> dict:
    """All import-time checks of a flight: ``log`` the :class:`FlightLog`, ``meta`` its
    :class:`FlightMetadata`, ``fl`` the :class:`~workbench.problems.post2.rocket.BoostSolution`,
    ``t`` (n,) [s after launch], ``t_ej``/``t_main`` the detected openings [s],
    ``ca0_unclipped`` the measured coast drag multiplier before its clip, ``obs_rate_hz`` the rate
    of the block-mean observations [Hz]; ``names`` the import's own names of :data:`INPUT_NAMES`
    (:func:`rename`; None: the FIRM log's).

    Returns a JSON-ready dict {"checks": [Check as dict], "undefined": [key-window names],
    "notes": [str]}."""
    name = log.path.name
    t_coast = float(t[np.flatnonzero(log.letters == "C")[0]])
    checks = [_axes_check(t, log.f_B, log.w_B, fl.gyro_bias, t_coast, t_ej, name)]
    t_f = float(t[np.flatnonzero(log.letters == "F")[0]])
    # the checks that need what a log may lack (the flight computer's attitude, the magnetometer, the
    # rod angle, the landed coordinates, the board temperature) are left out without it
    if log.ref_q is not None:
        checks.append(accel_sign_check(t, log.f_B, log.w_B, log.ref_q, t_coast, min(t_ej, t_f) - 1.0, name))
    sd = coast_strapdown(t, log.f_B, log.w_B, fl, t_ej - PITCH_OVER_BEFORE_EJECTION_S)
    checks.append(pitch_over_check(sd, t_coast, name))
    checks.append(strapdown_apogee_check(sd, log.pressure, fl.atmosphere, fl.h_pad, name))
    if meta.rod_angle_deg is not None:
        checks.append(pad_tilt_check(float(fl.pad_info["tilt_on_pad_deg"]), float(meta.rod_angle_deg)))
    k0 = int(np.searchsorted(t, fl.pad_info["ignition_t_s"] - 0.2))
    if log.mag_B is not None:
        checks.append(_mag_gyro_check(t, log.w_B, log.mag_B, fl.gyro_bias, k0, t_ej - 0.5, name))
    mc = motor_check(t, log.f_B, log.letters, meta, name)
    if mc is not None:
        checks.append(mc)
    gm = gyro_magnetometer_check(fl.pad_info, name)
    if gm is not None:
        checks.append(gm)
    checks += site_checks(meta, fl.pad_info, inclination_deg, name)
    t_pad_end = fl.pad_info["ignition_t_s"] - 0.1
    pad = (t >= t_pad_end - 1.0) & (t < t_pad_end)
    board = float(np.mean(log.temperature[pad])) if log.temperature is not None else None
    checks += weather_checks(meta, board)
    cd = coast_drag_coefficient(ca0_unclipped, meta.cd)
    lo, hi = ROCKET_CD_RANGE
    msg = (
        f"the first coast drag implies C_D {cd:.2f} on the reference area (metadata Cd {meta.cd:g} × measured "
        f"multiplier {ca0_unclipped:.2f}; any rocket, air brakes out: {lo:g}–{hi:g})"
    )
    if lo <= cd <= hi:
        checks.append(_check("physics.coast_drag_coefficient", OK, cd, [lo, hi], msg))
    else:
        msg += ": check rocket_dry_mass_kg (in lb? ×0.4536; ×10?), rocket_Cd and rocket_cross_sectional_area_m2"
        checks.append(_check("physics.coast_drag_coefficient", ERROR, cd, [lo, hi], msg))
    checks.append(rate_check(obs_rate_hz, 1.0 / float(np.median(np.diff(log.t))), name))
    gaps_rel = fl_gaps(log, t)
    gc, undefined, notes = _gap_checks(gaps_rel, key_windows(t_coast, t_ej, t_main), name)
    checks += gc
    return {"checks": [c.__dict__ for c in rename(checks, names)], "undefined": undefined, "notes": notes}


def fl_gaps(log, t):
    """The log's gaps (:class:`Gap`) with their times in seconds after launch (``t`` the log's times
    after launch, (n,))."""
    shift = float(log.t[0] - t[0])
    return [type(g)(g.t_a - shift, g.t_b - shift, g.dt, g.row, g.phase) for g in log.gaps]


def undefined_outputs(flight: dict) -> dict[str, str]:
    """{key window: why} of the windows whose outputs are undefined (a gap inside them), from the
    import's ``flight.json``."""
    hc = flight.get("health_checks") or {}
    by = {c["name"]: c["message"] for c in hc.get("checks", [])}
    return {w: by.get(f"data.gap.{w}", "gap") for w in hc.get("undefined", [])}


#: a bounded parameter at its bound is an ERROR only this many prior σ from its prior value: a bound
#: that is a parametrisation (a tilt kept positive, honest near zero) is no verdict on the data
BOUND_PRIOR_Z = 2.0


def bound_checks(cfg, hist: dict, *, plausibility: bool = False) -> list[Check]:
    """``physics.bound.<state>`` for every estimated scalar parameter with bounds (``cfg.states``;
    ``hist`` the smoothed state history {name: {"value": (n, k), ...}}, SI): ERROR when its final
    value sits at a bound (within 1 % of the range) more than :data:`BOUND_PRIOR_Z` prior σ from its
    prior value, or at once with ``plausibility`` (the bounds are the limits of any plausible
    vehicle, as an import writes them) — the model cannot explain the data inside the bounds, the
    declared inputs it multiplies are likely wrong (:data:`BOUND_HINTS`); else OK."""
    checks = []
    for spec in getattr(cfg, "states", ()):
        b = getattr(spec, "bounds", None)
        if b is None or spec.name not in hist:
            continue
        lo, hi = b
        v = float(hist[spec.name]["value"][-1, 0])
        tol = 0.01 * (hi - lo)
        at = "lower" if v <= lo + tol else ("upper" if v >= hi - tol else None)
        prior, sig = float(np.ravel(spec.value)[0]), float(np.ravel(spec.sigma)[0])
        z = abs(v - prior) / sig if sig > 0.0 else math.inf
        name = f"physics.bound.{spec.name}"
        if at is None or (z <= BOUND_PRIOR_Z and not plausibility):
            where = f"at its {at} bound, {z:.1f} prior σ from its prior" if at else "inside its bounds"
            checks.append(_check(name, OK, v, [lo, hi], f"{spec.name} {v:.4g} {where} [{lo:g}, {hi:g}]"))
        else:
            hint = BOUND_HINTS.get(spec.name, "the model cannot explain the data inside the bounds: check its inputs")
            msg = (
                f"{spec.name} ends at its {at} bound ({v:.4g} in [{lo:g}, {hi:g}], {z:.1f} prior σ from its prior "
                f"{prior:g}): not a result; {hint}"
            )
            checks.append(_check(name, ERROR, v, [lo, hi], msg))
    return checks


def run_checks(cfg, hist: dict) -> tuple[list[Check], list[str]]:
    """(checks, notes) a POST2 run adds to its health: :func:`bound_checks` of its estimate and, for
    an imported rocket flight, the import's checks (``flight.json`` beside the problem file), their
    messages in the names of the import's inputs (``flight.json`` ``input_names``, :func:`rename`)."""
    path = getattr(getattr(cfg, "run", None), "path", None)
    if path is None or not (Path(path).parent / "flight.json").is_file():
        return bound_checks(cfg, hist), []
    flight = read_json(Path(path).parent / "flight.json")  # written by the import (generated)
    hc = flight.get("health_checks") or {}
    checks = rename(bound_checks(cfg, hist, plausibility=True), flight.get("input_names"))
    return [Check(**c) for c in hc.get("checks", [])] + checks, list(hc.get("notes", []))


#: the names of the inputs the checks' messages give (the FIRM log's columns, its metadata's keys, the
#: import's options): an import from another layout maps each to its own (:func:`rename`)
INPUT_NAMES = (
    "raw_acceleration_[xyz]_gs",
    "raw_angular_rate_[xyz]_deg_per_s",
    "magnetic_field_[xyz]_microteslas",
    "launch_site.launch_coordinates",
    "flight_data.landed_coordinates",
    "launch_site.air_temperature_celsius",
    "launch_site.wind_speed_kmh",
    "launch_rod_angle",
    "rocket_dry_mass_kg",
    "rocket_cross_sectional_area_m2",
    "rocket_Cd",
    "--inclination-deg",
    "--obs-rate-hz",
)


def rename(checks: list[Check], names: dict | None) -> list[Check]:
    """``checks`` with each name of :data:`INPUT_NAMES` in their messages replaced by ``names[name]``
    (the import's own name of that input; None or absent: kept)."""
    if not names:
        return checks
    out = []
    for c in checks:
        msg = c.message
        for k in INPUT_NAMES:
            if k in names:
                msg = msg.replace(k, names[k])
        out.append(dataclasses.replace(c, message=msg))
    return out
