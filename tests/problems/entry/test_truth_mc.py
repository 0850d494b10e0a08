"""The entry Monte Carlo against the truth simulator (``problems/entry/truth_mc.py``), on 3 members.

Slow tier: each member is a 6-DOF truth simulation, telemetry files and a full reconstruction.
Checks the machinery, not the statistics (those are ``tests/benchmarks/bench_entry_truth_mc.py``):
the members' truths differ, their telemetry files were written and read back, the stage ANEES
equal an independent recomputation (member 0's NEES from a fresh reconstruction of its kept files
against its ``truth.npz``, with scipy's rotations), and the covariances are symmetric positive
definite.
"""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from workbench.cli import build_parser
from workbench.io.assets import asset_path
from workbench.io.scenario import load_scenario
from workbench.problems.entry import pipeline as en
from workbench.problems.entry.filter import EntryFilterResult
from workbench.problems.entry.problem import EntryProblem
from workbench.problems.entry.synthetic import TELEMETRY_FILES
from workbench.problems.entry.truth_mc import run_truth_monte_carlo

N_RUNS, MEMBERS, ROUNDS, SEED = 3, 500, 1, 11


def test_cli_routes_truth_sim_options():
    a = build_parser().parse_args(["mc", "schiaparelli", "--truth-sim", "--refine-rounds", "2", "--seeds", "4"])
    assert a.truth_sim is True and a.refine_rounds == 2 and a.seeds == 4
    b = build_parser().parse_args(["mc", "schiaparelli"])
    assert b.truth_sim is False and b.refine_rounds is None


@pytest.fixture(scope="module")
def mc(tmp_path_factory):
    sc = EntryProblem().settings(load_scenario(asset_path("scenarios", "schiaparelli.toml")))
    work = tmp_path_factory.mktemp("truth_mc")
    res = run_truth_monte_carlo(
        sc, n_runs=N_RUNS, seed=SEED, members=MEMBERS, refine_rounds=ROUNDS, scheduler="loop", work_dir=work
    )
    return sc, work, res


def _data_rows(path) -> list[list[float]]:
    """Data rows of a telemetry CSV, parsed here (comments '#', one header line)."""
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    return [[float(x) for x in ln.split(",")] for ln in lines[1:] if not ln.split(",")[1].isalpha()]


@pytest.mark.slow
def test_members_have_different_truths(mc):
    _, work, res = mc
    assert len(res.members) == N_RUNS and not any(m.scores.failed for m in res.members)
    specs = [m.info["truth_spec"] for m in res.members]
    for key in (
        "fpa_offset_deg",
        "speed_offset_mps",
        "initial_position_offset_km",
        "ca_deviation",
        "wind_layer_speeds_mps",
    ):
        assert len({str(s[key]) for s in specs}) == N_RUNS, key
    for key in ("imu_errors", "nominal_dx0"):  # every member its own sensor errors
        assert len({str(m.info[key]) for m in res.members}) == N_RUNS, key
    assert res.members[0].info["imu_errors"]  # drawn (not empty)
    pdd = [m.info["truth_events"]["PDD"] for m in res.members]
    assert len(set(pdd)) > 1  # different trajectories reach Mach 2 at different times
    digests = {hashlib.sha256((work / f"member_{k}" / "telemetry" / "gnc.csv").read_bytes()).hexdigest()
               for k in range(N_RUNS)}  # fmt: skip
    assert len(digests) == N_RUNS
    truths = [np.load(work / f"member_{k}" / "telemetry" / "truth.npz") for k in range(N_RUNS)]
    assert not np.allclose(truths[0]["p_M"][-1], truths[1]["p_M"][-1], atol=100.0)


