"""ROS names: joining a namespace and a name into a full name, and reading one back."""

from __future__ import annotations

from course_helpers.core.errors import CourseError


def full_name(namespace: str, name: str) -> str:
    """``('/robot1', 'camera')`` -> ``'/robot1/camera'``; ``('/', 'talker')`` -> ``'/talker'``."""
    return (namespace or "").rstrip("/") + "/" + name


def as_full_name(name) -> str:
    """A node name as typed by a student ('talker' or '/talker') -> its full name ('/talker')."""
    if not isinstance(name, str) or not name:
        raise CourseError(f"node name must be a string like '/talker', got {name!r}")
    return name if name.startswith("/") else "/" + name


def split_full_name(fqn: str) -> tuple[str, str]:
    """``'/robot1/camera'`` -> ``('/robot1', 'camera')``; ``'/talker'`` -> ``('/', 'talker')``."""
    fqn = as_full_name(fqn)
    namespace, _, name = fqn.rpartition("/")
    return namespace or "/", name


def is_hidden(fqn: str) -> bool:
    """True if any token of a name starts with '_' (ros2cli hides such nodes and topics)."""
    return any(token.startswith("_") for token in fqn.split("/") if token)


def node_full_names(pairs, include_hidden: bool = False) -> list[str]:
    """Sorted full names from rclpy's ``get_node_names_and_namespaces()`` pairs."""
    names = {full_name(namespace, name) for name, namespace in pairs}
    return sorted(n for n in names if include_hidden or not is_hidden(n))
