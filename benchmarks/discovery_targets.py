"""Child-process targets of ``discovery_latency.py`` (a child imports its target from a module:
``benchmarks.discovery_targets``, on the venv's path like the rest of the repository)."""

from __future__ import annotations

import time

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.core.channel import report
from course_helpers.core.names import node_full_names
from course_helpers.core.runtime import get_runtime

ANCHOR = "/bench_anchor"
TOPIC = "bench_beacon"
PROBE_TIMEOUT_S = 6.0  # longer than two default announcement periods


class Beacon(Node):
    """The long-running side: publishes the beacon the probes' subscriptions match (as is, it is the
    node the benchmark's own runtime adds in the kernel's place)."""

    def __init__(self):
        super().__init__("bench_anchor")
        self.publisher = self.create_publisher(String, TOPIC, 10)


class BeaconAnchor(Beacon):
    """The long-running side in a child process: the beacon, and a report of each new node it sees,
    with the time."""

    def __init__(self):
        super().__init__()
        self.seen: set[str] = set()
        self.timer = self.create_timer(0.002, self.look)  # s: how often the graph is read

    def look(self) -> None:
        now = time.monotonic()
        for name in node_full_names(self.get_node_names_and_namespaces()):
            if name not in self.seen:
                self.seen.add(name)
                report("seen", node=name, t=now)


class BeaconProbe(Node):
    """The new process's node: a subscription whose matched event is timed."""

    def __init__(self, index: int):
        super().__init__(f"bench_probe_{index}")
        self.matched_at: float | None = None
        self.subscription = self.create_subscription(
            String, TOPIC, lambda _msg: None, 10,
            event_callbacks=SubscriptionEventCallbacks(matched=self.on_matched))

    def on_matched(self, _status) -> None:
        if self.matched_at is None:
            self.matched_at = time.monotonic()


def probe_procedure(index: int) -> None:
    """A child procedure: create the probe node, wait until it sees the anchor and matched, report,
    then stay (and stay discoverable) until the benchmark stops it once the anchor has listed it."""
    rt = get_runtime()
    started = time.monotonic()
    probe = rt.add(BeaconProbe, index)
    created = time.monotonic()
    seen = None

    def done() -> bool:
        nonlocal seen
        if seen is None and ANCHOR in rt.graph_nodes():
            seen = time.monotonic()
        return seen is not None and probe.matched_at is not None

    rt.poll_until(done, PROBE_TIMEOUT_S)
    report("result", start=started, created=created, seen=seen, matched=probe.matched_at)
    # leaving now would hide the probe from an anchor that has not listed it yet
    time.sleep(max(0.0, created + PROBE_TIMEOUT_S - time.monotonic()))


def named_node_procedure(name: str) -> None:
    """A child procedure: make node ``name``, report 'ready', then wait to be stopped or killed."""
    get_runtime().add(Node, name)
    report("ready")
    time.sleep(300)
