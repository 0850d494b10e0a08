"""Measurement models and error models of the drop-test instruments (REDLand paper, "Test article").

* Four ENDEVCO accelerometer triads on the base petal (BP, PYBP, PXBP, MXBP): range ±2000 g,
  accuracy ~0.2 g. A triad at lever arm ``r_B`` from the CM senses the specific force
  ``f_B = C_B_I a_ng_I + α_B × r_B + ω_B × (ω_B × r_B)`` (REDLand Eq. 3 and 7).
* A CFX triaxial rate gyro, ±1000 °/s, ±3 % accuracy (taken as 3σ scale-factor error).
* The IDDAS acquisition: anti-alias low-pass at 500 Hz (modelled as a 4th-order Butterworth
  applied at the simulation rate) and sampling at ``sample_rate_hz``; saturation at the range.
* A Microstrain 3DM (gravity + magnetic unit vectors) read while the lander hangs, for the
  initial attitude by the algebraic method.
* Optional range aiding (the paper's future work): a bungee-sheave odometer measuring the rope
  length from the sheave to the attachment until the cut, and radar guns at fixed chamber points
  measuring range and range rate to a reflector on the lander.

Functions here produce *measurements from truth* (synthetic scenarios) and the matching
*predictions from a state* (the estimator's h(x)); the two share only the geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, filtfilt, lfilter, lfilter_zi

from workbench.core.rotation import quat_conjugate, quat_from_rotvec, quat_rotate
from workbench.problems.droptest.config import Ranging

__all__ = [
    "ImuErrorModel",
    "specific_force_at",
    "acquisition_filter",
    "acquisition_group_delay",
    "apply_errors",
    "tilt_unit_vectors",
    "RangingSpec",
]


@dataclass(frozen=True)
class ImuErrorModel:
    """Error budget of one sensor axis family (1σ values, SI).

    ``noise`` white noise per sample [m/s² or rad/s]; ``bias`` constant per axis; ``scale``
    scale-factor error (fraction); ``misalignment`` small-angle axis misalignment [rad];
    ``full_scale`` saturation limit [SI]. Draws are per axis and per run.
    """

    noise: float
    bias: float
    scale: float
    misalignment: float
    full_scale: float


def specific_force_at(
    r_B: np.ndarray, a_ng_I: np.ndarray, q_I_B: np.ndarray, w_B: np.ndarray, alpha_B: np.ndarray
) -> np.ndarray:
    """Specific force [m/s², body] (n,3) sensed at lever arm ``r_B`` (3,) [m] (REDLand Eq. 3, 7).

    a_ng_I (n,3) non-gravitational CM acceleration in SPF; q_I_B (n,4); w_B, alpha_B (n,3) body.
    """
    a_B = quat_rotate(quat_conjugate(q_I_B), a_ng_I)
    return a_B + np.cross(alpha_B, r_B) + np.cross(w_B, np.cross(w_B, r_B))


def acquisition_filter(
    x: np.ndarray, fs_hz: float, cutoff_hz: float = 500.0, order: int = 4, kind: str = "butterworth"
) -> np.ndarray:
    """The acquisition (anti-alias) filter along axis 0 of ``x`` sampled at ``fs_hz`` [Hz]:
    ``kind`` "butterworth" — causal Butterworth low-pass (the IDDAS 500 Hz filter), started at rest
    on x[0]; "zero_phase" — the same design run forward and backward (``filtfilt``: no delay, the
    squared magnitude); "none" (or ``order`` 0) — ``x`` unchanged."""
    x = np.asarray(x, float)
    if kind == "none" or int(order) == 0:
        return x.copy()
    b, a = butter(order, cutoff_hz / (0.5 * fs_hz))
    if kind == "zero_phase":
        return filtfilt(b, a, x, axis=0)
    if kind != "butterworth":
        raise ValueError(f"acquisition filter kind must be butterworth, zero_phase or none, got {kind!r}")
    zi = lfilter_zi(b, a)
    out = np.empty_like(x)
    flat = x.reshape(x.shape[0], -1)
    o = out.reshape(x.shape[0], -1)
    for j in range(flat.shape[1]):
        o[:, j], _ = lfilter(b, a, flat[:, j], zi=zi * flat[0, j])
    return out


def acquisition_group_delay(cutoff_hz: float = 500.0, order: int = 4, kind: str = "butterworth") -> float:
    """Low-frequency group delay [s] of the acquisition filter (0 for "zero_phase" and "none").

    Butterworth: evaluated with ``scipy.signal.group_delay`` on the same design at a sample rate
    200× the cutoff (close to the analogue filter): ≈ 0.83 ms for the 4th-order 500 Hz IDDAS filter.
    The reconstruction shifts the telemetry time tags back by this delay.
    """
    if kind in ("zero_phase", "none") or int(order) == 0:
        return 0.0
    from scipy.signal import group_delay

    fs = 200.0 * cutoff_hz
    b, a = butter(order, cutoff_hz / (0.5 * fs))
    _, gd = group_delay((b, a), w=[1e-3], fs=fs)
    return float(gd[0] / fs)


def apply_errors(x_true: np.ndarray, model: ImuErrorModel, rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Apply per-run scale, misalignment and bias, per-sample noise and saturation to (n,3) truth.

    Returns (measured (n,3), drawn-errors dict). Saturated samples are clipped at ±full_scale,
    as a real channel would be.
    """
    S = np.diag(rng.normal(0.0, model.scale, 3))
    M = np.array([[0, -1, 1], [1, 0, -1], [-1, 1, 0]]) * rng.normal(0.0, model.misalignment, (3, 3))
    b = rng.normal(0.0, model.bias, 3)
    y = x_true @ (np.eye(3) + S + M).T + b + rng.normal(0.0, model.noise, x_true.shape)
    y = np.clip(y, -model.full_scale, model.full_scale)
    return y, {"scale": np.diag(S), "bias": b, "matrix": S + M}


