"""Chapter 01 (architecture): the ROS 2 layers of this very process, and the "no master" demo.

* :func:`layer_stack` / :func:`show_layer_stack` / :func:`draw_layer_stack` - rclpy, rcl, rmw,
  the rmw implementation, Fast DDS and Fast CDR as this kernel runs them: package versions and
  the shared libraries actually mapped into the process (its memory maps, read with psutil);
* :func:`transports_in_use` - the shared-memory segments and UDP sockets Fast DDS opened here;
* :class:`NamedTalker` and :class:`ChatterCounter` - nodes for the demo in which nodes in
  separate processes find each other with nothing started first, and keep talking when one of
  them is killed (``rt.spawn('talker_a', NamedTalker, {'name': 'talker_a'})``).
* :class:`Echo`, :class:`Pinger` and :func:`bounce` - several nodes in one process: round trips
  to an echo in this process and to one in a child process (:class:`RoundTrips`); which DDS
  participant holds each node is :func:`course_helpers.core.participants.participant_of`.

Linux only, like the rest of the course.
"""

from __future__ import annotations

import os
import re
import statistics
import time
from collections import Counter
from dataclasses import dataclass, field
from functools import partial

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from std_msgs.msg import Int64, String

from course_helpers.core import dds_config, processes
from course_helpers.core.errors import CourseError
from course_helpers.core.machine_load import LoadMeter, MachineLoad
from course_helpers.core.mapped_files import mapped_files, shm_files
from course_helpers.core.spawning import CHILD_HANG_S
from course_helpers.core.udp_sockets import classify_port, udp_sockets
from course_helpers.core.validation import check_node_name
from course_helpers.core.versions import package_version
from course_helpers.nodes.chatter import Talker


@dataclass
class Layer:
    """One layer of the ROS 2 stack as found in this process."""

    name: str
    role: str
    package: str  # the pip distribution that ships it
    version: str
    libraries: list[str] = field(default_factory=list)  # loaded shared libraries (basenames)

    @property
    def loaded(self) -> bool:
        return bool(self.libraries)


# name: (pip distributions to ask for its version, regex of its shared libraries)
_LAYER_FILES = {
    "rclpy": (("ros-jazzy-rclpy", "ros-rclpy"), r"^_rclpy_pybind11\..*\.so$"),
    "rcl": (("ros-rcl",), r"^librcl\.so"),
    "rmw": (("ros-rmw",), r"^librmw\.so"),
    "rmw_fastrtps_cpp": (("ros-jazzy-rmw-fastrtps-cpp", "ros-rmw-fastrtps-cpp"),
                         r"^librmw_fastrtps_(cpp|shared_cpp)\.so"),
    "Fast DDS": (("ros-fastrtps",), r"^libfastrtps\.so|^libfastdds\.so"),
    "Fast CDR": (("ros-fastcdr",), r"^libfastcdr\.so"),
}
_ROLES = {
    "rclpy": "Python client library: Node, publishers, timers, executors",
    "rcl": "ROS client library in C: names, arguments, parameter overrides, graph, timers",
    "rmw": "ROS middleware interface: the C API every middleware implements",
    "rmw_fastrtps_cpp": "the rmw implementation for eProsima Fast DDS",
    "Fast DDS": "the DDS implementation: discovery, QoS, readers and writers (RTPS protocol)",
    "Fast CDR": "serialises messages into the CDR wire format",
}


def loaded_libraries(pattern: str | None = None, pid: int | str = "self") -> list[str]:
    """Basenames of the shared libraries mapped into a process.

    Args:
        pattern: a regular expression; only the names it matches are returned (all if None).
        pid: the process ID to look at, or 'self' for this process.

    Returns:
        The sorted basenames, e.g. ``['libfastrtps.so.2.14', 'librmw_fastrtps_cpp.so']``.
    """
    names = {os.path.basename(path) for path in mapped_files(pid) if ".so" in path}
    regex = re.compile(pattern) if pattern else None
    return sorted(n for n in names if regex is None or regex.search(n))


def layer_stack() -> list[Layer]:
    """The layers from rclpy down to Fast CDR, top first, as this process runs them.

    Returns one :class:`Layer` per layer with its version and the libraries loaded here.
    Start the runtime first (``get_runtime()``): the middleware libraries load when the
    first context is initialised.
    """
    libraries = loaded_libraries()
    layers = []
    for name, (dists, pattern) in _LAYER_FILES.items():
        regex = re.compile(pattern)
        layers.append(Layer(name, _ROLES[name], dists[-1], package_version(*dists),
                            [lib for lib in libraries if regex.search(lib)]))
    return layers


