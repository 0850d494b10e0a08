"""Drop-test telemetry: the files a drop-test scenario names, read and validated.

:func:`telemetry_paths` resolves the scenario's ``[telemetry]`` table: ``imu``, ``attitude_3dm``,
``events`` and ``setup`` are required, ``ranging`` is optional (an optional sensor: the
reconstruction uses it when the file is given).  :func:`load_drop_telemetry` reads them into a
:class:`DropTelemetry` on the filter's time grid; format defects are errors naming file, column and
row (:mod:`workbench.io.telemetry`), degradations (saturation, dead channels, gaps) are listed.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from workbench.core.bodies import G0
from workbench.io.scenario import ScenarioError
from workbench.io.schema import read_toml
from workbench.io.telemetry import Problem, Telemetry, TelemetryError, read_events, read_telemetry
from workbench.io.units import likely_unit
from workbench.problems.droptest.config import SETUP_SCHEMA, DropSettings
from workbench.problems.droptest.sensors import RangingSpec, acquisition_group_delay

__all__ = [
    "STREAMS",
    "TOUCH_G",
    "OPTIONAL_STREAMS",
    "DropTelemetry",
    "telemetry_paths",
    "read_setup",
    "load_drop_telemetry",
    "time_shift_causes",
]

#: Telemetry streams of a drop-test scenario (``[telemetry]`` keys).
STREAMS = ("imu", "attitude_3dm", "events", "setup", "ranging")
#: Of those, the optional ones.
OPTIONAL_STREAMS = ("ranging",)
#: Event labels of ``events.csv`` the reconstruction reads; any other label is reported (WARN).
KNOWN_EVENTS = ("release", "bungee_cut")


@dataclass(frozen=True)
class DropTelemetry:
    """Validated telemetry on the filter's time grid.

    ``t`` (n,) [s from release], already shifted back by ``group_delay_s``; ``f_B`` (n, n_triads, 3)
    triad specific forces [m/s², body] in the order of ``triads``; ``f_valid`` (n, n_triads) bool;
    ``w_B`` (n, 3) gyro rates [rad/s, body]; ``w_valid`` (n,) bool; ``hanging`` (n,) bool (before
    the release event); ``events`` name -> time [s]; ``degradations`` human-readable list of
    what was dropped or bridged and why; ``raw`` the files as read (for ``/sensors``).
    ``jerk`` (n,) measured jerk indicator [m/s³] that raises the process noise; ``counts`` the IMU
    samples averaged into each step, per triad (n, n_triads) and for the gyro (n,); ``rate_hz`` the
    filter rate actually used (a whole number of IMU samples per step).  ``time_shifts_s`` stream ->
    the lag [s] taken off that stream's time tags: ``imu`` the acquisition filter's delay plus the
    IMU latency (= ``group_delay_s``, already applied to ``t``), ``attitude_3dm`` and ``ranging``
    their latencies (ranging plus the filter delay when it went through the acquisition filter),
    applied where those streams are used; ``time_shift_causes`` stream -> {cause: seconds}, what each
    of those totals is made of (:func:`time_shift_causes`; the events file's tags are used as written).
    """

    t: np.ndarray
    f_B: np.ndarray
    f_valid: np.ndarray
    w_B: np.ndarray
    w_valid: np.ndarray
    hanging: np.ndarray
    triads: tuple[str, ...]
    lever_arms_B: np.ndarray
    events: dict[str, float]
    setup: dict
    group_delay_s: float
    degradations: tuple[tuple[float, str, str], ...]
    imu: Telemetry
    attitude: Telemetry
    ranging: Telemetry | None
    jerk: np.ndarray
    counts: tuple[np.ndarray, np.ndarray]
    rate_hz: float
    time_shifts_s: dict = field(default_factory=dict)
    time_shift_causes: dict = field(default_factory=dict)


def time_shift_causes(settings: DropSettings, has_ranging: bool) -> dict[str, dict[str, float]]:
    """What the reconstruction takes off each stream's time tags, by cause: stream (``imu``,
    ``attitude_3dm``, ``ranging`` when the run has ranging) -> {cause: lag [s]}, each cause named
    with the scenario key that sets it (zeros listed too: a declared latency of 0 is a statement).
    A stream's total lag is the sum of its causes (``DropTelemetry.time_shifts_s``)."""
    aq = settings.acquisition
    filter_delay = acquisition_group_delay(aq.cutoff_hz, aq.order, aq.filter)
    what = {
        "butterworth": f"causal Butterworth order {aq.order}, {aq.cutoff_hz:g} Hz",
        "zero_phase": "zero-phase: none",
        "none": "no filter",
    }[aq.filter]
    filt = "acquisition-filter group delay ({}{})"
    out = {
        "imu": {
            filt.format("[sensors.acquisition]: ", what): filter_delay,
            "latency ([sensors.acquisition] latency_s)": aq.latency_s,
        },
        "attitude_3dm": {"latency ([sensors.attitude_3dm] latency_s)": settings.attitude_3dm.latency_s},
    }
    if has_ranging:
        rg = {"latency ([sensors.ranging] latency_s)": settings.ranging.latency_s}
        if settings.ranging.acquisition_filter:
            rg[filt.format("[sensors.ranging] acquisition_filter = true, ", what)] = filter_delay
        out["ranging"] = rg
    return out


