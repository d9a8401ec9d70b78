"""Pieces shared by the ``%ros2`` verbs: the argparse classes that print into the cell, the verb
tables, the options several verbs share, argument types, graph-name helpers and the polling tick.

Each command module describes its verbs as a table of :class:`Verb` rows, each with its
:class:`Option` list; an option that several verbs take (``-t/--show-types``, ``-c/--count-*``,
``--include-hidden-nodes``, an entity's name) is declared once here, and :func:`add_verb_table`
turns a table into argparse sub-commands.
"""

from __future__ import annotations

import argparse
import difflib
import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass

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
        raise _UsageError(self, _with_suggestion(message))

    def exit(self, status=0, message=None):
        if message:
            print(message, end="")
        raise _ParserExit(status)

    def _print_message(self, message, file=None):
        if message:
            print(message, end="")


_INVALID_CHOICE = re.compile(r"invalid choice: '(?P<given>[^']*)' \(choose from (?P<choices>.*)\)$")


def _with_suggestion(message: str) -> str:
    """argparse's "invalid choice: 'nodez' (choose from ...)" with "did you mean 'node'?" when one of
    the choices is close (the quotes around the choices differ between Python versions)."""
    found = _INVALID_CHOICE.search(message)
    if found is None:
        return message
    choices = [choice.strip().strip("'") for choice in found["choices"].split(",")]
    close = difflib.get_close_matches(found["given"], choices, n=1, cutoff=0.6)
    return f"{message}; did you mean '{close[0]}'?" if close else message


def _verbs(parser):
    verbs = parser.add_subparsers(dest="verb", title="verbs", parser_class=_Parser)
    verbs.required = True
    parser.lists_verbs = True
    return verbs


@dataclass(frozen=True)
class Option:
    """One argument of a verb: the flags (or the positional name) and what ``add_argument`` gets."""

    flags: tuple[str, ...]
    settings: dict

    def add_to(self, parser) -> None:
        parser.add_argument(*self.flags, **self.settings)


@dataclass(frozen=True)
class OneOf:
    """Options of which a command line may give at most one (argparse's mutually exclusive group)."""

    options: tuple[Option, ...]

    def add_to(self, parser) -> None:
        group = parser.add_mutually_exclusive_group()
        for each in self.options:
            each.add_to(group)


@dataclass(frozen=True)
class Verb:
    """One verb of a command: its name, help, what runs it (``run(rt, args)`` returns a failure
    text or None) and its options."""

    name: str
    help: str
    run: Callable
    options: tuple = ()


def option(*flags: str, **settings) -> Option:
    return Option(flags, settings)


def add_verb_table(parser, table: Iterable[Verb]) -> None:
    """Give ``parser`` one sub-command per row of ``table``."""
    verbs = _verbs(parser)
    for verb in table:
        sub = verbs.add_parser(verb.name, help=verb.help)
        for each in verb.options:
            each.add_to(sub)
        sub.set_defaults(func=verb.run)


# ---------------------------------------------------------------------- options several verbs take
def show_types(kind: str) -> Option:
    """``-t/--show-types`` of a list of ``kind``s (topic, service, action)."""
    return option("-t", "--show-types", action="store_true", help=f"Additionally show the {kind} type")


def count_of(things: str, flag: str | None = None, what: str | None = None) -> Option:
    """``-c/--count-<things>``: print only how many there are."""
    return option("-c", flag or f"--count-{things}", action="store_true",
                  help=f"Only display the number of {what or things}")


def name_of(kind: str, dest: str, example: str, purpose: str = "", **settings) -> Option:
    """The positional name of a ROS entity (``topic_name``, ``service_name`` ...)."""
    return option(dest, help=f"Name of the ROS {kind}{purpose}, e.g. {example}", **settings)


NODE_NAME = name_of("node", "node_name", "/talker")
INCLUDE_HIDDEN_NODES = option("--include-hidden-nodes", action="store_true",
                              help="Consider hidden nodes as well")


def _number(convert: Callable, minimum: float, above: bool, expected: str) -> Callable:
    """An argparse type: ``convert(text)``, finite, above (or at least) ``minimum``."""
    def parse(text):
        try:
            value = convert(text)
        except ValueError:
            value = None
        if value is None or math.isinf(value) or not (value > minimum if above else value >= minimum):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value

    return parse


_positive_float = _number(float, 0.0, True, "a number of seconds/Hz > 0")
_positive_int = _number(int, 1, False, "a whole number >= 1")
_non_negative_int = _number(int, 0, False, "a whole number >= 0")
_non_negative_float = _number(float, 0.0, False, "a number >= 0")


def print_names(pairs, show_types: bool = False, count_only: bool = False) -> None:
    """What a ``list`` verb prints for ``(name, types)`` pairs: each name (with its types), or how many."""
    if count_only:
        print(len(pairs))
        return
    for name, types in pairs:
        print(f"{name} [{', '.join(types)}]" if show_types else name)


def print_types(kind: str, given: str, types: list[str]) -> str | None:
    """What a ``type`` verb prints: each type of the ``kind`` named ``given``, or ros2cli's failure."""
    if not types:
        return f"Unknown {kind} '{given}'"
    for each in types:
        print(each)
    return None


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
