"""Pieces shared by the ``%ros2`` verbs: the argparse classes that print into the cell,
argument types, graph-name helpers and the polling tick (all chapters that use ``%ros2``).
"""

from __future__ import annotations

import argparse
import math

from course_helpers.core.errors import CourseError
from course_helpers.core.names import full_name, is_hidden
from course_helpers.core.validation import check_topic_name, interface_name

SERVICE_WAIT_S = 5.0  # how long to wait for a service or action server to appear
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


def _verbs(parser):
    verbs = parser.add_subparsers(dest="verb", title="verbs", parser_class=_Parser)
    verbs.required = True
    parser.lists_verbs = True
    return verbs


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not value > 0 or math.isinf(value):
        raise argparse.ArgumentTypeError(f"expected a number of seconds/Hz > 0, got {text!r}")
    return value


def _is_hidden(name: str) -> bool:
    """ROS hides names with a token starting with '_' (e.g. /fibonacci/_action/status)."""
    return is_hidden(name)


def _absolute(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def _topic_arg(name: str) -> str:
    if name.startswith("~"):
        raise CourseError(f"{name!r}: private names ('~/...') only make sense inside a node; "
                          "give the full name, e.g. '/talker/status'")
    return check_topic_name(_absolute(name))


def _graph_node_names(rt, include_hidden: bool) -> list[str]:
    """Full names of the nodes in the graph, sorted, duplicates kept (like ros2cli)."""
    return sorted(full_name(namespace, name) for name, namespace in rt.graph.get_node_names_and_namespaces()
                  if include_hidden or not name.startswith("_"))


def _check_same_type(kind: str, name: str, cls, types_in_graph: list[str]) -> None:
    """Refuse a type other than the one the graph uses for ``name``.

    Endpoints of different types never connect, and Fast DDS refuses a second
    type for a topic within one process (the kernel), so say so up front.
    """
    wanted = interface_name(cls)
    if types_in_graph and wanted not in types_in_graph:
        raise CourseError(f"{kind} {name} has type {', '.join(types_in_graph)}, not {wanted}; endpoints of "
                          f"different types never connect. Use the type shown by %ros2 {kind} type {name}.")
