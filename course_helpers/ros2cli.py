"""The ``ros2`` command-line tool, re-implemented on the course runtime (the ``%ros2`` magic).

ros2cli cannot be installed from PyPI, so the notebooks get the same verbs here,
with ros2cli's output format, run against the live graph of the kernel's ROS
domain. Chapters 01-10 use them: 01 ``node``, 03 ``topic`` (list/info/echo/hz/pub),
04 ``service``, 05 ``action``, 06 ``param``, 08 the ``--qos-*`` flags of
``topic echo``/``topic pub``; ``interface show`` wherever a type is introduced.

``run('topic echo /chatter --count 2')`` (or a list of arguments) prints what
``ros2 topic echo /chatter`` would print and returns an exit code. Nothing here
spins in the calling thread: subscriptions, publishers and clients live on the
runtime's hidden node (``rt.graph``) or on a temporary hidden node
``_ros2cli_<verb>`` spun by the runtime's executor, and the calling thread only
waits and prints. Long commands stop after ``--count``/``--times``/``--duration``
(or a default duration, which they announce) or when the cell is interrupted,
and always destroy what they created.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import copy
import math
import os
import shlex
import sys
import threading
import time
from collections.abc import Callable

import yaml
from rclpy.node import Node
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSPresetProfiles,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_policy_name_from_kind,
)

from .errors import CourseError, WaitTimeout
from .msg_yaml import (
    element_type,
    message_to_csv,
    message_to_dict,
    message_to_yaml,
    plain_value,
    set_message_fields,
    values_from_yaml,
)
from .validation import check_topic_name, interface_name, resolve_interface

__all__ = ["build_parser", "message_to_dict", "message_to_yaml", "run", "set_message_fields"]

ECHO_DEFAULT_S = 10.0  # topic echo stops after this long unless --count/--once/--duration says otherwise
HZ_DEFAULT_S = 5.0  # topic hz and topic bw measure this long by default
PUB_DEFAULT_S = 10.0  # topic pub without --once/--times publishes this long
TYPE_DISCOVERY_S = 2.0  # how long echo/hz/bw wait for a topic's type to appear in the graph
SERVICE_WAIT_S = 5.0  # how long to wait for a service or action server to appear
MATCH_WAIT_S = 5.0  # how long topic pub waits for matching subscriptions
TRUNCATE_LENGTH = 128  # ros2cli's default for arrays and strings in echo
_TICK_S = 0.02  # how often a waiting command checks for news


class _UsageError(Exception):
    def __init__(self, parser: argparse.ArgumentParser, message: str):
        super().__init__(message)
        self.parser = parser


class _ParserExit(Exception):
    def __init__(self, status: int):
        super().__init__(status)
        self.status = status


class _Formatter(argparse.HelpFormatter):
    """Usage and help wrapped at a fixed width, so saved notebook outputs do not depend on the terminal."""

    def __init__(self, prog):
        super().__init__(prog, width=100)


class _Parser(argparse.ArgumentParser):
    """argparse that prints into the cell (stdout) and raises instead of calling sys.exit()."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _Formatter)
        super().__init__(*args, **kwargs)

    def error(self, message):
        raise _UsageError(self, message)

    def exit(self, status=0, message=None):
        if message:
            print(message, end="")
        raise _ParserExit(status)

    def _print_message(self, message, file=None):
        if message:
            print(message, end="")


# ====================================================================== entry point
def run(argv: list[str] | str, rt=None) -> int:
    """Run one ``ros2`` command, e.g. ``run('topic list -t')``; print its output, return an exit code.

    0 means success, 1 a failed command (printed like ros2cli does), 2 a usage error
    (the usage is printed, naming the allowed sub-commands). ``rt`` defaults to
    :func:`course_helpers.get_runtime`.
    """
    if isinstance(argv, str):
        try:
            argv = shlex.split(argv)
        except ValueError as exc:  # e.g. an unclosed quote
            print(f"error: cannot split the command line: {exc}. Quote YAML values like "
                  "\"{data: hello}\".")
            return 2
    argv = list(argv)
    if argv[:1] == ["ros2"]:
        argv = argv[1:]
    parser = build_parser()
    if not argv:
        parser.print_help()
        return 0
    try:
        args = parser.parse_args(argv)
    except _ParserExit as exc:
        return exc.status
    except _UsageError as exc:
        group = getattr(exc.parser, "lists_verbs", False) and "required" in str(exc)
        # a bare command such as 'topic' gets the list of its verbs, as in ros2cli
        print(exc.parser.format_help() if group else exc.parser.format_usage(), end="")
        print(f"{exc.parser.prog}: error: {exc}")
        return 2
    if rt is None:
        from .runtime import get_runtime

        rt = get_runtime()
    try:
        failure = args.func(rt, args)
    except KeyboardInterrupt:  # the cell was interrupted: the command cleaned up, ROS keeps running
        return 130
    except (CourseError, WaitTimeout) as exc:
        print(f"error: {exc}")
        return 1
    if failure:
        print(failure)
        return 1
    return 0


# ====================================================================== parser
def build_parser() -> argparse.ArgumentParser:
    """The argparse tree of all supported commands (``ros2 <command> <verb> ...``)."""
    parser = _Parser(prog="ros2", description="ros2 commands for the notebook (a subset of ros2cli).")
    commands = parser.add_subparsers(dest="command", metavar="{node,topic,service,action,param,interface}",
                                     title="commands", parser_class=_Parser)
    commands.required = True
    _add_node_verbs(commands.add_parser("node", help="Inspect nodes"))
    _add_topic_verbs(commands.add_parser("topic", help="Inspect, echo and publish topics"))
    _add_service_verbs(commands.add_parser("service", help="Inspect and call services"))
    _add_action_verbs(commands.add_parser("action", help="Inspect actions and send goals"))
    _add_param_verbs(commands.add_parser("param", help="List, get, set and dump parameters"))
    _add_interface_verbs(commands.add_parser("interface", help="Show message/service/action definitions"))
    return parser


def _verbs(parser):
    verbs = parser.add_subparsers(dest="verb", title="verbs", parser_class=_Parser)
    verbs.required = True
    parser.lists_verbs = True
    return verbs


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


def _non_negative_int(text):
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return value


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not value > 0 or math.isinf(value):
        raise argparse.ArgumentTypeError(f"expected a number of seconds/Hz > 0, got {text!r}")
    return value


def _non_negative_float(text):
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value >= 0 or math.isinf(value):
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return value


