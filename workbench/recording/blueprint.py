"""Default Viewer layouts (``rerun.blueprint``) embedded in workbench recordings.

:func:`standard_blueprint` builds the layout every pipeline starts from (docs/RECORDING.md: a 3D view,
the key time series, residuals, the report): the 3D scene on the left (60 %), and on the right a
tab strip of time-series views, a tab strip of residual views (if any), the markdown report and
the event log. Pipelines pass their own lists of ``(tab name, entity origin)``; the builder knows
nothing about any one problem. A blueprint applies to recordings with the same application id
(``layout.APPLICATION_ID``).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import rerun.blueprint as rrb

from workbench.recording import layout

__all__ = [
    "standard_blueprint",
    "save_blueprint",
    "plot_view",
    "events_view",
    "report_view",
    "time_window",
    "tab",
    "has_unit",
    "legible_range",
    "labelled_ticks",
    "y_range_if_needed",
    "LABEL_SPACING_PX",
]

LABEL_SPACING_PX = 20.0
"""Closest spacing [CSS px] of two labelled y ticks of Rerun 0.41's time-series view: it labels the
multiples of the smallest power of ten at least this far apart (ticks closer are drawn unlabelled)."""


def standard_blueprint(
    *,
    scene_origin: str = layout.WORLD,
    scene_exclude: Sequence[str] = (),
    plots: Sequence[tuple[str, str]] = (),
    residuals: Sequence[tuple[str, str]] = (),
    extra_views: Sequence[Any] = (),
    time_window_s: float | None = None,
) -> rrb.Blueprint:
    """The standard layout: 3D scene left, plots / residuals / report / events right.

    Parameters
    ----------
    scene_origin : origin of the 3D view (its subtree is shown).
    scene_exclude : entity paths hidden from the 3D view together with their subtrees
        (e.g. ``/world/truth`` for a clean scene).
    plots : ``(tab name, origin)`` pairs, one ``TimeSeriesView`` tab each (:func:`plot_view`: the
        name must carry the unit, e.g. ``("altitude [m]", layout.plot_path("altitude"))``).
    residuals : ``(tab name, origin)`` pairs for a second tab strip of residual views.
    extra_views : further blueprint views/containers, added as tabs next to the 3D view.
    time_window_s : if given, time-series views show only the trailing window
        ``[cursor − time_window_s, cursor]`` [s] of the ``time`` timeline; otherwise everything.

    The time panel starts expanded on the ``time`` timeline; the selection panel collapsed.
    """
    contents = ["+ $origin/**"] + [f"- {p.rstrip('/')}/**" for p in scene_exclude]
    scene: Any = rrb.Spatial3DView(name="Scene", origin=scene_origin, contents=contents)
    if extra_views:
        scene = rrb.Tabs(scene, *extra_views, active_tab=0)

    ts_kwargs: dict[str, Any] = {}
    if time_window_s is not None:
        if time_window_s <= 0:
            raise ValueError("time_window_s must be > 0")
        ts_kwargs["time_range"] = rrb.VisibleTimeRange(
            layout.TIME,
            start=rrb.TimeRangeBoundary.cursor_relative(seconds=-float(time_window_s)),
            end=rrb.TimeRangeBoundary.cursor_relative(),
        )

    right: list[Any] = []
    shares: list[float] = []
    if plots:
        right.append(rrb.Tabs(*[plot_view(n, o, **ts_kwargs) for n, o in plots], active_tab=0))
        shares.append(3.0)
    if residuals:
        right.append(rrb.Tabs(*[plot_view(n, o, **ts_kwargs) for n, o in residuals], active_tab=0))
        shares.append(2.0)
    right.append(report_view("Report"))
    right.append(events_view())
    shares += [1.5, 1.0]

    return rrb.Blueprint(
        rrb.Horizontal(scene, rrb.Vertical(*right, row_shares=shares), column_shares=[3, 2]),
        rrb.TimePanel(state="expanded", timeline=layout.TIME),
        rrb.SelectionPanel(state="collapsed"),
    )


def save_blueprint(
    bp: rrb.Blueprint, path: str | os.PathLike[str], application_id: str = layout.APPLICATION_ID
) -> Path:
    """Write ``bp`` as a standalone ``.rbl`` file (``rerun run.rrd layout.rbl``); returns the path."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    bp.save(application_id, str(p))
    return p


