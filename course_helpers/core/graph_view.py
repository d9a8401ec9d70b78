"""A runtime's view of the ROS graph: its hidden node, and answers kept until the graph changes.

Every graph query of the course (``rt.graph_nodes()``, a child's node settling, ``%ros2 node list``)
goes through the runtime's hidden node ``_course_runtime``. A query costs rcl calls per node (its
publishers, subscriptions, services and clients), and waits ask again and again. A
:class:`~course_helpers.core.graph_events.GraphWatcher` counts the graph's changes, so an answer is
computed once per change and a wait sleeps until the next one. An answer is also kept no longer
than :data:`WATCHED_PERIOD_S`, so that a change rmw did not signal could cost no more than that.
Without the watcher (rcl could not be loaded), every query asks rcl again and graph waits look every
:data:`~course_helpers.core.waiting.UNNOTIFIED_PERIOD_S`.
"""

from __future__ import annotations

import threading
import time

from rclpy.node import Node

from course_helpers.core.dds_config import DEFAULT_ANNOUNCEMENT_S
from course_helpers.core.graph_events import GraphWatcher
from course_helpers.core.names import full_name, node_full_names
from course_helpers.core.node_hook import outside_builds
from course_helpers.core.waiting import UNNOTIFIED_PERIOD_S

INTERNAL_NODE = "_course_runtime"  # hidden (leading underscore), like ros2cli's daemon nodes
# A new participant may learn of an older one only at its next periodic announcement (every 3 s
# outside the course): by this long after the start, the graph shows what was already running.
GRAPH_SETTLE_S = DEFAULT_ANNOUNCEMENT_S + 0.3
# rmw's DDS topic prefixes: which of a node's four lists an endpoint belongs to if it writes, if it reads,
# and the suffix the service's name carries (0 publishers, 1 subscriptions, 2 services, 3 clients)
_ROS_TOPIC_KINDS = {"rt/": (0, 1, ""), "rq/": (3, 2, "Request"), "rr/": (2, 3, "Reply")}
NO_ENDPOINTS = ((), (), (), ())  # the entry of a node the graph lists nothing live for
WATCHED_PERIOD_S = 1.0  # s; with a watcher, a graph wait still looks this often, and answers are
# kept no longer (a lost event costs no more)


class GraphView:
    """The graph as the hidden node ``INTERNAL_NODE`` in ``context`` sees it; :meth:`close` before the
    context shuts down. ``started_at`` is when the runtime started (``time.monotonic()``)."""

    def __init__(self, context, started_at: float):
        self._started_at = started_at
        self._settled = False
        with outside_builds():  # the first query may come from inside a child's procedure
            self.node = Node(INTERNAL_NODE, context=context, enable_rosout=False,
                             start_parameter_services=False)
        try:
            self._watcher: GraphWatcher | None = GraphWatcher(self.node)
        except (OSError, AttributeError):
            self._watcher = None
        self._lock = threading.Lock()
        self._cached_version: tuple | None = None
        self._cache: dict = {}
        self._local_changes = 0  # this process's own changes, counted as they happen (see changed())

    @property
    def wait_period(self) -> float:
        """How often a wait for something in the graph must look besides the graph's change events."""
        return WATCHED_PERIOD_S if self._watcher is not None and self._watcher.alive else UNNOTIFIED_PERIOD_S

    def changed(self) -> None:
        """This process changed the graph (a node added or destroyed): answers kept so far are stale at
        once. The watcher hears of it too, but from another thread and a moment later: without this, a
        query right after ``rt.add()`` could get the answer from before."""
        with self._lock:
            self._local_changes += 1

    def _cached(self, key, compute):
        """``compute()``, kept until the graph changes or for :data:`WATCHED_PERIOD_S` (not kept
        without a watcher)."""
        if self._watcher is None or not self._watcher.alive:
            return compute()
        version = (self._watcher.version, self._local_changes)
        now = time.monotonic()
        with self._lock:
            if self._cached_version != version:
                self._cache, self._cached_version = {}, version
            if key in self._cache and now - self._cache[key][0] < WATCHED_PERIOD_S:
                return self._cache[key][1]
        value = compute()  # a change meanwhile raises the version: the next call computes again
        with self._lock:
            if self._cached_version == version:
                self._cache[key] = (now, value)
        return value

    def settle(self) -> None:
        """Wait, once per start, until discovery has found the processes that were already running.

        A new participant announces itself at start, and the others answer; ros2cli keeps a
        daemon running for the same reason. ``%ros2`` calls this before its first graph query,
        so a command run right after the runtime started does not show an empty graph.
        """
        if not self._settled:
            remaining = self._started_at + GRAPH_SETTLE_S - time.monotonic()
            if remaining > 0:
                time.sleep(remaining)
            self._settled = True

    def nodes(self, include_hidden: bool = False) -> list[str]:
        """Full names of all nodes discovered in this domain (the live graph), sorted.

        A node listed without a single endpoint is left out. rclpy gives every node at least its
        ``/parameter_events`` publisher, so such an entry is either a node still being created or
        a ghost: one that rmw keeps listing after its process has left (see :mod:`.child` on the
        goodbye that overtakes a node's last graph update, and :meth:`endpoints`).
        """
        def compute() -> list[str]:
            names = node_full_names(self.node.get_node_names_and_namespaces(), include_hidden)
            owners = self.endpoints()
            return [fqn for fqn in names if fqn in owners]

        return list(self._cached(("nodes", include_hidden), compute))

    def entry(self, fqn: str) -> tuple:
        """What the graph lists for node ``fqn``: its publishers, subscriptions, services and clients,
        each a sorted tuple of ``'name type'`` (all four empty for a node without live endpoints)."""
        return self.endpoints().get(fqn, NO_ENDPOINTS)

    def endpoints(self) -> dict[str, tuple]:
        """Node full name -> its live publishers, subscriptions, services and clients (see :meth:`entry`
        and :func:`endpoints_by_node`), kept until the graph changes."""
        try:
            return self._cached(("endpoints",), lambda: endpoints_by_node(self.node))
        except Exception:  # the context went down meanwhile: nothing is live
            return {}

    def whereabouts(self, fqn: str) -> str:
        """What the graph says of node ``fqn`` right now, in words, for the message of a wait that ran out:
        whether it lists the name at all, and with or without endpoints."""
        listed = node_full_names(self.node.get_node_names_and_namespaces(), True)
        if fqn not in listed:
            return f"the graph lists {len(listed)} node(s), none named {fqn}"
        return f"the graph lists {fqn} with {'its endpoints' if any(self.entry(fqn)) else 'no endpoint yet'}"

    def close(self) -> None:
        """Stop the watcher and destroy the hidden node."""
        if self._watcher is not None:
            self._watcher.stop()
            self._watcher = None
        try:
            self.node.destroy_node()
        except Exception:  # the context is gone already
            pass