def _add_qos_arguments(parser, entity: str, default_profile: str) -> None:
    parser.add_argument("--qos-profile", choices=QoSPresetProfiles.short_keys(), default=default_profile,
                        help=f"QoS preset profile to {entity} with (default: {default_profile})")
    parser.add_argument("--qos-depth", type=_positive_int, metavar="N",
                        help="Queue size setting to " + entity + " with (overrides the profile's depth)")
    parser.add_argument("--qos-history", choices=QoSHistoryPolicy.short_keys(),
                        help="History of samples setting to " + entity + " with")
    parser.add_argument("--qos-reliability", choices=QoSReliabilityPolicy.short_keys(),
                        help="Reliability setting to " + entity + " with")
    parser.add_argument("--qos-durability", choices=QoSDurabilityPolicy.short_keys(),
                        help="Durability setting to " + entity + " with")


def _add_node_verbs(parser):
    verbs = _verbs(parser)
    p = verbs.add_parser("list", help="Output a list of available nodes")
    p.add_argument("-a", "--all", action="store_true", help="Display all nodes even hidden ones")
    p.add_argument("-c", "--count-nodes", action="store_true", help="Only display the number of nodes")
    p.set_defaults(func=_node_list)
    p = verbs.add_parser("info", help="Output information about a node")
    p.add_argument("node_name", help="Fully qualified node name, e.g. /talker")
    p.add_argument("--include-hidden", action="store_true",
                   help="Display hidden topics, services, and actions as well")
    p.set_defaults(func=_node_info)


def _add_topic_verbs(parser):
    verbs = _verbs(parser)
    p = verbs.add_parser("list", help="Output a list of available topics")
    p.add_argument("-t", "--show-types", action="store_true", help="Additionally show the topic type")
    p.add_argument("-c", "--count-topics", action="store_true", help="Only display the number of topics")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="List full details about each topic (publishers and subscribers)")
    p.add_argument("--include-hidden-topics", action="store_true", help="Consider hidden topics as well")
    p.set_defaults(func=_topic_list)

    p = verbs.add_parser("info", help="Print information about a topic")
    p.add_argument("topic_name", help="Name of the ROS topic, e.g. /chatter")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="Print node name, type, GID and QoS profile of each publisher and subscription")
    p.set_defaults(func=_topic_info)

    p = verbs.add_parser("type", help="Print a topic's type")
    p.add_argument("topic_name", help="Name of the ROS topic, e.g. /chatter")
    p.set_defaults(func=_topic_type)

    p = verbs.add_parser("find", help="Output a list of available topics of a given type")
    p.add_argument("topic_type", help="Name of the ROS topic type, e.g. std_msgs/msg/String")
    p.add_argument("-c", "--count-topics", action="store_true", help="Only display the number of topics")
    p.set_defaults(func=_topic_find)

    p = verbs.add_parser("echo", help="Output messages from a topic")
    p.add_argument("topic_name", help="Name of the ROS topic to listen to, e.g. /chatter")
    p.add_argument("message_type", nargs="?",
                   help="Type of the message, e.g. std_msgs/msg/String (default: found in the graph)")
    p.add_argument("--once", action="store_true", help="Print the first message received and stop")
    p.add_argument("--count", type=_positive_int, metavar="N", help="Stop after N messages")
    p.add_argument("--duration", "--timeout", dest="duration", type=_positive_float, metavar="S",
                   help=f"Stop after S seconds (default: {ECHO_DEFAULT_S:g} s unless --count/--once)")
    p.add_argument("--field", help="Echo a selected field of the message, e.g. 'linear.x'")
    p.add_argument("--csv", action="store_true", help="Output all fields separated by commas")
    p.add_argument("-f", "--full-length", action="store_true",
                   help="Output all elements of arrays and strings (no truncation)")
    p.add_argument("-l", "--truncate-length", type=_non_negative_int, default=TRUNCATE_LENGTH,
                   metavar="N",
                   help=f"Truncate arrays and strings to N elements (default: {TRUNCATE_LENGTH})")
    p.add_argument("--no-arr", action="store_true", help="Don't print array fields of messages")
    p.add_argument("--no-str", action="store_true", help="Don't print string fields of messages")
    p.add_argument("--flow-style", action="store_true", help="Print messages in YAML flow style (one line)")
    _add_qos_arguments(p, "subscribe", "sensor_data")
    p.set_defaults(func=_topic_echo)

    p = verbs.add_parser("hz", help="Print the average receiving rate")
    p.add_argument("topic_name", help="Name of the ROS topic to listen to, e.g. /chatter")
    p.add_argument("-w", "--window", type=_positive_int, default=10000, metavar="N",
                   help="Window size, in number of messages, for calculating the rate (default: 10000)")
    p.add_argument("--duration", type=_positive_float, metavar="S",
                   help=f"Measure for S seconds (default: {HZ_DEFAULT_S:g})")
    _add_qos_arguments(p, "subscribe", "sensor_data")
    p.set_defaults(func=_topic_hz)

    p = verbs.add_parser("bw", help="Display the bandwidth used by a topic")
    p.add_argument("topic_name", help="Name of the ROS topic to listen to, e.g. /chatter")
    p.add_argument("-w", "--window", type=_positive_int, default=100, metavar="N",
                   help="Maximum window size, in number of messages (default: 100)")
    p.add_argument("--duration", type=_positive_float, metavar="S",
                   help=f"Measure for S seconds (default: {HZ_DEFAULT_S:g})")
    _add_qos_arguments(p, "subscribe", "sensor_data")
    p.set_defaults(func=_topic_bw)

    p = verbs.add_parser("pub", help="Publish a message to a topic")
    p.add_argument("topic_name", help="Name of the ROS topic to publish to, e.g. /cmd_vel")
    p.add_argument("message_type", help="Type of the message, e.g. geometry_msgs/msg/Twist")
    p.add_argument("values", nargs="?", default="{}",
                   help="Values of the message in YAML, e.g. \"{linear: {x: 0.5}, angular: {z: 0.1}}\"")
    p.add_argument("-r", "--rate", type=_positive_float, default=1.0, metavar="N",
                   help="Publishing rate in Hz (default: 1)")
    p.add_argument("-p", "--print", dest="print_nth", type=_non_negative_int, default=1, metavar="N",
                   help="Print every N-th published message (0: print none; default: 1)")
    how_long = p.add_mutually_exclusive_group()
    how_long.add_argument("-1", "--once", action="store_true", help="Publish one message and stop")
    how_long.add_argument("-t", "--times", type=_positive_int, metavar="N",
                          help="Publish N messages and stop")
    how_long.add_argument("--duration", type=_positive_float, metavar="S",
                          help=f"Publish for S seconds (default without --once/--times: {PUB_DEFAULT_S:g})")
    p.add_argument("-w", "--wait-matching-subscriptions", type=_non_negative_int, metavar="N",
                   help="Wait for N matching subscriptions first (default: 1 with --once/--times, else 0)")
    p.add_argument("--max-wait-time-secs", type=_positive_float, default=MATCH_WAIT_S, metavar="S",
                   help=f"Longest wait for matching subscriptions (default: {MATCH_WAIT_S:g})")
    p.add_argument("--keep-alive", type=_non_negative_float, default=0.1, metavar="S",
                   help="Keep the publisher alive S seconds after the last message (default: 0.1)")
    _add_qos_arguments(p, "publish", "default")
    p.set_defaults(func=_topic_pub)


