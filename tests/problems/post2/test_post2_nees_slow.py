"""post2 case 2 (thesis [R3] Ch. 3.2.2) over seeds: the ANEES of the 12 trajectory states inside its χ²
band (slow tier).

Each member: the truth's initial state is the Table 3-5 truth plus a draw from the stated covariance
(Table 3-4), the sensor noise has its own seed; the estimator starts from Test Case 1 (7.9 km off).
The span is shortened to the first 40 s (convergence from 7.9 km and the 15 s mark of the thesis) to
keep the test to a few minutes; ``tests/benchmarks/bench_post2_nees.py`` runs the whole entry.
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.estimation.consistency import anees_bounds
from workbench.io.assets import assets_dir
from workbench.io.scenario import load_scenario
from workbench.problems.post2 import pipeline
from workbench.problems.post2.problem import Post2Problem
from workbench.problems.post2.scoring import trajectory_nees

SEEDS = 6
T_END = 40.0


def _member(seed: int, tmp) -> np.ndarray:
    base = load_scenario(assets_dir() / "scenarios" / "post2_entry6dof.toml")
    rng = np.random.default_rng(10_000 + seed)
    ov: dict = {"model.t_end_s": T_END}
    for name in ("position", "velocity", "attitude", "body_rates"):
        sd = np.asarray(base.data["states"][name]["sigma"], dtype=float) * np.ones(3)
        tv = np.asarray(base.data["truth"]["states"][name], dtype=float)
        ov[f"truth.states.{name}"] = (tv + sd * rng.standard_normal(3)).tolist()
    sc = base.with_overrides(ov)
    prob = Post2Problem()
    settings = prob.settings(sc)
    syn = prob.synthesize(settings, tmp / f"m{seed}", seed)
    res = None
    for stage in pipeline.reconstruct(settings, dict(syn.telemetry)):
        res = stage
    n = trajectory_nees(res, prob.load_truth(syn.truth))
    k15 = int(np.searchsorted(n["t"], 15.0 - 1e-9))
    return n["forward"][k15:]


@pytest.mark.slow
def test_entry6dof_anees_after_15s_inside_its_band(tmp_path):
    nees = np.array([_member(s, tmp_path) for s in range(1, SEEDS + 1)])  # (seeds, steps after 15 s)
    anees = nees.mean(axis=0)
    lo, hi = anees_bounds(12, SEEDS, 0.95)
    # The time mean of the per-step ANEES is more concentrated than one step's (the docstring of
    # anees_bounds), so the per-step 95 % band is already a loose test of it; the margin is 1.0x:
    # no widening.  Per step, at most 20 % of the steps may leave the band (5 % expected if the steps
    # were independent; they are correlated over the filter's memory, so excursions come in runs).
    # measured (velocity PSD 3e-7, these 6 seeds): ANEES over 15-40 s 13.1 in [8.4, 16.2], 1.6 % of the
    # steps outside; over the whole entry and 50 seeds the forward ANEES after 15 s is 10.9 in its band
    # (bench_post2_nees50.json; with the earlier PSD 1e-8 it rose to 17.5, above it)
    assert lo <= anees.mean() <= hi, (anees.mean(), lo, hi)
    assert np.mean((anees < lo) | (anees > hi)) <= 0.20
