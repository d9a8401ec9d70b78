"""Checker of chapter 01 (architecture): a watchdog that notices a crashed talker by its silence.

The student's node, ``silence_watchdog``, subscribes to ``chatter`` (std_msgs/String,
'<sender>: <count>') and publishes the name of every sender that went quiet on ``silent_talkers``.

The checker runs it on a clock of its own (:func:`~course_helpers.checks.student_on_clock`): two talker
nodes, ``wd_talker_1`` and ``wd_talker_2``, talk 19 times a second of that clock; then the first stops
talking while its node stays in the graph, as a crashed process's node stays until its lease runs out.
The watchdog must report it, once, and never the one that keeps talking. Then the checker talks in the
first one's name again, as a restarted talker would, and stops: the watchdog must report that new
silence too. Every time below is ROS time the checker owns, so the verdict is the same on any machine.
Once, the clock stands still for a second of wall time, as a paused simulation's does: a pause is no
silence, so a watchdog that keeps wall time (time.monotonic()) reports both talkers then, on any machine
(a slower machine only lengthens the pause).
"""

from __future__ import annotations

import time

from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.checks import CheckReport, callback_errors_criterion, student_on_clock
from course_helpers.core.runtime import get_runtime

TALKERS = ("wd_talker_1", "wd_talker_2")  # the first one falls silent
TALKER_PERIOD_S = 1 / 19  # 19 messages a second: not in step with a 10 Hz timer
NODE_NAME = "silence_watchdog"
SILENCE_S = 0.5  # the exercise's threshold: a sender quiet for longer is reported [s]
QUIET_WINDOW_S = 2.0  # both talkers talk this long: no alarm may come
REPORT_WITHIN_S = 1.0  # after the last message: the silence (0.5 s), a timer period (0.1 s) and room
REPEAT_WINDOW_S = 2.0  # after the report: no second alarm about the same silence
RETURN_MESSAGES = 10  # the checker talks again in the first talker's name: this many messages...
RETURN_PERIOD_S = 0.05  # ...this far apart
STEP_S = 0.01  # the checker's clock moves in steps this long
PAUSE_WALL_S = 1.0  # the clock stands still this long (wall time, at least): twice the silence threshold
AFTER_PAUSE_S = 0.35  # then the talkers wait this long (ROS time): a 10 Hz timer looks before they talk,
                      # and the longest silence (0.35 + 1/19 + a step) stays under SILENCE_S


def _endpoint_types(probe, topic: str, node, publishers: bool) -> list[str]:
    infos = (probe.get_publishers_info_by_topic(topic) if publishers
             else probe.get_subscriptions_info_by_topic(topic))
    return sorted({i.topic_type for i in infos
                   if i.node_name == node.get_name() and i.node_namespace == node.get_namespace()})


def _has_endpoint(report: CheckReport, probe, node, topic: str, publishers: bool, hint: str) -> bool:
    types = _endpoint_types(probe, topic, node, publishers)  # this process's own endpoints: listed at once
    verb = "publishes on" if publishers else "subscribes to"
    detail = "" if types == ["std_msgs/msg/String"] else (
        f"with type {', '.join(types)}" if types else "none found in the graph")
    return report.add(f"{verb} {topic} with type std_msgs/msg/String", types == ["std_msgs/msg/String"],
                      detail, hint)


class _Talk:
    """The checker's side: talkers that talk on the clock, and the alarms heard, with their ROS times."""

    def __init__(self, rt, clock, probe):
        self.clock = clock
        self.alarms: list[tuple[float, str]] = []  # (ROS time [s], text)
        self.talking = set(TALKERS)
        self.next_at = {name: clock.now_s for name in TALKERS}
        self.counts = dict.fromkeys(TALKERS, 0)
        self.last_said = dict.fromkeys(TALKERS, clock.now_s)
        self.chatter = {}
        for name in TALKERS:  # one node per talker: the graph lists each, as it lists a process's node
            talker = clock.drive(rt.build(Node, name, enable_rosout=False, start_parameter_services=False))
            self.chatter[name] = talker.create_publisher(String, "chatter", 10)
        probe.create_subscription(String, "silent_talkers",
                                  lambda msg: self.alarms.append((clock.now_s, msg.data)), 10)
        clock.wait_matched()

    def say(self, name: str) -> None:
        self.chatter[name].publish(String(data=f"{name}: {self.counts[name]}"))
        self.counts[name] += 1
        self.last_said[name] = self.clock.now_s

    def between_steps(self) -> None:
        """Called after every step of the clock: each talking talker talks when its period is up."""
        for name in sorted(self.talking):
            if self.clock.now_s + 1e-9 >= self.next_at[name]:
                self.say(name)
                self.next_at[name] += TALKER_PERIOD_S

    def run(self, seconds: float) -> None:
        self.clock.advance(seconds, STEP_S, self.between_steps)

    def pause(self) -> None:
        """The clock stands still for PAUSE_WALL_S of wall time (an input: load only lengthens it), then
        the talkers keep quiet for AFTER_PAUSE_S of ROS time, so the watchdog's timer looks first."""
        time.sleep(PAUSE_WALL_S)
        for name in self.talking:
            self.next_at[name] = self.clock.now_s + AFTER_PAUSE_S

    def naming(self, sender: str, since: float = float("-inf")) -> list[float]:
        """When (ROS time) each alarm naming ``sender`` came, from ``since`` on."""
        return [at for at, text in self.alarms if sender in text and at >= since]


