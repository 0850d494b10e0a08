"""Entry telemetry (AMELIA Table 1 shape): the files an entry scenario names, read and checked.

:func:`telemetry_paths` resolves the scenario's ``[telemetry]`` table.  Rule: all of :data:`STREAMS`
are required — ``gnc``, ``gnc_nav``, ``rda_slant_range``, ``rda_out``, ``events`` and
``initial_state``; the radar files feed the radar-aided smoother (AMELIA Sects. 7–8), without
them there is nothing to reconstruct beyond the strapdown.  A missing key or file is a
:class:`~workbench.io.scenario.ScenarioError` naming it.

Reading (:func:`read_entry_telemetry`) turns the five CSV streams (format in ``io/FORMATS.md``) into
an :class:`EntryTelemetry` in SI; :func:`read_nominal_state` reads ``initial_state.toml``
(AMELIA Table 2 style) into a :class:`NominalState`.

Defect policy — nothing is silently integrated; every finding names file, column and row:

* format defects are **errors** (:class:`~workbench.io.telemetry.TelemetryError`, raised by
  ``read_telemetry``): NaN/inf or unparsable cells (a NaN burst lists up to 20 rows and the
  total), duplicated packets (repeated time) and out-of-order packets (time going backwards),
  missing columns, wrong units, negative ranges;
* a quaternion whose norm departs from 1 by more than ``quat_error_tol`` (1e-3) is an **error**;
  by more than ``quat_warn_tol`` (1e-6) but less, a **WARN** and it is normalised;
* a radar packet with a zero range where data is expected (after the first
  ``zero_filled_packets`` slant-range packets, which Schiaparelli sent zero-filled: INFO) or a
  zero slant-out / all-zero velocity-out is a **WARN** and the packet is marked invalid
  (``sr_valid`` / ``rda_valid`` False) — never used as a range of 0 m;
* empty acceleration cells (the ``a_*`` columns are sparse: the real TM stops the acceleration
  before the rate) set ``a_valid`` False; outside a trailing block they are a WARN; those rows
  are left out of the IMU grid (so a long run of them becomes a bridged gap);
* repeated events: WARN, the first is used;
* time gaps (blackouts) are NOTE lines and :class:`StreamGap` records (``gaps``): the health
  verdict judges them against the key events (``entry.health.gap_checks``);
* units, timing and axes from physics are **errors** naming file, column and the likely unit or
  column map: :func:`rate_problems` (time step against ``# rate_hz:``, where each file ends),
  :func:`check_units` (magnitudes), :func:`axis_problems` (rate against the quaternions,
  acceleration against the on-board velocity, vector by vector); the nominal initial state's
  speed and altitude (:func:`read_nominal_state`).

Frames: M = MMED inertial, G = GNC body; the TM JPL quaternion "MMED to GNC" becomes
``q_M_G = conj(quat_from_jpl(q_jpl))`` (numerically the raw components).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from workbench.core.bodies import G0
from workbench.core.rotation import quat_conjugate, quat_from_jpl, quat_multiply, quat_normalize, quat_to_jpl
from workbench.io.scenario import ScenarioError
from workbench.io.schema import REQUIRED, Key, Schema, Table, load_file
from workbench.io.telemetry import (
    MAX_PROBLEMS,
    Problem,
    TelemetryError,
    atomic_write_text,
    read_events,
    read_telemetry,
)
from workbench.io.units import UNITS, canonical_unit, likely_unit
from workbench.problems.entry.site import R_MOLA

__all__ = [
    "signed_permutations",
    "STREAMS",
    "CSV_STREAMS",
    "TelemetryChecks",
    "RadarTracks",
    "EntryTelemetry",
    "StreamGap",
    "rate_problems",
    "axis_problems",
    "AXIS_MISMATCH_MAX",
    "ENTRY_SPEED_RANGE_MPS",
    "ENTRY_ALTITUDE_RANGE_M",
    "NominalState",
    "telemetry_paths",
    "read_entry_telemetry",
    "check_event_span",
    "INITIAL_STATE_SCHEMA",
    "read_nominal_state",
    "write_nominal_state",
    "true_runs",
]

#: ``[telemetry]`` keys of an entry scenario, all required (module docstring).
STREAMS = ("gnc", "gnc_nav", "rda_slant_range", "rda_out", "events", "initial_state")
#: The CSV streams among them (read by :func:`read_entry_telemetry`).
CSV_STREAMS = ("gnc", "gnc_nav", "rda_slant_range", "rda_out", "events")


@dataclass(frozen=True)
class TelemetryChecks:
    """Check settings of :func:`read_entry_telemetry`: a GNC quaternion whose norm is off by more
    than ``quat_error_tol`` is an error, by more than ``quat_warn_tol`` a WARN (normalised); the
    first ``zero_filled_packets`` slant-range packets are expected zero-filled (INFO).  Scenario
    keys ``[preprocess] quat_error_tol``, ``quat_warn_tol``, ``[sensors.radar] zero_filled_packets``."""

    quat_error_tol: float = 1e-3
    quat_warn_tol: float = 1e-6
    zero_filled_packets: int = 2


@dataclass(frozen=True)
class NominalState:
    """Nominal initial state at ``t0`` [s from EIP] (AMELIA Table 2): MMED velocity [m/s], position [m],
    attitude ``q_M_G`` (converted from the JPL "MMED to GNC" quaternion at the file edge)."""

    t0: float
    v_M: np.ndarray
    p_M: np.ndarray
    q_M_G: np.ndarray
    source: str = ""


@dataclass(frozen=True)
class RadarTracks:
    """The radar altimeter's tracks, SI, times [s] from EIP: ``t_sr`` (k,), ``slant_ranges`` (k, 4)
    [m] beams B0..B3, ``sr_valid`` (k,) bool; ``t_rda`` (j,), ``slant_out`` (j,) [m] along B0,
    ``v_out_G`` (j, 3) [m/s] terrain-relative velocity in G, ``rda_valid`` (j,) bool.  Shared by
    the telemetry as read (:class:`EntryTelemetry`) and the smoother's input
    (:class:`~workbench.problems.entry.filter.RadarData`)."""

    t_sr: np.ndarray
    slant_ranges: np.ndarray
    sr_valid: np.ndarray
    t_rda: np.ndarray
    slant_out: np.ndarray
    v_out_G: np.ndarray
    rda_valid: np.ndarray


@dataclass(frozen=True)
class EntryTelemetry(RadarTracks):
    """Entry telemetry as read, SI, ``t`` [s] from EIP.

    ``t_gnc`` (n,), ``w_G`` (n,3) [rad/s] body rate, ``q_M_G_nav`` (n,4) on-board attitude
    (normalised), ``a_M_total`` (n,3) [m/s²] on-board inertial acceleration incl. gravity (NaN
    where ``a_valid`` is False); ``t_nav`` (m,), ``p_M_nav``, ``v_M_nav`` (m,3) [m, m/s];
    ``t_sr`` (k,), ``slant_ranges`` (k,4) [m], ``sr_valid`` (k,); ``t_rda`` (j,), ``slant_out``
    (j,) [m], ``v_out_G`` (j,3) [m/s], ``rda_valid`` (j,); ``events`` name → t; ``epoch_utc``
    (metadata); ``problems`` the WARN/INFO findings (located, see the module docstring);
    ``files`` stream → path; ``gaps`` the time gaps of every file (:class:`StreamGap`).
    """

    t_gnc: np.ndarray
    w_G: np.ndarray
    q_M_G_nav: np.ndarray
    a_M_total: np.ndarray
    a_valid: np.ndarray
    t_nav: np.ndarray
    p_M_nav: np.ndarray
    v_M_nav: np.ndarray
    events: dict[str, float]
    epoch_utc: str
    problems: list[str]
    files: dict[str, Path]
    gaps: list[StreamGap] = field(default_factory=list)


def telemetry_paths(files: Mapping[str, Path], scenario_file: Path) -> dict[str, Path]:
    """The ``[telemetry]`` files (``files``: stream -> absolute path, as resolved against the
    scenario file by ``EntrySettings``): ``{stream: path}`` for every key of :data:`STREAMS` (all
    required; a missing key or file is a :class:`ScenarioError` on ``scenario_file`` naming it)."""
    missing = [k for k in STREAMS if k not in files]
    if missing:
        raise ScenarioError(
            scenario_file,
            f"telemetry.{missing[0]}",
            f"missing [telemetry] key(s) {', '.join(missing)}: an entry reconstruction needs all of "
            f"{', '.join(STREAMS)} (the radar files feed the radar-aided smoother)",
        )
    for k in STREAMS:
        if not Path(files[k]).exists():
            raise ScenarioError(scenario_file, f"telemetry.{k}", f"file not found: {files[k]}")
    return {k: Path(files[k]) for k in STREAMS}


def write_nominal_state(path: Path, st: NominalState, comment: str = "") -> Path:
    """Write ``initial_state.toml`` in the user format (km, km/s, JPL quaternion MMED→GNC)."""
    q_jpl = quat_to_jpl(quat_conjugate(st.q_M_G))  # JPL of G w.r.t. M has the DCM C_G_M
    f = lambda a: ", ".join(f"{x:.9f}" for x in a)  # noqa: E731
    text = (
        f"# Nominal initial state (AMELIA Table 2 format). {comment}\n"
        "[initial_state]\n"
        f"t0_s = {st.t0:.6f}                  # seconds from EIP\n"
        f"position_km = [{f(st.p_M / 1e3)}]   # MMED\n"
        f"velocity_kmps = [{f(st.v_M / 1e3)}] # MMED\n"
        f"quaternion_jpl = [{f(q_jpl)}]       # JPL (Shuster) scalar-last, MMED to GNC\n"
    )
    return atomic_write_text(path, text)


#: The schema of the nominal initial state file (``initial_state.toml``, AMELIA Table 2 style).
INITIAL_STATE_SCHEMA = Schema(
    "initial_state",
    "entry nominal initial state",
    (
        Table(
            "initial_state",
            "the on-board nominal state at the first IMU sample (MMED inertial)",
            (
                Key(
                    "t0_s",
                    "float",
                    REQUIRED,
                    "s",
                    "time of the state, from EIP (the first sample with an acceleration)",
                ),
                Key("position_km", "vec3", REQUIRED, "km", "position, MMED"),
                Key("velocity_kmps", "vec3", REQUIRED, "km/s", "inertial velocity, MMED"),
                Key(
                    "quaternion_jpl",
                    "list",
                    REQUIRED,
                    "1",
                    "JPL (Shuster) quaternion MMED→GNC, scalar last, 4 numbers; norm within 1e-3 of 1",
                ),
            ),
        ),
    ),
    noun="initial-state file",
    intro="Keys of the nominal initial state file (`[telemetry] initial_state`, `initial_state.toml`)",
)


def read_nominal_state(path: Path) -> NominalState:
    """Read ``initial_state.toml`` (:data:`INITIAL_STATE_SCHEMA`): position [km] and velocity [km/s]
    to SI, the JPL quaternion to ``q_M_G``; every error is a :class:`ScenarioError` naming the file
    and key (unknown keys with the nearest valid one, non-finite values, a non-unit quaternion)."""
    path = Path(path)
    st = load_file(path, INITIAL_STATE_SCHEMA)["initial_state"]
    q = st["quaternion_jpl"]
    if len(q) != 4 or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in q):
        raise ScenarioError(path, "initial_state.quaternion_jpl", "need a list of 4 numbers")
    q_jpl = np.asarray(q, dtype=float)
    for key, a in (
        ("quaternion_jpl", q_jpl),
        ("position_km", st["position_km"]),
        ("velocity_kmps", st["velocity_kmps"]),
    ):
        if not np.all(np.isfinite(a)):
            raise ScenarioError(path, f"initial_state.{key}", "not finite")
    nq = float(np.linalg.norm(q_jpl))
    if abs(nq - 1.0) > 1e-3:
        raise ScenarioError(path, "initial_state.quaternion_jpl", f"not a unit quaternion (norm {nq:.6f})")
    if not np.isfinite(st["t0_s"]):
        raise ScenarioError(path, "initial_state.t0_s", "not finite")
    q_M_G = quat_conjugate(quat_from_jpl(quat_normalize(q_jpl)))
    v_M, p_M = st["velocity_kmps"] * 1e3, st["position_km"] * 1e3
    _check_state_magnitudes(path, v_M, p_M)
    return NominalState(st["t0_s"], v_M, p_M, q_M_G, str(path))


#: Plausible inertial speed of a Mars entry state [m/s]: from orbit ~3.5 km/s, hyperbolic
#: arrivals 5.5-7.5 km/s (Viking, Pathfinder, MER, MSL, Schiaparelli); 1-20 km/s leaves room.
ENTRY_SPEED_RANGE_MPS = (1.0e3, 2.0e4)
#: Plausible altitude of an entry state above the Mars reference sphere [m]: the state is given
#: before or near the entry interface (~120 km); -20 km (below Hellas) to 5000 km leaves room.
ENTRY_ALTITUDE_RANGE_M = (-2.0e4, 5.0e6)


def _unit_that_fits(value: float, declared: str, plausible, typical: float) -> str | None:
    """The unit of the kind of ``declared`` in which the number ``value`` (as written, in
    ``declared``) becomes plausible (``plausible(si) -> bool``), the one nearest ``typical`` [SI]
    in ratio when several do; None when none does."""
    kind = UNITS[canonical_unit(declared)].kind
    fits = [
        (abs(np.log(value * u.factor / typical)), name)
        for name, u in UNITS.items()
        if u.kind == kind and name != canonical_unit(declared) and not u.offset and plausible(value * u.factor)
    ]
    return min(fits)[1] if fits else None


def _check_state_magnitudes(path: Path, v_M: np.ndarray, p_M: np.ndarray) -> None:
    """Unit sanity of the nominal initial state (SI, MMED): the speed |``v_M``| [m/s] inside
    :data:`ENTRY_SPEED_RANGE_MPS` and the altitude |``p_M``| − R [m] inside
    :data:`ENTRY_ALTITUDE_RANGE_M`; otherwise a :class:`ScenarioError` on ``path`` naming the key
    and, when a unit-like factor explains it (:func:`~workbench.io.units.likely_unit`), the unit."""
    speed = float(np.linalg.norm(v_M))
    lo, hi = ENTRY_SPEED_RANGE_MPS
    if not lo <= speed <= hi:
        likely = _unit_that_fits(speed / 1e3, "km/s", lambda v: lo <= v <= hi, 6.0e3)
        hint = f": the values look like [{likely}], not [km/s]" if likely else ": wrong unit or frame?"
        raise ScenarioError(
            path,
            "initial_state.velocity_kmps",
            f"speed {speed / 1e3:.6g} km/s is not an entry speed ({lo / 1e3:g}-{hi / 1e3:g} km/s){hint}",
        )
    r = float(np.linalg.norm(p_M))
    lo, hi = ENTRY_ALTITUDE_RANGE_M
    if not lo <= r - R_MOLA <= hi:
        likely = _unit_that_fits(r / 1e3, "km", lambda x: lo <= x - R_MOLA <= hi, R_MOLA + 1.25e5)
        hint = f": the values look like [{likely}], not [km]" if likely else ": wrong unit or frame?"
        raise ScenarioError(
            path,
            "initial_state.position_km",
            f"the position lies {r / 1e3:.6g} km from the centre of Mars, an altitude of {(r - R_MOLA) / 1e3:.6g} km "
            f"above the {R_MOLA / 1e3:.0f} km sphere (an entry state: {lo / 1e3:g} to {hi / 1e3:g} km){hint}",
        )


def _note(level: str, file, column: str | None, row: int | None, reason: str) -> str:
    return f"{level}: {Problem(str(file), column, row, None, reason)}"


def _header(tel, name: str) -> str:
    return f"{name} [{tel.units[name]}]"


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive (start, end) index pairs of the True runs of a 1-D bool mask (n,)."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), (np.flatnonzero(d == -1) - 1).tolist(), strict=True))


def _flat_top_notes(tel, run: int = 5) -> list[str]:
    """WARN notes for rate and acceleration channels holding one non-zero value for ``run`` or more
    consecutive samples: a flat top (saturated or stuck sensor)."""
    out = []
    for name in [f"{q}_{a}" for q in "wa" for a in "xyz"]:
        v = tel.channel(name)
        same = np.r_[False, (v[1:] == v[:-1]) & (v[1:] != 0) & np.isfinite(v[1:])]
        for i0, i1 in true_runs(same):
            if i1 - i0 + 2 >= run:
                out.append(
                    f"WARN: {Problem(str(tel.path), f'{name} [{tel.units[name]}]', i0, None, '')}".rstrip(": ")
                    + f": {i1 - i0 + 2} samples flat at {v[i0]:.6g} SI "
                    f"(t = {tel.time[i0 - 1]:.3f}–{tel.time[i1]:.3f} s): saturated or stuck"
                )
                break
    return out


def _early_end_notes(gnc, others: Mapping[str, np.ndarray], paths, events: Mapping[str, float]) -> list[str]:
    """WARN notes for files that end early (truncated?): the GNC data more than 1 s before the last
    event, another stream more than 10 s before the GNC data (the radar may stop a few seconds
    before the end of the data, not tens)."""
    out = []
    t_end = float(gnc.time[-1])
    if events:
        name, t_last = max(events.items(), key=lambda kv: kv[1])
        if t_last > t_end + 1.0:
            out.append(
                f"WARN: {paths['gnc']}: the data end at {t_end:.3f} s, {t_last - t_end:.3g} s before the last "
                f"event {name} ({t_last:.3f} s): truncated?"
            )
    for k, t in others.items():
        if len(t) and t_end - float(t[-1]) > 10.0:
            out.append(
                f"WARN: {paths[k]}: the data end at {float(t[-1]):.3f} s, {t_end - float(t[-1]):.3g} s before the "
                "GNC data: truncated?"
            )
    return out


def _gap_notes(tel) -> list[StreamGap]:
    """The time gaps of a telemetry file as :class:`StreamGap` records (blackouts are expected;
    the health verdict judges each against the key events, see ``entry.health``)."""
    return [StreamGap(str(tel.path), g.start_s, g.end_s, g.row) for g in tel.gaps]


@dataclass(frozen=True)
class StreamGap:
    """A time gap of one telemetry file: ``file``, the times of the samples before and after it
    ``start_s``/``end_s`` [s from EIP], ``row`` the data row after it."""

    file: str
    start_s: float
    end_s: float
    row: int

    def __str__(self) -> str:
        d = self.end_s - self.start_s
        return f"{self.file}: gap {self.start_s:.3f}–{self.end_s:.3f} s ({d:.3g} s, row {self.row})"


def _unit_problem(file, tel, name: str, ratio: float, what: str) -> Problem | None:
    """A located problem when ``ratio`` (measured / expected) is explained by a unit mix-up."""
    unit = tel.units[name]
    likely = likely_unit(ratio, unit)
    if likely is None:
        return None
    return Problem(str(file), f"{name} [{unit}]", None, None, f"{what}: the values look like [{likely}], not [{unit}]")


def _factor_problem(
    file, tel, name: str, ratio: float, quantity: str, reference: str, tol: float = 1.5
) -> Problem | None:
    """:func:`_unit_problem` when the median ``ratio`` of ``quantity`` to ``reference`` (two
    magnitudes that should agree, e.g. a speed and the rate of change of a position) is off by
    more than the factor ``tol`` either way; None otherwise (also for a NaN ratio)."""
    if not abs(np.log(ratio)) > np.log(tol):
        return None
    return _unit_problem(file, tel, name, ratio, f"{quantity} is {ratio:.4g}× {reference}")


def radar_unit_notes(nav, out, file) -> list[str]:
    """WARN notes when the radar's slant-out range (along the near-vertical beam B0) and the on-board
    altitude above the Mars reference sphere, at the same times (where the on-board navigation covers
    the radar phase), differ by a unit-like factor (1000 m ↔ km, 3.28 ft ↔ m; their median ratio).

    A note, not an error: the on-board altitude is not evidence enough. After a blackout or a
    saturated gyro it can be off by kilometres (the shipped Schiaparelli-like run: on-board 17 km
    above the sphere while the radar measures 5-7 km, ratio 0.34), and the terrain is ± a few km
    from the sphere, so a dispersed but valid flight reached a ratio of 3.41 — within 4 % of
    feet (member 43 of the 50-member truth-simulator Monte Carlo, which the error used to reject).
    The note names the file, the column and the likely unit; the health verdict carries it."""
    t = out.time
    so = out.channel("slant_out")
    p = nav.stack([f"p_{a}" for a in "xyz"])
    inside = (t >= nav.time[0]) & (t <= nav.time[-1]) & (so > 0)
    if inside.sum() < 5:
        return []
    h = np.linalg.norm(np.column_stack([np.interp(t[inside], nav.time, p[:, i]) for i in range(3)]), axis=1) - R_MOLA
    ok = h > 2000.0  # well above the terrain uncertainty
    if ok.sum() < 5:
        return []
    ratio = float(np.median(so[inside][ok] / h[ok]))
    pr = _factor_problem(
        file,
        out,
        "slant_out",
        ratio,
        "the slant-out range",
        "the on-board altitude (or the on-board altitude is off)",
        tol=2.5,
    )
    return [f"WARN: {pr}"] if pr else []


def _time_column(tel) -> str:
    return f"{tel.time_name} [{tel.time_unit}]"


def rate_problems(
    tels: Mapping[str, object], paths: Mapping[str, os.PathLike], events: Mapping[str, float] | None = None
) -> tuple[list[Problem], list[str]]:
    """Time-unit sanity of the CSV streams ``tels`` (stream → :class:`~workbench.io.telemetry.Telemetry`):
    the median time step of a file against the interval its ``# rate_hz:`` metadata declares, and
    the time each file ends against the median end of all of them and of the ``events`` (name → t
    [s]; every stream ends near the end of the flight).  Returns (errors: a step or an end off by a
    unit-like factor, e.g. times in ms labelled s, naming the file, the time column and the likely
    unit; WARN notes: a step off the declared rate by more than a factor 1.5 that no unit explains)."""
    errors: list[Problem] = []
    warns: list[str] = []
    for k, tel in tels.items():
        if tel.time.size < 3 or "rate_hz" not in tel.meta:
            continue
        try:
            dt_decl = 1.0 / float(tel.meta["rate_hz"])
        except (TypeError, ValueError, ZeroDivisionError):
            continue
        dt = float(np.median(np.diff(tel.time)))
        ratio = dt / dt_decl
        if not abs(np.log(ratio)) > np.log(1.5):
            continue
        what = (
            f"the median time step {dt:.6g} s is {ratio:.4g}× the {dt_decl:.6g} s that '# rate_hz: "
            f"{tel.meta['rate_hz']}' declares"
        )
        likely = likely_unit(ratio, tel.time_unit)
        if likely:
            errors.append(
                Problem(
                    str(paths[k]),
                    _time_column(tel),
                    None,
                    None,
                    f"{what}: the times look like [{likely}], not [{tel.time_unit}]",
                )
            )
        else:
            warns.append(f"WARN: {Problem(str(paths[k]), _time_column(tel), None, None, what + ': wrong rate_hz?')}")
    if errors:
        return errors, warns
    # without rates: every stream ends at the end of the flight (the radar a few seconds before,
    # the last event about then), in seconds from EIP; a file whose end is a unit-like factor off
    # the median end of all of them has its times in another unit
    ends = {k: float(tel.time[-1]) for k, tel in tels.items() if tel.time.size}
    if events:
        ends["events"] = float(max(events.values()))
    med = float(np.median(list(ends.values()))) if ends else 0.0
    if len(ends) < 3 or not med > 1.0:
        return errors, warns
    for k, end in ends.items():
        if not end > 0:
            continue
        unit = tels[k].time_unit if k in tels else "s"
        likely = likely_unit(end / med, unit)
        if likely:
            errors.append(
                Problem(
                    str(paths[k]),
                    _time_column(tels[k]) if k in tels else "time",
                    None,
                    None,
                    f"the data end at {end:.6g} s, {end / med:.4g}× the {med:.6g} s at which the other files and the "
                    f"events end: the times look like [{likely}], not [{unit}]",
                )
            )
    return errors, warns


def signed_permutations(prefix: str) -> list[tuple[np.ndarray, str]]:
    """The 48 signed permutations ``M`` (3, 3) (identity first) with the column names they read,
    e.g. ``"(a_y, -a_x, a_z)"`` for ``prefix`` ``"a_"``."""
    import itertools

    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            M = np.zeros((3, 3))
            M[np.arange(3), perm] = signs
            name = ", ".join(("-" if sg < 0 else "") + prefix + "xyz"[j] for j, sg in zip(perm, signs, strict=True))
            out.append((M, f"({name})"))
    out.sort(key=lambda x: not np.array_equal(x[0], np.eye(3)))
    return out


#: Largest median vector disagreement, relative to the median magnitude, of two measurements of
#: one quantity on the same axes (body rate vs attitude quaternions, acceleration vs on-board
#: velocity) for their axes to be accepted as the same.  An axis swap or a sign flip of a channel
#: carrying the motion gives ≳ 0.3 (a 90° or 180° turn of that component); sample noise, the 10 Hz
#: quaternion's own integration and the on-board navigation's 1 Hz sampling stay two orders below.
AXIS_MISMATCH_MAX = 0.1


def _axis_problem(meas: np.ndarray, ref: np.ndarray, file, columns: str, prefix: str, quantity: str, reference: str):
    """A located :class:`Problem` when ``meas`` (n, 3) disagrees with ``ref`` (n, 3) (same frame
    and units) by more than :data:`AXIS_MISMATCH_MAX` of the median |ref|, naming the signed
    permutation of the columns that would fit best; None when they agree (or too few samples)."""
    ok = np.all(np.isfinite(meas), axis=1) & np.all(np.isfinite(ref), axis=1)
    if ok.sum() < 10:
        return None
    meas, ref = meas[ok], ref[ok]
    scale = float(np.median(np.linalg.norm(ref, axis=1)))
    if not scale > 0:
        return None
    mis = float(np.median(np.linalg.norm(meas - ref, axis=1))) / scale
    if mis <= AXIS_MISMATCH_MAX:
        return None
    fits = [
        (float(np.median(np.linalg.norm(meas @ M.T - ref, axis=1))) / scale, nm)
        for M, nm in signed_permutations(prefix)
    ]
    best, name = min(fits)
    hint = (
        f"read as {name} they agree ({best:.2g}): an axis swap or sign flip of the columns"
        if best <= AXIS_MISMATCH_MAX
        else "no swap or sign flip of the columns explains it: a frame or quaternion-convention mix-up?"
    )
    return Problem(
        str(file),
        columns,
        None,
        None,
        f"{quantity} disagrees with {reference} (median difference {mis:.3g}× the median magnitude, "
        f"bound {AXIS_MISMATCH_MAX:g}); {hint}",
    )


def axis_problems(gnc, nav, paths: Mapping[str, os.PathLike]) -> list[Problem]:
    """Axis and sign sanity of the GNC file, vector by vector (frames as the file declares):

    * the body rate ``w_*`` against the rotation between successive attitude quaternions
      (``q1..q4``, JPL MMED→GNC), expressed in the body frame, on the steps at the nominal rate
      outside saturation (a gyro axis swapped or sign-flipped, or a quaternion convention that is
      not the declared one);
    * the total acceleration ``a_*`` (MMED) averaged over each on-board navigation interval
      against that interval's velocity change (``v_*`` of gnc_nav): an accelerometer axis swapped
      or sign-flipped.
    Each finding names the file, the columns and the signed permutation that would fit."""
    out: list[Problem] = []
    t = gnc.time
    q = gnc.stack([f"q{i}" for i in range(1, 5)])
    w = gnc.stack([f"w_{x}" for x in "xyz"])
    if t.size > 12:
        qn = q / np.linalg.norm(q, axis=1, keepdims=True)
        q_M_G = quat_conjugate(quat_from_jpl(qn))
        dq = quat_multiply(quat_conjugate(q_M_G[:-1]), q_M_G[1:])
        dq = dq * np.where(dq[:, 3:4] < 0, -1.0, 1.0)
        dt = np.diff(t)
        ang = 2.0 * np.arctan2(np.linalg.norm(dq[:, :3], axis=1), dq[:, 3])
        axis = dq[:, :3] / np.maximum(np.linalg.norm(dq[:, :3], axis=1, keepdims=True), 1e-300)
        w_q = axis * (ang / dt)[:, None]
        w_m = 0.5 * (w[1:] + w[:-1])
        step = float(np.median(dt))
        sat = np.zeros(t.size - 1, bool)
        for name in ("w_x", "w_y", "w_z"):
            m = np.asarray(gnc.saturated.get(name, np.zeros(t.size, bool)), bool)
            sat |= m[1:] | m[:-1]
        flat = np.abs(w_m).max(axis=1) >= 0.999 * np.nanmax(np.abs(w))  # a saturated full-scale plateau
        keep = (dt <= 1.5 * step) & ~sat & ~flat & (ang / dt > np.radians(0.5))
        pr = _axis_problem(
            w_m[keep],
            w_q[keep],
            paths["gnc"],
            f"{_header(gnc, 'w_x')}..{_header(gnc, 'w_z')}",
            "w_",
            "the body rate",
            "the rotation of the attitude quaternions q1..q4 (JPL MMED→GNC)",
        )
        out += [pr] if pr else []
    a = gnc.stack([f"a_{x}" for x in "xyz"])
    ok_a = np.all(np.isfinite(a), axis=1)
    tn = nav.time
    v = nav.stack([f"v_{x}" for x in "xyz"])
    if tn.size > 12 and ok_a.sum() > 12:
        ta, aa = t[ok_a], a[ok_a]
        dtn = np.diff(tn)
        step = float(np.median(dtn))
        cum = np.column_stack(
            [np.concatenate([[0.0], np.cumsum(0.5 * (aa[1:, i] + aa[:-1, i]) * np.diff(ta))]) for i in range(3)]
        )
        dv_a = np.column_stack([np.interp(tn, ta, cum[:, i]) for i in range(3)])
        mean_a = np.diff(dv_a, axis=0) / dtn[:, None]
        dv_n = np.diff(v, axis=0) / dtn[:, None]
        # intervals inside the acceleration data with no GNC gap: the 10 Hz samples cover them
        gaps = [(g.start_s, g.end_s) for g in gnc.gaps]
        covered = (tn[:-1] >= ta[0]) & (tn[1:] <= ta[-1]) & (dtn <= 1.5 * step)
        for g0, g1 in gaps:
            covered &= ~((tn[:-1] < g1) & (tn[1:] > g0))
        pr = _axis_problem(
            mean_a[covered],
            dv_n[covered],
            paths["gnc"],
            f"{_header(gnc, 'a_x')}..{_header(gnc, 'a_z')}",
            "a_",
            "the total acceleration (MMED)",
            f"the rate of change of the on-board velocity v_* ({paths['gnc_nav']})",
        )
        out += [pr] if pr else []
    return out


def check_units(gnc, nav, paths: Mapping[str, os.PathLike], events: Mapping[str, float]) -> None:
    """Unit plausibility from physics (frame-free magnitudes), raising :class:`TelemetryError` naming
    the file, the column and the likely unit when a mismatch is a unit-like factor (9.81, 1000, 57.3,
    3.28: :func:`~workbench.io.units.likely_unit`):

    * the on-board position ``p_*`` (gnc_nav) lies near the Mars radius (median |p| / 3396 km);
    * the on-board velocity ``v_*`` matches the position differences (median |v| / |Δp/Δt|);
    * the total acceleration ``a_*`` (gnc) matches the on-board velocity differences;
    * the body rate ``w_*`` (gnc) matches the rotation between successive attitude quaternions;
    * the parachute deployment (PDD, events) comes after the peak of |a| (the hypersonic
      deceleration), and a PDD time off by 1000 from it is an events time unit mix-up.
    Magnitudes are compared by medians, so saturation and blackouts do not matter.
    """
    problems: list[Problem] = []
    p = nav.stack([f"p_{a}" for a in "xyz"])
    v = nav.stack([f"v_{a}" for a in "xyz"])
    r = float(np.median(np.linalg.norm(p, axis=1)))
    pos_ok = True
    if r > 0 and abs(np.log(r / R_MOLA)) > np.log(1.5):
        pos_ok = False
        pr = _unit_problem(
            paths["gnc_nav"],
            nav,
            "p_x",
            r / R_MOLA,
            f"the on-board position lies {r / 1e3:.4g} km "
            f"from the centre of Mars, whose radius is {R_MOLA / 1e3:.0f} km",
        )
        problems.append(
            pr
            or Problem(
                str(paths["gnc_nav"]),
                f"p_x [{nav.units['p_x']}]",
                None,
                None,
                f"the on-board position lies {r / 1e3:.4g} km from the centre of Mars "
                f"(radius {R_MOLA / 1e3:.0f} km): wrong unit or frame",
            )
        )
    if pos_ok and nav.time.size > 2:
        dt = np.diff(nav.time)
        dp = np.linalg.norm(np.diff(p, axis=0), axis=1) / dt
        vm = 0.5 * (np.linalg.norm(v[1:], axis=1) + np.linalg.norm(v[:-1], axis=1))
        ok = (dp > 1.0) & (vm > 0)
        if ok.sum() > 2:
            ratio = float(np.median(vm[ok] / dp[ok]))
            ref = "the rate of change of the on-board position"
            pr = _factor_problem(paths["gnc_nav"], nav, "v_x", ratio, "the on-board speed", ref)
            problems += [pr] if pr else []
    if nav.time.size > 2 and not problems:
        dv = np.diff(v, axis=0) / np.diff(nav.time)[:, None]
        tm = 0.5 * (nav.time[1:] + nav.time[:-1])
        a = gnc.stack([f"a_{x}" for x in "xyz"])
        ok_a = np.all(np.isfinite(a), axis=1)
        if ok_a.sum() > 2:
            ai = np.column_stack([np.interp(tm, gnc.time[ok_a], a[ok_a, i]) for i in range(3)])
            na, ndv = np.linalg.norm(ai, axis=1), np.linalg.norm(dv, axis=1)
            inside = (tm >= gnc.time[ok_a][0]) & (tm <= gnc.time[ok_a][-1]) & (ndv > 0.5)
            if inside.sum() > 2:
                ratio = float(np.median(na[inside] / ndv[inside]))
                ref = "the rate of change of the on-board velocity"
                pr = _factor_problem(paths["gnc"], gnc, "a_x", ratio, "the acceleration", ref)
                problems += [pr] if pr else []
    q = gnc.stack([f"q{i}" for i in range(1, 5)])
    if q.shape[0] > 3:
        qn = q / np.linalg.norm(q, axis=1, keepdims=True)
        dots = np.clip(np.abs(np.sum(qn[1:] * qn[:-1], axis=1)), 0.0, 1.0)
        rate_q = 2.0 * np.arccos(dots) / np.diff(gnc.time)
        w = np.linalg.norm(gnc.stack([f"w_{x}" for x in "xyz"]), axis=1)
        wm = 0.5 * (w[1:] + w[:-1])
        ok = (rate_q > np.radians(0.5)) & (wm > 0)
        if ok.sum() > 5:
            ratio = float(np.median(wm[ok] / rate_q[ok]))
            ref = "the rotation rate of the attitude quaternions"
            pr = _factor_problem(paths["gnc"], gnc, "w_x", ratio, "the body rate", ref)
            problems += [pr] if pr else []
    if problems:
        raise TelemetryError(problems)
    a = gnc.stack([f"a_{x}" for x in "xyz"])
    ok_a = np.all(np.isfinite(a), axis=1)
    if "PDD" in events and ok_a.sum() > 10:
        t_peak = float(gnc.time[ok_a][int(np.argmax(np.linalg.norm(a[ok_a], axis=1)))])
        t_pdd = events["PDD"]
        span = (float(gnc.time[0]), float(gnc.time[-1]))
        if not (t_peak < t_pdd <= span[1]):
            for f in (1e3, 1e-3, 1e6):
                if t_peak < t_pdd * f <= span[1] and not (t_peak < t_pdd <= span[1]):
                    raise TelemetryError.single(
                        paths["events"],
                        f"the parachute deployment (PDD) at {t_pdd:.6g} s is not after the peak deceleration "
                        f"({t_peak:.1f} s) inside the GNC data ({span[0]:.1f}–{span[1]:.1f} s), but {t_pdd * f:.6g} s "
                        f"would be: the times look {1 / f:g}× off — a time unit mix-up (s ↔ ms)?",
                        column="time",
                    )


def read_entry_telemetry(
    paths: Mapping[str, str | os.PathLike], checks: TelemetryChecks | None = None
) -> EntryTelemetry:
    """Read and check the entry telemetry ``paths`` (``{stream: path}`` with the keys of
    :data:`CSV_STREAMS`, e.g. from :func:`telemetry_paths`; other keys are ignored) with the
    ``checks`` (default :class:`TelemetryChecks`).  Raises :class:`~workbench.io.telemetry.TelemetryError`
    (file, column, row) for format defects and non-unit quaternions; returns the softer findings in
    ``problems`` (policy in the module docstring).
    """
    checks = TelemetryChecks() if checks is None else checks
    paths = {k: Path(v) for k, v in paths.items() if k in CSV_STREAMS}
    missing = [k for k in CSV_STREAMS if k not in paths]
    if missing:
        raise ValueError(f"read_entry_telemetry: missing telemetry stream(s) {missing}; give {CSV_STREAMS}")
    problems: list[str] = []

    # ---- GNC 10 Hz ---------------------------------------------------------------------------
    req = {f"w_{a}": "angular_rate" for a in "xyz"}
    req.update({f"q{i}": "dimensionless" for i in range(1, 5)})
    req.update({f"a_{a}": "acceleration" for a in "xyz"})
    lim = {f"a_{a}": (-100 * G0, 100 * G0) for a in "xyz"}  # physically possible: an entry peaks at ~10 g
    lim.update({f"w_{a}": (-np.radians(3000.0), np.radians(3000.0)) for a in "xyz"})
    gnc = read_telemetry(paths["gnc"], required=req, sparse=[f"a_{a}" for a in "xyz"], limits=lim)
    problems += [f"WARN: {note}" for note in gnc.notes] + _flat_top_notes(gnc)
    gaps = _gap_notes(gnc)
    fname = str(paths["gnc"])
    q_raw = gnc.stack([f"q{i}" for i in range(1, 5)])
    norm = np.linalg.norm(q_raw, axis=1)
    dev = np.abs(norm - 1.0)
    qcol = f"{_header(gnc, 'q1')}..{_header(gnc, 'q4')}"
    bad = np.flatnonzero(dev > checks.quat_error_tol)
    if bad.size:
        raise TelemetryError(
            [
                Problem(
                    fname,
                    qcol,
                    int(r) + 1,
                    None,
                    f"quaternion norm {norm[r]:.6g} is not 1 (tolerance {checks.quat_error_tol:g})",
                )
                for r in bad[:MAX_PROBLEMS]
            ],
            int(bad.size),
        )
    small = np.flatnonzero(dev > checks.quat_warn_tol)
    for r in small[:MAX_PROBLEMS]:
        problems.append(
            _note("WARN", fname, qcol, int(r) + 1, f"quaternion norm {norm[r]:.9g} is not unit: normalised")
        )
    if small.size > MAX_PROBLEMS:
        problems.append(_note("WARN", fname, qcol, None, f"{small.size} non-unit quaternions in all, normalised"))
    q_M_G = quat_conjugate(quat_from_jpl(q_raw / norm[:, None]))  # JPL MMED->GNC -> Hamilton q_M_G (raw numbers)
    a_M = gnc.stack([f"a_{a}" for a in "xyz"])
    a_valid = np.all(np.isfinite(a_M), axis=1)
    for i0, i1 in true_runs(~a_valid):
        partial = np.isfinite(a_M[i0 : i1 + 1]).any()
        if i1 == a_valid.size - 1 and not partial:
            problems.append(
                _note(
                    "INFO",
                    fname,
                    "a_x..a_z",
                    i0 + 1,
                    f"acceleration ends at t = {gnc.time[i0 - 1]:.3f} s" if i0 else "no acceleration",
                )
            )
            continue
        problems.append(
            _note(
                "WARN",
                fname,
                "a_x..a_z",
                i0 + 1,
                f"acceleration missing in rows {i0 + 1}–{i1 + 1} (t = {gnc.time[i0]:.3f}–{gnc.time[i1]:.3f} s): "
                "rows left out of the IMU grid",
            )
        )

    # ---- on-board navigation 1 Hz -----------------------------------------------------------
    req_nav = {f"p_{a}": "length" for a in "xyz"}
    req_nav.update({f"v_{a}": "velocity" for a in "xyz"})
    lim = {f"p_{a}": (-5 * R_MOLA, 5 * R_MOLA) for a in "xyz"}  # within a few Mars radii
    lim.update({f"v_{a}": (-2e4, 2e4) for a in "xyz"})  # below 20 km/s (entries are 4-8 km/s)
    nav = read_telemetry(paths["gnc_nav"], required=req_nav, limits=lim)
    problems += [f"WARN: {note}" for note in nav.notes]
    gaps += _gap_notes(nav)

    # ---- radar --------------------------------------------------------------------------------
    names = [f"B{i}" for i in range(4)]
    tel_sr = read_telemetry(
        paths["rda_slant_range"], required=dict.fromkeys(names, "length"), limits=dict.fromkeys(names, (0.0, 1e7))
    )
    problems += [f"WARN: {note}" for note in tel_sr.notes]
    gaps += _gap_notes(tel_sr)
    t_sr, sr = tel_sr.time.copy(), tel_sr.stack(names)
    zero = sr == 0.0
    sr_valid = ~zero.any(axis=1)
    f = str(paths["rda_slant_range"])
    for r in np.flatnonzero(~sr_valid):
        cols = ",".join(_header(tel_sr, names[j]) for j in np.flatnonzero(zero[r]))
        if r < checks.zero_filled_packets and zero[r].all():
            problems.append(
                _note("INFO", f, cols, int(r) + 1, "zero-filled slant-range packet (expected at RDA start): not used")
            )
        else:
            problems.append(
                _note(
                    "WARN",
                    f,
                    cols,
                    int(r) + 1,
                    f"radar packet of zeros where data is expected (t = {t_sr[r]:.3f} s): marked invalid, not used",
                )
            )
    vn = [f"v_out_{a}" for a in "xyz"]
    req_r = {"slant_out": "length", **dict.fromkeys(vn, "velocity")}
    tel = read_telemetry(paths["rda_out"], required=req_r, limits={"slant_out": (0.0, 1e7)})
    problems += [f"WARN: {note}" for note in tel.notes]
    gaps += _gap_notes(tel)
    problems += radar_unit_notes(nav, tel, paths["rda_out"])
    t_rda, so, vo = tel.time.copy(), tel.channel("slant_out").copy(), tel.stack(vn)
    zero_so = so == 0.0
    zero_v = np.all(vo == 0.0, axis=1)
    rda_valid = ~(zero_so | zero_v)
    f = str(paths["rda_out"])
    bad = np.flatnonzero(~rda_valid)
    for r in bad[:MAX_PROBLEMS]:
        col = _header(tel, "slant_out") if zero_so[r] else ",".join(_header(tel, n) for n in vn)
        problems.append(
            _note(
                "WARN",
                f,
                col,
                int(r) + 1,
                f"radar packet of zeros (t = {t_rda[r]:.3f} s): marked invalid, not used",
            )
        )
    if bad.size > MAX_PROBLEMS:
        problems.append(_note("WARN", f, None, None, f"{bad.size} zero radar packets in all, marked invalid"))

    # ---- events -------------------------------------------------------------------------------
    events: dict[str, float] = {}
    for t_e, name in read_events(paths["events"]):
        if name in events:
            problems.append(
                _note(
                    "WARN",
                    paths["events"],
                    "event",
                    None,
                    f"event {name!r} repeated at {t_e:.4f} s; the first, at {events[name]:.4f} s, is used",
                )
            )
            continue
        events[name] = float(t_e)

    rate_errors, rate_warns = rate_problems(
        {"gnc": gnc, "gnc_nav": nav, "rda_slant_range": tel_sr, "rda_out": tel}, paths, events
    )
    if rate_errors:
        raise TelemetryError(rate_errors)
    problems += rate_warns
    check_units(gnc, nav, paths, events)
    axis = axis_problems(gnc, nav, paths)
    if axis:
        raise TelemetryError(axis)
    problems += _early_end_notes(gnc, {"gnc_nav": nav.time, "rda_slant_range": t_sr, "rda_out": t_rda}, paths, events)
    problems += [f"NOTE: {g}" for g in gaps]  # judged against the key events by the health verdict
    return EntryTelemetry(
        t_gnc=gnc.time.copy(),
        w_G=gnc.stack([f"w_{a}" for a in "xyz"]),
        q_M_G_nav=q_M_G,
        a_M_total=a_M,
        a_valid=a_valid,
        t_nav=nav.time.copy(),
        p_M_nav=nav.stack([f"p_{a}" for a in "xyz"]),
        v_M_nav=nav.stack([f"v_{a}" for a in "xyz"]),
        t_sr=t_sr,
        slant_ranges=sr,
        sr_valid=sr_valid,
        t_rda=t_rda,
        slant_out=so,
        v_out_G=vo,
        rda_valid=rda_valid,
        events=events,
        epoch_utc=gnc.meta.get("epoch_utc", ""),
        problems=problems,
        files=dict(paths),
        gaps=gaps,
    )


def check_event_span(tm: EntryTelemetry, paths: Mapping[str, os.PathLike]) -> None:
    """PDD and FSR present and inside the GNC data.  Each file's own problem is reported against it:
    a GNC file that ends shortly before an event (truncated?) is a :class:`TelemetryError` on the GNC
    file; an event far outside the data is a :class:`ScenarioError` on the events file."""
    for ev in ("PDD", "FSR"):
        if ev not in tm.events:
            raise ScenarioError(Path(paths["events"]), ev, "event missing (needed for the dispersion rules and phases)")
        if tm.t_gnc[-1] < tm.events[ev] < tm.t_gnc[-1] + 0.5 * (tm.t_gnc[-1] - tm.t_gnc[0]):
            # the events are in order but the GNC data stop early: the GNC file is the suspect
            raise TelemetryError.single(
                paths["gnc"],
                f"the data end at {tm.t_gnc[-1]:.3f} s, before the {ev} event at {tm.events[ev]:.3f} s "
                f"({paths['events']}): is the GNC file truncated?",
            )
        if not (tm.t_gnc[0] <= tm.events[ev] <= tm.t_gnc[-1]):
            raise ScenarioError(
                Path(paths["events"]),
                ev,
                f"at {tm.events[ev]:.3f} s, outside the GNC data {tm.t_gnc[0]:.3f}–{tm.t_gnc[-1]:.3f} s of "
                f"{Path(paths['gnc']).name} (is that file cut short, or are the event times on another clock?)",
            )
