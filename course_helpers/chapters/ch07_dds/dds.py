"""DDS and discovery, measured on the live system (chapter 07).

* :func:`compare_models` / :func:`plot_models` / :func:`center_failure_table` - the
  peer-to-peer, broker, broadcast and DDS-databus models, routed message by message for a
  growing number of nodes (connections, copies handled by the busiest process, irrelevant
  deliveries, and what survives when the busiest process fails);
* :func:`reserve_spare_domain` / :func:`nodes_in_domain` - a second ROS domain no other course
  kernel uses, and a short-lived participant that lists the nodes of any domain;
* :func:`measure_discovery` - how long a new process takes to find the kernel's node (child
  processes; each reports its own timings);
* :class:`DiscoveryServer` / :func:`start_discovery_server` - eProsima's discovery server
  started from the notebook, stopped and reaped when asked, on re-run and at exit;
* :func:`dds_entities` / :func:`guid_prefix` / :func:`guid_process_id` - ROS names as the DDS
  topics and types they become (the ``rt/``, ``rq/``, ``rr/`` prefixes), and what a GUID says;
* :func:`middleware_report` - the active RMW implementation and the ones installed;
* :func:`measure_transports` / :func:`plot_transports` - one large message bounced between two
  nodes in one process (intra-process), two processes over shared memory, and over UDP;
* :func:`try_secure_node` - what Fast DDS says when asked to enable DDS security.

Child-process targets (``make_printing_listener``, ``discovery_probe``, ``make_pong``,
``run_ping``, ``secure_node_attempt``) are importable here so ``rt.spawn`` can start them.
"""

from __future__ import annotations

import atexit
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

from course_helpers.core.domains import reserve_domain
from course_helpers.core.errors import CourseError, WaitTimeout

RESULT_TAG = "DDS_RESULT "  # child targets print one line 'DDS_RESULT {json}'


# ====================================================================== communication models
MODELS = {
    "peer_to_peer": "peer to peer: every sender keeps a connection to every receiver it knows",
    "broker": "broker: everybody connects to one central broker that forwards each message",
    "broadcast": "broadcast: one shared channel, everybody receives everything",
    "dds_databus": "DDS databus: discovery matches each writer with the readers of its topic",
}


@dataclass
class ModelResult:
    """What one communication model costs for ``nodes`` nodes (each publishes one topic)."""

    model: str
    nodes: int
    interested: int  # receivers per topic
    connections: int  # point-to-point links (a shared channel counts as one)
    addresses_to_configure: int  # addresses someone must write into a configuration
    transmissions: int  # message copies sent per round (every node publishes once)
    busiest_load: int  # copies sent + received by the busiest process in one round
    irrelevant: int  # copies received by nodes that did not want them
    delivered: int  # wanted copies that arrived
    wanted: int  # wanted copies in total


def _interested_in(publisher: int, nodes: int, interested: int) -> list[int]:
    """The receivers of ``publisher``'s topic: the next ``interested`` nodes round the ring."""
    return [(publisher + step) % nodes for step in range(1, interested + 1)]


