"""Horizontal winds under the parachute from the reconstructed trajectory (AMELIA Sect. 10).

Primary method, ``method="attitude"``: the parachute–module system weather-vanes into the
air-relative velocity, so the module's −Z_G axis points along it: ``v_air ≈ s d`` with
``d = −Z_G`` in local NED (smoothed attitude) and ``s > 0``.  With zero vertical wind the down
components agree, ``s = v_D / d_D``, hence::

    wind_h = v_h − v_D d_h / d_D          (h = north, east)

with ``v`` the ground-relative velocity ``v_M − ω×p_M`` in NED at the vehicle.  This needs
neither the density nor the drag coefficients, unlike the paper's acceleration balance.

Cross-check, ``method="specific_force"``: the same relation with ``d`` the direction of the
measured specific force rotated to NED.  The non-gravitational force (riser tension + module
drag) points *against* the air-relative velocity, so ``d = −f`` (``d_h/d_D`` is scale-free).
This is the paper's horizontal-acceleration method in closed form: its no-wind drag prediction
``f_h = −k|v_air| v_air,h`` with ``f_D = −k|v_air| v_D`` gives ``v_air,h = v_D f_h / f_D`` once the
unknown ``k = ρ C S / 2m`` is eliminated by the vertical component.  On the truth simulator
(module swinging about the riser attachment) −f stays within ~1° of v_air while −Z_G swings by
2-10°, so this variant is the more accurate there (wind rms 1.1 vs 1.9 m/s, max 2.2 vs 6 m/s);
both stay within 2.5 m/s inside the wind layers.

Both per-sample estimates oscillate with the pendulum motion; they are averaged over a centred
window of one pendulum period (estimated from the spectrum of the tilt, or ``window_s``), which
nulls the fundamental oscillation; half a window is dropped at each end of a valid stretch so
that every kept window is full and centred.  Valid samples: under the parachute (phase ≥ 1) from
``PDD + settle_s`` (inflation transient, AMELIA: 180–190 s after EIP), outside the FSR window,
with the axis at least 30° below the horizon.  Invalid samples carry NaN.

1σ: first-order propagation of the trajectory covariance ``P`` (velocity, attitude and, through
``ω×p``, position blocks; for the specific-force method also the accelerometer noise
``sigmas.accel``) through the per-sample Jacobian, averaged over the window as fully correlated
(the smoothed-trajectory errors vary slowly), plus the model error ``sigmas.wind_model`` in
quadrature.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.bodies import MARS
from workbench.core.frames import ned_basis
from workbench.core.interpolation import interp_rows
from workbench.core.rotation import quat_to_dcm, skew
from workbench.problems.entry.atmosphere import as_profile_sigmas
from workbench.problems.entry.state import DP, DTH, DV

__all__ = ["WindResult", "pendulum_period", "estimate_winds"]


@dataclass(frozen=True)
class WindResult:
    """Wind profile along the trajectory (n input samples).

    ``t`` [s from EIP], ``h_amr`` [m above 3396 km], ``wind_N``/``wind_E`` [m/s] the horizontal
    wind the air blows *towards* (NaN where not valid), ``sigma_N``/``sigma_E`` 1σ [m/s] (NaN
    where not valid), ``valid`` (n,) bool, ``method`` ("attitude" or "specific_force").
    """

    t: np.ndarray
    h_amr: np.ndarray
    wind_N: np.ndarray
    wind_E: np.ndarray
    sigma_N: np.ndarray
    sigma_E: np.ndarray
    valid: np.ndarray
    method: str


def pendulum_period(t: np.ndarray, x: np.ndarray, band_hz: tuple[float, float] = (0.25, 3.0)) -> float | None:
    """Dominant period [s] of the signal(s) x (n,) or (n, k) sampled at t (n,) within ``band_hz``.

    Resampled on a uniform grid, detrended (linear), Hann-windowed; the summed power spectrum's
    peak in the band, refined by a parabola through the log-power of the three bins around it.
    Returns None when fewer than 3 periods of the band's slowest frequency are covered, or when
    the peak is at the band edge or less than 10× the band's median power (no clear oscillation).
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float).reshape(t.size, -1)
    if t.size < 8 or (t[-1] - t[0]) < 3.0 / band_hz[0]:
        return None
    dt = max(float(np.median(np.diff(t))), 1e-3)
    tu = np.arange(t[0], t[-1], dt)
    xu = interp_rows(tu, t, x)
    A = np.stack([np.ones_like(tu), tu - tu.mean()], -1)
    xu = xu - A @ np.linalg.lstsq(A, xu, rcond=None)[0]
    nfft = int(2 ** np.ceil(np.log2(8 * tu.size)))
    spec = np.sum(np.abs(np.fft.rfft(xu * np.hanning(tu.size)[:, None], n=nfft, axis=0)) ** 2, axis=1)
    freq = np.fft.rfftfreq(nfft, dt)
    band = np.flatnonzero((freq >= band_hz[0]) & (freq <= band_hz[1]))
    if band.size < 3:
        return None
    j = int(np.argmax(spec[band]))
    if j < 2 or j > band.size - 3 or spec[band[j]] < 10.0 * np.median(spec[band]):
        return None  # no clear in-band peak
    k = band[j]
    if 0 < k < spec.size - 1:
        y0, y1, y2 = np.log(spec[k - 1 : k + 2] + 1e-300)
        den = y0 - 2 * y1 + y2
        k = k + (0.5 * (y0 - y2) / den if den < 0 else 0.0)
    return float(1.0 / (k * (freq[1] - freq[0])))


