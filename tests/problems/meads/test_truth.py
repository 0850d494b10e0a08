"""MEADS truth simulator and sensors: an MSL-like entry, the error chain's switches, the files."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from workbench.io.assets import asset_path
from workbench.io.scenario import Scenario
from workbench.models.flush_airdata import incidence_cos, load_fads_vehicle, newtonian_pressure, pressure_ratio
from workbench.problems.meads.config import MeadsSettings
from workbench.problems.meads.sensors import measure_pressures
from workbench.problems.meads.truth import simulate_entry

VEHICLE = load_fads_vehicle(asset_path("vehicles", "msl_meads.toml"))


def _schema_defaults():
    """Settings of a scenario that sets nothing but its vehicle: every default of the schema."""
    data = {"scenario": {"name": "defaults", "kind": "meads"}, "vehicle": {"file": "../vehicles/msl_meads.toml"}}
    sc = Scenario(asset_path("scenarios", "msl_meads.toml"), "defaults", "meads", "", data)
    return MeadsSettings.from_scenario(sc)


DEFAULTS = _schema_defaults()
SPEC = DEFAULTS.truth


@pytest.fixture(scope="module")
def truth():
    return simulate_entry(VEHICLE, SPEC)


def test_msl_like_entry(truth):
    assert truth.h[0] == pytest.approx(125e3)
    assert np.linalg.norm(truth.v_M[0]) == pytest.approx(5845.0)
    assert 12e3 < truth.qbar.max() < 16e3  # the paper's Table 2: max q 14.0 kPa
    hyper = (truth.mach > 5) & (truth.t < truth.t_chute)
    assert 14.0 < np.degrees(truth.alpha[hyper]).min() and np.degrees(truth.alpha[hyper]).max() < 22.0
    crossings = np.flatnonzero(np.diff(np.sign(truth.fpa)) != 0)
    assert crossings.size == 2  # the flight-path angle crosses zero twice, as MSL's (paper Fig. 1c)
    i = np.searchsorted(truth.t, truth.t_chute)
    assert truth.mach[i] == pytest.approx(SPEC.chute_mach, abs=0.02)
    # the specific force is the aerodynamic force: |f| ~ q S C_D / m before the chute
    k = np.argmax(truth.qbar)
    assert np.linalg.norm(truth.f_B[k]) == pytest.approx(
        truth.qbar[k] * VEHICLE.ref_area * 1.65 / SPEC.mass_kg, rel=0.1
    )


def test_truth_pressures_differ_from_newtonian(truth):
    off = dataclasses.replace(
        DEFAULTS.pressure,
        location=False,
        time_tag=False,
        lag=False,
        transpiration="off",
        calibration=False,
        scale_factors=False,
        noise=False,
        quantization=False,
    )
    pm = measure_pressures(truth, VEHICLE, SPEC, off, np.random.default_rng(0))
    np.testing.assert_allclose(pm.p, np.clip(pm.p_surface, 0, VEHICLE.transducer_full_scale), rtol=1e-12)
    # model-form difference to the estimator's Newtonian model: percent level, not zero
    k = np.argmin(np.abs(pm.t - 80.0))
    M = np.interp(pm.t[k], truth.t, truth.mach)
    a, b = (np.interp(pm.t[k], truth.t, x) for x in (truth.alpha, truth.beta))
    q = np.interp(pm.t[k], truth.t, truth.qbar)
    R = pressure_ratio(M, 1.335)
    pt = 2 * q / (1.335 * R * M**2)
    newt = newtonian_pressure(pt, R, incidence_cos(a, b, VEHICLE.cone(), VEHICLE.clock()))
    rel = np.abs(pm.p[k] / newt - 1.0)
    assert 0.003 < rel.max() < 0.15


def test_each_error_source_changes_the_reading(truth):
    base = dict(
        location=False,
        time_tag=False,
        lag=False,
        transpiration="off",
        calibration=False,
        scale_factors=False,
        noise=False,
        quantization=False,
    )
    clean = measure_pressures(
        truth, VEHICLE, SPEC, dataclasses.replace(DEFAULTS.pressure, **base), np.random.default_rng(3)
    )
    for key, val in (
        ("location", True),
        ("lag", True),
        ("transpiration", "knudsen"),
        ("calibration", True),
        ("scale_factors", True),
        ("noise", True),
        ("quantization", True),
        ("time_tag", True),
    ):
        spec = dataclasses.replace(DEFAULTS.pressure, **{**base, key: val})
        pm = measure_pressures(truth, VEHICLE, SPEC, spec, np.random.default_rng(3))
        assert np.max(np.abs(pm.p - clean.p)) > 0.0, key
    fail = dataclasses.replace(DEFAULTS.pressure, failure_port="P5", failure_time_s=150.0, failure_mode="stuck")
    pm = measure_pressures(truth, VEHICLE, SPEC, fail, np.random.default_rng(3))
    after = pm.t >= 150.0
    assert np.all(pm.p[after, 4] == pm.p[np.argmax(after) - 1, 4]) and pm.failed_port == 4
    assert math.isclose(pm.p[np.argmax(after) + 40, 0], clean.p[np.argmax(after) + 40, 0], rel_tol=0.05)
