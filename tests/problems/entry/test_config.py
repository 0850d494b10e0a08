"""Entry scenario settings: every shipped scenario validates; the defaults are those of the
code's dataclasses; a misspelt key is a located error; the pipeline and the smoother validation
read the same settings; the settings are frozen, picklable and varied with dataclasses.replace."""

from __future__ import annotations

import dataclasses
import math
import pickle
import shutil
from pathlib import Path

import pytest

from workbench.io.assets import assets_dir
from workbench.io.scenario import Scenario, ScenarioError, find_scenarios, load_scenario
from workbench.problems.entry import montecarlo as mc
from workbench.problems.entry.config import SCHEMA, EntrySettings
from workbench.problems.entry.dispersion import AcceptanceRules
from workbench.problems.entry.preprocess import PreprocessConfig
from workbench.problems.entry.problem import EntryProblem
from workbench.problems.entry.sensors import EntryTelemetrySpec
from workbench.problems.entry.telemetry import TelemetryChecks, telemetry_paths
from workbench.problems.entry.truth import EntryTruthSpec
from workbench.problems.entry.truth_mc import member_settings

SHIPPED = {n: p for n, p in find_scenarios(assets_dir()).items() if load_scenario(p).kind == "entry"}


def minimal(tmp_path: Path, **tables) -> Scenario:
    data = {"scenario": {"name": "m", "kind": "entry"}, **tables}
    return Scenario(tmp_path / "m.toml", "m", "entry", "", data)


def test_there_is_a_shipped_entry_scenario():
    assert "schiaparelli" in SHIPPED


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_every_shipped_scenario_validates(name):
    sc = load_scenario(SHIPPED[name])
    cfg = EntryProblem().settings(sc)
    assert cfg.dispersion.members > 0 and cfg.reconstruction.bridge_mode in ("relative", "paper")
    assert cfg.vehicle is not None and cfg.vehicle_path.is_absolute()
    assert pickle.loads(pickle.dumps(cfg)).run == cfg.run  # Monte Carlo workers receive it


def test_settings_are_frozen_and_varied_by_replace():
    cfg = EntrySettings.from_scenario(load_scenario(SHIPPED["schiaparelli"]))
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.dispersion.members = 1  # type: ignore[misc]
    mc_cfg = member_settings(cfg, 2)
    assert mc_cfg.dispersion.refine_rounds == 2 and mc_cfg.dispersion.cloud == 0
    assert cfg.dispersion.refine_rounds == 3 and mc_cfg.vehicle is cfg.vehicle


def test_schiaparelli_values():
    cfg = EntrySettings.from_scenario(load_scenario(SHIPPED["schiaparelli"]))
    d = cfg.dispersion
    assert d.members == 10000 and d.refine_rounds == 3 and d.cloud == 300
    assert d.rules == AcceptanceRules(h_pdd_m=(10000.0, 2000.0))  # the file's rules are the defaults
    assert cfg.radar.azimuths_deg == (0.0, 120.0, 240.0) and cfg.radar.constrained and cfg.terrain_m == -1440.0
    assert cfg.synthetic.seed == 7 == cfg.synthetic.truth_seed
    assert cfg.synthetic.truth.epoch_utc == cfg.epoch_utc == "2016-10-19T14:42:22.132Z"
    assert cfg.synthetic.telemetry.squint_deg == cfg.radar.squint_deg == 20.0
    assert cfg.atmosphere.fill_method == "hydrostatic" and cfg.atmosphere.fill_temperature_shape == "linear"


def test_defaults_are_those_of_the_code(tmp_path):
    cfg = EntrySettings.from_scenario(minimal(tmp_path))
    assert cfg.preprocess == PreprocessConfig()
    assert cfg.checks == TelemetryChecks()
    assert cfg.dispersion.rules == AcceptanceRules()
    assert cfg.epoch_utc is None and cfg.reconstruction.initial == "fused" and cfg.wind_method == "specific_force"
    assert cfg.vehicle is None  # a user scenario without [vehicle] file: only the reconstruction needs it
    with pytest.raises(ScenarioError, match="vehicle"):
        cfg.require_vehicle()
    # the synthetic spec: the code's defaults, the beam geometry and terrain from [radar] and [site]
    spec, d = cfg.synthetic.telemetry, EntryTelemetrySpec()
    assert spec.imu.gyro_bias == pytest.approx(d.imu.gyro_bias, rel=1e-12)  # the schema rounds its degrees
    assert dataclasses.replace(spec, imu=d.imu, squint_deg=None, azimuths_deg=None) == d
    assert cfg.synthetic.truth == EntryTruthSpec()
    truth_keys = {k.name: k.default for k in SCHEMA.table("truth").keys}
    d = EntryTruthSpec()
    assert set(truth_keys) == set(EntryTruthSpec.__dataclass_fields__)
    assert truth_keys["pdd_mach"] == d.pdd_mach and truth_keys["dt_chute"] == d.dt_chute


