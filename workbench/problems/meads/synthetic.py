"""Synthetic MSL-like entry for the flush air data problem: truth -> files exactly as a user supplies them.

:func:`synthesize_meads` runs :func:`.truth.simulate_entry`, the pressure error chain and the IMU
(:mod:`.sensors`) and writes ``pressures.csv`` (8 Hz, one column per port, Pa), ``imu.csv``,
``initial_state.toml`` (formats in :mod:`.telemetry`) and ``truth.npz`` (scoring and drawing only).
Seeds: the sensor draws use ``SeedSequence(seed)`` spawned into (pressures, imu, navigation).
:func:`synthesize_from_truth` is the same on a given truth and seed sequence (the Monte Carlo
against the truth simulator, :mod:`.truth_mc`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.io.telemetry import atomic_write_npz, write_telemetry
from workbench.problems.meads.config import MeadsSettings
from workbench.problems.meads.sensors import initial_navigation, measure_imu, measure_pressures
from workbench.problems.meads.telemetry import IMU_COLUMNS, InitialState, write_initial_state
from workbench.problems.meads.truth import MeadsTruth, MeadsTruthSpec, simulate_entry

__all__ = ["synthesize_meads", "synthesize_from_truth", "load_truth", "TruthArrays"]


class TruthArrays(dict):
    """The arrays of ``truth.npz`` by name (a dict: truth fields on the simulation grid ``t``,
    ``sensor_*`` of the pressure chain, ``imu_*``) with the truth on an estimate's grid."""

    def at(self, key: str, t: np.ndarray, scale: float = 1.0, col: int | None = None) -> np.ndarray:
        """``scale`` × the truth field ``key`` (column ``col`` of a 2-D one) linearly interpolated
        at the times ``t`` (n,) [s] of an estimate."""
        y = self[key] if col is None else self[key][:, col]
        return scale * np.interp(t, self["t"], y)


def synthesize_meads(settings: MeadsSettings, out_dir: str | Path, seed: int) -> dict[str, Path]:
    """Simulate the entry of ``settings.truth`` with ``settings.vehicle`` and write the telemetry +
    ``truth.npz`` into ``out_dir``; returns {stream: path, "truth": path}."""
    truth = simulate_entry(settings.vehicle, settings.truth)
    return synthesize_from_truth(
        settings,
        truth,
        settings.truth,
        out_dir,
        np.random.SeedSequence(seed),
        f"workbench synthetic {settings.run.name} (seed {seed})",
    )


def synthesize_from_truth(
    settings: MeadsSettings,
    truth: MeadsTruth,
    truth_spec: MeadsTruthSpec,
    out_dir: str | Path,
    seed: np.random.SeedSequence,
    source: str,
    *,
    compress: bool = True,
) -> dict[str, Path]:
    """The sensors of ``settings`` (``pressure``, ``imu``, ``navigation``, on ``settings.vehicle``)
    on a simulated ``truth`` (whose surface-pressure model is ``truth_spec``'s), written into
    ``out_dir`` as a user supplies them plus ``truth.npz``; the draws are ``seed.spawn(3)``
    (pressures, IMU, navigation); ``source`` goes into the files' metadata; ``compress``: write
    ``truth.npz`` compressed (False: stored, for a file read back once and deleted, e.g. a Monte
    Carlo member's; the arrays are the same).  Returns {stream: path, "truth": path}."""
    cfg, vehicle = settings, settings.vehicle
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rp, ri, rn = (np.random.default_rng(s) for s in seed.spawn(3))
    pm = measure_pressures(truth, vehicle, truth_spec, cfg.pressure, rp)
    ti, f, w, drawn = measure_imu(truth, cfg.imu.model, cfg.imu.rate_hz, ri)
    p0, v0, q0, sig = initial_navigation(truth, cfg.navigation, rn)
    meta = {"source": source, "frame": "body B (+x out of the nose)"}
    pressures = write_telemetry(
        out / "pressures.csv",
        pm.t,
        {n: (pm.p[:, j], "Pa") for j, n in enumerate(vehicle.port_names)},
        meta={**meta, "rate_hz": cfg.pressure.rate_hz},
    )
    cols = {c: (f[:, k], "m/s^2") for k, c in enumerate(IMU_COLUMNS[:3])}
    cols |= {c: (w[:, k], "deg/s") for k, c in enumerate(IMU_COLUMNS[3:])}
    imu = write_telemetry(out / "imu.csv", ti, cols, meta={**meta, "rate_hz": cfg.imu.rate_hz})
    init = write_initial_state(
        out / "initial_state.toml",
        InitialState(0.0, p0, v0, q0, float(sig[0]), float(sig[1]), float(sig[2])),
        "navigation state at the entry interface (inertial frame M, +Z the pole; q_M_B body -> M)",
    )
    arrays = truth.arrays()
    arrays |= {f"sensor_{k}": np.asarray(v) for k, v in pm.__dict__.items()}
    arrays |= {f"imu_{k}": np.asarray(v) for k, v in drawn.items()}
    atomic_write_npz(out / "truth.npz", arrays, compress=compress)
    return {"pressures": pressures, "imu": imu, "initial_state": init, "truth": out / "truth.npz"}


def load_truth(path: str | Path) -> TruthArrays:
    """The arrays of ``truth.npz`` (truth fields, ``sensor_*`` of the pressure chain, ``imu_*``)."""
    with np.load(path) as z:
        return TruthArrays({k: z[k] for k in z.files})
