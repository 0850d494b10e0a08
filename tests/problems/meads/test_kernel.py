"""The compiled MEADS measurement function (:mod:`workbench.problems.meads.kernel`) against its numpy
reference path (``ekf.make_pressure_model(..., compiled=False)``): the same pressures and Jacobian
(and flow angles, Mach), both pressure models, states spread over the entry's flight conditions, a
subset of ports, and the table's edges."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.rotation import dcm_to_quat
from workbench.io.assets import asset_path
from workbench.models.flush_airdata import build_estimator_table, load_fads_vehicle
from workbench.problems.meads import ekf

VEHICLE = load_fads_vehicle(asset_path("vehicles", "msl_meads.toml"))
TABLE = build_estimator_table(VEHICLE)


def _rot(axis: int, ang: float) -> np.ndarray:
    c, s = math.cos(ang), math.sin(ang)
    R = np.eye(3)
    i, j = [k for k in range(3) if k != axis]
    R[i, i], R[i, j], R[j, i], R[j, j] = c, s, -s, c
    return R


def _states(n: int, seed: int = 5):
    """n states: altitudes 10–100 km, speeds 0.45–6 km/s (Mach ~2 to ~35 and beyond the table),
    α −5…35° (outside the table's 0–30° too), β ±6°, winds, attitude errors; with C_B_M (n, 3, 3)."""
    rng = np.random.default_rng(seed)
    atm = MarsEngineeringAtmosphere()
    X, C = [], []
    for _ in range(n):
        h = rng.uniform(10e3, 100e3)
        lat, lon = rng.uniform(-1.2, 1.2), rng.uniform(-3.0, 3.0)
        up = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
        p = (MARS.reference_radius + h) * up
        v = rng.uniform(450.0, 6000.0) * rng.normal(size=3) / math.sqrt(3.0)
        x = np.zeros(ekf.N_X)
        x[ekf.IP], x[ekf.IV] = p, v
        x[ekf.ITH] = rng.normal(0.0, 1e-3, 3)
        x[ekf.IW] = rng.normal(0.0, 20.0, 3)
        x[ekf.ILP] = math.log(atm.pressure(h)) + rng.normal(0.0, 0.1)
        x[ekf.ILR] = math.log(atm.density(h)) + rng.normal(0.0, 0.1)
        x[ekf.ILAM] = rng.normal(0.0, 0.01, 7)
        x[ekf.IC] = rng.normal(0.0, 0.01)
        # the model-error states, so that every column of H's assembly is exercised
        x[ekf.IB] = rng.normal(0.0, 0.01, 7)
        x[ekf.IBIAS] = rng.normal(0.0, 2.0, 7)
        x[ekf.IMM] = rng.normal(0.0, 0.01)
        x[ekf.IMA] = rng.normal(0.0, 0.01, 2)
        # body x axis near the air velocity, so that α, β are entry-like
        C0 = np.eye(3)
        d = v / np.linalg.norm(v)
        C0[0] = d
        C0[1] = np.cross([0.0, 0.0, 1.0], d)
        C0[1] /= np.linalg.norm(C0[1])
        C0[2] = np.cross(d, C0[1])
        Cb = _rot(1, -math.radians(rng.uniform(-5.0, 35.0))) @ _rot(2, math.radians(rng.uniform(-6.0, 6.0))) @ C0
        X.append(x)
        C.append(Cb)
    return np.array(X), np.array(C)


def _inputs(model: str) -> ekf.EkfInputs:
    n = 2
    z = np.zeros((n, 3))
    q = dcm_to_quat(np.broadcast_to(np.eye(3), (n, 3, 3)))
    return ekf.EkfInputs(
        np.arange(n, dtype=float), z, z, q, 1.0, 1.0, 1.0, np.zeros((n, 7)), np.ones((n, 7)),
        np.ones((n, 7), bool), VEHICLE, model, TABLE if model == "table" else None, 1.335,
    )  # fmt: skip


@pytest.mark.parametrize("model", ["table", "newtonian"])
def test_kernel_matches_the_numpy_reference(model):
    _check_kernel(model, None)


@pytest.mark.parametrize("model", ["table", "newtonian"])
def test_kernel_on_the_carried_states_matches_the_numpy_reference(model):
    """The first-order filter's 39 carried states (the columns after the dropped rates shift)."""
    keep = ekf.carried_states(SimpleNamespace(model_error_order=1))
    assert keep.size == ekf.N_X - 7
    _check_kernel(model, keep)


def _check_kernel(model, keep):
    X, C = _states(60)
    inp = _inputs(model)
    h_fast = ekf.make_pressure_model(inp, keep=keep)
    h_ref = ekf.make_pressure_model(inp, compiled=False, keep=keep)
    imm = ekf.IMM
    if keep is not None:
        X = X[:, keep]
        imm = int(np.searchsorted(keep, ekf.IMM))
    subsets = [np.arange(7), np.array([0, 2, 3, 6]), np.array([5])]
    worst_p = worst_H = worst_m = 0.0
    for i, (x, Cb) in enumerate(zip(X, C, strict=True)):
        # a strided C_B_M, as the filter passes it (a slice of swapped axes)
        Cs = np.swapaxes(np.ascontiguousarray(Cb.T), 0, 1)
        use = subsets[i % 3]
        p1, H1 = h_fast(x, Cs, use)
        p0, H0 = h_ref(x, Cb, use)
        assert p1.shape == p0.shape == (use.size,) and H1.shape == H0.shape == (use.size, X.shape[1])
        worst_p = max(worst_p, float(np.max(np.abs(p1 - p0) / np.abs(p0))))
        scale = np.abs(H0).max(axis=0) + 1e-300  # per state column
        dH = np.abs(H1 - H0)
        # the model Mach error's column is M ∂p/∂M = ∂p/∂ln ρ∞ − ∂p/∂ln p∞ − p + 2 p∞, a difference
        # of terms of the size of p: zero in exact arithmetic where the table is clamped below its
        # lowest Mach, so it is judged against the pressures (differencing noise ~1e-11 of p)
        worst_m = max(worst_m, float(np.max(dH[:, imm]) / np.abs(p0).max()))
        dH[:, imm] = 0.0
        worst_H = max(worst_H, float(np.max(dH / scale)))
    # the pressures to ~1e-14, but the Mach and flow-angle error terms x_m g_m + g_ab x_a multiply
    # central differences (eps_z of 1e-2 m/s, 1e-5): a last-place difference of the two paths'
    # pressures becomes ~1e-11 of p there
    assert worst_p < 1e-10
    # The Jacobian is central differences: a last-place difference (1e-16 of the value) becomes
    # 1e-16 |value| / (2 eps) in a column. The noisiest columns are position (1 m against
    # velocities of 5 km/s, through Ω × p and the local-vertical frame: ~1e-7 of the column) and
    # ln p∞ (the pressures change by 1e-5 of p∞, itself ~1e-3 of the pressures: ~1e-8); the
    # reference's own Jacobian carries the same noise.
    assert worst_H < 2e-6
    assert worst_m < 1e-9


def test_flow_kernel_matches_the_numpy_air_data():
    """The transition's flight-condition distance: α, β, Mach of one state, compiled vs numpy."""
    from workbench.problems.meads.kernel import flow_kernel

    X, C = _states(60, seed=9)
    for x, Cb in zip(X, C, strict=True):
        a, b, _, M, _, _ = ekf.air_data_of_state(x, Cb, 1.335)
        got = flow_kernel(x, Cb, MARS.rotation_rate, 1.335)
        np.testing.assert_allclose(got, (a, b, M), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("model", ["table", "newtonian"])
def test_kernel_at_a_lost_atmosphere_is_not_finite_as_the_reference(model):
    """A filter that lost the atmosphere (ln ρ∞ = −750: ρ∞ underflows to 0, so q∞ = 0 and M = 0)
    predicts non-finite pressures on both paths: the compiled kernel follows IEEE arithmetic as
    numpy does (no ZeroDivisionError), so the forward pass reports the same non-finite innovation
    at the same step."""
    X, C = _states(1)
    x = X[0].copy()
    x[ekf.ILR] = -750.0
    inp = _inputs(model)
    use = np.arange(7)
    with np.errstate(all="ignore"):
        p0, _ = ekf.make_pressure_model(inp, compiled=False)(x, C[0], use)
    p1, _ = ekf.make_pressure_model(inp)(x, C[0], use)
    assert not np.isfinite(p0).any()
    np.testing.assert_array_equal(np.isfinite(p1), np.isfinite(p0))
    # and what the pass says of such a state: the atmosphere, the temperature it implies, the biases
    note = ekf.divergence_note(x, SimpleNamespace(bias_sigma_pa=3.5))
    assert "ln ρ∞ = -750" in note and "K; Mars' atmosphere is ~100–300 K" in note and "σ of its prior" in note
