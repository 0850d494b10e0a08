"""Real rocket flights (issue #9, case 5): the boost from the IMU, the problem file of the coast and
descent, and the scores against the flight's references.

The motor's thrust history is not known, so the model-based estimation (post2's 3-DOF
:class:`~workbench.problems.post2.model.TrajectoryModel` with the drag of the rocket and of its
parachutes) starts shortly after burnout, and the boost is integrated from the IMU:

* **pad alignment** — over the last second of standby before the first motor row: the mean
  specific force is "up" (tilt), the mean body rate is the gyro bias, and the magnetic field gives
  the heading through the site's magnetic declination (TRIAD, :func:`workbench.core.rotation.triad`).
  The field is the one at the pad attitude of the magnetometer's in-flight alignment
  (:func:`magnetometer_alignment`: its axes, hard-iron offset and the field, fitted so the field
  turns with the integrated gyro through boost and coast), because the FIRM boards' magnetometer
  axes are not the IMU's (turned by −134° and −45° about z) and the steel launch rail distorts the
  standby field; the heading is trusted when that fit is good and its dip matches the site's
  inclination;
* **boost** — :func:`workbench.estimation.strapdown.integrate` (point mass + J2 gravity of the
  Earth, first-order covariance) from the pad to ``t_start`` = first coast row + 0.3 s (tail-off),
  in a planet-centred inertial frame M whose axes are the Earth-fixed axes at launch.  The pad sits
  at the launch coordinates (geodetic latitude used as the spherical one) at the altitude where the
  site's atmosphere has the standby pressure;
* the covariance at ``t_start`` is the strapdown's, plus an engineering budget for what a white-noise
  model leaves out: 1 % scale-factor error on the velocity gained and its integral on the
  position (the post2 problem file takes a diagonal 1σ per component: correlations are dropped).

The site's reported air pressure is read as QNH (reduced to sea level); the atmosphere is the U.S.
Standard Atmosphere 1976 with that sea-level pressure, and the pad altitude is the altitude of the
standby pressure, so the ``baro_bias`` state measures only the departure *in flight* from that
profile.  The tuning constants below were measured on the three flights; the measurements are in
``docs/tuning/post2.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from workbench.core.atmosphere import EarthStandardAtmosphere
from workbench.core.bodies import EARTH
from workbench.core.rotation import (
    dcm_to_quat,
    quat_history_from_body_rates,
    quat_multiply,
    quat_to_dcm,
    quat_to_rotvec,
    triad,
)
from workbench.estimation.consistency import chi2_ppf, mixture_hdr_level
from workbench.estimation.magnetometer import align_magnetometer
from workbench.estimation.strapdown import ImuArrays, integrate
from workbench.io.schema import read_json
from workbench.io.telemetry import read_telemetry
from workbench.problems.post2 import pipeline, rocket_checks
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.model import POSITION, VELOCITY
from workbench.problems.post2.rocket_results import (
    LANDING_MIXTURE_SAMPLES,
    LANDING_MIXTURE_SEED,
    altitude_above_pad,
    covariance_given_heading,
    enu_axes,
    horizontal_covariance,
    landing_heading_mixture,
    vertical_sigma,
)

__all__ = [
    "PAD_WINDOW_S",
    "TAIL_OFF_S",
    "BoostSolution",
    "site_atmosphere",
    "pad_position",
    "reconstruct_boost",
    "detect_ejection",
    "detect_main_deploy",
    "pressure_sigma",
    "accel_sigma",
    "local_noise",
    "initial_ca_multiplier",
    "ca_scale",
    "problem_file",
    "local_en",
    "score_flight",
    "FIRM_ALTITUDE_SCALE_M",
    "FIRM_PRESSURE_EXPONENT",
    "SEA_LEVEL_PRESSURE_PA",
    "firm_altitude",
    "firm_pressure",
    "flight_computer_altimeter",
    "run_flight",
    "landing_point_inertial",
]

#: the strapdown's error state [δv, δθ, δp] (9,) (:func:`workbench.estimation.strapdown.integrate`)
SD_VELOCITY, SD_ATTITUDE, SD_POSITION = slice(0, 3), slice(3, 6), slice(6, 9)
#: length of the standby window that aligns the IMU on the pad [s]
PAD_WINDOW_S = 1.0
#: the pad window ends this long before the detected ignition [s]
IGNITION_GUARD_S = 0.1
#: the model starts this long after the first coast row (motor tail-off) [s]
TAIL_OFF_S = 0.3
#: engineering 1σ of what the strapdown's white noise leaves out: accelerometer scale factor [-]
ACCEL_SCALE_SIGMA = 0.01
#: 1σ of the pad tilt [rad] (accelerometer levelling) and heading [rad] (the aligned magnetometer:
#: the pad heading fitted on thirds of the alignment window spreads by 11° RMS about the whole
#: window's on flight 1 and 4.5° on flight 4 — gyro scale errors over ~2 000° of roll, soft iron)
TILT_SIGMA = math.radians(1.0)
HEADING_SIGMA = math.radians(10.0)
#: the magnetometer's heading is trusted only if its dip at the pad is within this of the site's
#: magnetic inclination [deg] and its in-flight alignment fitted; otherwise (no alignment: a
#: decimated log or a saturated gyro; hard/soft iron beyond the fit) the heading is taken as
#: unknown: 1σ HEADING_SIGMA_UNTRUSTED (as wide as a linearised filter can carry)
DIP_TOLERANCE_DEG = 10.0
HEADING_SIGMA_UNTRUSTED = math.radians(60.0)
#: gyro full scale of the FIRM logs [rad/s] (~1 800 deg/s; samples at or above are saturated)
GYRO_SATURATION = math.radians(1790.0)


#: the magnetometer's in-flight alignment (:func:`magnetometer_alignment`) is fitted from the pad to
#: this long before the drogue's ejection [s] (the ejection tumbles the body beyond the gyro's range)
MAG_FIT_BEFORE_EJECTION_S = 0.5
#: ... and accepted when its residual RMS is at most this fraction of the fitted field (measured:
#: 0.9, 2.9 and 2.0 µT of ~50 µT on flights 1, 3, 4 — servo currents and soft iron)
MAG_FIT_RMS_FRACTION = 0.1
#: ... on at least this many gyro/magnetometer samples (a decimated log cannot follow the coning)
MAG_FIT_MIN_RATE_HZ = 50.0


def magnetometer_alignment(t, w_B, mag_B, k0: int, t_end: float):
    """The magnetometer's in-flight alignment (:func:`workbench.estimation.magnetometer.align_magnetometer`)
    over the samples from index ``k0`` (the reference attitude: the pad) to ``t_end`` [s], from the
    body rates ``w_B`` (n, 3) [rad/s, bias removed] and the field ``mag_B`` (n, 3) [T] at ``t`` (n,)
    [s]; None when that stretch is shorter than 2 s, sampled below MAG_FIT_MIN_RATE_HZ, or
    holds a saturated gyro sample (its attitude would be wrong from there on).

    The FIRM logs need it: their magnetometer axes are turned about the IMU's z axis by −134°
    (flight 1, FIRM v0.1) and −45° (flights 3, 4, v1.0) — in both boards the magnetometer's +y is
    the rocket's nose, the IMU sits at 45° — which the pad's raw dip betrays (−49°, +7°, +30°
    against the sites' +62–66°); aligned, the dips are 62°, 64°, 65°."""
    k1 = int(np.searchsorted(t, t_end))
    sel = slice(k0, k1)
    tt = t[sel]
    if tt.size < 10 or tt[-1] - tt[0] < 2.0 or (tt.size - 1) / (tt[-1] - tt[0]) < MAG_FIT_MIN_RATE_HZ:
        return None
    if np.any(np.abs(w_B[sel]) >= GYRO_SATURATION):
        return None
    C_0_B = quat_to_dcm(quat_history_from_body_rates(tt, w_B[sel]))
    return align_magnetometer(C_0_B, mag_B[sel])


@dataclass(frozen=True, eq=False)
class BoostSolution:
    """The boost integrated from the IMU: ``t_start`` [s after launch] where the model starts;
    ``p_M``, ``v_M`` (3,) [m, m/s] there, 1σ ``sigma_p``, ``sigma_v`` (3,); ``atmosphere`` the site's;
    ``h_pad`` [m] pad altitude (above the Earth's mean sphere); ``p_pad`` (3,) pad position in M;
    ``q_M_B_pad`` (4,) pad attitude; ``gyro_bias`` (3,) [rad/s]; ``axis_B`` (3,) the rocket's long
    axis in the IMU frame (mean specific force of the boost); ``pad_pressure_std`` [Pa] standby
    noise; ``pad_info``/``burnout_info`` JSON-ready records; ``corr_pv`` (6, 6) the correlation
    matrix of the errors of [p_M, v_M] (None: independent)."""

    t_start: float
    p_M: np.ndarray
    v_M: np.ndarray
    sigma_p: np.ndarray
    sigma_v: np.ndarray
    atmosphere: EarthStandardAtmosphere
    h_pad: float
    p_pad: np.ndarray
    q_M_B_pad: np.ndarray
    gyro_bias: np.ndarray
    axis_B: np.ndarray
    pad_pressure_std: float
    pad_info: dict
    burnout_info: dict
    corr_pv: np.ndarray | None = None


def site_atmosphere(qnh_pa: float, site_temperature_K: float, standby_pressure_pa: float):
    """(atmosphere, pad altitude [m]): the 1976 standard atmosphere with sea-level pressure ``qnh_pa``
    and the site temperature reduced to sea level (−6.5 K/km) at the altitude of the standby pressure
    (two fixed-point iterations; altitudes above the Earth's mean sphere).

    A standby pressure above ``qnh_pa`` (flight 1: +165 Pa, a coastal field read as 14 m below sea
    level) would put the pad and the last metres of the descent below h = 0, where post2's model
    holds the atmosphere at its h = 0 values (the pressure stops rising and the barometer offset
    absorbs it: +150 Pa on flight 1); the standby pressure then anchors the column (pad at h = 0)."""
    qnh_pa = max(float(qnh_pa), float(standby_pressure_pa))
    h = 0.0
    atm = EarthStandardAtmosphere(qnh_pa, site_temperature_K)
    for _ in range(3):
        atm = EarthStandardAtmosphere(qnh_pa, site_temperature_K + 0.0065 * h)
        h = float(atm.altitude_of_pressure(standby_pressure_pa))
    return atm, h


def pad_position(lat_deg: float, lon_deg: float, h_pad: float) -> np.ndarray:
    """Pad position (3,) [m] in M: the launch coordinates (geodetic latitude used as spherical) at
    ``h_pad`` above the Earth's mean sphere."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    return (EARTH.reference_radius + h_pad) * enu_axes(lat, lon)[:, 2]


def local_en(lat_deg, lon_deg, lat0_deg: float, lon0_deg: float) -> np.ndarray:
    """East/north offsets [m] (..., 2) of coordinates [deg] from (lat0, lon0) on the mean sphere
    (flat-Earth: fine over a few km)."""
    r = EARTH.reference_radius
    dn = np.radians(np.asarray(lat_deg, float) - lat0_deg) * r
    de = np.radians(np.asarray(lon_deg, float) - lon0_deg) * r * math.cos(math.radians(lat0_deg))
    return np.stack([de, dn], axis=-1)


def reconstruct_boost(
    t,
    letters,
    f_B,
    w_B,
    mag_B,
    pressure,
    meta,
    declination_deg: float,
    inclination_deg: float | None = None,
    heading_prior_deg: tuple[float | None, float] = (None, math.degrees(HEADING_SIGMA_UNTRUSTED)),
) -> BoostSolution:
    """Pad alignment + strapdown through the boost (module docstring).

    ``t`` (n,) [s from launch], ``letters`` (n,) phase letters, ``f_B`` (n, 3) [m/s²], ``w_B`` (n, 3)
    [rad/s], ``mag_B`` (n, 3) [T] or None (no magnetometer), ``pressure`` (n,) [Pa] as logged; ``meta``
    the flight's :class:`~workbench.problems.post2.importers.flightlog.FlightMetadata`;
    ``declination_deg`` east positive; ``inclination_deg`` the site's magnetic dip (down positive) that
    the pad's measured dip is checked against (None: not checked, the heading trusted).

    Without a magnetometer, or with one that has no in-flight alignment and whose raw dip on the pad is
    not the site's (``inclination_deg``, else the dipole's) within DIP_TOLERANCE_DEG — its axes are not
    the IMU's —, the pad heading is the prior ``heading_prior_deg`` = (bearing [deg clockwise from true
    north] of the horizontal projection of the body x axis — of the y axis when x is within 30° of the
    vertical — or None: unknown, taken as 0; its 1σ [deg]) and is never trusted.
    ValueError if there is less than half a pad window of contiguous standby data."""
    k_launch = int(np.flatnonzero(letters == "M")[0])
    # the motor letter comes after lift-off is detected: ignition is the first sample of the last
    # run of |f| > 1.5 g before it; the pad window ends IGNITION_GUARD_S before ignition
    fn = np.linalg.norm(f_B, axis=1) / 9.80665
    k_ign = k_launch
    while k_ign > 0 and fn[k_ign - 1] > 1.5:
        k_ign -= 1
    t_ign = float(t[k_ign])
    t_pad_end = t_ign - IGNITION_GUARD_S
    pad = np.flatnonzero((t >= t_pad_end - PAD_WINDOW_S) & (t < t_pad_end) & (letters == "S"))
    # keep only the contiguous run just before launch (standby logs are sparse)
    if pad.size:
        steps = np.diff(t[pad])
        cut = np.flatnonzero(steps > 3.0 * np.median(np.diff(t[max(0, k_launch - 50) : k_launch + 1])))
        if cut.size:
            pad = pad[cut[-1] + 1 :]
    if pad.size < 5 or t[pad[-1]] - t[pad[0]] < 0.5 * PAD_WINDOW_S:
        raise ValueError("fewer than 0.5 s of contiguous standby data before launch: cannot align the IMU on the pad")
    f_pad = f_B[pad].mean(axis=0)
    bias = w_B[pad].mean(axis=0)
    p_standby = float(pressure[pad].mean())
    p_std = float(pressure[pad].std(ddof=1))
    atm, h_pad = site_atmosphere(meta.qnh, meta.temperature, p_standby)
    down = -f_pad / np.linalg.norm(f_pad)

    def dip_of(m):
        return 90.0 - math.degrees(math.acos(np.clip(np.dot(down, m) / np.linalg.norm(m), -1.0, 1.0)))

    t_coast = float(t[np.flatnonzero(letters == "C")[0]])
    mag_info: dict = {"magnetometer_alignment": None, "magnetometer_dip_deg": None}

    def prior_heading():
        # the heading prior's: the bearing of a horizontal body axis, never trusted
        psi_deg = heading_prior_deg[0]
        axis_h = 0 if abs(float(down[0])) < math.cos(math.radians(30.0)) else 1
        e_h = np.eye(3)[axis_h]
        psi = math.radians(psi_deg or 0.0)
        q = triad(f_pad, e_h - np.dot(e_h, -down) * -down, [0.0, 0.0, 1.0], [math.sin(psi), math.cos(psi), 0.0])
        return q, {"pad_heading_prior_deg": psi_deg, "pad_heading_axis": "xyz"[axis_h]}

    if mag_B is None:
        q_enu_b, info_h = prior_heading()
        trusted = False
        sig_heading = math.radians(heading_prior_deg[1])
        mag_info |= info_h | {"magnetometer": None, "pad_heading_source": "prior (no magnetometer)"}
    else:
        m_pad = mag_B[pad].mean(axis=0)
        dec = math.radians(declination_deg)
        # the magnetometer's own axes are not the IMU's: align it in flight (gyro-consistent fit through
        # boost and coast) and take the field at the pad attitude from that fit, not the pad samples
        # (the steel launch rail distorts those)
        k_f = np.flatnonzero(letters == "F")
        t_ej = detect_ejection(t, f_B, t_coast, float(t[k_f[0]]) if k_f.size else float(t[-1]))
        mag_fit = magnetometer_alignment(t, w_B - bias, mag_B, int(pad[-1]), t_ej - MAG_FIT_BEFORE_EJECTION_S)
        m_pad_raw = m_pad
        if mag_fit is not None:
            m_pad = mag_fit.field_0
        dip = dip_of(m_pad)
        inc_ref = inclination_deg
        if inc_ref is None:
            inc_ref = rocket_checks.dipole_field(meta.launch_lat_deg, meta.launch_lon_deg)[1]
        info_h = {"pad_heading_source": "magnetometer, aligned in flight"}
        if mag_fit is None and not abs(dip - inc_ref) <= DIP_TOLERANCE_DEG:
            # no in-flight alignment and a raw dip that is not the site's: the magnetometer's axes are
            # not the IMU's, so its raw field says nothing of the heading -- the prior's, as without one
            q_enu_b, info_h = prior_heading()
            info_h["pad_heading_source"] = (
                f"prior (the unaligned magnetometer's dip {dip:.0f} deg is not the site's {inc_ref:.0f} deg: "
                "its axes are not the IMU's)"
            )
        else:
            # TRIAD: up from the specific force, heading from the horizontal part of the field (any dip)
            q_enu_b = triad(f_pad, m_pad, np.array([0.0, 0.0, 1.0]), np.array([math.sin(dec), math.cos(dec), -1.5]))
            if mag_fit is None:
                info_h["pad_heading_source"] = "magnetometer, raw axes (its dip is the site's)"
        fit_ok = mag_fit is not None and mag_fit.rms <= MAG_FIT_RMS_FRACTION * float(np.linalg.norm(mag_fit.field_0))
        mirror = None
        if mag_fit is not None and not fit_ok:
            # a gyro whose axes are a mirror image of the true ones (a swapped or sign-flipped column)
            # turns the field the wrong way round: no rotation absorbs it, one mirrored axis does
            w_mirror = (w_B - bias) * np.array([1.0, 1.0, -1.0])
            mirror = magnetometer_alignment(t, w_mirror, mag_B, int(pad[-1]), t_ej - MAG_FIT_BEFORE_EJECTION_S)
        trusted = fit_ok and (inclination_deg is None or abs(dip - inclination_deg) <= DIP_TOLERANCE_DEG)
        sig_heading = HEADING_SIGMA if trusted else HEADING_SIGMA_UNTRUSTED
        if "pad_heading_prior_deg" in info_h:
            sig_heading = math.radians(heading_prior_deg[1])
        mag_info = info_h | {
            "magnetometer_dip_deg": dip,
            "magnetometer_dip_raw_pad_deg": dip_of(m_pad_raw),
            "magnetic_field_uT": float(np.linalg.norm(m_pad) * 1e6),
            "magnetometer_alignment": None
            if mag_fit is None
            else {
                "rotation_imu_to_magnetometer_rotvec_deg": np.degrees(
                    quat_to_rotvec(dcm_to_quat(mag_fit.C_mag_imu))
                ).tolist(),
                "hard_iron_offset_uT": (mag_fit.offset * 1e6).tolist(),
                "fit_rms_uT": mag_fit.rms * 1e6,
                "samples": mag_fit.samples,
                "window_s": [float(t[pad[-1]]), t_ej - MAG_FIT_BEFORE_EJECTION_S],
                "fit_accepted": bool(fit_ok),
                "field_uT": float(np.linalg.norm(mag_fit.field_0) * 1e6),
                "mirrored_gyro_fit_rms_uT": None if mirror is None else mirror.rms * 1e6,
            },
        }
    lat, lon = math.radians(meta.launch_lat_deg), math.radians(meta.launch_lon_deg)
    C_M_ENU = enu_axes(lat, lon)
    q_m_b = quat_multiply(dcm_to_quat(C_M_ENU), q_enu_b)
    p0 = pad_position(meta.launch_lat_deg, meta.launch_lon_deg, h_pad)
    v0 = np.cross([0.0, 0.0, EARTH.rotation_rate], p0)
    # attitude 1σ: tilt about east/north, heading about up -> body frame small angles
    C_B_ENU = quat_to_dcm(q_enu_b).T
    # an untrusted heading is left out: the run adds it as an exact rotation about the pad's vertical
    # ([launch] heading_sigma_deg; pipeline.Estimator), which a linearised boost covariance does not carry
    sig_boost_heading = sig_heading if trusted else 0.0
    P_att = C_B_ENU @ np.diag([TILT_SIGMA**2, TILT_SIGMA**2, sig_boost_heading**2]) @ C_B_ENU.T
    P0 = np.zeros((9, 9))
    P0[SD_VELOCITY, SD_VELOCITY] = np.eye(3) * 0.01**2
    P0[SD_ATTITUDE, SD_ATTITUDE] = P_att
    P0[SD_POSITION, SD_POSITION] = np.eye(3) * 1.0**2
    t_start = t_coast + TAIL_OFF_S
    sel = np.flatnonzero((t >= t[pad[-1]]) & (t <= t_start + 1e-9))
    imu = ImuArrays(
        t[sel], f_B[sel], w_B[sel] - bias, np.full((sel.size, 3), 0.05), np.full((sel.size, 3), math.radians(0.1))
    )
    sp = integrate(imu, v0, q_m_b, p0, P0, body=EARTH)
    # the strapdown ends at the last sample before t_start: carry it ballistically (< 1 sample)
    p1, v1 = sp.p_M[-1], sp.v_M[-1]
    dv = v1 - v0
    dur = float(sp.t[-1] - sp.t[0])
    # covariance of [δp, δv] (6, 6) at t_start: the strapdown's (error state [δv, δθ, δp]) plus the
    # scale-factor error, one number s for the whole boost: δv = s Δv, δp ≈ s Δv T/2 (fully correlated)
    ipv = np.r_[np.arange(9)[SD_POSITION], np.arange(9)[SD_VELOCITY]]  # -> the TRANSLATION layout
    u = np.concatenate([0.5 * dv * dur, dv])
    P_pv = sp.P[-1][np.ix_(ipv, ipv)] + ACCEL_SCALE_SIGMA**2 * np.outer(u, u)
    P_pv = 0.5 * (P_pv + P_pv.T)
    sd = np.sqrt(np.diag(P_pv))
    sig_p, sig_v = sd[POSITION], sd[VELOCITY]
    corr_pv = P_pv / np.outer(sd, sd)
    boost = (t >= 0.0) & (t < t_coast)
    axis = f_B[boost].mean(axis=0)
    axis /= np.linalg.norm(axis)
    up = p1 / np.linalg.norm(p1)
    info_pad = {
        "standby_pressure_pa": p_standby,
        "standby_pressure_std_pa": p_std,
        "pad_altitude_m": h_pad,
        "qnh_minus_standby_pa": meta.qnh - p_standby,
        "gyro_bias_deg_s": np.degrees(bias).tolist(),
        "specific_force_on_pad_g": float(np.linalg.norm(f_pad) / 9.80665),
        "rocket_axis_imu": axis.tolist(),
        "tilt_on_pad_deg": math.degrees(math.acos(np.clip(np.dot(axis, f_pad / np.linalg.norm(f_pad)), -1, 1))),
        "samples": int(pad.size),
        **mag_info,
        "site_inclination_deg": inclination_deg,
        "magnetometer_heading_trusted": bool(trusted),
        "heading_sigma_deg": math.degrees(sig_heading),
        "ignition_t_s": t_ign,
    }
    C_ENU_M = C_M_ENU.T
    info_burnout = {
        "t_s": float(sp.t[-1]),
        "altitude_above_pad_m": float(np.linalg.norm(p1) - EARTH.reference_radius - h_pad),
        "velocity_enu_m_s": (C_ENU_M @ (v1 - np.cross([0.0, 0.0, EARTH.rotation_rate], p1))).tolist(),
        "sigma_position_m": sig_p.tolist(),
        "sigma_velocity_m_s": sig_v.tolist(),
        "vertical_speed_m_s": float(np.dot(v1 - np.cross([0.0, 0.0, EARTH.rotation_rate], p1), up)),
    }
    return BoostSolution(
        float(sp.t[-1]), p1, v1, sig_p, sig_v, atm, h_pad, p0, q_m_b, bias, axis, p_std, info_pad, info_burnout, corr_pv
    )


#: the ejection shock: the first |specific force| above this after the coast's first seconds [m/s²]
EJECTION_THRESHOLD = 3.0 * 9.80665
#: ... searched from this long after the coast letter [s] (the burnout transient ends before)
EJECTION_SEARCH_AFTER_COAST_S = 3.0


def detect_ejection(t, f_B, t_coast: float, t_letter: float) -> float:
    """Time [s] of the drogue's ejection: the first sample after ``t_coast`` +
    EJECTION_SEARCH_AFTER_COAST_S and before ``t_letter`` + 1 s (the flight computer's descent
    letter) whose |specific force| (``f_B`` (n, 3) [m/s²] at ``t`` (n,) [s]) exceeds
    EJECTION_THRESHOLD; the letter itself when there is none.  (Flight 4's letter comes 3.5 s after
    the ejection shock of 25.6 g; flights 1 and 3 agree with their letters within 0.03 s.)"""
    fn = np.linalg.norm(f_B, axis=1)
    k = np.flatnonzero((t > t_coast + EJECTION_SEARCH_AFTER_COAST_S) & (t < t_letter + 1.0) & (fn > EJECTION_THRESHOLD))
    return float(t[k[0]]) if k.size else float(t_letter)


def detect_main_deploy(t, pressure, f_B, atm, t_apogee: float, t_end: float) -> float | None:
    """Time [s] of the main parachute's opening, or None: after apogee + 5 s, the barometric descent
    rate (1 s differences of the altitude) falls below half the drogue's median rate and stays there
    for 2 s; the opening is the largest |specific force| in the 3 s before that."""
    sel = (t > t_apogee) & (t <= t_end)
    ts = t[sel]
    if ts.size < 20 or ts[-1] - ts[0] < 8.0:
        return None
    h = atm.altitude_of_pressure(pressure[sel])
    grid = np.arange(ts[0], ts[-1], 0.25)
    hg = np.interp(grid, ts, h)
    rate = np.full(grid.size, np.nan)
    rate[4:] = -(hg[4:] - hg[:-4]) / 1.0
    drogue = (grid > t_apogee + 5.0) & (grid < t_apogee + 12.0)
    if not np.any(drogue):
        return None
    v_d = float(np.nanmedian(rate[drogue]))
    if not v_d > 3.0:
        return None
    slow = np.nan_to_num(rate, nan=np.inf) < 0.5 * v_d
    for k in np.flatnonzero(slow & (grid > t_apogee + 5.0)):
        later = (grid >= grid[k]) & (grid <= grid[k] + 2.0)
        if np.all(slow[later]):
            w = (t >= grid[k] - 3.0) & (t <= grid[k])
            if not np.any(w):
                return float(grid[k])
            return float(t[w][np.argmax(np.linalg.norm(f_B[w], axis=1))])
    return None


#: random-walk PSD of the coast drag multiplier [1/s] (air brakes, coning, pitch-over; measured:
#: docs/tuning/post2.md) at the metadata Cd of the flights it was measured on, CD_MEASURED
CA_PSD = 0.4
#: the metadata's Cd [-] at which CA_PSD and the multiplier's prior floor, bounds and clip
#: (CA_SIGMA_FLOOR, CA_BOUNDS, CA_CLIP) apply: flight 1's and the excerpt's (flights 3 and 4 declare
#: 0.393; CA_PSD pooled over the three is 0.41 at 0.38, within its flight-to-flight spread). The
#: problem file scales them by CD_MEASURED / Cd (:func:`ca_scale`), so that the declared Cd only
#: normalises the multiplier (the coast drag coefficient multiplier × Cd, and every other number of
#: the run, do not depend on it)
CD_MEASURED = 0.38
CA_SIGMA_FLOOR = 0.5
CA_BOUNDS = (0.2, 6.0)
CA_CLIP = (0.3, 5.5)


def ca_scale(cd: float) -> float:
    """The factor [-] by which the coast drag multiplier's levels (CA_PSD: by its square; CA_SIGMA_FLOOR,
    CA_BOUNDS, CA_CLIP) measured at Cd = CD_MEASURED apply to a rocket whose metadata declares ``cd``
    [-]: CD_MEASURED / cd (1 for a non-positive or non-finite cd, which the import refuses anyway)."""
    return CD_MEASURED / cd if math.isfinite(cd) and cd > 0.0 else 1.0


#: 1σ model-error levels of the block-mean pressure [Pa] per phase (coast, drogue, main; the burnout
#: transient of BURNOUT_TRANSIENT_S [s] and the drogue's ejection: 3 kPa, i.e. not used): the RMS of
#: the 10 Hz innovations on the three flights, pooled (issue #9 case 5; docs/tuning/post2.md)
PRESSURE_SIGMA_COAST = 120.0
PRESSURE_SIGMA_DROGUE = 125.0
PRESSURE_SIGMA_MAIN = 25.0
PRESSURE_SIGMA_TRANSIENT = 3000.0
BURNOUT_TRANSIENT_S = 2.5
#: prior 1σ of the in-flight barometer offset [Pa] (~2.5 m): the pad altitude is fitted to the
#: standby pressure, so what is left is a drift in flight (board heating, port effects)
BARO_BIAS_SIGMA = 30.0
# The flight computer's altitude is a standard-day pressure altitude (flight_computer_altimeter scores
# it raw and like for like); the barometer states baro_scale and baro_q_coefficient were tried and are
# not written into the problem files (measurements: docs/tuning/post2.md, "the flight computer's altitude").


def pressure_sigma(
    t, t_coast: float, t_apogee: float, standby_std: float, count, t_main: float | None = None, levels=None
) -> np.ndarray:
    """1σ [Pa] (n,) of the block-mean pressures at t (n,) [s after launch]: the standby noise over
    √count plus the measured model-error levels above (coast letter at ``t_coast``, drogue ejection
    at ``t_apogee``, main at ``t_main``; None: the drogue's level to the end).  ``levels`` {name:
    value or None} overrides the coast/drogue/main levels (``pressure_coast_pa``, ``pressure_drogue_pa``,
    ``pressure_main_pa``: a flight whose barometer or airframe differs from the FIRM flights')."""
    lv = {k: v for k, v in (levels or {}).items() if v is not None}
    t = np.asarray(t, float)
    floor = np.where(
        t < t_apogee,
        lv.get("pressure_coast_pa", PRESSURE_SIGMA_COAST),
        lv.get("pressure_drogue_pa", PRESSURE_SIGMA_DROGUE),
    )
    if t_main is not None:
        floor = np.where(t >= t_main, lv.get("pressure_main_pa", PRESSURE_SIGMA_MAIN), floor)
    floor = np.where(t < t_coast + BURNOUT_TRANSIENT_S, PRESSURE_SIGMA_TRANSIENT, floor)
    floor = np.where((t >= t_apogee - 0.2) & (t <= t_apogee + 2.0), PRESSURE_SIGMA_TRANSIENT, floor)
    return np.sqrt(floor**2 + standby_std**2 / np.asarray(count, float))


#: 1σ [m/s²] of the block-mean |specific force| against the 3-DOF drag model: the block's own
#: sensor/vibration noise (:func:`local_noise` over √count) plus a model-error level per phase (coast,
#: drogue, main, within 2 s of an opening), measured as the pressure levels (docs/tuning/post2.md)
ACCEL_SIGMA_COAST = 0.3
ACCEL_SIGMA_DROGUE = 14.0
ACCEL_SIGMA_MAIN = 3.0
ACCEL_SIGMA_OPENING = 30.0
#: half-width of the window of :func:`local_noise` [s]
NOISE_WINDOW_S = 0.25
#: ... widened up to this half-width [s] where it holds fewer than NOISE_MIN_SAMPLES samples (a sparse
#: or thinned log: without it the block's own noise would count as zero and its σ be the model
#: error's alone)
NOISE_WINDOW_MAX_S = 1.0
NOISE_MIN_SAMPLES = 4


def local_noise(t_blocks, t, v) -> np.ndarray:
    """1σ sample noise (n,) of the samples v (m,) at t (m,) [s] around each block time t_blocks (n,):
    the RMS of the samples in ±NOISE_WINDOW_S about their straight-line fit (the flight's own trend
    removed); where that window holds fewer than NOISE_MIN_SAMPLES samples, the NOISE_MIN_SAMPLES + 1
    samples nearest the block within ±NOISE_WINDOW_MAX_S; 0 where even those are too few."""
    t_blocks = np.asarray(t_blocks, float)
    out = np.zeros(t_blocks.size)
    lo = np.searchsorted(t, t_blocks - NOISE_WINDOW_S)
    hi = np.searchsorted(t, t_blocks + NOISE_WINDOW_S, side="right")
    lo_w = np.searchsorted(t, t_blocks - NOISE_WINDOW_MAX_S)
    hi_w = np.searchsorted(t, t_blocks + NOISE_WINDOW_MAX_S, side="right")
    for k, (a, b) in enumerate(zip(lo, hi, strict=True)):
        if b - a < NOISE_MIN_SAMPLES:
            near = np.arange(lo_w[k], hi_w[k])
            near = near[np.argsort(np.abs(t[near] - t_blocks[k]), kind="stable")[: NOISE_MIN_SAMPLES + 1]]
            if near.size < NOISE_MIN_SAMPLES:
                continue
            a, b = int(near.min()), int(near.max()) + 1
        tt, vv = t[a:b] - t_blocks[k], v[a:b]
        c = np.polyfit(tt, vv, 1)
        out[k] = math.sqrt(float(np.sum((vv - np.polyval(c, tt)) ** 2)) / (b - a - 2))
    return out


def accel_sigma(t, t_apogee: float, t_main: float | None, noise=None, count=None, levels=None) -> np.ndarray:
    """1σ [m/s²] (n,) of the block-mean |specific force| at t (n,) [s after launch]: the model-error
    levels above (drogue from ``t_apogee``, main from ``t_main``; the opening level within
    −0.2 .. +2 s of each opening) combined with the block's sample ``noise`` (n,) [m/s²] over
    √``count`` (n,) (:func:`local_noise`; None: none).  ``levels`` {name: value or None} overrides
    the coast/drogue/main levels (``accel_coast_m_s2``, ``accel_drogue_m_s2``, ``accel_main_m_s2``)."""
    lv = {k: v for k, v in (levels or {}).items() if v is not None}
    t = np.asarray(t, float)
    s = np.where(
        t < t_apogee, lv.get("accel_coast_m_s2", ACCEL_SIGMA_COAST), lv.get("accel_drogue_m_s2", ACCEL_SIGMA_DROGUE)
    )
    if t_main is not None:
        s = np.where(t >= t_main, lv.get("accel_main_m_s2", ACCEL_SIGMA_MAIN), s)
    for te in (t_apogee, t_main):
        if te is not None:
            s = np.where((t >= te - 0.2) & (t <= te + 2.0), ACCEL_SIGMA_OPENING, s)
    if noise is not None:
        s = np.sqrt(s**2 + np.asarray(noise, float) ** 2 / np.asarray(count, float))
    return s


def initial_ca_multiplier(t, f_B, t0: float, v_rel: float, rho: float, meta, clip: bool = True) -> float:
    """The coast drag multiplier at ``t0`` [s] measured from the data: the mean |specific force| (``f_B``
    (n, 3) [m/s²] at ``t`` (n,) [s]) over the first 0.3 s after ``t0`` times the mass over the
    metadata's Cd S and the dynamic pressure ½ ``rho`` ``v_rel``² of the burnout state; clipped to
    CA_CLIP × :func:`ca_scale` (at Cd 0.38: [0.3, 5.5]; flight 1, air brakes stuck open: 4.0; flights 3,
    4: 1.4, 1.0) unless not ``clip`` (the measurement itself, for
    :mod:`workbench.problems.post2.rocket_checks`)."""
    sel = (t >= t0) & (t <= t0 + 0.3)
    if not np.any(sel) or not v_rel > 1.0:
        return 1.0
    a = float(np.mean(np.linalg.norm(f_B[sel], axis=1)))
    den = meta.cd * meta.area * 0.5 * rho * v_rel**2
    if not (np.isfinite(den) and den > 0.0):  # no air at the burnout state (an absurd trajectory)
        return 1.0 if clip else float("nan")
    m = a * meta.mass / den
    k = ca_scale(meta.cd)
    return float(np.clip(m, CA_CLIP[0] * k, CA_CLIP[1] * k)) if clip else float(m)


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(x):.10g}" for x in np.atleast_1d(v)) + "]"