# ---------------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------------


def telemetry_paths(settings: DropSettings) -> dict[str, Path]:
    """The telemetry files of the settings' ``[telemetry]`` table (absolute paths): ``imu``,
    ``attitude_3dm``, ``events``, ``setup`` required (a missing key or file raises
    :class:`ScenarioError` naming the scenario file and the key), ``ranging`` optional."""
    paths = {}
    for k in STREAMS:
        p = settings.telemetry.get(k)
        if p is None:
            if k in OPTIONAL_STREAMS:
                continue
            given = ", ".join(n for n, q in settings.telemetry.items() if q is not None)
            raise ScenarioError(
                settings.path, f"telemetry.{k}", f"missing str value{'; keys here: ' + given if given else ''}"
            )
        if not p.exists():
            raise ScenarioError(settings.path, f"telemetry.{k}", f"file not found: {p}")
        paths[k] = p
    return paths


#: keys of the setup file's ``[bungee]`` table: all of them for the dynamic filter, only the
#: geometry for the odometer, none otherwise (kinematic mode ignores the table)
BUNGEE_KEYS = ("anchor_m", "rest_length_m", "coefficients", "count", "attach_body_m", "mass_kg")
ODOMETER_BUNGEE_KEYS = ("anchor_m", "attach_body_m")


def read_setup(path: Path, bungee_keys: tuple[str, ...] | None = None) -> dict:
    """The drop setup file (``[hanging]`` survey, optional ``[bungee]`` test plan and ``[rocks]``
    field) validated against :data:`~workbench.problems.droptest.config.SETUP_SCHEMA`: an unknown
    key, a wrong type or a value out of bounds raises :class:`ScenarioError` naming file and key.
    Returns the nested dict; a table the file does not have is absent, and of ``[bungee]`` only the
    keys the file gives are present.

    ``bungee_keys``: the ``[bungee]`` keys the run needs (then the table is required); None: when a
    ``[bungee]`` table is given it must be complete (:data:`BUNGEE_KEYS`)."""
    raw = read_toml(path)
    d = SETUP_SCHEMA.validate(raw, path, optional=("rocks",))
    for table in ("bungee", "rocks"):
        if table not in raw:
            del d[table]
    if "bungee" in d:
        d["bungee"] = {k: x for k, x in d["bungee"].items() if x is not None}
    if bungee_keys is None and "bungee" in d:  # complete when given
        bungee_keys = BUNGEE_KEYS
    for k in bungee_keys or ():
        if k not in d.get("bungee", {}):
            raise ScenarioError(path, f"bungee.{k}", "missing")
    return d


