"""How a notebook waits on the runtime: for a future, a condition, messages, a node, or the
executor's own queue, never by spinning the executor from the notebook's thread.

:class:`NotebookWaits` is the waiting half of :class:`.runtime.CourseRuntime`; it uses the runtime's
``executor``, ``graph``, ``graph_nodes``, ``_graph_view``, ``_ensure_running`` and
``_in_executor_thread``.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.qos import QoSProfile

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.names import as_full_name
from course_helpers.core.validation import check_depth, check_topic_name, interface_name, resolve_interface
from course_helpers.core.waiting import HANG_S, poll_until, wait_for_future, wait_until


class NotebookWaits:
    """The runtime's waits (mixed into CourseRuntime)."""

    def call_in_executor(self, function: Callable, *args, timeout: float = HANG_S):
        """Run ``function(*args)`` in the executor thread and return its result.

        Called from the executor thread itself (from a callback), it runs the function directly.
        """
        self._ensure_running()
        if self._in_executor_thread():
            return function(*args)
        task = self.executor.create_task(function, *args)
        self.executor.wake()
        return self.wait_for_future(task, timeout=timeout, what=getattr(function, "__name__", "task"))

    def settle_callbacks(self, rounds: int = 2, timeout: float = 60.0) -> None:
        """Wait until the executor ran every callback ready now, and those they made ready, ``rounds``
        deep: a sentinel on its own queue (a task runs before its next wait), not a window (a chain
        of this kernel's nodes, one hop a round, has finished). ``timeout`` bounds a hang only."""
        for _ in range(rounds):
            self.call_in_executor(lambda: None, timeout=timeout)

    wait_for_future = staticmethod(wait_for_future)

    def wait_until(self, predicate: Callable[[], object], timeout: float = HANG_S,
                   what: str = "the condition") -> bool:
        """Wait until ``predicate()`` is true; if not, raise :class:`WaitTimeout` naming ``what``
        and the nodes the graph lists at that moment (what is there when something is not). The
        default ``timeout`` only ends a hang (:data:`.waiting.HANG_S`): pass a short one only where
        timing out is the outcome a cell shows.

        The wait wakes on graph changes, child reports and this kernel's callbacks, and looks every
        20 ms besides (:mod:`.waiting`)."""
        try:
            return wait_until(predicate, timeout, what)
        except WaitTimeout as exc:
            listed = ", ".join(self.graph_nodes()) or "no node"
            raise WaitTimeout(f"{exc}; the graph lists {listed}") from None

    def poll_until(self, predicate: Callable[[], object], timeout: float = 5.0) -> bool:
        """Wait until ``predicate()`` is true; False (not an error) if ``timeout`` passes first."""
        return poll_until(predicate, timeout)

    def wait_for_messages(self, topic: str, msg_type, count: int = 1, timeout: float = HANG_S,
                          qos: QoSProfile | int = 10) -> list:
        """Subscribe to ``topic``, return the first ``count`` messages, then unsubscribe."""
        check_topic_name(topic)
        msg_type = resolve_interface(msg_type, "msg")
        if isinstance(qos, int):
            qos = check_depth(qos)
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise CourseError(f"count must be a whole number >= 1, got {count!r}")
        received: list = []
        internal = self.graph
        sub = internal.create_subscription(msg_type, topic, received.append, qos)
        try:
            wait_until(lambda: len(received) >= count, timeout,
                       f"{count} message(s) on {topic} ({interface_name(msg_type)}); got {len(received)}")
        finally:
            self.call_in_executor(internal.destroy_subscription, sub)
        return received[:count]

    def wait_for_node(self, fqn: str, timeout: float = HANG_S) -> None:
        """Wait until a node (in any process of this domain) shows up in the ROS graph (woken by the
        graph's changes)."""
        fqn = as_full_name(fqn)
        graph = self._graph_view()
        wait_until(lambda: fqn in graph.nodes(), timeout, f"node {fqn} in the graph", graph.wait_period)
