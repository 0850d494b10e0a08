"""post2 Monte Carlo against the truth (workbench/problems/post2/truth_mc.py): seeds, draws, scoring,
the study end to end on one member, its recording and table."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import ScenarioError, load_scenario
from workbench.problems.post2 import truth_mc as tmc
from workbench.problems.post2.problem import Post2Problem
from workbench.problems.post2.recording_mc import record_truth_mc, truth_mc_markdown
from workbench.recording.reader import read_recording

TOML = assets_dir() / "scenarios" / "post2_huygens.toml"


@pytest.fixture(scope="module")
def cfg():
    return Post2Problem().settings(load_scenario(TOML))


def test_streams_are_disjoint_and_members_distinct():
    tun = [tmc.member_seeds(7, "tuning", i) for i in range(20)]
    val = [tmc.member_seeds(7, "validation", i) for i in range(20)]
    seeds = [s[k] for s in tun + val for k in ("noise", "state", "params")]
    assert len(set(seeds)) == len(seeds)
    assert tmc.member_seeds(7, "validation", 3) == val[3]  # a pure function of (entropy, stream, member)


def test_parameters_are_the_estimated_ones_with_a_truth(cfg):
    names = tmc.parameter_names(cfg)
    assert names[:3] == ("ca_multiplier_fm", "ca_multiplier_hyp", "ca_multiplier_sup")
    assert "position" not in names and "density_multiplier" not in names  # no truth value: not scored
    assert cfg.truth.monte_carlo_draw_from_prior == names[:3]


def test_draws_follow_the_prior_each_from_its_own_stream(cfg):
    one = tmc.draw_parameters(cfg, 5, ("tilt",))
    both = tmc.draw_parameters(cfg, 5, ("tilt", "parachute_drag_multiplier"))
    assert set(one) == {"tilt"} and one["tilt"] == both["tilt"]  # the same draw whatever else is drawn
    s = cfg.state("parachute_drag_multiplier")
    lo, hi = s.bounds
    draws = np.array([tmc.draw_parameters(cfg, k, ("parachute_drag_multiplier",))["parachute_drag_multiplier"][0]
                      for k in range(400)])  # fmt: skip
    assert np.all((draws > lo) & (draws < hi))  # through the S-curve: inside the bounds
    assert abs(np.median(draws) - s.value[0]) < 0.2 * s.sigma[0] * 3  # centred on the prior


def test_member_settings_change_only_the_truth(cfg):
    seeds = tmc.member_seeds(1, "validation", 0)
    m = tmc.member_settings(cfg, seeds, ("ca_multiplier_fm",))
    assert m.states == cfg.states and m.monte_carlo == cfg.monte_carlo  # the estimator sees nothing new
    assert not np.allclose(m.truth.states["position"], cfg.truth.states["position"])
    assert m.truth.states["ca_multiplier_fm"] != cfg.truth.states["ca_multiplier_fm"]
    assert np.array_equal(m.truth.states["tilt"], cfg.truth.states["tilt"])  # planted, kept


def test_health_calibration_members_fly_dispersed_truths_where_the_scenario_has_a_delivered_covariance(cfg):
    prob = Post2Problem()
    a, b = prob.calibration_settings(cfg, 11), prob.calibration_settings(cfg, 12)
    assert not np.allclose(a.truth.states["position"], b.truth.states["position"])
    assert a.states == cfg.states  # the estimator's settings untouched
    j2 = prob.settings(load_scenario(assets_dir() / "scenarios" / "post2_j2.toml"))
    assert j2.monte_carlo.covariance is None and prob.calibration_settings(j2, 11) is j2


def test_draw_names_are_checked(tmp_path):
    text = TOML.read_text(encoding="utf-8").replace(
        'monte_carlo_draw_from_prior = ["ca_multiplier_fm"', 'monte_carlo_draw_from_prior = ["ca_multiplyer_fm"'
    )
    bad = tmp_path / "post2_huygens.toml"
    bad.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError, match="monte_carlo_draw_from_prior.*ca_multiplyer_fm"):
        Post2Problem().settings(load_scenario(bad))


def _run(nees, end_pos, z):
    e = np.asarray(end_pos, float)
    return {
        "nees": nees,
        "z": list(z),
        "start_error_m": 1.0,
        "trajectory": {
            q: {"end_nees": float(e @ e), "end_error": e.tolist(), "end_sigma": [1.0, 1.0, 1.0],
                "grid_mean_nees_smoothed": 3.0}
            for q in ("position", "velocity")
        },
    }  # fmt: skip


def test_aggregate_on_constructed_runs():
    runs = [_run(2.0, [1, 1, 1], [1.0, -1.0]), _run(4.0, [4, 0, 0], [3.5, 0.0])]
    a = tmc.aggregate(runs, ("p", "q"))
    assert a["mean_nees"] == 3.0 and a["dimension"] == 2 and a["verdict"] == "consistent"
    assert a["per_parameter_inside_3sigma"] == {"p": 0.5, "q": 1.0}
    tp = a["trajectory"]["position"]
    assert tp["end_mean_nees"] == 9.5 and tp["end_verdict"] == "overconfident"
    assert tp["end_per_axis_inside_3sigma"] == [0.5, 1.0, 1.0]
    assert tmc.verdict(0.1, tmc.mean_band(2, 3)) == "conservative"


def test_one_member_end_to_end_recorded(cfg, tmp_path):
    """The study on one validation member (no selection stage): scored against its own truth,
    consistent with itself, recorded with its table."""
    res = tmc.run_truth_monte_carlo(Post2Problem(), replace(cfg), n_runs=1, entropy=3, members=0, workers=1)
    s = res.summary
    assert s["runs_completed"] == 1 and not s["failed_members"]
    assert s["seed_stream"]["stream"] == "validation" and s["seed_stream"]["members"] == [0]
    assert len(s["parameters"]) == 9 and np.isfinite(s["mean_nees"])
    assert s["trajectory"]["position"]["end_per_axis_inside_3sigma"] == [1.0, 1.0, 1.0]
    assert res.grid_nees.shape == (1, res.t.size, 2) and np.all(np.isfinite(res.grid_nees))
    json.dumps(s)  # JSON-ready
    md = truth_mc_markdown(s)
    assert "validation" in md and "| ca_multiplier_fm |" in md
    rrd = record_truth_mc(tmp_path / "mc.rrd", "mc", res, s)
    rec = read_recording(rrd)
    assert "/plots/post2_truth_mc/grid_nees/position_mean" in rec.entities()
    t, v = rec.scalars("/plots/post2_truth_mc/grid_nees/position_mean")
    assert t.size == res.t.size and np.allclose(v[:, 0], res.grid_nees[0, :, 0])
    assert "Monte Carlo against the truth simulator" in rec.text_document()


def test_user_data_has_no_truth_monte_carlo(cfg, tmp_path):
    from workbench.problems.base import McOptions

    user = replace(cfg, run=replace(cfg.run, synthetic=False))
    with pytest.raises(ScenarioError, match=r"synthetic.*needs a synthetic scenario"):
        Post2Problem().monte_carlo(user, tmp_path, McOptions(n_runs=1), print)
