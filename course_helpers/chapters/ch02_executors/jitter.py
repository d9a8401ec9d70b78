"""How regularly a timer fires, idle and beside a CPU-heavy callback (chapter 02, real time).

:func:`measure_timer_jitter` spins a :class:`JitterProbe` alone in an executor and returns a
:class:`JitterResult`: for every call of the probe's timer, when it fell due and when it started,
and for every run of the heavy callback, when it started and ended, all on the node's clock.

With those, the executor's share of a late call can be told from the operating system's. A call
that fell due while the heavy callback ran (:meth:`JitterResult.due_while_busy`) either waited
for the heavy callback to end (one thread: it cannot start earlier) or started while it still ran
(another thread). That is decided by the executor and the callback groups, not by the machine's
speed or load, which only add waiting on top; the idle run measures what they add alone.
"""

from __future__ import annotations

import statistics
from bisect import bisect_right
from dataclasses import dataclass, field
from itertools import pairwise

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from course_helpers.chapters.ch02_executors.blocking import spin_for
from course_helpers.core.errors import CourseError

NS_PER_MS = 1_000_000


class JitterProbe(Node):
    """A periodic timer that records when each call fell due and when it started, optionally beside
    a CPU-heavy timer (in the default group, or in a group of its own with ``separate_groups``)."""

    def __init__(self, period_s: float = 0.01, heavy_ms: float = 0.0, heavy_period_s: float = 0.05,
                 separate_groups: bool = False, name: str = "jitter_probe"):
        super().__init__(name)
        self.heavy_s = heavy_ms / 1e3
        self.calls: list[tuple[int, int]] = []  # (fell due, started) of each timer call, ns
        self.busy: list[tuple[int, int]] = []  # (started, ended) of each heavy callback, ns
        group = MutuallyExclusiveCallbackGroup() if separate_groups else None
        self.timer = self.create_timer(period_s, self.on_timer)
        self._next_due = self._now() + self.timer.time_until_next_call()
        if heavy_ms > 0:
            self.heavy_timer = self.create_timer(heavy_period_s, self.crunch, callback_group=group)

    def _now(self) -> int:
        return self.get_clock().now().nanoseconds  # the clock the timers run on

    @property
    def fired(self) -> list[float]:
        """When each timer call started, in seconds."""
        return [started / 1e9 for _due, started in self.calls]

    def on_timer(self) -> None:
        started = self._now()
        self.calls.append((self._next_due, started))
        # the executor has already moved the timer on: its next call falls due this long from now
        self._next_due = self._now() + self.timer.time_until_next_call()

    def crunch(self) -> None:
        started = self._now()
        deadline = started + self.heavy_s * 1e9
        total = 0
        while self._now() < deadline:  # pure-Python arithmetic: keeps a CPU core busy
            total += sum(range(200))
        self.busy.append((started, self._now()))


@dataclass(frozen=True)
class DueWhileBusy:
    """A timer call that fell due while the heavy callback ran."""

    wait_ms: float  # from falling due to starting
    left_ms: float  # how long the heavy callback still ran after the call fell due

    @property
    def waited_for_it(self) -> bool:
        """True if the call started only after the heavy callback had ended."""
        return self.wait_ms >= self.left_ms


@dataclass
class JitterResult:
    """The calls of a periodic timer, and the runs of the heavy callback beside it (ns)."""

    label: str
    period_s: float
    calls: list[tuple[int, int]]  # (fell due, started)
    busy: list[tuple[int, int]] = field(default_factory=list)  # (started, ended)

    @property
    def intervals_s(self) -> list[float]:
        """Seconds between the starts of consecutive calls."""
        return [(b - a) / 1e9 for (_, a), (_, b) in pairwise(self.calls)]

    @property
    def lateness_ms(self) -> list[float]:
        """How long after falling due each call started (ms)."""
        return [(started - due) / NS_PER_MS for due, started in self.calls]

    @property
    def longest_ms(self) -> float:
        """The longest interval between two calls (ms)."""
        return max(self.intervals_s) * 1e3 if len(self.calls) > 1 else float("nan")

    def percentile_ms(self, q: float) -> float:
        """The ``q``-th percentile (0-100) of the lateness (ms)."""
        values = sorted(self.lateness_ms)
        if not values:
            return float("nan")
        return values[min(len(values) - 1, int(round(q / 100 * (len(values) - 1))))]

    def calls_due_while_busy(self) -> list[tuple[int, int, int]]:
        """(fell due, started, the heavy callback's end) of each call that fell due while it ran (ns)."""
        runs = sorted(self.busy)
        starts = [start for start, _end in runs]
        found = []
        for due, started in self.calls:
            k = bisect_right(starts, due) - 1
            if k >= 0 and due < runs[k][1]:
                found.append((due, started, runs[k][1]))
        return found

    def due_while_busy(self) -> list[DueWhileBusy]:
        """The calls that fell due while a heavy callback ran, with how long each waited and how
        long the heavy callback still ran then."""
        return [DueWhileBusy((started - due) / NS_PER_MS, (end - due) / NS_PER_MS)
                for due, started, end in self.calls_due_while_busy()]

    def summary(self) -> str:
        """One line: the calls, the median (p50) and 95th percentile (p95) of how late they started,
        and the longest interval between two calls."""
        return (f"{self.label}: {len(self.calls)} calls, late by p50 {self.percentile_ms(50):.2f} ms, "
                f"p95 {self.percentile_ms(95):.2f} ms; longest interval {self.longest_ms:.1f} ms")

    def busy_summary(self) -> str:
        """One line on the calls that fell due while the heavy callback ran."""
        found = self.due_while_busy()
        if not found:
            return f"{self.label}: no call fell due while the heavy callback ran"
        after = [c for c in found if c.waited_for_it]
        during = len(found) - len(after)
        text = (f"{self.label}: {len(found)} calls fell due while the heavy callback ran; "
                f"{len(after)} started only after it ended, {during} while it still ran")
        if after:
            left = statistics.fmean(c.left_ms for c in after)
            more = statistics.fmean(c.wait_ms - c.left_ms for c in after)
            text += (f". Those that waited for it: {left:.1f} ms for the rest of the heavy callback, "
                     f"then {more:.2f} ms more, on average")
        return text


