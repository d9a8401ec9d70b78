"""``%ros2 action list|info|type|send_goal`` (chapter 05).
"""

from __future__ import annotations

import collections
import time

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.msg_yaml import (
    message_to_yaml,
    set_message_fields,
    values_from_yaml,
)
from course_helpers.core.validation import interface_name, resolve_interface
from course_helpers.core.waiting import poll_until
from course_helpers.notebook.ros2cli._common import (
    _TICK_S,
    SERVICE_WAIT_S,
    Verb,
    _check_same_type,
    _positive_float,
    _topic_arg,
    add_verb_table,
    count_of,
    name_of,
    option,
    print_names,
    print_types,
    show_types,
)


def _action_list(rt, args):
    from rclpy.action import get_action_names_and_types

    print_names(sorted(get_action_names_and_types(rt.graph)), args.show_types, args.count_actions)
    return None


def _action_endpoints(rt, action: str):
    from rclpy.action import graph as action_graph

    clients, servers = [], []
    for name, namespace in rt.graph.get_node_names_and_namespaces():
        fqn = namespace.rstrip("/") + "/" + name
        for found, getter in ((clients, action_graph.get_action_client_names_and_types_by_node),
                              (servers, action_graph.get_action_server_names_and_types_by_node)):
            try:
                pairs = getter(rt.graph, name, namespace)
            except Exception:  # the node left the graph meanwhile
                continue
            found.extend((fqn, types) for each, types in pairs if each == action)
    return sorted(clients), sorted(servers)


def _action_info(rt, args):
    action = _topic_arg(args.action_name)
    clients, servers = _action_endpoints(rt, action)
    print(f"Action: {action}")
    for title, endpoints in (("Action clients", clients), ("Action servers", servers)):
        print(f"{title}: {len(endpoints)}")
        if args.count:
            continue
        for fqn, types in endpoints:
            print(f"    {fqn} [{', '.join(types)}]" if args.show_types else f"    {fqn}")
    return None


def _action_types(rt, action: str) -> list[str]:
    from rclpy.action import get_action_names_and_types

    for name, types in get_action_names_and_types(rt.graph):
        if name == action:
            return list(types)
    return []


def _action_type(rt, args):
    return print_types("action", args.action_name, _action_types(rt, _topic_arg(args.action_name)))


_GOAL_STATUS = {1: "ACCEPTED", 2: "EXECUTING", 3: "CANCELING", 4: "SUCCEEDED", 5: "CANCELED", 6: "ABORTED"}


def _action_send_goal(rt, args):
    from rclpy.action import ActionClient

    action = _topic_arg(args.action_name)
    action_class = resolve_interface(args.action_type, "action")
    if not hasattr(action_class, "Goal"):
        raise CourseError(f"{args.action_type!r} is not an action type; actions use types such as "
                          "course_interfaces/action/Fibonacci")
    _check_same_type("action", action, action_class, _action_types(rt, action))
    goal = set_message_fields(action_class.Goal(), values_from_yaml(args.goal, "goal"),
                              now=lambda: rt.graph.get_clock().now().to_msg())
    feedback: collections.deque = collections.deque()
    client = ActionClient(rt.graph, action_class, action)
    goal_handle = None
    try:
        print("Waiting for an action server to become available...")
        try:
            rt.wait_until(client.server_is_ready, SERVICE_WAIT_S, f"action server {action}")
        except WaitTimeout:
            return (f"Action server {action} ({interface_name(action_class)}) did not become available "
                    f"within {SERVICE_WAIT_S:g} s; check %ros2 action list -t")
        print(f"Sending goal:\n     {message_to_yaml(goal)}")
        on_feedback = (lambda fb: feedback.append(fb.feedback)) if args.feedback else None
        deadline = time.monotonic() + args.timeout
        goal_handle = rt.wait_for_future(client.send_goal_async(goal, feedback_callback=on_feedback),
                                         args.timeout, f"the goal response of {action}")
        if not goal_handle.accepted:
            goal_handle = None
            print("Goal was rejected.")
            return None
        print(f"Goal accepted with ID: {bytes(goal_handle.goal_id.uuid).hex()}\n")
        result_future = goal_handle.get_result_async()

        def print_feedback() -> bool:  # True once the result is in
            while feedback:
                print(f"Feedback:\n    {message_to_yaml(feedback.popleft())}")
            return result_future.done()

        if not poll_until(print_feedback, max(0.0, deadline - time.monotonic()), period=_TICK_S):
            return f"No result within {args.timeout:g} s (see --timeout)"
        print_feedback()
        result = result_future.result()
        goal_handle = None
        print(f"Result:\n    {message_to_yaml(result.result)}")
        print(f"Goal finished with status: {_GOAL_STATUS.get(result.status, 'UNKNOWN')}")
    finally:
        if goal_handle is not None and goal_handle.status in (0, 1, 2):  # unknown/accepted/executing
            print("Canceling goal...")
            try:
                rt.wait_for_future(goal_handle.cancel_goal_async(), SERVICE_WAIT_S, "the cancel response")
                print("Goal canceled.")
            except WaitTimeout:
                print("(no answer to the cancel request)")
        rt.call_in_executor(client.destroy)
    return None


ACTION_NAME = name_of("action", "action_name", "/fibonacci")
VERBS = (
    Verb("list", "Output a list of action names", _action_list, (show_types("action"), count_of("actions"))),
    Verb("info", "Print information about an action", _action_info, (
        ACTION_NAME, show_types("action"),
        count_of("actions", flag="--count", what="action clients and action servers"))),
    Verb("type", "Print an action's type", _action_type, (ACTION_NAME,)),
    Verb("send_goal", "Send an action goal", _action_send_goal, (
        ACTION_NAME,
        option("action_type", help="Type of the ROS action, e.g. course_interfaces/action/Fibonacci"),
        option("goal", nargs="?", default="{}", help="Goal values in YAML, e.g. \"{order: 5}\""),
        option("-f", "--feedback", action="store_true", help="Echo feedback messages for the goal"),
        option("--timeout", type=_positive_float, default=60.0, metavar="S",
               help="Give up (and cancel the goal) after S seconds (default: 60)"))),
)


def add_verbs(parser):
    add_verb_table(parser, VERBS)
