"""Chapter 03b's odometry-monitor checker: it accepts the reference, and every criterion fails on a wrong one.

The checker replays a recorded bag into the node under a SimClock it owns, so each verdict is
exact. Each wrong monitor below is a mistake a student makes; the table names the criteria it must
fail, and the test of the reference checks that the table covers every criterion the checker reports.
"""

from __future__ import annotations

import time

import pytest
from rclpy.duration import Duration
from std_msgs.msg import Bool, Float64

from course_helpers.checks.ch03b_bags import check_odom_monitor
from course_helpers.solutions.ch03b_bags import OdomMonitor

from .criteria_registry import assert_reference_criteria, failing


def _failed(report) -> set[str]:
    return {c.name for c in report.criteria if not c.passed}


class NeedsAnArgument(OdomMonitor):
    """Wrong: the constructor takes an argument the checker cannot give."""

    def __init__(self, timeout_s):
        super().__init__()


class ComparesWithNothing(OdomMonitor):
    """Wrong: the first message has no previous one, and the callback raises."""

    def on_odom(self, msg):
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        t0, x0 = self.previous  # None at the first message: TypeError
        self.speed_publisher.publish(Float64(data=(msg.pose.pose.position.x - x0) / (stamp - t0)))
        self.previous = (stamp, msg.pose.pose.position.x)
        self.last_heard = self.get_clock().now()


class SpeedFromTheFirstMessage(OdomMonitor):
    """Wrong: publishes a speed of 0 for the first message too."""

    def on_odom(self, msg):
        if self.previous is None:
            self.speed_publisher.publish(Float64(data=0.0))
        super().on_odom(msg)


class SpeedFromReceiveTimes(OdomMonitor):
    """Wrong: divides by the time between arrivals, not between the stamps."""

    def on_odom(self, msg):
        now = self.get_clock().now().nanoseconds * 1e-9
        x = msg.pose.pose.position.x
        if self.previous is not None:
            self.speed_publisher.publish(Float64(data=(x - self.previous[1]) / (now - self.previous[0])))
        self.previous = (now, x)
        self.last_heard = self.get_clock().now()
        if self.stale:
            self.stale = False
            self.stale_publisher.publish(Bool(data=False))


class WatchdogOnTheWallClock(OdomMonitor):
    """Wrong: times the silence with time.monotonic(), which does not follow the bag's clock."""

    def on_odom(self, msg):
        super().on_odom(msg)
        self.wall_heard = time.monotonic()

    def check(self):
        if getattr(self, "wall_heard", None) is None or self.stale:
            return
        if time.monotonic() - self.wall_heard > 0.5:
            self.stale = True
            self.stale_publisher.publish(Bool(data=True))


class AlarmOnEveryTick(OdomMonitor):
    """Wrong: repeats True on every timer tick of the dropout."""

    def check(self):
        if self.last_heard is not None and self.get_clock().now() - self.last_heard > self.timeout:
            self.stale = True
            self.stale_publisher.publish(Bool(data=True))


class TooTightATimeout(OdomMonitor):
    """Wrong: 50 ms, the period itself: a message that arrives a little late raises an alarm."""

    def __init__(self):
        super().__init__()
        self.timeout = Duration(seconds=0.05)


class NeverRecovers(OdomMonitor):
    """Wrong: reports the dropout but never says that odometry came back."""

    def on_odom(self, msg):
        stale, self.stale = self.stale, False
        super().on_odom(msg)
        self.stale = stale


DROPOUT = "it reports the dropout (True on /odom_stale) 0.5-0.6 s of ROS time after the last message"
ONCE = "it reports that dropout once, and raises no other alarm"
WRONG = [
    pytest.param(NeedsAnArgument, {"the node can be created"}, id="argument"),
    pytest.param(ComparesWithNothing, {"its callbacks ran without an error"}, id="raises"),
    pytest.param(SpeedFromTheFirstMessage,
                 {"it publishes one speed on /speed per odometry message after the first (93)"}, id="first"),
    pytest.param(SpeedFromReceiveTimes,
                 {"each speed is the distance over the time between the two header stamps"},
                 id="receive-times"),
    pytest.param(WatchdogOnTheWallClock, {DROPOUT}, id="wall-clock"),
    pytest.param(AlarmOnEveryTick, {ONCE}, id="every-tick"),
    pytest.param(TooTightATimeout, {DROPOUT, ONCE}, id="tight"),
    pytest.param(NeverRecovers, {"it reports the recovery (False) when odometry comes back"},
                 id="no-recovery"),
]


def test_the_reference_passes_the_same_way_twice_and_every_criterion_has_a_wrong_solution(rt):
    first, second = check_odom_monitor(OdomMonitor, rt), check_odom_monitor(OdomMonitor, rt)
    assert first.passed, first.summary()
    assert first.summary() == second.summary()  # the bag's clock: the same report on every run
    assert_reference_criteria("check_odom_monitor", first)


@pytest.mark.parametrize("wrong, failing", WRONG)
def test_each_criterion_fails_on_a_wrong_solution(rt, wrong, failing):
    report = check_odom_monitor(wrong, rt)
    assert not report.passed
    assert failing <= _failed(report), report.summary()


COVERED = {"check_odom_monitor": failing(WRONG)}
ONLY_WHEN_FAILING = {"check_odom_monitor": {"the node can be created"}}
