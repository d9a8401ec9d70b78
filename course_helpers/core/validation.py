"""Checks of names, message types and QoS numbers, with errors students can act on.

Used by the runtime (chapter 00 on), the ``%ros2`` commands (chapters 01-10)
and the QoS helpers (chapter 08).
"""

from __future__ import annotations

import importlib
import re

from rclpy.exceptions import (
    InvalidNamespaceException,
    InvalidNodeNameException,
    InvalidTopicNameException,
)
from rclpy.validate_full_topic_name import validate_full_topic_name
from rclpy.validate_namespace import validate_namespace
from rclpy.validate_node_name import validate_node_name
from rclpy.validate_topic_name import validate_topic_name

from course_helpers.core.errors import CourseError

_TYPE_RE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(?:(msg|srv|action)/)?([A-Z][A-Za-z0-9]*)$")


def check_node_name(name: str) -> str:
    """Return ``name`` if it is a valid ROS node name, else raise :class:`CourseError`."""
    if not isinstance(name, str):
        raise CourseError(f"node name must be a string, got {type(name).__name__}")
    try:
        validate_node_name(name)
    except InvalidNodeNameException as exc:
        raise CourseError(
            f"invalid node name {name!r}: {_reason(exc)}. Node names use letters, digits "
            "and underscores, must not start with a digit, and contain no '/' "
            "(put the '/robot1' part in the namespace)."
        ) from None
    return name


def check_namespace(namespace: str) -> str:
    """Return a namespace normalised to start with '/', or raise :class:`CourseError`."""
    namespace = namespace or "/"
    if not namespace.startswith("/"):
        namespace = "/" + namespace
    try:
        validate_namespace(namespace)
    except InvalidNamespaceException as exc:
        raise CourseError(
            f"invalid namespace {namespace!r}: {_reason(exc)}. A namespace looks like "
            "'/robot1' or '/fleet/robot1': tokens of letters, digits and underscores."
        ) from None
    return namespace


def check_topic_name(name: str) -> str:
    """Return ``name`` if it is a valid topic or service name, else raise :class:`CourseError`."""
    if not isinstance(name, str) or not name:
        raise CourseError(f"topic name must be a non-empty string, got {name!r}")
    try:
        validate_topic_name(name)
        if not name.startswith("~"):  # the full name it becomes must be valid too (no '//')
            validate_full_topic_name(name if name.startswith("/") else "/" + name)
    except InvalidTopicNameException as exc:
        raise CourseError(
            f"invalid topic name {name!r}: {_reason(exc)}. Topic names look like "
            "'chatter', '/robot1/cmd_vel' or '~/status': tokens of letters, digits and "
            "underscores separated by single '/', not starting with a digit."
        ) from None
    return name


def check_depth(depth: int) -> int:
    """Return a history depth, or raise :class:`CourseError` if it is not a positive integer."""
    if isinstance(depth, bool) or not isinstance(depth, int) or depth < 1:
        raise CourseError(
            f"history depth must be a whole number >= 1, got {depth!r}. "
            "(With KEEP_ALL the depth is ignored; pass depth=1 or leave it out.)"
        )
    return depth


def resolve_interface(type_name: str, kind: str | None = None):
    """Import an interface class from a name like ``std_msgs/msg/String`` or ``std_msgs/String``.

    ``kind`` limits the search to 'msg', 'srv' or 'action'. Raises :class:`CourseError`
    naming the allowed forms when the name is malformed or the package is not installed.
    """
    if not isinstance(type_name, str):
        return _check_class(type_name, kind)
    match = _TYPE_RE.match(type_name.strip())
    if not match:
        raise CourseError(
            f"unknown interface type {type_name!r}: write it as 'package/msg/Name' "
            "(for example 'std_msgs/msg/String', 'std_srvs/srv/Trigger', "
            "'course_interfaces/action/Fibonacci')."
        )
    package, given_kind, cls_name = match.groups()
    kinds = [given_kind] if given_kind else ([kind] if kind else ["msg", "srv", "action"])
    for each in kinds:
        try:
            module = importlib.import_module(f"{package}.{each}")
        except ImportError:
            continue
        if hasattr(module, cls_name):
            return getattr(module, cls_name)
    raise CourseError(
        f"unknown interface type {type_name!r}: no {'/'.join(kinds)} called {cls_name!r} in "
        f"package {package!r}. Installed examples: std_msgs/msg/String, geometry_msgs/msg/Twist, "
        "sensor_msgs/msg/Imu, std_srvs/srv/SetBool, course_interfaces/srv/AddTwoInts."
    )


def interface_name(cls) -> str:
    """Return the ROS name of an interface class, e.g. ``std_msgs/msg/String``."""
    module = cls.__module__.split(".")
    return f"{module[0]}/{module[1]}/{cls.__name__}"


def _check_class(cls, kind):
    if not hasattr(cls, "__module__") or not (
        hasattr(cls, "_TYPE_SUPPORT") or hasattr(cls, "Request") or hasattr(cls, "Goal")
    ):
        raise CourseError(
            f"{cls!r} is not a ROS interface class: pass a generated class such as "
            "std_msgs.msg.String, or its name 'std_msgs/msg/String'."
        )
    return cls


def _reason(exc: Exception) -> str:
    text = str(exc).splitlines()[0]
    text = text.split(":", 1)[-1] if ":" in text else text
    return text.strip().rstrip(":")
