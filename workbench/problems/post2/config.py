"""The post2 problem file: schema of a ``kind = "post2"`` scenario and :class:`Post2Settings`, the
frozen settings of one run built once from it (:meth:`Post2Settings.from_scenario`, called by
:meth:`~workbench.problems.post2.problem.Post2Problem.settings`; nothing below the problem object sees
the scenario).

A user who has a new vehicle writes a problem file, not code (thesis [R3] Ch. 3.1.2: the
estimated states, their derivatives and the observations are named in the input, the
observations and their weights come from files vs time).  The fixed tables are declared in
:data:`SCHEMA`; the named tables ``[states.<name>]``, ``[observations.<name>]``,
``[events.<name>]`` and ``[truth.states]`` are checked here against the model's catalogues
(:data:`~workbench.problems.post2.model.STATES`, :data:`~workbench.problems.post2.model.OBSERVATIONS`)
and their own key lists: an unknown name or key is a :class:`~workbench.io.scenario.ScenarioError`
naming the file and the dotted key, with a "did you mean".
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.io.assets import assets_dir
from workbench.io.scenario import RunInfo, Scenario, ScenarioError, check_value
from workbench.io.schema import REQUIRED, Key, Schema, Table, scenario_table
from workbench.io.units import to_si
from workbench.models.aerodynamics import EntryVehicle, load_vehicle
from workbench.problems.post2.model import OBSERVATIONS, STATES
from workbench.problems.post2.schedules import SCHEDULE_KEYS, Schedule

__all__ = [
    "SCHEMA",
    "unit_factor",
    "STATE_KEYS",
    "OBSERVATION_KEYS",
    "EVENT_KEYS",
    "StateSpec",
    "ObservationSpec",
    "EventSpec",
    "EnvironmentSettings",
    "VehicleSettings",
    "FilterSettings",
    "TruthSettings",
    "MonteCarloSettings",
    "LaunchSite",
    "Post2Settings",
]

_F, _I, _S, _B, _L = "float", "int", "str", "bool", "list"

#: keys of a ``[states.<name>]`` table: kind, default, unit note, meaning
STATE_KEYS: dict[str, tuple[str, Any, str]] = {
    "value": ("number_or_list", REQUIRED, "initial estimate, in the state's unit (attitude: [α, β, σ] deg)"),
    "sigma": ("number_or_list", REQUIRED, "initial 1σ, same unit"),
    "process": (
        _S,
        "constant",
        "`constant`, `random_walk` (with `psd`), `markov` (with `tau_s`) or `consider`: a constant parameter "
        "held at `value`, never fitted, whose `sigma` is added to every state's covariance by sensitivity (the "
        "run again with it moved by 1σ): an unknown the data cannot separate, e.g. a site temperature",
    ),
    "psd": ("number_or_list", 0.0, "random-walk PSD [unit²/s], or the Markov driving PSD (0: from sigma)"),
    "tau_s": (_F, None, "first-order Markov time constant [s]"),
    "sigma_altitude_km": (
        _L,
        None,
        "markov, scalar state: altitudes [km] (increasing) of a stationary-1σ profile: the driving noise keeps "
        "the 1σ at `sigma_profile` interpolated linearly at the vehicle's altitude (constant outside the nodes)",
    ),
    "sigma_profile": (_L, None, "the stationary 1σ at `sigma_altitude_km`, in the state's unit (> 0)"),
    "bounds": (_L, None, "[lo, hi]: the model uses the tanh S-curve of the estimated state (scalar parameters)"),
    "step": (_F, None, "perturbation of the numeric Jacobian, state unit (default per state)"),
}

#: keys of an ``[observations.<name>]`` table
OBSERVATION_KEYS: dict[str, tuple[str, Any, str]] = {
    "quantity": (_S, REQUIRED, "model output observed: " + ", ".join(OBSERVATIONS)),
    "file": (_S, None, "CSV of the observations (user telemetry; synthetic: written as <name>.csv)"),
    "weights": (_S, None, "CSV of the weights W vs time (R = W⁻¹), columns as the observation's, unit 1/unit²"),
    "sigma": ("number_or_list", None, "constant 1σ in the observation's unit (instead of a weights file)"),
    "median_window": (_I, 0, "sliding-median pre-smoothing over this many samples (0: none), whole windows only"),
    "decimate": (_I, 1, "assimilate every n-th sample after the pre-smoothing (smoothed samples are correlated)"),
    "gate_probability": (_F, 0.0, "χ² gate probability of the update (0: no gate)"),
    "iterations": (_I, 1, "Gauss-Newton iterations of the update (iterated EKF, Bell & Cathey 1993); 1: plain EKF"),
    "rate_hz": (_F, None, "synthetic: sample rate"),
    "start_s": (_F, None, "synthetic: first sample time (default: the start)"),
    "end_s": (_F, None, "synthetic: last sample time (default: the end)"),
    "noise_sigma": ("number_or_list", None, "synthetic: sensor white-noise 1σ (default: sigma)"),
}

#: keys of an ``[events.<name>]`` table
EVENT_KEYS: dict[str, tuple[str, Any, str]] = {
    "when": (_S, REQUIRED, "`time`, `mach_below`, `altitude_below` or `dynamic_pressure_above`"),
    "value": (_F, None, "time [s], Mach [-], altitude [m] or dynamic pressure [Pa] (required unless `detect_in`)"),
    "detect_in": (
        _L,
        None,
        '`when = "time"` read from the data instead of `value`: the observations (sensed acceleration) whose '
        "raw files give it, the first rise of |a| by more than `detect_jump_m_s2` between consecutive samples "
        "after the peak of |a| (a parachute's opening shock after the entry pulse), midpoint of the two samples",
    ),
    "detect_jump_m_s2": (_F, 1.0, "the rise of |a| between consecutive samples that `detect_in` looks for"),
    "mass_kg": (_F, None, "new mass"),
    "ref_area_m2": (_F, None, "new aerodynamic reference area"),
    "parachute": (_B, None, "true: the parachute opens; false: it is released"),
    "chute": (
        _S,
        None,
        "which parachute acts from here: `main` (the vehicle file's table, or the `main_drag_area` "
        "state), `drogue` ([vehicle] drogue_* table, or the `drogue_drag_area` state) or `none`",
    ),
    "truth_when": (
        _S,
        None,
        "synthetic truth only: its own trigger (e.g. `mach_below`) when the reconstruction's is "
        "the time read from the data",
    ),
    "truth_value": (_F, None, "synthetic truth only: the value of `truth_when`"),
}

EVENT_CONDITIONS = ("time", "mach_below", "altitude_below", "dynamic_pressure_above")
PROCESSES = ("constant", "random_walk", "markov", "consider")
CHUTES = ("drogue", "main", "none")


def _named_meaning(keys: dict) -> str:
    return "; ".join(f"`{k}`: {m}" for k, (_, _, m) in keys.items())


SCHEMA = Schema(
    "post2",
    "parameter reconstruction from a problem file (POST2 EKF method)",
    (
        scenario_table("post2", name="names the run"),
        Table(
            "model",
            "the trajectory model (simulator and the EKF's process model)",
            (
                Key("dof", _I, 3, meaning="3 (translation) or 6 (translation + rotation)"),
                Key("t_start_s", _F, 0.0, "s", "start of the reconstruction (initial state epoch)"),
                Key("t_end_s", _F, REQUIRED, "s", "end of the reconstruction"),
                Key("step_s", _F, 1.0, "s", "largest RK4 step of the estimator's propagation", gt=0.0),
                Key("grid_s", _F, None, "s", "propagation grid between observations (default: step_s)", gt=0.0),
            ),
        ),
        Table(
            "environment",
            "planet, gravity, atmosphere",
            (
                Key("body", _S, "mars", meaning="central body", choices=("mars", "titan", "earth")),
                Key("gm_m3_s2", _F, None, "m^3/s^2", "gravitational parameter (default: the body's)"),
                Key("equatorial_radius_m", _F, None, "m", "J2 reference radius (default: the body's)"),
                Key("reference_radius_m", _F, None, "m", "altitude reference sphere (default: the body's)"),
                Key("j2", _F, None, "1", "nominal J2 when not estimated (default: the body's)"),
                Key("rotation_rate_rad_s", _F, None, "rad/s", "planet rotation (atmosphere co-rotates)"),
                Key(
                    "atmosphere",
                    _S,
                    "none",
                    meaning="atmosphere model",
                    choices=("none", "exponential", "table", "mars_engineering", "titan_default", "earth_standard"),
                ),
                Key("sea_level_pressure_pa", _F, 101325.0, "Pa", "earth_standard: sea-level pressure (a site's QNH)"),
                Key("sea_level_temperature_K", _F, 288.15, "K", "earth_standard: sea-level temperature"),
                Key(
                    "baro_scale_anchor_m",
                    _F,
                    0.0,
                    "m",
                    "altitude about which the baro_scale state stretches the barometer's altitude (a launch pad's)",
                ),
                Key("rho0_kg_m3", _F, 0.015, "kg/m^3", "exponential: density at h = 0"),
                Key("scale_height_m", _F, 11100.0, "m", "exponential: scale height"),
                Key("temperature_K", _F, 210.0, "K", "exponential: temperature"),
                Key("table_altitude_m", _L, None, "m", "table: altitude nodes, increasing (held constant outside)"),
                Key("table_density_kg_m3", _L, None, "kg/m^3", "table: density at the nodes (log-linear)"),
                Key("table_pressure_pa", _L, None, "Pa", "table: pressure at the nodes (log-linear)"),
                Key("table_temperature_K", _L, None, "K", "table: temperature at the nodes (linear)"),
                Key(
                    "table_file",
                    _S,
                    None,
                    meaning="table: CSV altitude_m, density_kg_m3, pressure_pa, temperature_K (instead of the lists)",
                ),
            ),
        ),
        Table(
            "vehicle",
            "mass properties and aerodynamics",
            (
                Key(
                    "file",
                    _S,
                    None,
                    meaning="vehicle asset (shipped name in assets/vehicles or a path), the entry vehicle's format",
                ),
                Key("mass_kg", _F, None, "kg", "mass (default: the asset's entry mass)"),
                Key("ref_area_m2", _F, None, "m^2", "aerodynamic reference area (default: the asset's)"),
                Key("cd", _F, None, "1", "constant drag coefficient on ref_area_m2 when there is no vehicle file"),
                # ---- Huygens-like descent: the second (drogue / stabiliser) parachute
                Key("drogue_area_m2", _F, None, "m^2", 'drogue parachute reference area (`chute = "drogue"`)', gt=0.0),
                Key("drogue_cd", _F, 0.55, "1", "drogue parachute drag coefficient (constant)", gt=0.0),
            ),
        ),
        Table("events", "phase changes", free="table", free_meaning="`[events.<name>]`: " + _named_meaning(EVENT_KEYS)),
        Table(
            "states",
            "estimated states by name: " + ", ".join(STATES),
            free="table",
            free_meaning="`[states.<name>]`: " + _named_meaning(STATE_KEYS),
        ),
        Table(
            "observations",
            "observations by name",
            free="table",
            free_meaning="`[observations.<name>]`: " + _named_meaning(OBSERVATION_KEYS),
        ),
        # ---- schedules (observation weights / system noise vs time or event; schedules.py)
        Table(
            "schedules",
            "observation weights and system noise vs time or event (thesis Ch. 3.2.3: early weight, late noise)",
            free="table",
            free_meaning="`[schedules.<name>]`: " + _named_meaning(SCHEDULE_KEYS),
        ),
        Table(
            "initial_correlation",
            "correlations of the initial errors of some states (default: independent)",
            (
                Key(
                    "states",
                    _L,
                    None,
                    meaning="the correlated estimated states, in the order of `matrix` (no attitude)",
                ),
                Key(
                    "matrix",
                    _L,
                    None,
                    "",
                    "correlation matrix (symmetric, unit diagonal, positive semi-definite) over the listed states' "
                    "components; the initial covariance block is diag(sigma) C diag(sigma)",
                ),
            ),
        ),
        Table(
            "launch",
            "a rocket flight's launch pad (written by `workbench import airbrakes`): with `lat_deg` set the run "
            "reports rocket results (apogee, speeds, landing point, descent rates) in the pad's local frame; "
            "times are s after launch and the inertial axes are the planet-fixed axes at t = 0",
            (
                Key(
                    "lat_deg",
                    _F,
                    None,
                    "deg",
                    "pad latitude (geodetic, taken as spherical as the import does)",
                    ge=-90.0,
                    le=90.0,
                ),
                Key("lon_deg", _F, None, "deg", "pad longitude, east positive", ge=-180.0, le=360.0),
                Key("pad_altitude_m", _F, 0.0, "m", "pad altitude above the reference sphere"),
                Key("burnout_s", _F, None, "s", "motor burnout (the flight computer's first coast row)"),
                Key("touchdown_s", _F, None, "s", "touchdown (first landed row); absent: the data end in flight"),
                Key(
                    "heading_sigma_deg",
                    _F,
                    60.0,
                    "deg",
                    "the pad heading's 1σ (read when `heading_trusted` is false: the run adds it to P0 as a turn "
                    "of the flight about the pad's vertical, which no pressure or |f| observation moves, and the "
                    "landing's heading ring)",
                    ge=0.0,
                    le=180.0,
                ),
                Key(
                    "heading_trusted",
                    _B,
                    True,
                    meaning="the pad heading came from an accepted magnetometer alignment (false: `heading_sigma_deg`, "
                    "carried as an exact turn about the pad's vertical, the boost covariance written without it)",
                ),
            ),
        ),
        Table(
            "filter",
            "estimator options",
            (
                Key("smoother", _B, True, meaning="run the RTS smoother after the forward pass"),
                Key(
                    "compare_propagation",
                    _B,
                    False,
                    meaning="also propagate the initial estimate without observations (propagation-only reference)",
                ),
            ),
        ),
        Table(
            "truth",
            "synthetic truth: how it differs from the estimator's model (never read by the reconstruction)",
            (
                Key("rtol", _F, 1e-10, "1", "relative tolerance of the truth's DOP853 integrator"),
                Key("output_step_s", _F, 0.01, "s", "truth sampling step"),
                Key("ca_factor", _F, 1.0, "1", "truth CA / table CA"),
                Key("cn_factor", _F, 1.0, "1", "truth CN / table CN"),
                Key("cm_factor", _F, 1.0, "1", "truth Cm / table Cm"),
                Key("density_wave_amplitude", _F, 0.0, "1", "truth density × (1 + a sin(2π h / λ))"),
                Key("density_wave_length_m", _F, 10000.0, "m", "λ of that wave"),
                # ---- Huygens-like descent: the truth's own Titan atmosphere and a smooth CA(Mach) error
                Key(
                    "titan_node_altitudes_m",
                    _L,
                    None,
                    "m",
                    "truth atmosphere: a layered Titan atmosphere through these temperature nodes (from 0)",
                ),
                Key("titan_node_temperatures_K", _L, None, "K", "truth atmosphere: temperatures at those nodes"),
                Key("ca_mach_wave_amplitude", _F, 0.0, "1", "truth CA × (1 + a sin(2π log10(Mach) / 1.2))"),
                Key(
                    "monte_carlo_draw_from_prior",
                    _L,
                    [],
                    meaning="`workbench mc --truth-sim`: these estimated parameters of each member's truth drawn "
                    "from the estimator's prior (the others keep [truth.states])",
                ),
            ),
        ),
        Table(
            "truth.tolerances",
            "scorecard: recovered − planted must be inside this (state unit) as well as inside its 3σ",
            free="number_or_vec3",
            free_meaning="tolerance (state unit)",
        ),
        Table(
            "monte_carlo",
            "Monte Carlo initial-state selection (thesis [R3] Ch. 5.1); members = 0: off",
            (
                Key("members", _I, 0, meaning="dispersed initial states drawn from `covariance`"),
                Key("keep", _I, 20, meaning="best members kept (their spread is the EKF's initial covariance)"),
                Key("observation", _S, None, meaning="observation name whose residual is accumulated"),
                Key("end_s", _F, None, "s", "end of the phase the residual is accumulated to"),
                Key("align_level_m_s2", _F, 0.5, "m/s^2", "|measured acceleration| at which time is aligned"),
                Key("step_s", _F, 0.5, "s", "RK4 step of the member propagation", gt=0.0),
                Key("seed", _I, 0, meaning="seed of the dispersion (offset by the run seed)"),
                Key(
                    "covariance",
                    _L,
                    None,
                    meaning="6×6 covariance of [position km, velocity km/s] (km², km²/s², km²/s): the delivered one",
                ),
            ),
        ),
        Table(
            "truth.states",
            "truth values of states and model inputs, by state name, in the state's unit",
            free="number_or_vec3",
            free_meaning="truth value (attitude: [α, β, σ] deg)",
        ),
        Table(
            "synthetic",
            "simulate instead of reading telemetry",
            (Key("seed", _I, 0, meaning="seed of the sensor noise"),),
        ),
    ),
)


def _suggest(word: str, candidates) -> str:
    close = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.5)
    return f"; did you mean '{close[0]}'?" if close else ""


def _value(file: Path, dotted: str, v: Any, kind: str) -> Any:
    if kind == "number_or_list":
        if isinstance(v, int | float) and not isinstance(v, bool):
            return float(v)
        a = check_value(file, dotted, v, "list")
        try:
            return np.array(a, dtype=float)
        except (TypeError, ValueError):
            raise ScenarioError(file, dotted, f"expected a number or a list of numbers, got {a!r}") from None
    return check_value(file, dotted, v, kind)


def _sub(file: Path, prefix: str, table: Any, keys: dict) -> dict:
    """Check a named sub-table against ``keys``; returns its values with defaults filled in."""
    if not isinstance(table, dict):
        raise ScenarioError(file, prefix, f"expected a table [{prefix}]")
    out = {}
    for k, v in table.items():
        if k not in keys:
            raise ScenarioError(
                file,
                f"{prefix}.{k}",
                f"unknown key '{k}' in [{prefix}]{_suggest(k, keys)} (keys here: {', '.join(keys)})",
            )
        out[k] = _value(file, f"{prefix}.{k}", v, keys[k][0])
    for k, (_, default, _) in keys.items():
        if k not in out:
            if default is REQUIRED:
                raise ScenarioError(file, f"{prefix}.{k}", f"missing (required in [{prefix}])")
            out[k] = default
    return out


def _vec(file: Path, dotted: str, v: Any, size: int) -> np.ndarray:
    a = np.atleast_1d(np.asarray(v, dtype=float))
    if a.size == 1 and size > 1:
        a = np.full(size, float(a[0]))
    if a.shape != (size,):
        raise ScenarioError(file, dotted, f"expected {size} number(s), got {a.size}")
    if not np.all(np.isfinite(a)):
        raise ScenarioError(file, dotted, "must be finite")
    return a


@dataclass(frozen=True)
class StateSpec:
    """One estimated state: ``value``, ``sigma`` (size,) in SI (attitude: rad), ``process``,
    ``psd`` (size,) SI per second, ``tau`` [s] or None, ``bounds`` (lo, hi) SI or None, ``step``
    (error-state size,) SI perturbation, ``sigma_profile`` None or (altitudes [m] (k,), stationary
    1σ SI (k,)) of a Markov state whose stationary 1σ depends on the vehicle's altitude."""

    name: str
    value: np.ndarray
    sigma: np.ndarray
    process: str
    psd: np.ndarray
    tau: float | None
    bounds: tuple[float, float] | None
    step: np.ndarray
    sigma_profile: tuple[np.ndarray, np.ndarray] | None = None


