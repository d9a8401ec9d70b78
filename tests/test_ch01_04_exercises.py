"""Exercises of chapters 02-04: each checker accepts the reference solution and rejects wrong ones.

Real nodes over real Fast DDS: the checkers start talker processes, spin the student's node in an
executor, call its services. Wrong solutions are the mistakes students make.
"""

from __future__ import annotations

import pytest
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

from course_helpers.checks.ch02_executors import check_responsive_robot
from course_helpers.notebook.solution import solution_source
from course_helpers.solutions.ch02_executors import Robot

from .criteria_registry import assert_reference_criteria

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing

# ---------------------------------------------------------------------- 02: responsive robot
# One plausible wrong solution per criterion of check_responsive_robot; each test sees its criterion fail.
STARTS = "the node starts and spins"
GIVEN_TIMERS = "its timers are the given ones: every 0.1 s, 0.2 s and 0.5 s"
BESIDE = "the heartbeat kept beating while the planner blocked"
NO_LONG_GAP = "no gap between heartbeats above 0.15 s"
CAMERA_AS_GIVEN = "the camera ran as given: at least 5 times, each taking 50 ms"
PLANNER_AS_GIVEN = "the planner ran as given: at least 2 times, each taking 300 ms"


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


# what each wrong robot fails (the tests below assert it, each with what its report says besides)
ROBOT_FAILS = {
    ConfiguredRobot: [STARTS],
    RarePlanner: [GIVEN_TIMERS],
    HeartbeatWithPlanner: [BESIDE, NO_LONG_GAP],
    UngroupedRobot: [NO_LONG_GAP],
    CameraWithoutTheWait: [CAMERA_AS_GIVEN],
    UngroupedRobotWithoutTheSleep: [PLANNER_AS_GIVEN],
}


def _fails_its_criteria(report, wrong) -> bool:
    return set(ROBOT_FAILS[wrong]) <= set(failed_criteria(report))


def test_robot_checker_accepts_the_reference(rt):
    report = check_responsive_robot(Robot)
    assert report.passed, report.summary()
    assert_reference_criteria("check_responsive_robot", report)


def test_robot_checker_rejects_a_constructor_with_arguments(rt):
    report = check_responsive_robot(ConfiguredRobot)
    assert failed_criteria(report) == ROBOT_FAILS[ConfiguredRobot], report.summary()


def test_robot_checker_rejects_changed_timer_periods(rt):
    report = check_responsive_robot(RarePlanner)
    assert _fails_its_criteria(report, RarePlanner), report.summary()
    assert "found timers every [0.1, 0.2, 2.0] s" in report.summary()


def test_robot_checker_rejects_a_heartbeat_that_never_runs_beside_the_planner(rt):
    report = check_responsive_robot(HeartbeatWithPlanner)
    assert _fails_its_criteria(report, HeartbeatWithPlanner), report.summary()
    # decided by the callback groups, before any timing: the same verdict on any machine
    assert "share one mutually exclusive group: they can never overlap" in report.summary()
    assert "[BUSY]" not in report.summary()


def test_robot_checker_rejects_the_default_group(rt):
    report = check_responsive_robot(UngroupedRobot)
    assert _fails_its_criteria(report, UngroupedRobot), report.summary()
    assert "they can never overlap" in report.summary()


def test_robot_checker_rejects_a_camera_that_no_longer_waits(rt):
    report = check_responsive_robot(CameraWithoutTheWait)
    assert failed_criteria(report) == ROBOT_FAILS[CameraWithoutTheWait], report.summary()
    assert "a call took less than 50 ms" in report.summary()


def test_robot_checker_rejects_deleting_the_planners_sleep(rt):
    report = check_responsive_robot(UngroupedRobotWithoutTheSleep)
    assert _fails_its_criteria(report, UngroupedRobotWithoutTheSleep), report.summary()
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
    assert_reference_criteria("check_throughput", report)


COVERED = {"check_responsive_robot": set().union(*ROBOT_FAILS.values())}