def test_preprocess_sigmas_fall_back_to_the_reconstruction_table(tmp_path):
    cfg = EntrySettings.from_scenario(
        minimal(tmp_path, reconstruction={"rate_pdd_dps": 5.0}, preprocess={"sigma_rate_dps": 0.02})
    )
    assert cfg.preprocess.sigma_w_saturated == math.radians(5.0) == cfg.preprocess.sigma_w_resampled
    assert cfg.preprocess.sigma_w == math.radians(0.02)


def _copy_with(tmp_path: Path, old: str, new: str) -> Path:
    src = SHIPPED["schiaparelli"]
    dst = tmp_path / "scenarios" / "my_entry.toml"
    dst.parent.mkdir(parents=True)
    shutil.copytree(src.parent.parent / "vehicles", tmp_path / "vehicles")
    text = src.read_text()
    assert text.count(old) == 1
    dst.write_text(text.replace(old, new).replace('name = "schiaparelli"', 'name = "my_entry"'))
    return dst


@pytest.mark.parametrize(
    "old, new, key, table, suggestion",
    [
        ("squint_deg = 20.0", "squint_dg = 20.0", "radar.squint_dg", "[radar]", "squint_deg"),
        ("mach_pdd = [2.0, 0.2]", "mach_pd = [2.0, 0.2]", "dispersion.rules.mach_pd", "[dispersion.rules]", "mach_pdd"),
        ("fsr_delay_s = 41.0", "fsr_delay = 41.0", "truth.fsr_delay", "[truth]", "fsr_delay_s"),
        ("[winds]", "[wind]", "wind", "top level", "winds"),
        (
            "resample_hz = 100.0",
            "resample_rate_hz = 100.0",
            "preprocess.resample_rate_hz",
            "[preprocess]",
            "resample_hz",
        ),
    ],
)
def test_misspelt_key_is_a_located_error(tmp_path, old, new, key, table, suggestion):
    path = _copy_with(tmp_path, old, new)
    with pytest.raises(ScenarioError) as ei:
        EntrySettings.from_scenario(load_scenario(path))
    e = ei.value
    assert e.file == str(path) and e.key == key
    assert table in str(e) and f"did you mean '{suggestion}'?" in str(e)


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("reconstruction.initial", "fusion", "use one of fused, dispersion, nominal"),
        ("dispersion.chunk_size", 0, "must be > 0"),
        ("dispersion.rules.h_end_m", [3000.0, -1.0], "half-width > 0"),
        ("scenario.epoch_utc", "yesterday", "epoch_utc"),
        ("sensors.imu.gyro_full_scale_dps", [1.0, 2.0], "list of 3"),
        ("preprocess.gap_factor", 0.5, "gap_factor"),
        ("synthetic.nominal_error.dx0", [1.0, 2.0], "9 numbers"),
        ("truth.wind_layers", [["a", 1, 2, 3, 4]], "wind_layers"),
        ("vehicle.file", "nowhere.toml", "file not found"),
        ("atmosphere.fill_temperature_shape", "cubic", "use one of model, linear"),
        # a negative 1σ: before the bound, numpy's "scale < 0" traceback from the synthetic writer
        ("sensors.imu.accel_noise_mps2", -0.001, "must be ≥ 0"),
        ("sensors.imu.gyro_noise_dps", -0.01, "must be ≥ 0"),
        ("sensors.radar.velocity_sigma_mps", -1.0, "must be ≥ 0"),
        ("sensors.radar.range_sigma_frac", -0.005, "must be ≥ 0"),
        # 1σ keys not named "sigma": the reconstruction's (the filter's process and initial noise;
        # > 0 for the initial 1σ and the rate inside the saturation window, which the gyro does not
        # measure), the IMU datasheet's, the dispersion's (> 0: a zero spread made the accepted
        # members' covariance singular, a LinAlgError naming no key) and the synthetic IMU's (a
        # negative one was numpy's "scale < 0" traceback)
        ("reconstruction.rate_dps", -0.02, "must be ≥ 0"),
        ("reconstruction.rate_pdd_dps", -0.5, "must be > 0"),
        ("preprocess.sigma_rate_saturated_dps", 0.0, "must be > 0"),
        ("preprocess.sigma_rate_resampled_dps", 0.0, "must be > 0"),
        ("reconstruction.accel_mps2", -0.01, "must be ≥ 0"),
        ("reconstruction.attitude_deg", 0.0, "must be > 0"),
        ("reconstruction.velocity_mps", -10.0, "must be > 0"),
        ("reconstruction.position_m", 0.0, "must be > 0"),
        ("reconstruction.imu_gyro_bias_dps", -0.01, "must be ≥ 0"),
        ("reconstruction.imu_accel_scale", -1e-4, "must be ≥ 0"),
        ("reconstruction.imu_accel_misalignment_rad", -1e-3, "must be ≥ 0"),
        ("dispersion.attitude_deg", 0.0, "must be > 0"),
        ("dispersion.velocity_mps", -1.0, "must be > 0"),
        ("dispersion.position_m", 0.0, "must be > 0"),
        ("dispersion.members", 0, "must be > 0"),
        ("sensors.imu.gyro_bias_dps", -0.01, "must be ≥ 0"),
        ("sensors.imu.accel_scale", -1e-4, "must be ≥ 0"),
        ("sensors.imu.gyro_misalignment_rad", -1e-3, "must be ≥ 0"),
        ("atmosphere.tolerance", 0.0, "must be > 0"),
        ("atmosphere.max_iterations", 0, "must be > 0"),
        # 0 neighbours left every saturated gyro run clipped, noted as "at the edge of the data"
        ("preprocess.rebuild_neighbours", 0, "must be > 0"),
    ],
)
def test_bad_values_are_located_errors(key, value, match):
    sc = load_scenario(SHIPPED["schiaparelli"]).with_overrides({key: value})
    with pytest.raises(ScenarioError, match=match) as ei:
        EntrySettings.from_scenario(sc)
    assert ei.value.key.split(".")[0] == key.split(".")[0]


