"""The post2 Monte Carlo drawings: the initial-state selection (thesis [R3] Ch. 5.1) and the truth study.

The selection, drawn (entity paths of :mod:`workbench.recording.layout`):

* ``/plots/mc_initial_state/metric`` — every member's accumulated |residual| against its member
  index (``sample`` timeline), ``.../kept`` the kept ones, ``.../delivered`` the delivered state's;
* ``/plots/mc_initial_state/shift`` — every member's time alignment Δ [s];
* ``/world/dispersion/mc_initial_state/{members,kept,chosen}`` — the dispersed initial positions
  (all, kept, the chosen one moved by its Δ) in the inertial frame [m].

:func:`open_mc_recording` wraps the post2 recording's drawer: it draws the
:class:`~workbench.problems.post2.huygens.McSelection` stage and hands every other stage on.

:func:`record_truth_mc` writes the recording of the Monte Carlo against the truth
(:mod:`.truth_mc`, ``workbench mc --truth-sim``): NEES along the grid, running NEES over the
members and each member's error/σ under ``/plots/post2_truth_mc`` (docs/RECORDING.md), and its table.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from workbench.problems.post2.huygens import McSelection
from workbench.problems.post2.model import POSITION
from workbench.problems.post2.truth_mc import TruthMcResult, mean_band
from workbench.recording import layout
from workbench.recording.blueprint import plot_view, report_view, tab
from workbench.recording.writer import open_recording

__all__ = [
    "McDrawer",
    "draw_mc_selection",
    "open_mc_recording",
    "record_truth_mc",
    "truth_mc_blueprint",
    "truth_mc_markdown",
]

_BASE = layout.plot_path("mc_initial_state")
_CLOUD = layout.join(layout.DISPERSION, "mc_initial_state")


def draw_mc_selection(rec, sel: McSelection) -> None:
    """Draw one :class:`McSelection` into the recording writer ``rec`` (paths in the module docstring)."""
    n = sel.metric.size
    idx = np.arange(n)
    fin = np.isfinite(sel.metric)
    grey, green = (150, 150, 150), (120, 200, 120)
    _sample_points(rec, layout.join(_BASE, "metric"), idx[fin], sel.metric[fin], "member metric [m/s²]", grey, 1.5)
    _sample_points(rec, layout.join(_BASE, "kept"), sel.kept, sel.metric[sel.kept], "kept", (255, 140, 0), 4.0)
    _sample_points(rec, layout.join(_BASE, "delivered"), np.array([0]), np.array([sel.nominal_metric]),
                   "delivered state (member 0)", (60, 140, 255), 6.0)  # fmt: skip
    fs = np.isfinite(sel.shift_s)
    _sample_points(rec, layout.join(_BASE, "shift"), idx[fs], sel.shift_s[fs], "time alignment Δ [s]", green, 1.5)
    rec.points(layout.join(_CLOUD, "members"), sel.members[:, POSITION], colors=(150, 150, 150, 160), radii=300.0)
    rec.points(layout.join(_CLOUD, "kept"), sel.members[sel.kept, POSITION], colors=(255, 140, 0, 255), radii=800.0)
    rec.points(layout.join(_CLOUD, "chosen"), sel.x0[None, POSITION], colors=(255, 40, 40, 255), radii=1500.0)


def _sample_points(rec, entity: str, samples: np.ndarray, values: np.ndarray, name: str, color, size: float) -> None:
    """Values (k,) against member indices ``samples`` (k,) on the ``sample`` timeline, as markers."""
    rec.stream.send_columns(
        entity,
        indexes=[rr.TimeColumn(layout.SAMPLE, sequence=np.asarray(samples, dtype=np.int64))],
        columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)),
    )
    rec.stream.log(
        entity, rr.SeriesPoints(names=[name], colors=[(*color, 255)], markers=["circle"], marker_sizes=[size]),
        static=True,
    )  # fmt: skip


class McDrawer:
    """A drawer that handles :class:`McSelection` and passes every other stage to ``inner``."""

    def __init__(self, inner):
        self.inner = inner
        self.rec = inner.rec

    def handle(self, stage) -> None:
        """Draw a stage."""
        if isinstance(stage, McSelection):
            draw_mc_selection(self.rec, stage)
        else:
            self.inner.handle(stage)

    def finish(self, result, summary: dict) -> None:
        """The inner drawer's finish (the scorecard)."""
        self.inner.finish(result, summary)


@contextlib.contextmanager
def open_mc_recording(inner_cm):
    """Wrap the post2 recording context manager ``inner_cm``: yields a :class:`McDrawer`."""
    with inner_cm as inner:
        yield McDrawer(inner)


