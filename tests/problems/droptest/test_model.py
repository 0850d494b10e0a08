"""Pins the REDLand model's analytic Jacobians against finite differences in the error state."""

import numpy as np
import pytest

from workbench.core.bodies import G0
from workbench.core.rotation import attitude_error, quat_boxplus, quat_from_rotvec
from workbench.problems.droptest import model as rl


def _boxplus(x, dx):
    y = x.copy()
    y[0:9] += dx[0:9]
    y[9:13] = quat_boxplus(x[9:13], dx[9:12])
    y[13:] += dx[12:]
    return y


def _boxminus(x1, x0):
    d = np.empty(x1.size - 1)
    d[0:9] = x1[0:9] - x0[0:9]
    d[9:12] = attitude_error(x0[9:13], x1[9:13])
    d[12:] = x1[13:] - x0[13:]
    return d


@pytest.fixture
def x():
    rng = np.random.default_rng(3)
    x = np.zeros(rl.N_X)  # every entry set below: np.empty once left new states as garbage
    x[0:3] = [0.5, -3.0, 6.0]
    x[3:6] = rng.normal(0, 5, 3)
    x[6:9] = rng.normal(0, 30, 3)
    x[9:13] = quat_from_rotvec(rng.normal(0, 1, 3))
    x[13:16] = rng.normal(0, 3, 3)
    x[16:19] = rng.normal(0, 50, 3)
    x[rl.SS] = rng.normal(0, 0.01, 9)
    x[rl.SBG] = rng.normal(0, 1e-3, 3)
    return x


def _numeric(fun, x, eps=1e-6):
    z0 = fun(x)
    cols = []
    for j in range(x.size - 1):
        e = np.zeros(x.size - 1)
        e[j] = eps
        cols.append((fun(_boxplus(x, e)) - fun(_boxplus(x, -e))) / (2 * eps))
    return np.stack(cols, -1), z0


def test_triad_jacobian(x):
    r = np.array([0.32, -0.185, -0.34])
    H_num, _ = _numeric(lambda s: rl.triad_model(s, r)[0], x)
    np.testing.assert_allclose(rl.triad_model(x, r)[1], H_num, atol=1e-5)


def test_gyro_jacobian(x):
    H_num, _ = _numeric(lambda s: rl.gyro_model(s)[0], x)
    np.testing.assert_allclose(rl.gyro_model(x)[1], H_num, atol=1e-7)


def test_range_and_rate_jacobians(x):
    r = np.array([0.0, 0.0, 0.8])
    g = np.array([8.0, -6.0, -7.0])
    for model in (rl.range_model, rl.range_rate_model):
        H_num, _ = _numeric(lambda s, m=model: m(s, g, r)[0], x)
        np.testing.assert_allclose(model(x, g, r)[1], H_num, atol=1e-6)


def test_transition_jacobian(x):
    dt = 1e-3
    grav = np.array([0, 0, -G0])
    xn, F = rl.propagate(x, dt, grav)
    F_num = np.stack(
        [_boxminus(rl.propagate(_boxplus(x, e), dt, grav)[0], xn) / 1e-6 for e in np.eye(rl.N_E) * 1e-6], -1
    )
    np.testing.assert_allclose(F, F_num, atol=2e-5)


def test_heading_stays_unobservable(x):
    """A rotation of the whole estimate about the vertical is invisible to triads and dynamics."""
    dt = 1e-3
    grav = np.array([0, 0, -G0])
    from workbench.core.rotation import quat_conjugate, quat_rotate

    def heading_direction(s):
        e_z = np.array([0.0, 0.0, 1.0])
        n = np.zeros(rl.N_E)
        n[0:3] = np.cross(e_z, s[0:3])
        n[3:6] = np.cross(e_z, s[3:6])
        n[9:12] = quat_rotate(quat_conjugate(s[9:13]), e_z)
        return n

    N0 = heading_direction(x)
    xn, F = rl.propagate(x, dt, grav)
    np.testing.assert_allclose(F @ N0, heading_direction(xn), atol=1e-9)
    for r in ([0.32, -0.185, -0.34], [0.0, 0.37, -0.34]):
        np.testing.assert_allclose(rl.triad_model(x, np.array(r))[1] @ N0, 0.0, atol=1e-12)


def test_transition_jacobian_dynamic_mode(x):
    dt = 1e-3
    grav = np.array([0, 0, -G0])
    b = rl.BungeeModel(np.array([0.0, 9.0, -8.0]), 4.0, (900.0, 60.0, -2.0), 3.0, 533.0, np.zeros(3))
    xn, F = rl.propagate(x, dt, grav, b)
    F_num = np.stack(
        [_boxminus(rl.propagate(_boxplus(x, e), dt, grav, b)[0], xn) / 1e-6 for e in np.eye(rl.N_E) * 1e-6],
        -1,
    )
    # the increment's attitude dependence is neglected (documented): compare v, a, ω, α columns
    cols = np.r_[3:9, 12 : rl.N_E]
    np.testing.assert_allclose(F[:, cols], F_num[:, cols], atol=1e-4)


