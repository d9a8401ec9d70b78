"""A listener in a child process that tells the kernel what it hears (domains, discovery server).

``rt.spawn('far_listener', ReportingListener, params={'name': 'far_listener'}, env=...)`` starts
it; :func:`heard_lines` reads what it reported over the process channel.
"""

from __future__ import annotations

from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.core.channel import report


class ReportingListener(Node):
    """Subscribes to a String topic and reports each message as ``report('heard', data=...)``."""

    def __init__(self, name: str = "listener", topic: str = "chatter"):
        super().__init__(name)
        self.subscription = self.create_subscription(String, topic, self.on_message, 10)

    def on_message(self, msg: String) -> None:
        report("heard", data=msg.data)


def heard_lines(child) -> list[str]:
    """The texts a :class:`ReportingListener` child (a ``ChildProcess``) has heard so far, oldest first."""
    return [entry["data"] for entry in child.reports("heard")]
