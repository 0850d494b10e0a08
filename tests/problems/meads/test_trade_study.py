"""MEADS trade study: vectorised over runs, executor-independent, error levels scale the 3σ."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import resolve_scenario
from workbench.problems.meads import montecarlo as mcmod
from workbench.problems.meads.problem import MeadsProblem


@pytest.fixture(scope="module")
def shared():
    st = MeadsProblem().settings(resolve_scenario("msl_meads", assets_dir()))
    sh = mcmod.prepare_trade_study(dataclasses.replace(st, mc=dataclasses.replace(st.mc, stride=32)))
    return dataclasses.replace(sh, levels=(0.005, 0.05))


def test_trade_study_is_executor_independent_and_scales(shared, monkeypatch):
    monkeypatch.setattr(mcmod, "CHUNK", 4)
    loop = mcmod.run_trade_study(shared, 8, 5, workers=1)
    pool = mcmod.run_trade_study(shared, 8, 5, workers=2, scheduler="processes")
    for lv in shared.levels:
        assert np.array_equal(loop.three_sigma[lv], pool.three_sigma[lv], equal_nan=True)
    ratio = np.nanmedian(loop.three_sigma[0.05][:, :3] / loop.three_sigma[0.005][:, :3])
    assert 7.0 < ratio < 13.0  # 3σ of α, β, q grows ~linearly with the error level (10x)
    row = loop.summary["table"]["0.5%"]
    assert set(row) == {"alpha_deg", "beta_deg", "qbar_pct", "mach"}
    assert row["qbar_pct"]["max_3sigma"] < loop.summary["table"]["5%"]["qbar_pct"]["max_3sigma"]


def test_trade_study_recording_is_on_time_and_on_mach(tmp_path):
    from workbench.problems.meads.recording_mc import mach_axis, record_trade_study
    from workbench.recording import layout
    from workbench.recording.reader import read_recording

    n, levels = 12, (0.01, 0.05)
    t = 40.0 + np.arange(n)
    mach = np.linspace(25.0, 3.0, n)
    three = {lv: np.tile(100 * lv * np.linspace(1.0, 2.0, n)[:, None], (1, 4)) for lv in levels}
    row = {"max_3sigma": 1.0, "median_3sigma": 0.5, "met": False}
    summary = {
        "runs_per_level": 10,
        "fixed_r": 0.001,
        "objectives_3sigma": mcmod.OBJECTIVES,
        "table": {f"{100 * lv:g}%": {q: dict(row) for q in mcmod.QUANTITIES} for lv in levels},
        "executor": "loop",
        "wall_s": 0.1,
    }
    ts = mcmod.TradeStudy(t, mach, np.full(n, 1e3), levels, three, three, summary, 0.1)
    rec = read_recording(record_trade_study(tmp_path / "trade.rrd", "trade", ts, summary))
    entity = layout.meads_trade_path("qbar_pct", mcmod.level_name(0.05))
    tt, y = rec.scalars(entity)
    np.testing.assert_allclose(tt, t)
    x, ym = rec.scalars(entity, layout.MACH_DESCENDING)
    np.testing.assert_array_equal(x, mach_axis(mach))  # Mach falls: x rises
    np.testing.assert_allclose(ym[:, 0], three[0.05][:, 2])
    np.testing.assert_allclose(y, ym)  # the same rows on both timelines
    assert x[0] == -2500 and x[-1] == -300
