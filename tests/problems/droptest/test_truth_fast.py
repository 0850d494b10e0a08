"""The compiled (numba) truth kernels agree with the pure-numpy reference path of the truth.

Force model on random states covering every contact kind (lobes on the ramp, lobes on rocks, body
on the ramp, body on a rock, bungee uncut/cut), the state derivative, the sampled post-pass, the
release design's point-mass flight, and a short integrated contact phase (same DOP853 settings).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from workbench.problems.droptest import truth, truth_fast
from workbench.problems.droptest.lander import load_lander
from workbench.problems.droptest.surface import Surface
from workbench.problems.droptest.truth import BungeeRig, DropTestConfig, ForceModel, fly_reference

ROOT = Path(__file__).resolve().parents[3]
LANDER = ROOT / "assets" / "landers" / "mer_drop_lander.toml"
RTOL = 1e-11  # of each output's largest magnitude; measured worst ~3e-13


@pytest.fixture(scope="module")
def lander():
    return load_lander(LANDER)


def _ramp(rocks: bool) -> Surface:
    n = np.array([0.0, -np.sin(np.radians(60.0)), np.cos(np.radians(60.0))])
    if not rocks:
        return Surface(point=np.zeros(3), normal=n)
    rng = np.random.default_rng(7)
    t1 = np.cross(n, [1.0, 0.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    uv = rng.uniform(-1.5, 1.5, (40, 2))
    r = rng.uniform(0.1, 0.25, 40)
    c = uv[:, :1] * t1 + uv[:, 1:] * t2 + (0.3 * r)[:, None] * n  # partly embedded spheres
    return Surface(point=np.zeros(3), normal=n, rock_centers=c, rock_radii=r)


def _rig() -> BungeeRig:
    return BungeeRig(
        anchor_I=np.array([0.0, 12.0, -7.0]),
        rest_length=4.0,
        coeffs=(900.0, 60.0, -2.0),
        count=3.1,
        attach_B=np.array([0.0, 0.0, -0.45]),
        hammer_length=0.0,
    )


def _states(lander, surf: Surface, rng: np.random.Generator, k: int) -> np.ndarray:
    """Random states (k, 13) with the CM at heights from deep body contact to free flight."""
    out = np.empty((k, 13))
    lobe_reach = lander.lobe_radius + np.max(np.linalg.norm(lander.lobe_centers_B, axis=1))
    for i in range(k):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q) * rng.uniform(0.9, 1.1)  # not exactly unit: both normalise
        t1 = np.cross(surf.normal, [1.0, 0.0, 0.0])
        along = rng.uniform(-1.0, 1.0, 2)
        h = rng.uniform(0.2, 1.2 * lobe_reach)
        p = surf.point + h * surf.normal + along[0] * t1 + along[1] * np.array([1.0, 0.0, 0.0])
        out[i] = np.r_[p, rng.normal(0.0, 8.0, 3), q, rng.normal(0.0, 5.0, 3)]
    return out


def _assert_close(a, b):
    for x, y in zip(a, b, strict=True):
        x, y = np.atleast_1d(np.asarray(x, float)), np.atleast_1d(np.asarray(y, float))
        np.testing.assert_allclose(y, x, rtol=0.0, atol=RTOL * max(np.max(np.abs(x)), 1e-30))


@pytest.mark.parametrize("rocks", [False, True])
def test_evaluate_matches_reference_on_random_states(lander, rocks):
    surf = _ramp(rocks)
    model = ForceModel(lander, surf, _rig(), lander.pressure_pa)
    rng = np.random.default_rng(3 + rocks)
    seen = {"lobe": 0, "body": 0, "rock": 0}
    for y in _states(lander, surf, rng, 250):
        for cut in (False, True):
            model.cut = cut
            ref = model.evaluate(y)
            _assert_close(ref, model.evaluate_fast(y))
            seen["lobe"] += ref[4].max() > 0.0
            seen["body"] += ref[5] > 0.0
        if rocks:
            x = y[0:3] + truth.quat_rotate(y[6:10] / np.linalg.norm(y[6:10]), model.lobes_B)
            seen["rock"] += np.any(np.linalg.norm(x[:, None] - model.rock_c[None], axis=-1) < model.R + model.rock_r)
    assert seen["lobe"] > 50 and seen["body"] > 10, seen
    assert not rocks or seen["rock"] > 50, seen


def test_body_on_rock_matches_reference(lander):
    """A body vertex pushed into a rock (the rock-only body penalty) and the lobes wrapping it."""
    surf0 = _ramp(False)
    model0 = ForceModel(lander, surf0, _rig(), lander.pressure_pa)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    p = surf0.normal * 1.0
    v_world = model0.verts_B + p
    k = int(np.argmin(v_world @ surf0.normal))  # the vertex nearest the ramp
    c = v_world[k] - 0.04 * surf0.normal  # rock centre 4 cm inside, radius 0.1 m: vertex 6 cm deep
    surf = Surface(point=surf0.point, normal=surf0.normal, rock_centers=c[None], rock_radii=[0.1])
    model = ForceModel(lander, surf, _rig(), lander.pressure_pa)
    y = np.r_[p, 0.3, -2.0, -1.0, q, 0.5, -0.2, 0.1]
    ref = model.evaluate(y)
    assert ref[5] > 0.05
    _assert_close(ref, model.evaluate_fast(y))


def test_rhs_and_post_pass_match_reference(lander):
    surf = _ramp(True)
    model = ForceModel(lander, surf, _rig(), lander.pressure_pa)
    Y = _states(lander, surf, np.random.default_rng(11), 200)
    cut = np.arange(Y.shape[0]) % 2 == 0
    out = truth_fast.evaluate_many(Y, cut, *model.packed())
    for i, y in enumerate(Y):
        model.cut = bool(cut[i])
        ref = model.evaluate(y)
        _assert_close(ref, tuple(o[i] for o in out))
        f = model.rhs_fast()
        d_ref, d_fast = model.rhs(0.0, y), f(0.0, y)
        for sl in (slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 13)):
            scale = max(np.max(np.abs(d_ref[sl])), 1e-30)
            np.testing.assert_allclose(d_fast[sl], d_ref[sl], rtol=0.0, atol=RTOL * scale)


def test_constants_shared():
    assert truth_fast.V_SLIP == truth.V_SLIP
    assert np.array_equal(np.array([0.0, 0.0, -truth_fast.G0_MPS2]), truth.GRAVITY_SPF)


@pytest.mark.parametrize("count", [0.4, 2.5])
def test_fly_matches_reference(lander, count):
    surf = _ramp(False)
    cfg = DropTestConfig  # the truth's own constants (class defaults): rest length, polynomial, cut lead
    rig = BungeeRig(np.array([0.0, 12.0, -7.0]), cfg.bungee_rest_length, cfg.bungee_coeffs, count, np.zeros(3), 0.0)
    args = (lander.mass, surf.normal, surf.point, 0.9, cfg.cut_lead_s)
    p0 = np.array([0.0, -6.0, 9.0])
    p, v, t, cut = fly_reference(p0, rig, *args)
    coeffs = np.asarray(rig.coeffs, float)
    pf, vf, tf, cutf = truth_fast.fly(p0, rig.anchor_I, rig.rest_length, coeffs, count, *args, 1e-3, 6000)
    assert cut is not None and abs(cutf - cut) < 1e-12
    np.testing.assert_allclose(pf, p, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(vf, v, rtol=0.0, atol=1e-9)
    assert abs(tf - t) < 1e-12


@pytest.mark.parametrize("rocks", [False, True])
def test_integrated_contact_onset_matches_reference(lander, rocks):
    """The first 10 ms of airbag contact integrated both ways (the truth's DOP853 settings).

    Later in the contact phase the two paths drift apart at the size of the integrator's own
    truncation error (DOP853's step choices react to rounding; see truth_fast's module note), so
    the 1e-9 m bound is checked over the onset (measured: 5e-15 m on the bare ramp, 2e-10 m with
    rocks, whose contacts start at once)."""
    surf = _ramp(rocks)
    model = ForceModel(lander, surf, _rig(), lander.pressure_pa)
    model.cut = True
    q = np.array([0.05, -0.02, 0.01, 1.0])
    q /= np.linalg.norm(q)
    h = lander.lobe_radius - np.min(truth.quat_rotate(q, model.lobes_B) @ surf.normal)
    v = -12.0 * surf.normal + 16.0 * np.cross(surf.normal, [1.0, 0.0, 0.0]) + [0.3, 0.0, 0.0]  # down-slope
    vn = -(v @ surf.normal)
    p = surf.point + (h + 0.002 * vn) * surf.normal  # first touch 2 ms from the start
    y0 = np.r_[p, v, q, 0.4, -0.3, 0.2]
    opts = dict(method="DOP853", max_step=1e-3, rtol=1e-9, atol=1e-9)
    a = solve_ivp(model.rhs, (0.0, 0.012), y0, **opts)
    b = solve_ivp(model.rhs_fast(), (0.0, 0.012), y0, **opts)
    assert a.success and b.success
    assert np.max(model.evaluate(a.y[:, -1])[4]) > 0.05  # well into the contact
    assert np.max(np.abs(a.y[0:3, -1] - b.y[0:3, -1])) < 1e-9
    assert np.max(np.abs(a.y[3:6, -1] - b.y[3:6, -1])) < 1e-7


def test_simulate_drop_fast_is_default():
    """The compiled path is the default of both entry points (a keyword, no module switch)."""
    import inspect

    for fn in (truth.simulate_drop, truth.design_release):
        assert inspect.signature(fn).parameters["fast"].default is True