def show_layer_stack(layers: list[Layer] | None = None) -> None:
    """Print ``layers`` (default: :func:`layer_stack`) as a table: layer, version, libraries, role."""
    layers = layers or layer_stack()
    for layer in layers:
        libs = ", ".join(layer.libraries) or "NOT LOADED"
        print(f"{layer.name:<17} {layer.version:<8} {libs}")
        print(f"{'':<17} {'':<8} └ {layer.role}")


# ---------------------------------------------------------------------- transports
@dataclass
class Transports:
    """What Fast DDS opened in this process: shared-memory files and UDP sockets."""

    domain_id: int
    shm_files: list[str]
    udp_sockets: list[tuple[str, int, str]]  # (address, port, meaning)

    @property
    def udp_ports(self) -> list[tuple[int, str]]:
        """(port, meaning) of each UDP socket."""
        return [(port, meaning) for _address, port, meaning in self.udp_sockets]

    @property
    def uses_shm(self) -> bool:
        return bool(self.shm_files)

    @property
    def uses_udp(self) -> bool:
        return bool(self.udp_sockets)

    @property
    def addresses(self) -> list[str]:
        """The addresses the UDP sockets are bound to, sorted, each once."""
        return sorted({address for address, _port, _meaning in self.udp_sockets})


def transports_in_use(domain_id: int | None = None) -> Transports:
    """The shared-memory files mapped and the UDP sockets bound by this process.

    Args:
        domain_id: the ROS domain, to name the ports (default: ``ROS_DOMAIN_ID``).

    Returns:
        A :class:`Transports`. Fast DDS keeps the shared-memory segments and ports in
        ``/dev/shm/fastrtps_*`` and ``/dev/shm/fastdds_*``, mapped into the process (read with
        psutil); the UDP sockets are the process's own
        (:func:`course_helpers.core.udp_sockets.udp_sockets`). The runtime's DDS
        participant is created first if no node has created it yet.
    """
    from course_helpers.core.runtime import get_runtime

    get_runtime().graph_nodes()  # rmw creates the participant (and its transports) with the first node
    if domain_id is None:
        domain_id = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    return Transports(domain_id, shm_files(),
                      [(address, port, classify_port(port, domain_id)) for address, port in udp_sockets()])


def show_transports(transports: Transports | None = None) -> None:
    """Print the shared-memory files and UDP sockets of ``transports`` (default: measured now)."""
    t = transports or transports_in_use()
    print(f"shared memory (/dev/shm), {len(t.shm_files)} files mapped:")
    for name in t.shm_files:
        print(f"  {name}")
    print(f"UDP sockets, address:port (domain {t.domain_id}):")
    for address, port, meaning in t.udp_sockets:
        print(f"  {address + ':' + str(port):>15}  {meaning}")


