"""What ``%ros2 topic`` commands ask the graph, and the hidden node they subscribe or publish with."""

from __future__ import annotations

import collections
import contextlib
import copy
import time

from rclpy.node import Node
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSPresetProfiles,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_policy_name_from_kind,
)

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.validation import resolve_interface

TYPE_DISCOVERY_S = 2.0  # how long echo/hz/bw wait for a topic's type to appear in the graph


def topic_types(rt, topic: str) -> list[str]:
    for name, types in rt.graph.get_topic_names_and_types():
        if name == topic:
            return list(types)
    return []


def message_class(type_name: str):
    cls = resolve_interface(type_name, "msg")
    if hasattr(cls, "Request") or hasattr(cls, "Goal") or not hasattr(cls, "get_fields_and_field_types"):
        raise CourseError(f"{type_name!r} is not a message type; topics carry messages such as "
                          "std_msgs/msg/String or geometry_msgs/msg/Twist")
    return cls


def profile_from_arguments(args) -> tuple[QoSProfile, bool]:
    """The QoS profile the --qos-* flags describe, and whether any policy flag was given."""
    profile = copy.copy(QoSPresetProfiles.get_from_short_key(args.qos_profile))
    explicit = False
    if args.qos_history is not None:
        profile.history = QoSHistoryPolicy.get_from_short_key(args.qos_history)
        explicit = True
    if args.qos_depth is not None:
        profile.depth = args.qos_depth
        explicit = True
    if args.qos_reliability is not None:
        profile.reliability = QoSReliabilityPolicy.get_from_short_key(args.qos_reliability)
        explicit = True
    if args.qos_durability is not None:
        profile.durability = QoSDurabilityPolicy.get_from_short_key(args.qos_durability)
        explicit = True
    return profile, explicit


def choose_subscription_qos(rt, topic: str, args) -> QoSProfile:
    """ros2cli's choice for echo/hz/bw: the flags if given, else adapt to the publishers' offers.

    Reliable only if every publisher is reliable, transient-local only if every
    publisher is, so the subscription connects to all of them.
    """
    profile, explicit = profile_from_arguments(args)
    if explicit:
        return profile
    publishers = rt.graph.get_publishers_info_by_topic(topic)
    if not publishers:
        return profile
    choices = (("reliability", QoSReliabilityPolicy.RELIABLE, QoSReliabilityPolicy.BEST_EFFORT),
               ("durability", QoSDurabilityPolicy.TRANSIENT_LOCAL, QoSDurabilityPolicy.VOLATILE))
    for policy, strong, weak in choices:
        offering = sum(getattr(p.qos_profile, policy) == strong for p in publishers)
        if 0 < offering < len(publishers):
            print(f"Some, but not all, publishers are offering {_policy(strong)}. Falling back to "
                  f"{_policy(weak)} as it will connect to all publishers")
        setattr(profile, policy, strong if offering == len(publishers) else weak)
    return profile


@contextlib.contextmanager
def temporary_node(rt, verb: str):
    """A hidden node ``_ros2cli_<verb>`` spun by the runtime's executor, destroyed with its entities at exit.

    Like ros2cli's ``_ros2cli_<pid>`` node. It is added to the executor directly,
    not with ``rt.add``: it is no node of the notebook's, needs no console widget,
    and must not show up in ``rt.nodes()``.
    """
    rt.graph  # noqa: B018 - starts the runtime if it was stopped
    node = Node(f"_ros2cli_{verb}", context=rt.context, enable_rosout=False, start_parameter_services=False)
    executor = rt.executor
    executor.add_node(node)

    def destroy():
        executor.remove_node(node)
        node.destroy_node()

    try:
        yield node
    finally:
        rt.call_in_executor(destroy)


def discover_type(rt, topic: str, what: str) -> str:
    """The single type of ``topic`` in the graph, waiting briefly for it to appear."""
    try:
        rt.wait_until(lambda: topic_types(rt, topic), TYPE_DISCOVERY_S, f"topic {topic}")
    except WaitTimeout:
        raise CourseError(f"Could not determine the type for the passed topic {topic!r}: it is not in the "
                          f"graph after {TYPE_DISCOVERY_S:g} s. Check %ros2 topic list, or pass the type: "
                          f"%ros2 topic {what} {topic} std_msgs/msg/String") from None
    types = topic_types(rt, topic)
    if len(types) > 1:
        raise CourseError(f"Cannot {what} topic {topic!r}, as it contains more than one type: "
                          f"[{', '.join(types)}]; pass the one you want after the topic name")
    return types[0]


def watch_events(inbox: collections.deque):
    """Subscription event callbacks that queue rclpy's incompatible-QoS/-type warnings for the cell.

    rclpy's default callbacks would log them from the executor thread, where a
    notebook cell never sees them; the command prints them from ``inbox`` instead.
    """
    from rclpy.event_handler import SubscriptionEventCallbacks

    return SubscriptionEventCallbacks(
        incompatible_qos=lambda event: inbox.append(
            ("warning", "New publisher discovered on topic '{topic}', offering incompatible QoS. No messages "
                        "will be received from it. Last incompatible policy: "
                        + qos_policy_name_from_kind(event.last_policy_kind))),
        incompatible_type=lambda _event: inbox.append(
            ("warning", "Incompatible type on topic '{topic}', no messages will be sent to it.")))


def print_warning(node: Node, topic: str, template: str) -> None:
    print(f"[WARN] [{time.time():.9f}] [{node.get_name()}]: {template.format(topic=topic)}")


def _policy(value) -> str:
    """'QoSReliabilityPolicy.RELIABLE', as ros2cli prints a policy value."""
    return f"{type(value).__name__}.{value.name}"
