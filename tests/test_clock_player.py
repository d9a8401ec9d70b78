"""ClockPlayer (core/clock_player.py): a node with use_sim_time follows it, paused, stepped, sped up, jumped.

Each verdict waits for the node's clock to show the value the player set (by construction: a
paused clock publishes one time); the one measurement of speed carries the timing mark.
"""

from __future__ import annotations

import time

import pytest
from rclpy.clock import ClockChange, JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter

from course_helpers.core.clock_player import ClockPlayer
from course_helpers.core.errors import CourseError


class Follower(Node):
    """Lives in /clock's time; keeps every time jump it is told about."""

    def __init__(self):
        super().__init__("clock_follower", parameter_overrides=[Parameter("use_sim_time", value=True)])
        self.jumps: list[tuple[ClockChange, float]] = []
        self.jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=Duration(seconds=1.0), min_backward=Duration(seconds=-1.0)),
            post_callback=lambda jump: self.jumps.append((jump.clock_change, jump.delta.nanoseconds / 1e9)))

    def now_ns(self) -> int:
        return self.get_clock().now().nanoseconds


@pytest.fixture
def clock(rt):
    player = ClockPlayer(rt, start_s=100.0, publish_hz=50.0)
    yield player
    player.close()


def test_paused_and_stepped_time_is_exactly_what_the_player_says(rt, clock):
    node = rt.add(Follower, console=False)
    clock.pause()
    paused = clock.now_ns
    rt.wait_until(lambda: node.now_ns() == paused, 5, "the node to see the paused time")
    clock.step(2.5)
    rt.wait_until(lambda: node.now_ns() == paused + 2_500_000_000, 5, "the node to see the step")
    clock.jump(50.0)
    rt.wait_until(lambda: node.now_ns() == 50_000_000_000, 5, "the node to see the jump back")
    rt.wait_until(lambda: any(delta < -50 for _change, delta in node.jumps), 5, "the backward jump callback")
    clock.step(10.0)
    rt.wait_until(lambda: any(delta == 10.0 for _change, delta in node.jumps), 5, "the forward jump callback")
    assert all(change == ClockChange.ROS_TIME_NO_CHANGE for change, _delta in node.jumps)


@pytest.mark.timing
def test_ten_times_faster_moves_ros_time_ten_times_as_far(rt, clock):
    node = rt.add(Follower, console=False)
    rt.wait_until(lambda: node.now_ns() >= 100_000_000_000, 5, "the node on the player's clock")
    clock.set_rate(10.0)
    ros0, wall0 = clock.now_ns, time.monotonic()
    rt.poll_until(lambda: False, 0.3)
    ros, wall = clock.now_ns - ros0, time.monotonic() - wall0
    assert ros / 1e9 == pytest.approx(10.0 * wall, rel=0.01)  # the player's own time: by its formula
    rt.wait_until(lambda: node.now_ns() >= ros0 + ros, 5, "the node to catch up")


def test_bad_values_are_refused(rt, clock):
    for call, match in ((lambda: clock.set_rate(0), "rate"), (lambda: clock.step(-1), "forward"),
                        (lambda: clock.jump(-5), "jump"),
                        (lambda: ClockPlayer(rt, publish_hz=0), "publish_hz")):
        with pytest.raises(CourseError, match=match):
            call()
