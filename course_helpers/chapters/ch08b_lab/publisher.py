"""The QoS lab's publisher, run in a child process: ``rt.spawn(CHILD_LABEL, LabPublisher, params=...)``.

Running it in another process makes every sample cross a real Fast DDS transport (shared
memory or UDP); inside one process Fast DDS would hand samples over intra-process and
nothing could be lost. It tells the kernel how far it is over the process channel:
``report('progress', ...)`` when it starts sending and about every 0.1 s, and
``report('summary', ...)`` once it is done, then ``report('acked')`` once every reader has
acknowledged every sample (at once for best-effort, which has no acknowledgements). Before its
first sample it reports ``report('writer', gid=...)``: its DDS writer's GUID, which a capture of
the run finds in every RTPS submessage of that writer (chapter 08c).
"""

from __future__ import annotations

import time
from array import array

from course_interfaces.msg import ExperimentSample
from rclpy._rclpy_pybind11 import RCLError
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Empty

from course_helpers.core.channel import report
from course_helpers.core.qos_dict import qos_from_dict

CHILD_LABEL = "qos_lab_publisher"
PUBLISHER_NODE = "qos_lab_publisher"
MATCH_SETTLE_S = 0.2  # the publisher waits this long once matched, so both sides know each other
PROGRESS_PERIOD_S = 0.1  # a progress report at most this often
MAX_BURST = 500  # samples one timer tick may send (bounded work per callback)
# The subscriber's "I have matched you" on the lossy link: kept for a late reader, repaired if lost
READY_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)


class LabPublisher(Node):
    """Publishes ``count`` ExperimentSample messages at ``rate_hz`` with a timer.

    Args:
        topic: the topic to publish on.
        qos: the QoS as a dict (``ExperimentConfig.qos_dict()``).
        rate_hz: samples per second.
        payload_bytes: size of each sample's filler.
        count: how many samples to send.
        wait_for_subscriber: start once a subscription is matched.
        wait_for_node: start once this node (a full name) is in the graph (for a late joiner).
        deadline_s: stop sending after this many seconds, even if not everything was sent.
        ready_topic: also wait for a message on this topic: the subscriber's word that it has
            matched the publisher (on a lossy link either side may learn of the other first, and a
            reader drops samples from a writer it does not know yet).

    Each sample carries a sequence number, the send time (ns, this machine's clock) and the
    filler. The timer ticks at the rate (at most every millisecond) and sends the samples
    that are due, so the average rate holds even when a tick is late. A ``publish()`` that
    raises (a full KEEP_ALL history) is counted, not fatal. Reports: ``progress`` and
    ``summary`` with attempted, published, publish_errors and elapsed_s; the summary adds
    first_error and not_attempted. Then ``acked`` when the readers have acknowledged everything.
    """

    def __init__(self, topic: str, qos: dict, rate_hz: float, payload_bytes: int, count: int,
                 wait_for_subscriber: bool = True, wait_for_node: str | None = None,
                 deadline_s: float = 30.0, ready_topic: str | None = None):
        super().__init__(PUBLISHER_NODE)
        self.rate_hz = float(rate_hz)  # samples per second
        self.count = int(count)
        self.deadline_s = float(deadline_s)  # stop trying after this long [s]
        self.publisher = self.create_publisher(ExperimentSample, topic, qos_from_dict(qos))
        self.sample = ExperimentSample()
        self.sample.payload = array("B", bytes(payload_bytes))  # built once, reused
        self.attempted = self.published = self.errors = 0
        self.first_error = ""
        self.started_ns = 0
        self.last_report = 0.0
        self.wait_for_subscriber = wait_for_subscriber
        self.wait_for_node = wait_for_node
        self.ready_at = 0.0
        self.peer_ready = ready_topic is None
        if ready_topic is not None:
            self.ready_subscription = self.create_subscription(Empty, ready_topic, self.on_peer_ready,
                                                               READY_QOS)
        self.timer = self.create_timer(max(1.0 / self.rate_hz, 0.001), self.tick)  # period [s]
        self.timer.cancel()  # started by start()
        self.wait_timer = self.create_timer(0.01, self.check_ready)  # every 10 ms until ready
        self.ack_timer = self.create_timer(0.02, self.check_acked)
        self.ack_timer.cancel()  # started once everything is sent

    def on_peer_ready(self, _msg) -> None:
        self.peer_ready = True

    def check_ready(self) -> None:
        """Start sending once the other side is there (and has had MATCH_SETTLE_S to notice us)."""
        if self.wait_for_subscriber and self.publisher.get_subscription_count() == 0:
            return
        if not self.peer_ready:
            return
        if self.wait_for_node and self.wait_for_node not in {
                ns.rstrip("/") + "/" + name for name, ns in self.get_node_names_and_namespaces()}:
            return
        if not self.ready_at:
            self.ready_at = time.monotonic()
        elif time.monotonic() - self.ready_at >= MATCH_SETTLE_S:  # the other side knows us by now
            self.wait_timer.cancel()
            self.start()

    def start(self) -> None:
        report("writer", gid=self.writer_gid())
        self.started_ns = time.monotonic_ns()
        report("progress", **self.counts(0.0))
        self.timer.reset()

    def tick(self) -> None:
        elapsed_s = (time.monotonic_ns() - self.started_ns) * 1e-9
        due = min(self.count, int(elapsed_s * self.rate_hz) + 1)
        burst_end = min(due, self.attempted + MAX_BURST)
        sample, publish = self.sample, self.publisher.publish
        while self.attempted < burst_end:
            sample.seq = self.attempted
            sample.stamp_ns = time.time_ns()
            self.attempted += 1
            try:
                publish(sample)
            except RCLError as exc:  # a KEEP_ALL history is full: back-pressure
                self.errors += 1
                self.first_error = self.first_error or str(exc).strip().splitlines()[0][:200]
                break  # publish() already waited; the next tick tries again
            self.published += 1
        if self.attempted >= self.count or elapsed_s > self.deadline_s:
            self.timer.cancel()
            report("summary", **self.counts(elapsed_s), first_error=self.first_error,
                   not_attempted=self.count - self.attempted)
            self.ack_timer.reset()
        elif time.monotonic() - self.last_report > PROGRESS_PERIOD_S:
            self.last_report = time.monotonic()
            report("progress", **self.counts(elapsed_s))

    def writer_gid(self) -> str:
        """This publisher's DDS writer GUID, 32 hex digits, as its own participant's graph lists it."""
        for info in self.get_publishers_info_by_topic(self.publisher.topic_name):
            if (info.node_name, info.node_namespace) == (self.get_name(), self.get_namespace()):
                return bytes(info.endpoint_gid).hex()
        return ""

    def check_acked(self) -> None:
        """Report once when every matched reader has acknowledged every sample (no waiting here)."""
        if self.publisher.wait_for_all_acked(Duration(seconds=0)):
            self.ack_timer.cancel()
            report("acked")

    def counts(self, elapsed_s: float) -> dict:
        """What was sent so far: attempted, published, publish_errors, elapsed_s."""
        return {"attempted": self.attempted, "published": self.published,
                "publish_errors": self.errors, "elapsed_s": round(elapsed_s, 4)}
