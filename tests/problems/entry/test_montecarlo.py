"""AMELIA Sect. 8 validation of the entry smoother (``pipelines.entry_mc``) on a small fixture.

Fixture: a 40 s kinematic descent from 8 km above the terrain sphere (constant inertial velocity,
80 m/s down, vertical attitude with a slow spin and two pendulum swings), clean IMU
``f_G = −C_G_M g(p)`` and the analytic body rate at 10 Hz with a 100 Hz stretch (10–11 s) and one
data gap (20–22 s) bridged from the truth; a dispersion look-alike of 200 offsets of which about
half are "accepted"; radar time tags off the IMU grid.
"""

from __future__ import annotations

import importlib.util
from dataclasses import fields
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import dcm_to_quat, quat_boxplus, quat_from_rotvec, quat_multiply, quat_to_dcm
from workbench.estimation.strapdown import GapBridge, ImuArrays
from workbench.models.radar import mars_rate_M
from workbench.problems.entry.filter import EntryFilterSigmas
from workbench.problems.entry.montecarlo import ValidationResult, ValidationSettings, noise_scale, validate_smoother
from workbench.problems.entry.scoring import ERROR_NAMES
from workbench.problems.entry.site import R_GROUND

OM = mars_rate_M()
EX, EY, EZ = np.eye(3)
SIG = EntryFilterSigmas(slant_range=30.0, slant_out=30.0, velocity_out=3.0)
DISP_SIG = np.r_[[3.0] * 3, [np.deg2rad(0.5)] * 3, [300.0] * 3]


_IMU = ImuArrays  # the workbench's own type (was a duck-typed copy)


_Bridge = GapBridge  # the workbench's own type (was a duck-typed copy)


def _truth(t: np.ndarray) -> dict:
    lat, lon = np.deg2rad(-2.05), np.deg2rad(-6.2)
    u = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    east = np.cross(EZ, u)
    east /= np.linalg.norm(east)
    p0 = (R_GROUND + 8000.0) * u
    v = -80.0 * u + 10.0 * east + np.cross(OM, p0)
    p = p0 + t[:, None] * v
    spin, a1, w1, a2, w2 = np.deg2rad(5.0), np.deg2rad(8.0), 2 * np.pi / 7, np.deg2rad(5.0), 2 * np.pi / 11
    psi, phi, th = spin * t, a1 * np.sin(w1 * t), a2 * np.sin(w2 * t)
    dpsi, dphi, dth = spin + 0 * t, a1 * w1 * np.cos(w1 * t), a2 * w2 * np.cos(w2 * t)
    qv = dcm_to_quat(np.stack([east, np.cross(u, east), u], axis=1))
    qz, qx, qy = (quat_from_rotvec(a[:, None] * e) for a, e in ((psi, EZ), (phi, EX), (th, EY)))
    q = quat_multiply(quat_multiply(quat_multiply(qv, qz), qx), qy)
    Cx, Cy = quat_to_dcm(qx), quat_to_dcm(qy)
    w = np.einsum("nji,nj->ni", Cy, np.einsum("nji,j->ni", Cx, EZ) * dpsi[:, None] + dphi[:, None] * EX)
    w = w + dth[:, None] * EY
    f = -np.einsum("nji,nj->ni", quat_to_dcm(q), gravity_j2(p, MARS))
    return dict(v=np.broadcast_to(v, p.shape).copy(), p=p, q=q, w_G=w, f_G=f)


@pytest.fixture(scope="module")
def fixture():
    t = np.round(np.arange(0.0, 40.0 + 1e-9, 0.1), 10)
    t = np.union1d(t, np.round(np.arange(10.0, 11.0, 0.01), 10))  # a 100 Hz stretch
    tr = _truth(t)
    ia, ib = int(np.argmin(abs(t - 20.0))), int(np.argmin(abs(t - 22.0)))
    Ca, Cb = quat_to_dcm(tr["q"][ia]).T, quat_to_dcm(tr["q"][ib]).T
    dp = tr["p"][ib] - tr["p"][ia]
    br = _Bridge(
        float(t[ia]),
        float(t[ib]),
        Ca @ (tr["v"][ib] - tr["v"][ia]),
        Ca @ dp,
        Ca @ (dp - tr["v"][ia] * (t[ib] - t[ia])),
        Cb @ Ca.T,
    )
    keep = np.ones(t.size, bool)
    keep[ia + 1 : ib] = False
    n = int(keep.sum())
    imu = _IMU(t[keep], tr["f_G"][keep], tr["w_G"][keep], np.full((n, 3), 0.01), np.full((n, 3), 1e-4), [br])
    rng = np.random.default_rng(11)
    dx0 = DISP_SIG * rng.standard_normal((200, 9))
    accepted = rng.random(200) < 0.5
    mean = dx0[accepted].mean(axis=0)
    nominal = (tr["v"][0], tr["q"][0], tr["p"][0])
    disp = SimpleNamespace(
        dx0=dx0,
        accepted=accepted,
        refined_v0=nominal[0] + mean[0:3],
        refined_q0=quat_boxplus(nominal[1], mean[3:6]),
        refined_p0=nominal[2] + mean[6:9],
        refined_P0=np.cov(dx0[accepted], rowvar=False),
        events_t={"PDD": 5.0},
    )
    t_sr = np.array([15.037, 25.037, 35.037])
    t_rda = 18.013 + 0.1 * np.arange(int((39.9 - 18.013) / 0.1))
    return imu, nominal, disp, (t_sr, t_rda)


def _run(fixture, **kw) -> ValidationResult:
    imu, nominal, disp, times = fixture
    vs = ValidationSettings(n_runs=kw.pop("n_runs", 6), seed=5, sigmas=SIG, **kw)
    return validate_smoother(imu, nominal, disp, times, vs)


