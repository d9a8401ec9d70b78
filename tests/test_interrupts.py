"""The interrupt button in a course kernel stops the cell and never ROS (issue 22, item 2).

A student pastes the textbook's ``rclpy.init(); node = Node(...); rclpy.spin(node)`` into a course
notebook and presses Interrupt. rclpy's default SIGINT handler would shut down every context of
the process, the course runtime's too; in a course kernel ``rclpy.init()`` installs none, and the
interrupt still ends ``rclpy.spin``.
"""

from __future__ import annotations

import re

import psutil
import pytest

from .conftest import REPO
from .kernel_session import KernelSession

# A chapter's set-up: two nodes in the kernel and two child processes, with data flowing through
# one of the children (talker -> relay child -> listener).
CHAPTER = """
from course_helpers import get_runtime
from course_helpers.nodes import Listener, Relay, Talker
rt = get_runtime()
rt.add(Talker, rate_hz=20, console=False)
listener = rt.add(Listener, topic='chatter_relayed', console=False)
rt.spawn('relay', Relay, wait_for='/relay')
rt.spawn('sensor', Talker, params={'name': 'temperature', 'namespace': 'sensor', 'topic': 'temperature'},
         wait_for='/sensor/temperature')
rt.wait_until(lambda: listener.heard, 10, 'a relayed message')
"""

TEXTBOOK = """
import rclpy
from rclpy.node import Node

rclpy.init()
node = Node('textbook_node')
rclpy.spin(node)
"""

STATE = """
print('nodes', rt.nodes())
print('children', sorted((name, child.pid, child.alive) for name, child in rt.children().items()))
"""

NEXT_CELL = """
heard = len(listener.heard)
rt.wait_until(lambda: len(listener.heard) > heard + 5, 10, 'more relayed messages')
rt.wait_for_node('/sensor/temperature', timeout=5)
rt.wait_for_node('/textbook_node', timeout=5)
print('textbook node', node.get_fully_qualified_name(), node.context.ok())
print('course context', rt.context.ok(), 'restarts', rt.restarts)
"""

ANSI = re.compile(r"\x1b\[[0-9;]*m")


@pytest.fixture
def kernel():
    session = KernelSession(cwd=REPO)
    yield session
    session.shutdown()


def _plain(lines: list[str]) -> list[str]:
    """A traceback's lines as a student reads them (colour codes removed, split at newlines)."""
    return [line for text in lines for line in ANSI.sub("", text).splitlines() if line.strip()]


def test_textbook_spin_then_interrupt_keeps_every_node_and_child(kernel):
    out, error = kernel.run(CHAPTER)
    assert error is None, out
    before, _ = kernel.run(STATE)
    assert "nodes ['/listener', '/talker']" in before, before
    assert "('relay'," in before and "('sensor'," in before, before
    pids = [int(pid) for pid in re.findall(r"'(?:relay|sensor)', (\d+), True", before)]
    assert len(pids) == 2, before

    out, error = kernel.run(TEXTBOOK, timeout=30, interrupt_after=3.0)  # a TimeoutError if it ignores it
    assert error == "KeyboardInterrupt", (error, out, kernel.traceback)
    shown = _plain(kernel.traceback)
    assert len(shown) == 1 and shown[0].startswith("KeyboardInterrupt"), kernel.traceback
    assert out.strip() == "", f"the interrupted cell printed more than its one line:\n{out}"

    after, error = kernel.run(STATE)
    assert error is None and after == before, f"before:\n{before}\nafter:\n{after}"
    assert all(psutil.pid_exists(pid) for pid in pids)
    out, error = kernel.run(NEXT_CELL, timeout=60)
    assert error is None, (out, kernel.traceback)
    assert "[course]" not in out, out
    assert "textbook node /textbook_node True" in out, out
    assert "course context True restarts 0" in out, out
    # The textbook cell runs again: rclpy.init() starts the default context afresh instead of failing,
    # the old node leaves the graph even while its object lives on, and the interrupt is one line again.
    kernel.run("old_node = node")
    out, error = kernel.run(TEXTBOOK, timeout=30, interrupt_after=3.0)
    assert error == "KeyboardInterrupt", (error, out, kernel.traceback)
    assert out.startswith("[course] rclpy.init() again: the default context was running;"), out
    assert len(_plain(kernel.traceback)) == 1, kernel.traceback
    one_node = ("rt.wait_until(lambda: [name for name, _ in rt.graph.get_node_names_and_namespaces()]"
                ".count('textbook_node') == 1, 10, 'the old /textbook_node to leave the graph')")
    out, error = kernel.run(NEXT_CELL + one_node, timeout=60)
    assert error is None and "course context True restarts 0" in out, (out, kernel.traceback)


def test_explicit_signal_handler_options_are_honoured(kernel):
    out, error = kernel.run(
        "from course_helpers import get_runtime\nrt = get_runtime()\n"
        "import rclpy\nfrom rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options\n"
        "rclpy.init()\nprint('default', get_current_signal_handlers_options())\n"
        "rclpy.shutdown()\n"
        "rclpy.init(signal_handler_options=SignalHandlerOptions.SIGINT)\n"
        "rt = get_runtime()\n"
        "print('explicit', get_current_signal_handlers_options())\n"
        "rclpy.shutdown()\n")
    assert error is None, out
    assert "default SignalHandlerOptions.NO" in out, out
    assert "explicit SignalHandlerOptions.SIGINT" in out, out  # getting the runtime again keeps it


BROKEN_CONSOLES = """
import time
from course_helpers import get_runtime
from course_helpers.nodes import Talker
rt = get_runtime()

def broken(logger_name, line):
    raise RuntimeError('the consoles are gone')

rt._router.write_log = broken  # breaks what the /rosout reader calls for each log line
talker = rt.add(Talker, console=False)
talker.get_logger().info('a line for the /rosout reader')
rt.wait_until(lambda: rt.errors, 10, 'the /rosout reader to fail')
# A window, on purpose: the line comes from the /rosout reader's thread, and that path is the one this
# cell broke, so no sentinel can follow it. A late second line would be missed, never counted wrongly.
time.sleep(0.5)
"""


def test_an_internal_error_shows_one_line_and_keeps_its_traceback_in_a_log(kernel):
    out, error = kernel.run(BROKEN_CONSOLES)
    assert error is None, (out, kernel.traceback)
    assert "Traceback" not in out, out
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == 1, out
    assert lines[0].startswith("[course] internal error in the /rosout reader: RuntimeError: the consoles "
                               "are gone (traceback in "), lines
    log_path = lines[0].split("(traceback in ")[1].rstrip(")")
    out, error = kernel.run(f"print(open({log_path!r}).read())\nprint('running', rt.running)")
    assert error is None and "Traceback (most recent call last)" in out and "in broken" in out, out
    assert "running True" in out, out
