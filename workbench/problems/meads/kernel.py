"""Compiled (numba) MEADS EKF: measurement, transition, forward pass and RTS smoother.

The filter's numpy path (``compiled=False`` of :func:`.ekf.run_pass`: ``estimation.ekf.run_filter``
with :func:`.ekf.make_transition` and :func:`.ekf.make_pressure_model`, ``estimation.smoother.rts_smooth``)
is the reference; it spends its time in the overhead of small array operations on one state at a
time, not in arithmetic. :func:`forward_kernel` runs a whole pass in one call (its steps
:func:`transition_kernel` and the iterated Joseph update with :func:`measurement_kernel`), and
:func:`rts_kernel` the smoother's recursion. :func:`pressure_kernel`, the core of the measurement,
does the numpy path's arithmetic in the same order of operations:

1. the body-axis air velocity ``u = (I − [δθ×]) C_B_M (v_M + Ω ẑ × p_M − C_M_N w_N)`` at the state
   and its central-difference Jacobian over position, velocity, attitude error and wind with the
   filter's perturbations (``ekf.EPS``), exactly as ``estimation.ekf.numeric_jacobian_batched``
   forms it (the other state columns are zero: ``u`` does not depend on them);
2. the 11 points z = (u, ln p∞, ln ρ∞) ± ``eps_z`` → (α, β, q∞, M) (``ekf._freestream``);
3. the port pressures through the "mach" set of :func:`workbench.problems.meads.airdata.pressure_model`:
   Newtonian (Eq. 1–3 with R(M) of Eq. 2, ``models.flush_airdata.newtonian_pressure``) or the
   estimator's table ``p∞ + q∞ Cp(M, α_T, φ − φ_w, s)`` with the multilinear interpolation and
   edge clamping of :meth:`models.flush_airdata.SurfacePressureTable.cp`;
4. ``p0`` at z and ``∂p/∂z`` by central differences.

The two paths agree to a few units in the last place (``tests/problems/meads/test_kernel.py``,
``test_ekf.py``); libm's and numpy's transcendental functions and summation orders may round
differently, and the iterated update's stop rule turns such differences into ~1e-9 of a pass.
"""

from __future__ import annotations

import math

import numpy as np

from workbench.core.jit import njit
from workbench.estimation.kernels import add_into, cho_solve, copy_matrix, copy_vector, symmetrise
from workbench.problems.meads.state import ILP, ILR, IP, ITH, IV, IW, N_PORTS, N_U_COLS

__all__ = ["pressure_kernel", "measurement_kernel", "flow_kernel", "transition_kernel", "TRANSITION_PARAMS", "N_U_COLS"]

#: the order of the settings in :func:`transition_kernel`'s ``par`` array
TRANSITION_PARAMS = (
    "accel_psd", "attitude_psd", "wind_var_per_km", "vertical_wind_length_km", "vertical_wind_sigma_mps",
    "wind_sigma_mps", "atmosphere_var_per_km", "model_error_sigma", "model_error_order", "model_mach_sigma",
    "model_angle_sigma_rad", "model_angle_mach_low", "model_angle_mach_high", "model_angle_hypersonic_fraction",
    "model_error_mach_length", "model_error_angle_rad", "markov",
)  # fmt: skip

# the state's first columns as compile-time integers (the compiled code indexes element by element)
_P0, _V0, _TH0, _W0 = IP.start, IV.start, ITH.start, IW.start


@njit
def _air_velocity(x, C, omega, out):  # pragma: no cover - compiled
    """Body-axis air velocity (3,) [m/s] of state x (n_x,) with the strapdown C_B_M (3, 3)."""
    px, py, pz = x[_P0], x[_P0 + 1], x[_P0 + 2]
    vgx = x[_V0] + omega * py
    vgy = x[_V0 + 1] + omega * -px
    vgz = x[_V0 + 2]
    r = math.sqrt(px * px + py * py + pz * pz)
    ux, uy, uz = px / r, py / r, pz / r
    ex, ey = -uy, ux  # ẑ × up
    ne = math.sqrt(ex * ex + ey * ey)
    ex, ey = ex / ne, ey / ne
    nx = uy * 0.0 - uz * ey  # up × east (east_z = 0)
    ny = uz * ex - ux * 0.0
    nz = ux * ey - uy * ex
    wn, we, wd = x[_W0], x[_W0 + 1], x[_W0 + 2]
    ax = vgx - (nx * wn + ex * we - ux * wd)
    ay = vgy - (ny * wn + ey * we - uy * wd)
    az = vgz - (nz * wn + 0.0 * we - uz * wd)
    u0 = C[0, 0] * ax + C[0, 1] * ay + C[0, 2] * az
    u1 = C[1, 0] * ax + C[1, 1] * ay + C[1, 2] * az
    u2 = C[2, 0] * ax + C[2, 1] * ay + C[2, 2] * az
    t0, t1, t2 = x[_TH0], x[_TH0 + 1], x[_TH0 + 2]
    out[0] = u0 - (t1 * u2 - t2 * u1)
    out[1] = u1 - (t2 * u0 - t0 * u2)
    out[2] = u2 - (t0 * u1 - t1 * u0)