@dataclass(frozen=True)
class ObservationSpec:
    """One observation channel: ``quantity``, its ``size``, SI ``sigma`` (size,) or None (weights
    file), ``weights`` file key present, pre-smoothing ``median_window``, ``gate_probability``
    (None: no gate), and the synthetic sensor's ``rate_hz``, ``start``, ``end`` [s], ``noise`` (size,) SI;
    ``path``/``weights_path`` the files resolved to absolute paths (None when not given)."""

    name: str
    quantity: str
    size: int
    unit: str
    file: str | None
    weights: str | None
    sigma: np.ndarray | None
    median_window: int
    gate_probability: float | None
    iterations: int
    rate_hz: float | None
    start: float | None
    end: float | None
    noise: np.ndarray | None
    decimate: int = 1
    path: Path | None = None  # ``file`` resolved against the problem file's folder
    weights_path: Path | None = None  # ``weights`` resolved likewise


@dataclass(frozen=True)
class EventSpec:
    """One event: ``name``, ``when`` condition, ``value`` (SI; nan until read from the data when
    ``detect_in`` names the observations that give it, :func:`~workbench.problems.post2.pipeline.detect_event_times`
    with the rise ``detect_jump`` [m/s²]), new ``mass``/``ref_area``/``parachute``, ``chute``
    (``drogue``/``main``/``none``: which drag-area state acts from the event on)."""

    name: str
    when: str
    value: float
    mass: float | None
    ref_area: float | None
    parachute: bool | None
    chute: str | None = None
    truth_when: str | None = None
    truth_value: float | None = None
    detect_in: tuple[str, ...] | None = None
    detect_jump: float = 1.0