#: 1σ [m] per inertial axis of the landed coordinates as an observation (the landing elevation
#: is not known: taken as the pad's; ±15 m covers the terrain of the three sites' fields)
LANDING_SIGMA = 15.0


def landing_point_inertial(meta, h_pad: float, t_land: float) -> np.ndarray:
    """The landed coordinates as a position (3,) [m] in M at ``t_land`` [s after launch] (pad
    elevation; the Earth turned by ω t_land since launch)."""
    p_e = pad_position(meta.landed_lat_deg, meta.landed_lon_deg, h_pad)
    a = EARTH.rotation_rate * t_land
    c, s_ = math.cos(a), math.sin(a)
    return np.array([c * p_e[0] - s_ * p_e[1], s_ * p_e[0] + c * p_e[1], p_e[2]])


def problem_file(
    name: str,
    meta,
    fl: BoostSolution,
    t0: float,
    t_end: float,
    t_apogee: float,
    t_main,
    landing: bool = False,
    ca0: float = 1.0,
    t_burnout: float | None = None,
    t_touchdown: float | None = None,
    gnss: bool = False,
) -> str:
    """Text of the post2 problem file of a flight's coast and descent (from ``t0`` to ``t_end`` [s
    after launch]): 3-DOF, Earth, the site's standard atmosphere, the rocket as a point mass with
    the metadata's Cd and area, drogue at the apogee letter and main at ``t_main``; states
    position, velocity (from the boost), coast drag multiplier, barometer bias, drogue and main
    drag areas, wind (prior: the site's surface wind); observations pressure and |specific force|;
    with ``landing`` also the landed coordinates (``landing.csv``) — the variant that estimates the
    winds under the parachutes (the IMU and the barometer do not see the horizontal drift).  Its
    ``[launch]`` table (the pad, ``t_burnout`` and ``t_touchdown`` [s after launch, None: unknown])
    makes the run report the rocket results (:mod:`workbench.problems.post2.rocket_results`).  ``gnss``:
    also observe ``gnss.csv`` (fixes east/north/up of the pad, weights ``gnss_weights.csv``)."""
    # the metadata's direction is where the wind comes from; the state is the air's velocity [east,
    # north] (where it goes: v_rel = v − ω×r − wind), hence the minus signs (checked on flights 3 and 4:
    # docs/tuning/post2.md, "the wind prior")
    wf = math.radians(meta.wind_from_deg)
    k_ca = ca_scale(meta.cd)
    w_en = (-meta.wind_speed * math.sin(wf), -meta.wind_speed * math.cos(wf))
    lines = [
        f"# post2 problem file of the flight {meta.name}, written by `workbench import airbrakes`.",
        "# Coast and descent after the boost; the boost was integrated from the IMU (flight.json: burnout).",
        "[scenario]",
        f'name = "{name}"',
        'kind = "post2"',
        f'description = "real rocket flight {meta.name} ({meta.date[:10]}): coast and descent on Earth'
        + (', with the landed coordinates observed (winds)"' if landing else '"'),
        "",
        "[model]",
        "dof = 3",
        f"t_start_s = {t0:.9f}",
        f"t_end_s = {t_end:.9f}",
        "step_s = 0.05",
        "grid_s = 0.1",
        "",
        "[environment]",
        'body = "earth"',
        'atmosphere = "earth_standard"',
        f"sea_level_pressure_pa = {fl.atmosphere.sea_level_pressure:.2f}  # QNH (site_atmosphere)",
        f"sea_level_temperature_K = {fl.atmosphere.sea_level_temperature:.3f}  # site temperature + 6.5 K/km x pad",
        f"# pad altitude {fl.h_pad:.1f} m above the mean sphere (the standby pressure in this atmosphere)",
        f"baro_scale_anchor_m = {fl.h_pad:.3f}  # the baro_scale state stretches the baro altitude about the pad",
        "",
        "[launch]  # the pad: the run reports apogee, speeds, landing point and descent rates in its local frame",
        f"lat_deg = {meta.launch_lat_deg:.10g}",
        f"lon_deg = {meta.launch_lon_deg:.10g}",
        f"pad_altitude_m = {fl.h_pad:.3f}",
        f"heading_trusted = {'true' if fl.pad_info.get('magnetometer_heading_trusted', True) else 'false'}",
        f"heading_sigma_deg = {float(fl.pad_info.get('heading_sigma_deg', 0.0)):.4g}  # the pad heading's 1σ",
    ]
    if t_burnout is not None:
        lines.append(f"burnout_s = {t_burnout:.4f}  # the first coast row")
    if t_touchdown is not None:
        lines.append(f"touchdown_s = {t_touchdown:.9f}  # the first landed row (t_end_s: the digits of the span's end)")
    lines += [
        "",
        "[vehicle]",
        f"mass_kg = {meta.mass}  # metadata dry mass: the coast/descent mass",
        f"ref_area_m2 = {meta.area}",
        f"cd = {meta.cd}",
        "",
        "[events.drogue]",
        'when = "time"',
        f"value = {t_apogee:.4f}  # the ejection shock (detect_ejection)",
        'chute = "drogue"',
    ]
    if t_main is not None:
        lines += ["", "[events.main]", 'when = "time"', f"value = {t_main:.4f}  # detected opening", 'chute = "main"']
    lines += [
        "",
        "[states.position]",
        f"value = {_fmt(fl.p_M)}",
        f"sigma = {_fmt(fl.sigma_p)}",
        "",
        "[states.velocity]",
        f"value = {_fmt(fl.v_M)}",
        f"sigma = {_fmt(fl.sigma_v)}",
        'process = "random_walk"  # unmodelled forces: lift at incidence, gusts, swinging under a parachute',
        "psd = 0.5",
        "",
    ]
    if fl.corr_pv is not None:
        rows = ",\n    ".join(_fmt(r) for r in fl.corr_pv)
        lines += [
            "",
            "# the boost's errors are correlated (the pad heading moves the position and the velocity",
            "# together, across the inertial axes): dropping the correlations would let the barometer",
            "# 'observe' the horizontal drift through the M axes' vertical components",
            "[initial_correlation]",
            'states = ["position", "velocity"]',
            f"matrix = [\n    {rows},\n]",
        ]
    lines += [
        "",
        "[states.ca_multiplier]  # coast drag multiplier (air brakes, mass and Cd errors)",
        f"value = {ca0:.4f}  # measured: the first 0.3 s of coast drag at the burnout state",
        f"sigma = {max(CA_SIGMA_FLOOR * k_ca, 0.25 * ca0):.4f}",
        f"bounds = [{CA_BOUNDS[0] * k_ca:.6g}, {CA_BOUNDS[1] * k_ca:.6g}]",
        "",
        "# the coast drag varies as fast as |f| m / (Cd S q) does along the flights (rocket.CA_PSD, scaled",
        f"# by (0.38 / Cd)^2 = {k_ca**2:.6g}); under the parachutes the body's drag is not separable from the",
        "# chute's: the multiplier is held",
        "[schedules.coast_drag]",
        'state = "ca_multiplier"',
        f"psd = {CA_PSD * k_ca**2:.6g}",
        'end_event = "drogue"',
        "",
        "[states.baro_bias]  # the pad altitude matches the standby pressure: only the in-flight offset",
        "value = 0.0",
        f"sigma = {BARO_BIAS_SIGMA}",
        "",
        "# the barometer's altitude scales with the air column's mean temperature, known only to",
        f"# ±{meta.temperature_sigma:g} K (site temperature, lapse rate, humidity): a consider parameter, carried in",
        "# every σ and never fitted (fitting it stretches the barometer to the IMU's altitude)",
        "[states.baro_scale]",
        "value = 1.0",
        f"sigma = {meta.temperature_sigma / meta.temperature:.6f}  # σ_T / T_site",
        'process = "consider"',
        "",
        "[states.drogue_drag_area]",
        "value = 0.5",
        "sigma = 0.5",
        "bounds = [0.01, 5.0]",
        "",
        "[states.main_drag_area]",
        "value = 8.0",
        "sigma = 8.0",
        "bounds = [0.1, 40.0]",
        "",
        "[states.wind]  # prior: the site's surface wind",
        f"value = {_fmt(w_en)}",
        "sigma = [4.0, 4.0]",
        'process = "random_walk"',
        "psd = [0.05, 0.05]",
        "",
        "[observations.baro]",
        'quantity = "pressure"',
        'file = "pressure.csv"',
        'weights = "pressure_weights.csv"',
        "",
        "[observations.accel]",
        'quantity = "acceleration_magnitude"',
        'file = "accel.csv"',
        'weights = "accel_weights.csv"',
        "gate_probability = 0.9999",
        "",
    ]
    if gnss:
        lines += [
            "[observations.gnss]  # GNSS fixes relative to the pad's own fix (the import's [gnss] mapping)",
            'quantity = "position_pad_enu"',
            'file = "gnss.csv"',
            'weights = "gnss_weights.csv"',
            "gate_probability = 0.9999",
            "",
        ]
    if landing:
        lines += [
            "[observations.landing]  # the landed coordinates at touchdown (metadata, within 1-2 m)",
            'quantity = "position_inertial"',
            'file = "landing.csv"',
            f"sigma = {LANDING_SIGMA}",
            "",
        ]
    return "\n".join(lines)


