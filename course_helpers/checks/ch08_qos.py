"""Checkers of chapter 08a's exercises: QoS for four robot channels, and a mismatched subscriber.

* :func:`check_channel_qos` runs the student's profile for each channel live: a camera driver in
  another process feeding a slow consumer, a lidar consumer fed by a sensor-data driver and one that
  starts late, robot_state_publisher's reliable subscription, a controller started after an e-stop.
* :func:`check_mismatched_subscriber` runs the student's node against a best-effort publisher.
* :func:`check_deadline_watchdog` runs the student's watchdog against an odometry driver in another
  process that falls silent for a while, and listens for its alarms.
* :func:`check_heartbeat` commands the student's MANUAL_BY_TOPIC heartbeat to stop and start, and
  runs the student's monitor against a heartbeat in another process that stops asserting.

Names, details and hints never give the answer: reports say what was measured; hints, where to look.
"""

from __future__ import annotations

import time

from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_profile_sensor_data,
)

from course_helpers.chapters.ch08_qos import explain_compatibility, try_pair
from course_helpers.chapters.ch08_qos.exercise import (
    CONSUMER_WORK_S,
    HEARTBEAT_QOS,
    ODOM_QOS,
    ROBOT_CMD_QOS,
    CameraDriver,
    OdomSensor,
    RobotCmdPublisher,
    ScheduledHeartbeat,
    SlowConsumer,
)
from course_helpers.chapters.ch08_qos.liveliness import seen_seconds, watched_downtime
from course_helpers.checks import CheckReport, student_node
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import qos_from_dict, qos_to_dict
from course_helpers.core.waiting import poll_until

CHANNELS = ("camera", "lidar", "joint_states", "estop")
MAX_FRAME_AGE_S = 0.25


# ====================================================================== helpers
def _live_pair(rt, msg_type, topic, pub_qos, sub_qos, make_msg, published_before=None):
    """:func:`try_pair` on ``topic``; (messages received, incompatible policies at the subscription)."""
    pair = try_pair(rt, pub_qos, sub_qos, topic=topic, msg_type=msg_type, make_message=make_msg,
                    published_before=published_before)
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
    ages = _slow_camera_consumer(rt, qos)
    if not ages:
        report.add(fresh, False, "no frame reached the consumer",
                   hint="Section 8: can a publisher and a subscription that both use your profile match?")
        return
    ages.sort()
    median = ages[len(ages) // 2]
    report.add(fresh, median < MAX_FRAME_AGE_S, f"median age {median * 1000:.0f} ms", hint=queue_hint)


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

    # most lidar drivers publish with the sensor-data profile; a consumer written with yours must hear them
    passed, detail = _connects(*_live_pair(rt, LaserScan, "scan", qos_profile_sensor_data, qos, scan))
    report.add("lidar: a consumer with your profile receives scans from a driver that publishes with "
               "qos_profile_sensor_data", passed, detail,
               hint="Section 8: a subscription must request no more than the publisher offers; section 9 "
                    "shows what the sensor-data profile offers.")
    received, bad = _live_pair(rt, LaserScan, "scan_late", qos, qos, scan, published_before=3)
    report.add("lidar: a node that starts later gets no old scan", not received and not bad,
               f"it got {received} scan(s) from before it started" if received else
               (f"incompatible QoS: {', '.join(bad)}" if bad else ""),
               hint="Section 4 (durability): what does a publisher keep for nodes that join later? A stored "
                    "scan shows obstacles where they were, not where they are.")
    small = qos.history == QoSHistoryPolicy.KEEP_LAST and qos.depth <= 10
    report.add("lidar: only recent scans are queued (a depth of 10 at most)", small,
               "" if small else f"it queues {_depth_text(qos)}", hint="Section 3 (history and depth).")


def _check_joint_states(rt, report, qos: QoSProfile) -> None:
    from sensor_msgs.msg import JointState

    def joints():
        return JointState(name=["shoulder", "elbow"], position=[0.1, 0.2])

    rsp = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)  # like robot_state_publisher
    passed, detail = _connects(*_live_pair(rt, JointState, "joint_states", qos, rsp, joints))
    report.add("joint_states: robot_state_publisher's RELIABLE subscription receives them", passed, detail,
               hint="Section 8: the publisher must offer at least what robot_state_publisher requests.")


