"""Telemetry CSV reading/writing and the events CSV (workbench.io.telemetry)."""

import os
import pickle

import numpy as np
import pytest

from workbench.io import telemetry as tm
from workbench.io.telemetry import (
    TelemetryError,
    read_events,
    read_telemetry,
    write_events,
    write_telemetry,
)

G0 = 9.80665

GOOD = """\
# sensor: BP triad
# rate_hz: 100
# epoch_utc: 2002-05-14T18:30:00Z
# raw file from the drop-test DAQ
time [s],BP.x [g],BP.z [g],gyro.z [deg/s]
0.00,0.0,1.0,0.0
0.01,0.1,1.1,10.0
0.02,0.2,1.2,20.0
0.03,0.3,1.3,30.0
0.04,0.4,1.4,40.0
"""


def write(tmp_path, text, name="imu.csv"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def set_cell(text, line, col, value):
    """Replace the cell at 1-based file ``line``, 0-based column ``col``."""
    lines = text.split("\n")
    cells = lines[line - 1].split(",")
    cells[col] = value
    lines[line - 1] = ",".join(cells)
    return "\n".join(lines)


def one_error(path, **kw) -> TelemetryError:
    with pytest.raises(TelemetryError) as info:
        read_telemetry(path, **kw)
    return info.value


# ---- good files ---------------------------------------------------------------------------


def test_read_good_file_in_si_with_metadata(tmp_path):
    tel = read_telemetry(write(tmp_path, GOOD), required={"BP.x": "acceleration", "gyro.z": "angular_rate"})
    assert len(tel) == 5 and tel.names == ["BP.x", "BP.z", "gyro.z"]
    np.testing.assert_allclose(tel.time, [0.0, 0.01, 0.02, 0.03, 0.04])
    np.testing.assert_allclose(tel.channel("BP.x"), np.array([0, 0.1, 0.2, 0.3, 0.4]) * G0)
    np.testing.assert_allclose(tel.channel("gyro.z"), np.deg2rad([0, 10, 20, 30, 40]))
    assert tel.units == {"BP.x": "g", "BP.z": "g", "gyro.z": "deg/s"}
    assert tel.kinds["gyro.z"] == "angular_rate"
    assert tel.meta == {
        "sensor": "BP triad",
        "rate_hz": "100",
        "epoch_utc": "2002-05-14T18:30:00Z",
        "notes": "raw file from the drop-test DAQ",
    }
    assert tel.stack(["BP.x", "BP.z"]).shape == (5, 2)
    assert not tel.gaps and not any(m.any() for m in tel.saturated.values())
    with pytest.raises(ValueError):
        tel.channel("BP.x")[0] = 1.0  # read-only: SI data cannot be edited by accident
    with pytest.raises(KeyError, match="BP.y.*channels: BP.x, BP.z, gyro.z"):
        tel.channel("BP.y")


def test_crlf_bom_and_trailing_blank_lines(tmp_path):
    p = tmp_path / "imu.csv"
    p.write_bytes(b"\xef\xbb\xbf" + GOOD.replace("\n", "\r\n").encode() + b"\r\n\r\n")
    assert len(read_telemetry(p)) == 5


def test_round_trip_non_si_units(tmp_path):
    rng = np.random.default_rng(1)
    n = 200
    t = np.arange(n) * 0.005
    acc = rng.normal(0.0, 30.0, n)  # m/s^2
    rate = rng.normal(0.0, 2.0, n)  # rad/s
    alt = 1e4 + rng.normal(0.0, 100.0, n)  # m
    temp = 200.0 + rng.normal(0.0, 5.0, n)  # K
    p = write_telemetry(
        tmp_path / "out.csv",
        t,
        {"acc": (acc, "g"), "rate": (rate, "deg/s"), "alt": (alt, "km"), "T": (temp, "degC")},
        meta={"source": "test"},
        time_unit="ms",
    )
    text = p.read_text()
    assert "time [ms],acc [g],rate [deg/s],alt [km],T [degC]" in text
    tel = read_telemetry(p)
    np.testing.assert_allclose(tel.time, t, rtol=1e-9, atol=1e-12)
    for name, v in [("acc", acc), ("rate", rate), ("alt", alt), ("T", temp)]:
        np.testing.assert_allclose(tel.channel(name), v, rtol=1e-8, atol=1e-9)
    assert tel.meta == {"source": "test"} and tel.time_unit == "ms"


# ---- each bad input: exact file, column, row, line -----------------------------------------

# GOOD has the header on line 5, so data row r is on line r + 5.
CELL_CASES = [
    (7, 1, "nan", "BP.x [g]", "value is NaN"),
    (7, 2, "", "BP.z [g]", "empty cell"),
    (8, 3, "1.2.3", "gyro.z [deg/s]", "cannot parse '1.2.3'"),
    (9, 1, "inf", "BP.x [g]", "value is inf"),
    (9, 0, "0.02", "time [s]", "duplicate time 0.02 s: same as row 3"),
    (9, 0, "0.015", "time [s]", "time goes backwards: 0.015 s after 0.02 s at row 3"),
]


@pytest.mark.parametrize(("line", "col", "value", "column", "reason"), CELL_CASES)
def test_bad_cell_is_located(tmp_path, line, col, value, column, reason):
    p = write(tmp_path, set_cell(GOOD, line, col, value))
    err = one_error(p)
    assert (err.file, err.column, err.row, err.line) == (str(p), column, line - 5, line)
    assert reason in err.reason
    assert str(err).startswith(f"{p}, column '{column}', row {line - 5} (line {line}): ")
    assert err.total == 1


def test_out_of_range_value(tmp_path):
    p = write(tmp_path, set_cell(GOOD, 8, 2, "12"))  # 12 g = 117.7 m/s^2
    err = one_error(p, limits={"BP.z": (-100.0, 100.0)})
    assert (err.column, err.row, err.line) == ("BP.z [g]", 3, 8)
    assert "value 12 g (= 117.6798 m/s^2) is outside the limits [-100, 100] m/s^2" in err.reason


def test_missing_column_lists_present_columns(tmp_path):
    p = write(tmp_path, GOOD)
    err = one_error(p, required={"BP.y": "acceleration"})
    assert err.column is None and err.line == 5
    assert "missing column 'BP.y' (acceleration); columns present: time [s], BP.x [g], BP.z [g]" in str(err)
    assert str(err).startswith(f"{p}, line 5: ")


def test_wrong_kind_unit(tmp_path):
    p = write(tmp_path, GOOD.replace("BP.x [g]", "BP.x [deg]"))
    err = one_error(p, required={"BP.x": "acceleration"})
    assert err.column == "BP.x [deg]" and err.row is None and err.line == 5
    assert "column 'BP.x [deg]' has unit of angle, expected acceleration" in str(err)


def test_unknown_unit(tmp_path):
    p = write(tmp_path, GOOD.replace("BP.x [g]", "BP.x [gee]"))
    err = one_error(p, required={"BP.x": "acceleration"})
    assert err.column == "BP.x [gee]" and "unknown unit 'gee' (expected acceleration: m/s^2, g)" in err.reason
    err = one_error(p)
    assert "known units:" in err.reason and "deg/s" in err.reason


def test_header_without_unit_and_first_column_not_time(tmp_path):
    p = write(tmp_path, GOOD.replace("BP.x [g]", "BP.x"))
    assert "has no '[unit]'" in one_error(p).reason
    p = write(tmp_path, GOOD.replace("time [s]", "time [m]"))
    err = one_error(p)
    assert err.column == "time [m]" and "must be time" in err.reason


def test_row_shape_problems(tmp_path):
    lines = GOOD.split("\n")
    lines[6] = "0.01,0.1,1.1"  # line 7: one field short
    lines[7] = ""  # line 8: blank
    lines[8] = "# pause"  # line 9: comment inside data
    err = one_error(write(tmp_path, "\n".join(lines)))
    assert [(p.row, p.line) for p in err.problems] == [(2, 7), (3, 8), (4, 9)]
    assert "expected 4 fields, found 3" in err.problems[0].reason
    assert "blank row" in err.problems[1].reason
    assert "comment line inside the data" in err.problems[2].reason


def test_multiple_problems_reported_together_in_file_order(tmp_path):
    text = GOOD.replace("gyro.z [deg/s]", "gyro.z [deg]")
    text = set_cell(text, 9, 2, "abc")
    text = set_cell(text, 7, 1, "nan")
    text = set_cell(text, 10, 0, "0.01")
    p = write(tmp_path, text)
    err = one_error(p, required={"gyro.z": "angular_rate", "mag.x": "magnetic"})
    got = [(p_.column, p_.row, p_.line) for p_ in err.problems]
    assert got == [
        ("gyro.z [deg]", None, 5),
        (None, None, 5),
        ("BP.x [g]", 2, 7),
        ("BP.z [g]", 4, 9),
        ("time [s]", 5, 10),
    ]
    msg = str(err)
    assert msg.startswith(f"5 problems in {p}:")
    assert f"{p}, column 'BP.z [g]', row 4 (line 9): cannot parse 'abc' as a number" in msg
    assert "time goes backwards: 0.01 s after 0.03 s at row 4" in msg


def test_many_problems_are_capped_with_total(tmp_path):
    rows = [f"{i * 0.01:.2f},nan" for i in range(100)]
    p = write(tmp_path, "time [s],x [m]\n" + "\n".join(rows) + "\n")
    err = one_error(p)
    assert err.total == 100 and len(err.problems) == tm.MAX_PROBLEMS
    assert str(err).startswith(f"100 problems in {p} (first 20 listed):")
    assert [q.row for q in err.problems] == list(range(1, 21))


def test_no_data_and_no_header(tmp_path):
    assert "no data rows" in one_error(write(tmp_path, "# a: b\ntime [s],x [m]\n")).reason
    assert "no header row" in one_error(write(tmp_path, "# only: comments\n")).reason
    assert one_error(tmp_path / "absent.csv").reason == "file not found"


def test_not_utf8(tmp_path):
    p = tmp_path / "imu.csv"
    p.write_bytes(b"time [s],T [degC]\n0,1\n1,\xb0\n")
    err = one_error(p)
    assert err.line == 3 and "UTF-8" in err.reason


def test_duplicate_metadata_and_bad_rate(tmp_path):
    err = one_error(write(tmp_path, "# rate_hz: fast\n# rate_hz: 10\n" + GOOD.split("\n", 4)[4]))
    assert [(q.line, q.reason[:20]) for q in err.problems] == [
        (1, "metadata rate_hz 'fa"),
        (2, "duplicate metadata k"),
    ]


def test_error_pickles(tmp_path):
    err = one_error(write(tmp_path, set_cell(GOOD, 7, 1, "nan")))
    back = pickle.loads(pickle.dumps(err))
    assert str(back) == str(err) and back.row == err.row


def test_unknown_channel_in_limits_is_an_error(tmp_path):
    err = one_error(write(tmp_path, GOOD), limits={"BP.y": (-1, 1)})
    assert "limits given for 'BP.y'" in err.reason


# ---- saturation, gaps, sparse --------------------------------------------------------------


def test_saturation_is_flagged_not_raised(tmp_path):
    text = set_cell(set_cell(GOOD, 8, 3, "-2000"), 9, 3, "1999.9")
    tel = read_telemetry(write(tmp_path, text), saturation={"gyro.z": np.deg2rad(2000.0)})
    np.testing.assert_array_equal(tel.saturated["gyro.z"], [False, False, True, False, False])
    assert not tel.saturated["BP.x"].any()


def test_gaps_found_with_start_end_and_row(tmp_path):
    t = np.r_[np.arange(0, 1.0, 0.01), np.arange(1.5, 2.0, 0.01), np.arange(2.05, 2.5, 0.01)]
    p = write_telemetry(tmp_path / "g.csv", t, {"x": (np.zeros_like(t), "m")}, float_format="%.12g")
    tel = read_telemetry(p)
    assert len(tel.gaps) == 2
    g0, g1 = tel.gaps
    assert g0.start_s == pytest.approx(0.99) and g0.end_s == pytest.approx(1.5)
    assert g0.duration_s == pytest.approx(0.51) and g0.row == 101
    assert tel.time[g0.row - 1] == g0.end_s
    assert (g1.start_s, g1.end_s) == pytest.approx((1.99, 2.05)) and g1.row == 151
    assert len(read_telemetry(p, gap_factor=10.0).gaps) == 1
    assert len(read_telemetry(p, nominal_dt=0.1).gaps) == 1


def test_gap_uses_rate_hz_metadata(tmp_path):
    text = "# rate_hz: 1000\ntime [s],x [m]\n0,0\n0.01,0\n0.02,0\n0.03,0\n"
    tel = read_telemetry(write(tmp_path, text))
    assert len(tel.gaps) == 3  # 10 ms steps are gaps at a declared 1 kHz


def test_sparse_channel(tmp_path):
    text = "# sparse: R1\ntime [s],acc [g],R1 [km]\n0,1,\n0.1,1,2.5\n0.2,1,\n0.3,1,2.4\n"
    tel = read_telemetry(write(tmp_path, text))
    assert np.isnan(tel.channel("R1")[[0, 2]]).all()
    ts, r = tel.samples("R1")
    np.testing.assert_allclose(ts, [0.1, 0.3])
    np.testing.assert_allclose(r, [2500.0, 2400.0])
    # a sparse channel still refuses a literal nan, and a dense one its empty cells
    err = one_error(write(tmp_path, text.replace("0.2,1,", "0.2,,nan")))
    assert [(q.column, q.row, q.reason[:12]) for q in err.problems] == [
        ("acc [g]", 3, "empty cell ("),
        ("R1 [km]", 3, "value is NaN"),
    ]
    # declared by keyword instead of metadata; round trip through write_telemetry
    tel2 = read_telemetry(write(tmp_path, text.split("\n", 1)[1]), sparse=["R1"])
    np.testing.assert_array_equal(np.isnan(tel2.channel("R1")), [True, False, True, False])
    p = write_telemetry(tmp_path / "w.csv", tel2.time, {"R1": (tel2.channel("R1"), "m")}, sparse=["R1"])
    assert "# sparse: R1" in p.read_text()
    np.testing.assert_array_equal(read_telemetry(p).channel("R1"), tel2.channel("R1"))


# ---- writing -------------------------------------------------------------------------------


def test_write_refuses_nan_naming_channel_and_index(tmp_path):
    x = np.array([1.0, 2.0, np.nan, 4.0])
    with pytest.raises(ValueError, match=r"imu.csv: channel 'BP.x' has nan at index 2 \(time 0.2 s\)"):
        write_telemetry(tmp_path / "imu.csv", [0.0, 0.1, 0.2, 0.3], {"BP.x": (x, "g")})
    assert not list(tmp_path.iterdir())


def test_write_refuses_bad_time_and_names(tmp_path):
    with pytest.raises(ValueError, match="strictly increasing; index 2"):
        write_telemetry(tmp_path / "a.csv", [0.0, 0.1, 0.1], {"x": (np.zeros(3), "m")})
    with pytest.raises(ValueError, match="channel name 'x,y'"):
        write_telemetry(tmp_path / "a.csv", [0.0, 0.1], {"x,y": (np.zeros(2), "m")})
    with pytest.raises(ValueError, match=r"shape \(3,\), time has \(2,\)"):
        write_telemetry(tmp_path / "a.csv", [0.0, 0.1], {"x": (np.zeros(3), "m")})


def test_atomic_write_leaves_no_temp_file(tmp_path, monkeypatch):
    p = write_telemetry(tmp_path / "imu.csv", [0.0, 1.0], {"x": (np.ones(2), "m")})
    assert sorted(os.listdir(tmp_path)) == ["imu.csv"]
    before = p.read_text()

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(tm.os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        write_telemetry(p, [0.0, 1.0], {"x": (np.zeros(2), "m")})
    assert sorted(os.listdir(tmp_path)) == ["imu.csv"]  # no temp file left behind
    assert p.read_text() == before  # old file intact


# ---- events --------------------------------------------------------------------------------


def test_events_round_trip(tmp_path):
    ev = [(0.0, "release"), (0.8125, "bungee_cut"), (0.8125, "contact, first bounce"), (2.1, "max_stroke")]
    p = write_events(tmp_path / "events.csv", ev, meta={"source": "daq"})
    assert p.read_text().startswith("# source: daq\ntime [s],event\n0,release\n")
    assert read_events(p) == ev


def test_events_in_ms_and_errors(tmp_path):
    p = write(tmp_path, "time [ms],event\n0,release\n812.5,bungee_cut\n", "events.csv")
    assert read_events(p) == [(0.0, "release"), (0.8125, "bungee_cut")]
    p = write(tmp_path, "time [s],event\n0,release\n0.5,\nx,contact\n0.2,stop\n", "events.csv")
    with pytest.raises(TelemetryError) as info:
        read_events(p)
    got = [(q.column, q.row, q.line) for q in info.value.problems]
    assert got == [("event", 2, 3), ("time [s]", 3, 4), ("time [s]", 4, 5)]
    assert "time goes backwards: 0.2 after 0.5 at row 2" in str(info.value)
    with pytest.raises(ValueError, match="before"):
        write_events(tmp_path / "e.csv", [(1.0, "a"), (0.5, "b")])


def test_atomic_npz_round_trips_and_leaves_nothing_behind_on_failure(tmp_path):
    """truth.npz written atomically: every array back exactly (floats, strings, scalars), deflated
    smaller than stored; an array it refuses (an object array: no pickles) leaves neither the file
    nor a temp file, and an existing file under the name is kept as it was."""
    rng = np.random.default_rng(0)
    arrays = {
        "t": np.linspace(0.0, 2.0, 4001),
        "p_I": np.cumsum(rng.normal(size=(4001, 3)), axis=0),
        "names": np.array(["release", "first_contact"]),
        "seed": 7,
    }
    packed = tm.atomic_write_npz(tmp_path / "truth.npz", arrays)
    stored = tm.atomic_write_npz(tmp_path / "stored.npz", arrays, compress=False)
    for path in (packed, stored):
        with np.load(path) as z:
            assert sorted(z.files) == sorted(arrays)
            for k, v in arrays.items():
                np.testing.assert_array_equal(z[k], v)
    assert packed.stat().st_size < 0.9 * stored.stat().st_size
    before = packed.read_bytes()
    with pytest.raises(ValueError):
        tm.atomic_write_npz(packed, {"t": arrays["t"], "bad": np.array([{"a": 1}], dtype=object)})
    assert packed.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stored.npz", "truth.npz"]