# ------------------------------------------------------------------ Monte Carlo against the truth
_BAND = (120, 120, 120)
_TRAJ_RGB = {"position": (40, 120, 220), "velocity": (230, 120, 20)}
_RUNNING = {"parameters": (40, 160, 60), "end_position": (40, 120, 220), "end_velocity": (230, 120, 20)}
_PALETTE = [
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
]  # fmt: skip


def truth_mc_blueprint(window: tuple[float, float] | None = None) -> rrb.Blueprint:
    """Three tabs beside the table, the time panel expanded on ``sample`` (a view plots against the
    active timeline): running NEES over the members, each member's error/σ, and the NEES along the
    descent (on ``time``, opened on ``window`` (t0, t1) [s] when given; its title says to switch)."""
    grp = lambda g: layout.join(layout.POST2_TRUTH_MC, g)  # noqa: E731
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Tabs(
                tab(
                    "running NEES",
                    plot_view(
                        "running mean NEES [-] vs member (95 % bands lighter / grey)",
                        grp("running_nees"),
                        legend="RightTop",
                    ),
                ),
                tab(
                    "error / σ",
                    plot_view(
                        "each member's final parameter error / σ [-] (one colour per parameter; black crosses "
                        "the end position x, y, z) vs member; black ±3",
                        grp("z"),
                        legend="RightTop",
                    ),
                ),
                tab(
                    "NEES along the descent",
                    plot_view(
                        "mean smoothed NEES (3 dof) [-] vs time [s] (set the time panel's timeline to 'time') — "
                        "blue position, orange velocity; grey the 95 % band of a mean of N χ²(3)",
                        grp("grid_nees"),
                        legend="RightTop",
                        window=window,
                    ),
                ),
                active_tab=0,
            ),
            report_view("Monte Carlo vs truth", health=False),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(state="expanded", timeline=layout.SAMPLE, play_state="paused"),
        rrb.SelectionPanel(state="collapsed"),
    )


def record_truth_mc(path: Path, name: str, res: TruthMcResult, summary: dict) -> Path:
    """Write the recording of the post2 Monte Carlo against the truth (atomically) and return its
    path: the series of the module docstring from ``res`` and the table from ``summary``."""
    s = summary
    ok = [m for m in res.members if not m["failed"]]
    k = np.arange(len(ok), dtype=np.int64)
    sample = {layout.SAMPLE: k}
    window = (float(res.t[0]), float(res.t[-1])) if res.t.size >= 2 else None
    bp = truth_mc_blueprint(window)
    with open_recording(path, name, blueprint=bp, properties={"run": {"kind": s["kind"]}}) as rec:
        with np.errstate(all="ignore"):
            mean = np.nanmean(res.grid_nees, axis=0)  # (n, 2)
        counted = np.sum(np.isfinite(res.grid_nees[:, :, 0]), axis=0)
        n_grid = int(np.max(counted)) if counted.size else 0
        for j, q in enumerate(("position", "velocity")):
            rec.scalars(layout.post2_truth_mc_path("grid_nees", f"{q}_mean"), res.t, mean[:, j],
                        names=f"{q} mean NEES", colors=_TRAJ_RGB[q], widths=2.0)  # fmt: skip
        if n_grid:
            lo, hi = mean_band(n_grid, 3)
            for label, v in (("band_lo", lo), ("band_hi", hi)):
                rec.scalars(layout.post2_truth_mc_path("grid_nees", label), res.t, np.full(res.t.size, v),
                            names=f"95 % band ({n_grid} members)", colors=_BAND, widths=1.0)  # fmt: skip
        d = len(s["parameters"])
        series = {
            "parameters": ([m["nees"] for m in ok], d),
            "end_position": ([m["trajectory"]["position"]["end_nees"] for m in ok], 3),
            "end_velocity": ([m["trajectory"]["velocity"]["end_nees"] for m in ok], 3),
        }
        for key, (vals, dof) in series.items():
            run_mean = np.cumsum(vals) / (k + 1)
            rec.scalars(layout.post2_truth_mc_path("running_nees", key), None, run_mean, sequences=sample,
                        names=f"{key.replace('_', ' ')} ({dof} dof)", colors=_RUNNING[key], widths=2.0)  # fmt: skip
        for dof, key, rgb in ((d, "parameters", _tint(_RUNNING["parameters"])), (3, "three_dof", _BAND)):
            bands = np.array([mean_band(int(i) + 1, dof) for i in k])
            label = "parameters' band" if key == "parameters" else "end position and velocity band (3 dof)"
            for b, side in ((0, "lo"), (1, "hi")):
                entity = layout.post2_truth_mc_path("running_nees", f"{key}_{side}")
                rec.scalars(entity, None, bands[:, b], sequences=sample, names=label, colors=rgb, widths=1.0)
        z = np.array([m["z"] for m in ok])
        names = list(s["parameters"])
        rec.scatter(layout.post2_truth_mc_path("z", "parameters"), None, z, sequences=sample, names=names,
                    colors=[_PALETTE[i % len(_PALETTE)] for i in range(len(names))], size=4.0)  # fmt: skip
        ze = np.array([np.divide(m["trajectory"]["position"]["end_error"], m["trajectory"]["position"]["end_sigma"])
                       for m in ok])  # fmt: skip
        rec.scatter(layout.post2_truth_mc_path("z", "end_position"), None, ze, sequences=sample,
                    names=["end position x", "end position y", "end position z"], colors=[(0, 0, 0)] * 3,
                    marker="cross", size=4.0)  # fmt: skip
        for label, v in (("plus_3", 3.0), ("minus_3", -3.0)):
            rec.scalars(layout.post2_truth_mc_path("z", label), None, np.full(k.size, v), sequences=sample,
                        names="±3", colors=(0, 0, 0), widths=1.0)  # fmt: skip
        rec.report(truth_mc_markdown(s))
    return Path(path)


