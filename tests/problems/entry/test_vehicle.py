"""The entry-vehicle asset schema (``models.aerodynamics.VEHICLE_SCHEMA``): the shipped assets load;
a misspelt key is a located error with the nearest valid key, and ``workbench run`` exits 3 on it;
an out-of-range value names the bound; shapes are checked after the keys."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from workbench.cli import EXIT_INPUT, main
from workbench.io.assets import assets_dir
from workbench.io.scenario import ScenarioError
from workbench.models.aerodynamics import VEHICLE_SCHEMA, load_vehicle
from workbench.problems.entry.problem import EntryProblem
from workbench.problems.registry import schemas

VEHICLES = assets_dir() / "vehicles"


@pytest.mark.parametrize("name", ["schiaparelli", "huygens", "mer_like"])
def test_shipped_vehicle_assets_load(name):
    v = load_vehicle(VEHICLES / f"{name}.toml")
    assert v.mass_entry > v.parachute.mass + v.mass_front_shield + v.mass_back_shell
    assert v.inertia_G.shape == (3, 3) and v.capsule.ca.ndim == 3


def test_the_schema_is_listed_for_formats():
    assert VEHICLE_SCHEMA in EntryProblem.file_schemas
    assert any(s is VEHICLE_SCHEMA for s in schemas())


def _asset(tmp_path: Path, old: str, new: str) -> Path:
    text = (VEHICLES / "schiaparelli.toml").read_text()
    assert text.count(old) == 1, old
    out = tmp_path / "vehicle.toml"
    out.write_text(text.replace(old, new))
    return out


@pytest.mark.parametrize(
    "old, new, key, suggestion",
    [
        ("mass_entry_kg = 577.0", "mass_entri_kg = 577.0", "vehicle.mass_entri_kg", "mass_entry_kg"),
        ("nominal_diameter_m = 12.0", "nominal_diam_m = 12.0", "aero.parachute.nominal_diam_m", "nominal_diameter_m"),
    ],
)
def test_wrong_key_names_file_key_and_nearest(tmp_path, old, new, key, suggestion):
    path = _asset(tmp_path, old, new)
    with pytest.raises(ScenarioError) as ei:
        load_vehicle(path)
    e = ei.value
    assert e.file == str(path) and e.key == key
    assert "vehicle asset" in str(e) and f"did you mean '{suggestion}'?" in str(e)


def test_out_of_range_value_names_the_bound(tmp_path):
    path = _asset(tmp_path, "mass_entry_kg = 577.0", "mass_entry_kg = -1.0")
    with pytest.raises(ScenarioError, match=r"must be > 0") as ei:
        load_vehicle(path)
    assert ei.value.key == "vehicle.mass_entry_kg"


def test_shapes_are_checked_after_the_keys(tmp_path):
    text = (VEHICLES / "schiaparelli.toml").read_text()
    path = tmp_path / "vehicle.toml"
    path.write_text(text.replace("attach_point_m = [0.0, 0.0, 0.95]", "attach_point_m = [0.0, 0.95]"))
    with pytest.raises(ScenarioError, match="attach_point_m"):
        load_vehicle(path)
    path.write_text(text.replace("kn_continuum = 1.0e-3", "kn_continuum = 20.0"))
    with pytest.raises(ScenarioError, match="must exceed kn_continuum"):
        load_vehicle(path)


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_vehicle(tmp_path / "none.toml")


def test_workbench_run_exits_3_on_a_wrong_vehicle_key(tmp_path, capsys):
    src = assets_dir() / "scenarios" / "schiaparelli.toml"
    (tmp_path / "scenarios").mkdir()
    shutil.copy(src, tmp_path / "scenarios" / "my_entry.toml")
    (tmp_path / "vehicles").mkdir()
    _asset(tmp_path / "vehicles", "riser_length_m = 27.0", "riser_lenght_m = 27.0").rename(
        tmp_path / "vehicles" / "schiaparelli.toml"
    )
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "scenarios" / "my_entry.toml"), "--out", str(out), "-q"]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert "vehicle.riser_lenght_m" in err and "did you mean 'riser_length_m'?" in err
    assert str(tmp_path / "vehicles" / "schiaparelli.toml") in err
    assert not out.exists(), "a rejected run wrote an output folder"
