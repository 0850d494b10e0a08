"""Strapdown of an ensemble of initial states through one IMU record: attitude once, translation per member.

Every member of a dispersion (:mod:`workbench.problems.entry.dispersion`) is integrated with the
same IMU inputs and gap bridges, and the attitude equation ``dq/dt = ½ q ⊗ [w_G, 0]`` (like the
quaternion part of the classical RK4 of :func:`workbench.estimation.strapdown.rk4_step`, and the
gap bridge ``q_b = q_a ⊗ q(dCᵀ)``) is linear in q and acts from the right.  So a member's attitude
is ``q_i(t) = q0_i ⊗ Δq(t)``, with ``Δq`` integrated once from the identity (the renormalisation
commutes with the left product by a unit ``q0_i``), and so is every RK4 stage quaternion
``q0_i ⊗ Q_s``.  The rotation of the specific force at a stage, ``C(q0_i ⊗ Q_s) f_s`` in the
component form of :func:`~workbench.estimation.strapdown.rotate` (which, for a stage quaternion of
norm ``s ≠ 1``, equals ``s² R(Q̂_s) f_s + (1 − s²) f_s``), is then ``R0_i a_s + b_s`` with the shared
``a_s = s² R(Q̂_s) f_s`` and ``b_s = (1 − s²) f_s`` (:func:`attitude_track`), and only the
translational RK4 (J2 gravity, a 3x3 product per stage) is done per member
(:func:`integrate_ensemble`).  This is the same RK4 as ``rk4_step`` up to rounding (~1e-16 per
step, relative): a member's positions differ from ``integrate_members``' by floating-point noise.

Three executions of one definition of the per-member maths (:func:`_rk4_member`,
:func:`_gap_member`, plain float arithmetic and ``math.sqrt``), all bit-identical because they do
the same IEEE operations in the same order (no fused multiply-add, no reassociation):

* ``"numba"`` — compiled (``numba.njit(nogil=True, cache=True)``), members in blocks of
  :data:`LANES` whose per-step loop over members LLVM vectorises (AVX2: 4 members per
  instruction), the blocks split over the cores by threads (not numba's OpenMP layer: GNU OpenMP
  does not survive the fork of a process pool); the default when numba imports.  The first call
  after an install or an edit compiles (~3.5 s CPU), later ones load numba's cache;
* ``"numpy"`` — the pure-numpy reference path: the same functions on (m,) arrays per component;
* ``"python"`` — one member at a time on Python floats: the per-trajectory loop baseline.

Units SI, frame M (planet-centred inertial, +Z the pole), ``q_M_G`` scalar-last Hamilton.
"""

from __future__ import annotations

import math
import os
import types
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.core.bodies import Body
from workbench.core.gravity import j2_factor
from workbench.core.rotation import dcm_components, dcm_to_quat, quat_multiply, quat_normalize
from workbench.estimation.strapdown import rotate

try:  # numba is a dependency, but keep the numpy path usable without it
    import numba
    from numba.extending import register_jitable
except ImportError:  # pragma: no cover - exercised only without numba
    numba = None

    def register_jitable(*args, **kwargs):
        """Identity stand-in for :func:`numba.extending.register_jitable`."""
        return args[0] if args and callable(args[0]) else (lambda fn: fn)


__all__ = ["BACKENDS", "HAVE_NUMBA", "AttitudeTrack", "attitude_track", "integrate_ensemble", "default_backend"]

#: The executions of the per-member maths (module docstring).
BACKENDS = ("numba", "numpy", "python")
HAVE_NUMBA = numba is not None
#: Members per block of the compiled kernel (a block's states stay in L1; its loop over members is
#: vectorised by LLVM, 4 doubles per AVX2 register).
LANES = 32
#: Step kinds of an :class:`AttitudeTrack`: an RK4 step, a "relative" or a "paper" gap bridge.
STEP_RK4, STEP_GAP_RELATIVE, STEP_GAP_PAPER = 0, 1, 2


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def default_backend() -> str:
    """``"numba"`` when numba imports, else ``"numpy"``."""
    return "numba" if HAVE_NUMBA else "numpy"


