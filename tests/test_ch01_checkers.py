"""Exercise 01, the silence watchdog: the checker accepts the reference and rejects each mistake.

The checker runs the student's node on a clock it owns (SimClock), so every verdict here is exact:
the same on any machine, however busy, and a 7 s scenario takes a fraction of a second.
"""

from __future__ import annotations

import time

import pytest
from rclpy.node import Node
from std_msgs.msg import Int32, String

from course_helpers.checks.ch01_architecture import check_silence_watchdog
from course_helpers.solutions.ch01_architecture import SilenceWatchdog

from .criteria_registry import assert_reference_criteria


def _failed(report) -> list[str]:
    return [c.name for c in report.criteria if not c.passed]


def test_the_reference_passes_every_criterion_in_well_under_a_second_of_wall_time(rt):
    started = time.monotonic()
    report = check_silence_watchdog(SilenceWatchdog, rt)
    wall = time.monotonic() - started
    assert report.passed, report.summary()
    assert_reference_criteria("check_silence_watchdog", report)
    names = [c.name for c in report.criteria]
    assert "the node is named silence_watchdog" in names
    assert "reports wd_talker_1 again after it talked again and fell silent" in names
    assert "after 0.5" in report.summary() or "after 0.6" in report.summary()  # ROS time, exactly
    assert not [n for n in rt.graph_nodes() if "wd_talker" in n or "silence_watchdog" in n]
    print(f"{report.summary()}\n(wall time {wall:.2f} s for about 7 s of the checker's clock)")


def test_the_verdict_is_the_same_every_time(rt):
    first = check_silence_watchdog(SilenceWatchdog, rt).summary()
    assert check_silence_watchdog(SilenceWatchdog, rt).summary() == first


# One plausible wrong watchdog per criterion.
class NeedsAnArgument(SilenceWatchdog):
    """Wrong: the constructor wants the silence threshold, so the checker cannot build it."""

    def __init__(self, silence_s):
        super().__init__()
        self.SILENCE_S = silence_s


class WrongName(SilenceWatchdog):
    """Wrong: a watchdog that works, under another node name."""

    def __init__(self):
        Node.__init__(self, "watchdog")
        self.last_heard, self.reported = {}, set()
        self.alarm = self.create_publisher(String, "silent_talkers", 10)
        self.subscription = self.create_subscription(String, "chatter", self.on_chatter, 10)
        self.timer = self.create_timer(0.1, self.check)


class DeafWatchdog(Node):
    """Wrong: forgets to subscribe to chatter."""

    def __init__(self):
        super().__init__("silence_watchdog")
        self.alarm = self.create_publisher(String, "silent_talkers", 10)


class NumbersForAlarms(Node):
    """Wrong: publishes its alarms as Int32 (a count) instead of the sender's name."""

    def __init__(self):
        super().__init__("silence_watchdog")
        self.alarm = self.create_publisher(Int32, "silent_talkers", 10)
        self.subscription = self.create_subscription(String, "chatter", lambda msg: None, 10)


class Jumpy(SilenceWatchdog):
    """Wrong: a threshold in the wrong unit (20 ms, not 0.5 s): talkers at 19 Hz look silent."""

    SILENCE_S = 0.02


class GraphWatchdog(SilenceWatchdog):
    """Wrong: waits for the silent talker to leave the ROS graph, which a crashed node does only after
    its whole lease."""

    def check(self):
        present = {name for name, _ns in self.get_node_names_and_namespaces()}
        for sender in self.last_heard:
            if sender not in present and sender not in self.reported:
                self.reported.add(sender)
                self.alarm.publish(String(data=sender))


class WallClockWatchdog(SilenceWatchdog):
    """Wrong: keeps time with time.monotonic(), not its node's clock, so in a replay or a simulation
    (or this checker) it measures silences in the wrong time."""

    def seconds(self) -> float:
        return time.monotonic()


class NaggingWatchdog(SilenceWatchdog):
    """Wrong: reports a silent sender at every check, ten times a second."""

    def check(self):
        now = self.seconds()
        for sender, heard in self.last_heard.items():
            if now - heard > self.SILENCE_S:
                self.alarm.publish(String(data=sender))


class ReportsEveryone(SilenceWatchdog):
    """Wrong: when anybody is silent, reports every sender it has ever heard."""

    def check(self):
        now = self.seconds()
        if any(now - heard > self.SILENCE_S for heard in self.last_heard.values()):
            for sender in self.last_heard:
                if sender not in self.reported:
                    self.reported.add(sender)
                    self.alarm.publish(String(data=sender))


class ReportsOnceEver(SilenceWatchdog):
    """Wrong: never forgets whom it reported, so a talker that comes back and falls silent is missed."""

    def on_chatter(self, msg):
        self.last_heard[msg.data.split(":", 1)[0]] = self.seconds()


class ForgetsWhileLooking(SilenceWatchdog):
    """Wrong: deletes a silent sender from the dict it is iterating over (RuntimeError in the timer)."""

    def check(self):
        now = self.seconds()
        for sender, heard in self.last_heard.items():
            if now - heard > self.SILENCE_S:
                self.alarm.publish(String(data=sender))
                del self.last_heard[sender]


REPORTS_SILENCE = "reports wd_talker_1 within 1 s of its last message, while its node is still in the graph"
WRONG = [
    (NeedsAnArgument, "the node can be created"),
    (WrongName, "the node is named silence_watchdog"),
    (DeafWatchdog, "subscribes to /chatter with type std_msgs/msg/String"),
    (NumbersForAlarms, "publishes on /silent_talkers with type std_msgs/msg/String"),
    (Jumpy, "no alarm while both talkers talk (2 s)"),
    (GraphWatchdog, REPORTS_SILENCE),
    (WallClockWatchdog, "no alarm after the clock stood still for 1 s (a paused simulation)"),
    (NaggingWatchdog, "reports that silence once"),
    (ReportsEveryone, "never reports wd_talker_2, which keeps talking"),
    (ReportsOnceEver, "reports wd_talker_1 again after it talked again and fell silent"),
    (ForgetsWhileLooking, "callbacks raised no errors"),
]


@pytest.mark.parametrize("wrong, criterion", WRONG, ids=[w.__name__ for w, _ in WRONG])
def test_each_mistake_fails_its_criterion(rt, wrong, criterion):
    report = check_silence_watchdog(wrong, rt)
    assert criterion in _failed(report), report.summary()


def test_the_wall_clock_watchdog_gets_the_hint_about_the_node_clock(rt):
    report = check_silence_watchdog(WallClockWatchdog, rt)
    assert "self.get_clock().now()" in report.summary()


NOT_RUN = "two talkers, one falls silent"


def test_a_node_without_a_subscription_stops_the_scenario(rt):
    report = check_silence_watchdog(DeafWatchdog, rt)
    summary = report.summary()
    assert "[FAIL] subscribes to /chatter" in summary and "[pass] publishes on /silent_talkers" in summary
    assert NOT_RUN in _failed(report) and "not run" in summary


COVERED = {"check_silence_watchdog": {criterion for _wrong, criterion in WRONG} | {NOT_RUN}}
ONLY_WHEN_FAILING = {"check_silence_watchdog": {"the node can be created", NOT_RUN}}