def run_flight(settings: Post2Settings) -> tuple[object, dict]:
    """Reconstruct an imported flight from the settings of its post2 problem file (the import's
    ``flight.json``, ``imu.csv`` and ``reference.csv`` beside that file) and score it:
    (Post2Result, :func:`score_flight`)."""
    path = settings.run.path
    result = None
    for stage in pipeline.reconstruct(settings, settings.telemetry_files(), None):
        result = stage
    flight = read_json(path.parent / "flight.json")  # written by the importer (generated, not user input)
    imu = read_telemetry(path.parent / "imu.csv")
    ref = read_telemetry(path.parent / "reference.csv")
    return result, score_flight(result, flight, imu, ref)


def score_flight(result, flight: dict, imu, reference) -> dict:
    """Scores of a post2 :class:`~workbench.problems.post2.pipeline.Post2Result` of a flight against
    its references: apogee vs the metadata (m, %), landing point vs the landed coordinates (m, and
    the Mahalanobis distance with the reconstruction's horizontal covariance: inside 3σ when
    d² ≤ χ²₂(0.9973)), altitude vs the flight computer's, the pad-aligned gyro attitude vs the flight
    computer's quaternion (tilt from vertical and attitude change since the pad, deg), and the
    estimated parameters.  ``flight`` the import's ``flight.json``; ``imu``, ``reference`` the
    telemetry of ``imu.csv`` / ``reference.csv``."""
    meta = flight["metadata"]
    h_pad = flight["pad"]["pad_altitude_m"]
    t = result.t
    hist = result.history["smoothed"]
    p = hist["position"]["value"]
    h = altitude_above_pad(p, EARTH.reference_radius, h_pad)
    k = int(np.argmax(h))
    out: dict = {"flight": flight["flight"]}
    # apogee: the altitude of the reconstructed apogee above the pad (rocket_results: the run's summary
    # reports the same number)
    sp = result.smap.blocks["position"].se
    sig_h = float(vertical_sigma(p[k : k + 1], result.P[k : k + 1][:, sp, sp])[0])
    out["apogee"] = {
        "reconstructed_m": float(h[k]),
        "sigma_m": sig_h,
        "t_s": float(t[k]),
        "metadata_m": meta["apogee"],
        "error_m": float(h[k] - meta["apogee"]),
        "error_percent": float(100.0 * (h[k] - meta["apogee"]) / meta["apogee"]),
        "flight_computer_max_m": float(np.max(reference.channel("h"))),
    }
    # the same apogee as a standard-day altimeter reads it (T0 = 288.15 K): the pressure altitude
    atm, _ = site_atmosphere(meta["qnh"], meta["temperature"], flight["pad"]["standby_pressure_pa"])
    std = EarthStandardAtmosphere(meta["qnh"], 288.15)
    p_apo = float(atm.pressure(h[k] + h_pad))
    h_std = float(std.altitude_of_pressure(p_apo) - std.altitude_of_pressure(flight["pad"]["standby_pressure_pa"]))
    out["apogee"]["standard_day_pressure_altitude_m"] = h_std
    out["apogee"]["standard_day_error_m"] = h_std - meta["apogee"]
    # ... and from the pressure the barometer reads there (model + estimated in-flight offset): the
    # metadata's apogee is the flight computer's barometric altitude, so this is the like-for-like one
    if "baro_bias" in hist:
        if "baro_scale" in hist:
            p_apo = float(atm.pressure(h_pad + h[k] * float(hist["baro_scale"]["value"][k, 0])))
        p_read = p_apo + float(hist["baro_bias"]["value"][k, 0])
        pad_p = flight["pad"]["standby_pressure_pa"]
        h_read = float(std.altitude_of_pressure(p_read) - std.altitude_of_pressure(pad_p))
        out["apogee"]["standard_day_barometer_altitude_m"] = h_read
        out["apogee"]["standard_day_barometer_error_m"] = h_read - meta["apogee"]
    # landing point
    lat, lon, P_en = horizontal_covariance(p[-1], float(t[-1]), result.P[-1][sp, sp], EARTH.rotation_rate)
    lat0, lon0 = meta["launch_lat_deg"], meta["launch_lon_deg"]
    ours = local_en(lat, lon, lat0, lon0)
    truth = local_en(meta["landed_lat_deg"], meta["landed_lon_deg"], lat0, lon0)
    err = ours - truth
    d2 = float(err @ np.linalg.solve(P_en, err))
    out["landing"] = {
        "reconstructed_en_m": ours.tolist(),
        "landed_en_m": truth.tolist(),
        "error_m": float(np.linalg.norm(err)),
        "error_en_m": err.tolist(),
        "sigma_en_m": np.sqrt(np.diag(P_en)).tolist(),
        "mahalanobis": math.sqrt(d2),
        "inside_3sigma": bool(d2 <= chi2_ppf(0.9973, 2)),
        "drift_from_pad_reconstructed_m": float(np.linalg.norm(ours)),
        "drift_from_pad_landed_m": float(np.linalg.norm(truth)),
        # the boost's heading comes from the aligned magnetometer only if it passed the dip check;
        # when it did not, the heading is a 60 deg 1σ that a linearised filter cannot carry (a
        # ±110 m/s cross-track velocity on a 104 m/s track changes the speed at second order, which
        # the drag |f| then "observes"), so the 3σ above is too small: the verdict is then the
        # heading pushed through exactly (heading_nonlinear, landing_heading_mixture)
        "heading_trusted": bool(flight["pad"].get("magnetometer_heading_trusted", True)),
        "bearing_reconstructed_deg": float(np.degrees(np.arctan2(ours[0], ours[1]))),
        "bearing_landed_deg": float(np.degrees(np.arctan2(truth[0], truth[1]))),
    }
    if not out["landing"]["heading_trusted"]:  # the verdict from the heading pushed through, not linearised
        wind_en = hist["wind"]["value"] if "wind" in hist else None
        P_nodes, sig_psi = P_en, math.radians(flight["pad"]["heading_sigma_deg"])
        if result.heading_direction is not None:  # P carries the heading: the nodes take P given it
            G, sig_psi = covariance_given_heading(result.P[-1], result.heading_direction)
            P_nodes = horizontal_covariance(p[-1], float(t[-1]), G[sp, sp], EARTH.rotation_rate)[2]
        nl = landing_heading_mixture(ours, P_nodes, t, wind_en, sig_psi)
        rng = np.random.default_rng(LANDING_MIXTURE_SEED)
        level = mixture_hdr_level(truth, *nl[:3], rng, LANDING_MIXTURE_SAMPLES)
        out["landing"]["heading_nonlinear"] = {
            "hdr_level": level,
            # the 2-D Mahalanobis distance a Gaussian would give at that level (χ²₂ quantile)
            "gaussian_equivalent_mahalanobis": math.sqrt(-2.0 * math.log(max(1.0 - level, 1e-12))),
            "inside_3sigma": bool(level <= 0.9973),
            "heading_sigma_deg": math.degrees(sig_psi),
            "turning_drift_m": float(np.linalg.norm(ours - nl[3])),
            "wind_drift_en_m": nl[3].tolist(),
        }
        out["landing"]["mahalanobis_linearised"] = out["landing"]["mahalanobis"]
        out["landing"]["inside_3sigma"] = out["landing"]["heading_nonlinear"]["inside_3sigma"]
    # altitude vs the flight computer's solution: raw (its altitude as logged, ours geometric above the pad)
    href = np.interp(t, reference.time, reference.channel("h"))
    dh = h - href
    late = t >= flight["t_start_s"] - TAIL_OFF_S + BURNOUT_TRANSIENT_S  # the baro is de-weighted before
    out["altitude_vs_flight_computer"] = {
        "rms_m": float(np.sqrt(np.mean(dh**2))),
        "max_abs_m": float(np.max(np.abs(dh))),
        "at_apogee_m": float(dh[k]),
        "rms_after_burnout_transient_m": float(np.sqrt(np.mean(dh[late] ** 2))),
        "max_abs_after_burnout_transient_m": float(np.max(np.abs(dh[late]))),
    }
    out["altitude_vs_flight_computer"].update(_altitude_like_for_like(flight, imu, reference, atm, t, h, hist, k, late))
    # the apogee like for like: ours against the flight computer's highest altitude made geometric above
    # the pad (the metadata's apogee is the flight computer's on flights 1 and 3, 762.28 and 1131.2 m)
    h_fc_apo = out["altitude_vs_flight_computer"]["like_for_like"]["flight_computer_max_geometric_m"]
    out["apogee"]["flight_computer_geometric_m"] = h_fc_apo
    out["apogee"]["error_vs_flight_computer_geometric_m"] = float(h[k] - h_fc_apo)
    out["apogee"]["error_vs_flight_computer_geometric_percent"] = float(100.0 * (h[k] - h_fc_apo) / h_fc_apo)
    out["attitude_vs_flight_computer"] = _attitude_scores(flight, imu, reference)
    # estimated parameters (smoothed, end of the span) and the wind prior
    params = {}
    for name in (
        "ca_multiplier",
        "baro_bias",
        "baro_scale",
        "baro_q_coefficient",
        "drogue_drag_area",
        "main_drag_area",
        "wind",
    ):
        if name in hist:
            params[name] = {
                "value": hist[name]["value"][-1].tolist(),
                "sigma": hist[name]["sigma"][-1].tolist(),
                "prior": result.summary["states"][name]["initial"],
            }
    if "ca_multiplier" in hist:
        coast = t < flight.get("t_ejection_s", flight["t_apogee_letter_s"])
        params["ca_multiplier"]["coast_mean"] = float(np.mean(hist["ca_multiplier"]["value"][coast, 0]))
        params["ca_multiplier"]["coast_min_max"] = [
            float(np.min(hist["ca_multiplier"]["value"][coast, 0])),
            float(np.max(hist["ca_multiplier"]["value"][coast, 0])),
        ]
    if "wind" in hist:
        # the state is the air's velocity [east, north] (where it blows to); the metadata gives where
        # it blows from: both as a compass bearing the wind comes from [deg], with the speed [m/s]
        w_end = np.asarray(hist["wind"]["value"][-1], float)
        params["wind"]["from_deg"] = float(np.degrees(np.arctan2(-w_end[0], -w_end[1])) % 360.0)
        params["wind"]["speed_m_s"] = float(np.hypot(*w_end))
        params["wind"]["metadata_from_deg"] = float(meta["wind_from_deg"])
        params["wind"]["metadata_speed_m_s"] = float(meta["wind_speed"])
    out["parameters"] = params
    out["pad_altitude_m"] = h_pad
    out["observations"] = result.summary["observations"]
    _mark_undefined(out, rocket_checks.undefined_outputs(flight))
    return out


