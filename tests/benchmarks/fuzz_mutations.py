"""The mutations users make (issue 26, item 5): seeded edits of a user's FILES — telemetry CSVs,
scenario/setup/vehicle TOMLs, a rocket log and its ``metadata.json`` — in the seven classes of the
issue: ``axis_swap``, ``sign_flip``, ``unit`` (a plausible-unit mistake: values in one unit under a
header or key of another), ``geometry``, ``truncation`` (data ending or breaking at a key event),
``timing`` (mis-declared filtering, latency, rates) and ``metadata`` (mass, Cd, motor, site).

A :class:`Mutation` edits a copy of a *base* folder (``workbench init <scenario>`` output, or the
rocket log with its metadata) in place; ``tests/benchmarks/bench_fuzz.py`` runs the edited folder
through the same reading, validation and reconstruction path as a user's data and scores it against
the unmutated base.  :func:`catalogue` lists every mutation of every base, deterministically from a
seed.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CLASSES = ("axis_swap", "sign_flip", "unit", "geometry", "truncation", "timing", "metadata")
G0 = 9.80665
DEG = math.pi / 180.0


@dataclass(frozen=True)
class Mutation:
    """One user mistake: its ``cls`` (one of :data:`CLASSES`), the ``problem`` it is scored under,
    the ``base`` folder it edits, ``what`` (one line), ``edit(folder)`` applying it to a copy of the
    base in place, the ``file`` and ``column``/``key`` it touches (a clear error names one of them),
    and for the rocket importer extra command-line ``import_args``."""

    cls: str
    problem: str
    base: str
    what: str
    edit: Callable[[Path], None]
    file: str
    names: tuple[str, ...] = ()
    import_args: tuple[str, ...] = field(default=())

    @property
    def key(self) -> str:
        """A stable identifier ``problem/cls/what``."""
        return f"{self.problem}/{self.cls}/{self.what}"


# ------------------------------------------------------------------------------------- CSV files
class Csv:
    """A telemetry CSV as a user's editor sees it: the comment lines, the header cells and the data
    rows as strings (cells keep their text unless a column is rewritten)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        text = self.path.read_text(encoding="utf-8")
        lines = text.split("\n")
        h = next(i for i, s in enumerate(lines) if s.strip() and not s.lstrip().startswith("#"))
        self.pre = lines[:h]
        self.header = lines[h].split(",")
        self.rows = [s.split(",") for s in lines[h + 1 :] if s.strip() and not s.lstrip().startswith("#")]
        self.post = [s for s in lines[h + 1 :] if s.lstrip().startswith("#")]

    def col(self, name: str) -> int:
        """Index of the column whose name (before `` [unit]``) is ``name``."""
        for j, c in enumerate(self.header):
            if re.sub(r"\s*\[.*\]\s*$", "", c).strip() == name:
                return j
        raise KeyError(f"{self.path.name}: no column {name!r} in {self.header}")

    def values(self, name: str) -> np.ndarray:
        """The column ``name`` as floats (NaN for empty cells)."""
        j = self.col(name)
        return np.array([float(r[j]) if r[j].strip() else np.nan for r in self.rows])

    def set_values(self, name: str, v: np.ndarray) -> None:
        """Rewrite column ``name`` with ``v`` (empty cells stay empty)."""
        j = self.col(name)
        for r, x in zip(self.rows, v, strict=True):
            if r[j].strip():
                r[j] = f"{x:.10g}"

    def map(self, name: str, f: Callable[[np.ndarray], np.ndarray]) -> None:
        """Column ``name`` replaced by ``f(column)``."""
        self.set_values(name, f(self.values(name)))

    def swap(self, a: str, b: str) -> None:
        """The data of columns ``a`` and ``b`` exchanged (the header stays: a wiring/axis mix-up)."""
        i, j = self.col(a), self.col(b)
        for r in self.rows:
            r[i], r[j] = r[j], r[i]

    def time(self) -> np.ndarray:
        """The first column (time) as floats."""
        return np.array([float(r[0]) for r in self.rows])

    def keep(self, mask: np.ndarray) -> None:
        """Keep only the rows where ``mask``."""
        self.rows = [r for r, k in zip(self.rows, mask, strict=True) if k]

    def save(self) -> None:
        """Write back (same comment lines, header, newline at the end)."""
        lines = [*self.pre, ",".join(self.header), *(",".join(r) for r in self.rows), *self.post]
        self.path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def csv_edit(rel: str, *ops: Callable[[Csv], None]) -> Callable[[Path], None]:
    """An edit of the CSV ``rel`` (relative to the case folder) applying ``ops`` in order."""

    def edit(folder: Path) -> None:
        c = Csv(folder / rel)
        for op in ops:
            op(c)
        c.save()

    return edit


def scale(*names: str, k: float) -> Callable[[Csv], None]:
    """Columns ``names`` multiplied by ``k``."""
    return lambda c: [c.map(n, lambda v: v * k) for n in names]


def offset(*names: str, d: float) -> Callable[[Csv], None]:
    """Columns ``names`` shifted by ``d``."""
    return lambda c: [c.map(n, lambda v: v + d) for n in names]


def swap(a: str, b: str) -> Callable[[Csv], None]:
    """Data of columns ``a`` and ``b`` exchanged."""
    return lambda c: c.swap(a, b)


def time_scale(k: float) -> Callable[[Csv], None]:
    """The time column multiplied by ``k`` (e.g. ms written under ``[s]``)."""

    def op(c: Csv) -> None:
        j = 0
        for r in c.rows:
            r[j] = f"{float(r[j]) * k:.10g}"

    return op


def time_shift(d: float) -> Callable[[Csv], None]:
    """The time column shifted by ``d`` [s] (a latency between streams)."""

    def op(c: Csv) -> None:
        for r in c.rows:
            r[0] = f"{float(r[0]) + d:.10g}"

    return op


def end_at(t_end: float) -> Callable[[Csv], None]:
    """Rows after ``t_end`` [s] removed (the file ends there)."""
    return lambda c: c.keep(c.time() <= t_end)


def drop_between(t0: float, t1: float) -> Callable[[Csv], None]:
    """Rows in ``[t0, t1]`` [s] removed (a gap)."""
    return lambda c: c.keep(~((c.time() >= t0) & (c.time() <= t1)))


def comment(key: str, value: str) -> Callable[[Csv], None]:
    """The ``# key: value`` comment line set (added when absent)."""

    def op(c: Csv) -> None:
        for i, s in enumerate(c.pre):
            if re.match(rf"^#\s*{re.escape(key)}\s*:", s):
                c.pre[i] = f"# {key}: {value}"
                return
        c.pre.append(f"# {key}: {value}")

    return op