def tilt_unit_vectors(u: np.ndarray, sigma: float, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """Rotate the unit vector ``u`` (3,) by random small tilts ⟂ u of 1σ ``sigma`` [rad] per axis.

    Returns (3,) if ``n`` is None, else (n,3).
    """
    u = np.asarray(u, float) / np.linalg.norm(u)
    k = 1 if n is None else n
    d = rng.normal(0.0, sigma, (k, 3))
    d -= (d @ u)[:, None] * u
    out = quat_rotate(quat_from_rotvec(d), u)
    return out[0] if n is None else out


@dataclass(frozen=True)
class RangingSpec:
    """Range-aiding instruments of a scenario's ``[sensors.ranging]`` table (SI units).

    ``odometer``: a bungee-sheave odometer measures the rope length from the sheave (the bungee
    anchor of the setup file) to the attachment point until the cut, 1σ ``odometer_sigma`` [m];
    ``guns``: radar-gun name -> fixed SPF position [m], measuring range (1σ ``range_sigma`` [m])
    and range rate (1σ ``rate_sigma`` [m/s]) to a reflector at ``reflector_B`` [m, body];
    ``rate_hz`` sampling rate of the ranging file.  Per gun (name -> value, every gun listed):
    ``reflectors_L`` its reflector in the lander frame L [m] (``reflector_B`` is the common one,
    also in L: the asset's ``cm_m`` turns it into the body frame), ``range_sigmas`` [m] and
    ``rate_sigmas`` [m/s]; ``odometer_zero`` [m] the odometer reads the rope length minus this;
    ``odometer_quantisation`` [m] its count step (0: not quantised; the rounding adds q²/12 to its
    variance, :attr:`odometer_variance`).
    """

    odometer: bool
    odometer_sigma: float
    guns: dict[str, np.ndarray]
    reflector_B: np.ndarray
    range_sigma: float
    rate_sigma: float
    rate_hz: float
    reflectors_L: dict[str, np.ndarray]
    range_sigmas: dict[str, float]
    rate_sigmas: dict[str, float]
    odometer_zero: float
    odometer_quantisation: float = 0.0

    @property
    def odometer_variance(self) -> float:
        """Variance [m²] of one odometer reading: its noise plus the rounding to its count step q,
        uniform over one step (q²/12)."""
        return self.odometer_sigma**2 + self.odometer_quantisation**2 / 12.0

    @classmethod
    def from_settings(cls, r: Ranging) -> RangingSpec:
        """The instruments of the run's ``[sensors.ranging]`` settings (:class:`~workbench.problems.
        droptest.config.Ranging`), in SI units."""
        return cls(
            odometer=r.odometer,
            odometer_sigma=r.odometer_sigma_m,
            guns=dict(r.radar_guns),
            reflector_B=np.asarray(r.reflector_body_m),
            range_sigma=r.radar_range_sigma_m,
            rate_sigma=r.radar_rate_sigma_mps,
            rate_hz=r.rate_hz,
            reflectors_L={g: np.asarray(p) for g, p in r.reflectors_body_m.items()},
            range_sigmas=dict(r.range_sigma_m),
            rate_sigmas=dict(r.rate_sigma_mps),
            odometer_zero=r.odometer_zero_m,
            odometer_quantisation=r.odometer_quantisation_m,
        )
