"""Node logs for the consoles: ``/rosout`` read on a hidden node, in a thread of its own.

Inside a kernel every node's log lines reach the consoles through ``/rosout``. Spinning
that subscription in the runtime's executor would put one more node into every wait and
cost about a tenth of the message throughput; here the reader's thread sleeps in rcl's
wait (with the GIL released) until a log line arrives.

A line reaches the reader a little after the node logged it. So that a cell's consoles are
complete when the cell ends, :meth:`RosoutReader.sync` sends a marker of its own on ``/rosout``
and waits until the reader has it: the lines logged before it in this process came first.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, QoSReliabilityPolicy

from course_helpers.core.executors import SpinThread
from course_helpers.core.waiting import poll_until

LOG_NODE = "_course_logs"  # hidden (leading underscore), like ros2cli's daemon nodes
SYNC_MARK = "console sync "  # a marker's text, followed by its number; never shown in a console
SYNC_TIMEOUT_S = 2.0  # a marker travels within the process in about a millisecond


class RosoutReader:
    """Calls ``on_log(entry)`` for every ``rcl_interfaces/msg/Log`` on ``/rosout``."""

    def __init__(self, context, on_log: Callable, on_error: Callable):
        from rcl_interfaces.msg import Log

        self._on_log = on_log
        self._sent = itertools.count(1)
        self._seen = 0  # the number of the last marker the reader has had
        self.node = Node(LOG_NODE, context=context, enable_rosout=False, start_parameter_services=False)
        qos = QoSProfile(depth=100, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.VOLATILE)
        self.node.create_subscription(Log, "/rosout", self._on_entry, qos)
        self._marker = self.node.create_publisher(Log, "/rosout", qos)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.spinner = SpinThread(self.executor, "ros-logs", on_error).start()

    def sync(self, timeout: float = SYNC_TIMEOUT_S) -> bool:
        """Return once the lines logged so far in this process have reached ``on_log``.

        True when the marker came through; False if it did not within ``timeout`` (the reader's
        thread has ended, or the machine is very busy).
        """
        from rcl_interfaces.msg import Log

        number = next(self._sent)
        self._marker.publish(Log(stamp=self.node.get_clock().now().to_msg(), level=Log.DEBUG,
                                 name=LOG_NODE, msg=f"{SYNC_MARK}{number}"))
        return poll_until(lambda: self._seen >= number or not self.spinner.alive, timeout,
                          period=0.001) and self._seen >= number

    def _on_entry(self, entry) -> None:
        if entry.name == LOG_NODE and entry.msg.startswith(SYNC_MARK):
            self._seen = max(self._seen, int(entry.msg[len(SYNC_MARK):]))
        else:
            self._on_log(entry)

    def stop(self) -> None:
        """End the thread, then destroy the node (before the context shuts down)."""
        self.spinner.stop()
        try:
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
        except Exception:  # the context was shut down from outside: nothing left to free
            pass


def log_to_consoles(router) -> Callable:
    """An ``on_log`` for :class:`RosoutReader` that writes each entry, as one line, to its node's console."""
    from course_helpers.core.console import format_log_line

    def on_log(entry) -> None:
        stamp = entry.stamp.sec + entry.stamp.nanosec * 1e-9
        router.write_log(entry.name, format_log_line(entry.level, entry.name, entry.msg, stamp))

    return on_log