def draw_layer_stack(layers: list[Layer] | None = None, transports: Transports | None = None):
    """Draw the stack as boxes, top (your code) to bottom (transport), labelled with live facts.

    Takes :func:`layer_stack` and :func:`transports_in_use` results (measured if None); returns
    the matplotlib figure.
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyBboxPatch

    layers = layers or layer_stack()
    transports = transports or transports_in_use()
    rows = [("your node (Python)", "class Talker(Node): ...", "#e0f2fe")]
    colours = ["#dbeafe", "#dcfce7", "#fef9c3", "#fde68a", "#fce7f3", "#ede9fe"]
    for layer, colour in zip(layers, colours, strict=False):
        libs = ", ".join(layer.libraries[:2]) or "not loaded"
        rows.append((f"{layer.name}  {layer.version}", f"{layer.role}\n[{libs}]", colour))
    shm = f"shared memory: {len(transports.shm_files)} files in /dev/shm"
    udp = f"UDP: {len(transports.udp_sockets)} sockets on {', '.join(transports.addresses)}"
    rows.append(("transport", f"{shm}   |   {udp}", "#e5e7eb"))
    fig, ax = plt.subplots(figsize=(9.5, 0.62 * len(rows) + 0.6))
    ax.set_xlim(0, 1)
    ax.set_ylim(0, len(rows))
    ax.axis("off")
    for i, (title, detail, colour) in enumerate(rows):
        y = len(rows) - 1 - i
        ax.add_patch(FancyBboxPatch((0.01, y + 0.08), 0.98, 0.84, boxstyle="round,pad=0.005",
                                    facecolor=colour, edgecolor="#374151", linewidth=1))
        ax.text(0.03, y + 0.5, title, va="center", fontsize=9.5, fontweight="bold")
        ax.text(0.33, y + 0.5, detail, va="center", fontsize=8)
    ax.set_title("The ROS 2 stack in this kernel, top to bottom (live)", fontsize=11)
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------- no master
def short_lease_env(lease_s: float = 2.0) -> dict[str, str]:
    """Environment for ``rt.spawn(..., env=...)``: the child's participant announces a short lease.

    Takes the lease in seconds (0.5..60); returns ``{'FASTRTPS_DEFAULT_PROFILES_FILE': path}``.

    Peers drop a participant that stays silent longer than its lease. Fast DDS's default is
    20 s; a 2 s lease lets the notebook show a crashed node leaving the graph without a long
    wait. The lease is set in the course's Fast DDS XML profile (``FASTRTPS_DEFAULT_PROFILES_FILE``,
    :func:`course_helpers.core.dds_config.short_lease_env`), written into this kernel's private
    folder.
    """
    return dds_config.short_lease_env(processes.log_dir(), lease_s)


class NamedTalker(Talker):
    """A :class:`~course_helpers.nodes.chatter.Talker` whose messages say who sent them.

    Publishes '<node name>: <count>' (std_msgs/String) on ``topic`` at ``rate_hz`` (default 10 Hz),
    so a :class:`ChatterCounter` can tell the senders apart. Takes Talker's arguments.
    """

    def __init__(self, name: str = "talker", topic: str = "chatter", rate_hz: float = 10.0, **kwargs):
        super().__init__(name=name, topic=topic, rate_hz=rate_hz, **kwargs)

    def tick(self) -> None:
        self.publisher.publish(String(data=f"{self.get_name()}: {self.count}"))
        self.count += 1


class ChatterCounter(Node):
    """Counts the messages on a String ``topic`` per sender (the text before ':') in ``counts``."""

    def __init__(self, name: str = "chatter_counter", topic: str = "chatter"):
        super().__init__(name)
        self.counts: Counter[str] = Counter()
        self.subscription = self.create_subscription(String, topic, self.on_message, 10)

    def on_message(self, msg: String) -> None:
        self.counts[msg.data.split(":", 1)[0]] += 1


def count_during(counter: ChatterCounter, seconds: float = 1.0) -> dict[str, int]:
    """Listen for ``seconds`` seconds; return the messages per sender that the running ``counter``
    heard meanwhile (``{'talker_a': 15, 'talker_b': 0}``, senders sorted)."""
    before = Counter(counter.counts)
    time.sleep(seconds)
    after = Counter(counter.counts)
    return {sender: after[sender] - before[sender] for sender in sorted(set(after) | set(before))}


# ---------------------------------------------------------------------- several nodes, one process
# Reliable and transient-local, depth 1: a ping or pong sent before its reader has matched is delivered
# when it matches, so the one message in flight is never lost and a chain of round trips never stalls.
BOUNCE_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
MAX_ROUNDS = 10_000


class Echo(Node):
    """Answers every number on its ``~/ping`` with the same message on its ``~/pong``.

    ``last`` is the last message it received.
    """

    def __init__(self, name: str = "echo"):
        super().__init__(name)
        self.last: Int64 | None = None
        self.publisher = self.create_publisher(Int64, "~/pong", BOUNCE_QOS)
        self.subscription = self.create_subscription(Int64, "~/ping", self.on_ping, BOUNCE_QOS)

    def on_ping(self, msg: Int64) -> None:
        self.last = msg
        self.publisher.publish(msg)


class Pinger(Node):
    """Bounces numbered messages off :class:`Echo` nodes (named in ``echoes``), one message in flight.

    Each answer sends the next message, to the next echo in turn, from the answer's callback: the
    whole run happens in the executor's thread, and the echoes take turns, so a change in the
    machine's load falls on all of them alike. The numbers start from the monotonic clock, so an
    answer left over from an earlier run is never taken for one of this run.
    """

    def __init__(self, echoes=("echo",), name: str = "pinger"):
        super().__init__(name)
        if isinstance(echoes, str) or not echoes:
            raise CourseError(f"echoes must be a list of echo node names, e.g. ['echo_here'], got {echoes!r}")
        self.echoes = [check_node_name(echo) for echo in echoes]
        self.sent: dict[str, Int64] = {}  # the last message sent to each echo
        self.round_trips: dict[str, list[float]] = {echo: [] for echo in self.echoes}  # seconds
        self.to_echo = {e: self.create_publisher(Int64, f"/{e}/ping", BOUNCE_QOS) for e in self.echoes}
        self.from_echo = {e: self.create_subscription(Int64, f"/{e}/pong", partial(self.on_pong, e),
                                                      BOUNCE_QOS) for e in self.echoes}
        self._plan: list[str] = []  # the echoes still to ping, in order
        self._in_flight: tuple[str, int, float] | None = None  # (echo, number, time.perf_counter())
        self._number = time.monotonic_ns()
        self._done = Future()

    def matched(self) -> bool:
        """True once every echo subscribes to its ping and publishes its pong, as this node sees it."""
        return all(self.to_echo[e].get_subscription_count() > 0
                   and self.from_echo[e].get_publisher_count() > 0 for e in self.echoes)

    def start(self, rounds: int) -> Future:
        """Send ``rounds`` messages to each echo in turn; call it in the executor's thread.

        Returns a future done with :attr:`round_trips` when the last answer came.
        """
        self.round_trips = {echo: [] for echo in self.echoes}
        self._plan = self.echoes * rounds
        self._done = Future()
        self._send_next()
        return self._done

    def _send_next(self) -> None:
        if not self._plan:
            self._in_flight = None
            self._done.set_result(self.round_trips)
            return
        echo = self._plan.pop(0)
        self._number += 1
        self.sent[echo] = Int64(data=self._number)
        self._in_flight = (echo, self._number, time.perf_counter())
        self.to_echo[echo].publish(self.sent[echo])

    def on_pong(self, echo: str, msg: Int64) -> None:
        arrived = time.perf_counter()
        if self._in_flight is None or (echo, msg.data) != self._in_flight[:2]:
            return  # an answer left over from an earlier run
        self.round_trips[echo].append(arrived - self._in_flight[2])
        self._send_next()


@dataclass
class RoundTrips:
    """Round-trip times in seconds, per echo, and how busy the machine was while they were measured."""

    seconds: dict[str, list[float]]
    load: MachineLoad

    def one_way_us(self, echo: str) -> float:
        """Half the median round trip to ``echo``, in microseconds."""
        return statistics.median(self.seconds[echo]) / 2 * 1e6

    def fastest_us(self, echo: str) -> float:
        """Half the fastest round trip to ``echo``, in microseconds: when nothing got in the way."""
        return min(self.seconds[echo]) / 2 * 1e6

    def show(self, labels: dict[str, str] | None = None) -> None:
        """Print one line per echo (``labels`` names them: {'echo_here': 'same process'}), then the load."""
        labels = labels or {}
        print(f"{'':<16} {'round trips':>11}  {'one way, median':>15}  {'fastest':>9}")
        for echo, seconds in self.seconds.items():
            print(f"{labels.get(echo, echo):<16} {len(seconds):>11}  {self.one_way_us(echo):>12.0f} µs"
                  f"  {self.fastest_us(echo):>6.0f} µs")
        if len(self.seconds) == 2:
            first, second = self.seconds
            print(f"{labels.get(second, second)} / {labels.get(first, first)}, median one way: "
                  f"{self.one_way_us(second) / self.one_way_us(first):.2f}")
        print(self.load.describe())


def bounce(rt, pinger: Pinger, rounds: int = 200, timeout: float = CHILD_HANG_S) -> RoundTrips:
    """Measure ``rounds`` round trips from ``pinger`` (a running node of ``rt``) to each of its echoes.

    Waits until the pinger has matched every echo, sends one message to each that is not counted
    (buffers and connections warm up), then the counted ones. ``timeout`` bounds a hang of each part.
    Returns a :class:`RoundTrips`.
    """
    if isinstance(rounds, bool) or not isinstance(rounds, int) or not 1 <= rounds <= MAX_ROUNDS:
        raise CourseError(f"rounds must be a whole number from 1 to {MAX_ROUNDS}, got {rounds!r}")
    echoes = ", ".join(pinger.echoes)
    rt.wait_until(pinger.matched, timeout, f"{pinger.get_name()} to match the echoes {echoes}")
    rt.wait_for_future(rt.call_in_executor(pinger.start, 1), timeout, f"a first round trip to {echoes}")
    meter = LoadMeter()
    run = rt.call_in_executor(pinger.start, rounds)
    rt.wait_for_future(run, timeout, f"{rounds} round trips to {echoes}")
    return RoundTrips({echo: list(times) for echo, times in pinger.round_trips.items()}, meter.finish())
