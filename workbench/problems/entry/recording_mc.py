"""Draw the entry smoother's validation (``problems.entry.montecarlo``, AMELIA Sect. 8) into a Rerun recording.

* ``sample`` timeline (sequence = run index): per run the time-averaged smoothed NEES
  (``/plots/validation/runs/nees_time_avg``), the max altitude-AGL error after the radar fix with
  its 3σ (``/plots/validation/runs/h_agl_error_max`` and ``.../h_agl_3sigma``) and the fraction of
  (step, state) pairs with the truth inside ±3σ (``/plots/validation/runs/inside_3sigma``);
* ``time`` timeline [s from EIP]: ANEES(t) (9 dof) of the smoothed and forward passes, Cartesian
  and curvilinear (``problems.entry.montecarlo``), with the 95 % χ² band (``/plots/validation/anees/…``);
  RMS errors over the runs with the RMS of the reported 1σ
  (``/plots/validation/rms/{position,altitude,velocity,attitude}/…``, attitude in degrees);
* the summary as the ``/report`` scorecard (:func:`validation_markdown`).

Paths: the ``VALIDATION_*`` names of :mod:`workbench.recording.layout`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from workbench.recording import layout
from workbench.recording.blueprint import plot_view, report_view
from workbench.recording.writer import open_recording

__all__ = ["record_entry_validation", "validation_markdown", "validation_blueprint"]

_BLUE, _RED, _GREEN, _GREY, _PURPLE, _ORANGE = (
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (150, 150, 150),
    (148, 103, 189),
    (255, 127, 14),
)


def _fmt(x: float, nd: int = 2) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{nd}f}"


def validation_markdown(summary: dict, title: str = "Entry smoother validation") -> str:
    """Markdown scorecard of a :func:`~workbench.problems.entry.montecarlo.summarize_validation` summary."""
    s = summary
    lo, hi = s["anees_band"]
    L = [
        f"# {title} — {s['n_ok']}/{s['n_runs']} runs (AMELIA Sect. 8)",
        "",
        (
            f"Truths: {s['truths_note']}; radar noise "
            if "truths_note" in s
            else f"Truths: accepted dispersion members ({s.get('accepted_members', '?')} accepted, "
            f"{s.get('distinct_members_used', '?')} distinct used); radar noise "
        )
        + (
            ", ".join(f"{k} {v:g}" for k, v in s["radar_noise"].items())
            if "radar_noise" in s
            else ", ".join(f"{k} {v}" for k, v in s["radar_noise_simulated"].items())
            if "radar_noise_simulated" in s
            else "as the filter R"
        )
        + f"; gap noise in the truth: {s.get('gap_noise_in_truth', '?')}. Executor: {s['executor']}; "
        f"wall time {s['total_wall_s']:.0f} s (median run {s['run_wall_median_s']:.2f} s).",
        "",
        f"## ANEES (9 dof), 95 % band {lo:.2f}–{hi:.2f}",
        "",
        "Cartesian: the filter's error state; curvilinear: position error as horizontal + altitude about "
        "the estimate (free of the |δp_h|²/2R curvature term, see `problems/entry/montecarlo.py`).",
        "",
        "| epoch | t [s] | smoothed | inside | smoothed curvilinear | inside | forward | forward curvilinear |",
        "|---|---|---|---|---|---|---|---|",
    ]
    yes = {True: "yes", False: "NO"}
    for k, v in s["anees_at"].items():
        L.append(
            f"| {k} | {s['times_s'][k]:.2f} | {_fmt(v)} | {yes[s['anees_at_inside'][k]]} | "
            f"{_fmt(s['anees_curvilinear_at'][k])} | {yes[s['anees_curvilinear_at_inside'][k]]} | "
            f"{_fmt(s['anees_forward_at'][k])} | {_fmt(s['anees_forward_curvilinear_at'][k])} |"
        )
    L += [
        "",
        f"Time-averaged ANEES: smoothed {_fmt(s['anees_time_avg'])}, curvilinear "
        f"{_fmt(s['anees_curvilinear_time_avg'])}; forward {_fmt(s['anees_forward_time_avg'])}, curvilinear "
        f"{_fmt(s['anees_forward_curvilinear_time_avg'])}. ANEES(t) inside the band at "
        f"{100 * s['anees_fraction_of_steps_in_band']:.0f} % of the steps (curvilinear "
        f"{100 * s['anees_curvilinear_fraction_of_steps_in_band']:.0f} %); truth inside ±3σ for "
        f"{100 * s['inside_3sigma_mean']:.2f} % of (step, state) pairs (curvilinear "
        f"{100 * s['inside_3sigma_curvilinear_mean']:.2f} %).",
        "",
        "## RMS errors over the runs (RMS of the reported 1σ in brackets)",
        "",
    ]
    names = list(next(iter(s["rms_at"].values())).keys())
    L.append("| epoch | " + " | ".join(names) + " |")
    L.append("|---|" + "---|" * len(names))
    for k, row in s["rms_at"].items():
        sig = s["rms_sigma_at"][k]
        L.append(f"| {k} | " + " | ".join(f"{row[n]:.3g} ({sig[n]:.3g})" for n in names) + " |")
    h = s.get("h_agl_after_fix")
    if h:
        L += [
            "",
            f"After the first radar data ({h['t_fix_s']:.2f} s): max altitude-AGL error {h['max_error_m']:.1f} m "
            f"(median over runs {h['median_max_error_m']:.1f} m, median 3σ there {h['median_3sigma_at_max_m']:.1f} m); "
            f"max inside its 3σ in {100 * h['fraction_runs_max_inside_3sigma']:.0f} % of the runs, within 50 m in "
            f"{100 * h['fraction_runs_within_50m']:.0f} %.",
        ]
    nis = s.get("nis_mean", {})
    if nis:
        L += ["", "Mean NIS: " + ", ".join(f"{k} {_fmt(v['value'])} (dof {v['dof']})" for k, v in nis.items()) + "."]
    if "filter_R" in s:
        fr = s["filter_R"]
        L += ["", "Filter R (1σ): " + ", ".join(f"{k} {v:g}" for k, v in fr.items() if k != "note") + "."]
        if "note" in fr:  # the truth-simulator Monte Carlo says how the slant-out R was inflated
            L[-1] += f" ({fr['note']})"
    hf = s.get("h_agl_at_fix")
    if hf:
        L += [
            "",
            f"Altitude-AGL error at the first radar fix: RMS {hf['rms_error_m']:.1f} m, max "
            f"{hf['max_abs_error_m']:.1f} m vs median 3σ {hf['median_3sigma_m']:.1f} m (inside 3σ in "
            f"{100 * hf['fraction_inside_3sigma']:.0f} % of the runs; largest |error|/3σ "
            f"{hf['max_abs_error_over_3sigma']:.2f}).",
        ]
    if s.get("n_failed"):
        L += ["", f"**{s['n_failed']} runs failed**: " + "; ".join(s.get("failures", []))]
    return "\n".join(L) + "\n"


def validation_blueprint() -> rrb.Blueprint:
    """Default layout: ANEES and RMS curves on the left, per-run markers and the scorecard on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                plot_view("ANEES (9 dof) and 95 % band [-]", layout.VALIDATION_ANEES, legend="RightTop"),
                plot_view("RMS horizontal position error [m]", layout.VALIDATION_RMS_POSITION, legend="RightTop"),
                plot_view("RMS altitude-AGL error [m]", layout.VALIDATION_RMS_ALTITUDE, legend="RightTop"),
                plot_view("RMS velocity error [m/s]", layout.VALIDATION_RMS_VELOCITY, legend="RightTop"),
                plot_view("RMS attitude error [deg]", layout.VALIDATION_RMS_ATTITUDE, legend="RightTop"),
            ),
            rrb.Vertical(
                plot_view(
                    "per run: time-averaged NEES [-] (set the time panel's timeline to 'sample')",
                    layout.VALIDATION_RUNS_NEES,
                    legend="RightTop",
                ),
                plot_view(
                    "per run: max altitude error after fix [m] (timeline 'sample')",
                    layout.VALIDATION_RUNS_H_AGL,
                    legend="RightTop",
                ),
                report_view("Scorecard", health=False),
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(state="expanded", timeline=layout.TIME),
    )


