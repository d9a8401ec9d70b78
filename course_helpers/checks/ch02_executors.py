"""Checker of chapter 02 (nodes and executors): a heartbeat that stays regular beside slow callbacks."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from course_helpers.chapters.ch02_executors import spin_for, tick_gaps
from course_helpers.checks import CheckReport, judge_timed_scenario

HEARTBEAT_PERIOD_S = 0.1
CAMERA_PERIOD_S, CAMERA_WAIT_S = 0.2, 0.05
PLANNER_PERIOD_S, PLANNER_BLOCK_S = 0.5, 0.3
GIVEN_PERIODS_S = (HEARTBEAT_PERIOD_S, CAMERA_PERIOD_S, PLANNER_PERIOD_S)
MAX_GAP_S = 0.15  # the exercise's watchdog: a heartbeat gap longer than this fails
EXCLUSIVE = "the heartbeat and the planner share one mutually exclusive group: they can never overlap"
PLANNER_GAP_S = 0.25  # a gap this long means the heartbeat waited for the 0.3 s planner
SLEEP_SLACK_S = 0.002  # time.sleep(t) never returns before t; this covers the clock's rounding


@dataclass
class TimedCalls:
    """The calls of one timer's callback: when each started and how long it ran (seconds)."""

    starts: list[float] = field(default_factory=list)
    durations: list[float] = field(default_factory=list)

    def started_during(self, other: TimedCalls) -> int:
        """How many of these calls started while a call of ``other`` was running."""
        runs = list(zip(other.starts, other.durations, strict=True))
        return sum(any(start <= t < start + took for start, took in runs) for t in self.starts)

    def wrap(self, callback):
        def timed(*args):
            started = time.monotonic()
            try:
                return callback(*args)
            finally:
                self.starts.append(started)
                self.durations.append(time.monotonic() - started)

        return timed


def _timed_robot(node_class, calls: dict[float, TimedCalls], periods: list[float], groups: dict):
    """A factory that builds the student's node and times the callback of each of its timers,
    keyed by the timer's period (s), which it appends to ``periods``, and notes each timer's callback
    group in ``groups``. The callbacks themselves are left as they are."""

    def build():
        node = node_class()
        for timer in list(getattr(node, "timers", [])):
            period = round(timer.timer_period_ns / 1e9, 3)
            periods.append(period)
            groups[period] = timer.callback_group
            timer.callback = calls.setdefault(period, TimedCalls()).wrap(timer.callback)
        return node

    return build


def _share_an_exclusive_group(first, second) -> bool:
    """True if two callbacks share one MutuallyExclusiveCallbackGroup: then they never run at once,
    whatever the threads (rclpy's executor asks the group before it starts a callback)."""
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

    return first is not None and first is second and isinstance(first, MutuallyExclusiveCallbackGroup)


def check_responsive_robot(node_class, duration_s: float = 2.0, threads: int = 3) -> CheckReport:
    """Check the student's robot node: the heartbeat stays regular while the slow callbacks run as given.

    Args:
        node_class: a Node subclass (or function) that builds, without arguments, a node with
            three timers: ``heartbeat`` every 0.1 s, ``camera`` every 0.2 s waiting 0.05 s,
            ``planner`` every 0.5 s blocking 0.3 s.
        duration_s: how long to spin it, seconds.
        threads: threads of the MultiThreadedExecutor it is spun in.

    Returns:
        A :class:`CheckReport`, one criterion per requirement. Each timer's callback is timed as it
        runs, so a callback made faster (the planner's sleep deleted) fails although the heartbeat
        would then be regular, and a beat that starts while the planner runs shows that the two
        may overlap. Threads, the GIL and the operating system's scheduler decide when a callback
        really runs, so the run is judged by the one timing verdict
        (:func:`~course_helpers.checks.judge_timed_scenario`): a heartbeat gap on a busy machine is
        measured again, and reported as inconclusive rather than failed.
    """
    from course_helpers.core.runtime import get_runtime

    report = CheckReport("Exercise: keep the heartbeat regular")
    node = report.run("the node starts and spins", lambda: get_runtime().build(node_class),
                      hint="Run the class cell first; __init__ takes no arguments.")
    if node is None:
        return report
    node.destroy_node()
    report.add("the node starts and spins", True)
    judge_timed_scenario(report, "the heartbeat stays regular beside the camera and the planner",
                         lambda: _robot_run(node_class, duration_s, threads))
    return report


def _robot_run(node_class, duration_s: float, threads: int) -> list:
    """One run of the robot in a multi-threaded executor, judged: (name, passed, detail, hint) each, and
    True fifth where the callback groups alone decide the outcome."""
    calls: dict[float, TimedCalls] = {}
    periods: list[float] = []
    groups: dict[float, object] = {}
    spin_for(_timed_robot(node_class, calls, periods, groups), duration_s, "multi", threads=threads)
    exclusive = _share_an_exclusive_group(groups.get(HEARTBEAT_PERIOD_S), groups.get(PLANNER_PERIOD_S))
    periods.sort()
    heartbeat = calls.get(HEARTBEAT_PERIOD_S, TimedCalls())
    planner = calls.get(PLANNER_PERIOD_S, TimedCalls())
    beside = heartbeat.started_during(planner)
    worst = tick_gaps(heartbeat.starts, HEARTBEAT_PERIOD_S, "heartbeat").max_gap_s
    if worst < MAX_GAP_S:
        gap = ""
    elif worst >= PLANNER_GAP_S:
        gap = f"a gap of {worst:.2f} s: the heartbeat waited for the planner"
    else:
        gap = f"a gap of {worst:.2f} s"
    return [
        ("its timers are the given ones: every 0.1 s, 0.2 s and 0.5 s", periods == sorted(GIVEN_PERIODS_S),
         "" if periods == sorted(GIVEN_PERIODS_S) else f"found timers every {periods} s",
         "Compare the timers with the exercise as given: their periods stay as they are."),
        ("the heartbeat kept beating while the planner blocked", beside > 0 and not exclusive,
         EXCLUSIVE if exclusive else ("" if beside else "no beat started while the planner ran"),
         "Two callbacks run at the same time only when nothing forbids it: section 8 shows what decides "
         "that, beside the number of threads.", exclusive),
        ("no gap between heartbeats above 0.15 s", not gap and not exclusive, EXCLUSIVE if exclusive else gap,
         "Section 8 measured a control loop that kept ticking beside a blocking planner in one of three "
         "configurations: compare that node's constructor with yours.", exclusive),
        _ran_as_given("camera", calls.get(CAMERA_PERIOD_S), CAMERA_WAIT_S, 5),
        _ran_as_given("planner", calls.get(PLANNER_PERIOD_S), PLANNER_BLOCK_S, 2),
    ]


def _ran_as_given(what: str, timed: TimedCalls | None, takes_s: float, at_least: int) -> tuple:
    """The criterion that the ``what`` callback ran ``at_least`` times, each taking ``takes_s`` (sleep
    never returns early: a call shorter than that was changed), as (name, passed, detail, hint)."""
    name = f"the {what} ran as given: at least {at_least} times, each taking {takes_s * 1e3:g} ms"
    calls = timed.durations if timed is not None else []
    if len(calls) < at_least:
        detail = f"fewer than {at_least} calls"
    elif min(calls) < takes_s - SLEEP_SLACK_S:
        detail = f"a call took less than {takes_s * 1e3:g} ms"
    else:
        detail = ""
    return (name, not detail, detail, f"The exercise leaves what the {what} does unchanged; compare your "
            f"{what} timer and callback with the cell as given.")
