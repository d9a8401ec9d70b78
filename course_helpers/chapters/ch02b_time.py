"""Chapter 02b, time: a stamped sensor to measure latency with, and the plots of the chapter.

* :class:`StampedTalker` - a child-process node that publishes ``geometry_msgs/PointStamped`` at
  ``rate_hz``, stamped with its clock when it publishes;
* :func:`plot_latencies` - a histogram of latencies in milliseconds.
"""

from __future__ import annotations

from geometry_msgs.msg import PointStamped
from rclpy.node import Node


class StampedTalker(Node):
    """Publishes ``stamped`` (PointStamped) at ``rate_hz``, ``header.stamp`` = its clock's now()."""

    def __init__(self, rate_hz: float = 50.0):
        super().__init__("stamped_talker")
        self.count = 0
        self.publisher = self.create_publisher(PointStamped, "stamped", 10)
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # 20 ms at 50 Hz

    def tick(self) -> None:
        msg = PointStamped()
        msg.header.stamp = self.get_clock().now().to_msg()  # the time of the measurement
        msg.header.frame_id = "sensor"
        msg.point.x = float(self.count)
        self.publisher.publish(msg)
        self.count += 1


def plot_latencies(latencies_ms: list[float], title: str):
    """A histogram of ``latencies_ms``; returns the figure."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 2.8))
    ax.hist(latencies_ms, bins=40, color="tab:blue")
    ax.set_xlabel("receive time - header stamp [ms]")
    ax.set_ylabel("messages")
    ax.set_title(title)
    fig.tight_layout()
    return fig