@pytest.fixture(scope="module")
def result(fixture) -> ValidationResult:
    return _run(fixture)


def _same(a: ValidationResult, b: ValidationResult) -> None:
    for name in ValidationResult.DETERMINISTIC:
        x, y = getattr(a, name), getattr(b, name)
        assert np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True), name


def test_noise_scale_matches_filter_psd():
    t = np.r_[0.0, 0.1, 0.2, 0.21, 0.22, 0.3, 0.4, 2.0, 2.1, 2.2]  # a gap 0.4 -> 2.0
    s, sample_dt = noise_scale(t, {6: None})
    assert sample_dt == pytest.approx(0.1)
    assert s[0] == pytest.approx(1.0) and s[-1] == pytest.approx(1.0) and s[7] == pytest.approx(1.0)
    assert s[3] == pytest.approx(np.sqrt(10.0))  # the 100 Hz samples: PSD σ² · sample_dt as the filter assumes


@pytest.mark.slow
def test_validation_consistent_and_shaped(result, fixture):
    res = result
    imu = fixture[0]
    n = imu.t.size
    assert not res.failed.any(), res.messages
    assert res.nees.shape == (6, n) and res.nees.dtype == np.float32
    assert res.rms_error.shape == (n, len(ERROR_NAMES)) == res.rms_sigma.shape
    assert np.all(np.isfinite(res.anees)) and np.all(np.isin(res.member, np.flatnonzero(fixture[2].accepted)))
    s = res.summary
    lo, hi = s["anees_band"]
    assert lo < 9.0 < hi
    # wide sanity band: a consistent smoother gives ≈ 9 (6 runs; time steps are correlated)
    assert 9.0 / 3.0 < s["anees_time_avg"] < 9.0 * 3.0, s["anees_time_avg"]
    assert set(s["anees_at"]) == {"start", "blackout_end", "PDD", "first_radar", "end"}
    assert all(np.isfinite(v) for v in s["anees_at"].values())
    # the radar fixes the altitude: RMS altitude error after the fix ≪ the initial 300 m spread
    assert s["rms_at"]["end"]["h_agl [m]"] < 60.0
    assert s["h_agl_after_fix"]["max_error_m"] < 150.0
    assert 0.9 < s["inside_3sigma_mean"] <= 1.0
    # RMS error of the reported σ of the same order as the RMS error (consistency, loosely)
    i = -1
    ratio = res.rms_error[i, 3] / res.rms_sigma[i, 3]
    assert 0.2 < ratio < 3.0
    for ch in ("slant_range", "slant_out", "velocity_out"):
        assert np.isfinite(s["nis_mean"][ch]["value"])


@pytest.mark.slow
def test_deterministic_per_seed(result, fixture):
    _same(result, _run(fixture))
    other = validate_smoother(*fixture, ValidationSettings(n_runs=6, seed=6, sigmas=SIG))
    assert not np.array_equal(other.nees, result.nees)


@pytest.mark.slow
def test_process_pool_identical(result, fixture):
    _same(result, _run(fixture, workers=2))


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("distributed") is None, reason="dask.distributed not installed")
def test_dask_local_identical(result, fixture):
    _same(result, _run(fixture, scheduler="local"))


def test_needs_accepted_members(fixture):
    imu, nominal, disp, times = fixture
    bad = SimpleNamespace(**{**vars(disp), "accepted": np.zeros(200, bool), "refined_P0": np.full((9, 9), np.nan)})
    with pytest.raises(ValueError, match="accepted"):
        validate_smoother(imu, nominal, bad, times, ValidationSettings(n_runs=2, seed=1))


def test_result_fields_documented():
    names = {f.name for f in fields(ValidationResult)}
    assert set(ValidationResult.DETERMINISTIC) <= names


@pytest.mark.slow
def test_recording_roundtrip(result, tmp_path):
    from workbench.problems.entry.recording_mc import record_entry_validation
    from workbench.recording.reader import read_recording

    rrd = record_entry_validation(tmp_path / "v_mc.rrd", "validation", result)
    data = read_recording(rrd)
    n = result.t.size
    assert data.row_count("/plots/validation/anees/smoothed") == n
    assert data.row_count("/plots/validation/rms/altitude/h_agl") == n
    assert data.row_count("/plots/validation/runs/nees/time_avg", "sample") == result.n_runs
    _, v = data.scalars("/plots/validation/anees/smoothed_curvilinear")
    assert np.allclose(np.ravel(v), result.anees_curvilinear)
    assert "ANEES (9 dof)" in data.text_document("/report")


@pytest.mark.slow
def test_gaussian_truths_about_a_given_start(fixture):
    """``start`` + ``truth_initial="gaussian"``: truths from the smoother's own initial distribution."""
    imu, nominal, disp, times = fixture
    P0 = np.diag(np.r_[[2.0] * 3, [np.deg2rad(0.3)] * 3, [200.0] * 3] ** 2)
    start = (nominal[0], nominal[1], nominal[2], P0)
    vs = ValidationSettings(n_runs=6, seed=2, sigmas=SIG, start=start, truth_initial="gaussian", events={})
    res = validate_smoother(imu, nominal, None, times, vs)
    assert np.all(res.member == -1) and not res.failed.any()
    assert 9.0 / 3.0 < res.summary["anees_time_avg"] < 9.0 * 3.0
    assert res.summary["truth_initial"] == "gaussian" and "PDD" not in res.times
    with pytest.raises(ValueError, match="truth_initial"):
        validate_smoother(imu, nominal, disp, times, ValidationSettings(n_runs=1, seed=1, truth_initial="members"))
