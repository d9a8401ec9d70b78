"""What ``rt.status()`` reports, and the table ``rt.show_status()`` prints (chapter 00 and any cell)."""

from __future__ import annotations

import os

import rclpy

from course_helpers.core.other_kernels import other_kernels
from course_helpers.core.versions import rclpy_version


def status_of(runtime) -> dict:
    """Versions, middleware, domain, discovery range, executor, nodes, child processes, callback
    errors, and the other notebooks of this Jupyter server that run ROS (:mod:`.other_kernels`)."""
    return {
        "rclpy": rclpy_version(),
        "rmw": rclpy.get_rmw_implementation_identifier(),
        "domain_id": runtime.domain.domain_id,
        "domain_chosen_by": runtime.domain.source,
        "discovery_range": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET"),
        "executor": ("SingleThreadedExecutor" if runtime.executor_kind == "single"
                     else "MultiThreadedExecutor"),
        "nodes": runtime.nodes(),
        "children": {n: (c.pid, "running" if c.alive else f"exited {c.returncode}")
                     for n, c in runtime.children().items()},
        "callback_errors": len(runtime.errors),
        "other_kernels": [kernel.describe() for kernel in other_kernels()],
    }


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
