"""Checkers of chapter 08a's event exercises, which DDS times on the wall clock.

* :func:`check_deadline_watchdog` runs the student's watchdog against an odometry driver in another
  process that falls silent for a while, and listens for its alarms.
* :func:`check_heartbeat` commands the student's MANUAL_BY_TOPIC heartbeat to stop and start, and
  runs the student's monitor against a heartbeat in another process that stops asserting.

Deadlines and leases are DDS's own timing, so these scenarios run on the wall clock, and each one's
timed criteria are judged by the one timing verdict (:func:`~course_helpers.checks.judge_timed_scenario`):
a criterion missed on a busy machine is measured again, and reported as inconclusive, never as a pass.
Names, details and hints never give the answer: reports say what was measured; hints, where to look.
"""

from __future__ import annotations

import contextlib
import time

from rclpy.node import Node
from rclpy.qos import QoSProfile, QoSReliabilityPolicy

from course_helpers.chapters.ch08_qos.exercise import (
    HEARTBEAT_QOS,
    ODOM_QOS,
    OdomSensor,
    ScheduledHeartbeat,
)
from course_helpers.chapters.ch08_qos.liveliness import seen_seconds, watched_downtime
from course_helpers.checks import CheckReport, judge_timed_scenario, student_node
from course_helpers.checks.ch08_qos import _endpoint_criterion, _mismatches, _name
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import qos_from_dict
from course_helpers.core.waiting import poll_until, wait_until

# ====================================================================== exercise 08.3
WATCHDOG_DEADLINE_S = (0.2, 1.0)  # the deadlines a watchdog of 10 Hz odometry may request
ALARM_MARGIN_S = 1.0  # s an alarm may come later than the requested deadline (judged by the timing verdict)
HANG_S = 60.0  # bounds a hang only: a driver gets through its 4 s schedule


def _run_quiet_spell(rt, label: str, target, params: dict) -> dict[str, float]:
    """Spawn ``target`` (a node with a QuietSpell) and wait until its schedule is done (its own
    report: no sleep here). Returns the monotonic times of its 'start', 'quiet', 'resume' and 'done'
    reports (the channel stamps them with the machine's clock). A driver that never gets through its
    schedule within ``HANG_S`` raises :class:`CourseError` (the student's code cannot stop it: the
    endpoints were checked before)."""
    child = rt.spawn(label, target, params=params, wait_for=f"/{label}")
    try:
        if not poll_until(lambda: child.last("done") is not None, HANG_S):
            what = "never matched the node" if child.last("start") is None else "did not finish its run"
            raise CourseError(f"the checker's {label} {what} within {HANG_S:g} s: run the check again")
        return {tag: child.channel.stamped(tag)[0][0] for tag in ("start", "quiet", "resume", "done")}
    finally:
        rt.stop_child(label)


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
    judge_timed_scenario(report, "the watchdog alarms when, and only when, odometry misses its deadline",
                         lambda: _watchdog_run(rt, node_class, deadline_s))
    return report


def _watchdog_run(rt, node_class, deadline_s: float) -> list:
    """One run of the watchdog's timed scenario, with a new watchdog (a retry starts from scratch)."""
    from std_msgs.msg import String

    with _fresh(rt, node_class, "watchdog_probe") as probe:
        alarms: list[float] = []  # time.monotonic() of each alarm
        probe.create_subscription(String, "/alarm", lambda _m: alarms.append(time.monotonic()),
                                  QoSProfile(depth=100, reliability=QoSReliabilityPolicy.BEST_EFFORT))
        times = _run_quiet_spell(rt, "odom_driver", OdomSensor,
                                 {"speak_s": 1.0, "quiet_s": 1.6, "after_s": 1.5})
        return _judge_alarms([t for t in alarms if t <= times["done"]], times, deadline_s)


def _judge_alarms(alarms: list[float], times: dict[str, float], deadline_s: float) -> list:
    """The three timed criteria of the deadline watchdog, as (name, passed, detail, hint)."""
    early = [t for t in alarms if t < times["quiet"]]
    late = [t - times["quiet"] for t in alarms if t >= times["quiet"]]
    limit = deadline_s + ALARM_MARGIN_S
    stale = [t for t in alarms if times["resume"] + 0.5 < t]
    return [
        ("no alarm while odometry arrives every 0.1 s", not early, f"{len(early)} alarm(s)" if early else "",
         "Section 5: which callback tells the node that the deadline was missed?"),
        (f"an alarm within {limit:g} s after the odometry stopped", bool(late) and late[0] <= limit,
         f"the first came after {late[0]:.2f} s" if late else "no alarm arrived",
         "Section 5: the event callbacks are given when the subscription is created."),
        ("no alarm once odometry flows again", not stale, f"{len(stale)} alarm(s) after it resumed" if stale
         else "", "Alarm only when DDS reports a missed deadline."),
    ]


# ====================================================================== exercise 08.4
HEARTBEAT_MAX_LEASE_S = 1.0
LOST_MARGIN_S = 1.5  # s beyond the lease that a loaded machine may take to notice a silent writer
WATCH_LEASES = 6  # leases for which a heartbeat must stay alive
DOWN_LEASES = 1  # leases of that window without a live writer (time the probe could not see left out)
ALIVE_WITHIN_S = 3.0  # s for a monitor to see an asserting heartbeat alive (judged by the timing verdict)
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
    judge_timed_scenario(report, "the heartbeat stays alive, stops on False and comes back on True",
                         lambda: _heartbeat_run(rt, node_class, lease))


