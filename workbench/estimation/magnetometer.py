"""In-flight alignment of a magnetometer to the rate gyro: the magnetometer's axes, its hard-iron
offset and the field at a reference attitude, from a stretch of tumbling flight.

Over a few seconds the Earth's field is constant in an inertial frame, so in the IMU (gyro) frame it
turns against the integrated body rates: with ``C_0_B(t)`` the attitude at t relative to the
reference time t₀ (:func:`workbench.core.rotation.quat_history_from_body_rates`),

    m(t) = C_mag_imu · C_0_B(t)ᵀ · b₀ + o

where ``b₀`` is the field in the IMU frame at t₀, ``C_mag_imu`` the (proper) rotation from the IMU
axes to the magnetometer's and ``o`` the hard-iron offset in the magnetometer's axes.  For a given
rotation the model is linear in (b₀, o); for given (b₀, o) the rotation is an orthogonal Procrustes
(Wahba) problem.  :func:`align_magnetometer` alternates the two from several starting rotations about
the IMU z axis (a chip turned on its board) and keeps the best fit.  The rotation is restricted to
det = +1: the reflected solution −C with −b₀ fits equally well (the field's sign is not observable
from a rotating body), and a mounted chip cannot be a reflection, so the restriction fixes the sign.

Soft iron (a scale/shear of the field) is not modelled: its residual stays in ``rms``.  The
alignment is observable only when the body turns about more than one axis during the stretch; the
fit's ``rms`` and the field's dip against the site's inclination are the caller's checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MagnetometerAlignment", "align_magnetometer"]


@dataclass(frozen=True, eq=False)
class MagnetometerAlignment:
    """Result of :func:`align_magnetometer`: ``C_mag_imu`` (3, 3) rotation IMU → magnetometer axes;
    ``offset`` (3,) hard-iron offset in the magnetometer's axes [same unit as the samples];
    ``field_0`` (3,) the field in the IMU frame at the reference attitude; ``rms`` the RMS of the
    residuals per component; ``samples`` how many samples were fitted."""

    C_mag_imu: np.ndarray
    offset: np.ndarray
    field_0: np.ndarray
    rms: float
    samples: int

    def to_imu(self, m: np.ndarray) -> np.ndarray:
        """Samples m (..., 3) in the magnetometer's axes → the IMU frame, offset removed."""
        return (np.asarray(m, float) - self.offset) @ self.C_mag_imu


def _linear_step(C_B_0: np.ndarray, S: np.ndarray, m: np.ndarray, C: np.ndarray):
    """(field_0, offset, residuals (n, 3)) of the least-squares fit for a fixed rotation C; ``S`` the
    sum of ``C_B_0`` over the samples.  The normal equations are 6 × 6 because C · C_B_0 is
    orthogonal: AᵀA = [[n I, (C S)ᵀ], [C S, n I]]."""
    n = m.shape[0]
    CS = C @ S
    N = np.block([[n * np.eye(3), CS.T], [CS, n * np.eye(3)]])
    mC = m @ C  # rows (Cᵀ m_k)ᵀ
    rhs = np.concatenate([np.einsum("kji,kj->i", C_B_0, mC), m.sum(axis=0)])
    x = np.linalg.solve(N, rhs)
    u = C_B_0 @ x[:3]  # (n, 3) the field in the IMU frame
    return x[:3], x[3:], m - u @ C.T - x[3:], u


def align_magnetometer(
    C_0_B: np.ndarray, m: np.ndarray, starts: int = 8, iterations: int = 200, tol: float = 1e-9
) -> MagnetometerAlignment:
    """Fit the magnetometer's rotation, offset and the reference field (module docstring).

    ``C_0_B`` (n, 3, 3) the body attitudes relative to the reference time (body → reference frame);
    ``m`` (n, 3) the magnetometer's samples at the same times, in its own axes (any unit: the offset,
    field and rms come back in it).  ``starts`` initial rotations about the IMU z axis, evenly spaced
    over a turn; each is iterated until the residual RMS changes by less than ``tol`` (relative) or
    ``iterations`` passes.  ValueError with fewer than 10 samples."""
    m = np.asarray(m, float)
    C_0_B = np.asarray(C_0_B, float)
    if m.shape[0] < 10:
        raise ValueError(f"align_magnetometer: {m.shape[0]} samples, at least 10 needed")
    C_B_0 = np.swapaxes(C_0_B, -1, -2)
    S = C_B_0.sum(axis=0)
    best = None
    for k in range(starts):
        a = 2.0 * math.pi * k / starts
        C = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        rms_prev = math.inf
        for _ in range(iterations):
            b0, o, r, u = _linear_step(C_B_0, S, m, C)
            rms = math.sqrt(float(np.mean(r**2)))
            if abs(rms_prev - rms) <= tol * max(rms, 1e-300):
                break
            rms_prev = rms
            U, _, Vt = np.linalg.svd((m - o).T @ u)
            C = U @ np.diag([1.0, 1.0, float(np.linalg.det(U @ Vt))]) @ Vt
        b0, o, r, _ = _linear_step(C_B_0, S, m, C)
        rms = math.sqrt(float(np.mean(r**2)))
        if best is None or rms < best.rms:
            best = MagnetometerAlignment(C, o, b0, rms, int(m.shape[0]))
    return best
