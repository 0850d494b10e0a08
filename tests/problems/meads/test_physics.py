"""MEADS physics cross-checks and unit checks (``problems/meads/physics.py``, ``telemetry.py``) on the
shipped scenario's synthetic telemetry: each fires on its mutation and stays OK on the clean data.

One module fixture synthesizes msl_meads once and reduces its pressures (least squares, no EKF: a
few seconds); each IMU mutation re-runs only the strapdown and the checks."""

from __future__ import annotations

import re
import shutil
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.io.scenario import ScenarioError
from workbench.io.telemetry import TelemetryError, read_telemetry, write_telemetry
from workbench.problems.meads import pipeline as md
from workbench.problems.meads.health import meads_health
from workbench.problems.meads.physics import (
    IMU_PRESSURE_ERROR_Z,
    accel_direction_checks,
    imu_vs_pressure_checks,
)
from workbench.problems.meads.telemetry import read_meads_telemetry
from workbench.problems.runner import prepare

FILES = {"pressures": "pressures.csv", "imu": "imu.csv", "initial_state": "initial_state.toml"}


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """The shipped msl_meads synthesized (its own seed), read and reduced up to the winds."""
    _, problem, settings = prepare("msl_meads")
    folder = tmp_path_factory.mktemp("meads_clean")
    syn = problem.synthesize(settings, folder, 11)
    paths = dict(syn.telemetry)
    est, vehicle = settings.estimator, settings.vehicle
    tel = read_meads_telemetry(paths, vehicle)
    nav = md.navigate(tel, vehicle)
    lag = md.invert_lag(tel.t_p, tel.p, vehicle, est.gamma, est.lag_inversion)
    first, fit, mask, failures, hi = md.fit_with_failures(tel.t_p, lag.p, vehicle, nav, est, list(tel.ports), "")
    air = md.AirDataStage(tel.t_p, first, fit, mask, tuple(failures), None, 1.0, hi)
    wind = md.winds_and_density(fit, nav, est, hi)
    above = np.nan_to_num(fit.qbar) >= est.min_qbar_pa
    return SimpleNamespace(
        paths=paths,
        settings=settings,
        tel=tel,
        nav=nav,
        air=air,
        wind=wind,
        above=above,
        truth=problem.load_truth(syn.truth),
        folder=folder,
    )


def _mutated(c, sensor: str, op: str, axes: tuple[int, ...], *, navigate: bool = True):
    """The telemetry with one IMU column mistake, and its strapdown (None unless ``navigate``)."""
    f, w = c.tel.f_B.copy(), c.tel.w_B.copy()
    a = f if sensor == "acc" else w
    if op == "scale":
        a *= axes[0]
    elif op == "swap":
        a[:, list(axes)] = a[:, list(axes[::-1])]
    else:
        a[:, axes[0]] *= -1.0
    tel = replace(c.tel, f_B=f, w_B=w)
    return tel, md.navigate(tel, c.settings.vehicle) if navigate else None


def _by_name(checks):
    return {ch.name: ch for ch in checks}


def test_clean_imu_agrees_with_the_pressures(clean):
    c = clean
    checks = _by_name(
        imu_vs_pressure_checks(c.tel, c.nav, c.air.fit, c.above, 30.0)
        + accel_direction_checks(c.tel, c.air.fit, c.above)
    )
    for n in ("physics.imu_vs_pressure_alpha", "physics.imu_vs_pressure_beta"):
        assert checks[n].status == "OK", checks[n]
        assert checks[n].value < 1.5 and checks[n].stat == {"kind": "upper"}
    assert checks["physics.accel_axis_deg"].status == "OK" and checks["physics.accel_axis_deg"].value < 10.0
    assert checks["physics.accel_flow_plane_deg"].status == "OK"
    assert checks["physics.accel_flow_plane_deg"].value < 15.0


