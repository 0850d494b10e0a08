"""Physics cross-checks of an imported rocket flight (issue 26, ``rocket_checks``): each check fires on
the mutated committed excerpt of flight 1 (``data/airbrakes_excerpt``) and stays OK on the clean one;
the input mistakes that used to end in a traceback end as located input errors (exit 3); an import
is written atomically.  The three real flights: ``test_post2_rocket_checks_slow.py``."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.cli import main
from workbench.estimation.health import ERROR, OK, WARNING, UnhealthyError
from workbench.io.scenario import load_scenario
from workbench.io.telemetry import TelemetryError
from workbench.problems.post2 import rocket, rocket_checks
from workbench.problems.post2.importers import airbrakes
from workbench.problems.post2.problem import Post2Problem

DATA = Path(__file__).resolve().parent / "data" / "airbrakes_excerpt"
LOG = DATA / "jackpot_launch_1_excerpt.csv"
META = DATA / "metadata.json"
ACC = ("raw_acceleration_x_gs", "raw_acceleration_y_gs", "raw_acceleration_z_gs")
TIME = "timestamp_seconds"
MAG = ("magnetic_field_x_microteslas", "magnetic_field_y_microteslas", "magnetic_field_z_microteslas")
GYRO = ("raw_angular_rate_x_deg_per_s", "raw_angular_rate_y_deg_per_s", "raw_angular_rate_z_deg_per_s")


def _lines() -> list[str]:
    return LOG.read_text(encoding="utf-8").splitlines()


def _map(lines: list[str], columns, fn) -> list[str]:
    """``lines`` with the values of ``columns`` in every data row replaced by ``fn(values)``."""
    idx = [lines[0].split(",").index(c) for c in columns]
    out = [lines[0]]
    for ln in lines[1:]:
        cells = ln.split(",")
        for i, v in zip(idx, fn([float(cells[i]) for i in idx]), strict=True):
            cells[i] = repr(float(v))
        out.append(",".join(cells))
    return out


def _log(tmp_path: Path, lines: list[str]) -> Path:
    p = tmp_path / LOG.name
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


def _meta(tmp_path: Path, edit=None) -> Path:
    m = json.loads(META.read_text(encoding="utf-8"))
    if edit is not None:
        edit(m[LOG.name])
    p = tmp_path / "metadata.json"
    p.write_text(json.dumps(m), encoding="utf-8")
    return p


def _import(tmp_path: Path, lines=None, edit=None, **kw) -> dict:
    """Import (allow_unhealthy) the excerpt, mutated; returns {check name: check} of flight.json."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    log = _log(tmp_path, lines if lines is not None else _lines())
    out = tmp_path / "flight"
    kw.setdefault("declination_deg", -10.5)
    kw.setdefault("inclination_deg", 64.0)
    airbrakes.import_flight(log, _meta(tmp_path, edit), out, allow_unhealthy=True, **kw)
    fl = json.loads((out / "flight.json").read_text(encoding="utf-8"))
    return {c["name"]: c for c in fl["health_checks"]["checks"]}


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return _import(tmp_path_factory.mktemp("clean"))


def test_clean_excerpt_passes_every_import_check(clean):
    bad = {n: c["message"] for n, c in clean.items() if c["status"] != OK}
    assert not bad
    for name in (
        "geometry.imu_axes",
        "geometry.pad_tilt",
        "geometry.accel_sign",
        "geometry.pitch_over",
        "physics.strapdown_apogee",
        "units.gyro",
        "geometry.landing_distance",
        "units.magnetometer",
        "geometry.site_inclination",
        "physics.site_temperature",
        "physics.wind",
        "physics.coast_drag_coefficient",
        "timing.observation_rate",
        "data.gap.coast",
        "data.gap.drogue_opening",
    ):
        assert name in clean, name
    assert clean["geometry.imu_axes"]["value"] < 5.0 and clean["units.gyro"]["value"] < 1.2


