"""Recordings of the MEADS Monte Carlo studies (``workbench mc msl_meads``).

The trade study (paper Fig. 6, :mod:`.montecarlo`): ``/plots/trade_study/<quantity>/<level>`` —
3σ over the runs of α, β [deg], q∞ [%] and Mach error against time, one series per error level,
and ``.../objective`` the science objective; the table of levels × objectives as the report.  The
runs share one trajectory, so the same rows are also on the ``minus_100_mach`` timeline (its true
Mach): the time panel's timeline switches the plots to Mach, for reading beside the full-error
Monte Carlo.

The full-error-model Monte Carlo against the truth (paper Figs. 11–13, :mod:`.truth_mc`,
``--truth-sim``), against the flight condition: on the ``minus_100_mach`` timeline (x =
−100 · Mach, Mach decreasing left to right as in flight; one row per Mach bin at its centre, each
member-sample at its own true Mach, q∞ ≥ 850 Pa) ``/plots/truth_mc/<quantity>/<estimator>_mc`` the
3σ of the error over the member-samples of the solid bins (a line), ``.../<estimator>_mc_thin`` of
the thin bins (markers only: too few members), ``.../<estimator>_reported`` the median reported 3σ
(solid bins), ``.../objective``; the table and the per-bin table as the report.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun.blueprint as rrb

from workbench.problems.meads import truth_mc as tmc
from workbench.problems.meads.montecarlo import QUANTITIES, TradeStudy, level_name
from workbench.recording import layout
from workbench.recording.blueprint import plot_view, report_view, tab
from workbench.recording.writer import open_recording

__all__ = [
    "record_trade_study",
    "trade_blueprint",
    "trade_markdown",
    "record_truth_mc",
    "truth_mc_blueprint",
    "truth_mc_markdown",
]

_UNITS = {"alpha_deg": "α 3σ [deg]", "beta_deg": "β 3σ [deg]", "qbar_pct": "q∞ 3σ [%]", "mach": "Mach 3σ [-]"}
_COLORS = [(40, 120, 220), (40, 170, 60), (230, 150, 20), (200, 40, 40), (120, 60, 180)]


def trade_blueprint(window: tuple[float, float] | None = None) -> rrb.Blueprint:
    """One time-series tab per quantity, opened on ``window`` (t0, t1) [s] (the study's samples)
    when given, and the table."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Tabs(
                *[
                    plot_view(
                        _UNITS[q] + " vs time",
                        layout.join(layout.MEADS_TRADE_STUDY, q),
                        legend="RightTop",
                        window=window,
                    )
                    for q in QUANTITIES
                ]
            ),
            report_view("Trade study", health=False),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(state="collapsed", timeline=layout.TIME),
    )


def trade_markdown(summary: dict) -> str:
    """The levels × objectives table (markdown)."""
    md = [
        f"# MEADS trade study ({summary['runs_per_level']} runs per level, fixed R = {summary['fixed_r']:g})",
        "",
        "Max over the samples above 850 Pa of the 3σ error (median in brackets); ✔ = objective met.",
        "",
        "| error level | α (≤ 0.5°) | β (≤ 0.5°) | q∞ (≤ 2 %) | Mach (≤ 0.1) | Mach below M 5 |",
        "|---|---|---|---|---|---|",
    ]
    for lv, row in summary["table"].items():
        cells = []
        for q in QUANTITIES:
            r = row[q]
            cells.append(f"{r['max_3sigma']:.3g} ({r['median_3sigma']:.3g}) {'✔' if r['met'] else '✘'}")
        cells.append(f"{row['mach'].get('max_3sigma_below_mach5', float('nan')):.3g}")
        md.append(f"| {lv} | " + " | ".join(cells) + " |")
    md += ["", f"Executor: {summary['executor']}; wall time {summary['wall_s']:.1f} s."]
    return "\n".join(md) + "\n"


def record_trade_study(path: Path, name: str, ts: TradeStudy, summary: dict) -> Path:
    """Write the trade-study recording (atomically) and return its path: rows on ``time`` and on
    ``minus_100_mach`` (module docstring)."""
    x = {layout.MACH_DESCENDING: mach_axis(ts.mach)}  # the shared trajectory's true Mach
    window = (float(ts.t[0]), float(ts.t[-1])) if ts.t.size >= 2 else None  # the viewer opens on the cursor
    with open_recording(
        path, name, blueprint=trade_blueprint(window), properties={"run": {"kind": "meads_trade_study"}}
    ) as rec:
        for j, q in enumerate(QUANTITIES):
            for i, lv in enumerate(ts.levels):
                rec.scalars(
                    layout.meads_trade_path(q, level_name(lv)),
                    ts.t,
                    ts.three_sigma[lv][:, j],
                    sequences=x,
                    names=f"{100 * lv:g} % of reading",
                    colors=_COLORS[i % len(_COLORS)],
                )
            obj = summary["objectives_3sigma"][q]
            rec.scalars(
                layout.meads_trade_path(q, "objective"),
                ts.t,
                np.full(ts.t.size, obj),
                sequences=x,
                names="objective",
                colors=(0, 0, 0),
            )
        rec.report(trade_markdown(summary))
    return Path(path)


