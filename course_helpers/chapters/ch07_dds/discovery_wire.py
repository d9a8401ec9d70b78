"""Discovery on the wire (notebook 07b): one node starts, and its SPDP and SEDP messages are counted.

:func:`count_discovery` makes a private network namespace (:mod:`course_helpers.core.netns`),
captures its loopback (:mod:`course_helpers.core.rtps_capture`), starts an *observer* node, then
the *newcomer* (a talker), both course children on UDP only (with shared memory, Fast DDS would
carry discovery in memory, past any capture). It stops the capture once each side's ROS graph
shows the other: the observer lists every publisher, subscription, service and client of the
newcomer (so it has received all of the newcomer's endpoint announcements), and the newcomer lists
the observer (so the observer has received the newcomer's graph reader). Then it counts, in the
capture:

* **SPDP**, the participant announcements (DATA(p)) the newcomer sent, and to how many ports;
* **SEDP**, the endpoint announcements: the distinct endpoint GUIDs the newcomer announced in
  DATA(w) (writers) and DATA(r) (readers), whoever sent them on. Announcements repeat (a reliable
  writer resends, each peer gets its copy), so endpoints are counted, not datagrams.

rmw_fastrtps makes each ROS publisher and subscription one DDS writer or reader, each service one
request reader and one reply writer, each client one request writer and one reply reader, and
each participant one writer and one reader of ``ros_discovery_info`` (which node owns which
endpoint). So the newcomer announces exactly ``publishers + subscriptions + 2 x (services +
clients) + 2`` endpoints (:meth:`DiscoveryCount.expected`). The newcomer's process also holds the
course's hidden keeper node, which has no endpoints.

``setting='discovery server'`` starts eProsima's discovery server in the namespace first and makes
both nodes its clients (``ROS_DISCOVERY_SERVER``); the observer is a *super client*
(``ROS_SUPER_CLIENT=TRUE``, which ROS 2's command-line tools need to see everything), which the
server tells about every endpoint, not only those matching its own topics. Then the newcomer
announces itself to the server alone, and the observer learns the newcomer's endpoints from the
server.
"""

from __future__ import annotations

from dataclasses import dataclass

from rclpy.node import Node

from course_helpers.chapters.ch07_dds.server import READY_TEXT, SERVER_GROUP, _server_binary
from course_helpers.core import dds_config, netns, processes, rtps_capture
from course_helpers.core.channel import report
from course_helpers.core.errors import CourseError
from course_helpers.core.names import split_full_name
from course_helpers.core.rtps_capture import SEDP_PUBLICATIONS_WRITER, SEDP_SUBSCRIPTIONS_WRITER, SPDP_WRITER
from course_helpers.core.runtime import get_runtime
from course_helpers.core.waiting import poll_until
from course_helpers.nodes.chatter import Talker

SETTINGS = ("simple", "discovery server")
NAMESPACE_LABEL = "discovery_wire"
CAPTURE_LABEL = "discovery_wire_capture"
LABELS = {"observer": "discovery_wire_observer", "newcomer": "discovery_wire_newcomer",
          "server": "discovery_wire_server"}
OBSERVER, NEWCOMER = "/observer", "/newcomer"
SERVER_PORT = 11811  # Fast DDS's default discovery-server port (the namespace is private)
LOOK_PERIOD_S = 0.02  # s; how often each node looks at its graph
START_TIMEOUT_S = 20.0  # a child's start (Python, rclpy) and its discovery
GRAPH_ROLES = 2  # the writer and reader of ros_discovery_info, one pair per participant


def discovery_wire_unavailable_reason() -> str | None:
    """None if discovery can be captured here; else one line: what is missing and how to get it."""
    return rtps_capture.unavailable_reason() or netns.unavailable_reason()


def endpoint_counts(node: Node, fqn: str) -> dict | None:
    """What node ``fqn`` publishes, subscribes, serves and calls, as ``node``'s graph lists it (None
    while the graph does not know it)."""
    namespace, name = split_full_name(fqn)
    if (name, namespace) not in node.get_node_names_and_namespaces():
        return None
    try:
        return {"publishers": len(node.get_publisher_names_and_types_by_node(name, namespace)),
                "subscriptions": len(node.get_subscriber_names_and_types_by_node(name, namespace)),
                "services": len(node.get_service_names_and_types_by_node(name, namespace)),
                "clients": len(node.get_client_names_and_types_by_node(name, namespace))}
    except Exception:  # it left between the two questions
        return None


