"""The rocket cross-checks (``rocket_checks``) on the three real flights, when the data are present:
no false alarm on any of them, and on flight 1 (full rate, the magnetometer aligned in flight) the
checks the decimated excerpt cannot exercise fire on its mutations — all accelerations sign-flipped
(the aligned dip changes sign), 199 coast rows removed, an observation rate above the packet rate.

Needs ``EDL_FLIGHT_DATA`` (a folder containing ``airbrakes_firm/``); skipped with the reason otherwise.
"""

from __future__ import annotations

import json
import math

import pytest
from flight_data import FLIGHTS, SITE_MAGNETIC, airbrakes_dir

from workbench.estimation.health import ERROR, OK
from workbench.problems.post2.importers.airbrakes import import_flight

DATA, WHY = airbrakes_dir()

pytestmark = [pytest.mark.slow, pytest.mark.skipif(DATA is None, reason=WHY)]


def _checks(log, tmp_path, **kw) -> dict:
    dec, inc = SITE_MAGNETIC[log.name]
    out = tmp_path / "flight"
    import_flight(log, DATA / "metadata.json", out, declination_deg=dec, inclination_deg=inc, **kw)
    fl = json.loads((out / "flight.json").read_text(encoding="utf-8"))
    return {c["name"]: c for c in fl["health_checks"]["checks"]}


@pytest.mark.parametrize("log", FLIGHTS)
def test_no_false_alarm_on_the_real_flights(log, tmp_path):
    checks = _checks(DATA / log, tmp_path)
    assert {n: c["message"] for n, c in checks.items() if c["status"] != OK} == {}
    assert checks["physics.magnetic_dip"]["status"] == OK  # the aligned magnetometer is checked too


def _mutated(tmp_path, log: str, fn) -> object:
    lines = (DATA / log).read_text(encoding="utf-8").splitlines()
    tmp_path.mkdir(parents=True, exist_ok=True)
    p = tmp_path / log
    p.write_text("\n".join(fn(lines)) + "\n", encoding="utf-8")
    return p


def _columns(pattern: str, fn):
    """A line edit applying ``fn`` to the three cells (strings) of the columns ``pattern.format(c)``,
    c in x, y, z, of every data row."""

    def edit(lines):
        head = lines[0].split(",")
        idx = [head.index(pattern.format(c)) for c in "xyz"]
        out = [lines[0]]
        for ln in lines[1:]:
            cells = ln.split(",")
            for i, v in zip(idx, fn([cells[i] for i in idx]), strict=True):
                cells[i] = v
            out.append(",".join(cells))
        return out

    return edit


GYRO = "raw_angular_rate_{}_deg_per_s"
_flip = _columns("raw_acceleration_{}_gs", lambda v: [repr(-float(x)) for x in v])


def _cut_coast(lines):
    coast = [i for i, ln in enumerate(lines) if ln.startswith("C,")]
    cut = set(coast[len(coast) // 2 : len(coast) // 2 + 199])
    return [ln for i, ln in enumerate(lines) if i not in cut]


def test_flight_1_mutations(tmp_path):
    log = FLIGHTS[0]
    c = _checks(_mutated(tmp_path / "a", log, _flip), tmp_path / "a", allow_unhealthy=True)
    assert c["physics.magnetic_dip"]["status"] == ERROR and "sign-flipped" in c["physics.magnetic_dip"]["message"]
    assert c["geometry.accel_sign"]["status"] == ERROR
    c = _checks(_mutated(tmp_path / "b", log, _cut_coast), tmp_path / "b", allow_unhealthy=True)
    assert c["data.gap.coast"]["status"] == ERROR and c["data.gap.coast"]["value"] > 2.0
    c = _checks(DATA / log, tmp_path / "c", allow_unhealthy=True, obs_rate_hz=200.0)
    assert c["timing.observation_rate"]["status"] == ERROR


def test_flight_1_gyro_in_rad_per_s(tmp_path):
    rad = _columns(GYRO, lambda v: [repr(math.radians(float(x))) for x in v])
    c = _checks(_mutated(tmp_path, FLIGHTS[0], rad), tmp_path, allow_unhealthy=True)
    assert c["units.gyro"]["status"] == ERROR


@pytest.mark.parametrize(
    "what, fn",
    [
        ("x<->y", lambda g: [g[1], g[0], g[2]]),
        ("z negated", lambda g: [g[0], g[1], repr(-float(g[2]))]),
    ],
)
def test_flight_1_gyro_axes_mirrored_against_the_magnetometer(tmp_path, what, fn):
    # a swap or a single sign flip mirrors the gyro's frame: the field no longer turns with its rates
    c = _checks(_mutated(tmp_path, FLIGHTS[0], _columns(GYRO, fn)), tmp_path, allow_unhealthy=True)
    gm = c["geometry.gyro_magnetometer"]
    assert gm["status"] == ERROR, what
    assert "mirror image" in gm["message"] and "raw_angular_rate_[xyz]_deg_per_s" in gm["message"]
