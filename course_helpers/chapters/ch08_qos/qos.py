"""Quality of Service, one policy at a time, on real publishers and subscriptions (chapter 08a).

Every ``demo_*`` function runs real nodes (in the kernel, or in a child process when the
point needs a real transport or a process that can be killed), records what arrived and
which QoS events fired, and returns the data; the ``plot_*`` functions draw it.

* :func:`demo_reliability` - large messages from a child process, best effort vs reliable,
  with the subscription's ``message_lost`` event;
* :func:`demo_history` - a burst into a subscription that is not being spun: KEEP_LAST(1),
  KEEP_LAST(5), KEEP_ALL;
* :func:`demo_durability` - a late joiner with TRANSIENT_LOCAL gets what the publisher kept;
* :func:`demo_deadline` - offered/requested deadline missed while a publisher pauses;
* :func:`demo_lifespan` - a late joiner gets only the stored messages that have not expired;
* :func:`demo_liveliness_kill` / :func:`demo_liveliness_manual` - liveliness changed/lost when a
  publisher process is killed, or when a MANUAL_BY_TOPIC publisher stops asserting;
* :func:`explain_compatibility`, :func:`try_pair`, :func:`compatibility_explorer` - whether a
  publisher and a subscription connect, policy by policy, checked against
  ``rclpy.qos.qos_check_compatible`` and a live pair;
* :func:`profiles_table` - the predefined profiles side by side.

Profiles cross process boundaries as plain dicts (:func:`qos_to_dict` / :func:`qos_from_dict`).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import (
    QoSCompatibility,
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    qos_check_compatible,
    qos_policy_name_from_kind,
)
from std_msgs.msg import String, UInt8MultiArray

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.qos_dict import (  # noqa: F401  (re-exported for the chapter's notebook)
    DEFAULT_QOS_DICT,
    describe_qos,
    duration_seconds,
    qos_from_dict,
    qos_to_dict,
    seconds_to_duration,
)


# ====================================================================== small helpers
class _Clock:
    def __init__(self):
        self.start = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self.start


def _remove(rt, *names):
    for name in names:
        rt.remove(name)


# ====================================================================== child-process publishers
def make_stream_publisher(name: str = "qos_stream", topics: dict | None = None, size: int = 1000,
                          rate_hz: float = 50.0, count: int = 100, linger_s: float = 30.0):
    """Child-process target: publish ``count`` numbered messages of ``size`` bytes on each topic.

    ``topics`` maps topic name -> QoS dict. Publishing starts once every topic has a matched
    subscription; the message number travels in ``layout.data_offset``. The node stays up
    afterwards (``linger_s``) so a reliable writer can finish resending.
    """
    node = Node(name)
    publishers = [node.create_publisher(UInt8MultiArray, topic, qos_from_dict(qos))
                  for topic, qos in (topics or {"stream": {}}).items()]
    payload = bytes(size)
    state = {"sent": 0, "ready_since": None}

    def tick():
        if state["sent"] >= count:
            return
        if state["ready_since"] is None:
            if all(p.get_subscription_count() > 0 for p in publishers):
                state["ready_since"] = time.monotonic()
            return
        if time.monotonic() - state["ready_since"] < 0.3:  # let the reverse match settle too
            return
        message = UInt8MultiArray(data=payload)
        message.layout.data_offset = state["sent"]
        for publisher in publishers:
            publisher.publish(message)
        state["sent"] += 1
        if state["sent"] == count:
            print(f"sent {count}", flush=True)

    node.timer = node.create_timer(1.0 / rate_hz, tick)
    return node


def make_qos_talker(name: str = "qos_talker", topic: str = "chatter", qos: dict | None = None,
                    rate_hz: float = 10.0, text: str = "hello"):
    """Child-process target: a String talker with the QoS given as a dict (see :func:`qos_from_dict`)."""
    node = Node(name)
    publisher = node.create_publisher(String, topic, qos_from_dict(qos or {}))
    count = [0]

    def tick():
        publisher.publish(String(data=f"{text} {count[0]}"))
        count[0] += 1

    node.timer = node.create_timer(1.0 / rate_hz, tick)
    return node


def make_int_talker(name: str = "int_talker", topic: str = "chatter", value: int = 66,
                    qos: dict | None = None, rate_hz: float = 2.0):
    """Child-process target: publishes Int32 ``value`` at ``rate_hz`` (``ros2 topic pub ... "data: 66"``)."""
    from std_msgs.msg import Int32

    node = Node(name)
    publisher = node.create_publisher(Int32, topic, qos_from_dict(qos or {}))
    node.timer = node.create_timer(1.0 / rate_hz, lambda: publisher.publish(Int32(data=value)))
    return node


# ====================================================================== reliability (+ message_lost)
@dataclass
class ReliabilityResult:
    """Which numbered messages each subscription got, and the message_lost events reported."""

    sent: int
    size: int
    rate_hz: float
    received: dict[str, list[int]]  # 'best_effort' / 'reliable' -> message numbers
    lost_reported: dict[str, int]  # message_lost total_count per subscription

    def share(self, kind: str) -> float:
        return len(set(self.received[kind])) / self.sent


def demo_reliability(rt, size: int = 1_000_000, rate_hz: float = 60.0, count: int = 90,
                     timeout: float = 20.0) -> ReliabilityResult:
    """A child process publishes the same numbered messages on a best-effort and a reliable topic.

    The kernel subscribes to both with matching QoS and a ``message_lost`` event callback.
    Large messages at a high rate overflow transport buffers: best effort drops what does not
    fit (and reports it), reliable resends until everything the writer still holds arrives.
    """
    if not 1 <= count <= 1000:
        raise CourseError(f"count must be 1..1000, got {count}")
    keep = {"history": "keep_last", "depth": count}
    topics = {"qos_best_effort": {**keep, "reliability": "best_effort"},
              "qos_reliable": {**keep, "reliability": "reliable"}}
    received = {"best_effort": [], "reliable": []}
    lost = {"best_effort": 0, "reliable": 0}
    node = rt.node("qos_reliability_sub", console=False)
    for kind, topic in (("best_effort", "qos_best_effort"), ("reliable", "qos_reliable")):
        def on_lost(status, kind=kind):
            lost[kind] = status.total_count

        node.create_subscription(
            UInt8MultiArray, topic, lambda msg, kind=kind: received[kind].append(msg.layout.data_offset),
            qos_from_dict(topics[topic]), event_callbacks=SubscriptionEventCallbacks(message_lost=on_lost))
    child = rt.spawn("qos_stream", "course_helpers.chapters.ch08_qos.qos:make_stream_publisher",
                     params={"name": "qos_stream", "topics": topics, "size": size, "rate_hz": rate_hz,
                             "count": count})
    try:
        rt.wait_until(lambda: f"sent {count}" in child.log() or not child.alive, timeout,
                      "the stream publisher to send everything")
        try:
            rt.wait_until(lambda: len(set(received["reliable"])) >= count, 5.0, "the reliable stream")
        except WaitTimeout:
            pass  # reported as it is
        time.sleep(0.3)
    finally:
        rt.stop_child("qos_stream")
        _remove(rt, node)
    return ReliabilityResult(count, size, rate_hz, {k: sorted(set(v)) for k, v in received.items()}, lost)


def plot_reliability(result: ReliabilityResult):
    """A barcode per subscription: one tick per message number that arrived."""
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


# ====================================================================== history / depth
def demo_history(rt, burst: int = 20, depths=(1, 5)) -> dict[str, list[int]]:
    """Publish a burst into subscriptions whose node is not spun yet, then spin it.

    While nobody takes messages, each subscription's DDS reader keeps what its history allows:
    KEEP_LAST(depth) keeps the newest ``depth``; KEEP_ALL keeps everything. Returns, for each
    subscription ('KEEP_LAST(1)', ..., 'KEEP_ALL'), the numbers it finally delivered.
    """
    got: dict[str, list[int]] = {}
    holder = Node("qos_history_sub", context=rt.context)
    profiles = [(f"KEEP_LAST({d})", QoSProfile(depth=d)) for d in depths]
    profiles.append(("KEEP_ALL", QoSProfile(history=QoSHistoryPolicy.KEEP_ALL)))
    for label, profile in profiles:
        got[label] = []
        holder.create_subscription(String, "qos_burst", lambda m, label=label: got[label].append(int(m.data)),
                                   profile)
    pub_node = rt.node("qos_history_pub", console=False)
    publisher = pub_node.create_publisher(String, "qos_burst", QoSProfile(history=QoSHistoryPolicy.KEEP_ALL))
    spun = False
    try:
        rt.wait_until(lambda: publisher.get_subscription_count() >= len(profiles), 5.0, "matching")
        for i in range(burst):
            publisher.publish(String(data=str(i)))
        time.sleep(0.2)  # delivered into the readers' histories; no callback has run
        rt.add(holder, console=False)
        spun = True
        rt.wait_until(lambda: len(got["KEEP_ALL"]) >= burst, 5.0, "the burst")
        time.sleep(0.2)
    finally:
        _remove(rt, pub_node)
        if spun:
            rt.remove(holder)
        else:
            holder.destroy_node()
    return got


# ====================================================================== durability
def demo_durability(rt, published: int = 5, publisher_depth: int = 3) -> dict[str, list[int]]:
    """A TRANSIENT_LOCAL publisher sends ``published`` messages; then two subscriptions join late.

    Returns what each late joiner received: 'transient_local' gets the last ``publisher_depth``
    messages the publisher kept, 'volatile' gets nothing from before it joined.
    """
    pub_node = rt.node("qos_durability_pub", console=False)
    stored = QoSProfile(depth=publisher_depth, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    publisher = pub_node.create_publisher(String, "qos_latched", stored)
    for i in range(published):
        publisher.publish(String(data=str(i)))
    time.sleep(0.3)
    got: dict[str, list[int]] = {"transient_local": [], "volatile": []}
    sub_node = rt.node("qos_durability_late_joiner", console=False)
    for kind, durability in (("transient_local", QoSDurabilityPolicy.TRANSIENT_LOCAL),
                             ("volatile", QoSDurabilityPolicy.VOLATILE)):
        sub_node.create_subscription(String, "qos_latched",
                                     lambda m, kind=kind: got[kind].append(int(m.data)),
                                     QoSProfile(depth=10, durability=durability))
    try:
        try:
            rt.wait_until(lambda: len(got["transient_local"]) >= min(published, publisher_depth), 3.0,
                          "the stored messages")
        except WaitTimeout:
            pass
        time.sleep(0.5)
    finally:
        _remove(rt, pub_node, sub_node)
    return got


# ====================================================================== deadline
@dataclass
class DeadlineResult:
    """Arrival times and deadline-missed events (seconds since the demo started)."""

    deadline_s: float
    pause: tuple[float, float]
    arrivals: list[float]
    offered_missed: list[tuple[float, int]]  # (time, total_count) at the publisher
    requested_missed: list[tuple[float, int]]  # (time, total_count) at the subscription

    def missed_during_pause(self, which: str = "requested") -> int:
        events = self.requested_missed if which == "requested" else self.offered_missed
        start, end = self.pause
        return sum(1 for t, _ in events if start < t <= end + self.deadline_s)

    def missed_outside_pause(self, which: str = "requested") -> int:
        events = self.requested_missed if which == "requested" else self.offered_missed
        return len(events) - self.missed_during_pause(which)


def demo_deadline(rt, period_s: float = 0.1, deadline_s: float = 0.3, pause: tuple = (1.0, 2.0),
                  duration_s: float = 3.0) -> DeadlineResult:
    """A publisher sends every ``period_s`` but is silent during ``pause``; both ends ask for ``deadline_s``.

    DDS checks the deadline at both ends: the publisher gets 'offered deadline missed', the
    subscription 'requested deadline missed', about once per ``deadline_s`` of silence.
    """
    if not period_s < deadline_s:
        raise CourseError(f"period_s ({period_s}) must be shorter than deadline_s ({deadline_s})")
    clock = _Clock()
    result = DeadlineResult(deadline_s, tuple(pause), [], [], [])
    profile = QoSProfile(depth=10, deadline=seconds_to_duration(deadline_s, "deadline_s"))
    sub_node = rt.node("qos_deadline_sub", console=False)
    sub_node.create_subscription(
        String, "qos_deadline", lambda _m: result.arrivals.append(clock.now()), profile,
        event_callbacks=SubscriptionEventCallbacks(
            deadline=lambda s: result.requested_missed.append((clock.now(), s.total_count))))
    pub_node = rt.node("qos_deadline_pub", console=False)
    publisher = pub_node.create_publisher(
        String, "qos_deadline", profile,
        event_callbacks=PublisherEventCallbacks(
            deadline=lambda s: result.offered_missed.append((clock.now(), s.total_count))))
    rt.wait_until(lambda: publisher.get_subscription_count() > 0, 5.0, "matching")
    clock.start = time.monotonic()

    def tick():
        if not pause[0] <= clock.now() < pause[1]:
            publisher.publish(String(data="on time"))

    pub_node.create_timer(period_s, tick)
    try:
        time.sleep(duration_s)
    finally:
        _remove(rt, pub_node, sub_node)
    return result


def plot_deadline(result: DeadlineResult):
    """Arrivals as ticks, deadline-missed events as markers, the pause shaded."""
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
@dataclass
class LifespanResult:
    """When each numbered message was published, when the late joiner joined, what it got."""

    lifespan_s: float
    published_at: list[float]
    joined_at: float
    received: list[int]

    def ages_at_join(self) -> list[float]:
        return [self.joined_at - t for t in self.published_at]


def demo_lifespan(rt, lifespan_s: float = 1.0, period_s: float = 0.4, count: int = 6,
                  depth: int = 10) -> LifespanResult:
    """A TRANSIENT_LOCAL publisher with a lifespan sends ``count`` messages; a late joiner subscribes.

    The publisher keeps up to ``depth`` messages for late joiners, but a message older than
    ``lifespan_s`` is removed: the late joiner only gets the ones still fresh.
    """
    clock = _Clock()
    profile = QoSProfile(depth=depth, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL,
                         lifespan=seconds_to_duration(lifespan_s, "lifespan_s"))
    pub_node = rt.node("qos_lifespan_pub", console=False)
    publisher = pub_node.create_publisher(String, "qos_lifespan", profile)
    published: list[float] = []
    done = threading.Event()

    def tick():
        if len(published) < count:
            publisher.publish(String(data=str(len(published))))
            published.append(clock.now())
        else:
            done.set()

    pub_node.create_timer(period_s, tick)
    received: list[int] = []
    try:
        if not done.wait(count * period_s + 5):
            raise WaitTimeout("the lifespan publisher did not finish")
        sub_node = rt.node("qos_lifespan_late_joiner", console=False)
        joined = clock.now()
        sub_node.create_subscription(String, "qos_lifespan", lambda m: received.append(int(m.data)),
                                     QoSProfile(depth=depth, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL))
        time.sleep(0.6)
    finally:
        _remove(rt, pub_node, "/qos_lifespan_late_joiner")
    return LifespanResult(lifespan_s, published, joined, sorted(received))


def plot_lifespan(result: LifespanResult):
    """Each message's age when the late joiner joined, coloured by whether it was delivered."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 2.8))
    ages = result.ages_at_join()
    colours = ["#16a34a" if i in result.received else "#9ca3af" for i in range(len(ages))]
    ax.bar(range(len(ages)), ages, color=colours)
    ax.axhline(result.lifespan_s, color="#dc2626", linestyle="--", label=f"lifespan {result.lifespan_s:g} s")
    ax.set_xlabel("message number (green: delivered to the late joiner, grey: expired)")
    ax.set_ylabel("age at join (s)")
    ax.set_title("Lifespan: stored messages older than the lifespan are dropped", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


# ====================================================================== liveliness
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
        """Seconds from the cut until ``label``'s subscription saw its publisher not alive."""
        for t, _alive, not_alive in self.changed[label]:
            if t >= self.cut_at and not_alive > 0:
                return t - self.cut_at
        return None


def demo_liveliness_kill(rt, lease_s: float = 1.0, watch_s: float = 2.5) -> LivelinessResult:
    """A publisher in a child process (AUTOMATIC liveliness, lease ``lease_s``) is killed with SIGKILL.

    The process cannot say goodbye; the subscription notices when the lease runs out without
    the participant's liveliness heartbeat, and its liveliness-changed event fires.
    """
    clock = _Clock()
    qos = {"liveliness": "automatic", "lease_s": lease_s}
    changed: list[tuple[float, int, int]] = []
    received = [0]
    node = rt.node("qos_liveliness_watch", console=False)
    node.create_subscription(
        String, "qos_alive", lambda _m: received.__setitem__(0, received[0] + 1), qos_from_dict(qos),
        event_callbacks=SubscriptionEventCallbacks(
            liveliness=lambda s: changed.append((clock.now(), s.alive_count, s.not_alive_count))))
    child = rt.spawn("qos_alive_talker", "course_helpers.chapters.ch08_qos.qos:make_qos_talker",
                     params={"name": "qos_alive_talker", "topic": "qos_alive", "qos": qos, "rate_hz": 10.0},
                     wait_for="/qos_alive_talker")
    try:
        rt.wait_until(lambda: received[0] >= 3, 10.0, "messages from the child talker")
        cut = clock.now()
        child.kill()
        time.sleep(watch_s)
    finally:
        rt.stop_child("qos_alive_talker")
        _remove(rt, node)
    return LivelinessResult(lease_s, cut, None, {"automatic": changed}, [], {"automatic": received[0]},
                            cut + watch_s)


def make_liveliness_talker(name: str = "qos_liveliness_pub", lease_s: float = 0.5, period_s: float = 0.1,
                           quiet_from: float = 1.0, quiet_until: float = 2.5):
    """Child-process target for :func:`demo_liveliness_manual`: one node, two publishers, a quiet spell.

    Publishes on ``qos_automatic`` (AUTOMATIC) and ``qos_manual_by_topic`` (MANUAL_BY_TOPIC), both
    with lease ``lease_s``, from the moment both are matched; stays silent from ``quiet_from`` to
    ``quiet_until`` seconds after that. Prints 'START <monotonic s>' and, for every liveliness-lost
    event of the manual publisher, 'LOST <monotonic s> <total_count>'.
    """
    node = Node(name)
    publishers = {}
    for kind in ("automatic", "manual_by_topic"):
        callbacks = PublisherEventCallbacks(
            liveliness=lambda s: print(f"LOST {time.monotonic()} {s.total_count}", flush=True)) \
            if kind == "manual_by_topic" else PublisherEventCallbacks()
        publishers[kind] = node.create_publisher(String, f"qos_{kind}",
                                                 qos_from_dict({"liveliness": kind, "lease_s": lease_s}),
                                                 event_callbacks=callbacks)
    state = {"t0": None}

    def tick():
        now = time.monotonic()
        if state["t0"] is None:
            if all(p.get_subscription_count() for p in publishers.values()):
                state["t0"] = now
                print(f"START {now}", flush=True)
            return
        if not quiet_from <= now - state["t0"] < quiet_until:
            for publisher in publishers.values():
                publisher.publish(String(data="still here"))  # publishing asserts liveliness

    node.timer = node.create_timer(period_s, tick)
    return node


def demo_liveliness_manual(rt, lease_s: float = 0.5, period_s: float = 0.1, quiet_from: float = 1.0,
                           quiet_until: float = 2.5, duration_s: float = 3.5) -> LivelinessResult:
    """A child process publishes on two topics, AUTOMATIC and MANUAL_BY_TOPIC, goes quiet, then resumes.

    The process stays alive all along. The AUTOMATIC writer stays alive (its participant keeps
    asserting for it); the MANUAL_BY_TOPIC writer must publish or call ``assert_liveliness()``
    within every lease, so it is declared lost (publisher: liveliness lost; subscription:
    liveliness changed) until it speaks again. A child process is used because inside one
    process Fast DDS delivers data directly and the participant's liveliness messages do not
    reach a subscription of the same process.
    """
    changed: dict[str, list] = {"automatic": [], "manual_by_topic": []}
    received = {"automatic": 0, "manual_by_topic": 0}
    sub_node = rt.node("qos_liveliness_sub", console=False)
    for kind in ("automatic", "manual_by_topic"):
        def on_message(_m, kind=kind):
            received[kind] += 1

        sub_node.create_subscription(
            String, f"qos_{kind}", on_message, qos_from_dict({"liveliness": kind, "lease_s": lease_s}),
            event_callbacks=SubscriptionEventCallbacks(
                liveliness=lambda s, kind=kind: changed[kind].append(
                    (time.monotonic(), s.alive_count, s.not_alive_count))))
    child = rt.spawn("qos_liveliness_pub", "course_helpers.chapters.ch08_qos.qos:make_liveliness_talker",
                     params={"lease_s": lease_s, "period_s": period_s, "quiet_from": quiet_from,
                             "quiet_until": quiet_until})
    try:
        rt.wait_until(lambda: "START " in child.log() or not child.alive, 15.0, "the liveliness talker")
        t0 = float(next(line.split()[1] for line in child.log().splitlines() if line.startswith("START ")))
        time.sleep(max(0.0, t0 + duration_s - time.monotonic()))
        log = child.log().splitlines()
    finally:
        rt.stop_child("qos_liveliness_pub")
        _remove(rt, sub_node)
    lost = [(float(line.split()[1]) - t0, int(line.split()[2])) for line in log if line.startswith("LOST ")]
    rel = {k: [(t - t0, a, n) for t, a, n in v if t - t0 <= duration_s] for k, v in changed.items()}
    return LivelinessResult(lease_s, quiet_from, quiet_until, rel, lost, received, duration_s)


def plot_liveliness(results: list[LivelinessResult], titles: list[str]):
    """Alive writers seen by each subscription over time, one panel per demo."""
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


# ====================================================================== compatibility
@dataclass
class PolicyVerdict:
    """Whether one policy lets the publisher and subscription match, and why."""

    policy: str
    publisher: str
    subscription: str
    compatible: bool | None  # None: this policy plays no part in matching
    reason: str


def _duration_text(seconds: float) -> str:
    return "infinite" if not seconds else f"{seconds:g} s"


def explain_compatibility(pub: QoSProfile, sub: QoSProfile) -> list[PolicyVerdict]:
    """Policy by policy, the DDS 'requested vs offered' rule: the publisher must offer at least what
    the subscription requests. History, depth and lifespan never prevent a match.
    """
    p, s = qos_to_dict(pub), qos_to_dict(sub)
    rows = []
    ok = not (p["reliability"] == "best_effort" and s["reliability"] == "reliable")
    rows.append(PolicyVerdict(
        "reliability", p["reliability"], s["reliability"], ok,
        "the publisher offers at least what is requested" if ok else
        "a best-effort publisher cannot promise the delivery a reliable subscription requests"))
    ok = not (p["durability"] == "volatile" and s["durability"] == "transient_local")
    rows.append(PolicyVerdict(
        "durability", p["durability"], s["durability"], ok,
        "the publisher offers at least what is requested" if ok else
        "a volatile publisher keeps nothing for late joiners, which a transient-local subscription requests"))
    pd, sd = p["deadline_s"], s["deadline_s"]
    ok = not sd or (bool(pd) and pd <= sd)
    rows.append(PolicyVerdict(
        "deadline", _duration_text(pd), _duration_text(sd), ok,
        "the publisher promises a period no longer than the one requested" if ok else
        "the subscription requests a shorter period than the publisher promises"))
    ok = not (p["liveliness"] == "automatic" and s["liveliness"] == "manual_by_topic")
    rows.append(PolicyVerdict(
        "liveliness", p["liveliness"], s["liveliness"], ok,
        "the publisher's kind is at least as strict as requested" if ok else
        "manual-by-topic is requested but the publisher only offers automatic liveliness"))
    pl, sl = p["lease_s"], s["lease_s"]
    ok = not sl or (bool(pl) and pl <= sl)
    rows.append(PolicyVerdict(
        "lease duration", _duration_text(pl), _duration_text(sl), ok,
        "the publisher promises to assert within the requested lease" if ok else
        "the subscription requests a shorter lease than the publisher promises"))
    depth = lambda d: f"{d['history']}({d['depth']})" if d["history"] == "keep_last" else d["history"]  # noqa: E731
    rows.append(PolicyVerdict("history / depth", depth(p), depth(s), None,
                              "local to each side: never prevents a match"))
    rows.append(PolicyVerdict("lifespan", _duration_text(p["lifespan_s"]), _duration_text(s["lifespan_s"]),
                              None, "a publisher-side setting: never prevents a match"))
    return rows


def compatible(pub: QoSProfile, sub: QoSProfile) -> bool:
    """True if every policy in :func:`explain_compatibility` allows the match."""
    return all(row.compatible is not False for row in explain_compatibility(pub, sub))


def rclpy_verdict(pub: QoSProfile, sub: QoSProfile) -> tuple[str, str]:
    """rclpy's own check, ``qos_check_compatible``: ('OK' | 'WARNING' | 'ERROR', reason)."""
    verdict, reason = qos_check_compatible(pub, sub)
    return QoSCompatibility(verdict).name, reason


@dataclass
class PairResult:
    """What a live publisher/subscription pair did in ``seconds``."""

    received: int
    publisher_events: list[str]  # incompatible-QoS events at the publisher (policy names)
    subscription_events: list[str]

    @property
    def connected(self) -> bool:
        return self.received > 0


def try_pair(rt, pub: QoSProfile, sub: QoSProfile, seconds: float = 1.0,
             topic: str = "qos_pair") -> PairResult:
    """Create a real publisher and subscription with these profiles; publish for ``seconds``.

    Records the messages received and the incompatible-QoS events at both ends.
    """
    received = [0]
    pub_events: list[str] = []
    sub_events: list[str] = []
    sub_node = rt.node("qos_pair_sub", console=False)
    sub_node.create_subscription(
        String, topic, lambda _m: received.__setitem__(0, received[0] + 1), sub,
        event_callbacks=SubscriptionEventCallbacks(
            incompatible_qos=lambda s: sub_events.append(qos_policy_name_from_kind(s.last_policy_kind))))
    pub_node = rt.node("qos_pair_pub", console=False)
    publisher = pub_node.create_publisher(
        String, topic, pub,
        event_callbacks=PublisherEventCallbacks(
            incompatible_qos=lambda s: pub_events.append(qos_policy_name_from_kind(s.last_policy_kind))))
    pub_node.create_timer(0.05, lambda: publisher.publish(String(data="hello")))
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (received[0] >= 3 or (pub_events and sub_events)):
            time.sleep(0.02)
        if not received[0] and not sub_events:
            time.sleep(max(0.0, end - time.monotonic()))
    finally:
        _remove(rt, pub_node, sub_node)
    return PairResult(received[0], sorted(set(pub_events)), sorted(set(sub_events)))


def compatibility_report(rt, pub: QoSProfile, sub: QoSProfile, live: bool = True) -> str:
    """Text: the per-policy table, rclpy's verdict and (if ``live``) what a real pair did."""
    rows = explain_compatibility(pub, sub)
    lines = [f"{'policy':<16} {'publisher':<16} {'subscription':<16} verdict",
             "-" * 72]
    for r in rows:
        mark = "n/a" if r.compatible is None else ("ok" if r.compatible else "MISMATCH")
        lines.append(f"{r.policy:<16} {r.publisher:<16} {r.subscription:<16} {mark}: {r.reason}")
    expected = compatible(pub, sub)
    verdict, reason = rclpy_verdict(pub, sub)
    lines.append("")
    lines.append(f"prediction: {'they connect' if expected else 'they do NOT connect'}")
    lines.append(f"rclpy.qos.qos_check_compatible: {verdict}" + (f" ({reason.strip()})" if reason else ""))
    if live:
        pair = try_pair(rt, pub, sub)
        events = ", ".join(pair.subscription_events) or "none"
        lines.append(f"live pair: {'messages arrived' if pair.connected else 'no message arrived'}; "
                     f"incompatible-QoS events at the subscription: {events}")
    return "\n".join(lines)


_CHOICES = {
    "reliability": ["reliable", "best_effort"],
    "durability": ["volatile", "transient_local"],
    "deadline_s": [("infinite", 0.0), ("0.1 s", 0.1), ("0.5 s", 0.5), ("1 s", 1.0)],
    "liveliness": ["automatic", "manual_by_topic"],
    "lease_s": [("infinite", 0.0), ("0.5 s", 0.5), ("1 s", 1.0), ("2 s", 2.0)],
    "history": ["keep_last", "keep_all"],
    "depth": [1, 5, 10],
}


def compatibility_explorer(rt, pub: dict | None = None, sub: dict | None = None):
    """A widget: pick the publisher's and the subscription's policies, press the button, read why.

    The verdict is given three ways: the per-policy rule, ``qos_check_compatible``, and a real
    publisher/subscription pair created on the spot (its incompatible-QoS events included).
    """
    import ipywidgets as w

    start = {"pub": {**DEFAULT_QOS_DICT, **(pub or {})}, "sub": {**DEFAULT_QOS_DICT, **(sub or {})}}
    pickers: dict[str, dict] = {"pub": {}, "sub": {}}
    columns = []
    for side, title in (("pub", "Publisher offers"), ("sub", "Subscription requests")):
        boxes = [w.HTML(f"<b>{title}</b>")]
        for key, options in _CHOICES.items():
            picker = w.Dropdown(options=options, value=start[side][key], description=key.replace("_s", ""),
                                layout=w.Layout(width="260px"))
            pickers[side][key] = picker
            boxes.append(picker)
        columns.append(w.VBox(boxes))
    button = w.Button(description="Check (live pair)", button_style="primary")
    output = w.Output()

    def on_click(_button):
        output.clear_output()
        with output:
            try:
                profiles = [qos_from_dict({k: p.value for k, p in pickers[side].items()})
                            for side in ("pub", "sub")]
                print(compatibility_report(rt, *profiles))
            except CourseError as exc:
                print(f"CourseError: {exc}")

    button.on_click(on_click)
    return w.VBox([w.HBox(columns), button, output])


# ====================================================================== predefined profiles
PREDEFINED = [
    ("qos_profile_default", "publishers and subscriptions unless told otherwise"),
    ("qos_profile_sensor_data", "sensor streams: the newest sample matters, old ones do not"),
    ("qos_profile_services_default", "service requests and replies"),
    ("qos_profile_parameters", "parameter services"),
    ("qos_profile_parameter_events", "/parameter_events"),
    ("qos_profile_action_status_default", "an action's status topic (late joiners get the state)"),
    ("qos_profile_system_default", "whatever the middleware's own defaults are"),
    ("qos_profile_best_available", "subscriptions that adapt to the publishers they find"),
]


def _profile_cell(value, kind) -> str:
    text = policy_name(value)
    if kind == "duration":
        ns = value.nanoseconds
        if ns in (0, 2**63 - 1):
            return "infinite"
        return "best available" if ns >= 2**62 else f"{ns / 1e9:g} s"
    return text


def profiles_table() -> list[dict]:
    """One row per predefined rclpy profile: its policies as text."""
    from rclpy import qos as rq

    rows = []
    for name, use in PREDEFINED:
        profile = getattr(rq, name)
        history = policy_name(profile.history)
        if profile.history == QoSHistoryPolicy.KEEP_LAST:
            history = f"KEEP_LAST({profile.depth})"
        rows.append({"profile": name, "reliability": _profile_cell(profile.reliability, ""),
                     "durability": _profile_cell(profile.durability, ""), "history": history,
                     "deadline": _profile_cell(profile.deadline, "duration"),
                     "liveliness": _profile_cell(profile.liveliness, ""), "used for": use})
    return rows


def show_profiles_table(rows: list[dict] | None = None) -> None:
    """Print :func:`profiles_table` aligned."""
    rows = rows or profiles_table()
    keys = ["profile", "reliability", "durability", "history", "deadline", "liveliness"]
    widths = {k: max(len(k), *(len(str(r[k])) for r in rows)) for k in keys}
    print("  ".join(f"{k:<{widths[k]}}" for k in keys))
    for r in rows:
        print("  ".join(f"{r[k]:<{widths[k]}}" for k in keys))
    print()
    for r in rows:
        print(f"{r['profile']:<{widths['profile']}}  {r['used for']}")


# ====================================================================== the mismatched-subscriber exercise
ROBOT_CMD_QOS = {"reliability": "best_effort", "durability": "volatile", "history": "keep_last", "depth": 5}


def make_robot_cmd_publisher(name: str = "robot_controller", rate_hz: float = 5.0):
    """Child-process target: sends 'forward', 'backward', 'stop' in turn on /robot_cmd (best effort)."""
    node = Node(name)
    publisher = node.create_publisher(String, "/robot_cmd", qos_from_dict(ROBOT_CMD_QOS))
    commands = ["forward", "backward", "stop"]
    count = [0]

    def tick():
        publisher.publish(String(data=commands[count[0] % len(commands)]))
        count[0] += 1

    node.timer = node.create_timer(1.0 / rate_hz, tick)
    return node
