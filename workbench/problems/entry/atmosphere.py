"""Atmospheric density, pressure and temperature profiles from a reconstructed entry (AMELIA Sect. 9).

What: the drag equation ``ρ = 2 m a_Z / (v_r² C S)`` along the smoothed trajectory, iterated on the
drag coefficients (Mach, Knudsen, angle of attack from the previous smoothed profile), the
blackout and transients filled (hydrostatic or exponential), hydrostatic pressure from the top,
ideal-gas temperature, a refined (smoothed) profile and first-order 1σ
(:func:`reconstruct_atmosphere`, settings :class:`AtmosphereSettings`).  Why: the entry's
deceleration is the only in-situ measurement of the atmosphere along the path.  Every array of
:class:`ProfileIteration` and :class:`AtmosphereResult` lives on the profile grid (the input
samples from the top of the profile plus fill samples in time gaps).  The full method notes and
the measurements behind the fill's choices are in ``docs/tuning/entry.md``.

Reference: Aboudan et al., Space Sci. Rev. 214:97, 2018 (AMELIA), Sect. 9, Eqs. 2-6, Table 3.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from workbench.core.atmosphere import R_UNIVERSAL, Atmosphere
from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import quat_to_dcm
from workbench.problems.entry.state import DP, DV, N_ERR

__all__ = [
    "MARS_MOLAR_MASS",
    "CA_FIRST_GUESS",
    "FILL_TEMPERATURE_SHAPES",
    "EntryProfileSigmas",
    "AtmosphereSettings",
    "as_profile_sigmas",
    "profile_sigmas",
    "ProfileIteration",
    "AtmosphereResult",
    "air_relative_velocity",
    "angle_of_attack",
    "radial_gravity",
    "hydrostatic_pressure",
    "exponential_fill",
    "fill_sigma",
    "smooth_in_altitude",
    "system_mass",
    "drag_area",
    "reconstruct_atmosphere",
]

MARS_MOLAR_MASS = 43.41e-3
"""Mean molar mass of the Martian atmosphere below 104 km [kg/mol] (AMELIA Sect. 9)."""
FILL_TEMPERATURE_SHAPES = ("model", "linear")
"""Temperature families of the hydrostatic blackout fill (:class:`AtmosphereSettings`)."""
CA_FIRST_GUESS = 1.65
"""Entry axial coefficient of the first iteration (AMELIA Sect. 9: mean C_D from the deceleration
peak to PDD over 500 Monte Carlo entries)."""


@dataclass(frozen=True)
class EntryProfileSigmas:
    """1σ inputs of the atmosphere and wind uncertainty (AMELIA Table 3, "Reconstruction").

    Attributes:
        cd_rel: relative 1σ of each drag coefficient [-] (Table 3: 10 %).
        accel: accelerometer noise 1σ per sample [m/s²] (Table 3: 0.001).
        wind: horizontal wind 1σ per component [m/s] below ``wind_ceiling_m`` (Table 3: 10).
        wind_ceiling_m: altitude AMR [m] above which the wind term is dropped (paper: 30 km).
        p_top_rel: relative 1σ of the top pressure taken from the default model [-] (engineering
            choice, 20 %: the paper's Table 7 models differ by tens of % at 100 km).
        fill_temperature_K: 1σ [K] of the true temperature's departure from the temperature the
            fill assumes (the default model's shape plus a linear trend, a linear trend alone,
            or an isothermal layer for the exponential fill), a Gaussian process in altitude (see :func:`fill_sigma`).
            Physical argument, not a fit to any truth: Mars temperature profiles depart from a
            climatological shape by ~10 K through the middle atmosphere (the Mars Climate
            Database's climatology, warm, cold and dust scenarios differ by 10-20 K at 30-70 km,
            which is AMELIA Table 7's model spread; entry profiles carry gravity waves of a few
            K that grow with altitude).  Default 10 K.
        fill_correlation_km: correlation length [km] of that departure (squared-exponential
            kernel; default 10 km, the vertical scale of the waves and layers the shape misses).
        wind_model: model error of the wind estimate [m/s] (module/canopy misalignment and the
            module's lag in shear; engineering choice, 2 m/s), used by ``entry_winds``.
    """

    cd_rel: float = 0.10
    accel: float = 1.0e-3
    wind: float = 10.0
    wind_ceiling_m: float = 30.0e3
    p_top_rel: float = 0.20
    fill_temperature_K: float = 10.0
    fill_correlation_km: float = 10.0
    wind_model: float = 2.0


def as_profile_sigmas(sigmas) -> EntryProfileSigmas:
    """Coerce ``None`` (defaults), an :class:`EntryProfileSigmas` or a mapping of its field names
    (unknown keys are ignored, so a wider sigma table can be passed) into :class:`EntryProfileSigmas`."""
    if sigmas is None:
        return EntryProfileSigmas()
    if isinstance(sigmas, EntryProfileSigmas):
        return sigmas
    if isinstance(sigmas, Mapping):
        names = {f.name for f in fields(EntryProfileSigmas)}
        return EntryProfileSigmas(**{k: float(v) for k, v in sigmas.items() if k in names})
    raise TypeError(f"sigmas must be None, EntryProfileSigmas or a mapping, not {type(sigmas).__name__}")


@dataclass(frozen=True)
class ProfileIteration:
    """One pass of the drag-coefficient loop (raw profile) on the m profile samples.

    Attributes: ``iteration`` (1-based); ``t`` [s from EIP]; ``h_amr`` [m above 3396 km];
    ``rho`` [kg/m³]; ``p`` [Pa]; ``T`` [K]; ``cd`` the effective drag coefficient
    ``(C_A S_module + C_P S_P)/S_capsule`` referred to the capsule reference area (the module's
    C_A alone during the entry); ``mach`` and ``kn`` (module reference length) used for the
    coefficients of this pass; ``filled`` (m,) bool, samples filled by the exponential;
    ``max_rel_change`` max |Δx/x| of ρ, p, T against the previous pass (nan for the first).
    """

    iteration: int
    t: np.ndarray
    h_amr: np.ndarray
    rho: np.ndarray
    p: np.ndarray
    T: np.ndarray
    cd: np.ndarray
    mach: np.ndarray
    kn: np.ndarray
    filled: np.ndarray
    max_rel_change: float


@dataclass(frozen=True)
class AtmosphereResult:
    """Result of :func:`reconstruct_atmosphere`.

    ``iterations`` every pass, ``final`` the last one; ``rho_smooth``, ``p_smooth``, ``T_smooth``
    the refined profiles (m,); ``sigma_rho`` [kg/m³], ``sigma_p`` [Pa], ``sigma_T`` [K] first-order
    1σ (m,); ``converged`` whether the last change was below the tolerance; ``n_iterations``.
    """

    iterations: list[ProfileIteration]
    final: ProfileIteration
    rho_smooth: np.ndarray
    p_smooth: np.ndarray
    T_smooth: np.ndarray
    sigma_rho: np.ndarray
    sigma_p: np.ndarray
    sigma_T: np.ndarray
    converged: bool
    n_iterations: int


# ----------------------------------------------------------------------------------- geometry
def _omega_M() -> np.ndarray:
    return np.array([0.0, 0.0, MARS.rotation_rate])


def _up_M(p_M: np.ndarray) -> np.ndarray:
    return p_M / np.linalg.norm(p_M, axis=-1, keepdims=True)


def _north_east_M(p_M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local north and east unit vectors (..., 3) in M at p_M (M's +Z is the Mars pole)."""
    up = _up_M(p_M)
    east = np.cross(np.array([0.0, 0.0, 1.0]), up)
    east /= np.linalg.norm(east, axis=-1, keepdims=True)
    return np.cross(up, east), east


def air_relative_velocity(p_M: np.ndarray, v_M: np.ndarray, wind_NE: np.ndarray | None = None) -> np.ndarray:
    """Air-relative velocity ``v − ω×p − w`` (n, 3) in M [m/s] for p_M, v_M (n, 3) in MMED.

    ω = ``[0, 0, MARS.rotation_rate]`` (the ~300 s entry approximation of the spec); ``wind_NE``
    (n, 2) horizontal wind north/east [m/s] (blowing towards), None for no wind.
    """
    p_M = np.asarray(p_M, dtype=float)
    v_rel = np.asarray(v_M, dtype=float) - np.cross(_omega_M(), p_M)
    if wind_NE is not None:
        wind_NE = np.asarray(wind_NE, dtype=float)
        north, east = _north_east_M(p_M)
        v_rel = v_rel - wind_NE[..., :1] * north - wind_NE[..., 1:2] * east
    return v_rel


def angle_of_attack(q_M_G: np.ndarray, v_rel_M: np.ndarray) -> np.ndarray:
    """Total angle of attack [rad] (n,): angle between −Z_G and the air-relative velocity (n, 3, M)."""
    C_M_G = quat_to_dcm(np.asarray(q_M_G, dtype=float))
    minus_z = -C_M_G[..., :, 2]
    u = v_rel_M / np.linalg.norm(v_rel_M, axis=-1, keepdims=True)
    return np.arccos(np.clip(np.sum(minus_z * u, axis=-1), -1.0, 1.0))


def radial_gravity(p_M: np.ndarray) -> np.ndarray:
    """Downward radial component [m/s²] (n,) of J2 gravity at p_M (n, 3) in M (positive down)."""
    p_M = np.asarray(p_M, dtype=float)
    return -np.sum(gravity_j2(p_M, MARS) * _up_M(p_M), axis=-1)


def _log_mean(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Logarithmic mean (a − b)/ln(a/b) of positive arrays (arithmetic mean when a ≈ b)."""
    r = np.log(a / b)
    small = np.abs(r) < 1e-8
    return np.where(small, 0.5 * (a + b), (a - b) / np.where(small, 1.0, r))


def hydrostatic_pressure(h: np.ndarray, rho: np.ndarray, g: np.ndarray, p0: float) -> np.ndarray:
    """Integrate ``dp/dh = −ρ g`` along the sample order from ``p0`` [Pa] at the first sample.

    h [m], rho [kg/m³] (> 0), g [m/s²] (n,); ρ is log-linear in h between samples (exact for an
    exponential atmosphere), g linear.  Returns p [Pa] (n,).
    """
    h = np.asarray(h, dtype=float)
    rho = np.asarray(rho, dtype=float)
    g = np.asarray(g, dtype=float)
    dp = -0.5 * (g[1:] + g[:-1]) * _log_mean(rho[1:], rho[:-1]) * np.diff(h)
    return p0 + np.concatenate([[0.0], np.cumsum(dp)])


def _fill_runs(h: np.ndarray, y: np.ndarray, good: np.ndarray, fit_window_m: float) -> list[tuple]:
    """Bad runs ``[a, b)`` with their edge anchors of log ρ.

    Returns tuples ``(a, b, h1, y1, s1, h2, y2, s2)``: upper edge (sample a−1) altitude, fitted
    log ρ and slope, lower edge (sample b) likewise; None for a missing side.
    """
    n = h.size
    bad = ~good
    edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(np.int8), [0]])))
    runs = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        upper = lower = (None, None, None)
        if a > 0:
            i = j = a - 1
            while j - 1 >= 0 and good[j - 1] and abs(h[j - 1] - h[i]) <= fit_window_m:
                j -= 1
            m, sl, c = _line_fit(h[j : i + 1], y[j : i + 1])
            upper = (h[i], m + sl * (h[i] - c), sl)
        if b < n:
            i = j = b
            while j + 1 < n and good[j + 1] and abs(h[j + 1] - h[i]) <= fit_window_m:
                j += 1
            m, sl, c = _line_fit(h[i : j + 1], y[i : j + 1])
            lower = (h[i], m + sl * (h[i] - c), sl)
        runs.append((int(a), int(b), *upper, *lower))
    return runs


def _line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least-squares ``y ≈ m + s (x − c)``; returns (m, s, c) with c = x̄ (s = 0 for < 2 points)."""
    c = float(x.mean())
    dx = x - c
    sxx = float(np.sum(dx * dx))
    s = float(np.sum(dx * (y - y.mean())) / sxx) if x.size >= 2 and sxx > 0 else 0.0
    return float(y.mean()), s, c


def exponential_fill(
    h: np.ndarray, rho: np.ndarray, good: np.ndarray, *, fit_window_m: float = 2000.0
) -> tuple[np.ndarray, np.ndarray]:
    """Fill the samples where ``good`` is False with an exponential in altitude (AMELIA Sect. 9).

    For each run of bad samples, log ρ is fitted linearly in h over the contiguous good samples
    on each side lying within ``fit_window_m`` [m] of the gap edge, evaluated at the edge, and
    interpolated linearly in h between the two edges (one-sided runs: extrapolated with that
    side's fit).  h [m], rho [kg/m³] (n,), good (n,) bool (non-finite or non-positive ρ counts
    as bad).  Returns (rho_filled, filled mask).  Raises ValueError when nothing is good.
    """
    rho, filled, _ = _exponential_fill(h, rho, good, fit_window_m)
    return rho, filled


def _exponential_fill(h, rho, good, fit_window_m):
    h = np.asarray(h, dtype=float)
    rho = np.array(rho, dtype=float)
    with np.errstate(invalid="ignore"):
        good = np.asarray(good, dtype=bool) & np.isfinite(rho) & (rho > 0)
    if not good.any():
        raise ValueError("exponential_fill: no valid density sample")
    filled = ~good
    if not filled.any():
        return rho, filled, []
    y = np.log(np.where(good, rho, 1.0))
    runs = _fill_runs(h, y, good, fit_window_m)
    for a, b, h1, y1, s1, h2, y2, s2 in runs:
        hs = h[a:b]
        if h1 is not None and h2 is not None:
            if abs(h2 - h1) > 1e-6:
                ys = y1 + (y2 - y1) * (hs - h1) / (h2 - h1)
            else:
                ys = np.full(hs.shape, 0.5 * (y1 + y2))
        elif h1 is not None:
            ys = y1 + s1 * (hs - h1)
        else:
            ys = y2 + s2 * (hs - h2)
        rho[a:b] = np.exp(ys)
    return rho, filled, runs


def _hydrostatic_gap(hh, gg, T_shape, T1, p1, y2, R_gas):
    """Density (k,) along the gap altitudes ``hh`` (k ≥ 2, hh[0] the upper edge, hh[-1] the lower)
    for ``T = T_shape + a + b (hh[0] − h)``: a gives T1 at the upper edge, b the density exp(y2) at
    the lower edge, p from ``dln p/dh = −g/(R T)`` from p1.  None if no such b exists."""
    from scipy.optimize import brentq

    depth = hh[0] - hh
    D = float(depth[-1])
    base = T_shape + (T1 - T_shape[0])
    if D <= 1.0 or not np.all(base > 0) or not np.isfinite(p1) or p1 <= 0:
        return None

    def log_rho(b):
        T = base + b * depth
        f = gg / (R_gas * T)
        lnp = np.log(p1) + np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * -np.diff(hh))])
        return lnp - np.log(R_gas * T)

    lo = -0.7 * float(np.min(base)) / D
    hi = float(np.max(base)) / D
    f_lo, f_hi = log_rho(lo)[-1] - y2, log_rho(hi)[-1] - y2
    if not (np.isfinite(f_lo) and np.isfinite(f_hi)) or f_lo * f_hi > 0:
        return None
    b = brentq(lambda x: log_rho(x)[-1] - y2, lo, hi, xtol=1e-12)
    return np.exp(log_rho(b))


