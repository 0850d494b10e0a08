"""The compiled dynamics kernel (post2/kernels.py) against the numpy reference of the model.

``TrajectoryModel.derivative`` / ``aero_force_moment`` run the numba kernel; ``*_reference`` keep the
numpy code.  The kernel follows the reference's order of operations, so on the shipped scenarios'
models (estimator and truth, every event phase) the two agree bit for bit; the assertion allows
1e-12 relative (a few units in the last place) in case a numpy/BLAS build sums in another order.
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import load_scenario
from workbench.problems.post2 import model as post2_model
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.model import (
    Environment,
    StateMap,
    TrajectoryModel,
    Vehicle,
    aero_angles,
    aero_angles_loop,
    quat_from_aero_angles,
)
from workbench.problems.post2.pipeline import Estimator
from workbench.problems.post2.truth import truth_model

SCENARIOS = ("post2_entry6dof", "post2_mer_quaternion", "post2_huygens", "post2_j2")


def _phases(model: TrajectoryModel) -> list[dict]:
    """The initial phase and the phase after each event in turn."""
    out = [model.initial_phase()]
    for ev in model.events:
        out.append(model.apply_event(out[-1], ev))
    return out


def _batch(model: TrajectoryModel, x0: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """n states around x0: perturbed positions (±2 km), velocities, attitude, rates, parameters."""
    X = np.repeat(x0[None, :], n, axis=0)
    sm = model.smap
    X[:, sm.blocks["position"].sx] += rng.normal(scale=2000.0, size=(n, 3))
    X[:, sm.blocks["velocity"].sx] *= 1.0 + rng.normal(scale=0.05, size=(n, 1))
    for name, b in sm.blocks.items():
        if name in ("position", "velocity"):
            continue
        X[:, b.sx] += rng.normal(scale=0.02, size=(n, b.sx.stop - b.sx.start))
    return X


def _models(name: str):
    sc = load_scenario(assets_dir() / "scenarios" / f"{name}.toml")
    cfg = Post2Settings.from_scenario(sc)
    est = Estimator(cfg)
    tm = truth_model(cfg)
    x_truth = np.zeros(tm.smap.n_x)
    for blk in ("position", "velocity") + (("attitude", "body_rates") if cfg.dof == 6 else ()):
        x_truth[tm.smap.blocks[blk].sx] = est.x0[est.smap.blocks[blk].sx]
    return [(est.model, est.x0), (tm, x_truth)]


def _assert_close(a: np.ndarray, b: np.ndarray) -> None:
    scale = np.maximum(np.abs(b), 1e-300)
    assert a.shape == b.shape
    assert np.all(np.isfinite(a) == np.isfinite(b))
    assert np.max(np.abs(a - b) / scale, initial=0.0) <= 1e-12


@pytest.mark.parametrize("name", SCENARIOS)
def test_kernel_matches_the_numpy_reference_on_the_shipped_scenarios(name):
    rng = np.random.default_rng(7)
    for model, x0 in _models(name):
        assert model._plan() is not None
        for phase in _phases(model):
            X = _batch(model, x0, 31, rng)
            _assert_close(model.derivative(X, phase), model.derivative_reference(X, phase))
            F, M = model.aero_force_moment(X, phase)
            Fr, Mr = model.aero_force_moment_reference(X, phase)
            _assert_close(F, Fr)
            _assert_close(M, Mr)
            if "velocity" in model.smap:  # acceleration_inertial: the kernel's velocity block
                sv = model.smap.blocks["velocity"].sx
                F_ref = model.aero_force_moment_reference(X, phase)[0]
                _assert_close(
                    model.observe(X, "acceleration_inertial", phase), model.gravity(X) + F_ref / phase["mass"]
                )
                _assert_close(model.observe(X, "acceleration_inertial", phase), model.derivative(X, phase)[:, sv])
            # one state (the truth's solve_ivp) and a 2-D leading shape
            _assert_close(model.derivative(X[3], phase), model.derivative_reference(X[3], phase))
            X3 = X[:30].reshape(5, 6, -1)
            _assert_close(model.derivative(X3, phase), model.derivative_reference(X3, phase))


def test_kernel_matches_the_reference_for_a_constant_cd_and_drag_area_states():
    """Rocket-flight style pieces: a 3-DOF point mass with a constant cd, drag-area states, winds."""
    from workbench.core.atmosphere import ExponentialAtmosphere

    env = Environment(3.986e14, 6378137.0, 1.08e-3, 6371000.0, 7.29e-5, ExponentialAtmosphere(1.2, 8500.0, 288.0))
    veh = Vehicle(20.0, np.eye(3), None, ref_area=0.01, cd=0.45)
    sm = StateMap(["position", "velocity", "drogue_drag_area", "main_drag_area", "wind_vertical"])
    m = TrajectoryModel(sm, 3, env, veh, nominal={"wind_horizontal": 3.0})
    rng = np.random.default_rng(3)
    X = np.zeros((25, sm.n_x))
    X[:, :3] = [6371000.0 + 3000.0, 0.0, 0.0] + rng.normal(scale=500.0, size=(25, 3))
    X[:, 3:6] = rng.normal(scale=100.0, size=(25, 3))
    X[:, 6:] = np.abs(rng.normal(scale=0.5, size=(25, 3)))
    for chute in (None, "drogue", "main"):
        phase = {**m.initial_phase(), "parachute": chute is not None, "chute": chute}
        _assert_close(m.derivative(X, phase), m.derivative_reference(X, phase))


def test_vacuum_model_and_the_switch_to_the_reference(monkeypatch):
    sm = StateMap(["position", "velocity", "j2"])
    m = TrajectoryModel(sm, 3, Environment(4.28e13, 3.39e6, 1.96e-3, 3.39e6, 0.0, None), Vehicle(1e3, np.eye(3), None))
    X = np.array([[3.0e6, 1.5e6, 1.0e6, 0.0, 3000.0, 1000.0, 1.9e-3], [3.1e6, -1.5e6, 2.0e6, 10.0, 300.0, 100.0, 2e-3]])
    ph = m.initial_phase()
    _assert_close(m.derivative(X, ph), m.derivative_reference(X, ph))
    calls = []
    monkeypatch.setenv(post2_model.KERNEL_ENV, "0")  # the one switch: models built from now on
    ref = TrajectoryModel(sm, 3, m.env, m.vehicle)
    assert not ref.use_kernel and m.use_kernel
    monkeypatch.setattr(TrajectoryModel, "_kernel_eval", lambda *a, **k: calls.append(1))
    np.testing.assert_array_equal(ref.derivative(X, ph), m.derivative_reference(X, ph))
    assert not calls
    monkeypatch.delenv(post2_model.KERNEL_ENV)
    assert TrajectoryModel(sm, 3, m.env, m.vehicle).use_kernel


def test_rocket_wind_state_falls_back_to_the_reference():
    sm = StateMap(["position", "velocity", "wind"])
    m = TrajectoryModel(sm, 3, Environment(4.28e13, 3.39e6, 0.0, 3.39e6, 0.0, None), Vehicle(1e3, np.eye(3), None))
    assert m._plan() is None
    X = np.array([3.0e6, 1.5e6, 1.0e6, 0.0, 3000.0, 1000.0, 1.0, 2.0])
    np.testing.assert_array_equal(m.derivative(X, m.initial_phase()), m.derivative_reference(X, m.initial_phase()))


def test_vectorised_aero_angles_match_the_row_loop():
    rng = np.random.default_rng(0)
    n = 300
    r, v = rng.normal(size=(n, 3)) * 3e6, rng.normal(size=(n, 3)) * 4000.0
    ang = np.radians(rng.uniform(-20.0, 20.0, (n, 3))) * [1.0, 1.0, 8.0]
    q = np.array([quat_from_aero_angles(r[i], v[i], ang[i]) for i in range(n)])
    _assert_close(aero_angles(r, v, q), aero_angles_loop(r, v, q))
    np.testing.assert_allclose(aero_angles(r, v, q), ang, atol=1e-12)
    assert aero_angles(r[0], v[0], q[0]).shape == (1, 3)


@pytest.mark.parametrize("name", SCENARIOS)
def test_compiled_propagation_matches_the_numpy_rk4(name, monkeypatch):
    """``propagate`` (all RK4 stages, atmosphere included, in one compiled call) against the numpy
    RK4 over the numpy reference derivative, on the estimator's batch of every phase."""
    rng = np.random.default_rng(11)
    model, x0 = _models(name)[0]
    for phase in _phases(model):
        X = _batch(model, x0, 9, rng)
        fast = model.propagate(X, 0.0, 0.3, phase, 0.1)
        monkeypatch.setattr(model, "use_kernel", False)
        ref = model.propagate(X, 0.0, 0.3, phase, 0.1)
        monkeypatch.setattr(model, "use_kernel", True)
        _assert_close(fast, ref)