def simulate_model(model: str, nodes: int, interested: int = 2, failed: int | None = None) -> ModelResult:
    """Route one round of messages (every node publishes once) through ``model``; count the copies.

    Node ``i`` publishes topic ``i``, wanted by the next ``interested`` nodes. ``failed`` names a
    process that is down: a node index, or ``-1`` for the central broker. Nothing is estimated:
    each copy is routed and counted.
    """
    if model not in MODELS:
        raise CourseError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    if isinstance(nodes, bool) or not isinstance(nodes, int) or nodes < 2:
        raise CourseError(f"nodes must be a whole number >= 2, got {nodes!r}")
    if not 1 <= interested < nodes:
        raise CourseError(f"interested must be 1..{nodes - 1} (receivers per topic), got {interested!r}")
    broker = -1
    load: dict[int, int] = {}
    sent = irrelevant = delivered = 0

    def copy(sender: int, receiver: int) -> bool:
        nonlocal sent
        if failed in (sender, receiver):
            return False
        sent += 1
        load[sender] = load.get(sender, 0) + 1
        load[receiver] = load.get(receiver, 0) + 1
        return True

    for publisher in range(nodes):
        wanted_by = set(_interested_in(publisher, nodes, interested))
        if model in ("peer_to_peer", "dds_databus"):
            delivered += sum(copy(publisher, receiver) for receiver in sorted(wanted_by))
        elif model == "broker":
            if copy(publisher, broker):
                delivered += sum(copy(broker, receiver) for receiver in sorted(wanted_by))
        else:  # broadcast: one send on the shared channel, every other node receives it
            if failed == publisher:
                continue
            sent += 1
            load[publisher] = load.get(publisher, 0) + 1
            for receiver in range(nodes):
                if receiver in (publisher, failed):
                    continue
                load[receiver] = load.get(receiver, 0) + 1
                if receiver in wanted_by:
                    delivered += 1
                else:
                    irrelevant += 1
    pairs = nodes * interested
    connections = {"peer_to_peer": pairs, "dds_databus": pairs, "broker": nodes, "broadcast": 1}[model]
    addresses = {"peer_to_peer": pairs, "broker": nodes, "broadcast": 0, "dds_databus": 0}[model]
    return ModelResult(model, nodes, interested, connections, addresses, sent,
                       max(load.values(), default=0), irrelevant, delivered, pairs)


def compare_models(node_counts=(4, 8, 16, 32, 64), interested: int = 2) -> list[ModelResult]:
    """:func:`simulate_model` for every model and node count."""
    return [simulate_model(model, n, interested) for model in MODELS for n in node_counts]


def busiest_process(model: str) -> int:
    """The process that handles the most copies (-1 is the broker)."""
    return -1 if model == "broker" else 0  # in the other models every node carries the same load


def center_failure_table(nodes: int = 10, interested: int = 2) -> list[dict]:
    """For each model: share of wanted messages still delivered when its busiest process fails."""
    rows = []
    for model in MODELS:
        down = busiest_process(model)
        result = simulate_model(model, nodes, interested, failed=down)
        rows.append({"model": model, "failed": "the broker" if down == -1 else f"node {down}",
                     "delivered": result.delivered, "wanted": result.wanted,
                     "share": result.delivered / result.wanted})
    return rows


def plot_models(results: list[ModelResult]):
    """Three panels against the number of nodes: connections, busiest process, irrelevant copies."""
    import matplotlib.pyplot as plt

    styles = {"peer_to_peer": ("#2563eb", "o"), "broker": ("#dc2626", "s"),
              "broadcast": ("#d97706", "^"), "dds_databus": ("#16a34a", "D")}
    panels = [("connections", "point-to-point connections"),
              ("busiest_load", "copies handled by the busiest process\n(one round)"),
              ("irrelevant", "copies delivered to nodes\nthat did not want them")]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for ax, (attr, title) in zip(axes, panels, strict=True):
        for model, (colour, marker) in styles.items():
            rows = sorted((r for r in results if r.model == model), key=lambda r: r.nodes)
            dashed = model == "dds_databus"  # it coincides with peer to peer in the first panel
            ax.plot([r.nodes for r in rows], [getattr(r, attr) for r in rows], marker=marker,
                    color=colour, label=model.replace("_", " "), linewidth=1.5, markersize=4,
                    linestyle="--" if dashed else "-")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("nodes")
        ax.set_xscale("log", base=2)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    interested = results[0].interested if results else 0
    fig.suptitle(f"Four communication models, each node publishing one topic wanted by {interested} "
                 "others", fontsize=11)
    fig.tight_layout()
    return fig


# ====================================================================== domains
_spare_domains: list[int] = []  # the spare domain, once reserved


def reserve_spare_domain() -> int:
    """A second ROS domain for this kernel, reserved like the kernel's own (no other course kernel uses it).

    Re-running returns the same domain. The reservation is a lock file the operating system
    releases when the kernel exits.
    """
    if not _spare_domains:
        own = int(os.environ.get("ROS_DOMAIN_ID", "-1") or -1)
        _spare_domains.append(reserve_domain(exclude=(own,)))
    return _spare_domains[0]


