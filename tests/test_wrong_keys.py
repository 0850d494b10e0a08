"""Every input file kind has a schema (issue 25): a misspelt key, typed the way a new user would,
ends the run with exit 3 and a message naming the file, the dotted key and the nearest valid key,
before anything is computed or written. One row per file kind: the scenario of each problem, the
drop-test lander asset and setup file, the vehicle assets, the rocket log's metadata."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from workbench.cli import EXIT_INPUT, main
from workbench.io.assets import assets_dir

#: (file kind, shipped scenario to run, file to mutate (relative to the copied assets), key, typo)
SCENARIO_ROWS = [
    ("droptest scenario", "droptest", "scenarios/droptest.toml", "ramp_angle_deg", "ramp_angel_deg"),
    ("entry scenario", "schiaparelli", "scenarios/schiaparelli.toml", "gyro_noise_dps", "gyro_nois_dps"),
    ("meads scenario", "msl_meads", "scenarios/msl_meads.toml", "failure_port", "failur_port"),
    ("post2 problem file", "post2_huygens", "scenarios/post2_huygens.toml", "t_end_s", "t_ends_s"),
    ("flush-air-data vehicle asset", "msl_meads", "vehicles/msl_meads.toml", "tube_length_m", "tube_lenght_m"),
    ("entry vehicle asset", "schiaparelli", "vehicles/schiaparelli.toml", "nose_radius_m", "nose_radus_m"),
    ("drop-test lander asset", "droptest", "landers/mer_drop_lander.toml", "standoff_m", "standof_m"),
]


def _copy_assets(tmp_path: Path) -> Path:
    root = tmp_path / "assets"
    shutil.copytree(assets_dir(), root, ignore=shutil.ignore_patterns("__pycache__", "*.py"))
    return root


def _misspell(path: Path, key: str, typo: str) -> None:
    text = path.read_text(encoding="utf-8")
    new, n = re.subn(rf"(?m)^(\s*){re.escape(key)}(\s*=)", rf"\g<1>{typo}\g<2>", text, count=1)
    assert n == 1, f"{path} has no line '{key} = ...' to misspell"
    path.write_text(new, encoding="utf-8")


def _assert_named(err: str, path: Path, typo: str, key: str) -> None:
    assert "input error" in err, err
    assert str(path) in err, f"the message does not name the file {path}:\n{err}"
    assert typo in err, f"the message does not name the key {typo!r}:\n{err}"
    assert f"did you mean '{key}'" in err, f"the message does not suggest {key!r}:\n{err}"


@pytest.mark.parametrize(("what", "scenario", "file", "key", "typo"), SCENARIO_ROWS, ids=[r[0] for r in SCENARIO_ROWS])
def test_a_misspelt_key_is_exit_3_naming_file_key_and_nearest(tmp_path, capsys, what, scenario, file, key, typo):
    root = _copy_assets(tmp_path)
    path = root / file
    _misspell(path, key, typo)
    out = tmp_path / "out"
    code = main(["run", str(root / "scenarios" / f"{scenario}.toml"), "--out", str(out), "--jobs", "1", "-q"])
    err = capsys.readouterr().err
    assert code == EXIT_INPUT, err
    _assert_named(err, path, typo, key)
    assert not out.exists(), "a rejected run wrote an output folder"


def test_a_misspelt_metadata_key_of_a_flight_log_is_exit_3(tmp_path, capsys):
    """The rocket log's metadata.json (``workbench import airbrakes``): the JSON path of the key."""
    import json

    data = Path(__file__).parent / "problems" / "post2" / "data" / "airbrakes_excerpt"
    log = data / "jackpot_launch_1_excerpt.csv"
    meta = json.loads((data / "metadata.json").read_text(encoding="utf-8"))
    rocket = meta[log.name]["rocket"]
    rocket["rocket_cross_sectional_area_m"] = rocket.pop("rocket_cross_sectional_area_m2")
    path = tmp_path / "metadata.json"
    path.write_text(json.dumps(meta), encoding="utf-8")
    out = tmp_path / "flight"
    code = main(["import", "airbrakes", str(log), "--metadata", str(path), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == EXIT_INPUT, err
    _assert_named(err, path, f"{log.name}.rocket.rocket_cross_sectional_area_m", "rocket_cross_sectional_area_m2")
    assert not out.exists()


def test_a_misspelt_key_of_the_drop_setup_file_is_exit_3(tmp_path, capsys):
    """The drop rig's setup file (``[telemetry] setup``, a user-data scenario written by ``workbench
    init droptest``): a misspelt ``position_sigma_m`` in ``[hanging]``."""
    folder = tmp_path / "rig"
    assert main(["init", "droptest", str(folder)]) == 0
    capsys.readouterr()
    setup = next((folder / "telemetry").glob("*setup*.toml"))
    _misspell(setup, "position_sigma_m", "position_sigm_m")
    out = tmp_path / "out"
    code = main(["run", str(folder / "scenario.toml"), "--out", str(out), "--jobs", "1", "-q"])
    err = capsys.readouterr().err
    assert code == EXIT_INPUT, err
    _assert_named(err, setup.resolve(), "position_sigm_m", "position_sigma_m")
    assert not out.exists()