def _check_estop(rt, report, qos: QoSProfile) -> None:
    from course_interfaces.msg import EStop

    def pressed():
        return EStop(engaged=True, reason="operator pressed the button", source="operator")

    never_lost = qos.reliability == QoSReliabilityPolicy.RELIABLE
    report.add("estop: a press lost on the way is sent again", never_lost,
               "" if never_lost else f"with {_name(qos.reliability)} a lost press is gone",
               hint="Section 2 (reliability).")
    passed, detail = _connects(*_live_pair(rt, EStop, "estop", qos, qos, pressed, published_before=1),
                               nothing="the late joiner got nothing")
    report.add("estop: a controller that starts after the button was pressed still gets it", passed, detail,
               hint="Section 4 (durability): late joiners.")
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
        poll_until(lambda: len(node.received) >= 3, 3.0)
        got = list(node.received)
        report.add("its callback gets the commands (3 within 3 s)", len(got) >= 3, f"received {len(got)}",
                   hint="No data flows while any policy mismatches (section 8), and the callback must keep "
                        "what arrives.")
        if got:
            words = {str(g) for g in got}
            report.add("they are the controller's commands", words <= {"forward", "backward", "stop"},
                       f"got {sorted(words)[:3]}",
                       hint="Look at what the callback keeps: the controller sends command words.")
    finally:
        if node is not None:
            rt.remove(node)
        rt.stop_child("robot_controller")
    return report


# ====================================================================== exercise 08.3
WATCHDOG_DEADLINE_S = (0.2, 1.0)  # the deadlines a watchdog of 10 Hz odometry may request
ALARM_MARGIN_S = 1.0  # s an alarm may come later than the requested deadline (a loaded machine)
AFTER_RESUME_S = 1.5  # s watched after the driver speaks again


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


def _run_quiet_spell(rt, label: str, target, params: dict, after_s: float) -> dict[str, float]:
    """Spawn ``target`` (a node with a QuietSpell), wait until it spoke again plus ``after_s``.

    Returns the monotonic times of its 'start', 'quiet' and 'resume' reports, and the 'end' of the
    watch. The student's code cannot stop the driver's run (the endpoints were checked before), so
    a run that does not finish is the machine's trouble: a :class:`CourseError` says so.
    """
    child = rt.spawn(label, target, params=params, wait_for=f"/{label}")
    try:
        if not poll_until(lambda: child.last("resume") is not None, 20.0):
            what = "never matched the node" if child.last("start") is None else "did not finish its run"
            raise CourseError(f"the checker's {label} {what} within 20 s (a machine too busy?): run the "
                              "check again")
        times = {tag: child.channel.stamped(tag)[0][0] for tag in ("start", "quiet", "resume")}
        time.sleep(max(0.0, times["resume"] + after_s - time.monotonic()))  # the last phase runs
    finally:
        rt.stop_child(label)
    times["end"] = times["resume"] + after_s
    return times


def check_deadline_watchdog(node_class, rt=None) -> CheckReport:
    """Check a watchdog node class: its /odom subscription requests a deadline, it has no timer of its
    own, and it publishes a String on /alarm when the requested deadline is missed (and only then).

    An odometry driver in a child process publishes at 10 Hz, falls silent for 1.6 s, then speaks
    again. ``rt`` is the runtime (the kernel's by default). Returns a :class:`CheckReport`.
    """
    from nav_msgs.msg import Odometry
    from std_msgs.msg import String

    from course_helpers.core.qos_dict import duration_seconds
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 08.3 - a deadline watchdog for /odom")
    with student_node(report, rt, node_class, "watchdog_probe") as (node, probe):
        if node is None:
            return report
        subs = _endpoint_criterion(
            report, "it subscribes to /odom (nav_msgs/msg/Odometry)", node.subscriptions, "/odom", Odometry,
            "Keep the topic and type of the starting code's subscription.")
        if not subs:
            return report
        deadline_s = duration_seconds(subs[0].qos_profile.deadline)
        low, high = WATCHDOG_DEADLINE_S
        if not report.add(f"the subscription requests a deadline ({low:g} s to {high:g} s)",
                          low <= deadline_s <= high,
                          f"it requests {deadline_s:g} s" if deadline_s else "it requests no deadline",
                          hint="Section 5 (deadline): where does a subscription state the longest gap it "
                               "accepts?"):
            return report
        timers = len(list(node.timers))
        if not report.add("it leaves the watching to DDS (no timer of its own)", not timers,
                          f"it has {timers} timer(s)" if timers else "",
                          hint="Section 5: DDS measures the gaps and tells the node through an event."):
            return report
        wrong = _mismatches(ODOM_QOS, subs[0].qos_profile)
        if not report.add("its QoS is compatible with the odometry driver (reliable, deadline 0.2 s)",
                          not wrong, wrong,
                          hint="Section 8: request no more than the driver offers."):
            return report
        if not _endpoint_criterion(
            report, "it publishes on /alarm (std_msgs/msg/String)", node.publishers, "/alarm", String,
            "Keep the topic and type of the starting code's alarm publisher."):
            return report
        alarms: list[float] = []  # time.monotonic() of each alarm
        probe.create_subscription(String, "/alarm", lambda _m: alarms.append(time.monotonic()),
                                  QoSProfile(depth=100, reliability=QoSReliabilityPolicy.BEST_EFFORT))
        times = _run_quiet_spell(rt, "odom_driver", OdomSensor, {"speak_s": 1.0, "quiet_s": 1.6},
                                 AFTER_RESUME_S)
        _judge_alarms([t for t in alarms if t <= times["end"]], times, deadline_s, report)
    return report


