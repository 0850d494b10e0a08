"""The column-mapped importer (``workbench import csv --mapping MAP.toml``, issue #27 item 1) on the
committed excerpt of flight 1 (``data/airbrakes_excerpt``, MIT licence) re-expressed by the test into
another flight computer's layout: other column names, time in ms, accelerations in m/s², rates in
rad/s, field in nT, pressure in hPa, the IMU and the barometer (+ board temperature) in separate files
at different rates, the log's axes a permutation with a sign flip of the body axes declared in the
mapping.  Its run's apogee agrees with ``workbench import airbrakes``'s within that run's 1σ, with
and without the magnetometer (then the heading is untrusted), with the phases detected or read from a
phase column; every bad input is a located error and writes nothing."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.estimation.health import UnhealthyError
from workbench.io.scenario import ScenarioError, load_scenario
from workbench.io.telemetry import TelemetryError
from workbench.problems.base import RunOptions
from workbench.problems.post2 import rocket
from workbench.problems.post2.importers import mapped
from workbench.problems.post2.problem import Post2Problem

DATA = Path(__file__).resolve().parent / "data" / "airbrakes_excerpt"
LOG = DATA / "jackpot_launch_1_excerpt.csv"
META = DATA / "metadata.json"
G0 = 9.80665


def remap(dst: Path, *, mag: bool = True, letters: bool = False, edit=None) -> Path:
    """Write the excerpt in another layout into ``dst``: ``imu.csv`` (time in ms; the log's axes a, b, c
    are the body's y, −x, z), ``baro.csv`` (every other row, s, hPa, °C) and ``map.toml``; ``edit(text)``
    changes the mapping's text.  Returns the mapping file."""
    dst.mkdir(parents=True, exist_ok=True)
    rows = list(csv.DictReader(LOG.open(encoding="utf-8")))
    with (dst / "imu.csv").open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        hdr = ["t_ms", "acc_a", "acc_b", "acc_c", "gyr_a", "gyr_b", "gyr_c"]
        w.writerow(hdr + (["mag_a", "mag_b", "mag_c"] if mag else []) + (["phase"] if letters else []))
        for r in rows:
            ax, ay, az = (float(r[f"raw_acceleration_{c}_gs"]) * G0 for c in "xyz")
            gx, gy, gz = (math.radians(float(r[f"raw_angular_rate_{c}_deg_per_s"])) for c in "xyz")
            line = [float(r["timestamp_seconds"]) * 1000.0, ay, -ax, az, gy, -gx, gz]
            if mag:
                mx, my, mz = (float(r[f"magnetic_field_{c}_microteslas"]) * 1000.0 for c in "xyz")
                line += [my, -mx, mz]
            w.writerow([repr(v) for v in line] + ([r["state_letter"]] if letters else []))
    with (dst / "baro.csv").open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["time", "p_hpa", "temp_c"])
        for r in rows[::2]:
            w.writerow([r["timestamp_seconds"], repr(float(r["pressure_pascals"]) / 100.0), r["temperature_celsius"]])
    meta = json.loads(META.read_text(encoding="utf-8"))[LOG.name]
    site, rocket = meta["launch_site"], meta["rocket"]
    text = f"""[flight]
name = "remapped"

[site]
lat_deg = {site["launch_coordinates"]["latitude"]}
lon_deg = {site["launch_coordinates"]["longitude"]}
qnh_hpa = {site["air_pressure_mb"]}
temperature_degC = {site["air_temperature_celsius"]}
wind_speed_m_s = {site["wind_speed_kmh"] / 3.6}
wind_from_deg = 0.0
launch_rod_angle_deg = {site["launch_rod_angle"]}
declination_deg = -10.5
{"inclination_deg = 64.0" if mag else ""}

[rocket]
dry_mass_kg = {rocket["rocket_dry_mass_kg"]}
cd = {rocket["rocket_Cd"]}
ref_area_m2 = {rocket["rocket_cross_sectional_area_m2"]}
motor = "{rocket["motor"]}"

[files.imu]
path = "imu.csv"
time = "t_ms"
time_unit = "ms"

[files.baro]
path = "baro.csv"
time = "time"

[accelerometer]
file = "imu"
unit = "m/s^2"
body_x = "-acc_b"
body_y = "acc_a"
body_z = "acc_c"

[gyro]
file = "imu"
unit = "rad/s"
body_x = "-gyr_b"
body_y = "gyr_a"
body_z = "gyr_c"

[barometer]
file = "baro"
column = "p_hpa"
unit = "hPa"

[temperature]
file = "baro"
column = "temp_c"
unit = "degC"
"""
    if mag:
        text += '\n[magnetometer]\nfile = "imu"\nunit = "nT"\nbody_x = "-mag_b"\nbody_y = "mag_a"\nbody_z = "mag_c"\n'
    if letters:
        text += '\n[phases]\nfile = "imu"\ncolumn = "phase"\n'
    if edit is not None:
        text = edit(text)
    (dst / "map.toml").write_text(text, encoding="utf-8")
    return dst / "map.toml"


