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
    the final result; ``blueprint``: the layout sent when ``layout`` is absent or gives None.  A
    recording with a ``layout`` is opened without one (``open_recording(blueprint=None)``) and gets
    exactly one, at the end, as its default and active: a Viewer that opens the file has made its
    own layout by then (from a default met earlier, else a heuristic one), and only an activation
    replaces it.  A layout opened with the recording must therefore be loaded after it, as
    ``workbench open --at`` (:func:`~workbench.recording.moments.seek_viewer`) and ``workbench
    screenshot --blueprint`` do.
    """

    def __init__(
        self,
        rec,
        drawer,
        scorecard: Callable[[dict], str],
        layout: Callable[[object, dict], Any] | None = None,
        blueprint: Any = None,
    ) -> None:
        self.rec = rec
        self.drawer = drawer
        self.scorecard = scorecard
        self.layout = layout
        self.blueprint = blueprint

    def handle(self, stage: object) -> None:
        """Draw one stage with the problem's stage recorder (an unknown stage type is its ``TypeError``)."""
        self.drawer.handle(stage)

    def finish(self, result: object, summary: dict) -> None:
        """After the last stage: the scorecard of ``summary``, its health verdict and key moments,
        then the one layout of the recording: ``layout(result, summary)``, else ``blueprint``."""
        from workbench.recording.moments import log_key_moments

        self.rec.report(self.scorecard(summary))
        if "health" in summary:
            self.rec.health(summary["health"])
        log_key_moments(self.rec, summary.get("key_moments", []))
        blueprint = None if self.layout is None else self.layout(result, summary)
        if blueprint is None:
            blueprint = self.blueprint
        if blueprint is not None:
            self.rec.stream.send_blueprint(blueprint, make_active=True, make_default=True)
