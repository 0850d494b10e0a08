"""Schedules of the post2 problem file: observation weights and system noise vs time or vs event.

Thesis [R3] Ch. 3.2.3 (the MER-type entry with quaternion observations): the quaternion (and
attitude-rate) observations were given a *higher weight early* — before the deceleration, when the
acceleration says little about the attitude — and brought back to the acceleration's weight once
the deceleration began (around 130 s); *system noise was added late*, from that point on, so the
filter does not become "smug" when the reconstruction model starts to differ from the flight's
(early system noise would have slowed the rapid error reduction before 130 s).

A ``[schedules.<name>]`` table opens a window — from ``start_s`` or the firing of ``start_event``
(default: the start) until ``end_s`` or the firing of ``end_event`` (default: the end) — and inside
it either scales an observation's weights (``observation`` + ``weight_factor``: W × factor, i.e.
R / factor) or adds system noise to a state (``state`` + ``psd``: a random-walk PSD added to the
state's own, in the state's unit²/s).  Events are the ``[events.<name>]`` of the problem file as the
*estimator* sees them fire (conditions evaluated on its own state), so a schedule follows the
reconstructed trajectory, as POST2's event-driven inputs do.  Several windows on one target
combine: weight factors multiply, PSDs add.  The tables are validated in
:meth:`workbench.problems.post2.config.Post2Settings.from_scenario`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SCHEDULE_KEYS", "Schedule", "weight_factor", "extra_psd", "is_active"]

#: keys of a ``[schedules.<name>]`` table: kind, default, meaning
SCHEDULE_KEYS: dict[str, tuple[str, Any, str]] = {
    "observation": ("str", None, "observation name whose weights the window scales"),
    "state": ("str", None, "state name that gets system noise in the window"),
    "weight_factor": ("float", None, "observation: W × factor inside the window (R / factor), > 0"),
    "psd": ("number_or_list", None, "state: random-walk PSD added inside the window [unit²/s], ≥ 0"),
    "start_s": ("float", None, "window opens at this time [s] (default: the start)"),
    "start_event": ("str", None, "window opens when this event fires in the estimator (instead of start_s)"),
    "end_s": ("float", None, "window closes at this time [s] (default: the end)"),
    "end_event": ("str", None, "window closes when this event fires in the estimator (instead of end_s)"),
}


@dataclass(frozen=True)
class Schedule:
    """One window: ``target`` ("observation" or "state") and its ``name``; ``factor`` (weights) or
    ``psd`` (size,) SI²/s (system noise); opening/closing time [s] or event name (None: open)."""

    name: str
    target: str
    target_name: str
    factor: float | None
    psd: np.ndarray | None
    start_s: float | None
    start_event: str | None
    end_s: float | None
    end_event: str | None


def is_active(s: Schedule, t: float, fired) -> bool:
    """Whether the window is open at time t [s] with the events ``fired`` (names) so far."""
    if s.start_s is not None and t < s.start_s - 1e-9:
        return False
    if s.start_event is not None and s.start_event not in fired:
        return False
    if s.end_s is not None and t >= s.end_s - 1e-9:
        return False
    return not (s.end_event is not None and s.end_event in fired)


def weight_factor(schedules, observation: str, t: float, fired) -> float:
    """Product of the open windows' weight factors on ``observation`` at t [s] (1: none)."""
    f = 1.0
    for s in schedules:
        if s.target == "observation" and s.target_name == observation and is_active(s, t, fired):
            f *= s.factor
    return f


def extra_psd(schedules, state: str, size: int, t: float, fired) -> np.ndarray:
    """Sum of the open windows' PSDs (size,) [SI²/s] on ``state`` at t [s] (zeros: none)."""
    out = np.zeros(size)
    for s in schedules:
        if s.target == "state" and s.target_name == state and is_active(s, t, fired):
            out = out + s.psd
    return out