def _run(toml: Path, out: Path) -> dict:
    assert main(["run", str(toml), "--out", str(out), "--allow-unhealthy", "--quiet"]) == 0
    return json.loads((out / f"{toml.stem}.summary.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def airbrakes_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("airbrakes")
    args = ["import", "airbrakes", str(LOG), "--metadata", str(META), "--out", str(out / "flight")]
    assert main([*args, "--declination-deg", "-10.5", "--inclination-deg", "64"]) == 0
    return _run(out / "flight" / "jackpot_launch_1_excerpt.toml", out / "rec")


def _import_and_run(tmp: Path, **kw) -> tuple[Path, dict]:
    mp = remap(tmp / "log", **kw)
    assert main(["import", "csv", "--mapping", str(mp), "--out", str(tmp / "flight"), "--allow-unhealthy"]) == 0
    toml = tmp / "flight" / "remapped.toml"
    return toml, _run(toml, tmp / "rec")


@pytest.mark.parametrize("letters", [False, True], ids=["phases-detected", "phase-column"])
def test_remapped_excerpt_gives_the_airbrakes_apogee(airbrakes_run, tmp_path, letters):
    toml, s = _import_and_run(tmp_path, letters=letters)
    ref = airbrakes_run["rocket"]["apogee"]
    a = s["rocket"]["apogee"]
    assert abs(a["altitude_m"] - ref["altitude_m"]) <= ref["sigma_m"], (a, ref)
    assert a["sigma_m"] == pytest.approx(ref["sigma_m"], rel=0.2)
    fl = json.loads((toml.parent / "flight.json").read_text(encoding="utf-8"))
    src = fl["source"]
    assert src["phases_source"]["burnout"] == ("column" if letters else "detected")
    assert src["columns"]["accelerometer"]["columns"] == ["-acc_b", "acc_a", "acc_c"]
    assert set(src["files"]) == {"imu", "baro"}
    # the detected burnout is FIRM's coast letter (2.541 s after its motor letter) to the sample
    assert fl["t_start_s"] + fl["t_launch_log_s"] == pytest.approx(2.7826505700002144 + 1209.46567625, abs=0.13)
    assert not (toml.parent / "remapped_landing.toml").exists()  # no landed coordinates in the mapping


def test_without_the_magnetometer_the_heading_is_an_untrusted_prior(airbrakes_run, tmp_path):
    toml, s = _import_and_run(tmp_path, mag=False)
    ref = airbrakes_run["rocket"]["apogee"]
    assert abs(s["rocket"]["apogee"]["altitude_m"] - ref["altitude_m"]) <= ref["sigma_m"]
    assert "heading_trusted = false" in toml.read_text(encoding="utf-8")
    assert s["rocket"]["landing"]["heading_trusted"] is False
    pad = json.loads((toml.parent / "flight.json").read_text(encoding="utf-8"))["pad"]
    assert pad["magnetometer"] is None and pad["pad_heading_prior_deg"] is None
    assert pad["heading_sigma_deg"] == pytest.approx(60.0)
    assert "mag.x" not in (toml.parent / "imu.csv").read_text(encoding="utf-8").splitlines()[-1]


def test_a_declared_heading_prior_sets_its_sigma(tmp_path):
    def edit(text):
        return text.replace("declination_deg = -10.5", "pad_heading_deg = 30.0\npad_heading_sigma_deg = 20.0")

    mp = remap(tmp_path / "log", mag=False, edit=edit)
    toml = mapped.import_mapped(mp, tmp_path / "flight", allow_unhealthy=True)
    pad = json.loads((toml.parent / "flight.json").read_text(encoding="utf-8"))["pad"]
    assert pad["pad_heading_prior_deg"] == 30.0 and pad["heading_sigma_deg"] == pytest.approx(20.0)
    assert not pad["magnetometer_heading_trusted"]


def test_a_wrong_axis_sign_in_the_mapping_is_caught(tmp_path):
    """The axis map is applied: the accelerometer's x declared without its sign (the gyro's right)
    puts the boost's axis off the gyro's roll axis, which the import's cross-check refuses."""
    mp = remap(tmp_path / "log", edit=lambda t: t.replace('body_x = "-acc_b"', 'body_x = "acc_b"'))
    with pytest.raises(UnhealthyError, match="geometry.imu_axes") as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert not (tmp_path / "flight").exists()
    # the message names the mapping's columns, not the FIRM log's
    assert "acc_b, acc_a, acc_c ([accelerometer] of map.toml" in str(e.value) and "raw_acc" not in str(e.value)


def test_a_mass_in_pounds_is_named_by_its_mapping_key(tmp_path):
    mp = remap(tmp_path / "log", edit=lambda t: t.replace("dry_mass_kg = 16.848", "dry_mass_kg = 37.14"))
    with pytest.raises(UnhealthyError) as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert "[rocket] dry_mass_kg" in str(e.value) and "rocket_dry_mass_kg" not in str(e.value)


def _refused(tmp_path, mp: Path, capsys) -> str:
    out = tmp_path / "flight"
    assert main(["import", "csv", "--mapping", str(mp), "--out", str(out)]) == 3
    assert not out.exists() and not list(tmp_path.glob(".flight.*"))  # nothing written
    return capsys.readouterr().err


def test_a_wrong_unit_is_located(tmp_path, capsys):
    mp = remap(tmp_path / "log", edit=lambda t: t.replace('unit = "m/s^2"', 'unit = "m/s/s"'))
    with pytest.raises(TelemetryError) as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert e.value.file.endswith("imu.csv") and e.value.column == "acc_b" and e.value.line == 1
    assert "accelerometer.unit" in str(e.value) and "m/s^2" in str(e.value)
    assert "'m/s/s'" in _refused(tmp_path, mp, capsys)
    # a known unit of the wrong kind too
    mp = remap(tmp_path / "log", edit=lambda t: t.replace('unit = "rad/s"', 'unit = "hPa"'))
    with pytest.raises(TelemetryError, match="not a known angular rate unit") as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert e.value.column == "gyr_b"


def test_a_missing_column_is_located(tmp_path, capsys):
    mp = remap(tmp_path / "log", edit=lambda t: t.replace('column = "p_hpa"', 'column = "p_mbar"'))
    with pytest.raises(TelemetryError) as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert e.value.file.endswith("baro.csv") and e.value.column == "p_mbar" and e.value.line == 1
    assert "is missing" in str(e.value)
    _refused(tmp_path, mp, capsys)


def test_a_non_monotonic_time_is_located(tmp_path, capsys):
    mp = remap(tmp_path / "log")
    lines = (mp.parent / "baro.csv").read_text(encoding="utf-8").splitlines()
    cells = lines[40].split(",")
    cells[0] = lines[38].split(",")[0]  # data row 40 goes back to row 38's time
    lines[40] = ",".join(cells)
    (mp.parent / "baro.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(TelemetryError) as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert e.value.file.endswith("baro.csv") and e.value.column == "time" and e.value.row == 40
    assert "goes backwards" in str(e.value)
    _refused(tmp_path, mp, capsys)


def test_text_in_a_number_is_located(tmp_path):
    mp = remap(tmp_path / "log")
    lines = (mp.parent / "imu.csv").read_text(encoding="utf-8").splitlines()
    cells = lines[7].split(",")
    cells[3] = "n/a"
    lines[7] = ",".join(cells)
    (mp.parent / "imu.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(TelemetryError) as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert (e.value.column, e.value.row) == ("acc_c", 7)


def test_mapping_errors_name_the_key(tmp_path):
    mp = remap(tmp_path / "log", edit=lambda t: t.replace("dry_mass_kg", "dry_mas_kg"))
    with pytest.raises(ScenarioError, match="did you mean 'dry_mass_kg'"):
        mapped.read_mapping(mp)
    mp = remap(
        tmp_path / "log", edit=lambda t: t.replace('file = "baro"\ncolumn = "p_hpa"', 'file = "bar"\ncolumn = "p_hpa"')
    )
    with pytest.raises(ScenarioError) as e:
        mapped.read_mapping(mp)
    assert e.value.key == "barometer.file"
    mp = remap(tmp_path / "log", edit=lambda t: t.replace("qnh_hpa", "pad_altitude_m = 3.0\nqnh_hpa"))
    with pytest.raises(ScenarioError, match="exactly one"):
        mapped.read_mapping(mp)


def test_a_phase_time_in_the_mapping_overrides_the_detection(tmp_path):
    mp = remap(tmp_path / "log", edit=lambda t: t + "\n[phases]\nburnout_s = 1211.8\n")
    toml = mapped.import_mapped(mp, tmp_path / "flight", allow_unhealthy=True)
    fl = json.loads((toml.parent / "flight.json").read_text(encoding="utf-8"))
    assert fl["source"]["phases_source"]["burnout"] == "mapping"
    assert fl["t_start_s"] + fl["t_launch_log_s"] == pytest.approx(1211.8 + 0.3, abs=0.13)  # + the tail-off


def test_an_unknown_phase_value_is_located(tmp_path):
    mp = remap(tmp_path / "log", letters=True)
    lines = (mp.parent / "imu.csv").read_text(encoding="utf-8").splitlines()
    lines[12] = lines[12][: lines[12].rindex(",")] + ",X"
    (mp.parent / "imu.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(TelemetryError) as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert (e.value.column, e.value.row) == ("phase", 12) and "'X' is not a phase value" in str(e.value)


def _toml_blocks(path: Path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    return [b.split("```", 1)[0] for b in text.split("```toml\n")[1:]]


def test_the_tutorial_mapping_imports_and_the_formats_example_validates(tmp_path):
    """The documentation's mappings stay valid: the tutorial's imports the re-expressed excerpt (the
    files it describes), FORMATS.md's example passes the schema and its cross-references."""
    root = Path(__file__).resolve().parents[3]
    (tut,) = _toml_blocks(root / "docs" / "TUTORIAL_FLIGHT.md")
    mp = remap(tmp_path / "log", mag=False, edit=lambda _: tut)
    toml = mapped.import_mapped(mp, tmp_path / "flight", allow_unhealthy=True)
    assert toml.name == "my_flight.toml"
    formats = root / "workbench" / "io" / "FORMATS.md"
    examples = [b for b in _toml_blocks(formats) if "[accelerometer]" in b]
    assert len(examples) == 1
    (tmp_path / "example.toml").write_text(examples[0], encoding="utf-8")
    m = mapped.read_mapping(tmp_path / "example.toml")
    assert m.data["site"]["pad_heading_deg"] == 90.0 and set(m.files) == {"imu", "baro"}


def test_accelerations_declared_in_the_wrong_unit_are_refused(tmp_path):
    mp = remap(tmp_path / "log", edit=lambda t: t.replace('unit = "m/s^2"', 'unit = "g"'))
    with pytest.raises(TelemetryError, match="look like m/s², not g") as e:
        mapped.import_mapped(mp, tmp_path / "flight")
    assert e.value.column == "acc_b" and e.value.file.endswith("imu.csv")


def test_the_firm_layout_through_import_csv_is_import_airbrakes(tmp_path):
    """``import airbrakes`` reads its log through the generic reader with a built-in mapping
    (``airbrakes.FIRM_LAYOUT``): that mapping written out as a file and imported with ``import csv``
    gives the same problem file, to the digit, and the same telemetry."""
    from firm_mapping import firm_mapping

    from workbench.problems.post2.importers import airbrakes

    a = airbrakes.import_flight(LOG, META, tmp_path / "a", declination_deg=-10.5, inclination_deg=64.0)
    mp = firm_mapping(LOG, META, tmp_path / "map", declination_deg=-10.5, inclination_deg=64.0)
    c = mapped.import_mapped(mp, tmp_path / "c")
    assert c.name == a.name
    # the flight's name: the metadata entry's ("<log>.csv") for airbrakes, the mapping's for csv
    assert c.read_text(encoding="utf-8") == a.read_text(encoding="utf-8").replace(LOG.name, LOG.stem)
    for f in ("pressure.csv", "accel.csv", "accel_weights.csv", "imu.csv", "reference.csv", "landing.csv"):
        assert (c.parent / f).read_bytes() == (a.parent / f).read_bytes(), f
    ja, jc = (json.loads((x.parent / "flight.json").read_text(encoding="utf-8")) for x in (a, c))
    assert jc["pad"] == ja["pad"] and jc["burnout"] == ja["burnout"]
    assert [x["status"] for x in jc["health_checks"]["checks"]] == [x["status"] for x in ja["health_checks"]["checks"]]


def test_a_gap_in_the_barometer_file_is_reported_and_not_observed(tmp_path):
    """The barometer's file loses 2 s of the coast: the gap is listed (its file, its row; the logger's
    pause on the pad is another), and no pressure observation lies inside it (the interpolated values
    there are not measurements)."""
    mp = remap(tmp_path / "log")
    lines = (mp.parent / "baro.csv").read_text(encoding="utf-8").splitlines()
    t_launch = 1209.46567625
    cut = [i for i, ln in enumerate(lines[1:], 1) if 6.0 < float(ln.split(",")[0]) - t_launch < 8.0]
    assert len(cut) >= 6
    (mp.parent / "baro.csv").write_text("\n".join(ln for i, ln in enumerate(lines) if i not in cut) + "\n")
    toml = mapped.import_mapped(mp, tmp_path / "flight", allow_unhealthy=True)
    fl = json.loads((toml.parent / "flight.json").read_text(encoding="utf-8"))
    gaps = [g for g in fl["source"]["gaps"] if g["file"] == "baro" and g["t_a_s"] > t_launch]
    assert len(gaps) == 1 and gaps[0]["row"] == cut[0]
    a, b = gaps[0]["t_a_s"] - fl["t_launch_log_s"], gaps[0]["t_b_s"] - fl["t_launch_log_s"]
    tp = [float(ln.split(",")[0]) for ln in (toml.parent / "pressure.csv").read_text().splitlines() if ln[:1].isdigit()]
    assert tp and not [x for x in tp if a + 1e-6 < x < b - 1e-6]
    assert any(g["dt_s"] == pytest.approx(b - a) for g in fl["gaps"])  # and in the import's gap list


def test_site_temperature_sigma_becomes_the_barometer_scale_consider_parameter(tmp_path):
    """``[site] temperature_sigma_K`` (issue 27 item 3): the import writes ``baro_scale`` as a consider
    parameter of 1σ σ_T / T_site, so the run's σ carries the column temperature it does not know."""
    mp = remap(
        tmp_path / "log",
        edit=lambda t: t.replace("wind_from_deg = 0.0", "wind_from_deg = 0.0\ntemperature_sigma_K = 8.0"),
    )
    assert main(["import", "csv", "--mapping", str(mp), "--out", str(tmp_path / "flight"), "--allow-unhealthy"]) == 0
    st = load_scenario(tmp_path / "flight" / "remapped.toml").data["states"]["baro_scale"]
    t_site = json.loads(META.read_text(encoding="utf-8"))[LOG.name]["launch_site"]["air_temperature_celsius"]
    assert st["process"] == "consider"
    assert st["sigma"] == pytest.approx(8.0 / (t_site + 273.15), rel=1e-5)


def _gnss_file(path: Path, t_log, enu, lat0: float, lon0: float, alt0: float) -> None:
    """A GNSS CSV (time [s], lat/lon [deg], alt [m] in its own datum) of the positions ``enu`` (k, 3)
    [m east/north/up of the pad's fix at (lat0, lon0, alt0)], the inverse of the importer's local
    east/north on the mean sphere."""
    from workbench.core.bodies import EARTH

    r = EARTH.reference_radius
    lat = lat0 + np.degrees(enu[:, 1] / r)
    lon = lon0 + np.degrees(enu[:, 0] / (r * math.cos(math.radians(lat0))))
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["gps_time", "lat", "lon", "alt_ft"])
        for row in zip(t_log, lat, lon, (alt0 + enu[:, 2]) / 0.3048, strict=True):
            w.writerow([repr(float(v)) for v in row])


def test_gnss_fixes_are_observed_relative_to_the_pad(tmp_path):
    """Issue 27 item 1, GNSS: fixes made from the reconstruction without GNSS, moved 15 m east (inside
    the boost's 1σ, 23 m) and carrying a constant 40 m north error (pad fixes included), pull the track
    15 m east and the 40 m cancels; the landing, on a heading ring of radius > 100 m without them, is
    known to < 10 m (1σ) with them; every fix is accepted at the default fix σ (10 m horizontal, 20 m
    vertical)."""
    toml0, s0 = _import_and_run(tmp_path / "plain")
    fl = json.loads((toml0.parent / "flight.json").read_text(encoding="utf-8"))
    settings = Post2Problem().settings(load_scenario(toml0))
    *_, r0 = Post2Problem().reconstruct(settings, Post2Problem().telemetry_files(settings), RunOptions())
    tr = r0.rocket
    t_fix = np.arange(tr.t[0] + 0.5, tr.t[-1], 1.0)
    enu = np.column_stack([np.interp(t_fix, tr.t, tr.enu[:, i]) for i in range(3)]) + [15.0, 40.0, 0.0]
    pad_t = -np.arange(6.0, 0.0, -1.0)  # six fixes in the seconds before liftoff
    enu = np.vstack([np.tile([0.0, 40.0, 0.0], (pad_t.size, 1)), enu])
    site = s0["rocket"]["pad"]
    log = tmp_path / "log"
    remap(log)
    _gnss_file(log / "gps.csv", np.concatenate([pad_t, t_fix]) + fl["t_launch_log_s"], enu, 35.0, -76.0, 12.0)
    gnss_map = '[files.gps]\npath = "gps.csv"\ntime = "gps_time"\n\n[gnss]\nfile = "gps"\nlatitude = "lat"\n'
    gnss_map += 'longitude = "lon"\naltitude = "alt_ft"\naltitude_unit = "ft"\n'
    mp = remap(log, edit=lambda t: t + "\n" + gnss_map)
    assert main(["import", "csv", "--mapping", str(mp), "--out", str(tmp_path / "flight"), "--allow-unhealthy"]) == 0
    toml = tmp_path / "flight" / "remapped.toml"
    assert 'quantity = "position_pad_enu"' in toml.read_text(encoding="utf-8")
    info = json.loads((tmp_path / "flight" / "flight.json").read_text(encoding="utf-8"))["gnss"]
    assert info["on_pad"] == 6 and info["observed_in_span"] == t_fix.size
    s = _run(toml, tmp_path / "rec")
    a, b = s0["rocket"]["landing"], s["rocket"]["landing"]
    moved = rocket.local_en(b["lat_deg"], b["lon_deg"], a["lat_deg"], a["lon_deg"])
    assert abs(moved[0] - 15.0) < 3.0 * b["sigma_east_m"] and abs(moved[1]) < 3.0 * b["sigma_north_m"], moved
    # without GNSS the heading is not known: the landing lies on a ring about the drift (hundreds of m)
    assert b["sigma_east_m"] < 10.0 and b["sigma_north_m"] < 10.0 and a["heading_ring"]["radius_m"] > 100.0
    assert s["observations"]["gnss"]["accepted"] == t_fix.size
    assert s["observations"]["gnss"]["nis_verdict"] == "consistent"
    assert site == s["rocket"]["pad"]


def test_gnss_without_fixes_on_the_pad_is_a_located_error(tmp_path, capsys):
    """The fixes are referenced to the pad's own fix: a GNSS file starting after liftoff cannot be."""
    log = tmp_path / "log"
    remap(log)
    _gnss_file(log / "gps.csv", np.array([1300.0, 1301.0]), np.zeros((2, 3)), 35.0, -76.0, 12.0)
    gnss_map = '[files.gps]\npath = "gps.csv"\ntime = "gps_time"\n\n[gnss]\nfile = "gps"\nlatitude = "lat"\n'
    gnss_map += 'longitude = "lon"\naltitude = "alt_ft"\naltitude_unit = "ft"\n'
    mp = remap(log, edit=lambda t: t + "\n" + gnss_map)
    err = _refused(tmp_path, mp, capsys)
    assert "gps.csv" in err and "gps_time" in err and "min_pad_fixes" in err


def test_model_error_levels_are_overridable(tmp_path):
    """Issue 27 item 3: the observations' model-error levels default to the FIRM flights' measured ones
    and a mapping may set its own (``[model_error]``); the weights written follow them."""
    from workbench.io.telemetry import read_telemetry
    from workbench.problems.post2 import rocket as rk

    def coast_sigma(folder: Path) -> np.ndarray:
        w = read_telemetry(folder / "pressure_weights.csv")
        fl = json.loads((folder / "flight.json").read_text(encoding="utf-8"))
        coast = (w.time > fl["t_start_s"] + rk.BURNOUT_TRANSIENT_S + 0.5) & (w.time < fl["t_ejection_s"] - 0.5)
        return 1.0 / np.sqrt(w.channel("p")[coast])

    base = mapped.import_mapped(remap(tmp_path / "a"), tmp_path / "fa", allow_unhealthy=True).parent
    edit = lambda t: t + "\n[model_error]\npressure_coast_pa = 40.0\n"  # noqa: E731
    over = mapped.import_mapped(remap(tmp_path / "b", edit=edit), tmp_path / "fb", allow_unhealthy=True).parent
    s0, s1 = coast_sigma(base), coast_sigma(over)
    assert s0.size > 10 and np.all(s0 >= rk.PRESSURE_SIGMA_COAST)
    assert np.all(s1 >= 40.0) and np.all(s1 < 0.5 * s0)
    assert json.loads((over / "flight.json").read_text(encoding="utf-8"))["model_error_overrides"] == {
        "pressure_coast_pa": 40.0
    }
