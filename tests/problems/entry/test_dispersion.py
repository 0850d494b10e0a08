"""Tests of workbench.problems.entry.dispersion (AMELIA Sect. 6): per-member determinism across chunk
sizes, the per-trajectory loop and a Dask LocalCluster; acceptance logic; the refined state."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from workbench.core.rotation import quat_from_rotvec, quat_multiply, quat_normalize
from workbench.problems.entry import dispersion as ds

synth = importlib.import_module("entry_synth")  # tests/support, on sys.path via tests/conftest.py
#: small sigmas so that a fair share of the members is accepted by truth-centred rules
SIG = ds.DispersionSigmas(velocity_m_s=5.0, attitude_rad=np.deg2rad(0.3), position_m=1000.0)


@pytest.fixture(scope="module")
def case():
    tr = synth.truth(dt=0.5)
    imu = synth.make_imu(tr, gaps=[(20.0, 77.0), (100.0, 101.5)])
    v0, q0, p0 = tr["v"][0], tr["q"][0], tr["p"][0]
    # truth-centred rules with the paper's half-widths
    ref = ds.run_dispersion(imu, v0, q0, p0, np.zeros(9), n=1, events_t=tr["events"], n_cloud=0, bridge_mode="relative")
    e = {k: float(v[0]) for k, v in ref.events.items()}
    rules = ds.AcceptanceRules(
        mach_pdd=(e["mach_pdd"], 0.2),
        h_pdd_m=(e["h_pdd"], 2e3),
        h_fsr_m=(e["h_fsr"], 2e3),
        h_end_m=(e["h_end"], 2e3),
        time_to_impact_s=(e["time_to_impact"], 15.0),
    )
    res = ds.run_dispersion(imu, v0, q0, p0, SIG, n=200, rules=rules, events_t=tr["events"], chunk_size=64, seed=3,
                            n_cloud=40, bridge_mode="relative")  # fmt: skip
    return dict(tr=tr, imu=imu, v0=v0, q0=q0, p0=p0, rules=rules, res=res, e_nominal=e)


def _same(a: ds.DispersionResult, b: ds.DispersionResult, n: int | None = None):
    n = n or min(a.n, b.n)
    np.testing.assert_array_equal(a.dx0[:n], b.dx0[:n])
    for k in ds.EVENT_NAMES:
        np.testing.assert_array_equal(a.events[k][:n], b.events[k][:n])
    np.testing.assert_array_equal(a.accepted[:n], b.accepted[:n])


def test_nominal_member_events_match_truth(case):
    tr, e = case["tr"], case["e_nominal"]
    assert abs(e["mach_pdd"] - 2.0) < 0.03  # the synthetic PDD is at Mach 2 (on the truth grid)
    h = np.linalg.norm(tr["p"], axis=1) - ds.MARS.reference_radius
    assert abs(e["h_end"] - h[-1]) < 1000.0  # 2 Hz samples straddle the drag jump at PDD: O(dt) error
    assert 20.0 < e["time_to_impact"] < 60.0


def test_offsets_depend_only_on_seed_and_member():
    s = ds.DispersionSigmas().vector()
    a = ds.sample_offsets(5, 0, 1000, s)
    np.testing.assert_array_equal(a[300:777], ds.sample_offsets(5, 300, 777, s))
    assert not np.array_equal(a, ds.sample_offsets(6, 0, 1000, s))
    z = a / s
    assert abs(z.std() - 1.0) < 0.02 and abs(z.mean()) < 0.02


def test_chunk_size_loop_and_dask_give_identical_results(case):
    c = case
    args = (c["imu"], c["v0"], c["q0"], c["p0"], SIG)
    kw = dict(rules=c["rules"], events_t=c["tr"]["events"], seed=3, n_cloud=40, bridge_mode="relative")
    other = ds.run_dispersion(*args, n=200, chunk_size=200, **kw)
    _same(c["res"], other)
    np.testing.assert_array_equal(c["res"].cloud_p_M, other.cloud_p_M)
    loop = ds.run_dispersion_loop(*args, n=12, **kw)
    _same(c["res"], loop)
    assert loop.scheduler == "per-trajectory loop"
    pool = ds.run_dispersion(*args, n=200, chunk_size=100, workers=2, **kw)
    _same(c["res"], pool)
    assert "process pool" in pool.scheduler
    pytest.importorskip("distributed")
    dk = ds.run_dispersion(*args, n=200, chunk_size=50, scheduler="local", **kw)
    _same(c["res"], dk)
    assert "LocalCluster" in dk.scheduler


def test_acceptance_rules():
    r = ds.AcceptanceRules()
    ev = {
        "mach_pdd": np.array([2.0, 2.19, 2.21, 1.9, np.nan]),
        "h_pdd": np.array([10e3, 12e3, 10e3, 8e3, 10e3]),
        "h_fsr": np.array([6e3, 4e3, 6e3, 6e3, 6e3]),
        "h_end": np.array([3e3, 1e3, 3e3, 5.1e3, 3e3]),
        "time_to_impact": np.array([40.0, 25.0, 40.0, 40.0, 40.0]),
    }
    np.testing.assert_array_equal(r.accept(ev), [True, True, False, False, False])
    ch = r.checks(ev)
    assert not ch["mach_pdd"][2] and not ch["h_end"][3] and not ch["mach_pdd"][4]
    assert r.bands()["h_fsr"] == (6e3, 2e3)


def test_acceptance_and_refined_state(case):
    res, c = case["res"], case
    assert res.n == 200 and res.dx0.shape == (200, 9)
    acc = res.accepted
    assert 0 < acc.sum() < 200  # the rules do select
    np.testing.assert_array_equal(acc, c["rules"].accept(res.events))
    mean = res.dx0[acc].mean(axis=0)
    np.testing.assert_allclose(res.refined_v0, c["v0"] + mean[0:3], rtol=1e-15)
    np.testing.assert_allclose(res.refined_p0, c["p0"] + mean[6:9], rtol=1e-15)
    q_ref = quat_normalize(quat_multiply(c["q0"], quat_from_rotvec(mean[3:6])))
    np.testing.assert_allclose(res.refined_q0 * np.sign(res.refined_q0 @ q_ref), q_ref, atol=1e-14)
    np.testing.assert_allclose(res.refined_P0, np.cov(res.dx0[acc], rowvar=False))
    sd = np.sqrt(np.diagonal(res.refined_P0))
    np.testing.assert_allclose(res.refined_sigma_max, sd.reshape(3, 3).max(axis=1))
    # the rules are informative: the accepted position spread is narrower than the prior
    assert sd[6:9].mean() < SIG.position_m
    # the refined state is closer to the truth (= the nominal here) than the sampling spread
    assert np.all(np.abs(mean / SIG.vector()) < 3.0 / np.sqrt(acc.sum()) + 0.5)


def test_cloud_thinned_and_mixed(case):
    res = case["res"]
    m, k = res.cloud_index.size, res.cloud_t.size
    assert 0 < m <= 40 and res.cloud_p_M.shape == (m, k, 3)
    assert res.cloud_accepted.any() and (~res.cloud_accepted).any()
    np.testing.assert_array_equal(res.cloud_accepted, res.accepted[res.cloud_index])
    gaps = [(g.t_a, g.t_b) for g in case["imu"].gaps]
    for a, b in zip(res.cloud_t[:-1], res.cloud_t[1:], strict=True):  # ~1 Hz except across data gaps
        assert b - a <= 1.0 + 1e-9 or any(ta >= a - 1e-9 and tb <= b + 1e-9 for ta, tb in gaps)
    assert res.cloud_t[-1] == case["imu"].t[-1]
    # the first cloud sample is the member's initial position
    np.testing.assert_allclose(res.cloud_p_M[:, 0], case["p0"] + res.dx0[res.cloud_index, 6:9])


def test_none_accepted_and_bad_inputs(case):
    c = case
    strict = ds.AcceptanceRules(mach_pdd=(10.0, 0.01))
    r = ds.run_dispersion(c["imu"], c["v0"], c["q0"], c["p0"], SIG, n=8, rules=strict, events_t=c["tr"]["events"],
                          n_cloud=4, bridge_mode="relative")  # fmt: skip
    assert r.n_accepted == 0 and np.all(np.isnan(r.refined_P0))
    np.testing.assert_array_equal(r.refined_v0, c["v0"])
    assert r.cloud_index.size == 4 and not r.cloud_accepted.any()
    with pytest.raises(ValueError, match="PDD"):
        ds.run_dispersion(
            c["imu"], c["v0"], c["q0"], c["p0"], SIG, n=2, events_t={"FSR": 10.0}, n_cloud=0, bridge_mode="relative"
        )
    with pytest.raises(ValueError, match="scheduler"):
        ds.run_dispersion(c["imu"], c["v0"], c["q0"], c["p0"], SIG, n=2, events_t=c["tr"]["events"], scheduler="x",
                          n_cloud=0, bridge_mode="relative")  # fmt: skip


def test_sigma_forms():
    ref = ds.DispersionSigmas(velocity_m_s=5.0, attitude_rad=0.01, position_m=100.0).vector()
    np.testing.assert_array_equal(ds.sigma_vector({"velocity": 5.0, "attitude": 0.01, "position": 100.0}), ref)
    np.testing.assert_array_equal(ds.sigma_vector([5.0, 0.01, 100.0]), ref)
    np.testing.assert_array_equal(ds.sigma_vector(None), ds.DispersionSigmas().vector())
    with pytest.raises(ValueError, match="unknown"):
        ds.sigma_vector({"speed": 1.0})


def test_refinement_rounds_are_deterministic_and_weighted(case):
    c = case
    wide = ds.DispersionSigmas(velocity_m_s=30.0, attitude_rad=np.deg2rad(1.0), position_m=5000.0)
    kw = dict(rules=c["rules"], events_t=c["tr"]["events"], seed=9, n_cloud=10, refine_rounds=1, min_elite=10,
              bridge_mode="relative")  # fmt: skip
    a = ds.run_dispersion(c["imu"], c["v0"], c["q0"], c["p0"], wide, n=120, chunk_size=120, **kw)
    b = ds.run_dispersion(c["imu"], c["v0"], c["q0"], c["p0"], wide, n=120, chunk_size=50, **kw)
    _same(a, b)
    np.testing.assert_array_equal(a.weights, b.weights)
    assert [r["round"] for r in a.rounds] == [0, 1]
    assert a.rounds[1]["n_accepted"] > a.rounds[0]["n_accepted"]
    assert np.all(a.rounds[1]["proposal_sigma"] <= wide.vector() + 1e-12)  # never wider than the prior
    acc = a.accepted
    m = np.average(a.dx0[acc], axis=0, weights=a.weights[acc])
    np.testing.assert_allclose(a.refined_p0, c["p0"] + m[6:9], rtol=1e-15)
    np.testing.assert_allclose(a.refined_P0, np.cov(a.dx0[acc], rowvar=False, aweights=a.weights[acc]))
    np.testing.assert_array_less(a.score[acc], 1.0 + 1e-12)
