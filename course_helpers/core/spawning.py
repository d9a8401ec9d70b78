"""Nodes in child processes, as the runtime starts them: ``rt.spawn(...)`` and friends.

:class:`ChildNodes` is what the runtime delegates its child-process methods to. It needs three
things from the runtime, passed in explicitly: the current :class:`~.graph_view.GraphView` (to see
a child's nodes arrive and leave), the console router (a child's output in the notebook, or None
outside one), and a way to make sure the runtime runs. The processes themselves are started,
tracked and stopped by the process layer (:mod:`.processes`).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from course_helpers.core import processes
from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.graph_view import GraphView
from course_helpers.core.machine_load import cpu_seconds
from course_helpers.core.mapped_files import replaced_shm_ports
from course_helpers.core.validation import check_node_name
from course_helpers.core.waiting import poll_until

CHILD_HANG_S = 60.0  # s; bounds a hang only: a child starts and is discovered in 1-2 s idle, several
# seconds beside a full test stage on two cores; a child that fails says so at once (its exit)
ENTRY_SETTLE_S = 0.15  # s; a new node's graph entry unchanged this long counts as complete
OLD_NODES_GONE_S = 3.0  # s; how long a re-spawn waits for the old process's nodes to leave the graph


class ChildNodes:
    """The child-process nodes of one runtime.

    Args:
        graph: returns the runtime's current graph view (starting the runtime if needed).
        consoles: the router that shows a child's output under its cell, or None outside a notebook.
        ensure_running: starts the runtime if it is not running.
    """

    def __init__(self, graph: Callable[[], GraphView], consoles, ensure_running: Callable[[], None]):
        self._graph = graph
        self._consoles = consoles
        self._ensure_running = ensure_running

    def spawn(self, name: str, target, params: dict | None = None, wait_for: str | None = None,
              timeout: float = CHILD_HANG_S, env: dict | None = None) -> processes.ChildProcess:
        """Run ``target`` in a child process: a function or Node subclass, or 'module:callable'.

        ``name`` labels the process; a child with the same label is stopped first. ``params`` are
        keyword arguments for the target (JSON values). ``wait_for`` names a node ('/talker') to
        wait for in the graph before returning. ``env`` adds environment variables (e.g. another
        ROS_DOMAIN_ID).
        """
        check_node_name(name)
        if params is not None and not isinstance(params, dict):
            raise CourseError(f"params must be a dict of keyword arguments, got {params!r}")
        argv = processes.python_target_argv(target, params)  # a bad target fails before anything stops
        self._ensure_running()
        old = processes.get(name)
        old_nodes = set((old.last("ready") or {}).get("nodes", [])) if old is not None else set()
        processes.stop([name])
        if old_nodes:  # the old process's nodes leave the graph before the new ones are awaited
            graph = self._graph()
            poll_until(lambda: not old_nodes & set(graph.nodes()), OLD_NODES_GONE_S, graph.wait_period)
        child = processes.start(name, argv, env=env, target=processes.target_spec(target))
        if self._consoles is not None:
            self._consoles.open(name, f"child process {name}", show=False)
        if wait_for:
            started = time.monotonic()
            child.wait_for_report("ready", timeout, f"its nodes to be created (waiting for {wait_for})")
            self.wait_for_child_node(child, wait_for, max(0.5, timeout - (time.monotonic() - started)))
        return child

    def wait_for_child_node(self, child: processes.ChildProcess, fqn: str,
                            timeout: float = CHILD_HANG_S) -> None:
        """Wait until ``child``'s node ``fqn`` is in the graph with all its endpoints; fail at once if
        the process ends.

        A node's endpoints reach the graph one update after another, and the first update can list
        the node before all of them: after the node appears, this waits (within ``timeout``) until
        its publishers, subscriptions, services and clients stay the same for ``ENTRY_SETTLE_S``.
        Both waits wake on the graph's change events (and on the child's end).
        """
        graph = self._graph()
        started = time.monotonic()
        if not poll_until(lambda: fqn in graph.nodes() or not child.alive, timeout, graph.wait_period):
            cpu = cpu_seconds(child.pid)
            used = "?" if cpu is None else f"{cpu:.1f}"
            replaced = replaced_shm_ports()
            ports = f"; shared-memory ports this process maps were replaced: {replaced}" if replaced else ""
            raise WaitTimeout(f"{child.group} process {child.label!r} did not show node {fqn} in the graph "
                              f"within {timeout:g} s ({graph.whereabouts(fqn)}; the process has used "
                              f"{used} s of CPU{ports}). Its output:\n{child.output_tail()}")
        if fqn not in graph.nodes():
            raise child.failure(f"node {fqn} appeared")
        entry, since = graph.entry(fqn), time.monotonic()

        def settled() -> bool:
            nonlocal entry, since
            now = graph.entry(fqn)
            if now != entry:
                entry, since = now, time.monotonic()
            return time.monotonic() - since >= ENTRY_SETTLE_S

        # woken by each change; the period lets the quiet time itself run out
        poll_until(settled, max(0.0, timeout - (time.monotonic() - started)), ENTRY_SETTLE_S / 3)

    def stop_child(self, name: str) -> int | None:
        """Stop a child process by name (SIGTERM, then SIGKILL); returns its exit code."""
        return self.stop_children([name]).get(name)

    def stop_children(self, names) -> dict[str, int | None]:
        """Stop several child processes together: SIGTERM to all, then wait; exit codes by name."""
        names = list(names)
        if self._consoles is not None:
            for name in names:
                self._consoles.close(name)
        return processes.stop(names)

    def children(self) -> dict[str, processes.ChildProcess]:
        """The child processes started by this kernel, by name."""
        return processes.running("node")
