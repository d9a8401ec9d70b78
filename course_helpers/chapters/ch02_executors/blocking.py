"""A blocking callback and the executor: chapter 02's stall measurements, and their plot.

* :func:`spin_for` / :func:`spinning_alone` spin a node in a dedicated single- or multi-threaded
  executor for a few seconds, then destroy it, to compare executors and callback groups.
* :func:`measure_blocking` runs a control timer beside a planner that blocks;
  :func:`tick_gaps` / :func:`plot_tick_gaps` turn a timer's tick times into gaps and draw them.

The measurements run real rclpy timers in the kernel's context; on a busy machine the numbers
move, so the notebook asserts only what holds under load (a blocking callback stalls a timer of
its own group, and none of another group on another thread) and prints the rest.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field
from itertools import pairwise

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from course_helpers.core.errors import CourseError
from course_helpers.core.executors import spinning_alone as core_spinning_alone

EXECUTORS = ("single", "multi")


@contextmanager
def spinning_alone(node_factory: Callable[..., Node], executor: str = "single", threads: int = 2,
                   **kwargs):
    """Build a node and spin it in a fresh executor of its own while the ``with`` block runs.

    Args:
        node_factory: a Node subclass (or a function returning a node), called with ``kwargs``.
        executor: 'single' (SingleThreadedExecutor) or 'multi' (MultiThreadedExecutor with
            ``threads`` threads).

    Yields:
        The node. It joins the kernel's context, like ``rt.add``, but its executor spins nothing
        else, so a measurement is not mixed with the notebook's other nodes. After the block the
        executor is shut down and the node destroyed; then the first exception a callback raised
        is raised again.
    """
    from course_helpers.core.runtime import get_runtime

    if executor not in EXECUTORS:
        raise CourseError(f"executor must be 'single' or 'multi', got {executor!r}")
    with core_spinning_alone(get_runtime(), _checked_factory(node_factory), executor, threads,
                             thread_name=f"spin_for-{executor}", **kwargs) as node:
        yield node


def _checked_factory(node_factory):
    def build(**kwargs):
        node = node_factory(**kwargs)
        if not isinstance(node, Node):
            raise CourseError(f"{node_factory!r} returned {type(node).__name__}, not an rclpy Node")
        return node

    return build


def spin_for(node_factory: Callable[..., Node], duration_s: float = 2.0, executor: str = "single",
             threads: int = 2, **kwargs) -> Node:
    """Build a node, spin it alone in a fresh executor for ``duration_s`` seconds, destroy it.

    Takes what :func:`spinning_alone` takes, and ``duration_s`` in (0, 30] seconds. Returns the
    (destroyed) node, so its recorded attributes can be read; the first exception a callback
    raised is raised again instead.
    """
    if not 0 < duration_s <= 30:
        raise CourseError(f"duration_s must be in (0, 30] seconds, got {duration_s!r}")
    with spinning_alone(node_factory, executor, threads, **kwargs) as node:
        time.sleep(duration_s)  # the measurement window
    return node


# ---------------------------------------------------------------------- a blocking callback
class ControlLoopWithPlanner(Node):
    """A fast control timer and a slow 'planner' timer whose callback blocks (sleeps).

    ``separate_groups=True`` puts each timer in its own mutually exclusive callback group, so
    a multi-threaded executor can run the control tick while the planner blocks.
    """

    def __init__(self, control_period_s: float = 0.02, plan_period_s: float = 0.5,
                 block_s: float = 0.3, separate_groups: bool = False, name: str = "controller"):
        super().__init__(name)
        self.period_s, self.block_s = control_period_s, block_s
        control_group = MutuallyExclusiveCallbackGroup() if separate_groups else None
        planner_group = MutuallyExclusiveCallbackGroup() if separate_groups else None
        self.ticks: list[float] = []  # time.monotonic() of each control tick, s
        self.control_timer = self.create_timer(control_period_s, self.control_tick,
                                               callback_group=control_group)
        self.plan_timer = self.create_timer(plan_period_s, self.plan, callback_group=planner_group)

    def control_tick(self) -> None:
        self.ticks.append(time.monotonic())

    def plan(self) -> None:
        time.sleep(self.block_s)  # stands in for a slow computation or a blocking call


@dataclass
class GapResult:
    """Gaps between consecutive ticks of a timer (seconds) in one executor configuration."""

    label: str
    period_s: float
    gaps_s: list[float]
    ticks: list[float] = field(default_factory=list, repr=False)

    @property
    def max_gap_s(self) -> float:
        return max(self.gaps_s) if self.gaps_s else float("inf")

    @property
    def tick_count(self) -> int:
        return len(self.ticks)


def tick_gaps(ticks: list[float], period_s: float, label: str = "") -> GapResult:
    """A :class:`GapResult` of the gaps between consecutive ``ticks`` (seconds) of a timer of
    ``period_s``; ``label`` names the configuration."""
    gaps = [b - a for a, b in pairwise(ticks)]
    return GapResult(label, period_s, gaps, list(ticks))


def measure_blocking(executor: str = "single", separate_groups: bool = False, duration_s: float = 2.0,
                     block_s: float = 0.3, control_period_s: float = 0.02,
                     node_class: Callable[..., Node] = ControlLoopWithPlanner) -> GapResult:
    """Run a control loop next to a blocking planner and return the control timer's gaps.

    Args:
        executor: 'single' or 'multi' (see :func:`spin_for`).
        separate_groups: passed to ``node_class``: its own callback group for each timer.
        duration_s: how long to spin, seconds.
        block_s, control_period_s: the planner's blocking time and the control period, seconds;
            ``control_period_s`` is used only if the node has no ``period_s`` attribute.
        node_class: must accept ``separate_groups`` and record ``ticks`` (like
            :class:`ControlLoopWithPlanner`); the notebook passes its own class.

    Returns:
        A :class:`GapResult` labelled with the configuration.
    """
    node = spin_for(node_class, duration_s, executor, separate_groups=separate_groups)
    groups = "separate groups" if separate_groups else "one default group"
    label = f"{'single' if executor == 'single' else 'multi'}-threaded, {groups}"
    return tick_gaps(node.ticks, getattr(node, "period_s", control_period_s), label)


def plot_tick_gaps(results: list[GapResult], block_s: float | None = None):
    """Draw one row per :class:`GapResult`: each gap as a line at its tick's time, the period and
    (if given) the blocking time ``block_s`` as reference lines. Returns the matplotlib figure."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(results), 1, figsize=(9, 1.6 + 1.3 * len(results)), sharex=True,
                             squeeze=False)
    for ax, result in zip(axes[:, 0], results, strict=True):
        if not result.ticks:
            ax.text(0.5, 0.5, "no ticks", transform=ax.transAxes, ha="center")
            continue
        start = result.ticks[0]
        times = [t - start for t in result.ticks[1:]]
        gaps_ms = [g * 1e3 for g in result.gaps_s]
        ax.vlines(times, 0, gaps_ms, color="#2563eb", linewidth=1)
        ax.axhline(result.period_s * 1e3, color="#16a34a", linestyle="--", linewidth=1,
                   label=f"period {result.period_s * 1e3:.0f} ms")
        if block_s:
            ax.axhline(block_s * 1e3, color="#dc2626", linestyle=":", linewidth=1,
                       label=f"blocking call {block_s * 1e3:.0f} ms")
        ax.set_ylabel("gap (ms)")
        ax.set_title(result.label, fontsize=10, loc="left")
        ax.legend(loc="upper left", fontsize=7)  # over the first ticks, which are short
    axes[-1, 0].set_xlabel("time since first control tick (s)")
    fig.suptitle("Gaps between control-timer ticks", fontsize=11)
    fig.tight_layout()
    return fig
