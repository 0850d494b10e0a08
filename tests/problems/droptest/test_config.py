"""Drop-test settings: every shipped scenario validates into one frozen :class:`DropSettings`; a
misspelt or mistyped key in a copied scenario, lander asset or setup file is a located error, also
through ``workbench run``."""

from __future__ import annotations

import dataclasses
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import ScenarioError, find_scenarios, load_scenario
from workbench.problems.droptest.config import SCHEMA, DropSettings
from workbench.problems.droptest.problem import DropTestProblem
from workbench.problems.droptest.synthetic import synthesize_droptest
from workbench.problems.droptest.telemetry import read_setup

SHIPPED = {n: p for n, p in find_scenarios(assets_dir()).items() if load_scenario(p).kind == "droptest"}


def test_there_are_shipped_droptest_scenarios():
    assert {"droptest", "droptest_ranging", "droptest_rocks", "droptest_fullstroke"} <= set(SHIPPED)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_every_shipped_scenario_validates(name):
    sc = load_scenario(SHIPPED[name])
    s = DropTestProblem().settings(sc)
    assert isinstance(s, DropSettings) and s.run.name == name
    assert s.accelerometer.triads == ("BP", "PYBP", "PXBP", "MXBP") and s.filter.mode == "kinematic"
    assert s.ranging.enabled == (name == "droptest_ranging") and (s.chamber.rocks is not None) == (
        name == "droptest_rocks"
    )
    assert s.lander_file.is_absolute() and s.lander.mass > 0.0  # the asset, read once
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.filter = None  # type: ignore[misc]


def test_settings_are_picklable_and_vary_with_replace():
    s = DropTestProblem().settings(load_scenario(SHIPPED["droptest"]))
    back = pickle.loads(pickle.dumps(s))
    assert back.gyro == s.gyro and back.lander.mass == s.lander.mass
    t = dataclasses.replace(s, chamber=dataclasses.replace(s.chamber, ramp_angle_deg=45.0))
    assert t.chamber.ramp_angle_deg == 45.0 and s.chamber.ramp_angle_deg == 60.0


def test_defaults_fill_what_a_scenario_leaves_out():
    sc = load_scenario(SHIPPED["droptest"])
    data = {k: v for k, v in sc.data.items() if k not in ("filter", "sensors")}
    s = DropSettings.from_scenario(type(sc)(sc.path, sc.name, sc.kind, "", data))
    assert s.filter.rate_hz == 1000.0 and s.filter.q_accel == 5.0 and s.gyro.noise_dps == 0.4
    assert s.accelerometer.full_scale_g == 2000.0 and s.acquisition.order == 4 and s.synthetic.bag_pressure_psi is None
    assert not s.ranging.enabled and s.ranging.radar_guns == {}


def test_ranging_guns_are_read():
    s = DropSettings.from_scenario(load_scenario(SHIPPED["droptest_ranging"]))
    assert set(s.ranging.radar_guns) == {"G1", "G2", "G3"}
    assert np.array_equal(s.ranging.radar_guns["G3"], [0.0, -12.0, 4.0])
    assert s.ranging.odometer and s.ranging.rate_hz == 200.0 and s.ranging.rate_given


def _copy_with(tmp_path: Path, old: str, new: str, lander: tuple[tuple[str, str], ...] = ()) -> Path:
    src = SHIPPED["droptest"]
    dst = tmp_path / "scenarios" / "my_drop.toml"
    dst.parent.mkdir(parents=True)
    shutil.copytree(src.parent.parent / "landers", tmp_path / "landers")
    text = src.read_text()
    assert text.count(old) == 1
    dst.write_text(text.replace(old, new).replace('name = "droptest"', 'name = "my_drop"'))
    asset = tmp_path / "landers" / "mer_drop_lander.toml"
    for a, b in lander:
        atext = asset.read_text()
        assert atext.count(a) == 1
        asset.write_text(atext.replace(a, b))
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
        DropSettings.from_scenario(load_scenario(path))
    e = ei.value
    assert e.file == str(path) and e.key == key
    assert table in str(e) and f"did you mean '{suggestion}'?" in str(e)


def test_wrong_type_is_a_located_error(tmp_path):
    path = _copy_with(tmp_path, "nail_depth_m = 0.3", 'nail_depth_m = "0.3 m"')
    with pytest.raises(ScenarioError, match="expected a number") as ei:
        DropSettings.from_scenario(load_scenario(path))
    assert ei.value.key == "chamber.nail_depth_m"


def test_synthesis_rejects_the_scenario_before_simulating(tmp_path):
    path = _copy_with(tmp_path, "noise_g = 0.2", "noise_gg = 0.2")
    with pytest.raises(ScenarioError, match="noise_gg"):
        synthesize_droptest(DropTestProblem().settings(load_scenario(path)), tmp_path / "tel")
    assert not list((tmp_path / "tel").glob("*.csv"))