class DiscoveryObserver(Node):
    """Reports ``report('seen', ...)`` each time its graph's view of ``watched``'s endpoints changes."""

    def __init__(self, watched: str = NEWCOMER):
        super().__init__(OBSERVER[1:])
        self.watched = watched
        self.seen: dict | None = None
        gid = self.get_publishers_info_by_topic("/rosout")
        report("participant", prefix=next((bytes(i.endpoint_gid[:12]).hex() for i in gid
                                           if i.node_name == self.get_name()), ""))
        self.timer = self.create_timer(LOOK_PERIOD_S, self.look)

    def look(self) -> None:
        counts = endpoint_counts(self, self.watched)
        if counts is not None and counts != self.seen:
            self.seen = counts
            report("seen", **counts)


class Newcomer(Talker):
    """The node that starts: a talker that reports its own endpoints and participant (``'endpoints'``),
    then ``report('sees', ...)`` once its graph lists ``watched``."""

    def __init__(self, watched: str = OBSERVER):
        super().__init__(name=NEWCOMER[1:], rate_hz=10.0)
        self.watched = watched
        mine = self.get_publishers_info_by_topic(self.publisher.topic_name)
        prefix = next((bytes(i.endpoint_gid[:12]).hex() for i in mine if i.node_name == self.get_name()), "")
        report("endpoints", prefix=prefix, **endpoint_counts(self, self.get_fully_qualified_name()))
        self.watch = self.create_timer(LOOK_PERIOD_S, self.look)

    def look(self) -> None:
        if endpoint_counts(self, self.watched) is not None:
            self.watch.cancel()
            report("sees", node=self.watched)


@dataclass
class DiscoveryCount:
    """What one setting's capture showed (see the module docstring)."""

    setting: str
    node_endpoints: dict  # the newcomer's publishers, subscriptions, services, clients (its own graph)
    spdp_datagrams: int  # participant announcements the newcomer sent
    spdp_ports: int  # to how many distinct UDP ports
    writers: int  # distinct writer GUIDs the newcomer announced (DATA(w))
    readers: int  # distinct reader GUIDs (DATA(r))
    sedp_submessages: int  # the newcomer's DATA(w)/DATA(r) submessages, repeats included
    sent_to: list  # who the newcomer's SEDP went to: 'observer', 'discovery server'
    observer_heard_from: list  # who sent the observer the newcomer's endpoints
    capture_bytes: int

    @property
    def expected(self) -> int:
        """Endpoints the newcomer's participant has: its node's, plus the ros_discovery_info pair."""
        n = self.node_endpoints
        return n["publishers"] + n["subscriptions"] + 2 * (n["services"] + n["clients"]) + GRAPH_ROLES

    @property
    def announced(self) -> int:
        """Distinct endpoints the newcomer announced."""
        return self.writers + self.readers

    def row(self) -> str:
        return (f"{self.setting:<17}{self.spdp_datagrams:>6} to {self.spdp_ports:>2} ports   "
                f"{self.writers:>3} + {self.readers:<3} = {self.announced:<5}{self.expected:<10}"
                f"{', '.join(self.sent_to):<18}{', '.join(self.observer_heard_from)}")


def discovery_table(counts: list[DiscoveryCount]) -> str:
    """A text table of :func:`count_discovery` results, one row per setting."""
    head = (f"{'setting':<17}{'SPDP (DATA(p))':<20}{'SEDP w + r':<17}{'expected':<10}"
            f"{'SEDP sent to':<18}observer heard from")
    return "\n".join([head, *(c.row() for c in counts)])


