"""Truth simulator of the Schiaparelli-like entry (physics.entry) and its aerodynamic database.

One full simulation per module (fixture); the checks are physical: vacuum invariants, a
hydrostatic true atmosphere that departs from the default, PDD near Mach 2 and 10 km, the
X-rate spike after deployment, winds in their layers, the module above ground at BSR and the
specific force consistent with the trajectory.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.core.atmosphere import R_UNIVERSAL, MarsEngineeringAtmosphere
from workbench.core.bodies import MARS
from workbench.core.gravity import gravity_j2
from workbench.core.rotation import quat_to_dcm
from workbench.io.scenario import ScenarioError, load_scenario
from workbench.models.aerodynamics import AeroTable, knudsen_bridge, load_vehicle
from workbench.problems.entry.config import EntrySettings
from workbench.problems.entry.site import R_GROUND
from workbench.problems.entry.truth import (
    MARS_MOLAR_MASS,
    EntryTruthSpec,
    coefficient_deviation,
    disperse_truth_spec,
    draw_coefficient_deviation,
    simulate_entry,
    true_atmosphere,
    wind_profile_truth,
)

ROOT = Path(__file__).resolve().parents[3]
VEHICLE = ROOT / "assets" / "vehicles" / "schiaparelli.toml"
SCENARIO = ROOT / "assets" / "scenarios" / "schiaparelli.toml"
SAT_DPS = 187.5


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle(VEHICLE)


@pytest.fixture(scope="module")
def truth(vehicle):
    return simulate_entry(vehicle, EntryTruthSpec(), np.random.default_rng(7))


def _index(truth, t):
    return int(np.argmin(np.abs(truth.t - t)))


# ------------------------------------------------------------------------------ aerodynamics


def test_vehicle_asset(vehicle):
    assert vehicle.mass_entry == 577.0 and vehicle.mass_front_shield == 80.0 and vehicle.mass_back_shell == 20.0
    assert vehicle.diameter == 2.4
    assert vehicle.capsule.ref_area == pytest.approx(np.pi * 1.2**2)
    assert vehicle.parachute.ref_area == pytest.approx(np.pi * 36.0)
    np.testing.assert_allclose(vehicle.mass_at(np.array([0, 1, 2])), [577.0, 562.0, 482.0])
    assert vehicle.attach_point_G[2] > 0.0 and vehicle.riser_length == 27.0
    ca, cn, cm = vehicle.capsule.coefficients([0.3, 2.0, 30.0], 1e-6, 0.0)
    np.testing.assert_allclose(ca, [1.05, 1.45, 1.67], atol=0.01)
    np.testing.assert_allclose(cn, 0.0, atol=1e-12)
    # free-molecular limit and restoring moment / positive small normal force at incidence
    assert vehicle.capsule.coefficients(30.0, 100.0, 0.0)[0] == pytest.approx(2.0)
    _, cn, cm = vehicle.capsule.coefficients(20.0, 1e-6, np.radians(10.0))
    assert 0.0 < cn < 0.1 and cm < 0.0
    assert vehicle.capsule.cmq < 0.0
    np.testing.assert_allclose(vehicle.parachute.cd_at([0.3, 2.0]), [0.60, 0.43])


def test_scalar_path_matches_vectorised(vehicle):
    rng = np.random.default_rng(0)
    tab = vehicle.capsule
    m = rng.uniform(0.1, 40.0, 50)
    kn = 10.0 ** rng.uniform(-6.0, 3.0, 50)
    a = rng.uniform(0.0, 1.7, 50)
    vec = np.stack(tab.coefficients(m, kn, a), -1)
    sca = np.array([tab.coefficients_scalar(*x) for x in zip(m, kn, a, strict=True)])
    np.testing.assert_allclose(sca, vec, atol=1e-12)
    cd = [vehicle.parachute.cd_scalar(x) for x in m]
    np.testing.assert_allclose(cd, vehicle.parachute.cd_at(m), atol=1e-12)


def test_knudsen_bridge_and_table_validation():
    np.testing.assert_allclose(knudsen_bridge([1e-4, 1e-3, 10.0, 100.0]), [0.0, 0.0, 1.0, 1.0], atol=1e-15)
    assert knudsen_bridge(10 ** (-1.0)) == pytest.approx(0.5)  # midpoint in log Kn
    with pytest.raises(ValueError, match="strictly increasing"):
        z = np.zeros((2, 2, 2))
        AeroTable("x", [1.0, 1.0], [0, 1], [0, 1], z, z, z, -0.1, 1.0, 1.0)


def test_load_vehicle_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_vehicle(tmp_path / "none.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text(VEHICLE.read_text().replace("mass_entry_kg = 577.0", "mass_entry_kg = -1.0"))
    with pytest.raises(ValueError, match="mass_entry_kg"):
        load_vehicle(bad)


# ---------------------------------------------------------------------------------- vacuum


def test_vacuum_invariants(vehicle):
    """Aero off: specific energy (with the J2 potential), H_z and the rotational energy are conserved."""
    spec = EntryTruthSpec(aero_enabled=False, t_end=30.0)
    tr = simulate_entry(vehicle, spec, np.random.default_rng(0))
    r = np.linalg.norm(tr.p_M, axis=1)
    s = tr.p_M[:, 2] / r
    U = -MARS.gm / r * (1.0 - MARS.j2 * (MARS.equatorial_radius / r) ** 2 * 0.5 * (3.0 * s * s - 1.0))
    E = 0.5 * np.sum(tr.v_M**2, axis=1) + U
    assert np.max(np.abs(E - E[0])) / abs(E[0]) < 1e-6
    Hz = np.cross(tr.p_M, tr.v_M)[:, 2]
    assert np.max(np.abs(Hz - Hz[0])) / abs(Hz[0]) < 1e-9
    I = vehicle.inertia_G
    T = 0.5 * np.einsum("ni,ij,nj->n", tr.w_G, I, tr.w_G)
    assert np.max(np.abs(T - T[0])) / T[0] < 1e-7
    np.testing.assert_allclose(tr.f_G, 0.0, atol=1e-12)
    assert tr.t[0] == -15.0 and tr.t[-1] == pytest.approx(30.0)
    assert np.isnan(tr.events["PDD"]) and tr.parachute_p_M is None


# ------------------------------------------------------------------------------ atmosphere


def test_true_atmosphere(truth):
    """Hydrostatic, ideal gas with the truth's own constants, and not the estimator's model's shape."""
    atm = truth.atmosphere
    dflt = MarsEngineeringAtmosphere()
    spec = EntryTruthSpec()
    h = np.arange(0.0, 120e3, 100.0)
    ratio = atm.density(h) / dflt.density(h)
    dev = np.abs(ratio - 1.0)
    assert 0.05 < dev.max() < 0.6  # a realistic departure somewhere, never wild
    # ideal gas with the truth's molar mass, which differs from AMELIA's 43.41 g/mol (the estimator's)
    R = R_UNIVERSAL / (spec.molar_mass_g_per_mol * 1e-3)
    assert spec.molar_mass_g_per_mol * 1e-3 != MARS_MOLAR_MASS
    np.testing.assert_allclose(atm.p, atm.rho * R * atm.T, rtol=1e-12)
    assert atm.gas_constant == pytest.approx(R) and atm.gamma != dflt.gamma
    # hydrostatic: dp/dh = -rho g (central differences on the 10 m table)
    hh = atm.h[1:-1]
    dpdh = (atm.p[2:] - atm.p[:-2]) / (atm.h[2:] - atm.h[:-2])
    g = MARS.gm / (MARS.reference_radius + hh) ** 2
    np.testing.assert_allclose(dpdh, -atm.rho[1:-1] * g, rtol=2e-4)
    # a temperature inversion near 10-13 km
    hi = np.arange(9e3, 14e3, 50.0)
    assert np.any(np.diff(atm.temperature(hi)) > 0.0)
    # surface temperature in the published 200-250 K daytime range, colder than the model's 242 K
    assert 200.0 < float(atm.temperature(0.0)) < 235.0 < float(dflt.temperature(0.0))
    # not the default shape plus bumps: the difference T_true - T_default is not a sum of a few
    # narrow features but changes over the whole column (the lapse-rate structure differs), and
    # the scale height differs by more than 10 % somewhere between 10 and 90 km
    dT = atm.temperature(h) - dflt.temperature(h)
    assert dT.max() > 10.0 and dT.min() < -10.0
    hs = np.arange(10e3, 90e3, 1e3)
    H_true = R * atm.temperature(hs) / (MARS.gm / (MARS.reference_radius + hs) ** 2)
    H_dflt = dflt.gas_constant * dflt.temperature(hs) / (MARS.gm / (MARS.reference_radius + hs) ** 2)
    assert np.max(np.abs(H_true / H_dflt - 1.0)) > 0.10
    # gravity waves: a few K with 5-15 km vertical wavelengths (the band-pass residual of T)
    from scipy.ndimage import uniform_filter1d

    Tz = atm.temperature(np.arange(0.0, 60e3, 100.0))
    resid = Tz - uniform_filter1d(Tz, 201, mode="nearest")
    assert 1.0 < np.std(resid[100:-100]) < 10.0


