"""MEADS health verdict (``problems/meads/health.py``) on constructed stages: the WLS residual χ²
judged per degrees of freedom, the envelope and density checks each able to fail."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from workbench.core.atmosphere import MarsEngineeringAtmosphere
from workbench.problems.meads.health import meads_health, wls_chi2

N, M = 400, 7


def _stages(rng, *, sigma_scale=1.0, alpha_deg=18.0, density_factor=1.0):
    """Stages of a consistent reduction: residuals drawn with the σ the fit used (× sigma_scale)."""
    sigma = np.full((N, M), 20.0)
    used = np.ones((N, M), bool)
    used[N // 2 :, 4] = False  # a port dropped half way: 6 ports, dof 2 after it
    x = rng.normal(size=(N, 4))
    x[: N // 4, 3] = np.nan  # fixed-R rows: three states solved, dof 4
    residual = np.where(used, sigma_scale * sigma * rng.standard_normal((N, M)), np.nan)
    # a least-squares residual has m − k degrees of freedom: k of its components are fitted away
    ks = np.isfinite(x).sum(axis=1)
    residual[np.arange(M)[None, :] < ks[:, None]] = 0.0
    h = np.linspace(40e3, 10e3, N)
    rho = density_factor * MarsEngineeringAtmosphere().density(h)
    qbar = np.full(N, 5000.0)
    fit = SimpleNamespace(
        qbar=qbar,
        alpha=np.full(N, np.radians(alpha_deg)),
        beta=np.full(N, np.radians(0.5)),
        mach=np.full(N, 10.0),
        sigma_p=sigma,
        wls=SimpleNamespace(residual=residual, used=used, x=x, P=np.tile(np.diag([100.0, 1e-5, 1e-5, 0.1]), (N, 1, 1))),
    )
    t = np.arange(N) / 8.0
    tel = SimpleNamespace(t_p=t, degradations=[])
    nav = SimpleNamespace(h=h, mach_inertial=np.full(N, 10.0))
    air = SimpleNamespace(fit=fit, plausibility_ratio=1.02, failures=(), alt=None)
    wind = SimpleNamespace(density=rho, mach_source=np.full(N, "air_data"))
    est = SimpleNamespace(min_qbar_pa=850.0, plausibility_factor=3.0, model="table")
    return tel, nav, air, wind, est


def _by_name(h):
    return {c["name"]: c for c in h["checks"]}


def test_wls_chi2_degrees_of_freedom():
    rng = np.random.default_rng(0)
    tel, nav, air, wind, est = _stages(rng)
    w = air.fit.wls
    chi2, dof = wls_chi2(w.residual, air.fit.sigma_p, w.used, w.x)
    assert set(np.unique(dof)) == {2, 3, 4}
    assert np.all(dof[: N // 4] == 4) and np.all(dof[N // 2 :] == 2)
    np.testing.assert_allclose(chi2[0], np.sum((w.residual[0] / 20.0) ** 2))


def test_consistent_reduction_is_ok():
    h = meads_health(*_stages(np.random.default_rng(1)))
    assert h["verdict"] == "OK", h
    names = _by_name(h)
    assert {"nis.pressure_wls_dof2", "nis.pressure_wls_dof3", "nis.pressure_wls_dof4"} <= set(names)


@pytest.mark.parametrize(
    ("kw", "name", "status"),
    [
        ({"sigma_scale": 6.0}, "nis.pressure_wls_dof2", "ERROR"),  # port σ far too small
        ({"sigma_scale": 0.3}, "nis.pressure_wls_dof3", "WARNING"),  # conservative
        ({"alpha_deg": 40.0}, "envelope.alpha_deg", "WARNING"),  # outside the models' validity
        ({"alpha_deg": 120.0}, "envelope.alpha_deg", "ERROR"),  # not physical for forebody ports
        ({"density_factor": 8.0}, "density.vs_default", "ERROR"),
    ],
)
def test_each_check_can_fail(kw, name, status):
    h = meads_health(*_stages(np.random.default_rng(2), **kw))
    assert _by_name(h)[name]["status"] == status
    assert h["verdict"] in (status, "ERROR")


@pytest.mark.parametrize(
    ("shift_deg", "outside", "status"), [(0.05, 0.0, "OK"), (0.5, 0.3, "WARNING"), (0.5, 1.0, "ERROR")]
)
def test_newtonian_model_form_against_the_table(shift_deg, outside, status):
    """With the Newtonian model the same pressures reduced with the table are the yardstick of its
    model-form error: an α difference beyond the published 3σ (0.3° here) at a fraction
    ``outside`` of the samples is a WARNING, at most of them an ERROR, one well inside it is OK;
    with the table as the model nothing is judged."""
    tel, nav, air, wind, est = _stages(np.random.default_rng(3))
    shift = np.where(np.arange(N) < outside * N, shift_deg, 0.05)
    fit = SimpleNamespace(
        **{**air.fit.__dict__, "sigma_alpha": np.full(N, np.radians(0.1)), "sigma_qbar": np.full(N, 50.0)}
    )
    alt = SimpleNamespace(**{**fit.__dict__, "alpha": fit.alpha + np.radians(shift), "model": "table"})
    air = SimpleNamespace(**{**air.__dict__, "fit": fit, "alt": alt})
    names = _by_name(meads_health(tel, nav, air, wind, SimpleNamespace(**{**est.__dict__, "model": "newtonian"})))
    assert names["model_form.alpha_newtonian_vs_table"]["status"] == status
    assert names["model_form.qbar_newtonian_vs_table"]["status"] == "OK"
    assert not any(n.startswith("model_form") for n in _by_name(meads_health(tel, nav, air, wind, est)))


def test_failed_ports_are_notes_until_the_redundancy_is_gone():
    """Each detected and excluded port failure is a note; ``data.failed_ports`` is a WARNING only
    when fewer than MIN_PORTS_LEFT ports remain (no redundancy to catch the next failure)."""
    from workbench.problems.meads.health import MIN_PORTS_LEFT, failed_ports_check

    def fail(port, t):
        return SimpleNamespace(port=port, t=t, how="stuck", message=f"{port} stuck")

    assert failed_ports_check([fail("P5", 150.0)], M).status == "OK"
    many = [fail(f"P{i}", 100.0 + i) for i in range(1, M - MIN_PORTS_LEFT + 2)]
    c = failed_ports_check(many, M)
    assert c.status == "WARNING" and f"{M - len(many)} left" in c.message
    tel, nav, air, wind, est = _stages(np.random.default_rng(4))
    air = SimpleNamespace(**{**air.__dict__, "failures": (fail("P5", 25.0),)})
    tel = SimpleNamespace(**{**tel.__dict__, "degradations": ["pressures.csv, column 'P2 [Pa]', rows 3-4: dropout"]})
    h = meads_health(tel, nav, air, wind, est)
    assert h["verdict"] == "OK", h
    assert h["notes"][0].startswith("port P5 failed at 25.0 s (stuck), detected and excluded")
    assert h["notes"][1].startswith("telemetry dropout, handled: pressures.csv, column 'P2 [Pa]'")
