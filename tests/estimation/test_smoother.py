"""Tests of workbench.estimation.smoother: exactness on a linear time-varying system, PD check,
iterated (re-linearised) smoother as Gauss-Newton on a range-only tracking problem."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from workbench.estimation.ekf import ErrorStateLayout, ForwardPass, Measurement, run_filter
from workbench.estimation.smoother import cross_covariance, iterated_rts, rts_smooth


def _spd(rng, n, scale):
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T / n + 0.5 * np.eye(n))


def _ltv_problem(seed=0, n=25, d=3):
    """x_k = F_k x_{k-1} + u_k + w_k with F_k, Q_k, H_k all varying; some steps without data,
    some with two measurements (processed sequentially)."""
    rng = np.random.default_rng(seed)
    Fs = [np.eye(d)] + [np.eye(d) + 0.3 * rng.standard_normal((d, d)) for _ in range(1, n)]
    us = [np.zeros(d)] + [rng.standard_normal(d) for _ in range(1, n)]
    Qs = [np.zeros((d, d))] + [_spd(rng, d, 0.2) for _ in range(1, n)]
    meas = {}
    for k in range(n):
        if k % 4 == 3:
            continue  # no measurement at this step
        items = []
        for _ in range(2 if k % 5 == 0 else 1):
            m = int(rng.integers(1, 3))
            H = rng.standard_normal((m, d))
            R = _spd(rng, m, 0.5)
            z = rng.standard_normal(m) * 3
            items.append((H, R, z))
        meas[k] = items
    m0 = rng.standard_normal(d)
    P0 = _spd(rng, d, 2.0)
    return Fs, us, Qs, meas, m0, P0


def _batch_map(Fs, us, Qs, meas, m0, P0):
    """Information matrix Λ (n d, n d) and MAP solution of the whole-batch least-squares problem."""
    n, d = len(Fs), m0.size
    Lam = np.zeros((n * d, n * d))
    eta = np.zeros(n * d)

    def add(rows_A, W, b):
        # rows_A: list of (block index, matrix); residual = Σ A_i x_i − b, weight W
        for i, Ai in rows_A:
            eta[i * d : (i + 1) * d] += Ai.T @ W @ b
            for j, Aj in rows_A:
                Lam[i * d : (i + 1) * d, j * d : (j + 1) * d] += Ai.T @ W @ Aj

    add([(0, np.eye(d))], np.linalg.inv(P0), m0)
    for k in range(1, n):
        add([(k, np.eye(d)), (k - 1, -Fs[k])], np.linalg.inv(Qs[k]), us[k])
    for k, items in meas.items():
        for H, R, z in items:
            add([(k, H)], np.linalg.inv(R), z)
    X = np.linalg.solve(Lam, eta).reshape(n, d)
    C = np.linalg.inv(Lam)
    return X, np.array([C[k * d : (k + 1) * d, k * d : (k + 1) * d] for k in range(n)])


def _run(Fs, us, Qs, meas, m0, P0):
    d = m0.size
    lay = ErrorStateLayout(d)
    t = np.arange(len(Fs), dtype=float)

    def transition(x, t0, t1):
        k = int(round(t1))
        return Fs[k] @ x + us[k], Fs[k]

    def process_noise(x, t0, t1):
        return Qs[int(round(t1))]

    def measurements_at(k, tk, x):
        return [
            Measurement(f"m{i}_{z.size}", z, R, lambda s, H=H: H @ s, H) for i, (H, R, z) in enumerate(meas.get(k, []))
        ]

    fp = run_filter(m0, P0, t, transition, process_noise, measurements_at, lay)
    return fp, rts_smooth(fp, lay)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kf_rts_equals_batch_map_on_linear_time_varying_system(seed):
    Fs, us, Qs, meas, m0, P0 = _ltv_problem(seed)
    fp, sp = _run(Fs, us, Qs, meas, m0, P0)
    X, C = _batch_map(Fs, us, Qs, meas, m0, P0)
    np.testing.assert_allclose(sp.x, X, rtol=1e-9, atol=1e-9 * np.abs(X).max())
    np.testing.assert_allclose(sp.P, C, rtol=1e-9, atol=1e-9 * np.abs(C).max())
    # the filter's last posterior is the smoother's last estimate
    np.testing.assert_array_equal(sp.x[-1], fp.x_post[-1])
    assert np.all(sp.G[-1] == 0.0)
    # smoothing never increases the variance
    var_s = np.diagonal(sp.P, axis1=1, axis2=2)
    assert np.all(var_s <= np.diagonal(fp.P_post, axis1=1, axis2=2) * (1 + 1e-12))


@pytest.mark.parametrize("seed", [0, 1])
def test_cross_covariance_is_the_batch_joint_covariance(seed):
    """The smoother's lag cross-covariance between two epochs equals the off-diagonal block of the
    inverse batch information matrix (the exact joint posterior of the linear problem)."""
    Fs, us, Qs, meas, m0, P0 = _ltv_problem(seed)
    fp, sp = _run(Fs, us, Qs, meas, m0, P0)
    n, d = len(Fs), m0.size
    Lam = np.zeros((n * d, n * d))
    # rebuild the information matrix as _batch_map does (it returns only the diagonal blocks)
    Lam[:d, :d] += np.linalg.inv(P0)
    for k in range(1, n):
        A = [(k, np.eye(d)), (k - 1, -Fs[k])]
        W = np.linalg.inv(Qs[k])
        for i, Ai in A:
            for j, Aj in A:
                Lam[i * d : (i + 1) * d, j * d : (j + 1) * d] += Ai.T @ W @ Aj
    for k, items in meas.items():
        for H, R, _z in items:
            Lam[k * d : (k + 1) * d, k * d : (k + 1) * d] += H.T @ np.linalg.inv(R) @ H
    C = np.linalg.inv(Lam)
    for a, b in ((2, 9), (0, n - 1), (5, 5)):
        want = C[a * d : (a + 1) * d, b * d : (b + 1) * d]
        np.testing.assert_allclose(cross_covariance(sp, a, b), want, rtol=1e-8, atol=1e-10)
    with pytest.raises(ValueError):
        cross_covariance(sp, 4, 3)


def test_time_varying_F_index_matters():
    """Guard against filterpy #278: using F[k] instead of F[k+1] gives a different (wrong) answer."""
    Fs, us, Qs, meas, m0, P0 = _ltv_problem(0)
    fp, sp = _run(Fs, us, Qs, meas, m0, P0)
    shifted = ForwardPass(
        fp.t, fp.x_prior, fp.P_prior, fp.x_post, fp.P_post, np.concatenate([fp.F[1:], fp.F[-1:]]), fp.Q, fp.innovations
    )
    try:
        wrong = rts_smooth(shifted, ErrorStateLayout(3))
    except ValueError:  # here the mis-indexed gain even drives P_s indefinite
        return
    assert np.max(np.abs(wrong.x - sp.x)) > 1e-3