def test_planted_aerodynamic_deviations(vehicle, truth):
    """The truth flies CA × (1 + δ(M)) — smooth in Mach, about 10 % — not the shared table."""
    spec = EntryTruthSpec()
    m = np.geomspace(0.3, 40.0, 400)
    d = coefficient_deviation(m, spec.aero_deviation_mach, spec.ca_deviation)
    assert np.all(np.abs(d) < 0.3) and np.ptp(d) > 0.05  # Mach-dependent, not a constant factor
    assert np.max(np.abs(np.diff(d) / np.diff(np.log(m)))) < 0.2  # smooth in log Mach
    np.testing.assert_allclose(
        coefficient_deviation(spec.aero_deviation_mach, spec.aero_deviation_mach, spec.ca_deviation),
        spec.ca_deviation,
        atol=1e-12,
    )
    # along the flight: the factor the simulator applied is the planted one at the true Mach
    ent = (truth.phase == 0) & (truth.t > 0)
    np.testing.assert_allclose(
        truth.ca_factor[ent],
        1.0 + coefficient_deviation(truth.mach[ent], spec.aero_deviation_mach, spec.ca_deviation),
        atol=2e-4,
    )
    # the parachute flies its planted CD deviation (at the canopy's own Mach), none before PDD
    ch = truth.phase > 0
    dp = np.asarray(spec.parachute_cd_deviation)
    assert np.all(truth.chute_cd_factor[~ch] == 1.0)
    fp = truth.chute_cd_factor[ch]
    assert np.all((fp >= 1 + dp.min() - 1e-9) & (fp <= 1 + dp.max() + 1e-9))
    assert np.ptp(truth.chute_cd_factor[ch]) > 0.02  # Mach-dependent: supersonic at PDD, subsonic later
    # the hypersonic drag is measurably off the table (what the density reconstruction must absorb)
    hyp = ent & (truth.mach > 15)
    assert np.abs(truth.ca_factor[hyp] - 1.0).max() > 0.03
    # the statistics of the draw: 10 % 1σ in total (AMELIA Table 3)
    rng = np.random.default_rng(0)
    draws = np.array([draw_coefficient_deviation(rng, spec.aero_deviation_mach) for _ in range(4000)])
    assert np.std(draws, axis=0) == pytest.approx(np.full(draws.shape[1], 0.10), rel=0.08)


