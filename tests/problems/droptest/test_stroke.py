"""Tests of workbench.problems.droptest.surface and workbench.problems.droptest.stroke against hand-derived values."""

import numpy as np
import pytest

from workbench.core.rotation import (
    quat_boxplus,
    quat_from_axis_angle,
    quat_identity,
    quat_multiply,
    quat_rotate,
)
from workbench.problems.droptest.lander import tetrahedron_body
from workbench.problems.droptest.stroke import max_stroke, restitution, sampled_stroke_sigma, stroke_history
from workbench.problems.droptest.surface import Surface, ramp_mesh, ramp_surface, rock_field, rock_meshes

BODY = tetrahedron_body(1.2, 1.6, 0.4)  # apex 0.8 m above the CM, base 0.4 m below
V = BODY.vertices
F = BODY.faces
S60, C60 = np.sin(np.pi / 3), np.cos(np.pi / 3)
FLAT = Surface(point=[0.0, 0.0, 0.0], normal=[0.0, 0.0, 1.0])


def _q_x(deg):
    return quat_from_axis_angle([1.0, 0.0, 0.0], np.deg2rad(deg))


# --------------------------------------------------------------------------- surface


def test_ramp_surface_frame():
    s = ramp_surface(60.0, 0.3)
    assert np.allclose(s.normal, [0.0, -S60, C60])
    # the nail (origin) is 0.3 m behind the ramp face
    d, g, f = s.distance(np.zeros(3))
    assert d == pytest.approx(-0.3) and f == -1 and np.allclose(g, s.normal)
    # hand: (0,0,1): n.x - 0.3 = 0.5 - 0.3; (0,-1,0): 0.866 - 0.3; X lies in the plane
    d, _, _ = s.distance(np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [5.0, 0.0, 0.0]]))
    assert np.allclose(d, [0.2, S60 - 0.3, -0.3])
    # the ramp rises toward +Y: moving up-slope (0, cos60, sin60) keeps the distance
    d2, _, _ = ramp_surface(60.0, 0.3).distance(np.array([0.0, C60, S60]) * 4.0)
    assert d2 == pytest.approx(-0.3)


def test_surface_distance_with_rock_hand_values():
    s = Surface(point=[0, 0, 0], normal=[0, 0, 2.0], rock_centers=[[0, 0, 0.1]], rock_radii=[0.2])
    pts = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, 0.1], [0.3, 0.0, 0.5], [0.0, 0.0, 0.2]])
    d, g, f = s.distance(pts)
    # (0,0,1): rock 0.9-0.2=0.7 < plane 1; (0.5,0,0.1): plane 0.1 < rock 0.3;
    # (0.3,0,0.5): rock |(0.3,0,0.4)|-0.2 = 0.3 < plane 0.5; (0,0,0.2): inside the rock, -0.1
    assert np.allclose(d, [0.7, 0.1, 0.3, -0.1])
    assert np.array_equal(f, [0, -1, 0, 0])
    assert np.allclose(g, [[0, 0, 1], [0, 0, 1], [0.6, 0, 0.8], [0, 0, 1]])
    assert d.shape == (4,) and s.distance(pts.reshape(2, 2, 3))[0].shape == (2, 2)


def test_surface_gradient_finite_differences():
    rng = np.random.default_rng(1)
    s = rock_field(ramp_surface(60.0, 0.3), rng, ((-2.0, 2.0), (-2.0, 2.0)), 1.0)
    t1, t2 = s.tangent_basis()
    u = rng.uniform(-2, 2, (200, 2))
    x = s.point + u[:, :1] * t1 + u[:, 1:] * t2 + rng.uniform(0.05, 0.6, (200, 1)) * s.normal
    d, g, f = s.distance(x)
    assert np.any(f >= 0) and np.any(f == -1)
    h = 1e-6
    fd = np.stack([(s.distance(x + h * e)[0] - s.distance(x - h * e)[0]) / (2 * h) for e in np.eye(3)], -1)
    # exclude points within 1e-5 m of a plane/rock switch (the distance has a kink there)
    ok = np.ones(len(x), bool)
    for e in np.eye(3):
        ok &= s.distance(x + h * e)[2] == f
        ok &= s.distance(x - h * e)[2] == f
    assert ok.sum() > 150
    assert np.allclose(fd[ok], g[ok], atol=1e-6)


