"""Preprocessing of the entry telemetry (AMELIA Sect. 4): from the ``EntryTelemetry`` as read
(:mod:`workbench.problems.entry.telemetry`) to the strapdown input :class:`PreprocessedIMU`.

:func:`preprocess` (AMELIA Sects. 4–5): (1) the 1 Hz on-board position/velocity brought to the 10 Hz
grid, by default acceleration-aided (the on-board total acceleration integrated between nodes, the
mismatch spread so the result passes through every node; ``nav_interpolation="cubic"`` is the
paper's plain cubic); (2) gravity removed at the on-board position and the result rotated to the
body with the on-board attitude, ``f_G = C_G_M(q_nav) (a_M − g)``, which recovers the measured
specific force whatever the attitude error; (3) gaps become :class:`GapBridge` from the on-board
solution at their edges (Sect. 5); (4) saturated X/Y rates rebuilt consistently with the lateral
acceleration the riser drives (``ẇ_x ≈ c f_y``, c fitted around the run; a cubic when the fit is
poor or for Z), with a 10 °/s ``sigma_w`` there (Table 3); (5) 100 Hz resampling for
``resample_window_s`` after PDD (Sect. 4, "Data extrapolation during PDD") with their own 1σ.
Measured accuracies of each step: docs/tuning/entry.md, "preprocess.py".

Frames: M = MMED inertial, G = GNC body; ``q_M_G`` body → inertial (Hamilton, scalar-last); the TM
JPL quaternion is converted with :func:`~workbench.core.rotation.quat_from_jpl`.
Reference: Aboudan et al., Space Sci. Rev. 214:97 (2018), Sects. 3–5, Tables 1 and 3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicHermiteSpline, CubicSpline
from scipy.spatial.transform import Rotation, Slerp

from workbench.core.bodies import MARS, Body
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import quat_conjugate, quat_rotate, quat_to_dcm
from workbench.estimation.strapdown import GapBridge
from workbench.problems.entry.telemetry import EntryTelemetry, true_runs

__all__ = [
    "GapBridge",
    "PreprocessedIMU",
    "PreprocessConfig",
    "onboard_nav_at",
    "rebuild_saturated_rate",
    "preprocess",
]


# --------------------------------------------------------------------------------------------
# data model
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PreprocessedIMU:
    """Strapdown input on one time grid (n,) [s]: 10 Hz TM samples plus the 100 Hz resampled
    ones after PDD.

    ``f_G`` (n,3) [m/s²] specific force and ``w_G`` (n,3) [rad/s] body rate (saturated samples
    rebuilt); ``sigma_f``, ``sigma_w`` (n,3) their 1σ per sample; ``saturated`` (n,) any gyro
    axis saturated (or between the neighbours of a saturated run, for resampled points);
    ``resampled`` (n,) sample interpolated, not in the TM; ``gaps`` — gap k lies between
    samples i and i+1 with ``t[i] = t_a``; ``g_M`` (n,3) the gravity removed (at the
    interpolated on-board position); ``q_M_G_nav`` (n,4), ``p_M_nav``, ``v_M_nav`` (n,3) the
    on-board solution on the same grid; ``notes`` what preprocessing did (saturation runs,
    resampling, interpolation fallbacks).
    """

    t: np.ndarray
    f_G: np.ndarray
    w_G: np.ndarray
    sigma_f: np.ndarray
    sigma_w: np.ndarray
    saturated: np.ndarray
    resampled: np.ndarray
    gaps: list[GapBridge]
    g_M: np.ndarray
    q_M_G_nav: np.ndarray
    p_M_nav: np.ndarray
    v_M_nav: np.ndarray
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class PreprocessConfig:
    """Preprocessing settings (SI).  Defaults: AMELIA Table 3 sigmas (rate 0.01 °/s, acceleration
    0.001 m/s², rate at PDD 10 °/s — used for the rebuilt saturated samples and for every sample
    interpolated after PDD), 1 m/s² for interpolated accelerations (the measured interpolation
    error of 10 Hz data through the parachute inflation: ~0.1–0.9 m/s² rms per axis), gyro range
    187.5 °/s with a 0.05 °/s detection margin, a gap is a step > 2.5 × nominal, 100 Hz
    resampling over 5 s after PDD, acceleration-aided interpolation of the on-board p/v
    ("acceleration" or "cubic"), saturated (and resampled) X/Y rates consistent with the lateral
    acceleration when that model fits (``rebuild_from_accel``), else a cubic through 2
    neighbours per side."""

    sigma_w: float = math.radians(0.01)
    sigma_f: float = 1e-3
    sigma_w_saturated: float = math.radians(10.0)
    sigma_w_resampled: float = math.radians(10.0)
    sigma_f_resampled: float = 1.0
    saturation: float = math.radians(187.5)
    saturation_margin: float = math.radians(0.05)
    gap_factor: float = 2.5
    resample_rate_hz: float = 100.0
    resample_window_s: float = 5.0
    nav_interpolation: str = "acceleration"
    rebuild_neighbours: int = 2
    rebuild_from_accel: bool = True
    body: Body = field(default=MARS, repr=False)

    def __post_init__(self) -> None:
        if self.nav_interpolation not in ("acceleration", "cubic"):
            raise ValueError(f"nav_interpolation must be 'acceleration' or 'cubic', got {self.nav_interpolation!r}")
        if self.gap_factor <= 1.0:
            raise ValueError(f"gap_factor must be > 1, got {self.gap_factor}")


# --------------------------------------------------------------------------------------------
# on-board navigation on the IMU grid
# --------------------------------------------------------------------------------------------


def _segments(t: np.ndarray, gap_factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Inclusive (starts, ends) indices of the gap-free segments of the time grid t (n,)."""
    dt = np.diff(t)
    if dt.size == 0:
        return np.array([0]), np.array([t.size - 1])
    brk = np.flatnonzero(dt > gap_factor * np.median(dt))
    return np.r_[0, brk + 1], np.r_[brk, t.size - 1]


