"""The QoS lab's subscriber: in the kernel's runtime (``rt.add(LabSubscriber, topic, qos)``), or in a
child process on the lossy link (:class:`ReportingLabSubscriber`, which reports over the channel).

It counts, in a cheap callback, what arrives, the gaps in the DDS
``publication_sequence_number`` of each sample, the DDS ``message_lost`` event, and the
latency from the send stamp.
"""

from __future__ import annotations

import time
from array import array

from course_interfaces.msg import ExperimentSample
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from std_msgs.msg import Empty

from course_helpers.core.channel import report
from course_helpers.core.qos_dict import qos_from_dict

SUBSCRIBER_NODE = "qos_lab_subscriber"


class LabSubscriber(Node):
    """Counts samples, sequence gaps, message_lost events and latency.

    Args:
        topic: the topic to subscribe to.
        qos: the QoS as a dict (``ExperimentConfig.qos_dict()``).
        processing_ms: how long the callback works on each sample (a stand-in for real work).
        joins_before_first_sample: DDS numbers a writer's samples from 1, so a subscriber
            that was matched before the first one knows that a first sample numbered 3
            means 2 were lost. A late joiner (False) starts counting at what it gets first.

    Read ``delivered``, ``gaps``, ``lost_events``, ``latency_ns`` (an int64 array),
    ``first_seq``, ``last_seq`` and ``last_arrival`` (monotonic seconds) at any time.
    """

    def __init__(self, topic: str, qos: dict, processing_ms: float = 0.0,
                 joins_before_first_sample: bool = True):
        super().__init__(SUBSCRIBER_NODE)
        self.delivered = 0
        self.gaps = 0  # samples missing between received publication sequence numbers
        self.last_seq = 0 if joins_before_first_sample else None
        self.first_seq = None
        self.lost_events = 0  # sum of the message_lost events' total_count_change
        self.latency_ns = array("q")  # C int64 values, no Python object per sample
        self.last_arrival = 0.0
        self.processing_s = processing_ms / 1000.0
        events = SubscriptionEventCallbacks(message_lost=self.on_message_lost)
        self.subscription = self.create_subscription(
            ExperimentSample, topic, self.on_sample, qos_from_dict(qos), event_callbacks=events)

    def on_sample(self, msg, info) -> None:  # two parameters: rclpy passes the MessageInfo too
        self.latency_ns.append(time.time_ns() - msg.stamp_ns)
        seq = info["publication_sequence_number"]
        last = self.last_seq
        if last is None:
            self.first_seq = seq
        elif seq > last + 1:
            self.gaps += seq - last - 1
        self.last_seq = seq
        self.delivered += 1
        if self.processing_s:
            time.sleep(self.processing_s)  # stands in for the work a real callback does
        self.last_arrival = time.monotonic()

    def on_message_lost(self, info) -> None:
        self.lost_events += info.total_count_change

    def latency(self) -> dict:
        """p50/p90/p99/max latency so far in ms (None values before the first sample)."""
        from course_helpers.chapters.ch08b_lab.results import latency_percentiles

        return latency_percentiles(self.latency_ns)


class ReportingLabSubscriber(LabSubscriber):
    """A :class:`LabSubscriber` in a child process (the lossy link): it reports what it counted.

    Every ``report_period_s`` it sends ``report('progress', ...)`` with :meth:`counts`, and one
    last ``report('final', ...)`` when it is destroyed (the process was asked to stop), so the
    kernel reads the exact totals over the process channel. Once its subscription has matched a
    publisher it says so on ``ready_topic`` (the publisher waits for that before it sends).
    """

    def __init__(self, topic: str, qos: dict, processing_ms: float = 0.0, report_period_s: float = 0.1,
                 ready_topic: str | None = None):
        super().__init__(topic, qos, processing_ms, joins_before_first_sample=True)
        self.ready_publisher = None
        if ready_topic is not None:
            from course_helpers.chapters.ch08b_lab.publisher import READY_QOS

            self.ready_publisher = self.create_publisher(Empty, ready_topic, READY_QOS)
        self.report_timer = self.create_timer(report_period_s, self.send_progress)  # period [s]

    def counts(self) -> dict:
        """delivered, gaps, lost_events, first_seq, last_seq, last_arrival (monotonic s), latency_ms."""
        from course_helpers.chapters.ch08b_lab.results import latency_percentiles

        return {"delivered": self.delivered, "gaps": self.gaps, "lost_events": self.lost_events,
                "first_seq": self.first_seq, "last_seq": self.last_seq, "last_arrival": self.last_arrival,
                "matched": self.subscription.get_publisher_count() > 0,
                "latency_ms": latency_percentiles(self.latency_ns)}

    def send_progress(self) -> None:
        counts = self.counts()
        if counts["matched"] and self.ready_publisher is not None:
            self.ready_publisher.publish(Empty())  # once is enough (transient local, reliable)
            self.ready_publisher = None
        report("progress", **counts)

    def destroy_node(self):
        report("final", **self.counts())
        return super().destroy_node()
