"""Liveliness: when a subscription declares its publisher not alive, and what keeps it alive.

The notebook writes the monitor (one subscription per topic, each with a liveliness callback), starts
the publishers in child processes (so that liveliness travels between two participants) and kills one;
these functions watch what follows and stop them:

* :func:`watch_after_crash` - after :class:`~.publishers.AliveTalker` (AUTOMATIC) was killed with
  SIGKILL, until its lease ran out;
* :func:`watch_quiet_spell` - while :class:`~.publishers.LivelinessTalker` goes quiet on an AUTOMATIC and
  a MANUAL_BY_TOPIC topic and its process lives; it reports ``start`` and its ``lost`` events;
* :func:`seconds_without_writer` - from a subscription's liveliness events, how long in a window no
  writer was alive (the heartbeat checker's measure), leaving out the :func:`blind_spells` in which
  the watcher's own executor did not run (its events then arrive late, all at once).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until

KINDS = ("automatic", "manual_by_topic")
AFTER_NOT_ALIVE_S = 0.2  # s watched after the killed publisher was declared not alive


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


def _check_monitor(monitor, labels) -> None:
    """A :class:`CourseError` unless ``monitor`` has ``changed`` and ``received`` for each of ``labels``."""
    for attr in ("changed", "received"):
        recorded = getattr(monitor, attr, None)
        if not isinstance(recorded, dict) or not set(labels) <= set(recorded):
            raise CourseError(f"the monitor needs self.{attr}, a dict with the labels {', '.join(labels)}")


def _since(monitor, start: float, until: float | None = None) -> dict[str, list[tuple[float, int, int]]]:
    """``monitor.changed`` with times in seconds since ``start`` (events after ``until`` left out)."""
    return {label: [(t - start, alive, not_alive) for t, alive, not_alive in events
                    if until is None or t - start <= until]
            for label, events in monitor.changed.items()}


def _stop(rt, talker, monitor) -> None:
    """Stop the talker's process and remove the monitor (both may be gone already)."""
    rt.stop_child(talker.label)
    rt.remove(monitor)


def watch_after_crash(rt, monitor, talker, lease_s: float, started: float, killed_at: float,
                      watch_s: float = 2.5) -> LivelinessResult:
    """Watch ``monitor`` after the notebook killed ``talker``, until the lease ran out.

    Args:
        rt: the kernel's runtime.
        monitor: a spinning node subscribed to the talker's topic, recording under the label
            'automatic' ``received`` (a message count) and ``changed`` ((time.monotonic(), alive_count,
            not_alive_count) of each liveliness-changed event). It is removed at the end.
        talker: the killed publisher's child process (``rt.spawn``'s ``ChildProcess``); stopped and
            reaped at the end.
        lease_s: the talker's liveliness lease.
        started, killed_at: ``time.monotonic()`` when the demo started and when the talker was killed.
        watch_s: the longest watch after the kill; it ends 0.2 s after the subscription saw the
            publisher not alive.

    Returns a :class:`LivelinessResult` (times since ``started``).
    """
    try:
        _check_monitor(monitor, ["automatic"])
        events = monitor.changed["automatic"]
        # the lease runs out meanwhile; no event by then is an outcome the result shows
        poll_until(lambda: any(t > killed_at and not_alive for t, _a, not_alive in events), watch_s)
        time.sleep(AFTER_NOT_ALIVE_S)  # anything more the subscription would report
    finally:
        _stop(rt, talker, monitor)
    return LivelinessResult(lease_s, killed_at - started, None, _since(monitor, started), [],
                            dict(monitor.received), time.monotonic() - started)


def watch_quiet_spell(rt, monitor, talker, duration_s: float = 3.5) -> LivelinessResult:
    """Watch ``monitor`` for ``duration_s`` seconds while ``talker`` goes quiet and resumes.

    Args:
        rt: the kernel's runtime.
        monitor: a spinning node subscribed to ``qos_automatic`` and ``qos_manual_by_topic``, recording
            under the labels 'automatic' and 'manual_by_topic' as for :func:`watch_after_crash`. It is
            removed at the end.
        talker: a :class:`LivelinessTalker` child process just started (``rt.spawn``); it reports
            ``start`` (with its lease and quiet spell) once both subscriptions matched, and ``lost``
            for each liveliness-lost event. Stopped and reaped at the end.
        duration_s: seconds watched from the moment the talker matched both subscriptions.

    The process stays alive all along. Returns a :class:`LivelinessResult` (times since the talker
    matched), with the talker's liveliness-lost events in ``lost``.
    """
    try:
        _check_monitor(monitor, KINDS)
        settings = talker.wait_for_report("start", 15.0, "the liveliness talker to match both subscriptions")
        start = talker.channel.stamped("start")[0][0]  # the child's monotonic clock is the kernel's
        time.sleep(max(0.0, start + duration_s - time.monotonic()))  # the quiet spell passes meanwhile
        lost = [(t - start, data["total_count"]) for t, data in talker.channel.stamped("lost")]
    finally:
        _stop(rt, talker, monitor)
    return LivelinessResult(settings["lease_s"], settings["quiet_from"], settings["quiet_until"],
                            _since(monitor, start, duration_s), lost, dict(monitor.received), duration_s)


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


def seconds_without_writer(changes: list[tuple], start: float, end: float,
                           leave_out: list[tuple[float, float]] = ()) -> float:
    """Seconds of [``start``, ``end``] in which no writer was alive, outside the ``leave_out`` spells.

    ``changes`` holds (time, writers alive, ...) for every liveliness event, in time order; the
    count before the first event is 0.
    """
    alive = next((change[1] for change in reversed(changes) if change[0] <= start), 0)
    down: list[tuple[float, float]] = []
    since = start
    for when, count, *_rest in changes:
        if when <= start:
            continue
        if when >= end:
            break
        if alive == 0:
            down.append((since, when))
        alive, since = count, when
    if alive == 0:
        down.append((since, end))
    return sum(b - a - _overlap((a, b), leave_out) for a, b in down)


def blind_spells(ticks: list[float], start: float, end: float, longest_s: float) -> list[tuple[float, float]]:
    """The spells of [``start``, ``end``] between two runs of a watcher's timer (``ticks``: when it
    ran) that lasted longer than ``longest_s``: its executor was held up, and events were late."""
    points = [start, *(t for t in ticks if start < t < end), end]
    return [(a, b) for a, b in zip(points, points[1:], strict=False) if b - a > longest_s]


def seen_seconds(ticks: list[float], start: float, end: float, longest_s: float) -> float:
    """Seconds of [``start``, ``end``] outside the :func:`blind_spells`."""
    return _outside(blind_spells(ticks, start, end, longest_s), start, end)


def watched_downtime(changes: list[tuple], ticks: list[float], start: float, end: float,
                     longest_s: float) -> tuple[float, float]:
    """(seconds without a live writer, seconds watched) of [``start``, ``end``], both outside the
    :func:`blind_spells` of the watcher's timer (``ticks``)."""
    blind = blind_spells(ticks, start, end, longest_s)
    return seconds_without_writer(changes, start, end, blind), _outside(blind, start, end)


def _outside(spells, start: float, end: float) -> float:
    """Seconds of [``start``, ``end``] outside ``spells`` (spans within it that do not overlap)."""
    return end - start - sum(b - a for a, b in spells)


def _overlap(span: tuple[float, float], spells) -> float:
    return sum(max(0.0, min(span[1], b) - max(span[0], a)) for a, b in spells)
