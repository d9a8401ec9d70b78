"""Which DDS participant holds a node, and which participants a process has, read from the ROS graph.

rmw_fastrtps gives each rclpy context one DDS participant. ``rclpy.init()`` creates none: rmw_init only
keeps the options (rmw_fastrtps_cpp/src/rmw_init.cpp). The context's first node creates it, with a writer
and a reader of ``ros_discovery_info`` (rmw_create_node calls ``increment_context_impl_ref_count``, which
runs ``init_context_impl`` when the count is 0: rmw_fastrtps_cpp/src/rmw_node.cpp and
init_rmw_context_impl.cpp), and the last node destroyed deletes it (``decrement_context_impl_ref_count``).

Every reader and writer carries its participant's 12-byte GUID prefix as the first 12 bytes of its GID
(rmw_fastrtps_shared_cpp/guid_utils.hpp), which rclpy gives as a topic endpoint's ``endpoint_gid``.
Fast DDS 2.14 builds the prefix from its vendor id (2 bytes, ``01.0f``), a host id (2), the low 16 bits
of the process id (2), a random value drawn once per process (2), and the participant's id in its process
(2, little endian) with a count of that id's earlier use (2) (src/cpp/rtps/common/GuidUtils.hpp,
RTPSDomain.cpp). So the first 8 bytes are shared by every participant of one process, and differ between
processes.
"""

from __future__ import annotations

from dataclasses import dataclass

from rclpy.node import Node

from course_helpers.core.dds_config import GRAPH_TOPIC
from course_helpers.core.names import as_full_name, split_full_name
from course_helpers.core.waiting import wait_until

PREFIX_BYTES = 12  # a GUID prefix: the participant
PROCESS_BYTES = 8  # Fast DDS: vendor, host, process id, random; the same for a process's participants


@dataclass(frozen=True, order=True)
class Participant:
    """A DDS participant, named by its GUID prefix (12 bytes)."""

    prefix: bytes

    @property
    def process(self) -> bytes:
        """The part of the prefix that Fast DDS gives every participant of one process."""
        return self.prefix[:PROCESS_BYTES]

    @property
    def number(self) -> int:
        """The participant's id in its process: the lowest one free there when Fast DDS made it."""
        return int.from_bytes(self.prefix[PROCESS_BYTES:PROCESS_BYTES + 2], "little")

    def __str__(self) -> str:
        """``01.0f.78.fd.ec.1f.a7.0a | 01.00.00.00``: the process part, then the participant's part."""
        return " | ".join(".".join(f"{b:02x}" for b in part)
                          for part in (self.process, self.prefix[PROCESS_BYTES:]))


def participant_of_gid(gid) -> Participant:
    """The participant of an endpoint GID (bytes, or the list of ints rclpy gives as ``endpoint_gid``)."""
    return Participant(bytes(gid)[:PREFIX_BYTES])


def participant_of_node(graph: Node, fqn: str) -> Participant | None:
    """The participant of node ``fqn`` ('/talker'), from the GID of one of its endpoints as ``graph`` (any
    node) sees them; None while the graph lists no endpoint of it."""
    namespace, name = split_full_name(fqn)
    queries = ((graph.get_publisher_names_and_types_by_node, graph.get_publishers_info_by_topic),
               (graph.get_subscriber_names_and_types_by_node, graph.get_subscriptions_info_by_topic))
    for topics_of_node, endpoints_of_topic in queries:
        try:
            topics = topics_of_node(name, namespace)
        except Exception:  # rclpy's NodeNameNonExistentError: not (or no longer) in the graph
            return None
        for topic, _types in topics:
            for info in endpoints_of_topic(topic):
                if info.node_name == name and info.node_namespace == namespace:
                    return participant_of_gid(info.endpoint_gid)
    return None


def participant_of(rt, fqn: str, timeout: float = 10.0) -> Participant:
    """The participant of node ``fqn`` ('/talker') as the runtime ``rt``'s graph sees it; waits until the
    graph lists an endpoint of the node (woken by the graph's changes), ``timeout`` bounding a hang."""
    fqn = as_full_name(fqn)
    graph = rt.graph
    found: list[Participant] = []

    def listed() -> bool:
        participant = participant_of_node(graph, fqn)
        if participant is not None:
            found.append(participant)
        return participant is not None

    wait_until(listed, timeout, f"an endpoint of {fqn} in the graph")
    return found[-1]


def participants_in_graph(graph: Node) -> list[Participant]:
    """Every participant ``graph`` knows of, sorted: rmw gives each one writer of ``ros_discovery_info``
    (whose node name is unknown: it belongs to the participant, not to a node)."""
    infos = graph.get_publishers_info_by_topic(GRAPH_TOPIC, no_mangle=True)
    return sorted({participant_of_gid(info.endpoint_gid) for info in infos})


def participants_of_process(graph: Node, process: bytes) -> list[Participant]:
    """The participants in ``graph`` whose prefix starts with ``process`` (a :attr:`Participant.process`)."""
    return [p for p in participants_in_graph(graph) if p.process == process]
