"""Health checks re-judged against a truth-Monte-Carlo band, and synthetic runs judged against their truth."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest

from workbench.estimation.calibration import (
    Z_BAND,
    band_key,
    calibrate_checks,
    family_z,
    finish_health,
    fit_band,
    nis_error_factor,
    truth_check,
)
from workbench.estimation.health import ERROR, OK, WARNING, Check, nis_check
from workbench.problems.calibration import CALIBRATION_STREAM, TUNING_STREAM, VALIDATION_STREAM, seeds_of


def _table(name: str, values, kind: str = "nis", dof: int = 3) -> dict:
    stat = {"kind": kind, "dof": dof} if kind == "nis" else {"kind": kind}
    return {"source": "test MC", "checks": {name: {"stat": stat, **fit_band(values, kind)}}}


def test_fit_band_covers_every_member_and_uses_log_scale_for_positive_statistics():
    rng = np.random.default_rng(5)
    v = np.exp(rng.normal(np.log(0.13), 0.1, 60))
    band = fit_band(v, "nis")
    assert band["scale"] == "log" and band["n"] == 60
    lo, hi = band["band"]
    assert lo <= v.min() and hi >= v.max()
    # the band is center ± Z_BAND σ of ln v: about ±33 % for σ = 0.1, nowhere near χ²'s [1.5, 6]
    assert hi < 0.25 and lo > 0.06
    assert abs(np.log(hi / lo) / 2 - Z_BAND * np.std(np.log(v), ddof=1)) < 0.05
    signed = fit_band(rng.normal(0.0, 1.0, 40), "two_sided")
    assert signed["scale"] == "linear" and signed["band"][0] < 0 < signed["band"][1]
    with pytest.raises(ValueError, match="at least 2"):
        fit_band([1.0, float("nan")], "upper")


def test_conservative_nis_inside_its_honest_band_is_ok_with_one_note():
    honest = np.exp(np.random.default_rng(1).normal(np.log(0.13), 0.08, 50))
    table = _table("nis.zupt", honest)
    raw = nis_check("zupt", np.full(500, 0.13), 3)
    assert raw.status == WARNING  # χ² alone: "conservative" on every honest run
    checks, notes = calibrate_checks([asdict(raw)], table)
    assert checks[0]["status"] == OK and "honest band" in checks[0]["message"]
    assert len(notes) == 1 and "conservative by design" in notes[0] and "nis.zupt" in notes[0]


def test_nis_above_band_warns_and_far_above_is_error_naming_the_sensor():
    honest = np.exp(np.random.default_rng(2).normal(np.log(0.13), 0.08, 50))
    table = _table("nis.zupt", honest)
    hi = table["checks"]["nis.zupt"]["band"][1]
    warn = asdict(nis_check("zupt", np.full(500, hi * 1.5), 3))
    err = asdict(nis_check("zupt", np.full(500, hi * nis_error_factor(3) * 1.2), 3))
    (w,), _ = calibrate_checks([warn], table)
    (e,), _ = calibrate_checks([err], table)
    assert w["status"] == WARNING and "above" in w["message"]
    assert e["status"] == ERROR and "zupt" in e["message"] and "unit" in e["message"]


def test_nis_above_a_narrow_band_by_its_width_is_error_far_below_only_a_warning():
    # a narrow honest band (±4 %, the Huygens entry accelerometer's): 2.5× its top is far outside every
    # honest member though far below the χ² factor; its bottom / 2.5 is only conservative
    honest = np.exp(np.random.default_rng(3).normal(np.log(0.43), 0.0115, 30))
    table = _table("nis.accel_entry", honest, dof=1)
    lo, hi = table["checks"]["nis.accel_entry"]["band"]
    assert hi * hi / lo < 1.2 * hi < 2.5 * hi < hi * nis_error_factor(1)
    inside_margin = asdict(nis_check("accel_entry", np.full(400, 0.99 * hi * hi / lo), 1))
    far = asdict(nis_check("accel_entry", np.full(400, 2.5 * hi), 1))
    low = asdict(nis_check("accel_entry", np.full(400, lo / 2.5), 1))
    (m,), _ = calibrate_checks([inside_margin], table)
    (e,), _ = calibrate_checks([far], table)
    (w,), _ = calibrate_checks([low], table)
    assert m["status"] == WARNING
    assert e["status"] == ERROR and "initial state" in e["message"] and "band's width" in e["message"]
    assert w["status"] == WARNING and "below" in w["message"]


def test_physics_error_is_never_softened_and_uncalibrated_checks_say_so():
    table = _table("nis.zupt", [0.1, 0.12, 0.14])
    phys = Check("geometry.hanging", ERROR, 1.0, 0.1, "hanging position contradicts the data")
    stat_err = Check("nis.zupt", ERROR, 0.13, [0.0, 1.0], "χ² says error", {"kind": "nis", "dof": 3})
    other = Check("nis.radar", WARNING, 0.2, [0.5, 2.0], "radar conservative", {"kind": "nis", "dof": 1})
    out, _ = calibrate_checks([asdict(phys), asdict(stat_err), asdict(other)], table)
    assert out[0] == asdict(phys)
    assert out[1]["status"] == ERROR
    assert out[2]["status"] == WARNING and "uncalibrated" in out[2]["message"]


def test_upper_statistic_below_its_band_is_ok():
    table = _table("gaps.max_s", [0.02, 0.03, 0.025, 0.028], kind="upper")
    c = Check("gaps.max_s", WARNING, 0.001, 0.02, "largest gap", {"kind": "upper"})
    (out,), _ = calibrate_checks([asdict(c)], table)
    assert out["status"] == OK


def test_truth_check_flags_a_headline_outside_its_reported_3_sigma():
    ok = truth_check("max_stroke", "max stroke", -0.039, 0.049, "m")
    assert ok.status == OK and ok.value == pytest.approx(0.795918, rel=1e-5)
    bad = truth_check("end_position", "end position", [-6160.0, -24210.0, -440.0], [360.0, 1170.0, 1940.0], "m")
    assert bad.status == ERROR and bad.value > 20 and "over-confident" in bad.message
    assert truth_check("x", "x", 1.0, 0.0).status == ERROR  # a σ of 0 cannot cover anything


def test_finish_health_recomputes_the_verdict_and_names_the_table():
    honest = np.exp(np.random.default_rng(3).normal(np.log(0.13), 0.08, 50))
    table = {**_table("nis.zupt", honest), "command": "python -m workbench.problems.calibration droptest"}
    health = {"verdict": WARNING, "checks": [asdict(nis_check("zupt", np.full(500, 0.13), 3))], "notes": []}
    out = finish_health(health, table, {"headline": [{"name": "s", "what": "stroke", "error": 0.01, "sigma": 0.05}]})
    assert out["verdict"] == OK and out["calibration"]["command"].endswith("droptest")
    assert [c["name"] for c in out["checks"]] == ["nis.zupt", "truth.s"]
    bad = finish_health(health, table, {"headline": [{"name": "s", "what": "stroke", "error": 0.5, "sigma": 0.05}]})
    assert bad["verdict"] == ERROR
    assert finish_health(health, None)["verdict"] == WARNING  # no table: χ² judgement stands


def test_seed_streams_are_disjoint_and_reproducible():
    t, v, c = (set(seeds_of(k, 200)) for k in (TUNING_STREAM, VALIDATION_STREAM, CALIBRATION_STREAM))
    assert not (t & v) and not (t & c) and not (v & c)
    assert seeds_of(CALIBRATION_STREAM, 5) == seeds_of(CALIBRATION_STREAM, 5)
    assert all(0 <= s < 2**31 for s in c)


def test_family_z_bounds_the_chance_that_an_honest_run_leaves_any_band():
    from scipy.stats import norm

    assert family_z(1) == Z_BAND  # one band: never narrower than the two-sided 99.9 %
    z = family_z(22)
    assert 3.4 < z < 3.6
    assert 22 * 2 * norm.sf(z) == pytest.approx(0.01, rel=1e-6)
    assert fit_band([1.0, 2.0, 3.0], "nis", z)["z"] == pytest.approx(z, rel=1e-5)


def test_a_pooled_check_is_judged_by_its_pools_band_not_by_its_name():
    # seven exchangeable ports share one band: a value outside the band of its own name's (absent)
    # entry but inside the pool's is OK, and the message names the pool
    rng = np.random.default_rng(3)
    table = _table("nis.pass1_port", np.exp(rng.normal(np.log(0.15), 0.06, 210)))
    hi = table["checks"]["nis.pass1_port"]["band"][1]
    stat = {"kind": "nis", "dof": 1, "pool": "nis.pass1_port"}
    inside = Check("nis.pass1_P4", WARNING, 0.95 * hi, [0.5, 2.0], "P4", stat)
    outside = Check("nis.pass1_P4", WARNING, 1.5 * hi, [0.5, 2.0], "P4", stat)
    (a,), _ = calibrate_checks([asdict(inside)], table)
    (b,), _ = calibrate_checks([asdict(outside)], table)
    assert a["status"] == OK and "pool nis.pass1_port" in a["message"]
    assert b["status"] == WARNING and "above" in b["message"]
    assert band_key("nis.pass1_P4", stat) == "nis.pass1_port" and band_key("nis.x", {"kind": "nis"}) == "nis.x"


def test_a_two_sided_statistic_far_beyond_its_band_is_an_error_with_the_checks_own_message():
    rng = np.random.default_rng(4)
    table = _table("geometry.first_contact.ranging", rng.normal(-0.07, 0.006, 30), kind="two_sided")
    lo, hi = table["checks"]["geometry.first_contact.ranging"]["band"]
    stat = {"kind": "two_sided", "pool": "geometry.first_contact.ranging"}
    half = 0.5 * (hi - lo)

    def judged(v):
        c = Check("geometry.first_contact", OK, v, [-0.3, 0.01], "likely: the lander geometry", stat)
        return calibrate_checks([asdict(c)], table)[0][0]

    assert judged(0.5 * (lo + hi))["status"] == OK
    assert judged(lo - 0.5 * half)["status"] == WARNING
    far = judged(lo - 1.5 * half)
    assert far["status"] == ERROR and "lander geometry" in far["message"] and "beyond" in far["message"]


def test_monte_carlo_options_seed_from_a_named_stream():
    """``workbench mc --stream validation``: the members' seeds are the validation stream's, the
    same the benchmarks use, disjoint from the tuning stream's and from ``--first-seed``'s."""
    from workbench.problems.base import McOptions

    legacy = McOptions(n_runs=5, first_seed=1)
    val = McOptions(n_runs=5, stream="validation")
    tun = McOptions(n_runs=5, stream="tuning")
    assert legacy.seeds == [1, 2, 3, 4, 5] and legacy.entropy == 1
    assert val.seeds == seeds_of(VALIDATION_STREAM, 5) and val.entropy == val.seeds[0]
    assert not set(val.seeds) & set(tun.seeds) and val.entropy != tun.entropy
    assert val.seed_record()["stream"] == "validation" and legacy.seed_record()["stream"] is None
    with pytest.raises(ValueError, match="unknown seed stream"):
        McOptions(stream="holdout")
