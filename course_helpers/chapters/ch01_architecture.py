"""Chapter 01 (architecture): the ROS 2 layers of this very process, and the "no master" demo.

* :func:`layer_stack` / :func:`show_layer_stack` / :func:`draw_layer_stack` - rclpy, rcl, rmw,
  the rmw implementation, Fast DDS and Fast CDR as this kernel runs them: package versions and
  the shared libraries actually mapped into the process (read from ``/proc/self/maps``);
* :func:`transports_in_use` - the shared-memory segments and UDP ports Fast DDS opened here;
* :func:`make_named_talker` and :class:`ChatterCounter` - nodes for the demo in which nodes
  in separate processes find each other with nothing started first, and keep talking when one
  of them is killed.

Linux only (``/proc``), like the rest of the course.
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version

from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.core.errors import CourseError


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


# name, role, distributions to ask for a version, regex of its shared libraries
_LAYERS = [
    ("rclpy", "Python client library: Node, publishers, timers, executors",
     ("ros-jazzy-rclpy", "ros-rclpy"), r"^_rclpy_pybind11\..*\.so$"),
    ("rcl", "ROS client library in C: names, parameters, graph; shared by rclpy and rclcpp",
     ("ros-rcl",), r"^librcl\.so"),
    ("rmw", "ROS middleware interface: the C API every middleware implements",
     ("ros-rmw",), r"^librmw\.so"),
    ("rmw_fastrtps_cpp", "the rmw implementation for eProsima Fast DDS",
     ("ros-jazzy-rmw-fastrtps-cpp", "ros-rmw-fastrtps-cpp"), r"^librmw_fastrtps_(cpp|shared_cpp)\.so"),
    ("Fast DDS", "the DDS implementation: discovery, QoS, readers and writers (RTPS protocol)",
     ("ros-fastrtps",), r"^libfastrtps\.so|^libfastdds\.so"),
    ("Fast CDR", "serialises messages into the CDR wire format",
     ("ros-fastcdr",), r"^libfastcdr\.so"),
]


def loaded_libraries(pattern: str | None = None, pid: int | str = "self") -> list[str]:
    """Basenames of the shared libraries mapped into a process, sorted (optionally regex-filtered)."""
    try:
        with open(f"/proc/{pid}/maps", encoding="utf-8") as handle:
            lines = handle.read().splitlines()
    except OSError as exc:
        raise CourseError(f"cannot read /proc/{pid}/maps ({exc}); this needs Linux") from None
    names = set()
    for line in lines:
        parts = line.split()
        if len(parts) >= 6 and ".so" in parts[-1]:
            names.add(os.path.basename(parts[-1]))
    regex = re.compile(pattern) if pattern else None
    return sorted(n for n in names if regex is None or regex.search(n))


def package_version(*distributions: str) -> str:
    """The version of the first installed pip distribution among ``distributions``."""
    for dist in distributions:
        try:
            return version(dist)
        except PackageNotFoundError:
            continue
    return "not installed"


def layer_stack() -> list[Layer]:
    """The layers from rclpy down to Fast CDR, with versions and the libraries loaded in this process.

    Start the runtime first (``get_runtime()``): the middleware libraries load when the first
    context is initialised.
    """
    libraries = loaded_libraries()
    layers = []
    for name, role, dists, pattern in _LAYERS:
        regex = re.compile(pattern)
        layers.append(Layer(name, role, dists[-1], package_version(*dists),
                            [lib for lib in libraries if regex.search(lib)]))
    return layers


def show_layer_stack(layers: list[Layer] | None = None) -> None:
    """Print the layer table: layer, version, loaded libraries, role."""
    layers = layers or layer_stack()
    for layer in layers:
        libs = ", ".join(layer.libraries) or "NOT LOADED"
        print(f"{layer.name:<17} {layer.version:<8} {libs}")
        print(f"{'':<17} {'':<8} └ {layer.role}")


# ---------------------------------------------------------------------- transports
@dataclass
class Transports:
    """What Fast DDS opened in this process: shared-memory files and UDP ports."""

    domain_id: int
    shm_files: list[str]
    udp_ports: list[tuple[int, str]]  # (port, meaning)

    @property
    def uses_shm(self) -> bool:
        return bool(self.shm_files)

    @property
    def uses_udp(self) -> bool:
        return bool(self.udp_ports)


def classify_port(port: int, domain_id: int) -> str:
    """What a UDP port is for, by the RTPS port mapping (base 7400 + 250 x domain)."""
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
    return "another Fast DDS port, outside the domain's RTPS range"


def transports_in_use(domain_id: int | None = None) -> Transports:
    """The shared-memory files mapped and the UDP ports bound by this process.

    Fast DDS keeps the shared-memory segments and ports in ``/dev/shm/fastrtps_*`` and
    ``/dev/shm/fastdds_*``; UDP sockets are found by matching this process's socket file
    descriptors with ``/proc/self/net/udp``.
    """
    if domain_id is None:
        domain_id = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    shm = set()
    with open("/proc/self/maps", encoding="utf-8") as handle:
        for line in handle:
            path = line.split()[-1] if line.strip() else ""
            if path.startswith("/dev/shm/fast"):
                shm.add(os.path.basename(path))
    inodes = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    ports = set()
    for table in ("/proc/self/net/udp", "/proc/self/net/udp6"):
        try:
            with open(table, encoding="utf-8") as handle:
                rows = handle.read().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            cols = row.split()
            if len(cols) > 9 and cols[9] in inodes:
                ports.add(int(cols[1].rsplit(":", 1)[1], 16))
    return Transports(domain_id, sorted(shm),
                      [(p, classify_port(p, domain_id)) for p in sorted(ports)])


def show_transports(transports: Transports | None = None) -> None:
    """Print the shared-memory files and UDP ports of :func:`transports_in_use`."""
    t = transports or transports_in_use()
    print(f"shared memory (/dev/shm), {len(t.shm_files)} files mapped:")
    for name in t.shm_files:
        print(f"  {name}")
    print(f"UDP ports bound (domain {t.domain_id}):")
    for port, meaning in t.udp_ports:
        print(f"  {port:>5}  {meaning}")


def draw_layer_stack(layers: list[Layer] | None = None, transports: Transports | None = None):
    """Draw the stack as boxes, top (your code) to bottom (transport), labelled with live facts."""
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
    udp = f"UDP: {len(transports.udp_ports)} ports"
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
_LEASE_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="course_short_lease" is_default_profile="true">
    <rtps>
      <builtin>
        <discovery_config>
          <leaseDuration><sec>{sec}</sec><nanosec>{nsec}</nanosec></leaseDuration>
          <leaseAnnouncement><sec>{asec}</sec><nanosec>{ansec}</nanosec></leaseAnnouncement>
        </discovery_config>
      </builtin>
    </rtps>
  </participant>
</profiles>
"""


