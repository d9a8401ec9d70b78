"""A node callback's error reads as the student's own error, once, in a real kernel.

Chapter 10 lets a deliberately broken node crash on every scan. The console shows the error and
the cell line that raised it, not rclpy's executor frames, and a repeat becomes a count instead of
a new block of text.
"""

from __future__ import annotations

import pytest

from course_helpers.core.callback_errors import RepeatCounter, describe

from .conftest import REPO
from .kernel_session import KernelSession

BROKEN_TIMER = """
from rclpy.node import Node
from course_helpers import get_runtime
rt = get_runtime()

class Divider(Node):
    def __init__(self):
        super().__init__('divider')
        self.calls = 0
        self.timer = self.create_timer(0.005, self.on_tick)

    def on_tick(self):
        self.calls += 1
        if self.calls <= 12:
            print(1 / 0)

divider = rt.add(Divider, console=False)
rt.wait_until(lambda: divider.calls > 12, 20, 'twelve failed ticks')
rt.remove(divider)
"""


@pytest.fixture
def kernel():
    session = KernelSession(cwd=REPO)
    yield session
    session.shutdown()


def test_a_callback_error_names_the_cells_line_once_then_counts_repeats(kernel):
    out, error = kernel.run(BROKEN_TIMER)
    assert error is None, (out, kernel.traceback)
    assert "Traceback" not in out and "rclpy" not in out, out
    first = "[callback error in /divider] ZeroDivisionError: division by zero\n" \
            "  at on_tick (a cell, line 14): print(1 / 0)"
    assert out.count(first) == 1, out
    assert out.count("[callback error in /divider]") == 2, out  # the first, then the tenth
    assert "the same ZeroDivisionError again: 10 times so far" in out, out


def _raise_in(function):
    try:
        function()
    except Exception as exc:  # noqa: BLE001 - the test wants the exception object
        return exc
    raise AssertionError("nothing raised")


def test_a_cause_and_a_different_line_are_reported_on_their_own():
    def parse():
        try:
            int("x")
        except ValueError as exc:
            raise KeyError("no reading") from exc

    described = describe(_raise_in(parse))
    assert described.startswith("KeyError: 'no reading'\n"), described
    assert described.endswith("raised while handling ValueError: invalid literal for int() with base 10: 'x'")

    counter = RepeatCounter()
    assert counter.report("/a", _raise_in(parse)) is not None
    assert counter.report("/a", _raise_in(parse)) is None  # the same line again: counted, not shown
    assert counter.report("/b", _raise_in(parse)) is not None  # another node's error is its own
    assert counter.report("/a", _raise_in(lambda: 1 / 0)) is not None  # another error of /a
