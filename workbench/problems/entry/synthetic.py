"""Synthetic Schiaparelli-like entry: truth simulation -> telemetry files exactly as a user supplies them.

The truth (``problems.entry.truth.simulate_entry``) is turned into the real-time telemetry of AMELIA
Table 1 by ``sensors.entry.generate_entry_tm`` (IMU errors, gyro clipping, the on-board strapdown
from an erroneous nominal state, blackout gaps, radar) and written in the documented CSV format
(``io/FORMATS.md``), times in seconds from the entry interface point (EIP), a ``# epoch_utc:``
line in every file:

* ``gnc.csv`` (10 Hz) — ``w_x, w_y, w_z [deg/s]`` measured body rate (GNC frame, clipped at the
  gyro range), ``q1..q4 [1]`` on-board attitude as the JPL quaternion "MMED to GNC" (q4 scalar;
  numerically the components of the Hamilton ``q_M_G``), ``a_x, a_y, a_z [m/s^2]`` the on-board
  total inertial acceleration in MMED, gravity included;
* ``gnc_nav.csv`` (1 Hz) — on-board position ``p_x.. [km]`` and velocity ``v_x.. [km/s]`` (MMED);
* ``rda_slant_range.csv`` (0.1 Hz) — ``B0..B3 [m]`` slant ranges of the four beams (the first
  packets zero-filled, as flown);
* ``rda_out.csv`` (10 Hz) — ``slant_out [m]`` along B0 and ``v_out_x.. [m/s]`` the
  terrain-relative velocity in the GNC frame;
* ``events.csv`` — EIP, PDD, FSR, RDA_ON, BSR;
* ``initial_state.toml`` — the nominal initial state at the first TM time (AMELIA Table 2 style:
  TGO-predicted position/velocity and the on-board attitude; here the on-board navigation's
  initial state, a few km, ~15 m/s and ~1° off the truth).

Rows inside the blackout windows are absent.  The truth and the on-board internals (nominal
initial state and its error, the 100 Hz on-board solution, drawn IMU errors) go to ``truth.npz``
for scoring and drawing only; the reconstruction reads the telemetry files and never this one.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from workbench.io.telemetry import atomic_write_npz, write_events, write_telemetry
from workbench.problems.entry.sensors import EntryTelemetrySpec, EntryTM, generate_entry_tm
from workbench.problems.entry.telemetry import NominalState, write_nominal_state

if TYPE_CHECKING:
    from workbench.problems.entry.config import EntrySettings

__all__ = [
    "TELEMETRY_FILES",
    "truth_for",
    "write_entry_telemetry",
    "synthesize_from_truth",
    "synthesize_entry",
    "load_truth",
    "load_entry_truth",
]

#: Logical stream name -> file name written by :func:`write_entry_telemetry` (the ``[telemetry]``
#: keys a user scenario gives).
TELEMETRY_FILES = {
    "gnc": "gnc.csv",
    "gnc_nav": "gnc_nav.csv",
    "rda_slant_range": "rda_slant_range.csv",
    "rda_out": "rda_out.csv",
    "events": "events.csv",
}


_TRUTH_CACHE: dict[tuple, object] = {}


def truth_for(settings: EntrySettings):
    """Truth simulation of the run (``EntryTruth``), deterministic per settings: its random
    parts (true atmosphere, winds) draw from ``synthetic.truth_seed`` (default ``synthetic.seed``).
    Cached per process, keyed by vehicle file, truth spec and seed (when the spec is hashable)."""
    from workbench.problems.entry.truth import simulate_entry

    vpath = settings.vehicle_path
    spec = settings.synthetic.truth
    tseed = settings.synthetic.truth_seed
    try:
        key = (str(vpath), spec, tseed)
        hash(key)
    except TypeError:
        key = None
    if key is not None and key in _TRUTH_CACHE:
        return _TRUTH_CACHE[key]
    truth = simulate_entry(settings.require_vehicle(), spec, np.random.default_rng([tseed, 1]))
    if key is not None:
        if len(_TRUTH_CACHE) >= 4:
            _TRUTH_CACHE.pop(next(iter(_TRUTH_CACHE)))
        _TRUTH_CACHE[key] = truth
    return truth


def write_entry_telemetry(tm: EntryTM, out_dir: str | Path, *, source: str = "synthetic") -> dict[str, Path]:
    """Write ``tm`` as the five telemetry files in ``out_dir`` (see the module docstring).

    Returns ``{stream: path}`` with the keys of :data:`TELEMETRY_FILES`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    common = {"epoch_utc": tm.epoch_utc or "unknown", "time_reference": "s from the entry interface point (EIP)"}
    common["source"] = source
    q = tm.q_jpl  # JPL MMED->GNC: numerically the components of q_M_G (rotation.quat_from_jpl)
    ch: dict[str, tuple[np.ndarray, str]] = {}
    ch.update({f"w_{a}": (tm.w_G[:, i], "deg/s") for i, a in enumerate("xyz")})
    ch.update({f"q{i + 1}": (q[:, i], "1") for i in range(4)})
    ch.update({f"a_{a}": (tm.a_M_total[:, i], "m/s^2") for i, a in enumerate("xyz")})
    paths = {
        "gnc": write_telemetry(
            out / TELEMETRY_FILES["gnc"],
            tm.t_gnc,
            ch,
            meta={
                "sensor": "GNC real-time TM: body rate (GNC), JPL quaternion MMED->GNC (q4 scalar), "
                "total inertial acceleration (MMED, gravity included)",
                "rate_hz": 10,
                **common,
            },
        )
    }
    nav = {f"p_{a}": (tm.p_M[:, i], "km") for i, a in enumerate("xyz")}
    nav.update({f"v_{a}": (tm.v_M[:, i], "km/s") for i, a in enumerate("xyz")})
    paths["gnc_nav"] = write_telemetry(
        out / TELEMETRY_FILES["gnc_nav"],
        tm.t_nav,
        nav,
        meta={"sensor": "GNC real-time TM: on-board position and velocity (MMED)", "rate_hz": 1, **common},
    )
    if tm.t_sr.size:
        paths["rda_slant_range"] = write_telemetry(
            out / TELEMETRY_FILES["rda_slant_range"],
            tm.t_sr,
            {f"B{i}": (tm.slant_ranges[:, i], "m") for i in range(4)},
            meta={
                "sensor": "RDA slant-range packets, beams B0..B3 (0 = no data / zero-filled packet)",
                "rate_hz": 0.1,
                **common,
            },
        )
    if tm.t_rda.size:
        rch = {"slant_out": (tm.slant_out, "m")}
        rch.update({f"v_out_{a}": (tm.v_out_G[:, i], "m/s") for i, a in enumerate("xyz")})
        paths["rda_out"] = write_telemetry(
            out / TELEMETRY_FILES["rda_out"],
            tm.t_rda,
            rch,
            meta={
                "sensor": "RDA slant-out along B0 and terrain-relative velocity in the GNC frame",
                "rate_hz": 10,
                **common,
            },
        )
    paths["events"] = write_events(
        out / TELEMETRY_FILES["events"], [(t, name) for name, t in tm.events.items()], meta=common
    )
    return paths


