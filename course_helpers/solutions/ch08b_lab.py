"""Reference solution of chapter 08b (the QoS lab); CI checks it with ``checks.ch08b_lab``."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def burst_qos() -> QoSProfile:
    """Exercise 08b: the QoS for a burst of 120 samples over a link that drops one datagram in ten, to a
    subscriber that handles one sample while two arrive.

    Reliable makes the writer keep and resend what the reader has not acknowledged: only that undoes
    the link's losses. A queue that holds the whole burst loses nothing to the slow subscriber either,
    and stays bounded. The price is latency: a repaired sample waits for the writer's heartbeat, and
    every later one waits behind it and behind the samples queued before it.
    """
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=120,  # the whole burst
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )
