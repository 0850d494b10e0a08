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

__all__ = ["RunDrawer", "verdict_block"]


def verdict_block(summary: dict) -> str:
    """The first lines of a run's scorecard (markdown), where the eye lands: the health verdict
    with every check that is not OK named, the headline (``summary["headline"]``), and for a
    synthetic run how far each headline number lies from its truth (``truth.*`` checks: |error| in
    units of the reported σ, ERROR beyond 3)."""
    health = summary.get("health") or {}
    lines = []
    if health:
        checks = health.get("checks", [])
        bad = [c for c in checks if c["status"] != "OK"]
        verdict = f"**Health: {health.get('verdict', '?')}** ({len(checks)} checks"
        named = ", ".join(f"{c['name']} {c['status']}" for c in bad)
        verdict += f"; not OK: {named})" if bad else ", all OK)"
        lines.append(verdict + " — details in the Health tab")
    if summary.get("headline"):
        lines.append(f"**{summary['headline']}**")
    truth = [c for c in health.get("checks", []) if c["name"].startswith("truth.")]
    if truth:
        lines.append(
            "truth (synthetic run), |error| / σ: "
            + ", ".join(
                f"{c['name'][len('truth.') :]} {c['value']:.2f}{'' if c['status'] == 'OK' else ' ' + c['status']}"
                for c in truth
                if isinstance(c.get("value"), int | float)
            )
            + " (inside 3σ: below 3)"
        )
    return "".join(f"{ln}  \n" for ln in lines) + ("\n" if lines else "")


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

        self.rec.report(verdict_block(summary) + self.scorecard(summary))
        if "health" in summary:
            self.rec.health(summary["health"])
        log_key_moments(self.rec, summary.get("key_moments", []))
        blueprint = None if self.layout is None else self.layout(result, summary)
        if blueprint is None:
            blueprint = self.blueprint
        if blueprint is not None:
            self.rec.stream.send_blueprint(blueprint, make_active=True, make_default=True)