def test_atmosphere_kernel_matches_the_numpy_atmospheres():
    from workbench.core.atmosphere import MarsEngineeringAtmosphere, TabulatedAtmosphere, TitanDefaultAtmosphere
    from workbench.problems.post2 import kernels

    lay = TitanDefaultAtmosphere()
    hs = np.arange(0.0, 1.4e6 + 1.0, 2000.0)
    tab = TabulatedAtmosphere(
        hs, lay.density(hs), lay.pressure(hs), lay.temperature(hs), lay.gas_constant, lay.gamma, lay.sutherland,
        extrapolate="clamp",
    )  # fmt: skip
    rng = np.random.default_rng(5)
    for atm, kind, hmax in ((MarsEngineeringAtmosphere(), kernels.ATM_MARS, 2e5), (tab, kernels.ATM_TABLE, 1.6e6)):
        m = TrajectoryModel(
            StateMap(["position", "velocity"]),
            3,
            Environment(1.0, 1.0, 0.0, 1.0, 0.0, atm),
            Vehicle(1.0, np.eye(3), None),
        )
        plan = m._plan()
        h = np.concatenate([rng.uniform(0.0, hmax, 5000), hs[:20], [0.0, 7000.0, 50e3, 1.4e6]])
        rho, a, kn = np.empty_like(h), np.empty_like(h), np.empty_like(h)
        kernels.atmosphere_kernel(kind, plan["ac"], *plan["atm_tables"], h, True, 2.65, rho, a, kn)
        _assert_close(rho, atm.density(h))
        _assert_close(a, atm.speed_of_sound(h))
        _assert_close(kn, atm.knudsen(h, 2.65))


