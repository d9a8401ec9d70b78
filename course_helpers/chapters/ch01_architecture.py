"""Chapter 01 (architecture): the ROS 2 layers of this very process, and the "no master" demo.

* :func:`layer_stack` / :func:`show_layer_stack` / :func:`draw_layer_stack` - rclpy, rcl, rmw,
  the rmw implementation, Fast DDS and Fast CDR as this kernel runs them: package versions and
  the shared libraries actually mapped into the process (its memory maps, read with psutil);
* :func:`transports_in_use` - the shared-memory segments and UDP sockets Fast DDS opened here;
* :class:`NamedTalker` and :class:`ChatterCounter` - nodes for the demo in which nodes in
  separate processes find each other with nothing started first, and keep talking when one of
  them is killed (``rt.spawn('talker_a', NamedTalker, {'name': 'talker_a'})``).

Linux only, like the rest of the course.
"""

from __future__ import annotations

import os
import re
import time
from collections import Counter
from dataclasses import dataclass, field

from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.core import dds_config, processes
from course_helpers.core.errors import CourseError
from course_helpers.core.udp_sockets import udp_sockets
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
    names = {os.path.basename(path) for path in _mapped_files(pid) if ".so" in path}
    regex = re.compile(pattern) if pattern else None
    return sorted(n for n in names if regex is None or regex.search(n))


def _mapped_files(pid: int | str = "self") -> list[str]:
    """The paths of the files mapped into process ``pid`` ('self': this one)."""
    import psutil

    try:
        process = psutil.Process() if pid == "self" else psutil.Process(int(pid))
        return [region.path for region in process.memory_maps(grouped=True)]
    except (psutil.Error, ValueError) as exc:
        raise CourseError(f"cannot read the memory maps of process {pid} ({exc}); this needs Linux "
                          "and a process of your own") from None


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


# rmw_fastrtps asks for a listening port of their own ("unique network flow") for the subscription
# that hears the graph's updates, ros_discovery_info (init_rmw_context_impl.cpp), and Fast DDS picks the
# first free one from its port base minus 400 up to the base (RTPSParticipantImpl.cpp), in any domain.
GRAPH_PORTS = (7400 - 400, 7400)


def classify_port(port: int, domain_id: int) -> str:
    """What a UDP ``port`` of a participant in ``domain_id`` is for, as a short phrase.

    Follows the RTPS port mapping (base 7400 + 250 x domain), e.g. 'discovery, unicast
    (participant 0)'.
    """
    base = 7400 + 250 * domain_id
    if port == base:
        return "discovery, multicast"
    if port == base + 1:
        return "user data, multicast"
    offset = port - base - 10
    if 0 <= offset < 240:
        participant = offset // 2
        kind = "discovery" if offset % 2 == 0 else "user data"
        return f"{kind}, unicast (participant {participant})"
    if port >= 32768:
        return "sending socket (ephemeral port picked by the OS)"
    if GRAPH_PORTS[0] <= port < GRAPH_PORTS[1]:
        return "graph updates (ros_discovery_info), a port of their own"
    return "another Fast DDS port, outside the domain's RTPS range"


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
    shm = {os.path.basename(path) for path in _mapped_files() if path.startswith("/dev/shm/fast")}
    return Transports(domain_id, sorted(shm),
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
