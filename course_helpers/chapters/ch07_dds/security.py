"""What Fast DDS says when a node asks for DDS security (SROS2)."""

from __future__ import annotations

import os

from rclpy.node import Node

from course_helpers.core.channel import report
from course_helpers.core.child_results import run_child_for_result


def secure_node_attempt() -> None:
    """Child-process procedure: create a node under the child's security settings.

    Reports ``result`` with ``created`` (bool) and ``error`` (the middleware's words, or '').
    """
    try:
        node = Node("secure_talker")
    except Exception as exc:  # the middleware refuses: report its words
        report("result", created=False, error=str(exc))
        return
    node.destroy_node()
    report("result", created=True, error="")


def try_secure_node(rt) -> dict:
    """Ask for DDS security (SROS2 environment variables, an empty keystore) in a child process.

    Returns ``{'created': bool, 'error': first line of the middleware's error}``. With the Fast
    DDS built into these wheels the answer is that the security plugins are not compiled in.
    """
    keystore = os.path.join(rt.log_dir, "empty_keystore")
    os.makedirs(os.path.join(keystore, "enclaves"), exist_ok=True)
    env = {"ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce",
           "ROS_SECURITY_KEYSTORE": keystore}
    result = run_child_for_result(rt, "secure_node", secure_node_attempt, env=env)
    result["error"] = result["error"].splitlines()[0] if result["error"] else ""
    return result