@njit
def _pressure_ratio(m, g):  # pragma: no cover - compiled
    """R = p∞/p_t (Eq. 2) at Mach m: Rayleigh pitot above 1, isentropic below."""
    m2 = max(m * m, 1e-12)
    if m > 1.0:
        m2s = max(m2, 1.0)
        return (2.0 / ((g + 1.0) * m2s)) ** (g / (g - 1.0)) * ((2.0 * g * m2s - (g - 1.0)) / (g + 1.0)) ** (
            1.0 / (g - 1.0)
        )
    return (1.0 + 0.5 * (g - 1.0) * m2) ** (-g / (g - 1.0))


@njit
def _cell(grid, v):  # pragma: no cover - compiled
    """(i, t): the lower node and the fraction of ``v`` in cell i of ``grid`` (scipy's rule)."""
    n = grid.size
    lo, hi = 0, n  # np.searchsorted(grid, v) (side "left"), bisected: numba's compiles for seconds
    if v != v:
        lo = n
    while lo < hi:
        mid = (lo + hi) >> 1
        if grid[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    i = lo - 1
    if i < 0:
        i = 0
    if i > n - 2:
        i = n - 2
    return i, (v - grid[i]) / (grid[i + 1] - grid[i])


@njit
def _table_cp(gm, ga, gc, gs, values, m, a, c, s):  # pragma: no cover - compiled
    """Cp of :meth:`SurfacePressureTable.cp` at one point (clock wrapped to 0..π, edges clamped)."""
    c = abs(math.atan2(math.sin(c), math.cos(c)))
    m = min(max(m, gm[0]), gm[-1])
    a = min(max(a, ga[0]), ga[-1])
    s = min(max(s, gs[0]), gs[-1])
    i0, t0 = _cell(gm, m)
    i1, t1 = _cell(ga, a)
    i2, t2 = _cell(gc, c)
    i3, t3 = _cell(gs, s)
    out = 0.0
    for b0 in range(2):
        w0 = t0 if b0 else 1.0 - t0
        for b1 in range(2):
            w1 = t1 if b1 else 1.0 - t1
            for b2 in range(2):
                w2 = t2 if b2 else 1.0 - t2
                for b3 in range(2):
                    w3 = t3 if b3 else 1.0 - t3
                    out += values[i0 + b0, i1 + b1, i2 + b2, i3 + b3] * (w0 * w1 * w2 * w3)
    return out


@njit
def pressure_kernel(
    x,
    C,
    eps_x,
    eps_z,
    use,
    gamma,
    omega,
    table_model,
    port_cone,
    port_clock,
    port_s,
    gm,
    ga,
    gc,
    gs,
    values,
):  # pragma: no cover - compiled
    """Port pressures and their Jacobian in z for one filter state.

    ``x`` (n_x,) the EKF state (:mod:`.state`: p_M, v_M [m, m/s] in the planet-centred inertial
    frame, δθ_B [rad], wind NED [m/s], ln p∞, ln ρ∞ at ``ILP``, ``ILR``); ``C`` (3, 3) the
    strapdown C_B_M; ``eps_x`` (n_x,) the state perturbations; ``eps_z`` (5,) those of z = (u_B [m/s], ln p∞,
    ln ρ∞); ``use`` (k,) int port indices; ``gamma``; ``omega`` the planet's rotation rate [rad/s];
    ``table_model`` True: the table ``values`` on grids ``gm`` (Mach), ``ga`` (α_T [rad]), ``gc``
    (relative clock [rad]), ``gs`` (r/Rb); False: Newtonian with the ports' ``port_cone`` [rad];
    ``port_clock`` [rad], ``port_s`` (m,) of every port.

    Returns ``u0`` (3,) [m/s], ``Ju`` (3, N_U_COLS) the Jacobian of u over state columns 0 to N_U_COLS − 1, ``p0`` (k,)
    [Pa] and ``dp_dz`` (k, 5) [Pa per unit of z].
    """
    u0 = np.empty(3)
    Ju = np.empty((3, N_U_COLS))
    up = np.empty(3)
    um = np.empty(3)
    xp = x.copy()
    _air_velocity(x, C, omega, u0)
    for j in range(N_U_COLS):
        e = eps_x[j]
        xp[j] = x[j] + e
        _air_velocity(xp, C, omega, up)
        xp[j] = x[j] - e
        _air_velocity(xp, C, omega, um)
        xp[j] = x[j]
        for r in range(3):
            Ju[r, j] = (up[r] - um[r]) / (2.0 * e)
    k = use.size
    pz = np.empty((11, k))
    z0 = np.array([u0[0], u0[1], u0[2], x[ILP], x[ILR]])
    for row in range(11):
        z = z0.copy()
        if row > 0:
            j = (row - 1) % 5
            z[j] = z[j] + eps_z[j] if row <= 5 else z[j] - eps_z[j]
        V = math.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2])
        a = math.atan2(z[2], z[0])
        b = math.asin(min(max(z[1] / V, -1.0), 1.0))
        p_inf, rho = math.exp(z[3]), math.exp(z[4])
        q = 0.5 * rho * V * V
        M = V / math.sqrt(gamma * p_inf / rho)
        R = _pressure_ratio(M, gamma)
        pt = 2.0 * q / (gamma * R * M * M)
        cb = math.cos(b)
        wu, wv, ww = math.cos(a) * cb, math.sin(b), math.sin(a) * cb
        if table_model:
            at = math.acos(min(max(wu, -1.0), 1.0))
            phw = math.atan2(wv, ww)
            pm = R * pt
            for i in range(k):
                port = use[i]
                cp = _table_cp(gm, ga, gc, gs, values, M, at, port_clock[port] - phw, port_s[port])
                pz[row, i] = pm + q * cp
        else:
            for i in range(k):
                port = use[i]
                sc = math.sin(port_cone[port])
                ct = (
                    wu * math.cos(port_cone[port])
                    + wv * (math.sin(port_clock[port]) * sc)
                    + ww * (math.cos(port_clock[port]) * sc)
                )
                pz[row, i] = pt * ((1.0 - R) * ct * ct + R)
    p0 = pz[0].copy()
    dp_dz = np.empty((k, 5))
    for j in range(5):
        for i in range(k):
            dp_dz[i, j] = (pz[1 + j, i] - pz[6 + j, i]) / (2.0 * eps_z[j])
    return u0, Ju, p0, dp_dz


