"""What a :class:`~workbench.problems.base.Problem` passes through to its pipeline module.

A problem composes a pipeline module that holds the reconstruction's final result (with its
JSON-ready ``summary``), ``score(result, truth)`` and ``scorecard_markdown(summary)``; the problem's
methods of those names only hand over.  :class:`PipelineProblem` is that hand-over once: a problem
class derives from it and names its module in ``pipeline``.  :func:`folder_telemetry` and
:func:`synthesized` are the telemetry-folder convention the entry problems share.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from workbench.problems.base import Synthesized

__all__ = ["PipelineProblem", "folder_telemetry", "synthesized"]


def folder_telemetry(folder: Path, streams: Iterable[str]) -> dict[str, Path]:
    """The standard telemetry file names inside ``folder`` (the layout a synthetic run writes):
    ``{stream: folder/<stream>.csv}`` for every stream, ``initial_state.toml`` for the initial state."""
    d = Path(folder)
    return {k: d / f"{k}.{'toml' if k == 'initial_state' else 'csv'}" for k in streams}


def synthesized(paths: Mapping[str, Path]) -> Synthesized:
    """:class:`~workbench.problems.base.Synthesized` of what a truth simulation wrote, ``paths``:
    {stream: telemetry file, ..., ``"truth"``: ``truth.npz``}."""
    return Synthesized(telemetry={k: v for k, v in paths.items() if k != "truth"}, truth=paths["truth"])


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