def report_view(name: str = "Scorecard", health: bool = True, extra: Sequence[Any] = ()) -> Any:
    """The view of the run's markdown scorecard at ``layout.REPORT`` — that entity only, since the
    health verdict is a second text document under it (``layout.HEALTH``) and a text view given
    both shows neither — with, when ``health``, the verdict in a second tab and ``extra`` views
    (e.g. :func:`events_view`) as further tabs of the same strip (full width for the event text)."""
    card = rrb.TextDocumentView(name=name, origin=layout.REPORT, contents="$origin")
    if not health:
        return card if not extra else rrb.Tabs(card, *extra, active_tab=0, name=name)
    health_view = rrb.TextDocumentView(name="Health", origin=layout.HEALTH, contents="$origin")
    return rrb.Tabs(card, health_view, *extra, active_tab=0, name=name)


_UNIT = re.compile(r"\[[^\]]+\]")


def has_unit(name: str) -> bool:
    """True if a view name states a unit in brackets (``"stroke [m]"``, ``"NIS [-]"``)."""
    return bool(_UNIT.search(name))


def legible_range(
    lo: float, hi: float, *, min_px: float = 120.0, label_px: float = LABEL_SPACING_PX, pad: float = 0.05
) -> tuple[float, float]:
    """A y range (a, b) [plotted unit] holding ``[lo, hi]`` on which a time-series view at least
    ``min_px`` [CSS px] high labels three ticks or more.

    The view labels multiples of one power of ten ``s`` only, the smallest whose ticks are
    ``label_px`` apart: a short panel over a span a little above a power of ten (±5.2 km in 150 px)
    labels only "0". The range is ``[lo, hi]`` widened by ``pad`` of its span on each side; if fewer
    than three multiples of the ``s`` it gets at ``min_px`` lie in it, it is widened to the nearest
    further multiples (with ``pad`` of ``s`` beyond them, so their labels are not cut)."""
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
        raise ValueError(f"legible_range needs finite lo <= hi, got [{lo}, {hi}]")
    if min_px <= 3.0 * label_px:
        raise ValueError(f"min_px {min_px} too small for three labels {label_px} px apart")
    span = hi - lo if hi > lo else max(abs(lo), 1.0) * 0.2
    a, b = lo - pad * span, hi + pad * span
    step = 10.0 ** math.ceil(math.log10((b - a) * label_px / min_px))
    while True:
        k0, k1 = math.ceil(a / step - 1e-9), math.floor(b / step + 1e-9)
        aa, bb = a, b
        while k1 - k0 + 1 < 3:
            if aa - (k0 - 1) * step < (k1 + 1) * step - bb:
                k0 -= 1
                aa = min(aa, (k0 - pad) * step)
            else:
                k1 += 1
                bb = max(bb, (k1 + pad) * step)
        if (bb - aa) * label_px / min_px <= step * (1.0 + 1e-9):
            return aa, bb
        step *= 10.0


def labelled_ticks(lo: float, hi: float, px: float, label_px: float = LABEL_SPACING_PX) -> list[float]:
    """The y labels a time-series view ``px`` [CSS px] high over ``[lo, hi]`` shows (Rerun 0.41,
    modelled): the multiples in it of the smallest power of ten whose ticks are ``label_px`` apart."""
    if not hi > lo or px <= 0:
        return []
    step = 10.0 ** math.ceil(math.log10((hi - lo) * label_px / px))
    return [k * step for k in range(math.ceil(lo / step - 1e-9), math.floor(hi / step + 1e-9) + 1)]


def y_range_if_needed(lo: float, hi: float, px: float) -> tuple[float, float] | None:
    """None when the viewer's own fit of ``[lo, hi]`` (the data's extent) labels three ticks or
    more in a view ``px`` [CSS px] high (:func:`labelled_ticks`), else :func:`legible_range` for
    that height: a y range is fixed only where the viewer's would show one or two labels."""
    if len(labelled_ticks(lo, hi, px)) >= 3:
        return None
    return legible_range(lo, hi, min_px=px)


def time_window(t0_s: float, t1_s: float) -> rrb.VisibleTimeRange:
    """The fixed window ``[t0_s, t1_s]`` [s] of the ``time`` timeline (a zoomed plot of an event)."""
    if not t1_s > t0_s:
        raise ValueError(f"time window needs t1 > t0, got [{t0_s}, {t1_s}]")
    return rrb.VisibleTimeRange(
        layout.TIME,
        start=rrb.TimeRangeBoundary.absolute(seconds=float(t0_s)),
        end=rrb.TimeRangeBoundary.absolute(seconds=float(t1_s)),
    )


