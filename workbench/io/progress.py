"""Progress of long work on the terminal: timed stages, and counters with counts and an ETA.

A :class:`Reporter` has one of three modes:

* ``"bars"`` — live progress bars (``tqdm``, on stderr) for counters, and one line per finished
  stage with its wall time printed above them; for an interactive terminal;
* ``"plain"`` — no bars: one line per finished stage with its wall time, one line when a counter
  finishes (count and wall time) and, for a long one, a line at most every ``plain_every_s``
  seconds (count, percentage, ETA).  For logs, CI and ``workbench run all`` (several processes
  share one terminal: interleaved lines stay readable, bars would overwrite each other);
* ``"quiet"`` — no progress output at all (``--quiet``); stages are still timed.

:func:`reporter_for` picks bars only when the stream is a terminal.  Results (the headline, the
paths written) go through :meth:`Reporter.result` and are printed in every mode.

Deep code (a truth simulator, a dispersion, a Monte Carlo study) does not take a reporter argument:
like :mod:`logging`, it asks :func:`current` for the reporter the command made active with
:func:`active` (a context variable), and gets a silent one when none is active, in another thread,
or in a forked worker process (only the process that opened the reporter draws).  Counters are
cheap: :meth:`Counter.set` only stores the value unless ``bar_every_s`` (0.1 s, i.e. ≤ 10 Hz) has
passed since the last redraw, so a per-step call in an integrator costs a clock read.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, TextIO

__all__ = [
    "MODES",
    "Counter",
    "Reporter",
    "StageTime",
    "active",
    "as_reporter",
    "current",
    "format_seconds",
    "reporter_for",
    "stage_times",
]

#: The reporter modes (see the module docstring); ``"auto"`` in :func:`reporter_for` = bars on a terminal.
MODES = ("bars", "plain", "quiet")


@dataclass(frozen=True)
class StageTime:
    """One timed stage: its ``label`` (e.g. ``"filter pass 1/2 (forward EKF)"``) and ``wall_s`` [s]."""

    label: str
    wall_s: float


def format_seconds(s: float) -> str:
    """A duration [s] for people: ``"0.42 s"``, ``"12.3 s"``, ``"4 min 05 s"``, ``"1 h 02 min"``."""
    if s != s or s < 0:  # NaN or negative: unknown
        return "?"
    if s < 10:
        return f"{s:.2f} s"
    if s < 60:
        return f"{s:.1f} s"
    if s < 3600:
        m, sec = divmod(int(round(s)), 60)
        return f"{m} min {sec:02d} s"
    h, m = divmod(int(round(s / 60)), 60)
    return f"{h} h {m:02d} min"


class Counter:
    """Progress of one piece of work with a count: ``done`` of ``total`` (None: unknown) ``unit``.

    Use as a context manager (or call :meth:`close`).  :meth:`set` / :meth:`update` may be called
    at any rate (they redraw at most every ``bar_every_s``); calling the counter as
    ``counter(done, total)`` is :meth:`set` — the ``progress`` callback signature of
    :func:`workbench.estimation.montecarlo.run_monte_carlo`.  Floats are allowed (e.g. seconds of
    simulated time).
    """

    def __init__(self, reporter: Reporter, desc: str, total: float | None, unit: str, nested: bool):
        self.reporter, self.desc, self.total, self.unit, self.nested = reporter, desc, total, unit, nested
        self.n: float = 0
        self.t0 = time.perf_counter()
        self._last_draw = self._last_line = time.monotonic()
        self._bar = reporter.open_bar(desc, total, unit) if reporter.mode == "bars" else None
        self.closed = False

    def set(self, done: float, total: float | None = None) -> None:
        """The count is now ``done`` (and the total ``total`` when given)."""
        self.n = done
        if total is not None and total != self.total:
            self.total = total
            if self._bar is not None:
                self._bar.total = total
        now = time.monotonic()
        if now - self._last_draw < self.reporter.bar_every_s:
            return
        self._last_draw = now
        if self._bar is not None:
            self._bar.update(done - self._bar.n)
        elif self.reporter.mode == "plain" and not self.nested and now - self._last_line >= self.reporter.plain_every_s:
            self._last_line = now
            self.reporter.line(self.describe(running=True))

    __call__ = set

    def update(self, n: float = 1) -> None:
        """Add ``n`` to the count."""
        self.set(self.n + n)

    def describe(self, running: bool = False) -> str:
        """The counter as one line: count (of total), elapsed wall time and, while ``running``, the ETA."""
        el = time.perf_counter() - self.t0
        num = (lambda v: f"{v:.1f}") if isinstance(self.n, float) or isinstance(self.total, float) else str
        if self.total:
            frac = min(max(self.n / self.total, 0.0), 1.0)
            count = f"{num(self.n)}/{num(self.total)} {self.unit}"
            if running:
                eta = el * (1 - frac) / frac if frac > 0 else float("nan")
                return (
                    f"{self.desc}: {count} ({100 * frac:.0f} %) after {format_seconds(el)}, ETA {format_seconds(eta)}"
                )
        else:
            count = f"{num(self.n)} {self.unit}"
            if running:
                return f"{self.desc}: {count} after {format_seconds(el)}"
        return f"{self.desc}: {count} in {format_seconds(el)}"

    def close(self, report: bool = True) -> None:
        """Finish: remove the bar and, for a top-level counter (and ``report``), print its final
        count and time."""
        if self.closed:
            return
        self.closed = True
        if self._bar is not None:
            self._bar.update(self.n - self._bar.n)
            self._bar.close()
        self.reporter.counter_closed(self, report)

    def __enter__(self) -> Counter:
        return self

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        self.close(report=exc_type is None)


class Reporter:
    """Where progress goes: stage lines, counters and results (module docstring).

    ``mode`` one of :data:`MODES`; ``stream`` the text stream (default ``sys.stderr`` at the time of
    writing); ``sink`` instead of the stream, a callable receiving each plain line (e.g. a test's
    ``list.append``; no bars then); ``prefix`` put before every line and bar (the runner sets
    ``"[<scenario>] "``); ``bar_every_s`` [s] the shortest interval between two redraws of a
    counter; ``plain_every_s`` [s] the shortest interval between two plain lines of a running
    counter.  ``times`` holds every :class:`StageTime` recorded, in order.
    """

    def __init__(
        self,
        mode: str = "plain",
        *,
        stream: TextIO | None = None,
        sink: Callable[[str], None] | None = None,
        prefix: str = "",
        bar_every_s: float = 0.1,
        plain_every_s: float = 30.0,
    ):
        if mode not in MODES:
            raise ValueError(f"progress mode must be one of {MODES}, got {mode!r}")
        if sink is not None and mode == "bars":
            mode = "plain"
        self.mode, self.sink, self.prefix = mode, sink, prefix
        self._stream = stream
        self.bar_every_s, self.plain_every_s = float(bar_every_s), float(plain_every_s)
        self.times: list[StageTime] = []
        self.pid = os.getpid()
        self._open: list[Counter] = []

    @property
    def stream(self) -> TextIO:
        """The stream lines and bars are written to."""
        return self._stream if self._stream is not None else sys.stderr

    # -- lines -------------------------------------------------------------------------------
    def _emit(self, text: str) -> None:
        if self.sink is not None:
            self.sink(text)
        elif self.mode == "bars" and self._open:
            from tqdm import tqdm

            tqdm.write(text, file=self.stream)  # above the bars
        else:
            print(text, file=self.stream, flush=True)

    def line(self, msg: str) -> None:
        """A progress line (``prefix`` + ``msg``); nothing under ``"quiet"``."""
        if self.mode != "quiet":
            self._emit(self.prefix + msg)

    __call__ = line  # a Reporter is also a ``workbench.problems.base.Progress`` line sink

    def result(self, msg: str) -> None:
        """A result line (headline, a path written): printed in every mode."""
        self._emit(self.prefix + msg)

    # -- stages ------------------------------------------------------------------------------
    def record(self, label: str, wall_s: float) -> StageTime:
        """Record a stage that took ``wall_s`` [s] and print its line (``label``, wall time)."""
        st = StageTime(str(label), float(wall_s))
        self.times.append(st)
        self.line(f"{st.label:<40s} {format_seconds(st.wall_s):>10s}")
        return st

    @contextlib.contextmanager
    def stage(self, label: str) -> Iterator[None]:
        """Time the ``with`` block as the stage ``label`` (recorded and printed when it succeeds)."""
        t0 = time.perf_counter()
        yield
        self.record(label, time.perf_counter() - t0)

    def stage_times(self, since: int = 0) -> dict[str, float]:
        """The stages recorded from index ``since`` on as ``{label: wall_s}`` (:func:`stage_times`)."""
        return stage_times(self.times[since:])

    # -- counters ----------------------------------------------------------------------------
    def counter(self, desc: str, total: float | None = None, unit: str = "it") -> Counter:
        """A :class:`Counter` of ``desc`` up to ``total`` ``unit`` (None: unknown total)."""
        c = Counter(self, desc, total, unit, nested=bool(self._open))
        self._open.append(c)
        return c

    def counter_closed(self, c: Counter, report: bool = True) -> None:
        """Called by :meth:`Counter.close`: prints a top-level counter's final line (if ``report``)."""
        if c in self._open:
            self._open.remove(c)
        if report and not c.nested:
            self.line(c.describe())

    def open_bar(self, desc: str, total: float | None, unit: str):
        """A ``tqdm`` bar on :attr:`stream` (``leave=False``: the final line replaces it)."""
        from tqdm import tqdm

        fmt = None  # tqdm's default for integer counts
        if isinstance(total, float):
            fmt = "{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} {unit} [{elapsed}<{remaining}]"
        elif total is None:  # e.g. simulated seconds until an event nobody knows in advance
            fmt = "{desc}: {n:.1f} {unit} [{elapsed}]"
        return tqdm(
            total=total,
            desc=self.prefix + desc,
            unit=unit,
            file=self.stream,
            leave=False,
            dynamic_ncols=True,
            mininterval=self.bar_every_s,
            smoothing=0.1,
            bar_format=fmt,
            position=len(self._open),
        )


