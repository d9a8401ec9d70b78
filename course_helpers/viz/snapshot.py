"""The live ROS graph as plain data: which nodes exist, and what each publishes, subscribes,
serves and calls (``graph_snapshot``).

Everything comes from the live graph of the kernel's ROS domain, asked through the runtime's
hidden node, so nodes in child processes (or in another program on the same domain) appear as
well. Like ``ros2 node list`` and rqt_graph, a snapshot hides infrastructure unless asked
(``include_hidden=True``): nodes whose name starts with ``_``, names with a part starting with
``_`` (the ``/_action/`` topics and services behind every action), ``/rosout``,
``/parameter_events`` and each node's parameter and type-description services.

A DDS program without ROS (chapter 07b's Cyclone DDS participant) has endpoints on ROS topics but
no node: rmw lists them under the node name ``_CREATED_BY_BARE_DDS_APP_``. A snapshot shows each
such participant as one box of its own, named by its vendor and GUID prefix
(``[Eclipse Cyclone DDS 01.10.0d.22]``), with its writers and readers as edges.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rclpy.action.graph import (
    get_action_client_names_and_types_by_node,
    get_action_server_names_and_types_by_node,
)

from course_helpers.core.dds_vendors import gid_prefix, gid_vendor
from course_helpers.core.errors import CourseError
from course_helpers.core.names import full_name

HIDDEN_TOPICS = frozenset({"/rosout", "/parameter_events"})
BARE_DDS_NODE = "_CREATED_BY_BARE_DDS_APP_"  # rmw's node name for an endpoint that no ROS node owns
# Services every node offers for its parameters and interface descriptions.
INFRASTRUCTURE_SERVICES = frozenset({
    "describe_parameters", "get_parameter_types", "get_parameters", "list_parameters",
    "set_parameters", "set_parameters_atomically", "get_type_description",
})

@dataclass(frozen=True, order=True)
class Edge:
    """One arrow of the graph: ``source -> target`` carrying ``type``.

    Topic edges go publisher node -> topic and topic -> subscriber node; service
    edges client node -> service -> server node; action edges client -> action ->
    server. ``type`` is the full interface name, e.g. ``std_msgs/msg/String``.
    """

    source: str
    target: str
    type: str
    kind: str = "topic"
    role: str = "publisher"  # the node's role: publisher, subscriber, client or server

    @property
    def short_type(self) -> str:
        """The type as rqt and most docs abbreviate it: ``std_msgs/String``."""
        return short_type(self.type)


@dataclass
class GraphSnapshot:
    """The ROS graph at one moment, as plain sorted data (compare it, print it, draw it)."""

    domain_id: int | None
    nodes: list[str] = field(default_factory=list)
    topics: dict[str, list[str]] = field(default_factory=dict)
    edges: list[Edge] = field(default_factory=list)
    services: dict[str, list[str]] = field(default_factory=dict)
    service_edges: list[Edge] = field(default_factory=list)
    actions: dict[str, list[str]] = field(default_factory=dict)
    action_edges: list[Edge] = field(default_factory=list)
    include_hidden: bool = False

    def publishers(self, topic: str) -> list[str]:
        """Nodes publishing on ``topic``, sorted."""
        return sorted({e.source for e in self.edges if e.target == topic})

    def subscribers(self, topic: str) -> list[str]:
        """Nodes subscribed to ``topic``, sorted."""
        return sorted({e.target for e in self.edges if e.source == topic})

    def as_text(self) -> str:
        """One line per node and per topic edge, sorted (stable enough for nbval)."""
        lines = [f"nodes: {', '.join(self.nodes) or '(none)'}"]
        lines += [f"{e.source} -> {e.target} [{e.short_type}]" for e in self.edges]
        lines += [f"{e.source} -> {e.target} [{e.short_type}] (service)" for e in self.service_edges]
        lines += [f"{e.source} -> {e.target} [{e.short_type}] (action)" for e in self.action_edges]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.as_text()


def short_type(full: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs/String`` (other shapes are returned unchanged)."""
    parts = full.split("/")
    if len(parts) == 3 and parts[1] in ("msg", "srv", "action"):
        return f"{parts[0]}/{parts[2]}"
    return full


def is_hidden_node(fqn: str) -> bool:
    """True for nodes ros2cli hides: their base name starts with ``_``."""
    return fqn.rsplit("/", 1)[-1].startswith("_")


def is_hidden_topic(name: str) -> bool:
    """True for ``/rosout``, ``/parameter_events`` and names with a part starting with ``_``."""
    return name in HIDDEN_TOPICS or any(part.startswith("_") for part in name.split("/"))


def is_hidden_service(name: str) -> bool:
    """True for parameter/type-description services and names with a part starting with ``_``."""
    parts = name.split("/")
    return parts[-1] in INFRASTRUCTURE_SERVICES or any(p.startswith("_") for p in parts)