def _initial_correlation(file: Path, raw: dict, states: dict[str, int]) -> tuple[tuple[str, ...], np.ndarray] | None:
    """Validate ``[initial_correlation]``: ``raw`` the table, ``states`` estimated state name -> size.
    Returns (state names, correlation matrix (n, n)) or None when the table is absent."""
    if not raw or (raw.get("states") is None and raw.get("matrix") is None):
        return None
    pre = "initial_correlation"
    names = raw.get("states")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise ScenarioError(file, f"{pre}.states", "expected a non-empty list of estimated state names")
    for n in names:
        _check_name(file, f"{pre}.states", n, list(states), "estimated state")
        if n == "attitude":
            raise ScenarioError(file, f"{pre}.states", "the attitude's initial errors cannot be correlated here")
    if len(set(names)) != len(names):
        raise ScenarioError(file, f"{pre}.states", "a state is listed twice")
    size = sum(states[n] for n in names)
    try:
        c = np.asarray(raw.get("matrix"), dtype=float)
    except (TypeError, ValueError):
        c = np.zeros(0)
    if c.shape != (size, size):
        raise ScenarioError(file, f"{pre}.matrix", f"expected a {size}×{size} matrix (the listed states' components)")
    if not np.all(np.isfinite(c)) or not np.allclose(c, c.T, atol=1e-9):
        raise ScenarioError(file, f"{pre}.matrix", "must be finite and symmetric")
    if not np.allclose(np.diag(c), 1.0, atol=1e-9) or np.any(np.abs(c) > 1.0 + 1e-9):
        raise ScenarioError(file, f"{pre}.matrix", "a correlation matrix has a unit diagonal and |entries| <= 1")
    if np.min(np.linalg.eigvalsh(c)) < -1e-9:
        raise ScenarioError(file, f"{pre}.matrix", "is not positive semi-definite")
    return tuple(names), c


