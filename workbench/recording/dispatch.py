"""Route pipeline stage results to the recorder functions that draw them.

A pipeline yields stage results (dataclasses such as a telemetry bundle, a filter pass, a final
result); a recorder draws each one. :class:`StageDispatch` maps stage result *types* to handler
functions, so a recorder states which stages it draws (and which it deliberately skips, with
:meth:`StageDispatch.ignore`). A stage of a type nobody registered is an error
(:class:`TypeError` naming the type): a new stage added to a pipeline cannot go silently undrawn.

This module does not import rerun.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any

__all__ = ["StageDispatch"]

Handler = Callable[[Any], None]


def _ignore(stage: Any) -> None:
    """Handler of a stage that is deliberately not drawn."""


class StageDispatch:
    """Registry ``stage type -> handler``; calling it with a stage runs the handler of its type.

    ``handlers``: initial ``{type: handler}`` mapping; ``ignored``: types whose stages are accepted and
    not drawn. A stage whose exact type is not registered is looked up along its class hierarchy
    (method resolution order), so a subclass of a registered stage goes to the same handler.
    """

    def __init__(self, handlers: Mapping[type, Handler] | None = None, ignored: Iterable[type] = ()) -> None:
        self._handlers: dict[type, Handler] = {}
        for cls, fn in (handlers or {}).items():
            self.register(cls, fn)
        self.ignore(*ignored)

    def register(self, cls: type, handler: Handler) -> None:
        """Let ``handler(stage)`` draw stages of type ``cls``; registering a type twice is a ``ValueError``."""
        if not isinstance(cls, type):
            raise TypeError(f"stage types must be classes, got {cls!r}")
        if not callable(handler):
            raise TypeError(f"handler for {cls.__qualname__} is not callable: {handler!r}")
        if cls in self._handlers:
            raise ValueError(f"stage type {cls.__module__}.{cls.__qualname__} is already registered")
        self._handlers[cls] = handler

    def ignore(self, *classes: type) -> None:
        """Accept stages of these types without drawing anything (e.g. a final result already drawn)."""
        for cls in classes:
            self.register(cls, _ignore)

    @property
    def types(self) -> tuple[type, ...]:
        """The registered stage types, in registration order."""
        return tuple(self._handlers)

    def handler_for(self, stage: Any) -> Handler:
        """The handler of ``stage`` (its type or nearest registered base class); ``TypeError`` if none."""
        for cls in type(stage).__mro__:
            fn = self._handlers.get(cls)
            if fn is not None:
                return fn
        t = type(stage)
        known = ", ".join(c.__qualname__ for c in self._handlers) or "none"
        raise TypeError(f"no recorder handler for stage type {t.__module__}.{t.__qualname__} (registered: {known})")

    def __call__(self, stage: Any) -> None:
        """Draw ``stage`` with the handler registered for its type."""
        self.handler_for(stage)(stage)
