"""Publishers that chapter 08a runs in child processes.

A child process makes samples cross a real transport, and can be killed like a crashed program.
``rt.spawn`` needs a class defined in a module, so these live here; the notebook prints each
one's source before it runs it, and their QoS profiles are written out in the constructors, as
a student would write them in a package.
"""

from __future__ import annotations

import time

from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import LivelinessPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32, String, UInt8MultiArray

from course_helpers.core.channel import report
from course_helpers.core.qos_dict import qos_from_dict

MATCH_SETTLE_S = 0.3  # s; after its subscriptions matched, the publisher waits for the reverse match


class StreamPublisher(Node):
    """Sends the same ``count`` numbered messages of ``size`` bytes at ``rate_hz`` on two topics,
    ``stream_best_effort`` and ``stream_reliable``, once both have a subscription.

    The message number travels in ``layout.data_offset``. When all are sent it reports ``sent``
    (``report`` sends a result to the kernel) and stays up, so that the reliable writer can
    finish resending.
    """

    def __init__(self, size: int = 500_000, rate_hz: float = 60.0, count: int = 90):
        super().__init__("stream_publisher")
        # each writer keeps all `count` messages, so the reliable one can resend any of them
        best_effort = QoSProfile(depth=count, reliability=ReliabilityPolicy.BEST_EFFORT)
        reliable = QoSProfile(depth=count, reliability=ReliabilityPolicy.RELIABLE)
        self.best_effort = self.create_publisher(UInt8MultiArray, "stream_best_effort", best_effort)
        self.reliable = self.create_publisher(UInt8MultiArray, "stream_reliable", reliable)
        self.message = UInt8MultiArray(data=bytes(size))
        self.count, self.sent = count, 0
        self.matched_at: float | None = None  # time.monotonic() when both topics had a subscription
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # period in seconds

    def tick(self) -> None:
        if self.sent >= self.count:
            return
        if self.matched_at is None:
            if self.best_effort.get_subscription_count() and self.reliable.get_subscription_count():
                self.matched_at = time.monotonic()
            return
        if time.monotonic() - self.matched_at < MATCH_SETTLE_S:
            return
        self.message.layout.data_offset = self.sent  # the message number
        self.best_effort.publish(self.message)
        self.reliable.publish(self.message)
        self.sent += 1
        if self.sent == self.count:
            report("sent", count=self.sent)


class AliveTalker(Node):
    """Publishes 'still here' on ``alive`` every 0.1 s with AUTOMATIC liveliness and a lease of
    ``lease_s``: its participant asserts liveliness for it as long as the process runs."""

    def __init__(self, lease_s: float = 1.0):
        super().__init__("alive_talker")
        profile = QoSProfile(depth=10, liveliness=LivelinessPolicy.AUTOMATIC,
                             liveliness_lease_duration=Duration(seconds=lease_s))
        self.publisher = self.create_publisher(String, "alive", profile)
        self.timer = self.create_timer(0.1, self.tick)  # period in seconds

    def tick(self) -> None:
        self.publisher.publish(String(data="still here"))


class LivelinessTalker(Node):
    """One node, two publishers with lease ``lease_s``, and a quiet spell.

    Publishes on ``qos_automatic`` (AUTOMATIC) and ``qos_manual_by_topic`` (MANUAL_BY_TOPIC) every
    ``period_s`` from the moment both are matched, except from ``quiet_from`` to ``quiet_until``
    seconds after that. It reports ``start`` (with its lease and quiet spell) when both matched, and
    each liveliness-lost event of the manual publisher as ``lost`` (``report`` sends a result to the
    kernel).
    """

    def __init__(self, lease_s: float = 0.5, period_s: float = 0.1, quiet_from: float = 1.0,
                 quiet_until: float = 2.5):
        super().__init__("liveliness_talker")
        lease = Duration(seconds=lease_s)
        automatic = QoSProfile(depth=10, liveliness=LivelinessPolicy.AUTOMATIC,
                               liveliness_lease_duration=lease)
        manual = QoSProfile(depth=10, liveliness=LivelinessPolicy.MANUAL_BY_TOPIC,
                            liveliness_lease_duration=lease)
        self.automatic = self.create_publisher(String, "qos_automatic", automatic)
        self.manual = self.create_publisher(
            String, "qos_manual_by_topic", manual,
            event_callbacks=PublisherEventCallbacks(liveliness=self.on_liveliness_lost))
        self.lease_s, self.quiet = lease_s, (quiet_from, quiet_until)
        self.started_at: float | None = None  # time.monotonic() when both topics were matched
        self.timer = self.create_timer(period_s, self.tick)  # period in seconds

    def on_liveliness_lost(self, status) -> None:
        report("lost", total_count=status.total_count)

    def tick(self) -> None:
        now = time.monotonic()
        if self.started_at is None:
            if self.automatic.get_subscription_count() and self.manual.get_subscription_count():
                self.started_at = now
                report("start", lease_s=self.lease_s, quiet_from=self.quiet[0], quiet_until=self.quiet[1])
            return
        if not self.quiet[0] <= now - self.started_at < self.quiet[1]:
            for publisher in (self.automatic, self.manual):
                publisher.publish(String(data="still here"))  # publishing asserts liveliness


class IntTalker(Node):
    """Publishes the Int32 ``value`` at ``rate_hz``, like ``ros2 topic pub /chatter std_msgs/msg/Int32
    "data: 66"``; its QoS is given as a dict, like the ``--qos-*`` flags of ``ros2 topic pub``."""

    def __init__(self, name: str = "int_talker", topic: str = "chatter", value: int = 66,
                 qos: dict | None = None, rate_hz: float = 2.0):
        super().__init__(name)
        self.message = Int32(data=value)
        self.publisher = self.create_publisher(Int32, topic, qos_from_dict(qos or {}))
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # period in seconds

    def tick(self) -> None:
        self.publisher.publish(self.message)