def _judge_alarms(alarms: list[float], times: dict[str, float], deadline_s: float, report) -> None:
    early = [t for t in alarms if t < times["quiet"]]
    report.add("no alarm while odometry arrives every 0.1 s", not early,
               f"{len(early)} alarm(s)" if early else "",
               hint="Section 5: which callback tells the node that the deadline was missed?")
    late = [t - times["quiet"] for t in alarms if t >= times["quiet"]]
    limit = deadline_s + ALARM_MARGIN_S
    report.add(f"an alarm within {limit:g} s after the odometry stopped", bool(late) and late[0] <= limit,
               f"the first came after {late[0]:.2f} s" if late else "no alarm arrived",
               hint="Section 5: the event callbacks are given when the subscription is created.")
    stale = [t for t in alarms if times["resume"] + 0.5 < t]
    report.add("no alarm once odometry flows again", not stale,
               f"{len(stale)} alarm(s) after it resumed" if stale else "",
               hint="Alarm only when DDS reports a missed deadline.")


# ====================================================================== exercise 08.4
HEARTBEAT_MAX_LEASE_S = 1.0
LOST_MARGIN_S = 1.5  # s beyond the lease that a loaded machine may take to notice a silent writer
WATCH_LEASES = 6  # leases for which a heartbeat must stay alive
DOWN_LEASES = 1  # leases of that window without a live writer (time the probe could not see left out)
TICK_S, BLIND_S = 0.05, 0.15  # the probe's own timer; a gap above BLIND_S: its events came late, unjudged


