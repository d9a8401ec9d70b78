"""Deadline: offered and requested deadline-missed events while a publisher pauses.

The notebook writes the two nodes itself (a talker with ``paused`` and ``offered_missed``, a
listener with ``arrivals`` and ``requested_missed``); :func:`pause_talker` runs the schedule and
:meth:`DeadlineResult.from_nodes` collects what they recorded. :func:`demo_deadline` does the same
in one call, with plain nodes and lambdas.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import QoSProfile
from std_msgs.msg import String

from course_helpers.chapters.ch08_qos.cleanup import remove_nodes
from course_helpers.core.errors import CourseError
from course_helpers.core.qos_dict import seconds_to_duration


@dataclass
class DeadlineResult:
    """Arrival times and deadline-missed events (seconds since the demo started)."""

    deadline_s: float
    pause: tuple[float, float]
    arrivals: list[float]
    offered_missed: list[tuple[float, int]]  # (time, total_count) at the publisher
    requested_missed: list[tuple[float, int]]  # (time, total_count) at the subscription

    def missed_during_pause(self, which: str = "requested") -> int:
        """Deadline-missed events at the subscription ('requested') or the publisher ('offered')
        while the publisher was silent (up to one deadline after the pause)."""
        events = self.requested_missed if which == "requested" else self.offered_missed
        start, end = self.pause
        return sum(1 for t, _ in events if start < t <= end + self.deadline_s)

    def missed_outside_pause(self, which: str = "requested") -> int:
        """Deadline-missed events of ``which`` at any other time."""
        events = self.requested_missed if which == "requested" else self.offered_missed
        return len(events) - self.missed_during_pause(which)

    @classmethod
    def from_nodes(cls, talker, listener, start: float, deadline_s: float, pause: tuple) -> DeadlineResult:
        """What ``talker`` (``offered_missed``) and ``listener`` (``arrivals``, ``requested_missed``)
        recorded, as seconds since ``start`` (a ``time.monotonic()``). Events are ``(time.monotonic(),
        total_count)``, all of them kept; arrivals are ``time.monotonic()`` values, those before
        ``start`` left out."""
        def since(events):
            return [(t - start, count) for t, count in events]

        return cls(deadline_s, tuple(pause), [t - start for t in listener.arrivals if t >= start],
                   since(talker.offered_missed), since(listener.requested_missed))


def pause_talker(talker, pause: tuple = (1.0, 2.0), duration_s: float = 3.0) -> float:
    """Set ``talker.paused`` to True from ``pause[0]`` to ``pause[1]`` seconds from now, and return after
    ``duration_s`` seconds. The talker's own timer keeps running; its callback skips publishing while
    paused. Returns the start (``time.monotonic()``)."""
    if not 0 <= pause[0] < pause[1] <= duration_s:
        raise CourseError(f"pause must be (from, until) with 0 <= from < until <= duration_s, got {pause}")
    start = time.monotonic()
    for at, paused in ((pause[0], True), (pause[1], False), (duration_s, False)):
        time.sleep(max(0.0, start + at - time.monotonic()))  # the nodes run in the executor meanwhile
        talker.paused = paused
    return start


def demo_deadline(rt, period_s: float = 0.1, deadline_s: float = 0.3, pause: tuple = (1.0, 2.0),
                  duration_s: float = 3.0) -> DeadlineResult:
    """A publisher sends every ``period_s`` but is silent during ``pause``; both ends ask for ``deadline_s``.

    Args:
        rt: the kernel's runtime (both nodes run in it).
        period_s: seconds between messages; shorter than ``deadline_s``.
        deadline_s: the deadline both ends ask for.
        pause: (from, until) seconds after the start while the publisher is silent.
        duration_s: how long the demo runs.

    The one-call form of the notebook's deadline lesson (its nodes are plain nodes with lambdas):
    DDS checks the deadline at both ends, the publisher gets 'offered deadline missed', the
    subscription 'requested deadline missed', about once per ``deadline_s`` of silence.
    Returns a :class:`DeadlineResult`.
    """
    if not period_s < deadline_s:
        raise CourseError(f"period_s ({period_s}) must be shorter than deadline_s ({deadline_s})")
    profile = QoSProfile(depth=10, deadline=seconds_to_duration(deadline_s, "deadline_s"))
    listener = rt.node("qos_deadline_sub", console=False)
    listener.arrivals, listener.requested_missed = [], []
    listener.create_subscription(
        String, "qos_deadline", lambda _m: listener.arrivals.append(time.monotonic()), profile,
        event_callbacks=SubscriptionEventCallbacks(
            deadline=lambda s: listener.requested_missed.append((time.monotonic(), s.total_count))))
    talker = rt.node("qos_deadline_pub", console=False)
    talker.paused, talker.offered_missed = False, []
    publisher = talker.create_publisher(
        String, "qos_deadline", profile,
        event_callbacks=PublisherEventCallbacks(
            deadline=lambda s: talker.offered_missed.append((time.monotonic(), s.total_count))))
    try:
        rt.wait_until(lambda: publisher.get_subscription_count() > 0, 5.0, "matching")
        message = String(data="on time")
        talker.create_timer(period_s, lambda: None if talker.paused else publisher.publish(message))
        start = pause_talker(talker, pause, duration_s)
    finally:
        remove_nodes(rt, talker, listener)
    return DeadlineResult.from_nodes(talker, listener, start, deadline_s, pause)


def plot_deadline(result: DeadlineResult):
    """A matplotlib figure: arrivals as ticks, deadline-missed events as markers, the pause shaded."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 3.0))
    ax.axvspan(*result.pause, color="#fde68a", alpha=0.6, label="publisher silent")
    ax.vlines(result.arrivals, 1.65, 2.35, color="#2563eb", linewidth=1)
    ax.scatter([t for t, _ in result.offered_missed], [1] * len(result.offered_missed), marker="x",
               color="#dc2626", label="offered deadline missed (publisher)")
    ax.scatter([t for t, _ in result.requested_missed], [0] * len(result.requested_missed), marker="v",
               color="#9333ea", label="requested deadline missed (subscription)")
    ax.set_yticks([0, 1, 2], ["subscription\nevents", "publisher\nevents", "messages\narriving"])
    ax.set_ylim(-0.6, 2.8)
    ax.set_xlabel("time (s)")
    ax.set_title(f"Deadline {result.deadline_s:g} s: events fire while nothing arrives", fontsize=10)
    ax.legend(fontsize=8, loc="upper center", ncol=3, bbox_to_anchor=(0.5, -0.3))
    fig.tight_layout()
    return fig


# ====================================================================== lifespan
