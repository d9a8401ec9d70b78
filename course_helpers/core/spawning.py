"""Nodes in child processes, as the runtime starts them: ``rt.spawn(...)`` and friends.

A mix-in of :class:`course_helpers.core.runtime.CourseRuntime`; the processes themselves are
started, tracked and stopped by the process layer (:mod:`.processes`).
"""

from __future__ import annotations

import time

from course_helpers.core import processes
from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.names import split_full_name
from course_helpers.core.validation import check_node_name
from course_helpers.core.waiting import poll_until

ENTRY_SETTLE_S = 0.15  # s; a new node's graph entry unchanged this long counts as complete


class ChildProcesses:
    """The runtime's child-process methods (the runtime provides the graph and the consoles)."""

    def spawn(self, name: str, target, params: dict | None = None, wait_for: str | None = None,
              timeout: float = 15.0, env: dict | None = None) -> processes.ChildProcess:
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
        old_nodes = (old.last("ready") or {}).get("nodes", []) if old is not None else []
        processes.stop([name])
        if old_nodes:  # the old process's nodes leave the graph before the new ones are awaited
            poll_until(lambda: not set(old_nodes) & set(self.graph_nodes()), 3.0)
        child = processes.start(name, argv, env=env, target=processes.target_spec(target))
        if self._in_kernel:
            self._router.open(name, f"child process {name}", show=False)
        if wait_for:
            started = time.monotonic()
            child.wait_for_report("ready", timeout, f"its nodes to be created (waiting for {wait_for})")
            self.wait_for_child_node(child, wait_for, max(0.5, timeout - (time.monotonic() - started)))
        return child

    def wait_for_child_node(self, child: processes.ChildProcess, fqn: str, timeout: float = 15.0) -> None:
        """Wait until ``child``'s node ``fqn`` is in the graph with all its endpoints; fail at once if
        the process ends.

        A node's endpoints reach the graph one update after another, and the first update can list
        the node before all of them: after the node appears, this waits (within ``timeout``) until
        its publishers, subscriptions, services and clients stay the same for ``ENTRY_SETTLE_S``.
        """
        started = time.monotonic()
        if not poll_until(lambda: fqn in self.graph_nodes() or not child.alive, timeout):
            raise WaitTimeout(f"{child.group} process {child.label!r} did not show node {fqn} in the graph "
                              f"within {timeout:g} s. Its output:\n{child.output_tail()}")
        if fqn not in self.graph_nodes():
            raise child.failure(f"node {fqn} appeared")
        entry, since = self._graph_entry(fqn), time.monotonic()

        def settled() -> bool:
            nonlocal entry, since
            now = self._graph_entry(fqn)
            if now != entry:
                entry, since = now, time.monotonic()
            return time.monotonic() - since >= ENTRY_SETTLE_S

        poll_until(settled, max(0.0, timeout - (time.monotonic() - started)), period=0.02)

    def _graph_entry(self, fqn: str) -> tuple:
        """What the graph lists for node ``fqn``: its publishers, subscriptions, services and clients."""
        namespace, name = split_full_name(fqn)
        node = self._graph_node()
        try:
            return tuple(sorted(map(str, call(name, namespace))) for call in (
                node.get_publisher_names_and_types_by_node, node.get_subscriber_names_and_types_by_node,
                node.get_service_names_and_types_by_node, node.get_client_names_and_types_by_node))
        except Exception:  # the node left meanwhile: nothing to settle
            return ()

    def stop_child(self, name: str) -> int | None:
        """Stop a child process by name (SIGTERM, then SIGKILL); returns its exit code."""
        return self.stop_children([name]).get(name)

    def stop_children(self, names) -> dict[str, int | None]:
        """Stop several child processes together: SIGTERM to all, then wait; exit codes by name."""
        names = list(names)
        for name in names:
            self._router.close(name)
        return processes.stop(names)

    def children(self) -> dict[str, processes.ChildProcess]:
        """The child processes started by this kernel, by name."""
        return processes.running("node")
