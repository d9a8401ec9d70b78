"""Checker of chapter 05 (actions): the navigation action server (course_interfaces/action/Navigate).

The checker runs the student's server, and its own action client, on a clock it owns
(:func:`~course_helpers.checks.student_on_clock`): the trip's pace is measured in that clock's time,
exactly, and the verdict is the same on any machine, however busy.
"""

from __future__ import annotations

import contextlib
import math

from action_msgs.msg import GoalStatus
from action_msgs.srv import CancelGoal
from rclpy.action import ActionClient, ActionServer
from rclpy.action.graph import get_action_server_names_and_types_by_node
from rclpy.node import Node

from course_helpers.chapters.ch05_actions import status_name
from course_helpers.checks import CheckReport, callback_errors_criterion, student_on_clock
from course_helpers.core.runtime import get_runtime
from course_helpers.core.sim_clock import MATCH_TIMEOUT_S
from course_helpers.core.waiting import wait_until

MAX_SPEED = 1.5  # [m/s] the exercise's speed limit
STEP_S = 0.1  # [s] the exercise's control period
RESULT_WITHIN_S = 3.0  # [s of the checker's clock] the 0.5 m trip must have ended by then
TRIP_M, TRIP_SPEED = 0.5, 1.0  # the timed trip: 0.5 m at 1 m/s, five steps of 0.1 m
CLOCK_STEP_S = 0.01  # the checker's clock moves in steps this long
CANCEL_WITHIN_S = 1.0  # [s] a canceled goal must have ended by then


def check_navigation_server(node_class, rt=None) -> CheckReport:
    """Exercise 05: send goals to ``node_class``'s ``navigate`` action, reject bad ones, cancel one.

    Returns a CheckReport of ``node_class`` (the student's node class, built without
    arguments) run in ``rt`` (default: this kernel's runtime), with a hint per failure.
    """
    from course_interfaces.action import Navigate

    rt = rt or get_runtime()
    report = CheckReport("Exercise 05 - navigation action server")
    with student_on_clock(report, rt, node_class, "navigation_checker") as (node, probe, clock):
        if node is None:
            return report
        client = ActionClient(probe, Navigate, "/navigate")
        if _check_navigation(report, node, probe, clock, client, Navigate):
            callback_errors_criterion(report, clock.errors)
        client.destroy()
    _check_destroy_node(rt, report, node_class)
    return report


def _check_navigation(report, node, probe, clock, client, navigate) -> bool:
    """The behaviour criteria; False when the node is too far off for the rest to mean anything."""
    named = node.get_name() == "navigation_server"
    if not report.add("the node is called navigation_server", named,
                      "" if named else f"it is called {node.get_name()!r}",
                      "The exercise names the node: compare it with the name your constructor passes on."):
        return False
    servers = [w for w in node.waitables if isinstance(w, ActionServer)]
    listed = get_action_server_names_and_types_by_node(probe, node.get_name(), node.get_namespace())
    served = ("/navigate", ["course_interfaces/action/Navigate"]) in listed  # this process's: listed at once
    if served:  # its services and topics match the client's a moment later
        wait_until(client.server_is_ready, MATCH_TIMEOUT_S, "the navigate action's server and client")
    if not report.add("it has an ActionServer for navigate (course_interfaces/action/Navigate)", served,
                      "" if servers else "the node has no ActionServer",
                      "TODO 1: section 2's FibonacciServer creates one; the exercise names the action "
                      "and its type."):
        return False
    for speed in (0.0, 3.0):
        accepted = _send(clock, client, navigate, 0.3, 0.4, speed)
        rejected = accepted is not None and not accepted.accepted
        report.add(f"it rejects a goal with speed {speed:g} m/s", rejected,
                   "" if accepted is None or not accepted.accepted else "the goal was accepted",
                   "TODO 2 and section 2's on_goal: which callback decides about a goal, does the "
                   "ActionServer know it, and which speeds does the exercise allow?")
    _check_trip(report, clock, client, navigate)
    _check_cancel(report, clock, client, navigate)
    return True


def _send(clock, client, navigate, x, y, speed, feedback=None):
    """Send a goal; the goal handle once answered (None if the server never answers).
    ``feedback`` (a list) collects (the checker's time [s], feedback message) pairs."""
    goal = navigate.Goal()
    goal.target.x, goal.target.y, goal.speed = float(x), float(y), float(speed)
    callback = ((lambda msg: feedback.append((clock.now_s, msg.feedback)))
                if feedback is not None else None)
    future = client.send_goal_async(goal, feedback_callback=callback)
    clock.settle()  # the request, the server's answer and the response: all delivered by now
    return future.result() if future.done() else None


def _check_trip(report, clock, client, navigate) -> None:
    feedback: list = []
    handle = _send(clock, client, navigate, 0.3, 0.4, TRIP_SPEED, feedback)
    if not report.add("it accepts a goal to (0.3, 0.4) at 1 m/s", handle is not None and handle.accepted, "",
                      "Which speeds does the exercise allow? Is 1 m/s among them?"):
        return
    started = clock.now_s
    result_future = handle.get_result_async()
    if not clock.advance_until(result_future.done, RESULT_WITHIN_S, CLOCK_STEP_S):
        report.add(f"the 0.5 m trip ends within {RESULT_WITHIN_S:g} s", False, "no result",
                   "Section 2's execute callback shows how a goal steps and ends: does your loop end, "
                   "and does the goal succeed?")
        return
    took = clock.now_s - started
    outcome = result_future.result()
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
    steps = round(TRIP_M / (TRIP_SPEED * STEP_S))
    paced = math.isclose(took, steps * STEP_S, abs_tol=1.5 * CLOCK_STEP_S)
    report.add("it steps every 0.1 s (the 0.5 m trip at 1 m/s takes 0.5 s of its clock)", paced,
               f"it took {took:.2f} s", "The exercise's second bullet: how long does one step wait?")
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


def _check_cancel(report, clock, client, navigate) -> None:
    feedback: list = []
    handle = _send(clock, client, navigate, 1.2, 1.6, 1.0, feedback)  # 2 m: 2 s if not canceled
    if handle is None or not handle.accepted:
        report.add("it accepts a 2 m goal (to cancel it)", False,
                   "no answer" if handle is None else "the goal was rejected",
                   "Which speeds does the exercise allow? Is 1 m/s among them?")
        return
    clock.advance_until(lambda: len(feedback) >= 2, 2.0, CLOCK_STEP_S)  # without feedback: after 2 s
    cancel_future = handle.cancel_goal_async()
    clock.settle()
    answer = cancel_future.result() if cancel_future.done() else None
    accepted = answer is not None and answer.return_code == CancelGoal.Response.ERROR_NONE \
        and len(answer.goals_canceling) == 1
    report.add("it accepts the cancel request", accepted,
               "" if accepted else "the cancel request was refused or not answered",
               "TODO 3, and section 2: what does rclpy answer to a cancel request by default?")
    result_future = handle.get_result_async()
    if not clock.advance_until(result_future.done, CANCEL_WITHIN_S, CLOCK_STEP_S):
        report.add(f"the canceled goal ends within {CANCEL_WITHIN_S:g} s", False, "no result",
                   "Section 5: how does the execute callback notice a cancel request, and how often "
                   "does yours look?")
        clock.advance_until(result_future.done, 5.0, CLOCK_STEP_S)  # let the trip end before the clean-up
        return
    outcome = result_future.result()
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
