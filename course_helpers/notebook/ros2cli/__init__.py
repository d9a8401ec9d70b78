"""The ``ros2`` command-line tool, re-implemented on the course runtime (the ``%ros2`` magic).

ros2cli cannot be installed from PyPI, so the notebooks get the same verbs here,
with ros2cli's output format, run against the live graph of the kernel's ROS
domain. Chapters 01-10 use them: 01 ``node``, 03 ``topic`` (list/info/echo/hz/pub),
04 ``service``, 05 ``action``, 06 ``param``, 08 the ``--qos-*`` flags of
``topic echo``/``topic pub``; ``interface show`` wherever a type is introduced; 03b, 08b and 10
``bag`` (record/info/play).

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
import shlex

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.msg_yaml import message_to_dict, message_to_yaml, set_message_fields
from course_helpers.notebook.ros2cli import action, bag, interface, node, param, service, topic
from course_helpers.notebook.ros2cli._common import _Parser, _ParserExit, _UsageError

__all__ = ["build_parser", "message_to_dict", "message_to_yaml", "run", "set_message_fields"]


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
        from course_helpers.core.runtime import get_runtime

        rt = get_runtime()
    try:
        rt.settle_graph()  # the first command after a start waits until discovery has found what runs
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


def build_parser() -> argparse.ArgumentParser:
    """The argparse tree of all supported commands (``ros2 <command> <verb> ...``)."""
    parser = _Parser(prog="ros2", description="ros2 commands for the notebook (a subset of ros2cli).")
    commands = parser.add_subparsers(dest="command",
                                     metavar="{node,topic,service,action,param,interface,bag}",
                                     title="commands", parser_class=_Parser)
    commands.required = True
    node.add_verbs(commands.add_parser("node", help="Inspect nodes"))
    topic.add_verbs(commands.add_parser("topic", help="Inspect, echo and publish topics"))
    service.add_verbs(commands.add_parser("service", help="Inspect and call services"))
    action.add_verbs(commands.add_parser("action", help="Inspect actions and send goals"))
    param.add_verbs(commands.add_parser("param", help="List, get, set and dump parameters"))
    interface.add_verbs(commands.add_parser("interface", help="Show message/service/action definitions"))
    bag.add_verbs(commands.add_parser("bag", help="Record, inspect and play rosbag2 bags"))
    return parser