def nodes_in_domain(domain_id: int, wait_s: float = 1.5, expect: list[str] | tuple = ()) -> list[str]:
    """Full names of the nodes visible in ``domain_id``, seen by a short-lived participant.

    Waits ``wait_s`` seconds for discovery (less if every name in ``expect`` shows up first).
    The probe's own node is hidden (its name starts with '_') and left out.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    from course_helpers.core.domains import parse_domain_id

    domain_id = parse_domain_id(domain_id)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        probe = Node("_domain_probe", context=context, enable_rosout=False,
                     start_parameter_services=False)
        try:
            deadline = time.monotonic() + wait_s
            names: list[str] = []
            while time.monotonic() < deadline:
                names = sorted(ns.rstrip("/") + "/" + name
                               for name, ns in probe.get_node_names_and_namespaces()
                               if not name.startswith("_"))
                if expect and all(e in names for e in expect):
                    break
                time.sleep(0.05)
            return names
        finally:
            probe.destroy_node()
    finally:
        context.try_shutdown()


def make_printing_listener(name: str = "listener", topic: str = "chatter") -> object:
    """Child-process target: a String listener that prints 'heard: <data>' for every message."""
    from rclpy.node import Node
    from std_msgs.msg import String

    node = Node(name)
    node.subscription = node.create_subscription(
        String, topic, lambda msg: print(f"heard: {msg.data}", flush=True), 10)
    return node


def heard_lines(child) -> list[str]:
    """What a :func:`make_printing_listener` child has heard so far, in order."""
    return [line[len("heard: "):] for line in child.log().splitlines() if line.startswith("heard: ")]


# ====================================================================== discovery timing
ANCHOR_NODE = "discovery_anchor"
ANCHOR_TOPIC = "discovery_beacon"
PROBE_TOPIC = "discovery_echo"


@dataclass
class DiscoveryTiming:
    """Seconds from the start of a new process's first node until it found the kernel (None: never)."""

    create_node_s: float  # creating the node, which creates the DDS participant
    sees_node_s: float | None  # the kernel's anchor node appears in the child's graph
    reader_matched_s: float | None  # the child's subscription matched the kernel's publisher
    writer_matched_s: float | None  # the child's publisher matched the kernel's subscription
    first_message_s: float | None  # first message from the kernel arrived

    @property
    def found(self) -> bool:
        return self.reader_matched_s is not None and self.sees_node_s is not None


def discovery_probe(timeout_s: float = 5.0) -> None:
    """Child-process target: time how long this new participant takes to find the kernel's anchor.

    Prints one ``DDS_RESULT {json}`` line and exits. All times are measured inside the child,
    from just before its first node (and so its DDS participant) is created.
    """
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String

    marks: dict[str, float] = {}
    start = time.perf_counter()

    def mark(key):
        marks.setdefault(key, time.perf_counter() - start)

    node = Node("discovery_probe")
    mark("create_node_s")
    node.create_subscription(
        String, ANCHOR_TOPIC, lambda _msg: mark("first_message_s"), 10,
        event_callbacks=SubscriptionEventCallbacks(matched=lambda _s: mark("reader_matched_s")))
    node.create_publisher(
        String, PROBE_TOPIC, 10,
        event_callbacks=PublisherEventCallbacks(matched=lambda _s: mark("writer_matched_s")))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    keys = ("sees_node_s", "reader_matched_s", "writer_matched_s", "first_message_s")
    while time.perf_counter() - start < timeout_s and not all(k in marks for k in keys):
        executor.spin_once(timeout_sec=0.002)
        if "sees_node_s" not in marks and ANCHOR_NODE in node.get_node_names():
            mark("sees_node_s")
    print(RESULT_TAG + json.dumps({k: marks.get(k) for k in ("create_node_s",) + keys}), flush=True)
    executor.shutdown(timeout_sec=0.5)
    node.destroy_node()