@pytest.mark.slow
def test_telemetry_files_written_and_read_back(mc):
    _, work, res = mc
    for k, m in enumerate(res.members):
        folder = work / f"member_{k}" / "telemetry"
        for name in (*TELEMETRY_FILES.values(), "initial_state.toml"):
            assert (folder / name).is_file(), (k, name)
        rows = {
            s: len(_data_rows(folder / TELEMETRY_FILES[s])) for s in ("gnc", "gnc_nav", "rda_slant_range", "rda_out")
        }
        assert rows == m.info["rows_read"], k
        ev = {}
        for ln in (folder / "events.csv").read_text().splitlines():
            if ln and not ln.startswith("#") and not ln.startswith("time"):
                t, name = ln.split(",")
                ev[name] = float(t)
        assert m.info["events_read"] == pytest.approx(ev)
        assert m.times["PDD"] == pytest.approx(ev["PDD"])
        # the first radar epoch is the first valid radar time tag of the files (zero-filled packets skipped)
        sr = [r[0] for r in _data_rows(folder / "rda_slant_range.csv") if any(x > 0 for x in r[1:])]
        out = [r[0] for r in _data_rows(folder / "rda_out.csv") if r[1] > 0]
        assert m.info["t_fix_s"] == pytest.approx(min(sr[:1] + out[:1]))


def _nees_independent(sm, truth_npz, i: int) -> float:
    """NEES (9 dof) of smoothed sample i against the truth file, from scratch."""
    t = float(sm.t[i])
    tt = truth_npz["t"]
    v = np.array([np.interp(t, tt, truth_npz["v_M"][:, j]) for j in range(3)])
    p = np.array([np.interp(t, tt, truth_npz["p_M"][:, j]) for j in range(3)])
    q = np.array([np.interp(t, tt, truth_npz["q_M_G"][:, j]) for j in range(4)])
    dth = (Rotation.from_quat(sm.q_M_G[i]).inv() * Rotation.from_quat(q / np.linalg.norm(q))).as_rotvec()
    e = np.r_[v - sm.v_M[i], dth, p - sm.p_M[i]]
    return float(e @ np.linalg.solve(sm.P[i], e))


@pytest.mark.slow
def test_stage_anees_equal_manual_recomputation(mc):
    sc, work, res = mc
    s = res.summary
    # (a) every epoch's ANEES is the mean over members of each member's NEES at its own epoch sample
    for label in s["anees_at"]:
        vals = []
        for m in res.members:
            i = int(np.searchsorted(m.t, m.times[label] - 1e-9))
            vals.append(float(m.scores.nees[min(i, m.t.size - 1)]))
        assert s["anees_at"][label] == pytest.approx(np.mean(vals), rel=1e-5), label
    # (b) member 0's NEES recomputed from a fresh reconstruction of its kept files and its truth.npz
    folder = work / "member_0" / "telemetry"
    paths = {k: folder / v for k, v in TELEMETRY_FILES.items()} | {"initial_state": folder / "initial_state.toml"}
    sc0 = dataclasses.replace(sc, dispersion=dataclasses.replace(sc.dispersion, refine_rounds=ROUNDS, cloud=0))
    filt = next(st for st in en.reconstruct(sc0, paths, members=MEMBERS) if isinstance(st, EntryFilterResult))
    sm = filt.smoothed
    m0 = res.members[0]
    np.testing.assert_array_equal(sm.t, m0.t)
    with np.load(folder / "truth.npz") as z:
        truth_npz = {k: z[k] for k in ("t", "v_M", "p_M", "q_M_G")}
    for label, te in m0.times.items():
        i = int(np.searchsorted(sm.t, te - 1e-9))
        assert _nees_independent(sm, truth_npz, i) == pytest.approx(float(m0.scores.nees[i]), rel=1e-3), label
    # (c) covariances symmetric positive definite, forward and smoothed
    for P in (sm.P, filt.forward.P):
        assert np.allclose(P, np.swapaxes(P, 1, 2), rtol=0, atol=1e-9 * np.abs(P).max())
        assert np.all(np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, 1, 2)))[:, 0] > 0)
    assert s["covariance_symmetric_pd_all"] is True


@pytest.mark.slow
def test_summary_reports_noise_and_filter_R(mc):
    _, _, res = mc
    s = res.summary
    assert s["n_ok"] == N_RUNS and s["n_failed"] == 0
    assert {"range_sigma_m", "range_sigma_frac", "velocity_sigma_mps"} <= set(s["radar_noise_simulated"])
    assert {"slant_range_m", "slant_out_m", "velocity_out_mps"} <= set(s["filter_R"])
    lo, hi = s["anees_band"]
    assert 0 < lo < 9 < hi
    h = s["h_agl_at_fix"]
    assert np.isfinite(h["rms_error_m"]) and h["median_3sigma_m"] > 0
    assert set(s["nis_mean"]) == {"slant_range", "slant_out", "velocity_out"}
