"""``%ros2 topic list|info|type|find|echo|hz|bw|pub`` with ros2cli's ``--qos-*`` flags
(chapter 03 for the tools, 08 for the QoS flags and incompatible-QoS warnings).
"""

from __future__ import annotations

import collections
import math
import time

from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSPresetProfiles,
    QoSReliabilityPolicy,
)

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.msg_yaml import (
    message_to_csv,
    message_to_yaml,
    plain_value,
    set_message_fields,
    values_from_yaml,
)
from course_helpers.core.validation import interface_name
from course_helpers.core.waiting import poll_until
from course_helpers.notebook.ros2cli._common import (
    _TICK_S,
    OneOf,
    Verb,
    _check_same_type,
    _is_hidden,
    _non_negative_float,
    _non_negative_int,
    _positive_float,
    _positive_int,
    _topic_arg,
    add_verb_table,
    count_of,
    name_of,
    option,
    print_names,
    print_types,
    show_types,
)
from course_helpers.notebook.ros2cli.topic_graph import (
    choose_subscription_qos,
    discover_type,
    message_class,
    print_warning,
    profile_from_arguments,
    temporary_node,
    topic_types,
    watch_events,
)
from course_helpers.notebook.ros2cli.topic_rates import HZ_DEFAULT_S, topic_bw, topic_hz

ECHO_DEFAULT_S = 10.0  # topic echo stops after this long unless --count/--once/--duration says otherwise
PUB_DEFAULT_S = 10.0  # topic pub without --once/--times publishes this long
MATCH_WAIT_S = 5.0  # how long topic pub waits for matching subscriptions
TRUNCATE_LENGTH = 128  # ros2cli's default for arrays and strings in echo


def _topic_list(rt, args):
    pairs = sorted((n, t) for n, t in rt.graph.get_topic_names_and_types()
                   if args.include_hidden_topics or not _is_hidden(n))
    if args.verbose and not args.count_topics:
        for title, counter, noun in (("Published topics:", rt.graph.count_publishers, "publisher"),
                                     ("Subscribed topics:", rt.graph.count_subscribers, "subscriber")):
            print(title)
            for name, types in pairs:
                count = counter(name)
                if count:
                    print(f" * {name} [{', '.join(types)}] {count} {noun}{'s' if count > 1 else ''}")
            print()
        return None
    print_names(pairs, args.show_types, args.count_topics)
    return None


def _topic_info(rt, args):
    topic = _topic_arg(args.topic_name)
    types = topic_types(rt, topic)
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
    return print_types("topic", args.topic_name, topic_types(rt, _topic_arg(args.topic_name)))


def _topic_find(rt, args):
    wanted = interface_name(message_class(args.topic_type))
    print_names(sorted((n, types) for n, types in rt.graph.get_topic_names_and_types()
                       if wanted in types and not _is_hidden(n)), count_only=args.count_topics)
    return None


def _topic_echo(rt, args):
    topic = _topic_arg(args.topic_name)
    field = [part for part in (args.field or "").split(".") if part]
    if args.field is not None and not field:
        raise CourseError(f"invalid field {args.field!r}: name a field such as 'data' or 'linear.x'")
    type_name = args.message_type or discover_type(rt, topic, "echo")
    msg_class = message_class(type_name)
    _check_same_type("topic", topic, msg_class, topic_types(rt, topic))
    qos = choose_subscription_qos(rt, topic, args)
    limit = 1 if args.once else args.count
    duration = args.duration or ECHO_DEFAULT_S
    truncate = None if args.full_length else args.truncate_length

    inbox: collections.deque = collections.deque()
    received = 0
    with temporary_node(rt, "echo") as node:
        node.create_subscription(msg_class, topic, lambda msg: inbox.append(("msg", msg)), qos,
                                 event_callbacks=watch_events(inbox))
        failure = None

        def print_arrivals() -> bool:  # True once the command is done
            nonlocal received, failure
            while inbox and (limit is None or received < limit):
                kind, item = inbox.popleft()
                if kind == "warning":
                    print_warning(node, topic, item)
                    continue
                failure = _print_echoed(item, field, args, truncate)
                if failure:
                    return True
                received += 1
            return limit is not None and received >= limit

        poll_until(print_arrivals, duration, period=_TICK_S)
        if failure:
            return failure
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