def check_heartbeat(heartbeat_class, monitor_class, rt=None) -> CheckReport:
    """Check a MANUAL_BY_TOPIC heartbeat node class and a liveliness monitor node class.

    The heartbeat must assert liveliness on /heartbeat, stop when a std_msgs/Bool False arrives on
    /heartbeat/enable and start again on True. The monitor runs against a heartbeat in a child
    process that stops asserting for 1.5 s, and must publish 'lost' and then 'alive' on
    /heartbeat/status. ``rt`` is the runtime (the kernel's by default). Returns a :class:`CheckReport`.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 08.4 - a MANUAL_BY_TOPIC heartbeat and its monitor")
    _check_heartbeat_node(rt, report, heartbeat_class)
    _check_monitor_node(rt, report, monitor_class)
    return report


def _check_heartbeat_node(rt, report, node_class) -> None:
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.qos import QoSLivelinessPolicy
    from std_msgs.msg import Bool, String

    from course_helpers.core.qos_dict import duration_seconds

    with student_node(report, rt, node_class, "heartbeat_probe") as (node, probe):
        if node is None:
            return
        pubs = _endpoint_criterion(
            report, "heartbeat: it has a publisher on /heartbeat (std_msgs/msg/String)",
            node.publishers, "/heartbeat", String, "Section 7 ends with a heartbeat node: start from it.")
        if not pubs:
            return
        offered = pubs[0].qos_profile
        lease = duration_seconds(offered.liveliness_lease_duration)
        manual = offered.liveliness == QoSLivelinessPolicy.MANUAL_BY_TOPIC
        if not report.add(f"heartbeat: MANUAL_BY_TOPIC with a lease of at most {HEARTBEAT_MAX_LEASE_S:g} s",
                          manual and 0 < lease <= HEARTBEAT_MAX_LEASE_S,
                          f"it offers {_name(offered.liveliness)}, lease "
                          f"{f'{lease:g} s' if lease else 'infinite'}",
                          hint="Section 7: which liveliness makes the writer itself prove it is alive, and "
                               "which policy sets the lease?"):
            return
        if not _endpoint_criterion(
            report, "heartbeat: it subscribes to /heartbeat/enable (std_msgs/msg/Bool)",
            node.subscriptions, "/heartbeat/enable", Bool, "The exercise names the topic and its type."):
            return
        changes: list[tuple[float, int, int]] = []  # per liveliness event: (monotonic s, alive, lost)

        def alive(count: int = 1) -> bool:
            return (changes[-1][1] if changes else 0) == count

        probe.create_subscription(
            String, "/heartbeat", lambda _m: None,
            qos_from_dict({"depth": 1, "liveliness": "manual_by_topic", "lease_s": HEARTBEAT_MAX_LEASE_S}),
            event_callbacks=SubscriptionEventCallbacks(liveliness=lambda status: changes.append(
                (time.monotonic(), status.alive_count, max(0, status.not_alive_count_change)))))
        enable = probe.create_publisher(Bool, "/heartbeat/enable", 10)
        ticks: list[float] = []  # when the probe's executor ran its own timer
        probe.create_timer(TICK_S, lambda: ticks.append(time.monotonic()))
        hint = "Section 7: a MANUAL_BY_TOPIC writer must assert itself well within every lease."
        if not report.add("heartbeat: a monitor sees it alive", poll_until(alive, 5.0), hint=hint):
            return
        started, window = time.monotonic(), WATCH_LEASES * lease  # of time the probe could see
        poll_until(lambda: seen_seconds(ticks[:], started, time.monotonic(), BLIND_S) >= window, 4 * window)
        # time without a live writer, not one sample: a good heartbeat on a busy machine lapses only briefly
        down, seen = watched_downtime(list(changes), list(ticks), started, time.monotonic(), BLIND_S)
        lapses = sum(lost for when, _alive, lost in list(changes) if when > started)
        if not report.add(f"heartbeat: alive through {WATCH_LEASES} leases, with at most {DOWN_LEASES} of "
                          "them lost", down <= DOWN_LEASES / WATCH_LEASES * seen,
                          f"its lease ran out {lapses} time(s), {down:.1f} s of {seen:.1f} s without a live "
                          "writer" if lapses else "", hint=hint):
            return
        poll_until(lambda: enable.get_subscription_count() > 0, 3.0)
        enable.publish(Bool(data=False))
        report.add(f"heartbeat: lost within {lease + LOST_MARGIN_S:g} s of a False on /heartbeat/enable",
                   poll_until(lambda: alive(0), lease + LOST_MARGIN_S),
                   hint="What does the node do when False arrives? Nothing may assert its writer then.")
        enable.publish(Bool(data=True))
        report.add("heartbeat: alive again after a True", poll_until(alive, 3.0),
                   hint="What does the node do when True arrives after a False?")


def _check_monitor_node(rt, report, node_class) -> None:
    from std_msgs.msg import String

    with student_node(report, rt, node_class, "heartbeat_status_probe") as (node, probe):
        if node is None:
            return
        subs = _endpoint_criterion(
            report, "monitor: it subscribes to /heartbeat (std_msgs/msg/String)",
            node.subscriptions, "/heartbeat", String,
            "Section 7's heartbeat watcher subscribes the same way.")
        if not subs:
            return
        wrong = _mismatches(HEARTBEAT_QOS, subs[0].qos_profile)
        if not report.add("monitor: compatible with a MANUAL_BY_TOPIC heartbeat, lease 0.5 s", not wrong,
                          wrong, hint="Section 8: request no more than the heartbeat offers."):
            return
        if not _endpoint_criterion(
            report, "monitor: it publishes on /heartbeat/status (std_msgs/msg/String)",
            node.publishers, "/heartbeat/status", String, "The exercise names the topic and its type."):
            return
        said: list[tuple[float, str]] = []  # (time.monotonic(), text)
        probe.create_subscription(String, "/heartbeat/status",
                                  lambda m: said.append((time.monotonic(), m.data.strip().lower())),
                                  QoSProfile(depth=100, reliability=QoSReliabilityPolicy.BEST_EFFORT))
        times = _run_quiet_spell(rt, "heartbeat_driver", ScheduledHeartbeat, {"speak_s": 1.0, "quiet_s": 1.5},
                                 1.0)
        _judge_statuses([s for s in said if s[0] <= times["end"]], times, report)


def _judge_statuses(said: list[tuple[float, str]], times: dict[str, float], report) -> None:
    lease = HEARTBEAT_QOS["lease_s"]
    early = [t for t, text in said if text == "lost" and t < times["quiet"]]
    report.add("monitor: says nothing is lost while the heartbeat asserts every 0.1 s", not early,
               f"'lost' {len(early)} time(s)" if early else "",
               hint="Section 7: which field of the liveliness status says that a writer was lost?")
    lost = [t - times["quiet"] for t, text in said if text == "lost" and t >= times["quiet"]]
    limit = lease + LOST_MARGIN_S
    report.add(f"monitor: publishes 'lost' within {limit:g} s after the heartbeat stopped",
               bool(lost) and lost[0] <= limit,
               f"after {lost[0]:.2f} s" if lost else "no 'lost' arrived",
               hint="Section 7: the subscription's liveliness event fires when a writer misses its lease.")
    back = [t for t, text in said if text == "alive" and t >= times["resume"]]
    report.add("monitor: publishes 'alive' when the heartbeat is back", bool(back),
               "" if back else "no 'alive' after the heartbeat resumed",
               hint="The same event fires when a writer is alive again: which field says so?")
