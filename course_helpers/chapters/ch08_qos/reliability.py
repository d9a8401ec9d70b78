"""Reliability: large messages from another process, best effort against reliable, with the
subscription's ``message_lost`` event.

The notebook writes the listener (its two subscriptions, QoS profiles and ``message_lost``
callbacks); :func:`run_stream` starts :class:`~.publishers.StreamPublisher` in a child process
against it and collects what the listener recorded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from course_helpers.chapters.ch08_qos.publishers import StreamPublisher
from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until

KINDS = ("best_effort", "reliable")
RESEND_WAIT_S = 5.0  # s a reliable subscription may take to get what was resent
TAIL_S = 0.3  # s for the last best-effort messages and loss events after everything was sent


@dataclass
class ReliabilityResult:
    """Which numbered messages each subscription got, and the message_lost events reported."""

    sent: int
    size: int
    rate_hz: float
    received: dict[str, list[int]]  # 'best_effort' / 'reliable' -> message numbers, sorted
    lost_reported: dict[str, int]  # message_lost total_count per subscription

    def missing(self, kind: str) -> int:
        """How many of the messages sent never reached subscription ``kind``."""
        return self.sent - len(self.received[kind])


def run_stream(rt, listener, size: int = 500_000, rate_hz: float = 60.0, count: int = 90,
               timeout: float = 20.0) -> ReliabilityResult:
    """Start :class:`StreamPublisher` in a child process against ``listener``, then remove both.

    Args:
        rt: the kernel's runtime.
        listener: a spinning node subscribed to ``stream_best_effort`` and ``stream_reliable``, with
            ``received`` ({kind: [message numbers]}) and ``lost`` ({kind: message_lost total_count})
            for the kinds 'best_effort' and 'reliable'.
        size: bytes per message.
        rate_hz: messages per second.
        count: messages per topic, 1..1000.
        timeout: seconds the publisher may take to send everything.

    Waits until everything is sent, then (up to 5 s) until the reliable subscription has every
    message, as resends take a while. Returns a :class:`ReliabilityResult`.
    """
    if not 1 <= count <= 1000:
        raise CourseError(f"count must be 1..1000, got {count}")
    if not all(isinstance(getattr(listener, attr, None), dict) and set(KINDS) <= set(getattr(listener, attr))
               for attr in ("received", "lost")):
        raise CourseError("the listener needs self.received and self.lost, dicts with the keys "
                          "'best_effort' and 'reliable'")
    child = rt.spawn("stream_publisher", StreamPublisher,
                     params={"size": size, "rate_hz": rate_hz, "count": count})
    try:
        child.wait_for_report("sent", timeout, "the stream publisher to send everything")
        poll_until(lambda: len(set(listener.received["reliable"])) >= count, RESEND_WAIT_S)
        time.sleep(TAIL_S)
    finally:
        rt.stop_child("stream_publisher")
        rt.remove(listener)
    return ReliabilityResult(count, size, rate_hz, {k: sorted(set(listener.received[k])) for k in KINDS},
                             {k: listener.lost[k] for k in KINDS})


def plot_reliability(result: ReliabilityResult):
    """A matplotlib figure: a barcode per subscription, one tick per message number that arrived."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 2.4))
    rows = [("reliable", "#16a34a"), ("best_effort", "#dc2626")]
    for y, (kind, colour) in enumerate(rows):
        got = result.received[kind]
        ax.vlines(got, y - 0.35, y + 0.35, color=colour, linewidth=1.2)
        ax.text(result.sent + 1, y, f"{len(got)}/{result.sent}", va="center", fontsize=9)
    ax.set_yticks(range(len(rows)), [k.replace("_", " ") for k, _ in rows])
    ax.set_xlim(-1, result.sent + 12)
    ax.set_xlabel("message number (a gap = never delivered)")
    ax.set_title(f"{result.sent} messages of {result.size / 1e6:g} MB at {result.rate_hz:g} Hz from another "
                 "process", fontsize=10)
    fig.tight_layout()
    return fig