def test_an_error_check_refuses_the_import_and_writes_nothing(tmp_path):
    log = _log(tmp_path, _map(_lines(), ACC, lambda v: [v[2], v[1], v[0]]))
    out = tmp_path / "flight"
    with pytest.raises(UnhealthyError) as e:
        airbrakes.import_flight(log, META, out, flight=LOG.name)
    assert "geometry.imu_axes" in str(e.value) and "--allow-unhealthy" in str(e.value)
    assert not out.exists() and not list(tmp_path.glob(".flight.*.partial"))
    args = ["import", "airbrakes", str(log), "--metadata", str(META), "--out", str(out), "--flight", LOG.name]
    assert main(args) == 6 and not out.exists()


def test_accelerometer_axes_swapped_against_the_gyro(tmp_path):
    c = _import(tmp_path, _map(_lines(), ACC, lambda v: [v[2], v[1], v[0]]))["geometry.imu_axes"]
    assert c["status"] == ERROR and c["value"] > 45.0
    assert "swapped or sign-flipped" in c["message"] and "raw_acceleration_[xyz]_gs" in c["message"]


def test_one_accelerometer_axis_sign_flipped_against_the_gyro(tmp_path):
    c = _import(tmp_path, _map(_lines(), ACC, lambda v: [-v[0], v[1], v[2]]))["geometry.imu_axes"]
    assert c["status"] == ERROR and c["value"] > 60.0


def test_all_accelerometer_signs_flipped_against_the_flight_computers_attitude(tmp_path, clean):
    # −I commutes with every rotation: the gyro cannot see it; the flight computer's own attitude can
    assert clean["geometry.accel_sign"]["value"] > 0.5
    c = _import(tmp_path, _map(_lines(), ACC, lambda v: [-x for x in v]))["geometry.accel_sign"]
    assert c["status"] == ERROR and c["value"] < 0.0 and "look flipped" in c["message"]


def test_gyro_axes_a_mirror_of_the_accelerometers_turn_the_nose_the_wrong_way(tmp_path, clean):
    # two rate columns swapped keep the roll axis (imu_axes OK) and the decimated excerpt allows no
    # magnetometer fit; the strapdown's nose stays up while its velocity pitches over
    assert clean["geometry.pitch_over"]["value"] < rocket_checks.PITCH_OVER_BOUND_DEG
    checks = _import(tmp_path, _map(_lines(), GYRO, lambda v: [v[1], v[0], v[2]]))
    c = checks["geometry.pitch_over"]
    assert checks["geometry.imu_axes"]["status"] == OK
    assert c["status"] == ERROR and c["value"] > rocket_checks.PITCH_OVER_BOUND_DEG
    assert "mirror images" in c["message"] and "raw_angular_rate_[xyz]_deg_per_s" in c["message"]


def test_one_accelerometer_sign_flipped_overshoots_the_barometric_apogee(tmp_path, clean):
    assert abs(clean["physics.strapdown_apogee"]["value"]) < rocket_checks.STRAPDOWN_APOGEE_BOUND
    checks = _import(tmp_path, _map(_lines(), ACC, lambda v: [v[0], v[1], -v[2]]))
    c = checks["physics.strapdown_apogee"]
    assert c["status"] == ERROR and c["value"] > rocket_checks.STRAPDOWN_APOGEE_BOUND
    assert "raw_acceleration_[xyz]_gs" in c["message"]


def _sd(el_nose, el_v, h):
    n = len(el_v)
    return {
        "t": np.linspace(0.0, 10.0, n),
        "k": np.arange(n),
        "el_nose": np.asarray(el_nose, float),
        "el_v": np.asarray(el_v, float),
        "speed": np.full(n, 200.0),
        "h": np.asarray(h, float),
    }