def plot_view(
    name: str,
    origin: str,
    *,
    legend: str | None = None,
    y_range: tuple[float, float] | None = None,
    time_range: Any = None,
    window: tuple[float, float] | None = None,
    x_range: tuple[int, int] | None = None,
    span: tuple[float, float] | None = None,
    contents: Any = None,
) -> rrb.TimeSeriesView:
    """A time-series view whose name states the y unit, with a legend that does not cover the data.

    ``name`` must contain the unit in brackets (``"stroke [m]"``; ``[-]`` for a pure number), since
    Rerun 0.41's plot has no y-axis title: the view name is the axis name (``ValueError`` otherwise).
    ``legend``: None hides the legend (the colours are then explained in ``name``, e.g.
    ``"… — blue smoothed, grey ±3σ"``); a corner (``"LeftTop"``, ``"RightBottom"`` …) shows it there,
    for views with few series whose curves leave that corner free. ``y_range`` (lo, hi) in the
    plotted unit fixes the y axis (zoom on an interesting band); ``time_range`` a
    ``VisibleTimeRange`` (the data shown, e.g. trailing the cursor); ``window`` (t0, t1) [s] a fixed
    zoom: only that data, and the x axis opened on it (the viewer otherwise opens the x axis on its
    own span); ``x_range`` (lo, hi) the x axis opened on that span of a *sequence* timeline (e.g.
    ``minus_100_mach``; the viewer otherwise opens it around the time cursor); ``span`` (t0, t1)
    [s] the x axis opened on that span of the ``time`` timeline, all data kept (a run of hours
    otherwise opens on a minute around the cursor); ``contents`` an entity query other than
    ``$origin/**``.
    """
    if not has_unit(name):
        raise ValueError(f"plot view {name!r} must state its unit in brackets, e.g. '[m]' or '[-]'")
    kw: dict[str, Any] = {
        "plot_legend": rrb.PlotLegend(visible=False) if legend is None else rrb.PlotLegend(corner=legend, visible=True),
    }
    if y_range is not None:
        kw["axis_y"] = rrb.ScalarAxis(range=(float(y_range[0]), float(y_range[1])))
    if time_range is not None and window is not None:
        raise ValueError("give time_range or window, not both")
    if time_range is not None:
        kw["time_ranges"] = time_range
    if window is not None:
        kw["time_ranges"] = time_window(*window)
        kw["axis_x"] = rrb.TimeAxis(
            view_range=rrb.TimeRange(
                start=rrb.TimeRangeBoundary.absolute(seconds=float(window[0])),
                end=rrb.TimeRangeBoundary.absolute(seconds=float(window[1])),
            )
        )
    if sum(v is not None for v in (window, x_range, span)) > 1:
        raise ValueError("give one of window, x_range and span")
    if span is not None:
        if not span[1] > span[0]:
            raise ValueError(f"span needs t1 > t0, got {span}")
        kw["axis_x"] = rrb.TimeAxis(
            view_range=rrb.TimeRange(
                start=rrb.TimeRangeBoundary.absolute(seconds=float(span[0])),
                end=rrb.TimeRangeBoundary.absolute(seconds=float(span[1])),
            )
        )
    if x_range is not None:
        kw["axis_x"] = rrb.TimeAxis(
            view_range=rrb.TimeRange(
                start=rrb.TimeRangeBoundary.absolute(seq=int(x_range[0])),
                end=rrb.TimeRangeBoundary.absolute(seq=int(x_range[1])),
            )
        )
    if contents is not None:
        kw["contents"] = contents
    return rrb.TimeSeriesView(name=name, origin=origin, **kw)


def events_view(name: str = "Events") -> rrb.TextLogView:
    """The event log at ``layout.EVENTS``: time, level and text only (the entity-path column, always
    ``/events``, and the other timelines are hidden, so the text gets the width)."""
    return rrb.TextLogView(
        name=name,
        origin=layout.EVENTS,
        columns=rrb.TextLogColumns(
            timeline_columns=[rrb.encodings.TimelineColumn(tl, visible=tl == layout.TIME) for tl in layout.TIMELINES],
            text_log_columns=[
                rrb.encodings.TextLogColumn(rrb.encodings.TextLogColumnKind.LogLevel),
                rrb.encodings.TextLogColumn(rrb.encodings.TextLogColumnKind.Body),
                rrb.encodings.TextLogColumn(rrb.encodings.TextLogColumnKind.EntityPath, visible=False),
            ],
        ),
    )


def tab(name: str, *views: Any, shares: Sequence[float] | None = None) -> rrb.Vertical:
    """A tab with a short ``name`` (``"stroke [m]"``) holding ``views`` stacked: the views keep their
    long names (unit and colour key) in their own title bars, while the tab strip stays readable."""
    return rrb.Vertical(*views, name=name, row_shares=list(shares) if shares is not None else None)