@dataclass(frozen=True)
class AttitudeTrack:
    """What every member shares: the attitude from the identity and the per-stage force terms.

    ``t`` (n,) [s]; ``dq`` (n, 4) ``Δq = q_G0_G`` at the samples (``q_i = q0_i ⊗ Δq``);
    ``kind`` (n−1,) int8 step kinds (:data:`STEP_RK4`, :data:`STEP_GAP_RELATIVE`,
    :data:`STEP_GAP_PAPER`); ``dt`` (n−1,) [s] step lengths ``t[k+1] − t[k]``; ``a``, ``b``
    (n−1, 4, 3) [m/s² for RK4 stages, m/s and m for gaps]: the specific force of RK4 stage s in
    M is ``R0 a[k, s] + b[k, s]`` (``R0 = C_M_G0`` of the member); for a gap step, index 0 holds
    the velocity change ``dv_G`` and index 1 the position change (``dp_rel_G`` or ``dp_G``) in the
    same form; ``bridge_mode`` of the gaps.
    """

    t: np.ndarray
    dq: np.ndarray
    kind: np.ndarray
    dt: np.ndarray
    a: np.ndarray
    b: np.ndarray
    bridge_mode: str


# ---------------------------------------------------------------------------------------------
# shared attitude


def _qdot_f(q, w):
    """``½ q ⊗ [w, 0]`` on Python floats (the operations of ``strapdown._qdot``)."""
    qx, qy, qz, qw = q
    a, b, c = w
    return (
        0.5 * (qw * a + qy * c - qz * b),
        0.5 * (qw * b - qx * c + qz * a),
        0.5 * (qw * c + qx * b - qy * a),
        0.5 * -(qx * a + qy * b + qz * c),
    )


