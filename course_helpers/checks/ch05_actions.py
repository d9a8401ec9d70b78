"""Checker of chapter 05 (actions): the navigation action server (course_interfaces/action/Navigate)."""

from __future__ import annotations

import contextlib
import math
import time

from action_msgs.msg import GoalStatus
from action_msgs.srv import CancelGoal
from rclpy.action import ActionClient, ActionServer
from rclpy.node import Node

from course_helpers.chapters.ch05_actions import status_name
from course_helpers.checks import CheckReport, student_node
from course_helpers.core.runtime import get_runtime
from course_helpers.core.waiting import poll_until

MAX_SPEED = 1.5  # [m/s] the exercise's speed limit
STEP_S = 0.1  # [s] the exercise's control period
RESULT_TIMEOUT_S = 3.0
TRIP_M, TRIP_SPEED = 0.5, 1.0  # the timed trip: 0.5 m at 1 m/s, five steps of 0.1 m
PACE_RANGE = (0.75, 1.6)  # the trip's duration over that of five 0.1 s steps timed beside it


class StepClock:
    """Times ``steps`` waits of ``step_s`` the way the exercise's server waits: one-shot timers in a chain.

    It runs on the checker's probe node in the same executor as the student's server, so a busy
    machine delays both alike; ``seconds`` is None until the last step has passed.
    """

    def __init__(self, node: Node, steps: int, step_s: float = STEP_S):
        self.node, self.left, self.step_s = node, steps, step_s
        self.started = time.monotonic()
        self.seconds: float | None = None
        self.timer = node.create_timer(step_s, self._step)

    def _step(self) -> None:
        self.node.destroy_timer(self.timer)
        self.left -= 1
        if self.left > 0:
            self.timer = self.node.create_timer(self.step_s, self._step)
        else:
            self.seconds = time.monotonic() - self.started


def check_navigation_server(node_class, rt=None) -> CheckReport:
    """Exercise 05: send goals to ``node_class``'s ``navigate`` action, reject bad ones, cancel one.

    Returns a CheckReport of ``node_class`` (the student's node class, built without
    arguments) run in ``rt`` (default: this kernel's runtime), with a hint per failure.
    """
    from course_interfaces.action import Navigate

    rt = rt or get_runtime()
    report = CheckReport("Exercise 05 - navigation action server")
    with student_node(report, rt, node_class, "navigation_checker") as (node, probe):
        if node is None:
            return report
        client = ActionClient(probe, Navigate, "/navigate")
        if not _check_navigation(rt, report, node, probe, client, Navigate):
            return report
    _check_destroy_node(rt, report, node_class)
    return report


def _check_navigation(rt, report, node, probe, client, navigate) -> bool:
    """The behaviour criteria; False when the node is too far off for the rest to mean anything."""
    named = node.get_name() == "navigation_server"
    if not report.add("the node is called navigation_server", named,
                      "" if named else f"it is called {node.get_name()!r}",
                      "The exercise names the node: compare it with the name your constructor passes on."):
        return False
    servers = [w for w in node.waitables if isinstance(w, ActionServer)]
    if not report.add("it has an ActionServer for navigate (course_interfaces/action/Navigate)",
                      any(s._action_type is navigate for s in servers) and client.wait_for_server(3.0),
                      "" if servers else "the node has no ActionServer",
                      "TODO 1: section 2's FibonacciServer creates one; the exercise names the action "
                      "and its type."):
        return False
    for speed in (0.0, 3.0):
        accepted = _send(rt, client, navigate, 0.3, 0.4, speed)
        rejected = accepted is not None and not accepted.accepted
        report.add(f"it rejects a goal with speed {speed:g} m/s", rejected,
                   "" if accepted is None or not accepted.accepted else "the goal was accepted",
                   "TODO 2 and section 2's on_goal: which callback decides about a goal, does the "
                   "ActionServer know it, and which speeds does the exercise allow?")
    _check_trip(rt, report, probe, client, navigate)
    _check_cancel(rt, report, client, navigate)
    return True


def _send(rt, client, navigate, x, y, speed, feedback=None):
    """Send a goal; ``feedback`` (a list) collects (arrival time [s], feedback message) pairs."""
    goal = navigate.Goal()
    goal.target.x, goal.target.y, goal.speed = float(x), float(y), float(speed)
    callback = ((lambda msg: feedback.append((time.monotonic(), msg.feedback)))
                if feedback is not None else None)
    try:
        return rt.wait_for_future(client.send_goal_async(goal, feedback_callback=callback), 2.0,
                                  "the goal response")
    except TimeoutError:
        return None