def test_rock_field_layout():
    rng = np.random.default_rng(7)
    s = rock_field(ramp_surface(60.0, 0.3), rng, ((-3.0, 3.0), (-3.0, 3.0)), 1.0)
    assert s.n_rocks == 49
    assert np.all((s.rock_radii >= 0.1) & (s.rock_radii <= 0.25))  # sizes 0.2-0.5 m = diameters
    h = (s.rock_centers - s.point) @ s.normal
    assert np.allclose(h, 0.5 * s.rock_radii)  # centres half a radius above the ramp
    c = s.rock_centers
    nn = np.sort(np.linalg.norm(c[:, None] - c[None], axis=-1), axis=1)[:, 1]
    assert nn.min() >= 0.6 - 1e-9 and 0.8 < nn.mean() < 1.2  # "approximately one meter apart"
    slab = ramp_mesh(s, 8.0, 4.0, 6.0)
    assert slab.is_watertight
    top = slab.vertices[np.isclose((slab.vertices - s.point) @ s.normal, 0.0)]
    assert top.shape[0] == 4
    assert len(rock_meshes(s, subdivisions=0).vertices) == 49 * 12


def test_surface_distance_in_blocks_equals_whole(monkeypatch):
    """A long batch of points against a rock field is evaluated in blocks (bounded memory): the
    same distances, gradients and features, bit for bit, as one evaluation."""
    from workbench.problems.droptest import surface as sf

    s = rock_field(ramp_surface(60.0, 0.3), np.random.default_rng(7), ((-3.0, 3.0), (-3.0, 3.0)), 1.0)
    x = s.point + np.random.default_rng(3).normal(scale=2.0, size=(1201, 5, 3))
    monkeypatch.setattr(sf, "ROCK_BLOCK_ELEMENTS", 49 * 100)  # 100 points a block: 61 blocks
    blocks = s.distance(x)
    monkeypatch.setattr(sf, "ROCK_BLOCK_ELEMENTS", 10**12)
    whole = s.distance(x)
    assert [a.shape for a in blocks] == [(1201, 5), (1201, 5, 3), (1201, 5)]
    assert all(np.array_equal(a, b) for a, b in zip(blocks, whole, strict=True))
    assert np.any(whole[2] >= 0)  # some points are nearest a rock


# --------------------------------------------------------------------------- stroke distance


def _pose_base_parallel(h, along=(0.3, -0.7)):
    """CM at height h above the ramp with the base face parallel to it (body +Z = ramp normal)."""
    s = ramp_surface(60.0, 0.3)
    t1, t2 = s.tangent_basis()
    p = s.point + h * s.normal + along[0] * t1 + along[1] * t2
    return s, p, _q_x(60.0)


def test_stroke_base_parallel_to_ramp():
    s, p, q = _pose_base_parallel(1.0)
    hist = stroke_history(V, p[None], q[None], np.zeros((1, 6, 6)), s, faces_B=F)
    assert hist.distance[0] == pytest.approx(1.0 - 0.4)  # h - cm_height
    assert hist.vertex[0] in (0, 1, 2)  # a base vertex
    assert hist.feature[0] == -1
    assert np.allclose(hist.surface_point_I[0], hist.closest_point_I[0] - 0.6 * s.normal)
    assert s.distance(hist.surface_point_I[0])[0] == pytest.approx(0.0, abs=1e-12)


def test_stroke_apex_down_penetrating():
    # apex toward the ramp: body +Z = -n, i.e. R_x(60°) ⊗ R_x(180°); closest = apex, distance h - 0.8
    s = ramp_surface(60.0, 0.3)
    q = quat_multiply(_q_x(60.0), _q_x(180.0))
    hs = np.array([1.5, 0.8, 0.7])
    p = s.point + hs[:, None] * s.normal
    hist = stroke_history(V, p, np.tile(q, (3, 1)), np.zeros((3, 6, 6)), s)
    assert np.allclose(hist.distance, hs - 0.8)
    assert np.array_equal(hist.vertex, [3, 3, 3])
    assert np.allclose(hist.closest_point_I[2], p[2] - 0.8 * s.normal)


