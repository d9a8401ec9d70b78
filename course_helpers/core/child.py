"""Entry point of every child process the course starts (see :mod:`.processes`).

``python -m course_helpers.core.child run module:callable '{json kwargs}'``
    Calls the target with the keyword arguments inside the child's own course runtime.
    If it builds nodes (it returns a node, a list of nodes, or a Node subclass is the
    target), they are spun until the process gets SIGTERM or SIGINT; then they are
    destroyed, the process's participant leaves :data:`DEPARTURE_S` later, and the process
    exits 0. The child reports ``ready`` with its nodes' full
    names on the channel first. A target that returns None is a procedure: it runs,
    reports what it measured over the channel, and the process exits.
``python -m course_helpers.core.child exec PROGRAM ARGS...``
    Runs PROGRAM as its only child and stays as its supervisor (:mod:`.supervisor`), so that
    the program's own children stop with it, even when the kernel dies.

Either way the child asks Linux for SIGTERM when the kernel dies, exits at once if the kernel
is already gone, and ends whatever it started when it exits (it is a child subreaper). A ``run``
child also watches for the kernel going away (in case that signal is lost, as it can be when the
kernel ends with ``os._exit``), and gives its clean-up :data:`CLEANUP_S` seconds before it
simply exits, so no orphan keeps running. That last step does not rely on Python: the first stop
signal, or the watchdog, arms an interval timer whose SIGALRM ends the process by the operating
system's default action, even while a hung call holds the GIL and no Python thread can run (the
process's own children then get their death signal).
"""

from __future__ import annotations

import atexit
import importlib
import json
import os
import signal
import sys
import threading
import time
import traceback

from course_helpers.core.channel import CHANNEL_ENV, report
from course_helpers.core.supervisor import (
    CLEANUP_S,
    become_subreaper,
    die_with_parent,
    end_descendants,
    orphaned,
    supervise,
)
from course_helpers.core.waiting import poll_until

PARENT_CHECK_S = 0.5  # how often the watchdog looks for the kernel
KEEPER_NODE = "_course_child"  # hidden: holds the process's participant until its nodes have left
DEPARTURE_S = 0.2  # s; from a stopping child's last node update to its participant's goodbye
# s; from the first stop signal to the end of the process, by the operating system: after the watchdog's
# own end (CLEANUP_S), which also ends the process's descendants, for a clean-up that hangs holding the GIL
DEADLINE_S = CLEANUP_S + 2.0


def load_target(spec: str):
    """Import ``module:callable`` and return the callable."""
    module_name, _, attr = spec.partition(":")
    if not module_name or not attr:
        raise SystemExit(f"target must look like 'package.module:callable', got {spec!r}")
    obj = importlib.import_module(module_name)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def _arm_deadline() -> None:
    """End this process :data:`DEADLINE_S` from now, whatever its threads are doing (armed once).

    SIGALRM with its default action terminates the process in the kernel, without running Python.
    """
    if signal.getitimer(signal.ITIMER_REAL)[0] == 0:
        signal.setitimer(signal.ITIMER_REAL, DEADLINE_S)


class _StopSignal:
    """SIGTERM/SIGINT: while nodes are served, ask the serving loop to stop; before, exit. Either way,
    the stop has a deadline (:func:`_arm_deadline`)."""

    def __init__(self):
        self.event = threading.Event()
        self.serving = False
        signal.signal(signal.SIGALRM, signal.SIG_DFL)  # the deadline's signal ends the process
        signal.signal(signal.SIGTERM, self._handle)
        signal.signal(signal.SIGINT, self._handle)

    def _handle(self, _signum, _frame) -> None:
        _arm_deadline()
        self.event.set()
        if not self.serving:
            raise SystemExit(0)  # stopped before (or instead of) serving nodes: end at once


