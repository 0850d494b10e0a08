"""Compiled (numba) evaluation of the POST2 trajectory model's dynamics, row by row over a batch.

:meth:`~workbench.problems.post2.model.TrajectoryModel.derivative` and
:meth:`~workbench.problems.post2.model.TrajectoryModel.aero_force_moment` are called ~10⁵ times per
reconstruction on small batches (the 1 + 2 n_e rows of the batched numeric Jacobian, ~31 x 16): the
numpy version spends its time in the overhead of ~150 array operations per call, not in arithmetic.
:func:`dynamics_kernel` does the same arithmetic in one compiled loop over the rows, in the same
order of operations as the numpy reference (``model.py``), so the two agree to a few units in the
last place (the reference's BLAS/einsum sums may round differently; see
``tests/problems/post2/test_post2_kernels.py``).  The atmosphere (density, speed of sound, Knudsen)
and the S-curve of bounded parameters are evaluated by the caller in numpy (any
:class:`~workbench.core.atmosphere.Atmosphere`; numpy's SIMD ``tanh`` differs from libm's in the
last bit) and passed in per row.

Layout of the arguments (built by ``TrajectoryModel._fast_plan``):

* ``X`` (b, n_x) states; ``rho``, ``a_snd``, ``kn``, ``ca_extra`` (b,) density [kg/m³] (density
  wave applied, multiplier not), speed of sound [m/s], Knudsen number [-], truth-side CA(Mach)
  factor [-];
* parameters: slot k of :data:`PARAM_SLOTS` is ``pnom[k]`` when ``pmode[k] == 0``, the raw state
  ``X[:, pidx[k]]`` when 1, the precomputed row ``PB[pidx[k]]`` (S-curve applied) when 2;
* ``ci`` integer flags, ``cf`` float constants (indices :data:`CI` / :data:`CF`);
* ``inertia``, ``inertia_inv`` (3, 3) body frame [kg m²]; aero table grids ``g_mach``, ``g_lkn``,
  ``g_alpha`` and coefficients ``tab`` (n_mach, n_kn, n_alpha, 3) [CA, CN, Cm]; the parachute
  table ``chute_mach``, ``chute_cd`` of the open canopy (drogue or main);
* outputs ``dx`` (b, n_x) (only if ``want_dx``), ``F`` (b, 3) inertial [N], ``M`` (b, 3) body [N m].

The Huygens-like Monte Carlo selection has its own: the members' propagation with the axial
accelerometer on the grid (:func:`propagate_axial_kernel`) and the alignment search of its metric
(:func:`metric_search_kernel`); references ``TrajectoryModel.axial_on_grid_reference`` and the numpy
branch of ``huygens._metric``.
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.interp_kernel import interp_at, interp_index, interp_index_near
from workbench.core.jit import njit

__all__ = [
    "PARAM_SLOTS",
    "CI",
    "CF",
    "dynamics_kernel",
    "air_speed_kernel",
    "interp_index",
    "interp_index_near",
    "interp_at",
    "axial_kernel",
    "propagate_axial_kernel",
    "metric_search_kernel",
]

#: parameter slots of the kernel (name, size 1 each)
PARAM_SLOTS = (
    "j2",
    "ca_multiplier",
    "cn_multiplier",
    "cm_multiplier",
    "density_multiplier",
    "ca_multiplier_fm",
    "ca_multiplier_hyp",
    "ca_multiplier_sup",
    "drogue_drag_multiplier",
    "parachute_drag_multiplier",
    "drogue_drag_area",
    "main_drag_area",
    "wind_vertical",
    "wind_horizontal",
    "log_pressure_offset",
)
_J2, _CAM, _CNM, _CMM, _RHOM, _FM, _HYP, _SUP, _DROGM, _PARAM, _DROGA, _MAINA, _WV, _WH, _LPO = range(15)

#: integer flags: dof, atmosphere present, aero table present, constant cd present, Knudsen
#: matters, regime CA multiplier on, open chute table (0 none, 1 drogue, 2 parachute), drag-area state chute
#: (0 none, 1 drogue, 2 main), Huygens wind on, x offsets of position, velocity, attitude, rates
CI = {
    "dof": 0,
    "atm": 1,
    "aero": 2,
    "has_cd": 3,
    "kn_matters": 4,
    "regime": 5,
    "chute": 6,
    "area_chute": 7,
    "wind": 8,
    "i_pos": 9,
    "i_vel": 10,
    "i_att": 11,
    "i_w": 12,
}
#: float constants: planet rate [rad/s], GM [m³/s²], R_eq² [m²], R_ref [m], S [m²], mass [kg],
#: L [m], Cmq, CA/CN/Cm truth factors, constant cd, chute reference area [m²]
CF = {
    "omega": 0,
    "gm": 1,
    "re2": 2,
    "radius_ref": 3,
    "area": 4,
    "mass": 5,
    "ref_length": 6,
    "cmq": 7,
    "ca_factor": 8,
    "cn_factor": 9,
    "cm_factor": 10,
    "cd": 11,
    "chute_area": 12,
}


@njit
def _params(r, X, PB, pmode, pidx, pnom, pv):
    """The parameter slots of row r into ``pv`` (nominal, raw state or precomputed S-curve value)."""
    for k in range(pnom.size):
        m = pmode[k]
        if m == 0:
            pv[k] = pnom[k]
        elif m == 1:
            pv[k] = X[r, pidx[k]]
        else:
            pv[k] = PB[pidx[k], r]


@njit
def _locate(grid, x):
    """numpy's ``_locate`` of aerodynamics.py: lower node and clamped weight (searchsorted right)."""
    n = grid.size
    lo, hi = 0, n
    while lo < hi:  # first index with grid[i] > x
        mid = (lo + hi) // 2
        if grid[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    i = lo - 1
    if i < 0:
        i = 0
    if i > n - 2:
        i = n - 2
    w = (x - grid[i]) / (grid[i + 1] - grid[i])
    if w < 0.0:
        w = 0.0
    elif w > 1.0:
        w = 1.0
    return i, w


@njit
def _smoothstep(u):
    if u < 0.0:
        u = 0.0
    elif u > 1.0:
        u = 1.0
    return u * u * (3.0 - 2.0 * u)


@njit
def _vrel(r, X, pv, ci, cf):
    """Air-relative velocity v − ω × r − wind [m/s] of row r (the model's ``v_rel``)."""
    ip, iv = ci[9], ci[10]
    px, py, pz = X[r, ip], X[r, ip + 1], X[r, ip + 2]
    omega = cf[0]
    vr0 = X[r, iv] - (-omega * py)
    vr1 = X[r, iv + 1] - omega * px
    vr2 = X[r, iv + 2] - 0.0
    if ci[8]:
        wv = pv[_WV]
        wh = pv[_WH]
        if wv != 0.0 or wh != 0.0:
            rn = math.sqrt(px * px + py * py + pz * pz)
            e0, e1 = -py, px
            en = math.sqrt(e0 * e0 + e1 * e1 + 0.0 * 0.0)
            if en < 1e-9:
                en = 1e-9
            e0, e1, e2 = e0 / en, e1 / en, 0.0 / en
            vr0 = vr0 - (wv * px / rn + wh * e0)
            vr1 = vr1 - (wv * py / rn + wh * e1)
            vr2 = vr2 - (wv * pz / rn + wh * e2)
    return vr0, vr1, vr2


@njit
def air_speed_kernel(X, PB, pmode, pidx, pnom, ci, cf, out):
    """|v_rel| [m/s] of each row of X (b, n_x) into ``out`` (b,) (arguments as :func:`dynamics_kernel`)."""
    pv = np.empty(pnom.size)
    for r in range(X.shape[0]):
        _params(r, X, PB, pmode, pidx, pnom, pv)
        vr0, vr1, vr2 = _vrel(r, X, pv, ci, cf)
        out[r] = math.sqrt(vr0 * vr0 + vr1 * vr1 + vr2 * vr2)


@njit
def axial_kernel(X, F, PB, pmode, pidx, pnom, ci, cf, mass, cos_tilt, bias, out):
    """Huygens-like 3-DOF axial accelerometer [m/s²] of each row of X (b, n_x) into ``out`` (b,):
    ``(F · v̂_rel / mass) cos_tilt + bias`` with F (b, 3) the inertial aero force [N] of
    :func:`dynamics_kernel`, ``cos_tilt`` and ``bias`` (b,) evaluated by the caller; the model's
    numpy ``axial_acceleration_3dof`` with its sums' order (numpy reduces 3 columns left to right)."""
    pv = np.empty(pnom.size)
    for r in range(X.shape[0]):
        _params(r, X, PB, pmode, pidx, pnom, pv)
        vr0, vr1, vr2 = _vrel(r, X, pv, ci, cf)
        n = math.sqrt(vr0 * vr0 + vr1 * vr1 + vr2 * vr2)
        if n < 1e-9:  # np.maximum(|v_rel|, 1e-9); NaN stays NaN
            n = 1e-9
        a = F[r, 0] * (vr0 / n) + F[r, 1] * (vr1 / n) + F[r, 2] * (vr2 / n)
        out[r] = (a / mass) * cos_tilt[r] + bias[r]


@njit
def dynamics_kernel(
    X, rho, a_snd, kn, ca_extra, PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv,
    g_mach, g_lkn, g_alpha, tab, chute_mach, chute_cd, want_dx, dx, F, M,
):  # fmt: skip
    """Derivative ``dx`` (if ``want_dx``), aero force ``F`` (inertial) and moment ``M`` (body) of
    each row of X (b, n_x); see the module docstring for the arguments.  No return value."""
    b = X.shape[0]
    dof = ci[0]
    has_atm, has_aero, has_cd, kn_matters = ci[1], ci[2], ci[3], ci[4]
    regime, chute, area_chute = ci[5], ci[6], ci[7]
    ip, iv, iq, iw = ci[9], ci[10], ci[11], ci[12]
    gm, re2, S, mass = cf[1], cf[2], cf[4], cf[5]
    L, cmq = cf[6], cf[7]
    pv = np.empty(pnom.size)
    l0, wl0 = 0, 0.0
    if dof == 3 and has_aero:  # trimmed at zero angle of attack: the same node for every row
        l0, wl0 = _locate(g_alpha, 0.0)
    for r in range(b):
        _params(r, X, PB, pmode, pidx, pnom, pv)
        px, py, pz = X[r, ip], X[r, ip + 1], X[r, ip + 2]
        vx, vy, vz = X[r, iv], X[r, iv + 1], X[r, iv + 2]
        F0 = F1 = F2 = 0.0
        M0 = M1 = M2 = 0.0
        if has_atm:
            rho_r = rho[r] * pv[_RHOM]
            if pv[_LPO] != 0.0:  # the atmosphere's ln-p offset: rho = p / (R T) moves with p
                rho_r = rho_r * math.exp(pv[_LPO])
            vr0, vr1, vr2 = _vrel(r, X, pv, ci, cf)
            V = math.sqrt(vr0 * vr0 + vr1 * vr1 + vr2 * vr2)
            qbar = 0.5 * rho_r * V * V
            mach = V / a_snd[r]
            Vs = V if V > 1e-9 else 1e-9
            ca_m = pv[_CAM] * cf[8]
            kn_r = kn[r] if kn_matters else 1e-6
            # log10 Kn once for the regime weight and the table (the same number where both use it)
            lkn = math.log10(kn_r if kn_r > 1e-300 else 1e-300)
            if has_aero:
                if regime:
                    m_fm = pv[_FM]
                    m_h = pv[_HYP]
                    m_s = pv[_SUP]
                    w_fm = _smoothstep((lkn if kn_r > 1e-12 else math.log10(1e-12)) + 2.0)
                    w_h = _smoothstep((mach - 5.0) / 5.0)
                    ca_m = ca_m * (w_fm * m_fm + (1.0 - w_fm) * (w_h * m_h + (1.0 - w_h) * m_s))
                else:
                    ca_m = ca_m * 1.0
                ca_m = ca_m * ca_extra[r]
            if dof == 3:
                if has_aero:
                    i, wi = _locate(g_mach, mach)
                    j, wj = _locate(g_lkn, lkn)
                    l, wl = l0, wl0
                    ca = 0.0
                    for di in range(2):
                        fi = wi if di == 1 else 1.0 - wi
                        for dj in range(2):
                            fj = wj if dj == 1 else 1.0 - wj
                            for dl in range(2):
                                fl = wl if dl == 1 else 1.0 - wl
                                ca = ca + fi * fj * fl * tab[i + di, j + dj, l + dl, 0]
                    c = ca_m * ca * qbar * S / Vs
                    F0, F1, F2 = F0 - c * vr0, F1 - c * vr1, F2 - c * vr2
                elif has_cd:
                    c = ca_m * cf[11] * qbar * S / Vs
                    F0, F1, F2 = F0 - c * vr0, F1 - c * vr1, F2 - c * vr2
            elif has_aero:
                qx, qy, qzz, qw = X[r, iq], X[r, iq + 1], X[r, iq + 2], X[r, iq + 3]
                nq = math.sqrt(qx * qx + qy * qy + qzz * qzz + qw * qw)
                if nq == 0.0:
                    raise ValueError("cannot normalise a zero quaternion")
                qx, qy, qzz, qw = qx / nq, qy / nq, qzz / nq, qw / nq
                xx, yy, zz = qx * qx, qy * qy, qzz * qzz
                xy, xz, yz = qx * qy, qx * qzz, qy * qzz
                wx, wy, wz = qw * qx, qw * qy, qw * qzz
                R00, R01, R02 = 1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)
                R10, R11, R12 = 2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)
                R20, R21, R22 = 2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)
                # v_B = Rᵀ v_rel
                vb0 = R00 * vr0 + R10 * vr1 + R20 * vr2
                vb1 = R01 * vr0 + R11 * vr1 + R21 * vr2
                vb2 = R02 * vr0 + R12 * vr1 + R22 * vr2
                lat = math.sqrt(vb1 * vb1 + vb2 * vb2)
                alpha_t = math.atan2(lat, vb0)
                i, wi = _locate(g_mach, mach)
                j, wj = _locate(g_lkn, lkn)
                l, wl = _locate(g_alpha, alpha_t)
                ca = 0.0
                cn = 0.0
                cm = 0.0
                for di in range(2):
                    fi = wi if di == 1 else 1.0 - wi
                    for dj in range(2):
                        fj = wj if dj == 1 else 1.0 - wj
                        for dl in range(2):
                            fl = wl if dl == 1 else 1.0 - wl
                            f = fi * fj * fl
                            ca = ca + f * tab[i + di, j + dj, l + dl, 0]
                            cn = cn + f * tab[i + di, j + dj, l + dl, 1]
                            cm = cm + f * tab[i + di, j + dj, l + dl, 2]
                cn = cn * pv[_CNM] * cf[9]
                cm = cm * pv[_CMM] * cf[10]
                safe = lat if lat > 1e-12 else 1e-12
                e_y, e_z = vb1 / safe, vb2 / safe
                if not lat > 1e-12:
                    e_y = 0.0
                    e_z = 0.0
                qs = qbar * S
                Fb0 = -ca_m * ca * qs
                Fb1 = -cn * qs * e_y
                Fb2 = -cn * qs * e_z
                mk = cm * qs * L
                damp = cmq * qs * L * L / (2.0 * Vs)
                M1 = mk * e_z + damp * X[r, iw + 1]
                M2 = -mk * e_y + damp * X[r, iw + 2]
                # R F_B: numpy's einsum("...ij,...j->...i") sums in the order (j0 + j2) + j1
                F0 = F0 + ((R00 * Fb0 + R02 * Fb2) + R01 * Fb1)
                F1 = F1 + ((R10 * Fb0 + R12 * Fb2) + R11 * Fb1)
                F2 = F2 + ((R20 * Fb0 + R22 * Fb2) + R21 * Fb1)
            if chute != 0:  # open canopy: 1 the drogue table, 2 the (main) parachute table
                cd = interp_at(interp_index(mach, chute_mach), mach, chute_mach, chute_cd) * (
                    pv[_DROGM] if chute == 1 else pv[_PARAM]
                )
                c = cd * qbar * cf[12] / Vs
                F0, F1, F2 = F0 - c * vr0, F1 - c * vr1, F2 - c * vr2
            if area_chute != 0:  # drag-area state −CD·S q v̂_rel
                cds = pv[_DROGA] if area_chute == 1 else pv[_MAINA]
                c = cds * qbar / Vs
                F0, F1, F2 = F0 - c * vr0, F1 - c * vr1, F2 - c * vr2
        F[r, 0], F[r, 1], F[r, 2] = F0, F1, F2
        M[r, 0], M[r, 1], M[r, 2] = M0, M1, M2
        if not want_dx:
            continue
        for c in range(X.shape[1]):
            dx[r, c] = 0.0
        dx[r, ip], dx[r, ip + 1], dx[r, ip + 2] = vx, vy, vz
        # point mass + J2 (gravity_j2_xyz)
        j2k = 1.5 * pv[_J2] * gm * re2
        r2 = px * px + py * py + pz * pz
        rr = math.sqrt(r2)
        gm_r3 = gm / (r2 * rr)
        z2 = 5.0 * (pz * pz) / r2
        kk = j2k / (r2 * r2 * rr)
        a = gm_r3 + kk * (1.0 - z2)
        dx[r, iv] = -a * px + F0 / mass
        dx[r, iv + 1] = -a * py + F1 / mass
        dx[r, iv + 2] = -(gm_r3 + kk * (3.0 - z2)) * pz + F2 / mass
        if dof == 6:
            qx, qy, qzz, qw = X[r, iq], X[r, iq + 1], X[r, iq + 2], X[r, iq + 3]
            w0, w1, w2 = X[r, iw], X[r, iw + 1], X[r, iw + 2]
            w3 = 0.0
            dx[r, iq] = 0.5 * (qw * w0 + qx * w3 + qy * w2 - qzz * w1)
            dx[r, iq + 1] = 0.5 * (qw * w1 - qx * w2 + qy * w3 + qzz * w0)
            dx[r, iq + 2] = 0.5 * (qw * w2 + qx * w1 - qy * w0 + qzz * w3)
            dx[r, iq + 3] = 0.5 * (qw * w3 - qx * w0 - qy * w1 - qzz * w2)
            I = inertia
            Iw0 = w0 * I[0, 0] + w1 * I[0, 1] + w2 * I[0, 2]
            Iw1 = w0 * I[1, 0] + w1 * I[1, 1] + w2 * I[1, 2]
            Iw2 = w0 * I[2, 0] + w1 * I[2, 1] + w2 * I[2, 2]
            t0 = M0 - (w1 * Iw2 - w2 * Iw1)
            t1 = M1 - (w2 * Iw0 - w0 * Iw2)
            t2 = M2 - (w0 * Iw1 - w1 * Iw0)
            J = inertia_inv
            dx[r, iw] = t0 * J[0, 0] + t1 * J[0, 1] + t2 * J[0, 2]
            dx[r, iw + 1] = t0 * J[1, 0] + t1 * J[1, 1] + t2 * J[1, 2]
            dx[r, iw + 2] = t0 * J[2, 0] + t1 * J[2, 1] + t2 * J[2, 2]