@njit
def measurement_kernel(
    x,
    C,
    eps_x,
    eps_z,
    use,
    gamma,
    omega,
    table_model,
    port_cone,
    port_clock,
    port_s,
    gm,
    ga,
    gc,
    gs,
    values,
    cols,
):  # pragma: no cover - compiled
    """The filter's measurement: port pressures (k,) [Pa] and their Jacobian H (k, n_c) over the
    carried state x (n_c,), :func:`pressure_kernel` chained with the model-error states as
    ``ekf.make_pressure_model`` assembles them (its numpy path is the reference).

    Arguments as :func:`pressure_kernel` (``eps_x`` over the carried state), and ``cols`` (6,) int:
    the carried-state columns of the first scale factor, the model level, the first model error,
    the first bias, the Mach error and the first flow-angle error (the position, velocity,
    attitude, wind, ln p∞ and ln ρ∞ columns are the full state's)."""
    u0, Ju, p0, dp_dz = pressure_kernel(
        x, C, eps_x, eps_z, use, gamma, omega, table_model, port_cone, port_clock, port_s, gm, ga, gc, gs, values
    )
    i_lam, i_c, i_b, i_bias, i_mm, i_ma = cols[0], cols[1], cols[2], cols[3], cols[4], cols[5]
    k = use.size
    n = x.size
    g_m = np.empty(k)
    for i in range(k):
        g_m[i] = dp_dz[i, 4] - dp_dz[i, 3] - p0[i] + 2.0 * math.exp(x[ILP])
    V = math.sqrt(u0[0] * u0[0] + u0[1] * u0[1] + u0[2] * u0[2])
    hy = math.hypot(u0[0], u0[2])
    ca, sa = u0[0] / hy, u0[2] / hy
    sb = u0[1] / V
    cb = math.sqrt(max(1.0 - sb * sb, 0.0))
    du0 = (V * (-sa * cb), V * 0.0, V * (ca * cb))  # ∂u/∂α
    du1 = (V * (-ca * sb), V * cb, V * (-sa * sb))  # ∂u/∂β
    lev = 1.0 + x[i_c]
    pm = np.empty(k)
    H = np.zeros((k, n))
    for i in range(k):
        ga_ = dp_dz[i, 0] * du0[0] + dp_dz[i, 1] * du0[1] + dp_dz[i, 2] * du0[2]
        gb_ = dp_dz[i, 0] * du1[0] + dp_dz[i, 1] * du1[1] + dp_dz[i, 2] * du1[2]
        pm_i = p0[i] + x[i_mm] * g_m[i] + (ga_ * x[i_ma] + gb_ * x[i_ma + 1])
        port = use[i]
        lam = 1.0 + x[i_lam + port]
        mod = 1.0 + x[i_b + port]
        f = lam * lev * mod
        for j in range(N_U_COLS):
            H[i, j] = f * (dp_dz[i, 0] * Ju[0, j] + dp_dz[i, 1] * Ju[1, j] + dp_dz[i, 2] * Ju[2, j])
        H[i, ILP] = f * dp_dz[i, 3]
        H[i, ILR] = f * dp_dz[i, 4]
        H[i, i_lam + port] = pm_i * lev * mod
        H[i, i_c] = pm_i * lam * mod
        H[i, i_b + port] = pm_i * lam * lev
        H[i, i_bias + port] = 1.0
        H[i, i_mm] = g_m[i] * lam * lev * mod
        H[i, i_ma] = ga_ * f
        H[i, i_ma + 1] = gb_ * f
        pm[i] = pm_i * lam * lev * mod + x[i_bias + port]
    return pm, H


