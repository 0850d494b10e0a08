"""IAU body-fixed frames, planetocentric geodesy, local NED and test-chamber frames.

Frames: ``I`` planet-centred inertial (ICRF/J2000 axes); ``M`` for Mars the MMED frame of AMELIA
(Aboudan et al. 2018, Sect. 3; SPICE's MARSIAU: +Z the IAU pole at J2000.0, :func:`C_mmed_icrf`);
``F`` the body-fixed frame of the IAU rotation model, ``C_F_I = Rz(W) Rx(90° − δ0) Rz(90° + α0)``
(frame rotations, Archinal et al. 2018, Sect. 2); ``N`` local North-East-Down at a planetocentric
latitude/longitude; lab frames (the REDLand SPF chamber) with a fixed rotation to a level "planet"
frame (:class:`LabFrame`). Epochs are TDB Julian dates (:func:`julian_date_from_utc`, re-exported
from :mod:`workbench.core.timescales`: UTC -> TAI -> TT -> TDB with ERFA).

Two latitude/longitude conventions: :func:`planetocentric_of_date` (pole and prime meridian of date
at the exact TDB: for physics) and :func:`planetocentric_amelia` (latitude in MMED, longitude as
MMED spun by the IAU ``W`` with the UTC date as TDB: only to compare with numbers printed in the
AMELIA paper). Why two, and the hypotheses measured against AMELIA Table 5: docs/tuning/core.md.
Angles are radians inside; the IAU elements of :class:`~workbench.core.bodies.Body` are in degrees
as published and converted here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from workbench.core.bodies import Body
from workbench.core.rotation import dcm_to_quat, quat_from_axis_angle, quat_to_dcm
from workbench.core.timescales import SECONDS_PER_DAY, julian_date_from_utc

__all__ = [
    "J2000_JD",
    "SECONDS_PER_DAY",
    "DAYS_PER_CENTURY",
    "julian_date_from_utc",
    "days_since_j2000",
    "centuries_since_j2000",
    "iau_pole_and_meridian",
    "meridian_rate",
    "C_bodyfixed_inertial",
    "C_mmed_icrf",
    "C_bodyfixed_mmed",
    "inertial_to_bodyfixed",
    "bodyfixed_to_inertial",
    "planetocentric_from_cartesian",
    "planetocentric_of_date",
    "planetocentric_amelia",
    "cartesian_from_planetocentric",
    "altitude_above_sphere",
    "C_ned_bodyfixed",
    "C_enu_bodyfixed",
    "ned_basis",
    "north_east_xyz",
    "ned_from_enu",
    "ned_from_bodyfixed",
    "bodyfixed_from_ned",
    "local_ned_position",
    "C_mars_spf",
    "LabFrame",
    "SPF_LAB",
]

J2000_JD = 2451545.0
"""Julian date of the J2000.0 epoch, 2000-01-01T12:00:00 TDB."""
DAYS_PER_CENTURY = 36525.0


# ----------------------------------------------------------------------------------------- time
def days_since_j2000(jd: np.ndarray | float) -> np.ndarray:
    """Days d since J2000.0 (JD 2451545.0) of Julian date(s) ``jd`` [days], any shape."""
    return np.asarray(jd, dtype=float) - J2000_JD


def centuries_since_j2000(jd: np.ndarray | float) -> np.ndarray:
    """Julian centuries T = d / 36525 since J2000.0 of Julian date(s) ``jd`` [days], any shape."""
    return days_since_j2000(jd) / DAYS_PER_CENTURY


# ------------------------------------------------------------------------------------ IAU model
def _periodic_arg_rad(term: tuple[str, float, float, float], T: np.ndarray) -> np.ndarray:
    _, _, phase0_deg, rate_deg_per_century = term
    return np.deg2rad(phase0_deg + rate_deg_per_century * T)


def iau_pole_and_meridian(body: Body, jd_tdb: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IAU pole right ascension α0, declination δ0 and prime meridian W [rad] at ``jd_tdb``.

    ``jd_tdb`` is a Julian date (TDB) of any shape; the three outputs have that shape.  α0, δ0
    are ICRF/J2000 equatorial coordinates of the north pole; W is the angle from the ascending
    node of the body equator on the ICRF equator to the prime meridian, reduced to [0, 2π).
    Periodic terms of ``body`` are included (α0: A sin, δ0: A cos, W: A sin; Archinal et al.
    2018, Table 2).
    """
    d = days_since_j2000(jd_tdb)
    T = d / DAYS_PER_CENTURY
    alpha = body.alpha0_deg + body.alpha0_rate_deg_per_century * T
    delta = body.delta0_deg + body.delta0_rate_deg_per_century * T
    # W0 + Ẇ d can be ~1e6 deg: reduce the secular part before adding small terms.
    W = np.mod(body.w0_deg + np.mod(body.w_rate_deg_per_day * d, 360.0), 360.0)
    for term in body.periodic_terms:
        kind, amp = term[0], term[1]
        arg = _periodic_arg_rad(term, T)
        if kind == "alpha0":
            alpha = alpha + amp * np.sin(arg)
        elif kind == "delta0":
            delta = delta + amp * np.cos(arg)
        else:  # "W"
            W = W + amp * np.sin(arg)
    return np.deg2rad(alpha), np.deg2rad(delta), np.mod(np.deg2rad(W), 2.0 * np.pi)


