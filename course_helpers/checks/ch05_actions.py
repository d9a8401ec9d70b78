"""Checker of chapter 05 (actions): the navigation action server (course_interfaces/action/Navigate)."""

from __future__ import annotations

import math
import time

from action_msgs.msg import GoalStatus
from action_msgs.srv import CancelGoal
from rclpy.action import ActionClient, ActionServer

from course_helpers.chapters.ch05_actions import status_name
from course_helpers.checks import CheckReport, student_node
from course_helpers.core.runtime import get_runtime

MAX_SPEED = 1.5  # [m/s] the exercise's speed limit
RESULT_TIMEOUT_S = 3.0


def check_navigation_server(node_class, rt=None) -> CheckReport:
    """Exercise 05: send goals to ``node_class``'s ``navigate`` action, reject bad ones, cancel one.

    Returns a CheckReport of ``node_class`` (the student's node class, built without
    arguments) run in ``rt`` (default: this kernel's runtime), with a hint per failure.
    """
    from course_interfaces.action import Navigate

    rt = rt or get_runtime()
    report = CheckReport("Exercise 05 - navigation action server")
    with student_node(report, rt, node_class, "navigation_checker") as (node, probe):
        if node is not None:
            _check_navigation(rt, report, node, ActionClient(probe, Navigate, "/navigate"), Navigate)
    return report


def _check_navigation(rt, report, node, client, navigate) -> None:
    named = node.get_name() == "navigation_server"
    if not report.add("the node is called navigation_server", named,
                      "" if named else f"it is called {node.get_name()!r}",
                      "super().__init__('navigation_server')"):
        return
    servers = [w for w in node.waitables if isinstance(w, ActionServer)]
    if not report.add("it has an ActionServer for navigate (course_interfaces/action/Navigate)",
                      any(s._action_type is navigate for s in servers) and client.wait_for_server(3.0),
                      "" if servers else "the node has no ActionServer",
                      "self.server = ActionServer(self, Navigate, 'navigate', self.execute, ...)"):
        return
    for speed in (0.0, 3.0):
        accepted = _send(rt, client, navigate, 0.3, 0.4, speed)
        rejected = accepted is not None and not accepted.accepted
        report.add(f"it rejects a goal with speed {speed:g} m/s", rejected,
                   "" if accepted is None or not accepted.accepted else "the goal was accepted",
                   f"Pass goal_callback=self.on_goal; return GoalResponse.REJECT unless "
                   f"0 < speed <= {MAX_SPEED} m/s.")
    _check_trip(rt, report, client, navigate)
    _check_cancel(rt, report, client, navigate)


def _send(rt, client, navigate, x, y, speed, feedback=None):
    goal = navigate.Goal()
    goal.target.x, goal.target.y, goal.speed = float(x), float(y), float(speed)
    callback = (lambda msg: feedback.append(msg.feedback)) if feedback is not None else None
    try:
        return rt.wait_for_future(client.send_goal_async(goal, feedback_callback=callback), 2.0,
                                  "the goal response")
    except TimeoutError:
        return None


