"""The Monte Carlo initial-state selection in the post2 recording (thesis [R3] Ch. 5.1).

Drawn (entity paths of :mod:`workbench.recording.layout`):

* ``/plots/mc_initial_state/metric`` — every member's accumulated |residual| against its member
  index (``sample`` timeline), ``.../kept`` the kept ones, ``.../delivered`` the delivered state's;
* ``/plots/mc_initial_state/shift`` — every member's time alignment Δ [s];
* ``/world/dispersion/mc_initial_state/{members,kept,chosen}`` — the dispersed initial positions
  (all, kept, the chosen one moved by its Δ) in the inertial frame [m].

:func:`open_mc_recording` wraps the post2 recording's drawer: it draws the
:class:`~workbench.problems.post2.huygens.McSelection` stage and hands every other stage on.
"""

from __future__ import annotations

import contextlib

import numpy as np
import rerun as rr

from workbench.problems.post2.huygens import McSelection
from workbench.problems.post2.model import POSITION
from workbench.recording import layout

__all__ = ["McDrawer", "draw_mc_selection", "open_mc_recording"]

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
