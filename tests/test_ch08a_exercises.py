"""Chapter 08a's new exercises: each checker accepts the reference solution and rejects wrong code,
running real nodes (the student's in this process, the drivers in child processes)."""

from __future__ import annotations

from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSLivelinessPolicy, QoSProfile
from std_msgs.msg import String

from course_helpers.checks.ch08_qos import check_deadline_watchdog, check_heartbeat
from course_helpers.notebook.solution import solution_source
from course_helpers.solutions import ch08_qos as reference


def _failed(report) -> list[str]:
    return [c.name for c in report.criteria if not c.passed]


# ---------------------------------------------------------------- wrong watchdogs
class TimerWatchdog(Node):
    """Watches /odom with a timer of its own instead of a QoS deadline."""

    def __init__(self):
        super().__init__("odom_watchdog")
        self.alarm = self.create_publisher(String, "alarm", 10)
        self.subscription = self.create_subscription(Odometry, "odom", lambda _m: None, 10)


class SilentWatchdog(Node):
    """Requests the deadline but never raises the alarm."""

    def __init__(self):
        super().__init__("odom_watchdog")
        self.alarm = self.create_publisher(String, "alarm", 10)
        self.subscription = self.create_subscription(
            Odometry, "odom", lambda _m: None, QoSProfile(depth=10, deadline=Duration(seconds=0.5)))


class NoisyWatchdog(Node):
    """Requests the deadline, and sounds the alarm on every message (and on every missed deadline)."""

    def __init__(self):
        super().__init__("odom_watchdog")
        self.alarm = self.create_publisher(String, "alarm", 10)
        self.subscription = self.create_subscription(
            Odometry, "odom", self.ring, QoSProfile(depth=10, deadline=Duration(seconds=0.5)),
            event_callbacks=SubscriptionEventCallbacks(deadline=self.ring))

    def ring(self, _what) -> None:
        self.alarm.publish(String(data="alarm"))


def test_watchdog_checker_accepts_the_reference_solution(rt):
    report = check_deadline_watchdog(reference.OdomWatchdog, rt)
    assert report.passed, report.summary()


def test_watchdog_checker_rejects_a_watchdog_without_a_deadline(rt):
    report = check_deadline_watchdog(TimerWatchdog, rt)
    assert _failed(report) == ["the subscription requests a deadline (0.2 s to 1 s)"], report.summary()


def test_watchdog_checker_rejects_a_watchdog_that_never_alarms_or_always_does(rt):
    silent = check_deadline_watchdog(SilentWatchdog, rt)
    assert _failed(silent) == ["an alarm within 1.5 s after the odometry stopped"], silent.summary()
    noisy = check_deadline_watchdog(NoisyWatchdog, rt)
    failed = _failed(noisy)
    assert "no alarm while odometry arrives every 0.1 s" in failed, noisy.summary()
    assert "no alarm once odometry flows again" in failed, noisy.summary()


# ---------------------------------------------------------------- wrong heartbeats and monitors
class StubbornHeartbeat(reference.SwitchableHeartbeat):
    """Ignores the command to stop."""

    def on_enable(self, msg) -> None:
        pass


class SeldomHeartbeat(reference.SwitchableHeartbeat):
    """Asserts every 2 s, four times the 0.5 s lease it promises."""

    def __init__(self):
        super().__init__()
        self.destroy_timer(self.timer)
        self.timer = self.create_timer(2.0, self.beat)  # period in seconds


class AutomaticHeartbeat(Node):
    """Publishes with AUTOMATIC liveliness: the process, not the writer, keeps it alive."""

    def __init__(self):
        super().__init__("heartbeat")
        qos = QoSProfile(depth=1, liveliness=QoSLivelinessPolicy.AUTOMATIC,
                         liveliness_lease_duration=Duration(seconds=0.5))
        self.publisher = self.create_publisher(String, "heartbeat", qos)


class DeafMonitor(Node):
    """Subscribes to the heartbeat and publishes a status topic, but has no liveliness callback."""

    def __init__(self):
        super().__init__("heartbeat_monitor")
        self.status = self.create_publisher(String, "heartbeat/status", 10)
        self.subscription = self.create_subscription(String, "heartbeat", lambda _m: None,
                                                     reference.HEARTBEAT_QOS)


def test_heartbeat_checker_accepts_the_reference_solution(rt):
    report = check_heartbeat(reference.SwitchableHeartbeat, reference.HeartbeatMonitor, rt)
    assert report.passed, report.summary()


def test_heartbeat_checker_rejects_a_heartbeat_that_ignores_the_command_and_a_deaf_monitor(rt):
    report = check_heartbeat(StubbornHeartbeat, DeafMonitor, rt)
    failed = _failed(report)
    assert "heartbeat: lost within 2 s of a False on /heartbeat/enable" in failed, report.summary()
    assert "monitor: publishes 'lost' within 2 s after the heartbeat stopped" in failed, report.summary()
    assert "monitor: publishes 'alive' when the heartbeat is back" in failed, report.summary()
    assert "heartbeat: a monitor sees it alive" not in failed  # the parts that are right pass


def test_heartbeat_checker_rejects_a_heartbeat_that_asserts_too_seldom(rt):
    report = check_heartbeat(SeldomHeartbeat, reference.HeartbeatMonitor, rt)
    assert _failed(report) == ["heartbeat: still alive two leases later"], report.summary()


def test_heartbeat_checker_rejects_automatic_liveliness(rt):
    report = check_heartbeat(AutomaticHeartbeat, reference.HeartbeatMonitor, rt)
    assert _failed(report) == ["heartbeat: MANUAL_BY_TOPIC with a lease of at most 1 s"], report.summary()


def test_the_solutions_are_offered_by_show_solution():
    for name in ("OdomWatchdog", "SwitchableHeartbeat", "HeartbeatMonitor"):
        assert f"class {name}(Node)" in solution_source("ch08_qos", name)
