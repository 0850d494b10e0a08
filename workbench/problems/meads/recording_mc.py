"""Recording of the MEADS trade study (``workbench mc msl_meads``): the paper's Fig. 6.

``/plots/trade_study/<quantity>/<level>`` — 3σ over the runs of α, β [deg], q∞ [%] and Mach error
against time, one series per error level, and ``.../objective`` the science objective; the
table of levels × objectives as the report.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun.blueprint as rrb

from workbench.problems.meads.montecarlo import QUANTITIES, TradeStudy, level_name
from workbench.recording import layout
from workbench.recording.blueprint import plot_view, report_view
from workbench.recording.writer import open_recording

__all__ = ["record_trade_study", "trade_blueprint", "trade_markdown"]

_UNITS = {"alpha_deg": "α 3σ [deg]", "beta_deg": "β 3σ [deg]", "qbar_pct": "q∞ 3σ [%]", "mach": "Mach 3σ [-]"}
_COLORS = [(40, 120, 220), (40, 170, 60), (230, 150, 20), (200, 40, 40), (120, 60, 180)]


def trade_blueprint() -> rrb.Blueprint:
    """One time-series tab per quantity and the table."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Tabs(
                *[
                    plot_view(_UNITS[q] + " vs time", layout.join(layout.MEADS_TRADE_STUDY, q), legend="RightTop")
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
    """Write the trade-study recording (atomically) and return its path."""
    with open_recording(
        path, name, blueprint=trade_blueprint(), properties={"run": {"kind": "meads_trade_study"}}
    ) as rec:
        for j, q in enumerate(QUANTITIES):
            for i, lv in enumerate(ts.levels):
                rec.scalars(
                    layout.meads_trade_path(q, level_name(lv)),
                    ts.t,
                    ts.three_sigma[lv][:, j],
                    names=f"{100 * lv:g} % of reading",
                    colors=_COLORS[i % len(_COLORS)],
                )
            obj = summary["objectives_3sigma"][q]
            rec.scalars(
                layout.meads_trade_path(q, "objective"),
                ts.t,
                np.full(ts.t.size, obj),
                names="objective",
                colors=(0, 0, 0),
            )
        rec.report(trade_markdown(summary))
    return Path(path)