@dataclass(frozen=True)
class EnvironmentSettings:
    """``[environment]`` as validated (SI, the keys' names; None: the body's value), plus the
    ``table_file`` resolved to an absolute path and its ``table`` (k, 4) [altitude m, density kg/m³,
    pressure Pa, temperature K] read once (None without a table file)."""

    body: str
    gm_m3_s2: float | None
    equatorial_radius_m: float | None
    reference_radius_m: float | None
    j2: float | None
    rotation_rate_rad_s: float | None
    atmosphere: str
    sea_level_pressure_pa: float
    sea_level_temperature_K: float
    baro_scale_anchor_m: float
    rho0_kg_m3: float
    scale_height_m: float
    temperature_K: float
    table_altitude_m: list | None
    table_density_kg_m3: list | None
    table_pressure_pa: list | None
    table_temperature_K: list | None
    table_file: Path | None
    table: np.ndarray | None = None


@dataclass(frozen=True)
class VehicleSettings:
    """``[vehicle]`` as validated (SI), the asset ``path`` resolved (a shipped name under
    ``assets/vehicles`` or a path beside the problem file) and the ``asset`` loaded once by
    :func:`~workbench.models.aerodynamics.load_vehicle` (both None without a vehicle file)."""

    file: str | None
    mass_kg: float | None
    ref_area_m2: float | None
    cd: float | None
    drogue_area_m2: float | None
    drogue_cd: float
    path: Path | None = None
    asset: EntryVehicle | None = None


@dataclass(frozen=True)
class FilterSettings:
    """``[filter]``: run the RTS ``smoother``; ``compare_propagation`` with the no-observation run."""

    smoother: bool
    compare_propagation: bool


@dataclass(frozen=True)
class TruthSettings:
    """``[truth]`` of a synthetic scenario (never read by the reconstruction): the DOP853 ``rtol``,
    the sampling ``output_step_s`` [s], the coefficient factors, the density wave (amplitude, λ [m]),
    the truth's own Titan temperature nodes [m], [K] and CA(Mach) wave; the parameters the truth
    Monte Carlo draws from the prior (:mod:`.truth_mc`); ``states`` the
    ``[truth.states]`` by name in SI (size,); ``tolerances`` the ``[truth.tolerances]`` in SI (size,)."""

    rtol: float
    output_step_s: float
    ca_factor: float
    cn_factor: float
    cm_factor: float
    density_wave_amplitude: float
    density_wave_length_m: float
    titan_node_altitudes_m: list | None
    titan_node_temperatures_K: list | None
    ca_mach_wave_amplitude: float
    monte_carlo_draw_from_prior: tuple[str, ...]
    states: dict[str, np.ndarray]
    tolerances: dict[str, np.ndarray]


