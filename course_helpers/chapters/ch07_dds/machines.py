"""Two machines on one box: what the discovery range and static peers do across a real link.

Two network namespaces (:mod:`course_helpers.core.netns`) stand for two computers: each has its own
loopback and one interface of a veth pair, with its own address (``10.77.0.1`` and ``10.77.0.2``,
which exist only inside these namespaces). A talker runs on machine A, a listener on machine B,
both course children. Shared memory is off (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``): two computers
share no memory, so everything crosses the link.

:func:`two_machines` runs every setting of ``SETTINGS`` at the same time, each on a pair of machines
of its own, and returns a :class:`LinkResult` for each: did the listener hear the talker, how long
discovery took across the link (from the later of the two nodes' start to the first message), and
how many bytes the link carried. A pair that did not meet was watched for ``WINDOW_FACTOR`` times
the slowest discovery of the pairs that did. :func:`link_table` prints them.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from course_helpers.core import netns, processes
from course_helpers.core.dds_config import PROFILE_ENV, profile_xml, write_profile
from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until
from course_helpers.nodes.chatter import Listener, make_talker

ADDRESS_A, ADDRESS_B = "10.77.0.1", "10.77.0.2"  # private: only inside each pair of namespaces
PROFILE = "course_two_machines.xml"  # the course's discovery timing; rmw sets the transports
RATE_HZ = 20.0
START_TIMEOUT_S = 20.0
WINDOW_FACTOR = 10  # a pair that did not meet is watched this many times the slowest pair that did ...
MIN_WINDOW_S = 0.5  # ... and at least this long (five of the course's announcement periods)
NOBODY_MET_WINDOW_S = 5.0  # how long to watch when no pair has met at all
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
    window_s: float  # how long a pair that did not meet was watched
    link_bytes: int  # bytes machine B's interface received meanwhile


class TwoMachines:
    """Two namespaces joined by a veth pair, for one setting; :meth:`start` puts a node on each."""

    def __init__(self, index: int, setting: str, profile: str):
        if setting not in SETTINGS:
            raise CourseError(f"setting must be one of {list(SETTINGS)}, got {setting!r}")
        self.setting = setting
        self.profile = profile
        self.labels = [f"machine_a{index}_talker", f"machine_b{index}_listener"]
        self.a = netns.create(f"machine_a{index}")
        try:
            self.b = netns.create(f"machine_b{index}", owner=self.a)
            netns.connect(self.a, self.b, ADDRESS_A, ADDRESS_B)
            if SETTINGS[setting][2]:
                self._drop_multicast()
        except CourseError:
            self.close()
            raise
        self.talker = self.listener = None
        self.bytes_before = 0

    def _drop_multicast(self) -> None:
        rule = f"add rule inet {NFT_TABLE} input ip daddr 224.0.0.0/4 drop"
        for machine in (self.a, self.b):
            machine.run("nft", f"add table inet {NFT_TABLE}; add chain inet {NFT_TABLE} input "
                               f"{{ type filter hook input priority 0; }}; {rule}")

    def environments(self) -> tuple[dict, dict]:
        """The environment of machine A's and of machine B's process."""
        env, peers, _drop = SETTINGS[self.setting]
        base = {**env, "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4", PROFILE_ENV: self.profile}
        return ({**base, **({"ROS_STATIC_PEERS": ADDRESS_B} if peers else {})},
                {**base, **({"ROS_STATIC_PEERS": ADDRESS_A} if peers else {})})

    def start(self) -> None:
        """Start the talker on A and the listener on B (returns at once)."""
        env_a, env_b = self.environments()
        self.bytes_before = self.b.received_bytes("veth_b")
        self.talker = self.a.start(self.labels[0], processes.python_target_argv(
            make_talker, {"name": "talker_on_a", "rate_hz": RATE_HZ}), env=env_a)
        self.listener = self.b.start(self.labels[1], processes.python_target_argv(
            Listener, {"name": "listener_on_b", "report_heard": True}), env=env_b)

    def both_up(self) -> float:
        """When the later of the two nodes was created (the machine's monotonic clock); waits for it."""
        for child in (self.talker, self.listener):
            child.wait_for_report("ready", START_TIMEOUT_S, "its node to start")
        return max(child.channel.stamped("ready")[0][0] for child in (self.talker, self.listener))

    def discovery_s(self) -> float | None:
        """From both nodes up to the listener's first message; None while it has heard nothing."""
        heard = self.listener.channel.stamped("heard")
        return heard[0][0] - self.both_up() if heard else None

    def result(self, window_s: float) -> LinkResult:
        env_a, env_b = self.environments()
        found = self.discovery_s()
        return LinkResult(self.setting, _shown(env_a), _shown(env_b), SETTINGS[self.setting][2],
                          found is not None, found, window_s,
                          self.b.received_bytes("veth_b") - self.bytes_before)

    def close(self) -> None:
        """Stop both nodes and both machines (the namespaces go with their holders)."""
        processes.stop(self.labels)
        for name in ("b", "a"):
            if hasattr(self, name):
                getattr(self, name).close()


def _shown(env: dict) -> dict:
    return {key: value for key, value in env.items() if key.startswith("ROS_")}


def watch_window(met: list[float]) -> float:
    """How long a pair that has not met is watched, given the discovery times of those that did."""
    return max(MIN_WINDOW_S, WINDOW_FACTOR * max(met)) if met else NOBODY_MET_WINDOW_S


def two_machines(log_dir: str, settings=tuple(SETTINGS)) -> list[LinkResult]:
    """Run each of ``settings`` on a pair of machines of its own, all at the same time; remove them after.

    Every pair is watched until its listener has heard, or for :func:`watch_window` of the pairs that
    met. Raises CourseError with the one-line reason where namespaces cannot be made.
    """
    reason = netns.unavailable_reason()
    if reason is not None:
        raise CourseError(f"two machines on one box need network namespaces, and {reason}")
    profile = write_profile(log_dir, PROFILE, profile_xml(()))
    pairs: list[TwoMachines] = []

    def make(index: int, setting: str) -> None:
        pair = TwoMachines(index, setting, profile)
        pairs.append(pair)
        pair.start()

    try:
        with ThreadPoolExecutor(max_workers=len(settings)) as pool:  # the pairs are made at the same time
            for made in [pool.submit(make, i, setting) for i, setting in enumerate(settings)]:
                made.result()
        pairs.sort(key=lambda pair: settings.index(pair.setting))
        up = {pair.setting: pair.both_up() for pair in pairs}

        def window() -> float:
            return watch_window([s for s in (pair.discovery_s() for pair in pairs) if s is not None])

        def settled() -> bool:
            now = time.monotonic()
            return all(pair.discovery_s() is not None or now - up[pair.setting] >= window() for pair in pairs)

        poll_until(settled, START_TIMEOUT_S, period=0.02)
        final = window()
        return [pair.result(final) for pair in pairs]
    finally:
        processes.stop([label for pair in pairs for label in pair.labels])  # together: as long as the slowest
        for pair in pairs:
            pair.close()


def link_table(results: list[LinkResult]) -> str:
    """A text table: setting, did they meet, discovery time (or how long they were watched), link bytes."""
    lines = [f"{'setting':<50}{'B heard A':<11}{'discovery':<14}link bytes"]
    for r in results:
        found = f"{r.discovery_s:.2f} s" if r.heard else f"- ({r.window_s:.1f} s)"
        lines.append(f"{r.setting:<50}{'yes' if r.heard else 'no':<11}{found:<14}{r.link_bytes}")
    return "\n".join(lines)
