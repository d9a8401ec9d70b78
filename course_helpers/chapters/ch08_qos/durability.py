"""Durability and lifespan: what a subscription that joins late gets of what was published before."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from std_msgs.msg import String

from course_helpers.chapters.ch08_qos.cleanup import remove_nodes
from course_helpers.core.qos_dict import seconds_to_duration
from course_helpers.core.waiting import poll_until, wait_until


class DemoClock:
    """Seconds since the demo started (``start`` may be reset once the nodes are matched)."""

    def __init__(self):
        self.start = time.monotonic()

    def now(self) -> float:
        """Seconds since :attr:`start`."""
        return time.monotonic() - self.start


def demo_durability(rt, published: int = 5, publisher_depth: int = 3) -> dict[str, list[int]]:
    """A TRANSIENT_LOCAL publisher sends ``published`` messages; then two subscriptions join late.

    Args:
        rt: the kernel's runtime.
        published: numbered messages sent before anyone subscribes.
        publisher_depth: how many the publisher keeps (KEEP_LAST).

    Returns what each late joiner received: 'transient_local' gets the last ``publisher_depth``
    messages the publisher kept, 'volatile' gets nothing from before it joined.
    """
    pub_node = rt.node("qos_durability_pub", console=False)
    stored = QoSProfile(depth=publisher_depth, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    publisher = pub_node.create_publisher(String, "qos_latched", stored)
    for i in range(published):
        publisher.publish(String(data=str(i)))
    time.sleep(0.3)  # published well before anyone subscribes
    got: dict[str, list[int]] = {"transient_local": [], "volatile": []}
    sub_node = rt.node("qos_durability_late_joiner", console=False)
    for kind, durability in (("transient_local", QoSDurabilityPolicy.TRANSIENT_LOCAL),
                             ("volatile", QoSDurabilityPolicy.VOLATILE)):
        sub_node.create_subscription(String, "qos_latched",
                                     lambda m, kind=kind: got[kind].append(int(m.data)),
                                     QoSProfile(depth=10, durability=durability))
    try:
        poll_until(lambda: len(got["transient_local"]) >= min(published, publisher_depth), 3.0)
        time.sleep(0.5)  # anything more (or anything for the volatile one) would arrive now
    finally:
        remove_nodes(rt, pub_node, sub_node)
    return got


@dataclass
class LifespanResult:
    """When each numbered message was published, when the late joiner joined, what it got."""

    lifespan_s: float
    published_at: list[float]
    joined_at: float
    received: list[int]

    def ages_at_join(self) -> list[float]:
        """Each message's age in seconds when the late joiner subscribed."""
        return [self.joined_at - t for t in self.published_at]


def demo_lifespan(rt, lifespan_s: float = 1.0, period_s: float = 0.4, count: int = 6,
                  depth: int = 10) -> LifespanResult:
    """A TRANSIENT_LOCAL publisher with a lifespan sends ``count`` messages; a late joiner subscribes.

    Args:
        rt: the kernel's runtime.
        lifespan_s: how long a published message stays valid.
        period_s: seconds between messages.
        count: how many messages.
        depth: how many the publisher keeps for late joiners.

    A message older than ``lifespan_s`` is removed from what the publisher keeps: the late
    joiner only gets the ones still fresh. Returns a :class:`LifespanResult`.
    """
    clock = DemoClock()
    profile = QoSProfile(depth=depth, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL,
                         lifespan=seconds_to_duration(lifespan_s, "lifespan_s"))
    pub_node = rt.node("qos_lifespan_pub", console=False)
    publisher = pub_node.create_publisher(String, "qos_lifespan", profile)
    published: list[float] = []
    done = threading.Event()

    def tick():
        if len(published) < count:
            publisher.publish(String(data=str(len(published))))
            published.append(clock.now())
        else:
            done.set()

    pub_node.create_timer(period_s, tick)
    received: list[int] = []
    try:
        wait_until(done.is_set, count * period_s + 5, "the lifespan publisher to finish")
        sub_node = rt.node("qos_lifespan_late_joiner", console=False)
        joined = clock.now()
        sub_node.create_subscription(String, "qos_lifespan", lambda m: received.append(int(m.data)),
                                     QoSProfile(depth=depth, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL))
        time.sleep(0.6)  # the stored messages that are still fresh arrive
    finally:
        remove_nodes(rt, pub_node, "/qos_lifespan_late_joiner")
    return LifespanResult(lifespan_s, published, joined, sorted(received))


def plot_lifespan(result: LifespanResult):
    """A matplotlib figure: each message's age when the late joiner joined, green if delivered."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 2.8))
    ages = result.ages_at_join()
    colours = ["#16a34a" if i in result.received else "#9ca3af" for i in range(len(ages))]
    ax.bar(range(len(ages)), ages, color=colours)
    ax.axhline(result.lifespan_s, color="#dc2626", linestyle="--", label=f"lifespan {result.lifespan_s:g} s")
    ax.set_xlabel("message number (green: delivered to the late joiner, grey: expired)")
    ax.set_ylabel("age at join (s)")
    ax.set_title("Lifespan: stored messages older than the lifespan are dropped", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