def fill_sigma(
    h: np.ndarray,
    g: np.ndarray,
    T: np.ndarray,
    R_gas: float,
    sigma_T: float,
    corr_m: float,
    *,
    upper_edge: bool = True,
    lower_edge: bool = True,
) -> np.ndarray:
    """Relative 1σ [-] of a hydrostatic blackout fill along its samples (k,), from a physical prior.

    Samples ``h`` (k,) [m] in flight order (descending altitude; ``h[0]`` the upper edge when
    ``upper_edge``, ``h[-1]`` the lower edge when ``lower_edge``), radial gravity ``g`` (k,)
    [m/s²], the fill's temperature ``T`` (k,) [K], gas constant ``R_gas`` [J/(kg K)].  The true
    temperature is the fill's plus ``δT``, a zero-mean Gaussian process (squared-exponential
    kernel, 1σ ``sigma_T`` [K], correlation length ``corr_m`` [m]).  To first order the density
    error is ``δ ln ρ(h) = −∫_h^{h0} g δT /(R T²) dh' − δT(h)/T(h)`` (hydrostatic pressure from the
    upper edge, ideal gas).  The fill's temperature family (the assumed shape plus an offset and
    a linear trend in depth) absorbs the part of δT that its two constraints see — the upper
    edge's temperature and the lower edge's density — and the returned σ is that of ``δ ln ρ`` of
    the remaining part (a one-sided fill: an offset and the upper constraint only): zero at the
    matched edges, largest inside the gap.  Returns (k,).
    """
    h = np.asarray(h, dtype=float)
    g = np.asarray(g, dtype=float)
    T = np.asarray(T, dtype=float)
    k = h.size
    if k < 2 or sigma_T <= 0.0:
        return np.zeros(k)
    K = sigma_T**2 * np.exp(-0.5 * ((h[:, None] - h[None, :]) / corr_m) ** 2) + 1e-9 * np.eye(k)
    # trapezoid integral of w = g/(R T²) from the first sample: I[i] = Σ_j<i ½ (w_j + w_{j+1}) |Δh_j|
    w = g / (R_gas * T**2)
    dh = np.abs(np.diff(h))
    W = np.zeros((k, k))
    for i in range(1, k):
        W[i] = W[i - 1]
        W[i, i - 1] += 0.5 * w[i - 1] * dh[i - 1]
        W[i, i] += 0.5 * w[i] * dh[i - 1]
    A = -W - np.diag(1.0 / T)  # δ ln ρ = A δT: warmer air above lets ln p grow more slowly
    # the fill absorbs the part of δT in its own family (an offset, and a linear trend in depth
    # when it is two-sided) chosen to meet its constraints: residual = (I − B (C B)⁻¹ C) δT
    rows, cols = [], [np.ones(k)]
    if upper_edge:
        e0 = np.zeros(k)
        e0[0] = 1.0
        rows.append(e0)
    if lower_edge:
        rows.append(A[-1])
        cols.append(np.abs(h - h[0]))
    if rows:
        C = np.array(rows)
        B = np.array(cols[: len(rows)]).T
        M = np.eye(k) - B @ np.linalg.solve(C @ B, C)
    else:
        M = np.eye(k)
    AM = A @ M
    S = AM @ K @ AM.T
    return np.sqrt(np.clip(np.diag(S), 0.0, None))