def start_discovery_anchor(rt):
    """The kernel's side of :func:`measure_discovery`: a node publishing a beacon at 50 Hz."""
    from std_msgs.msg import String

    anchor = rt.node(ANCHOR_NODE, console=False)
    publisher = anchor.create_publisher(String, ANCHOR_TOPIC, 10)
    anchor.create_subscription(String, PROBE_TOPIC, lambda _msg: None, 10)
    anchor.create_timer(0.02, lambda: publisher.publish(String(data="beacon")))
    return anchor


def run_child_for_result(rt, label: str, target: str, params: dict | None = None,
                         env: dict | None = None, timeout: float = 30.0) -> dict:
    """Start a child target that prints one ``DDS_RESULT`` line and exits; return that JSON."""
    child = rt.spawn(label, target, params=params or {}, env=env)
    try:
        rt.wait_until(lambda: not child.alive, timeout, f"child {label} to finish")
    except WaitTimeout:
        rt.stop_child(label)
        raise
    for line in child.log().splitlines():
        if line.startswith(RESULT_TAG):
            rt.stop_child(label)
            return json.loads(line[len(RESULT_TAG):])
    rt.stop_child(label)
    raise CourseError(f"child {label} printed no result. Its output:\n{child.log()[-1500:]}")


def measure_discovery(rt, repeats: int = 3, env: dict | None = None,
                      timeout_s: float = 5.0) -> list[DiscoveryTiming]:
    """Start ``repeats`` fresh processes one after the other; each times how it finds the kernel.

    ``env`` changes the children's environment (e.g. ``{'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}``).
    A child that never finds the kernel within ``timeout_s`` reports None for those steps.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 1 <= repeats <= 20:
        raise CourseError(f"repeats must be a whole number 1..20, got {repeats!r}")
    start_discovery_anchor(rt)
    timings = []
    for _ in range(repeats):
        result = run_child_for_result(rt, "discovery_probe", "course_helpers.chapters.ch07_dds.dds:discovery_probe",
                                      {"timeout_s": timeout_s}, env, timeout=timeout_s + 20)
        timings.append(DiscoveryTiming(**result))
    rt.remove("/" + ANCHOR_NODE)
    return timings


def summarize_discovery(timings: list[DiscoveryTiming]) -> dict[str, float | None]:
    """Median of each step over the runs that found the kernel (None if none did)."""
    found = [t for t in timings if t.found]
    summary = {}
    for key in ("create_node_s", "sees_node_s", "reader_matched_s", "writer_matched_s", "first_message_s"):
        values = [getattr(t, key) for t in found if getattr(t, key) is not None]
        summary[key] = statistics.median(values) if values else None
    return summary


# ====================================================================== discovery server
SERVER_BINARY = "fast-discovery-server"


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that nothing is bound to right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _server_binary() -> str:
    path = os.path.join(os.path.dirname(sys.executable), SERVER_BINARY)
    if not os.path.exists(path):
        raise CourseError(f"{path} is missing: the Fast DDS wheel ships it; run `make lab` again")
    return path


_PDEATHSIG_EXEC = (
    "import ctypes, os, signal, sys\n"
    "ctypes.CDLL('libc.so.6').prctl(1, signal.SIGTERM)\n"
    "if os.getppid() != int(sys.argv[1]): sys.exit(0)\n"
    "os.execv(sys.argv[2], sys.argv[2:])\n"
)


@dataclass
class DiscoveryServer:
    """A running ``fast-discovery-server`` process listening on 127.0.0.1:``port``."""

    port: int
    process: subprocess.Popen
    log_path: str
    started: float = field(default_factory=time.monotonic)
    final_output: str | None = None  # kept when the log file is removed at stop()

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    @property
    def pid(self) -> int:
        return self.process.pid

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def client_env(self) -> dict:
        """Environment that makes a process a client of this server (server ID 0)."""
        return {"ROS_DISCOVERY_SERVER": self.address}

    def output(self) -> str:
        """What the server printed."""
        if self.final_output is not None:
            return self.final_output
        try:
            with open(self.log_path, encoding="utf-8", errors="replace") as handle:
                return handle.read()
        except OSError:
            return ""

    def stop(self) -> int:
        """Stop the server (SIGTERM, then SIGKILL) and reap it; returns its exit code."""
        if self.alive:
            self.process.terminate()
            try:
                self.process.wait(timeout=3)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=5)
        if self.final_output is None:
            self.final_output = self.output()
            try:
                os.remove(self.log_path)
            except OSError:
                pass
        if _servers.get(self.port) is self:
            del _servers[self.port]
        return self.process.returncode

    def __repr__(self) -> str:
        state = "running" if self.alive else f"exited {self.process.returncode}"
        return f"<DiscoveryServer {self.address} {state}>"


_servers: dict[int, DiscoveryServer] = {}


def start_discovery_server(port: int | None = None, timeout: float = 5.0) -> DiscoveryServer:
    """Start eProsima's discovery server on 127.0.0.1 (a free port unless given); re-run safe.

    A server this kernel started earlier is stopped first. The server process ends with the
    kernel, and :func:`stop_discovery_servers` (also run at exit) reaps it.
    """
    stop_discovery_servers()
    port = free_udp_port() if port is None else int(port)
    if not 1024 <= port <= 65535:
        raise CourseError(f"port must be 1024..65535, got {port}")
    log_path = os.path.join(tempfile.gettempdir(), f"discovery-server-{os.getpid()}-{port}.log")
    command = [_server_binary(), "-i", "0", "-l", "127.0.0.1", "-p", str(port)]
    with open(log_path, "wb") as log:
        process = subprocess.Popen(
            [sys.executable, "-c", _PDEATHSIG_EXEC, str(os.getpid()), *command],
            stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    server = DiscoveryServer(port, process, log_path)
    _servers[port] = server
    deadline = time.monotonic() + timeout
    while "Server is running" not in server.output():
        if not server.alive or time.monotonic() > deadline:
            server.stop()
            raise CourseError(f"the discovery server did not start. Its output:\n{server.output()[-1500:]}")
        time.sleep(0.02)
    return server


def stop_discovery_servers() -> None:
    """Stop and reap every discovery server this kernel started."""
    for server in list(_servers.values()):
        server.stop()


atexit.register(stop_discovery_servers)


# ====================================================================== ROS names as DDS names
PREFIXES = {
    "rt": "topic",
    "rq": "service request",
    "rr": "service reply",
    "rs": "service (unused by Fast DDS)",
    "rp": "parameter (reserved)",
    "ra": "action (reserved)",
}


@dataclass
class DdsEntity:
    """One DDS topic in the graph and the ROS name it comes from."""

    dds_topic: str
    dds_type: str
    prefix: str
    meaning: str
    ros_name: str
    ros_type: str


def ros_type_from_dds(dds_type: str) -> str:
    """'std_msgs::msg::dds_::String_' -> 'std_msgs/msg/String' (services: Request_/Response_ dropped)."""
    parts = dds_type.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        name = parts[3][:-1]
        for suffix in ("_Request", "_Response"):
            if name.endswith(suffix):
                name = name[: -len(suffix)]
        return f"{parts[0]}/{parts[1]}/{name}"
    return dds_type


def ros_name_from_dds(dds_topic: str) -> tuple[str, str, str]:
    """Split a DDS topic name into (prefix, meaning, ROS name); unprefixed names are not ROS topics."""
    head, _, rest = dds_topic.partition("/")
    if head in PREFIXES and rest:
        name = "/" + rest
        if head == "rq" and name.endswith("Request"):
            name = name[: -len("Request")]
        elif head == "rr" and name.endswith("Reply"):
            name = name[: -len("Reply")]
        return head, PREFIXES[head], name
    return "", "the middleware's own topic, not a ROS name", dds_topic


def dds_entities(rt, contains: str = "", include_hidden: bool = False) -> list[DdsEntity]:
    """The DDS topics in this domain (raw, un-demangled names), each with the ROS name it carries.

    ``contains`` keeps only DDS names containing that text; hidden ROS names (a token starting
    with '_', such as the course runtime's own services) are left out unless asked for.
    """
    rows = []
    for dds_topic, types in rt.graph.get_topic_names_and_types(no_demangle=True):
        if contains and contains not in dds_topic:
            continue
        prefix, meaning, ros_name = ros_name_from_dds(dds_topic)
        if not include_hidden and any(token.startswith("_") for token in ros_name.split("/")):
            continue
        for dds_type in types:
            rows.append(DdsEntity(dds_topic, dds_type, prefix, meaning, ros_name,
                                  ros_type_from_dds(dds_type)))
    return sorted(rows, key=lambda r: (r.dds_topic, r.dds_type))


def show_dds_entities(rows: list[DdsEntity]) -> None:
    """Print :func:`dds_entities` as an aligned table."""
    width = max([len(r.dds_topic) for r in rows] + [9])
    type_width = max([len(r.dds_type) for r in rows] + [8])
    print(f"{'DDS topic':<{width}}  {'DDS type':<{type_width}}  ROS name (meaning)")
    for r in rows:
        print(f"{r.dds_topic:<{width}}  {r.dds_type:<{type_width}}  {r.ros_name} ({r.meaning})")


def guid_prefix(gid) -> str:
    """The participant part (first 12 bytes) of an endpoint GUID, as dotted hex."""
    return ".".join(f"{b:02x}" for b in bytes(gid)[:12])


def guid_process_id(gid) -> int:
    """The (low 16 bits of the) process ID that Fast DDS writes into bytes 4-5 of a GUID prefix."""
    raw = bytes(gid)
    return raw[4] | (raw[5] << 8)


def guid_vendor(gid) -> str:
    """The DDS vendor in the first two bytes of a GUID (01.0f is eProsima)."""
    raw = bytes(gid)
    vendors = {(1, 15): "eProsima Fast DDS", (1, 16): "Eclipse Cyclone DDS", (1, 1): "RTI Connext DDS"}
    return vendors.get((raw[0], raw[1]), f"vendor {raw[0]:02x}.{raw[1]:02x}")


# ====================================================================== middleware
def installed_rmw_implementations() -> list[str]:
    """The rmw implementations whose libraries are installed in this environment."""
    lib = os.path.join(sys.prefix, "lib")
    found = set()
    for name in os.listdir(lib) if os.path.isdir(lib) else []:
        if name.startswith("librmw_") and name.endswith(".so"):
            impl = name[len("lib"):-len(".so")]
            if not impl.endswith(("_shared_cpp", "_common")) and "dds_common" not in impl \
                    and impl not in ("rmw_implementation",):
                found.add(impl)
    return sorted(found)


def middleware_report() -> dict:
    """Active rmw implementation, what RMW_IMPLEMENTATION says, what is installed, Fast DDS version."""
    import rclpy

    from course_helpers.chapters.ch01_architecture import package_version

    return {
        "active": rclpy.get_rmw_implementation_identifier(),
        "RMW_IMPLEMENTATION": os.environ.get("RMW_IMPLEMENTATION", "(not set: the default is used)"),
        "installed": installed_rmw_implementations(),
        "Fast DDS": package_version("ros-fastrtps"),
    }


# ====================================================================== transports
TRANSPORT_LABELS = {
    "intra-process": "both nodes in one process: Fast DDS hands the sample over in memory",
    "shared memory": "two processes on one machine: Fast DDS's default between local processes",
    "UDP": "two processes, UDP through the loopback interface (as between two machines)",
}
_TRANSPORT_QOS_DEPTH = 10


def _reliable_qos():
    from rclpy.qos import QoSProfile, QoSReliabilityPolicy

    return QoSProfile(depth=_TRANSPORT_QOS_DEPTH, reliability=QoSReliabilityPolicy.RELIABLE)


def make_pong(name: str = "pong"):
    """Child-process target: a node that sends every ``ping`` message straight back on ``pong``."""
    from rclpy.node import Node
    from std_msgs.msg import UInt8MultiArray

    node = Node(name)
    node.echo = node.create_publisher(UInt8MultiArray, "pong", _reliable_qos())
    node.subscription = node.create_subscription(UInt8MultiArray, "ping", node.echo.publish, _reliable_qos())
    return node


def run_ping(sizes: list[int], round_trips: int = 10, with_pong: bool = False,
             timeout_s: float = 15.0) -> None:
    """Child-process target: bounce messages of each size off a pong node; print the round trips.

    With ``with_pong`` the pong node runs in this same process (intra-process delivery).
    Prints ``DDS_RESULT {"<size>": [round-trip seconds, ...], ...}`` and exits.
    """
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import UInt8MultiArray

    node = Node("ping")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    if with_pong:
        executor.add_node(make_pong())
    arrivals: list[float] = []
    node.create_subscription(UInt8MultiArray, "pong", lambda _m: arrivals.append(time.perf_counter()),
                             _reliable_qos())
    publisher = node.create_publisher(UInt8MultiArray, "ping", _reliable_qos())
    start = time.monotonic()
    while publisher.get_subscription_count() == 0 or node.count_publishers("pong") == 0:
        executor.spin_once(timeout_sec=0.02)
        if time.monotonic() - start > timeout_s:
            raise SystemExit("no pong node found")
    warm = UInt8MultiArray(data=bytes(16))
    for _ in range(20):  # until the pong's publisher has matched our subscription too
        arrivals.clear()
        publisher.publish(warm)
        end = time.monotonic() + 0.5
        while not arrivals and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
        if arrivals:
            break
    results: dict[str, list[float]] = {}
    for size in sizes:
        message = UInt8MultiArray(data=bytes(size))
        times = []
        for i in range(round_trips + 1):  # the first of each size warms buffers up, not counted
            arrivals.clear()
            sent = time.perf_counter()
            publisher.publish(message)
            while not arrivals and time.perf_counter() - sent < timeout_s:
                executor.spin_once(timeout_sec=0.5)
            if arrivals and i > 0:
                times.append(arrivals[0] - sent)
        results[str(size)] = times
    print(RESULT_TAG + json.dumps(results), flush=True)
    executor.shutdown(timeout_sec=0.5)


def _udp_env(rt) -> dict:
    """Environment for a child whose samples cross the loopback network (see the QoS lab's engine)."""
    from course_helpers.chapters.ch08b_lab.engine import transport_env

    return transport_env("udp", rt.log_dir)


@dataclass
class TransportResult:
    """Round-trip times (seconds) per transport and message size."""

    sizes: list[int]
    round_trips: dict[str, dict[int, list[float]]]

    def one_way_ms(self, transport: str, size: int) -> float:
        """Median round trip / 2, in milliseconds."""
        return statistics.median(self.round_trips[transport][size]) / 2 * 1e3

    def throughput_mb_s(self, transport: str, size: int) -> float:
        """Megabytes per second if messages of ``size`` followed each other at the one-way latency."""
        return size / (self.one_way_ms(transport, size) / 1e3) / 1e6


def measure_transports(rt, sizes=(1_000, 100_000, 500_000, 2_000_000), round_trips: int = 10,
                       transports=tuple(TRANSPORT_LABELS)) -> TransportResult:
    """Bounce messages of each size between a ping and a pong node; all nodes run in child processes.

    'intra-process': ping and pong in one child. 'shared memory': two children with the kernel's
    settings. 'UDP': two children restricted to UDP on 127.0.0.1. Reliable QoS, so every round
    trip completes (a lost fragment is resent).
    """
    sizes = [int(s) for s in sizes]
    if not sizes or any(not 1 <= s <= 8_000_000 for s in sizes):
        raise CourseError(f"sizes must be 1 byte .. 8 MB, got {sizes}")
    if isinstance(round_trips, bool) or not isinstance(round_trips, int) or not 1 <= round_trips <= 200:
        raise CourseError(f"round_trips must be a whole number 1..200, got {round_trips!r}")
    unknown = [t for t in transports if t not in TRANSPORT_LABELS]
    if unknown:
        raise CourseError(f"unknown transport(s) {unknown}; choose from {list(TRANSPORT_LABELS)}")
    params = {"sizes": sizes, "round_trips": round_trips}
    out: dict[str, dict[int, list[float]]] = {}
    for transport in transports:
        if transport == "intra-process":
            result = run_child_for_result(rt, "ping", "course_helpers.chapters.ch07_dds.dds:run_ping",
                                          {**params, "with_pong": True}, timeout=120)
        else:
            env = _udp_env(rt) if transport == "UDP" else {}
            rt.spawn("pong", "course_helpers.chapters.ch07_dds.dds:make_pong", env=env, wait_for="/pong")
            try:
                result = run_child_for_result(rt, "ping", "course_helpers.chapters.ch07_dds.dds:run_ping", params, env,
                                              timeout=120)
            finally:
                rt.stop_child("pong")
        out[transport] = {int(size): times for size, times in result.items()}
        missing = [s for s in sizes if not out[transport].get(s)]
        if missing:
            raise CourseError(f"{transport}: no round trip completed for sizes {missing}")
    return TransportResult(sizes, out)


def plot_transports(result: TransportResult):
    """Left: one-way latency against message size (log-log). Right: throughput at each size."""
    import matplotlib.pyplot as plt

    colours = {"intra-process": "#16a34a", "shared memory": "#2563eb", "UDP": "#dc2626"}
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 3.8))
    for transport in result.round_trips:
        ms = [result.one_way_ms(transport, s) for s in result.sizes]
        left.plot(result.sizes, ms, marker="o", color=colours.get(transport), label=transport)
    left.set_xscale("log")
    left.set_yscale("log")
    left.set_xlabel("message size (bytes)")
    left.set_ylabel("one-way latency (ms, median)")
    left.set_title("latency: round trip / 2", fontsize=10)
    left.grid(alpha=0.3, which="both")
    left.legend(fontsize=8)
    width = 0.8 / max(len(result.round_trips), 1)
    for i, transport in enumerate(result.round_trips):
        values = [result.throughput_mb_s(transport, s) for s in result.sizes]
        positions = [j + (i - (len(result.round_trips) - 1) / 2) * width for j in range(len(result.sizes))]
        right.bar(positions, values, width=width, color=colours.get(transport), label=transport)
    right.set_xticks(range(len(result.sizes)), [_human_size(s) for s in result.sizes])
    right.set_xlabel("message size")
    right.set_ylabel("MB/s (size / one-way latency)")
    right.set_title("throughput one message at a time", fontsize=10)
    right.grid(alpha=0.3, axis="y")
    fig.suptitle("The same message, three ways between two nodes (reliable QoS, measured now)", fontsize=11)
    fig.tight_layout()
    return fig


