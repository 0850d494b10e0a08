"""Tests of workbench.estimation.ensemble: the attitude integrated once (q_i = q0_i ⊗ Δq) with the
translational RK4 per member equals the full per-member strapdown (strapdown.integrate_members) to
floating-point noise, and its three executions (numba kernel, numpy reference, per-member Python
floats) are bit-identical."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from workbench.core.bodies import MARS
from workbench.core.rotation import attitude_error, quat_multiply, quat_normalize
from workbench.estimation import ensemble as en
from workbench.estimation import strapdown as sd

synth = importlib.import_module("entry_synth")  # tests/support, on sys.path via tests/conftest.py


@pytest.fixture(scope="module")
def case():
    tr = synth.truth(dt=0.5)
    imu = synth.make_imu(tr, gaps=[(20.0, 77.0), (100.0, 101.5)])
    rng = np.random.default_rng(4)
    m = 37  # not a multiple of the kernel's block
    d = rng.standard_normal((m, 9)) * np.r_[np.full(3, 50.0), np.full(3, 0.1), np.full(3, 5e3)]
    v = tr["v"][0] + d[:, 0:3]
    q = np.array([synth.perturb(tr["q"][0], x) for x in d[:, 3:6]])
    p = tr["p"][0] + d[:, 6:9]
    n = imu.t.size
    rec = np.array([0, 1, 40, 41, n // 2, n - 2, n - 1])
    return dict(imu=imu, v=v, q=q, p=p, rec=rec)


@pytest.mark.parametrize("mode", ["relative", "paper"])
def test_matches_the_per_member_strapdown(case, mode):
    c = case
    track = en.attitude_track(c["imu"], mode)
    assert np.count_nonzero(track.kind) == 2
    V, P = en.integrate_ensemble(track, c["v"], c["q"], c["p"], c["rec"], body=MARS, backend="numpy")
    ref = sd.integrate_members(c["imu"], c["v"], c["q"], c["p"], bridge_mode=mode, body=MARS)
    # the same RK4 (the stage quaternions q0 ⊗ Q_s): rounding-level differences only
    np.testing.assert_allclose(P, ref["p"][c["rec"]], rtol=0, atol=1e-6)  # |p| ~ 3.4e6 m: ~3e-13 relative
    np.testing.assert_allclose(V, ref["v"][c["rec"]], rtol=0, atol=1e-9)
    q_ens = quat_normalize(quat_multiply(quat_normalize(c["q"])[None], track.dq[c["rec"], None]))
    assert np.abs(attitude_error(ref["q"][c["rec"]], q_ens)).max() < 1e-12


@pytest.mark.parametrize("mode", ["relative", "paper"])
def test_backends_are_bit_identical(case, mode):
    c = case
    track = en.attitude_track(c["imu"], mode)
    args = (track, c["v"], c["q"], c["p"], c["rec"])
    V, P = en.integrate_ensemble(*args, body=MARS, backend="numpy")
    Vp, Pp = en.integrate_ensemble(*args, body=MARS, backend="python")
    np.testing.assert_array_equal(Vp, V)
    np.testing.assert_array_equal(Pp, P)
    if en.HAVE_NUMBA:
        for threads in (1, 2):
            Vn, Pn = en.integrate_ensemble(*args, body=MARS, backend="numba", threads=threads)
            np.testing.assert_array_equal(Vn, V)
            np.testing.assert_array_equal(Pn, P)
    # a member's result does not depend on the other members of the call
    V1, P1 = en.integrate_ensemble(track, c["v"][5:6], c["q"][5:6], c["p"][5:6], c["rec"], body=MARS)
    np.testing.assert_array_equal(V1[:, 0], V[:, 5])
    np.testing.assert_array_equal(P1[:, 0], P[:, 5])


def test_bad_arguments(case):
    c = case
    track = en.attitude_track(c["imu"])
    with pytest.raises(ValueError, match="record"):
        en.integrate_ensemble(track, c["v"], c["q"], c["p"], np.array([3, 1]), body=MARS)
    with pytest.raises(ValueError, match="backend"):
        en.integrate_ensemble(track, c["v"], c["q"], c["p"], c["rec"], body=MARS, backend="cuda")
    with pytest.raises(ValueError, match="bridge_mode"):
        en.attitude_track(c["imu"], "other")
