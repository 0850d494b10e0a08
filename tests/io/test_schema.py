"""The declarative scenario schema (workbench/io/schema.py): unknown keys, types, defaults, and
FORMATS.md generated from the problems' schemas."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import workbench.io.schema as schema_mod
from workbench.io.scenario import ScenarioError, parse_file
from workbench.io.schema import (
    REQUIRED,
    Key,
    Schema,
    Table,
    from_table,
    render_markdown,
    scenario_table,
    update_formats,
)
from workbench.problems.droptest.config import SCHEMA as DROPTEST
from workbench.problems.entry.config import SCHEMA as ENTRY
from workbench.problems.meads.config import SCHEMA as MEADS
from workbench.problems.post2.config import SCHEMA as POST2

FILE = Path("/data/my_scenario.toml")

TOY = Schema(
    "toy",
    "a test schema",
    (
        Table("scenario", "what", (Key("name", "str", REQUIRED), Key("kind", "str", REQUIRED))),
        Table(
            "sensors.imu",
            "an IMU",
            (
                Key("noise_dps", "float", 0.4, "deg/s", "noise"),
                Key("rate_hz", "int", 100),
                Key("mode", "str", "fast", choices=("fast", "slow")),
                Key("lever_m", "vec3", [0.0, 0.0, 1.0], "m"),
                Key("bias_dps", "float", None, "deg/s", "absent: none"),
            ),
        ),
        Table("guns", "named guns", free="vec3", free_meaning="position"),
    ),
)


def base(**imu) -> dict:
    return {"scenario": {"name": "a", "kind": "toy"}, "sensors": {"imu": dict(imu)}}


def test_unknown_key_names_file_table_key_and_suggests():
    with pytest.raises(ScenarioError) as ei:
        TOY.validate(base(noise_dsp=0.3), FILE)
    e = ei.value
    assert e.file == str(FILE) and e.key == "sensors.imu.noise_dsp"
    msg = str(e)
    assert str(FILE) in msg and "[sensors.imu]" in msg and "'noise_dsp'" in msg
    assert "did you mean 'noise_dps'?" in msg


def test_unknown_table_is_an_error_with_a_suggestion():
    data = base()
    data["sensor"] = {"imu": {}}
    with pytest.raises(ScenarioError, match="did you mean 'sensors'") as ei:
        TOY.validate(data, FILE)
    assert ei.value.key == "sensor"
    data = base()
    data["sensors"]["gps"] = {}
    with pytest.raises(ScenarioError, match=r"unknown key 'gps' in table \[sensors\]") as ei:
        TOY.validate(data, FILE)
    assert ei.value.key == "sensors.gps"


def test_no_suggestion_for_a_far_off_key():
    with pytest.raises(ScenarioError) as ei:
        TOY.validate(base(xyzzy=1), FILE)
    assert "did you mean" not in str(ei.value) and "noise_dps" in str(ei.value)  # lists the keys instead


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("noise_dps", "0.4 deg/s", "expected a number"),
        ("rate_hz", 100.0, "expected an integer"),
        ("mode", "medium", "use one of fast, slow"),
        ("lever_m", [1.0, 2.0], "expected a list of 3 numbers"),
        ("noise_dps", True, "expected a number"),
    ],
)
def test_wrong_type_is_a_located_error(key, value, match):
    with pytest.raises(ScenarioError, match=match) as ei:
        TOY.validate(base(**{key: value}), FILE)
    assert ei.value.key == f"sensors.imu.{key}" and ei.value.file == str(FILE)


def test_a_table_where_a_value_belongs_and_vice_versa():
    with pytest.raises(ScenarioError, match="expected a table") as ei:
        TOY.validate({"scenario": {"name": "a", "kind": "toy"}, "sensors": 3}, FILE)
    assert ei.value.key == "sensors"


def test_defaults_filled_and_values_converted():
    v = TOY.validate(base(rate_hz=50), FILE)
    imu = v["sensors"]["imu"]
    assert imu["rate_hz"] == 50 and imu["noise_dps"] == 0.4 and imu["mode"] == "fast"
    assert imu["bias_dps"] is None  # optional, absent
    assert isinstance(imu["lever_m"], np.ndarray) and np.array_equal(imu["lever_m"], [0.0, 0.0, 1.0])
    assert v["guns"] == {}
    v = TOY.validate(base(noise_dps=1), FILE)
    assert isinstance(v["sensors"]["imu"]["noise_dps"], float)


def test_required_key_missing():
    with pytest.raises(ScenarioError, match="required") as ei:
        TOY.validate({"scenario": {"name": "a"}}, FILE)
    assert ei.value.key == "scenario.kind"


def test_free_table_checks_the_value_kind():
    v = TOY.validate({**base(), "guns": {"G1": [1, 2, 3]}}, FILE)
    assert np.array_equal(v["guns"]["G1"], [1.0, 2.0, 3.0])
    with pytest.raises(ScenarioError, match="list of 3") as ei:
        TOY.validate({**base(), "guns": {"G1": [1, 2]}}, FILE)
    assert ei.value.key == "guns.G1"


def test_markdown_lists_every_key_once():
    md = render_markdown(TOY)
    assert "`[sensors.imu]` — an IMU" in md and md.count("| `noise_dps` |") == 1
    assert "| `name` | str |  | required |" in md and "| `bias_dps` | float | deg/s | — |" in md
    assert "One of: `fast`, `slow`." in md and "*any name*" in md


def test_update_formats_needs_the_markers():
    with pytest.raises(ValueError, match="schema:toy:begin"):
        update_formats("no markers here", [TOY])
    text = "a\n<!-- schema:toy:begin -->\nold\n<!-- schema:toy:end -->\nb\n"
    new = update_formats(text, [TOY])
    assert "old" not in new and new.startswith("a\n<!-- schema:toy:begin -->\n") and new.endswith("end -->\nb\n")
    assert update_formats(new, [TOY]) == new


def test_formats_md_matches_the_schemas():
    """io/FORMATS.md holds the generated tables of every file kind; regenerate with
    ``python -m workbench.problems.registry --write-formats``."""
    from workbench.problems import registry

    path = Path(schema_mod.__file__).with_name("FORMATS.md")
    text = path.read_text(encoding="utf-8")
    assert update_formats(text, registry.schemas()) == text, (
        "FORMATS.md is out of date: run python -m workbench.problems.registry --write-formats"
    )


def test_the_registry_hands_every_problem_schema():
    from workbench.problems import registry

    got = registry.schemas()
    for s in (DROPTEST, ENTRY, POST2, MEADS):
        assert any(g is s for g in got)
    assert len({s.name for s in got}) == len(got), "two file kinds share a marker name"


BOUNDED = Schema(
    "rig",
    "a test rig",
    (
        Table(
            "",
            "top-level keys",
            (
                Key("mass_kg", "float", REQUIRED, "kg", "mass", gt=0.0),
                Key("angle_deg", "float", 60.0, "deg", "inclination", gt=0.0, lt=90.0),
                Key("cm_m", "vec3", [0.0, 0.0, 0.0], "m", "centre of mass", ge=-10.0, le=10.0),
            ),
        ),
        Table("bungee", "optional", (Key("count", "int", REQUIRED, meaning="cords", ge=1),)),
    ),
    noun="rig file",
    intro="Keys of a rig file",
)


@pytest.mark.parametrize(
    ("data", "key", "match"),
    [
        ({"mass_kg": 0.0}, "mass_kg", r"0 kg is out of range: must be > 0 kg"),
        ({"mass_kg": float("nan")}, "mass_kg", "out of range"),
        ({"mass_kg": 1.0, "angle_deg": 90}, "angle_deg", r"must be > 0, < 90 deg"),
        ({"mass_kg": 1.0, "cm_m": [0, 11, 0]}, "cm_m", r"11 m is out of range: must be ≥ -10, ≤ 10 m"),
        ({"mass_kg": 1.0, "bungee": {"count": 0}}, "bungee.count", r"must be ≥ 1"),
    ],
)
def test_bounds_name_the_key_and_the_bound(data, key, match):
    with pytest.raises(ScenarioError, match=match) as ei:
        BOUNDED.validate(data, FILE)
    assert ei.value.key == key and ei.value.file == str(FILE)


def test_a_default_is_checked_against_the_bounds_too():
    bad = Schema("b", "b", (Table("t", "t", (Key("x", "float", -1.0, ge=0.0),)),))
    with pytest.raises(ScenarioError, match="out of range"):
        bad.validate({}, FILE)


def test_a_file_schema_names_its_noun_top_level_keys_and_optional_tables():
    with pytest.raises(
        ScenarioError, match=r"unknown key 'mas_kg' in the top level of a rig file; did you mean 'mass_kg'"
    ):
        BOUNDED.validate({"mas_kg": 1.0}, FILE)
    with pytest.raises(ScenarioError, match=r"missing \(required in table \[bungee\] of a rig file\)"):
        BOUNDED.validate({"mass_kg": 1.0, "bungee": {}}, FILE)
    v = BOUNDED.validate({"mass_kg": 2}, FILE, optional=("bungee",))
    assert v["mass_kg"] == 2.0 and v["angle_deg"] == 60.0 and v["bungee"] == {"count": None}
    with pytest.raises(ScenarioError) as ei:
        BOUNDED.validate({"mass_kg": -2}, FILE, where="flights.f1")
    assert ei.value.key == "flights.f1.mass_kg"
    md = render_markdown(BOUNDED)
    assert md.startswith("Keys of a rig file.") and "| `angle_deg` | float | deg | `60.0` | > 0, < 90 |" in md


def test_load_file_reads_toml_and_json_and_names_bad_files(tmp_path):
    t = tmp_path / "rig.toml"
    t.write_text("mass_kg = 3\n[bungee]\ncount = 2\n", encoding="utf-8")
    assert schema_mod.load_file(t, BOUNDED)["bungee"]["count"] == 2
    j = tmp_path / "rig.json"
    j.write_text('{"mass_kg": 3, "bungee": {"count": 2}}', encoding="utf-8")
    assert schema_mod.load_file(j, BOUNDED)["mass_kg"] == 3.0
    j.write_text('{"mass_kg": 3,', encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"not valid JSON: .*line 1") as ei:
        schema_mod.load_file(j, BOUNDED)
    assert ei.value.file == str(j)
    t.write_text("mass_kg = = 3\n", encoding="utf-8")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        schema_mod.load_file(t, BOUNDED)
    with pytest.raises(ScenarioError, match="file not found"):
        schema_mod.load_file(tmp_path / "none.toml", BOUNDED)


def test_a_wrong_choice_suggests_the_nearest():
    s = Schema("c", "c", (Table("t", "t", (Key("mode", "str", "fast", choices=("kinematic", "dynamic")),)),))
    with pytest.raises(ScenarioError, match="did you mean 'dynamic'"):
        s.validate({"t": {"mode": "dynamik"}}, FILE)


def test_scenario_table_declares_the_common_keys():
    t = scenario_table("toy", epoch="UTC of t = 0")
    assert t.name == "scenario" and [k.name for k in t.keys] == ["name", "kind", "description", "epoch_utc"]
    assert t.key("kind").meaning == '`"toy"`' and t.key("name").default is REQUIRED
    assert scenario_table("toy").key("epoch_utc") is None  # no epoch: no key
    s = Schema("toy", "a test", (scenario_table("toy"),))
    with pytest.raises(ScenarioError, match="missing"):
        s.validate({"scenario": {"kind": "toy"}}, FILE)
    assert s.validate({"scenario": {"name": "a", "kind": "toy"}}, FILE)["scenario"]["description"] == ""


@dataclass(frozen=True)
class _Stage:
    noise_dps: float
    rate_hz: int
    lever_m: tuple
    extra: int = 7


def test_from_table_takes_the_keys_named_like_the_fields():
    v = TOY.validate({"scenario": {"name": "a", "kind": "toy"}, "sensors": {"imu": {"rate_hz": 50}}}, FILE)
    imu = v["sensors"]["imu"]
    st = from_table(_Stage, imu, lever_m=tuple(imu["lever_m"]))
    assert st == _Stage(0.4, 50, (0.0, 0.0, 1.0), 7)  # keys that are no field (mode, bias_dps) are the caller's
    assert from_table(_Stage, imu, lever_m=(), extra=1).extra == 1
    with pytest.raises(TypeError, match="no field lever"):
        from_table(_Stage, imu, lever=())
    with pytest.raises(TypeError):
        from_table(_Stage, {"noise_dps": 1.0})  # rate_hz, lever_m: no value


class _SyntaxError(Exception):
    pass


def test_parse_file_names_the_file_for_every_failure(tmp_path):
    def load(p: Path) -> str:
        text = p.read_text(encoding="utf-8")
        if text.startswith("bad"):
            raise _SyntaxError("line 1")
        return text

    def read(path):
        return parse_file(path, load, _SyntaxError, lambda exc: f"broken: {exc}")

    ok, bad, binary = tmp_path / "ok.txt", tmp_path / "bad.txt", tmp_path / "bin.txt"
    ok.write_text("fine")
    bad.write_text("bad")
    binary.write_bytes(b"\xff\xfe\x00")
    assert read(ok) == "fine"
    for path, match in ((bad, "broken: line 1"), (binary, "not valid UTF-8"), (tmp_path / "no.txt", "not found")):
        with pytest.raises(ScenarioError, match=match) as e:
            read(path)
        assert path.name in str(e.value)


def test_number_or_list_takes_one_number_or_a_list_within_the_bounds():
    s = Schema("toy", "a test", (Table("", "top", (Key("spacing_m", "number_or_list", None, "m", gt=0.0),)),))
    assert s.validate({"spacing_m": 2}, FILE)["spacing_m"] == 2.0
    assert isinstance(s.validate({"spacing_m": 2}, FILE)["spacing_m"], float)
    assert s.validate({"spacing_m": [1.0, 1.5]}, FILE)["spacing_m"] == [1.0, 1.5]
    assert s.validate({}, FILE)["spacing_m"] is None
    with pytest.raises(ScenarioError, match="spacing_m"):
        s.validate({"spacing_m": "wide"}, FILE)
    with pytest.raises(ScenarioError, match="out of range"):
        s.validate({"spacing_m": [1.0, -1.0]}, FILE)
    assert "| `spacing_m` | number or list |" in render_markdown(s)
