"""Exercises of chapters 01-04: each checker accepts the reference solution and rejects wrong ones.

Real nodes over real Fast DDS: the checkers start talker processes, spin the student's node in an
executor, call its services. Wrong solutions are the mistakes students make.
"""

from __future__ import annotations

import time

import pytest
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from std_msgs.msg import Int32, String

from course_helpers.checks.ch01_architecture import check_silence_watchdog
from course_helpers.checks.ch02_executors import check_responsive_robot
from course_helpers.notebook.solution import solution_source
from course_helpers.solutions.ch01_architecture import SilenceWatchdog
from course_helpers.solutions.ch02_executors import Robot


# ---------------------------------------------------------------------- 01: silence watchdog
def _failed(report) -> list[str]:
    return [c.name for c in report.criteria if not c.passed]


def test_watchdog_checker_accepts_the_reference(rt):
    report = check_silence_watchdog(SilenceWatchdog, rt)
    assert report.passed, report.summary()
    assert "while the ROS graph still listed /wd_talker_1" in report.summary()
    names = [c.name for c in report.criteria]
    assert "the node is named silence_watchdog" in names
    assert "reports wd_talker_1 again after it talked again and fell silent" in names
    assert not [label for label in rt.children() if label.startswith("wd_talker")]


class GraphWatchdog(SilenceWatchdog):
    """Wrong: waits for the dead node to leave the ROS graph, which takes its whole lease (5 s)."""

    def check(self):
        present = {name for name, _ns in self.get_node_names_and_namespaces()}
        for sender in self.last_heard:
            if sender not in present and sender not in self.reported:
                self.reported.add(sender)
                self.alarm.publish(String(data=sender))


class NaggingWatchdog(SilenceWatchdog):
    """Wrong: reports a silent sender at every check, ten times a second."""

    def check(self):
        now = time.monotonic()
        for sender, heard in self.last_heard.items():
            if now - heard > self.SILENCE_S:
                self.alarm.publish(String(data=sender))


class DeafWatchdog(Node):
    """Wrong: forgets to subscribe to chatter."""

    def __init__(self):
        super().__init__("silence_watchdog")
        self.alarm = self.create_publisher(String, "silent_talkers", 10)


def test_watchdog_checker_rejects_waiting_for_the_graph(rt):
    report = check_silence_watchdog(GraphWatchdog, rt)
    assert not report.passed
    failed = [c.name for c in report.criteria if not c.passed]
    # (a graph watchdog may also raise a false alarm while the graph is catching up)
    assert "reports wd_talker_1 within 3 s of its crash" in failed, report.summary()


def test_watchdog_checker_rejects_repeated_alarms(rt):
    report = check_silence_watchdog(NaggingWatchdog, rt)
    failed = [c.name for c in report.criteria if not c.passed]
    assert "reports that silence once" in failed, report.summary()


def test_watchdog_checker_stops_early_without_a_subscription(rt):
    report = check_silence_watchdog(DeafWatchdog, rt)
    assert not report.passed
    summary = report.summary()
    assert "[FAIL] subscribes to /chatter" in summary and "[pass] publishes on /silent_talkers" in summary
    assert "not run" in summary
    assert not rt.children()


# One plausible wrong watchdog per criterion (the three above included).
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


class NumbersForAlarms(Node):
    """Wrong: publishes its alarms as Int32 (a count) instead of the sender's name."""

    def __init__(self):
        super().__init__("silence_watchdog")
        self.alarm = self.create_publisher(Int32, "silent_talkers", 10)
        self.subscription = self.create_subscription(String, "chatter", lambda msg: None, 10)


class Jumpy(SilenceWatchdog):
    """Wrong: a threshold in the wrong unit (20 ms, not 0.5 s): talkers at 20 Hz look silent."""

    SILENCE_S = 0.02


class ReportsOnceEver(SilenceWatchdog):
    """Wrong: never forgets whom it reported, so a talker that comes back and dies again is missed."""

    def on_chatter(self, msg):
        self.last_heard[msg.data.split(":", 1)[0]] = time.monotonic()


class ReportsEveryone(SilenceWatchdog):
    """Wrong: when anybody is silent, reports every sender it has ever heard."""

    def check(self):
        now = time.monotonic()
        if any(now - heard > self.SILENCE_S for heard in self.last_heard.values()):
            for sender in self.last_heard:
                if sender not in self.reported:
                    self.reported.add(sender)
                    self.alarm.publish(String(data=sender))


class ForgetsWhileLooking(SilenceWatchdog):
    """Wrong: deletes a silent sender from the dict it is iterating over (RuntimeError in the timer)."""

    def check(self):
        now = time.monotonic()
        for sender, heard in self.last_heard.items():
            if now - heard > self.SILENCE_S:
                self.alarm.publish(String(data=sender))
                del self.last_heard[sender]


@pytest.mark.parametrize("wrong, criterion", [
    (NeedsAnArgument, "the node can be created"),
    (WrongName, "the node is named silence_watchdog"),
    (NumbersForAlarms, "publishes on /silent_talkers with type std_msgs/msg/String"),
    (Jumpy, "no alarm while both talkers talk"),
    (ReportsOnceEver, "reports wd_talker_1 again after it talked again and fell silent"),
    (ReportsEveryone, "never reports wd_talker_2, which keeps talking"),
    (ForgetsWhileLooking, "callbacks raised no errors"),
])
def test_watchdog_checker_rejects(rt, wrong, criterion):
    report = check_silence_watchdog(wrong, rt)
    assert criterion in _failed(report), report.summary()
    assert not [label for label in rt.children() if label.startswith("wd_talker")]


