"""Entry point of a child-process node: ``python -m course_helpers.child TARGET KWARGS_JSON``.

Used through :meth:`course_helpers.runtime.CourseRuntime.spawn` in chapters 01
(kill a node, the rest keep talking), 06 (several nodes started together, like a
launch file), 07 (domains, discovery), 08 (real transport loss) and 10.

``TARGET`` is ``module:callable``. The callable is called with the keyword
arguments; if it returns a node (or a list of nodes) they are spun until the
process gets SIGTERM or SIGINT, then destroyed, and the process exits 0 (callbacks that are
running when the signal arrives are allowed to finish first). A
callable that returns None is run for its side effects and the process exits.
"""

from __future__ import annotations

import ctypes
import importlib
import json
import os
import signal
import sys
import threading

SPIN_SLICE_S = 0.05  # s; how long one spin_once may wait before the stop flag is checked again


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
    # SIGTERM/SIGINT only ask the spin loop below to stop. Letting rclpy's own handler
    # shut the context down instead races with callbacks that are running at that moment
    # (a relay's publish() then raises and the process exits 1 instead of 0).
    stop_requested = threading.Event()

    def request_stop(_signum, _frame) -> None:
        stop_requested.set()

    signal.signal(signal.SIGTERM, request_stop)
    signal.signal(signal.SIGINT, request_stop)

    _die_with_parent()
    if len(argv) != 3:
        print("usage: python -m course_helpers.child module:callable '{json kwargs}'",
              file=sys.stderr)
        return 2
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    target = load_target(argv[1])
    kwargs = json.loads(argv[2])
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    try:
        result = target(**kwargs)
        nodes = [result] if isinstance(result, Node) else list(result or [])
        if nodes:
            executor = SingleThreadedExecutor()
            for node in nodes:
                executor.add_node(node)
            print(f"child {os.getpid()} ready: {[n.get_fully_qualified_name() for n in nodes]}",
                  flush=True)
            while not stop_requested.is_set():
                executor.spin_once(timeout_sec=SPIN_SLICE_S)  # the signal is seen within one slice
            executor.shutdown(timeout_sec=1.0)
            for node in nodes:
                node.destroy_node()
    finally:
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
