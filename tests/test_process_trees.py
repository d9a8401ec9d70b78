"""Stopping a child stops its whole process tree: timeouts, stops and a killed kernel.

Real processes throughout: shells whose background children hold the output pipe, a kernel-like
Python process that is SIGKILLed, and psutil to see what is left.
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import textwrap
import threading

import psutil
import pytest

from course_helpers import CourseError
from course_helpers.core import processes
from course_helpers.core.child import DEADLINE_S
from course_helpers.core.waiting import poll_until, wait_until

from .conftest import REPO

LONG_S = 300  # s; how long the grandchildren would live if nobody stopped them


def _identity(pid: int) -> tuple[int, float] | None:
    """(pid, start time) of a running process, or None if it is gone (a zombie counts as gone)."""
    try:
        proc = psutil.Process(pid)
        if proc.status() == psutil.STATUS_ZOMBIE:
            return None
        return pid, proc.create_time()
    except psutil.NoSuchProcess:
        return None


def _alive(identities) -> list[tuple[int, float]]:
    """The processes of ``identities`` still running (the same pid and start time)."""
    return [ident for ident in identities if _identity(ident[0]) == ident]


def _kill(identities) -> None:
    """Clean-up after a failed test: SIGKILL what is still running."""
    for pid, _started in _alive(identities):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_run_returns_at_its_timeout_while_a_grandchild_holds_the_output_and_leaves_nothing():
    """A build step's compiler keeps the pipe open after the step itself is killed (issue 23)."""
    pids: list[int] = []
    outcome: list[BaseException] = []
    script = f"sleep {LONG_S} & echo $!; sleep {LONG_S} & echo $!; wait"

    def build_step() -> None:
        try:
            processes.run(["sh", "-c", script], timeout=1.0, on_line=lambda line: pids.append(int(line)))
        except BaseException as exc:  # handed to the test thread
            outcome.append(exc)

    worker = threading.Thread(target=build_step, daemon=True)
    worker.start()
    wait_until(lambda: len(pids) == 2, 30, "the two grandchildren to print their process ids")
    grandchildren = [ident for ident in map(_identity, pids) if ident is not None]
    try:
        worker.join(30)  # far past the 1 s timeout, far before the grandchildren's own end
        assert not worker.is_alive(), (
            "processes.run did not return 30 s after its 1 s timeout: a grandchild holds its output")
        assert outcome and isinstance(outcome[0], CourseError), outcome
        assert "took longer than 1 s" in str(outcome[0])
        assert poll_until(lambda: not _alive(grandchildren), 5), (
            f"grandchildren still running after the timeout: {_alive(grandchildren)}")
    finally:
        _kill(grandchildren)


def test_stopping_a_program_stops_its_children_too():
    child = processes.start("tree", processes.program_argv("sh", "-c", f"sleep {LONG_S} & sleep {LONG_S}"),
                            group="test-tree", channel=False)
    tree: list[tuple[int, float]] = []
    try:
        def sleeps() -> list[tuple[int, float]]:
            found = [p for p in psutil.Process(child.pid).children(recursive=True) if p.name() == "sleep"]
            return [(p.pid, p.create_time()) for p in found]

        wait_until(lambda: len(sleeps()) == 2, 30, "the program's two children")
        tree = sleeps()
        code = child.stop()
        assert code == -signal.SIGTERM, f"the shell should end by the stop signal, got {code}"
        assert not _alive(tree), f"still running after stop: {_alive(tree)}"
    finally:
        _kill(tree)


KERNEL = f"""
import time
from course_helpers.core import processes
processes.start('program', processes.program_argv('sh', '-c', 'sleep {LONG_S} & sleep {LONG_S} & wait'),
                group='test', channel=False)
processes.start('runner', processes.python_target_argv('tests.helpers_children:start_program_tree'),
                group='test')
print('started', flush=True)
time.sleep({LONG_S})
"""


@pytest.mark.timeout(120)
def test_a_killed_kernels_childrens_grandchildren_go_too():
    """SIGKILL, so the kernel runs no clean-up: its children's descendants must still end.

    The kernel runs a program (a shell with two background sleeps) and a Python target that starts
    such a program itself; four sleeps in all, two and three levels below the kernel.
    """
    kernel = subprocess.Popen([sys.executable, "-c", textwrap.dedent(KERNEL)], cwd=REPO,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    tree: list[tuple[int, float]] = []
    try:
        assert kernel.stdout.readline().strip() == "started"

        def sleeps() -> list[tuple[int, float]]:
            found = [p for p in psutil.Process(kernel.pid).children(recursive=True) if p.name() == "sleep"]
            return [(p.pid, p.create_time()) for p in found]

        wait_until(lambda: len(sleeps()) == 4, 60, "four sleeps below the kernel")
        tree = [(p.pid, p.create_time()) for p in psutil.Process(kernel.pid).children(recursive=True)]
        kernel.kill()
        kernel.wait(10)
        assert poll_until(lambda: not _alive(tree), 30), (
            f"processes left after the kernel was killed: "
            f"{[' '.join(psutil.Process(pid).cmdline()) for pid, _ in _alive(tree)]}")
    finally:
        if kernel.poll() is None:
            kernel.kill()
            kernel.wait(10)
        _kill(tree)


def _signal_main_thread(pid: int, sig: int) -> None:
    """``sig`` to the main thread of process ``pid`` (glibc's tgkill), the thread where Python runs signal
    handlers; ``os.kill`` lets Linux pick any thread of the process."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.tgkill(pid, pid, sig) != 0:
        raise OSError(ctypes.get_errno(), f"tgkill({pid}, {sig}) failed")


@pytest.mark.timeout(120)
def test_a_child_whose_clean_up_hangs_holding_the_gil_still_ends_by_its_deadline():
    """The child's clean-up blocks in C with the GIL held, so no Python thread of it runs again (its
    parent watchdog included): the deadline its stop signal armed with the operating system ends it."""
    child = processes.start("hung", processes.python_target_argv(
        "tests.helpers_children:block_holding_the_gil_when_stopped"), group="test-hung")
    try:
        child.wait_for_report("waiting", 60)
        _signal_main_thread(child.pid, signal.SIGTERM)
        # a bound for a hang: the child's own deadline is DEADLINE_S after the stop signal
        assert poll_until(lambda: not child.alive, DEADLINE_S + 15), (
            f"the child still runs {DEADLINE_S + 15:g} s after its stop signal")
        assert child.returncode == -signal.SIGALRM, f"it should end by its deadline, got {child.returncode}"
    finally:
        processes.stop(["hung"], group="test-hung")