def test_workbench_run_rejects_an_unknown_key(tmp_path, capsys):
    from workbench.cli import main

    path = _copy_with(tmp_path, "adaptive_gain = 4.0", "adaptive_gian = 4.0")
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert "filter.adaptive_gian" in err and "did you mean 'adaptive_gain'" in err and str(path) in err
    assert not list((tmp_path / "out").glob("*.rrd"))


# ------------------------------------------------------------------ the lander asset's schema
#: the shipped asset with its lobes given one by one (the layout where `standoff_m` is optional)
_EXPLICIT_LOBES = (
    "lobes_per_bag = 6",
    "lobe_centers_m = [[0, 0, -1.2], [0, 1.2, 0.3], [1.0, -0.6, 0.3], [-1.0, -0.6, 0.3]]\n"
    'lobe_faces = ["base", "side_PY", "side_PX", "side_MX"]',
)


@pytest.mark.parametrize(
    "edits, key, suggestion",
    [
        ((_EXPLICIT_LOBES, ("standoff_m = -0.60", "standof_m = -0.60")), "airbags.standof_m", "standoff_m"),
        ((("gamma = 1.4 ", "gama = 1.4 "),), "airbags.gama", "gamma"),
    ],
)
def test_misspelt_lander_key_is_a_located_error(tmp_path, capsys, edits, key, suggestion):
    """Before the schema a misspelt optional key was ignored (`standof_m` with explicit lobes: exit
    0, the standoff taken as 0, the health check's bag-thickness bound moved); now the scenario is
    refused before any work, by the settings and by the CLI (exit 3)."""
    from workbench.cli import main

    path = _copy_with(tmp_path, "noise_g = 0.2", "noise_g = 0.2", lander=edits)
    asset = tmp_path / "landers" / "mer_drop_lander.toml"
    with pytest.raises(ScenarioError) as ei:
        DropSettings.from_scenario(load_scenario(path))
    e = ei.value
    assert Path(e.file).resolve() == asset.resolve() and e.key == key
    assert "lander asset" in str(e) and f"did you mean '{suggestion}'?" in str(e)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert key in err and "mer_drop_lander.toml" in err and f"did you mean '{suggestion}'" in err


def test_lander_value_out_of_bounds_names_the_bound(tmp_path):
    path = _copy_with(
        tmp_path, "noise_g = 0.2", "noise_g = 0.2", lander=(("gas_volume_m3 = 40.0", "gas_volume_m3 = -4.0"),)
    )
    with pytest.raises(ScenarioError, match="out of range: must be > 0") as ei:
        DropSettings.from_scenario(load_scenario(path))
    assert ei.value.key == "airbags.gas_volume_m3"


# ------------------------------------------------------------------ the setup file's schema
_SETUP = """[hanging]
position_m = [0.0, -10.0, 8.0]
position_sigma_m = 0.03
[bungee]
anchor_m = [0.0, 0.0, 20.0]
rest_length_m = 4.0
coefficients = [900.0, 60.0, -2.0]
count = 1.2
attach_body_m = [0.0, 0.0, -0.4]
mass_kg = 533.0
"""


@pytest.mark.parametrize(
    "old, new, key, suggestion",
    [
        ("position_sigma_m", "position_sigme_m", "hanging.position_sigme_m", "position_sigma_m"),
        ("rest_length_m", "rest_lenght_m", "bungee.rest_lenght_m", "rest_length_m"),
    ],
)
def test_misspelt_setup_key_is_a_located_error(tmp_path, old, new, key, suggestion):
    p = tmp_path / "setup.toml"
    p.write_text(_SETUP.replace(old, new))
    with pytest.raises(ScenarioError) as ei:
        read_setup(p, ())
    e = ei.value
    assert Path(e.file) == p and e.key == key
    assert "drop setup file" in str(e) and f"did you mean '{suggestion}'?" in str(e)


def test_negative_position_sigma_names_the_bound(tmp_path):
    p = tmp_path / "setup.toml"
    p.write_text(_SETUP.replace("position_sigma_m = 0.03", "position_sigma_m = -0.03"))
    with pytest.raises(ScenarioError, match=r"-0.03 m is out of range: must be > 0 m") as ei:
        read_setup(p, ())
    assert ei.value.key == "hanging.position_sigma_m"


