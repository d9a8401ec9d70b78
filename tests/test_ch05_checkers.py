"""Chapter 05's checker: it accepts the reference navigation server, and every criterion fails on a wrong one.

Real action servers and clients over Fast DDS. Each wrong server below is a mistake a student makes;
the table names the criteria it must fail, and the test that runs the reference solution checks
that the table covers every criterion the checker reports.
"""

from __future__ import annotations

import math

import pytest
from course_interfaces.action import Navigate
from rclpy.action import ActionServer, GoalResponse
from rclpy.node import Node

from course_helpers.chapters.ch05_actions import sleep_async
from course_helpers.checks.ch05_actions import check_navigation_server
from course_helpers.solutions.ch05_actions import STEP_S, NavigationServer

from .criteria_registry import assert_reference_criteria, failing


def _failed(report) -> set[str]:
    return {c.name for c in report.criteria if not c.passed}


class Trip(NavigationServer):
    """The reference server with its trip loop spelt out, so that each wrong server changes one thing."""

    step_s = STEP_S  # how long one step waits [s]
    step_time_s = STEP_S  # how much driving time one step covers [s]

    async def execute(self, goal_handle):
        goal = goal_handle.request
        distance = math.hypot(goal.target.x, goal.target.y)
        travelled = 0.0
        while not self.arrived(travelled, distance):
            if goal_handle.is_cancel_requested:
                return self.cancel(goal_handle, travelled)
            await sleep_async(self, self.step_s)
            travelled = min(distance, travelled + goal.speed * self.step_time_s)
            self.feedback(goal_handle, travelled, distance)
        return self.arrive(goal_handle, travelled)

    def arrived(self, travelled, distance):
        return travelled >= distance

    def feedback(self, goal_handle, travelled, distance):
        goal_handle.publish_feedback(Navigate.Feedback(distance_remaining=distance - travelled,
                                                       progress=travelled / distance))

    def cancel(self, goal_handle, travelled):
        goal_handle.canceled()
        return Navigate.Result(success=False, distance_travelled=travelled)

    def arrive(self, goal_handle, travelled):
        goal_handle.succeed()
        return Navigate.Result(success=True, distance_travelled=travelled)


class TripNeedsAMap(Trip):
    """Wrong: a constructor argument the checker does not give."""

    def __init__(self, map_name):
        super().__init__()


class TripCalledNavigator(Trip):
    """Wrong: another node name."""

    def __init__(self):
        Node.__init__(self, "navigator")
        self.server = ActionServer(self, Navigate, "navigate", self.execute,
                                   goal_callback=self.on_goal, cancel_callback=self.on_cancel)


class TripWithoutServer(Trip):
    """Wrong: TODO 1 left undone; no action server."""

    def __init__(self):
        Node.__init__(self, "navigation_server")

    def destroy_node(self):
        Node.destroy_node(self)


class TripAtAnySpeed(Trip):
    """Wrong: accepts every speed (0 m/s never arrives; 3 m/s is over the limit)."""

    def on_goal(self, goal):
        return GoalResponse.ACCEPT


class TripBelowOneMetrePerSecond(Trip):
    """Wrong: a limit of 'below 1 m/s' instead of 'up to 1.5 m/s'."""

    def on_goal(self, goal):
        return GoalResponse.ACCEPT if 0.0 < goal.speed < 1.0 else GoalResponse.REJECT


class TripThatNeverArrives(Trip):
    """Wrong: a loop condition that stays true on arrival (the distance is never exceeded)."""

    def arrived(self, travelled, distance):
        return travelled > distance


class TripWithoutSucceed(Trip):
    """Wrong: returns the result without calling succeed(), so rclpy aborts the goal."""

    def arrive(self, goal_handle, travelled):
        return Navigate.Result(success=True, distance_travelled=travelled)


class TripInCoarseSteps(Trip):
    """Wrong: one step every 0.2 s covering 0.2 s of driving (the right speed, in steps twice too long)."""

    step_s = step_time_s = 2 * STEP_S


class TripAtHalfSpeed(Trip):
    """Wrong: waits 0.2 s per step but drives only 0.1 s' worth: half the requested speed."""

    step_s = 2 * STEP_S


class TripWithoutFeedback(Trip):
    """Wrong: never publishes feedback."""

    def feedback(self, goal_handle, travelled, distance):
        pass


class TripWithProgressBackwards(Trip):
    """Wrong: progress counts down (the fraction still to go)."""

    def feedback(self, goal_handle, travelled, distance):
        goal_handle.publish_feedback(Navigate.Feedback(distance_remaining=distance - travelled,
                                                       progress=(distance - travelled) / distance))