def _heartbeat_run(rt, node_class, lease: float) -> list:
    """One run of the heartbeat's timed scenario, with a node of the student's class and a probe of
    its own (a retry starts from scratch)."""
    from rclpy.event_handler import SubscriptionEventCallbacks
    from std_msgs.msg import Bool, String

    with _fresh(rt, node_class, "heartbeat_probe") as probe:
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
        wait_until(lambda: enable.get_subscription_count() > 0, HANG_S, "the heartbeat's /heartbeat/enable")
        return _heartbeat_scenario(changes, ticks, enable, lease, alive)


@contextlib.contextmanager
def _fresh(rt, node_class, probe_name: str):
    """A new node of ``node_class`` and a probe beside it, for one run of a timed scenario (the class was
    built once already, so building it cannot fail now); yields the probe; removes both afterwards."""
    node = rt.add(node_class, console=False)
    probe = rt.add(Node, probe_name, console=False)
    try:
        yield probe
    finally:
        rt.remove(probe)
        rt.remove(node)


def _heartbeat_scenario(changes: list, ticks: list, enable, lease: float, alive) -> list:
    """The heartbeat's four timed criteria, as (name, passed, detail, hint); those after a failed one
    are not tried (they would say nothing more)."""
    from std_msgs.msg import Bool

    hint = "Section 7: a MANUAL_BY_TOPIC writer must assert itself well within every lease."
    names = ["heartbeat: a monitor sees it alive",
             f"heartbeat: alive through {WATCH_LEASES} leases, with at most {DOWN_LEASES} of them lost",
             f"heartbeat: lost within {lease + LOST_MARGIN_S:g} s of a False on /heartbeat/enable",
             "heartbeat: alive again after a True"]
    results = [(names[0], poll_until(alive, ALIVE_WITHIN_S), "", hint)]
    if results[-1][1]:
        started, window = time.monotonic(), WATCH_LEASES * lease  # of time the probe could see
        poll_until(lambda: seen_seconds(ticks[:], started, time.monotonic(), BLIND_S) >= window, 4 * window)
        # time without a live writer, not one sample: a good heartbeat on a busy machine lapses only briefly
        down, seen = watched_downtime(list(changes), list(ticks), started, time.monotonic(), BLIND_S)
        lapses = sum(lost for when, _alive, lost in list(changes) if when > started)
        results.append((names[1], down <= DOWN_LEASES / WATCH_LEASES * seen,
                        f"its lease ran out {lapses} time(s), {down:.1f} s of {seen:.1f} s without a live "
                        "writer" if lapses else "", hint))
    if results[-1][1]:
        enable.publish(Bool(data=False))
        results.append((names[2], poll_until(lambda: alive(0), lease + LOST_MARGIN_S), "",
                        "What does the node do when False arrives? Nothing may assert its writer then."))
    if results[-1][1]:
        enable.publish(Bool(data=True))
        results.append((names[3], poll_until(alive, ALIVE_WITHIN_S), "",
                        "What does the node do when True arrives after a False?"))
    return results


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
    judge_timed_scenario(report, "the monitor says 'lost' and 'alive' when the heartbeat stops and "
                         "comes back", lambda: _monitor_run(rt, node_class))


def _monitor_run(rt, node_class) -> list:
    """One run of the monitor's timed scenario, with a new monitor (a retry starts from scratch)."""
    from std_msgs.msg import String

    with _fresh(rt, node_class, "heartbeat_status_probe") as probe:
        said: list[tuple[float, str]] = []  # (time.monotonic(), text)
        probe.create_subscription(String, "/heartbeat/status",
                                  lambda m: said.append((time.monotonic(), m.data.strip().lower())),
                                  QoSProfile(depth=100, reliability=QoSReliabilityPolicy.BEST_EFFORT))
        times = _run_quiet_spell(rt, "heartbeat_driver", ScheduledHeartbeat,
                                 {"speak_s": 1.0, "quiet_s": 1.5, "after_s": 1.0})
        return _judge_statuses([s for s in said if s[0] <= times["done"]], times)


def _judge_statuses(said: list[tuple[float, str]], times: dict[str, float]) -> list:
    """The three timed criteria of the liveliness monitor, as (name, passed, detail, hint)."""
    lease = HEARTBEAT_QOS["lease_s"]
    early = [t for t, text in said if text == "lost" and t < times["quiet"]]
    lost = [t - times["quiet"] for t, text in said if text == "lost" and t >= times["quiet"]]
    limit = lease + LOST_MARGIN_S
    back = [t for t, text in said if text == "alive" and t >= times["resume"]]
    return [
        ("monitor: says nothing is lost while the heartbeat asserts every 0.1 s", not early,
         f"'lost' {len(early)} time(s)" if early else "",
         "Section 7: which field of the liveliness status says that a writer was lost?"),
        (f"monitor: publishes 'lost' within {limit:g} s after the heartbeat stopped",
         bool(lost) and lost[0] <= limit, f"after {lost[0]:.2f} s" if lost else "no 'lost' arrived",
         "Section 7: the subscription's liveliness event fires when a writer misses its lease."),
        ("monitor: publishes 'alive' when the heartbeat is back", bool(back),
         "" if back else "no 'alive' after the heartbeat resumed",
         "The same event fires when a writer is alive again: which field says so?"),
    ]
