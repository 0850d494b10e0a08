"""Physics cross-checks of a drop test: the inputs against what the physics of the rig says.

* :func:`hanging_checks` — while the lander hangs still before the release every accelerometer
  triad reads the gravity reaction, 1 g "up", in the body frame: each triad's mean specific force
  against the other triads and the 3DM ``up`` vector (axis swapped or sign-flipped, dead channel),
  the 3DM against the triads, the 3DM magnetic dip against the declared field, and the gyro rates ≈ 0
  with the scatter of its declared noise (stuck, scaled);
* :func:`contact_geometry_check` — the declared rig geometry (hanging position, lander and airbag
  geometry, ramp) against the first-contact kinematics: where the estimated trajectory puts the
  airbag lobes at the measured onset of the impact (IMU |f| > 2 g), they must just touch the ramp;
* :func:`full_stroke_check` — the stroke's full-stroke verdict (declared geometry) against the
  IMU's rigid impact: a rigid frame striking the ramp shows as a jerk tens of times any bag's;
* :func:`max_stroke_note` — a note, not a check: the max stroke is the distance of a declared body
  vertex no sensor sees, and how far it moves per metre that vertex moves;
* :func:`contact_completeness` — data that end (or break) inside the contact: the contact's outputs
  are then undefined;
* :func:`timing_check` — the declared time shifts of the IMU against the ranging residuals: the lag
  estimated from the range-rate innovations and the line-of-sight acceleration.

Each returns :class:`~workbench.estimation.health.Check` objects whose message names the file,
column or scenario key and the likely cause.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from itertools import permutations, product

import numpy as np

from workbench.core.bodies import G0
from workbench.estimation.health import ERROR, OK, WARNING, Check
from workbench.problems.droptest.telemetry import TOUCH_G

__all__ = [
    "AXIS_ERROR_SIGMAS",
    "ContactCompleteness",
    "contact_completeness",
    "contact_geometry_check",
    "full_stroke_check",
    "RIGID_JERK_G_PER_S",
    "rigid_impact",
    "structural_give",
    "diagnose_axes",
    "LAG_FIT_CHI2",
    "LAG_SIGNIFICANT_Z",
    "LagEstimate",
    "estimate_lag",
    "hanging_checks",
    "lobe_clearance",
    "max_stroke_note",
    "mean_triad_force",
    "measured_impact",
    "measured_touch",
    "timing_checks",
    "VERTEX_KEYS",
]

#: a hanging direction off its reference by more than this many of its own 1σ (and by more than
#: :data:`AXIS_ERROR_DEG`) is an axis error, not noise: ERROR
AXIS_ERROR_SIGMAS = 10.0
#: ... and by more than this angle [deg] (an axis swap or sign flip moves it by tens of degrees)
AXIS_ERROR_DEG = 3.0
#: a hanging direction off by more than this many σ is a WARNING (χ² with 2 dof: P ≈ 4e-5)
AXIS_WARNING_SIGMAS = 4.5


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0.0 else v


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(_unit(a) @ _unit(b), -1.0, 1.0))))


def diagnose_axes(measured: np.ndarray, expected: np.ndarray, max_deg: float) -> str | None:
    """The likely column mistake that turns the ``expected`` direction (3,) into the ``measured``
    one (3,) (any lengths, same frame): the signed axis permutation, other than the identity, that
    maps expected onto measured within ``max_deg`` [deg], as text ("axis y looks sign-flipped",
    "x and z swapped", "x and z swapped, y sign-flipped"); None when none does."""
    best = None
    for perm in permutations(range(3)):
        for signs in product((1.0, -1.0), repeat=3):
            if perm == (0, 1, 2) and signs == (1.0, 1.0, 1.0):
                continue
            cand = np.array([signs[i] * expected[perm[i]] for i in range(3)])
            ang = _angle_deg(measured, cand)
            # the simplest mistake first: fewest swapped axes and flipped signs, then the closest
            changes = sum(perm[i] != i for i in range(3)) + sum(s < 0 for s in signs)
            if ang <= max_deg and (best is None or (changes, ang) < best[0]):
                best = ((changes, ang), perm, signs)
    if best is None:
        return None
    _, perm, signs = best
    axes = "xyz"
    parts = []
    swapped = [(i, perm[i]) for i in range(3) if perm[i] > i]
    if perm != (0, 1, 2):
        if any(perm[perm[i]] != i for i in range(3)):
            parts.append(f"axes {axes} rotated to {''.join(axes[p] for p in perm)}")
        else:
            parts += [f"{axes[i]} and {axes[j]} swapped" for i, j in swapped]
    flips = [axes[i] for i in range(3) if signs[i] < 0]
    if flips:
        parts.append(f"axis {', '.join(flips)} look{'s' if len(flips) == 1 else ''} sign-flipped")
    return ", ".join(parts)


def _hang_mask(time: np.ndarray, t_release: float, shift: float = 0.0) -> np.ndarray:
    return time - shift < t_release


def hanging_checks(tel, settings) -> list[Check]:
    """Sensor axes, signs and units against gravity while the lander hangs still (IMU and 3DM
    samples before the release event) from the telemetry ``tel`` (``DropTelemetry``) of a run with
    ``settings`` (``DropSettings``: declared noises, biases, magnetic field).

    ``units.hanging.<triad>``: the triad's mean specific force direction against the reference (the
    median direction of the other triads, or the 3DM ``up`` with fewer than three triads) and its
    magnitude against 1 g; 1σ of the direction from the declared noise over the samples and the
    declared bias (rad per g).  ``units.hanging.3dm_up``: the 3DM ``up`` vector against the triads'
    consensus (1σ: the declared ``gravity_sigma_deg`` and the triads' σ).
    ``units.hanging.3dm_dip``: the angle between the 3DM ``up`` and ``mag`` vectors against the one
    between SPF up and ``[chamber] magnetic_field_spf`` (a reversed field).  ``units.hanging.gyro``:
    the gyro's mean rate and scatter against its declared bias and noise (stuck, scaled).
    Fewer than 20 hanging IMU samples: nothing is checked."""
    imu, att = tel.imu, tel.attitude
    t_rel = tel.events["release"]
    hang = _hang_mask(imu.time, t_rel)
    n = int(hang.sum())
    if n < 20:
        return []
    fname = str(imu.path)
    acc = settings.accelerometer
    # 1σ [rad] of a hanging triad direction: per-sample noise averaged over n, plus the bias, per g
    s_tri = float(np.hypot(acc.noise_g / np.sqrt(n), acc.bias_g) + np.radians(acc.misalignment_deg))
    means = {}
    for name in tel.triads:
        means[name] = imu.stack([f"{name}.{a}" for a in "xyz"])[hang].mean(0)
    ah = _hang_mask(att.time, t_rel, tel.time_shifts_s.get("attitude_3dm", 0.0))
    up3 = att.stack(["up.x", "up.y", "up.z"])[ah].mean(0) if ah.any() else None
    mag3 = att.stack(["mag.x", "mag.y", "mag.z"])[ah].mean(0) if ah.any() else None
    s_3dm = np.radians(settings.attitude_3dm.gravity_sigma_deg)
    checks: list[Check] = []
    live = {k: v for k, v in means.items() if np.linalg.norm(v) > 0.1 * G0}
    for name, m in means.items():
        cols = ", ".join(f"{name}.{a}" for a in "xyz")
        mag = float(np.linalg.norm(m))
        ratio = mag / G0
        others = [_unit(v) for k, v in live.items() if k != name]
        if len(others) >= 2:
            ref, what = _unit(np.median(others, axis=0)), f"the other {len(others)} triads"
            sig = s_tri * np.sqrt(1.0 + 1.0 / len(others))
        elif up3 is not None:
            ref, what = _unit(up3), "the 3DM 'up' vector"
            sig = float(np.hypot(s_tri, s_3dm))
        else:
            continue
        cname = f"units.hanging.{name}"
        if ratio < 0.1:
            dead = "all zeros: a dead channel or unconnected triad" if mag == 0.0 else f"{ratio:.3g} g: a dead channel?"
            checks.append(
                Check(
                    cname,
                    ERROR,
                    _g(ratio),
                    [0.7, 1.3],
                    f"triad {name} reads {dead} while hanging ({fname}, "
                    f"columns {cols}); expected 1 g of gravity reaction",
                )
            )
            continue
        ang = _angle_deg(m, ref)
        z = float(np.radians(ang) / sig)
        exp_txt = ", ".join(f"{x:+.2f}" for x in ref * G0)
        got_txt = ", ".join(f"{x:+.2f}" for x in m)
        base = (
            f"triad {name} while hanging: specific force ({got_txt}) m/s², {ratio:.3f} g, {ang:.2f}° from {what} "
            f"({exp_txt}) = {z:.1f}σ"
        )
        if ang > AXIS_ERROR_DEG and z > AXIS_ERROR_SIGMAS:
            why = diagnose_axes(m, ref, max(3.0, 5.0 * np.degrees(sig)))
            cause = f"{why} ({fname}, columns {cols})" if why else f"wrong axes or mounting ({fname}, columns {cols})"
            checks.append(Check(cname, ERROR, _g(z), AXIS_ERROR_SIGMAS, f"{base}: {cause}", {"kind": "upper"}))
        elif abs(np.log(ratio)) > np.log(1.3):
            checks.append(
                Check(
                    cname,
                    WARNING,
                    _g(z),
                    AXIS_WARNING_SIGMAS,
                    f"{base}: magnitude {ratio:.3g} g, expected 1 g (scale of {cols} in {fname}?)",
                    {"kind": "upper"},
                )
            )
        elif z > AXIS_WARNING_SIGMAS:
            checks.append(Check(cname, WARNING, _g(z), AXIS_WARNING_SIGMAS, f"{base}: misaligned?", {"kind": "upper"}))
        else:
            checks.append(Check(cname, OK, _g(z), AXIS_WARNING_SIGMAS, base, {"kind": "upper"}))
    if up3 is not None and len(live) >= 2:
        ref = _unit(np.median([_unit(v) for v in live.values()], axis=0))
        sig = float(np.hypot(s_3dm, s_tri / np.sqrt(len(live))))
        ang = _angle_deg(up3, ref)
        z = float(np.radians(ang) / sig)
        base = (
            f"3DM 'up' while hanging ({', '.join(f'{x:+.3f}' for x in _unit(up3))}) is {ang:.2f}° from the "
            f"{len(live)} triads' gravity reaction ({', '.join(f'{x:+.3f}' for x in ref)}) = {z:.1f}σ"
        )
        if ang > AXIS_ERROR_DEG and z > AXIS_ERROR_SIGMAS:
            if _angle_deg(-up3, ref) < 3.0 * np.degrees(sig) + 1.0:
                why = "the 'up' vector looks reversed (specific force, not gravity: flip the sign of up.x..z)"
            elif mag3 is not None and _angle_deg(mag3, ref) < 5.0 * np.degrees(sig) + 2.0:
                why = "the 'up' and 'mag' vectors look swapped (columns up.* and mag.*)"
            else:
                why = diagnose_axes(up3, ref, max(3.0, 5.0 * np.degrees(sig))) or "wrong axes or mounting of the 3DM"
            checks.append(
                Check(
                    "units.hanging.3dm_up",
                    ERROR,
                    _g(z),
                    AXIS_ERROR_SIGMAS,
                    f"{base}: {why} ({att.path})",
                    {"kind": "upper"},
                )
            )
        else:
            st = WARNING if z > AXIS_WARNING_SIGMAS else OK
            checks.append(Check("units.hanging.3dm_up", st, _g(z), AXIS_WARNING_SIGMAS, base, {"kind": "upper"}))
    # the dip against the triads' gravity reaction when there are triads (a wrong 3DM 'up' is judged above)
    up_ref = _unit(np.median([_unit(v) for v in live.values()], axis=0)) if len(live) >= 2 else up3
    if up_ref is not None and mag3 is not None and np.linalg.norm(mag3) > 0 and np.linalg.norm(up_ref) > 0:
        field = np.asarray(settings.chamber.magnetic_field_spf, float)
        dip_decl = _angle_deg(np.array([0.0, 0.0, 1.0]), field)
        dip_meas = _angle_deg(up_ref, mag3)
        sig_deg = float(np.hypot(settings.attitude_3dm.magnetic_sigma_deg, settings.attitude_3dm.gravity_sigma_deg))
        d = dip_meas - dip_decl
        z = abs(d) / max(sig_deg, 1e-6)
        base = (
            f"angle between gravity-up (the triads' hanging specific force) and the 3DM 'mag' vector "
            f"{dip_meas:.1f}°, the declared field "
            f"[chamber] magnetic_field_spf makes {dip_decl:.1f}° with SPF up ({z:.1f}σ)"
        )
        if abs(d) > 5.0 and z > AXIS_ERROR_SIGMAS:
            rev = abs(dip_meas - (180.0 - dip_decl)) < 5.0 + 3.0 * sig_deg
            why = (
                "the magnetic field looks reversed: the sign of mag.x..z in "
                f"{att.path} or of [chamber] magnetic_field_spf in {settings.path}"
                if rev
                else f"check [chamber] magnetic_field_spf in {settings.path} and the mag.* columns of {att.path}"
            )
            if any(c.name == "units.hanging.3dm_up" and c.status == ERROR for c in checks):
                why += " (the 3DM 'up' vector is wrong too: fix its columns first)"
            checks.append(
                Check("units.hanging.3dm_dip", ERROR, _g(d), [-5.0, 5.0], f"{base}: {why}", {"kind": "two_sided"})
            )
        else:
            st = WARNING if z > AXIS_WARNING_SIGMAS else OK
            checks.append(Check("units.hanging.3dm_dip", st, _g(d), [-5.0, 5.0], base, {"kind": "two_sided"}))
    checks += _gyro_hanging(tel, settings, hang)
    return checks


def _gyro_hanging(tel, settings, hang: np.ndarray) -> list[Check]:
    """``units.hanging.gyro``: stuck (no scatter at all, or constant over the whole record), scaled
    (scatter off the declared noise by more than 3×) or reading a rate while hanging (mean beyond
    5σ of the declared bias and the noise averaged over the samples)."""
    imu = tel.imu
    gy = settings.gyro
    cols = [f"gyro.{a}" for a in "xyz"]
    w = imu.stack(cols)
    wh = w[hang]
    n = wh.shape[0]
    mean = np.degrees(wh.mean(0))
    sd = np.degrees(wh.std(0))
    whole = np.ptp(w, axis=0)
    fname = str(imu.path)
    stuck = [c for c, s, p in zip(cols, sd, whole, strict=True) if p == 0.0 or (gy.noise_dps > 0 and s == 0.0)]
    s_mean = float(np.hypot(gy.bias_dps, gy.noise_dps / np.sqrt(n)))
    z = float(np.max(np.abs(mean)) / max(s_mean, 1e-12))
    ratio = float(np.sqrt(np.mean(sd**2)) / gy.noise_dps) if gy.noise_dps > 0 else float("nan")
    base = (
        f"gyro while hanging: mean ({', '.join(f'{x:+.3f}' for x in mean)}) deg/s ({z:.1f}σ of the declared bias "
        f"and noise), scatter {ratio:.2f}× the declared noise_dps"
    )
    if stuck:
        return [
            Check(
                "units.hanging.gyro",
                ERROR,
                _g(z),
                5.0,
                f"{base}: channel(s) {', '.join(stuck)} constant (stuck or dead) in {fname}",
            )
        ]
    if z > 10.0 and np.max(np.abs(mean)) > 1.0:
        return [
            Check(
                "units.hanging.gyro",
                ERROR,
                _g(z),
                5.0,
                f"{base}: the gyro reads a rate while the lander hangs still — a stuck, offset or mislabelled "
                f"channel in {fname}",
                {"kind": "upper"},
            )
        ]
    if z > 5.0 or (np.isfinite(ratio) and abs(np.log(ratio)) > np.log(3.0)):
        return [
            Check(
                "units.hanging.gyro",
                WARNING,
                _g(z),
                5.0,
                f"{base}: a bias beyond [sensors.gyro] bias_dps, or a scale/noise off its declaration ({fname})",
                {"kind": "upper"},
            )
        ]
    return [Check("units.hanging.gyro", OK, _g(z), 5.0, base, {"kind": "upper"})]


def _g(x: float) -> float:
    return float(f"{float(x):.6g}")


# ---------------------------------------------------------------------------------------------
# the impact in the data
# ---------------------------------------------------------------------------------------------


def mean_triad_force(tel) -> tuple[np.ndarray, np.ndarray]:
    """(time [s] on the IMU's own tags, mean specific force over the triads [m/s², body] (n, 3))
    of the raw IMU samples of ``tel``."""
    imu = tel.imu
    f = np.stack([imu.stack([f"{n}.{a}" for a in "xyz"]) for n in tel.triads], axis=1)
    return imu.time, np.mean(f, axis=1)


def measured_impact(tel, threshold_g: float = 2.0, merge_s: float = 0.01) -> tuple[float, float, bool] | None:
    """The first measured impact after the release (or bungee cut): where the norm of the mean
    triad specific force of the raw IMU samples exceeds ``threshold_g`` [g], dips shorter than
    ``merge_s`` [s] bridged.  Returns ``(t_start, t_end, at_data_end)`` [s, on the filter's time
    line: the IMU tags less ``tel.group_delay_s``], ``at_data_end`` True when the impact still lasts
    at the last sample (the file ends inside it); None when there is no such sample."""
    imu = tel.imu
    start = max(tel.events.get("release", -np.inf), tel.events.get("bungee_cut", -np.inf))
    fm = np.linalg.norm(mean_triad_force(tel)[1], axis=1)
    hard = np.flatnonzero((imu.time >= start) & (fm > threshold_g * G0))
    if not hard.size:
        return None
    i0 = i1 = int(hard[0])
    for j in hard[1:]:
        if imu.time[j] - imu.time[i1] > merge_s:
            break
        i1 = int(j)
    dt = float(np.median(np.diff(imu.time)))
    at_end = imu.time[-1] - imu.time[i1] <= 2.5 * dt
    d = tel.group_delay_s
    return float(imu.time[i0] - d), float(imu.time[i1] - d), bool(at_end)


def structural_give(smo, tel, lander) -> tuple[float, float] | None:
    """How deep [m] a vertex of the rigid lander can reach into the surface under the peak load:
    ``(m·|a|max / k, |a|max [g])``, ``|a|max`` the largest estimated non-gravitational acceleration
    of the CM (the smoothed ``FilterStage`` ``smo``; the triads read it with their lever arms, which a
    vertex strike's angular acceleration moves by tens of g) after the release (or bungee cut) of the
    telemetry ``tel``, m the lander's mass, k its declared contact stiffness
    (``[lander] contact_stiffness_n_per_m``: structure and ramp compliance).  None without a step
    after the release."""
    from workbench.problems.droptest import model as rl

    start = max(tel.events.get("release", -np.inf), tel.events.get("bungee_cut", -np.inf))
    a = np.linalg.norm(smo.x[smo.t >= start][:, rl.SA], axis=1)
    a = a[np.isfinite(a)]
    if not a.size:
        return None
    peak = float(a.max())
    return float(lander.mass) * peak / float(lander.contact_stiffness), peak / G0


@dataclass(frozen=True)
class ContactCompleteness:
    """Whether the data cover the contact: ``complete`` False when the IMU file ends (or breaks)
    inside the measured impact (``t_data_end`` [s], the last IMU tag on the filter's time line);
    ``max_stroke_defined`` False when, in addition, the lander still moves toward the ramp at the
    data end (the stroke had not reached its maximum) or the break comes before the max stroke;
    ``reason`` one line naming the file and the time."""

    complete: bool
    max_stroke_defined: bool
    t_data_end: float
    reason: str


#: the lander asset's keys that set the clearance, for either layout (MER or vertices) and either
#: airbag description (rack or explicit lobes): named where the data contradict the geometry
GEOMETRY_KEYS = "height_m, cm_height_m or vertices_m, cm_m; lobe_diameter_m, standoff_m or lobe_centers_m"
#: the data must go on this long [s] after the estimated contact ends for the contact to be complete
#: (two of the 10 ms windows over which the contact detection bridges dips)
CONTACT_TAIL_S = 0.02


def contact_completeness(
    tel,
    smo_t: np.ndarray,
    smo_v: np.ndarray,
    normal: np.ndarray,
    t_max_stroke: float = np.inf,
    t_contact_end: float | None = None,
    stroke_rise: float = np.inf,
) -> ContactCompleteness:
    """:class:`ContactCompleteness` of the telemetry ``tel`` against the smoothed CM velocity
    ``smo_v`` (n, 3) [m/s, SPF] at ``smo_t`` (n,) [s] and the ramp's unit ``normal`` (3,): an IMU
    gap across the measured impact, up to ``t_contact_end`` when that is later (then the max
    stroke is undefined too when the gap starts before ``t_max_stroke`` [s], the estimated
    max-stroke time), or the IMU file ending inside the contact:
    less than :data:`CONTACT_TAIL_S` after ``t_contact_end`` [s] (the end of the contact the
    restitution is defined over; None: none detected, then the measured impact still lasting at
    the last sample).  A file ending inside the contact leaves the max stroke defined only when
    the lander already moves away from the ramp, ``stroke_rise`` (the smoothed stroke at the data
    end above its minimum, in units of its 1σ there) exceeds 1 and the measured impact (> 2 g) is
    over at the last sample."""
    t_end = float(tel.imu.time[-1] - tel.group_delay_s)
    imp = measured_impact(tel)
    if imp is not None:
        d = tel.group_delay_s
        pad = 2.0 * float(np.median(np.diff(tel.imu.time)))
        # the impact as the restitution reads it lasts to the contact's end (a last push off)
        imp_end = max(imp[1], t_contact_end) if t_contact_end is not None else imp[1]
        for g in tel.imu.gaps:
            a, b = g.start_s - d, g.end_s - d
            if a < imp_end + pad and b > imp[0] - pad:
                reason = (
                    f"the IMU data ({tel.imu.path}) break inside the impact: a {b - a:.3g} s gap {a:.4f}–{b:.4f} s "
                    f"(row {g.row}) across the measured impact {imp[0]:.4f}–{imp_end:.4f} s"
                )
                return ContactCompleteness(False, a > t_max_stroke, t_end, reason)
    if t_contact_end is not None:
        ends_inside = t_end - t_contact_end < CONTACT_TAIL_S
    else:
        ends_inside = imp is not None and imp[2]
    if imp is None or not ends_inside:
        return ContactCompleteness(True, True, t_end, "")
    vn_end = float(smo_v[-1] @ normal)
    # moving away, the stroke past its minimum, and the bags unloading (the measured impact over): a
    # lander still pressed at > 2 g at the data end can roll onto another face and compress again
    reached = vn_end > 0.0 and stroke_rise > 1.0 and not imp[2]
    reason = (
        f"the IMU data ({tel.imu.path}) end at t = {t_end:.4f} s inside the contact (impact measured from "
        f"{imp[0]:.4f} s, the estimated contact still on at the data end; a truncated file?)"
    )
    return ContactCompleteness(False, reached, t_end, reason)


# ---------------------------------------------------------------------------------------------
# rig geometry against the first contact
# ---------------------------------------------------------------------------------------------


def lobe_clearance(p: np.ndarray, q: np.ndarray, lander, surface) -> np.ndarray:
    """Smallest clearance [m] of the airbag lobes (spheres) from the ramp for CM positions ``p``
    (n, 3) [m, SPF] and attitudes ``q`` (n, 4) (q_SPF_B); negative: the lobes are pressed in."""
    from workbench.core.rotation import quat_rotate

    c_B = np.asarray(lander.lobe_centers_B, float)
    n, m = p.shape[0], c_B.shape[0]
    qq = np.repeat(q, m, axis=0)
    cc = np.tile(c_B, (n, 1))
    c_I = np.repeat(p, m, axis=0) + quat_rotate(qq, cc)
    d = surface.distance(c_I)[0].reshape(n, m) - float(lander.lobe_radius)
    return d.min(axis=1)


def _lobe_clearance_sigma(x: np.ndarray, P: np.ndarray, lander, surface) -> float:
    """1σ [m] of the closest lobe's clearance from the ramp for the state ``x`` (N_X,) and its error
    covariance ``P`` (N_E, N_E), linearised: d = n·(p + R c_B) − r, so J = [nᵀ, −nᵀ R [c_B×]] on
    the pose error [δp (SPF), δθ (body)]."""
    from workbench.core.rotation import quat_rotate, quat_to_dcm, skew
    from workbench.problems.droptest import model as rl

    c_B = np.asarray(lander.lobe_centers_B, float)
    q = np.repeat(x[rl.SQ][None], c_B.shape[0], axis=0)
    d = surface.distance(x[rl.SP] + quat_rotate(q, c_B))[0]
    j = int(np.argmin(d))
    n = surface.distance((x[rl.SP] + quat_rotate(q[:1], c_B[j : j + 1]))[0])[1]
    R = quat_to_dcm(x[rl.SQ])
    J = np.concatenate([n, -n @ R @ skew(c_B[j])])
    return float(np.sqrt(max(J @ rl.pose_covariance(P) @ J, 0.0)))


def measured_touch(tel, onset: float, threshold_g: float = TOUCH_G) -> float | None:
    """The measured first touch of the bags before the impact whose 2 g onset is ``onset`` [s, on
    the filter's time line] (:func:`measured_impact`): the last raw IMU sample before the onset, after
    the release or bungee cut, where the mean triad specific force is at most ``threshold_g`` [g]
    (the lander still in free fall), its time on the filter's time line (IMU tags less
    ``tel.group_delay_s``).  Scanning back from the onset, noise spikes earlier in the fall do not
    matter.  None when no such sample exists (the bungee still pulling at the contact, a gap)."""
    t, f = mean_triad_force(tel)
    d = tel.group_delay_s
    start = max(tel.events.get("release", -np.inf), tel.events.get("bungee_cut", -np.inf))
    fm = np.linalg.norm(f, axis=1) / G0
    quiet = np.flatnonzero((t >= start) & (t - d < onset) & (fm <= threshold_g))
    if not quiet.size:
        return None
    k = int(quiet[-1])
    # the rise from the touch to the onset is one stretch of data (no gap across it)
    on = int(np.searchsorted(t - d, onset))
    if on - k > 1 and np.max(np.diff(t[k : on + 1])) > 2.5 * float(np.median(np.diff(t))):
        return None
    return float(t[k] - d)


def _touch_radius(x: np.ndarray, lander, surface, within: float) -> tuple[float, str]:
    """The effective radius [m] of the contact a lobe makes first, for the state ``x`` (N_X,): the
    lobe radius R on the ramp plane, ``R r / (R + r)`` on a rock of radius r (its footprint grows
    that much slower with the penetration, so a force presses it in that much further); the
    smallest over the lobes whose clearance is at most ``within`` [m] (the closest, and those the
    pose's uncertainty cannot tell from it), with a phrase naming the rock when it is one."""
    from workbench.core.rotation import quat_rotate
    from workbench.problems.droptest import model as rl

    c_B = np.asarray(lander.lobe_centers_B, float)
    R = float(lander.lobe_radius)
    q = np.repeat(x[rl.SQ][None], c_B.shape[0], axis=0)
    d, _, feature = surface.distance(x[rl.SP] + quat_rotate(q, c_B))
    best, on = R, ""
    for j in np.flatnonzero(d - R <= within):
        f = int(feature[j])
        if f >= 0:
            r = float(surface.rock_radii[f])
            r_e = R * r / (R + r)
            if r_e < best:
                best, on = r_e, f" (a lobe on rock {f}, radius {r:.2f} m: effective radius {r_e:.3f} m)"
    return best, on


def contact_geometry_check(tel, smo, st, settings) -> Check | None:
    """``geometry.first_contact``: the airbag lobes of the declared geometry, placed by the smoothed
    pose ``smo`` (``FilterStage``) at the measured first touch of the bags (:func:`measured_touch`:
    the last free-fall sample, mean triad |f| ≤ :data:`TOUCH_G`, before the impact's 2 g onset of
    :func:`measured_impact`), must just touch the ramp: clearance in [−δ − |v_n| Δt − 3σ,
    +|v_n| Δt + 3σ], δ the penetration at which one lobe's gas overpressure alone carries the
    threshold force (m·g_thr / (Δp·2π r), the declared pressures, mass and lobe radius r — on a rock
    the contact's effective radius, :func:`_touch_radius`; the lobe
    radius when the asset declares no bag pressures, as user data may), |v_n| Δt how far the lobes
    move along the ramp normal in one IMU sample (the touch is known to a sample), σ the
    clearance's 1σ from the pose covariance there.  At the first touch one lobe carries the force,
    whatever the impact; by the 2 g onset several lobes may press in at once (a vertex first: three
    bags' corner lobes) and their shared footprint makes the depth there depend on the attitude.
    Without a free-fall sample before the onset (the bungee still pulling at the contact) the
    clearance is judged at the 2 g onset with δ for 2 g.  Outside: ERROR naming the keys that set
    the geometry (the clearance moves the stroke with it).  The truth-MC calibration re-judges the
    clearance in one band per sensor configuration (its stat's ``pool``:
    ``geometry.first_contact.ranging`` / ``.imu_only``).  None when no impact is measured."""
    imp = measured_impact(tel)
    if imp is None:
        return None
    from workbench.problems.droptest import model as rl

    lander, surface = st.lander, st.surface
    t_touch = measured_touch(tel, imp[0])
    g_thr = 2.0 if t_touch is None else TOUCH_G
    t_on = imp[0] if t_touch is None else t_touch
    k = int(np.clip(np.searchsorted(smo.t, t_on), 0, smo.t.size - 1))
    clear = lobe_clearance(smo.x[:, rl.SP], smo.x[:, rl.SQ], lander, surface)
    c = float(clear[k])
    sig = _lobe_clearance_sigma(smo.x[k], smo.P[k], lander, surface)
    step = abs(float(smo.x[k, rl.SV] @ surface.normal)) * float(np.median(np.diff(tel.imu.time)))
    if lander.pressure_pa is None or lander.ambient_pressure_pa is None:
        # user data without the bag pressures: how far the force presses the lobes in is unknown
        delta = float(lander.lobe_radius)
        pressed = f"the bag pressures not declared, up to a lobe radius ({delta:.3f} m) pressed in"
    else:
        dp = max(float(lander.pressure_pa - lander.ambient_pressure_pa), 1.0)
        r_e, on = _touch_radius(smo.x[k], lander, surface, c + 2.0 * (3.0 * sig + step))
        delta = lander.mass * g_thr * G0 / (dp * 2.0 * np.pi * r_e)
        pressed = f"at most {delta:.3f} m pressed in at {g_thr:g} g{on}"
    lo, hi = -delta - step - 3.0 * sig, step + 3.0 * sig
    after = max(tel.events.get("release", -np.inf), tel.events.get("bungee_cut", -np.inf))
    touch = np.flatnonzero((clear <= 0.0) & (smo.t >= after))
    t_touch_est = f"{smo.t[touch[0]]:.4f} s" if touch.size else "never"
    when = (
        f"the measured first touch (t = {t_on:.4f} s, the last mean triad |f| ≤ {TOUCH_G:g} g before the 2 g "
        f"onset at {imp[0]:.4f} s)"
        if t_touch is not None
        else f"the measured onset of the impact (t = {t_on:.4f} s, mean triad |f| > 2 g; no free-fall sample before it)"
    )
    base = (
        f"airbag lobes {c:+.3f} ± {sig:.3f} m (1σ) from the ramp at {when}; {pressed}, ± {step:.3f} m in one IMU "
        f"sample; the estimated lobes touch the ramp at {t_touch_est}"
    )
    # one honest band per sensor configuration: with ranging the pose at the impact is known ~30× better
    config = "ranging" if getattr(tel, "ranging", None) is not None else "imu_only"
    stat = {"kind": "two_sided", "pool": f"geometry.first_contact.{config}"}
    if lo <= c <= hi:
        # the keys that set the clearance: said here too, for the calibrated band's WARNING/ERROR
        keys = (
            f"the setup file's [hanging] position_m, the lander geometry in {settings.lander_file} "
            f"({GEOMETRY_KEYS}), [chamber] ramp_angle_deg / nail_depth_m (or ramp_point_m) in {settings.path}"
        )
        msg = f"{base}; a clearance outside the honest band moves the stroke with it — likely: {keys}"
        return Check("geometry.first_contact", OK, _g(c), [_g(lo), _g(hi)], msg, stat)
    ang = float(settings.chamber.ramp_angle_deg)
    keys = []
    if ang < 0.5 * np.pi + 0.05:
        keys.append(f"[chamber] ramp_angle_deg = {ang:g} looks like radians ({np.degrees(ang):.1f}°)")
    side = "clear of the ramp" if c > hi else "pressed into the ramp"
    shift = c - (hi if c > hi else lo)
    keys += [
        f"the setup file's [hanging] position_m (off by ≈ {abs(shift):.3f} m along the ramp normal?)",
        f"the lander geometry in {settings.lander_file} ({GEOMETRY_KEYS})",
        f"[chamber] ramp_angle_deg / nail_depth_m (or ramp_point_m) in {settings.path}",
    ]
    return Check(
        "geometry.first_contact",
        ERROR,
        _g(c),
        [_g(lo), _g(hi)],
        f"{base}: the declared geometry puts the bags {side} when the IMU feels the impact — the stroke is off by "
        f"as much; likely: {'; '.join(keys)}",
        stat,
    )


# ---------------------------------------------------------------------------------------------
# the geometry's full-stroke verdict against the IMU's rigid impact
# ---------------------------------------------------------------------------------------------


#: a mean-triad jerk above this [g/s] is the rigid lander striking the surface, not the bags: gas
#: bags load over tens of ms, a rigid frame over a few ms (the two ranges over the truth Monte Carlo:
#: docs/RESULTS.md, "Drop test: full stroke against the IMU")
RIGID_JERK_G_PER_S = 10_000.0
#: ... and above this many times the 99th percentile of the jerk while the lander hangs (noise floor)
RIGID_JERK_NOISE_FACTOR = 10.0


def rigid_impact(tel) -> tuple[float, float, float, float] | None:
    """The sharpest change of the measured specific force after the first impact starts: ``(jerk
    [g/s], t [s] on the filter's time line, threshold [g/s], peak |f| [g] within 10 ms)`` — jerk
    the largest |Δf̄|/Δt of the mean triad specific force f̄ between consecutive IMU samples (no
    differences across gaps), threshold the larger of :data:`RIGID_JERK_G_PER_S` and
    :data:`RIGID_JERK_NOISE_FACTOR` × the 99th percentile of the jerk while hanging (noise).
    None without a measured impact."""
    imp = measured_impact(tel)
    if imp is None:
        return None
    t, f = mean_triad_force(tel)
    dt = np.diff(t)
    ok = (dt > 0) & (dt <= 2.5 * float(np.median(dt))) & np.all(np.isfinite(f[1:] - f[:-1]), axis=1)
    jerk = np.where(ok, np.linalg.norm(np.diff(f, axis=0), axis=1) / np.where(ok, dt, 1.0) / G0, 0.0)
    d = tel.group_delay_s
    after = t[1:] - d >= imp[0] - 0.005
    if not after.any():
        return None
    hang = ok & _hang_mask(t[1:], tel.events.get("release", -np.inf))
    floor = float(np.percentile(jerk[hang], 99)) if hang.sum() >= 20 else 0.0
    thr = max(RIGID_JERK_G_PER_S, RIGID_JERK_NOISE_FACTOR * floor)
    k = int(np.argmax(np.where(after, jerk, -1.0)))
    near = np.abs(t - t[k + 1]) <= 0.01
    peak = float(np.max(np.linalg.norm(f[near], axis=1))) / G0
    return float(jerk[k]), float(t[k + 1] - d), thr, peak


def full_stroke_check(tel, st, settings, smo=None) -> Check | None:
    """``geometry.full_stroke``: the stroke's full-stroke verdict (the declared lander geometry at
    the estimated pose, ``st`` a ``StrokeStage`` with lengths in m) against the IMU's own evidence
    of a rigid impact (:func:`rigid_impact`): a rigid frame striking the ramp shows as a jerk tens
    of times any gas bag's.  ERROR when the IMU shows a rigid impact but the geometry keeps the
    lander more than 3σ clear, or the geometry puts the lander through the surface without one by
    more than 3σ and the depth the structure gives under the estimated peak load
    (:func:`structural_give` from the smoothed ``smo``, none without it: a vertex that grazes the
    ramp loads it too gently for a rigid jerk, but cannot reach deeper); WARNING when it puts the
    lander through the surface by more than 2σ and that depth and the IMU shows no rigid impact (an
    honest near miss, the truth's stroke ≥ 0, gets there with a probability ≤ 2.3 %).  The stroke
    rests on the declared geometry (``height_m``,
    ``cm_height_m``, ...) that no sensor sees; this is the one place the data can contradict it.
    None without a measured impact or a max stroke."""
    ms = getattr(st, "max", None)
    rig = rigid_impact(tel)
    if ms is None or rig is None or not np.isfinite(ms.distance):
        return None
    jerk, t_j, thr, peak = rig
    d, s = float(ms.distance), float(ms.sigma)
    rigid = jerk > thr
    imu_says = (
        f"the IMU's sharpest jerk {jerk:.3g} g/s at t = {t_j:.4f} s (peak |f| {peak:.1f} g; a rigid impact "
        f"> {thr:.3g} g/s)"
    )
    geo_says = f"the declared geometry's max stroke {d:+.3f} ± {s:.3f} m (1σ) at t = {ms.time:.4f} s"
    keys = (
        f"the lander geometry in {settings.lander_file} (height_m, cm_height_m, base_side_m or vertices_m) or the "
        f"setup file's [hanging] position_m"
    )
    if rigid and d - 3.0 * s > 0.0:
        return Check(
            "geometry.full_stroke",
            ERROR,
            _g(jerk),
            _g(thr),
            f"{imu_says} is the rigid lander striking the surface, but {geo_says} keeps it clear by more than 3σ: "
            f"the declared geometry places the lander's body too far inside its bags; likely: {keys}",
        )
    give = None if smo is None else structural_give(smo, tel, st.lander)
    depth = 0.0 if give is None else give[0]
    if not rigid and d + 3.0 * s < -depth:
        return Check(
            "geometry.full_stroke",
            ERROR,
            _g(jerk),
            _g(thr),
            f"{geo_says} puts the rigid lander through the surface (FULL STROKE) by more than 3σ and the "
            f"{depth:.4f} m the structure gives under the measured peak load, but {imu_says} shows no rigid "
            f"impact: the declared geometry places the body too far out of its bags; likely: {keys}",
        )
    if not rigid and d + 2.0 * s < -depth:
        return Check(
            "geometry.full_stroke",
            WARNING,
            _g(jerk),
            _g(thr),
            f"{geo_says} puts the rigid lander through the surface by more than 2σ and the {depth:.4f} m the "
            f"structure gives, but {imu_says} shows no rigid impact: either the frame met the surface too gently "
            f"for a rigid jerk or the stroke is off by as much; check {keys}",
        )
    if rigid:
        verdict = f"full stroke corroborated: {imu_says}; {geo_says}"
    elif d - 3.0 * s <= 0.0:
        verdict = f"{geo_says} leaves a full stroke within 3σ; {imu_says} shows no rigid impact: no full stroke"
    else:
        verdict = f"no full stroke: {geo_says}; {imu_says} shows no rigid impact either"
    return Check("geometry.full_stroke", OK, _g(jerk), _g(thr), verdict)


#: the lander asset's keys that place the body's vertices (the max stroke's closest point)
VERTEX_KEYS = "height_m, cm_height_m, base_side_m or vertices_m, cm_m"


def max_stroke_note(smo, st, settings) -> str | None:
    """The health note on what the max stroke rests on: the distance [m] of one vertex of the
    declared body (``st.max.vertex``; 3 the apex, 0–2 the base) from the surface, a point no sensor
    sees inside the bags, so its 1σ covers the estimated pose only.  With the stroke's gradient
    with respect to that vertex's position in the body frame at the max stroke, ``∇ = Rᵀ ∂d/∂p``
    (R = the smoothed attitude q_SPF_B of ``smo`` at ``st.max.index``, ``∂d/∂p`` the surface
    gradient of ``st.smoothed.jacobian``): how far the stroke moves per metre the declared vertex
    moves (body +z: ``height_m`` for the apex in the MER layout).  None without a finite max stroke."""
    ms = getattr(st, "max", None)
    if ms is None or not np.isfinite(ms.distance):
        return None
    from workbench.core.rotation import quat_to_dcm
    from workbench.problems.droptest import model as rl

    k = int(ms.index)
    g_B = quat_to_dcm(smo.x[k, rl.SQ]).T @ np.asarray(st.smoothed.jacobian[k, :3], float)
    v_B = np.asarray(st.lander.body.vertices[ms.vertex], float)
    which = "vertex 3, the apex" if ms.vertex == 3 else f"vertex {ms.vertex}, a base vertex"
    return (
        f"max stroke {ms.distance:.3f} ± {ms.sigma:.3f} m (1σ): the distance of the declared body's {which} "
        f"([{v_B[0]:.3f}, {v_B[1]:.3f}, {v_B[2]:.3f}] m from the CM), from the surface — a point no sensor sees "
        f"while the bags hold it off the surface, so the 1σ covers the estimated pose only and the stroke moves "
        f"with the declared geometry: by {g_B[2]:+.2f} m per metre that vertex moves along body +z "
        f"(∇ = [{g_B[0]:+.2f}, {g_B[1]:+.2f}, {g_B[2]:+.2f}] per metre along body x, y, z); the geometry: "
        f"the lander file {os.path.basename(str(settings.lander_file))} ({VERTEX_KEYS})"
    )


# ---------------------------------------------------------------------------------------------
# timing: declared time shifts against the ranging residuals
# ---------------------------------------------------------------------------------------------


#: ranging channels' innovations over this margin [s] around the measured impact enter the lag estimate
LAG_WINDOW_S = 0.1

#: the lag is significant beyond this many σ: the honest z of the joint fit scatters a little more than
#: N(0, 1) (model error of the open-loop IMU trajectory; docs/RESULTS.md), so 4 leaves honest drops alone
LAG_SIGNIFICANT_Z = 4.0

#: above this reduced χ² the range-rate residuals over the impact are not a time shift plus the errors
#: the fit shares (honest drops stay near 1: docs/RESULTS.md), and the check names the other causes first
LAG_FIT_CHI2 = 2.0


def _slice_tel(tel, k0: int, k1: int, lag: float):
    """The telemetry ``tel`` restricted to filter steps ``k0..k1-1`` with its IMU time line moved by
    ``−lag`` [s] (a further lag taken off the IMU tags)."""
    from dataclasses import replace

    sl = slice(k0, k1)
    return replace(
        tel,
        t=tel.t[sl] - lag,
        f_B=tel.f_B[sl],
        f_valid=tel.f_valid[sl],
        w_B=tel.w_B[sl],
        w_valid=tel.w_valid[sl],
        hanging=tel.hanging[sl],
        jerk=tel.jerk[sl],
        counts=(tel.counts[0][sl], tel.counts[1][sl]),
    )


@dataclass(frozen=True)
class LagEstimate:
    """The IMU lag against the ranging stream: ``lag_s`` the further lag [s] to take off the IMU
    tags beyond the declared ``time_shifts_s["imu"]`` (negative: the declared one is too large),
    ``sigma_s`` its 1σ [s] (scaled by √χ²ᵣ when the residuals scatter more than declared),
    ``chi2_red`` the fit's reduced χ², ``guns`` ((gun, samples), ...) the range-rate channels used."""

    lag_s: float
    sigma_s: float
    chi2_red: float
    guns: tuple


def estimate_lag(settings, tel, fwd, forward: Callable) -> LagEstimate | None:
    """The lag of the IMU time line against the radar guns' range rates over the impact, where the
    motion changes fastest.  The filter is re-run from its own prior just before the measured impact
    to just after it on the IMU alone (open loop: no ranging update can absorb a timing error), and
    the range-rate residuals z − h(x) of all guns, weighted by their declared σ, are fitted jointly
    (one least-squares problem) with the errors the guns share: the prior's velocity error δv and
    a drift δa (u·δv + u·δa t, u the line of sight), an attitude error δθ that tilts the velocity
    change Δv (δθ·(Δv × u)), a rate offset per gun, and the lag: a state ``lag`` late reads
    h(t − lag) ≈ h − lag·dh/dt, so the coefficient of dh/dt is the lag.  The guns share the nuisance
    (fitting each gun alone with its own tilt cost a factor 2.4 in σ), and the lag and its variance
    come from dh/dt's part orthogonal to the nuisance columns
    (:func:`~workbench.estimation.regression.partial_coefficient`), so a rank-deficient nuisance
    (one gun: its line of sight barely turns) costs precision, not a singular matrix.  ``forward``: the
    forward pass ``forward(settings, tel, init) -> FilterStage`` (:func:`.pipeline.forward_pass`).
    Samples where the open-loop model is not finite are left out.  None without radar guns, without an impact,
    without a gun with 8 finite range rates over it, or when the fit has no degree of freedom left
    or dh/dt lies in the nuisance's span."""
    if tel.ranging is None:
        return None
    imp = measured_impact(tel)
    if imp is None:
        return None
    from dataclasses import replace

    from workbench.estimation.regression import partial_coefficient
    from workbench.problems.droptest import model as rl
    from workbench.problems.droptest.sensors import RangingSpec

    spec = RangingSpec.from_settings(settings.ranging)
    if not spec.guns:
        return None
    fp = fwd.forward
    k0 = int(np.searchsorted(tel.t, imp[0] - LAG_WINDOW_S))
    k1 = int(np.searchsorted(tel.t, imp[1] + LAG_WINDOW_S))
    if k0 < 1 or k1 - k0 < 20:
        return None
    sub = replace(_slice_tel(tel, k0, k1, 0.0), ranging=None)
    x = forward(settings, sub, _Init(fp.x_prior[k0].copy(), fp.P_prior[k0].copy())).x
    rt = tel.ranging
    t_meas = rt.time - tel.time_shifts_s.get("ranging", 0.0)
    inside = (t_meas >= sub.t[0]) & (t_meas <= sub.t[-1])
    used = []
    blocks = []  # per gun, whitened: shared nuisance (n, 9), dh/dt (n,), residual (n,); and 1/σ
    t_mid = 0.5 * (sub.t[0] + sub.t[-1])
    if not inside.any():
        return None
    # one reference for every gun's velocity change (the attitude error δθ is shared)
    v_ref = np.array([np.interp(t_meas[inside][0], sub.t, x[:, i]) for i in range(rl.SV.start, rl.SV.stop)])
    for name, G in spec.guns.items():
        col = f"{name}.rate"
        if col not in rt.channels:
            continue
        z = rt.channel(col)
        m = inside & np.isfinite(z)
        if m.sum() < 8:
            continue
        r_B = settings.lander.to_body(spec.reflectors_L[name])
        tm = t_meas[m]
        # the state at each measurement time: linear between the filter steps (sub-step offsets)
        xs = np.stack([np.interp(tm, sub.t, x[:, i]) for i in range(x.shape[1])], axis=1)
        h = np.array([rl.range_rate_model(xi, G, r_B)[0][0] for xi in xs])
        ok = np.isfinite(h)
        if ok.sum() < 8:
            continue
        tm, xs, h, res = tm[ok], xs[ok], h[ok], z[m][ok] - h[ok]
        u = xs[:, rl.SP] - G
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        tilt = np.cross(xs[:, rl.SV] - v_ref, u)
        w = 1.0 / spec.rate_sigmas[name]  # > 0: a noise-free declaration fails the filter's own pass first
        shared = np.hstack([u, u * (tm - t_mid)[:, None], tilt]) * w
        blocks.append((shared, np.gradient(h, tm) * w, res * w, w))
        used.append((name, int(tm.size)))
    if not blocks:
        return None
    n_g = len(blocks)
    rows = sum(b[2].size for b in blocks)
    N = np.zeros((rows, 9 + n_g))  # nuisance: δv, δa, δθ (shared), one offset per gun
    d = np.empty(rows)
    y = np.empty(rows)
    r0 = 0
    for j, (shared, dh, res, w) in enumerate(blocks):
        r1 = r0 + res.size
        N[r0:r1, :9] = shared
        N[r0:r1, 9 + j] = w
        d[r0:r1], y[r0:r1] = dh, res
        r0 = r1
    fit = partial_coefficient(N, d, y)
    if fit is None:
        return None
    return LagEstimate(fit.coef, fit.sigma, fit.chi2_red, tuple(used))


@dataclass(frozen=True)
class _Init:
    """The start of a trial forward pass: state ``x0`` (N_X,) and covariance ``P0`` (N_E, N_E)."""

    x0: np.ndarray
    P0: np.ndarray


def timing_checks(tel, smo, st, settings, est: LagEstimate | None) -> tuple[list[Check], list[str]]:
    """``timing.imu_vs_ranging``: the declared time shifts (``tel.time_shifts_s``: the IMU's from
    ``[sensors.acquisition]`` filter / order / cutoff and latency_s, the ranging's from
    ``[sensors.ranging]`` latency_s / acquisition_filter) against the lag ``est`` of :func:`estimate_lag`.
    The IMU-driven trajectory at the impact moves by |v_n| × lag (v_n the CM speed into the ramp at
    the first contact); ERROR when the lag is significant (> :data:`LAG_SIGNIFICANT_Z` σ) and that
    shift exceeds 2σ of the max stroke (the IMU and the ranging then disagree by more than the
    headline's uncertainty), WARNING when only significant; a significant lag whose fit has a reduced
    χ² above :data:`LAG_FIT_CHI2` is not a time shift alone, and its message names the other causes
    (axes, units, lever arms, gun positions, a gun's declared rate noise) before the timing keys.
    Returns ``(checks, notes)``; a run without ranging has nothing to compare its IMU time line with
    (a note)."""
    shifts = ", ".join(f"{k} {v * 1e3:.3f} ms" for k, v in tel.time_shifts_s.items())
    if tel.ranging is None:
        return [], []
    if est is None:
        return [], [
            "timing: no IMU lag estimate (no impact inside the ranging record, too few finite range rates over it, "
            f"or a degenerate fit); time shifts applied: {shifts}"
        ]
    from workbench.problems.droptest import model as rl

    lag, sig = est.lag_s, est.sigma_s
    i0 = st.contact[0] if st.contact[0] >= 0 else int(st.max.index)
    vn = abs(float(smo.x[i0, rl.SV] @ st.surface.normal))
    move = vn * abs(lag)
    s_ms = float(st.max.sigma)
    z = abs(lag) / sig
    aq = settings.acquisition
    base = (
        f"IMU time line against the ranging: best further lag {lag * 1e3:+.3f} ± {sig * 1e3:.3f} ms ({z:.1f}σ; "
        f"the range rates of {', '.join(g for g, _ in est.guns)} over the impact, reduced χ² {est.chi2_red:.2f}) "
        "beyond "
        f"the declared shifts ({shifts}); it shifts the IMU-driven trajectory at the impact by ≈ {move * 1e3:.1f} mm "
        f"(|v_n| {vn:.1f} m/s × lag) against the max-stroke 1σ {s_ms * 1e3:.1f} mm"
    )
    half = max(LAG_SIGNIFICANT_Z * sig, 2.0 * s_ms / max(vn, 1e-6))
    bound = [_g(-half), _g(half)]
    keys = (
        f"[sensors.acquisition] filter = {aq.filter!r} (order {aq.order}, {aq.cutoff_hz:g} Hz; 'zero_phase' has no "
        f"delay) or latency_s = {aq.latency_s:g}, or [sensors.ranging] latency_s / acquisition_filter in "
        f"{settings.path}"
    )
    if est.chi2_red > LAG_FIT_CHI2:  # the residuals are not a time shift plus the shared errors
        verdict = (
            f"the range rates do not fit a time shift (reduced χ² {est.chi2_red:.2f} > {LAG_FIT_CHI2:g}): the IMU "
            "and the ranging disagree for another reason — a sensor axis, unit, lever arm, radar gun position or "
            "a gun's declared rate noise "
            f"(see the other checks) more likely than the timing; if those are right, check {keys}"
        )
    else:
        verdict = f"the declared timing is wrong — {keys}"
    if z > LAG_SIGNIFICANT_Z and move > 2.0 * s_ms:
        return [Check("timing.imu_vs_ranging", ERROR, _g(lag), bound, f"{base}: {verdict}", {"kind": "two_sided"})], []
    if z > LAG_SIGNIFICANT_Z:
        return [
            Check(
                "timing.imu_vs_ranging",
                WARNING,
                _g(lag),
                bound,
                f"{base}: {verdict if est.chi2_red > LAG_FIT_CHI2 else f'check {keys}'}",
                {"kind": "two_sided"},
            )
        ], []
    return [Check("timing.imu_vs_ranging", OK, _g(lag), bound, base, {"kind": "two_sided"})], []
