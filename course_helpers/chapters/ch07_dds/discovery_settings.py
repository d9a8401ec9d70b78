"""Discovery tuning as a real knob: how fast a new process finds a node, and what the speed costs.

:func:`compare_discovery` times fresh probe processes (:func:`.discovery.discovery_probe`) against
an anchor node in a child process, once with Fast DDS's default discovery settings and once with
the course's profile, each set-up in a ROS domain of its own so the two never meet. Probes of both set-ups
start together, so a busy moment on the machine hits both alike.

:func:`listen_to_announcements` measures what the announcements cost: it binds plain UDP sockets
to the discovery ports of participants that do not exist, in a domain where one lone participant
runs, and counts the datagrams that participant sends there.
"""

from __future__ import annotations

import socket
import statistics
import time
from dataclasses import dataclass, field

from course_helpers.chapters.ch07_dds.discovery import DiscoveryAnchor, DiscoveryTiming, discovery_probe
from course_helpers.chapters.ch07_dds.listener import ReportingListener
from course_helpers.core.channel import report
from course_helpers.core.dds_config import (
    ANNOUNCEMENT_S,
    DEFAULT_ACKNACK_S,
    DEFAULT_ANNOUNCEMENT_S,
    DEFAULT_SHM_HEALTH_CHECK_MS,
    GRAPH_ACKNACK_S,
    PEER_IDS,
    SHM_HEALTH_CHECK_MS,
    default_discovery_env,
)
from course_helpers.core.domains import reserve_domain, reserve_spare_domain
from course_helpers.core.errors import CourseError
from course_helpers.core.udp_sockets import discovery_port, udp_sockets
from course_helpers.core.waiting import poll_until

SETTINGS = {
    "Fast DDS default": (f"announcements every {DEFAULT_ANNOUNCEMENT_S:g} s, graph request after "
                         f"{DEFAULT_ACKNACK_S * 1e3:g} ms, "
                         f"shared-memory check {DEFAULT_SHM_HEALTH_CHECK_MS} ms"),
    "course": (f"announcements every {ANNOUNCEMENT_S:g} s, graph request after {GRAPH_ACKNACK_S * 1e3:g} ms, "
               f"shared-memory check {SHM_HEALTH_CHECK_MS} ms"),
}
PROBE_TIMEOUT_S = 6.5  # s; two default announcement periods and a margin
ANCHOR_SETTLE_S = 1.0  # s; past the anchors' first, fast announcements (5 at 0.1 s), into the period
_domains: list[int] = []  # the two domains of the comparison, reserved once per process


def _comparison_domains() -> list[int]:
    if not _domains:
        spare = reserve_spare_domain()
        _domains.extend([spare, reserve_domain(exclude=(spare,))])
    return _domains


def _env(setting: str, domain: int, log_dir: str) -> dict:
    extra = default_discovery_env(log_dir) if setting == "Fast DDS default" else {}
    return {"ROS_DOMAIN_ID": str(domain), **extra}  # the course's profile is inherited from the kernel


