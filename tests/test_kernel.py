"""The runtime inside a real Jupyter kernel: interrupts, re-runs, output routing, clean exit."""

from __future__ import annotations

import pytest

from course_helpers.core.waiting import wait_until

from .conftest import REPO
from .kernel_session import KernelSession

SETUP = """
from course_helpers import get_runtime
from course_helpers.nodes import Talker, Listener
rt = get_runtime()
rt.add(Talker, rate_hz=100)
listener = rt.add(Listener)
rt.wait_until(lambda: len(listener.heard) > 5, 10)
"""

PRINTER = """
from rclpy.node import Node

class Printer(Node):
    def __init__(self):
        super().__init__('printer')
        self.timer = self.create_timer(0.05, self.tick)  # 20 Hz

    def tick(self):
        print('tick from the printer')
        self.get_logger().info('log from the printer')

printer = rt.add(Printer)
"""


@pytest.fixture
def kernel():
    session = KernelSession(cwd=REPO)
    yield session
    try:
        session.shutdown()
    except Exception:
        pass


def test_interrupt_does_not_stop_ros_and_shutdown_is_clean(kernel):
    out, error = kernel.run(SETUP)
    assert error is None, out
    _, error = kernel.run("rt.wait_until(lambda: False, 60, 'forever')", interrupt_after=1.5)
    assert error == "KeyboardInterrupt"
    out, error = kernel.run(
        "n = len(listener.heard)\n"
        "rt.wait_until(lambda: len(listener.heard) > n + 20, 5)\n"
        "print('delivering', rt.context.ok())"
    )
    assert error is None and "delivering True" in out
    code, stderr = kernel.shutdown()
    assert "terminate called" not in stderr, stderr
    assert code == 0, stderr


def test_rerunning_cells_leaves_no_duplicates(kernel):
    for _ in range(3):
        out, error = kernel.run(SETUP)
        assert error is None, out
    out, error = kernel.run(
        "import threading\n"
        "rt.wait_until(lambda: len(rt.graph_nodes()) >= 2, 10, 'the graph to list the nodes')\n"
        "print(rt.nodes(), rt.graph_nodes())\n"
        "print(sum(t.name == 'ros-executor' for t in threading.enumerate()))"
    )
    assert error is None, out
    assert "['/listener', '/talker'] ['/listener', '/talker']" in out
    assert out.strip().endswith("1")


def test_callback_output_goes_to_the_node_console_not_the_running_cell(kernel):
    kernel.run(SETUP)
    out, error = kernel.run(PRINTER)
    assert error is None, out
    assert out == ""  # the console shows nothing until the node writes something
    # No window: this cell runs until three more ticks reached the node's console, so a tick routed to the
    # running cell instead would show in its output.
    out, error = kernel.run(
        "ticks = lambda: rt._router.console_for('printer').text().count('tick from the printer')\n"
        "seen = ticks()\n"
        "rt.wait_until(lambda: ticks() >= seen + 3, 10, 'three ticks in the console of /printer')\n"
        "print('other cell done')"
    )
    assert error is None
    assert out == "other cell done\n"

    def printer_consoles() -> list[dict]:
        kernel.run("pass")  # an idle cell takes the updates the kernel sent meanwhile
        return [data for data in kernel.displays.values() if "console of /printer" in data["text/plain"]]

    # The console reaches the frontend on the kernel's next refresh (every 0.2 s).
    wait_until(printer_consoles, 10, "the console of /printer to reach the frontend")
    consoles = printer_consoles()
    assert len(consoles) == 1, kernel.displays  # under the cell that added the node, updated in place
    assert "tick from the printer" in consoles[0]["text/plain"]
    assert "tick from the printer" in consoles[0]["text/html"]
    out, _ = kernel.run("print(rt._router.console_for('printer').text())")
    assert "tick from the printer" in out
    assert "log from the printer" in out and "[INFO]" in out


def test_a_cell_that_ends_with_a_claim_shows_its_line_once(kernel):
    out, error = kernel.run("from course_helpers import claim\nclaim('one and one make two', 1 + 1 == 2)")
    assert error is None and out.count("one and one make two") == 1, out
    out, error = kernel.run("from course_helpers.core.verdict import judge\njudge('never printed', True)")
    assert error is None and out.count("never printed") == 1, out  # a verdict not yet printed shows its line