#: the outputs of each key window (rocket_checks.KEY_WINDOWS) that a gap inside it makes undefined
UNDEFINED_OUTPUTS = {
    "coast": ("apogee",),
    "drogue_opening": ("parameters.drogue_drag_area",),
    "main_opening": ("parameters.main_drag_area",),
}


def _mark_undefined(out: dict, undefined: dict) -> None:
    """Replace the numbers of the outputs of each undefined key window ({window: why}) in the scores
    ``out`` by None, with the reason under ``"undefined"``: never a number where the data break."""
    for window, why in undefined.items():
        for key in UNDEFINED_OUTPUTS.get(window, ()):
            node, leaf = out, key
            if "." in key:
                head, leaf = key.split(".", 1)
                node = out.get(head, {})
            if leaf in node and isinstance(node[leaf], dict):
                node[leaf] = {k: None for k in node[leaf]} | {"undefined": why}


#: the FIRM flight computer's altimeter formula (the pressure model of its UKF, ``ukf_functions.c`` of
#: the NCSU FIRM firmware): p = p_ref (1 − h/44330)^5.255876, the standard day's troposphere
#: (288.15 K at h = 0, −6.5 K/km; 44330 ≈ 288.15/0.0065 m) with ``p_ref`` the pressure at h = 0.
#: Which ``p_ref`` a log used is measured, not assumed (:func:`flight_computer_altimeter`; per flight:
#: docs/tuning/post2.md)
FIRM_ALTITUDE_SCALE_M = 44330.0
FIRM_PRESSURE_EXPONENT = 5.255876
#: the standard day's sea-level pressure [Pa]
SEA_LEVEL_PRESSURE_PA = 101325.0


