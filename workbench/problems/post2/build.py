"""Build the model pieces a post2 run needs from its :class:`~workbench.problems.post2.config.Post2Settings`:
the environment (body, gravity, atmosphere), the vehicle (the entry vehicle's asset format, loaded by
:func:`workbench.models.aerodynamics.load_vehicle`), the events, and the estimator's state map.

Shared by the reconstruction and the truth simulator; the truth passes its own atmosphere
perturbation and coefficient factors (``truth.py``).
"""

from __future__ import annotations

import math

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
from workbench.io.scenario import ScenarioError
from workbench.models.aerodynamics import ParachuteTable
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.model import C_B_G, Environment, Event, StateMap, Vehicle

__all__ = ["STATE_ORDER", "environment", "vehicle", "events", "state_map"]

#: dynamic states first, in this order; parameters follow in problem-file order
STATE_ORDER = ("position", "velocity", "attitude", "body_rates")


def environment(cfg: Post2Settings, density_factor=None) -> Environment:
    """The :class:`Environment` of ``[environment]`` (SI); ``density_factor`` (truth only) multiplies ρ."""
    e = cfg.environment
    body = get_body(e.body)
    if e.atmosphere == "none":
        atm = None
    elif e.atmosphere == "exponential":
        atm = ExponentialAtmosphere(e.rho0_kg_m3, e.scale_height_m, e.temperature_K)
    elif e.atmosphere == "table" and e.table is not None:  # Huygens-like: the profile from a file
        atm = table_file_atmosphere(cfg)
    elif e.atmosphere == "table":
        cols = (e.table_altitude_m, e.table_density_kg_m3, e.table_pressure_pa, e.table_temperature_K)
        try:
            atm = TabulatedAtmosphere(*(np.asarray(c, dtype=float) for c in cols), extrapolate="clamp")
        except (TypeError, ValueError) as err:
            raise ScenarioError(cfg.run.path, "environment.table_altitude_m", f"bad atmosphere table: {err}") from None
    elif e.atmosphere == "earth_standard":
        atm = EarthStandardAtmosphere(e.sea_level_pressure_pa, e.sea_level_temperature_K)
    elif e.atmosphere == "mars_engineering":
        atm = MarsEngineeringAtmosphere()
    else:
        atm = TitanDefaultAtmosphere()
    return Environment(
        gm=e.gm_m3_s2 if e.gm_m3_s2 is not None else body.gm,
        radius_eq=e.equatorial_radius_m if e.equatorial_radius_m is not None else body.equatorial_radius,
        j2=e.j2 if e.j2 is not None else body.j2,
        radius_ref=e.reference_radius_m if e.reference_radius_m is not None else body.reference_radius,
        omega=e.rotation_rate_rad_s if e.rotation_rate_rad_s is not None else body.rotation_rate,
        atmosphere=atm,
        density_factor=density_factor,
        baro_anchor=e.baro_scale_anchor_m,
    )


def table_file_atmosphere(cfg: Post2Settings) -> TabulatedAtmosphere:
    """The ``[environment] table_file`` profile (read by the settings: altitude_m, density_kg_m3,
    pressure_pa, temperature_K) as a :class:`TabulatedAtmosphere` held constant outside, with the
    gas of the body (Titan N2, Mars CO2; Earth air as N2); a bad profile is a located error."""
    e = cfg.environment
    a = e.table
    gas = {"mars": (MARS_CO2_GAS_CONSTANT, MARS_GAMMA, CO2_SUTHERLAND)}.get(
        e.body, (TITAN_N2_GAS_CONSTANT, TITAN_GAMMA, N2_SUTHERLAND)
    )
    try:
        return TabulatedAtmosphere(a[:, 0], a[:, 1], a[:, 2], a[:, 3], *gas, extrapolate="clamp")
    except ValueError as err:
        raise ScenarioError(cfg.run.path, "environment.table_file", f"{e.table_file.name}: {err}") from None


def vehicle(cfg: Post2Settings, ca_factor=1.0, cn_factor=1.0, cm_factor=1.0) -> Vehicle:
    """The :class:`Vehicle` of ``[vehicle]``: the asset (loaded once by the settings) with its capsule
    table, parachute and inertia mapped to the body frame B; without a file a point mass of
    ``mass_kg`` with no aerodynamics, or with a constant drag coefficient ``cd``.  The factors
    (truth only) multiply the table's CA, CN, Cm."""
    v = cfg.vehicle
    if v.asset is None:
        return Vehicle(float(v.mass_kg), np.eye(3), None, None, v.ref_area_m2, cd=v.cd)
    ev = v.asset
    inertia_B = C_B_G @ np.asarray(ev.inertia_G) @ C_B_G.T
    mass = float(v.mass_kg) if v.mass_kg is not None else float(ev.mass_entry)
    drogue = None
    if v.drogue_area_m2 is not None:  # Huygens-like: the second parachute, constant CD
        drogue = ParachuteTable("drogue", np.array([0.0, 10.0]), np.full(2, float(v.drogue_cd)),
                                float(v.drogue_area_m2), 1.0)  # fmt: skip
    return Vehicle(
        mass, inertia_B, ev.capsule, ev.parachute, v.ref_area_m2, ca_factor, cn_factor, cm_factor, drogue=drogue
    )


def events(cfg: Post2Settings, truth: bool = False) -> tuple[Event, ...]:
    """The :class:`Event` list of ``[events.*]`` in file order (``truth``: with the truth's own triggers;
    an event read from the data (``detect_in``) needs ``truth_when`` for a synthetic truth)."""
    for e in cfg.events:
        if truth and not e.truth_when and not math.isfinite(e.value):
            raise ScenarioError(
                cfg.run.path, f"events.{e.name}.truth_when", "read from the data: the truth needs its own trigger"
            )
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


def state_map(cfg: Post2Settings) -> StateMap:
    """The estimator's :class:`StateMap`: dynamic states in :data:`STATE_ORDER`, then parameters."""
    names = [n for n in STATE_ORDER if cfg.state(n) is not None]
    names += [s.name for s in cfg.states if s.name not in STATE_ORDER]
    bounds = {s.name: s.bounds for s in cfg.states if s.bounds is not None}
    return StateMap(names, bounds)