# ---------------------------------------------------------------------------------------------
# atmospheres (exact ports of workbench.core.atmosphere's numpy expressions, for the hot path)
# ---------------------------------------------------------------------------------------------
#: atmosphere kinds of :func:`atmosphere_kernel`: 1 MarsEngineeringAtmosphere, 2 TabulatedAtmosphere
#: (extrapolate "clamp"); ``ac`` constants: [h_blend, H_aloft, GLENN_R, γR, μ0, T0, T0 + C, C, R]
ATM_MARS, ATM_TABLE = 1, 2


@njit
def atmosphere_kernel(kind, ac, t_h, t_lrho, t_lp, t_T, hc, want_kn, L, rho, a_snd, kn):
    """Density [kg/m³], speed of sound [m/s] and (if ``want_kn``) Knudsen number on length L [m] at
    altitudes ``hc`` (b,) [m] into ``rho``, ``a_snd``, ``kn`` (b,), same operations as the numpy
    classes (``kind``/``ac`` above; ``t_*`` the table's nodes, log ρ, log p, T)."""
    inv_step = 0.0  # the table's nodes per metre if they were evenly spaced: the node search's first guess
    if kind == 2 and t_h.size > 1 and t_h[t_h.size - 1] > t_h[0]:
        inv_step = (t_h.size - 1) / (t_h[t_h.size - 1] - t_h[0])
    for r in range(hc.size):
        h = hc[r]
        if kind == 1:
            hb = ac[0]
            hm = h if h < hb else hb
            T = (-31.0 - 0.000998 * hm if hm < 7000.0 else -23.4 - 0.00222 * hm) + 273.15
            above = h - hb
            if not above > 0.0:
                above = 0.0
            p = 0.699e3 * math.exp(-0.00009 * hm) * math.exp(-above / ac[1])
            rho[r] = p / (ac[2] * T)
        else:  # one node search for the three columns (np.interp's arithmetic, :func:`interp_at`)
            j = interp_index_near(h, t_h, inv_step)
            T = interp_at(j, h, t_h, t_T)
            p = math.exp(interp_at(j, h, t_h, t_lp))
            rho[r] = math.exp(interp_at(j, h, t_h, t_lrho))
        a_snd[r] = math.sqrt(ac[3] * T)
        if want_kn:
            mu = ac[4] * (T / ac[5]) ** 1.5 * ac[6] / (T + ac[7])
            kn[r] = mu / p * math.sqrt(0.5 * np.pi * ac[8] * T) / L


