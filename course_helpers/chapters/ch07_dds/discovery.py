"""How long a new process takes to find a node, step by step (simple discovery).

A :class:`DiscoveryAnchor` is the node already running: in the kernel (:func:`measure_discovery`)
or in a child process (:mod:`.discovery_settings`). Each fresh child process runs :func:`discovery_probe`,
which times its own :class:`DiscoveryProbe` node against the anchor and reports the timings over
the process channel.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.core.channel import report
from course_helpers.core.child_results import run_child_for_result
from course_helpers.core.errors import CourseError
from course_helpers.core.runtime import get_runtime

ANCHOR_NODE = "discovery_anchor"
ANCHOR_TOPIC = "discovery_beacon"
PROBE_TOPIC = "discovery_echo"
STEPS = ("create_node_s", "sees_node_s", "reader_matched_s", "writer_matched_s", "first_message_s")


@dataclass
class DiscoveryTiming:
    """Seconds from just before a new process's first node was created until each step (None: never)."""

    create_node_s: float  # creating the node, which creates the DDS participant
    sees_node_s: float | None  # the anchor node appears in the child's graph
    reader_matched_s: float | None  # the child's subscription matched the anchor's publisher
    writer_matched_s: float | None  # the child's publisher matched the anchor's subscription
    first_message_s: float | None  # first message from the anchor arrived

    @property
    def found(self) -> bool:
        """True if the child saw the anchor node and its subscription matched."""
        return self.reader_matched_s is not None and self.sees_node_s is not None


class DiscoveryAnchor(Node):
    """The node already running: publishes a beacon at 50 Hz and subscribes to the probes' topic."""

    def __init__(self):
        super().__init__(ANCHOR_NODE)
        self.publisher = self.create_publisher(String, ANCHOR_TOPIC, 10)
        self.subscription = self.create_subscription(String, PROBE_TOPIC, self.on_echo, 10)
        self.timer = self.create_timer(0.02, self.beacon)  # period in seconds (50 Hz)

    def beacon(self) -> None:
        self.publisher.publish(String(data="beacon"))

    def on_echo(self, _msg: String) -> None:
        pass  # the subscription is there to be matched


class DiscoveryProbe(Node):
    """A new process's first node: notes when each discovery step towards the anchor happened.

    ``start`` is the ``time.perf_counter()`` value just before the node (and so the process's
    DDS participant) was created; :attr:`marks` maps each step in :data:`STEPS` to seconds since.
    """

    def __init__(self, start: float):
        super().__init__("discovery_probe")
        self.start = start
        self.marks: dict[str, float] = {}
        self.mark("create_node_s")
        self.subscription = self.create_subscription(
            String, ANCHOR_TOPIC, self.on_beacon, 10,
            event_callbacks=SubscriptionEventCallbacks(matched=self.on_reader_matched))
        self.publisher = self.create_publisher(
            String, PROBE_TOPIC, 10,
            event_callbacks=PublisherEventCallbacks(matched=self.on_writer_matched))

    def mark(self, step: str) -> None:
        self.marks.setdefault(step, time.perf_counter() - self.start)

    def on_beacon(self, _msg: String) -> None:
        self.mark("first_message_s")

    def on_reader_matched(self, _status) -> None:
        self.mark("reader_matched_s")

    def on_writer_matched(self, _status) -> None:
        self.mark("writer_matched_s")

    def found_everything(self) -> bool:
        """Look for the anchor in the graph; True once every step has happened."""
        if "sees_node_s" not in self.marks and ANCHOR_NODE in self.get_node_names():
            self.mark("sees_node_s")
        return all(step in self.marks for step in STEPS)


def discovery_probe(timeout_s: float = 5.0) -> None:
    """Child-process procedure: time how long this new process takes to find the anchor node.

    Waits at most ``timeout_s`` seconds, then reports ``result`` with one entry per step in
    :data:`STEPS` (seconds, or None for a step that never happened).
    """
    rt = get_runtime()
    start = time.perf_counter()
    probe = rt.add(DiscoveryProbe, start, console=False)
    rt.poll_until(probe.found_everything, timeout_s)
    report("result", **{step: probe.marks.get(step) for step in STEPS})


def measure_discovery(rt, repeats: int = 3, env: dict | None = None,
                      timeout_s: float = 5.0) -> list[DiscoveryTiming]:
    """Start ``repeats`` fresh processes one after the other; each times how it finds the kernel.

    Args:
        rt: the kernel's runtime (it runs the anchor node meanwhile).
        repeats: how many processes, 1..20.
        env: environment changes for the children (e.g. ``{'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}``).
        timeout_s: how long each child looks; a step it never saw is None.

    Returns one :class:`DiscoveryTiming` per child, in order.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 1 <= repeats <= 20:
        raise CourseError(f"repeats must be a whole number 1..20, got {repeats!r}")
    anchor = rt.add(DiscoveryAnchor, console=False)
    try:
        return [DiscoveryTiming(**run_child_for_result(rt, "discovery_probe", discovery_probe,
                                                       {"timeout_s": timeout_s}, env, timeout=timeout_s + 20))
                for _ in range(repeats)]
    finally:
        rt.remove(anchor)


def summarize_discovery(timings: list[DiscoveryTiming]) -> dict[str, float | None]:
    """The median of each step in :data:`STEPS` over the runs that found the kernel (None if none did)."""
    found = [t for t in timings if t.found]
    summary = {}
    for step in STEPS:
        values = [getattr(t, step) for t in found if getattr(t, step) is not None]
        summary[step] = statistics.median(values) if values else None
    return summary