def _topic_pub(rt, args):
    topic = _topic_arg(args.topic_name)
    msg_class = message_class(args.message_type)
    _check_same_type("topic", topic, msg_class, topic_types(rt, topic))
    values = values_from_yaml(args.values)
    qos, _explicit = profile_from_arguments(args)
    times = 1 if args.once else args.times
    duration = args.duration or (None if times else PUB_DEFAULT_S)
    wait_for = args.wait_matching_subscriptions
    if wait_for is None:
        wait_for = 1 if times else 0

    def build():  # rebuilt for every message, so 'now' time stamps advance like ros2cli's
        return set_message_fields(msg_class(), values, now=lambda: rt.graph.get_clock().now().to_msg())

    build()  # bad values fail here, before anything is created
    with temporary_node(rt, "pub") as node:
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
        period = 1.0 / args.rate  # s
        start = time.monotonic()
        count = 0

        def publish_due() -> bool:  # publish the messages whose time has come; True when finished
            nonlocal count
            while (times is None or count < times) and (duration is None or count * period < duration) \
                    and start + count * period <= time.monotonic():
                msg = build()
                publisher.publish(msg)
                count += 1
                if args.print_nth and count % args.print_nth == 0:
                    print(f"publishing #{count}: {msg!r}\n")
            return ((times is not None and count >= times)
                    or (duration is not None and count * period >= duration))

        limit_s = math.inf if duration is None else duration + period
        poll_until(publish_due, limit_s, period=min(_TICK_S, period))
        time.sleep(args.keep_alive)  # let the last message reach the wire before destroying the publisher
    if args.duration is None and times is None:
        print(f"(pub stopped after {duration:g} s; use --once, --times N or --duration S to change this)")
    return None


def qos_options(entity: str, default_profile: str) -> tuple:
    """ros2cli's ``--qos-*`` options of a verb that makes a subscription or publisher (``entity``:
    'subscribe' or 'publish')."""
    return (
        option("--qos-profile", choices=QoSPresetProfiles.short_keys(), default=default_profile,
               help=f"QoS preset profile to {entity} with (default: {default_profile})"),
        option("--qos-depth", type=_positive_int, metavar="N",
               help="Queue size setting to " + entity + " with (overrides the profile's depth)"),
        *(option(f"--qos-{policy}", choices=choices, help=f"{what} setting to {entity} with")
          for policy, choices, what in (("history", QoSHistoryPolicy.short_keys(), "History of samples"),
                                        ("reliability", QoSReliabilityPolicy.short_keys(), "Reliability"),
                                        ("durability", QoSDurabilityPolicy.short_keys(), "Durability"))))


def rate_options(window: int, window_help: str) -> tuple:
    """What ``hz`` and ``bw`` take: the topic, a window of messages, a duration, the QoS options."""
    return (LISTENED_TOPIC,
            option("-w", "--window", type=_positive_int, default=window, metavar="N", help=window_help),
            option("--duration", type=_positive_float, metavar="S",
                   help=f"Measure for S seconds (default: {HZ_DEFAULT_S:g})"),
            *qos_options("subscribe", "sensor_data"))


