"""Liveliness: when a subscription declares its publisher not alive, and what keeps it alive.

* :func:`demo_liveliness_kill` - a publisher process is killed with SIGKILL;
* :func:`demo_liveliness_manual` - a MANUAL_BY_TOPIC publisher goes quiet while its process lives
  (:class:`LivelinessTalker`, in a child process, reports ``start`` and its ``lost`` events).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.chapters.ch08_qos.publishers import QosTalker
from course_helpers.core.channel import report
from course_helpers.core.qos_dict import qos_from_dict

KINDS = ("automatic", "manual_by_topic")


@dataclass
class LivelinessResult:
    """Liveliness events (seconds since the demo started) and when the publisher was cut off."""

    lease_s: float
    cut_at: float  # the publisher was killed / stopped asserting
    resumed_at: float | None
    changed: dict[str, list[tuple[float, int, int]]]  # sub label -> (time, alive_count, not_alive_count)
    lost: list[tuple[float, int]] = field(default_factory=list)  # publisher side (time, total_count)
    received: dict[str, int] = field(default_factory=dict)
    watched_until: float = 0.0  # end of the observation (seconds since the start)

    def first_not_alive_after_cut(self, label: str) -> float | None:
        """Seconds from the cut until ``label``'s subscription saw its publisher not alive (None: never)."""
        for t, _alive, not_alive in self.changed[label]:
            if t >= self.cut_at and not_alive > 0:
                return t - self.cut_at
        return None


class LivelinessWatcher(Node):
    """Subscribes to String topics and records each subscription's liveliness-changed events.

    ``topics`` maps a label to (topic, QoSProfile). :attr:`changed` maps each label to
    (``time.monotonic()``, alive_count, not_alive_count) events; :attr:`received` counts messages.
    The notebook writes a node of its own with the same constructor and attributes, and passes it
    to the demos as ``watcher_class``.
    """

    def __init__(self, name: str, topics: dict):
        super().__init__(name)
        self.changed: dict[str, list[tuple[float, int, int]]] = {label: [] for label in topics}
        self.received = {label: 0 for label in topics}
        for label, (topic, qos) in topics.items():
            self.create_subscription(
                String, topic, partial(self.on_message, label), qos,
                event_callbacks=SubscriptionEventCallbacks(liveliness=partial(self.on_liveliness, label)))

    def on_message(self, label: str, _msg: String) -> None:
        self.received[label] += 1

    def on_liveliness(self, label: str, status) -> None:
        self.changed[label].append((time.monotonic(), status.alive_count, status.not_alive_count))


def _since(watcher, start: float, until: float | None = None) -> dict[str, list[tuple[float, int, int]]]:
    """``watcher.changed`` with times in seconds since ``start`` (events after ``until`` left out)."""
    return {label: [(t - start, alive, not_alive) for t, alive, not_alive in events
                    if until is None or t - start <= until]
            for label, events in watcher.changed.items()}


def demo_liveliness_kill(rt, lease_s: float = 1.0, watch_s: float = 2.5,
                         watcher_class=LivelinessWatcher) -> LivelinessResult:
    """A publisher in a child process (AUTOMATIC liveliness, lease ``lease_s``) is killed with SIGKILL.

    Args:
        rt: the kernel's runtime (the subscription runs in it).
        lease_s: the liveliness lease both ends use.
        watch_s: seconds watched after the kill.
        watcher_class: the subscribing node, built as ``watcher_class(name, {label: (topic, QoSProfile)})``
            (see :class:`LivelinessWatcher`).

    The process cannot say goodbye; the subscription notices when the lease runs out without
    the participant's liveliness heartbeat, and its liveliness-changed event fires. Returns a
    :class:`LivelinessResult` with the label 'automatic'.
    """
    start = time.monotonic()
    qos = {"liveliness": "automatic", "lease_s": lease_s}
    watcher = rt.add(watcher_class, "qos_liveliness_watch", {"automatic": ("qos_alive", qos_from_dict(qos))},
                     console=False)
    child = rt.spawn("qos_alive_talker", QosTalker,
                     params={"name": "qos_alive_talker", "topic": "qos_alive", "qos": qos, "rate_hz": 10.0},
                     wait_for="/qos_alive_talker")
    try:
        rt.wait_until(lambda: watcher.received["automatic"] >= 3, 10.0, "messages from the child talker")
        cut = time.monotonic() - start
        child.kill()
        time.sleep(watch_s)  # the lease runs out meanwhile
    finally:
        rt.stop_child("qos_alive_talker")
        rt.remove(watcher)
    return LivelinessResult(lease_s, cut, None, _since(watcher, start), [], dict(watcher.received),
                            cut + watch_s)


