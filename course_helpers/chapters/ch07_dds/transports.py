"""One message bounced between two nodes three ways: in one process, over shared memory, over UDP.

:func:`measure_transports` runs a :class:`Ping` node (procedure :func:`run_ping`) and a
:class:`Pong` node in child processes and collects the round-trip times the ping reports;
:func:`plot_transports` draws latency and throughput against message size.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

from rclpy.node import Node
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import UInt8MultiArray

from course_helpers.core.channel import report
from course_helpers.core.child_results import run_child_for_result
from course_helpers.core.dds_config import udp_loopback_env
from course_helpers.core.errors import CourseError
from course_helpers.core.runtime import get_runtime
from course_helpers.core.spawning import CHILD_HANG_S
from course_helpers.core.units import format_bytes

TRANSPORT_LABELS = {
    "intra-process": "both nodes in one process: Fast DDS hands the sample over in memory",
    "shared memory": "two processes on one machine: Fast DDS's default between local processes",
    "UDP": "two processes, UDP through the loopback interface (as between two machines)",
}
# Reliable, so every round trip completes (a lost fragment is resent).
BOUNCE_QOS = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
WARM_UP_TRIES = 20  # warm-up messages until the first comes back (both directions matched)
WARM_UP_WAIT_S = 0.5  # s to wait for each


class Pong(Node):
    """Sends every message it gets on ``ping`` straight back on ``pong``."""

    def __init__(self, name: str = "pong"):
        super().__init__(name)
        self.publisher = self.create_publisher(UInt8MultiArray, "pong", BOUNCE_QOS)
        self.subscription = self.create_subscription(UInt8MultiArray, "ping", self.publisher.publish,
                                                     BOUNCE_QOS)


class Ping(Node):
    """Sends messages on ``ping`` one at a time, each as soon as the previous one came back on ``pong``.

    Everything happens in the executor's thread, as in a single-threaded program: the echo's
    callback sends the next message. Each message carries its number in ``layout.data_offset``,
    so a late echo of a message given up on is not taken for the current one.
    """

    def __init__(self):
        super().__init__("ping")
        self.queue: list[UInt8MultiArray] = []  # still to send
        self.in_flight: tuple[int, float] | None = None  # (number, time.perf_counter() when sent)
        self.number = 0
        self.round_trips: list[float] = []  # seconds, of the current :meth:`bounce`
        self.publisher = self.create_publisher(UInt8MultiArray, "ping", BOUNCE_QOS)
        self.subscription = self.create_subscription(UInt8MultiArray, "pong", self.on_pong, BOUNCE_QOS)

    def matched(self) -> bool:
        """True once a pong subscribes to ``ping`` and publishes on ``pong``."""
        return self.publisher.get_subscription_count() > 0 and self.subscription.get_publisher_count() > 0

    def bounce(self, messages: list[UInt8MultiArray]) -> None:
        """Start sending ``messages`` one after the other (call it in the executor's thread)."""
        self.round_trips = []
        self.queue = list(messages)
        self.send_next()

    def finished(self) -> bool:
        """True once every message of the last :meth:`bounce` came back."""
        return self.in_flight is None and not self.queue

    def send_next(self) -> None:
        if not self.queue:
            self.in_flight = None
            return
        message = self.queue.pop(0)
        self.number += 1
        message.layout.data_offset = self.number
        self.in_flight = (self.number, time.perf_counter())
        self.publisher.publish(message)

    def on_pong(self, msg: UInt8MultiArray) -> None:
        arrived = time.perf_counter()
        if self.in_flight is None or msg.layout.data_offset != self.in_flight[0]:
            return  # the echo of a message given up on
        self.round_trips.append(arrived - self.in_flight[1])
        self.send_next()


def run_ping(sizes: list[int], round_trips: int = 10, with_pong: bool = False,
             timeout_s: float = CHILD_HANG_S) -> None:
    """Child-process procedure: bounce messages of each size off a pong node.

    Args:
        sizes: message sizes in bytes.
        round_trips: round trips counted per size (one more warms buffers up, not counted).
        with_pong: run the :class:`Pong` node in this same process (intra-process delivery).
        timeout_s: seconds to wait for the pong, and for each round trip.

    Reports ``result`` with ``round_trips``: {"<size>": [seconds, ...]}.
    """
    rt = get_runtime()
    if with_pong:
        rt.add(Pong, console=False)
    ping = rt.add(Ping, console=False)
    rt.wait_until(ping.matched, timeout_s, "a pong node")
    warm = UInt8MultiArray(data=bytes(16))
    for _ in range(WARM_UP_TRIES):  # until the pong's publisher has matched our subscription too
        rt.call_in_executor(ping.bounce, [warm])
        if rt.poll_until(ping.finished, WARM_UP_WAIT_S):
            break
    results: dict[str, list[float]] = {}
    for size in sizes:
        rt.call_in_executor(ping.bounce, [UInt8MultiArray(data=bytes(size))] * (round_trips + 1))
        rt.wait_until(ping.finished, timeout_s * (round_trips + 1),
                      f"{round_trips + 1} round trips of {size} bytes")
        results[str(size)] = ping.round_trips[1:]
    report("result", round_trips=results)


@dataclass
class TransportResult:
    """Round-trip times (seconds) per transport and message size."""

    sizes: list[int]
    round_trips: dict[str, dict[int, list[float]]]

    def one_way_ms(self, transport: str, size: int) -> float:
        """Median round trip / 2, in milliseconds."""
        return statistics.median(self.round_trips[transport][size]) / 2 * 1e3

    def fastest_ms(self, transport: str, size: int) -> float:
        """The fastest round trip / 2, in milliseconds: what is left when nothing got in the way."""
        return min(self.round_trips[transport][size]) / 2 * 1e3

    def throughput_mb_s(self, transport: str, size: int) -> float:
        """Megabytes per second if messages of ``size`` followed each other at the one-way latency."""
        return size / (self.one_way_ms(transport, size) / 1e3) / 1e6


def measure_transports(rt, sizes=(1_000, 100_000, 500_000, 2_000_000), round_trips: int = 10,
                       transports=tuple(TRANSPORT_LABELS)) -> TransportResult:
    """Bounce messages of each size between a ping and a pong node, all in child processes.

    Args:
        rt: the kernel's runtime.
        sizes: message sizes, 1 byte .. 8 MB.
        round_trips: round trips per size, 1..200.
        transports: names from :data:`TRANSPORT_LABELS`. 'intra-process': ping and pong in one
            child; 'shared memory': two children with the kernel's settings; 'UDP': two children
            restricted to UDP on 127.0.0.1.

    Returns a :class:`TransportResult`. Raises ``CourseError`` if a size got no round trip.
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
            result = run_child_for_result(rt, "ping", run_ping, {**params, "with_pong": True}, timeout=120)
        else:
            env = udp_loopback_env(rt.log_dir) if transport == "UDP" else {}
            rt.spawn("pong", Pong, env=env, wait_for="/pong")
            try:
                result = run_child_for_result(rt, "ping", run_ping, params, env, timeout=120)
            finally:
                rt.stop_child("pong")
        out[transport] = {int(size): times for size, times in result["round_trips"].items()}
        missing = [s for s in sizes if not out[transport].get(s)]
        if missing:
            raise CourseError(f"{transport}: no round trip completed for sizes {missing}")
    return TransportResult(sizes, out)


def plot_transports(result: TransportResult):
    """A matplotlib figure: one-way latency against message size (log-log), and throughput per size."""
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
    right.set_xticks(range(len(result.sizes)), [format_bytes(s, binary=False) for s in result.sizes])
    right.set_xlabel("message size")
    right.set_ylabel("MB/s (size / one-way latency)")
    right.set_title("throughput one message at a time", fontsize=10)
    right.grid(alpha=0.3, axis="y")
    fig.suptitle("The same message, three ways between two nodes (reliable QoS, measured now)", fontsize=11)
    fig.tight_layout()
    return fig
