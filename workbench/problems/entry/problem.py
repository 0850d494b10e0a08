"""Entry and descent (AMELIA, Schiaparelli-like) as a :class:`~workbench.problems.base.Problem`.

Composes :mod:`.pipeline` (reconstruction, scoring, scorecard), :mod:`.synthetic` (truth and
telemetry), :mod:`.recording` (layout and drawer) and :mod:`.montecarlo` / :mod:`.recording_mc`
(the smoother validation of AMELIA Sect. 8, a self-consistency check) and :mod:`.truth_mc` (the
Monte Carlo against the truth simulator through the full pipeline, ``mc --truth-sim``).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.bodies import G0
from workbench.io import progress as prog
from workbench.io.moments import KeyMoment, slug
from workbench.io.scenario import Scenario, ScenarioError
from workbench.models.aerodynamics import VEHICLE_SCHEMA
from workbench.problems.base import ExportTable, McOptions, McOutcome, Progress, RunOptions, Synthesized
from workbench.problems.drawer import RunDrawer
from workbench.problems.entry import pipeline as en
from workbench.problems.entry.config import SCHEMA, EntrySettings
from workbench.problems.entry.state import DP, DTH, DV
from workbench.problems.entry.telemetry import INITIAL_STATE_SCHEMA, STREAMS, telemetry_paths
from workbench.problems.pipeline_problem import PipelineProblem, folder_telemetry, synthesized

__all__ = ["EntryProblem", "key_moments"]

#: what the telemetry events of an entry mean (other names are listed as they are)
_EVENT_TEXT = {
    "EIP": "entry interface point",
    "PDD": "parachute deployment (PDD)",
    "FSR": "front-shield release (FSR)",
    "BSR": "back-shell release (BSR)",
    "RDA_ON": "radar (RDA) switched on",
}

#: the radar channels of the smoother (``filter.innovations``)
_RADAR_CHANNELS = ("slant_range", "slant_out", "velocity_out")


def key_moments(result: en.EntryResult) -> list[KeyMoment]:
    """Key moments of an entry from its reconstruction, times [s] from EIP on the ``time`` timeline:
    every telemetry event (EIP, PDD, FSR, RDA_ON, BSR ...), the peak deceleration (largest
    |specific force| of the preprocessed IMU before PDD, in g₀ = 9.80665 m/s²) and the parachute
    opening load (the largest in the 10 s after PDD), the gyro saturation (first to
    last saturated sample, if any), the first radar measurement the smoother accepted, and the end
    of the data; each with the smoothed altitude above ground where the smoother covers it."""
    sm = result.filter.smoothed
    r_ground = float(result.summary["r_ground_m"])
    radius = np.linalg.norm(sm.p_M, axis=1)

    def agl(t: float) -> str:
        if not sm.t[0] <= t <= sm.t[-1]:
            return ""
        return f", h AGL {(np.interp(t, sm.t, radius) - r_ground) / 1e3:.2f} km"

    out = []
    for name, t_e in sorted(result.events.items(), key=lambda kv: kv[1]):
        t_e = float(t_e)
        out.append(
            KeyMoment(slug(name), t_e, _EVENT_TEXT.get(name, f"{name} (events file)") + agl(t_e), (t_e - 10, t_e + 20))
        )
    imu = result.imu
    f = np.linalg.norm(np.nan_to_num(np.asarray(imu.f_G, dtype=float)), axis=1)
    t_imu = np.asarray(imu.t, dtype=float)
    t_pdd = float(result.events.get("PDD", np.inf))
    for name, what, sel, half in (
        ("peak_deceleration", "peak deceleration", t_imu < t_pdd, 20.0),
        ("opening_load", "parachute opening load", (t_imu >= t_pdd) & (t_imu <= t_pdd + 10.0), 5.0),
    ):
        if not sel.any():
            continue
        k = int(np.flatnonzero(sel)[np.argmax(f[sel])])
        tk = float(t_imu[k])
        text = f"{what} {f[k] / G0:.2f} g₀ ({f[k]:.1f} m/s², measured specific force){agl(tk)}"
        edge = [g for g in imu.gaps if np.isclose(g.t_a, tk) or np.isclose(g.t_b, tk)]
        if edge:  # the largest sample borders a data gap: the peak may lie inside it, undefined
            g = edge[0]
            text = (
                f"{what} undefined: the largest measured specific force ({f[k]:.1f} m/s² at {tk:.2f} s) borders the "
                f"{g.t_a:.2f}–{g.t_b:.2f} s data gap, the peak may lie inside it{agl(tk)}"
            )
        out.append(KeyMoment(name, tk, text, (tk - half, tk + half)))
    sat = np.flatnonzero(np.asarray(imu.saturated, bool))
    if sat.size:
        a, b = float(imu.t[sat[0]]), float(imu.t[sat[-1]])
        out.append(
            KeyMoment(
                "saturation",
                a,
                f"gyro saturation: {sat.size} samples from {a:.2f} to {b:.2f} s (rate rebuilt){agl(a)}",
                (a - 2, b + 2),
            )
        )
    first = [
        (float(ih.t[np.asarray(ih.accepted, bool)][0]), ch)
        for ch, ih in result.filter.innovations.items()
        if ch in _RADAR_CHANNELS and np.any(np.asarray(ih.accepted, bool))
    ]
    if first:
        t_r, ch = min(first)
        out.append(
            KeyMoment(
                "first_radar_fix", t_r, f"first radar fix: {ch} accepted by the smoother{agl(t_r)}", (t_r - 5, t_r + 15)
            )
        )
    e = result.summary["end"]
    t_end = float(e["t_s"])
    out.append(
        KeyMoment(
            "end",
            t_end,
            f"end of the data: h AGL {e['h_agl_m'] / 1e3:.2f} km ± {e['sigma_h_m']:.0f} m (1σ)",
            (t_end - 20, t_end),
        )
    )
    names = [m.name for m in out]
    return [m for i, m in enumerate(out) if m.name not in names[:i]]  # an event named like a derived moment wins


class EntryProblem(PipelineProblem):
    """Entry, descent and landing from IMU + radar telemetry: strapdown, dispersion analysis,
    radar-aided smoother, atmosphere and winds.

    Scored (``pipeline.score``) on the trajectory, atmosphere and wind errors against the truth."""

    kind = "entry"
    pipeline = en
    title = "entry"
    schema = SCHEMA
    file_schemas = (VEHICLE_SCHEMA, INITIAL_STATE_SCHEMA)
    #: modules of the cached numba kernels (the truth simulator's model, the smoother's IMU step):
    #: compiled in a child process on a checkout's first run (:mod:`workbench.problems.precompile`)
    compiled_modules = ("workbench.problems.entry.truth_fast", "workbench.estimation.strapdown_kernel")

    def settings(self, scenario: Scenario) -> EntrySettings:
        """The run's frozen :class:`~workbench.problems.entry.config.EntrySettings` (validated once,
        the vehicle asset loaded once); a :class:`ScenarioError` naming file and key otherwise."""
        return EntrySettings.from_scenario(scenario)

    def telemetry_files(self, settings: EntrySettings, folder: Path | None = None) -> dict[str, Path]:
        """``[telemetry]`` files (``telemetry.STREAMS``), or the standard names in ``folder``."""
        if folder is None:
            return telemetry_paths(settings.telemetry, settings.run.path)
        return folder_telemetry(folder, STREAMS)

    def synthesize(self, settings: EntrySettings, out_dir: Path, seed: int) -> Synthesized:
        """Simulate the entry (truth) and write the telemetry + ``truth.npz`` into ``out_dir``."""
        from workbench.problems.entry.synthetic import synthesize_entry

        paths = synthesize_entry(settings, out_dir, seed=seed)
        return synthesized(paths)

    def load_truth(self, path: Path) -> dict:
        """The truth of ``truth.npz`` (``synthetic.load_truth``)."""
        from workbench.problems.entry.synthetic import load_truth

        return load_truth(path)

    def reconstruct(
        self, settings: EntrySettings, telemetry: Mapping[str, Path], options: RunOptions
    ) -> Iterator[object]:
        """``pipeline.reconstruct``; ``options.members``/``scheduler`` set the dispersion analysis."""
        return en.reconstruct(settings, dict(telemetry), scheduler=options.scheduler, members=options.members)

    def key_moments(self, result: en.EntryResult) -> list[KeyMoment]:
        """EIP, peak deceleration, PDD, saturation, FSR, first radar fix ... (:func:`key_moments`)."""
        return key_moments(result)

    def headline(self, summary: dict) -> str:
        """Altitude above ground ± 1σ at the end of the data and the dispersion acceptance; with a
        truth, the measured density error per segment against AMELIA's bounds and its share inside
        3σ, and the wind bound (PASS/FAIL as measured)."""
        e, d = summary["end"], summary["dispersion"]
        line = (
            f"end of data: h AGL {e['h_agl_m']:.0f} ± {e['sigma_h_m']:.0f} m (1σ); "
            f"dispersion {d['accepted']}/{d['members']} accepted"
        )
        tr = summary.get("truth", {})
        parts = []
        for seg, short in (
            ("entry_measured", "entry"),
            ("entry_filled_blackout", "blackout"),
            ("under_parachute", "chute"),
        ):
            a = tr.get("atmosphere", {}).get(seg)
            if a:
                parts.append(
                    f"{short} {100 * a['density_max_abs_error_rel']:.1f} %/{100 * a['density_bound_rel']:.0f} % "
                    f"{'PASS' if a['density_bound_pass'] else 'FAIL'} "
                    f"({100 * a['density_fraction_within_3sigma']:.0f} % in 3σ)"
                )
        w = tr.get("winds_in_layers")
        if w:
            parts.append(
                f"winds {w['max_error_mps']:.1f}/{w['bound_mps']:.0f} m/s {'PASS' if w['bound_pass'] else 'FAIL'}"
            )
        if parts:
            line += "; density max error " + ", ".join(parts)
        return line

    @contextlib.contextmanager
    def open_recording(self, path: Path, settings: EntrySettings, truth: Any, properties: dict) -> Iterator[RunDrawer]:
        """The entry recording drawn in the landing-site frame; its one layout
        (``recording.entry_blueprint``), sent when the run is done, has the AGL views fixed on the
        descent (known only then; without a descent the generic AGL view) and every time plot's axes
        on what it draws (the run's span, the radar's span, the residuals' ±3σ)."""
        from workbench.core.bodies import MARS
        from workbench.problems.entry.recording import (
            EntryRecorder,
            descent_window,
            entry_blueprint,
            residual_ranges,
            residual_spans,
            run_span,
        )
        from workbench.recording.writer import open_recording

        with open_recording(path, settings.run.name, properties=properties) as rec:
            drawer = EntryRecorder(
                rec,
                settings.require_vehicle(),
                truth,
                r_ground=settings.r_ground,
                jd_tdb0=en.epoch_jd_tdb(settings) if settings.epoch_utc is not None else None,
                body=MARS,
            )

            def layout(result: object, summary: dict):
                window = descent_window(summary)
                return entry_blueprint(
                    descent=window,
                    residual_y=residual_ranges(result.filter),
                    span=run_span(summary),
                    residual_span=residual_spans(result.filter),
                )

            yield RunDrawer(rec, drawer, en.scorecard_markdown, layout=layout, blueprint=entry_blueprint())

    def export_columns(self, result: en.EntryResult) -> ExportTable:
        """Smoothed position, velocity (MMED inertial), attitude q_M_G and their σ."""
        sm = result.filter.smoothed
        sd = np.sqrt(np.einsum("nii->ni", sm.P))
        cols: dict[str, tuple[np.ndarray, str]] = {}
        for i, a in enumerate("xyz"):
            cols[f"p_M.{a}"] = (sm.p_M[:, i], "m")
            cols[f"v_M.{a}"] = (sm.v_M[:, i], "m/s")
            cols[f"sigma_v.{a}"] = (sd[:, DV][:, i], "m/s")
            cols[f"sigma_theta.{a}"] = (sd[:, DTH][:, i], "rad")
            cols[f"sigma_p.{a}"] = (sd[:, DP][:, i], "m")
        for i, a in enumerate("xyzw"):
            cols[f"q_M_G.{a}"] = (sm.q_M_G[:, i], "1")
        return ExportTable(sm.t, cols, "MMED inertial; q_M_G body (GNC) to MMED")

    def monte_carlo(self, settings: EntrySettings, out_dir: Path, options: McOptions, progress: Progress) -> McOutcome:
        """Validate the radar-aided smoother on ``options.n_runs`` trajectories drawn from the
        accepted dispersion members (AMELIA Sect. 8).  Synthetic scenarios are synthesized first
        (into ``<out>/<name>_mc_work/telemetry``); user scenarios use their telemetry.  The stages
        up to the dispersion run with the scenario's settings (``options.members`` overrides the
        member count, ``options.scheduler`` also runs the dispersion on Dask).  Writes
        ``<out>/<name>_mc.rrd``; raises ``ScenarioError`` if fewer than 2 members were accepted."""
        from workbench.problems.entry.montecarlo import ValidationSettings, prepare_validation, validate_smoother
        from workbench.problems.entry.recording_mc import record_entry_validation

        if options.truth_sim:
            return self._truth_monte_carlo(settings, Path(out_dir), options, progress)
        t_start = time.perf_counter()
        sc, out = settings, Path(out_dir)
        name = sc.run.name
        rep = prog.current()
        if sc.run.synthetic:
            with rep.stage("entry truth simulation + telemetry"):
                paths = self.synthesize(sc, out / f"{name}_mc_work" / "telemetry", sc.synthetic.seed).telemetry
        else:
            paths = self.telemetry_files(sc)
        with rep.stage("preprocessing + dispersion analysis"):
            inp = prepare_validation(sc, paths, members=options.members, scheduler=options.scheduler)
        d = inp.dispersion
        progress(
            f"dispersion: {int(d.accepted.sum())}/{d.accepted.size} accepted; validating the smoother on "
            f"{options.n_runs} runs from the {inp.start_mode!r} start "
            f"({options.scheduler or f'{options.workers} local worker(s)'}) ..."
        )
        if int(d.accepted.sum()) < 2 and inp.start_mode == "dispersion":
            raise ScenarioError(
                sc.run.path,
                None,
                f"the dispersion accepted {int(d.accepted.sum())} of {d.accepted.size} members; the validation "
                "draws its truths from the accepted ones (need >= 2): raise --members, [dispersion] "
                "refine_rounds or widen [dispersion.rules]",
            )
        t_val = time.perf_counter()
        res = validate_smoother(
            inp.imu,
            inp.nominal,
            d,
            inp.radar_times,
            ValidationSettings(
                n_runs=options.n_runs,
                seed=options.entropy,
                scheduler=options.scheduler,
                workers=options.workers,
                **inp.validation_kwargs(),
            ),
        )
        rep.record(f"smoother validation ({options.n_runs} runs)", time.perf_counter() - t_val)
        summary = {"scenario": name, "kind": "entry_validation", **res.summary}
        summary["smoother_start_mode"] = inp.start_mode
        summary["smoother_start_note"] = inp.start_note
        summary["dispersion"] = {
            "members": int(d.accepted.size),
            "accepted": int(d.accepted.sum()),
            "wall_s": float(d.wall_s),
            "scheduler": str(d.scheduler),
        }
        summary["wall_time_s"] = time.perf_counter() - t_start
        rrd = record_entry_validation(out / f"{name}_mc.rrd", f"{name} smoother validation", res, summary)
        lo, hi = summary["anees_band"]
        h = summary.get("h_agl_after_fix", {})
        headline = (
            f"smoothed ANEES (9 dof) time-avg {summary['anees_time_avg']:.2f}, at end "
            f"{summary['anees_at']['end']:.2f} (95 % band {lo:.2f}-{hi:.2f}); max altitude error after the radar "
            f"fix {h.get('max_error_m', float('nan')):.1f} m; wrote {rrd} in {summary['wall_time_s']:.0f} s"
        )
        return McOutcome(summary, Path(rrd), headline, res)

    def _truth_monte_carlo(self, sc: EntrySettings, out: Path, options: McOptions, progress: Progress) -> McOutcome:
        """``options.n_runs`` members, each a truth-simulator run and a full reconstruction from its
        telemetry files (``truth_mc.run_truth_monte_carlo``); writes ``<out>/<name>_truth_mc.rrd``."""
        from workbench.problems.entry.recording_mc import record_entry_validation
        from workbench.problems.entry.truth_mc import DEFAULT_MEMBERS, run_truth_monte_carlo

        if not sc.run.synthetic:
            raise NotImplementedError(
                f"{sc.run.path}: the Monte Carlo against the truth simulator needs a synthetic scenario"
            )
        t_start = time.perf_counter()
        members = options.members or DEFAULT_MEMBERS
        progress(
            f"Monte Carlo against the truth simulator: {options.n_runs} members, each a 6-DOF truth, "
            f"telemetry files and the full pipeline ({members} dispersion members) "
            f"({options.scheduler or f'{options.workers} local worker(s)'}) ..."
        )
        res = run_truth_monte_carlo(
            sc,
            n_runs=options.n_runs,
            seed=options.entropy,
            members=members,
            refine_rounds=options.refine_rounds,
            scheduler=options.scheduler,
            workers=options.workers,
        )
        summary = {"scenario": sc.run.name, **res.summary, "wall_time_s": time.perf_counter() - t_start}
        rrd = record_entry_validation(
            out / f"{sc.run.name}_truth_mc.rrd",
            f"{sc.run.name} Monte Carlo against the truth simulator",
            res.validation,
            summary,
        )
        lo, hi = summary["anees_band"]
        h = summary.get("h_agl_at_fix", {})
        headline = (
            f"truth-simulator Monte Carlo: smoothed ANEES (9 dof) at end {summary['anees_at']['end']:.2f}, curvilinear "
            f"{summary['anees_curvilinear_at']['end']:.2f} (95 % band {lo:.2f}-{hi:.2f}); altitude error at the radar "
            f"fix RMS {h.get('rms_error_m', float('nan')):.1f} m vs median 3σ "
            f"{h.get('median_3sigma_m', float('nan')):.1f} m; "
            f"wrote {rrd} in {summary['wall_time_s']:.0f} s"
        )
        return McOutcome(summary, Path(rrd), headline, res)
