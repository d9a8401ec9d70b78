"""Checker of chapter 01 (architecture): a watchdog that notices a crashed talker by its silence.

The student's node, ``silence_watchdog``, subscribes to ``chatter`` (std_msgs/String,
'<sender>: <count>') and publishes the name of every sender that went quiet on ``silent_talkers``.
The checker starts two talker processes, kills one with SIGKILL, and checks that the watchdog
reports it, once, long before the ROS graph forgets the dead node (the talkers announce a 5 s
lease, so a crashed one stays listed that long, and leaves before a second run of the notebook
could list it twice). Then it talks in the dead talker's name for a moment, as a restarted talker
would, and falls silent again: the watchdog must report that new silence too.
"""

from __future__ import annotations

import time

from std_msgs.msg import String

from course_helpers.chapters.ch01_architecture import NamedTalker, short_lease_env
from course_helpers.checks import CheckReport, student_node
from course_helpers.core.waiting import poll_until, sleep_unless

TALKERS = ("wd_talker_1", "wd_talker_2")  # the first one is killed
TALKER_RATE_HZ = 19.0  # not a multiple of a 10 Hz timer: its ticks do not stay in step with the talk
TALKER_LEASE_S = 5.0  # peers keep a crashed talker this long in their graph
QUIET_WINDOW_S = 1.0  # both talkers talk: no alarm may come
QUIET_TENTHS = 8  # ... and the checker must hear both in this many tenths of a second of the window
REPORT_WITHIN_S = 3.0  # the watchdog must report the killed talker this soon (its silence: 0.5 s),
# well before its lease runs out
REPEAT_WINDOW_S = 1.0  # after the report: no second alarm about the same silence
NODE_NAME = "silence_watchdog"
SILENCE_S = 0.5  # the exercise's threshold: a sender quiet for longer is reported [s]
RETURN_MESSAGES = 10  # the checker talks again in the dead talker's name: this many messages...
RETURN_PERIOD_S = 0.05  # ...this far apart (as fast as the talkers)


def _endpoint_types(rt, topic: str, node, publishers: bool) -> list[str]:
    infos = (rt.graph.get_publishers_info_by_topic(topic) if publishers
             else rt.graph.get_subscriptions_info_by_topic(topic))
    return sorted({i.topic_type for i in infos
                   if i.node_name == node.get_name() and i.node_namespace == node.get_namespace()})


def _has_endpoint(report: CheckReport, rt, node, topic: str, publishers: bool, hint: str) -> bool:
    poll_until(lambda: _endpoint_types(rt, topic, node, publishers), 2.0)
    types = _endpoint_types(rt, topic, node, publishers)
    verb = "publishes on" if publishers else "subscribes to"
    detail = "" if types == ["std_msgs/msg/String"] else (
        f"with type {', '.join(types)}" if types else "none found in the graph")
    return report.add(f"{verb} {topic} with type std_msgs/msg/String", types == ["std_msgs/msg/String"],
                      detail, hint)


