"""Synthetic point-mass entry with a spinning body for the strapdown / dispersion tests and benchmark.

Not a truth simulator (that is ``workbench.problems.entry.truth``): a drag-only point mass through
``MarsEngineeringAtmosphere`` from AMELIA's Table 2 nominal state (15 s before EIP), ballistic
coefficient 80 kg/m² until the Mach-2 "parachute deployment", 8 kg/m² after; the body spins at
16 °/s about +Z_G with a slow coning, and the IMU samples are the exact f_G = C_G_M a_drag and w_G
at 10 Hz (optionally with data gaps bridged from the truth, as an on-board solution would).
Events: PDD at Mach 2, FSR = PDD + 41 s, BSR = FSR + 41 s (end of data).  Load it with
``importlib`` (the test folders are not packages).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.integrate import solve_ivp

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import quat_from_rotvec, quat_multiply, quat_normalize, quat_to_dcm
from workbench.estimation.strapdown import GapBridge, ImuArrays

OMEGA_M = np.array([0.0, 0.0, MARS.rotation_rate])
P0 = np.array([-1317.4056, 3254.8625, -223.9034]) * 1e3
V0 = np.array([-4.9636, -3.3138, 0.8326]) * 1e3
Q0 = quat_normalize(np.array([0.7250, -0.2476, 0.3916, -0.5096]))  # raw JPL numbers = q_M_G
T0 = -15.0
ATM = MarsEngineeringAtmosphere()


Bridge = GapBridge  # the workbench's own type (was a duck-typed copy)


SynthIMU = ImuArrays  # the workbench's own type (was a duck-typed copy)


def body_rate(t):
    """w_G(t) [rad/s]: 16 °/s spin about +Z with a small coning of the transverse rate."""
    t = np.asarray(t, float)
    s = np.deg2rad(16.0)
    return np.stack([0.02 * np.sin(0.3 * t), 0.02 * np.cos(0.2 * t), s + 0.0 * t], -1)


def _rhs(t, y, beta_fn):
    v, p, q = y[0:3], y[3:6], y[6:10]
    h = np.linalg.norm(p) - MARS.reference_radius
    vr = v - np.cross(OMEGA_M, p)
    rho = ATM.density(max(h, -5e3))
    a_drag = -0.5 * rho * np.linalg.norm(vr) * vr / beta_fn(t)
    w = body_rate(t)
    dq = 0.5 * quat_multiply(q, np.r_[w, 0.0])
    return np.concatenate([gravity_j2(p, MARS) + a_drag, v, dq])


@lru_cache(maxsize=4)
def truth(dt: float = 0.1, t_end_max: float = 320.0, beta_entry: float = 80.0, beta_chute: float = 8.0):
    """Truth on a uniform grid from T0: dict with t, v, p, q (q_M_G), f_G, w_G and the events."""

    def mach(t, y, *_):
        p, v = y[3:6], y[0:3]
        h = np.linalg.norm(p) - MARS.reference_radius
        return np.linalg.norm(v - np.cross(OMEGA_M, p)) / ATM.speed_of_sound(h) - 2.0

    mach.terminal = True
    mach.direction = -1
    y0 = np.concatenate([V0, P0, Q0])
    kw = dict(rtol=1e-11, atol=1e-9, method="DOP853", dense_output=True)
    s1 = solve_ivp(_rhs, (T0, t_end_max), y0, events=mach, args=(lambda t: beta_entry,), **kw)
    t_pdd = float(s1.t_events[0][0])
    t_fsr, t_bsr = t_pdd + 41.0, t_pdd + 82.0
    s2 = solve_ivp(_rhs, (t_pdd, t_bsr), s1.y[:, -1], args=(lambda t: beta_chute,), **kw)
    n = int(np.floor((t_bsr - T0) / dt + 1e-9)) + 1
    t = T0 + dt * np.arange(n)
    y = np.where(t[None, :] <= t_pdd, s1.sol(np.minimum(t, t_pdd)), s2.sol(np.maximum(t, t_pdd)))
    v, p, q = y[0:3].T, y[3:6].T, quat_normalize(y[6:10].T)
    beta = np.where(t <= t_pdd, beta_entry, beta_chute)
    h = np.linalg.norm(p, axis=1) - MARS.reference_radius
    vr = v - np.cross(OMEGA_M, p)
    a_M = -0.5 * ATM.density(h)[:, None] * np.linalg.norm(vr, axis=1)[:, None] * vr / beta[:, None]
    f_G = np.einsum("nji,nj->ni", quat_to_dcm(q), a_M)
    return dict(t=t, v=v, p=p, q=q, f_G=f_G, w_G=body_rate(t), events={"PDD": t_pdd, "FSR": t_fsr, "BSR": float(t[-1])})


def make_imu(tr: dict, gaps=(), sigma_f: float = 1e-3, sigma_w: float = np.deg2rad(0.01), rng=None) -> SynthIMU:
    """IMU from the truth with data gaps ``[(t_a, t_b), ...]`` removed and bridged from the truth.

    ``rng`` given: white noise of the given per-sample σ added to f_G and w_G.
    """
    t, f, w = tr["t"], tr["f_G"].copy(), tr["w_G"].copy()
    if rng is not None:
        f = f + sigma_f * rng.standard_normal(f.shape)
        w = w + sigma_w * rng.standard_normal(w.shape)
    keep = np.ones(t.size, bool)
    bridges = []
    for ta, tb in gaps:
        ia, ib = int(np.argmin(abs(t - ta))), int(np.argmin(abs(t - tb)))
        keep[ia + 1 : ib] = False
        Ca, Cb = quat_to_dcm(tr["q"][ia]).T, quat_to_dcm(tr["q"][ib]).T
        dp = tr["p"][ib] - tr["p"][ia]
        bridges.append(
            Bridge(
                t_a=float(t[ia]),
                t_b=float(t[ib]),
                dv_G=Ca @ (tr["v"][ib] - tr["v"][ia]),
                dp_G=Ca @ dp,
                dp_rel_G=Ca @ (dp - tr["v"][ia] * (t[ib] - t[ia])),
                dC=Cb @ Ca.T,
            )
        )
    n = int(keep.sum())
    return SynthIMU(
        t=t[keep],
        f_G=f[keep],
        w_G=w[keep],
        sigma_f=np.full((n, 3), sigma_f),
        sigma_w=np.full((n, 3), sigma_w),
        gaps=bridges,
    )


def perturb(q, dtheta):
    """``q ⊗ exp(δθ)``."""
    return quat_normalize(quat_multiply(q, quat_from_rotvec(dtheta)))