def test_dispersed_truth_differs_and_still_flies(vehicle):
    """disperse_truth_spec draws a different truth; it still reaches PDD and BSR above ground."""
    rng = np.random.default_rng(11)
    base = EntryTruthSpec()
    a, b = disperse_truth_spec(base, rng), disperse_truth_spec(base, rng)
    for f in ("ca_deviation", "parachute_cd_deviation", "temperature_profile_km_K", "wind_layers", "terrain_modes"):
        assert getattr(a, f) != getattr(b, f) and getattr(a, f) != getattr(base, f), f
    assert a.pdd_mach == base.pdd_mach and a.fsr_delay_s == base.fsr_delay_s  # events and parachute kept
    overrides = {"truth.ca_deviation": list(a.ca_deviation), "truth.surface_pressure_pa": a.surface_pressure_pa}
    assert _truth_spec(overrides).ca_deviation == a.ca_deviation
    tr = simulate_entry(vehicle, a, np.random.default_rng(1))
    i = _index(tr, tr.events["PDD"])
    assert 7e3 < tr.h_amr[i] < 14e3 and np.all(np.linalg.norm(tr.p_M, axis=1) > R_GROUND)


def _truth_spec(overrides: dict) -> EntryTruthSpec:
    """The truth spec of the shipped scenario with ``overrides`` (dotted keys), through the settings."""
    return EntrySettings.from_scenario(load_scenario(SCENARIO).with_overrides(overrides)).synthetic.truth


def test_spec_from_proposal_and_errors():
    spec = _truth_spec({})
    assert spec == EntryTruthSpec()
    hash(spec)  # the pipeline caches truths keyed by the spec
    with pytest.raises(ScenarioError, match="unknown key"):
        _truth_spec({"truth.pdd_mahc": 2.0})
    with pytest.raises(ScenarioError, match="wind_layers"):
        _truth_spec({"truth.wind_layers": [["a", 1, 2, 3, 4]]})


# ---------------------------------------------------------------------------------- entry