# ------------------------------------------------------------- full error model vs the truth

_MC_UNITS = {
    "alpha_deg": "α 3σ [deg]",
    "beta_deg": "β 3σ [deg]",
    "qbar_pct": "q∞ 3σ [%]",
    "mach": "Mach 3σ [-]",
    "p_inf_pct": "p∞ 3σ [%]",
    "density_pct": "density 3σ [%]",
    "wind_north_mps": "wind north 3σ [m/s]",
    "wind_east_mps": "wind east 3σ [m/s]",
    "wind_down_mps": "wind down 3σ [m/s]",
}
_EST = {
    "least_squares": ("least squares", (40, 120, 220)),
    "ekf_pass1": ("EKF pass 1", (230, 150, 20)),
    "ekf_pass2": ("EKF pass 2", (40, 170, 60)),
}


def _tint(rgb: tuple[int, int, int], f: float = 0.5) -> tuple[int, int, int]:
    """``rgb`` mixed with white by ``f``."""
    return tuple(int(round(c + (255 - c) * f)) for c in rgb)


def mach_axis(mach: np.ndarray) -> np.ndarray:
    """The ``minus_100_mach`` timeline value (n,) int64 of Mach (n,) [-]: −round(100 · Mach)."""
    return -np.round(100.0 * np.asarray(mach, float)).astype(np.int64)