def test_stroke_rock_under_base_face_exact():
    # identity attitude, CM at z=2 (base at z=1.6); rock centre (0,0,1.0) r=0.3 under the base middle:
    # exact = 1.6 - 1.0 - 0.3 = 0.3 at (0,0,1.6); vertex-only = |(0.92376, 0, 0.6)| - 0.3 = 0.80153
    s = Surface(point=[0, 0, 0], normal=[0, 0, 1], rock_centers=[[0, 0, 1.0]], rock_radii=[0.3])
    p = np.array([[0.0, 0.0, 2.0]])
    q = quat_identity((1,))
    exact = stroke_history(V, p, q, np.zeros((1, 6, 6)), s, faces_B=F)
    assert exact.distance[0] == pytest.approx(0.3)
    assert exact.feature[0] == 0
    assert np.allclose(exact.closest_point_I[0], [0, 0, 1.6])
    assert np.allclose(exact.surface_point_I[0], [0, 0, 1.3])
    assert np.allclose(exact.jacobian[0, :3], [0, 0, 1])
    vert_only = stroke_history(V, p, q, np.zeros((1, 6, 6)), s)
    assert vert_only.distance[0] == pytest.approx(np.hypot(1.6 / np.sqrt(3), 0.6) - 0.3)
    # rock centre inside the body, 0.1 m above the base face (the nearest face): -0.1 - r
    s_in = Surface(point=[0, 0, 0], normal=[0, 0, 1], rock_centers=[[0, 0, 1.7]], rock_radii=[0.05])
    inside = stroke_history(V, p, q, np.zeros((1, 6, 6)), s_in, faces_B=F)
    assert inside.distance[0] == pytest.approx(-0.15)


def _poses_over_rock_field(seed: int, n: int):
    """A rock field on the ramp and n random poses 0.9-1.3 m above it, tilted around 60° about x."""
    rng = np.random.default_rng(seed)
    s = rock_field(ramp_surface(60.0, 0.3), rng, ((-3.0, 3.0), (-3.0, 3.0)), 1.0, size_range=(0.4, 0.5))
    t1, t2 = s.tangent_basis()
    u = rng.uniform(-2, 2, (n, 2))
    p = s.point + u[:, :1] * t1 + u[:, 1:] * t2 + rng.uniform(0.9, 1.3, (n, 1)) * s.normal
    q = quat_boxplus(np.tile(_q_x(60.0), (n, 1)), rng.normal(0, 0.3, (n, 3)))
    return s, p, q


def test_stroke_exact_vs_dense_sampling_in_rock_field():
    n = 30
    s, p, q = _poses_over_rock_field(3, n)
    hist = stroke_history(V, p, q, np.zeros((n, 6, 6)), s, faces_B=F)
    pts_B = np.concatenate([V, BODY.sample(20000, seed=5)])
    brute = np.array([s.distance(p[i] + quat_rotate(q[i], pts_B))[0].min() for i in range(n)])
    assert np.all(brute >= hist.distance - 1e-9)
    assert np.max(brute - hist.distance) < 0.01
    assert np.any(hist.feature >= 0)  # some poses are closest to a rock
    # without faces: the vertex minimum of Surface.distance, an upper bound of the exact distance
    vert = stroke_history(V, p, q, np.zeros((n, 6, 6)), s)
    X = p[:, None] + quat_rotate(q[:, None], V[None])
    dv, _, fv = s.distance(X)
    assert np.allclose(vert.distance, dv.min(axis=1))
    assert np.array_equal(vert.feature, fv[np.arange(n), vert.vertex])
    assert np.all(vert.distance >= hist.distance - 1e-12)


