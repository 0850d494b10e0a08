"""Physics cross-checks of a MEADS reconstruction: the IMU against the pressures.

The pressure pattern alone (the least squares of :mod:`.airdata`) gives the flow angles α, β in
body axes independently of the IMU; the strapdown of the IMU from the initial state gives them too,
from the inertial velocity and attitude (with the wind unknown: its prior 1σ over the speed is part
of the comparison's σ).  Two independent estimates of the same angles: their difference over their
combined σ is a standard normal for honest data (median |z| 0.67).  A swapped or sign-flipped IMU
axis, a wrong initial attitude or a port map that does not match the vehicle makes them disagree by
many σ: :func:`imu_vs_pressure_checks` is an ERROR when the median |z| over the samples above the
dynamic-pressure threshold exceeds :data:`IMU_PRESSURE_ERROR_Z` (half the flight disagreeing by
more than 3σ: no honest σ does that), and names the likely sensor axis by re-running the strapdown
with each single swap, sign flip or g / rad unit factor of the IMU columns undone
(:func:`diagnose_imu_axes`).

The accelerometer alone, in body axes, against the same flow angles (:func:`accel_direction_checks`):
the aerodynamic force of a blunt, axisymmetric capsule points nearly along −x_B (its axial force
dominates: |C_N| ≪ C_A for a 70° sphere-cone at |α| ≤ 30°), and its transverse part lies in the
plane of the body axis and the air velocity (the symmetry plane of an axisymmetric body at that
incidence).  A force far off the axis means an accelerometer axis swapped with x or x flipped; a
transverse force across the flow's plane, y and z swapped.
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.bodies import MARS
from workbench.core.rotation import quat_normalize, quat_to_dcm
from workbench.estimation.health import ERROR, OK, Check
from workbench.estimation.strapdown import rk4_step

__all__ = [
    "IMU_PRESSURE_ERROR_Z",
    "ACCEL_AXIS_ERROR_DEG",
    "ACCEL_PLANE_ERROR_DEG",
    "IMU_CANDIDATES",
    "inertial_flow_angles",
    "imu_vs_pressure_z",
    "imu_vs_pressure_checks",
    "diagnose_imu_axes",
    "accel_direction_checks",
]

#: median |z| of (pressure − IMU-driven) flow angle over its σ above which the IMU and the pressures
#: cannot both be right: half the samples beyond 3σ (a standard normal has median |z| 0.67)
IMU_PRESSURE_ERROR_Z = 3.0
#: median angle [deg] between the specific force and −x_B above which the measured force is not a
#: blunt capsule's aerodynamic force (|C_N| < C_A puts it within 45° of the axis; a 70° sphere-cone
#: at |α| ≤ 30° within about 10°)
ACCEL_AXIS_ERROR_DEG = 45.0
#: median angle [deg, 0–90] between the transverse specific force and the plane of the body axis and
#: the air velocity above which the force is not an axisymmetric body's (it lies in that plane)
ACCEL_PLANE_ERROR_DEG = 45.0
#: the transverse flow must be this far off the axis [deg] (total angle of attack) and the transverse
#: force this fraction of |f| for the plane of :data:`ACCEL_PLANE_ERROR_DEG` to be defined
MIN_TOTAL_ALPHA_DEG, MIN_TRANSVERSE_FRACTION = 5.0, 0.02
#: least samples for a check
MIN_SAMPLES = 20
_AXES = "xyz"

#: standard gravity [m/s²] and degrees per radian: the unit factors an IMU column mislabelled
#: between g and m/s² or rad/s and deg/s carries
_G0, _DEG = 9.80665, 180.0 / math.pi
#: the single IMU column mistakes tried by :func:`diagnose_imu_axes`: (sensor, "swap"/"flip", axes)
#: and (sensor, "scale", factor that undoes it, what the file likely holds)
IMU_CANDIDATES = tuple(
    [(s, "swap", a) for s in ("accelerometer", "gyro") for a in ((0, 1), (0, 2), (1, 2))]
    + [(s, "flip", (i,)) for s in ("accelerometer", "gyro") for i in range(3)]
    + [
        ("accelerometer", "scale", _G0, "specific force in g labelled as an acceleration unit"),
        ("accelerometer", "scale", 1.0 / _G0, "specific force in m/s² labelled as g"),
        ("gyro", "scale", _DEG, "body rates in rad/s labelled as deg/s"),
        ("gyro", "scale", 1.0 / _DEG, "body rates in deg/s labelled as rad/s"),
    ]
)


def inertial_flow_angles(
    q_M_B: np.ndarray, p_M: np.ndarray, v_M: np.ndarray, Q: np.ndarray | None, wind_sigma_mps: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """α, β [rad] (n,) of the planet-relative velocity in body axes (no wind) from the strapdown's
    attitude ``q_M_B`` (n, 4) (body → M), position ``p_M`` and velocity ``v_M`` (n, 3) [m, m/s] in M,
    and their 1σ [rad] (n,): the attitude and velocity 1σ of ``Q`` (n, 6, 6) covariance of
    [δv_N, δθ_B] (None: 0) and the unknown wind, ``wind_sigma_mps`` over the speed."""
    C_M_B = quat_to_dcm(q_M_B)
    v_g = v_M - np.cross(np.array([0.0, 0.0, MARS.rotation_rate]), p_M)
    u = np.einsum("nji,nj->ni", C_M_B, v_g)
    V = np.maximum(np.linalg.norm(u, axis=1), 1e-9)
    alpha = np.arctan2(u[:, 2], u[:, 0])
    beta = np.arcsin(np.clip(u[:, 1] / V, -1.0, 1.0))
    var = (wind_sigma_mps / V) ** 2
    if Q is not None:
        d = np.maximum(np.einsum("nii->ni", Q), 0.0)
        var = var + d[:, 3:].max(axis=1) + d[:, :3].max(axis=1) / V**2
    return alpha, beta, np.sqrt(var)


def imu_vs_pressure_z(
    fit, alpha_i: np.ndarray, beta_i: np.ndarray, sigma_i: np.ndarray, above: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(z_α, z_β) over the samples ``above`` (bool (n,)) where both are finite: the least squares'
    angle minus the IMU-driven one (``alpha_i``, ``beta_i`` [rad] (n,)), over the root sum square
    of the fit's 1σ and ``sigma_i`` [rad] (n,)."""
    out = []
    for p, sp, i in ((fit.alpha, fit.sigma_alpha, alpha_i), (fit.beta, fit.sigma_beta, beta_i)):
        d = np.angle(np.exp(1j * (p - i)))
        z = d / np.hypot(sp, sigma_i)
        out.append(z[above & np.isfinite(z)])
    return out[0], out[1]


