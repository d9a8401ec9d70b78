"""Reference solutions of chapter 08a's exercises: QoS per channel, the mismatched subscriber, the
deadline watchdog, the MANUAL_BY_TOPIC heartbeat and its monitor."""

from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSLivelinessPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_policy_name_from_kind,
    qos_profile_sensor_data,
)
from rclpy.qos_overriding_options import QoSOverridingOptions
from std_msgs.msg import Bool, String


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


class OdomWatchdog(Node):
    """Exercise 08.3: DDS watches the gap between odometry messages; a missed deadline raises an alarm."""

    def __init__(self):
        super().__init__("odom_watchdog")
        qos = QoSProfile(depth=10, deadline=Duration(seconds=0.5))  # no odometry for 0.5 s: alarm
        self.alarm = self.create_publisher(String, "alarm", 10)
        self.subscription = self.create_subscription(
            Odometry, "odom", self.on_odom, qos,
            event_callbacks=SubscriptionEventCallbacks(deadline=self.on_deadline_missed))

    def on_odom(self, msg: Odometry) -> None:
        pass  # a real watchdog would forward or check the odometry here

    def on_deadline_missed(self, status) -> None:
        self.alarm.publish(String(data=f"no odometry for 0.5 s (missed {status.total_count} times)"))


HEARTBEAT_QOS = QoSProfile(depth=1, liveliness=QoSLivelinessPolicy.MANUAL_BY_TOPIC,
                           liveliness_lease_duration=Duration(seconds=0.5))


class SwitchableHeartbeat(Node):
    """Exercise 08.4: asserts its liveliness every 0.2 s while enabled; /heartbeat/enable switches it."""

    def __init__(self):
        super().__init__("heartbeat")
        self.beating = True
        self.publisher = self.create_publisher(String, "heartbeat", HEARTBEAT_QOS)
        self.enable = self.create_subscription(Bool, "heartbeat/enable", self.on_enable, 10)
        self.timer = self.create_timer(0.2, self.beat)  # period in seconds, well within the 0.5 s lease

    def on_enable(self, msg: Bool) -> None:
        self.beating = msg.data

    def beat(self) -> None:
        if self.beating:
            self.publisher.assert_liveliness()


class HeartbeatMonitor(Node):
    """Exercise 08.4: reports on /heartbeat/status when the heartbeat's writer is lost or alive again."""

    def __init__(self):
        super().__init__("heartbeat_monitor")
        self.status = self.create_publisher(String, "heartbeat/status", 10)
        self.subscription = self.create_subscription(
            String, "heartbeat", self.on_beat, HEARTBEAT_QOS,
            event_callbacks=SubscriptionEventCallbacks(liveliness=self.on_liveliness))

    def on_beat(self, msg: String) -> None:
        pass  # the heartbeat carries no data: only its liveliness matters

    def on_liveliness(self, status) -> None:
        if status.not_alive_count_change > 0:
            self.status.publish(String(data="lost"))
        if status.alive_count_change > 0:
            self.status.publish(String(data="alive"))


def heartbeat_nodes() -> tuple[type, type]:
    """Exercise 08.4's two node classes, for ``check_heartbeat(*heartbeat_nodes())``."""
    return SwitchableHeartbeat, HeartbeatMonitor
