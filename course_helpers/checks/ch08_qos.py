"""Checkers of chapter 08a's exercises: QoS for four robot channels, and a mismatched subscriber.

* :func:`check_channel_qos` runs the student's profile for each channel live: a camera driver in
  another process feeding a slow consumer, a lidar consumer fed by a sensor-data driver and one that
  starts late, a joint state publisher for robot_state_publisher (whose ``SensorDataQoS`` subscription
  any offer satisfies), a controller started after an e-stop.
* :func:`check_mismatched_subscriber` runs the student's node against a best-effort publisher, then
  again as a deployer who overrides its reliability through a parameter, so that it must name the
  policy of the incompatible-QoS event it meets (the diagnosis the exercise asks the node to make).
* the deadline watchdog (08.3) and the heartbeat (08.4), which DDS times on the wall clock, are
  checked in :mod:`course_helpers.checks.ch08_qos_events`.

Names, details and hints never give the answer: reports say what was measured; hints, where to look.
"""

from __future__ import annotations

from rclpy.node import Node
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_profile_sensor_data,
)

from course_helpers.chapters.ch08_qos import explain_compatibility, late_joiner_gets, try_pair
from course_helpers.chapters.ch08_qos.exercise import (
    CONSUMER_WORK_S,
    ROBOT_CMD_QOS,
    CameraDriver,
    RobotCmdPublisher,
    SlowConsumer,
)
from course_helpers.checks import CheckReport, judge_timed_scenario
from course_helpers.core.qos_dict import qos_from_dict, qos_to_dict
from course_helpers.core.waiting import poll_until, wait_until

CHANNELS = ("camera", "lidar", "joint_states", "estop")
MAX_FRAME_AGE_S = 0.25
PROBE_COMMANDS = 6  # the sentinel: the checker's probe hears this many commands (3 or more reach the node)
PAIR_HANG_S = 30.0  # bounds a hang only: a pair that matches exchanges messages in milliseconds
# exercise 08.2's deployer: asks the listener's subscription for reliable delivery (section 10's overrides)
OVERRIDE_PARAMETER = "qos_overrides./robot_cmd.subscription.reliability"
OVERRIDE = f"a deployer can override its reliability ({OVERRIDE_PARAMETER})"
DIAGNOSIS = "it keeps the policy its incompatible-QoS event names in self.incompatible"



# ====================================================================== helpers
def _live_pair(rt, msg_type, topic, pub_qos, sub_qos, make_msg):
    """:func:`try_pair` on ``topic`` until it connects (messages arrive) or both ends report an
    incompatibility; ``PAIR_HANG_S`` only bounds a hang. Returns (messages received, incompatible
    policies at the subscription)."""
    pair = try_pair(rt, pub_qos, sub_qos, seconds=PAIR_HANG_S, topic=topic, msg_type=msg_type,
                    make_message=make_msg)
    return pair.received, pair.subscription_events


def _mismatches(offered: dict, requested: QoSProfile) -> str:
    """'' if ``requested`` is compatible with the ``offered`` QoS dict, else which policies are not."""
    wrong = [v for v in explain_compatibility(qos_from_dict(offered), requested) if v.compatible is False]
    return "; ".join(f"{v.policy}: offered {v.publisher}, you request {v.subscription}" for v in wrong)


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
                   hint="Keep the dict of the starting cell, one entry per channel.")
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


def _connects(received: int, bad: list[str], nothing: str = "nothing arrived") -> tuple[bool, str]:
    """(passed, detail) of a live pair: it passes when something arrived and no policy mismatched."""
    if bad:
        return False, f"incompatible QoS: {', '.join(bad)}"
    return bool(received), "" if received else nothing


