"""The tightly-coupled MEADS/IMU extended Kalman filter, multi-pass, with RTS smoothing.

Karlgaard et al., "Mars Entry Atmospheric Data System Trajectory Reconstruction Algorithms and
Flight Results", AIAA 2013, Sect. III.B (Eq. 19–35) and Sect. IV.B.4 (the multi-pass scheme),
composed on the shared engine (:func:`workbench.estimation.ekf.run_filter`, iterated
:func:`~workbench.estimation.ekf.update`, :func:`workbench.estimation.smoother.rts_smooth`).

State (46, all additive; :data:`STATE_NAMES`)::

    x = [p_M (3) m, v_M (3) m/s, δθ_B (3) rad, w_N (3) m/s, ln p∞, ln ρ∞, λ_1..λ_7, c,
         b_1..b_7, b'_1..b'_7, β_1..β_7 Pa, m, a_m, b_m rad]

* ``p_M``, ``v_M``: inertial position and velocity in the planet-centred inertial frame M (the
  paper's r, θ, φ, u, v, w of Eq. 19, in Cartesian form).  They are driven by the IMU through the
  strapdown of :func:`.pipeline.navigate`: the filter propagates the deviation from the strapdown
  solution, ``δp' = δp + δv Δt``, ``δv' = δv + G(p) δp Δt − [Δv_f×] C_M_B δθ`` (G the point-mass
  gravity gradient; ``Δv_f`` the strapdown's specific-force velocity increment over the step in M,
  its velocity change less its gravity; the IMU increments themselves are in the strapdown), with
  accelerometer process noise (the paper's "additive process noise on the acceleration
  measurements").  The last term is the strapdown's own error dynamics
  (:mod:`workbench.estimation.strapdown`, ``d(δv)/dt = −C_M_B [f×] δθ``): an attitude error tilts
  the specific force the strapdown integrated, so the velocity error grows as ``δθ × Δv`` — over
  the ~5.5 km/s the heat shield takes off, 1 mrad of attitude error is ~5 m/s of velocity error,
  twenty times the 0.2 m/s the initial state is known to (``[ekf] attitude_velocity_coupling``, on
  by default; Titterton & Weston, "Strapdown Inertial Navigation Technology", 2004, Sect. 12.3,
  the velocity error equation; issue #10 measured it, below).
* ``δθ_B``: the attitude.  The paper carries Euler parameters (Eq. 26) integrated from the gyros;
  here the strapdown's attitude ``q_M_B`` is a known input and the state is the body-frame
  small-angle error of it (``C_B_M = (I − [δθ×]) C_B_M,nav``), rotated with the body between
  samples and driven by gyro process noise.  For a constant-rate strapdown error this is the
  same first-order model as integrating Eq. 26 in the filter; it keeps the filter linear in the
  attitude.
* ``w_N``: wind (north, east, down) in the local-vertical frame, Eq. 29–31: the horizontal wind a
  random walk whose variance grows with the altitude travelled (winds change with height, not
  with time); the vertical wind a zero-mean first-order Gauss–Markov over the altitude travelled
  (``[ekf] vertical_wind_length_km``, 5 km, 1σ ``vertical_wind_sigma_mps``, 3 m/s): Martian
  vertical winds are gravity waves of ~10 km vertical wavelength (Creasey, Forbes & Hinson,
  "Global and seasonal distribution of gravity wave activity in Mars' lower atmosphere derived
  from MGS radio occultation data", GRL 2006), so a vertical wind does not persist over tens of
  km as a random walk lets it.
* ``ln p∞``, ``ln ρ∞``: Eq. 27–28 (hydrostatic, isothermal over a step: both change by
  ``−g Δh ρ∞/p∞``), in logarithms so the 10⁵ range of the entry stays well scaled; a random walk
  per altitude travelled absorbs the temperature structure.
* ``λ_i``: transducer scale factors, ``λ̇ = 0`` (Sect. III.B): the measured pressure of port i is
  ``(1 + λ_i)(1 + c) h_i(x)``.
* ``c``: an addition to the paper — the common level error of the estimator's pressure model
  (a constant, prior 1σ ``[ekf] model_level_sigma``, by default the least squares' model-form
  allowance).  It multiplies every port, like λ's common mode and like a common scaling of
  p∞ and ρ∞ (q∞ = ρ∞V²/2, M unchanged): the pressures cannot tell these apart, so c keeps its
  prior and what it does is carry the model-level uncertainty into the 1σ of q∞, p∞ and ρ∞
  (without it the filter reports q∞ to ~0.5 % 1σ while the estimator's table differs from the
  synthetic truth's pressures by ~1 %).  0 turns it off.
* ``b_i`` (and ``b'_i``): the estimator's pressure-model error of port i, multiplicative like λ —
  the least squares' 1 % model-form allowance carried as a *coloured* state instead of white
  noise in R (issue #10): a Gauss–Markov process of steady-state 1σ ``[ekf] model_error_sigma``
  that decorrelates with the flight condition travelled, not with time
  (:func:`flight_distance`: ``|ΔM|/model_error_mach_length + (|Δα| + |Δβ|)/model_error_angle_deg``:
  the table errs as a smooth function of Mach and the flow angles — port-location errors make it
  angle-dependent), first order (``b'`` absent) or a critically damped second order (``b'`` its
  rate, smooth increments; :func:`markov_step`, Q exact for the stationary process).  λ is the
  constant and b the varying part of the same multiplicative error: they separate only as far as
  the flight condition changes, and λ's σ says so.
* ``β_i`` [Pa]: the transducer's additive residual bias after the in-flight zero (Eq. 51), a
  constant of prior 1σ ``[ekf] bias_sigma_pa``: it is what a multiplicative error cannot be at the
  low pressures of the first seconds (without it, measured on seed 11: λ of P1 −2.6 % against
  its 3σ of 1.2 %, α inside its 3σ at 53 % of the samples).
* ``m``: the model's relative Mach error, the pressures read at ``M (1 + m)`` (first-order
  Gauss–Markov over the same distance, 1σ ``[ekf] model_mach_sigma``): the table's Mach
  dependence is the model's weakest part, which a white-noise R would otherwise let the filter
  trust (measured on seed 11, pass 1, without it: Mach 99 % inside 3σ instead of 100 %, p∞ RMS
  4.3 % instead of 3.3 %; before the flow angles were in the distance it was Mach 38 %).
* ``a_m``, ``b_m`` [rad]: the model's flow-angle error, the pressures read at ``(α + a_m, β + b_m)``
  (first-order Gauss–Markov over the same distance, 1σ :func:`angle_sigma` — by default 1° at and
  below Mach 5 falling linearly to 0.1° at Mach 10 and above, the Mach-independence principle;
  ``model_angle_sigma_deg = 0``: not modelled, the states stay at 0 with zero variance).  A forebody pressure model
  places the stagnation point from the geometry; the real shock layer moves it (the FADS
  "upwash"/flow-angle calibration of Whitmore et al.), an error a per-port multiplicative b
  cannot represent because it is a rotation of the whole pattern — the least squares see it as
  an α error and no residual shows it.

Measurement (Eq. 33–35, iterated update): the seven port pressures
``p_i = (1 + λ_i)(1 + c)(1 + b_i) h_i(x; M (1 + m), α + a_m, β + b_m) + β_i`` (m, a_m, b_m to
first order) through the same surface pressure
model as the least squares (:func:`.airdata.pressure_model`, Newtonian or the estimator's table,
"mach" set) with α, β, q∞ and Mach computed from the state — the air-relative velocity in body
axes ``C_B_M (v_M − Ω × p_M − C_M_N w_N)``, ``q∞ = ½ ρ∞ V²``, ``M = V / √(γ p∞/ρ∞)`` (the
substitution of Eq. 11–12 the paper describes).  R is only what is white: the channel's noise
and quantisation (:func:`.pipeline.sensor_sigma` with ``noise_counts``, σ ≈ 0.65 count ≈ 1.4 Pa);
with ``model_error_sigma = 0`` R is the least squares' σ with its white 1 % of reading, the
filter before issue #10.  Ports the least squares declared failed or that have no sample are
left out of the update.

Multi-pass (Sect. IV.B.4): pass 1 estimates the scale factors with everything else; pass 2 divides
the pressures by ``1 + λ̂`` (pass-1 smoothed) and runs again with the scale factors as Schmidt
*consider* parameters — mean zero, pass 1's covariance, carried in P (so S and the outputs' 1σ
include them) but never updated (gain projected to zero on them; ``rts_smooth(consider=...)``):
the data are not used twice.  Each pass is a forward iterated EKF and an RTS smoother.

Measured (``msl_meads``, seeds 11/1/2, table model, above 850 Pa, pass 2; before → after issue
#10, and before the defaults of the last paragraph — with them, seed 11: RMS α 0.12°, β 0.06°, q∞
0.69 %, p∞ 2.1 %, density 2.4 %, Mach 0.25, north wind 4.8 m/s, every output inside its 3σ at
every sample, scale factors 7 of 7): the outputs are honest — α, β, q∞, Mach, p∞, density and the
north wind inside their reported 3σ at every sample, the east wind at 96–100 % (before: α 91–94 %,
Mach 81–100 %, north wind 77–100 %); RMS errors α 0.08–0.16° (0.15–0.22°), q∞ 0.54–0.65 % (1.0–2.2
%), p∞ 2.3–3.4 % (4.0–7.4 %), Mach 0.21–0.25 (0.21–0.42), density 1.3–2.0 % (1.0–1.3 %); pass 1's
scale factors inside 3σ for 7 of 7 ports on every seed (4, 1, 5 of 7), common-mode error −0.1 to
−0.5 % (−0.9 to −2.2 %). Still conservative: the mean per-port NIS is 0.14–0.20 (0.02–0.15 before;
health WARNING below 0.5). The innovations' S is dominated by the per-step process noise of
first-order models of smooth processes — the model-error Markov as α and Mach change, the wind and
ln p∞/ln ρ∞ random walks per km — while the truth's errors are smooth, so the one-step innovations
are near the 1.4 Pa white noise. The second-order Markov (``model_error_order = 2``) doubles the
NIS (0.29–0.38) but leaves 4–7 of 7 scale factors inside 3σ; smaller wind/atmosphere random walks
bring it to 0.7–1.4 but make Mach and p∞ overconfident (43 % and 86 % inside 3σ with 3e-5/km and
15 (m/s)²/km): the smooth atmosphere (gravity waves, lapse rate) would need its own higher-order
model. With the Newtonian model the 1 % σ is too small (its error against the truth is ~3 %,
common mode 2.6 %; α 37 % inside 3σ, 13 % before); ``model_error_sigma = 0.03`` makes it α 77 %,
q∞ 89 %, the rest 93–100 %: the Newtonian's error is more than a smooth per-port factor; the
health verdict says so from the data (the same pressures reduced with the table,
:func:`.health.model_form_checks`). On pressures from the estimator's own model planted scale
factors are recovered (tests/problems/meads/test_ekf.py).

The vertical wind in the full-error Monte Carlo (issue #10; :mod:`.truth_mc`, seed 1, members
0–7, pass 2, above 850 Pa; 3 × RMS, % of member-samples inside the reported 3σ): w_down 26.9 m/s
reported 6.7 (58 % inside).  Measured cause, two parts: (1) the inertial velocity is not what the
filter says — the strapdown's velocity error against the truth is 1–7 m/s per NED axis where the
filter reports 0.25 m/s (5–19σ), and the true attitude error times the specific-force increments
reproduces it (member 0 down −8.2 m/s true, −7.8 predicted; 3: −9.2/−9.9; 6: −13.0/−11.2): the
missing ``δθ × Δv`` term above (``attitude_velocity_coupling``); (2) the dominant part: the
estimator's table errs in α against the dispersed CFD-like truths at Mach < 8 by −0.4 to −1.1°
in every member (the least squares' own α error), far beyond its 1 % pressure allowance, and the
vertical air-relative velocity is ``V × α`` (1 000 m/s × 0.5° = 9 m/s): whatever the filter does not
attribute to α goes into w_down (or, with the coupling, into δθ and through it into δv).  The
coupling alone: velocity honest, p∞ 9.8 → 7.7 %, Mach 0.31 → 0.25, north wind inside 94 → 98 %,
but w_down 31 m/s, 58 % and α inside 88 → 78 % (the new freedom is used to absorb the α error);
the velocity errors inside their 3σ at 90–100 % of the member-samples per axis (22–43 % without);
with the flow-angle states at 0.6° as well: α 0.79 → 0.61° (97 % inside), w_down 26.5 m/s (75 %),
but q∞ 1.5 → 5.0 % and density 4.4 → 8.1 % (the flow-angle error trades with the level of the
pressures); the flow-angle states at 0.6° without the coupling: α 95 % inside, w_down 25.5 m/s
at 59 %, q∞ 5.4 %, density 7.3 %.

Per Mach bin (:mod:`.truth_mc`) the rest of the vertical-wind error showed itself: with the
coupling it is a bias common to every member, set in the hypersonic phase (−6 to −9 m/s from
Mach 22 down: the table's ~−0.1° α error there times ~5.5 km/s, absorbed into a vertical wind
that a random walk per km then carries for 100 km), growing again below Mach 12 (the table's
low-Mach α error times V).  Hence the defaults, each physical rather than fitted: the coupling
on; the vertical wind a zero-mean Gauss–Markov of 5 km (above); the flow-angle error 1° at and
below Mach 5 and 0.1° from Mach 10 (:func:`angle_sigma`: hypersonic pressure patterns are Mach
independent).  Measured on the same 8 members (seed 1; pass 2, above 850 Pa, per Mach bin, the
median over bins of 3 × RMS and of reported/MC 3σ, % of member-samples inside the reported 3σ;
``workbench mc msl_meads --truth-sim --seeds 8 --first-seed 1``), before → after: α 0.73° ×0.75
88 % → 0.58° ×0.95 99 %; β 0.44° 98 % → 0.48° 97 %; q∞ 1.51 % ×4.5 → 1.92 % ×3.5 (100 %: the
angle states trade with the pressure level, the cost of the change); Mach 96 → 99.5 %; p∞ 9.4 →
7.6 %, 99 → 100 %; density 4.3 → 4.2 %; north / east wind 94 / 97 → 98.5 / 98 %; vertical wind
26.4 m/s ×0.30 58 % → 6.7 m/s ×3.2 94 %.  Each part alone (same members): the Gauss–Markov
vertical wind with the coupling but no angle states, w_down 7.7 m/s, 77 % (the low-Mach α error
goes into it), q∞ 1.47 %; the angle states (0.6°, 0.1 above Mach 10) with the coupling but a
random-walk vertical wind, w_down 27.9 m/s, 68 %.  The 50-member numbers are the benchmark's
(README).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2, gravity_point_mass_gradient
from workbench.core.rotation import quat_to_dcm, skew
from workbench.estimation.ekf import (
    ErrorStateLayout,
    ForwardPass,
    Measurement,
    derived_with_sigma,
    numeric_jacobian_batched,
    run_filter,
)
from workbench.estimation.smoother import SmoothedPass, rts_smooth
from workbench.models.flush_airdata import FadsVehicle, SurfacePressureTable
from workbench.problems.meads.airdata import ned_frames, pressure_model
from workbench.problems.meads.config import EkfSettings
from workbench.problems.meads.kernel import flow_kernel, pressure_kernel
from workbench.problems.meads.state import (
    IB,
    IBD,
    IBIAS,
    IC,
    ILAM,
    ILP,
    ILR,
    IMA,
    IMM,
    IP,
    ITH,
    IV,
    IW,
    IW_DOWN,
    IW_EAST,
    IW_NORTH,
    N_PORTS,
    N_U_COLS,
    N_X,
    STATE_NAMES,
)

__all__ = [
    "STATE_NAMES",
    "OUTPUT_NAMES",
    "EkfSettings",
    "EkfInputs",
    "EkfPass",
    "run_pass",
    "run_passes",
    "air_outputs",
    "air_data_of_state",
    "make_transition",
    "make_pressure_model",
    "flight_distance",
    "markov_step",
    "markov_steady_var",
]

LAYOUT = ErrorStateLayout(N_X)
OUTPUT_NAMES = ("alpha", "beta", "qbar", "mach", "p_inf", "rho", "wind_north", "wind_east", "wind_down")
"""Columns of :func:`air_outputs` [rad, rad, Pa, 1, Pa, kg/m³, m/s, m/s, m/s]."""

#: perturbations of the numeric Jacobians, error-state units
EPS = np.r_[
    np.full(3, 1.0), np.full(3, 1e-2), np.full(3, 1e-6), np.full(3, 1e-2), 1e-5, 1e-5, np.full(7, 1e-6), 1e-6,
    np.full(2 * N_PORTS, 1e-6), np.full(N_PORTS, 1e-2), 1e-6, 1e-6, 1e-6,
]  # fmt: skip


@dataclass(frozen=True)
class EkfInputs:
    """What the filter reads, at the n pressure times ``t`` [s]: the strapdown ``p_M``, ``v_M``
    (n, 3) and ``q_M_B`` (n, 4) (:class:`.pipeline.Navigation`), the initial 1σ of position [m],
    velocity [m/s] and attitude [rad], the (lag-corrected) pressures ``p`` (n, m) [Pa], their 1σ
    ``sigma_p`` (n, m) [Pa], ``usable`` (n, m) bool (finite and not failed), the vehicle, the
    pressure ``model`` (``"newtonian"``/``"table"``), its ``table`` and ``gamma``."""

    t: np.ndarray
    p_M: np.ndarray
    v_M: np.ndarray
    q_M_B: np.ndarray
    sigma_pos: float
    sigma_vel: float
    sigma_att: float
    p: np.ndarray
    sigma_p: np.ndarray
    usable: np.ndarray
    vehicle: FadsVehicle
    model: str
    table: SurfacePressureTable | None
    gamma: float


@dataclass(frozen=True)
class EkfPass:
    """One filter pass (a pipeline stage): ``index`` 1 or 2 of ``passes``; ``t`` (n,) [s];
    ``forward`` the :class:`ForwardPass` (innovations under ``"pressure"``, NaN for unused ports;
    ``P_prior``, ``P_post``, ``F`` empty and ``Q`` None: dropped after smoothing, the forward 1σ
    is ``sigma_post``; all kept with ``run_pass(keep_all=True)``); ``smoothed`` the
    :class:`SmoothedPass` (``G`` empty, dropped); ``outputs`` (n, 9) and ``sigma`` (n, 9) of
    :data:`OUTPUT_NAMES` from the smoothed state; ``scale`` (7,) the scale factors used or found
    (smoothed) with 1σ ``sigma_scale`` and covariance ``scale_cov`` (7, 7); ``scale_estimated``
    whether this pass estimated them;
    ``nis_port`` (k, 7) per-port normalised innovations squared ``y_i²/S_ii`` of the forward pass at
    the processed samples (NaN where unused); ``wall_s`` [s]; ``sigma_post`` (n, N_X) the forward
    pass's 1σ of every state (error-state units)."""

    index: int
    passes: int
    t: np.ndarray
    forward: ForwardPass
    smoothed: SmoothedPass
    outputs: np.ndarray
    sigma: np.ndarray
    scale: np.ndarray
    sigma_scale: np.ndarray
    scale_cov: np.ndarray
    scale_estimated: bool
    nis_port: np.ndarray
    wall_s: float
    sigma_post: np.ndarray

    @property
    def stage_label(self) -> str:
        """Its name in progress lines and ``summary["stage_times_s"]``."""
        what = "scale factors estimated" if self.scale_estimated else "scale-corrected pressures"
        return f"EKF pass {self.index}/{self.passes} ({what}, RTS smoothed)"

    def output(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(value, 1σ) (n,) of one of :data:`OUTPUT_NAMES`."""
        j = OUTPUT_NAMES.index(name)
        return self.outputs[:, j], self.sigma[:, j]

    def output_error_pct(self, name: str, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(error, 1σ) (n,) [% of ``truth`` (n,), the true value on :attr:`t`] of one of
        :data:`OUTPUT_NAMES`."""
        v, s = self.output(name)
        return 100 * (v / truth - 1), 100 * s / truth

    def scale_history(self) -> tuple[np.ndarray, np.ndarray]:
        """Scale factors and their 1σ (n, 7) [of reading] along the pass: the forward filter's
        estimate converging when this pass estimated them, else the constant correction applied."""
        if self.scale_estimated:
            return self.forward.x_post[:, ILAM], self.sigma_post[:, ILAM]
        n, m = self.t.size, self.scale.size
        return np.broadcast_to(self.scale, (n, m)), np.broadcast_to(self.sigma_scale, (n, m))

    def innovation_sigma(self) -> np.ndarray | None:
        """√S_ii (k, 7) [Pa] of the forward pass's pressure innovations (None: no update ran)."""
        inn = self.forward.innovations.get("pressure")
        return None if inn is None else np.sqrt(np.einsum("kii->ki", inn.S))


# ------------------------------------------------------------------------------------- model


def _air_velocity(X: np.ndarray, C_B_M: np.ndarray) -> np.ndarray:
    """Air-relative velocity in body axes (..., 3) [m/s] of states X (..., 21) with the strapdown
    attitude C_B_M (..., 3, 3): ``(I − [δθ×]) C_B_M (v_M − Ω × p_M − C_M_N w_N)``."""
    p_M, v_M = X[..., IP], X[..., IV]
    v_g = v_M + MARS.rotation_rate * np.stack([p_M[..., 1], -p_M[..., 0], np.zeros_like(p_M[..., 0])], axis=-1)
    C_N_M = ned_frames(p_M.reshape(-1, 3)).reshape(*p_M.shape[:-1], 3, 3)
    v_air_M = v_g - np.einsum("...ji,...j->...i", C_N_M, X[..., IW])
    u = np.einsum("...ij,...j->...i", C_B_M, v_air_M)
    th = X[..., ITH]
    return u - np.stack(
        [
            th[..., 1] * u[..., 2] - th[..., 2] * u[..., 1],
            th[..., 2] * u[..., 0] - th[..., 0] * u[..., 2],
            th[..., 0] * u[..., 1] - th[..., 1] * u[..., 0],
        ],
        axis=-1,
    )


def _freestream(u: np.ndarray, ln_p: np.ndarray, ln_rho: np.ndarray, gamma: float) -> tuple[np.ndarray, ...]:
    """(α, β, q∞, M, p∞, ρ∞) (...,) from the body-axis air velocity u (..., 3) and ln p∞, ln ρ∞."""
    V = np.linalg.norm(u, axis=-1)
    alpha = np.arctan2(u[..., 2], u[..., 0])
    beta = np.arcsin(np.clip(u[..., 1] / V, -1.0, 1.0))
    p_inf, rho = np.exp(ln_p), np.exp(ln_rho)
    return alpha, beta, 0.5 * rho * V**2, V / np.sqrt(gamma * p_inf / rho), p_inf, rho


def air_data_of_state(X: np.ndarray, C_B_M: np.ndarray, gamma: float) -> tuple[np.ndarray, ...]:
    """(α, β, q∞, M, p∞, ρ∞) (...,) from states X (..., 21) and the strapdown C_B_M (..., 3, 3)."""
    return _freestream(_air_velocity(X, C_B_M), X[..., ILP], X[..., ILR], gamma)


#: perturbations of the air-data Jacobian in (u_B [m/s], ln p∞, ln ρ∞)
_EPS_Z = np.array([1e-2, 1e-2, 1e-2, 1e-5, 1e-5])
_NO_GRID = np.zeros(2)
_NO_TABLE = np.zeros((2, 2, 2, 2))


def make_pressure_model(inp: EkfInputs, *, compiled: bool = True):
    """``h(x, C_B_M, use) -> (p (k,), H (k, N_X))``: the pressures of the ports ``use`` [Pa] and
    their Jacobian.  The model depends on the state only through z = (u_B, ln p∞, ln ρ∞) and λ, so
    the surface-pressure model is differenced in z (11 evaluations) and chained with ∂z/∂x.
    ``compiled``: run as the compiled :func:`.kernel.pressure_kernel`; False: the numpy reference
    path (same numbers to a few ulp, ``tests/problems/meads/test_kernel.py``)."""
    h4 = pressure_model(inp.vehicle, inp.model, "mach", inp.gamma, inp.table)
    D = np.diag(_EPS_Z)
    dz = np.concatenate([np.zeros((1, 5)), D, -D])
    compiled = compiled and inp.model in ("newtonian", "table")
    if compiled:
        veh, tab = inp.vehicle, inp.table
        ports = (veh.cone(), veh.clock(), veh.radius() / veh.base_radius)
        grids = (_NO_GRID,) * 4 + (_NO_TABLE,)
        if tab is not None:
            grids = (tab.mach, tab.alpha_t, tab.clock, tab.s, np.ascontiguousarray(tab.values, dtype=float))
        table_model = inp.model == "table"

    def h(x: np.ndarray, C_B_M: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if compiled:
            u0, Ju12, p0, dp_dz = pressure_kernel(
                x, C_B_M, EPS, _EPS_Z, use, inp.gamma, MARS.rotation_rate, table_model, *ports, *grids
            )
            Ju = np.zeros((3, N_X))
            Ju[:, :N_U_COLS] = Ju12
        else:
            u0, Ju = numeric_jacobian_batched(lambda X: _air_velocity(X, C_B_M), x, LAYOUT, EPS)
            Z = np.r_[u0, x[ILP], x[ILR]][None, :] + dz
            a, b, q, M, _, _ = _freestream(Z[:, :3], Z[:, 3], Z[:, 4], inp.gamma)
            pz = h4(np.stack([q, a, b, M], axis=1))[:, use]  # (11, k)
            p0 = pz[0]
            dp_dz = ((pz[1:6] - pz[6:11]) / (2.0 * _EPS_Z)[:, None]).T  # (k, 5)
        Jz = np.zeros((5, N_X))
        Jz[:3] = Ju
        Jz[3, ILP] = Jz[4, ILR] = 1.0
        # the model read at M (1 + m): p ≈ p0 + m g_m with g_m = M ∂p/∂M at constant q∞, p∞, from
        # the ln p∞, ln ρ∞ columns (M = V √(ρ∞/γp∞), p = p∞ + q∞ Cp); g_m's own derivatives
        # (m times the model's curvature) are left out of H
        g_m = dp_dz[:, 4] - dp_dz[:, 3] - p0 + 2.0 * math.exp(x[ILP])
        # and at (α + a_m, β + b_m): g_a, g_b = ∂p/∂α, ∂p/∂β at constant V, q∞, M (u rotated)
        V = math.sqrt(float(u0 @ u0))
        ca, sa = u0[0] / math.hypot(u0[0], u0[2]), u0[2] / math.hypot(u0[0], u0[2])
        sb = u0[1] / V
        cb = math.sqrt(max(1.0 - sb * sb, 0.0))
        du = V * np.array([[-sa * cb, 0.0, ca * cb], [-ca * sb, cb, -sa * sb]])  # ∂u/∂α, ∂u/∂β
        g_ab = dp_dz[:, :3] @ du.T  # (k, 2)
        pm = p0 + x[IMM] * g_m + g_ab @ x[IMA]
        lam = 1.0 + x[ILAM][use]
        lev = 1.0 + x[IC]
        mod = 1.0 + x[IB][use]
        rows = np.arange(use.size)
        H = (lam * lev * mod)[:, None] * (dp_dz @ Jz)
        H[rows, ILAM.start + use] = pm * lev * mod
        H[:, IC] = pm * lam * mod
        H[rows, IB.start + use] = pm * lam * lev
        H[rows, IBIAS.start + use] = 1.0
        H[:, IMM] = g_m * lam * lev * mod
        H[:, IMA] = g_ab * (lam * lev * mod)[:, None]
        return pm * lam * lev * mod + x[IBIAS][use], H

    return h


def air_outputs(x: np.ndarray, P: np.ndarray, q_M_B: np.ndarray, gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """:data:`OUTPUT_NAMES` (n, 9) and their 1σ (n, 9) from states x (n, N_X), covariances P
    (n, N_X, N_X) and the strapdown attitude q_M_B (n, 4) (first-order propagation).  Evaluated
    :data:`OUTPUT_CHUNK` samples at a time (each sample's outputs depend on that sample only): the
    perturbed-state stack of all samples at once would hold (n, 1 + 2 N_X, N_X) and its
    intermediates (~150 MB on ``msl_meads``)."""
    C_all = np.swapaxes(quat_to_dcm(q_M_B), 1, 2)[:, None]
    ys, ss = [], []
    for i in range(0, len(x), OUTPUT_CHUNK):
        C_B_M = C_all[i : i + OUTPUT_CHUNK]

        def g(X, C_B_M=C_B_M):
            a, b, q, M, pi, rho = air_data_of_state(X, C_B_M, gamma)
            w = X[..., IW]
            return np.stack([a, b, q, M, pi, rho, w[..., 0], w[..., 1], w[..., 2]], axis=-1)

        y, s, _ = derived_with_sigma(g, x[i : i + OUTPUT_CHUNK], P[i : i + OUTPUT_CHUNK], LAYOUT, EPS)
        ys.append(y)
        ss.append(s)
    return np.concatenate(ys), np.concatenate(ss)


#: samples per block of :func:`air_outputs`
OUTPUT_CHUNK = 256


def _initial(inp: EkfInputs, st: EkfSettings, scale0: np.ndarray, scale_cov: np.ndarray, compiled: bool) -> tuple:
    atm = MarsEngineeringAtmosphere()
    h0 = float(np.linalg.norm(inp.p_M[0]) - MARS.reference_radius)
    x0 = np.zeros(N_X)
    x0[IP], x0[IV] = inp.p_M[0], inp.v_M[0]
    x0[ILP], x0[ILR] = math.log(float(atm.pressure(h0))), math.log(float(atm.density(h0)))
    x0[ILAM] = scale0
    sw = st.wind_sigma_mps
    d = np.r_[
        np.full(3, inp.sigma_pos**2),
        np.full(3, inp.sigma_vel**2),
        np.full(3, inp.sigma_att**2),
        [sw**2, sw**2, st.vertical_wind_sigma_mps**2],
        np.full(2, st.atmosphere_sigma_ln**2),
        np.zeros(scale0.size),
        [st.model_level_sigma**2],
        np.full(N_PORTS, markov_steady_var(st)[0]),
        np.full(N_PORTS, markov_steady_var(st)[1]),
        np.full(N_PORTS, st.bias_sigma_pa**2),
        [st.model_mach_sigma**2],
        np.full(2, angle_sigma(st, _flow(x0, quat_to_dcm(inp.q_M_B[0]).T, inp.gamma, compiled)[2]) ** 2),
    ]
    P0 = np.diag(d)
    P0[ILAM, ILAM] = scale_cov
    return x0, P0


def markov_steady_var(st: EkfSettings) -> tuple[float, float]:
    """Steady-state variances of one port's model-error Gauss–Markov: (b [1], b' [1 per correlation
    length]); b' is absent (0) for the first-order process."""
    s2 = st.model_error_sigma**2
    return (s2, s2) if st.model_error_order == 2 else (s2, 0.0)


def markov_step(st: EkfSettings, d: float) -> tuple[np.ndarray, np.ndarray]:
    """(Φ, Q) (2, 2) of one port's model-error state [b, b'] over the distance ``d`` >= 0 travelled
    in flight condition, in correlation lengths (:func:`flight_distance`): first order
    ``db/ds = −b + w`` or critically damped second order ``b'' = −2b' − b + w`` (smooth: its
    increments over a short step are O(d^{3/2}) instead of O(d^{1/2})); Q is the exact
    ``P∞ − Φ P∞ Φᵀ`` of the stationary process (``P∞`` of :func:`markov_steady_var`)."""
    e = math.exp(-d)
    if st.model_error_order == 2:
        Phi = e * np.array([[1.0 + d, d], [-d, 1.0 - d]])
    else:
        Phi = np.array([[e, 0.0], [0.0, 0.0]])
    Pinf = np.diag(markov_steady_var(st))
    return Phi, Pinf - Phi @ Pinf @ Phi.T


def angle_sigma(st: EkfSettings, mach: float) -> float:
    """1σ [rad] of the model's flow-angle error at ``mach``: ``model_angle_sigma_deg`` at and below
    ``model_angle_mach_low``, ``model_angle_hypersonic_fraction`` of it at and above
    ``model_angle_mach_high``, linear in Mach between.  Why it falls with Mach: the Mach-independence
    principle (Oswatitsch, "Similarity laws for hypersonic flow", 1950; Anderson, "Hypersonic and
    High-Temperature Gas Dynamics", 2006, Sect. 4.4): a blunt forebody's surface-pressure
    distribution freezes as the Mach number grows, so a table or Newtonian-type model places the
    stagnation point well in hypersonic flow, while at low supersonic Mach the shock stand-off and
    the sonic line move with Mach and the flow angle the model infers is least certain (the
    flight FADS calibrations' "upwash" corrections are largest there: Whitmore, Cobleigh & Haering,
    "Design and calibration of the X-33 flush airdata sensing (FADS) system", AIAA 98-0201)."""
    s0 = math.radians(st.model_angle_sigma_deg)
    lo, hi = st.model_angle_mach_low, st.model_angle_mach_high
    w = min(max((float(mach) - lo) / (hi - lo), 0.0), 1.0)
    return s0 * (1.0 + w * (st.model_angle_hypersonic_fraction - 1.0))


def _flow(x: np.ndarray, C_B_M: np.ndarray, gamma: float, compiled: bool = True) -> tuple[float, float, float]:
    """(α [rad], β [rad], Mach) of one state ``x`` (N_X,) with the strapdown C_B_M (3, 3); compiled
    (:func:`.kernel.flow_kernel`) or the numpy :func:`air_data_of_state`."""
    if compiled:
        return flow_kernel(x, C_B_M, MARS.rotation_rate, gamma)
    a, b, _, m, _, _ = air_data_of_state(x, C_B_M, gamma)
    return float(a), float(b), float(m)


def flight_distance(
    x0: np.ndarray, x1: np.ndarray, C0: np.ndarray, C1: np.ndarray, gamma: float, st: EkfSettings
) -> float:
    """The distance [correlation lengths] travelled in flight condition from state x0 (attitude
    C_B_M C0 (3, 3)) to x1 (C1): ``|ΔM| / model_error_mach_length + (|Δα| + |Δβ|) /
    model_error_angle_deg`` — the estimator's pressure model errs as a smooth function of Mach
    and the flow angles, so its error decorrelates with them, not with time."""
    return _distance(_flow(x0, C0, gamma), _flow(x1, C1, gamma), st)


def _distance(f0: tuple[float, float, float], f1: tuple[float, float, float], st: EkfSettings) -> float:
    """:func:`flight_distance` from the two states' (α [rad], β [rad], Mach) of :func:`_flow`."""
    a0, b0, m0 = f0
    a1, b1, m1 = f1
    d_angle = (abs(a1 - a0) + abs(b1 - b0)) / math.radians(st.model_error_angle_deg)
    return float(abs(m1 - m0) / st.model_error_mach_length + d_angle)


def make_transition(inp: EkfInputs, st: EkfSettings, *, compiled: bool = True):
    """``transition(x, t0, t1) -> (x1, F, Q)`` on the pressure-time grid (module docstring);
    ``compiled``: the flight condition of a state by the compiled kernel (else numpy)."""
    t = inp.t
    C_M_B = quat_to_dcm(inp.q_M_B)
    idx = {float(v): i for i, v in enumerate(t.tolist())}
    I3 = np.eye(3)

    C_B_M = np.swapaxes(C_M_B, 1, 2)
    markov = st.model_error_sigma > 0.0 or st.model_mach_sigma > 0.0 or st.model_angle_sigma_deg > 0.0
    # the strapdown's specific-force velocity increments in M over each step (n - 1, 3) [m/s]:
    # its velocity change less the gravity it integrated (point mass + J2, trapezoidal)
    g = gravity_j2(inp.p_M, MARS)
    dv_sf = np.diff(inp.v_M, axis=0) - 0.5 * (g[1:] + g[:-1]) * np.diff(t)[:, None]

    def transition(x, t0, t1):
        k = idx[t1]
        dt = t1 - t0
        dp, dv = x[IP] - inp.p_M[k - 1], x[IV] - inp.v_M[k - 1]
        G = gravity_point_mass_gradient(inp.p_M[k - 1][None], MARS.gm)[0]
        # the attitude error tilts the specific force the strapdown integrated:
        # δv' = δv − [Δv_sf×] C_M_B δθ (module docstring)
        Fvt = -skew(dv_sf[k - 1]) @ C_M_B[k - 1] if st.attitude_velocity_coupling else np.zeros((3, 3))
        x1 = x.copy()
        x1[IP] = inp.p_M[k] + dp + dv * dt
        x1[IV] = inp.v_M[k] + dv + G @ dp * dt + Fvt @ x[ITH]
        Rb = C_M_B[k].T @ C_M_B[k - 1]  # body at k-1 -> body at k
        x1[ITH] = Rb @ x[ITH]
        r0, r1 = np.linalg.norm(x[IP]), np.linalg.norm(x1[IP])
        dh = r1 - r0
        c = MARS.gm / r0**2 * math.exp(x[ILR] - x[ILP])  # g ρ/p [1/m]
        x1[ILP] = x[ILP] - c * dh
        x1[ILR] = x[ILR] - c * dh
        F = np.eye(N_X)
        F[IP, IV] = dt * I3
        F[IV, IP] = G * dt
        F[IV, ITH] = Fvt
        F[ITH, ITH] = Rb
        u0, u1 = x[IP] / r0, x1[IP] / r1
        dh_dp = u1 - u0  # ∂Δh/∂p (through p1 = p + ...)
        dh_dv = u1 * dt
        for i in (ILP, ILR):
            F[i, IP] = -c * dh_dp
            F[i, IV] = -c * dh_dv
            F[i, ILP] = F[i, ILP] + c * dh
            F[i, ILR] = F[i, ILR] - c * dh
        Q = np.zeros((N_X, N_X))
        qa = st.accel_psd
        Q[IP, IP] = qa * dt**3 / 3.0 * I3
        Q[IP, IV] = Q[IV, IP] = qa * dt**2 / 2.0 * I3
        Q[IV, IV] = qa * dt * I3
        Q[ITH, ITH] = st.attitude_psd * dt * I3
        km = abs(dh) / 1e3
        Q[IW_NORTH, IW_NORTH] = Q[IW_EAST, IW_EAST] = st.wind_var_per_km * km
        if st.vertical_wind_length_km > 0.0:
            # the vertical wind as gravity waves: zero-mean, decorrelating over the altitude travelled
            phi_w = math.exp(-km / st.vertical_wind_length_km)
            x1[IW_DOWN] = phi_w * x[IW_DOWN]
            F[IW_DOWN, IW_DOWN] = phi_w
            Q[IW_DOWN, IW_DOWN] = st.vertical_wind_sigma_mps**2 * (1.0 - phi_w**2)
        else:
            Q[IW_DOWN, IW_DOWN] = st.wind_var_per_km * km * (st.vertical_wind_sigma_mps / st.wind_sigma_mps) ** 2
        Q[ILP, ILP] = Q[ILR, ILR] = st.atmosphere_var_per_km * km
        # the flight condition at both ends, once: the distance and the flow-angle σ(M) read it
        f0 = _flow(x, C_B_M[k - 1], inp.gamma, compiled) if markov else None
        f1 = _flow(x1, C_B_M[k], inp.gamma, compiled) if markov else None
        dist = _distance(f0, f1, st) if markov else 0.0
        if st.model_error_sigma > 0.0:
            Phi, Qb = markov_step(st, dist)
            x1[IB] = Phi[0, 0] * x[IB] + Phi[0, 1] * x[IBD]
            x1[IBD] = Phi[1, 0] * x[IB] + Phi[1, 1] * x[IBD]
            for a, ia in ((0, IB), (1, IBD)):
                for b, ib in ((0, IB), (1, IBD)):
                    F[ia, ib] = Phi[a, b] * np.eye(N_PORTS)
                    Q[ia, ib] = Qb[a, b] * np.eye(N_PORTS)
        if st.model_mach_sigma > 0.0:
            phi = math.exp(-dist)
            x1[IMM] = phi * x[IMM]
            F[IMM, IMM] = phi
            Q[IMM, IMM] = st.model_mach_sigma**2 * (1.0 - phi**2)
        if st.model_angle_sigma_deg > 0.0:
            # a_m = s(M) z, z a unit first-order Gauss–Markov over the distance: as s(M) changes
            # with Mach (angle_sigma) the state scales with it, its variance stays s(M)²
            s0, s1 = angle_sigma(st, f0[2]), angle_sigma(st, f1[2])
            phi = math.exp(-dist)
            f = phi * s1 / s0 if s0 > 0.0 else 0.0
            x1[IMA] = f * x[IMA]
            F[IMA, IMA] = f * np.eye(2)
            Q[IMA, IMA] = s1**2 * (1.0 - phi**2) * np.eye(2)
        return x1, F, Q

    return transition


def run_pass(
    inp: EkfInputs,
    st: EkfSettings,
    *,
    index: int = 1,
    passes: int = 1,
    estimate_scale: bool = True,
    scale_fixed: np.ndarray | None = None,
    scale_cov_fixed: np.ndarray | None = None,
    keep_all: bool = False,
    compiled: bool = True,
) -> EkfPass:
    """One pass: forward iterated EKF over the pressure samples, then RTS smoothing.

    ``keep_all``: keep the forward pass's covariances and the smoother's gains in the result
    (tests); by default they are dropped after smoothing (:class:`EkfPass`).  ``compiled``: the
    compiled measurement and flight-condition kernels (False: the numpy reference path).

    ``estimate_scale``: the scale factors are states (prior 0 ± ``st.scale_factor_sigma``);
    otherwise the pressures are divided by ``1 + scale_fixed`` (7,) and the scale-factor states
    become *consider* parameters (Schmidt): mean zero, covariance ``scale_cov_fixed`` (7, 7) (the
    previous pass's), carried in P so that the innovations' S and the outputs' 1σ include them,
    but never updated (gain projected to zero on them, no smoother gain) — the data are not
    used twice.
    """
    t0 = time.perf_counter()
    m = inp.p.shape[1]
    p, sig = inp.p, inp.sigma_p
    scale0 = np.zeros(m)
    if estimate_scale:
        Pl0 = np.diag(np.full(m, st.scale_factor_sigma**2))
        projector = None
    else:
        lam = np.zeros(m) if scale_fixed is None else np.asarray(scale_fixed, float)
        Pl0 = np.zeros((m, m)) if scale_cov_fixed is None else np.asarray(scale_cov_fixed, float)
        p = p / (1.0 + lam)
        Pi = np.eye(N_X)
        Pi[ILAM, ILAM] = 0.0

        def projector(_x):
            return Pi

    x0, P0 = _initial(inp, st, scale0, Pl0, compiled)
    h = make_pressure_model(inp, compiled=compiled)
    C_B_M = np.swapaxes(quat_to_dcm(inp.q_M_B), 1, 2)
    transition = make_transition(inp, st, compiled=compiled)

    def measurements_at(k, tk, x):
        use = np.flatnonzero(inp.usable[k] & np.isfinite(p[k]))
        if use.size == 0:
            return []
        C = C_B_M[k]
        cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

        def both(xx):
            # h and H from one evaluation; the update asks for h(x_i), then H(x_i)
            key = xx.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = h(xx, C, use)
            return cache[key]

        return [
            Measurement(
                "pressure",
                p[k, use],
                np.diag(sig[k, use] ** 2),
                lambda xx: both(xx)[0],
                H=lambda xx: both(xx)[1],
                iterations=st.iterations,
                step_tol=EPS,
                gain_projector=projector,
                slots=use,
                size=m,
            )
        ]

    with np.errstate(invalid="ignore"):
        fp = run_filter(x0, P0, inp.t, transition, None, measurements_at, LAYOUT, keep_q=keep_all)
        sm = rts_smooth(fp, LAYOUT, consider=None if estimate_scale else np.arange(N_X)[ILAM])
    out, sd = air_outputs(sm.x, sm.P, inp.q_M_B, inp.gamma)
    inn = fp.innovations.get("pressure")
    if inn is None:
        nis_port = np.zeros((0, m))
    else:
        nis_port = inn.y**2 / np.einsum("kii->ki", inn.S)
    if estimate_scale:
        lam = sm.x[0, ILAM].copy()
    Pl = sm.P[0][ILAM, ILAM].copy()
    slam = np.sqrt(np.diag(Pl))
    # what the pass keeps: the smoother's inputs P_prior and F, its gains G and the forward
    # covariances are not read after it (recording, health and summary use x_post, its 1σ, the
    # innovations, the smoothed x and P); each is an (n, N_X, N_X) array (36 MB on msl_meads)
    sigma_post = np.sqrt(np.maximum(np.einsum("nii->ni", fp.P_post), 0.0))
    if not keep_all:
        none = np.empty((0, N_X, N_X))
        fp = replace(fp, P_prior=none, P_post=none, F=none, Q=None)
        sm = replace(sm, G=none)
    return EkfPass(
        index,
        passes,
        inp.t,
        fp,
        sm,
        out,
        sd,
        lam,
        slam,
        Pl,
        estimate_scale,
        nis_port,
        time.perf_counter() - t0,
        sigma_post,
    )


def run_passes(inp: EkfInputs, st: EkfSettings, keep_all: bool = False, *, compiled: bool = True):
    """Yield pass 1 (scale factors estimated) and, with ``st.passes == 2``, pass 2 (pressures
    corrected by pass 1's scale factors); ``keep_all``, ``compiled`` as :func:`run_pass`."""
    n = int(st.passes)
    first = run_pass(inp, st, index=1, passes=n, estimate_scale=True, keep_all=keep_all, compiled=compiled)
    yield first
    if n >= 2:
        yield run_pass(
            inp,
            st,
            index=2,
            passes=n,
            estimate_scale=False,
            scale_fixed=first.scale,
            scale_cov_fixed=first.scale_cov,
            keep_all=keep_all,
            compiled=compiled,
        )