def check_silence_watchdog(node_class, rt=None) -> CheckReport:
    """Check a silence watchdog: it reports a killed talker on ``silent_talkers``, once, and no other.

    Args:
        node_class: the student's Node subclass, built without arguments.
        rt: the course runtime (default: this process's).

    Returns:
        A :class:`CheckReport`. The node must subscribe to ``/chatter`` and publish on
        ``/silent_talkers`` (both std_msgs/String); with two talker processes running, stay quiet;
        after one is killed, publish that sender's name within 3 s, once; never name the survivor.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise: a watchdog for silent talkers")
    errors_before = len(rt.errors)
    with student_node(report, rt, node_class, "watchdog_checker") as (node, probe):
        if node is None:
            return report
        name = node.get_name()
        named = name == NODE_NAME
        report.add(f"the node is named {NODE_NAME}", named, "" if named else f"its name is {name!r}",
                   hint="The name is the first argument of super().__init__ in your constructor.")
        subscribes = _has_endpoint(report, rt, node, "/chatter", False,
                                   "TODO 1: chapter 00's Listener shows how a node subscribes; the topic "
                                   "and the type are in the task.")
        publishes = _has_endpoint(report, rt, node, "/silent_talkers", True,
                                  "Compare your publisher's topic and message type with the task.")
        if not (subscribes and publishes):
            report.add("two talkers, one killed", False, "not run: the node must subscribe and publish first",
                       hint="Fix the criteria above, then check again.")
            return report
        alarms: list[tuple[float, str]] = []  # (when the checker got it, monotonic s; its text)
        heard: dict[str, list[float]] = {}  # sender -> when the checker heard it (monotonic s)

        def on_alarm(msg) -> None:
            alarms.append((time.monotonic(), msg.data))

        def on_chatter(msg) -> None:
            heard.setdefault(msg.data.split(":", 1)[0], []).append(time.monotonic())

        probe.create_subscription(String, "silent_talkers", on_alarm, 10)
        probe.create_subscription(String, "chatter", on_chatter, 10)
        impostor = probe.create_publisher(String, "chatter", 10)
        try:
            _run_scenario(report, rt, alarms, heard, impostor)
        finally:
            for label in TALKERS:
                if label in rt.children():
                    rt.stop_child(label)
        errors = rt.errors[errors_before:]
        report.add("callbacks raised no errors", not errors, errors[0].splitlines()[0] if errors else "",
                   hint="Read the traceback in the node's console under the checker's cell.")
    return report


def _run_scenario(report: CheckReport, rt, alarms: list[tuple[float, str]], heard: dict[str, list[float]],
                  impostor) -> None:
    dead, alive = TALKERS
    # A talker killed by an earlier check stays in the graph for its lease; a namesake of it would
    # make a watchdog that waits for the graph look right, so start once it is gone.
    poll_until(lambda: not {f"/{name}" for name in TALKERS} & set(rt.graph_nodes()), TALKER_LEASE_S + 2)
    lease = short_lease_env(TALKER_LEASE_S)
    children = {name: rt.spawn(name, NamedTalker, {"name": name, "rate_hz": TALKER_RATE_HZ},
                               wait_for=f"/{name}", env=lease) for name in TALKERS}
    if not poll_until(lambda: set(TALKERS) <= heard.keys(), 10):  # the checker's own set-up, not a criterion
        report.add("the checker could hear its two talkers", False, "no message from one of them within 10 s",
                   hint="The machine may be very busy; run the check again.")
        return
    time.sleep(0.3)  # the watchdog hears them too
    started = time.monotonic()
    sleep_unless(lambda: alarms, QUIET_WINDOW_S)
    # the watchdog's timer runs in the executor that delivers the talk to the checker: the window
    # lasts until the checker heard both talkers in most of its tenths of a second (not in one burst
    # after a stall, when the watchdog's timer may not have run at all)
    poll_until(lambda: alarms or min(_tenths_heard(heard[name], started) for name in TALKERS) >= QUIET_TENTHS,
               10.0)
    report.add("no alarm while both talkers talk", not alarms, f"got {alarms[0][1]!r}" if alarms else "",
               hint="Report a sender only when it has been silent for more than SILENCE_S.")
    alarms.clear()
    children[dead].kill()  # SIGKILL: a crash, no goodbye
    killed = time.monotonic()
    reported = poll_until(lambda: _naming(alarms, dead), REPORT_WITHIN_S)
    after_s = time.monotonic() - killed
    still_listed = f"/{dead}" in rt.graph_nodes()
    report.add(f"reports {dead} within {REPORT_WITHIN_S:g} s of its crash", reported,
               (f"after {after_s:.1f} s, while the ROS graph still listed /{dead}" if still_listed
                else f"after {after_s:.1f} s") if reported else "no alarm naming it",
               hint="Listen to the data, not to the graph (it keeps a killed node for its whole lease): "
                    "what does your timer compare, ten times a second?")
    if not reported:
        return
    sleep_unless(lambda: len(_naming(alarms, dead)) > 1, REPEAT_WINDOW_S)
    repeats = len(_naming(alarms, dead))
    report.add("reports that silence once", repeats == 1,
               "" if repeats == 1 else f"{repeats} alarms naming {dead}",
               hint="Keep track of the senders you have already reported (the skeleton's self.reported).")
    silences = _silences_before_alarms(heard, alive, alarms)
    wrong = [gap for gap in silences if gap <= SILENCE_S * 0.8]
    report.add(f"never reports {alive}, which keeps talking", not wrong,
               f"the checker heard it every {max(wrong):.2f} s or sooner before the alarm" if wrong else
               (f"it named {alive} after this busy machine had delivered nothing from it for "
                f"{min(silences):.1f} s, a real silence" if silences else ""),
               hint="Compare each sender's own last-heard time.")
    # The dead talker comes back (the checker talks in its name) and falls silent again.
    before = len(alarms)
    for count in range(RETURN_MESSAGES):
        impostor.publish(String(data=f"{dead}: {count}"))
        time.sleep(RETURN_PERIOD_S)
    returned = time.monotonic()
    again = poll_until(lambda: _naming(alarms[before:], dead), REPORT_WITHIN_S)
    report.add(f"reports {dead} again after it talked again and fell silent", again,
               f"after {time.monotonic() - returned:.1f} s" if again else
               f"no new alarm within {REPORT_WITHIN_S:g} s of its last message",
               hint="A sender you reported is heard again: what must your watchdog forget then?")


def _naming(alarms: list[tuple[float, str]], sender: str) -> list[float]:
    """When the checker got each alarm that names ``sender`` (monotonic s)."""
    return [arrived for arrived, text in list(alarms) if sender in text]


def _silences_before_alarms(heard: dict[str, list[float]], sender: str,
                            alarms: list[tuple[float, str]]) -> list[float]:
    """For each alarm naming ``sender``: the longest the checker went without a message from it in the
    ``SILENCE_S`` + 1 s before the alarm arrived [s]. A machine too busy to deliver the sender's
    messages in time (to the checker and the watchdog alike) makes such a silence real."""
    times = list(heard.get(sender, []))
    silences = []
    for arrived in _naming(alarms, sender):
        start = arrived - SILENCE_S - 1.0
        points = [start, *(t for t in times if start < t < arrived), arrived]
        silences.append(max(later - earlier for earlier, later in zip(points, points[1:], strict=False)))
    return silences


def _tenths_heard(times: list[float], start: float) -> int:
    """In how many tenths of a second since ``start`` a message arrived (``times``: monotonic s)."""
    return len({int((t - start) * 10) for t in list(times) if t >= start})