def test_settings_reject_a_sensor_key_before_simulating(tmp_path):
    path = _copy_with(tmp_path, "velocity_sigma_mps = 1.0", "velocity_sigma = 1.0")
    with pytest.raises(ScenarioError, match=r"sensors.radar.velocity_sigma'.*did you mean 'velocity_sigma_mps'"):
        EntryProblem().settings(load_scenario(path))


def test_telemetry_paths_need_every_stream_radar_included(tmp_path):
    streams = {k: f"tm/{k}.csv" for k in ("gnc", "gnc_nav", "rda_slant_range", "events", "initial_state")}
    with pytest.raises(ScenarioError, match="rda_out") as ei:
        cfg = EntrySettings.from_scenario(minimal(tmp_path, telemetry=streams))
        telemetry_paths(cfg.telemetry, cfg.run.path)
    assert ei.value.key == "telemetry.rda_out" and "radar" in str(ei.value)


class _Stop(Exception):
    pass


def test_prepare_validation_reads_the_scenarios_telemetry_checks(tmp_path, monkeypatch):
    """The validation run reads the telemetry with the same checks as the pipeline
    (``[preprocess] quat_*_tol``, ``[sensors.radar] zero_filled_packets``)."""
    seen = {}

    def fake_read(paths, checks=None):
        seen["checks"] = checks
        raise _Stop

    monkeypatch.setattr(mc, "read_entry_telemetry", fake_read)
    (tmp_path / "initial_state.toml").write_text("")
    sc = load_scenario(SHIPPED["schiaparelli"]).with_overrides(
        {"preprocess.quat_error_tol": 2e-3, "preprocess.quat_warn_tol": 1e-5, "sensors.radar.zero_filled_packets": 3}
    )
    with pytest.raises(_Stop):
        mc.prepare_validation(EntrySettings.from_scenario(sc), {"initial_state": tmp_path / "initial_state.toml"})
    assert seen["checks"] == TelemetryChecks(quat_error_tol=2e-3, quat_warn_tol=1e-5, zero_filled_packets=3)


def test_terrain_correlation_inflates_only_the_slant_out_terrain_term(tmp_path):
    sc = minimal(
        tmp_path,
        radar={
            "slant_out_sigma_m": 40.0,
            "slant_range_sigma_m": 40.0,
            "terrain_sigma_m": 100.0,
            "terrain_correlation_s": 30.0,
        },
    )
    cfg = EntrySettings.from_scenario(sc)
    white = cfg.smoother_sigmas()
    assert white["slant_out"] == pytest.approx(math.hypot(40.0, 100.0))
    corr = cfg.smoother_sigmas(slant_out_dt_s=0.1)
    # 30 s of 10 Hz samples count as one: terrain variance × 300
    assert corr["slant_out"] == pytest.approx(math.hypot(40.0, 100.0 * math.sqrt(300.0)))
    assert corr["slant_range"] == white["slant_range"] and corr["velocity_out"] == white["velocity_out"]
    # a sample interval longer than the correlation time leaves the term white
    assert cfg.smoother_sigmas(slant_out_dt_s=60.0)["slant_out"] == pytest.approx(white["slant_out"])
