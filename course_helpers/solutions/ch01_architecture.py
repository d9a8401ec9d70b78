"""Reference solution of chapter 01 (architecture); CI checks it with ``checks.ch01_architecture``."""

from __future__ import annotations

from rclpy.node import Node
from std_msgs.msg import String


class SilenceWatchdog(Node):
    """Exercise 01: reports on ``silent_talkers`` each sender of ``chatter`` that went quiet."""

    SILENCE_S = 0.5  # a sender quiet for longer than this is reported [s]

    def __init__(self):
        super().__init__('silence_watchdog')
        self.last_heard = {}  # sender -> the node clock's time of its latest message [s]
        self.reported = set()  # senders reported silent and not heard since
        self.alarm = self.create_publisher(String, 'silent_talkers', 10)
        self.subscription = self.create_subscription(String, 'chatter', self.on_chatter, 10)
        self.timer = self.create_timer(0.1, self.check)  # look ten times a second

    def seconds(self) -> float:
        """Now, on this node's clock (ROS time: a simulator's or a bag's under use_sim_time) [s]."""
        return self.get_clock().now().nanoseconds * 1e-9

    def on_chatter(self, msg: String) -> None:
        sender = msg.data.split(':', 1)[0]
        self.last_heard[sender] = self.seconds()
        self.reported.discard(sender)  # it talks again: a new silence will be reported again

    def check(self) -> None:
        now = self.seconds()
        for sender, heard in self.last_heard.items():
            if now - heard > self.SILENCE_S and sender not in self.reported:
                self.reported.add(sender)
                self.alarm.publish(String(data=sender))
                self.get_logger().warning(f'{sender} has been silent for {now - heard:.1f} s')
