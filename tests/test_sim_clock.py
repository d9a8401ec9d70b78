"""SimClock (core/sim_clock.py): a node's timers follow the clock a test owns, exactly, on any machine."""

from __future__ import annotations

import time

import pytest
from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.core.errors import CourseError
from course_helpers.core.sim_clock import START_S, SimClock


class Ticker(Node):
    """Ticks every 0.1 s of its own clock; echoes every message it hears on 'ping' to 'pong'."""

    def __init__(self):
        super().__init__("sim_ticker")
        self.ticks: list[float] = []
        self.timer = self.create_timer(0.1, self.tick)
        self.pong = self.create_publisher(String, "pong", 10)
        self.create_subscription(String, "ping", lambda msg: self.pong.publish(msg), 10)

    def tick(self) -> None:
        self.ticks.append(self.get_clock().now().nanoseconds / 1e9)


class WallTicker(Node):
    """The same timer, but it reads the wall clock: what a checker must catch."""

    def __init__(self):
        super().__init__("sim_wall_ticker")
        self.stamps: list[float] = []
        self.timer = self.create_timer(0.1, lambda: self.stamps.append(time.time()))


@pytest.fixture
def clock(rt):
    owned = SimClock(rt)
    yield owned
    nodes = list(owned.driven)
    owned.close()
    for node in nodes:
        node.destroy_node()


def test_timers_follow_the_owned_clock_exactly_and_fast(rt, clock):
    node = clock.drive(rt.build(Ticker))
    started = time.monotonic()
    clock.advance(10.0, step_s=0.05)
    wall = time.monotonic() - started
    assert len(node.ticks) in (99, 100), len(node.ticks)  # one every 0.1 s of ROS time, nothing else
    assert all(abs(b - a - 0.1) < 1e-6 for a, b in zip(node.ticks, node.ticks[1:], strict=False))
    assert node.ticks[-1] <= START_S + 10.0 and clock.now_s == pytest.approx(START_S + 10.0)
    print(f"10 s of ROS time in {wall:.3f} s of wall time")
    clock.step(0.0)
    ticks = len(node.ticks)
    clock.settle()
    assert len(node.ticks) == ticks  # time stands still: no timer fires


def test_after_a_settle_every_message_has_arrived_and_been_answered(rt, clock):
    node = clock.drive(rt.build(Ticker))
    heard: list[str] = []
    probe = clock.drive(rt.build(Node, "sim_probe"))
    probe.create_subscription(String, "pong", lambda msg: heard.append(msg.data), 10)
    ping = probe.create_publisher(String, "ping", 10)
    clock.wait_matched()  # the new subscription and publisher match inside the participant
    for count in range(5):
        ping.publish(String(data=f"n{count}"))
    clock.settle()
    assert heard == [f"n{count}" for count in range(5)]  # no window: the settle is the proof
    clock.step(1.0)
    assert heard == [f"n{count}" for count in range(5)]  # and nothing else came
    assert node.ticks


def test_a_node_that_reads_the_wall_clock_is_seen(rt, clock):
    node = clock.drive(rt.build(WallTicker))
    clock.advance(1.0)
    assert len(node.stamps) >= 9  # its timer follows ROS time ...
    assert max(node.stamps) - min(node.stamps) < 1.0  # ... but the wall clock it reads barely moved
    assert abs(min(node.stamps) - START_S) > 1e6  # and is nowhere near the ROS time it was given


def test_bad_steps_are_refused(rt, clock):
    with pytest.raises(CourseError, match="forward only"):
        clock.step(-1.0)
    with pytest.raises(CourseError, match="step_s"):
        clock.advance(1.0, step_s=0)


class Echo(Node):
    """Publishes every message it hears back to its own topic: it never goes quiet."""

    def __init__(self):
        super().__init__("sim_echo")
        self.out = self.create_publisher(String, "loop", 10)
        self.create_subscription(String, "loop", self.out.publish, 10)


def test_callbacks_that_never_go_quiet_are_an_error_not_a_hang(rt, clock):
    node = clock.drive(rt.build(Echo))
    node.out.publish(String(data="again"))
    with pytest.raises(CourseError, match="did not go quiet"):
        clock.settle()


class Sleeper(Node):
    """An async callback that awaits a one-shot timer's future across clock steps. The callback is in a
    group of its own: while it waits, it holds its group, and the timer must run in another."""

    def __init__(self):
        from rclpy.callback_groups import ReentrantCallbackGroup

        super().__init__("sim_sleeper")
        self.woke: list[float] = []
        self.create_subscription(String, "nap", self.nap, 10, callback_group=ReentrantCallbackGroup())

    async def nap(self, _msg) -> None:
        from rclpy.task import Future

        done = Future()

        def wake():
            self.destroy_timer(timer)
            done.set_result(None)

        timer = self.create_timer(0.5, wake)
        await done
        self.woke.append(self.get_clock().now().nanoseconds / 1e9)


def test_a_coroutine_waiting_for_time_is_quiet_until_time_moves(rt, clock):
    node = clock.drive(rt.build(Sleeper))
    sender = clock.drive(rt.build(Node, "sim_nap_sender"))
    nap = sender.create_publisher(String, "nap", 10)
    clock.wait_matched()
    nap.publish(String(data="now"))
    clock.settle()  # the coroutine waits: a settle ends instead of spinning on it
    assert node.woke == []
    clock.advance(0.49)
    assert node.woke == []
    clock.advance(0.02)
    assert len(node.woke) == 1 and node.woke[0] == pytest.approx(START_S + 0.5, abs=0.011)


def test_advance_until_stops_at_the_first_step_that_makes_it_true(rt, clock):
    node = clock.drive(rt.build(Ticker))
    assert clock.advance_until(lambda: len(node.ticks) >= 3, 1.0, step_s=0.01)
    assert len(node.ticks) == 3 and clock.now_s == pytest.approx(node.ticks[-1])
    assert not clock.advance_until(lambda: len(node.ticks) >= 100, 0.5)
    assert clock.now_s == pytest.approx(node.ticks[2] + 0.5)