def firm_altitude(p, p_ref: float) -> np.ndarray:
    """The FIRM altimeter's standard-day altitude [m] of the pressure ``p`` [Pa] (any shape) with
    ``p_ref`` [Pa] the pressure at its zero (:data:`FIRM_ALTITUDE_SCALE_M`)."""
    return FIRM_ALTITUDE_SCALE_M * (1.0 - (np.asarray(p, float) / p_ref) ** (1.0 / FIRM_PRESSURE_EXPONENT))


def firm_pressure(h, p_ref: float) -> np.ndarray:
    """Inverse of :func:`firm_altitude`: the pressure [Pa] (shape of ``h``) at the FIRM altimeter's
    standard-day altitude ``h`` [m] with ``p_ref`` [Pa] the pressure at its zero."""
    return p_ref * (1.0 - np.asarray(h, float) / FIRM_ALTITUDE_SCALE_M) ** FIRM_PRESSURE_EXPONENT


#: the flight computer's altimeter is measured against its own barometer from the end of the burnout
#: transient to the end of the span, without the drogue's ejection (−0.2 .. +2 s: the charge
#: pressurises the bay) — the windows :func:`pressure_sigma` does not use either
def _altimeter_window(t, flight: dict) -> np.ndarray:
    """Boolean mask (n,) of the times ``t`` (n,) [s after launch] the altimeter is measured over."""
    t = np.asarray(t, float)
    t_ej = flight.get("t_ejection_s", flight["t_apogee_letter_s"])
    sel = (t >= flight["t_start_s"] - TAIL_OFF_S + BURNOUT_TRANSIENT_S) & (t <= flight["t_end_s"])
    return sel & ~((t >= t_ej - 0.2) & (t <= t_ej + 2.0))


