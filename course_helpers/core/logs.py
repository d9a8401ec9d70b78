"""Node logs for the consoles: ``/rosout`` read on a hidden node, in a thread of its own.

Inside a kernel every node's log lines reach the consoles through ``/rosout``. Spinning
that subscription in the runtime's executor would put one more node into every wait and
cost about a tenth of the message throughput; here the reader's thread sleeps in rcl's
wait (with the GIL released) until a log line arrives.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, QoSReliabilityPolicy

from course_helpers.core.executors import QuietSingleThreadedExecutor, SpinThread
from course_helpers.core.node_hook import outside_builds

LOG_NODE = "_course_logs"  # hidden (leading underscore), like ros2cli's daemon nodes


class RosoutReader:
    """Calls ``on_log(entry)`` for every ``rcl_interfaces/msg/Log`` on ``/rosout``."""

    def __init__(self, context, on_log: Callable, on_error: Callable):
        from rcl_interfaces.msg import Log

        with outside_builds():  # the runtime's own node, even when a build starts the runtime
            self.node = Node(LOG_NODE, context=context, enable_rosout=False, start_parameter_services=False)
        qos = QoSProfile(depth=100, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.VOLATILE)
        self.node.create_subscription(Log, "/rosout", on_log, qos)
        self.executor = QuietSingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.spinner = SpinThread(self.executor, "ros-logs", on_error).start()

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
