"""post2 model pieces: S-curve, process models, aerodynamic angles, Jacobians vs analytic, batched Jacobian."""

from __future__ import annotations

import math

import numpy as np
import pytest

from workbench.estimation.ekf import ErrorStateLayout, numeric_jacobian_batched, numeric_measurement_jacobian
from workbench.io.assets import assets_dir
from workbench.io.scenario import load_scenario
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.model import (
    Environment,
    StateMap,
    TrajectoryModel,
    Vehicle,
    aero_angles,
    quat_from_aero_angles,
    scurve,
    scurve_inverse,
    scurve_slope,
)
from workbench.problems.post2.pipeline import Estimator

MU, RE = 4.2828287e13, 3393940.0


def test_scurve_keeps_the_physical_value_inside_its_bounds():
    lo, hi = 0.6, 1.6
    s = np.array([-1e6, -3.0, 0.6, 1.1, 1.5, 40.0])
    p = scurve(s, lo, hi)
    assert np.all((p >= lo) & (p <= hi))
    assert scurve(1.1, lo, hi) == pytest.approx(1.1)  # centre maps to itself
    assert scurve_slope(1.1, lo, hi) == pytest.approx(1.0)
    inner = np.array([0.61, 1.0, 1.59])
    np.testing.assert_allclose(scurve(scurve_inverse(inner, lo, hi), lo, hi), inner, rtol=1e-12)
    ds = 1e-6
    num = (scurve(1.4 + ds, lo, hi) - scurve(1.4 - ds, lo, hi)) / (2 * ds)
    assert scurve_slope(1.4, lo, hi) == pytest.approx(num, rel=1e-8)


def test_aero_angles_round_trip():
    r = np.array([-2833460.1, -1796348.4, -1072627.1])
    v = np.array([3532.51, -4171.4, 1338.9])
    ang = np.radians([3.0, -2.0, 40.0])
    q = quat_from_aero_angles(r, v, ang)
    np.testing.assert_allclose(aero_angles(r, v, q)[0], ang, atol=1e-12)


def _orbit_model(j2=1.9595e-3):
    sm = StateMap(["position", "velocity", "j2"])
    return TrajectoryModel(sm, 3, Environment(MU, RE, j2, RE, 0.0, None), Vehicle(1000.0, np.eye(3), None))


def test_gravity_magnitude_jacobian_matches_the_analytic_point_mass_gradient():
    m = _orbit_model()
    layout = ErrorStateLayout(7)
    x = np.array([3.0e6, 1.5e6, 1.0e6, 0.0, 3000.0, 1000.0, 0.0])  # J2 = 0: point mass
    ph = m.initial_phase()
    eps = np.array([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3, 1e-6])
    g0, H = numeric_jacobian_batched(lambda X: m.observe(X, "gravity_magnitude", ph), x, layout, eps)
    r = np.linalg.norm(x[:3])
    assert g0[0] == pytest.approx(MU / r**2, rel=1e-12)
    np.testing.assert_allclose(H[0, :3], -2.0 * MU / r**3 * x[:3] / r, rtol=1e-6)
    np.testing.assert_allclose(H[0, 3:6], 0.0, atol=1e-15)
    # d|g|/dJ2 at J2 = 0: -(3/2) GM Re^2 / r^4 (1 - 3 sin^2 phi) projected on r̂ (radial part of the J2 term)
    z2 = (x[2] / r) ** 2
    dg = 1.5 * MU * RE**2 / r**4 * (1.0 - 3.0 * z2)
    assert H[0, 6] == pytest.approx(dg, rel=1e-6)
    # the one-call-per-column engine function gives the same numbers
    H2 = numeric_measurement_jacobian(lambda xx: m.observe(xx, "gravity_magnitude", ph), x, layout, eps=eps)
    np.testing.assert_allclose(H, H2, rtol=1e-12, atol=1e-20)


def test_transition_jacobian_matches_analytic_free_flight():
    """The position/velocity block of F over a short step is
    [[I, dt I], [G dt, I]] to first order, G the point-mass gravity gradient."""
    m = _orbit_model(j2=0.0)
    layout = ErrorStateLayout(7)
    x = np.array([3.5e6, 0.0, 0.0, 0.0, 3000.0, 0.0, 0.0])
    dt = 0.1
    ph = m.initial_phase()
    _, F = numeric_jacobian_batched(
        lambda X: m.propagate(X, 0.0, dt, ph, dt),
        x,
        layout,
        np.array([1, 1, 1, 1e-3, 1e-3, 1e-3, 1e-6]),
        out_layout=layout,
    )
    r = 3.5e6
    G = MU / r**3 * (3.0 * np.diag([1.0, 0.0, 0.0]) - np.eye(3))
    np.testing.assert_allclose(F[:3, 3:6], dt * np.eye(3), atol=1e-6)
    # first order in dt: the O(dt²) terms (gradient change along v dt) are ~1e-4 of G dt
    np.testing.assert_allclose(F[3:6, :3], G * dt, rtol=1e-3, atol=1e-3 * np.abs(G * dt).max())
    np.testing.assert_allclose(F[6, :6], 0.0, atol=1e-12)


