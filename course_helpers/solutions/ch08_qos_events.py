"""Reference solutions of chapter 08a's exercises 08.3 and 08.4 (QoS events, judged by
checks/ch08_qos_events.py): the deadline watchdog, the MANUAL_BY_TOPIC heartbeat and its monitor."""

from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSLivelinessPolicy, QoSProfile
from std_msgs.msg import Bool, String


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