def meridian_rate(body: Body, jd_tdb: np.ndarray | float) -> np.ndarray:
    """dW/dt [rad/s] at ``jd_tdb`` (any shape), including the derivative of the periodic W terms.

    This is the body's spin rate about its pole used for ``ω_F = [0, 0, dW/dt]``; the slow drift
    of the pole (≲ 1e-13 rad/s for Mars) is neglected.
    """
    T = centuries_since_j2000(jd_tdb)
    rate_deg_per_day = np.full(T.shape, body.w_rate_deg_per_day)
    for term in body.periodic_terms:
        if term[0] == "W":
            amp, rate_c = term[1], term[3]
            # d/dd [A sin(φ0 + ν T)] with T = d/36525 and the argument in degrees
            rate_deg_per_day = (
                rate_deg_per_day + amp * np.cos(_periodic_arg_rad(term, T)) * np.deg2rad(rate_c) / DAYS_PER_CENTURY
            )
    return np.deg2rad(rate_deg_per_day) / SECONDS_PER_DAY


def _frame_rot(axis: int, angle: np.ndarray) -> np.ndarray:
    """Passive (frame) rotation matrix about coordinate ``axis`` by ``angle`` [rad], (..., 3, 3)."""
    e = np.zeros(3)
    e[axis] = 1.0
    # a frame rotation by +a equals the active rotation by -a
    return quat_to_dcm(quat_from_axis_angle(e, -np.asarray(angle, dtype=float)))


def C_bodyfixed_inertial(body: Body, jd_tdb: np.ndarray | float) -> np.ndarray:
    """DCM ``C_F_I`` (..., 3, 3) from planet-centred inertial (ICRF axes) to the IAU body-fixed frame.

    ``C_F_I = Rz(W) Rx(90° − δ0) Rz(90° + α0)`` (IAU WGCCRE report, passive rotations), so that
    ``r_F = C_F_I @ r_I``.  Vectorised over the shape of ``jd_tdb`` (Julian date, TDB).
    """
    alpha, delta, W = iau_pole_and_meridian(body, jd_tdb)
    return _frame_rot(2, W) @ _frame_rot(0, 0.5 * np.pi - delta) @ _frame_rot(2, 0.5 * np.pi + alpha)


