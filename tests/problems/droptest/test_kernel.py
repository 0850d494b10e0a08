"""The compiled drop-test recursion (``droptest.kernel``) against the pure-numpy reference path.

Piece by piece (transition, process noise, triad and gyro models, one Joseph-form update) on a
random state, and whole forward passes of the shipped drops with ``engine="numba"`` against
``engine="reference"`` (the generic ``run_filter`` with the Python models): the same numbers to
floating-point noise (sums are taken in another order), every per-sensor innovation channel kept.
"""

from dataclasses import replace

import numpy as np
import pytest

from workbench.core.rotation import quat_from_rotvec, quat_to_dcm
from workbench.estimation.ekf import update
from workbench.estimation.kernels import joseph_update
from workbench.estimation.smoother import rts_smooth
from workbench.problems.droptest import kernel as kn
from workbench.problems.droptest import model as rl
from workbench.problems.droptest import pipeline as dt

N_T = 4
N_X, N_E = rl.sizes(N_T)


@pytest.fixture
def x():
    rng = np.random.default_rng(7)
    x = np.zeros(N_X)
    x[0:3] = [0.5, -3.0, 6.0]
    x[3:6] = rng.normal(0, 5, 3)
    x[6:9] = rng.normal(0, 30, 3)
    x[9:13] = quat_from_rotvec(rng.normal(0, 1, 3))
    x[13:16] = rng.normal(0, 3, 3)
    x[16:19] = rng.normal(0, 50, 3)
    x[rl.SS] = rng.normal(0, 0.01, 9)
    x[rl.SBG] = rng.normal(0, 1e-3, 3)
    x[rl.N_X :] = rng.normal(0, 0.05, 3 * N_T)
    return x


@pytest.fixture
def P():
    rng = np.random.default_rng(8)
    A = rng.normal(0, 1, (N_E, N_E))
    return A @ A.T / N_E + 0.1 * np.eye(N_E)


def _close(a, b, rtol=1e-12):
    np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * float(np.max(np.abs(b))))


def test_transition_and_process_noise(x, P):
    g = np.array([0.0, 0.0, -9.81])
    dt_ = 1e-3
    xn, F = np.empty(N_X), np.empty((N_E, N_E))
    w3 = np.empty((8, 3, 3))
    kn.propagate_kinematic(x, dt_, g, xn, F, w3)
    xr, Fr = rl.propagate(x, dt_, g)
    _close(xn, xr)
    _close(F, Fr)
    assert np.array_equal(F[kn.NC :, :], np.eye(N_E)[kn.NC :, :]) and not F[: kn.NC, kn.NC :].any()
    Q = np.empty((N_E, N_E))
    C = quat_to_dcm(xr[rl.SQ])
    kn.process_noise_into(dt_, 3.0, 40.0, C, Q, w3[6])
    _close(Q, rl.process_noise(dt_, 3.0, 40.0, C, N_E))
    Pk = P.copy()
    kn.predict_covariance(Pk, F, Q, np.empty((kn.NC, N_E)))
    A = Fr @ P @ Fr.T + Q
    _close(Pk, 0.5 * (A + A.T))
    assert np.array_equal(Pk, Pk.T)


@pytest.mark.parametrize("channel", ["triad", "gyro"])
def test_models_and_joseph_update(x, P, channel):
    zp, Hc, cols, w3 = np.empty(3), np.empty((3, 15)), np.empty(15, dtype=np.int64), np.empty((8, 3, 3))
    r = np.array([0.32, -0.185, -0.34])
    if channel == "triad":
        nc = kn.triad_into(x, r, 2, True, zp, Hc, cols, w3)
        z_ref, H_ref = rl.triad_model(x, r, 2)
    else:
        nc = 15
        kn.gyro_into(x, zp, Hc, cols)
        z_ref, H_ref = rl.gyro_model(x)
    H = np.zeros((3, N_E))
    H[:, cols[:nc]] = Hc[:, :nc]
    _close(zp, z_ref)
    _close(H, H_ref)
    R = np.diag([0.3, 0.2, 0.5])
    z = z_ref + np.array([0.4, -0.2, 0.1])
    ref = update(x, P, z, lambda s: z_ref, R, dt.layout_for(N_T), H=H_ref)
    xk, Pk, y, S = x.copy(), P.copy(), np.empty(3), np.empty((3, 3))
    W, M, L, v = np.empty((9, N_E)), np.empty((N_E, N_E)), np.zeros((3, 3)), np.empty((4, N_E))
    nis, status = joseph_update(Pk, z, zp, Hc, cols, nc, R, y, S, W, M, L, v)
    assert status == 0
    kn.boxplus_into(xk, v[3])
    _close(y, ref.y)
    _close(S, ref.S)
    assert nis == pytest.approx(ref.nis, rel=1e-12)
    _close(xk, ref.x_post)
    _close(Pk, ref.P_post)
    # a non-positive-definite S is reported, not factorised
    assert joseph_update(P.copy(), z, zp, Hc, cols, nc, -1e6 * np.eye(3), y, S, W, M, L, v)[1] == 1