@dataclass
class DiscoveryComparison:
    """Timings of fresh processes finding an anchor node, per setting (one list per key of SETTINGS)."""

    timings: dict[str, list[DiscoveryTiming]]
    timeout_s: float = PROBE_TIMEOUT_S

    def seconds(self, setting: str) -> list[float]:
        """Per probe: seconds from its node's creation until it saw the anchor node and its
        subscription matched the anchor's publisher; a probe that never did counts as the timeout."""
        out = []
        for t in self.timings[setting]:
            if t.found:
                out.append(max(t.sees_node_s, t.reader_matched_s) - t.create_node_s)
            else:
                out.append(self.timeout_s)
        return out

    def missed(self, setting: str) -> int:
        """How many probes of ``setting`` never found the anchor within the timeout."""
        return sum(not t.found for t in self.timings[setting])

    def percentile(self, setting: str, q: float) -> float:
        """The ``q`` quantile (0..1, nearest rank) of :meth:`seconds`; 0.5 is the median."""
        ordered = sorted(self.seconds(setting))
        return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def compare_discovery(rt, repeats: int = 6, timeout_s: float = PROBE_TIMEOUT_S) -> DiscoveryComparison:
    """Time ``repeats`` fresh processes per setting finding an anchor, with each of :data:`SETTINGS`.

    Args:
        rt: the kernel's runtime (it starts the children; its own node takes no part).
        repeats: probe processes per setting, 2..20; a probe of each setting starts at the same time.
        timeout_s: how long each probe looks for the anchor.

    Returns a :class:`DiscoveryComparison`.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 2 <= repeats <= 20:
        raise CourseError(f"repeats must be a whole number 2..20, got {repeats!r}")
    domains = dict(zip(SETTINGS, _comparison_domains(), strict=True))
    labels = {setting: "default" if setting == "Fast DDS default" else "course" for setting in SETTINGS}
    envs = {setting: _env(setting, domains[setting], rt.log_dir) for setting in SETTINGS}
    anchors_of = {s: f"{labels[s]}_anchor" for s in SETTINGS}
    probes_of = {s: f"{labels[s]}_probe" for s in SETTINGS}
    anchors, probes = list(anchors_of.values()), list(probes_of.values())
    timings: dict[str, list[DiscoveryTiming]] = {setting: [] for setting in SETTINGS}
    try:
        for setting in SETTINGS:
            rt.spawn(anchors_of[setting], DiscoveryAnchor, env=envs[setting]).wait_for_report("ready", 30)
        time.sleep(ANCHOR_SETTLE_S)
        for _ in range(repeats):
            children = {setting: rt.spawn(probes_of[setting], discovery_probe,
                                          params={"timeout_s": timeout_s}, env=envs[setting])
                        for setting in SETTINGS}
            for setting, child in children.items():
                result = child.wait_for_report("result", timeout_s + 30, f"the result of a {setting} probe")
                timings[setting].append(DiscoveryTiming(**result))
            running = list(children.values())
            poll_until(lambda: not any(c.alive for c in running), 5.0)  # noqa: B023 (used at once)
            rt.stop_children(probes)  # the probes' participants leave before the next ones start
    finally:
        rt.stop_children(anchors + probes)
    return DiscoveryComparison(timings, timeout_s)


# ---------------------------------------------------------------------- what announcing costs
@dataclass
class AnnouncementTraffic:
    """What one lone participant sent to the discovery ports of participants that did not exist."""

    window_s: float  # s listened
    arrivals: dict[int, list[float]] = field(default_factory=dict)  # participant id -> time.monotonic()
    sizes: list[int] = field(default_factory=list)  # bytes of each datagram (UDP payload)
    senders: set[bytes] = field(default_factory=set)  # RTPS GUID prefixes of the senders
    held_ids: list[int] = field(default_factory=list)  # ids whose port another socket held: not listened to
    own_id: int | None = None  # the lone participant's id, read from its own sockets (None: not known)

    @property
    def held_by_others(self) -> list[int]:
        """The ids of :attr:`held_ids` other than the lone participant's: ports another program held."""
        return [pid for pid in self.held_ids if pid != self.own_id]

    @property
    def ports_reached(self) -> list[int]:
        """The participant ids whose discovery port received something, sorted."""
        return sorted(pid for pid, times in self.arrivals.items() if times)

    @property
    def datagram_bytes(self) -> int:
        """The median datagram size in bytes (one announcement to one port)."""
        return int(statistics.median(self.sizes)) if self.sizes else 0

    @property
    def period_s(self) -> float | None:
        """The median time between two announcements at one port, or None if fewer than two came."""
        gaps = [b - a for times in self.arrivals.values() for a, b in zip(times, times[1:], strict=False)]
        return statistics.median(gaps) if gaps else None