@njit
def full_derivative(
    X, PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv, g_mach, g_lkn, g_alpha, tab, chute_mach, chute_cd,
    kind, ac, t_h, t_lrho, t_lp, t_T, waves, want_dx, dx, F, M, hc, rho, a_snd, kn, ones,
):  # fmt: skip
    """:func:`dynamics_kernel` with the altitude ``max(|r| − R_ref, 0)`` and the atmosphere
    (:func:`atmosphere_kernel`, ``kind`` 0: vacuum) evaluated here, and the truth's waves
    (``waves`` = [density wave on, amplitude, wavelength [m], CA(Mach) wave on, amplitude], the
    model's ``DensityWave`` / ``CaMachWave``); scratch ``hc``, ``rho``, ``a_snd``, ``kn``, ``ones`` (b,)."""
    if kind != 0:
        ip, R = ci[9], cf[3]
        for r in range(X.shape[0]):
            px, py, pz = X[r, ip], X[r, ip + 1], X[r, ip + 2]
            h = math.sqrt(px * px + py * py + pz * pz) - R
            hc[r] = 0.0 if h < 0.0 else h
        atmosphere_kernel(kind, ac, t_h, t_lrho, t_lp, t_T, hc, ci[2] != 0 and ci[4] != 0, cf[6], rho, a_snd, kn)
        if waves[0] != 0.0:
            for r in range(X.shape[0]):
                rho[r] = rho[r] * (1.0 + waves[1] * math.sin(2.0 * math.pi * hc[r] / waves[2]))
        if waves[3] != 0.0:
            pv = np.empty(pnom.size)
            for r in range(X.shape[0]):
                _params(r, X, PB, pmode, pidx, pnom, pv)
                vr0, vr1, vr2 = _vrel(r, X, pv, ci, cf)
                mach = math.sqrt(vr0 * vr0 + vr1 * vr1 + vr2 * vr2) / a_snd[r]
                lm = math.log10(mach if mach > 1e-3 else 1e-3)
                ones[r] = 1.0 + waves[4] * math.sin(2.0 * math.pi * lm / 1.2)
    dynamics_kernel(
        X, rho, a_snd, kn, ones, PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv,
        g_mach, g_lkn, g_alpha, tab, chute_mach, chute_cd, want_dx, dx, F, M,
    )  # fmt: skip