def test_non_pd_smoothed_covariance_raises_naming_step():
    n = 4
    lay = ErrorStateLayout(1)
    F = np.ones((n, 1, 1))
    F[2] = 10.0  # inconsistent with P_prior[2] below
    P_post = np.ones((n, 1, 1))
    P_post[2:] = 1e-3
    P_prior = np.ones((n, 1, 1))
    fp = ForwardPass(
        np.arange(n, dtype=float), np.zeros((n, 1)), P_prior, np.zeros((n, 1)), P_post, F, np.zeros((n, 1, 1)), {}
    )
    with pytest.raises(ValueError, match="step 1"):
        rts_smooth(fp, lay)


# ---------------------------------------------------------------------------------------------
# iterated (re-linearised) RTS on a nonlinear problem: a constant-velocity target in the plane
# tracked by ranges [m] from two stations, started 30 m off.  Independent of any problem package.

_STATIONS = np.array([[0.0, 0.0], [60.0, 0.0]])


def _ranges(x):
    return np.linalg.norm(x[:2] - _STATIONS, axis=1)


def _ranges_H(x):
    d = x[:2] - _STATIONS
    H = np.zeros((2, 4))
    H[:, :2] = d / np.linalg.norm(d, axis=1)[:, None]
    return H


def _range_only_problem(seed=6, n=25):
    """State [p_x, p_y, v_x, v_y] (m, m/s), dt = 1 s, white-acceleration process noise."""
    rng = np.random.default_rng(seed)
    F = np.eye(4)
    F[0, 2] = F[1, 3] = 1.0
    Q = 0.05 * np.array([[1 / 3, 0, 1 / 2, 0], [0, 1 / 3, 0, 1 / 2], [1 / 2, 0, 1, 0], [0, 1 / 2, 0, 1]])
    P0 = np.diag([30.0, 30.0, 3.0, 3.0]) ** 2
    x = np.array([10.0, 40.0, 2.0, -1.0])
    m0 = x + rng.multivariate_normal(np.zeros(4), P0)
    X = [x]
    for _ in range(1, n):
        X.append(F @ X[-1] + rng.multivariate_normal(np.zeros(4), Q))
    X = np.array(X)
    R = 0.5**2 * np.eye(2)
    Z = np.array([_ranges(xk) for xk in X]) + 0.5 * rng.standard_normal((n, 2))
    return F, Q, m0, P0, X, Z, R