class LivelinessTalker(Node):
    """One node, two publishers with lease ``lease_s``, and a quiet spell.

    Args:
        name: the node name.
        lease_s: the liveliness lease of both publishers.
        period_s: seconds between messages.
        quiet_from, quiet_until: the quiet spell, in seconds after the start.

    Publishes on ``qos_automatic`` (AUTOMATIC) and ``qos_manual_by_topic`` (MANUAL_BY_TOPIC)
    from the moment both are matched, and reports ``start`` then. Every liveliness-lost event
    of the manual publisher is reported as ``lost`` with its ``total_count``.
    """

    def __init__(self, name: str = "qos_liveliness_pub", lease_s: float = 0.5, period_s: float = 0.1,
                 quiet_from: float = 1.0, quiet_until: float = 2.5):
        super().__init__(name)
        self.quiet = (quiet_from, quiet_until)
        self.started_at: float | None = None
        self.automatic = self.create_publisher(
            String, "qos_automatic", qos_from_dict({"liveliness": "automatic", "lease_s": lease_s}))
        self.manual = self.create_publisher(
            String, "qos_manual_by_topic",
            qos_from_dict({"liveliness": "manual_by_topic", "lease_s": lease_s}),
            event_callbacks=PublisherEventCallbacks(liveliness=self.on_liveliness_lost))
        self.timer = self.create_timer(period_s, self.tick)  # period in seconds

    def on_liveliness_lost(self, status) -> None:
        report("lost", total_count=status.total_count)

    def tick(self) -> None:
        now = time.monotonic()
        if self.started_at is None:
            if self.automatic.get_subscription_count() and self.manual.get_subscription_count():
                self.started_at = now
                report("start")
            return
        if not self.quiet[0] <= now - self.started_at < self.quiet[1]:
            for publisher in (self.automatic, self.manual):
                publisher.publish(String(data="still here"))  # publishing asserts liveliness


def demo_liveliness_manual(rt, lease_s: float = 0.5, period_s: float = 0.1, quiet_from: float = 1.0,
                           quiet_until: float = 2.5, duration_s: float = 3.5,
                           watcher_class=LivelinessWatcher) -> LivelinessResult:
    """A child process publishes on two topics, AUTOMATIC and MANUAL_BY_TOPIC, goes quiet, then resumes.

    Args:
        rt: the kernel's runtime (the subscriptions run in it).
        lease_s, period_s, quiet_from, quiet_until: see :class:`LivelinessTalker`.
        duration_s: seconds watched from the start.
        watcher_class: the subscribing node, as for :func:`demo_liveliness_kill`.

    The process stays alive all along. The AUTOMATIC writer stays alive (its participant keeps
    asserting for it); the MANUAL_BY_TOPIC writer must publish or call ``assert_liveliness()``
    within every lease, so it is declared lost (publisher: liveliness lost; subscription:
    liveliness changed) until it speaks again. The publisher runs in a child process so that
    liveliness travels between two participants, as between two programs on a robot. Returns a
    :class:`LivelinessResult` with the labels 'automatic' and 'manual_by_topic'.
    """
    topics = {kind: (f"qos_{kind}", qos_from_dict({"liveliness": kind, "lease_s": lease_s}))
              for kind in KINDS}
    watcher = rt.add(watcher_class, "qos_liveliness_sub", topics, console=False)
    child = rt.spawn("qos_liveliness_pub", LivelinessTalker,
                     params={"lease_s": lease_s, "period_s": period_s, "quiet_from": quiet_from,
                             "quiet_until": quiet_until})
    try:
        child.wait_for_report("start", 15.0, "the liveliness talker to match both subscriptions")
        start = child.channel.stamped("start")[0][0]  # the child's monotonic clock is the kernel's
        time.sleep(max(0.0, start + duration_s - time.monotonic()))  # the quiet spell passes meanwhile
        lost = [(t - start, data["total_count"]) for t, data in child.channel.stamped("lost")]
    finally:
        rt.stop_child("qos_liveliness_pub")
        rt.remove(watcher)
    return LivelinessResult(lease_s, quiet_from, quiet_until, _since(watcher, start, duration_s), lost,
                            dict(watcher.received), duration_s)


def plot_liveliness(results: list[LivelinessResult], titles: list[str]):
    """A matplotlib figure: alive writers seen by each subscription over time, one panel per result
    (``titles`` names them)."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(5.5 * len(results), 2.8), squeeze=False)
    colours = {"automatic": "#2563eb", "manual_by_topic": "#dc2626"}
    for ax, result, title in zip(axes[0], results, titles, strict=True):
        times_seen = [t for events in result.changed.values() for t, *_ in events]
        end = max([result.watched_until, result.cut_at + 2 * result.lease_s] + times_seen)
        for label, events in result.changed.items():
            if not events:
                continue
            times = [t for t, _a, _n in events] + [end]
            alive = [a for _t, a, _n in events]
            alive.append(alive[-1])
            offset = 0.04 if label == "automatic" else -0.04
            ax.step(times, [a + offset for a in alive], where="post", color=colours.get(label, "k"),
                    label=f"{label}: alive writers seen by the subscription")
        ax.axvline(result.cut_at, color="#111827", linestyle="--", linewidth=1)
        ax.text(result.cut_at, 1.25, " cut off", fontsize=8)
        if result.resumed_at is not None:
            ax.axvline(result.resumed_at, color="#16a34a", linestyle="--", linewidth=1)
            ax.text(result.resumed_at, 1.25, " resumes", fontsize=8)
        for i, (t, _count) in enumerate(result.lost):
            ax.plot(t, 0.5, marker="x", color="#111827", linestyle="none",
                    label="liveliness lost (publisher event)" if i == 0 else None)
        ax.set_ylim(-0.3, 1.5)
        ax.set_yticks([0, 1])
        ax.set_xlabel("time (s)")
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    return fig
