"""The POST2-style trajectory model: one simulator that runs forward *and* is the EKF's process model.

POST2's premise (thesis [R3], Ch. 3.1.2): "any POST2 input parameter that has an associated
derivative ... can be an estimated state, and any POST2 output parameter can be an observation".
Here the state vector is assembled from named blocks (:data:`STATES`); every block the problem
file does not estimate keeps its nominal value from the environment and vehicle.  The same
:class:`TrajectoryModel` integrates the truth (with its own integrator and environment, see
``truth.py``) and the estimator's prediction, and evaluates the named observations
(:data:`OBSERVATIONS`).

Frames and conventions (SI inside):

* ``p_I``, ``v_I`` [m, m/s]: planet-centred inertial, +Z the pole (as J2 needs); no precession.
* ``q_I_B`` scalar-last, rotates body vectors to inertial; body frame B: +X along the symmetry
  axis towards the heat shield (the air-relative velocity is along +X_B at zero angle of attack,
  as in the thesis' Ch. 3.2.2 "the vehicle body X-axis aligned with the velocity vector"),
  +Y, +Z completing a right-handed frame.  The vehicle asset's GNC frame G (+Z towards the back
  shell, :mod:`workbench.models.aerodynamics`) maps as X_B = −Z_G, Y_B = Y_G, Z_B = X_G.
* ``w_B`` [rad/s] body rates.  Aerodynamic angles from the air-relative body velocity
  ``v_B = (u, v, w)``: α = atan2(w, u), β = asin(v / |v_B|); the bank angle σ about the
  air-relative velocity from a reference "wind" frame W0 whose x is v̂_rel and whose z points
  down (towards the planet, in the plane of r and v): ``R_I_B = R_I_W0 Rx(σ) Rz(−β) Ry(α)``.
* The atmosphere co-rotates (ω about +Z): ``v_rel = v − ω × r``; altitude ``|r| − R_ref`` (sphere).

Aerodynamics (conventions of :mod:`workbench.models.aerodynamics`, mapped to B): axial force
``−CA q S X_B``, normal force ``−CN q S e⊥`` against the lateral air-relative velocity, moment
``Cm q S L k̂`` with ``k̂ = unit(v̂ × X_B)`` (Cm < 0 restoring), pitch damping
``Cmq q S L² / (2V) ω⊥``; coefficients vs (Mach, Knudsen, total α) from the vehicle's
:class:`~workbench.models.aerodynamics.AeroTable`, each scaled by its multiplier state.  An open
parachute adds ``−CD_p q S_p v̂_rel · multiplier`` (a drag element).  Rotational dynamics
``I ω̇ = M − ω × I ω``; kinematics ``q̇ = ½ q ⊗ (ω, 0)``.  ``dof = 3`` drops the attitude: the
aero force is drag only (``−CA q S v̂_rel``).

Estimated-state processes (thesis Ch. 3.1.1 Eq. 3.1): ``constant``, ``random_walk`` (Q = PSD dt) or
``markov`` (Φ = e^(−dt/τ), Q = σ² (1 − Φ²), σ the prior 1σ unless a PSD is given); bounded parameters
go through the tanh S-curve of Ch. 5 (Fig. 5-15): the model uses ``c + h tanh((s − c)/h)``.

Speed: ``derivative``, ``aero_force_moment`` and ``propagate`` run the compiled kernels of
:mod:`workbench.problems.post2.kernels`, bit-identical to the numpy reference (``WORKBENCH_POST2_KERNEL=0``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from workbench.core.atmosphere import Atmosphere, MarsEngineeringAtmosphere, TabulatedAtmosphere
from workbench.core.gravity import gravity_j2_xyz
from workbench.core.rotation import dcm_to_quat, quat_multiply, quat_normalize, quat_to_dcm
from workbench.models.aerodynamics import AeroTable, ParachuteTable
from workbench.problems.post2 import kernels

__all__ = [
    "StateDef",
    "ObservationDef",
    "STATES",
    "OBSERVATIONS",
    "DESCENT_NOMINALS",
    "C_B_G",
    "Environment",
    "Vehicle",
    "Event",
    "StateBlock",
    "StateMap",
    "TrajectoryModel",
    "scurve",
    "scurve_inverse",
    "scurve_slope",
    "rk4_step",
    "TRANSLATION",
    "POSITION",
    "VELOCITY",
    "wind_inertial",
    "quat_from_aero_angles",
    "aero_angles",
    "KERNEL_ENV",
    "kernel_enabled",
    "DensityWave",
    "CaMachWave",
]

#: the one switch of the compiled kernels: ``WORKBENCH_POST2_KERNEL=0`` in the environment makes every
#: :class:`TrajectoryModel` built afterwards evaluate :meth:`TrajectoryModel.derivative` /
#: :meth:`TrajectoryModel.aero_force_moment` / ``propagate`` with the numpy reference
#: (``derivative_reference`` / ``aero_force_moment_reference``; the two agree to rounding) instead of
#: :func:`~workbench.problems.post2.kernels.dynamics_kernel`; unset or any other value: the kernels
KERNEL_ENV = "WORKBENCH_POST2_KERNEL"


def kernel_enabled() -> bool:
    """True unless the environment sets :data:`KERNEL_ENV` to ``0`` (the numpy reference path)."""
    return os.environ.get(KERNEL_ENV, "").strip() != "0"


@dataclass(frozen=True)
class StateDef:
    """A state the model knows: ``size`` of its value, ``unit`` of its value in a problem file
    (``"deg"`` for attitude: α, β, σ), ``dynamic`` (the model owns its derivative: only constant
    or random-walk noise may be added), ``dofs`` it exists in, default numeric-Jacobian ``step``
    (in ``unit``), and what it means."""

    size: int
    unit: str
    dynamic: bool
    dofs: tuple[int, ...]
    step: float
    meaning: str


#: Every state name the model knows (the problem file's ``[states.<name>]``).
STATES: dict[str, StateDef] = {
    "position": StateDef(3, "m", True, (3, 6), 1.0, "inertial position p_I (thesis XI, YI, ZI)"),
    "velocity": StateDef(3, "m/s", True, (3, 6), 1e-3, "inertial velocity v_I (VXI, VYI, VZI)"),
    "attitude": StateDef(
        3,
        "deg",
        True,
        (6,),
        1e-4,
        "aerodynamic angles [α, β, σ] (ALPHA, BETA, BNKANG) at the start; carried as a quaternion",
    ),
    "body_rates": StateDef(3, "deg/s", True, (6,), 1e-5, "body angular velocity (ROLBD, PITBD, YAWBD)"),
    "j2": StateDef(1, "1", False, (3, 6), 1e-6, "zonal harmonic J2 of the gravity field"),
    "ca_multiplier": StateDef(1, "1", False, (3, 6), 1e-4, "multiplier of the axial coefficient CA"),
    "cn_multiplier": StateDef(1, "1", False, (6,), 1e-4, "multiplier of the normal coefficient CN"),
    "cm_multiplier": StateDef(1, "1", False, (6,), 1e-4, "multiplier of the pitching-moment coefficient Cm"),
    "density_multiplier": StateDef(1, "1", False, (3, 6), 1e-4, "multiplier of the model atmosphere's density"),
    "parachute_drag_multiplier": StateDef(1, "1", False, (3, 6), 1e-4, "multiplier of the parachute CD"),
    "accel_bias": StateDef(
        3, "m/s^2", False, (3, 6), 1e-6, "accelerometer bias, body frame (sensed-acceleration observations)"
    ),
    "radar_scale_factor": StateDef(1, "1", False, (3, 6), 1e-5, "radar altimeter scale factor (altitude observation)"),
    # --- rocket flights (case 5): barometer, winds, drag areas of a two-stage recovery -----------
    "baro_bias": StateDef(1, "Pa", False, (3, 6), 0.1, "barometer bias: measured = model pressure + baro_bias"),
    "baro_q_coefficient": StateDef(
        1,
        "1",
        False,
        (3, 6),
        1e-5,
        "static-port error per dynamic pressure: measured pressure += baro_q_coefficient · ½ρ|v_rel|²",
    ),
    "baro_scale": StateDef(
        1,
        "1",
        False,
        (3, 6),
        1e-5,
        "barometric altitude scale: the pressure is the model's at h_a + (h − h_a)·baro_scale, h_a = [environment] "
        "baro_scale_anchor_m (a column warmer or colder than the model's: baro_scale ≈ T_model / T_air)",
    ),
    "wind": StateDef(
        2, "m/s", False, (3, 6), 1e-3, "horizontal wind [east, north] at the vehicle (air moves with it), local frame"
    ),
    "drogue_drag_area": StateDef(1, "m^2", False, (3, 6), 1e-4, "CD·S of the drogue (events with chute = 'drogue')"),
    "main_drag_area": StateDef(1, "m^2", False, (3, 6), 1e-4, "CD·S of the main parachute (chute = 'main')"),
}

# ---- Huygens-like descent (thesis [R3] Ch. 4-5): per-regime CA, drogue, tilt, winds ------------------
#: nominal (model-input) value of each of these states when not estimated nor planted
DESCENT_NOMINALS: dict[str, float] = {
    "ca_multiplier_fm": 1.0,
    "ca_multiplier_hyp": 1.0,
    "ca_multiplier_sup": 1.0,
    "drogue_drag_multiplier": 1.0,
    "tilt": 0.0,
    "wind_vertical": 0.0,
    "wind_horizontal": 0.0,
}
STATES = {
    **STATES,
    "ca_multiplier_fm": StateDef(
        1, "1", False, (3, 6), 1e-4, "CA multiplier in the free-molecular regime (Kn >= 0.1; Table 4-1)"
    ),
    "ca_multiplier_hyp": StateDef(1, "1", False, (3, 6), 1e-4, "CA multiplier, hypersonic continuum (Mach > 10)"),
    "ca_multiplier_sup": StateDef(1, "1", False, (3, 6), 1e-4, "CA multiplier, supersonic continuum (Mach < 5)"),
    "drogue_drag_multiplier": StateDef(1, "1", False, (3, 6), 1e-4, "multiplier of the drogue parachute CD"),
    "tilt": StateDef(1, "deg", False, (3,), 1e-3, "3-DOF: probe axis from the air-relative velocity, under the drogue"),
    "wind_vertical": StateDef(1, "m/s", False, (3, 6), 1e-3, "vertical wind, + up (the air moves along +r̂)"),
    "wind_horizontal": StateDef(1, "m/s", False, (3, 6), 1e-3, "horizontal (zonal, + east) wind"),
    # the pre-flight atmosphere's error where the vehicle is (observation-only: the Huygens-like
    # descent's log-pressure and temperature are modelled as table(h) + offset; a Markov process
    # in time, the vehicle moving through an error profile that varies with altitude)
    "log_pressure_offset": StateDef(
        1, "1", False, (3, 6), 1e-4, "ln p of the atmosphere minus the model table's at the vehicle (log_pressure)"
    ),
    "temperature_offset": StateDef(
        1, "K", False, (3, 6), 1e-3, "temperature of the atmosphere minus the model table's at the vehicle"
    ),
}


@dataclass(frozen=True)
class ObservationDef:
    """An observable model output: ``size`` of its residual (and of its σ / weights), ``unit`` of σ
    and of the file columns, the file's column names ``components``, the DOFs it exists in, its
    meaning, and ``file_unit`` when the file columns have another unit than σ (quaternion: ``1``)."""

    size: int
    unit: str
    components: tuple[str, ...]
    dofs: tuple[int, ...]
    meaning: str
    file_unit: str | None = None

    @property
    def residual_names(self) -> tuple[str, ...]:
        """Names of the residual components (the file columns, or x, y, z for a quaternion)."""
        return self.components if len(self.components) == self.size else ("x", "y", "z")


#: Every observation quantity the model computes (the problem file's ``[observations.<name>] quantity``).
OBSERVATIONS: dict[str, ObservationDef] = {
    "gravity_magnitude": ObservationDef(1, "m/s^2", ("g",), (3, 6), "|g| of point mass + J2 (thesis SPCV1)"),
    "acceleration_inertial": ObservationDef(
        3, "m/s^2", ("ax", "ay", "az"), (3, 6), "total inertial acceleration incl. gravity (AXI, AYI, AZI)"
    ),
    "acceleration_body": ObservationDef(
        3, "m/s^2", ("ax", "ay", "az"), (6,), "sensed (non-gravitational) acceleration, body frame, + accel_bias"
    ),
    "acceleration_axial": ObservationDef(
        1, "m/s^2", ("ax",), (3, 6), "sensed acceleration along +X_B + bias (3-DOF: X_B along v_rel, tilted by `tilt`)"
    ),
    "body_rates": ObservationDef(3, "deg/s", ("p", "q", "r"), (6,), "body angular velocity (ROLBD, PITBD, YAWBD)"),
    "quaternion": ObservationDef(
        3,
        "deg",
        ("qx", "qy", "qz", "qw"),
        (6,),
        "attitude q_I_B (scalar last); residual = body-frame small angle to the measured attitude, σ per axis in deg",
        file_unit="1",
    ),
    "altitude": ObservationDef(1, "m", ("h",), (3, 6), "radar altitude = (|r| − R_ref) · radar_scale_factor"),
    "pressure": ObservationDef(1, "Pa", ("p",), (3, 6), "static pressure of the model atmosphere"),
    "density": ObservationDef(1, "kg/m^3", ("rho",), (3, 6), "density of the model atmosphere"),
    # --- rocket flights (case 5) ----------------------------------------------------------------
    "acceleration_magnitude": ObservationDef(
        1, "m/s^2", ("a",), (3, 6), "|sensed (non-gravitational) acceleration|: drag / mass (attitude-free)"
    ),
    "position_inertial": ObservationDef(
        3, "m", ("x", "y", "z"), (3, 6), "inertial position p_I (e.g. a surveyed landing point at its time)"
    ),
    "position_pad_enu": ObservationDef(
        3,
        "m",
        ("e", "n", "u"),
        (3, 6),
        "position east/north/up of the `[launch]` pad in its planet-fixed axes at the sample's time (a GNSS fix "
        "relative to the pad; needs `[launch]`; reconstruction only)",
    ),
    # ---- Huygens-like descent (thesis [R3] Ch. 4.2.3): pressure over decades, temperature
    "log_pressure": ObservationDef(1, "1", ("ln_p",), (3, 6), "ln(static pressure / 1 Pa): σ is the relative error"),
    "temperature": ObservationDef(1, "K", ("T",), (3, 6), "static temperature of the model atmosphere"),
}

#: DCM from the GNC frame G of the vehicle asset to the post2 body frame B (X_B = −Z_G, Z_B = X_G).
C_B_G = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
C_B_G.flags.writeable = False


def scurve(s, lo: float, hi: float):
    """Physical value in (lo, hi) of the unbounded estimated state ``s``: ``c + h tanh((s − c)/h)``,
    c = (lo + hi)/2, h = (hi − lo)/2 (thesis Ch. 5, Fig. 5-15); identity near c (slope 1)."""
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    return c + h * np.tanh((np.asarray(s, dtype=float) - c) / h)


def _scurve_columns(bounded) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x columns (k,), centres c (k,), half widths h (k,)) of bounded slots ((sx, (lo, hi)), ...):
    :func:`scurve`'s c and h, for all k slots at once."""
    cols = np.array([sx.start for sx, _ in bounded], dtype=np.int64)
    c = np.array([0.5 * (lo + hi) for _, (lo, hi) in bounded])
    h = np.array([0.5 * (hi - lo) for _, (lo, hi) in bounded])
    return cols, c, h