def C_mmed_icrf(body: Body) -> np.ndarray:
    """Constant DCM ``C_M_ICRF`` (3, 3) from ICRF axes to the body's mean-equator frame of J2000 ("MMED").

    MMED (SPICE name for Mars: "Mars Mean Equator and IAU vector of J2000", used by AMELIA):
    +Z is the IAU pole at J2000, +X the ascending node of the body equator on the ICRF equator
    at J2000 (the "IAU vector").  ``C_M_ICRF = Rx(90° − δ0) Rz(90° + α0)`` at J2000.0, i.e.
    :func:`C_bodyfixed_inertial` without the spin ``Rz(W)``.
    """
    alpha, delta, _ = iau_pole_and_meridian(body, J2000_JD)
    return _frame_rot(0, 0.5 * np.pi - delta) @ _frame_rot(2, 0.5 * np.pi + alpha)


def C_bodyfixed_mmed(body: Body, jd_tdb: np.ndarray | float) -> np.ndarray:
    """DCM ``C_F_M`` (..., 3, 3) from the MMED frame (:func:`C_mmed_icrf`) to the IAU body-fixed frame.

    ``C_F_M = C_F_ICRF(jd) C_M_ICRFᵀ``.  For Mars over a few years this is ``Rz(W')`` to within
    the pole drift (~0.002°/yr); vectorised over ``jd_tdb`` (Julian date, TDB).
    """
    return C_bodyfixed_inertial(body, jd_tdb) @ C_mmed_icrf(body).T


def _omega_F(body: Body, jd_tdb) -> np.ndarray:
    w = meridian_rate(body, jd_tdb)
    return np.stack([np.zeros_like(w), np.zeros_like(w), w], -1)