def _check_camera(rt, report, qos: QoSProfile) -> None:
    report.add("camera: a lost frame is not resent (a late frame is worthless)",
               qos.reliability == QoSReliabilityPolicy.BEST_EFFORT,
               "" if qos.reliability == QoSReliabilityPolicy.BEST_EFFORT else
               f"with {_name(qos.reliability)} the driver resends lost frames",
               hint="Section 2: which reliability resends what was lost, and what does a resend cost a "
                    "stream that is replaced 30 times a second?")
    fresh = (f"camera: frames stay fresh at a consumer that needs {CONSUMER_WORK_S * 1000:.0f} ms per frame "
             f"(median age < {MAX_FRAME_AGE_S * 1000:.0f} ms)")
    queue_hint = "Section 3 (history and depth): what does a reader that is slower than its publisher get?"
    if qos.history == QoSHistoryPolicy.KEEP_ALL:
        report.add(fresh, False, "KEEP_ALL queues every frame the consumer cannot keep up with",
                   hint=queue_hint)
        return
    def scenario() -> list:
        ages = sorted(_slow_camera_consumer(rt, qos))
        if not ages:
            return [(fresh, False, "no frame reached the consumer",
                     "Section 8: can a publisher and a subscription that both use your profile match?")]
        median = ages[len(ages) // 2]
        return [(fresh, median < MAX_FRAME_AGE_S, f"median age {median * 1000:.0f} ms", queue_hint)]

    judge_timed_scenario(report, "the camera's frames stay fresh at a slow consumer", scenario)


def _slow_camera_consumer(rt, qos: QoSProfile, seconds: float = 1.5, warm_up: float = 0.7) -> list[float]:
    """A camera driver in a child process at 30 Hz; a :class:`SlowConsumer` in the kernel.

    Returns the age of each frame when the consumer started working on it, skipping the first
    ``warm_up`` seconds.
    """
    consumer = rt.add(SlowConsumer, qos, warm_up, console=False)
    try:
        rt.spawn("camera_driver", CameraDriver, params={"qos": qos_to_dict(qos)}, wait_for="/camera_driver")
        poll_until(lambda: consumer.watched_for(seconds), PAIR_HANG_S)  # a hang bound: frames flow at once
    finally:
        rt.stop_child("camera_driver")
        rt.remove(consumer)
    return list(consumer.ages)


def _check_lidar(rt, report, qos: QoSProfile) -> None:
    from sensor_msgs.msg import LaserScan

    def scan():
        return LaserScan(angle_min=-3.14, angle_max=3.14, angle_increment=6.28 / 720, range_min=0.1,
                         range_max=30.0, ranges=[5.0] * 720)

    # most lidar drivers publish with the sensor-data profile; a consumer written with yours must hear them
    passed, detail = _connects(*_live_pair(rt, LaserScan, "scan", qos_profile_sensor_data, qos, scan))
    report.add("lidar: a consumer with your profile receives scans from a driver that publishes with "
               "qos_profile_sensor_data", passed, detail,
               hint="Section 8: a subscription must request no more than the publisher offers; section 9 "
                    "shows what the sensor-data profile offers.")
    _no_old_samples(report, "lidar: a node that starts later gets no old scan", qos,
                    "Section 4 (durability): what does a publisher keep for nodes that join later? A stored "
                    "scan shows obstacles where they were, not where they are.")
    _recent_only(report, "lidar: only recent scans are queued (a depth of 10 at most)", qos)


def _no_old_samples(report, name: str, qos: QoSProfile, hint: str) -> None:
    """By construction: a VOLATILE writer keeps nothing for late joiners (and a VOLATILE reader asks for
    nothing), so only TRANSIENT_LOCAL at both ends would hand a late node old samples."""
    volatile = qos.durability != QoSDurabilityPolicy.TRANSIENT_LOCAL
    report.add(name, volatile, "" if volatile else "TRANSIENT_LOCAL at both ends hands a late joiner the "
               "samples the writer kept", hint=hint)


def _recent_only(report, name: str, qos: QoSProfile) -> None:
    small = qos.history == QoSHistoryPolicy.KEEP_LAST and qos.depth <= 10
    report.add(name, small, "" if small else f"it queues {_depth_text(qos)}",
               hint="Section 3 (history and depth).")


def _check_joint_states(rt, report, qos: QoSProfile) -> None:
    # robot_state_publisher subscribes with rclcpp::SensorDataQoS() (best effort, volatile, depth 5;
    # src/robot_state_publisher.cpp): it requests the least of every policy, so whatever a publisher
    # offers connects, and connecting is no criterion. What the profile decides is judged.
    _no_old_samples(report, "joint_states: a node that starts later gets no old state", qos,
                    "Section 4 (durability): an old joint state puts the arm where it was, not where it is.")
    _recent_only(report, "joint_states: only recent states are queued (a depth of 10 at most)", qos)


def _check_estop(rt, report, qos: QoSProfile) -> None:
    from course_interfaces.msg import EStop

    def pressed():
        return EStop(engaged=True, reason="operator pressed the button", source="operator")

    never_lost = qos.reliability == QoSReliabilityPolicy.RELIABLE
    report.add("estop: a press lost on the way is sent again", never_lost,
               "" if never_lost else f"with {_name(qos.reliability)} a lost press is gone",
               hint="Section 2 (reliability).")
    late = "estop: a controller that starts after the button was pressed still gets it"
    if never_lost:  # a reliable pair says for certain what a late joiner gets (no window)
        got = late_joiner_gets(rt, qos, [pressed()], EStop(reason="checker's sentinel"), topic="estop")
        report.add(late, got == 1, "" if got else "the late joiner got nothing",
                   hint="Section 4 (durability): late joiners.")
    else:
        report.add(late, False, f"with {_name(qos.reliability)} nothing promises it the press",
                   hint="Section 4 (durability): late joiners; section 2: what does best effort promise?")
    monitor = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    passed, detail = _connects(*_live_pair(rt, EStop, "estop_monitor", qos, monitor, pressed))
    report.add("estop: a safety monitor requesting RELIABLE + TRANSIENT_LOCAL connects", passed, detail,
               hint="Section 8: the publisher must offer at least what the monitor requests.")


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
                          hint="Keep the topic of the starting code's subscription."):
            return report
        verdicts = explain_compatibility(qos_from_dict(ROBOT_CMD_QOS), subs[0].qos_profile)
        wrong = [v.policy for v in verdicts if v.compatible is False]
        report.add("its QoS is compatible with what the publisher offers", not wrong,
                   f"the policies that do not match: {', '.join(wrong)}" if wrong else "",
                   hint="Find out what the controller offers (the exercise says how), then request no more "
                        "than that (section 8).")
        keeps = isinstance(getattr(node, "received", None), list)
        if not report.add("it keeps what it receives in self.received", keeps,
                          hint="Keep self.received, the list of the starting code, and add to it in the "
                               "callback."):
            return report
        got = _commands_heard(rt, node) if not wrong else []
        report.add("its callback gets the commands", len(got) >= 3, f"received {len(got)}",
                   hint="No data flows while any policy mismatches (section 8), and the callback must keep "
                        "what arrives.")
        if got:
            words = {str(g) for g in got}
            report.add("they are the controller's commands", words <= {"forward", "backward", "stop"},
                       f"got {sorted(words)[:3]}",
                       hint="Look at what the callback keeps: the controller sends command words.")
        rt.remove(node)
        node = None
        if wrong:
            for name in (OVERRIDE, DIAGNOSIS):
                report.add(name, False, "not tried: its QoS must match the controller's first",
                           hint="Fix the QoS criterion above first.")
        else:
            _check_diagnosis(rt, report, node_class)
    finally:
        if node is not None:
            rt.remove(node)
        rt.stop_child("robot_controller")
    return report


