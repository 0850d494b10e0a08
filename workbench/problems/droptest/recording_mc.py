"""Draw a drop-test Monte Carlo (:func:`workbench.problems.droptest.montecarlo.monte_carlo`) into a Rerun recording.

One row per Monte Carlo member on the ``sample`` timeline (sequence = the member's seed):
``/plots/mc/max_stroke_error`` with its reported ``plus_3sigma`` / ``minus_3sigma``,
``/plots/mc/nees_stroke`` (1 dof) and ``/plots/mc/nees_pose_at_max`` (6 dof) as markers, the
restitution error, and the consistency summary as the ``/report`` scorecard (paths: the ``MC_*``
names of :mod:`workbench.recording.layout`). A reviewer scrubs through the members and sees at a
glance which ones leave their 3σ band.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from workbench.recording import layout
from workbench.recording.blueprint import plot_view, report_view
from workbench.recording.writer import open_recording

__all__ = ["record_monte_carlo", "mc_markdown"]


def _send(stream, entity: str, seeds: np.ndarray, values: np.ndarray) -> None:
    stream.send_columns(
        entity,
        indexes=[rr.TimeColumn(layout.SAMPLE, sequence=seeds)],
        columns=rr.Scalars.columns(scalars=np.asarray(values, float)),
    )


def mc_markdown(summary: dict) -> str:
    """Markdown scorecard of ``summarize_mc`` output (lengths converted to cm for reading)."""
    s = summary
    lo, hi = s["anees_stroke_band"]
    plo, phi = s["anees_pose_band"]
    return (
        "\n".join(
            [
                f"# Monte Carlo `{s['scenario']}` ({s['mode']}) — {s['n_runs']} runs",
                "",
                f"Executor: {s['executor']}; wall time {s['total_wall_s']:.0f} s.",
                "",
                *(
                    [
                        f"**{s['n_failed']} member(s) FAILED and are not in the statistics:**",
                        "",
                        *(f"- seed {f['seed']}: {f['error']}" for f in s["failed_members"]),
                        "",
                    ]
                    if s.get("n_failed")
                    else []
                ),
                "| quantity | value |",
                "|---|---|",
                f"| truth max stroke inside reported 3σ | {100 * s['fraction_inside_3sigma']:.1f} % |",
                f"| median reported 3σ | {100 * s['median_3sigma_m']:.2f} cm |",
                f"| error mean / median | {100 * s['error_mean_m']:+.2f} / {100 * s['error_median_m']:+.2f} cm |",
                f"| abs(error) median / p95 / max | {100 * s['abs_error_median_m']:.2f} / "
                f"{100 * s['abs_error_p95_m']:.2f} / {100 * s['abs_error_max_m']:.2f} cm |",
                f"| MER (error ≤ 10 cm and 3σ ≤ 10 cm) | {100 * s['fraction_mer_requirement']:.0f} % |",
                f"| max-stroke ANEES (1 dof) | {s['anees_stroke']:.2f} (band {lo:.2f}–{hi:.2f}) |",
                f"| pose NEES at max stroke (6 dof) | {s['anees_pose_at_max']:.2f} (band {plo:.2f}–{phi:.2f}) |",
                "",
            ]
        )
        + "\n"
    )


def record_monte_carlo(path: str | Path, name: str, res, summary: dict) -> Path:
    """Write the Monte Carlo ``res`` (an ``McResult``) and its ``summary`` to ``path`` (atomic)."""
    seeds = np.asarray(res.seed, dtype=np.int64)
    bp = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                plot_view("max-stroke error ±3σ [m]", layout.MC_STROKE, legend="RightTop"),
                plot_view("NEES [-]", layout.MC_NEES, legend="RightTop"),
                plot_view("restitution error [-]", layout.MC_RESTITUTION, legend="RightTop"),
            ),
            report_view("Scorecard", health=False),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(state="expanded", timeline=layout.SAMPLE),
    )
    with open_recording(path, name, blueprint=bp) as rec:
        st = rec.stream
        three = 3.0 * np.asarray(res.sigma, float)
        for ent, vals, label, color in (
            (layout.MC_STROKE_ERROR, res.error, "estimate − truth", (31, 119, 180)),
            (layout.MC_STROKE_PLUS_3SIGMA, three, "+3σ (reported)", (150, 150, 150)),
            (layout.MC_STROKE_MINUS_3SIGMA, -three, "−3σ (reported)", (150, 150, 150)),
            (layout.MC_NEES_STROKE, res.nees_stroke, "max-stroke NEES (1 dof)", (214, 39, 40)),
            (layout.MC_NEES_POSE_AT_MAX, res.nees_pose_at_max, "pose NEES at max stroke (6 dof)", (44, 160, 44)),
            (layout.MC_RESTITUTION_ERROR, res.restitution_error, "restitution error", (148, 103, 189)),
        ):
            _send(st, ent, seeds, vals)
            st.log(
                ent, rr.SeriesPoints(names=[label], colors=[color], markers=["circle"], marker_sizes=[3.0]), static=True
            )
        rec.report(mc_markdown(summary))
    return Path(path)