def truth_mc_blueprint(x_range: tuple[int, int] | None = None) -> rrb.Blueprint:
    """One tab per quantity (Monte Carlo and median reported 3σ per estimator, objective) against
    the Mach timeline, opened on ``x_range`` (lo, hi) of :func:`mach_axis` values when given, and
    the table; the selection panel collapsed (the table needs the width)."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Tabs(
                *[
                    tab(
                        _MC_UNITS[q].replace(" 3σ", ""),
                        plot_view(
                            _MC_UNITS[q] + " vs Mach, x = −100·Mach (−2500 = M 25, flight left to right) — "
                            "blue least squares, orange EKF pass 1, green EKF pass 2: thick Monte Carlo, "
                            "thin median reported, dots bins with too few members; black objective",
                            layout.join(layout.MEADS_TRUTH_MC, q),
                            x_range=x_range,
                        ),
                    )
                    for q in tmc.QUANTITIES
                ]
            ),
            report_view("Monte Carlo", health=False),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(state="collapsed", timeline=layout.MACH_DESCENDING, play_state="paused"),
        rrb.SelectionPanel(state="collapsed"),
    )


def _row(q: str, label: str, row: dict, obj: float | None) -> str:
    met = ""
    if "3rms_meets_objective" in row:
        met = " ✔" if row["3rms_meets_objective"] else " ✘"
    return (
        f"| {q} | {label} | {row['mc_3sigma_median']:.3g} | {row['mc_3rms_median']:.3g}{met} | "
        f"{row['reported_3sigma_median']:.3g} | {row['ratio_median']:.2f} | "
        f"{100 * row['fraction_inside_reported_3sigma']:.1f} % | {'' if obj is None else f'{obj:g}'} |"
    )


def truth_mc_markdown(summary: dict) -> str:
    """The estimators × quantities table and the disagreements (markdown)."""
    s = summary
    ests = [e for e in tmc.ESTIMATORS if e in s["table"]]
    truth = "dispersed entry, atmosphere, winds, CFD-like pressures" if s["truth_dispersed"] else "the scenario's"
    off = s.get("failure_port_switched_off")
    unc = s.get("mc_3sigma_relative_uncertainty")
    md = [
        f"# MEADS Monte Carlo, full error model vs the truth ({s['n_ok']}/{s['n_runs']} members)",
        "",
        f"Every member: its own truth ({truth}) and its own sensor errors (port location, time tags, lag, "
        "transpiration, calibration, scale factors, noise), reconstructed from its telemetry files as "
        "`workbench run` does" + (f"; the scenario's failure of {off} switched off." if off else "."),
        "",
        f"Per Mach bin (each member-sample at its own true Mach, above {s['min_qbar_pa']:g} Pa true q∞), "
        f"medians over the bins reached by ≥ {s.get('min_bin_members', 2)} members: **MC 3σ** the spread "
        "of the pooled errors (3 × std), **3 RMS** the total error (bias included; ✔/✘ its max meets the "
        "objective), **reported** the mean reported 3σ, **ratio** reported / MC 3σ (> 1 conservative), "
        "**inside** the member-samples inside their reported 3σ."
        + (f" The MC 3σ itself is uncertain by ±{100 * unc:.0f} % (1σ)." if unc else ""),
        "",
        "| quantity | estimator | MC 3σ | 3 RMS | reported | ratio | inside | objective |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for q in tmc.QUANTITIES:
        obj = s["objectives_3sigma"].get(q)
        first = True
        for e in ests:
            row = s["table"][e].get(q)
            if row is not None:
                md.append(_row(q if first else "", _EST[e][0], row, obj))
                first = False
    md += _bin_table(s)
    md += ["", "## Where the reported 3σ disagrees with the Monte Carlo spread", ""]
    md += [f"- {d}" for d in s["disagreements"]] or ["- nowhere (ratio within 0.67–1.5, ≥ 90 % inside)"]
    md += [
        "",
        f"Executor: {s['executor']}; wall time {s['wall_s']:.0f} s; "
        f"per member median {s['member_wall_s']['median']:.1f} s.",
    ]
    if s["failed_members"]:
        md += ["", "Failed members: " + "; ".join(s["failed_members"])]
    return "\n".join(md) + "\n"


_BIN_QUANTITIES = ("alpha_deg", "beta_deg", "qbar_pct", "mach")


def _bin_table(s: dict, est: str = "ekf_pass2") -> list[str]:
    """Markdown lines: per Mach bin (high first) of ``est``, for α, β, q∞, Mach: MC 3σ / median
    reported 3σ (inside %), the members; thin bins in italics."""
    bm = s.get("by_mach", {})
    rows = bm.get("estimators", {}).get(est, {})
    qs = [q for q in _BIN_QUANTITIES if q in rows]
    if not qs:
        return []
    md = [
        "",
        f"## Per Mach bin, {_EST[est][0]}: MC 3σ / median reported 3σ (inside)",
        "",
        "*italics*: a thin bin (fewer members than the table needs).",
        "",
        "| Mach | members | " + " | ".join(_MC_UNITS[q].replace(" 3σ", "") for q in qs) + " |",
        "|---|---|" + "---|" * len(qs),
    ]
    for i, (lo, hi) in enumerate(zip(bm["mach_lo"], bm["mach_hi"], strict=True)):
        members = max(rows[q]["members"][i] for q in qs)
        if members == 0:
            continue
        cells = []
        for q in qs:
            r = rows[q]
            mc, rep, ins = r["mc_3sigma"][i], r["reported_3sigma_median"][i], r["inside"][i]
            cells.append(f"{mc:.3g} / {rep:.3g} ({100 * ins:.0f} %)" if r["member_samples"][i] else "")
        thin = not any(rows[q]["solid"][i] for q in qs)
        mach = f"{lo:g}–{hi:g}"
        md.append(f"| {f'*{mach}*' if thin else mach} | {members} | " + " | ".join(cells) + " |")
    return md


def record_truth_mc(path: Path, name: str, res: tmc.FullMcResult, summary: dict) -> Path:
    """Write the full-error-model Monte Carlo recording (atomically) and return its path: per
    quantity and estimator the Monte Carlo and median reported 3σ per Mach bin of ``res.by_mach``
    on the ``minus_100_mach`` timeline (module docstring)."""
    bm = res.by_mach
    x = mach_axis(bm["mach_mid"])
    span = None
    if x.size >= 2:  # half a bin beyond the outer centres
        lo, hi = mach_axis(bm["mach_hi"][0]), mach_axis(bm["mach_lo"][-1])
        span = (int(lo), int(hi))
    with open_recording(
        path, name, blueprint=truth_mc_blueprint(span), properties={"run": {"kind": "meads_truth_mc"}}
    ) as rec:

        def line(entity: str, sel: np.ndarray, v: np.ndarray, **style) -> bool:
            if sel.sum() < 1:
                return False
            rec.scalars(entity, None, v[sel], sequences={layout.MACH_DESCENDING: x[sel]}, **style)
            return True

        for j, q in enumerate(tmc.QUANTITIES):
            drawn = np.zeros(x.size, bool)
            for e, est in enumerate(tmc.ESTIMATORS):
                label, rgb = _EST[est]
                mc, rep = bm["mc_3sigma"][:, j, e], bm["reported_3sigma_median"][:, j, e]
                solid = bm["solid"][:, j, e] & np.isfinite(mc)
                thin = ~bm["solid"][:, j, e] & np.isfinite(mc)
                if solid.sum() >= 2:
                    path_mc = layout.meads_truth_mc_path(q, f"{est}_mc")
                    line(path_mc, solid, mc, names=f"{label} Monte Carlo 3σ", colors=rgb, widths=2.5)
                    ok = solid & np.isfinite(rep)
                    name_rep = f"{label} median reported 3σ"
                    line(
                        layout.meads_truth_mc_path(q, f"{est}_reported"),
                        ok,
                        rep,
                        names=name_rep,
                        colors=_tint(rgb),
                        widths=1.0,
                    )
                    drawn |= solid
                if thin.any():
                    rec.scatter(
                        layout.meads_truth_mc_path(q, f"{est}_mc_thin"),
                        None,
                        mc[thin],
                        sequences={layout.MACH_DESCENDING: x[thin]},
                        names=f"{label} Monte Carlo 3σ, too few members",
                        colors=rgb,
                        size=3.0,
                    )
            obj = summary["objectives_3sigma"].get(q)
            if obj is not None and drawn.sum() >= 2:
                line(
                    layout.meads_truth_mc_path(q, "objective"),
                    drawn,
                    np.full(x.size, obj),
                    names="objective",
                    colors=(0, 0, 0),
                )
        rec.report(truth_mc_markdown(summary))
    return Path(path)