@njit
def flow_kernel(x, C, omega, gamma):  # pragma: no cover - compiled
    """(α [rad], β [rad], Mach) of one EKF state ``x`` (n_x,) with the strapdown C_B_M ``C`` (3, 3),
    the planet's rotation rate ``omega`` [rad/s] and ``gamma``: ``ekf.air_data_of_state`` for one
    state (the transition's flight-condition distance asks for it twice a step)."""
    u = np.empty(3)
    _air_velocity(x, C, omega, u)
    V = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    a = math.atan2(u[2], u[0])
    b = math.asin(min(max(u[1] / V, -1.0), 1.0))
    return a, b, V / math.sqrt(gamma * math.exp(x[ILP]) / math.exp(x[ILR]))


@njit
def _angle_sigma(par, mach):  # pragma: no cover - compiled
    """``ekf.angle_sigma``: the flow-angle error's 1σ [rad] at ``mach``."""
    lo, hi = par[11], par[12]
    w = min(max((mach - lo) / (hi - lo), 0.0), 1.0)
    return par[10] * (1.0 + w * (par[13] - 1.0))


@njit
def transition_kernel(x, k, dt, p_M, v_M, G, Fvt, Rb, C_B_M, gm, omega, gamma, par, cols):  # pragma: no cover
    """One step k−1 → k of the MEADS EKF (``ekf.make_transition``'s numpy path is the reference):
    ``(x1 (n_c,), F (n_c, n_c), Q (n_c, n_c))`` over the carried state x (n_c,).

    ``dt`` [s]; the strapdown ``p_M``, ``v_M`` (n, 3) [m, m/s] and ``C_B_M`` (n, 3, 3); per step
    (n − 1, 3, 3): the point-mass gravity gradient ``G`` [1/s²] at p_M[k−1], the specific-force tilt
    ``Fvt`` and the body rotation ``Rb`` over the step; ``gm`` [m³/s²], ``omega`` [rad/s],
    ``gamma``; ``par`` the settings in :data:`TRANSITION_PARAMS` order; ``cols`` (4,) int the
    carried-state columns of the first model error b, its first rate b' (−1: first order), the Mach
    error and the first flow-angle error (the other columns are the full state's)."""
    n = x.size
    km1 = k - 1
    i_b, i_bd, i_mm, i_ma = cols[0], cols[1], cols[2], cols[3]
    x1 = x.copy()
    F = np.zeros((n, n))  # the identity (numba's np.eye compiles its k and dtype handling too)
    for i in range(n):
        F[i, i] = 1.0
    Q = np.zeros((n, n))
    dp = np.empty(3)
    dv = np.empty(3)
    for i in range(3):
        dp[i] = x[_P0 + i] - p_M[km1, i]
        dv[i] = x[_V0 + i] - v_M[km1, i]
    for i in range(3):
        x1[_P0 + i] = p_M[k, i] + dp[i] + dv[i] * dt
        gdp = G[km1, i, 0] * dp[0] + G[km1, i, 1] * dp[1] + G[km1, i, 2] * dp[2]
        ft = Fvt[km1, i, 0] * x[_TH0] + Fvt[km1, i, 1] * x[_TH0 + 1] + Fvt[km1, i, 2] * x[_TH0 + 2]
        x1[_V0 + i] = v_M[k, i] + dv[i] + gdp * dt + ft
        x1[_TH0 + i] = Rb[km1, i, 0] * x[_TH0] + Rb[km1, i, 1] * x[_TH0 + 1] + Rb[km1, i, 2] * x[_TH0 + 2]
    r0 = math.sqrt(x[_P0] * x[_P0] + x[_P0 + 1] * x[_P0 + 1] + x[_P0 + 2] * x[_P0 + 2])
    r1 = math.sqrt(x1[_P0] * x1[_P0] + x1[_P0 + 1] * x1[_P0 + 1] + x1[_P0 + 2] * x1[_P0 + 2])
    dh = r1 - r0
    c = gm / r0**2 * math.exp(x[ILR] - x[ILP])
    x1[ILP] = x[ILP] - c * dh
    x1[ILR] = x[ILR] - c * dh
    for i in range(3):
        F[_P0 + i, _V0 + i] = dt
        for j in range(3):
            F[_V0 + i, _P0 + j] = G[km1, i, j] * dt
            F[_V0 + i, _TH0 + j] = Fvt[km1, i, j]
            F[_TH0 + i, _TH0 + j] = Rb[km1, i, j]
    for row in (ILP, ILR):
        for i in range(3):
            u0 = x[_P0 + i] / r0
            u1 = x1[_P0 + i] / r1
            F[row, _P0 + i] = -c * (u1 - u0)
            F[row, _V0 + i] = -c * (u1 * dt)
        F[row, ILP] = F[row, ILP] + c * dh
        F[row, ILR] = F[row, ILR] - c * dh
    qa = par[0]
    for i in range(3):
        Q[_P0 + i, _P0 + i] = qa * dt**3 / 3.0
        Q[_P0 + i, _V0 + i] = qa * dt**2 / 2.0
        Q[_V0 + i, _P0 + i] = qa * dt**2 / 2.0
        Q[_V0 + i, _V0 + i] = qa * dt
        Q[_TH0 + i, _TH0 + i] = par[1] * dt
    km = abs(dh) / 1e3
    Q[_W0, _W0] = par[2] * km
    Q[_W0 + 1, _W0 + 1] = par[2] * km
    if par[3] > 0.0:
        phi_w = math.exp(-km / par[3])
        x1[_W0 + 2] = phi_w * x[_W0 + 2]
        F[_W0 + 2, _W0 + 2] = phi_w
        Q[_W0 + 2, _W0 + 2] = par[4] ** 2 * (1.0 - phi_w**2)
    else:
        Q[_W0 + 2, _W0 + 2] = par[2] * km * (par[4] / par[5]) ** 2
    Q[ILP, ILP] = par[6] * km
    Q[ILR, ILR] = par[6] * km
    dist = 0.0
    m0 = m1 = 0.0
    if par[16] > 0.0:
        a0, b0, m0 = flow_kernel(x, C_B_M[km1], omega, gamma)
        a1, b1, m1 = flow_kernel(x1, C_B_M[k], omega, gamma)
        d_angle = (abs(a1 - a0) + abs(b1 - b0)) / par[15]
        dist = abs(m1 - m0) / par[14] + d_angle
    if par[7] > 0.0:
        e = math.exp(-dist)
        s2 = par[7] ** 2
        if par[8] == 2.0:
            p00, p01, p10, p11 = e * (1.0 + dist), e * dist, e * -dist, e * (1.0 - dist)
            s2d = s2
        else:
            p00, p01, p10, p11 = e, 0.0, 0.0, 0.0
            s2d = 0.0
        # Q = P∞ − Φ P∞ Φᵀ with P∞ = diag(s2, s2d)
        q00 = s2 - (p00 * s2 * p00 + p01 * s2d * p01)
        q01 = 0.0 - (p00 * s2 * p10 + p01 * s2d * p11)
        q11 = s2d - (p10 * s2 * p10 + p11 * s2d * p11)
        for i in range(N_PORTS):
            b = x[i_b + i]
            if i_bd >= 0:
                bd = x[i_bd + i]
                x1[i_b + i] = p00 * b + p01 * bd
                x1[i_bd + i] = p10 * b + p11 * bd
                F[i_b + i, i_bd + i] = p01
                F[i_bd + i, i_b + i] = p10
                F[i_bd + i, i_bd + i] = p11
                Q[i_b + i, i_bd + i] = q01
                Q[i_bd + i, i_b + i] = q01
                Q[i_bd + i, i_bd + i] = q11
            else:
                x1[i_b + i] = p00 * b
            F[i_b + i, i_b + i] = p00
            Q[i_b + i, i_b + i] = q00
    if par[9] > 0.0:
        phi = math.exp(-dist)
        x1[i_mm] = phi * x[i_mm]
        F[i_mm, i_mm] = phi
        Q[i_mm, i_mm] = par[9] ** 2 * (1.0 - phi**2)
    if par[10] > 0.0:
        s0, s1 = _angle_sigma(par, m0), _angle_sigma(par, m1)
        phi = math.exp(-dist)
        f = phi * s1 / s0 if s0 > 0.0 else 0.0
        for i in range(2):
            x1[i_ma + i] = f * x[i_ma + i]
            F[i_ma + i, i_ma + i] = f
            Q[i_ma + i, i_ma + i] = s1**2 * (1.0 - phi**2)
    return x1, F, Q


