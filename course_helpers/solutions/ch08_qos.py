"""Reference solutions of chapter 08a's exercises (QoS per channel; the mismatched subscriber)."""

from rclpy.node import Node
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_profile_sensor_data,
)
from std_msgs.msg import String


def channel_qos() -> dict:
    """Exercise 08.1: one profile per channel."""
    return {
        # newest frame only; a lost frame is replaced 33 ms later
        "camera": QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                             reliability=QoSReliabilityPolicy.BEST_EFFORT,
                             durability=QoSDurabilityPolicy.VOLATILE),
        # the sensor-data profile: best effort, volatile, the last 5 scans
        "lidar": qos_profile_sensor_data,
        # robot_state_publisher subscribes reliable; only the current state matters
        "joint_states": QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=10,
                                   reliability=QoSReliabilityPolicy.RELIABLE,
                                   durability=QoSDurabilityPolicy.VOLATILE),
        # never lost, and kept for controllers that start later
        "estop": QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                            reliability=QoSReliabilityPolicy.RELIABLE,
                            durability=QoSDurabilityPolicy.TRANSIENT_LOCAL),
    }


class RobotCmdListener(Node):
    """Exercise 08.2: asks for no more than the best-effort, volatile publisher offers."""

    def __init__(self):
        super().__init__("robot_listener")
        self.received = []
        qos = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.BEST_EFFORT,
                         durability=QoSDurabilityPolicy.VOLATILE)
        self.subscription = self.create_subscription(String, "/robot_cmd", self.on_cmd, qos)

    def on_cmd(self, msg: String) -> None:
        self.received.append(msg.data)