def check_units_at_rest(
    imu: Telemetry, t_release: float, triads: tuple[str, ...], gyro_noise_dps: float, fname: str
) -> list[tuple[float, str, str]]:
    """Unit plausibility from physics while the lander hangs still (IMU samples before
    ``t_release`` [s]): every one of the ``triads``' mean specific force magnitude is 1 g and the
    gyro reads ≈ 0 with a scatter of its declared noise (``gyro_noise_dps`` [deg/s], 1σ).  A mismatch by a unit-like
    factor (9.81, 57.3, 1000 ...: :func:`~workbench.io.units.likely_unit`) is a
    :class:`TelemetryError` naming the file, the column and the likely unit; a mismatch by
    another factor (beyond ±30 % for the triads) is returned as a WARN degradation
    ``(t, "WARN", text)``.  Fewer than 20 hanging samples: nothing is checked."""
    hang = imu.time < t_release
    out: list[tuple[float, str, str]] = []
    if hang.sum() < 20:
        return out
    problems = []
    for n in triads:
        cols = [f"{n}.{a}" for a in "xyz"]
        if not all(c in imu.channels for c in cols):
            continue
        g_meas = float(np.mean(np.linalg.norm(imu.stack(cols)[hang], axis=1)))
        ratio = g_meas / G0
        unit = imu.units[cols[0]]
        if not ratio > 0.0:  # all zeros: a dead triad (judged by the hanging checks and the dead-channel scan)
            out.append((float(t_release), "WARN", f"{fname}: the hanging lander reads 0 g on triad {n}"))
        elif abs(np.log(ratio)) > np.log(1.3):
            likely = likely_unit(ratio, unit)
            what = (
                f"the hanging lander reads {g_meas / G0:.4g} g on triad {n} (expected 1 g at rest): "
                f"the values look like [{likely}], not [{unit}]"
                if likely
                else f"the hanging lander reads {g_meas / G0:.4g} g on triad {n} (expected 1 g at rest)"
            )
            if likely:
                problems.append(Problem(fname, f"{cols[0]} [{unit}]", None, None, what))
            else:
                out.append((float(t_release), "WARN", f"{fname}: {what}"))
    cols = [f"gyro.{a}" for a in "xyz"]
    if all(c in imu.channels for c in cols) and gyro_noise_dps > 0:
        w = imu.stack(cols)[hang]
        spread = float(np.sqrt(np.mean(np.var(w, axis=0))))
        ratio = spread / np.radians(gyro_noise_dps)
        unit = imu.units[cols[0]]
        likely = likely_unit(ratio, unit, rtol=0.3) if ratio > 0.0 and abs(np.log(ratio)) > np.log(3.0) else None
        if likely:
            problems.append(
                Problem(
                    fname,
                    f"{cols[0]} [{unit}]",
                    None,
                    None,
                    f"the hanging gyro scatters {ratio:.3g}× its declared noise (sensors.gyro.noise_dps = "
                    f"{gyro_noise_dps:g}): the values look like [{likely}], not [{unit}]",
                )
            )
    if problems:
        raise TelemetryError(problems)
    return out


#: the mean-triad specific force [g] below which the airbags have not yet touched the surface: the
#: last sample at most this before an impact's first 2 g sample is the bags' first touch (the free
#: fall's end); low enough that one lobe alone carries it, high enough to stand out of the noise of
#: the mean of the triads only within the steep rise of a contact
TOUCH_G = 0.25


def check_free_fall(imu: Telemetry, events: dict[str, float], triads, fname: str) -> list[tuple[float, str, str]]:
    """The ``bungee_cut`` event against physics: right after the cut the lander falls freely, so
    the median specific force (norm of the mean of the ``triads``' accelerometers, m/s²) is below
    0.5 g over the *early* window from the cut + 10 ms to the earlier of + 60 ms and the bags'
    first touch (the last sample at most :data:`TOUCH_G` before the first impact sample, mean triad
    specific force above 2 g; none at all: not free fall).  Only up to the touch: the airbags load
    the lander gradually before the 2 g sample (a vertex first, three bags' corner lobes, for tens
    of ms), and the bungee swing before the cut (0.05–0.95 g) is not free fall over 50 ms.  If the
    window fails, and the cut time scaled by 1000 (a s ↔ ms mix-up in the events file) would pass,
    a :class:`TelemetryError` naming the events file and the likely unit; otherwise a WARN
    degradation.  Nothing is checked without a cut, an impact or
    10 samples in the window.  ``imu.time`` [s]; returns degradations ``(t [s], level, text)``."""
    if "bungee_cut" not in events:
        return []
    cols = [[f"{n}.{a}" for a in "xyz"] for n in triads]
    if not all(c in imu.channels for grp in cols for c in grp):
        return []
    f = np.linalg.norm(np.mean([imu.stack(grp) for grp in cols], axis=0), axis=1)

    def falls_freely(t_cut: float) -> bool | None:
        hard = np.flatnonzero((imu.time > t_cut) & (f > 2.0 * G0))
        if not hard.size:
            return None
        t0 = t_cut + 0.01
        if np.sum((imu.time > t0) & (imu.time < imu.time[hard[0]])) < 10:
            return None
        # the bags' first touch: the last sample at most TOUCH_G before the first impact sample
        quiet = np.flatnonzero((imu.time > t_cut) & (imu.time < imu.time[hard[0]]) & (f <= TOUCH_G * G0))
        if not quiet.size:
            return False
        t1 = min(t0 + 0.05, float(imu.time[quiet[-1]]))
        m = (imu.time > t0) & (imu.time <= t1)
        return None if m.sum() < 10 else bool(np.median(f[m]) < 0.5 * G0)

    cut = events["bungee_cut"]
    ok = falls_freely(cut)
    if ok is None or ok:
        return []
    for fac in (1e3, 1e-3):
        if imu.time[0] < cut * fac < imu.time[-1] and falls_freely(cut * fac):
            raise TelemetryError.single(
                fname,
                f"after the bungee cut at {cut:.6g} s the lander does not fall freely (median specific force "
                f"above 0.5 g), but it would after {cut * fac:.6g} s: the event times look 1000× too "
                f"{'small' if fac > 1 else 'large'} — "
                "a time unit mix-up (s ↔ ms)?",
                column="time",
            )
    return [(float(cut), "WARN", f"{fname}: the lander does not fall freely after the bungee cut at {cut:.4f} s")]


