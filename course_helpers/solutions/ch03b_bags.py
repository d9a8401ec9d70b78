"""Reference solution of chapter 03b (recording and replay); CI checks it with ``checks.ch03b_bags``."""

from __future__ import annotations

from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import Bool, Float64


class OdomMonitor(Node):
    """Exercise 03b: the speed between odometry messages, and a watchdog for odometry that stops."""

    def __init__(self):
        super().__init__('odom_monitor')
        self.timeout = Duration(seconds=0.5)  # silence longer than this is a dropout
        self.previous = None  # (stamp in s, x in m) of the last message
        self.last_heard = None  # ROS time of the last message
        self.stale = False
        self.speed_publisher = self.create_publisher(Float64, 'speed', 10)
        self.stale_publisher = self.create_publisher(Bool, 'odom_stale', 10)
        self.subscription = self.create_subscription(Odometry, 'odom', self.on_odom, 10)
        self.timer = self.create_timer(0.1, self.check)  # 10 Hz of ROS time

    def on_odom(self, msg: Odometry) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9  # when it was measured [s]
        x = msg.pose.pose.position.x
        if self.previous is not None:
            (t0, x0) = self.previous
            self.speed_publisher.publish(Float64(data=(x - x0) / (stamp - t0)))
        self.previous = (stamp, x)
        self.last_heard = self.get_clock().now()  # ROS time: the bag's, when replayed
        if self.stale:
            self.stale = False
            self.stale_publisher.publish(Bool(data=False))

    def check(self) -> None:
        if self.last_heard is None or self.stale:
            return
        if self.get_clock().now() - self.last_heard > self.timeout:
            self.stale = True
            self.stale_publisher.publish(Bool(data=True))