@njit
def _cho(S, L):  # pragma: no cover - compiled
    """Lower Cholesky factor of S (m, m) into L; False when S is not positive definite."""
    m = S.shape[0]
    for j in range(m):
        s = S[j, j]
        for c in range(j):
            s -= L[j, c] * L[j, c]
        if not s > 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, m):
            v = S[i, j]
            for c in range(j):
                v -= L[i, c] * L[j, c]
            L[i, j] = v / L[j, j]
    return True


@njit
def _cho_solve(L, B):  # pragma: no cover - compiled
    """X with L Lᵀ X = B for B (m, r) (a new array); row operations, each element's sums in the
    order of a column-by-column substitution."""
    m, r = B.shape
    X = B.copy()
    for i in range(m):
        for c in range(i):
            f = L[i, c]
            for j in range(r):
                X[i, j] -= f * X[c, j]
        d = L[i, i]
        for j in range(r):
            X[i, j] = X[i, j] / d
    for i in range(m - 1, -1, -1):
        for c in range(i + 1, m):
            f = L[c, i]
            for j in range(r):
                X[i, j] -= f * X[c, j]
        d = L[i, i]
        for j in range(r):
            X[i, j] = X[i, j] / d
    return X


@njit
def forward_kernel(
    x0, P0, t, p_M, v_M, G, Fvt, Rb, C_B_M, gm, omega, gamma, par, tcols,
    eps_x, eps_z, table_model, port_cone, port_clock, port_s, gm_, ga, gc, gs, values, mcols,
    z_all, r_all, usable, iterations, step_tol, consider,
    x_prior, P_prior, x_post, P_post, F_hist, Q_hist, keep_q, zp_out, y_out, S_out, nis_out,
):  # pragma: no cover - compiled  # fmt: skip
    """The MEADS forward EKF over the n pressure times in one compiled call: the same recursion as
    ``estimation.ekf.run_filter`` with the iterated update of ``estimation.ekf.update`` (Joseph
    form, gain projection, absolute step rule), :func:`transition_kernel` and
    :func:`measurement_kernel` (their arguments ``p_M`` … ``tcols`` and ``eps_x`` … ``mcols``).

    ``z_all``, ``r_all`` (n, m) the pressures [Pa] and their variances [Pa²]; ``usable`` (n, m)
    bool; ``iterations``; ``step_tol`` (n_c,); ``consider`` (n_c,) bool the states whose gain is
    projected to zero.  Fills ``x_prior``, ``x_post`` (n, n_c), ``P_prior``, ``P_post``,
    ``F_hist`` (n, n_c, n_c), ``Q_hist`` (when ``keep_q``), and per step with a measurement
    ``zp_out``, ``y_out`` (n, m), ``S_out`` (n, m, m) in the used ports (NaN-filled by the caller)
    and ``nis_out`` (n,).  Returns ``(status, k)``: 0 done; 1 S not positive definite, 2 a
    non-finite innovation or NIS, 3 an iterate's S not positive definite, at step k."""
    n = t.size
    n_c = x0.size
    m_all = z_all.shape[1]
    x = x0.copy()
    P = P0.copy()
    use_buf = np.empty(m_all, dtype=np.int64)
    for k in range(n):
        if k > 0:
            x, F, Q = transition_kernel(
                x, k, t[k] - t[k - 1], p_M, v_M, G, Fvt, Rb, C_B_M, gm, omega, gamma, par, tcols
            )
            P = (F @ P) @ F.T
            add_into(P, Q)
            symmetrise(P)
            copy_matrix(F, F_hist[k])
            if keep_q:
                copy_matrix(Q, Q_hist[k])
        else:
            for i in range(n_c):
                for j in range(n_c):
                    F_hist[0, i, j] = 1.0 if i == j else 0.0
                    if keep_q:
                        Q_hist[0, i, j] = 0.0
        copy_vector(x, x_prior[k])
        copy_matrix(P, P_prior[k])
        m = 0
        for j in range(m_all):
            if usable[k, j]:
                use_buf[m] = j
                m += 1
        if m == 0:
            copy_vector(x, x_post[k])
            copy_matrix(P, P_post[k])
            continue
        use = use_buf[:m].copy()
        z = np.empty(m)
        R = np.zeros((m, m))
        for i in range(m):
            z[i] = z_all[k, use[i]]
            R[i, i] = r_all[k, use[i]]
        C = C_B_M[k]
        # the iterated update: iteration 0 linearises at the prior x (innovation y, S, NIS recorded
        # from it), each further one at the previous iterate until the step changes less than step_tol
        y = np.empty(m)
        r = np.empty(m)
        w = np.empty(m)
        nis = 0.0
        zp = y
        S = R
        x_i = x
        x_new = x
        dx = x
        K = np.zeros((n_c, m))
        Hk = np.zeros((m, n_c))
        PHt = K
        for it in range(max(iterations, 1)):
            zp_i, H_i = measurement_kernel(
                x_i, C, eps_x, eps_z, use, gamma, omega, table_model, port_cone, port_clock, port_s,
                gm_, ga, gc, gs, values, mcols,
            )  # fmt: skip
            finite = True
            for i in range(m):
                r[i] = z[i] - zp_i[i]
                if not math.isfinite(r[i]):
                    finite = False
            if it > 0 and not finite:
                break
            if it == 0 and not finite:  # before S, as the reference (a NaN in S is no "not PD")
                return 2, k
            PHt_i = P @ H_i.T
            S_i = H_i @ PHt_i
            add_into(S_i, R)
            L = np.zeros((m, m))
            if not _cho(S_i, L):
                return (1 if it == 0 else 3), k
            if it == 0:
                zp, S = zp_i, S_i
                copy_vector(r, y)
                cho_solve(L, y, w)
                for i in range(m):
                    nis += y[i] * w[i]
                if not math.isfinite(nis):
                    return 2, k
            for i in range(n_c):
                if consider[i]:
                    for a in range(m):
                        K[i, a] = 0.0
                else:
                    cho_solve(L, PHt_i[i], K[i])
            Hk, PHt = H_i, PHt_i
            if it > 0:  # r_i − H (x − x_i)
                e = np.empty(n_c)
                for i in range(n_c):
                    e[i] = x[i] - x_i[i]
                dr = Hk @ e
                for i in range(m):
                    r[i] -= dr[i]
            dx_new = K @ r
            x_new = np.empty(n_c)
            for i in range(n_c):
                x_new[i] = x[i] + dx_new[i]
            done = it > 0
            if it > 0:
                for i in range(n_c):
                    if not abs(dx_new[i] - dx[i]) < step_tol[i]:
                        done = False
            dx = dx_new
            x_i = x_new
            if done:
                break
        # Joseph form: M = P − K (P Hᵀ)ᵀ, P⁺ = M − (M Hᵀ − K R) Kᵀ, symmetrised
        M = K @ PHt.T
        for i in range(n_c):
            for j in range(n_c):
                M[i, j] = P[i, j] - M[i, j]
        D = M @ Hk.T
        KR = K @ R
        for i in range(n_c):
            for a in range(m):
                D[i, a] = D[i, a] - KR[i, a]
        P = D @ K.T
        for i in range(n_c):
            for j in range(n_c):
                P[i, j] = M[i, j] - P[i, j]
        symmetrise(P)
        x = x_new
        for i in range(m):
            zp_out[k, use[i]] = zp[i]
            y_out[k, use[i]] = y[i]
            for j in range(m):
                S_out[k, use[i], use[j]] = S[i, j]
        nis_out[k] = nis
        copy_vector(x, x_post[k])
        copy_matrix(P, P_post[k])
    return 0, n


