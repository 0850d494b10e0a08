"""MEADS settings (issue 25): one frozen, picklable settings object per run, built once from the
scenario; the vehicle asset and the initial-state file read through their schemas; a bad key in
the vehicle asset is a located error and ``workbench run`` exits 3 with it."""

from __future__ import annotations

import dataclasses
import pickle
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from workbench import cli
from workbench.io.assets import asset_path
from workbench.io.scenario import ScenarioError, load_scenario
from workbench.problems.meads import problem as meads_problem
from workbench.problems.meads.config import MeadsSettings
from workbench.problems.meads.problem import MeadsProblem
from workbench.problems.meads.telemetry import InitialState, read_initial_state, write_initial_state

PACKAGE = Path(meads_problem.__file__).resolve().parent


def test_settings_are_frozen_picklable_and_hold_the_vehicle():
    st = MeadsProblem().settings(load_scenario(asset_path("scenarios", "msl_meads.toml")))
    assert isinstance(st, MeadsSettings) and st.run.name == "msl_meads" and st.run.seed == 11
    assert st.vehicle_file.is_absolute() and st.vehicle_file.name == "msl_meads.toml"
    assert st.vehicle.port_names == ("P1", "P2", "P3", "P4", "P5", "P6", "P7")
    assert st.pressure.failure_port == "P5" and st.estimator.model == "table"
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.ekf.passes = 1  # type: ignore[misc]
    back = pickle.loads(pickle.dumps(st))
    assert back.run == st.run and back.ekf == st.ekf and back.truth == st.truth
    assert np.array_equal(back.vehicle.radius(), st.vehicle.radius())
    nominal = dataclasses.replace(st, pressure=dataclasses.replace(st.pressure, failure_port=""))
    assert nominal.pressure.failure_port == "" and st.pressure.failure_port == "P5"


def test_nothing_below_problem_py_sees_the_scenario():
    for p in sorted(PACKAGE.glob("*.py")):
        if p.name in ("config.py", "problem.py"):
            continue
        text = p.read_text()
        assert not re.search(r"\bScenario\b", text), f"{p.name} names Scenario"
        assert not re.search(r"scenario\.(get|has|path_of|data|with_overrides)\b", text), p.name
        assert "config_for" not in text and "import tomllib" not in text, p.name


def _vehicle_scenario(tmp_path: Path, old: str, new: str) -> Path:
    veh = tmp_path / "veh.toml"
    text = asset_path("vehicles", "msl_meads.toml").read_text()
    assert old in text
    veh.write_text(text.replace(old, new))
    sc = tmp_path / "m.toml"
    shutil.copy(asset_path("scenarios", "msl_meads.toml"), sc)
    sc.write_text(sc.read_text().replace('file = "../vehicles/msl_meads.toml"', 'file = "veh.toml"'))
    return sc


def test_wrong_key_in_the_vehicle_asset_is_located_and_exits_3(tmp_path, capsys):
    sc = _vehicle_scenario(tmp_path, "nose_radius_m = 1.125", "nose_raduis_m = 1.125")
    with pytest.raises(ScenarioError) as info:
        MeadsProblem().settings(load_scenario(sc))
    err = info.value
    assert err.file == str(tmp_path / "veh.toml") and err.key == "vehicle.nose_raduis_m"
    assert "flush-air-data vehicle asset" in err.reason and "did you mean 'nose_radius_m'?" in err.reason
    out = tmp_path / "out"
    assert cli.main(["run", str(sc), "--out", str(out), "--quiet"]) == cli.EXIT_INPUT == 3
    msg = capsys.readouterr().err
    assert "veh.toml" in msg and "vehicle.nose_raduis_m" in msg and "did you mean 'nose_radius_m'?" in msg


def test_out_of_range_vehicle_value_names_the_bound(tmp_path):
    sc = _vehicle_scenario(tmp_path, "mass_kg = 3300.0", "mass_kg = 0.0")
    with pytest.raises(ScenarioError, match=r"vehicle\.mass_kg'.*0 kg is out of range: must be > 0 kg"):
        MeadsProblem().settings(load_scenario(sc))


def test_initial_state_file_has_a_schema(tmp_path):
    # a state an entry can have (telemetry.RADIUS_ENVELOPE_M, SPEED_ENVELOPE_MPS)
    st = InitialState(
        1.5, np.array([3.5e6, 1.0, 1.0]), np.full(3, 2000.0), np.array([0.0, 0.0, 0.0, 1.0]), 10.0, 0.1, 1e-3
    )
    p = write_initial_state(tmp_path / "initial_state.toml", st)
    back = read_initial_state(p)
    assert back.t == 1.5 and np.array_equal(back.v_M, st.v_M) and back.sigma_att == pytest.approx(1e-3)
    p.write_text(p.read_text().replace("sigma_position_m", "sigma_positon_m"))
    with pytest.raises(ScenarioError, match=r"state\.sigma_positon_m.*did you mean 'sigma_position_m'\?"):
        read_initial_state(p)
    p = write_initial_state(tmp_path / "b.toml", dataclasses.replace(st, sigma_v=-1.0))
    with pytest.raises(ScenarioError, match=r"state\.sigma_velocity_mps.*must be ≥ 0"):
        read_initial_state(p)


@pytest.mark.parametrize(
    "key",
    [
        "sensors.pressure.scale_sigma",
        "sensors.pressure.residual_bias_sigma_pa",
        "sensors.imu.accel_noise_mps2",
        # 1σ keys not named "sigma" (their meaning says "1-sigma")
        "sensors.imu.accel_bias_mps2",
        "sensors.imu.gyro_scale",
        "estimator.model_error_frac",
    ],
)
def test_a_negative_sigma_of_the_error_model_names_the_bound(key):
    """A 1σ of the synthetic error chain below 0 was taken (squared, or as numpy's scale); now refused."""
    sc = load_scenario(asset_path("scenarios", "msl_meads.toml")).with_overrides({key: -0.5})
    with pytest.raises(ScenarioError, match="out of range: must be ≥ 0") as e:
        MeadsProblem().settings(sc)
    assert e.value.key == key