def _integrals(ts: np.ndarray, a: np.ndarray):
    """V(t) = ∫a, P(t) = ∫V from ts[0], exact for a linear between the samples; returns a function
    of query times (q,) -> (V (q,3), P (q,3)), a polynomial extrapolation outside [ts0, ts-1]."""
    h = np.diff(ts)
    V = np.zeros_like(a)
    V[1:] = np.cumsum(0.5 * (a[1:] + a[:-1]) * h[:, None], axis=0)
    P = np.zeros_like(a)
    P[1:] = np.cumsum(h[:, None] * V[:-1] + (h**2)[:, None] * (2.0 * a[:-1] + a[1:]) / 6.0, axis=0)

    def at(tq: np.ndarray):
        k = np.clip(np.searchsorted(ts, tq, side="right") - 1, 0, ts.size - 2)
        tau = (tq - ts[k])[:, None]
        hk = h[k][:, None]
        da = a[k + 1] - a[k]
        Vq = V[k] + a[k] * tau + da * tau**2 / (2.0 * hk)
        Pq = P[k] + V[k] * tau + a[k] * tau**2 / 2.0 + da * tau**3 / (6.0 * hk)
        return Vq, Pq

    return at


def onboard_nav_at(
    t_eval: np.ndarray,
    t_gnc: np.ndarray,
    a_M: np.ndarray,
    t_nav: np.ndarray,
    p_nav: np.ndarray,
    v_nav: np.ndarray,
    *,
    gap_factor: float = 2.5,
    method: str = "acceleration",
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """On-board position and velocity (q,3) [m, m/s] at times ``t_eval`` (q,), never interpolated
    across a TM gap.

    ``t_gnc`` (n,) / ``a_M`` (n,3) the 10 Hz on-board total acceleration (valid rows only);
    ``t_nav`` (m,) / ``p_nav``, ``v_nav`` (m,3) the 1 Hz on-board solution.  ``method``:
    ``"acceleration"`` integrates ``a_M`` (linear between samples) from the previous node of the
    same gap-free segment and spreads the mismatch at the next node (exact at the nodes);
    ``"cubic"`` is a cubic Hermite in position (slopes = velocity) and a cubic spline in
    velocity over the segment's nodes.  A segment without a node (or with a single TM sample)
    falls back to the cubic over all nodes (noted).  Returns ``(p, v, notes)``.
    """
    t_eval = np.asarray(t_eval, float)
    starts, ends = _segments(t_gnc, gap_factor)
    seg_of = np.clip(np.searchsorted(t_gnc[starts], t_eval, side="right") - 1, 0, starts.size - 1)
    p_out = np.full((t_eval.size, 3), np.nan)
    v_out = np.full((t_eval.size, 3), np.nan)
    notes: list[str] = []
    tol = 1e-6
    for s in np.unique(seg_of):
        sel = np.flatnonzero(seg_of == s)
        ts = t_gnc[starts[s] : ends[s] + 1]
        jn = np.flatnonzero((t_nav >= ts[0] - tol) & (t_nav <= ts[-1] + tol))
        te = t_eval[sel]
        if jn.size == 0 or (method == "acceleration" and ts.size < 2):
            notes.append(
                f"on-board p/v: no 1 Hz node in the TM segment {ts[0]:.2f}–{ts[-1]:.2f} s; "
                "cubic over all nodes used there"
            )
            jn_all = np.arange(t_nav.size)
            p_out[sel] = CubicHermiteSpline(t_nav[jn_all], p_nav[jn_all], v_nav[jn_all])(te)
            v_out[sel] = CubicSpline(t_nav[jn_all], v_nav[jn_all])(te)
            continue
        tn, pn, vn = t_nav[jn], p_nav[jn], v_nav[jn]
        if method == "cubic":
            if tn.size == 1:
                p_out[sel] = pn[0] + vn[0] * (te - tn[0])[:, None]
                v_out[sel] = vn[0]
            else:
                p_out[sel] = CubicHermiteSpline(tn, pn, vn)(te)
                v_out[sel] = CubicSpline(tn, vn)(te)
            continue
        at = _integrals(ts, a_M[starts[s] : ends[s] + 1])
        Vn, Pn = at(tn)
        Ve, Pe = at(te)
        j = np.clip(np.searchsorted(tn, te, side="right") - 1, 0, tn.size - 1)
        d = (te - tn[j])[:, None]
        v = vn[j] + Ve - Vn[j]
        p = pn[j] + vn[j] * d + Pe - Pn[j] - Vn[j] * d
        if tn.size > 1:  # spread the mismatch at the next node over each interval
            H = np.diff(tn)[:, None]
            ev = vn[1:] - (vn[:-1] + Vn[1:] - Vn[:-1])
            ep = pn[1:] - (pn[:-1] + vn[:-1] * H + Pn[1:] - Pn[:-1] - Vn[:-1] * H + ev * H / 2.0)
            inner = (j < tn.size - 1) & (te >= tn[j])
            ji = j[inner]
            sfrac = d[inner] / H[ji]
            v[inner] += ev[ji] * sfrac
            p[inner] += ev[ji] * H[ji] * sfrac**2 / 2.0 + ep[ji] * sfrac
        p_out[sel], v_out[sel] = p, v
    return p_out, v_out, notes


# --------------------------------------------------------------------------------------------
# saturation
# --------------------------------------------------------------------------------------------


def _rate_from_acceleration(
    t: np.ndarray,
    w: np.ndarray,
    f: np.ndarray,
    sat: np.ndarray,
    segment: np.ndarray,
    ax: int,
    i0: int,
    i1: int,
    window_s: float,
):
    """Fit ``ẇ_ax = c0 f_lat + c1`` (lat = the other lateral axis) on the unsaturated sample pairs
    within ``window_s`` of the run; returns ``(antiderivative of the spline of f_lat, c, R², n)``
    or None when there are too few pairs."""
    lat = 1 - ax
    idx = np.flatnonzero((segment == segment[i0]) & (t >= t[i0] - window_s) & (t <= t[i1] + window_s))
    if idx.size < 10:
        return None
    S = CubicSpline(t[idx], f[idx, lat]).antiderivative()
    k0, k1 = idx[:-1], idx[1:]
    ok = ~sat[k0, ax] & ~sat[k1, ax]
    k0, k1 = k0[ok], k1[ok]
    if k0.size < 8:
        return None
    A = np.column_stack([S(t[k1]) - S(t[k0]), t[k1] - t[k0]])
    dw = w[k1, ax] - w[k0, ax]
    c, *_ = np.linalg.lstsq(A, dw, rcond=None)
    r2 = 1.0 - float(np.sum((dw - A @ c) ** 2)) / max(float(np.sum(dw**2)), 1e-300)
    return S, c, r2, int(k0.size)


def _resample_rate_from_acceleration(
    t: np.ndarray, w: np.ndarray, f: np.ndarray, sat: np.ndarray, ax: int, tn: np.ndarray
) -> tuple[np.ndarray | None, float]:
    """Rate of axis ``ax`` (0 or 1) at times ``tn`` inside a gap-free window of samples ``t``,
    integrated between the bracketing samples from ``ẇ_ax = c0 f_lat + c1`` (fitted on the
    window's unsaturated pairs) and blended so both samples are met.  Returns (values, R²)."""
    model = _rate_from_acceleration(t, w, f, sat, np.zeros(t.size, int), ax, 0, t.size - 1, 0.0)
    if model is None:
        return None, math.nan
    S, c, r2, _ = model
    k = np.clip(np.searchsorted(t, tn, side="right") - 1, 0, t.size - 2)
    fwd = w[k, ax] + c[0] * (S(tn) - S(t[k])) + c[1] * (tn - t[k])
    bwd = w[k + 1, ax] - c[0] * (S(t[k + 1]) - S(tn)) - c[1] * (t[k + 1] - tn)
    s = (tn - t[k]) / (t[k + 1] - t[k])
    return (1.0 - s) * fwd + s * bwd, r2


def rebuild_saturated_rate(
    t: np.ndarray,
    w: np.ndarray,
    segment: np.ndarray,
    threshold: float,
    margin: float,
    n_side: int = 2,
    f: np.ndarray | None = None,
    *,
    window_s: float = 3.0,
    min_r2: float = 0.9,
) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """Detect and rebuild saturated gyro samples (AMELIA Sect. 4, "reconstructed yaw rate").

    ``t`` (n,) [s], ``w`` (n,3) [rad/s], ``segment`` (n,) gap-free segment id of each sample,
    ``f`` (n,3) [m/s²] the body specific force (optional).  A sample of an axis is saturated if
    ``|w| ≥ threshold − margin``.  Each run of saturated samples (of one sign) is rebuilt

    * **consistent with the acceleration** (X and Y axes, when ``f`` is given): under the
      parachute the riser pulls at a point on the symmetry axis, so the torque about X (Y) is
      proportional to the lateral force along Y (X): ``ẇ_x ≈ c0 f_y + c1``.  ``c`` is fitted on
      the unsaturated sample pairs within ``window_s`` (Δw against the integral of the cubic
      spline of f); if the fit explains ≥ ``min_r2`` of Δw, the rate across the run is integrated
      from both unsaturated neighbours and the two blended linearly (so both ends are met);
    * otherwise by the cubic through up to ``n_side`` unsaturated neighbours on each side.

    Either way the magnitude is bounded below by ``threshold`` (the true rate exceeded it).  A
    run without an unsaturated neighbour on both sides is left clipped.  Returns ``(w_rebuilt
    (n,3), saturated (n,3) bool, runs)``, ``runs`` a list of dicts (axis, i0, i1, t0, t1, t_left,
    t_right, peak [rad/s], rebuilt, method "acceleration"/"cubic"/"clipped", r2, gain).
    """
    w = np.asarray(w, float)
    sat = np.abs(w) >= threshold - margin
    out = w.copy()
    runs: list[dict] = []
    for ax in range(3):
        for sgn in (1.0, -1.0):
            m = sat[:, ax] & (np.sign(w[:, ax]) == sgn)
            for i0, i1 in true_runs(m):
                left, right = [], []
                k = i0 - 1
                while k >= 0 and len(left) < n_side and not sat[k, ax] and segment[k] == segment[i0]:
                    left.append(k)
                    k -= 1
                k = i1 + 1
                while k < t.size and len(right) < n_side and not sat[k, ax] and segment[k] == segment[i1]:
                    right.append(k)
                    k += 1
                info = {"axis": ax, "i0": i0, "i1": i1, "t0": float(t[i0]), "t1": float(t[i1])}
                info["t_left"] = float(t[left[0]]) if left else float(t[i0])
                info["t_right"] = float(t[right[0]]) if right else float(t[i1])
                info.update(r2=math.nan, gain=math.nan)
                if not left or not right:
                    info.update(peak=float(np.max(np.abs(w[i0 : i1 + 1, ax]))), rebuilt=False, method="clipped")
                    runs.append(info)
                    continue
                ts = t[i0 : i1 + 1]
                model = (
                    None
                    if f is None or ax == 2
                    else _rate_from_acceleration(t, w, f, sat, segment, ax, i0, i1, window_s)
                )
                if model is not None and model[2] >= min_r2:
                    S, c, r2, _ = model
                    L, R = left[0], right[0]
                    fwd = w[L, ax] + c[0] * (S(ts) - S(t[L])) + c[1] * (ts - t[L])
                    bwd = w[R, ax] - c[0] * (S(t[R]) - S(ts)) - c[1] * (t[R] - ts)
                    s = (ts - t[L]) / (t[R] - t[L])
                    val = (1.0 - s) * fwd + s * bwd
                    info.update(method="acceleration", r2=float(r2), gain=float(c[0]))
                else:
                    pts = np.array(sorted(left + right))
                    coef = np.polyfit(t[pts] - t[i0], w[pts, ax], min(3, pts.size - 1))
                    val = np.polyval(coef, ts - t[i0])
                    info.update(method="cubic", r2=float(model[2]) if model is not None else math.nan)
                val = sgn * np.maximum(sgn * val, threshold)
                out[i0 : i1 + 1, ax] = val
                info.update(peak=float(np.max(np.abs(val))), rebuilt=True)
                runs.append(info)
    runs.sort(key=lambda r: r["t0"])
    return out, sat, runs


# --------------------------------------------------------------------------------------------
# preprocessing
# --------------------------------------------------------------------------------------------


def preprocess(tm: EntryTelemetry, config: PreprocessConfig | None = None) -> PreprocessedIMU:
    """AMELIA Sect. 4 preprocessing of read telemetry into strapdown input (see the module docstring).

    ``config``: a :class:`PreprocessConfig` (a scenario's: ``EntryConfig.preprocess`` of
    :mod:`workbench.problems.entry.config`) or None (defaults).  Rows without acceleration are left
    out of the grid.
    """
    cfg = PreprocessConfig() if config is None else config
    notes: list[str] = []
    ok = np.asarray(tm.a_valid, bool)
    t = tm.t_gnc[ok]
    a = tm.a_M_total[ok]
    w_raw = tm.w_G[ok]
    q = tm.q_M_G_nav[ok]
    if t.size < 4:
        raise ValueError("preprocess: fewer than 4 GNC samples with acceleration")
    starts, ends = _segments(t, cfg.gap_factor)
    seg = np.zeros(t.size, int)
    for s, (i0, i1) in enumerate(zip(starts, ends, strict=True)):
        seg[i0 : i1 + 1] = s

    def nav_at(te):
        p, v, nn = onboard_nav_at(
            te, t, a, tm.t_nav, tm.p_M_nav, tm.v_M_nav, gap_factor=cfg.gap_factor, method=cfg.nav_interpolation
        )
        notes.extend(n for n in nn if n not in notes)
        return p, v

    p_nav, v_nav = nav_at(t)
    g = gravity_j2(p_nav, cfg.body)
    f = quat_rotate(quat_conjugate(q), a - g)

    # gaps (AMELIA Sect. 5)
    bridges: list[GapBridge] = []
    for i in ends[:-1]:
        Ca = quat_to_dcm(q[i]).T
        Cb = quat_to_dcm(q[i + 1]).T
        dv = v_nav[i + 1] - v_nav[i]
        dp = p_nav[i + 1] - p_nav[i]
        T = t[i + 1] - t[i]
        bridges.append(
            GapBridge(
                t_a=float(t[i]),
                t_b=float(t[i + 1]),
                dv_G=Ca @ dv,
                dp_G=Ca @ dp,
                dp_rel_G=Ca @ (dp - v_nav[i] * T),
                dC=Cb @ Ca.T,
            )
        )
        notes.append(f"gap {t[i]:.2f}–{t[i + 1]:.2f} s ({T:.2f} s): bridged with the on-board Δv, Δp, ΔC")

    # saturation
    w, sat_ax, runs = rebuild_saturated_rate(
        t,
        w_raw,
        seg,
        cfg.saturation,
        cfg.saturation_margin,
        cfg.rebuild_neighbours,
        f if cfg.rebuild_from_accel else None,
    )
    for r in runs:
        ax = "xyz"[r["axis"]]
        if r["rebuilt"]:
            how = (
                f"integrated from ẇ_{ax} = {r['gain']:.3g} f_{'yx'[r['axis']]} (fit R² {r['r2']:.3f}) between "
                "the unsaturated neighbours"
                if r["method"] == "acceleration"
                else "a cubic through the unsaturated neighbours"
            )
            notes.append(
                f"w_{ax} saturated {r['t0']:.2f}–{r['t1']:.2f} s ({r['i1'] - r['i0'] + 1} samples): rebuilt by {how}, "
                f"peak {math.degrees(r['peak']):.1f} °/s, σ {math.degrees(cfg.sigma_w_saturated):g} °/s"
            )
        else:
            notes.append(
                f"w_{ax} saturated {r['t0']:.2f}–{r['t1']:.2f} s at the edge of the data: left clipped, "
                f"σ {math.degrees(cfg.sigma_w_saturated):g} °/s"
            )
    sigma_f = np.full((t.size, 3), cfg.sigma_f)
    sigma_w = np.full((t.size, 3), cfg.sigma_w)
    sigma_w[sat_ax] = cfg.sigma_w_saturated
    saturated = sat_ax.any(axis=1)
    resampled = np.zeros(t.size, bool)

    # 100 Hz resampling after PDD
    pdd = tm.events.get("PDD")
    if pdd is None:
        notes.append("no PDD event: no 100 Hz resampling")
    elif cfg.resample_window_s > 0 and cfg.resample_rate_hz > 0:
        step = 1.0 / cfg.resample_rate_hz
        tn = pdd + step * np.arange(int(round(cfg.resample_window_s / step)) + 1)
        s_pdd = seg[np.clip(np.searchsorted(t, pdd, side="right") - 1, 0, t.size - 1)]
        i0, i1 = starts[s_pdd], ends[s_pdd]
        keep = (tn >= t[i0]) & (tn <= t[i1])
        if not keep.all():
            notes.append(f"100 Hz resampling cut at the TM segment end ({t[i1]:.2f} s)")
        tn = tn[keep]
        near = np.abs(t[np.clip(np.searchsorted(t, tn), 0, t.size - 1)] - tn) < 1e-6
        near |= np.abs(t[np.clip(np.searchsorted(t, tn) - 1, 0, t.size - 1)] - tn) < 1e-6
        tn = tn[~near]
        if tn.size:
            loc = np.arange(i0, i1 + 1)
            loc = loc[(t[loc] >= pdd - 1.0) & (t[loc] <= pdd + cfg.resample_window_s + 1.0)]
            fn = CubicSpline(t[loc], f[loc])(tn)
            wn = CubicSpline(t[loc], w[loc])(tn)
            if cfg.rebuild_from_accel:
                for ax in (0, 1):
                    wn_ax, r2 = _resample_rate_from_acceleration(t[loc], w[loc], f[loc], sat_ax[loc], ax, tn)
                    if wn_ax is not None and r2 >= 0.9:
                        wn[:, ax] = wn_ax
                        notes.append(f"w_{'xy'[ax]} resampled consistently with f_{'yx'[ax]} (ẇ fit R² {r2:.3f})")
            qn = Slerp(t[loc], Rotation.from_quat(q[loc]))(tn).as_quat()
            pn, vn = nav_at(tn)
            gn = gravity_j2(pn, cfg.body)
            satn = np.zeros((tn.size, 3), bool)
            for r in runs:
                satn[(tn > r["t_left"]) & (tn < r["t_right"]), r["axis"]] = True
            sw = np.full((tn.size, 3), cfg.sigma_w_resampled)
            sw[satn] = np.maximum(cfg.sigma_w_saturated, cfg.sigma_w_resampled)
            notes.append(
                f"{tn.size} samples added at {cfg.resample_rate_hz:g} Hz in {pdd:.2f}–"
                f"{pdd + cfg.resample_window_s:.2f} s after PDD (cubic spline of f_G and w_G, slerp of the attitude)"
            )
            t_all = np.concatenate([t, tn])
            order = np.argsort(t_all, kind="stable")
            t = t_all[order]

            def cat(x, y):
                return np.concatenate([x, y])[order]

            f, w, q, p_nav, v_nav, g = (cat(f, fn), cat(w, wn), cat(q, qn), cat(p_nav, pn), cat(v_nav, vn), cat(g, gn))
            sigma_f = cat(sigma_f, np.full((tn.size, 3), cfg.sigma_f_resampled))
            sigma_w = cat(sigma_w, sw)
            saturated = cat(saturated, satn.any(axis=1))
            resampled = cat(resampled, np.ones(tn.size, bool))

    return PreprocessedIMU(
        t=t,
        f_G=f,
        w_G=w,
        sigma_f=sigma_f,
        sigma_w=sigma_w,
        saturated=saturated,
        resampled=resampled,
        gaps=bridges,
        g_M=g,
        q_M_G_nav=q,
        p_M_nav=p_nav,
        v_M_nav=v_nav,
        notes=tuple(notes),
    )
