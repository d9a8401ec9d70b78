"""What rcl and Fast DDS do when a node asks for DDS security (SROS 2's environment variables).

:func:`try_security_settings` starts one child process that, for each case, sets the case's
``ROS_SECURITY_*`` variables, initialises a fresh rclpy context and creates a node in it, and
reports whether the node was created or what the middleware said. :func:`empty_keystore` makes
a keystore folder with an empty ``enclaves/`` inside (no certificate, no key).
"""

from __future__ import annotations

import os

from rclpy.context import Context
from rclpy.node import Node

from course_helpers.core.channel import report
from course_helpers.core.child_results import run_child_for_result
from course_helpers.core.errors import CourseError

SECURITY_VARIABLES = ("ROS_SECURITY_ENABLE", "ROS_SECURITY_STRATEGY", "ROS_SECURITY_KEYSTORE",
                      "ROS_SECURITY_ENCLAVE_OVERRIDE")
NODE_NAME = "secure_talker"


def _first_words(error: str, keystore: str) -> str:
    """The first line of an rcl/rmw error, without the source location, the keystore path named."""
    line = error.splitlines()[0] if error else ""
    line = line.split(", at /", 1)[0].strip()
    return line.replace(keystore, "$ROS_SECURITY_KEYSTORE") if keystore else line


def secure_node_attempts(cases: dict) -> None:
    """Child-process procedure: one fresh context and node per case, under that case's variables.

    ``cases`` maps a label to the ``ROS_SECURITY_*`` variables of that case. Reports ``result``
    with, per label, ``created`` (bool) and ``error`` (the first line of what rcl or the middleware
    said, or '').
    """
    results = {}
    for label, variables in cases.items():
        for key in SECURITY_VARIABLES:
            os.environ.pop(key, None)
        os.environ.update(variables)  # rcl reads them when a context is initialised
        context = Context()
        try:
            context.init()
            Node(NODE_NAME, context=context).destroy_node()
            results[label] = {"created": True, "error": ""}
        except Exception as exc:  # rcl or the middleware refuses: keep its words
            results[label] = {"created": False,
                              "error": _first_words(str(exc), variables.get("ROS_SECURITY_KEYSTORE", ""))}
        finally:
            context.try_shutdown()
    report("result", cases=results)


def empty_keystore(directory: str) -> str:
    """Make ``directory``/keystore with an empty ``enclaves/`` folder; return the keystore's path."""
    keystore = os.path.join(directory, "keystore")
    os.makedirs(os.path.join(keystore, "enclaves"), exist_ok=True)
    return keystore


def try_security_settings(rt, cases: dict) -> dict:
    """Create a node under each case's security variables, in one child process.

    Args:
        rt: the kernel's runtime.
        cases: label -> ``{'ROS_SECURITY_ENABLE': 'true', 'ROS_SECURITY_STRATEGY': ..., ...}``;
            only ``ROS_SECURITY_*`` variables are allowed.

    Returns:
        label -> ``{'created': bool, 'error': str}``, in the order of ``cases``.
    """
    for label, variables in cases.items():
        unknown = sorted(set(variables) - set(SECURITY_VARIABLES))
        if unknown:
            raise CourseError(f"case {label!r}: {', '.join(unknown)} is not a security variable; "
                              f"allowed: {', '.join(SECURITY_VARIABLES)}")
    result = run_child_for_result(rt, "secure_nodes", secure_node_attempts, params={"cases": cases})
    return result["cases"]
