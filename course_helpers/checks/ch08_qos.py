"""Checkers of chapter 08a's exercises: QoS for four robot channels, and a mismatched subscriber.

* :func:`check_channel_qos` runs the student's profile for each channel in a realistic live
  scenario: a camera driver in another process feeding a slow consumer, a late-joining lidar
  consumer, robot_state_publisher's reliable subscription, a controller that starts after the
  e-stop was pressed.
* :func:`check_mismatched_subscriber` runs the student's node against a best-effort publisher in
  another process and checks that messages arrive.
"""

from __future__ import annotations

import time

from rclpy.node import Node
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_profile_sensor_data,
)
from sensor_msgs.msg import Image

from course_helpers.chapters.ch08_qos import ROBOT_CMD_QOS, RobotCmdPublisher, explain_compatibility, try_pair
from course_helpers.checks import CheckReport
from course_helpers.core.qos_dict import qos_from_dict, qos_to_dict
from course_helpers.core.waiting import poll_until

CHANNELS = ("camera", "lidar", "joint_states", "estop")
CAMERA_RATE_HZ = 30.0
CONSUMER_WORK_S = 0.15  # the perception node's processing time per frame
MAX_FRAME_AGE_S = 0.25


# ====================================================================== nodes
class CameraDriver(Node):
    """Publishes mono8 images of ``width`` x ``height`` at ``rate_hz``, stamped with the time they were
    taken, on camera/image_raw with the QoS given as a dict (a child-process target)."""

    def __init__(self, qos: dict, rate_hz: float = CAMERA_RATE_HZ, width: int = 640, height: int = 480):
        super().__init__("camera_driver")
        self.publisher = self.create_publisher(Image, "camera/image_raw", qos_from_dict(qos))
        self.frame = Image(height=height, width=width, encoding="mono8", step=width,
                           data=bytes(width * height))
        self.timer = self.create_timer(1.0 / rate_hz, self.capture)  # period in seconds

    def capture(self) -> None:
        self.frame.header.stamp = self.get_clock().now().to_msg()
        self.publisher.publish(self.frame)


class SlowConsumer(Node):
    """Takes :data:`CONSUMER_WORK_S` per camera frame and notes each frame's age when work starts.

    Ages (seconds from the frame's stamp) are kept in :attr:`ages` once ``warm_up`` seconds have
    passed since the first frame (the queue fills up meanwhile).
    """

    def __init__(self, qos: QoSProfile, warm_up: float):
        super().__init__("perception")
        self.warm_up = warm_up
        self.first_frame_at: float | None = None  # time.monotonic()
        self.ages: list[float] = []
        self.subscription = self.create_subscription(Image, "camera/image_raw", self.work, qos)

    def work(self, frame: Image) -> None:
        now = self.get_clock().now()
        if self.first_frame_at is None:
            self.first_frame_at = time.monotonic()
        if time.monotonic() - self.first_frame_at > self.warm_up:
            stamp_ns = frame.header.stamp.sec * 10**9 + frame.header.stamp.nanosec
            self.ages.append((now.nanoseconds - stamp_ns) / 1e9)
        time.sleep(CONSUMER_WORK_S)  # stands for the perception work; blocks like real work would

    def watched_for(self, seconds: float) -> bool:
        """True once ``warm_up`` + ``seconds`` have passed since the first frame."""
        started = self.first_frame_at
        return started is not None and time.monotonic() - started >= self.warm_up + seconds


# ====================================================================== helpers
def _live_pair(rt, msg_type, topic, pub_qos, sub_qos, make_msg, published_before=None):
    """:func:`try_pair` on ``topic``; (messages received, incompatible policies at the subscription)."""
    pair = try_pair(rt, pub_qos, sub_qos, topic=topic, msg_type=msg_type, make_message=make_msg,
                    published_before=published_before)
    return pair.received, pair.subscription_events


def _profile_problem(profile) -> str:
    return "" if isinstance(profile, QoSProfile) else f"got {type(profile).__name__}, not a QoSProfile"


def _name(policy) -> str:
    return getattr(policy, "name", str(policy))


def _depth_text(profile: QoSProfile) -> str:
    return "KEEP_ALL" if profile.history == QoSHistoryPolicy.KEEP_ALL else f"KEEP_LAST({profile.depth})"


