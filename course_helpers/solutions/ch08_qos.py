"""Reference solutions of chapter 08a's exercises 08.1 and 08.2: QoS per channel, the mismatched
subscriber (08.3 and 08.4, judged by checks/ch08_qos_events.py, are in solutions/ch08_qos_events.py)."""

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_policy_name_from_kind,
    qos_profile_sensor_data,
)
from rclpy.qos_overriding_options import QoSOverridingOptions
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
        # robot_state_publisher subscribes with the sensor-data profile; only the current state matters
        "joint_states": qos_profile_sensor_data,
        # never lost, and kept for controllers that start later
        "estop": QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                            reliability=QoSReliabilityPolicy.RELIABLE,
                            durability=QoSDurabilityPolicy.TRANSIENT_LOCAL),
    }


class RobotCmdListener(Node):
    """Exercise 08.2: asks for no more than the best-effort, volatile publisher offers, and names the
    policy of every incompatible-QoS event (a deployer may override its reliability by parameter)."""

    def __init__(self, parameter_overrides=()):
        super().__init__("robot_listener", parameter_overrides=list(parameter_overrides))
        self.received = []
        self.incompatible = []  # the policy each incompatible-QoS event names, e.g. 'RELIABILITY'
        qos = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.BEST_EFFORT,
                         durability=QoSDurabilityPolicy.VOLATILE)
        self.subscription = self.create_subscription(
            String, "/robot_cmd", self.on_cmd, qos,
            event_callbacks=SubscriptionEventCallbacks(incompatible_qos=self.on_incompatible_qos),
            qos_overriding_options=QoSOverridingOptions.with_default_policies())

    def on_cmd(self, msg: String) -> None:
        self.received.append(msg.data)

    def on_incompatible_qos(self, status) -> None:
        policy = qos_policy_name_from_kind(status.last_policy_kind)
        self.incompatible.append(policy)
        self.get_logger().warning(f"a publisher of /robot_cmd cannot give what this subscription asks for: "
                                  f"{policy} (no command will arrive from it)")