def short_lease_env(lease_s: float = 2.0) -> dict[str, str]:
    """Environment for ``rt.spawn(..., env=...)``: the child's participant announces a short lease.

    Peers drop a participant that stays silent longer than its lease. Fast DDS's default is
    20 s; a 2 s lease lets the notebook show a crashed node leaving the graph without a long
    wait. The lease is set in a Fast DDS XML profile (``FASTRTPS_DEFAULT_PROFILES_FILE``);
    the participant announces itself four times per lease.
    """
    if not 0.5 <= lease_s <= 60:
        raise CourseError(f"lease_s must be 0.5..60 seconds, got {lease_s!r}")
    announce = lease_s / 4

    def split(seconds):
        whole = int(seconds)
        return whole, int(round((seconds - whole) * 1e9))

    (sec, nsec), (asec, ansec) = split(lease_s), split(announce)
    path = os.path.join(tempfile.gettempdir(), f"ros2-course-lease-{os.getuid()}-{sec}.{nsec:09d}.xml")
    partial = f"{path}.{os.getpid()}"
    with open(partial, "w", encoding="utf-8") as handle:
        handle.write(_LEASE_PROFILE.format(sec=sec, nsec=nsec, asec=asec, ansec=ansec))
    os.replace(partial, path)  # atomic: a child never reads a half-written profile
    return {"FASTRTPS_DEFAULT_PROFILES_FILE": path}