def _check_diagnosis(rt, report, node_class) -> None:
    """The listener again, as a deployer who asks for reliable delivery runs it (a parameter override,
    section 10): the controller cannot serve that, and the node must keep the policy its
    incompatible-QoS event names. No data flows, so "nothing kept" is judged with a sentinel."""
    from rclpy.parameter import Parameter

    override = Parameter(OVERRIDE_PARAMETER, value="reliable")
    node = report.run(OVERRIDE, lambda: rt.add(node_class, parameter_overrides=[override], console=False),
                      hint="Keep the starting code's constructor: it hands parameter_overrides on to Node "
                           "(section 10).")
    if node is None:
        report.add(DIAGNOSIS, False, "not tried: the node must start with the override first",
                   hint="Fix the criterion above first.")
        return
    try:
        subs = [s for s in node.subscriptions if s.topic_name == "/robot_cmd"]
        overridden = bool(subs) and subs[0].qos_profile.reliability == QoSReliabilityPolicy.RELIABLE
        if not report.add(OVERRIDE, overridden, "" if overridden else "the parameter did not change the "
                          "subscription's reliability",
                          hint="Keep the starting code's qos_overriding_options on the subscription "
                               "(section 10)."):
            report.add(DIAGNOSIS, False, "not tried: the override must reach the subscription first",
                       hint="Fix the criterion above first.")
            return
        named = _incompatibility_a_probe_sees(rt, subs[0].qos_profile)
        kept = getattr(node, "incompatible", None)
        if not isinstance(kept, list):
            report.add(DIAGNOSIS, False, "the node has no list self.incompatible",
                       hint="Keep self.incompatible, the list of the starting code.")
            return
        names = sorted({_policy_kind_name(k) for k in kept})
        report.add(DIAGNOSIS, named in names,
                   f"the event named {named}; self.incompatible holds {', '.join(names) or 'nothing'}",
                   hint="Section 5 lists the event callbacks a subscription takes; the status an "
                        "incompatible-QoS callback gets says which policy failed (section 8).")
    finally:
        rt.remove(node)