@njit
def _rk4_step(
    y, dt, have_k1, k1, k2, k3, k4, tmp, F, M, hc, rho, a_snd, kn, ones, want_dx,
    PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv, g_mach, g_lkn, g_alpha, tab,
    chute_mach, chute_cd, kind, ac, t_h, t_lrho, t_lp, t_T, waves,
):  # fmt: skip
    """One classic RK4 step of ``dt`` [s] of the rows of ``y`` (b, n_x), in place, through
    :func:`full_derivative` (its model arguments); ``have_k1``: ``k1`` already holds the derivative
    at ``y``.  ``k1`` … ``k4``, ``tmp`` (b, n_x) and ``F`` … ``ones`` are the caller's scratch."""
    b, nx = y.shape
    half = 0.5 * dt
    sixth = dt / 6.0
    for stage in range(4):
        if stage == 0:
            if have_k1:
                continue
            src, dst = y, k1
        elif stage == 1:
            for r in range(b):
                for c in range(nx):
                    tmp[r, c] = y[r, c] + half * k1[r, c]
            src, dst = tmp, k2
        elif stage == 2:
            for r in range(b):
                for c in range(nx):
                    tmp[r, c] = y[r, c] + half * k2[r, c]
            src, dst = tmp, k3
        else:
            for r in range(b):
                for c in range(nx):
                    tmp[r, c] = y[r, c] + dt * k3[r, c]
            src, dst = tmp, k4
        full_derivative(
            src, PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv, g_mach, g_lkn, g_alpha, tab,
            chute_mach, chute_cd, kind, ac, t_h, t_lrho, t_lp, t_T, waves, want_dx, dst, F, M, hc, rho, a_snd, kn,
            ones,
        )  # fmt: skip
    for r in range(b):
        for c in range(nx):
            y[r, c] = y[r, c] + sixth * (k1[r, c] + 2.0 * k2[r, c] + 2.0 * k3[r, c] + k4[r, c])