@pytest.mark.parametrize(
    ("mutation", "check", "names"),
    [
        (
            ("acc", "swap", (1, 2)),
            "physics.imu_vs_pressure_beta",
            r"accelerometer axes y and z swapped.*'f_y \[.*'f_z \[",
        ),
        (("acc", "flip", (2,)), "physics.imu_vs_pressure_alpha", r"accelerometer axis z sign-flipped.*'f_z \["),
        (("acc", "flip", (0,)), "physics.imu_vs_pressure_alpha", r"accelerometer axis x sign-flipped.*'f_x \["),
        (("gyro", "flip", (1,)), "physics.imu_vs_pressure_beta", r"gyro axis y sign-flipped.*'w_y \["),
        (("gyro", "swap", (0, 2)), "physics.imu_vs_pressure_alpha", r"gyro axes x and z swapped.*'w_x \[.*'w_z \["),
        (("gyro", "scale", (np.pi / 180.0,)), "physics.imu_vs_pressure_alpha", r"rates in rad/s labelled as deg/s"),
    ],
)
def test_imu_axis_mistake_is_an_error_naming_the_axis(clean, mutation, check, names):
    """A swapped or sign-flipped IMU axis (each moves the EKF's α or β by many σ): the pressures'
    flow angles and the strapdown's disagree far beyond their σ; the message names the column."""
    tel, nav = _mutated(clean, *mutation)
    c = _by_name(imu_vs_pressure_checks(tel, nav, clean.air.fit, clean.above, 30.0))[check]
    assert c.status == "ERROR" and c.value > IMU_PRESSURE_ERROR_Z, c
    assert re.search(names, c.message), c.message
    assert "imu.csv" in c.message


@pytest.mark.parametrize(
    ("mutation", "check", "names"),
    [
        (("acc", "swap", (0, 1)), "physics.accel_axis_deg", r"axes x and y swapped"),
        (("acc", "swap", (0, 2)), "physics.accel_axis_deg", r"axes x and z swapped"),
        (("acc", "flip", (0,)), "physics.accel_axis_deg", r"axis x sign-flipped"),
        (("acc", "swap", (1, 2)), "physics.accel_flow_plane_deg", r"axes y and z swapped"),
    ],
)
def test_accelerometer_force_direction_names_the_axes(clean, mutation, check, names):
    """The drag of a blunt capsule reads along −x_B and its normal force in the flow's plane."""
    tel, _ = _mutated(clean, *mutation, navigate=False)
    c = _by_name(accel_direction_checks(tel, clean.air.fit, clean.above))[check]
    assert c.status == "ERROR", c
    assert re.search(names, c.message), c.message


def test_shipped_port_failure_is_a_note_not_a_warning(clean):
    """The planted stuck P5, detected and excluded, is a note of the report; no non-statistic check
    of the least squares' health is a WARNING."""
    c = clean
    est = c.settings.estimator
    h = meads_health(c.tel, c.nav, c.air, c.wind, est, wind_sigma_mps=c.settings.ekf.wind_sigma_mps)
    assert any(n.startswith("port P5 failed at 149.9 s (stuck), detected and excluded") for n in h["notes"])
    bad = [ch for ch in h["checks"] if ch["status"] != "OK" and not ch.get("stat")]
    assert not bad, bad
    fp = _by_name(SimpleNamespace(**ch) for ch in h["checks"])["data.failed_ports"]
    assert fp.status == "OK" and fp.value == 1
    # after its failure P5 has no residual: NaN, not a perfect zero
    k = c.air.failures[0].k
    assert np.all(np.isnan(c.air.residual_used[k:, c.tel.ports.index("P5")]))


def test_headline_at_peak_qbar_inside_its_3_sigma(clean):
    """The headline entries (least squares here, no EKF): α, β [rad] and q∞ [Pa] at peak q∞ with the
    fit's own 1σ; the clean run lands inside 3σ."""
    hl = md.headline_at_peak_qbar(SimpleNamespace(air=clean.air, ekf=()), clean.truth)
    assert [h["name"] for h in hl] == ["alpha_at_peak_qbar", "beta_at_peak_qbar", "qbar_at_peak_qbar"]
    assert [h["unit"] for h in hl] == ["rad", "rad", "Pa"]
    for h in hl:
        assert h["sigma"] > 0 and abs(h["error"]) <= 3 * h["sigma"], h


