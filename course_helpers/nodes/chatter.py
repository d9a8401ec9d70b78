"""Small, idiomatic rclpy nodes the chapters reuse, in the kernel or in child processes.

Chapters 00-03 use the talker and listener; 01, 06 and 07 start them in child
processes (``rt.spawn('talker', 'course_helpers.nodes:make_talker')``). Each class
is written the way a student would write it in a package: a Node subclass, a
timer instead of a sleep loop, units in comments.
"""

from __future__ import annotations

from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import String

from course_helpers.core.channel import report


class Talker(Node):
    """Publishes 'hello N' on a topic at a fixed rate."""

    def __init__(self, name: str = "talker", topic: str = "chatter", rate_hz: float = 2.0,
                 namespace: str = "", qos: QoSProfile | int = 10):
        super().__init__(name, namespace=namespace)
        self.count = 0
        self.publisher = self.create_publisher(String, topic, qos)
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # period in seconds

    def tick(self) -> None:
        msg = String()
        msg.data = f"hello {self.count}"
        self.publisher.publish(msg)
        self.count += 1


class Listener(Node):
    """Subscribes to a String topic and keeps what it heard.

    In a child process, ``report_heard=True`` also sends each message to the kernel as
    ``report('heard', data=...)`` over the process channel.
    """

    def __init__(self, name: str = "listener", topic: str = "chatter", namespace: str = "",
                 qos: QoSProfile | int = 10, echo: bool = False, report_heard: bool = False):
        super().__init__(name, namespace=namespace)
        self.heard: list[str] = []
        self.echo = echo
        self.report_heard = report_heard
        self.subscription = self.create_subscription(String, topic, self.on_message, qos)

    def on_message(self, msg: String) -> None:
        self.heard.append(msg.data)
        if self.echo:
            self.get_logger().info(f"I heard: {msg.data}")
        if self.report_heard:
            report("heard", data=msg.data)


def make_talker(name: str = "talker", topic: str = "chatter", rate_hz: float = 2.0,
                namespace: str = "") -> Talker:
    """Child-process target: a :class:`Talker` (``rt.spawn('talker', make_talker)``)."""
    return Talker(name=name, topic=topic, rate_hz=rate_hz, namespace=namespace)


class Relay(Node):
    """Republishes every String it hears on ``source`` to ``sink``."""

    def __init__(self, name: str = "relay", source: str = "chatter", sink: str = "chatter_relayed",
                 namespace: str = ""):
        super().__init__(name, namespace=namespace)
        self.publisher = self.create_publisher(String, sink, 10)
        self.subscription = self.create_subscription(String, source, self.publisher.publish, 10)


def make_relay(name: str = "relay", source: str = "chatter", sink: str = "chatter_relayed",
               namespace: str = "") -> Relay:
    """Child-process target: a :class:`Relay`."""
    return Relay(name=name, source=source, sink=sink, namespace=namespace)