def _window_mean(t: np.ndarray, x: np.ndarray, valid: np.ndarray, window: float) -> tuple[np.ndarray, np.ndarray]:
    """Centred moving mean of x (n, k) over ``round(window / dt)`` consecutive valid samples (dt the
    median step; the estimate is valid on the uniform grid well after PDD).  Only samples whose
    full window lies inside their contiguous valid segment are kept (half a window is dropped at
    each segment end, so a sinusoid of period ``window`` averages out everywhere and no one-sided
    window biases a trend).  Returns (mean (n, k), kept (n,) bool); not-kept samples get 0."""
    n = t.size
    if n == 0:
        return np.zeros_like(x), np.zeros(0, bool)
    seg = np.cumsum(np.concatenate([[0], (valid[1:] != valid[:-1]).astype(int)]))
    idx = np.arange(n)
    first = np.full(seg[-1] + 1, n)
    last = np.full(seg[-1] + 1, -1)
    np.minimum.at(first, seg, idx)
    np.maximum.at(last, seg, idx)
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    k = max(1, int(round(window / dt)))
    lo = idx - k // 2
    hi = lo + k
    kept = valid & (lo >= first[seg]) & (hi <= last[seg] + 1)
    lo = np.clip(lo, 0, n)
    hi = np.clip(hi, 0, n)
    c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(np.where(valid[:, None], x, 0.0), axis=0)])
    return np.where(kept[:, None], (c[hi] - c[lo]) / k, 0.0), kept


