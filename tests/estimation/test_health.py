"""The health checks (``estimation/health.py``): each status reachable, bounds from χ², the
verdict the worst status, and the report shape the summaries rely on."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.estimation.health import (
    ERROR,
    OK,
    WARNING,
    Check,
    UnhealthyError,
    covariance_check,
    covariance_stats,
    exact_components,
    gap_check,
    health_markdown,
    health_report,
    interval_check,
    nis_check,
    notes_check,
    verdict,
)


def test_nis_consistent_optimistic_conservative():
    rng = np.random.default_rng(1)
    nis = np.sum(rng.standard_normal((2000, 3)) ** 2, axis=1)  # χ²(3) samples: a consistent filter
    assert nis_check("BP", nis, 3).status == OK
    bad = nis_check("BP", 34.0 * nis, 3)  # a triad in g read as m/s² is ~100× in variance
    assert bad.status == ERROR and "filter inconsistent with sensor BP" in bad.message
    assert nis_check("zupt", 0.04 * nis, 3).status == WARNING  # conservative: over-large R
    assert nis_check("BP", 3.0 * nis, 3).status == WARNING  # optimistic, but not a unit error
    assert nis_check("x", np.array([]), 1).status == WARNING


def test_nis_few_samples_use_the_band_of_the_mean():
    # with one sample of dof 1 the mean may legitimately be large: the 99 % band is wide
    assert nis_check("g", np.array([6.0]), 1).status != ERROR


def test_covariance_check():
    P = np.tile(np.eye(3), (5, 1, 1))
    assert covariance_check(P).status == OK
    Q = P.copy()
    Q[3, 0, 0] = -1e-3
    c = covariance_check(Q)
    assert c.status == ERROR and "step 3" in c.message
    R = P.copy()
    R[2, 0, 1] = 0.5
    assert covariance_check(R).status == ERROR and "symmetric" in covariance_check(R).message
    S = P.copy()
    S[1, 1, 1] = np.nan
    assert covariance_check(S).status == ERROR


def test_components_declared_exact_are_left_out_and_named():
    """An error declared absent (σ = 0, no process noise) is an all-zero row and column at every step:
    the check judges the other components and names it; a variance that collapses to zero later, or
    an indefinite rest, is still an ERROR."""
    P = np.tile(np.diag([1.0, 0.0, 4.0]), (5, 1, 1))
    c = covariance_check(P, labels=["position", "gyro bias_dps", "velocity"])
    assert c.status == OK and "known exactly" in c.message and "gyro bias_dps" in c.message
    assert list(exact_components(P)) == [1]
    late = np.tile(np.eye(3), (5, 1, 1))
    late[3:, 1, 1] = 0.0  # zero only from step 3: not declared, collapsed
    assert exact_components(late).size == 0 and covariance_check(late).status == ERROR
    bad = P.copy()
    bad[2, 0, 0] = -1.0
    assert covariance_check(bad).status == ERROR


def test_covariance_stats_chunked_equal_whole(monkeypatch):
    """The history is examined in chunks of steps (bounded memory): the per-step numbers and the
    step a failure names do not depend on the chunk size."""
    import workbench.estimation.health as health

    rng = np.random.default_rng(4)
    A = rng.normal(size=(2500, 6, 6))
    P = A @ np.swapaxes(A, 1, 2) + 1e-3 * np.eye(6)
    P[1777, 2, 2] = -50.0  # one step not positive definite, in the second chunk
    P[2100, 0, 5] += 1e-3  # one asymmetric step
    whole = (
        np.max(np.abs(P - np.swapaxes(P, 1, 2)), axis=(1, 2)),
        np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, 1, 2))).min(axis=1),
    )
    for chunk in (1, 7, 1024, 10_000):
        monkeypatch.setattr(health, "_CHUNK_STEPS", chunk)
        a_abs, a_rel, emin = covariance_stats(P)
        np.testing.assert_array_equal(a_abs, whole[0])
        np.testing.assert_array_equal(emin, whole[1])
        assert int(np.argmax(a_rel)) == 2100 and int(np.argmin(emin)) == 1777
        P_sym = 0.5 * (P + np.swapaxes(P, 1, 2))
        assert "step 1777" in covariance_check(P_sym).message


def test_screened_covariance_check_equals_the_full_one():
    """Without ``stats`` the check computes the eigenvalues only where they can decide it (a
    Cholesky screen above the smallest of every 8th step): the same check as with every step's
    eigenvalues — positive definite, one indefinite or semi-definite step off the sampled ones,
    the minimum between samples, states of very different scales, correlation matrices."""
    rng = np.random.default_rng(9)
    A = rng.normal(size=(3001, 14, 14))
    P = A @ np.swapaxes(A, 1, 2) + 1e-3 * np.eye(14)
    cases = [P]
    for step, d in ((1234, -1.0), (2001, -1e-13), (77, 1e-9)):
        Q = P.copy()
        Q[step] = np.diag(np.r_[np.ones(13), d])
        cases.append(Q)
    s = np.r_[np.full(7, 1e4), np.full(7, 1e-8)]
    cases.append(P * s[None, :, None] * s[None, None, :])
    d = 1.0 / np.sqrt(np.einsum("nii->ni", P))
    cases.append(P * d[:, :, None] * d[:, None, :])
    for Q in cases:
        assert covariance_check(Q, "c") == covariance_check(Q, "c", stats=covariance_stats(Q))


def test_interval_and_gap_checks():
    assert interval_check("e", 0.4, 0.0, 1.0, "restitution").status == OK
    c = interval_check("e", 1.64, 0.0, 1.0, "restitution")
    assert c.status == ERROR and "physically implausible" in c.message
    assert interval_check("e", np.nan, 0.0, 1.0, "restitution").status == ERROR
    assert interval_check("r", 0.5, 0.0, 0.1, "share", status=WARNING).status == WARNING
    w = {"contact": (1.30, 1.45)}
    assert gap_check("g", [(0.2, 0.3)], w).status == OK
    c = gap_check("g", [(1.2, 1.7), (0.2, 0.3)], w)
    assert c.status == ERROR and c.value == pytest.approx(0.5) and "contact" in c.message


def test_verdict_report_markdown_and_error():
    checks = [Check("a", OK, 1, None, "fine"), notes_check("t", ["WARN: x"])]
    assert verdict(checks) == WARNING and verdict([]) == OK
    checks.append(Check("b", ERROR, 2, 1, "bad thing"))
    rep = health_report(checks)
    assert rep["verdict"] == ERROR
    assert set(rep["checks"][0]) == {"name", "status", "value", "bound", "message", "stat"}
    md = health_markdown({**rep, "written_anyway": True})
    assert "UNHEALTHY" in md and "bad thing" in md and "| a |" not in md  # OK checks are not listed
    err = UnhealthyError("s.toml", rep)
    assert "bad thing" in str(err) and "--allow-unhealthy" in str(err)
    with pytest.raises(ValueError):
        Check("c", "FINE", 0, None, "")


def test_covariance_check_tells_round_off_from_indefinite():
    """A state combination known to numerical precision (perfectly correlated states) gives an
    eigenvalue of either sign at round-off level: a WARNING, not an ERROR; a correlation beyond 1 by
    more than round-off is indefinite (ERROR). Both in units far from 1 (1e6 m², 1e-8)."""
    sig = np.array([1e3, 1e-4, 2.0])
    for eps, status in ((-1e-13, WARNING), (-1e-6, ERROR), (1e-11, OK)):
        C = np.eye(3)
        C[0, 1] = C[1, 0] = 1.0 - eps  # correlation 1 + 1e-13: eigenvalue -1e-13 of C
        P = np.tile(sig[:, None] * C * sig[None, :], (4, 1, 1))
        P[:2] = np.diag(sig**2)  # the first steps are fine
        c = covariance_check(P)
        assert c.status == status, (eps, c.message)
        if status == WARNING:  # (the OK case: the unscaled eigenvalue's sign is itself round-off)
            assert "round-off" in c.message and "2 step(s)" in c.message, c.message


def test_finite_steps_is_per_step_and_does_not_depend_on_the_chunk(monkeypatch):
    """:func:`finite_steps` (a long covariance history checked without an (n, k, k) boolean
    temporary) flags exactly the steps holding a NaN or an inf, whatever the chunk size."""
    import workbench.estimation.health as health

    P = np.ones((700, 4, 4))
    P[3, 1, 2] = np.nan
    P[699, 0, 0] = -np.inf
    x = np.zeros((700, 5))
    x[256, 4] = np.inf
    for chunk in (1, 255, 256, 10_000):
        monkeypatch.setattr(health, "_CHUNK_STEPS", chunk)
        assert np.flatnonzero(~health.finite_steps(P)).tolist() == [3, 699]
        assert np.flatnonzero(~health.finite_steps(x)).tolist() == [256]
