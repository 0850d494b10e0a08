"""The compiled (numba) MEADS truth right-hand side agrees with the Python reference of the truth.

The derivative and the parachute event's Mach at random states in both phases (lift and bank
before the parachute, its inflating drag after, the opening instant itself) agree to rounding (bit
for bit where BLAS rounds its 3-vector dot products as the compiled path does, as on the
development machine); a whole entry agrees at least to DOP853's reaction to that rounding, far
below the sensor errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from workbench.io.assets import asset_path
from workbench.io.scenario import Scenario
from workbench.models.flush_airdata import load_fads_vehicle
from workbench.problems.meads import truth_fast as tf
from workbench.problems.meads.config import MeadsSettings
from workbench.problems.meads.truth import TruthDynamics, entry_state, simulate_entry

VEHICLE = load_fads_vehicle(asset_path("vehicles", "msl_meads.toml"))


def _spec():
    """The truth of a scenario that sets nothing but its vehicle: the schema's MSL-like entry."""
    data = {"scenario": {"name": "defaults", "kind": "meads"}, "vehicle": {"file": "../vehicles/msl_meads.toml"}}
    sc = Scenario(asset_path("scenarios", "msl_meads.toml"), "defaults", "meads", "", data)
    return MeadsSettings.from_scenario(sc).truth


SPEC = _spec()


def _reference(dyn: TruthDynamics, t: float, y: np.ndarray) -> np.ndarray:
    return np.concatenate([y[3:], dyn.accel(t, y[:3], y[3:])[0]])


@pytest.mark.parametrize("t_chute", [None, 150.0])
def test_derivative_and_mach_agree_to_rounding(t_chute):
    dyn = TruthDynamics(VEHICLE, SPEC)
    dyn.t_chute = t_chute
    args = dyn.packed()
    p0, v0 = entry_state(SPEC)
    rng = np.random.default_rng(7)
    times = list(rng.uniform(0.0, 300.0, 400)) + ([t_chute, t_chute + 0.5] if t_chute else [])
    for t in times:
        y = np.r_[p0 * (1.0 - rng.uniform(0.0, 0.03)), v0 * rng.uniform(0.05, 1.0)] + rng.normal(0.0, 100.0, 6)
        ref, fast = _reference(dyn, t, y), tf.rhs(t, y, *args)
        np.testing.assert_allclose(fast[:3], ref[:3], rtol=0.0, atol=0.0)
        np.testing.assert_allclose(fast[3:], ref[3:], rtol=0.0, atol=1e-13 * np.linalg.norm(ref[3:]))
        _, _, T, v_air, _ = dyn.air(t, y[:3], y[3:])
        m_ref = math.sqrt(v_air @ v_air) / math.sqrt(SPEC.gamma * dyn.R * T)
        assert tf.mach(t, y, *args[:7]) == pytest.approx(m_ref, rel=1e-14)


def test_whole_entry_agrees_with_the_reference():
    ref, fast = simulate_entry(VEHICLE, SPEC, fast=False), simulate_entry(VEHICLE, SPEC)
    assert fast.t.size == ref.t.size
    assert fast.t_chute == pytest.approx(ref.t_chute, abs=1e-5)
    for key in ("p_M", "v_M", "q_M_B", "f_B", "alpha", "beta", "mach", "qbar", "rho", "p_inf"):
        a, b = getattr(fast, key), getattr(ref, key)
        # DOP853's step control reacts to the rounding: agreement to its tolerance, not bit for bit
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-6 * np.max(np.abs(b)), err_msg=key)
