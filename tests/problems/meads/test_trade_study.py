"""MEADS trade study: vectorised over runs, executor-independent, error levels scale the 3σ."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import resolve_scenario
from workbench.problems.meads import montecarlo as mcmod


@pytest.fixture(scope="module")
def shared():
    sh = mcmod.prepare_trade_study(resolve_scenario("msl_meads", assets_dir()), stride=32)
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