@pytest.mark.parametrize("m", [5, 64, 300, 1111])
def test_mc_metric_kernel_matches_the_numpy_expression(m):
    from workbench.problems.post2 import kernels

    rng = np.random.default_rng(m)
    n_members, n_grid, t0, h = 40, 400, 10.0, 0.5
    a = rng.normal(size=(n_members, n_grid)) * 10 ** rng.uniform(-2, 2, (n_members, 1))
    tu = np.sort(rng.uniform(t0 - 5.0, t0 + h * n_grid + 5.0, m))
    zu = rng.normal(size=m)
    sh = rng.normal(scale=3.0, size=n_members)
    hi = a.shape[1] - 1.000001
    rows = np.arange(n_members)[:, None]
    u = np.clip((tu[None, :] + sh[:, None] - t0) / h, 0.0, hi)
    k = np.floor(u).astype(int)
    f = u - k
    ref = np.sum(np.abs(zu[None, :] - (a[rows, k] * (1.0 - f) + a[rows, k + 1] * f)), axis=1)
    out = np.empty(n_members)
    kernels.metric_total_kernel(a, tu, zu, sh, t0, h, hi, out)
    _assert_close(out, ref)


def test_interp_port_is_np_interp_to_the_bit():
    """kernels.interp_index + interp_at (one node search shared by the atmosphere's columns) give
    np.interp's numbers exactly: inside, on the nodes, outside on both sides, NaN."""
    from workbench.problems.post2 import kernels

    rng = np.random.default_rng(3)
    xp = np.cumsum(rng.uniform(0.1, 3.0, 60))
    fps = [rng.normal(size=60), np.exp(rng.normal(size=60)), np.full(60, 2.5)]
    fps[0][10:12] = np.inf  # the NaN fall-back branch of arr_interp
    x = np.concatenate([rng.uniform(xp[0] - 5.0, xp[-1] + 5.0, 4000), xp, [xp[0], xp[-1], np.nan, -np.inf, np.inf]])
    for fp in fps:
        ref = np.interp(x, xp, fp)
        got = np.array([kernels.interp_at(kernels.interp_index(v, xp), v, xp, fp) for v in x])
        np.testing.assert_array_equal(got, ref)