def _check_trip(rt, report, client, navigate) -> None:
    feedback: list = []
    started = time.monotonic()
    handle = _send(rt, client, navigate, 0.3, 0.4, 1.0, feedback)
    if not report.add("it accepts a goal to (0.3, 0.4) at 1 m/s", handle is not None and handle.accepted, "",
                      "Return GoalResponse.ACCEPT for speeds in (0, 1.5]."):
        return
    try:
        outcome = rt.wait_for_future(handle.get_result_async(), RESULT_TIMEOUT_S, "the result")
    except TimeoutError:
        report.add(f"the 0.5 m trip ends within {RESULT_TIMEOUT_S:g} s", False, "no result",
                   "Step 0.1 s at a time with `await sleep_async(self, 0.1)` and call "
                   "goal_handle.succeed() at the end.")
        return
    took = time.monotonic() - started
    result = outcome.result
    succeeded = (outcome.status == GoalStatus.STATUS_SUCCEEDED and result.success
                 and abs(result.distance_travelled - 0.5) < 0.02)
    report.add("the trip succeeds with success=True and distance_travelled = 0.5 m", succeeded,
               "" if succeeded else f"status {status_name(outcome.status)}, success={result.success}, "
               f"distance_travelled={result.distance_travelled:.3f}",
               "goal_handle.succeed(), then return Navigate.Result(success=True, distance_travelled=...).")
    report.add("it drives at the requested speed (0.5 m at 1 m/s takes about 0.5 s)", 0.35 <= took <= 2.0,
               "" if 0.35 <= took <= 2.0 else ("much faster" if took < 0.35 else "much slower") +
               " than 0.5 s", "Advance speed * 0.1 m per 0.1 s step.")
    progress = [f.progress for f in feedback]
    remaining = [f.distance_remaining for f in feedback]
    report.add("it sends feedback while driving (at least 3 messages)", len(feedback) >= 3,
               "" if len(feedback) >= 3 else f"{len(feedback)} message(s)",
               "goal_handle.publish_feedback(feedback) after every step.")
    if len(feedback) >= 2:
        rising = all(0.0 <= a <= b <= 1.0 + 1e-6 for a, b in zip(progress, progress[1:], strict=False))
        falling = all(a >= b - 1e-6 for a, b in zip(remaining, remaining[1:], strict=False))
        report.add("feedback: progress rises from 0 to 1, distance_remaining falls",
                   rising and falling and math.isclose(progress[-1], 1.0, abs_tol=0.02),
                   "" if rising and falling else "the values are not monotonic",
                   "progress = travelled / distance, distance_remaining = distance - travelled.")


def _check_cancel(rt, report, client, navigate) -> None:
    feedback: list = []
    handle = _send(rt, client, navigate, 1.2, 1.6, 1.0, feedback)  # 2 m: 2 s if not canceled
    if handle is None or not handle.accepted:
        report.add("it accepts a 2 m goal (to cancel it) within 2 s", False,
                   "no answer" if handle is None else "the goal was rejected",
                   "If the execute callback blocks (time.sleep), the executor cannot answer anything "
                   "else meanwhile: make it `async def` and `await sleep_async(self, 0.1)`.")
        return
    rt.wait_until(lambda: len(feedback) >= 2, 2.0, "two feedback messages")
    try:
        answer = rt.wait_for_future(handle.cancel_goal_async(), 1.0, "the cancel response")
    except TimeoutError:
        answer = None
    accepted = answer is not None and answer.return_code == CancelGoal.Response.ERROR_NONE \
        and len(answer.goals_canceling) == 1
    report.add("it accepts the cancel request", accepted,
               "" if accepted else "the cancel request was refused or not answered",
               "rclpy refuses every cancel by default: pass cancel_callback=self.on_cancel "
               "returning CancelResponse.ACCEPT.")
    try:
        outcome = rt.wait_for_future(handle.get_result_async(), 1.0, "the canceled goal's result")
    except TimeoutError:
        report.add("the canceled goal ends within 1 s", False, "no result",
                   "Check goal_handle.is_cancel_requested every step; if set, call goal_handle.canceled() "
                   "and return. A blocking sleep (time.sleep) stops the executor from even hearing "
                   "the cancel request.")
        rt.wait_for_future(handle.get_result_async(), 5.0, "the goal's end")
        return
    result = outcome.result
    honoured = (outcome.status == GoalStatus.STATUS_CANCELED and not result.success
                and 0.0 < result.distance_travelled < 2.0)
    report.add("the canceled goal ends CANCELED, success=False, with the distance driven so far",
               honoured, "" if honoured else f"status {status_name(outcome.status)}, "
               f"success={result.success}, distance_travelled={result.distance_travelled:.2f}",
               "goal_handle.canceled(), then return Navigate.Result(success=False, "
               "distance_travelled=travelled).")
