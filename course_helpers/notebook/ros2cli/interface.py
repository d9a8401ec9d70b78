"""``%ros2 interface show|list|packages|package``: definitions read from the installed
``.msg``/``.srv``/``.action`` files (chapters 03-05 and 09).
"""

from __future__ import annotations

import os
import sys

from course_helpers.core.errors import CourseError
from course_helpers.core.msg_yaml import (
    element_type,
)
from course_helpers.core.validation import interface_name, resolve_interface
from course_helpers.notebook.ros2cli._common import OneOf, Verb, add_verb_table, option

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


VERBS = (
    Verb("show", "Output the interface definition", _interface_show, (
        option("type", help="Interface type, e.g. std_msgs/msg/String or std_srvs/srv/SetBool"),
        OneOf((option("--all-comments", action="store_true",
                      help="Show all comments, including for nested interface definitions"),
               option("--no-comments", action="store_true", help="Show no comments or whitespace"))))),
    Verb("list", "List all interface types available", _interface_list, tuple(
        option(short, f"--only-{kinds}", action="store_true", help=f"Print out only the {what}")
        for short, kinds, what in (("-m", "msgs", "messages"), ("-s", "srvs", "services"),
                                   ("-a", "actions", "actions")))),
    Verb("packages", "Output a list of packages that provide interfaces", _interface_packages),
    Verb("package", "Output a list of the interfaces of a package", _interface_package, (
        option("package_name", help="Name of the package, e.g. std_msgs"),)),
)


def add_verbs(parser):
    add_verb_table(parser, VERBS)