def test_axial_kernel_matches_the_numpy_axial_accelerometer(monkeypatch):
    """The compiled 3-DOF axial accelerometer (kernels.axial_kernel) against the numpy reference on the
    Huygens-like estimator and truth models in every phase (drogue: the tilt), batches and one state."""
    rng = np.random.default_rng(11)
    for model, x0 in _models("post2_huygens"):
        for phase in _phases(model):
            X = _batch(model, x0, 31, rng)
            fast = model.observe(X, "acceleration_axial", phase)
            np.testing.assert_array_equal(fast, model.axial_acceleration_3dof_reference(X, phase))
            np.testing.assert_array_equal(model.observe(X[4], "acceleration_axial", phase), fast[4])
            monkeypatch.setattr(model, "use_kernel", False)  # all numpy (the force too)
            _assert_close(fast, model.observe(X, "acceleration_axial", phase))
            monkeypatch.setattr(model, "use_kernel", True)


def test_measurement_h_and_h_jacobian_share_one_batched_call(tmp_path):
    """Estimator.measurement: h(x) is the first row of the batched Jacobian call and H(x) at the same x
    reuses it; both equal the separate calls to the bit, for every observation of the Huygens case."""
    from workbench.estimation.ekf import numeric_jacobian_batched
    from workbench.problems.post2.pipeline import read_observations
    from workbench.problems.post2.problem import Post2Problem

    sc = load_scenario(assets_dir() / "scenarios" / "post2_huygens.toml")
    cfg = Post2Settings.from_scenario(sc)
    syn = Post2Problem().synthesize(cfg, tmp_path, 3)
    data = read_observations(cfg, syn.telemetry)
    est = Estimator(cfg)
    rng = np.random.default_rng(4)
    for phase in _phases(est.model):
        est.phase = phase
        for ch in data.channels.values():
            x = _batch(est.model, est.x0, 1, rng)[0]
            m = est.measurement(ch, 0)
            q = ch.spec.quantity
            zp = m.h(x)
            np.testing.assert_array_equal(zp, est.model.observe(x, q, phase))
            ref = numeric_jacobian_batched(lambda X, q=q, p=phase: est.model.observe(X, q, p), x, est.layout, est.eps)
            np.testing.assert_array_equal(m.H(x), ref[1])
            np.testing.assert_array_equal(m.H(x.copy()), ref[1])  # another x: computed, not reused


def _search_reference(a, tu, zu, base, stages, t0, h, hi):
    """The exhaustive numpy search of huygens._metric: every candidate's total, np.argmin per stage."""
    rows = np.arange(a.shape[0])[:, None]

    def total(sh):
        u = np.clip((tu[None, :] + sh[:, None] - t0) / h, 0.0, hi)
        k = np.floor(u).astype(int)
        f = u - k
        return np.sum(np.abs(zu[None, :] - (a[rows, k] * (1.0 - f) + a[rows, k + 1] * f)), axis=1)

    for offs in stages:
        m = np.stack([total(base + d) for d in offs], axis=1)
        base = base + offs[np.argmin(m, axis=1)]
    return total(base), base