def _degrade(log: list, t: float, level: str, text: str) -> None:
    log.append((float(t), level, text))


def load_drop_telemetry(settings: DropSettings, paths: dict[str, Path]) -> DropTelemetry:
    """Read and validate the drop-test telemetry ``paths`` (:func:`telemetry_paths`) of a run with
    ``settings`` (its lander's lever arms); resample to the filter rate (see :class:`DropTelemetry`).

    The steps, in order (each error raised before any later file is read): read the IMU, 3DM and
    events files (:func:`_read_imu_3dm_events`), the events (:func:`_events`), unit plausibility from
    physics (:func:`check_units_at_rest`, :func:`check_free_fall`), the ranging file
    (:func:`_read_ranging`), the setup file as the filter mode needs it, the triads' lever arms;
    then the degradations (:func:`_stream_notes`, :func:`_usable_samples`), the average down to the
    filter rate (:func:`_average_down`) and the measured jerk (:func:`_jerk_indicator`)."""
    cfg = settings
    lander = settings.lander
    triads = cfg.accelerometer.triads
    imu, att, ev_list = _read_imu_3dm_events(settings, paths)
    att_log = _unit_vector_notes(att, paths["attitude_3dm"])
    events, ev_log = _events(ev_list, paths["events"])
    unit_notes = check_units_at_rest(imu, events["release"], triads, cfg.gyro.noise_dps, str(paths["imu"]))
    unit_notes += check_free_fall(imu, events, triads, str(paths["events"]))
    ranging, uses_odometer = _read_ranging(settings, paths["ranging"]) if "ranging" in paths else (None, False)
    setup = read_setup(
        paths["setup"], BUNGEE_KEYS if cfg.filter.mode == "dynamic" else ODOMETER_BUNGEE_KEYS if uses_odometer else ()
    )
    missing = [n for n in triads if n not in lander.instruments]
    if missing:
        raise ScenarioError(
            settings.path,
            "sensors.accelerometer.triads",
            f"triads {missing} have no lever arm in the lander asset's [instruments]",
        )

    log = att_log + ev_log + unit_notes + _stream_notes(imu, att, ranging, events, paths["attitude_3dm"])
    f_raw, f_ok, w_raw, w_ok = _usable_samples(settings, imu, events, paths["imu"], log)
    t, f_B, f_cnt, w_B, w_cnt, rate = _average_down(imu, f_raw, f_ok, w_raw, w_ok, cfg.filter.rate_hz)
    aq = cfg.acquisition
    filter_delay = acquisition_group_delay(aq.cutoff_hz, aq.order, aq.filter)
    delay = filter_delay + aq.latency_s  # the IMU tags' total lag behind the motion
    t = t - delay
    return DropTelemetry(
        t=t,
        f_B=f_B,
        f_valid=f_cnt > 0,
        w_B=w_B,
        w_valid=w_cnt > 0,
        hanging=t < events["release"],
        triads=triads,
        lever_arms_B=np.array([lander.instruments[n] for n in triads]),
        events=events,
        setup=setup,
        group_delay_s=delay,
        degradations=tuple(sorted(log)),
        imu=imu,
        attitude=att,
        ranging=ranging,
        jerk=_jerk_indicator(t, f_B, f_cnt, rate),
        counts=(f_cnt.astype(int), w_cnt.astype(int)),
        rate_hz=rate,
        time_shifts_s={
            "imu": delay,
            "attitude_3dm": cfg.attitude_3dm.latency_s,
            "ranging": cfg.ranging.latency_s + (filter_delay if cfg.ranging.acquisition_filter else 0.0),
        },
        time_shift_causes=time_shift_causes(settings, ranging is not None),
    )