def _check_trip(rt, report, probe, client, navigate) -> None:
    feedback: list = []
    handle = _send(rt, client, navigate, 0.3, 0.4, TRIP_SPEED, feedback)
    if not report.add("it accepts a goal to (0.3, 0.4) at 1 m/s", handle is not None and handle.accepted, "",
                      "Which speeds does the exercise allow? Is 1 m/s among them?"):
        return
    steps = round(TRIP_M / (TRIP_SPEED * STEP_S))
    clock = rt.call_in_executor(lambda: StepClock(probe, steps))  # five 0.1 s waits, timed beside the trip
    try:
        outcome = rt.wait_for_future(handle.get_result_async(), RESULT_TIMEOUT_S, "the result")
    except TimeoutError:
        report.add(f"the 0.5 m trip ends within {RESULT_TIMEOUT_S:g} s", False, "no result",
                   "Section 2's execute callback shows how a goal steps and ends: does your loop end, "
                   "and does the goal succeed?")
        return
    took = time.monotonic() - clock.started
    result = outcome.result
    succeeded = (outcome.status == GoalStatus.STATUS_SUCCEEDED and result.success
                 and abs(result.distance_travelled - TRIP_M) < 0.02)
    report.add("the trip succeeds with success=True and distance_travelled = 0.5 m", succeeded,
               "" if succeeded else f"status {status_name(outcome.status)}, success={result.success}, "
               f"distance_travelled={result.distance_travelled:.3f}",
               "The exercise's third bullet says how a trip ends and what its result holds.")
    remaining = [f.distance_remaining for _, f in feedback]
    step_lengths = [a - b for a, b in zip([TRIP_M, *remaining], remaining, strict=False)]
    even = bool(step_lengths) and all(math.isclose(s, TRIP_SPEED * STEP_S, abs_tol=0.01)
                                      for s in step_lengths)
    report.add("it moves speed × 0.1 m per step (0.1 m at 1 m/s)", even,
               "" if even else "steps of " + ", ".join(f"{s:.3f}" for s in step_lengths[:6]) + " m",
               "The exercise's second bullet: how far does the robot move in one step?")
    rt.wait_until(lambda: clock.seconds is not None, RESULT_TIMEOUT_S, "the checker's own five steps")
    pace = took / clock.seconds
    paced = took >= 0.9 * steps * STEP_S and PACE_RANGE[0] <= pace <= PACE_RANGE[1]
    report.add("it steps every 0.1 s (the 0.5 m trip lasts as long as five 0.1 s steps timed beside it)",
               paced, "" if paced else
               f"it took {took:.2f} s, the five steps beside it {clock.seconds:.2f} s",
               "The exercise's second bullet: how long does one step wait?")
    report.add("it sends feedback while driving (at least 3 messages)", len(feedback) >= 3,
               "" if len(feedback) >= 3 else f"{len(feedback)} message(s)",
               "The exercise's second bullet says when feedback is published.")
    if len(feedback) >= 2:
        progress = [f.progress for _, f in feedback]
        rising = all(0.0 <= a <= b <= 1.0 + 1e-6 for a, b in zip(progress, progress[1:], strict=False))
        falling = all(a >= b - 1e-6 for a, b in zip(remaining, remaining[1:], strict=False))
        report.add("feedback: progress rises from 0 to 1, distance_remaining falls",
                   rising and falling and math.isclose(progress[-1], 1.0, abs_tol=0.02),
                   "" if rising and falling else "the values are not monotonic",
                   "What do progress and distance_remaining mean? The Navigate definition above says.")


def _check_cancel(rt, report, client, navigate) -> None:
    feedback: list = []
    handle = _send(rt, client, navigate, 1.2, 1.6, 1.0, feedback)  # 2 m: 2 s if not canceled
    if handle is None or not handle.accepted:
        report.add("it accepts a 2 m goal (to cancel it) within 2 s", False,
                   "no answer" if handle is None else "the goal was rejected",
                   "Section 2 explains what a blocking wait in the execute callback does to every "
                   "other callback of the kernel.")
        return
    poll_until(lambda: len(feedback) >= 2, 2.0)  # a server without feedback is canceled after 2 s
    try:
        answer = rt.wait_for_future(handle.cancel_goal_async(), 1.0, "the cancel response")
    except TimeoutError:
        answer = None
    accepted = answer is not None and answer.return_code == CancelGoal.Response.ERROR_NONE \
        and len(answer.goals_canceling) == 1
    report.add("it accepts the cancel request", accepted,
               "" if accepted else "the cancel request was refused or not answered",
               "TODO 3, and section 2: what does rclpy answer to a cancel request by default?")
    try:
        outcome = rt.wait_for_future(handle.get_result_async(), 1.0, "the canceled goal's result")
    except TimeoutError:
        report.add("the canceled goal ends within 1 s", False, "no result",
                   "Section 5: how does the execute callback notice a cancel request, and how often "
                   "does yours look?")
        rt.wait_for_future(handle.get_result_async(), 5.0, "the goal's end")
        return
    result = outcome.result
    honoured = (outcome.status == GoalStatus.STATUS_CANCELED and not result.success
                and 0.0 < result.distance_travelled < 2.0)
    report.add("the canceled goal ends CANCELED, success=False, with the distance driven so far",
               honoured, "" if honoured else f"status {status_name(outcome.status)}, "
               f"success={result.success}, distance_travelled={result.distance_travelled:.2f}",
               "The exercise's fourth bullet says how a canceled trip ends and what its result holds.")


def _check_destroy_node(rt, report, node_class) -> None:
    """Build the class once more, unspun, and see whether its destroy_node leaves the action server alive."""
    name = "destroy_node also destroys the action server"
    node = report.run(name, lambda: rt.build(node_class),
                      hint="Run the class cell first; the constructor must take no arguments.")
    if node is None:
        return
    try:
        before = len(report.criteria)
        report.run(name, node.destroy_node,
                   hint="TODO 5: destroy the action server, then let Node do the rest.")
        if len(report.criteria) > before:  # destroy_node raised
            return
        left = [w for w in node.waitables if isinstance(w, ActionServer)]
        report.add(name, not left, "" if not left else "after destroy_node() the ActionServer is still alive",
                   "Section 2, after FibonacciServer: what does Node.destroy_node() leave alive? (TODO 5)")
    finally:
        _free(node)


def _free(node: Node) -> None:
    """Free what the student's destroy_node left behind: its action servers, or the whole node."""
    for waitable in list(node.waitables):
        if isinstance(waitable, ActionServer):
            with contextlib.suppress(Exception):
                waitable.destroy()
    with contextlib.suppress(Exception):  # destroying a node twice is harmless
        Node.destroy_node(node)