# ------------------------------------------------------------------------------------- TOML files
def _toml_literal(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_literal(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, float) else str(v)


def toml_get(path: Path, table: str, key: str):
    """The value of ``key`` in ``[table]`` of the TOML at ``path`` (None when absent)."""
    import tomllib

    d = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    for part in table.split(".") if table else []:
        d = d.get(part, {})
    return d.get(key)


def toml_set(path: Path, table: str, key: str, value) -> None:
    """``key = value`` in ``[table]`` of the TOML at ``path``, as a user edits it: the key's line
    (active or commented out) is replaced, else the line is added under the table header (the
    table is added at the end when absent)."""
    p = Path(path)
    lines = p.read_text(encoding="utf-8").split("\n")
    lit = f"{key} = {_toml_literal(value)}"
    head = next((i for i, s in enumerate(lines) if s.strip() == f"[{table}]"), None)
    if head is None:
        lines += ["", f"[{table}]", lit]
    else:
        end = next((i for i in range(head + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
        hit = [i for i in range(head + 1, end) if re.match(rf"^\s*{re.escape(key)}\s*=", lines[i])]
        if not hit:
            hit = [i for i in range(head + 1, end) if re.match(rf"^\s*#\s*{re.escape(key)}\s*=", lines[i])]
        if hit:
            lines[hit[0]] = lit
        else:
            lines.insert(head + 1, lit)
    p.write_text("\n".join(lines), encoding="utf-8")


def toml_edit(rel: str, table: str, key: str, f: Callable) -> Callable[[Path], None]:
    """An edit of ``key`` in ``[table]`` of the TOML ``rel``: its new value is ``f(old value)``."""

    def edit(folder: Path) -> None:
        p = folder / rel
        toml_set(p, table, key, f(toml_get(p, table, key)))

    return edit


def declared_instead_of_detected(rel: str, table: str, value: float) -> Callable[[Path], None]:
    """An event whose time the scenario reads from the data (``detect_in``) declared by hand as
    ``value`` [s] instead (the ``detect_in`` line replaced by ``value = ...``), as a user who copied
    a time from a plot does."""

    def edit(folder: Path) -> None:
        p = folder / rel
        lines = p.read_text(encoding="utf-8").split("\n")
        head = next(i for i, s in enumerate(lines) if s.strip() == f"[{table}]")
        k = next(i for i in range(head + 1, len(lines)) if re.match(r"^\s*detect_in\s*=", lines[i]))
        lines[k] = f"value = {float(value)!r}"
        p.write_text("\n".join(lines), encoding="utf-8")

    return edit


def vec(f: Callable[[np.ndarray], np.ndarray]) -> Callable:
    """A TOML-value function applying ``f`` to a vector value (returns a list)."""
    return lambda v: [float(x) for x in f(np.asarray(v, float))]


def json_edit(rel: str, path: tuple[str, ...], f: Callable) -> Callable[[Path], None]:
    """An edit of the JSON value at ``path`` (keys from the top) of the JSON file ``rel``."""

    def edit(folder: Path) -> None:
        p = folder / rel
        d = json.loads(p.read_text(encoding="utf-8"))
        node = d
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = f(node[path[-1]])
        p.write_text(json.dumps(d, indent=2), encoding="utf-8")

    return edit


def both(*edits: Callable[[Path], None]) -> Callable[[Path], None]:
    """Several edits as one mutation."""

    def edit(folder: Path) -> None:
        for e in edits:
            e(folder)

    return edit


# ------------------------------------------------------------------------------------- catalogue
def _pick(rng: np.random.Generator, items: list, n: int) -> list:
    """``n`` of ``items`` (all of them when fewer), in a seeded random order."""
    if len(items) <= n:
        return list(items)
    idx = rng.choice(len(items), size=n, replace=False)
    return [items[i] for i in sorted(idx)]


def _droptest(problem: str, base: str, rng: np.random.Generator, ranging: bool) -> list[Mutation]:
    """Drop test (telemetry of ``workbench init droptest[_ranging]``): IMU ``telemetry/imu.csv``
    (triads BP, PYBP, PXBP, MXBP in g, gyro in deg/s), ``3dm.csv``, ``events.csv``,
    ``setup.toml``, ``ranging.csv``; lander ``mer_drop_lander.toml``; ``scenario.toml``.  Release at
    0 s, contact ≈ 1.365–1.650 s, max stroke ≈ 1.655 s."""
    imu, tdm, ev, setup, lander, sc = (
        "telemetry/imu.csv",
        "telemetry/3dm.csv",
        "telemetry/events.csv",
        "telemetry/setup.toml",
        "mer_drop_lander.toml",
        "scenario.toml",
    )
    triads = ["BP", "PYBP", "PXBP", "MXBP"]
    out: list[Mutation] = []

    def m(cls, what, edit, file, *names, args=()):
        out.append(Mutation(cls, problem, base, what, edit, file, tuple(names), args))

    # axis swaps
    swaps = [(t, a, b) for t in [*triads, "gyro"] for a, b in (("x", "y"), ("y", "z"), ("x", "z"))]
    for t, a, b in _pick(rng, swaps, 6):
        m("axis_swap", f"{t}.{a}<->{t}.{b}", csv_edit(imu, swap(f"{t}.{a}", f"{t}.{b}")), imu, f"{t}.{a}", f"{t}.{b}")
    m(
        "axis_swap",
        "every triad x<->y (the IMU mounted turned 90 deg)",
        csv_edit(imu, *[swap(f"{t}.x", f"{t}.y") for t in triads]),
        imu,
        "x",
    )
    for v, a, b in _pick(rng, [("up", "x", "y"), ("mag", "x", "z"), ("up", "y", "z"), ("mag", "x", "y")], 2):
        m("axis_swap", f"3dm {v}.{a}<->{v}.{b}", csv_edit(tdm, swap(f"{v}.{a}", f"{v}.{b}")), tdm, f"{v}.{a}")
    # sign flips
    flips = [(t, a) for t in [*triads, "gyro"] for a in "xyz"]
    for t, a in _pick(rng, flips, 6):
        m("sign_flip", f"{t}.{a} negated", csv_edit(imu, scale(f"{t}.{a}", k=-1.0)), imu, f"{t}.{a}")
    m("sign_flip", "all accelerometer z negated", csv_edit(imu, scale(*[f"{t}.z" for t in triads], k=-1.0)), imu, "z")
    m("sign_flip", "every gyro axis negated", csv_edit(imu, scale("gyro.x", "gyro.y", "gyro.z", k=-1.0)), imu, "gyro")
    m("sign_flip", "3dm up vector reversed", csv_edit(tdm, scale("up.x", "up.y", "up.z", k=-1.0)), tdm, "up")
    m("sign_flip", "3dm magnetic field reversed", csv_edit(tdm, scale("mag.x", "mag.y", "mag.z", k=-1.0)), tdm, "mag")
    m(
        "sign_flip",
        "magnetic_field_spf reversed in the scenario",
        toml_edit(sc, "chamber", "magnetic_field_spf", vec(lambda v: -v)),
        sc,
        "magnetic_field_spf",
    )
    # plausible units
    t = str(rng.choice(triads))
    m("unit", f"{t} triad in m/s^2 under [g]", csv_edit(imu, scale(*[f"{t}.{a}" for a in "xyz"], k=G0)), imu, t)
    m(
        "unit",
        "every triad in m/s^2 under [g]",
        csv_edit(imu, scale(*[f"{t}.{a}" for t in triads for a in "xyz"], k=G0)),
        imu,
        "g",
    )
    m("unit", "gyro in rad/s under [deg/s]", csv_edit(imu, scale("gyro.x", "gyro.y", "gyro.z", k=DEG)), imu, "gyro")
    m("unit", "IMU time in ms under [s]", csv_edit(imu, time_scale(1000.0)), imu, "time")
    c = f"{rng.choice(triads)}.{rng.choice(list('xyz'))}"
    m("unit", f"one column {c} x1000", csv_edit(imu, scale(c, k=1000.0)), imu, c)
    m("unit", "hanging position in cm", toml_edit(setup, "hanging", "position_m", vec(lambda v: v * 100)), setup)
    m("unit", "airbag pressure in kPa", toml_edit(lander, "airbags", "pressure_pa", lambda v: v / 1000), lander)
    if ranging:
        m(
            "unit",
            "radar ranges in km under [m]",
            csv_edit("telemetry/ranging.csv", scale("G1.range", "G2.range", "G3.range", k=1e-3)),
            "telemetry/ranging.csv",
            "range",
        )
        m(
            "unit",
            "radar range rates in mph under [m/s]",
            csv_edit("telemetry/ranging.csv", scale("G1.rate", "G2.rate", "G3.rate", k=2.23694)),
            "telemetry/ranging.csv",
            "rate",
        )
    # geometry
    ax = int(rng.integers(2))
    m(
        "geometry",
        f"hanging position +1 m along SPF {'xyz'[ax]}",
        toml_edit(setup, "hanging", "position_m", vec(lambda v: v + np.eye(3)[ax])),
        setup,
        "position_m",
    )
    m(
        "geometry",
        "hanging position +1 m along SPF z",
        toml_edit(setup, "hanging", "position_m", vec(lambda v: v + np.eye(3)[2])),
        setup,
        "position_m",
    )
    m("geometry", "lander height x1.2", toml_edit(lander, "lander", "height_m", lambda v: v * 1.2), lander, "height_m")
    m(
        "geometry",
        "ramp angle in rad",
        toml_edit(sc, "chamber", "ramp_angle_deg", lambda v: v * DEG),
        sc,
        "ramp_angle_deg",
    )
    m(
        "geometry",
        "ramp angle 50 deg (another ramp)",
        toml_edit(sc, "chamber", "ramp_angle_deg", lambda v: v - 10.0),
        sc,
        "ramp_angle_deg",
    )
    m(
        "geometry",
        "CM height x1.5",
        toml_edit(lander, "lander", "cm_height_m", lambda v: v * 1.5),
        lander,
        "cm_height_m",
    )
    m("geometry", "nail depth 0.6 m", toml_edit(sc, "chamber", "nail_depth_m", lambda v: 0.6), sc, "nail_depth_m")
    t = str(rng.choice(triads))
    m(
        "geometry",
        f"{t} position x/y swapped in the lander file",
        toml_edit(lander, "instruments", t, vec(lambda v: v[[1, 0, 2]])),
        lander,
        t,
    )
    if ranging:
        m(
            "geometry",
            "radar gun G1 x/y swapped",
            toml_edit(sc, "sensors.ranging.radar_guns", "G1", vec(lambda v: v[[1, 0, 2]])),
            sc,
            "G1",
        )
    # truncation at key events
    for t_end, why in ((1.45, "mid-contact"), (1.30, "before contact"), (1.52, "after max stroke, bags pressed")):
        m("truncation", f"IMU ends at {t_end} s ({why})", csv_edit(imu, end_at(t_end)), imu)
    m("truncation", "IMU rows 1.40-1.46 s removed (gap in contact)", csv_edit(imu, drop_between(1.40, 1.46)), imu)
    m("truncation", "3dm ends after 0.1 s of hanging", csv_edit(tdm, end_at(-0.4)), tdm)
    if ranging:
        m(
            "truncation",
            "ranging ends mid-contact",
            csv_edit("telemetry/ranging.csv", end_at(1.45)),
            "telemetry/ranging.csv",
        )
    # timing
    acq = "sensors.acquisition"
    m(
        "timing",
        "filter declared zero_phase, data causal",
        toml_edit(sc, acq, "filter", lambda v: "zero_phase"),
        sc,
        "filter",
    )
    m("timing", "filter declared none, data causal", toml_edit(sc, acq, "filter", lambda v: "none"), sc, "filter")
    m("timing", "IMU latency 2 ms declared, none", toml_edit(sc, acq, "latency_s", lambda v: 0.002), sc, "latency_s")
    m("timing", "release event 20 ms late", _event_shift(ev, "release", 0.02), ev, "release")
    m("timing", "3dm time +5 ms", csv_edit(tdm, time_shift(0.005)), tdm)
    m(
        "timing",
        "filter rate above the IMU sample rate (4 kHz)",
        toml_edit(sc, "filter", "rate_hz", lambda v: 4000.0),
        sc,
        "rate_hz",
    )
    m(
        "timing",
        "sample rate declared 1 kHz (data 2 kHz)",
        toml_edit(sc, acq, "sample_rate_hz", lambda v: 1000.0),
        sc,
        "sample_rate_hz",
    )
    if ranging:
        m("timing", "ranging time +5 ms", csv_edit("telemetry/ranging.csv", time_shift(0.005)), "telemetry/ranging.csv")
        m(
            "timing",
            "ranging declared through the acquisition filter",
            toml_edit(sc, "sensors.ranging", "acquisition_filter", lambda v: True),
            sc,
            "acquisition_filter",
        )
    # metadata
    m("metadata", "lander mass x10", toml_edit(lander, "lander", "mass_kg", lambda v: v * 10), lander, "mass_kg")
    m("metadata", "lander mass in lb", toml_edit(lander, "lander", "mass_kg", lambda v: v * 2.20462), lander, "mass_kg")
    m(
        "metadata",
        "accelerometer noise_g x10",
        toml_edit(sc, "sensors.accelerometer", "noise_g", lambda v: v * 10),
        sc,
        "noise_g",
    )
    m(
        "metadata",
        "gyro noise in rad/s under noise_dps",
        toml_edit(sc, "sensors.gyro", "noise_dps", lambda v: v * DEG),
        sc,
        "noise_dps",
    )
    m(
        "metadata",
        "hanging position sigma x10 too small",
        toml_edit(setup, "hanging", "position_sigma_m", lambda v: v / 10),
        setup,
        "position_sigma_m",
    )
    m(
        "metadata",
        "accelerometer full scale in m/s^2",
        toml_edit(sc, "sensors.accelerometer", "full_scale_g", lambda v: v * G0),
        sc,
        "full_scale_g",
    )
    return out


def _event_shift(rel: str, name: str, d: float) -> Callable[[Path], None]:
    """The time of event ``name`` in the events CSV ``rel`` shifted by ``d`` [s]."""

    def edit(folder: Path) -> None:
        c = Csv(folder / rel)
        j = c.col("event")
        for r in c.rows:
            if r[j].strip() == name:
                r[0] = f"{float(r[0]) + d:.10g}"
        c.save()

    return edit


def _zero_phase(problem: str, base: str) -> list[Mutation]:
    """The issue's case: a drop with ranging whose IMU went through a zero-phase filter, declared
    causal (and the latency/rate variants), on the base synthesized with ``filter = "zero_phase"``."""
    sc, acq = "scenario.toml", "sensors.acquisition"
    return [
        Mutation(
            "timing",
            problem,
            base,
            "zero-phase filter declared causal (butterworth)",
            toml_edit(sc, acq, "filter", lambda v: "butterworth"),
            sc,
            ("filter",),
        ),
        Mutation(
            "timing",
            problem,
            base,
            "zero-phase filter declared causal, order 8",
            both(
                toml_edit(sc, acq, "filter", lambda v: "butterworth"), toml_edit(sc, acq, "filter_order", lambda v: 8)
            ),
            sc,
            ("filter",),
        ),
        Mutation(
            "timing",
            problem,
            base,
            "zero-phase filter declared causal, cutoff 250 Hz",
            both(
                toml_edit(sc, acq, "filter", lambda v: "butterworth"),
                toml_edit(sc, acq, "filter_cutoff_hz", lambda v: 250.0),
            ),
            sc,
            ("filter",),
        ),
        Mutation(
            "timing",
            problem,
            base,
            "IMU latency 1 ms declared, none",
            toml_edit(sc, acq, "latency_s", lambda v: 0.001),
            sc,
            ("latency_s",),
        ),
    ]


def _entry(rng: np.random.Generator) -> list[Mutation]:
    """Entry (``workbench init schiaparelli``): ``gnc.csv`` (w deg/s, JPL quaternion q1..q4, a m/s²,
    10 Hz), ``gnc_nav.csv`` (p km, v km/s, 1 Hz), ``rda_out.csv``, ``rda_slant_range.csv``,
    ``events.csv`` (PDD 180.48 s, FSR 221.48 s, RDA_ON 225.48 s, BSR 262.48 s),
    ``initial_state.toml``, vehicle ``schiaparelli.toml``."""
    P, g, nav, out_, ev, ini, veh, sc = (
        "entry",
        "telemetry/gnc.csv",
        "telemetry/gnc_nav.csv",
        "telemetry/rda_out.csv",
        "telemetry/events.csv",
        "telemetry/initial_state.toml",
        "schiaparelli.toml",
        "scenario.toml",
    )
    out: list[Mutation] = []

    def m(cls, what, edit, file, *names):
        out.append(Mutation(cls, P, "entry", what, edit, file, tuple(names)))

    for a, b in _pick(rng, [("a_x", "a_y"), ("a_y", "a_z"), ("a_x", "a_z")], 3):
        m("axis_swap", f"{a}<->{b}", csv_edit(g, swap(a, b)), g, a, b)
    for a, b in _pick(rng, [("w_x", "w_y"), ("w_y", "w_z"), ("w_x", "w_z")], 3):
        m("axis_swap", f"{a}<->{b}", csv_edit(g, swap(a, b)), g, a, b)
    m(
        "axis_swap",
        "quaternion scalar first (q4 written as q1)",
        csv_edit(g, swap("q1", "q4"), swap("q2", "q4"), swap("q3", "q4")),
        g,
        "q1",
    )
    m("axis_swap", "rda v_out_x<->v_out_y", csv_edit(out_, swap("v_out_x", "v_out_y")), out_, "v_out_x")
    m("axis_swap", "gnc_nav p_x<->p_y", csv_edit(nav, swap("p_x", "p_y"), swap("v_x", "v_y")), nav, "p_x")
    for c in _pick(rng, ["a_x", "a_y", "a_z", "w_x", "w_y", "w_z"], 4):
        m("sign_flip", f"{c} negated", csv_edit(g, scale(c, k=-1.0)), g, c)
    m("sign_flip", "quaternion conjugated (Hamilton vs JPL)", csv_edit(g, scale("q1", "q2", "q3", k=-1.0)), g, "q1")
    m("sign_flip", "rda v_out_z negated", csv_edit(out_, scale("v_out_z", k=-1.0)), out_, "v_out_z")
    m("unit", "gnc_nav velocity in m/s under [km/s]", csv_edit(nav, scale("v_x", "v_y", "v_z", k=1000.0)), nav, "v_x")
    m("unit", "gnc_nav position in m under [km]", csv_edit(nav, scale("p_x", "p_y", "p_z", k=1000.0)), nav, "p_x")
    m("unit", "gnc time in ms", csv_edit(g, time_scale(1000.0)), g, "time")
    m("unit", "gnc rates in rad/s under [deg/s]", csv_edit(g, scale("w_x", "w_y", "w_z", k=DEG)), g, "w_x")
    m("unit", "gnc acceleration in g under [m/s^2]", csv_edit(g, scale("a_x", "a_y", "a_z", k=1 / G0)), g, "a_x")
    m("unit", "slant_out in ft", csv_edit(out_, scale("slant_out", k=3.28084)), out_, "slant_out")
    m(
        "unit",
        "initial velocity_kmps in m/s",
        toml_edit(ini, "initial_state", "velocity_kmps", vec(lambda v: v * 1000)),
        ini,
        "velocity_kmps",
    )
    m("unit", "one column a_z x1000", csv_edit(g, scale("a_z", k=1000.0)), g, "a_z")
    m("geometry", "terrain_m sign flipped (+1440 m)", toml_edit(sc, "site", "terrain_m", lambda v: -v), sc, "terrain_m")
    m("geometry", "terrain in km (-1.44)", toml_edit(sc, "site", "terrain_m", lambda v: v / 1000), sc, "terrain_m")
    m("geometry", "radar squint in rad", toml_edit(sc, "radar", "squint_deg", lambda v: v * DEG), sc, "squint_deg")
    m(
        "geometry",
        "initial position 20 km off",
        toml_edit(ini, "initial_state", "position_km", vec(lambda v: v + np.array([20.0, 0.0, 0.0]))),
        ini,
        "position_km",
    )
    m(
        "geometry",
        "radar azimuths mirrored",
        toml_edit(sc, "radar", "azimuths_deg", vec(lambda v: (-v) % 360)),
        sc,
        "azimuths_deg",
    )
    m("truncation", "GNC ends at the parachute opening (PDD + 1 s)", csv_edit(g, end_at(181.5)), g)
    m("truncation", "GNC ends inside peak deceleration (60 s)", csv_edit(g, end_at(60.0)), g)
    m("truncation", "GNC rows 179-186 s removed (gap at PDD)", csv_edit(g, drop_between(179.0, 186.0)), g)
    m("truncation", "rda_out ends 10 s after RDA_ON", csv_edit(out_, end_at(235.5)), out_)
    m("truncation", "gnc_nav ends at 100 s", csv_edit(nav, end_at(100.0)), nav)
    m("timing", "rda_out time +0.5 s", csv_edit(out_, time_shift(0.5)), out_)
    m("timing", "gnc_nav time +1 s", csv_edit(nav, time_shift(1.0)), nav)
    m("timing", "PDD event 2 s late", _event_shift(ev, "PDD", 2.0), ev, "PDD")
    m("timing", "gnc declared 100 Hz (data 10 Hz)", csv_edit(g, comment("rate_hz", "100")), g, "rate_hz")
    m("timing", "gnc time +50 ms", csv_edit(g, time_shift(0.05)), g)
    m("metadata", "entry mass x10", toml_edit(veh, "vehicle", "mass_entry_kg", lambda v: v * 10), veh, "mass_entry_kg")
    m(
        "metadata",
        "entry mass in lb",
        toml_edit(veh, "vehicle", "mass_entry_kg", lambda v: v * 2.20462),
        veh,
        "mass_entry_kg",
    )
    m("metadata", "diameter in ft", toml_edit(veh, "vehicle", "diameter_m", lambda v: v * 3.28084), veh, "diameter_m")
    m(
        "metadata",
        "atmosphere molar mass in kg/mol",
        toml_edit(sc, "atmosphere", "molar_mass_g_per_mol", lambda v: v / 1000),
        sc,
        "molar_mass_g_per_mol",
    )
    return out


def _meads(rng: np.random.Generator) -> list[Mutation]:
    """MEADS (``workbench init msl_meads``): ``pressures.csv`` (P1..P7 Pa, 8 Hz), ``imu.csv``
    (f m/s², w deg/s, 20 Hz), ``initial_state.toml``, vehicle ``msl_meads.toml``; peak q ≈ 81.6 s."""
    P, pr, imu, ini, veh = (
        "meads",
        "telemetry/pressures.csv",
        "telemetry/imu.csv",
        "telemetry/initial_state.toml",
        "msl_meads.toml",
    )
    out: list[Mutation] = []

    def m(cls, what, edit, file, *names):
        out.append(Mutation(cls, P, "meads", what, edit, file, tuple(names)))

    for a, b in _pick(rng, [("f_x", "f_z"), ("f_y", "f_z"), ("f_x", "f_y")], 2):
        m("axis_swap", f"{a}<->{b}", csv_edit(imu, swap(a, b)), imu, a, b)
    for a, b in _pick(rng, [("w_y", "w_z"), ("w_x", "w_y"), ("w_x", "w_z")], 2):
        m("axis_swap", f"{a}<->{b}", csv_edit(imu, swap(a, b)), imu, a, b)
    for a, b in _pick(rng, [("P1", "P3"), ("P4", "P6"), ("P2", "P7"), ("P3", "P5")], 3):
        m("axis_swap", f"ports {a}<->{b} (cabling)", csv_edit(pr, swap(a, b)), pr, a, b)
    for c in _pick(rng, ["f_x", "f_y", "f_z", "w_x", "w_y", "w_z"], 6):
        m("sign_flip", f"{c} negated", csv_edit(imu, scale(c, k=-1.0)), imu, c)
    m("sign_flip", "port clock angles mirrored", _port_edit(veh, "clock_deg", lambda v: (-v) % 360), veh, "clock_deg")
    m("unit", "pressures in kPa under [Pa]", csv_edit(pr, scale(*[f"P{i}" for i in range(1, 8)], k=1e-3)), pr, "P1")
    m("unit", "pressures in mbar under [Pa]", csv_edit(pr, scale(*[f"P{i}" for i in range(1, 8)], k=1e-2)), pr, "P1")
    c = f"P{int(rng.integers(1, 8))}"
    m("unit", f"port {c} x1000", csv_edit(pr, scale(c, k=1000.0)), pr, c)
    m("unit", "specific force in g under [m/s^2]", csv_edit(imu, scale("f_x", "f_y", "f_z", k=1 / G0)), imu, "f_x")
    m("unit", "body rates in rad/s under [deg/s]", csv_edit(imu, scale("w_x", "w_y", "w_z", k=DEG)), imu, "w_x")
    m("unit", "pressure time in ms", csv_edit(pr, time_scale(1000.0)), pr, "time")
    m("unit", "initial velocity in km/s", toml_edit(ini, "state", "v_M_mps", vec(lambda v: v / 1000)), ini, "v_M_mps")
    m("unit", "initial position in km", toml_edit(ini, "state", "p_M_m", vec(lambda v: v / 1000)), ini, "p_M_m")
    m("geometry", "port P3 radius in inches", _port_edit(veh, "radius_m", lambda v: v * 39.37, port=3), veh, "radius_m")
    m(
        "geometry",
        "heat shield diameter x1.2",
        toml_edit(veh, "vehicle", "diameter_m", lambda v: v * 1.2),
        veh,
        "diameter_m",
    )
    m(
        "geometry",
        "initial attitude 10 deg off (q_M_B components rotated)",
        toml_edit(ini, "state", "q_M_B", vec(_rot_q(10.0))),
        ini,
        "q_M_B",
    )
    m(
        "geometry",
        "initial position 50 km off",
        toml_edit(ini, "state", "p_M_m", vec(lambda v: v + np.array([5e4, 0, 0]))),
        ini,
        "p_M_m",
    )
    m("geometry", "nose radius x2", toml_edit(veh, "vehicle", "nose_radius_m", lambda v: v * 2), veh, "nose_radius_m")
    m("truncation", "pressures end at peak q (81.6 s)", csv_edit(pr, end_at(81.6)), pr)
    m("truncation", "IMU ends at peak q", csv_edit(imu, end_at(81.6)), imu)
    m("truncation", "pressure rows 75-90 s removed (around peak q)", csv_edit(pr, drop_between(75.0, 90.0)), pr)
    m("truncation", "IMU rows 70-85 s removed", csv_edit(imu, drop_between(70.0, 85.0)), imu)
    m("timing", "pressure time +125 ms (one sample)", csv_edit(pr, time_shift(0.125)), pr)
    m("timing", "pressure time +20 ms", csv_edit(pr, time_shift(0.02)), pr)
    m("timing", "IMU time -50 ms", csv_edit(imu, time_shift(-0.05)), imu)
    m(
        "timing",
        "tube length x10 (lag model)",
        toml_edit(veh, "vehicle", "tube_length_m", lambda v: v * 10),
        veh,
        "tube_length_m",
    )
    m("timing", "pressures declared 80 Hz (data 8 Hz)", csv_edit(pr, comment("rate_hz", "80")), pr, "rate_hz")
    m("metadata", "mass x10", toml_edit(veh, "vehicle", "mass_kg", lambda v: v * 10), veh, "mass_kg")
    m(
        "metadata",
        "drag coefficient x0.5",
        toml_edit(veh, "vehicle", "drag_coefficient", lambda v: v * 0.5),
        veh,
        "drag_coefficient",
    )
    m(
        "metadata",
        "ref area in ft^2",
        toml_edit(veh, "vehicle", "ref_area_m2", lambda v: v * 10.7639),
        veh,
        "ref_area_m2",
    )
    m(
        "metadata",
        "transducer full scale in psi",
        toml_edit(veh, "vehicle", "transducer_full_scale_pa", lambda v: v / 6894.76),
        veh,
        "transducer_full_scale_pa",
    )
    m(
        "metadata",
        "initial velocity sigma x100 too small",
        toml_edit(ini, "state", "sigma_velocity_mps", lambda v: v / 100),
        ini,
        "sigma_velocity_mps",
    )
    return out


def _rot_q(deg: float) -> Callable[[np.ndarray], np.ndarray]:
    """A scalar-last quaternion post-multiplied by a rotation of ``deg`` about body y."""

    def f(q: np.ndarray) -> np.ndarray:
        h = math.radians(deg) / 2
        x, y, z, w = q
        bx, by, bz, bw = 0.0, math.sin(h), 0.0, math.cos(h)
        return np.array(
            [
                w * bx + x * bw + y * bz - z * by,
                w * by - x * bz + y * bw + z * bx,
                w * bz + x * by - y * bx + z * bw,
                w * bw - x * bx - y * by - z * bz,
            ]
        )

    return f


def _port_edit(rel: str, key: str, f: Callable, port: int | None = None) -> Callable[[Path], None]:
    """``key`` of every ``[[ports]]`` entry (or only the ``port``-th, from 1) of the vehicle TOML
    ``rel`` replaced by ``f(value)``, line by line as a user edits it."""

    def edit(folder: Path) -> None:
        p = folder / rel
        lines = p.read_text(encoding="utf-8").split("\n")
        k = 0
        for i, s in enumerate(lines):
            if s.strip() == "[[ports]]":
                k += 1
            mm = re.match(rf"^(\s*{key}\s*=\s*)([-+0-9.eE]+)(.*)$", s)
            if mm and k and (port is None or port == k):
                lines[i] = f"{mm.group(1)}{f(float(mm.group(2))):.6g}{mm.group(3)}"
        p.write_text("\n".join(lines), encoding="utf-8")

    return edit


def _post2_j2(rng: np.random.Generator) -> list[Mutation]:
    """post2_j2 (``workbench init post2_j2``): ``gravity.csv`` (g, m/s², every 100 s) and the
    problem file's states/vehicle/environment."""
    P, obs, sc = "post2_j2", "telemetry/gravity.csv", "scenario.toml"
    out: list[Mutation] = []

    def m(cls, what, edit, file, *names):
        out.append(Mutation(cls, P, "post2_j2", what, edit, file, tuple(names)))

    m(
        "axis_swap",
        "initial velocity x<->y",
        toml_edit(sc, "states.velocity", "value", vec(lambda v: v[[1, 0, 2]])),
        sc,
        "value",
    )
    m(
        "axis_swap",
        "initial position x<->z",
        toml_edit(sc, "states.position", "value", vec(lambda v: v[[2, 1, 0]])),
        sc,
        "value",
    )
    # (a negated initial velocity or one negated component mirrors the orbit through a symmetry
    # plane of the J2 field: the gravity magnitudes are identical, no data can tell; not included)
    m("sign_flip", "gravity column negated", csv_edit(obs, scale("g", k=-1.0)), obs, "g")
    m(
        "sign_flip",
        "J2 prior value negated (-2e-3)",
        toml_edit(sc, "states.j2", "value", lambda v: -2.0e-3),
        sc,
        "value",
    )
    m("unit", "gravity in mGal under [m/s^2]", csv_edit(obs, scale("g", k=1e5)), obs, "g")
    m("unit", "gravity in cm/s^2", csv_edit(obs, scale("g", k=100.0)), obs, "g")
    m("unit", "time in ms", csv_edit(obs, time_scale(1000.0)), obs, "time")
    m("unit", "initial position in km", toml_edit(sc, "states.position", "value", vec(lambda v: v / 1000)), sc, "value")
    m("unit", "GM in km^3/s^2", toml_edit(sc, "environment", "gm_m3_s2", lambda v: v / 1e9), sc, "gm_m3_s2")
    m(
        "geometry",
        "equatorial radius in km",
        toml_edit(sc, "environment", "equatorial_radius_m", lambda v: v / 1000),
        sc,
        "equatorial_radius_m",
    )
    m(
        "geometry",
        "initial position +10 km",
        toml_edit(sc, "states.position", "value", vec(lambda v: v + np.array([1e4, 0, 0]))),
        sc,
        "value",
    )
    m("truncation", "observations end at 5000 s", csv_edit(obs, end_at(5000.0)), obs)
    m("truncation", "observations 3000-6000 s removed", csv_edit(obs, drop_between(3000.0, 6000.0)), obs)
    m("timing", "observation time +100 s (one sample)", csv_edit(obs, time_shift(100.0)), obs)
    m("timing", "observation time +5 s", csv_edit(obs, time_shift(5.0)), obs)
    m("metadata", "mass x10", toml_edit(sc, "vehicle", "mass_kg", lambda v: v * 10), sc, "mass_kg")
    m(
        "metadata",
        "gravity sigma x100 too small",
        toml_edit(sc, "observations.gravity", "sigma", lambda v: v / 100),
        sc,
        "sigma",
    )
    m(
        "metadata",
        "gravity sigma x100 too large",
        toml_edit(sc, "observations.gravity", "sigma", lambda v: v * 100),
        sc,
        "sigma",
    )
    m(
        "metadata",
        "J2 prior 2e-6 (units of 1e-3 taken literally)",
        toml_edit(sc, "states.j2", "sigma", lambda v: v * 1e-3),
        sc,
        "sigma",
    )
    return out


def _huygens(rng: np.random.Generator) -> list[Mutation]:
    """post2_huygens (``workbench init post2_huygens``): axial accelerometer files
    ``accel_{entry,deploy,main,drogue,late}.csv`` (ax m/s²), ``pressure.csv`` (ln_p), ``temperature.csv``
    (T K), ``radar_{a,b}.csv`` (h m); main chute 268.57 s, drogue 1171 s."""
    P, sc = "post2_huygens", "scenario.toml"
    acc = [f"telemetry/accel_{s}.csv" for s in ("entry", "deploy", "main", "drogue", "late")]
    out: list[Mutation] = []

    def m(cls, what, edit, file, *names):
        out.append(Mutation(cls, P, "post2_huygens", what, edit, file, tuple(names)))

    m(
        "axis_swap",
        "initial position x<->y",
        toml_edit(sc, "states.position", "value", vec(lambda v: v[[1, 0, 2]])),
        sc,
        "value",
    )
    m(
        "axis_swap",
        "initial velocity y<->z",
        toml_edit(sc, "states.velocity", "value", vec(lambda v: v[[0, 2, 1]])),
        sc,
        "value",
    )
    for f in _pick(rng, acc, 4):
        m("sign_flip", f"{Path(f).name} ax negated", csv_edit(f, scale("ax", k=-1.0)), f, "ax")
    m(
        "sign_flip",
        "every accelerometer file negated",
        both(*[csv_edit(f, scale("ax", k=-1.0)) for f in acc]),
        acc[0],
        "ax",
    )
    for f in _pick(rng, acc, 3):
        m("unit", f"{Path(f).name} in g under [m/s^2]", csv_edit(f, scale("ax", k=1 / G0)), f, "ax")
    m(
        "unit",
        "radar_a in km under [m]",
        csv_edit("telemetry/radar_a.csv", scale("h", k=1e-3)),
        "telemetry/radar_a.csv",
        "h",
    )
    m("unit", "radar_b in ft", csv_edit("telemetry/radar_b.csv", scale("h", k=3.28084)), "telemetry/radar_b.csv", "h")
    m(
        "unit",
        "ln_p of kPa (ln 1000 off)",
        csv_edit("telemetry/pressure.csv", offset("ln_p", d=-math.log(1000.0))),
        "telemetry/pressure.csv",
        "ln_p",
    )
    m(
        "unit",
        "temperature in degC under [K]",
        csv_edit("telemetry/temperature.csv", offset("T", d=-273.15)),
        "telemetry/temperature.csv",
        "T",
    )
    m(
        "unit",
        "temperature in degF under [K]",
        csv_edit("telemetry/temperature.csv", _col_map("T", lambda v: (v - 273.15) * 1.8 + 32)),
        "telemetry/temperature.csv",
        "T",
    )
    m("unit", "accel_main time in ms", csv_edit(acc[2], time_scale(1000.0)), acc[2], "time")
    m(
        "geometry",
        "initial position 30 km off",
        toml_edit(sc, "states.position", "value", vec(lambda v: v + np.array([3e4, 0, 0]))),
        sc,
        "value",
    )
    m(
        "geometry",
        "reference area in ft^2",
        toml_edit(sc, "vehicle", "ref_area_m2", lambda v: v * 10.7639),
        sc,
        "ref_area_m2",
    )
    m(
        "geometry",
        "drogue area x4 (diameter for radius)",
        toml_edit(sc, "vehicle", "drogue_area_m2", lambda v: v * 4),
        sc,
        "drogue_area_m2",
    )
    m("truncation", "accel_deploy ends inside the main-chute opening (275 s)", csv_edit(acc[1], end_at(275.0)), acc[1])
    m("truncation", "accel_entry ends at 150 s (inside peak deceleration)", csv_edit(acc[0], end_at(150.0)), acc[0])
    m("truncation", "accel_drogue rows 1171-1400 s removed", csv_edit(acc[3], drop_between(1171.0, 1400.0)), acc[3])
    m(
        "truncation",
        "radar_a ends after 500 s",
        csv_edit("telemetry/radar_a.csv", end_at(4400.0)),
        "telemetry/radar_a.csv",
    )
    m(
        "timing",
        "main chute event declared by hand 5 s late",
        declared_instead_of_detected(sc, "events.main_chute", 268.6 + 5.0),
        sc,
        "value",
    )
    m("timing", "accel_deploy time +0.24 s (one sample)", csv_edit(acc[1], time_shift(0.24)), acc[1])
    m("timing", "radar time +5 s", csv_edit("telemetry/radar_a.csv", time_shift(5.0)), "telemetry/radar_a.csv")
    m("timing", "pressure time -10 s", csv_edit("telemetry/pressure.csv", time_shift(-10.0)), "telemetry/pressure.csv")
    m("metadata", "main-chute mass x10", toml_edit(sc, "events.main_chute", "mass_kg", lambda v: v * 10), sc, "mass_kg")
    m("metadata", "vehicle mass in lb", toml_edit(sc, "vehicle", "mass_kg", lambda v: 320.0 * 2.20462), sc, "mass_kg")
    m("metadata", "drogue Cd = 0", toml_edit(sc, "vehicle", "drogue_cd", lambda v: 0.0), sc, "drogue_cd")
    m("metadata", "drogue Cd x3", toml_edit(sc, "vehicle", "drogue_cd", lambda v: v * 3), sc, "drogue_cd")
    return out


# rocket log columns
_ACC = [f"raw_acceleration_{a}_gs" for a in "xyz"]
_GYR = [f"raw_angular_rate_{a}_deg_per_s" for a in "xyz"]
_MAG = [f"magnetic_field_{a}_microteslas" for a in "xyz"]


def _rocket(problem: str, base: str, log: str, rng: np.random.Generator, n_rows: int | None = None) -> list[Mutation]:
    """The rocket importer (``workbench import airbrakes LOG --metadata metadata.json``): the FIRM
    log ``log`` (accelerations in g, rates in deg/s, field in µT, pressure in Pa, temperature in °C,
    ``timestamp_seconds``, ``state_letter`` S/M/C/F/L) and its metadata entry."""
    meta = "metadata.json"
    out: list[Mutation] = []

    def m(cls, what, edit, file, *names, args=()):
        out.append(Mutation(cls, problem, base, what, edit, file, tuple(names), tuple(args)))

    def entry(*path):
        return (log, *path)

    noop = lambda folder: None  # noqa: E731
    for a, b in _pick(rng, [(0, 1), (1, 2), (0, 2)], 3):
        m("axis_swap", f"acceleration {'xyz'[a]}<->{'xyz'[b]}", csv_edit(log, swap(_ACC[a], _ACC[b])), log, _ACC[a])
    for a, b in _pick(rng, [(0, 1), (1, 2), (0, 2)], 3):
        m("axis_swap", f"angular rate {'xyz'[a]}<->{'xyz'[b]}", csv_edit(log, swap(_GYR[a], _GYR[b])), log, _GYR[a])
    for a, b in _pick(rng, [(0, 1), (1, 2), (0, 2)], 2):
        m("axis_swap", f"magnetic field {'xyz'[a]}<->{'xyz'[b]}", csv_edit(log, swap(_MAG[a], _MAG[b])), log, _MAG[a])
    m(
        "axis_swap",
        "IMU x<->z (acceleration and rate)",
        csv_edit(log, swap(_ACC[0], _ACC[2]), swap(_GYR[0], _GYR[2])),
        log,
        _ACC[0],
    )
    m("sign_flip", "all accelerations negated", csv_edit(log, scale(*_ACC, k=-1.0)), log, _ACC[0])
    for j in _pick(rng, [0, 1, 2], 3):
        m("sign_flip", f"acceleration {'xyz'[j]} negated", csv_edit(log, scale(_ACC[j], k=-1.0)), log, _ACC[j])
    for j in _pick(rng, [0, 1, 2], 3):
        m("sign_flip", f"angular rate {'xyz'[j]} negated", csv_edit(log, scale(_GYR[j], k=-1.0)), log, _GYR[j])
    m("sign_flip", "magnetic field negated", csv_edit(log, scale(*_MAG, k=-1.0)), log, _MAG[0])
    m(
        "sign_flip",
        "declination sign flipped (--declination-deg +10.5)",
        noop,
        log,
        "declination",
        args=("--declination-deg", "10.5"),
    )
    m("unit", "accelerations in m/s^2 (column _gs)", csv_edit(log, scale(*_ACC, k=G0)), log, _ACC[0])
    m("unit", "accelerations in mg", csv_edit(log, scale(*_ACC, k=1000.0)), log, _ACC[0])
    m("unit", "angular rates in rad/s", csv_edit(log, scale(*_GYR, k=DEG)), log, _GYR[0])
    m("unit", "timestamp in ms", csv_edit(log, _col_scale("timestamp_seconds", 1000.0)), log, "timestamp_seconds")
    m("unit", "pressure in hPa", csv_edit(log, scale("pressure_pascals", k=0.01)), log, "pressure_pascals")
    m("unit", "pressure in kPa", csv_edit(log, scale("pressure_pascals", k=1e-3)), log, "pressure_pascals")
    m(
        "unit",
        "temperature in degF",
        csv_edit(log, _col_map("temperature_celsius", lambda v: v * 1.8 + 32)),
        log,
        "temperature_celsius",
    )
    m("unit", "magnetic field in gauss", csv_edit(log, scale(*_MAG, k=0.01)), log, _MAG[0])
    c = str(rng.choice([*_ACC, *_GYR]))
    m("unit", f"one column x1000 ({c})", csv_edit(log, scale(c, k=1000.0)), log, c)
    m(
        "unit",
        "wind speed in mph under _kmh",
        json_edit(meta, entry("launch_site", "wind_speed_kmh"), lambda v: v / 1.609344),
        meta,
        "wind_speed_kmh",
    )
    m(
        "unit",
        "QNH in inHg under _mb",
        json_edit(meta, entry("launch_site", "air_pressure_mb"), lambda v: v * 0.02953),
        meta,
        "air_pressure_mb",
    )
    m(
        "unit",
        "cross-section in cm^2",
        json_edit(meta, entry("rocket", "rocket_cross_sectional_area_m2"), lambda v: v * 1e4),
        meta,
        "rocket_cross_sectional_area_m2",
    )
    m(
        "geometry",
        "launch latitude and longitude swapped",
        json_edit(
            meta,
            entry("launch_site", "launch_coordinates"),
            lambda v: {"latitude": v["longitude"], "longitude": v["latitude"]},
        ),
        meta,
        "launch_coordinates",
    )
    m(
        "geometry",
        "launch longitude sign flipped",
        json_edit(
            meta,
            entry("launch_site", "launch_coordinates"),
            lambda v: {"latitude": v["latitude"], "longitude": -v["longitude"]},
        ),
        meta,
        "launch_coordinates",
    )
    m(
        "geometry",
        "launch rod angle in rad",
        json_edit(meta, entry("launch_site", "launch_rod_angle"), lambda v: v * DEG),
        meta,
        "launch_rod_angle",
    )
    m(
        "geometry",
        "launch rod angle from the horizontal (70)",
        json_edit(meta, entry("launch_site", "launch_rod_angle"), lambda v: 90.0 - v),
        meta,
        "launch_rod_angle",
    )
    m(
        "geometry",
        "landed coordinates swapped",
        json_edit(
            meta,
            entry("flight_data", "landed_coordinates"),
            lambda v: {"latitude": v["longitude"], "longitude": v["latitude"]},
        ),
        meta,
        "landed_coordinates",
    )
    m(
        "truncation",
        "log ends in coast (no F rows)",
        csv_edit(log, _letters_keep(lambda s: s in "SMC")),
        log,
        "state_letter",
    )
    m("truncation", "log ends at the ejection (2 F rows)", csv_edit(log, _keep_first_of("F", 2)), log, "state_letter")
    m("truncation", "a third of the coast rows removed", csv_edit(log, _drop_middle_of("C", 1 / 3)), log)
    m("truncation", "log ends mid-boost", csv_edit(log, _keep_first_of("M", 6, drop_after=True)), log, "state_letter")
    m("truncation", "every other coast row removed", csv_edit(log, _drop_every_other("C")), log)
    m("timing", "observation rate 100 Hz above the packet rate", noop, log, "obs-rate", args=("--obs-rate-hz", "100"))
    m("timing", "observation rate 30 Hz", noop, log, "obs-rate", args=("--obs-rate-hz", "30"))
    m(
        "timing",
        "timestamps 5 ms late on the pressure (column shifted one row)",
        csv_edit(log, _shift_column("pressure_pascals", 1)),
        log,
        "pressure_pascals",
    )
    m("timing", "accelerations one packet late", csv_edit(log, _shift_column(_ACC, 1)), log, _ACC[0])
    m(
        "timing",
        "packet frequency in metadata 1000 Hz",
        json_edit(meta, entry("ins_details", "data_packet_frequency"), lambda v: 1000.0),
        meta,
        "data_packet_frequency",
    )
    m(
        "metadata",
        "dry mass x10",
        json_edit(meta, entry("rocket", "rocket_dry_mass_kg"), lambda v: v * 10),
        meta,
        "rocket_dry_mass_kg",
    )
    m(
        "metadata",
        "dry mass in lb",
        json_edit(meta, entry("rocket", "rocket_dry_mass_kg"), lambda v: v * 2.20462),
        meta,
        "rocket_dry_mass_kg",
    )
    m("metadata", "Cd = 0", json_edit(meta, entry("rocket", "rocket_Cd"), lambda v: 0.0), meta, "rocket_Cd")
    m("metadata", "Cd x3", json_edit(meta, entry("rocket", "rocket_Cd"), lambda v: v * 3), meta, "rocket_Cd")
    m(
        "metadata",
        "wrong motor (L1390G-P -> K535W)",
        json_edit(meta, entry("rocket", "motor"), lambda v: "K535W"),
        meta,
        "motor",
    )
    m(
        "metadata",
        "site temperature in degF",
        json_edit(meta, entry("launch_site", "air_temperature_celsius"), lambda v: v * 1.8 + 32),
        meta,
        "air_temperature_celsius",
    )
    m(
        "metadata",
        "apogee in ft",
        json_edit(meta, entry("flight_data", "apogee_meters"), lambda v: v * 3.28084),
        meta,
        "apogee_meters",
    )
    m(
        "metadata",
        "diameter in inches",
        json_edit(meta, entry("rocket", "rocket_diameter_m"), lambda v: v * 39.37),
        meta,
        "rocket_diameter_m",
    )
    return out


def _col_scale(name: str, k: float) -> Callable[[Csv], None]:
    return lambda c: c.map(name, lambda v: v * k)


def _col_map(name: str, f: Callable) -> Callable[[Csv], None]:
    return lambda c: c.map(name, f)


def _letters(c: Csv) -> np.ndarray:
    j = c.col("state_letter")
    return np.array([r[j].strip() for r in c.rows])


def _letters_keep(pred: Callable[[str], bool]) -> Callable[[Csv], None]:
    """Rows whose state letter satisfies ``pred`` kept."""
    return lambda c: c.keep(np.array([pred(s) for s in _letters(c)]))


def _keep_first_of(letter: str, n: int, drop_after: bool = True) -> Callable[[Csv], None]:
    """The log cut after the ``n``-th row of phase ``letter``."""

    def op(c: Csv) -> None:
        idx = np.flatnonzero(_letters(c) == letter)
        if len(idx) > n:
            c.keep(np.arange(len(c.rows)) <= idx[n - 1])

    return op


def _drop_middle_of(letter: str, frac: float) -> Callable[[Csv], None]:
    """The middle ``frac`` of the rows of phase ``letter`` removed."""

    def op(c: Csv) -> None:
        idx = np.flatnonzero(_letters(c) == letter)
        k = int(len(idx) * frac)
        s = (len(idx) - k) // 2
        mask = np.ones(len(c.rows), bool)
        mask[idx[s : s + k]] = False
        c.keep(mask)

    return op


def _drop_every_other(letter: str) -> Callable[[Csv], None]:
    def op(c: Csv) -> None:
        idx = np.flatnonzero(_letters(c) == letter)
        mask = np.ones(len(c.rows), bool)
        mask[idx[1::2]] = False
        c.keep(mask)

    return op


def _shift_column(names, k: int) -> Callable[[Csv], None]:
    """Columns ``names`` delayed by ``k`` rows (the first rows repeat): a stream logged late."""
    names = [names] if isinstance(names, str) else list(names)

    def op(c: Csv) -> None:
        for n in names:
            j = c.col(n)
            vals = [r[j] for r in c.rows]
            vals = vals[:1] * k + vals[:-k]
            for r, v in zip(c.rows, vals, strict=True):
                r[j] = v

    return op


def catalogue(seed: int = 0, *, flights: tuple[str, ...] = ()) -> list[Mutation]:
    """Every mutation of every base, drawn from ``seed``: the drop test (with and without ranging,
    and the zero-phase base), entry, MEADS, post2 (J2, Huygens), the rocket importer on the committed
    excerpt and on each full FIRM log named in ``flights`` (base ``rocket_<stem>``)."""
    rng = np.random.default_rng(seed)
    out = [
        *_droptest("droptest", "droptest", rng, ranging=False),
        *_droptest("droptest_ranging", "droptest_ranging", rng, ranging=True),
        *_zero_phase("droptest_ranging", "droptest_ranging_zp"),
        *_entry(rng),
        *_meads(rng),
        *_post2_j2(rng),
        *_huygens(rng),
        *_rocket("rocket", "rocket", "jackpot_launch_1_excerpt.csv", rng),
    ]
    for f in flights:
        out += _rocket(f"rocket_{Path(f).stem}", f"rocket_{Path(f).stem}", f, rng)
    return out


def quick(muts: list[Mutation], per: int = 2, seed: int = 0) -> list[Mutation]:
    """At most ``per`` mutations per (problem, class), drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    groups: dict[tuple[str, str], list[Mutation]] = {}
    for m in muts:
        groups.setdefault((m.problem, m.cls), []).append(m)
    keep = {id(m) for g in groups.values() for m in _pick(rng, g, per)}
    return [m for m in muts if id(m) in keep]
