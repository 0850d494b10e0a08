"""Drop-test scenario configuration: every shipped scenario validates; a misspelt or mistyped key
in a copied scenario is a located error, also through ``workbench run``."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import ScenarioError, find_scenarios, load_scenario
from workbench.problems.droptest.config import SCHEMA, DropConfig, config_for
from workbench.problems.droptest.synthetic import synthesize_droptest

SHIPPED = {n: p for n, p in find_scenarios(assets_dir()).items() if load_scenario(p).kind == "droptest"}


def test_there_are_shipped_droptest_scenarios():
    assert {"droptest", "droptest_ranging", "droptest_rocks", "droptest_fullstroke"} <= set(SHIPPED)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_every_shipped_scenario_validates(name):
    sc = load_scenario(SHIPPED[name])
    cfg = DropConfig.from_scenario(sc)
    assert cfg.triads == ("BP", "PYBP", "PXBP", "MXBP") and cfg.mode == "kinematic"
    assert cfg.ranging == (name == "droptest_ranging") and cfg.rocks == (name == "droptest_rocks")
    assert config_for(sc) is config_for(sc)  # built once per scenario


def test_defaults_fill_what_a_scenario_leaves_out():
    sc = load_scenario(SHIPPED["droptest"])
    data = {k: v for k, v in sc.data.items() if k not in ("filter", "sensors")}
    cfg = DropConfig.from_scenario(type(sc)(sc.path, sc.name, sc.kind, "", data))
    assert cfg.filter_rate_hz == 1000.0 and cfg.q_accel == 5.0 and cfg.gyro_noise_dps == 0.4
    assert cfg.accel_full_scale_g == 2000.0 and cfg.filter_order == 4 and cfg.bag_pressure_psi is None
    assert not cfg.ranging and cfg.radar_guns == {}


def test_ranging_guns_are_read():
    cfg = config_for(load_scenario(SHIPPED["droptest_ranging"]))
    assert set(cfg.radar_guns) == {"G1", "G2", "G3"} and np.array_equal(cfg.radar_guns["G3"], [0.0, -12.0, 4.0])
    assert cfg.odometer and cfg.ranging_rate_hz == 200.0


def _copy_with(tmp_path: Path, old: str, new: str) -> Path:
    src = SHIPPED["droptest"]
    dst = tmp_path / "scenarios" / "my_drop.toml"
    dst.parent.mkdir(parents=True)
    shutil.copytree(src.parent.parent / "landers", tmp_path / "landers")
    text = src.read_text()
    assert text.count(old) == 1
    dst.write_text(text.replace(old, new).replace('name = "droptest"', 'name = "my_drop"'))
    return dst


@pytest.mark.parametrize(
    "old, new, key, table, suggestion",
    [
        ("noise_dps = 0.4", "noise_dsp = 0.4", "sensors.gyro.noise_dsp", "[sensors.gyro]", "noise_dps"),
        ("q_angular = 20.0", "q_angualr = 20.0", "filter.q_angualr", "[filter]", "q_angular"),
        ("[chamber]", "[chamber]\nramp_angel_deg = 45.0", "chamber.ramp_angel_deg", "[chamber]", "ramp_angle_deg"),
        ("[sensors.gyro]", "[sensors.gyros]", "sensors.gyros", "[sensors]", "gyro"),
    ],
)
def test_misspelt_key_is_a_located_error(tmp_path, old, new, key, table, suggestion):
    path = _copy_with(tmp_path, old, new)
    with pytest.raises(ScenarioError) as ei:
        DropConfig.from_scenario(load_scenario(path))
    e = ei.value
    assert e.file == str(path) and e.key == key
    assert table in str(e) and f"did you mean '{suggestion}'?" in str(e)


def test_wrong_type_is_a_located_error(tmp_path):
    path = _copy_with(tmp_path, "nail_depth_m = 0.3", 'nail_depth_m = "0.3 m"')
    with pytest.raises(ScenarioError, match="expected a number") as ei:
        config_for(load_scenario(path))
    assert ei.value.key == "chamber.nail_depth_m"


def test_synthesis_rejects_the_scenario_before_simulating(tmp_path):
    path = _copy_with(tmp_path, "noise_g = 0.2", "noise_gg = 0.2")
    with pytest.raises(ScenarioError, match="noise_gg"):
        synthesize_droptest(load_scenario(path), tmp_path / "tel")
    assert not list((tmp_path / "tel").glob("*.csv"))


def test_workbench_run_rejects_an_unknown_key(tmp_path, capsys):
    from workbench.cli import main

    path = _copy_with(tmp_path, "adaptive_gain = 4.0", "adaptive_gian = 4.0")
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert "filter.adaptive_gian" in err and "did you mean 'adaptive_gain'" in err and str(path) in err
    assert not list((tmp_path / "out").glob("*.rrd"))


def test_schema_declares_every_table_of_the_shipped_scenarios():
    tables = {t.name for t in SCHEMA.tables}
    for p in SHIPPED.values():
        data = load_scenario(p).data
        for top, v in data.items():
            assert top in tables or any(t.startswith(top + ".") for t in tables), top
            assert isinstance(v, dict)