@dataclass(frozen=True)
class MonteCarloSettings:
    """``[monte_carlo]`` initial-state selection (thesis [R3] Ch. 5.1): ``members`` (0: off), ``keep``,
    the ``observation`` name, ``end_s`` [s] or None, ``align_level_m_s2`` [m/s²], RK4 ``step_s`` [s],
    ``seed``; ``covariance`` (6, 6) SI [m², m²/s, m²/s²] checked symmetric positive definite, or
    None (the position/velocity states' 1σ)."""

    members: int
    keep: int
    observation: str | None
    end_s: float | None
    align_level_m_s2: float
    step_s: float
    seed: int
    covariance: np.ndarray | None


@dataclass(frozen=True)
class LaunchSite:
    """``[launch]`` of a rocket flight: pad ``lat_deg``, ``lon_deg`` [deg] (edge units, as in the file),
    ``pad_altitude_m`` [m] above the reference sphere, ``burnout_s`` and ``touchdown_s`` [s after launch,
    None: unknown / not in the data], ``heading_trusted`` (the pad heading's source was accepted),
    ``heading_sigma_deg`` [deg] the pad heading's 1σ."""

    lat_deg: float
    lon_deg: float
    pad_altitude_m: float
    burnout_s: float | None
    touchdown_s: float | None
    heading_trusted: bool
    heading_sigma_deg: float = 60.0


@dataclass(frozen=True)
class Post2Settings:
    """The frozen settings of one post2 run (SI), built once by :meth:`from_scenario`: ``run`` (the
    scenario file's :class:`~workbench.io.scenario.RunInfo`), ``dof``, reconstruction span ``t_start``,
    ``t_end`` [s], estimator ``step`` and ``grid`` [s]; ``states``, ``observations`` (telemetry paths
    resolved), ``events`` and ``schedules`` in file order; ``initial_correlation`` (states, C) or None;
    the ``environment`` and ``vehicle`` (asset loaded); the ``filter`` options; the synthetic
    ``truth``; the ``monte_carlo`` selection; ``launch`` a rocket flight's pad (None: not a
    rocket).  Picklable (process pools, Dask); a study that varies it uses
    :func:`dataclasses.replace`."""

    run: RunInfo
    dof: int
    t_start: float
    t_end: float
    step: float
    grid: float
    states: tuple[StateSpec, ...]
    observations: tuple[ObservationSpec, ...]
    events: tuple[EventSpec, ...]
    schedules: tuple[Schedule, ...]
    initial_correlation: tuple[tuple[str, ...], np.ndarray] | None
    environment: EnvironmentSettings
    vehicle: VehicleSettings
    filter: FilterSettings
    truth: TruthSettings
    monte_carlo: MonteCarloSettings
    launch: LaunchSite | None = None

    def state(self, name: str) -> StateSpec | None:
        """The :class:`StateSpec` called ``name`` or None."""
        return next((s for s in self.states if s.name == name), None)

    def with_state(self, name: str, **changes) -> Post2Settings:
        """These settings with the state ``name``'s :class:`StateSpec` fields replaced (SI), e.g.
        ``value=``, ``sigma=`` (a Monte Carlo initial state): :func:`dataclasses.replace`."""
        if self.state(name) is None:
            raise KeyError(f"no estimated state {name!r}")
        return replace(self, states=tuple(replace(s, **changes) if s.name == name else s for s in self.states))

    def telemetry_files(self, folder: Path | None = None) -> dict[str, Path]:
        """{observation name: CSV, name + "_weights": CSV}: the ``[observations.<name>] file/weights``
        paths (a missing key or file is a :class:`ScenarioError` naming the key) or, with ``folder``,
        ``<name>.csv`` / ``<name>_weights.csv`` inside it (a synthetic run's)."""
        out = {}
        for o in self.observations:
            if folder is not None:
                out[o.name] = Path(folder) / f"{o.name}.csv"
                if o.weights is not None:
                    out[o.name + "_weights"] = Path(folder) / f"{o.name}_weights.csv"
                continue
            out[o.name] = self._existing(f"observations.{o.name}.file", o.path)
            if o.weights is not None:
                out[o.name + "_weights"] = self._existing(f"observations.{o.name}.weights", o.weights_path)
        return out

    def _existing(self, dotted: str, path: Path | None) -> Path:
        if path is None:
            raise ScenarioError(self.run.path, dotted, "missing str value")
        if not path.exists():
            raise ScenarioError(self.run.path, dotted, f"file not found: {path}")
        return path

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> Post2Settings:
        """Validate ``scenario`` against :data:`SCHEMA` and the named tables, resolve its files and load
        its vehicle asset; :class:`ScenarioError` naming file and dotted key for anything wrong."""
        return _settings(scenario)


def unit_factor(unit: str) -> float:
    """SI value [SI/unit] of one ``unit`` of a problem-file state (a pure scale: the state units have no
    offset; ``"1"``, ``"-"`` and ``"m^2"`` are 1)."""
    return 1.0 if unit in ("1", "-", "m^2") else float(to_si(1.0, unit)[0])


def _si(v: np.ndarray, unit: str) -> np.ndarray:
    return np.asarray(v, dtype=float) * unit_factor(unit)


def _check_name(file: Path, dotted: str, name: str, known, what: str) -> None:
    if name not in known:
        raise ScenarioError(
            file,
            dotted,
            f"unknown {what} '{name}'{_suggest(name, known)} ({what}s the model knows: {', '.join(known)})",
        )


