"""Compiled (numba) kernels of the entry truth simulator: the fast path of :mod:`.truth`.

The same model as the scalar reference ``truth._Model.deriv`` (kept selectable with
``simulate_entry(..., fast=False)``): point mass + J2 gravity of Mars, the truth's own tabulated
atmosphere and winds (uniform altitude grid, log-linear density and mean free path), the vehicle's
aerodynamic table (clamped trilinear in Mach, log10 Kn, total AoA) times the planted deviations,
the pitch damping and roll torque, and after PDD the elastic riser to the canopy point mass with
its drag, inflation, breathing and asymmetric-inflation side force; fixed-step RK4 with the
quaternion renormalised after each step.  Every expression is written with the reference's
operations in the reference's order, so the compiled trajectory is the reference's up to the
libm rounding of a few transcendental calls (tests/problems/entry/test_truth_fast.py).

Frames and units as in :mod:`.truth`: MMED inertial M, body G, SI.  The state ``y`` (19,) is
``[p_M (3) m, v_M (3) m/s, q_M_G (4, scalar last), w_G (3) rad/s, canopy p_M (3) m, canopy v_M
(3) m/s]``; only its first ``n`` (13 before PDD, 19 after) entries are used.

Parameters are a flat scalar vector ``sc`` (indices ``SC_*``, filled by ``truth._Model.packed``)
and a tuple of arrays ``arrs`` = (atmosphere (5, n_h): ln ρ, sound speed, ln mean free path, wind
north, wind east; the phase's aero table Mach nodes, log10 Kn nodes, AoA nodes [rad] and
coefficients (n_mach, n_kn, n_alpha, 3) = CA, CN, Cm; the axial-deviation factors and the
parachute-deviation factors on their uniform ln-Mach grids; parachute Mach nodes and CD; the
phase's inertia (3, 3) [kg m²] and its inverse).
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.jit import njit

__all__ = ["N_SC", "N_AUX", "STATUS_PDD", "STATUS_DONE", "STATUS_GROUND", "STATUS_SEGMENT", "deriv", "run_segment"]

# indices of the scalar parameter vector ``sc``
SC_GM, SC_J2K, SC_RREF, SC_OM, SC_AERO_ON = 0, 1, 2, 3, 4
SC_H_LO, SC_INV_DH, SC_D, SC_S, SC_LREF, SC_CMQ, SC_M = 5, 6, 7, 8, 9, 10, 11
SC_CN_FAC, SC_CM_FAC, SC_ROLL = 12, 13, 14
SC_M_P, SC_A0, SC_L0, SC_K_R, SC_C_R, SC_ATT = 15, 16, 17, 18, 19, 20  # SC_ATT .. +2
SC_T_PDD, SC_SIDE = 23, 24  # SC_SIDE .. +2
SC_PHI_B, SC_AMP_B, SC_INFL, SC_B_DECAY, SC_B_PERIOD = 27, 28, 29, 30, 31
SC_SF_START, SC_SF_END, SC_SF_COEFF = 32, 33, 34
SC_CA_X0, SC_CA_INV, SC_CP_X0, SC_CP_INV = 35, 36, 37, 38
SC_TWO = 39  # the exponent 2.0 as data: see _rk4
N_SC = 40
"""Length of the scalar parameter vector."""
N_AUX = 17
"""Length of the auxiliary output (as ``truth._Model.deriv(..., aux=True)``)."""

STATUS_PDD, STATUS_DONE, STATUS_GROUND, STATUS_SEGMENT = 0, 1, 2, 3


@njit
def _locate(grid, x):
    """(lower node index, weight clamped to [0, 1]) of x on an increasing grid (n ≥ 2): ``bisect_right`` − 1."""
    n = grid.shape[0]
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if x < grid[mid]:
            hi = mid
        else:
            lo = mid + 1
    i = min(max(lo - 1, 0), n - 2)
    g0 = grid[i]
    g1 = grid[i + 1]
    w = (x - g0) / (g1 - g0)
    if w < 0.0:
        w = 0.0
    elif w > 1.0:
        w = 1.0
    return i, w


@njit
def _factor(fac, x0, inv, mach):
    """``1 + δ(M)`` from its uniform ln-Mach table (``truth._lookup``)."""
    u = (math.log(mach) - x0) * inv if mach > 0.0 else 0.0
    n = fac.shape[0]
    if u <= 0.0:
        return fac[0]
    if u >= n - 1:
        return fac[n - 1]
    i = int(u)
    return fac[i] + (u - i) * (fac[i + 1] - fac[i])


@njit
def _gravity(x, y, z, gm, j2k):
    """Point mass + J2 (``truth._Model.gravity``): (g_x, g_y, g_z) [m/s²] and |r| [m]."""
    r2 = x * x + y * y + z * z
    r = math.sqrt(r2)
    ir3 = 1.0 / (r2 * r)
    k = j2k / (r2 * r2 * r)
    zz = 5.0 * z * z / r2
    a = -gm * ir3
    return a * x - k * x * (1.0 - zz), a * y - k * y * (1.0 - zz), a * z - k * z * (3.0 - zz), r


@njit
def _atm(h, sc, atm):
    """(ρ, sound speed, mean free path, wind north, wind east) at altitude h [m] (``truth._Model.atm``)."""
    x = (h - sc[SC_H_LO]) * sc[SC_INV_DH]
    n_h = atm.shape[1]
    i = int(x)
    if i < 0:
        i, f = 0, 0.0
    elif i >= n_h - 1:
        i, f = n_h - 2, 1.0
    else:
        f = x - i
    return (
        math.exp(atm[0, i] + f * (atm[0, i + 1] - atm[0, i])),
        atm[1, i] + f * (atm[1, i + 1] - atm[1, i]),
        math.exp(atm[2, i] + f * (atm[2, i + 1] - atm[2, i])),
        atm[3, i] + f * (atm[3, i + 1] - atm[3, i]),
        atm[4, i] + f * (atm[4, i + 1] - atm[4, i]),
    )


@njit
def _coefficients(gm, gk, ga, stack, mach, kn, alpha):
    """(CA, CN, Cm) of the table (``AeroTable.coefficients_scalar``'s interpolation and order)."""
    i, wi = _locate(gm, mach)
    j, wj = _locate(gk, math.log10(kn) if kn > 0.0 else -300.0)
    l, wl = _locate(ga, alpha)
    out0 = out1 = out2 = 0.0
    for k in range(3):
        a0 = stack[i, j, l, k]
        b0 = stack[i + 1, j, l, k]
        a1 = stack[i, j + 1, l, k]
        b1 = stack[i + 1, j + 1, l, k]
        v0 = a0 + wi * (b0 - a0)
        v1 = a1 + wi * (b1 - a1)
        u0 = v0 + wj * (v1 - v0)
        a0 = stack[i, j, l + 1, k]
        b0 = stack[i + 1, j, l + 1, k]
        a1 = stack[i, j + 1, l + 1, k]
        b1 = stack[i + 1, j + 1, l + 1, k]
        v0 = a0 + wi * (b0 - a0)
        v1 = a1 + wi * (b1 - a1)
        u1 = v0 + wj * (v1 - v0)
        o = u0 + wl * (u1 - u0)
        if k == 0:
            out0 = o
        elif k == 1:
            out1 = o
        else:
            out2 = o
    return out0, out1, out2


@njit
def _area(t, sc):
    """Canopy drag area [m²] at time t [s] (``truth._Model.area``)."""
    tau = t - sc[SC_T_PDD]
    if tau <= 0.0:
        return 0.0
    ti = sc[SC_INFL]
    s = tau / ti
    u = 1.0 if s >= 1.0 else s * s * (3.0 - 2.0 * s)
    env = 1.0 if tau <= ti else math.exp(-(tau - ti) / sc[SC_B_DECAY])
    b = sc[SC_AMP_B] * env * math.cos(2.0 * math.pi * (tau - ti) / sc[SC_B_PERIOD] + sc[SC_PHI_B])
    return sc[SC_A0] * u * (1.0 + b)


@njit
def _side_weight(t, sc):
    """Side-force fraction of the canopy drag at time t (``truth._Model.side_weight``)."""
    tau = t - sc[SC_T_PDD]
    a, b, e = sc[SC_SF_START], sc[SC_SF_END], 0.15
    if tau <= a - e or tau >= b + e or sc[SC_SF_COEFF] == 0.0:
        return 0.0
    up = 1.0 if tau >= a + e else 0.5 - 0.5 * math.cos(math.pi * (tau - a + e) / (2 * e))
    dn = 1.0 if tau <= b - e else 0.5 + 0.5 * math.cos(math.pi * (tau - b + e) / (2 * e))
    return sc[SC_SF_COEFF] * up * dn


@njit
def deriv(t, s, n, out, aux, sc, arrs):
    """Time derivative of the state ``s`` (first ``n`` of (19,)) at t [s] into ``out`` (19,), and the
    auxiliary outputs (17,) into ``aux`` (f_G (3) [m/s²], Mach, Kn, total AoA [rad], q [Pa], h AMR
    [m], v_rel_M (3) [m/s], wind N, E [m/s], riser tension [N], canopy area [m²], CA factor, canopy CD
    factor) — ``truth._Model.deriv`` with ``aux=True``, operation for operation."""
    atm, gmach, gkn, galpha, stack, ca_fac, cp_fac, ch_mach, ch_cd, I, Ii = arrs
    px, py, pz, vx, vy, vz = s[0], s[1], s[2], s[3], s[4], s[5]
    qx, qy, qz, qw, wx, wy, wz = s[6], s[7], s[8], s[9], s[10], s[11], s[12]
    gmu, j2k = sc[SC_GM], sc[SC_J2K]
    gx, gy, gz, r = _gravity(px, py, pz, gmu, j2k)
    h = r - sc[SC_RREF]
    # DCM C_M_G from q_M_G (core.rotation.dcm_components)
    xx, yy, zz = qx * qx, qy * qy, qz * qz
    xy, xz, yz = qx * qy, qx * qz, qy * qz
    qwx, qwy, qwz = qw * qx, qw * qy, qw * qz
    c00, c01, c02 = 1 - 2 * (yy + zz), 2 * (xy - qwz), 2 * (xz + qwy)
    c10, c11, c12 = 2 * (xy + qwz), 1 - 2 * (xx + zz), 2 * (yz - qwx)
    c20, c21, c22 = 2 * (xz - qwy), 2 * (yz + qwx), 1 - 2 * (xx + yy)
    om = sc[SC_OM]
    FGx = FGy = FGz = 0.0
    Mx = My = Mz = 0.0
    mach = kn = alpha = qd = 0.0
    ca_f = cp_f = 1.0
    vrx = vry = vrz = 0.0
    wn = we = 0.0
    aero_on = sc[SC_AERO_ON] != 0.0
    if aero_on:
        rho, a_snd, lam, wn, we = _atm(h, sc, atm)
        # local north/east in M (core.frames.north_east_xyz)
        rxy = math.sqrt(px * px + py * py)
        nx, ny, nz, ex, ey = -px * pz / (r * rxy), -py * pz / (r * rxy), rxy / r, -py / rxy, px / rxy
        vrx = vx + om * py - wn * nx - we * ex
        vry = vy - om * px - wn * ny - we * ey
        vrz = vz - wn * nz
        V = math.sqrt(vrx * vrx + vry * vry + vrz * vrz)
        if V > 1e-6:
            bx = c00 * vrx + c10 * vry + c20 * vrz
            by = c01 * vrx + c11 * vry + c21 * vrz
            bz = c02 * vrx + c12 * vry + c22 * vrz
            ca_ = -bz / V
            alpha = math.acos(1.0 if ca_ > 1.0 else -1.0 if ca_ < -1.0 else ca_)
            mach = V / a_snd
            kn = lam / sc[SC_D]
            CA, CN, CM = _coefficients(gmach, gkn, galpha, stack, mach, kn, alpha)
            ca_f = _factor(ca_fac, sc[SC_CA_X0], sc[SC_CA_INV], mach)
            CA, CN, CM = CA * ca_f, CN * sc[SC_CN_FAC], CM * sc[SC_CM_FAC]
            qd = 0.5 * rho * V * V
            qS = qd * sc[SC_S]
            FGz = CA * qS
            nl = math.sqrt(bx * bx + by * by)
            if nl > 1e-9 * V:
                FGx = -CN * qS * bx / nl
                FGy = -CN * qS * by / nl
                mm = CM * qS * sc[SC_LREF] / nl
                Mx = -mm * by
                My = mm * bx
            damp = sc[SC_CMQ] * qS * sc[SC_LREF] * sc[SC_LREF] / (2.0 * V)
            Mx += damp * wx
            My += damp * wy
            Mz += sc[SC_ROLL] * qS * sc[SC_LREF]
    T = 0.0
    area = 0.0
    if n > 13:
        ppx, ppy, ppz, vpx, vpy, vpz = s[13], s[14], s[15], s[16], s[17], s[18]
        ax_, ay_, az_ = sc[SC_ATT], sc[SC_ATT + 1], sc[SC_ATT + 2]
        cax = c00 * ax_ + c01 * ay_ + c02 * az_
        cay = c10 * ax_ + c11 * ay_ + c12 * az_
        caz = c20 * ax_ + c21 * ay_ + c22 * az_
        tx, ty, tz = wy * az_ - wz * ay_, wz * ax_ - wx * az_, wx * ay_ - wy * ax_
        vax = vx + c00 * tx + c01 * ty + c02 * tz
        vay = vy + c10 * tx + c11 * ty + c12 * tz
        vaz = vz + c20 * tx + c21 * ty + c22 * tz
        dx, dy, dz = ppx - px - cax, ppy - py - cay, ppz - pz - caz
        L = math.sqrt(dx * dx + dy * dy + dz * dz)
        ux, uy, uz = dx / L, dy / L, dz / L
        stretch = L - sc[SC_L0]
        if stretch > 0.0:
            sd = ux * (vpx - vax) + uy * (vpy - vay) + uz * (vpz - vaz)
            T = sc[SC_K_R] * stretch + sc[SC_C_R] * sd
            if T < 0.0:
                T = 0.0
        gpx, gpy, gpz, rp = _gravity(ppx, ppy, ppz, gmu, j2k)
        Dx = Dy = Dz = 0.0
        Ap = _area(t, sc)
        area = Ap
        if aero_on and Ap > 0.0:
            rho_p, a_p, _lam_p, wnp, wep = _atm(rp - sc[SC_RREF], sc, atm)
            rxy = math.sqrt(ppx * ppx + ppy * ppy)
            nxp, nyp, nzp = -ppx * ppz / (rp * rxy), -ppy * ppz / (rp * rxy), rxy / rp
            exp_, eyp = -ppy / rxy, ppx / rxy
            wx_p = vpx + om * ppy - wnp * nxp - wep * exp_
            wy_p = vpy - om * ppx - wnp * nyp - wep * eyp
            wz_p = vpz - wnp * nzp
            Vp = math.sqrt(wx_p * wx_p + wy_p * wy_p + wz_p * wz_p)
            if Vp > 1e-6:
                mp = Vp / a_p
                cp_f = _factor(cp_fac, sc[SC_CP_X0], sc[SC_CP_INV], mp)
                i, w = _locate(ch_mach, mp)
                cd = ch_cd[i] + w * (ch_cd[i + 1] - ch_cd[i])
                Dk = 0.5 * rho_p * Vp * cd * cp_f * Ap
                Dx, Dy, Dz = -Dk * wx_p, -Dk * wy_p, -Dk * wz_p
                ks = _side_weight(t, sc)
                if ks > 0.0:
                    sx, sy, sz = sc[SC_SIDE], sc[SC_SIDE + 1], sc[SC_SIDE + 2]
                    sv = (sx * wx_p + sy * wy_p + sz * wz_p) / (Vp * Vp)
                    sx, sy, sz = sx - sv * wx_p, sy - sv * wy_p, sz - sv * wz_p
                    sn = ks * Dk * Vp / math.sqrt(sx * sx + sy * sy + sz * sz)
                    Dx, Dy, Dz = Dx + sn * sx, Dy + sn * sy, Dz + sn * sz
        imp = 1.0 / sc[SC_M_P]
        out[13] = vpx
        out[14] = vpy
        out[15] = vpz
        out[16] = gpx + (Dx - T * ux) * imp
        out[17] = gpy + (Dy - T * uy) * imp
        out[18] = gpz + (Dz - T * uz) * imp
        fbx = T * (c00 * ux + c10 * uy + c20 * uz)
        fby = T * (c01 * ux + c11 * uy + c21 * uz)
        fbz = T * (c02 * ux + c12 * uy + c22 * uz)
        FGx += fbx
        FGy += fby
        FGz += fbz
        Mx += ay_ * fbz - az_ * fby
        My += az_ * fbx - ax_ * fbz
        Mz += ax_ * fby - ay_ * fbx
    im = 1.0 / sc[SC_M]
    fx, fy, fz = FGx * im, FGy * im, FGz * im
    out[0] = vx
    out[1] = vy
    out[2] = vz
    out[3] = gx + (c00 * fx + c01 * fy + c02 * fz)
    out[4] = gy + (c10 * fx + c11 * fy + c12 * fz)
    out[5] = gz + (c20 * fx + c21 * fy + c22 * fz)
    hx = I[0, 0] * wx + I[0, 1] * wy + I[0, 2] * wz
    hy = I[1, 0] * wx + I[1, 1] * wy + I[1, 2] * wz
    hz = I[2, 0] * wx + I[2, 1] * wy + I[2, 2] * wz
    rx = Mx - (wy * hz - wz * hy)
    ry = My - (wz * hx - wx * hz)
    rz = Mz - (wx * hy - wy * hx)
    out[6] = 0.5 * (qw * wx + qy * wz - qz * wy)
    out[7] = 0.5 * (qw * wy + qz * wx - qx * wz)
    out[8] = 0.5 * (qw * wz + qx * wy - qy * wx)
    out[9] = -0.5 * (qx * wx + qy * wy + qz * wz)
    out[10] = Ii[0, 0] * rx + Ii[0, 1] * ry + Ii[0, 2] * rz
    out[11] = Ii[1, 0] * rx + Ii[1, 1] * ry + Ii[1, 2] * rz
    out[12] = Ii[2, 0] * rx + Ii[2, 1] * ry + Ii[2, 2] * rz
    aux[0], aux[1], aux[2] = fx, fy, fz
    aux[3], aux[4], aux[5], aux[6], aux[7] = mach, kn, alpha, qd, h
    aux[8], aux[9], aux[10], aux[11], aux[12] = vrx, vry, vrz, wn, we
    aux[13], aux[14], aux[15], aux[16] = T, area, ca_f, cp_f


@njit
def _rk4(t, y, n, dt, sc, arrs, k1, k2, k3, k4, tmp, aux):
    """One RK4 step of ``dt`` [s] of the first ``n`` entries of ``y`` in place, quaternion renormalised
    (``truth._rk4``)."""
    deriv(t, y, n, k1, aux, sc, arrs)
    h2 = 0.5 * dt
    for i in range(n):
        tmp[i] = y[i] + h2 * k1[i]
    deriv(t + h2, tmp, n, k2, aux, sc, arrs)
    for i in range(n):
        tmp[i] = y[i] + h2 * k2[i]
    deriv(t + h2, tmp, n, k3, aux, sc, arrs)
    for i in range(n):
        tmp[i] = y[i] + dt * k3[i]
    deriv(t + dt, tmp, n, k4, aux, sc, arrs)
    d6 = dt / 6.0
    for i in range(n):
        y[i] = y[i] + d6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
    # the reference squares with ``x ** 2``, i.e. libm's pow, which is not always the correctly
    # rounded x * x; an exponent read from data keeps LLVM from rewriting pow(x, 2.0) into x * x
    two = sc[SC_TWO]
    qn = 1.0 / math.sqrt(math.pow(y[6], two) + math.pow(y[7], two) + math.pow(y[8], two) + math.pow(y[9], two))
    y[6] *= qn
    y[7] *= qn
    y[8] *= qn
    y[9] *= qn


@njit
def run_segment(k, k_end, k_last, t0, dt_out, y, n, n_sub, trig_mode, trig_value, r_ground, states, auxs, sc, arrs):
    """Output samples ``k`` .. ``k_end − 1`` of the truth loop (``truth.simulate_entry``): at each, the
    auxiliary outputs at ``t = t0 + k dt_out``, the PDD check, the sample stored in ``states[k, :n]``
    and ``auxs[k]``, then ``n_sub`` RK4 steps of ``dt_out / n_sub`` advance ``y`` (19,) in place.

    ``trig_mode``: 0 no PDD check, 1 PDD at ``t ≥ trig_value − 1e-9`` (a time [s]), 2 PDD when Mach
    < ``trig_value`` and t > 0.  Returns (status, k): :data:`STATUS_PDD` at sample k (not stored,
    ``y`` its state), :data:`STATUS_DONE` after storing ``k ≥ k_last``, :data:`STATUS_GROUND` (stored,
    the module below ``r_ground`` [m]), or :data:`STATUS_SEGMENT` with k = ``k_end`` and ``y`` there."""
    d = np.zeros(19)
    k1 = np.zeros(19)
    k2 = np.zeros(19)
    k3 = np.zeros(19)
    k4 = np.zeros(19)
    tmp = np.zeros(19)
    aux = np.zeros(N_AUX)
    scratch = np.zeros(N_AUX)
    h = dt_out / n_sub
    while k < k_end:
        t = t0 + k * dt_out
        deriv(t, y, n, d, aux, sc, arrs)
        if trig_mode == 1 and t >= trig_value - 1e-9:
            return STATUS_PDD, k
        if trig_mode == 2 and aux[3] < trig_value and t > 0:
            return STATUS_PDD, k
        for i in range(n):
            states[k, i] = y[i]
        for i in range(N_AUX):
            auxs[k, i] = aux[i]
        if k >= k_last:
            return STATUS_DONE, k
        if math.sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]) < r_ground:
            return STATUS_GROUND, k
        for j in range(n_sub):
            _rk4(t + j * h, y, n, h, sc, arrs, k1, k2, k3, k4, tmp, scratch)
        k += 1
    return STATUS_SEGMENT, k
