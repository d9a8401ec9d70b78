"""Checker of chapter 02 (nodes and executors): a heartbeat that stays regular beside slow callbacks."""

from __future__ import annotations

from course_helpers.chapters.ch02_executors import JitterProbe, spin_for, spinning_alone, tick_gaps
from course_helpers.checks import CheckReport

HEARTBEAT_PERIOD_S = 0.1
MAX_GAP_S = 0.15  # the exercise's watchdog: a heartbeat gap longer than this fails
PLANNER_GAP_S = 0.25  # a gap this long means the heartbeat waited for the 0.3 s planner
PROBE_PERIOD_S = 0.02


def check_responsive_robot(node_class, duration_s: float = 2.5, threads: int = 3) -> CheckReport:
    """Check the student's robot node: the heartbeat stays regular while slow callbacks run.

    Args:
        node_class: a Node subclass (or function) that builds, without arguments, a node with
            three timers: ``heartbeat`` every 0.1 s appending time.monotonic() to ``self.beats``,
            ``camera`` every 0.2 s sleeping 0.05 s and counting ``self.frames``, ``planner`` every
            0.5 s sleeping 0.3 s and counting ``self.plans``.
        duration_s: how long to spin it, seconds.
        threads: threads of the MultiThreadedExecutor it is spun in.

    Returns:
        A :class:`CheckReport`, one criterion per requirement. A probe timer, spun alone beside the
        node, measures how long the machine itself kept this process from running (other
        programs on a busy computer); a heartbeat gap is judged without that delay, but a gap
        as long as a wait for the planner always fails.
    """
    report = CheckReport("Exercise: keep the heartbeat regular")
    with spinning_alone(JitterProbe, period_s=PROBE_PERIOD_S, name="_stall_probe") as probe:
        node = report.run("the node starts and spins",
                          lambda: spin_for(node_class, duration_s, "multi", threads=threads),
                          hint="Run the class cell first; __init__ takes no arguments.")
    if node is None:
        return report
    machine_delay_s = max(tick_gaps(probe.fired, PROBE_PERIOD_S).max_gap_s - PROBE_PERIOD_S, 0.0)
    report.add("the node starts and spins", True)
    beats = tick_gaps(list(getattr(node, "beats", [])), HEARTBEAT_PERIOD_S, "heartbeat")
    frames, plans = getattr(node, "frames", 0), getattr(node, "plans", 0)
    enough = beats.tick_count >= 0.8 * duration_s / HEARTBEAT_PERIOD_S
    report.add("the heartbeat fired about every 0.1 s", enough,
               "" if enough else "fewer than 80% of the expected beats",
               hint="Record time.monotonic() in self.beats at every heartbeat.")
    worst = beats.max_gap_s
    allowed = min(MAX_GAP_S + machine_delay_s, PLANNER_GAP_S)
    if worst < allowed:
        detail = ""
    elif worst >= PLANNER_GAP_S:
        detail = "a gap of 0.25 s or more: the heartbeat waited for the planner"
    else:
        detail = "a gap between 0.15 and 0.25 s"
    report.add("no gap between heartbeats above 0.15 s (beyond the machine's own delays)", worst < allowed,
               detail,
               hint="Callbacks in one mutually exclusive group never overlap: give the heartbeat "
                    "its own callback group, separate from the slow callbacks.")
    report.add("the camera callback kept running (>= 5 frames)", frames >= 5,
               "" if frames >= 5 else "fewer than 5 frames",
               hint="Keep the 0.2 s camera timer and count self.frames.")
    report.add("the planner still ran (>= 2 plans)", plans >= 2,
               "" if plans >= 2 else "fewer than 2 plans",
               hint="Keep the 0.5 s planner with its 0.3 s sleep; making it fast is not the fix.")
    return report
