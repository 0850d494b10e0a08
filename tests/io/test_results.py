"""Summary JSON and CSV exports (workbench.io.results)."""

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pytest

from workbench.io.results import export_csv, read_summary, to_jsonable, write_summary
from workbench.io.telemetry import read_telemetry


@dataclasses.dataclass(frozen=True)
class Stroke:
    max_m: float
    sigma_m: np.ndarray
    where: Path


def test_to_jsonable_numpy_nan_dataclass_path():
    obj = {
        "n": np.int64(3),
        "x": np.float32(0.5),
        "ok": np.bool_(True),
        "nan": float("nan"),
        "inf": -np.inf,
        "arr": np.array([[1.0, np.nan], [np.inf, 2.0]]),
        "ints": np.arange(3),
        "stroke": Stroke(0.4, np.array([0.01, 0.02]), Path("/tmp/a.rrd")),
        "tup": (1, np.float64(2.5)),
        7: "int key",
    }
    out = to_jsonable(obj)
    assert out == {
        "n": 3,
        "x": 0.5,
        "ok": True,
        "nan": None,
        "inf": "-inf",
        "arr": [[1.0, None], ["inf", 2.0]],
        "ints": [0, 1, 2],
        "stroke": {"max_m": 0.4, "sigma_m": [0.01, 0.02], "where": "/tmp/a.rrd"},
        "tup": [1, 2.5],
        "7": "int key",
    }
    assert type(out["n"]) is int and type(out["x"]) is float
    json.dumps(out, allow_nan=False)  # strictly valid JSON


def test_to_jsonable_names_where_it_fails():
    with pytest.raises(TypeError, match=r"summary\['a'\]\[1\]: cannot convert object"):
        to_jsonable({"a": [1, object()]})


def test_summary_round_trip_keeps_key_order(tmp_path):
    summary = {"scenario": "spf", "z_last": 1, "a_first": np.array([np.nan, 1.5]), "rmse": np.float64(0.25)}
    p = write_summary(tmp_path / "run.summary.json", summary)
    assert os.listdir(tmp_path) == ["run.summary.json"]
    text = p.read_text()
    assert text.index('"z_last"') < text.index('"a_first"')
    assert '"a_first": [\n    null,\n    1.5\n  ]' in text  # indent 2
    assert read_summary(p) == {"scenario": "spf", "z_last": 1, "a_first": [None, 1.5], "rmse": 0.25}


def test_read_summary_reports_file_and_line(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text('{\n  "a": 1,\n  "b": \n}\n')
    with pytest.raises(ValueError, match=r"bad.json, line 4 column 1: invalid JSON"):
        read_summary(p)


def test_export_reads_back_with_read_telemetry(tmp_path):
    t = np.linspace(0.0, 2.0, 21)
    alt = 1000.0 - 40.0 * t
    sig = np.full_like(t, 0.125)
    p = export_csv(tmp_path / "export.csv", t, {"alt": (alt, "km"), "sigma_alt": (sig, "m")}, meta={"pass": "smoothed"})
    tel = read_telemetry(p, required={"alt": "length"})
    np.testing.assert_allclose(tel.channel("alt"), alt, rtol=1e-12)
    np.testing.assert_allclose(tel.channel("sigma_alt"), sig)
    assert tel.meta["pass"] == "smoothed" and tel.units["alt"] == "km"
    with pytest.raises(ValueError, match="'alt' has nan at index 0"):
        export_csv(tmp_path / "e2.csv", t, {"alt": (np.full_like(t, np.nan), "m")})