def make_named_talker(name: str = "talker", topic: str = "chatter", rate_hz: float = 10.0) -> Node:
    """Child-process target: a node that publishes '<name>: <count>' on ``topic`` at ``rate_hz``."""
    node = Node(name)
    publisher = node.create_publisher(String, topic, 10)
    count = [0]

    def tick():
        publisher.publish(String(data=f"{name}: {count[0]}"))
        count[0] += 1

    node.talk_timer = node.create_timer(1.0 / rate_hz, tick)
    return node


class ChatterCounter(Node):
    """Counts the messages on a String topic per sender (the text before ':')."""

    def __init__(self, name: str = "chatter_counter", topic: str = "chatter"):
        super().__init__(name)
        self.counts: Counter[str] = Counter()
        self.subscription = self.create_subscription(String, topic, self.on_message, 10)

    def on_message(self, msg: String) -> None:
        self.counts[msg.data.split(":", 1)[0]] += 1


def count_during(counter: ChatterCounter, seconds: float = 1.0) -> dict[str, int]:
    """Messages per sender that ``counter`` heard during the next ``seconds`` seconds."""
    before = Counter(counter.counts)
    time.sleep(seconds)
    after = Counter(counter.counts)
    return {sender: after[sender] - before[sender] for sender in sorted(set(after) | set(before))}


# ---------------------------------------------------------------------- the exercise
def check_crash_exercise(rt, counter: ChatterCounter, window_s: float = 1.5):
    """Check chapter 01's exercise: a third talker process runs and talker_b's process was killed.

    Expected state: a child labelled ``talker_c`` runs ``/talker_c`` (started with
    :func:`make_named_talker`); the child ``talker_b`` has been killed; ``counter`` (a running
    :class:`ChatterCounter`) now hears talker_c and nobody else.
    """
    from course_helpers.checks import CheckReport

    report = CheckReport("Exercise: a third talker, and a second crash")
    children = rt.children()
    c = children.get("talker_c")
    report.add("a child process labelled 'talker_c' is running", c is not None and c.alive,
               "" if c is not None else "no child labelled talker_c",
               hint="rt.spawn('talker_c', 'course_helpers.chapters.ch01_architecture:make_named_talker', "
                    "{'name': 'talker_c'}, wait_for='/talker_c')")
    in_graph = "/talker_c" in rt.graph_nodes()
    report.add("node /talker_c is in the ROS graph", in_graph,
               hint="Pass {'name': 'talker_c'} so the node gets that name.")
    b = children.get("talker_b")
    killed = b is not None and not b.alive
    report.add("talker_b's process is dead", killed,
               "" if killed else ("talker_b is still running" if b is not None
                                  else "no child labelled talker_b: start it again, then kill it"),
               hint="Keep the ChildNode that rt.spawn returned and call its kill() method.")
    heard = count_during(counter, window_s)
    others = sorted(s for s, n in heard.items() if n and s != "talker_c")
    report.add("the counter hears talker_c", heard.get("talker_c", 0) >= 3,
               "" if heard.get("talker_c", 0) >= 3 else "no messages from talker_c",
               hint="talker_c must publish on 'chatter', the topic the counter listens to.")
    report.add("the counter hears nobody else", not others,
               f"still hearing {', '.join(others)}" if others else "",
               hint="Both talker_a and talker_b must be dead.")
    return report