def test_stroke_history_chunked_equal_whole(monkeypatch):
    """Poses and (pose, rock) pairs are examined in chunks (bounded memory): identical numbers for
    any chunk size, in a rock field where many poses approach a rock."""
    import workbench.problems.droptest.stroke as stroke

    n = 57
    s, p, q = _poses_over_rock_field(8, n)
    P = np.tile(np.diag([1e-4] * 3 + [1e-3] * 3), (n, 1, 1))
    ref = stroke_history(V, p, q, P, s, faces_B=F)
    assert np.any(ref.feature >= 0)
    for pose_chunk, pair_chunk in ((1, 4), (10, 33), (4096, 65536)):
        monkeypatch.setattr(stroke, "_POSE_CHUNK", pose_chunk)
        monkeypatch.setattr(stroke, "_PAIR_FACE_CHUNK", pair_chunk)
        h = stroke_history(V, p, q, P, s, faces_B=F)
        for f in ("distance", "sigma", "vertex", "closest_point_I", "surface_point_I", "feature", "jacobian"):
            np.testing.assert_array_equal(getattr(h, f), getattr(ref, f), err_msg=f)


def _generic_case(with_rock):
    s = ramp_surface(60.0, 0.3)
    if with_rock:  # a rock facing the middle of the side_PY face
        s = Surface(s.point, s.normal, rock_centers=[[0.2, -1.2, 0.2]], rock_radii=[0.3])
    p = np.array([0.1, -1.0, 1.3])
    q = quat_boxplus(_q_x(60.0), np.array([0.35, -0.2, 0.5]))
    return s, p, q


@pytest.mark.parametrize("with_rock", [False, True])
def test_jacobian_finite_differences(with_rock):
    s, p, q = _generic_case(with_rock)
    hist = stroke_history(V, p[None], q[None], np.zeros((1, 6, 6)), s, faces_B=F)
    if with_rock:  # closest to the rock, at a point inside a face (0.29 m from every vertex)
        assert hist.feature[0] == 0
        X = p + quat_rotate(q, V)
        assert np.linalg.norm(X - hist.closest_point_I[0], axis=1).min() > 0.1
    h = 1e-6
    fd = np.zeros(6)
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        dp = stroke_history(V, (p + e[:3])[None], quat_boxplus(q, e[3:])[None], np.zeros((1, 6, 6)), s, F)
        dm = stroke_history(V, (p - e[:3])[None], quat_boxplus(q, -e[3:])[None], np.zeros((1, 6, 6)), s, F)
        fd[k] = (dp.distance[0] - dm.distance[0]) / (2 * h)
    assert np.allclose(hist.jacobian[0], fd, atol=1e-6)
    assert np.linalg.norm(hist.jacobian[0, 3:]) > 0.1  # attitude matters: the check has teeth


@pytest.mark.parametrize("with_rock", [False, True])
def test_linearised_sigma_vs_sampled(with_rock):
    s, p, q = _generic_case(with_rock)
    A = np.diag([0.02, 0.03, 0.015, 0.01, 0.015, 0.02])  # 2-3 cm, ~0.6-1.1 deg
    A[0, 4] = A[2, 3] = 0.008  # some correlation
    P = (A @ A.T)[None]
    hist = stroke_history(V, p[None], q[None], P, s, faces_B=F)
    mean, std = sampled_stroke_sigma(V, p[None], q[None], P, s, 20000, np.random.default_rng(11), faces_B=F)
    assert std[0] == pytest.approx(hist.sigma[0], rel=0.10)
    assert mean[0] == pytest.approx(hist.distance[0], abs=3 * hist.sigma[0] / np.sqrt(20000) + 2e-3)


# --------------------------------------------------------------------------- max stroke, restitution


