"""Two machines on one box: what the discovery range and static peers do across a real link.

Two network namespaces (:mod:`course_helpers.core.netns`) stand for two computers: each has its own
loopback and one interface of a veth pair, with its own address (``10.77.0.1`` and ``10.77.0.2``,
which exist only inside these namespaces). A talker runs on machine A, a listener on machine B,
both course children. Shared memory is off (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``): two computers
share no memory, so everything crosses the link.

:func:`two_machines` runs the settings of ``SETTINGS`` one after the other and returns a
:class:`LinkResult` for each: did the listener hear the talker, how long discovery took across
the link (from the later of the two nodes' start to the first message), and how many bytes the
link carried. :func:`link_table` prints them.
"""

from __future__ import annotations

from dataclasses import dataclass

from course_helpers.core import netns, processes
from course_helpers.core.dds_config import PROFILE_ENV, profile_xml, write_profile
from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until
from course_helpers.nodes.chatter import Listener, make_talker

ADDRESS_A, ADDRESS_B = "10.77.0.1", "10.77.0.2"  # private: only inside the two namespaces
PROFILE = "course_two_machines.xml"  # the course's discovery timing; rmw sets the transports
RATE_HZ = 20.0
START_TIMEOUT_S = 20.0
MIN_WINDOW_S = 3.0  # a pair that did not meet gets at least this long (and 5x the slowest that did)
NFT_TABLE = "two_machines"
# name: (environment of both machines, static peers?, multicast dropped on the link?)
SETTINGS = {
    "LOCALHOST": ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}, False, False),
    "SUBNET": ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, False, False),
    "SUBNET, multicast dropped": ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, False, True),
    "LOCALHOST + ROS_STATIC_PEERS, multicast dropped": (
        {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}, True, True),
}


@dataclass
class LinkResult:
    """One setting across the link."""

    setting: str
    env_a: dict  # what machine A's processes had set
    env_b: dict
    multicast_dropped: bool
    heard: bool  # the listener on B heard the talker on A
    discovery_s: float | None  # from the later node's start to the first message (None: not heard)
    window_s: float  # how long a pair that did not meet was given
    link_bytes: int  # bytes machine B's interface received meanwhile


class TwoMachines:
    """Two namespaces joined by a veth pair; ``run(setting)`` runs one talker/listener pair across it."""

    def __init__(self, log_dir: str):
        self.a = netns.create("machine_a")
        try:
            self.b = netns.create("machine_b", owner=self.a)
            netns.connect(self.a, self.b, ADDRESS_A, ADDRESS_B)
        except CourseError:
            self.close()
            raise
        self.profile = write_profile(log_dir, PROFILE, profile_xml(()))

    def _drop_multicast(self, drop: bool) -> None:
        for machine in (self.a, self.b):
            machine.run("nft", f"add table inet {NFT_TABLE}; flush table inet {NFT_TABLE}")
            if drop:
                chain = f"add chain inet {NFT_TABLE} input {{ type filter hook input priority 0; }}"
                machine.run("nft", f"{chain}; add rule inet {NFT_TABLE} input ip daddr 224.0.0.0/4 drop")

    def run(self, setting: str, window_s: float = MIN_WINDOW_S) -> LinkResult:
        """Talker on A, listener on B, with ``setting`` (a key of SETTINGS); stops both at the end."""
        if setting not in SETTINGS:
            raise CourseError(f"setting must be one of {list(SETTINGS)}, got {setting!r}")
        env, peers, drop = SETTINGS[setting]
        base = {**env, "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4", PROFILE_ENV: self.profile}
        env_a = {**base, **({"ROS_STATIC_PEERS": ADDRESS_B} if peers else {})}
        env_b = {**base, **({"ROS_STATIC_PEERS": ADDRESS_A} if peers else {})}
        self._drop_multicast(drop)
        before = self.b.received_bytes("veth_b")
        labels = ["machine_a_talker", "machine_b_listener"]
        try:
            talker = self.a.start(labels[0], processes.python_target_argv(
                make_talker, {"name": "talker_on_a", "rate_hz": RATE_HZ}), env=env_a)
            listener = self.b.start(labels[1], processes.python_target_argv(
                Listener, {"name": "listener_on_b", "report_heard": True}), env=env_b)
            for child in (talker, listener):
                child.wait_for_report("ready", START_TIMEOUT_S, "its node to start")
            both_up = max(child.channel.stamped("ready")[0][0] for child in (talker, listener))
            poll_until(lambda: listener.last("heard") is not None or not listener.alive, window_s)
            heard = listener.channel.stamped("heard")
            return LinkResult(setting, _shown(env_a), _shown(env_b), drop, bool(heard),
                              heard[0][0] - both_up if heard else None, window_s,
                              self.b.received_bytes("veth_b") - before)
        finally:
            processes.stop(labels)

    def close(self) -> None:
        """Stop both machines (their namespaces go with their holders)."""
        for name in ("b", "a"):
            if hasattr(self, name):
                getattr(self, name).close()


def _shown(env: dict) -> dict:
    return {key: value for key, value in env.items() if key.startswith("ROS_")}


def two_machines(log_dir: str, settings=tuple(SETTINGS)) -> list[LinkResult]:
    """Run each of ``settings`` across a fresh pair of machines; the link is removed at the end.

    The pairs that do not meet are given ``max(MIN_WINDOW_S, 5 x the slowest discovery that did)``,
    so the settings that connect run first. Raises CourseError with the one-line reason where
    namespaces cannot be made.
    """
    reason = netns.unavailable_reason()
    if reason is not None:
        raise CourseError(f"two machines on one box need network namespaces, and {reason}")
    machines = TwoMachines(log_dir)
    try:
        results = {}
        for setting in settings:
            results[setting] = machines.run(setting)
        met = [r.discovery_s for r in results.values() if r.heard]
        window = max([MIN_WINDOW_S, *(5 * s for s in met)])
        for setting, result in results.items():  # a pair that did not meet gets the full window
            if not result.heard and result.window_s < window:
                results[setting] = machines.run(setting, window)
        return [results[s] for s in settings]
    finally:
        machines.close()


def link_table(results: list[LinkResult]) -> str:
    """A text table: setting, did they meet, discovery time, bytes over the link."""
    lines = [f"{'setting':<50}{'B heard A':<11}{'discovery':<12}link bytes"]
    for r in results:
        found = f"{r.discovery_s:.2f} s" if r.heard else f"- ({r.window_s:.0f} s)"
        lines.append(f"{r.setting:<50}{'yes' if r.heard else 'no':<11}{found:<12}{r.link_bytes}")
    return "\n".join(lines)