def _state(file: Path, name: str, raw: dict, dof: int) -> StateSpec:
    pre = f"states.{name}"
    d = STATES[name]
    if dof not in d.dofs:
        raise ScenarioError(file, pre, f"state '{name}' exists only in a {' or '.join(map(str, d.dofs))}-DOF model")
    t = _sub(file, pre, raw, STATE_KEYS)
    value = _si(_vec(file, f"{pre}.value", t["value"], d.size), d.unit)
    sigma = _si(_vec(file, f"{pre}.sigma", t["sigma"], d.size), d.unit)
    if np.any(sigma <= 0):
        raise ScenarioError(file, f"{pre}.sigma", "must be > 0")
    process = t["process"]
    if process not in PROCESSES:
        raise ScenarioError(
            file, f"{pre}.process", f"{process!r}: use one of {', '.join(PROCESSES)}{_suggest(process, PROCESSES)}"
        )
    if process in ("markov", "consider") and d.dynamic:
        raise ScenarioError(file, f"{pre}.process", f"'{name}' has model dynamics: use constant or random_walk")
    psd = _vec(file, f"{pre}.psd", t["psd"], d.size)
    if np.any(psd < 0):
        raise ScenarioError(file, f"{pre}.psd", "must be >= 0")
    if process == "consider" and np.any(psd > 0):
        raise ScenarioError(file, f"{pre}.psd", "a consider parameter is constant: psd must be 0")
    psd = psd * unit_factor(d.unit) ** 2  # unit²/s -> SI²/s
    tau = t["tau_s"]
    if process == "markov" and (tau is None or not tau > 0):
        raise ScenarioError(file, f"{pre}.tau_s", "a markov process needs tau_s > 0")
    bounds = None
    if t["bounds"] is not None:
        b = t["bounds"]
        if d.size != 1 or name == "attitude":
            raise ScenarioError(file, f"{pre}.bounds", "bounds apply to scalar parameters only")
        if len(b) != 2 or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in b):
            raise ScenarioError(file, f"{pre}.bounds", f"expected [lo, hi], got {b!r}")
        lo, hi = float(b[0]), float(b[1])
        if not lo < hi:
            raise ScenarioError(file, f"{pre}.bounds", f"lo ({lo:g}) must be below hi ({hi:g})")
        if not lo < float(value[0]) < hi:
            raise ScenarioError(file, f"{pre}.value", f"{float(value[0]):g} is not inside the bounds ({lo:g}, {hi:g})")
        bounds = (lo, hi)
    step = t["step"] if t["step"] is not None else d.step
    if not step > 0:
        raise ScenarioError(file, f"{pre}.step", "must be > 0")
    step_si = float(_si(np.array([step]), d.unit)[0])
    profile = _sigma_profile(file, pre, t, d, process, psd)
    return StateSpec(name, value, sigma, process, psd, tau, bounds, np.full(d.size, step_si), profile)


def _sigma_profile(file: Path, pre: str, t: dict, d, process: str, psd: np.ndarray):
    """``sigma_altitude_km`` + ``sigma_profile`` of a ``[states.<name>]`` table, checked: None or
    (altitudes [m] (k,), stationary 1σ SI (k,))."""
    alt, sig = t["sigma_altitude_km"], t["sigma_profile"]
    if alt is None and sig is None:
        return None
    if alt is None or sig is None:
        raise ScenarioError(file, pre, "sigma_altitude_km and sigma_profile go together")
    if process != "markov" or d.size != 1:
        raise ScenarioError(file, f"{pre}.sigma_profile", "an altitude profile of sigma is for scalar markov states")
    if np.any(psd > 0):
        raise ScenarioError(file, f"{pre}.sigma_profile", "give either a driving psd or a sigma profile")
    try:
        h = np.asarray(alt, dtype=float)
        s = np.asarray(sig, dtype=float)
    except (TypeError, ValueError):
        raise ScenarioError(file, f"{pre}.sigma_profile", "expected lists of numbers") from None
    if h.ndim != 1 or h.size < 1 or h.shape != s.shape:
        raise ScenarioError(file, f"{pre}.sigma_profile", f"expected as many sigmas as altitudes ({h.size})")
    if not (np.all(np.isfinite(h)) and np.all(np.isfinite(s))) or np.any(np.diff(h) <= 0):
        raise ScenarioError(file, f"{pre}.sigma_altitude_km", "must be finite and increasing")
    if np.any(s <= 0):
        raise ScenarioError(file, f"{pre}.sigma_profile", "must be > 0")
    return h * 1e3, _si(s, d.unit)


def _observation(file: Path, name: str, raw: dict, dof: int) -> ObservationSpec:
    pre = f"observations.{name}"
    t = _sub(file, pre, raw, OBSERVATION_KEYS)
    q = t["quantity"]
    _check_name(file, f"{pre}.quantity", q, OBSERVATIONS, "observation quantity")
    d = OBSERVATIONS[q]
    if dof not in d.dofs:
        raise ScenarioError(file, f"{pre}.quantity", f"'{q}' needs a {' or '.join(map(str, d.dofs))}-DOF model")
    if t["sigma"] is None and t["weights"] is None:
        raise ScenarioError(file, pre, "give a constant `sigma` or a `weights` file")
    if t["sigma"] is not None and t["weights"] is not None:
        raise ScenarioError(file, pre, "give either `sigma` or `weights`, not both")
    sigma = None
    if t["sigma"] is not None:
        sigma = _si(_vec(file, f"{pre}.sigma", t["sigma"], d.size), d.unit)
        if np.any(sigma <= 0):
            raise ScenarioError(file, f"{pre}.sigma", "must be > 0")
    noise = (
        None if t["noise_sigma"] is None else _si(_vec(file, f"{pre}.noise_sigma", t["noise_sigma"], d.size), d.unit)
    )
    if noise is not None and not np.all(noise >= 0):
        raise ScenarioError(file, f"{pre}.noise_sigma", "must be >= 0 (a 1σ)")
    w = int(t["median_window"])
    if w < 0:
        raise ScenarioError(file, f"{pre}.median_window", "must be >= 0")
    gp = float(t["gate_probability"])
    if not 0.0 <= gp < 1.0:
        raise ScenarioError(file, f"{pre}.gate_probability", "must be in [0, 1)")
    if t["iterations"] < 1:
        raise ScenarioError(file, f"{pre}.iterations", "must be >= 1")
    if t["decimate"] < 1:
        raise ScenarioError(file, f"{pre}.decimate", "must be >= 1")
    return ObservationSpec(
        name,
        q,
        d.size,
        d.unit,
        t["file"],
        t["weights"],
        sigma,
        w,
        gp or None,
        int(t["iterations"]),
        t["rate_hz"],
        t["start_s"],
        t["end_s"],
        noise,
        int(t["decimate"]),
    )


