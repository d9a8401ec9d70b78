"""The runtime in a real Jupyter kernel: it heals after an outside shutdown, and %ros2 starts warm."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from course_helpers.core.domains import reserve_domain

from .conftest import REPO
from .kernel_session import KernelSession

NOTEBOOKS = os.path.join(REPO, "notebooks")

COURSE_CELL = """
import threading
from course_helpers import get_runtime
from course_helpers.nodes import Listener, Talker
rt = get_runtime()
rt.add(Talker, console=False)
rt.add(Listener, console=False)
"""

STATE_CELL = """
import collections
names = sorted(t.name for t in threading.enumerate() if t.is_alive())
counts = collections.Counter(names)
print('nodes', rt.nodes())
print('executor threads', counts['ros-executor'], 'log threads', counts['ros-logs'],
      'console threads', counts['course-console'])
print('heard', rt.wait_until(lambda: len(rt.get('/listener').heard) >= 2, 10, 'the talker'))
"""


@pytest.fixture
def kernel():
    session = KernelSession(cwd=NOTEBOOKS)
    yield session
    session.shutdown()


def _assert_healthy(out: str) -> None:
    assert "nodes ['/listener', '/talker']" in out, out
    assert "executor threads 1 log threads 1 console threads 1" in out, out
    assert "heard True" in out, out


CHILD_CELL = """
from course_helpers.nodes import Relay
rt.spawn('relay', Relay, wait_for='/relay')
"""


def _healed_line(out: str) -> str:
    healed = [line for line in out.splitlines() if line.startswith("[course]")]
    assert len(healed) == 1, out
    return healed[0]


def test_an_interrupt_with_rclpys_handler_asked_for_is_healed_naming_the_cells(kernel):
    out, error = kernel.run(COURSE_CELL)
    assert error is None, out
    nodes_cell = kernel.execution_count
    out, error = kernel.run(CHILD_CELL)
    assert error is None, out
    child_cell = kernel.execution_count
    # A student who asks for rclpy's signal handler gets it, and its interrupt shuts every context down.
    textbook = ("import rclpy\nfrom rclpy.node import Node\nfrom rclpy.signals import SignalHandlerOptions\n"
                "rclpy.init(signal_handler_options=SignalHandlerOptions.ALL)\n"
                "node = Node('textbook_node')\nrclpy.spin(node)\n")
    out, error = kernel.run(textbook, timeout=60, interrupt_after=3.0)
    assert error is not None, "the interrupt should end the textbook cell"
    out, error = kernel.run(COURSE_CELL + STATE_CELL, timeout=60)
    assert error is None, out
    healed = _healed_line(out)
    assert "shut down from outside" in healed and "signal handler has been removed" in healed, healed
    assert (f'run again In [{nodes_cell}] "import threading" (/talker, /listener) and In [{child_cell}] '
            '"from course_helpers.nodes import Relay" (child process relay).') in healed, healed
    _assert_healthy(out)
    # The interrupt button is harmless again: interrupting a course cell leaves ROS running.
    out, error = kernel.run("import time\ntime.sleep(30)", timeout=60, interrupt_after=1.0)
    assert error == "KeyboardInterrupt"
    out, error = kernel.run(STATE_CELL, timeout=60)
    assert error is None and "[course]" not in out, out
    _assert_healthy(out)


def test_context_shut_down_by_hand_is_healed_without_stale_nodes(kernel):
    out, error = kernel.run(COURSE_CELL)
    assert error is None, out
    nodes_cell = kernel.execution_count
    out, error = kernel.run("import rclpy\nrclpy.shutdown(context=rt.context)\nprint(rt.running)")
    assert error is None and "False" in out, out
    shutdown_out = out
    out, error = kernel.run(COURSE_CELL + STATE_CELL, timeout=60)
    assert error is None, out
    # The runtime's threads end quietly: a shutdown is no error of the executor or the /rosout reader.
    assert "Traceback" not in shutdown_out + out and "error" not in shutdown_out + out, shutdown_out + out
    healed = _healed_line(out)
    assert healed.startswith("[course] ROS was shut down from outside"), healed
    assert healed.endswith(f'run again In [{nodes_cell}] "import threading" (/talker, /listener).'), healed
    _assert_healthy(out)
    out, error = kernel.run("print('restarts', rt.restarts)")
    assert "restarts 1" in out


PLAIN_TALKER = textwrap.dedent("""
    import rclpy
    from rclpy.node import Node
    from std_msgs.msg import String

    class WarmTalker(Node):
        def __init__(self):
            super().__init__('warm_talker')
            self.publisher = self.create_publisher(String, 'warm_chatter', 10)
            self.timer = self.create_timer(0.1, self.tick)  # seconds

        def tick(self):
            self.publisher.publish(String(data='warm'))

    rclpy.init()
    node = WarmTalker()
    print('up', flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
""")


def test_first_ros2_command_sees_a_node_started_before_the_kernel():
    domain = reserve_domain()
    env = {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    talker = subprocess.Popen([sys.executable, "-c", PLAIN_TALKER], env={**os.environ, **env},
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    session = None
    try:
        assert talker.stdout.readline().strip() == "up"
        session = KernelSession(cwd=NOTEBOOKS, env=env)
        out, error = session.run("from course_helpers import get_runtime\nrt = get_runtime()\n"
                                 "%ros2 node list\n%ros2 topic echo /warm_chatter --once")
        assert error is None, out
        assert "/warm_talker" in out.splitlines(), out
        assert "data: warm" in out, out
    finally:
        if session is not None:
            session.shutdown()
        talker.terminate()
        talker.wait(timeout=10)