def test_max_stroke_picks_step_and_vertex():
    # apex down over a flat floor, CM height z(t) = 0.82 + (t - 0.3)^2: closest approach at t = 0.3,
    # distance 0.82 - 0.8 = 0.02 m at the apex (vertex 3, shared by the three side faces 1, 2, 3)
    t = np.linspace(0.0, 1.0, 101)
    z = 0.82 + (t - 0.3) ** 2
    p = np.stack([0.1 * t, 0 * t, z], -1)
    q = np.tile(_q_x(180.0), (t.size, 1))
    P = np.zeros((t.size, 6, 6))
    P[:, 2, 2] = 0.01**2  # 1 cm vertical, no attitude error: sigma = 0.01 exactly
    hist = stroke_history(V, p, q, P, FLAT, faces_B=F)
    ms = max_stroke(t, hist, BODY)
    assert ms.index == 30 and ms.time == pytest.approx(0.3)
    assert ms.distance == pytest.approx(0.02) and ms.sigma == pytest.approx(0.01)
    assert ms.vertex == 3 and sorted(ms.faces.tolist()) == [1, 2, 3]
    assert np.allclose(ms.point_I, [0.03, 0.0, 0.02])
    assert not ms.full_stroke and ms.possible_full_stroke
    # push it through the floor
    hist2 = stroke_history(V, p - [0, 0, 0.05], q, P, FLAT, faces_B=F)
    ms2 = max_stroke(t, hist2, BODY)
    assert ms2.distance == pytest.approx(-0.03) and ms2.full_stroke


def _bounce(sig_b, sig_a):
    s = ramp_surface(60.0, 0.3)
    t1, _ = s.tangent_basis()
    n = s.normal
    t = np.array([0.0, 0.1, 0.2, 0.3])
    v = np.array([-8.0 * n + 3 * t1, -2.0 * n, 1.0 * n, 4.0 * n + 2 * t1])
    P = np.zeros((4, 3, 3))
    P[0] = sig_b**2 * np.eye(3)
    P[3] = sig_a**2 * np.eye(3)
    return t, v, P, n


def test_restitution_value_and_sigma():
    t, v, P, n = _bounce(0.1, 0.1)
    e, se = restitution(t, v, P, n, 0, 3)
    assert e == pytest.approx(0.5)  # -4 / -8
    # hand: σ² = σa²/b² + a² σb²/b⁴ = 0.01/64 + 16*0.01/4096
    assert se == pytest.approx(np.sqrt(0.01 / 64 + 0.16 / 4096))
    rng = np.random.default_rng(2)
    m = 200000
    vb = v[0] @ n + 0.1 * rng.standard_normal(m)
    va = v[3] @ n + 0.1 * rng.standard_normal(m)
    assert np.std(-va / vb) == pytest.approx(se, rel=0.03)
    # fully correlated errors (δv_after = δv_before): the cross term adds, independence is optimistic
    e_c, se_c = restitution(t, v, P, n, 0, 3, P_cross=0.01 * np.eye(3))
    common = 0.1 * rng.standard_normal(m)
    assert np.std(-(v[3] @ n + common) / (v[0] @ n + common)) == pytest.approx(se_c, rel=0.03)
    assert se_c > se
    with pytest.raises(ValueError):
        restitution(t, v, P, n, 3, 2)
    with pytest.raises(ValueError):
        restitution(t[:3], v[1:], P[1:], n, 1, 2)  # "before" is already leaving the surface


def _pulse_history(gap_s: float = 0.0):
    """A bounce on a flat surface (normal +z, gravity -z): free fall, then a triangular bag pulse of
    peak 20 g over 0.2 s (rising linearly from zero, so touch and leave are the pulse's ends), then
    flight; with ``gap_s`` > 0 a second, separate 0.1 s pulse after that gap (a second touch-down)."""
    g = 9.80665
    dt = 1e-4
    t = np.arange(0.0, 1.0, dt)
    a = np.zeros_like(t)
    t0, T = 0.2, 0.2
    a += np.clip(20 * g * (1 - np.abs(t - t0 - T / 2) / (T / 2)), 0.0, None)
    if gap_s:
        t2 = t0 + T + gap_s
        a += np.clip(8 * g * (1 - np.abs(t - t2 - 0.05) / 0.05), 0.0, None)
    vz = -10.0 + np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) - g) * dt])
    v = np.column_stack([np.zeros_like(t), np.zeros_like(t), vz])
    A = np.column_stack([np.zeros_like(t), np.zeros_like(t), a])
    return t, v, A, np.array([0.0, 0.0, -g]), (t0, t0 + T)