@njit
def rts_kernel(x_prior, P_prior, x_post, P_post, G, dsq, consider, xs, Ps):  # pragma: no cover - compiled
    """The backward recursion of ``estimation.smoother.rts_smooth`` (its reference) for additive
    states whose predicted variances are all positive: gain on the Jacobi-scaled ``P_prior``
    (``dsq`` (n, n_c) the square roots of its diagonal), ``consider`` (n_c,) bool constant consider
    parameters (G's rows the selection of themselves).  ``G`` (n, n_c, n_c) holds
    ``F[k+1] P_post[k]`` on entry and the gains on return; fills ``xs`` (n, n_c), ``Ps``.
    Returns ``(status, k)``: 0 done; 1 a scaled ``P_prior[k+1]`` or 2 a smoothed covariance at
    step k not positive definite (the caller reruns the reference for its diagnosis)."""
    n, n_c = x_post.shape
    copy_vector(x_post[n - 1], xs[n - 1])
    copy_matrix(P_post[n - 1], Ps[n - 1])
    L = np.zeros((n_c, n_c))
    if not _cho(Ps[n - 1], L):
        return 2, n - 1
    for k in range(n - 2, -1, -1):
        Pp = P_prior[k + 1]
        d = dsq[k + 1]
        Sc = np.empty((n_c, n_c))
        rhs = np.empty((n_c, n_c))
        for i in range(n_c):
            for j in range(n_c):
                Sc[i, j] = Pp[i, j] / (d[i] * d[j])
                rhs[i, j] = G[k, i, j] / d[i]
        if not _cho(Sc, L):
            return 1, k
        Gt = _cho_solve(L, rhs)
        for i in range(n_c):
            for j in range(n_c):
                Gt[i, j] = Gt[i, j] / d[i]
        for c in range(n_c):
            if consider[c]:
                for i in range(n_c):
                    Gt[i, c] = 0.0
        for c in range(n_c):
            if consider[c]:
                Gt[c, c] = 1.0
        Gk = np.empty((n_c, n_c))
        e = np.empty(n_c)
        for i in range(n_c):
            e[i] = xs[k + 1, i] - x_prior[k + 1, i]
            for j in range(n_c):
                Gk[i, j] = Gt[j, i]
                rhs[i, j] = Ps[k + 1, i, j] - Pp[i, j]
        dx = Gk @ e
        for i in range(n_c):
            xs[k, i] = x_post[k, i] + dx[i]
        A = (Gk @ rhs) @ Gt
        add_into(A, P_post[k])
        symmetrise(A)
        for i in range(n_c):
            if not A[i, i] > 0.0:
                return 2, k
        if not _cho(A, L):
            return 2, k
        copy_matrix(A, Ps[k])
        copy_matrix(Gk, G[k])
    return 0, 0
