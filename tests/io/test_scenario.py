"""Scenario TOML files (workbench.io.scenario)."""

import textwrap

import numpy as np
import pytest

from workbench.io.scenario import ScenarioError, find_scenarios, load_scenario, resolve_scenario

DROP = """\
[scenario]
name = "spf_drop_1"
kind = "droptest"
description = "60 deg ramp drop"
epoch_utc = 2002-05-14T18:30:00Z

[vehicle]
mass_kg = 533
lever_arm_m = [0.05, 0.03, -0.34]
name = "MER"

[telemetry]
imu = "data/imu.csv"

[synthetic]
seed = 7

[filter]
enabled = true
"""


def write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def test_load_and_typed_get(tmp_path):
    sc = load_scenario(write(tmp_path / "drop.toml", DROP))
    assert (sc.name, sc.kind, sc.description) == ("spf_drop_1", "droptest", "60 deg ramp drop")
    assert sc.get("scenario.epoch_utc") == "2002-05-14T18:30:00+00:00"
    assert sc.get("vehicle.mass_kg", kind="float") == 533.0
    assert isinstance(sc.get("vehicle.mass_kg", kind="float"), float)
    assert sc.get("synthetic.seed", kind="int") == 7
    np.testing.assert_array_equal(sc.get("vehicle.lever_arm_m", kind="vec3"), [0.05, 0.03, -0.34])
    assert sc.get("filter.enabled", kind="bool") is True
    assert sc.get("telemetry", kind="table") == {"imu": "data/imu.csv"}
    assert sc.get("filter.gain", 0.5, kind="float") == 0.5
    assert sc.has("vehicle.name") and not sc.has("vehicle.nope") and not sc.has("vehicle.name.x")
    assert sc.is_synthetic


def test_get_errors_name_file_key_and_type(tmp_path):
    sc = load_scenario(write(tmp_path / "drop.toml", DROP))
    with pytest.raises(ScenarioError) as info:
        sc.get("vehicle.name", kind="float")
    msg = str(info.value)
    assert "drop.toml" in msg and "'vehicle.name'" in msg and "expected a number" in msg
    assert info.value.key == "vehicle.name"
    with pytest.raises(ScenarioError, match=r"'vehicle.mass_kg'.*list of 3 numbers, got int 533"):
        sc.get("vehicle.mass_kg", kind="vec3")
    with pytest.raises(ScenarioError, match=r"'filter.enabled'.*integer"):
        sc.get("filter.enabled", kind="int")  # a bool is not an int
    with pytest.raises(ScenarioError, match=r"drop.toml, key 'vehicle.drag'.*missing.*mass_kg"):
        sc.get("vehicle.drag", kind="float")


def test_returned_tables_are_copies(tmp_path):
    sc = load_scenario(write(tmp_path / "drop.toml", DROP))
    sc.get("telemetry", kind="table")["imu"] = "other.csv"
    assert sc.get("telemetry.imu") == "data/imu.csv"


def test_resolve_relative_to_scenario_dir(tmp_path):
    sc = load_scenario(write(tmp_path / "sub" / "drop.toml", DROP))
    assert sc.resolve("data/imu.csv") == tmp_path / "sub" / "data" / "imu.csv"
    assert sc.resolve(tmp_path / "abs.csv") == tmp_path / "abs.csv"
    with pytest.raises(ScenarioError, match="'telemetry.imu'.*file not found"):
        sc.path_of("telemetry.imu")
    (tmp_path / "sub" / "data").mkdir()
    (tmp_path / "sub" / "data" / "imu.csv").write_text("x")
    assert sc.path_of("telemetry.imu") == tmp_path / "sub" / "data" / "imu.csv"


def test_with_overrides(tmp_path):
    sc = load_scenario(write(tmp_path / "drop.toml", DROP))
    sc2 = sc.with_overrides({"synthetic.seed": 11, "filter.q.accel": 0.1, "scenario.name": "b"})
    assert sc2.get("synthetic.seed") == 11 and sc2.get("filter.q.accel") == 0.1 and sc2.name == "b"
    assert sc.get("synthetic.seed") == 7 and sc.name == "spf_drop_1"
    with pytest.raises(ScenarioError, match="'vehicle.mass_kg'.*cannot set"):
        sc.with_overrides({"vehicle.mass_kg.x": 1})
    with pytest.raises(ScenarioError, match="'scenario.kind'"):
        sc.with_overrides({"scenario.kind": 3})
    with pytest.raises(ScenarioError, match="'scenario.kind'"):
        sc.with_overrides({"scenario.kind": " "})


def test_any_kind_string_loads(tmp_path):
    """io does not know the problems: a kind without a problem loads (the registry refuses it)."""
    sc = load_scenario(write(tmp_path / "r.toml", '[scenario]\nname = "r"\nkind = "rocket"\n'))
    assert sc.kind == "rocket"


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[vehicle]\nmass_kg = 1\n", "scenario"),
        ('[scenario]\nkind = "entry"\n', "scenario.name"),
        ('[scenario]\nname = "a"\nkind = 3\n', "scenario.kind"),
        ('[scenario]\nname = "a"\n', "scenario.kind"),
        ('[scenario]\nname = "a"\nkind = "entry"\n[telemetry]\nimu = 3\n', "telemetry.imu"),
        ('[scenario]\nname = "a"\nkind = "entry"\n[synthetic]\nseed = -1\n', "synthetic.seed"),
    ],
)
def test_invalid_scenarios_name_key(tmp_path, text, key):
    with pytest.raises(ScenarioError) as info:
        load_scenario(write(tmp_path / "bad.toml", text))
    assert info.value.key == key and "bad.toml" in str(info.value)


def test_bad_toml_and_missing_file(tmp_path):
    with pytest.raises(ScenarioError, match=r"bad.toml: not valid TOML.*line 2"):
        load_scenario(write(tmp_path / "bad.toml", '[scenario]\nname = "a\n'))
    with pytest.raises(ScenarioError, match="nope.toml: file not found"):
        load_scenario(tmp_path / "nope.toml")


def test_find_and_resolve_scenarios(tmp_path):
    assets = tmp_path / "assets"
    write(assets / "scenarios" / "drop.toml", DROP)
    write(assets / "scenarios" / "entry" / "edm.toml", '[scenario]\nname = "edm"\nkind = "entry"\n')
    write(assets / "scenarios" / "lander.toml", "[lander]\nmass_kg = 1\n")  # not a scenario
    found = find_scenarios(assets)
    assert found == {
        "edm": assets / "scenarios" / "entry" / "edm.toml",
        "spf_drop_1": assets / "scenarios" / "drop.toml",
    }
    assert resolve_scenario("edm", assets).kind == "entry"
    assert resolve_scenario("drop", assets).name == "spf_drop_1"  # by file stem
    assert resolve_scenario(str(assets / "scenarios" / "drop.toml"), assets).name == "spf_drop_1"
    with pytest.raises(ScenarioError, match=r"no scenario named 'mars'.*edm, spf_drop_1"):
        resolve_scenario("mars", assets)
    write(assets / "scenarios" / "dup.toml", '[scenario]\nname = "edm"\nkind = "entry"\n')
    with pytest.raises(ScenarioError, match="also used by"):
        find_scenarios(assets)
    assert find_scenarios(tmp_path / "empty") == {}
