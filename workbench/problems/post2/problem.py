"""The post2 problem (kind ``post2``): parameter and trajectory reconstruction declared in a problem
file, after the POST2 EKF reconstruction module (thesis [R3], Ch. 3).

Synthetic scenarios: the truth simulator (``truth.py``) writes one CSV per observation (and a
weights file where declared) exactly as a user supplies them, and ``truth.npz``; the
reconstruction (``pipeline.py``) reads only those files.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from workbench.core.bodies import G0
from workbench.estimation.health import health_markdown
from workbench.io.moments import KeyMoment, slug
from workbench.io.scenario import Scenario
from workbench.io.telemetry import atomic_write_npz
from workbench.problems.base import (
    SEED_ENTROPY,
    ExportTable,
    McOutcome,
    RunOptions,
    Synthesized,
    require_synthetic,
)
from workbench.problems.post2 import build, huygens, rocket_results
from workbench.problems.post2.config import SCHEMA, Post2Settings
from workbench.problems.post2.model import DESCENT_NOMINALS, OBSERVATIONS, STATES, aero_angles
from workbench.problems.post2.recording import COMPONENTS, open_post2_recording
from workbench.problems.post2.recording_mc import open_mc_recording, record_truth_mc
from workbench.problems.post2.scoring import score
from workbench.problems.post2.truth import sample_times, simulate_truth, write_observations
from workbench.problems.post2.truth_mc import member_settings, run_truth_monte_carlo

__all__ = ["Post2Problem", "key_moments"]

#: observation quantities that measure the sensed (non-gravitational) acceleration
_SENSED_ACCELERATION = ("acceleration_axial", "acceleration_magnitude", "acceleration_body")


def key_moments(result) -> list[KeyMoment]:
    """Key moments of a post2 reconstruction, times [s] on the ``time`` timeline: the start and end
    of the grid, every event that fired (``[events]`` of the problem file: parachutes, separations,
    phase changes), and the peak of the measured sensed acceleration (largest |z| over the
    observations of ``acceleration_axial``/``_magnitude``/``_body``, in g₀ = 9.80665 m/s²) when the
    problem file observes one; a rocket flight's ``burnout``, ``apogee`` and ``landing``
    (:func:`~workbench.problems.post2.rocket_results.moments`). Each has a window of ± 1 % of the
    grid's span, at least ± 15 s (or ± 5 % of a span shorter than 300 s), clipped to the grid."""
    t = np.asarray(result.t, dtype=float)
    t0, t1 = float(t[0]), float(t[-1])
    half = max(0.01 * (t1 - t0), min(0.05 * (t1 - t0), 15.0))  # an 8000 s descent: ± 80 s

    def moment(name: str, tk: float, text: str) -> KeyMoment:
        return KeyMoment(name, float(tk), text, (max(t0, tk - half), min(t1, tk + half)))

    out = [moment("start", t0, "start of the reconstruction (first grid time)")]
    for t_e, name in result.events:
        out.append(moment(slug(name), float(t_e), f"event {name!r} fires (problem file [events])"))
    peak = None
    for name, ch in result.channels.items():
        if ch.spec.quantity not in _SENSED_ACCELERATION or not len(ch.t):
            continue
        z = np.abs(np.asarray(ch.z, dtype=float).reshape(len(ch.t), -1))
        a = np.linalg.norm(np.nan_to_num(z), axis=1)
        k = int(np.argmax(a))
        if peak is None or a[k] > peak[0]:
            peak = (float(a[k]), float(ch.t[k]), name)
    if peak is not None:
        a, tk, name = peak
        out.append(
            moment("peak_acceleration", tk, f"peak sensed acceleration {a / G0:.2f} g₀ ({a:.1f} m/s², {name} measured)")
        )
    block = (getattr(result, "summary", None) or {}).get("rocket")
    if block is not None:  # a rocket flight ([launch]): burnout, apogee, landing
        out += [moment(n, tk, text) for n, tk, text in rocket_results.moments(block)]
    out.append(moment("end", t1, "end of the reconstruction (last grid time)"))
    names = [m.name for m in out]
    return [m for i, m in enumerate(out) if m.name not in names[:i]]  # an event fired twice: its first time


