"""Entry point of a child-process node: ``python -m course_helpers.child TARGET KWARGS_JSON``.

Used through :meth:`course_helpers.runtime.CourseRuntime.spawn` in chapters 01
(kill a node, the rest keep talking), 06 (several nodes started together, like a
launch file), 07 (domains, discovery), 08 (real transport loss) and 10.

``TARGET`` is ``module:callable``. The callable is called with the keyword
arguments; if it returns a node (or a list of nodes) they are spun until the
process gets SIGTERM or SIGINT, then destroyed, and the process exits 0. A
callable that returns None is run for its side effects and the process exits.
"""

from __future__ import annotations

import ctypes
import importlib
import json
import os
import signal
import sys


def _die_with_parent() -> None:
    """Ask Linux to send SIGTERM to this process when the kernel that started it dies."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        pr_set_pdeathsig = 1
        libc.prctl(pr_set_pdeathsig, signal.SIGTERM)
    except OSError:
        pass
    if os.getppid() != int(os.environ.get("COURSE_PARENT_PID", os.getppid())):
        sys.exit(0)  # the parent is already gone


def load_target(spec: str):
    """Import ``module:callable`` and return the callable."""
    module_name, _, attr = spec.partition(":")
    if not module_name or not attr:
        raise SystemExit(f"target must look like 'package.module:callable', got {spec!r}")
    obj = importlib.import_module(module_name)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def main(argv: list[str]) -> int:
    _die_with_parent()
    if len(argv) != 3:
        print("usage: python -m course_helpers.child module:callable '{json kwargs}'",
              file=sys.stderr)
        return 2
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node

    target = load_target(argv[1])
    kwargs = json.loads(argv[2])
    rclpy.init()  # default signal handlers: SIGINT and SIGTERM shut this process down
    try:
        result = target(**kwargs)
        nodes = [result] if isinstance(result, Node) else list(result or [])
        if nodes:
            executor = SingleThreadedExecutor()
            for node in nodes:
                executor.add_node(node)
            print(f"child {os.getpid()} ready: {[n.get_fully_qualified_name() for n in nodes]}",
                  flush=True)
            try:
                executor.spin()
            except (KeyboardInterrupt, ExternalShutdownException):
                pass
            executor.shutdown(timeout_sec=1.0)
            for node in nodes:
                node.destroy_node()
    finally:
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
