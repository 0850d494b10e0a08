"""MEADS least squares (Eq. 5-10), winds (Eq. 11-17), failed ports and bad input — fast unit tests."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from workbench.io.assets import asset_path
from workbench.io.scenario import Scenario
from workbench.io.telemetry import TelemetryError, write_telemetry
from workbench.models.flush_airdata import build_estimator_table, load_fads_vehicle
from workbench.problems.meads.airdata import fit_air_data, pressure_model, solve_winds
from workbench.problems.meads.config import MeadsSettings
from workbench.problems.meads.pipeline import detect_residual_failure, detect_stuck, reduce_pressures, sensor_sigma
from workbench.problems.meads.telemetry import InitialState, read_meads_telemetry, write_initial_state

VEHICLE = load_fads_vehicle(asset_path("vehicles", "msl_meads.toml"))


def _schema_defaults():
    """Settings of a scenario that sets nothing but its vehicle: every default of the schema."""
    data = {"scenario": {"name": "defaults", "kind": "meads"}, "vehicle": {"file": "../vehicles/msl_meads.toml"}}
    sc = Scenario(asset_path("scenarios", "msl_meads.toml"), "defaults", "meads", "", data)
    return MeadsSettings.from_scenario(sc)


DEFAULTS = _schema_defaults()
G = 1.335


def _states(n=40, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.uniform(900, 14000, n)
    a = np.radians(rng.uniform(12, 22, n))
    b = np.radians(rng.uniform(-2, 2, n))
    M = rng.uniform(2.2, 4.0, n)
    return np.stack([q, a, b, M], 1)


@pytest.mark.parametrize("model", ["newtonian", "table"])
def test_wls_recovers_the_state_of_its_own_model(model):
    x = _states()
    table = build_estimator_table(VEHICLE) if model == "table" else None
    p = pressure_model(VEHICLE, model, "mach", G, table)(x)
    sig = sensor_sigma(p, VEHICLE, 0.01)
    f = fit_air_data(
        p,
        sig,
        VEHICLE,
        model=model,
        solution="mach",
        gamma=G,
        mach_guess=x[:, 3] * 1.2,
        fixed_r=0.0,
        iterations=12,
        table=table,
    )
    np.testing.assert_allclose(f.alpha, x[:, 1], atol=1e-5)
    np.testing.assert_allclose(f.beta, x[:, 2], atol=1e-5)
    np.testing.assert_allclose(f.qbar, x[:, 0], rtol=1e-4)
    np.testing.assert_allclose(f.mach, x[:, 3], rtol=2e-3)
    # the vectorised fit is the per-sample fit
    one = fit_air_data(
        p[7:8],
        sig[7:8],
        VEHICLE,
        model=model,
        solution="mach",
        gamma=G,
        mach_guess=x[7:8, 3] * 1.2,
        fixed_r=0.0,
        iterations=12,
        table=table,
    )
    assert one.alpha[0] == pytest.approx(f.alpha[7], abs=1e-9)


def test_fixed_r_and_static_sets():
    x = _states(seed=1)
    x[:, 3] = 25.0  # hypersonic: R M^2 at its limit, R ~ 0.001
    p = pressure_model(VEHICLE, "newtonian", "mach", G)(x)
    sig = sensor_sigma(p, VEHICLE, 0.01)
    f = fit_air_data(
        p,
        sig,
        VEHICLE,
        model="newtonian",
        solution="fixed_r",
        gamma=G,
        mach_guess=np.full(40, 25.0),
        fixed_r=0.0,
        iterations=12,
    )
    np.testing.assert_allclose(f.alpha, x[:, 1], atol=1e-6)
    np.testing.assert_allclose(f.qbar, x[:, 0], rtol=1e-6)  # R scheduled at the true Mach: exact
    c = fit_air_data(
        p,
        sig,
        VEHICLE,
        model="newtonian",
        solution="fixed_r",
        gamma=G,
        mach_guess=np.full(40, 25.0),
        fixed_r=0.001,
        iterations=12,
    )
    assert np.max(np.abs(c.qbar / x[:, 0] - 1)) < 0.01  # constant R = 0.001: biased, but little at Mach 25
    assert np.all(np.isnan(c.sigma_mach))  # Mach is not estimated by the fixed-R set
    x[:, 3] = 3.0
    p = pressure_model(VEHICLE, "newtonian", "mach", G)(x)
    s = fit_air_data(
        p,
        sensor_sigma(p, VEHICLE, 0.01),
        VEHICLE,
        model="newtonian",
        solution="static",
        gamma=G,
        mach_guess=np.full(40, 4.0),
        fixed_r=0.0,
        iterations=12,
    )
    np.testing.assert_allclose(s.mach, 3.0, rtol=1e-3)


def _wind_case(fpa_deg, wind=(12.0, -7.0), n=5):
    g = math.radians(fpa_deg)
    V = 900.0
    v_N = np.tile([V * math.cos(g) * 0.6, V * math.cos(g) * 0.8, -V * math.sin(g)], (n, 1))
    rel = v_N - np.array([wind[0], wind[1], 0.0])
    # body: x along -(...) rotated so alpha ~ 18 deg, beta ~ 1 deg
    e = rel[0] / np.linalg.norm(rel[0])
    up = np.array([0.0, 0.0, -1.0])
    z = up - (up @ e) * e
    z /= np.linalg.norm(z)
    y = np.cross(z, e)
    a, b = math.radians(18.0), math.radians(1.0)
    C_B_W = np.array(
        [
            [math.cos(a) * math.cos(b), -math.cos(a) * math.sin(b), -math.sin(a)],
            [math.sin(b), math.cos(b), 0.0],
            [math.sin(a) * math.cos(b), -math.sin(a) * math.sin(b), math.cos(a)],
        ]
    )
    C_B_N = np.tile(C_B_W @ np.stack([e, y, z]), (n, 1, 1))
    u = C_B_N[0] @ rel[0]
    al, be = math.atan2(u[2], u[0]), math.asin(u[1] / np.linalg.norm(u))
    P = np.tile(np.diag([1e-6, 1e-6]), (n, 1, 1))
    return solve_winds(np.full(n, al), np.full(n, be), P, v_N, C_B_N, np.tile(np.eye(6) * 1e-4, (n, 1, 1)), det_min=0.1)


def test_winds_by_newton_and_the_zero_flight_path_singularity():
    w = _wind_case(-20.0)
    np.testing.assert_allclose(w.wind_NE, np.tile([12.0, -7.0], (5, 1)), atol=1e-3)
    assert not w.singular.any()
    s = _wind_case(0.0)
    assert s.singular.all() and np.all(np.isnan(s.wind_NE))  # detected and not published


def test_stuck_and_residual_failures_are_found():
    x = _states(n=200, seed=3)
    x[:, 0] = np.linspace(12000, 2000, 200)
    x[:, 3] = 20.0
    p = pressure_model(VEHICLE, "newtonian", "mach", G)(x)
    rng = np.random.default_rng(0)
    p *= 1 + 0.002 * rng.standard_normal(p.shape)
    t = np.arange(200) / 8.0
    est = dataclasses.replace(DEFAULTS.estimator, solution="fixed_r", switch_mach=3.0)
    bad = p.copy()
    bad[120:, 3] *= 1.12  # P4 reads 12 % high from sample 120 (a P5-P7 offset is partly absorbed by α, β)
    fit, _ = reduce_pressures(t, bad, VEHICLE, x[:, 3], est)
    f = detect_residual_failure(fit, t, list(VEHICLE.port_names), np.ones_like(p, bool), 6.0, 4)
    assert f is not None and f.port == "P4" and 118 <= f.k <= 125
    stuck = p.copy()
    stuck[90:, 2] = stuck[89, 2]
    s = detect_stuck(t, stuck, list(VEHICLE.port_names), VEHICLE)
    assert [(x.port, x.k) for x in s] == [("P3", 89)]


def _files(tmp_path, cols=None, values=None):
    t = np.arange(20) / 8.0
    ports = VEHICLE.port_names if cols is None else cols
    p = np.full((20, len(ports)), 5000.0) if values is None else values
    write_telemetry(tmp_path / "pressures.csv", t, {n: (p[:, j], "Pa") for j, n in enumerate(ports)}, sparse=ports)
    ti = np.arange(50) / 20.0
    z = np.zeros(50)
    write_telemetry(
        tmp_path / "imu.csv",
        ti,
        {**{c: (z, "m/s^2") for c in ("f_x", "f_y", "f_z")}, **{c: (z, "deg/s") for c in ("w_x", "w_y", "w_z")}},
    )
    write_initial_state(
        tmp_path / "initial_state.toml",
        InitialState(
            0.0, np.array([3.5e6, 0, 0]), np.array([0, 5800.0, 0]), np.array([0, 0, 0, 1.0]), 100.0, 0.1, 0.001
        ),
    )
    return {
        k: tmp_path / f"{k}.{'toml' if k == 'initial_state' else 'csv'}" for k in ("pressures", "imu", "initial_state")
    }


def test_bad_pressure_files_are_located(tmp_path):
    paths = _files(tmp_path, cols=("P1", "P2", "P3", "P4", "P5", "P7"))
    with pytest.raises(TelemetryError, match=r"pressures.csv.*P6"):
        read_meads_telemetry(paths, VEHICLE)
    paths = _files(tmp_path)
    text = paths["pressures"].read_text().splitlines()
    hdr = next(i for i, ln in enumerate(text) if ln.startswith("time"))
    text[hdr + 5] = text[hdr + 5].replace(",5000,", ",nan,", 1)  # a NaN written into the file
    paths["pressures"].write_text("\n".join(text) + "\n")
    with pytest.raises(TelemetryError, match=r"pressures.csv.*row 5"):
        read_meads_telemetry(paths, VEHICLE)
    v = np.full((20, 7), 5000.0)
    v[6:10, 3] = np.nan  # a dropout burst (empty cells): a logged degradation, not an error
    tel = read_meads_telemetry(_files(tmp_path, values=v), VEHICLE)
    assert len(tel.degradations) == 1 and "'P4 [Pa]', rows 7-10" in tel.degradations[0]
