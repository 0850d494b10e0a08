"""``workbench mc <scenario> --truth-sim --seeds 4`` on each of the four problems exits 0 and writes a
complete recording and its JSON (issue 29: a Monte Carlo for every problem, no tracebacks).
Slow tier: ~2–3 min on 2 cores."""

from __future__ import annotations

import json

import pytest

from workbench.cli import EXIT_OK, main
from workbench.recording.reader import read_recording, verify

CASES = {
    "droptest": "droptest_mc.rrd",
    "schiaparelli": "schiaparelli_truth_mc.rrd",
    "msl_meads": "msl_meads_truth_mc.rrd",
    "post2_huygens": "post2_huygens_truth_mc.rrd",
}


@pytest.mark.slow
@pytest.mark.parametrize("scenario", list(CASES))
def test_truth_sim_monte_carlo_of_every_problem(scenario, tmp_path, capsys):
    out = tmp_path / "mc"
    assert main(["mc", scenario, "--truth-sim", "--seeds", "4", "--out", str(out), "-q"]) == EXIT_OK
    rrd = out / CASES[scenario]
    ok, msg = verify(rrd)
    assert ok, msg
    assert read_recording(rrd).text_document()  # the study's table
    summary = json.loads((out / f"{scenario}_truth.mc.json").read_text(encoding="utf-8"))
    assert summary
    assert "Traceback" not in capsys.readouterr().err
