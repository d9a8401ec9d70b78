"""Reference solutions of chapter 03 (topics), checked by ``course_helpers/checks/ch03_topics.py``.

1. :class:`TiltMonitor` - warns on ``/safety/tilt_warning`` (std_msgs/String) when the IMU on
   ``/imu`` reports a tilt above 15°.
2. :class:`CmdVelCsvLogger` - writes every ``/cmd_vel`` Twist as a CSV row, flushed at once.
3. :func:`expected_load` and :func:`measure_load` - throughput of a sensor array, computed and
   measured.
"""

from __future__ import annotations

import csv
import math
import time

from geometry_msgs.msg import Twist
from rclpy.node import Node
from sensor_msgs.msg import Imu
from std_msgs.msg import String

from course_helpers.core.waiting import poll_until


# ---------------------------------------------------------------------- exercise 1
class TiltMonitor(Node):
    """Publishes a warning whenever the robot tilts more than ``threshold_deg`` from upright."""

    def __init__(self, threshold_deg: float = 15.0):
        super().__init__("tilt_monitor")
        self.threshold_deg = threshold_deg
        self.warning_pub = self.create_publisher(String, "/safety/tilt_warning", 10)
        self.imu_sub = self.create_subscription(Imu, "/imu", self.on_imu, 10)

    def on_imu(self, msg: Imu) -> None:
        tilt = tilt_deg(msg.orientation)
        if tilt > self.threshold_deg:
            warning = String(data=f"tilt {tilt:.1f} deg exceeds {self.threshold_deg:.1f} deg")
            self.warning_pub.publish(warning)
            self.get_logger().warn(warning.data)


def tilt_deg(q) -> float:
    """Angle (degrees) between the robot's up axis and the vertical, from its orientation quaternion.

    The robot's z axis in world coordinates has the z component 1 - 2(x² + y²) for a unit
    quaternion (divided by the squared norm here, in case the quaternion is not normalised).
    Yaw does not change it: turning on the spot is not tilting.
    """
    norm2 = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w
    if norm2 == 0.0:
        return 0.0
    up_z = 1.0 - 2.0 * (q.x * q.x + q.y * q.y) / norm2
    return math.degrees(math.acos(max(-1.0, min(1.0, up_z))))


# ---------------------------------------------------------------------- exercise 2
CSV_COLUMNS = ["time_s", "linear_x", "linear_y", "linear_z", "angular_x", "angular_y", "angular_z"]


class CmdVelCsvLogger(Node):
    """Appends each Twist on ``/cmd_vel`` to a CSV file: receive time (s) and six velocities."""

    def __init__(self, csv_path: str):
        super().__init__("cmd_vel_logger")
        self.file = open(csv_path, "w", newline="", encoding="utf-8")  # closed in destroy_node
        self.writer = csv.writer(self.file)
        self.writer.writerow(CSV_COLUMNS)
        self.file.flush()
        self.subscription = self.create_subscription(Twist, "/cmd_vel", self.on_twist, 10)

    def on_twist(self, msg: Twist) -> None:
        now_s = self.get_clock().now().nanoseconds / 1e9  # ROS time, seconds since the epoch
        self.writer.writerow([f"{now_s:.6f}", msg.linear.x, msg.linear.y, msg.linear.z,
                              msg.angular.x, msg.angular.y, msg.angular.z])
        self.file.flush()  # on disk at once: a crash loses nothing

    def destroy_node(self):
        self.file.close()
        return super().destroy_node()


# ---------------------------------------------------------------------- exercise 3
def expected_load(n_sensors: int, rate_hz: float, message_bytes: int) -> tuple[float, float]:
    """(messages per second, bytes per second) that ``n_sensors`` publishers at ``rate_hz`` produce."""
    messages_per_s = n_sensors * rate_hz
    return messages_per_s, messages_per_s * message_bytes


def measure_load(node: Node, topics: list[str], duration_s: float = 2.0) -> tuple[float, float]:
    """Subscribe to ``topics`` (sensor_msgs/Imu) and measure the total messages/s and bytes/s.

    Raw subscriptions hand over the serialized bytes, so the byte count is what travelled
    through the middleware (like ``ros2 topic bw``). The count starts after every topic has
    delivered a first message, so discovery time is not counted as silence.
    """
    seen: set[str] = set()
    totals = {"messages": 0, "bytes": 0}

    def make_callback(topic):
        def on_raw(data: bytes) -> None:
            seen.add(topic)
            totals["messages"] += 1
            totals["bytes"] += len(data)
        return on_raw

    subscriptions = [node.create_subscription(Imu, t, make_callback(t), 100, raw=True) for t in topics]
    try:
        poll_until(lambda: len(seen) == len(topics), 10.0)  # up to 10 s for every first message
        start_messages, start_bytes, start = totals["messages"], totals["bytes"], time.monotonic()
        time.sleep(duration_s)
        elapsed = time.monotonic() - start
        return ((totals["messages"] - start_messages) / elapsed,
                (totals["bytes"] - start_bytes) / elapsed)
    finally:
        for subscription in subscriptions:
            node.destroy_subscription(subscription)


class ThroughputSolution:
    """Exercise 3's two functions as one object, for ``show_passing_report`` in the notebook."""

    expected_load = staticmethod(expected_load)
    measure_load = staticmethod(measure_load)