def flight_computer_altimeter(flight: dict, imu, reference) -> dict:
    """What the flight computer's altitude is, measured on its own log (not assumed).

    Its altitude is a standard-day pressure altitude (:func:`firm_altitude`: 15 °C at its zero, −6.5
    K/km) of its barometer, fused with its IMU, h_fc = firm_altitude(p, p_ref) + c. Two references
    occur: its **initial** pressure (c = 0: zero where it was switched on, which is not the pad at
    launch when the weather or the board's warming moved the pressure since) and the standard day's
    **101 325 Pa** (c: minus the altitude of the initial pressure). Each candidate is pinned to the pad
    — its mean altitude over the pad window (the last PAD_WINDOW_S s before ignition − IGNITION_GUARD_S)
    at the standby pressure — and the one closer to the flight computer's altitude over
    :func:`_altimeter_window` (RMS of h_fc minus the formula of the logged pressure) is the flight
    computer's. ``flight`` the import's ``flight.json``, ``imu``/``reference`` the telemetry of
    ``imu.csv``/``reference.csv``.

    Returns a JSON-ready dict: ``reference`` ("initial" or "101325"), ``p_ref_pa`` [Pa],
    ``offset_m`` (c) [m], ``pad_reading_m`` [m] (its altitude on the pad at launch),
    ``rms_vs_own_barometer_m`` {candidate: RMS [m]} and ``samples``."""
    t = np.asarray(reference.time, float)
    h_fc = np.asarray(reference.channel("h"), float)
    p = np.asarray(imu.channel("pressure"), float)
    t_pad_end = flight["pad"]["ignition_t_s"] - IGNITION_GUARD_S
    pad = (t >= t_pad_end - PAD_WINDOW_S) & (t < t_pad_end)
    if not np.any(pad):
        raise ValueError("no flight-computer sample in the pad window: cannot pin its altimeter")
    h_pad = float(np.mean(h_fc[pad]))
    p_pad = float(flight["pad"]["standby_pressure_pa"])
    candidates = {
        "initial": (p_pad / (1.0 - h_pad / FIRM_ALTITUDE_SCALE_M) ** FIRM_PRESSURE_EXPONENT, 0.0),
        "101325": (SEA_LEVEL_PRESSURE_PA, h_pad - float(firm_altitude(p_pad, SEA_LEVEL_PRESSURE_PA))),
    }
    win = _altimeter_window(t, flight)
    rms = {
        name: float(np.sqrt(np.mean((h_fc[win] - firm_altitude(p[win], p_ref) - c) ** 2)))
        for name, (p_ref, c) in candidates.items()
    }
    best = min(rms, key=rms.get)
    p_ref, c = candidates[best]
    return {
        "reference": best,
        "p_ref_pa": float(p_ref),
        "offset_m": float(c),
        "pad_reading_m": h_pad,
        "rms_vs_own_barometer_m": rms,
        "samples": int(np.sum(win)),
    }


