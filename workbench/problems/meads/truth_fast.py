"""Compiled (numba) right-hand side of the MEADS truth simulator: the fast path of :mod:`.truth`.

The same translational dynamics as the Python reference ``truth.TruthDynamics.accel`` (kept
selectable with ``simulate_entry(..., fast=False)``): point mass + J2 gravity of Mars, the truth's
own tabulated atmosphere (density, temperature) and winds interpolated in altitude, its drag
coefficient ``C_D(M)``, lift ``L/D = 0.24 α_trim/18°`` rolled by the bank profile before the
parachute and the parachute's drag after it.  Every expression is written with the reference's
operations in the reference's order and roundings: the 3-vector dot products as BLAS's ``ddot``
rounds them (a chain of fused multiply-adds), ``tanh`` and ``r**5`` evaluated by numpy itself (its
SIMD functions round differently from libm's; one call back into the interpreter per derivative).
So :func:`rhs` reproduces the reference bit for bit where BLAS and numpy round so (checked on the
development machine: a whole entry identical); elsewhere it differs by rounding, and DOP853's step
control turns that into differences of the integrator's tolerance
(tests/problems/meads/test_truth_fast.py).

Frames and units as in :mod:`.truth`: the Mars-centred inertial frame M (+Z the pole), SI.  The
state is ``y = [p_M (3) m, v_M (3) m/s]``.  Parameters: a flat scalar vector ``sc`` (indices
``SC_*``, filled by ``truth.TruthDynamics.packed``) and the tables ``h_tab`` [m], ``rho_tab``
[kg/m³], ``T_tab`` [K] (the true atmosphere), ``wh`` [m], ``wn``, ``we`` [m/s] (the true wind
north/east), ``bank_t`` [s], ``bank`` [rad] (the bank profile's nodes).
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import objmode, types
from numba.extending import intrinsic

from workbench.core.interp_kernel import interp_at, interp_index
from workbench.core.jit import njit

__all__ = [
    "N_SC",
    "SC_GM",
    "SC_J2K",
    "SC_RREF",
    "SC_OMEGA",
    "SC_GAMMA",
    "SC_R",
    "SC_S",
    "SC_MASS",
    "SC_CDS",
    "SC_ALPHA_HYPER",
    "SC_ALPHA_LOW",
    "SC_T_CHUTE",
    "SC_CHUTE_ON",
    "accel",
    "rhs",
    "mach",
]

# indices of the scalar parameter vector ``sc``
SC_GM, SC_J2K, SC_RREF, SC_OMEGA, SC_GAMMA, SC_R, SC_S, SC_MASS, SC_CDS = 0, 1, 2, 3, 4, 5, 6, 7, 8
SC_ALPHA_HYPER, SC_ALPHA_LOW, SC_T_CHUTE, SC_CHUTE_ON = 9, 10, 11, 12
N_SC = 13
"""Length of the scalar parameter vector."""

_DEG2RAD = math.pi / 180.0  # np.radians' factor
_RAD2DEG = 180.0 / math.pi  # math.degrees' factor


@intrinsic
def _fma(typingctx, a, b, c):
    """``a b + c`` with one rounding (LLVM's fma): the rounding of BLAS's ``ddot`` on 3-vectors."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


@njit
def _dot(a0, a1, a2, b0, b1, b2):
    """``a @ b`` of two 3-vectors rounded as the reference's ``@`` (BLAS ddot: a chain of fma)."""
    return _fma(a2, b2, _fma(a1, b1, a0 * b0))


@njit
def _np_tanh_pow5(x, r):
    """``(np.tanh(x), r**5)`` evaluated by numpy itself, as the reference does (numpy's SIMD tanh
    and power round differently from libm's): one call back into the interpreter."""
    with objmode(th="float64", r5="float64"):
        th = float(np.tanh(x))
        r5 = float((np.array([r]) ** 5)[0])
    return th, r5


@njit
def _interp(x, xp, fp):
    """``np.interp(x, xp, fp)`` for a scalar x and increasing xp (n,), fp (n,), to the bit."""
    return interp_at(interp_index(x, xp), x, xp, fp)


@njit
def _air(p0, p1, p2, v0, v1, v2, sc, h_tab, rho_tab, T_tab, wh, wn, we, out):
    """Air-relative velocity (3) [m/s] in M into ``out[0:3]``, up (3) into ``out[3:6]``; returns
    (altitude h [m], density [kg/m³], temperature [K]) at position p, inertial velocity v."""
    r = math.sqrt(_dot(p0, p1, p2, p0, p1, p2))
    h = r - sc[SC_RREF]
    rho = _interp(h, h_tab, rho_tab)
    T = _interp(h, h_tab, T_tab)
    w_n = _interp(h, wh, wn)
    w_e = _interp(h, wh, we)
    rn = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    rxy = math.sqrt(p0 * p0 + p1 * p1)
    u0, u1, u2 = p0 / rn, p1 / rn, p2 / rn
    e0, e1, e2 = -p1 / rxy, p0 / rxy, 0.0
    n0 = u1 * e2 - u2 * e1
    n1 = u2 * e0 - u0 * e2
    n2 = u0 * e1 - u1 * e0
    w = sc[SC_OMEGA]
    out[0] = v0 - -w * p1 - w_n * n0 - w_e * e0
    out[1] = v1 - w * p0 - w_n * n1 - w_e * e1
    out[2] = v2 - 0.0 - w_n * n2 - w_e * e2
    out[3], out[4], out[5] = u0, u1, u2
    return h, rho, T


@njit
def mach(t, y, sc, h_tab, rho_tab, T_tab, wh, wn, we):
    """Mach number [-] of the truth at time t [s], state y (6,) (the parachute event's quantity)."""
    buf = np.empty(6)
    h, rho, T = _air(y[0], y[1], y[2], y[3], y[4], y[5], sc, h_tab, rho_tab, T_tab, wh, wn, we, buf)
    V = math.sqrt(_dot(buf[0], buf[1], buf[2], buf[0], buf[1], buf[2]))
    return V / math.sqrt(sc[SC_GAMMA] * sc[SC_R] * T)


@njit
def accel(t, y, sc, h_tab, rho_tab, T_tab, wh, wn, we, bank_t, bank, out):
    """Total acceleration [m/s²] in M at time t [s], state y (6,) into ``out`` (3,) (gravity + the
    aerodynamic/parachute acceleration: ``truth.TruthDynamics.accel``'s first output)."""
    buf = np.empty(6)
    p0, p1, p2 = y[0], y[1], y[2]
    h, rho, T = _air(p0, p1, p2, y[3], y[4], y[5], sc, h_tab, rho_tab, T_tab, wh, wn, we, buf)
    V = math.sqrt(_dot(buf[0], buf[1], buf[2], buf[0], buf[1], buf[2]))
    ev0, ev1, ev2 = buf[0] / V, buf[1] / V, buf[2] / V
    m = V / math.sqrt(sc[SC_GAMMA] * sc[SC_R] * T)
    q = 0.5 * rho * V * V
    r2 = p0 * p0 + p1 * p1 + p2 * p2
    rn = math.sqrt(r2)
    th, rn5 = _np_tanh_pow5((m - 3.0) / 3.0, rn)
    cd = 1.45 + 0.2 * th
    drag = q * sc[SC_S] * cd / sc[SC_MASS]
    a0, a1, a2 = -drag * ev0, -drag * ev1, -drag * ev2
    t_chute = sc[SC_T_CHUTE]
    if sc[SC_CHUTE_ON] == 0.0 or t <= t_chute:
        frac = min(max((25.0 - m) / 20.0, 0.0), 1.0)
        ah, al = sc[SC_ALPHA_HYPER], sc[SC_ALPHA_LOW]
        alpha = (ah + (al - ah) * frac) * _DEG2RAD
        ld = 0.24 * (alpha * _RAD2DEG) / 18.0
        up0, up1, up2 = buf[3], buf[4], buf[5]
        d = _dot(up0, up1, up2, ev0, ev1, ev2)
        x0, x1, x2 = up0 - d * ev0, up1 - d * ev1, up2 - d * ev2
        un = math.sqrt(_dot(x0, x1, x2, x0, x1, x2))
        x0, x1, x2 = x0 / un, x1 / un, x2 / un
        s = _interp(t, bank_t, bank)
        cs, ss = math.cos(s), math.sin(s)
        c0 = ev1 * x2 - ev2 * x1
        c1 = ev2 * x0 - ev0 * x2
        c2 = ev0 * x1 - ev1 * x0
        k = ld * drag
        a0 = a0 + k * (cs * x0 + ss * c0)
        a1 = a1 + k * (cs * x1 + ss * c1)
        a2 = a2 + k * (cs * x2 + ss * c2)
    else:
        infl = min(max((t - t_chute) / 1.0, 0.0), 1.0)
        k = infl * q * sc[SC_CDS] / sc[SC_MASS]
        a0, a1, a2 = a0 - k * ev0, a1 - k * ev1, a2 - k * ev2
    z2_r2 = p2**2 / r2
    kj = sc[SC_J2K] / rn5
    gm = sc[SC_GM]
    out[0] = -gm * p0 / (rn * r2) - kj * p0 * (1.0 - 5.0 * z2_r2) + a0
    out[1] = -gm * p1 / (rn * r2) - kj * p1 * (1.0 - 5.0 * z2_r2) + a1
    out[2] = -gm * p2 / (rn * r2) - kj * p2 * (3.0 - 5.0 * z2_r2) + a2


@njit
def rhs(t, y, sc, h_tab, rho_tab, T_tab, wh, wn, we, bank_t, bank):
    """State derivative (6,) = [v_M, total acceleration] of the truth at time t [s], state y (6,)."""
    dy = np.empty(6)
    a = np.empty(3)
    accel(t, y, sc, h_tab, rho_tab, T_tab, wh, wn, we, bank_t, bank, a)
    dy[0], dy[1], dy[2] = y[3], y[4], y[5]
    dy[3], dy[4], dy[5] = a[0], a[1], a[2]
    return dy