class TripWithoutCancelCallback(Trip):
    """Wrong: no cancel callback, so rclpy rejects every cancel request (and the trip goes on)."""

    def __init__(self):
        Node.__init__(self, "navigation_server")
        self.server = ActionServer(self, Navigate, "navigate", self.execute, goal_callback=self.on_goal)


class TripCanceledAsSuccess(Trip):
    """Wrong: a canceled trip reports success."""

    def cancel(self, goal_handle, travelled):
        goal_handle.canceled()
        return Navigate.Result(success=True, distance_travelled=travelled)


class TripDividesBySpeed(Trip):
    """Wrong: works out the trip's duration in the goal callback, dividing by a speed that can be 0."""

    def on_goal(self, goal):
        self.get_logger().info(f"this trip takes {0.5 / goal.speed:.1f} s")  # ZeroDivisionError at 0 m/s
        return super().on_goal(goal)


class TripLeavesItsServer(Trip):
    """Wrong: TODO 5 left undone; destroy_node leaves the action server alive."""

    def destroy_node(self):
        Node.destroy_node(self)


NAVIGATION_WRONG = [
    pytest.param(TripNeedsAMap, {"the node can be created"}, id="constructor-argument"),
    pytest.param(TripCalledNavigator, {"the node is called navigation_server"}, id="name"),
    pytest.param(TripWithoutServer,
                 {"it has an ActionServer for navigate (course_interfaces/action/Navigate)"}, id="no-server"),
    pytest.param(TripAtAnySpeed, {"it rejects a goal with speed 0 m/s", "it rejects a goal with speed 3 m/s"},
                 id="any-speed"),
    pytest.param(TripBelowOneMetrePerSecond, {"it accepts a goal to (0.3, 0.4) at 1 m/s",
                                              "it accepts a 2 m goal (to cancel it)"},
                 id="limit-too-low"),
    pytest.param(TripThatNeverArrives, {"the 0.5 m trip ends within 3 s"}, id="never-arrives"),
    pytest.param(TripWithoutSucceed, {"the trip succeeds with success=True and distance_travelled = 0.5 m"},
                 id="no-succeed"),
    pytest.param(TripInCoarseSteps, {"it moves speed × 0.1 m per step (0.1 m at 1 m/s)"}, id="coarse-steps"),
    pytest.param(TripAtHalfSpeed,
                 {"it steps every 0.1 s (the 0.5 m trip at 1 m/s takes 0.5 s of its clock)"},
                 id="half-speed"),
    pytest.param(TripWithoutFeedback, {"it sends feedback while driving (at least 3 messages)"},
                 id="no-feedback"),
    pytest.param(TripWithProgressBackwards,
                 {"feedback: progress rises from 0 to 1, distance_remaining falls"}, id="progress-backwards"),
    pytest.param(TripWithoutCancelCallback,
                 {"it accepts the cancel request", "the canceled goal ends within 1 s"}, id="no-cancel"),
    pytest.param(TripCanceledAsSuccess,
                 {"the canceled goal ends CANCELED, success=False, with the distance driven so far"},
                 id="canceled-as-success"),
    pytest.param(TripLeavesItsServer, {"destroy_node also destroys the action server"}, id="destroy-node"),
    pytest.param(TripDividesBySpeed, {"callbacks raised no errors"}, id="error-in-a-callback"),
]


@pytest.mark.parametrize("server", [NavigationServer, Trip], ids=["reference", "reference-spelt-out"])
def test_navigation_checker_accepts_the_reference_and_every_criterion_has_a_wrong_solution(rt, server):
    report = check_navigation_server(server, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_navigation_server", report)


@pytest.mark.parametrize("wrong, failing", NAVIGATION_WRONG)
def test_navigation_checker_fails_each_criterion_on_a_wrong_solution(rt, wrong, failing):
    report = check_navigation_server(wrong, rt)
    assert not report.passed
    assert failing <= _failed(report), report.summary()


def test_the_speed_criteria_pass_only_the_exercise_s_pace(rt):
    """Half speed fails only the pace; coarse steps fail the step length, and the pace too: measured on
    the checker's clock, three 0.2 s steps take 0.6 s, not 0.5 s."""
    coarse = _failed(check_navigation_server(TripInCoarseSteps, rt))
    assert coarse == {"it moves speed × 0.1 m per step (0.1 m at 1 m/s)",
                      "it steps every 0.1 s (the 0.5 m trip at 1 m/s takes 0.5 s of its clock)"}, coarse
    half = _failed(check_navigation_server(TripAtHalfSpeed, rt))
    assert half == {"it steps every 0.1 s (the 0.5 m trip at 1 m/s takes 0.5 s of its clock)"}


COVERED = {"check_navigation_server": failing(NAVIGATION_WRONG)}
ONLY_WHEN_FAILING = {"check_navigation_server": {"the node can be created"}}