class Post2Problem:
    """Reconstruction from a POST2-style problem file (kind ``post2``)."""

    kind = "post2"
    title = "trajectory"
    schema = SCHEMA
    compiled_modules = ("workbench.problems.post2.kernels",)

    def settings(self, scenario: Scenario) -> Post2Settings:
        """The run's frozen :class:`~workbench.problems.post2.config.Post2Settings` (validated, files
        resolved, vehicle asset loaded), built once; every other method receives them."""
        return Post2Settings.from_scenario(scenario)

    def telemetry_files(self, settings: Post2Settings, folder: Path | None = None) -> dict[str, Path]:
        """{observation name: CSV, name + "_weights": CSV} from ``[observations.<name>] file/weights``
        (resolved by the settings; a missing one is a located error) or, with ``folder``,
        ``<name>.csv`` / ``<name>_weights.csv`` inside it."""
        return settings.telemetry_files(folder)

    def synthesize(self, settings: Post2Settings, out_dir: Path, seed: int) -> Synthesized:
        """Truth (DOP853, its own atmosphere and aero) -> observation CSVs (+ weights) and ``truth.npz``."""
        cfg = settings
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        tr = simulate_truth(cfg, sample_times(cfg))
        files = write_observations(cfg, tr, out, np.random.default_rng(seed))
        model = tr["model"]
        sm = model.smap
        arrays = {"t": tr["t"], "position": sm.raw(tr["x"], "position"), "velocity": sm.raw(tr["x"], "velocity")}
        if cfg.dof == 6:
            arrays["quaternion"] = sm.raw(tr["x"], "attitude")
            arrays["attitude"] = aero_angles(arrays["position"], model.v_rel(tr["x"]), arrays["quaternion"])
            arrays["body_rates"] = sm.raw(tr["x"], "body_rates")
        tf = cfg.truth
        defaults = {
            "j2": model.env.j2,
            "ca_multiplier": tf.ca_factor,
            "cn_multiplier": tf.cn_factor,
            "cm_multiplier": tf.cm_factor,
            "parachute_drag_multiplier": 1.0,
            "density_multiplier": 1.0,
            "accel_bias": np.zeros(3),
            "radar_scale_factor": 1.0,
            # rocket flights (case 5): no synthetic truth of their own yet
            "baro_bias": 0.0,
            "baro_scale": 1.0,
            "baro_q_coefficient": 0.0,
            "wind": np.zeros(2),
            "drogue_drag_area": 0.0,
            "main_drag_area": 0.0,
            **DESCENT_NOMINALS,  # Huygens-like descent parameters
        }
        for name, d in STATES.items():
            if d.dynamic or (name == "density_multiplier" and tf.density_wave_amplitude):
                continue  # a density wave has no single truth multiplier
            if name in ("log_pressure_offset", "temperature_offset"):
                continue  # the truth's own atmosphere minus the table varies with altitude: no single value
            v = tf.states.get(name, defaults[name])
            if name in ("ca_multiplier", "cn_multiplier", "cm_multiplier") and name in tf.states:
                v = np.asarray(v) * defaults[name]
            arrays[f"param_{name}"] = np.atleast_1d(np.asarray(v, dtype=float))
        arrays["event_times"] = np.array([t for t, _ in tr["events"]], dtype=float)
        for name, v in tf.tolerances.items():  # scorecard tolerances (SI)
            arrays[f"tol_{name}"] = v
        atomic_write_npz(out / "truth.npz", arrays, compress=False)
        return Synthesized(files, out / "truth.npz")

    def load_truth(self, path: Path) -> dict:
        """The arrays of ``truth.npz`` (t, position, velocity[, quaternion, attitude, body_rates], param_*)."""
        with np.load(path) as z:
            return {k: z[k] for k in z.files}

    def reconstruct(self, settings: Post2Settings, telemetry, options: RunOptions):
        """Observation files -> EKF forward pass -> RTS smoother (stages of :mod:`.pipeline`)."""
        yield from huygens.reconstruct(settings, telemetry, options)  # [monte_carlo] stage first, if any

    def summary(self, result) -> dict:
        """A copy of the result's summary."""
        return dict(result.summary)

    def key_moments(self, result) -> list[KeyMoment]:
        """Start, events fired, peak sensed acceleration, end (:func:`key_moments`)."""
        return key_moments(result)

    def score(self, result, truth: dict) -> dict:
        """Errors against the truth (:func:`workbench.problems.post2.scoring.score`)."""
        out = score(result, truth)
        if any(k.startswith("tol_") for k in truth):  # Huygens-like: the planted-vs-recovered scorecard
            out["planted_vs_recovered"] = huygens.planted_table(result, truth)
        return out

    def scorecard(self, summary: dict) -> str:
        """Markdown: a rocket flight's results (:func:`~.rocket_results.markdown`), final states ± 1σ,
        observation statistics and, when scored, the errors."""
        md = f"# {summary['scenario']} scorecard (post2, {summary['dof']}-DOF)\n\n"
        if "rocket" in summary:  # a rocket flight: its results first
            md += rocket_results.markdown(summary["rocket"])
        md += "| state | final | 1σ | unit |\n|---|---|---|---|\n"
        for name, s in summary["states"].items():
            # fixed point, to the σ's second significant figure (one format per row: "-2.46e+06,
            # 647735" mixed notations)
            sig = [float(v) for v in s["final_sigma"] if v is not None and float(v) > 0]
            dec = int(min(9, max(0, 1 - np.floor(np.log10(min(sig)))))) if sig else 6
            fin = ", ".join(f"{v:.{dec}f}" for v in s["final"])
            sd = ", ".join(f"{v:.{dec}f}" if float(v) >= 10.0**-dec else f"{v:.2g}" for v in s["final_sigma"])
            md += f"| {name} | {fin} | {sd} | {s['unit']} |\n"
        md += (
            "\n| observation | samples | accepted | mean NIS (dim) | 99 % band | verdict | normalized residual RMS |\n"
        )
        md += "|---|---|---|---|---|---|---|\n"
        for name, o in summary["observations"].items():
            nis = f"{o['mean_nis']:.2f} ({o['dimension']})"
            band = "{:.2f} .. {:.2f}".format(*o["mean_nis_band_99"])
            md += f"| {name} | {o['samples']} | {o['accepted']} | {nis} | {band} | {o['nis_verdict']} |"
            md += f" {o['normalized_residual_rms']:.2f} |\n"
        tr = summary.get("truth")
        if tr and "planted_vs_recovered" in tr:
            md += huygens.planted_markdown(tr["planted_vs_recovered"])
        if "mc_initial_state" in summary:
            m = summary["mc_initial_state"]
            md += (
                f"\n## Monte Carlo initial state\n\n{m['members']} members ({m['scheduler']}, {m['wall_s']:.1f} s): "
                f"best member {m['best_member']} metric {m['best_metric']:.4g} "
                f"(delivered state {m['nominal_metric']:.4g}), "
                f"time shift {m['best_shift_s']:+.2f} s; {m['kept']} kept\n"
            )
        if tr:
            md += "\n## Against the truth\n\n"
            if "position_error_m" in tr:
                e = tr["position_error_m"]
                md += "| position error | m |\n|---|---|\n"
                for k in ("start", "after_15s_forward", "end_forward", "end_smoothed", "max_smoothed"):
                    md += f"| {k} | {e[k]:.1f} |\n"
                md += (
                    f"\nposition components inside 3σ (smoothed): {100 * tr['position_inside_3sigma_fraction']:.1f} %\n"
                )
            md += _planted_table(summary)
            fvp = tr.get("filtered_vs_propagation")
            if fvp:
                md += "\n| error at the end (norm) | propagation only | filtered (forward) | smoothed | unit |\n"
                md += "|---|---|---|---|---|\n"
                for name, c in fvp.items():
                    e = c["end_error_norm"]
                    shown = "attitude [α, β, bank]" if name == "attitude" else name
                    md += f"| {shown} | {e['propagation_only']:.4g} | {e['forward']:.4g} | {e['smoothed']:.4g}"
                    md += f" | {c['unit']} |\n"
            for name, p in tr.get("parameters", {}).items():
                unit = summary["states"].get(name, {}).get("unit", "")
                k = _display_factor(unit)
                md += (
                    f"\n**{name}** (truth {_numbers(p['truth'], k)}{'' if unit in ('', '1', '-') else ' ' + unit}):\n\n"
                    f"| after | error [{unit or '-'}] |\n|---|---|\n"
                )
                for n in (1, 4, 10):
                    if f"error_after_{n}_obs" in p:
                        md += f"| {n} observation(s) | {_numbers(p[f'error_after_{n}_obs'], k, signed=True)} |\n"
                md += (
                    f"| end (forward) | {_numbers(p['final_error_forward'], k, signed=True)}"
                    f" (3σ {_numbers(p['final_3sigma_forward'], k)}) |\n"
                )
                flag = "inside" if p["inside_3sigma_at_end"] else "**OUTSIDE**"
                md += f"\nfinal error {flag} its 3σ.\n"
        if "health" in summary:
            md += "\n" + health_markdown(summary["health"])
        return md

    def headline(self, summary: dict) -> str:
        """The main number: a rocket flight's apogee, max speed and landing point
        (:func:`~.rocket_results.headline`); else the position error at the end, or the first
        parameter's final error."""
        tr = summary.get("truth") or {}
        zs = [(float(np.max(np.abs(np.divide(h["error"], h["sigma"])))), h["name"]) for h in tr.get("headline", [])]
        worst = f"; truth headline max |z| {max(zs)[0]:.2f} ({max(zs)[1]})" if zs else ""
        if "rocket" in summary:
            return rocket_results.headline(summary["rocket"]) + worst
        if "position_error_m" in tr and "attitude" in summary["states"]:
            e = tr["position_error_m"]
            return (
                f"position error {e['start']:.0f} m -> {e['after_15s_forward']:.0f} m after 15 s"
                f" -> {e['end_forward']:.1f} m at the end{worst}"
            )
        if "planted_vs_recovered" in tr and "position_error_m" in tr:
            rows = tr["planted_vs_recovered"]
            n_pass = sum(r["pass"] for r in rows)
            n_un = sum(not r["informed"] for r in rows)
            return (
                f"end position error {tr['position_error_m']['end_smoothed'] / 1e3:.2f} km; planted parameters "
                f"{n_pass}/{len(rows)} PASS, {n_un} not informed by the data{worst}"
            )
        for name, p in tr.get("parameters", {}).items():
            k = 180.0 / np.pi if STATES[name].unit in ("deg", "deg/s") else 1.0
            unit = STATES[name].unit if STATES[name].unit != "1" else ""
            err, sig = _numbers(p["final_error_forward"], k, signed=True), _numbers(p["final_3sigma_forward"], k)
            return f"{name} error {err} (3σ {sig}) {unit}".rstrip() + worst
        s = next(iter(summary["states"].items()))
        return f"{s[0]} final {_numbers(s[1]['final'])} {s[1].get('unit', '')}".rstrip()

    def open_recording(self, path: Path, settings: Post2Settings, truth, properties: dict):
        """The post2 recording (:mod:`.recording`)."""
        cfg = settings
        geometry = None
        veh = build.vehicle(cfg)
        if veh.area > 0:  # display geometry: capsule from the reference area, canopy from the parachute's
            d_chute = float(np.sqrt(4.0 * veh.parachute.ref_area / np.pi)) if veh.parachute is not None else None
            geometry = {
                "diameter_m": float(np.sqrt(4.0 * veh.area / np.pi)),
                "parachute_diameter_m": d_chute,
                "riser_m": 2.0 * d_chute if d_chute else 0.0,
                "planet_rate_rad_s": float(build.environment(cfg).omega),
            }
        return open_mc_recording(
            open_post2_recording(
                path,
                cfg.run.name,
                truth,
                properties,
                self.scorecard,
                states=[st.name for st in cfg.states],
                observations=[ob.name for ob in cfg.observations],
                sizes={st.name: STATES[st.name].size for st in cfg.states},
                residual_components={ob.name: OBSERVATIONS[ob.quantity].residual_names for ob in cfg.observations},
                observation_units={ob.name: OBSERVATIONS[ob.quantity].unit for ob in cfg.observations},
                schedules=sorted({s.target_name for s in cfg.schedules if s.target == "observation"}),
                geometry=geometry,
                parachute_events={e.name: e.parachute for e in cfg.events if e.parachute is not None},
                has_events=bool(cfg.events),
                rocket_span=None if cfg.launch is None else (cfg.t_start, cfg.t_end),
            )
        )

    def export_columns(self, result) -> ExportTable:
        """Every state block (smoothed, physical) and its 1σ, SI (angles in rad); a rocket flight adds
        its track in the pad's frame (:class:`~.rocket_results.LocalTrack`: altitude above the pad,
        east, north, up, downrange [m], vertical speed, speed [m/s], lat, lon [written in deg]) with
        their 1σ."""
        cols = {}
        for name, h in result.history["smoothed"].items():
            unit = STATES[name].unit
            comps = COMPONENTS.get(name, ("value",))
            for i, c in enumerate(comps):
                cols[f"{name}.{c}"] = (h["value"][:, i], _si_unit(unit))
                cols[f"sigma_{name}.{c}"] = (h["sigma"][:, i], _si_unit(unit))
        frame = "planet-centred inertial (+Z pole); attitude as α, β, bank"
        tr = result.rocket
        if tr is not None:  # a rocket flight: the pad's local frame too (lat/lon written in deg)
            local = {
                "altitude_above_pad": (tr.altitude, tr.sigma_altitude, "m"),
                "east": (tr.enu[:, 0], tr.sigma_enu[:, 0], "m"),
                "north": (tr.enu[:, 1], tr.sigma_enu[:, 1], "m"),
                "up": (tr.enu[:, 2], tr.sigma_enu[:, 2], "m"),
                "downrange": (tr.downrange, tr.sigma_downrange, "m"),
                "vertical_speed": (tr.vertical_speed, tr.sigma_vertical_speed, "m/s"),
                "speed": (tr.speed, tr.sigma_speed, "m/s"),
                "lat": (tr.lat, tr.sigma_lat, "deg"),
                "lon": (tr.lon, tr.sigma_lon, "deg"),
            }
            for name, (v, sd, unit) in local.items():
                cols[name] = (v, unit)
                cols[f"sigma_{name}"] = (sd, unit)
            frame += "; rocket: the pad's east/north/up (m), altitude above the pad, planet-relative velocity"
        return ExportTable(result.t, cols, frame)

    def calibration_settings(self, settings: Post2Settings, seed: int) -> Post2Settings:
        """A health-calibration member's settings (:func:`workbench.problems.runner.evaluate`): with a
        delivered ``[monte_carlo] covariance`` (the scenario's truth is one draw from it), the truth
        dispersed as :mod:`.truth_mc` disperses it (initial state, the parameters of
        ``[truth] monte_carlo_draw_from_prior``), seeded from ``seed``; otherwise unchanged."""
        if settings.monte_carlo.covariance is None:
            return settings
        state, params = (int(v) for v in np.random.SeedSequence(int(seed), spawn_key=(1,)).generate_state(2))
        return member_settings(
            settings, {"state": state, "params": params}, settings.truth.monte_carlo_draw_from_prior
        )  # fmt: skip

    def monte_carlo(self, settings: Post2Settings, out_dir, options, progress) -> McOutcome:
        """The Monte Carlo against the truth simulator (:mod:`.truth_mc`; the only post2 study, with or
        without ``options.truth_sim``): ``options.n_runs`` members of the seed stream ``options.stream``
        (entropy :data:`~workbench.problems.base.SEED_ENTROPY`), or of the validation stream with entropy
        ``options.first_seed`` when no stream is named, on ``options.workers`` processes or ``options.scheduler``;
        ``options.members`` the initial-state selection's members; writes ``<out>/<name>_truth_mc.rrd``
        (:func:`.recording_mc.record_truth_mc`).  A scenario without ``[synthetic]`` is a ScenarioError."""
        require_synthetic(settings.run)
        t0 = time.perf_counter()
        n = int(options.n_runs)
        where = options.scheduler or f"{options.workers} local worker(s)"
        stream = options.stream or "validation"
        progress(f"Monte Carlo against the truth simulator: {n} members of the {stream} stream ({where}) ...")
        res = run_truth_monte_carlo(
            self, settings, n_runs=n, workers=options.workers, stream=stream,
            entropy=SEED_ENTROPY if options.stream else options.first_seed,
            scheduler=options.scheduler, members=options.members,
        )  # fmt: skip
        summary = {**res.summary, "wall_time_s": time.perf_counter() - t0}
        name = settings.run.name
        rrd = record_truth_mc(Path(out_dir) / f"{name}_truth_mc.rrd", f"{name} Monte Carlo vs truth", res, summary)
        tp = summary["trajectory"]["position"]
        headline = (
            f"truth Monte Carlo, {summary['runs_completed']} members: parameter NEES {summary['mean_nees']:.2f} "
            f"({summary['verdict']}, band {summary['band_95'][0]:.2f}-{summary['band_95'][1]:.2f}); end position "
            f"NEES {tp['end_mean_nees']:.2f} ({tp['end_verdict']}); wrote {rrd}"
        )
        return McOutcome(summary, Path(rrd), headline, res)