@njit
def propagate_kernel(
    X0, n, dt, iq, PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv, g_mach, g_lkn, g_alpha, tab,
    chute_mach, chute_cd, kind, ac, t_h, t_lrho, t_lp, t_T, waves,
):  # fmt: skip
    """``n`` classic RK4 steps of ``dt`` [s] of the rows of X0 (b, n_x) (the model's ``propagate``:
    ``rk4_step`` then the quaternion at x offset ``iq`` (−1: none) renormalised); returns (b, n_x).
    Parameters are constant over the steps (their derivative is zero), so ``PB`` holds for all."""
    b, nx = X0.shape
    y = X0.copy()
    k1, k2, k3, k4 = np.empty((b, nx)), np.empty((b, nx)), np.empty((b, nx)), np.empty((b, nx))
    tmp = np.empty((b, nx))
    F, M = np.empty((b, 3)), np.empty((b, 3))
    hc, rho, a_snd, kn, ones = np.empty(b), np.empty(b), np.empty(b), np.empty(b), np.ones(b)
    # want_dx (and no_k1) run-time bools, not the literals True (False): a literal argument makes numba
    # compile separate Literal[bool] versions of full_derivative and dynamics_kernel (and _rk4_step)
    # beside the ones Python calls (~4 s of compiling on a fresh checkout)
    want_dx = b >= 0
    no_k1 = b < 0
    for _ in range(n):
        _rk4_step(
            y, dt, no_k1, k1, k2, k3, k4, tmp, F, M, hc, rho, a_snd, kn, ones, want_dx,
            PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv, g_mach, g_lkn, g_alpha, tab,
            chute_mach, chute_cd, kind, ac, t_h, t_lrho, t_lp, t_T, waves,
        )  # fmt: skip
        for r in range(b):
            if iq >= 0:
                q0, q1, q2, q3 = y[r, iq], y[r, iq + 1], y[r, iq + 2], y[r, iq + 3]
                nq = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
                if nq == 0.0:
                    raise ValueError("cannot normalise a zero quaternion")
                y[r, iq], y[r, iq + 1], y[r, iq + 2], y[r, iq + 3] = q0 / nq, q1 / nq, q2 / nq, q3 / nq
    return y