def stage_times(times: Sequence[StageTime]) -> dict[str, float]:
    """``{label: wall_s}`` [s, rounded to 0.1 ms] of ``times`` in order, JSON-ready; a repeated
    label gets `` #2``, `` #3``, ..."""
    out: dict[str, float] = {}
    for st in times:
        key, k = st.label, 1
        while key in out:
            k += 1
            key = f"{st.label} #{k}"
        out[key] = round(st.wall_s, 4)
    return out


_ACTIVE: contextvars.ContextVar[Reporter | None] = contextvars.ContextVar("workbench_progress", default=None)


def reporter_for(mode: str = "auto", *, quiet: bool = False, stream: TextIO | None = None) -> Reporter:
    """The reporter of a command: ``"quiet"`` with ``quiet``; for ``mode="auto"`` bars when
    ``stream`` (default ``sys.stderr``) is a terminal and the ``TERM`` is not ``dumb``, else plain
    lines; or the given mode (``"bars"``, ``"plain"``, ``"quiet"``)."""
    if quiet:
        return Reporter("quiet", stream=stream)
    if mode == "auto":
        s = stream if stream is not None else sys.stderr
        try:
            tty = bool(s.isatty())
        except (AttributeError, ValueError):
            tty = False
        mode = "bars" if tty and os.environ.get("TERM", "") != "dumb" else "plain"
    return Reporter(mode, stream=stream)


def as_reporter(progress: Reporter | Callable[[str], None] | None) -> Reporter:
    """``progress`` as a :class:`Reporter`: itself; a line callable wrapped as a plain reporter
    writing to it; None: a quiet reporter."""
    if isinstance(progress, Reporter):
        return progress
    if progress is None:
        return Reporter("quiet")
    return Reporter("plain", sink=progress)


@contextlib.contextmanager
def active(reporter: Reporter) -> Iterator[Reporter]:
    """Make ``reporter`` the one :func:`current` returns inside the ``with`` block (this thread)."""
    token = _ACTIVE.set(reporter)
    try:
        yield reporter
    finally:
        _ACTIVE.reset(token)


def current() -> Reporter:
    """The active reporter (:func:`active`), or a quiet one when none is active or this is not
    the process that made it active (a forked worker inherits the variable but must not draw)."""
    rep = _ACTIVE.get()
    if rep is None or rep.pid != os.getpid():
        return Reporter("quiet")
    return rep