def estimate_winds(
    t: np.ndarray,
    p_M: np.ndarray,
    v_M: np.ndarray,
    q_M_G: np.ndarray,
    P: np.ndarray,
    f_G: np.ndarray,
    phase: np.ndarray,
    vehicle=None,
    atmosphere_result=None,
    *,
    sigmas=None,
    events=None,
    method: str = "attitude",
    window_s: float | None = None,
    settle_s: float = 10.0,
    fsr_exclusion_s: tuple[float, float] = (-0.5, 3.0),
    default_window_s: float = 2.0,
) -> WindResult:
    """Estimate the horizontal wind under the parachute (see module docstring).

    Args:
        t: (n,) time [s from EIP], increasing.
        p_M, v_M: (n, 3) smoothed position [m] and inertial velocity [m/s] in MMED.
        q_M_G: (n, 4) smoothed attitude (G → M, scalar-last).
        P: (n, 9, 9) error-state covariance ``[δv_M, δθ_G, δp_M]`` (``q_true = q ⊗ exp(δθ)``).
        f_G: (n, 3) specific force in G [m/s²] (used by ``method="specific_force"``).
        phase: (n,) int, 0 entry, 1 PDD..FSR, 2 FSR..BSR.
        vehicle, atmosphere_result: accepted for interface compatibility; neither method needs
            them (the density and drag coefficients cancel, see the module docstring).
        sigmas: :class:`~workbench.problems.entry.atmosphere.EntryProfileSigmas` (uses
            ``wind_model`` [m/s] and ``accel`` [m/s²]), a mapping, or None.
        events: optional {"PDD": t, "FSR": t} [s]; default: first sample of phase 1 / phase 2.
        method: "attitude" (primary) or "specific_force" (cross-check).
        window_s: averaging window [s]; None = one pendulum period estimated from the tilt
            spectrum (0.25–3 Hz), ``default_window_s`` when none is found.
        settle_s: seconds after PDD before the estimate is valid.
        fsr_exclusion_s: (before, after) [s] around FSR marked invalid.

    Returns:
        :class:`WindResult` on the n input samples.
    """
    t = np.asarray(t, dtype=float)
    p_M = np.asarray(p_M, dtype=float)
    v_M = np.asarray(v_M, dtype=float)
    q_M_G = np.asarray(q_M_G, dtype=float)
    P = np.asarray(P, dtype=float)
    f_G = np.asarray(f_G, dtype=float)
    phase = np.asarray(phase, dtype=int)
    if method not in ("attitude", "specific_force"):
        raise ValueError(f"estimate_winds: unknown method {method!r}; use 'attitude' or 'specific_force'")
    n = t.size
    for name, a, shape in (("p_M", p_M, (n, 3)), ("v_M", v_M, (n, 3)), ("q_M_G", q_M_G, (n, 4)), ("P", P, (n, 9, 9))):
        if a.shape != shape:
            raise ValueError(f"estimate_winds: {name} has shape {a.shape}, expected {shape}")
    sig = as_profile_sigmas(sigmas)
    h = np.linalg.norm(p_M, axis=-1) - MARS.reference_radius

    omega = np.array([0.0, 0.0, MARS.rotation_rate])
    C_N_M = ned_basis(p_M)  # MMED's +Z is the pole
    C_M_G = quat_to_dcm(q_M_G)
    v_N = np.einsum("nij,nj->ni", C_N_M, v_M - np.cross(omega, p_M))
    d_G = -f_G if method == "specific_force" else np.broadcast_to([0.0, 0.0, -1.0], (n, 3))
    d_N = np.einsum("nij,njk,nk->ni", C_N_M, C_M_G, d_G)

    # validity
    events = {} if events is None else dict(events)
    valid = phase >= 1
    t_pdd = events.get("PDD", t[int(np.argmax(phase >= 1))] if valid.any() else None)
    t_fsr = events.get("FSR", t[int(np.argmax(phase >= 2))] if (phase >= 2).any() else None)
    if t_pdd is not None:
        valid &= t >= t_pdd + settle_s
    if t_fsr is not None:
        valid &= ~((t >= t_fsr + fsr_exclusion_s[0]) & (t <= t_fsr + fsr_exclusion_s[1]))
    dnorm = np.linalg.norm(d_N, axis=-1)
    valid &= np.isfinite(d_N).all(axis=-1) & (d_N[:, 2] > 0.5 * np.maximum(dnorm, 1e-12))
    if method == "specific_force":
        valid &= np.isfinite(f_G).all(axis=-1)

    dD = np.where(valid, d_N[:, 2], 1.0)
    dh = np.where(valid[:, None], d_N[:, :2], 0.0)
    vD = v_N[:, 2]
    w_raw = v_N[:, :2] - vD[:, None] * dh / dD[:, None]

    # first-order Jacobian of w_h w.r.t. (v_N, d_N), then to the error state
    Jv = np.zeros((n, 2, 3))
    Jv[:, 0, 0] = Jv[:, 1, 1] = 1.0
    Jv[:, :, 2] = -dh / dD[:, None]
    Jd = np.zeros((n, 2, 3))
    Jd[:, 0, 0] = Jd[:, 1, 1] = -vD / dD
    Jd[:, :, 2] = vD[:, None] * dh / dD[:, None] ** 2
    J = np.zeros((n, 2, 9))
    J[:, :, DV] = Jv @ C_N_M  # δv_N = C_N_M δv_M
    J[:, :, DP] = -(Jv @ C_N_M) @ skew(omega)  # δv_ground = −ω×δp
    C_N_G = C_N_M @ C_M_G
    J[:, :, DTH] = -(Jd @ C_N_G) @ skew(np.asarray(d_G))  # δd_M = C (δθ × d_G) = −C [d_G×] δθ
    cov = np.einsum("nai,nij,nbj->nab", J, P, J)
    if method == "specific_force":
        Jf = Jd @ C_N_G  # δd_G = −δf_G; sign irrelevant for the variance
        cov = cov + sig.accel**2 * np.einsum("nai,nbi->nab", Jf, Jf)
    sd_state = np.sqrt(np.clip(np.stack([cov[:, 0, 0], cov[:, 1, 1]], -1), 0.0, None))

    # averaging window: one pendulum period
    if window_s is None:
        window_s = default_window_s
        if valid.sum() >= 8:
            tilt = d_N[valid, :2] / d_N[valid, 2:3]
            period = pendulum_period(t[valid], tilt)
            if period is not None:
                window_s = period
    avg, valid = _window_mean(t, np.concatenate([w_raw, sd_state], axis=1), valid, window_s)
    w_avg, sd_avg = avg[:, :2], avg[:, 2:]
    sigma = np.sqrt(sd_avg**2 + sig.wind_model**2)

    nan = np.full(n, np.nan)
    return WindResult(
        t=t.copy(),
        h_amr=h,
        wind_N=np.where(valid, w_avg[:, 0], nan),
        wind_E=np.where(valid, w_avg[:, 1], nan),
        sigma_N=np.where(valid, sigma[:, 0], nan),
        sigma_E=np.where(valid, sigma[:, 1], nan),
        valid=valid,
        method=method,
    )
