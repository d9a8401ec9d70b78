"""Checker of chapter 03b (recording and replay): an odometry monitor judged on a recorded bag.

The bag (``checks/data/ch03b_odometry``, recorded by the course from
:class:`course_helpers.chapters.ch03b_bags.OdometrySource`) holds 94 odometry messages: each stamped
when it was measured and received 6-44 ms later, and a silence of about 1.2 s in the middle. The
checker owns ``/clock`` and the executor (:class:`~course_helpers.core.sim_clock.SimClock`): it
feeds each message to the student's node at the time it was recorded (:class:`SimReplay`), lets
everything settle, and judges what the node published and when, in the bag's own time. The
expected values come from the bag itself, so the verdict is the same on every run and machine.
"""

from __future__ import annotations

from pathlib import Path

from rclpy.node import Node
from std_msgs.msg import Bool, Float64

from course_helpers.checks import CheckReport
from course_helpers.core import bags
from course_helpers.core.sim_clock import SimClock

EXERCISE_BAG = Path(__file__).resolve().parent / "data" / "ch03b_odometry"
TIMEOUT_S = 0.5  # the exercise's dropout: no odometry for longer than this
TIMER_PERIOD_S = 0.1  # the exercise's watchdog timer
STEP_S = 0.01  # the checker moves the clock in steps of this between messages
SPEED_TOLERANCE = 1e-6  # m/s: a speed from the stamps matches to the last digits


class _Probe(Node):
    """Keeps what the monitor publishes, with the ROS time it arrived at."""

    def __init__(self):
        super().__init__("odom_monitor_probe")
        self.speeds: list[float] = []
        self.stale: list[tuple[float, bool]] = []
        self.create_subscription(Float64, "speed", lambda msg: self.speeds.append(msg.data), 100)
        self.create_subscription(Bool, "odom_stale", self.on_stale, 100)

    def on_stale(self, msg: Bool) -> None:
        self.stale.append((self.get_clock().now().nanoseconds / 1e9, msg.data))


def _expected(bag) -> tuple[list[float], float, float, list[tuple[float, float]]]:
    """From the bag: the speeds between stamps, the receive times before and after its silence, and
    every ``(receive s, stamp s)``."""
    messages = bags.read(bag, "/odom")
    points = [(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, m.pose.pose.position.x)
              for _t, m in messages]
    speeds = [(x1 - x0) / (t1 - t0) for (t0, x0), (t1, x1) in zip(points, points[1:], strict=False)]
    received = [t / 1e9 for t, _m in messages]
    gap = max(range(1, len(received)), key=lambda i: received[i] - received[i - 1])
    return speeds, received[gap - 1], received[gap], list(zip(received, (p[0] for p in points), strict=True))


def check_odom_monitor(node_class, rt=None, bag=None) -> CheckReport:
    """Replay the exercise's bag into ``node_class`` (built without arguments) under a clock the
    checker owns, and judge its speeds and its dropout reports."""
    if rt is None:
        from course_helpers.core.runtime import get_runtime

        rt = get_runtime()
    bag = bag or EXERCISE_BAG
    report = CheckReport("Odometry monitor, replayed from a bag")
    speeds, silent_from, back_at, _times = _expected(bag)
    clock = SimClock(rt, start_s=bags.bag_info(bag).start_ns / 1e9 - 1.0)
    built = []
    try:
        node = report.run("the node can be created", lambda: clock.drive(rt.build(node_class)),
                          hint="Run the class cell first; the constructor must take no arguments.")
        if node is None:
            return report
        built.append(node)
        probe = clock.drive(rt.build(_Probe))
        built.append(probe)
        replay = bags.SimReplay(rt, clock, bag, topics=["/odom"])
        built.append(replay.node)
        replay.run(step_s=STEP_S)
        clock.advance(TIMEOUT_S / 2, step_s=STEP_S)  # settle, but stop before the end looks like a dropout
        _judge(report, clock, probe, speeds, silent_from, back_at)
    finally:
        clock.close()
        for each in built:
            each.destroy_node()
    return report


def _judge(report: CheckReport, clock: SimClock, probe: _Probe, speeds, silent_from: float,
           back_at: float) -> None:
    errors = clock.errors
    report.add("its callbacks ran without an error", not errors,
               f"{type(errors[0]).__name__}: {errors[0]}" if errors else "",
               "A callback raised; the first message has no previous one to compare with.")
    report.add(f"it publishes one speed on /speed per odometry message after the first ({len(speeds)})",
               len(probe.speeds) == len(speeds), f"got {len(probe.speeds)}",
               "Publish in the odom callback, from the second message on.")
    close = len(probe.speeds) == len(speeds) and all(
        abs(got - want) <= SPEED_TOLERANCE for got, want in zip(probe.speeds, speeds, strict=True))
    worst = max((abs(g - w) for g, w in zip(probe.speeds, speeds, strict=False)), default=0.0)
    report.add("each speed is the distance over the time between the two header stamps", close,
               f"largest difference {worst:.3g} m/s" if probe.speeds else "no speed published",
               "Use msg.header.stamp (when the pose was measured), not the time it arrived.")
    alarms = [t for t, stale in probe.stale if stale]
    first = alarms[0] - silent_from if alarms else None
    on_time = first is not None and TIMEOUT_S < first <= TIMEOUT_S + TIMER_PERIOD_S + STEP_S + 1e-9
    report.add("it reports the dropout (True on /odom_stale) 0.5-0.6 s of ROS time after the last message",
               on_time, f"first report {first:.3f} s after it" if first is not None else "no report",
               "Keep self.get_clock().now() of the last message and compare in a timer; time.time() or "
               "time.monotonic() do not follow the bag's clock.")
    report.add("it reports that dropout once, and raises no other alarm", len(alarms) == 1,
               f"{len(alarms)} True message(s)", "Publish True only when the state changes.")
    recovered = [t for t, stale in probe.stale if not stale]
    report.add("it reports the recovery (False) when odometry comes back",
               len(recovered) == 1 and abs(recovered[0] - back_at) < 1e-6,
               f"False at {[round(t - back_at, 3) for t in recovered]} s after the first new message",
               "In the odom callback, publish False if the state was stale.")
