"""The drop test (REDLand) as a :class:`~workbench.problems.base.Problem`.

Composes :mod:`.pipeline` (reconstruction, scoring, scorecard), :mod:`.synthetic` (truth and
telemetry), :mod:`.recording` (the recording layout and drawer) and :mod:`.montecarlo`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from workbench.io.moments import KeyMoment, slug
from workbench.io.scenario import Scenario
from workbench.problems.base import ExportTable, McOptions, McOutcome, Progress, RunOptions, Synthesized
from workbench.problems.drawer import RunDrawer
from workbench.problems.droptest import model as rl
from workbench.problems.droptest import pipeline as dt
from workbench.problems.droptest.config import LANDER_SCHEMA, SCHEMA, SETUP_SCHEMA, DropSettings
from workbench.problems.droptest.telemetry import OPTIONAL_STREAMS, telemetry_paths
from workbench.problems.pipeline_problem import PipelineProblem

__all__ = ["TELEMETRY_FILES", "DropTestProblem", "key_moments", "residual_names"]

#: telemetry stream -> file name in a telemetry folder (what synthetic.synthesize_droptest writes)
TELEMETRY_FILES = {
    "imu": "imu.csv",
    "attitude_3dm": "3dm.csv",
    "events": "events.csv",
    "setup": "setup.toml",
    "ranging": "ranging.csv",
}


def residual_names(settings: DropSettings) -> list[str]:
    """Names of the measurement residual groups the run's filter has (blueprint panels):
    the accelerometer triads, ``gyro``, ``zupt``, and with ``[sensors.ranging]`` the odometer and
    ``<gun>.range``/``<gun>.rate`` per radar gun."""
    names = [*settings.accelerometer.triads, "gyro", "zupt"]
    rg = settings.ranging
    if rg.enabled:
        if rg.odometer:
            names.append("odometer")
        for gname in rg.radar_guns:
            names += [f"{gname}.range", f"{gname}.rate"]
    return names


#: what the events-file entries of a drop mean (other names are listed as they are)
_EVENT_TEXT = {
    "release": "release: the lander leaves the release mechanism (events file)",
    "bungee_cut": "bungee cut: the lander falls free (events file)",
}


def key_moments(result: dt.DropResult) -> list[KeyMoment]:
    """Key moments of a drop from its reconstruction, times [s] on the ``time`` timeline: the
    events-file entries (release, bungee cut), the first airbag contact (start of the contact the
    pipeline detects from the estimated non-gravitational acceleration, > 1 g), the max stroke,
    and the rebound: the first time after the max stroke when the smoothed stroke is back at its
    value at first contact (the airbags leave the ramp). The impact's moments share one window,
    0.15 s before contact to 0.25 s after the rebound (or the end of the detected contact); contact
    and rebound are left out when they did not happen in the data."""
    st, smo = result.stroke, result.smoothed
    t = smo.t
    out = []
    for name, t_e in sorted(result.telemetry.events.items(), key=lambda kv: kv[1]):
        text = _EVENT_TEXT.get(name, f"{name} (events file)")
        out.append(KeyMoment(slug(name), float(t_e), text, (float(t_e) - 0.25, float(t_e) + 0.5)))
    ms, h = st.max, st.smoothed
    i0, i1 = st.contact
    k_max = int(ms.index)
    k_up = None
    if i0 >= 0:
        back = np.flatnonzero(h.distance[k_max:] >= h.distance[i0])
        k_up = k_max + int(back[0]) if back.size else None
        end = float(t[max(i1, k_up if k_up is not None else i1)])
        window = (float(t[i0]) - 0.15, end + 0.25)
    else:
        window = (float(ms.time) - 0.3, float(ms.time) + 0.3)
    # the window holds every moment in it (a max stroke at the data end, after a diverged filter ...)
    window = (min(window[0], float(ms.time) - 0.05), max(window[1], float(ms.time) + 0.05))
    summ = result.summary or {}
    if summ.get("restitution", {}).get("undefined"):
        k_up = None  # the data end inside the contact: no rebound in the data
    if i0 >= 0:
        out.append(
            KeyMoment(
                "first_contact",
                float(t[i0]),
                f"first airbag contact (estimated |a_ng| > 1 g), stroke {h.distance[i0]:.3f} ± "
                f"{h.sigma[i0]:.3f} m (1σ)",
                window,
            )
        )
    flag = " — FULL STROKE" if ms.full_stroke else " — full stroke within 3σ" if ms.possible_full_stroke else ""
    if summ.get("max_stroke", {}).get("distance_m", 0.0) is not None:
        out.append(
            KeyMoment(
                "max_stroke",
                float(ms.time),
                f"max stroke {ms.distance:.3f} ± {ms.sigma:.3f} m (1σ) at vertex {ms.vertex}{flag}",
                window,
            )
        )
    if k_up is not None:
        e, se = st.restitution
        kb, ka = st.restitution_index
        rest = (
            f"restitution e = {e:.3f} ± {se:.3f} (1σ; v_n approaching at {t[kb]:.3f} s, leaving at {t[ka]:.3f} s)"
            if np.isfinite(e) and min(kb, ka) >= 0
            else "restitution not defined"
        )
        out.append(
            KeyMoment(
                "rebound",
                float(t[k_up]),
                f"rebound: the airbags leave the ramp (stroke back at {h.distance[i0]:.3f} m), {rest}",
                window,
            )
        )
    return out


class DropTestProblem(PipelineProblem):
    """Airbag drop test in the SPF chamber: kinematic/dynamic EKF + RTS smoother + airbag stroke.

    Scored (``pipeline.score``) on the max stroke, the restitution and the pose errors against the truth."""

    kind = "droptest"
    pipeline = dt
    title = "drop"
    schema = SCHEMA
    #: the other input file kinds a drop test reads (FORMATS.md tables)
    file_schemas = (LANDER_SCHEMA, SETUP_SCHEMA)
    #: telemetry streams that are TOML files of a schema (``workbench init`` marks their example values)
    telemetry_schemas = {"setup": SETUP_SCHEMA}
    #: modules of the cached numba kernels (truth forces, filter recursion): compiled in a child
    #: process on a checkout's first run (:mod:`workbench.problems.precompile`)
    compiled_modules = ("workbench.problems.droptest.truth_fast", "workbench.problems.droptest.kernel")

    def settings(self, scenario: Scenario) -> DropSettings:
        """The frozen settings of the run (:meth:`DropSettings.from_scenario`: the scenario
        validated, the lander asset read); the only place below the runner that sees the scenario."""
        return DropSettings.from_scenario(scenario)

    def telemetry_files(self, settings: DropSettings, folder: Path | None = None) -> dict[str, Path]:
        """``[telemetry]`` files (imu, attitude_3dm, events, setup, optional ranging), or the
        standard names in ``folder`` (ranging only if the file exists)."""
        if folder is None:
            return telemetry_paths(settings)
        d = Path(folder)
        return {k: d / f for k, f in TELEMETRY_FILES.items() if k not in OPTIONAL_STREAMS or (d / f).exists()}

    def synthesize(self, settings: DropSettings, out_dir: Path, seed: int) -> Synthesized:
        """Simulate the drop (truth) and write the telemetry + ``truth.npz`` into ``out_dir``."""
        from workbench.problems.droptest.synthetic import synthesize_droptest

        syn = synthesize_droptest(settings, out_dir, seed=seed)
        return Synthesized(telemetry=dict(syn.telemetry), truth=syn.truth_path)

    def calibration_settings(self, settings: DropSettings, seed: int) -> DropSettings:
        """A health-calibration member's settings (:func:`workbench.problems.runner.evaluate`): the
        scenario's drop replaced by the truth Monte Carlo's drop ``seed`` (``synthetic.disperse_drop``
        within the REDLand envelope, generator ``SeedSequence(seed, spawn_key=(1,))``), so the bands
        cover the honest drops a user flies, not one drop's sensor noise; sensors, rig and rocks kept."""
        from workbench.problems.droptest.synthetic import dispersed_settings

        return dispersed_settings(settings, int(seed))

    def load_truth(self, path: Path) -> dict[str, np.ndarray]:
        """The truth arrays of ``truth.npz`` (``synthetic.load_truth``)."""
        from workbench.problems.droptest.synthetic import load_truth

        return load_truth(path)

    def reconstruct(
        self, settings: DropSettings, telemetry: Mapping[str, Path], options: RunOptions
    ) -> Iterator[object]:
        """``pipeline.reconstruct``; ``options.seed`` drives the posterior sampling of the stroke σ."""
        return dt.reconstruct(settings, dict(telemetry), seed=0 if options.seed is None else options.seed)

    def key_moments(self, result: dt.DropResult) -> list[KeyMoment]:
        """Release, bungee cut, first contact, max stroke, rebound (:func:`key_moments`)."""
        return key_moments(result)

    def estimator(self, settings: DropSettings) -> str:
        """The size of the run's filter, for ``workbench list``: ``"EKF: 42 error states (43 full)"``
        (``model.sizes`` of its triads, so the number follows the code)."""
        n_x, n_e = rl.sizes(len(settings.accelerometer.triads))
        return f"EKF: {n_e} error states ({n_x} full)"

    def headline(self, summary: dict) -> str:
        """Max stroke ± 1σ and its time (and the true max stroke when scored)."""
        ms = summary["max_stroke"]
        if ms.get("distance_m") is None:
            line = f"max stroke undefined ({ms.get('undefined', 'not determined')})"
        else:
            line = f"max stroke {ms['distance_m']:.3f} ± {ms['sigma_m']:.3f} m (1σ) at t = {ms['time_s']:.3f} s"
        e = summary.get("restitution", {})
        if e.get("e") is None and e.get("undefined"):
            line += "; restitution undefined (the data end inside the contact)"
        if "truth" in summary:
            line += f"; truth {summary['truth']['max_stroke_truth_m']:.3f} m"
        return line

    @contextlib.contextmanager
    def open_recording(self, path: Path, settings: DropSettings, truth: Any, properties: dict) -> Iterator[RunDrawer]:
        """The drop-test recording; its one layout (``recording.droptest_blueprint``), sent when the run
        is done, has the camera at the impact, the stroke zoom and the bounded quantities' y ranges
        where the viewer's own would label fewer than three ticks (the generic one only if no impact)."""
        from workbench.problems.droptest.recording import (
            DropTestRecorder,
            bounded_y_ranges,
            droptest_blueprint,
            impact_view,
        )
        from workbench.recording.writer import open_recording

        residuals = residual_names(settings)
        triads = list(settings.accelerometer.triads)
        bp = droptest_blueprint(residuals, triads=triads)
        with open_recording(path, settings.name, properties=properties) as rec:

            def layout(result: object, summary: dict):
                impact = impact_view(result)
                whole, zoom = bounded_y_ranges(rec, impact)
                return droptest_blueprint(residuals, impact, triads, y_ranges=whole, zoom_y_ranges=zoom)

            yield RunDrawer(rec, DropTestRecorder(rec, truth), dt.scorecard_markdown, layout=layout, blueprint=bp)

    def export_columns(self, result: dt.DropResult) -> ExportTable:
        """Smoothed position, velocity, attitude (SPF chamber frame), their σ, and the stroke."""
        x = result.smoothed.x
        sd = np.sqrt(np.einsum("nii->ni", result.smoothed.P))
        p, v, q, sd_p = x[:, rl.SP], x[:, rl.SV], x[:, rl.SQ], sd[:, rl.EP]
        cols: dict[str, tuple[np.ndarray, str]] = {}
        for i, a in enumerate("xyz"):
            cols[f"p.{a}"] = (p[:, i], "m")
            cols[f"sigma_p.{a}"] = (sd_p[:, i], "m")
            cols[f"v.{a}"] = (v[:, i], "m/s")
        for i, a in enumerate("xyzw"):
            cols[f"q_spf_body.{a}"] = (q[:, i], "1")
        cols["stroke"] = (result.stroke.smoothed.distance, "m")
        cols["sigma_stroke"] = (result.stroke.smoothed.sigma, "m")
        return ExportTable(result.smoothed.t, cols, "SPF chamber frame")

    def monte_carlo(self, settings: DropSettings, out_dir: Path, options: McOptions, progress: Progress) -> McOutcome:
        """Consistency statistics of a synthetic scenario over ``options.seeds`` (truth inside 3σ,
        ANEES); writes ``<out>/<name>_mc.rrd`` and works in ``<out>/<name>_mc_work``."""
        from workbench.problems.droptest.montecarlo import monte_carlo, summarize_mc
        from workbench.problems.droptest.recording_mc import record_monte_carlo

        if not settings.run.synthetic:
            raise NotImplementedError(f"{settings.path}: Monte Carlo needs a synthetic droptest scenario")
        out = Path(out_dir)
        seeds = options.seeds
        how = options.scheduler or f"{options.workers} local worker(s)"
        progress(f"Monte Carlo: {len(seeds)} runs ({how}) ...")
        if options.truth_sim:
            progress(
                "note: every drop-test Monte Carlo member is already a different drop flown by "
                "the truth simulator (synthetic.disperse_drop); --truth-sim changes nothing here"
            )
        name = settings.name
        res = monte_carlo(
            settings, seeds, out / f"{name}_mc_work", scheduler=options.scheduler, workers=options.workers
        )
        summary = summarize_mc(res)
        rrd = record_monte_carlo(out / f"{name}_mc.rrd", f"{name} Monte Carlo", res, summary)
        first = summary["failed_members"][0] if summary["n_failed"] else {}
        failed = (
            f"{summary['n_failed']} of {len(seeds)} members FAILED (first: seed {first.get('seed')}: "
            f"{first.get('error', '')[:200]}); the statistics are over the other {summary['n_runs']}; "
            if summary["n_failed"]
            else ""
        )
        headline = failed + (
            f"truth inside 3σ in {100 * summary['fraction_inside_3sigma']:.0f} % of runs, "
            f"median 3σ {100 * summary['median_3sigma_m']:.1f} cm, max-stroke ANEES "
            f"{summary['anees_stroke']:.2f}; wrote {rrd} in {res.total_wall_s:.0f} s"
        )
        return McOutcome(summary, Path(rrd), headline, res)