def test_triad_jacobian_with_bias_states(x):
    """Triad j's bias enters additively with H = I on its own block, and nothing else changes."""
    rng = np.random.default_rng(5)
    xb = np.concatenate([x, rng.normal(0, 0.05, 12)])
    r = np.array([0.0, 0.37, -0.34])
    z0, H0 = rl.triad_model(x, r)
    z, H = rl.triad_model(xb, r, 2)
    H_num, _ = _numeric(lambda s: rl.triad_model(s, r, 2)[0], xb)
    np.testing.assert_allclose(H, H_num, atol=1e-5)
    np.testing.assert_allclose(z - z0, xb[rl.bias_slices(2)[0]])
    np.testing.assert_allclose(H[:, : rl.N_E], H0)
    xn, F = rl.propagate(xb, 1e-3, np.array([0, 0, -G0]))
    np.testing.assert_array_equal(xn[rl.N_X :], xb[rl.N_X :])  # biases are random constants
    np.testing.assert_array_equal(F[rl.N_E :, rl.N_E :], np.eye(12))


def test_prediction_does_not_depend_on_the_body_axes(x):
    """One predict step ``F P Fᵀ + Q`` in body axes B and in B' = R B (the same lander, its frame
    turned): the covariances are the same up to that rotation.  The jerk-noise blocks that couple
    SPF position/velocity with body acceleration once paired SPF axis i with body axis i; a rig
    described in another lander frame then gave another max stroke (test_rig_frame: −22 mm)."""
    from workbench.core.rotation import dcm_to_quat, quat_to_dcm

    rng = np.random.default_rng(11)
    R = quat_to_dcm(quat_from_rotvec(np.array([0.4, -2.1, 1.3])))  # x_B' = R x_B
    n_e = rl.N_E
    T = np.eye(n_e)  # error state in B' = T (error state in B): body-frame blocks turn with R
    for sl in (rl.EA, rl.ETH, rl.EW, rl.EAL, rl.EBG):
        T[sl, sl] = R
    T[rl.ES, rl.ES] = np.kron(R, R)  # E' = R E Rᵀ, row-major
    x2 = x.copy()
    x2[rl.SQ] = dcm_to_quat(quat_to_dcm(x[rl.SQ]) @ R.T)
    for sl in (rl.SA, rl.SW, rl.SAL, rl.SBG):
        x2[sl] = R @ x[sl]
    x2[rl.SS] = (R @ x[rl.SS].reshape(3, 3) @ R.T).ravel()
    A = rng.normal(0, 1, (n_e, n_e))
    P = A @ A.T / n_e + 0.1 * np.eye(n_e)
    dt, grav = 1e-3, np.array([0, 0, -G0])
    out = []
    for s, Ps in ((x, P), (x2, T @ P @ T.T)):
        sn, F = rl.propagate(s, dt, grav)
        Q = rl.process_noise(dt, 5e4, 3e5, quat_to_dcm(sn[rl.SQ]), n_e)  # impact-sized PSDs
        assert np.min(np.linalg.eigvalsh(Q)) > -1e-12 * np.max(np.abs(Q))
        out.append(F @ Ps @ F.T + Q)
    np.testing.assert_allclose(out[1], T @ out[0] @ T.T, atol=1e-12 * float(np.max(np.abs(out[0]))))


@pytest.mark.parametrize("j", [None, 0, 3])
def test_triad_specific_force_over_a_history_is_the_models_prediction(x, j):
    """The batched prediction (the recording's measured-vs-predicted plot) equals triad_model's z row
    by row, with and without the bias states, and takes one state as well as a history."""
    rng = np.random.default_rng(11)
    X = np.concatenate([x, rng.normal(0, 0.05, 12)]) + rng.normal(0, 0.3, (40, rl.N_X + 12))
    r = np.array([0.32, -0.185, -0.34])
    ref = np.array([rl.triad_model(s, r, j)[0] for s in X])
    np.testing.assert_allclose(rl.triad_specific_force(X, r, j), ref, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(rl.triad_specific_force(X[5], r, j), ref[5], rtol=1e-13, atol=1e-13)
    core = X[:, : rl.N_X]  # no bias states: triad j's bias is not there to add
    np.testing.assert_allclose(rl.triad_specific_force(core, r, j), rl.triad_specific_force(X, r, None), rtol=0, atol=0)