def _add_service_verbs(parser):
    verbs = _verbs(parser)
    p = verbs.add_parser("list", help="Output a list of available services")
    p.add_argument("-t", "--show-types", action="store_true", help="Additionally show the service type")
    p.add_argument("-c", "--count-services", action="store_true", help="Only display the number of services")
    p.add_argument("--include-hidden-services", action="store_true", help="Consider hidden services as well")
    p.set_defaults(func=_service_list)
    p = verbs.add_parser("type", help="Output a service's type")
    p.add_argument("service_name", help="Name of the ROS service, e.g. /add_two_ints")
    p.set_defaults(func=_service_type)
    p = verbs.add_parser("find", help="Output a list of available services of a given type")
    p.add_argument("service_type", help="Name of the ROS service type, e.g. std_srvs/srv/SetBool")
    p.set_defaults(func=_service_find)
    p = verbs.add_parser("call", help="Call a service")
    p.add_argument("service_name", help="Name of the ROS service to call, e.g. /add_two_ints")
    p.add_argument("service_type", help="Type of the ROS service, e.g. std_srvs/srv/SetBool")
    p.add_argument("values", nargs="?", default="{}", help="Request values in YAML, e.g. \"{data: true}\"")
    p.add_argument("--timeout", type=_positive_float, default=SERVICE_WAIT_S, metavar="S",
                   help=f"Wait at most S seconds for the server and for the response "
                        f"(default: {SERVICE_WAIT_S:g})")
    p.set_defaults(func=_service_call)


def _add_action_verbs(parser):
    verbs = _verbs(parser)
    p = verbs.add_parser("list", help="Output a list of action names")
    p.add_argument("-t", "--show-types", action="store_true", help="Additionally show the action type")
    p.add_argument("-c", "--count-actions", action="store_true", help="Only display the number of actions")
    p.set_defaults(func=_action_list)
    p = verbs.add_parser("info", help="Print information about an action")
    p.add_argument("action_name", help="Name of the ROS action, e.g. /fibonacci")
    p.add_argument("-t", "--show-types", action="store_true", help="Additionally show the action type")
    p.add_argument("-c", "--count", action="store_true",
                   help="Only display the number of action clients and action servers")
    p.set_defaults(func=_action_info)
    p = verbs.add_parser("type", help="Print an action's type")
    p.add_argument("action_name", help="Name of the ROS action, e.g. /fibonacci")
    p.set_defaults(func=_action_type)
    p = verbs.add_parser("send_goal", help="Send an action goal")
    p.add_argument("action_name", help="Name of the ROS action, e.g. /fibonacci")
    p.add_argument("action_type", help="Type of the ROS action, e.g. course_interfaces/action/Fibonacci")
    p.add_argument("goal", nargs="?", default="{}", help="Goal values in YAML, e.g. \"{order: 5}\"")
    p.add_argument("-f", "--feedback", action="store_true", help="Echo feedback messages for the goal")
    p.add_argument("--timeout", type=_positive_float, default=60.0, metavar="S",
                   help="Give up (and cancel the goal) after S seconds (default: 60)")
    p.set_defaults(func=_action_send_goal)


def _add_param_verbs(parser):
    verbs = _verbs(parser)
    p = verbs.add_parser("list", help="Output a list of available parameters")
    p.add_argument("node_name", nargs="?", help="Name of the ROS node (default: every node)")
    p.add_argument("--param-type", action="store_true", help="Print parameter types with parameter names")
    p.add_argument("--param-prefixes", nargs="+", default=[], metavar="PREFIX",
                   help="Only list parameters with the provided prefixes")
    p.add_argument("--include-hidden-nodes", action="store_true", help="Consider hidden nodes as well")
    p.set_defaults(func=_param_list)
    p = verbs.add_parser("get", help="Get a parameter")
    p.add_argument("node_name", help="Name of the ROS node, e.g. /talker")
    p.add_argument("parameter_name", help="Name of the parameter")
    p.add_argument("--hide-type", action="store_true", help="Hide the type information")
    p.add_argument("--include-hidden-nodes", action="store_true", help="Consider hidden nodes as well")
    p.set_defaults(func=_param_get)
    p = verbs.add_parser("set", help="Set a parameter")
    p.add_argument("node_name", help="Name of the ROS node, e.g. /talker")
    p.add_argument("parameter_name", help="Name of the parameter")
    p.add_argument("value", help="Value of the parameter (YAML: 5, 2.5, true, hello, [1, 2])")
    p.add_argument("--include-hidden-nodes", action="store_true", help="Consider hidden nodes as well")
    p.set_defaults(func=_param_set)
    p = verbs.add_parser("dump", help="Show all of the parameters of a node in YAML file format")
    p.add_argument("node_name", help="Name of the ROS node, e.g. /talker")
    p.add_argument("--include-hidden-nodes", action="store_true", help="Consider hidden nodes as well")
    p.set_defaults(func=_param_dump)
    p = verbs.add_parser("describe", help="Show descriptive information about declared parameters")
    p.add_argument("node_name", help="Name of the ROS node, e.g. /talker")
    p.add_argument("parameter_names", nargs="+", help="Names of the parameters")
    p.add_argument("--include-hidden-nodes", action="store_true", help="Consider hidden nodes as well")
    p.set_defaults(func=_param_describe)


def _add_interface_verbs(parser):
    verbs = _verbs(parser)
    p = verbs.add_parser("show", help="Output the interface definition")
    p.add_argument("type", help="Interface type, e.g. std_msgs/msg/String or std_srvs/srv/SetBool")
    comments = p.add_mutually_exclusive_group()
    comments.add_argument("--all-comments", action="store_true",
                          help="Show all comments, including for nested interface definitions")
    comments.add_argument("--no-comments", action="store_true", help="Show no comments or whitespace")
    p.set_defaults(func=_interface_show)
    p = verbs.add_parser("list", help="List all interface types available")
    p.add_argument("-m", "--only-msgs", action="store_true", help="Print out only the messages")
    p.add_argument("-s", "--only-srvs", action="store_true", help="Print out only the services")
    p.add_argument("-a", "--only-actions", action="store_true", help="Print out only the actions")
    p.set_defaults(func=_interface_list)
    p = verbs.add_parser("packages", help="Output a list of packages that provide interfaces")
    p.set_defaults(func=_interface_packages)
    p = verbs.add_parser("package", help="Output a list of the interfaces of a package")
    p.add_argument("package_name", help="Name of the package, e.g. std_msgs")
    p.set_defaults(func=_interface_package)