def _planted_table(summary: dict) -> str:
    """Markdown table of the planted (truth) vs recovered (final, smoothed) value of every estimated
    parameter with a known truth, with its 3σ and the error in units of 3σ."""
    params = (summary.get("truth") or {}).get("parameters", {})
    if not params:
        return ""
    md = "\n| parameter | planted | recovered | ±3σ | error / 3σ | inside 3σ | posterior/prior σ |\n"
    md += "|---|---|---|---|---|---|---|\n"
    for name, p in params.items():
        st = summary["states"][name]
        for i, tv in enumerate(p["truth"]):
            z = p["final_error_over_3sigma_smoothed"][i]
            inside = "yes" if abs(z) <= 1.0 else "**no**"
            ratio = "—"
            if "informed_by_data" in p:
                ratio = f"{p['posterior_over_prior_sigma'][i]:.2f}"
                if not p["informed_by_data"][i]:
                    ratio += " (not informed by the data)"
            tv = tv * _display_factor(st["unit"])  # the truth is SI, the states' final values display units
            md += f"| {name}{'' if len(p['truth']) == 1 else f'[{i}]'} | {tv:.6g} | {st['final'][i]:.6g} |"
            md += f" {3.0 * st['final_sigma'][i]:.3g} | {z:+.2f} | {inside} | {ratio} |\n"
    return md


def _display_factor(unit: str) -> float:
    """SI -> the display ``unit`` of a state in the summary (deg and deg/s are shown, rad stored)."""
    return 180.0 / np.pi if unit in ("deg", "deg/s") else 1.0


def _numbers(values, factor: float = 1.0, *, signed: bool = False) -> str:
    """A scalar or vector (SI) as comma-separated numbers in the display unit (× ``factor``), four
    significant figures, ``+`` on positives when ``signed`` (errors), instead of a raw list."""
    fmt = "{:+.4g}" if signed else "{:.4g}"
    return ", ".join(fmt.format(float(v) * factor) for v in np.atleast_1d(np.asarray(values, dtype=float)))


def _si_unit(unit: str) -> str:
    return {"deg": "rad", "deg/s": "rad/s"}.get(unit, unit)
