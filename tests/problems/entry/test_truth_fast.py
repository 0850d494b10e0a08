"""The compiled (numba) entry truth kernels agree with the scalar Python reference path of the truth.

Short spans of every branch of the model: the entry in vacuum and with aerodynamics (a time
limit), a parachute deployment by Mach and one by time with the front-shield release, the
riser, breathing and side force; every stored sample's state and auxiliary outputs compared.  Both
paths perform the same operations in the same order, so the tolerance is rounding-level (in
practice they agree bit for bit).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from workbench.models.aerodynamics import load_vehicle
from workbench.problems.entry.truth import EntryTruthSpec, simulate_entry

ROOT = Path(__file__).resolve().parents[3]
VEHICLE = ROOT / "assets" / "vehicles" / "schiaparelli.toml"
RTOL = 1e-12  # of each output's largest magnitude

_FIELDS = (
    "p_M",
    "v_M",
    "q_M_G",
    "w_G",
    "f_G",
    "mach",
    "knudsen",
    "alpha_total",
    "dynamic_pressure",
    "h_amr",
    "v_rel_M",
    "wind_NE",
    "riser_tension",
    "parachute_area",
    "ca_factor",
    "chute_cd_factor",
)


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(VEHICLE)


def _assert_close(x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    assert x.shape == y.shape
    np.testing.assert_allclose(y, x, rtol=0.0, atol=RTOL * max(float(np.nanmax(np.abs(x))), 1e-300))


def _both(vehicle, spec):
    fast = simulate_entry(vehicle, spec, np.random.default_rng(3), fast=True)
    ref = simulate_entry(vehicle, spec, np.random.default_rng(3), fast=False)
    assert fast.events.keys() == ref.events.keys()
    for k, v in ref.events.items():
        assert fast.events[k] == v or (np.isnan(v) and np.isnan(fast.events[k]))
    np.testing.assert_array_equal(fast.t, ref.t)
    np.testing.assert_array_equal(fast.phase, ref.phase)
    for nm in _FIELDS:
        _assert_close(getattr(ref, nm), getattr(fast, nm))
    if ref.parachute_p_M is None:
        assert fast.parachute_p_M is None
    else:
        np.testing.assert_array_equal(np.isnan(fast.parachute_p_M), np.isnan(ref.parachute_p_M))
        _assert_close(np.nan_to_num(ref.parachute_p_M), np.nan_to_num(fast.parachute_p_M))
    return fast, ref


@pytest.mark.parametrize("aero", [False, True])
def test_entry_span_matches_reference(vehicle, aero):
    spec = dataclasses.replace(EntryTruthSpec(), aero_enabled=aero, t_end=-10.0)
    fast, _ = _both(vehicle, spec)
    assert fast.t.size == 501 and np.all(fast.phase == 0)


def test_deployment_by_mach_matches_reference(vehicle):
    # PDD at the first sample after EIP (Mach < 40 there), FSR 0.6 s and BSR 1.2 s later
    spec = dataclasses.replace(EntryTruthSpec(), pdd_mach=40.0, fsr_delay_s=0.6, bsr_delay_s=0.6)
    fast, _ = _both(vehicle, spec)
    assert fast.events["PDD"] == pytest.approx(0.01) and fast.events["BSR"] == pytest.approx(1.21)
    assert set(np.unique(fast.phase)) == {0, 1, 2}
    assert np.max(fast.riser_tension) > 0.0


def test_deployment_by_time_with_side_force_matches_reference(vehicle):
    # the canopy inflates, breathes and takes the side force (0.55-1.65 s after PDD) within the span
    spec = dataclasses.replace(EntryTruthSpec(), pdd_time_s=-14.0, fsr_delay_s=1.0, bsr_delay_s=0.9)
    fast, _ = _both(vehicle, spec)
    assert fast.events["PDD"] == pytest.approx(-14.0) and np.max(fast.parachute_area) > 0.0
    assert set(np.unique(fast.phase)) == {0, 1, 2}