def count_discovery(setting: str = "simple") -> DiscoveryCount:
    """Start a newcomer beside an observer in a private namespace, capture, and count (module docstring).

    Everything it started (capture, nodes, server, namespace) is stopped before it returns. Raises
    CourseError with the one-line reason where namespaces or tshark are missing.
    """
    if setting not in SETTINGS:
        raise CourseError(f"setting must be one of {', '.join(map(repr, SETTINGS))}, got {setting!r}")
    reason = discovery_wire_unavailable_reason()
    if reason is not None:
        raise CourseError(f"counting discovery on the wire needs tshark and a network namespace: {reason}")
    rt = get_runtime()  # its domain is the children's: they inherit ROS_DOMAIN_ID
    env = {**dds_config.udp_loopback_env(rt.log_dir), "ROS_DOMAIN_ID": str(rt.domain.domain_id)}
    namespace = netns.create(NAMESPACE_LABEL)
    capture = None
    try:
        observer_env = env
        if setting == "discovery server":
            _start_server(namespace)
            env = {**env, "ROS_DISCOVERY_SERVER": f"127.0.0.1:{SERVER_PORT}"}
            observer_env = {**env, "ROS_SUPER_CLIENT": "TRUE"}
        capture = rtps_capture.start_capture(namespace, CAPTURE_LABEL)
        observer = namespace.start(LABELS["observer"], processes.python_target_argv(DiscoveryObserver),
                                   env=observer_env)
        observer.wait_for_report("ready", START_TIMEOUT_S, "the observer node")
        newcomer = namespace.start(LABELS["newcomer"], processes.python_target_argv(Newcomer), env=env)
        mine = newcomer.wait_for_report("endpoints", START_TIMEOUT_S, "the newcomer's endpoints")
        own = {k: v for k, v in mine.items() if k != "prefix"}

        def both_know() -> bool:
            return observer.last("seen") == own and newcomer.last("sees") is not None

        if not poll_until(lambda: both_know() or not (observer.alive and newcomer.alive), START_TIMEOUT_S) \
                or not both_know():
            raise CourseError(f"the observer and the newcomer did not discover each other within "
                              f"{START_TIMEOUT_S:g} s ({setting}); the observer saw {observer.last('seen')}")
        capture.stop()
        prefixes = {mine["prefix"]: "newcomer",
                    (observer.last("participant") or {}).get("prefix", ""): "observer"}
    finally:
        processes.stop(list(LABELS.values()))
        processes.stop([LABELS["server"]], group=SERVER_GROUP)
        if capture is not None:
            capture.stop()
        namespace.close()
    return _counted(setting, own, mine["prefix"], prefixes, capture)


def _start_server(namespace: netns.NetworkNamespace) -> None:
    profile = dds_config.discovery_server_profile(processes.log_dir(), dds_config.LEASE_S)
    argv = processes.program_argv(_server_binary(), "-i", "0", "-l", "127.0.0.1", "-p", str(SERVER_PORT),
                                  "-x", profile)
    server = namespace.start(LABELS["server"], argv, group=SERVER_GROUP, channel=False)
    if not poll_until(lambda: READY_TEXT in server.log() or not server.alive, START_TIMEOUT_S) \
            or READY_TEXT not in server.log():
        raise CourseError(f"the discovery server did not start in the namespace: {server.output_tail(600)}")


def _counted(setting: str, own: dict, prefix: str, roles: dict, capture) -> DiscoveryCount:
    records = capture.submessages()
    spdp = [s for s in records if s.src == prefix and s.kind == "DATA" and s.alive
            and s.writer == SPDP_WRITER]
    sedp = [s for s in records if s.kind == "DATA" and s.alive and s.endpoint.startswith(prefix)
            and s.writer in (SEDP_PUBLICATIONS_WRITER, SEDP_SUBSCRIPTIONS_WRITER)]
    announced = [s for s in sedp if s.src == prefix]

    def role(guid_prefix: str) -> str:  # a message without INFO_DST is for every participant
        return roles.get(guid_prefix, "discovery server") if guid_prefix else "everyone"

    return DiscoveryCount(
        setting=setting, node_endpoints=own, spdp_datagrams=len(spdp),
        spdp_ports=len({s.dst_port for s in spdp}),
        writers=len({s.endpoint for s in announced if s.writer == SEDP_PUBLICATIONS_WRITER}),
        readers=len({s.endpoint for s in announced if s.writer == SEDP_SUBSCRIPTIONS_WRITER}),
        sedp_submessages=len(announced), sent_to=sorted({role(s.dst) for s in announced if s.dst}),
        observer_heard_from=sorted({role(s.src) for s in sedp if role(s.dst) in ("observer", "everyone")}),
        capture_bytes=capture.size_bytes)
