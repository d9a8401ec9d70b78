"""Publishers that the QoS demos run in child processes, each given its QoS as a dict.

A child process makes samples cross a real transport, and can be killed like a crashed
program. Start one with ``rt.spawn(label, StreamPublisher, params={...})``; QoS dicts are
read by :func:`course_helpers.core.qos_dict.qos_from_dict`.
"""

from __future__ import annotations

import time

from rclpy.node import Node
from std_msgs.msg import Int32, UInt8MultiArray

from course_helpers.core.channel import report
from course_helpers.core.qos_dict import qos_from_dict
from course_helpers.nodes import Talker

MATCH_SETTLE_S = 0.3  # s; after its subscriptions matched, the publisher waits for the reverse match


class StreamPublisher(Node):
    """Publishes ``count`` numbered messages of ``size`` bytes on every topic, at ``rate_hz``.

    Args:
        name: the node name.
        topics: topic name -> QoS dict, one publisher each.
        size: bytes per message.
        rate_hz: messages per second.
        count: how many messages.

    Publishing starts :data:`MATCH_SETTLE_S` after every topic has a matched subscription. The
    message number travels in ``layout.data_offset``. When all are sent it reports ``sent`` with
    ``count``, and stays up so that a reliable writer can finish resending.
    """

    def __init__(self, name: str = "qos_stream", topics: dict | None = None, size: int = 1000,
                 rate_hz: float = 50.0, count: int = 100):
        super().__init__(name)
        self.count = count
        self.sent = 0
        self.matched_at: float | None = None
        self.message = UInt8MultiArray(data=bytes(size))
        self.publisher_list = [self.create_publisher(UInt8MultiArray, topic, qos_from_dict(qos))
                               for topic, qos in (topics or {"stream": {}}).items()]
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # period in seconds

    def tick(self) -> None:
        if self.sent >= self.count:
            return
        if self.matched_at is None:
            if all(p.get_subscription_count() > 0 for p in self.publisher_list):
                self.matched_at = time.monotonic()
            return
        if time.monotonic() - self.matched_at < MATCH_SETTLE_S:
            return
        self.message.layout.data_offset = self.sent
        for publisher in self.publisher_list:
            publisher.publish(self.message)
        self.sent += 1
        if self.sent == self.count:
            report("sent", count=self.sent)


class QosTalker(Talker):
    """A :class:`course_helpers.nodes.Talker` ('hello N' at ``rate_hz``) with its QoS given as a dict."""

    def __init__(self, name: str = "qos_talker", topic: str = "chatter", qos: dict | None = None,
                 rate_hz: float = 10.0):
        super().__init__(name=name, topic=topic, rate_hz=rate_hz, qos=qos_from_dict(qos or {}))


class IntTalker(Node):
    """Publishes the Int32 ``value`` at ``rate_hz``, like ``ros2 topic pub /chatter std_msgs/msg/Int32
    "data: 66"``; its QoS is given as a dict."""

    def __init__(self, name: str = "int_talker", topic: str = "chatter", value: int = 66,
                 qos: dict | None = None, rate_hz: float = 2.0):
        super().__init__(name)
        self.message = Int32(data=value)
        self.publisher = self.create_publisher(Int32, topic, qos_from_dict(qos or {}))
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # period in seconds

    def tick(self) -> None:
        self.publisher.publish(self.message)