# ------------------------------------------------------------------------------------- units


def _copy(clean, tmp_path):
    d = tmp_path / "tel"
    d.mkdir()
    for k, f in FILES.items():
        shutil.copy(clean.paths[k], d / f)
    return {k: d / f for k, f in FILES.items()}


def _rewrite(path, *, time_factor=1.0, column=None, factor=1.0, sparse=()):
    t = read_telemetry(path, sparse=sparse)
    cols = {n: (t.channel(n) * (factor if n == column else 1.0), t.units[n]) for n in t.names}
    write_telemetry(path, t.time * time_factor, cols, sparse=sparse)


def test_one_port_a_unit_factor_off_is_refused_naming_column_and_unit(clean, tmp_path):
    paths = _copy(clean, tmp_path)
    _rewrite(paths["pressures"], column="P3", factor=1000.0, sparse=clean.tel.ports)
    with pytest.raises(TelemetryError, match=r"P3 \[Pa\].*1000.*kPa") as info:
        read_meads_telemetry(paths, clean.settings.vehicle)
    assert info.value.column == "P3 [Pa]" and info.value.row is not None
    _rewrite(paths["pressures"], column="P3", factor=1e-6, sparse=clean.tel.ports)  # now 1e-3 of the others
    with pytest.raises(TelemetryError, match=r"P3.*1000× smaller"):
        read_meads_telemetry(paths, clean.settings.vehicle)


@pytest.mark.parametrize("stream", ["pressures", "imu"])
def test_time_in_ms_is_refused_naming_the_file(clean, tmp_path, stream):
    paths = _copy(clean, tmp_path)
    _rewrite(paths[stream], time_factor=1000.0, sparse=clean.tel.ports if stream == "pressures" else ())
    with pytest.raises(TelemetryError, match=r"time column spans .* ms written as s") as info:
        read_meads_telemetry(paths, clean.settings.vehicle)
    assert info.value.file.endswith(FILES[stream]) and info.value.column == "time [s]"


@pytest.mark.parametrize(("key", "unit"), [("p_M_m", "km"), ("v_M_mps", "km/s")])
def test_initial_state_in_km_is_refused_naming_the_key(clean, tmp_path, key, unit):
    paths = _copy(clean, tmp_path)
    text = paths["initial_state"].read_text()

    def km(m):
        return f"{key} = [" + ", ".join(repr(float(x) / 1e3) for x in m.group(1).split(",")) + "]"

    paths["initial_state"].write_text(re.sub(rf"{key} = \[([^\]]*)\]", km, text))
    with pytest.raises(ScenarioError, match=rf"state\.{key}.*written in {unit}\?"):
        read_meads_telemetry(paths, clean.settings.vehicle)


def test_filter_divergence_is_a_numerical_failure_naming_the_stage(clean, monkeypatch):
    """An overflow inside the EKF ends as a LinAlgError (the runner's numerical failure, exit 4)
    naming the pass and the files, never a traceback of the kernel."""

    def boom(*_a, **_k):
        raise OverflowError("math range error")
        yield

    monkeypatch.setattr(md, "run_passes", boom)
    with pytest.raises(np.linalg.LinAlgError, match=r"EKF pass 1: the filter diverged.*pressures.csv"):
        for _ in md.reconstruct(clean.settings, clean.paths):
            pass


def test_a_later_pass_diverging_does_not_blame_the_inputs(clean, monkeypatch):
    """Pass 2 runs on the inputs pass 1 converged on: its divergence names the pass, the step and
    the filter's state (the EKF's diagnosis), not the files."""

    def second_fails(*_a, **_k):
        yield SimpleNamespace(index=1)
        raise np.linalg.LinAlgError("step 345 (t=43.125 s), measurement 'pressure': non-finite innovation")

    monkeypatch.setattr(md, "run_passes", second_fails)
    with pytest.raises(np.linalg.LinAlgError, match=r"EKF pass 2: the filter diverged.*step 345") as err:
        for _ in md.reconstruct(clean.settings, clean.paths):
            pass
    assert "pass 1 converged on the same" in str(err.value) and "pressures.csv" not in str(err.value)