Log = list[tuple[float, str, str]]


def _read_imu_3dm_events(settings: DropSettings, paths: dict[str, Path]) -> tuple[Telemetry, Telemetry, list]:
    """The IMU file (the triads' specific forces and the gyro rates, with their saturation levels:
    99.9 % of the declared full scale), the 3DM file (unit vectors) and the events list."""
    triads = settings.accelerometer.triads
    fs_acc = settings.accelerometer.full_scale_g * G0
    fs_gyr = np.radians(settings.gyro.full_scale_dps)
    required = {f"{n}.{a}": "acceleration" for n in triads for a in "xyz"}
    required.update({f"gyro.{a}": "angular_rate" for a in "xyz"})
    sat = {k: (0.999 * fs_acc if k.split(".")[0] != "gyro" else 0.999 * fs_gyr) for k in required}
    imu = read_telemetry(paths["imu"], required=required, saturation=sat)
    att = read_telemetry(
        paths["attitude_3dm"], required={f"{v}.{a}": "dimensionless" for v in ("up", "mag") for a in "xyz"}
    )
    return imu, att, read_events(paths["events"])


def _unit_vector_notes(att: Telemetry, path: Path) -> Log:
    """WARN where the 3DM ``up`` / ``mag`` vectors are not unit (beyond 5 %): only their directions are used."""
    log: Log = []
    for v in ("up", "mag"):
        norms = np.linalg.norm(att.stack([f"{v}.x", f"{v}.y", f"{v}.z"]), axis=1)
        if np.any(np.abs(norms - 1.0) > 0.05):
            k = int(np.argmax(np.abs(norms - 1.0)))
            log.append(
                (
                    float(att.time[k]),
                    "WARN",
                    f"{path}: '{v}' vectors are not unit (|v| = {norms.min():.3f}–"
                    f"{norms.max():.3f}, worst at row {k + 1}); only their directions are used",
                )
            )
    return log


def _events(ev_list: list, path: Path) -> tuple[dict[str, float], Log]:
    """Event name -> time [s] (the first of a repeated name, WARN), unknown labels WARNed with a
    "did you mean"; no ``release`` event is a :class:`ScenarioError` naming the events file."""
    events: dict[str, float] = {}
    log: Log = []
    for t_e, name in ev_list:
        if name in events:
            log.append(
                (
                    float(t_e),
                    "WARN",
                    f"{path}: event '{name}' repeated at {t_e:.4f} s; the first, at {events[name]:.4f} s, is used",
                )
            )
            continue
        events[name] = t_e
    if "release" not in events:
        raise ScenarioError(path, None, "no 'release' event: the reconstruction needs the release time")
    for t_e, name in ev_list:
        if name not in KNOWN_EVENTS:
            close = difflib.get_close_matches(name, KNOWN_EVENTS, n=1, cutoff=0.6)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            log.append(
                (
                    float(t_e),
                    "WARN",
                    f"{path}: unknown event label '{name}' at {t_e:.4f} s, ignored "
                    f"(known: {', '.join(KNOWN_EVENTS)}){hint}",
                )
            )
    return events, log


