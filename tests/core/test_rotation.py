"""Pin workbench.core.rotation against scipy.spatial.transform.Rotation and hand-derived values."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from workbench.core import rotation as rot

RNG_SEED = 20240611


@pytest.fixture
def rng():
    return np.random.default_rng(RNG_SEED)


def _same_rotation(q1, q2, atol=1e-12):
    """Quaternions equal up to sign."""
    q1, q2 = np.asarray(q1), np.asarray(q2)
    d = np.minimum(np.abs(q1 - q2).max(-1), np.abs(q1 + q2).max(-1))
    return np.all(d < atol)


def test_multiply_matches_scipy_composition(rng):
    R1, R2 = Rotation.random(50, random_state=1), Rotation.random(50, random_state=2)
    q = rot.quat_multiply(R1.as_quat(), R2.as_quat())
    assert _same_rotation(q, (R1 * R2).as_quat())


def test_rotate_and_dcm_match_scipy(rng):
    R = Rotation.random(50, random_state=3)
    v = rng.normal(size=(50, 3))
    np.testing.assert_allclose(rot.quat_rotate(R.as_quat(), v), R.apply(v), atol=1e-12)
    np.testing.assert_allclose(rot.quat_to_dcm(R.as_quat()), R.as_matrix(), atol=1e-12)
    # dcm_to_quat over rotations near every Shepperd branch (incl. 180° turns)
    mats = np.concatenate([R.as_matrix(), Rotation.from_rotvec(np.pi * np.eye(3)).as_matrix()])
    q = rot.dcm_to_quat(mats)
    assert _same_rotation(q, Rotation.from_matrix(mats).as_quat(), atol=1e-12)
    assert np.all(q[..., 3] >= 0)


def test_skew_is_cross_product(rng):
    a, b = rng.normal(size=(2, 10, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", rot.skew(a), b), np.cross(a, b), atol=1e-12)


def test_rotvec_round_trip_matches_scipy(rng):
    phi = rng.normal(size=(100, 3))
    phi = phi / np.linalg.norm(phi, axis=-1, keepdims=True) * rng.uniform(0, np.pi, (100, 1))
    phi = np.concatenate([phi, [[1e-9, -2e-9, 0.0], [0.0, 0.0, 0.0]]])
    q = rot.quat_from_rotvec(phi)
    assert _same_rotation(q, Rotation.from_rotvec(phi).as_quat())
    np.testing.assert_allclose(rot.quat_to_rotvec(q), Rotation.from_quat(q).as_rotvec(), atol=1e-12)


def test_euler123_is_scipy_intrinsic_XYZ(rng):
    angles = rng.uniform([-np.pi, -np.pi / 2 + 0.01, -np.pi], [np.pi, np.pi / 2 - 0.01, np.pi], (100, 3))
    q = rot.quat_from_euler123(angles)
    assert _same_rotation(q, Rotation.from_euler("XYZ", angles).as_quat())
    np.testing.assert_allclose(rot.euler123_from_quat(q), angles, atol=1e-10)
    # gimbal lock: theta = 90°, the rotation must still be reproduced
    lock = np.array([0.3, np.pi / 2, 0.2])
    back = rot.euler123_from_quat(rot.quat_from_euler123(lock))
    np.testing.assert_allclose(
        Rotation.from_euler("XYZ", back).as_matrix(), Rotation.from_euler("XYZ", lock).as_matrix(), atol=1e-7
    )


def test_attitude_error_is_right_perturbation(rng):
    R_est = Rotation.random(20, random_state=4)
    dtheta = rng.normal(scale=0.05, size=(20, 3))
    R_true = R_est * Rotation.from_rotvec(dtheta)  # q_true = q_est ⊗ exp(δθ)
    np.testing.assert_allclose(rot.attitude_error(R_est.as_quat(), R_true.as_quat()), dtheta, atol=1e-12)
    q_back = rot.quat_boxplus(R_est.as_quat(), dtheta)
    assert _same_rotation(q_back, R_true.as_quat())


def test_integrate_body_rate_constant_rate():
    # 90 deg/s about body z for 1 s from identity -> 90° about z
    q = rot.quat_integrate_body_rate(rot.quat_identity(), np.array([0.0, 0.0, np.pi / 2]), 1.0)
    np.testing.assert_allclose(q, [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    # plain-list rate with a scalar dt, and per-sample dt arrays
    q = rot.quat_integrate_body_rate(rot.quat_identity(), [0.0, 0.0, np.pi / 2], 1.0)
    np.testing.assert_allclose(q, [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    q = rot.quat_integrate_body_rate(rot.quat_identity((2,)), [[np.pi, 0, 0]] * 2, np.array([0.5, 1.0]))
    np.testing.assert_allclose(q, [[np.sqrt(0.5), 0, 0, np.sqrt(0.5)], [1.0, 0, 0, 0.0]], atol=1e-12)


def test_jpl_conversion_hand_derived():
    """JPL quaternion of 90° about z: q̄ = [0, 0, sin 45°, cos 45°].

    Trawny & Roumeliotis (2005) Eq. (62): C(q̄) = (2q4² − 1) I − 2 q4 [q×] + 2 q qᵀ, which for this
    q̄ is [[0, 1, 0], [−1, 0, 0], [0, 0, 1]] (a passive rotation: x maps to −y).  The Hamilton
    quaternion with the same DCM is a −90° rotation about z: [0, 0, −sin 45°, cos 45°].
    """
    s = np.sqrt(0.5)
    q_jpl = np.array([0.0, 0.0, s, s])
    C_jpl = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    q = rot.quat_from_jpl(q_jpl)
    np.testing.assert_allclose(q, [0.0, 0.0, -s, s], atol=1e-15)
    np.testing.assert_allclose(rot.quat_to_dcm(q), C_jpl, atol=1e-15)
    np.testing.assert_allclose(rot.quat_to_jpl(q), q_jpl, atol=1e-15)


def test_jpl_conversion_preserves_composition(rng):
    """JPL product p ⊗_J q = [p4 q + q4 p − p × q, p4 q4 − p·q] composes DCMs as C(p ⊗_J q) = C(p) C(q)."""

    def jpl_mult(p, q):
        v = p[3] * q[:3] + q[3] * p[:3] - np.cross(p[:3], q[:3])
        return np.concatenate([v, [p[3] * q[3] - p[:3] @ q[:3]]])

    p, q = Rotation.random(2, random_state=5).as_quat()
    lhs = rot.quat_from_jpl(jpl_mult(p, q))
    rhs = rot.quat_multiply(rot.quat_from_jpl(p), rot.quat_from_jpl(q))
    assert _same_rotation(lhs, rhs)


def test_triad_recovers_known_rotation_exactly(rng):
    R = Rotation.random(10, random_state=6)  # C_N_B
    u_N, v_N = rng.normal(size=(2, 10, 3))
    u_B, v_B = R.inv().apply(u_N), R.inv().apply(v_N)
    q = rot.triad(u_B * 3.0, v_B * 0.5, u_N, v_N)  # lengths do not matter
    assert _same_rotation(q, R.as_quat(), atol=1e-12)


def test_triad_rejects_parallel_vectors():
    with pytest.raises(ValueError):
        rot.triad([0, 0, 1.0], [0, 0, 2.0], [0, 0, 1.0], [1.0, 0, 0])


def _tilt(b, sigma, rng, n_samples=20000):
    """Unit vectors b (3,) tilted by isotropic perpendicular noise of 1σ ``sigma`` per axis."""
    n = rng.normal(scale=sigma, size=(n_samples, 3))
    n -= np.outer(n @ b, b)
    out = b + n
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def test_triad_covariance_matches_monte_carlo(rng):
    R = Rotation.from_euler("XYZ", [0.4, -0.7, 1.9])  # C_N_B, deliberately not identity
    u_N = np.array([0.1, -0.2, -1.0])
    v_N = np.array([0.6, 0.3, 0.2])
    u_B, v_B = R.inv().apply(u_N), R.inv().apply(v_N)
    u_B, v_B = u_B / np.linalg.norm(u_B), v_B / np.linalg.norm(v_B)
    sigma_u, sigma_v = 1e-3, 4e-3
    q_est = rot.triad(_tilt(u_B, sigma_u, rng), _tilt(v_B, sigma_v, rng), u_N, v_N)
    err = rot.attitude_error(q_est, np.broadcast_to(R.as_quat(), q_est.shape))
    S = np.cov(err.T)
    P = rot.triad_covariance(u_B, v_B, sigma_u, sigma_v)
    # whitened sample covariance must be the identity within 10 %
    L = np.linalg.cholesky(P)
    W = np.linalg.solve(L, np.linalg.solve(L, S).T)
    eig = np.linalg.eigvalsh(0.5 * (W + W.T))
    assert np.all(np.abs(eig - 1.0) < 0.10), eig
    assert np.all(np.abs(err.mean(0)) < 3 * np.sqrt(np.diag(P) / err.shape[0]) + 1e-6)


def test_single_quaternion_paths_equal_the_vectorised_ones(rng):
    """The one-quaternion fast paths (used in hot loops) give the vectorised results to the bit."""
    p = rng.normal(size=(20, 4))
    q = rng.normal(size=(20, 4))
    M = rot.quat_multiply(p, q)
    C = rot.quat_to_dcm(q)
    N = rot.quat_normalize(q)
    np.testing.assert_array_equal(rot.quat_multiply(p[0], q), rot.quat_multiply(p[:1], q))  # broadcasting
    for k in range(20):
        np.testing.assert_array_equal(rot.quat_multiply(p[k], q[k]), M[k])
        np.testing.assert_array_equal(rot.quat_to_dcm(q[k]), C[k])
        np.testing.assert_array_equal(rot.quat_normalize(q[k]), N[k])
        rows = rot.dcm_components(*q[k].tolist())  # Python floats in, Python floats out
        assert isinstance(rows[0][0], float)
        np.testing.assert_array_equal(np.array(rows), C[k])
    # against scipy for unit quaternions, and the norm really is 1
    np.testing.assert_allclose(np.linalg.norm(N, axis=-1), 1.0, rtol=1e-15)
    np.testing.assert_allclose(rot.quat_to_dcm(N[3]), Rotation.from_quat(N[3]).as_matrix(), atol=1e-14)
    with pytest.raises(ValueError):
        rot.quat_normalize(np.zeros(4))


def test_single_quaternion_fast_paths_equal_the_vectorised_ones():
    """quat_boxplus_one / attitude_error_one (the filters' hot path) equal the array versions."""
    from workbench.core.rotation import attitude_error, attitude_error_one, quat_boxplus, quat_boxplus_one

    rng = np.random.default_rng(11)
    for scale in (1e-9, 1e-3, 0.5, 2.0):
        for _ in range(50):
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            d = scale * rng.normal(size=3)
            np.testing.assert_allclose(quat_boxplus_one(q, d), quat_boxplus(q, d), rtol=0, atol=1e-15)
            q2 = quat_boxplus(q, d)
            np.testing.assert_allclose(attitude_error_one(q, q2), attitude_error(q, q2), rtol=0, atol=1e-12)
            if scale < 1.0:
                np.testing.assert_allclose(attitude_error_one(q, q2), d, rtol=1e-9, atol=1e-15)


def test_quat_x_along_points_x_along_the_vector():
    """X_b along v (post2's 3-DOF drawing attitude), a right-handed orthonormal frame, Y_b along ẑ × X_b
    (horizontal) unless v is within 26° of ±Z (then x̂ × X_b), for every row of a batch and near-vertical rows."""
    rng = np.random.default_rng(3)
    v = np.concatenate([rng.normal(size=(200, 3)) * [1e3, 1e3, 3e3], [[0.0, 0.0, -5.0], [1e-3, 0.0, 7.0]]])
    C = rot.quat_to_dcm(rot.quat_x_along(v))
    u = v / np.linalg.norm(v, axis=1)[:, None]
    np.testing.assert_allclose(C[:, :, 0], u, atol=1e-12)
    np.testing.assert_allclose(np.swapaxes(C, 1, 2) @ C, np.broadcast_to(np.eye(3), C.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(C), 1.0, atol=1e-12)
    steep = np.abs(u[:, 2]) >= 0.9
    assert steep.any() and (~steep).any()
    a = np.where(steep[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    y = np.cross(a, u)
    np.testing.assert_allclose(C[:, :, 1], y / np.linalg.norm(y, axis=1)[:, None], atol=1e-12)