def _engines_agree(st, tel, init):
    a = dt.forward_pass(st, tel, init, engine="numba").forward
    b = dt.forward_pass(st, tel, init, engine="reference").forward
    for f in ("x_prior", "x_post", "P_prior", "P_post", "F"):
        _close(getattr(a, f), getattr(b, f), rtol=1e-9)
    # the compiled pass keeps no Q history (nothing downstream reads it; Q enters P_prior, compared)
    assert a.Q is None and b.Q.shape == b.P_prior.shape
    assert list(a.innovations) == list(b.innovations)
    for name, hb in b.innovations.items():
        ha = a.innovations[name]
        assert np.array_equal(ha.step, hb.step) and np.array_equal(ha.accepted, hb.accepted)
        assert np.array_equal(ha.t, hb.t) and np.array_equal(ha.z, hb.z)
        for f in ("z_pred", "y", "S", "nis"):
            _close(getattr(ha, f), getattr(hb, f), rtol=1e-9)
    return a


def test_engines_agree_on_the_drop(droptest_result, droptest_run):
    r = droptest_result
    fp = _engines_agree(droptest_run.settings, r.telemetry, r.initial)
    assert {"gyro", "zupt", *r.telemetry.triads} <= set(fp.innovations)


def test_the_result_keeps_neither_transitions_nor_gains_and_smooths_bit_for_bit(droptest_result, droptest_run):
    """The smoother writes its gains and smoothed covariances into the memory of the transitions
    and the priors, and the result keeps none of the three (a long log's memory, see DropResult); its
    smoothed pass is bit for bit the forward pass smoothed with all kept."""
    r = droptest_result
    assert r.forward.forward.F.shape[0] == 0 and r.smoothed.smoothed.G.shape[0] == 0
    assert r.forward.forward.P_prior.shape[0] == 0
    fwd = dt.forward_pass(droptest_run.settings, r.telemetry, r.initial)
    sp = rts_smooth(fwd.forward, dt.layout_for(len(r.telemetry.triads)))
    assert np.array_equal(sp.x, r.smoothed.x) and np.array_equal(sp.P, r.smoothed.P)
    # the gains' one use, the restitution's cross-covariance, before they were dropped
    smo = dt.FilterStage("smoothed", sp.t, sp.x, sp.P, smoothed=sp)
    rng = np.random.default_rng(droptest_run.summary["seed"])
    st = dt.stroke_stage(fwd, smo, droptest_run.settings.lander, r.stroke.surface, r.telemetry.events, rng)
    assert np.isfinite(st.restitution[1]) and st.restitution == r.stroke.restitution


def test_engines_agree_in_dynamic_mode(droptest_result, droptest_run):
    r = droptest_result
    st = droptest_run.settings
    _engines_agree(replace(st, filter=replace(st.filter, mode="dynamic")), r.telemetry, r.initial)


@pytest.mark.slow
def test_engines_agree_with_ranging(cli_run):
    run = cli_run("droptest_ranging")
    r = dt.run_droptest(run.settings, run.telemetry_paths(), seed=run.summary["seed"])
    fp = _engines_agree(run.settings, r.telemetry, r.initial)
    assert any(name.endswith(".range") for name in fp.innovations)


def test_unknown_engine_is_an_error(droptest_result, droptest_run):
    r = droptest_result
    with pytest.raises(ValueError, match="engine"):
        dt.forward_pass(droptest_run.settings, r.telemetry, r.initial, engine="fortran")
