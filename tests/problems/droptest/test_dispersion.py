"""Every Monte Carlo seed is a different drop: the draw, its envelope, and (slow) the
reconstruction of a few different drops against their truth.

The slow test uses the first natural seeds (1..4), not picked to pass.  If the reported σ are
right, a max-stroke error outside 3σ has probability 0.0027 per drop (≈ 1 % for one of four);
the restitution error is checked against its reported σ, which carries the estimation and the
definition terms (``stroke.restitution_definitions``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.io.scenario import load_scenario
from workbench.problems.droptest.problem import DropTestProblem
from workbench.problems.droptest.synthetic import (
    DROP_PARAMETER_NAMES,
    PSI,
    REDLAND_ENVELOPE,
    disperse_drop,
    dispersed_truth,
    drop_config,
    drop_rng,
)

SCENARIOS = Path(__file__).resolve().parents[3] / "assets" / "scenarios"
ENV = REDLAND_ENVELOPE


def _settings(name: str, overrides: dict | None = None):
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    return DropTestProblem().settings(sc.with_overrides(overrides) if overrides else sc)


def _base(name: str):
    return drop_config(_settings(name).synthetic)


def _inside(x: float, lo_hi: tuple[float, float]) -> bool:
    return lo_hi[0] <= x <= lo_hi[1]


def test_disperse_drop_draws_different_drops_inside_the_envelope():
    base = _base("droptest")
    drops = [disperse_drop(base, drop_rng(seed), 60.0) for seed in range(1, 21)]
    vn = np.array([d.impact_normal_speed for d in drops])
    vp = np.array([d.impact_parallel_speed for d in drops])
    eul = np.array([d.release_euler123_deg for d in drops])
    psi = np.array([d.pressure_pa for d in drops]) / PSI
    assert np.unique(vn).size == 20 and np.unique(vp).size == 20 and np.unique(eul[:, 2]).size == 20
    assert all(_inside(v, ENV.normal_mps) for v in vn) and all(_inside(v, ENV.parallel_mps) for v in vp)
    assert all(_inside(p, ENV.pressure_psi) for p in psi)
    d_att = eul - np.asarray(base.release_euler123_deg)
    assert np.all(np.abs(d_att[:, :2]) <= ENV.tilt_deg) and np.all(np.abs(d_att[:, 2]) <= ENV.yaw_deg)
    # the draws cover the envelope, not one corner of it
    assert np.ptp(vn) > 0.5 * np.diff(ENV.normal_mps)[0] and np.ptp(vp) > 0.5 * np.diff(ENV.parallel_mps)[0]
    # the same seed is the same drop; the scenario's own drop is untouched
    assert disperse_drop(base, drop_rng(3), 60.0) == drops[2]
    assert base == _base("droptest")


def test_an_off_spec_scenario_pressure_is_kept():
    base = _base("droptest_fullstroke")
    assert disperse_drop(base, drop_rng(1), 60.0).pressure_pa == base.pressure_pa == pytest.approx(0.05 * PSI)


def test_contact_timing_follows_the_rigs_ramp_angle():
    """The release-to-contact time is drawn as a fraction of v_parallel / (g sin α) of the rig's own α."""
    base = _base("droptest")
    a, b = disperse_drop(base, drop_rng(4), 60.0), disperse_drop(base, drop_rng(4), 45.0)
    assert a.impact_parallel_speed == b.impact_parallel_speed
    assert b.release_to_contact_s / a.release_to_contact_s == pytest.approx(
        np.sin(np.radians(60)) / np.sin(np.radians(45))
    )


@pytest.mark.parametrize("seed", [2, 3, 4])
def test_monte_carlo_drops_on_a_45_degree_rig_hit_at_the_requested_speeds(seed):
    """A Monte Carlo drop (disperse_drop + the truth simulation) on a 45° ramp makes first contact at
    its target normal and parallel speeds, measured in the 45° ramp's own frame.

    Tolerance 6 %: the release design is a point-mass energy calculation with the test plan's
    bungee, while the truth flies the rigid lander with the true bungee (0.97–1.06 × the plan), so
    the flown speeds miss the targets by a few per cent on the shipped 60° rig too (measured seeds
    1–6 at 60°: up to 5.1 %; at 45° after the fix, seeds 2–6: up to 3.5 %).  Before the fix (the
    60° Mars frame and 60° timing on a 45° ramp) the same drops missed by 18–37 %."""
    st = _settings("droptest", {"chamber.ramp_angle_deg": 45.0})
    truth, _, surf = dispersed_truth(st, seed)
    c = truth.config
    t_c = truth.events["first_contact"]
    v = np.array([np.interp(t_c, truth.t, truth.v_I[:, i]) for i in range(3)])
    n = surf.normal
    vn, vp = -(v @ n), np.linalg.norm(v - (v @ n) * n)
    assert vn == pytest.approx(c.impact_normal_speed, rel=0.06)
    assert vp == pytest.approx(c.impact_parallel_speed, rel=0.06)


