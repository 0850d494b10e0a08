"""post2: the truth headline of a synthetic run (end position, estimated parameters) judged against the
run's own 3σ, a parameter the data do not inform never PASS, an event time read from the data, and the
model's end beyond the data one warning (not one per phased file) (issue 26 / issue 29 items 1, 3, 4, 5)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from workbench.estimation.calibration import finish_health
from workbench.io.assets import assets_dir
from workbench.io.scenario import ScenarioError, load_scenario
from workbench.problems.base import RunOptions
from workbench.problems.post2 import huygens, pipeline
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.problem import Post2Problem
from workbench.problems.post2.scoring import score

MAIN_ONLY = """
[scenario]
name = "huygens_main_only"
kind = "post2"
[model]
dof = 3
t_end_s = 240.0
step_s = 2.0
[environment]
body = "titan"
atmosphere = "table"
table_file = "{atm}"
[vehicle]
file = "huygens"
mass_kg = 207.64
ref_area_m2 = 1.34
drogue_area_m2 = 7.23
drogue_cd = 0.55
[events.main]
when = "time"
value = 0.0
parachute = true
chute = "main"
[states.position]
value = [2725000.0, 0.0, 0.0]
sigma = 200.0
[states.velocity]
value = [-150.0, 0.0, 0.0]
sigma = 1.0
[states.parachute_drag_multiplier]
value = 1.0
sigma = 0.2
bounds = [0.6, 1.6]
[states.drogue_drag_multiplier]    # no drogue phase here: nothing informs it
value = 1.0
sigma = 0.2
bounds = [0.4, 2.2]
[observations.accel]
quantity = "acceleration_axial"
rate_hz = 1.0
noise_sigma = 0.01
sigma = 0.01
[observations.pressure]
quantity = "log_pressure"
rate_hz = 0.5
noise_sigma = 0.005
sigma = 0.005
[filter]
smoother = false
[truth]
rtol = 1e-8
output_step_s = 0.5
[truth.states]
position = [2725100.0, 0.0, 0.0]
velocity = [-150.5, 0.0, 0.0]
parachute_drag_multiplier = 1.14
[truth.tolerances]
parachute_drag_multiplier = 0.02
[synthetic]
seed = 2
"""


@pytest.fixture(scope="module")
def main_only(tmp_path_factory):
    """(settings, synthesized telemetry, truth, result) of the short main-chute descent."""
    tmp = tmp_path_factory.mktemp("main_only")
    p = tmp / "main_only.toml"
    p.write_text(MAIN_ONLY.format(atm=(assets_dir() / "scenarios" / "post2_huygens_atmosphere.csv").as_posix()))
    prob = Post2Problem()
    settings = prob.settings(load_scenario(p))
    syn = prob.synthesize(settings, tmp / "tel", 2)
    res = list(prob.reconstruct(settings, syn.telemetry, RunOptions(seed=2)))[-1]
    return settings, syn, prob.load_truth(syn.truth), res


def test_headline_ok_on_the_clean_run_and_error_when_the_truth_lies_outside_3sigma(main_only):
    _, _, truth, res = main_only
    sc = score(res, truth)
    names = [h["name"] for h in sc["headline"]]
    assert names == ["end_position", "param.parachute_drag_multiplier", "param.drogue_drag_multiplier"]
    end = sc["headline"][0]
    assert len(end["error"]) == 3 and len(end["sigma"]) == 3 and end["unit"] == "m"
    clean = finish_health(res.summary["health"], None, sc)
    checks = {c["name"]: c for c in clean["checks"]}
    assert checks["truth.end_position"]["status"] == "OK", checks["truth.end_position"]
    assert checks["truth.param.parachute_drag_multiplier"]["status"] == "OK"
    # the truth moved 10σ along y at the end: the same run is now off by 10σ of its own covariance
    moved = copy.deepcopy(truth)
    moved["position"] = moved["position"] + np.array([0.0, 10.0 * end["sigma"][1], 0.0])
    bad = finish_health(res.summary["health"], None, score(res, moved))
    c = {c["name"]: c for c in bad["checks"]}["truth.end_position"]
    assert bad["verdict"] == "ERROR" and c["status"] == "ERROR", c
    assert "outside its reported 3σ" in c["message"]


def test_a_parameter_the_data_do_not_inform_never_passes(main_only):
    _, _, truth, res = main_only
    rows = {r["parameter"]: r for r in huygens.planted_table(res, truth)}
    drogue, main = rows["drogue_drag_multiplier"], rows["parachute_drag_multiplier"]
    assert drogue["sigma_ratio"] > pipeline.INFORMED_RATIO and not drogue["informed"] and not drogue["pass"]
    assert drogue["inside_3sigma"]  # at its prior, the truth (1.0) is inside: it would have "passed"
    assert main["informed"] and main["sigma_ratio"] < 0.3 and main["pass"], main
    md = huygens.planted_markdown(list(rows.values()))
    assert "not informed by the data" in md.split("drogue_drag_multiplier")[1].splitlines()[0]
    notes = res.summary["health"]["notes"]
    assert any("not informed by the data" in n and "drogue_drag_multiplier" in n for n in notes), notes
    assert not any("parachute_drag_multiplier" in n for n in notes), notes


def _detecting(settings_path, extra: dict) -> Post2Settings:
    sc = load_scenario(settings_path)
    ev = sc.data["events"]["main"]
    ev.pop("value")
    ev.update({"detect_in": ["accel"], "truth_when": "time", "truth_value": 0.0, **extra})
    return Post2Settings.from_scenario(sc)


def _accel_csv(path, t, a):
    rows = "\n".join(f"{ti:.3f},{ai:.6f}" for ti, ai in zip(t, a, strict=True))
    path.write_text("time [s],ax [m/s^2]\n" + rows + "\n", encoding="utf-8")


def test_event_time_read_from_the_data_and_a_located_error_without_a_shock(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(MAIN_ONLY.format(atm=(assets_dir() / "scenarios" / "post2_huygens_atmosphere.csv").as_posix()))
    cfg = _detecting(p, {})
    t = np.arange(0.0, 200.0, 0.5)
    pulse = -60.0 * np.exp(-0.5 * ((t - 40.0) / 8.0) ** 2)  # the entry pulse, then the chute's shock at 120.2 s
    a = pulse + np.where(t > 120.2, -20.0, 0.0) + np.random.default_rng(0).normal(0.0, 0.02, t.size)
    _accel_csv(tmp_path / "accel.csv", t, a)
    out, facts = pipeline.detect_event_times(cfg, {"accel": tmp_path / "accel.csv"})
    assert out.events[0].value == pytest.approx(120.25) and "read from accel.csv" in facts[0]
    _accel_csv(tmp_path / "flat.csv", t, pulse)  # no opening shock in the file
    with pytest.raises(ScenarioError, match=r"events\.main\.detect_in.*no rise of \|a\|"):
        pipeline.detect_event_times(cfg, {"accel": tmp_path / "flat.csv"})
    with pytest.raises(ScenarioError, match=r"events\.main\.detect_in.*'pressure' is not"):
        pipeline.detect_event_times(_detecting(p, {"detect_in": ["pressure"]}), {"pressure": tmp_path / "accel.csv"})
    sc = load_scenario(p)
    sc.data["events"]["main"]["detect_in"] = ["accel"]  # and the value too: one or the other
    with pytest.raises(ScenarioError, match=r"events\.main\.value"):
        Post2Settings.from_scenario(sc)


def test_model_end_beyond_all_the_data_is_one_warning_a_channel_ending_early_none(main_only, tmp_path):
    settings, syn, _, _ = main_only
    data = pipeline.read_observations(settings, syn.telemetry)
    assert data.facts == () and data.notes == ()
    cut = {}
    for name, path in syn.telemetry.items():  # every file ends at 100 s of the 240 s span
        lines = path.read_text(encoding="utf-8").splitlines()
        keep = [ln for ln in lines if not ln[:1].isdigit() or float(ln.split(",")[0]) <= 100.0]
        cut[name] = tmp_path / path.name
        cut[name].write_text("\n".join(keep) + "\n", encoding="utf-8")
    data = pipeline.read_observations(settings, cut)
    assert data.facts == ()
    assert len(data.notes) == 1 and "runs 140 s past the data" in data.notes[0], data.notes
    data = pipeline.read_observations(settings, {**syn.telemetry, "accel": cut["accel"]})  # one channel only
    assert data.notes == () and data.facts == ()


def test_the_huygens_ekf_starts_from_the_delivered_state_and_full_covariance():
    cfg = Post2Settings.from_scenario(load_scenario(assets_dir() / "scenarios" / "post2_huygens.toml"))
    est = pipeline.Estimator(huygens.start_from_delivered(cfg))
    sm = est.smap
    idx = np.r_[np.arange(sm.blocks["position"].se.start, sm.blocks["position"].se.stop),
                np.arange(sm.blocks["velocity"].se.start, sm.blocks["velocity"].se.stop)]  # fmt: skip
    np.testing.assert_allclose(est.P0[np.ix_(idx, idx)], huygens.delivered_covariance(cfg), rtol=1e-12)
    np.testing.assert_allclose(sm.raw(est.x0, "position"), cfg.state("position").value)
    others = np.setdiff1d(np.arange(sm.n_e), idx)
    assert not np.any(est.P0[np.ix_(idx, others)])  # no correlation with the parameters
