"""What ``rt.status()`` reports, and the table ``rt.show_status()`` prints (chapter 00 and any cell)."""

from __future__ import annotations

import os

import rclpy

from course_helpers.core.other_kernels import other_kernels
from course_helpers.core.versions import rclpy_version


def status_of(runtime) -> dict:
    """Versions, middleware, domain, discovery range, executor, nodes, child processes, callback
    errors, and the other notebooks of this Jupyter server that run ROS (:mod:`.other_kernels`).
    Nodes of this process in another context (a textbook ``rclpy.init()`` and ``Node('x')``) are
    listed under ``not_the_courses``, when there are any."""
    others = nodes_outside(runtime)
    return {
        "rclpy": rclpy_version(),
        "rmw": rclpy.get_rmw_implementation_identifier(),
        "domain_id": runtime.domain.domain_id,
        "domain_chosen_by": runtime.domain.source,
        "discovery_range": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET"),
        "executor": ("SingleThreadedExecutor" if runtime.executor_kind == "single"
                     else "MultiThreadedExecutor"),
        "nodes": runtime.nodes(),
        **({"not_the_courses": others} if others else {}),
        "children": {n: (c.pid, "running" if c.alive else f"exited {c.returncode}")
                     for n, c in runtime.children().items()},
        "callback_errors": len(runtime.errors),
        "other_kernels": [kernel.describe() for kernel in other_kernels()],
    }


def nodes_outside(runtime) -> list[str]:
    """Nodes alive in this process whose context is not the runtime's, each marked with its context:
    '/x (rclpy's default context, not the course's: node.destroy_node() ends it)'."""
    import gc

    from rclpy.node import Node
    from rclpy.utilities import get_default_context

    default = get_default_context()
    found = set()
    for obj in gc.get_objects():
        if not isinstance(obj, Node) or obj.context is runtime.context:
            continue
        try:
            name = obj.get_fully_qualified_name()  # raises once the node is destroyed
        except Exception:
            continue
        where = "rclpy's default context" if obj.context is default else "a context of its own"
        found.add(f"{name} ({where}, not the course's: node.destroy_node() ends it)")
    return sorted(found)


def status_table(status: dict) -> str:
    """``status`` as aligned lines, one per key; empty lists and dicts as '(none)'."""
    lines = []
    for key, value in status.items():
        if isinstance(value, list):
            value = ", ".join(value) or "(none)"
        elif isinstance(value, dict):
            value = ", ".join(f"{n} (pid {p}, {s})" for n, (p, s) in value.items()) or "(none)"
        lines.append(f"{key:<18} {value}")
    return "\n".join(lines)