def _event(file: Path, name: str, raw: dict) -> EventSpec:
    pre = f"events.{name}"
    t = _sub(file, pre, raw, EVENT_KEYS)
    if t["when"] not in EVENT_CONDITIONS:
        raise ScenarioError(
            file,
            f"{pre}.when",
            f"{t['when']!r}: use one of {', '.join(EVENT_CONDITIONS)}{_suggest(t['when'], EVENT_CONDITIONS)}",
        )
    if t["chute"] is not None and t["chute"] not in CHUTES:
        hint = _suggest(t["chute"], CHUTES)
        raise ScenarioError(file, f"{pre}.chute", f"{t['chute']!r}: use one of {', '.join(CHUTES)}{hint}")
    if t["truth_when"] is not None and (t["truth_when"] not in EVENT_CONDITIONS or t["truth_value"] is None):
        raise ScenarioError(file, f"{pre}.truth_when", f"use one of {', '.join(EVENT_CONDITIONS)}, with truth_value")
    detect = t["detect_in"]
    if detect is not None:
        if not detect or not all(isinstance(n, str) for n in detect):
            raise ScenarioError(file, f"{pre}.detect_in", "expected a non-empty list of observation names")
        if t["when"] != "time":
            raise ScenarioError(file, f"{pre}.detect_in", 'only for when = "time"')
        if t["value"] is not None:
            raise ScenarioError(file, f"{pre}.value", "give either value or detect_in (the time read from the data)")
        if not t["detect_jump_m_s2"] > 0.0:
            raise ScenarioError(file, f"{pre}.detect_jump_m_s2", "must be > 0")
    elif t["value"] is None:
        raise ScenarioError(file, f"{pre}.value", f"missing (required in [{pre}] without detect_in)")
    return EventSpec(
        name, t["when"], float("nan") if detect else float(t["value"]), t["mass_kg"], t["ref_area_m2"],
        t["parachute"], t["chute"], t["truth_when"], t["truth_value"],
        None if detect is None else tuple(detect), float(t["detect_jump_m_s2"]),
    )  # fmt: skip


# ---- schedules (workbench/problems/post2/schedules.py): validation of [schedules.<name>]
def _schedules(
    file: Path, raw: dict, states: dict[str, tuple[int, float, str]], observations, events
) -> tuple[Schedule, ...]:
    """Validate the ``[schedules]`` tables.  ``raw``: {name: table}; ``states``: estimated state name
    -> (size, SI factor of its unit, process); ``observations``, ``events``: the declared names.
    Every mistake is a :class:`ScenarioError` naming ``file`` and the dotted key."""
    out = []
    for name, table in raw.items():
        pre = f"schedules.{name}"
        t = _sub(file, pre, table, SCHEDULE_KEYS)
        if (t["observation"] is None) == (t["state"] is None):
            raise ScenarioError(file, pre, "name exactly one target: `observation` or `state`")
        for a, b in (("start_s", "start_event"), ("end_s", "end_event")):
            if t[a] is not None and t[b] is not None:
                raise ScenarioError(file, f"{pre}.{b}", f"give `{a}` or `{b}`, not both")
        for k in ("start_event", "end_event"):
            if t[k] is not None:
                _check_name(file, f"{pre}.{k}", t[k], list(events), "event")
        if t["start_s"] is not None and t["end_s"] is not None and not t["end_s"] > t["start_s"]:
            raise ScenarioError(file, f"{pre}.end_s", f"{t['end_s']:g} s must be after start_s ({t['start_s']:g} s)")
        if t["start_event"] is not None and t["start_event"] == t["end_event"]:
            raise ScenarioError(file, f"{pre}.end_event", "the window would close when it opens")
        factor = psd = None
        if t["observation"] is not None:
            target, tname = "observation", t["observation"]
            _check_name(file, f"{pre}.observation", tname, list(observations), "observation")
            if t["psd"] is not None:
                raise ScenarioError(file, f"{pre}.psd", "an observation window takes `weight_factor`, not `psd`")
            if t["weight_factor"] is None:
                raise ScenarioError(file, f"{pre}.weight_factor", "missing (required with `observation`)")
            factor = float(t["weight_factor"])
            if not (factor > 0 and np.isfinite(factor)):
                raise ScenarioError(file, f"{pre}.weight_factor", f"must be > 0, got {factor:g}")
        else:
            target, tname = "state", t["state"]
            _check_name(file, f"{pre}.state", tname, list(states), "estimated state")
            if t["weight_factor"] is not None:
                raise ScenarioError(file, f"{pre}.weight_factor", "a state window takes `psd`, not `weight_factor`")
            if t["psd"] is None:
                raise ScenarioError(file, f"{pre}.psd", "missing (required with `state`)")
            size, unit_si, process = states[tname]
            if process == "markov":
                raise ScenarioError(file, f"{pre}.state", f"'{tname}' is a markov state: schedule constant/random_walk")
            psd = _vec(file, f"{pre}.psd", t["psd"], size)
            if np.any(psd < 0):
                raise ScenarioError(file, f"{pre}.psd", "must be >= 0")
            psd = psd * unit_si**2
        out.append(
            Schedule(name, target, tname, factor, psd, t["start_s"], t["start_event"], t["end_s"], t["end_event"])
        )
    return tuple(out)


def _settings(scenario: Scenario) -> Post2Settings:
    """:meth:`Post2Settings.from_scenario`."""
    file = Path(scenario.path)
    run = RunInfo.from_scenario(scenario)
    data = SCHEMA.validate(scenario.data, file)
    m = data["model"]
    dof = int(m["dof"])
    if dof not in (3, 6):
        raise ScenarioError(file, "model.dof", f"must be 3 or 6, got {dof}")
    if not m["t_end_s"] > m["t_start_s"]:
        raise ScenarioError(file, "model.t_end_s", "must be after t_start_s")
    states = []
    for name, raw in data.get("states", {}).items():
        _check_name(file, f"states.{name}", name, STATES, "state")
        states.append(_state(file, name, raw, dof))
    names = [s.name for s in states]
    for need in ("position", "velocity") + (("attitude", "body_rates") if dof == 6 else ()):
        if need not in names:
            raise ScenarioError(file, f"states.{need}", f"missing: a {dof}-DOF model needs the state '{need}'")
    obs = []
    for name, raw in data.get("observations", {}).items():
        o = _observation(file, name, raw, dof)
        obs.append(replace(o, path=_resolved(run, o.file), weights_path=_resolved(run, o.weights)))
    if not obs:
        raise ScenarioError(file, "observations", "no observation declared")
    launch = _launch(file, data.get("launch", {}))
    for o in obs:
        if o.quantity == "position_pad_enu" and (launch is None or scenario.is_synthetic):
            raise ScenarioError(
                file,
                f"observations.{o.name}.quantity",
                "position_pad_enu is relative to the [launch] pad (give launch.lat_deg/lon_deg/pad_altitude_m) "
                "and is read from a file, not synthesized (no [synthetic])",
            )
    events = tuple(_event(file, n, r) for n, r in data.get("events", {}).items())
    truth_states = {}
    for name, v in data.get("truth", {}).get("states", {}).items():
        _check_name(file, f"truth.states.{name}", name, STATES, "state")
        d = STATES[name]
        truth_states[name] = _si(_vec(file, f"truth.states.{name}", v, d.size), d.unit)
    grid = m["grid_s"] if m["grid_s"] is not None else m["step_s"]
    # ---- schedules (schedules.py): targets and events must be declared above
    schedules = _schedules(
        file,
        data.get("schedules", {}),
        {s.name: (STATES[s.name].size, unit_factor(STATES[s.name].unit), s.process) for s in states},
        [o.name for o in obs],
        [e.name for e in events],
    )
    corr = _initial_correlation(
        file, data.get("initial_correlation", {}), {s.name: STATES[s.name].size for s in states}
    )
    tr = {k: v for k, v in data["truth"].items() if k not in ("states", "tolerances")}
    tr["monte_carlo_draw_from_prior"] = _draw_names(file, tr["monte_carlo_draw_from_prior"], states, truth_states)
    tolerances = {n: _tolerance(file, n, v) for n, v in data["truth"].get("tolerances", {}).items()}
    mc = dict(data["monte_carlo"])
    mc["covariance"] = _covariance(file, mc["covariance"])
    return Post2Settings(
        run, dof, float(m["t_start_s"]), float(m["t_end_s"]), float(m["step_s"]), float(grid),
        tuple(states), tuple(obs), events, schedules, corr,
        _environment(file, run, data["environment"]), _vehicle(file, run, data["vehicle"]),
        FilterSettings(**data["filter"]), TruthSettings(**tr, states=truth_states, tolerances=tolerances),
        MonteCarloSettings(**mc), launch,
    )  # fmt: skip