def _range_only_pass(F, Q, m0, P0, Z, R):
    """``run_pass(reference)`` of :func:`iterated_rts`: the EKF, or the pass with the ranges
    linearised about the reference trajectory (the dynamics are linear)."""
    lay = ErrorStateLayout(4)
    t = np.arange(Z.shape[0], dtype=float)

    def run_pass(ref):
        def measurements_at(k, tk, x):
            if ref is None:
                return [Measurement("range", Z[k], R, _ranges, _ranges_H)]
            xb = ref[k]
            hb, Hb = _ranges(xb), _ranges_H(xb)
            return [Measurement("range", Z[k], R, lambda s: hb + Hb @ (s - xb), Hb)]

        return run_filter(m0, P0, t, lambda x, t0, t1: (F @ x, F), lambda x, t0, t1: Q, measurements_at, lay)

    return run_pass, lay


def _map_cost_and_gradient(X, F, Q, m0, P0, Z, R):
    """Batch MAP cost J (prior + dynamics + ranges) of a trajectory X (n, 4) and its gradient (n, 4)."""
    g = np.zeros_like(X)
    e = X[0] - m0
    J = 0.5 * e @ np.linalg.solve(P0, e)
    g[0] += np.linalg.solve(P0, e)
    for k in range(1, X.shape[0]):
        e = X[k] - F @ X[k - 1]
        w = np.linalg.solve(Q, e)
        J += 0.5 * e @ w
        g[k] += w
        g[k - 1] -= F.T @ w
    for k in range(X.shape[0]):
        e = Z[k] - _ranges(X[k])
        w = np.linalg.solve(R, e)
        J += 0.5 * e @ w
        g[k] -= _ranges_H(X[k]).T @ w
    return J, g


def test_iterated_rts_is_gauss_newton_on_range_only_tracking():
    F, Q, m0, P0, X, Z, R = _range_only_problem()
    run_pass, lay = _range_only_pass(F, Q, m0, P0, Z, R)
    one = iterated_rts(run_pass, lay, 1)
    # one pass is the plain EKF + RTS
    ref = rts_smooth(run_pass(None), lay)
    np.testing.assert_array_equal(one.smoothed.x, ref.x)
    np.testing.assert_array_equal(one.smoothed.P, ref.P)
    assert one.passes == 1 and one.changes == [] and one.forward is one.first and not one.converged

    it = iterated_rts(run_pass, lay, 8)
    assert it.passes == 8 and len(it.changes) == 7 and not it.converged
    # the first (causal) forward pass is kept; the last one is the re-linearised pass
    np.testing.assert_array_equal(it.first.x_post, one.first.x_post)
    assert not np.allclose(it.forward.x_post, it.first.x_post)
    # the change between passes shrinks (quadratically here) to round-off
    size = np.array([c.max() for c in it.changes])
    assert size[0] > 1.0
    assert np.all(size[1:5] < 0.1 * size[:4])
    assert size[-1] < 1e-9
    # it reaches the batch MAP estimate (gradient ~ 0) that the single pass misses ...
    J1, g1 = _map_cost_and_gradient(one.smoothed.x, F, Q, m0, P0, Z, R)
    J, g = _map_cost_and_gradient(it.smoothed.x, F, Q, m0, P0, Z, R)
    assert J < 0.1 * J1
    assert np.abs(g).max() < 1e-6 * np.abs(g1).max()
    # ... and is closer to the truth: the first pass kept the EKF's linearisation errors
    err1 = np.sqrt(np.mean((one.smoothed.x[:, :2] - X[:, :2]) ** 2))
    err = np.sqrt(np.mean((it.smoothed.x[:, :2] - X[:, :2]) ** 2))
    assert err < 0.5 * err1


def test_iterated_rts_stops_on_step_tolerance():
    F, Q, m0, P0, X, Z, R = _range_only_problem()
    run_pass, lay = _range_only_pass(F, Q, m0, P0, Z, R)
    full = iterated_rts(run_pass, lay, 8)
    tol = np.array([1e-6, 1e-6, 1e-7, 1e-7])
    early = iterated_rts(run_pass, lay, 8, step_tol=tol)
    assert early.converged and early.passes < full.passes
    assert np.all(early.changes[-1] < tol) and not np.all(early.changes[-2] < tol)
    np.testing.assert_allclose(early.smoothed.x, full.smoothed.x, rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="passes"):
        iterated_rts(run_pass, lay, 0)