def measure_timer_jitter(period_s: float = 0.01, duration_s: float = 2.0, heavy_ms: float = 0.0,
                         heavy_period_s: float = 0.05, executor: str = "single",
                         separate_groups: bool = False, label: str | None = None) -> JitterResult:
    """Fire a timer every ``period_s`` for ``duration_s`` and return what its calls did.

    Args:
        period_s: the timer's period, 0.001..1 s.
        duration_s: how long to measure, seconds.
        heavy_ms: > 0 adds a second timer (every ``heavy_period_s`` s) whose callback keeps the CPU
            busy for that many milliseconds, in the same executor.
        executor, separate_groups: as in :func:`spin_for`; ``separate_groups`` gives the heavy
            timer a callback group of its own.
        label: the result's name (default: 'idle' or a description of the heavy callback).

    Returns:
        A :class:`JitterResult`.
    """
    if not 0.001 <= period_s <= 1:
        raise CourseError(f"period_s must be 0.001..1 s, got {period_s!r}")
    if heavy_ms < 0 or heavy_ms >= heavy_period_s * 1e3:
        raise CourseError(f"heavy_ms must be >= 0 and shorter than heavy_period_s "
                          f"({heavy_period_s * 1e3:g} ms), got {heavy_ms!r}")
    node = spin_for(JitterProbe, duration_s, executor, period_s=period_s, heavy_ms=heavy_ms,
                    heavy_period_s=heavy_period_s, separate_groups=separate_groups)
    if label is None:
        label = "idle" if heavy_ms == 0 else f"beside a CPU-heavy callback ({heavy_ms:g} ms)"
    return JitterResult(label, period_s, list(node.calls), list(node.busy))


def plot_jitter(results: list[JitterResult], bins: int = 50):
    """Draw one histogram per :class:`JitterResult` of how late the timer's calls started (ms), on a
    shared axis; the calls that fell due while the heavy callback ran are stacked in a second
    colour. Returns the matplotlib figure."""
    import matplotlib.pyplot as plt

    all_ms = [ms for r in results for ms in r.lateness_ms]
    if not all_ms:
        raise CourseError("no timer calls to plot; measure for longer")
    high = max(max(all_ms), results[0].period_s * 1e3)
    edges = [high * k / bins for k in range(bins + 1)]
    fig, axes = plt.subplots(len(results), 1, figsize=(8.5, 1.2 + 1.5 * len(results)), sharex=True,
                             squeeze=False)
    for ax, result in zip(axes[:, 0], results, strict=True):
        busy = {due for due, _started, _end in result.calls_due_while_busy()}
        during = [(s - d) / NS_PER_MS for d, s in result.calls if d in busy]
        other = [(s - d) / NS_PER_MS for d, s in result.calls if d not in busy]
        ax.hist([other, during], bins=edges, stacked=True, color=["#16a34a", "#dc2626"],
                label=["fell due while nothing else ran", "fell due while the heavy callback ran"])
        ax.set_yscale("log")
        ax.set_ylabel("calls")
        ax.set_title(f"{result.label}: half of the calls started within {result.percentile_ms(50):.2f} ms, "
                     f"95% within {result.percentile_ms(95):.2f} ms", fontsize=9, loc="left")
        if during:
            ax.legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel(f"how late a call of the {results[0].period_s * 1e3:g} ms timer started (ms)")
    fig.suptitle("Timer lateness: the same timer, idle and beside a CPU-heavy callback", fontsize=11)
    fig.tight_layout()
    return fig