def listen_to_announcements(domain: int, seconds: float = 1.5,
                            participant_ids=range(2 * PEER_IDS)) -> AnnouncementTraffic:
    """Count the discovery datagrams sent in ``domain`` to the ports of ``participant_ids`` for ``seconds``.

    Only ports nobody holds are bound (plain UDP sockets on 127.0.0.1); run it while one participant,
    and no new one, lives in ``domain``: a participant starting meanwhile could not use those ports.
    Returns an :class:`AnnouncementTraffic`.
    """
    if not 0.2 <= seconds <= 10:
        raise CourseError(f"seconds must be 0.2..10, got {seconds!r}")
    sockets: dict[socket.socket, int] = {}
    traffic = AnnouncementTraffic(seconds)
    try:
        for pid in participant_ids:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.bind(("127.0.0.1", discovery_port(domain, pid)))
            except OSError:
                sock.close()  # a participant of that domain holds it, or some other program
                traffic.held_ids.append(pid)
                continue
            sock.setblocking(False)
            sockets[sock] = pid
            traffic.arrivals[pid] = []

        def drain() -> bool:
            now = time.monotonic()
            for sock, pid in sockets.items():
                while True:
                    try:
                        data = sock.recv(65536)
                    except BlockingIOError:
                        break
                    traffic.arrivals[pid].append(now)
                    traffic.sizes.append(len(data))
                    if data[:4] == b"RTPS":
                        traffic.senders.add(data[8:20])  # the header's GUID prefix: who sent it
            return False

        poll_until(drain, seconds, period=0.002)
    finally:
        for sock in sockets:
            sock.close()
    return traffic


class LoneListener(ReportingListener):
    """A quiet listener that reports the UDP ports its process holds (``report('ports', ports=[...])``).

    Its id need not be 0. Fast DDS gives a participant the smallest id its own process is not using
    (``RTPSDomainImpl::getNewId``), and moves a locator it cannot open, such as a port another program
    holds, by one id's worth of ports and tries again (``applyLocatorAdaptRule`` in
    ``RTPSParticipantImpl.cpp``). So its own ports tell which id it took.
    """

    def __init__(self, name: str = "lone_listener"):
        super().__init__(name)  # the first node creates the participant, which binds its ports
        report("ports", ports=sorted({port for _, port in udp_sockets()}))


def measure_announcements(rt, seconds: float = 1.5) -> AnnouncementTraffic:
    """Start one lone, quiet node (a listener) with the course's settings in a domain of its own,
    and listen to its announcements.

    Returns the :class:`AnnouncementTraffic` seen in ``seconds`` (after its first announcements), with
    the participant's own id.
    """
    domain = _comparison_domains()[0]
    child = rt.spawn("lone_participant", LoneListener, env=_env("course", domain, rt.log_dir))
    try:
        ports = set(child.wait_for_report("ports", 30, "the lone participant's ports")["ports"])
        child.wait_for_report("ready", 30)
        time.sleep(ANCHOR_SETTLE_S)  # past its first, fast announcements
        traffic = listen_to_announcements(domain, seconds)
    finally:
        rt.stop_child("lone_participant")
    traffic.own_id = next((pid for pid in range(2 * PEER_IDS) if discovery_port(domain, pid) in ports), None)
    return traffic


def plot_discovery(comparison: DiscoveryComparison):
    """A matplotlib figure: each probe's time to find the anchor, one row of dots per setting."""
    import matplotlib.pyplot as plt

    colours = {"Fast DDS default": "#dc2626", "course": "#16a34a"}
    fig, ax = plt.subplots(figsize=(9, 2.4))
    for row, setting in enumerate(SETTINGS):
        values = [max(v, 1e-3) for v in comparison.seconds(setting)]  # the log axis starts at 1 ms
        ax.scatter(values, [row] * len(values), color=colours[setting], alpha=0.7, s=40)
    ax.axvline(DEFAULT_ANNOUNCEMENT_S, color="#6b7280", linestyle="--", linewidth=1)
    ax.text(DEFAULT_ANNOUNCEMENT_S, 1.45, "one default period ", fontsize=8, color="#6b7280", va="top",
            ha="right")
    periods = (DEFAULT_ANNOUNCEMENT_S, ANNOUNCEMENT_S)  # in the order of SETTINGS
    names = [f"{s}\n(every {p:g} s)" for s, p in zip(SETTINGS, periods, strict=True)]
    ax.set_yticks(range(len(SETTINGS)), names)
    ax.set_ylim(-0.6, 1.6)
    ax.set_xscale("log")
    ax.set_xlim(1e-3, 10)
    ax.set_xlabel("seconds from the new node's creation until it found the anchor (log scale)")
    ax.grid(alpha=0.3, axis="x", which="both")
    ax.set_title("Fresh processes finding a node, measured now", fontsize=10)
    fig.tight_layout()
    return fig