def test_pitch_over_and_strapdown_apogee_checks_on_synthetic_histories():
    el_v = np.linspace(70.0, 10.0, 20)
    h = np.linspace(0.0, 1000.0, 20)
    assert rocket_checks.pitch_over_check(_sd(el_v + 5.0, el_v, h), 0.0, "x.csv").status == OK
    bad = rocket_checks.pitch_over_check(_sd(np.full(20, 70.0), el_v, h), 0.0, "x.csv")
    assert bad.status == ERROR and bad.value == pytest.approx(60.0)
    assert rocket_checks.pitch_over_check(None, 0.0, "x.csv").status == OK  # unchecked
    atm = SimpleNamespace(pressure=lambda hh: 101325.0 * np.exp(-np.asarray(hh) / 8400.0))
    p = 101325.0 * np.exp(-h / 8400.0)
    ok = rocket_checks.strapdown_apogee_check(_sd(el_v, el_v, 1.05 * h), p, atm, 0.0, "x.csv")
    assert ok.status == OK and ok.value == pytest.approx(0.05, abs=2e-3)
    bad = rocket_checks.strapdown_apogee_check(_sd(el_v, el_v, 1.2 * h), p, atm, 0.0, "x.csv")
    assert bad.status == ERROR and bad.value == pytest.approx(0.2, abs=2e-3)


def test_local_noise_widens_its_window_on_a_sparse_log():
    rng = np.random.default_rng(1)
    t_dense = np.arange(0.0, 4.0, 0.01)
    t_sparse = np.arange(0.0, 4.0, 0.25)  # 2 samples per ±0.25 s
    for t in (t_dense, t_sparse):
        v = 3.0 * t + rng.normal(0.0, 1.0, t.size)  # a trend plus unit noise
        s = rocket.local_noise(np.array([1.0, 2.0, 3.0]), t, v)
        assert np.all(s > 0.3) and np.all(s < 3.0)
    assert np.all(rocket.local_noise(np.array([2.0]), np.array([0.0, 4.0]), np.array([1.0, 2.0])) == 0.0)


def test_gyro_in_rad_per_s_labelled_deg_per_s(tmp_path):
    c = _import(tmp_path, _map(_lines(), GYRO, lambda v: [math.radians(x) for x in v]))["units.gyro"]
    assert c["status"] == ERROR and c["value"] > 20.0 and "rad/s" in c["message"]


@pytest.mark.parametrize("factor", [2.20462, 10.0])
def test_dry_mass_in_lb_or_ten_times_gives_an_implausible_drag_coefficient(tmp_path, factor):
    def edit(e):
        e["rocket"]["rocket_dry_mass_kg"] *= factor

    c = _import(tmp_path, edit=edit)["physics.coast_drag_coefficient"]
    assert c["status"] == ERROR and c["value"] > rocket_checks.ROCKET_CD_RANGE[1]
    assert "rocket_dry_mass_kg" in c["message"]


def test_site_temperature_in_fahrenheit(tmp_path):
    def edit(e):
        e["launch_site"]["air_temperature_celsius"] = 14.0 * 1.8 + 32.0

    c = _import(tmp_path, edit=edit)["physics.site_temperature"]
    assert c["status"] == ERROR and "°F" in c["message"] and "14.0 °C" in c["message"]


def test_launch_latitude_and_longitude_swapped(tmp_path):
    def swap(node):
        node["latitude"], node["longitude"] = node["longitude"], node["latitude"]

    c = _import(tmp_path, edit=lambda e: swap(e["launch_site"]["launch_coordinates"]))
    assert c["geometry.landing_distance"]["status"] == ERROR
    msg = c["geometry.landing_distance"]["message"]
    assert "swapped of launch_site.launch_coordinates (the declared inclination agrees with the corrected" in msg

    def landed(e):  # the landing's pair swapped: the launch site agrees with the declared inclination
        swap(e["flight_data"]["landed_coordinates"])

    msg = _import(tmp_path / "landed", edit=landed)["geometry.landing_distance"]["message"]
    assert "flight_data.landed_coordinates (the launch site agrees" in msg and "swapped" in msg

    def west(e):  # the landing's longitude written without its sign (W as +)
        e["flight_data"]["landed_coordinates"]["longitude"] *= -1.0

    c = _import(tmp_path / "west", edit=west)
    msg = c["geometry.landing_distance"]["message"]
    assert "the longitude's sign of " in msg and "landed_coordinates" in msg

    def both(e):  # the landing swapped too: the distance agrees, the declared inclination does not
        swap(e["launch_site"]["launch_coordinates"])
        swap(e["flight_data"]["landed_coordinates"])

    c = _import(tmp_path / "both", edit=both)
    assert c["geometry.landing_distance"]["status"] == OK
    assert c["geometry.site_inclination"]["status"] == ERROR
    assert "site latitude and longitude may be swapped" in c["geometry.site_inclination"]["message"]