def scurve_inverse(p, lo: float, hi: float):
    """Estimated state ``s`` of a physical value ``p`` strictly inside (lo, hi) (inverse of :func:`scurve`)."""
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    return c + h * np.arctanh((np.asarray(p, dtype=float) - c) / h)


def scurve_slope(s, lo: float, hi: float):
    """d scurve / ds = 1 − tanh²((s − c)/h) (dimensionless), for mapping 1σ to the physical value."""
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    return 1.0 - np.tanh((np.asarray(s, dtype=float) - c) / h) ** 2


@dataclass(frozen=True)
class DensityWave:
    """Truth-side density factor ``1 + amplitude sin(2π h / wavelength)`` [-] of altitude h [m] (any
    shape); a class (not a closure) so that the compiled kernel evaluates it too."""

    amplitude: float
    wavelength: float

    def __call__(self, h):
        return 1.0 + self.amplitude * np.sin(2.0 * math.pi * np.asarray(h) / self.wavelength)


@dataclass(frozen=True)
class CaMachWave:
    """Truth-side CA factor ``1 + amplitude sin(2π log10(max(Mach, 1e-3)) / 1.2)`` [-] (any shape);
    a class (not a closure) so that the compiled kernel evaluates it too."""

    amplitude: float

    def __call__(self, mach):
        return 1.0 + self.amplitude * np.sin(2.0 * math.pi * np.log10(np.maximum(mach, 1e-3)) / 1.2)