def _median_abs(z: np.ndarray) -> float:
    return float(np.median(np.abs(z))) if z.size else float("nan")


def _candidate_label(tel, cand) -> str:
    sensor, op, axes = cand[:3]
    pre = "f_" if sensor == "accelerometer" else "w_"
    units = tel.imu_units or {}
    if op == "scale":
        cols = ", ".join(f"'{pre}{a} [{units.get(pre + a, '?')}]'" for a in _AXES)
        return f"{cand[3]} (columns {cols}, off by a factor {axes:.4g})"
    cols = [f"'{pre}{_AXES[a]} [{units.get(pre + _AXES[a], '?')}]'" for a in axes]
    if op == "swap":
        return f"{sensor} axes {_AXES[axes[0]]} and {_AXES[axes[1]]} swapped (columns {cols[0]} and {cols[1]})"
    return f"{sensor} axis {_AXES[axes[0]]} sign-flipped (column {cols[0]})"


def _apply(cand, f_B: np.ndarray, w_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    f, w = f_B.copy(), w_B.copy()
    sensor, op, axes = cand[:3]
    a = f if sensor == "accelerometer" else w
    if op == "scale":
        a *= axes
    elif op == "swap":
        i, j = axes
        a[:, [i, j]] = a[:, [j, i]]
    else:
        a[:, axes[0]] *= -1.0
    return f, w


def _strapdown_members(tel, f: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean-only strapdown of the members' IMU samples ``f``, ``w`` (m, n, 3) from the telemetry's
    initial state, vectorised over the members; (v_M, q_M_B, p_M) (m, n, ...) at the IMU times."""
    init = tel.initial
    sel = tel.t_imu >= init.t - 1e-9
    t = tel.t_imu[sel]
    f, w = f[:, sel], w[:, sel]
    m, n = f.shape[0], t.size
    v = np.tile(init.v_M, (m, 1))
    q = np.tile(init.q_M_B, (m, 1))
    p = np.tile(init.p_M, (m, 1))
    V, Qs, P = np.empty((m, n, 3)), np.empty((m, n, 4)), np.empty((m, n, 3))
    V[:, 0], Qs[:, 0], P[:, 0] = v, q, p
    with np.errstate(all="ignore"):
        for k in range(n - 1):
            v, q, p = rk4_step(v, q, p, f[:, k], w[:, k], f[:, k + 1], w[:, k + 1], float(t[k + 1] - t[k]), MARS)
            V[:, k + 1], Qs[:, k + 1], P[:, k + 1] = v, q, p
    return t, V, Qs, P


def diagnose_imu_axes(tel, fit, above: np.ndarray, wind_sigma_mps: float, Q: np.ndarray | None) -> list[dict]:
    """Each single IMU column mistake of :data:`IMU_CANDIDATES` undone in turn: the strapdown re-run
    (mean only) from the initial state and the median |z| of α and β against the pressures
    (:func:`imu_vs_pressure_z`; the IMU side's σ from the original run's navigation covariance ``Q``
    (n, 6, 6) and the candidate's own speed, :func:`inertial_flow_angles`); a list of
    ``{"label", "median_abs_z": [α, β]}`` sorted best first."""
    cands = list(IMU_CANDIDATES)
    fs, ws = zip(*(_apply(c, tel.f_B, tel.w_B) for c in cands), strict=True)
    t, V, Qs, P = _strapdown_members(tel, np.stack(fs), np.stack(ws))
    tp = tel.t_p
    out = []
    for i, c in enumerate(cands):
        q = Qs[i].copy()
        flip = np.einsum("ni,ni->n", q[1:], q[:-1]) < 0
        q[1:][np.cumsum(flip) % 2 == 1] *= -1

        def at(a):
            return np.stack([np.interp(tp, t, a[:, j]) for j in range(a.shape[1])], 1)

        with np.errstate(all="ignore"):
            a_i, b_i, s_i = inertial_flow_angles(quat_normalize(at(q)), at(P[i]), at(V[i]), Q, wind_sigma_mps)
            za, zb = imu_vs_pressure_z(fit, a_i, b_i, s_i, above)
        mz = [_median_abs(za), _median_abs(zb)]
        if all(math.isfinite(x) for x in mz):
            out.append({"label": _candidate_label(tel, c), "median_abs_z": mz})
    return sorted(out, key=lambda d: max(d["median_abs_z"]))


def imu_vs_pressure_checks(tel, nav, fit, above: np.ndarray, wind_sigma_mps: float, *, diagnose: bool = True) -> list:
    """``physics.imu_vs_pressure_alpha`` and ``..._beta``: the median |z| of the least squares' flow
    angles against the strapdown's (module docstring) over the samples ``above`` (bool (n,)); ERROR
    above :data:`IMU_PRESSURE_ERROR_Z`, its message naming the IMU column mistake that best restores
    the agreement (``diagnose``), else the other suspects.  ``stat`` upper: the WARNING band is the
    truth Monte Carlo's."""
    a_i, b_i, s_i = inertial_flow_angles(nav.q_M_B, nav.p_M, nav.v_M, nav.Q, wind_sigma_mps)
    za, zb = imu_vs_pressure_z(fit, a_i, b_i, s_i, above)
    stat = {"kind": "upper"}
    checks = []
    bad = []
    for name, z in (("alpha", za), ("beta", zb)):
        cname = f"physics.imu_vs_pressure_{name}"
        if z.size < MIN_SAMPLES:
            checks.append(
                Check(cname, OK, None, IMU_PRESSURE_ERROR_Z, f"too few samples above the threshold ({z.size})")
            )
            continue
        mz = _median_abs(z)
        dmed = math.degrees(float(np.median(_diff(fit, name, a_i, b_i, above))))
        msg = (
            f"{name} from the pressures against the IMU strapdown (no wind, wind 1σ {wind_sigma_mps:g} m/s): "
            f"median |z| {mz:.3g} over {z.size} samples above the threshold (honest ≈ 0.67), median difference "
            f"{dmed:.3g} deg"
        )
        status = OK
        if mz > IMU_PRESSURE_ERROR_Z:
            status = ERROR
            bad.append(name)
        checks.append(Check(cname, status, float(f"{mz:.6g}"), IMU_PRESSURE_ERROR_Z, msg, stat))
    if bad:
        hint = _diagnosis(tel, fit, above, wind_sigma_mps, nav.Q, max(_median_abs(za), _median_abs(zb)), diagnose)
        checks = [
            Check(
                c.name,
                c.status,
                c.value,
                c.bound,
                c.message + ": the IMU-driven flow angles and the pressures' cannot both be right — " + hint,
                c.stat,
            )
            if c.status == ERROR
            else c
            for c in checks
        ]
    return checks


def _diff(fit, name: str, a_i: np.ndarray, b_i: np.ndarray, above: np.ndarray) -> np.ndarray:
    p, i = (fit.alpha, a_i) if name == "alpha" else (fit.beta, b_i)
    d = np.angle(np.exp(1j * (p - i)))
    return d[above & np.isfinite(d)]


def _diagnosis(tel, fit, above, wind_sigma_mps, Q, worst: float, diagnose: bool) -> str:
    others = (
        f"the initial attitude (q_M_B in the initial state), the IMU's body axes (+x out of the nose) in "
        f"{tel.imu_file or 'the IMU file'}, or the ports' positions in the vehicle file"
    )
    if not diagnose:
        return "suspects: an IMU axis swapped or sign-flipped, " + others
    ranked = diagnose_imu_axes(tel, fit, above, wind_sigma_mps, Q)
    if ranked:
        best = ranked[0]
        b = max(best["median_abs_z"])
        if b <= IMU_PRESSURE_ERROR_Z and b < 0.5 * worst:
            return (
                f"likely the {best['label']} in {tel.imu_file or 'the IMU file'}: undoing it brings the median |z| of "
                f"α, β to {best['median_abs_z'][0]:.3g}, {best['median_abs_z'][1]:.3g}"
            )
    return "no single swap, sign flip or unit factor of the IMU columns restores the agreement; suspects: " + others


def accel_direction_checks(tel, fit, above: np.ndarray) -> list:
    """``physics.accel_axis_deg`` and ``physics.accel_flow_plane_deg`` (module docstring): the
    specific force in body axes at the pressure times (interpolated, samples ``above`` with
    |f| > 1 m/s²) against −x_B and against the plane of x_B and the pressures' air direction;
    ERROR beyond :data:`ACCEL_AXIS_ERROR_DEG` / :data:`ACCEL_PLANE_ERROR_DEG`, naming the columns."""
    f = np.stack([np.interp(tel.t_p, tel.t_imu, tel.f_B[:, j]) for j in range(3)], 1)
    fm = np.linalg.norm(f, axis=1)
    ok = above & (fm > 1.0) & np.isfinite(fit.alpha) & np.isfinite(fit.beta)
    units = tel.imu_units or {}
    file = tel.imu_file or "the IMU file"
    checks = []
    if ok.sum() < MIN_SAMPLES:
        return checks
    fu = f[ok] / fm[ok, None]
    ang = np.degrees(np.arccos(np.clip(-fu[:, 0], -1.0, 1.0)))
    med = float(np.median(ang))
    msg = (
        f"specific force against −x_B (a blunt capsule's drag): median angle {med:.3g} deg over {int(ok.sum())} samples"
    )
    if med > ACCEL_AXIS_ERROR_DEG:
        mean = np.median(fu, axis=0)
        k = int(np.argmax(np.abs(mean)))
        col = f"'f_{_AXES[k]} [{units.get('f_' + _AXES[k], '?')}]'"
        if k == 0:
            what = f"the drag reads along +x: accelerometer axis x sign-flipped (column {col})"
        else:
            sign = "+" if mean[k] > 0 else "−"
            what = (
                f"the drag reads along {sign}{_AXES[k]}: accelerometer axes x and {_AXES[k]} swapped "
                f"(columns 'f_x [{units.get('f_x', '?')}]' and {col})"
            )
        checks.append(
            Check("physics.accel_axis_deg", ERROR, round(med, 4), ACCEL_AXIS_ERROR_DEG, f"{msg}; {what} in {file}")
        )
    else:
        checks.append(Check("physics.accel_axis_deg", OK, round(med, 4), ACCEL_AXIS_ERROR_DEG, msg))
        d = fit.air_direction_B[ok]
        tot = np.degrees(np.arccos(np.clip(d[:, 0], -1.0, 1.0)))
        ft = np.hypot(fu[:, 1], fu[:, 2])
        use = (tot > MIN_TOTAL_ALPHA_DEG) & (ft > MIN_TRANSVERSE_FRACTION)
        if use.sum() >= MIN_SAMPLES:
            phi_f = np.arctan2(-fu[use, 1], -fu[use, 2])
            phi_v = np.arctan2(d[use, 1], d[use, 2])
            dphi = np.degrees(np.abs(np.angle(np.exp(1j * (phi_f - phi_v)))))
            dphi = np.minimum(dphi, 180.0 - dphi)  # the plane, either side of the axis
            mp = float(np.median(dphi))
            msg = (
                f"transverse specific force against the plane of x_B and the pressures' air velocity (an axisymmetric "
                f"body's force lies in it): median angle {mp:.3g} deg over {int(use.sum())} samples"
            )
            if mp > ACCEL_PLANE_ERROR_DEG:
                msg += (
                    f"; the normal force is across the flow's plane: accelerometer axes y and z swapped (columns "
                    f"'f_y [{units.get('f_y', '?')}]' and 'f_z [{units.get('f_z', '?')}]') in {file}?"
                )
            status = ERROR if mp > ACCEL_PLANE_ERROR_DEG else OK
            checks.append(Check("physics.accel_flow_plane_deg", status, round(mp, 4), ACCEL_PLANE_ERROR_DEG, msg))
    return checks