def inertial_to_bodyfixed(
    body: Body, jd_tdb: np.ndarray | float, r_I: np.ndarray, v_I: np.ndarray | None = None
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Position (and velocity) from inertial I to body-fixed F at epoch(s) ``jd_tdb``.

    ``r_F = C_F_I r_I`` [m]; ``v_F = C_F_I v_I − ω_F × r_F`` [m/s] (equivalently
    ``C_F_I (v_I − ω_I × r_I)``), with ``ω_F = [0, 0, dW/dt]`` from :func:`meridian_rate`.
    ``r_I``, ``v_I`` are (..., 3) and broadcast against the shape of ``jd_tdb``.  Returns ``r_F``
    alone when ``v_I`` is None, else ``(r_F, v_F)``.
    """
    C = C_bodyfixed_inertial(body, jd_tdb)
    r_F = np.einsum("...ij,...j->...i", C, np.asarray(r_I, dtype=float))
    if v_I is None:
        return r_F
    v_F = np.einsum("...ij,...j->...i", C, np.asarray(v_I, dtype=float)) - np.cross(_omega_F(body, jd_tdb), r_F)
    return r_F, v_F


def bodyfixed_to_inertial(
    body: Body, jd_tdb: np.ndarray | float, r_F: np.ndarray, v_F: np.ndarray | None = None
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`inertial_to_bodyfixed`: ``r_I = C_F_Iᵀ r_F``, ``v_I = C_F_Iᵀ (v_F + ω_F × r_F)``.

    Shapes (..., 3) broadcasting against ``jd_tdb``; returns ``r_I`` or ``(r_I, v_I)`` [m, m/s].
    """
    C_I_F = np.swapaxes(C_bodyfixed_inertial(body, jd_tdb), -1, -2)
    r_F = np.asarray(r_F, dtype=float)
    r_I = np.einsum("...ij,...j->...i", C_I_F, r_F)
    if v_F is None:
        return r_I
    v_rel = np.asarray(v_F, dtype=float) + np.cross(_omega_F(body, jd_tdb), r_F)
    return r_I, np.einsum("...ij,...j->...i", C_I_F, v_rel)


# -------------------------------------------------------------------------------------- geodesy
def planetocentric_from_cartesian(r_F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Planetocentric latitude [rad, ±π/2], east longitude [rad, ±π] and radius [m] of r_F (..., 3)."""
    r_F = np.asarray(r_F, dtype=float)
    x, y, z = r_F[..., 0], r_F[..., 1], r_F[..., 2]
    rho = np.hypot(x, y)
    return np.arctan2(z, rho), np.arctan2(y, x), np.hypot(rho, z)


def planetocentric_of_date(
    body: Body, jd_tdb: np.ndarray | float, p_M: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Physically exact planetocentric latitude, east longitude [rad] and radius [m] of MMED position(s).

    ``p_M`` (..., 3) [m] in the body's mean-equator-of-J2000 frame (:func:`C_mmed_icrf`) at Julian
    date(s) ``jd_tdb`` (TDB, e.g. from :func:`julian_date_from_utc`; broadcast against ``p_M[..., 0]``)
    is rotated into the IAU body-fixed frame with the pole *and* prime meridian of date
    (:func:`C_bodyfixed_mmed`), then :func:`planetocentric_from_cartesian`.  This is the convention
    of the whole workbench; see the module docstring for how it differs from the AMELIA paper's.
    """
    r_F = np.einsum("...ij,...j->...i", C_bodyfixed_mmed(body, jd_tdb), np.asarray(p_M, dtype=float))
    return planetocentric_from_cartesian(r_F)


def planetocentric_amelia(
    body: Body, jd_utc: np.ndarray | float, p_M: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Latitude, east longitude [rad] and radius [m] in the convention that reproduces AMELIA's Table 5.

    Aboudan et al. 2018 ("ExoMars 2016 Schiaparelli module trajectory and atmospheric profiles
    reconstruction", Space Sci. Rev. 214:97), Table 5 from the MMED states of Table 2:

    * latitude ``asin(z_M / |p|)`` — the MMED (J2000) pole, not the pole of date;
    * longitude ``atan2(y_M, x_M) − W`` — MMED spun about its own +Z by the IAU prime-meridian
      angle ``W`` of ``body``, with ``W`` evaluated at the **UTC** Julian date ``jd_utc``
      (:func:`workbench.core.timescales.julian_date_utc`) in place of TDB, wrapped to [−π, π);
    * radius ``|p|`` (altitude AMR = radius − ``body.reference_radius``).

    Reproduces Table 5's first row to the printed digits in latitude and altitude and to +0.0102°
    in longitude (module docstring: the hypotheses measured).  Not a physical frame: for physics
    use :func:`planetocentric_of_date` at the TDB date.  ``p_M`` (..., 3) [m]; ``jd_utc`` [days]
    broadcasts against ``p_M[..., 0]``.
    """
    p_M = np.asarray(p_M, dtype=float)
    x, y, z = p_M[..., 0], p_M[..., 1], p_M[..., 2]
    rho = np.hypot(x, y)
    _, _, W = iau_pole_and_meridian(body, jd_utc)
    lon = np.mod(np.arctan2(y, x) - W + np.pi, 2.0 * np.pi) - np.pi
    return np.arctan2(z, rho), lon, np.hypot(rho, z)


def cartesian_from_planetocentric(lat: np.ndarray, lon: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Body-fixed position (..., 3) [m] from planetocentric latitude, east longitude [rad] and radius [m]."""
    lat, lon, radius = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (lat, lon, radius)))
    c = np.cos(lat)
    return np.stack([radius * c * np.cos(lon), radius * c * np.sin(lon), radius * np.sin(lat)], -1)


def altitude_above_sphere(r: np.ndarray, reference_radius: float) -> np.ndarray:
    """Altitude ``|r| − R`` [m] above a sphere of radius ``reference_radius`` [m]; r (..., 3) in any
    planet-centred frame -> (...).  For Mars AMR use ``MARS.reference_radius`` (AMELIA Eq. B.1)."""
    return np.linalg.norm(np.asarray(r, dtype=float), axis=-1) - reference_radius


def C_ned_bodyfixed(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """DCM ``C_N_F`` (..., 3, 3) from body-fixed F to North-East-Down at planetocentric (lat, lon) [rad].

    Rows are the N, E, D unit vectors in F: N = (−sφ cλ, −sφ sλ, cφ), E = (−sλ, cλ, 0),
    D = (−cφ cλ, −cφ sλ, −sφ) = −r̂.  ``v_N = C_N_F @ v_F``.
    """
    lat, lon = np.broadcast_arrays(np.asarray(lat, dtype=float), np.asarray(lon, dtype=float))
    sp, cp, sl, cl = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    z = np.zeros_like(lat)
    north = np.stack([-sp * cl, -sp * sl, cp], -1)
    east = np.stack([-sl, cl, z], -1)
    down = np.stack([-cp * cl, -cp * sl, -sp], -1)
    return np.stack([north, east, down], -2)


def C_enu_bodyfixed(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """DCM ``C_L_F`` (..., 3, 3) from body-fixed F to East-North-Up at planetocentric (lat, lon) [rad].

    The rows of :func:`C_ned_bodyfixed` reordered: E, N and Up = −D = r̂.  ``v_ENU = C_L_F @ v_F``.
    """
    C = C_ned_bodyfixed(lat, lon)
    return np.stack([C[..., 1, :], C[..., 0, :], -C[..., 2, :]], -2)


def ned_basis(r: np.ndarray) -> np.ndarray:
    """``C_N_X`` (..., 3, 3): rows the local north, east, down unit vectors at position(s) r (..., 3) [m].

    ``r`` is planet-centred in any frame X whose +Z is the pole (body-fixed F, or an inertial frame
    such as Mars' MMED): Down is −r̂, East ``ẑ × r̂`` normalised, North ``r̂ × East``.  This equals
    :func:`C_ned_bodyfixed` at the latitude and the longitude *in X* of r, without trigonometry.
    Undefined on the pole axis.
    """
    r = np.asarray(r, dtype=float)
    up = r / np.linalg.norm(r, axis=-1, keepdims=True)
    east = np.cross(np.array([0.0, 0.0, 1.0]), up)
    east /= np.linalg.norm(east, axis=-1, keepdims=True)
    north = np.cross(up, east)
    return np.stack([north, east, -up], axis=-2)


def north_east_xyz(x: float, y: float, z: float, r: float) -> tuple[float, float, float, float, float]:
    """Local north and east unit vectors at one position, by components (for hot scalar loops).

    x, y, z [m] planet-centred in a frame whose +Z is the pole, ``r`` = ``|(x, y, z)|`` [m] (the
    caller usually has it already).  Returns ``(n_x, n_y, n_z, e_x, e_y)`` (``e_z`` = 0): the first
    two rows of :func:`ned_basis` written out.  Undefined on the pole axis.
    """
    rxy = math.sqrt(x * x + y * y)
    return -x * z / (r * rxy), -y * z / (r * rxy), rxy / r, -y / rxy, x / rxy


def ned_from_enu(v: np.ndarray) -> np.ndarray:
    """Components (..., 3) of East-North-Up vector(s) v (..., 3) in North-East-Down: ``(v_N, v_E, −v_U)``."""
    v = np.asarray(v, dtype=float)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], -1)


def ned_from_bodyfixed(v_F: np.ndarray, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Express body-fixed vector(s) v_F (..., 3) in local NED at (lat, lon) [rad]: ``C_N_F v_F``."""
    return np.einsum("...ij,...j->...i", C_ned_bodyfixed(lat, lon), np.asarray(v_F, dtype=float))


def bodyfixed_from_ned(v_N: np.ndarray, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Express NED vector(s) v_N (..., 3) at (lat, lon) [rad] in the body-fixed frame: ``C_N_Fᵀ v_N``."""
    return np.einsum("...ji,...j->...i", C_ned_bodyfixed(lat, lon), np.asarray(v_N, dtype=float))


def local_ned_position(r_F: np.ndarray, origin_F: np.ndarray) -> np.ndarray:
    """Position (..., 3) [m] of r_F relative to ``origin_F`` (3,), in the NED frame at the origin.

    This is the "local origin" frame for logging geometry (never log planet-centred metres); it
    is a flat tangent frame, so Down differs from the local vertical far away.
    """
    origin_F = np.asarray(origin_F, dtype=float)
    lat, lon, _ = planetocentric_from_cartesian(origin_F)
    return ned_from_bodyfixed(np.asarray(r_F, dtype=float) - origin_F, lat, lon)


# ------------------------------------------------------------------------------------ lab frames
def C_mars_spf() -> np.ndarray:
    """DCM ``C_M_S`` (3, 3) from the SPF test-chamber frame S to the level "Mars" frame M.

    SPF frame (REDLand MER airbag paper, "Typical test sequence"): origin at the trigger nail,
    Z up, Y toward the face of the 60° ramp, X = Y × Z.  "A −60 degree rotation about the SPF
    X-axis is required to visualize results in a Mars frame": ``C_M_S`` is the active rotation by
    −60° about X, which maps the ramp normal (0, −sin 60°, cos 60°)_S to (0, 0, 1)_M.
    """
    return quat_to_dcm(quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), np.deg2rad(-60.0)))


@dataclass(frozen=True, eq=False)
class LabFrame:
    """A test-chamber frame L with a fixed rotation to a "planet" frame P (e.g. SPF -> Mars frame).

    Attributes:
        name: frame name ("SPF").
        C_planet_lab: DCM ``C_P_L`` (3, 3), ``v_P = C_P_L @ v_L``.
        origin: position of the lab origin in the planet frame [m] (3,); zero when both frames
            share the origin (SPF: the trigger nail).
    """

    name: str
    C_planet_lab: np.ndarray
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        C = np.array(self.C_planet_lab, dtype=float)
        o = np.array(self.origin, dtype=float)
        if C.shape != (3, 3) or o.shape != (3,):
            raise ValueError("LabFrame: C_planet_lab must be (3, 3) and origin (3,)")
        if not np.allclose(C @ C.T, np.eye(3), atol=1e-9) or np.linalg.det(C) < 0:
            raise ValueError("LabFrame: C_planet_lab is not a proper rotation matrix")
        C.flags.writeable = False
        o.flags.writeable = False
        object.__setattr__(self, "C_planet_lab", C)
        object.__setattr__(self, "origin", o)

    @property
    def q_planet_lab(self) -> np.ndarray:
        """Quaternion ``q_P_L`` (4,) scalar-last of :attr:`C_planet_lab`."""
        return dcm_to_quat(self.C_planet_lab)

    def to_planet(self, v: np.ndarray) -> np.ndarray:
        """Rotate free vectors (velocity, acceleration, direction) (..., 3) from lab to planet axes."""
        return np.asarray(v, dtype=float) @ self.C_planet_lab.T

    def from_planet(self, v: np.ndarray) -> np.ndarray:
        """Rotate free vectors (..., 3) from planet to lab axes (inverse of :meth:`to_planet`)."""
        return np.asarray(v, dtype=float) @ self.C_planet_lab

    def point_to_planet(self, p_L: np.ndarray) -> np.ndarray:
        """Positions (..., 3) [m] in the lab frame -> planet frame: ``origin + C_P_L p_L``."""
        return self.origin + self.to_planet(p_L)

    def point_from_planet(self, p_P: np.ndarray) -> np.ndarray:
        """Positions (..., 3) [m] in the planet frame -> lab frame: ``C_P_Lᵀ (p_P − origin)``."""
        return self.from_planet(np.asarray(p_P, dtype=float) - self.origin)


SPF_LAB = LabFrame(name="SPF", C_planet_lab=C_mars_spf())
"""SPF chamber -> Mars frame (−60° about SPF X, common origin at the trigger nail; REDLand)."""
