"""Reliability: large messages from another process, best effort against reliable, with the
subscription's ``message_lost`` event."""

from __future__ import annotations

import time
from dataclasses import dataclass

from rclpy.event_handler import SubscriptionEventCallbacks
from std_msgs.msg import UInt8MultiArray

from course_helpers.chapters.ch08_qos.cleanup import remove_nodes
from course_helpers.chapters.ch08_qos.publishers import StreamPublisher
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import qos_from_dict
from course_helpers.core.waiting import poll_until

RESEND_WAIT_S = 5.0  # s a reliable subscription may take to get what was resent
TOPICS = {"best_effort": "qos_best_effort", "reliable": "qos_reliable"}


@dataclass
class ReliabilityResult:
    """Which numbered messages each subscription got, and the message_lost events reported."""

    sent: int
    size: int
    rate_hz: float
    received: dict[str, list[int]]  # 'best_effort' / 'reliable' -> message numbers
    lost_reported: dict[str, int]  # message_lost total_count per subscription

    def share(self, kind: str) -> float:
        """The share (0..1) of the messages that subscription ``kind`` received."""
        return len(set(self.received[kind])) / self.sent


def demo_reliability(rt, size: int = 1_000_000, rate_hz: float = 60.0, count: int = 90,
                     timeout: float = 20.0) -> ReliabilityResult:
    """A child process publishes the same numbered messages on a best-effort and a reliable topic.

    Args:
        rt: the kernel's runtime; it subscribes to both topics with matching QoS and a
            ``message_lost`` event callback.
        size: bytes per message.
        rate_hz: messages per second.
        count: messages per topic, 1..1000.
        timeout: seconds the publisher may take to send everything.

    Large messages at a high rate overflow transport buffers: best effort drops what does not
    fit (and reports it), reliable resends until everything the writer still holds arrives.
    Returns a :class:`ReliabilityResult`.
    """
    if not 1 <= count <= 1000:
        raise CourseError(f"count must be 1..1000, got {count}")
    keep = {"history": "keep_last", "depth": count}
    qos = {kind: {**keep, "reliability": kind} for kind in TOPICS}
    received: dict[str, list[int]] = {kind: [] for kind in TOPICS}
    lost = {kind: 0 for kind in TOPICS}
    node = rt.node("qos_reliability_sub", console=False)
    for kind, topic in TOPICS.items():
        def on_lost(status, kind=kind):
            lost[kind] = status.total_count

        node.create_subscription(
            UInt8MultiArray, topic, lambda msg, kind=kind: received[kind].append(msg.layout.data_offset),
            qos_from_dict(qos[kind]), event_callbacks=SubscriptionEventCallbacks(message_lost=on_lost))
    topics = {TOPICS[kind]: qos[kind] for kind in TOPICS}
    child = rt.spawn("qos_stream", StreamPublisher, params={"name": "qos_stream", "topics": topics,
                                                           "size": size, "rate_hz": rate_hz, "count": count})
    try:
        child.wait_for_report("sent", timeout, "the stream publisher to send everything")
        poll_until(lambda: len(set(received["reliable"])) >= count, RESEND_WAIT_S)  # reported as it is
        time.sleep(0.3)  # the last best-effort messages and loss events
    finally:
        rt.stop_child("qos_stream")
        remove_nodes(rt, node)
    return ReliabilityResult(count, size, rate_hz, {k: sorted(set(v)) for k, v in received.items()}, lost)


def plot_reliability(result: ReliabilityResult):
    """A matplotlib figure: a barcode per subscription, one tick per message number that arrived."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 2.4))
    rows = [("reliable", "#16a34a"), ("best_effort", "#dc2626")]
    for y, (kind, colour) in enumerate(rows):
        got = result.received[kind]
        ax.vlines(got, y - 0.35, y + 0.35, color=colour, linewidth=1.2)
        ax.text(result.sent + 1, y, f"{len(got)}/{result.sent}", va="center", fontsize=9)
    ax.set_yticks(range(len(rows)), [k.replace("_", " ") for k, _ in rows])
    ax.set_xlim(-1, result.sent + 12)
    ax.set_xlabel("message number (a gap = never delivered)")
    ax.set_title(f"{result.sent} messages of {result.size / 1e6:g} MB at {result.rate_hz:g} Hz from another "
                 "process", fontsize=10)
    fig.tight_layout()
    return fig
