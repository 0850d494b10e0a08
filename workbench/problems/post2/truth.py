"""The post2 truth simulator and sensors: what a synthetic scenario's observation files come from.

It is not the estimator's model (no "inverse crime"); what differs, by design:

* **integrator**: adaptive DOP853 (``scipy.integrate.solve_ivp``, ``[truth] rtol``) with the events
  located by the integrator (terminal event functions) — the estimator uses fixed-step RK4 of
  ``[model] step_s`` and checks its events on its grid;
* **atmosphere**: the scenario's atmosphere times ``1 + a sin(2π h / λ)`` (``[truth]
  density_wave_amplitude``, ``density_wave_length_m``), which the estimator does not know;
* **aerodynamics**: the table's CA, CN, Cm times ``[truth] ca_factor``, ``cn_factor``, ``cm_factor``
  (and any multiplier named in ``[truth.states]``);
* **initial state and parameters**: ``[truth.states]`` (the estimator starts from ``[states.*]
  value``); sensor bias and radar scale factor as planted there;
* **sensors**: white noise of ``noise_sigma`` (default the observation's ``sigma``) from a seeded
  generator.

The equations of motion (gravity with J2, the aerodynamic force/moment laws, rigid-body rotation)
are the model's: the premise of the POST2 method is that the reconstruction uses the same
simulation as the design (thesis [R3] Ch. 3.1); the truth differs in everything listed above.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from workbench.core.atmosphere import TabulatedAtmosphere, TitanDefaultAtmosphere
from workbench.core.rotation import quat_boxplus, quat_normalize
from workbench.io.telemetry import write_telemetry
from workbench.problems.post2 import build
from workbench.problems.post2.config import Post2Settings
from workbench.problems.post2.model import (
    DESCENT_NOMINALS,
    OBSERVATIONS,
    CaMachWave,
    DensityWave,
    StateMap,
    TrajectoryModel,
    quat_from_aero_angles,
)

__all__ = ["truth_model", "simulate_truth", "write_observations", "sample_times"]


def _truth_value(cfg: Post2Settings, name: str, default=None):
    if name in cfg.truth.states:
        return cfg.truth.states[name]
    s = cfg.state(name)
    return s.value if s is not None else default


def truth_model(cfg: Post2Settings) -> TrajectoryModel:
    """The truth's :class:`TrajectoryModel` (its own atmosphere wave and aero factors; parameters at
    their truth values, none estimated)."""
    tr = cfg.truth
    a, lam = tr.density_wave_amplitude, tr.density_wave_length_m

    env = build.environment(cfg, density_factor=DensityWave(a, lam) if a else None)
    j2 = _truth_value(cfg, "j2")
    if j2 is not None:
        env = replace(env, j2=float(j2[0]))
    mult = {k: float(_truth_value(cfg, f"{k}_multiplier", np.ones(1))[0]) for k in ("ca", "cn", "cm")}
    veh = build.vehicle(cfg, tr.ca_factor * mult["ca"], tr.cn_factor * mult["cn"], tr.cm_factor * mult["cm"])
    if "parachute_drag_multiplier" in cfg.truth.states and veh.parachute is not None:
        m = float(cfg.truth.states["parachute_drag_multiplier"][0])
        veh = replace(veh, parachute=replace(veh.parachute, cd=veh.parachute.cd * m))
    names = ["position", "velocity"] + (["attitude", "body_rates"] if cfg.dof == 6 else [])
    # ---- Huygens-like descent: planted descent parameters, own Titan atmosphere, CA(Mach) error
    nominal = {k: float(cfg.truth.states[k][0]) for k in DESCENT_NOMINALS if k in cfg.truth.states}
    if tr.titan_node_altitudes_m is not None:
        lay = TitanDefaultAtmosphere(
            node_altitudes=tuple(float(v) for v in tr.titan_node_altitudes_m),
            node_temperatures=tuple(float(v) for v in tr.titan_node_temperatures_K or ()),
        )
        hs = np.arange(0.0, 1.4e6 + 1.0, 250.0)  # sampled finely once: the layered model is slow per call
        atm = TabulatedAtmosphere(
            hs, lay.density(hs), lay.pressure(hs), lay.temperature(hs),
            lay.gas_constant, lay.gamma, lay.sutherland, extrapolate="clamp",
        )  # fmt: skip
        env = replace(env, atmosphere=atm)
    if tr.ca_mach_wave_amplitude:
        aw = float(tr.ca_mach_wave_amplitude)
        veh = replace(veh, ca_mach_factor=CaMachWave(aw))
    return TrajectoryModel(StateMap(names), cfg.dof, env, veh, build.events(cfg, truth=True), nominal=nominal)


def _x0(model: TrajectoryModel, cfg: Post2Settings) -> np.ndarray:
    sm = model.smap
    x = np.zeros(sm.n_x)
    for name in ("position", "velocity", "body_rates"):
        if name in sm:
            x[sm.blocks[name].sx] = _truth_value(cfg, name)
    if "attitude" in sm:
        x[sm.blocks["attitude"].sx] = quat_from_aero_angles(
            sm.raw(x, "position"), model.v_rel(x), _truth_value(cfg, "attitude")
        )
    return x


def simulate_truth(cfg: Post2Settings, extra_times: np.ndarray | None = None) -> dict:
    """Integrate the truth from ``[model] t_start_s`` to ``t_end_s``; returns ``t`` (n,) [s] (the
    ``output_step_s`` grid united with ``extra_times``), ``x`` (n, n_x) in the truth map's layout
    (position, velocity[, quaternion q_I_B, body rates]), ``phase_index`` (n,) into ``phases`` (the
    phase dicts), ``events`` [(t, name)], ``model``."""
    tr = cfg.truth
    model = truth_model(cfg)
    n_out = int(round((cfg.t_end - cfg.t_start) / tr.output_step_s))
    grid = np.unique(
        np.round(
            np.concatenate(
                [
                    cfg.t_start + tr.output_step_s * np.arange(n_out + 1),
                    np.empty(0) if extra_times is None else extra_times,
                ]
            ),
            9,
        )
    )
    grid = grid[(grid >= cfg.t_start - 1e-9) & (grid <= cfg.t_end + 1e-9)]
    x = _x0(model, cfg)
    phase = model.check_events(x, cfg.t_start, model.initial_phase())
    phases = [phase]
    X = np.empty((grid.size, x.size))
    pidx = np.zeros(grid.size, dtype=int)
    fired: list[tuple[float, str]] = []
    t = cfg.t_start
    done = 0
    sq = model.smap.blocks["attitude"].sx if cfg.dof == 6 else None
    while True:
        pending = [e for e in model.events if e.name not in phase["fired"]]
        t_stop = min([cfg.t_end] + [e.value for e in pending if e.when == "time" and e.value > t])
        funcs, cond = [], []
        for e in pending:
            if e.when == "time":
                continue
            cond.append(e)

            def fn(tt, y, e=e):
                return model.event_margin(y, e)

            fn.terminal = True
            funcs.append(fn)
        rest = grid[done:]
        t_eval = np.clip(rest[rest <= t_stop + 1e-12], t, t_stop)  # each grid sample exactly once
        sol = solve_ivp(
            lambda tt, y, phase=phase: model.derivative(y, phase),
            (t, t_stop),
            x,
            method="DOP853",
            t_eval=t_eval,
            rtol=tr.rtol,
            atol=1e-9,
            events=funcs or None,
            dense_output=True,
        )
        ys = np.asarray(sol.y, dtype=float).reshape(x.size, -1).T
        if sq is not None and ys.size:
            ys[:, sq] = quat_normalize(ys[:, sq])
        X[done : done + ys.shape[0]] = ys
        pidx[done : done + ys.shape[0]] = len(phases) - 1
        done += ys.shape[0]
        new = phase
        if sol.status == 1:  # a condition event: fire it (its margin is ~0 at the located time)
            i = next(i for i, te in enumerate(sol.t_events) if te.size)
            t, x = float(sol.t_events[i][0]), np.array(sol.y_events[i][0])
            new = model.apply_event(phase, cond[i])
        else:
            t, x = t_stop, np.asarray(sol.sol(t_stop), dtype=float)
            if t >= cfg.t_end - 1e-9:
                break
        new = model.check_events(x, t + 1e-9, new)
        fired += [(t, n) for n in new["fired"][len(phase["fired"]) :]]
        phase = new
        phases.append(phase)
    return {
        "t": grid[:done],
        "x": X[:done],
        "phase_index": pidx[:done],
        "phases": phases,
        "events": fired,
        "model": model,
    }


def write_observations(cfg: Post2Settings, truth: dict, out_dir: Path, rng: np.random.Generator):
    """Sample every declared observation from the truth, add the sensor errors, and write
    ``<name>.csv`` (and ``<name>_weights.csv`` when the observation names a weights file: W = 1/σ²,
    column unit ``1`` meaning 1/SI²) into ``out_dir``; returns {stream: path}."""
    out = {}
    model: TrajectoryModel = truth["model"]
    t_all = truth["t"]
    bias = _truth_value(cfg, "accel_bias", np.zeros(3))
    scale = float(_truth_value(cfg, "radar_scale_factor", np.ones(1))[0])
    for spec in cfg.observations:
        d = OBSERVATIONS[spec.quantity]
        ts = _sample_times(cfg, spec)
        k = np.searchsorted(t_all, np.round(ts, 9))
        if np.any(k >= t_all.size) or np.any(np.abs(t_all[np.minimum(k, t_all.size - 1)] - ts) > 1e-6):
            raise ValueError(f"observation {spec.name}: sample times are not on the truth grid")
        z = np.empty((ts.size, len(d.components)))
        for p in np.unique(truth["phase_index"][k]):
            sel = truth["phase_index"][k] == p
            z[sel] = model.observe(truth["x"][k[sel]], spec.quantity, truth["phases"][p])
        if spec.quantity in ("acceleration_body", "acceleration_axial"):
            z = z + bias[: d.size]
        if spec.quantity == "altitude":
            z = z * scale
        noise = spec.noise if spec.noise is not None else spec.sigma
        if noise is None:
            raise ValueError(f"observation {spec.name}: give noise_sigma for a synthetic weights-file channel")
        if spec.quantity == "quaternion":  # a body-frame small-angle error of 1σ noise [rad] per axis
            z = quat_boxplus(z, rng.standard_normal((ts.size, 3)) * noise)
        else:
            z = z + rng.standard_normal(z.shape) * noise
        cols = {c: (z[:, i], d.file_unit or d.unit) for i, c in enumerate(d.components)}
        out[spec.name] = write_telemetry(
            out_dir / f"{spec.name}.csv", ts, cols, meta={"source": "synthetic post2 truth"}
        )
        if spec.weights is not None:
            w = {c: (np.full(ts.size, 1.0 / noise[i] ** 2), "1") for i, c in enumerate(d.residual_names)}
            out[spec.name + "_weights"] = write_telemetry(
                out_dir / f"{spec.name}_weights.csv", ts, w, meta={"weights": "W = 1/sigma^2 in 1/SI^2 (R = W^-1)"}
            )
    return out


def _sample_times(cfg: Post2Settings, spec) -> np.ndarray:
    if spec.rate_hz is None or not spec.rate_hz > 0:
        raise ValueError(f"observation {spec.name}: a synthetic scenario needs rate_hz > 0")
    t0 = spec.start if spec.start is not None else cfg.t_start
    t1 = spec.end if spec.end is not None else cfg.t_end
    dt = 1.0 / spec.rate_hz
    n = int(math.floor((t1 - t0) / dt + 1e-9))
    return np.round(t0 + dt * np.arange(n + 1), 9)


def sample_times(cfg: Post2Settings) -> np.ndarray:
    """All synthetic observation times of the scenario (s), to be on the truth grid."""
    return np.unique(np.concatenate([_sample_times(cfg, s) for s in cfg.observations]))