def test_dipole_field_at_the_sites():
    # IGRF-13 degree 1: inclination within 3 deg of the WMM values the tests use for the three sites
    # (tests/support/flight_data.py), magnitude within the dipole's 30 %; the southern hemisphere dips up
    for (lat, lon), inc in (((35.176, -76.828), 64.0), ((38.376, -79.607), 66.0), ((34.894, -86.617), 62.0)):
        b, i = rocket_checks.dipole_field(lat, lon)
        assert abs(i - inc) < 3.0 and 35e-6 < b < 65e-6
    b, i = rocket_checks.dipole_field(-76.8, 35.2)
    assert i < -60.0
    _, i_eq = rocket_checks.dipole_field(9.0, -72.7 + 180.0)  # near the dipole equator: small dip
    assert abs(i_eq) < 20.0


def _pad(dip):
    return {"magnetic_field_uT": 47.0, "magnetometer_dip_deg": dip, "magnetometer_alignment": {"fit_accepted": True}}


def test_aligned_magnetometer_dip_with_the_wrong_sign_names_the_accelerometer():
    meta = airbrakes.read_metadata(META, LOG.name)
    ok = {c.name: c for c in rocket_checks.site_checks(meta, _pad(62.3), 64.0, LOG.name)}
    assert ok["physics.magnetic_dip"].status == OK and ok["units.magnetometer"].status == OK
    bad = {c.name: c for c in rocket_checks.site_checks(meta, _pad(-62.3), 64.0, LOG.name)}
    c = bad["physics.magnetic_dip"]
    assert c.status == ERROR and "accelerometer's axes look sign-flipped" in c.message
    gauss = {c.name: c for c in rocket_checks.site_checks(meta, {"magnetic_field_uT": 0.47}, None, LOG.name)}
    assert gauss["units.magnetometer"].status == WARNING and "gauss" in gauss["units.magnetometer"].message


def test_observation_rate_above_the_packet_rate():
    assert rocket_checks.rate_check(10.0, 90.0, "f.csv").status == OK
    assert rocket_checks.rate_check(10.0, 8.25, "f.csv").status == OK  # the decimated excerpt
    c = rocket_checks.rate_check(200.0, 90.0, "f.csv")
    assert c.status == ERROR and "packet rate" in c.message and c.value == pytest.approx(90.0)
    assert rocket_checks.rate_check(15.0, 90.0, "f.csv").status == WARNING


def test_pad_tilt_against_the_launch_rod_angle(clean):
    assert abs(clean["geometry.pad_tilt"]["value"]) < 1.0  # 19.6 deg seen vs the 20 deg rod
    c = rocket_checks.pad_tilt_check(19.6, math.radians(20.0))  # the rod angle written in radians
    assert c.status == WARNING and "launch_rod_angle" in c.message


def test_wind_beyond_any_launch_day_is_a_warning():
    meta = airbrakes.read_metadata(META, LOG.name)
    board = meta.temperature + 15.0
    assert {c.name: c.status for c in rocket_checks.weather_checks(meta, board)}["physics.wind"] == OK
    windy = type(meta)(**{**meta.__dict__, "wind_speed": 30.0})
    assert {c.name: c.status for c in rocket_checks.weather_checks(windy, board)}["physics.wind"] == WARNING