def _split_rot(Q: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(a, b)`` with ``rotate(q0 ⊗ Q, x) = R(q0) a + b`` for any unit q0: ``b = (1 − |Q|²) x``."""
    s2 = np.sum(Q * Q, axis=-1, keepdims=True)
    b = (1.0 - s2) * x
    return rotate(Q, x) - b, b


def attitude_track(imu: Any, bridge_mode: str = "relative") -> AttitudeTrack:
    """Integrate the attitude once from the identity over an IMU record; :class:`AttitudeTrack`.

    ``imu`` with ``t`` (n,) [s], ``f_G`` (n, 3) [m/s²], ``w_G`` (n, 3) [rad/s] and ``gaps``
    (:class:`~workbench.estimation.strapdown.GapBridge`, as
    :func:`~workbench.estimation.strapdown.integrate_members`); ``bridge_mode`` "relative" or
    "paper" (:func:`~workbench.estimation.strapdown.apply_gap`).  The quaternion RK4 of
    :func:`~workbench.estimation.strapdown.rk4_step` (inputs linear between the samples, mid-point
    stages at their mean, renormalised after each step) runs on Python floats; the stage force
    terms are then formed vectorised over the steps.
    """
    from workbench.estimation.strapdown import gap_index

    if bridge_mode not in ("relative", "paper"):
        raise ValueError(f"attitude_track: bridge_mode must be 'relative' or 'paper', got {bridge_mode!r}")
    t = np.asarray(imu.t, dtype=float)
    f = np.asarray(imu.f_G, dtype=float)
    w = np.asarray(imu.w_G, dtype=float)
    n = t.size
    if n < 2:
        raise ValueError("attitude_track: need at least two IMU samples")
    gaps = gap_index(t, getattr(imu, "gaps", ()))
    dq = np.empty((n, 4))
    Qs = np.empty((n - 1, 4, 4))  # stage quaternions
    Fs = np.empty((n - 1, 4, 3))  # stage inputs
    kind = np.zeros(n - 1, dtype=np.int8)
    dts = np.diff(t)
    wl, fl = w.tolist(), f.tolist()
    q = (0.0, 0.0, 0.0, 1.0)
    dq[0] = q
    for k in range(n - 1):
        g = gaps.get(k)
        if g is not None:
            kind[k] = STEP_GAP_RELATIVE if bridge_mode == "relative" else STEP_GAP_PAPER
            dts[k] = float(g.t_b) - float(g.t_a)
            Qs[k] = q
            Fs[k] = 0.0
            Fs[k, 0] = np.asarray(g.dv_G, dtype=float)
            Fs[k, 1] = np.asarray(g.dp_rel_G if bridge_mode == "relative" else g.dp_G, dtype=float)
            qb = quat_normalize(quat_multiply(np.array(q), dcm_to_quat(np.asarray(g.dC, dtype=float).T)))
            q = tuple(qb.tolist())
        else:
            dt = dts[k]
            h, s = 0.5 * dt, dt / 6.0
            w0, w1 = wl[k], wl[k + 1]
            wm = [0.5 * (x + y) for x, y in zip(w0, w1, strict=True)]
            k1 = _qdot_f(q, w0)
            q2 = tuple(x + h * y for x, y in zip(q, k1, strict=True))
            k2 = _qdot_f(q2, wm)
            q3 = tuple(x + h * y for x, y in zip(q, k2, strict=True))
            k3 = _qdot_f(q3, wm)
            q4 = tuple(x + dt * y for x, y in zip(q, k3, strict=True))
            k4 = _qdot_f(q4, w1)
            Qs[k] = (q, q2, q3, q4)
            Fs[k, 0], Fs[k, 3] = fl[k], fl[k + 1]
            Fs[k, 1] = Fs[k, 2] = [0.5 * (x + y) for x, y in zip(fl[k], fl[k + 1], strict=True)]
            q1 = [x + s * (a + 2.0 * (b + c) + d) for x, a, b, c, d in zip(q, k1, k2, k3, k4, strict=True)]
            nq = math.sqrt(q1[0] * q1[0] + q1[1] * q1[1] + q1[2] * q1[2] + q1[3] * q1[3])
            q = (q1[0] / nq, q1[1] / nq, q1[2] / nq, q1[3] / nq)
        dq[k + 1] = q
    a, b = _split_rot(Qs, Fs)
    gap = kind != STEP_RK4
    a[gap, 2:] = 0.0
    b[gap, 2:] = 0.0
    return AttitudeTrack(t=t, dq=dq, kind=kind, dt=dts, a=np.ascontiguousarray(a), b=np.ascontiguousarray(b),
                         bridge_mode=bridge_mode)  # fmt: skip


# ---------------------------------------------------------------------------------------------
# per-member maths (one definition; plain float arithmetic, compiled by numba, or on arrays)


@register_jitable(forceinline=True)
def _accel(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, ax, ay, az, bx, by, bz, gm, j2k):
    """``g_J2(p) + (R0 a + b)``: the velocity derivative at one RK4 stage (operations of
    ``gravity_j2_xyz`` and ``strapdown.derivatives``)."""
    r2 = px * px + py * py + pz * pz
    r = math.sqrt(r2)
    gm_r3 = gm / (r2 * r)
    z2 = 5.0 * (pz * pz) / r2
    k = j2k / (r2 * r2 * r)
    c = gm_r3 + k * (1.0 - z2)
    gx = -c * px
    gy = -c * py
    gz = -(gm_r3 + k * (3.0 - z2)) * pz
    fx = r00 * ax + r01 * ay + r02 * az + bx
    fy = r10 * ax + r11 * ay + r12 * az + by
    fz = r20 * ax + r21 * ay + r22 * az + bz
    return gx + fx, gy + fy, gz + fz


@register_jitable(inline="always")
def _rk4_member(vx, vy, vz, px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, dt, A, B, gm, j2k):
    """One translational RK4 step of a member: returns (v, p) components [m/s, m] after ``dt`` [s].

    ``A``, ``B`` (12,) the step's stage terms (``[stage s, component c]`` at ``3 s + c``); the stage
    order and operations of ``strapdown.rk4_step`` (``h = dt/2``, ``s = dt/6``)."""
    h = 0.5 * dt
    s = dt / 6.0
    k1x, k1y, k1z = _accel(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22,
                           A[0], A[1], A[2], B[0], B[1], B[2], gm, j2k)  # fmt: skip
    v2x, v2y, v2z = vx + h * k1x, vy + h * k1y, vz + h * k1z
    k2x, k2y, k2z = _accel(px + h * vx, py + h * vy, pz + h * vz, r00, r01, r02, r10, r11, r12, r20, r21, r22,
                           A[3], A[4], A[5], B[3], B[4], B[5], gm, j2k)  # fmt: skip
    v3x, v3y, v3z = vx + h * k2x, vy + h * k2y, vz + h * k2z
    k3x, k3y, k3z = _accel(px + h * v2x, py + h * v2y, pz + h * v2z, r00, r01, r02, r10, r11, r12, r20, r21, r22,
                           A[6], A[7], A[8], B[6], B[7], B[8], gm, j2k)  # fmt: skip
    v4x, v4y, v4z = vx + dt * k3x, vy + dt * k3y, vz + dt * k3z
    k4x, k4y, k4z = _accel(px + dt * v3x, py + dt * v3y, pz + dt * v3z, r00, r01, r02, r10, r11, r12, r20, r21, r22,
                           A[9], A[10], A[11], B[9], B[10], B[11], gm, j2k)  # fmt: skip
    return (
        vx + s * (k1x + 2.0 * (k2x + k3x) + k4x),
        vy + s * (k1y + 2.0 * (k2y + k3y) + k4y),
        vz + s * (k1z + 2.0 * (k2z + k3z) + k4z),
        px + s * (vx + 2.0 * (v2x + v3x) + v4x),
        py + s * (vy + 2.0 * (v2y + v3y) + v4y),
        pz + s * (vz + 2.0 * (v2z + v3z) + v4z),
    )


@register_jitable
def _gap_member(vx, vy, vz, px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, dt, A, B, relative):
    """A gap bridge of a member (``strapdown.apply_gap``): ``v + C dv_G``, ``p [+ Δt v] + C dp``."""
    dvx = r00 * A[0] + r01 * A[1] + r02 * A[2] + B[0]
    dvy = r10 * A[0] + r11 * A[1] + r12 * A[2] + B[1]
    dvz = r20 * A[0] + r21 * A[1] + r22 * A[2] + B[2]
    dpx = r00 * A[3] + r01 * A[4] + r02 * A[5] + B[3]
    dpy = r10 * A[3] + r11 * A[4] + r12 * A[5] + B[4]
    dpz = r20 * A[3] + r21 * A[4] + r22 * A[5] + B[5]
    if relative:
        return vx + dvx, vy + dvy, vz + dvz, px + dt * vx + dpx, py + dt * vy + dpy, pz + dt * vz + dpz
    return vx + dvx, vy + dvy, vz + dvz, px + dpx, py + dpy, pz + dpz


# the numpy reference path: the same code objects with numpy's sqrt (elementwise on (m,) arrays)
def _numpy_twins() -> tuple[Callable, Callable, Callable]:
    """(_accel, _rk4_member, _gap_member) as plain Python functions of the same code objects in a
    namespace whose ``math.sqrt`` is numpy's, so they run elementwise on (m,) arrays."""
    ns: dict[str, Any] = {**globals(), "math": types.SimpleNamespace(sqrt=np.sqrt)}
    ns["_accel"] = types.FunctionType(_accel.__code__, ns, "_accel")
    rk4 = types.FunctionType(_rk4_member.__code__, ns, "_rk4_member")
    gap = types.FunctionType(_gap_member.__code__, ns, "_gap_member")
    return ns["_accel"], rk4, gap


_accel_np, _rk4_member_np, _gap_member_np = _numpy_twins()


def _run_python(track: AttitudeTrack, v: np.ndarray, p: np.ndarray, R: np.ndarray, slot: np.ndarray,
                out_v: np.ndarray, out_p: np.ndarray, gm: float, j2k: float) -> None:  # fmt: skip
    """Per member, per step on Python floats (the per-trajectory loop); fills out_v/out_p (k, 3, m)."""
    kind, dts = track.kind.tolist(), track.dt.tolist()
    A, B = track.a.reshape(-1, 12).tolist(), track.b.reshape(-1, 12).tolist()
    slots = slot.tolist()
    m = v.shape[1]
    for i in range(m):
        st = (*v[:, i].tolist(), *p[:, i].tolist())
        Ri = tuple(R[:, i].tolist())
        if slots[0] >= 0:
            out_v[slots[0], :, i], out_p[slots[0], :, i] = st[:3], st[3:]
        for k in range(len(kind)):
            if kind[k] == STEP_RK4:
                st = _rk4_member(*st, *Ri, dts[k], A[k], B[k], gm, j2k)
            else:
                st = _gap_member(*st, *Ri, dts[k], A[k], B[k], kind[k] == STEP_GAP_RELATIVE)
            j = slots[k + 1]
            if j >= 0:
                out_v[j, :, i], out_p[j, :, i] = st[:3], st[3:]


def _run_numpy(track: AttitudeTrack, v: np.ndarray, p: np.ndarray, R: np.ndarray, slot: np.ndarray,
               out_v: np.ndarray, out_p: np.ndarray, gm: float, j2k: float) -> None:  # fmt: skip
    """All members at once per step, numpy on (m,) component arrays (the reference path)."""
    st = (*v, *p)
    Rs = tuple(R)
    dts, A, B = track.dt.tolist(), track.a.reshape(-1, 12).tolist(), track.b.reshape(-1, 12).tolist()
    if slot[0] >= 0:
        out_v[slot[0]], out_p[slot[0]] = st[:3], st[3:]
    for k in range(track.kind.size):
        kd = track.kind[k]
        if kd == STEP_RK4:
            st = _rk4_member_np(*st, *Rs, dts[k], A[k], B[k], gm, j2k)
        else:
            st = _gap_member_np(*st, *Rs, dts[k], A[k], B[k], kd == STEP_GAP_RELATIVE)
        j = slot[k + 1]
        if j >= 0:
            out_v[j], out_p[j] = st[:3], st[3:]


if HAVE_NUMBA:

    @numba.njit(nogil=True, cache=True, error_model="numpy")
    def run_numba(kind, dts, A, B, v, p, R, slot, out_v, out_p, gm, j2k, g0, g1):  # pragma: no cover - compiled
        """Members in blocks of :data:`LANES` (``m`` a multiple of it), blocks ``g0..g1−1``.  A
        block's states are a (6, LANES) array; per step one loop over its members, which LLVM
        vectorises (SIMD over members; the same IEEE operations per member).  Releases the GIL,
        so threads can run disjoint block ranges."""
        for ig in range(g0, g1):
            i0 = LANES * ig
            S = np.empty((6, LANES))
            Rl = np.empty((9, LANES))
            for L in range(LANES):
                for c in range(3):
                    S[c, L] = v[c, i0 + L]
                    S[3 + c, L] = p[c, i0 + L]
                for c in range(9):
                    Rl[c, L] = R[c, i0 + L]
            js = slot[0]
            if js >= 0:
                for L in range(LANES):
                    for c in range(3):
                        out_v[js, c, i0 + L] = S[c, L]
                        out_p[js, c, i0 + L] = S[3 + c, L]
            for k in range(kind.size):
                a = A[k]
                b = B[k]
                Ak = (a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9], a[10], a[11])
                Bk = (b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7], b[8], b[9], b[10], b[11])
                dt = dts[k]
                if kind[k] == STEP_RK4:
                    for L in range(LANES):
                        x = _rk4_member(
                            S[0, L], S[1, L], S[2, L], S[3, L], S[4, L], S[5, L],
                            Rl[0, L], Rl[1, L], Rl[2, L], Rl[3, L], Rl[4, L], Rl[5, L], Rl[6, L], Rl[7, L], Rl[8, L],
                            dt, Ak, Bk, gm, j2k,
                        )  # fmt: skip
                        S[0, L] = x[0]
                        S[1, L] = x[1]
                        S[2, L] = x[2]
                        S[3, L] = x[3]
                        S[4, L] = x[4]
                        S[5, L] = x[5]
                else:
                    rel = kind[k] == STEP_GAP_RELATIVE
                    for L in range(LANES):
                        x = _gap_member(
                            S[0, L], S[1, L], S[2, L], S[3, L], S[4, L], S[5, L],
                            Rl[0, L], Rl[1, L], Rl[2, L], Rl[3, L], Rl[4, L], Rl[5, L], Rl[6, L], Rl[7, L], Rl[8, L],
                            dt, Ak, Bk, rel,
                        )  # fmt: skip
                        S[0, L] = x[0]
                        S[1, L] = x[1]
                        S[2, L] = x[2]
                        S[3, L] = x[3]
                        S[4, L] = x[4]
                        S[5, L] = x[5]
                js = slot[k + 1]
                if js >= 0:
                    for L in range(LANES):
                        for c in range(3):
                            out_v[js, c, i0 + L] = S[c, L]
                            out_p[js, c, i0 + L] = S[3 + c, L]


