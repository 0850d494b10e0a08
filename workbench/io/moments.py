"""Key moments of a run: the instants a reviewer jumps to (release, first contact, max stroke, PDD ...).

A problem names its key moments from the final result of a reconstruction
(:meth:`workbench.problems.base.Problem.key_moments`, never from the truth); the runner stores them,
in time order, in the run summary under ``"key_moments"`` (a list of :meth:`KeyMoment.to_dict`),
and the recorder logs them into the recording (``workbench.recording.moments``: a bookmark row per
moment in the events log and a machine-readable recording property), from where
``workbench open REC.rrd --at NAME`` finds them.

This module is plain data (no rerun): the :class:`KeyMoment` record, its JSON form and checks.
Times are seconds on the recording's ``time`` timeline (from the scenario's reference event).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["KeyMoment", "MomentError", "default_window", "moments_from_dicts", "ordered", "slug"]

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


class MomentError(ValueError):
    """A key moment is malformed (name, time, window) or names repeat."""


@dataclass(frozen=True)
class KeyMoment:
    """One key moment of a run.

    ``name``: identifier used on the command line (``--at max_stroke``): lower-case letters, digits
    and ``_``, starting with a letter; ``t_s``: its time [s] on the recording's ``time`` timeline;
    ``description``: one line saying what happens there (with the reconstructed value and unit
    where there is one); ``window_s``: optional ``(start, end)`` [s] of the time range worth
    looking at around it (``start <= t_s <= end``); None lets the viewer tooling choose
    (:func:`default_window`).
    """

    name: str
    t_s: float
    description: str
    window_s: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise MomentError(
                f"key moment name {self.name!r} must be lower-case letters, digits and '_', starting with a letter"
            )
        t = float(self.t_s)
        if not math.isfinite(t):
            raise MomentError(f"key moment {self.name!r}: time {self.t_s!r} is not a finite number of seconds")
        object.__setattr__(self, "t_s", t)
        desc = str(self.description).strip()
        if not desc or "\n" in desc:
            raise MomentError(f"key moment {self.name!r}: the description must be one non-empty line")
        object.__setattr__(self, "description", desc)
        if self.window_s is not None:
            lo, hi = (float(v) for v in self.window_s)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= t <= hi and lo < hi):
                raise MomentError(
                    f"key moment {self.name!r}: window {self.window_s!r} [s] must be finite, start < end and "
                    f"contain t = {t:g} s"
                )
            object.__setattr__(self, "window_s", (lo, hi))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: ``{"name", "t_s", "description", "window_s": [start, end] or None}``."""
        w = None if self.window_s is None else [self.window_s[0], self.window_s[1]]
        return {"name": self.name, "t_s": self.t_s, "description": self.description, "window_s": w}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> KeyMoment:
        """The inverse of :meth:`to_dict` (``window_s`` optional); :class:`MomentError` if malformed."""
        try:
            w = d.get("window_s")
            return cls(str(d["name"]), float(d["t_s"]), str(d["description"]), None if w is None else tuple(w))
        except (KeyError, TypeError, ValueError) as err:
            if isinstance(err, MomentError):
                raise
            raise MomentError(f"malformed key moment {dict(d)!r}: {err}") from err

    def window_or_default(self, span_s: tuple[float, float] | None = None) -> tuple[float, float]:
        """``window_s``, or :func:`default_window` of ``t_s`` in the recording's time span ``span_s``."""
        return self.window_s if self.window_s is not None else default_window(self.t_s, span_s)


def default_window(
    t_s: float, span_s: tuple[float, float] | None = None, fraction: float = 0.05
) -> tuple[float, float]:
    """A time range [s] around ``t_s`` when a moment declares none: ± ``fraction`` of the
    recording's time span ``span_s = (first, last)`` [s] (at least ± 0.1 s), clipped to the span;
    ± 1 s without a span."""
    if span_s is None:
        return (t_s - 1.0, t_s + 1.0)
    lo, hi = float(span_s[0]), float(span_s[1])
    half = max(0.1, fraction * (hi - lo))
    a, b = max(lo, t_s - half), min(hi, t_s + half)
    if not a < b:  # t outside the span or a zero-length span
        a, b = t_s - half, t_s + half
    return (min(a, t_s), max(b, t_s))


def ordered(moments: Iterable[KeyMoment]) -> list[KeyMoment]:
    """The moments sorted by time (stable: equal times keep the problem's order); a
    :class:`MomentError` naming the repeated name if two share a name."""
    out = sorted(moments, key=lambda m: m.t_s)
    seen: set[str] = set()
    for m in out:
        if not isinstance(m, KeyMoment):
            raise MomentError(f"expected KeyMoment, got {type(m).__name__}")
        if m.name in seen:
            raise MomentError(f"key moment name {m.name!r} appears twice")
        seen.add(m.name)
    return out


def moments_from_dicts(items: Sequence[Mapping[str, Any]] | None) -> list[KeyMoment]:
    """Key moments from their JSON form (a summary's ``"key_moments"``), in time order."""
    return ordered(KeyMoment.from_dict(d) for d in (items or []))


def slug(text: str) -> str:
    """A free-form event name as a key-moment name: lower case, runs of other characters as one
    ``_`` (``"Main chute"`` → ``main_chute``, ``"RDA_ON"`` → ``rda_on``); ``event`` prefixed when it
    would not start with a letter."""
    s = re.sub(r"[^a-z0-9]+", "_", str(text).lower()).strip("_")
    if not s or not s[0].isalpha():
        s = "event_" + s if s else "event"
    return s
