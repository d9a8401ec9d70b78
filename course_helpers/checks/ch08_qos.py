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

from course_helpers.checks import CheckReport

CHANNELS = ("camera", "lidar", "joint_states", "estop")
CAMERA_RATE_HZ = 30.0
CONSUMER_WORK_S = 0.15  # the perception node's processing time per frame
MAX_FRAME_AGE_S = 0.25


# ====================================================================== child: a camera driver
def make_camera_driver(qos: dict, rate_hz: float = CAMERA_RATE_HZ, width: int = 640, height: int = 480):
    """Child-process target: a camera driver publishing mono8 images stamped with the time they were taken."""
    from sensor_msgs.msg import Image

    from course_helpers.chapters.ch08_qos.qos import qos_from_dict

    node = Node("camera_driver")
    publisher = node.create_publisher(Image, "camera/image_raw", qos_from_dict(qos))
    frame = Image(height=height, width=width, encoding="mono8", step=width, data=bytes(width * height))

    def capture():
        frame.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(frame)

    node.timer = node.create_timer(1.0 / rate_hz, capture)
    return node


# ====================================================================== helpers
def _live_pair(rt, msg_type, topic, pub_qos, sub_qos, make_msg, seconds=1.0, before_subscribing=None):
    """Publish on ``topic`` with ``pub_qos`` every 50 ms; a subscription with ``sub_qos`` listens.

    ``before_subscribing``: number of messages published once before the subscription exists
    (then the publisher stays silent: a late joiner can only get stored messages).
    Returns (messages received, incompatible policies seen by the subscription).
    """
    received, incompatible = [], []
    pub_node = rt.node("qos_check_publisher", console=False)
    publisher = pub_node.create_publisher(msg_type, topic, pub_qos)
    if before_subscribing is not None:
        for _ in range(before_subscribing):
            publisher.publish(make_msg())
        time.sleep(0.3)
    else:
        pub_node.create_timer(0.05, lambda: publisher.publish(make_msg()))
    sub_node = rt.node("qos_check_subscriber", console=False)
    sub_node.create_subscription(
        msg_type, topic, received.append, sub_qos,
        event_callbacks=SubscriptionEventCallbacks(
            incompatible_qos=lambda s: incompatible.append(qos_policy_name_from_kind(s.last_policy_kind))))
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not incompatible and len(received) < 5:
            time.sleep(0.02)
        if before_subscribing is not None:
            time.sleep(max(0.0, end - time.monotonic()))
    finally:
        rt.remove(pub_node)
        rt.remove(sub_node)
    return received, sorted(set(incompatible))


def _profile_problem(profile) -> str:
    return "" if isinstance(profile, QoSProfile) else f"got {type(profile).__name__}, not a QoSProfile"


def _name(policy) -> str:
    return getattr(policy, "name", str(policy))


def _depth_text(profile: QoSProfile) -> str:
    return "KEEP_ALL" if profile.history == QoSHistoryPolicy.KEEP_ALL else f"KEEP_LAST({profile.depth})"


# ====================================================================== exercise 08.1
def check_channel_qos(profiles: dict, rt=None) -> CheckReport:
    """Check a dict {'camera', 'lidar', 'joint_states', 'estop'} -> QoSProfile, live, channel by channel."""
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
    from sensor_msgs.msg import Image

    from course_helpers.chapters.ch08_qos.qos import qos_to_dict

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
    ages = _slow_camera_consumer(rt, qos, qos_to_dict(qos))
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


def _slow_camera_consumer(rt, qos: QoSProfile, qos_dict: dict, seconds: float = 1.5,
                          warm_up: float = 0.7) -> list[float]:
    """A camera driver in a child process at 30 Hz; a consumer in the kernel taking 150 ms per frame.

    Returns the age (now - stamp) of each frame when the consumer started working on it,
    skipping the first ``warm_up`` seconds (the queue fills up).
    """
    from sensor_msgs.msg import Image

    ages: list[float] = []
    node = rt.node("perception", console=False)
    clock = node.get_clock()
    started = [None]

    def work(frame):
        now = clock.now()
        if started[0] is None:
            started[0] = time.monotonic()
        if time.monotonic() - started[0] > warm_up:
            stamp_ns = frame.header.stamp.sec * 10**9 + frame.header.stamp.nanosec
            ages.append((now.nanoseconds - stamp_ns) / 1e9)
        time.sleep(CONSUMER_WORK_S)  # stands for the perception work; blocks like real work would

    node.create_subscription(Image, "camera/image_raw", work, qos)
    try:
        rt.spawn("camera_driver", "course_helpers.checks.ch08_qos:make_camera_driver", params={"qos": qos_dict},
                 wait_for="/camera_driver")
        end = time.monotonic() + 10.0
        while time.monotonic() < end and (started[0] is None
                                          or time.monotonic() - started[0] < warm_up + seconds):
            time.sleep(0.05)
    finally:
        rt.stop_child("camera_driver")
        rt.remove(node)
    return ages


def _check_lidar(rt, report, qos: QoSProfile) -> None:
    from sensor_msgs.msg import LaserScan

    def scan():
        return LaserScan(angle_min=-3.14, angle_max=3.14, angle_increment=6.28 / 720, range_min=0.1,
                         range_max=30.0, ranges=[5.0] * 720)

    received, bad = _live_pair(rt, LaserScan, "scan", qos, qos_profile_sensor_data, scan)
    report.add("lidar: a consumer with qos_profile_sensor_data receives scans", bool(received) and not bad,
               f"incompatible: {', '.join(bad)}" if bad else ("" if received else "nothing arrived"),
               hint="Most lidar consumers subscribe with the sensor-data profile.")
    received, bad = _live_pair(rt, LaserScan, "scan_late", qos, qos, scan, before_subscribing=3)
    report.add("lidar: a node that starts later gets no old scan", not received and not bad,
               f"it got {len(received)} scan(s) from before it started" if received else
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
    received, bad = _live_pair(rt, EStop, "estop", qos, qos, pressed, before_subscribing=1)
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
    """Start the best-effort /robot_cmd publisher in a child process; add the student's node."""
    from course_helpers.chapters.ch08_qos.qos import ROBOT_CMD_QOS, explain_compatibility, qos_from_dict
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 08.2 - fix the mismatched subscriber")
    rt.spawn("robot_controller", "course_helpers.chapters.ch08_qos.qos:make_robot_cmd_publisher", wait_for="/robot_controller")
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
        end = time.monotonic() + 3.0
        while time.monotonic() < end and len(node.received) < 3:
            time.sleep(0.05)
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