def test_restitution_definitions_on_a_known_pulse():
    from workbench.problems.droptest.stroke import restitution_definitions

    t, v, A, grav, (t_touch, t_leave) = _pulse_history()
    n = np.array([0.0, 0.0, 1.0])
    rd = restitution_definitions(t, v, A, n, after=0.0, gravity=grav)
    vn = v[:, 2]
    # primary: the extremes of v_n (where the bag force equals gravity: a = 1 g on this flat floor)
    assert rd.primary == pytest.approx(-vn.max() / vn.min(), rel=1e-12)
    assert vn[rd.i_before] == vn.min() and vn[rd.i_after] == pytest.approx(vn[t < 0.6].max())
    # the physical touch/leave value differs (gravity acts while the force is still small) ...
    e_tl = -np.interp(t_leave, t, vn) / np.interp(t_touch, t, vn)
    assert abs(e_tl - rd.primary) > 5e-4
    # ... and the extrapolation to touch/leave finds it (a linear rise is exact here)
    assert rd.values["touch_leave"] == pytest.approx(e_tl, abs=5e-5)
    for k in ("ends_0.25g", "ends_0.5g", "ends_1g"):
        assert np.isfinite(rd.values[k])
    # the definition spread covers the touch/leave value
    assert rd.spread >= abs(e_tl - rd.primary) - 5e-5


def _pulses(pulses, t_end: float = 2.0):
    """Free fall at −10 m/s onto a flat surface (normal +z, gravity −z) with triangular bag pulses
    ``(start [s], duration [s], peak [g])``: (t, v, A, gravity)."""
    g = 9.80665
    dt = 1e-4
    t = np.arange(0.0, t_end, dt)
    a = np.zeros_like(t)
    for t0, T, peak in pulses:
        a += np.clip(peak * g * (1 - np.abs(t - t0 - T / 2) / (T / 2)), 0.0, None)
    vz = -10.0 + np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) - g) * dt])
    z = np.zeros_like(t)
    return t, np.column_stack([z, z, vz]), np.column_stack([z, z, a]), np.array([0.0, 0.0, -g])


def test_restitution_definitions_end_at_the_rebound_apex():
    from workbench.problems.droptest.stroke import restitution_definitions

    n = np.array([0.0, 0.0, 1.0])
    main = (0.2, 0.2, 20.0)
    t, v, A, grav = _pulses([main])
    alone = restitution_definitions(t, v, A, n, after=0.0, gravity=grav)
    assert 0.3 < alone.primary < 0.9
    # a second touch-down after the apex (v_n back through zero: the lander came down again) is a
    # new contact, not part of the first impact's restitution
    apex = t[np.flatnonzero((t > 0.4) & (v[:, 2] <= 0.0))[0]]
    t2, v2, A2, _ = _pulses([main, (apex + 0.1, 0.1, 8.0)])
    rd = restitution_definitions(t2, v2, A2, n, after=0.0, gravity=grav)
    assert rd.primary == pytest.approx(alone.primary, rel=1e-12)
    assert rd.values == pytest.approx(alone.values, rel=1e-12, nan_ok=True)
    # a bag pushing again 30 ms after the first leaves, while the lander still moves away (rolling
    # onto the next face), is part of the rebound: the velocity after the impact includes it
    t3, v3, A3, _ = _pulses([main, (0.43, 0.1, 8.0)])
    rd3 = restitution_definitions(t3, v3, A3, n, after=0.0, gravity=grav)
    vn3 = v3[:, 2]
    assert rd3.primary == pytest.approx(-vn3.max() / vn3.min(), rel=1e-12)
    assert rd3.primary > alone.primary + 0.05
    # the lowest threshold's reading brackets both pushes, so it stays an equivalent definition
    assert np.isfinite(rd3.values["ends_0.25g"])