def _tint(rgb) -> tuple[int, int, int]:
    """A lighter shade of ``rgb`` (the band of a series)."""
    return tuple(int(c + 0.55 * (255 - c)) for c in rgb)


def truth_mc_markdown(s: dict) -> str:
    """The Monte Carlo's table (markdown) from its summary (:func:`~.truth_mc.run_truth_monte_carlo`)."""
    ss = s["seed_stream"]
    n = s["runs_completed"]
    drawn = s["parameters_drawn_from_prior"]
    counts = s["member_health_counts"]
    md = [
        f"# {s['scenario']}: Monte Carlo against the truth simulator",
        "",
        f"**{n} members** of the **{ss['stream']}** seed stream (`SeedSequence({ss['entropy']}, "
        f"spawn_key=({ss['spawn_key'][0]}, i))`, members {ss['members'][0]}–{ss['members'][-1]}): each its own "
        "sensor noise, initial state drawn from the delivered covariance"
        + (f" and {', '.join(drawn)} drawn from the prior" if drawn else "")
        + ", reconstructed from its telemetry files as `workbench run` does.",
        "",
        "| NEES | dof | mean | 95 % band | verdict |",
        "|---|---|---|---|---|",
        f"| parameters (final, smoothed) | {s['dimension']} | {s['mean_nees']:.2f} | "
        f"{s['band_95'][0]:.2f}–{s['band_95'][1]:.2f} | {s['verdict']} |",
    ]  # fmt: skip
    for q in ("position", "velocity"):
        t = s["trajectory"][q]
        lo, hi = t["end_band_95"]
        md.append(f"| end {q} | 3 | {t['end_mean_nees']:.2f} | {lo:.2f}–{hi:.2f} | {t['end_verdict']} |")
    for q in ("position", "velocity"):
        t = s["trajectory"][q]
        md.append(f"| {q} along the grid (smoothed, mean) | 3 | {t['grid_mean_nees_smoothed']:.2f} | | |")
    md += ["", "| parameter | mean z | mean z² | inside 3σ |", "|---|---|---|---|"]
    for p in s["parameters"]:
        md.append(
            f"| {p} | {s['per_parameter_mean_z'][p]:+.2f} | {s['per_parameter_mean_z2'][p]:.2f} | "
            f"{100 * s['per_parameter_inside_3sigma'][p]:.0f} % |"
        )
    tp = s["trajectory"]["position"]
    md += [
        "",
        "End position per axis: mean z² " + " / ".join(f"{v:.2f}" for v in tp["end_per_axis_mean_z2"])
        + ", inside 3σ " + " / ".join(f"{100 * v:.0f} %" for v in tp["end_per_axis_inside_3sigma"]) + ".",
        "",
        f"Start position error (mean) {s['start_error_m_mean'] / 1e3:.2f} km. Members' health: "
        + ", ".join(f"{v} {c}" for v, c in counts.items())
        + f". Executor: {s['executor']}; wall time {s['wall_s']:.0f} s, per member "
        f"median {s['member_wall_s']['median']:.1f} s.",
    ]  # fmt: skip
    not_ok = s.get("member_health_not_ok", {})
    if not_ok:
        md += ["", "Checks not OK: " + "; ".join(f"member {k}: {', '.join(v)}" for k, v in not_ok.items())]
    if s["failed_members"]:
        md += ["", "Failed members: " + "; ".join(s["failed_members"])]
    return "\n".join(md) + "\n"
