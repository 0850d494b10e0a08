"""open_recording publishes a file only when the block completes (atomic rename after the footer)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.recording.reader import read_recording, verify
from workbench.recording.writer import open_recording


def _log_some(rec):
    t = np.arange(1000) * 0.001
    rec.scalars("/plots/s", t, np.sin(t))


def test_exception_leaves_no_file(tmp_path):
    final = tmp_path / "out" / "failed.rrd"
    with pytest.raises(RuntimeError, match="diverged"):
        with open_recording(final, "failed") as rec:
            _log_some(rec)
            raise RuntimeError("solver diverged")
    assert not final.exists()
    assert list(final.parent.iterdir()) == []


def test_keyboard_interrupt_leaves_no_file(tmp_path):
    final = tmp_path / "interrupted.rrd"
    with pytest.raises(KeyboardInterrupt):
        with open_recording(final, "interrupted") as rec:
            _log_some(rec)
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_partial_exists_only_while_open(tmp_path):
    final = tmp_path / "run.rrd"
    with open_recording(final, "run") as rec:
        _log_some(rec)
        partials = list(tmp_path.glob("run.rrd.*.partial"))
        assert len(partials) == 1 and not final.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["run.rrd"]
    assert verify(final)[0]


def test_failed_rerun_keeps_previous_file(tmp_path):
    final = tmp_path / "run.rrd"
    with open_recording(final, "first") as rec:
        _log_some(rec)
    with pytest.raises(ValueError):
        with open_recording(final, "second") as rec:
            raise ValueError("boom")
    assert read_recording(final).recording_name == "first"
    assert [p.name for p in tmp_path.iterdir()] == ["run.rrd"]