def test_entry_phase(truth):
    t = truth.t
    assert t[0] == -15.0 and np.allclose(np.diff(t), 0.01)
    e = truth.events
    assert e["EIP"] == 0.0
    i0 = _index(truth, 0.0)
    assert 100e3 < truth.h_amr[i0] < 108e3  # AMELIA Table 5: EIP at 104.0 km AMR
    assert np.degrees(truth.alpha_total[i0]) < 5.0
    assert np.degrees(truth.alpha_total[(t > 0) & (truth.phase == 0)]).max() < 6.0  # AMELIA: AoA < 5.5 deg
    assert np.degrees(truth.w_G[0, 2]) == pytest.approx(16.0)
    assert 10.0 < np.degrees(truth.w_G[_index(truth, e["PDD"]) - 1, 2]) < 15.0  # spin slowed to ~12 deg/s
    ent = truth.phase == 0
    assert 60.0 < truth.f_G[ent, 2].max() < 100.0  # AMELIA: ~80 m/s^2 peak deceleration
    assert np.all(np.isnan(truth.parachute_p_M[ent]))


def test_pdd_fsr_bsr(truth):
    e = truth.events
    i = _index(truth, e["PDD"])
    assert 170.0 < e["PDD"] < 195.0
    assert truth.mach[i] == pytest.approx(2.0, abs=0.02)
    assert 8e3 < truth.h_amr[i] < 12e3
    assert e["FSR"] == pytest.approx(e["PDD"] + 41.0) and e["BSR"] == pytest.approx(e["FSR"] + 41.0)
    assert truth.t[-1] == pytest.approx(e["BSR"])
    np.testing.assert_array_equal(truth.phase[[i - 1, i, _index(truth, e["FSR"]), -1]], [0, 1, 2, 2])
    assert np.all(np.diff(truth.phase) >= 0)
    # above the terrain at BSR, in the 2-4.5 km AMR band (AMELIA: last data at 2.76 km AMR)
    h_agl_end = np.linalg.norm(truth.p_M[-1]) - R_GROUND
    assert h_agl_end > 1000.0 and 2e3 < truth.h_amr[-1] < 4.5e3
    assert np.all(np.linalg.norm(truth.p_M, axis=1) > R_GROUND)


def test_deployment_transient(truth):
    """Inflation peak on +Z and the X-rate above the 187.5 deg/s gyro limit for ~1 s."""
    P = truth.events["PDD"]
    m = (truth.t >= P) & (truth.t < P + 3.0)
    fz = truth.f_G[m, 2]
    assert 70.0 < fz.max() < 120.0
    assert 0.3 < truth.t[m][np.argmax(fz)] - P < 1.2
    wx = np.degrees(truth.w_G[:, 0])
    wy = np.degrees(truth.w_G[:, 1])
    above = (np.abs(wx) > SAT_DPS) & (truth.t >= P)
    ta = truth.t[above] - P
    assert above.any()
    assert 0.5 < ta.min() < 1.5  # starts ~1 s after PDD (AMELIA Sect. 4)
    assert 0.5 <= ta.max() - ta.min() <= 1.5  # and lasts about a second
    assert np.abs(wy[truth.t >= P]).max() < SAT_DPS  # Y stays inside the limit
    # the canopy trails about one riser length behind
    dist = np.linalg.norm(truth.parachute_p_M[truth.t > P + 5] - truth.p_M[truth.t > P + 5], axis=1)
    assert np.all((dist > 26.0) & (dist < 30.0))


def test_winds(truth):
    h = truth.h_amr
    speed = np.linalg.norm(truth.wind_NE, axis=1)
    layer1 = (h > 5.2e3) & (h < 5.8e3)
    layer2 = (h > 3.5e3) & (h < 4.1e3)
    calm = (h > 6.8e3) & (h < 9e3)
    gap = (h > 4.6e3) & (h < 4.8e3)
    assert speed[layer1].max() > 15.0 and speed[layer2].max() > 15.0
    assert speed[calm & (truth.phase > 0)].max() <= 3.5
    assert speed[gap].min() < 8.0  # two distinct layers
    np.testing.assert_allclose(truth.wind_NE, wind_profile_truth(h, EntryTruthSpec()), atol=0.02)
    assert speed.max() < 23.0
    # the air-relative velocity includes the co-rotating atmosphere and the wind
    p, v = truth.p_M, truth.v_M
    up = p / np.linalg.norm(p, axis=1, keepdims=True)
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east, axis=1, keepdims=True)
    north = np.cross(up, east)
    v_air = np.cross([0.0, 0.0, MARS.rotation_rate], p) + truth.wind_NE[:, :1] * north + truth.wind_NE[:, 1:] * east
    np.testing.assert_allclose(truth.v_rel_M, v - v_air, atol=0.05)