def check_silence_watchdog(node_class, rt=None) -> CheckReport:
    """Check a silence watchdog: it reports a silent talker on ``silent_talkers``, once, and no other.

    Args:
        node_class: the student's Node subclass, built without arguments.
        rt: the course runtime (default: this process's).

    Returns:
        A :class:`CheckReport`. The node must subscribe to ``/chatter`` and publish on
        ``/silent_talkers`` (both std_msgs/String); while two talkers talk, stay quiet; after one stops,
        publish that sender's name within 1 s of its last message, once; never name the other.
    """
    rt = rt or get_runtime()
    report = CheckReport("Exercise: a watchdog for silent talkers")
    with student_on_clock(report, rt, node_class, "watchdog_checker") as (node, probe, clock):
        if node is None:
            return report
        name = node.get_name()
        named = name == NODE_NAME
        report.add(f"the node is named {NODE_NAME}", named, "" if named else f"its name is {name!r}",
                   hint="The name is the first argument of super().__init__ in your constructor.")
        subscribes = _has_endpoint(report, probe, node, "/chatter", False,
                                   "TODO 1: chapter 00's Listener shows how a node subscribes; the topic "
                                   "and the type are in the task.")
        publishes = _has_endpoint(report, probe, node, "/silent_talkers", True,
                                  "Compare your publisher's topic and message type with the task.")
        if not (subscribes and publishes):
            report.add("two talkers, one falls silent", False,
                       "not run: the node must subscribe and publish first",
                       hint="Fix the criteria above, then check again.")
            return report
        _run_scenario(report, _Talk(rt, clock, probe))
        callback_errors_criterion(report, clock.errors)
    return report


def _run_scenario(report: CheckReport, talk: _Talk) -> None:
    silent, alive = TALKERS
    started = talk.clock.now_s
    talk.run(QUIET_WINDOW_S)
    report.add(f"no alarm while both talkers talk ({QUIET_WINDOW_S:g} s)", not talk.alarms,
               f"got {talk.alarms[0][1]!r} after {talk.alarms[0][0] - started:.2f} s" if talk.alarms else "",
               hint="Report a sender only when it has been silent for more than SILENCE_S.")
    talk.alarms.clear()
    talk.pause()
    talk.run(AFTER_PAUSE_S + 2 * TALKER_PERIOD_S)
    report.add(f"no alarm after the clock stood still for {PAUSE_WALL_S:g} s (a paused simulation)",
               not talk.alarms, f"got {talk.alarms[0][1]!r}" if talk.alarms else "",
               hint="Keep time with your node's own clock, self.get_clock().now(): while a simulation or "
                    "a replay pauses, ROS time stands still, and a pause is no silence.")
    talk.alarms.clear()
    talk.talking.discard(silent)  # it stops; its node stays in the graph, as a crashed one would
    talk.run(REPORT_WITHIN_S)
    heard = talk.naming(silent)
    after = heard[0] - talk.last_said[silent] if heard else None
    report.add(f"reports {silent} within {REPORT_WITHIN_S:g} s of its last message, while its node is "
               "still in the graph", bool(heard),
               f"after {after:.2f} s" if heard else f"no alarm naming it in {REPORT_WITHIN_S:g} s",
               hint="Listen to the data, not to the graph (it keeps a crashed node for its whole lease). "
                    "And keep time with your node's own clock, self.get_clock().now(): this checker "
                    "runs your node on a clock it owns, as a bag replay or a simulator would.")
    if not heard:
        return
    talk.run(REPEAT_WINDOW_S)
    repeats = len(talk.naming(silent))
    report.add("reports that silence once", repeats == 1,
               "" if repeats == 1 else f"{repeats} alarms naming {silent}",
               hint="Keep track of the senders you have already reported (the skeleton's self.reported).")
    wrong = talk.naming(alive)
    report.add(f"never reports {alive}, which keeps talking", not wrong,
               f"named it at {len(wrong)} moment(s), though it talked every {TALKER_PERIOD_S:.3f} s"
               if wrong else "", hint="Compare each sender's own last-heard time.")
    before = talk.clock.now_s
    for _ in range(RETURN_MESSAGES):  # it comes back for a moment, and falls silent again
        talk.say(silent)
        talk.run(RETURN_PERIOD_S)
    talk.run(REPORT_WITHIN_S)
    again = talk.naming(silent, since=before)
    report.add(f"reports {silent} again after it talked again and fell silent", bool(again),
               f"after {again[0] - talk.last_said[silent]:.2f} s" if again else
               f"no new alarm within {REPORT_WITHIN_S:g} s of its last message",
               hint="A sender you reported is heard again: what must your watchdog forget then?")