def test_exactly_known_component_gets_no_gain_and_matches_the_reduced_smoother():
    """A state with zero variance and no process noise (an error declared absent, σ = 0) is known
    exactly: the smoother must not fail on it, keep it at its value with zero variance, and give the
    other components exactly what the smoother of the reduced system gives."""
    rng = np.random.default_rng(3)
    n = 30
    t = np.arange(n, dtype=float)
    z = np.cumsum(rng.normal(0.0, 0.3, n)) + rng.normal(0.0, 0.5, n)

    def run(full: bool):
        d = 3 if full else 2
        F = np.eye(d)
        F[0, 1] = 1.0  # position, velocity (+ a bias of exactly 0.7 with σ = 0)
        Q = np.zeros((d, d))
        Q[1, 1] = 0.05
        x0 = np.array([0.0, 0.0, 0.7])[:d]
        P0 = np.diag([4.0, 1.0, 0.0][:d])
        H = np.zeros((1, d))
        H[0, 0] = 1.0
        if full:
            H[0, 2] = 1.0  # the measurement sees the (known) bias
        zz = z + (0.7 if full else 0.0)

        def transition(x, t0, t1):
            return F @ x, F

        def meas(k, tk, x):
            return [Measurement("z", np.array([zz[k]]), np.array([[0.25]]), lambda x: H @ x, H)]

        lay = ErrorStateLayout(d)
        fp = run_filter(x0, P0, t, transition, lambda x, t0, t1: Q, meas, lay)
        return rts_smooth(fp, lay)

    full, reduced = run(True), run(False)
    np.testing.assert_allclose(full.x[:, :2], reduced.x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(full.P[:, :2, :2], reduced.P, rtol=1e-10, atol=1e-14)
    assert np.all(full.x[:, 2] == 0.7) and np.all(full.P[:, 2, :] == 0.0)


def test_consider_parameter_smoother_covariance_is_exact():
    """A random walk seen through a constant bias c that is *considered* (Schmidt: carried in P,
    never estimated): the smoothed error covariance equals the exact one, computed from the
    estimator's linear response to each independent error source, and c is never moved."""
    n, q, r, p0, pc = 12, 0.3, 0.5, 2.0, 0.8
    layout = ErrorStateLayout(2)
    Pi = np.diag([1.0, 0.0])
    H = np.array([[1.0, 1.0]])

    def run(e0, c, w, v):
        x_true = e0 + np.cumsum(np.r_[0.0, w])
        z = x_true + c + v

        def transition(x, t0, t1):
            return x, np.eye(2), np.diag([q, 0.0])

        def meas(k, tk, x):
            return [Measurement("z", z[k : k + 1], np.array([[r]]), lambda s: H @ s, H=H, gain_projector=lambda s: Pi)]

        fp = run_filter(np.zeros(2), np.diag([p0, pc]), np.arange(n, dtype=float), transition, None, meas, layout)
        sm = rts_smooth(fp, layout, consider=[1])
        return sm, sm.x - np.stack([x_true, np.full(n, c)], 1)

    sources = [(np.sqrt(p0), 0.0, np.zeros(n - 1), np.zeros(n)), (0.0, np.sqrt(pc), np.zeros(n - 1), np.zeros(n))]
    for i in range(n - 1):
        w = np.zeros(n - 1)
        w[i] = np.sqrt(q)
        sources.append((0.0, 0.0, w, np.zeros(n)))
    for i in range(n):
        v = np.zeros(n)
        v[i] = np.sqrt(r)
        sources.append((0.0, 0.0, np.zeros(n - 1), v))
    errs = []
    for s in sources:
        sm, e = run(*s)
        errs.append(e)
        assert np.all(sm.x[:, 1] == 0.0)  # the consider parameter keeps its prior value
    E = np.array(errs)  # (sources, n, 2)
    exact = np.einsum("snj,snk->njk", E, E)
    np.testing.assert_allclose(sm.P, exact, rtol=1e-9, atol=1e-12)
    # and the smoother did help the estimated state where the filter alone could not
    assert sm.P[0, 0, 0] < p0 + pc


def _consider_pass():
    """A random walk seen through a constant bias that is considered (projected gain), as below."""
    rng = np.random.default_rng(5)
    n, layout, H = 40, ErrorStateLayout(2), np.array([[1.0, 1.0]])
    z = np.cumsum(rng.normal(0.0, 0.5, n)) + 0.8 + rng.normal(0.0, 0.7, n)

    def meas(k, tk, x):
        return [
            Measurement(
                "z", z[k : k + 1], np.array([[0.5]]), lambda s: H @ s, H=H, gain_projector=lambda s: np.diag([1.0, 0.0])
            )
        ]

    def transition(x, t0, t1):
        return x, np.eye(2), np.diag([0.3, 0.0])

    return run_filter(np.zeros(2), np.diag([2.0, 0.8]), np.arange(n, dtype=float), transition, None, meas, layout)


def _known_component_pass():
    """Position, velocity and a bias known exactly (σ = 0, no process noise): the smoother's
    zero-variance branch."""
    rng = np.random.default_rng(6)
    F, H = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 1.0]])
    z = np.cumsum(rng.normal(0.0, 0.3, 30)) + 0.7

    def meas(k, tk, x):
        return [Measurement("z", z[k : k + 1], np.array([[0.25]]), lambda s: H @ s, H)]

    Q = np.diag([0.0, 0.05, 0.0])
    return run_filter(
        np.array([0.0, 0.0, 0.7]), np.diag([4.0, 1.0, 0.0]), np.arange(30.0), lambda x, t0, t1: (F @ x, F),
        lambda x, t0, t1: Q, meas, ErrorStateLayout(3),
    )  # fmt: skip


