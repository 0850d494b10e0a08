"""workbench.core.forking: a function run in a forked child, with the inherited heap frozen for the
child's garbage collector, and the collector paused around the imports a process forks with."""

from __future__ import annotations

import gc
import os

import pytest

from workbench.core.forking import CAN_FORK, fork_call, gc_paused

needs_fork = pytest.mark.skipif(not CAN_FORK, reason="this platform does not fork")


def _child_output(fn, stream: str = "stdout") -> tuple[int, str]:
    """Run ``fn`` through fork_call with its stdout (or stderr) to a pipe; (exit code, what it wrote)."""
    r, w = os.pipe()
    pid = fork_call(fn, close_fds=(r,), **{f"{stream}_fd": w})
    os.close(w)
    with os.fdopen(r) as f:
        text = f.read()
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), text


@needs_fork
def test_fork_call_runs_fn_in_child_with_its_exit_code_and_stdout():
    parent = os.getpid()

    def fn() -> int:
        print(f"child {os.getpid() != parent}")
        return 7

    code, text = _child_output(fn)
    assert code == 7
    assert text.strip() == "child True"


@needs_fork
def test_fork_call_exits_1_with_the_traceback_when_fn_raises():
    def fn() -> int:
        raise RuntimeError("boom")

    code, err = _child_output(fn, "stderr")
    assert code == 1
    assert "RuntimeError: boom" in err


@needs_fork
def test_the_child_freezes_what_it_inherited_and_the_caller_stays_as_it_was():
    gc.unfreeze()
    assert gc.get_freeze_count() == 0
    held = [[i] for i in range(1000)]  # tracked containers created before the fork
    assert any(o is held for o in gc.get_objects())

    def fn() -> int:
        # frozen objects are in no generation that gc.get_objects() lists
        print(gc.get_freeze_count() > 0, any(o is held for o in gc.get_objects()))
        return 0

    code, text = _child_output(fn)
    assert code == 0
    assert text.split() == ["True", "False"]
    assert gc.get_freeze_count() == 0  # the caller: nothing frozen
    assert any(o is held for o in gc.get_objects())


def test_gc_paused_turns_the_collector_off_inside_and_restores_it():
    was = gc.isenabled()
    gc.enable()
    try:
        with gc_paused():
            assert not gc.isenabled()
        assert gc.isenabled()
        with pytest.raises(ValueError), gc_paused():
            raise ValueError
        assert gc.isenabled()  # on again after an exception too
        gc.disable()
        with gc_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()  # it was off before: stays off
    finally:
        (gc.enable if was else gc.disable)()