def test_process_models_random_walk_and_markov(tmp_path):
    sc = load_scenario(assets_dir() / "scenarios" / "post2_j2.toml")
    sc = sc.with_overrides(
        {
            "states.j2.process": "markov",
            "states.j2.tau_s": 50.0,
            "states.velocity.process": "random_walk",
            "states.velocity.psd": 4e-6,
        }
    )
    est = Estimator(Post2Settings.from_scenario(sc))
    Q, phis = est.q_matrix(10.0)
    np.testing.assert_allclose(np.diag(Q)[3:6], 4e-5)  # PSD x dt
    phi = math.exp(-10.0 / 50.0)
    assert phis["j2"] == pytest.approx(phi)
    assert Q[6, 6] == pytest.approx((2.0e-3) ** 2 * (1.0 - phi**2))  # stationary 1σ = prior 1σ
    x = est.x0.copy()
    x[6] = 1.0e-3
    y = est.advance(x[None], 0.0, 10.0, est.phase, phis)[0]
    assert y[6] == pytest.approx(phi * 1.0e-3)  # decays towards the initial value 0


def test_events_fire_on_time_and_on_conditions():
    from workbench.core.atmosphere import MarsEngineeringAtmosphere
    from workbench.models.aerodynamics import load_vehicle
    from workbench.problems.post2.model import Event

    veh = load_vehicle(assets_dir() / "vehicles" / "mer_like.toml")
    events = (
        Event("chute", "mach_below", 2.0, parachute=True),
        Event("shield", "time", 30.0, mass=700.0, ref_area=4.0),
        Event("low", "altitude_below", 5000.0),
    )
    env = Environment(4.2828e13, 3396190.0, 0.0, 3396190.0, 0.0, MarsEngineeringAtmosphere())
    m = TrajectoryModel(
        StateMap(["position", "velocity"]), 3, env, Vehicle(827.0, np.eye(3), veh.capsule, veh.parachute), events
    )
    ph = m.initial_phase()
    fast = np.array([3396190.0 + 10000.0, 0.0, 0.0, 0.0, 1000.0, 0.0])  # 10 km, ~Mach 4
    slow = np.array([3396190.0 + 10000.0, 0.0, 0.0, 0.0, 300.0, 0.0])  # ~Mach 1.3
    assert m.event_margin(fast, events[0]) > 0 > m.event_margin(slow, events[0])
    p1 = m.check_events(fast, 10.0, ph)
    assert p1["fired"] == () and not p1["parachute"] and p1["mass"] == 827.0
    p2 = m.check_events(slow, 31.0, p1)
    assert p2["fired"] == ("chute", "shield") and p2["parachute"] and p2["mass"] == 700.0 and p2["area"] == 4.0
    # the open parachute adds drag along -v_rel
    a1 = m.derivative(slow, p1)[3:6] - m.gravity(slow)
    a2 = m.derivative(slow, p2)[3:6] - m.gravity(slow)
    assert a2[1] < a1[1] < 0.0


def test_truth_locates_a_condition_event_and_switches_phase():
    from workbench.problems.post2.truth import simulate_truth

    sc = load_scenario(assets_dir() / "scenarios" / "post2_entry6dof.toml").with_overrides(
        {
            "model.dof": 3,
            "truth.output_step_s": 0.5,
            "truth.rtol": 1e-8,
            "events.chute": {"when": "altitude_below", "value": 25000.0, "parachute": True},
        }
    )
    for k in ("attitude", "body_rates", "cn_multiplier", "cm_multiplier"):
        sc.data["states"].pop(k)
    sc.data["truth"]["states"].pop("attitude")
    sc.data["truth"]["states"].pop("body_rates")
    sc.data["observations"].pop("rates")
    tr = simulate_truth(Post2Settings.from_scenario(sc))
    ((t_ev, name),) = tr["events"]
    assert name == "chute"
    m = tr["model"]
    h = m.altitude(tr["x"])
    k = np.searchsorted(tr["t"], t_ev)
    assert h[k - 1] > 25000.0 > h[k]  # located between the samples that bracket the crossing
    assert tr["phase_index"][k - 1] == 0 and tr["phase_index"][k] == 1 and tr["phases"][1]["parachute"]