TOPIC_NAME = name_of("topic", "topic_name", "/chatter")
LISTENED_TOPIC = name_of("topic", "topic_name", "/chatter", " to listen to")
COUNT_TOPICS = count_of("topics")
VERBS = (
    Verb("list", "Output a list of available topics", _topic_list, (
        show_types("topic"), COUNT_TOPICS,
        option("-v", "--verbose", action="store_true",
               help="List full details about each topic (publishers and subscribers)"),
        option("--include-hidden-topics", action="store_true", help="Consider hidden topics as well"))),
    Verb("info", "Print information about a topic", _topic_info, (
        TOPIC_NAME,
        option("-v", "--verbose", action="store_true",
               help="Print node name, type, GID and QoS profile of each publisher and subscription"))),
    Verb("type", "Print a topic's type", _topic_type, (TOPIC_NAME,)),
    Verb("find", "Output a list of available topics of a given type", _topic_find, (
        option("topic_type", help="Name of the ROS topic type, e.g. std_msgs/msg/String"), COUNT_TOPICS)),
    Verb("echo", "Output messages from a topic", _topic_echo, (
        LISTENED_TOPIC,
        option("message_type", nargs="?",
               help="Type of the message, e.g. std_msgs/msg/String (default: found in the graph)"),
        option("--once", action="store_true", help="Print the first message received and stop"),
        option("--count", type=_positive_int, metavar="N", help="Stop after N messages"),
        option("--duration", "--timeout", dest="duration", type=_positive_float, metavar="S",
               help=f"Stop after S seconds (default: {ECHO_DEFAULT_S:g} s unless --count/--once)"),
        option("--field", help="Echo a selected field of the message, e.g. 'linear.x'"),
        option("--csv", action="store_true", help="Output all fields separated by commas"),
        option("-f", "--full-length", action="store_true",
               help="Output all elements of arrays and strings (no truncation)"),
        option("-l", "--truncate-length", type=_non_negative_int, default=TRUNCATE_LENGTH, metavar="N",
               help=f"Truncate arrays and strings to N elements (default: {TRUNCATE_LENGTH})"),
        option("--no-arr", action="store_true", help="Don't print array fields of messages"),
        option("--no-str", action="store_true", help="Don't print string fields of messages"),
        option("--flow-style", action="store_true", help="Print messages in YAML flow style (one line)"),
        *qos_options("subscribe", "sensor_data"))),
    Verb("hz", "Print the average receiving rate", topic_hz, rate_options(
        10000, "Window size, in number of messages, for calculating the rate (default: 10000)")),
    Verb("bw", "Display the bandwidth used by a topic", topic_bw, rate_options(
        100, "Maximum window size, in number of messages (default: 100)")),
    Verb("pub", "Publish a message to a topic", _topic_pub, (
        name_of("topic", "topic_name", "/cmd_vel", " to publish to"),
        option("message_type", help="Type of the message, e.g. geometry_msgs/msg/Twist"),
        option("values", nargs="?", default="{}",
               help="Values of the message in YAML, e.g. \"{linear: {x: 0.5}, angular: {z: 0.1}}\""),
        option("-r", "--rate", type=_positive_float, default=1.0, metavar="N",
               help="Publishing rate in Hz (default: 1)"),
        option("-p", "--print", dest="print_nth", type=_non_negative_int, default=1, metavar="N",
               help="Print every N-th published message (0: print none; default: 1)"),
        OneOf((option("-1", "--once", action="store_true", help="Publish one message and stop"),
               option("-t", "--times", type=_positive_int, metavar="N", help="Publish N messages and stop"),
               option("--duration", type=_positive_float, metavar="S",
                      help=f"Publish for S seconds (default without --once/--times: {PUB_DEFAULT_S:g})"))),
        option("-w", "--wait-matching-subscriptions", type=_non_negative_int, metavar="N",
               help="Wait for N matching subscriptions first (default: 1 with --once/--times, else 0)"),
        option("--max-wait-time-secs", type=_positive_float, default=MATCH_WAIT_S, metavar="S",
               help=f"Longest wait for matching subscriptions (default: {MATCH_WAIT_S:g})"),
        option("--keep-alive", type=_non_negative_float, default=0.1, metavar="S",
               help="Keep the publisher alive S seconds after the last message (default: 0.1)"),
        *qos_options("publish", "default"))),
)


def add_verbs(parser):
    add_verb_table(parser, VERBS)