def endpoints_by_node(node: Node) -> dict[str, tuple]:
    """Node full name -> its live publishers, subscriptions, services and clients, as ``node`` sees the
    graph: four sorted tuples of ``'name type'``.

    Read endpoint by endpoint, topic by topic, not with rcl's queries by node name. rmw_dds_common's
    graph cache answers those from the first node of that name it finds (``__find_node``), so a ghost
    of a node that left, listed under the same name, would hide the live node's endpoints: a package
    run again after Ctrl+C would never seem to appear. A ghost has no live endpoint, so it owns
    nothing here. Services are the request and reply topics rmw makes for them (``rq/``, ``rr/``); each
    is listed once, with the service's type as ``ros2 service list -t`` spells it.
    """
    found: dict[str, tuple[set, set, set, set]] = {}
    for raw, _types in node.get_topic_names_and_types(no_demangle=True):
        kind = _ROS_TOPIC_KINDS.get(raw[:3])
        if kind is None:  # a DDS topic of rmw's own (ros_discovery_info)
            continue
        name = "/" + raw[3:].removesuffix(kind[2])
        writers = node.get_publishers_info_by_topic(raw, no_mangle=True)
        readers = node.get_subscriptions_info_by_topic(raw, no_mangle=True)
        for writes, infos in ((True, writers), (False, readers)):
            for info in infos:
                if info.node_name.startswith("_NODE_"):  # an endpoint whose node rmw does not know
                    continue
                fqn = full_name(info.node_namespace, info.node_name)
                sets = found.setdefault(fqn, (set(), set(), set(), set()))
                sets[kind[0] if writes else kind[1]].add(f"{name} {_ros_type(info.topic_type, kind[2])}")
    return {fqn: tuple(tuple(sorted(group)) for group in sets) for fqn, sets in found.items()}


def _ros_type(dds_type: str, service: str) -> str:
    """A DDS type name as ROS spells it: ``std_msgs::msg::dds_::String_`` -> ``std_msgs/msg/String``;
    a service's request or reply type (``service`` is 'Request' or 'Reply') -> the service's type."""
    parts = dds_type.split("::")
    if len(parts) != 4 or parts[2] != "dds_":
        return dds_type
    name = parts[3].removesuffix("_")
    if service:
        name = name.removesuffix("_Request").removesuffix("_Response")
    return f"{parts[0]}/{parts[1]}/{name}"