# ---------------------------------------------------------------------- 02: responsive robot
# One plausible wrong solution per criterion of check_responsive_robot; each test sees its criterion fail.
NO_LONG_GAP = "no gap between heartbeats above 0.15 s (beyond the machine's own delays)"


def failed_criteria(report) -> list[str]:
    return [c.name for c in report.criteria if not c.passed]


def regroup(robot, heartbeat_group, camera_group, planner_group, planner_period_s=0.5):
    """Create the robot's three timers again, in the given callback groups (None: the default one)."""
    for timer in (robot.heartbeat_timer, robot.camera_timer, robot.planner_timer):
        robot.destroy_timer(timer)
    robot.heartbeat_timer = robot.create_timer(0.1, robot.heartbeat, callback_group=heartbeat_group)
    robot.camera_timer = robot.create_timer(0.2, robot.camera, callback_group=camera_group)
    robot.planner_timer = robot.create_timer(planner_period_s, robot.planner, callback_group=planner_group)


class UngroupedRobot(Robot):
    """Wrong: the exercise as given, every timer in the node's default group."""

    def __init__(self):
        super().__init__()
        regroup(self, None, None, None)


class HeartbeatWithPlanner(Robot):
    """Wrong: the camera got its own group, but the heartbeat still shares one with the planner."""

    def __init__(self):
        super().__init__()
        shared = MutuallyExclusiveCallbackGroup()
        regroup(self, shared, MutuallyExclusiveCallbackGroup(), shared)


class ConfiguredRobot(Robot):
    """Wrong: the constructor wants an argument the checker cannot know."""

    def __init__(self, planner_period_s):
        super().__init__()


class RarePlanner(Robot):
    """Wrong: the planner runs every 2 s instead of every 0.5 s, so it blocks less often."""

    def __init__(self):
        super().__init__()
        regroup(self, MutuallyExclusiveCallbackGroup(), MutuallyExclusiveCallbackGroup(),
                MutuallyExclusiveCallbackGroup(), planner_period_s=2.0)


class CameraWithoutTheWait(Robot):
    """Wrong: the camera's 50 ms wait for a frame is gone."""

    def camera(self):
        self.frames += 1


class UngroupedRobotWithoutTheSleep(UngroupedRobot):
    """Wrong: no callback group at all, and the planner's 0.3 s sleep deleted instead, so that the
    heartbeat is regular because the planner no longer blocks."""

    def planner(self):
        self.plans += 1


def test_robot_checker_accepts_the_reference(rt):
    report = check_responsive_robot(Robot)
    assert report.passed, report.summary()


def test_robot_checker_rejects_a_constructor_with_arguments(rt):
    report = check_responsive_robot(ConfiguredRobot)
    assert failed_criteria(report) == ["the node starts and spins"], report.summary()


def test_robot_checker_rejects_changed_timer_periods(rt):
    report = check_responsive_robot(RarePlanner)
    assert "its timers are the given ones: every 0.1 s, 0.2 s and 0.5 s" in failed_criteria(report)
    assert "found timers every [0.1, 0.2, 2.0] s" in report.summary()


def test_robot_checker_rejects_a_heartbeat_that_never_runs_beside_the_planner(rt):
    report = check_responsive_robot(HeartbeatWithPlanner)
    assert "the heartbeat kept beating while the planner blocked" in failed_criteria(report), \
        report.summary()
    assert "no beat started while the planner ran" in report.summary()


def test_robot_checker_rejects_the_default_group(rt):
    report = check_responsive_robot(UngroupedRobot)
    assert NO_LONG_GAP in failed_criteria(report)
    assert "the heartbeat waited for the planner" in report.summary()


def test_robot_checker_rejects_a_heartbeat_that_shares_the_planners_group(rt):
    report = check_responsive_robot(HeartbeatWithPlanner)
    assert NO_LONG_GAP in failed_criteria(report)
    assert "the heartbeat waited for the planner" in report.summary()


def test_robot_checker_rejects_a_camera_that_no_longer_waits(rt):
    report = check_responsive_robot(CameraWithoutTheWait)
    assert failed_criteria(report) == ["the camera ran as given: at least 5 times, each taking 50 ms"], \
        report.summary()
    assert "a call took less than 50 ms" in report.summary()


def test_robot_checker_rejects_deleting_the_planners_sleep(rt):
    report = check_responsive_robot(UngroupedRobotWithoutTheSleep)
    assert "the planner ran as given: at least 2 times, each taking 300 ms" in failed_criteria(report), \
        report.summary()
    assert "a call took less than 300 ms" in report.summary()


def test_robot_checker_hints_do_not_give_the_answer(rt):
    report = check_responsive_robot(UngroupedRobot)
    hints = " ".join(c.hint for c in report.criteria).lower()
    assert "callback group" not in hints and "callback_group" not in hints, hints


# ---------------------------------------------------------------------- show_solution finds them
def test_show_solution_loads_the_reference_solutions():
    assert "class SilenceWatchdog(Node)" in solution_source("ch01_architecture", "SilenceWatchdog")
    assert "callback_group=beat_group" in solution_source("ch02_executors", "Robot")
    for name in ("TiltMonitor", "tilt_deg", "CmdVelCsvLogger", "expected_load", "measure_load"):
        assert solution_source("ch03_topics", name).lstrip().startswith(("class ", "def "))
    for name in ("BatteryMonitor", "SumRelay"):
        assert solution_source("ch04_services", name).startswith("class ")


# ---------------------------------------------------------------------- 03: throughput
def test_throughput_solution_object_passes_the_checker(rt):
    from course_helpers.checks.ch03_topics import check_throughput
    from course_helpers.solutions.ch03_topics import ThroughputSolution

    report = check_throughput(ThroughputSolution.expected_load, ThroughputSolution.measure_load, rt)
    assert report.passed, report.summary()
