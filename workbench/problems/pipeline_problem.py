"""What a :class:`~workbench.problems.base.Problem` passes through to its pipeline module.

A problem composes a pipeline module that holds the reconstruction's final result (with its
JSON-ready ``summary``), ``score(result, truth)`` and ``scorecard_markdown(summary)``; the problem's
methods of those names only hand over.  :class:`PipelineProblem` is that hand-over once: a problem
class derives from it and names its module in ``pipeline``.
"""

from __future__ import annotations

from typing import Any

__all__ = ["PipelineProblem"]


class PipelineProblem:
    """Base of a problem class whose ``pipeline`` (a module, class attribute) has ``score`` and
    ``scorecard_markdown``; gives :meth:`summary`, :meth:`score` and :meth:`scorecard` of the
    :class:`~workbench.problems.base.Problem` protocol."""

    #: the problem's pipeline module (``score(result, truth)``, ``scorecard_markdown(summary)``)
    pipeline: Any

    def summary(self, result: Any) -> dict:
        """A copy of the final ``result.summary`` (JSON-ready, SI), so the runner may add to it."""
        return dict(result.summary)

    def score(self, result: Any, truth: Any) -> dict:
        """``pipeline.score``: the errors of the final ``result`` against the ``truth`` (JSON-ready)."""
        return self.pipeline.score(result, truth)

    def scorecard(self, summary: dict) -> str:
        """``pipeline.scorecard_markdown``: the run's scorecard (markdown) from its ``summary``."""
        return self.pipeline.scorecard_markdown(summary)