def _altitude_like_for_like(flight: dict, imu, reference, atm, t, h, hist, k: int, late) -> dict:
    """The altitude comparisons with the flight computer that compare like with like (keys added to
    ``altitude_vs_flight_computer`` by :func:`score_flight`; ``atm`` the site atmosphere, ``t`` (n,)
    [s], ``h`` (n,) [m] our geometric altitude above the pad, ``hist`` the smoothed history, ``k`` the
    apogee's index, ``late`` (n,) the mask after the burnout transient).

    * ``like_for_like`` — the flight computer's altitude turned into what ours is, a geometric altitude
      above the pad at launch: its formula inverted to the pressure it stands for
      (:func:`flight_computer_altimeter`), that pressure's altitude in the site's atmosphere (the
      reconstruction's own: the site temperature, −6.5 K/km — the hypsometric "true altitude"), minus
      the pad's.  It takes out the two conventions (15 °C vs the day's temperature: 3.5 % of the
      height on the 25 °C days; its zero at switch-on vs the pad at launch: +2.0 and +7.6 m on flights
      3 and 4) and leaves what the two solutions disagree on: the barometer's in-flight error the
      reconstruction estimates (``baro_bias``, the static-port error behind flight 1's open air
      brakes) and the IMU-anchored coast against the barometer, the flight computer's own filter
      (its lag and IMU-driven excursions, the ejection).  It cannot see an error of the site
      atmosphere (temperature, lapse rate): both altitudes go through the same one.
    * ``barometer_scale`` — the other way round: our reconstruction as the flight computer's
      altimeter would read it (the model pressure at our altitude plus the estimated barometer
      offset, through its formula).  Nearly a tautology — the reconstruction fits that same
      barometer, so this compares the barometer with itself: what is left is the flight computer's
      departure from its own barometer (``flight_computer_altimeter`` ``rms_vs_own_barometer_m``) and
      our barometer residuals; it cannot detect an error of our altitude that the barometer fit hides."""
    fc = flight_computer_altimeter(flight, imu, reference)
    h_pad = flight["pad"]["pad_altitude_m"]
    p_ref, c = fc["p_ref_pa"], fc["offset_m"]
    tr = np.asarray(reference.time, float)
    h_fc = np.asarray(reference.channel("h"), float)
    h_fc_geo = atm.altitude_of_pressure(firm_pressure(h_fc - c, p_ref)) - h_pad  # geometric, above the pad
    d = h - np.interp(t, tr, h_fc_geo)
    out = {
        "flight_computer_altimeter": fc,
        "like_for_like": {
            "meaning": "ours minus the flight computer's altitude as a geometric altitude above the pad "
            "(its standard-day formula inverted, the pressure's altitude in the site atmosphere)",
            "rms_m": float(np.sqrt(np.mean(d**2))),
            "rms_after_burnout_transient_m": float(np.sqrt(np.mean(d[late] ** 2))),
            "mean_after_burnout_transient_m": float(np.mean(d[late])),
            "max_abs_after_burnout_transient_m": float(np.max(np.abs(d[late]))),
            "at_apogee_m": float(d[k]),
            "flight_computer_max_geometric_m": float(np.max(h_fc_geo)),
            "scale_at_apogee": float(np.max(h_fc_geo) / (np.max(h_fc) - fc["pad_reading_m"])),
        },
    }
    if "baro_bias" in hist:
        h_b = h * (hist["baro_scale"]["value"][:, 0] if "baro_scale" in hist else 1.0)
        p_read = atm.pressure(h_pad + h_b) + hist["baro_bias"]["value"][:, 0]
        d_b = firm_altitude(p_read, p_ref) + c - np.interp(t, tr, h_fc)
        out["barometer_scale"] = {
            "meaning": "our reconstruction as the flight computer's altimeter reads it (model pressure + "
            "estimated offset) minus its altitude: nearly the barometer against itself",
            "rms_after_burnout_transient_m": float(np.sqrt(np.mean(d_b[late] ** 2))),
            "mean_after_burnout_transient_m": float(np.mean(d_b[late])),
        }
    return out


