"""Truth simulator of a MER-style airbag drop test in the SPF chamber (synthetic scenarios only).

This is the *truth*, not the estimator's model: a 6-DOF rigid body (lander + airbags) released
from hanging, pulled toward the ramp (60° at the SPF; any angle here) by a bungee whose force is a
polynomial of stretch times the number of bungees, cut by the hammer/nail shortly before contact,
then stopped and thrown back by **airbag contact forces**: each airbag lobe is a sphere that
flattens against the ramp; the force on a lobe is the gauge pressure of the bags' *shared* gas
volume (the bags vent into each other) times the flattened contact area, plus a damping term and
Coulomb friction. The gas is compressed adiabatically by the volume the flattened caps displace.
If the bags compress far enough, a vertex of the rigid lander body reaches the ramp: a stiff
penalty contact then acts and the run is a *full stroke*.

The REDLand estimator is kinematic (it never sees these forces); the only shared items are the
geometry of the ramp and lander and the nominal bungee test plan (used by the estimator's
optional dynamic mode, with the truth's bungee deliberately a few per cent off nominal).

Chamber (SPF) frame: origin at the trigger nail, Z up, Y toward the ramp face, X = Y × Z
(REDLand paper, "Test facility"). Mars frame = SPF rotated by −α about X for a ramp of
inclination α (−60° at the SPF), the ramp level: :func:`mars_from_spf`.
Body frame B: origin at the CM (see ``assets/landers/mer_drop_lander.toml``).

References: REDLand paper (``redland-mer-airbag-droptest.txt``): test sequence, bungee model,
impact speeds (16 m/s horizontal, 12 m/s vertical in the Mars frame), bungee cut ~0.05 s before
contact, whole event < 2.5 s, bag pressure 1.0–1.3 psi, 5 torr chamber.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from workbench.core.bodies import G0
from workbench.core.rotation import (
    quat_from_euler123,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_to_dcm,
)
from workbench.io import progress
from workbench.problems.droptest import truth_fast
from workbench.problems.droptest.lander import LanderModel
from workbench.problems.droptest.surface import Surface

GRAVITY_SPF = np.array([0.0, 0.0, -G0])

__all__ = ["BungeeRig", "DropTestConfig", "DropTruth", "simulate_drop", "design_release", "mars_from_spf"]

V_SLIP = 0.1  # friction regularisation speed [m/s]: |F_t| = μ F_n tanh(|v_t| / V_SLIP)


def mars_from_spf(surface: Surface) -> np.ndarray:
    """DCM (3, 3) from the SPF chamber frame to the "Mars" frame of the ramp ``surface``, in which
    the ramp is level: rows X (across the ramp), up-slope ``n × X`` and the ramp normal ``n``
    (REDLand "Test facility": a −60° rotation about X for the SPF's 60° ramp; any ramp angle here)."""
    n = np.asarray(surface.normal, float)
    x = np.array([1.0, 0.0, 0.0])
    return np.array([x, np.cross(n, x), n]) + 0.0  # + 0.0: no negative zeros


@dataclass(frozen=True)
class BungeeRig:
    """The bungee acceleration system, as a test plan states it.

    Force on the lander along the rope toward ``anchor_I`` [m, SPF]:
    ``F = count · Σ_k coeffs[k] · s^(k+1)`` [N] for stretch ``s = |anchor − x_att| − rest_length > 0``.
    ``coeffs`` are per-bungee polynomial coefficients [N/m, N/m², N/m³, N/m⁴] (REDLand: "a third
    or fourth order polynomial"). ``attach_B`` is the rope attachment on the lander [m, body].
    ``hammer_length`` [m]: the rope is cut when the attachment comes within this distance of the
    nail (the SPF origin) — the hammer on the rope hits the nail.
    """

    anchor_I: np.ndarray
    rest_length: float
    coeffs: tuple[float, ...]
    count: float
    attach_B: np.ndarray
    hammer_length: float

    def force(self, x_att: np.ndarray) -> np.ndarray:
        """Rope force [N] (..., 3) in SPF on an attachment point at ``x_att`` (..., 3) [m]."""
        d = self.anchor_I - x_att
        L = np.linalg.norm(d, axis=-1, keepdims=True)
        s = np.clip(L - self.rest_length, 0.0, None)
        f = np.zeros_like(s)
        for k, c in enumerate(self.coeffs):
            f = f + c * s ** (k + 1)
        return self.count * f * d / L


@dataclass(frozen=True)
class DropTestConfig:
    """Settings of one synthetic drop (SI units; angles in rad unless named ``_deg``).

    ``impact_parallel_speed`` / ``impact_normal_speed`` [m/s] are the targets in the Mars frame
    at first airbag contact, reached ``release_to_contact_s`` after release; :func:`design_release`
    finds the release point, bungee count and bungee rest length that produce them, like the
    test engineer's energy calculation. The run ends ``tail_s`` after the lander leaves the ramp
    (it flies into the catch net, which is not modelled) or at ``duration_s``.
    """

    impact_parallel_speed: float
    impact_normal_speed: float
    release_euler123_deg: tuple[float, float, float]
    pre_release_s: float
    release_to_contact_s: float
    bungee_truth_scale: float  # true bungee stiffness / the test plan's
    pressure_pa: float | None  # override the asset's bag pressure (full-stroke case); None: the asset's
    duration_s: float = 2.3
    cut_lead_s: float = 0.05
    tail_s: float = 0.35
    bungee_rest_length: float = 4.0
    bungee_coeffs: tuple[float, ...] = (900.0, 60.0, -2.0)
    bungee_anchor_distance: float = 14.0
    max_step: float = 1.0e-3
    output_rate_hz: float = 10_000.0


@dataclass(frozen=True)
class DropTruth:
    """Truth history of a simulated drop, sampled at ``output_rate_hz``.

    Shapes: t (n,) [s from release]; p_I, v_I (n,3) [m, m/s, SPF, CM]; q_I_B (n,4);
    w_B, alpha_B (n,3) [rad/s, rad/s², body]; a_ng_I (n,3) non-gravitational acceleration of the
    CM [m/s², SPF]; contact_force (n,) total airbag normal force [N]; gauge_pressure (n,) [Pa];
    lobe_penetration (n, n_lobes) [m]; body_penetration (n,) [m] (>0: full stroke).
    ``events`` maps names (release, bungee_cut, first_contact, last_contact, ...) to times [s].
    ``rig`` is the *true* bungee (the test plan's is ``nominal_rig``).
    """

    t: np.ndarray
    p_I: np.ndarray
    v_I: np.ndarray
    q_I_B: np.ndarray
    w_B: np.ndarray
    alpha_B: np.ndarray
    a_ng_I: np.ndarray
    contact_force: np.ndarray
    gauge_pressure: np.ndarray
    lobe_penetration: np.ndarray
    body_penetration: np.ndarray
    events: dict[str, float]
    rig: BungeeRig
    nominal_rig: BungeeRig
    p_release: np.ndarray
    q_release: np.ndarray
    config: DropTestConfig = field(repr=False)


class ForceModel:
    """Force model of the lander + airbags against the ramp (vectorised over a leading axis)."""

    def __init__(self, lander: LanderModel, surface: Surface, rig: BungeeRig, pressure_pa: float):
        self.m = lander.mass
        self.J = np.asarray(lander.inertia_B, float)
        self.Jinv = np.linalg.inv(self.J)
        self.lobes_B = np.asarray(lander.lobe_centers_B, float)
        self.R = float(lander.lobe_radius)
        self.verts_B = np.asarray(lander.body.vertices, float)
        self.n = np.asarray(surface.normal, float)
        self.P0 = np.asarray(surface.point, float)
        self.T = tuple(np.asarray(v, float) for v in surface.tangent_basis())  # in-plane unit vectors
        self.rock_c = np.asarray(surface.rock_centers, float).reshape(-1, 3)
        self.rock_r = np.asarray(surface.rock_radii, float).reshape(-1)
        self.rig = rig
        self.p0 = pressure_pa
        self.p_amb = lander.ambient_pressure_pa
        self.V0 = lander.gas_volume_m3
        self.gamma = lander.gamma
        self.damp = lander.damping
        self.mu = lander.friction
        self.k_body = float(lander.contact_stiffness)  # rigid-body penalty stiffness [N/m] (the asset's)
        self.c_body = 2.0e4  # [N s/m]
        self.cut = False

    def packed(self) -> tuple:
        """Parameters of the compiled kernels (:mod:`.truth_fast`), after ``y`` and ``cut``:
        (lobes_B, verts_B, geo, rock_c, rock_r, rig, coeffs, sc); see that module's docstring."""

        def f(a):  # a writable C-contiguous copy: one compiled signature whatever the source
            return np.array(a, float, order="C")

        return (
            f(self.lobes_B),
            f(self.verts_B),
            np.concatenate([self.n, self.P0, *self.T]),
            f(self.rock_c),
            f(self.rock_r),
            np.concatenate([np.asarray(self.rig.anchor_I, float), np.asarray(self.rig.attach_B, float)]),
            np.asarray(self.rig.coeffs, float),
            np.array(
                [
                    self.R,
                    self.p0,
                    self.p_amb,
                    self.V0,
                    self.gamma,
                    self.damp,
                    self.mu,
                    self.k_body,
                    self.c_body,
                    self.rig.rest_length,
                    self.rig.count,
                    self.m,
                ],
                float,
            ),
        )

    def evaluate_fast(self, y):
        """:meth:`evaluate` through the compiled kernel (same returns; agrees to rounding)."""
        F = np.empty(3)
        T = np.empty(3)
        pen = np.empty(self.lobes_B.shape[0])
        fn, pg, bpen = truth_fast.evaluate(np.asarray(y, float), self.cut, *self.packed(), F, T, pen)
        return F, T, fn, pg, pen, bpen

    def rhs_fast(self) -> callable:
        """``fun(t, y)`` for solve_ivp through the compiled kernel, for the current ``cut`` state
        (the cut flag and parameters are bound now: make a new one after changing ``cut``)."""
        args = (self.cut, *self.packed(), np.array(self.J, float, order="C"), np.array(self.Jinv, float, order="C"))
        kernel = truth_fast.rhs

        def fun(t, y):
            return kernel(y, *args)

        return fun

    def evaluate(self, y):
        """Forces for one state y = [p, v, q_I_B, ω_B] (13,).

        Returns (F [N, SPF] non-gravitational force, T_B [N m, body] torque about the CM,
        total airbag normal force [N], gauge pressure [Pa], lobe penetrations (n_lobes,) [m],
        deepest body-vertex penetration [m]).
        """
        p, v, q, w = y[0:3], y[3:6], y[6:10], y[10:13]
        x_, y_, z_, w_ = q / np.sqrt(q @ q)
        C = np.array(
            [
                [1 - 2 * (y_ * y_ + z_ * z_), 2 * (x_ * y_ - w_ * z_), 2 * (x_ * z_ + w_ * y_)],
                [2 * (x_ * y_ + w_ * z_), 1 - 2 * (x_ * x_ + z_ * z_), 2 * (y_ * z_ - w_ * x_)],
                [2 * (x_ * z_ - w_ * y_), 2 * (y_ * z_ + w_ * x_), 1 - 2 * (x_ * x_ + y_ * y_)],
            ]
        )
        w_I = C @ w
        n = self.n
        F = np.zeros(3)
        T_I = np.zeros(3)
        r_I = self.lobes_B @ C.T
        dc = (p - self.P0) @ n + r_I @ n
        pen_all = np.clip(self.R - dc, 0.0, self.R)
        hit = pen_all > 0.0
        fn_total = 0.0
        vcap = np.pi * pen_all * pen_all * (3.0 * self.R - pen_all) / 3.0
        pg = self.p0 * (self.V0 / (self.V0 - vcap.sum())) ** self.gamma - self.p_amb
        if hit.any():
            pe = pen_all[hit]
            rc = r_I[hit] - dc[hit, None] * n  # footprint centres rel. CM
            a2 = 2.0 * self.R * pe - pe * pe  # footprint radius² of each flattened lobe
            area = footprint_areas(rc, np.sqrt(a2), *self.T)
            f_l, fn_total = self._membrane(pg, area, rc, np.broadcast_to(n, rc.shape), v, w_I)
            F += f_l.sum(0)
            T_I += np.cross(rc, f_l).sum(0)
        if self.rock_r.size:
            F_r, T_r, fn_r, vcap_r, bpen_r = self._rocks(p, v, C, w_I, r_I, pg)
            F += F_r
            T_I += T_r
            fn_total += fn_r
        else:
            bpen_r = 0.0
        rv = self.verts_B @ C.T
        dv = (p - self.P0) @ n + rv @ n
        bpen = float(max(0.0, -dv.min(), bpen_r))
        if bpen > 0.0:
            b = dv < 0
            vv = v + np.cross(w_I, rv[b])
            fb = np.clip(-self.k_body * dv[b] - self.c_body * (vv @ n), 0.0, None)
            F += fb.sum() * n
            T_I += np.cross(rv[b], fb[:, None] * n).sum(0)
        if not self.cut:
            x_att = p + C @ self.rig.attach_B
            Fb = self.rig.force(x_att)
            F += Fb
            T_I += np.cross(x_att - p, Fb)
        return F, C.T @ T_I, fn_total, pg, pen_all, bpen

    def _membrane(self, pg, area, rc, normals, v, w_I):
        """Contact force of pressurised fabric on a rigid surface, per contact (k,3), and its sum of
        normal components [N]: gauge pressure × footprint area, minus damping × area × normal
        closing speed (never pulling), plus regularised Coulomb friction against the contact
        point's sliding velocity. ``rc`` (k,3) contact points rel. CM; ``normals`` (k,3) unit,
        pointing away from the surface; v [m/s] and w_I [rad/s] in SPF."""
        vc = v + np.cross(w_I, rc)
        vn = np.sum(vc * normals, axis=1)
        fn = np.clip(pg * area - self.damp * area * vn, 0.0, None)
        vt = vc - vn[:, None] * normals
        vtn = np.linalg.norm(vt, axis=1)
        ft = -self.mu * (fn * np.tanh(vtn / V_SLIP) / np.maximum(vtn, 1e-9))[:, None] * vt
        return fn[:, None] * normals + ft, float(fn.sum())

    def _rocks(self, p, v, C, w_I, r_I, pg):
        """Lobe-on-rock and body-on-rock contact (rocks are rigid spheres on the ramp).

        A lobe of radius R pressed by δ onto a rock of radius r wraps it like a sphere of the
        effective radius R_e = R r / (R + r): footprint area π(2 R_e δ − δ²), force pg × area
        along the centre line, plus damping and friction as on the ramp. The gas volume these
        caps displace is small next to the ramp caps and is neglected. A body vertex inside a
        rock gets the same stiff penalty as on the ramp. Returns (F, T_I, total normal force,
        0.0, deepest body penetration into a rock [m]).
        """
        F = np.zeros(3)
        T_I = np.zeros(3)
        x = p + r_I
        d = x[:, None, :] - self.rock_c[None, :, :]
        dist = np.linalg.norm(d, axis=-1)
        pen = self.R + self.rock_r[None, :] - dist
        fn_total = 0.0
        li, ri = np.nonzero(pen > 0.0)
        if li.size:
            u = d[li, ri] / dist[li, ri, None]
            Re = self.R * self.rock_r[ri] / (self.R + self.rock_r[ri])
            pe = np.minimum(pen[li, ri], Re)
            area = np.pi * (2.0 * Re * pe - pe * pe)
            rc = self.rock_c[ri] + u * self.rock_r[ri, None] - p
            f, fn_total = self._membrane(pg, area, rc, u, v, w_I)
            F += f.sum(0)
            T_I += np.cross(rc, f).sum(0)
        rv = self.verts_B @ C.T
        dvr = np.linalg.norm(p + rv[:, None, :] - self.rock_c[None], axis=-1) - self.rock_r[None]
        vi, rj = np.nonzero(dvr < 0.0)
        bpen = 0.0
        if vi.size:
            u = p + rv[vi] - self.rock_c[rj]
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            vv = v + np.cross(w_I, rv[vi])
            fb = np.clip(-self.k_body * dvr[vi, rj] - self.c_body * np.sum(vv * u, axis=1), 0.0, None)
            F += (fb[:, None] * u).sum(0)
            T_I += np.cross(rv[vi], fb[:, None] * u).sum(0)
            bpen = float(-dvr[vi, rj].min())
        return F, T_I, fn_total, 0.0, bpen

    def rhs(self, t, y):
        """State derivative for solve_ivp: y = [p, v, q_I_B, ω_B] (13,)."""
        F, T, *_ = self.evaluate(y)
        v, q, w = y[3:6], y[6:10], y[10:13]
        q = q / np.sqrt(q @ q)
        a = F / self.m + GRAVITY_SPF
        qd = 0.5 * quat_multiply(q, np.array([w[0], w[1], w[2], 0.0]))
        wd = self.Jinv @ (T - np.cross(w, self.J @ w))
        return np.concatenate([v, a, qd, wd])


def footprint_areas(c: np.ndarray, a: np.ndarray, t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    """Contact area [m²] (k,) of each flattened lobe, footprint centres c (k,3) [m] in the plane spanned
    by the unit vectors t1, t2 (3,), radii a (k,) [m]: its share of the footprints' union.

    Rack lobes overlap (centre spacing < diameter) and the racks of neighbouring faces press at
    nearly the same place, so their footprints overlap, often many deep; each point of the union
    is shared equally by the footprints covering it (for two disks: the disk minus half the lens).
    The numpy reference of :func:`.truth_fast.footprint_areas` (the same rays; here the cover count
    is taken at the midpoint of every interval between crossings instead of swept).
    """
    k = a.size
    out = np.pi * a * a
    if k < 2:
        return out
    th = (np.arange(truth_fast.FOOT_RAYS) + 0.5) * 2.0 * np.pi / truth_fast.FOOT_RAYS
    U = np.cos(th)[:, None] * t1 + np.sin(th)[:, None] * t2  # (rays, 3)
    e = c[:, None, :] - c[None, :, :]  # (i, j, 3)
    b = np.einsum("ijx,rx->ijr", e, U)
    disc = b * b - (e * e).sum(-1)[:, :, None] + (a * a)[None, :, None]
    ok = (disc > 0.0) & ~np.eye(k, dtype=bool)[:, :, None] & (a > 0.0)[None, :, None]
    sq = np.sqrt(np.where(ok, disc, 0.0))
    ai = a[:, None, None]
    r0 = np.where(ok, np.clip(-b - sq, 0.0, ai), 0.0)
    r1 = np.where(ok, np.clip(-b + sq, 0.0, ai), 0.0)
    r1 = np.maximum(r1, r0)  # an interval beyond the disk or behind the centre is empty
    edges = np.sort(np.concatenate([np.zeros((k, 1, th.size)), r0, r1, np.broadcast_to(ai, (k, 1, th.size))], 1), 1)
    mid = 0.5 * (edges[:, 1:, :] + edges[:, :-1, :])  # (i, intervals, rays)
    m = 1.0 + ((r0[:, None, :, :] <= mid[:, :, None, :]) & (mid[:, :, None, :] < r1[:, None, :, :])).sum(2)
    f = (0.5 * (edges[:, 1:, :] ** 2 - edges[:, :-1, :] ** 2) / m).sum(1)  # (i, rays)
    return np.where(a > 0.0, f.sum(1) * 2.0 * np.pi / th.size, 0.0)


def _join(first, second):
    """Dense-output callable over two consecutive solve_ivp solutions."""
    t_split = float(first.t[-1])

    def dense(t):
        t = np.asarray(t, float)
        out = np.empty((13, t.size))
        m = t <= t_split
        if m.any():
            out[:, m] = first.sol(t[m])
        if (~m).any():
            out[:, ~m] = second.sol(t[~m])
        return out

    return dense


def _contact_height(lander: LanderModel, surface: Surface, q_I_B: np.ndarray) -> float:
    """Height [m] of the CM above the ramp when the first lobe touches, for attitude ``q_I_B``."""
    r = quat_rotate(q_I_B, lander.lobe_centers_B) @ surface.normal
    return float(lander.lobe_radius - np.min(r))


def _nominal_rig(cfg: DropTestConfig, lander: LanderModel, surface: Surface, count: float, anchor_dir: np.ndarray):
    attach_B = np.array([0.0, 0.0, float(np.min(lander.body.vertices[:, 2]))])
    return BungeeRig(
        anchor_I=np.asarray(surface.point) - cfg.bungee_anchor_distance * anchor_dir,
        rest_length=cfg.bungee_rest_length,
        coeffs=tuple(cfg.bungee_coeffs),
        count=float(count),
        attach_B=attach_B,
        hammer_length=0.0,
    )


def fly_reference(
    p0: np.ndarray,
    rig: BungeeRig,
    m: float,
    n: np.ndarray,
    point: np.ndarray,
    h_c: float,
    cut_lead_s: float,
    dt: float = 1e-3,
    n_max: int = 6000,
) -> tuple[np.ndarray, np.ndarray, float, float | None]:
    """Point-mass flight of the release design, pure-Python reference of :func:`.truth_fast.fly`.

    From rest at ``p0`` (3,) [m, SPF] under gravity and ``rig`` (its attachment taken at the CM),
    mass ``m`` [kg], until the CM is ``h_c`` [m] above the ramp plane (unit normal ``n``, through
    ``point``, SPF); the rope is released ``cut_lead_s`` [s] before the predicted contact.
    Semi-implicit Euler steps of ``dt`` [s], at most ``n_max``. Returns (p [m], v [m/s] at the
    crossing, t [s] from release, cut time [s] or None).
    """
    rig = replace(rig, attach_B=np.zeros(3))
    p = np.array(p0, float)
    v = np.zeros(3)
    cut_t = None
    t = 0.0
    # integrate until the CM reaches the contact height (plane distance); the crossing is
    # interpolated inside the last step so that the residuals are smooth in the unknowns
    h_prev = (p - point) @ n
    for _ in range(n_max):
        acc = GRAVITY_SPF + (rig.force(p) / m if cut_t is None else 0.0)
        vn = -(v @ n)
        if cut_t is None and vn > 0 and (h_prev - h_c) / vn < cut_lead_s:
            cut_t = t
        v_new = v + acc * dt
        p_new = p + v_new * dt
        h = (p_new - point) @ n
        if h <= h_c:
            frac = (h_prev - h_c) / (h_prev - h)
            p = p + frac * (p_new - p)
            v = v + frac * (v_new - v)
            t += frac * dt
            break
        p, v, h_prev = p_new, v_new, h
        t += dt
    return p, v, t, cut_t


def design_release(
    cfg: DropTestConfig, lander: LanderModel, surface: Surface, *, fast: bool = True
) -> tuple[np.ndarray, BungeeRig, float]:
    """Find the release point and bungee count that give the target impact velocity.

    Point-mass design (as the test engineer's energy calculation): gravity + the test-plan
    bungee (attachment at the CM), free flight for ``cut_lead_s`` before contact. Unknowns:
    release (y, z) in the SPF YZ-plane and the (continuous) bungee count; targets: Mars-frame
    velocity at first contact (parallel, normal) and first contact at the ramp point nearest
    the nail, ``release_to_contact_s`` after release. Unknowns: release (y, z), bungee count and
    the direction of the rope run (YZ plane). Returns (p_release [m, SPF], nominal rig with its
    hammer length, t_contact [s]). The Mars frame is the ramp's own (:func:`mars_from_spf`), so
    the targets hold for any ramp angle. ``fast`` (default True, what every run uses): fly the
    trial releases with the compiled :func:`.truth_fast.fly`; False: the Python reference loop
    :func:`fly_reference` (same steps).
    """
    q0 = quat_from_euler123(np.radians(np.asarray(cfg.release_euler123_deg, float)))
    n = np.asarray(surface.normal, float)
    h_c = _contact_height(lander, surface, q0)
    p_contact = np.asarray(surface.point, float) + h_c * n
    # target velocity in SPF: Mars-frame (0, -v_par, -v_norm) -> SPF (down-slope, into the ramp)
    v_target = mars_from_spf(surface).T @ np.array([0.0, -cfg.impact_parallel_speed, -cfg.impact_normal_speed])
    u = v_target / np.linalg.norm(v_target)
    m = lander.mass

    def pull_dir(beta):  # unit vector from the anchor toward the ramp, in the YZ plane
        return -np.array([0.0, np.sin(beta), -np.cos(beta)])

    point = np.asarray(surface.point, float)
    coeffs = np.asarray(cfg.bungee_coeffs, float)

    def fly(params):
        y0, z0, count, beta = params
        rig = _nominal_rig(cfg, lander, surface, count, pull_dir(beta))
        p0 = np.array([0.0, y0, z0])
        if not fast:
            return fly_reference(p0, rig, m, n, point, h_c, cfg.cut_lead_s)
        args = (rig.anchor_I, rig.rest_length, coeffs, rig.count, m, n, point, h_c, cfg.cut_lead_s, 1e-3, 6000)
        p, v, t, cut_t = truth_fast.fly(p0, *args)
        return p, v, t, (None if cut_t < 0.0 else cut_t)

    def resid(params):
        p, v, t, _ = fly(params)
        along = np.cross(n, np.array([1.0, 0.0, 0.0]))
        return np.concatenate([(v - v_target)[1:], [(p - p_contact) @ along, 10.0 * (t - cfg.release_to_contact_s)]])

    guess_dist = 0.5 * np.linalg.norm(v_target) * cfg.release_to_contact_s
    beta0 = np.arctan2(u[1], -u[2])
    x0 = np.array([p_contact[1] - u[1] * guess_dist, p_contact[2] - u[2] * guess_dist, 1.0, beta0])
    best = None
    for count0 in (1.0, 0.3, 3.0):  # a few starts: the bounded problem has poor local minima
        x0[2] = count0
        sol = least_squares(
            resid,
            x0,
            bounds=([-40, -5, 0.05, -1.2], [20, 35, 40, 1.2]),
            diff_step=1e-3,
            x_scale=[1.0, 1.0, 0.3, 0.1],
        )
        if best is None or sol.cost < best.cost:
            best = sol
        if np.max(np.abs(sol.fun)) < 0.01:
            break
    sol = best
    _, _, t_contact, t_cut = fly(sol.x)
    if np.max(np.abs(resid(sol.x))) > 0.05:
        raise ValueError(
            f"design_release: cannot reach the impact target {cfg.impact_parallel_speed} m/s parallel, "
            f"{cfg.impact_normal_speed} m/s normal in {cfg.release_to_contact_s} s (residual {resid(sol.x)})"
        )
    p_release = np.array([0.0, sol.x[0], sol.x[1]])
    rig = _nominal_rig(cfg, lander, surface, sol.x[2], pull_dir(sol.x[3]))
    # hammer length: distance from the attachment to the nail at the designed cut time
    p = p_release.copy()
    v = np.zeros(3)
    dt = 1e-3
    tt = 0.0
    rig0 = replace(rig, attach_B=np.zeros(3))
    while tt < (t_cut if t_cut is not None else t_contact - cfg.cut_lead_s):
        v = v + (GRAVITY_SPF + rig0.force(p) / m) * dt
        p = p + v * dt
        tt += dt
    x_att_cut = p + quat_rotate(q0, rig.attach_B)
    rig = replace(rig, hammer_length=float(np.linalg.norm(x_att_cut)))
    return p_release, rig, t_contact


def simulate_drop(
    cfg: DropTestConfig, lander: LanderModel, surface: Surface, *, fast: bool = True, tol: float = 1e-9
) -> DropTruth:
    """Simulate one drop (deterministic for a given config) and return its truth history.

    The lander hangs at rest for ``pre_release_s`` (t < 0), is released at t = 0, pulled by the
    true bungee until the hammer hits the nail, then impacts the ramp on its airbags. Integration:
    DOP853 with ``max_step``; output resampled on a uniform grid at ``output_rate_hz``.
    ``fast`` (default True, what every run uses): the force model, derivative and release design
    run as the compiled kernels of :mod:`.truth_fast`; False runs the pure-numpy reference path
    (``ForceModel.evaluate`` / ``rhs``, :func:`fly_reference`; same integrator and tolerances; they
    agree to the integrator's truncation error, tests/problems/droptest/test_truth_fast.py).
    ``tol``: DOP853's rtol = atol (the truth's is 1e-9; smaller values are
    for convergence checks, e.g. tests/benchmarks/bench_droptest_truth.py).
    """
    q0 = quat_normalize(quat_from_euler123(np.radians(np.asarray(cfg.release_euler123_deg, float))))
    p_release, nominal_rig, _ = design_release(cfg, lander, surface, fast=fast)
    true_rig = replace(nominal_rig, count=nominal_rig.count * cfg.bungee_truth_scale)
    pressure = lander.pressure_pa if cfg.pressure_pa is None else cfg.pressure_pa
    model = ForceModel(lander, surface, true_rig, pressure)

    y0 = np.concatenate([p_release, np.zeros(3), q0, np.zeros(3)])

    def cut_event(t, y):
        C = quat_to_dcm(y[6:10])
        x_att = y[0:3] + C @ true_rig.attach_B
        return np.linalg.norm(x_att) - true_rig.hammer_length

    cut_event.terminal = True
    cut_event.direction = -1

    def separation(t, y):  # deepest lobe penetration [m]; crosses 0 downward when the bags leave
        C = quat_to_dcm(y[6:10])
        dc = (y[0:3] - model.P0) @ model.n + (model.lobes_B @ C.T) @ model.n
        return float(np.max(model.R - dc)) + 1e-4

    separation.terminal = True
    separation.direction = -1
    opts = dict(method="DOP853", max_step=cfg.max_step, rtol=tol, atol=tol, dense_output=True)
    with progress.current().counter("drop truth simulation", total=float(cfg.duration_s), unit="s simulated") as bar:

        def tick(t, y):  # evaluated once per accepted step; never crosses zero, so never an event
            bar.set(float(t))
            return 1.0

        sol1 = solve_ivp(
            model.rhs_fast() if fast else model.rhs, (0.0, cfg.duration_s), y0, events=[cut_event, tick], **opts
        )
        segments = [(0.0, sol1.t[-1], sol1.sol, False)]
        t_cut = float(sol1.t[-1]) if sol1.status == 1 else None
        t_end = cfg.duration_s
        if t_cut is not None:
            model.cut = True
            y1 = sol1.y[:, -1].copy()
            y1[6:10] = quat_normalize(y1[6:10])
            fun = model.rhs_fast() if fast else model.rhs
            sol2 = solve_ivp(fun, (t_cut, cfg.duration_s), y1, events=[separation, tick], **opts)
            if sol2.status == 1:
                t_end = min(cfg.duration_s, float(sol2.t[-1]) + cfg.tail_s)
                bar.set(float(sol2.t[-1]), total=float(t_end))
                y2 = sol2.y[:, -1].copy()
                y2[6:10] = quat_normalize(y2[6:10])
                sol3 = solve_ivp(fun, (float(sol2.t[-1]), t_end), y2, events=[tick], **opts)
                sol2 = _join(sol2, sol3)
            segments.append((t_cut, t_end, sol2 if callable(sol2) else sol2.sol, True))
        bar.set(float(t_end))

    dt = 1.0 / cfg.output_rate_hz
    n_pre = int(round(cfg.pre_release_s / dt))
    t = np.arange(-n_pre, int(np.floor(t_end / dt + 1e-9)) + 1) * dt
    Y = np.empty((t.size, 13))
    cut_flag = np.zeros(t.size, bool)
    Y[t < 0] = y0
    for t0, t1, dense, is_cut in segments:
        m = (t >= t0) & (t <= t1) if not is_cut else (t > t0)
        if not is_cut and t_cut is not None:
            m &= t <= t_cut
        Y[m] = dense(t[m]).T
        cut_flag[m] = is_cut
    p, v, q, w = Y[:, 0:3], Y[:, 3:6], quat_normalize(Y[:, 6:10]), Y[:, 10:13]

    # forces along the history: the same scalar force model, sample by sample
    Yn = np.concatenate([p, v, q, w], axis=1)
    if fast:
        F, T, fn, pg, pen, bpen = truth_fast.evaluate_many(Yn, cut_flag, *model.packed())
    else:
        F = np.empty((t.size, 3))
        T = np.empty((t.size, 3))
        fn = np.empty(t.size)
        pg = np.empty(t.size)
        pen = np.empty((t.size, model.lobes_B.shape[0]))
        bpen = np.empty(t.size)
        for k in range(t.size):
            model.cut = bool(cut_flag[k])
            F[k], T[k], fn[k], pg[k], pen[k], bpen[k] = model.evaluate(Yn[k])
    # hanging: the release rope holds the lander at rest (a_ng = -g)
    hang = t < 0
    a_ng = F / lander.mass
    a_ng[hang] = -GRAVITY_SPF
    Jw = w @ model.J.T
    alpha = (T - np.cross(w, Jw)) @ model.Jinv.T
    alpha[hang] = 0.0

    events = {"release": 0.0}
    if t_cut is not None:
        events["bungee_cut"] = t_cut
    in_contact = fn > 1.0
    if np.any(in_contact):
        idx = np.flatnonzero(in_contact)
        first = idx[0]
        gap = np.flatnonzero(~in_contact[first:])
        last = first + (gap[0] - 1 if gap.size else in_contact[first:].size - 1)
        events["first_contact"] = float(t[first])
        events["peak_load"] = float(t[first + np.argmax(fn[first : last + 1])])
        events["rebound"] = float(t[last])
    if np.any(bpen > 0):
        events["body_contact"] = float(t[np.flatnonzero(bpen > 0)[0]])
    return DropTruth(
        t=t,
        p_I=p,
        v_I=v,
        q_I_B=q,
        w_B=w,
        alpha_B=alpha,
        a_ng_I=a_ng,
        contact_force=fn,
        gauge_pressure=pg,
        lobe_penetration=pen,
        body_penetration=bpen,
        events=events,
        rig=true_rig,
        nominal_rig=nominal_rig,
        p_release=p_release,
        q_release=q0,
        config=cfg,
    )