def _read_ranging(settings: DropSettings, path: Path) -> tuple[Telemetry, bool]:
    """The ranging file with the channels ``[sensors.ranging]`` names (sparse columns), and whether
    the odometer is used; a declared ``rate_hz`` off the file's median rate by more than 10 % is a
    :class:`ScenarioError` naming the scenario key."""
    spec = RangingSpec.from_settings(settings.ranging)
    req = {"odometer": "length"} if spec.odometer else {}
    for gun in spec.guns:
        req.update({f"{gun}.range": "length", f"{gun}.rate": "velocity"})
    ranging = read_telemetry(path, required=req, sparse=[k for k in req])
    if settings.ranging.rate_given and len(ranging) > 2:
        rate_file = 1.0 / float(np.median(np.diff(ranging.time)))
        if abs(rate_file / spec.rate_hz - 1.0) > 0.1:
            raise ScenarioError(
                settings.path,
                "sensors.ranging.rate_hz",
                f"{spec.rate_hz:g} Hz, but {path} is sampled at {rate_file:.4g} Hz "
                "(median interval); correct the key or leave it out",
            )
    return ranging, spec.odometer


def _stream_notes(
    imu: Telemetry, att: Telemetry, ranging: Telemetry | None, events: dict[str, float], att_path: Path
) -> Log:
    """The readers' notes of every file, a 3DM record that ends well before the release
    (truncated?), and the gaps of the 3DM and ranging files (WARN)."""
    log: Log = []
    for tf in (imu, att, ranging):
        if tf is not None:
            log += [(float(tf.time[-1]), "WARN", note) for note in tf.notes]
    if att.time.size > 1:
        early = events["release"] - float(att.time[-1])
        if early > max(0.2, 10.0 * float(np.median(np.diff(att.time)))):
            _degrade(
                log,
                float(att.time[-1]),
                "WARN",
                f"{att_path}: the readings end {early:.3g} s before the release: truncated?",
            )
    for tf in (att, ranging):
        for gap in tf.gaps if tf is not None else ():
            _degrade(
                log,
                gap.start_s,
                "WARN",
                f"{tf.path}: gap {gap.start_s:.4f}–{gap.end_s:.4f} s ({gap.duration_s * 1e3:.1f} ms, row {gap.row})",
            )
    return log


