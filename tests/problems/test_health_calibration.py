"""Every problem's health thresholds come from a stored truth-Monte-Carlo calibration, and every shipped
scenario's committed summary is judged against it (issue 26: a nominal run is OK)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from workbench.estimation.calibration import band_key, load_table
from workbench.io import assets
from workbench.io.scenario import resolve_scenario
from workbench.problems import registry
from workbench.problems.calibration import CALIBRATION_STREAM, seeds_of, shipped_scenarios
from workbench.problems.runner import calibration_path

ROOT = Path(__file__).resolve().parents[2]
SUMMARIES = ROOT / "docs" / "results" / "summaries"
KINDS = ("droptest", "entry", "meads", "post2")


@pytest.mark.parametrize("kind", KINDS)
def test_calibration_table_is_stored_and_traceable(kind):
    table = load_table(calibration_path(registry.get(kind)))
    assert table is not None, f"{kind}: no health_calibration.json (workbench calibrate {kind} --write)"
    paths = shipped_scenarios(kind)
    assert sorted(table["scenarios"]) == sorted(p.stem for p in paths)
    assert table["command"].startswith(f"workbench calibrate {kind}")
    assert table["seed_stream"]["spawn_key"] == [CALIBRATION_STREAM]
    stream = [s for s in seeds_of(CALIBRATION_STREAM, len(table["seeds"]) + 8) if s not in _shipped_seeds(paths)]
    assert table["seeds"] == stream[: len(table["seeds"])]
    assert not set(table["seeds"]) & _shipped_seeds(paths), "a shipped scenario's own seed is a calibration member"
    assert len(table["seeds"]) >= 20 and not table["failed"]
    for name, e in table["checks"].items():
        lo, hi = e["band"]
        assert lo <= e["min"] <= e["max"] <= hi, name
        assert e["n"] >= 10, name


def _shipped_seeds(paths) -> set[int]:
    return {int(resolve_scenario(p, assets.assets_dir()).get("synthetic.seed", 0, kind="int")) for p in paths}


@pytest.mark.parametrize("summary", sorted(SUMMARIES.glob("*.summary.json")), ids=lambda p: p.name.split(".")[0])
def test_shipped_scenario_verdict_is_ok_and_every_statistic_is_calibrated(summary):
    s = json.loads(summary.read_text(encoding="utf-8"))
    health = s["health"]
    kind = resolve_scenario(summary.name.split(".")[0], assets.assets_dir()).kind
    table = load_table(calibration_path(registry.get(kind)))
    for c in health["checks"]:
        if c.get("stat"):
            key = band_key(c["name"], c["stat"])
            assert key in table["checks"], f"{summary.name}: {c['name']} has no calibrated band ({key})"
    assert health["calibration"] is not None
    not_ok = [f"{c['name']}: {c['message']}" for c in health["checks"] if c["status"] != "OK"]
    assert health["verdict"] == "OK", f"{summary.name}: " + "; ".join(not_ok)
