"""The :class:`~workbench.problems.base.StageRecorder` a problem's ``open_recording`` yields.

Every problem draws a run the same way: each stage goes to the problem's own stage recorder
(``DropTestRecorder``, ``EntryRecorder``, ...); after the last stage the recording gets the run's
scorecard (markdown), its health verdict (``summary["health"]``, when there is one) and its key
moments (:func:`workbench.recording.moments.log_key_moments`), and optionally a layout that needs
the whole result (camera at the impact, AGL views fixed on the descent).  :class:`RunDrawer` is that
sequence once, so that the problems differ only in what they pass to it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["RunDrawer"]


class RunDrawer:
    """:class:`~workbench.problems.base.StageRecorder` of one run.

    ``rec``: the open :class:`~workbench.recording.writer.Recorder`; ``drawer``: the problem's stage
    recorder (anything with ``handle(stage)``); ``scorecard``: the problem's scorecard, summary dict ->
    markdown; ``layout``: optional ``(result, summary) -> blueprint or None``, the layout that needs
    the final result.  That layout becomes the recording's default, not forced active, so that a
    layout opened with the recording (``workbench open --at``, ``rerun REC.rrd LAYOUT.rbl``) wins
    whichever the Viewer loads first; None leaves the layout of ``open_recording`` alone.
    """

    def __init__(
        self,
        rec,
        drawer,
        scorecard: Callable[[dict], str],
        layout: Callable[[object, dict], Any] | None = None,
    ) -> None:
        self.rec = rec
        self.drawer = drawer
        self.scorecard = scorecard
        self.layout = layout

    def handle(self, stage: object) -> None:
        """Draw one stage with the problem's stage recorder (an unknown stage type is its ``TypeError``)."""
        self.drawer.handle(stage)

    def finish(self, result: object, summary: dict) -> None:
        """After the last stage: the scorecard of ``summary``, its health verdict and key moments,
        then the final layout (``layout(result, summary)``) when the problem has one."""
        from workbench.recording.moments import log_key_moments

        self.rec.report(self.scorecard(summary))
        if "health" in summary:
            self.rec.health(summary["health"])
        log_key_moments(self.rec, summary.get("key_moments", []))
        blueprint = None if self.layout is None else self.layout(result, summary)
        if blueprint is not None:
            self.rec.stream.send_blueprint(blueprint, make_active=False, make_default=True)