def test_truth_time_event_on_a_grid_sample_keeps_every_sample_once():
    from workbench.problems.post2.truth import simulate_truth

    sc = load_scenario(assets_dir() / "scenarios" / "post2_j2.toml").with_overrides(
        {"model.t_end_s": 1000.0, "events.mark": {"when": "time", "value": 300.0, "mass_kg": 900.0}}
    )
    tr = simulate_truth(Post2Settings.from_scenario(sc))
    assert np.all(np.diff(tr["t"]) > 0) and tr["t"][-1] == 1000.0 and tr["t"].size == 101
    assert tr["events"] == [(300.0, "mark")]
    # a sample at the event time still belongs to the old phase (as in the estimator, which checks
    # events at the start of each step)
    assert tr["phase_index"][30] == 0 and tr["phase_index"][31] == 1
    # vacuum, mass change only: the orbit continues smoothly through the event
    plain = load_scenario(assets_dir() / "scenarios" / "post2_j2.toml").with_overrides({"model.t_end_s": 1000.0})
    ref = simulate_truth(Post2Settings.from_scenario(plain))
    np.testing.assert_allclose(tr["x"], ref["x"], rtol=0, atol=1e-3)


def test_tabulated_atmosphere_from_the_problem_file():
    from workbench.io.scenario import ScenarioError
    from workbench.problems.post2 import build

    sc = load_scenario(assets_dir() / "scenarios" / "post2_entry6dof.toml").with_overrides(
        {
            "environment.atmosphere": "table",
            "environment.table_altitude_m": [0.0, 50e3, 150e3],
            "environment.table_density_kg_m3": [0.015, 1.5e-4, 1e-9],
            "environment.table_pressure_pa": [600.0, 5.0, 1e-4],
            "environment.table_temperature_K": [210.0, 160.0, 140.0],
        }
    )
    env = build.environment(Post2Settings.from_scenario(sc))
    assert env.atmosphere.density(50e3) == pytest.approx(1.5e-4)
    assert env.atmosphere.density(25e3) == pytest.approx(math.sqrt(0.015 * 1.5e-4))  # log-linear
    bad = sc.with_overrides({"environment.table_density_kg_m3": [0.015, -1.0, 1e-9]})
    with pytest.raises(ScenarioError, match="table_altitude_m"):
        build.environment(Post2Settings.from_scenario(bad))


def test_quaternion_observation_residual_is_the_body_small_angle():
    from workbench.core.rotation import quat_boxplus
    from workbench.problems.post2.pipeline import Channel

    sc = load_scenario(assets_dir() / "scenarios" / "post2_entry6dof.toml").with_overrides(
        {"observations.att": {"quantity": "quaternion", "sigma": 0.01, "rate_hz": 8.0}}
    )
    cfg = Post2Settings.from_scenario(sc)
    spec = next(o for o in cfg.observations if o.name == "att")
    assert spec.size == 3 and np.allclose(spec.sigma, np.radians(0.01))
    est = Estimator(cfg)
    sq = est.smap.blocks["attitude"].sx
    d = np.radians([0.02, -0.01, 0.03])
    q_meas = quat_boxplus(est.x0[sq], d)
    ch = Channel(spec, np.zeros(1), q_meas[None, :], q_meas[None, :], np.diag(spec.sigma**2)[None])
    m = est.measurement(ch, 0)
    y = m.z - m.h(est.x0)
    np.testing.assert_allclose(y, d, atol=1e-12)  # the correction that takes the state to the measurement
    H = m.H(est.x0)
    se = est.smap.blocks["attitude"].se
    # the Jacobian of the SO(3) log at the offset d: I + O(|d|/2) (off-diagonal ½[d×] terms)
    np.testing.assert_allclose(H[:, se], np.eye(3), atol=0.5 * np.linalg.norm(d) + 1e-9)
    assert np.allclose(np.delete(H, np.arange(se.start, se.stop), axis=1), 0.0)


def test_aero_force_and_moment_ignore_the_quaternion_norm_at_small_alpha():
    """RK4's intermediate stages carry |q|² = 1 + O((hω)²): the aerodynamics must use the unit
    quaternion and a scale-invariant α (before the fix, |q|² = 1 + 2e-6 at α = 0.1° clipped
    arccos(u/V) to α = 0 and the moment vanished)."""
    sc = load_scenario(assets_dir() / "scenarios" / "post2_entry6dof.toml").with_overrides(
        {"states.attitude.value": [0.1, 0.0, 0.0], "states.position.value": [0.0, 0.0, 3396190.0 + 40e3]}
    )
    est = Estimator(Post2Settings.from_scenario(sc))
    m, x = est.model, est.x0.copy()
    ph = m.initial_phase()
    F, M = m.aero_force_moment(x, ph)
    assert np.linalg.norm(M) > 0.0
    sq = est.smap.blocks["attitude"].sx
    y = x.copy()
    y[sq] *= math.sqrt(1.0 + 2e-6)
    F2, M2 = m.aero_force_moment(y, ph)
    np.testing.assert_allclose(M2, M, rtol=1e-9, atol=1e-12 * np.abs(M).max())
    np.testing.assert_allclose(F2, F, rtol=1e-12)
    np.testing.assert_allclose(m.sensed_acceleration_B(y, ph), m.sensed_acceleration_B(x, ph), rtol=1e-12)