@njit
def propagate_axial_kernel(
    X0, nsub, dts, PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv, g_mach, g_lkn, g_alpha, tab,
    chute_mach, chute_cd, kind, ac, t_h, t_lrho, t_lp, t_T, waves, mass, cos_tilt, bias, out,
):  # fmt: skip
    """3-DOF rows X0 (b, n_x) (no quaternion) through the grid steps k = 0 … n − 1 (``nsub[k]`` RK4 sub-steps of
    ``dts[k]`` [s] each, :func:`propagate_kernel`'s arithmetic) with the axial accelerometer
    (:func:`axial_kernel`, its ``mass``, ``cos_tilt``, ``bias`` (b,)) at every grid node into
    ``out`` (b, n + 1) [m/s²]: the model's step-by-step ``propagate`` and ``observe`` in one call,
    the force at a node being the first RK4 stage's (the same evaluation of the same state)."""
    b, nx = X0.shape
    y = X0.copy()
    k1, k2, k3, k4 = np.empty((b, nx)), np.empty((b, nx)), np.empty((b, nx)), np.empty((b, nx))
    tmp = np.empty((b, nx))
    F, M = np.empty((b, 3)), np.empty((b, 3))
    hc, rho, a_snd, kn, ones = np.empty(b), np.empty(b), np.empty(b), np.empty(b), np.ones(b)
    col = np.empty(b)
    want_dx = b >= 0  # run-time bool (see propagate_kernel)
    n = dts.size
    for k in range(n + 1):
        # the force at the node: full_derivative of y (the next step's first stage, or the last node)
        full_derivative(
            y, PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv, g_mach, g_lkn, g_alpha, tab,
            chute_mach, chute_cd, kind, ac, t_h, t_lrho, t_lp, t_T, waves, want_dx, k1, F, M, hc, rho, a_snd, kn,
            ones,
        )  # fmt: skip
        axial_kernel(y, F, PB, pmode, pidx, pnom, ci, cf, mass, cos_tilt, bias, col)
        for r in range(b):
            out[r, k] = col[r]
        if k == n:
            break
        dt = dts[k]
        for sub in range(nsub[k]):
            # k1 of the node's state is the evaluation above (sub-step 0)
            _rk4_step(
                y, dt, sub == 0, k1, k2, k3, k4, tmp, F, M, hc, rho, a_snd, kn, ones, want_dx,
                PB, pmode, pidx, pnom, ci, cf, inertia, inertia_inv, g_mach, g_lkn, g_alpha, tab,
                chute_mach, chute_cd, kind, ac, t_h, t_lrho, t_lp, t_T, waves,
            )  # fmt: skip