def _watch_parent(stop: _StopSignal) -> None:
    """Stop serving when the kernel is gone; end the process if the clean-up then hangs.

    Polls: a lost death signal leaves nothing to wait on but the parent PID changing.
    """

    def watch() -> None:
        poll_until(lambda: stop.event.is_set() or orphaned(), float("inf"), period=PARENT_CHECK_S,
                   wake_on=None)  # not woken by the node's callbacks
        stop.event.set()
        _arm_deadline()  # the kernel is gone and its death signal may have been lost
        time.sleep(CLEANUP_S)  # the main thread exits long before this, unless its clean-up hangs
        end_descendants(0)
        os._exit(0)  # leave no orphan behind

    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def _participant_keeper(rt):
    """A hidden node without endpoints that keeps this process's DDS participant alive.

    rmw_fastrtps deletes the participant, and sends its goodbye, when the last node of the
    context is destroyed: in the same instant as the graph updates that say the nodes are gone.
    The kernel handles the two in separate threads. If it drops the participant first, and only
    then applies an update that still lists a node, it re-adds that node for good: a ghost no
    lease can remove (rmw_dds_common's ``update_participant_entities`` re-creates an unknown
    participant). With the keeper, the nodes leave first and the goodbye follows
    :data:`DEPARTURE_S` later; the keeper's own last update lists no node.
    """
    from course_helpers.core.node_hook import bare_node

    return bare_node(rt.context, KEEPER_NODE)


def _leave(rt, keeper) -> None:
    """Destroy the nodes; :data:`DEPARTURE_S` later, end the participant (the keeper goes last)."""
    rt.stop()
    if keeper is not None:
        time.sleep(DEPARTURE_S)
        keeper.destroy_when_not_in_use()


def run(spec: str, kwargs: dict) -> int:
    """Run a target in this process's course runtime; the process's exit code."""
    from rclpy.node import Node

    from course_helpers.core.runtime import get_runtime

    stop = _StopSignal()
    _watch_parent(stop)
    target = load_target(spec)
    rt = get_runtime()
    keeper = None
    try:
        try:
            result = rt.build(target, **kwargs)
        except Exception as exc:
            report("error", type=type(exc).__name__, message=str(exc))
            raise
        nodes = [result] if isinstance(result, Node) else [n for n in (result or []) if isinstance(n, Node)]
        if not nodes:
            return 0
        for node in nodes:
            rt.add(node, console=False)
        keeper = _participant_keeper(rt)
        stop.serving = True
        report("ready", nodes=[n.get_fully_qualified_name() for n in nodes], pid=os.getpid())
        print(f"child {os.getpid()} ready: {[n.get_fully_qualified_name() for n in nodes]}", flush=True)
        while not stop.event.wait(3600):  # interruptible: the handler sets the event
            pass
        return 0
    finally:
        stop.serving = True  # a second signal during the clean-up must not cut it short
        _leave(rt, keeper)


def _drop_channel() -> None:
    """A program gets no report channel (and is no course child); the supervisor closes its copy."""
    os.environ.pop("COURSE_CHILD", None)
    fd = os.environ.pop(CHANNEL_ENV, None)
    if fd is not None:
        try:
            os.close(int(fd))
        except OSError:
            pass


def main(argv: list[str]) -> int:
    os.environ["COURSE_CHILD"] = "1"  # reports go to the channel, or to stdout without one
    die_with_parent()
    become_subreaper()
    if len(argv) >= 3 and argv[1] == "exec":
        supervise(argv[2], argv[3:], _drop_channel)
    atexit.register(end_descendants)  # registered first, so it runs last (after the process layer's)
    if len(argv) != 4 or argv[1] != "run":
        print("usage: python -m course_helpers.core.child run module:callable '{json kwargs}'\n"
              "       python -m course_helpers.core.child exec PROGRAM [ARGS...]", file=sys.stderr)
        return 2
    try:
        return run(argv[2], json.loads(argv[3]))
    except SystemExit:
        raise
    except Exception:
        traceback.print_exc()
        return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