@pytest.mark.slow
def test_four_different_drops_are_reconstructed_inside_their_3sigma(tmp_path):
    from workbench.problems.droptest.montecarlo import run_seed

    st = _settings("droptest")
    res = [run_seed(st, seed, tmp_path) for seed in (1, 2, 3, 4)]
    col = {name: np.array([r.drop[j] for r in res]) for j, name in enumerate(DROP_PARAMETER_NAMES)}
    # the drops differ: truth contact speeds and attitude
    for name in ("impact_normal_truth_mps", "impact_parallel_truth_mps", "yaw_deg", "roll_deg", "bag_pressure_psi"):
        assert np.unique(np.round(col[name], 6)).size == 4, f"{name} repeats: {col[name]}"
    assert np.ptp(col["impact_normal_truth_mps"]) > 0.5 and np.ptp(col["impact_parallel_truth_mps"]) > 0.5
    # each inside the envelope: targets inside it, the flown contact speeds within 10 % of them
    for k, r in enumerate(res):
        assert _inside(col["impact_normal_target_mps"][k], ENV.normal_mps)
        assert _inside(col["impact_parallel_target_mps"][k], ENV.parallel_mps)
        assert _inside(col["bag_pressure_psi"][k], ENV.pressure_psi)
        for kind in ("normal", "parallel"):
            tgt, flown = col[f"impact_{kind}_target_mps"][k], col[f"impact_{kind}_truth_mps"][k]
            assert abs(flown - tgt) <= 0.1 * tgt, f"seed {r.seed}: {kind} contact speed {flown:.2f} vs {tgt:.2f}"
    # max stroke: the truth inside the reported 3σ on every drop (or say which failed)
    bad = [
        f"seed {r.seed}: error {r.error * 100:+.1f} cm = {r.error / r.sigma:+.2f}σ" for r in res if not r.inside_3sigma
    ]
    assert not bad, "max stroke outside 3σ: " + "; ".join(bad)
    # restitution: where a rebound is defined, the error inside its reported 3σ
    rest = [r for r in res if np.isfinite(r.restitution_error)]
    assert rest, "no drop with a defined restitution"
    bad = [
        f"seed {r.seed}: error {r.restitution_error:+.4f} = {r.restitution_error / r.restitution_sigma:+.2f}σ"
        for r in rest
        if abs(r.restitution_error) > 3.0 * r.restitution_sigma
    ]
    assert not bad, "restitution outside 3σ: " + "; ".join(bad)


def test_calibration_members_fly_the_monte_carlo_drop_of_their_seed(tmp_path):
    """The health calibration's member ``seed`` (``calibration_settings``) flies the truth Monte
    Carlo's drop ``seed`` (``disperse_drop`` on ``drop_rng(seed)``), not the scenario's own drop:
    the bands cover honest drops across the envelope; the sensors and the survey are the scenario's."""
    problem = DropTestProblem()
    settings = _settings("droptest_fullstroke")
    member = problem.calibration_settings(settings, 7)
    drawn = disperse_drop(drop_config(settings.synthetic), drop_rng(7), settings.chamber.ramp_angle_deg)
    got = drop_config(member.synthetic)
    assert got.impact_normal_speed == drawn.impact_normal_speed
    assert got.impact_parallel_speed == drawn.impact_parallel_speed
    assert got.release_euler123_deg == drawn.release_euler123_deg
    assert got.release_to_contact_s == drawn.release_to_contact_s
    assert got.pressure_pa == pytest.approx(drawn.pressure_pa, rel=1e-12)  # the scenario's off-spec pressure
    assert got != drop_config(settings.synthetic)
    assert member.accelerometer is settings.accelerometer and member.synthetic.seed == settings.synthetic.seed
    assert drop_config(problem.calibration_settings(settings, 7).synthetic) == got  # deterministic
    syn = problem.synthesize(member, tmp_path, 7)
    params = dict(zip(DROP_PARAMETER_NAMES, np.load(syn.truth)["drop_parameters"], strict=True))
    assert params["impact_normal_target_mps"] == drawn.impact_normal_speed