def _per_run(stream, entity: str, runs: np.ndarray, values: np.ndarray, label: str, color) -> None:
    v = np.asarray(values, float)
    ok = np.isfinite(v)
    if not ok.any():
        return
    stream.send_columns(
        entity,
        indexes=[rr.TimeColumn(layout.SAMPLE, sequence=runs[ok])],
        columns=rr.Scalars.columns(scalars=v[ok]),
    )
    stream.log(
        entity, rr.SeriesPoints(names=[label], colors=[color], markers=["circle"], marker_sizes=[3.0]), static=True
    )


def record_entry_validation(path: str | Path, name: str, res, summary: dict | None = None) -> Path:
    """Write a ``ValidationResult`` ``res`` (and its ``summary``, default ``res.summary``) to ``path``
    (atomic; see the module docstring for the entities)."""
    summary = res.summary if summary is None else summary
    runs = np.arange(res.n_runs, dtype=np.int64)
    with open_recording(
        path,
        name,
        blueprint=validation_blueprint(),
        properties={"validation": {"n_runs": int(res.n_runs), "seed": int(res.seed)}},
    ) as rec:
        st = rec.stream
        # per run (sample timeline)
        _per_run(st, layout.VALIDATION_RUNS_NEES_TIME_AVG, runs, res.nees_time_avg, "time-averaged NEES (9 dof)", _BLUE)
        _per_run(
            st, layout.VALIDATION_RUNS_NEES_CURVILINEAR, runs, res.nees_curvilinear_time_avg, "… curvilinear", _GREEN
        )
        _per_run(
            st, layout.VALIDATION_RUNS_INSIDE_3SIGMA_X9, runs, 9.0 * res.inside_3sigma, "9 × inside-3σ fraction", _GREY
        )
        _per_run(
            st,
            layout.VALIDATION_RUNS_H_AGL_ERROR_MAX,
            runs,
            res.h_err_max_after_fix,
            "max |h AGL error| after fix",
            _RED,
        )
        _per_run(st, layout.VALIDATION_RUNS_H_AGL_THREE_SIGMA, runs, res.h_3sigma_at_max, "3σ at that step", _GREY)
        # curves (time timeline)
        t = res.t
        lo, hi = res.anees_band
        for ent, vals, label, col, wd in (
            (layout.VALIDATION_ANEES_SMOOTHED, res.anees, "ANEES smoothed", _BLUE, 1.5),
            (
                layout.VALIDATION_ANEES_SMOOTHED_CURVILINEAR,
                res.anees_curvilinear,
                "ANEES smoothed, curvilinear",
                _GREEN,
                1.5,
            ),
            (layout.VALIDATION_ANEES_FORWARD, res.anees_forward, "ANEES forward", _ORANGE, 1.0),
            (
                layout.VALIDATION_ANEES_FORWARD_CURVILINEAR,
                res.anees_forward_curvilinear,
                "ANEES forward, curvilinear",
                _PURPLE,
                1.0,
            ),
        ):
            rec.scalars(ent, t, vals, names=label, colors=[col], widths=wd)
        rec.scalars(
            layout.VALIDATION_ANEES_BAND_LO, t, np.full(t.size, lo), names="95 % band", colors=[_GREY], widths=0.5
        )
        rec.scalars(
            layout.VALIDATION_ANEES_BAND_HI, t, np.full(t.size, hi), names="95 % band", colors=[_GREY], widths=0.5
        )
        names = list(res.error_names)
        conv = np.array([180.0 / math.pi if u == "rad" else 1.0 for u in res.error_units])
        groups = {
            layout.VALIDATION_RMS_POSITION: [0, 1],
            layout.VALIDATION_RMS_ALTITUDE: [2],
            layout.VALIDATION_RMS_VELOCITY: [3, 4, 5],
            layout.VALIDATION_RMS_ATTITUDE: [6, 7, 8],
        }
        palette = [_BLUE, _RED, _GREEN]
        for g, cols in groups.items():
            for j, c in enumerate(cols):
                col = palette[j % 3] if g != layout.VALIDATION_RMS_ALTITUDE else _PURPLE
                rec.scalars(
                    layout.validation_rms_path(g, names[c]),
                    t,
                    res.rms_error[:, c] * conv[c],
                    names=f"RMS {names[c]}",
                    colors=[col],
                    widths=1.5,
                )
                rec.scalars(
                    layout.validation_rms_path(g, names[c], sigma=True),
                    t,
                    res.rms_sigma[:, c] * conv[c],
                    names=f"reported 1σ {names[c]}",
                    colors=[tuple(int(0.45 * x + 0.55 * 255) for x in col)],
                    widths=0.75,
                )
        rec.report(validation_markdown(summary))
    return Path(path)