def _usable_samples(
    settings: DropSettings, imu: Telemetry, events: dict[str, float], imu_path: Path, log: Log
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The raw triad forces ``f_raw`` (n, n_triads, 3) [m/s²] and gyro rates ``w_raw`` (n, 3)
    [rad/s] with their usable-sample masks: saturated samples dropped, a triad with a dead channel
    (no variation after release) excluded (ERROR), IMU gaps noted; appends to ``log``.  No usable
    triad at all is a :class:`ScenarioError` naming the IMU file."""
    triads = settings.accelerometer.triads
    f_raw = np.stack([imu.stack([f"{n}.x", f"{n}.y", f"{n}.z"]) for n in triads], axis=1)  # (n,4,3)
    w_raw = imu.stack(["gyro.x", "gyro.y", "gyro.z"])
    f_ok, w_ok = _unsaturated(settings, imu, log)
    _dead_channels(triads, imu, f_raw, f_ok, events, log)
    if (imu.time >= events["release"]).sum() > 10 and not f_ok.any():
        raise ScenarioError(imu_path, None, "no usable accelerometer triad (all dead)")
    for gap in imu.gaps:
        _degrade(
            log,
            gap.start_s,
            "WARN",
            f"IMU gap {gap.start_s:.4f}–{gap.end_s:.4f} s ({gap.duration_s * 1e3:.1f} ms, row {gap.row}): "
            "bridged by propagation, covariance grows",
        )
    return f_raw, f_ok, w_raw, w_ok


def _unsaturated(settings: DropSettings, imu: Telemetry, log: Log) -> tuple[np.ndarray, np.ndarray]:
    """The masks of unsaturated samples: per triad (n, n_triads) and for the gyro (n,) (a
    saturated gyro axis drops the gyro sample: the rate is then carried by the lever arms)."""
    triads = settings.accelerometer.triads
    fs_acc = settings.accelerometer.full_scale_g * G0
    fs_gyr = np.radians(settings.gyro.full_scale_dps)
    n_raw = len(imu)
    f_ok = np.ones((n_raw, len(triads)), bool)
    for j, n in enumerate(triads):
        s = np.zeros(n_raw, bool)
        for a in "xyz":
            s |= imu.saturated[f"{n}.{a}"]
        if s.any():
            f_ok[s, j] = False
            _degrade(
                log,
                imu.time[np.argmax(s)],
                "WARN",
                f"triad {n}: {int(s.sum())} saturated samples (±{fs_acc / G0:g} g) dropped from the filter",
            )
    w_ok = np.ones(n_raw, bool)
    for a in "xyz":
        s = imu.saturated[f"gyro.{a}"]
        if s.any():
            w_ok &= ~s
            _degrade(
                log,
                imu.time[np.argmax(s)],
                "WARN",
                f"gyro.{a}: {int(s.sum())} saturated samples (±{np.degrees(fs_gyr):g} °/s); gyro dropped, "
                "rate carried by the triads' lever arms",
            )
    return f_ok, w_ok


def _dead_channels(
    triads: tuple[str, ...], imu: Telemetry, f_raw: np.ndarray, f_ok: np.ndarray, events: dict, log: Log
) -> None:
    """Exclude (in ``f_ok``, ERROR in ``log``) a triad with a channel that does not vary after the
    release while the others see the impact."""
    moving = imu.time >= events["release"]
    if moving.sum() > 10:
        spread = np.ptp(f_raw[moving], axis=0)  # (4,3)
        ref = np.median(spread)
        for j, n in enumerate(triads):
            dead_axes = [a for i, a in enumerate("xyz") if spread[j, i] < 1e-3 * max(ref, 1.0)]
            if dead_axes:
                f_ok[:, j] = False
                _degrade(
                    log,
                    events["release"],
                    "ERROR",
                    f"triad {n}: channel(s) {', '.join(dead_axes)} dead (no variation after release): "
                    "triad excluded from the reconstruction",
                )


def _average_down(
    imu: Telemetry, f_raw: np.ndarray, f_ok: np.ndarray, w_raw: np.ndarray, w_ok: np.ndarray, rate_req: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Average the usable samples down to the filter rate: a boxcar of k IMU samples (k the whole
    number nearest the requested ``rate_req`` [Hz]), grouped on the uniform sample grid.  Returns
    the step times (n,) [s, IMU tags], the mean forces and the samples in each ``(f_B, f_cnt)``,
    the mean rates ``(w_B, w_cnt)`` and the rate actually used [Hz]."""
    n_raw = len(imu)
    dt_raw = float(np.median(np.diff(imu.time)))
    k = max(1, int(round(1.0 / (rate_req * dt_raw))))
    rate = 1.0 / (k * dt_raw)  # the grid actually used: a whole number k of IMU samples per step
    slot = np.floor((imu.time - imu.time[0]) / (k * dt_raw) + 1e-6).astype(int)
    starts = np.flatnonzero(np.r_[True, np.diff(slot) != 0])
    counts = np.diff(np.r_[starts, n_raw])

    def avg(x, ok):
        okf = ok.astype(float)
        num = np.add.reduceat(x * okf[..., None], starts, axis=0)
        den = np.add.reduceat(okf, starts, axis=0)
        return num / np.maximum(den, 1.0)[..., None], den

    t = np.add.reduceat(imu.time, starts) / counts
    f_B, f_cnt = avg(f_raw, f_ok)
    w_B, w_cnt = avg(w_raw, w_ok)
    return t, f_B, f_cnt, w_B, w_cnt, rate


def _jerk_indicator(t: np.ndarray, f_B: np.ndarray, f_cnt: np.ndarray, rate: float) -> np.ndarray:
    """The measured jerk indicator (n,) [m/s³] that raises the process noise: the centred
    difference of 10 ms means of the mean triad force (slots without a valid triad hold the last
    valid mean, so no artificial jerk spike)."""
    fbar = np.where(f_cnt[..., None] > 0, f_B, np.nan)
    with np.errstate(invalid="ignore"):
        fbar = np.nanmean(fbar, axis=1)
    ok_rows = np.flatnonzero(np.all(np.isfinite(fbar), axis=1))
    if ok_rows.size:  # slots with no valid triad: hold the last valid mean (no artificial jerk spike)
        fill = ok_rows[np.clip(np.searchsorted(ok_rows, np.arange(fbar.shape[0]), side="right") - 1, 0, None)]
        fbar = fbar[fill]
    L = max(1, int(round(0.010 * rate)))
    ker = np.ones(L) / L
    sm = np.stack([np.convolve(np.nan_to_num(fbar[:, i]), ker, mode="same") for i in range(3)], 1)
    jerk = np.zeros(t.size)
    if t.size > 2 * L:
        d = np.zeros_like(sm)
        d[L:-L] = (sm[2 * L :] - sm[: -2 * L]) / (2 * L / rate)
        jerk = np.linalg.norm(d, axis=1)
    return jerk
