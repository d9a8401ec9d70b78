"""A ROS time source the caller steers live: pause, resume, step, change the rate, jump.

rosbag2's player keeps the time of what it replays in a *time controller clock* that it can
pause, step and speed up, and with ``--clock`` it publishes that time on ``/clock``. Every node
with the parameter ``use_sim_time`` true then reads its time, and runs its timers, from there.
:class:`ClockPlayer` is that clock for the course: the time lesson drives a node's timers with it,
and the bag player (:mod:`course_helpers.core.bags.player`) paces its messages by it.

Its time runs from the moment it starts at ``rate`` times the speed of the machine's steady clock.
While ``publish_hz`` is set, a node of its own publishes the current time on ``/clock`` that
often (rosbag2's ``--clock`` default is 40 Hz), from a timer on the steady clock (so the clock does
not wait for itself), and once more at once after every change. The QoS is rclcpp's ``ClockQoS``
(best effort, KEEP_LAST 1), which rclpy's time source subscribes with.

Unlike :class:`course_helpers.core.sim_clock.SimClock`, which a checker steps by hand and which
runs the driven nodes itself, this clock runs by itself in the runtime's executor: what the nodes
see depends on when the executor gets to them, so it is for lessons, not for verdicts.
"""

from __future__ import annotations

import threading
import time

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from course_helpers.core.errors import CourseError

CLOCK_TOPIC = "/clock"
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)  # rclcpp::ClockQoS
DEFAULT_PUBLISH_HZ = 40.0  # rosbag2 play --clock without a value
MAX_RATE = 1000.0
_players: dict[str, ClockPlayer] = {}  # by node name: a new player replaces the old one (re-run safe)


def _check_rate(rate: float) -> float:
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0 < rate <= MAX_RATE:
        raise CourseError(f"rate must be a number > 0 and <= {MAX_RATE:g} (1 = real time), got {rate!r}")
    return float(rate)


class ClockPlayer:
    """``ClockPlayer(rt, start_s=None, rate=1.0, publish_hz=40.0)``: a time that starts at ``start_s``
    (default: now, by the system clock) and runs at ``rate``; ``publish_hz=None`` publishes nothing.

    ``now_ns`` / ``now_s``, ``pause()``, ``resume()``, ``paused``, ``set_rate(r)``, ``step(s)``
    (forward by ``s`` seconds at once), ``jump(to_s)`` (anywhere, backwards too), ``close()``.
    A new player with the ``name`` of one that still runs closes that one first, so running a cell
    again never leaves two clocks publishing.
    """

    def __init__(self, rt, start_s: float | None = None, rate: float = 1.0,
                 publish_hz: float | None = DEFAULT_PUBLISH_HZ, name: str = "_clock_player"):
        self._rate = _check_rate(rate)
        if publish_hz is not None and not 0 < publish_hz <= 1000:
            raise CourseError(f"publish_hz must be > 0 and <= 1000 (or None), got {publish_hz!r}")
        self._changed = threading.Condition()
        self._base_ns = round((time.time() if start_s is None else start_s) * 1e9)
        self._anchor = time.monotonic_ns()
        self._paused = False
        self._closed = False
        self.rt = rt
        self.name = name
        self.node = self._publisher = self._timer = None
        if _players.get(name) is not None:
            _players.pop(name).close()
        if publish_hz is not None:
            from rosgraph_msgs.msg import Clock as ClockMessage

            self._message = ClockMessage
            self.node = Node(name, context=rt.context, enable_rosout=False, start_parameter_services=False)
            self._publisher = self.node.create_publisher(ClockMessage, CLOCK_TOPIC, CLOCK_QOS)
            self._timer = self.node.create_timer(1.0 / publish_hz, self.publish,
                                                 clock=Clock(clock_type=ClockType.STEADY_TIME))
            rt.executor.add_node(self.node)
            _players[name] = self

    # ------------------------------------------------------------------ the time
    @property
    def now_ns(self) -> int:
        with self._changed:
            return self._now_locked()

    @property
    def now_s(self) -> float:
        return self.now_ns / 1e9

    def _now_locked(self) -> int:
        if self._paused:
            return self._base_ns
        return self._base_ns + round(self._rate * (time.monotonic_ns() - self._anchor))

    def _rebase(self) -> None:
        self._base_ns, self._anchor = self._now_locked(), time.monotonic_ns()

    @property
    def rate(self) -> float:
        return self._rate

    @property
    def paused(self) -> bool:
        return self._paused

    def _change(self, what) -> None:
        with self._changed:
            if self._closed:
                raise CourseError("this clock player is closed; make a new one")
            self._rebase()
            what()
            self._anchor = time.monotonic_ns()
            self._changed.notify_all()
        self.publish()

    def pause(self) -> None:
        """Stop the time where it is (nodes under it see it stand still; their timers stop)."""
        self._change(lambda: setattr(self, "_paused", True))

    def resume(self) -> None:
        """Let the time run again from where it stopped."""
        self._change(lambda: setattr(self, "_paused", False))

    def set_rate(self, rate: float) -> None:
        """Run at ``rate`` times real time from now on (10: ten seconds of ROS time per second)."""
        rate = _check_rate(rate)
        self._change(lambda: setattr(self, "_rate", rate))

    def step(self, seconds: float) -> None:
        """Move the time forward by ``seconds`` at once (paused or not)."""
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not seconds >= 0:
            raise CourseError(f"step moves time forward: seconds must be a number >= 0, got {seconds!r}")
        self._change(lambda: setattr(self, "_base_ns", self._base_ns + round(seconds * 1e9)))

    def jump(self, to_s: float) -> None:
        """Set the time to ``to_s`` seconds, forward or back: a time jump for every node under it."""
        if isinstance(to_s, bool) or not isinstance(to_s, (int, float)) or to_s < 0:
            raise CourseError(f"jump takes a time in seconds >= 0, got {to_s!r}")
        self._change(lambda: setattr(self, "_base_ns", round(to_s * 1e9)))

    def wait_until(self, ns: int, stop: threading.Event) -> bool:
        """Block until this clock reads at least ``ns``: True; False once ``stop`` is set."""
        with self._changed:
            while not stop.is_set() and not self._closed:
                now = self._now_locked()
                if now >= ns:
                    return True
                wall_s = None if self._paused else (ns - now) / self._rate / 1e9
                self._changed.wait(min(wall_s, 0.1) if wall_s is not None else 0.1)
        return False

    # ------------------------------------------------------------------ /clock
    def publish(self) -> None:
        """Publish the current time on /clock now (the timer does it ``publish_hz`` times a second)."""
        if self._publisher is None or self._closed:
            return
        message = self._message()
        message.clock.sec, message.clock.nanosec = divmod(self.now_ns, 1_000_000_000)
        self._publisher.publish(message)

    def close(self) -> None:
        """Stop publishing and destroy the clock's node."""
        with self._changed:
            if self._closed:
                return
            self._closed = True
            self._changed.notify_all()
        if _players.get(self.name) is self:
            del _players[self.name]
        if self.node is not None:
            node = self.node

            def destroy():
                if self.rt.executor is not None:
                    self.rt.executor.remove_node(node)
                node.destroy_node()

            if self.rt.running:
                self.rt.call_in_executor(destroy)

    def __enter__(self) -> ClockPlayer:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()
