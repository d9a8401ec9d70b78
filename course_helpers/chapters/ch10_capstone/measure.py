"""Measuring the running robot: what reaches a topic's reader, and each endpoint's QoS.

:func:`measure_delivery` counts the stamped messages on a topic and finds the frames that
never made it from gaps between the stamps (and, in the same window, collects the times a
node reports for its frames); :func:`endpoint_qos` and :func:`qos_table` read the reliability
and durability of every endpoint from the live graph.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field

from geometry_msgs.msg import PointStamped
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64

from course_helpers.core.errors import WaitTimeout
from course_helpers.core.names import full_name, is_hidden
from course_helpers.core.qos_dict import policy_name
from course_helpers.core.waiting import poll_until

MIN_MESSAGES = 3  # a window holds at least this many messages (two gaps between stamps)...
MIN_MESSAGES_WAIT_S = 10.0  # ...if they come within this much longer [s]


@dataclass
class Delivery:
    """What arrived on a stamped topic during a measurement."""

    topic: str
    expected_hz: float
    seconds: float
    received: int
    missed: int
    mean_age_ms: float
    callback_ms: list[float] = field(default_factory=list)  # a node's own time per frame [ms], if asked
    span_s: float = float("nan")  # from the first to the last stamp received [s]
    gap_frames: list[float] = field(default_factory=list)  # between consecutive stamps [frame periods]

    @property
    def mean_callback_ms(self) -> float:
        """The mean of :attr:`callback_ms` [ms] (nan when none were collected)."""
        return sum(self.callback_ms) / len(self.callback_ms) if self.callback_ms else float("nan")

    @property
    def median_callback_ms(self) -> float:
        """The median time of the callbacks that :attr:`gap_frames` follow [ms] (nan when none).

        The k-th time collected belongs to the k-th message, and the gap after the last message
        falls outside the window, so its callback is left out; on a machine so busy that only a
        few messages arrive, that one callback would otherwise decide the median."""
        paired = self.callback_ms[:len(self.gap_frames)] or self.callback_ms
        return statistics.median(paired) if paired else float("nan")

    @property
    def median_gap_frames(self) -> float:
        """The median gap between consecutive stamps received [frame periods] (nan: fewer than 2)."""
        return statistics.median(self.gap_frames) if self.gap_frames else float("nan")

    @property
    def frames_per_message(self) -> float:
        """Source frames per message received, from the stamps' span (1.0: every frame; nan: < 2).

        Unlike the rate, it does not depend on where the window's edges fall between two messages."""
        return self.span_s * self.expected_hz / (self.received - 1) if self.received > 1 else float("nan")

    @property
    def delivered_hz(self) -> float:
        """Messages received per second of the measurement [Hz]."""
        return self.received / self.seconds if self.seconds else 0.0

    @property
    def missed_fraction(self) -> float:
        """The share of the camera's frames (0..1) that never produced a message."""
        total = self.received + self.missed
        return self.missed / total if total else 1.0

    def __str__(self) -> str:
        return (f"{self.topic}: {self.delivered_hz:.1f} Hz delivered of {self.expected_hz:g} Hz, "
                f"{self.missed_fraction:.0%} of frames missed, mean age {self.mean_age_ms:.0f} ms")


