"""Build the model pieces a post2 run needs from a :class:`~workbench.problems.post2.config.Post2Config`:
the environment (body, gravity, atmosphere), the vehicle (the entry vehicle's asset format, loaded by
:func:`workbench.models.aerodynamics.load_vehicle`), the events, and the estimator's state map.

Shared by the reconstruction and the truth simulator; the truth passes its own atmosphere
perturbation and coefficient factors (``truth.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.core.atmosphere import (
    CO2_SUTHERLAND,
    MARS_CO2_GAS_CONSTANT,
    MARS_GAMMA,
    N2_SUTHERLAND,
    TITAN_GAMMA,
    TITAN_N2_GAS_CONSTANT,
    EarthStandardAtmosphere,
    ExponentialAtmosphere,
    MarsEngineeringAtmosphere,
    TabulatedAtmosphere,
    TitanDefaultAtmosphere,
)
from workbench.core.bodies import get_body
from workbench.io.assets import assets_dir
from workbench.io.scenario import Scenario, ScenarioError
from workbench.models.aerodynamics import ParachuteTable, load_vehicle
from workbench.problems.post2.config import Post2Config
from workbench.problems.post2.model import C_B_G, Environment, Event, StateMap, Vehicle

__all__ = ["STATE_ORDER", "environment", "vehicle", "events", "state_map"]

#: dynamic states first, in this order; parameters follow in problem-file order
STATE_ORDER = ("position", "velocity", "attitude", "body_rates")


def environment(scenario: Scenario, cfg: Post2Config, density_factor=None) -> Environment:
    """The :class:`Environment` of ``[environment]`` (SI); ``density_factor`` (truth only) multiplies ρ."""
    e = cfg.data["environment"]
    body = get_body(e["body"])
    atm_kind = e["atmosphere"]
    if atm_kind == "none":
        atm = None
    elif atm_kind == "exponential":
        atm = ExponentialAtmosphere(e["rho0_kg_m3"], e["scale_height_m"], e["temperature_K"])
    elif atm_kind == "table" and e["table_file"] is not None:  # Huygens-like: the profile from a file
        atm = table_file_atmosphere(scenario, e["body"])
    elif atm_kind == "table":
        cols = ("table_altitude_m", "table_density_kg_m3", "table_pressure_pa", "table_temperature_K")
        for c in cols:
            if e[c] is None:
                raise ScenarioError(scenario.path, f"environment.{c}", "atmosphere = 'table' needs this list")
        try:
            atm = TabulatedAtmosphere(*(np.asarray(e[c], dtype=float) for c in cols), extrapolate="clamp")
        except (TypeError, ValueError) as err:
            raise ScenarioError(scenario.path, "environment.table_altitude_m", f"bad atmosphere table: {err}") from None
    elif atm_kind == "earth_standard":
        atm = EarthStandardAtmosphere(e["sea_level_pressure_pa"], e["sea_level_temperature_K"])
    elif atm_kind == "mars_engineering":
        atm = MarsEngineeringAtmosphere()
    else:
        atm = TitanDefaultAtmosphere()
    return Environment(
        gm=e["gm_m3_s2"] if e["gm_m3_s2"] is not None else body.gm,
        radius_eq=e["equatorial_radius_m"] if e["equatorial_radius_m"] is not None else body.equatorial_radius,
        j2=e["j2"] if e["j2"] is not None else body.j2,
        radius_ref=e["reference_radius_m"] if e["reference_radius_m"] is not None else body.reference_radius,
        omega=e["rotation_rate_rad_s"] if e["rotation_rate_rad_s"] is not None else body.rotation_rate,
        atmosphere=atm,
        density_factor=density_factor,
        baro_anchor=e["baro_scale_anchor_m"],
    )


def table_file_atmosphere(scenario: Scenario, body: str) -> TabulatedAtmosphere:
    """The ``[environment] table_file`` profile (CSV: altitude_m, density_kg_m3, pressure_pa,
    temperature_K; ``#`` comments) as a :class:`TabulatedAtmosphere` held constant outside, with the
    gas of ``body`` (Titan N2, Mars CO2; Earth air as N2); a bad file is a located error."""
    path = scenario.path_of("environment.table_file")
    try:
        a = np.loadtxt(path, delimiter=",", comments="#", skiprows=1, ndmin=2)
    except ValueError as err:
        raise ScenarioError(scenario.path, "environment.table_file", f"{path.name}: {err}") from None
    if a.shape[1] != 4:
        raise ScenarioError(
            scenario.path, "environment.table_file", f"{path.name}: expected 4 columns, got {a.shape[1]}"
        )
    gas = {"mars": (MARS_CO2_GAS_CONSTANT, MARS_GAMMA, CO2_SUTHERLAND)}.get(
        body, (TITAN_N2_GAS_CONSTANT, TITAN_GAMMA, N2_SUTHERLAND)
    )
    try:
        return TabulatedAtmosphere(a[:, 0], a[:, 1], a[:, 2], a[:, 3], *gas, extrapolate="clamp")
    except ValueError as err:
        raise ScenarioError(scenario.path, "environment.table_file", f"{path.name}: {err}") from None


def vehicle(scenario: Scenario, cfg: Post2Config, ca_factor=1.0, cn_factor=1.0, cm_factor=1.0) -> Vehicle:
    """The :class:`Vehicle` of ``[vehicle]``: the asset (a shipped name under ``assets/vehicles`` or a
    path) with its capsule table, parachute and inertia mapped to the body frame B; without a file a
    point mass of ``mass_kg`` with no aerodynamics, or with a constant drag coefficient ``cd``."""
    v = cfg.data["vehicle"]
    if v["file"] is None:
        if v["mass_kg"] is None:
            raise ScenarioError(scenario.path, "vehicle.mass_kg", "needed when no vehicle file is given")
        return Vehicle(float(v["mass_kg"]), np.eye(3), None, None, v["ref_area_m2"], cd=v["cd"])
    name = v["file"]
    shipped = assets_dir() / "vehicles" / f"{name}.toml"
    path = shipped if shipped.is_file() else scenario.resolve(name)
    if not Path(path).is_file():
        raise ScenarioError(scenario.path, "vehicle.file", f"no shipped vehicle {name!r} and no file {path}")
    ev = load_vehicle(path)
    inertia_B = C_B_G @ np.asarray(ev.inertia_G) @ C_B_G.T
    mass = float(v["mass_kg"]) if v["mass_kg"] is not None else float(ev.mass_entry)
    drogue = None
    if v["drogue_area_m2"] is not None:  # Huygens-like: the second parachute, constant CD
        if not (v["drogue_area_m2"] > 0 and v["drogue_cd"] > 0):
            raise ScenarioError(scenario.path, "vehicle.drogue_area_m2", "drogue area and drogue_cd must be > 0")
        drogue = ParachuteTable("drogue", np.array([0.0, 10.0]), np.full(2, float(v["drogue_cd"])),
                                float(v["drogue_area_m2"]), 1.0)  # fmt: skip
    return Vehicle(
        mass, inertia_B, ev.capsule, ev.parachute, v["ref_area_m2"], ca_factor, cn_factor, cm_factor, drogue=drogue
    )


def events(cfg: Post2Config, truth: bool = False) -> tuple[Event, ...]:
    """The :class:`Event` list of ``[events.*]`` in file order (``truth``: with the truth's own triggers)."""
    return tuple(
        Event(
            e.name,
            e.truth_when if truth and e.truth_when else e.when,
            e.truth_value if truth and e.truth_when else e.value,
            e.mass,
            e.ref_area,
            e.parachute,
            e.chute,
        )  # fmt: skip
        for e in cfg.events
    )


def state_map(cfg: Post2Config) -> StateMap:
    """The estimator's :class:`StateMap`: dynamic states in :data:`STATE_ORDER`, then parameters."""
    names = [n for n in STATE_ORDER if cfg.state(n) is not None]
    names += [s.name for s in cfg.states if s.name not in STATE_ORDER]
    bounds = {s.name: s.bounds for s in cfg.states if s.bounds is not None}
    return StateMap(names, bounds)