# ====================================================================== exercise 08.1
def check_channel_qos(profiles: dict, rt=None) -> CheckReport:
    """Check a dict {'camera', 'lidar', 'joint_states', 'estop'} -> QoSProfile, live, channel by channel.

    ``rt`` is the runtime (the kernel's by default). Returns a :class:`CheckReport`.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 08.1 - QoS for four robot channels")
    if not isinstance(profiles, dict):
        report.add("profiles is a dict of channel -> QoSProfile", False, f"got {type(profiles).__name__}",
                   hint="profiles = {'camera': QoSProfile(...), 'lidar': ..., 'joint_states': ..., "
                        "'estop': ...}")
        return report
    problems = [f"{c}: missing" for c in CHANNELS if c not in profiles]
    problems += [f"{c}: {_profile_problem(profiles[c])}" for c in CHANNELS if c in profiles
                 and _profile_problem(profiles[c])]
    if not report.add("one QoSProfile for each of camera, lidar, joint_states, estop", not problems,
                      "; ".join(problems), hint="Fill in every entry of the dict with a QoSProfile(...)."):
        return report
    _check_camera(rt, report, profiles["camera"])
    _check_lidar(rt, report, profiles["lidar"])
    _check_joint_states(rt, report, profiles["joint_states"])
    _check_estop(rt, report, profiles["estop"])
    return report


def _check_camera(rt, report, qos: QoSProfile) -> None:
    report.add("camera: BEST_EFFORT (a late frame is worthless; never stall the stream to resend one)",
               qos.reliability == QoSReliabilityPolicy.BEST_EFFORT, f"you chose {_name(qos.reliability)}",
               hint="Video is replaced 30 times a second: retransmitting an old frame only adds delay.")
    received, bad = _live_pair(rt, Image, "camera/preview", qos, qos_profile_sensor_data,
                               lambda: Image(height=2, width=2, encoding="mono8", step=2, data=bytes(4)))
    report.add("camera: a viewer with qos_profile_sensor_data receives frames", bool(received) and not bad,
               f"incompatible: {', '.join(bad)}" if bad else ("" if received else "nothing arrived"),
               hint="Viewers and perception nodes usually subscribe with the sensor-data profile.")
    if qos.history == QoSHistoryPolicy.KEEP_ALL:
        report.add("camera: frames stay fresh at a slow consumer", False,
                   "KEEP_ALL queues every frame the consumer cannot keep up with",
                   hint="Keep only the newest frame or two: KEEP_LAST with a small depth.")
        return
    ages = _slow_camera_consumer(rt, qos)
    if not ages:
        report.add("camera: frames stay fresh at a slow consumer", False, "no frame reached the consumer",
                   hint="Check that the profile can connect to itself (no deadline shorter than 1/30 s).")
        return
    ages.sort()
    median = ages[len(ages) // 2]
    report.add(f"camera: frames stay fresh at a consumer that needs {CONSUMER_WORK_S * 1000:.0f} ms per "
               f"frame (median age < {MAX_FRAME_AGE_S * 1000:.0f} ms)", median < MAX_FRAME_AGE_S,
               f"{_depth_text(qos)}: frames were {median * 1000:.0f} ms old when processed",
               hint="A deep queue makes the consumer work through old frames. Use a small depth (1-2).")


def _slow_camera_consumer(rt, qos: QoSProfile, seconds: float = 1.5, warm_up: float = 0.7) -> list[float]:
    """A camera driver in a child process at 30 Hz; a :class:`SlowConsumer` in the kernel.

    Returns the age of each frame when the consumer started working on it, skipping the first
    ``warm_up`` seconds.
    """
    consumer = rt.add(SlowConsumer, qos, warm_up, console=False)
    try:
        rt.spawn("camera_driver", CameraDriver, params={"qos": qos_to_dict(qos)}, wait_for="/camera_driver")
        poll_until(lambda: consumer.watched_for(seconds), 10.0)
    finally:
        rt.stop_child("camera_driver")
        rt.remove(consumer)
    return list(consumer.ages)


def _check_lidar(rt, report, qos: QoSProfile) -> None:
    from sensor_msgs.msg import LaserScan

    def scan():
        return LaserScan(angle_min=-3.14, angle_max=3.14, angle_increment=6.28 / 720, range_min=0.1,
                         range_max=30.0, ranges=[5.0] * 720)

    received, bad = _live_pair(rt, LaserScan, "scan", qos, qos_profile_sensor_data, scan)
    report.add("lidar: a consumer with qos_profile_sensor_data receives scans", bool(received) and not bad,
               f"incompatible: {', '.join(bad)}" if bad else ("" if received else "nothing arrived"),
               hint="Most lidar consumers subscribe with the sensor-data profile.")
    received, bad = _live_pair(rt, LaserScan, "scan_late", qos, qos, scan, published_before=3)
    report.add("lidar: a node that starts later gets no old scan", not received and not bad,
               f"it got {received} scan(s) from before it started" if received else
               (f"incompatible: {', '.join(bad)}" if bad else ""),
               hint="A stored scan shows obstacles where they were, not where they are: keep it VOLATILE.")
    small = qos.history == QoSHistoryPolicy.KEEP_LAST and qos.depth <= 10
    report.add("lidar: KEEP_LAST with a small depth (only recent scans matter)", small,
               f"you chose {_depth_text(qos)}", hint="KEEP_LAST with depth 1-10.")


def _check_joint_states(rt, report, qos: QoSProfile) -> None:
    from sensor_msgs.msg import JointState

    def joints():
        return JointState(name=["shoulder", "elbow"], position=[0.1, 0.2])

    rsp = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)  # like robot_state_publisher
    received, bad = _live_pair(rt, JointState, "joint_states", qos, rsp, joints)
    report.add("joint_states: robot_state_publisher's RELIABLE subscription receives them",
               bool(received) and not bad,
               f"incompatible: {', '.join(bad)}" if bad else ("" if received else "nothing arrived"),
               hint="robot_state_publisher subscribes RELIABLE; a BEST_EFFORT publisher cannot match it.")
    received, bad = _live_pair(rt, JointState, "joint_states_monitor", qos, qos_profile_sensor_data, joints)
    report.add("joint_states: a best-effort monitoring tool receives them too", bool(received) and not bad,
               f"incompatible: {', '.join(bad)}" if bad else ("" if received else "nothing arrived"),
               hint="Avoid settings a plain subscriber cannot request (e.g. a deadline or lease).")


def _check_estop(rt, report, qos: QoSProfile) -> None:
    from course_interfaces.msg import EStop

    def pressed():
        return EStop(engaged=True, reason="operator pressed the button", source="operator")

    report.add("estop: RELIABLE (it must never be lost)", qos.reliability == QoSReliabilityPolicy.RELIABLE,
               f"you chose {_name(qos.reliability)}", hint="Safety commands must be delivered: RELIABLE.")
    received, bad = _live_pair(rt, EStop, "estop", qos, qos, pressed, published_before=1)
    report.add("estop: a controller that starts after the button was pressed still gets it",
               bool(received) and not bad,
               f"incompatible: {', '.join(bad)}" if bad else
               ("" if received else "the late joiner got nothing"),
               hint="TRANSIENT_LOCAL makes the publisher keep the last e-stop for nodes that join later.")
    monitor = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    received, bad = _live_pair(rt, EStop, "estop_monitor", qos, monitor, pressed)
    report.add("estop: a safety monitor requesting RELIABLE + TRANSIENT_LOCAL connects",
               bool(received) and not bad,
               f"incompatible: {', '.join(bad)}" if bad else ("" if received else "nothing arrived"),
               hint="The publisher must offer at least what the monitor requests.")


# ====================================================================== exercise 08.2
def check_mismatched_subscriber(node_class, rt=None) -> CheckReport:
    """Start the best-effort /robot_cmd publisher in a child process; add the student's node.

    ``node_class`` is the student's Node subclass (no constructor arguments); ``rt`` the runtime
    (the kernel's by default). Returns a :class:`CheckReport`.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 08.2 - fix the mismatched subscriber")
    rt.spawn("robot_controller", RobotCmdPublisher, wait_for="/robot_controller")
    node = None
    try:
        node = report.run("the node starts", lambda: rt.add(node_class, console=False),
                          hint="Run the class cell first; the constructor must take no arguments.")
        if node is None:
            return report
        subs = [s for s in node.subscriptions if s.topic_name == "/robot_cmd"]
        if not report.add("it subscribes to /robot_cmd", bool(subs),
                          "" if subs else "no subscription on /robot_cmd",
                          hint="self.create_subscription(String, '/robot_cmd', self.on_cmd, qos)"):
            return report
        verdicts = explain_compatibility(qos_from_dict(ROBOT_CMD_QOS), subs[0].qos_profile)
        wrong = [v for v in verdicts if v.compatible is False]
        report.add("its QoS is compatible with what the publisher offers", not wrong,
                   "; ".join(f"{v.policy}: publisher {v.publisher}, you {v.subscription}" for v in wrong),
                   hint="; ".join(v.reason for v in wrong) or "")
        keeps = isinstance(getattr(node, "received", None), list)
        if not report.add("it keeps what it receives in self.received", keeps,
                          hint="Start with self.received = [] and append msg.data in the callback."):
            return report
        poll_until(lambda: len(node.received) >= 3, 3.0)
        got = list(node.received)
        report.add("commands arrive (3 within 3 s)", len(got) >= 3, f"received {len(got)}",
                   hint="No data flows while any policy mismatches; the incompatible-QoS event names it.")
        if got:
            words = {str(g) for g in got}
            report.add("they are the controller's commands", words <= {"forward", "backward", "stop"},
                       f"got {sorted(words)[:3]}", hint="Append msg.data, the command text.")
    finally:
        if node is not None:
            rt.remove(node)
        rt.stop_child("robot_controller")
    return report