def integrate_ensemble(
    track: AttitudeTrack,
    v0: np.ndarray,
    q0: np.ndarray,
    p0: np.ndarray,
    record: np.ndarray,
    *,
    body: Body,
    backend: str | None = None,
    threads: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and positions of members at chosen samples (module docstring).

    ``track`` from :func:`attitude_track`; initial states at ``track.t[0]``: v0 (m, 3) [m/s],
    q0 (m, 4) ``q_M_G`` (normalised here), p0 (m, 3) [m]; ``record`` (k,) sample indices (sorted,
    unique, in ``0..n−1``); ``body`` the planet (point mass + J2 gravity); ``backend`` one of
    :data:`BACKENDS` (default :func:`default_backend`); ``threads`` for "numba" (default: the
    cores available to this process).  Returns ``v`` (k, m, 3) [m/s] and ``p``
    (k, m, 3) [m] in frame M at those samples; the attitude there is ``q0 ⊗ track.dq[record]``.
    A member's result does not depend on the other members of the call nor on the backend.
    """
    backend = backend or default_backend()
    if backend not in BACKENDS:
        raise ValueError(f"integrate_ensemble: backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "numba" and not HAVE_NUMBA:
        raise ValueError("integrate_ensemble: backend 'numba' needs numba installed")
    n = track.t.size
    record = np.asarray(record, dtype=np.int64)
    if record.size and (np.any(np.diff(record) <= 0) or record[0] < 0 or record[-1] >= n):
        raise ValueError("integrate_ensemble: record must be sorted unique sample indices in 0..n-1")
    v = np.ascontiguousarray(np.atleast_2d(np.asarray(v0, dtype=float)).T)
    p = np.ascontiguousarray(np.atleast_2d(np.asarray(p0, dtype=float)).T)
    q = quat_normalize(np.atleast_2d(np.asarray(q0, dtype=float)))
    R = np.ascontiguousarray(np.array(dcm_components(q[:, 0], q[:, 1], q[:, 2], q[:, 3])).reshape(9, -1))
    m = v.shape[1]
    slot = np.full(n, -1, dtype=np.int64)
    slot[record] = np.arange(record.size)
    out_v = np.empty((record.size, 3, m))
    out_p = np.empty((record.size, 3, m))
    gm, j2k = float(body.gm), float(j2_factor(body))
    if backend == "numba":
        pad = -m % LANES  # groups of LANES members: pad with copies of the last one
        if pad:
            v, p, R = (np.concatenate([x, np.repeat(x[:, -1:], pad, axis=1)], axis=1) for x in (v, p, R))
            out_v, out_p = np.empty((record.size, 3, m + pad)), np.empty((record.size, 3, m + pad))
        A, B = track.a.reshape(-1, 12), track.b.reshape(-1, 12)
        args = (track.kind, track.dt, A, B, v, p, R, slot, out_v, out_p, gm, j2k)
        ng = (m + pad) // LANES
        nt = max(1, min(int(threads or _cores()), ng))
        if nt == 1:
            run_numba(*args, 0, ng)
        else:  # threads on disjoint blocks (the kernel releases the GIL); no OpenMP, so fork-safe
            edges = np.linspace(0, ng, nt + 1).round().astype(int)
            with ThreadPoolExecutor(nt) as ex:
                list(ex.map(lambda ab: run_numba(*args, ab[0], ab[1]), zip(edges[:-1], edges[1:], strict=True)))
        out_v, out_p = out_v[:, :, :m], out_p[:, :, :m]
    elif backend == "numpy":
        _run_numpy(track, v, p, R, slot, out_v, out_p, gm, j2k)
    else:
        _run_python(track, v, p, R, slot, out_v, out_p, gm, j2k)
    return np.swapaxes(out_v, 1, 2), np.swapaxes(out_p, 1, 2)