@dataclass(frozen=True)
class Environment:
    """Planet and atmosphere: ``gm`` [m³/s²], ``radius_eq`` [m] (J2 reference radius), ``j2``
    nominal [-], ``radius_ref`` [m] (altitude reference sphere), ``omega`` [rad/s] planet rate
    about +Z, ``atmosphere`` (an :class:`~workbench.core.atmosphere.Atmosphere` or None: vacuum),
    ``density_factor(h) -> factor`` (None: 1) an optional multiplicative density perturbation
    (used by the truth simulator only); ``baro_anchor`` [m] the altitude about which the
    ``baro_scale`` state stretches the barometer's altitude."""

    gm: float
    radius_eq: float
    j2: float
    radius_ref: float
    omega: float
    atmosphere: Atmosphere | None
    density_factor: Callable[[np.ndarray], np.ndarray] | None = None
    baro_anchor: float = 0.0


@dataclass(frozen=True)
class Event:
    """A phase change: ``when`` ``"time"`` (``value`` [s]) or ``"mach_below"``, ``"altitude_below"``
    [m], ``"dynamic_pressure_above"`` [Pa] evaluated on the propagated state; ``mass`` [kg] /
    ``ref_area`` [m²] new values (None: unchanged); ``parachute`` True opens / False releases the
    parachute (None: unchanged); ``name`` for the recording."""

    name: str
    when: str
    value: float
    mass: float | None = None
    ref_area: float | None = None
    parachute: bool | None = None
    chute: str | None = None  # "main" / "drogue" / "none": which parachute table or drag-area state acts


@dataclass(frozen=True)
class Vehicle:
    """Mass [kg], body-frame inertia ``inertia_B`` (3, 3) [kg m²], ``aero`` table (its ref_area
    [m²] and ref_length [m] unless ``ref_area`` overrides), ``parachute`` table or None, and
    truth-side coefficient factors ``ca_factor``/``cn_factor``/``cm_factor`` (1 for the
    estimator: how the truth's aero differs from the table the estimator uses)."""

    mass: float
    inertia_B: np.ndarray
    aero: AeroTable | None
    parachute: ParachuteTable | None = None
    ref_area: float | None = None
    ca_factor: float = 1.0
    cn_factor: float = 1.0
    cm_factor: float = 1.0
    cd: float | None = None  # constant drag coefficient on ``ref_area`` when there is no aero table
    # ---- Huygens-like descent: a second parachute; truth only: CA × f(Mach) (smooth table error)
    drogue: ParachuteTable | None = None
    ca_mach_factor: Callable[[np.ndarray], np.ndarray] | None = None

    @property
    def area(self) -> float:
        """Aerodynamic reference area [m²]."""
        if self.ref_area is not None:
            return float(self.ref_area)
        return float(self.aero.ref_area) if self.aero is not None else 0.0


@dataclass(frozen=True)
class StateBlock:
    """One named block of the estimated state: slices into x and into the error state,
    the block's ``StateDef`` and (for scalar parameters) optional ``bounds`` (lo, hi)."""

    name: str
    sx: slice
    se: slice
    definition: StateDef
    bounds: tuple[float, float] | None = None


class StateMap:
    """Where each named block sits in the state ``x``; the quaternion block (attitude) is 4 long in
    x and 3 in the error state.  Built from the ordered names and bounds."""

    def __init__(self, names: list[str], bounds: dict[str, tuple[float, float]] | None = None):
        bounds = bounds or {}
        blocks: dict[str, StateBlock] = {}
        ix = ie = 0
        quats = []
        for nm in names:
            d = STATES[nm]
            nx = 4 if nm == "attitude" else d.size
            if nm == "attitude":
                quats.append((ix, ie))
            blocks[nm] = StateBlock(nm, slice(ix, ix + nx), slice(ie, ie + d.size), d, bounds.get(nm))
            ix += nx
            ie += d.size
        self.blocks = blocks
        self.n_x, self.n_e = ix, ie
        self.quat_blocks = tuple(quats)
        self.names = list(names)

    def __contains__(self, name: str) -> bool:
        return name in self.blocks

    def raw(self, x: np.ndarray, name: str) -> np.ndarray:
        """The block ``name`` of x (..., n_x) as stored (estimated, unbounded)."""
        return x[..., self.blocks[name].sx]

    def physical(self, x: np.ndarray, name: str) -> np.ndarray:
        """The block's physical value (S-curve applied if bounded), (..., size)."""
        b = self.blocks[name]
        v = x[..., b.sx]
        return scurve(v, *b.bounds) if b.bounds is not None else v


#: the 3-DOF translation state [position m, velocity m/s] (6,): the Monte Carlo members' and the
#: entry model's layout; :data:`POSITION` and :data:`VELOCITY` are its named slices
TRANSLATION = StateMap(["position", "velocity"])
POSITION, VELOCITY = TRANSLATION.blocks["position"].sx, TRANSLATION.blocks["velocity"].sx


def wind_inertial(p_I: np.ndarray, wind_en: np.ndarray) -> np.ndarray:
    """Inertial wind vector [m/s] (..., 3) of a horizontal wind ``wind_en`` (..., 2) [east, north]
    [m/s] at positions ``p_I`` (..., 3) [m] (+Z the pole): east = unit(Ẑ × r̂), north = r̂ × east
    (undefined exactly at a pole)."""
    up = p_I / np.linalg.norm(p_I, axis=-1, keepdims=True)
    east = np.stack([-up[..., 1], up[..., 0], np.zeros_like(up[..., 0])], axis=-1)
    east = east / np.linalg.norm(east, axis=-1, keepdims=True)
    north = np.cross(up, east)
    return wind_en[..., :1] * east + wind_en[..., 1:2] * north