@pytest.mark.parametrize("flags", [(True, False), (False, True), (True, True)], ids=["F", "prior", "both"])
@pytest.mark.parametrize(
    "case", ["linear time-varying", "one step", "two steps", "consider parameter", "component known exactly"]
)
def test_overwrite_writes_gains_and_smoothed_covariances_in_place_with_the_same_numbers(case, flags):
    """``overwrite_F`` / ``overwrite_prior`` (a long pass's memory: one n × n_e² history less each)
    give bit for bit the default smoother's x, P and G, and fp.F's / fp.P_prior's memory then holds
    G / P_s (the transitions and priors are consumed)."""
    over_F, over_prior = flags
    consider = None
    if case == "consider parameter":
        fp, consider = _consider_pass(), [1]
    elif case == "component known exactly":
        fp = _known_component_pass()
        assert np.all(fp.P_prior[:, 2, :] == 0.0)  # the branch under test
    else:
        n = {"one step": 1, "two steps": 2}.get(case, 25)
        fp = _run(*_ltv_problem(2, n=n))[0]
    layout = ErrorStateLayout(fp.x_post.shape[1])
    ref = rts_smooth(fp, layout, consider=consider)
    F_before, prior_before = fp.F.copy(), fp.P_prior.copy()
    sp = rts_smooth(fp, layout, consider=consider, overwrite_F=over_F, overwrite_prior=over_prior)
    for a, b in ((sp.x, ref.x), (sp.P, ref.P), (sp.G, ref.G)):
        np.testing.assert_array_equal(a, b)
    assert (sp.G is fp.F) == over_F and (sp.P is fp.P_prior) == over_prior
    assert np.array_equal(fp.F, F_before) != over_F
    assert np.array_equal(fp.P_prior, prior_before) != over_prior
    if fp.t.size > 1:
        np.testing.assert_array_equal(cross_covariance(sp, 0, fp.t.size - 1), cross_covariance(ref, 0, fp.t.size - 1))


def test_overwrite_refuses_an_array_it_cannot_write():
    Fs, us, Qs, meas, m0, P0 = _ltv_problem(0)
    fp, _ = _run(Fs, us, Qs, meas, m0, P0)
    ro = fp.F.copy()
    ro.flags.writeable = False
    for F in (ro, fp.F.astype(np.float32), fp.F[:-1]):
        with pytest.raises(ValueError, match="overwrite_F"):
            rts_smooth(replace(fp, F=F), ErrorStateLayout(m0.size), overwrite_F=True)
        with pytest.raises(ValueError, match="overwrite_prior"):
            rts_smooth(replace(fp, P_prior=F), ErrorStateLayout(m0.size), overwrite_prior=True)
    with pytest.raises(ValueError, match="share memory"):  # a view of P_post would be read after it is written
        rts_smooth(replace(fp, P_prior=fp.P_post[:]), ErrorStateLayout(m0.size), overwrite_prior=True)