def _truth_arrays(truth) -> dict[str, np.ndarray]:
    """Every array (and scalar) of an EntryTruth-like object, flattened for ``np.savez``."""
    items = (
        {f.name: getattr(truth, f.name) for f in dataclasses.fields(truth)}
        if dataclasses.is_dataclass(truth)
        else dict(vars(truth))
    )
    out: dict[str, np.ndarray] = {}
    for name, v in items.items():
        if name == "events":
            ev = dict(v)
            out["event_names"] = np.array(list(ev), dtype=str)
            out["event_times"] = np.array(list(ev.values()), dtype=float)
        elif isinstance(v, np.ndarray):
            out[name] = v
        elif isinstance(v, bool | int | float | str):
            out[name] = np.array(v)
        elif v is not None and dataclasses.is_dataclass(v):  # e.g. the true TabulatedAtmosphere
            for f in dataclasses.fields(v):
                a = getattr(v, f.name)
                if isinstance(a, np.ndarray):
                    out[f"{name}_{f.name}"] = a
                elif name == "atmosphere" and isinstance(a, int | float | str) and not isinstance(a, bool):
                    out[f"{name}_{f.name}"] = np.array(a)
    return out


def synthesize_from_truth(
    truth,
    out_dir: str | Path,
    spec: EntryTelemetrySpec,
    seed: int,
    *,
    source: str | None = None,
    compress: bool = True,
) -> dict[str, Path]:
    """Telemetry files + ``truth.npz`` from a given truth (an ``EntryTruth`` or look-alike).

    ``seed`` drives every random draw (nominal-state error, IMU errors and noise, radar noise).
    ``compress``: write ``truth.npz`` compressed (False: stored, for files read back once and
    deleted, e.g. a Monte Carlo member's; the arrays are the same).
    Returns ``{stream: path}`` plus ``"truth"`` and ``"initial_state"``.
    """
    out = Path(out_dir)
    tm = generate_entry_tm(truth, spec, np.random.default_rng([int(seed), 2]))
    paths = write_entry_telemetry(tm, out, source=source or f"synthetic entry, seed {seed}")
    t0, v0, q0, p0, dx0 = tm.nominal
    ev = dict(truth.events)
    ev.update({k: v for k, v in tm.events.items() if k not in ev})
    arrays = _truth_arrays(truth)
    arrays["event_names"] = np.array(list(ev), dtype=str)
    arrays["event_times"] = np.array(list(ev.values()), dtype=float)
    tspec = getattr(truth, "spec", None)
    if tspec is not None and hasattr(tspec, "ca_deviation"):  # the planted coefficient deviations
        for k in ("aero_deviation_mach", "ca_deviation", "parachute_deviation_mach", "parachute_cd_deviation"):
            arrays[f"planted_{k}"] = np.asarray(getattr(tspec, k), dtype=float)
        arrays["planted_cn_deviation"] = np.array(float(tspec.cn_deviation))
        arrays["planted_cm_deviation"] = np.array(float(tspec.cm_deviation))
    if tm.slant_out_true is not None and tm.slant_out_true.size:
        arrays["radar_t"] = tm.t_rda
        arrays["radar_slant_out_true"] = tm.slant_out_true
        arrays["radar_slant_out_sphere"] = tm.slant_out_sphere
    truth_path = out / "truth.npz"
    atomic_write_npz(
        truth_path,
        dict(
            arrays,
            nominal_t0=np.array(t0),
            nominal_v0=v0,
            nominal_q0=q0,
            nominal_p0=p0,
            nominal_dx0=dx0,
            onboard_t=tm.onboard.t,
            onboard_v_M=tm.onboard.v_M,
            onboard_q_M_G=tm.onboard.q_M_G,
            onboard_p_M=tm.onboard.p_M,
            onboard_w_G=tm.onboard.w_G,
            onboard_f_G=tm.onboard.f_G,
            **{f"imu_{k}": v for k, v in tm.imu_errors.items()},
            gyro_full_scale=np.asarray(spec.imu.gyro_full_scale),
            r_ground=np.array(spec.r_ground),
            seed=np.array(int(seed)),
        ),
        compress=compress,
    )
    paths["truth"] = truth_path
    paths["initial_state"] = write_nominal_state(
        out / "initial_state.toml",
        NominalState(t0=t0, v_M=v0, p_M=p0, q_M_G=q0),
        comment="On-board navigation initial state (TGO prediction + on-board attitude).",
    )
    return paths