# ====================================================================== names and the graph
def _is_hidden(name: str) -> bool:
    """ROS hides names with a token starting with '_' (e.g. /fibonacci/_action/status)."""
    return any(token.startswith("_") for token in name.split("/"))


def _absolute(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def _topic_arg(name: str) -> str:
    if name.startswith("~"):
        raise CourseError(f"{name!r}: private names ('~/...') only make sense inside a node; "
                          "give the full name, e.g. '/talker/status'")
    return check_topic_name(_absolute(name))


def _split_node_name(fqn: str) -> tuple[str, str]:
    """'/ns/name' -> ('/ns', 'name'); '/name' -> ('/', 'name')."""
    namespace, _, name = _absolute(fqn).rpartition("/")
    return namespace or "/", name


def _graph_node_names(rt, include_hidden: bool) -> list[str]:
    """Full names of the nodes in the graph, sorted, duplicates kept (like ros2cli)."""
    names = []
    for name, namespace in rt.graph.get_node_names_and_namespaces():
        if name.startswith("_") and not include_hidden:
            continue
        names.append(namespace.rstrip("/") + "/" + name)
    return sorted(names)


def _topic_types(rt, topic: str) -> list[str]:
    for name, types in rt.graph.get_topic_names_and_types():
        if name == topic:
            return list(types)
    return []


def _service_types(rt, service: str) -> list[str]:
    for name, types in rt.graph.get_service_names_and_types():
        if name == service:
            return list(types)
    return []


def _require_node(rt, node_name: str, include_hidden: bool) -> str | None:
    """The absolute node name if the node is in the graph (waiting up to 1 s, as ros2cli does)."""
    fqn = _absolute(node_name)
    try:
        rt.wait_until(lambda: fqn in _graph_node_names(rt, include_hidden), 1.0, f"node {fqn}")
    except WaitTimeout:
        return None
    return fqn


def _print_names_and_types(pairs) -> None:
    # ros2cli prints one (possibly empty) line per section: print(*lines, sep='\n')
    print(*[f"    {name}: {', '.join(types)}" for name, types in pairs], sep="\n")


def _check_same_type(kind: str, name: str, cls, types_in_graph: list[str]) -> None:
    """Refuse a type other than the one the graph uses for ``name``.

    Endpoints of different types never connect, and Fast DDS refuses a second
    type for a topic within one process (the kernel), so say so up front.
    """
    wanted = interface_name(cls)
    if types_in_graph and wanted not in types_in_graph:
        raise CourseError(f"{kind} {name} has type {', '.join(types_in_graph)}, not {wanted}; endpoints of "
                          f"different types never connect. Use the type shown by %ros2 {kind} type {name}.")


def _message_class(type_name: str):
    cls = resolve_interface(type_name, "msg")
    if hasattr(cls, "Request") or hasattr(cls, "Goal") or not hasattr(cls, "get_fields_and_field_types"):
        raise CourseError(f"{type_name!r} is not a message type; topics carry messages such as "
                          "std_msgs/msg/String or geometry_msgs/msg/Twist")
    return cls


# ====================================================================== QoS
def _profile_from_arguments(args) -> tuple[QoSProfile, bool]:
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


def _choose_subscription_qos(rt, topic: str, args) -> QoSProfile:
    """ros2cli's choice for echo/hz/bw: the flags if given, else adapt to the publishers' offers.

    Reliable only if every publisher is reliable, transient-local only if every
    publisher is, so the subscription connects to all of them.
    """
    profile, explicit = _profile_from_arguments(args)
    if explicit:
        return profile
    publishers = rt.graph.get_publishers_info_by_topic(topic)
    if not publishers:
        return profile
    reliable = sum(p.qos_profile.reliability == QoSReliabilityPolicy.RELIABLE for p in publishers)
    transient = sum(p.qos_profile.durability == QoSDurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
    if reliable == len(publishers):
        profile.reliability = QoSReliabilityPolicy.RELIABLE
    else:
        if reliable:
            print("Some, but not all, publishers are offering QoSReliabilityPolicy.RELIABLE. Falling back "
                  "to QoSReliabilityPolicy.BEST_EFFORT as it will connect to all publishers")
        profile.reliability = QoSReliabilityPolicy.BEST_EFFORT
    if transient == len(publishers):
        profile.durability = QoSDurabilityPolicy.TRANSIENT_LOCAL
    else:
        if transient:
            print("Some, but not all, publishers are offering QoSDurabilityPolicy.TRANSIENT_LOCAL. Falling "
                  "back to QoSDurabilityPolicy.VOLATILE as it will connect to all publishers")
        profile.durability = QoSDurabilityPolicy.VOLATILE
    return profile


# ====================================================================== helpers for streaming verbs
@contextlib.contextmanager
def _temporary_node(rt, verb: str):
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


def _discover_type(rt, topic: str, what: str) -> str:
    """The single type of ``topic`` in the graph, waiting briefly for it to appear."""
    try:
        rt.wait_until(lambda: _topic_types(rt, topic), TYPE_DISCOVERY_S, f"topic {topic}")
    except WaitTimeout:
        raise CourseError(f"Could not determine the type for the passed topic {topic!r}: it is not in the "
                          f"graph after {TYPE_DISCOVERY_S:g} s. Check %ros2 topic list, or pass the type: "
                          f"%ros2 topic {what} {topic} std_msgs/msg/String") from None
    types = _topic_types(rt, topic)
    if len(types) > 1:
        raise CourseError(f"Cannot {what} topic {topic!r}, as it contains more than one type: "
                          f"[{', '.join(types)}]; pass the one you want after the topic name")
    return types[0]


def _watch_events(inbox: collections.deque):
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


def _print_warning(node: Node, topic: str, template: str) -> None:
    print(f"[WARN] [{time.time():.9f}] [{node.get_name()}]: {template.format(topic=topic)}")


# ====================================================================== node verbs
def _node_list(rt, args):
    names = _graph_node_names(rt, args.all)
    if args.count_nodes:
        print(len(names))
        return None
    if len(set(names)) < len(names):
        print("WARNING: Be aware that there are nodes in the graph that share an exact name, which can "
              "have unintended side effects.")
    for name in names:
        print(name)
    return None


def _node_info(rt, args):
    fqn = _absolute(args.node_name)
    names = _graph_node_names(rt, include_hidden=True)
    if fqn not in names:
        return f"Unable to find node '{args.node_name}'"
    if names.count(fqn) > 1:
        print(f'There are {names.count(fqn)} nodes in the graph with the exact name "{fqn}". '
              "You are seeing information about only one of them.")
    from rclpy.action import graph as action_graph

    namespace, name = _split_node_name(fqn)
    graph = rt.graph
    keep = (lambda pairs: sorted(pairs)) if args.include_hidden else (
        lambda pairs: sorted((n, t) for n, t in pairs if not _is_hidden(n)))
    try:
        sections = [
            ("Subscribers", graph.get_subscriber_names_and_types_by_node(name, namespace)),
            ("Publishers", graph.get_publisher_names_and_types_by_node(name, namespace)),
            ("Service Servers", graph.get_service_names_and_types_by_node(name, namespace)),
            ("Service Clients", graph.get_client_names_and_types_by_node(name, namespace)),
            ("Action Servers",
             action_graph.get_action_server_names_and_types_by_node(graph, name, namespace)),
            ("Action Clients",
             action_graph.get_action_client_names_and_types_by_node(graph, name, namespace)),
        ]
    except Exception:  # the node left the graph meanwhile
        return f"Unable to find node '{args.node_name}'"
    print(fqn)
    for title, pairs in sections:
        print(f"  {title}:")
        _print_names_and_types(keep(pairs))
    return None


# ====================================================================== topic verbs
def _topic_list(rt, args):
    pairs = sorted((n, t) for n, t in rt.graph.get_topic_names_and_types()
                   if args.include_hidden_topics or not _is_hidden(n))
    if args.count_topics:
        print(len(pairs))
        return None
    if args.verbose:
        for title, counter, noun in (("Published topics:", rt.graph.count_publishers, "publisher"),
                                     ("Subscribed topics:", rt.graph.count_subscribers, "subscriber")):
            print(title)
            for name, types in pairs:
                count = counter(name)
                if count:
                    print(f" * {name} [{', '.join(types)}] {count} {noun}{'s' if count > 1 else ''}")
            print()
        return None
    for name, types in pairs:
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return None


def _topic_info(rt, args):
    topic = _topic_arg(args.topic_name)
    types = _topic_types(rt, topic)
    if not types:
        return f"Unknown topic '{args.topic_name}'"
    end = "\n\n" if args.verbose else "\n"
    print(f"Type: {types[0] if len(types) == 1 else types}", end=end)
    print(f"Publisher count: {rt.graph.count_publishers(topic)}", end=end)
    if args.verbose:
        for info in rt.graph.get_publishers_info_by_topic(topic):
            print(info, end=end)
    print(f"Subscription count: {rt.graph.count_subscribers(topic)}", end=end)
    if args.verbose:
        for info in rt.graph.get_subscriptions_info_by_topic(topic):
            print(info, end=end)
    return None


def _topic_type(rt, args):
    topic = _topic_arg(args.topic_name)
    types = _topic_types(rt, topic)
    if not types:
        return f"Unknown topic '{args.topic_name}'"
    for each in types:
        print(each)
    return None


def _topic_find(rt, args):
    wanted = interface_name(_message_class(args.topic_type))
    names = sorted(n for n, types in rt.graph.get_topic_names_and_types()
                   if wanted in types and not _is_hidden(n))
    if args.count_topics:
        print(len(names))
    else:
        for name in names:
            print(name)
    return None


def _topic_echo(rt, args):
    topic = _topic_arg(args.topic_name)
    field = [part for part in (args.field or "").split(".") if part]
    if args.field is not None and not field:
        raise CourseError(f"invalid field {args.field!r}: name a field such as 'data' or 'linear.x'")
    type_name = args.message_type or _discover_type(rt, topic, "echo")
    msg_class = _message_class(type_name)
    _check_same_type("topic", topic, msg_class, _topic_types(rt, topic))
    qos = _choose_subscription_qos(rt, topic, args)
    limit = 1 if args.once else args.count
    duration = args.duration or ECHO_DEFAULT_S
    truncate = None if args.full_length else args.truncate_length

    inbox: collections.deque = collections.deque()
    received = 0
    with _temporary_node(rt, "echo") as node:
        node.create_subscription(msg_class, topic, lambda msg: inbox.append(("msg", msg)), qos,
                                 event_callbacks=_watch_events(inbox))
        deadline = time.monotonic() + duration
        while limit is None or received < limit:
            while inbox and (limit is None or received < limit):
                kind, item = inbox.popleft()
                if kind == "warning":
                    _print_warning(node, topic, item)
                    continue
                failure = _print_echoed(item, field, args, truncate)
                if failure:
                    return failure
                received += 1
            if time.monotonic() >= deadline or (limit is not None and received >= limit):
                break
            time.sleep(_TICK_S)
    if received == 0:
        print(f"(no message received on {topic} within {duration:g} s)")
    elif args.duration is None and (limit is None or received < limit):
        print(f"(echo stopped after {duration:g} s; use --count N or --duration S to change this)")
    return None


def _print_echoed(msg, field, args, truncate) -> str | None:
    value = msg
    for part in field:
        if not hasattr(value, "get_fields_and_field_types") or part not in value.get_fields_and_field_types():
            return f"Invalid field '{'.'.join(field)}': {interface_name(type(msg))} has no field '{part}'"
        value = getattr(value, part)
    if not hasattr(value, "get_fields_and_field_types"):
        plain = plain_value(value, "", truncate, args.no_arr, args.no_str)
        print(plain, end="\n---\n")
    elif args.csv:
        print(message_to_csv(value, truncate, args.no_arr, args.no_str))
    else:
        print(message_to_yaml(value, truncate, args.no_arr, args.no_str, args.flow_style), end="---\n")
    return None


class _RateMeter:
    """ros2cli's ``topic hz`` statistics over arrival times taken in the executor thread."""

    def __init__(self, window: int):
        self.window = window
        self.lock = threading.Lock()
        self.times: list[int] = []  # intervals between messages, ns
        self.last_ns = -1
        self.last_printed_ns = 0
        self.received = 0

    def on_message(self, _raw) -> None:
        now = time.monotonic_ns()
        with self.lock:
            self.received += 1
            if self.last_ns >= 0:
                self.times.append(now - self.last_ns)
                if len(self.times) > self.window:
                    self.times.pop(0)
            self.last_ns = now

    def report(self) -> str | None:
        """A report once per second of message time, as ros2cli prints it (None: nothing new)."""
        with self.lock:
            if not self.times:
                return None
            if self.last_printed_ns == 0:
                self.last_printed_ns = self.last_ns
                return None
            if self.last_ns < self.last_printed_ns + 1_000_000_000:
                return None
            n = len(self.times)
            mean = sum(self.times) / n
            rate = 1e9 / mean if mean > 0 else 0.0
            std_dev = math.sqrt(sum((x - mean) ** 2 for x in self.times) / n)
            self.last_printed_ns = self.last_ns
            low, high = min(self.times), max(self.times)
        return (f"average rate: {rate:.3f}\n\tmin: {low * 1e-9:.3f}s max: {high * 1e-9:.3f}s "
                f"std dev: {std_dev * 1e-9:.5f}s window: {n}")


def _topic_hz(rt, args):
    topic = _topic_arg(args.topic_name)
    msg_class = _message_class(_discover_type(rt, topic, "hz"))
    qos = _choose_subscription_qos(rt, topic, args)
    meter = _RateMeter(args.window)
    duration = args.duration or HZ_DEFAULT_S
    warnings: collections.deque = collections.deque()
    with _temporary_node(rt, "hz") as node:
        node.create_subscription(msg_class, topic, meter.on_message, qos, raw=True,
                                 event_callbacks=_watch_events(warnings))
        _measure(duration, meter.report, lambda: _print_warnings(node, topic, warnings))
    if meter.received == 0:
        print(f"(no message received on {topic} within {duration:g} s)")
    return None


class _BandwidthMeter:
    """ros2cli's ``topic bw`` statistics: serialized sizes over a window of messages."""

    def __init__(self, window: int):
        self.window = window
        self.lock = threading.Lock()
        self.samples: collections.deque = collections.deque(maxlen=window)  # (time s, bytes)
        self.received = 0
        self.next_report = time.monotonic() + 1.0

    def on_message(self, raw: bytes) -> None:
        with self.lock:
            self.received += 1
            self.samples.append((time.monotonic(), len(raw)))

    def report(self) -> str | None:
        now = time.monotonic()
        if now < self.next_report:
            return None
        self.next_report += 1.0
        with self.lock:
            if len(self.samples) < 2 or now <= self.samples[0][0]:
                return None
            sizes = [size for _, size in self.samples]
            rate = sum(sizes) / (now - self.samples[0][0])
        unit, scale, digits = ("B", 1, 0) if rate < 1000 else ("KB", 1e3, 2) if rate < 1e6 else ("MB", 1e6, 2)

        def fmt(value):
            return f"{value / scale:.{digits}f} {unit}"

        return (f"{fmt(rate)}/s from {len(sizes)} messages\n\tMessage size mean: "
                f"{fmt(sum(sizes) / len(sizes))} min: {fmt(min(sizes))} max: {fmt(max(sizes))}")


def _topic_bw(rt, args):
    topic = _topic_arg(args.topic_name)
    msg_class = _message_class(_discover_type(rt, topic, "bw"))
    qos = _choose_subscription_qos(rt, topic, args)
    meter = _BandwidthMeter(args.window)
    duration = args.duration or HZ_DEFAULT_S
    warnings: collections.deque = collections.deque()
    with _temporary_node(rt, "bw") as node:
        node.create_subscription(msg_class, topic, meter.on_message, qos, raw=True,
                                 event_callbacks=_watch_events(warnings))
        print(f"Subscribed to [{topic}]")
        meter.next_report = time.monotonic() + 1.0
        _measure(duration, meter.report, lambda: _print_warnings(node, topic, warnings))
    if meter.received == 0:
        print(f"(no message received on {topic} within {duration:g} s)")
    return None


def _print_warnings(node: Node, topic: str, warnings: collections.deque) -> None:
    while warnings:
        _print_warning(node, topic, warnings.popleft()[1])


def _measure(duration: float, report: Callable[[], str | None], news: Callable[[], None]) -> None:
    deadline = time.monotonic() + duration
    while time.monotonic() < deadline:
        news()
        text = report()
        if text:
            print(text)
        time.sleep(_TICK_S)


def _topic_pub(rt, args):
    topic = _topic_arg(args.topic_name)
    msg_class = _message_class(args.message_type)
    _check_same_type("topic", topic, msg_class, _topic_types(rt, topic))
    values = values_from_yaml(args.values)
    qos, _explicit = _profile_from_arguments(args)
    times = 1 if args.once else args.times
    duration = args.duration or (None if times else PUB_DEFAULT_S)
    wait_for = args.wait_matching_subscriptions
    if wait_for is None:
        wait_for = 1 if times else 0

    def build():  # rebuilt for every message, so 'now' time stamps advance like ros2cli's
        return set_message_fields(msg_class(), values, now=lambda: rt.graph.get_clock().now().to_msg())

    build()  # bad values fail here, before anything is created
    with _temporary_node(rt, "pub") as node:
        publisher = node.create_publisher(msg_class, topic, qos)
        if wait_for:
            print(f"Waiting for at least {wait_for} matching subscription(s)...")
            try:
                rt.wait_until(lambda: publisher.get_subscription_count() >= wait_for,
                              args.max_wait_time_secs, "matching subscriptions")
            except WaitTimeout:
                print(f"(only {publisher.get_subscription_count()} matching subscription(s) after "
                      f"{args.max_wait_time_secs:g} s; publishing anyway)")
        print("publisher: beginning loop")
        period = 1.0 / args.rate
        start = time.monotonic()
        count = 0
        while True:
            msg = build()
            publisher.publish(msg)
            count += 1
            if args.print_nth and count % args.print_nth == 0:
                print(f"publishing #{count}: {msg!r}\n")
            if times is not None and count >= times:
                break
            next_at = start + count * period
            if duration is not None and next_at - start >= duration:
                break
            time.sleep(max(0.0, next_at - time.monotonic()))
        time.sleep(args.keep_alive)  # let the last message reach the wire before destroying the publisher
    if args.duration is None and times is None:
        print(f"(pub stopped after {duration:g} s; use --once, --times N or --duration S to change this)")
    return None


# ====================================================================== service verbs
def _service_list(rt, args):
    pairs = sorted((n, t) for n, t in rt.graph.get_service_names_and_types()
                   if args.include_hidden_services or not _is_hidden(n))
    if args.count_services:
        print(len(pairs))
        return None
    for name, types in pairs:
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return None


def _service_type(rt, args):
    service = _topic_arg(args.service_name)
    types = _service_types(rt, service)
    if not types:
        return f"Unknown service '{args.service_name}'"
    for each in types:
        print(each)
    return None


def _service_find(rt, args):
    wanted = interface_name(_service_class(args.service_type))
    for name in sorted(n for n, types in rt.graph.get_service_names_and_types()
                       if wanted in types and not _is_hidden(n)):
        print(name)
    return None


def _service_class(type_name: str):
    cls = resolve_interface(type_name, "srv")
    if not hasattr(cls, "Request") or hasattr(cls, "Goal"):
        raise CourseError(f"{type_name!r} is not a service type; services use types such as "
                          "std_srvs/srv/SetBool or std_srvs/srv/Trigger")
    return cls


def _service_call(rt, args):
    service = _topic_arg(args.service_name)
    srv_class = _service_class(args.service_type)
    _check_same_type("service", service, srv_class, _service_types(rt, service))
    request = set_message_fields(srv_class.Request(), values_from_yaml(args.values, "request"),
                                 now=lambda: rt.graph.get_clock().now().to_msg())
    client = rt.graph.create_client(srv_class, service)
    try:
        if not client.service_is_ready():
            print("waiting for service to become available...")
            try:
                rt.wait_until(client.service_is_ready, args.timeout, f"service {service}")
            except WaitTimeout:
                return (f"Service {service} ({interface_name(srv_class)}) did not become available within "
                        f"{args.timeout:g} s; check %ros2 service list -t")
        print(f"requester: making request: {request!r}\n")
        response = rt.wait_for_future(client.call_async(request), args.timeout, f"the response of {service}")
        print(f"response:\n{response!r}\n")
    finally:
        rt.call_in_executor(rt.graph.destroy_client, client)
    return None


# ====================================================================== action verbs
def _action_list(rt, args):
    from rclpy.action import get_action_names_and_types

    pairs = sorted(get_action_names_and_types(rt.graph))
    if args.count_actions:
        print(len(pairs))
        return None
    for name, types in pairs:
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
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
    types = _action_types(rt, _topic_arg(args.action_name))
    if not types:
        return f"Unknown action '{args.action_name}'"
    for each in types:
        print(each)
    return None


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
        while not result_future.done():
            while feedback:
                print(f"Feedback:\n    {message_to_yaml(feedback.popleft())}")
            if time.monotonic() > deadline:
                return f"No result within {args.timeout:g} s (see --timeout)"
            time.sleep(_TICK_S)
        while feedback:
            print(f"Feedback:\n    {message_to_yaml(feedback.popleft())}")
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


# ====================================================================== param verbs
_PARAM_TYPES = {0: "not set", 1: "boolean", 2: "integer", 3: "double", 4: "string", 5: "byte array",
                6: "boolean array", 7: "integer array", 8: "double array", 9: "string array"}
_PARAM_LABELS = {1: "Boolean value is:", 2: "Integer value is:", 3: "Double value is:",
                 4: "String value is:", 5: "Byte values are:", 6: "Boolean values are:",
                 7: "Integer values are:", 8: "Double values are:", 9: "String values are:"}


def _call_service(rt, srv_class, service: str, request, timeout: float = SERVICE_WAIT_S):
    """Call a service from the runtime's hidden node and return the response (WaitTimeout if none)."""
    client = rt.graph.create_client(srv_class, service)
    try:
        rt.wait_until(client.service_is_ready, timeout, f"service {service}")
        return rt.wait_for_future(client.call_async(request), timeout, f"the response of {service}")
    finally:
        rt.call_in_executor(rt.graph.destroy_client, client)


def _parameter_nodes(rt, node_name: str | None, include_hidden: bool) -> list[str] | str:
    if node_name:
        fqn = _require_node(rt, node_name, include_hidden)
        return [fqn] if fqn else "Node not found"
    services = {name for name, _ in rt.graph.get_service_names_and_types()}
    return sorted({fqn for fqn in _graph_node_names(rt, include_hidden)
                   if f"{fqn.rstrip('/')}/list_parameters" in services})


def _list_parameter_names(rt, fqn: str, prefixes=()) -> list[str]:
    from rcl_interfaces.srv import ListParameters

    request = ListParameters.Request(prefixes=list(prefixes))
    return sorted(_call_service(rt, ListParameters, f"{fqn}/list_parameters", request).result.names)


def _get_parameter_values(rt, fqn: str, names: list[str]) -> list:
    from rcl_interfaces.srv import GetParameters

    return list(_call_service(rt, GetParameters, f"{fqn}/get_parameters",
                              GetParameters.Request(names=names)).values)


def _describe_parameters(rt, fqn: str, names: list[str]) -> list:
    from rcl_interfaces.srv import DescribeParameters

    return list(_call_service(rt, DescribeParameters, f"{fqn}/describe_parameters",
                              DescribeParameters.Request(names=names)).descriptors)


def _param_list(rt, args):
    nodes = _parameter_nodes(rt, args.node_name, args.include_hidden_nodes)
    if isinstance(nodes, str):
        return nodes
    for fqn in nodes:
        try:
            names = _list_parameter_names(rt, fqn, args.param_prefixes)
        except WaitTimeout as exc:
            print(f"Exception while calling service of node '{fqn}': {exc}")
            continue
        if not args.node_name:
            print(f"{fqn}:")
        types = {}
        if args.param_type and names:
            types = {d.name: _PARAM_TYPES.get(d.type, "unknown")
                     for d in _describe_parameters(rt, fqn, names)}
        for name in names:
            print(f"  {name} (type: {types.get(name, 'unknown')})" if args.param_type else f"  {name}")
    return None


def _python_value(parameter_value):
    from rclpy.parameter import parameter_value_to_python

    value = parameter_value_to_python(parameter_value)
    if isinstance(value, list):
        value = [v[0] if isinstance(v, bytes) and len(v) == 1 else v for v in value]
    return value


def _param_get(rt, args):
    fqn = _require_node(rt, args.node_name, args.include_hidden_nodes)
    if fqn is None:
        return "Node not found"
    values = _get_parameter_values(rt, fqn, [args.parameter_name])
    if not values:
        return "Parameter not set"
    value = values[0]
    if value.type == 0:
        print("Parameter not set.")
        return None
    python = _python_value(value)
    if args.hide_type:
        print(python)
    else:
        print(_PARAM_LABELS.get(value.type, "Value is:"), python)
    return None


def _param_set(rt, args):
    from rcl_interfaces.msg import Parameter
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import get_parameter_value

    fqn = _require_node(rt, args.node_name, args.include_hidden_nodes)
    if fqn is None:
        return "Node not found"
    parameter = Parameter(name=args.parameter_name, value=get_parameter_value(args.value))
    response = _call_service(rt, SetParameters, f"{fqn}/set_parameters",
                             SetParameters.Request(parameters=[parameter]))
    result = response.results[0]
    if result.successful:
        print("Set parameter successful" + (f": {result.reason}" if result.reason else ""))
    else:
        print("Setting parameter failed" + (f": {result.reason}" if result.reason else ""))
    return None


def _param_dump(rt, args):
    fqn = _require_node(rt, args.node_name, args.include_hidden_nodes)
    if fqn is None:
        return "Node not found"
    names = _list_parameter_names(rt, fqn)
    values = _get_parameter_values(rt, fqn, names) if names else []
    tree: dict = {}
    for name, value in zip(names, values, strict=False):
        branch = tree
        *parents, leaf = name.split(".")
        for part in parents:
            branch = branch.setdefault(part, {})
        branch[leaf] = _python_value(value)
    print(yaml.safe_dump({fqn: {"ros__parameters": tree}}, default_flow_style=False))
    return None


def _param_describe(rt, args):
    fqn = _require_node(rt, args.node_name, args.include_hidden_nodes)
    if fqn is None:
        return "Node not found"
    descriptors = _describe_parameters(rt, fqn, list(args.parameter_names))
    if not descriptors:
        return "Parameter not found"
    for d in descriptors:
        print(f"Parameter name: {d.name}")
        print(f"  Type: {_PARAM_TYPES.get(d.type, 'unknown')}")
        if d.description:
            print(f"  Description: {d.description}")
        if d.additional_constraints or d.read_only or d.dynamic_typing or d.integer_range or \
                d.floating_point_range:
            print("  Constraints:")
            if d.read_only:
                print("    Read only: true")
            if d.dynamic_typing:
                print("    Dynamic typing: true")
            for each in list(d.integer_range) + list(d.floating_point_range):
                print(f"    Min value: {each.from_value}")
                print(f"    Max value: {each.to_value}")
                if each.step:
                    print(f"    Step: {each.step}")
            if d.additional_constraints:
                print(f"    Additional constraints: {d.additional_constraints}")
    return None


# ====================================================================== interface verbs
_KINDS = ("msg", "srv", "action")
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
               "uint32", "int64", "uint64", "string", "wstring", "time", "duration"}


def _ament_prefixes() -> list[str]:
    """Install prefixes holding an ament index: AMENT_PREFIX_PATH, and always this venv."""
    try:
        from ament_index_python.search_paths import get_search_paths

        prefixes = list(get_search_paths())
    except (ImportError, OSError):  # AMENT_PREFIX_PATH unset: the venv is the only prefix
        prefixes = []
    if sys.prefix not in prefixes:
        prefixes.append(sys.prefix)
    return prefixes


def _interfaces_by_package() -> dict[str, list[str]]:
    """{package: ['pkg/msg/Name', ...]} from the ament index's rosidl_interfaces resources."""
    found: dict[str, set] = {}
    for prefix in _ament_prefixes():
        index = os.path.join(prefix, "share", "ament_index", "resource_index", "rosidl_interfaces")
        if not os.path.isdir(index):
            continue
        for package in os.listdir(index):
            with open(os.path.join(index, package)) as handle:
                for line in handle.read().split("\n"):
                    kind, _, file_name = line.strip().partition("/")
                    stem, dot, _ext = file_name.rpartition(".")
                    if kind in _KINDS and dot:
                        found.setdefault(package, set()).add(f"{package}/{kind}/{stem}")
    return {package: sorted(names) for package, names in sorted(found.items())}


def _definition_path(package: str, kind: str, name: str) -> str | None:
    for prefix in _ament_prefixes():
        path = os.path.join(prefix, "share", package, kind, f"{name}.{kind}")
        if os.path.isfile(path):
            return path
    return None


def _full_interface_name(type_name: str) -> tuple[str, str, str]:
    parts = type_name.strip().split("/")
    if len(parts) == 3 and parts[1] in _KINDS:
        return parts[0], parts[1], parts[2]
    if len(parts) == 2:
        for kind in _KINDS:
            if _definition_path(parts[0], kind, parts[1]):
                return parts[0], kind, parts[1]
        cls = resolve_interface(type_name)
        return tuple(interface_name(cls).split("/"))  # type: ignore[return-value]
    raise CourseError(f"Invalid name '{type_name}'. Expected three parts separated by '/', "
                      "e.g. std_msgs/msg/String, std_srvs/srv/SetBool, course_interfaces/action/Fibonacci")


def _nested_type(package: str, line: str) -> str | None:
    """'pkg/msg/Name' if this definition line declares a field of a message type, else None."""
    code = line.split("#", 1)[0].strip()
    tokens = code.split()
    if len(tokens) < 2 or code.startswith("---") or "=" in tokens[1]:
        return None
    base = tokens[0].split("[", 1)[0].split("<", 1)[0]
    if base in _PRIMITIVES:
        return None
    if "/" in base:
        pkg, _, name = base.partition("/")
        return f"{pkg}/msg/{name}"
    if base == "Header":
        return "std_msgs/msg/Header"
    return f"{package}/msg/{base}"


def _definition_lines(package: str, kind: str, name: str, comments: bool, nested_comments: bool,
                      depth: int = 0) -> list[str]:
    path = _definition_path(package, kind, name)
    if path is None:
        if depth:
            return []
        return _lines_from_class(f"{package}/{kind}/{name}")
    out = []
    with open(path) as handle:
        text = handle.read()
    for raw in text.split("\n")[:-1] if text.endswith("\n") else text.split("\n"):
        line = raw.rstrip()
        stripped = line.strip()
        if not comments:
            if not stripped or stripped.startswith("#"):
                continue
            line = line.split("#", 1)[0].rstrip() if not stripped.startswith("---") else line
        out.append("\t" * depth + line if line else "")
        nested = _nested_type(package, raw)
        if nested:
            n_pkg, n_kind, n_name = nested.split("/")
            out.extend(_definition_lines(n_pkg, n_kind, n_name, nested_comments, nested_comments, depth + 1))
    return out


_IDL_TO_MSG = {"boolean": "bool", "octet": "byte", "float": "float32", "double": "float64"}


def _lines_from_class(full_name: str) -> list[str]:
    """Fallback when no definition file is installed: list the fields of the generated class."""
    cls = resolve_interface(full_name)
    parts = [cls.Goal, cls.Result, cls.Feedback] if hasattr(cls, "Goal") else (
        [cls.Request, cls.Response] if hasattr(cls, "Request") else [cls])
    lines: list[str] = []
    for index, part in enumerate(parts):
        if index:
            lines.append("---")
        for field, type_name in part.get_fields_and_field_types().items():
            if type_name.startswith("sequence<"):
                type_name = _IDL_TO_MSG.get(element_type(type_name), element_type(type_name)) + "[]"
            base, bracket, rest = type_name.partition("[")
            lines.append(f"{_IDL_TO_MSG.get(base, base)}{bracket}{rest} {field}")
    return lines


def _interface_show(rt, args):
    package, kind, name = _full_interface_name(args.type)
    if _definition_path(package, kind, name) is None:
        resolve_interface(f"{package}/{kind}/{name}")  # CourseError naming the installed examples
    comments = args.all_comments or not args.no_comments
    for line in _definition_lines(package, kind, name, comments, args.all_comments):
        print(line)
    return None


def _interface_list(rt, args):
    flags = (args.only_msgs, args.only_srvs, args.only_actions)
    wanted = [k for k, flag in zip(_KINDS, flags, strict=True) if flag]
    wanted = wanted or list(_KINDS)
    everything = [n for names in _interfaces_by_package().values() for n in names]
    for kind, title in zip(_KINDS, ("Messages:", "Services:", "Actions:"), strict=True):
        if kind in wanted:
            print(title)
            for full in sorted(n for n in everything if n.split("/")[1] == kind):
                print(f"    {full}")
    return None


def _interface_packages(rt, args):
    for package in _interfaces_by_package():
        print(package)
    return None


def _interface_package(rt, args):
    names = _interfaces_by_package().get(args.package_name)
    if not names:
        return f"Unknown package '{args.package_name}'"
    for full in names:
        print(full)
    return None
