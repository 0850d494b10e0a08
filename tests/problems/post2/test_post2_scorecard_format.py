"""The post2 scorecard's truth sections print numbers, not Python lists, and in one unit per row
(the planted tilt is stored in radians, its recovered value shown in degrees)."""

from __future__ import annotations

import math

from workbench.problems.post2.problem import Post2Problem


def _summary() -> dict:
    tilt = math.radians(10.0)
    return {
        "scenario": "fake",
        "dof": 3,
        "states": {
            "tilt": {"unit": "deg", "final": [10.15], "final_sigma": [0.305]},
            "accel_bias": {"unit": "m/s^2", "final": [0.0029, 0.0, 0.0], "final_sigma": [0.0009, 1e-6, 1e-6]},
            "radar_scale_factor": {"unit": "1", "final": [0.9319], "final_sigma": [0.0027]},
        },
        "observations": {},
        "truth": {
            "parameters": {
                "tilt": {
                    "truth": [tilt],
                    "error_after_1_obs": [-0.0872664625997],
                    "final_error_forward": [0.00258211143910339],
                    "final_3sigma_forward": [0.0159885085134442],
                    "final_error_over_3sigma_smoothed": [0.1615],
                    "inside_3sigma_at_end": True,
                },
                "radar_scale_factor": {
                    "truth": [0.93],
                    "final_error_forward": [0.00185874302786870],
                    "final_3sigma_forward": [0.00800712285332602],
                    "final_error_over_3sigma_smoothed": [0.23],
                    "inside_3sigma_at_end": True,
                },
                "accel_bias": {
                    "truth": [0.003, 0.0, 0.0],
                    "final_error_forward": [-0.000102710674332668, 0.0, 0.0],
                    "final_3sigma_forward": [0.00267351186593159, 3e-06, 3e-06],
                    "final_error_over_3sigma_smoothed": [-0.04, 0.0, 0.0],
                    "inside_3sigma_at_end": True,
                },
            }
        },
    }


def test_truth_sections_in_display_units_without_raw_lists():
    md = Post2Problem().scorecard(_summary())
    truth = md[md.index("## Against the truth") :]
    assert "[" not in truth.replace("[deg]", "").replace("[m/s^2]", "").replace("[0]", "").replace("[1]", "").replace(
        "[2]", ""
    )
    assert "| tilt | 10 | 10.15 |" in truth  # planted in degrees beside the recovered degrees
    assert "**tilt** (truth 10 deg)" in truth
    assert "| end (forward) | +0.1479 (3σ 0.9161) |" in truth
    assert "0.00258211143910339" not in truth and "0.0872664625997" not in truth
    assert "**accel_bias** (truth 0.003, 0, 0 m/s^2)" in truth
    assert "**radar_scale_factor** (truth 0.93):" in truth  # no unit "1" after a pure number


def test_committed_summaries_give_initial_errors_in_si():
    """Every scored parameter's ``initial_error`` is the initial value (the summary's, in the problem
    file's unit: deg for angles) minus the truth, in SI like the other errors — the Huygens tilt once
    subtracted a truth in radians from an initial value in degrees (4.83 for a 5° − 10° start)."""
    import json
    from pathlib import Path

    from workbench.problems.post2.model import STATES

    root = Path(__file__).resolve().parents[3] / "docs" / "results" / "summaries"
    seen = 0
    for path in sorted(root.glob("post2_*.summary.json")):
        s = json.loads(path.read_text(encoding="utf-8"))
        for name, p in s.get("truth", {}).get("parameters", {}).items():
            k = 180.0 / math.pi if STATES[name].unit in ("deg", "deg/s") else 1.0
            want = [a / k - b for a, b in zip(s["states"][name]["initial"], p["truth"], strict=True)]
            assert all(abs(a - b) <= 1e-12 * max(1.0, abs(b)) for a, b in zip(p["initial_error"], want, strict=True)), (
                path.name,
                name,
                p["initial_error"],
                want,
            )
            seen += k != 1.0
    assert seen >= 1  # an angle parameter (the Huygens tilt) was checked


def test_a_parameter_headline_prints_numbers_in_the_display_unit():
    """A run whose headline is a parameter's error (post2_j2) prints numbers, not Python lists, and
    an angle in degrees."""
    s = {
        "states": {"tilt": {"unit": "deg", "final": [10.15]}},
        "truth": {"parameters": {"tilt": {"final_error_forward": [0.0026], "final_3sigma_forward": [0.016]}}},
    }
    line = Post2Problem().headline(s)
    assert "[" not in line and line.startswith("tilt error +0.149 (3σ 0.9167) deg"), line
