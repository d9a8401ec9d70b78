"""History and depth: what a subscription's reader keeps while nobody takes its messages."""

from __future__ import annotations

import time

from rclpy.node import Node
from rclpy.qos import QoSHistoryPolicy, QoSProfile
from std_msgs.msg import String

from course_helpers.chapters.ch08_qos.cleanup import remove_nodes

BURST_TOPIC = "qos_burst"


def demo_history(rt, burst: int = 20, depths=(1, 5)) -> dict[str, list[int]]:
    """Publish a burst into subscriptions whose node is not spun yet, then spin it.

    Args:
        rt: the kernel's runtime.
        burst: how many numbered messages the publisher sends at once.
        depths: one KEEP_LAST(depth) subscription each; a KEEP_ALL subscription is added.

    While nobody takes messages, each subscription's DDS reader keeps what its history allows:
    KEEP_LAST(depth) keeps the newest ``depth``; KEEP_ALL keeps everything. Returns, for each
    subscription ('KEEP_LAST(1)', ..., 'KEEP_ALL'), the numbers it finally delivered.
    """
    got: dict[str, list[int]] = {}
    profiles = [(f"KEEP_LAST({d})", QoSProfile(depth=d)) for d in depths]
    profiles.append(("KEEP_ALL", QoSProfile(history=QoSHistoryPolicy.KEEP_ALL)))
    holder = rt.build(Node, "qos_history_sub")  # built in the runtime's context, not spun yet
    for label, profile in profiles:
        got[label] = []
        holder.create_subscription(String, BURST_TOPIC, lambda m, label=label: got[label].append(int(m.data)),
                                   profile)
    pub_node = rt.node("qos_history_pub", console=False)
    publisher = pub_node.create_publisher(String, BURST_TOPIC, QoSProfile(history=QoSHistoryPolicy.KEEP_ALL))
    spun = False
    try:
        rt.wait_until(lambda: publisher.get_subscription_count() >= len(profiles), 5.0, "matching")
        for i in range(burst):
            publisher.publish(String(data=str(i)))
        time.sleep(0.2)  # delivered into the readers' histories; no callback has run
        rt.add(holder, console=False)
        spun = True
        rt.wait_until(lambda: len(got["KEEP_ALL"]) >= burst, 5.0, "the burst")
        time.sleep(0.2)  # anything beyond what the history kept would show up now
    finally:
        remove_nodes(rt, pub_node)
        if spun:
            rt.remove(holder)
        else:
            holder.destroy_node()
    return got