@pytest.mark.parametrize("m", [7, 300, 813])
def test_mc_metric_search_kernel_is_the_exhaustive_search(m):
    """kernels.metric_search_kernel (pruned, middle-out) chooses the same shifts and gives the same
    totals, to the bit, as the exhaustive numpy search: smooth pulses, noise, ties (a flat row), a
    row with NaN (its first NaN candidate wins, as np.argmin's) and pruning switched off."""
    from workbench.problems.post2 import kernels

    rng = np.random.default_rng(m)
    n_members, n_grid, t0, h = 24, 300, 5.0, 1.0
    tg = t0 + h * np.arange(n_grid)
    centre = rng.uniform(120.0, 180.0, (n_members, 1))
    a = -80.0 * np.exp(-0.5 * ((tg[None, :] - centre) / rng.uniform(8.0, 20.0, (n_members, 1))) ** 2)
    a[3] = 1.0  # flat: every candidate ties, the first wins
    a[5, 140:150] = np.nan
    tu = np.sort(rng.uniform(t0, t0 + 260.0, m))
    zu = -80.0 * np.exp(-0.5 * ((tu - 150.0) / 12.0) ** 2) + rng.normal(scale=0.3, size=m)
    base = rng.normal(scale=5.0, size=n_members)
    stages = [np.arange(-half, half + 0.5 * step, step) for half, step in ((1.0, 0.1), (0.1, 0.01))]
    hi = n_grid - 1.000001
    ref_m, ref_s = _search_reference(a, tu, zu, base, stages, t0, h, hi)
    order = np.argsort(-np.abs(zu), kind="stable")
    for prune in (np.all(np.isfinite(a), axis=1), np.zeros(n_members, bool)):
        metric, shift = np.empty(n_members), np.empty(n_members)
        kernels.metric_search_kernel(a, tu, zu, base, *stages, t0, h, hi, order, prune, metric, shift)
        np.testing.assert_array_equal(shift, ref_s)
        np.testing.assert_array_equal(metric, ref_m)


def test_axial_on_grid_is_the_step_by_step_loop(monkeypatch):
    """TrajectoryModel.axial_on_grid (propagation and axial accelerometer in one compiled call) gives
    the loop of propagate + observe to the bit, and the all-numpy loop to 1e-12, on the Huygens-like
    selection's entry model (dispersed members, an uneven grid start) and on the drogue phase."""
    from workbench.problems.post2 import huygens

    cfg = Post2Settings.from_scenario(load_scenario(assets_dir() / "scenarios" / "post2_huygens.toml"))
    model = huygens.entry_model(cfg)
    mean = np.concatenate([cfg.state("position").value, cfg.state("velocity").value])
    X = huygens.dispersed_members(mean, huygens.delivered_covariance(cfg), 6, seed=4)
    times = [0.3 + 0.7 * k for k in range(25)]
    for phase in _phases(model):
        fast = model.axial_on_grid(X, times, phase, 0.5)
        np.testing.assert_array_equal(fast, model.axial_on_grid_reference(X, times, phase, 0.5))
        monkeypatch.setattr(model, "use_kernel", False)
        _assert_close(fast, model.axial_on_grid(X, times, phase, 0.5))
        monkeypatch.setattr(model, "use_kernel", True)
    a = huygens.propagate_axial_acceleration(model, X, 0.0, 10, 1.0)
    np.testing.assert_array_equal(
        a, model.axial_on_grid_reference(X, [float(k) for k in range(11)], _phases(model)[0], 1.0)
    )


def test_interp_index_near_is_the_bisection():
    """kernels.interp_index_near (a guess from even spacing, then neighbours) finds interp_index's node
    on even, nearly even and uneven nodes, on the nodes, outside, NaN, and with no spacing given."""
    from workbench.problems.post2 import kernels

    rng = np.random.default_rng(8)
    for xp in (
        np.arange(0.0, 1.4e6 + 1.0, 2000.0),
        np.cumsum(rng.uniform(1900.0, 2100.0, 300)),
        np.cumsum(rng.uniform(0.1, 30.0, 200) ** 2),
    ):
        inv = (xp.size - 1) / (xp[-1] - xp[0])
        x = np.concatenate([rng.uniform(xp[0] - 10.0, xp[-1] + 10.0, 3000), xp, [np.nan, -np.inf, np.inf]])
        for v in x:
            want = kernels.interp_index(v, xp)
            assert kernels.interp_index_near(v, xp, inv) == want
            assert kernels.interp_index_near(v, xp, 0.0) == want
