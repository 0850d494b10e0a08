"""workbench.core.forking: a function run in a forked child, with the parent's heap frozen for the
child's garbage collector, and the collector paused around the imports a process forks with."""

from __future__ import annotations

import gc
import os

import pytest

from workbench.core.forking import CAN_FORK, fork_call, gc_paused

needs_fork = pytest.mark.skipif(not CAN_FORK, reason="this platform does not fork")


def _child_output(fn) -> tuple[int, str]:
    """Run ``fn`` (which prints) through fork_call with stdout to a pipe; (exit code, what it printed)."""
    r, w = os.pipe()
    pid = fork_call(fn, stdout_fd=w, close_fds=(r,))
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
def test_fork_call_exits_1_when_fn_raises():
    def fn() -> int:
        raise RuntimeError("boom")

    code, _ = _child_output(fn)
    assert code == 1


@needs_fork
def test_objects_held_before_the_fork_are_frozen_in_the_child():
    # container objects the collector tracks, created before the fork: the child's collections must
    # not walk them (gc.freeze moved them to the permanent generation)
    held = [[i] for i in range(20_000)]
    try:

        def fn() -> int:
            print(gc.get_freeze_count())
            return 0

        code, text = _child_output(fn)
        assert code == 0
        assert int(text) >= len(held)
    finally:
        gc.unfreeze()  # give this test process's objects back to its collector


def test_gc_paused_turns_the_collector_off_inside_and_restores_it():
    was = gc.isenabled()
    gc.enable()
    try:
        with gc_paused():
            assert not gc.isenabled()
        assert gc.isenabled()
        gc.disable()
        with gc_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()  # it was off before: stays off
        with pytest.raises(ValueError), gc_paused():
            raise ValueError
        assert not gc.isenabled()
    finally:
        (gc.enable if was else gc.disable)()
