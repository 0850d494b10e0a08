"""The scorecard formatter: units, at most ~4 significant digits, words instead of ``nan``, no raw
dicts — and the drop-test / entry scorecards built from summaries with undefined values and nested
dicts read that way too."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from workbench.io import scorecard as sc

_NUM = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


def _sig_digits(token: str) -> int:
    """Significant digits of a printed number (trailing zeros of an integer do not count)."""
    mant = token.lstrip("+-").split("e")[0]
    digits = mant.replace(".", "").lstrip("0")
    return len(digits) if "." in mant else len(digits.rstrip("0"))


VALUES = [0.07047934931485789, 4.42, 1234.5678, 123456.789, 1.0e-5, -0.00123, 2.7003894999803584, 19.02276779864163]


@pytest.mark.parametrize("x", VALUES)
def test_num_prints_at_most_four_significant_digits_and_the_unit(x):
    s = sc.num(x, "m")
    assert s.endswith(" m")
    tok = s[:-2]
    assert _sig_digits(tok) <= 4, s
    assert math.isclose(float(tok), x, rel_tol=1e-3), s


@pytest.mark.parametrize("bad", [float("nan"), None, float("inf"), -float("inf"), np.nan])
def test_undefined_values_are_words(bad):
    assert sc.num(bad, "m") == sc.UNDEFINED
    assert sc.num(bad, undefined="not defined: no rebound") == "not defined: no rebound"
    assert "nan" not in sc.pct(bad).lower() and "inf" not in sc.signed(bad).lower()


def test_integers_bools_and_signs():
    assert sc.num(2791) == "2791"
    assert sc.num(True) == "yes" and sc.num(False) == "no"
    assert sc.signed(0.0123, "m") == "+0.0123 m"
    assert sc.pct(0.0704793) == "7.05 %"
    assert sc.num(0.0) == "0"


def test_fields_turns_a_nested_summary_into_readable_items():
    d = {
        "max_abs_rel_error": 0.07047934931485789,
        "max_h_agl_error_m": 75.23456,
        "inside_3sigma_fraction": 1.0,
        "nees_95pct_band": [2.7003894999803584, 19.02276779864163],
        "restitution": float("nan"),
        "sub": {"speed_mps": 12.3456789, "ok": True},
        "note": "a|b",
    }
    text = "; ".join(sc.fields(d))
    assert "{" not in text and "'" not in text and "nan" not in text.lower()
    assert "max h agl error 75.23 m" in text
    assert "inside 3sigma 100 %" in text
    assert "nees 95pct band [2.7, 19.02]" in text
    assert "speed 12.35 m/s" in text and "ok yes" in text
    assert "restitution not defined" in text
    assert "a\\|b" in text  # safe in a markdown table cell
    for tok in _NUM.findall(text):
        assert _sig_digits(tok) <= 4, tok


def _droptest_summary(e_true: float) -> dict:
    """A drop-test summary of the shape ``pipeline.summarize`` + ``score`` write (values made up)."""
    return {
        "scenario": "t",
        "mode": "kinematic",
        "steps": 10,
        "filter_rate_hz": 1000.0,
        "group_delay_s": 8.3e-4,
        "max_stroke": {
            "distance_m": 0.1,
            "sigma_m": 0.01,
            "time_s": 1.6,
            "sampled_sigma_m": 0.011,
            "vertex": 3,
            "faces": [1],
            "full_stroke": True,
            "possible_full_stroke": True,
        },
        "restitution": {"e": float("nan"), "sigma": float("nan"), "definition": "d"},
        "covariance": {"max_asymmetry": 0.0, "min_eigenvalue": 1e-9},
        "truth": {
            "max_stroke_truth_m": 0.1,
            "max_stroke_truth_time_s": 1.6,
            "max_stroke_error_m": 0.001,
            "max_stroke_error_over_sigma": 0.1,
            "max_stroke_inside_3sigma": True,
            "position_error_max_m": 0.1,
            "position_error_over_sigma_max": 1.0,
            "attitude_error_max_deg": 1.0,
            "nees_pose_mean": 6.0,
            "restitution_truth": e_true,
            "restitution_error": float("nan"),
            "restitution_error_over_sigma": float("nan"),
            "restitution_inside_3sigma": False,
            "restitution_truth_touch_leave": e_true,
            "restitution_error_touch_leave": float("nan"),
            "full_stroke_truth": True,
        },
        "innovations": {},
        "degradations": [],
    }


def test_droptest_scorecard_without_rebound_says_so():
    from workbench.problems.droptest.pipeline import NO_REBOUND, scorecard_markdown

    md = scorecard_markdown(_droptest_summary(float("nan")))
    assert not re.search(r"\bnan\b", md, re.IGNORECASE), md
    assert md.count(NO_REBOUND) == 3  # estimate, truth (same definition), truth (touch/leave)


def test_entry_scorecard_has_no_raw_dicts_or_long_floats():
    from workbench.problems.entry.pipeline import scorecard_markdown

    s = {
        "scenario": "t",
        "dispersion": {"members": 10, "accepted": 5, "accepted_fraction": 0.5, "wall_s": 1.0, "scheduler": "x"},
        "atmosphere": {"iterations": 2},
        "event_table": [],
        "nominal_integration": {},
        "truth": {
            "nees_smoothed": {"mean": 5.894321987, "single_step_95pct_band_9dof": [2.7003894999803584, 19.0227677]},
            "after_radar_fix": {"max_h_agl_error_m": 75.23456789, "inside_3sigma_fraction": 1.0},
            "winds_in_layers": {
                "method": "m",
                "n": 3,
                "max_error_mps": 3.6,
                "bound_mps": 5.0,
                "bound_pass": True,
                "rms_error_mps": 2.0,
            },
        },
    }
    md = scorecard_markdown(s)
    assert "{'" not in md and not re.search(r"\bnan\b", md, re.IGNORECASE), md
    assert not re.search(r"\d\.\d{7,}", md), md  # no 16-digit float reprs
    assert "max h agl error 75.23 m" in md and "[2.7, 19.02]" in md
    assert "north rms error not defined" in md  # a missing statistic is said in words
