"""Replaying a recorded mission into a node under the bag's clock, and what came out (section 9).

:func:`replay_scans` feeds the LIDAR scans of a mission bag to a fresh node of a given class,
each at its recorded time, under a :class:`~course_helpers.core.sim_clock.SimClock` that starts at
the bag's first message and owns the node's executor. Every scan is handled before the next one,
and the node's timers and ``now()`` follow the bag's time, so the same bag gives the same result
on every run, on any machine: a bug found in it is found again. :func:`plot_time_to_collision`
draws what the node published.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rclpy.node import Node
from std_msgs.msg import Float64

from course_helpers.core import bags
from course_helpers.core.sim_clock import SimClock

TTC_TOPIC = "/robot1/perception/time_to_collision"


@dataclass
class ReplayResult:
    """What a replay gave: each published value and each callback error, at its time in the bag [s
    after the bag's first message]."""

    scans: int = 0
    duration_s: float = 0.0  # of the bag
    published: list[tuple[float, float]] = field(default_factory=list)
    errors: list[tuple[float, int, str]] = field(default_factory=list)  # (time s, scan number, error)

    def first_error(self) -> str:
        if not self.errors:
            return "no error"
        t, scan, error = self.errors[0]
        return f"{error}, at {t:.3f} s of the bag (scan {scan} of {self.scans})"


class _Probe(Node):
    def __init__(self, clock: SimClock, start_s: float, result: ReplayResult):
        super().__init__("replay_probe")
        self.create_subscription(Float64, TTC_TOPIC, lambda msg: result.published.append(
            (round(clock.now_s - start_s, 9), msg.data)), 100)


def replay_scans(rt, bag, node_class, topic: str = "/robot1/scan") -> ReplayResult:
    """Replay ``topic`` of ``bag`` into a new ``node_class()`` under the bag's clock; the result."""
    info = bags.bag_info(bag)
    start_s = info.start_ns / 1e9
    clock = SimClock(rt, start_s=start_s)
    result = ReplayResult(duration_s=info.duration_ns / 1e9)
    node = probe = replay = None
    try:
        node = clock.drive(rt.build(node_class))
        probe = clock.drive(rt.build(_Probe, clock, start_s, result))
        replay = bags.SimReplay(rt, clock, bag, topics=[topic])

        def after(_topic: str, _stamp: int) -> None:
            result.scans += 1
            while len(result.errors) < len(clock.errors):
                error = clock.errors[len(result.errors)]
                result.errors.append((round(clock.now_s - start_s, 9), result.scans,
                                      f"{type(error).__name__}: {error}"))

        replay.run(after=after)
    finally:
        for each in (replay, probe, node):
            if each is not None:
                (each.close if each is replay else each.destroy_node)()
        clock.close()
    return result


def plot_time_to_collision(result: ReplayResult, title: str):
    """The time to collision the node published over the bag's time (clipped to +-10 s; infinite ones
    on a line of their own), and a red line at each callback error; returns the figure."""
    import math

    import matplotlib.pyplot as plt

    limit = 10.0  # s shown either side of zero
    fig, ax = plt.subplots(figsize=(8, 3.2))
    finite = [(t, max(-limit, min(limit, v))) for t, v in result.published if math.isfinite(v)]
    endless = [t for t, v in result.published if not math.isfinite(v)]
    ax.plot([t for t, _ in finite], [v for _, v in finite], ".", markersize=5, label="time to collision")
    if endless:
        ax.plot(endless, [0.9 * limit] * len(endless), "x", color="tab:green", markersize=4,
                label="infinite: not closing in")
    for n, (t, _scan, _error) in enumerate(result.errors):
        ax.axvline(t, color="tab:red", alpha=0.5, label="callback raised" if n == 0 else None)
    ax.axhline(0.0, color="black", linewidth=0.8)
    ax.set_xlim(0, max(result.duration_s, 0.1))
    ax.set_ylim(-limit, limit)
    ax.set_xlabel("time in the bag [s]")
    ax.set_ylabel("time to collision [s]")
    ax.set_title(title)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return fig
