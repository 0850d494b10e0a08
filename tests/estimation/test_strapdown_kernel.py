"""The compiled strapdown step (estimation.strapdown_kernel) agrees with the reference path
``rk4_step`` + ``covariance_step`` of estimation.strapdown: the state bit for bit, Φ and Qd to rounding."""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest
from scipy.linalg import expm

from workbench.core.bodies import MARS
from workbench.core.gravity import j2_factor
from workbench.estimation.strapdown import covariance_step, integrate, rk4_step
from workbench.estimation.strapdown_kernel import expm_taylor, transition_step

synth = importlib.import_module("entry_synth")  # tests/support, on sys.path via tests/conftest.py
RTOL = 1e-13  # of each matrix's largest entry


def _case(rng):
    p = rng.normal(0.0, 1.0, 3)
    p *= (MARS.reference_radius + rng.uniform(0.0, 120e3)) / np.linalg.norm(p)
    v = rng.normal(0.0, 3000.0, 3)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    f0, f1 = rng.normal(0.0, 40.0, 3), rng.normal(0.0, 40.0, 3)
    w0, w1 = rng.normal(0.0, 1.5, 3), rng.normal(0.0, 1.5, 3)
    return v, q, p, f0, w0, f1, w1


@pytest.mark.parametrize("gradient", [False, True])
@pytest.mark.parametrize("with_state_noise", [False, True])
def test_transition_step_matches_reference(gradient, with_state_noise):
    rng = np.random.default_rng(5)
    qpsd = rng.uniform(0.0, 1e-3, 9) if with_state_noise else None
    for dt in (0.002, 0.0125, 0.05, 1.3):
        v, q, p, f0, w0, f1, w1 = _case(rng)
        sw, sf = rng.uniform(1e-4, 1e-2, 3), rng.uniform(1e-3, 0.5, 3)
        sample_dt = 0.0125
        v1, q1, p1, Phi, Qd = transition_step(
            v, q, p, f0, w0, f1, w1, dt, sw, sf, sample_dt, np.zeros(9) if qpsd is None else qpsd, gradient,
            MARS.gm, j2_factor(MARS),
        )  # fmt: skip
        rv, rq, rp = rk4_step(v, q, p, f0, w0, f1, w1, dt, MARS)
        np.testing.assert_array_equal(v1, rv)
        np.testing.assert_array_equal(q1, rq)
        np.testing.assert_array_equal(p1, rp)
        qm = q + rq if (q @ rq) >= 0.0 else q - rq
        qm = qm / math.sqrt(qm @ qm)
        _, rPhi, rQd = covariance_step(
            np.eye(9), qm, 0.5 * (f0 + f1), 0.5 * (w0 + w1), dt, sw, sf, sample_dt, qpsd,
            0.5 * (p + rp) if gradient else None, body=MARS,
        )  # fmt: skip
        np.testing.assert_allclose(Phi, rPhi, rtol=0.0, atol=RTOL * np.max(np.abs(rPhi)))
        np.testing.assert_allclose(Qd, rQd, rtol=0.0, atol=RTOL * np.max(np.abs(rQd)))
        np.testing.assert_array_equal(Qd, Qd.T)


def test_expm_taylor_matches_scipy():
    rng = np.random.default_rng(1)
    for scale in (1e-6, 0.1, 1.0, 8.0):
        M = scale * rng.normal(size=(9, 9))
        E = expm_taylor(M)
        R = expm(M)
        np.testing.assert_allclose(E, R, rtol=0.0, atol=1e-13 * np.max(np.abs(R)))
    np.testing.assert_array_equal(expm_taylor(np.zeros((9, 9))), np.eye(9))


def test_integrate_fast_matches_reference_path():
    """``integrate(fast=True)`` (compiled steps) against the default reference path, with data gaps and
    state noise: the same states bit for bit, P, Φ and Qd to rounding."""
    tr = synth.truth()
    imu = synth.make_imu(tr, gaps=[(20.0, 77.2), (100.0, 101.4)])
    P0 = np.diag(np.r_[np.full(3, 10.0**2), np.full(3, np.deg2rad(1.0) ** 2), np.full(3, 2000.0**2)])
    args = (imu, tr["v"][0], tr["q"][0], tr["p"][0], P0)
    kw = {"q_state_psd": np.full(9, 1e-6), "body": MARS}
    fast = integrate(*args, fast=True, **kw)
    ref = integrate(*args, **kw)
    for f in ("v_M", "q_M_G", "p_M"):
        np.testing.assert_array_equal(getattr(fast, f), getattr(ref, f))
    np.testing.assert_array_equal(fast.bridged, ref.bridged)
    for f in ("P", "Phi", "Qd"):
        a, b = getattr(fast, f), getattr(ref, f)
        scale = np.max(np.abs(b), axis=(1, 2), keepdims=True)
        assert np.all(np.abs(a - b) <= 1e-12 * scale), f