def _incompatibility_a_probe_sees(rt, qos: QoSProfile) -> str:
    """The policy an incompatible-QoS event names for a probe subscription of the checker's that asks
    for ``qos`` (the student's overridden profile), created after the student's: a sentinel. This
    process's participant knows the controller's writer already (it heard its commands), and a new
    reader is paired with the writers it knows while it is created (Fast DDS's EDP), so the student's
    event was ready before the probe's. Once the probe's callback ran, one more round of the
    runtime's single-threaded executor has run the student's too. ``PAIR_HANG_S`` bounds a hang only."""
    from rclpy.event_handler import SubscriptionEventCallbacks
    from std_msgs.msg import String

    named: list[str] = []
    probe = rt.add(Node, "robot_cmd_diagnosis_probe", console=False)
    try:
        probe.create_subscription(
            String, "/robot_cmd", lambda _msg: None, qos,
            event_callbacks=SubscriptionEventCallbacks(
                incompatible_qos=lambda status: named.append(_policy_kind_name(status.last_policy_kind))))
        wait_until(lambda: named, PAIR_HANG_S, "the checker's own incompatible-QoS event")
        rt.settle_callbacks()
        return named[0]
    finally:
        rt.remove(probe)


def _policy_kind_name(value) -> str:
    """'RELIABILITY' for QoSPolicyKind.RELIABILITY, its number, or a text naming it in any case."""
    from rclpy.qos import QoSPolicyKind

    if isinstance(value, str):
        return value.rsplit(".", 1)[-1].strip().upper()
    try:
        return QoSPolicyKind(int(value)).name
    except (TypeError, ValueError):
        return type(value).__name__


def _commands_heard(rt, node) -> list:
    """What the student's node kept by the time a probe of the checker's, in the same process and the
    same executor, has heard ``PROBE_COMMANDS`` commands after it: a sentinel, not a window. Both
    readers are handed each sample by the same receive, and a single-threaded executor runs every
    callback of one wait before it waits again, so by then the student's callback has run for the
    commands before the probe's last ones. ``PAIR_HANG_S`` only bounds a hang."""
    from std_msgs.msg import String

    heard: list = []
    probe = rt.add(Node, "robot_cmd_probe", console=False)
    try:
        probe.create_subscription(String, "/robot_cmd", heard.append, qos_from_dict(ROBOT_CMD_QOS))
        wait_until(lambda: len(heard) >= PROBE_COMMANDS, PAIR_HANG_S, "the checker's own commands")
        return list(node.received)
    finally:
        rt.remove(probe)


def _endpoint_criterion(report, name: str, entities, topic: str, msg_type, hint: str) -> list:
    """Add the criterion ``name``: ``entities`` (a node's publishers or subscriptions) include one on
    ``topic`` of ``msg_type``. Returns the ones found, or [] if the criterion failed."""
    found, problem = [e for e in entities if e.topic_name == topic], ""
    if not found:
        problem = f"none on {topic}"
    elif found[0].msg_type is not msg_type:
        found, problem = [], f"its type is {found[0].msg_type.__name__}, not {msg_type.__name__}"
    report.add(name, not problem, problem, hint=hint)
    return found


