"""Progress reporting (``workbench.io.progress``): plain timed lines off a terminal, bars on one,
nothing under quiet, the active reporter only in its own process, and stage labels that say which
pass a repeated stage is."""

from __future__ import annotations

import io
import multiprocessing as mp
import re

import numpy as np
import pytest

from workbench.io import progress
from workbench.io.progress import Reporter, current, format_seconds, reporter_for
from workbench.problems.runner import stage_label

STAGE_LINE = re.compile(r"^\[x\] (?P<label>.+?)\s+(?P<value>[0-9.]+) s$")


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_auto_mode_is_plain_off_a_terminal_and_bars_on_one(monkeypatch):
    monkeypatch.setenv("TERM", "xterm")
    assert reporter_for("auto", stream=io.StringIO()).mode == "plain"
    assert reporter_for("auto", stream=_Tty()).mode == "bars"
    assert reporter_for("auto", quiet=True, stream=_Tty()).mode == "quiet"
    assert reporter_for("bars", quiet=True, stream=_Tty()).mode == "quiet"
    monkeypatch.setenv("TERM", "dumb")
    assert reporter_for("auto", stream=_Tty()).mode == "plain"
    with pytest.raises(ValueError, match="progress mode"):
        Reporter("fancy")


def test_plain_mode_logs_one_timed_line_per_stage_and_a_final_line_per_counter():
    out = io.StringIO()
    rep = Reporter("plain", stream=out, prefix="[x] ")
    with rep.stage("truth simulation"):
        with rep.counter("members", total=4, unit="members") as c:
            for _ in range(4):
                c.update()
    rep.record("filter pass 1/2 (forward EKF)", 1.25)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("[x] members: 4/4 members in ")
    m1, m2 = STAGE_LINE.match(lines[1]), STAGE_LINE.match(lines[2])
    assert m1["label"] == "truth simulation" and float(m1["value"]) >= 0
    assert m2["label"] == "filter pass 1/2 (forward EKF)" and m2["value"] == "1.25"
    assert "\r" not in out.getvalue() and len(lines) == 3  # no bar drawing in the log
    assert [t.label for t in rep.times] == ["truth simulation", "filter pass 1/2 (forward EKF)"]
    rep.record("truth simulation", 0.5)
    assert list(rep.stage_times()) == ["truth simulation", "filter pass 1/2 (forward EKF)", "truth simulation #2"]


def test_quiet_prints_no_progress_but_results_and_still_times_stages():
    out = io.StringIO()
    rep = Reporter("quiet", stream=out)
    with rep.stage("a stage"), rep.counter("members", total=3) as c:
        c.set(3)
    rep.line("a progress line")
    assert out.getvalue() == ""
    assert [t.label for t in rep.times] == ["a stage"]
    rep.result("wrote x.rrd")
    assert out.getvalue() == "wrote x.rrd\n"


def test_bars_draw_counts_on_the_stream_and_stage_lines_stay_readable():
    out = _Tty()
    rep = Reporter("bars", stream=out, prefix="[x] ", bar_every_s=0.0)
    with rep.counter("members", total=5, unit="members") as c:
        for k in range(1, 6):
            c.set(k)
        rep.record("inside", 0.1)
    text = out.getvalue()
    assert "[x] members" in text and "5/5" in text
    assert "[x] inside" in text and "[x] members: 5/5 members in " in text


def test_a_running_counter_logs_count_and_eta_at_most_every_interval():
    out = io.StringIO()
    rep = Reporter("plain", stream=out, bar_every_s=0.0, plain_every_s=0.0)
    c = rep.counter("runs", total=10, unit="runs")
    c.set(5)
    assert re.match(r"^runs: 5/10 runs \(50 %\) after .+, ETA .+$", out.getvalue().splitlines()[0])
    rep2 = Reporter("plain", stream=io.StringIO())  # default: a line at most every 30 s
    c2 = rep2.counter("runs", total=10**6)
    for k in range(10**5):
        c2.set(k)
    assert rep2.stream.getvalue() == ""
    c.close()
    c2.close()


def test_nested_counters_report_only_the_outer_one():
    out = io.StringIO()
    rep = Reporter("plain", stream=out)
    with rep.counter("Monte Carlo members", total=2) as outer:
        for k in range(2):
            with rep.counter("drop truth simulation", total=1.0, unit="s simulated") as inner:
                inner.set(1.0)
            outer.set(k + 1)
    lines = out.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Monte Carlo members: 2/2 it in ")


def test_float_counts_are_formatted():
    rep = Reporter("plain", stream=io.StringIO())
    with rep.counter("truth", total=2.5, unit="s simulated") as c:
        c.set(2.5)
    assert rep.stream.getvalue().startswith("truth: 2.5/2.5 s simulated in ")


def _mode_in_child(q):
    q.put(current().mode)


def test_current_is_quiet_outside_active_and_in_a_forked_worker():
    assert current().mode == "quiet"
    rep = Reporter("plain", stream=io.StringIO())
    with progress.active(rep):
        assert current() is rep
        ctx = mp.get_context("fork")
        q = ctx.Queue()
        p = ctx.Process(target=_mode_in_child, args=(q,))
        p.start()
        p.join(10)
        assert q.get(timeout=5) == "quiet"  # the forked child inherits the variable but must not draw
    assert current().mode == "quiet"


def test_format_seconds():
    assert format_seconds(0.4213) == "0.42 s"
    assert format_seconds(12.34) == "12.3 s"
    assert format_seconds(245) == "4 min 05 s"
    assert format_seconds(3720) == "1 h 02 min"
    assert format_seconds(float("nan")) == "?"


def test_stage_labels_say_which_pass():
    from workbench.problems.droptest.pipeline import FilterStage

    z = np.zeros((2, 1))
    seen: dict[str, int] = {}
    fwd = FilterStage("forward", z[:, 0], z, z[:, :, None])
    smo = FilterStage("smoothed", z[:, 0], z, z[:, :, None])
    assert stage_label(fwd, seen) == "filter pass 1/2 (forward EKF)"
    assert stage_label(smo, seen) == "filter pass 2/2 (RTS smoother)"

    class Plain:
        pass

    class Named:
        def __init__(self, name):
            self.name = name

    assert [stage_label(Plain(), seen) for _ in range(3)] == ["Plain", "Plain #2", "Plain #3"]
    assert [stage_label(Named(n), seen) for n in ("forward", "smoothed")] == ["Named (forward)", "Named (smoothed)"]