def test_specific_force_matches_trajectory(truth):
    """f_G = C_G_M (dv/dt - g(p)) within the differentiation error (4th-order central differences)."""
    dt = 0.01
    v = truth.v_M
    dv = (-v[4:] + 8.0 * v[3:-1] - 8.0 * v[1:-3] + v[:-4]) / (12.0 * dt)
    k = np.arange(2, len(truth.t) - 2)
    a_ng_M = dv - gravity_j2(truth.p_M[k], MARS)
    C = quat_to_dcm(truth.q_M_G[k])
    f_pred = np.einsum("nji,nj->ni", C, a_ng_M)
    err = np.linalg.norm(f_pred - truth.f_G[k], axis=1)
    # exclude the samples next to events (discontinuous forces: PDD, FSR)
    near = np.zeros(len(k), bool)
    for name in ("PDD", "FSR"):
        near |= np.abs(truth.t[k] - truth.events[name]) < 0.05
    P = truth.events["PDD"]
    smooth = ~near & ((truth.t[k] < P) | (truth.t[k] > P + 4.0))
    assert np.max(err[smooth]) < 0.02
    # inflation transients: the riser snaps taut (a force step) and rings at ~14 Hz, which the
    # 0.01 s differences do not resolve; still consistent almost everywhere
    trans = ~near & ~smooth
    assert np.percentile(err[trans], 99) < 0.3 and np.max(err[trans]) < 5.0
    # dynamic pressure / Mach outputs are consistent with the atmosphere
    i = _index(truth, 100.0)
    V = np.linalg.norm(truth.v_rel_M[i])
    assert truth.dynamic_pressure[i] == pytest.approx(0.5 * truth.atmosphere.density(truth.h_amr[i]) * V**2, rel=1e-3)
    assert truth.mach[i] == pytest.approx(V / truth.atmosphere.speed_of_sound(truth.h_amr[i]), rel=1e-3)


def test_deterministic_given_rng(vehicle, truth):
    spec = EntryTruthSpec(t_end=1.0)
    a = simulate_entry(vehicle, spec, np.random.default_rng(3))
    b = simulate_entry(vehicle, spec, np.random.default_rng(3))
    np.testing.assert_array_equal(a.p_M, b.p_M)
    np.testing.assert_allclose(a.p_M, truth.p_M[: len(a.t)], rtol=0, atol=1e-6)  # rng unused before PDD


def test_true_atmosphere_function_matches(truth):
    atm = true_atmosphere(EntryTruthSpec())
    np.testing.assert_allclose(atm.rho, truth.atmosphere.rho)


def test_terrain_relief_and_radar_ranges():
    """The relief has the stated RMS, turns with Mars, and the beam ranges hit the relief, not the sphere."""
    from workbench.core.rotation import quat_normalize
    from workbench.models.radar import slant_range_sphere, slant_range_surface
    from workbench.problems.entry.site import TerrainRelief

    relief = TerrainRelief(R_GROUND, EntryTruthSpec().terrain_modes)
    assert relief.rms_m() == pytest.approx(100.0, rel=1e-3)
    rng = np.random.default_rng(0)
    u = rng.normal(size=(20000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    h = relief.height(u * R_GROUND, 0.0)
    assert np.std(h) == pytest.approx(100.0, rel=0.1) and np.abs(h).max() < 500.0
    # co-rotating: a point carried by the rotation keeps its height
    t = 40.0
    a = MARS.rotation_rate * t
    Rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(relief.height((Rz @ (u[:50] * R_GROUND).T).T, t), h[:50], atol=1e-6)
    # a beam's range ends on the relief surface
    p = u[:200] * (R_GROUND + 5000.0)
    q = quat_normalize(rng.normal(size=(200, 4)))
    beam = np.array([0.0, 0.0, -1.0])
    rho = slant_range_surface(p, q, beam, R_GROUND, lambda x: relief.radius(x, t))
    sph = slant_range_sphere(p, q, beam, R_GROUND)
    from workbench.core.rotation import quat_rotate

    # beams within 60° of the local vertical (the radar's geometry: 20° squint plus the attitude)
    steep = -np.sum(quat_rotate(q, beam) * u[:200], axis=1) > np.cos(np.radians(60.0))
    ok = np.isfinite(rho) & np.isfinite(sph) & steep
    assert ok.sum() > 30
    x = p[ok] + rho[ok, None] * quat_rotate(q[ok], beam)
    np.testing.assert_allclose(np.linalg.norm(x, axis=1), relief.radius(x, t), atol=1e-3)
    assert np.std(rho[ok] - sph[ok]) > 30.0
