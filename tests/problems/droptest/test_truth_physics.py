"""Physical sanity of the drop-test truth simulator itself: what every reconstruction is judged against."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import resolve_scenario
from workbench.problems.droptest.problem import DropTestProblem
from workbench.problems.droptest.synthetic import truth_for


@pytest.mark.xfail(
    strict=True,
    reason="open: the truth's footprint areas subtract half of every pairwise lens overlap, so where lobes of "
    "several bags press into the ramp at nearly the same place (their centres differ mostly along the normal) "
    "the overlaps are counted many times and every area is clipped to zero: droptest's own drop has 25 ms "
    "(1.660-1.684 s) with 9 lobes pressed up to a full radius (1.0 m) and no bag force at all, and 11 of 21 "
    "drops (the scenario's and 20 of the Monte Carlo's validation stream) have such spells of 6-105 ms; the "
    "lander then pushes off again as the areas come back. A fix (each lobe's share of the footprints' union) "
    "changes every drop-test truth, summary, calibration and benchmark",
)
def test_pressed_bags_always_push():
    settings = DropTestProblem().settings(resolve_scenario("droptest", assets_dir()))
    tr, _, _ = truth_for(settings)
    pressed = tr.lobe_penetration.max(axis=1) > 0.1  # some lobe more than 10 cm into the ramp [m]
    assert pressed.any()
    # a gas bag pressed into the ramp pushes with its gauge pressure over its footprint, never zero
    assert np.all(tr.contact_force[pressed] > 0.0)
