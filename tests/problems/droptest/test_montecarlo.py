"""Monte Carlo driver of the drop test: executor independence and the summary statistics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.estimation.consistency import anees_bounds
from workbench.io.scenario import load_scenario
from workbench.problems.droptest.montecarlo import Z_NAMES, McResult, monte_carlo, summarize_mc
from workbench.problems.droptest.problem import DropTestProblem

SCENARIOS = Path(__file__).resolve().parents[3] / "assets" / "scenarios"


@pytest.mark.slow
def test_results_do_not_depend_on_the_executor(tmp_path):
    """Each task's randomness comes only from its seed: loop and 2-process pool agree exactly."""
    sc = DropTestProblem().settings(load_scenario(SCENARIOS / "droptest.toml"))
    seeds = [3, 1, 2]
    a = monte_carlo(sc, seeds, tmp_path / "loop")
    b = monte_carlo(sc, seeds, tmp_path / "pool", workers=2)
    assert a.executor == "loop" and b.executor.startswith("process pool")
    for name in McResult.DETERMINISTIC:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(a.seed, seeds)
    assert a.z_at_max.shape == (3, len(Z_NAMES)) and a.nees_blocks_mean.shape == (3, 4)
    # every task cleaned up its subfolder
    # nothing left behind: the work folders are removed (or at least empty)
    for d in (tmp_path / "loop", tmp_path / "pool"):
        assert not d.exists() or list(d.iterdir()) == [], list(d.iterdir())


def _fake(n: int, err: np.ndarray, sigma: np.ndarray) -> McResult:
    z = np.ones((n, len(Z_NAMES)))
    return McResult(
        scenario="fake", mode="kinematic", executor="none", total_wall_s=1.0,
        seed=np.arange(n), max_stroke=0.3 + err, sigma=sigma, truth=np.full(n, 0.3), error=err,
        inside_3sigma=np.abs(err) <= 3 * sigma, nees_pose_mean=np.full(n, 6.0),
        nees_pose_at_max=np.full(n, 12.0), nees_stroke=(err / sigma) ** 2,
        restitution_error=np.r_[np.nan, np.full(n - 1, 0.01)], z_at_max=z,
        nees_blocks_mean=np.full((n, 4), 3.0), wall_time_s=np.ones(n), reconstruct_s=np.ones(n),
    )  # fmt: skip


def test_summary_statistics():
    err = np.array([0.01, -0.02, 0.2, 0.05])
    sig = np.array([0.01, 0.01, 0.05, 0.04])  # 3σ: 0.03, 0.03, 0.15, 0.12
    s = summarize_mc(_fake(4, err, sig))
    assert s["n_runs"] == 4
    assert s["fraction_inside_3sigma"] == pytest.approx(0.75)  # run 2 (|−0.02| ≤ 0.03 ok), run 4 ok
    assert s["median_3sigma_m"] == pytest.approx(0.075)
    assert s["abs_error_median_m"] == pytest.approx(0.035)
    assert s["fraction_mer_requirement"] == pytest.approx(0.5)  # runs 1 and 2
    assert s["anees_pose_band"] == pytest.approx(list(anees_bounds(6, 4)))
    assert s["anees_pose_time_avg"] == pytest.approx(6.0)
    assert s["anees_pose_at_max"] == pytest.approx(12.0) and not s["anees_pose_at_max_inside"]
    assert s["anees_stroke"] == pytest.approx(np.mean((err / sig) ** 2))
    assert s["anees_stroke_band"] == pytest.approx(list(anees_bounds(1, 4)))
    assert s["restitution_abs_error_median"] == pytest.approx(0.01)  # NaN run ignored
    assert s["z2_at_max_mean"]["p.x"] == pytest.approx(1.0)


def test_a_failing_member_is_reported_and_the_others_kept(tmp_path, monkeypatch):
    """One member that raises (before: the whole Monte Carlo stopped with that member's error and the
    others' work was lost) is listed with its seed and error in the result, the summary, the
    scorecard and the headline; the statistics are over the others; all failing is an error."""
    from workbench.problems.droptest import montecarlo as mc
    from workbench.problems.droptest.recording_mc import mc_markdown as scorecard_markdown

    def fake_run_seed(settings, seed, work_dir):
        if seed == 7:
            raise ValueError("events.csv: the event times look 1000× too small\nsecond line")
        n = len(Z_NAMES)
        return mc.SeedResult(
            seed=seed, max_stroke=0.31, sigma=0.01, truth=0.3, error=0.01, inside_3sigma=True,
            nees_pose_mean=6.0, nees_pose_at_max=6.0, nees_stroke=1.0, restitution_error=0.0,
            z_at_max=np.ones(n), nees_blocks_mean=np.full(4, 3.0), wall_time_s=1.0, reconstruct_s=1.0,
        )  # fmt: skip

    monkeypatch.setattr(mc, "run_seed", fake_run_seed)
    sc = DropTestProblem().settings(load_scenario(SCENARIOS / "droptest.toml"))
    res = monte_carlo(sc, [5, 7, 9], tmp_path / "work")
    np.testing.assert_array_equal(res.seed, [5, 9])
    assert res.failed == (mc.FailedSeed(7, "ValueError: events.csv: the event times look 1000× too small"),)
    s = summarize_mc(res)
    assert s["n_runs"] == 2 and s["n_failed"] == 1 and s["failed_members"][0]["seed"] == 7
    assert "1 member(s) FAILED" in scorecard_markdown(s) and "seed 7: ValueError" in scorecard_markdown(s)
    monkeypatch.setattr(mc, "run_seed", lambda *a: (_ for _ in ()).throw(OSError("disk full")))
    with pytest.raises(RuntimeError, match="all 2 members failed; first: seed 5: OSError: disk full"):
        monte_carlo(sc, [5, 7], tmp_path / "work2")


def test_uncompressed_truth_of_a_member_holds_the_same_arrays(tmp_path):
    """A Monte Carlo member writes its truth.npz uncompressed (compress_truth=False): the same arrays."""
    from workbench.problems.droptest.synthetic import load_truth, synthesize_droptest

    sc = DropTestProblem().settings(load_scenario(SCENARIOS / "droptest.toml"))
    a = load_truth(synthesize_droptest(sc, tmp_path / "a", seed=5, disperse=True).truth_path)
    b = load_truth(synthesize_droptest(sc, tmp_path / "b", seed=5, disperse=True, compress_truth=False).truth_path)
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