def test_restitution_definitions_merge_a_glancing_first_touch():
    from workbench.problems.droptest.stroke import restitution_definitions

    n = np.array([0.0, 0.0, 1.0])
    # a 1 g glancing touch, 40 ms without load while still approaching, then the main strike
    t, v, A, grav = _pulses([(0.2, 0.05, 1.0), (0.29, 0.2, 20.0)])
    rd = restitution_definitions(t, v, A, n, after=0.0, gravity=grav)
    vn = v[:, 2]
    # the rebound is found (v_n turns positive only after the strike) and e spans the whole impact: a
    # 1 g touch on this floor only balances gravity, so v_n is least as the strike's load passes 1 g
    assert rd.primary == pytest.approx(-vn.max() / vn[t < 0.5].min(), rel=1e-12)
    assert 0.29 < t[rd.i_before] < 0.30 and 0.45 < t[rd.i_after] < 0.49
    # the 0.25 and 0.5 g readings start at the glancing touch, 90 ms from the minimum: not the same
    # instants, so no reading; the 1 g reading brackets the strike alone
    assert np.isnan(rd.values["ends_0.25g"]) and np.isnan(rd.values["ends_0.5g"])
    assert np.isfinite(rd.values["ends_1g"])
    # without any rebound (the lander stays on the floor) nothing is defined
    t4, v4, A4, _ = _pulses([(0.2, 0.2, 10.0)], t_end=0.5)
    v4[:, 2] = np.minimum(v4[:, 2], -0.01)
    none = restitution_definitions(t4, v4, A4, n, after=0.0, gravity=grav)
    assert np.isnan(none.primary) and none.i_before == -1 and np.isnan(none.spread)
    # a load while the lander already moves away from the floor (v_n > 0 throughout) is no impact
    v5 = v4.copy()
    v5[:, 2] = 1.0
    assert np.isnan(restitution_definitions(t4, v5, A4, n, after=0.0, gravity=grav).primary)


def test_restitution_definitions_read_only_stationary_extremes():
    from workbench.problems.droptest.stroke import restitution_definitions

    n = np.array([0.0, 0.0, 1.0])
    g = 9.80665
    # rocking onto the next face under load: the strike leaves v_n just above zero, a 0.5 g load
    # (less than gravity) holds on while v_n dips below zero, then a 15 g push: one impact, the apex
    # is only where v_n is back at zero in free flight
    t, v, A, grav = _pulses([(0.2, 0.2, 14.4), (0.5, 0.1, 15.0)])
    a = A[:, 2] + np.where((t >= 0.4) & (t < 0.52), 0.5 * g, 0.0)  # holds on into the push
    vz = -10.0 + np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) - g) * (t[1] - t[0])])
    A[:, 2], v[:, 2] = a, vz
    assert vz[(t > 0.4) & (t < 0.5)].max() > 0.0 > vz[(t > 0.4) & (t < 0.5)].min()
    rd = restitution_definitions(t, v, A, n, after=0.0, gravity=grav)
    assert rd.primary == pytest.approx(-vz[t < 1.0].max() / vz.min(), rel=1e-12)
    assert t[rd.i_after] > 0.55
    # the data end while v_n still rises (a bag still pushing): the leaving velocity is not in the data
    cut = t < 0.55
    assert np.isnan(restitution_definitions(t[cut], v[cut], A[cut], n, after=0.0, gravity=grav).primary)
    # the cut time inside the impact: v_n still falls where the window starts, no minimum to read
    t2, v2, A2, _ = _pulses([(0.2, 0.2, 20.0)])
    late = restitution_definitions(t2, v2, A2, n, after=0.22, gravity=grav)
    assert np.isnan(late.primary) and late.i_before == -1
    # a non-finite velocity after the turn-around reads nothing either
    v3 = v2.copy()
    v3[(t2 > 0.45) & (t2 < 0.46), 2] = np.nan
    bad = restitution_definitions(t2, v3, A2, n, after=0.0, gravity=grav)
    assert np.isnan(bad.primary) and bad.i_after == -1


def test_contact_end_is_the_later_of_the_contact_and_the_leaving_instant():
    from workbench.problems.droptest.stroke import contact_end

    t = np.linspace(0.0, 1.0, 11)
    assert contact_end(t, (2, 5), 8) == pytest.approx(0.8)
    assert contact_end(t, (2, 5), -1) == pytest.approx(0.5)
    assert contact_end(t, (-1, -1), 7) == pytest.approx(0.7)
    assert contact_end(t, (-1, -1), -1) is None