def measure_delivery(rt, topic: str, msg_type=PointStamped, seconds: float = 3.0,
                     expected_hz: float = 30.0, qos: QoSProfile | int = 50,
                     first_timeout: float = 20.0, timing_topic: str | None = None) -> Delivery:
    """Count messages on ``topic`` for ``seconds``; find missed frames from gaps in header stamps.

    Args: ``rt`` the runtime, ``topic`` a topic of stamped messages (``msg_type``),
    ``expected_hz`` the rate of the source [Hz], ``qos`` the reader's profile or depth,
    ``timing_topic`` a std_msgs/Float64 topic on which the node publishes how long each frame
    took [ms] (perception's ``~/processing_time_ms``), read in the same window.
    Returns: a :class:`Delivery`; its missed frames come from :func:`count_missed`, its age
    is receive time minus the camera's stamp (same machine, same clock). The window starts
    0.3 s after the first message and lasts ``seconds``, or longer until :data:`MIN_MESSAGES` came
    (at most :data:`MIN_MESSAGES_WAIT_S` s more); if nothing arrives within ``first_timeout`` s, the
    result says 0 messages (all missed). The wait ends at the first message, so the default costs
    nothing when data flows; it leaves room for a just-spawned node to be matched and to
    finish its first frame (about 3 s on two busy cores; more than 8 s while the grading tests ran
    beside four other test workers).
    """
    stamps: list[float] = []
    ages: list[float] = []
    timings: list[float] = []

    def on_message(msg) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        stamps.append(stamp)
        ages.append(time.time() - stamp)

    sub = rt.graph.create_subscription(msg_type, topic, on_message, qos)
    timing = (rt.graph.create_subscription(Float64, timing_topic, lambda m: timings.append(m.data), 50)
              if timing_topic else None)
    try:
        try:
            rt.wait_until(lambda: len(stamps) > 0, first_timeout, f"a first message on {topic}")
        except WaitTimeout:
            return Delivery(topic, expected_hz, first_timeout, 0, round(first_timeout * expected_hz),
                            float("nan"))
        time.sleep(0.3)  # let the pipeline settle
        stamps.clear()
        ages.clear()
        timings.clear()
        started = time.monotonic()
        time.sleep(seconds)
        # a slow callback on a very busy machine: go on until there is a gap to measure, within reason
        poll_until(lambda: len(stamps) >= MIN_MESSAGES, MIN_MESSAGES_WAIT_S)
        elapsed = time.monotonic() - started
        got = sorted(stamps)
        age = list(ages)
        took = list(timings)
    finally:
        rt.call_in_executor(rt.graph.destroy_subscription, sub)
        if timing is not None:
            rt.call_in_executor(rt.graph.destroy_subscription, timing)
    return Delivery(topic, expected_hz, elapsed, len(got), count_missed(got, expected_hz, elapsed),
                    1000.0 * sum(age) / len(age) if age else float("nan"), took,
                    got[-1] - got[0] if got else float("nan"),
                    [(b - a) * expected_hz for a, b in zip(got, got[1:], strict=False)])


def count_missed(stamps: list[float], expected_hz: float, seconds: float) -> int:
    """Frames that never arrived, from the sorted source ``stamps`` [s] received in ``seconds``.

    A gap of k frame periods between consecutive stamps means k - 1 lost frames. A source
    at ``expected_hz`` also sent about ``seconds * expected_hz`` frames in the window, so
    with only a few messages (a very slow callback) the shortfall is counted where the gaps
    cannot show it. Returns the larger of the two counts.
    """
    period = 1.0 / expected_hz
    in_gaps = sum(max(0, round((b - a) / period) - 1) for a, b in zip(stamps, stamps[1:], strict=False))
    return max(in_gaps, round(seconds * expected_hz) - len(stamps))


def endpoint_qos(rt, topic: str) -> dict[str, list[tuple[str, str, str]]]:
    """Publishers and subscriptions of ``topic``: (node, reliability, durability), sorted.

    The history depth is not in the list: it is a local setting of each endpoint and is
    not exchanged during discovery (``ros2 topic info -v`` shows it as UNKNOWN).
    """
    def rows(infos):
        return sorted((full_name(i.node_namespace, i.node_name),
                       policy_name(i.qos_profile.reliability).lower(),
                       policy_name(i.qos_profile.durability).lower())
                      for i in infos)

    return {"publishers": rows(rt.graph.get_publishers_info_by_topic(topic)),
            "subscriptions": rows(rt.graph.get_subscriptions_info_by_topic(topic))}


def qos_table(rt, namespace: str, topics: list[str]) -> str:
    """Who publishes and subscribes each of ``topics`` (relative to ``namespace``), with their QoS.

    Returns: an aligned text table, one row per endpoint (hidden nodes left out).
    """
    lines = [f"{'topic':<26} {'endpoint':<10} {'node':<28} {'reliability':<12} durability"]
    for topic in topics:
        full = topic if topic.startswith("/") else full_name(namespace, topic)
        info = endpoint_qos(rt, full)
        for kind, label in (("publishers", "pub"), ("subscriptions", "sub")):
            for node, reliability, durability in info[kind]:
                if is_hidden(node):
                    continue  # the runtime's own hidden node
                lines.append(f"{full:<26} {label:<10} {node:<28} {reliability:<12} {durability}")
    return "\n".join(lines)