def smooth_in_altitude(h: np.ndarray, y: np.ndarray, window_m: float, min_samples: int = 5) -> np.ndarray:
    """Local linear fit of y against h over a window of ``window_m`` [m] centred on each sample.

    The window is widened to at least ``min_samples`` neighbours in altitude order.  A local
    linear (order-1 Savitzky-Golay-like) fit leaves linear trends — e.g. log ρ of an exponential
    atmosphere — unbiased, also at the ends.  h, y (n,) -> (n,).
    """
    h = np.asarray(h, dtype=float)
    y = np.asarray(y, dtype=float)
    n = h.size
    if n < 3:
        return y.copy()
    order = np.argsort(h, kind="stable")
    hs = h[order]
    ys = y[order]
    hc = hs - hs.mean()
    idx = np.arange(n)
    lo = np.searchsorted(hs, hs - 0.5 * window_m, side="left")
    hi = np.searchsorted(hs, hs + 0.5 * window_m, side="right")
    k = max(int(min_samples), 3)
    lo = np.minimum(lo, np.clip(idx - k // 2, 0, max(n - k, 0)))
    hi = np.maximum(hi, np.minimum(lo + k, n))

    def csum(a):
        return np.concatenate([[0.0], np.cumsum(a)])

    S0 = (hi - lo).astype(float)
    c1, c2, cy, cxy = csum(hc), csum(hc * hc), csum(ys), csum(hc * ys)
    S1 = c1[hi] - c1[lo]
    S2 = c2[hi] - c2[lo]
    Sy = cy[hi] - cy[lo]
    Sxy = cxy[hi] - cxy[lo]
    den = S0 * S2 - S1 * S1
    ok = den > 1e-9 * np.maximum(S0 * S2, 1e-300)
    b = np.where(ok, (S0 * Sxy - S1 * Sy) / np.where(ok, den, 1.0), 0.0)
    a = (Sy - b * S1) / S0
    out = np.empty(n)
    out[order] = a + b * hc
    return out


# ----------------------------------------------------------------------------------- vehicle
def system_mass(vehicle, phase: np.ndarray) -> np.ndarray:
    """Mass [kg] (n,) decelerated by the measured drag: ``vehicle.mass_at(phase)``, plus the
    parachute mass ``vehicle.parachute.mass`` under the parachute (phase ≥ 1, AMELIA Eq. 5 m_D + m_P)
    unless the vehicle says its ``mass_at`` already includes it (``mass_at_includes_parachute``)."""
    phase = np.asarray(phase)
    m = np.asarray(vehicle.mass_at(phase), dtype=float)
    if not getattr(vehicle, "mass_at_includes_parachute", False):
        m = m + np.where(phase >= 1, float(vehicle.parachute.mass), 0.0)
    return m


def drag_area(
    vehicle, phase: np.ndarray, mach: np.ndarray, mean_free_path: np.ndarray, alpha: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Drag area terms of Eqs. 2 and 5 from the vehicle tables.

    Phase 0 capsule (``vehicle.capsule``), phase 1 capsule + parachute, phase 2 descent module
    (``vehicle.descent_module``) + parachute.  Inputs (n,): phase, Mach [-], mean free path [m],
    total angle of attack [rad].  Returns ``(CS_module, CS_parachute, kn_module, ca_module)``:
    ``C_A S`` of the module [m²], ``C_P S_P`` of the canopy [m²] (0 in phase 0), the module's
    Knudsen number (its table's reference length) and its axial coefficient.
    """
    phase = np.asarray(phase)
    n = phase.size
    cs_mod = np.zeros(n)
    cs_par = np.zeros(n)
    kn = np.zeros(n)
    ca_out = np.zeros(n)
    for table, sel in ((vehicle.capsule, phase <= 1), (vehicle.descent_module, phase >= 2)):
        if not sel.any():
            continue
        kn_t = mean_free_path[sel] / float(table.ref_length)
        ca, _, _ = table.coefficients(mach[sel], kn_t, alpha[sel])
        ca = np.asarray(ca, dtype=float)
        cs_mod[sel] = ca * float(table.ref_area)
        kn[sel] = kn_t
        ca_out[sel] = ca
    chute = phase >= 1
    if chute.any():
        para = vehicle.parachute
        cs_par[chute] = np.asarray(para.cd_at(mach[chute]), dtype=float) * float(para.ref_area)
    return cs_mod, cs_par, kn, ca_out


def _mean_free_path(atm: Atmosphere, p: np.ndarray, T: np.ndarray) -> np.ndarray:
    """λ = μ(T)/p sqrt(π R T/2) [m] with the gas constants of ``atm`` (as Atmosphere.mean_free_path)."""
    return atm.sutherland.viscosity(T) / p * np.sqrt(0.5 * np.pi * atm.gas_constant * T)


def _speed_of_sound(atm: Atmosphere, T: np.ndarray) -> np.ndarray:
    return np.sqrt(atm.gamma * atm.gas_constant * T)


def _rel_change(new: np.ndarray, old: np.ndarray) -> float:
    return float(np.max(np.abs(new - old) / np.abs(old)))


# ----------------------------------------------------------------------------------- main entry
def _profile_grid(t: np.ndarray, h: np.ndarray, max_gap_s: float, fill_step_m: float):
    """Profile grid: the samples plus, inside every time gap longer than ``max_gap_s``, samples
    evenly spaced in altitude (≤ ``fill_step_m``).  Returns (src (m,), w (m,)): grid sample j lies
    between input samples src[j] and src[j]+1 at fraction w[j] of the altitude step (w = 0 for
    input samples); time is taken linear in altitude across a gap."""
    n = t.size
    counts = np.zeros(n, dtype=int)
    gaps = np.flatnonzero(np.diff(t) > max_gap_s)
    if gaps.size:
        counts[gaps] = np.maximum(np.ceil(np.abs(h[gaps + 1] - h[gaps]) / fill_step_m).astype(int) - 1, 0)
    src = np.repeat(np.arange(n), 1 + counts)
    start = np.concatenate([[0], np.cumsum(1 + counts)[:-1]])
    w = (np.arange(src.size) - start[src]) / (1.0 + counts[src])
    return src, w


def _on_grid(x: np.ndarray, src: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Linear interpolation of per-sample x (n, ...) onto the grid of :func:`_profile_grid`."""
    nxt = np.minimum(src + 1, x.shape[0] - 1)
    ww = w.reshape((-1,) + (1,) * (x.ndim - 1))
    return x[src] + ww * (x[nxt] - x[src])


_SIGMA_ALIASES = {"cd": "cd_rel", "cd_sigma": "cd_rel", "wind_mps": "wind", "accel_mps2": "accel"}


@dataclass(frozen=True)
class AtmosphereSettings:
    """Settings of :func:`reconstruct_atmosphere` (``[atmosphere]``; defaults AMELIA Sect. 9).

    ``molar_mass_g_per_mol`` [g/mol] of the ideal-gas temperature; ``fill_method``
    "hydrostatic" or "exponential" (the paper) for two-sided gaps; ``fill_temperature_shape`` the
    hydrostatic fill's temperature across a gap: "model" (the default model's temperature plus an
    offset and a linear trend) or "linear" (an offset and a linear trend alone: only the two edge
    constraints, no assumed structure in between); ``tolerance`` convergence
    threshold of the max relative change of ρ, p, T; ``max_iterations`` (≥ 1); ``sigmas`` the
    :class:`EntryProfileSigmas` of the 1σ; ``min_specific_force`` a_Z [m/s²] that defines the top
    of the profile; ``p_top`` pressure [Pa] there (None: the default model's); time gaps longer
    than ``max_gap_s`` [s] get fill samples every ≤ ``fill_step_m`` [m] of altitude;
    ``inflation_drop_m`` [m] below PDD filled (parachute inflation transient); ``fsr_exclusion_s``
    (before, after) [s] around FSR filled (FSR spike); ``fill_fit_window_m`` [m] of the one-sided
    edge fits; ``smooth_window_m`` [m] of the refined (smoothed) profile.
    """

    molar_mass_g_per_mol: float = MARS_MOLAR_MASS * 1e3
    fill_method: str = "hydrostatic"
    fill_temperature_shape: str = "model"
    tolerance: float = 0.01
    max_iterations: int = 10
    sigmas: EntryProfileSigmas = EntryProfileSigmas()
    min_specific_force: float = 0.05
    p_top: float | None = None
    max_gap_s: float = 0.5
    fill_step_m: float = 100.0
    inflation_drop_m: float = 900.0
    fsr_exclusion_s: tuple[float, float] = (-0.5, 3.0)
    fill_fit_window_m: float = 2000.0
    smooth_window_m: float = 300.0

    @property
    def molar_mass(self) -> float:
        """Mean molar mass [kg/mol]."""
        return self.molar_mass_g_per_mol / 1e3


def profile_sigmas(sigmas) -> EntryProfileSigmas:
    """:func:`as_profile_sigmas` that also takes the scenario-style aliases (``cd``, ``cd_sigma``,
    ``wind_mps``, ``accel_mps2``) in a mapping."""
    if isinstance(sigmas, Mapping):
        sigmas = {_SIGMA_ALIASES.get(k, k): v for k, v in sigmas.items()}
    return as_profile_sigmas(sigmas)


@dataclass(frozen=True)
class _Grid:
    """The trajectory on the profile grid (m,), from the top of the profile: time ``t`` [s],
    altitude ``h`` [m AMR], air-relative speed ``v_r`` [m/s], angle of attack ``alpha`` [rad],
    radial gravity ``g_r`` [m/s²], variances of v_r and h, horizontal share ``u_h2`` of the
    air-relative direction, ``phase``, measured ``a_z`` (NaN on inserted samples), ``valid``, and
    the input samples' times and phases (``t_in``, ``phase_in``)."""

    t: np.ndarray
    h: np.ndarray
    v_r: np.ndarray
    alpha: np.ndarray
    g_r: np.ndarray
    var_vr: np.ndarray
    var_h: np.ndarray
    u_h2: np.ndarray
    phase: np.ndarray
    a_z: np.ndarray
    valid: np.ndarray
    t_in: np.ndarray
    phase_in: np.ndarray


def _checked_inputs(t, p_M, v_M, q_M_G, P, f_G, f_valid, phase, cfg: AtmosphereSettings) -> tuple:
    """The inputs as arrays, their shapes checked against n = t.size; ``ValueError`` naming the bad one."""
    t = np.asarray(t, dtype=float)
    arrays = (
        ("p_M", np.asarray(p_M, dtype=float), (t.size, 3)),
        ("v_M", np.asarray(v_M, dtype=float), (t.size, 3)),
        ("q_M_G", np.asarray(q_M_G, dtype=float), (t.size, 4)),
        ("P", np.asarray(P, dtype=float), (t.size, 9, 9)),
        ("f_G", np.asarray(f_G, dtype=float), (t.size, 3)),
        ("f_valid", np.asarray(f_valid, dtype=bool), (t.size,)),
        ("phase", np.asarray(phase, dtype=int), (t.size,)),
    )
    for name, a, shape in arrays:
        if a.shape != shape:
            raise ValueError(f"reconstruct_atmosphere: {name} has shape {a.shape}, expected {shape}")
    if cfg.max_iterations < 1:
        raise ValueError("reconstruct_atmosphere: max_iterations must be >= 1")
    if cfg.fill_method not in ("hydrostatic", "exponential"):
        raise ValueError(f"reconstruct_atmosphere: fill_method {cfg.fill_method!r}; use 'hydrostatic' or 'exponential'")
    if cfg.fill_temperature_shape not in FILL_TEMPERATURE_SHAPES:
        raise ValueError(
            f"reconstruct_atmosphere: fill_temperature_shape {cfg.fill_temperature_shape!r}; use 'model' or 'linear'"
        )
    return (t, *(a for _, a, _ in arrays))


def _profile_grid_inputs(t, p_M, v_M, q_M_G, P, f_G, f_valid, phase, wind_NE, cfg: AtmosphereSettings) -> _Grid:
    """The trajectory from the top of the profile (first valid a_Z ≥ ``min_specific_force``) on
    the profile grid (fill samples inside time gaps), with the per-sample inputs of the 1σ:
    variance of v_r from P (J = [u, 0, ω×u]) and of the altitude, and the horizontal part of u."""
    a_z_all = f_G[:, 2]
    with np.errstate(invalid="ignore"):
        usable = f_valid & np.isfinite(a_z_all) & (a_z_all >= cfg.min_specific_force)
    if not usable.any():
        raise ValueError(f"reconstruct_atmosphere: no valid sample with a_Z >= {cfg.min_specific_force} m/s²")
    s = slice(int(np.argmax(usable)), t.size)
    tt, pM, vM = t[s], p_M[s], v_M[s]
    h_in = np.linalg.norm(pM, axis=-1) - MARS.reference_radius
    wind = None if wind_NE is None else np.asarray(wind_NE, dtype=float)[s]
    v_rel_M = air_relative_velocity(pM, vM, wind)
    v_r_in = np.linalg.norm(v_rel_M, axis=-1)
    u = v_rel_M / v_r_in[:, None]
    J = np.zeros((h_in.size, N_ERR))
    J[:, DV] = u
    J[:, DP] = np.cross(_omega_M(), u)
    up_in = _up_M(pM)
    src, w = _profile_grid(tt, h_in, cfg.max_gap_s, cfg.fill_step_m)
    inserted = w > 0
    return _Grid(
        t=_on_grid(tt, src, w),
        h=_on_grid(h_in, src, w),
        v_r=_on_grid(v_r_in, src, w),
        alpha=_on_grid(angle_of_attack(q_M_G[s], v_rel_M), src, w),
        g_r=_on_grid(radial_gravity(pM), src, w),
        var_vr=_on_grid(np.einsum("ni,nij,nj->n", J, P[s], J), src, w),
        var_h=_on_grid(np.einsum("ni,nij,nj->n", up_in, P[s][:, DP, DP], up_in), src, w),  # [m²]
        u_h2=_on_grid(np.clip(1.0 - np.sum(u * up_in, axis=-1) ** 2, 0.0, 1.0), src, w),
        phase=phase[s][src],
        a_z=np.where(inserted, np.nan, a_z_all[s][src]),
        valid=f_valid[s][src] & ~inserted,
        t_in=tt,
        phase_in=phase[s],
    )


def _excluded(g: _Grid, events: Mapping[str, float] | None, cfg: AtmosphereSettings) -> np.ndarray:
    """Samples whose drag is not used (m,): invalid, the inflation transient below PDD, the FSR spike."""
    events = {} if events is None else dict(events)
    tt, ph_in, t_s, h = g.t_in, g.phase_in, g.t, g.h
    exclude = ~(g.valid & np.isfinite(g.a_z))
    t_pdd = events.get("PDD", tt[int(np.argmax(ph_in >= 1))] if (ph_in >= 1).any() else None)
    t_fsr = events.get("FSR", tt[int(np.argmax(ph_in >= 2))] if (ph_in >= 2).any() else None)
    if t_pdd is not None and t_s[0] <= t_pdd <= t_s[-1]:
        h_pdd = float(np.interp(t_pdd, t_s, h))
        exclude |= (t_s >= t_pdd) & (h > h_pdd - cfg.inflation_drop_m)
    if t_fsr is not None:
        exclude |= (t_s >= t_fsr + cfg.fsr_exclusion_s[0]) & (t_s <= t_fsr + cfg.fsr_exclusion_s[1])
    return exclude


@dataclass(frozen=True)
class _Gas:
    """What every profile pass shares: system ``mass`` (m,) [kg], capsule reference area ``s_ref``
    [m²], top pressure ``p0`` [Pa], gas constant ``R_gas`` [J/(kg K)], the default model's
    temperature ``T_shape`` (m,) [K] on the grid."""

    mass: np.ndarray
    s_ref: float
    p0: float
    R_gas: float
    T_shape: np.ndarray


def _profile(g: _Grid, gas: _Gas, cs: np.ndarray, exclude: np.ndarray, cfg: AtmosphereSettings) -> tuple:
    """One raw profile from the drag equation with drag area ``cs`` (m,) [m²]: ρ from a_Z, the
    excluded runs filled (exponential, then hydrostatic for two-sided runs when so configured),
    hydrostatic p from the top, T = p/(ρ R).  Returns (rho, p, T, filled, runs)."""
    h = g.h
    with np.errstate(invalid="ignore", divide="ignore"):
        rho_raw = 2.0 * gas.mass * g.a_z / (g.v_r**2 * cs)
    rho, filled, runs = _exponential_fill(h, rho_raw, ~exclude, cfg.fill_fit_window_m)
    if cfg.fill_method == "hydrostatic":
        for a, b, h1, y1, _, h2, y2, _ in runs:
            if h1 is None or h2 is None:
                continue
            p1 = hydrostatic_pressure(h[:a], rho[:a], g.g_r[:a], gas.p0)[-1]
            hh = np.concatenate([[h1], h[a:b], [h2]])
            gg = g.g_r[a - 1 : b + 1]
            Tsh = gas.T_shape[a - 1 : b + 1]
            if cfg.fill_temperature_shape == "linear":
                Tsh = np.full(Tsh.shape, Tsh[0])  # offset + trend only
            fill = _hydrostatic_gap(hh, gg, Tsh, p1 / (np.exp(y1) * gas.R_gas), p1, y2, gas.R_gas)
            if fill is not None:
                rho[a:b] = fill[1:-1]
    p = hydrostatic_pressure(h, rho, g.g_r, gas.p0)
    return rho, p, p / (rho * gas.R_gas), filled, runs


def _smoothed(g: _Grid, gas: _Gas, rho: np.ndarray, cfg: AtmosphereSettings) -> tuple:
    """The refined profile: log ρ smoothed in altitude, p and T recomputed.  Returns (rho, p, T)."""
    rho_s = np.exp(smooth_in_altitude(g.h, np.log(rho), cfg.smooth_window_m))
    p_s = hydrostatic_pressure(g.h, rho_s, g.g_r, gas.p0)
    return rho_s, p_s, p_s / (rho_s * gas.R_gas)


def _iterate(g: _Grid, gas: _Gas, vehicle, atm: Atmosphere, exclude: np.ndarray, cfg: AtmosphereSettings) -> tuple:
    """The drag-coefficient loop: iteration 1 takes Mach/Kn from the default model and a constant
    C_A for the entry, later ones from the previous smoothed profile, until the max relative change
    of ρ, p, T is below ``tolerance``.  Returns (iterations, converged, smoothed (rho, p, T),
    (cs_mod, cs_par, cs) of the last pass, the fill runs of the last pass)."""
    T_prev = gas.T_shape
    p_prev = np.asarray(atm.pressure(g.h), dtype=float)
    iterations: list[ProfileIteration] = []
    converged = False
    prev = None
    for it in range(1, cfg.max_iterations + 1):
        mach = g.v_r / _speed_of_sound(atm, T_prev)
        lam = _mean_free_path(atm, p_prev, T_prev)
        cs_mod, cs_par, kn, _ = drag_area(vehicle, g.phase, mach, lam, g.alpha)
        if it == 1:
            cs_mod = np.where(g.phase == 0, CA_FIRST_GUESS * gas.s_ref, cs_mod)
        cs = cs_mod + cs_par
        rho, p, T, filled, runs = _profile(g, gas, cs, exclude, cfg)
        change = np.nan if prev is None else max(_rel_change(x, y) for x, y in zip((rho, p, T), prev, strict=True))
        iterations.append(
            ProfileIteration(
                iteration=it,
                t=g.t,
                h_amr=g.h,
                rho=rho,
                p=p,
                T=T,
                cd=cs / gas.s_ref,
                mach=mach,
                kn=kn,
                filled=filled,
                max_rel_change=float(change),
            )
        )
        smooth = _smoothed(g, gas, rho, cfg)
        if prev is not None and change < cfg.tolerance:
            converged = True
            break
        prev = (rho, p, T)
        T_prev, p_prev = smooth[2], smooth[1]
    return iterations, converged, smooth, (cs_mod, cs_par, cs), runs


def _fill_rel_sigma(g: _Grid, gas: _Gas, final: ProfileIteration, runs: list, cfg: AtmosphereSettings) -> np.ndarray:
    """Relative density 1σ (m,) of the filled samples (:func:`fill_sigma` per run), zero elsewhere."""
    sig, h = cfg.sigmas, g.h
    rel_fill = np.zeros(h.size)
    for a, b, h1, _, _, h2, _, _ in runs:
        if b - a < 1:
            continue
        lo, hi = max(a - 1, 0), min(b + 1, h.size)  # the run with its measured edges
        T_shape = gas.T_shape[lo:hi]
        if cfg.fill_method == "exponential" or h1 is None or h2 is None:
            # an exponential (isothermal) fill misses the whole temperature structure across the gap
            extra = float(np.std(T_shape - np.polyval(np.polyfit(h[lo:hi], T_shape, 1), h[lo:hi])))
            sT = (
                float(np.hypot(sig.fill_temperature_K, extra))
                if cfg.fill_method == "exponential"
                else sig.fill_temperature_K
            )
        else:
            sT = sig.fill_temperature_K
        s_run = fill_sigma(
            h[lo:hi],
            g.g_r[lo:hi],
            final.T[lo:hi],
            gas.R_gas,
            sT,
            sig.fill_correlation_km * 1e3,
            upper_edge=h1 is not None and lo == a - 1,
            lower_edge=h2 is not None and hi == b + 1,
        )
        rel_fill[a:b] = s_run[(a - lo) : (a - lo) + (b - a)]
    return rel_fill


def _uncertainty(g: _Grid, gas: _Gas, final: ProfileIteration, areas: tuple, rel_fill, cfg) -> tuple:
    """First-order 1σ of ρ, p, T (docs/tuning/entry.md, atmosphere, item 7).  Returns (sigma_rho, sigma_p, sigma_T)."""
    sig, h, v_r, g_r = cfg.sigmas, g.h, g.v_r, g.g_r
    cs_mod, cs_par, cs = areas
    sig_wind = np.where(h < sig.wind_ceiling_m, sig.wind, 0.0)
    rel_v = 2.0 * np.sqrt(g.var_vr + sig_wind**2 * g.u_h2) / v_r  # ∂ρ/∂v_r = −2ρ/v_r
    rel_cd = sig.cd_rel * np.sqrt(cs_mod**2 + cs_par**2) / cs
    a_model = final.rho * v_r**2 * cs / (2.0 * gas.mass)  # equals a_Z where not filled
    rel_acc = sig.accel / np.maximum(np.abs(a_model), 1e-12)
    rel_corr = np.sqrt(rel_v**2 + rel_cd**2 + rel_fill**2)
    sigma_rho_rel = np.sqrt(rel_corr**2 + rel_acc**2)
    # pressure: correlated part integrated linearly, white part and p0 in quadrature
    wgt = 0.5 * (g_r[1:] + g_r[:-1]) * np.abs(np.diff(h))
    corr_i = wgt * 0.5 * (rel_corr[1:] * final.rho[1:] + rel_corr[:-1] * final.rho[:-1])
    white_i = wgt * 0.5 * (rel_acc[1:] * final.rho[1:] + rel_acc[:-1] * final.rho[:-1])
    sp_corr = np.concatenate([[0.0], np.cumsum(corr_i)])
    sp_white = np.sqrt(np.concatenate([[0.0], np.cumsum(white_i**2)]))
    sigma_p = np.sqrt(sp_corr**2 + sp_white**2 + (sig.p_top_rel * gas.p0) ** 2)
    sigma_T = final.T * np.sqrt((sigma_p / final.p) ** 2 + sigma_rho_rel**2)
    # the profile is a function of altitude: the altitude's own 1σ moves ρ(h) and p(h) by σ_h / H
    # (H = R T / g the local scale height); T(h) only by σ_h dT/dh, neglected
    rel_h = np.sqrt(np.maximum(g.var_h, 0.0)) * g_r / (gas.R_gas * final.T)
    sigma_rho = np.sqrt(sigma_rho_rel**2 + rel_h**2) * final.rho
    sigma_p = np.sqrt(sigma_p**2 + (rel_h * final.p) ** 2)
    return sigma_rho, sigma_p, sigma_T


def reconstruct_atmosphere(
    t: np.ndarray,
    p_M: np.ndarray,
    v_M: np.ndarray,
    q_M_G: np.ndarray,
    P: np.ndarray,
    f_G: np.ndarray,
    f_valid: np.ndarray,
    phase: np.ndarray,
    vehicle,
    *,
    default_atmosphere: Atmosphere,
    settings: AtmosphereSettings | None = None,
    events: Mapping[str, float] | None = None,
    wind_NE: np.ndarray | None = None,
) -> AtmosphereResult:
    """Reconstruct ρ, p, T along the trajectory by the drag-equation iteration (docs/tuning/entry.md).

    ``t`` (n,) time [s from EIP], increasing (may jump over data gaps); ``p_M``, ``v_M`` (n, 3)
    MMED position [m] and inertial velocity [m/s] (the smoothed trajectory); ``q_M_G`` (n, 4)
    attitude (G → M, scalar-last); ``P`` (n, 9, 9) error-state covariance ``[δv_M, δθ_G, δp_M]``;
    ``f_G`` (n, 3) specific force in G [m/s²] (only a_Z is used); ``f_valid`` (n,) bool; ``phase``
    (n,) 0 entry, 1 PDD..FSR, 2 FSR..BSR; ``vehicle`` the :class:`~workbench.models.aerodynamics.EntryVehicle`;
    ``default_atmosphere`` the model of iteration 1, of the top pressure, of the hydrostatic fill's
    temperature shape (``fill_temperature_shape="model"``) and of the gas constants; ``settings``
    the :class:`AtmosphereSettings` (None: defaults); ``events`` optional {"PDD": t, "FSR": t} [s]
    (default: first sample of phase 1 / 2); ``wind_NE`` optional (n, 2) wind north/east [m/s]
    subtracted in v_r (None: zero wind, as in the paper).  Returns an :class:`AtmosphereResult` on the profile grid.
    """
    cfg = AtmosphereSettings() if settings is None else settings
    t, p_M, v_M, q_M_G, P, f_G, f_valid, phase = _checked_inputs(t, p_M, v_M, q_M_G, P, f_G, f_valid, phase, cfg)
    atm = default_atmosphere
    g = _profile_grid_inputs(t, p_M, v_M, q_M_G, P, f_G, f_valid, phase, wind_NE, cfg)
    gas = _Gas(
        mass=system_mass(vehicle, g.phase),
        s_ref=float(vehicle.capsule.ref_area),
        p0=float(atm.pressure(g.h[0])) if cfg.p_top is None else float(cfg.p_top),
        R_gas=R_UNIVERSAL / cfg.molar_mass,
        T_shape=np.asarray(atm.temperature(g.h), dtype=float),
    )
    exclude = _excluded(g, events, cfg)
    iterations, converged, (rho_s, p_s, T_s), areas, runs = _iterate(g, gas, vehicle, atm, exclude, cfg)
    final = iterations[-1]
    rel_fill = _fill_rel_sigma(g, gas, final, runs, cfg)
    sigma_rho, sigma_p, sigma_T = _uncertainty(g, gas, final, areas, rel_fill, cfg)
    return AtmosphereResult(
        iterations=iterations,
        final=final,
        rho_smooth=rho_s,
        p_smooth=p_s,
        T_smooth=T_s,
        sigma_rho=sigma_rho,
        sigma_p=sigma_p,
        sigma_T=sigma_T,
        converged=converged,
        n_iterations=len(iterations),
    )
