"""Real rocket flights (issue #9, case 5): the FIRM log importer (unit conversions, gaps, located
errors) and, on the committed excerpt of flight 1 (``data/airbrakes_excerpt``, MIT licence), the
import + a short reconstruction through the command line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.core.atmosphere import EarthStandardAtmosphere
from workbench.core.bodies import G0
from workbench.estimation.consistency import mixture_hdr_level
from workbench.io.scenario import ScenarioError, load_scenario
from workbench.io.telemetry import TelemetryError, read_telemetry
from workbench.problems.post2 import rocket
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.importers import airbrakes, flightlog
from workbench.problems.post2.importers.airbrakes import find_gaps, read_log, read_metadata
from workbench.problems.post2.pipeline import Estimator
from workbench.problems.post2.problem import Post2Problem

DATA = Path(__file__).resolve().parent / "data" / "airbrakes_excerpt"
LOG = DATA / "jackpot_launch_1_excerpt.csv"
META = DATA / "metadata.json"
EXIT_INPUT = 3


def _lines() -> list[str]:
    return LOG.read_text(encoding="utf-8").splitlines()


def _write(tmp_path: Path, lines: list[str], name: str = "log.csv") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


def _cell(lines: list[str], row: int, column: str) -> str:
    """The text of data row ``row`` (1-based), column ``column``."""
    return lines[row].split(",")[lines[0].split(",").index(column)]


def _set(lines: list[str], row: int, column: str, value: str) -> list[str]:
    out = list(lines)
    cells = out[row].split(",")
    cells[out[0].split(",").index(column)] = value
    out[row] = ",".join(cells)
    return out


def test_units_are_converted_to_si():
    lines = _lines()
    log = read_log(LOG)
    r = 5  # a data row (1-based)
    assert log.f_B[r - 1, 0] == pytest.approx(float(_cell(lines, r, "raw_acceleration_x_gs")) * G0, rel=1e-12)
    assert log.w_B[r - 1, 2] == pytest.approx(
        math.radians(float(_cell(lines, r, "raw_angular_rate_z_deg_per_s"))), rel=1e-12
    )
    assert log.temperature[r - 1] == pytest.approx(float(_cell(lines, r, "temperature_celsius")) + 273.15)
    assert log.mag_B[r - 1, 1] == pytest.approx(float(_cell(lines, r, "magnetic_field_y_microteslas")) * 1e-6)
    assert log.pressure[r - 1] == float(_cell(lines, r, "pressure_pascals"))
    # the flight computer's quaternion is logged scalar first: stored scalar last, normalised
    qw = float(_cell(lines, r, "est_quaternion_w"))
    assert log.ref_q[r - 1, 3] == pytest.approx(qw, abs=1e-6)
    assert np.allclose(np.linalg.norm(log.ref_q, axis=1), 1.0)
    # on the pad the specific force is ~1 g (the IMU's scale is sane after the conversion)
    pad = log.letters == "S"
    assert np.median(np.linalg.norm(log.f_B[pad], axis=1)) == pytest.approx(G0, rel=0.02)
    assert set(log.letters) == {"S", "M", "C", "F"}


def test_gaps_are_found_and_reported_not_filled():
    log = read_log(LOG)
    # the excerpt keeps three standby rows before the logger's ~18 min pause, then -1.7 s .. +16 s
    assert len(log.gaps) == 1
    g = log.gaps[0]
    assert g.row == 4 and g.phase == "S" and g.dt > 1000.0
    assert log.t.size == len(_lines()) - 1  # no row invented
    # find_gaps: a step above factor x the median step
    t = np.array([0.0, 0.01, 0.02, 0.05, 0.06])
    gaps = find_gaps(t, np.array(list("SSSSS")), gap_factor=2.0)
    assert [(x.t_a, x.t_b, x.row) for x in gaps] == [(0.02, 0.05, 4)]


def testblock_means_never_span_a_gap():
    t = np.array([0.00, 0.02, 0.04, 0.30, 0.32, 0.34])
    v = np.array([1.0, 1.0, 1.0, 5.0, 5.0, 5.0])[:, None]
    gap = airbrakes.Gap(0.04, 0.30, 0.26, 4, "C")
    # blocks of 1 s would mix both sides; the gap cuts the block
    tm, vm, n = airbrakes.block_means(t, v, 0.0, 1.0, 1.0, (gap,))
    assert vm[:, 0].tolist() == [1.0, 5.0] and n.tolist() == [3, 3]


def test_a_gap_inside_the_boost_is_refused(tmp_path):
    lines = _lines()
    motor = [i for i, ln in enumerate(lines) if ln.startswith("M,")]
    cut = motor[5:12]  # ~0.8 s of the boost missing
    bad = _write(tmp_path, [ln for i, ln in enumerate(lines) if i not in cut], "gappy.csv")
    with pytest.raises(TelemetryError) as e:
        airbrakes.import_flight(bad, META, tmp_path / "out", flight=LOG.name)
    assert "inside the boost" in str(e.value) and "gappy.csv" in str(e.value)
    assert e.value.row == motor[12] - len(cut) and e.value.column == "timestamp_seconds"
    assert not (tmp_path / "out").exists()  # nothing written


def test_missing_column_is_located(tmp_path):
    lines = _lines()
    col = lines[0].split(",").index("pressure_pascals")
    cut = [",".join(c for j, c in enumerate(ln.split(",")) if j != col) for ln in lines]
    with pytest.raises(TelemetryError) as e:
        read_log(_write(tmp_path, cut))
    assert e.value.column == "pressure_pascals" and "missing" in e.value.reason and "log.csv" in str(e.value)


def test_text_in_a_number_is_located(tmp_path):
    bad = _set(_lines(), 7, "raw_acceleration_y_gs", "1.2e")
    with pytest.raises(TelemetryError) as e:
        read_log(_write(tmp_path, bad))
    assert (e.value.column, e.value.row, e.value.line) == ("raw_acceleration_y_gs", 7, 8)
    assert "'1.2e' is not a number" in str(e.value)


def test_nan_and_empty_cells_are_errors(tmp_path):
    bad = _set(_set(_lines(), 9, "pressure_pascals", "nan"), 10, "temperature_celsius", "")
    with pytest.raises(TelemetryError) as e:
        read_log(_write(tmp_path, bad))
    assert e.value.total == 2
    assert [(p.column, p.row) for p in e.value.problems] == [("pressure_pascals", 9), ("temperature_celsius", 10)]


def test_backwards_time_is_located(tmp_path):
    lines = _lines()
    t9 = float(_cell(lines, 9, "timestamp_seconds"))
    bad = _set(lines, 10, "timestamp_seconds", f"{t9 - 0.005:.8f}")
    with pytest.raises(TelemetryError) as e:
        read_log(_write(tmp_path, bad))
    assert (e.value.column, e.value.row) == ("timestamp_seconds", 10) and "goes backwards" in e.value.reason


def test_repeated_packet_is_dropped_but_a_clashing_one_is_an_error(tmp_path):
    lines = _lines()
    dup = lines[:12] + [lines[11]] + lines[12:]  # row 11 logged twice
    log = read_log(_write(tmp_path, dup, "dup.csv"))
    assert log.repeated_rows == 1 and log.t.size == len(lines) - 1
    clash = _set(dup, 12, "pressure_pascals", "90000.0")  # same time, another value
    with pytest.raises(TelemetryError) as e:
        read_log(_write(tmp_path, clash, "clash.csv"))
    assert e.value.row == 12 and "repeats (with other values)" in e.value.reason


def test_unknown_phase_letter_and_bad_metadata_are_located(tmp_path):
    with pytest.raises(TelemetryError) as e:
        read_log(_write(tmp_path, _set(_lines(), 3, "state_letter", "X")))
    assert (e.value.column, e.value.row) == ("state_letter", 3)
    meta = json.loads(META.read_text(encoding="utf-8"))
    del meta["jackpot_launch_1_excerpt.csv"]["rocket"]["rocket_Cd"]
    mp = tmp_path / "metadata.json"
    mp.write_text(json.dumps(meta), encoding="utf-8")
    with pytest.raises(ScenarioError) as e:
        read_metadata(mp, "jackpot_launch_1_excerpt.csv")
    assert e.value.key == "jackpot_launch_1_excerpt.csv.rocket.rocket_Cd" and "missing" in str(e.value)
    with pytest.raises(ScenarioError, match="no entry for 'other.csv'"):
        read_metadata(META, "other.csv")


def _metadata_with(tmp_path: Path, edit) -> Path:
    """A copy of the excerpt's metadata.json with ``edit(entry)`` applied to the flight's entry."""
    meta = json.loads(META.read_text(encoding="utf-8"))
    edit(meta[LOG.name])
    mp = tmp_path / "metadata.json"
    mp.write_text(json.dumps(meta), encoding="utf-8")
    return mp


def test_a_misspelt_metadata_key_names_the_file_the_json_path_and_the_nearest_key(tmp_path, capsys):
    mp = _metadata_with(tmp_path, lambda e: e["rocket"].update(rocket_dry_mas_kg=e["rocket"].pop("rocket_dry_mass_kg")))
    with pytest.raises(ScenarioError) as e:
        read_metadata(mp, LOG.name)
    msg = str(e.value)
    assert Path(e.value.file) == mp and e.value.key == f"{LOG.name}.rocket.rocket_dry_mas_kg"
    assert "flight-log metadata file" in msg and "did you mean 'rocket_dry_mass_kg'?" in msg
    out = tmp_path / "flight"
    args = ["import", "airbrakes", str(LOG), "--metadata", str(mp), "--out", str(out)]
    assert main(args) == EXIT_INPUT
    err = capsys.readouterr().err
    assert str(mp) in err and "rocket_dry_mas_kg" in err and "did you mean" in err
    assert not out.exists()  # refused before anything is written


@pytest.mark.parametrize(
    ("table", "key", "value", "bound"),
    [
        ("rocket", "rocket_dry_mass_kg", -1.0, "> 0"),
        ("launch_site", "air_temperature_celsius", 140.0, "≤ 60"),
        ("launch_site", "air_pressure_mb", 101325.0, "≤ 1100"),  # Pa written where mb is meant
        ("launch_site.launch_coordinates", "latitude", 135.2, "≤ 90"),
        ("flight_data.landed_coordinates", "longitude", -200.0, "≥ -180"),
    ],
)
def test_an_out_of_range_metadata_value_names_the_bound(tmp_path, table, key, value, bound):
    def edit(entry):
        node = entry
        for part in table.split("."):
            node = node[part]
        node[key] = value

    with pytest.raises(ScenarioError) as e:
        read_metadata(_metadata_with(tmp_path, edit), LOG.name)
    assert e.value.key == f"{LOG.name}.{table}.{key}" and "out of range" in str(e.value) and bound in str(e.value)


def test_optional_metadata_fields_stay_optional(tmp_path):
    def edit(entry):
        for k in ("date", "flight_description", "ins_details"):
            entry.pop(k)
        entry["rocket"].pop("motor")
        entry["flight_data"].pop("target_apogee_meters")

    m = read_metadata(_metadata_with(tmp_path, edit), LOG.name)
    assert m.date == "" and m.mass == pytest.approx(16.848) and m.qnh == pytest.approx(101514.0)


def test_earth_standard_atmosphere_matches_the_1976_table():
    a = EarthStandardAtmosphere()
    # U.S. Standard Atmosphere 1976, Table I (geometric altitude): 1 km, 11 km, 20 km
    assert a.pressure(np.array([0.0, 1000.0, 11000.0, 20000.0])) == pytest.approx(
        [101325.0, 89874.6, 22699.9, 5529.3], rel=2e-5
    )
    assert a.temperature(1000.0) == pytest.approx(281.651, abs=1e-3)
    assert a.density(0.0) == pytest.approx(1.2250, rel=1e-4)
    h = np.array([-50.0, 300.0, 2500.0])
    assert a.altitude_of_pressure(a.pressure(h)) == pytest.approx(h, abs=1e-6)
    # a warm day: the same pressure drop is a taller column (hypsometric equation)
    warm = EarthStandardAtmosphere(101325.0, 298.15)
    assert warm.altitude_of_pressure(89874.6) > 1.03 * a.altitude_of_pressure(89874.6)


@pytest.fixture(scope="module")
def excerpt_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("airbrakes")
    args = ["import", "airbrakes", str(LOG), "--metadata", str(META), "--out", str(out / "flight")]
    args += ["--declination-deg", "-10.5", "--inclination-deg", "64"]
    assert main(args) == 0
    toml = out / "flight" / "jackpot_launch_1_excerpt.toml"
    # --allow-unhealthy: a WARNING verdict still writes; the health test below asserts it is not ERROR
    assert main(["run", str(toml), "--out", str(out / "rec"), "--allow-unhealthy", "--export"]) == 0
    result, score = rocket.run_flight(Post2Problem().settings(load_scenario(toml)))
    return out, toml, result, score


def test_an_imported_flight_exports_its_reconstruction(excerpt_run):
    """``--export`` of an imported rocket problem (issue 27: it failed with "unknown unit 'm^2'" on
    the drag-area states after the recording was written): every state and its 1σ in SI."""
    out, toml, _, _ = excerpt_run
    tel = read_telemetry(out / "rec" / f"{toml.stem}.reconstruction.csv", sparse=())
    assert "position.x" in tel.channels and "sigma_position.x" in tel.channels
    areas = [c for c, u in tel.units.items() if u == "m^2"]
    assert areas, f"no drag-area column among {list(tel.units)}"
    assert tel.kinds[areas[0]] == "area"


def test_import_writes_telemetry_a_problem_file_and_the_references(excerpt_run):
    out, toml, _, _ = excerpt_run
    d = toml.parent
    for f in ("pressure.csv", "pressure_weights.csv", "accel.csv", "imu.csv", "reference.csv", "events.csv"):
        assert (d / f).is_file(), f
    imu = read_telemetry(d / "imu.csv")
    assert imu.units["f.x"] == "g" and imu.gaps and imu.gaps[0].duration_s > 1000.0  # the gap is kept, not filled
    events = (d / "events.csv").read_text(encoding="utf-8")
    assert "phase M (motor)" in events and "phase F (descent)" in events and "gap 1073" in events
    fl = json.loads((d / "flight.json").read_text(encoding="utf-8"))
    assert fl["gaps"][0]["row"] == 4
    # pad: tilt = the 20 deg launch rod.  The excerpt is decimated to ~8 Hz, too slow for the gyro to
    # follow the coning, so the magnetometer is not aligned in flight; its raw axes (not the IMU's)
    # give a pad dip that disagrees with the site's -> heading untrusted
    assert fl["pad"]["tilt_on_pad_deg"] == pytest.approx(20.0, abs=1.5)
    assert fl["pad"]["magnetometer_alignment"] is None
    assert abs(fl["pad"]["magnetometer_dip_deg"] - 64.0) > 10.0
    assert not fl["pad"]["magnetometer_heading_trusted"]
    assert (out / "rec" / "jackpot_launch_1_excerpt.rrd").is_file()
    assert "\\" not in toml.read_text(encoding="utf-8") and "shared" not in toml.read_text(encoding="utf-8")


def test_boost_covariance_keeps_its_correlations(excerpt_run):
    # the pad heading moves position and velocity together across the inertial axes: the problem file
    # carries the boost's correlation matrix and the EKF's P0 is diag(sigma) C diag(sigma) over it
    _, toml, _, _ = excerpt_run
    sc = load_scenario(toml)
    cfg = Post2Settings.from_scenario(sc)
    names, corr = cfg.initial_correlation
    assert names == ("position", "velocity") and corr.shape == (6, 6)
    assert np.max(np.abs(corr - np.eye(6))) > 0.5  # strongly correlated, not a diagonal in disguise
    est = Estimator(cfg)
    sig = np.concatenate([cfg.state("position").sigma, cfg.state("velocity").sigma])
    # the untrusted heading (60 deg) is not in the boost's covariance: the run adds it as an exact turn
    # of the flight about the pad's vertical (pipeline.Estimator.pad_rotation)
    assert cfg.launch is not None and not cfg.launch.heading_trusted
    n = est.pad_rotation(est.x0, cfg.t_start)
    heading = math.radians(cfg.launch.heading_sigma_deg) ** 2 * np.outer(n, n)
    np.testing.assert_allclose(est.P0[:6, :6] - heading[:6, :6], sig[:, None] * corr * sig[None, :], rtol=1e-9)
    assert np.min(np.linalg.eigvalsh(est.P0)) > -1e-6 * np.max(np.diag(est.P0))


def test_excerpt_reconstruction_is_healthy(excerpt_run):
    out, _, _, _ = excerpt_run
    summary = json.loads((out / "rec" / "jackpot_launch_1_excerpt.summary.json").read_text(encoding="utf-8"))
    assert summary["health"]["verdict"] != "ERROR", summary["health"]


def test_an_unaligned_magnetometer_whose_dip_is_not_the_sites_does_not_set_the_heading(excerpt_run, tmp_path):
    """issue 26: the excerpt is decimated (no in-flight alignment) and its raw field dips -49 deg where
    the site's dips +64: the magnetometer's axes are not the IMU's, so the heading is the prior's and a
    magnetometer negated or with two axes swapped changes nothing (before: the boost's prior turned with
    the raw field, the end position moved 31σ and 5σ under the same WARNING as the good run)."""
    out, toml, _, _ = excerpt_run
    fl = json.loads((toml.parent / "flight.json").read_text(encoding="utf-8"))
    assert fl["pad"]["pad_heading_source"].startswith("prior (the unaligned magnetometer's dip -49 deg")
    lines = _lines()
    names = lines[0].split(",")
    mag = [names.index(f"magnetic_field_{a}_microteslas") for a in "xyz"]

    def edited(op):
        rows = [lines[0]]
        for line in lines[1:]:
            c = line.split(",")
            c[mag[0]], c[mag[1]], c[mag[2]] = op(c[mag[0]], c[mag[1]], c[mag[2]])
            rows.append(",".join(c))
        return rows

    def neg(v):
        return v[1:] if v.startswith("-") else "-" + v

    for tag, op in (("negated", lambda x, y, z: (neg(x), neg(y), neg(z))), ("swapped", lambda x, y, z: (y, x, z))):
        (tmp_path / tag).mkdir()
        log = _write(tmp_path / tag, edited(op), LOG.name)
        args = ["import", "airbrakes", str(log), "--metadata", str(META), "--out", str(tmp_path / tag / "flight")]
        assert main([*args, "--declination-deg", "-10.5", "--inclination-deg", "64"]) == 0
        text = (tmp_path / tag / "flight" / toml.name).read_text(encoding="utf-8")
        assert text == toml.read_text(encoding="utf-8"), tag


def test_an_untrusted_heading_stays_unknown(excerpt_run):
    """issue 26: a turn of the flight about the pad's vertical changes neither the pressure nor |f|,
    so the 60 deg heading prior of the decimated excerpt must still be in the end position's σ along
    that turn's lever (tests/benchmarks/bench_heading_consistency.py).  Before the run carried the
    turn itself (observability-constrained Jacobians), the EKF's moving linearisation point made the
    heading look observed: 133 m where the prior alone gives 1.3-1.5 km."""
    _, toml, result, _ = excerpt_run
    cfg = Post2Settings.from_scenario(load_scenario(toml))
    est = Estimator(cfg)
    n = est.pad_rotation(result.x[-1], float(result.t[-1]))
    ip = np.arange(result.smap.n_e)[result.smap.blocks["position"].se]
    lever = np.linalg.norm(n[ip])
    e = n[ip] / lever
    sigma_along = math.sqrt(float(e @ result.P[-1][np.ix_(ip, ip)] @ e))
    assert lever > 500.0  # the excerpt drifts ~1 km from the pad before its end
    assert sigma_along > 0.7 * lever * math.radians(cfg.launch.heading_sigma_deg), (sigma_along, lever)


def test_the_declared_cd_only_normalises_the_coast_drag_multiplier(excerpt_run, tmp_path):
    """issue 26: a rocket_Cd declared 3× too large is a normalisation of the multiplier (its prior is
    measured from the coast drag), not a different rocket: the coast drag coefficient (multiplier × Cd)
    and every other state come out the same.  With the random walk's PSD in multiplier units (not
    scaled by (0.38 / Cd)²) the velocity at the end of FIRM flight 1 moved 4.3σ."""
    out, toml, result, _ = excerpt_run

    def triple(entry):
        entry["rocket"]["rocket_Cd"] = 3.0 * entry["rocket"]["rocket_Cd"]

    meta = _metadata_with(tmp_path, triple)
    args = ["import", "airbrakes", str(LOG), "--metadata", str(meta), "--out", str(tmp_path / "flight")]
    assert main([*args, "--declination-deg", "-10.5", "--inclination-deg", "64"]) == 0
    toml3 = tmp_path / "flight" / toml.name
    assert "\ncd = 1.14" in toml3.read_text(encoding="utf-8")
    r3, _ = rocket.run_flight(Post2Problem().settings(load_scenario(toml3)))
    for name in ("position", "velocity", "ca_multiplier", "baro_bias", "drogue_drag_area", "wind"):
        k = 3.0 if name == "ca_multiplier" else 1.0
        v, v3 = result.history["smoothed"][name]["value"][-1], r3.history["smoothed"][name]["value"][-1] * k
        s = result.history["smoothed"][name]["sigma"][-1]
        assert np.all(np.abs(v3 - v) <= 0.05 * s), (name, v, v3, s)


@pytest.mark.xfail(
    strict=True,
    reason="open (issue #9 case 5): like for like (the flight computer's standard-day altitude made geometric "
    "above the pad: its formula inverted, the pressure's altitude in the site atmosphere) 38.8 m RMS after "
    "the burnout transient on the excerpt (raw 37.1 m); full flights 28.2/16.8/12.6 m (raw 27.1/35.1/30.9 m). "
    "Flights 3 and 4 were the conventions (15 C vs 25 C: 3.5 % of the height; zero at switch-on: +2.0/+7.6 m "
    "on the pad). Flight 1 is not: ours sits above the barometer's geometric altitude all along (coast "
    "+42 m mean, apogee +24 m, under the main +21 m; the reconstruction touches down 16.6 m above the pad "
    "where the barometer reads +0.9 m): the constant baro_bias (188 Pa) fitted against the IMU-anchored coast "
    "behind the open air brakes is carried into the descent, and its v0.1 flight computer is 8 m (mean) below "
    "its own barometer. baro_q_coefficient makes it worse like for like too (excerpt 68.6 m, flight 1 "
    "34.4 m); see docs/tuning/post2.md (the flight computer's altitude)",
)
def test_altitude_follows_the_flight_computer_within_30_m(excerpt_run):
    _, _, _, s = excerpt_run
    a = s["altitude_vs_flight_computer"]
    assert np.isfinite(a["rms_after_burnout_transient_m"])  # the raw comparison: reported, not asserted
    assert a["like_for_like"]["rms_after_burnout_transient_m"] < 30.0


def test_flight_computer_altitude_is_converted_like_for_like(excerpt_run):
    # flight 1's flight computer (v0.1) holds 0 on the pad; its standard-day altitude (15 C at the pad)
    # made geometric in the 14 C site atmosphere shrinks by the hypsometric ratio T_site / 288.15 K
    out, toml, _, s = excerpt_run
    fc = s["altitude_vs_flight_computer"]["flight_computer_altimeter"]
    assert fc["pad_reading_m"] == pytest.approx(0.0, abs=0.1)
    ll = s["altitude_vs_flight_computer"]["like_for_like"]
    t_site = json.loads((toml.parent / "flight.json").read_text(encoding="utf-8"))["metadata"]["temperature"]
    assert ll["scale_at_apogee"] == pytest.approx(t_site / 288.15, abs=1e-3)
    ref = read_telemetry(toml.parent / "reference.csv")
    assert ll["flight_computer_max_geometric_m"] == pytest.approx(
        float(np.max(ref.channel("h"))) * t_site / 288.15, abs=1.0
    )
    # the reverse comparison (ours on the barometer's scale) is reported beside it
    assert np.isfinite(s["altitude_vs_flight_computer"]["barometer_scale"]["rms_after_burnout_transient_m"])


class _Series:
    """A stand-in for :class:`~workbench.io.telemetry.Telemetry`: ``time`` and ``channel(name)``."""

    def __init__(self, t, **channels):
        self.time = t
        self._c = channels

    def channel(self, name):
        return self._c[name]


@pytest.mark.parametrize("reference", ["initial", "101325"])
def test_flight_computer_altimeter_reference_is_measured(reference):
    # a flight computer switched on at 98 473 Pa, the pad at 98 384 Pa at launch (the weather moved):
    # its altitude is the standard-day formula with its initial pressure or with 101 325 Pa minus the
    # altitude of the initial pressure; the two differ by 0.55 % of the height, which the log tells apart
    t = np.linspace(-3.0, 40.0, 4301)
    p_init, p_pad = 98473.0, 98384.0
    up = np.clip(t, 0.0, None)
    p = np.where(t < 0.0, p_pad, p_pad - 12000.0 * np.sin(np.pi * np.clip(up / 40.0, 0.0, 1.0)))
    if reference == "initial":
        h_fc = rocket.firm_altitude(p, p_init)
    else:
        h_fc = rocket.firm_altitude(p, 101325.0) - rocket.firm_altitude(p_init, 101325.0)
    flight = {
        "pad": {"ignition_t_s": 0.0, "standby_pressure_pa": p_pad},
        "t_start_s": 2.8,
        "t_end_s": 40.0,
        "t_ejection_s": 20.0,
        "t_apogee_letter_s": 20.0,
    }
    fc = rocket.flight_computer_altimeter(flight, _Series(t, pressure=p), _Series(t, h=h_fc))
    assert fc["reference"] == reference
    other = "101325" if reference == "initial" else "initial"
    assert fc["rms_vs_own_barometer_m"][reference] < 1e-6 < 1.0 < fc["rms_vs_own_barometer_m"][other]
    assert fc["pad_reading_m"] == pytest.approx(float(h_fc[0]), abs=1e-9) and 7.0 < h_fc[0] < 8.0
    if reference == "initial":
        assert fc["p_ref_pa"] == pytest.approx(p_init, rel=1e-9) and fc["offset_m"] == 0.0
    else:
        assert fc["p_ref_pa"] == 101325.0
        assert fc["offset_m"] == pytest.approx(-float(rocket.firm_altitude(p_init, 101325.0)), abs=1e-6)
    # the formula and its inverse; the standard day's 1 000 m (U.S. Standard Atmosphere 1976) within 0.2 m
    # (the formula's altitude is geopotential: 999.84 m)
    assert rocket.firm_pressure(rocket.firm_altitude(p, p_pad), p_pad) == pytest.approx(p, rel=1e-12)
    assert float(rocket.firm_altitude(89874.6, 101325.0)) == pytest.approx(1000.0, abs=0.2)


def test_short_reconstruction_follows_the_flight(excerpt_run):
    _, toml, result, s = excerpt_run
    # the excerpt ends 2.3 s after the apogee letter: apogee within 3 % of the metadata's (the flight
    # computer's).  The altitude against the flight computer's is reported, not asserted: its
    # barometric altitude and the IMU-anchored one differ in scale by ~2 % (the baro offset estimate
    # absorbs it; the benchmark reports both)
    assert abs(s["apogee"]["error_percent"]) < 3.0
    # the coast drag as measured: flight 1's air brakes opened at once and stuck (metadata), so the
    # first coast drag is several times the clean rocket's (the data-derived CA prior); with each
    # block's own sample noise in its sigma no |f| block is gated out (before: 18 of 109)
    fl0 = json.loads((toml.parent / "flight.json").read_text(encoding="utf-8"))
    assert fl0["initial_ca_multiplier"] > 2.0
    assert s["observations"]["accel"]["accepted"] == s["observations"]["accel"]["samples"]
    assert s["observations"]["baro"]["accepted"] == s["observations"]["baro"]["samples"]
    p = s["parameters"]
    # the coast drag multiplier is a random walk (the drag varies: brakes, coning, pitch-over): its
    # final 1σ stays near the walk's, but below the prior's (max(0.5, 0.25 x the measured start))
    assert 0.2 < p["ca_multiplier"]["value"][0] < 6.0
    assert p["ca_multiplier"]["sigma"][0] < max(0.5, 0.25 * p["ca_multiplier"]["prior"][0])
    # the rocket flies nose first: the gyro tilt at burnout matches the angle of the IMU-integrated
    # velocity from the vertical within 10 deg (two outputs of the boost: gyro vs accelerometers)
    fl = json.loads((excerpt_run[1].parent / "flight.json").read_text(encoding="utf-8"))
    v = np.asarray(fl["burnout"]["velocity_enu_m_s"])
    path_angle = math.degrees(math.acos(v[2] / np.linalg.norm(v)))
    t = s["attitude_vs_flight_computer"]["tilt_deg"]
    assert abs(t["ours_at_burnout"] - path_angle) < 10.0
    assert np.isfinite(t["difference_rms"])  # against the flight computer: reported (benchmark), not asserted


def test_barometer_scale_and_dynamic_pressure_states(excerpt_run):
    # the post2 barometer states a rocket problem file may add: baro_scale stretches the barometer's
    # altitude about [environment] baro_scale_anchor_m (the import writes the pad's), and
    # baro_q_coefficient adds a static-port error proportional to the dynamic pressure
    _, toml, _, _ = excerpt_run
    base = load_scenario(toml)
    est0 = Estimator(Post2Settings.from_scenario(base))
    h_a = base.data["environment"]["baro_scale_anchor_m"]
    sc = base.with_overrides(
        {
            "states.baro_scale": {"value": 1.04, "sigma": 0.03},
            "states.baro_q_coefficient": {"value": 0.1, "sigma": 0.1},
        }
    )
    est = Estimator(Post2Settings.from_scenario(sc))
    m, x = est.model, est.x0
    h = float(m.altitude(x))
    rho = float(m.env.atmosphere.density(h))
    q = 0.5 * rho * float(np.sum(m.v_rel(x) ** 2))
    expected = m.env.atmosphere.pressure(h_a + 1.04 * (h - h_a)) + 0.1 * q  # baro_bias starts at 0
    assert float(m.observe(x, "pressure", est.phase)[0]) == pytest.approx(float(expected), rel=1e-12)
    # without the states: the model pressure at the altitude, unchanged
    p0 = float(est0.model.observe(est0.x0, "pressure", est0.phase)[0])
    assert p0 == pytest.approx(float(m.env.atmosphere.pressure(h)), rel=1e-12)
    assert abs(float(expected) - p0) > 100.0  # the states change the reading by far more than round-off


def test_wind_prior_blows_away_from_where_the_metadata_says_it_comes_from(excerpt_run):
    # metadata: where the wind comes from (flight 1: NNE, 5.5 km/h); the state: the air's velocity
    # [east, north] (v_rel = v - wind), so its prior points the other way (SSW), and the score turns it back
    _, toml, _, s = excerpt_run
    w = np.asarray(load_scenario(toml).data["states"]["wind"]["value"], float)
    frm = math.radians(22.5)
    np.testing.assert_allclose(w, -5.5 / 3.6 * np.array([math.sin(frm), math.cos(frm)]), rtol=1e-9)
    wind = s["parameters"]["wind"]
    assert wind["metadata_from_deg"] == 22.5
    v = np.asarray(wind["value"], float)
    assert wind["from_deg"] == pytest.approx(math.degrees(math.atan2(-v[0], -v[1])) % 360.0)
    assert wind["speed_m_s"] == pytest.approx(float(np.hypot(*v)))


def test_landing_heading_mixture_turns_the_air_path_about_the_pad_and_keeps_the_wind_drift():
    t = np.linspace(0.0, 50.0, 501)
    wind = np.tile([2.0, -1.0], (t.size, 1))  # 100 m east, 50 m south over the span
    landing = np.array([700.0, 450.0])
    P = np.diag([30.0**2, 20.0**2])
    means, covs, w, d_w = rocket.landing_heading_mixture(landing, P, t, wind, math.radians(60.0))
    np.testing.assert_allclose(d_w, [100.0, -50.0], atol=1e-9)
    r = np.linalg.norm(means - d_w, axis=1)
    np.testing.assert_allclose(r, np.linalg.norm(landing - d_w), rtol=1e-12)  # a ring about the wind drift
    assert w.sum() == pytest.approx(1.0) and np.allclose(covs, P)
    np.testing.assert_allclose(means[np.argmax(w)], landing, atol=1e-9)  # the middle node: no heading error
    # the landed point 60 deg round the ring: far outside the linearised ellipse, inside the mixture's 3 sigma
    c, s = math.cos(math.radians(60.0)), math.sin(math.radians(60.0))
    e, n = landing - d_w
    other = d_w + np.array([c * e + s * n, -s * e + c * n])
    assert float((other - landing) @ np.linalg.solve(P, other - landing)) > 100.0
    assert mixture_hdr_level(other, means, covs, w, np.random.default_rng(1)) < 0.9973


def test_untrusted_heading_landing_verdict_is_the_nonlinear_one(excerpt_run):
    # the excerpt's heading is untrusted (60 deg 1 sigma): its landing verdict is the heading mixture's
    _, _, _, s = excerpt_run
    L = s["landing"]
    nl = L["heading_nonlinear"]
    assert 0.0 <= nl["hdr_level"] <= 1.0 and nl["turning_drift_m"] > 100.0
    assert L["inside_3sigma"] == (nl["hdr_level"] <= 0.9973)
    assert L["mahalanobis_linearised"] == L["mahalanobis"]


def test_site_temperature_is_a_consider_parameter_in_every_sigma(excerpt_run):
    """Issue 27 item 3: the air column's temperature is an unknown the data cannot separate from the
    trajectory (a warmer column is taller for the same pressures), so the import writes ``baro_scale``
    as a Schmidt consider parameter (σ_T / T): never moved by an observation, its σ carried into the
    trajectory's.  Against the same problem with the temperature taken as exact (σ ~ 0) the altitude
    σ grows by about the scale's 1σ times the height above the pad."""
    _, toml, result, _ = excerpt_run
    sc = load_scenario(toml)
    st = sc.data["states"]["baro_scale"]
    meta = read_metadata(META, LOG.name)
    assert st["process"] == "consider"
    assert st["sigma"] == pytest.approx(flightlog.TEMPERATURE_SIGMA_K / meta.temperature, rel=1e-5)
    for hist in (result.history["smoothed"], result.history["forward"]):
        np.testing.assert_array_equal(hist["baro_scale"]["value"], 1.0)  # never fitted
        np.testing.assert_allclose(hist["baro_scale"]["sigma"], st["sigma"], rtol=1e-6)  # never informed
    assert result.summary["states"]["baro_scale"]["consider"] is True
    assert any("consider parameters" in n for n in result.summary["health"]["notes"])
    r0, _ = rocket.run_flight(Post2Problem().settings(sc.with_overrides({"states.baro_scale.sigma": 1e-9})))
    alt_sigma, alt_sigma0 = result.rocket.sigma_altitude, r0.rocket.sigma_altitude
    h = result.rocket.altitude
    k = int(np.argmax(h))
    expected = math.hypot(alt_sigma0[k], st["sigma"] * h[k])
    assert alt_sigma[k] > 1.5 * alt_sigma0[k]
    assert alt_sigma[k] == pytest.approx(expected, rel=0.15)


def test_a_consider_state_must_be_a_constant_parameter(excerpt_run):
    _, toml, _, _ = excerpt_run
    sc = load_scenario(toml)
    with pytest.raises(ScenarioError, match="states.velocity.process"):
        Post2Settings.from_scenario(sc.with_overrides({"states.velocity.process": "consider"}))
    with pytest.raises(ScenarioError, match="states.baro_scale.psd"):
        Post2Settings.from_scenario(sc.with_overrides({"states.baro_scale.psd": 1e-6}))