def _launch(file: Path, la: dict) -> LaunchSite | None:
    """``[launch]``: None without ``lat_deg`` (then any other key off its default is an error: it would
    be ignored); ``lat_deg`` needs ``lon_deg``."""
    if not la or la.get("lat_deg") is None:
        keys = next(t for t in SCHEMA.tables if t.name == "launch").keys
        for k in keys:
            if la and la.get(k.name) is not None and la.get(k.name) != k.default:
                raise ScenarioError(file, f"launch.{k.name}", "is read only with launch.lat_deg (the pad)")
        return None
    if la.get("lon_deg") is None:
        raise ScenarioError(file, "launch.lat_deg", "needs launch.lon_deg too (the pad's longitude)")
    return LaunchSite(
        float(la["lat_deg"]), float(la["lon_deg"]), float(la["pad_altitude_m"]),
        la["burnout_s"], la["touchdown_s"], bool(la["heading_trusted"]), float(la["heading_sigma_deg"]),
    )  # fmt: skip


def _draw_names(file, names, states, truth_states) -> tuple[str, ...]:
    """``[truth] monte_carlo_draw_from_prior``: estimated parameters (not position/velocity/attitude/
    rates) with a ``[truth.states]`` value, else a ScenarioError naming the key and the valid names."""
    valid = [s.name for s in states if not STATES[s.name].dynamic and s.name in truth_states]
    for n in names:
        if n not in valid:
            raise ScenarioError(
                file, "truth.monte_carlo_draw_from_prior", f"{n!r} is not an estimated parameter with a truth value: "
                f"use {', '.join(valid) or 'none (no parameter has a [truth.states] value)'}",
            )  # fmt: skip
    return tuple(names)


def _resolved(run: RunInfo, rel: str | None) -> Path | None:
    return None if rel is None else run.resolve(rel)


def _environment(file: Path, run: RunInfo, e: dict) -> EnvironmentSettings:
    """``[environment]``: the table atmosphere's lists or file checked, the file read once."""
    path = table = None
    if e["atmosphere"] == "table" and e["table_file"] is not None:  # Huygens-like: the profile from a file
        path = run.resolve(e["table_file"])
        if not path.exists():
            raise ScenarioError(file, "environment.table_file", f"file not found: {path}")
        try:
            table = np.loadtxt(path, delimiter=",", comments="#", skiprows=1, ndmin=2)
        except ValueError as err:
            raise ScenarioError(file, "environment.table_file", f"{path.name}: {err}") from None
        if table.shape[1] != 4:
            why = f"{path.name}: expected 4 columns, got {table.shape[1]}"
            raise ScenarioError(file, "environment.table_file", why)
    elif e["atmosphere"] == "table":
        for c in ("table_altitude_m", "table_density_kg_m3", "table_pressure_pa", "table_temperature_K"):
            if e[c] is None:
                raise ScenarioError(file, f"environment.{c}", "atmosphere = 'table' needs this list")
    return EnvironmentSettings(**{**e, "table_file": path}, table=table)


def _vehicle(file: Path, run: RunInfo, v: dict) -> VehicleSettings:
    """``[vehicle]``: the asset found (shipped name or path) and loaded once; the cross-field checks."""
    if v["file"] is None:
        if v["mass_kg"] is None:
            raise ScenarioError(file, "vehicle.mass_kg", "needed when no vehicle file is given")
        return VehicleSettings(**v)
    name = v["file"]
    shipped = assets_dir() / "vehicles" / f"{name}.toml"
    path = shipped if shipped.is_file() else run.resolve(name)
    if not Path(path).is_file():
        raise ScenarioError(file, "vehicle.file", f"no shipped vehicle {name!r} and no file {path}")
    return VehicleSettings(**v, path=Path(path), asset=load_vehicle(path))


def _tolerance(file: Path, name: str, value) -> np.ndarray:
    """A ``[truth.tolerances]`` entry in SI (the state's unit converted), (size,)."""
    if name not in STATES:
        raise ScenarioError(file, f"truth.tolerances.{name}", f"unknown state '{name}'")
    v = np.atleast_1d(np.asarray(value, dtype=float))
    if np.any(v <= 0):
        raise ScenarioError(file, f"truth.tolerances.{name}", "must be > 0")
    return v * unit_factor(STATES[name].unit)


def _covariance(file: Path, c) -> np.ndarray | None:
    """``[monte_carlo] covariance`` (km², km²/s, km²/s²) -> (6, 6) SI, symmetric positive definite."""
    if c is None:
        return None
    try:
        C = np.array(c, dtype=float)
    except (TypeError, ValueError):
        raise ScenarioError(file, "monte_carlo.covariance", "expected a 6×6 list of numbers") from None
    if C.shape != (6, 6) or not np.allclose(C, C.T, rtol=1e-9, atol=0.0):
        raise ScenarioError(file, "monte_carlo.covariance", f"must be a symmetric 6×6, got shape {C.shape}")
    C = C * 1e6  # km², km²/s, km²/s² -> m², m²/s, m²/s²
    try:
        np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        raise ScenarioError(file, "monte_carlo.covariance", "not positive definite") from None
    return C