def test_workbench_run_rejects_an_unknown_setup_key(tmp_path, capsys):
    """A user-telemetry scenario whose setup file has a misspelt key: exit 3 naming file and key."""
    from workbench.cli import main

    tel = tmp_path / "tel"
    synthesize_droptest(DropTestProblem().settings(load_scenario(SHIPPED["droptest"])), tel)
    setup = tel / "setup.toml"
    setup.write_text(setup.read_text().replace("position_sigma_m", "position_sigme_m"))
    text = SHIPPED["droptest"].read_text()
    user = text[: text.index("[synthetic]")]  # the last table: the scenario becomes a user-telemetry one
    user = user.replace('lander = "../landers/', f'lander = "{SHIPPED["droptest"].parent.parent}/landers/')
    user = user.replace('name = "droptest"', 'name = "my_user_drop"')
    user += (
        f'\n[telemetry]\nimu = "{tel / "imu.csv"}"\nattitude_3dm = "{tel / "3dm.csv"}"\n'
        f'events = "{tel / "events.csv"}"\nsetup = "{setup}"\n'
    )
    path = tmp_path / "my_user_drop.toml"
    path.write_text(user)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert "hanging.position_sigme_m" in err and str(setup) in err and "did you mean 'position_sigma_m'" in err


def test_schema_declares_every_table_of_the_shipped_scenarios():
    tables = {t.name for t in SCHEMA.tables}
    for p in SHIPPED.values():
        data = load_scenario(p).data
        for top, v in data.items():
            assert top in tables or any(t.startswith(top + ".") for t in tables), top
            assert isinstance(v, dict)


# ------------------------------------------------------------------ a 1σ the filter cannot use
def _ranging_copy_with(tmp_path: Path, key: str, value: str, extra: str = "") -> Path:
    """droptest_ranging copied with the line ``key = ...`` set to ``value`` (and ``extra`` appended)."""
    src = SHIPPED["droptest_ranging"]
    dst = tmp_path / "scenarios" / "my_drop.toml"
    dst.parent.mkdir(parents=True)
    shutil.copytree(src.parent.parent / "landers", tmp_path / "landers")
    lines = src.read_text().splitlines()
    hits = [i for i, line in enumerate(lines) if line.split("=")[0].strip() == key]
    assert len(hits) == 1, key
    lines[hits[0]] = f"{key} = {value}"
    dst.write_text("\n".join(lines) + "\n" + extra)
    return dst


@pytest.mark.parametrize(
    "table, key",
    [
        ("sensors.gyro", "noise_dps"),
        ("sensors.attitude_3dm", "gravity_sigma_deg"),
        ("sensors.attitude_3dm", "magnetic_sigma_deg"),
        ("sensors.ranging", "radar_range_sigma_m"),
        ("sensors.ranging", "radar_rate_sigma_mps"),
        ("filter", "hang_zupt_sigma_mps"),
        ("filter", "velocity_sigma_mps"),
        ("synthetic", "survey_sigma_m"),
    ],
)
@pytest.mark.parametrize("value", ["0.0", "-0.01"])
def test_a_zero_or_negative_filter_sigma_is_a_located_error(tmp_path, table, key, value):
    """A measurement's or the filter's 1σ of 0 declares a perfect measurement or model: before the
    bound, the smoother stopped with a non-positive-definite covariance naming other keys (exit 4),
    and a negative survey σ ended in numpy's traceback; now the scenario is refused, naming the key."""
    path = _ranging_copy_with(tmp_path, key, value)
    with pytest.raises(ScenarioError, match="out of range: must be > 0") as ei:
        DropSettings.from_scenario(load_scenario(path))
    assert ei.value.key == f"{table}.{key}" and Path(ei.value.file) == path


def test_a_per_gun_zero_rate_sigma_is_a_located_error(tmp_path):
    guns = DropTestProblem().settings(load_scenario(SHIPPED["droptest_ranging"])).ranging.radar_guns
    gun = sorted(guns)[0]
    path = _ranging_copy_with(
        tmp_path, "radar_rate_sigma_mps", "0.05", f"[sensors.ranging.rate_sigma_mps]\n{gun} = 0.0\n"
    )
    with pytest.raises(ScenarioError, match="out of range: must be > 0") as ei:
        DropSettings.from_scenario(load_scenario(path))
    assert ei.value.key == f"sensors.ranging.rate_sigma_mps.{gun}"


def test_a_perfect_odometer_is_refused_unless_it_is_quantised(tmp_path):
    path = _ranging_copy_with(tmp_path, "odometer_sigma_m", "0.0")
    with pytest.raises(ScenarioError, match="perfect odometer") as ei:
        DropSettings.from_scenario(load_scenario(path))
    assert ei.value.key == "sensors.ranging.odometer_sigma_m"
    quantised = _ranging_copy_with(tmp_path / "q", "odometer_sigma_m", "0.0")
    text = quantised.read_text().replace(
        "odometer_sigma_m = 0.0", "odometer_sigma_m = 0.0\nodometer_quantisation_m = 0.002"
    )
    quantised.write_text(text)
    s = DropSettings.from_scenario(load_scenario(quantised))
    assert s.ranging.odometer_sigma_m == 0.0 and s.ranging.odometer_quantisation_m == 0.002
