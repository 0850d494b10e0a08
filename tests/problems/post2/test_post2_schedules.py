"""post2 schedules (thesis [R3] Ch. 3.2.3): observation weights and system noise vs time or event —
validated with located errors, and applied by the pipeline (R / factor inside the window, Q + PSD dt)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import ScenarioError, load_scenario
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.pipeline import Channel, Estimator
from workbench.problems.post2.schedules import extra_psd, is_active, weight_factor

MER = assets_dir() / "scenarios" / "post2_mer_quaternion.toml"
J2 = assets_dir() / "scenarios" / "post2_j2.toml"


def test_the_mer_schedules_parse_with_si_psd():
    cfg = Post2Settings.from_scenario(load_scenario(MER))
    by = {s.name: s for s in cfg.schedules}
    q = by["quaternion_early"]
    assert q.target == "observation" and q.target_name == "attitude" and q.factor == 100.0
    assert q.end_event == "deceleration" and q.start_s is None
    r = by["rates_noise_late"]
    np.testing.assert_allclose(r.psd, 1e-6 * (np.pi / 180.0) ** 2)  # (deg/s)²/s -> (rad/s)²/s
    assert is_active(q, 100.0, ()) and not is_active(q, 100.0, ("deceleration",))
    assert not is_active(r, 100.0, ()) and is_active(r, 100.0, ("deceleration",))


def _j2(extra: dict):
    return load_scenario(J2).with_overrides(extra)


def test_time_windows_scale_r_and_add_q():
    sc = _j2(
        {
            "schedules.w": {"observation": "gravity", "weight_factor": 4.0, "start_s": 200.0, "end_s": 500.0},
            "schedules.w2": {"observation": "gravity", "weight_factor": 2.0, "start_s": 400.0},
            "schedules.n": {"state": "j2", "psd": 1e-9, "start_s": 300.0},
        }
    )
    cfg = Post2Settings.from_scenario(sc)
    assert weight_factor(cfg.schedules, "gravity", 100.0, ()) == 1.0
    assert weight_factor(cfg.schedules, "gravity", 200.0, ()) == 4.0
    assert weight_factor(cfg.schedules, "gravity", 450.0, ()) == 8.0  # overlapping windows multiply
    assert weight_factor(cfg.schedules, "gravity", 500.0, ()) == 2.0  # end_s closes the window
    est = Estimator(cfg)
    spec = cfg.observations[0]
    t = np.array([100.0, 250.0])
    R = np.full((2, 1, 1), 1e-10)
    ch = Channel(spec, t, np.ones((2, 1)), np.ones((2, 1)), R)
    assert est.measurement(ch, 0).R[0, 0] == pytest.approx(1e-10)
    assert est.measurement(ch, 1).R[0, 0] == pytest.approx(1e-10 / 4.0)
    assert est.weight_log["gravity"] == [(100.0, 1.0), (250.0, 4.0)]
    Q0, _ = est.q_matrix(10.0, 0.0)
    Q1, _ = est.q_matrix(10.0, 300.0)
    assert Q0[6, 6] == 0.0 and Q1[6, 6] == pytest.approx(1e-8)  # constant J2 gets noise only in the window
    assert np.array_equal(est.q_matrix(10.0)[0], Q0)  # no time: no window (the phase-1 call)


def test_event_windows_follow_the_estimators_phase():
    sc = _j2(
        {
            "events.mark": {"when": "time", "value": 300.0},
            "schedules.n": {"state": "velocity", "psd": 1e-6, "start_event": "mark"},
        }
    )
    cfg = Post2Settings.from_scenario(sc)
    est = Estimator(cfg)
    x = est.x0
    est.transition(x, 200.0, 300.0)  # checks events at t0 = 200: not yet
    assert est.phase["fired"] == ()
    assert np.all(extra_psd(cfg.schedules, "velocity", 3, 250.0, est.phase["fired"]) == 0.0)
    _, _, Q = est.transition(x, 300.0, 400.0)
    assert est.phase["fired"] == ("mark",)
    np.testing.assert_allclose(np.diag(Q)[3:6], 1e-6 * 100.0)


@pytest.mark.parametrize(
    ("table", "key", "message"),
    [
        ({"observation": "gravty", "weight_factor": 2.0}, "schedules.s.observation", "did you mean 'gravity'"),
        ({"state": "ca_multiplier", "psd": 1.0}, "schedules.s.state", "unknown estimated state 'ca_multiplier'"),
        ({"observation": "gravity", "weight_factor": 2.0, "state": "j2"}, "schedules.s", "exactly one target"),
        ({"observation": "gravity"}, "schedules.s.weight_factor", "missing"),
        ({"observation": "gravity", "weight_factor": 0.0}, "schedules.s.weight_factor", "must be > 0"),
        ({"observation": "gravity", "weight_factor": 2.0, "psd": 1.0}, "schedules.s.psd", "not `psd`"),
        ({"state": "j2", "psd": -1.0}, "schedules.s.psd", "must be >= 0"),
        ({"state": "velocity", "psd": [1.0, 2.0]}, "schedules.s.psd", "expected 3 number(s)"),
        ({"state": "j2", "psd": 1.0, "start_event": "chute"}, "schedules.s.start_event", "unknown event 'chute'"),
        ({"state": "j2", "psd": 1.0, "start_s": 5.0, "end_s": 5.0}, "schedules.s.end_s", "must be after start_s"),
        ({"state": "j2", "psd": 1.0, "start_s": 5.0, "start_event": "x"}, "schedules.s.start_event", "not both"),
        ({"state": "j2", "psd": 1.0, "wieght": 1.0}, "schedules.s.wieght", "unknown key 'wieght'"),
    ],
)
def test_schedule_mistakes_are_located(table, key, message):
    with pytest.raises(ScenarioError) as ei:
        Post2Settings.from_scenario(_j2({"schedules.s": table}))
    assert ei.value.key == key and message in str(ei.value) and "post2_j2.toml" in str(ei.value)


def test_markov_states_take_no_schedule():
    sc = _j2({"states.j2.process": "markov", "states.j2.tau_s": 50.0, "schedules.s": {"state": "j2", "psd": 1.0}})
    with pytest.raises(ScenarioError, match="markov") as ei:
        Post2Settings.from_scenario(sc)
    assert ei.value.key == "schedules.s.state"
