"""Exercise 08.2's publisher: robot commands sent best effort, for a subscriber to match."""

from __future__ import annotations

from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.core.qos_dict import qos_from_dict

ROBOT_CMD_QOS = {"reliability": "best_effort", "durability": "volatile", "history": "keep_last", "depth": 5}
COMMANDS = ("forward", "backward", "stop")


class RobotCmdPublisher(Node):
    """Sends 'forward', 'backward', 'stop' in turn on /robot_cmd at ``rate_hz``, QoS :data:`ROBOT_CMD_QOS`."""

    def __init__(self, name: str = "robot_controller", rate_hz: float = 5.0):
        super().__init__(name)
        self.sent = 0
        self.publisher = self.create_publisher(String, "/robot_cmd", qos_from_dict(ROBOT_CMD_QOS))
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # period in seconds

    def tick(self) -> None:
        self.publisher.publish(String(data=COMMANDS[self.sent % len(COMMANDS)]))
        self.sent += 1
