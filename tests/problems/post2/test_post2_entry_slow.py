"""post2 validation case 2 (thesis [R3] Ch. 3.2.2, 6-DOF ballistic Mars entry, start 1 of Table 3-5),
end to end with model error in the truth (slow tier, ~75 s)."""

from __future__ import annotations

import json

import pytest

from workbench.cli import main


@pytest.mark.slow
def test_entry6dof_position_error_collapses_and_stays_bounded(tmp_path):
    assert main(["run", "post2_entry6dof", "--out", str(tmp_path)]) == 0
    s = json.loads((tmp_path / "post2_entry6dof.summary.json").read_text(encoding="utf-8"))
    e = s["truth"]["position_error_m"]
    assert 7000.0 < e["start"] < 9000.0  # Table 3-5 start 1 vs truth: ~7.9 km (thesis Fig. 3-4)
    # thesis Fig. 3-4: below 200 m after 15 s of observations, of the order of 20 m at the end
    assert e["after_15s_forward"] < 200.0
    assert e["end_forward"] < 50.0 and e["max_smoothed"] < 50.0
    # and the covariance admits the error (the thesis' Figs. 3-24..3-26 show it inside 1-3σ)
    assert s["truth"]["position_inside_3sigma_fraction"] >= 0.95
    assert s["observations"]["acceleration"]["accepted"] == 2001