def _human_size(n: int) -> str:
    for unit, scale in (("MB", 1_000_000), ("kB", 1_000)):
        if n >= scale:
            return f"{n / scale:g} {unit}"
    return f"{n} B"


# ====================================================================== security
def secure_node_attempt() -> None:
    """Child-process target: try to create a node with DDS security enforced; print what happened."""
    from rclpy.node import Node

    try:
        node = Node("secure_talker")
    except Exception as exc:  # the middleware refuses: report its words
        print(RESULT_TAG + json.dumps({"created": False, "error": str(exc)}), flush=True)
        return
    node.destroy_node()
    print(RESULT_TAG + json.dumps({"created": True, "error": ""}), flush=True)


def try_secure_node(rt) -> dict:
    """Ask for DDS security (SROS2 environment variables, an empty keystore) in a child process.

    Returns ``{'created': bool, 'error': first line of the middleware's error}``. With the Fast
    DDS built into these wheels the answer is that the security plugins are not compiled in.
    """
    keystore = os.path.join(rt.log_dir, "empty_keystore")
    os.makedirs(os.path.join(keystore, "enclaves"), exist_ok=True)
    env = {"ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce",
           "ROS_SECURITY_KEYSTORE": keystore}
    result = run_child_for_result(rt, "secure_node", "course_helpers.chapters.ch07_dds.dds:secure_node_attempt", env=env)
    result["error"] = result["error"].splitlines()[0] if result["error"] else ""
    return result
