"""The QoS lab's lossy link: a private network whose loopback drops a share of the UDP datagrams.

Both ends run as child processes inside a network namespace of their own (:mod:`course_helpers.core.netns`),
so they talk over that namespace's loopback interface and over UDP only (shared memory is off:
Fast DDS would otherwise hand the samples over in memory, past the network). On that loopback

* an nftables rule on the **input** hook drops ``loss_percent`` of the UDP datagrams sent to a data
  port at random, as a noisy radio link loses frames: the sender never learns of it (a drop on the
  output hook would return an error to the sender instead, which no network does);
* a token bucket (``tc qdisc ... tbf``) limits the link to ``link_mbit`` if asked.

RTPS's port formula (chapter 07) gives every participant an even port for discovery (metatraffic)
and an odd one for user traffic, so the rule drops by the port's parity: samples, heartbeats and
acknowledgements are lost alike, while discovery gets through, and each run starts measuring as soon
as both ends are up instead of after a discovery slowed by a random number of lost announcements.
The link is made once per kernel and set for each run; it goes away with the kernel (its holder is
a course child).

Both ends read :func:`link_env`'s Fast DDS profile: UDP on 127.0.0.1 only, and a reliable writer
that sends its periodic heartbeat every ``HEARTBEAT_S`` instead of Fast DDS's 3 s. A lost sample is
repaired only after a heartbeat has made the reader ask for it, so with the default a run on a
lossy link would spend most of its time waiting for the last repairs.
"""

from __future__ import annotations

from course_helpers.core import netns, processes
from course_helpers.core.dds_config import PROFILE_ENV, RANGE_ENV, profile_xml, write_profile
from course_helpers.core.errors import CourseError

LINK_LABEL = "qos_lab_link"
SUBSCRIBER_LABEL = "qos_lab_subscriber"
NFT_TABLE = "qos_lab"
TBF_LATENCY_MS = 50  # how long a datagram may wait in the token bucket before it is dropped
MIN_BURST_BYTES = 70_000  # above one 64 KiB datagram: a smaller bucket could never pass a big one
HEARTBEAT_S = 0.25  # s; a reliable writer's periodic heartbeat on the link (Fast DDS default: 3 s)
DEFAULT_HEARTBEAT_S = 3.0
PROFILE = "course_lossy_link.xml"

_link: list[netns.NetworkNamespace] = []


def link_unavailable_reason() -> str | None:
    """None if the lossy link can be made here, else one line saying why (namespaces not permitted...)."""
    return netns.unavailable_reason()


def lossy_link(loss_percent: int = 0, link_mbit: float = 0.0, log_group: int | None = None
               ) -> netns.NetworkNamespace:
    """The kernel's lossy link (made on first use), set to drop ``loss_percent`` % of the UDP datagrams
    sent to odd (data) ports and, with ``link_mbit`` > 0, to carry at most that many Mbit/s.
    With ``log_group``, each dropped datagram is also logged to that netfilter log group, one at a
    time (``queue-threshold 1``), where a capture reads it (:mod:`course_helpers.core.rtps_capture`).

    Raises CourseError (with the one-line reason) where namespaces cannot be made.
    """
    reason = link_unavailable_reason()
    if reason is not None:
        raise CourseError(f"the lossy link needs a private network namespace, and {reason}")
    if not _link or not _link[0].alive:
        _link[:] = [netns.create(LINK_LABEL)]
    link = _link[0]
    rules = [f"flush table inet {NFT_TABLE}" if _has_table(link) else f"add table inet {NFT_TABLE}"]
    if loss_percent:
        log = f"log group {int(log_group)} queue-threshold 1 " if log_group is not None else ""
        rules += [f"add chain inet {NFT_TABLE} input {{ type filter hook input priority 0; policy accept; }}",
                  f"add rule inet {NFT_TABLE} input udp dport & 1 == 1 numgen random mod 100 < "
                  f"{int(loss_percent)} {log}drop"]  # odd ports: user traffic (see the module docstring)
    link.run("nft", "; ".join(rules))
    if link_mbit:
        burst = max(MIN_BURST_BYTES, int(link_mbit * 1e6 / 8 / 100))  # 10 ms of traffic, at least
        link.run("tc", "qdisc", "replace", "dev", "lo", "root", "tbf", "rate", f"{link_mbit:g}mbit",
                 "burst", str(burst), "latency", f"{TBF_LATENCY_MS}ms")
    else:
        link.run("tc", "qdisc", "del", "dev", "lo", "root", check=False)  # none there: fine
    return link


def _has_table(link: netns.NetworkNamespace) -> bool:
    code, _ = link.run("nft", "list", "table", "inet", NFT_TABLE, check=False)
    return code == 0


def link_env(directory: str) -> dict:
    """Environment of a process on the link: the link's Fast DDS profile (see the module docstring).

    The range is SYSTEM_DEFAULT, so that rmw_fastrtps leaves the transports to the profile (for
    LOCALHOST it would set up shared memory and UDP itself).
    """
    writer = ('  <data_writer profile_name="course_link_writer" is_default_profile="true">\n'
              f"    <times><heartbeatPeriod><sec>0</sec><nanosec>{round(HEARTBEAT_S * 1e9)}</nanosec>"
              "</heartbeatPeriod></times>\n  </data_writer>\n")
    text = profile_xml(("UDPv4",)).replace("</profiles>", writer + "</profiles>")
    return {RANGE_ENV: "SYSTEM_DEFAULT", PROFILE_ENV: write_profile(directory, PROFILE, text)}


def link_settings(link: netns.NetworkNamespace) -> str:
    """What the link's loopback does now: its nftables rules and queueing discipline (text)."""
    return link.run("nft", "list", "ruleset")[1] + link.run("tc", "qdisc", "show", "dev", "lo")[1]


def close_link() -> None:
    """Remove the lossy link (its namespace ends with its holder)."""
    if _link:
        _link.pop().close()


class RemoteSubscriber:
    """The kernel's view of a :class:`ReportingLabSubscriber` running on the link.

    It has the attributes :func:`run_experiment` reads from a local subscriber (``delivered``,
    ``gaps``, ``lost_events``, ``first_seq``, ``last_seq``, ``last_arrival``, :meth:`latency`),
    taken from the child's newest report; :meth:`finish` stops the child and keeps its final totals.
    """

    def __init__(self, child: processes.ChildProcess):
        self.child = child
        self._final: dict | None = None

    def _counts(self) -> dict:
        return self._final or self.child.last("progress") or {}

    @property
    def matched(self) -> bool:
        return bool(self._counts().get("matched"))

    delivered = property(lambda self: self._counts().get("delivered", 0))
    gaps = property(lambda self: self._counts().get("gaps", 0))
    lost_events = property(lambda self: self._counts().get("lost_events", 0))
    first_seq = property(lambda self: self._counts().get("first_seq"))
    last_seq = property(lambda self: self._counts().get("last_seq", 0))
    last_arrival = property(lambda self: self._counts().get("last_arrival", 0.0))

    def latency(self) -> dict:
        """p50/p90/p99/max in ms, as the child computed them (None values before the first sample)."""
        return self._counts().get("latency_ms") or {"p50": None, "p90": None, "p99": None, "max": None}

    def finish(self) -> None:
        """Stop the subscriber's process; its last report holds the exact totals."""
        processes.stop([self.child.label], group=self.child.group)
        self._final = self.child.last("final") or self.child.last("progress")