def rk4_step(f: Callable[[np.ndarray, float], np.ndarray], x: np.ndarray, t: float, dt: float) -> np.ndarray:
    """One classic Runge-Kutta step of ``ẋ = f(x, t)`` for x (..., n) over dt [s]."""
    k1 = f(x, t)
    k2 = f(x + 0.5 * dt * k1, t + 0.5 * dt)
    k3 = f(x + 0.5 * dt * k2, t + 0.5 * dt)
    k4 = f(x + dt * k3, t + dt)
    return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def _smoothstep(u):
    """3u² − 2u³ of u clipped to [0, 1] (C¹ blend from 0 to 1)."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _wind_frame(r_I: np.ndarray, v_rel_I: np.ndarray) -> np.ndarray:
    """R_I_W0 (3, 3): x along v_rel, z down (towards the planet) in the plane of r and v_rel."""
    x = v_rel_I / np.linalg.norm(v_rel_I)
    down = -r_I / np.linalg.norm(r_I)
    z = down - np.dot(down, x) * x
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def quat_from_aero_angles(r_I: np.ndarray, v_rel_I: np.ndarray, angles_rad: np.ndarray) -> np.ndarray:
    """q_I_B (4,) scalar-last from the aerodynamic angles [α, β, σ] [rad] at position r_I [m] and
    air-relative velocity v_rel_I [m/s]: ``R_I_B = R_I_W0 Rx(σ) Rz(−β) Ry(α)`` (module docstring)."""

    a, b, s = (float(v) for v in angles_rad)
    R = _wind_frame(np.asarray(r_I, float), np.asarray(v_rel_I, float)) @ _rx(s) @ _rz(-b) @ _ry(a)
    return quat_normalize(dcm_to_quat(R))


def aero_angles(r_I: np.ndarray, v_rel_I: np.ndarray, q_I_B: np.ndarray) -> np.ndarray:
    """[α, β, σ] [rad] (n, 3) of states r_I, v_rel_I (n, 3) [m, m/s] and q_I_B (n, 4): inverse of
    :func:`quat_from_aero_angles` (vectorised over n; :func:`aero_angles_loop` is the row-by-row
    reference, equal to rounding)."""
    r_I, v_rel_I, q_I_B = (np.atleast_2d(np.asarray(a, float)) for a in (r_I, v_rel_I, q_I_B))
    R = quat_to_dcm(q_I_B)  # (n, 3, 3) R_I_B
    vb = np.einsum("nji,nj->ni", R, v_rel_I)
    al = np.arctan2(vb[:, 2], vb[:, 0])
    be = np.arcsin(np.clip(vb[:, 1] / np.sqrt(np.sum(vb * vb, axis=1)), -1.0, 1.0))
    x = v_rel_I / np.sqrt(np.sum(v_rel_I * v_rel_I, axis=1))[:, None]
    down = -r_I / np.sqrt(np.sum(r_I * r_I, axis=1))[:, None]
    z = down - np.sum(down * x, axis=1)[:, None] * x
    z = z / np.sqrt(np.sum(z * z, axis=1))[:, None]
    y = np.cross(z, x)
    W = np.stack([x, y, z], axis=2)  # R_I_W0, columns x, y, z
    ca, sa, cb, sb = np.cos(al), np.sin(al), np.cos(-be), np.sin(-be)
    o, n0 = np.ones_like(al), np.zeros_like(al)
    ry_t = np.stack([np.stack([ca, n0, -sa], -1), np.stack([n0, o, n0], -1), np.stack([sa, n0, ca], -1)], -2)
    rz_t = np.stack([np.stack([cb, sb, n0], -1), np.stack([-sb, cb, n0], -1), np.stack([n0, n0, o], -1)], -2)
    M = np.swapaxes(W, 1, 2) @ R @ ry_t @ rz_t
    return np.stack([al, be, np.arctan2(M[:, 2, 1], M[:, 1, 1])], axis=1)


def aero_angles_loop(r_I: np.ndarray, v_rel_I: np.ndarray, q_I_B: np.ndarray) -> np.ndarray:
    """Row-by-row reference of :func:`aero_angles` (same arguments, units and shape)."""
    r_I, v_rel_I, q_I_B = (np.atleast_2d(np.asarray(a, float)) for a in (r_I, v_rel_I, q_I_B))
    out = np.empty((r_I.shape[0], 3))
    for i in range(r_I.shape[0]):
        R_I_B = quat_to_dcm(q_I_B[i])
        vb = R_I_B.T @ v_rel_I[i]
        al = math.atan2(vb[2], vb[0])
        be = math.asin(max(-1.0, min(1.0, vb[1] / np.linalg.norm(vb))))
        M = _wind_frame(r_I[i], v_rel_I[i]).T @ R_I_B @ _ry(al).T @ _rz(-be).T
        out[i] = (al, be, math.atan2(M[2, 1], M[1, 1]))
    return out


class TrajectoryModel:
    """The 3-DOF / 6-DOF trajectory model over the state laid out by a :class:`StateMap`.

    ``dof`` 3 or 6; ``env`` :class:`Environment`; ``vehicle`` :class:`Vehicle`; ``events``
    the phase changes in order; ``nominal``: the value of every *model input* not in the state
    (``"j2"``, multipliers, biases, scale factor; SI) and, for a 3-DOF model, nothing else.
    ``use_kernel``: evaluate with the compiled kernels (None: :func:`kernel_enabled`, the environment's
    choice), False: the numpy reference.  Every method is vectorised over leading dimensions of x (..., n_x).
    """

    def __init__(
        self,
        smap: StateMap,
        dof: int,
        env: Environment,
        vehicle: Vehicle,
        events: tuple[Event, ...] = (),
        nominal: dict[str, float] | None = None,
        use_kernel: bool | None = None,
    ):
        if dof not in (3, 6):
            raise ValueError("dof must be 3 or 6")
        if "position" not in smap or "velocity" not in smap:
            raise ValueError("the state needs 'position' and 'velocity' blocks (the trajectory)")
        if dof == 6 and ("attitude" not in smap or "body_rates" not in smap):
            raise ValueError("a 6-DOF model needs 'attitude' and 'body_rates' blocks")
        self.smap, self.dof, self.env, self.vehicle = smap, dof, env, vehicle
        self.events = tuple(events)
        self.use_kernel = kernel_enabled() if use_kernel is None else bool(use_kernel)
        # model inputs that are not in the state (the truth plants its values here); default DESCENT_NOMINALS
        self.nominal = {**DESCENT_NOMINALS, **(nominal or {})}
        self._inertia = np.asarray(vehicle.inertia_B, float)
        self._inertia_inv = np.linalg.inv(self._inertia)
        a = vehicle.aero
        # a continuum-only table does not depend on Knudsen: skip the mean free path
        self._kn_matters = a is not None and not (
            a.log10_kn.size == 2 and all(np.array_equal(c[:, 0], c[:, 1]) for c in (a.ca, a.cn, a.cm))
        )

    # ------------------------------------------------------------------ parameters
    def param(self, x: np.ndarray, name: str, nominal: float | np.ndarray) -> np.ndarray:
        """Physical value of parameter ``name`` from x (..., n_x) if estimated, else ``nominal``,
        shaped (..., size)."""
        if name in self.smap:
            return self.smap.physical(x, name)
        nominal = self.nominal.get(name, nominal)
        size = STATES[name].size
        return np.broadcast_to(np.asarray(nominal, float).reshape(size), (*x.shape[:-1], size))

    def j2(self, x: np.ndarray) -> np.ndarray:
        """J2 [-] (...,)."""
        return self.param(x, "j2", self.env.j2)[..., 0]

    # ------------------------------------------------------------------ compiled kernel
    def _plan(self) -> dict | None:
        """What the kernel needs that does not change per call (built once); None when the model
        uses a feature the kernel does not have (the rocket flights' ``wind`` state)."""
        plan = self.__dict__.get("_plan_cache", False)
        if plan is not False:
            return plan
        if "wind" in self.smap:
            self._plan_cache = None
            return None
        sm, env, veh = self.smap, self.env, self.vehicle
        k = len(kernels.PARAM_SLOTS)
        pmode, pidx, pnom = np.zeros(k, np.int64), np.zeros(k, np.int64), np.zeros(k)
        bounded = []
        defaults = {
            "j2": env.j2,
            "drogue_drag_area": 0.0,
            "main_drag_area": 0.0,
            "wind_vertical": 0.0,
            "wind_horizontal": 0.0,
            "log_pressure_offset": 0.0,
        }
        for i, name in enumerate(kernels.PARAM_SLOTS):
            if name in sm:
                b = sm.blocks[name]
                if b.bounds is not None:
                    pmode[i], pidx[i] = 2, len(bounded)
                    bounded.append((b.sx, b.bounds))
                else:
                    pmode[i], pidx[i] = 1, b.sx.start
            elif name == "density_multiplier":  # the reference applies it only when estimated
                pnom[i] = 1.0
            else:
                pnom[i] = float(np.asarray(self.nominal.get(name, defaults.get(name, 1.0)), float).reshape(1)[0])
        regime_names = [f"ca_multiplier_{r}" for r in ("fm", "hyp", "sup")]
        regime = any(n in sm for n in regime_names) or any(
            pnom[kernels.PARAM_SLOTS.index(n)] != 1.0 for n in regime_names
        )
        wind = any(n in sm or self.nominal.get(n, 0.0) != 0.0 for n in ("wind_vertical", "wind_horizontal"))
        a = veh.aero
        ci = np.zeros(len(kernels.CI), np.int64)
        ci[kernels.CI["dof"]] = self.dof
        ci[kernels.CI["atm"]] = env.atmosphere is not None
        ci[kernels.CI["aero"]] = a is not None
        ci[kernels.CI["has_cd"]] = veh.cd is not None
        ci[kernels.CI["kn_matters"]] = self._kn_matters
        ci[kernels.CI["regime"]] = regime
        ci[kernels.CI["wind"]] = wind
        for key, name in (("i_pos", "position"), ("i_vel", "velocity"), ("i_att", "attitude"), ("i_w", "body_rates")):
            ci[kernels.CI[key]] = sm.blocks[name].sx.start if name in sm else 0
        cf = np.zeros(len(kernels.CF))
        cf[kernels.CF["omega"]] = env.omega
        cf[kernels.CF["gm"]] = env.gm
        cf[kernels.CF["re2"]] = env.radius_eq**2
        cf[kernels.CF["radius_ref"]] = env.radius_ref
        cf[kernels.CF["ref_length"]] = a.ref_length if a is not None else 1.0
        cf[kernels.CF["cmq"]] = a.cmq if a is not None else 0.0
        cf[kernels.CF["ca_factor"]] = veh.ca_factor
        cf[kernels.CF["cn_factor"]] = veh.cn_factor
        cf[kernels.CF["cm_factor"]] = veh.cm_factor
        cf[kernels.CF["cd"]] = veh.cd if veh.cd is not None else 0.0
        dummy1, dummy4 = np.zeros(2), np.zeros((2, 2, 2, 3))
        # the atmosphere in the kernel too (exact ports; other kinds, a truth's density wave or CA(Mach)
        # factor: the atmosphere in numpy per call, see _kernel_eval)
        atm, ac, tabs, kind = env.atmosphere, np.zeros(9), (dummy1, dummy1, dummy1, dummy1), None
        if atm is None:
            kind = 0
        elif type(atm) is MarsEngineeringAtmosphere:
            kind = kernels.ATM_MARS
            ac[:3] = atm.h_blend, atm.scale_height_aloft, atm.GLENN_R
        elif type(atm) is TabulatedAtmosphere and atm.extrapolate == "clamp":
            kind = kernels.ATM_TABLE
            tabs = tuple(np.array(v, dtype=float) for v in (atm.h, atm._log_rho, atm._log_p, atm.T))
        if atm is not None:
            s = atm.sutherland
            ac[3:] = atm.gamma * atm.gas_constant, s.mu0, s.T0, s.T0 + s.C, s.C, atm.gas_constant
        df, cm = env.density_factor, veh.ca_mach_factor
        full = kind is not None and (df is None or type(df) is DensityWave) and (cm is None or type(cm) is CaMachWave)
        waves = np.zeros(5)  # [density wave on, amplitude, wavelength, CA(Mach) wave on, amplitude]
        if type(df) is DensityWave:
            waves[:3] = 1.0, df.amplitude, df.wavelength
        if type(cm) is CaMachWave and a is not None:
            waves[3:] = 1.0, cm.amplitude
        plan = {
            "atm_kind": kind if full else None, "atm_port": kind, "ac": ac, "atm_tables": tabs, "waves": waves,
            "pmode": pmode, "pidx": pidx, "pnom": pnom, "bounded": tuple(bounded), "ci": ci, "cf": cf,
            "inertia": np.ascontiguousarray(self._inertia), "inertia_inv": np.ascontiguousarray(self._inertia_inv),
            # writable copies: one compiled signature for every model (read-only arrays type differently)
            "grids": tuple(np.array(g, dtype=float) for g in (a.mach, a.log10_kn, a.alpha, a._stack))
            if a is not None
            else (dummy1, dummy1, dummy1, dummy4),
            "dummy": dummy1, "phases": {}, "scratch": {}, "full_args": {}, "no_dx": np.empty((0, 0)),
        }  # fmt: skip
        self._plan_cache = plan
        return plan

    def _phase_consts(self, plan: dict, phase: dict):
        """(ci, cf, chute mach, chute cd) of the kernel for a phase (cached per phase values)."""
        key = (phase["mass"], phase["area"], bool(phase["parachute"]), phase.get("chute"))
        got = plan["phases"].get(key)
        if got is not None:
            return got
        veh = self.vehicle
        ci, cf = plan["ci"].copy(), plan["cf"].copy()
        cf[kernels.CF["area"]] = phase["area"]
        cf[kernels.CF["mass"]] = phase["mass"]
        table = None
        if phase["parachute"] and phase.get("chute") == "drogue" and veh.drogue is not None:
            ci[kernels.CI["chute"]], table = 1, veh.drogue
        elif phase["parachute"] and veh.parachute is not None:
            ci[kernels.CI["chute"]], table = 2, veh.parachute
        if table is not None:
            cf[kernels.CF["chute_area"]] = table.ref_area
        ci[kernels.CI["area_chute"]] = {"drogue": 1, "main": 2}.get(phase.get("chute"), 0)
        tm, tc = (np.array(table.mach), np.array(table.cd)) if table is not None else (plan["dummy"], plan["dummy"])
        got = (ci, cf, tm, tc)
        plan["phases"][key] = got
        return got

    def _full_args(self, plan: dict, phase: dict) -> tuple:
        """The arguments of :func:`~workbench.problems.post2.kernels.full_derivative` between the
        bounded parameters and ``want_dx`` (plan and phase constants), one tuple per phase."""
        key = (phase["mass"], phase["area"], bool(phase["parachute"]), phase.get("chute"))
        got = plan["full_args"].get(key)
        if got is None:
            ci, cf, tm, tc = self._phase_consts(plan, phase)
            gm_, gk, ga, tab = plan["grids"]
            got = plan["full_args"][key] = (
                plan["pmode"], plan["pidx"], plan["pnom"], ci, cf, plan["inertia"], plan["inertia_inv"],
                gm_, gk, ga, tab, tm, tc, plan["atm_kind"], plan["ac"], *plan["atm_tables"], plan["waves"],
            )  # fmt: skip
        return got

    @staticmethod
    def _scratch(plan: dict, b: int) -> tuple[np.ndarray, ...]:
        """full_derivative's scratch rows for a batch of b (altitude, ρ, a, Kn, CA(Mach) factor),
        kept per b: the kernel writes every row of the first four before reading them, and the fifth
        (ones) only when the plan has a CA(Mach) wave, then every row of it on each call."""
        got = plan["scratch"].get(b)
        if got is None:
            got = plan["scratch"][b] = (np.empty(b), np.empty(b), np.empty(b), np.empty(b), np.ones(b))
        return got

    @staticmethod
    def _bounded(plan: dict, X: np.ndarray) -> np.ndarray:
        """Physical values (S-curve, numpy as the reference) of the bounded parameter slots, (k, b)."""
        bounded = plan["bounded"]
        if len(bounded) < 2:  # none, or one S-curve
            PB = np.empty((len(bounded), X.shape[0]))
            for i, (sx, bounds) in enumerate(bounded):
                PB[i] = scurve(X[..., sx], *bounds)[..., 0]
            return PB
        # every bounded slot in one array expression: scurve's arithmetic element by element
        cols, c, h = plan.get("bounded_columns") or plan.setdefault("bounded_columns", _scurve_columns(bounded))
        return np.ascontiguousarray((c + h * np.tanh((X[:, cols] - c) / h)).T)

    def _kernel_eval(self, x: np.ndarray, phase: dict, want_dx: bool, PB: np.ndarray | None = None):
        """(ẋ or None, F, M) of x (..., n_x) by :func:`~workbench.problems.post2.kernels.dynamics_kernel`;
        the atmosphere and bounded parameters evaluated here in numpy, as the reference does (``PB``:
        the bounded parameters of x's rows from :meth:`_bounded`, if the caller has them)."""
        plan = self._plan()
        x = np.asarray(x, dtype=float)
        shape = x.shape[:-1]
        X = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
        if not X.flags.writeable:
            X = X.copy()
        b = X.shape[0]
        if plan["atm_kind"] is not None:  # altitude, atmosphere and dynamics in one compiled call
            PB = self._bounded(plan, X) if PB is None else PB
            F = np.empty((b, 3))
            M = np.empty((b, 3))
            dx = np.empty_like(X) if want_dx else plan["no_dx"]
            kernels.full_derivative(X, PB, *self._full_args(plan, phase), want_dx, dx, F, M, *self._scratch(plan, b))
            return (dx.reshape(x.shape) if want_dx else None), F.reshape(*shape, 3), M.reshape(*shape, 3)
        ci, cf, tm, tc = self._phase_consts(plan, phase)
        env, veh = self.env, self.vehicle
        atm = env.atmosphere
        dummy = plan["dummy"]
        rho = a_snd = kn = ca_extra = dummy
        PB = self._bounded(plan, X) if PB is None else PB
        F = np.empty((b, 3))
        M = np.empty((b, 3))
        dx = np.empty_like(X) if want_dx else np.empty((0, 0))
        gm_, gk, ga, tab = plan["grids"]
        if atm is not None:
            hc = np.maximum(self.altitude(X), 0.0)
            want_kn = veh.aero is not None and self._kn_matters
            if plan["atm_port"] is not None:  # the compiled port of this atmosphere
                rho, a_snd, kn = np.empty(b), np.empty(b), np.empty(b)
                L = veh.aero.ref_length if want_kn else 1.0
                kernels.atmosphere_kernel(
                    plan["atm_port"], plan["ac"], *plan["atm_tables"], hc, want_kn, L, rho, a_snd, kn
                )
            else:
                rho = atm.density(hc)
                a_snd = atm.speed_of_sound(hc)
                if want_kn:
                    kn = atm.knudsen(hc, veh.aero.ref_length)
            if env.density_factor is not None:
                rho = rho * env.density_factor(hc)
        if atm is not None and veh.aero is not None:
            if veh.ca_mach_factor is not None:  # truth: CA × f(Mach), |v_rel| as the kernel has it
                V = np.empty(b)
                kernels.air_speed_kernel(X, PB, plan["pmode"], plan["pidx"], plan["pnom"], ci, cf, V)
                ca_extra = veh.ca_mach_factor(V / a_snd)
            else:
                ca_extra = np.ones(b)
        kernels.dynamics_kernel(
            X, np.ascontiguousarray(rho, dtype=float), np.ascontiguousarray(a_snd, dtype=float),
            np.ascontiguousarray(kn, dtype=float), np.ascontiguousarray(ca_extra, dtype=float), PB,
            plan["pmode"], plan["pidx"], plan["pnom"], ci, cf, plan["inertia"], plan["inertia_inv"],
            gm_, gk, ga, tab, tm, tc, want_dx, dx, F, M,
        )  # fmt: skip
        return (dx.reshape(x.shape) if want_dx else None), F.reshape(*shape, 3), M.reshape(*shape, 3)

    def _axial_kernel(self, x: np.ndarray, phase: dict) -> np.ndarray:
        """:meth:`axial_acceleration_3dof` by :func:`~workbench.problems.post2.kernels.axial_kernel`
        (the force by :meth:`_kernel_eval`; cos(tilt) and the bias in numpy, as the reference)."""
        plan = self._plan()
        x = np.asarray(x, dtype=float)
        X = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
        if not X.flags.writeable:
            X = X.copy()
        PB = self._bounded(plan, X)
        _, F, _ = self._kernel_eval(X, phase, want_dx=False, PB=PB)
        ci, cf, _, _ = self._phase_consts(plan, phase)
        if phase["parachute"] and phase.get("chute") == "drogue":
            cos_tilt = np.array(np.cos(self.param(X, "tilt", 0.0)[..., 0]), dtype=float, order="C")
        else:
            cos_tilt = np.ones(X.shape[0])  # a · 1.0 is a: the reference's branch without the tilt
        # a writable copy (the nominal bias is a read-only broadcast): one compiled signature
        bias = np.array(self.param(X, "accel_bias", np.zeros(3))[..., 0], dtype=float, order="C")
        out = np.empty(X.shape[0])
        kernels.axial_kernel(
            X, F, PB, plan["pmode"], plan["pidx"], plan["pnom"], ci, cf, float(phase["mass"]),
            cos_tilt, bias, out,
        )  # fmt: skip
        return out.reshape(*x.shape[:-1], 1)

    # ------------------------------------------------------------------ physics pieces
    def gravity(self, x: np.ndarray) -> np.ndarray:
        """Point-mass + J2 gravity [m/s²] (..., 3) at the position of x, inertial frame (+Z pole)."""
        p = self.smap.raw(x, "position")
        j2k = 1.5 * self.j2(x) * self.env.gm * self.env.radius_eq**2
        gx, gy, gz, _ = gravity_j2_xyz(p[..., 0], p[..., 1], p[..., 2], self.env.gm, j2k)
        return np.stack([gx, gy, gz], axis=-1)

    def altitude(self, x: np.ndarray) -> np.ndarray:
        """Altitude |r| − R_ref [m] (...,)."""
        return np.linalg.norm(self.smap.raw(x, "position"), axis=-1) - self.env.radius_ref

    def v_rel(self, x: np.ndarray) -> np.ndarray:
        """Air-relative velocity v − ω × r − wind [m/s] (..., 3), inertial frame (wind: the
        ``wind`` state [east, north] in the local horizontal frame at the vehicle, if estimated)."""
        p, v = self.smap.raw(x, "position"), self.smap.raw(x, "velocity")
        w = self.env.omega
        vr = v - np.stack([-w * p[..., 1], w * p[..., 0], np.zeros_like(p[..., 0])], axis=-1)
        vr = vr - self._wind(x, p)
        if "wind" in self.smap:  # rocket flights: [east, north] wind state
            vr = vr - wind_inertial(p, self.smap.physical(x, "wind"))
        return vr

    def _wind(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Huygens-like: wind velocity [m/s] (..., 3), inertial: ``wind_vertical`` along r̂ (+ up) and
        ``wind_horizontal`` along east ê = unit(ẑ × r) (zero when neither is estimated nor planted)."""
        wv, wh = self.param(x, "wind_vertical", 0.0)[..., 0], self.param(x, "wind_horizontal", 0.0)[..., 0]
        if not (np.any(wv) or np.any(wh)):
            return np.zeros_like(p)
        r = np.linalg.norm(p, axis=-1, keepdims=True)
        east = np.stack([-p[..., 1], p[..., 0], np.zeros_like(p[..., 0])], axis=-1)
        east = east / np.maximum(np.linalg.norm(east, axis=-1, keepdims=True), 1e-9)
        return wv[..., None] * p / r + wh[..., None] * east

    def ca_regime_multiplier(self, mach: np.ndarray, kn: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Huygens-like per-regime CA multiplier (...,): ``w_fm m_fm + w_hyp m_hyp + w_sup m_sup`` with
        smooth weights (thesis [R3] Ch. 4.1.2: "a smooth transition between flight regimes"):
        free-molecular w_fm = smoothstep of log10 Kn from −2 to −1 (full at Kn ≥ 0.1), the continuum
        rest split by smoothstep of Mach from 5 to 10 (hypersonic above 10, supersonic below 5)."""
        m = [self.param(x, f"ca_multiplier_{r}", 1.0)[..., 0] for r in ("fm", "hyp", "sup")]
        estimated = any(f"ca_multiplier_{r}" in self.smap for r in ("fm", "hyp", "sup"))
        if not estimated and not any(np.any(v != 1.0) for v in m):
            return np.ones_like(mach)
        w_fm = _smoothstep(np.log10(np.maximum(kn, 1e-12)) + 2.0)
        w_h = _smoothstep((mach - 5.0) / 5.0)
        return w_fm * m[0] + (1.0 - w_fm) * (w_h * m[1] + (1.0 - w_h) * m[2])

    def _air(self, h: np.ndarray, x: np.ndarray | None = None):
        atm = self.env.atmosphere
        hc = np.maximum(h, 0.0)
        rho = atm.density(hc)
        if self.env.density_factor is not None:
            rho = rho * self.env.density_factor(hc)
        if x is not None and "density_multiplier" in self.smap:
            rho = rho * self.smap.physical(x, "density_multiplier")[..., 0]
        if x is not None and "log_pressure_offset" in self.smap:  # ρ = p / (R T): the ln-p offset moves ρ too
            rho = rho * np.exp(self.smap.physical(x, "log_pressure_offset")[..., 0])
        return rho, atm.speed_of_sound(hc), atm

    def aero_force_moment(self, x: np.ndarray, phase: dict) -> tuple[np.ndarray, np.ndarray]:
        """Aerodynamic (+ parachute) force [N] in the inertial frame and moment [N m] in the body
        frame, each (..., 3); zero in vacuum.  ``phase``: the current mass/area/parachute state.
        Compiled kernel when ``use_kernel`` (and the model is supported), else the reference."""
        if self.use_kernel and self._plan() is not None:
            _, F, M = self._kernel_eval(x, phase, want_dx=False)
            return F, M
        return self.aero_force_moment_reference(x, phase)

    def aero_force_moment_reference(self, x: np.ndarray, phase: dict) -> tuple[np.ndarray, np.ndarray]:
        """Numpy reference of :meth:`aero_force_moment` (same arguments, units, frames and shapes)."""
        shape = x.shape[:-1]
        F = np.zeros((*shape, 3))
        M = np.zeros((*shape, 3))
        if self.env.atmosphere is None:
            return F, M
        veh = self.vehicle
        h = self.altitude(x)
        rho, a_snd, atm = self._air(h, x)
        vr = self.v_rel(x)
        V = np.linalg.norm(vr, axis=-1)
        qbar = 0.5 * rho * V * V
        mach = V / a_snd
        S = phase["area"]
        ca_m = self.param(x, "ca_multiplier", 1.0)[..., 0] * veh.ca_factor
        if veh.aero is not None:
            L = veh.aero.ref_length
            kn = atm.knudsen(np.maximum(h, 0.0), L) if self._kn_matters else np.full_like(h, 1e-6)
        if veh.aero is not None:  # Huygens-like: per-regime multipliers; truth: CA × f(Mach)
            ca_m = ca_m * self.ca_regime_multiplier(mach, kn, x)
            if veh.ca_mach_factor is not None:
                ca_m = ca_m * veh.ca_mach_factor(mach)
        if self.dof == 3:
            if veh.aero is not None:
                ca, _, _ = veh.aero.coefficients(mach, kn, np.zeros_like(mach))
                F = F - (ca_m * ca * qbar * S / np.maximum(V, 1e-9))[..., None] * vr
            elif veh.cd is not None:  # a point mass with a constant drag coefficient (rocket flights)
                F = F - (ca_m * veh.cd * qbar * S / np.maximum(V, 1e-9))[..., None] * vr
        else:
            # the unit quaternion: RK4's intermediate stages (and the truth's DOP853 stages) carry
            # |q|² = 1 + O((h ω)²); an unnormalised DCM scales v_B by |q|², and at α ~ 0.1° that
            # alone moved α_t = arccos(u / V) by ~100 % (the cosine clipped at 1): the moment at the
            # stages was wrong, RK4's error per 0.1 s at peak drag was 7.5e-6 rad/s (8σ of the rate
            # noise) and the Cm multiplier absorbed it.  atan2(|v_lat|, u) is also scale invariant.
            q = quat_normalize(self.smap.raw(x, "attitude"))
            R = quat_to_dcm(q)  # R_I_B (..., 3, 3)
            vb = np.einsum("...ji,...j->...i", R, vr)
            if veh.aero is not None:
                lat = np.sqrt(vb[..., 1] ** 2 + vb[..., 2] ** 2)
                alpha_t = np.arctan2(lat, vb[..., 0])
                ca, cn, cm = veh.aero.coefficients(mach, kn, alpha_t)
                cn = cn * self.param(x, "cn_multiplier", 1.0)[..., 0] * veh.cn_factor
                cm = cm * self.param(x, "cm_multiplier", 1.0)[..., 0] * veh.cm_factor
                safe = np.maximum(lat, 1e-12)
                e_y, e_z = vb[..., 1] / safe, vb[..., 2] / safe
                e_y = np.where(lat > 1e-12, e_y, 0.0)
                e_z = np.where(lat > 1e-12, e_z, 0.0)
                qs = qbar * S
                Fb = np.stack([-ca_m * ca * qs, -cn * qs * e_y, -cn * qs * e_z], axis=-1)
                # k = unit(v̂ × X_B) = unit((0, vz, −vy)): rotation about k increases α
                mk = cm * qs * L
                w = self.smap.raw(x, "body_rates")
                damp = veh.aero.cmq * qs * L * L / (2.0 * np.maximum(V, 1e-9))
                M = np.stack([np.zeros_like(mk), mk * e_z + damp * w[..., 1], -mk * e_y + damp * w[..., 2]], axis=-1)
                F = F + np.einsum("...ij,...j->...i", R, Fb)
        if phase["parachute"] and phase.get("chute") == "drogue" and veh.drogue is not None:
            cd = veh.drogue.cd_at(mach) * self.param(x, "drogue_drag_multiplier", 1.0)[..., 0]
            F = F - (cd * qbar * veh.drogue.ref_area / np.maximum(V, 1e-9))[..., None] * vr
        elif phase["parachute"] and veh.parachute is not None:
            cd = veh.parachute.cd_at(mach) * self.param(x, "parachute_drag_multiplier", 1.0)[..., 0]
            F = F - (cd * qbar * veh.parachute.ref_area / np.maximum(V, 1e-9))[..., None] * vr
        chute = phase.get("chute")
        if chute in ("drogue", "main"):  # a drag area state (rocket flights): −CD·S q v̂_rel
            cds = self.param(x, f"{chute}_drag_area", 0.0)[..., 0]
            F = F - (cds * qbar / np.maximum(V, 1e-9))[..., None] * vr
        return F, M

    def sensed_acceleration_B(self, x: np.ndarray, phase: dict) -> np.ndarray:
        """Non-gravitational acceleration in the body frame [m/s²] (..., 3) plus ``accel_bias``."""
        F, _ = self.aero_force_moment(x, phase)
        R = quat_to_dcm(quat_normalize(self.smap.raw(x, "attitude")))
        a_b = np.einsum("...ji,...j->...i", R, F / phase["mass"])
        return a_b + self.param(x, "accel_bias", np.zeros(3))

    def axial_acceleration_3dof(self, x: np.ndarray, phase: dict) -> np.ndarray:
        """Huygens-like 3-DOF axial accelerometer [m/s²] (..., 1): the probe axis X_B is along the
        air-relative velocity (trimmed at zero α), tilted by ``tilt`` while the drogue is open, so the
        reading is ``(F · v̂_rel / m) cos(tilt) + accel_bias_x`` (negative under drag)."""
        if self.use_kernel and self._plan() is not None:
            return self._axial_kernel(x, phase)
        return self.axial_acceleration_3dof_reference(x, phase)

    def axial_acceleration_3dof_reference(self, x: np.ndarray, phase: dict) -> np.ndarray:
        """Numpy reference of :meth:`axial_acceleration_3dof` (same arguments, units and shapes)."""
        F, _ = self.aero_force_moment(x, phase)
        vr = self.v_rel(x)
        vh = vr / np.maximum(np.linalg.norm(vr, axis=-1, keepdims=True), 1e-9)
        a = np.sum(F * vh, axis=-1) / phase["mass"]
        if phase["parachute"] and phase.get("chute") == "drogue":
            a = a * np.cos(self.param(x, "tilt", 0.0)[..., 0])
        return (a + self.param(x, "accel_bias", np.zeros(3))[..., 0])[..., None]

    # ------------------------------------------------------------------ dynamics
    def derivative(self, x: np.ndarray, phase: dict) -> np.ndarray:
        """ẋ (..., n_x): kinematics, translational and (6-DOF) rotational dynamics; parameters constant.
        Compiled kernel when ``use_kernel`` (and the model is supported), else the reference."""
        if self.use_kernel and self._plan() is not None:
            return self._kernel_eval(x, phase, want_dx=True)[0]
        return self.derivative_reference(x, phase)

    def derivative_reference(self, x: np.ndarray, phase: dict) -> np.ndarray:
        """Numpy reference of :meth:`derivative` (same arguments, units and shapes)."""
        sm = self.smap
        dx = np.zeros_like(x)
        F, M = self.aero_force_moment_reference(x, phase)
        dx[..., sm.blocks["position"].sx] = sm.raw(x, "velocity")
        dx[..., sm.blocks["velocity"].sx] = self.gravity(x) + F / phase["mass"]
        if self.dof == 6:
            q = sm.raw(x, "attitude")
            w = sm.raw(x, "body_rates")
            w4 = np.concatenate([w, np.zeros((*w.shape[:-1], 1))], axis=-1)
            dx[..., sm.blocks["attitude"].sx] = 0.5 * quat_multiply(q, w4)
            Iw = w @ self._inertia.T
            dx[..., sm.blocks["body_rates"].sx] = (M - np.cross(w, Iw)) @ self._inertia_inv.T
        return dx

    def initial_phase(self) -> dict:
        """The phase state at the start: mass [kg], area [m²], parachute open (bool), events fired."""
        return {
            "mass": float(self.vehicle.mass), "area": self.vehicle.area, "parachute": False, "fired": (), "chute": None,
        }  # fmt: skip

    def event_margin(self, x: np.ndarray, ev: Event) -> float:
        """Continuous margin of a condition event at x (n_x,): > 0 before, < 0 once it holds
        (altitude − value, Mach − value, value − dynamic pressure); for the truth's event location."""
        h = float(self.altitude(x))
        if ev.when == "altitude_below":
            return h - ev.value
        if self.env.atmosphere is None:
            return 1.0
        rho, a, _ = self._air(np.array(h))
        V = float(np.linalg.norm(self.v_rel(x)))
        if ev.when == "mach_below":
            return V / float(a) - ev.value
        return ev.value - 0.5 * float(rho) * V * V

    @staticmethod
    def apply_event(phase: dict, ev: Event) -> dict:
        """The phase after event ``ev`` (mass, area, parachute changes; marked fired)."""
        out = dict(phase)
        out["fired"] = (*out["fired"], ev.name)
        if ev.mass is not None:
            out["mass"] = ev.mass
        if ev.ref_area is not None:
            out["area"] = ev.ref_area
        if ev.parachute is not None:
            out["parachute"] = ev.parachute
        if ev.chute is not None:
            out["chute"] = None if ev.chute == "none" else ev.chute
        return out

    def check_events(self, x: np.ndarray, t: float, phase: dict) -> dict:
        """The phase after applying every not-yet-fired event whose condition holds at (x (n_x,), t)."""
        out = dict(phase)
        for ev in self.events:
            if ev.name in out["fired"]:
                continue
            hit = (t >= ev.value - 1e-9) if ev.when == "time" else self.event_margin(x, ev) < 0.0
            if hit:
                out = self.apply_event(out, ev)
        return out

    def propagate(self, x: np.ndarray, t0: float, t1: float, phase: dict, max_step: float) -> np.ndarray:
        """RK4 from t0 to t1 [s] in equal sub-steps ≤ ``max_step`` [s]; x (..., n_x); quaternion
        renormalised after each sub-step.  Events are not re-checked inside (the caller checks them
        on the grid)."""
        n = max(1, int(math.ceil((t1 - t0) / max_step - 1e-9)))
        dt = (t1 - t0) / n
        plan = self._plan() if self.use_kernel else None
        if plan is not None and plan["atm_kind"] is not None:  # every RK4 stage in one compiled call
            x = np.asarray(x, dtype=float)
            X = np.array(x.reshape(-1, x.shape[-1]), dtype=float, order="C")  # one compiled layout
            ci, cf, tm, tc = self._phase_consts(plan, phase)
            gm_, gk, ga, tab = plan["grids"]
            iq = self.smap.blocks["attitude"].sx.start if self.dof == 6 else -1
            Y = kernels.propagate_kernel(
                X, n, dt, iq, self._bounded(plan, X), plan["pmode"], plan["pidx"], plan["pnom"], ci, cf,
                plan["inertia"], plan["inertia_inv"], gm_, gk, ga, tab, tm, tc, plan["atm_kind"], plan["ac"],
                *plan["atm_tables"], plan["waves"],
            )  # fmt: skip
            return Y.reshape(x.shape)
        y = np.array(x, dtype=float)
        for i in range(n):
            y = rk4_step(lambda z, _t: self.derivative(z, phase), y, t0 + i * dt, dt)
            if self.dof == 6:
                sq = self.smap.blocks["attitude"].sx
                y[..., sq] = quat_normalize(y[..., sq])
        return y

    def axial_on_grid(self, x: np.ndarray, times, phase: dict, max_step: float) -> np.ndarray:
        """3-DOF axial accelerometer [m/s²] (b, n + 1) of the rows x (b, n_x) carried over the grid
        ``times`` (n + 1,) [s] (no events): :meth:`propagate` from node k to k + 1 and
        ``observe(·, "acceleration_axial")`` at every node, the same numbers as that loop (its
        reference, :meth:`axial_on_grid_reference`) in one compiled call when the kernel applies."""
        plan = self._plan() if self.use_kernel and self.dof == 3 else None
        if plan is None or plan["atm_kind"] is None:
            return self.axial_on_grid_reference(x, times, phase, max_step)
        tl = [float(t) for t in times]
        nsub = np.empty(len(tl) - 1, np.int64)
        dts = np.empty(len(tl) - 1)
        for k in range(len(tl) - 1):  # propagate's sub-steps, step by step
            nsub[k] = max(1, int(math.ceil((tl[k + 1] - tl[k]) / max_step - 1e-9)))
            dts[k] = (tl[k + 1] - tl[k]) / nsub[k]
        X = np.array(np.asarray(x, dtype=float).reshape(-1, x.shape[-1]), dtype=float, order="C")
        ci, cf, tm, tc = self._phase_consts(plan, phase)
        gm_, gk, ga, tab = plan["grids"]
        if phase["parachute"] and phase.get("chute") == "drogue":  # as _axial_kernel (parameters constant)
            cos_tilt = np.array(np.cos(self.param(X, "tilt", 0.0)[..., 0]), dtype=float, order="C")
        else:
            cos_tilt = np.ones(X.shape[0])
        # a writable copy (the nominal bias is a read-only broadcast): one compiled signature
        bias = np.array(self.param(X, "accel_bias", np.zeros(3))[..., 0], dtype=float, order="C")
        out = np.empty((X.shape[0], len(tl)))
        kernels.propagate_axial_kernel(
            X, nsub, dts, self._bounded(plan, X), plan["pmode"], plan["pidx"], plan["pnom"], ci, cf,
            plan["inertia"], plan["inertia_inv"], gm_, gk, ga, tab, tm, tc, plan["atm_kind"], plan["ac"],
            *plan["atm_tables"], plan["waves"], float(phase["mass"]), cos_tilt, bias, out,
        )  # fmt: skip
        return out

    def axial_on_grid_reference(self, x: np.ndarray, times, phase: dict, max_step: float) -> np.ndarray:
        """The loop of :meth:`axial_on_grid` (same arguments, units and shapes): one :meth:`propagate`
        and one :meth:`observe` per grid step."""
        tl = [float(t) for t in times]
        y = np.array(x, dtype=float)
        out = np.empty((y.shape[0], len(tl)))
        out[:, 0] = self.observe(y, "acceleration_axial", phase)[:, 0]
        for k in range(len(tl) - 1):
            y = self.propagate(y, tl[k], tl[k + 1], phase, max_step)
            out[:, k + 1] = self.observe(y, "acceleration_axial", phase)[:, 0]
        return out

    # ------------------------------------------------------------------ observations
    def observe(self, x: np.ndarray, quantity: str, phase: dict) -> np.ndarray:
        """Model value of observation ``quantity`` (:data:`OBSERVATIONS`) at x (..., n_x), SI, (..., size)."""
        if quantity == "gravity_magnitude":
            return np.linalg.norm(self.gravity(x), axis=-1, keepdims=True)
        if quantity == "acceleration_inertial":
            if self.use_kernel and self._plan() is not None:  # the velocity block of ẋ: gravity + F / m
                return self._kernel_eval(x, phase, want_dx=True)[0][..., self.smap.blocks["velocity"].sx]
            F, _ = self.aero_force_moment(x, phase)
            return self.gravity(x) + F / phase["mass"]
        if quantity == "acceleration_body":
            return self.sensed_acceleration_B(x, phase)
        if quantity == "acceleration_axial" and self.dof == 3:
            return self.axial_acceleration_3dof(x, phase)
        if quantity == "acceleration_axial":
            return self.sensed_acceleration_B(x, phase)[..., :1]
        if quantity == "position_inertial":
            return np.array(self.smap.raw(x, "position"))
        if quantity == "acceleration_magnitude":
            F, _ = self.aero_force_moment(x, phase)
            return np.linalg.norm(F, axis=-1, keepdims=True) / phase["mass"]
        if quantity == "body_rates":
            return np.array(self.smap.raw(x, "body_rates"))
        if quantity == "quaternion":
            return np.array(self.smap.raw(x, "attitude"))
        if quantity == "altitude":
            return (self.altitude(x) * self.param(x, "radar_scale_factor", 1.0)[..., 0])[..., None]
        if quantity in ("pressure", "density"):
            if self.env.atmosphere is None:
                raise ValueError(f"observation {quantity!r} needs an atmosphere")
            h = self.altitude(x)
            if quantity == "pressure":
                if "baro_scale" in self.smap:  # the barometer's altitude, stretched about the anchor
                    a = self.env.baro_anchor
                    h = a + (h - a) * self.smap.physical(x, "baro_scale")[..., 0]
                h = np.maximum(h, 0.0)
                p = self.env.atmosphere.pressure(h) + self.param(x, "baro_bias", 0.0)[..., 0]
                if "baro_q_coefficient" in self.smap:  # static-port error with the dynamic pressure
                    rho = self._air(np.maximum(self.altitude(x), 0.0), x)[0]
                    q = 0.5 * rho * np.sum(self.v_rel(x) ** 2, axis=-1)
                    p = p + self.smap.physical(x, "baro_q_coefficient")[..., 0] * q
                return p[..., None]
            h = np.maximum(h, 0.0)
            return self._air(h, x)[0][..., None]
        if quantity in ("log_pressure", "temperature"):  # Huygens-like
            if self.env.atmosphere is None:
                raise ValueError(f"observation {quantity!r} needs an atmosphere")
            h = np.maximum(self.altitude(x), 0.0)
            if quantity == "log_pressure":
                return (np.log(self.env.atmosphere.pressure(h)) + self.param(x, "log_pressure_offset", 0.0)[..., 0])[
                    ..., None
                ]
            return (self.env.atmosphere.temperature(h) + self.param(x, "temperature_offset", 0.0)[..., 0])[..., None]
        if quantity == "position_pad_enu":
            raise ValueError("position_pad_enu depends on the sample's time: the estimator builds it (pad_frame)")
        raise KeyError(f"unknown observation quantity {quantity!r}")