def bare_participant_name(gid) -> str:
    """The box of a participant without ROS nodes: its vendor and the start of its GUID prefix."""
    return f"[{gid_vendor(gid)} {gid_prefix(gid)[:11]}]"


def resolve_runtime(rt):
    if rt is None:
        from course_helpers.core.runtime import get_runtime

        return get_runtime()
    if not hasattr(rt, "graph"):
        raise CourseError(f"rt must be the course runtime (rt = get_runtime()), got {type(rt).__name__}")
    return rt


def graph_snapshot(rt=None, include_hidden: bool = False) -> GraphSnapshot:
    """Ask the live graph which nodes exist and what each publishes, subscribes, serves and calls.

    Nodes of every process in the runtime's domain are included. Infrastructure
    (see the module docstring) is left out unless ``include_hidden=True``.
    """
    rt = resolve_runtime(rt)
    return snapshot_of(rt.graph, rt.domain.domain_id, include_hidden)


def snapshot_of(graph, domain_id: int | None = None, include_hidden: bool = False) -> GraphSnapshot:
    """:func:`graph_snapshot` asked through any rclpy node (``graph``) instead of the runtime."""
    snap = GraphSnapshot(domain_id=domain_id, include_hidden=include_hidden)
    topic_types: dict[str, set[str]] = {}
    service_types: dict[str, set[str]] = {}
    action_types: dict[str, set[str]] = {}
    edges: set[Edge] = set()
    service_edges: set[Edge] = set()
    action_edges: set[Edge] = set()

    def collect(query, name, namespace, role, kind, hidden, types, into):
        try:
            found = query(name, namespace)
        except Exception:  # the node left the graph between listing and asking
            return False
        fqn = full_name(namespace, name)
        for endpoint, endpoint_types in found:
            if hidden(endpoint) and not include_hidden:
                continue
            types.setdefault(endpoint, set()).update(endpoint_types)
            for type_name in endpoint_types:
                into.add(Edge(fqn, endpoint, type_name, kind, role) if role in ("publisher", "client")
                         else Edge(endpoint, fqn, type_name, kind, role))
        return True

    nodes = set()
    for name, namespace in sorted(set(graph.get_node_names_and_namespaces()), key=lambda p: p[::-1]):
        fqn = full_name(namespace, name)
        if is_hidden_node(fqn) and not include_hidden:
            continue
        if not collect(graph.get_publisher_names_and_types_by_node, name, namespace, "publisher", "topic",
                       is_hidden_topic, topic_types, edges):
            continue
        nodes.add(fqn)
        collect(graph.get_subscriber_names_and_types_by_node, name, namespace, "subscriber", "topic",
                is_hidden_topic, topic_types, edges)
        collect(graph.get_client_names_and_types_by_node, name, namespace, "client", "service",
                is_hidden_service, service_types, service_edges)
        collect(graph.get_service_names_and_types_by_node, name, namespace, "server", "service",
                is_hidden_service, service_types, service_edges)
        collect(lambda n, ns: get_action_client_names_and_types_by_node(graph, n, ns), name, namespace,
                "client", "action", lambda _a: False, action_types, action_edges)
        collect(lambda n, ns: get_action_server_names_and_types_by_node(graph, n, ns), name, namespace,
                "server", "action", lambda _a: False, action_types, action_edges)

    for topic, _types in graph.get_topic_names_and_types():
        if include_hidden or not is_hidden_topic(topic):
            _collect_bare_dds(graph, topic, nodes, topic_types, edges)
    snap.nodes = sorted(nodes)
    snap.topics = {t: sorted(types) for t, types in sorted(topic_types.items())}
    snap.edges = sorted(edges)
    snap.services = {s: sorted(types) for s, types in sorted(service_types.items())}
    snap.service_edges = sorted(service_edges)
    snap.actions = {a: sorted(types) for a, types in sorted(action_types.items())}
    snap.action_edges = sorted(action_edges)
    return snap


def _collect_bare_dds(graph, topic: str, nodes: set, topic_types: dict, edges: set) -> None:
    """Add the writers and readers of ``topic`` that no ROS node owns, one box per participant."""
    for query, role in ((graph.get_publishers_info_by_topic, "publisher"),
                        (graph.get_subscriptions_info_by_topic, "subscriber")):
        try:
            infos = query(topic)
        except Exception:  # the topic left the graph meanwhile
            continue
        for info in infos:
            if info.node_name != BARE_DDS_NODE:
                continue
            box = bare_participant_name(info.endpoint_gid)
            nodes.add(box)
            topic_types.setdefault(topic, set()).add(info.topic_type)
            edges.add(Edge(box, topic, info.topic_type, "topic", role) if role == "publisher"
                      else Edge(topic, box, info.topic_type, "topic", role))