def _rotation_angle_deg(R: np.ndarray) -> np.ndarray:
    """Rotation angle [deg] (n,) of rotation matrices R (n, 3, 3)."""
    return np.degrees(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)))


def _attitude_scores(flight: dict, imu, reference) -> dict:
    """Gyro attitude from the pad (bias removed) vs the flight computer's quaternion.

    The flight computer's body frame is its own (flights 3 and 4 log a "rotated" acceleration with
    +z along the rocket) and its navigation frame is not documented, so the comparison uses two
    frame-free quantities: the **tilt** of the rocket's long axis from the vertical (ours: the IMU
    axis of the boost's mean specific force, turned by the integrated gyro, against the pad's
    vertical; the flight computer's: its body axis closest to its navigation z on the pad, with
    R(q) read as body -> navigation, z vertical), and the **rotation angle since the pad**
    (the angle of R_pad^T R(t) in each).  Both over boost and coast up to 1 s before the apogee
    letter (the ejection and the tumbling under the drogue saturate the gyro)."""
    t = imu.time
    w = imu.stack(["w.x", "w.y", "w.z"])
    f = imu.stack(["f.x", "f.y", "f.z"])
    w_c = w - np.radians(flight["pad"]["gyro_bias_deg_s"])
    qref = reference.stack(["qx", "qy", "qz", "qw"])
    t_pad_end = flight["pad"]["ignition_t_s"] - IGNITION_GUARD_S
    k0 = int(np.searchsorted(t, t_pad_end)) - 1
    t_ej = flight.get("t_ejection_s", flight["t_apogee_letter_s"])
    k1 = int(np.searchsorted(t, t_ej - 1.0))
    pad = (t > t_pad_end - PAD_WINDOW_S) & (t <= t_pad_end)
    axis = np.asarray(flight["pad"]["rocket_axis_imu"])
    R_rel_ours = quat_to_dcm(quat_history_from_body_rates(t[k0:k1], w_c[k0:k1]))  # R_{B_pad B(t)}
    up_b0 = f[pad].mean(axis=0) / np.linalg.norm(f[pad].mean(axis=0))
    tilt_ours = np.degrees(np.arccos(np.clip((R_rel_ours @ axis) @ up_b0, -1, 1)))
    Rfc = quat_to_dcm(qref[k0:k1])  # read as body -> navigation
    kax = int(np.argmax(np.abs(Rfc[0][2])))
    sgn = float(np.sign(Rfc[0][2, kax]))
    tilt_fc = np.degrees(np.arccos(np.clip(sgn * Rfc[:, 2, kax], -1, 1)))
    ang_fc = _rotation_angle_deg(np.einsum("ji,njk->nik", Rfc[0], Rfc))
    ang_ours = _rotation_angle_deg(R_rel_ours)
    tt = t[k0:k1]
    kb = int(np.searchsorted(tt, flight["t_start_s"]))
    dtilt = tilt_ours - tilt_fc
    dang = ang_ours - ang_fc
    sat = np.any(np.abs(w) >= GYRO_SATURATION, axis=1)
    return {
        "window_s": [float(tt[0]), float(tt[-1])],
        "flight_computer_long_axis": f"{'+' if sgn > 0 else '-'}{'xyz'[kax]} (its body frame)",
        "tilt_deg": {
            "ours_at_burnout": float(tilt_ours[kb]),
            "flight_computer_at_burnout": float(tilt_fc[kb]),
            "ours_end": float(tilt_ours[-1]),
            "flight_computer_end": float(tilt_fc[-1]),
            "difference_rms": float(np.sqrt(np.mean(dtilt**2))),
            "difference_max_abs": float(np.max(np.abs(dtilt))),
        },
        "rotation_since_pad_deg": {
            "ours_end": float(ang_ours[-1]),
            "flight_computer_end": float(ang_fc[-1]),
            "difference_rms": float(np.sqrt(np.mean(dang**2))),
            "difference_max_abs": float(np.max(np.abs(dang))),
        },
        "gyro_saturated_samples": {
            "boost_coast": int(np.sum(sat[(t >= 0) & (t < t_ej)])),
            "descent": int(np.sum(sat[t >= t_ej])),
        },
    }
