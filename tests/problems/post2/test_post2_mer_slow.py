"""post2 validation case 3 (thesis [R3] Ch. 3.2.3, Tables 3-6/3-7): MER-type entry with sensed acceleration
and quaternion observations at 8 Hz, the early-weight / late-noise schedules, against the
propagation-only run (slow tier)."""

from __future__ import annotations

import json

import pytest

from workbench.cli import main


@pytest.mark.slow
def test_mer_quaternion_filtered_beats_propagation_and_stays_inside_3_sigma(tmp_path):
    assert main(["run", "post2_mer_quaternion", "--out", str(tmp_path)]) == 0
    s = json.loads((tmp_path / "post2_mer_quaternion.summary.json").read_text(encoding="utf-8"))
    assert [e["event"] for e in s["events"]] == ["deceleration"]
    assert 120.0 < s["events"][0]["t_s"] < 140.0  # "when vehicle deceleration begins (around 130 sec)"
    tr = s["truth"]
    c = tr["filtered_vs_propagation"]
    # the observations must beat the model alone by a wide margin on every block (measured seed 1:
    # position 963 -> 267 m, velocity 13 -> 0.14 m/s, attitude 2.5 -> 0.006 deg, rates 1.2 -> 0.002 deg/s)
    assert c["position"]["end_error_norm"]["forward"] < 0.5 * c["position"]["end_error_norm"]["propagation_only"]
    for name in ("velocity", "attitude", "body_rates"):
        e = c[name]["end_error_norm"]
        assert e["forward"] < 0.05 * e["propagation_only"], name
    assert tr["position_inside_3sigma_fraction"] >= 0.95
    for name in ("velocity_error", "attitude_error", "body_rates_error"):
        err, sd = tr[name]["end_forward"], tr[name]["end_sigma_smoothed"]
        assert all(abs(a) <= 3.0 * b for a, b in zip(err, sd, strict=True)), (name, err, sd)
    for p in tr["parameters"].values():
        assert p["inside_3sigma_at_end"]