def synthesize_entry(settings: EntrySettings, out_dir: str | Path, seed: int | None = None) -> dict[str, Path]:
    """Simulate the run's entry and write its telemetry files (and ``truth.npz``) into ``out_dir``.

    ``seed`` (default ``[synthetic] seed``) drives the sensor-side draws; the truth trajectory is
    deterministic per settings (:func:`truth_for`).  Returns ``{stream: path}`` (keys of
    :data:`TELEMETRY_FILES` plus ``"initial_state"`` and ``"truth"``).
    """
    seed = int(settings.synthetic.seed if seed is None else seed)
    return synthesize_from_truth(truth_for(settings), out_dir, settings.synthetic.telemetry, seed)


def load_truth(path: str | Path) -> dict:
    """Load ``truth.npz`` written by :func:`synthesize_entry` (scoring and drawing only).

    Arrays keep their EntryTruth names; ``events`` becomes a dict; 0-d arrays become scalars;
    ``atmosphere`` is the true :class:`~workbench.core.atmosphere.TabulatedAtmosphere` rebuilt
    from its tables (``atmosphere_*``); ``nominal_*`` hold the on-board initial state at
    ``nominal_t0`` and ``nominal_dx0`` its error (truth − nominal, ``[δv, δθ, δp]``);
    ``onboard_*`` the 100 Hz on-board solution (t, v_M, q_M_G, p_M and the measured w_G, f_G);
    ``imu_*`` the per-run IMU errors; ``planted_*`` the planted coefficient deviations (truth
    spec); ``radar_t``, ``radar_slant_out_true`` / ``radar_slant_out_sphere`` the noise-free
    slant-out on the true terrain and on the estimator's sphere [m].
    """
    with np.load(path) as z:
        d = {k: z[k] for k in z.files}
    d["events"] = {str(k): float(v) for k, v in zip(d.pop("event_names"), d.pop("event_times"), strict=True)}
    for k, v in list(d.items()):
        if isinstance(v, np.ndarray) and v.ndim == 0:
            d[k] = v.item()
    if "seed" in d:
        d["seed"] = int(d["seed"])
    if all(f"atmosphere_{k}" in d for k in ("h", "rho", "p", "T")):
        from workbench.core.atmosphere import TabulatedAtmosphere

        names = {f.name for f in dataclasses.fields(TabulatedAtmosphere)}
        kw = {k[len("atmosphere_") :]: v for k, v in d.items() if k.startswith("atmosphere_")}
        d["atmosphere"] = TabulatedAtmosphere(**{k: v for k, v in kw.items() if k in names})
    return d


#: The name the CLI uses.
load_entry_truth = load_truth
