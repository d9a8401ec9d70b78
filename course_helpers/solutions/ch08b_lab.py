"""Reference solution of chapter 08b (the QoS lab); CI checks it with ``checks.ch08b_lab``."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def burst_qos() -> QoSProfile:
    """Exercise 08b: the QoS for a burst of 60 samples to a subscriber that handles one while two arrive.

    A queue that holds the whole burst loses nothing: the subscriber is slow, not gone. Reliable
    makes the writer keep and resend what the reader has not acknowledged. The price is latency:
    the last sample waits for the ones queued before it.
    """
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=60,  # the whole burst
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )
