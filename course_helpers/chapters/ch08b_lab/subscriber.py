"""The QoS lab's subscriber, which runs in the kernel's runtime: ``rt.add(LabSubscriber, topic, qos)``.

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