# ---------------------------------------------------------------------------------------------
# Huygens-like Monte Carlo alignment metric (huygens._metric's ``total``)
# ---------------------------------------------------------------------------------------------
@njit
def _pairwise_block(a, lo, n):
    """numpy's pairwise-summation leaf (n ≤ 128): 8 running sums, combined in a tree, then the rest."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    m = n - (n % 8)
    while i < m:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit
def _pairwise_sum(a, lo, n):
    """numpy's pairwise summation of a[lo:lo + n] (float64 add.reduce over a contiguous axis), to the
    bit: blocks of ≤ 128 split in halves (multiples of 8), left + right.  No recursion (numba's cache
    does not reload recursive functions reliably): an explicit post-order stack."""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    s_lo = np.empty(128, np.int64)
    s_n = np.empty(128, np.int64)
    s_st = np.empty(128, np.int64)
    vals = np.empty(128)
    top, nv = 0, 0
    s_lo[0], s_n[0], s_st[0] = lo, n, 0
    top = 1
    while top > 0:
        top -= 1
        flo, fn, fst = s_lo[top], s_n[top], s_st[top]
        if fn <= 128:
            vals[nv] = _pairwise_block(a, flo, fn)
            nv += 1
        elif fst == 1:
            right = vals[nv - 1]
            left = vals[nv - 2]
            nv -= 2
            vals[nv] = left + right
            nv += 1
        else:
            n2 = fn // 2
            n2 -= n2 % 8
            s_lo[top], s_n[top], s_st[top] = flo, fn, 1
            s_lo[top + 1], s_n[top + 1], s_st[top + 1] = flo + n2, fn - n2, 0
            s_lo[top + 2], s_n[top + 2], s_st[top + 2] = flo, n2, 0
            top += 3
    return vals[0]


@njit
def metric_total_kernel(a, tu, zu, sh, t0, h, hi, out):
    """Σ_j |zu_j − a_r(tu_j + sh_r)| per member r into ``out`` (N,): ``a`` (N, n) the members' axial
    acceleration on the grid t0 + h k [s], linear interpolation at u = clip((tu + sh − t0)/h, 0, hi);
    the numpy expression of ``huygens._metric`` with its pairwise row sum."""
    m = tu.size
    row = np.empty(m)
    start = m - m  # 0 as a run-time int: a literal 0 would compile a second _pairwise_block
    for r in range(a.shape[0]):
        for j in range(m):
            u = (tu[j] + sh[r] - t0) / h
            if u < 0.0:
                u = 0.0
            elif u > hi:
                u = hi
            k = int(math.floor(u))
            f = u - k
            row[j] = abs(zu[j] - (a[r, k] * (1.0 - f) + a[r, k + 1] * f))
        out[r] = _pairwise_sum(row, start, m)


@njit
def _metric_row_pruned(a, r, tu, zu, sh, t0, h, hi, order, row, bound):
    """Row r's terms |zu_j − a_r(tu_j + sh)| into ``row`` (m,) and their pairwise sum (as
    :func:`metric_total_kernel`), or +inf as soon as a running sum of the terms taken in ``order``
    exceeds ``bound`` (the total then exceeds it as well: the terms are ≥ 0; ``bound`` carries the
    caller's margin for rounding).  NaN terms never stop the sum."""
    m = tu.size
    part = 0.0
    for q in range(m):
        j = order[q]
        u = (tu[j] + sh - t0) / h
        if u < 0.0:
            u = 0.0
        elif u > hi:
            u = hi
        k = int(math.floor(u))
        f = u - k
        v = abs(zu[j] - (a[r, k] * (1.0 - f) + a[r, k + 1] * f))
        row[j] = v
        part += v
        if (q & 15) == 15 and part > bound:
            return math.inf
    return _pairwise_sum(row, m - m, m)


@njit
def metric_search_kernel(a, tu, zu, base, offs_coarse, offs_fine, t0, h, hi, order, prune, metric, shift):
    """The alignment search of ``huygens._metric`` per member r: ``shift[r]`` = base_r moved by the
    offset of ``offs_coarse`` with the smallest total Σ_j |zu_j − a_r(tu_j + s)| (the first of equal
    ones, as ``np.argmin``; the first NaN total wins, as there), then likewise by one of ``offs_fine``
    (the candidates are tried from the middle outwards, the order not changing the one chosen);
    ``metric[r]`` its total (the pairwise sum of :func:`metric_total_kernel`, to the bit).  A
    candidate whose running sum (terms in ``order``, (m,) a permutation of the samples) exceeds the
    best total so far by 1e-9 relative cannot be the smallest and is dropped before its end (only
    where ``prune[r]``: a row and samples without NaN/inf, whose totals cannot turn NaN later); the
    totals that are kept are the full ones, so shift and metric equal the exhaustive search's."""
    m = tu.size
    row = np.empty(m)
    for r in range(a.shape[0]):
        b = base[r]
        for stage in range(2):
            offs = offs_coarse if stage == 0 else offs_fine
            nf = offs.size
            best = math.inf
            bi = -1
            nan_at = nf
            for q in range(nf):  # from the middle outwards: the smallest is usually near the start
                c = nf // 2
                i = c + (q + 1) // 2 if q % 2 == 1 else c - q // 2
                if i < 0 or i >= nf:  # an even count: the last one left over
                    i = nf - 1 if i < 0 else 0
                bound = best * (1.0 + 1e-9) if prune[r] and best < math.inf else math.inf
                v = _metric_row_pruned(a, r, tu, zu, b + offs[i], t0, h, hi, order, row, bound)
                if math.isnan(v):  # np.argmin: the first NaN
                    if i < nan_at:
                        nan_at = i
                elif bi < 0 or v < best or (v == best and i < bi):
                    best = v
                    bi = i
            if nan_at < nf:
                bi = nan_at
                best = math.nan
            elif bi < 0:
                bi = 0
            b = b + offs[bi]
        shift[r] = b
        metric[r] = best  # the chosen candidate's full total: the total at the final shift
