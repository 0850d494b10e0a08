"""Flush air data models: the MSL/MEADS vehicle file, the forebody check, Eq. 1-4, lag, transpiration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from workbench.core.atmosphere import CO2_SUTHERLAND, MARS_CO2_GAS_CONSTANT
from workbench.io.assets import asset_path
from workbench.io.scenario import ScenarioError
from workbench.models.flush_airdata import (
    VehicleFileError,
    build_estimator_table,
    incidence_cos,
    load_fads_vehicle,
    modified_newtonian_cp,
    newtonian_pressure,
    pressure_ratio,
    rm2_limit,
    second_order_tube,
    total_angles,
    transpiration_ratio,
)

VEHICLE = asset_path("vehicles", "msl_meads.toml")


def test_msl_layout_as_the_paper_describes():
    v = load_fads_vehicle(VEHICLE)
    assert v.port_names == ("P1", "P2", "P3", "P4", "P5", "P6", "P7")
    by = {p.name: p for p in v.ports}
    assert by["P4"].radius == 0.0 and by["P4"].cone == 0.0  # geometric centre
    for n in ("P3", "P4", "P5"):  # on the spherical cap
        assert by[n].radius <= v.tangency_radius
    for n in ("P6", "P7"):  # horizontal plane, ~1 m off the centreline
        assert abs(by[n].radius - 1.0) < 0.05 and abs(math.cos(by[n].clock)) < 1e-12
    for n in ("P1", "P2"):  # windward cone ray: faces the flow at alpha = 20 deg
        assert incidence_cos(math.radians(20.0), 0.0, by[n].cone, by[n].clock) == pytest.approx(1.0)


def _write(tmp_path, text):
    p = tmp_path / "veh.toml"
    p.write_text(VEHICLE.read_text().replace(*text))
    return p


def test_port_off_the_forebody_is_a_located_error(tmp_path):
    p = _write(
        tmp_path,
        ("radius_m = 1.00\ncone_deg = 20.0\nclock_deg = 90.0", "radius_m = 2.60\ncone_deg = 20.0\nclock_deg = 90.0"),
    )
    with pytest.raises(
        VehicleFileError,
        match=r"veh\.toml, key 'ports\[6\]\.radius_m': port 'P6': radius_m = 2.6 m is not on the forebody",
    ):
        load_fads_vehicle(p)
    p = _write(
        tmp_path,
        ("radius_m = 0.30\ncone_deg = 15.47\nclock_deg = 0.0", "radius_m = 0.30\ncone_deg = 20.0\nclock_deg = 0.0"),
    )
    with pytest.raises(
        VehicleFileError,
        match=r"'ports\[3\]\.cone_deg': port 'P3': cone_deg = 20.0 is not the forebody normal at radius_m = 0.3 m",
    ):
        load_fads_vehicle(p)


def test_unknown_key_names_file_key_and_the_nearest_valid_one(tmp_path):
    p = _write(tmp_path, ("tube_length_m = 0.10", "tube_lenght_m = 0.10"))
    with pytest.raises(ScenarioError) as info:
        load_fads_vehicle(p)
    err = info.value
    assert err.file == str(p) and err.key == "vehicle.tube_lenght_m"
    assert "flush-air-data vehicle asset" in str(err) and "did you mean 'tube_length_m'?" in str(err)
    p = _write(tmp_path, ('name = "P7"\nradius_m = 1.00', 'name = "P7"\nradius = 1.00'))
    with pytest.raises(ScenarioError, match=r"ports\[7\]\.radius.*did you mean 'radius_m'\?"):
        load_fads_vehicle(p)


def test_out_of_range_value_names_the_bound(tmp_path):
    p = _write(tmp_path, ("half_angle_deg = 70.0", "half_angle_deg = 95.0"))
    with pytest.raises(ScenarioError, match=r"vehicle\.half_angle_deg'.*95 deg is out of range: must be > 0, < 90 deg"):
        load_fads_vehicle(p)
    p = _write(tmp_path, ("tube_diameter_m = 0.00254", "tube_diameter_m = -0.00254"))
    with pytest.raises(ScenarioError, match=r"vehicle\.tube_diameter_m'.*must be > 0 m"):
        load_fads_vehicle(p)


def test_newtonian_relations():
    g = 1.335
    # Eq. 2 continuous at Mach 1, R M^2 tends to its limit
    assert pressure_ratio(1.0 - 1e-9, g) == pytest.approx(pressure_ratio(1.0 + 1e-9, g), rel=1e-6)
    assert pressure_ratio(60.0, g) * 3600 == pytest.approx(rm2_limit(g), rel=1e-3)
    # Eq. 1 at the stagnation point is p_t, at 90 deg incidence p_inf
    pt, R = np.array([[1000.0]]), pressure_ratio(np.array([[5.0]]), g)
    assert newtonian_pressure(pt, R, np.array([[1.0, 0.0]])) == pytest.approx(np.array([[1000.0, 1000.0 * R[0, 0]]]))
    # polar form of (alpha, beta) reproduces Eq. 3
    a, b = math.radians(18.0), math.radians(-3.0)
    at, pw = total_angles(a, b)
    c, k = 0.3, 1.1
    assert math.cos(at) * math.cos(c) + math.sin(at) * math.sin(c) * math.cos(k - pw) == pytest.approx(
        incidence_cos(a, b, c, k)
    )


def test_table_reproduces_its_model_at_the_nodes_and_between():
    v = load_fads_vehicle(VEHICLE)
    t = build_estimator_table(v)
    s = np.array([0.0, 0.3 / 2.25, 1.0 / 2.25])
    cone = v.surface_cone_angle(s * v.base_radius)
    m, a, c = 12.0, math.radians(17.0), math.radians(33.0)
    exact = modified_newtonian_cp(m, a, c, cone, s)
    assert np.max(np.abs(t.cp(m, a, c, s) - exact)) < 0.01 * np.max(exact)


def test_tube_lag_and_transpiration_orders_of_magnitude():
    v = load_fads_vehicle(VEHICLE)
    mu = CO2_SUTHERLAND.viscosity(250.0)
    wn, z = second_order_tube(
        1600.0, 250.0, v.tube_length, v.tube_diameter, v.transducer_volume, 1.335, MARS_CO2_GAS_CONSTANT, mu
    )
    delay = 2 * z / wn
    assert 1e-4 < delay < 1e-2  # the paper's Table 2: 0.1-2 ms
    visc = CO2_SUTHERLAND.viscosity
    hi = transpiration_ratio(20000.0, 1200.0, 300.0, v.tube_diameter, MARS_CO2_GAS_CONSTANT, visc, model="knudsen")
    lo = transpiration_ratio(1.0, 1200.0, 300.0, v.tube_diameter, MARS_CO2_GAS_CONSTANT, visc, model="knudsen")
    assert abs(hi - 1.0) < 1e-3  # continuum: no effect
    assert 0.5 < lo < 0.99  # rarefied: the cold transducer reads low, towards sqrt(300/1200)
    pot = transpiration_ratio(1.0, 1200.0, 300.0, v.tube_diameter, MARS_CO2_GAS_CONSTANT, visc, model="potter")
    assert 0.5 < pot < 0.99
