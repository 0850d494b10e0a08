"""Compiled (numba) kernels of the drop-test truth simulator: the fast path of :mod:`.truth`.

The same force model as :meth:`workbench.problems.droptest.truth.ForceModel.evaluate` (the pure-numpy
reference path, kept selectable with ``simulate_drop(..., fast=False)``), written as scalar loops
so that numba compiles it: airbag lobes flattened on the ramp (shared gas volume, each footprint's
share of the footprints' union), membrane pressure + damping + regularised Coulomb friction, lobe-on-rock
and body-on-rock contacts, the stiff body penalty on the ramp and the bungee while it is uncut.
Also the state derivative for ``solve_ivp`` (:func:`rhs`), the force model over a whole sampled
history (:func:`evaluate_many`) and the point-mass flight of the release design (:func:`fly`).

Frames and units as in :mod:`.truth`: SPF chamber frame (I), body frame B at the CM, SI units;
the state is ``y = [p_I (3) m, v_I (3) m/s, q_I_B (4, scalar last), ω_B (3) rad/s]``.

Parameters are passed as a few flat arrays (built by ``ForceModel.packed``): ``lobes_B`` (n_l, 3)
[m], ``verts_B`` (n_v, 3) [m], ``geo`` (12,) = ramp normal (3), ramp point (3) [m, SPF] and its
in-plane unit vectors (3 + 3, ``Surface.tangent_basis``), ``rock_c`` (n_r, 3) [m, SPF], ``rock_r``
(n_r,) [m], ``rig`` (6,) = bungee anchor (3) [m, SPF] and attachment (3) [m, body], ``coeffs`` (k,)
per-bungee polynomial [N/m^j], ``sc`` (12,) scalars, in order: lobe radius [m], bag pressure [Pa],
ambient pressure [Pa], gas volume [m³], γ, damping [N s/m³], friction μ, body stiffness [N/m], body
damping [N s/m], bungee rest length [m], bungee count, mass [kg]; ``J``, ``Jinv`` (3, 3) inertia
about the CM [kg m², body] and its inverse.

Agreement with the reference (tests/problems/droptest/test_truth_fast.py): the force model, the
derivative and the release design agree to rounding; a whole drop agrees to the integrator's own
truncation error (DOP853's step control reacts to rounding), far below the sensor noise
(measurements: docs/tuning/droptest.md, "truth_fast.py").
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.bodies import G0
from workbench.core.jit import njit

__all__ = ["evaluate", "evaluate_many", "rhs", "fly", "footprint_areas"]

V_SLIP = 0.1  # friction regularisation speed [m/s]; the same constant as truth.V_SLIP
G0_MPS2 = G0  # standard gravity [m/s²]; truth.GRAVITY_SPF = (0, 0, -G0)


FOOT_RAYS = 32  # rays of the angular quadrature of a footprint's share (:func:`footprint_areas`)


@njit
def _insert(ev_r, ev_d, ne, r, d):
    """Insert the crossing (radius r [m], change d of the cover count) into the first ne entries
    of ev_r/ev_d, kept sorted by radius; returns the new count."""
    q = ne
    while q > 0 and ev_r[q - 1] > r:
        ev_r[q] = ev_r[q - 1]
        ev_d[q] = ev_d[q - 1]
        q -= 1
    ev_r[q] = r
    ev_d[q] = d
    return ne + 1


@njit
def footprint_areas(rc, a, t1, t2, out):
    """Contact area [m²] of each flattened lobe: its share of the footprints' union.

    rc (k, 3) footprint centres [m] in one plane spanned by the unit vectors t1, t2 (3,) (the
    surface's ``tangent_basis``), a (k,) footprint radii [m]; fills out (k,). Every point of the
    union is shared equally by the footprints that cover it, so lobe i gets ∫_disk_i 1/m(x) dA with
    m the number of disks covering x: the areas sum to the union's (to the quadrature's accuracy),
    never below zero, and for two disks this is the disk minus half the lens (the half-lens rule,
    which over-subtracts where three or more overlap). Along each of :data:`FOOT_RAYS` rays from the
    disk's centre m is piecewise constant between the crossings of the other circles, so the radial
    integral is exact and only the angle is sampled (midpoint rule, periodic); the area is
    continuous in the footprints' motion.
    """
    k = a.shape[0]
    ev_r = np.empty(2 * k)
    ev_d = np.empty(2 * k)
    near = np.empty(k, np.int64)
    for i in range(k):
        ai = a[i]
        nn = 0
        for j in range(k):
            if j != i and a[j] > 0.0:
                dx = rc[i, 0] - rc[j, 0]
                dy = rc[i, 1] - rc[j, 1]
                dz = rc[i, 2] - rc[j, 2]
                if math.sqrt(dx * dx + dy * dy + dz * dz) < ai + a[j]:
                    near[nn] = j
                    nn += 1
        if nn == 0 or ai <= 0.0:
            out[i] = math.pi * ai * ai
            continue
        tot = 0.0
        for ray in range(FOOT_RAYS):
            th = (ray + 0.5) * 2.0 * math.pi / FOOT_RAYS
            c = math.cos(th)
            s = math.sin(th)
            u0 = c * t1[0] + s * t2[0]
            u1 = c * t1[1] + s * t2[1]
            u2 = c * t1[2] + s * t2[2]
            ne = 0
            for jj in range(nn):
                j = near[jj]
                e0 = rc[i, 0] - rc[j, 0]
                e1 = rc[i, 1] - rc[j, 1]
                e2 = rc[i, 2] - rc[j, 2]
                b = u0 * e0 + u1 * e1 + u2 * e2
                disc = b * b - (e0 * e0 + e1 * e1 + e2 * e2) + a[j] * a[j]
                if disc > 0.0:
                    sq = math.sqrt(disc)
                    r0 = max(-b - sq, 0.0)
                    r1 = min(-b + sq, ai)
                    if r1 > r0:
                        ne = _insert(ev_r, ev_d, ne, r0, 1.0)
                        ne = _insert(ev_r, ev_d, ne, r1, -1.0)
            m = 1.0
            r = 0.0
            f = 0.0
            for q in range(ne):
                f += 0.5 * (ev_r[q] * ev_r[q] - r * r) / m
                r = ev_r[q]
                m += ev_d[q]
            f += 0.5 * (ai * ai - r * r) / m
            tot += f
        out[i] = tot * 2.0 * math.pi / FOOT_RAYS


@njit
def _poly(coeffs, s):
    """Per-bungee force [N] ``Σ_k coeffs[k] · s^(k+1)`` at stretch s [m] (as ``BungeeRig.force``)."""
    f = 0.0
    for k in range(coeffs.shape[0]):
        f = f + coeffs[k] * s ** (k + 1)
    return f


@njit
def _membrane(pg, area, rc, nx, ny, nz, v, w_I, damp, mu, F, T_I):
    """Add the membrane force of one contact (area [m²], contact point rc (3) [m] rel. CM, unit
    normal (nx, ny, nz) away from the surface) to F [N] and its torque to T_I [N m]; returns its
    normal force [N]."""
    vcx = v[0] + (w_I[1] * rc[2] - w_I[2] * rc[1])
    vcy = v[1] + (w_I[2] * rc[0] - w_I[0] * rc[2])
    vcz = v[2] + (w_I[0] * rc[1] - w_I[1] * rc[0])
    vn = vcx * nx + vcy * ny + vcz * nz
    fn = max(pg * area - damp * area * vn, 0.0)
    vtx = vcx - vn * nx
    vty = vcy - vn * ny
    vtz = vcz - vn * nz
    vtn = math.sqrt(vtx * vtx + vty * vty + vtz * vtz)
    g = -mu * (fn * math.tanh(vtn / V_SLIP) / max(vtn, 1e-9))
    fx = fn * nx + g * vtx
    fy = fn * ny + g * vty
    fz = fn * nz + g * vtz
    F[0] += fx
    F[1] += fy
    F[2] += fz
    T_I[0] += rc[1] * fz - rc[2] * fy
    T_I[1] += rc[2] * fx - rc[0] * fz
    T_I[2] += rc[0] * fy - rc[1] * fx
    return fn


@njit
def evaluate(y, cut, lobes_B, verts_B, geo, rock_c, rock_r, rig, coeffs, sc, F, T_B, pen):
    """Forces for one state ``y`` (13,); ``cut``: the bungee is cut.

    Fills F (3,) non-gravitational force [N, SPF], T_B (3,) torque about the CM [N m, body] and
    pen (n_l,) lobe penetrations into the ramp [m]; returns (total airbag normal force [N], gauge
    pressure [Pa], deepest body penetration [m]) — as ``ForceModel.evaluate``.
    """
    R, p0, p_amb, V0, gamma, damp, mu, k_body, c_body, rest, count = (
        sc[0],
        sc[1],
        sc[2],
        sc[3],
        sc[4],
        sc[5],
        sc[6],
        sc[7],
        sc[8],
        sc[9],
        sc[10],
    )
    n = geo[0:3]
    P0 = geo[3:6]
    p = y[0:3]
    v = y[3:6]
    qn = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    x_, y_, z_, w_ = y[6] / qn, y[7] / qn, y[8] / qn, y[9] / qn
    C = np.empty((3, 3))
    C[0, 0] = 1 - 2 * (y_ * y_ + z_ * z_)
    C[0, 1] = 2 * (x_ * y_ - w_ * z_)
    C[0, 2] = 2 * (x_ * z_ + w_ * y_)
    C[1, 0] = 2 * (x_ * y_ + w_ * z_)
    C[1, 1] = 1 - 2 * (x_ * x_ + z_ * z_)
    C[1, 2] = 2 * (y_ * z_ - w_ * x_)
    C[2, 0] = 2 * (x_ * z_ - w_ * y_)
    C[2, 1] = 2 * (y_ * z_ + w_ * x_)
    C[2, 2] = 1 - 2 * (x_ * x_ + y_ * y_)
    w_I = np.empty(3)
    for i in range(3):
        w_I[i] = C[i, 0] * y[10] + C[i, 1] * y[11] + C[i, 2] * y[12]
    F[:] = 0.0
    T_I = np.zeros(3)
    h0 = (p[0] - P0[0]) * n[0] + (p[1] - P0[1]) * n[1] + (p[2] - P0[2]) * n[2]

    # lobes against the ramp
    nl = lobes_B.shape[0]
    r_I = np.empty((nl, 3))
    dc = np.empty(nl)
    vcap = 0.0
    nhit = 0
    for i in range(nl):
        for j in range(3):
            r_I[i, j] = C[j, 0] * lobes_B[i, 0] + C[j, 1] * lobes_B[i, 1] + C[j, 2] * lobes_B[i, 2]
        dc[i] = h0 + (r_I[i, 0] * n[0] + r_I[i, 1] * n[1] + r_I[i, 2] * n[2])
        pe = min(max(R - dc[i], 0.0), R)
        pen[i] = pe
        vcap += math.pi * pe * pe * (3.0 * R - pe) / 3.0
        if pe > 0.0:
            nhit += 1
    pg = p0 * (V0 / (V0 - vcap)) ** gamma - p_amb
    fn_total = 0.0
    if nhit > 0:
        idx = np.empty(nhit, np.int64)
        k = 0
        for i in range(nl):
            if pen[i] > 0.0:
                idx[k] = i
                k += 1
        rc = np.empty((nhit, 3))
        a = np.empty(nhit)
        a2 = np.empty(nhit)
        for k in range(nhit):
            i = idx[k]
            pe = pen[i]
            for j in range(3):
                rc[k, j] = r_I[i, j] - dc[i] * n[j]
            a2[k] = 2.0 * R * pe - pe * pe
            a[k] = math.sqrt(a2[k])
        area = np.empty(nhit)
        footprint_areas(rc, a, geo[6:9], geo[9:12], area)
        for k in range(nhit):
            fn_total += _membrane(pg, area[k], rc[k], n[0], n[1], n[2], v, w_I, damp, mu, F, T_I)

    # body vertices (rotated once, used for rocks and ramp)
    nv = verts_B.shape[0]
    rv = np.empty((nv, 3))
    for i in range(nv):
        for j in range(3):
            rv[i, j] = C[j, 0] * verts_B[i, 0] + C[j, 1] * verts_B[i, 1] + C[j, 2] * verts_B[i, 2]

    # rocks: lobes and body vertices against rigid spheres
    bpen_r = 0.0
    nr = rock_r.shape[0]
    if nr > 0:
        # rocks that a lobe or a vertex can reach from the CM (a conservative cull: a rock farther
        # than the farthest lobe/vertex + radii + 1 mm from the CM touches nothing; skipping it
        # changes no number)
        reach = 0.0
        for i in range(nl):
            reach = max(reach, math.sqrt(r_I[i, 0] ** 2 + r_I[i, 1] ** 2 + r_I[i, 2] ** 2) + R)
        for i in range(nv):
            reach = max(reach, math.sqrt(rv[i, 0] ** 2 + rv[i, 1] ** 2 + rv[i, 2] ** 2))
        near = np.empty(nr, np.int64)
        nn = 0
        for j in range(nr):
            d0 = p[0] - rock_c[j, 0]
            d1 = p[1] - rock_c[j, 1]
            d2 = p[2] - rock_c[j, 2]
            if math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) < reach + rock_r[j] + 1e-3:
                near[nn] = j
                nn += 1
        rcr = np.empty(3)
        for i in range(nl):
            x0 = p[0] + r_I[i, 0]
            x1 = p[1] + r_I[i, 1]
            x2 = p[2] + r_I[i, 2]
            for jj in range(nn):
                j = near[jj]
                d0 = x0 - rock_c[j, 0]
                d1 = x1 - rock_c[j, 1]
                d2 = x2 - rock_c[j, 2]
                dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                pr = R + rock_r[j] - dist
                if pr > 0.0:
                    u0, u1, u2 = d0 / dist, d1 / dist, d2 / dist
                    Re = R * rock_r[j] / (R + rock_r[j])
                    pe = min(pr, Re)
                    area = math.pi * (2.0 * Re * pe - pe * pe)
                    rcr[0] = rock_c[j, 0] + u0 * rock_r[j] - p[0]
                    rcr[1] = rock_c[j, 1] + u1 * rock_r[j] - p[1]
                    rcr[2] = rock_c[j, 2] + u2 * rock_r[j] - p[2]
                    fn_total += _membrane(pg, area, rcr, u0, u1, u2, v, w_I, damp, mu, F, T_I)
        found = False
        for i in range(nv):
            for jj in range(nn):
                j = near[jj]
                d0 = p[0] + rv[i, 0] - rock_c[j, 0]
                d1 = p[1] + rv[i, 1] - rock_c[j, 1]
                d2 = p[2] + rv[i, 2] - rock_c[j, 2]
                dn = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                dvr = dn - rock_r[j]
                if dvr < 0.0:
                    u0, u1, u2 = d0 / dn, d1 / dn, d2 / dn
                    vv0 = v[0] + (w_I[1] * rv[i, 2] - w_I[2] * rv[i, 1])
                    vv1 = v[1] + (w_I[2] * rv[i, 0] - w_I[0] * rv[i, 2])
                    vv2 = v[2] + (w_I[0] * rv[i, 1] - w_I[1] * rv[i, 0])
                    fb = max(-k_body * dvr - c_body * (vv0 * u0 + vv1 * u1 + vv2 * u2), 0.0)
                    f0, f1, f2 = fb * u0, fb * u1, fb * u2
                    F[0] += f0
                    F[1] += f1
                    F[2] += f2
                    T_I[0] += rv[i, 1] * f2 - rv[i, 2] * f1
                    T_I[1] += rv[i, 2] * f0 - rv[i, 0] * f2
                    T_I[2] += rv[i, 0] * f1 - rv[i, 1] * f0
                    if not found or -dvr > bpen_r:
                        bpen_r = -dvr
                    found = True

    # body vertices against the ramp (stiff penalty)
    dvmin = math.inf
    for i in range(nv):
        dvi = h0 + (rv[i, 0] * n[0] + rv[i, 1] * n[1] + rv[i, 2] * n[2])
        dvmin = min(dvmin, dvi)
    bpen = max(0.0, -dvmin, bpen_r)
    if bpen > 0.0:
        for i in range(nv):
            dvi = h0 + (rv[i, 0] * n[0] + rv[i, 1] * n[1] + rv[i, 2] * n[2])
            if dvi < 0.0:
                vv0 = v[0] + (w_I[1] * rv[i, 2] - w_I[2] * rv[i, 1])
                vv1 = v[1] + (w_I[2] * rv[i, 0] - w_I[0] * rv[i, 2])
                vv2 = v[2] + (w_I[0] * rv[i, 1] - w_I[1] * rv[i, 0])
                fb = max(-k_body * dvi - c_body * (vv0 * n[0] + vv1 * n[1] + vv2 * n[2]), 0.0)
                f0, f1, f2 = fb * n[0], fb * n[1], fb * n[2]
                F[0] += f0
                F[1] += f1
                F[2] += f2
                T_I[0] += rv[i, 1] * f2 - rv[i, 2] * f1
                T_I[1] += rv[i, 2] * f0 - rv[i, 0] * f2
                T_I[2] += rv[i, 0] * f1 - rv[i, 1] * f0

    # bungee (until the hammer cuts it)
    if not cut:
        ra = np.empty(3)
        for j in range(3):
            ra[j] = C[j, 0] * rig[3] + C[j, 1] * rig[4] + C[j, 2] * rig[5]
        xa0, xa1, xa2 = p[0] + ra[0], p[1] + ra[1], p[2] + ra[2]
        d0 = rig[0] - xa0
        d1 = rig[1] - xa1
        d2 = rig[2] - xa2
        L = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        cf = count * _poly(coeffs, max(L - rest, 0.0))
        f0, f1, f2 = cf * d0 / L, cf * d1 / L, cf * d2 / L
        F[0] += f0
        F[1] += f1
        F[2] += f2
        l0, l1, l2 = xa0 - p[0], xa1 - p[1], xa2 - p[2]
        T_I[0] += l1 * f2 - l2 * f1
        T_I[1] += l2 * f0 - l0 * f2
        T_I[2] += l0 * f1 - l1 * f0

    for i in range(3):
        T_B[i] = C[0, i] * T_I[0] + C[1, i] * T_I[1] + C[2, i] * T_I[2]
    return fn_total, pg, bpen


@njit
def rhs(y, cut, lobes_B, verts_B, geo, rock_c, rock_r, rig, coeffs, sc, J, Jinv):
    """State derivative (13,) of ``y`` (13,) — as ``ForceModel.rhs``: [v, a, q̇, ω̇] with a = F/m + g."""
    F = np.empty(3)
    T = np.empty(3)
    pen = np.empty(lobes_B.shape[0])
    evaluate(y, cut, lobes_B, verts_B, geo, rock_c, rock_r, rig, coeffs, sc, F, T, pen)
    m = sc[11]
    out = np.empty(13)
    out[0], out[1], out[2] = y[3], y[4], y[5]
    out[3] = F[0] / m
    out[4] = F[1] / m
    out[5] = F[2] / m - G0_MPS2
    qn = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
    px, py, pz, pw = y[6] / qn, y[7] / qn, y[8] / qn, y[9] / qn
    qx, qy, qz = y[10], y[11], y[12]
    out[6] = 0.5 * (pw * qx + py * qz - pz * qy)
    out[7] = 0.5 * (pw * qy - px * qz + pz * qx)
    out[8] = 0.5 * (pw * qz + px * qy - py * qx)
    out[9] = 0.5 * (-px * qx - py * qy - pz * qz)
    Jw = np.empty(3)
    for i in range(3):
        Jw[i] = J[i, 0] * qx + J[i, 1] * qy + J[i, 2] * qz
    e0 = T[0] - (qy * Jw[2] - qz * Jw[1])
    e1 = T[1] - (qz * Jw[0] - qx * Jw[2])
    e2 = T[2] - (qx * Jw[1] - qy * Jw[0])
    for i in range(3):
        out[10 + i] = Jinv[i, 0] * e0 + Jinv[i, 1] * e1 + Jinv[i, 2] * e2
    return out


@njit
def evaluate_many(Y, cut, lobes_B, verts_B, geo, rock_c, rock_r, rig, coeffs, sc):
    """:func:`evaluate` over a history: Y (n, 13) states, cut (n,) bool.

    Returns F (n,3) [N, SPF], T_B (n,3) [N m, body], fn (n,) [N], pg (n,) [Pa],
    pen (n, n_l) [m], bpen (n,) [m]."""
    n = Y.shape[0]
    F = np.empty((n, 3))
    T = np.empty((n, 3))
    fn = np.empty(n)
    pg = np.empty(n)
    pen = np.empty((n, lobes_B.shape[0]))
    bpen = np.empty(n)
    for k in range(n):
        fn[k], pg[k], bpen[k] = evaluate(
            Y[k], cut[k], lobes_B, verts_B, geo, rock_c, rock_r, rig, coeffs, sc, F[k], T[k], pen[k]
        )
    return F, T, fn, pg, pen, bpen


@njit
def fly(p0, anchor, rest, coeffs, count, m, n, point, h_c, cut_lead_s, dt, n_max):
    """Point-mass flight of the release design (``design_release``'s reference ``fly``).

    From rest at p0 (3) [m, SPF] under gravity and the test-plan bungee (attachment at the CM,
    anchor (3) [m, SPF], rest length [m], per-bungee coeffs, count) until the CM comes within h_c
    [m] of the ramp plane (normal n (3), point (3)); the bungee is released ``cut_lead_s`` [s]
    before the predicted contact. Explicit (semi-implicit Euler) steps of dt [s], at most n_max;
    the crossing is interpolated inside the last step. Returns (p (3) [m], v (3) [m/s], t [s],
    cut time [s] or −1 if never cut).
    """
    p = p0.copy()
    v = np.zeros(3)
    cut_t = -1.0
    t = 0.0
    h_prev = (p[0] - point[0]) * n[0] + (p[1] - point[1]) * n[1] + (p[2] - point[2]) * n[2]
    acc = np.empty(3)
    v_new = np.empty(3)
    p_new = np.empty(3)
    for _ in range(n_max):
        acc[0] = 0.0
        acc[1] = 0.0
        acc[2] = -G0_MPS2
        if cut_t < 0.0:
            d0 = anchor[0] - p[0]
            d1 = anchor[1] - p[1]
            d2 = anchor[2] - p[2]
            L = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            cf = count * _poly(coeffs, max(L - rest, 0.0))
            acc[0] += cf * d0 / L / m
            acc[1] += cf * d1 / L / m
            acc[2] += cf * d2 / L / m
        vn = -(v[0] * n[0] + v[1] * n[1] + v[2] * n[2])
        if cut_t < 0.0 and vn > 0 and (h_prev - h_c) / vn < cut_lead_s:
            cut_t = t
        for j in range(3):
            v_new[j] = v[j] + acc[j] * dt
            p_new[j] = p[j] + v_new[j] * dt
        h = (p_new[0] - point[0]) * n[0] + (p_new[1] - point[1]) * n[1] + (p_new[2] - point[2]) * n[2]
        if h <= h_c:
            frac = (h_prev - h_c) / (h_prev - h)
            for j in range(3):
                p[j] = p[j] + frac * (p_new[j] - p[j])
                v[j] = v[j] + frac * (v_new[j] - v[j])
            t += frac * dt
            break
        for j in range(3):
            p[j] = p_new[j]
            v[j] = v_new[j]
        h_prev = h
        t += dt
    return p, v, t, cut_t