def _cut_coast(lines: list[str], n: int) -> list[str]:
    coast = [i for i, ln in enumerate(lines) if ln.startswith("C,")]
    cut = set(coast[len(coast) // 2 : len(coast) // 2 + n])
    return [ln for i, ln in enumerate(lines) if i not in cut]


def test_a_gap_in_the_coast_makes_the_apogee_undefined(tmp_path):
    c = _import(tmp_path, _cut_coast(_lines(), 8))["data.gap.coast"]  # ~1 s of the 8 Hz excerpt
    assert c["status"] == ERROR and "undefined" in c["message"] and "row" in c["message"]
    fl = json.loads((tmp_path / "flight" / "flight.json").read_text(encoding="utf-8"))
    assert fl["health_checks"]["undefined"] == ["coast"]
    # the run: the import's ERROR is in its verdict, and the apogee score is undefined, not a number
    toml = tmp_path / "flight" / f"{LOG.stem}.toml"
    result, s = rocket.run_flight(Post2Problem().settings(load_scenario(toml)))
    h = result.summary["health"]
    assert h["verdict"] == ERROR and any(x["name"] == "data.gap.coast" for x in h["checks"])
    assert s["apogee"]["reconstructed_m"] is None and "undefined" in s["apogee"]
    # one missing row is a WARNING, nothing undefined
    c = _import(tmp_path / "one", _cut_coast(_lines(), 1))["data.gap.coast"]
    assert c["status"] in (OK, WARNING)


def test_a_mass_in_lb_pins_the_drag_multiplier_at_its_bound_in_the_run(tmp_path):
    def edit(e):
        e["rocket"]["rocket_dry_mass_kg"] *= 2.20462

    _import(tmp_path, edit=edit)
    toml = tmp_path / "flight" / f"{LOG.stem}.toml"
    result, _ = rocket.run_flight(Post2Problem().settings(load_scenario(toml)))
    checks = {c["name"]: c for c in result.summary["health"]["checks"]}
    assert checks["physics.bound.ca_multiplier"]["status"] == ERROR
    assert "rocket_dry_mass_kg" in checks["physics.bound.ca_multiplier"]["message"]
    assert checks["physics.bound.drogue_drag_area"]["status"] == OK


def test_parameter_ending_at_its_bound_is_an_error(tmp_path):
    (tmp_path / "flight.json").write_text(json.dumps({"health_checks": {"checks": []}}), encoding="utf-8")
    spec = SimpleNamespace(name="ca_multiplier", bounds=(0.2, 6.0), value=5.5, sigma=1.4)
    cfg = SimpleNamespace(run=SimpleNamespace(path=tmp_path / "f.toml"), states=(spec,))
    at = {"ca_multiplier": {"value": np.array([[3.0], [5.999]])}}
    checks, _ = rocket_checks.run_checks(cfg, at)
    assert checks[0].status == ERROR and "upper bound" in checks[0].message and "lb" in checks[0].message
    inside = {"ca_multiplier": {"value": np.array([[3.0], [2.0]])}}
    assert rocket_checks.run_checks(cfg, inside)[0][0].status == OK
    # another post2 problem (no flight.json beside it): a bound may be a parametrisation, so an
    # estimate at it is an error only far from its prior
    other = SimpleNamespace(run=SimpleNamespace(path=tmp_path / "x" / "f.toml"), states=(spec,))
    near, notes = rocket_checks.run_checks(other, at)
    assert [c.status for c in near] == [OK] and notes == []
    far = SimpleNamespace(**{**vars(spec), "value": 1.0, "sigma": 0.2})
    (c,), _ = rocket_checks.run_checks(SimpleNamespace(run=other.run, states=(far,)), at)
    assert c.status == ERROR and "prior σ" in c.message


@pytest.mark.parametrize(
    ("mutation", "column", "words"),
    [
        (lambda ls: _map(ls, ACC, lambda v: [x * 9.80665 for x in v]), "raw_acceleration_x_gs", "m/s²"),
        (lambda ls: _map(ls, ACC, lambda v: [x * 1000.0 for x in v]), "raw_acceleration_x_gs", "mg"),
        (lambda ls: _map(ls, (TIME,), lambda v: [x * 1e3 for x in v]), TIME, "milliseconds"),
        (lambda ls: [ln for ln in ls if ln[:2] not in ("F,", "L,")], "state_letter", "no phase 'F'"),
        (lambda ls: _map(ls, MAG, lambda v: [0.0, 0.0, 0.0]), MAG[0], "dead or missing magnetometer"),
        (lambda ls: _map(ls, ACC, lambda v: [v[0], 0.0, v[2]]), ACC[0], "y +0"),
        (lambda ls: _map(ls, GYRO, lambda v: [v[0], v[1] * 1000.0, v[2]]), GYRO[1], "gyro range"),
    ],
    ids=["accel_m_s2", "accel_mg", "time_ms", "ends_in_coast", "magnetometer_zero", "accel_axis_dead", "rate_x1000"],
)
def test_former_tracebacks_are_located_input_errors(tmp_path, capsys, mutation, column, words):
    log = _log(tmp_path, mutation(_lines()))
    with pytest.raises(TelemetryError) as e:
        airbrakes.import_flight(log, META, tmp_path / "flight", flight=LOG.name)
    assert e.value.column == column and LOG.name in str(e.value)
    assert words in str(e.value)
    args = ["import", "airbrakes", str(log), "--metadata", str(META), "--out", str(tmp_path / "flight")]
    assert main([*args, "--flight", LOG.name]) == 3 and "input error" in capsys.readouterr().err
    assert not (tmp_path / "flight").exists()


def test_a_byte_order_mark_is_read(tmp_path):
    lines = _lines()
    log = _log(tmp_path, ["\ufeff" + lines[0], *lines[1:]])
    assert airbrakes.read_log(log).t.size == len(lines) - 1


def test_import_is_atomic(tmp_path, monkeypatch):
    def boom(*a, **k):
        raise ZeroDivisionError("injected")

    monkeypatch.setattr(rocket, "problem_file", boom)
    with pytest.raises(ZeroDivisionError):
        airbrakes.import_flight(LOG, META, tmp_path / "flight", declination_deg=-10.5)
    assert list(tmp_path.iterdir()) == []  # neither the folder nor a partial one
    monkeypatch.undo()
    # a partial folder of an import killed outright (its process gone) is removed by the next import
    (tmp_path / ".flight.999999999.partial").mkdir()
    # into an existing folder: the files replaced, others kept
    (tmp_path / "flight").mkdir()
    (tmp_path / "flight" / "notes.txt").write_text("mine", encoding="utf-8")
    airbrakes.import_flight(LOG, META, tmp_path / "flight", declination_deg=-10.5)
    names = {p.name for p in (tmp_path / "flight").iterdir()}
    assert "notes.txt" in names and "flight.json" in names and len(list(tmp_path.iterdir())) == 1


def test_gyro_magnetometer_check_tells_a_mirrored_gyro_from_a_poor_fit():
    al = {"fit_rms_uT": 0.9, "field_uT": 51.0, "fit_accepted": True, "mirrored_gyro_fit_rms_uT": None}
    assert rocket_checks.gyro_magnetometer_check({"magnetometer_alignment": al}, "f.csv").status == OK
    bad = {**al, "fit_rms_uT": 7.8, "fit_accepted": False, "mirrored_gyro_fit_rms_uT": 0.94}
    c = rocket_checks.gyro_magnetometer_check({"magnetometer_alignment": bad}, "f.csv")
    assert c.status == ERROR and "mirror image" in c.message and "f.csv" in c.message
    poor = {**bad, "mirrored_gyro_fit_rms_uT": 8.0}
    assert rocket_checks.gyro_magnetometer_check({"magnetometer_alignment": poor}, "f.csv").status == WARNING
    assert rocket_checks.gyro_magnetometer_check({"magnetometer_alignment": None}, "f.csv") is None


def test_declared_motor_against_the_boost_names_a_mass_in_lb_and_a_wrong_motor(tmp_path, clean):
    assert clean["physics.motor"]["status"] == OK and 0.7 < clean["physics.motor"]["value"] < 1.1

    def lb(e):
        e["rocket"]["rocket_dry_mass_kg"] *= 2.20462

    c = _import(tmp_path / "lb", edit=lb)["physics.motor"]
    assert c["status"] == ERROR and "rocket_dry_mass_kg" in c["message"] and "lb" in c["message"]

    def k_motor(e):
        e["rocket"]["motor"] = "K535W"

    c = _import(tmp_path / "k", edit=k_motor)["physics.motor"]
    assert c["status"] == ERROR and "K535W" in c["message"] and "class K" in c["message"]

    def unknown(e):
        e["rocket"]["motor"] = "homemade"

    assert "physics.motor" not in _import(tmp_path / "u", edit=unknown)
