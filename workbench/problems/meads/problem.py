"""Flush air data (MEADS, MSL) as a :class:`~workbench.problems.base.Problem`.

Composes :mod:`.pipeline` (reduction, scoring, scorecard), :mod:`.synthetic` (truth and
telemetry), :mod:`.recording` and :mod:`.montecarlo` (the paper's trade study, ``workbench mc``).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.io import progress as prog
from workbench.io.moments import KeyMoment
from workbench.io.scenario import Scenario
from workbench.models.flush_airdata import FADS_PORT_SCHEMA, FADS_VEHICLE_SCHEMA
from workbench.problems.base import (
    ExportTable,
    McOptions,
    McOutcome,
    Progress,
    RunOptions,
    Synthesized,
    require_synthetic,
)
from workbench.problems.drawer import RunDrawer
from workbench.problems.meads import pipeline as md
from workbench.problems.meads.config import SCHEMA, MeadsSettings
from workbench.problems.meads.telemetry import INITIAL_STATE_SCHEMA, STREAMS, telemetry_paths
from workbench.problems.pipeline_problem import PipelineProblem, folder_telemetry, synthesized

__all__ = ["MeadsProblem", "key_moments"]


def key_moments(result: md.MeadsResult) -> list[KeyMoment]:
    """Key moments of a flush-air-data reduction, times [s] on the ``time`` timeline: the peak
    dynamic pressure, the largest |α| and |β| while q∞ is at least 10 % of its peak (below it the
    angles are poorly observed), the first port failure, if any, and the transonic crossing (the
    estimated Mach number first below 1, where it is estimated)."""
    fit, t = result.air.fit, np.asarray(result.air.t, dtype=float)
    q = np.nan_to_num(np.asarray(fit.qbar, dtype=float), nan=-np.inf)
    out = []
    if np.isfinite(q).any():
        k = int(np.argmax(q))
        out.append(KeyMoment("peak_qbar", float(t[k]), f"peak dynamic pressure q∞ {q[k] / 1e3:.2f} kPa"))
        strong = q >= 0.1 * q[k]
        for name, ang, sig in (("max_alpha", fit.alpha, fit.sigma_alpha), ("max_beta", fit.beta, fit.sigma_beta)):
            a = np.where(strong, np.abs(np.nan_to_num(np.asarray(ang, dtype=float))), -1.0)
            j = int(np.argmax(a))
            if a[j] >= 0:
                sym = "α" if name == "max_alpha" else "β"
                out.append(
                    KeyMoment(
                        name,
                        float(t[j]),
                        f"largest |{sym}| {np.degrees(ang[j]):+.2f} ± {np.degrees(sig[j]):.2f} deg (1σ) "
                        "with q∞ ≥ 10 % of its peak",
                    )
                )
    for f in sorted(result.air.failures, key=lambda f: f.t)[:1]:
        out.append(KeyMoment("port_failure", float(f.t), f"port {f.port} failed ({f.how})"))
    mach = np.asarray(result.wind.mach, dtype=float)
    sub = np.flatnonzero(np.isfinite(mach) & (mach < 1.0))
    if sub.size and np.any(np.isfinite(mach[: sub[0]]) & (mach[: sub[0]] >= 1.0)):
        out.append(KeyMoment("subsonic", float(t[sub[0]]), "transonic crossing: estimated Mach first below 1"))
    return out


class MeadsProblem(PipelineProblem):
    """Seven flush pressure ports + IMU -> q∞, Mach, α, β, p∞, density, winds (least squares).

    Scored (``pipeline.score``) on the errors above 850 Pa against the truth, each vs its reported 3σ."""

    kind = "meads"
    pipeline = md
    title = "entry"
    schema = SCHEMA
    file_schemas = (FADS_VEHICLE_SCHEMA, FADS_PORT_SCHEMA, INITIAL_STATE_SCHEMA)
    #: the module of the cached numba kernels (the EKF's forward pass, smoother, measurement and
    #: transition): compiled in a child process on a checkout's first run (:mod:`workbench.problems.precompile`)
    compiled_modules = (
        "workbench.problems.meads.kernel",
        "workbench.problems.meads.truth_fast",
        "workbench.models.flush_airdata_kernel",
        "workbench.estimation.strapdown_kernel",
        "workbench.estimation.propagation_kernel",
    )

    def settings(self, scenario: Scenario) -> MeadsSettings:
        """The run's frozen settings (:meth:`MeadsSettings.from_scenario`: validated, the vehicle
        file read once); every other method receives them, never the scenario."""
        return MeadsSettings.from_scenario(scenario)

    def telemetry_files(self, settings: MeadsSettings, folder: Path | None = None) -> dict[str, Path]:
        """``[telemetry]`` files (absolute), or the standard names in ``folder``."""
        if folder is None:
            return telemetry_paths(settings.telemetry, settings.run.path)
        return folder_telemetry(folder, STREAMS)

    def synthesize(self, settings: MeadsSettings, out_dir: Path, seed: int) -> Synthesized:
        """Simulate the entry (truth) and write the telemetry + ``truth.npz`` into ``out_dir``."""
        from workbench.problems.meads.synthetic import synthesize_meads

        paths = synthesize_meads(settings, out_dir, seed)
        return synthesized(paths)

    def load_truth(self, path: Path) -> dict:
        """The arrays of ``truth.npz``."""
        from workbench.problems.meads.synthetic import load_truth

        return load_truth(path)

    def reconstruct(
        self, settings: MeadsSettings, telemetry: Mapping[str, Path], options: RunOptions
    ) -> Iterator[object]:
        """``pipeline.reconstruct``."""
        return md.reconstruct(settings, dict(telemetry))

    def key_moments(self, result: md.MeadsResult) -> list[KeyMoment]:
        """Peak q∞, largest |α| and |β|, first port failure, transonic crossing (:func:`key_moments`)."""
        return key_moments(result)

    def headline(self, summary: dict) -> str:
        """Failed ports and, with a truth, the max α/β/q∞ errors above 850 Pa and the headline's
        α/β/q∞ errors at peak q∞ over their 1σ (``summary["truth"]["headline"]``)."""
        fails = ", ".join(f"{f['port']} at {f['t_s']:.1f} s ({f['how']})" for f in summary["failed_ports"]) or "none"
        line = f"{summary['model']} model; failed ports: {fails}"
        tr = summary.get("truth", {}).get("final")
        if tr:
            line += (
                f"; above 850 Pa max |error| α {tr['alpha_deg']['max_abs']:.2f}° β {tr['beta_deg']['max_abs']:.2f}° "
                f"q∞ {tr['qbar_pct']['max_abs']:.2f} %"
            )
        hl = summary.get("truth", {}).get("headline") or []
        if hl:
            z = ", ".join(f"{h['name'].split('_')[0]} {h['error'] / h['sigma']:+.2f}σ" for h in hl if h["sigma"] > 0)
            line += f"; at peak q∞ error/1σ {z}"
        return line

    @contextlib.contextmanager
    def open_recording(self, path: Path, settings: MeadsSettings, truth: Any, properties: dict) -> Iterator[RunDrawer]:
        """The MEADS recording; its one layout (``recording.meads_blueprint``), sent when the run
        is done, opens the port views on the pressure samples' span and the air-data views on the
        span above the objectives' q∞ threshold (known only then), their y axes fixed where the
        viewer's own fit would label fewer than three ticks (``recording.view_y_ranges``)."""
        from workbench.problems.meads.recording import MeadsRecorder, meads_blueprint, view_y_ranges
        from workbench.recording.writer import open_recording

        ekf = settings.ekf
        ports, passes = settings.vehicle.port_names, ekf.passes if ekf.enabled else 0
        with open_recording(path, settings.run.name, properties=properties) as rec:

            def layout(result: md.MeadsResult, summary: dict):
                t = np.asarray(result.air.t, dtype=float)
                above = t[np.nan_to_num(result.air.fit.qbar) >= settings.estimator.min_qbar_pa]

                def span(x):
                    return (float(x[0]), float(x[-1])) if x.size > 1 and x[-1] > x[0] else None

                air = span(above)
                return meads_blueprint(
                    ports,
                    passes,
                    truth is not None,
                    span=span(t),
                    air_span=air,
                    y_ranges=view_y_ranges(rec, ports, passes, air),
                )

            yield RunDrawer(
                rec,
                MeadsRecorder(rec, truth),
                md.scorecard_markdown,
                layout=layout,
                blueprint=meads_blueprint(ports, passes, truth is not None),
            )

    def export_columns(self, result: md.MeadsResult) -> ExportTable:
        """Air data, density and winds with their 1σ at the pressure times (least squares, and the
        last EKF pass as ``ekf_*`` / ``sigma_ekf_*`` when it ran)."""
        f, w = result.air.fit, result.wind
        cols: dict[str, tuple[np.ndarray, str]] = {
            "qbar": (f.qbar, "Pa"),
            "sigma_qbar": (f.sigma_qbar, "Pa"),
            "alpha": (f.alpha, "rad"),
            "sigma_alpha": (f.sigma_alpha, "rad"),
            "beta": (f.beta, "rad"),
            "sigma_beta": (f.sigma_beta, "rad"),
            "mach": (w.mach, "1"),
            "sigma_mach": (w.sigma_mach, "1"),
            "p_inf": (w.p_inf, "Pa"),
            "density": (w.density, "kg/m^3"),
            "sigma_density": (w.sigma_density, "kg/m^3"),
            "wind_north": (w.winds.wind_NE[:, 0], "m/s"),
            "wind_east": (w.winds.wind_NE[:, 1], "m/s"),
        }
        for name in ("qbar", "alpha", "beta", "mach", "density"):  # no 1σ: the fit did not solve there
            (v, unit), (sd, _) = cols[name], cols[f"sigma_{name}"]
            cols[name] = (np.where(np.isfinite(sd), v, np.nan), unit)
        if result.ekf:  # the last EKF pass (smoothed), with its 1σ
            last = result.ekf[-1]
            units = {"alpha": "rad", "beta": "rad", "qbar": "Pa", "mach": "1", "p_inf": "Pa", "rho": "kg/m^3"}
            units |= {"wind_north": "m/s", "wind_east": "m/s", "wind_down": "m/s"}
            for name, unit in units.items():
                v, sd = last.output(name)
                cols[f"ekf_{name}"] = (v, unit)
                cols[f"sigma_ekf_{name}"] = (sd, unit)
        # the least squares has no solution where too few ports are usable or q∞ is too low: those
        # columns are sparse (empty cells there), not a dropout of the file
        sparse = tuple(k for k, (v, _) in cols.items() if not np.all(np.isfinite(v)))
        frame = "air data: body axes B; winds: local north/east (EKF: north/east/down)"
        return ExportTable(result.air.t, cols, frame, sparse=sparse)

    def calibration_settings(self, settings: MeadsSettings, seed: int) -> MeadsSettings:
        """A health-calibration member's settings (:func:`workbench.problems.runner.evaluate`): its
        truth dispersed as the truth Monte Carlo disperses it (entry state, trim α, atmosphere,
        winds, pressure model: :func:`~.truth.disperse_truth_spec`, generator
        ``SeedSequence(seed, spawn_key=(1,))``); the scenario's sensors and injected failure kept."""
        from workbench.problems.meads.truth import MeadsDispersionSigmas, disperse_truth_spec

        rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(1,)))
        return replace(settings, truth=disperse_truth_spec(settings.truth, rng, MeadsDispersionSigmas()))

    def monte_carlo(self, settings: MeadsSettings, out_dir: Path, options: McOptions, progress: Progress) -> McOutcome:
        """The paper's trade study (:mod:`.montecarlo`) with ``options.n_runs`` runs per error level
        (``workbench mc msl_meads --seeds 3000``), seed ``first_seed``, on ``options.workers``
        processes or ``options.scheduler``; writes ``<out>/<name>_mc.rrd`` (:mod:`.recording_mc`).
        With ``options.truth_sim`` the full-error-model Monte Carlo against the truth simulator
        instead (:mod:`.truth_mc`, ``workbench mc msl_meads --truth-sim --seeds 50``; the runner
        writes ``<name>_truth.mc.json``), recorded in ``<out>/<name>_truth_mc.rrd``."""
        if options.truth_sim:
            return self._truth_monte_carlo(settings, Path(out_dir), options, progress)
        from workbench.problems.meads.montecarlo import CHUNK, QUANTITIES, prepare_trade_study, run_trade_study
        from workbench.problems.meads.recording_mc import record_trade_study

        t0 = time.perf_counter()
        cfg, name = settings, settings.run.name
        runs = int(options.n_runs) if options.n_runs else cfg.mc.runs
        where = options.scheduler or f"{options.workers} local worker(s)"
        progress(f"trade study: {runs} runs x {len(cfg.mc.levels)} levels ({where}) ...")
        rep = prog.current()
        with rep.stage("truth simulation + nominal air-data fit"):
            sh = prepare_trade_study(settings)
        with rep.counter("trade study runs", total=runs, unit="runs") as bar:  # counted in tasks of CHUNK runs
            ts = run_trade_study(
                sh,
                runs,
                options.entropy,
                workers=options.workers,
                scheduler=options.scheduler,
                progress=lambda done, _tasks: bar.set(min(done * CHUNK, runs)),
            )
        summary = {"scenario": name, "kind": "meads_trade_study", **ts.summary}
        summary["wall_time_s"] = time.perf_counter() - t0
        rrd = record_trade_study(Path(out_dir) / f"{name}_mc.rrd", f"{name} trade study", ts, summary)
        parts = []
        for lv, row in summary["table"].items():
            met = [q for q in QUANTITIES if row[q]["met"]]
            parts.append(f"{lv}: meets {'/'.join(met) or 'none'}")
        headline = f"trade study ({runs} runs/level, R = {sh.fixed_r:g}): " + "; ".join(parts) + f"; wrote {rrd}"
        return McOutcome(summary, Path(rrd), headline, ts)

    def _truth_monte_carlo(
        self, settings: MeadsSettings, out_dir: Path, options: McOptions, progress: Progress
    ) -> McOutcome:
        """``monte_carlo`` with ``truth_sim``: :func:`.truth_mc.run_full_monte_carlo` with
        ``options.n_runs`` members seeded from ``options.entropy`` (``first_seed`` or the named stream's)."""
        from workbench.problems.meads.recording_mc import record_truth_mc
        from workbench.problems.meads.truth_mc import run_full_monte_carlo

        name = settings.run.name
        require_synthetic(settings.run)
        t0 = time.perf_counter()
        n = int(options.n_runs)
        where = options.scheduler or f"{options.workers} local worker(s)"
        progress(f"Monte Carlo against the truth simulator, full error model: {n} members ({where}) ...")
        res = run_full_monte_carlo(
            settings, n_runs=n, seed=options.entropy, workers=options.workers, scheduler=options.scheduler
        )
        summary = {**res.summary, "wall_time_s": time.perf_counter() - t0}
        rrd = record_truth_mc(Path(out_dir) / f"{name}_truth_mc.rrd", f"{name} Monte Carlo vs truth", res, summary)
        last = summary["table"].get("ekf_pass2") or summary["table"].get("least_squares") or {}
        met = [q for q, row in last.items() if row.get("3rms_meets_objective")]
        verdict = (
            f"final estimator's 3 RMS meets {'/'.join(met) or 'no objective'}; "
            f"{len(summary['disagreements'])} reported-vs-Monte-Carlo 3σ disagreement(s)"
            if last
            else f"NO STATISTICS: no Mach bin was reached by {summary.get('min_bin_members', 2)} or more members "
            "(run more members)"
        )
        headline = (
            f"Monte Carlo vs truth ({summary['n_ok']}/{n} members, median {summary['member_wall_s']['median']:.1f} "
            f"s each): {verdict}; wrote {rrd}"
        )
        return McOutcome(summary, Path(rrd), headline, res)
