"""The runtime inside a real Jupyter kernel: interrupts, re-runs, output routing, clean exit."""

from __future__ import annotations

import pytest

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
        "import threading, time\n"
        "time.sleep(1.0)\n"
        "print(rt.nodes(), rt.graph_nodes())\n"
        "print(sum(t.name == 'ros-executor' for t in threading.enumerate()))"
    )
    assert error is None, out
    assert "['/listener', '/talker'] ['/listener', '/talker']" in out
    assert out.strip().endswith("1")


def test_callback_output_goes_to_a_console_not_to_the_running_cells_stream(kernel):
    kernel.run(SETUP)
    out, error = kernel.run(PRINTER)
    assert error is None, out
    assert out == ""  # the console shows nothing until the node writes something
    out, error = kernel.run("import time; time.sleep(1.0); print('other cell done')")
    assert error is None
    assert kernel.cell_streams == "other cell done\n"  # the ticks are not printed into the cell
    ticks = consoles_in_last_cell(kernel, "/printer")
    assert len(ticks) == 1, kernel.displays  # one console of the printer for this cell, updated in place
    assert "tick from the printer" in ticks[0]["text/plain"]
    assert "tick from the printer" in ticks[0]["text/html"]
    out, _ = kernel.run("print(rt._router.console_for('printer').text())")
    assert "tick from the printer" in out
    assert "log from the printer" in out and "[INFO]" in out


GREETER = """
import time

from course_helpers import get_runtime
from rclpy.node import Node
from std_srvs.srv import Trigger

rt = get_runtime()


class Greeter(Node):
    def __init__(self):
        super().__init__('greeter')
        self.service = self.create_service(Trigger, 'greet', self.on_greet)
        self.get_logger().info('up and ready')

    def on_greet(self, request, response):
        self.get_logger().info('asked to greet')
        print('hello from the callback')
        response.success = True
        return response


greeter = rt.add(Greeter)
client = rt.node('greet_caller').create_client(Trigger, 'greet')
assert client.wait_for_service(timeout_sec=5.0)
"""
GREET = """
answer = client.call(Trigger.Request(), timeout_sec=5.0)
time.sleep(0.5)  # consoles refresh meanwhile
print('answered:', answer.success)
answer.success
"""


def consoles_in_last_cell(kernel, node: str) -> list[dict]:
    """The latest data of each console of ``node`` that the last cell created."""
    return [kernel.displays[i] for i in kernel.cell_display_ids
            if f"data-console='{node}'" in kernel.displays[i].get("text/html", "")]


def test_each_console_line_shows_under_the_cell_that_caused_it(kernel):
    """A node added in one cell and asked in another: each cell shows its own lines, once."""
    out, error = kernel.run(GREETER)
    assert error is None, out
    [added] = kernel.cell_display_ids[:1]
    asked = []
    for _ in range(2):  # the asking cell, run and re-run
        out, error = kernel.run(GREET)
        assert error is None and kernel.cell_streams == "answered: True\n", out
        [console] = consoles_in_last_cell(kernel, "/greeter")
        # after the cell's own outputs, wherever the refreshes fell: nbval compares their order
        assert [kind for kind, _ in kernel.cell_outputs] == ["stream", "execute_result", "display_data"]
        asked.append(console)
        for text in (console["text/plain"], console["text/html"]):
            assert text.count("asked to greet") == 1 and text.count("hello from the callback") == 1, text
            assert "up and ready" not in text
    assert asked[0] is not asked[1]  # the re-run showed its line in a display of its own
    assert "asked to greet" in asked[0]["text/plain"]  # ...and left the first run's display as it was
    creation = kernel.displays[added]["text/plain"]
    assert "up and ready" in creation and "asked to greet" not in creation, creation
    assert "hello from the callback" not in creation

    # A line written after a cell has finished goes under that cell (where JupyterLab shows it late).
    out, error = kernel.run("import threading\n"
                            "threading.Timer(0.5, client.call_async, [Trigger.Request()]).start()")
    assert error is None and kernel.cell_display_ids == [], out
    last = kernel.cell_msg_id
    kernel.client.kernel_info()  # a request that is no cell (JupyterLab sends such) comes in between
    kernel.listen(2.0)  # the kernel is idle when the service logs
    [late] = [i for i, cell in kernel.display_cells.items() if cell == last]
    assert "asked to greet" in kernel.displays[late]["text/plain"]
    out, error = kernel.run("print('next')")
    assert error is None and out == "next\n"  # the next cell shows nothing of it
